//! A new term for what nothing explains: when a signal stays beyond the reference and no candidate
//! of the libraries accounts for it, its held-out residual is regressed on a library of physical
//! regressors and the few that carry it are printed as an equation the engineer can read, e.g.
//!
//! ```text
//! bucket_force residual ≈ 5.10 kN per MPa·(p_head − p_rod)_bucket [1.00] + 3.82 kN [1.00] − 27.6 kN per m/s·v_bucket [0.99] − 4.87 kN·sign(v_bucket) [0.92] + ...
//! ```
//!
//! The regression is SINDy's sequentially thresholded least squares (Brunton, Proctor and Kutz,
//! PNAS 2016) on standardised regressors, repeated over bootstrap resamples of the training digs:
//! the ensemble SINDy of Fasel, Kutz, Brunton and Brunton (Proc. R. Soc. A 478, 2022). The
//! threshold is the largest of a few whose ensemble's equation explains the training digs about
//! as well as the best one's ([`TermConfig::parsimony`]): the sparsest equation that does. A term's
//! **inclusion probability** is the share of the ensemble's models that keep it; the terms kept at
//! least [`TermConfig::min_inclusion`] of the time make the suggestion. The ensemble chooses the
//! terms, and their coefficients are the least-squares fit on all training digs with those terms
//! alone. The spread of that fit over the same resamples is each coefficient's uncertainty. Taking
//! each coefficient's ensemble median ("bragging") instead gives an incoherent equation when
//! terms are nearly collinear: a constant with the cosine and sine of a link angle that varies little.
//! Each model of the ensemble shares the load among them differently, and the medians do not add up
//! to any one model's sum. The suggestion is scored on the held-out digs: the share of their residual
//! mean square it removes. Below [`TermConfig::min_explained`] nothing is suggested.
//!
//! The library per signal (values in the units printed): the valve command of the signal's
//! cylinder and the same 50 ms and 150 ms earlier, its pump's pressure and its head-rod pressure
//! difference (MPa), its cylinder velocity (m/s) and that velocity's sign (a Coulomb-like term,
//! zero below 5 mm/s), indicators of the bucket in the soil and of the Dig stage, the cosine and
//! sine of the link's angle to the horizontal (gravity), and a constant. Pump pressures take the
//! commands, pressure differences and velocities of the cylinders on the pump and the pump's own
//! pressure; the soil, end-stop and payload signals those of all three cylinders. A regressor that
//! does not vary on the training digs is left out.
//!
//! Each dig's normal equations (Gram matrix of the regressors, their products with the residual)
//! are accumulated once, so a bootstrap model is a weighted sum of them and a few small solves.

use std::fmt::Write as _;

use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::greybox::{Augmentation, GreyBoxParams, PreparedRecord, SignalGroups, replay};
use crate::{Signal, StageTag};

/// Settings of the term suggestion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TermConfig {
    /// Bootstrap resamples of the training digs (models in the ensemble).
    pub bootstrap: usize,
    /// STLSQ thresholds tried on a standardised coefficient (residual standard deviations per
    /// regressor standard deviation; a term that moves the residual by less is dropped), smallest
    /// first. The largest whose ensemble's equation explains at least [`TermConfig::parsimony`]
    /// of the best one's share of the training residual is taken (the sparsest that explains about
    /// as much).
    pub thresholds: [f64; 5],
    /// See [`TermConfig::thresholds`].
    pub parsimony: f64,
    /// A term is kept when at least this share of the ensemble's models include it.
    pub min_inclusion: f64,
    /// A suggestion is made only when it removes at least this share of the held-out residual's
    /// mean square.
    pub min_explained: f64,
    /// Seed of the bootstrap draws (a fixed seed: the same sessions give the same suggestion).
    pub seed: u64,
}

impl Default for TermConfig {
    fn default() -> Self {
        Self {
            bootstrap: 100,
            thresholds: [0.05, 0.1, 0.2, 0.3, 0.5],
            parsimony: 0.95,
            min_inclusion: 0.8,
            min_explained: 0.25,
            seed: 0x5eed,
        }
    }
}

/// STLSQ rounds (the support settles in a few).
const STLSQ_ITERATIONS: usize = 10;

/// Below this speed a cylinder's velocity sign is taken as zero, m/s (the rate sensor's noise).
const SIGN_DEAD_ZONE_M_PER_S: f64 = 0.005;

