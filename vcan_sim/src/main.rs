//! `excavator-sim`: the simulated excavator behind its CAN gateway.
//!
//! ```text
//! excavator-sim --iface vcan0 [--machine FILE] [--bench FILE] [--seed N] [--effect NAME=VALUE]...
//!               [--state-log FILE] [--scan-socket ADDR]
//! excavator-sim --list-effects [--json]
//! excavator-sim bench [--seconds S]
//! ```

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use vcan_sim::node::MachineNode;
use vcan_sim::plant::PHYSICS_DT_S;
use vcan_sim::realtime::{RealtimeOptions, run};
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
    /// JSON-lines log of the true state every 10 ms.
    #[arg(long)]
    state_log: Option<PathBuf>,
    /// HOST:PORT of the range-scan socket (docs/scan-protocol.md), e.g. 127.0.0.1:7878.
    #[arg(long)]
    scan_socket: Option<String>,
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
        /// Simulated seconds per scenario.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// Run only the cases whose name contains this text (e.g. `idle`, `digging`, `node`).
        #[arg(long)]
        case: Option<String>,
    },
}

fn bench(config: &SimConfig, seconds: f64, case: Option<&str>) -> Result<()> {
    let selected = |name: &str| case.is_none_or(|c| name.contains(c));
    let steps = (seconds / PHYSICS_DT_S).round() as u64;
    let scenarios: [(&str, [f64; 6]); 3] = [
        ("idle (valves neutral)", [0.0; 6]),
        ("all joints moving", [0.6, -0.5, 0.7, 0.3, 0.0, 0.0]),
        (
            "digging (stick in, bucket curl)",
            [-0.3, 1.0, 0.4, 0.0, 0.0, 0.0],
        ),
    ];
    println!("excavator-sim bench: {seconds} simulated s per case, 1 kHz physics, one core");
    for (name, commands) in scenarios {
        if !selected(name) {
            continue;
        }
        let mut plant = config.build()?;
        let start = Instant::now();
        for k in 0..steps {
            // Reverse every 4 s so the joints stay inside their strokes.
            let sign = if (k / 4000) % 2 == 0 { 1.0 } else { -1.0 };
            plant.step(commands.map(|u| u * sign));
        }
        let wall = start.elapsed().as_secs_f64();
        println!(
            "  {name:<34} {:>8.0} x real time ({:.3} s wall, {:.2} us per step)",
            seconds / wall,
            wall,
            wall / steps as f64 * 1e6
        );
    }
    // The node adds the gateway and the CAN frame encoding.
    if !selected("node") {
        return Ok(());
    }
    let mut node = MachineNode::new(config.build()?);
    let mut out = Vec::new();
    let start = Instant::now();
    for _ in 0..steps {
        out.clear();
        node.step(&mut out);
    }
    let wall = start.elapsed().as_secs_f64();
    println!(
        "  {:<34} {:>8.0} x real time",
        "node (gateway + plant + frames)",
        seconds / wall
    );
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
    if let Some(Command::Bench { seconds, case }) = cli.command {
        return bench(&config, seconds, case.as_deref());
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
        .init();
    let node = MachineNode::new(config.build().context("building the machine")?);
    let options = RealtimeOptions {
        iface,
        state_log: cli.state_log,
        scan_socket: cli.scan_socket,
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
        run(node, options, shutdown).await
    })?;
    tracing::info!(
        simulated_s = summary.simulated_s,
        frames_sent = summary.frames_sent,
        frames_received = summary.frames_received,
        "stopped"
    );
    Ok(())
}
