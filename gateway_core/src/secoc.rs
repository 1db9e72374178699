//! Freshness and authentication of the controller's control frames (after AUTOSAR SecOC).
//!
//! The frames that can make the machine move, the valve commands, the position setpoints and the
//! heartbeat (which arms the gateway), carry a trailer: a `FreshnessValue` (the low bits of the
//! sender's 64-bit counter for that id) and an `Authenticator` (an AES-128-CMAC truncated to the
//! field). The CMAC covers the gateway's session nonce ([`crate::messages::GatewaySession`]), the CAN
//! id, the full counter and the eight data bytes with the authenticator (and the heartbeat's
//! checksum) set to ones. The gateway ([`Verifier`]) accepts a frame only if the authenticator verifies
//! for the smallest counter above the last one it accepted for that id whose low bits are the ones
//! received; so
//!
//! - a frame recorded in another session does not verify (other nonce);
//! - a frame replayed in the same session does not verify (its counter is not above the last);
//! - a second sender with the controller's address but its own counter does not verify;
//! - with a provisioned [`SessionKey`], a node without the key cannot compute an authenticator.
//!
//! Without a provisioned key the CMAC is keyed with [`SessionKey::PUBLIC`] (all zeros): the first three
//! hold, against recordings and faults, but anyone who reads the protocol can forge frames.
//!
//! The sender ([`Sealer`]) learns the session from the gateway, resets its counters on a new session
//! and sends nothing secured before it knows one. Counters are per id, start at 1 in every session and
//! never wrap (64 bits).

use core::fmt;

use aes::Aes128;
use cmac::{Cmac, KeyInit, Mac};

use crate::dbc::{self, SignalDesc};
use crate::frame::CanFrame;
use crate::messages::{self, Decoded, EncodeError, Message, Trailer};

/// A 128-bit AES key for the authenticator. Its `Debug` and `Display` never show the key.
#[derive(Clone, PartialEq, Eq)]
pub struct SessionKey([u8; 16]);

impl SessionKey {
    /// The key used when none is provisioned: all zeros, public, so it authenticates nothing (see the
    /// module docs); freshness and the session binding still hold.
    pub const PUBLIC: Self = Self([0; 16]);

    /// A key from 32 hexadecimal digits (spaces, `:` and `-` between digits allowed).
    ///
    /// # Errors
    /// [`KeyError`] for another length, a non-hex character, or the all-zero public key (provisioning
    /// it would look like authentication and be none). The error never contains the text.
    pub fn from_hex(text: &str) -> Result<Self, KeyError> {
        let digits = || text.bytes().filter(|b| !matches!(b, b' ' | b':' | b'-'));
        let count = digits().count();
        if count != 32 {
            return Err(KeyError::Length(count));
        }
        let mut key = [0u8; 16];
        for (i, c) in digits().enumerate() {
            let nibble = (c as char).to_digit(16).ok_or(KeyError::NotHex)?;
            // A hex digit fits 4 bits; the high one comes first.
            let nibble = u8::try_from(nibble).map_err(|_| KeyError::NotHex)?;
            key[i / 2] |= if i % 2 == 0 { nibble << 4 } else { nibble };
        }
        if key == [0; 16] {
            return Err(KeyError::Public);
        }
        Ok(Self(key))
    }

    /// The key in a file: 32 hex digits (16 bytes), surrounding whitespace ignored. The file must be
    /// readable by its owner only (`chmod 600`): a key others can read authenticates nothing. The key
    /// is never printed.
    ///
    /// # Errors
    /// [`KeyFileError`] naming the file and what is wrong: unreadable, open to group or others,
    /// longer than 256 bytes, or not a valid key.
    #[cfg(feature = "std")]
    pub fn from_file(path: &std::path::Path) -> Result<Self, KeyFileError> {
        use std::io::Read as _;
        use std::string::{String, ToString};
        let err = |reason: String| KeyFileError {
            path: path.display().to_string(),
            reason,
        };
        // Opened without blocking (a FIFO as the key file would wait for a writer forever), then
        // checked to be a regular file before any read.
        let (file, meta) = crate::file::open_regular(path).map_err(|e| err(e.to_string()))?;
        check_private(&meta).map_err(err)?;
        let mut text = String::new();
        file.take(257)
            .read_to_string(&mut text)
            .map_err(|e| err(e.to_string()))?;
        if text.len() > 256 {
            return Err(err("longer than 256 bytes".into()));
        }
        Self::from_hex(text.trim()).map_err(|e| err(e.to_string()))
    }