/// The two command delays of the library, samples of 10 ms.
const COMMAND_DELAYS: [usize; 2] = [5, 15];

/// One regressor of the library.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Regressor {
    Constant,
    Command(usize),
    DelayedCommand(usize, usize),
    CommandMagnitude(usize),
    PumpPressure(usize),
    PressureDifference(usize),
    Velocity(usize),
    VelocitySign(usize),
    InSoil,
    Dig,
    Cos(usize),
    Sin(usize),
}

const CYLINDERS: [&str; 3] = ["boom", "stick", "bucket"];

/// The pump feeding cylinder `i` (boom and bucket on pump 1, the stick on pump 2).
fn pump_of(i: usize) -> usize {
    usize::from(i == 1)
}

impl Regressor {
    /// Name in the equation.
    fn name(self) -> String {
        match self {
            Regressor::Constant => "1".into(),
            Regressor::Command(i) => format!("u_{}", CYLINDERS[i]),
            Regressor::DelayedCommand(i, lag) => {
                format!("u_{}(t − {} ms)", CYLINDERS[i], lag * 10)
            }
            Regressor::CommandMagnitude(i) => format!("|u_{}|", CYLINDERS[i]),
            Regressor::PumpPressure(p) => format!("p_pump{}", p + 1),
            Regressor::PressureDifference(i) => format!("(p_head − p_rod)_{}", CYLINDERS[i]),
            Regressor::Velocity(i) => format!("v_{}", CYLINDERS[i]),
            Regressor::VelocitySign(i) => format!("sign(v_{})", CYLINDERS[i]),
            Regressor::InSoil => "[in soil]".into(),
            Regressor::Dig => "[dig]".into(),
            Regressor::Cos(i) => format!("cos(θ_{})", CYLINDERS[i]),
            Regressor::Sin(i) => format!("sin(θ_{})", CYLINDERS[i]),
        }
    }

    /// Unit of the value ("1": dimensionless).
    fn unit(self) -> &'static str {
        match self {
            Regressor::PumpPressure(_) | Regressor::PressureDifference(_) => "MPa",
            Regressor::Velocity(_) => "m/s",
            _ => "1",
        }
    }

    /// The value at sample `k` of `rec`.
    fn value(self, rec: &PreparedRecord, k: usize) -> f64 {
        let s = &rec.samples[k];
        let v = |i: usize| rec.cylinder_velocities()[k][i];
        // The link's angle to the horizontal: the joint angles summed from the boom out.
        let link = |i: usize| s.angles_rad[..=i].iter().sum::<f64>();
        match self {
            Regressor::Constant => 1.0,
            Regressor::Command(i) => s.command[i],
            Regressor::DelayedCommand(i, lag) => rec.samples[k.saturating_sub(lag)].command[i],
            Regressor::CommandMagnitude(i) => s.command[i].abs(),
            Regressor::PumpPressure(p) => s.pump_pa[p] * 1e-6,
            Regressor::PressureDifference(i) => (s.head_pa[i] - s.rod_pa[i]) * 1e-6,
            Regressor::Velocity(i) => v(i),
            Regressor::VelocitySign(i) if v(i).abs() > SIGN_DEAD_ZONE_M_PER_S => v(i).signum(),
            Regressor::VelocitySign(_) => 0.0,
            Regressor::InSoil => f64::from(u8::from(s.stage.in_soil())),
            Regressor::Dig => f64::from(u8::from(s.stage == StageTag::Dig)),
            Regressor::Cos(i) => link(i).cos(),
            Regressor::Sin(i) => link(i).sin(),
        }
    }
}

/// The library of regressors for `sig` (the constant first).
fn library(sig: Signal) -> Vec<Regressor> {
    use Regressor::*;
    let cylinder = |i: usize| {
        vec![
            Constant,
            Command(i),
            DelayedCommand(i, COMMAND_DELAYS[0]),
            DelayedCommand(i, COMMAND_DELAYS[1]),
            PumpPressure(pump_of(i)),
            PressureDifference(i),
            Velocity(i),
            VelocitySign(i),
            InSoil,
            Dig,
            Cos(i),
            Sin(i),
        ]
    };
    match (sig.cylinder(), sig) {
        (Some(i), _) => cylinder(i),
        (None, Signal::Pump1Pressure | Signal::Pump2Pressure) => {
            let p = usize::from(sig == Signal::Pump2Pressure);
            let mut out = vec![Constant, PumpPressure(p), InSoil, Dig];
            for i in (0..3).filter(|i| pump_of(*i) == p) {
                out.extend([CommandMagnitude(i), PressureDifference(i), Velocity(i)]);
            }
            out
        }
        _ => {
            let mut out = vec![Constant, InSoil, Dig];
            for i in 0..3 {
                out.extend([Command(i), PressureDifference(i), Velocity(i), Cos(i)]);
            }
            out
        }
    }
}

