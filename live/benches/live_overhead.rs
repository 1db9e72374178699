//! What the live view costs the control loop as the deployed controller runs it (prints figures,
//! asserts nothing).
//!
//! The controller closes the loop with the embedded simulator (the lab's harness, the default bench and
//! plan, as `lab`'s `control_step` bench) in three variants: without the live view, with the live view
//! and no client, and with the live view and a Foxglove client subscribed to every topic (the test's
//! Python client, when python3 has `websockets` and `foxglove-schemas-protobuf`).
//!
//! The loop runs as `excavator-ctl run` does under its systemd unit: paced, one step per control period
//! ([`CONTROL_PERIOD`], 10 ms: step, then sleep until the next period boundary, a late step skipping
//! the boundaries it missed), on a thread at `SCHED_FIFO` priority 50 while the live view's publisher
//! and server threads and the client run at normal priority. A loop that never sleeps is not what is
//! deployed: at normal priority its mean carries the other threads' preemptions, at `SCHED_FIFO` it
//! runs into the kernel's real-time throttling. Without the permission for `SCHED_FIFO` the loop runs
//! at normal priority and the output says so first.
//!
//! Each variant keeps its own closed loop going over 6 rounds of 800 steps (48 s of session in all);
//! the variants run in turn, their order rotating from round to round, so that a slow spell of a
//! shared machine falls on all three alike. Paced at the real period that is 144 s of loop; fewer
//! steps would leave the mean to a few outliers, a shorter period would not be the deployed loop.
//!
//! For each variant: the controller's step (`ControllerNode::step`), the observer's call after it
//! (what the live view adds to the loop) and their sum: mean, median, p99, max, each round's median
//! and their median, and the sum's mean and medians against the view's absence and against the view
//! without a client; the steps that started over a period late (deadline misses) and the latest
//! start; what took the CPU from the loop (its thread's involuntary context switches, the machine's
//! steal and interrupt time while the variant ran); the stream's counts, and the client's own report
//! of what it decoded, so a client that never connected (a slow Python start) shows as such instead
//! of passing for one.
//!
//! Run: `cargo bench -p live --bench live_overhead`.

#![allow(clippy::unwrap_used)]

use std::process::{Child, Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use controller::ControllerConfig;
use controller::session::driver::{NoObserver, SessionObserver};
use firmware_bridge::dbc::CONTROL_PERIOD;
use lab::harness::{Harness, HarnessOptions};
use live::{LiveArgs, LiveStream};
use planner::autodig::AutodigMaps;
use thread_priority::{
    RealtimeThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
    set_thread_priority_and_policy, thread_native_id,
};
use vcan_sim::SimConfig;

/// Steps of one variant in one round.
const STEPS: usize = 800;
/// Rounds of the three variants.
const ROUNDS: usize = 6;
/// The loop thread's `SCHED_FIFO` priority: `CPUSchedulingPriority` of
/// `packaging/excavator-ctl@.service`.
const FIFO_PRIORITY: u8 = 50;
const CLIENT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../excavator_ctl/tests/foxglove_client.py"
);

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Prints the figures of `v`; returns `[mean, median]`.
fn summary(label: &str, mut v: Vec<f64>) -> [f64; 2] {
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    v.sort_by(f64::total_cmp);
    println!(
        "  {label}: mean {mean:.2} us, median {:.2} us, p99 {:.2} us, max {:.1} us",
        percentile(&v, 0.5),
        percentile(&v, 0.99),
        percentile(&v, 1.0)
    );
    [mean, percentile(&v, 0.5)]
}

/// The loop thread's involuntary context switches (another thread took its CPU).
fn involuntary_switches() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/thread-self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("nonvoluntary_ctxt_switches:"))?
        .trim()
        .parse()
        .ok()
}

/// `[steal, irq + softirq]` CPU time of all CPUs since boot, s (`/proc/stat`, in USER_HZ ticks,
/// 1/100 s on Linux).
fn cpu_times_s() -> Option<[f64; 2]> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let ticks: Vec<u64> = stat
        .lines()
        .next()?
        .strip_prefix("cpu ")?
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()?;
    let tick_s = 0.01;
    Some([
        *ticks.get(7)? as f64 * tick_s,
        (ticks.get(5)? + ticks.get(6)?) as f64 * tick_s,
    ])
}

