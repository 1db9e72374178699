//! Naming the missing effect: each candidate's magnitude is fitted on the training digs (a coarse grid,
//! then golden-section search inside the bounds), scored on the held-out digs with a BIC penalty, and
//! the best significant one is added; repeated (greedy forward selection, as in sparse term selection)
//! until no candidate is significant.
//!
//! Cost: the chi-square of the residuals, each signal weighted by its nominal residual variance on the
//! training digs and by its decorrelation factor `kappa` (the integrated autocorrelation time of the
//! nominal residuals, in samples), so that `chi2 = sum_s SSE_s / (sigma_s^2 kappa_s)` behaves like
//! `-2 ln L` of independent samples and `n_eff = sum_s n_s / kappa_s`. Held-out score of a candidate:
//! `dBIC = chi2_test(0) - chi2_test(m) - ln(n_eff_test)` (one parameter), with `kappa` of the
//! candidate's own signals re-estimated on the training residuals it leaves (the noise under the
//! alternative; the nominal residual's autocorrelation includes the effect's own smooth
//! signature). It is significant when `dBIC` exceeds [`AnalysisConfig::min_delta_bic`] and it explains at least
//! [`AnalysisConfig::min_explained`] of the held-out chi-square of the signals it acts on, on the
//! samples where it changes the prediction by more than a tenth of the residual spread (or
//! `dBIC` exceeds [`AnalysisConfig::strong_delta_bic`] and it explains at least
//! [`AnalysisConfig::strong_explained`]: signals with few independent samples, the forces), and it
//! raises no signal's held-out RMS by more than 10 %; the thresholds were calibrated on
//! effect-free traces (docs/discrepancy.md). The candidate added is the significant one with the
//! largest `dBIC`; after each addition the residual spread and decorrelation are re-estimated. Uncertainty: `sqrt(2 / chi2'')` from the curvature of
//! the training cost at the optimum (Fisher information), the `kappa` weighting making it honest for
//! correlated samples.
//!
//! Layout: `trial` (the candidates of the selection), `cost` (replay, sums of squares, the noise
//! model), `search` (a candidate's magnitude by grid and Brent search), `confusable` (joint fits
//! of correlated candidates); this module runs the selection over them.

use serde::Serialize;

use super::effects::{Candidate, CandidateEffect as _};
use super::greybox::{
    Augmentation, GreyBoxParams, N_SIGNALS, PreparedRecord, Signal, SignalGroups, replay,
};
use super::parameters::ParameterLibrary;
use super::stats::{self, ResidualSummary};
use super::{DiscrepancyError, Result};

mod confusable;
mod cost;
mod search;
mod trial;

use confusable::{Resolution, Round, resolve_confusable};
use cost::{
    Evaluator, HeldOutSse, Weights, chi2, decorrelation, groups_contain, noise_model, weights_of,
};
use search::minimise;
use trial::Trial;

/// Settings of the analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AnalysisConfig {
    /// The candidates to try.
    pub candidates: Vec<Candidate>,
    /// Minimum held-out BIC improvement for a candidate to be significant.
    pub min_delta_bic: f64,
    /// Minimum fraction of the held-out chi-square a candidate must explain on the samples where it
    /// acts (with [`AnalysisConfig::min_delta_bic`]). Default 0.15 (0.05 until 2026-11-26: with the
    /// replay warmed up after gaps the hydraulic residual spread fell, and 5.8-23 kPa pressure
    /// offsets explaining 8.8-9.8 % where they act passed in two soil sessions; every correctly
    /// named effect explains at least 19 % there, the smallest leakage; docs/discrepancy.md).
    pub min_explained: f64,
    /// A candidate is also significant with a smaller held-out BIC improvement, at least this one,
    /// if it explains at least [`AnalysisConfig::strong_explained`] of the held-out chi-square of
    /// its signals (signals with few independent samples, such as the cylinder forces, cannot reach
    /// [`AnalysisConfig::min_delta_bic`] however well an effect explains them).
    pub strong_delta_bic: f64,
    /// The explained fraction that goes with [`AnalysisConfig::strong_delta_bic`].
    pub strong_explained: f64,
    /// At most this many effects are named.
    pub max_effects: usize,
    /// Coarse grid points before the golden-section search.
    pub grid_points: usize,
    /// Golden-section iterations.
    pub golden_iterations: usize,
    /// The model's effects before the analysis (from `--model`); their candidates are not refitted,
    /// except those in `refit`.
    pub base: Augmentation,
    /// Candidates of `base` fitted again (the starting model's own effects and the calibration on a
    /// reference: a healthy machine's own transport delay must not hide a larger one); a named
    /// one's magnitude is the change on top of `base`.
    pub refit: Vec<Candidate>,
    /// The machine's own parameters as candidates (parameter drift), derived from its file; none
    /// without it.
    #[serde(skip)]
    pub parameters: Option<ParameterLibrary>,
    /// The signals a candidate may be named for: one acting on none of them is not tried. Judged
    /// against a reference, the signals beyond it with the starting model (and those it cannot
    /// judge): a candidate that only lowers residuals the reference expects fits noise, or stands
    /// in for what another candidate explains elsewhere. `None`: every signal.
    pub eligible: Option<[bool; N_SIGNALS]>,
    /// Judged against a reference, each signal's expected residual RMS (0 where the reference
    /// cannot say): a candidate makes a signal clearly worse only beyond both its RMS without the
    /// candidate and this level. (A healthy machine's own residual can cancel a model error by
    /// chance: the nominal boom force's free-air bias of about -2.4 kN hid most of a +0.2 MPa
    /// pressure offset's +2 kN, so the right offset raised the boom force's RMS by 11 %, to 1.0x
    /// the expected level, and was vetoed.) `None`: the RMS without the candidate alone.
    pub expected_rms: Option<[f64; N_SIGNALS]>,
    /// Signals taken as evidence for no candidate (weight 0 in every chi-square): the weighed
    /// payload when the empty bucket's free-air forces show the links' mass properties off, as it
    /// is weighed through the same links (a 20 % heavier stick weighed 184 kg of payload more than
    /// the reference, and an 11.5 kPa pressure offset, whose payload term is the only one it has
    /// of that size, was named for it).
    pub ignored: [bool; N_SIGNALS],
}

