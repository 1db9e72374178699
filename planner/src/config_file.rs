//! Reading a configuration file as untrusted input: it must be a regular file (not a FIFO that
//! never ends, a device such as `/dev/zero` that never ends either, or a folder) of at most
//! [`MAX_CONFIG_BYTES`], read through a bounded reader so that memory stays bounded whatever the
//! path names.

use std::io::Read as _;
use std::path::Path;

/// The largest configuration file read, bytes (the largest shipped file is under 100 kB).
pub const MAX_CONFIG_BYTES: u64 = 4 << 20;

/// The text of the configuration file at `path`.
///
/// # Errors
/// Why it cannot be used, one phrase without the path (the caller names the file): not a regular
/// file, larger than [`MAX_CONFIG_BYTES`], unreadable, or not UTF-8.
pub fn read_text(path: &Path) -> Result<String, String> {
    // Opened without blocking on a FIFO (which has no writer), then checked before any read.
    let file = open_nonblocking(path).map_err(|e| e.to_string())?;
    let meta = file.metadata().map_err(|e| e.to_string())?;
    if !meta.is_file() {
        return Err("not a regular file".to_owned());
    }
    if meta.len() > MAX_CONFIG_BYTES {
        return Err(format!(
            "{} bytes: larger than the {MAX_CONFIG_BYTES}-byte limit of a configuration file",
            meta.len()
        ));
    }
    let mut bytes = Vec::new();
    file.take(MAX_CONFIG_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > MAX_CONFIG_BYTES {
        return Err(format!(
            "grew past the {MAX_CONFIG_BYTES}-byte limit of a configuration file while read"
        ));
    }
    String::from_utf8(bytes).map_err(|e| format!("not UTF-8 text: {e}"))
}

#[cfg(unix)]
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt as _;
    // O_NONBLOCK: opening a FIFO for reading returns at once instead of waiting for a writer.
    const O_NONBLOCK: i32 = 0o4000;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(path)
}

#[cfg(not(unix))]
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    std::fs::File::open(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_bounded_regular_files_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("a.toml");
        std::fs::write(&ok, "x = 1\n").unwrap();
        assert_eq!(read_text(&ok).unwrap(), "x = 1\n");
        assert_eq!(read_text(dir.path()).unwrap_err(), "not a regular file");
        let big = dir.path().join("big.toml");
        std::fs::write(&big, vec![b'#'; (MAX_CONFIG_BYTES + 1) as usize]).unwrap();
        assert!(read_text(&big).unwrap_err().contains("larger than"));
        #[cfg(target_os = "linux")]
        assert_eq!(
            read_text(Path::new("/dev/zero")).unwrap_err(),
            "not a regular file"
        );
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, [0xff, 0xfe]).unwrap();
        assert!(read_text(&bad).unwrap_err().starts_with("not UTF-8"));
        assert!(read_text(&dir.path().join("missing")).is_err());
    }
}
