//! A CAN frame value type: classic data, remote (RTR), error and CAN FD frames.
//!
//! [`CanFrame`] is `Copy`, holds at most 64 data bytes inline and never allocates, so it can move through
//! the control path, channels and queues freely. It is independent of any socket: the SocketCAN transport
//! converts to and from the `socketcan` crate's frames at the edge; a microcontroller's driver through
//! the [`embedded_can::Frame`] trait, which [`CanFrame`] implements ([`CanFrame::from_frame`] takes any
//! driver's frame).

use core::fmt;

/// Largest payload of a classic CAN frame.
pub const CAN_MAX_LEN: usize = 8;
/// Largest payload of a CAN FD frame.
pub const CANFD_MAX_LEN: usize = 64;
/// Largest 11-bit identifier.
pub const MAX_STANDARD_ID: u16 = 0x7FF;
/// Error-frame flag in a Linux `can_id`; the candump text format shows it in the 8 hex digits.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// Mask of the error class bits of an error frame.
pub const CAN_ERR_MASK: u32 = 0x1FFF_FFFF;
/// CAN FD flag: bit rate switch.
pub const CANFD_BRS: u8 = 0x01;
/// CAN FD flag: error state indicator.
pub const CANFD_ESI: u8 = 0x02;

/// Errors building a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Standard id above 0x7FF.
    #[error("standard id {0:#x} does not fit 11 bits")]
    StandardIdTooLarge(u32),
    /// Extended id above 0x1FFFFFFF.
    #[error("extended id {0:#x} does not fit 29 bits")]
    ExtendedIdTooLarge(u32),
    /// More data than the frame type can carry, or an invalid CAN FD length.
    #[error("{len} data bytes are not valid for this frame type")]
    BadLength {
        /// The offending length.
        len: usize,
    },
}

/// Result alias for this module.
pub type Result<T> = core::result::Result<T, FrameError>;

/// A CAN identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CanId {
    /// 11-bit identifier.
    Standard(u16),
    /// 29-bit identifier.
    Extended(u32),
}

/// As CAN tools print ids: hex, 8 digits for a 29-bit id (`0x0CFF1234`), 3 for an 11-bit one
/// (`0x123`).
impl core::fmt::Display for CanId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Standard(id) => write!(f, "0x{id:03X}"),
            Self::Extended(id) => write!(f, "0x{id:08X}"),
        }
    }
}

impl CanId {
    /// An 11-bit id.
    ///
    /// # Errors
    /// [`FrameError::StandardIdTooLarge`] above 0x7FF.
    pub const fn standard(id: u16) -> Result<Self> {
        if id > MAX_STANDARD_ID {
            return Err(FrameError::StandardIdTooLarge(id as u32));
        }
        Ok(Self::Standard(id))
    }

    /// A 29-bit id.
    ///
    /// # Errors
    /// [`FrameError::ExtendedIdTooLarge`] above 0x1FFFFFFF.
    pub const fn extended(id: u32) -> Result<Self> {
        if id > CAN_ERR_MASK {
            return Err(FrameError::ExtendedIdTooLarge(id));
        }
        Ok(Self::Extended(id))
    }

    /// The numeric id without flags.
    pub const fn raw(self) -> u32 {
        match self {
            Self::Standard(id) => id as u32,
            Self::Extended(id) => id,
        }
    }

    /// True for a 29-bit id.
    pub const fn is_extended(self) -> bool {
        matches!(self, Self::Extended(_))
    }
}

/// What kind of frame this is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FrameKind {
    /// Classic CAN data frame (0..=8 bytes).
    Data,
    /// Remote transmission request; carries a requested length but no data.
    Remote,
    /// An error frame reported by the controller driver (Linux `CAN_ERR_FLAG`); the id is the error class
    /// bits and the 8 data bytes are the details (see `linux/can/error.h`).
    Error,
    /// CAN FD data frame with its flags ([`CANFD_BRS`], [`CANFD_ESI`]).
    Fd {
        /// CAN FD flags byte.
        flags: u8,
    },
}

/// A CAN frame of any kind, held by value.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: CanId,
    kind: FrameKind,
    len: u8,
    data: [u8; CANFD_MAX_LEN],
}

/// The valid CAN FD payload lengths.
pub const CANFD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

impl CanFrame {
    fn with(id: CanId, kind: FrameKind, data: &[u8]) -> Self {
        let mut buf = [0u8; CANFD_MAX_LEN];
        buf[..data.len()].copy_from_slice(data);
        Self {
            id,
            kind,
            len: data.len() as u8,
            data: buf,
        }
    }

    /// A classic data frame with a 29-bit id, the kind every J1939 message uses.
    ///
    /// # Errors
    /// [`FrameError`] if the id does not fit 29 bits or there are more than 8 bytes.
    pub fn new_extended(id: u32, data: &[u8]) -> Result<Self> {
        Self::new_data(CanId::extended(id)?, data)
    }