/// The unit a signal's residual is printed in, and the factor from its SI unit.
fn display_unit(sig: Signal) -> (&'static str, f64) {
    match sig.unit() {
        "Pa" => ("MPa", 1e-6),
        "N" => ("kN", 1e-3),
        u => (u, 1.0),
    }
}

/// One dig's normal equations: `sum x x^T`, `sum x y`, `sum y^2` and the sample count.
#[derive(Debug, Clone, PartialEq)]
pub struct DigGram {
    xx: DMatrix<f64>,
    xy: DVector<f64>,
    yy: f64,
    n: usize,
}

impl DigGram {
    /// Empty equations of `p` regressors.
    pub fn new(p: usize) -> Self {
        Self {
            xx: DMatrix::zeros(p, p),
            xy: DVector::zeros(p),
            yy: 0.0,
            n: 0,
        }
    }

    /// Adds one sample: regressor values `x` (as many as the equations have) and residual `y`.
    pub fn add(&mut self, x: &[f64], y: f64) {
        let x = DVector::from_column_slice(x);
        self.xx.ger(1.0, &x, &x, 1.0);
        self.xy.axpy(y, &x, 1.0);
        self.yy += y * y;
        self.n += 1;
    }

    fn add_scaled(&mut self, other: &DigGram, weight: f64) {
        self.xx += &other.xx * weight;
        self.xy += &other.xy * weight;
        self.yy += other.yy * weight;
        self.n += (other.n as f64 * weight).round() as usize;
    }

    /// The equations of several digs together.
    fn sum<'a>(digs: impl IntoIterator<Item = &'a DigGram>, p: usize) -> DigGram {
        let mut out = DigGram::new(p);
        for d in digs {
            out.add_scaled(d, 1.0);
        }
        out
    }

    /// Sum of squares of `y - x^T xi`.
    fn sse(&self, xi: &DVector<f64>) -> f64 {
        (self.yy - 2.0 * xi.dot(&self.xy) + (&self.xx * xi).dot(xi)).max(0.0)
    }
}

/// Least squares on the columns `support` of the equations (zeros elsewhere): Cholesky of the
/// small normal matrix, the SVD's pseudo-inverse where it is singular.
fn solve_on(g: &DigGram, support: &[usize]) -> DVector<f64> {
    let p = g.xy.len();
    let mut xi = DVector::zeros(p);
    if support.is_empty() {
        return xi;
    }
    let a = DMatrix::from_fn(support.len(), support.len(), |r, c| {
        g.xx[(support[r], support[c])]
    });
    let b = DVector::from_fn(support.len(), |r, _| g.xy[support[r]]);
    let sol = match a.clone().cholesky() {
        Some(ch) => ch.solve(&b),
        None => a
            .svd(true, true)
            .solve(&b, 1e-12)
            .unwrap_or_else(|_| DVector::zeros(support.len())),
    };
    for (r, j) in support.iter().enumerate() {
        xi[*j] = sol[r];
    }
    xi
}

/// Sequentially thresholded least squares on `g` with column `c`'s standardised coefficient
/// `xi_c scale[c]` dropped below `threshold` (`scale`: regressor spread over the residual's).
/// Columns not `active` are never in the support.
fn stlsq(g: &DigGram, scale: &[f64], active: &[bool], threshold: f64) -> DVector<f64> {
    let mut support: Vec<usize> = (0..scale.len()).filter(|j| active[*j]).collect();
    let mut xi = solve_on(g, &support);
    for _ in 0..STLSQ_ITERATIONS {
        let kept: Vec<usize> = support
            .iter()
            .copied()
            .filter(|j| (xi[*j] * scale[*j]).abs() >= threshold)
            .collect();
        if kept.len() == support.len() {
            break;
        }
        support = kept;
        xi = solve_on(g, &support);
    }
    xi
}

