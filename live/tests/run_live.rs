//! `excavator-ctl run --live`: the run loop ([`onboard::run::run_on_observed`]) over the in-process
//! bus on the wall clock, against the simulator's real-time loop, with the live view observing it.
//! The operator page's event stream follows the session, and its e-stop (an HTTP POST, as the
//! page's button sends) goes through the run loop's operator port: the controller faults with the
//! e-stop and commands neutral valves.

#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use firmware_bridge::transport::{InProcessBus, TimeScale};
use lab::demo::DemoArgs;
use onboard::run::RunArgs;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use vcan_sim::node::MachineNode;
use vcan_sim::realtime::RealtimeOptions;

/// POSTs `body` to the page's `/command` at `addr`; returns the status code and the reply.
async fn post_command(addr: &str, body: &str) -> (u16, serde_json::Value) {
    let token = common::page_token(addr).await;
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let request = format!(
        "POST /command HTTP/1.1\r\nHost: {addr}\r\nOrigin: http://{addr}\r\n\
         X-Operator-Token: {token}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    s.write_all(request.as_bytes()).await.unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).await.unwrap();
    let code = text[9..12].parse().unwrap();
    let reply = text.split("\r\n\r\n").nth(1).unwrap_or_default();
    (code, serde_json::from_str(reply).unwrap())
}

#[test]
#[ignore = "wall clock: scripts/test-all runs it alone, after the parallel tests"]
fn run_serves_the_page_and_its_estop_reaches_the_run_loop() {
    let dir = tempfile::tempdir().unwrap();
    let demo_args = DemoArgs::fixed(dir.path().join("sim"));
    let (sim, _, _) = lab::demo::setup(&demo_args).unwrap();
    // The safety timing of a simulated machine on a loaded host (`config/vm.toml`, as lab's wire
    // tests): the plumbing is under test.
    let safety =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/vm.toml"));
    let time_scale = TimeScale::new(2.0).unwrap();
    let args = RunArgs {
        config: Some(safety),
        digs: Some(1),
        time_scale: Some(time_scale),
        // The page is under test, not the key: both ends in this process use the public key.
        insecure_no_key: true,
        ..RunArgs::new("vcan0")
    };
    // The live view has its own runtime: started outside the session's.
    let mut stream = live::LiveStream::start(
        &live::LiveArgs {
            live: Some("127.0.0.1:0".into()),
            pace: None,
            live_queue: live::DEFAULT_QUEUE,
            ..Default::default()
        },
        &onboard::run::machine(&args).unwrap(),
    )
    .unwrap();
    let page = format!("127.0.0.1:{}", stream.page_port());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let (moving, after) = runtime.block_on(async {
        let bus = InProcessBus::with_wall_clock("vcan0");
        let sim_node = bus.attach();
        let ctl_node = bus.attach();
        let (sim_stop, sim_stopped) = tokio::sync::oneshot::channel::<()>();
        let machine = MachineNode::new(sim.build().unwrap());
        let options = RealtimeOptions {
            iface: "vcan0".into(),
            state_log: None,
            scan_socket: None,
            time_scale,
        };
        let sim_task = tokio::spawn(async move {
            vcan_sim::realtime::run_on(&sim_node, machine, options, async {
                let _ = sim_stopped.await;
            })
            .await
        });
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let operator = tokio::spawn({
            let page = page.clone();
            async move {
                let moving =
                    common::wait_for_state(&page, |s| {
                        s["operator"] == true
                            && s["valves"].as_array().unwrap().iter().any(|v| {
                                v["command_pct"].as_f64().is_some_and(|pct| pct.abs() > 1.0)
                            })
                    })
                    .await;
                let (code, reply) = post_command(&page, r#"{"cmd":"estop"}"#).await;
                assert_eq!(code, 200, "{reply}");
                assert_eq!(reply["status"]["fault"], "emergency stop", "{reply}");
                let after = common::wait_for_state(&page, |s| s["fault"] == "emergency stop").await;
                let _ = stop.send(());
                (moving, after)
            }
        });
        let budget = async {
            tokio::select! {
                _ = stopped => {}
                () = tokio::time::sleep(Duration::from_secs(120)) => {}
            }
        };
        onboard::run::run_on_observed(
            &ctl_node,
            None,
            &args,
            onboard::run::RunConsole::default(),
            budget,
            &mut stream,
        )
        .await
        .unwrap();
        let _ = sim_stop.send(());
        sim_task.await.unwrap().unwrap();
        tokio::time::timeout(Duration::from_secs(5), operator)
            .await
            .expect("the page's operator never saw the e-stop (budget ran out)")
            .unwrap()
    });
    drop(runtime);
    drop(stream);
    assert!(moving["time_s"].as_f64().unwrap() > 0.0, "{moving}");
    assert_eq!(after["safety"], "Faulted", "{after}");
    assert!(after["fault_count"].as_u64().unwrap() >= 1, "{after}");
    // From the e-stop on, the controller commands neutral valves.
    assert!(
        after["valves"]
            .as_array()
            .unwrap()
            .iter()
            .all(|v| v["command_pct"].as_f64() == Some(0.0)),
        "{after}"
    );
}