    /// A random key (the operating system's generator).
    #[cfg(feature = "std")]
    pub fn generate() -> Self {
        Self::generate_with(&mut rand::rng())
    }

    /// A key drawn from `rng`, never the public one. For a session whose both ends are in one
    /// process (`demo`, the lab) a generator seeded from the session's seed keeps the trace
    /// reproducible while the control path is authenticated as on a provisioned machine.
    #[cfg(feature = "std")]
    pub fn generate_with<R: rand::Rng + ?Sized>(rng: &mut R) -> Self {
        use rand::RngExt as _;
        loop {
            let key: [u8; 16] = rng.random();
            if key != [0; 16] {
                return Self(key);
            }
        }
    }

    /// True for [`SessionKey::PUBLIC`] (no key provisioned).
    pub fn is_public(&self) -> bool {
        self.0 == [0; 16]
    }
}

impl fmt::Debug for SessionKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.is_public() {
            "SessionKey(public)"
        } else {
            "SessionKey(<provisioned>)"
        })
    }
}

#[cfg(feature = "std")]
impl TryFrom<std::string::String> for SessionKey {
    type Error = KeyError;
    fn try_from(text: std::string::String) -> Result<Self, KeyError> {
        Self::from_hex(&text)
    }
}

#[cfg(feature = "std")]
impl<'de> serde::Deserialize<'de> for SessionKey {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = std::string::String::deserialize(d)?;
        Self::from_hex(&text).map_err(serde::de::Error::custom)
    }
}

/// Why a key text was refused (never quoting it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// Not 32 hex digits.
    #[error("a key is 32 hexadecimal digits (128 bits), this one has {0}")]
    Length(usize),
    /// A character that is not a hex digit.
    #[error("a key is hexadecimal digits only")]
    NotHex,
    /// The all-zero key, which is public.
    #[error("the all-zero key is the public one and authenticates nothing")]
    Public,
}

/// `Err` (the reason, with the fix) when a key file's permissions let group or others at it.
#[cfg(all(feature = "std", unix))]
fn check_private(meta: &std::fs::Metadata) -> Result<(), std::string::String> {
    use std::os::unix::fs::PermissionsExt as _;
    let mode = meta.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(std::format!(
            "open to group or others (mode {mode:03o}): anyone who can read the key can arm and \
             drive the machine; make it private with `chmod 600`"
        ));
    }
    Ok(())
}

/// Permissions are not checked where they are not Unix modes.
#[cfg(all(feature = "std", not(unix)))]
fn check_private(_meta: &std::fs::Metadata) -> Result<(), std::string::String> {
    Ok(())
}

/// A key file that cannot be used (the error never contains the key).
#[cfg(feature = "std")]
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("key file {path}: {reason}")]
pub struct KeyFileError {
    /// The file.
    pub path: std::string::String,
    /// What is wrong.
    pub reason: std::string::String,
}

/// Why a frame could not be sealed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SealError {
    /// No session known yet: the gateway's `GatewaySession` has not been received.
    #[error("no gateway session yet")]
    NoSession,
    /// The message does not encode.
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// Why a secured frame was not accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AuthError {
    /// The message carries no trailer (it is not a secured message).
    #[error("not a secured message")]
    NotSecured,
    /// The authenticator does not verify for the next fresh counter: replayed, from another session,
    /// from another sender, forged, or with another key.
    #[error("authenticator does not verify (replayed, other session or sender, or wrong key)")]
    BadAuthenticator,
}

/// The PGNs of the secured messages; the index is the counter slot.
const SECURED_PGNS: [u32; 8] = [
    dbc::aux_valve_command_boom::PGN,
    dbc::aux_valve_command_stick::PGN,
    dbc::aux_valve_command_bucket::PGN,
    dbc::aux_valve_command_swing::PGN,
    dbc::aux_valve_command_left_track::PGN,
    dbc::aux_valve_command_right_track::PGN,
    dbc::position_setpoint::PGN,
    dbc::controller_heartbeat::PGN,
];

