//! The absolute reference for "expected": the residual level, spread and structure of every signal
//! on sessions the user declares healthy (`analyse --reference DIR...`), replayed through the same
//! starting model as the measured sessions. A measured signal is judged by its held-out residual as
//! a ratio to this level, not by its own nominal residual (which a large systematic error inflates
//! until it sets its own noise level).
//!
//! Per signal the reference keeps: the residual RMS over all its digs and per Autodig stage, each
//! dig's mean square (from which [`Reference::tolerance`] takes how far the RMS of a few digs of a
//! healthy machine strays), the whiteness (Ljung-Box `Q(20)`) and largest command cross-correlation
//! ([`crate::stats::localise`]), and the correlation of the residual with a few physical regressors
//! ([`Regressor`]).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::greybox::{
    Augmentation, GreyBoxParams, N_SIGNALS, PreparedRecord, Signal, SignalGroups, replay,
};
use crate::{DiscrepancyError, Result, StageTag, stats};

/// Format name of a reference file.
pub const REFERENCE_FORMAT: &str = "excavator-discrepancy-reference";

/// The built-in reference of the default machine (`config/nominal_reference.json`): healthy
/// default `demo` sessions replayed through the shipped nominal model, recorded by
/// `excavator-ctl discrepancy record-reference` ([`Recording`] says with which command and seeds).
/// `analyse` without `--reference` judges against it when the machine and the starting model are
/// the defaults.
pub const BUILTIN_REFERENCE_JSON: &str = include_str!("../../config/nominal_reference.json");

/// A ratio to the reference below this is never called beyond it, whatever the reference's own
/// spread, for the signals whose level follows the session's work: the cylinder forces, the soil
/// forces and the weighed payload. Healthy sessions of the same machine on different ground differ
/// by up to about 1.7x there (sixteen-dig planned sessions at seeds 500-509 against a reference of
/// seeds 300-301: stick force 0.43-1.73, payload 0.64-1.51), more than the spread of one
/// reference's digs shows.
pub const MIN_TOLERANCE: f64 = 2.0;

/// The same floor for the cylinder velocities, the pump pressures and the end-stop angles, which
/// every phase of the work cycle samples alike: the same healthy sessions stay within 0.78-1.18 of
/// the reference there, so a change that moves them by 1.35x is not the ground.
pub const MIN_TOLERANCE_HYDRAULIC: f64 = 1.35;

/// The floor of [`Reference::tolerance`] for `sig`: [`MIN_TOLERANCE_HYDRAULIC`] or
/// [`MIN_TOLERANCE`].
pub fn min_tolerance(sig: Signal) -> f64 {
    let hydraulic = SignalGroups {
        hydraulic: true,
        pumps: true,
        stops: true,
        force: false,
        soil: false,
        payload: false,
    };
    if hydraulic.contains(sig.index()) {
        MIN_TOLERANCE_HYDRAULIC
    } else {
        MIN_TOLERANCE
    }
}

/// Quantile of the bootstrap RMS ratio taken as the tolerance.
pub const TOLERANCE_QUANTILE: f64 = 0.99;

/// Bootstrap draws of the tolerance.
const BOOTSTRAP_DRAWS: usize = 400;

/// A signal is judged only with at least this many samples (held-out and in the reference).
pub const MIN_JUDGED_SAMPLES: usize = 100;

/// Quantities the residual is correlated with in the structure test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regressor {
    /// The measured signal itself (a residual proportional to it is a gain error: a bore, a
    /// discharge coefficient, a mass).
    Measured,
    /// The valve command of the signal's cylinder, or the summed magnitude of the commands on the
    /// signal's pump.
    Command,
    /// The pressure of the pump feeding the signal's cylinder.
    PumpPressure,
    /// Head less rod pressure of the signal's cylinder.
    PressureDifference,
    /// The swept volume the controller reports (in the soil stages).
    SweptVolume,
}