impl Default for AnalysisConfig {
    fn default() -> Self {
        Self {
            candidates: Candidate::ALL.to_vec(),
            min_delta_bic: 150.0,
            min_explained: 0.15,
            strong_delta_bic: 25.0,
            strong_explained: 0.2,
            max_effects: 3,
            grid_points: 9,
            golden_iterations: 12,
            base: Augmentation::nominal(),
            refit: Vec::new(),
            parameters: None,
            eligible: None,
            expected_rms: None,
            ignored: [false; N_SIGNALS],
        }
    }
}

/// A candidate's fit and score in one round of the forward selection.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CandidateScore {
    /// Effect name (the simulator's) or machine-file key.
    pub name: String,
    /// Fitted magnitude, in the simulator's unit (a parameter: the factor on the file's value
    /// less 1).
    pub magnitude: f64,
    /// Standard uncertainty of the magnitude.
    pub uncertainty: f64,
    /// Training chi-square drop.
    pub train_chi2_drop: f64,
    /// Held-out BIC improvement (positive = better than without it).
    pub heldout_delta_bic: f64,
    /// Fraction of the held-out chi-square of its signals it explains.
    pub heldout_explained: f64,
    /// Fraction of the held-out chi-square of its signals it explains on the samples where it
    /// changes the prediction by more than a tenth of the residual spread.
    pub heldout_explained_acted: f64,
    /// Whether it passed the thresholds and worsened no signal by more than 10 %.
    pub significant: bool,
    /// Why it is not significant (`None` when it is): the signal it makes worse, a magnitude
    /// within three uncertainties of zero, no signal beyond the reference lowered, or too small a
    /// gain.
    pub veto: Option<String>,
}

/// An effect the analysis named.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NamedEffect {
    /// Effect name (the simulator's, `excavator-sim --list-effects`), or the machine file's key of
    /// a parameter.
    pub name: String,
    /// What kind of candidate it is: `effect` (the effect library) or `parameter` (a machine-file
    /// field, [`crate::parameters`]).
    pub kind: &'static str,
    /// Fitted magnitude (a parameter: the fitted value in the machine file's units).
    pub magnitude: f64,
    /// Standard uncertainty.
    pub uncertainty: f64,
    /// Unit of the magnitude.
    pub unit: &'static str,
    /// What the effect is.
    pub description: String,
    /// Held-out BIC improvement when it was added (the second of a joint fit: its gain over the
    /// first alone).
    pub heldout_delta_bic: f64,
    /// The confusable candidate it was fitted jointly with (both named, each with the joint
    /// fit's magnitude and marginal uncertainty).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fitted_jointly_with: Option<String>,
}

/// One candidate of an ambiguous pair: its fit alone and in the joint fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AmbiguousCandidate {
    /// Effect name or machine-file key.
    pub name: String,
    /// `effect` or `parameter`.
    pub kind: &'static str,
    /// Unit of the magnitudes (a parameter: the value in the machine file's units).
    pub unit: &'static str,
    /// Its magnitude fitted alone.
    pub alone: f64,
    /// Uncertainty of that.
    pub alone_uncertainty: f64,
    /// Held-out BIC improvement alone.
    pub alone_delta_bic: f64,
    /// Its magnitude in the joint fit of the pair.
    pub joint: f64,
    /// Its marginal uncertainty in the joint fit (from the joint cost's curvature).
    pub joint_uncertainty: f64,
}

/// Two confusable candidates the data cannot tell apart: their effects on the predictions are
/// alike, either alone explains the residual about as well, and the joint fit does not separate
/// them. Reported with both fits instead of naming one.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ambiguity {
    /// The two candidates, the better one alone first.
    pub candidates: [AmbiguousCandidate; 2],
    /// Correlation of their fitted effects on the training predictions (chi-square weighted).
    pub effect_correlation: f64,
    /// Correlation of their magnitudes in the joint fit (from its covariance).
    pub parameter_correlation: f64,
    /// Held-out BIC gain of the joint fit over the better one alone.
    pub joint_gain_delta_bic: f64,
    /// Which one the written model carries (the better one alone).
    pub in_model: String,
    /// What it means, for the report.
    pub note: String,
}

/// Held-out residual RMS of one signal before and after the augmentation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SignalRms {
    /// Signal name.
    pub signal: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Samples.
    pub samples: usize,
    /// RMS with the nominal model.
    pub before: f64,
    /// RMS with the augmented model.
    pub after: f64,
    /// Per Autodig stage: `(stage, samples, before, after)`.
    pub per_stage: Vec<(&'static str, usize, f64, f64)>,
    /// Where the augmentation acts: `(samples, before, after)` over the samples whose prediction it
    /// moves by more than a tenth of the signal's nominal residual spread (the same share of samples
    /// the significance test's "acted" figure takes; a flow sharing acts only while the boom and
    /// bucket valves are open together, a leakage only across a pressure difference). Zeros when
    /// it acts nowhere.
    pub acted: (usize, f64, f64),
}

