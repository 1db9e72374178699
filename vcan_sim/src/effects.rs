//! The hidden physical effects the plant applies.
//!
//! Each [`Effect`] (the one catalogue, [`planner::effects`]) is a physical phenomenon the real machine
//! has and the planner's nominal dig model does not. All are off (magnitude 0) in the nominal
//! machine. A magnitude is *added on top of* the nominal plant (e.g. `transport_delay = 0.05` means
//! 50 ms of delay beyond the nominal delay), so "off" is always 0 and the magnitude is what a
//! discrepancy analysis should recover.
//!
//! Effects are set from the machine/scenario file (`[effects]` table) or from the command line
//! (`--effect NAME=VALUE`, repeatable) and are never revealed on the bus: the plant applies them to
//! its physics and sensors only.

use serde::Serialize;

pub use planner::effects::{Effect, N_EFFECTS};

/// Errors when naming or setting an effect.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    /// The name is not one of [`Effect::ALL`].
    #[error("unknown effect `{0}` (see --list-effects)")]
    Unknown(String),
    /// The value is outside the effect's documented range.
    #[error("effect `{name}` = {value} is out of range [{min}, {max}] {unit}")]
    OutOfRange {
        /// Effect name.
        name: &'static str,
        /// Rejected value.
        value: f64,
        /// Minimum allowed.
        min: f64,
        /// Maximum allowed.
        max: f64,
        /// Unit of the magnitude.
        unit: &'static str,
    },
    /// A `NAME=VALUE` argument could not be parsed.
    #[error("cannot parse effect `{0}`: expected NAME=VALUE with a numeric VALUE")]
    Syntax(String),
}

/// Static description of an effect from the catalogue: unit, range and plain-language meaning (the
/// rows of `--list-effects`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EffectInfo {
    /// Catalogue name (snake_case), as used by `--effect NAME=VALUE`.
    pub name: &'static str,
    /// Unit of the magnitude.
    pub unit: &'static str,
    /// Smallest allowed magnitude.
    pub min: f64,
    /// Largest allowed magnitude.
    pub max: f64,
    /// What the effect does.
    pub description: &'static str,
}

impl EffectInfo {
    /// The catalogue entry of one effect.
    pub fn of(effect: Effect) -> Self {
        let (min, max) = effect.range();
        Self {
            name: effect.name(),
            unit: effect.unit(),
            min,
            max,
            description: effect.description(),
        }
    }
}

/// The catalogue as a table, in order.
pub fn registry() -> Vec<EffectInfo> {
    Effect::ALL.iter().map(|e| EffectInfo::of(*e)).collect()
}

/// Looks an effect up by name.
///
/// # Errors
/// [`EffectError::Unknown`] for a name not in the catalogue.
pub fn parse_effect(name: &str) -> Result<Effect, EffectError> {
    Effect::from_name(name).ok_or_else(|| EffectError::Unknown(name.trim().to_owned()))
}

/// A set of effect magnitudes; every effect not set is off (0).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EffectSet {
    values: [f64; N_EFFECTS],
}

impl EffectSet {
    /// The nominal machine: every effect off.
    pub fn nominal() -> Self {
        Self::default()
    }

    /// Sets one effect.
    ///
    /// # Errors
    /// [`EffectError::OutOfRange`] when the value is outside the effect's range or not finite.
    pub fn set(&mut self, effect: Effect, value: f64) -> Result<(), EffectError> {
        let info = EffectInfo::of(effect);
        if !value.is_finite() || value < info.min || value > info.max {
            return Err(EffectError::OutOfRange {
                name: info.name,
                value,
                min: info.min,
                max: info.max,
                unit: info.unit,
            });
        }
        self.values[effect.index()] = value;
        Ok(())
    }

    /// Sets one effect by name.
    ///
    /// # Errors
    /// [`EffectError::Unknown`] for an unknown name, [`EffectError::OutOfRange`] for a bad value.
    pub fn set_by_name(&mut self, name: &str, value: f64) -> Result<(), EffectError> {
        self.set(parse_effect(name)?, value)
    }

