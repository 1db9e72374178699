//! The end-to-end scenarios over the in-process bus in virtual time: the simulator
//! (`vcan_sim::embedded`) and the controller node on one `InProcessBus`, plus an intruder node that
//! injects frames (spoofs, floods) and an observer that records everything like `candump` does.
//!
//! Per 10 ms period: the machine advances (10 physics steps at 1 kHz, the gateway sees the frames sent
//! since the last period), the node steps with the frames it received and its output goes on the bus;
//! scan requests are answered with `EmbeddedMachine::scan`. "Killing" the controller stops the node
//! without its shutdown frames, as SIGKILL does.

use controller::node::ControllerNode;
use firmware_bridge::CanFrame;
use firmware_bridge::transport::{InProcessBus, InProcessNode, TimestampedFrame, VirtualClock};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;
use vcan_sim::sensors::ScanRequest;

use crate::analysis::{Rec, StateSample};

/// The control period, s.
pub const PERIOD_S: f64 = 0.01;

/// A simulator, a controller and an intruder on one in-process bus.
pub struct Session {
    /// The virtual clock (simulation time).
    pub clock: VirtualClock,
    /// The bus.
    pub bus: InProcessBus,
    ctl: InProcessNode,
    intruder: InProcessNode,
    observer: InProcessNode,
    /// The simulator.
    pub machine: EmbeddedMachine,
    /// The controller; `None` once killed.
    pub node: Option<ControllerNode>,
    /// Every frame on the bus, in order (what `candump` records).
    pub record: Vec<Rec>,
    /// The simulator's true state every period (what `--state-log` writes).
    pub truth: Vec<StateSample>,
    /// Scans answered.
    pub scans: u64,
    inbox: Vec<TimestampedFrame>,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("time_s", &self.time_s())
            .field("frames", &self.record.len())
            .finish_non_exhaustive()
    }
}

impl Session {
    /// The default machine and bench (seed `seed`) with a controller configured by `config`.
    ///
    /// # Panics
    /// When the built-in machine, bench or maps do not load, or `config` is invalid.
    pub fn new(config: controller::node::ControllerConfig, seed: u64) -> Self {
        let sim = SimConfig::load::<&str>(None, None, Some(seed), &[])
            .unwrap_or_else(|e| panic!("simulator config: {e}"));
        let clock = VirtualClock::new();
        let bus = InProcessBus::with_virtual_clock("sim0", clock.clone());
        let ctl = bus.attach_with_queue(1 << 16);
        let intruder = bus.attach();
        let observer = bus.attach_with_queue(1 << 20);
        let plant = sim
            .build()
            .unwrap_or_else(|e| panic!("building the simulator: {e}"));
        let machine =
            EmbeddedMachine::new(plant, bus.attach_with_queue(1 << 16), Some(clock.clone()));
        let maps = AutodigMaps::builtin().unwrap_or_else(|e| panic!("Autodig maps: {e}"));
        let node = ControllerNode::new(&sim.machine, maps, config)
            .unwrap_or_else(|e| panic!("controller: {e}"));
        Self {
            clock,
            bus,
            ctl,
            intruder,
            observer,
            machine,
            node: Some(node),
            record: Vec::new(),
            truth: Vec::new(),
            scans: 0,
            inbox: Vec::new(),
        }
    }

    /// Simulation time, s.
    pub fn time_s(&self) -> f64 {
        self.clock.now_s()
    }

    /// The controller (panics if killed).
    ///
    /// # Panics
    /// After [`Self::kill_controller`].
    pub fn node(&self) -> &ControllerNode {
        self.node
            .as_ref()
            .unwrap_or_else(|| panic!("the controller was killed"))
    }

    /// Puts a frame on the bus from a third node (the gateway and the controller both receive it).
    ///
    /// # Panics
    /// When the bus refuses it.
    pub fn inject(&self, frame: CanFrame) {
        self.intruder
            .send(frame)
            .unwrap_or_else(|e| panic!("injecting {frame:?}: {e}"));
    }

    /// Stops the controller without its shutdown frames (SIGKILL).
    pub fn kill_controller(&mut self) {
        self.node = None;
        self.drain_observer();
    }

    fn drain_observer(&mut self) {
        while let Some(tf) = self.observer.try_recv() {
            self.record.push(Rec {
                t_s: tf.time_s(),
                frame: tf.frame,
            });
        }
    }

    /// Advances the machine by `dt_s` without stepping the controller (fine-grained timing checks).
    pub fn advance_machine(&mut self, dt_s: f64) {
        self.machine.advance(dt_s);
        self.drain_observer();
    }

    /// One control period.
    ///
    /// # Panics
    /// When the controller's frames cannot be sent.
    pub fn step(&mut self) {
        self.machine.advance(PERIOD_S);
        self.drain_observer();
        self.truth.push({
            let s = self.machine.plant().true_state();
            StateSample {
                time_s: s.time_s,
                angles_rad: s.angles_rad,
                rates_rad_per_s: s.rates_rad_per_s,
            }
        });
        self.inbox.clear();
        while let Some(f) = self.ctl.try_recv() {
            self.inbox.push(f);
        }
        let now = self.clock.now_s();
        let Some(node) = self.node.as_mut() else {
            return;
        };
        let out = node.step(now, &self.inbox);
        for f in &out {
            self.ctl
                .send(*f)
                .unwrap_or_else(|e| panic!("controller send: {e}"));
        }
        if node.take_scan_request() {
            let scan = self.machine.scan(&ScanRequest::default());
            if let Ok(grid) = node.cycle().config().scan_grid.terrain(&scan.points) {
                node.provide_terrain(grid);
                self.scans += 1;
            }
        }
        self.drain_observer();
    }

    /// Steps until `done` holds or `max_s` of simulation time passed; returns whether `done` held.
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
}
