//! The virtual-time harness: the simulated machine (`vcan_sim::embedded`) and the controller node on
//! one in-process bus, stepped in lockstep. Every in-process user (the demo, the experiments, the
//! lab's and the HIL crate's in-process tests, the control-step bench) runs this one loop.
//!
//! One control period ([`Harness::step`]): the machine advances 10 ms (ten 1 ms physics steps; its
//! gateway sees the frames sent since the last period and sends its sensor frames), then the node steps
//! once at the bus's virtual time with the frames it received, and its frames go on the bus.
//!
//! The gateway and the node share a key ([`HarnessOptions::key`]; by default one drawn from the
//! simulator's seed, so a session of one seed gives the same trace byte for byte), so the control path is authenticated with the truncated CMAC as on a provisioned
//! machine (docs/protocol.md). The gateway's session ids follow the simulator's seed.
//!
//! With a machine profile ([`HarnessOptions::profile`]) both ends speak that gateway's wire protocol
//! on the bus, translated where each end meets it, as `excavator-sim --profile` and `excavator-ctl
//! run --profile` do (docs/machine-profile.md); the gateway sends at the profile's periods.

use firmware_bridge::CanFrame;
use firmware_bridge::scan::{Scan, ScanRequest};
use firmware_bridge::secoc::SessionKey;
use std::sync::Arc;

use firmware_bridge::profile::Profile;
use firmware_bridge::transport::{
    InProcessBus, InProcessNode, ProfileLink, TimestampedFrame, VirtualClock,
};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;

use controller::session::driver::{BoxError, ScanSource};
use controller::{ControllerConfig, ControllerNode, Outbox};

/// The control period, s ([`firmware_bridge::dbc::CONTROL_PERIOD`]).
pub const PERIOD_S: f64 = firmware_bridge::dbc::CONTROL_PERIOD.as_secs_f64();

/// Bus options of a harness.
#[derive(Debug, Clone)]
pub struct HarnessOptions {
    /// The in-process bus's name.
    pub bus_name: String,
    /// Receive queue of the controller's bus node, frames (the bus's default when `None`).
    pub controller_queue: Option<usize>,
    /// Receive queue of the machine's bus node, frames (the bus's default when `None`).
    pub machine_queue: Option<usize>,
    /// The key the gateway and the controller share; `None`: one drawn from the simulator's seed
    /// ([`session_key`]).
    pub key: Option<SessionKey>,
    /// The machine profile both ends speak on the bus; `None`: the project's protocol.
    pub profile: Option<Arc<Profile>>,
}

/// The key of an in-process session of `seed`: both ends are in this process, so the key only has
/// to exercise the authenticated path, and drawing it from the seed (on its own stream) keeps the
/// session reproducible.
pub fn session_key(seed: u64) -> SessionKey {
    use rand::SeedableRng as _;
    /// Separates the key's stream from the other generators seeded from the same seed.
    const KEY_STREAM: u64 = 0x6b65_795f_7374_7265;
    SessionKey::generate_with(&mut rand_chacha::ChaCha8Rng::seed_from_u64(
        seed ^ KEY_STREAM,
    ))
}

impl Default for HarnessOptions {
    fn default() -> Self {
        Self {
            bus_name: "vcan0".to_owned(),
            controller_queue: None,
            machine_queue: None,
            key: None,
            profile: None,
        }
    }
}

