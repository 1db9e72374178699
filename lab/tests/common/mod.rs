//! The closed-loop tests' knobs over the lab's virtual-time harness (`lab::harness`): a sensor
//! dropout switch, extra frames for the node, the fixed plan's scans answered.

#![allow(dead_code, clippy::unwrap_used)]

use controller::cycle::Phase;
use controller::node::{ControllerConfig, ControllerNode, Outbox};
use firmware_bridge::messages::{AuxValveCommand, Message, RequestedMode, Valve};
use firmware_bridge::transport::TimestampedFrame;
use lab::harness::{Harness, HarnessOptions};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;

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
