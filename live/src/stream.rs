//! [`LiveStream`]: the session observer that serves the Foxglove view of a session over a WebSocket
//! (crate docs for the data flow).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use crossbeam_utils::CachePadded;
use rtrb::{Consumer, Producer};

use foxglove::messages::{FrameTransforms, Grid, Log, SceneEntity, SceneUpdate, log::Level};
use foxglove::{Channel, Context, WebSocketServer, WebSocketServerHandle};
use planner::kinematics::{Kinematics, MachinePose};
use planner::machine::MachineConfig;
use planner::terrain::TerrainGrid;

use controller::io::operator::OperatorSender;
use controller::session::driver::{SessionEvent, SessionObserver};
use controller::session::planned::PlannedSession;
use controller::step::cycle::{Action, CycleCommand, Phase};
use controller::step::cycle::{DigStats, dig_number};
use controller::step::node::ControllerNode;
use controller::step::safety::{Fault, SafetyState};
use firmware_bridge::messages::ControllerStatus;
use trace_tools::view;

use crate::access::{Access, Token};
use crate::page::{App, PageFeed, PageStep, Snapshot};
use crate::{LiveAddr, LiveArgs, LiveError};

/// How often the publisher repeats what does not change every step (the terrain, the scene), wall
/// time, so a client that connects late sees them.
const LATCH_EVERY: Duration = Duration::from_secs(1);

/// How often the publisher drains the queue (a 1024-update queue holds 10 s of steps at real time
/// and about 0.2 s at the demo's virtual-time speed).
const POLL: Duration = Duration::from_millis(5);

/// How long the end of a stream waits for the pages to receive the session's last state.
const PAGE_LINGER: Duration = Duration::from_secs(2);

/// One control step as the publisher needs it: plain values copied on the control loop (no
/// allocation, no conversion); the publisher derives the messages and the page's state from it.
#[derive(Debug, Clone, Copy)]
struct StepRecord {
    time_s: f64,
    estimate: view::EstimateSample,
    status: ControllerStatus,
    /// The safety state (with the active fault, if any).
    safety: SafetyState,
    fault_count: u64,
    /// Digs finished (the node's statistics).
    digs_done: u32,
    command: CycleCommand,
    action: Option<Action>,
    paused: bool,
    stopping: bool,
}

/// What the control loop hands to the publisher. A step is carried by value in the queue's
/// preallocated slot, so handing it over allocates nothing; the other updates are rare.
#[expect(
    clippy::large_enum_variant,
    reason = "the step, the common update, is carried by value so the control loop never allocates"
)]
#[derive(Debug)]
enum Update {
    Step(StepRecord),
    Terrain(u64, Box<TerrainGrid>),
    Scene(u64, Vec<SceneEntity>),
    Log(u64, Level, String),
    /// A dig finished (the page's last dig).
    DigDone(Box<DigStats>),
    /// The chosen dig's planned start in the world, m (the page's next dig).
    NextDig([f64; 3]),
    /// The page's commands reach a control loop.
    OperatorControl,
    /// The session ended, and why.
    Finished(String),
}

/// Counts of a stream. `queued` and `dropped` are written by the control loop only (a plain store,
/// no read-modify-write), `published` by the publisher only, each on a cache line of its own so that
/// neither thread's count takes the line from the other.
#[derive(Debug, Default)]
pub struct LiveStats {
    /// Updates handed to the publisher.
    pub queued: CachePadded<AtomicU64>,
    /// Updates dropped because the queue was full (the publisher or the client was behind).
    pub dropped: CachePadded<AtomicU64>,
    /// Foxglove messages the publisher logged on its channels.
    pub published: CachePadded<AtomicU64>,
}

/// The publisher's channels.
struct Channels {
    tf: Channel<FrameTransforms>,
    terrain: Channel<Grid>,
    scene: Channel<SceneUpdate>,
    signals: Channel<view::Signals>,
    log: Channel<Log>,
}

