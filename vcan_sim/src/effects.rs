//! The registry of hidden physical effects.
//!
//! Each [`Effect`] is a physical phenomenon the real machine has and the planner's nominal dig model
//! does not. All are off (magnitude 0) in the nominal machine. A magnitude is *added on top of* the
//! nominal plant (e.g. `transport_delay = 0.05` means 50 ms of delay beyond the nominal delay), so
//! "off" is always 0 and the magnitude is what a discrepancy analysis should recover.
//!
//! Effects are set from the machine/scenario file (`[effects]` table) or from the command line
//! (`--effect NAME=VALUE`, repeatable) and are never revealed on the bus: the plant applies them to
//! its physics and sensors only.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

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

/// One named hidden effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// Dead band on every valve command (fraction of full command).
    ValveDeadband,
    /// Extra fixed delay between command and spool motion (s).
    TransportDelay,
    /// Extra first-order lag on the spool/flow response (time constant, s).
    HydraulicLag,
    /// Boom-bucket flow sharing: the bucket spool steals boom meter-in flow (fraction).
    FlowSharing,
    /// Pump flow saturation: fraction of the nominal maximum pump flow that is lost.
    PumpSaturation,
    /// Coulomb (dry) friction in every cylinder (N).
    CoulombFriction,
    /// Viscous friction in every cylinder (N s/m).
    ViscousFriction,
    /// Cross-piston internal leakage coefficient of every cylinder (m^3/(s Pa)).
    InternalLeakage,
    /// Offset added to every pressure sensor reading (Pa).
    PressureSensorOffset,
    /// Offset added to the boom, stick and bucket resolver angles (rad).
    ResolverOffset,
    /// Increase of the soil cohesion everywhere (Pa).
    SoilCohesion,
    /// Increase of the soil (bank) density everywhere (kg/m^3).
    SoilDensity,
}

/// Static description of an effect: unit, range and plain-language meaning.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EffectInfo {
    /// Registry name (snake_case), as used by `--effect NAME=VALUE`.
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

impl Effect {
    /// Every effect, in registry order.
    pub const ALL: [Effect; 12] = [
        Effect::ValveDeadband,
        Effect::TransportDelay,
        Effect::HydraulicLag,
        Effect::FlowSharing,
        Effect::PumpSaturation,
        Effect::CoulombFriction,
        Effect::ViscousFriction,
        Effect::InternalLeakage,
        Effect::PressureSensorOffset,
        Effect::ResolverOffset,
        Effect::SoilCohesion,
        Effect::SoilDensity,
    ];

