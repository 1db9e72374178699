//! `excavator-ctl run --strategy planned` through the real run loop ([`onboard::run::run_on`],
//! [`controller::io::run::run_session_loop`]) over the in-process bus on the wall clock, against the
//! simulator's real-time loop (`vcan_sim::realtime::run_on`) with its scan socket on loopback TCP,
//! both at the same time scale: the session folder is the one `demo` writes; a controller dropped
//! mid-session and started again with `--resume` finishes the session without losing or repeating
//! an action. Both ends hold the same key file, so the control path is authenticated.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::time::Duration;

use std::sync::Arc;

use firmware_bridge::profile::Profile;
use firmware_bridge::trace::Recorder;
use firmware_bridge::transport::{InProcessBus, ProfileBus, TimeScale};
use lab::demo::{DemoArgs, DemoStrategy, DemoSummary};
use onboard::run::RunArgs;
use vcan_sim::node::MachineNode;
use vcan_sim::realtime::RealtimeOptions;

/// A fresh key in `dir/machine.key`, readable by its owner only.
fn write_key_file(dir: &std::path::Path) -> std::path::PathBuf {
    use std::os::unix::fs::PermissionsExt as _;
    let path = dir.join("machine.key");
    let key: String = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos()
        .to_be_bytes()
        .iter()
        .map(|b| format!("{:02x}", b ^ 0x5a))
        .collect();
    std::fs::write(&path, format!("{key}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    path
}

/// A session seed that differs between runs (as a gateway's must at every start).
fn rand_seed() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos()
        .into()
}

fn free_port() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().to_string()
}

/// The simulator's real-time loop on an in-process bus (the planned demo's bench), serving range
/// scans; it runs until `stop` is sent.
struct Simulator {
    bus: InProcessBus,
    scan_addr: String,
    /// The key provisioned on both ends, as on a machine: the gateway's and `run --key-file`.
    key_file: std::path::PathBuf,
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<vcan_sim::Result<vcan_sim::realtime::RunSummary>>,
}

async fn simulator(out: &std::path::Path, time_scale: TimeScale) -> Simulator {
    simulator_with(out, time_scale, None).await
}

/// As [`simulator`], speaking `profile`'s wire protocol on the bus when one is given.
async fn simulator_with(
    out: &std::path::Path,
    time_scale: TimeScale,
    profile: Option<Arc<Profile>>,
) -> Simulator {
    let scan_addr = free_port();
    let (sim, _, _) = lab::demo::setup(&DemoArgs::defaults(out.to_path_buf())).unwrap();
    let bus = InProcessBus::with_wall_clock("vcan0");
    let sim_node = bus.attach();
    let options = RealtimeOptions {
        iface: "vcan0".into(),
        state_log: None,
        scan_socket: Some(scan_addr.clone()),
        time_scale,
    };
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let key_file = write_key_file(out.parent().unwrap());
    let key = firmware_bridge::secoc::SessionKey::from_file(&key_file).unwrap();
    // A profile's gateway sends at its periods and keeps its watchdogs, as `excavator-sim --profile`.
    let plant = sim.build().unwrap();
    let machine = match &profile {
        Some(p) => MachineNode::with_timing(plant, &p.timing()).unwrap(),
        None => MachineNode::new(plant),
    }
    .with_security(&key, rand_seed());
    let (stop, sim_stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        let stopped = async {
            let _ = sim_stopped.await;
        };
        match profile {
            Some(p) => {
                let bus = ProfileBus::new(sim_node, p);
                vcan_sim::realtime::run_on(&bus, machine, options, stopped).await
            }
            None => vcan_sim::realtime::run_on(&sim_node, machine, options, stopped).await,
        }
    });
    // The scan socket is bound by the simulator's task.
    tokio::time::sleep(Duration::from_millis(200)).await;
    Simulator {
        bus,
        scan_addr,
        key_file,
        stop,
        task,
    }
}

/// The safety timing for a simulated machine on a loaded host, `config/vm.toml` (README, "Running on
/// vcan"): the loop shares the test machine's cores with the simulator, and at a load of several
/// times the core count its 10 ms tick slips past the default 30 ms sensor age. The plumbing is
/// under test, not the timing.
pub const VM_CONFIG: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/vm.toml");

