//! Outputs of the analysis: `report.json` (named effects with magnitude and uncertainty, residual RMS
//! before and after per signal and stage, every round's candidate scores, the localisation),
//! `report.md`, `model.json` (the augmented model the planner loads, `AugmentedModel::from_json`) and
//! SVG figures of a held-out dig measured against the old and the new model.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::greybox::{N_SIGNALS, PreparedRecord, SignalGroups, replay};
use crate::model::ModelEffect;
use crate::{AnalysisResult, AugmentedModel, Signal};
use anyhow::Context as _;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use serde::Serialize;

use crate::session::{Analysis, SkippedSession};
use crate::term::TermSuggestion;

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("plot: {e}")
}

/// `report.json`.
#[derive(Debug, Serialize)]
struct ReportJson<'a> {
    measured: Vec<String>,
    /// Sessions that could not be read and were left out (the others were analysed).
    skipped_sessions: &'a [SkippedSession],
    model_in: &'a str,
    model_out: &'static str,
    digs: usize,
    /// The session's outcome against the reference (`expected`, `named`, `partly_explained`,
    /// `unexplained`, `not_judged`), absent without a reference.
    outcome: Option<crate::verdict::Outcome>,
    /// The named effects and parameters, then the terms suggested for what nothing explains
    /// (`kind: "term"`, one entry per term).
    named_effects: Vec<NamedEntry<'a>>,
    /// The term suggestions whole: per signal the equation, every term's inclusion probability,
    /// the held-out share explained.
    terms: &'a [TermSuggestion],
    /// Confusable candidates the data cannot tell apart (neither named; both fits given).
    ambiguous: &'a [crate::fit::Ambiguity],
    /// No effect named and (with a reference) no signal beyond it.
    no_missing_effect_found: bool,
    /// Signals beyond the reference after the named effects.
    unexplained: &'a [crate::verdict::Unexplained],
    warnings: &'a [String],
    /// Every signal judged against the reference, and what each named effect left.
    verdict: Option<&'a crate::verdict::Verdict>,
    /// The reference sessions (`--reference`).
    reference: Option<&'a [String]>,
    residual_rms: &'a [crate::fit::SignalRms],
    rounds: &'a [Vec<crate::fit::CandidateScore>],
    localisation: &'a [crate::stats::ResidualSummary],
    train_digs: &'a [u32],
    test_digs: &'a [u32],
    nominal_sigma: &'a [f64],
    kappa: &'a [f64],
    figures: Vec<String>,
    /// The updated twin: the simulator profile written (`twin/machine.toml`, `twin/effects.toml`)
    /// and the simulator's gap to the held-out digs before and after.
    twin: Option<&'a crate::twin::TwinReport>,
}

/// An entry of `report.json`'s `named_effects[]`: a named candidate, or one term of a suggestion.
#[derive(Debug, Serialize)]
#[serde(untagged)]
enum NamedEntry<'a> {
    Candidate(&'a crate::NamedEffect),
    Term {
        /// `signal: regressor`, e.g. `boom_force: cos(θ_boom)`.
        name: String,
        kind: &'static str,
        /// The coefficient.
        magnitude: f64,
        unit: &'a str,
        /// Standard deviation of the coefficient over the ensemble.
        uncertainty: f64,
        /// Share of the ensemble's models that include the term.
        inclusion: f64,
        /// The whole equation.
        description: &'a str,
    },
}

/// `report.json`'s named effects: the candidates, then every suggested term.
fn named_entries(a: &Analysis) -> Vec<NamedEntry<'_>> {
    let terms = a.terms.iter().flat_map(|t| {
        t.terms.iter().map(move |term| NamedEntry::Term {
            name: format!("{}: {}", t.signal, term.regressor),
            kind: "term",
            magnitude: term.coefficient,
            unit: &term.unit,
            uncertainty: term.uncertainty,
            inclusion: term.inclusion,
            description: &t.equation,
        })
    });
    a.result
        .named_effects
        .iter()
        .map(NamedEntry::Candidate)
        .chain(terms)
        .collect()
}

