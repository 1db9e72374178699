//! State files: a controller's saved state, written atomically and validated on load.
//!
//! [`save`] writes the value as JSON to a temporary file in the target's folder, flushes it to the
//! disk (`fsync`), renames it over the target and flushes the folder, so a process killed at any
//! moment leaves either the previous state or the new one, never a torn file. [`load`] treats the file
//! as untrusted input: a syntax error names the file, line and column; a missing or mistyped field
//! and every [`Validate`] failure name the file and the field.

use std::fs::{self, File};
use std::io::Write as _;
use std::path::{Path, PathBuf};

use firmware_bridge::range::Limits;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// Why a state file could not be saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum StateFileError {
    /// Reading, writing, syncing or renaming failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid JSON (truncated, corrupted).
    #[error("{}: line {line}, column {column}: {message}", path.display())]
    Syntax {
        /// The file.
        path: PathBuf,
        /// Line of the error, 1-based.
        line: usize,
        /// Column of the error, 1-based.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A field is missing, mistyped or out of range.
    #[error("{}: field `{field}`: {message}", path.display())]
    Field {
        /// The file.
        path: PathBuf,
        /// The field's path, e.g. `terrain.heights_m[12]`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The value could not be serialised.
    #[error("{}: serialising: {source}", path.display())]
    Serialize {
        /// The file.
        path: PathBuf,
        /// The error.
        #[source]
        source: serde_json::Error,
    },
}

/// A field that failed validation: its path and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldError {
    /// The field's path.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl FieldError {
    /// `field` is wrong because of `message`.
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
        }
    }
}

impl FieldError {
    /// This error of a part, named from the whole: `prefix.field`.
    #[must_use]
    pub fn within(self, prefix: &str) -> Self {
        let field = if self.field.starts_with('[') {
            format!("{prefix}{}", self.field)
        } else {
            format!("{prefix}.{}", self.field)
        };
        Self { field, ..self }
    }
}

impl StateFileError {
    /// The file `path` has the wrong `error.field`.
    pub fn field(path: &Path, error: FieldError) -> Self {
        Self::Field {
            path: path.to_path_buf(),
            field: error.field,
            message: error.message,
        }
    }
}

/// Checks of a loaded state beyond its types (finite values, consistent sizes, ranges).
pub trait Validate {
    /// The first field that is wrong.
    ///
    /// # Errors
    /// The field and what is wrong with it.
    fn validate(&self) -> Result<(), FieldError>;
}

/// `value` of `field` is finite.
///
/// # Errors
/// NaN or an infinity.
pub fn finite(field: &str, value: f64) -> Result<(), FieldError> {
    Limits::FINITE
        .check(value)
        .map_err(|e| FieldError::new(field, format!("{value}: {e}")))
}

/// Every value of `values` (the field `field`) is finite; the error names the index.
///
/// # Errors
/// The first NaN or infinity.
pub fn all_finite(field: &str, values: &[f64]) -> Result<(), FieldError> {
    match values.iter().position(|&v| !Limits::FINITE.contains(v)) {
        None => Ok(()),
        Some(i) => finite(&format!("{field}[{i}]"), values[i]),
    }
}

