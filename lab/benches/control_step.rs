//! Control-step cost and receive-to-command latency (prints figures, asserts nothing).
//!
//! 1. Step cost: the controller closes the loop with the embedded simulator in virtual time over the
//!    default bench (the lab's harness); only `ControllerNode::step` is timed (target: under 20 us per 100 Hz step, 0.2 %
//!    of the period).
//! 2. Latency over the in-process bus (wall clock): a sensor frame is sent by a "gateway" node, the
//!    controller receives it, steps and sends its commands; the time from the sensor frame's send to
//!    the first command's arrival at the gateway node, bus timestamps.
//!
//! Run: `cargo bench -p lab --bench control_step`.

#![allow(clippy::unwrap_used)]

use controller::{ControllerConfig, ControllerNode};
use firmware_bridge::messages::{JointAngles, Message};
use firmware_bridge::transport::InProcessBus;
use lab::harness::{Harness, HarnessOptions};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn step_cost() {
    let sim = SimConfig::load::<&str>(None, None, Some(1), &[]).unwrap();
    let mut h = Harness::with_options(
        &sim,
        AutodigMaps::builtin().unwrap(),
        ControllerConfig::default(),
        &HarnessOptions {
            bus_name: "bench0".to_owned(),
            ..HarnessOptions::default()
        },
    )
    .unwrap();
    let mut costs_us = Vec::with_capacity(6000);
    for _ in 0..6000 {
        h.step().unwrap();
        costs_us.push(h.node_step_wall().as_secs_f64() * 1e6);
        h.answer_scan_request();
    }
    let node = h.node().unwrap();
    let mean = costs_us.iter().sum::<f64>() / costs_us.len() as f64;
    costs_us.sort_by(f64::total_cmp);
    println!(
        "control step ({} steps, 60 s of closed-loop digging): mean {:.2} us, p50 {:.2} us, p99 {:.2} us, max {:.1} us ({:.3} % of the 10 ms period at the mean); digs {}",
        costs_us.len(),
        mean,
        percentile(&costs_us, 0.5),
        percentile(&costs_us, 0.99),
        percentile(&costs_us, 1.0),
        mean / 100.0,
        node.statistics().len()
    );
}

fn latency() {
    let bus = InProcessBus::with_wall_clock("bench1");
    let gateway = bus.attach();
    let ctl = bus.attach();
    let mut node = ControllerNode::new(
        &planner::machine::MachineConfig::default_machine().unwrap(),
        AutodigMaps::builtin().unwrap(),
        ControllerConfig::default(),
    )
    .unwrap();
    let sensor = Message::JointAngles(JointAngles {
        boom_rad: 0.3,
        stick_rad: -1.5,
        bucket_rad: -1.0,
        swing_rad: 0.0,
    })
    .encode()
    .unwrap();
    let mut lat_us = Vec::with_capacity(2000);
    let mut inbox = Vec::with_capacity(8);
    for _ in 0..2000 {
        let t_send = bus.clock().now_ns();
        gateway.send(sensor).unwrap();
        inbox.clear();
        while let Some(f) = ctl.try_recv() {
            inbox.push(f);
        }
        let now = ctl_now(&bus);
        let out = node.step(now, &inbox);
        for f in &out {
            ctl.send(*f).unwrap();
        }
        let mut first = None;
        while let Some(f) = gateway.try_recv() {
            first.get_or_insert(f.timestamp_ns);
        }
        if let Some(t) = first {
            lat_us.push((t.saturating_sub(t_send)) as f64 * 1e-3);
        }
    }
    lat_us.sort_by(f64::total_cmp);
    if lat_us.is_empty() {
        println!("latency: no commands observed");
        return;
    }
    println!(
        "receive-to-command latency over the in-process bus ({} samples, excluding the wait for the 10 ms tick): p50 {:.2} us, p99 {:.2} us, max {:.1} us; with the tick the worst case adds one period (10 ms)",
        lat_us.len(),
        percentile(&lat_us, 0.5),
        percentile(&lat_us, 0.99),
        percentile(&lat_us, 1.0)
    );
}

fn ctl_now(bus: &InProcessBus) -> f64 {
    bus.clock().now_ns() as f64 * 1e-9
}

fn main() {
    step_cost();
    latency();
}