/// One line per term suggestion: the equation and the held-out share it explains.
fn term_line(t: &TermSuggestion) -> String {
    format!(
        "{} (held-out residual RMS {:.3e} -> {:.3e} {}, {:.0} % of its mean square explained; \
         inclusion probabilities over {} bootstrap fits in brackets)",
        t.equation,
        t.heldout_rms.0,
        t.heldout_rms.1,
        t.unit,
        100.0 * t.heldout_explained,
        t.bootstrap
    )
}

/// A short text summary (printed by the command): the verdict against the reference first, the
/// warnings, the named effects, the held-out residuals.
pub fn summary_text(a: &Analysis) -> String {
    let r = &a.result;
    let mut s = String::new();
    if let Some(v) = &a.verdict {
        s.push_str(&crate::verdict::verdict_text(v));
    }
    if let Some(line) = recorded_reference_line(a) {
        let _ = writeln!(s, "{line}");
    }
    for w in &a.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    if r.named_effects.is_empty() && r.ambiguous.is_empty() {
        s.push_str(no_effect_line(a));
        s.push('\n');
    }
    for amb in &r.ambiguous {
        let _ = writeln!(s, "ambiguous: {}", amb.note);
    }
    for e in &r.named_effects {
        let _ = writeln!(
            s,
            "named effect: {} = {:.4e} +- {:.2e} {} (held-out dBIC {:.0})",
            e.name, e.magnitude, e.uncertainty, e.unit, e.heldout_delta_bic
        );
    }
    for t in &a.terms {
        let _ = writeln!(s, "suggested term: {}", term_line(t));
    }
    if let Some((_, t)) = &a.twin {
        let _ = writeln!(
            s,
            "twin: {} ({} samples); simulator gap nominal -> twin (after/before):",
            t.demo_options, t.gap_before.samples
        );
        for (group, unit, before, after, ratio) in t.rows() {
            let _ = writeln!(
                s,
                "  {group:<17} {before:>11.4e} -> {after:>11.4e} {unit} ({ratio:.2})"
            );
        }
    }
    let _ = writeln!(s, "held-out residual RMS (before -> after):");
    for m in &r.rms {
        if m.samples > 0 {
            let _ = writeln!(
                s,
                "  {:<16} {:>11.4e} -> {:>11.4e} {} ({:+.1} %)",
                m.signal,
                m.before,
                m.after,
                m.unit,
                reduction_percent(m.before, m.after)
            );
        }
    }
    s
}

/// For a reference recorded from simulated sessions (the built-in one of the default machine):
/// which, by what command, and how to record one for a real machine.
fn recorded_reference_line(a: &Analysis) -> Option<String> {
    let rec = a.reference.as_ref()?.recording.as_ref()?;
    Some(format!(
        "judged against a reference recorded from simulated healthy sessions (`{}`): the \
         simulated default machine's, not yours; {}",
        rec.command,
        crate::analysis::RECORD_REFERENCE_ADVICE
    ))
}

/// What to say when nothing is named: "no missing effect found" only when the residuals are within
/// the reference.
fn no_effect_line(a: &Analysis) -> &'static str {
    match &a.verdict {
        Some(v) if v.unexplained.is_empty() && v.outcome != crate::verdict::Outcome::NotJudged => {
            "no missing effect found: no candidate is significant and every signal is within the reference"
        }
        Some(v) if v.unexplained.is_empty() => {
            "too few data to judge: the residuals could not be judged against the reference (too few held-out samples), and nothing is named"
        }
        Some(_) => "no effect in the library explains the residuals beyond the reference (above)",
        None => "no candidate is significant (the residuals were not judged: no --reference)",
    }
}

