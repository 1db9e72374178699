//! `excavator-sim`: the simulated excavator behind its CAN gateway.
//!
//! ```text
//! excavator-sim --iface vcan0 [--machine FILE] [--bench FILE] [--seed N] [--effect NAME=VALUE]...
//!               [--state-log FILE] [--scan-socket ADDR] [--profile FILE]
//!               (--key-file FILE | --insecure-no-key)
//! excavator-sim --list-effects [--json]
//! excavator-sim bench [--seconds S] [--case TEXT] [--repeat N]
//! ```

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use firmware_bridge::secoc::SessionKey;
use firmware_bridge::transport::TimeScale;
use vcan_sim::node::MachineNode;
use vcan_sim::plant::PHYSICS_DT_S;
use vcan_sim::realtime::{RealtimeOptions, run, run_with_profile};
use vcan_sim::{SimConfig, effects};

#[derive(Debug, Parser)]
#[command(
    name = "excavator-sim",
    version,
    about = "The excavator emulated behind its CAN gateway"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// CAN interface to run on in real time (SocketCAN), e.g. vcan0.
    #[arg(long)]
    iface: Option<String>,
    /// Machine file (default: the bundled config/machine.toml).
    #[arg(long)]
    machine: Option<PathBuf>,
    /// Bench scenario file (default: the bundled config/bench.toml).
    #[arg(long)]
    bench: Option<PathBuf>,
    /// Seed for sensor noise and random boulders (overrides the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Hidden effect NAME=VALUE (repeatable; see --list-effects).
    #[arg(long = "effect", value_name = "NAME=VALUE")]
    effects: Vec<String>,
    /// JSON-lines log of the true state at every resolver sample (every 10 ms of simulated time).
    #[arg(long)]
    state_log: Option<PathBuf>,
    /// HOST:PORT of the range-scan socket (docs/scan-protocol.md), e.g. 127.0.0.1:7878.
    #[arg(long)]
    scan_socket: Option<String>,
    /// File with the machine's 128-bit authentication key (32 hex digits, mode 600); the controller
    /// must hold the same key. Required on a bus (docs/deployment.md, "The machine's key") unless
    /// --insecure-no-key is given.
    #[arg(long)]
    key_file: Option<PathBuf>,
    /// Run the gateway without a key: it accepts control frames sealed with the public all-zero
    /// key, which anyone on the bus can forge. Bench tests only; logged as an error.
    #[arg(long, conflicts_with = "key_file")]
    insecure_no_key: bool,
    /// Machine profile (TOML naming the gateway's DBC and the mapping, docs/machine-profile.md): speak
    /// that gateway's messages on the bus. Default: the project's own protocol (excavator.dbc).
    #[arg(long, value_name = "FILE")]
    profile: Option<PathBuf>,
    /// Simulated seconds per wall second, 0.1 to 20 (default 1, real time); the controller must run
    /// at the same scale (`excavator-ctl run --time-scale`).
    #[arg(long, value_name = "X", default_value_t = TimeScale::REAL_TIME)]
    time_scale: TimeScale,
    /// Print the hidden-effects registry and exit.
    #[arg(long)]
    list_effects: bool,
    /// With --list-effects: print JSON.
    #[arg(long, requires = "list_effects")]
    json: bool,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Measures simulated seconds per wall second in-process on one core.
    Bench {
        /// Simulated seconds per scenario (0.01 to 3600).
        #[arg(long, default_value_t = 60.0, value_parser = parse_bench_seconds)]
        seconds: f64,
        /// Run only the cases whose name contains this text (e.g. `idle`, `digging`, `node`).
        #[arg(long)]
        case: Option<String>,
        /// Runs per case, 1 to 100 (the figures are printed as a range).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=MAX_BENCH_REPEAT))]
        repeat: u32,
    },
}

/// Longest `bench --seconds`: an hour of simulated time per case is minutes of CPU; more is a typo
/// (`1e308` ran for ever).
const MAX_BENCH_SECONDS: f64 = 3600.0;
/// Most `bench --repeat` runs per case.
const MAX_BENCH_REPEAT: i64 = 100;

/// `--seconds`: a finite number of simulated seconds in `[0.01, MAX_BENCH_SECONDS]`.
fn parse_bench_seconds(text: &str) -> std::result::Result<f64, String> {
    let seconds: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    firmware_bridge::range::Limits::closed(0.01, MAX_BENCH_SECONDS, "")
        .check(seconds)
        .map(|()| seconds)
        .map_err(|e| format!("{} simulated seconds: {e}", text.trim()))
}