/// The spread of every regressor (the constant: 1) over the residual's, from summed equations;
/// and which regressors vary at all (relative spread above 1e-6).
fn standardisation(g: &DigGram) -> (Vec<f64>, Vec<bool>) {
    let p = g.xy.len();
    let n = g.n.max(1) as f64;
    let y_mean = g.xy[0] / n;
    let y_sd = (g.yy / n - y_mean * y_mean).max(0.0).sqrt();
    let mut scale = vec![0.0; p];
    let mut active = vec![false; p];
    for j in 0..p {
        let sd = if j == 0 {
            1.0
        } else {
            let mean = g.xx[(0, j)] / n;
            let var = (g.xx[(j, j)] / n - mean * mean).max(0.0);
            let sd = var.sqrt();
            if sd <= 1e-6 * (mean.abs() + sd) || sd == 0.0 {
                continue;
            }
            sd
        };
        if y_sd > 0.0 {
            scale[j] = sd / y_sd;
            active[j] = true;
        }
    }
    (scale, active)
}

/// The ensemble's fit: per regressor its inclusion probability; the equation on the regressors
/// kept in at least [`TermConfig::min_inclusion`] of the models, and each coefficient's standard
/// deviation over the resamples.
#[derive(Debug, Clone, PartialEq)]
pub struct EnsembleFit {
    /// The STLSQ threshold chosen.
    pub threshold: f64,
    /// Share of the training residual's mean square [`EnsembleFit::equation`] removes.
    pub train_explained: f64,
    /// Share of the ensemble's models that include each regressor.
    pub inclusion: Vec<f64>,
    /// The equation: least squares on all training digs with the kept regressors alone (zero for
    /// the others).
    pub equation: Vec<f64>,
    /// Standard deviation of each coefficient of that least-squares fit over the resamples.
    pub spread: Vec<f64>,
}

/// E-SINDy on per-dig equations (first regressor the constant): for each threshold of
/// [`TermConfig::thresholds`], STLSQ on bootstrap resamples of `digs` (the same draws for each);
/// the ensemble of the threshold [`TermConfig::parsimony`] chooses.
pub fn ensemble_fit(digs: &[DigGram], config: &TermConfig) -> Option<EnsembleFit> {
    let p = digs.first()?.xy.len();
    let all = DigGram::sum(digs, p);
    let (_, active) = standardisation(&all);
    let draws = config.bootstrap.max(1);
    // The draws: how often each dig is in each resample.
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let counts: Vec<Vec<usize>> = (0..draws)
        .map(|_| {
            let mut c = vec![0; digs.len()];
            for _ in 0..digs.len() {
                c[rng.random_range(0..digs.len())] += 1;
            }
            c
        })
        .collect();
    // A resample's equations summed.
    let resample = |c: &[usize]| {
        let mut g = DigGram::new(p);
        for (d, n) in digs.iter().zip(c).filter(|(_, n)| **n > 0) {
            g.add_scaled(d, *n as f64);
        }
        g
    };
    let ensembles: Vec<(f64, Vec<Vec<f64>>)> = config
        .thresholds
        .iter()
        .map(|threshold| {
            let mut coefficients = vec![Vec::with_capacity(draws); p];
            for c in &counts {
                let g = resample(c);
                let (scale, varies) = standardisation(&g);
                let usable: Vec<bool> = active.iter().zip(&varies).map(|(a, v)| *a && *v).collect();
                let xi = stlsq(&g, &scale, &usable, *threshold);
                for (j, c) in coefficients.iter_mut().enumerate() {
                    c.push(xi[j]);
                }
            }
            (*threshold, coefficients)
        })
        .collect();
    // Each ensemble's terms (those it agrees on), refitted on all the training digs and scored
    // there; the sparsest that explains about as much as the best.
    let mut fits: Vec<EnsembleFit> = ensembles
        .into_iter()
        .map(|(threshold, coefficients)| {
            let inclusion: Vec<f64> = coefficients
                .iter()
                .map(|c| c.iter().filter(|x| **x != 0.0).count() as f64 / draws as f64)
                .collect();
            let support: Vec<usize> = (0..p)
                .filter(|j| inclusion[*j] >= config.min_inclusion)
                .collect();
            let equation = solve_on(&all, &support);
            let train_explained = if all.yy > 0.0 {
                1.0 - all.sse(&equation) / all.yy
            } else {
                0.0
            };
            EnsembleFit {
                threshold,
                train_explained,
                inclusion,
                equation: equation.iter().copied().collect(),
                spread: vec![0.0; p],
            }
        })
        .collect();
    let best = fits
        .iter()
        .map(|f| f.train_explained)
        .fold(f64::NEG_INFINITY, f64::max);
    let choice = fits
        .iter()
        .rposition(|f| f.train_explained >= config.parsimony * best)?;
    let mut fit = fits.swap_remove(choice);
    // The uncertainty: the same least squares on every resample.
    let support: Vec<usize> = (0..p)
        .filter(|j| fit.inclusion[*j] >= config.min_inclusion)
        .collect();
    let refits: Vec<DVector<f64>> = counts
        .iter()
        .map(|c| solve_on(&resample(c), &support))
        .collect();
    for j in support {
        let m = refits.iter().map(|x| x[j]).sum::<f64>() / draws as f64;
        fit.spread[j] =
            (refits.iter().map(|x| (x[j] - m).powi(2)).sum::<f64>() / draws as f64).sqrt();
    }
    Some(fit)
}

