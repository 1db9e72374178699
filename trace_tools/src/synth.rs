//! Synthetic but realistic traces: the full message schedule (`busload::SCHEDULE`, every periodic DBC
//! message at its `GenMsgCycleTime`, 1192 frames/s) of a machine digging over and over, with no
//! active fault, for the tests, the benchmark and the documentation examples.
//!
//! One work cycle lasts [`CYCLE_S`]: Autodig (boom down, pre-dig, dig, capture, done), then swing to
//! dump, dump and return. The bucket tip follows a dig path in the x-z plane that is turned into joint
//! angles with the default machine's inverse kinematics (`planner::kinematics`) once, into a table of
//! one cycle; valve commands follow the joint rates with the cylinder sign conventions of
//! `docs/ARCHITECTURE.md`, pressures rise while digging. Frames of one 10 ms control period are spaced
//! by about one frame time with a small deterministic jitter, so timestamps increase strictly.
//!
//! Memory is the one-cycle table, independent of the number of frames produced.

use std::io::{self, Write};

use firmware_bridge::dbc::{self, MessageDesc};
use firmware_bridge::dm1::{CONTROLLER_DTCS, Dm1Reporter, GATEWAY_DTCS};
use firmware_bridge::frame::CanFrame;
use firmware_bridge::messages::{
    Activity, AutodigStageCode, AuxValveCommand, AuxValveMeasured, ControllerHeartbeat,
    ControllerStatus, Cylinder, GatewayFaults, GatewayMode, GatewaySession, GatewayStatus,
    JointAngles, JointRates, PositionSetpoint, PumpPressures, RequestedMode, TrackOdometry, Valve,
    ValveState,
};
use firmware_bridge::secoc::{Sealer, SessionKey};
use firmware_bridge::{GATEWAY_ADDRESS, Message, trace};
use planner::kinematics::{BucketPose, Kinematics};
use planner::machine::MachineConfig;

/// Length of one synthetic work cycle, s.
pub const CYCLE_S: f64 = 12.0;
/// Control period, s ([`firmware_bridge::dbc::CONTROL_PERIOD`]).
const PERIOD_S: f64 = dbc::CONTROL_PERIOD.as_secs_f64();
/// Control periods per cycle.
const STEPS_PER_CYCLE: usize = (CYCLE_S / PERIOD_S + 0.5) as usize;
/// Whether a message of `desc` goes out in control period `step`: every `GenMsgCycleTime` of the
/// DBC, rounded to whole control periods.
fn due(desc: &MessageDesc, step: u64) -> bool {
    let period_ns = dbc::CONTROL_PERIOD.as_nanos().max(1);
    let every = (u128::from(desc.cycle_time_ms) * 1_000_000 / period_ns).max(1);
    u128::from(step).is_multiple_of(every)
}

/// Nanoseconds between frames of one control period (a 131-160 bit frame takes 262-320 us at
/// 500 kbit/s).
const FRAME_SPACING_NS: u64 = 300_000;

/// The number of frames of `seconds` of the schedule ([`firmware_bridge::busload::SCHEDULE`]).
pub fn frames_in(seconds: f64) -> u64 {
    let per_s: f64 = firmware_bridge::busload::SCHEDULE
        .iter()
        .map(|e| e.rate_hz)
        .sum();
    (seconds * per_s).round() as u64
}

/// Settings of a synthetic trace.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthConfig {
    /// Number of frames to produce.
    pub frames: u64,
    /// Timestamp of the first control period, ns since the Unix epoch.
    pub start_ns: u64,
    /// Interface name written on every line.
    pub interface: String,
    /// Seed of the timing jitter.
    pub seed: u64,
    /// Largest timing jitter added to each frame, ns (below the 300 us frame spacing keeps the order).
    pub jitter_ns: u64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            frames: 10_000,
            start_ns: 1_700_000_000_000_000_000,
            interface: "vcan0".to_string(),
            seed: 1,
            jitter_ns: 40_000,
        }
    }
}

