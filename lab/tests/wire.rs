//! `excavator-ctl run --strategy planned` through the real run loop ([`lab::wire::run_on`],
//! [`controller::run::run_session_loop`]) over the in-process bus on the wall clock, against the
//! simulator's real-time loop (`vcan_sim::realtime::run_on`) with its scan socket on loopback TCP,
//! both at the same time scale: the session folder is the one `demo` writes. Both ends hold the same
//! key file, so the control path is authenticated.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use firmware_bridge::trace::Recorder;
use firmware_bridge::transport::{InProcessBus, TimeScale};
use lab::demo::{DemoArgs, DemoStrategy, DemoSummary};
use lab::wire::RunArgs;
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_planned_session_runs_over_a_bus_in_scaled_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let scan_addr = free_port();
    let time_scale = TimeScale::new(2.0).unwrap();
    // The loop shares the test machine's cores with the simulator and other tests: at a load of
    // several times the core count its 10 ms tick slips past the default 30 ms sensor age and the
    // five automatic re-arms run out before the first dig. The wider timing of a loaded machine
    // (the same as the HIL tests' in a TCG VM) keeps the session going; the plumbing is under test.
    let safety = dir.path().join("safety.toml");
    std::fs::write(
        &safety,
        "[safety]\nsensor_max_age_s = 0.1\nstatus_max_age_s = 0.6\narm_timeout_s = 2.0\n\
         max_auto_rearms = 1000\n",
    )
    .unwrap();
    let (sim, _, _) = lab::demo::setup(&DemoArgs::planned(out.clone())).unwrap();
    let bus = InProcessBus::with_wall_clock("vcan0");
    let sim_node = bus.attach();
    let mut ctl_node = bus.attach();
    let options = RealtimeOptions {
        iface: "vcan0".into(),
        state_log: None,
        scan_socket: Some(scan_addr.clone()),
        time_scale,
    };
    // The key provisioned on both ends, as on a machine: the gateway's and `run --key-file`.
    let key_file = write_key_file(dir.path());
    let key = firmware_bridge::secoc::SessionKey::from_file(&key_file).unwrap();
    let machine = MachineNode::new(sim.build().unwrap()).with_security(&key, rand_seed());
    let (stop_sim, sim_stopped) = tokio::sync::oneshot::channel::<()>();
    let simulator = tokio::spawn(async move {
        vcan_sim::realtime::run_on(&sim_node, machine, options, async {
            let _ = sim_stopped.await;
        })
        .await
    });
    // The scan socket is bound by the simulator's task.
    tokio::time::sleep(Duration::from_millis(200)).await;
    std::fs::create_dir_all(&out).unwrap();
    let recorder = Recorder::create(&out.join("trace.log"), "vcan0").unwrap();
    ctl_node.set_recorder(recorder.clone());
    let args = RunArgs {
        iface: "vcan0".into(),
        listen_only: false,
        machine: None,
        maps: None,
        config: Some(safety),
        key_file: Some(key_file),
        trace: None,
        digs: Some(2),
        scan_addr: Some(scan_addr),
        strategy: DemoStrategy::Planned,
        bench: None,
        seed: None,
        planner: None,
        hardness: None,
        time_scale,
        out: Some(out.clone()),
    };
    // A budget far above the session's ~2 x 30 s at 2x; the test fails if it is what stops it.
    let budget = tokio::time::sleep(Duration::from_secs(240));
    lab::wire::run_on(&ctl_node, Some(recorder), &args, budget)
        .await
        .unwrap();
    let _ = stop_sim.send(());
    let summary = simulator.await.unwrap().unwrap();
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

/// The arguments of `run --iface vcan0 --config CONFIG [--digs N]` with the fixed strategy.
fn fixed_args(config: &std::path::Path, digs: Option<u32>) -> RunArgs {
    RunArgs {
        iface: "vcan0".into(),
        listen_only: false,
        machine: None,
        maps: None,
        config: Some(config.to_owned()),
        key_file: None,
        trace: None,
        digs,
        scan_addr: None,
        strategy: DemoStrategy::Fixed,
        bench: None,
        seed: None,
        planner: None,
        hardness: None,
        time_scale: TimeScale::REAL_TIME,
        out: None,
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
    let (node, _, _) = lab::wire::build(&fixed_args(&config, None)).unwrap();
    assert_eq!(node.cycle().config().max_digs, Some(4));
    let (node, _, _) = lab::wire::build(&fixed_args(&config, Some(2))).unwrap();
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
    assert!(lab::wire::build(&fixed_args(&config, Some(1))).is_ok());
    // Readable by others: refused, naming the file and the fix.
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
    let e = format!(
        "{:#}",
        lab::wire::build(&fixed_args(&config, Some(1)))
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
    let e = format!("{:#}", lab::wire::build(&args).err().unwrap());
    assert!(
        e.contains("short.key") && e.contains("32 hexadecimal digits") && e.contains("has 30"),
        "{e}"
    );
}
