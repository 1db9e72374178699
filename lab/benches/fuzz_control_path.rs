//! Bounded-time fuzz of the control path: the frame decoder, the trace reader, the gateway core and
//! the controller node, fed random and mutated frames (seeded, reproducible). Prints frames tried,
//! frames per second, panics and forbidden outputs; exits non-zero if either count is not zero.
//!
//! Forbidden outputs: a gateway valve output that the authenticated controller did not command (the
//! gateway holds a provisioned key; the legitimate sender commands the boom at 0.5 and nothing else),
//! a non-finite or out-of-range valve output, and a controller frame that does not decode.
//!
//! Run: `cargo bench -p lab --bench fuzz_control_path -- --seconds 120 [--seed N] [--frames N]`.

#![allow(clippy::unwrap_used)] // setup of fixed, valid fixtures

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::{Duration, Instant};

use controller::{ControllerConfig, ControllerNode};
use firmware_bridge::gateway::{Gateway, VALVES};
use firmware_bridge::messages::{
    AuxValveCommand, ControllerHeartbeat, GatewayMode, JointAngles, RequestedMode, Valve,
};
use firmware_bridge::secoc::{Sealer, SeededNonceSource, SessionKey};
use firmware_bridge::trace::{self, ReadMode, TraceReader};
use firmware_bridge::{CanFrame, CanId, Message, TimestampedFrame};
use planner::autodig::AutodigMaps;

/// The legitimate controller's boom command.
const LEGIT_BOOM: f64 = 0.5;
const KEY_HEX: &str = "2b7e151628aed2a6abf7158809cf4f3c";
/// Fuzz frames per simulated millisecond (one gateway tick).
const FRAMES_PER_TICK: u64 = 8;

const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// SplitMix64: a seeded generator with no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// One fuzz frame: random (any kind), a mutation or a verbatim replay of a recorded legitimate frame.
fn fuzz_frame(rng: &mut Rng, recorded: &[CanFrame]) -> CanFrame {
    let r = rng.next();
    let mut data = [0u8; 64];
    for chunk in data.chunks_mut(8) {
        chunk.copy_from_slice(&rng.next().to_le_bytes());
    }
    let len = (r >> 8) as usize % 9;
    match r % 8 {
        0 => CanFrame::new_standard((r >> 16) as u16 & 0x7FF, &data[..len]).unwrap(),
        1 => CanFrame::new_remote(CanId::Extended((r >> 20) as u32 & 0x1FFF_FFFF), len as u8)
            .unwrap_or_else(|_| CanFrame::new_standard(1, &[]).unwrap()),
        2 => CanFrame::new_error((r >> 16) as u32 & 0x1FFF_FFFF, [data[0]; 8])
            .unwrap_or_else(|_| CanFrame::new_standard(2, &[]).unwrap()),
        3 => CanFrame::new_fd(
            CanId::Extended((r >> 20) as u32 & 0x1FFF_FFFF),
            &data[..FD_LENGTHS[(r >> 12) as usize % FD_LENGTHS.len()]],
            (r >> 40) as u8,
        )
        .unwrap_or_else(|_| CanFrame::new_standard(3, &[]).unwrap()),
        4 => CanFrame::new_extended((r >> 20) as u32 & 0x1FFF_FFFF, &data[..len]).unwrap(),
        // A recorded controller or gateway frame replayed as it was.
        5 => recorded[rng.below(recorded.len() as u64) as usize],
        // A recorded frame with bits flipped in its data or its source address changed.
        _ => {
            let base = recorded[rng.below(recorded.len() as u64) as usize];
            let mut d = [0u8; 8];
            d[..base.data().len()].copy_from_slice(base.data());
            for _ in 0..1 + rng.below(3) {
                let bit = rng.below(64);
                d[(bit / 8) as usize] ^= 1 << (bit % 8);
            }
            let id = base.id().raw()
                ^ if r.is_multiple_of(3) {
                    (r >> 32) as u32 & 0xFF
                } else {
                    0
                };
            CanFrame::new_extended(id & 0x1FFF_FFFF, &d[..base.data().len()]).unwrap()
        }
    }
}

/// The legitimate controller: arms with its key in the gateway's session and drives the boom.
struct Legit {
    sealer: Sealer,
    key: SessionKey,
    alive: u8,
}

impl Legit {
    fn hb(&mut self, g: &Gateway, mode: RequestedMode) -> CanFrame {
        if self.sealer.set_session(g.session().session_id) {
            self.sealer = Sealer::new(&self.key);
            self.sealer.set_session(g.session().session_id);
        }
        self.alive = (self.alive + 1) % 16;
        let hb = ControllerHeartbeat {
            mode,
            alive_counter: self.alive,
        };
        self.sealer.seal(&Message::ControllerHeartbeat(hb)).unwrap()
    }
    fn boom(&mut self) -> CanFrame {
        let cmd = AuxValveCommand::from_fraction(Valve::Boom, LEGIT_BOOM).unwrap();
        self.sealer.seal(&Message::AuxValveCommand(cmd)).unwrap()
    }
}

