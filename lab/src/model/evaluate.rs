//! `excavator-ctl model evaluate`: the free-running error of an actuator model on the digs of `train`'s
//! split, optionally split by phantom-rate samples, with the statics-force gap and a CSV dump for
//! diagnosis.

use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;
use planner::actuator::{ActuatorDig, ActuatorModel, TrainConfig};
use planner::kinematics::Joint;

use super::training_data::{ForceSource, TraceDig, VelocitySource, load_trace_digs};

/// Which digs of `train`'s split `model evaluate` runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EvalSplit {
    /// The held-out test digs (the reported figure).
    Test,
    /// The validation digs (early stopping; the split to choose between trainings on).
    Validation,
    /// The training digs.
    Train,
}

/// Arguments of `model evaluate`.
#[derive(Debug, Args)]
pub struct EvaluateArgs {
    /// candump -L traces, in the order given to `model train`.
    #[arg(long, required = true, num_args = 1..)]
    pub trace: Vec<PathBuf>,
    /// Actuator model (default: the shipped config/nominal_actuator.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Seed of `train`'s split (the test digs are the ones `train --seed` held out).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Evaluate on every dig instead of the held-out test digs.
    #[arg(long)]
    pub all: bool,
    /// Which digs of the seed's split to evaluate on (ignored with `--all`).
    #[arg(long, value_enum, default_value_t = EvalSplit::Test)]
    pub split: EvalSplit,
    /// Hold the force-rate input at zero, as the dig model does with its quasi-static forces
    /// (with `--forces statics`: the networks as the dig model runs them).
    #[arg(long)]
    pub zero_rate: bool,
    /// The target velocity signal (default: `model train`'s).
    #[arg(long, value_enum, default_value_t = VelocitySource::Angles)]
    pub velocity: VelocitySource,
    /// The force inputs.
    #[arg(long, value_enum, default_value_t = ForceSource::Measured)]
    pub forces: ForceSource,
    /// Also split the error by samples where the rate and the resolver angles disagree (the
    /// simulator's phantom rate of a stalled cylinder) and report it against both targets.
    #[arg(long)]
    pub breakdown: bool,
    /// Also write every evaluated step as CSV (dig, time, Autodig stage, commands, forces, chamber and
    /// pump pressures, both velocity signals, the free-running prediction) for diagnosis.
    #[arg(long, value_name = "FILE")]
    pub dump: Option<PathBuf>,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
}

/// Prints the error table of an evaluation, a row per cylinder.
pub(super) fn print_errors(report: &planner::actuator::EvaluationReport) {
    println!("  cylinder  MAE [m/s]  peak [m/s]  MAE % of peak");
    for e in &report.cylinders {
        println!(
            "  {:<8}  {:>9.4}  {:>10.3}  {:>8.2} %{}",
            e.joint.to_string(),
            e.mae_m_per_s,
            e.peak_m_per_s,
            e.mae_percent_of_peak,
            if e.mae_percent_of_peak < 5.0 {
                ""
            } else {
                "  (above 5 %)"
            }
        );
    }
}

/// A sample's sampled rate is counted as a phantom (a stalled cylinder's aliased chatter, docs/simulator.md
/// Known issues) when the resolver angles say the cylinder moves slower than this, m/s ...
const PHANTOM_ANGLE_SPEED_M_PER_S: f64 = 0.01;
/// ... while the rate says it moves faster than this, m/s.
const PHANTOM_RATE_SPEED_M_PER_S: f64 = 0.02;

