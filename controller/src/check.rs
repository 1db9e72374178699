//! The parameter checks every part's `validate()` shares: [`ParamError`] (the field and the rule it
//! breaks), `check`, `check_deg` (over `Limits`, the workspace's one finite-and-range check,
//! [`firmware_bridge::range`]), `check_count` and `toml_float` (a value as TOML spells it).

pub(crate) use firmware_bridge::range::Limits;

use crate::ControllerError;

/// A configuration value that is not finite, out of range, or inconsistent with another.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{}: {rule}", self.path(), value_suffix(self.value.as_deref()))]
pub struct ParamError {
    /// The table of the controller config the value lives in (`safety`, `estimator`, `cycle`,
    /// `autodig`, `cleanup`, `j1939`; empty for top-level keys).
    pub section: &'static str,
    /// The key inside it as the file spells it, dotted through nested tables and array entries
    /// (`sensor_max_age_s`, `joint.kp`, `actions.2.swing_deg`).
    pub key: String,
    /// The value as the file states it (degrees for `_deg` keys), when known.
    pub value: Option<String>,
    /// The rule it breaks.
    pub rule: String,
}

fn value_suffix(value: Option<&str>) -> String {
    value.map(|v| format!(" = {v}")).unwrap_or_default()
}

impl ParamError {
    /// An error for `key` in `section`.
    pub fn new(
        section: &'static str,
        key: impl Into<String>,
        value: Option<String>,
        rule: impl Into<String>,
    ) -> Self {
        Self {
            section,
            key: key.into(),
            value,
            rule: rule.into(),
        }
    }

    /// The dotted path of the field in the controller config (`safety.sensor_max_age_s`).
    pub fn path(&self) -> String {
        match (self.section.is_empty(), self.key.is_empty()) {
            (true, _) => self.key.clone(),
            (false, true) => self.section.to_owned(),
            (false, false) => format!("{}.{}", self.section, self.key),
        }
    }
}

impl From<ParamError> for ControllerError {
    fn from(e: ParamError) -> Self {
        let (field, reason) = if e.section.is_empty() {
            ("controller", e.to_string())
        } else {
            (
                e.section,
                format!("{}{}: {}", e.key, value_suffix(e.value.as_deref()), e.rule),
            )
        };
        ControllerError::Config { field, reason }
    }
}

/// A value as TOML spells it (`nan`, `inf`, `1e308`, `0.25`).
pub(crate) fn toml_float(v: f64) -> String {
    if v.is_nan() {
        "nan".to_owned()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_owned()
    } else {
        format!("{v:?}")
    }
}

/// `Ok` if `v` is finite and within `limits`; `why` (may be empty) explains the limits.
pub(crate) fn check(
    section: &'static str,
    key: &str,
    v: f64,
    limits: Limits,
    why: &str,
) -> Result<(), ParamError> {
    limits
        .check(v)
        .map_err(|e| out_of_range(section, key, toml_float(v), e.to_string(), why))
}

/// [`check`] for an angle held in radians and written in degrees (a `_deg` key); `limits` in
/// degrees.
pub(crate) fn check_deg(
    section: &'static str,
    key: &str,
    v_rad: f64,
    limits_deg: Limits,
) -> Result<(), ParamError> {
    check(section, key, v_rad.to_degrees(), limits_deg, "")
}

/// `Ok` if the count `v` is within `[lo, hi]`; `why` (may be empty) explains the limits.
pub(crate) fn check_count(
    section: &'static str,
    key: &str,
    v: u64,
    lo: u64,
    hi: u64,
    why: &str,
) -> Result<(), ParamError> {
    if (lo..=hi).contains(&v) {
        return Ok(());
    }
    Err(out_of_range(
        section,
        key,
        v.to_string(),
        format!("must be in [{lo}, {hi}]"),
        why,
    ))
}

/// The error of [`check`] and [`check_count`]: `rule`, then `why` in parentheses unless empty.
fn out_of_range(
    section: &'static str,
    key: &str,
    value: String,
    rule: String,
    why: &str,
) -> ParamError {
    let rule = if why.is_empty() {
        rule
    } else {
        format!("{rule} ({why})")
    };
    ParamError::new(section, key, Some(value), rule)
}
