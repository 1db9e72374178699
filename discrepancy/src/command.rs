//! `excavator-ctl discrepancy`: the model-discrepancy workflow on measured sessions (issue 8,
//! docs/discrepancy.md).
//!
//! - [`read`]: a session folder (`trace.log` + `scans/`) -> 100 Hz records per dig;
//! - [`report`]: `report.json`, `report.md`, the SVG figures and the augmented model file;
//! - [`eval`]: the hidden-effect evaluation (`discrepancy eval`): sessions generated in-process with
//!   one hidden simulator effect, analysed blind, and the confusion table.
//!
//! The physics, fitting and statistics are `planner::discrepancy`.

use std::path::{Path, PathBuf};

use crate::greybox::PreparedRecord;
use crate::{AnalysisConfig, AnalysisResult, AugmentedModel, analyse};
use crate::{eval, read, report};
use anyhow::Context as _;
use clap::{Args, Subcommand};
use planner::machine::MachineConfig;

/// Arguments of `excavator-ctl discrepancy`.
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct DiscrepancyArgs {
    /// `eval` or `bench`; without one, analyse the `--measured` sessions.
    #[command(subcommand)]
    pub cmd: Option<DiscrepancyCommand>,
    /// The analysis of measured sessions.
    #[command(flatten)]
    pub analyse: AnalyseArgs,
}

/// Subcommands of `excavator-ctl discrepancy`.
#[derive(Debug, Clone, Subcommand)]
pub enum DiscrepancyCommand {
    /// Hidden-effect evaluation: generate sessions with one hidden effect each (and effect-free ones),
    /// analyse them told nothing, print the confusion table.
    Eval(eval::EvalArgs),
    /// Time the analysis of N digs with the full effect library on one core.
    Bench(eval::BenchArgs),
}

/// Arguments of the analysis.
#[derive(Debug, Clone, Args)]
pub struct AnalyseArgs {
    /// Session folders as `excavator-ctl demo` writes them (`trace.log`, `scans/`); repeatable.
    #[arg(long, value_name = "DIR", num_args = 1..)]
    pub measured: Vec<PathBuf>,
    /// Starting model file (default: the shipped nominal model, config/nominal_greybox.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
    /// Output folder (report.json, report.md, figures, model.json).
    #[arg(long, default_value = "out/discrepancy", value_name = "DIR")]
    pub out: PathBuf,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Also write `dig_N_replay.csv` (inputs, measured, nominal and augmented signals) for every dig.
    #[arg(long)]
    pub replay_csv: bool,
}

/// Runs `excavator-ctl discrepancy`.
///
/// # Errors
/// Reading the sessions, too little data, writing the outputs.
pub fn run(args: DiscrepancyArgs) -> anyhow::Result<()> {
    match args.cmd {
        Some(DiscrepancyCommand::Eval(a)) => eval::run_eval(&a),
        Some(DiscrepancyCommand::Bench(a)) => eval::run_bench(&a),
        None => {
            if args.analyse.measured.is_empty() {
                anyhow::bail!("give at least one --measured DIR (or a subcommand: eval, bench)");
            }
            let out = run_analysis(&args.analyse)?;
            print!("{}", report::summary_text(&out.result));
            println!("report: {}", args.analyse.out.join("report.md").display());
            Ok(())
        }
    }
}

/// The outcome of an analysis.
pub struct Analysis {
    /// What the planner's analysis found.
    pub result: AnalysisResult,
    /// The model it started from.
    pub model: AugmentedModel,
    /// The prepared records.
    pub records: Vec<PreparedRecord>,
    /// Sessions left out because they could not be read, with the reason (only when other
    /// sessions could be).
    pub skipped_sessions: Vec<SkippedSession>,
}

/// A session folder left out of an analysis (`report.json`'s `skipped_sessions`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct SkippedSession {
    /// The folder.
    pub session: PathBuf,
    /// Why it could not be read (the error's whole cause chain).
    pub reason: String,
}