/// Saves `value` to `path` atomically (module docs).
///
/// # Errors
/// Serialisation or I/O errors, naming the file.
pub fn save<T: Serialize>(path: &Path, value: &T) -> Result<(), StateFileError> {
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |source| StateFileError::Io { path: p, source }
    };
    let json = serde_json::to_vec(value).map_err(|source| StateFileError::Serialize {
        path: path.to_path_buf(),
        source,
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
    tmp_name.push(".tmp");
    let tmp = dir.join(tmp_name);
    {
        let mut f = File::create(&tmp).map_err(io(&tmp))?;
        f.write_all(&json).map_err(io(&tmp))?;
        f.sync_all().map_err(io(&tmp))?;
    }
    fs::rename(&tmp, path).map_err(io(path))?;
    // The rename itself reaches the disk with the folder.
    File::open(dir).and_then(|d| d.sync_all()).map_err(io(dir))
}

/// Loads and validates the state in `path` (module docs).
///
/// # Errors
/// [`StateFileError`]: unreadable, not JSON, a field missing, mistyped or failing [`Validate`].
pub fn load<T: DeserializeOwned + Validate>(path: &Path) -> Result<T, StateFileError> {
    let text = fs::read_to_string(path).map_err(|source| StateFileError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| StateFileError::Syntax {
            path: path.to_path_buf(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
    let value: T = serde_path_to_error::deserialize(json).map_err(|e| {
        let message = e.inner().to_string();
        let at = e.path().to_string();
        // A missing field is named in the message, at its struct's path.
        let field = match field_of(&message) {
            Some(name) if message.starts_with("missing field") => {
                if at == "." {
                    name.to_owned()
                } else {
                    format!("{at}.{name}")
                }
            }
            _ => at,
        };
        StateFileError::Field {
            path: path.to_path_buf(),
            field,
            message,
        }
    })?;
    value
        .validate()
        .map_err(|e| StateFileError::field(path, e))?;
    Ok(value)
}

/// The field a serde message names (``missing field `x` ``).
fn field_of(message: &str) -> Option<&str> {
    let start = message.find('`')? + 1;
    let len = message[start..].find('`')?;
    Some(&message[start..start + len])
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Saved {
        digs: u32,
        heights_m: Vec<f64>,
    }

    impl Validate for Saved {
        fn validate(&self) -> Result<(), FieldError> {
            if self.heights_m.len() != 4 {
                return Err(FieldError::new(
                    "heights_m",
                    format!("{} cells, the grid has 4", self.heights_m.len()),
                ));
            }
            all_finite("heights_m", &self.heights_m)
        }
    }

    fn saved() -> Saved {
        Saved {
            digs: 3,
            heights_m: vec![0.0, -0.25, 0.5, 1.0],
        }
    }

    #[test]
    fn round_trip_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        save(&path, &Saved { digs: 1, ..saved() }).unwrap();
        save(&path, &saved()).unwrap();
        assert_eq!(load::<Saved>(&path).unwrap(), saved());
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("state.json")]);
    }

    #[test]
    fn truncated_file_is_refused_with_file_and_position() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        save(&path, &saved()).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        fs::write(&path, &text[..text.len() / 2]).unwrap();
        let e = load::<Saved>(&path).unwrap_err();
        assert!(matches!(e, StateFileError::Syntax { .. }), "{e}");
        let msg = e.to_string();
        assert!(
            msg.contains("state.json") && msg.contains("line 1"),
            "{msg}"
        );
    }

    #[test]
    fn corrupted_fields_are_refused_with_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        let cases = [
            (r#"{"heights_m":[0,0,0,0]}"#, "digs"),
            (r#"{"digs":-1,"heights_m":[0,0,0,0]}"#, "digs"),
            (r#"{"digs":1,"heights_m":[0,"x",0,0]}"#, "heights_m[1]"),
            (r#"{"digs":1,"heights_m":[0,0,0],"extra":1}"#, "extra"),
            (r#"{"digs":1,"heights_m":[0,0,0]}"#, "heights_m"),
            // JSON has no NaN or infinity: serde_json writes them as null, refused here.
            (r#"{"digs":1,"heights_m":[0,0,null,0]}"#, "heights_m[2]"),
            (r#"{"digs":1,"heights_m":[0,0,1e999,0]}"#, "heights_m[2]"),
        ];
        for (text, field) in cases {
            if text.contains("1e999") {
                // Out of f64's range: refused by the parser, at its position.
                fs::write(&path, text).unwrap();
                assert!(matches!(
                    load::<Saved>(&path),
                    Err(StateFileError::Syntax { column: 32, .. })
                ));
                continue;
            }
            fs::write(&path, text).unwrap();
            match load::<Saved>(&path) {
                Err(StateFileError::Field {
                    path: p, field: f, ..
                }) => {
                    assert_eq!((p.as_path(), f.as_str()), (path.as_path(), field), "{text}");
                }
                other => panic!("{text}: {other:?}"),
            }
        }
    }

    #[test]
    fn non_finite_values_are_named_by_index() {
        assert_eq!(all_finite("h", &[0.0, 1.0]), Ok(()));
        assert_eq!(all_finite("h", &[0.0, f64::NAN]).unwrap_err().field, "h[1]");
        assert!(finite("x", f64::INFINITY).is_err());
    }
}
