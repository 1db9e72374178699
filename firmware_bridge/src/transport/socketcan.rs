//! SocketCAN transport through the `socketcan` crate's tokio socket.
//!
//! Classic CAN only (the protocol is classic CAN at 500 kbit/s): CAN FD and error frames cannot be
//! sent. Error frames are enabled on the socket and come back from `recv` as [`Error::Fault`].
//! Received frames carry the kernel's receive timestamp (`SO_TIMESTAMPNS`, wall clock since the Unix
//! epoch), asked for when the socket opens; where the kernel refuses the option or a frame comes
//! without one, the wall clock when the frame was read ([`TraceClock`]).

use std::future::Future;
use std::io;
use std::time::Duration;

use socketcan::{EmbeddedFrame, ExtendedId, Frame as _, SocketOptions, StandardId};

use super::clock::wall_now_ns;
use super::{Bus, BusFault, Error, Result, TimestampedFrame, TraceClock};
use crate::frame::{CAN_MAX_LEN, CanFrame, CanId};
use crate::trace::{Direction, Recorder};

/// `CAN_EFF_FLAG`: set in filter ids and masks to match only extended frames.
const CAN_EFF_FLAG: u32 = 0x8000_0000;

/// A receive filter: a frame passes if `frame_id & mask == id & mask` and its id kind matches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IdFilter {
    /// Id to match.
    pub id: u32,
    /// Bits of the id that must match.
    pub mask: u32,
    /// Match 29-bit ids (true) or 11-bit ids (false).
    pub extended: bool,
}

impl IdFilter {
    /// Frames from one J1939 source address (any PGN, any priority).
    pub const fn from_source_address(source_address: u8) -> Self {
        Self {
            id: source_address as u32,
            mask: 0xFF,
            extended: true,
        }
    }

    fn to_socketcan(self) -> socketcan::CanFilter {
        if self.extended {
            socketcan::CanFilter::new(self.id | CAN_EFF_FLAG, self.mask | CAN_EFF_FLAG)
        } else {
            socketcan::CanFilter::new(self.id, self.mask | CAN_EFF_FLAG)
        }
    }
}

/// How long a send waits when the kernel transmit queue is full (`ENOBUFS`): it retries with a
/// doubling delay up to `max_attempts` times, then returns [`Error::TxQueueFull`]. Frames are never
/// dropped silently.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SendRetry {
    /// Attempts in total, including the first.
    pub max_attempts: u32,
    /// Delay after the first failed attempt; doubled after each further one.
    pub first_delay: Duration,
    /// Upper bound of one delay.
    pub max_delay: Duration,
}

impl Default for SendRetry {
    /// 8 attempts, 100 us doubling to 2 ms: about 8 ms in total, under one 10 ms control period.
    fn default() -> Self {
        Self {
            max_attempts: 8,
            first_delay: Duration::from_micros(100),
            max_delay: Duration::from_millis(2),
        }
    }
}

fn is_enobufs(e: &io::Error) -> bool {
    e.raw_os_error() == Some(libc_enobufs())
}

/// `ENOBUFS` on Linux (the only platform with SocketCAN).
const fn libc_enobufs() -> i32 {
    105
}

/// Runs `attempt` until it succeeds, retrying only on `ENOBUFS` with the delays of `policy`.
///
/// # Errors
/// [`Error::TxQueueFull`] when every attempt hit `ENOBUFS`; [`Error::Io`] for other errors.
pub async fn send_with_retry<F, Fut>(iface: &str, policy: SendRetry, mut attempt: F) -> Result<()>
where
    F: FnMut() -> Fut,
    Fut: Future<Output = io::Result<()>>,
{
    let mut delay = policy.first_delay;
    let attempts = policy.max_attempts.max(1);
    for n in 1..=attempts {
        match attempt().await {
            Ok(()) => return Ok(()),
            Err(e) if is_enobufs(&e) => {
                if n == attempts {
                    break;
                }
                tracing::debug!(iface, attempt = n, "CAN transmit queue full, retrying");
                tokio::time::sleep(delay).await;
                delay = (delay * 2).min(policy.max_delay);
            }
            Err(source) => {
                return Err(Error::Io {
                    iface: iface.to_string(),
                    source,
                });
            }
        }
    }
    Err(Error::TxQueueFull { attempts })
}