/// Loads the machine file or the built-in one.
///
/// # Errors
/// Reading or parsing the file.
pub fn load_machine(path: Option<&Path>) -> anyhow::Result<MachineConfig> {
    Ok(match path {
        Some(p) => MachineConfig::from_toml_file(p)?,
        None => MachineConfig::default_machine()?,
    })
}

/// Loads a model file or the shipped nominal model.
///
/// # Errors
/// Reading or parsing the file.
pub fn load_model(path: Option<&Path>) -> anyhow::Result<AugmentedModel> {
    Ok(match path {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            AugmentedModel::from_json(&text).with_context(|| format!("model {}", p.display()))?
        }
        None => AugmentedModel::nominal()?,
    })
}

/// Reads and prepares every dig of the sessions (dig indices renumbered so they are unique across
/// sessions).
///
/// # Errors
/// Reading a session; a record the model cannot prepare.
pub fn prepare_sessions(
    dirs: &[PathBuf],
    machine: &MachineConfig,
    model: &AugmentedModel,
) -> anyhow::Result<Vec<PreparedRecord>> {
    let (records, skipped) = prepare_readable_sessions(dirs, machine, model)?;
    match skipped.into_iter().next() {
        Some(s) => Err(anyhow::anyhow!(
            "reading session {}: {}",
            s.session.display(),
            s.reason
        )),
        None => Ok(records),
    }
}

/// As [`prepare_sessions`], but a session that cannot be read (a trace without the controller's
/// status, a folder without a trace) is left out and returned with its reason, so one bad folder
/// among many does not lose the others.
///
/// # Errors
/// No session readable (the first one's reason); a record the model cannot prepare.
pub fn prepare_readable_sessions(
    dirs: &[PathBuf],
    machine: &MachineConfig,
    model: &AugmentedModel,
) -> anyhow::Result<(Vec<PreparedRecord>, Vec<SkippedSession>)> {
    let mut records = Vec::new();
    let mut skipped = Vec::new();
    for dir in dirs {
        let digs = match read::read_session(dir, machine) {
            Ok(digs) => digs,
            Err(e) => {
                skipped.push(SkippedSession {
                    session: dir.clone(),
                    reason: format!("{e:#}"),
                });
                continue;
            }
        };
        for mut d in digs {
            d.index = records.len() as u32;
            records.push(PreparedRecord::new(&d, machine, &model.params)?);
        }
    }
    if records.is_empty()
        && let Some(s) = skipped.first()
    {
        anyhow::bail!("reading session {}: {}", s.session.display(), s.reason);
    }
    Ok((records, skipped))
}

/// Reads the sessions, runs the analysis and writes the outputs to `args.out`.
///
/// # Errors
/// As [`prepare_sessions`], [`analyse`] and writing the outputs.
pub fn run_analysis(args: &AnalyseArgs) -> anyhow::Result<Analysis> {
    let machine = load_machine(args.machine.as_deref())?;
    let model = load_model(args.model.as_deref())?;
    let (records, skipped_sessions) = prepare_readable_sessions(&args.measured, &machine, &model)?;
    for s in &skipped_sessions {
        tracing::warn!("session {} left out: {}", s.session.display(), s.reason);
    }
    let config = AnalysisConfig {
        base: model.augmentation()?,
        ..AnalysisConfig::default()
    };
    let bar = (!args.quiet && std::io::IsTerminal::is_terminal(&std::io::stdout())).then(|| {
        let bar = indicatif::ProgressBar::new(1);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} fitting candidates [{bar:30}] {pos}/{len} {elapsed}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });
    let result = analyse(&records, &model.params, &config, &mut |done, total| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let analysis = Analysis {
        result,
        model,
        records,
        skipped_sessions,
    };
    report::write_outputs(&args.out, &analysis, &args.measured, args.replay_csv)?;
    Ok(analysis)
}
