//! Localising the discrepancy: residual statistics per signal, per Autodig stage and per operating
//! regime (command level and sign, load pressure, velocity sign, simultaneous boom and bucket demand,
//! depth below the pre-dig surface), and the classical residual tests of system identification
//! (MATLAB's `resid`): whiteness (autocorrelation, Ljung-Box `Q`) and the cross-correlation of the
//! residual with the signal's input (the command), which points at timing and dead-band errors.

// Per-cylinder and per-signal arrays run in parallel; indexing them by one counter is clearer here
// than zipping four iterators.
#![allow(clippy::needless_range_loop)]

use serde::Serialize;

use super::greybox::{
    Augmentation, GreyBoxParams, N_SIGNALS, PreparedRecord, Signal, SignalGroups, replay,
};

/// Residual statistics of one group of samples.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BinStats {
    /// What the group is (e.g. `stage=dig`, `|command|>=0.6`).
    pub bin: String,
    /// Samples.
    pub samples: usize,
    /// Mean residual (measured - model).
    pub mean: f64,
    /// RMS residual.
    pub rms: f64,
}

/// Localisation of one signal's residuals.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResidualSummary {
    /// Signal name.
    pub signal: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// All samples.
    pub overall: BinStats,
    /// Per stage and per regime.
    pub bins: Vec<BinStats>,
    /// Autocorrelation at lags 1, 5, 10, 20 samples.
    pub autocorrelation: [f64; 4],
    /// Ljung-Box statistic over lags 1..=20 (white residuals: about chi-square with 20 d.o.f., 95 %
    /// quantile 31.4).
    pub ljung_box_q: f64,
    /// Whether the residual passes the whiteness test at 5 %.
    pub white: bool,
    /// Largest absolute cross-correlation between the residual and the command of its cylinder (or the
    /// sum of the pump's commands) over lags -30..=30 samples, and its lag (positive: residual after
    /// command).
    pub input_cross_correlation: (f64, i32),
    /// Whether the cross-correlation exceeds the 95 % band `1.96 / sqrt(n)`.
    pub correlated_with_input: bool,
}

#[derive(Default, Clone)]
struct Acc {
    n: usize,
    sum: f64,
    sq: f64,
}

impl Acc {
    fn add(&mut self, r: f64) {
        self.n += 1;
        self.sum += r;
        self.sq += r * r;
    }

    fn stats(&self, bin: String) -> BinStats {
        let n = self.n.max(1) as f64;
        BinStats {
            bin,
            samples: self.n,
            mean: self.sum / n,
            rms: (self.sq / n).sqrt(),
        }
    }
}