/// A SocketCAN interface (`vcan0`, `can0`).
#[derive(Debug)]
pub struct SocketCanBus {
    socket: socketcan::tokio::CanSocket,
    iface: String,
    retry: SendRetry,
    recorder: Option<Recorder>,
    /// The kernel accepted `SO_TIMESTAMPNS`.
    kernel_stamps: bool,
}

/// Whether the kernel can make `AF_CAN` sockets at all: a raw CAN socket bound to every interface
/// (index 0), closed at once.
fn af_can_available() -> io::Result<()> {
    use socketcan::Socket as _;
    socketcan::CanSocket::open_iface(0).map(drop)
}

fn map_open_error(iface: &str, e: io::Error) -> Error {
    classify_open_error(iface, e, af_can_available)
}

/// The error of opening `iface`. The interface's name is looked up before any CAN socket is made,
/// so on a kernel without SocketCAN the lookup fails first (`ENODEV`): then `af_can` tells a
/// missing interface from a missing protocol.
fn classify_open_error(
    iface: &str,
    e: io::Error,
    af_can: impl FnOnce() -> io::Result<()>,
) -> Error {
    const ENODEV: i32 = 19;
    const EAFNOSUPPORT: i32 = 97;
    let not_found = e.raw_os_error() == Some(ENODEV) || e.kind() == io::ErrorKind::NotFound;
    match e.raw_os_error() {
        Some(EAFNOSUPPORT) => Error::NoSocketCan(e),
        _ if not_found => match af_can() {
            Err(probe) if probe.raw_os_error() == Some(EAFNOSUPPORT) => Error::NoSocketCan(probe),
            _ => Error::InterfaceNotFound {
                iface: iface.to_string(),
            },
        },
        _ => Error::Io {
            iface: iface.to_string(),
            source: e,
        },
    }
}

impl SocketCanBus {
    /// Opens `iface` receiving every frame, with error frames enabled.
    ///
    /// # Errors
    /// [`Error::InterfaceNotFound`], [`Error::NoSocketCan`] or [`Error::Io`].
    pub fn open(iface: &str) -> Result<Self> {
        Self::open_with_filters(iface, &[])
    }

    /// Opens `iface` receiving only frames that pass one of `filters` (all frames if empty); error
    /// frames are always enabled.
    ///
    /// # Errors
    /// As [`SocketCanBus::open`].
    pub fn open_with_filters(iface: &str, filters: &[IdFilter]) -> Result<Self> {
        // Check the name first: a missing interface is the common mistake and deserves a clear error,
        // whichever errno the socket layer would give.
        if iface.is_empty() || iface.len() >= 16 {
            return Err(Error::InterfaceNotFound {
                iface: iface.to_string(),
            });
        }
        let socket =
            socketcan::tokio::CanSocket::open(iface).map_err(|e| map_open_error(iface, e))?;
        let io_err = |source| Error::Io {
            iface: iface.to_string(),
            source,
        };
        if !filters.is_empty() {
            let f: Vec<socketcan::CanFilter> = filters.iter().map(|f| f.to_socketcan()).collect();
            socket.set_filters(&f).map_err(io_err)?;
        }
        socket.set_error_filter_accept_all().map_err(io_err)?;
        // The kernel's receive time: a frame's age then includes the time it waited in the socket.
        let kernel_stamps = match socket.set_recv_timestamp(true) {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(
                    iface,
                    error = %e,
                    "no kernel receive timestamps (SO_TIMESTAMPNS): frames are stamped when read"
                );
                false
            }
        };
        Ok(Self {
            socket,
            iface: iface.to_string(),
            retry: SendRetry::default(),
            recorder: None,
            kernel_stamps,
        })
    }

    /// Sets the `ENOBUFS` retry policy.
    pub fn set_send_retry(&mut self, retry: SendRetry) {
        self.retry = retry;
    }

    /// Records every frame sent (` T`) and received (` R`) to `recorder`.
    pub fn set_recorder(&mut self, recorder: Recorder) {
        self.recorder = Some(recorder);
    }
}

