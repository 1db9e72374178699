//! J1939-73 DM1 (active diagnostic trouble codes, PGN 65226 `0xFECA`): the one table of the faults the
//! gateway and the controller report to a J1939 service tool, and the schedule that sends them.
//!
//! Every fault kind has a stated SPN in the proprietary range (520192..=524287, SAE J1939-73: for
//! manufacturer-specific parameters), a failure mode identifier (FMI) and the lamp it lights. The
//! gateway's entries are its fault bits ([`crate::messages::GatewayFaults`], index = bit); the
//! controller's are its fault codes (`controller::step::safety::Fault::code`, index = code - 1). The
//! code sends from these tables; the DBC's value tables of `DM1.SpnLow` / `DM1_Gateway.SpnLow` and the
//! table in `docs/protocol.md` are tied to them by tests (`firmware_bridge/tests/dm1_table.rs`).
//!
//! One DTC fits one 8-byte frame. With several faults active (the gateway's fault bits can be several
//! at once) the DM1 carries the most severe one ([`most_severe`]) and lamps lit for all of them; the
//! full set stays in `GatewayStatus.FaultBits`. J1939-21's TP.BAM, which would carry every DTC, is not
//! implemented: it needs a transport-protocol sender with its own timing in the `no_std` core and a
//! reassembler in every receiver, and a DBC decoder (cantools, SavvyCAN) cannot reassemble it anyway.
//!
//! [`Dm1Reporter`] sends a DM1 once per second ([`DM1_PERIOD`]) and at once when what it reports
//! changes, but not sooner than [`DM1_MIN_GAP`] after the previous one (J1939-73 asks for a limit on
//! the rate of change-triggered DM1s of a flickering fault); with no fault active it sends lamps off
//! and a DTC of all zeros (SPN 0, FMI 0, occurrence count 0), as J1939-73 specifies.

use crate::messages::{Dm1, Dtc, LampFlash, LampState, LampStatus, Lamps};
use crate::time::Instant;

/// DM1's PGN (J1939-73).
pub const DM1_PGN: u32 = 0xFECA;

/// The period of DM1 while nothing changes (J1939-73: once per second), the DBC's `GenMsgCycleTime`.
pub const DM1_PERIOD: core::time::Duration =
    core::time::Duration::from_millis(crate::dbc::dm1::MESSAGE.cycle_time_ms as u64);

/// The least time between two DM1s of one node: a change is sent at once unless the previous DM1 left
/// less than this before; then when this much has passed. Bounds a node's DM1 rate to 10 frames/s.
pub const DM1_MIN_GAP: core::time::Duration = core::time::Duration::from_millis(100);

/// First SPN of the proprietary range (J1939-73, manufacturer-specific parameters).
pub const PROPRIETARY_SPN_FIRST: u32 = 520_192;
/// Last SPN of the proprietary range.
pub const PROPRIETARY_SPN_LAST: u32 = 524_287;

/// The lamp a fault lights (J1939-73). The malfunction indicator (emission-related faults) and the
/// protect lamp (a non-electronic subsystem) are lit by none of the project's faults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Lamp {
    /// Red stop lamp: the machine stopped and stays stopped until someone acts (e-stop, a lost
    /// address, the gateway's clock, a latched controller fault).
    RedStop,
    /// Amber warning lamp: motion stopped (valves neutral) and the controller's arming handshake
    /// brings it back.
    AmberWarning,
}

/// One fault kind in DM1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DtcSpec {
    /// The fault's name: the gateway's fault bit constant in UpperCamelCase, or the controller's
    /// `Fault` variant. Also its name in the DBC's value table.
    pub name: &'static str,
    /// Suspect parameter number, in the proprietary range.
    pub spn: u32,
    /// Failure mode identifier (J1939-73: 0 data above the normal range, most severe; 2 data erratic
    /// or incorrect; 7 mechanical system not responding; 9 abnormal update rate; 12 bad intelligent
    /// device; 19 received network data in error; 31 condition exists).
    pub fmi: u8,
    /// The lamp it lights.
    pub lamp: Lamp,
}

const fn spec(name: &'static str, spn: u32, fmi: u8, lamp: Lamp) -> DtcSpec {
    DtcSpec {
        name,
        spn,
        fmi,
        lamp,
    }
}

use Lamp::{AmberWarning as Amber, RedStop as Red};

