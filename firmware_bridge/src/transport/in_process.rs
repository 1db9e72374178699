//! The in-process bus: a broadcast medium between nodes in one process.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};

use tokio::sync::Notify;

use super::{Bus, BusFault, Clock, Error, Result, TimestampedFrame, TraceClock, VirtualClock};
use crate::frame::CanFrame;
use crate::trace::{Direction, Recorder};

/// Default number of frames a node's receive queue holds before it drops (like a socket buffer).
pub const DEFAULT_RX_QUEUE: usize = 4096;

/// Faults injected on an [`InProcessBus`] for fault tests.
///
/// Latency is measured on the bus clock. With a [`VirtualClock`] frames become due when the simulation
/// advances the clock; with the wall clock the async `recv` waits with tokio timers, so do not combine
/// a wall-clock bus with latency and tokio's paused clock (use a virtual clock for such tests).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultInjection {
    /// Delay from send to delivery, in bus clock nanoseconds (fixed, so order is kept).
    pub latency_ns: u64,
    /// Probability in `[0, 1]` that a frame is lost for one receiver (drawn per receiver).
    pub loss_probability: f64,
    /// Seed of the loss generator: the same seed and send order lose the same frames.
    pub seed: u64,
}

impl Default for FaultInjection {
    fn default() -> Self {
        Self {
            latency_ns: 0,
            loss_probability: 0.0,
            seed: 0,
        }
    }
}

/// Splitmix64: tiny, seedable and good enough for loss decisions.
#[derive(Debug)]
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[derive(Debug)]
struct NodeQueue {
    node_id: u64,
    frames: Mutex<VecDeque<TimestampedFrame>>,
    capacity: usize,
    dropped: Mutex<u64>,
    arrived: Notify,
}

#[derive(Debug)]
struct BusState {
    nodes: Vec<Arc<NodeQueue>>,
    next_node_id: u64,
    faults: FaultInjection,
    rng: Rng,
    frames_sent: u64,
    frames_lost: u64,
}

#[derive(Debug)]
struct Shared {
    name: String,
    clock: Clock,
    state: Mutex<BusState>,
}

/// Locks a mutex, continuing with the data if another thread panicked while holding it (the queues
/// stay structurally valid, and a test panic must not cascade into every other node).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Delivers `frame` to every node except `except`, applying fault injection; returns the send time.
fn deliver(shared: &Shared, frame: CanFrame, except: Option<u64>) -> u64 {
    let now = shared.clock.now_ns();
    let mut state = lock(&shared.state);
    state.frames_sent += 1;
    let faults = state.faults;
    let deliver_at = now.saturating_add(faults.latency_ns);
    let nodes = state.nodes.clone();
    for node in nodes.iter().filter(|n| Some(n.node_id) != except) {
        if faults.loss_probability > 0.0 && state.rng.next_f64() < faults.loss_probability {
            state.frames_lost += 1;
            continue;
        }
        let mut frames = lock(&node.frames);
        if frames.len() >= node.capacity {
            *lock(&node.dropped) += 1;
            continue;
        }
        frames.push_back(TimestampedFrame {
            timestamp_ns: deliver_at,
            frame,
        });
        drop(frames);
        node.arrived.notify_one();
    }
    now
}

/// An in-process CAN bus. Clone it to share; [`InProcessBus::attach`] adds a node.
///
/// ```
/// use firmware_bridge::transport::{InProcessBus, VirtualClock};
/// use firmware_bridge::CanFrame;
/// let clock = VirtualClock::new();
/// let bus = InProcessBus::with_virtual_clock("sim", clock.clone());
/// let controller = bus.attach();
/// let gateway = bus.attach();
/// clock.set_ns(10_000_000);
/// controller.send(CanFrame::new_extended(0x0CFE_3027, &[0; 8]).unwrap()).unwrap();
/// let got = gateway.try_recv().unwrap();
/// assert_eq!(got.timestamp_ns, 10_000_000);
/// assert!(controller.try_recv().is_none()); // a node never sees its own frames
/// ```
#[derive(Debug, Clone)]
pub struct InProcessBus {
    shared: Arc<Shared>,
}

