//! Confusable candidates: a significant candidate whose fitted change correlates with another's is
//! fitted jointly with it, and the pair is named together, or reported as ambiguous.

use super::cost::{Evaluator, Weights, chi2};
use super::search::minimise;
use super::trial::Trial;
use super::*;

/// Effects whose fitted changes of the training predictions correlate at least this much
/// (chi-square weighted) are confusable, and the better one is fitted jointly with the other.
pub(super) const CONFUSABLE_CORRELATION: f64 = 0.7;

/// A significant confusable partner that explains at least this share of the better one's
/// training chi-square drop on its own, and that the joint fit cannot separate, makes the pair
/// ambiguous (the held-out gains differ more between the two, through the decorrelation each
/// leaves).
pub(super) const AMBIGUOUS_SHARE: f64 = 0.95;

/// Points on the line between two confusable candidates' fits alone where the joint fit starts.
pub(super) const JOINT_START_POINTS: usize = 8;

/// At most this many sweeps (along each candidate once) of the joint fit's coordinate descent.
pub(super) const JOINT_SWEEPS: usize = 3;

/// A sweep of the coordinate descent that lowers the training chi-square by less than this has
/// converged (a chi-square unit is `-2 ln L`; 0.1 is far below any significance threshold).
pub(super) const JOINT_MIN_GAIN: f64 = 0.1;

/// At most this many of the round's best-scoring other candidates are checked for confusion.
pub(super) const MAX_PARTNERS: usize = 4;

/// The noise model and held-out baseline of one round of the forward selection.
pub(super) struct Round<'r> {
    pub(super) w: Weights,
    pub(super) sigma: &'r [f64],
    pub(super) kappa: &'r [f64],
    pub(super) test_base_sse: [f64; N_SIGNALS],
    pub(super) n_test: [usize; N_SIGNALS],
    pub(super) config: &'r AnalysisConfig,
}

/// What to name after the best candidate of a round is checked against its confusable partners.
pub(super) enum Resolution {
    /// The best candidate alone (no confusable partner, or the partner adds nothing).
    Alone,
    /// Both, with the joint fit's changes and marginal uncertainties, and the second's held-out
    /// BIC gain over the first alone.
    Both {
        other: Trial,
        changes: [f64; 2],
        uncertainties: [f64; 2],
        gain: f64,
    },
    /// Neither named: the pair is reported.
    Ambiguous {
        other: Trial,
        ambiguity: Box<Ambiguity>,
    },
}

/// Cosine of two vectors (0 when either is zero).
pub(super) fn cosine(a: &[f64], b: &[f64]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa > 0.0 && bb > 0.0 {
        ab / (aa * bb).sqrt()
    } else {
        0.0
    }
}

