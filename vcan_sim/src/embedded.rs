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

use std::sync::Arc;

use firmware_bridge::gateway::GatewayConfigError;
use firmware_bridge::profile::Profile;
use firmware_bridge::secoc::SessionKey;
use firmware_bridge::transport::{InProcessNode, ProfileLink, VirtualClock};

use crate::node::{MachineNode, steps_in};
use crate::plant::{PHYSICS_DT_S, Plant};
use crate::sensors::{Scan, ScanRequest};

/// The session-nonce seed of an in-process gateway until its owner calls
/// [`MachineNode::set_security`]: reproducible, and never on a bus (`excavator-sim` draws its own).
const IN_PROCESS_NONCE_SEED: u64 = 0;

/// The machine on the in-process bus in virtual time.
#[derive(Debug)]
pub struct EmbeddedMachine {
    node: MachineNode,
    bus: InProcessNode,
    clock: Option<VirtualClock>,
    outbox: Vec<firmware_bridge::CanFrame>,
    send_errors: u64,
    /// The machine profile the gateway speaks on the bus, if not the project's protocol.
    link: Option<ProfileLink>,
}

impl EmbeddedMachine {
    /// Attaches a plant to a bus node. With `clock`, each physics step sets the bus's virtual clock
    /// to the simulation time (the clock never goes backwards, so a controller loop may set it too).
    pub fn new(plant: Plant, bus: InProcessNode, clock: Option<VirtualClock>) -> Self {
        Self::attached(MachineNode::new(plant), bus, clock, None)
    }

    fn attached(
        mut node: MachineNode,
        bus: InProcessNode,
        clock: Option<VirtualClock>,
        link: Option<ProfileLink>,
    ) -> Self {
        // In virtual time a run must repeat exactly, so the gateway's nonces start from a fixed seed
        // instead of the OS's; the lab reseeds them (and keys both ends) from the session's seed.
        node.set_security(&SessionKey::PUBLIC, IN_PROCESS_NONCE_SEED);
        Self {
            node,
            bus,
            clock,
            outbox: Vec::with_capacity(16),
            send_errors: 0,
            link,
        }
    }

    /// As [`Self::new`], the gateway speaking `profile`'s wire protocol on the bus at its periods
    /// and with its watchdogs ([`MachineNode::with_timing`]; `docs/machine-profile.md`).
    ///
    /// # Errors
    /// [`GatewayConfigError`] if the profile's timeouts do not validate.
    pub fn with_profile(
        plant: Plant,
        bus: InProcessNode,
        clock: Option<VirtualClock>,
        profile: Arc<Profile>,
    ) -> Result<Self, GatewayConfigError> {
        let node = MachineNode::with_timing(plant, &profile.timing())?;
        Ok(Self::attached(
            node,
            bus,
            clock,
            Some(ProfileLink::new(profile)),
        ))
    }

    /// The profile's translation and its counts (`None`: the project's protocol).
    pub fn profile_link(&self) -> Option<&ProfileLink> {
        self.link.as_ref()
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
            match &self.link {
                None => self.node.on_frame(&f.frame),
                Some(link) => {
                    if let Some(frame) = link.from_wire(&f.frame) {
                        self.node.on_frame(&frame);
                    }
                }
            }
        }
        self.outbox.clear();
        self.node.step(&mut self.outbox);
        if let Some(clock) = &self.clock {
            clock.set_ns(((self.node.time_s()) * 1e9).round() as u64);
        }
        for frame in self.outbox.drain(..) {
            let frame = match &self.link {
                None => frame,
                Some(link) => match link.to_wire(&frame) {
                    Some(wire) => wire,
                    None => continue,
                },
            };
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
