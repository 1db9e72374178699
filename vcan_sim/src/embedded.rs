//! The simulator in-process: a [`MachineNode`] attached to an [`InProcessNode`] of the in-process bus,
//! advanced in virtual time by the caller (no threads, deterministic for a seed).
//!
//! ```no_run
//! use firmware_bridge::transport::{InProcessBus, VirtualClock};
//! use vcan_sim::{SimConfig, embedded::EmbeddedMachine};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let clock = VirtualClock::new();
//! let bus = InProcessBus::with_virtual_clock("sim0", clock.clone());
//! let controller = bus.attach();
//! let config = SimConfig::load(None, None, Some(7), &["valve_deadband=0.1"])?;
//! let mut machine = EmbeddedMachine::new(config.build()?, bus.attach(), Some(clock));
//! // controller sends heartbeats/commands on `controller`, then:
//! machine.advance(0.01); // 10 physics steps; sensor frames are now on the bus
//! while let Some(frame) = controller.try_recv() { /* decode */ let _ = frame; }
//! # Ok(()) }
//! ```

use firmware_bridge::transport::{InProcessNode, VirtualClock};

use crate::node::{MachineNode, steps_in};
use crate::plant::{PHYSICS_DT_S, Plant};
use crate::sensors::{Scan, ScanRequest};

/// The machine on the in-process bus in virtual time.
#[derive(Debug)]
pub struct EmbeddedMachine {
    node: MachineNode,
    bus: InProcessNode,
    clock: Option<VirtualClock>,
    outbox: Vec<firmware_bridge::CanFrame>,
    send_errors: u64,
}

impl EmbeddedMachine {
    /// Attaches a plant to a bus node. With `clock`, each physics step sets the bus's virtual clock
    /// to the simulation time (the clock never goes backwards, so a controller loop may set it too).
    pub fn new(plant: Plant, bus: InProcessNode, clock: Option<VirtualClock>) -> Self {
        Self {
            node: MachineNode::new(plant),
            bus,
            clock,
            outbox: Vec::with_capacity(16),
            send_errors: 0,
        }
    }

    /// Advances by `dt_s` of simulated time (rounded to 1 ms steps): each step delivers the frames
    /// due to the gateway, runs the gateway and the physics, and sends the frames due.
    pub fn advance(&mut self, dt_s: f64) {
        self.advance_watched(dt_s, |_| {});
    }

    /// As [`Self::advance`], with `watch` called after every physics step (the gateway's state and
    /// the valve commands it applied in that step: [`MachineNode::valve_commands`]).
    pub fn advance_watched(&mut self, dt_s: f64, mut watch: impl FnMut(&MachineNode)) {
        for _ in 0..steps_in(dt_s) {
            self.step_once();
            watch(&self.node);
        }
    }

    fn step_once(&mut self) {
        if let Some(clock) = &self.clock {
            clock.set_ns(((self.node.time_s()) * 1e9).round() as u64);
        }
        while let Some(f) = self.bus.try_recv() {
            self.node.on_frame(&f.frame);
        }
        self.outbox.clear();
        self.node.step(&mut self.outbox);
        if let Some(clock) = &self.clock {
            clock.set_ns(((self.node.time_s()) * 1e9).round() as u64);
        }
        for frame in self.outbox.drain(..) {
            if self.bus.send(frame).is_err() {
                self.send_errors += 1;
            }
        }
    }

    /// Simulation time (s).
    pub fn time_s(&self) -> f64 {
        self.node.time_s()
    }

    /// The physics step (s).
    pub fn physics_dt_s(&self) -> f64 {
        PHYSICS_DT_S
    }

    /// The node (gateway and plant).
    pub fn node(&self) -> &MachineNode {
        &self.node
    }

    /// The node, mutably.
    pub fn node_mut(&mut self) -> &mut MachineNode {
        &mut self.node
    }

    /// The plant (true state, terrain, mass ledger).
    pub fn plant(&self) -> &Plant {
        self.node.plant()
    }

    /// A terrain scan (the in-process form of the scan interface, docs/scan-protocol.md).
    pub fn scan(&mut self, request: &ScanRequest) -> Scan {
        self.node.scan(request)
    }

    /// Frames the bus refused.
    pub fn send_errors(&self) -> u64 {
        self.send_errors
    }
}
