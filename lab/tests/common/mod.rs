//! The closed-loop tests' knobs over the lab's virtual-time harness (`lab::harness`): a sensor
//! dropout switch, extra frames for the node, the fixed plan's scans answered.

#![allow(dead_code, clippy::unwrap_used)]

use controller::step::cycle::{Action, Phase, StartPose};
use controller::{ControllerConfig, ControllerNode, Outbox};
use firmware_bridge::messages::{AuxValveCommand, Message, RequestedMode, Valve};
use firmware_bridge::transport::TimestampedFrame;
use lab::harness::{Harness, HarnessOptions};
use planner::autodig::AutodigMaps;
use planner::cleanup::CleanupPlan;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;

#[allow(unused_imports)]
pub use lab::harness::PERIOD_S;

/// The harness with the knobs the closed-loop tests turn.
pub struct Loop {
    pub h: Harness,
    pub sim: SimConfig,
    /// Forward the machine's frames to the node (false: sensor dropout).
    pub forward: bool,
    pub last_out: Outbox,
}

impl Loop {
    pub fn new(sim: SimConfig, config: ControllerConfig) -> Self {
        Self::with_maps(sim, config, AutodigMaps::builtin().unwrap())
    }

    pub fn with_maps(sim: SimConfig, config: ControllerConfig, maps: AutodigMaps) -> Self {
        let h = Harness::with_options(
            &sim,
            maps,
            config,
            &HarnessOptions {
                bus_name: "sim0".to_owned(),
                ..HarnessOptions::default()
            },
        )
        .unwrap();
        Self {
            h,
            sim,
            forward: true,
            last_out: Outbox::new().unwrap(),
        }
    }

    pub fn node(&self) -> &ControllerNode {
        self.h.node().unwrap()
    }

    pub fn node_mut(&mut self) -> &mut ControllerNode {
        self.h.node_mut().unwrap()
    }

    pub fn machine(&self) -> &EmbeddedMachine {
        &self.h.machine
    }

    /// One control period; extra frames are delivered to the node after the machine's.
    pub fn step_with(&mut self, extra: &[TimestampedFrame]) -> Outbox {
        let forward = self.forward;
        let out = self
            .h
            .step_with(|inbox| {
                if !forward {
                    inbox.clear();
                }
                inbox.extend_from_slice(extra);
            })
            .unwrap();
        self.h.answer_scan_request();
        self.last_out = out;
        out
    }

    pub fn step(&mut self) -> Outbox {
        self.step_with(&[])
    }

    pub fn time_s(&self) -> f64 {
        self.h.time_s()
    }

    /// Steps until `done` or `max_s` of simulated time; returns whether `done` held.
    pub fn run_until(&mut self, max_s: f64, mut done: impl FnMut(&Self) -> bool) -> bool {
        let end = self.time_s() + max_s;
        while self.time_s() < end {
            self.step();
            if done(self) {
                return true;
            }
        }
        false
    }

    pub fn phase(&self) -> Phase {
        self.node().cycle().phase()
    }
}

/// True if `out` holds neutral commands for all six valves.
pub fn has_all_neutral(out: &[firmware_bridge::CanFrame]) -> bool {
    Valve::ALL.iter().all(|v| {
        out.iter().any(|f| {
            matches!(Message::decode(f), Ok(d) if d.message == Message::AuxValveCommand(AuxValveCommand::neutral(*v)))
        })
    })
}

/// The requested mode of the heartbeat in `out`, if any.
pub fn heartbeat_mode(out: &[firmware_bridge::CanFrame]) -> Option<RequestedMode> {
    out.iter().find_map(|f| match Message::decode(f) {
        Ok(d) => match d.message {
            Message::ControllerHeartbeat(hb) => Some(hb.mode),
            _ => None,
        },
        Err(_) => None,
    })
}