impl Channels {
    fn new(ctx: &Arc<Context>) -> Self {
        Self {
            tf: ctx.channel_builder(view::TOPIC_TRANSFORMS).build(),
            terrain: ctx.channel_builder(view::TOPIC_TERRAIN).build(),
            scene: ctx.channel_builder(view::TOPIC_SCENE).build(),
            signals: ctx.channel_builder(view::TOPIC_SIGNALS).build(),
            log: ctx.channel_builder(view::TOPIC_LOG).build(),
        }
    }
}

/// The publisher thread: queue in, Foxglove messages out.
struct Publisher {
    channels: Channels,
    kin: Kinematics,
    stats: Arc<LiveStats>,
    /// Scene entities by id (the latest of each), repeated for late clients.
    scene: BTreeMap<String, SceneEntity>,
    terrain: Option<Grid>,
    last_time_ns: u64,
    page: PageFeed,
}

impl Publisher {
    /// Drains the queue every [`POLL`] rather than waiting on it: the control loop never has to wake
    /// a waiting publisher, so handing over an update costs it no system call. Returns once the
    /// stream has closed the queue and what it queued is published.
    fn run(mut self, mut rx: Consumer<Update>) {
        let mut latched_at = Instant::now();
        loop {
            let closed = rx.is_abandoned();
            while let Ok(update) = rx.pop() {
                self.publish(update);
            }
            if closed {
                return;
            }
            self.page.flush(false);
            if latched_at.elapsed() >= LATCH_EVERY {
                self.republish_latched();
                latched_at = Instant::now();
            }
            std::thread::sleep(POLL);
        }
    }

    fn count(&self, n: u64) {
        self.stats.published.fetch_add(n, Ordering::Relaxed);
    }

    fn publish(&mut self, update: Update) {
        match update {
            Update::Step(step) => {
                let t = view::time_ns(step.time_s);
                self.last_time_ns = t;
                let e = &step.estimate;
                let tf = view::machine_transforms(&self.kin, &e.joints, e.swing_rad, &e.pose, t);
                self.channels.tf.log_with_time(&tf, t);
                self.channels.signals.log_with_time(&step_signals(&step), t);
                self.count(2);
                self.page.step(
                    &page_step(&step),
                    active_fault(step.safety).map(|f| f.to_string()),
                );
            }
            Update::Terrain(t, grid) => {
                self.page.terrain(&grid);
                let grid = view::terrain_grid(&grid, t);
                self.channels.terrain.log_with_time(&grid, t);
                self.terrain = Some(grid);
                self.count(1);
            }
            Update::Scene(t, entities) => {
                for e in &entities {
                    self.scene.insert(e.id.clone(), e.clone());
                }
                self.channels.scene.log_with_time(&view::scene(entities), t);
                self.count(1);
            }
            Update::Log(t, level, text) => {
                self.page.log(&format!("{:7.1} s  {text}", t as f64 * 1e-9));
                self.channels
                    .log
                    .log_with_time(&view::log(t, level, text), t);
                self.count(1);
            }
            Update::DigDone(d) => self.page.dig_done(&d),
            Update::NextDig(at) => self.page.next_dig(at),
            Update::OperatorControl => self.page.set_operator(true),
            Update::Finished(reason) => self.page.finished(&reason),
        }
    }

    fn republish_latched(&mut self) {
        let t = self.last_time_ns;
        if let Some(grid) = &self.terrain {
            self.channels.terrain.log_with_time(grid, t);
            self.count(1);
        }
        if !self.scene.is_empty() {
            let entities = self.scene.values().cloned().collect();
            self.channels.scene.log_with_time(&view::scene(entities), t);
            self.count(1);
        }
    }
}

/// The name of a safety state (its variant).
fn safety_name(s: SafetyState) -> &'static str {
    match s {
        SafetyState::ListenOnly => "ListenOnly",
        SafetyState::Disarmed => "Disarmed",
        SafetyState::Arming { .. } => "Arming",
        SafetyState::Armed { .. } => "Armed",
        SafetyState::Faulted { .. } => "Faulted",
        SafetyState::Shutdown => "Shutdown",
    }
}

/// The active fault of a safety state (as `Safety::active_fault`).
fn active_fault(s: SafetyState) -> Option<Fault> {
    match s {
        SafetyState::Faulted { fault, .. } => Some(fault),
        _ => None,
    }
}

