//! The velocity signals' prefilter: measurement and prediction through the same centred moving
//! average, so the residual is the prefiltered prediction error.

use crate::signal::N_SIGNALS;

/// Half width of the velocity signals' prefilter, samples: a centred moving average over
/// `2 h + 1 = 5` samples (50 ms; -3 dB at 9 Hz, first zero at 20 Hz).
pub const VELOCITY_PREFILTER_HALF: usize = 2;

/// Prefilters the velocity signals (the first three) in place: each becomes the centred moving
/// average over `2 VELOCITY_PREFILTER_HALF + 1` samples, NaN unless every sample of the window is
/// defined. Measurement and prediction go through the same linear filter, so their difference is
/// the prefiltered prediction error (Ljung, System Identification, 7.3: the prefilter weights the
/// error to the band where the model is meant to hold). The velocity relation (Eqs. 1-2) is
/// quasi-static, meant for what 100 Hz samples resolve of the oil flow; above about 10 Hz the
/// measured rate is the rate sensor's white noise (2e-3 rad/s, 3-4 mm/s of cylinder speed at rest
/// in every session) and the oil columns' aliased oscillations, which no candidate effect predicts.
/// Unfiltered, that noise floor was most of the residual an augmented model left (session
/// internal_leakage_1e-11: held-out stick velocity RMS 8.3 -> 5.0 mm/s raw, 6.2 -> 1.9 mm/s
/// through this filter; docs/discrepancy.md).
pub fn prefilter_velocities(series: &mut [[f64; N_SIGNALS]]) {
    const H: usize = VELOCITY_PREFILTER_HALF;
    const W: usize = 2 * H + 1;
    let n = series.len();
    for i in 0..3 {
        // In place (the replay runs this on every candidate evaluation): the raw values of the
        // window `k - H ..= k + H` in a ring, the ones before `k` already overwritten in `series`.
        let mut ring = [f64::NAN; W];
        for (k, slot) in ring.iter_mut().enumerate().take(H.min(n)) {
            *slot = series[k][i];
        }
        for k in 0..n {
            ring[(k + H) % W] = series.get(k + H).map_or(f64::NAN, |s| s[i]);
            series[k][i] = if k >= H && k + H < n {
                let window = (k - H..=k + H).map(|j| ring[j % W]);
                if window.clone().all(f64::is_finite) {
                    window.sum::<f64>() / W as f64
                } else {
                    f64::NAN
                }
            } else {
                f64::NAN
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The prefilter keeps a bias (what a missing effect leaves), divides white noise's variance by
    /// the window, needs a whole window of defined samples and leaves the other signals alone.
    #[test]
    fn prefilter_keeps_a_bias_and_cuts_white_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let mut uniform = || rng.random::<f64>() - 0.5;
        let n = 20_000;
        let mut series: Vec<[f64; N_SIGNALS]> = (0..n)
            .map(|_| {
                let mut s = [7.0; N_SIGNALS];
                s[0] = 0.01 + uniform();
                s[1] = 0.02;
                s
            })
            .collect();
        series[100][1] = f64::NAN;
        prefilter_velocities(&mut series);
        let width = 2 * VELOCITY_PREFILTER_HALF + 1;
        let h = VELOCITY_PREFILTER_HALF;
        assert!(series[..h].iter().all(|s| s[0].is_nan()));
        assert!(series[n - h..].iter().all(|s| s[0].is_nan()));
        assert!((100 - h..=100 + h).all(|k| series[k][1].is_nan()));
        assert!((series[100 + h + 1][1] - 0.02).abs() < 1e-15);
        assert!(
            series
                .iter()
                .all(|s| s[3] == 7.0 && s[N_SIGNALS - 1] == 7.0)
        );
        let x: Vec<f64> = series
            .iter()
            .map(|s| s[0])
            .filter(|v| v.is_finite())
            .collect();
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64;
        assert!((mean - 0.01).abs() < 0.005, "{mean}");
        let white = 1.0 / 12.0;
        let ratio = var / (white / width as f64);
        assert!((0.9..1.1).contains(&ratio), "{ratio}");
    }
}
