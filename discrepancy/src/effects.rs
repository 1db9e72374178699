//! The library of candidate effects: each a named physical augmentation of the grey-box model with one
//! parameter, its unit and bounds (the simulator's names, units and ranges, so a fitted magnitude
//! compares with a hidden one directly) and the signals it acts on.

use serde::Serialize;

use crate::signal::SignalGroups;

/// Number of candidate effects.
pub const N_CANDIDATES: usize = 12;

/// One candidate effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Candidate {
    /// Valve dead band: `|u|` below the magnitude gives no spool motion.
    ValveDeadband,
    /// Extra fixed command-to-spool delay.
    TransportDelay,
    /// Extra first-order lag in series with the spool response.
    HydraulicLag,
    /// Boom meter-in area scaled by `1 - m |bucket spool|` (shared pump 1).
    FlowSharing,
    /// Pumps saturating at `(1 - m)` of their nominal maximum flow.
    PumpSaturation,
    /// Dry friction with stiction in every cylinder.
    CoulombFriction,
    /// Extra viscous friction in every cylinder.
    ViscousFriction,
    /// Cross-piston leakage `m (p_h - p_r)` in every cylinder.
    InternalLeakage,
    /// Offset on every pressure reading.
    PressureSensorOffset,
    /// Offset on the boom, stick and bucket resolver readings.
    ResolverOffset,
    /// Higher soil cohesion (FEE `c`, Eq. 17).
    SoilCohesion,
    /// Higher soil density (FEE `gamma`, Eq. 17, and the payload).
    SoilDensity,
}

impl Candidate {
    /// Every candidate, in the simulator's registry order.
    pub const ALL: [Candidate; N_CANDIDATES] = [
        Candidate::ValveDeadband,
        Candidate::TransportDelay,
        Candidate::HydraulicLag,
        Candidate::FlowSharing,
        Candidate::PumpSaturation,
        Candidate::CoulombFriction,
        Candidate::ViscousFriction,
        Candidate::InternalLeakage,
        Candidate::PressureSensorOffset,
        Candidate::ResolverOffset,
        Candidate::SoilCohesion,
        Candidate::SoilDensity,
    ];