/// The updated twin: the profile written and the simulator's gap before and after.
fn twin_markdown(s: &mut String, a: &Analysis) {
    let Some((_, t)) = &a.twin else {
        return;
    };
    let _ = writeln!(s, "## The twin\n");
    let _ = writeln!(
        s,
        "Simulator profile: `{}` (the machine file with the named parameters written in{}) and `{}`; \
         run it with `excavator-ctl demo {}`.\n",
        t.machine_file,
        if t.parameters.is_empty() {
            String::new()
        } else {
            format!(
                ": {}",
                t.parameters
                    .iter()
                    .map(|p| format!("{} = {:.4e} {}", p.name, p.value, p.unit))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
        t.effects_file,
        t.demo_options
    );
    let _ = writeln!(
        s,
        "The simulator re-run on the held-out digs' commands ({} windows of up to {} samples from the \
         measured state, {} samples with the empty bucket in free air outside Autodig), RMS of its \
         readings less the measured ones:\n",
        t.gap_before.windows,
        crate::twin::WINDOW_SAMPLES,
        t.gap_before.samples
    );
    let _ = writeln!(
        s,
        "| group | unit | nominal plant | twin | after / before |\n|---|---|---|---|---|"
    );
    for (group, unit, before, after, ratio) in t.rows() {
        let _ = writeln!(
            s,
            "| {group} | {unit} | {before:.4e} | {after:.4e} | {ratio:.2} |"
        );
    }
    s.push('\n');
}

/// `100 (after - before) / before`, 0 when `before` is 0.
pub fn reduction_percent(before: f64, after: f64) -> f64 {
    if before > 0.0 {
        100.0 * (after - before) / before
    } else {
        0.0
    }
}

fn upper_first(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().chain(c).collect())
        .unwrap_or_default()
}

/// The report's lead: the verdict per signal group against the reference, what each named effect
/// left, and the warnings.
fn verdict_markdown(s: &mut String, a: &Analysis) {
    let _ = writeln!(s, "## Verdict\n");
    for w in &a.warnings {
        let _ = writeln!(s, "**Warning**: {w}.\n");
    }
    let Some(v) = &a.verdict else {
        let _ = writeln!(
            s,
            "Not judged: no reference (`--reference` sessions of this machine declared healthy, or a `reference.json`).\n"
        );
        return;
    };
    let _ = writeln!(
        s,
        "Against the reference ({}): **{}**.\n",
        v.reference.join(", "),
        v.outcome.name()
    );
    if let Some(line) = recorded_reference_line(a) {
        let _ = writeln!(s, "{}.\n", upper_first(&line));
    }
    let groups: [(&str, std::ops::RangeInclusive<usize>); 6] = [
        ("cylinder velocities", 0..=2),
        ("pump pressures", 3..=4),
        ("cylinder forces", 5..=7),
        ("soil force", 8..=9),
        ("end stops", 10..=10),
        ("payload", 11..=11),
    ];
    let _ = writeln!(
        s,
        "| group | signal | outcome | ratio to expected (before -> after) | tolerance | expected RMS | note |\n|---|---|---|---|---|---|---|"
    );
    for (group, range) in groups {
        for sv in &v.signals[range] {
            let _ = writeln!(
                s,
                "| {group} | {} | {} | {:.2} -> {:.2} | {:.2} | {:.3e} {} | {} |",
                sv.signal,
                sv.outcome.name(),
                sv.ratio_before,
                sv.ratio_after,
                sv.tolerance,
                sv.expected_rms,
                sv.unit,
                sv.note
            );
        }
    }
    s.push('\n');
    for u in &v.unexplained {
        match a.terms.iter().find(|t| t.signal == u.signal) {
            Some(t) => {
                let _ = writeln!(s, "- `{}`: suggested new term: {}.", u.signal, term_line(t));
            }
            None => {
                let _ = writeln!(
                    s,
                    "- `{}`: no term of the regressor library explains it on the held-out digs.",
                    u.signal
                );
            }
        }
    }
    for n in &v.named {
        if n.outcome == crate::verdict::Outcome::PartlyExplained {
            let _ = writeln!(
                s,
                "- `{}` explains only part: {} stay beyond the reference; it may stand in for something the library lacks.",
                n.name,
                n.remaining_text()
            );
        }
    }
    s.push('\n');
}

fn markdown(a: &Analysis, measured: &[PathBuf], figures: &[String]) -> String {
    let r = &a.result;
    let mut s = String::new();
    let _ = writeln!(s, "# Model-discrepancy report\n");
    let _ = writeln!(
        s,
        "Sessions: {}. Digs: {} (training {:?}, held out {:?}). Starting model: {}.\n",
        measured
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        a.records.len(),
        r.train_digs,
        r.test_digs,
        a.model.provenance
    );
    for skipped in &a.skipped_sessions {
        let _ = writeln!(
            s,
            "**Session left out**: {}: {}.\n",
            skipped.session.display(),
            skipped.reason
        );
    }
    verdict_markdown(&mut s, a);
    let _ = writeln!(s, "## Named effects\n");
    if r.named_effects.is_empty() {
        let _ = writeln!(s, "{}.\n", upper_first(no_effect_line(a)));
    } else {
        let _ = writeln!(
            s,
            "| effect | magnitude | uncertainty | unit | held-out dBIC | meaning |\n|---|---|---|---|---|---|"
        );
        for e in &r.named_effects {
            let _ = writeln!(
                s,
                "| {} | {:.4e} | {:.2e} | {} | {:.0} | {} |",
                e.name, e.magnitude, e.uncertainty, e.unit, e.heldout_delta_bic, e.description
            );
        }
        let _ = writeln!(
            s,
            "\nThe augmented model is `model.json` (load it with `--model model.json` or `crate::AugmentedModel::from_json`).\n"
        );
    }
    ambiguous_markdown(&mut s, r);
    twin_markdown(&mut s, a);
    let _ = writeln!(s, "## Held-out residual RMS, before and after\n");
    let _ = writeln!(
        s,
        "The velocity signals (measured and predicted alike, here, in the plots and in the replay CSV) are \
         centred moving averages over {} samples, the prefilter of the prediction error \
         (`crate::prefilter_velocities`).\n",
        2 * crate::VELOCITY_PREFILTER_HALF + 1
    );
    let _ = writeln!(
        s,
        "| signal | unit | samples | before | after | change |\n|---|---|---|---|---|---|"
    );
    for m in &r.rms {
        if m.samples > 0 {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.4e} | {:.4e} | {:+.1} % |",
                m.signal,
                m.unit,
                m.samples,
                m.before,
                m.after,
                reduction_percent(m.before, m.after)
            );
        }
    }
    let _ = writeln!(
        s,
        "\nPer Autodig stage (held-out digs):\n\n| signal | stage | samples | before | after |\n|---|---|---|---|---|"
    );
    for m in &r.rms {
        for (st, n, b, af) in &m.per_stage {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.4e} | {:.4e} |",
                m.signal, st, n, b, af
            );
        }
    }
    let _ = writeln!(s, "\n## Candidate scores per round\n");
    for (i, round) in r.rounds.iter().enumerate() {
        let _ = writeln!(
            s,
            "Round {}:\n\n| candidate | magnitude | uncertainty | train chi2 drop | held-out dBIC | explained (where it acts) | significant |\n|---|---|---|---|---|---|---|",
            i + 1
        );
        for c in round {
            let _ = writeln!(
                s,
                "| {} | {:.4e} | {:.2e} | {:.1} | {:.1} | {:.3} ({:.3}) | {} |",
                c.name,
                c.magnitude,
                c.uncertainty,
                c.train_chi2_drop,
                c.heldout_delta_bic,
                c.heldout_explained,
                c.heldout_explained_acted,
                c.veto.as_deref().unwrap_or("yes")
            );
        }
        s.push('\n');
    }
    let _ = writeln!(s, "## Where the nominal model is wrong (all digs)\n");
    let _ = writeln!(
        s,
        "| signal | RMS | mean | lag-1 autocorr | Ljung-Box Q(20) | white | max input xcorr (lag) |\n|---|---|---|---|---|---|---|"
    );
    for l in &r.localisation {
        if l.overall.samples > 0 {
            let _ = writeln!(
                s,
                "| {} | {:.3e} | {:.3e} | {:.2} | {:.0} | {} | {:.2} ({}) |",
                l.signal,
                l.overall.rms,
                l.overall.mean,
                l.autocorrelation[0],
                l.ljung_box_q,
                l.white,
                l.input_cross_correlation.0,
                l.input_cross_correlation.1
            );
        }
    }
    let _ = writeln!(
        s,
        "\nPer stage and regime (mean / RMS of measured - model):\n"
    );
    for l in &r.localisation {
        if l.overall.samples == 0 {
            continue;
        }
        let _ = writeln!(
            s,
            "- **{}** [{}]: {}",
            l.signal,
            l.unit,
            l.bins
                .iter()
                .map(|b| format!(
                    "{} n={} mean {:.2e} rms {:.2e}",
                    b.bin, b.samples, b.mean, b.rms
                ))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    let _ = writeln!(s, "\n## Figures\n");
    for f in figures {
        let _ = writeln!(s, "![{f}]({f})\n");
    }
    s
}

/// The ambiguous pairs: both candidates, alone and jointly fitted, and why neither is named.
fn ambiguous_markdown(s: &mut String, r: &AnalysisResult) {
    if r.ambiguous.is_empty() {
        return;
    }
    let _ = writeln!(s, "## Ambiguous: confusable candidates\n");
    for a in &r.ambiguous {
        let _ = writeln!(s, "{}\n", a.note);
        let _ = writeln!(
            s,
            "| candidate | kind | alone | held-out dBIC alone | joint fit | unit |\n|---|---|---|---|---|---|"
        );
        for c in &a.candidates {
            let _ = writeln!(
                s,
                "| {} | {} | {:.4e} +- {:.2e} | {:.0} | {:.4e} +- {:.2e} | {} |",
                c.name,
                c.kind,
                c.alone,
                c.alone_uncertainty,
                c.alone_delta_bic,
                c.joint,
                c.joint_uncertainty,
                c.unit
            );
        }
        let _ = writeln!(s);
    }
}

/// Writes the analysis outputs to `out`.
///
/// # Errors
/// Creating the folder or writing a file.
pub fn write_outputs(
    out: &Path,
    a: &Analysis,
    measured: &[PathBuf],
    all_csv: bool,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let r = &a.result;
    let mut effects: Vec<ModelEffect> = a.model.effects.clone();
    // The named machine parameters are in the parameters (`r.params`), the effects listed.
    // Of an ambiguous pair, the model carries the better one alone.
    let carried = r
        .named_effects
        .iter()
        .filter(|e| e.kind == "effect")
        .map(|e| (e.name.as_str(), e.magnitude, e.uncertainty))
        .chain(
            r.ambiguous
                .iter()
                .map(|a| &a.candidates[0])
                .filter(|c| c.kind == "effect")
                .map(|c| (c.name.as_str(), c.alone, c.alone_uncertainty)),
        );
    for (name, magnitude, uncertainty) in carried {
        // A refitted calibration effect adds its change to the calibrated value.
        match effects.iter_mut().find(|m| m.name == name) {
            Some(m) => {
                m.magnitude += magnitude;
                m.uncertainty = m.uncertainty.hypot(uncertainty);
            }
            None => effects.push(ModelEffect {
                name: name.to_string(),
                magnitude,
                uncertainty,
            }),
        }
    }
    let model = AugmentedModel::new(
        r.params.clone(),
        effects,
        format!(
            "augmented by excavator-ctl discrepancy from {} ({})",
            measured
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            a.model.provenance
        ),
    );
    std::fs::write(out.join("model.json"), model.to_json()?).context("writing model.json")?;
    if let Some(reference) = &a.reference {
        std::fs::write(out.join("reference.json"), reference.to_json()?)
            .context("writing reference.json")?;
    }
    if let Some((profile, _)) = &a.twin {
        let dir = out.join("twin");
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        std::fs::write(dir.join("machine.toml"), &profile.machine_toml)
            .context("writing twin/machine.toml")?;
        std::fs::write(dir.join("effects.toml"), profile.effects_toml())
            .context("writing twin/effects.toml")?;
    }
    let mut figures = Vec::new();
    let test: Vec<&PreparedRecord> = a
        .records
        .iter()
        .filter(|rec| r.test_digs.contains(&rec.index))
        .collect();
    if let Some(rec) = test.iter().max_by_key(|rec| rec.len()) {
        let name = format!("dig_{}_signals.svg", rec.index);
        let svg = dig_svg(rec, &a.model, &model, r)?;
        std::fs::write(out.join(&name), svg).with_context(|| format!("writing {name}"))?;
        figures.push(name);
        let csv_name = format!("dig_{}_replay.csv", rec.index);
        std::fs::write(out.join(&csv_name), replay_csv(rec, &a.model, &model, r)?)
            .with_context(|| format!("writing {csv_name}"))?;
    }
    if all_csv {
        for rec in &a.records {
            let csv_name = format!("dig_{}_replay.csv", rec.index);
            std::fs::write(out.join(&csv_name), replay_csv(rec, &a.model, &model, r)?)
                .with_context(|| format!("writing {csv_name}"))?;
        }
    }
    let svg = rms_svg(r)?;
    std::fs::write(out.join("residual_rms.svg"), svg).context("writing residual_rms.svg")?;
    figures.push("residual_rms.svg".into());
    let json = ReportJson {
        measured: measured.iter().map(|p| p.display().to_string()).collect(),
        skipped_sessions: &a.skipped_sessions,
        model_in: &a.model.provenance,
        model_out: "model.json",
        digs: a.records.len(),
        outcome: a.verdict.as_ref().map(|v| v.outcome),
        named_effects: named_entries(a),
        terms: &a.terms,
        ambiguous: &r.ambiguous,
        no_missing_effect_found: r.named_effects.is_empty()
            && r.ambiguous.is_empty()
            && a.verdict.as_ref().is_some_and(|v| {
                v.unexplained.is_empty() && v.outcome != crate::verdict::Outcome::NotJudged
            }),
        unexplained: a
            .verdict
            .as_ref()
            .map_or(&[][..], |v| v.unexplained.as_slice()),
        warnings: &a.warnings,
        verdict: a.verdict.as_ref(),
        reference: a.reference.as_ref().map(|r| r.source.as_slice()),
        residual_rms: &r.rms,
        rounds: &r.rounds,
        localisation: &r.localisation,
        train_digs: &r.train_digs,
        test_digs: &r.test_digs,
        nominal_sigma: &r.sigma,
        kappa: &r.kappa,
        figures: figures.clone(),
        twin: a.twin.as_ref().map(|(_, t)| t),
    };
    std::fs::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&json)?,
    )
    .context("writing report.json")?;
    std::fs::write(out.join("report.md"), markdown(a, measured, &figures))
        .context("writing report.md")?;
    Ok(())
}