impl Regressor {
    /// Every regressor.
    pub const ALL: [Regressor; 5] = [
        Regressor::Measured,
        Regressor::Command,
        Regressor::PumpPressure,
        Regressor::PressureDifference,
        Regressor::SweptVolume,
    ];

    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Regressor::Measured => "the measured value",
            Regressor::Command => "the valve command",
            Regressor::PumpPressure => "the pump pressure",
            Regressor::PressureDifference => "the head-rod pressure difference",
            Regressor::SweptVolume => "the swept volume",
        }
    }

    /// The regressor's value at sample `k` of `rec` for signal `sig` (NaN where it means nothing).
    fn value(self, sig: Signal, rec: &PreparedRecord, k: usize) -> f64 {
        let s = &rec.samples[k];
        let pump_of = |i: usize| if i == 1 { 1 } else { 0 };
        match (self, sig.cylinder()) {
            (Regressor::Measured, _) => rec.measured[k][sig.index()],
            (Regressor::Command, Some(i)) => s.command[i],
            (Regressor::Command, None) => match sig {
                Signal::Pump1Pressure => s.command[0].abs() + s.command[2].abs(),
                Signal::Pump2Pressure => s.command[1].abs() + s.swing_command.abs(),
                _ => f64::NAN,
            },
            (Regressor::PumpPressure, Some(i)) => s.pump_pa[pump_of(i)],
            (Regressor::PressureDifference, Some(i)) => s.head_pa[i] - s.rod_pa[i],
            (Regressor::SweptVolume, _) if s.stage.in_soil() => s.swept_volume_m3,
            (Regressor::SweptVolume, _) => 0.0,
            _ => f64::NAN,
        }
    }
}

/// Pearson correlation accumulated over samples.
#[derive(Debug, Clone, Copy, Default)]
struct CorrAcc {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    syy: f64,
    sxy: f64,
}

impl CorrAcc {
    fn add(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.syy += y * y;
        self.sxy += x * y;
    }

    fn value(&self) -> f64 {
        if self.n < 3.0 {
            return 0.0;
        }
        let vx = self.sxx - self.sx * self.sx / self.n;
        let vy = self.syy - self.sy * self.sy / self.n;
        let c = self.sxy - self.sx * self.sy / self.n;
        if vx > 0.0 && vy > 0.0 {
            c / (vx * vy).sqrt()
        } else {
            0.0
        }
    }
}

/// Residual level of one group of samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Level {
    /// What the group is (`all` or a stage name).
    pub group: String,
    /// Samples.
    pub samples: usize,
    /// Residual RMS.
    pub rms: f64,
}

/// Residual structure of one signal over a set of digs under one model: what the reference keeps of
/// a signal, and what the verdict compares with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SignalStructure {
    /// Signal name.
    pub signal: String,
    /// Unit of the RMS.
    pub unit: String,
    /// Residual RMS over all samples.
    pub overall: Level,
    /// Per Autodig stage (stages with samples).
    pub per_stage: Vec<Level>,
    /// Per dig: `(samples, mean square residual)`.
    pub per_dig: Vec<(usize, f64)>,
    /// Per dig, the same digs: mean residual (empty in a reference written before it was kept; no
    /// bias is then judged).
    #[serde(default)]
    pub per_dig_mean: Vec<f64>,
    /// Ljung-Box `Q(20)` (mean over digs).
    pub ljung_box_q: f64,
    /// Largest cross-correlation with the command over lags -30..=30 samples, and its lag.
    pub input_cross_correlation: (f64, i32),
    /// Correlation of the residual with each regressor ([`Regressor::ALL`] order; 0 where it
    /// means nothing for the signal).
    pub correlations: Vec<f64>,
}

