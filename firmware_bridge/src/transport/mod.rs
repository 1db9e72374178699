//! How frames travel: the async [`Bus`] trait and its implementations.
//!
//! - [`SocketCanBus`]: a Linux SocketCAN interface (`vcan0`, `can0`) through the `socketcan` crate's
//!   tokio socket. Timestamps are wall-clock nanoseconds since the Unix epoch: the kernel's receive
//!   timestamp (`SO_TIMESTAMPNS`) where the socket delivers one, else the time the frame was read
//!   ([`TraceClock`]).
//! - [`InProcessBus`]: a broadcast medium inside one process with the same semantics (every attached
//!   node sees every frame the others send, in order, never its own), timestamped from a [`Clock`] that
//!   is either the wall clock or a [`VirtualClock`] set by the simulation. Besides the async [`Bus`]
//!   methods it has a synchronous `send`/`try_recv` path for single-threaded virtual-time loops, and
//!   optional fault injection ([`FaultInjection`]: latency in clock time, seeded loss).
//!
//! - [`ProfileBus`]: any bus speaking a machine profile's wire protocol ([`crate::profile`]), seen
//!   by the node above as the canonical protocol.
//!
//! - [`link`]: the interface's link over netlink (up, bitrate, state, `restart-ms`, listen-only) and
//!   whether a controller may start on it.
//!
//! Error frames received from the controller driver surface as [`Error::Fault`] with a [`BusFault`];
//! they do not break the bus, so the caller decides (neutral valves) and keeps calling `recv`.

mod clock;
mod in_process;
pub mod link;
mod profile_bus;
mod socketcan;
mod trace_clock;

pub use clock::{Clock, TimeScale, TimeScaleError, VirtualClock};
pub use in_process::{FaultInjection, InProcessBus, InProcessNode};
pub use link::{ControllerState, LinkRefusal, LinkStatus};
pub use profile_bus::{ProfileBus, ProfileLink, ProfileStats};
pub use socketcan::{IdFilter, SendRetry, SocketCanBus, send_with_retry};
pub use trace_clock::{TraceClock, TraceTimeBase, VIRTUAL_EPOCH_UNIX_NS};

use std::future::Future;

use crate::frame::{CAN_MAX_LEN, CanFrame};

/// A received (or sent) frame with the bus clock's time, nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimestampedFrame {
    /// Time in nanoseconds: since the Unix epoch for the wall clock, since simulation start for a
    /// [`VirtualClock`].
    pub timestamp_ns: u64,
    /// The frame.
    pub frame: CanFrame,
}

impl TimestampedFrame {
    /// The timestamp in seconds.
    pub fn time_s(&self) -> f64 {
        self.timestamp_ns as f64 * 1e-9
    }
}

/// A bus condition reported by an error frame (Linux `linux/can/error.h`), most severe first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BusFault {
    /// The controller went bus-off: it no longer sends or receives until restarted.
    BusOff,
    /// Error counters above 127: the node is error passive.
    ErrorPassive,
    /// No node acknowledged a transmitted frame (nobody else on the bus, or wiring).
    NoAck,
    /// Transmission timed out.
    TxTimeout,
    /// A receive or transmit buffer overflowed in the controller.
    Overflow,
    /// A protocol violation (stuff, form, bit or CRC error).
    ProtocolViolation,
    /// A transceiver (wiring) fault.
    Transceiver,
    /// Error counters above 95: warning level.
    ErrorWarning,
    /// Arbitration was lost (normally harmless; reported only if enabled).
    ArbitrationLost,
    /// The controller restarted after bus-off.
    Restarted,
    /// The controller is back to error active.
    ErrorActive,
    /// Any other error class bits.
    Other(u32),
}

/// Linux error class bits and controller detail bits (`linux/can/error.h`).
mod err_bits {
    pub const TX_TIMEOUT: u32 = 0x001;
    pub const LOSTARB: u32 = 0x002;
    pub const CRTL: u32 = 0x004;
    pub const PROT: u32 = 0x008;
    pub const TRX: u32 = 0x010;
    pub const ACK: u32 = 0x020;
    pub const BUSOFF: u32 = 0x040;
    pub const BUSERROR: u32 = 0x080;
    pub const RESTARTED: u32 = 0x100;
    pub const CRTL_RX_OVERFLOW: u8 = 0x01;
    pub const CRTL_TX_OVERFLOW: u8 = 0x02;
    pub const CRTL_RX_WARNING: u8 = 0x04;
    pub const CRTL_TX_WARNING: u8 = 0x08;
    pub const CRTL_RX_PASSIVE: u8 = 0x10;
    pub const CRTL_TX_PASSIVE: u8 = 0x20;
    pub const CRTL_ACTIVE: u8 = 0x40;
}

impl BusFault {
    /// The most severe condition an error frame reports; `None` if `frame` is not an error frame.
    pub fn from_error_frame(frame: &CanFrame) -> Option<Self> {
        if !frame.is_error() {
            return None;
        }
        let mut details = [0u8; CAN_MAX_LEN];
        let data = frame.data();
        let n = data.len().min(CAN_MAX_LEN);
        details[..n].copy_from_slice(&data[..n]);
        Some(Self::from_error_class(frame.error_class(), details))
    }

