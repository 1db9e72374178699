//! The library of candidate effects: every effect of the catalogue ([`planner::effects`]: the
//! simulator's names, units and ranges, so a fitted magnitude compares with a hidden one directly) as
//! a one-parameter augmentation of the grey-box model, with how the model adds it and the signals it
//! acts on ([`CandidateEffect`]).

use crate::signal::SignalGroups;

/// A candidate effect: an effect of the catalogue.
pub use planner::effects::Effect as Candidate;
/// Number of candidate effects: the catalogue's.
pub use planner::effects::N_EFFECTS as N_CANDIDATES;

/// What the candidate library adds to a catalogue effect: how the grey-box model represents it,
/// which signals it acts on and the scale of its fit. Its name, unit and bounds (the catalogue's
/// range) are the catalogue's.
pub trait CandidateEffect {
    /// How the grey-box model adds the effect, in plain language (the reports' description).
    fn model_description(self) -> &'static str;

    /// The signal groups the candidate is fitted and scored on (the others need no recomputation
    /// when fitting it).
    fn groups(self) -> SignalGroups;

    /// A typical magnitude, the scale of the golden-section tolerance and of the uncertainty step.
    fn scale(self) -> f64;
}

impl CandidateEffect for Candidate {
    fn model_description(self) -> &'static str {
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

    /// A resolver offset also moves the gravity forces of the augmented model's replay, but is
    /// identified on the end-stop angles alone.
    fn groups(self) -> SignalGroups {
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

    fn scale(self) -> f64 {
        let (lo, hi) = self.range();
        hi.max(-lo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vcan_sim::effects::registry;

    /// The candidate library and the simulator do not drift apart: every effect the simulator can
    /// hide is a candidate of the same name, unit and range, and every candidate is one of them.
    #[test]
    fn every_simulator_effect_is_a_candidate_of_the_same_name_unit_and_range() {
        let simulator = registry();
        assert_eq!(simulator.len(), N_CANDIDATES);
        for info in simulator {
            let c = Candidate::from_name(info.name)
                .unwrap_or_else(|| panic!("no candidate named {}", info.name));
            assert_eq!(c.unit(), info.unit, "{}", info.name);
            assert_eq!(c.range(), (info.min, info.max), "{}", info.name);
            assert!(!c.model_description().is_empty(), "{}", info.name);
        }
    }
}