impl InProcessBus {
    /// A bus named `name` (the interface name in traces) with the given clock.
    pub fn new(name: &str, clock: Clock) -> Self {
        Self {
            shared: Arc::new(Shared {
                name: name.to_string(),
                clock,
                state: Mutex::new(BusState {
                    nodes: Vec::new(),
                    next_node_id: 0,
                    faults: FaultInjection::default(),
                    rng: Rng(0),
                    frames_sent: 0,
                    frames_lost: 0,
                }),
            }),
        }
    }

    /// A bus timestamped by the wall clock.
    pub fn with_wall_clock(name: &str) -> Self {
        Self::new(name, Clock::Wall)
    }

    /// A bus timestamped by a virtual clock the simulation sets.
    pub fn with_virtual_clock(name: &str, clock: VirtualClock) -> Self {
        Self::new(name, Clock::Virtual(clock))
    }

    /// Sets (or clears, with the default) injected faults; reseeds the loss generator.
    pub fn set_faults(&self, faults: FaultInjection) {
        let mut state = lock(&self.shared.state);
        state.faults = faults;
        state.rng = Rng(faults.seed);
    }

    /// Attaches a node with the default receive queue.
    pub fn attach(&self) -> InProcessNode {
        self.attach_with_queue(DEFAULT_RX_QUEUE)
    }

    /// Attaches a node whose receive queue holds `capacity` frames; further frames are dropped and
    /// counted ([`InProcessNode::dropped`]), as a socket receive buffer would.
    pub fn attach_with_queue(&self, capacity: usize) -> InProcessNode {
        let mut state = lock(&self.shared.state);
        let queue = Arc::new(NodeQueue {
            node_id: state.next_node_id,
            frames: Mutex::new(VecDeque::new()),
            capacity: capacity.max(1),
            dropped: Mutex::new(0),
            arrived: Notify::new(),
        });
        state.next_node_id += 1;
        state.nodes.push(Arc::clone(&queue));
        InProcessNode {
            shared: Arc::clone(&self.shared),
            queue,
            recorder: None,
        }
    }

    /// Delivers an error frame (as a CAN controller driver would report one) to every node, for fault
    /// tests: the async `recv` returns it as [`Error::Fault`], `try_recv` as the frame itself.
    ///
    /// # Errors
    /// [`Error::Unsupported`] if `frame` is not an error frame.
    pub fn inject_error(&self, frame: CanFrame) -> Result<()> {
        if !frame.is_error() {
            return Err(Error::Unsupported("inject_error needs an error frame"));
        }
        deliver(&self.shared, frame, None);
        Ok(())
    }

    /// Frames sent so far and deliveries lost by fault injection.
    pub fn stats(&self) -> (u64, u64) {
        let state = lock(&self.shared.state);
        (state.frames_sent, state.frames_lost)
    }

    /// The bus clock.
    pub fn clock(&self) -> &Clock {
        &self.shared.clock
    }
}

/// A node on an [`InProcessBus`]. Dropping it detaches it.
///
/// Besides the async [`Bus`] methods, it has a synchronous path for a single-threaded virtual-time
/// loop: [`InProcessNode::send`] and [`InProcessNode::try_recv`]. (In async code, call the trait's
/// `Bus::send(&node, frame).await`; the inherent `send` is the synchronous one.)
#[derive(Debug)]
pub struct InProcessNode {
    shared: Arc<Shared>,
    queue: Arc<NodeQueue>,
    recorder: Option<Recorder>,
}

impl InProcessNode {
    /// Records every frame this node sends (` T`) and receives (` R`) to `recorder`, stamped as
    /// [`TraceClock::trace_ns`] writes this bus clock's times (a virtual clock from its epoch).
    pub fn set_recorder(&mut self, recorder: Recorder) {
        self.recorder = Some(recorder);
    }

    /// Sends synchronously: every other attached node gets the frame (subject to fault injection),
    /// timestamped with the bus clock plus the injected latency.
    ///
    /// # Errors
    /// Never fails today; the `Result` keeps the signature of a real transport.
    pub fn send(&self, frame: CanFrame) -> Result<()> {
        let now = deliver(&self.shared, frame, Some(self.queue.node_id));
        if let Some(rec) = &self.recorder {
            rec.record(
                self.trace_clock().trace_ns(now),
                Direction::Transmit,
                &frame,
            );
        }
        Ok(())
    }

