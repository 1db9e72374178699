//! The payload weighed as the controller weighs it (valves neutral, implement held up): the
//! least-squares payload of the joint torques less the links' gravity and inertia (Eqs. A19-A22).

use serde::Serialize;

use super::inertia::payload_reflected_mass_per_kg;
use super::params::GreyBoxParams;
use crate::Sample;
use planner::kinematics::{JointAngles, Kinematics, payload_least_squares};

/// The payload terms of one weighing sample: what the payload signal is made of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PayloadTerms {
    /// Soil in the bucket by the replay (the volume cut, up to the capacity), m^3.
    pub volume_m3: f64,
    /// Change of the weighed payload per Pa of a common pressure-sensor offset, kg/Pa.
    pub per_offset_pa: f64,
}

/// Time the controller's Weigh lets the implement settle before it averages, s (the work cycle's
/// `weigh_settle_s` default): the oil columns ring for a while after the valves close.
pub(super) const WEIGH_SETTLE_S: f64 = 0.8;

/// Half width of the central difference of the cylinder velocities that gives the accelerations of
/// the weighing, samples: the implement's oscillation while it is weighed is about 1.5 Hz, which a
/// difference over +-0.05 s keeps (sin(0.47)/0.47 = 0.96) while it averages out the rate noise that a
/// one-sample difference amplifies (per-sample payload scatter 116-476 kg against 400 kg with it).
const WEIGH_ACCEL_HALF_SAMPLES: usize = 5;

/// Cylinder accelerations at sample `k` for the weighing (see [`WEIGH_ACCEL_HALF_SAMPLES`]), m/s^2.
pub(super) fn weigh_accel(velocity: &[[f64; 3]], samples: &[Sample], k: usize) -> [f64; 3] {
    let h = WEIGH_ACCEL_HALF_SAMPLES;
    let (Some(lo), hi) = (k.checked_sub(h), k + h) else {
        return [0.0; 3];
    };
    if hi >= samples.len() {
        return [0.0; 3];
    }
    let dt = samples[hi].time_s - samples[lo].time_s;
    if dt <= 0.0 {
        return [0.0; 3];
    }
    [0, 1, 2].map(|i| (velocity[hi][i] - velocity[lo][i]) / dt)
}

/// Smallest bucket fill (fraction of the capacity, by the replay's cut volume) that is weighed.
pub(super) const WEIGH_MIN_FILL: f64 = 0.95;

/// Fraction of a cylinder's stroke at either end within which it does not take part in the weighing
/// (the controller's `weigh_stroke_end_margin`): a cylinder on its end stop carries an unknown force.
const WEIGH_STROKE_END_MARGIN: f64 = 0.01;

/// The payload estimate of one sample, kg, and its change per Pa of a common pressure offset: the
/// least-squares mass `m` of `tau - M acc - g0 = m (a + r b acc)` over the cylinders away from their
/// stroke ends (`tau` the joint torques of the Eq. A20 forces, Eqs. A21-A22; `M acc` the links'
/// reflected inertia; `g0` the links' gravity torques and `a` the gravity torque per kg of payload at
/// its centroid, Eq. A19; `r b acc` the payload's own inertia per kg, Eq. A1 with the payload as a
/// body). The controller weighs statically and averages over whole periods of the implement's
/// oscillation on its oil columns (about 1.5 Hz, +-40 % of the payload); per sample, the inertia
/// takes that oscillation out.
#[allow(clippy::too_many_arguments)]
pub(super) fn weighed_payload(
    kin: &Kinematics,
    params: &GreyBoxParams,
    s: &Sample,
    q: &JointAngles,
    arms: &[f64; 3],
    len: &[f64; 3],
    strokes: &[(f64, f64); 3],
    (mass, accel): ([f64; 3], [f64; 3]),
) -> Option<(f64, f64)> {
    let g0 = kin.gravity_torques(q, 0.0);
    let a = kin.gravity_torques(q, 1.0) - g0;
    let per_kg = payload_reflected_mass_per_kg(kin, q)?;
    let usable = [0, 1, 2].map(|i| {
        let (lo, hi) = strokes[i];
        let e = (len[i] - lo) / (hi - lo);
        e > WEIGH_STROKE_END_MARGIN && e < 1.0 - WEIGH_STROKE_END_MARGIN
    });
    let regressor = [0, 1, 2].map(|i| a[i] + arms[i] * per_kg[i] * accel[i]);
    let excess = [0, 1, 2].map(|i| {
        let force = s.head_pa[i] * params.head_area_m2[i] - s.rod_pa[i] * params.rod_area_m2[i]; // Eq. A20
        arms[i] * (force - mass[i] * accel[i]) - g0[i]
    });
    // A common offset adds `(A_h - A_r) offset` to every force (A20).
    let per_pa_torque =
        [0, 1, 2].map(|i| arms[i] * (params.head_area_m2[i] - params.rod_area_m2[i]));
    let m = payload_least_squares(&regressor, &excess, usable)?;
    let per_pa = payload_least_squares(&regressor, &per_pa_torque, usable)?;
    Some((m, per_pa))
}

