//! The verdict of an analysis against the reference ([`crate::reference`]): per signal, its held-out
//! residual as a ratio to the expected level before and after the named effects, the stages where it
//! stays beyond, and its structure (correlation with physical regressors and the command, whiteness)
//! against the reference's; and one of four outcomes per signal and per session:
//!
//! - **expected**: within the reference's tolerance, nothing named for it;
//! - **named**: beyond the tolerance with the nominal model, back within it with the named effects;
//! - **partly explained**: named effects act on it, but it stays beyond the tolerance (the ratio
//!   that remains is reported; a named effect whose own signals stay beyond is flagged as possibly
//!   a proxy for something else);
//! - **unexplained**: beyond the tolerance and no named effect acts on it ("boom_velocity residual
//!   5.2x expected ..., not explained by any candidate").

use std::fmt::Write as _;

use serde::Serialize;

use crate::effects::CandidateEffect as _;
use crate::fit::{AnalysisResult, SignalRms};
use crate::parameters::ParameterLibrary;
use crate::reference::{MIN_JUDGED_SAMPLES, Reference, Regressor, SignalStructure};

/// Fewest held-out samples on which a signal's mean residual is checked against the reference's
/// band ([`SignalVerdict::bias_beyond`]): the band is that of the reference's per-dig means over as
/// many digs, so it does not need the [`MIN_JUDGED_SAMPLES`] an RMS ratio does (the free-air forces
/// of the empty bucket, 5-10 held-out samples a dig).
pub const MIN_BIAS_SAMPLES: usize = 30;
use crate::{Candidate, Signal};

/// A correlation counts as structure when its magnitude exceeds this ...
const MIN_CORRELATION: f64 = 0.3;
/// ... and the reference's by this much.
const CORRELATION_MARGIN: f64 = 0.2;
/// Whiteness is reported as lost when `Q(20)` exceeds the reference's by this factor.
const WHITENESS_FACTOR: f64 = 2.0;

/// The outcome for a signal or a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Within what the reference expects; nothing named for it.
    Expected,
    /// Beyond the reference with the starting model, within it with the named effects.
    Named,
    /// Named effects act on it but it stays beyond the reference.
    PartlyExplained,
    /// Beyond the reference and no named effect acts on it.
    Unexplained,
    /// Too few samples (held out or in the reference) to judge.
    NotJudged,
}

impl Outcome {
    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Expected => "expected",
            Outcome::Named => "named",
            Outcome::PartlyExplained => "partly explained",
            Outcome::Unexplained => "unexplained",
            Outcome::NotJudged => "not judged",
        }
    }
}

/// A correlation of the residual beyond the reference's.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Structure {
    /// What the residual correlates with (e.g. `the valve command at lag 0`).
    pub with: String,
    /// Correlation on the held-out digs (after the named effects).
    pub correlation: f64,
    /// The same on the reference.
    pub reference: f64,
}

/// One signal judged against the reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SignalVerdict {
    /// Signal name.
    pub signal: &'static str,
    /// Unit of the RMS figures.
    pub unit: &'static str,
    /// Held-out samples.
    pub samples: usize,
    /// Expected residual RMS (the reference's).
    pub expected_rms: f64,
    /// Ratio above which the held-out digs are beyond the reference.
    pub tolerance: f64,
    /// Held-out residual RMS over the expected one, starting model.
    pub ratio_before: f64,
    /// The same with the named effects.
    pub ratio_after: f64,
    /// Stages where the ratio with the named effects exceeds the tolerance, `(stage, ratio)`, worst
    /// first.
    pub stages: Vec<(&'static str, f64)>,
    /// Correlations beyond the reference's (after the named effects).
    pub structure: Vec<Structure>,
    /// Ljung-Box `Q(20)` of the held-out residual over the reference's.
    pub whiteness_ratio: f64,
    /// Mean held-out residual with the named effects (a one-signed shift the RMS ratio may hide
    /// under a large healthy spread, e.g. the soil force of a more cohesive soil).
    pub mean_residual: Option<f64>,
    /// The band of that mean on as many digs of the reference ([`Reference::bias_band`]).
    pub bias_band: Option<(f64, f64)>,
    /// Whether the mean is outside the band (signals with at least [`MIN_BIAS_SAMPLES`] held-out
    /// samples).
    pub bias_beyond: bool,
    /// Named effects acting on the signal.
    pub named: Vec<String>,
    /// The outcome.
    pub outcome: Outcome,
    /// One line for the report.
    pub note: String,
}