/// Errors of the harness.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The simulator could not be built.
    #[error("building the simulator: {0}")]
    Simulator(#[from] vcan_sim::SimError),
    /// The controller could not be built.
    #[error("controller: {0}")]
    Controller(#[from] controller::ControllerError),
    /// The profile's gateway timeouts do not validate.
    #[error("the machine profile's gateway: {0}")]
    Gateway(#[from] firmware_bridge::gateway::GatewayConfigError),
    /// The bus refused a frame of the controller.
    #[error("in-process bus: {0}")]
    Bus(#[from] firmware_bridge::transport::Error),
    /// A frame could not be built.
    #[error("frame: {0}")]
    Frame(#[from] firmware_bridge::frame::FrameError),
}

/// The machine and the controller on one in-process bus in virtual time (module docs).
#[derive(Debug)]
pub struct Harness {
    /// The virtual clock (simulation time).
    pub clock: VirtualClock,
    /// The bus (attach more nodes to watch or inject).
    pub bus: InProcessBus,
    ctl: InProcessNode,
    /// The simulated machine.
    pub machine: EmbeddedMachine,
    node: Option<ControllerNode>,
    key: SessionKey,
    inbox: Vec<TimestampedFrame>,
    /// The controller's translation to the profile's wire protocol, if any.
    link: Option<ProfileLink>,
    /// With a profile: the wire frames behind `inbox`.
    wire_inbox: Vec<TimestampedFrame>,
    /// The frames the controller put on the bus in the last step or send.
    wire_sent: Vec<CanFrame>,
    empty: Outbox,
    steps: u64,
    node_step_wall: std::time::Duration,
}

impl Harness {
    /// The machine of `sim` and a controller with `maps` and `config`, on the default bus.
    ///
    /// # Errors
    /// [`HarnessError`] when the simulator or the controller cannot be built.
    pub fn new(
        sim: &SimConfig,
        maps: AutodigMaps,
        config: ControllerConfig,
    ) -> Result<Self, HarnessError> {
        Self::with_options(sim, maps, config, &HarnessOptions::default())
    }

    /// As [`Self::new`] with bus options.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn with_options(
        sim: &SimConfig,
        maps: AutodigMaps,
        config: ControllerConfig,
        options: &HarnessOptions,
    ) -> Result<Self, HarnessError> {
        let clock = VirtualClock::new();
        let bus = InProcessBus::with_virtual_clock(&options.bus_name, clock.clone());
        let attach = |queue: Option<usize>| match queue {
            Some(q) => bus.attach_with_queue(q),
            None => bus.attach(),
        };
        let ctl = attach(options.controller_queue);
        let plant = sim.build()?;
        let machine_bus = attach(options.machine_queue);
        let mut machine = match &options.profile {
            Some(p) => {
                EmbeddedMachine::with_profile(plant, machine_bus, Some(clock.clone()), p.clone())?
            }
            None => EmbeddedMachine::new(plant, machine_bus, Some(clock.clone())),
        };
        let key = options
            .key
            .clone()
            .unwrap_or_else(|| session_key(sim.scenario.seed));
        machine.node_mut().set_security(&key, sim.scenario.seed);
        machine.node_mut().set_gateway_name(sim.gateway_name);
        let mut node = ControllerNode::new(&sim.machine, maps, config)?;
        node.set_key(&key);
        Ok(Self {
            clock,
            bus,
            ctl,
            machine,
            node: Some(node),
            key,
            inbox: Vec::new(),
            link: options.profile.clone().map(ProfileLink::new),
            wire_inbox: Vec::new(),
            wire_sent: Vec::new(),
            empty: Outbox::new()?,
            steps: 0,
            node_step_wall: std::time::Duration::ZERO,
        })
    }

    /// Simulation time, s.
    pub fn time_s(&self) -> f64 {
        self.clock.now_s()
    }

    /// Control periods stepped.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Wall time the controller's last step took (what the control-step bench measures).
    pub fn node_step_wall(&self) -> std::time::Duration {
        self.node_step_wall
    }

    /// The controller, `None` once killed.
    pub fn node(&self) -> Option<&ControllerNode> {
        self.node.as_ref()
    }

    /// The controller, mutably.
    pub fn node_mut(&mut self) -> Option<&mut ControllerNode> {
        self.node.as_mut()
    }

    /// The controller and the machine together (both mutably), `None` once the controller is killed.
    pub fn parts_mut(&mut self) -> Option<(&mut ControllerNode, &mut EmbeddedMachine)> {
        self.node.as_mut().map(|n| (n, &mut self.machine))
    }

    /// Stops the controller without its shutdown frames, as SIGKILL does; the machine runs on.
    pub fn kill_controller(&mut self) {
        self.node = None;
    }

    /// Starts `node` in place of the controller (after [`Self::kill_controller`]: a restarted
    /// controller process), with the harness's key. Frames queued for the dead one are dropped, as a
    /// new process opens a new socket.
    pub fn start_controller(&mut self, mut node: ControllerNode) {
        node.set_key(&self.key);
        self.drain_controller_inbox();
        self.node = Some(node);
    }

    /// The frames the controller received in the last period (after any edit by
    /// [`Self::step_with`]).
    pub fn inbox(&self) -> &[TimestampedFrame] {
        &self.inbox
    }

    /// The frames of [`Self::inbox`] as they were on the bus (the profile's wire frames, with one).
    pub fn wire_inbox(&self) -> &[TimestampedFrame] {
        match self.link {
            Some(_) => &self.wire_inbox,
            None => &self.inbox,
        }
    }

    /// The frames the controller put on the bus in the last step or [`Self::send_from_controller`]
    /// (the profile's wire frames, with one).
    pub fn wire_sent(&self) -> &[CanFrame] {
        &self.wire_sent
    }

    /// The controller's translation to the profile's wire protocol and its counts, if any.
    pub fn profile_link(&self) -> Option<&ProfileLink> {
        self.link.as_ref()
    }

    /// One control period (module docs). Returns the controller's frames (empty once killed).
    ///
    /// # Errors
    /// [`HarnessError::Bus`] when the bus refuses a frame of the controller.
    pub fn step(&mut self) -> Result<Outbox, HarnessError> {
        self.step_with(|_| {})
    }

    /// One control period with the controller's received frames edited by `edit` first (drop them
    /// for a sensor dropout, add frames of another node).
    ///
    /// # Errors
    /// As [`Self::step`].
    pub fn step_with(
        &mut self,
        edit: impl FnOnce(&mut Vec<TimestampedFrame>),
    ) -> Result<Outbox, HarnessError> {
        self.step_watched(edit, |_| {})
    }

    /// As [`Self::step_with`], with `watch` called after every physics step of the machine (the
    /// gateway's state and the valve commands it applied in that step).
    ///
    /// # Errors
    /// As [`Self::step`].
    pub fn step_watched(
        &mut self,
        edit: impl FnOnce(&mut Vec<TimestampedFrame>),
        watch: impl FnMut(&vcan_sim::node::MachineNode),
    ) -> Result<Outbox, HarnessError> {
        self.machine.advance_watched(PERIOD_S, watch);
        self.inbox.clear();
        self.wire_inbox.clear();
        while let Some(f) = self.ctl.try_recv() {
            match &self.link {
                None => self.inbox.push(f),
                Some(link) => {
                    if let Some(frame) = link.from_wire(&f.frame) {
                        self.inbox.push(TimestampedFrame {
                            timestamp_ns: f.timestamp_ns,
                            frame,
                        });
                    }
                    self.wire_inbox.push(f);
                }
            }
        }
        edit(&mut self.inbox);
        self.steps += 1;
        self.wire_sent.clear();
        let Some(node) = self.node.as_mut() else {
            return Ok(self.empty);
        };
        let now_s = self.clock.now_s();
        let t0 = std::time::Instant::now();
        let out = node.step(now_s, &self.inbox);
        self.node_step_wall = t0.elapsed();
        for f in &out {
            self.send(f)?;
        }
        Ok(out)
    }

    /// Puts one of the controller's frames on the bus (translated, with a profile).
    fn send(&mut self, frame: &CanFrame) -> Result<(), HarnessError> {
        let wire = match &self.link {
            None => *frame,
            Some(link) => match link.to_wire(frame) {
                Some(wire) => wire,
                None => return Ok(()),
            },
        };
        self.ctl.send(wire)?;
        self.wire_sent.push(wire);
        Ok(())
    }

    /// Sends frames from the controller's bus node (its shutdown frames, say).
    ///
    /// # Errors
    /// [`HarnessError::Bus`] when the bus refuses one.
    pub fn send_from_controller(&mut self, frames: &[CanFrame]) -> Result<(), HarnessError> {
        self.wire_sent.clear();
        for f in frames {
            self.send(f)?;
        }
        Ok(())
    }

    /// Frames waiting for the controller (received after the last step), as they are on the bus (the
    /// profile's wire frames, with one).
    pub fn drain_controller_inbox(&mut self) -> Vec<TimestampedFrame> {
        let mut out = Vec::new();
        while let Some(f) = self.ctl.try_recv() {
            out.push(f);
        }
        out
    }

    /// Answers a pending scan request of the controller's work cycle with the default scan gridded by
    /// the cycle itself (the fixed plan's perception); returns whether one was answered.
    pub fn answer_scan_request(&mut self) -> bool {
        let Some(node) = self.node.as_mut() else {
            return false;
        };
        if !node.take_scan_request() {
            return false;
        }
        let scan = self.machine.scan(&ScanRequest::default());
        match node.cycle().config().scan_grid.terrain(&scan.points) {
            Ok(grid) => {
                node.provide_terrain(grid);
                true
            }
            Err(e) => {
                tracing::warn!(error = %e, "scan not usable");
                false
            }
        }
    }
}

/// The embedded machine as the session driver's scan source (the in-process form of the scan
/// interface, docs/scan-protocol.md): it scans at once, in virtual time.
#[derive(Debug)]
pub struct SimScans<'a> {
    machine: &'a mut EmbeddedMachine,
    ready: Option<Scan>,
}

impl<'a> SimScans<'a> {
    /// Scans of `machine`.
    pub fn new(machine: &'a mut EmbeddedMachine) -> Self {
        Self {
            machine,
            ready: None,
        }
    }
}

impl ScanSource for SimScans<'_> {
    fn request(&mut self, request: &ScanRequest) {
        self.ready = Some(self.machine.scan(request));
    }

    fn take(&mut self) -> Option<Result<Scan, BoxError>> {
        self.ready.take().map(Ok)
    }
}