    /// A classic data frame with an 11-bit id.
    ///
    /// # Errors
    /// [`FrameError`] if the id does not fit 11 bits or there are more than 8 bytes.
    pub fn new_standard(id: u16, data: &[u8]) -> Result<Self> {
        Self::new_data(CanId::standard(id)?, data)
    }

    /// A classic data frame.
    ///
    /// # Errors
    /// [`FrameError::BadLength`] for more than 8 bytes.
    pub fn new_data(id: CanId, data: &[u8]) -> Result<Self> {
        if data.len() > CAN_MAX_LEN {
            return Err(FrameError::BadLength { len: data.len() });
        }
        Ok(Self::with(id, FrameKind::Data, data))
    }

    /// A remote transmission request asking for `dlc` bytes.
    ///
    /// # Errors
    /// [`FrameError::BadLength`] for `dlc > 8`.
    pub fn new_remote(id: CanId, dlc: u8) -> Result<Self> {
        if usize::from(dlc) > CAN_MAX_LEN {
            return Err(FrameError::BadLength {
                len: usize::from(dlc),
            });
        }
        let mut frame = Self::with(id, FrameKind::Remote, &[]);
        frame.len = dlc;
        Ok(frame)
    }

    /// An error frame with the given error class bits (without [`CAN_ERR_FLAG`]) and detail bytes.
    ///
    /// # Errors
    /// [`FrameError::ExtendedIdTooLarge`] if `class` has bits outside [`CAN_ERR_MASK`].
    pub fn new_error(class: u32, details: [u8; CAN_MAX_LEN]) -> Result<Self> {
        Ok(Self::with(
            CanId::extended(class)?,
            FrameKind::Error,
            &details,
        ))
    }

    /// A CAN FD frame; `data.len()` must be one of [`CANFD_LENGTHS`].
    ///
    /// # Errors
    /// [`FrameError::BadLength`] for a length CAN FD cannot carry.
    pub fn new_fd(id: CanId, data: &[u8], flags: u8) -> Result<Self> {
        if !CANFD_LENGTHS.contains(&data.len()) {
            return Err(FrameError::BadLength { len: data.len() });
        }
        Ok(Self::with(id, FrameKind::Fd { flags }, data))
    }

    /// The identifier (for an error frame, the error class bits as an extended id).
    pub const fn id(&self) -> CanId {
        self.id
    }

    /// The frame kind.
    pub const fn kind(&self) -> FrameKind {
        self.kind
    }

    /// True for a 29-bit id.
    pub const fn is_extended(&self) -> bool {
        self.id.is_extended()
    }

    /// True for a remote transmission request.
    pub const fn is_remote(&self) -> bool {
        matches!(self.kind, FrameKind::Remote)
    }

    /// True for an error frame.
    pub const fn is_error(&self) -> bool {
        matches!(self.kind, FrameKind::Error)
    }

    /// True for a CAN FD frame.
    pub const fn is_fd(&self) -> bool {
        matches!(self.kind, FrameKind::Fd { .. })
    }

    /// Payload length in bytes (0 for a remote frame; see [`CanFrame::dlc`]).
    pub const fn len(&self) -> usize {
        self.data().len()
    }

    /// The length field: the payload length, or for a remote frame the requested length.
    pub const fn dlc(&self) -> usize {
        self.len as usize
    }

    /// True if the frame carries no data bytes.
    pub const fn is_empty(&self) -> bool {
        self.data().is_empty()
    }

    /// The payload (empty for a remote frame).
    pub const fn data(&self) -> &[u8] {
        match self.kind {
            FrameKind::Remote => &[],
            // `len` never exceeds 64 by construction, so the split cannot fail.
            _ => self.data.split_at(self.len as usize).0,
        }
    }

    /// The error class bits of an error frame (0 for other frames).
    pub const fn error_class(&self) -> u32 {
        match self.kind {
            FrameKind::Error => self.id.raw(),
            _ => 0,
        }
    }

    /// The Linux `can_id` word: id plus `CAN_EFF_FLAG`, `CAN_RTR_FLAG`, `CAN_ERR_FLAG` as applicable.
    pub const fn linux_can_id(&self) -> u32 {
        const EFF: u32 = 0x8000_0000;
        const RTR: u32 = 0x4000_0000;
        match self.kind {
            FrameKind::Error => self.id.raw() | CAN_ERR_FLAG,
            _ => {
                let base = match self.id {
                    CanId::Standard(id) => id as u32,
                    CanId::Extended(id) => id | EFF,
                };
                if self.is_remote() { base | RTR } else { base }
            }
        }
    }
}

impl From<CanId> for embedded_can::Id {
    fn from(id: CanId) -> Self {
        match id {
            // Both constructors accept every value a `CanId` holds (11 and 29 bits by construction).
            CanId::Standard(raw) => embedded_can::StandardId::new(raw).map_or(
                Self::Standard(embedded_can::StandardId::ZERO),
                Self::Standard,
            ),
            CanId::Extended(raw) => embedded_can::ExtendedId::new(raw).map_or(
                Self::Extended(embedded_can::ExtendedId::ZERO),
                Self::Extended,
            ),
        }
    }
}