/// One control period of the cycle table.
#[derive(Debug, Clone, Copy)]
struct Sample {
    q: [f64; 3],
    /// False where the inverse kinematics failed and the previous angles were kept (checked by the
    /// tests: every pose of the cycle is reachable).
    #[cfg_attr(not(test), allow(dead_code))]
    reached: bool,
    swing_rad: f64,
    stage: AutodigStageCode,
    activity: Activity,
}

/// An iterator of `(timestamp_ns, frame)` following the schedule.
#[derive(Debug)]
pub struct SyntheticTrace {
    cfg: SynthConfig,
    cycle: Vec<Sample>,
    produced: u64,
    step: u64,
    pending: Vec<(u64, CanFrame)>,
    next_pending: usize,
    rng: u64,
    heartbeat: ControllerHeartbeat,
    gateway_alive: u8,
    status_alive: u8,
    /// The controller's frames are sealed as on the bus, for session [`SYNTH_SESSION_ID`].
    sealer: Sealer,
    swept_m3: f64,
}

/// Stage, activity and bucket-tip pose `(x, z, bucket_abs)` at a phase of the cycle (seconds).
/// The gateway session of synthetic traces.
pub const SYNTH_SESSION_ID: u32 = 0x5157_0001;

fn cycle_pose(t: f64) -> (AutodigStageCode, Activity, [f64; 3], f64) {
    fn lerp(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
        let s = (0.5 - 0.5 * (std::f64::consts::PI * s.clamp(0.0, 1.0)).cos()).clamp(0.0, 1.0);
        [
            a[0] + (b[0] - a[0]) * s,
            a[1] + (b[1] - a[1]) * s,
            a[2] + (b[2] - a[2]) * s,
        ]
    }
    // Bucket angles are `bucket_abs` (pin -> tip to the horizontal): curling lowers it, so the
    // captured bucket points back toward the machine (about -pi).
    const START: [f64; 3] = [7.2, 1.2, -1.4];
    const TOUCH: [f64; 3] = [7.2, -0.2, -1.4];
    const PENETRATED: [f64; 3] = [7.0, -0.7, -1.6];
    const DRAGGED: [f64; 3] = [5.0, -0.6, -2.3];
    const CAPTURED: [f64; 3] = [5.4, 1.0, -3.0];
    const CARRY: [f64; 3] = [5.8, 2.5, -3.0];
    const DUMPED: [f64; 3] = [6.2, 2.5, -1.2];
    use Activity as A;
    use AutodigStageCode as S;
    // (duration s, stage, activity, tip from, tip to, swing from, swing to)
    type Phase = (f64, S, A, [f64; 3], [f64; 3], f64, f64);
    let phases: [Phase; 8] = [
        (1.5, S::BoomDown, A::Dig, START, TOUCH, 0.0, 0.0),
        (1.5, S::PreDig, A::Dig, TOUCH, PENETRATED, 0.0, 0.0),
        (3.5, S::Dig, A::Dig, PENETRATED, DRAGGED, 0.0, 0.0),
        (1.5, S::Capture, A::Dig, DRAGGED, CAPTURED, 0.0, 0.0),
        (0.5, S::Done, A::Dig, CAPTURED, CAPTURED, 0.0, 0.0),
        (1.5, S::None, A::SwingToDump, CAPTURED, CARRY, 0.0, 1.5),
        (1.0, S::None, A::Dump, CARRY, DUMPED, 1.5, 1.5),
        (1.0, S::None, A::Return, DUMPED, START, 1.5, 0.0),
    ];
    let mut start = 0.0;
    for (len, stage, activity, from, to, swing_from, swing_to) in phases {
        if t < start + len {
            let s = (t - start) / len;
            let pose = lerp(from, to, s);
            let swing = lerp([swing_from; 3], [swing_to; 3], s)[0];
            return (stage, activity, pose, swing);
        }
        start += len;
    }
    (S::None, A::Return, START, 0.0)
}