/// The digs `node` has finished.
fn digs_done(node: &ControllerNode) -> u32 {
    u32::try_from(node.statistics().len()).unwrap_or(u32::MAX)
}

/// The page's view of a step.
fn page_step(step: &StepRecord) -> PageStep {
    let e = &step.estimate;
    let [tip_x_m, tip_z_m] = e.tip_m;
    let tip = e.pose.world_from_base(e.swing_rad, tip_x_m, tip_z_m);
    PageStep {
        time_s: step.time_s,
        activity: step.status.activity,
        stage: step.status.stage,
        digs_done: step.digs_done,
        // The bus counts the digs begun: while one runs (from the move to it to its dump) that is
        // its number.
        current_dig: (u32::from(step.status.dig_index) > step.digs_done)
            .then_some(u32::from(step.status.dig_index)),
        safety: safety_name(step.safety),
        fault_count: step.fault_count,
        paused: step.paused,
        stopping: step.stopping,
        action: step.action,
        pose: [e.pose.x_m, e.pose.y_m, e.pose.heading_rad],
        tip_m: tip,
        valves: valve_fractions(step.command),
    }
}

/// The valve commands of `command` as fractions.
fn valve_fractions(command: CycleCommand) -> [Option<f64>; 6] {
    match command {
        CycleCommand::Neutral => [Some(0.0); 6],
        CycleCommand::Valves(v) => v.map(view::finite),
        // Position mode: the gateway's loops drive the valves.
        CycleCommand::Position(_) => [None; 6],
    }
}

/// The `/signals` sample of a step: the estimate, the status the controller reports, its command.
fn step_signals(step: &StepRecord) -> view::Signals {
    let mut s = view::estimate_signals(&step.estimate);
    view::apply_status(&mut s, &step.status);
    s.valve_command = view::ValveCommands::from_array(valve_fractions(step.command));
    s.safety_state = Some(safety_name(step.safety).to_owned());
    s.fault = active_fault(step.safety).map(|f| f.to_string());
    s.fault_count = Some(step.fault_count);
    s
}

/// The live view of a session (crate docs): a Foxglove WebSocket server and the session observer
/// that feeds it.
pub struct LiveStream {
    tx: Option<Producer<Update>>,
    /// The counts of [`LiveStats`], kept here and stored there (this is their only writer).
    queued: u64,
    dropped: u64,
    stats: Arc<LiveStats>,
    pace: Option<f64>,
    wall_start: Option<(Instant, f64)>,
    publisher: Option<std::thread::JoinHandle<()>>,
    server: Option<WebSocketServerHandle>,
    page_server: Option<tokio::task::JoinHandle<()>>,
    /// The subprotocol shim in front of the server ([`crate::subprotocol`]).
    shim: Option<tokio::task::JoinHandle<()>>,
    /// Whether every page's event stream has ended (after the session's last state).
    pages_idle: Box<dyn Fn() -> bool + Send>,
    runtime: Option<tokio::runtime::Runtime>,
    port: u16,
    page_port: u16,
    operator: Arc<OnceLock<OperatorSender>>,
    started: Instant,
    last_fault: Option<Fault>,
    scene_sent: bool,
    floor_sent: bool,
    kin: Kinematics,
    track_length_m: f64,
}