    /// Index of the effect in [`Effect::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The effect's registry entry.
    pub fn info(self) -> EffectInfo {
        let (name, unit, min, max, description) = match self {
            Effect::ValveDeadband => (
                "valve_deadband",
                "fraction of full command",
                0.0,
                0.3,
                "commands with |u| below the magnitude give no spool motion; above it the spool \
                 sees sign(u) (|u| - magnitude)",
            ),
            Effect::TransportDelay => (
                "transport_delay",
                "s",
                0.0,
                0.3,
                "extra fixed delay between a valve command and spool motion, on top of the nominal delay",
            ),
            Effect::HydraulicLag => (
                "hydraulic_lag",
                "s",
                0.0,
                0.5,
                "extra first-order lag (time constant) in series with the nominal spool response",
            ),
            Effect::FlowSharing => (
                "flow_sharing",
                "fraction",
                0.0,
                1.0,
                "boom-bucket flow sharing on pump 1: the boom meter-in area is scaled by \
                 (1 - magnitude |bucket spool|), so the boom slows while the bucket moves",
            ),
            Effect::PumpSaturation => (
                "pump_saturation",
                "fraction of nominal maximum pump flow",
                0.0,
                0.6,
                "both pumps saturate at (1 - magnitude) times their nominal maximum flow",
            ),
            Effect::CoulombFriction => (
                "coulomb_friction",
                "N",
                0.0,
                50_000.0,
                "dry (Coulomb) friction force opposing motion in each of the boom, stick and bucket \
                 cylinders, with stiction at rest",
            ),
            Effect::ViscousFriction => (
                "viscous_friction",
                "N s/m",
                0.0,
                2.0e6,
                "viscous friction force (magnitude x rod velocity) in each of the boom, stick and \
                 bucket cylinders",
            ),
            Effect::InternalLeakage => (
                "internal_leakage",
                "m^3/(s Pa)",
                0.0,
                2.0e-11,
                "cross-piston leakage flow (magnitude x (head - rod pressure)) in each cylinder; \
                 1e-11 is about 0.6 L/min per MPa",
            ),
            Effect::PressureSensorOffset => (
                "pressure_sensor_offset",
                "Pa",
                -2.0e6,
                2.0e6,
                "offset added to every head, rod and pump pressure reading",
            ),
            Effect::ResolverOffset => (
                "resolver_offset",
                "rad",
                -0.1,
                0.1,
                "offset added to the boom, stick and bucket resolver angles",
            ),
            Effect::SoilCohesion => (
                "soil_cohesion",
                "Pa",
                0.0,
                100_000.0,
                "increase of the soil cohesion c (Eq. 17) in every terrain cell",
            ),
            Effect::SoilDensity => (
                "soil_density",
                "kg/m^3",
                0.0,
                1000.0,
                "increase of the soil bank density gamma (Eq. 17) in every terrain cell",
            ),
        };
        EffectInfo {
            name,
            unit,
            min,
            max,
            description,
        }
    }

    /// The registry name.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// The registry table, in order.
    pub fn registry() -> Vec<EffectInfo> {
        Self::ALL.iter().map(|e| e.info()).collect()
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Effect {
    type Err = EffectError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .iter()
            .copied()
            .find(|e| e.name() == s.trim())
            .ok_or_else(|| EffectError::Unknown(s.trim().to_owned()))
    }
}

/// A set of effect magnitudes; every effect not set is off (0).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EffectSet {
    values: [f64; 12],
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
        let info = effect.info();
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
        let effect: Effect = name.parse()?;
        self.set(effect, value)
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

/// The registry as a text table (for `--list-effects`).
pub fn registry_table() -> String {
    let mut out = format!(
        "{:<24} {:<38} {:>10} {:>10}  {}\n",
        "NAME", "UNIT", "MIN", "MAX", "DESCRIPTION"
    );
    for info in Effect::registry() {
        out.push_str(&format!(
            "{:<24} {:<38} {:>10} {:>10}  {}\n",
            info.name, info.unit, info.min, info.max, info.description
        ));
    }
    out
}

/// The registry as a JSON array of objects with `name`, `unit`, `min`, `max`, `description`.
///
/// # Errors
/// Only if JSON serialisation fails, which it cannot for these plain values.
pub fn registry_json() -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&Effect::registry())
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXPECTED_NAMES: [&str; 12] = [
        "valve_deadband",
        "transport_delay",
        "hydraulic_lag",
        "flow_sharing",
        "pump_saturation",
        "coulomb_friction",
        "viscous_friction",
        "internal_leakage",
        "pressure_sensor_offset",
        "resolver_offset",
        "soil_cohesion",
        "soil_density",
    ];

    #[test]
    fn registry_has_exactly_the_issue_names_and_zero_is_in_range() {
        let names: Vec<_> = Effect::registry().iter().map(|i| i.name).collect();
        assert_eq!(names, EXPECTED_NAMES);
        for info in Effect::registry() {
            assert!(info.min <= 0.0 && 0.0 <= info.max, "{}", info.name);
            assert!(!info.unit.is_empty() && !info.description.is_empty());
        }
        for (i, e) in Effect::ALL.iter().enumerate() {
            assert_eq!(e.index(), i);
            assert_eq!(e.name().parse::<Effect>().unwrap(), *e);
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
        assert_eq!(list.len(), 12);
        for item in list {
            for key in ["name", "unit", "min", "max", "description"] {
                assert!(item.get(key).is_some(), "{key}");
            }
        }
    }
}
