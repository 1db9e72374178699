//! The CAN interface's link as the kernel reports it over netlink (the `socketcan` crate's `nl`
//! module): up or down, bitrate, controller state, `restart-ms` and the listen-only control mode.
//!
//! [`LinkStatus::query`] reads it (no privileges needed); [`LinkStatus::check`] decides whether a
//! controller may start on it, a pure function of the parsed status so the decision is tested
//! without a kernel. A virtual interface (`vcan`) reports no CAN parameters at all: its bitrate,
//! state and `restart-ms` are `None`, shown as "none (virtual interface)", never made up.

use std::fmt;

use socketcan::nl::{CanCtrlMode, CanInterface, CanState, InterfaceDetails};

use super::Error;

/// The bitrate of the excavator's gateway, bit/s (docs/protocol.md).
pub const GATEWAY_BITRATE_BPS: u32 = 500_000;

/// The automatic restart after bus-off that the bring-up procedure sets, ms (docs/deployment.md).
pub const RECOMMENDED_RESTART_MS: u32 = 100;

/// The CAN controller's error state (the kernel's `enum can_state`; `ip -details link` names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "SCREAMING-KEBAB-CASE")]
pub enum ControllerState {
    /// Error counters below 96: normal operation.
    ErrorActive,
    /// Error counters of 96 or more.
    ErrorWarning,
    /// Error counters of 128 or more: the node may no longer signal errors actively.
    ErrorPassive,
    /// Transmit errors reached 256: the controller is off the bus until restarted.
    BusOff,
    /// The device is stopped (down).
    Stopped,
    /// The device is sleeping.
    Sleeping,
}

impl ControllerState {
    /// The name `ip -details link show` prints.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ErrorActive => "ERROR-ACTIVE",
            Self::ErrorWarning => "ERROR-WARNING",
            Self::ErrorPassive => "ERROR-PASSIVE",
            Self::BusOff => "BUS-OFF",
            Self::Stopped => "STOPPED",
            Self::Sleeping => "SLEEPING",
        }
    }
}

impl From<CanState> for ControllerState {
    fn from(s: CanState) -> Self {
        match s {
            CanState::ErrorActive => Self::ErrorActive,
            CanState::ErrorWarning => Self::ErrorWarning,
            CanState::ErrorPassive => Self::ErrorPassive,
            CanState::BusOff => Self::BusOff,
            CanState::Stopped => Self::Stopped,
            CanState::Sleeping => Self::Sleeping,
        }
    }
}

/// What the kernel reports about a CAN interface.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LinkStatus {
    /// The interface name.
    pub iface: String,
    /// The interface is administratively up.
    pub up: bool,
    /// Nominal bitrate, bit/s; `None` for an interface without bit timing (a `vcan`).
    pub bitrate_bps: Option<u32>,
    /// The controller's error state; `None` where the driver reports none (a `vcan`).
    pub state: Option<ControllerState>,
    /// Automatic restart after bus-off, ms (0: none); `None` where the driver has no such setting.
    pub restart_ms: Option<u32>,
    /// The listen-only control mode is on: the controller neither transmits nor acknowledges.
    pub listen_only: bool,
}

impl LinkStatus {
    /// Reads the link of `iface` over netlink.
    ///
    /// # Errors
    /// [`Error::InterfaceNotFound`] when there is no such interface; [`Error::Io`] when the netlink
    /// query fails (no `AF_NETLINK`, e.g. a service without it in `RestrictAddressFamilies`).
    pub fn query(iface: &str) -> super::Result<Self> {
        const ENODEV: i32 = 19;
        let not_found = || Error::InterfaceNotFound {
            iface: iface.to_string(),
        };
        if iface.is_empty() || iface.len() >= 16 {
            return Err(not_found());
        }
        let io = |e: socketcan::Error| Error::Io {
            iface: iface.to_string(),
            source: std::io::Error::other(format!("reading the link over netlink: {e}")),
        };
        let link = match CanInterface::open(iface) {
            Ok(l) => l,
            Err(socketcan::Error::Io(e))
                if e.raw_os_error() == Some(ENODEV) || e.kind() == std::io::ErrorKind::NotFound =>
            {
                return Err(not_found());
            }
            Err(e) => return Err(io(e)),
        };
        let details = link.details().map_err(io)?;
        Ok(Self::from_details(iface, &details))
    }

    /// The status in `details` (a netlink answer about `iface`).
    #[must_use]
    pub fn from_details(iface: &str, details: &InterfaceDetails) -> Self {
        let can = &details.can;
        Self {
            iface: details.name.clone().unwrap_or_else(|| iface.to_string()),
            up: details.is_up,
            // A bit timing of 0 bit/s is what a CAN device reports before its bitrate is set.
            bitrate_bps: can
                .bit_timing
                .as_ref()
                .map(|t| t.bitrate)
                .filter(|b| *b > 0),
            state: can.state.map(ControllerState::from),
            restart_ms: can.restart_ms,
            listen_only: can
                .ctrl_mode
                .is_some_and(|m| m.has_mode(CanCtrlMode::ListenOnly)),
        }
    }

