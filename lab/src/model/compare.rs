//! `excavator-ctl model compare`: the simulator and the dig model from the same starts over the same
//! sections (thesis Figs. 34-41): the errors per dig and on average, `compare.json`, and the plots.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Args;
use planner::dig_model::DigPrediction;
use rayon::prelude::*;

use super::comparison::{DigComparison, compare_dig, mean_errors};
use super::plots::{plot_compare, plot_dig_series};
use super::sim_dig::{PERIOD_S, SimDig, random_setups, run_sim_dig_diagnosed};
use super::start::load_model;

/// Arguments of `model compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Number of digs.
    #[arg(long, default_value_t = 8)]
    pub digs: usize,
    /// Seed of the starts (different from the training data's by default).
    #[arg(long, default_value_t = 1001)]
    pub seed: u64,
    /// Actuator model (default: the shipped config/nominal_actuator.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Output folder for `compare.svg` and `compare.json`.
    #[arg(long, default_value = "model-compare")]
    pub out: PathBuf,
    /// Factor on the soil's force on the bucket in both the simulator and the dig model (thesis
    /// Table 2's force factor), to compare them in harder soil than the default bench's.
    #[arg(long, default_value_t = 1.0)]
    pub force_factor: f64,
    /// Print both trajectories every 0.2 s.
    #[arg(long)]
    pub verbose: bool,
}

/// Runs `model compare`.
///
/// # Errors
/// Bad arguments, reading the model, simulator or dig-model errors, writing the outputs.
pub fn run(a: &CompareArgs) -> anyhow::Result<()> {
    if a.digs == 0 {
        bail!("--digs must be at least 1");
    }
    if !(a.force_factor.is_finite() && (0.0..=10.0).contains(&a.force_factor)) {
        bail!(
            "--force-factor must be within 0..=10, got {}",
            a.force_factor
        );
    }
    let model = load_model(a.model.as_deref())?;
    let mut setups = random_setups(a.digs, a.seed, false)?;
    for s in &mut setups {
        s.soil_force_factor = a.force_factor;
    }
    let bar = indicatif::ProgressBar::new(setups.len() as u64);
    let runs: Vec<anyhow::Result<(SimDig, DigComparison, DigPrediction)>> = setups
        .par_iter()
        .map(|s| {
            let sim = run_sim_dig_diagnosed(s, None, Some(&model))?;
            let (cmp, pred) = compare_dig(&model, &sim)?;
            bar.inc(1);
            Ok((sim, cmp, pred))
        })
        .collect();
    bar.finish_and_clear();
    let mut rows = Vec::new();
    for r in runs {
        rows.push(r.map_err(|e| anyhow::anyhow!("{e:#}"))?);
    }
    println!(
        "dig model vs simulator, {} digs, soil force x{} (thesis Fig. 41: within 12-15 %; target 15 %)",
        rows.len(),
        a.force_factor
    );
    println!(
        "  dig  traj RMS [m]  time sim/model [s]  energy sim/model [kJ]  volume sim/model [m^3]  err time/energy/volume [%]  lowest z sim/model [m]  soil F open loop [%]  end sim / model"
    );
    for (_, c, _) in &rows {
        println!(
            "  {:>3}  {:>12.3}  {:>7.2} / {:>6.2}  {:>9.1} / {:>8.1}  {:>9.2} / {:>9.2}  {:>+7.1} / {:>+7.1} / {:>+7.1}  {:>9.2} / {:>9.2}  {:>18}  {} / {}",
            c.index,
            c.trajectory_rms_m,
            c.time_s[0],
            c.time_s[1],
            c.energy_kj[0],
            c.energy_kj[1],
            c.volume_m3[0],
            c.volume_m3[1],
            c.error_percent[0],
            c.error_percent[1],
            c.error_percent[2],
            c.min_tip_z_m[0],
            c.min_tip_z_m[1],
            c.soil_force_error_percent
                .map_or_else(|| "-".to_owned(), |e| format!("{e:.1}")),
            c.end[0],
            c.end[1]
        );
    }
    if a.verbose {
        for (sim, c, pred) in &rows {
            println!(
                "  dig {}: t, sim (x z bucket_abs cmd), model (stage x z bucket_abs cmd head MPa)",
                c.index
            );
            for k in (0..sim.samples.len().max(pred.samples.len())).step_by(20) {
                let fmt_sim = sim.samples.get(k).map_or(String::new(), |s| {
                    format!(
                        "{:5.2} {:5.2} {:6.0} {:+.2?} {:.1?} {:.0?} soil {:.0?} model@sim {:.0?}",
                        s.tip_x_m,
                        s.tip_z_m,
                        s.bucket_abs_rad.to_degrees(),
                        s.command,
                        s.head_pa.map(|p| p * 1e-6),
                        s.force_n.map(|f| f * 1e-3),
                        s.soil_force_n.map(|f| f * 1e-3),
                        s.model_soil_force_n.map(|m| m.map(|f| f * 1e-3))
                    )
                });
                let fmt_model = pred.samples.get(k).map_or(String::new(), |s| {
                    format!(
                        "{:?} {:5.2} {:5.2} {:6.0} {:+.2?} {:.1?} {:.0?} soil [{:.0}, {:.0}]",
                        s.stage,
                        s.tip_x_m,
                        s.tip_z_m,
                        s.bucket_abs_rad.to_degrees(),
                        s.command,
                        s.head_pa.map(|p| p * 1e-6),
                        s.force_n.map(|f| f * 1e-3),
                        s.soil_force.fx_n * 1e-3,
                        s.soil_force.fz_n * 1e-3
                    )
                });
                println!(
                    "    {:5.2}  {fmt_sim:<44}  {fmt_model}",
                    k as f64 * PERIOD_S
                );
            }
        }
    }
    let cmps: Vec<DigComparison> = rows.iter().map(|(_, c, _)| c.clone()).collect();
    let (mean, rms) = mean_errors(&cmps);
    println!(
        "  mean |error|: trajectory {:.3} m, time {:.1} %, energy {:.1} %, volume {:.1} %{}",
        rms,
        mean[0],
        mean[1],
        mean[2],
        if mean.iter().all(|e| *e <= 15.0) {
            " (within 15 %)"
        } else {
            " (above 15 % somewhere)"
        }
    );
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    std::fs::write(
        a.out.join("compare.json"),
        serde_json::to_string_pretty(&cmps)?,
    )?;
    let svg = a.out.join("compare.svg");
    plot_compare(&svg, &rows)?;
    for (sim, cmp, pred) in &rows {
        plot_dig_series(
            &a.out.join(format!("dig_{}.svg", cmp.index)),
            sim,
            cmp,
            pred,
        )?;
    }
    println!(
        "wrote {}, dig_N.svg (commands, joint angles, head pressures, soil force, swept volume over time) and compare.json",
        svg.display()
    );
    Ok(())
}