/// `run --strategy planned --digs N --out DIR --config config/vm.toml` against `sim` ([`VM_CONFIG`]).
fn planned_run(
    sim: &Simulator,
    digs: u32,
    time_scale: TimeScale,
    out: &std::path::Path,
) -> RunArgs {
    RunArgs {
        config: Some(VM_CONFIG.into()),
        key_file: Some(sim.key_file.clone()),
        digs: Some(digs),
        scan_addr: Some(sim.scan_addr.clone()),
        strategy: Some(DemoStrategy::Planned),
        time_scale: Some(time_scale),
        out: Some(out.to_path_buf()),
        ..RunArgs::new("vcan0")
    }
}

/// The controller's node on `sim`'s bus, recording to a new `out/trace.log`.
fn recorded_controller(
    sim: &Simulator,
    out: &std::path::Path,
) -> (
    firmware_bridge::transport::InProcessNode,
    onboard::run::SessionTrace,
) {
    let mut ctl_node = sim.bus.attach();
    std::fs::create_dir_all(out).unwrap();
    let recorder = Recorder::create(&out.join("trace.log"), "vcan0").unwrap();
    ctl_node.set_recorder(recorder.clone());
    let trace = onboard::run::SessionTrace {
        recorder,
        frames_before: 0,
    };
    (ctl_node, trace)
}

/// Runs the controller on `bus` until its session ends, then stops `sim`; the simulator's summary.
async fn run_to_the_end<B: firmware_bridge::Bus>(
    bus: &B,
    trace: onboard::run::SessionTrace,
    args: &RunArgs,
    sim: Simulator,
) -> vcan_sim::realtime::RunSummary {
    // A budget far above a session of two digs (~2 x 30 s at 2x); the test fails if it is what stops
    // it.
    let budget = tokio::time::sleep(Duration::from_secs(240));
    onboard::run::run_on(
        bus,
        Some(trace),
        args,
        onboard::run::RunConsole {
            plots: Some(Arc::new(lab::demo::Plots)),
            ..Default::default()
        },
        budget,
    )
    .await
    .unwrap();
    let _ = sim.stop.send(());
    sim.task.await.unwrap().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "wall clock: scripts/test-all runs it alone, after the parallel tests"]
async fn the_planned_session_runs_over_a_bus_in_scaled_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let time_scale = TimeScale::new(2.0).unwrap();
    let sim = simulator(&out, time_scale).await;
    let (ctl_node, trace) = recorded_controller(&sim, &out);
    let args = planned_run(&sim, 2, time_scale, &out);
    let summary = run_to_the_end(&ctl_node, trace, &args, sim).await;
    assert!(summary.simulated_s > 10.0, "{summary:?}");

    let s: DemoSummary =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s.strategy, "planned");
    assert_ne!(s.end, "stopped", "the session ran out of its budget: {s:?}");
    assert_eq!(s.totals.digs, 2, "{:?}", s.totals);
    assert!(s.totals.finished);
    assert!(s.planning.cycles >= 2, "{:?}", s.planning);
    assert!(s.totals.scans >= 2, "{:?}", s.totals);
    assert!(
        s.digs.iter().all(|d| d.weight_n.is_some_and(|w| w > 0.0)),
        "{:?}",
        s.digs
    );
    assert!(s.totals.trace_frames > 1000, "{:?}", s.totals);
    for f in [
        "summary.md",
        "trajectories.svg",
        "dig_stats.svg",
        "soil_samples.json",
        "map_after.svg",
        "trace.log",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(std::fs::read_dir(out.join("scans")).unwrap().count() >= 2);
}