impl std::fmt::Debug for LiveStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveStream")
            .field("port", &self.port)
            .field("page_port", &self.page_port)
            .field("pace", &self.pace)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl LiveStream {
    /// Starts the server for `args` (which must have `--live`) on its own runtime and the publisher
    /// thread, for a session of `machine`. Call outside an async context.
    ///
    /// # Errors
    /// [`LiveError`]: a bad address, pace or queue, a server that cannot bind, a machine whose
    /// kinematics cannot be built.
    pub fn start(args: &LiveArgs, machine: &MachineConfig) -> Result<Self, LiveError> {
        let addr_text = args
            .live
            .clone()
            .unwrap_or_else(|| crate::DEFAULT_ADDR.to_owned());
        let addr = LiveAddr::parse(&addr_text)?;
        if let Some(p) = args.pace
            && !(p.is_finite() && p > 0.0)
        {
            return Err(LiveError::Pace(p));
        }
        if args.live_queue == 0 {
            return Err(LiveError::Queue);
        }
        let kin = Kinematics::new(machine)?;
        // One worker: the server's I/O never competes with the control loop for both cores.
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("live-ws")
            .enable_all()
            .build()?;
        let ctx = Context::new();
        // The crate's server listens on loopback behind the subprotocol shim, which takes the
        // address asked for.
        let server = runtime
            .block_on(
                WebSocketServer::new()
                    .name("excavator")
                    .context(&ctx)
                    .bind("127.0.0.1", 0)
                    .tokio_runtime(runtime.handle())
                    .start(),
            )
            .map_err(|source| LiveError::Server {
                addr: addr_text.clone(),
                source,
            })?;
        let upstream = std::net::SocketAddr::from(([127, 0, 0, 1], server.port()));
        let ws_listener = runtime
            .block_on(tokio::net::TcpListener::bind((
                addr.host.as_str(),
                addr.port,
            )))
            .map_err(|source| LiveError::Bind {
                addr: addr_text.clone(),
                source,
            })?;
        let port = ws_listener.local_addr()?.port();
        let access = Access::new(&addr.host, &args.live_allow_host, &args.live_allow_origin);
        tracing::info!(allowed = %access, "live view: Host and Origin allow-list");
        let shim = runtime.spawn(crate::subprotocol::serve(
            ws_listener,
            upstream,
            Arc::new(access.clone()),
        ));
        // The operator page on the neighbouring port (any free one with port 0).
        let page_port = if addr.port == 0 {
            0
        } else {
            addr.port
                .checked_add(1)
                .ok_or(LiveError::PagePort(addr.port))?
        };
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind((
                addr.host.as_str(),
                page_port,
            )))
            .map_err(|source| LiveError::Page {
                addr: format!("{}:{page_port}", addr.host),
                source,
            })?;
        let page_port = listener.local_addr()?.port();
        let (page_tx, page_rx) = tokio::sync::watch::channel(Snapshot::default());
        let operator = Arc::new(OnceLock::new());
        let app = App::new(
            page_rx,
            Arc::clone(&operator),
            access,
            Token::random()?,
            page_port,
        );
        let pages_idle = Box::new(app.idle());
        let app = crate::page::router(app);
        let page_server = runtime.spawn(async move {
            if let Err(e) = axum::serve(listener, app).await {
                tracing::error!(error = %e, "the operator page's server stopped");
            }
        });
        let stats = Arc::new(LiveStats::default());
        let (mut tx, mut rx) = rtrb::RingBuffer::new(args.live_queue);
        // Touch every slot once now, so that the control loop never takes a page fault on the
        // queue's memory (it is allocated untouched).
        while tx.push(Update::OperatorControl).is_ok() {}
        while rx.pop().is_ok() {}
        let publisher = Publisher {
            channels: Channels::new(&ctx),
            kin: kin.clone(),
            stats: Arc::clone(&stats),
            scene: BTreeMap::new(),
            terrain: None,
            last_time_ns: 0,
            page: PageFeed::new(page_tx, false),
        };
        let handle = std::thread::Builder::new()
            .name("live-publisher".into())
            .spawn(move || {
                // The context lives as long as the publisher logs on its channels.
                let _ctx = ctx;
                publisher.run(rx);
            })?;
        Ok(Self {
            tx: Some(tx),
            queued: 0,
            dropped: 0,
            stats,
            pace: args.pace,
            wall_start: None,
            publisher: Some(handle),
            server: Some(server),
            page_server: Some(page_server),
            shim: Some(shim),
            pages_idle,
            runtime: Some(runtime),
            port,
            page_port,
            operator,
            started: Instant::now(),
            last_fault: None,
            scene_sent: false,
            floor_sent: false,
            kin,
            track_length_m: machine.tracks.length_m,
        })
    }

    /// The port the server listens on (the one asked for, or the one picked for port 0).
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The port of the operator page (HTTP): the WebSocket's port + 1, or a free one with port 0.
    pub fn page_port(&self) -> u16 {
        self.page_port
    }

    /// The stream's counts.
    pub fn stats(&self) -> &LiveStats {
        &self.stats
    }

    /// Hands an update to the publisher without waiting: a full queue drops it (counted).
    #[inline]
    fn offer(&mut self, update: Update) {
        let Some(tx) = &mut self.tx else {
            return;
        };
        if tx.push(update).is_ok() {
            self.queued += 1;
            self.stats.queued.store(self.queued, Ordering::Relaxed);
        } else {
            self.dropped += 1;
            self.stats.dropped.store(self.dropped, Ordering::Relaxed);
        }
    }

    /// Sleeps until wall time catches up with `time_s / pace` (only with `--pace`).
    fn pace_to(&mut self, time_s: f64) {
        let Some(factor) = self.pace else {
            return;
        };
        let (wall0, sim0) = *self.wall_start.get_or_insert((Instant::now(), time_s));
        let due = Duration::from_secs_f64(((time_s - sim0) / factor).max(0.0));
        if let Some(wait) = due.checked_sub(wall0.elapsed()) {
            std::thread::sleep(wait);
        }
    }

    /// The machine's scene on the first step, the floor on the first step of a planned session.
    #[cold]
    #[inline(never)]
    fn first_steps(
        &mut self,
        time_s: f64,
        node: &ControllerNode,
        session: Option<&PlannedSession>,
    ) {
        let t = view::time_ns(time_s);
        if !self.scene_sent {
            self.offer(Update::Scene(
                t,
                view::machine_entities(&self.kin, self.track_length_m, t),
            ));
            self.scene_sent = true;
        }
        if let Some(s) = session {
            let pose: MachinePose = node.estimator().state().pose;
            let floor_z_m = s.planner().config().floor_z_m;
            self.offer(Update::Scene(
                t,
                vec![view::floor_entity(floor_z_m, [pose.x_m, pose.y_m], 30.0, t)],
            ));
            self.floor_sent = true;
        }
    }

    /// A fault that came or went, as a log line.
    #[cold]
    #[inline(never)]
    fn fault_changed(&mut self, time_s: f64, fault: Option<Fault>) {
        let t = view::time_ns(time_s);
        if let Some(f) = fault {
            self.offer(Update::Log(t, Level::Error, format!("fault: {f}")));
        } else {
            self.offer(Update::Log(t, Level::Info, "fault cleared".to_owned()));
        }
        self.last_fault = fault;
    }

    /// Session events as log lines and scene entities, and the terrain map after a scan.
    #[cold]
    #[inline(never)]
    fn events(
        &mut self,
        time_s: f64,
        node: &ControllerNode,
        session: Option<&PlannedSession>,
        events: &[SessionEvent],
    ) {
        let t = view::time_ns(time_s);
        for event in events {
            match event {
                SessionEvent::Scanned(scan) => self.offer(Update::Log(
                    t,
                    Level::Debug,
                    format!("scan: {} points", scan.points.len()),
                )),
                SessionEvent::PhaseChanged { from, to } => {
                    self.offer(Update::Log(
                        t,
                        Level::Info,
                        format!("phase {from:?} -> {to:?}"),
                    ));
                    if *to == Phase::Dump {
                        // The spoil pile is where the bucket dumps.
                        let st = node.state();
                        let at = st.pose.world_from_base(st.swing_rad, st.tip.x_m, 0.0);
                        self.offer(Update::Scene(t, vec![view::spoil_entity(at, t)]));
                    }
                }
                SessionEvent::DigStarted { planned, pose } => {
                    let swing_rad = match node.action() {
                        Some(Action::Dig { swing_rad, .. } | Action::Cleanup { swing_rad, .. }) => {
                            *swing_rad
                        }
                        _ => node.state().swing_rad,
                    };
                    let mut text = format!(
                        "dig {} started at swing {:.1} deg",
                        dig_number(digs_done(node)),
                        swing_rad.to_degrees()
                    );
                    if let Some(v) = planned.volume_m3 {
                        text.push_str(&format!(", planned volume {v:.2} m3"));
                    }
                    self.offer(Update::Log(t, Level::Info, text));
                    if let Some([r_m, z_m, _]) = planned.start {
                        let start = pose.world_from_base(swing_rad, r_m, z_m);
                        self.offer(Update::NextDig(start));
                        self.offer(Update::Scene(
                            t,
                            vec![view::dig_entity([pose.x_m, pose.y_m], start, t)],
                        ));
                    }
                }
                SessionEvent::DigFinished { index, .. } => {
                    if let Some(d) = node.statistics().get(*index) {
                        self.offer(Update::DigDone(Box::new(*d)));
                        self.offer(Update::Log(
                            t,
                            Level::Info,
                            format!(
                                "dig {} done: {:?}, weight {} N, {:.1} s, {:.1} kJ, swept {:.2} m3",
                                d.number(),
                                d.action,
                                d.weight_n.map_or("-".to_owned(), |w| format!("{w:.0}")),
                                d.time_s,
                                d.energy_kj(),
                                d.swept_volume_m3
                            ),
                        ));
                    }
                }
            }
        }
        if events.iter().any(|e| matches!(e, SessionEvent::Scanned(_))) {
            let terrain = session
                .map(PlannedSession::terrain)
                .or_else(|| node.cycle().terrain());
            if let Some(grid) = terrain {
                self.offer(Update::Terrain(t, Box::new(grid.clone())));
            }
        }
    }
}