/// The residual structure of every signal of `records` under `params` and `aug`.
pub fn structure(
    records: &[&PreparedRecord],
    params: &GreyBoxParams,
    aug: &Augmentation,
) -> Vec<SignalStructure> {
    let n_stages = StageTag::ALL.len();
    let mut overall = [(0usize, 0.0f64); N_SIGNALS];
    let mut stage = vec![[(0usize, 0.0f64); N_SIGNALS]; n_stages];
    let mut per_dig: Vec<Vec<(usize, f64)>> = vec![Vec::new(); N_SIGNALS];
    let mut per_dig_mean: Vec<Vec<f64>> = vec![Vec::new(); N_SIGNALS];
    let mut corr = vec![[CorrAcc::default(); Regressor::ALL.len()]; N_SIGNALS];
    let mut pred = Vec::new();
    for rec in records {
        replay(rec, params, aug, SignalGroups::ALL, &mut pred);
        let mut dig = [(0usize, 0.0f64); N_SIGNALS];
        let mut dig_sum = [0.0f64; N_SIGNALS];
        for (k, (m, p)) in rec.measured.iter().zip(&pred).enumerate() {
            let st = StageTag::ALL
                .iter()
                .position(|t| *t == rec.samples[k].stage)
                .unwrap_or(0);
            for sig in Signal::ALL {
                let j = sig.index();
                let r = m[j] - p[j];
                if !r.is_finite() {
                    continue;
                }
                for acc in [&mut overall[j], &mut stage[st][j], &mut dig[j]] {
                    acc.0 += 1;
                    acc.1 += r * r;
                }
                dig_sum[j] += r;
                for (g, reg) in Regressor::ALL.iter().enumerate() {
                    let x = reg.value(sig, rec, k);
                    if x.is_finite() {
                        corr[j][g].add(x, r);
                    }
                }
            }
        }
        for j in 0..N_SIGNALS {
            if dig[j].0 > 0 {
                per_dig[j].push((dig[j].0, dig[j].1 / dig[j].0 as f64));
                per_dig_mean[j].push(dig_sum[j] / dig[j].0 as f64);
            }
        }
    }
    let localised = stats::localise(records, params, aug);
    let level = |group: &str, (n, s): (usize, f64)| Level {
        group: group.to_string(),
        samples: n,
        rms: if n > 0 { (s / n as f64).sqrt() } else { 0.0 },
    };
    Signal::ALL
        .iter()
        .zip(localised)
        .map(|(sig, loc)| {
            let j = sig.index();
            SignalStructure {
                signal: sig.name().to_string(),
                unit: sig.unit().to_string(),
                overall: level("all", overall[j]),
                per_stage: StageTag::ALL
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| stage[*i][j].0 > 0)
                    .map(|(i, t)| level(t.name(), stage[i][j]))
                    .collect(),
                per_dig: std::mem::take(&mut per_dig[j]),
                per_dig_mean: std::mem::take(&mut per_dig_mean[j]),
                ljung_box_q: loc.ljung_box_q,
                input_cross_correlation: loc.input_cross_correlation,
                correlations: corr[j].iter().map(CorrAcc::value).collect(),
            }
        })
        .collect()
}

/// The reference: residual structure of every signal on sessions declared healthy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    /// Format name ([`REFERENCE_FORMAT`]).
    pub format: String,
    /// Where it comes from (the session folders).
    pub source: Vec<String>,
    /// The model it was replayed with (its provenance).
    pub model: String,
    /// Effects the analysis of the healthy sessions named on the starting model: the starting
    /// model's calibration to this machine (a healthy machine's own signature, e.g. a few ms of
    /// transport delay the nominal model lacks on another bench). The measured sessions are
    /// analysed from the model with these added, and the levels below are the residuals with them.
    #[serde(default)]
    pub calibration: Vec<crate::model::ModelEffect>,
    /// Machine-file parameters the analysis of the healthy sessions named: the grey-box model's
    /// calibration to this machine as factors on the file's values (the nominal model's bulk
    /// modulus, fitted on healthy sessions of the default plant, about 10 % stiffer than the
    /// file's). A parameter named on measured sessions is a change on top of it.
    #[serde(default)]
    pub parameter_calibration: Vec<ParameterCalibration>,
    /// Digs.
    pub digs: usize,
    /// Per signal, [`Signal::ALL`] order.
    pub signals: Vec<SignalStructure>,
    /// How the reference's sessions were generated, for a reference recorded from simulated
    /// default sessions (`discrepancy record-reference`, the built-in one); `None` for one made
    /// from session folders a user declared healthy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recording: Option<Recording>,
}

/// How a recorded reference's healthy sessions were generated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Recording {
    /// The command that recorded it.
    pub command: String,
    /// The simulator seeds of its sessions (an evaluation judged against it keeps clear of them).
    pub seeds: Vec<u64>,
    /// Digs per session.
    pub digs: u32,
    /// The simulator's plant version ([`vcan_sim::PLANT_VERSION`] when it was recorded).
    pub plant_version: String,
}

/// A machine-file parameter of the reference's calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterCalibration {
    /// The machine file's dotted key.
    pub key: String,
    /// The fitted value, in the file's unit.
    pub value: f64,
    /// The fitted value over the file's.
    pub factor: f64,
}

impl Reference {
    /// The reference of healthy records under the starting model.
    ///
    /// # Errors
    /// [`DiscrepancyError::NotEnoughData`] without records.
    pub fn from_records(
        records: &[PreparedRecord],
        params: &GreyBoxParams,
        aug: &Augmentation,
        source: Vec<String>,
        model: String,
        calibration: Vec<crate::model::ModelEffect>,
        parameter_calibration: Vec<ParameterCalibration>,
    ) -> Result<Self> {
        if records.is_empty() {
            return Err(DiscrepancyError::NotEnoughData(
                "the reference sessions hold no usable dig".into(),
            ));
        }
        let refs: Vec<&PreparedRecord> = records.iter().collect();
        Ok(Self {
            format: REFERENCE_FORMAT.to_string(),
            source,
            model,
            calibration,
            parameter_calibration,
            digs: records.len(),
            signals: structure(&refs, params, aug),
            recording: None,
        })
    }