/// One variant: its closed loop and its samples over all rounds.
struct Variant {
    harness: Harness,
    /// The controller's step, us.
    step_us: Vec<f64>,
    /// The observer's call after the step, us.
    observe_us: Vec<f64>,
    /// Each round's median of step + observer, us.
    round_p50_us: Vec<f64>,
    /// Steps that started more than a period after their period boundary.
    late_starts: usize,
    /// The latest start after a period boundary, us.
    max_start_lateness_us: f64,
    /// Times the kernel switched the loop thread out for another thread, `None` where
    /// `/proc/thread-self/status` does not say.
    preempted: Option<u64>,
    /// CPU time the hypervisor took from the machine (steal) and interrupts took (irq, softirq)
    /// while this variant ran, s.
    steal_s: f64,
    irq_s: f64,
}

impl Variant {
    fn new(bus_name: &str) -> Self {
        let sim = SimConfig::load::<&str>(None, None, Some(1), &[]).unwrap();
        let harness = Harness::with_options(
            &sim,
            AutodigMaps::builtin().unwrap(),
            ControllerConfig::default(),
            &HarnessOptions {
                bus_name: bus_name.to_owned(),
                ..HarnessOptions::default()
            },
        )
        .unwrap();
        Self {
            harness,
            step_us: Vec::new(),
            observe_us: Vec::new(),
            round_p50_us: Vec::new(),
            late_starts: 0,
            max_start_lateness_us: 0.0,
            preempted: Some(0),
            steal_s: 0.0,
            irq_s: 0.0,
        }
    }

    /// Runs [`STEPS`] steps of the loop with `observer`, one per [`CONTROL_PERIOD`].
    fn run(&mut self, observer: &mut dyn SessionObserver) {
        let from = self.step_us.len();
        let (switches0, cpu0) = (involuntary_switches(), cpu_times_s());
        let h = &mut self.harness;
        let mut boundary = Instant::now();
        for _ in 0..STEPS {
            let lateness = boundary.elapsed();
            if lateness > CONTROL_PERIOD {
                self.late_starts += 1;
            }
            self.max_start_lateness_us =
                self.max_start_lateness_us.max(lateness.as_secs_f64() * 1e6);
            h.step().unwrap();
            self.step_us.push(h.node_step_wall().as_secs_f64() * 1e6);
            h.answer_scan_request();
            let time_s = h.time_s();
            let node = h.node().unwrap();
            let t0 = Instant::now();
            observer.after_step(time_s, node, None, &[]);
            self.observe_us.push(t0.elapsed().as_secs_f64() * 1e6);
            // The next boundary after now (those a late step overran are skipped, as `run` does).
            let now = Instant::now();
            boundary += CONTROL_PERIOD;
            while boundary <= now {
                boundary += CONTROL_PERIOD;
            }
            std::thread::sleep(boundary - now);
        }
        self.preempted = match (self.preempted, switches0, involuntary_switches()) {
            (Some(n), Some(a), Some(b)) => Some(n + b.saturating_sub(a)),
            _ => None,
        };
        if let (Some(a), Some(b)) = (cpu0, cpu_times_s()) {
            self.steal_s += b[0] - a[0];
            self.irq_s += b[1] - a[1];
        }
        let mut sum: Vec<f64> = self.step_us[from..]
            .iter()
            .zip(&self.observe_us[from..])
            .map(|(a, b)| a + b)
            .collect();
        sum.sort_by(f64::total_cmp);
        self.round_p50_us.push(percentile(&sum, 0.5));
    }