/// The best candidate `c` of a round against the other candidates that explain the held-out
/// digs too: the first whose fitted effect on the training predictions correlates with `c`'s by
/// at least [`CONFUSABLE_CORRELATION`] is fitted jointly with it (coordinate descent, then the
/// joint cost's curvature for the covariance). Both are named when the joint fit beats `c`
/// alone on the held-out digs by the strong significance threshold and each change is
/// 3 uncertainties from zero; the pair is ambiguous when the partner alone is significant and
/// explains nearly as much of the training cost ([`AMBIGUOUS_SHARE`]); otherwise `c` stands
/// alone.
pub(super) fn resolve_confusable(
    (train_eval, test_eval): (&mut Evaluator<'_>, &mut Evaluator<'_>),
    train: &[&PreparedRecord],
    (c, s): (Trial, &CandidateScore),
    scores: &[(Trial, CandidateScore)],
    round: &Round<'_>,
    (aug, params): (&Augmentation, &GreyBoxParams),
) -> Resolution {
    let config = round.config;
    let library = config.parameters.as_ref();
    let base = &config.base;
    let xc = c.base(base) + s.magnitude;
    let Some((a, p)) = c.at(xc, aug, params, library) else {
        return Resolution::Alone;
    };
    train_eval.sse_with(&a, p.as_ref(), c.groups(library));
    let effect_c = train_eval.weighted_delta(&round.w);
    let partner = scores
        .iter()
        .filter(|(d, ds)| {
            *d != c && ds.heldout_delta_bic > config.strong_delta_bic && ds.magnitude != 0.0
        })
        .take(MAX_PARTNERS)
        .find_map(|(d, ds)| {
            let (a, p) = d.at(d.base(base) + ds.magnitude, aug, params, library)?;
            train_eval.sse_with(&a, p.as_ref(), d.groups(library));
            let r = cosine(&effect_c, &train_eval.weighted_delta(&round.w));
            (r.abs() >= CONFUSABLE_CORRELATION).then(|| (*d, ds.clone(), r))
        });
    let Some((d, ds, effect_correlation)) = partner else {
        return Resolution::Alone;
    };
    let groups = c.groups(library).union(d.groups(library));
    let mut cost = |x: f64, y: f64| match c.at_pair(d, (x, y), aug, params, library) {
        Some((a, p)) => chi2(&round.w, &train_eval.sse_with(&a, p.as_ref(), groups)),
        None => f64::INFINITY,
    };
    let ((lo_c, hi_c), (lo_d, hi_d)) = (c.range(library), d.range(library));
    // Start on the line between the two fits alone (where the confusable pair trades one for
    // the other: coordinate descent from either end stays on its axis), then coordinate descent.
    let yd = d.base(base) + ds.magnitude;
    let (mut x, mut y, mut best) = (xc, d.base(base), f64::INFINITY);
    for k in 0..=JOINT_START_POINTS {
        let t = k as f64 / JOINT_START_POINTS as f64;
        let (xt, yt) = (
            c.base(base) + t * s.magnitude,
            d.base(base) + (1.0 - t) * (yd - d.base(base)),
        );
        let f = cost(xt, yt);
        if f < best {
            (x, y, best) = (xt, yt, f);
        }
    }
    // Alternately along y and x, until a sweep over both gains nothing.
    let mut sweep_gained = false;
    for step in 0..2 * JOINT_SWEEPS {
        let along_y = step % 2 == 0;
        if along_y {
            sweep_gained = false;
        }
        let (lo, hi) = if along_y { (lo_d, hi_d) } else { (lo_c, hi_c) };
        let (z, f1) = minimise(
            |z| if along_y { cost(x, z) } else { cost(z, y) },
            lo,
            hi,
            config.grid_points,
            config.golden_iterations,
        );
        if f1 < best {
            sweep_gained |= f1 < best - JOINT_MIN_GAIN;
            best = f1;
            if along_y {
                y = z;
            } else {
                x = z;
            }
        }
        if !along_y && !sweep_gained {
            break;
        }
    }
    // Covariance 2 H^-1 of the joint training cost (the chi-square is -2 ln L).
    let hx = (0.05 * x.abs()).max(0.005 * c.scale());
    let hy = (0.05 * y.abs()).max(0.005 * d.scale());
    let xs = x.clamp(lo_c + hx, hi_c - hx);
    let ys = y.clamp(lo_d + hy, hi_d - hy);
    let f0 = cost(xs, ys);
    let hxx = (cost(xs + hx, ys) - 2.0 * f0 + cost(xs - hx, ys)) / (hx * hx);
    let hyy = (cost(xs, ys + hy) - 2.0 * f0 + cost(xs, ys - hy)) / (hy * hy);
    let hxy = (cost(xs + hx, ys + hy) - cost(xs + hx, ys - hy) - cost(xs - hx, ys + hy)
        + cost(xs - hx, ys - hy))
        / (4.0 * hx * hy);
    let det = hxx * hyy - hxy * hxy;
    let (ux, uy, rho) = if det.is_finite() && det > 0.0 && hxx > 0.0 && hyy > 0.0 {
        (
            (2.0 * hyy / det).sqrt(),
            (2.0 * hxx / det).sqrt(),
            -hxy / (hxx * hyy).sqrt(),
        )
    } else {
        (c.scale(), d.scale(), -effect_correlation.signum())
    };
    // Held-out: the joint fit against `c` alone, under the noise the joint fit leaves.
    let (Some((a_joint, p_joint)), Some((a_one, p_one))) = (
        c.at_pair(d, (x, y), aug, params, library),
        c.at(xc, aug, params, library),
    ) else {
        return Resolution::Alone;
    };
    train_eval.sse_with(&a_joint, p_joint.as_ref(), groups);
    let mut w = round.w;
    let mut kappa = round.kappa.to_vec();
    for j in (0..N_SIGNALS).filter(|j| groups.contains(*j)) {
        if w.inv_var[j] > 0.0 {
            kappa[j] = decorrelation(train, &train_eval.scratch, j);
            w.inv_var[j] = 1.0 / (round.sigma[j] * round.sigma[j] * kappa[j]);
        }
    }
    let n_eff = (0..N_SIGNALS)
        .filter(|j| w.inv_var[*j] > 0.0)
        .map(|j| round.n_test[j] as f64 / kappa[j])
        .sum::<f64>()
        .max(2.0);
    let test_joint = test_eval.sse_with(&a_joint, p_joint.as_ref(), groups);
    let test_one = test_eval.sse_with(&a_one, p_one.as_ref(), groups);
    let gain = chi2(&w, &test_one) - chi2(&w, &test_joint) - n_eff.ln();
    let consistent = (0..N_SIGNALS).all(|j| {
        round.n_test[j] < 100
            || test_joint[j] <= MAX_SIGNAL_WORSENING.powi(2) * round.test_base_sse[j]
    });
    let changes = [x - c.base(base), y - d.base(base)];
    if consistent
        && gain > config.strong_delta_bic
        && changes[0].abs() > MIN_MAGNITUDE_Z * ux
        && changes[1].abs() > MIN_MAGNITUDE_Z * uy
    {
        return Resolution::Both {
            other: d,
            changes,
            uncertainties: [ux, uy],
            gain,
        };
    }
    if !(ds.significant && ds.train_chi2_drop >= AMBIGUOUS_SHARE * s.train_chi2_drop) {
        return Resolution::Alone;
    }
    // The held-out digs tell them apart when the partner alone leaves clearly more than `c` alone,
    // under one noise model (the joint fit's): their own held-out gains are each under the noise it
    // leaves, and differ through that too. (A 0.03 s transport delay: the lag alone leaves a
    // held-out chi-square thousands above the delay's, and the joint fit puts the lag at zero.)
    let Some((a_other, p_other)) = d.at(yd, aug, params, library) else {
        return Resolution::Alone;
    };
    let test_other = test_eval.sse_with(&a_other, p_other.as_ref(), groups);
    if chi2(&w, &test_other) - chi2(&w, &test_one) > config.strong_delta_bic {
        return Resolution::Alone;
    }
    let entry = |t: Trial, alone: &CandidateScore, joint: (f64, f64)| {
        let (kind, value, unc, unit) = t.reported(alone.magnitude, alone.uncertainty, library);
        let (_, joint_value, joint_unc, _) = t.reported(joint.0, joint.1, library);
        AmbiguousCandidate {
            name: t.name(library),
            kind,
            unit,
            alone: value,
            alone_uncertainty: unc,
            alone_delta_bic: alone.heldout_delta_bic,
            joint: joint_value,
            joint_uncertainty: joint_unc,
        }
    };
    let (name_c, name_d) = (c.name(library), d.name(library));
    let note = format!(
        "{name_c} and {name_d} change the predictions alike (effect correlation {effect_correlation:+.2}); \
         either alone explains the residual (held-out dBIC {:.0} and {:.0}) and the joint fit does \
         not separate them (magnitude correlation {rho:+.2}, joint gain dBIC {gain:.0}): neither is \
         named; the model carries {name_c} alone. Record what tells them apart.",
        s.heldout_delta_bic, ds.heldout_delta_bic
    );
    Resolution::Ambiguous {
        other: d,
        ambiguity: Box::new(Ambiguity {
            candidates: [
                entry(c, s, (changes[0], ux)),
                entry(d, &ds, (changes[1], uy)),
            ],
            effect_correlation,
            parameter_correlation: rho,
            joint_gain_delta_bic: gain,
            in_model: name_c,
            note,
        }),
    }
}