/// CPU time this thread has run (ns), from `/proc/thread-self/schedstat` (Linux); `None` elsewhere.
/// Unlike wall time it does not grow while other processes hold the core, so on the shared build
/// machine it measures what the simulator costs on one core.
fn thread_cpu_ns() -> Option<u64> {
    // A yield makes the kernel account the running slice before we read it.
    std::thread::yield_now();
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// The 1, 5 and 15 minute load averages, as `/proc/loadavg` prints them.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

/// Wall and CPU time of one run of `steps` physics steps.
struct Timing {
    wall_s: f64,
    cpu_s: Option<f64>,
}

fn timed(mut run: impl FnMut()) -> Timing {
    let cpu0 = thread_cpu_ns();
    let start = Instant::now();
    run();
    let wall_s = start.elapsed().as_secs_f64();
    let cpu_s = cpu0
        .zip(thread_cpu_ns())
        .map(|(a, b)| b.saturating_sub(a) as f64 * 1e-9);
    Timing { wall_s, cpu_s }
}

fn bench(config: &SimConfig, seconds: f64, case: Option<&str>, repeat: u32) -> Result<()> {
    // Checked by the argument parser too; `bench` may be called otherwise in future.
    if let Err(e) = parse_bench_seconds(&seconds.to_string()) {
        bail!("--seconds: {e}");
    }
    if !(1..=MAX_BENCH_REPEAT).contains(&i64::from(repeat)) {
        bail!("--repeat must be in [1, {MAX_BENCH_REPEAT}], got {repeat}");
    }
    let selected = |name: &str| case.is_none_or(|c| name.contains(c));
    let steps = (seconds / PHYSICS_DT_S).round().max(1.0) as u64;
    let scenarios: [(&str, Option<[f64; 6]>); 4] = [
        ("idle (valves neutral)", Some([0.0; 6])),
        ("all joints moving", Some([0.6, -0.5, 0.7, 0.3, 0.0, 0.0])),
        (
            "digging (stick in, bucket curl)",
            Some([-0.3, 1.0, 0.4, 0.0, 0.0, 0.0]),
        ),
        // The node adds the gateway (disarmed: valves neutral) and the CAN frame encoding.
        ("node (gateway + plant + frames)", None),
    ];
    println!(
        "excavator-sim bench: {seconds} simulated s per case, 1 kHz physics, one core, {repeat} run(s) \
         each; load average {} ({} CPUs)",
        load_average(),
        std::thread::available_parallelism().map_or(0, usize::from)
    );
    println!(
        "  {:<34} {:>14} {:>14} {:>14}",
        "case", "x real (wall)", "x real (CPU)", "ns/step (CPU)"
    );
    for (name, commands) in scenarios {
        if !selected(name) {
            continue;
        }
        let mut runs = Vec::new();
        for _ in 0..repeat.max(1) {
            let timing = match commands {
                Some(commands) => {
                    let mut plant = config.build()?;
                    timed(|| {
                        for k in 0..steps {
                            // Reverse every 4 s so the joints stay inside their strokes.
                            let sign = if (k / 4000) % 2 == 0 { 1.0 } else { -1.0 };
                            plant.step(commands.map(|u| u * sign));
                        }
                    })
                }
                None => {
                    let mut node = MachineNode::new(config.build()?);
                    let mut out = Vec::new();
                    timed(|| {
                        for _ in 0..steps {
                            out.clear();
                            node.step(&mut out);
                        }
                    })
                }
            };
            runs.push(timing);
        }
        let range = |values: Vec<f64>, digits: usize| {
            let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if values.len() > 1 {
                format!("{lo:.digits$}-{hi:.digits$}")
            } else {
                format!("{lo:.digits$}")
            }
        };
        let wall = range(runs.iter().map(|t| seconds / t.wall_s).collect(), 0);
        let cpu: Option<Vec<f64>> = runs.iter().map(|t| t.cpu_s).collect();
        let (cpu_ratio, cpu_ns) = match cpu {
            Some(cpu) => (
                range(cpu.iter().map(|c| seconds / c).collect(), 0),
                range(cpu.iter().map(|c| c / steps as f64 * 1e9).collect(), 0),
            ),
            None => ("n/a".into(), "n/a".into()),
        };
        println!("  {name:<34} {wall:>14} {cpu_ratio:>14} {cpu_ns:>14}");
    }
    println!("  load average after: {}", load_average());
    Ok(())
}

fn main() {
    if let Err(e) = real_main() {
        eprintln!("excavator-sim: {e:#}");
        std::process::exit(1);
    }
}

fn real_main() -> Result<()> {
    let cli = Cli::parse();
    if cli.list_effects {
        if cli.json {
            println!("{}", effects::registry_json()?);
        } else {
            print!("{}", effects::registry_table());
        }
        return Ok(());
    }
    let config = SimConfig::load(
        cli.machine.as_deref(),
        cli.bench.as_deref(),
        cli.seed,
        &cli.effects,
    )
    .context("loading the simulation")?;
    if let Some(Command::Bench {
        seconds,
        case,
        repeat,
    }) = cli.command
    {
        return bench(&config, seconds, case.as_deref(), repeat);
    }
    let Some(iface) = cli.iface else {
        bail!("--iface is required (or use --list-effects, or the `bench` subcommand)");
    };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        // Colours only for a person at a terminal: a journal, a file or a pipe gets plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let key = gateway_key(cli.key_file.as_deref(), cli.insecure_no_key)?;
    let profile = cli
        .profile
        .as_deref()
        .map(firmware_bridge::profile::Profile::load)
        .transpose()?
        .map(std::sync::Arc::new);
    // Every start is a new series of sessions, so no recording of an earlier run is accepted.
    let session_seed: u64 = rand::random();
    let plant = config.build().context("building the machine")?;
    // A profile's gateway sends at its periods and keeps its watchdogs.
    let mut node = match &profile {
        Some(p) => MachineNode::with_timing(plant, &p.timing())
            .with_context(|| format!("{}: the gateway's timeouts", p.origin()))?,
        None => MachineNode::new(plant),
    }
    .with_security(&key, session_seed);
    node.set_gateway_name(config.gateway_name);
    let options = RealtimeOptions {
        iface,
        state_log: cli.state_log,
        scan_socket: cli.scan_socket,
        time_scale: cli.time_scale,
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the tokio runtime")?;
    let summary = runtime.block_on(async {
        let shutdown = async {
            // If the signal handler cannot be installed, run until killed.
            if tokio::signal::ctrl_c().await.is_err() {
                std::future::pending::<()>().await;
            }
        };
        match profile {
            Some(profile) => run_with_profile(node, options, profile, shutdown).await,
            None => run(node, options, shutdown).await,
        }
    })?;
    tracing::info!(
        simulated_s = summary.simulated_s,
        frames_sent = summary.frames_sent,
        overruns = summary.overruns,
        slipped_s = summary.slipped_s,
        max_lag_s = summary.max_lag_s,
        frames_received = summary.frames_received,
        "stopped"
    );
    Ok(())
}

/// The gateway's key: the provisioned one, or the public all-zero key only when `insecure` asks
/// for it explicitly (and then loudly logged).
///
/// # Errors
/// No key file and no `--insecure-no-key`; an unreadable or invalid key file.
fn gateway_key(key_file: Option<&std::path::Path>, insecure: bool) -> Result<SessionKey> {
    match key_file {
        Some(path) => Ok(SessionKey::from_file(path)?),
        None if insecure => {
            tracing::error!(
                "INSECURE: --insecure-no-key: no key provisioned, the gateway accepts control frames \
                 sealed with the public all-zero key, which anyone who can send on the bus can forge \
                 (docs/protocol.md). Bench tests only."
            );
            Ok(SessionKey::PUBLIC)
        }
        None => bail!(
            "no key provisioned: the gateway refuses to run on the bus without one. Give the \
             machine's key with --key-file FILE (32 random hex digits, mode 600, the same file as \
             the controller's; docs/deployment.md, \"The machine's key\"), or --insecure-no-key for \
             a bench test with the public all-zero key"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without --key-file the simulator used to run its gateway with the public all-zero key, silently.
    #[test]
    fn the_gateway_refuses_to_run_without_a_key() {
        let e = format!("{:#}", gateway_key(None, false).unwrap_err());
        assert!(e.contains("no key provisioned"), "{e}");
        assert!(e.contains("docs/deployment.md"), "{e}");
        assert_eq!(gateway_key(None, true).unwrap(), SessionKey::PUBLIC);
        assert!(
            Cli::try_parse_from(["excavator-sim", "--key-file", "k", "--insecure-no-key"]).is_err(),
            "a key and the insecure mode contradict each other"
        );
    }

    #[test]
    fn bench_arguments_are_bounded() {
        for bad in ["1e308", "inf", "nan", "-1", "0", "3601", "ten"] {
            assert!(
                Cli::try_parse_from(["excavator-sim", "bench", "--seconds", bad]).is_err(),
                "--seconds {bad}"
            );
        }
        for bad in ["0", "101", "4294967295"] {
            assert!(
                Cli::try_parse_from(["excavator-sim", "bench", "--repeat", bad]).is_err(),
                "--repeat {bad}"
            );
        }
        let cli = Cli::try_parse_from([
            "excavator-sim",
            "bench",
            "--seconds",
            "0.5",
            "--repeat",
            "3",
        ])
        .expect("valid arguments");
        assert!(matches!(
            cli.command,
            Some(Command::Bench { seconds, repeat: 3, .. }) if seconds == 0.5
        ));
        let err = Cli::try_parse_from(["excavator-sim", "bench", "--seconds", "1e308"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("must be finite and in [0.01, 3600]"), "{err}");
    }
}
