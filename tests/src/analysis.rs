//! What a recorded session shows. The same functions read a `candump -L` log of a vcan run and the
//! recording of an in-process run, so both kinds of test check the same things.

use std::path::Path;

use firmware_bridge::messages::{
    Activity, ControllerHeartbeat, ControllerStatus, GatewayStatus, JointAngles, Message,
    ValveState,
};
use firmware_bridge::{CONTROLLER_ADDRESS, CanFrame, GATEWAY_ADDRESS};
use serde::Deserialize;

/// One recorded frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rec {
    /// Time, s (wall clock for candump, simulation time in-process).
    pub t_s: f64,
    /// The frame.
    pub frame: CanFrame,
}

/// Reads a `candump -L` log. Lines that do not parse are counted, not fatal (a killed candump may
/// leave half a line).
///
/// # Panics
/// When the file cannot be read.
pub fn read_candump(path: &Path) -> (Vec<Rec>, usize) {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let mut recs = Vec::new();
    let mut bad = 0;
    for line in text.lines() {
        match firmware_bridge::trace::parse_line(line) {
            Ok(r) => recs.push(Rec {
                t_s: r.timestamp_ns as f64 * 1e-9,
                frame: r.frame,
            }),
            Err(_) => bad += 1,
        }
    }
    (recs, bad)
}

/// Decoded messages from source address `sa`, with their times.
pub fn messages_from(recs: &[Rec], sa: u8) -> impl Iterator<Item = (f64, Message)> + '_ {
    recs.iter()
        .filter_map(move |r| match Message::decode(&r.frame) {
            Ok(d) if d.id.source_address() == sa => Some((r.t_s, d.message)),
            _ => None,
        })
}

/// The controller's `ControllerStatus` frames.
pub fn controller_statuses(recs: &[Rec]) -> Vec<(f64, ControllerStatus)> {
    messages_from(recs, CONTROLLER_ADDRESS)
        .filter_map(|(t, m)| match m {
            Message::ControllerStatus(s) => Some((t, s)),
            _ => None,
        })
        .collect()
}

/// The controller's heartbeats.
pub fn heartbeats(recs: &[Rec]) -> Vec<(f64, ControllerHeartbeat)> {
    messages_from(recs, CONTROLLER_ADDRESS)
        .filter_map(|(t, m)| match m {
            Message::ControllerHeartbeat(h) => Some((t, h)),
            _ => None,
        })
        .collect()
}

/// The gateway's `GatewayStatus` frames.
pub fn gateway_statuses(recs: &[Rec]) -> Vec<(f64, GatewayStatus)> {
    messages_from(recs, GATEWAY_ADDRESS)
        .filter_map(|(t, m)| match m {
            Message::GatewayStatus(s) => Some((t, s)),
            _ => None,
        })
        .collect()
}

/// The gateway's `JointAngles` as `[boom, stick, bucket, swing]`.
pub fn joint_angles(recs: &[Rec]) -> Vec<(f64, [f64; 4])> {
    messages_from(recs, GATEWAY_ADDRESS)
        .filter_map(|(t, m)| match m {
            Message::JointAngles(JointAngles {
                boom_rad,
                stick_rad,
                bucket_rad,
                swing_rad,
            }) => Some((t, [boom_rad, stick_rad, bucket_rad, swing_rad])),
            _ => None,
        })
        .collect()
}

/// Times of the gateway's valve measurements (100 Hz) in `from_s..=to_s` that show a valve passing
/// flow (a state other than Block): a driven valve.
pub fn driven_valves(recs: &[Rec], from_s: f64, to_s: f64) -> Vec<f64> {
    messages_from(recs, GATEWAY_ADDRESS)
        .filter_map(|(t, m)| match m {
            Message::AuxValveMeasured(v)
                if t >= from_s && t <= to_s && v.state != ValveState::Block =>
            {
                Some(t)
            }
            _ => None,
        })
        .collect()
}

/// The largest motion of any joint over `angles`, rad.
pub fn largest_motion_rad(angles: &[(f64, [f64; 4])]) -> f64 {
    (0..4)
        .map(|j| {
            let (lo, hi) = angles
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, q)| {
                    (lo.min(q[j]), hi.max(q[j]))
                });
            hi - lo
        })
        .fold(0.0, f64::max)
}

/// The activity sequence with consecutive repeats collapsed.
pub fn activity_sequence(statuses: &[(f64, ControllerStatus)]) -> Vec<Activity> {
    let mut seq: Vec<Activity> = Vec::new();
    for (_, s) in statuses {
        if seq.last() != Some(&s.activity) {
            seq.push(s.activity);
        }
    }
    seq
}