/// Everything the analysis found.
#[derive(Debug, Clone, Serialize)]
pub struct AnalysisResult {
    /// Named effects, in the order they were added (empty: "no missing effect found").
    pub named_effects: Vec<NamedEffect>,
    /// Confusable candidates the data cannot tell apart, reported instead of naming either.
    pub ambiguous: Vec<Ambiguity>,
    /// The final augmentation (magnitudes per candidate; of an ambiguous pair, the better one's
    /// fit alone).
    pub augmentation: Augmentation,
    /// The final grey-box parameters (the starting model's, with the named machine parameters).
    #[serde(skip)]
    pub params: GreyBoxParams,
    /// Every round's candidate scores.
    pub rounds: Vec<Vec<CandidateScore>>,
    /// Held-out residual RMS per signal, before and after.
    pub rms: Vec<SignalRms>,
    /// Localisation of the nominal residuals on all digs (per signal, stage and regime; whiteness,
    /// cross-correlation with the inputs).
    pub localisation: Vec<ResidualSummary>,
    /// Dig indices used for training.
    pub train_digs: Vec<u32>,
    /// Dig indices held out.
    pub test_digs: Vec<u32>,
    /// Samples per signal in the training digs (the held-out ones are in `rms`).
    pub train_samples: Vec<usize>,
    /// Nominal residual standard deviation per signal on the training digs.
    pub sigma: Vec<f64>,
    /// Decorrelation factor per signal (samples per independent sample).
    pub kappa: Vec<f64>,
}

/// A candidate acts on a sample's signal where it moves the prediction by more than this fraction
/// of the signal's residual spread; its explained share is taken over those samples.
const ACTED_FRACTION: f64 = 0.1;

/// A named magnitude must differ from zero by more than this many standard uncertainties (Wald
/// test): a magnitude at the search's resolution is no effect, however the held-out cost reacts.
const MIN_MAGNITUDE_Z: f64 = 3.0;

/// A candidate may raise no signal's held-out RMS by more than this factor.
const MAX_SIGNAL_WORSENING: f64 = 1.1;

/// Judged against a reference, a candidate must lower the held-out RMS of one of the signals it may
/// be named for ([`AnalysisConfig::eligible`]) at least to this factor: one whose gain comes from
/// signals the reference expects as they are fits noise there or stands in for something else (a
/// 20 % heavier stick, its boom and stick forces beyond the reference: an 11 kPa pressure offset
/// lowered them by 0.8 % and raised them by 3.3 %, its gain from the stick velocity, 1.0x the
/// expected level; a 30 MPa relief: the tank pressure 4 % up, the one signal beyond, the boom
/// velocity, 0.7 % lower; they explained 16 and 19 % where they act). Exempt: a candidate that
/// explains at least [`DECISIVE_EXPLAINED_ACTED`] where it acts, an effect confined to few samples
/// (a 30 MPa relief: 94 % on the samples at the relief, which no signal's RMS over the session
/// shows beyond the reference).
const MIN_ELIGIBLE_REDUCTION: f64 = 0.95;

/// See [`MIN_ELIGIBLE_REDUCTION`].
const DECISIVE_EXPLAINED_ACTED: f64 = 0.5;

