//! `excavator-ctl run`: the controller on a CAN bus in real time (or `--time-scale` times faster,
//! with the simulator at the same scale), with the action source of `--strategy`:
//!
//! - `planned` / `predefined`: the session driver that `demo` runs ([`SessionDriver`]: the dig
//!   planner or the predefined sequence, Autodig, cleanup, tracking back, the hardness index and the
//!   soil estimate online), with range scans from the scan service (`--scan-addr`;
//!   docs/scan-protocol.md) and the bench file's grid, floor and start pose (`--bench`, default
//!   config/bench_extended.toml, as in `demo`); the planner runs off the control loop
//!   ([`controller::run::run_session_loop`]);
//! - `fixed` (default): the controller config's action list, as before the planner was wired.
//!
//! With `--out DIR` the session folder is the one `demo` writes (trace, scans, `summary.json`,
//! `summary.md`, plots, `soil_samples.json`; docs/demo-output.md), without the simulator's truth
//! (true payload, true terrain), which a bus session does not have, plus `session_state.json`: the
//! session saved after every completed action ([`crate::resume`]). `--resume DIR` loads it, checks
//! that it is this machine's, bench's and configuration's, and goes on with the session where it
//! stood after the normal arming handshake, appending to its trace and records. The run's log goes
//! to the folder's `run.log` too ([`crate::session_log`]).
//!
//! Before it opens the bus, `run` reads the interface's link over netlink ([`check_link`]): it logs
//! the bitrate, state, `restart-ms` and listen-only mode, records them in the summary, and refuses a
//! down link or a listen-only one without `--listen-only`. `--config-dir DIR` (the package's
//! /etc/excavator) supplies the configuration files no option names ([`CONFIG_DIR_FILES`]).
//!
//! The operator's commands come from the control socket (`excavator-ctl ctl`) and, when standard
//! input is a terminal, from its keys ([`crate::keys`]); both through one [`OperatorPort`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use controller::node::{ControllerConfig, ControllerNode};
#[cfg(doc)]
use controller::operator::OperatorPort;
use controller::run::{
    CONTROL_PERIOD, LoopSession, StopReason, run_session_loop, scan_client_config,
};
use controller::scan_client::{NoScans, ScanClient, ScanService};
use controller::session::{NoObserver, ScanSource, SessionDriver, SessionEvent, SessionObserver};
use controller::session_state::{SessionIdentity, fingerprint};
use controller::state_file::StateFileError;
use firmware_bridge::profile::Profile;
use firmware_bridge::trace::Recorder;
use firmware_bridge::transport::{Bus, LinkStatus, ProfileBus, SocketCanBus, TimeScale};
use planner::autodig::AutodigMaps;
use planner::machine::MachineConfig;
use planner::plan::PlannerConfig;
use vcan_sim::SimConfig;

use crate::demo::{self, DemoArgs, DemoStrategy, SessionEnd, SessionRecords};
use crate::resume::{RunRecords, RunState, StateWriter};