/// Complete work cycles found in an activity sequence.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Cycles {
    /// Dig, swing to dump, dump, return (swing to the next dig, or home).
    pub digs: usize,
    /// Cleanup (with its Autodig hand-over), swing to dump, dump, return.
    pub cleanups: usize,
    /// Of these, cycles whose return was the final `Return` home.
    pub returns_home: usize,
}

/// Counts complete cycles: `Dig | Cleanup [-> Dig]`, then `SwingToDump`, `Dump`, then `SwingToDig` or
/// `Return`. Idle (weighing, between actions), Scan and Faulted (a pause that re-arms and resumes) do
/// not break a cycle; tracking does.
pub fn count_cycles(sequence: &[Activity]) -> Cycles {
    #[derive(Clone, Copy, PartialEq)]
    enum Step {
        None,
        Working(bool),
        Swung(bool),
        Dumped(bool),
    }
    let mut cycles = Cycles::default();
    let mut step = Step::None;
    for a in sequence {
        step = match (*a, step) {
            (Activity::Idle | Activity::Paused | Activity::Scan | Activity::Faulted, s) => s,
            (Activity::Dig, Step::Working(true)) => Step::Working(true),
            (Activity::Dig, _) => Step::Working(false),
            (Activity::Cleanup, _) => Step::Working(true),
            (Activity::SwingToDump, Step::Working(c) | Step::Swung(c)) => Step::Swung(c),
            (Activity::Dump, Step::Swung(c) | Step::Dumped(c)) => Step::Dumped(c),
            (Activity::SwingToDig | Activity::Return, Step::Dumped(cleanup)) => {
                if cleanup {
                    cycles.cleanups += 1;
                } else {
                    cycles.digs += 1;
                }
                if *a == Activity::Return {
                    cycles.returns_home += 1;
                }
                Step::None
            }
            _ => Step::None,
        };
    }
    cycles
}

/// One line of `excavator-sim --state-log` (the fields these tests use).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct StateSample {
    /// Simulation time, s.
    pub time_s: f64,
    /// `[boom, stick, bucket, swing]`, rad.
    pub angles_rad: [f64; 4],
    /// Their rates, rad/s.
    pub rates_rad_per_s: [f64; 4],
}

/// Reads a state log; a truncated last line (the simulator was stopped) is ignored.
///
/// # Panics
/// When the file cannot be read or a line other than the last does not parse.
pub fn read_state_log(path: &Path) -> Vec<StateSample> {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        match serde_json::from_str::<StateSample>(line) {
            Ok(s) => out.push(s),
            Err(e) if i + 1 == lines.len() => eprintln!("state log: last line ignored: {e}"),
            Err(e) => panic!("{}:{}: {e}", path.display(), i + 1),
        }
    }
    out
}

/// Resolution of the angles on the wire and in the resolver, rad: half the 14-bit resolver step
/// (2 pi / 16384) plus half the JointAngles LSB (1e-4 rad).
pub const ANGLE_RESOLUTION_RAD: f64 = std::f64::consts::PI / 16384.0 + 0.5e-4;
/// Resolver noise allowance, rad: five standard deviations of the simulator's 2e-4 rad.
pub const ANGLE_NOISE_RAD: f64 = 5.0 * 2e-4;
/// Step of the search within the alignment window, s.
const ALIGN_STEP_S: f64 = 0.001;

/// One sample outside the tolerance: time (s), decoded angles, true angles and allowed error (rad),
/// joints `[boom, stick, bucket, swing]`.
pub type AngleOutlier = (f64, [f64; 4], [f64; 4], [f64; 4]);

/// A candidate alignment of one decoded sample: true angles, error, tolerance (rad) and the excess of
/// the error over the tolerance.
type AlignedMatch = ([f64; 4], [f64; 4], [f64; 4], f64);

/// How decoded angles compare with the simulator's truth.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleComparison {
    /// Decoded samples compared.
    pub compared: usize,
    /// Samples sent in a catch-up burst (the simulator stepped several periods at once after a late
    /// wake-up, so their timestamps are not their simulation times; the alignment window covers them).
    pub burst: usize,
    /// Samples outside the tolerance.
    pub outside: Vec<AngleOutlier>,
    /// `wall - simulation` time offset per segment, s.
    pub offsets_s: Vec<f64>,
    /// Largest error per joint among the compared samples, rad.
    pub max_error_rad: [f64; 4],
    /// Largest error among samples taken while the joint moved slower than 0.01 rad/s, rad (where the
    /// alignment does not matter: resolution and noise only).
    pub max_error_still_rad: f64,
    /// 99th percentile of the per-sample largest joint error, rad.
    pub p99_error_rad: f64,
}