/// A non-neutral valve command in `out`.
pub fn has_motion(out: &[firmware_bridge::CanFrame]) -> bool {
    out.iter().any(|f| match Message::decode(f) {
        Ok(d) => match d.message {
            Message::AuxValveCommand(c) => c.to_fraction() != 0.0,
            Message::PositionSetpoint(_) => true,
            _ => false,
        },
        Err(_) => false,
    })
}

/// The default simulator (default machine and bench, seed 1).
pub fn default_sim() -> SimConfig {
    SimConfig::load::<&str>(None, None, Some(1), &[]).unwrap()
}

/// The default plan cut to its first dig, once.
pub fn one_dig() -> ControllerConfig {
    let mut c = ControllerConfig::default();
    c.cycle.actions.truncate(1);
    c.cycle.repeat = false;
    c.cycle.max_digs = Some(1);
    c
}

/// A cleanup of a 0.2 m layer left on the floor with the floor-levelling settings.
pub fn cleanup_setup() -> (vcan_sim::SimConfig, ControllerConfig) {
    let mut sim = default_sim();
    // A thin layer left on the floor: 0.2 m from x = 4 to 5.8, bare floor beyond.
    sim.scenario.bench.height_m = 0.2;
    sim.scenario.bench.face_x_m = 4.0;
    sim.scenario.bench.length_m = 1.8;
    let mut config = ControllerConfig::default();
    config.cycle.actions = vec![Action::Cleanup {
        swing_rad: 0.0,
        start: StartPose::Tip {
            x_m: 6.3,
            z_m: 0.8,
            bucket_abs_rad: planner::cleanup::CleanupConfig::levelling().bucket_abs_rad,
        },
        plan: CleanupPlan {
            start_radius_m: 6.3,
            min_radius_m: 3.2,
        },
    }];
    config.cycle.repeat = false;
    config.cycle.max_digs = Some(1);
    // The floor-levelling settings (docs/autodig.md, Floor cleanup) over the controller's probe settings.
    let levelling = planner::cleanup::CleanupConfig::levelling();
    config.cleanup.bucket_abs_rad = levelling.bucket_abs_rad;
    config.cleanup.pressure_threshold_pct = levelling.pressure_threshold_pct;
    config.cleanup.pressure_hold_s = levelling.pressure_hold_s;
    config.cleanup.follow_settle_s = levelling.follow_settle_s;
    config.cleanup.follow_clearance_m = levelling.follow_clearance_m;
    (sim, config)
}

/// Lowest and highest terrain along the cleaned strip (x 4..6.2 m, y -0.4..0.4 m).
pub fn floor_extremes(l: &Loop) -> (f64, f64) {
    let terrain = &l.machine().plant().world.terrain;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut x = 4.0;
    while x <= 6.2 {
        for y in [-0.4, 0.0, 0.4] {
            let h = terrain.height_at(x, y).unwrap();
            lo = lo.min(h);
            hi = hi.max(h);
        }
        x += 0.1;
    }
    (lo, hi)
}

/// What a trace of a session on the 11-bit example profile holds: its frames, and how many of them
/// are `JointAngles` and `ControllerHeartbeat`. Panics on a 29-bit frame or one that does not
/// translate back through `profile`.
pub fn wire_trace_counts(
    trace: &std::path::Path,
    profile: &firmware_bridge::profile::Profile,
) -> (u32, u32, u32) {
    let text = std::fs::read_to_string(trace).unwrap();
    let (mut frames, mut angles, mut heartbeats) = (0, 0, 0);
    for line in text.lines() {
        let rec = firmware_bridge::trace::parse_line(line).unwrap();
        assert!(!rec.frame.is_extended(), "{line}");
        let canonical = profile.from_wire(&rec.frame).unwrap();
        match Message::decode(&canonical).map(|d| d.message) {
            Ok(Message::JointAngles(_)) => angles += 1,
            Ok(Message::ControllerHeartbeat(_)) => heartbeats += 1,
            _ => {}
        }
        frames += 1;
    }
    (frames, angles, heartbeats)
}
