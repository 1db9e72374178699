//! `excavator-ctl run`: the controller on a CAN bus in real time (or `--time-scale` times faster,
//! with the simulator at the same scale), with the action source of `--strategy`:
//!
//! - `planned` / `predefined`: the session driver that `demo` runs ([`SessionDriver`]: the dig
//!   planner or the predefined sequence, Autodig, cleanup, tracking back, the hardness index and the
//!   soil estimate online), with range scans from the scan service (`--scan-addr`;
//!   docs/scan-protocol.md) on the site's work area, floor and start pose (`--site`, default
//!   config/site.toml, the site of `demo`'s bench); the planner runs off the control loop
//!   ([`controller::io::run::run_session_loop`]);
//! - `fixed` (default): the controller config's action list.
//!
//! The machine is the machine file's (`--machine`), the place the site file's: nothing comes from a
//! simulator. With `--out DIR` the session folder is the one `demo` writes (trace, scans,
//! `summary.json`, `summary.md`, plots, `soil_samples.json`; docs/demo-output.md), without the
//! simulator's truth (true payload, true terrain), which a bus session does not have, plus
//! `session_state.json`: the session saved after every completed action ([`crate::resume`]).
//! `--resume DIR` loads it, checks that it is this machine's, site's and configuration's, and goes
//! on with the session where it stood after the normal arming handshake, appending to its trace and
//! records. The run's log goes to the folder's `run.log` too ([`crate::session_log`]).
//!
//! Before it opens the bus, `run` reads the interface's link over netlink ([`check_link`]): it logs
//! the bitrate, state, `restart-ms` and listen-only mode, records them in the summary, and refuses a
//! down link or a listen-only one without `--listen-only`. `--config-dir DIR` (the package's
//! /etc/excavator) supplies the configuration files no option names ([`CONFIG_DIR_FILES`]).
//!
//! The operator's commands come from the control socket (`excavator-ctl ctl`) and, when standard
//! input is a terminal, from its keys ([`crate::keys`]); both through one [`OperatorPort`].

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use controller::ControllerConfig;
use controller::config::{KeyUse, SecurityConfig};
#[cfg(doc)]
use controller::io::operator::OperatorPort;
use controller::io::run::{LoopSession, StopReason, run_session_loop, scan_client_config};
use controller::io::scan_client::{NoScans, ScanClient, ScanService};
use controller::session::driver::{
    NoObserver, ScanSource, SessionDriver, SessionEvent, SessionObserver,
};
use controller::session::session_state::{SessionIdentity, fingerprint};
use controller::session::state_file::StateFileError;
use controller::step::node::ControllerNode;
use firmware_bridge::dbc::CONTROL_PERIOD;
use firmware_bridge::profile::Profile;
use firmware_bridge::trace::Recorder;
use firmware_bridge::transport::{Bus, LinkStatus, ProfileBus, SocketCanBus, TimeScale};
use planner::autodig::AutodigMaps;
use planner::machine::MachineConfig;
use planner::plan::PlannerConfig;
use planner::site::Site;

use crate::record::{BenchSnapshot, SessionRecords, SoilSamplesFile};
use crate::resume::{RunRecords, RunState, StateWriter};
use crate::setup;
use crate::summary::{self, DemoStrategy, DemoSummary, FileRecord, SessionEnd, SessionPlots};