    /// The next frame whose delivery time has come, without waiting. Error frames (see
    /// [`InProcessBus::inject_error`]) are returned as frames; map them with
    /// [`BusFault::from_error_frame`].
    pub fn try_recv(&self) -> Option<TimestampedFrame> {
        let now = self.shared.clock.now_ns();
        let got = {
            let mut frames = lock(&self.queue.frames);
            match frames.front() {
                Some(f) if f.timestamp_ns <= now => frames.pop_front(),
                _ => None,
            }
        };
        if let (Some(f), Some(rec)) = (&got, &self.recorder) {
            let at = self.trace_clock().trace_ns(f.timestamp_ns);
            rec.record(at, Direction::Receive, &f.frame);
        }
        got
    }

    /// Frames dropped because this node's receive queue was full.
    pub fn dropped(&self) -> u64 {
        *lock(&self.queue.dropped)
    }

    /// Delivery time of the next queued frame, if any (for virtual-time loops deciding how far to step).
    pub fn next_delivery_ns(&self) -> Option<u64> {
        lock(&self.queue.frames).front().map(|f| f.timestamp_ns)
    }

    async fn recv_async(&self) -> Result<TimestampedFrame> {
        loop {
            let arrived = self.queue.arrived.notified();
            tokio::pin!(arrived);
            arrived.as_mut().enable();
            if let Some(f) = self.try_recv() {
                return match BusFault::from_error_frame(&f.frame) {
                    Some(fault) => Err(Error::Fault(fault)),
                    None => Ok(f),
                };
            }
            match (self.next_delivery_ns(), &self.shared.clock) {
                (None, _) => arrived.await,
                (Some(at), Clock::Wall) => {
                    let wait = at.saturating_sub(self.shared.clock.now_ns());
                    tokio::time::sleep(std::time::Duration::from_nanos(wait)).await;
                }
                (Some(_), Clock::Virtual(v)) => {
                    let changed = v.changed();
                    tokio::pin!(changed);
                    changed.as_mut().enable();
                    if self.try_peek_due() {
                        continue;
                    }
                    changed.await;
                }
            }
        }
    }

    fn try_peek_due(&self) -> bool {
        self.next_delivery_ns()
            .is_some_and(|at| at <= self.shared.clock.now_ns())
    }
}

impl Drop for InProcessNode {
    fn drop(&mut self) {
        let mut state = lock(&self.shared.state);
        state.nodes.retain(|n| n.node_id != self.queue.node_id);
    }
}

impl Bus for InProcessNode {
    async fn send(&self, frame: CanFrame) -> Result<()> {
        InProcessNode::send(self, frame)
    }

    async fn recv(&self) -> Result<TimestampedFrame> {
        self.recv_async().await
    }

    fn now_ns(&self) -> u64 {
        self.shared.clock.now_ns()
    }

    fn interface(&self) -> &str {
        &self.shared.name
    }