    /// Parses and applies one `NAME=VALUE` argument.
    ///
    /// # Errors
    /// [`EffectError::Syntax`], [`EffectError::Unknown`] or [`EffectError::OutOfRange`].
    pub fn apply_arg(&mut self, arg: &str) -> Result<(), EffectError> {
        let (name, value) = arg
            .split_once('=')
            .ok_or_else(|| EffectError::Syntax(arg.to_owned()))?;
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|_| EffectError::Syntax(arg.to_owned()))?;
        self.set_by_name(name, value)
    }

    /// Builds a set from `NAME=VALUE` arguments, later ones overriding earlier ones.
    ///
    /// # Errors
    /// The first argument that fails [`EffectSet::apply_arg`].
    pub fn from_args<S: AsRef<str>>(args: &[S]) -> Result<Self, EffectError> {
        let mut set = Self::nominal();
        for arg in args {
            set.apply_arg(arg.as_ref())?;
        }
        Ok(set)
    }

    /// Magnitude of one effect (0 when off).
    pub fn get(&self, effect: Effect) -> f64 {
        self.values[effect.index()]
    }

    /// True when the effect is on (non-zero magnitude).
    pub fn is_on(&self, effect: Effect) -> bool {
        self.get(effect) != 0.0
    }

    /// The effects that are on, with their magnitudes.
    pub fn active(&self) -> Vec<(Effect, f64)> {
        Effect::ALL
            .iter()
            .filter(|e| self.is_on(**e))
            .map(|e| (*e, self.get(*e)))
            .collect()
    }

    /// Overrides this set with every effect that is on in `other`.
    pub fn merge(&mut self, other: &EffectSet) {
        for (effect, value) in other.active() {
            self.values[effect.index()] = value;
        }
    }
}

/// The catalogue as a text table (for `--list-effects`).
pub fn registry_table() -> String {
    let mut out = format!(
        "{:<24} {:<38} {:>10} {:>10}  {}\n",
        "NAME", "UNIT", "MIN", "MAX", "DESCRIPTION"
    );
    for info in registry() {
        out.push_str(&format!(
            "{:<24} {:<38} {:>10} {:>10}  {}\n",
            info.name, info.unit, info.min, info.max, info.description
        ));
    }
    out
}

/// The catalogue as a JSON array of objects with `name`, `unit`, `min`, `max`, `description`.
///
/// # Errors
/// Only if JSON serialisation fails, which it cannot for these plain values.
pub fn registry_json() -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&registry())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--list-effects` shows the catalogue's rows, in its order, and every name parses back.
    #[test]
    fn registry_is_the_catalogue() {
        let rows = registry();
        assert_eq!(rows.len(), N_EFFECTS);
        for (row, effect) in rows.iter().zip(Effect::ALL) {
            assert_eq!(*row, EffectInfo::of(effect));
            assert_eq!((row.min, row.max), effect.range());
            assert_eq!(parse_effect(row.name), Ok(effect));
        }
    }

    #[test]
    fn nominal_set_has_everything_off() {
        assert!(EffectSet::nominal().active().is_empty());
    }

    #[test]
    fn args_parse_and_reject_unknown_and_out_of_range() {
        let set = EffectSet::from_args(&["transport_delay=0.05", "valve_deadband = 0.1"]).unwrap();
        assert_eq!(set.get(Effect::TransportDelay), 0.05);
        assert_eq!(set.get(Effect::ValveDeadband), 0.1);
        assert!(matches!(
            EffectSet::from_args(&["bogus=1"]),
            Err(EffectError::Unknown(_))
        ));
        assert!(matches!(
            EffectSet::from_args(&["transport_delay=5"]),
            Err(EffectError::OutOfRange { .. })
        ));
        assert!(matches!(
            EffectSet::from_args(&["transport_delay"]),
            Err(EffectError::Syntax(_))
        ));
        assert!(matches!(
            EffectSet::from_args(&["transport_delay=NaN"]),
            Err(EffectError::OutOfRange { .. })
        ));
    }

    #[test]
    fn json_lists_name_unit_min_max() {
        let json = registry_json().unwrap();
        let value: serde_json::Value = serde_json::from_str(&json).unwrap();
        let list = value.as_array().unwrap();
        assert_eq!(list.len(), N_EFFECTS);
        for item in list {
            for key in ["name", "unit", "min", "max", "description"] {
                assert!(item.get(key).is_some(), "{key}");
            }
        }
    }
}