/// Arguments of `excavator-ctl run`.
#[derive(Debug, Clone, Args)]
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
    /// The machine's authentication key: 32 hex digits in a file readable by its owner only (chmod
    /// 600), the same file the gateway holds (excavator-sim --key-file). Overrides the config's
    /// `[security] key_file`. Without a key the control frames carry freshness only (docs/protocol.md).
    #[arg(long, value_name = "FILE")]
    pub key_file: Option<PathBuf>,
    /// Record a candump -L log of every frame sent and received (default with --out: DIR/trace.log).
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// Stop after this many digs (then swing home, neutral, disarm).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub digs: Option<u32>,
    /// Range-scan service address (host:port): the planner's map and the perception enhancements.
    #[arg(long, value_name = "ADDR")]
    pub scan_addr: Option<String>,
    /// The action source: the dig planner, the predefined sequence of 6.2, or the config's plan.
    #[arg(long, value_enum, default_value_t = DemoStrategy::Fixed)]
    pub strategy: DemoStrategy,
    /// Bench scenario file: the map's grid, the floor and the start pose of the planned and
    /// predefined strategies (default: the built-in config/bench_extended.toml).
    #[arg(long, value_name = "FILE")]
    pub bench: Option<PathBuf>,
    /// The simulator's seed, recorded in summary.json (default: the bench file's).
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Planner settings (default: the built-in config/planner.toml); the floor is the bench's.
    #[arg(long, value_name = "FILE")]
    pub planner: Option<PathBuf>,
    /// Hardness regression (default: the built-in config/hardness_regression.toml).
    #[arg(long, value_name = "FILE")]
    pub hardness: Option<PathBuf>,
    /// Session seconds per wall second, 0.1 to 20 (default 1, real time); excavator-sim must run
    /// with the same --time-scale.
    #[arg(long, value_name = "X", default_value_t = TimeScale::REAL_TIME)]
    pub time_scale: TimeScale,
    /// Session folder: trace, scans, summary and plots as `demo` writes them.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Go on with the session saved in this session folder (its `session_state.json`), with the
    /// same files and settings it was started with; the folder is the session folder.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// The operator's control socket (`excavator-ctl ctl`; default: `control.sock` in the session
    /// folder, none without one).
    #[arg(long, value_name = "PATH")]
    pub control_socket: Option<PathBuf>,
    /// The deployed configuration's folder (the package's /etc/excavator): machine.toml,
    /// autodig_maps.toml, controller.toml, bench.toml, planner.toml, hardness_regression.toml, key
    /// and profile.toml, each used when present; a file given by its own option wins, a missing one is the
    /// built-in default.
    #[arg(long, value_name = "DIR")]
    pub config_dir: Option<PathBuf>,
    /// Machine profile (TOML naming the gateway's DBC and the mapping, docs/machine-profile.md):
    /// speak that gateway's messages on the bus; the trace records them. Default: the project's own
    /// protocol (excavator.dbc).
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
}

/// The files `--config-dir` supplies, by name in the folder.
pub const CONFIG_DIR_FILES: [&str; 8] = [
    "machine.toml",
    "autodig_maps.toml",
    "controller.toml",
    "bench.toml",
    "planner.toml",
    "hardness_regression.toml",
    "key",
    "profile.toml",
];

/// Arguments of `excavator-ctl ctl`.
#[derive(Debug, Clone, Args)]
pub struct CtlArgs {
    /// The running controller's control socket (`run --control-socket`, default
    /// `SESSION_DIR/control.sock`).
    #[arg(long, value_name = "PATH")]
    pub socket: PathBuf,
    /// status, pause, resume, estop, reset or stop.
    pub command: controller::operator::Command,
    /// Why (written to the controller's log).
    #[arg(long)]
    pub reason: Option<String>,
}

/// `excavator-ctl ctl`: sends one operator command and prints the controller's state after it.
///
/// # Errors
/// The socket cannot be reached, or the controller refused the request.
pub async fn ctl(args: CtlArgs) -> anyhow::Result<()> {
    let reply = controller::operator::request(
        &args.socket,
        &controller::operator::Request {
            cmd: args.command,
            reason: args.reason,
        },
    )
    .await
    .context("control socket")?;
    if let Some(s) = &reply.status {
        println!(
            "phase {} | safety {} | fault {} | action {} (#{}) | digs {}{}{}",
            s.phase,
            s.safety,
            s.fault.as_deref().unwrap_or("none"),
            s.action.as_deref().unwrap_or("none"),
            s.action_index,
            s.digs,
            if s.paused { " | paused" } else { "" },
            if s.stopping { " | stopping" } else { "" },
        );
    }
    match reply.error {
        Some(e) if !reply.ok => anyhow::bail!("the controller refused: {e}"),
        _ => Ok(()),
    }
}

impl RunArgs {
    /// The command line's defaults on `iface`: the fixed strategy at real time, built-in files, no
    /// session folder (library callers and tests set what they need).
    #[must_use]
    pub fn new(iface: &str) -> Self {
        Self {
            iface: iface.to_owned(),
            listen_only: false,
            machine: None,
            maps: None,
            config: None,
            key_file: None,
            trace: None,
            digs: None,
            scan_addr: None,
            strategy: DemoStrategy::Fixed,
            bench: None,
            seed: None,
            planner: None,
            hardness: None,
            time_scale: TimeScale::REAL_TIME,
            out: None,
            resume: None,
            control_socket: None,
            config_dir: None,
            profile: None,
        }
    }