/// Builds the one-cycle table with the default machine's inverse kinematics; poses it cannot reach
/// keep the previous angles.
fn cycle_table() -> Vec<Sample> {
    let kin = MachineConfig::default_machine()
        .ok()
        .and_then(|m| Kinematics::new(&m).ok());
    let mut q = [0.3, -1.9, -1.0];
    (0..STEPS_PER_CYCLE)
        .map(|i| {
            let t = i as f64 * PERIOD_S;
            let (stage, activity, pose, swing_rad) = cycle_pose(t);
            let mut reached = false;
            if let Some(kin) = &kin {
                let target = BucketPose {
                    x_m: pose[0],
                    z_m: pose[1],
                    bucket_abs_rad: pose[2],
                };
                if let Ok(sol) = kin.inverse(&target) {
                    q = [sol.boom_rad, sol.stick_rad, sol.bucket_rad];
                    reached = true;
                }
            }
            Sample {
                q,
                reached,
                swing_rad,
                stage,
                activity,
            }
        })
        .collect()
}

impl SyntheticTrace {
    /// A trace with `cfg`.
    pub fn new(cfg: SynthConfig) -> Self {
        let rng = cfg.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        Self {
            cfg,
            cycle: cycle_table(),
            produced: 0,
            step: 0,
            pending: Vec::with_capacity(20),
            next_pending: 0,
            rng,
            heartbeat: ControllerHeartbeat {
                mode: RequestedMode::ArmValve,
                alive_counter: 0,
            },
            gateway_alive: 0,
            status_alive: 0,
            sealer: {
                let mut sealer = Sealer::new(&SessionKey::PUBLIC);
                sealer.set_session(SYNTH_SESSION_ID);
                sealer
            },
            swept_m3: 0.0,
        }
    }

    fn jitter(&mut self) -> u64 {
        // xorshift64: deterministic, no dependency.
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        if self.cfg.jitter_ns == 0 {
            0
        } else {
            self.rng % self.cfg.jitter_ns
        }
    }

    fn sample(&self, step: u64) -> Sample {
        let n = self.cycle.len().max(1) as u64;
        self.cycle
            .get((step % n) as usize)
            .copied()
            .unwrap_or(Sample {
                q: [0.0; 3],
                reached: false,
                swing_rad: 0.0,
                stage: AutodigStageCode::None,
                activity: Activity::Idle,
            })
    }

