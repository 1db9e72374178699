//! Closed-loop harness: the controller node and the simulator (`vcan_sim::embedded`) on one
//! in-process bus in virtual time; the machine advances 10 ms (10 physics steps), then the node steps
//! once with the frames it received, and its frames go back on the bus.

#![allow(dead_code, clippy::unwrap_used)]

use controller::cycle::Phase;
use controller::node::{ControllerConfig, ControllerNode, Outbox};
use firmware_bridge::messages::{AuxValveCommand, Message, RequestedMode, Valve};
use firmware_bridge::transport::{InProcessBus, InProcessNode, TimestampedFrame, VirtualClock};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;
use vcan_sim::sensors::ScanRequest;

/// The control period.
pub const PERIOD_S: f64 = 0.01;

pub struct Loop {
    pub clock: VirtualClock,
    pub bus: InProcessBus,
    pub ctl: InProcessNode,
    pub machine: EmbeddedMachine,
    pub node: ControllerNode,
    pub sim: SimConfig,
    pub inbox: Vec<TimestampedFrame>,
    /// Forward the machine's frames to the node (false: sensor dropout).
    pub forward: bool,
    pub last_out: Outbox,
    pub steps: u64,
}

impl Loop {
    pub fn new(sim: SimConfig, config: ControllerConfig) -> Self {
        let clock = VirtualClock::new();
        let bus = InProcessBus::with_virtual_clock("sim0", clock.clone());
        let ctl = bus.attach();
        let machine = EmbeddedMachine::new(sim.build().unwrap(), bus.attach(), Some(clock.clone()));
        let node =
            ControllerNode::new(&sim.machine, AutodigMaps::builtin().unwrap(), config).unwrap();
        let last_out = Outbox::new().unwrap();
        Self {
            clock,
            bus,
            ctl,
            machine,
            node,
            sim,
            inbox: Vec::new(),
            forward: true,
            last_out,
            steps: 0,
        }
    }

    /// One control period; extra frames are delivered to the node after the machine's.
    pub fn step_with(&mut self, extra: &[TimestampedFrame]) -> Outbox {
        self.machine.advance(PERIOD_S);
        self.inbox.clear();
        while let Some(f) = self.ctl.try_recv() {
            if self.forward {
                self.inbox.push(f);
            }
        }
        self.inbox.extend_from_slice(extra);
        let now = self.clock.now_s();
        let out = self.node.step(now, &self.inbox);
        for f in &out {
            self.ctl.send(*f).unwrap();
        }
        if self.node.take_scan_request() {
            let scan = self.machine.scan(&ScanRequest::default());
            match self.node.cycle().config().scan_grid.terrain(&scan.points) {
                Ok(grid) => self.node.provide_terrain(grid),
                Err(e) => eprintln!("scan: {e}"),
            }
        }
        self.last_out = out;
        self.steps += 1;
        out
    }

    pub fn step(&mut self) -> Outbox {
        self.step_with(&[])
    }

    pub fn time_s(&self) -> f64 {
        self.clock.now_s()
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
        self.node.cycle().phase()
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