impl SessionObserver for LiveStream {
    fn operator_control(&mut self, sender: OperatorSender) {
        if self.operator.set(sender).is_ok() {
            self.offer(Update::OperatorControl);
        }
    }

    /// The steady state is one copy of the step into the queue; the rest (the first step's scene,
    /// a fault that changed, session events) is rare and kept out of the common path.
    fn after_step(
        &mut self,
        time_s: f64,
        node: &ControllerNode,
        session: Option<&PlannedSession>,
        events: &[SessionEvent],
    ) {
        if !self.scene_sent || (!self.floor_sent && session.is_some()) {
            self.first_steps(time_s, node, session);
        }
        let fault = node.fault();
        if fault != self.last_fault {
            self.fault_changed(time_s, fault);
        }
        if !events.is_empty() {
            self.events(time_s, node, session, events);
        }
        let safety = node.safety();
        self.offer(Update::Step(StepRecord {
            time_s,
            estimate: view::EstimateSample::of(node.state()),
            status: node.bus_status(),
            safety: safety.state(),
            fault_count: safety.fault_count(),
            digs_done: digs_done(node),
            command: node.last_command(),
            action: node.action().copied(),
            paused: node.cycle().paused(),
            stopping: node.cycle().stop_requested(),
        }));
        self.pace_to(time_s);
    }