/// One term of a suggestion.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Term {
    /// The regressor, as in the equation (`(p_head − p_rod)_boom`, `sign(v_stick)`, `1`).
    pub regressor: String,
    /// Its unit (`1`: dimensionless).
    pub regressor_unit: &'static str,
    /// Coefficient (least squares on the training digs with the kept terms).
    pub coefficient: f64,
    /// Its unit (the residual's per the regressor's).
    pub unit: String,
    /// Standard deviation of the coefficient over the ensemble.
    pub uncertainty: f64,
    /// Share of the ensemble's models that include the term.
    pub inclusion: f64,
}

/// A new term suggested for one signal nothing explains.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TermSuggestion {
    /// Signal name.
    pub signal: &'static str,
    /// Unit the residual is given in (MPa for pressures, kN for forces).
    pub unit: &'static str,
    /// The terms kept, largest standardised effect first.
    pub terms: Vec<Term>,
    /// The equation as text, inclusion probabilities in brackets.
    pub equation: String,
    /// Share of the held-out residual's mean square the terms remove.
    pub heldout_explained: f64,
    /// Held-out residual RMS before and with the terms (in `unit`).
    pub heldout_rms: (f64, f64),
    /// Samples (training, held out).
    pub samples: (usize, usize),
    /// Models in the ensemble.
    pub bootstrap: usize,
    /// The STLSQ threshold the out-of-bag digs chose ([`TermConfig::thresholds`]).
    pub threshold: f64,
}

impl TermSuggestion {
    /// `+0.012 m/s·sign(v_boom) [0.95]` per term, joined.
    fn equation_of(signal: &str, terms: &[Term]) -> String {
        let mut s = format!("{signal} residual ≈");
        for (k, t) in terms.iter().enumerate() {
            let sign = match (k, t.coefficient < 0.0) {
                (0, false) => " ",
                (0, true) => " −",
                (_, false) => " + ",
                (_, true) => " − ",
            };
            let factor = if t.regressor == "1" {
                String::new()
            } else {
                format!("·{}", t.regressor)
            };
            let _ = write!(
                s,
                "{sign}{} {}{factor} [{:.2}]",
                format_number(t.coefficient.abs()),
                t.unit,
                t.inclusion
            );
        }
        s
    }
}

/// Three significant digits without an exponent where it reads well.
fn format_number(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let e = x.abs().log10().floor();
    if (-3.0..4.0).contains(&e) {
        let decimals = (2.0 - e).max(0.0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.2e}")
    }
}

