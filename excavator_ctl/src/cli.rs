//! The command line of `excavator-ctl` (clap).

use clap::{Args, Parser, Subcommand};

/// The excavator controller: Autodig, cleanup and the work cycle over CAN (after Cannon, CMU 1999).
#[derive(Debug, Parser)]
#[command(name = "excavator-ctl", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run on a CAN interface in real time (SocketCAN): the planned session of `demo`, the
    /// predefined sequence or the config's plan (--strategy); Ctrl-C leaves the valves neutral and
    /// the gateway disarmed; --out writes the session folder as `demo` does; --live serves it to
    /// Foxglove and the operator page (docs/live-view.md).
    Run(RunCmd),
    /// Operator control of a running `run` over its control socket: status, pause, resume, estop,
    /// reset, stop (docs/controller.md).
    Ctl(onboard::run::CtlArgs),
    /// Print the site part of a simulator bench file (the work area, floor, start pose and material
    /// that `run --site` reads; docs/controller.md, "The site").
    Site(SiteArgs),
    /// The embedded default: the simulator in-process in virtual time and a full autonomous session;
    /// writes the trace, scans, summary and plots into --out (docs/demo-output.md); --live serves it
    /// to Foxglove as it runs (docs/live-view.md).
    Demo(DemoCmd),
    /// The thesis's results reproduced in the simulator and the dig model: Tables 1-5, Figs. 52, 53
    /// and 60, the scoreboard of its statements and the results page (docs/results.md).
    Experiment(lab::experiment::ExperimentArgs),
    /// candump trace tools: decode, stats, plot, convert (csv, mcap), replay, diff (docs/trace-tools.md).
    Trace {
        /// The trace tool.
        #[command(subcommand)]
        cmd: trace_tools::TraceCommand,
    },
    /// The planner's dig model: train the actuator networks, generate simulator data, compare with
    /// the simulator, cross-validate the soil models (docs/models.md).
    Model {
        /// The model command.
        #[command(subcommand)]
        cmd: lab::model::ModelCommand,
    },
    /// Model-discrepancy workflow: `analyse` measured sessions (where the model and the measurements
    /// disagree, the missing effect named and added), `eval` (hidden-effect confusion table), `bench`
    /// (docs/discrepancy.md).
    #[command(subcommand)]
    Discrepancy(discrepancy::command::DiscrepancyArgs),
    /// Campaigns (docs/campaigns.md): run one job of a plan, as a cluster's worker does, or list a
    /// plan's jobs with what is done.
    #[command(subcommand)]
    Campaign(CampaignCmd),
    /// Rebuild every shipped artefact fitted on the simulated plant (actuator networks, hardness
    /// regression, the discrepancy workflow's nominal model) from the simulator and a seed, with a
    /// calibration report; --install copies them into a config folder (docs/models.md,
    /// "Calibration"). Long: not part of CI.
    Calibrate(calibration::CalibrateArgs),
    /// Write the manual pages and shell completions of this command line (scripts/package).
    #[command(hide = true)]
    GenerateDocs(crate::docs::DocsArgs),
}

/// Subcommands of `excavator-ctl campaign`.
#[derive(Debug, Subcommand)]
pub enum CampaignCmd {
    /// Run one job of a campaign plan (OUT/campaign/plan.json), in the plan's work folder: what a
    /// Dask worker runs for `--executor dask://`, and what another engine's job runs after
    /// `--plan-only`.
    Job {
        /// The plan file.
        #[arg(long, value_name = "FILE")]
        plan: std::path::PathBuf,
        /// The job's id.
        #[arg(long, value_name = "ID")]
        job: String,
    },
    /// List a plan's jobs: done (worker, attempts, CPU time) or pending.
    Status {
        /// The plan file.
        #[arg(long, value_name = "FILE")]
        plan: std::path::PathBuf,
    },
}

/// Arguments of `excavator-ctl demo`: the session's and the live view's.
#[derive(Debug, Args)]
pub struct DemoCmd {
    /// The session.
    #[command(flatten)]
    pub session: lab::demo::DemoArgs,
    /// The live view.
    #[command(flatten)]
    pub live: live::LiveArgs,
}