/// The gateway's DTCs (sent from `0x80`), index = the bit of [`crate::messages::GatewayFaults`].
pub const GATEWAY_DTCS: [DtcSpec; 11] = [
    spec("WatchdogTimeout", 520_192, 9, Amber),
    spec("BadChecksum", 520_193, 19, Amber),
    spec("BadAliveCounter", 520_194, 19, Amber),
    spec("StaleCommand", 520_195, 9, Amber),
    spec("EStop", 520_196, 31, Red),
    spec("BusError", 520_197, 12, Amber),
    spec("JointLimit", 520_198, 0, Amber),
    spec("SetpointOutOfRange", 520_199, 19, Amber),
    spec("ClockFault", 520_200, 2, Red),
    spec("AuthFailure", 520_201, 19, Amber),
    spec("AddressLost", 520_202, 31, Red),
];

/// The controller's DTCs (sent from `0x27`), index = its fault code - 1 (code 0 is healthy).
pub const CONTROLLER_DTCS: [DtcSpec; 15] = [
    spec("StaleSensor", 520_449, 9, Amber),
    spec("Decode", 520_450, 19, Amber),
    spec("UnexpectedFrame", 520_451, 19, Amber),
    spec("JointLimit", 520_452, 0, Amber),
    spec("EStop", 520_453, 31, Red),
    spec("GatewayFault", 520_454, 31, Amber),
    spec("GatewayMode", 520_455, 2, Amber),
    spec("ArmTimeout", 520_456, 7, Amber),
    spec("Bus", 520_457, 12, Amber),
    spec("Control", 520_458, 7, Amber),
    spec("Shutdown", 520_459, 31, Red),
    spec("GatewayFrozen", 520_460, 12, Amber),
    spec("AddressLost", 520_461, 31, Red),
    spec("AddressIntrusion", 520_462, 19, Red),
    spec("ImplausibleSensor", 520_463, 2, Red),
];

/// The entry of `table` to report among the `active` ones (bit i = entry i): the first that lights the
/// red stop lamp, else the first active one; `None` when none is active.
pub fn most_severe(table: &[DtcSpec], active: u32) -> Option<usize> {
    let is_active = |i: usize| i < 32 && active & (1 << i) != 0;
    let mut first = None;
    for (i, s) in table.iter().enumerate() {
        if !is_active(i) {
            continue;
        }
        if s.lamp == Lamp::RedStop {
            return Some(i);
        }
        first = first.or(Some(i));
    }
    first
}

/// Keeps the occurrence counts and sends DM1 on its schedule, for one node and its table of `N`
/// fault kinds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dm1Reporter<const N: usize> {
    table: &'static [DtcSpec; N],
    /// Times each kind became active (J1939-73's occurrence count: saturates at 126; 127 is "not
    /// available").
    occurrences: [u8; N],
    active: u32,
    last_sent: Option<(Instant, Dm1)>,
}

/// The largest occurrence count (127 is "not available").
pub const OCCURRENCE_COUNT_MAX: u8 = 126;

impl<const N: usize> Dm1Reporter<N> {
    /// A reporter for `table` (no fault seen yet).
    pub const fn new(table: &'static [DtcSpec; N]) -> Self {
        Self {
            table,
            occurrences: [0; N],
            active: 0,
            last_sent: None,
        }
    }

    /// The active set now (bit i = entry i; bits beyond the table are ignored): counts each kind that
    /// became active since the last call. Call it at every step, also while the node may not send.
    pub fn observe(&mut self, active: u32) {
        let mask = if N >= 32 { u32::MAX } else { (1u32 << N) - 1 };
        let active = active & mask;
        let rising = active & !self.active;
        for (i, count) in self.occurrences.iter_mut().enumerate() {
            if rising & (1 << i) != 0 {
                *count = count.saturating_add(1).min(OCCURRENCE_COUNT_MAX);
            }
        }
        self.active = active;
    }

    /// What DM1 reports now.
    pub fn current(&self) -> Dm1 {
        let lit = |lamp: Lamp| {
            let on = self
                .table
                .iter()
                .enumerate()
                .any(|(i, s)| s.lamp == lamp && self.active & (1 << i) != 0);
            LampState {
                status: if on { LampStatus::On } else { LampStatus::Off },
                flash: LampFlash::DoNotFlash,
            }
        };
        let off = LampState {
            status: LampStatus::Off,
            flash: LampFlash::DoNotFlash,
        };
        let dtc = most_severe(self.table, self.active)
            .and_then(|i| Some((self.table.get(i)?, *self.occurrences.get(i)?)))
            .map_or(Dtc::NONE, |(s, count)| Dtc {
                spn: s.spn,
                fmi: s.fmi,
                occurrence_count: count,
            });
        Dm1 {
            lamps: Lamps {
                malfunction_indicator: off,
                red_stop: lit(Lamp::RedStop),
                amber_warning: lit(Lamp::AmberWarning),
                protect: off,
            },
            dtc,
        }
    }