fn correlation(a: &[f64], b: &[f64], lag: i32) -> f64 {
    let n = a.len().min(b.len());
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    let ma = a.iter().sum::<f64>() / n.max(1) as f64;
    let mb = b.iter().sum::<f64>() / n.max(1) as f64;
    for k in 0..n {
        let j = k as i64 - i64::from(lag);
        if j < 0 || j >= n as i64 {
            continue;
        }
        let (x, y) = (a[k] - ma, b[j as usize] - mb);
        sab += x * y;
    }
    for k in 0..n {
        saa += (a[k] - ma).powi(2);
        sbb += (b[k] - mb).powi(2);
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

/// Residual statistics of every signal over the records for one augmentation.
pub fn localise(
    records: &[&PreparedRecord],
    params: &GreyBoxParams,
    aug: &Augmentation,
) -> Vec<ResidualSummary> {
    let mut pred = Vec::new();
    // Per signal: residual series per record with the input series, for the correlation tests.
    let mut series: Vec<Vec<(Vec<f64>, Vec<f64>)>> = vec![Vec::new(); N_SIGNALS];
    let mut overall = vec![Acc::default(); N_SIGNALS];
    let mut bins: Vec<std::collections::BTreeMap<String, Acc>> =
        vec![std::collections::BTreeMap::new(); N_SIGNALS];
    for rec in records {
        replay(rec, params, aug, SignalGroups::ALL, &mut pred);
        let mut per: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); N_SIGNALS];
        for (k, m) in rec.measured.iter().enumerate() {
            let s = &rec.samples[k];
            for j in 0..N_SIGNALS {
                let r = m[j] - pred[k][j];
                if !r.is_finite() {
                    continue;
                }
                let sig = Signal::ALL[j];
                let input = match sig.cylinder() {
                    Some(i) => s.command[i],
                    None if j == 3 => s.command[0].abs() + s.command[2].abs(),
                    None if j == 4 => s.command[1].abs() + s.swing_command.abs(),
                    None => s.swept_volume_m3,
                };
                per[j].0.push(r);
                per[j].1.push(input);
                overall[j].add(r);
                let b = &mut bins[j];
                b.entry(format!("stage={}", s.stage.name()))
                    .or_default()
                    .add(r);
                if let Some(i) = sig.cylinder() {
                    let u = s.command[i];
                    let level = match u.abs() {
                        x if x < 0.05 => "|u|<0.05",
                        x if x < 0.3 => "0.05<=|u|<0.3",
                        x if x < 0.7 => "0.3<=|u|<0.7",
                        _ => "|u|>=0.7",
                    };
                    b.entry(format!("command {level}")).or_default().add(r);
                    if u.abs() >= 0.05 {
                        let sign = if u > 0.0 { "extend" } else { "retract" };
                        b.entry(format!("command {sign}")).or_default().add(r);
                    }
                    let load = s.head_pa[i].max(s.rod_pa[i]);
                    let p = match load {
                        x if x < 5e6 => "load<5MPa",
                        x if x < 15e6 => "5<=load<15MPa",
                        _ => "load>=15MPa",
                    };
                    b.entry(format!("pressure {p}")).or_default().add(r);
                    let v = s.rates_rad_per_s[i];
                    let vs = if v.abs() < 0.01 {
                        "at rest"
                    } else if v > 0.0 {
                        "joint rate +"
                    } else {
                        "joint rate -"
                    };
                    b.entry(format!("velocity {vs}")).or_default().add(r);
                }
                let both = s.command[0].abs() > 0.2 && s.command[2].abs() > 0.2;
                if both {
                    b.entry("boom+bucket demand".to_string())
                        .or_default()
                        .add(r);
                }
                if s.stage.in_soil() {
                    let v = s.swept_volume_m3;
                    let vb = if v < 0.5 {
                        "swept<0.5m3"
                    } else {
                        "swept>=0.5m3"
                    };
                    b.entry(format!("in soil {vb}")).or_default().add(r);
                }
            }
        }
        for j in 0..N_SIGNALS {
            if !per[j].0.is_empty() {
                series[j].push(std::mem::take(&mut per[j]));
            }
        }
    }
    Signal::ALL
        .iter()
        .map(|sig| {
            let j = sig.index();
            // Correlations averaged over records (each record is a separate experiment).
            let mut ac = [0.0; 4];
            let mut q = 0.0;
            let mut best = (0.0_f64, 0_i32);
            let mut n_total = 0usize;
            let recs = series[j].len().max(1) as f64;
            for (res, input) in &series[j] {
                n_total += res.len();
                for (slot, lag) in ac.iter_mut().zip([1, 5, 10, 20]) {
                    *slot += correlation(res, res, lag) / recs;
                }
                let n = res.len() as f64;
                for lag in 1..=20 {
                    let r = correlation(res, res, lag);
                    q += n * (n + 2.0) * r * r / (n - f64::from(lag)).max(1.0) / recs;
                }
                for lag in (-30..=30).step_by(2) {
                    let c = correlation(res, input, lag);
                    if c.abs() > best.0.abs() {
                        best = (c, lag);
                    }
                }
            }
            let band = 1.96 / (n_total.max(1) as f64 / recs).sqrt();
            ResidualSummary {
                signal: sig.name(),
                unit: sig.unit(),
                overall: overall[j].stats("all".into()),
                bins: bins[j]
                    .iter()
                    .map(|(name, acc)| acc.stats(name.clone()))
                    .collect(),
                autocorrelation: ac,
                ljung_box_q: q,
                white: q < 31.4,
                input_cross_correlation: best,
                correlated_with_input: best.0.abs() > band,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn correlation_of_a_shifted_copy_peaks_at_its_lag() {
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let a: Vec<f64> = (0..400).map(|_| rng.random::<f64>()).collect();
        let b: Vec<f64> = (0..400).map(|k| a[(k + 400 - 3) % 400]).collect();
        assert!(correlation(&b, &a, 3) > 0.95);
        assert!(correlation(&b, &a, 0).abs() < 0.3);
    }
}