/// Converts to the `socketcan` crate's frame for sending.
///
/// # Errors
/// [`Error::Unsupported`] for error and CAN FD frames.
pub(crate) fn to_socketcan(frame: &CanFrame) -> Result<socketcan::CanFrame> {
    let id: socketcan::Id = match frame.id() {
        CanId::Standard(id) => StandardId::new(id).map(Into::into),
        CanId::Extended(id) => ExtendedId::new(id).map(Into::into),
    }
    .ok_or(Error::Unsupported("identifier out of range"))?;
    let out = if frame.is_error() {
        return Err(Error::Unsupported("error frames cannot be sent"));
    } else if frame.is_fd() {
        return Err(Error::Unsupported(
            "CAN FD frames cannot be sent on a classic CAN socket",
        ));
    } else if frame.is_remote() {
        socketcan::CanFrame::new_remote(id, frame.dlc())
    } else {
        socketcan::CanFrame::new(id, frame.data())
    };
    out.ok_or(Error::Unsupported("frame does not fit a classic CAN frame"))
}

/// Converts a received `socketcan` frame; error frames become [`Error::Fault`].
pub(crate) fn from_socketcan(frame: &socketcan::CanFrame) -> Result<CanFrame> {
    let id = if frame.is_extended() {
        CanId::Extended(frame.raw_id())
    } else {
        // The raw id of a standard frame is masked to 11 bits.
        CanId::Standard((frame.raw_id() & 0x7FF) as u16)
    };
    let bad = |_| Error::Unsupported("received frame out of range");
    match frame {
        socketcan::CanFrame::Error(e) => {
            let mut details = [0u8; CAN_MAX_LEN];
            let n = e.data().len().min(CAN_MAX_LEN);
            details[..n].copy_from_slice(&e.data()[..n]);
            let ours = CanFrame::new_error(e.error_bits(), details).map_err(bad)?;
            Err(Error::Fault(
                BusFault::from_error_frame(&ours).unwrap_or(BusFault::Other(0)),
            ))
        }
        socketcan::CanFrame::Remote(r) => {
            CanFrame::new_remote(id, r.dlc().min(CAN_MAX_LEN) as u8).map_err(bad)
        }
        socketcan::CanFrame::Data(d) => CanFrame::new_data(id, d.data()).map_err(bad),
    }
}

impl Bus for SocketCanBus {
    async fn send(&self, frame: CanFrame) -> Result<()> {
        let out = to_socketcan(&frame)?;
        send_with_retry(&self.iface, self.retry, || self.socket.write_frame(out)).await?;
        if let Some(rec) = &self.recorder {
            rec.record(wall_now_ns(), Direction::Transmit, &frame);
        }
        Ok(())
    }

    async fn recv(&self) -> Result<TimestampedFrame> {
        let (raw, stamps) = self
            .socket
            .read_frame_with_timestamps()
            .await
            .map_err(|source| Error::Io {
                iface: self.iface.clone(),
                source,
            })?;
        let timestamp_ns = stamps
            .socket
            .and_then(|t| epoch_ns(t).ok())
            .unwrap_or_else(wall_now_ns);
        if let (Some(rec), socketcan::CanFrame::Error(e)) = (&self.recorder, &raw) {
            let mut details = [0u8; CAN_MAX_LEN];
            let n = e.data().len().min(CAN_MAX_LEN);
            details[..n].copy_from_slice(&e.data()[..n]);
            if let Ok(f) = CanFrame::new_error(e.error_bits(), details) {
                rec.record(timestamp_ns, Direction::Receive, &f);
            }
        }
        let frame = from_socketcan(&raw)?;
        if let Some(rec) = &self.recorder {
            rec.record(timestamp_ns, Direction::Receive, &frame);
        }
        Ok(TimestampedFrame {
            timestamp_ns,
            frame,
        })
    }

    fn now_ns(&self) -> u64 {
        wall_now_ns()
    }

    fn interface(&self) -> &str {
        &self.iface
    }

    fn trace_clock(&self) -> TraceClock {
        if self.kernel_stamps {
            TraceClock::Kernel
        } else {
            TraceClock::WallAtRead
        }
    }
}

