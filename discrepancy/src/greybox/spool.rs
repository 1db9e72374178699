//! The spool relation: dead band, transport delay and first-order lag (Eq. 2's compressibility and
//! the pilot stage folded into one time constant), integrated at 1 ms over the zero-order-held
//! commands.

use super::params::{Augmentation, GreyBoxParams};
use crate::Sample;
use crate::effects::Candidate;

/// Physics substep of the spool integration, s (the simulator's and the valve's 1 kHz).
const SPOOL_DT_S: f64 = 0.001;
/// Substeps per record sample.
const SUBSTEPS: usize = 10;

/// Spool positions `[boom, stick, bucket, swing]` at every sample of a record: dead band, delay and lag
/// (nominal and augmented) integrated at 1 ms over the zero-order-held commands.
pub fn spools(samples: &[Sample], params: &GreyBoxParams, aug: &Augmentation) -> Vec<[f64; 4]> {
    use Candidate as C;
    let n = samples.len();
    let deadband = aug.get(C::ValveDeadband).max(0.0);
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
    let delay_ms =
        ((params.transport_delay_s + aug.get(C::TransportDelay).max(0.0)) / SPOOL_DT_S).max(0.0);
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
    let tau = params.lag_time_constant_s.max(SPOOL_DT_S);
    let extra = aug.get(C::HydraulicLag).max(0.0);
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
