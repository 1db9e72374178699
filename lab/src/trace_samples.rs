//! The state of the bus at each resolver sample of a session's `trace.log`: the one reading of a trace
//! that the actuator networks' training data (`model::training_data`) and the discrepancy workflow's
//! records (`discrepancy::read`) share.
//!
//! A sample is taken at every `JointAngles` frame, at its session time ([`crate::demo::trace_time_base`]:
//! the time of the scans), and completed with every frame up to the next `JointAngles`: the rates,
//! pressures and commands the controller sent in answer to those angles belong to it. A cut-short last
//! line ends the trace with a warning ([`trace_tools::input::records_until_cut`]); frames that do not
//! decode as the project's messages are skipped.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::Context as _;
use firmware_bridge::messages::{ControllerStatus, GatewayMode, Message};
use firmware_bridge::trace::{ReadMode, TraceReader};

/// The bus at one resolver sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusSample {
    /// Session time of the `JointAngles` frame, s.
    pub time_s: f64,
    /// Sensed joint angles `[boom, stick, bucket, swing]`, rad.
    pub angles_rad: [f64; 4],
    /// The latest sampled joint rates `[boom, stick, bucket, swing]`, rad/s (`None` before the first
    /// `JointRates`).
    pub rates_rad_per_s: Option<[f64; 4]>,
    /// The latest head-side pressures `[boom, stick, bucket]`, Pa (0 before the first reading).
    pub head_pa: [f64; 3],
    /// The latest rod-side pressures `[boom, stick, bucket]`, Pa.
    pub rod_pa: [f64; 3],
    /// The latest pump gallery pressures `[pump 1, pump 2]`, Pa (0 in traces without
    /// `PumpPressures`).
    pub pump_pa: [f64; 2],
    /// The latest valve commands `[boom, stick, bucket, swing]`, fractions of full spool travel.
    pub command: [f64; 4],
    /// The latest `ControllerStatus` (`None` before the first).
    pub status: Option<ControllerStatus>,
    /// Session time the gateway was last seen in its closed-loop position mode when the angles came
    /// (a `PositionSetpoint`, or a `GatewayStatus` in `ArmedPosition`), s; minus infinity before.
    pub position_mode_at_s: f64,
}

/// What a trace reader does with the trace: every decoded message as it comes, and every sample once
/// it is complete.
pub trait SampleSink {
    /// A decoded message at session time `time_s`, after it updated the samples' state.
    fn message(&mut self, _time_s: f64, _message: &Message) {}
    /// A complete sample, before the `JointAngles` frame that starts the next one (or at the end).
    fn sample(&mut self, sample: &BusSample);
}

/// Reads `path` into `sink` (module docs).
///
/// # Errors
/// Opening or reading the file, its time base.
pub fn read_samples(path: &Path, sink: &mut impl SampleSink) -> anyhow::Result<()> {
    let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let reader = TraceReader::new(BufReader::new(file), ReadMode::Skip);
    let mut time_base = crate::demo::trace_time_base(path)?;
    let mut state = BusSample {
        time_s: 0.0,
        angles_rad: [0.0; 4],
        rates_rad_per_s: None,
        head_pa: [0.0; 3],
        rod_pa: [0.0; 3],
        pump_pa: [0.0; 2],
        command: [0.0; 4],
        status: None,
        position_mode_at_s: f64::NEG_INFINITY,
    };
    // The sample's time, angles and position-mode time; the rest is `state` when it is complete.
    let mut pending: Option<(f64, [f64; 4], f64)> = None;
    let complete = |pending: (f64, [f64; 4], f64), state: &BusSample| BusSample {
        time_s: pending.0,
        angles_rad: pending.1,
        position_mode_at_s: pending.2,
        ..*state
    };
    for record in trace_tools::input::records_until_cut(path, reader) {
        let record = record.with_context(|| format!("reading {}", path.display()))?;
        let t = time_base.session_s(record.timestamp_ns);
        let Ok(decoded) = Message::decode(&record.frame) else {
            continue;
        };
        let message = decoded.message;
        match &message {
            Message::JointAngles(a) => {
                if let Some(p) = pending.take() {
                    sink.sample(&complete(p, &state));
                }
                let angles = [a.boom_rad, a.stick_rad, a.bucket_rad, a.swing_rad];
                pending = Some((t, angles, state.position_mode_at_s));
            }
            Message::JointRates(r) => {
                state.rates_rad_per_s = Some([
                    r.boom_rad_per_s,
                    r.stick_rad_per_s,
                    r.bucket_rad_per_s,
                    r.swing_rad_per_s,
                ]);
            }
            Message::AuxValveMeasured(m) => {
                let i = usize::from(m.cylinder.number());
                if i < 3 {
                    state.head_pa[i] = m.head_pressure_pa;
                    state.rod_pa[i] = m.rod_pressure_pa;
                }
            }
            Message::PumpPressures(p) => state.pump_pa = [p.pump1_pa, p.pump2_pa],
            Message::AuxValveCommand(c) => {
                let i = usize::from(c.valve.number());
                if i < 4 {
                    state.command[i] = c.to_fraction();
                }
            }
            Message::PositionSetpoint(_) => state.position_mode_at_s = t,
            Message::GatewayStatus(g) if g.mode == GatewayMode::ArmedPosition => {
                state.position_mode_at_s = t;
            }
            Message::ControllerStatus(s) => state.status = Some(*s),
            _ => {}
        }
        sink.message(t, &message);
    }
    if let Some(p) = pending {
        sink.sample(&complete(p, &state));
    }
    Ok(())
}