#[derive(Default)]
struct Counts {
    frames: u64,
    panics: u64,
    forbidden: u64,
    gateway_armed_ticks: u64,
    trace_lines: u64,
}

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let seconds: f64 = arg("--seconds")
        .and_then(|s| s.parse().ok())
        .unwrap_or(120.0);
    let max_frames: u64 = arg("--frames")
        .and_then(|s| s.parse().ok())
        .unwrap_or(u64::MAX);
    let seed: u64 = arg("--seed")
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x5EC_F022);
    let seconds = if seconds.is_finite() {
        seconds.clamp(0.1, 3600.0)
    } else {
        120.0
    };
    let mut rng = Rng(seed);
    let key = SessionKey::from_hex(KEY_HEX).unwrap();
    let machine = planner::machine::MachineConfig::default_machine().unwrap();
    let new_node = || {
        ControllerNode::new(
            &machine,
            AutodigMaps::builtin().unwrap(),
            ControllerConfig::default(),
        )
        .unwrap()
    };
    let mut node = new_node();
    let mut gateway =
        Gateway::with_default_config(&mut SeededNonceSource(seed)).with_security(&key, seed);
    let mut legit = Legit {
        sealer: Sealer::new(&key),
        key: key.clone(),
        alive: 0,
    };
    // Recorded legitimate traffic to replay and mutate: controller frames of a session and gateway
    // sensor frames.
    let mut recorded: Vec<CanFrame> = Vec::new();
    {
        let g = Gateway::with_default_config(&mut SeededNonceSource(seed ^ 1))
            .with_security(&key, seed ^ 1);
        let mut l = Legit {
            sealer: Sealer::new(&key),
            key: key.clone(),
            alive: 0,
        };
        for _ in 0..64 {
            recorded.push(l.hb(&g, RequestedMode::ArmValve));
            recorded.push(l.boom());
        }
        let angles = Message::JointAngles(JointAngles {
            boom_rad: 0.3,
            stick_rad: -1.5,
            bucket_rad: -1.0,
            swing_rad: 0.0,
        });
        recorded.push(angles.encode().unwrap());
        recorded.push(Message::GatewayStatus(gateway.status()).encode().unwrap());
        recorded.push(Message::GatewaySession(gateway.session()).encode().unwrap());
    }
    let mut counts = Counts::default();
    let mut batch: Vec<TimestampedFrame> = Vec::with_capacity(64);
    let start = Instant::now();
    let budget = Duration::from_secs_f64(seconds);
    let mut tick: u64 = 0;
    while counts.frames < max_frames && (!tick.is_multiple_of(1024) || start.elapsed() < budget) {
        let now_s = tick as f64 * 1e-3;
        // The legitimate controller: heartbeat every 50 ms, boom every 10 ms; re-handshake on faults.
        if tick.is_multiple_of(50) {
            let mode = match gateway.mode() {
                GatewayMode::Faulted => RequestedMode::Disarm,
                _ => RequestedMode::ArmValve,
            };
            let frame = legit.hb(&gateway, mode);
            gateway.on_frame(&frame, now_s);
        }
        if tick.is_multiple_of(10) && gateway.mode() == GatewayMode::ArmedValve {
            let frame = legit.boom();
            gateway.on_frame(&frame, now_s);
        }
        for _ in 0..FRAMES_PER_TICK {
            let frame = fuzz_frame(&mut rng, &recorded);
            counts.frames += 1;
            let outcome = catch_unwind(AssertUnwindSafe(|| {
                let _ = Message::decode(&frame);
                gateway.on_frame(&frame, now_s);
                // The trace writer and reader: the frame's line, sometimes with a byte changed.
                if let Ok(line) = trace::try_format_line(tick * 1_000_000, "vcan0", &frame, None) {
                    let mut bytes = line.into_bytes();
                    if rng.below(2) == 0 && !bytes.is_empty() {
                        let i = rng.below(bytes.len() as u64) as usize;
                        bytes[i] = rng.next() as u8;
                    }
                    let reader = TraceReader::new(&bytes[..], ReadMode::Skip);
                    counts.trace_lines += reader.count() as u64;
                }
            }));
            if outcome.is_err() {
                counts.panics += 1;
            }
            batch.push(TimestampedFrame {
                timestamp_ns: tick * 1_000_000,
                frame,
            });
        }
        let out = catch_unwind(AssertUnwindSafe(|| {
            gateway.tick(now_s, Some([0.3, -1.5, -1.0, 0.0]))
        }));
        match out {
            Ok(out) => {
                for (i, u) in out.valve_commands.iter().enumerate() {
                    let legit_value = (i == 0 && (*u - LEGIT_BOOM).abs() < 1e-3) || *u == 0.0;
                    if !u.is_finite() || !legit_value {
                        counts.forbidden += 1;
                    }
                }
                if out.valve_commands != [0.0; VALVES] {
                    counts.gateway_armed_ticks += 1;
                }
            }
            Err(_) => counts.panics += 1,
        }
        // The controller node every 10 ms with the fuzz frames of the period.
        if tick % 10 == 9 {
            let sent = catch_unwind(AssertUnwindSafe(|| {
                node.step(now_s, &batch).as_slice().to_vec()
            }));
            match sent {
                Ok(frames) => {
                    counts.forbidden += frames
                        .iter()
                        .filter(|f| Message::decode(f).is_err())
                        .count() as u64;
                }
                Err(_) => {
                    counts.panics += 1;
                    node = new_node();
                }
            }
            batch.clear();
        }
        tick += 1;
    }
    let elapsed = start.elapsed().as_secs_f64();
    println!(
        "fuzz control path (seed {seed}): {} frames tried in {:.1} s ({:.0} frames/s), {} trace lines read back, {} simulated s, gateway driving the legitimate boom in {} ticks; panics {}, forbidden outputs {}",
        counts.frames,
        elapsed,
        counts.frames as f64 / elapsed,
        counts.trace_lines,
        tick / 1000,
        counts.gateway_armed_ticks,
        counts.panics,
        counts.forbidden
    );
    if counts.panics > 0 || counts.forbidden > 0 {
        std::process::exit(1);
    }
}