impl From<embedded_can::Id> for CanId {
    fn from(id: embedded_can::Id) -> Self {
        match id {
            embedded_can::Id::Standard(s) => Self::Standard(s.as_raw()),
            embedded_can::Id::Extended(e) => Self::Extended(e.as_raw()),
        }
    }
}

impl CanFrame {
    /// The frame of any [`embedded_can::Frame`] implementation (a microcontroller's CAN driver): a data
    /// or remote frame with its id and length. `None` for a length above 8, which no classic driver
    /// delivers.
    pub fn from_frame<F: embedded_can::Frame>(frame: &F) -> Option<Self> {
        let id = CanId::from(frame.id());
        if frame.is_remote_frame() {
            let dlc = u8::try_from(frame.dlc()).ok()?;
            Self::new_remote(id, dlc).ok()
        } else {
            Self::new_data(id, frame.data()).ok()
        }
    }
}

/// Classic data and remote frames. An error frame reads as an extended data frame with its class bits
/// as the id, and a CAN FD frame as a data frame of its length; `embedded-can` drivers report bus
/// errors through their `Error` type instead (see [`crate::bus`]).
impl embedded_can::Frame for CanFrame {
    fn new(id: impl Into<embedded_can::Id>, data: &[u8]) -> Option<Self> {
        Self::new_data(CanId::from(id.into()), data).ok()
    }

    fn new_remote(id: impl Into<embedded_can::Id>, dlc: usize) -> Option<Self> {
        Self::new_remote(CanId::from(id.into()), u8::try_from(dlc).ok()?).ok()
    }

    fn is_extended(&self) -> bool {
        CanFrame::is_extended(self)
    }

    fn is_remote_frame(&self) -> bool {
        self.is_remote()
    }

    fn id(&self) -> embedded_can::Id {
        CanFrame::id(self).into()
    }

    fn dlc(&self) -> usize {
        CanFrame::dlc(self)
    }

    fn data(&self) -> &[u8] {
        CanFrame::data(self)
    }
}

impl fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CanFrame")
            .field("id", &self.id)
            .field("kind", &self.kind)
            .field("len", &self.len)
            .field("data", &self.data())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOOM_COMMAND: [u8; 8] = [0x7D, 0xFF, 0x31, 0x40, 0x4E, 0xFF, 0xFF, 0xFF];

    #[test]
    fn constructors_check_limits() {
        assert!(CanFrame::new_extended(0x0CFE_3027, &BOOM_COMMAND).is_ok());
        assert_eq!(
            CanFrame::new_extended(0x2000_0000, &[]),
            Err(FrameError::ExtendedIdTooLarge(0x2000_0000))
        );
        assert_eq!(
            CanFrame::new_standard(0x800, &[]),
            Err(FrameError::StandardIdTooLarge(0x800))
        );
        assert_eq!(
            CanFrame::new_standard(1, &[0; 9]),
            Err(FrameError::BadLength { len: 9 })
        );
        assert_eq!(
            CanFrame::new_fd(CanId::Standard(1), &[0; 9], 0),
            Err(FrameError::BadLength { len: 9 })
        );
        assert!(CanFrame::new_fd(CanId::Standard(1), &[0; 64], CANFD_BRS).is_ok());
        assert!(CanFrame::new_remote(CanId::Standard(1), 9).is_err());
    }

    #[test]
    fn remote_frame_has_length_but_no_data() {
        let f = CanFrame::new_remote(CanId::Standard(0x123), 5).unwrap();
        assert_eq!(f.dlc(), 5);
        assert!(f.is_empty());
        assert_eq!(f.linux_can_id(), 0x4000_0123);
    }

    #[test]
    fn embedded_can_frames_round_trip() {
        use embedded_can::Frame as _;
        let f = CanFrame::new_extended(0x0CFE_3027, &BOOM_COMMAND).unwrap();
        let via: CanFrame =
            embedded_can::Frame::new(embedded_can::Frame::id(&f), f.data()).unwrap();
        assert_eq!(via, f);
        assert_eq!(CanFrame::from_frame(&f), Some(f));
        let std_id = embedded_can::StandardId::new(0x123).unwrap();
        let r: CanFrame = embedded_can::Frame::new_remote(std_id, 5).unwrap();
        assert!(r.is_remote_frame() && r.is_standard());
        assert_eq!(CanFrame::from_frame(&r), Some(r));
        assert!(<CanFrame as embedded_can::Frame>::new(std_id, &[0; 9]).is_none());
    }

    #[test]
    fn linux_can_id_sets_flags() {
        let f = CanFrame::new_extended(0x0CFE_3027, &BOOM_COMMAND).unwrap();
        assert_eq!(f.linux_can_id(), 0x8CFE_3027);
        let e = CanFrame::new_error(0x40, [0; 8]).unwrap();
        assert_eq!(e.linux_can_id(), 0x2000_0040);
        assert_eq!(e.error_class(), 0x40);
    }
}