/// Arguments of `excavator-ctl run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// CAN interface, e.g. can0 (the machine) or vcan0 (excavator-sim); with `--resume`, the
    /// session's.
    #[arg(long, required_unless_present = "resume")]
    pub iface: Option<String>,
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
    /// `[security] key_file`. Without a key `run` refuses to arm (docs/deployment.md, "The
    /// machine's key"), unless it only listens or `--insecure-no-key` is given.
    #[arg(long, value_name = "FILE")]
    pub key_file: Option<PathBuf>,
    /// Arm without a key: the control frames are sealed with the public all-zero key, which anyone
    /// on the bus can forge (docs/protocol.md, "Threat model"). Bench tests only; logged as an error.
    /// Same as the config's `security.insecure_no_key = true`.
    #[arg(long)]
    pub insecure_no_key: bool,
    /// Record a candump -L log of every frame sent and received (default with --out: DIR/trace.log).
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// Stop after this many digs (then swing home, neutral, disarm).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub digs: Option<u32>,
    /// Range-scan service address (host:port): the planner's map and the perception enhancements.
    #[arg(long, value_name = "ADDR")]
    pub scan_addr: Option<String>,
    /// The action source: the dig planner, the predefined sequence of 6.2, or the config's plan
    /// (default: fixed, the config's plan).
    #[arg(long, value_enum)]
    pub strategy: Option<DemoStrategy>,
    /// Site file: the work area, the target floor, the machine's start pose and the material of the
    /// planned and predefined strategies (default: the built-in config/site.toml, the site of
    /// `demo`'s extended bench; `excavator-ctl site --bench FILE` writes a bench's).
    #[arg(long, value_name = "FILE")]
    pub site: Option<PathBuf>,
    /// The simulated machine's seed (`excavator-sim --seed`), recorded in summary.json when the
    /// machine is a simulator (default 0: none).
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
    #[arg(long, value_name = "X")]
    pub time_scale: Option<TimeScale>,
    /// Session folder: trace, scans, summary and plots as `demo` writes them.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Replace the session in `--out` (a folder holding another session is refused without it; a
    /// folder holding no session is never deleted).
    #[arg(long)]
    pub force: bool,
    /// Go on with the session saved in this session folder (its `session_state.json`), with the
    /// files and settings it was started with (`run_options.json`); an option given again must
    /// name the same value, but for --digs, --listen-only, --key-file and --control-socket.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// The operator's control socket (`excavator-ctl ctl`; default: `control.sock` in the session
    /// folder, none without one).
    #[arg(long, value_name = "PATH")]
    pub control_socket: Option<PathBuf>,
    /// A group whose members may use the control socket besides its owner and root (by name or
    /// number; the socket file then belongs to it, mode 660). The controller must be a member.
    #[arg(long, value_name = "GROUP")]
    pub control_socket_group: Option<String>,
    /// The deployed configuration's folder (the package's /etc/excavator): machine.toml,
    /// autodig_maps.toml, controller.toml, site.toml, planner.toml, hardness_regression.toml, key
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
    "site.toml",
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
    pub command: controller::io::operator::Command,
    /// Why (written to the controller's log).
    #[arg(long)]
    pub reason: Option<String>,
}

/// `excavator-ctl ctl`: sends one operator command and prints the controller's state after it.
///
/// # Errors
/// The socket cannot be reached, or the controller refused the request.
pub async fn ctl(args: CtlArgs) -> anyhow::Result<()> {
    let reply = controller::io::operator::request(
        &args.socket,
        &controller::io::operator::Request {
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
            iface: Some(iface.to_owned()),
            listen_only: false,
            machine: None,
            maps: None,
            config: None,
            key_file: None,
            insecure_no_key: false,
            trace: None,
            digs: None,
            scan_addr: None,
            strategy: None,
            site: None,
            seed: None,
            planner: None,
            hardness: None,
            time_scale: None,
            out: None,
            force: false,
            resume: None,
            control_socket: None,
            control_socket_group: None,
            config_dir: None,
            profile: None,
        }
    }

    /// `--strategy`, or the default: the fixed plan.
    #[must_use]
    pub fn strategy(&self) -> DemoStrategy {
        self.strategy.unwrap_or(DemoStrategy::Fixed)
    }

    /// `--time-scale`, or real time.
    #[must_use]
    pub fn time_scale(&self) -> TimeScale {
        self.time_scale.unwrap_or(TimeScale::REAL_TIME)
    }

    /// `--iface`.
    ///
    /// # Errors
    /// None given (and none saved with a resumed session).
    pub fn iface(&self) -> anyhow::Result<&str> {
        self.iface
            .as_deref()
            .context("--iface is required (a resumed session takes the one it was started with)")
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
        let [machine, maps, config, site, planner, hardness, key, profile] =
            CONFIG_DIR_FILES.map(|name| Some(dir.join(name)).filter(|p| p.is_file()));
        for (given, found) in [
            (&mut a.machine, machine),
            (&mut a.maps, maps),
            (&mut a.config, config),
            (&mut a.site, site),
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
            "machine {}, maps {}, controller {}, site {}, planner {}, hardness {}, key {}, \
             profile {}",
            show(&self.machine),
            show(&self.maps),
            show(&self.config),
            show(&self.site),
            show(&self.planner),
            show(&self.hardness),
            self.key_file
                .as_ref()
                .map_or_else(|| "none".to_owned(), |p| p.display().to_string()),
            show(&self.profile),
        )
    }
}

