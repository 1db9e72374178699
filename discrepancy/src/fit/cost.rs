//! The cost of a candidate: sums of squares and chi-square per signal over replayed records, the
//! evaluator that replays records under a candidate, and the noise model (residual spread and
//! decorrelation) that weights the chi-square.

use super::{ACTED_FRACTION, MAX_SIGNAL_WORSENING, MIN_ELIGIBLE_REDUCTION};
use crate::greybox::{
    Augmentation, GreyBoxParams, N_SIGNALS, PreparedRecord, SignalGroups, replay,
};

/// A candidate's held-out sums of squares per signal, with and without it, and the samples.
pub(super) struct HeldOutSse<'a> {
    pub(super) with: &'a [f64; N_SIGNALS],
    pub(super) without: &'a [f64; N_SIGNALS],
    pub(super) samples: &'a [usize; N_SIGNALS],
}

impl HeldOutSse<'_> {
    /// The signal (of at least 100 held-out samples) the candidate makes worse by the largest
    /// factor of RMS beyond [`MAX_SIGNAL_WORSENING`] times both its RMS without the candidate and
    /// the `expected` level ([`AnalysisConfig::expected_rms`]), with that factor.
    pub(super) fn most_worsened(
        &self,
        expected: Option<&[f64; N_SIGNALS]>,
    ) -> Option<(usize, f64)> {
        (0..N_SIGNALS)
            .filter(|j| {
                let expected_sse =
                    expected.map_or(0.0, |e| e[*j] * e[*j] * self.samples[*j] as f64);
                self.samples[*j] >= 100
                    && self.with[*j]
                        > MAX_SIGNAL_WORSENING.powi(2) * self.without[*j].max(expected_sse)
            })
            .map(|j| (j, (self.with[j] / self.without[j]).sqrt()))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Whether the candidate lowers the RMS of one of the `eligible` signals of its `groups` to
    /// [`MIN_ELIGIBLE_REDUCTION`] or less.
    pub(super) fn lowers_any(&self, eligible: &[bool; N_SIGNALS], groups: SignalGroups) -> bool {
        (0..N_SIGNALS).any(|j| {
            eligible[j]
                && groups_contain(groups, j)
                && self.without[j] > 0.0
                && self.with[j] <= MIN_ELIGIBLE_REDUCTION.powi(2) * self.without[j]
        })
    }
}

pub(super) fn groups_contain(g: SignalGroups, j: usize) -> bool {
    g.contains(j)
}

/// Per-signal weights of the chi-square.
#[derive(Debug, Clone, Copy)]
pub(super) struct Weights {
    pub(super) inv_var: [f64; N_SIGNALS],
}

/// Sum of squares and counts per signal over records.
pub(super) fn sse(
    records: &[&PreparedRecord],
    preds: &[Vec<[f64; N_SIGNALS]>],
) -> ([f64; N_SIGNALS], [usize; N_SIGNALS]) {
    let mut s = [0.0; N_SIGNALS];
    let mut n = [0usize; N_SIGNALS];
    for (rec, pred) in records.iter().zip(preds) {
        for (m, p) in rec.measured.iter().zip(pred) {
            for j in 0..N_SIGNALS {
                let r = m[j] - p[j];
                if r.is_finite() {
                    s[j] += r * r;
                    n[j] += 1;
                }
            }
        }
    }
    (s, n)
}

pub(super) fn chi2(w: &Weights, s: &[f64; N_SIGNALS]) -> f64 {
    (0..N_SIGNALS).map(|j| s[j] * w.inv_var[j]).sum()
}

/// Replays records with an augmentation, recomputing only `groups` over the cached nominal replay.
pub(super) struct Evaluator<'a> {
    pub(super) records: Vec<&'a PreparedRecord>,
    pub(super) params: GreyBoxParams,
    pub(super) base: Vec<Vec<[f64; N_SIGNALS]>>,
    pub(super) scratch: Vec<Vec<[f64; N_SIGNALS]>>,
}

impl<'a> Evaluator<'a> {
    pub(super) fn new(
        records: Vec<&'a PreparedRecord>,
        params: &GreyBoxParams,
        aug: &Augmentation,
    ) -> Self {
        let base: Vec<_> = records
            .iter()
            .map(|r| {
                let mut out = Vec::new();
                replay(r, params, aug, SignalGroups::ALL, &mut out);
                out
            })
            .collect();
        Self {
            scratch: base.clone(),
            records,
            params: params.clone(),
            base,
        }
    }

    /// Sum of squares per signal under `aug` and `params` (the evaluator's own without).
    pub(super) fn sse_with(
        &mut self,
        aug: &Augmentation,
        params: Option<&GreyBoxParams>,
        groups: SignalGroups,
    ) -> [f64; N_SIGNALS] {
        let params = params.unwrap_or(&self.params);
        for ((rec, out), base) in self.records.iter().zip(&mut self.scratch).zip(&self.base) {
            out.clone_from(base);
            replay(rec, params, aug, groups, out);
        }
        sse(&self.records, &self.scratch).0
    }