/// Nanoseconds since the Unix epoch of a kernel timestamp.
fn epoch_ns(t: std::time::SystemTime) -> std::result::Result<u64, std::time::SystemTimeError> {
    t.duration_since(std::time::UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opening_a_missing_interface_is_a_clear_error() {
        let err = SocketCanBus::open("nosuchcan0").unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, Error::InterfaceNotFound { .. } | Error::NoSocketCan(_)),
            "unexpected error: {text}"
        );
        assert!(
            text.contains("nosuchcan0") || text.contains("SocketCAN is not available"),
            "{text}"
        );
    }

    /// The no-SocketCAN message existed but was never reached: the interface's name is looked up
    /// first and fails with ENODEV on such a kernel, which gave the vcan advice instead.
    #[test]
    fn a_kernel_without_af_can_gets_the_no_socketcan_message() {
        let enodev = || io::Error::from_raw_os_error(19);
        let no_af_can = || Err(io::Error::from_raw_os_error(97));
        let err = classify_open_error("vcan0", enodev(), no_af_can);
        assert_eq!(
            err.to_string(),
            "SocketCAN is not available in this kernel (Address family not supported by protocol \
             (os error 97)): load its modules (`modprobe can_raw vcan`), or run the vcan tests in \
             scripts/test-all's VM"
        );
        let with_af_can = || Ok(());
        assert!(matches!(
            classify_open_error("vcan0", enodev(), with_af_can),
            Error::InterfaceNotFound { .. }
        ));
        // What this kernel says, whichever it is.
        let probe = af_can_available();
        let err = SocketCanBus::open("nosuchcan0").unwrap_err();
        match probe {
            Err(e) if e.raw_os_error() == Some(97) => {
                assert!(matches!(err, Error::NoSocketCan(_)), "{err}");
            }
            _ => assert!(matches!(err, Error::InterfaceNotFound { .. }), "{err}"),
        }
    }

    #[test]
    fn frames_convert_both_ways() {
        let ours = CanFrame::new_extended(0x0CFE_3027, &[1, 2, 3]).unwrap();
        assert_eq!(from_socketcan(&to_socketcan(&ours).unwrap()).unwrap(), ours);
        let std = CanFrame::new_standard(0x123, &[]).unwrap();
        assert_eq!(from_socketcan(&to_socketcan(&std).unwrap()).unwrap(), std);
        let rtr = CanFrame::new_remote(CanId::Extended(0x0CFE_3027), 8).unwrap();
        assert_eq!(from_socketcan(&to_socketcan(&rtr).unwrap()).unwrap(), rtr);
        let fd = CanFrame::new_fd(CanId::Standard(1), &[0; 12], 0).unwrap();
        assert!(matches!(to_socketcan(&fd), Err(Error::Unsupported(_))));
    }

    #[test]
    fn received_error_frames_become_faults() {
        let raw = socketcan::CanErrorFrame::new_error(0x40, &[0; 8]).unwrap();
        let got = from_socketcan(&socketcan::CanFrame::Error(raw));
        assert!(matches!(got, Err(Error::Fault(BusFault::BusOff))));
    }

    #[tokio::test(start_paused = true)]
    async fn enobufs_is_retried_then_reported() {
        let calls = std::cell::Cell::new(0u32);
        let policy = SendRetry::default();
        let ok_on_third = send_with_retry("vcan0", policy, || {
            calls.set(calls.get() + 1);
            let n = calls.get();
            async move {
                if n < 3 {
                    Err(io::Error::from_raw_os_error(105))
                } else {
                    Ok(())
                }
            }
        })
        .await;
        assert!(ok_on_third.is_ok());
        assert_eq!(calls.get(), 3);

        let always_full = send_with_retry("vcan0", policy, || async {
            Err(io::Error::from_raw_os_error(105))
        })
        .await;
        assert!(matches!(
            always_full,
            Err(Error::TxQueueFull { attempts: 8 })
        ));

        let other = send_with_retry("vcan0", policy, || async {
            Err(io::Error::from_raw_os_error(100))
        })
        .await;
        assert!(matches!(other, Err(Error::Io { .. })));
    }
}
