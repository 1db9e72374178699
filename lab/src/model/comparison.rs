//! The dig model against one simulated dig from the same start over the same section (thesis Figs.
//! 34, 40, 41): trajectory, time, energy and swept-volume errors ([`DigComparison`]).

use anyhow::Context as _;
use planner::dig_model::{DigModel, DigPrediction, DigSite, DigStart};
use serde::{Deserialize, Serialize};

use super::sim_dig::{SimDig, SimSample};

/// Model-versus-simulator figures of one dig (thesis Figs. 34, 40, 41).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigComparison {
    /// Dig number.
    pub index: usize,
    /// RMS distance between the predicted and measured tip paths (symmetric nearest-point), m.
    pub trajectory_rms_m: f64,
    /// Measured and predicted dig time, s.
    pub time_s: [f64; 2],
    /// Measured and predicted energy, kJ.
    pub energy_kj: [f64; 2],
    /// Measured and predicted swept volume, m^3.
    pub volume_m3: [f64; 2],
    /// Relative errors (model - measured) / measured, %: time, energy, volume.
    pub error_percent: [f64; 3],
    /// Measured and predicted end reasons.
    pub end: [String; 2],
    /// Open-loop soil force error: RMS of `|F_model - F_sim|` over the simulated dig's samples in
    /// contact, with the model's soil force at the simulator's true pose, motion, terrain and bucket
    /// content, as a % of the RMS simulated force (`None` without the diagnosis).
    pub soil_force_error_percent: Option<f64>,
    /// Measured and predicted lowest tip elevation, m.
    pub min_tip_z_m: [f64; 2],
}

/// Distance from `p` to the polyline `line`, m.
fn distance_to_polyline(p: [f64; 2], line: &[[f64; 2]]) -> f64 {
    if line.len() == 1 {
        return (p[0] - line[0][0]).hypot(p[1] - line[0][1]);
    }
    line.windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let len2 = d[0] * d[0] + d[1] * d[1];
            let t = if len2 > 0.0 {
                (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
        })
        .fold(f64::INFINITY, f64::min)
}

/// Symmetric RMS distance between two paths, m (each point of one to the other polyline).
#[must_use]
pub fn path_rms_m(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    let sq = |from: &[[f64; 2]], to: &[[f64; 2]]| {
        from.iter()
            .map(|p| distance_to_polyline(*p, to).powi(2))
            .sum::<f64>()
            / from.len() as f64
    };
    (0.5 * (sq(a, b) + sq(b, a))).sqrt()
}

fn percent(model: f64, measured: f64) -> f64 {
    if measured.abs() > 1e-12 {
        100.0 * (model - measured) / measured
    } else {
        0.0
    }
}

/// Runs the dig model from the simulator's start (joint angles when Autodig began) over its pre-dig
/// section and compares.
///
/// # Errors
/// The dig model's errors.
pub fn compare_dig(
    model: &DigModel,
    sim: &SimDig,
) -> anyhow::Result<(DigComparison, DigPrediction)> {
    let mut model = model.clone();
    model.set_hardness_index(sim.setup.hardness_index)?;
    model.set_force_factor(sim.setup.soil_force_factor)?;
    let site = DigSite::new(sim.profile.clone(), 0.0)?;
    let pred = model
        .predict(&DigStart::Joints(sim.start_joints), &site)
        .with_context(|| format!("dig model, dig {}", sim.setup.index))?;
    let measured: Vec<[f64; 2]> = sim.samples.iter().map(|s| [s.tip_x_m, s.tip_z_m]).collect();
    let predicted: Vec<[f64; 2]> = pred
        .samples
        .iter()
        .map(|s| [s.tip_x_m, s.tip_z_m])
        .collect();
    let s = &pred.summary;
    let cmp = DigComparison {
        index: sim.setup.index,
        trajectory_rms_m: path_rms_m(&measured, &predicted),
        time_s: [sim.time_s, s.time_s],
        energy_kj: [sim.energy_j * 1e-3, s.energy_kj()],
        volume_m3: [sim.swept_volume_m3, s.swept_volume_m3],
        error_percent: [
            percent(s.time_s, sim.time_s),
            percent(s.energy_j, sim.energy_j),
            percent(s.swept_volume_m3, sim.swept_volume_m3),
        ],
        end: [
            sim.end
                .map_or_else(|| "time limit".to_owned(), |e| format!("{e:?}")),
            format!("{:?}", s.end),
        ],
        soil_force_error_percent: open_loop_soil_error_percent(&sim.samples),
        min_tip_z_m: [
            sim.samples
                .iter()
                .map(|s| s.tip_z_m)
                .fold(f64::INFINITY, f64::min),
            s.min_tip_z_m,
        ],
    };
    Ok((cmp, pred))
}

/// RMS of the open-loop soil force error over the samples with a simulated soil force, as a % of the
/// RMS simulated force (`None` without model forces or contact).
fn open_loop_soil_error_percent(samples: &[SimSample]) -> Option<f64> {
    let (mut err2, mut ref2, mut n) = (0.0, 0.0, 0usize);
    for s in samples {
        let Some(m) = s.model_soil_force_n else {
            continue;
        };
        let f = s.soil_force_n;
        if f[0].hypot(f[1]) < 1.0 && m[0].hypot(m[1]) < 1.0 {
            continue;
        }
        err2 += (m[0] - f[0]).powi(2) + (m[1] - f[1]).powi(2);
        ref2 += f[0] * f[0] + f[1] * f[1];
        n += 1;
    }
    (n > 0 && ref2 > 0.0).then(|| 100.0 * (err2 / ref2).sqrt())
}

/// Mean of the absolute relative errors `[time, energy, volume]`, % and the mean trajectory RMS, m.
#[must_use]
pub fn mean_errors(c: &[DigComparison]) -> ([f64; 3], f64) {
    let n = c.len().max(1) as f64;
    let mut e = [0.0; 3];
    for d in c {
        for (k, v) in d.error_percent.iter().enumerate() {
            e[k] += v.abs() / n;
        }
    }
    (e, c.iter().map(|d| d.trajectory_rms_m).sum::<f64>() / n)
}