    /// The messages of one control period, in schedule order.
    fn period_messages(&mut self, step: u64) -> Vec<Message> {
        let now = self.sample(step);
        let prev = self.sample(step.saturating_sub(1));
        let rate = |i: usize| (now.q[i] - prev.q[i]) / PERIOD_S;
        let swing_rate = (now.swing_rad - prev.swing_rad) / PERIOD_S;
        // Cylinder extension raises the boom and lowers stick and bucket angles (ARCHITECTURE.md).
        let cmds = [
            (rate(0) / 0.6).clamp(-1.0, 1.0),
            (-rate(1) / 0.6).clamp(-1.0, 1.0),
            (-rate(2) / 1.0).clamp(-1.0, 1.0),
            (swing_rate / 1.2).clamp(-1.0, 1.0),
        ];
        let digging = matches!(
            now.stage,
            AutodigStageCode::PreDig | AutodigStageCode::Dig | AutodigStageCode::Capture
        );
        let load_pa = if digging { 18e6 } else { 4e6 };
        let mut out = Vec::with_capacity(20);
        let mut push = |m: Message| {
            if due(m.descriptor(), step) {
                out.push(m);
            }
        };
        for (valve, cmd) in [Valve::Boom, Valve::Stick, Valve::Bucket, Valve::Swing]
            .into_iter()
            .zip(cmds)
        {
            if let Ok(c) = AuxValveCommand::from_fraction(valve, cmd) {
                push(Message::AuxValveCommand(c));
            }
        }
        for track in [Valve::LeftTrack, Valve::RightTrack] {
            push(Message::AuxValveCommand(AuxValveCommand::neutral(track)));
        }
        push(Message::PositionSetpoint(PositionSetpoint {
            boom_rad: now.q[0],
            stick_rad: now.q[1],
            bucket_rad: now.q[2],
            swing_rad: now.swing_rad,
        }));
        if due(&dbc::controller_heartbeat::MESSAGE, step) {
            push(Message::ControllerHeartbeat(self.heartbeat));
            self.heartbeat = self.heartbeat.next(RequestedMode::ArmValve);
        }
        push(Message::JointAngles(JointAngles {
            boom_rad: now.q[0],
            stick_rad: now.q[1],
            bucket_rad: now.q[2],
            swing_rad: now.swing_rad,
        }));
        push(Message::JointRates(JointRates {
            boom_rad_per_s: rate(0).clamp(-30.0, 30.0),
            stick_rad_per_s: rate(1).clamp(-30.0, 30.0),
            bucket_rad_per_s: rate(2).clamp(-30.0, 30.0),
            swing_rad_per_s: swing_rate.clamp(-30.0, 30.0),
        }));
        let mut max_pa: f64 = 0.0;
        for (i, cylinder) in Cylinder::ALL.into_iter().enumerate() {
            let cmd = cmds[i];
            let state = if cmd > 0.0 {
                ValveState::Extend
            } else if cmd < 0.0 {
                ValveState::Retract
            } else {
                ValveState::Block
            };
            let head = (load_pa * (1.0 + 0.2 * i as f64) + 2e6 * cmd.max(0.0)).min(34e6);
            let rod = (1.5e6 + 3e6 * (-cmd).max(0.0)).min(34e6);
            max_pa = max_pa.max(head).max(rod);
            push(Message::AuxValveMeasured(AuxValveMeasured {
                cylinder,
                flow_percent: (cmd.abs() * 100.0).min(100.0),
                state,
                head_pressure_pa: head,
                rod_pressure_pa: rod,
            }));
        }
        push(Message::PumpPressures(PumpPressures {
            pump1_pa: (max_pa + 1e6).min(60e6),
            pump2_pa: (max_pa + 0.5e6).min(60e6),
        }));
        push(Message::TrackOdometry(TrackOdometry {
            left_m: 0.0,
            right_m: 0.0,
        }));
        if due(&dbc::gateway_status::MESSAGE, step) {
            push(Message::GatewayStatus(GatewayStatus {
                mode: GatewayMode::ArmedValve,
                faults: GatewayFaults(0),
                alive_counter: self.gateway_alive,
                unexpected_frames: 0,
                rejected_frames: 0,
            }));
            self.gateway_alive = self.gateway_alive.wrapping_add(1);
        }
        push(Message::GatewaySession(GatewaySession {
            session_id: SYNTH_SESSION_ID,
        }));
        if now.stage == AutodigStageCode::Dig {
            self.swept_m3 = (self.swept_m3 + 1.2 / 350.0).min(6.0);
        } else if now.stage == AutodigStageCode::BoomDown {
            self.swept_m3 = 0.0;
        }
        if due(&dbc::controller_status::MESSAGE, step) {
            let dig_index = (step / STEPS_PER_CYCLE as u64 + 1).min(64_255) as u16;
            push(Message::ControllerStatus(ControllerStatus {
                activity: now.activity,
                stage: now.stage,
                dig_index,
                hardness_index: 3.0,
                swept_volume_m3: self.swept_m3,
                fault_reason: 0,
                alive_counter: self.status_alive,
            }));
            self.status_alive = (self.status_alive + 1) % 16;
        }
        push(Message::Dm1(Dm1Reporter::new(&CONTROLLER_DTCS).current()));
        out
    }