#[cfg(test)]
mod tests {
    use super::super::inertia::cylinder_masses;
    use super::*;
    use nalgebra::Vector3;
    use planner::kinematics::{Joint, TipForce};
    use planner::machine::MachineConfig;

    /// The weighing recovers the payload that set the pressures (the cylinder forces of a held
    /// payload, Eq. A19, as head or rod pressure), statically and while the implement accelerates
    /// (the links' and the payload's reflected inertia added to the forces), leaves out a cylinder
    /// at its stroke end, and its offset term is the estimate's change for a common pressure offset.
    #[test]
    fn weighing_recovers_the_held_payload() {
        let cfg = MachineConfig::default_machine().unwrap();
        let kin = Kinematics::new(&cfg).unwrap();
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let q = JointAngles {
            boom_rad: 0.5,
            stick_rad: -1.2,
            bucket_rad: -0.6,
        };
        let strokes = Joint::ALL.map(|j| kin.stroke(j));
        let len = kin.cylinder_lengths(&q).unwrap().to_vector();
        let len = [len[0], len[1], len[2]];
        let arms = kin.moment_arms(&q).unwrap();
        let arms = [arms[0], arms[1], arms[2]];
        let mass = cylinder_masses(
            &kin,
            &cfg,
            &params.inertia_floor_kg_m2,
            &q,
            &Vector3::from(arms),
        );
        let per_kg = payload_reflected_mass_per_kg(&kin, &q).unwrap();
        let payload_kg = cfg.rated_payload_kg();
        let sample_for = |accel: [f64; 3], offset_pa: f64| {
            let held = kin
                .cylinder_forces_from_tip_force(&q, &TipForce::default(), payload_kg)
                .unwrap();
            let mut s = crate::Sample::default();
            for i in 0..3 {
                let f = held[i] + (mass[i] + payload_kg * per_kg[i]) * accel[i];
                if f >= 0.0 {
                    s.head_pa[i] = f / params.head_area_m2[i];
                } else {
                    s.rod_pa[i] = -f / params.rod_area_m2[i];
                }
                s.head_pa[i] += offset_pa;
                s.rod_pa[i] += offset_pa;
            }
            s
        };
        let weigh = |s: &crate::Sample, accel: [f64; 3], len: &[f64; 3]| {
            weighed_payload(&kin, &params, s, &q, &arms, len, &strokes, (mass, accel)).unwrap()
        };
        let (m, per_pa) = weigh(&sample_for([0.0; 3], 0.0), [0.0; 3], &len);
        assert!((m - payload_kg).abs() < 1e-6 * payload_kg, "static: {m} kg");
        let accel = [0.3, -0.2, 0.4];
        let (m, _) = weigh(&sample_for(accel, 0.0), accel, &len);
        // The payload's inertia enters the least squares through its regressor: exact up to the
        // weighting of the cylinders.
        assert!(
            (m - payload_kg).abs() < 1e-3 * payload_kg,
            "accelerating: {m} kg"
        );
        // A common offset moves the estimate by its offset term.
        let offset = 2.0e5;
        let (m_off, _) = weigh(&sample_for([0.0; 3], offset), [0.0; 3], &len);
        assert!(
            (m_off - payload_kg - offset * per_pa).abs() < 1e-6 * payload_kg,
            "offset: {m_off} kg, per Pa {per_pa}"
        );
        // About 10 kg for a 0.2 MPa offset on this pose.
        assert!(
            per_pa.abs() > 1e-5,
            "the offset term is not negligible: {per_pa}"
        );
        // A cylinder at its stroke end does not take part: the other two still weigh the payload.
        let mut at_end = len;
        at_end[2] = strokes[2].1;
        let (m_end, _) = weigh(&sample_for([0.0; 3], 0.0), [0.0; 3], &at_end);
        assert!(
            (m_end - payload_kg).abs() < 1e-6 * payload_kg,
            "at the end: {m_end} kg"
        );
    }
}