/// Arguments of `excavator-ctl run`: the session's and the live view's.
#[derive(Debug, Args)]
pub struct RunCmd {
    /// The session.
    #[command(flatten)]
    pub run: onboard::run::RunArgs,
    /// The live view.
    #[command(flatten)]
    pub live: live::LiveArgs,
}

/// Arguments of `excavator-ctl site`.
#[derive(Debug, Clone, clap::Args)]
pub struct SiteArgs {
    /// The bench file whose site part to print.
    #[arg(long, value_name = "FILE")]
    pub bench: std::path::PathBuf,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_is_consistent() {
        Cli::command().debug_assert();
    }

    /// `excavator-ctl demo ARGS...` as parsed.
    fn demo_cmd(args: &[&str]) -> DemoCmd {
        let mut all = vec!["excavator-ctl", "demo"];
        all.extend_from_slice(args);
        match Cli::try_parse_from(all).unwrap().command {
            Command::Demo(d) => d,
            _ => panic!("not demo"),
        }
    }

    /// `DemoArgs::defaults`, which `calibrate` and `discrepancy eval` start from, is what
    /// `excavator-ctl demo --out DIR` runs, and `calibrate`'s sessions differ from it only in the
    /// seed, the digs, the folder and the progress bar.
    #[test]
    fn the_library_s_default_session_is_demo_s() {
        let demo = |args: &[&str]| demo_cmd(args).session;
        assert_eq!(
            demo(&["--out", "s"]),
            lab::demo::DemoArgs::defaults("s".into())
        );
        let record = calibration::SessionRecord {
            set: "fresh",
            seed: 1401,
            digs: 12,
            dir: "out/calibration/sessions/fresh_1401".into(),
        };
        assert_eq!(
            demo(&[
                "--seed",
                "1401",
                "--digs",
                "12",
                "--out",
                "out/calibration/sessions/fresh_1401",
                "--quiet"
            ]),
            record.demo_args()
        );
    }

    #[test]
    fn live_takes_an_optional_address() {
        let live = |args: &[&str]| demo_cmd(args).live;
        assert_eq!(live(&[]).live, None);
        assert_eq!(live(&["--live"]).live.as_deref(), Some(live::DEFAULT_ADDR));
        let l = live(&["--live", "0.0.0.0:9000", "--pace", "2"]);
        assert_eq!(l.live.as_deref(), Some("0.0.0.0:9000"));
        assert_eq!(l.pace, Some(2.0));
    }

    #[test]
    fn run_arguments_parse() {
        let cli = Cli::try_parse_from([
            "excavator-ctl",
            "run",
            "--iface",
            "vcan0",
            "--listen-only",
            "--digs",
            "3",
            "--trace",
            "t.log",
            "--strategy",
            "planned",
            "--time-scale",
            "4",
        ])
        .unwrap();
        let Command::Run(RunCmd { run: o, live }) = cli.command else {
            panic!("not run")
        };
        assert_eq!(live.live, None);
        assert_eq!(o.iface.as_deref(), Some("vcan0"));
        assert!(o.listen_only);
        assert_eq!(o.digs, Some(3));
        assert_eq!(o.strategy(), onboard::DemoStrategy::Planned);
        assert!((o.time_scale().get() - 4.0).abs() < 1e-12);
        assert!(Cli::try_parse_from(["excavator-ctl", "run"]).is_err());
        // --resume DIR alone: the interface is the session's.
        assert!(Cli::try_parse_from(["excavator-ctl", "run", "--resume", "s"]).is_ok());
        for bad in ["0", "25", "NaN", "-2"] {
            assert!(
                Cli::try_parse_from([
                    "excavator-ctl",
                    "run",
                    "--iface",
                    "vcan0",
                    "--time-scale",
                    bad
                ])
                .is_err(),
                "{bad}"
            );
        }
    }