    /// The built-in reference of the default machine ([`BUILTIN_REFERENCE_JSON`]).
    ///
    /// # Errors
    /// As [`Reference::from_json`] (not expected: a test parses the shipped file).
    pub fn builtin() -> Result<Self> {
        Self::from_json(BUILTIN_REFERENCE_JSON)
    }

    /// Parses a reference file written by [`Reference::to_json`].
    ///
    /// # Errors
    /// [`DiscrepancyError::Invalid`] for JSON that is not a reference, has the wrong signal list or
    /// non-finite levels.
    pub fn from_json(text: &str) -> Result<Self> {
        let r: Reference = serde_json::from_str(text)
            .map_err(|e| DiscrepancyError::Invalid(format!("reference file: {e}")))?;
        if r.format != REFERENCE_FORMAT {
            return Err(DiscrepancyError::Invalid(format!(
                "reference file: format {:?}, expected {REFERENCE_FORMAT:?}",
                r.format
            )));
        }
        if r.signals.len() != N_SIGNALS
            || r.signals
                .iter()
                .zip(Signal::ALL)
                .any(|(s, sig)| s.signal != sig.name())
        {
            return Err(DiscrepancyError::Invalid(format!(
                "reference file: signals {:?}, expected {:?}",
                r.signals.iter().map(|s| &s.signal).collect::<Vec<_>>(),
                Signal::ALL.map(Signal::name)
            )));
        }
        for s in &r.signals {
            let bad = !(s.overall.rms.is_finite() && s.overall.rms >= 0.0)
                || s.per_dig
                    .iter()
                    .any(|(_, ms)| !(ms.is_finite() && *ms >= 0.0))
                || s.per_dig_mean.iter().any(|m| !m.is_finite())
                || !(s.per_dig_mean.is_empty() || s.per_dig_mean.len() == s.per_dig.len());
            if bad {
                return Err(DiscrepancyError::Invalid(format!(
                    "reference file: signal {}: a residual level is not a finite non-negative \
                     number, or the per-dig means do not match the per-dig levels",
                    s.signal
                )));
            }
        }
        Ok(r)
    }

    /// The reference as JSON.
    ///
    /// # Errors
    /// Serialisation (not expected).
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map_err(|e| DiscrepancyError::Invalid(format!("reference to JSON: {e}")))
    }

    /// The expected residual RMS of signal `sig` (0 where the reference has too few samples to say).
    pub fn expected_rms(&self, sig: Signal) -> f64 {
        let s = &self.signals[sig.index()];
        if s.overall.samples >= MIN_JUDGED_SAMPLES {
            s.overall.rms
        } else {
            0.0
        }
    }

    /// The ratio to the expected RMS above which `digs` digs of a healthy machine are unlikely
    /// (bootstrap of the reference's digs, the [`TOLERANCE_QUANTILE`] quantile of the RMS of
    /// `digs` digs drawn with replacement over the reference RMS), at least [`min_tolerance`].
    pub fn tolerance(&self, sig: Signal, digs: usize) -> f64 {
        let s = &self.signals[sig.index()];
        if s.per_dig.len() < 2 || s.overall.rms <= 0.0 || digs == 0 {
            return min_tolerance(sig);
        }
        let ratios = bootstrap(s.per_dig.len(), digs, 0x5EED + sig.index() as u64, |draw| {
            let (mut n, mut sq) = (0usize, 0.0);
            for &i in draw {
                let (dn, ms) = s.per_dig[i];
                n += dn;
                sq += ms * dn as f64;
            }
            (sq / n.max(1) as f64).sqrt() / s.overall.rms
        });
        quantile(&ratios, TOLERANCE_QUANTILE).max(min_tolerance(sig))
    }

    /// The mean residual of signal `sig` over the reference's digs ([`mean_residual`]), `None`
    /// where the reference has fewer than [`MIN_JUDGED_SAMPLES`] samples of it.
    pub fn mean_residual(&self, sig: Signal) -> Option<f64> {
        let s = &self.signals[sig.index()];
        let n: usize = s.per_dig.iter().map(|d| d.0).sum();
        if n < MIN_JUDGED_SAMPLES {
            return None;
        }
        mean_residual(s)
    }

    /// The band of the mean residual over `digs` digs of a healthy machine: the
    /// `(1 - TOLERANCE_QUANTILE) / 2` and `(1 + TOLERANCE_QUANTILE) / 2` quantiles of the
    /// sample-weighted mean residual of `digs` reference digs drawn with replacement. `None` when
    /// the reference keeps no per-dig means or has fewer than two digs.
    pub fn bias_band(&self, sig: Signal, digs: usize) -> Option<(f64, f64)> {
        let s = &self.signals[sig.index()];
        if s.per_dig.len() < 2 || s.per_dig_mean.len() != s.per_dig.len() || digs == 0 {
            return None;
        }
        let means = bootstrap(s.per_dig.len(), digs, 0xB1A5 + sig.index() as u64, |draw| {
            let (mut n, mut sum) = (0usize, 0.0);
            for &i in draw {
                n += s.per_dig[i].0;
                sum += s.per_dig_mean[i] * s.per_dig[i].0 as f64;
            }
            sum / n.max(1) as f64
        });
        Some((
            quantile(&means, (1.0 - TOLERANCE_QUANTILE) / 2.0),
            quantile(&means, (1.0 + TOLERANCE_QUANTILE) / 2.0),
        ))
    }
}