fn slot(pgn: u32) -> Option<usize> {
    SECURED_PGNS.iter().position(|p| *p == pgn)
}

/// True if frames of this PGN carry a freshness value and an authenticator.
pub fn is_secured(pgn: u32) -> bool {
    slot(pgn).is_some()
}

fn ones(sig: &SignalDesc) -> i64 {
    (1i64 << sig.len) - 1
}

/// The data the authenticator covers: the frame's bytes with the authenticator (and, for the
/// heartbeat, the checksum computed after it) set to ones.
fn masked(pgn: u32, auth: &SignalDesc, data: &[u8; 8]) -> [u8; 8] {
    let mut d = *data;
    // The raw value is the field's all-ones pattern, in range by construction.
    let _ = dbc::encode_raw(auth, ones(auth), &mut d);
    if pgn == dbc::controller_heartbeat::PGN {
        let crc = &dbc::controller_heartbeat::CHECKSUM;
        let _ = dbc::encode_raw(crc, ones(crc), &mut d);
    }
    d
}

/// The CMAC state keyed once; cloned per frame.
#[derive(Clone)]
struct Authenticator(Cmac<Aes128>);

impl Authenticator {
    fn new(key: &SessionKey) -> Self {
        // A 16-byte slice is a valid AES-128 key length.
        #[allow(clippy::expect_used)]
        let mac = <Cmac<Aes128> as KeyInit>::new_from_slice(&key.0).expect("16-byte AES-128 key");
        Self(mac)
    }

    /// The authenticator truncated to `bits` (the most significant bits of the CMAC, as in SecOC).
    fn tag(&self, session: u32, can_id: u32, freshness: u64, data: &[u8; 8], bits: u32) -> u32 {
        let mut mac = self.0.clone();
        mac.update(&session.to_le_bytes());
        mac.update(&can_id.to_le_bytes());
        mac.update(&freshness.to_le_bytes());
        mac.update(data);
        let full = mac.finalize().into_bytes();
        let top = u32::from_be_bytes([full[0], full[1], full[2], full[3]]);
        top >> (32 - bits)
    }
}

impl fmt::Debug for Authenticator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Authenticator")
    }
}

fn frame_bytes(frame: &CanFrame) -> Option<[u8; 8]> {
    frame.data().try_into().ok()
}

/// The sender's side: seals the controller's secured messages for the current session.
#[derive(Debug, Clone)]
pub struct Sealer {
    auth: Authenticator,
    session: Option<u32>,
    counters: [u64; SECURED_PGNS.len()],
}

impl Sealer {
    /// A sealer with `key` and no session yet.
    pub fn new(key: &SessionKey) -> Self {
        Self {
            auth: Authenticator::new(key),
            session: None,
            counters: [0; SECURED_PGNS.len()],
        }
    }

    /// The current session, if one is known.
    pub fn session(&self) -> Option<u32> {
        self.session
    }

    /// Takes the gateway's session; a new one resets every counter. True if it changed.
    pub fn set_session(&mut self, session_id: u32) -> bool {
        if self.session == Some(session_id) {
            return false;
        }
        self.session = Some(session_id);
        self.counters = [0; SECURED_PGNS.len()];
        true
    }

    /// Encodes `message`; a secured one gets the next counter of its id and its authenticator.
    ///
    /// # Errors
    /// [`SealError::NoSession`] for a secured message before a session is known; [`SealError::Encode`]
    /// if the message does not encode.
    pub fn seal(&mut self, message: &Message) -> Result<CanFrame, SealError> {
        let frame = message.encode()?;
        let pgn = message.descriptor().pgn;
        let (Some(i), Some((fv_sig, auth_sig))) = (slot(pgn), messages::trailer_signals(pgn))
        else {
            return Ok(frame);
        };
        let session = self.session.ok_or(SealError::NoSession)?;
        let mut d = frame_bytes(&frame).ok_or(SealError::Encode(EncodeError::OutOfRange {
            signal: "dlc",
            value: frame.len() as f64,
            min: 8.0,
            max: 8.0,
        }))?;
        let freshness = self.counters[i] + 1;
        let low = i64::try_from(freshness & ones(fv_sig).unsigned_abs()).unwrap_or(0);
        dbc::encode_raw(fv_sig, low, &mut d)?;
        let can_id = frame.id().raw();
        let tag = self.auth.tag(
            session,
            can_id,
            freshness,
            &masked(pgn, auth_sig, &d),
            u32::from(auth_sig.len),
        );
        dbc::encode_raw(auth_sig, i64::from(tag), &mut d)?;
        if pgn == dbc::controller_heartbeat::PGN {
            let crc = messages::heartbeat_checksum(&d);
            dbc::encode_raw(&dbc::controller_heartbeat::CHECKSUM, i64::from(crc), &mut d)?;
        }
        self.counters[i] = freshness;
        CanFrame::new_data(frame.id(), &d).map_err(|_| {
            SealError::Encode(EncodeError::OutOfRange {
                signal: "dlc",
                value: 8.0,
                min: 0.0,
                max: 8.0,
            })
        })
    }
}