/// The error of `model` on `digs` split by phantom-rate samples ([`PHANTOM_ANGLE_SPEED_M_PER_S`]),
/// against both target signals. Prints one table.
fn print_breakdown(model: &ActuatorModel, digs: &[TraceDig]) -> anyhow::Result<()> {
    // Per cylinder: [all, phantom] x (steps, |e| vs rates, |e| vs angles); peaks of both signals.
    let mut sums = [[(0usize, 0.0_f64, 0.0_f64); 2]; 3];
    let mut peaks = [[0.0_f64; 2]; 3];
    for dig in digs {
        let by_rates = model.simulate(&dig.to_actuator_dig(VelocitySource::Rates))?;
        let by_angles = model.simulate(&dig.to_actuator_dig(VelocitySource::Angles))?;
        for (r, g) in by_rates.iter().zip(&by_angles).skip(1) {
            for j in 0..3 {
                let (rate, angle) = (r.measured_m_per_s[j], g.measured_m_per_s[j]);
                let phantom = angle.abs() < PHANTOM_ANGLE_SPEED_M_PER_S
                    && rate.abs() > PHANTOM_RATE_SPEED_M_PER_S;
                peaks[j][0] = peaks[j][0].max(rate.abs());
                peaks[j][1] = peaks[j][1].max(angle.abs());
                for (class, sum) in sums[j].iter_mut().enumerate() {
                    if class == 0 || phantom {
                        sum.0 += 1;
                        sum.1 += (r.predicted_m_per_s[j] - rate).abs();
                        sum.2 += (g.predicted_m_per_s[j] - angle).abs();
                    }
                }
            }
        }
    }
    println!(
        "error by target signal; phantom samples: resolver speed < {PHANTOM_ANGLE_SPEED_M_PER_S} m/s while the rate says > {PHANTOM_RATE_SPEED_M_PER_S} m/s"
    );
    println!(
        "  cylinder  MAE vs rates  MAE vs angles  phantom samples  their share of |e| vs rates  MAE vs rates without them"
    );
    for (j, joint) in Joint::ALL.iter().enumerate() {
        let [all, ph] = sums[j];
        let pct = |x: f64, peak: f64| if peak > 0.0 { 100.0 * x / peak } else { 0.0 };
        let n = all.0.max(1) as f64;
        let rest_n = (all.0 - ph.0).max(1) as f64;
        println!(
            "  {:<8}  {:>10.2} %  {:>11.2} %  {:>8} ({:>4.1} %)  {:>18.1} %  {:>16.2} %",
            joint.to_string(),
            pct(all.1 / n, peaks[j][0]),
            pct(all.2 / n, peaks[j][1]),
            ph.0,
            100.0 * ph.0 as f64 / n,
            if all.1 > 0.0 {
                100.0 * ph.1 / all.1
            } else {
                0.0
            },
            pct((all.1 - ph.1) / rest_n, peaks[j][0]),
        );
    }
    println!(
        "  (each % of that signal's peak on these digs: rates {:.3} / {:.3} / {:.3} m/s, angles {:.3} / {:.3} / {:.3} m/s)",
        peaks[0][0], peaks[1][0], peaks[2][0], peaks[0][1], peaks[1][1], peaks[2][1]
    );
    Ok(())
}

/// The free-running error of `model` on every dig of `traces` with velocities from `velocity` and
/// the measured forces (the figure `model evaluate --all` prints).
///
/// # Errors
/// Reading the traces; the model's errors (a trace without digs included).
pub fn evaluate_traces(
    traces: &[PathBuf],
    model: &ActuatorModel,
    machine: &planner::machine::MachineConfig,
    velocity: VelocitySource,
) -> anyhow::Result<planner::actuator::EvaluationReport> {
    let digs: Vec<ActuatorDig> = load_trace_digs(traces, machine, ForceSource::Measured)?
        .iter()
        .map(|d| d.to_actuator_dig(velocity))
        .collect();
    Ok(model.evaluate(&digs)?)
}

/// Runs `model evaluate`.
///
/// # Errors
/// Reading the traces, the model or the machine file; the model's errors; writing the dump.
pub fn run(a: &EvaluateArgs) -> anyhow::Result<()> {
    let machine = planner::machine::MachineConfig::load_or_default(a.machine.as_deref())?;
    let trace_digs = load_trace_digs(&a.trace, &machine, a.forces)?;
    let text = match &a.model {
        Some(p) => {
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?
        }
        None => planner::dig_model::NOMINAL_ACTUATOR_JSON.to_owned(),
    };
    let model = ActuatorModel::from_json(&text)?;
    let chosen: Vec<TraceDig> = if a.all {
        trace_digs
    } else {
        let config = TrainConfig {
            seed: a.seed,
            ..TrainConfig::default()
        };
        let split = planner::actuator::split_digs(trace_digs.len(), &config)?;
        let picked = match a.split {
            EvalSplit::Test => &split.test,
            EvalSplit::Validation => &split.validation,
            EvalSplit::Train => &split.train,
        };
        picked.iter().map(|&i| trace_digs[i].clone()).collect()
    };
    let digs: Vec<ActuatorDig> = chosen
        .iter()
        .map(|d| d.to_actuator_dig(a.velocity))
        .collect();
    let report = if a.zero_rate {
        model.evaluate_static(&digs)?
    } else {
        model.evaluate(&digs)?
    };
    println!(
        "{} digs ({} steps), target: velocities from the {}, free-running (thesis Figs. 19-21: 5-8 %; target < 5 %):",
        report.digs,
        report.steps,
        match a.velocity {
            VelocitySource::Rates => "sampled joint rates",
            VelocitySource::Angles => "resolver angles' slope",
        }
    );
    print_errors(&report);
    if let Some(path) = &a.dump {
        write_dump(path, &model, &chosen, &digs)?;
        println!("wrote {}", path.display());
    }
    if a.breakdown {
        print_breakdown(&model, &chosen)?;
        if a.forces == ForceSource::Statics {
            let measured = load_trace_digs(&a.trace, &machine, ForceSource::Measured)?;
            print_force_gap(&measured, &trace_digs_all(&a.trace, &machine)?, &machine);
        }
    }
    Ok(())
}