/// Builds the node and the driver of a run (see the module docs for the strategies).
///
/// # Errors
/// Unreadable or invalid files, an inconsistent configuration, a planned strategy without a scan
/// service.
pub fn build(args: &RunArgs) -> anyhow::Result<(ControllerNode, SessionDriver, RunSetup)> {
    let args = &args.with_config_dir();
    let machine = setup::machine(args.machine.as_deref())?;
    let site = setup::site(args.site.as_deref())?;
    let maps = setup::maps(args.maps.as_deref())?;
    let mut config =
        setup::controller_config(args.strategy(), args.config.as_deref(), &site, false)?;
    let planner = setup::planner_config(args.planner.as_deref(), &site)?;
    let session = match args.strategy().session() {
        Some(st) => {
            anyhow::ensure!(
                args.scan_addr.is_some(),
                "--strategy {} plans on range scans: give the scan service's --scan-addr",
                args.strategy().name()
            );
            Some(setup::planned_session(
                &machine,
                planner,
                &site,
                st,
                args.hardness.as_deref(),
            )?)
        }
        None => None,
    };
    config.cycle.max_digs = match (args.digs, args.strategy()) {
        (Some(n), _) => Some(n),
        // The config's own limit (a repeating plan may stop only there).
        (None, DemoStrategy::Fixed) => config.cycle.max_digs,
        // The session driver ends the session when its region is done.
        (None, _) => None,
    };
    config.safety.listen_only |= args.listen_only;
    // A profile's gateway: the stale-data limits in its periods, checked against its watchdogs.
    if let Some(p) = setup::load_profile(args.profile.as_deref())? {
        config.safety = config.safety.for_gateway(p.timing());
    }
    // Without a scan service nobody would answer the cycle's requests: dig on the plain angle rules
    // at once instead of waiting `scan_timeout_s` before every dig.
    if args.scan_addr.is_none() {
        config.cycle.scan = false;
    }
    let full_bucket_n = site.full_bucket_n(machine.bucket.capacity_m3);
    if let Some(file) = &args.key_file {
        config.security.key_file = Some(file.clone());
    }
    config.security.insecure_no_key |= args.insecure_no_key;
    let key = SecurityConfig::key_for_motion(
        config.security.load_key().context("the machine's key")?,
        config.security.insecure_no_key,
        config.safety.listen_only,
    )?;
    let seed = args.seed.unwrap_or(0);
    let identity = session_identity(
        &machine,
        &site,
        seed,
        args.strategy(),
        &config,
        &planner,
        &maps,
    );
    let mut node =
        ControllerNode::new(&machine, maps, config).context("controller configuration")?;
    match &key {
        KeyUse::Provisioned(key) => {
            node.set_key(key);
            tracing::info!("control frames authenticated with the provisioned key");
        }
        KeyUse::ListenOnly => tracing::info!("no key provisioned: listen-only, nothing is sent"),
        KeyUse::Insecure => tracing::error!(
            "INSECURE: --insecure-no-key (security.insecure_no_key): no key provisioned, the control \
             frames are sealed with the public all-zero key and anyone who can send on the bus can \
             forge them and move the machine (docs/protocol.md). Bench tests only."
        ),
    }
    let mut driver = SessionDriver::new(session, None, &mut node);
    driver.set_detached_planning(true);
    let setup = RunSetup {
        site: site.name.clone(),
        seed,
        full_bucket_n,
        identity,
    };
    Ok((node, driver, setup))
}

/// The machine a run of `args` controls: the machine file's (or the built-in one).
///
/// # Errors
/// An unreadable or invalid machine file.
pub fn machine(args: &RunArgs) -> anyhow::Result<MachineConfig> {
    setup::machine(args.with_config_dir().machine.as_deref())
}