/// [`BOOTSTRAP_DRAWS`] values of `stat` over `digs` indices into `dig_count` reference digs drawn
/// with replacement (seeded), sorted.
fn bootstrap(dig_count: usize, digs: usize, seed: u64, stat: impl Fn(&[usize]) -> f64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut draw = vec![0; digs];
    let mut values: Vec<f64> = (0..BOOTSTRAP_DRAWS)
        .map(|_| {
            for i in draw.iter_mut() {
                *i = rng.random_range(0..dig_count);
            }
            stat(&draw)
        })
        .collect();
    values.sort_by(f64::total_cmp);
    values
}

/// The `q` quantile of sorted, non-empty `values`.
fn quantile(values: &[f64], q: f64) -> f64 {
    values[((q * values.len() as f64) as usize).min(values.len() - 1)]
}

/// The sample-weighted mean residual over the digs of `s`, `None` without per-dig means.
pub fn mean_residual(s: &SignalStructure) -> Option<f64> {
    let n: usize = s.per_dig.iter().map(|(n, _)| n).sum();
    (n > 0 && s.per_dig_mean.len() == s.per_dig.len()).then(|| {
        s.per_dig
            .iter()
            .zip(&s.per_dig_mean)
            .map(|((n, _), m)| m * *n as f64)
            .sum::<f64>()
            / n as f64
    })
}