/// Runs the workflow on prepared records: split, nominal residuals, localisation, forward selection,
/// before/after RMS. `progress(done, total)` is called after every candidate fit.
///
/// # Errors
/// [`DiscrepancyError::NotEnoughData`] for fewer than two records or no usable samples.
pub fn analyse(
    records: &[PreparedRecord],
    params: &GreyBoxParams,
    config: &AnalysisConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<AnalysisResult> {
    if records.len() < 2 {
        return Err(DiscrepancyError::NotEnoughData(format!(
            "{} dig(s): at least two are needed (training and held-out)",
            records.len()
        )));
    }
    let mut order: Vec<&PreparedRecord> = records.iter().collect();
    order.sort_by_key(|r| r.index);
    let train: Vec<&PreparedRecord> = order.iter().step_by(2).copied().collect();
    let test: Vec<&PreparedRecord> = order.iter().skip(1).step_by(2).copied().collect();

    let nominal = config.base;
    let mut train_eval = Evaluator::new(train.clone(), params, &nominal);
    let mut test_eval = Evaluator::new(test.clone(), params, &nominal);
    let (_, n0) = train_eval.base_sse();
    if n0.iter().all(|n| *n == 0) {
        return Err(DiscrepancyError::NotEnoughData(
            "no usable samples in the training digs".into(),
        ));
    }
    // Nominal residual spread and decorrelation per signal (training digs only).
    let (sigma, kappa) = noise_model(&train, &train_eval.base);
    let (_, n_test) = test_eval.base_sse();
    let n_eff = |inv_var: &[f64; N_SIGNALS], kappa: &[f64]| {
        (0..N_SIGNALS)
            .filter(|j| inv_var[*j] > 0.0)
            .map(|j| n_test[j] as f64 / kappa[j])
            .sum::<f64>()
            .max(2.0)
    };

    let localisation = stats::localise(&order, params, &nominal);

    let mut aug = config.base;
    let mut params_now = params.clone();
    let mut named = Vec::new();
    let mut ambiguous = Vec::new();
    let mut rounds = Vec::new();
    let mut remaining: Vec<Trial> = config
        .candidates
        .iter()
        .copied()
        .filter(|c| config.base.get(*c) == 0.0 || config.refit.contains(c))
        .map(Trial::Effect)
        .chain(
            config
                .parameters
                .iter()
                .flat_map(|l| (0..l.parameters.len()).map(Trial::Parameter)),
        )
        .filter(|t| {
            config.eligible.is_none_or(|e| {
                (0..N_SIGNALS)
                    .any(|j| e[j] && groups_contain(t.groups(config.parameters.as_ref()), j))
            })
        })
        .collect();
    let n_trials = remaining.len();
    let total = n_trials * (config.max_effects + 1).min(n_trials + 1);
    let mut done = 0;
    while named.len() + ambiguous.len() < config.max_effects && !remaining.is_empty() {
        // The residual spread and decorrelation of the model as it stands this round (after an
        // effect is added, the noise is re-estimated, as in forward selection).
        let (sigma_r, kappa_r) = if named.is_empty() {
            (sigma.clone(), kappa.clone())
        } else {
            noise_model(&train, &train_eval.base)
        };
        let mut w = Weights {
            inv_var: weights_of(&sigma_r, &kappa_r, &n0),
        };
        for (v, ignored) in w.inv_var.iter_mut().zip(config.ignored) {
            if ignored {
                *v = 0.0;
            }
        }
        let train_chi0 = chi2(&w, &train_eval.base_sse().0);
        let test_base_sse = test_eval.base_sse().0;
        let mut scores: Vec<(Trial, CandidateScore)> = Vec::new();
        for c in &remaining {
            let c = *c;
            let library = config.parameters.as_ref();
            let groups = c.groups(library);
            let (lo, hi) = c.range(library);
            // The model with the trial at `x`: an effect's magnitude, or a parameter's factor on
            // the file's value (`None`: the machine file is not valid there).
            let at = |x: f64| c.at(x, &aug, &params_now, library);
            let mut cost = |x: f64| match at(x) {
                Some((a, p)) => chi2(&w, &train_eval.sse_with(&a, p.as_ref(), groups)),
                None => f64::INFINITY,
            };
            let (x, fx) = minimise(
                &mut cost,
                lo,
                hi,
                config.grid_points,
                config.golden_iterations,
            );
            // Curvature of the training chi-square at the optimum (Fisher information).
            let h = (0.05 * x.abs()).max(0.005 * c.scale());
            let (xm, xp) = ((x - h).max(lo), (x + h).min(hi));
            let (fm, fp) = (cost(xm), cost(xp));
            let curvature = if xp > x && x > xm {
                2.0 * ((fp - fx) / (xp - x) - (fx - fm) / (x - xm)) / (xp - xm)
            } else {
                let (x1, f1, x2, f2) = if xp > x {
                    (x, fx, xp, fp)
                } else {
                    (xm, fm, x, fx)
                };
                // One-sided at a bound: the slope over the step, as a lower bound of the curvature.
                ((f2 - f1) / (x2 - x1)).abs() / h
            };
            let uncertainty = if curvature.is_finite() && curvature > 0.0 {
                (2.0 / curvature).sqrt()
            } else {
                c.scale()
            };
            let Some((a, p)) = at(x) else {
                continue;
            };
            // The decorrelation of the noise the candidate leaves (training digs): the nominal
            // residual's autocorrelation includes the candidate's own signature, which is smooth
            // where the effect is (a viscous friction `c v` follows the speed over a whole stroke:
            // stick and bucket force kappa 56 and 25 with a hidden 2e5 N s/m against 1.0 and 1.1
            // effect-free), so with it a real effect's held-out chi-square counted as a few dozen
            // independent samples. The test is against the noise under the alternative (as an F
            // test takes the full model's residual); the spread stays the nominal one (larger,
            // conservative), and a candidate fitted near zero leaves the noise model as it was.
            train_eval.sse_with(&a, p.as_ref(), groups);
            let mut kappa_c = kappa_r.clone();
            let mut w_c = w;
            for j in (0..N_SIGNALS).filter(|j| groups_contain(groups, *j)) {
                if w.inv_var[j] > 0.0 {
                    kappa_c[j] = decorrelation(&train, &train_eval.scratch, j);
                    w_c.inv_var[j] = 1.0 / (sigma_r[j] * sigma_r[j] * kappa_c[j]);
                }
            }
            let test_chi0_c = chi2(&w_c, &test_base_sse);
            let test_sse = test_eval.sse_with(&a, p.as_ref(), groups);
            let test_chi = chi2(&w_c, &test_sse);
            let delta_bic = test_chi0_c - test_chi - n_eff(&w_c.inv_var, &kappa_c).ln();
            // Explained share of the held-out chi-square of the signals the candidate acts on (a
            // friction must explain the forces, not the whole record) ...
            let own: f64 = (0..N_SIGNALS)
                .filter(|j| groups_contain(groups, *j))
                .map(|j| test_base_sse[j] * w_c.inv_var[j])
                .sum();
            let explained = if own > 0.0 {
                (test_chi0_c - test_chi) / own
            } else {
                0.0
            };
            // ... and on the samples where it acts at all (a flow sharing acts only while the boom
            // and bucket valves are open together, a pump saturation only at the flow limit).
            let [own0, own1] = test_eval.acted_chi2(&w_c, &sigma_r, groups);
            let explained_acted = if own0 > 0.0 {
                (own0 - own1) / own0
            } else {
                0.0
            };
            // A physical augmentation that is right does not make any signal clearly worse.
            let held_out = HeldOutSse {
                with: &test_sse,
                without: &test_base_sse,
                samples: &n_test,
            };
            let worsened = held_out.most_worsened(config.expected_rms.as_ref());
            // The change on top of the starting model (a refitted calibration's value included).
            let change = x - c.base(&config.base);
            let gain = (delta_bic > config.min_delta_bic && explained_acted > config.min_explained)
                || (delta_bic > config.strong_delta_bic && explained > config.strong_explained);
            let lowers_eligible = explained_acted >= DECISIVE_EXPLAINED_ACTED
                || config
                    .eligible
                    .is_none_or(|e| held_out.lowers_any(&e, groups));
            let veto = if let Some((j, f)) = worsened {
                Some(format!("worsens {} {f:.2}x", Signal::ALL[j].name()))
            } else if change.abs() <= MIN_MAGNITUDE_Z * uncertainty {
                Some(format!("within {MIN_MAGNITUDE_Z} uncertainties of zero"))
            } else if !lowers_eligible {
                Some(format!(
                    "lowers no signal beyond the reference to {MIN_ELIGIBLE_REDUCTION} of its RMS \
                     (explains {explained_acted:.3} where it acts)"
                ))
            } else if !gain {
                Some(format!(
                    "gain too small (explained {explained:.3}, where it acts {explained_acted:.3})"
                ))
            } else {
                None
            };
            let significant = veto.is_none();
            scores.push((
                c,
                CandidateScore {
                    name: c.name(library),
                    magnitude: change,
                    uncertainty,
                    train_chi2_drop: train_chi0 - fx,
                    heldout_delta_bic: delta_bic,
                    heldout_explained: explained,
                    heldout_explained_acted: explained_acted,
                    significant,
                    veto,
                },
            ));
            done += 1;
            progress(done, total);
        }
        scores.sort_by(|a, b| b.1.heldout_delta_bic.total_cmp(&a.1.heldout_delta_bic));
        // The significant candidate with the largest held-out BIC gain. (A pressure offset that
        // collects a large gain from small improvements spread over every pressure signal is not
        // significant: it explains little on the samples it acts on. Before the explained share
        // was taken there, candidates explaining `strong_explained` of their signals were
        // preferred, which passed over a 0.2 MPa pressure offset for a resolver offset.)
        let best = scores.iter().find(|(_, s)| s.significant).cloned();
        let library = config.parameters.as_ref();
        let round = Round {
            w,
            sigma: &sigma_r,
            kappa: &kappa_r,
            test_base_sse,
            n_test,
            config,
        };
        let resolution = match &best {
            Some((c, s)) => resolve_confusable(
                (&mut train_eval, &mut test_eval),
                &train,
                (*c, s),
                &scores,
                &round,
                (&aug, &params_now),
            ),
            None => Resolution::Alone,
        };
        rounds.push(scores.into_iter().map(|(_, s)| s).collect());
        let Some((c, s)) = best else {
            break;
        };
        match resolution {
            Resolution::Alone => {
                add_trial(c, s.magnitude, config, &mut aug, &mut params_now)?;
                named.push(named_entry(
                    c,
                    (s.magnitude, s.uncertainty, s.heldout_delta_bic),
                    library,
                    None,
                ));
            }
            Resolution::Both {
                other,
                changes,
                uncertainties,
                gain,
            } => {
                add_trial(c, changes[0], config, &mut aug, &mut params_now)?;
                add_trial(other, changes[1], config, &mut aug, &mut params_now)?;
                named.push(named_entry(
                    c,
                    (changes[0], uncertainties[0], s.heldout_delta_bic),
                    library,
                    Some(other.name(library)),
                ));
                named.push(named_entry(
                    other,
                    (changes[1], uncertainties[1], gain),
                    library,
                    Some(c.name(library)),
                ));
                remaining.retain(|r| *r != other);
            }
            Resolution::Ambiguous { other, ambiguity } => {
                add_trial(c, s.magnitude, config, &mut aug, &mut params_now)?;
                ambiguous.push(*ambiguity);
                remaining.retain(|r| *r != other);
            }
        }
        remaining.retain(|r| *r != c);
        train_eval = Evaluator::new(train.clone(), &params_now, &aug);
        test_eval = Evaluator::new(test.clone(), &params_now, &aug);
    }
    progress(total, total);

    let rms = before_after(&test, (params, &config.base), (&params_now, &aug), &sigma);
    Ok(AnalysisResult {
        named_effects: named,
        ambiguous,
        augmentation: aug,
        params: params_now,
        rounds,
        rms,
        localisation,
        train_digs: train.iter().map(|r| r.index).collect(),
        test_digs: test.iter().map(|r| r.index).collect(),
        train_samples: n0.to_vec(),
        sigma,
        kappa,
    })
}

/// Adds trial `c` at `change` on top of the starting model to the model in use.
fn add_trial(
    c: Trial,
    change: f64,
    config: &AnalysisConfig,
    aug: &mut Augmentation,
    params: &mut GreyBoxParams,
) -> Result<()> {
    match (c, config.parameters.as_ref()) {
        (Trial::Effect(e), _) => aug.set(e, config.base.get(e) + change),
        (Trial::Parameter(i), Some(l)) => *params = l.apply(params, i, 1.0 + change)?,
        (Trial::Parameter(_), None) => {}
    }
    Ok(())
}

/// The report entry of trial `c` named at `(change, uncertainty, held-out dBIC)`.
fn named_entry(
    c: Trial,
    (change, uncertainty, heldout_delta_bic): (f64, f64, f64),
    library: Option<&ParameterLibrary>,
    fitted_jointly_with: Option<String>,
) -> NamedEffect {
    let (kind, magnitude, uncertainty, unit) = c.reported(change, uncertainty, library);
    let description = match (c, library) {
        (Trial::Parameter(i), Some(l)) => {
            let p = &l.parameters[i];
            format!(
                "machine-file parameter {} = {:.6} {} ({:+.1} % of the file's {}): \
                 write it back to the machine file",
                p.key,
                magnitude,
                p.unit,
                100.0 * change,
                p.nominal
            )
        }
        (Trial::Effect(e), _) => e.model_description().to_string(),
        (Trial::Parameter(i), None) => format!("parameter {i}"),
    };
    NamedEffect {
        name: c.name(library),
        kind,
        magnitude,
        uncertainty,
        unit,
        description,
        heldout_delta_bic,
        fitted_jointly_with,
    }
}

/// Residual RMS per signal (and per stage, and where the augmentation acts by more than
/// a tenth of `sigma`) of records under the model `before` and the augmented one.
pub fn before_after(
    records: &[&PreparedRecord],
    (params, before): (&GreyBoxParams, &Augmentation),
    (params_after, aug): (&GreyBoxParams, &Augmentation),
    sigma: &[f64],
) -> Vec<SignalRms> {
    let nominal = *before;
    let mut acc = vec![([0.0; 2], 0usize); N_SIGNALS];
    let mut acted_acc = vec![([0.0; 2], 0usize); N_SIGNALS];
    let mut stage_acc = vec![vec![([0.0; 2], 0usize); super::StageTag::ALL.len()]; N_SIGNALS];
    let (mut p0, mut p1) = (Vec::new(), Vec::new());
    for rec in records {
        replay(rec, params, &nominal, SignalGroups::ALL, &mut p0);
        replay(rec, params_after, aug, SignalGroups::ALL, &mut p1);
        for (k, m) in rec.measured.iter().enumerate() {
            let st = super::StageTag::ALL
                .iter()
                .position(|s| *s == rec.samples[k].stage)
                .unwrap_or(0);
            for j in 0..N_SIGNALS {
                let (r0, r1) = (m[j] - p0[k][j], m[j] - p1[k][j]);
                if r0.is_finite() && r1.is_finite() {
                    acc[j].0[0] += r0 * r0;
                    acc[j].0[1] += r1 * r1;
                    acc[j].1 += 1;
                    stage_acc[j][st].0[0] += r0 * r0;
                    stage_acc[j][st].0[1] += r1 * r1;
                    stage_acc[j][st].1 += 1;
                    let spread = sigma.get(j).copied().unwrap_or(0.0);
                    if (p1[k][j] - p0[k][j]).abs() > ACTED_FRACTION * spread {
                        acted_acc[j].0[0] += r0 * r0;
                        acted_acc[j].0[1] += r1 * r1;
                        acted_acc[j].1 += 1;
                    }
                }
            }
        }
    }
    let rms = |s: f64, n: usize| if n > 0 { (s / n as f64).sqrt() } else { 0.0 };
    Signal::ALL
        .iter()
        .map(|sig| {
            let j = sig.index();
            SignalRms {
                signal: sig.name(),
                unit: sig.unit(),
                samples: acc[j].1,
                before: rms(acc[j].0[0], acc[j].1),
                after: rms(acc[j].0[1], acc[j].1),
                per_stage: super::StageTag::ALL
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| stage_acc[j][*i].1 > 0)
                    .map(|(i, st)| {
                        let (s, n) = stage_acc[j][i];
                        (st.name(), n, rms(s[0], n), rms(s[1], n))
                    })
                    .collect(),
                acted: {
                    let (s, n) = acted_acc[j];
                    (n, rms(s[0], n), rms(s[1], n))
                },
            }
        })
        .collect()
}

