//! The catalogue of hidden physical effects: phenomena a real machine has and the nominal models do
//! not, each with its name, the unit and range of its magnitude and what it does.
//!
//! One catalogue for the whole stack: the simulator applies these effects to its plant
//! (`vcan_sim::effects`, `--effect NAME=VALUE`) and the discrepancy workflow names them when it finds
//! them in measured sessions (its candidate library), so a fitted magnitude compares with a hidden one
//! directly. A magnitude is added on top of the nominal machine, so 0 is always "off".

use std::fmt;

use serde::Serialize;

/// Number of effects in the catalogue.
pub const N_EFFECTS: usize = 12;

/// One hidden effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
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

impl Effect {
    /// Every effect, in catalogue order.
    pub const ALL: [Effect; N_EFFECTS] = [
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

    /// The effect's name (snake_case), as `--effect NAME=VALUE` and the reports spell it.
    pub fn name(self) -> &'static str {
        match self {
            Effect::ValveDeadband => "valve_deadband",
            Effect::TransportDelay => "transport_delay",
            Effect::HydraulicLag => "hydraulic_lag",
            Effect::FlowSharing => "flow_sharing",
            Effect::PumpSaturation => "pump_saturation",
            Effect::CoulombFriction => "coulomb_friction",
            Effect::ViscousFriction => "viscous_friction",
            Effect::InternalLeakage => "internal_leakage",
            Effect::PressureSensorOffset => "pressure_sensor_offset",
            Effect::ResolverOffset => "resolver_offset",
            Effect::SoilCohesion => "soil_cohesion",
            Effect::SoilDensity => "soil_density",
        }
    }

    /// Looks an effect up by its name (surrounding white space ignored).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|e| e.name() == name.trim())
    }

    /// Unit of the magnitude.
    pub fn unit(self) -> &'static str {
        match self {
            Effect::ValveDeadband => "fraction of full command",
            Effect::TransportDelay | Effect::HydraulicLag => "s",
            Effect::FlowSharing => "fraction",
            Effect::PumpSaturation => "fraction of nominal maximum pump flow",
            Effect::CoulombFriction => "N",
            Effect::ViscousFriction => "N s/m",
            Effect::InternalLeakage => "m^3/(s Pa)",
            Effect::PressureSensorOffset | Effect::SoilCohesion => "Pa",
            Effect::ResolverOffset => "rad",
            Effect::SoilDensity => "kg/m^3",
        }
    }

    /// Smallest and largest allowed magnitude `(min, max)`; 0 (off) is always inside.
    pub fn range(self) -> (f64, f64) {
        match self {
            Effect::ValveDeadband => (0.0, 0.3),
            Effect::TransportDelay => (0.0, 0.3),
            Effect::HydraulicLag => (0.0, 0.5),
            Effect::FlowSharing => (0.0, 1.0),
            Effect::PumpSaturation => (0.0, 0.6),
            Effect::CoulombFriction => (0.0, 50_000.0),
            Effect::ViscousFriction => (0.0, 2.0e6),
            Effect::InternalLeakage => (0.0, 2.0e-11),
            Effect::PressureSensorOffset => (-2.0e6, 2.0e6),
            Effect::ResolverOffset => (-0.1, 0.1),
            Effect::SoilCohesion => (0.0, 100_000.0),
            Effect::SoilDensity => (0.0, 1000.0),
        }
    }

    /// What the effect does to the machine, in plain language.
    pub fn description(self) -> &'static str {
        match self {
            Effect::ValveDeadband => {
                "commands with |u| below the magnitude give no spool motion; above it the spool \
                 sees sign(u) (|u| - magnitude)"
            }
            Effect::TransportDelay => {
                "extra fixed delay between a valve command and spool motion, on top of the nominal delay"
            }
            Effect::HydraulicLag => {
                "extra first-order lag (time constant) in series with the nominal spool response"
            }
            Effect::FlowSharing => {
                "boom-bucket flow sharing on pump 1: the boom meter-in area is scaled by \
                 (1 - magnitude |bucket spool|), so the boom slows while the bucket moves"
            }
            Effect::PumpSaturation => {
                "both pumps saturate at (1 - magnitude) times their nominal maximum flow"
            }
            Effect::CoulombFriction => {
                "dry (Coulomb) friction force opposing motion in each of the boom, stick and bucket \
                 cylinders, with stiction at rest"
            }
            Effect::ViscousFriction => {
                "viscous friction force (magnitude x rod velocity) in each of the boom, stick and \
                 bucket cylinders"
            }
            Effect::InternalLeakage => {
                "cross-piston leakage flow (magnitude x (head - rod pressure)) in each cylinder; \
                 1e-11 is about 0.6 L/min per MPa"
            }
            Effect::PressureSensorOffset => {
                "offset added to every head, rod and pump pressure reading"
            }
            Effect::ResolverOffset => "offset added to the boom, stick and bucket resolver angles",
            Effect::SoilCohesion => {
                "increase of the soil cohesion c (Eq. 17) in every terrain cell"
            }
            Effect::SoilDensity => {
                "increase of the soil bank density gamma (Eq. 17) in every terrain cell"
            }
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names users type and the reports print, in catalogue order.
    const EXPECTED_NAMES: [&str; N_EFFECTS] = [
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
    fn names_round_trip_and_zero_is_in_every_range() {
        let names: Vec<_> = Effect::ALL.iter().map(|e| e.name()).collect();
        assert_eq!(names, EXPECTED_NAMES);
        for (i, e) in Effect::ALL.iter().enumerate() {
            assert_eq!(e.index(), i);
            assert_eq!(Effect::from_name(&format!(" {} ", e.name())), Some(*e));
            assert_eq!(e.to_string(), e.name());
            let (min, max) = e.range();
            assert!(min <= 0.0 && 0.0 < max, "{e}");
            assert!(!e.unit().is_empty() && !e.description().is_empty());
        }
        assert_eq!(Effect::from_name("bogus"), None);
    }

    #[test]
    fn serialises_as_its_name() {
        for e in Effect::ALL {
            assert_eq!(
                serde_json::to_string(&e).expect("a unit variant serialises"),
                format!("\"{}\"", e.name())
            );
        }
    }
}