#[cfg(test)]
impl Reference {
    /// A reference of four healthy digs with `signals`, for tests.
    pub(crate) fn healthy_fixture(signals: Vec<SignalStructure>) -> Self {
        Reference {
            format: REFERENCE_FORMAT.into(),
            source: vec!["healthy".into()],
            model: "nominal".into(),
            calibration: Vec::new(),
            parameter_calibration: Vec::new(),
            digs: 4,
            signals,
            recording: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(rms: f64, per_dig: Vec<(usize, f64)>) -> SignalStructure {
        SignalStructure {
            signal: String::new(),
            unit: String::new(),
            overall: Level {
                group: "all".into(),
                samples: 1000,
                rms,
            },
            per_stage: Vec::new(),
            per_dig_mean: Vec::new(),
            per_dig,
            ljung_box_q: 0.0,
            input_cross_correlation: (0.0, 0),
            correlations: vec![0.0; Regressor::ALL.len()],
        }
    }

    fn reference(signals: Vec<SignalStructure>) -> Reference {
        let mut signals = signals;
        for (s, sig) in signals.iter_mut().zip(Signal::ALL) {
            s.signal = sig.name().to_string();
        }
        Reference::healthy_fixture(signals)
    }

    /// Digs that agree give the floor tolerance; digs that scatter widely give a wider one, and
    /// fewer judged digs a wider one than many.
    #[test]
    fn the_tolerance_follows_the_reference_digs_spread() {
        let even = signal(1.0, vec![(100, 1.0); 6]);
        let scattered = signal(
            1.0,
            vec![
                (100, 0.1),
                (100, 0.2),
                (100, 0.3),
                (100, 9.0),
                (100, 0.2),
                (100, 1.2),
            ],
        );
        let r = reference(
            (0..N_SIGNALS)
                .map(|i| {
                    if i == 0 {
                        scattered.clone()
                    } else {
                        even.clone()
                    }
                })
                .collect(),
        );
        assert_eq!(
            r.tolerance(Signal::StickVelocity, 4),
            MIN_TOLERANCE_HYDRAULIC
        );
        let one = r.tolerance(Signal::BoomVelocity, 1);
        let eight = r.tolerance(Signal::BoomVelocity, 8);
        assert!(one > 2.9 && one > eight, "{one} {eight}");
    }

    #[test]
    fn a_reference_file_round_trips_and_bad_ones_are_errors() {
        let r = reference(vec![signal(2.0, vec![(100, 4.0)]); N_SIGNALS]);
        let back = Reference::from_json(&r.to_json().unwrap()).unwrap();
        assert_eq!(back, r);
        let mut wrong = r.clone();
        wrong.format = "something else".into();
        let e = Reference::from_json(&wrong.to_json().unwrap()).unwrap_err();
        assert!(e.to_string().contains("format"), "{e}");
        let mut short = r.clone();
        short.signals.pop();
        let e = Reference::from_json(&short.to_json().unwrap()).unwrap_err();
        assert!(e.to_string().contains("signals"), "{e}");
        let text = r
            .to_json()
            .unwrap()
            .replacen("\"rms\": 2.0", "\"rms\": -2.0", 1);
        let e = Reference::from_json(&text).unwrap_err();
        assert!(e.to_string().contains("finite non-negative"), "{e}");
        assert!(Reference::from_json("{").is_err());
        // Per-dig means: one per dig and finite, or none (a reference written before they were
        // kept, which judges no bias).
        let mut means = r.clone();
        means.signals[0].per_dig_mean = vec![0.5, 0.25];
        let e = Reference::from_json(&means.to_json().unwrap()).unwrap_err();
        assert!(e.to_string().contains("per-dig means"), "{e}");
        means.signals[0].per_dig_mean = vec![f64::NAN];
        assert!(Reference::from_json(&means.to_json().unwrap()).is_err());
        let old = r.to_json().unwrap().replace("\"per_dig_mean\": [],", "");
        assert!(!old.contains("per_dig_mean"));
        let back = Reference::from_json(&old).unwrap();
        assert_eq!(back.bias_band(Signal::BoomVelocity, 4), None);
    }

    /// The bias band holds the mean of as many healthy digs, and is narrower for more of them; a
    /// session whose digs all sit above every healthy dig's mean is outside it.
    #[test]
    fn the_bias_band_holds_healthy_means_and_not_a_one_signed_shift() {
        let mut s = signal(1.0, vec![(100, 1.0); 8]);
        s.per_dig_mean = vec![-0.6, 0.4, -0.2, 0.5, 0.1, -0.4, 0.3, -0.1];
        let r = reference(vec![s; N_SIGNALS]);
        let (lo1, hi1) = r.bias_band(Signal::SoilForceX, 1).unwrap();
        let (lo8, hi8) = r.bias_band(Signal::SoilForceX, 8).unwrap();
        assert!(lo1 <= -0.4 && hi1 >= 0.4, "{lo1} {hi1}");
        assert!(hi8 - lo8 < hi1 - lo1, "{lo8}..{hi8} against {lo1}..{hi1}");
        assert!(lo8 < 0.0 && hi8 > 0.0);
        let mut shifted = signal(1.0, vec![(100, 1.0); 8]);
        shifted.per_dig_mean = vec![0.7; 8];
        let m = mean_residual(&shifted).unwrap();
        assert!((m - 0.7).abs() < 1e-12 && m > hi8);
        shifted.per_dig_mean.clear();
        assert_eq!(mean_residual(&shifted), None);
    }

    /// The reference's mean residual of a signal weighs each dig by its samples, and is `None`
    /// on fewer than `MIN_JUDGED_SAMPLES` samples.
    #[test]
    fn the_mean_residual_weighs_digs_by_their_samples() {
        let mut s = signal(1.0, vec![(300, 1.0), (100, 1.0)]);
        s.per_dig_mean = vec![-2.0, 2.0];
        let r = reference(vec![s.clone(); N_SIGNALS]);
        let m = r.mean_residual(Signal::BoomForce).unwrap();
        assert!((m + 1.0).abs() < 1e-12, "{m}");
        s.per_dig = vec![(40, 1.0), (40, 1.0)];
        let few = reference(vec![s; N_SIGNALS]);
        assert_eq!(few.mean_residual(Signal::BoomForce), None);
    }
}
