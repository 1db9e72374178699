//! Synthetic data with a known truth, for the crate's tests, its examples and the benches (not for
//! the machine): digs of a simple hydraulic plant for the actuator networks (4.2.3), and digs whose
//! soil forces come from the modified FEE for the soil-property estimators (4.3.5). Deterministic
//! for a seed. Compiled for the tests and with the crate's `synthetic` feature.

use crate::actuator::{ActuatorDig, ActuatorSample};
use crate::estimate::SoilSample;
use crate::kinematics::TipForce;
use crate::soil::{DigGeometry, SoilProperties, fee_tip_force};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Sample period of the synthetic actuator digs, s.
pub const ACTUATOR_DT_S: f64 = 0.02;
/// Fixed command delay of the synthetic plant, steps.
pub const ACTUATOR_DELAY_STEPS: usize = 2;
/// Maximum cylinder speed of the synthetic plant, m/s.
pub const ACTUATOR_V_MAX_M_PER_S: f64 = 0.25;
/// Relief-level force of the synthetic plant, N.
const F_RELIEF: f64 = 3.0e5;
/// First-order lag of the synthetic plant, s.
const TAU_S: f64 = 0.15;

/// A smooth random signal in `[-amplitude, amplitude]`: a low-passed random staircase.
#[must_use]
pub fn smooth_signal(
    rng: &mut ChaCha8Rng,
    steps: usize,
    amplitude: f64,
    hold_steps: usize,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(steps);
    let (mut level, mut value) = (0.0, 0.0);
    for k in 0..steps {
        if k % hold_steps == 0 {
            level = rng.random_range(-amplitude..amplitude);
        }
        value += 0.2 * (level - value);
        out.push(value);
    }
    out
}

/// `count` digs of `steps` samples (every [`ACTUATOR_DT_S`]) of synthetic hydraulics driven by smooth
/// random commands and forces: delay, first-order lag, force-dependent orifice flow (Eq. 1), and the
/// bucket taking flow from the boom (shared pump, 4.2.1).
#[must_use]
pub fn actuator_digs(count: usize, steps: usize, seed: u64) -> Vec<ActuatorDig> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let u: Vec<Vec<f64>> = (0..3)
                .map(|_| smooth_signal(&mut rng, steps, 1.0, 25))
                .collect();
            let f: Vec<Vec<f64>> = (0..3)
                .map(|_| {
                    smooth_signal(&mut rng, steps, 1.5e5, 40)
                        .iter()
                        .map(|x| x + 5.0e4)
                        .collect()
                })
                .collect();
            let mut v = [0.0_f64; 3];
            let mut samples = Vec::with_capacity(steps);
            for k in 0..steps {
                let command = [u[0][k], u[1][k], u[2][k]];
                let force_n = [f[0][k], f[1][k], f[2][k]];
                samples.push(ActuatorSample {
                    time_s: k as f64 * ACTUATOR_DT_S,
                    command,
                    force_n,
                    velocity_m_per_s: v,
                });
                let d = k.saturating_sub(ACTUATOR_DELAY_STEPS);
                for j in 0..3 {
                    let ud = u[j][d];
                    // Force against the motion lowers the pressure margin across the valve.
                    let against = (-ud.signum() * f[j][k]).max(-F_RELIEF);
                    let margin = (1.0 - against / F_RELIEF).clamp(0.0, 2.0);
                    let mut target = ACTUATOR_V_MAX_M_PER_S * ud * margin.sqrt() / 2f64.sqrt();
                    if j == 0 {
                        target *= 1.0 - 0.3 * u[2][d].abs();
                    }
                    v[j] += ACTUATOR_DT_S / TAU_S * (target - v[j]);
                }
            }
            ActuatorDig { samples }
        })
        .collect()
}

/// Bucket width of the FEE digs, m.
pub const FEE_BUCKET_WIDTH_M: f64 = 1.5;
/// Samples per FEE dig (5 s at 10 Hz, as in 4.3.5).
pub const FEE_DIG_SAMPLES: usize = 50;

/// The soil of the FEE digs, the truth the estimators should recover.
#[must_use]
pub fn fee_soil() -> SoilProperties {
    SoilProperties {
        density_kg_per_m3: 1800.0,
        failure_angle_rad: 35f64.to_radians(),
        friction_angle_rad: 30f64.to_radians(),
        tool_friction_angle_rad: 18f64.to_radians(),
        cohesion_pa: 25e3,
    }
}

/// Geometry of a dig: depth rises then falls, the bucket curls (rake from -60 to -20 degrees), the
/// swept volume accumulates; the slope differs per dig.
#[must_use]
pub fn dig_geometries(rng: &mut ChaCha8Rng) -> Vec<DigGeometry> {
    let slope = rng.random_range(5f64.to_radians()..35f64.to_radians());
    let depth_max = rng.random_range(0.3..0.8);
    let mut vs = 0.0;
    (0..FEE_DIG_SAMPLES)
        .map(|k| {
            let s = k as f64 / (FEE_DIG_SAMPLES - 1) as f64;
            let depth = depth_max * (std::f64::consts::PI * s).sin() + 0.02;
            vs += depth * 0.04;
            DigGeometry {
                depth_m: depth,
                slope_rad: slope + rng.random_range(-0.05..0.05),
                rake_rad: (-60.0 + 40.0 * s + rng.random_range(-3.0..3.0)).to_radians(),
                swept_volume_m3: vs,
            }
        })
        .collect()
}

/// `force` with uniform noise of `+-noise_n` on each component (none for `noise_n <= 0`).
#[must_use]
pub fn with_noise(force: TipForce, rng: &mut ChaCha8Rng, noise_n: f64) -> TipForce {
    if noise_n <= 0.0 {
        return force;
    }
    TipForce {
        fx_n: force.fx_n + rng.random_range(-noise_n..noise_n),
        fz_n: force.fz_n + rng.random_range(-noise_n..noise_n),
        my_nm: force.my_nm + rng.random_range(-noise_n..noise_n),
    }
}

/// `count` digs of [`FEE_DIG_SAMPLES`] samples: [`dig_geometries`] with the modified FEE's forces
/// (Eqs. 14-19) on [`fee_soil`] for a [`FEE_BUCKET_WIDTH_M`] bucket, plus [`with_noise`].
#[must_use]
pub fn fee_digs(count: usize, noise_n: f64, seed: u64) -> Vec<Vec<SoilSample>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            dig_geometries(&mut rng)
                .into_iter()
                .map(|geometry| {
                    // Cannot fail: the geometries stay inside the FEE's domain (depth 2-82 cm,
                    // rake -63 to -17 degrees, slope about 2-38 degrees).
                    let f = fee_tip_force(&fee_soil(), &geometry, FEE_BUCKET_WIDTH_M, 0.4)
                        .expect("the FEE holds on these geometries");
                    SoilSample {
                        geometry,
                        force: with_noise(f, &mut rng, noise_n),
                    }
                })
                .collect()
        })
        .collect()
}