#[cfg(test)]
mod parameter_tests {
    use super::confusable::CONFUSABLE_CORRELATION;
    use super::*;
    use crate::parameters::ParameterLibrary;
    use crate::{DigRecord, LoadTag, Sample, StageTag};
    use planner::machine::MachineConfig;

    /// Records whose measured velocities and pump pressures are the replay of `truth` (grey-box
    /// parameters and effects) under the valve commands `command(t, record index)`, plus a little
    /// noise, prepared for the nominal model.
    fn synthetic_records(
        command: impl Fn(f64, u32) -> [f64; 3],
        truth: impl Fn(&GreyBoxParams) -> (GreyBoxParams, Augmentation),
    ) -> (Vec<PreparedRecord>, GreyBoxParams) {
        let cfg = MachineConfig::default_machine().unwrap();
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let (truth_params, truth_aug) = truth(&params);
        let mut noise = 0x2545_f491_u64;
        let mut records = Vec::new();
        for index in 0..6u32 {
            let samples = (0..600)
                .map(|k| {
                    let t = 0.01 * f64::from(k);
                    Sample {
                        time_s: t,
                        command: command(t, index),
                        angles_rad: [0.3, -1.5, -1.0],
                        head_pa: [8.0e6, 6.0e6, 4.0e6],
                        rod_pa: [1.5e6, 1.2e6, 1.0e6],
                        pump_pa: [11.0e6, 9.0e6],
                        stage: StageTag::Outside,
                        load: LoadTag::EmptyFreeAir,
                        ..Sample::default()
                    }
                })
                .collect();
            let record = DigRecord {
                index,
                samples,
                section: None,
                lanes: Vec::new(),
            };
            let mut rec = PreparedRecord::new(&record, &cfg, &params).unwrap();
            let mut out = Vec::new();
            replay(&rec, &truth_params, &truth_aug, SignalGroups::ALL, &mut out);
            for (m, p) in rec.measured.iter_mut().zip(&out) {
                for j in 0..5 {
                    noise ^= noise << 13;
                    noise ^= noise >> 7;
                    noise ^= noise << 17;
                    let e = (noise % 2001) as f64 / 1000.0 - 1.0;
                    let scale = if j < 3 { 2.0e-3 } else { 5.0e4 };
                    m[j] = p[j] + e * scale;
                }
            }
            records.push(rec);
        }
        (records, params)
    }