/// The planned session with both ends on the example profile of another gateway
/// (`examples/other_gateway.toml`): the bus carries only that gateway's 11-bit frames, the session
/// digs, and the trace decodes through the profile.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "wall clock: scripts/test-all runs it alone, after the parallel tests"]
async fn the_planned_session_runs_over_another_gateways_protocol() {
    let example = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/other_gateway.toml"
    );
    let profile = Arc::new(Profile::load(std::path::Path::new(example)).unwrap());
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let time_scale = TimeScale::new(2.0).unwrap();
    let sim = simulator_with(&out, time_scale, Some(profile.clone())).await;
    let (ctl_node, trace) = recorded_controller(&sim, &out);
    let ctl_bus = ProfileBus::new(ctl_node, profile.clone());
    let args = RunArgs {
        profile: Some(example.into()),
        ..planned_run(&sim, 1, time_scale, &out)
    };
    let summary = run_to_the_end(&ctl_bus, trace, &args, sim).await;
    assert!(summary.simulated_s > 5.0, "{summary:?}");
    assert_eq!(
        ctl_bus.stats(),
        Default::default(),
        "every frame translated"
    );

    let s: DemoSummary =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_ne!(s.end, "stopped", "the session ran out of its budget: {s:?}");
    assert_eq!(s.totals.digs, 1, "{:?}", s.totals);
    assert!(s.totals.finished);

    // The trace holds the wire: the example gateway's 11-bit ids only, each one translating back.
    let (frames, angles, heartbeats) = common::wire_trace_counts(&out.join("trace.log"), &profile);
    assert!(
        frames > 1000 && angles > 500,
        "{frames} frames, {angles} joint angles"
    );
    // The gateway sends its angles at the example's 20 ms, the controller its heartbeat at 50 ms:
    // 2.5 angles per heartbeat (5 with the project's 10 ms).
    let per_heartbeat = f64::from(angles) / f64::from(heartbeats);
    assert!(
        (2.0..3.0).contains(&per_heartbeat),
        "{angles} joint angles, {heartbeats} heartbeats"
    );
}

/// Every `ControllerStatus` the controller sent, in trace order.
fn controller_statuses(
    trace: &std::path::Path,
) -> Vec<firmware_bridge::messages::ControllerStatus> {
    use firmware_bridge::messages::Message;
    std::fs::read_to_string(trace)
        .unwrap()
        .lines()
        .map(|l| firmware_bridge::trace::parse_line(l).unwrap())
        .filter_map(|r| match Message::decode(&r.frame) {
            Ok(d) => match d.message {
                Message::ControllerStatus(s) => Some(s),
                _ => None,
            },
            Err(_) => None,
        })
        .collect()
}