    /// The session folder: `--resume`'s or `--out`'s.
    ///
    /// # Errors
    /// `--out` and `--resume` name different folders.
    pub fn session_dir(&self) -> anyhow::Result<Option<PathBuf>> {
        match (&self.out, &self.resume) {
            (Some(o), Some(r)) if o != r => anyhow::bail!(
                "--out {} and --resume {}: a resumed session stays in its folder",
                o.display(),
                r.display()
            ),
            (o, r) => Ok(r.clone().or_else(|| o.clone())),
        }
    }

    /// The arguments with the files of `--config-dir` filled in where no option names one
    /// ([`CONFIG_DIR_FILES`]); unchanged without `--config-dir`.
    #[must_use]
    pub fn with_config_dir(&self) -> Self {
        let mut a = self.clone();
        let Some(dir) = &self.config_dir else {
            return a;
        };
        let [
            machine,
            maps,
            config,
            bench,
            planner,
            hardness,
            key,
            profile,
        ] = CONFIG_DIR_FILES.map(|name| Some(dir.join(name)).filter(|p| p.is_file()));
        for (given, found) in [
            (&mut a.machine, machine),
            (&mut a.maps, maps),
            (&mut a.config, config),
            (&mut a.bench, bench),
            (&mut a.planner, planner),
            (&mut a.hardness, hardness),
            (&mut a.key_file, key),
            (&mut a.profile, profile),
        ] {
            if given.is_none() {
                *given = found;
            }
        }
        a
    }

    /// One line naming the file of each configuration option, or `built-in`.
    #[must_use]
    pub fn config_files(&self) -> String {
        let show = |p: &Option<PathBuf>| {
            p.as_ref()
                .map_or_else(|| "built-in".to_owned(), |p| p.display().to_string())
        };
        format!(
            "machine {}, maps {}, controller {}, bench {}, planner {}, hardness {}, key {}, \
             profile {}",
            show(&self.machine),
            show(&self.maps),
            show(&self.config),
            show(&self.bench),
            show(&self.planner),
            show(&self.hardness),
            self.key_file
                .as_ref()
                .map_or_else(|| "none".to_owned(), |p| p.display().to_string()),
            show(&self.profile),
        )
    }

    /// `demo`'s arguments for the same strategy, files and bench (one setup for both).
    fn demo_args(&self) -> DemoArgs {
        let out = self.resume.clone().or_else(|| self.out.clone());
        let mut d = DemoArgs::new(out.unwrap_or_default());
        d.strategy = self.strategy;
        d.machine.clone_from(&self.machine);
        d.bench.clone_from(&self.bench);
        d.seed = self.seed;
        d.maps.clone_from(&self.maps);
        d.config.clone_from(&self.config);
        d.planner.clone_from(&self.planner);
        d.hardness.clone_from(&self.hardness);
        d.profile.clone_from(&self.profile);
        d
    }
}

/// Builds the node and the driver of a run (see the module docs for the strategies).
///
/// # Errors
/// Unreadable or invalid files, an inconsistent configuration, a planned strategy without a scan
/// service.
pub fn build(args: &RunArgs) -> anyhow::Result<(ControllerNode, SessionDriver, RunSetup)> {
    let args = &args.with_config_dir();
    let dargs = args.demo_args();
    let (sim, mut config, maps) = demo::setup(&dargs)?;
    let session = match args.strategy.session() {
        Some(st) => {
            anyhow::ensure!(
                args.scan_addr.is_some(),
                "--strategy {} plans on range scans: give the scan service's --scan-addr",
                args.strategy.name()
            );
            Some(demo::build_session(&dargs, &sim, st)?)
        }
        None => {
            // The config's plan as it is (repeat and all), not the demo's plan.
            config = match &args.config {
                Some(p) => ControllerConfig::from_toml_file(p).context("controller config")?,
                None => ControllerConfig::default(),
            };
            None
        }
    };
    config.cycle.max_digs = match (args.digs, args.strategy) {
        (Some(n), _) => Some(n),
        // The config's own limit (a repeating plan may stop only there).
        (None, DemoStrategy::Fixed) => config.cycle.max_digs,
        // The session driver ends the session when its region is done.
        (None, _) => None,
    };
    config.safety.listen_only |= args.listen_only;
    // A profile's gateway: the stale-data limits in its periods, checked against its watchdogs.
    if let Some(p) = demo::load_profile(args.profile.as_deref())? {
        config.safety = config.safety.for_gateway(p.timing());
    }
    // Without a scan service nobody would answer the cycle's requests: dig on the plain angle rules
    // at once instead of waiting `scan_timeout_s` before every dig.
    if args.scan_addr.is_none() {
        config.cycle.scan = false;
    }
    let machine = machine_of(args, &sim)?;
    let full_bucket_n = machine.bucket.capacity_m3
        * sim.scenario.soil.density_kg_per_m3
        * planner::machine::GRAVITY_M_PER_S2;
    if let Some(file) = &args.key_file {
        config.security.key_file = Some(file.clone());
    }
    let key = config.security.load_key().context("the machine's key")?;
    let planner = demo::planner_config(&dargs, &sim)?;
    let identity = session_identity(&machine, &sim, args.strategy, &config, &planner, &maps);
    let mut node =
        ControllerNode::new(&machine, maps, config).context("controller configuration")?;
    match &key {
        Some(key) => {
            node.set_key(key);
            tracing::info!("control frames authenticated with the provisioned key");
        }
        None => tracing::warn!(
            "no key provisioned (--key-file, [security] key_file): the control frames carry \
             freshness only, and anyone who can send on the bus can forge them (docs/protocol.md)"
        ),
    }
    let mut driver = SessionDriver::new(session, None, &mut node);
    driver.set_detached_planning(true);
    let setup = RunSetup {
        bench: sim.scenario.name.clone(),
        seed: sim.scenario.seed,
        soil_contact: sim.scenario.soil_contact,
        full_bucket_n,
        identity,
    };
    Ok((node, driver, setup))
}