fn interpolate(truth: &[StateSample], t: f64) -> Option<([f64; 4], [f64; 4], f64)> {
    let i = truth.partition_point(|s| s.time_s < t);
    if i == 0 || i >= truth.len() {
        return None;
    }
    let (a, b) = (&truth[i - 1], &truth[i]);
    let dt = b.time_s - a.time_s;
    if dt.is_nan() || dt <= 0.0 || dt > 2.5 {
        return None;
    }
    let w = (t - a.time_s) / dt;
    let q = std::array::from_fn(|j| a.angles_rad[j] + w * (b.angles_rad[j] - a.angles_rad[j]));
    // The state log is written once per loop wake-up, so two lines may be several periods apart: the
    // interpolation itself is uncertain by up to the rate times half the gap.
    let r = std::array::from_fn(|j| a.rates_rad_per_s[j].abs().max(b.rates_rad_per_s[j].abs()));
    Some((q, r, 0.5 * dt))
}

/// Mean absolute error (all joints) of `samples` against the truth at `t - offset`.
fn alignment_cost(samples: &[(f64, [f64; 4])], truth: &[StateSample], offset: f64) -> f64 {
    let mut sum = 0.0;
    let mut n = 0usize;
    for (t, q) in samples {
        if let Some((truth_q, _, _)) = interpolate(truth, t - offset) {
            sum += (0..4).map(|j| (q[j] - truth_q[j]).abs()).sum::<f64>();
            n += 1;
        }
    }
    if n * 2 < samples.len() || n == 0 {
        f64::INFINITY
    } else {
        sum / n as f64
    }
}

/// The offset in `[center - half, center + half]` (grid `step`) that aligns `samples` best.
fn best_offset(
    samples: &[(f64, [f64; 4])],
    truth: &[StateSample],
    center: f64,
    half: f64,
    step: f64,
) -> f64 {
    let n = (2.0 * half / step).round() as i64;
    let mut best = (f64::INFINITY, center);
    for k in 0..=n {
        let o = center - half + k as f64 * step;
        let c = alignment_cost(samples, truth, o);
        if c < best.0 {
            best = (c, o);
        }
    }
    best.1
}

