//! The spool relation: dead band, transport delay and first-order lag (Eq. 2's compressibility and
//! the pilot stage folded into one time constant), integrated at 1 ms over the zero-order-held
//! commands.

use std::sync::{Arc, Mutex};

use super::params::{Augmentation, GreyBoxParams};
use crate::Sample;
use crate::effects::Candidate;

/// Physics substep of the spool integration, s (the simulator's and the valve's 1 kHz).
const SPOOL_DT_S: f64 = 0.001;
/// Substeps per record sample.
const SUBSTEPS: usize = 10;

/// What the spool positions depend on besides the commands: the dead band, the total transport
/// delay and the two lags (nominal and augmented).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct SpoolRelation {
    deadband: f64,
    delay_s: f64,
    lag_time_constant_s: f64,
    extra_lag_s: f64,
}

impl SpoolRelation {
    /// The relation of the model `params` with the effects `aug`.
    pub(super) fn of(params: &GreyBoxParams, aug: &Augmentation) -> Self {
        use Candidate as C;
        Self {
            deadband: aug.get(C::ValveDeadband).max(0.0),
            delay_s: params.transport_delay_s + aug.get(C::TransportDelay).max(0.0),
            lag_time_constant_s: params.lag_time_constant_s,
            extra_lag_s: aug.get(C::HydraulicLag).max(0.0),
        }
    }
}

/// The spool positions of a record's last replay, served again to the next replay with the same
/// [`SpoolRelation`]: most candidates (the pumps, friction, leakage, the sensors, the soil, most
/// machine parameters) leave the spools as they are, and a fit replays a record dozens of times.
#[derive(Debug, Default)]
pub(super) struct SpoolCache(Mutex<Option<(SpoolRelation, SpoolPositions)>>);

/// Spool positions `[boom, stick, bucket, swing]` of every sample of a record, shared.
pub(super) type SpoolPositions = Arc<Vec<[f64; 4]>>;

impl Clone for SpoolCache {
    /// A copy starts empty (the cache is no part of the record's data).
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl SpoolCache {
    /// [`spools`] of `samples` for `relation`, from the cache when the last call had the same.
    pub(super) fn spools(&self, samples: &[Sample], relation: SpoolRelation) -> SpoolPositions {
        if let Ok(last) = self.0.lock()
            && let Some((r, v)) = last.as_ref()
            && *r == relation
        {
            return Arc::clone(v);
        }
        let v = Arc::new(spools(samples, relation));
        if let Ok(mut last) = self.0.lock() {
            *last = Some((relation, Arc::clone(&v)));
        }
        v
    }
}

/// Spool positions `[boom, stick, bucket, swing]` at every sample of a record: dead band, delay and lag
/// (nominal and augmented) integrated at 1 ms over the zero-order-held commands.
pub(super) fn spools(samples: &[Sample], relation: SpoolRelation) -> Vec<[f64; 4]> {
    let n = samples.len();
    let deadband = relation.deadband;
    let band = |u: f64| {
        let u = u.clamp(-1.0, 1.0);
        u.signum() * (u.abs() - deadband).max(0.0)
    };
    let cmd: Vec<[f64; 4]> = samples
        .iter()
        .map(|s| {
            [
                band(s.command[0]),
                band(s.command[1]),
                band(s.command[2]),
                band(s.swing_command),
            ]
        })
        .collect();
    let delay_ms = (relation.delay_s / SPOOL_DT_S).max(0.0);
    let d0 = delay_ms.floor() as usize;
    let frac = delay_ms - d0 as f64;
    // Command in force during 1 ms step j (sample j / 10 holds it); before the record: the first one.
    let at = |j: isize| -> [f64; 4] {
        if j < 0 {
            cmd[0]
        } else {
            cmd[((j as usize) / SUBSTEPS).min(n - 1)]
        }
    };
    let tau = relation.lag_time_constant_s.max(SPOOL_DT_S);
    let extra = relation.extra_lag_s;
    let a1 = (SPOOL_DT_S / tau).min(1.0);
    let a2 = if extra > 0.0 {
        (SPOOL_DT_S / extra).min(1.0)
    } else {
        1.0
    };
    let mut s1 = at(-(d0 as isize) - 1);
    let mut s2 = s1;
    let mut out = vec![[0.0; 4]; n];
    if n == 0 {
        return out;
    }
    out[0] = s2;
    for (k, slot) in out.iter_mut().enumerate().skip(1) {
        for sub in 0..SUBSTEPS {
            let j = ((k - 1) * SUBSTEPS + sub) as isize;
            let c0 = at(j - d0 as isize);
            let c1 = at(j - d0 as isize - 1);
            for a in 0..4 {
                let target = c0[a] + frac * (c1[a] - c0[a]);
                s1[a] += (target - s1[a]) * a1;
                s2[a] += (s1[a] - s2[a]) * a2;
            }
        }
        *slot = s2;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cache serves the spools of the relation it was asked for: the same as a fresh
    /// integration, again for the same relation, and recomputed for another (a longer delay
    /// moves the spool's rise later).
    #[test]
    fn the_cache_serves_the_spools_of_the_relation_asked_for() {
        let samples: Vec<Sample> = (0..100)
            .map(|k| Sample {
                time_s: 0.01 * k as f64,
                command: [if k >= 20 { 0.8 } else { 0.0 }, 0.0, 0.0],
                ..Sample::default()
            })
            .collect();
        let params = crate::AugmentedModel::nominal().expect("model").params;
        let nominal = SpoolRelation::of(&params, &Augmentation::nominal());
        let mut delayed_aug = Augmentation::nominal();
        delayed_aug.set(Candidate::TransportDelay, 0.1);
        let delayed = SpoolRelation::of(&params, &delayed_aug);
        assert_ne!(nominal, delayed);
        let cache = SpoolCache::default();
        let first = cache.spools(&samples, nominal);
        assert_eq!(*first, spools(&samples, nominal));
        assert!(Arc::ptr_eq(&first, &cache.spools(&samples, nominal)));
        let later = cache.spools(&samples, delayed);
        assert_eq!(*later, spools(&samples, delayed));
        // At 0.35 s the nominal spool has risen (behind its own delay of tens of ms), the one
        // 0.1 s later not yet as far.
        assert!(first[35][0] > 0.1, "{}", first[35][0]);
        assert!(
            later[35][0] < first[35][0],
            "{} vs {}",
            later[35][0],
            first[35][0]
        );
        // A copy of a record starts with an empty cache.
        assert!(cache.clone().0.lock().expect("lock").is_none());
    }
}