/// The machine a run of `args` controls.
///
/// # Errors
/// An unreadable or invalid machine or bench file.
pub fn machine(args: &RunArgs) -> anyhow::Result<MachineConfig> {
    let args = &args.with_config_dir();
    let (sim, _, _) = demo::setup(&args.demo_args())?;
    machine_of(args, &sim)
}

/// The machine of `args` with the simulator configuration `sim` of its bench: the fixed plan's is
/// the machine file's, the planned and predefined strategies' the bench's.
fn machine_of(args: &RunArgs, sim: &SimConfig) -> anyhow::Result<MachineConfig> {
    Ok(match args.strategy {
        DemoStrategy::Fixed => {
            MachineConfig::load_or_default(args.machine.as_deref()).context("machine file")?
        }
        _ => sim.machine.clone(),
    })
}

/// What a saved session of `strategy` on `machine` and `sim`'s bench with `config`, `planner` and
/// `maps` belongs to ([`SessionIdentity`]): a state is resumed only by a run with the same.
#[must_use]
pub fn session_identity(
    machine: &MachineConfig,
    sim: &SimConfig,
    strategy: DemoStrategy,
    config: &ControllerConfig,
    planner: &PlannerConfig,
    maps: &AutodigMaps,
) -> SessionIdentity {
    SessionIdentity {
        machine: fingerprint(machine),
        bench: sim.scenario.name.clone(),
        seed: sim.scenario.seed,
        strategy: strategy.name().to_owned(),
        config: {
            // The dig count, listen-only and the key file may change between a session and its resumption.
            let mut c = config.clone();
            c.cycle.max_digs = None;
            c.safety.listen_only = false;
            // The key is the machine's, not the session's: it may be re-provisioned.
            c.security.key_file = None;
            fingerprint(&(c, planner, maps))
        },
    }
}

/// What a run's summary takes from its setup.
#[derive(Debug, Clone)]
pub struct RunSetup {
    bench: String,
    seed: u64,
    soil_contact: vcan_sim::scenario::SoilContactIntegration,
    full_bucket_n: f64,
    identity: SessionIdentity,
}

/// The session's trace file as the run records it.
#[derive(Debug)]
pub struct SessionTrace {
    /// Records every frame sent and received (attached to the bus by the caller).
    pub recorder: Recorder,
    /// Frames already in the file (a resumed session's earlier runs).
    pub frames_before: u64,
}

/// `excavator-ctl run`: opens the interface, runs the session until Ctrl-C/SIGTERM or its end, closes
/// the trace and writes the session folder.
///
/// # Errors
/// Configuration, interface, bus, scan and file errors.
pub async fn run(args: RunArgs) -> anyhow::Result<()> {
    run_observed(args, &mut NoObserver).await
}

