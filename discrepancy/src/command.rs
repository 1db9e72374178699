//! `excavator-ctl discrepancy`: the model-discrepancy workflow on measured sessions
//! (docs/discrepancy.md), one subcommand per action:
//!
//! - `analyse` ([`crate::analysis`]): measured session folders (`trace.log` + `scans/`) -> where the
//!   model and the measurements disagree, the missing effects named and added to the model
//!   (`report.md`, `report.json`, figures, `model.json`);
//! - `eval` ([`crate::eval`]): the hidden-effect evaluation: sessions generated in-process with one
//!   hidden simulator effect, analysed blind, and the confusion table;
//! - `fleet` ([`crate::fleet`]): `analyse` of every machine of a fleet as a campaign, and one table;
//! - `record-reference` ([`crate::record`]): a reference from healthy default sessions (the
//!   built-in one, config/nominal_reference.json, is its output);
//! - `bench`: the analysis time of N digs on one core.

use clap::Subcommand;

use crate::analysis::{AnalyseArgs, run_analysis};
use crate::{eval, report};

/// Subcommands of `excavator-ctl discrepancy`.
#[derive(Debug, Clone, Subcommand)]
pub enum DiscrepancyArgs {
    /// Analyse measured sessions: where the model and the measurements disagree, the missing effect
    /// named and added to the model (report.md, report.json, figures and model.json in --out).
    Analyse(AnalyseArgs),
    /// Hidden-effect evaluation: generate sessions with one hidden effect each (and effect-free ones),
    /// analyse them told nothing, print the confusion table.
    Eval(eval::EvalArgs),
    /// Analyse every machine of a fleet (FLEET/NAME/sessions/*, each against its own reference)
    /// as a campaign, in-process or on a Dask cluster: one table of what each machine shows
    /// (fleet.md, fleet.json; docs/campaigns.md).
    Fleet(crate::fleet::FleetArgs),
    /// Record a reference from healthy default `demo` sessions (the built-in reference,
    /// config/nominal_reference.json, is `--out config/nominal_reference.json` with the defaults).
    RecordReference(crate::record::RecordReferenceArgs),
    /// Time the analysis of N digs with the full effect library on one core.
    Bench(eval::BenchArgs),
}

/// Runs `excavator-ctl discrepancy`.
///
/// # Errors
/// Reading the sessions, too little data, writing the outputs.
pub fn run(args: DiscrepancyArgs) -> anyhow::Result<()> {
    match args {
        DiscrepancyArgs::Analyse(a) => {
            let out = run_analysis(&a)?;
            print!("{}", report::summary_text(&out));
            println!("report: {}", a.out.join("report.md").display());
            Ok(())
        }
        DiscrepancyArgs::Eval(a) => eval::run_eval(&a),
        DiscrepancyArgs::Fleet(a) => crate::fleet::run_fleet(&a).map(|_| ()),
        DiscrepancyArgs::RecordReference(a) => {
            let r = crate::record::run_record(&a)?;
            println!(
                "reference of {} digs ({}) written to {}",
                r.digs,
                r.source.join(", "),
                a.out.display()
            );
            Ok(())
        }
        DiscrepancyArgs::Bench(a) => eval::run_bench(&a),
    }
}