/// The receiver's side (the gateway): the last accepted counter per id in the current session.
#[derive(Debug, Clone)]
pub struct Verifier {
    auth: Authenticator,
    session: u32,
    last: [u64; SECURED_PGNS.len()],
}

impl Verifier {
    /// A verifier with `key` in session `session_id`.
    pub fn new(key: &SessionKey, session_id: u32) -> Self {
        Self {
            auth: Authenticator::new(key),
            session: session_id,
            last: [0; SECURED_PGNS.len()],
        }
    }

    /// The current session.
    pub fn session(&self) -> u32 {
        self.session
    }

    /// Starts a new session: every counter starts over, and nothing of the old session verifies.
    pub fn start_session(&mut self, session_id: u32) {
        self.session = session_id;
        self.last = [0; SECURED_PGNS.len()];
    }

    /// Checks a decoded secured frame and, if it verifies, records its counter as the last accepted.
    /// Returns the full counter.
    ///
    /// # Errors
    /// [`AuthError::NotSecured`] for a message without a trailer, [`AuthError::BadAuthenticator`]
    /// otherwise (see the module docs); nothing is recorded then.
    pub fn verify(&mut self, decoded: &Decoded, frame: &CanFrame) -> Result<u64, AuthError> {
        let pgn = decoded.id.pgn();
        let (
            Some(i),
            Some((fv_sig, auth_sig)),
            Some(Trailer {
                freshness,
                authenticator,
            }),
            Some(d),
        ) = (
            slot(pgn),
            messages::trailer_signals(pgn),
            decoded.trailer,
            frame_bytes(frame),
        )
        else {
            return Err(AuthError::NotSecured);
        };
        let modulus = 1u64 << fv_sig.len;
        let last = self.last[i];
        let mut candidate = (last & !(modulus - 1)) | u64::from(freshness);
        if candidate <= last {
            candidate = candidate
                .checked_add(modulus)
                .ok_or(AuthError::BadAuthenticator)?;
        }
        let expected = self.auth.tag(
            self.session,
            frame.id().raw(),
            candidate,
            &masked(pgn, auth_sig, &d),
            u32::from(auth_sig.len),
        );
        if expected != authenticator {
            return Err(AuthError::BadAuthenticator);
        }
        self.last[i] = candidate;
        Ok(candidate)
    }
}

/// Where a gateway's session nonces start: a value the platform provides that differs at every
/// power-up. On the microcontroller, its hardware random number generator (e.g. the STM32 `RNG`
/// peripheral) or a boot counter kept in non-volatile memory, incremented and written back before the
/// first session; on a host, the operating system's random source ([`OsNonceSource`]). Nonces need
/// to be unique, not secret. There is deliberately no default: a constant would give every power-up
/// the same sessions, and a recording of one would verify in the next.
pub trait NonceSource {
    /// The seed of this power-up's session nonces ([`SessionNonces::new`]).
    fn session_seed(&mut self) -> u64;
}

/// A seed given by the caller: for an in-process session whose trace must be reproducible from its
/// seed (`demo`, the lab, tests). Never on a machine, where every start would repeat its nonces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeededNonceSource(pub u64);

impl NonceSource for SeededNonceSource {
    fn session_seed(&mut self) -> u64 {
        self.0
    }
}

/// The host's nonce source: the operating system's random source (`getrandom`, through
/// `rand::rngs::SysRng`).
#[cfg(feature = "std")]
#[derive(Debug, Clone, Copy, Default)]
pub struct OsNonceSource;

