//! The command line of `excavator-ctl` (clap).

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use controller::run::RunOptions;

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
    /// Run on a CAN interface in real time (SocketCAN): arm, dig, dump; Ctrl-C leaves the valves
    /// neutral and the gateway disarmed.
    Run(RunArgs),
    /// The embedded default: the simulator in-process in virtual time and a full autonomous session;
    /// writes the trace, scans, summary and plots into --out (docs/demo-output.md).
    Demo(lab::demo::DemoArgs),
    /// The thesis's Autodig results in closed loop against the simulator: table1, table2, fig52.
    Experiment(lab::experiment::ExperimentArgs),
    /// candump trace tools: decode, stats, plot, convert (csv, mcap), replay, diff (docs/trace-tools.md).
    Trace {
        /// The trace tool.
        #[command(subcommand)]
        cmd: trace_tools::TraceCommand,
    },
    /// The planner's dig model: train the actuator networks, generate simulator data, compare with
    /// the simulator, thesis Table 2 and Fig. 52 (docs/models.md).
    Model {
        /// The model command.
        #[command(subcommand)]
        cmd: lab::model_cmd::ModelCommand,
    },
    /// Model-discrepancy workflow: where the model and measured sessions disagree, the missing effect
    /// named and added (`analyse --measured DIR... --out DIR`), `eval` (hidden-effect confusion
    /// table), `bench` (docs/discrepancy.md).
    #[command(subcommand)]
    Discrepancy(discrepancy::command::DiscrepancyArgs),
}

/// Arguments of `excavator-ctl run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// CAN interface, e.g. can0 (the machine) or vcan0 (excavator-sim).
    #[arg(long)]
    pub iface: String,
    /// Decode and log the bus but never transmit (first contact with a machine).
    #[arg(long)]
    pub listen_only: bool,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
    /// Autodig maps (default: the built-in config/autodig_maps.toml).
    #[arg(long, value_name = "FILE")]
    pub maps: Option<PathBuf>,
    /// Controller config: safety, plan, Autodig and cleanup parameters (TOML; see docs/controller.md).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Record a candump -L log of every frame sent and received.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// Stop after this many digs (then swing home, neutral, disarm).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub digs: Option<u32>,
    /// Range-scan service address (host:port) for the perception enhancements.
    #[arg(long, value_name = "ADDR")]
    pub scan_addr: Option<String>,
}

impl From<RunArgs> for RunOptions {
    fn from(a: RunArgs) -> Self {
        RunOptions {
            iface: a.iface,
            listen_only: a.listen_only,
            machine: a.machine,
            maps: a.maps,
            config: a.config,
            trace: a.trace,
            digs: a.digs,
            scan_addr: a.scan_addr,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_is_consistent() {
        Cli::command().debug_assert();
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
        ])
        .unwrap();
        let Command::Run(a) = cli.command else {
            panic!("not run")
        };
        let o = RunOptions::from(a);
        assert_eq!(o.iface, "vcan0");
        assert!(o.listen_only);
        assert_eq!(o.digs, Some(3));
        assert!(Cli::try_parse_from(["excavator-ctl", "run"]).is_err());
    }

    /// A count of zero ran an empty demo, printed Table 2 from no runs and generated 54 sessions the
    /// discrepancy evaluation could not analyse; it is refused at parse time.
    #[test]
    fn zero_counts_are_refused() {
        for args in [
            &["excavator-ctl", "demo", "--digs", "0"][..],
            &["excavator-ctl", "experiment", "table2", "--runs", "0"],
            &["excavator-ctl", "experiment", "extended", "--digs", "0"],
            &["excavator-ctl", "discrepancy", "eval", "--digs", "1"],
            &["excavator-ctl", "discrepancy", "eval", "--seeds", "0"],
            &["excavator-ctl", "discrepancy", "bench", "--digs", "0"],
            &["excavator-ctl", "discrepancy", "analyse", "--out", "d"],
            &["excavator-ctl", "run", "--iface", "vcan0", "--digs", "0"],
        ] {
            assert!(Cli::try_parse_from(args).is_err(), "{args:?} parsed");
        }
        assert!(Cli::try_parse_from(["excavator-ctl", "demo", "--digs", "1"]).is_ok());
        assert!(
            Cli::try_parse_from(["excavator-ctl", "discrepancy", "eval", "--digs", "2"]).is_ok()
        );
    }
}