    /// Chi-square of `groups`' signals `[base, last evaluation]` on the samples where the last
    /// [`Evaluator::sse_with`] changed the prediction by more than [`ACTED_FRACTION`] of the
    /// signal's residual spread `sigma` (where the candidate acts at all).
    pub(super) fn acted_chi2(&self, w: &Weights, sigma: &[f64], groups: SignalGroups) -> [f64; 2] {
        let mut total = [0.0; 2];
        for ((rec, out), base) in self.records.iter().zip(&self.scratch).zip(&self.base) {
            for ((m, p), b) in rec.measured.iter().zip(out).zip(base) {
                for j in (0..N_SIGNALS).filter(|j| groups_contain(groups, *j)) {
                    let (r0, r1) = (m[j] - b[j], m[j] - p[j]);
                    if r0.is_finite()
                        && r1.is_finite()
                        && (p[j] - b[j]).abs() > ACTED_FRACTION * sigma[j]
                    {
                        total[0] += r0 * r0 * w.inv_var[j];
                        total[1] += r1 * r1 * w.inv_var[j];
                    }
                }
            }
        }
        total
    }

    /// The last [`Evaluator::sse_with`]'s change of the prediction, every sample and signal in a
    /// fixed order, weighted by the square root of the chi-square weight (0 where not finite): the
    /// candidate's fitted effect on the residual.
    pub(super) fn weighted_delta(&self, w: &Weights) -> Vec<f64> {
        let mut out = Vec::new();
        for (out_rec, base) in self.scratch.iter().zip(&self.base) {
            for (p, b) in out_rec.iter().zip(base) {
                for j in 0..N_SIGNALS {
                    let d = (p[j] - b[j]) * w.inv_var[j].sqrt();
                    out.push(if d.is_finite() { d } else { 0.0 });
                }
            }
        }
        out
    }

    pub(super) fn base_sse(&self) -> ([f64; N_SIGNALS], [usize; N_SIGNALS]) {
        sse(&self.records, &self.base)
    }
}

/// Integrated autocorrelation time of a residual series (in samples), summed until the
/// autocorrelation falls below 0.05, capped at 100.
pub(super) fn integrated_time(series: &[f64]) -> f64 {
    let n = series.len();
    if n < 20 {
        return 1.0;
    }
    let mean = series.iter().sum::<f64>() / n as f64;
    let var = series.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
    if var <= 0.0 {
        return 1.0;
    }
    let mut tau = 1.0;
    for lag in 1..n.min(100) {
        let c = (0..n - lag)
            .map(|k| (series[k] - mean) * (series[k + lag] - mean))
            .sum::<f64>()
            / (n as f64 * var);
        if c < 0.05 {
            break;
        }
        tau += 2.0 * c;
    }
    tau.min(100.0)
}

/// Residual standard deviation and decorrelation factor (integrated autocorrelation time, averaged
/// over the records) per signal of `preds` against the records' measurements; signals with fewer than
/// 50 samples get zero spread.
pub(super) fn noise_model(
    records: &[&PreparedRecord],
    preds: &[Vec<[f64; N_SIGNALS]>],
) -> (Vec<f64>, Vec<f64>) {
    let (s, n) = sse(records, preds);
    let mut sigma = vec![0.0; N_SIGNALS];
    let mut kappa = vec![1.0; N_SIGNALS];
    for j in 0..N_SIGNALS {
        if n[j] < 50 {
            continue;
        }
        sigma[j] = (s[j] / n[j] as f64).sqrt();
        kappa[j] = decorrelation(records, preds, j);
    }
    (sigma, kappa)
}

/// Mean integrated autocorrelation time of signal `j`'s residuals over the records.
pub(super) fn decorrelation(
    records: &[&PreparedRecord],
    preds: &[Vec<[f64; N_SIGNALS]>],
    j: usize,
) -> f64 {
    let mut taus = Vec::new();
    for (rec, pred) in records.iter().zip(preds) {
        let series: Vec<f64> = rec
            .measured
            .iter()
            .zip(pred)
            .map(|(m, p)| m[j] - p[j])
            .filter(|r| r.is_finite())
            .collect();
        taus.push(integrated_time(&series));
    }
    taus.iter().sum::<f64>() / taus.len().max(1) as f64
}

/// Chi-square weights `1 / (sigma^2 kappa)` (zero for signals with too few samples or no spread).
pub(super) fn weights_of(sigma: &[f64], kappa: &[f64], n: &[usize; N_SIGNALS]) -> [f64; N_SIGNALS] {
    let mut inv_var = [0.0; N_SIGNALS];
    for j in 0..N_SIGNALS {
        if n[j] >= 50 && sigma[j] > 0.0 {
            inv_var[j] = 1.0 / (sigma[j] * sigma[j] * kappa[j]);
        }
    }
    inv_var
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn integrated_time_is_one_for_white_noise_and_larger_for_a_random_walk() {
        let mut rng = ChaCha8Rng::seed_from_u64(12345);
        let mut uniform = || rng.random::<f64>() - 0.5;
        let white: Vec<f64> = (0..5000).map(|_| uniform()).collect();
        assert!(integrated_time(&white) < 1.3);
        let mut x = 0.0;
        let smooth: Vec<f64> = (0..5000)
            .map(|_| {
                x = 0.95 * x + uniform();
                x
            })
            .collect();
        assert!(integrated_time(&smooth) > 10.0);
    }
}