    /// Maps Linux error class bits and detail bytes to the most severe [`BusFault`].
    pub fn from_error_class(class: u32, details: [u8; CAN_MAX_LEN]) -> Self {
        use err_bits::*;
        let ctrl = if class & CRTL != 0 { details[1] } else { 0 };
        if class & BUSOFF != 0 {
            Self::BusOff
        } else if ctrl & (CRTL_RX_PASSIVE | CRTL_TX_PASSIVE) != 0 {
            Self::ErrorPassive
        } else if class & ACK != 0 {
            Self::NoAck
        } else if class & TX_TIMEOUT != 0 {
            Self::TxTimeout
        } else if ctrl & (CRTL_RX_OVERFLOW | CRTL_TX_OVERFLOW) != 0 {
            Self::Overflow
        } else if class & (PROT | BUSERROR) != 0 {
            Self::ProtocolViolation
        } else if class & TRX != 0 {
            Self::Transceiver
        } else if ctrl & (CRTL_RX_WARNING | CRTL_TX_WARNING) != 0 {
            Self::ErrorWarning
        } else if class & LOSTARB != 0 {
            Self::ArbitrationLost
        } else if class & RESTARTED != 0 {
            Self::Restarted
        } else if ctrl & CRTL_ACTIVE != 0 {
            Self::ErrorActive
        } else {
            Self::Other(class)
        }
    }
}

/// Transport errors.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The bus reported a fault with an error frame. Not fatal: keep calling `recv`.
    #[error("bus fault: {0:?}")]
    Fault(BusFault),
    /// The interface does not exist.
    #[error(
        "CAN interface {iface:?} not found ({})",
        link::not_found_advice(iface)
    )]
    InterfaceNotFound {
        /// Interface name.
        iface: String,
    },
    /// The kernel has no SocketCAN support (no `AF_CAN`).
    #[error(
        "SocketCAN is not available in this kernel ({0}): load its modules (`modprobe can_raw \
         vcan`), or run the vcan tests in scripts/test-all's VM"
    )]
    NoSocketCan(std::io::Error),
    /// The transmit queue stayed full (`ENOBUFS`) for every retry.
    #[error("transmit queue full (ENOBUFS) after {attempts} attempts")]
    TxQueueFull {
        /// Attempts made.
        attempts: u32,
    },
    /// The frame cannot be sent on this transport (error frames; CAN FD on a classic socket).
    #[error("cannot send this frame: {0}")]
    Unsupported(&'static str),
    /// Any other I/O error.
    #[error("CAN I/O error on {iface:?}: {source}")]
    Io {
        /// Interface name.
        iface: String,
        /// The OS error.
        source: std::io::Error,
    },
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, Error>;

/// A CAN bus as a node sees it.
///
/// Both methods take `&self` so one task can `select!` between sending and receiving. `recv` yields
/// frames sent by others, never the node's own; an error frame yields `Err(Error::Fault(..))` and the
/// next call continues with the next frame.
pub trait Bus: Send + Sync {
    /// Sends a frame.
    ///
    /// # Errors
    /// [`Error`] if the frame cannot be sent (I/O error, queue full after retries, unsupported kind).
    fn send(&self, frame: CanFrame) -> impl Future<Output = Result<()>> + Send;

    /// Waits for the next frame from another node.
    ///
    /// # Errors
    /// [`Error::Fault`] for an error frame, [`Error::Io`] for a socket error.
    fn recv(&self) -> impl Future<Output = Result<TimestampedFrame>> + Send;

    /// The bus clock's current time, nanoseconds (the time base of received timestamps).
    fn now_ns(&self) -> u64;

    /// The interface name used in traces (`vcan0`, `can0`, or the in-process bus's name).
    fn interface(&self) -> &str;

    /// What stamps the received frames (recorded with a session so a reader knows what the trace's
    /// timestamps mean).
    fn trace_clock(&self) -> TraceClock;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_frames_map_to_the_most_severe_fault() {
        let busoff = CanFrame::new_error(0x40 | 0x04, [0, 0x20, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(BusFault::from_error_frame(&busoff), Some(BusFault::BusOff));
        let passive = CanFrame::new_error(0x04, [0, 0x10, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(
            BusFault::from_error_frame(&passive),
            Some(BusFault::ErrorPassive)
        );
        let noack = CanFrame::new_error(0x20, [0; 8]).unwrap();
        assert_eq!(BusFault::from_error_frame(&noack), Some(BusFault::NoAck));
        let warning = CanFrame::new_error(0x04, [0, 0x08, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(
            BusFault::from_error_frame(&warning),
            Some(BusFault::ErrorWarning)
        );
        let other = CanFrame::new_error(0x200, [0; 8]).unwrap();
        assert_eq!(
            BusFault::from_error_frame(&other),
            Some(BusFault::Other(0x200))
        );
        let data = CanFrame::new_standard(1, &[]).unwrap();
        assert_eq!(BusFault::from_error_frame(&data), None);
    }
}