/// As [`run`], with `observer` watching every control step (the live view) and offered the
/// operator control path.
///
/// # Errors
/// As [`run`].
pub async fn run_observed(args: RunArgs, observer: &mut dyn SessionObserver) -> anyhow::Result<()> {
    // A bad profile stops the run before it touches the bus. Without one the bus speaks the default
    // profile, the identity: every frame passes unchanged.
    let profile = match demo::load_profile(args.with_config_dir().profile.as_deref())? {
        Some(p) => p,
        None => std::sync::Arc::new(Profile::default_profile()?),
    };
    let link = check_link(&args)?;
    let mut bus = SocketCanBus::open(&args.iface)
        .with_context(|| format!("opening CAN interface {}", args.iface))?;
    let trace = match trace_path(&args)? {
        Some(p) => {
            let (recorder, frames_before) =
                crate::resume::open_trace(&p, &args.iface, args.resume.is_some())?;
            bus.set_recorder(recorder.clone());
            Some(SessionTrace {
                recorder,
                frames_before,
            })
        }
        None => None,
    };
    let console = RunConsole {
        keys: operator_terminal(),
        session_log: true,
        link: Some(link),
    };
    let bus = ProfileBus::new(bus, profile);
    let result = run_on_observed(
        &bus,
        trace,
        &args,
        console,
        controller::run::shutdown_signal(),
        observer,
    )
    .await;
    if !bus.profile().is_identity() {
        bus.log_stats();
    }
    result
}

/// The link of `--iface` over netlink, refused when it is down, or in listen-only mode without
/// `--listen-only` (the controller's own listen-only: it decodes, logs and records the trace but
/// never transmits, so it never arms).
///
/// # Errors
/// A missing interface (with the commands that create or configure it), a netlink failure, or the
/// refusal, each one line.
pub fn check_link(args: &RunArgs) -> anyhow::Result<LinkStatus> {
    let link = LinkStatus::query(&args.iface)?;
    link.check(args.listen_only)?;
    Ok(link)
}

/// What `run` does besides the session: the operator's keys, the session log and the link.
#[derive(Debug, Default)]
pub struct RunConsole {
    /// The terminal whose keys are operator commands ([`crate::keys`]); `None`: no key reader.
    pub keys: Option<std::fs::File>,
    /// Write the log to the session folder's `run.log` too ([`crate::session_log`]; the binary's
    /// subscriber carries its layer).
    pub session_log: bool,
    /// The interface's link as [`check_link`] found it: logged, and recorded in the summary.
    pub link: Option<LinkStatus>,
}

/// Standard input when it is a terminal (a person at the console), else `None`: no key reader for a
/// pipe, a file or a service.
fn operator_terminal() -> Option<std::fs::File> {
    use std::io::IsTerminal as _;
    use std::os::fd::AsFd as _;
    let stdin = std::io::stdin();
    if !stdin.is_terminal() {
        return None;
    }
    match stdin.as_fd().try_clone_to_owned() {
        Ok(fd) => Some(std::fs::File::from(fd)),
        Err(e) => {
            tracing::warn!(error = %e, "operator keys: standard input cannot be used: no keys");
            None
        }
    }
}

/// `--trace`, or the session folder's `trace.log`.
///
/// # Errors
/// As [`RunArgs::session_dir`].
pub fn trace_path(args: &RunArgs) -> anyhow::Result<Option<PathBuf>> {
    Ok(match &args.trace {
        Some(t) => Some(t.clone()),
        None => args.session_dir()?.map(|o| o.join("trace.log")),
    })
}

/// As [`run`] on a bus the caller opened (with the trace's recorder attached to it, closed here).
///
/// # Errors
/// As [`run`]; with `--resume`, a missing, broken or foreign state file (naming the file and the
/// field).
pub async fn run_on<B: Bus>(
    bus: &B,
    trace: Option<SessionTrace>,
    args: &RunArgs,
    console: RunConsole,
    shutdown: impl std::future::Future<Output = ()>,
) -> anyhow::Result<()> {
    run_on_observed(bus, trace, args, console, shutdown, &mut NoObserver).await
}