/// Suggests a term for each of `signals` (those left beyond the reference) from the residuals of
/// the model `params` + `aug`: the ensemble fitted on `train`, scored on `test`. A signal gets a
/// suggestion only when some term passes the inclusion threshold and the terms remove
/// [`TermConfig::min_explained`] of the held-out residual's mean square.
pub fn suggest(
    signals: &[Signal],
    train: &[&PreparedRecord],
    test: &[&PreparedRecord],
    (params, aug): (&GreyBoxParams, &Augmentation),
    config: &TermConfig,
) -> Vec<TermSuggestion> {
    if signals.is_empty() {
        return Vec::new();
    }
    let libraries: Vec<Vec<Regressor>> = signals.iter().map(|s| library(*s)).collect();
    let mut pred = Vec::new();
    let mut equations = |records: &[&PreparedRecord]| -> Vec<Vec<DigGram>> {
        let mut out: Vec<Vec<DigGram>> = vec![Vec::new(); signals.len()];
        let mut x = Vec::new();
        for rec in records {
            replay(rec, params, aug, SignalGroups::ALL, &mut pred);
            for ((sig, lib), digs) in signals.iter().zip(&libraries).zip(&mut out) {
                let j = sig.index();
                let (_, to_display) = display_unit(*sig);
                let mut g = DigGram::new(lib.len());
                for (k, (m, p)) in rec.measured.iter().zip(&pred).enumerate() {
                    let y = (m[j] - p[j]) * to_display;
                    if !y.is_finite() {
                        continue;
                    }
                    x.clear();
                    x.extend(lib.iter().map(|r| r.value(rec, k)));
                    if x.iter().all(|v| v.is_finite()) {
                        g.add(&x, y);
                    }
                }
                if g.n > 0 {
                    digs.push(g);
                }
            }
        }
        out
    };
    let train_eq = equations(train);
    let test_eq = equations(test);
    let mut out = Vec::new();
    for (((sig, lib), tr), te) in signals.iter().zip(&libraries).zip(&train_eq).zip(&test_eq) {
        if tr.len() < 2 || te.is_empty() {
            continue;
        }
        let Some(fit) = ensemble_fit(tr, config) else {
            continue;
        };
        let p = lib.len();
        let xi = DVector::from_vec(fit.equation.clone());
        let keep: Vec<usize> = (0..p).filter(|j| xi[*j] != 0.0).collect();
        if keep.is_empty() {
            continue;
        }
        let held = DigGram::sum(te, p);
        if held.yy <= 0.0 || held.n == 0 {
            continue;
        }
        let after = held.sse(&xi);
        let explained = 1.0 - after / held.yy;
        if explained < config.min_explained {
            continue;
        }
        let all_train = DigGram::sum(tr, p);
        let (scale, _) = standardisation(&all_train);
        let (unit, _) = display_unit(*sig);
        let mut order = keep.clone();
        order.sort_by(|a, b| {
            (xi[*b] * scale[*b])
                .abs()
                .total_cmp(&(xi[*a] * scale[*a]).abs())
        });
        let terms: Vec<Term> = order
            .iter()
            .map(|j| {
                let r = lib[*j];
                Term {
                    regressor: r.name(),
                    regressor_unit: r.unit(),
                    coefficient: xi[*j],
                    unit: match r.unit() {
                        "1" => unit.to_string(),
                        ru => format!("{unit} per {ru}"),
                    },
                    uncertainty: fit.spread[*j],
                    inclusion: fit.inclusion[*j],
                }
            })
            .collect();
        let n = held.n as f64;
        out.push(TermSuggestion {
            signal: sig.name(),
            unit,
            equation: TermSuggestion::equation_of(sig.name(), &terms),
            terms,
            heldout_explained: explained,
            heldout_rms: ((held.yy / n).sqrt(), (after / n).sqrt()),
            samples: (all_train.n, held.n),
            bootstrap: config.bootstrap,
            threshold: fit.threshold,
        });
    }
    out
}