/// One dig's replayed signals, a row per sample.
type Replayed = Vec<[f64; N_SIGNALS]>;

/// Every signal of one dig replayed by the nominal (`old`) and the augmented (`new`) model.
fn replay_old_new(
    rec: &PreparedRecord,
    old: &AugmentedModel,
    new: &AugmentedModel,
    r: &AnalysisResult,
) -> anyhow::Result<(Replayed, Replayed)> {
    let (mut p_old, mut p_new) = (Vec::new(), Vec::new());
    replay(
        rec,
        &old.params,
        &old.augmentation()?,
        SignalGroups::ALL,
        &mut p_old,
    );
    replay(
        rec,
        &new.params,
        &r.augmentation,
        SignalGroups::ALL,
        &mut p_new,
    );
    Ok((p_old, p_new))
}

/// One dig as CSV: inputs, then every signal measured, nominal and augmented (empty where undefined).
fn replay_csv(
    rec: &PreparedRecord,
    old: &AugmentedModel,
    new: &AugmentedModel,
    r: &AnalysisResult,
) -> anyhow::Result<String> {
    let (p_old, p_new) = replay_old_new(rec, old, new, r)?;
    let mut s = String::from(
        "time_s,stage,load,u_boom,u_stick,u_bucket,u_swing,head_boom,rod_boom,head_stick,rod_stick,head_bucket,rod_bucket,pump1,pump2,angle_boom_rad,angle_stick_rad,angle_bucket_rad,swing_rad,swing_rate_rad_per_s",
    );
    for sig in Signal::ALL {
        let _ = write!(s, ",{0}_measured,{0}_nominal,{0}_augmented", sig.name());
    }
    s.push_str(
        ",soil_depth_m,soil_slope_tan,soil_volume_m3,soil_x_per_pa,soil_z_per_pa,soil_x_per_kg_m3,soil_z_per_kg_m3,soil_x_per_payload_kg,soil_z_per_payload_kg",
    );
    s.push('\n');
    let cell = |v: f64| {
        if v.is_finite() {
            format!("{v:.6e}")
        } else {
            String::new()
        }
    };
    for (k, smp) in rec.samples.iter().enumerate() {
        let _ = write!(
            s,
            "{:.3},{},{:?},{:.4},{:.4},{:.4},{:.4}",
            smp.time_s,
            smp.stage.name(),
            smp.load,
            smp.command[0],
            smp.command[1],
            smp.command[2],
            smp.swing_command
        );
        for i in 0..3 {
            let _ = write!(s, ",{:.0},{:.0}", smp.head_pa[i], smp.rod_pa[i]);
        }
        let _ = write!(s, ",{:.0},{:.0}", smp.pump_pa[0], smp.pump_pa[1]);
        for a in smp.angles_rad {
            let _ = write!(s, ",{a:.5}");
        }
        let _ = write!(s, ",{:.5},{:.5}", smp.swing_rad, smp.swing_rate_rad_per_s);
        for j in 0..N_SIGNALS {
            let _ = write!(
                s,
                ",{},{},{}",
                cell(rec.measured[k][j]),
                cell(p_old[k][j]),
                cell(p_new[k][j])
            );
        }
        // The soil relation's terms: depth, payload volume and the sensitivities of the modelled
        // soil force to cohesion and density and of the measured one to the payload mass.
        match rec.soil_terms().get(k).copied().flatten() {
            Some(t) => {
                let _ = write!(
                    s,
                    ",{:.4},{:.4},{:.4},{},{},{},{},{},{}",
                    t.depth_m,
                    t.slope_tan,
                    t.payload_volume_m3,
                    cell(t.fee_per_pa[0]),
                    cell(t.fee_per_pa[1]),
                    cell(t.fee_per_density[0]),
                    cell(t.fee_per_density[1]),
                    cell(t.measured_per_kg[0]),
                    cell(t.measured_per_kg[1])
                );
            }
            None => s.push_str(",,,,,,,,,"),
        }
        s.push('\n');
    }
    Ok(s)
}

