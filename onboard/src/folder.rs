//! A session folder (`demo --out`, `run --out`) is written only when it is new or empty: a folder
//! holding another session's files is refused, so that a session never lands beside the scans and
//! plots of an earlier one. `--force` replaces a session folder (one holding the files a session
//! writes); a folder that holds none of them is never deleted.

use std::path::Path;

use anyhow::Context as _;

/// Files whose presence marks a folder as a session folder.
pub const SESSION_MARKERS: [&str; 5] = [
    "summary.json",
    "trace.log",
    "session_state.json",
    "run_options.json",
    "scans",
];

/// Makes `dir` ready for a new session: creates it when missing, accepts it when empty, and
/// otherwise refuses it, or with `force` replaces it when it is a session folder.
///
/// # Errors
/// A non-empty folder (with `force`: one that is not a session folder), or a file system error,
/// naming the folder.
pub fn prepare(dir: &Path, force: bool) -> anyhow::Result<()> {
    let entries: Vec<String> = match std::fs::read_dir(dir) {
        Ok(rd) => rd
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e).with_context(|| format!("reading the folder {}", dir.display())),
    };
    if !entries.is_empty() {
        let marks: Vec<&str> = SESSION_MARKERS
            .into_iter()
            .filter(|m| entries.iter().any(|e| e == m))
            .collect();
        match (force, marks.is_empty()) {
            (false, false) => anyhow::bail!(
                "{} holds another session ({}): give another --out, --resume it (run), or --force \
                 to replace it",
                dir.display(),
                marks.join(", ")
            ),
            (false, true) | (true, true) => anyhow::bail!(
                "{} is not empty and holds no session ({} entries, e.g. {}): give an empty or new \
                 folder as --out",
                dir.display(),
                entries.len(),
                entries[0]
            ),
            (true, false) => {
                tracing::warn!(folder = %dir.display(), "--force: replacing the session in it");
                std::fs::remove_dir_all(dir)
                    .with_context(|| format!("removing {}", dir.display()))?;
            }
        }
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_of_another_session_is_refused_unless_forced() {
        let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let dir = tmp.path().join("out");
        prepare(&dir, false).unwrap_or_else(|e| panic!("{e}"));
        prepare(&dir, false).unwrap_or_else(|e| panic!("empty: {e}"));
        std::fs::create_dir(dir.join("scans")).unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(dir.join("summary.json"), "{}").unwrap_or_else(|e| panic!("{e}"));
        let e = prepare(&dir, false).unwrap_err().to_string();
        assert!(e.contains("another session (summary.json, scans)"), "{e}");
        assert!(e.contains("--force"), "{e}");
        prepare(&dir, true).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(std::fs::read_dir(&dir).map(Iterator::count).ok(), Some(0));
    }

    #[test]
    fn a_folder_without_a_session_is_never_deleted() {
        let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        std::fs::write(tmp.path().join("notes.txt"), "mine").unwrap_or_else(|e| panic!("{e}"));
        for force in [false, true] {
            let e = prepare(tmp.path(), force).unwrap_err().to_string();
            assert!(
                e.contains("holds no session") && e.contains("notes.txt"),
                "{e}"
            );
        }
        assert!(tmp.path().join("notes.txt").exists());
    }
}
