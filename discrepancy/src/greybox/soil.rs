//! The soil relation's terms: the soil force on the bucket measured from the pressures (Eqs.
//! A20-A23) against the modified FEE on the section cut so far (Eqs. 14-18, [`crate::soil_replay`]),
//! affine in the soil's cohesion and density.

use nalgebra::Vector3;
use serde::Serialize;

use super::inertia::payload_reflected_mass_per_kg;
use super::params::GreyBoxParams;
use crate::Sample;
use crate::soil_replay::{self, CutSection};
use planner::kinematics::{JointAngles, Kinematics};
use planner::machine::MachineConfig;
use planner::soil::{BearingParams, BucketMotion, SoilProperties};

/// The soil terms of one sample (base frame `[x, z]`, N): what the soil signals are made of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SoilTerms {
    /// Measured soil force on the bucket at zero payload (Eqs. A20-A23).
    pub measured0: [f64; 2],
    /// Change of the measured soil force per kg of payload.
    pub measured_per_kg: [f64; 2],
    /// Soil in the bucket (the volume cut less what spilled, up to the capacity), m^3.
    pub payload_volume_m3: f64,
    /// Vertical depth of the edge below the cut surface, m.
    pub depth_m: f64,
    /// Terrain slope at the edge, `tan(alpha)`.
    pub slope_tan: f64,
    /// Modelled soil force at the nominal soil.
    pub fee0: [f64; 2],
    /// Its change per Pa of cohesion.
    pub fee_per_pa: [f64; 2],
    /// Its change per kg/m^3 of density.
    pub fee_per_density: [f64; 2],
}

/// Slowest tip speed at which a sample enters the soil signals, m/s: the soil force builds up from
/// rest over the creep speed (1 cm/s), so below a few times it the force hangs on the speed itself;
/// a stalled bucket's force is that of whatever holds it.
const SOIL_MOVING_SPEED_M_PER_S: f64 = 0.05;

/// Uncertainty of the replay's terrain slope `tan(alpha)` at the edge (the section's 0.1 m medians
/// cut by the measured edge path, differenced over +-[`soil_replay::SLOPE_HALF_BASE_M`]).
const SLOPE_TRUST_TAN: f64 = 0.1;

/// Largest change of the modelled soil force (either component) that an error of
/// [`SLOPE_TRUST_TAN`] in the slope may make for a sample to enter the soil signals, N: about the
/// relation's own residual RMS in the Dig stage of the effect-free sessions (8-10 kN).
const SLOPE_SENSITIVITY_N: f64 = 1.0e4;

/// Slowest speed at which a bearing (the edge pushed in tip first, the back pushed against the soil)
/// counts as surely pushed in or drawn away for a sample to enter the soil signals, in creep speeds
/// (the speed over which it is mobilised, `planner::soil::BearingParams`, 1 cm/s; `tanh 5` is 1 to
/// 5e-5). Slower, the bearing is mobilised part way and holds whatever the cylinders push, up to its
/// capacity: a constraint force, which the replay puts on or off by the sign of the measured rates
/// and their noise (a 40 kPa cohesion session: the simulator's edge bearing of 120 kN capacity
/// held the bucket at 70-115 kN while the replay switched it on and off from one sample to the
/// next).
const BEARING_SURE_CREEP_SPEEDS: f64 = 5.0;

/// Whether both bearings of `motion` are surely on or off: each pushed in or drawn away at
/// [`BEARING_SURE_CREEP_SPEEDS`] creep speeds or more.
fn bearings_sure(motion: &BucketMotion, bearing: &BearingParams) -> bool {
    let sure = BEARING_SURE_CREEP_SPEEDS * bearing.creep_speed_m_per_s;
    motion
        .bearing_speeds_m_per_s()
        .iter()
        .all(|v| v.abs() >= sure)
}

/// Fill (share of the bucket's capacity) from which a sample leaves the soil signals: a full bucket
/// spills what the edge cuts beyond its capacity around the edge, and the simulator's and the
/// machine's edge then meets that pile (a slope at the edge of `tan -1.2` to `-2.0`), which this
/// replay does not build (its slope there `tan -3.2` to `-4.0`, with a modelled force of 2-15 kN
/// against 55-80 kN).
pub(super) const SOIL_MAX_FILL: f64 = 0.93;

