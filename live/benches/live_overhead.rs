//! What the live view costs the control loop (prints figures, asserts nothing).
//!
//! The controller closes the loop with the embedded simulator in virtual time (the lab's harness,
//! the default bench and plan, as `lab`'s `control_step` bench) in three variants: without the live
//! view, with the live view and no client, and with the live view and a Foxglove client subscribed to
//! every topic (the test's Python client, when python3 has `websockets` and
//! `foxglove-schemas-protobuf`). The variants run interleaved, 3000 steps each in every one of 8
//! rounds, their order rotating from round to round, so that a slow spell of a shared machine (another
//! process, the CPU's clock) falls on all three alike rather than on whichever ran then. For each: the
//! controller's step (`ControllerNode::step`) and the observer's call after it (what the live view
//! adds to the loop) over all rounds, the median of the rounds' medians, and the stream's counts; the
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

/// Steps of one variant in one round.
const STEPS: usize = 3000;
/// Rounds of the three variants.
const ROUNDS: usize = 8;
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

/// Runs the loop with `observer` for [`STEPS`] steps; appends the step's and the observer's wall
/// times, us, to `step_us` and `observe_us`.
fn run(observer: &mut dyn SessionObserver, step_us: &mut Vec<f64>, observe_us: &mut Vec<f64>) {
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
}

/// One variant's samples over all rounds.
#[derive(Default)]
struct Samples {
    step_us: Vec<f64>,
    observe_us: Vec<f64>,
    /// Each round's median of step + observer, us.
    round_p50_us: Vec<f64>,
}

impl Samples {
    fn run(&mut self, observer: &mut dyn SessionObserver) {
        let from = self.step_us.len();
        run(observer, &mut self.step_us, &mut self.observe_us);
        let mut sum: Vec<f64> = self.step_us[from..]
            .iter()
            .zip(&self.observe_us[from..])
            .map(|(a, b)| a + b)
            .collect();
        sum.sort_by(f64::total_cmp);
        self.round_p50_us.push(percentile(&sum, 0.5));
    }

    /// Prints the figures; returns `[mean, median of the rounds' medians]` of step + observer, us.
    fn print(self, label: &str) -> [f64; 2] {
        println!("{label} ({} steps in {ROUNDS} rounds):", self.step_us.len());
        let step = summary("control step", self.step_us);
        let observe = summary("observer after the step", self.observe_us);
        let mut rounds = self.round_p50_us;
        rounds.sort_by(f64::total_cmp);
        let p50 = percentile(&rounds, 0.5);
        println!(
            "  step + observer, median per round: {} us (median {p50:.2} us)",
            rounds
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        [step[0] + observe[0], p50]
    }
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
    let mut idle = stream();
    let mut busy = stream();
    let child = client(busy.port());
    // Wait for the client to subscribe (it connects and subscribes within a second).
    std::thread::sleep(Duration::from_secs(2));
    let (mut base_s, mut idle_s, mut busy_s) =
        (Samples::default(), Samples::default(), Samples::default());
    let t = Instant::now();
    for round in 0..ROUNDS {
        for variant in (0..3).map(|i| (i + round) % 3) {
            match variant {
                0 => base_s.run(&mut NoObserver),
                1 => idle_s.run(&mut idle),
                _ => busy_s.run(&mut busy),
            }
        }
    }
    let wall_s = t.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(200));
    let base = base_s.print("no live view");
    let idle_fig = idle_s.print("live view, no client");
    report("stream", &idle, wall_s);
    let busy_fig = busy_s.print("live view, one client subscribed to every topic");
    report("stream", &busy, wall_s);
    drop(idle);
    drop(busy);
    // The server has closed: the client prints what it received and leaves.
    if let Some(c) = child {
        match c.wait_with_output() {
            Ok(out) => println!("  client: {}", received(&out.stdout)),
            Err(e) => println!("  client: no report ({e})"),
        }
    }
    // Means carry the outliers of a shared machine (a preempted thread); the medians say what a step
    // usually costs.
    for (what, i) in [("mean", 0), ("median of the rounds' medians", 1)] {
        let (base, idle, busy) = (base[i], idle_fig[i], busy_fig[i]);
        println!(
            "control step + observer, {what}: {base:.2} us without the view, {idle:.2} us with it and no client ({:+.1} %), {busy:.2} us with a client ({:+.1} %)",
            100.0 * (idle / base - 1.0),
            100.0 * (busy / base - 1.0),
        );
    }
}