    /// A slow sinusoidal command on the three valves.
    fn sine_command(t: f64, index: u32) -> [f64; 3] {
        let u = 0.6 * (t * (1.3 + 0.1 * f64::from(index))).sin();
        [u, -0.8 * u, 0.5 * u]
    }

    /// Records of a machine with the valve discharge coefficient 0.85 times the file's.
    fn drifted_records() -> (Vec<PreparedRecord>, GreyBoxParams, ParameterLibrary) {
        let cfg = MachineConfig::default_machine().unwrap();
        let library = ParameterLibrary::derive(&cfg).unwrap();
        let cd = library
            .find("hydraulics.valve_discharge_coefficient")
            .unwrap();
        let (records, params) = synthetic_records(sine_command, |p| {
            (library.apply(p, cd, 0.85).unwrap(), Augmentation::nominal())
        });
        (records, params, library)
    }

    /// Step commands: a new level on every valve every 0.4 s, different per record.
    fn step_command(t: f64, index: u32) -> [f64; 3] {
        let step = (t / 0.4) as u32 + 7 * index;
        let level = |k: u32| [0.7, -0.5, 0.3, -0.8, 0.55, -0.25, 0.85][(k % 7) as usize];
        [level(step), level(step + 2), level(step + 4)]
    }

    fn timing_analysis(
        command: fn(f64, u32) -> [f64; 3],
        delay_s: f64,
        lag_s: f64,
    ) -> AnalysisResult {
        let (records, params) = synthetic_records(command, |p| {
            let mut a = Augmentation::nominal();
            a.set(Candidate::TransportDelay, delay_s);
            a.set(Candidate::HydraulicLag, lag_s);
            (p.clone(), a)
        });
        let config = AnalysisConfig {
            candidates: vec![Candidate::TransportDelay, Candidate::HydraulicLag],
            ..AnalysisConfig::default()
        };
        analyse(&records, &params, &config, &mut |_, _| {}).unwrap()
    }