/// The soil terms of one sample: the measured tip force (Eqs. A20-A23 from the pressures, less
/// inertia and seal damping) at zero payload and per kg of payload, and the modelled soil force
/// ([`soil_replay`]) on the section cut so far, at nominal soil and per unit of cohesion and density
/// (the force is affine in both: Eqs. 14-17 and the bearing pressure are linear in `c` and `gamma`).
#[allow(clippy::too_many_arguments)]
pub(super) fn soil_terms_of(
    kin: &Kinematics,
    cfg: &MachineConfig,
    params: &GreyBoxParams,
    s: &Sample,
    section: &CutSection,
    tip_velocity: [f64; 2],
    velocity: [f64; 3],
    accel: [f64; 3],
    mass: [f64; 3],
) -> Option<SoilTerms> {
    let q = JointAngles {
        boom_rad: s.angles_rad[0],
        stick_rad: s.angles_rad[1],
        bucket_rad: s.angles_rad[2],
    };
    let pose = kin.forward(&q);
    if tip_velocity[0].hypot(tip_velocity[1]) < SOIL_MOVING_SPEED_M_PER_S {
        return None;
    }
    if section.content_m3() >= SOIL_MAX_FILL * cfg.bucket.capacity_m3 {
        return None;
    }
    let width = cfg.bucket.width_m;
    // What the bucket holds: the volume cut from the terrain less what spilled (at most the
    // capacity; the spill is on the section).
    let volume = section.content_m3().clamp(0.0, cfg.bucket.capacity_m3);
    let motion = section.motion([pose.x_m, pose.z_m], pose.bucket_abs_rad, tip_velocity)?;
    if motion.vertical_depth_m <= 0.0 {
        return None;
    }
    if !bearings_sure(&motion, &params.bearing) {
        return None;
    }
    // Measured soil force: Eq. A20 forces less inertia and seal damping, then Eq. A23.
    let forces = Vector3::from_fn(|i, _| {
        s.head_pa[i] * params.head_area_m2[i]
            - s.rod_pa[i] * params.rod_area_m2[i]
            - mass[i] * accel[i]
            - params.damping_n_s_per_m * velocity[i]
    });
    // The payload moves with the bucket: its inertia adds to every joint's (Eq. A1 with the payload
    // as a body at its centroid), so a loaded cylinder needs `m_p (d^2 + k^2) / r^2 a` more force
    // to accelerate, linear in the payload like its weight. Without it the inertia subtracted in
    // the Dig stage was short by the payload's part (the boom's reflected mass is about 0.5e6 kg
    // and its mean `M a` over the stage about -47 kN in the effect-free session none_s200), which
    // biased the measured soil force by -2.6 / +2.6 kN (x / z), like a soil 300 kg/m^3 lighter
    // (docs/discrepancy.md, 2026-11-25 soil effects).
    let per_kg = payload_reflected_mass_per_kg(kin, &q)?;
    let loaded = Vector3::from_fn(|i, _| forces[i] - 1000.0 * per_kg[i] * accel[i]);
    let f0 = kin.tip_force_from_cylinder_forces(&q, &forces, 0.0).ok()?;
    let f1 = kin
        .tip_force_from_cylinder_forces(&q, &loaded, 1000.0)
        .ok()?;
    let force =
        |psi: &SoilProperties| soil_replay::soil_force(psi, &params.bearing, width, &motion);
    let base = force(&params.soil)?;
    // Only where the replay's terrain is good enough for the force: near the wedge limit Eq. 17's
    // slope terms make the force steep in the slope at the edge, which the replay knows to about
    // SLOPE_TRUST_TAN (effect-free sessions: residuals of -16 to -53 kN where the modelled force
    // rose fastest with density, on the flatter faces, against +-2 kN elsewhere).
    for d in [-SLOPE_TRUST_TAN, SLOPE_TRUST_TAN] {
        let mut tilted = motion;
        tilted.slope_tan += d;
        let g = soil_replay::soil_force(&params.soil, &params.bearing, width, &tilted)?;
        if (g[0] - base[0]).abs().max((g[1] - base[1]).abs()) > SLOPE_SENSITIVITY_N {
            return None;
        }
    }
    let mut more_c = params.soil;
    more_c.cohesion_pa += 1000.0;
    let mut more_gamma = params.soil;
    more_gamma.density_kg_per_m3 += 100.0;
    let fc = force(&more_c)?;
    let fg = force(&more_gamma)?;
    let k = params.soil_force_factor;
    let out = SoilTerms {
        measured0: [f0.fx_n, f0.fz_n],
        measured_per_kg: [(f1.fx_n - f0.fx_n) / 1000.0, (f1.fz_n - f0.fz_n) / 1000.0],
        payload_volume_m3: volume,
        depth_m: motion.vertical_depth_m,
        slope_tan: motion.slope_tan,
        fee0: [k * base[0], k * base[1]],
        fee_per_pa: [
            k * (fc[0] - base[0]) / 1000.0,
            k * (fc[1] - base[1]) / 1000.0,
        ],
        fee_per_density: [k * (fg[0] - base[0]) / 100.0, k * (fg[1] - base[1]) / 100.0],
    };
    let all = out
        .measured0
        .iter()
        .chain(&out.measured_per_kg)
        .chain(&out.fee0)
        .chain(&out.fee_per_pa)
        .chain(&out.fee_per_density)
        .all(|v| v.is_finite());
    all.then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bucket dragged toward the machine along its opening is surely on neither bearing's push;
    /// the same drag with the edge pushed in (or drawn out) at under five creep speeds along the
    /// blade is not sure, at more it is; a NaN velocity is never sure.
    #[test]
    fn a_bearing_mobilised_part_way_is_not_sure() {
        let bearing = BearingParams::default();
        let creep = bearing.creep_speed_m_per_s;
        // The bucket line at -90 degrees (tip below the pin): the blade points up (+z), the
        // opening toward the machine (-x).
        let at = |v: [f64; 2]| BucketMotion {
            sin_bucket_abs: -1.0,
            cos_bucket_abs: 0.0,
            tip_velocity_m_per_s: v,
            vertical_depth_m: 0.3,
            slope_tan: 0.0,
            swept_volume_m3: 0.0,
        };
        assert_eq!(at([-0.3, 0.0]).bearing_speeds_m_per_s(), [0.0, -0.3]);
        assert!(!bearings_sure(&at([-0.3, 0.0]), &bearing));
        for vz in [-4.9 * creep, -0.5 * creep, 0.5 * creep, 4.9 * creep] {
            assert!(!bearings_sure(&at([-0.3, vz]), &bearing), "vz = {vz}");
        }
        for vz in [-5.1 * creep, 5.1 * creep, -0.2, 0.2] {
            assert!(bearings_sure(&at([-0.3, vz]), &bearing), "vz = {vz}");
        }
        assert!(!bearings_sure(&at([f64::NAN, 0.2]), &bearing));
    }
}
