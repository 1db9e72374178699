//! Recorded digs (the training and evaluation data of 4.2.3) and their resampling to the model period.

use super::ActuatorError;
use serde::{Deserialize, Serialize};

/// Longest dig in steps after resampling (an hour at 100 Hz); longer means a bad time stamp.
pub const MAX_DIG_STEPS: usize = 360_000;
/// Commands slightly outside `[-1, 1]` (rounding in recorded traces) are accepted and clamped.
const COMMAND_TOLERANCE: f64 = 1e-6;

/// One recorded sample of the implement (the training data of 4.2.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActuatorSample {
    /// Time, s.
    pub time_s: f64,
    /// Commands `[boom, stick, bucket]`, fractions of maximum cylinder velocity in `[-1, 1]`.
    pub command: [f64; 3],
    /// Cylinder forces `[boom, stick, bucket]`, N (Eq. A20).
    pub force_n: [f64; 3],
    /// Cylinder velocities `[boom, stick, bucket]`, m/s, positive = extending.
    pub velocity_m_per_s: [f64; 3],
}

/// One dig's samples in time order. They need not be uniformly spaced: they are resampled to the
/// model's period by linear interpolation.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ActuatorDig {
    /// Samples, time strictly increasing.
    pub samples: Vec<ActuatorSample>,
}

#[inline]
pub(super) fn clamp_command(command: [f64; 3]) -> [f64; 3] {
    command.map(|u| u.clamp(-1.0, 1.0))
}

/// A dig resampled to the model period.
#[derive(Debug, Clone, Default)]
pub(super) struct Sequence {
    pub(super) t0: f64,
    pub(super) command: Vec<[f64; 3]>,
    pub(super) force: Vec<[f64; 3]>,
    pub(super) velocity: Vec<[f64; 3]>,
}

impl Sequence {
    pub(super) fn len(&self) -> usize {
        self.velocity.len()
    }
}

/// Checks a dig and resamples it onto `t0 + k dt` by linear interpolation.
pub(super) fn resample(
    dig: &ActuatorDig,
    index: usize,
    dt_s: f64,
) -> Result<Sequence, ActuatorError> {
    let samples = &dig.samples;
    for (i, s) in samples.iter().enumerate() {
        let finite = s.time_s.is_finite()
            && s.command
                .iter()
                .chain(&s.force_n)
                .chain(&s.velocity_m_per_s)
                .all(|v| v.is_finite());
        if !finite {
            return Err(ActuatorError::NonFiniteSample {
                dig: index,
                sample: i,
            });
        }
        if let Some(&u) = s.command.iter().find(|u| u.abs() > 1.0 + COMMAND_TOLERANCE) {
            return Err(ActuatorError::CommandOutOfRange {
                dig: index,
                sample: i,
                value: u,
            });
        }
        if i > 0 && s.time_s <= samples[i - 1].time_s {
            return Err(ActuatorError::TimeNotIncreasing {
                dig: index,
                sample: i,
            });
        }
    }
    let (Some(first), Some(last)) = (samples.first(), samples.last()) else {
        return Err(ActuatorError::DigTooShort {
            dig: index,
            steps: 0,
            needed: 2,
        });
    };
    let span = last.time_s - first.time_s;
    let steps = (span / dt_s + 1e-9).floor() as usize + 1;
    if steps < 2 || !span.is_finite() {
        return Err(ActuatorError::DigTooShort {
            dig: index,
            steps,
            needed: 2,
        });
    }
    if steps > MAX_DIG_STEPS {
        return Err(ActuatorError::DigTooLong {
            dig: index,
            steps,
            max: MAX_DIG_STEPS,
        });
    }
    let mut seq = Sequence {
        t0: first.time_s,
        command: Vec::with_capacity(steps),
        force: Vec::with_capacity(steps),
        velocity: Vec::with_capacity(steps),
    };
    let mut i = 0;
    for k in 0..steps {
        let t = first.time_s + k as f64 * dt_s;
        while i + 2 < samples.len() && samples[i + 1].time_s <= t {
            i += 1;
        }
        let (a, b) = (&samples[i], &samples[(i + 1).min(samples.len() - 1)]);
        let w = if b.time_s > a.time_s {
            ((t - a.time_s) / (b.time_s - a.time_s)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let lerp = |x: &[f64; 3], y: &[f64; 3]| std::array::from_fn(|j| x[j] + w * (y[j] - x[j]));
        seq.command.push(lerp(&a.command, &b.command));
        seq.force.push(lerp(&a.force_n, &b.force_n));
        seq.velocity
            .push(lerp(&a.velocity_m_per_s, &b.velocity_m_per_s));
    }
    Ok(seq)
}
