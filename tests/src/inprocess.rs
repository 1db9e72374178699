//! The end-to-end scenarios over the in-process bus in virtual time: the lab's harness
//! (`lab::harness`: the simulator and the controller node in lockstep) plus an intruder node that
//! injects frames (spoofs, floods) and an observer that records everything like `candump` does.
//! Scan requests are answered with the default scan. "Killing" the controller stops the node
//! without its shutdown frames, as SIGKILL does.

use controller::step::node::ControllerNode;
use firmware_bridge::CanFrame;
use firmware_bridge::transport::InProcessNode;
use lab::harness::{Harness, HarnessOptions};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;
use vcan_sim::scenario::SoilContactIntegration;

use crate::analysis::{Rec, StateSample};

pub use lab::harness::PERIOD_S;

/// A simulator, a controller and an intruder on one in-process bus (the lab's harness plus an
/// intruder and an observer node).
pub struct Session {
    h: Harness,
    intruder: InProcessNode,
    observer: InProcessNode,
    /// Every frame on the bus, in order (what `candump` records).
    pub record: Vec<Rec>,
    /// The simulator's true state every period (what `--state-log` writes).
    pub truth: Vec<StateSample>,
    /// Scans answered.
    pub scans: u64,
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
    pub fn new(config: controller::ControllerConfig, seed: u64) -> Self {
        Self::with_soil_contact(config, seed, SoilContactIntegration::default())
    }

    /// [`Session::new`] with the plant integrating the soil's force as `contact` says.
    ///
    /// # Panics
    /// As [`Session::new`].
    pub fn with_soil_contact(
        config: controller::ControllerConfig,
        seed: u64,
        contact: SoilContactIntegration,
    ) -> Self {
        let mut sim = SimConfig::load::<&str>(None, None, Some(seed), &[])
            .unwrap_or_else(|e| panic!("simulator config: {e}"));
        sim.scenario.soil_contact = contact;
        let maps = AutodigMaps::builtin().unwrap_or_else(|e| panic!("Autodig maps: {e}"));
        let h = Harness::with_options(
            &sim,
            maps,
            config,
            &HarnessOptions {
                bus_name: "sim0".to_owned(),
                controller_queue: Some(1 << 16),
                machine_queue: Some(1 << 16),
                key: None,
                profile: None,
            },
        )
        .unwrap_or_else(|e| panic!("harness: {e}"));
        let intruder = h.bus.attach();
        let observer = h.bus.attach_with_queue(1 << 20);
        Self {
            h,
            intruder,
            observer,
            record: Vec::new(),
            truth: Vec::new(),
            scans: 0,
        }
    }

    /// Simulation time, s.
    pub fn time_s(&self) -> f64 {
        self.h.time_s()
    }

    /// The simulated machine.
    pub fn machine(&self) -> &EmbeddedMachine {
        &self.h.machine
    }

    /// The controller (panics if killed).
    ///
    /// # Panics
    /// After [`Self::kill_controller`].
    pub fn node(&self) -> &ControllerNode {
        self.h
            .node()
            .unwrap_or_else(|| panic!("the controller was killed"))
    }

    /// The controller, for the operator's commands (panics if killed).
    ///
    /// # Panics
    /// After [`Self::kill_controller`].
    pub fn node_mut(&mut self) -> &mut ControllerNode {
        self.h
            .node_mut()
            .unwrap_or_else(|| panic!("the controller was killed"))
    }

    /// Whether the controller is alive (not killed).
    pub fn controller_alive(&self) -> bool {
        self.h.node().is_some()
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
        self.h.kill_controller();
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
        self.h.machine.advance(dt_s);
        self.drain_observer();
    }

    /// One control period: the harness's step, with the simulator's truth and every frame recorded.
    ///
    /// # Panics
    /// When the controller's frames cannot be sent.
    pub fn step(&mut self) {
        self.h
            .step()
            .unwrap_or_else(|e| panic!("controller send: {e}"));
        // The node's step leaves the plant as the machine's advance left it.
        let s = self.h.machine.plant().true_state();
        self.truth.push(StateSample {
            time_s: s.time_s,
            angles_rad: s.angles_rad,
            rates_rad_per_s: s.rates_rad_per_s,
        });
        self.drain_observer();
        if self.h.answer_scan_request() {
            self.scans += 1;
        }
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