    /// The DM1 to send at `now`, if one is due: the first, one [`DM1_PERIOD`] after the last, or a
    /// changed one [`DM1_MIN_GAP`] after the last. Marks it sent.
    pub fn poll(&mut self, now: Instant) -> Option<Dm1> {
        let current = self.current();
        let due = match self.last_sent {
            None => true,
            Some((at, sent)) => {
                let since = now.nanos_since(at);
                let period = DM1_PERIOD.as_nanos() as i64;
                let gap = DM1_MIN_GAP.as_nanos() as i64;
                // A clock that went backwards sends at once: the schedule restarts from now.
                since < 0 || since >= period || (sent != current && since >= gap)
            }
        };
        due.then(|| {
            self.last_sent = Some((now, current));
            current
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spns_are_proprietary_distinct_and_fmis_fit_five_bits() {
        let all = GATEWAY_DTCS.iter().chain(CONTROLLER_DTCS.iter());
        let mut spns = std::vec::Vec::new();
        for s in all {
            assert!(
                (PROPRIETARY_SPN_FIRST..=PROPRIETARY_SPN_LAST).contains(&s.spn),
                "{}",
                s.name
            );
            assert!(s.fmi <= 31, "{}", s.name);
            assert!(!spns.contains(&s.spn), "{} repeats an SPN", s.name);
            spns.push(s.spn);
        }
    }

    #[test]
    fn red_stop_faults_win_and_lamps_light_for_every_active_fault() {
        let mut r = Dm1Reporter::new(&GATEWAY_DTCS);
        // Watchdog (bit 0, amber) and e-stop (bit 4, red).
        r.observe(1 | 1 << 4);
        let dm1 = r.current();
        assert_eq!(dm1.dtc.spn, GATEWAY_DTCS[4].spn);
        assert_eq!(dm1.lamps.red_stop.status, LampStatus::On);
        assert_eq!(dm1.lamps.amber_warning.status, LampStatus::On);
        assert_eq!(dm1.lamps.malfunction_indicator.status, LampStatus::Off);
        r.observe(1);
        assert_eq!(r.current().dtc.spn, GATEWAY_DTCS[0].spn);
        assert_eq!(r.current().lamps.red_stop.status, LampStatus::Off);
    }

    #[test]
    fn no_fault_is_lamps_off_and_an_all_zero_dtc() {
        let mut r = Dm1Reporter::new(&CONTROLLER_DTCS);
        let dm1 = r.poll(Instant::ZERO).expect("the first DM1 is due at once");
        assert_eq!(dm1.dtc, Dtc::NONE);
        assert_eq!(
            (Dtc::NONE.spn, Dtc::NONE.fmi, Dtc::NONE.occurrence_count),
            (0, 0, 0)
        );
        assert_eq!(dm1.lamps.red_stop.status, LampStatus::Off);
        assert_eq!(dm1.lamps.amber_warning.status, LampStatus::Off);
    }

    #[test]
    fn sent_once_per_second_and_on_a_change_at_most_every_100_ms() {
        let mut r = Dm1Reporter::new(&GATEWAY_DTCS);
        let ms = Instant::from_millis;
        assert!(r.poll(ms(0)).is_some());
        assert!(r.poll(ms(999)).is_none());
        assert!(r.poll(ms(1000)).is_some());
        // A change 50 ms later waits for the 100 ms gap, then goes out.
        r.observe(1 << 3);
        assert!(r.poll(ms(1050)).is_none());
        let dm1 = r.poll(ms(1100)).expect("the change is sent after the gap");
        assert_eq!(dm1.dtc.spn, GATEWAY_DTCS[3].spn);
        assert_eq!(dm1.dtc.occurrence_count, 1);
        // Nothing changed: the next one a second later.
        assert!(r.poll(ms(2099)).is_none());
        assert!(r.poll(ms(2100)).is_some());
    }

    #[test]
    fn occurrence_counts_rising_edges_and_saturate() {
        let mut r = Dm1Reporter::new(&CONTROLLER_DTCS);
        for _ in 0..200 {
            r.observe(1);
            r.observe(1);
            r.observe(0);
        }
        r.observe(1);
        assert_eq!(r.current().dtc.occurrence_count, OCCURRENCE_COUNT_MAX);
    }
}