    fn finished(&mut self, time_s: f64, reason: &str) {
        self.offer(Update::Log(
            view::time_ns(time_s),
            Level::Info,
            format!("session over: {reason}"),
        ));
        self.offer(Update::Finished(reason.to_owned()));
        let wall_s = self.started.elapsed().as_secs_f64();
        let published = self.stats.published.load(Ordering::Relaxed);
        tracing::info!(
            queued = self.stats.queued.load(Ordering::Relaxed),
            dropped = self.stats.dropped.load(Ordering::Relaxed),
            published,
            messages_per_s = format!("{:.0}", published as f64 / wall_s.max(1e-9)),
            "live stream"
        );
    }
}

impl Drop for LiveStream {
    fn drop(&mut self) {
        // Closing the queue ends the publisher once it has published what is queued.
        self.tx = None;
        if let Some(h) = self.publisher.take()
            && h.join().is_err()
        {
            tracing::warn!("the live publisher thread panicked");
        }
        // The pages following the session get its last state before the server goes: their event
        // streams end after sending it.
        let linger = Instant::now();
        while !(self.pages_idle)() && linger.elapsed() < PAGE_LINGER {
            std::thread::sleep(POLL);
        }
        if let Some(page) = self.page_server.take() {
            page.abort();
        }
        if let Some(shim) = self.shim.take() {
            shim.abort();
        }
        if let Some(server) = self.server.take() {
            drop(server.stop());
        }
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_timeout(Duration::from_secs(1));
        }
    }
}
