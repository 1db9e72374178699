//! `excavator-ctl discrepancy analyse`: the analysis of measured sessions end to end: read and
//! prepare them ([`crate::session`]), fit the candidate effects ([`crate::analyse`]), write the
//! report and the augmented model ([`crate::report`]).

use std::path::PathBuf;

use clap::Args;

use crate::session::{Analysis, load_machine, load_model, prepare_readable_sessions};
use crate::{AnalysisConfig, analyse, report};

/// Arguments of `discrepancy analyse`.
#[derive(Debug, Clone, Args)]
pub struct AnalyseArgs {
    /// Session folders as `excavator-ctl demo` writes them (`trace.log`, `scans/`); at least one,
    /// repeatable.
    #[arg(long, value_name = "DIR", num_args = 1.., required = true)]
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

/// Reads the sessions, runs the analysis and writes the outputs to `args.out`.
///
/// # Errors
/// As [`prepare_readable_sessions`], [`analyse`] and writing the outputs.
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