    fn trace_clock(&self) -> TraceClock {
        match self.shared.clock {
            Clock::Wall => TraceClock::WallAtRead,
            Clock::Virtual(_) => TraceClock::Virtual,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(n: u8) -> CanFrame {
        CanFrame::new_extended(0x0CFF_5080, &[n; 8]).unwrap()
    }

    #[test]
    fn every_other_node_sees_frames_in_order() {
        let bus = InProcessBus::with_virtual_clock("t", VirtualClock::new());
        let a = bus.attach();
        let b = bus.attach();
        let c = bus.attach();
        for n in 0..5 {
            a.send(frame(n)).unwrap();
        }
        for node in [&b, &c] {
            let got: Vec<u8> = std::iter::from_fn(|| node.try_recv())
                .map(|f| f.frame.data()[0])
                .collect();
            assert_eq!(got, vec![0, 1, 2, 3, 4]);
        }
        assert!(a.try_recv().is_none());
    }

    #[test]
    fn latency_holds_frames_until_the_virtual_clock_reaches_them() {
        let clock = VirtualClock::new();
        let bus = InProcessBus::with_virtual_clock("t", clock.clone());
        bus.set_faults(FaultInjection {
            latency_ns: 2_000_000,
            ..Default::default()
        });
        let a = bus.attach();
        let b = bus.attach();
        a.send(frame(1)).unwrap();
        assert!(b.try_recv().is_none());
        clock.advance_ns(1_999_999);
        assert!(b.try_recv().is_none());
        clock.advance_ns(1);
        assert_eq!(b.try_recv().unwrap().timestamp_ns, 2_000_000);
    }

    #[test]
    fn loss_is_deterministic_for_a_seed() {
        let run = |seed| {
            let bus = InProcessBus::with_virtual_clock("t", VirtualClock::new());
            bus.set_faults(FaultInjection {
                loss_probability: 0.3,
                seed,
                ..Default::default()
            });
            let a = bus.attach();
            let b = bus.attach();
            for n in 0..200 {
                a.send(frame(n as u8)).unwrap();
            }
            std::iter::from_fn(|| b.try_recv())
                .map(|f| f.frame.data()[0])
                .collect::<Vec<_>>()
        };
        let first = run(7);
        assert_eq!(first, run(7));
        assert!(
            first.len() > 100 && first.len() < 180,
            "{} delivered",
            first.len()
        );
    }

    #[test]
    fn full_queue_drops_and_counts() {
        let bus = InProcessBus::with_virtual_clock("t", VirtualClock::new());
        let a = bus.attach();
        let b = bus.attach_with_queue(2);
        for n in 0..5 {
            a.send(frame(n)).unwrap();
        }
        assert_eq!(b.dropped(), 3);
    }

    #[test]
    fn detached_nodes_stop_receiving() {
        let bus = InProcessBus::with_virtual_clock("t", VirtualClock::new());
        let a = bus.attach();
        let b = bus.attach();
        drop(b);
        a.send(frame(0)).unwrap();
        assert_eq!(bus.stats(), (1, 0));
    }

    // Real time on purpose: the wall-clock bus timestamps with the system clock, which tokio's paused
    // clock does not move. The latency is 5 ms, the timeout generous.
    #[tokio::test]
    async fn async_recv_waits_for_a_frame_and_for_wall_latency() {
        let bus = InProcessBus::with_wall_clock("t");
        bus.set_faults(FaultInjection {
            latency_ns: 5_000_000,
            ..Default::default()
        });
        let a = bus.attach();
        let b = bus.attach();
        let waiter = tokio::spawn(async move { Bus::recv(&b).await.map(|f| f.frame) });
        tokio::task::yield_now().await;
        Bus::send(&a, frame(9)).await.unwrap();
        let got = tokio::time::timeout(std::time::Duration::from_secs(10), waiter).await;
        assert_eq!(got.unwrap().unwrap().unwrap(), frame(9));
    }

    #[tokio::test]
    async fn injected_error_frames_surface_as_faults() {
        let bus = InProcessBus::with_virtual_clock("t", VirtualClock::new());
        let a = bus.attach();
        let b = bus.attach();
        bus.inject_error(CanFrame::new_error(0x40, [0; 8]).unwrap())
            .unwrap();
        a.send(frame(1)).unwrap();
        assert!(matches!(
            Bus::recv(&b).await,
            Err(Error::Fault(BusFault::BusOff))
        ));
        assert_eq!(Bus::recv(&b).await.unwrap().frame, frame(1));
        assert!(a.try_recv().unwrap().frame.is_error());
        assert!(bus.inject_error(frame(2)).is_err());
    }

    #[tokio::test]
    async fn async_recv_wakes_when_the_virtual_clock_reaches_a_delayed_frame() {
        let clock = VirtualClock::new();
        let bus = InProcessBus::with_virtual_clock("t", clock.clone());
        bus.set_faults(FaultInjection {
            latency_ns: 1_000,
            ..Default::default()
        });
        let a = bus.attach();
        let b = bus.attach();
        a.send(frame(3)).unwrap();
        let waiter = tokio::spawn(async move { Bus::recv(&b).await.map(|f| f.timestamp_ns) });
        tokio::task::yield_now().await;
        clock.advance_ns(1_000);
        let got = tokio::time::timeout(std::time::Duration::from_secs(5), waiter).await;
        assert_eq!(got.unwrap().unwrap().unwrap(), 1_000);
    }
}
