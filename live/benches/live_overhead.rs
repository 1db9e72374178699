//! What the live view costs the control loop (prints figures, asserts nothing).
//!
//! The controller closes the loop with the embedded simulator in virtual time (the lab's harness,
//! the default bench and plan, as `lab`'s `control_step` bench), 6000 steps, three times: without the
//! live view, with the live view and no client, and with the live view and a Foxglove client
//! subscribed to every topic (the test's Python client, when python3 has `websockets` and
//! `foxglove-schemas-protobuf`). For each: the controller's step (`ControllerNode::step`) and the
//! observer's call after it (what the live view adds to the loop), and the stream's counts; the
//! client's own report of what it decoded, so a client that never connected (a slow Python start)
//! shows as such instead of passing for one.
//!
//! Run: `cargo bench -p live --bench live_overhead`.

#![allow(clippy::unwrap_used)]

use std::process::{Child, Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use controller::node::ControllerConfig;
use controller::session::{NoObserver, SessionObserver};
use lab::harness::{Harness, HarnessOptions};
use live::{LiveArgs, LiveStream};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;

const STEPS: usize = 6000;
const CLIENT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../excavator_ctl/tests/foxglove_client.py"
);

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Prints the figures of `v`; returns `[mean, p50]`.
fn summary(label: &str, mut v: Vec<f64>) -> [f64; 2] {
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    v.sort_by(f64::total_cmp);
    println!(
        "  {label}: mean {mean:.2} us, p50 {:.2} us, p99 {:.2} us, max {:.1} us",
        percentile(&v, 0.5),
        percentile(&v, 0.99),
        percentile(&v, 1.0)
    );
    [mean, percentile(&v, 0.5)]
}

/// Runs the loop with `observer`; returns the step's and the observer's `[mean, p50]`, us.
fn run(label: &str, observer: &mut dyn SessionObserver) -> ([f64; 2], [f64; 2]) {
    let sim = SimConfig::load::<&str>(None, None, Some(1), &[]).unwrap();
    let mut h = Harness::with_options(
        &sim,
        AutodigMaps::builtin().unwrap(),
        ControllerConfig::default(),
        &HarnessOptions {
            bus_name: "bench-live".to_owned(),
            ..HarnessOptions::default()
        },
    )
    .unwrap();
    let mut step_us = Vec::with_capacity(STEPS);
    let mut observe_us = Vec::with_capacity(STEPS);
    let wall = Instant::now();
    for _ in 0..STEPS {
        h.step().unwrap();
        step_us.push(h.node_step_wall().as_secs_f64() * 1e6);
        h.answer_scan_request();
        let time_s = h.time_s();
        let node = h.node().unwrap();
        let t0 = Instant::now();
        observer.after_step(time_s, node, None, &[]);
        observe_us.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    println!(
        "{label} ({STEPS} steps, {:.2} s wall):",
        wall.elapsed().as_secs_f64()
    );
    let step = summary("control step", step_us);
    let observe = summary("observer after the step", observe_us);
    (step, observe)
}

fn stream() -> LiveStream {
    let sim = SimConfig::load::<&str>(None, None, Some(1), &[]).unwrap();
    LiveStream::start(
        &LiveArgs {
            live: Some("127.0.0.1:0".to_owned()),
            pace: None,
            live_queue: live::DEFAULT_QUEUE,
        },
        &sim.machine,
    )
    .unwrap()
}

fn report(label: &str, s: &LiveStream, wall_s: f64) {
    let st = s.stats();
    let published = st.published.load(Ordering::Relaxed);
    println!(
        "  {label}: queued {}, dropped {}, published {published} ({:.0} messages/s)",
        st.queued.load(Ordering::Relaxed),
        st.dropped.load(Ordering::Relaxed),
        published as f64 / wall_s
    );
}

/// What the client's report (`foxglove_client.py`'s JSON) says it received: the figures with a
/// client are only those of a streaming client if it decoded messages.
fn received(report: &[u8]) -> String {
    let Ok(v) = serde_json::from_slice::<serde_json::Value>(report) else {
        return "WARNING: no report: the figures with a client may be without one".to_owned();
    };
    let counts: Vec<(String, u64)> = v["topics"]
        .as_object()
        .map(|m| {
            m.iter()
                .map(|(t, c)| (t.clone(), c["count"].as_u64().unwrap_or(0)))
                .collect()
        })
        .unwrap_or_default();
    let total: u64 = counts.iter().map(|(_, n)| n).sum();
    if total == 0 {
        return "WARNING: decoded no message: the figures with a client are without one".to_owned();
    }
    let per_topic: Vec<String> = counts.iter().map(|(t, n)| format!("{t} {n}")).collect();
    format!("decoded {total} messages ({})", per_topic.join(", "))
}

fn client(port: u16) -> Option<Child> {
    let ok = Command::new("python3")
        .args(["-c", "import websockets, foxglove_schemas_protobuf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        println!("no client: python3 without websockets / foxglove-schemas-protobuf");
        return None;
    }
    Command::new("python3")
        .args([CLIENT, &format!("ws://127.0.0.1:{port}"), "30", "hold"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .ok()
}

fn main() {
    let (base_step, base_obs) = run("no live view", &mut NoObserver);

    let mut s = stream();
    let t = Instant::now();
    let (idle_step, idle_obs) = run("live view, no client", &mut s);
    std::thread::sleep(Duration::from_millis(200));
    report("stream", &s, t.elapsed().as_secs_f64());
    drop(s);

    let mut s = stream();
    let child = client(s.port());
    // Wait for the client to subscribe (it connects and subscribes within a second).
    std::thread::sleep(Duration::from_secs(2));
    let t = Instant::now();
    let (busy_step, busy_obs) = run("live view, one client subscribed to every topic", &mut s);
    std::thread::sleep(Duration::from_millis(200));
    report("stream", &s, t.elapsed().as_secs_f64());
    drop(s);
    // The server has closed: the client prints what it received and leaves.
    if let Some(c) = child {
        match c.wait_with_output() {
            Ok(out) => println!("  client: {}", received(&out.stdout)),
            Err(e) => println!("  client: no report ({e})"),
        }
    }
    // Means carry the outliers of a shared machine (a preempted thread); the medians say what a step
    // usually costs.
    for (what, i) in [("mean", 0), ("median", 1)] {
        let base = base_step[i] + base_obs[i];
        let idle = idle_step[i] + idle_obs[i];
        let busy = busy_step[i] + busy_obs[i];
        println!(
            "control step + observer, {what}: {base:.2} us without the view, {idle:.2} us with it and no client ({:+.1} %), {busy:.2} us with a client ({:+.1} %)",
            100.0 * (idle / base - 1.0),
            100.0 * (busy / base - 1.0),
        );
    }
}