/// Compares decoded `JointAngles` (`decoded`, wall or bus time) with the simulator's state log
/// (`truth`, simulation time). The time offset between the two clocks is estimated per `segment_s`
/// segment (it drifts when the simulator falls behind wall time), then every sample must match the
/// truth at some time within +/- `align_s` of its aligned time (the timestamp alignment tolerance)
/// to [`ANGLE_RESOLUTION_RAD`] + [`ANGLE_NOISE_RAD`] (+ the rate times half the gap between the two
/// state-log lines interpolated, which are one loop wake-up apart).
/// `initial_offset_s` is a first guess of `decoded time - simulation time` (e.g. the simulator's
/// start time), searched within +/- 2 s.
pub fn compare_angles(
    decoded: &[(f64, [f64; 4])],
    truth: &[StateSample],
    initial_offset_s: f64,
    segment_s: f64,
    align_s: f64,
) -> AngleComparison {
    let mut result = AngleComparison {
        compared: 0,
        burst: 0,
        outside: Vec::new(),
        offsets_s: Vec::new(),
        max_error_rad: [0.0; 4],
        max_error_still_rad: 0.0,
        p99_error_rad: 0.0,
    };
    let mut errors: Vec<f64> = Vec::with_capacity(decoded.len());
    if decoded.is_empty() || truth.is_empty() {
        return result;
    }
    // Frames closer than 3 ms to a neighbour were sent in a catch-up burst.
    let burst: Vec<bool> = (0..decoded.len())
        .map(|i| {
            let prev = i.checked_sub(1).map(|p| decoded[i].0 - decoded[p].0);
            let next = decoded.get(i + 1).map(|n| n.0 - decoded[i].0);
            prev.is_some_and(|d| d < 0.003) || next.is_some_and(|d| d < 0.003)
        })
        .collect();
    // Per segment: a wide coarse search on a subsample around the previous segment's offset (the
    // simulator only falls behind wall time, by up to seconds after long stalls), then a fine one.
    let t0 = decoded[0].0;
    let mut previous = initial_offset_s;
    let mut segments: Vec<(usize, usize, f64, bool)> = Vec::new();
    let mut start = 0;
    while start < decoded.len() {
        let end = decoded[start..]
            .iter()
            .position(|(t, _)| *t >= t0 + segment_s * (segments.len() + 1) as f64)
            .map_or(decoded.len(), |p| start + p);
        let seg: Vec<_> = (start..end)
            .filter(|&i| !burst[i])
            .map(|i| decoded[i])
            .collect();
        let (offset, flat) = if seg.len() >= 20 {
            let stride = (seg.len() / 100).max(1);
            let sub: Vec<_> = seg.iter().copied().step_by(stride).collect();
            let o = best_offset(&sub, truth, previous + 4.0, 5.0, 0.01);
            let o = best_offset(&seg, truth, o, 0.02, 0.001);
            let o = best_offset(&seg, truth, o, 0.001, 0.0001);
            // At rest every offset fits equally well.
            let flat =
                alignment_cost(&seg, truth, previous) - alignment_cost(&seg, truth, o) < 1e-4;
            (if flat { previous } else { o }, flat)
        } else {
            (previous, true)
        };
        previous = offset;
        segments.push((start, end, offset, flat));
        start = end;
    }
    // A segment at rest that ends where motion starts takes the next moving segment's offset.
    for k in (0..segments.len().saturating_sub(1)).rev() {
        if segments[k].3 && !segments[k + 1].3 {
            segments[k].2 = segments[k + 1].2;
            segments[k].3 = false;
        }
    }
    for (start, end, offset, _) in segments {
        result.offsets_s.push(offset);
        for i in start..end {
            if burst[i] {
                result.burst += 1;
            }
            let (t, q) = decoded[i];
            // The best match within the alignment window: the frame's sample time on the simulator's
            // clock is only known to within `align_s` (scheduling delays between sampling and the
            // kernel's timestamp).
            let mut best: Option<AlignedMatch> = None;
            let n = (align_s / ALIGN_STEP_S).round() as i64;
            for k in -n..=n {
                let Some((truth_q, rate, half_gap)) =
                    interpolate(truth, t - offset + k as f64 * ALIGN_STEP_S)
                else {
                    continue;
                };
                let err: [f64; 4] = std::array::from_fn(|j| (q[j] - truth_q[j]).abs());
                let excess = (0..4)
                    .map(|j| err[j] - rate[j] * half_gap)
                    .fold(f64::NEG_INFINITY, f64::max);
                if best.is_none_or(|b| excess < b.3) {
                    let tol = std::array::from_fn(|j| {
                        ANGLE_RESOLUTION_RAD + ANGLE_NOISE_RAD + rate[j] * half_gap
                    });
                    best = Some((truth_q, err, tol, excess));
                }
            }
            let Some((truth_q, err, tol, _)) = best else {
                continue;
            };
            result.compared += 1;
            let rate_at = interpolate(truth, t - offset).map_or([0.0; 4], |r| r.1);
            for j in 0..4 {
                result.max_error_rad[j] = result.max_error_rad[j].max(err[j]);
                if rate_at[j] < 0.01 {
                    result.max_error_still_rad = result.max_error_still_rad.max(err[j]);
                }
            }
            errors.push(err.iter().copied().fold(0.0, f64::max));
            if (0..4).any(|j| err[j] > tol[j]) {
                result.outside.push((t, q, truth_q, err));
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    if let Some(e) = errors.get(errors.len() * 99 / 100) {
        result.p99_error_rad = *e;
    }
    result
}

/// Joint angles from the text output of `excavator-ctl trace decode` or `cantools decode
/// --single-line` (both print `(time) iface ID#DATA :: JointAngles(BoomAngle: 0.5244 rad, ...)`).
/// Lines of other messages are skipped; a JointAngles line that does not parse is an error.
///
/// # Errors
/// The offending line.
pub fn decoded_joint_angles(text: &str) -> Result<Vec<(f64, [f64; 4])>, String> {
    const NAMES: [&str; 4] = ["BoomAngle", "StickAngle", "BucketAngle", "SwingAngle"];
    let mut out = Vec::new();
    for line in text.lines() {
        let Some((head, body)) = line.split_once(":: JointAngles(") else {
            continue;
        };
        let bad = || format!("cannot parse {line:?}");
        let t: f64 = head
            .trim_start()
            .strip_prefix('(')
            .and_then(|r| r.split_once(')'))
            .and_then(|(t, _)| t.parse().ok())
            .ok_or_else(bad)?;
        let mut q = [f64::NAN; 4];
        for field in body.trim_end().trim_end_matches(')').split(", ") {
            let (name, value) = field.split_once(": ").ok_or_else(bad)?;
            let value: f64 = value.trim_end_matches(" rad").parse().map_err(|_| bad())?;
            if let Some(j) = NAMES.iter().position(|n| *n == name) {
                q[j] = value;
            }
        }
        if q.iter().any(|v| v.is_nan()) {
            return Err(bad());
        }
        out.push((t, q));
    }
    Ok(out)
}

/// The simulator's sensor period, s: one resolver sample and one `JointAngles` frame per period
/// ([`firmware_bridge::dbc::SENSOR_PERIOD`], the DBC's cycle time).
pub const SENSOR_PERIOD_S: f64 = firmware_bridge::dbc::SENSOR_PERIOD.as_secs_f64();

/// Puts decoded `JointAngles` on the simulator's clock by their order: the simulator samples the
/// resolvers every [`SENSOR_PERIOD_S`] of simulation time and sends one frame per sample, so the
/// k-th frame captured is sample `k + d_k` with `d_k` the frames the capture lost before it
/// (non-decreasing). The wall-clock stamps are not used: a loaded host sends catch-up bursts
/// seconds late, and a capture writing to a slow file loses frames. `d_k` is chosen by dynamic
/// programming to minimise the summed absolute angle error against the state log, so the only
/// assumption is that frames keep their order; a decoder that is wrong stays wrong under every
/// order-preserving assignment. Frames outside the state log keep `d_k` of their neighbours.
pub fn on_simulation_clock(
    decoded: &[(f64, [f64; 4])],
    truth: &[StateSample],
) -> Vec<(f64, [f64; 4])> {
    let n = decoded.len();
    let samples = truth
        .last()
        .map_or(0, |s| (s.time_s / SENSOR_PERIOD_S).floor() as usize + 1);
    let max_lost = samples.saturating_sub(n);
    let error = |k: usize, d: usize| -> f64 {
        let t = (k + d) as f64 * SENSOR_PERIOD_S;
        interpolate(truth, t).map_or(0.0, |(q, _, _)| {
            (0..4).map(|j| (decoded[k].1[j] - q[j]).abs()).sum::<f64>()
        })
    };
    // cost[d]: the least summed error of frames 0..=k with frame k at sample k + d; from[k][d]: the
    // lost count of frame k-1 on that path.
    let mut cost: Vec<f64> = (0..=max_lost).map(|d| error(0, d)).collect();
    let mut from: Vec<Vec<u32>> = Vec::with_capacity(n);
    from.push((0..=max_lost as u32).collect());
    for k in 1..n {
        let mut best = (f64::INFINITY, 0u32);
        let mut next = Vec::with_capacity(max_lost + 1);
        let mut back = Vec::with_capacity(max_lost + 1);
        for (d, c) in cost.iter().enumerate() {
            if *c < best.0 {
                best = (*c, d as u32);
            }
            next.push(best.0 + error(k, d));
            back.push(best.1);
        }
        cost = next;
        from.push(back);
    }
    let mut lost = vec![0usize; n];
    if n > 0 {
        let mut d = (0..=max_lost)
            .min_by(|a, b| cost[*a].total_cmp(&cost[*b]))
            .unwrap_or(0);
        for k in (0..n).rev() {
            lost[k] = d;
            d = from[k][d] as usize;
        }
    }
    decoded
        .iter()
        .zip(lost)
        .enumerate()
        .map(|(k, ((_, q), d))| ((k + d) as f64 * SENSOR_PERIOD_S, *q))
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn cycles_are_counted_through_pauses_and_the_cleanup_hand_over() {
        use Activity::*;
        let seq = [
            Idle,
            Scan,
            SwingToDig,
            Dig,
            Idle,
            SwingToDump,
            Dump,
            Idle,
            Scan,
            SwingToDig,
            Dig,
            Faulted,
            Dig,
            SwingToDump,
            Dump,
            Scan,
            SwingToDig,
            Cleanup,
            Dig,
            SwingToDump,
            Dump,
            Return,
            Idle,
        ];
        assert_eq!(
            count_cycles(&seq),
            Cycles {
                digs: 2,
                cleanups: 1,
                returns_home: 1
            }
        );
        // A dig abandoned before its dump is no cycle.
        assert_eq!(count_cycles(&[Dig, SwingToDump, Return]).digs, 0);
    }

    /// A state log written every 30 ms of a motion, and the frames of every 10 ms sample.
    fn moving_session() -> (Vec<StateSample>, Vec<[f64; 4]>) {
        let angles = |t: f64| [0.5 * t.sin(), -1.0 + 0.3 * t, (2.0 * t).cos(), 0.1 * t];
        let rates = |t: f64| [0.5 * t.cos(), 0.3, -2.0 * (2.0 * t).sin(), 0.1];
        let truth = (1..=1000)
            .map(|i| {
                let t = 0.03 * f64::from(i);
                StateSample {
                    time_s: t,
                    angles_rad: angles(t),
                    rates_rad_per_s: rates(t),
                }
            })
            .collect();
        let frames = (0..3000).map(|k| angles(0.01 * f64::from(k))).collect();
        (truth, frames)
    }

    #[test]
    fn frames_go_to_their_samples_whatever_the_capture_lost() {
        let (truth, frames) = moving_session();
        // Lose every seventh frame and a run of forty; wall-clock stamps in late bursts.
        let kept: Vec<usize> = (0..frames.len())
            .filter(|k| k % 7 != 3 && !(1200..1240).contains(k))
            .collect();
        let decoded: Vec<_> = kept
            .iter()
            .map(|&k| (1.7e9 + 0.05 * (k / 10) as f64, frames[k]))
            .collect();
        let placed = on_simulation_clock(&decoded, &truth);
        for (p, &k) in placed.iter().zip(&kept).skip(5) {
            assert!(
                (p.0 - 0.01 * k as f64).abs() < 1e-9,
                "frame of sample {k} at {}",
                p.0
            );
        }
        let cmp = compare_angles(&placed, &truth, 0.0, 5.0, SENSOR_PERIOD_S);
        assert!(cmp.compared > 2500);
        assert!(cmp.outside.is_empty(), "{:?}", cmp.outside.first());
        // A decoder 1 % off in scale is caught under the best order-preserving placement.
        let wrong: Vec<_> = decoded
            .iter()
            .map(|(t, q)| (*t, q.map(|a| a * 1.01)))
            .collect();
        let cmp = compare_angles(&on_simulation_clock(&wrong, &truth), &truth, 0.0, 5.0, 0.01);
        assert!(cmp.outside.len() > 1000, "{}", cmp.outside.len());
    }

    #[test]
    fn decoder_output_lines_parse() {
        let text = "(1700000000.123456) vcan0 0CFF5080#7C14C8FB7EB2B57A :: JointAngles(BoomAngle: \
                    0.5244 rad, StickAngle: -0.108 rad, BucketAngle: -1.9842000000000002 rad, \
                    SwingAngle: 3.1413 rad)\n(1700000000.2) vcan0 0CFF5480#00 :: GatewayStatus(Mode: 0)";
        let q = decoded_joint_angles(text).unwrap();
        assert_eq!(q.len(), 1);
        assert!((q[0].0 - 1_700_000_000.123456).abs() < 1e-6);
        assert_eq!(q[0].1, [0.5244, -0.108, -1.9842000000000002, 3.1413]);
    }

    #[test]
    fn angle_comparison_finds_the_clock_offset() {
        let truth: Vec<StateSample> = (0..2000)
            .map(|k| {
                let t = k as f64 * 0.01;
                StateSample {
                    time_s: t,
                    angles_rad: [0.5 * (t * 0.5).sin(), -1.0, -0.5, 0.1 * t],
                    rates_rad_per_s: [0.25 * (t * 0.5).cos(), 0.0, 0.0, 0.1],
                }
            })
            .collect();
        let offset = 1_700_000_000.25;
        let decoded: Vec<(f64, [f64; 4])> = truth
            .iter()
            .skip(1)
            .map(|s| (s.time_s + offset + 0.003, s.angles_rad))
            .collect();
        let c = compare_angles(&decoded, &truth, 1_700_000_000.0, 5.0, 0.02);
        assert!(
            c.outside.is_empty(),
            "{:?}",
            &c.outside[..c.outside.len().min(3)]
        );
        assert!(c.compared > 1900);
        for o in &c.offsets_s {
            assert!((o - offset - 0.003).abs() < 0.002, "{o}");
        }
        // A wrong angle is found.
        let mut bad = decoded.clone();
        bad[500].1[1] += 0.01;
        let c = compare_angles(&bad, &truth, 1_700_000_000.0, 5.0, 0.02);
        assert_eq!(c.outside.len(), 1);
    }
}