    fn refill(&mut self) {
        self.pending.clear();
        self.next_pending = 0;
        let step = self.step;
        self.step += 1;
        let base = self
            .cfg
            .start_ns
            .saturating_add(step.saturating_mul((PERIOD_S * 1e9) as u64));
        let messages = self.period_messages(step);
        let mut frames: Vec<CanFrame> = messages
            .iter()
            .filter_map(|msg| self.sealer.seal(msg).ok())
            .collect();
        if due(&dbc::dm1_gateway::MESSAGE, step)
            && let Ok(frame) =
                Message::Dm1(Dm1Reporter::new(&GATEWAY_DTCS).current()).encode_from(GATEWAY_ADDRESS)
        {
            frames.push(frame);
        }
        for (i, frame) in frames.into_iter().enumerate() {
            let t = base + i as u64 * FRAME_SPACING_NS + self.jitter();
            self.pending.push((t, frame));
        }
    }
}

impl Iterator for SyntheticTrace {
    type Item = (u64, CanFrame);

    fn next(&mut self) -> Option<Self::Item> {
        if self.produced >= self.cfg.frames {
            return None;
        }
        while self.next_pending >= self.pending.len() {
            self.refill();
        }
        let item = self.pending.get(self.next_pending).copied();
        self.next_pending += 1;
        self.produced += 1;
        item
    }
}

/// Writes a synthetic trace as `candump -L` lines; returns the number of frames written.
///
/// # Errors
/// Write errors.
pub fn write_candump(out: &mut dyn Write, cfg: &SynthConfig) -> io::Result<u64> {
    let mut n = 0;
    for (t, frame) in SyntheticTrace::new(cfg.clone()) {
        let line = trace::format_line(t, &cfg.interface, &frame, None);
        out.write_all(line.as_bytes())?;
        out.write_all(b"\n")?;
        n += 1;
    }
    out.flush()?;
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_schedule_rate() {
        use firmware_bridge::busload::SCHEDULE;
        let total_hz: f64 = SCHEDULE.iter().map(|e| e.rate_hz).sum();
        assert!((total_hz - 1192.0).abs() < 1e-9, "{total_hz}");
        // 10 s of the schedule.
        let n = (10.0 * total_hz) as u64;
        let frames: Vec<_> = SyntheticTrace::new(SynthConfig {
            frames: n,
            ..SynthConfig::default()
        })
        .collect();
        assert_eq!(frames.len() as u64, n);
        let span_s = (frames[frames.len() - 1].0 - frames[0].0) as f64 * 1e-9;
        assert!((span_s - 10.0).abs() < 0.02, "{span_s}");
        assert!(frames.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(frames.iter().all(|(_, f)| Message::decode(f).is_ok()));
        // Every periodic message of the DBC at its rate, each from its sender.
        for entry in SCHEDULE {
            let desc = dbc::MESSAGES
                .iter()
                .find(|m| m.name == entry.message)
                .unwrap();
            let count = frames
                .iter()
                .filter(|(_, f)| f.id().raw() == desc.default_id)
                .count() as f64;
            assert!(
                (count - 10.0 * entry.rate_hz).abs() <= 1.0,
                "{}: {count} frames in 10 s, schedule {} Hz",
                entry.message,
                entry.rate_hz
            );
        }
    }

    #[test]
    fn the_dig_reaches_its_poses() {
        let table = cycle_table();
        let reached = table.iter().filter(|s| s.reached).count();
        assert_eq!(reached, table.len(), "poses out of reach");
        let kin = Kinematics::new(&MachineConfig::default_machine().unwrap()).unwrap();
        // The deepest point of the cycle is below the ground the tracks stand on.
        let min_z = table
            .iter()
            .map(|s| {
                kin.forward(&planner::kinematics::JointAngles {
                    boom_rad: s.q[0],
                    stick_rad: s.q[1],
                    bucket_rad: s.q[2],
                })
                .z_m
            })
            .fold(f64::INFINITY, f64::min);
        assert!(min_z < -0.3, "{min_z}");
    }
}