    /// A transport delay and a hydraulic lag together, on commands with steps that tell them
    /// apart, are fitted jointly and both named within 25 %, not lumped into one delay.
    #[test]
    fn a_delay_and_a_lag_together_are_both_named_from_a_joint_fit() {
        let result = timing_analysis(step_command, 0.05, 0.1);
        let named = &result.named_effects;
        assert!(result.ambiguous.is_empty(), "{:?}", result.ambiguous);
        assert_eq!(named.len(), 2, "{named:?}");
        for (name, truth) in [("transport_delay", 0.05), ("hydraulic_lag", 0.1)] {
            let e = named.iter().find(|e| e.name == name).unwrap();
            assert!((e.magnitude / truth - 1.0).abs() < 0.25, "{named:?}");
            assert!(e.fitted_jointly_with.is_some(), "{named:?}");
        }
    }

    /// On slow sinusoidal commands a delay and a lag shift the phase alike: a hidden delay is
    /// reported as ambiguous with a lag (both fits given), neither named.
    #[test]
    fn a_delay_on_slow_commands_is_ambiguous_with_a_lag() {
        let result = timing_analysis(sine_command, 0.05, 0.0);
        assert!(
            result.named_effects.is_empty(),
            "{:?}",
            result.named_effects
        );
        assert_eq!(result.ambiguous.len(), 1, "{:?}", result.rounds);
        let a = &result.ambiguous[0];
        let mut names: Vec<&str> = a.candidates.iter().map(|c| c.name.as_str()).collect();
        names.sort_unstable();
        assert_eq!(names, ["hydraulic_lag", "transport_delay"]);
        assert!(a.effect_correlation.abs() > CONFUSABLE_CORRELATION, "{a:?}");
        assert!(a.note.contains("neither is named"));
    }

    /// A discharge coefficient 15 % low is named as the machine file's parameter with its value,
    /// not as an effect of the library.
    #[test]
    fn a_drifted_discharge_coefficient_is_named_as_the_machine_parameter() {
        let (records, params, library) = drifted_records();
        let nominal = library.parameters[library
            .find("hydraulics.valve_discharge_coefficient")
            .unwrap()]
        .nominal;
        let config = AnalysisConfig {
            parameters: Some(library),
            max_effects: 1,
            ..AnalysisConfig::default()
        };
        let result = analyse(&records, &params, &config, &mut |_, _| {}).unwrap();
        let named = &result.named_effects;
        assert_eq!(named.len(), 1, "{named:?}");
        assert_eq!(named[0].kind, "parameter");
        assert_eq!(named[0].name, "hydraulics.valve_discharge_coefficient");
        assert!(
            (named[0].magnitude / nominal - 0.85).abs() < 0.02,
            "{named:?}"
        );
        assert!((result.params.meter_in_k[0] / params.meter_in_k[0] - 0.85).abs() < 0.02);
    }

    /// Held-out sums of squares with every signal at `rms_without` and the given signals at
    /// `rms_with` (1000 samples each).
    fn held_out_sse(
        rms_without: f64,
        rms_with: &[(Signal, f64)],
    ) -> ([f64; N_SIGNALS], [f64; N_SIGNALS], [usize; N_SIGNALS]) {
        let n = 1000;
        let without = [rms_without * rms_without * n as f64; N_SIGNALS];
        let mut with = without;
        for (s, r) in rms_with {
            with[s.index()] = r * r * n as f64;
        }
        (with, without, [n; N_SIGNALS])
    }