/// The `DigIndex` of every `ControllerStatus` the controller sent, in trace order.
fn status_dig_indices(trace: &std::path::Path) -> Vec<u16> {
    controller_statuses(trace)
        .iter()
        .map(|s| s.dig_index)
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "wall clock: scripts/test-all runs it alone, after the parallel tests"]
async fn a_controller_killed_mid_session_resumes_without_losing_or_repeating_an_action() {
    const DIGS: u32 = 2;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .try_init();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    // Twice real time: the kill and the restart need the loop's rate kept on a loaded host.
    let time_scale = TimeScale::new(2.0).unwrap();
    let sim = simulator(&out, time_scale).await;
    let mut args = planned_run(&sim, DIGS, time_scale, &out);
    let state_path = onboard::resume::state_path(&out);
    let trace_path = out.join("trace.log");

    // The first controller: killed (its future dropped at whatever step it is in) a while after
    // its first completed dig reached the state file.
    {
        let mut ctl_node = sim.bus.attach();
        let (recorder, before) = onboard::resume::open_trace(&trace_path, "vcan0", false).unwrap();
        assert_eq!(before, 0);
        ctl_node.set_recorder(recorder.clone());
        let trace = onboard::run::SessionTrace {
            recorder,
            frames_before: 0,
        };
        let killer = async {
            loop {
                tokio::time::sleep(Duration::from_millis(50)).await;
                // The second action planned and saved before the cycle begins it.
                let actions = std::fs::read(&state_path)
                    .ok()
                    .and_then(|b| serde_json::from_slice::<onboard::resume::RunState>(&b).ok())
                    .map_or(0, |s| s.driver.cycle.actions.len());
                if actions >= 2 {
                    break;
                }
            }
            // Into that action (the swing, the dig).
            tokio::time::sleep(Duration::from_millis(2500)).await;
        };
        tokio::select! {
            r = onboard::run::run_on(&ctl_node, Some(trace), &args, onboard::run::RunConsole::default(), std::future::pending()) => {
                panic!("the first run ended before it was killed: {r:?}");
            }
            () = killer => {}
            () = tokio::time::sleep(Duration::from_secs(200)) => panic!("no dig within the budget"),
        }
    }
    let saved: onboard::resume::RunState =
        serde_json::from_slice(&std::fs::read(&state_path).unwrap()).unwrap();
    assert_eq!(saved.records.digs.len(), 1, "{:?}", saved.records);
    // The interrupted action is in the state: the resumed session runs it, not another one.
    assert_eq!(saved.driver.cycle.action_index, 1);
    assert_eq!(saved.driver.cycle.actions.len(), 2);
    let interrupted = saved.driver.planned[1];
    let before_resume = status_dig_indices(&trace_path).len();

    // The second controller: `--resume`, after the gateway's watchdog neutralised the valves.
    tokio::time::sleep(Duration::from_millis(300)).await;
    args.out = None;
    args.resume = Some(out.clone());
    let mut ctl_node = sim.bus.attach();
    let (recorder, frames_before) =
        onboard::resume::open_trace(&trace_path, "vcan0", true).unwrap();
    assert!(frames_before > 1000, "{frames_before}");
    ctl_node.set_recorder(recorder.clone());
    let trace = onboard::run::SessionTrace {
        recorder,
        frames_before,
    };
    let budget = tokio::time::sleep(Duration::from_secs(200));
    onboard::run::run_on(
        &ctl_node,
        Some(trace),
        &args,
        onboard::run::RunConsole::default(),
        budget,
    )
    .await
    .unwrap();
    let _ = sim.stop.send(());
    sim.task.await.unwrap().unwrap();

    let s: DemoSummary =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_ne!(s.end, "stopped", "the session ran out of its budget: {s:?}");
    // An uninterrupted session of the same bench and seed (virtual time) does the same actions.
    let mut reference_args = DemoArgs::defaults(dir.path().join("reference"));
    reference_args.digs = DIGS;
    reference_args.quiet = true;
    let reference =
        lab::demo::run_session(&reference_args, &std::sync::atomic::AtomicBool::new(false))
            .unwrap();
    assert_eq!(s.totals.digs, reference.totals.digs, "{:?}", s.totals);
    assert_eq!(
        (s.totals.dig_actions, s.totals.cleanup_actions),
        (
            reference.totals.dig_actions,
            reference.totals.cleanup_actions
        )
    );
    // Each action once in the summary, the first one as saved before the kill.
    let indices: Vec<u32> = s.digs.iter().map(|d| d.index).collect();
    assert_eq!(indices, (0..DIGS).collect::<Vec<_>>());
    assert_eq!(s.digs[0].time_s, saved.records.digs[0].time_s);
    assert_eq!(
        (s.digs[1].predicted_volume_m3, s.digs[1].predicted_time_s),
        (interrupted.volume_m3, interrupted.time_s),
        "the resumed session planned another action instead of re-running the interrupted one"
    );
    assert!(s.digs.iter().all(|d| d.weight_n.is_some_and(|w| w > 0.0)));
    // The trace: one file, every line whole, the dig count never going back behind what was saved
    // and reaching the session's end.
    let digs = status_dig_indices(&trace_path);
    let (killed, resumed) = digs.split_at(before_resume);
    let saved_digs = u16::try_from(saved.records.digs.len()).unwrap();
    for part in [killed, resumed] {
        assert!(part.windows(2).all(|w| w[1] >= w[0]), "{part:?}");
    }
    assert!(
        resumed.first().is_some_and(|&d| d >= saved_digs),
        "{resumed:?}"
    );
    assert_eq!(resumed.last().copied(), Some(u16::try_from(DIGS).unwrap()));
    let lines = std::fs::read_to_string(&trace_path)
        .unwrap()
        .lines()
        .count();
    assert_eq!(s.totals.trace_frames, lines as u64);
    // Scans numbered on without gaps.
    let scans = std::fs::read_dir(out.join("scans")).unwrap().count();
    assert_eq!(scans, s.totals.scans);
}

/// The arguments of `run --iface vcan0 --config CONFIG [--digs N]` with the fixed strategy.
fn fixed_args(config: &std::path::Path, digs: Option<u32>) -> RunArgs {
    RunArgs {
        config: Some(config.to_owned()),
        digs,
        // The dig limit is under test, not the key (the key test's config names one).
        insecure_no_key: true,
        ..RunArgs::new("vcan0")
    }
}

#[test]
fn the_fixed_strategy_keeps_the_configs_dig_limit_unless_digs_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("plan.toml");
    std::fs::write(
        &config,
        "[cycle]\nrepeat = true\nmax_digs = 4\n\n[[cycle.actions]]\nkind = \"dig\"\nswing_deg = 0.0\n\
         start = { kind = \"tip\", x_m = 7.5, z_m = 2.4, bucket_abs_deg = -55.0 }\n",
    )
    .unwrap();
    // A repeating plan ends only at its limit: dropping it would run forever.
    let (node, _, _) = onboard::run::build(&fixed_args(&config, None)).unwrap();
    assert_eq!(node.cycle().config().max_digs, Some(4));
    let (node, _, _) = onboard::run::build(&fixed_args(&config, Some(2))).unwrap();
    assert_eq!(node.cycle().config().max_digs, Some(2));
}