/// One held-out dig: every signal measured (black), nominal model (blue), augmented model (red).
fn dig_svg(
    rec: &PreparedRecord,
    old: &AugmentedModel,
    new: &AugmentedModel,
    r: &AnalysisResult,
) -> anyhow::Result<String> {
    let (p_old, p_new) = replay_old_new(rec, old, new, r)?;
    let t0 = rec.samples.first().map_or(0.0, |s| s.time_s);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 1500)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let panels = root.split_evenly((N_SIGNALS.div_ceil(2), 2));
        for (j, area) in panels.iter().enumerate().take(N_SIGNALS) {
            let sig = Signal::ALL[j];
            let scale = if sig.unit() == "Pa" {
                1e-6
            } else if sig.unit() == "N" {
                1e-3
            } else {
                1.0
            };
            let unit = match sig.unit() {
                "Pa" => "MPa",
                "N" => "kN",
                u => u,
            };
            // The samples where the signal is defined, in runs of consecutive samples: a line joins
            // the samples of a run only (a signal left out for seconds is not drawn across the gap).
            let series = |vals: &dyn Fn(usize) -> f64| -> Vec<Vec<(f64, f64)>> {
                runs_of(
                    (0..rec.len())
                        .filter(|k| rec.measured[*k][j].is_finite() && vals(*k).is_finite())
                        .map(|k| (k, (rec.samples[k].time_s - t0, vals(k) * scale))),
                )
            };
            let meas = series(&|k| rec.measured[k][j]);
            let old_s = series(&|k| p_old[k][j]);
            let new_s = series(&|k| p_new[k][j]);
            if meas.is_empty() {
                continue;
            }
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for (_, y) in meas.iter().chain(&old_s).chain(&new_s).flatten() {
                lo = lo.min(*y);
                hi = hi.max(*y);
            }
            if hi <= lo {
                hi = lo + 1.0;
            }
            let pad = 0.05 * (hi - lo);
            let t_end = rec.samples.last().map_or(1.0, |s| s.time_s - t0).max(1.0);
            let mut chart = ChartBuilder::on(area)
                .caption(format!("{} [{unit}]", sig.name()), ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(25)
                .y_label_area_size(55)
                .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))
                .map_err(err)?;
            chart.configure_mesh().x_desc("t [s]").draw().map_err(err)?;
            for (runs, color, label) in [
                (meas, BLACK.to_rgba(), "measured"),
                (old_s, BLUE.mix(0.7), "nominal model"),
                (new_s, RED.mix(0.7), "augmented model"),
            ] {
                draw_runs(&mut chart, runs, color, label)?;
            }
            if j == 0 {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .label_font(("sans-serif", 11))
                    .draw()
                    .map_err(err)?;
            }
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// Splits `(sample index, point)` pairs, in increasing index, into runs of consecutive indices.
fn runs_of(points: impl IntoIterator<Item = (usize, (f64, f64))>) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut last: Option<usize> = None;
    for (k, point) in points {
        match runs.last_mut() {
            Some(run) if last.is_some_and(|l| l + 1 == k) => run.push(point),
            _ => runs.push(vec![point]),
        }
        last = Some(k);
    }
    runs
}