    /// A count of zero ran an empty demo, printed Table 2 from no runs and generated 54 sessions the
    /// discrepancy evaluation could not analyse; it is refused at parse time.
    #[test]
    fn zero_counts_are_refused() {
        for args in [
            &["excavator-ctl", "demo", "--digs", "0"][..],
            &["excavator-ctl", "experiment", "table2", "--runs", "0"],
            &["excavator-ctl", "experiment", "extended", "--digs", "0"],
            &["excavator-ctl", "experiment", "results", "--seeds", "0"],
            &["excavator-ctl", "discrepancy", "eval", "--digs", "1"],
            &["excavator-ctl", "discrepancy", "eval", "--seeds", "0"],
            &["excavator-ctl", "discrepancy", "bench", "--digs", "0"],
            &["excavator-ctl", "run", "--iface", "vcan0", "--digs", "0"],
        ] {
            assert!(Cli::try_parse_from(args).is_err(), "{args:?} parsed");
        }
        assert!(Cli::try_parse_from(["excavator-ctl", "demo", "--digs", "1"]).is_ok());
        // --pace and --live-queue only with --live.
        assert!(Cli::try_parse_from(["excavator-ctl", "demo", "--pace", "1"]).is_err());
        assert!(
            Cli::try_parse_from(["excavator-ctl", "discrepancy", "eval", "--digs", "2"]).is_ok()
        );
        // The analysis is a subcommand like the others, and needs its sessions.
        assert!(Cli::try_parse_from(["excavator-ctl", "discrepancy", "analyse"]).is_err());
        assert!(
            Cli::try_parse_from([
                "excavator-ctl",
                "discrepancy",
                "analyse",
                "--measured",
                "s1"
            ])
            .is_ok()
        );
        assert!(Cli::try_parse_from(["excavator-ctl", "discrepancy", "--measured", "s1"]).is_err());
    }

    /// Table 2 and Fig. 52 are `experiment` commands that print the simulator's and the dig model's
    /// results; `model table2|fig52` are gone, and each command takes only its own options.
    #[test]
    fn table2_and_fig52_are_experiments_with_both_sections_options() {
        for args in [
            &[
                "excavator-ctl",
                "experiment",
                "table2",
                "--runs",
                "2",
                "--start-r",
                "7.4",
            ][..],
            &[
                "excavator-ctl",
                "experiment",
                "fig52",
                "--soft-cohesion-kpa",
                "5",
                "--model-soft-cohesion-kpa",
                "6",
                "--model",
                "a.json",
            ],
            &[
                "excavator-ctl",
                "experiment",
                "results",
                "--runs",
                "3",
                "--out",
                "r.md",
            ],
        ] {
            assert!(Cli::try_parse_from(args).is_ok(), "{args:?} refused");
        }
        for args in [
            &["excavator-ctl", "model", "table2"][..],
            &["excavator-ctl", "model", "fig52"],
            &["excavator-ctl", "experiment", "table1", "--base-scale", "2"],
        ] {
            assert!(Cli::try_parse_from(args).is_err(), "{args:?} parsed");
        }
    }

    /// clap shows doc comments as help: no issue numbers and no rustdoc link markup (`[`Foo`]` shows
    /// literally) anywhere in the command line's help.
    #[test]
    fn help_texts_carry_no_issue_numbers_or_doc_links() {
        fn texts(cmd: &clap::Command, path: &str, out: &mut Vec<(String, String)>) {
            let mut add = |what: String, text: Option<&clap::builder::StyledStr>| {
                if let Some(t) = text {
                    out.push((what, t.to_string()));
                }
            };
            add(format!("{path}: about"), cmd.get_about());
            add(format!("{path}: long about"), cmd.get_long_about());
            for arg in cmd.get_arguments() {
                let name = format!("{path} --{}", arg.get_id());
                add(name.clone(), arg.get_help());
                add(name.clone(), arg.get_long_help());
                for v in arg.get_possible_values() {
                    add(format!("{name} {}", v.get_name()), v.get_help());
                }
            }
            for sub in cmd.get_subcommands() {
                texts(sub, &format!("{path} {}", sub.get_name()), out);
            }
        }
        let mut found = Vec::new();
        texts(&Cli::command(), "excavator-ctl", &mut found);
        let numbered = |text: &str| {
            let lower = text.to_lowercase();
            text.split('#')
                .skip(1)
                .any(|t| t.starts_with(|c: char| c.is_ascii_digit()))
                || lower
                    .split("issue ")
                    .skip(1)
                    .any(|t| t.starts_with(|c: char| c.is_ascii_digit()))
        };
        let bad: Vec<_> = found
            .iter()
            .filter(|(_, text)| text.contains("[`") || numbered(text))
            .collect();
        assert!(bad.is_empty(), "{bad:#?}");
    }
}