/// What a saved session of `strategy` on `machine` at `site` with `config`, `planner` and `maps`
/// belongs to ([`SessionIdentity`]): a state is resumed only by a run with the same.
#[must_use]
pub fn session_identity(
    machine: &MachineConfig,
    site: &Site,
    seed: u64,
    strategy: DemoStrategy,
    config: &ControllerConfig,
    planner: &PlannerConfig,
    maps: &AutodigMaps,
) -> SessionIdentity {
    SessionIdentity {
        machine: fingerprint(machine),
        bench: site.name.clone(),
        seed,
        strategy: strategy.name().to_owned(),
        config: {
            // The dig count, listen-only and the key file may change between a session and its resumption.
            let mut c = config.clone();
            c.cycle.max_digs = None;
            c.safety.listen_only = false;
            // The key is the machine's, not the session's: it may be re-provisioned.
            c.security.key_file = None;
            c.security.insecure_no_key = false;
            fingerprint(&(c, planner, maps))
        },
    }
}

/// What a run's summary takes from its setup.
#[derive(Debug, Clone)]
pub struct RunSetup {
    site: String,
    seed: u64,
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
pub async fn run(args: RunArgs, plots: Option<Arc<dyn SessionPlots>>) -> anyhow::Result<()> {
    run_observed(args, &mut NoObserver, plots).await
}

/// As [`run`], with `observer` watching every control step (the live view) and offered the
/// operator control path.
///
/// # Errors
/// As [`run`].
pub async fn run_observed(
    args: RunArgs,
    observer: &mut dyn SessionObserver,
    plots: Option<Arc<dyn SessionPlots>>,
) -> anyhow::Result<()> {
    let args = crate::options::resumed(args)?;
    if args.resume.is_none()
        && let Some(o) = &args.out
    {
        crate::folder::prepare(o, args.force)?;
    }
    let iface = args.iface()?;
    // A bad profile stops the run before it touches the bus. Without one the bus speaks the default
    // profile, the identity: every frame passes unchanged.
    let profile = match setup::load_profile(args.with_config_dir().profile.as_deref())? {
        Some(p) => p,
        None => std::sync::Arc::new(Profile::default_profile()?),
    };
    let link = check_link(&args)?;
    let mut bus =
        SocketCanBus::open(iface).with_context(|| format!("opening CAN interface {iface}"))?;
    let trace = match trace_path(&args)? {
        Some(p) => {
            let (recorder, frames_before) =
                crate::resume::open_trace(&p, iface, args.resume.is_some())?;
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
        plots,
    };
    let bus = ProfileBus::new(bus, profile);
    let result = run_on_observed(
        &bus,
        trace,
        &args,
        console,
        controller::io::run::shutdown_signal(),
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
    let link = LinkStatus::query(args.iface()?)?;
    link.check(args.listen_only)?;
    Ok(link)
}

/// Who may use the control socket besides its owner and root: `--control-socket-group`, a group
/// name or a numeric gid.
///
/// # Errors
/// A group that does not exist, naming the option.
pub fn socket_access(
    group: Option<&str>,
) -> anyhow::Result<controller::io::operator::SocketAccess> {
    let Some(group) = group else {
        return Ok(controller::io::operator::SocketAccess::default());
    };
    let by_name = nix::unistd::Group::from_name(group)
        .with_context(|| format!("--control-socket-group {group}: reading the group database"))?;
    let gid = match by_name {
        Some(g) => g.gid.as_raw(),
        None => match group.parse::<u32>() {
            Ok(gid)
                if nix::unistd::Group::from_gid(nix::unistd::Gid::from_raw(gid))
                    .is_ok_and(|g| g.is_some()) =>
            {
                gid
            }
            _ => anyhow::bail!("--control-socket-group {group}: no such group"),
        },
    };
    Ok(controller::io::operator::SocketAccess {
        group_gid: Some(gid),
    })
}

/// `safety.auto_rearm` (motion resumes after a transient fault without the operator) is a policy of
/// simulation: refused on a link with a real CAN controller.
///
/// # Errors
/// One line naming the key and the interface.
pub fn refuse_simulation_policy(
    safety: &controller::SafetyConfig,
    link: &LinkStatus,
) -> anyhow::Result<()> {
    if safety.auto_rearm && !link.is_virtual() {
        anyhow::bail!(
            "safety.auto_rearm = true is for simulation only (a vcan or the in-process bus): {} is a \
             CAN controller ({link}); after a fault that stopped motion the machine waits for the \
             operator's resume or reset. Remove the key from the controller config",
            link.iface
        );
    }
    Ok(())
}

/// What `run` does besides the session: the operator's keys, the session log and the link.
#[derive(Default)]
pub struct RunConsole {
    /// The terminal whose keys are operator commands ([`crate::keys`]); `None`: no key reader.
    pub keys: Option<std::fs::File>,
    /// Write the log to the session folder's `run.log` too ([`crate::session_log`]; the binary's
    /// subscriber carries its layer).
    pub session_log: bool,
    /// The interface's link as [`check_link`] found it: logged, and recorded in the summary.
    pub link: Option<LinkStatus>,
    /// Who draws the session folder's plots (the binary's lab layer); none: data files only.
    pub plots: Option<Arc<dyn SessionPlots>>,
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
    let args = &crate::options::resumed(args.clone())?;
    let (mut node, mut driver, setup) = build(args)?;
    if let Some(link) = &console.link {
        refuse_simulation_policy(node.safety().config(), link)?;
    }
    let out_dir = args.session_dir()?;
    let resumed = match &args.resume {
        Some(dir) => {
            let path = crate::resume::state_path(dir);
            let state: RunState = controller::session::session_state::load(&path, &setup.identity)
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
            // A finished session stays finished: nothing is armed or sent.
            if let Some(end) = finished_session(
                dir,
                state.records.digs.len(),
                node.cycle().config().max_digs,
            )? {
                tracing::info!(folder = %dir.display(), end, "the session is finished: nothing to resume");
                println!(
                    "excavator-ctl run: the session in {} is finished ({end}, {} digs): nothing to \
                     resume",
                    dir.display(),
                    state.records.digs.len()
                );
                return Ok(());
            }
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
        strategy = args.strategy().name(),
        time_scale = %args.time_scale(),
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
        Some(o) => {
            if args.resume.is_none() {
                std::fs::create_dir_all(o).with_context(|| format!("creating {}", o.display()))?;
                crate::options::SavedOptions::of(args, bus.interface()).save(o)?;
            }
            Some(StateWriter::spawn(crate::resume::state_path(o))?)
        }
        None => None,
    };
    let session_log = match (&out_dir, console.session_log) {
        (Some(o), true) => {
            std::fs::create_dir_all(o).with_context(|| format!("creating {}", o.display()))?;
            let path = o.join(crate::session_log::FILE_NAME);
            Some(
                crate::session_log::open(&path, base.session_time_s, args.time_scale().get())
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
    let mut operator = controller::io::operator::OperatorPort::new();
    let socket_path = args.control_socket.clone().or_else(|| {
        out_dir
            .as_deref()
            .map(controller::io::operator::default_path)
    });
    let access = socket_access(args.control_socket_group.as_deref())?;
    let socket_task = match &socket_path {
        Some(p) => {
            let task = operator.listen_with(p, access).with_context(|| {
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
    let mut bus_watch = BusWatch::new(bus.interface().to_owned());
    let mut observer = |node: &ControllerNode, driver: &SessionDriver, events: &[SessionEvent]| {
        steps += 1;
        bus_watch.check(session_s(steps), node);
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
                    dig = d.map(crate::record::DigRecord::number),
                    action = ?d.map(|d| d.action),
                    weight_n = %d
                        .and_then(|d| d.weight_n)
                        .map_or_else(|| "none".to_owned(), |w| format!("{w:.0}")),
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
        args.time_scale(),
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
        Some(t) => match t.recorder.close() {
            Ok(mut closed) => {
                tracing::info!(?closed, "trace closed");
                closed.recorded += t.frames_before;
                Ok(closed)
            }
            Err(e) => Err(anyhow::Error::new(e).context("closing the trace")),
        },
        None => Ok(firmware_bridge::trace::RecorderStats::default()),
    };
    live.finished(
        session_s(steps),
        match &result {
            Ok((StopReason::Signal, _)) => "stopped",
            Ok((StopReason::Finished, _)) => "finished",
            Err(_) => "error",
        },
    );
    // Whatever ended the session, its folder gets a summary that says so.
    let error = match (&result, &trace) {
        (Err(e), _) => Some(format!("{e:#}")),
        (_, Err(e)) => Some(format!("{e:#}")),
        _ => None,
    };
    let steps_run = match &result {
        Ok((reason, stats)) => {
            tracing::info!(
                ?reason,
                ?stats,
                ?saved,
                digs = node.statistics().len(),
                "stopped"
            );
            stats.steps
        }
        Err(_) => steps,
    };
    if let Some(out) = &out_dir {
        let end = match (&result, driver.end_reason()) {
            (Err(_), _) => "error".to_owned(),
            (Ok((StopReason::Signal, _)), _) => "stopped".to_owned(),
            (Ok((StopReason::Finished, _)), _) if node.cycle().stop_requested() => {
                "operator stop".to_owned()
            }
            (Ok((StopReason::Finished, _)), Some(why)) => why.to_owned(),
            (Ok((StopReason::Finished, _)), None) => "dig count reached".to_owned(),
        };
        let mut summary = summary::session_summary(
            log.records,
            SessionEnd {
                command: "run",
                strategy: args.strategy(),
                bench: setup.site,
                seed: setup.seed,
                soil_contact: None,
                effects: Vec::new(),
                full_bucket_n: setup.full_bucket_n,
                end,
                track_backs: driver.track_backs(),
                backups: driver.backups(),
                plan_ms: driver.planning_ms(),
                scans: log.scans,
                session_time_s: base.session_time_s + session_s(steps_run),
                wall_time_s: base.wall_time_s + wall.elapsed().as_secs_f64(),
                trace: trace.as_ref().copied().unwrap_or_default(),
                trace_clock: bus.trace_clock(),
            },
            &node,
            driver.session(),
        );
        summary.can_link = console.link;
        summary.error.clone_from(&error);
        summary.profile = args
            .with_config_dir()
            .profile
            .as_deref()
            .map(FileRecord::of)
            .transpose()?;
        write_folder(
            out,
            &summary,
            &node,
            &driver,
            &log.soil_samples,
            console.plots.as_deref(),
        )?;
        print!("{}", summary::summary_markdown(&summary));
        eprintln!(
            "excavator-ctl run: the session's files are in {}{}",
            out.display(),
            if summary.end == "stopped" || summary.end == "error" {
                format!(
                    " (go on with: excavator-ctl run --resume {})",
                    out.display()
                )
            } else {
                String::new()
            }
        );
    }
    result?;
    trace?;
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

/// Why the session in the folder `dir` ended, if it ended for good: its `summary.json` says it ended
/// (not stopped by a signal, not by an error) and, when it ended on its dig count, `digs` (done)
/// reach `max_digs` (a resumption may give more). `None`: there is something to resume.
///
/// # Errors
/// A `summary.json` that cannot be read or parsed.
pub fn finished_session(
    dir: &Path,
    digs: usize,
    max_digs: Option<u32>,
) -> anyhow::Result<Option<String>> {
    #[derive(serde::Deserialize)]
    struct Ended {
        #[serde(default)]
        end: String,
    }
    let path = dir.join("summary.json");
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let ended: Ended =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    Ok(match ended.end.as_str() {
        "" | "stopped" | "error" => None,
        "dig count reached" if max_digs.is_none_or(|m| digs < m as usize) => None,
        _ => Some(ended.end),
    })
}

/// Session seconds without a frame from the gateway before `run` says it is waiting for one.
pub const NO_GATEWAY_WARNING_S: f64 = 3.0;
/// Session seconds between two repeats of a bus warning.
const BUS_WARNING_REPEAT_S: f64 = 10.0;
/// Frames the gateway reports rejected, while the controller is not armed, before `run` says the
/// keys probably differ (a handshake sends about one secured frame per control period).
pub const REJECTED_FRAMES_WARNING: u16 = 20;

/// What `run` tells the person at the console about the bus when nothing else would: no gateway on
/// it, or a gateway that rejects the controller's frames (the keys differ).
#[derive(Debug)]
struct BusWatch {
    iface: String,
    last_no_gateway_s: Option<f64>,
    last_rejected_s: Option<f64>,
    first_rejected: Option<u16>,
}

impl BusWatch {
    fn new(iface: String) -> Self {
        Self {
            iface,
            last_no_gateway_s: None,
            last_rejected_s: None,
            first_rejected: None,
        }
    }

    /// Warns (at most every [`BUS_WARNING_REPEAT_S`]) at session time `now_s`.
    fn check(&mut self, now_s: f64, node: &ControllerNode) {
        let due = |last: Option<f64>| last.is_none_or(|t| now_s - t >= BUS_WARNING_REPEAT_S);
        let gateway = node.estimator().state().gateway;
        if gateway.is_none() && now_s >= NO_GATEWAY_WARNING_S && due(self.last_no_gateway_s) {
            self.last_no_gateway_s = Some(now_s);
            tracing::warn!(
                iface = %self.iface,
                "waiting for the gateway: no status from it (address 0x80) in {now_s:.0} s; is \
                 excavator-sim running on {} (or the machine's gateway powered and on this bus, at \
                 its bitrate)?",
                self.iface
            );
        }
        let Some(status) = gateway else {
            return;
        };
        let armed = matches!(
            node.safety().state(),
            controller::step::safety::SafetyState::Armed { .. }
        );
        if armed {
            self.first_rejected = None;
            return;
        }
        let first = *self.first_rejected.get_or_insert(status.rejected_frames);
        let rejected = status.rejected_frames.saturating_sub(first);
        if rejected >= REJECTED_FRAMES_WARNING && due(self.last_rejected_s) {
            self.last_rejected_s = Some(now_s);
            tracing::warn!(
                iface = %self.iface,
                rejected,
                "the gateway rejects this controller's frames ({rejected} since it was last seen \
                 armed) and does not arm: the keys probably differ (--key-file here and the \
                 gateway's key; docs/protocol.md, \"Key provisioning\")"
            );
        }
    }
}

/// Control steps between updates of the progress line (0.5 s of session time).
const PROGRESS_EVERY_STEPS: u64 = 50;

/// Session time of `steps` control steps, s.
fn session_s(steps: u64) -> f64 {
    CONTROL_PERIOD.as_secs_f64() * steps as f64
}

/// The session folder's files besides the trace and the scans: the data files here, the pictures
/// through `plots` when the caller draws them.
fn write_folder(
    out: &Path,
    summary: &DemoSummary,
    node: &ControllerNode,
    driver: &SessionDriver,
    soil: &SoilSamplesFile,
    plots: Option<&dyn SessionPlots>,
) -> anyhow::Result<()> {
    let plan = node.cycle().config().actions.clone();
    summary::write_files(out, summary, &plan)?;
    summary::write_soil_samples(out, soil)?;
    let mut snapshots = Vec::new();
    if let Some(s) = driver.session() {
        summary::write_last_plan(out, s)?;
        // The planner's map stands for the terrain: a bus session has no simulator truth.
        let pose = node.estimator().state().pose;
        snapshots.push(BenchSnapshot {
            digs: summary.digs.len(),
            backups: summary.backups,
            terrain: s.terrain().clone(),
            pose: [pose.x_m, pose.y_m, pose.heading_rad],
        });
    }
    match plots {
        Some(p) => p.write(out, summary, driver.session(), &snapshots),
        None => Ok(()),
    }
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

    /// `--control-socket-group` by name or number resolves to the group's gid; an unknown one is
    /// refused naming the option; without it only the owner and root may connect.
    #[test]
    fn the_control_socket_group_resolves_by_name_or_number() {
        let a = args(&["--control-socket-group", "root"]);
        assert_eq!(a.control_socket_group.as_deref(), Some("root"));
        let root = socket_access(a.control_socket_group.as_deref()).unwrap();
        assert_eq!(root.group_gid, Some(0));
        assert_eq!(socket_access(Some("0")).unwrap().group_gid, Some(0));
        let e = socket_access(Some("no-such-group-46"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--control-socket-group no-such-group-46"), "{e}");
        assert!(e.contains("no such group"), "{e}");
        assert!(socket_access(Some("4294967294")).is_err());
        assert_eq!(socket_access(None).unwrap().group_gid, None);
    }

    /// The simulation policy `safety.auto_rearm` is refused on a real CAN controller (bit timing and
    /// a controller state), allowed on a vcan; without it any link is fine.
    #[test]
    fn auto_rearm_is_refused_on_a_real_can_controller() {
        use firmware_bridge::transport::ControllerState;
        let vcan = LinkStatus {
            iface: "vcan0".into(),
            up: true,
            bitrate_bps: None,
            state: None,
            restart_ms: None,
            listen_only: false,
        };
        let can = LinkStatus {
            iface: "can0".into(),
            bitrate_bps: Some(500_000),
            state: Some(ControllerState::ErrorActive),
            restart_ms: Some(100),
            ..vcan.clone()
        };
        // A real controller before its bitrate is set still reports a state.
        let unset = LinkStatus {
            bitrate_bps: None,
            ..can.clone()
        };
        let sim = controller::SafetyConfig {
            auto_rearm: true,
            ..controller::SafetyConfig::default()
        };
        assert!(refuse_simulation_policy(&sim, &vcan).is_ok());
        for link in [&can, &unset] {
            let e = refuse_simulation_policy(&sim, link)
                .unwrap_err()
                .to_string();
            assert!(e.contains("safety.auto_rearm") && e.contains("can0"), "{e}");
            assert!(refuse_simulation_policy(&controller::SafetyConfig::default(), link).is_ok());
        }
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
        let a = args(&["--config-dir", d, "--insecure-no-key"]).with_config_dir();
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
        let (node, _, _) = build(&args(&["--insecure-no-key"])).unwrap();
        assert_eq!(
            *node.safety().config(),
            controller::step::safety::SafetyConfig::default(),
            "without a profile, the project's gateway"
        );
    }

    /// A folder whose summary says the session ended is finished, unless it was stopped, failed,
    /// or ended on a dig count that the resumption raises.
    #[test]
    fn a_finished_session_is_not_resumed() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            finished_session(dir.path(), 3, Some(3)).unwrap(),
            None,
            "no summary"
        );
        let write = |end: &str| {
            std::fs::write(
                dir.path().join("summary.json"),
                format!(r#"{{"end": "{end}", "seed": 1}}"#),
            )
            .unwrap();
        };
        for end in ["stopped", "error"] {
            write(end);
            assert_eq!(
                finished_session(dir.path(), 3, Some(3)).unwrap(),
                None,
                "{end}"
            );
        }
        write("dig count reached");
        assert_eq!(
            finished_session(dir.path(), 3, Some(3)).unwrap().as_deref(),
            Some("dig count reached")
        );
        assert_eq!(
            finished_session(dir.path(), 3, Some(5)).unwrap(),
            None,
            "more digs"
        );
        write("bench removed: no material within reach");
        assert!(finished_session(dir.path(), 3, None).unwrap().is_some());
        std::fs::write(dir.path().join("summary.json"), "{").unwrap();
        let e = format!("{:#}", finished_session(dir.path(), 3, None).unwrap_err());
        assert!(e.contains("summary.json"), "{e}");
    }

    /// Without a key `run` used to arm with the public all-zero key after a warning: now it refuses,
    /// unless it only listens or the insecure mode is asked for (flag or config key).
    #[test]
    fn run_without_a_key_refuses_to_arm() {
        let Err(e) = build(&args(&[])) else {
            panic!("a run without a key was built to arm")
        };
        let e = format!("{e:#}");
        assert!(e.contains("no key provisioned: refusing to arm"), "{e}");
        assert!(e.contains("docs/deployment.md"), "{e}");
        assert!(
            build(&args(&["--listen-only"])).is_ok(),
            "listen-only sends nothing"
        );
        assert!(build(&args(&["--insecure-no-key"])).is_ok());
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("controller.toml");
        std::fs::write(&config, "[security]\ninsecure_no_key = true\n").unwrap();
        assert!(build(&args(&["--config", config.to_str().unwrap()])).is_ok());
        let key = dir.path().join("key");
        std::fs::write(&key, "000102030405060708090a0b0c0d0e0f\n").unwrap();
        std::fs::set_permissions(&key, std::os::unix::fs::PermissionsExt::from_mode(0o600))
            .unwrap();
        assert!(build(&args(&["--key-file", key.to_str().unwrap()])).is_ok());
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