    /// A signal the candidate makes 11 % worse is vetoed on its own RMS, but not when it stays
    /// within 1.1 times the reference's level: a +0.2 MPa pressure offset raised the boom force's
    /// held-out RMS from 5442 N to 6040 N, where the reference expects 6010 N (the nominal model's
    /// own free-air bias had hidden most of the offset's shift).
    #[test]
    fn a_signal_is_made_worse_only_beyond_its_rms_and_the_expected_level() {
        let (with, without, samples) = held_out_sse(5442.0, &[(Signal::BoomForce, 6040.0)]);
        let h = HeldOutSse {
            with: &with,
            without: &without,
            samples: &samples,
        };
        let (j, factor) = h.most_worsened(None).expect("worse than without");
        assert_eq!(j, Signal::BoomForce.index());
        assert!((factor - 6040.0 / 5442.0).abs() < 1e-9);
        let mut expected = [1.0; N_SIGNALS];
        expected[Signal::BoomForce.index()] = 6010.0;
        assert_eq!(h.most_worsened(Some(&expected)), None);
        // Beyond 1.1 times the expected level it is worse again.
        expected[Signal::BoomForce.index()] = 5000.0;
        assert!(h.most_worsened(Some(&expected)).is_some());
    }

    /// A candidate must lower a signal beyond the reference: a 20 % heavier stick's boom and stick
    /// forces were beyond it, and an 11 kPa pressure offset moved them by -0.8 and +3.3 %.
    #[test]
    fn a_candidate_must_lower_an_eligible_signal() {
        let mut eligible = [false; N_SIGNALS];
        eligible[Signal::BoomForce.index()] = true;
        eligible[Signal::StickForce.index()] = true;
        let groups = Candidate::PressureSensorOffset.groups();
        let (with, without, samples) = held_out_sse(
            1.0,
            &[
                (Signal::BoomForce, 0.992),
                (Signal::StickForce, 1.033),
                (Signal::StickVelocity, 0.965),
            ],
        );
        let h = HeldOutSse {
            with: &with,
            without: &without,
            samples: &samples,
        };
        assert!(!h.lowers_any(&eligible, groups));
        eligible[Signal::StickVelocity.index()] = true;
        assert!(!h.lowers_any(&eligible, groups), "3.5 % is not enough");
        let (with, ..) = held_out_sse(1.0, &[(Signal::StickVelocity, 0.7)]);
        let h = HeldOutSse { with: &with, ..h };
        assert!(h.lowers_any(&eligible, groups));
        // Not through a signal outside the candidate's groups.
        assert!(!h.lowers_any(&eligible, Candidate::SoilCohesion.groups()));
    }

    /// The machine's parameters as the only candidates, one to be named.
    fn parameters_only(library: ParameterLibrary) -> AnalysisConfig {
        AnalysisConfig {
            candidates: Vec::new(),
            parameters: Some(library),
            max_effects: 1,
            ..AnalysisConfig::default()
        }
    }

    fn assert_nothing_named(result: &AnalysisResult) {
        assert!(
            result.named_effects.is_empty(),
            "{:?}",
            result.named_effects
        );
    }

    /// Signals marked ignored are evidence for no candidate: with the velocities and pump
    /// pressures ignored, the drifted discharge coefficient (which acts on them alone) is not named.
    #[test]
    fn ignored_signals_are_no_evidence() {
        let (records, params, library) = drifted_records();
        let mut ignored = [false; N_SIGNALS];
        for s in [
            Signal::BoomVelocity,
            Signal::StickVelocity,
            Signal::BucketVelocity,
            Signal::Pump1Pressure,
            Signal::Pump2Pressure,
        ] {
            ignored[s.index()] = true;
        }
        let config = AnalysisConfig {
            ignored,
            ..parameters_only(library)
        };
        let result = analyse(&records, &params, &config, &mut |_, _| {}).unwrap();
        assert_nothing_named(&result);
        assert!(
            result.rounds[0]
                .iter()
                .all(|c| !c.significant && c.veto.is_some()),
            "{:?}",
            result.rounds
        );
    }

    /// A candidate acting on none of the eligible signals is not tried: the drifted discharge
    /// coefficient moves the velocities and pump pressures, so with only the weighed payload
    /// eligible (the one signal a reference found beyond it) nothing is named, and with the
    /// velocities eligible it is.
    #[test]
    fn a_candidate_acting_on_no_eligible_signal_is_not_named() {
        let (records, params, library) = drifted_records();
        let only = |signals: &[Signal]| {
            let mut e = [false; N_SIGNALS];
            for s in signals {
                e[s.index()] = true;
            }
            e
        };
        let config = AnalysisConfig {
            eligible: Some(only(&[Signal::PayloadMass])),
            ..parameters_only(library)
        };
        let result = analyse(&records, &params, &config, &mut |_, _| {}).unwrap();
        assert_nothing_named(&result);
        assert!(
            result.rounds.iter().all(|r| r.is_empty()),
            "{:?}",
            result.rounds
        );
        let config = AnalysisConfig {
            eligible: Some(only(&[Signal::StickVelocity])),
            ..config
        };
        let result = analyse(&records, &params, &config, &mut |_, _| {}).unwrap();
        assert_eq!(
            result.named_effects.first().map(|e| e.name.as_str()),
            Some("hydraulics.valve_discharge_coefficient")
        );
    }
}