    /// Whether the interface is virtual (a `vcan`: no bit timing and no controller state), the bus
    /// of a simulated machine; a real CAN controller reports its state even before its bitrate is
    /// set.
    #[must_use]
    pub fn is_virtual(&self) -> bool {
        self.bitrate_bps.is_none() && self.state.is_none()
    }

    /// Whether a controller may start on this link: refused when it is down (or its device
    /// stopped), and when it is in listen-only mode unless `allow_listen_only` (the controller then
    /// never transmits).
    ///
    /// # Errors
    /// [`LinkRefusal`], whose text is one line with the command that fixes it.
    pub fn check(&self, allow_listen_only: bool) -> Result<(), LinkRefusal> {
        if !self.up || self.state == Some(ControllerState::Stopped) {
            return Err(LinkRefusal::Down {
                iface: self.iface.clone(),
            });
        }
        if self.listen_only && !allow_listen_only {
            return Err(LinkRefusal::ListenOnly {
                iface: self.iface.clone(),
            });
        }
        Ok(())
    }

    /// What deserves a warning though the link may be used: a bitrate other than the gateway's,
    /// bus-off or error-passive, no automatic restart after bus-off.
    #[must_use]
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(b) = self.bitrate_bps
            && b != GATEWAY_BITRATE_BPS
        {
            w.push(format!(
                "bitrate {b} bit/s, the gateway's is {GATEWAY_BITRATE_BPS}: expect no traffic and \
                 error frames"
            ));
        }
        if let Some(
            s @ (ControllerState::BusOff
            | ControllerState::ErrorPassive
            | ControllerState::ErrorWarning),
        ) = self.state
        {
            w.push(format!(
                "controller state {}: check wiring and termination",
                s.name()
            ));
        }
        if self.restart_ms == Some(0) {
            w.push(format!(
                "restart-ms 0: after bus-off the interface stays off until restarted by hand (ip \
                 link set {} type can restart-ms {RECOMMENDED_RESTART_MS})",
                self.iface
            ));
        }
        w
    }
}

/// One line: `can0 up, 500000 bit/s, ERROR-ACTIVE, restart-ms 100, listen-only off`.
impl fmt::Display for LinkStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const VIRTUAL: &str = "none (virtual interface)";
        write!(f, "{} {}, bitrate ", self.iface, updown(self.up))?;
        match self.bitrate_bps {
            Some(b) => write!(f, "{b} bit/s")?,
            None => f.write_str(VIRTUAL)?,
        }
        f.write_str(", state ")?;
        match self.state {
            Some(s) => f.write_str(s.name())?,
            None => f.write_str(VIRTUAL)?,
        }
        f.write_str(", restart-ms ")?;
        match self.restart_ms {
            Some(ms) => write!(f, "{ms}")?,
            None => f.write_str(VIRTUAL)?,
        }
        write!(
            f,
            ", listen-only {}",
            if self.listen_only { "on" } else { "off" }
        )
    }
}

fn updown(up: bool) -> &'static str {
    if up { "up" } else { "DOWN" }
}

/// Why a controller does not start on a link.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LinkRefusal {
    /// The interface is down: nothing can be sent or received.
    #[error(
        "CAN interface {iface} is down: bring it up first ({})",
        bring_up_advice(iface)
    )]
    Down {
        /// The interface.
        iface: String,
    },
    /// The interface is in listen-only mode: the controller's frames would never leave it.
    #[error(
        "CAN interface {iface} is in listen-only mode: run with --listen-only to monitor the bus \
         (never transmits, never arms), or switch the mode off (ip link set {iface} down && ip link \
         set {iface} type can listen-only off && ip link set {iface} up)"
    )]
    ListenOnly {
        /// The interface.
        iface: String,
    },
}

/// The commands that bring `iface` up: a virtual interface (a name starting with `vcan`) only needs
/// `up`; a real one is configured at the gateway's bitrate with automatic restart after bus-off.
#[must_use]
pub fn bring_up_advice(iface: &str) -> String {
    if iface.starts_with("vcan") {
        format!("ip link set {iface} up")
    } else {
        format!(
            "ip link set {iface} type can bitrate {GATEWAY_BITRATE_BPS} restart-ms \
             {RECOMMENDED_RESTART_MS} && ip link set {iface} up"
        )
    }
}