/// A signal beyond the reference that the named effects leave there (`report.json`'s
/// `unexplained[]`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Unexplained {
    /// Signal name.
    pub signal: &'static str,
    /// Held-out residual RMS (with the named effects) over the expected one.
    pub ratio_to_expected: f64,
    /// Stages where it is beyond the tolerance, worst first.
    pub stages: Vec<&'static str>,
    /// What it correlates with and what was tried.
    pub note: String,
}

/// What a named effect left behind.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NamedOutcome {
    /// Effect name.
    pub name: String,
    /// [`Outcome::Named`] or [`Outcome::PartlyExplained`].
    pub outcome: Outcome,
    /// Its signals that stay beyond the reference, `(signal, ratio to expected)`.
    pub remaining: Vec<(&'static str, f64)>,
}

impl NamedOutcome {
    /// The signals it leaves beyond the reference, e.g. `boom_velocity 3.2x, boom_force 4.0x`.
    pub fn remaining_text(&self) -> String {
        self.remaining
            .iter()
            .map(|(sig, r)| format!("{sig} {r:.1}x"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The verdict of an analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// The reference's sessions.
    pub reference: Vec<String>,
    /// The session's outcome: expected (nothing named, nothing beyond the reference), named,
    /// partly explained (named, something stays beyond), unexplained (nothing named, something
    /// beyond).
    pub outcome: Outcome,
    /// Per signal.
    pub signals: Vec<SignalVerdict>,
    /// Per named effect.
    pub named: Vec<NamedOutcome>,
    /// Signals beyond the reference after the named effects.
    pub unexplained: Vec<Unexplained>,
}

/// Whether the candidate `name` of `kind` (`effect` or `parameter`) acts on `sig`.
fn acts_on(name: &str, kind: &str, sig: Signal) -> bool {
    match kind {
        "parameter" => ParameterLibrary::groups_of(name).contains(sig.index()),
        _ => Candidate::ALL
            .iter()
            .any(|c| c.name() == name && c.groups().contains(sig.index())),
    }
}

/// The candidates whose signals include `sig`, among the named ones and those the model carries
/// for an ambiguous pair.
fn named_acting(result: &AnalysisResult, sig: Signal) -> Vec<String> {
    let named = result
        .named_effects
        .iter()
        .filter(|e| acts_on(&e.name, e.kind, sig))
        .map(|e| e.name.clone());
    let ambiguous = result
        .ambiguous
        .iter()
        .map(|a| &a.candidates[0])
        .filter(|c| acts_on(&c.name, c.kind, sig))
        .map(|c| c.name.clone());
    named.chain(ambiguous).collect()
}

fn structure_beyond(test: &SignalStructure, reference: &SignalStructure) -> Vec<Structure> {
    let beyond =
        |c: f64, r: f64| c.abs() > MIN_CORRELATION && c.abs() > r.abs() + CORRELATION_MARGIN;
    let mut out: Vec<Structure> = Regressor::ALL
        .iter()
        .zip(test.correlations.iter().zip(&reference.correlations))
        .filter(|(_, (c, r))| beyond(**c, **r))
        .map(|(g, (c, r))| Structure {
            with: g.name().to_string(),
            correlation: *c,
            reference: *r,
        })
        .collect();
    let (c, lag) = test.input_cross_correlation;
    if beyond(c, reference.input_cross_correlation.0) {
        out.push(Structure {
            with: format!("the valve command at lag {lag} samples"),
            correlation: c,
            reference: reference.input_cross_correlation.0,
        });
    }
    out.sort_by(|a, b| b.correlation.abs().total_cmp(&a.correlation.abs()));
    out
}

fn judge_signal(
    sig: Signal,
    rms: &SignalRms,
    after: &SignalStructure,
    reference: &Reference,
    test_digs: usize,
    named: Vec<String>,
) -> SignalVerdict {
    let refs = &reference.signals[sig.index()];
    let expected = reference.expected_rms(sig);
    let tolerance = reference.tolerance(sig, test_digs);
    let judged = rms.samples >= MIN_JUDGED_SAMPLES && expected > 0.0;
    let ratio = |x: f64| if expected > 0.0 { x / expected } else { 0.0 };
    let (ratio_before, ratio_after) = (ratio(rms.before), ratio(rms.after));
    let mut stages: Vec<(&'static str, f64)> = rms
        .per_stage
        .iter()
        .filter(|(_, n, _, _)| *n >= MIN_JUDGED_SAMPLES)
        .filter_map(|(st, _, _, a)| {
            let r = refs
                .per_stage
                .iter()
                .find(|l| l.group == *st && l.samples >= MIN_JUDGED_SAMPLES)?;
            (r.rms > 0.0 && a / r.rms > tolerance).then_some((*st, a / r.rms))
        })
        .collect();
    stages.sort_by(|a, b| b.1.total_cmp(&a.1));
    let structure = structure_beyond(after, refs);
    let whiteness_ratio = if refs.ljung_box_q > 0.0 {
        after.ljung_box_q / refs.ljung_box_q
    } else {
        0.0
    };
    let mean_residual = crate::reference::mean_residual(after);
    let bias_band = reference.bias_band(sig, after.per_dig.len());
    // A mean is judged on fewer samples than an RMS ratio: its band comes from the reference's
    // per-dig means on as many digs.
    let bias_judged = rms.samples >= MIN_BIAS_SAMPLES && expected > 0.0;
    let bias_beyond = bias_judged
        && matches!((mean_residual, bias_band), (Some(m), Some((lo, hi))) if m < lo || m > hi);
    let beyond = ratio_after > tolerance;
    let outcome = match (judged, beyond, named.is_empty()) {
        (false, _, _) => Outcome::NotJudged,
        (true, false, false) if ratio_before > tolerance => Outcome::Named,
        (true, false, _) => Outcome::Expected,
        (true, true, false) => Outcome::PartlyExplained,
        (true, true, true) => Outcome::Unexplained,
    };
    let mut note = String::new();
    if judged {
        let _ = write!(
            note,
            "residual {ratio_after:.1}x expected (tolerance {tolerance:.1}x"
        );
        if (ratio_before - ratio_after).abs() > 0.05 {
            let _ = write!(note, "; {ratio_before:.1}x before the named effects");
        }
        note.push(')');
        if !stages.is_empty() {
            let _ = write!(
                note,
                " in {}",
                stages
                    .iter()
                    .map(|(s, r)| format!("{s} {r:.1}x"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        if let Some(s) = structure.first() {
            let _ = write!(
                note,
                ", correlated with {} (r {:+.2}, reference {:+.2})",
                s.with, s.correlation, s.reference
            );
        }
        if whiteness_ratio > WHITENESS_FACTOR {
            let _ = write!(note, ", whiteness Q {whiteness_ratio:.1}x the reference's");
        }
        if let (true, Some(m), Some((lo, hi))) = (bias_beyond, mean_residual, bias_band) {
            let _ = write!(
                note,
                ", mean {m:.3e} {} outside the reference's {lo:.3e}..{hi:.3e}",
                sig.unit()
            );
        }
        match outcome {
            Outcome::Unexplained => note.push_str(": no effect in the library explains it"),
            Outcome::PartlyExplained => {
                let _ = write!(note, ": {} explain only part of it", named.join(" + "));
            }
            Outcome::Named => {
                let _ = write!(note, ": explained by {}", named.join(" + "));
            }
            _ => {}
        }
    } else {
        let _ = write!(
            note,
            "not judged: {} held-out samples, {} in the reference (at least {MIN_JUDGED_SAMPLES} each)",
            rms.samples, refs.overall.samples
        );
    }
    SignalVerdict {
        signal: sig.name(),
        unit: sig.unit(),
        samples: rms.samples,
        expected_rms: expected,
        tolerance,
        ratio_before,
        ratio_after,
        stages,
        structure,
        whiteness_ratio,
        mean_residual,
        bias_band,
        bias_beyond,
        named,
        outcome,
        note,
    }
}

/// Judges an analysis against the reference: `after` is the residual structure of the held-out
/// digs with the named effects ([`crate::reference::structure`]).
pub fn judge(result: &AnalysisResult, after: &[SignalStructure], reference: &Reference) -> Verdict {
    let test_digs = result.test_digs.len();
    let signals: Vec<SignalVerdict> = Signal::ALL
        .iter()
        .map(|sig| {
            let j = sig.index();
            judge_signal(
                *sig,
                &result.rms[j],
                &after[j],
                reference,
                test_digs,
                named_acting(result, *sig),
            )
        })
        .collect();
    let unexplained: Vec<Unexplained> = signals
        .iter()
        .filter(|v| matches!(v.outcome, Outcome::Unexplained | Outcome::PartlyExplained))
        .map(|v| Unexplained {
            signal: v.signal,
            ratio_to_expected: v.ratio_after,
            stages: v.stages.iter().map(|(s, _)| *s).collect(),
            note: v.note.clone(),
        })
        .collect();
    let named: Vec<NamedOutcome> = result
        .named_effects
        .iter()
        .map(|e| {
            let remaining: Vec<(&'static str, f64)> = signals
                .iter()
                .filter(|v| v.outcome == Outcome::PartlyExplained && v.named.contains(&e.name))
                .map(|v| (v.signal, v.ratio_after))
                .collect();
            NamedOutcome {
                name: e.name.clone(),
                outcome: if remaining.is_empty() {
                    Outcome::Named
                } else {
                    Outcome::PartlyExplained
                },
                remaining,
            }
        })
        .collect();
    let judged = signals.iter().any(|v| v.outcome != Outcome::NotJudged);
    let nothing_named = result.named_effects.is_empty() && result.ambiguous.is_empty();
    let outcome = match (nothing_named, unexplained.is_empty()) {
        _ if !judged => Outcome::NotJudged,
        (true, true) => Outcome::Expected,
        (false, true) => Outcome::Named,
        (false, false) => Outcome::PartlyExplained,
        (true, false) => Outcome::Unexplained,
    };
    Verdict {
        reference: reference.source.clone(),
        outcome,
        signals,
        named,
        unexplained,
    }
}

impl Verdict {
    /// True when no judged signal was beyond the reference with the starting model (before any
    /// named effect): a candidate is then named on its own held-out evidence alone.
    pub fn nothing_beyond_before(&self) -> bool {
        self.signals
            .iter()
            .filter(|s| s.outcome != Outcome::NotJudged)
            .all(|s| s.ratio_before <= s.tolerance)
    }
}

/// The verdict as text: the session's outcome, then one line per signal beyond the reference and
/// per named effect that leaves residue.
pub fn verdict_text(v: &Verdict) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "verdict against the reference ({}): {}",
        v.reference.join(", "),
        v.outcome.name()
    );
    for n in &v.named {
        if n.outcome == Outcome::PartlyExplained {
            let _ = writeln!(
                s,
                "  named {} leaves residue beyond the reference on {} (it may be a proxy for something the library lacks)",
                n.name,
                n.remaining_text()
            );
        }
    }
    for u in &v.unexplained {
        let _ = writeln!(s, "  {}: {}", u.signal, u.note);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::NamedEffect;
    use crate::reference::Level;

    fn level(group: &str, rms: f64) -> Level {
        Level {
            group: group.into(),
            samples: 1000,
            rms,
        }
    }

    fn structure_of(sig: Signal, rms: f64, corr_measured: f64) -> SignalStructure {
        let mut correlations = vec![0.0; Regressor::ALL.len()];
        correlations[0] = corr_measured;
        SignalStructure {
            signal: sig.name().into(),
            unit: sig.unit().into(),
            overall: level("all", rms),
            per_stage: vec![level("dig", rms), level("outside_autodig", rms)],
            per_dig: vec![(250, rms * rms); 4],
            per_dig_mean: vec![0.0; 4],
            ljung_box_q: 100.0,
            input_cross_correlation: (0.05, 0),
            correlations,
        }
    }

    fn rms_of(sig: Signal, before: f64, after: f64) -> SignalRms {
        SignalRms {
            signal: sig.name(),
            unit: sig.unit(),
            samples: 2000,
            before,
            after,
            per_stage: vec![
                ("dig", 1000, before, after),
                ("outside_autodig", 1000, 1.0, 1.0),
            ],
            acted: (0, 0.0, 0.0),
        }
    }

    fn result(rms: Vec<SignalRms>, named: &[&'static str]) -> AnalysisResult {
        AnalysisResult {
            named_effects: named
                .iter()
                .map(|n| NamedEffect {
                    name: n.to_string(),
                    kind: "effect",
                    magnitude: 0.1,
                    uncertainty: 0.01,
                    unit: "",
                    description: String::new(),
                    heldout_delta_bic: 500.0,
                    fitted_jointly_with: None,
                })
                .collect(),
            ambiguous: Vec::new(),
            augmentation: crate::Augmentation::nominal(),
            params: crate::AugmentedModel::nominal().unwrap().params,
            rounds: Vec::new(),
            rms,
            localisation: Vec::new(),
            train_digs: vec![0, 2, 4, 6],
            test_digs: vec![1, 3, 5, 7],
            train_samples: vec![2000; crate::greybox::N_SIGNALS],
            sigma: Vec::new(),
            kappa: Vec::new(),
        }
    }

    fn reference() -> Reference {
        Reference::healthy_fixture(
            Signal::ALL
                .iter()
                .map(|s| structure_of(*s, 1.0, 0.05))
                .collect(),
        )
    }

    /// A boom velocity residual five times the reference, its own nominal spread making it look
    /// like noise to the fit, is "unexplained", with its stage and its correlation with the
    /// measured speed; the same with a named effect that brings it back is "named"; one that
    /// halves it only is "partly explained"; clean signals stay "expected".
    /// A session whose residuals are all at the reference's level has nothing beyond it before
    /// the named effects, whatever the fit named.
    #[test]
    fn a_session_within_the_reference_has_nothing_beyond_before() {
        let rms: Vec<SignalRms> = Signal::ALL.iter().map(|s| rms_of(*s, 1.2, 1.0)).collect();
        let after: Vec<SignalStructure> = Signal::ALL
            .iter()
            .map(|s| structure_of(*s, 1.0, 0.05))
            .collect();
        let v = judge(&result(rms, &["transport_delay"]), &after, &reference());
        assert!(v.nothing_beyond_before(), "{v:?}");
    }

    #[test]
    fn residuals_are_judged_against_the_reference_not_against_themselves() {
        let reference = reference();
        let boom = Signal::BoomVelocity.index();
        let after_of = |boom_rms: f64| -> Vec<SignalStructure> {
            Signal::ALL
                .iter()
                .map(|s| {
                    if s.index() == boom {
                        structure_of(*s, boom_rms, 0.7)
                    } else {
                        structure_of(*s, 1.0, 0.05)
                    }
                })
                .collect()
        };
        let rms = |after: f64| -> Vec<SignalRms> {
            Signal::ALL
                .iter()
                .map(|s| {
                    if s.index() == boom {
                        rms_of(*s, 5.0, after)
                    } else {
                        rms_of(*s, 1.0, 1.0)
                    }
                })
                .collect()
        };
        let v = judge(&result(rms(5.0), &[]), &after_of(5.0), &reference);
        assert_eq!(v.outcome, Outcome::Unexplained);
        assert_eq!(v.unexplained.len(), 1, "{v:?}");
        let u = &v.unexplained[0];
        assert_eq!(u.signal, "boom_velocity");
        assert!((u.ratio_to_expected - 5.0).abs() < 1e-9);
        assert_eq!(u.stages, ["dig"]);
        assert!(u.note.contains("the measured value"), "{}", u.note);
        assert!(u.note.contains("no effect in the library"), "{}", u.note);
        assert!(verdict_text(&v).contains("boom_velocity"));
        assert!(
            v.signals
                .iter()
                .filter(|s| s.signal != "boom_velocity")
                .all(|s| s.outcome == Outcome::Expected)
        );

        let v = judge(
            &result(rms(1.1), &["valve_deadband"]),
            &after_of(1.1),
            &reference,
        );
        assert!(!v.nothing_beyond_before());
        assert_eq!(v.outcome, Outcome::Named);
        assert_eq!(v.signals[boom].outcome, Outcome::Named);
        assert_eq!(v.named[0].outcome, Outcome::Named);

        let v = judge(
            &result(rms(2.5), &["valve_deadband"]),
            &after_of(2.5),
            &reference,
        );
        assert_eq!(v.outcome, Outcome::PartlyExplained);
        assert_eq!(v.signals[boom].outcome, Outcome::PartlyExplained);
        assert_eq!(v.named[0].outcome, Outcome::PartlyExplained);
        assert_eq!(v.named[0].remaining, [("boom_velocity", 2.5)]);
        assert!(verdict_text(&v).contains("proxy"));

        // A friction acts on the forces only: the boom velocity stays unexplained beside it.
        let v = judge(
            &result(rms(5.0), &["coulomb_friction"]),
            &after_of(5.0),
            &reference,
        );
        assert_eq!(v.signals[boom].outcome, Outcome::Unexplained);
        assert_eq!(v.outcome, Outcome::PartlyExplained);

        let v = judge(
            &result(
                rms(1.0)
                    .into_iter()
                    .map(|mut m| {
                        m.before = 1.0;
                        m
                    })
                    .collect(),
                &[],
            ),
            &after_of(1.0),
            &reference,
        );
        assert_eq!(v.outcome, Outcome::Expected);
        assert!(v.unexplained.is_empty());
    }

    /// A signal with too few held-out samples is not judged, and says why.
    #[test]
    fn a_signal_with_too_few_samples_is_not_judged() {
        let reference = reference();
        let mut rms: Vec<SignalRms> = Signal::ALL.iter().map(|s| rms_of(*s, 9.0, 9.0)).collect();
        for m in &mut rms {
            m.samples = 10;
        }
        let after: Vec<_> = Signal::ALL
            .iter()
            .map(|s| structure_of(*s, 9.0, 0.0))
            .collect();
        let v = judge(&result(rms, &[]), &after, &reference);
        assert!(v.signals.iter().all(|s| s.outcome == Outcome::NotJudged));
        assert!(
            v.signals[0].note.contains("not judged"),
            "{}",
            v.signals[0].note
        );
        assert_eq!(v.outcome, Outcome::NotJudged);
    }
}