#[cfg(feature = "std")]
impl NonceSource for OsNonceSource {
    fn session_seed(&mut self) -> u64 {
        use rand::TryRng as _;
        // getrandom fails only where the OS has no random source at all; a gateway there must not
        // start with a guessable nonce, so this is the end of the program.
        rand::rngs::SysRng
            .try_next_u64()
            .unwrap_or_else(|e| panic!("the operating system's random source: {e}"))
    }
}

/// A 64-bit generator of session nonces (SplitMix64). Nonces need to be unique, not secret: seed it
/// from a hardware random source or a boot counter kept across power cycles, so that no two sessions
/// of the machine share a nonce.
#[derive(Debug, Clone)]
pub struct SessionNonces(u64);

impl SessionNonces {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next nonce, never equal to `previous`.
    pub fn next_after(&mut self, previous: Option<u32>) -> u32 {
        loop {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            let nonce = (z >> 32) as u32;
            if Some(nonce) != previous {
                return nonce;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{AuxValveCommand, ControllerHeartbeat, RequestedMode, Valve};
    use std::format;
    use std::string::ToString;
    use std::vec::Vec;

    const SESSION: u32 = 0x1234_5678;
    const KEY_HEX: &str = "000102030405060708090a0b0c0d0e0f";

    fn boom(u: f64) -> Message {
        Message::AuxValveCommand(AuxValveCommand::from_fraction(Valve::Boom, u).unwrap())
    }

    fn check(v: &mut Verifier, frame: &CanFrame) -> Result<u64, AuthError> {
        let decoded = Message::decode(frame).unwrap();
        v.verify(&decoded, frame)
    }

    #[test]
    fn sealed_frames_verify_once_in_order_and_not_in_another_session() {
        let mut s = Sealer::new(&SessionKey::PUBLIC);
        assert_eq!(s.seal(&boom(0.5)), Err(SealError::NoSession));
        s.set_session(SESSION);
        let frames: Vec<CanFrame> = (0..600).map(|_| s.seal(&boom(0.5)).unwrap()).collect();
        let mut v = Verifier::new(&SessionKey::PUBLIC, SESSION);
        for (k, f) in frames.iter().enumerate() {
            assert_eq!(check(&mut v, f), Ok(k as u64 + 1));
        }
        // Every frame again (a replay of the whole sequence) fails.
        for f in &frames {
            assert_eq!(check(&mut v, f), Err(AuthError::BadAuthenticator));
        }
        // In a new session none of them verifies either.
        let mut v = Verifier::new(&SessionKey::PUBLIC, SESSION + 1);
        assert!(frames.iter().all(|f| check(&mut v, f).is_err()));
    }

    #[test]
    fn lost_frames_within_the_window_are_tolerated() {
        let mut s = Sealer::new(&SessionKey::PUBLIC);
        s.set_session(SESSION);
        let mut v = Verifier::new(&SessionKey::PUBLIC, SESSION);
        for _ in 0..200 {
            s.seal(&boom(0.1)).unwrap();
        }
        assert_eq!(check(&mut v, &s.seal(&boom(0.1)).unwrap()), Ok(201));
    }

    #[test]
    fn heartbeat_checksum_still_verifies_after_sealing() {
        let mut s = Sealer::new(&SessionKey::PUBLIC);
        s.set_session(SESSION);
        let hb = Message::ControllerHeartbeat(ControllerHeartbeat {
            mode: RequestedMode::ArmValve,
            alive_counter: 3,
        });
        let frame = s.seal(&hb).unwrap();
        let decoded = Message::decode(&frame).expect("checksum over the sealed bytes");
        assert_eq!(decoded.message, hb);
        let mut v = Verifier::new(&SessionKey::PUBLIC, SESSION);
        assert_eq!(v.verify(&decoded, &frame), Ok(1));
    }

    #[test]
    fn without_the_key_nothing_verifies() {
        let key = SessionKey::from_hex(KEY_HEX).unwrap();
        let mut stranger = Sealer::new(&SessionKey::PUBLIC);
        stranger.set_session(SESSION);
        let mut v = Verifier::new(&key, SESSION);
        for _ in 0..100 {
            assert!(check(&mut v, &stranger.seal(&boom(1.0)).unwrap()).is_err());
        }
        let mut owner = Sealer::new(&key);
        owner.set_session(SESSION);
        assert!(check(&mut v, &owner.seal(&boom(1.0)).unwrap()).is_ok());
    }

    #[test]
    fn keys_are_validated_and_never_shown() {
        let key = SessionKey::from_hex("00:01:02:03:04:05:06:07:08:09:0A:0B:0C:0D:0E:0F").unwrap();
        assert_eq!(key, SessionKey::from_hex(KEY_HEX).unwrap());
        assert_eq!(format!("{key:?}"), "SessionKey(<provisioned>)");
        assert_eq!(SessionKey::from_hex("0102"), Err(KeyError::Length(4)));
        let not_hex = "zz0102030405060708090a0b0c0d0e0f";
        let e = SessionKey::from_hex(not_hex).unwrap_err();
        assert!(!e.to_string().contains("zz"));
        assert_eq!(SessionKey::from_hex(&"0".repeat(32)), Err(KeyError::Public));
    }

    #[test]
    fn nonces_differ_from_the_previous_one() {
        let mut n = SessionNonces::new(7);
        let mut prev = None;
        for _ in 0..1000 {
            let next = n.next_after(prev);
            assert_ne!(Some(next), prev);
            prev = Some(next);
        }
    }

    /// Writes `text` to a file with `mode` and returns it (the directory lives as long as the test).
    #[cfg(unix)]
    fn key_file(dir: &tempfile::TempDir, text: &str, mode: u32) -> std::path::PathBuf {
        use std::os::unix::fs::PermissionsExt as _;
        let path = dir.path().join("machine.key");
        std::fs::write(&path, text).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        path
    }

    #[cfg(unix)]
    #[test]
    fn key_file_errors_name_the_file_and_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let good = key_file(&dir, &format!("{KEY_HEX}\n"), 0o600);
        assert_eq!(
            SessionKey::from_file(&good).unwrap(),
            SessionKey::from_hex(KEY_HEX).unwrap()
        );
        let err = |text: &str, mode: u32| {
            let path = key_file(&dir, text, mode);
            let e = SessionKey::from_file(&path).unwrap_err().to_string();
            assert!(e.contains(&path.display().to_string()), "{e}");
            assert!(!e.contains(KEY_HEX), "the key in an error: {e}");
            e
        };
        // Readable by others: refused with the fix, the key never shown.
        let e = err(KEY_HEX, 0o644);
        assert!(e.contains("mode 644") && e.contains("chmod 600"), "{e}");
        assert!(err(KEY_HEX, 0o640).contains("chmod 600"));
        // 15 bytes, 17 bytes, not hex, the public key.
        assert!(err(&KEY_HEX[..30], 0o600).contains("this one has 30"));
        assert!(err(&format!("{KEY_HEX}10"), 0o600).contains("this one has 34"));
        assert!(err(&KEY_HEX.replace('a', "g"), 0o600).contains("hexadecimal"));
        assert!(err(&"0".repeat(32), 0o600).contains("public"));
        assert!(err(&"0".repeat(300), 0o600).contains("longer than 256 bytes"));
        let missing = dir.path().join("none.key");
        let e = SessionKey::from_file(&missing).unwrap_err().to_string();
        assert!(e.contains("none.key"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_or_a_device_as_the_key_file_is_refused_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("machine.key");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        for path in [fifo.as_path(), std::path::Path::new("/dev/zero")] {
            let started = std::time::Instant::now();
            let e = SessionKey::from_file(path).unwrap_err().to_string();
            assert!(e.contains("not a regular file"), "{e}");
            assert!(started.elapsed() < std::time::Duration::from_secs(1), "{e}");
        }
    }

    #[test]
    fn generated_keys_are_provisioned_and_differ() {
        let a = SessionKey::generate();
        let b = SessionKey::generate();
        assert!(!a.is_public());
        assert_ne!(a, b);
        // From a seeded generator: the same seed, the same key; another seed, another key.
        use rand::SeedableRng as _;
        let seeded =
            |seed| SessionKey::generate_with(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
        assert_eq!(seeded(7), seeded(7));
        assert_ne!(seeded(7), seeded(8));
    }
}
