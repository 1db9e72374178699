//! Reading a configuration file as untrusted input: it must be a regular file (not a FIFO that
//! never ends, a device such as `/dev/zero` that never ends either, or a folder) of at most
//! [`MAX_CONFIG_BYTES`], read through a bounded reader so that memory stays bounded whatever the
//! path names. The reader is `gateway_core::file`'s, which the machine profiles and the key files
//! use too (the planner cannot depend on `firmware_bridge`, which pulls tokio and socketcan).

use std::path::Path;

/// The largest configuration file read, bytes (the largest shipped file is under 100 kB).
pub use gateway_core::file::MAX_CONFIG_BYTES;

/// The text of the configuration file at `path`: [`gateway_core::file::read_text`], the workspace's
/// one bounded reader.
///
/// # Errors
/// Why it cannot be used, one phrase without the path (the caller names the file): not a regular
/// file, larger than [`MAX_CONFIG_BYTES`], unreadable, or not UTF-8.
pub fn read_text(path: &Path) -> Result<String, String> {
    gateway_core::file::read_text(path).map_err(|e| e.to_string())
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