/// As [`run_on`], with `observer` called after every control step (at the session time of the
/// step) and at the end, and offered the operator control path (the control socket's port, or a
/// port of its own without a socket).
///
/// # Errors
/// As [`run_on`].
pub async fn run_on_observed<B: Bus>(
    bus: &B,
    trace: Option<SessionTrace>,
    args: &RunArgs,
    console: RunConsole,
    shutdown: impl std::future::Future<Output = ()>,
    live: &mut dyn SessionObserver,
) -> anyhow::Result<()> {
    let wall = Instant::now();
    let (mut node, mut driver, setup) = build(args)?;
    let out_dir = args.session_dir()?;
    let resumed = match &args.resume {
        Some(dir) => {
            let path = crate::resume::state_path(dir);
            let state: RunState = controller::session_state::load(&path, &setup.identity)
                .context("--resume: the saved session")?;
            // The session's dig count, unless --digs gives another.
            if args.digs.is_none() && state.records.max_digs.is_some() {
                let mut with_digs = args.clone();
                with_digs.digs = state.records.max_digs;
                (node, driver, _) = build(&with_digs)?;
            }
            driver
                .restore(&state.driver, &mut node)
                .map_err(|e| StateFileError::field(&path, e))
                .context("--resume: the saved session")?;
            tracing::info!(
                state = %path.display(),
                actions_done = state.driver.cycle.action_index,
                digs = state.records.digs.len(),
                "resuming the session after the arming handshake"
            );
            Some(state.records)
        }
        None => None,
    };
    let base = resumed.clone().unwrap_or_default();
    let scans_dir = out_dir.as_ref().map(|o| o.join("scans"));
    if let Some(d) = &scans_dir {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    tracing::info!(
        iface = %bus.interface(),
        strategy = args.strategy.name(),
        time_scale = %args.time_scale,
        listen_only = node.safety().config().listen_only,
        scan_addr = args.scan_addr.as_deref().unwrap_or("none"),
        "excavator-ctl running; Ctrl-C stops (valves neutral, disarm)"
    );
    let mut scans: Box<dyn ScanSource> = match &args.scan_addr {
        Some(addr) => Box::new(ScanService::spawn(ScanClient::new(scan_client_config(
            &node, addr,
        )))),
        None => Box::new(NoScans::default()),
    };
    let mut log = SessionRecords::new(scans_dir.clone().unwrap_or_default());
    if let Some(r) = resumed {
        log.records = r.digs;
        log.soil_samples = r.soil_samples;
        log.scans = r.scans;
    }
    let mut state_writer = match &out_dir {
        Some(o) => Some(StateWriter::spawn(crate::resume::state_path(o))?),
        None => None,
    };
    let session_log = match (&out_dir, console.session_log) {
        (Some(o), true) => {
            std::fs::create_dir_all(o).with_context(|| format!("creating {}", o.display()))?;
            let path = o.join(crate::session_log::FILE_NAME);
            Some(
                crate::session_log::open(&path, base.session_time_s, args.time_scale.get())
                    .with_context(|| format!("opening the session log {}", path.display()))?,
            )
        }
        _ => None,
    };
    if args.config_dir.is_some() {
        tracing::info!("configuration: {}", args.with_config_dir().config_files());
    }
    if let Some(link) = &console.link {
        tracing::info!(iface = %link.iface, "CAN link: {link}");
        for w in link.warnings() {
            tracing::warn!(iface = %link.iface, "CAN link: {w}");
        }
    }
    // The socket's and the keys' commands meet in this one port.
    let mut operator = controller::operator::OperatorPort::new();
    let socket_path = args
        .control_socket
        .clone()
        .or_else(|| out_dir.as_deref().map(controller::operator::default_path));
    let socket_task = match &socket_path {
        Some(p) => {
            let task = operator.listen(p).with_context(|| {
                format!(
                    "control socket {}: a Unix socket needs a local file system (not a network \
                     share) and a path under 108 bytes; give --control-socket PATH",
                    p.display()
                )
            })?;
            tracing::info!(socket = %p.display(), "operator control: excavator-ctl ctl --socket");
            Some(task)
        }
        None => None,
    };
    let keys = match console.keys {
        Some(tty) => match crate::keys::KeyReader::start(
            tty,
            operator.sender(),
            tokio::runtime::Handle::current(),
        ) {
            Ok(reader) => {
                tracing::info!("{}", crate::keys::help());
                Some(reader)
            }
            Err(e) => {
                tracing::warn!(error = %e, "operator keys: the terminal cannot be set up: no keys");
                None
            }
        },
        None => None,
    };
    live.operator_control(operator.sender());
    let mut steps = 0_u64;
    let progress = crate::console::session_bar(args.digs, false);
    let mut observer = |node: &ControllerNode, driver: &SessionDriver, events: &[SessionEvent]| {
        steps += 1;
        live.after_step(session_s(steps), node, driver.session(), events);
        if steps.is_multiple_of(PROGRESS_EVERY_STEPS) {
            crate::console::update(progress.as_ref(), log.records.len(), node, driver.backups());
        }
        for e in events {
            if scans_dir.is_none() && matches!(e, SessionEvent::Scanned(_)) {
                continue;
            }
            if log.on_event(node, driver, None, e)? {
                let d = log.records.last();
                tracing::info!(
                    dig = d.map(crate::session::DigRecord::number),
                    action = ?d.map(|d| d.action),
                    weight_n = ?d.and_then(|d| d.weight_n),
                    backups = driver.backups(),
                    "dig done"
                );
            }
        }
        if let (Some(w), Some(cp)) = (&mut state_writer, driver.checkpoint()) {
            let records = RunRecords {
                digs: log.records.clone(),
                soil_samples: log.soil_samples.clone(),
                scans: log.scans,
                session_time_s: base.session_time_s + session_s(steps),
                wall_time_s: base.wall_time_s + wall.elapsed().as_secs_f64(),
                max_digs: node.cycle().config().max_digs,
            };
            w.save(crate::resume::run_state(
                &setup.identity,
                cp.clone(),
                records,
            ));
        }
        Ok(())
    };
    if let Some(l) = &session_log {
        l.start_clock();
    }
    let result = run_session_loop(
        bus,
        &mut node,
        CONTROL_PERIOD,
        args.time_scale,
        shutdown,
        Some(LoopSession {
            driver: &mut driver,
            scans: &mut *scans,
            observer: &mut observer,
        }),
        Some(&mut operator),
    )
    .await;
    if let (Some(task), Some(p)) = (socket_task, &socket_path) {
        task.abort();
        let _ = std::fs::remove_file(p);
    }
    // The port first: a key's request still queued is then answered at once, and the reader ends.
    drop(operator);
    drop(keys);
    if let Some(p) = &progress {
        p.finish_and_clear();
    }
    let saved = state_writer.map(StateWriter::finish);
    let trace = match trace {
        Some(t) => {
            let mut closed = t.recorder.close().context("closing the trace")?;
            tracing::info!(?closed, "trace closed");
            closed.recorded += t.frames_before;
            closed
        }
        None => firmware_bridge::trace::RecorderStats::default(),
    };
    live.finished(
        session_s(steps),
        match &result {
            Ok((StopReason::Signal, _)) => "stopped",
            Ok((StopReason::Finished, _)) => "finished",
            Err(_) => "error",
        },
    );
    let (reason, stats) = result?;
    tracing::info!(
        ?reason,
        ?stats,
        ?saved,
        digs = node.statistics().len(),
        "stopped"
    );
    let Some(out) = &out_dir else {
        return Ok(());
    };
    let end = match (reason, driver.end_reason()) {
        (StopReason::Signal, _) => "stopped".to_owned(),
        (StopReason::Finished, _) if node.cycle().stop_requested() => "operator stop".to_owned(),
        (StopReason::Finished, Some(why)) => why.to_owned(),
        (StopReason::Finished, None) => "dig count reached".to_owned(),
    };
    let mut summary = demo::session_summary(
        log.records,
        SessionEnd {
            strategy: args.strategy,
            bench: setup.bench,
            seed: setup.seed,
            soil_contact: setup.soil_contact,
            effects: Vec::new(),
            full_bucket_n: setup.full_bucket_n,
            end,
            track_backs: driver.track_backs(),
            backups: driver.backups(),
            plan_ms: driver.planning_ms(),
            scans: log.scans,
            session_time_s: base.session_time_s + session_s(stats.steps),
            wall_time_s: base.wall_time_s + wall.elapsed().as_secs_f64(),
            trace,
            trace_clock: bus.trace_clock(),
        },
        &node,
        driver.session(),
    );
    summary.can_link = console.link;
    write_folder(out, &summary, &node, &driver, log.soil_samples)?;
    print!("{}", demo::summary_markdown(&summary));
    match saved {
        Some(s) if s.failed > 0 => Err(anyhow::anyhow!(
            "the session state could not be saved {} times (last: {}): the session cannot be \
             resumed from its last actions",
            s.failed,
            s.last_error.unwrap_or_default()
        )),
        _ => Ok(()),
    }
}

/// Control steps between updates of the progress line (0.5 s of session time).
const PROGRESS_EVERY_STEPS: u64 = 50;

/// Session time of `steps` control steps, s.
fn session_s(steps: u64) -> f64 {
    CONTROL_PERIOD.as_secs_f64() * steps as f64
}

/// The session folder's files besides the trace and the scans.
fn write_folder(
    out: &Path,
    summary: &demo::DemoSummary,
    node: &ControllerNode,
    driver: &SessionDriver,
    soil: crate::session::SoilSamplesFile,
) -> anyhow::Result<()> {
    let plan = node.cycle().config().actions.clone();
    let mut snapshots = Vec::new();
    if let Some(s) = driver.session() {
        // The planner's map stands for the terrain: a bus session has no simulator truth.
        let pose = node.estimator().state().pose;
        let pose = [pose.x_m, pose.y_m, pose.heading_rad];
        demo::write_planner_outputs(out, s, pose)?;
        snapshots.push(demo::BenchSnapshot {
            digs: summary.digs.len(),
            backups: summary.backups,
            terrain: s.terrain().clone(),
            pose,
        });
    }
    demo::write_outputs(out, summary, None, &plan, &snapshots)?;
    demo::write_soil_samples(out, &soil)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(clap::Parser)]
    struct Cmd {
        #[command(flatten)]
        run: RunArgs,
    }

    fn args(extra: &[&str]) -> RunArgs {
        let mut all = vec!["run", "--iface", "can0"];
        all.extend_from_slice(extra);
        Cmd::try_parse_from(all).unwrap().run
    }

    #[test]
    fn config_dir_fills_what_no_option_names() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("machine.toml"), "").unwrap();
        std::fs::write(dir.path().join("planner.toml"), "").unwrap();
        let d = dir.path().to_str().unwrap();
        let a = args(&["--config-dir", d, "--planner", "mine.toml"]).with_config_dir();
        assert_eq!(a.machine, Some(dir.path().join("machine.toml")));
        assert_eq!(a.planner, Some("mine.toml".into()), "an option wins");
        assert_eq!(
            (a.maps, a.config, a.key_file),
            (None, None, None),
            "built-in"
        );
        let line = args(&["--config-dir", d]).with_config_dir().config_files();
        assert!(line.contains("machine.toml, maps built-in"), "{line}");
        assert_eq!(args(&[]).with_config_dir().machine, None);
    }

    /// `profile.toml` in the folder is the machine profile when no `--profile` names one: the
    /// controller's stale-data limits follow that gateway's periods; `--profile` wins.
    #[test]
    fn config_dir_supplies_the_machine_profile() {
        let dir = tempfile::tempdir().unwrap();
        let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
        std::fs::copy(
            examples.join("other_gateway.toml"),
            dir.path().join("profile.toml"),
        )
        .unwrap();
        std::fs::copy(
            examples.join("other_gateway.dbc"),
            dir.path().join("other_gateway.dbc"),
        )
        .unwrap();
        let d = dir.path().to_str().unwrap();
        let a = args(&["--config-dir", d]).with_config_dir();
        assert_eq!(a.profile, Some(dir.path().join("profile.toml")));
        assert!(
            a.config_files().ends_with("profile.toml"),
            "{}",
            a.config_files()
        );
        let (node, _, _) = build(&a).unwrap();
        let safety = node.safety().config();
        assert_eq!(safety.gateway.sensor_period_ms, 20);
        // Three of the gateway's 20 ms periods, as the default is three of 10 ms.
        assert!((safety.sensor_max_age_s - 0.06).abs() < 1e-12, "{safety:?}");
        let a = args(&["--config-dir", d, "--profile", "mine.toml"]).with_config_dir();
        assert_eq!(a.profile, Some("mine.toml".into()), "an option wins");
        let (node, _, _) = build(&args(&[])).unwrap();
        assert_eq!(
            *node.safety().config(),
            controller::safety::SafetyConfig::default(),
            "without a profile, the project's gateway"
        );
    }

    #[test]
    fn config_dir_files_are_read_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("machine.toml"), "not = [toml").unwrap();
        let d = dir.path().to_str().unwrap();
        let err = format!("{:#}", machine(&args(&["--config-dir", d])).unwrap_err());
        assert!(err.contains("machine"), "{err}");
    }
}