/// Draws the runs of one series (lines; a run of one sample as a dot), with one legend entry.
fn draw_runs<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    runs: Vec<Vec<(f64, f64)>>,
    color: RGBAColor,
    label: &str,
) -> anyhow::Result<()> {
    let style = ShapeStyle::from(color).stroke_width(1);
    let mut labelled = false;
    for run in runs {
        let drawn = if run.len() == 1 {
            chart
                .draw_series(run.into_iter().map(|p| Circle::new(p, 2, style.filled())))
                .map_err(err)?
        } else {
            chart
                .draw_series(LineSeries::new(run, style))
                .map_err(err)?
        };
        if !labelled {
            drawn
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], style));
            labelled = true;
        }
    }
    Ok(())
}

/// Held-out RMS before and after as percentages of the nominal RMS, per signal.
fn rms_svg(r: &AnalysisResult) -> anyhow::Result<String> {
    let rows: Vec<_> = r
        .rms
        .iter()
        .filter(|m| m.samples > 0 && m.before > 0.0)
        .collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1300, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "held-out residual RMS after augmentation, % of the nominal model's",
                ("sans-serif", 15),
            )
            .margin(12)
            .x_label_area_size(60)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..rows.len().max(1) as f64, 0.0..120.0)
            .map_err(err)?;
        let names: Vec<String> = rows.iter().map(|m| m.signal.to_string()).collect();
        // A label under the middle of every bar (ticks every half bar, the names on the middles).
        chart
            .configure_mesh()
            .x_labels(2 * rows.len().max(1) + 1)
            .x_label_formatter(&|x| {
                if (x - x.floor() - 0.5).abs() < 0.01 {
                    names.get(x.floor() as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_desc("%")
            .draw()
            .map_err(err)?;
        chart
            .draw_series(rows.iter().enumerate().map(|(i, m)| {
                let pct = (100.0 * m.after / m.before).min(120.0);
                Rectangle::new(
                    [(i as f64 + 0.15, 0.0), (i as f64 + 0.85, pct)],
                    RED.mix(0.6).filled(),
                )
            }))
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(
                vec![(0.0, 100.0), (rows.len().max(1) as f64, 100.0)],
                BLUE.stroke_width(1),
            ))
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A signal left out for a while is drawn as separate runs, not joined across the gap.
    #[test]
    fn runs_break_at_gaps_in_the_sample_index() {
        let p = |k: usize| (k, (k as f64, 1.0));
        let runs = runs_of([p(3), p(4), p(5), p(9), p(11), p(12)]);
        assert_eq!(runs.len(), 3);
        assert_eq!(runs.iter().map(Vec::len).collect::<Vec<_>>(), [3, 1, 2]);
        assert_eq!(runs[1], [(9.0, 1.0)]);
        assert!(runs_of(std::iter::empty()).is_empty());
    }
}