    /// Prints the figures; returns `[mean, median, median of the rounds' medians]` of step +
    /// observer, us.
    fn print(self, label: &str) -> [f64; 3] {
        println!("{label} ({} steps in {ROUNDS} rounds):", self.step_us.len());
        let sum: Vec<f64> = self
            .step_us
            .iter()
            .zip(&self.observe_us)
            .map(|(a, b)| a + b)
            .collect();
        summary("control step", self.step_us);
        summary("observer after the step", self.observe_us);
        let [mean, p50] = summary("step + observer", sum);
        let mut rounds = self.round_p50_us;
        rounds.sort_by(f64::total_cmp);
        let rounds_p50 = percentile(&rounds, 0.5);
        println!(
            "  step + observer, median per round: {} us (median {rounds_p50:.2} us)",
            rounds
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        println!(
            "  deadline misses (start over {} ms late): {}, latest start {:.0} us after its boundary",
            CONTROL_PERIOD.as_millis(),
            self.late_starts,
            self.max_start_lateness_us
        );
        let preempted = self
            .preempted
            .map_or_else(|| "unknown".to_owned(), |n| n.to_string());
        println!(
            "  loop thread preempted by another thread: {preempted} times; the machine's CPU time taken by the hypervisor (steal) {:.2} s, by interrupts {:.2} s",
            self.steal_s, self.irq_s
        );
        [mean, p50, rounds_p50]
    }
}

fn stream() -> LiveStream {
    let sim = SimConfig::load::<&str>(None, None, Some(1), &[]).unwrap();
    LiveStream::start(
        &LiveArgs {
            live: Some("127.0.0.1:0".to_owned()),
            pace: None,
            live_queue: live::DEFAULT_QUEUE,
            ..Default::default()
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

/// Starts the Python client on `port` for at most `seconds` (it leaves when the server closes).
fn client(port: u16, seconds: f64) -> Option<Child> {
    let ok = Command::new("python3")
        .args(["-c", "import websockets, foxglove_schemas_protobuf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        println!("no client: python3 without websockets / foxglove-schemas-protobuf");
        return None;
    }
    Command::new("python3")
        .args([
            CLIENT,
            &format!("ws://127.0.0.1:{port}"),
            &format!("{seconds:.0}"),
            "hold",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .ok()
}

fn main() {
    let mut idle = stream();
    let mut busy = stream();
    let run_s = (ROUNDS * STEPS * 3) as f64 * CONTROL_PERIOD.as_secs_f64();
    // The client stays until the server closes (with a margin for a slow machine).
    let child = client(busy.port(), 2.0 * run_s + 60.0);
    // Wait for the client to subscribe (it connects and subscribes within a second).
    std::thread::sleep(Duration::from_secs(2));
    // Every other thread (the streams' publishers and servers, the client) is running: only this one,
    // the loop's, is real-time, as in the deployed unit (whose later threads are reset to normal).
    match set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(FIFO_PRIORITY.try_into().unwrap()),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    ) {
        Ok(()) => println!(
            "loop thread: SCHED_FIFO priority {FIFO_PRIORITY} (the deployed unit's); the other threads normal"
        ),
        Err(e) => println!(
            "WARNING: loop thread at NORMAL priority: SCHED_FIFO not permitted ({e:?}); the figures include \
             preemption by the other threads, which the deployed controller does not see"
        ),
    }
    println!(
        "{ROUNDS} rounds x {STEPS} steps x 3 variants, paced at {} ms: {run_s:.0} s",
        CONTROL_PERIOD.as_millis()
    );
    let mut base_s = Variant::new("bench-live-base");
    let mut idle_s = Variant::new("bench-live-idle");
    let mut busy_s = Variant::new("bench-live-busy");
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
    for (what, i) in [
        ("mean", 0),
        ("median", 1),
        ("median of the rounds' medians", 2),
    ] {
        let (base, idle, busy) = (base[i], idle_fig[i], busy_fig[i]);
        println!(
            "control step + observer, {what}: {base:.2} us without the view; {idle:.2} us with it and no client ({:+.1} % vs no view); {busy:.2} us with a client ({:+.1} % vs no view, {:+.1} % vs no client)",
            100.0 * (idle / base - 1.0),
            100.0 * (busy / base - 1.0),
            100.0 * (busy / idle - 1.0),
        );
    }
}