/// Writes `evaluate --dump`'s CSV: one row per predicted step, with the trace sample nearest in time.
fn write_dump(
    path: &Path,
    model: &ActuatorModel,
    chosen: &[TraceDig],
    digs: &[ActuatorDig],
) -> anyhow::Result<()> {
    let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut out = BufWriter::new(file);
    writeln!(
        out,
        "dig,t,stage,u0,u1,u2,f0,f1,f2,ph0,ph1,ph2,pr0,pr1,pr2,pump1,pump2,vr0,vr1,vr2,va0,va1,va2,vt0,vt1,vt2,vp0,vp1,vp2"
    )?;
    for (d, (trace, dig)) in chosen.iter().zip(digs).enumerate() {
        let steps = model.simulate(dig)?;
        let times: Vec<f64> = trace.samples.iter().map(|s| s.sample.time_s).collect();
        for step in steps.iter().skip(1) {
            let k = times.partition_point(|&t| t < step.time_s);
            let k = if k > 0
                && (k == times.len() || step.time_s - times[k - 1] < times[k] - step.time_s)
            {
                k - 1
            } else {
                k.min(times.len() - 1)
            };
            let s = &trace.samples[k];
            let mut row = vec![d as f64, step.time_s, f64::from(s.stage)];
            row.extend(s.sample.command);
            row.extend(s.sample.force_n);
            row.extend(s.head_pa);
            row.extend(s.rod_pa);
            row.extend(s.pump_pa);
            row.extend(s.sample.velocity_m_per_s);
            row.extend(s.angle_velocity_m_per_s);
            row.extend(step.measured_m_per_s);
            row.extend(step.predicted_m_per_s);
            let text: Vec<String> = row.iter().map(|v| format!("{v:.6e}")).collect();
            writeln!(out, "{}", text.join(","))?;
        }
    }
    out.flush()?;
    Ok(())
}

/// All digs of `traces` with the statics forces (the same digs as [`ForceSource::Measured`] gives).
fn trace_digs_all(
    traces: &[PathBuf],
    machine: &planner::machine::MachineConfig,
) -> anyhow::Result<Vec<TraceDig>> {
    load_trace_digs(traces, machine, ForceSource::Statics)
}

/// How far the dig model's statics forces lie from the measured ones over all samples: mean and
/// mean absolute difference (statics - measured) per cylinder, as head-side pressure, MPa.
fn print_force_gap(
    measured: &[TraceDig],
    statics: &[TraceDig],
    machine: &planner::machine::MachineConfig,
) {
    let c = &machine.cylinders;
    let head = [&c.boom, &c.stick, &c.bucket].map(|c| c.head_area_m2());
    let mut sums = [(0.0_f64, 0.0_f64); 3];
    let mut n = 0usize;
    for (m, s) in measured.iter().zip(statics) {
        for (a, b) in m.samples.iter().zip(&s.samples) {
            for j in 0..3 {
                let d = (b.sample.force_n[j] - a.sample.force_n[j]) / head[j] * 1e-6;
                sums[j].0 += d;
                sums[j].1 += d.abs();
            }
            n += 1;
        }
    }
    let n = n.max(1) as f64;
    println!(
        "statics - measured force over all {} samples, as head pressure [MPa]: mean {:+.2} / {:+.2} / {:+.2}, mean |.| {:.2} / {:.2} / {:.2} (boom / stick / bucket)",
        n,
        sums[0].0 / n,
        sums[1].0 / n,
        sums[2].0 / n,
        sums[0].1 / n,
        sums[1].1 / n,
        sums[2].1 / n
    );
}