    /// Index in [`Candidate::ALL`] and in [`super::Augmentation::values`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The simulator's effect name (`excavator-sim --list-effects`).
    pub fn name(self) -> &'static str {
        match self {
            Candidate::ValveDeadband => "valve_deadband",
            Candidate::TransportDelay => "transport_delay",
            Candidate::HydraulicLag => "hydraulic_lag",
            Candidate::FlowSharing => "flow_sharing",
            Candidate::PumpSaturation => "pump_saturation",
            Candidate::CoulombFriction => "coulomb_friction",
            Candidate::ViscousFriction => "viscous_friction",
            Candidate::InternalLeakage => "internal_leakage",
            Candidate::PressureSensorOffset => "pressure_sensor_offset",
            Candidate::ResolverOffset => "resolver_offset",
            Candidate::SoilCohesion => "soil_cohesion",
            Candidate::SoilDensity => "soil_density",
        }
    }

    /// Looks a candidate up by its name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|c| c.name() == name.trim())
    }

    /// Unit of the magnitude (the simulator's).
    pub fn unit(self) -> &'static str {
        match self {
            Candidate::ValveDeadband => "fraction of full command",
            Candidate::TransportDelay | Candidate::HydraulicLag => "s",
            Candidate::FlowSharing => "fraction",
            Candidate::PumpSaturation => "fraction of nominal maximum pump flow",
            Candidate::CoulombFriction => "N",
            Candidate::ViscousFriction => "N s/m",
            Candidate::InternalLeakage => "m^3/(s Pa)",
            Candidate::PressureSensorOffset | Candidate::SoilCohesion => "Pa",
            Candidate::ResolverOffset => "rad",
            Candidate::SoilDensity => "kg/m^3",
        }
    }

    /// Search bounds of the magnitude (the simulator's ranges).
    pub fn bounds(self) -> (f64, f64) {
        match self {
            Candidate::ValveDeadband => (0.0, 0.3),
            Candidate::TransportDelay => (0.0, 0.3),
            Candidate::HydraulicLag => (0.0, 0.5),
            Candidate::FlowSharing => (0.0, 1.0),
            Candidate::PumpSaturation => (0.0, 0.6),
            Candidate::CoulombFriction => (0.0, 50_000.0),
            Candidate::ViscousFriction => (0.0, 2.0e6),
            Candidate::InternalLeakage => (0.0, 2.0e-11),
            Candidate::PressureSensorOffset => (-2.0e6, 2.0e6),
            Candidate::ResolverOffset => (-0.1, 0.1),
            Candidate::SoilCohesion => (0.0, 100_000.0),
            Candidate::SoilDensity => (0.0, 1000.0),
        }
    }

    /// Plain-language description of the physical augmentation.
    pub fn description(self) -> &'static str {
        match self {
            Candidate::ValveDeadband => {
                "valve dead band: commands below the magnitude do not move the spool, above it the \
                 spool sees sign(u) (|u| - magnitude)"
            }
            Candidate::TransportDelay => {
                "extra fixed delay between a valve command and the spool (onset of motion shifted)"
            }
            Candidate::HydraulicLag => {
                "extra first-order lag in series with the spool response (smoothed response)"
            }
            Candidate::FlowSharing => {
                "boom-bucket flow sharing on pump 1: the boom meter-in area shrinks by \
                 magnitude x |bucket spool| (boom slows while the bucket moves)"
            }
            Candidate::PumpSaturation => {
                "the pumps deliver only (1 - magnitude) of their nominal maximum flow (velocity cap \
                 and lower stand-by pressure)"
            }
            Candidate::CoulombFriction => {
                "dry friction of the magnitude opposing the motion of each cylinder, with stiction \
                 at rest"
            }
            Candidate::ViscousFriction => {
                "extra viscous friction force, magnitude x rod velocity, in each cylinder"
            }
            Candidate::InternalLeakage => {
                "cross-piston leakage magnitude x (head - rod pressure) in each cylinder (velocity \
                 deficit growing with the load pressure)"
            }
            Candidate::PressureSensorOffset => {
                "constant offset on every head, rod and pump pressure reading, also at rest"
            }
            Candidate::ResolverOffset => {
                "constant offset on the boom, stick and bucket angle readings (gravity torques do \
                 not match the measured pose)"
            }
            Candidate::SoilCohesion => {
                "the soil is more cohesive than the nominal model's: FEE cohesion c higher by the \
                 magnitude (Eq. 17)"
            }
            Candidate::SoilDensity => {
                "the soil is denser than the nominal model's: FEE density gamma and the payload \
                 higher by the magnitude (Eq. 17)"
            }
        }
    }

    /// The signal groups the candidate is fitted and scored on (the others need no recomputation when
    /// fitting it). A resolver offset also moves the gravity forces of the augmented model's replay,
    /// but is identified on the end-stop angles alone.
    pub fn groups(self) -> SignalGroups {
        let (hydraulic, force, soil) = match self {
            Candidate::ValveDeadband
            | Candidate::TransportDelay
            | Candidate::HydraulicLag
            | Candidate::FlowSharing
            | Candidate::PumpSaturation
            | Candidate::InternalLeakage => (true, false, false),
            Candidate::CoulombFriction | Candidate::ViscousFriction => (false, true, false),
            // Fitted and scored on the end-stop angles alone (the replay of the augmented model
            // also moves the gravity forces): in the force relation a common offset looks like an
            // error of the links' mass properties (A4: each link's gravity torque turns with its
            // absolute angle plus its centre-of-gravity angle) or soil left in the bucket; with no
            // offset, the forces of the 40 kPa cohesion session fitted -0.021 rad (dBIC 261).
            Candidate::ResolverOffset => (false, false, false),
            Candidate::PressureSensorOffset => (true, true, false),
            Candidate::SoilCohesion => (false, false, true),
            // Fitted and scored on the weighed payload alone (the replay of the augmented model
            // also moves the FEE forces, Eqs. 14-17, and the planner's dig model uses it there): the
            // payload is the density times the volume in the bucket, which is the capacity for a
            // full one, to a fraction of a percent (effect-free sessions: means 2545-2557 kg against
            // 2550 kg); in the soil force relation the replay's terrain left an effect-free bias
            // like -210 kg/m^3 in x, and in z the FEE and payload-weight terms nearly cancel
            // (docs/discrepancy.md, 2026-11-25 and 2026-11-26 soil effects).
            Candidate::SoilDensity => (false, false, false),
        };
        SignalGroups {
            hydraulic,
            // Cross-piston leakage changes no pump's flow balance (the meter-in flows depend on
            // the pressures alone).
            pumps: hydraulic && self != Candidate::InternalLeakage,
            force,
            soil,
            // The end-stop angles read the resolvers directly.
            stops: self == Candidate::ResolverOffset,
            // The weighed payload: the soil's density times the volume in the bucket; a pressure
            // offset shifts the cylinder forces it is weighed from.
            payload: matches!(
                self,
                Candidate::SoilDensity | Candidate::PressureSensorOffset
            ),
        }
    }

    /// A typical magnitude, the scale of the golden-section tolerance and of the uncertainty step.
    pub fn scale(self) -> f64 {
        let (lo, hi) = self.bounds();
        hi.max(-lo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bounds_contain_zero() {
        for (i, c) in Candidate::ALL.iter().enumerate() {
            assert_eq!(c.index(), i);
            assert_eq!(Candidate::from_name(c.name()), Some(*c));
            let (lo, hi) = c.bounds();
            assert!(lo <= 0.0 && 0.0 < hi, "{}", c.name());
            assert!(!c.description().is_empty() && !c.unit().is_empty());
        }
        assert_eq!(Candidate::from_name("bogus"), None);
    }
}