#[test]
fn the_key_file_is_checked_before_the_bus_is_touched() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("plan.toml");
    std::fs::write(&config, "[security]\nkey_file = \"machine.key\"\n").unwrap();
    let key = write_key_file(dir.path());
    // The config's key file, relative to the config's folder.
    assert!(onboard::run::build(&fixed_args(&config, Some(1))).is_ok());
    // Readable by others: refused, naming the file and the fix.
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
    let e = format!(
        "{:#}",
        onboard::run::build(&fixed_args(&config, Some(1)))
            .err()
            .unwrap()
    );
    assert!(e.contains("machine.key") && e.contains("chmod 600"), "{e}");
    // --key-file overrides the config's: a 15-byte key is refused, naming the file.
    let short = dir.path().join("short.key");
    std::fs::write(&short, "000102030405060708090a0b0c0d0e").unwrap();
    std::fs::set_permissions(&short, std::fs::Permissions::from_mode(0o600)).unwrap();
    let mut args = fixed_args(&config, Some(1));
    args.key_file = Some(short);
    let e = format!("{:#}", onboard::run::build(&args).err().unwrap());
    assert!(
        e.contains("short.key") && e.contains("32 hexadecimal digits") && e.contains("has 30"),
        "{e}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "wall clock: scripts/test-all runs it alone, after the parallel tests"]
async fn the_operator_keys_at_a_terminal_estop_reset_and_stop_the_run() {
    use firmware_bridge::messages::Activity;
    use nix::sys::termios::{LocalFlags, tcgetattr};
    use std::io::Write as _;

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let time_scale = TimeScale::new(2.0).unwrap();
    let sim = simulator(&out, time_scale).await;
    let (ctl_node, trace) = recorded_controller(&sim, &out);
    let args = planned_run(&sim, 3, time_scale, &out);
    // The operator's terminal: `run` reads the pty's slave end, the test types on the master.
    let pty = nix::pty::openpty(None, None).unwrap();
    let terminal = std::fs::File::from(pty.slave.try_clone().unwrap());
    let mut keyboard = std::fs::File::from(pty.master);
    let cooked = tcgetattr(&pty.slave).unwrap().local_flags;
    assert!(cooked.contains(LocalFlags::ICANON | LocalFlags::ECHO));
    let console = onboard::run::RunConsole {
        keys: Some(terminal),
        session_log: false,
        link: None,
        plots: None,
    };
    let slave = pty.slave;
    let operator = async {
        // Into the session (armed, the first action under way), then the keys.
        tokio::time::sleep(Duration::from_secs(6)).await;
        let during = tcgetattr(&slave).unwrap().local_flags;
        assert!(
            !during.intersects(LocalFlags::ICANON | LocalFlags::ECHO),
            "{during:?}"
        );
        keyboard.write_all(b" ").unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        keyboard.write_all(b"r").unwrap();
        tokio::time::sleep(Duration::from_secs(1)).await;
        keyboard.write_all(b"S").unwrap();
        std::future::pending::<()>().await;
    };
    let budget = tokio::time::sleep(Duration::from_secs(240));
    let shutdown = async {
        tokio::select! {
            () = operator => {}
            () = budget => {}
        }
    };
    onboard::run::run_on(&ctl_node, Some(trace), &args, console, shutdown)
        .await
        .unwrap();
    let _ = sim.stop.send(());
    sim.task.await.unwrap().unwrap();

    // The terminal as it was.
    assert_eq!(tcgetattr(&slave).unwrap().local_flags, cooked);
    let s: DemoSummary =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s.end, "operator stop", "{s:?}");
    assert!(s.totals.digs < 3, "{:?}", s.totals);
    assert_eq!(
        s.trace_clock,
        Some(firmware_bridge::transport::TraceClock::WallAtRead)
    );
    // The e-stop is in the trace (fault code 5), and the run went on after the reset.
    let statuses = controller_statuses(&out.join("trace.log"));
    let estop = statuses
        .iter()
        .position(|s| s.activity == Activity::Faulted && s.fault_reason == 5)
        .expect("no e-stop in the trace");
    assert!(
        statuses[estop..]
            .iter()
            .any(|s| !matches!(s.activity, Activity::Faulted | Activity::Idle)),
        "no activity after the reset"
    );
}
