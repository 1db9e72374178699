//! `excavator-ctl`: one command line over the controller (`run`), the lab (`demo`, `experiment`,
//! `model`), the trace tools (`trace`) and the discrepancy workflow (`discrepancy`). It parses
//! arguments and dispatches; the work is in those crates.

use clap::Parser;
mod cli;
mod docs;

use cli::{Cli, Command};

/// Starts the live view of `args` for a session of `machine` (outside the runtime: it has its own)
/// and prints where to watch it on stderr (with port 0, this is how a client learns the ports).
fn start_live(
    args: &live::LiveArgs,
    machine: &planner::machine::MachineConfig,
) -> anyhow::Result<live::LiveStream> {
    use anyhow::Context as _;
    let stream = live::LiveStream::start(args, machine).context("--live")?;
    let host = live::LiveAddr::parse(args.live.as_deref().unwrap_or(live::DEFAULT_ADDR))
        .map(|a| a.host)
        .unwrap_or_default();
    eprintln!(
        "live: serving the session on ws://{host}:{} (Foxglove: Open connection)",
        stream.port()
    );
    eprintln!(
        "live: operator page on http://{host}:{}/",
        stream.page_port()
    );
    Ok(stream)
}

/// `demo`, with the live view when `--live` is given.
fn demo(runtime: &tokio::runtime::Runtime, cmd: cli::DemoCmd) -> anyhow::Result<()> {
    if cmd.live.live.is_none() {
        return runtime.block_on(lab::demo::run(cmd.session));
    }
    let (sim, _, _) = lab::demo::setup(&cmd.session)?;
    let stream = start_live(&cmd.live, &sim.machine)?;
    runtime.block_on(lab::demo::run_observed(cmd.session, Box::new(stream)))
}

/// The lab's plots of a `run` session folder.
fn plots() -> std::sync::Arc<dyn onboard::summary::SessionPlots> {
    std::sync::Arc::new(lab::demo::Plots)
}

/// `site`: prints the site part of a bench file (what `run --site` reads).
fn site(args: &cli::SiteArgs) -> anyhow::Result<()> {
    use anyhow::Context as _;
    let bench = vcan_sim::scenario::Scenario::from_toml_file(&args.bench)
        .with_context(|| format!("bench {}", args.bench.display()))?;
    let text = bench.site().to_toml_string().context("writing the site")?;
    print!(
        "# The site part of the bench {} (excavator-ctl site --bench); planner::site.\n{text}",
        args.bench.display()
    );
    Ok(())
}

/// `run`, with the live view when `--live` is given.
fn run(runtime: &tokio::runtime::Runtime, cmd: cli::RunCmd) -> anyhow::Result<()> {
    if cmd.live.live.is_none() {
        return runtime.block_on(onboard::run::run(cmd.run, Some(plots())));
    }
    anyhow::ensure!(
        cmd.live.pace.is_none(),
        "--pace paces demo's virtual time; run follows the bus in real time (--time-scale)"
    );
    let machine = onboard::run::machine(&cmd.run)?;
    let mut stream = start_live(&cmd.live, &machine)?;
    let result = runtime.block_on(onboard::run::run_observed(
        cmd.run,
        &mut stream,
        Some(plots()),
    ));
    // The stream's runtime ends here, outside the session's runtime.
    drop(stream);
    result
}

/// `campaign`: one job of a plan, by the plan's kind, or the plan's status.
fn campaign(cmd: cli::CampaignCmd) -> anyhow::Result<()> {
    match cmd {
        cli::CampaignCmd::Job { plan, job } => {
            let plan = lab::campaign::Plan::read(&plan)?;
            match plan.kind.as_str() {
                discrepancy::eval::CAMPAIGN_KIND => discrepancy::eval::run_planned_job(&plan, &job),
                discrepancy::fleet::CAMPAIGN_KIND => {
                    discrepancy::fleet::run_planned_job(&plan, &job)
                }
                other => anyhow::bail!("a plan of kind {other:?}: this excavator-ctl runs none"),
            }
        }
        cli::CampaignCmd::Status { plan } => {
            print!("{}", lab::campaign::Plan::read(&plan)?.status_text());
            Ok(())
        }
    }
}

fn main() -> std::process::ExitCode {
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    let cli = Cli::parse();
    // `--quiet`: warnings and errors only, unless RUST_LOG asks for more.
    let quiet = matches!(&cli.command, Command::Demo(d) if d.session.quiet);
    tracing_subscriber::registry()
        .with(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
                tracing_subscriber::EnvFilter::new(if quiet { "warn" } else { "info" })
            }),
        )
        .with(
            tracing_subscriber::fmt::layer()
                // Through the console: log lines do not break the progress line of `demo` and `run`.
                .with_writer(|| onboard::console::ConsoleWriter)
                // Colours only for a person at a terminal: a journal, a file or a pipe gets plain text.
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())),
        )
        // `run`'s session log (run.log in its session folder), while one is open.
        .with(onboard::session_log::layer())
        .init();
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: starting the runtime: {e:#}");
            return std::process::ExitCode::FAILURE;
        }
    };
    let result = match cli.command {
        Command::Run(cmd) => run(&runtime, cmd),
        Command::Ctl(args) => runtime.block_on(onboard::run::ctl(args)),
        Command::Site(args) => site(&args),
        Command::Demo(cmd) => demo(&runtime, cmd),
        Command::Experiment(args) => lab::experiment::run(&args),
        Command::Trace { cmd } => runtime.block_on(trace_tools::run(cmd)),
        Command::Model { cmd } => lab::model::run(cmd),
        Command::Discrepancy(args) => discrepancy::command::run(args),
        Command::GenerateDocs(args) => docs::generate(&args),
        Command::Campaign(cmd) => campaign(cmd),
        Command::Calibrate(args) => calibration::run(&args).map(|report| {
            println!("{}", calibration::report_markdown(&report));
            println!("wrote {}", args.out.display());
        }),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