/// What to do about a missing `iface`: create a virtual one (a name starting with `vcan`), or check
/// the adapter and configure a real one.
#[must_use]
pub fn not_found_advice(iface: &str) -> String {
    if iface.starts_with("vcan") {
        format!("create it: ip link add dev {iface} type vcan && ip link set up {iface}")
    } else {
        format!(
            "check the adapter and its driver with `ip link show`, then configure it: {}",
            bring_up_advice(iface)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `can0` as `ip link set can0 type can bitrate 500000 restart-ms 100 && ip link set can0 up`
    /// leaves it.
    fn can0() -> LinkStatus {
        LinkStatus {
            iface: "can0".into(),
            up: true,
            bitrate_bps: Some(GATEWAY_BITRATE_BPS),
            state: Some(ControllerState::ErrorActive),
            restart_ms: Some(RECOMMENDED_RESTART_MS),
            listen_only: false,
        }
    }

    /// A vcan: up, and no CAN parameters at all.
    fn vcan0() -> LinkStatus {
        LinkStatus {
            iface: "vcan0".into(),
            up: true,
            bitrate_bps: None,
            state: None,
            restart_ms: None,
            listen_only: false,
        }
    }

    #[test]
    fn an_active_link_is_accepted_without_warnings() {
        assert_eq!(can0().check(false), Ok(()));
        assert!(can0().warnings().is_empty());
        assert_eq!(
            can0().to_string(),
            "can0 up, bitrate 500000 bit/s, state ERROR-ACTIVE, restart-ms 100, listen-only off"
        );
    }

    #[test]
    fn a_virtual_link_reports_no_bitrate() {
        assert_eq!(vcan0().check(false), Ok(()));
        assert!(vcan0().warnings().is_empty());
        let text = vcan0().to_string();
        assert!(text.contains("bitrate none (virtual interface)"), "{text}");
        assert!(!text.contains("bit/s"), "{text}");
    }

    #[test]
    fn a_down_or_stopped_link_is_refused_with_advice_for_its_kind() {
        let down = LinkStatus {
            up: false,
            ..can0()
        };
        let err = down.check(true).unwrap_err();
        assert_eq!(
            err,
            LinkRefusal::Down {
                iface: "can0".into()
            }
        );
        let text = err.to_string();
        assert!(
            text.contains("type can bitrate 500000 restart-ms 100") && !text.contains("vcan"),
            "{text}"
        );
        assert!(!text.contains('\n'));
        let stopped = LinkStatus {
            state: Some(ControllerState::Stopped),
            ..can0()
        };
        assert!(matches!(
            stopped.check(false),
            Err(LinkRefusal::Down { .. })
        ));
        let vdown = LinkStatus {
            up: false,
            ..vcan0()
        };
        let text = vdown.check(false).unwrap_err().to_string();
        assert!(
            text.ends_with("(ip link set vcan0 up)") && !text.contains("type can"),
            "{text}"
        );
    }

    #[test]
    fn listen_only_mode_needs_the_monitor_flag() {
        let lo = LinkStatus {
            listen_only: true,
            ..can0()
        };
        let err = lo.check(false).unwrap_err();
        assert!(matches!(err, LinkRefusal::ListenOnly { .. }));
        assert!(err.to_string().contains("--listen-only"), "{err}");
        assert_eq!(lo.check(true), Ok(()));
        assert!(lo.to_string().ends_with("listen-only on"));
    }

    #[test]
    fn wrong_bitrate_bus_off_and_no_restart_are_warned() {
        let bad = LinkStatus {
            bitrate_bps: Some(250_000),
            state: Some(ControllerState::BusOff),
            restart_ms: Some(0),
            ..can0()
        };
        assert_eq!(bad.check(false), Ok(()));
        let w = bad.warnings();
        assert_eq!(w.len(), 3, "{w:?}");
        assert!(w[0].contains("250000") && w[1].contains("BUS-OFF") && w[2].contains("restart-ms"));
    }

    #[test]
    fn netlink_details_are_parsed() {
        use socketcan::nl::{CanBitTiming, CanCtrlModes};
        let mut d = InterfaceDetails::new(3);
        d.name = Some("can0".into());
        d.is_up = true;
        d.can.bit_timing = Some(CanBitTiming {
            bitrate: 250_000,
            ..CanBitTiming::default()
        });
        d.can.state = Some(CanState::ErrorPassive);
        d.can.restart_ms = Some(100);
        d.can.ctrl_mode = Some(CanCtrlModes::from_mode(CanCtrlMode::ListenOnly, true));
        let s = LinkStatus::from_details("can0", &d);
        assert_eq!(s.bitrate_bps, Some(250_000));
        assert_eq!(s.state, Some(ControllerState::ErrorPassive));
        assert!(s.listen_only);
        // A vcan's answer: no link info.
        let v = LinkStatus::from_details("vcan0", &InterfaceDetails::new(4));
        assert_eq!(
            (v.bitrate_bps, v.state, v.restart_ms, v.listen_only),
            (None, None, None, false)
        );
    }

    #[test]
    fn a_missing_real_interface_gets_real_advice() {
        let can = Error::InterfaceNotFound {
            iface: "can0".into(),
        }
        .to_string();
        assert!(
            can.contains(
                "ip link set can0 type can bitrate 500000 restart-ms 100 && ip link set can0 up"
            ),
            "{can}"
        );
        assert!(!can.contains("vcan"), "{can}");
        let vcan = Error::InterfaceNotFound {
            iface: "vcan1".into(),
        }
        .to_string();
        assert!(vcan.contains("ip link add dev vcan1 type vcan"), "{vcan}");
    }

    #[test]
    fn querying_a_missing_interface_is_not_found() {
        // Netlink answers on any Linux kernel, with or without SocketCAN.
        match LinkStatus::query("nosuchcan0") {
            Err(Error::InterfaceNotFound { iface }) => assert_eq!(iface, "nosuchcan0"),
            other => panic!("{other:?}"),
        }
    }
}