/// The signals of `names` (the verdict's unexplained ones), in signal order.
pub fn signals_named(names: &[&str]) -> Vec<Signal> {
    Signal::ALL
        .iter()
        .copied()
        .filter(|s| names.contains(&s.name()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regressors of the synthetic case: a constant and six standard normal ones.
    const P: usize = 7;
    /// The two true terms: (column, coefficient).
    const TRUE_TERMS: [(usize, f64); 2] = [(2, 0.031), (5, -0.012)];
    /// Noise of the synthetic residual (standard deviation).
    const NOISE: f64 = 0.01;

    /// Eight digs of 1500 samples: six standard normal regressors (column 4 correlated with 2),
    /// residual = the two true terms plus noise.
    fn synthetic_digs(seed: u64, terms: &[(usize, f64)]) -> Vec<DigGram> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut normal = move || {
            // Box-Muller.
            let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        (0..8)
            .map(|_| {
                let mut g = DigGram::new(P);
                for _ in 0..1500 {
                    let mut x = [1.0; P];
                    for v in x.iter_mut().skip(1) {
                        *v = normal();
                    }
                    x[4] = 0.5 * x[2] + 0.8 * x[4];
                    let y = terms.iter().map(|(j, c)| c * x[*j]).sum::<f64>() + NOISE * normal();
                    g.add(&x, y);
                }
                g
            })
            .collect()
    }

    #[test]
    fn a_residual_of_two_library_terms_is_recovered_with_its_coefficients() {
        let digs = synthetic_digs(7, &TRUE_TERMS);
        let fit = ensemble_fit(&digs, &TermConfig::default()).unwrap();
        for (j, c) in TRUE_TERMS {
            assert!(fit.inclusion[j] > 0.95, "{fit:?}");
            assert!(
                (fit.equation[j] - c).abs() < 0.1 * c.abs(),
                "term {j}: {} against {c}",
                fit.equation[j]
            );
        }
        for j in (0..P).filter(|j| TRUE_TERMS.iter().all(|(t, _)| t != j)) {
            assert!(fit.inclusion[j] < 0.2, "irrelevant term {j}: {fit:?}");
        }
        // Held out: the suggestion removes the residual but the noise.
        let held = DigGram::sum(&synthetic_digs(8, &TRUE_TERMS), P);
        let xi = DVector::from_vec(fit.equation.clone());
        let explained = 1.0 - held.sse(&xi) / held.yy;
        let expected = 1.0 - NOISE.powi(2) / (0.031f64.powi(2) + 0.012f64.powi(2) + NOISE.powi(2));
        assert!(
            (explained - expected).abs() < 0.02,
            "{explained} vs {expected}"
        );
    }

    /// A constant residual (a heavier link's gravity over the few poses it is seen in) with the
    /// cosine and sine of an angle that varies by 0.2 rad: nearly collinear with the constant.
    fn collinear_digs(seed: u64) -> Vec<DigGram> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..8)
            .map(|_| {
                let mut g = DigGram::new(4);
                let centre: f64 = rng.random_range(0.3..0.5);
                for _ in 0..200 {
                    let a = centre + rng.random_range(-0.1..0.1);
                    let y = 20.0 + rng.random_range(-3.0..3.0);
                    g.add(&[1.0, a.cos(), a.sin(), rng.random_range(-1.0..1.0)], y);
                }
                g
            })
            .collect()
    }

    #[test]
    fn nearly_collinear_terms_give_one_coherent_equation() {
        let fit = ensemble_fit(&collinear_digs(3), &TermConfig::default()).unwrap();
        let xi = DVector::from_vec(fit.equation.clone());
        let held = DigGram::sum(&collinear_digs(4), 4);
        // Noise uniform in +-3 about 20: a perfect equation removes all but 3 / (400 + 3).
        let explained = 1.0 - held.sse(&xi) / held.yy;
        assert!(explained > 0.98, "{explained}: {fit:?}");
        assert!(fit.inclusion[3] < 0.2, "{fit:?}");
    }

    #[test]
    fn pure_noise_keeps_no_term() {
        let digs = synthetic_digs(9, &[]);
        let fit = ensemble_fit(&digs, &TermConfig::default()).unwrap();
        assert!(fit.inclusion.iter().all(|p| *p < 0.2), "{fit:?}");
    }

    #[test]
    fn the_equation_reads_with_units_and_inclusions() {
        let terms = vec![
            Term {
                regressor: "(p_head − p_rod)_boom".into(),
                regressor_unit: "MPa",
                coefficient: -0.031,
                unit: "m/s per MPa".into(),
                uncertainty: 0.001,
                inclusion: 1.0,
            },
            Term {
                regressor: "sign(v_boom)".into(),
                regressor_unit: "1",
                coefficient: 0.012,
                unit: "m/s".into(),
                uncertainty: 0.001,
                inclusion: 0.95,
            },
        ];
        assert_eq!(
            TermSuggestion::equation_of("boom_velocity", &terms),
            "boom_velocity residual ≈ −0.0310 m/s per MPa·(p_head − p_rod)_boom [1.00] + 0.0120 m/s·sign(v_boom) [0.95]"
        );
    }
}
