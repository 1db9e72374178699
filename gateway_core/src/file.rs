//! Reading a file as untrusted input (the `std` feature; host only): it must be a regular file (not a
//! FIFO that never ends, a device such as `/dev/zero` that never ends either, or a folder), opened
//! without blocking and checked before any read, then read through a bounded reader so that memory
//! stays bounded whatever the path names.
//!
//! The one reader of the workspace's configuration files: the planner's (`planner::config_file`,
//! the machine file, the site, the controller's configs), the machine profiles and their DBCs
//! (`firmware_bridge::profile`) and the key files ([`crate::secoc::SessionKey::from_file`], which
//! opens through [`open_regular`] and checks the permissions before it reads).

use std::fs::{File, Metadata};
use std::io::Read as _;
use std::path::Path;
use std::string::String;
use std::vec::Vec;

/// The largest configuration file read, bytes (the largest shipped file is under 100 kB).
pub const MAX_CONFIG_BYTES: u64 = 4 << 20;

/// Why a file cannot be used, one phrase without the path (the caller names the file).
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// Opening, inspecting or reading it failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// A folder, a FIFO, a device, ...
    #[error("not a regular file")]
    NotRegular,
    /// Larger than [`MAX_CONFIG_BYTES`] when opened.
    #[error("{0} bytes: larger than the {MAX_CONFIG_BYTES}-byte limit of a configuration file")]
    TooLarge(u64),
    /// Grew past [`MAX_CONFIG_BYTES`] while read.
    #[error("grew past the {MAX_CONFIG_BYTES}-byte limit of a configuration file while read")]
    Grew,
    /// Not UTF-8 text.
    #[error("not UTF-8 text: {0}")]
    NotUtf8(#[from] std::string::FromUtf8Error),
}

/// As an I/O error: the I/O error itself, or [`std::io::ErrorKind::InvalidData`] carrying the
/// reason.
impl From<ReadError> for std::io::Error {
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::Io(e) => e,
            other => Self::new(std::io::ErrorKind::InvalidData, other),
        }
    }
}

/// The file at `path` opened for reading without blocking (opening a FIFO that has no writer
/// returns at once) and its metadata, if it is a regular file.
///
/// # Errors
/// [`ReadError::Io`] if it cannot be opened or inspected, [`ReadError::NotRegular`] if it is not a
/// regular file.
pub fn open_regular(path: &Path) -> Result<(File, Metadata), ReadError> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        // O_NONBLOCK: opening a FIFO for reading returns at once instead of waiting for a writer.
        const O_NONBLOCK: i32 = 0o4000;
        options.custom_flags(O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(ReadError::NotRegular);
    }
    Ok((file, meta))
}

/// The text of the configuration file at `path`.
///
/// # Errors
/// [`ReadError`]: not a regular file, larger than [`MAX_CONFIG_BYTES`], unreadable, or not UTF-8.
pub fn read_text(path: &Path) -> Result<String, ReadError> {
    let (file, meta) = open_regular(path)?;
    if meta.len() > MAX_CONFIG_BYTES {
        return Err(ReadError::TooLarge(meta.len()));
    }
    let mut bytes = Vec::new();
    file.take(MAX_CONFIG_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_CONFIG_BYTES {
        return Err(ReadError::Grew);
    }
    Ok(String::from_utf8(bytes)?)
}
