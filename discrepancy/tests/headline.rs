//! The headline figures of the user's path, recomputed small for CI through the code the commands
//! run: fresh default `demo` sessions (`DemoArgs::defaults`, the CLI's own defaults) analysed as
//! `excavator-ctl discrepancy analyse --measured DIR` is, without `--reference`, and the shipped
//! actuator networks on one as `excavator-ctl model evaluate --trace DIR/trace.log --all` measures
//! them. A figure the docs claim and the user's commands do not reproduce fails here.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use discrepancy::analysis::{AnalyseArgs, run_analysis};
use lab::demo::{DemoArgs, run_session};

/// Digs per session: the fewest the analysis judges without warning about soil and payload
/// (`sufficiency::RECOMMENDED_COMPLETED_DIGS`).
const DIGS: u32 = 6;

/// Fresh seeds: no calibration (1000-1003, 1400-1402, 1700-1702), the built-in reference
/// (8501-8504) nor the figures in the docs (9101-9106, 9201-9206) used them.
const CLEAN_SEEDS: [u64; 2] = [9351, 9352];

/// The bound on the shipped networks' free-running error on one fresh default session, % of the
/// peak speed, every cylinder: the 5 % target with a margin for one short session (the
/// worst of 5 fresh 10-dig default sessions in docs/models.md is 5.75 % on the boom; this one,
/// seed 9353, gave 5.0 / 3.8 / 6.0 % boom / stick / bucket when the bound was set).
const NETWORK_BOUND_PERCENT: f64 = 7.0;

fn default_session(dir: &Path, seed: u64) -> PathBuf {
    let demo = DemoArgs {
        digs: DIGS,
        seed: Some(seed),
        quiet: true,
        ..DemoArgs::defaults(dir.to_path_buf())
    };
    run_session(&demo, &AtomicBool::new(false)).expect("a default demo session");
    dir.to_path_buf()
}

/// `discrepancy analyse --measured DIR` with its defaults names nothing on clean default sessions,
/// and says what it judged against (the built-in reference of the default machine).
#[test]
fn clean_default_sessions_analysed_without_reference_name_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    for seed in CLEAN_SEEDS {
        let s = default_session(&tmp.path().join(format!("s{seed}")), seed);
        let mut args = AnalyseArgs::new(vec![s], tmp.path().join(format!("r{seed}")));
        args.quiet = true;
        let a = run_analysis(&args).expect("the analysis");
        assert!(
            a.result.named_effects.is_empty() && a.result.ambiguous.is_empty(),
            "seed {seed}: {:?} {:?}",
            a.result.named_effects,
            a.result.ambiguous
        );
        let v = a
            .verdict
            .as_ref()
            .expect("judged against the built-in reference");
        assert!(v.unexplained.is_empty(), "seed {seed}: {:?}", v.unexplained);
        let summary = discrepancy::report::summary_text(&a);
        assert!(
            summary.contains("record-reference") && summary.contains("for a real machine"),
            "{summary}"
        );
    }
}

/// The shipped actuator networks on one fresh default session stay under
/// [`NETWORK_BOUND_PERCENT`] on every cylinder, measured as `model evaluate --all` does.
#[test]
fn shipped_networks_on_a_fresh_default_session_stay_under_the_bound() {
    let tmp = tempfile::tempdir().unwrap();
    let s = default_session(&tmp.path().join("s"), 9353);
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: lab::model::evaluate::EvaluateArgs,
    }
    let trace = s.join("trace.log");
    let args = <Cli as clap::Parser>::try_parse_from([
        "evaluate",
        "--trace",
        trace.to_str().unwrap(),
        "--all",
    ])
    .unwrap()
    .args;
    let model =
        planner::actuator::ActuatorModel::from_json(planner::dig_model::NOMINAL_ACTUATOR_JSON)
            .unwrap();
    let machine = planner::machine::MachineConfig::default_machine().unwrap();
    let report =
        lab::model::evaluate::evaluate_traces(&args.trace, &model, &machine, args.velocity)
            .unwrap();
    assert!(report.digs >= DIGS as usize, "{report:?}");
    for c in &report.cylinders {
        assert!(
            c.mae_percent_of_peak < NETWORK_BOUND_PERCENT,
            "{:?}: {:.2} % of peak (bound {NETWORK_BOUND_PERCENT} %): {report:?}",
            c.joint,
            c.mae_percent_of_peak
        );
    }
}
