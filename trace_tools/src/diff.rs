//! `trace diff A B`: where two traces of the same scenario (a machine run and a simulator run, two
//! simulator versions) first diverge, per signal.
//!
//! Each trace's time starts at its own first frame (`--offset-ms` shifts B). Both are streamed
//! together in time order and every signal is sampled on a common grid (`--step-ms`, 10 ms, the
//! control period) with the latest value of each trace at that time (zero-order hold). Per signal:
//! the first grid time where `|A - B|` exceeds the tolerance, the difference there, the largest
//! difference and the RMS difference over the grid points where both traces have a valid value.
//! The comparison ends when either trace ends.
//!
//! Tolerances are absolute, in the signal's DBC unit: `--tol NAME=VALUE` per signal (bare names apply
//! to every message with that signal), otherwise `--rel-tol` (1 %) of the signal's DBC range.
//! Alive counters, sequence counters and checksums are left out unless named with `--signal`: they
//! differ between any two runs.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::{self, BufRead, Write};
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use firmware_bridge::trace::{TraceError, TraceRecord};

use super::input::{self, Records};
use super::signals::{self, SignalRef};

/// `trace diff` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct DiffArgs {
    /// Reference trace (for example the machine).
    pub a: PathBuf,
    /// Trace to compare (for example the simulator).
    pub b: PathBuf,
    /// Comparison grid, ms.
    #[arg(long, default_value_t = 10.0, value_name = "MS")]
    pub step_ms: f64,
    /// Absolute tolerance of a signal in its DBC unit, `NAME=VALUE` (`BoomAngle=0.01`); repeatable.
    #[arg(long = "tol", value_name = "NAME=VALUE")]
    pub tolerances: Vec<String>,
    /// Default tolerance as a fraction of each signal's DBC range.
    #[arg(long, default_value_t = 0.01)]
    pub rel_tol: f64,
    /// Compare only these signals (`BoomAngle` or `Message.Signal`); repeatable.
    #[arg(long = "signal", value_name = "NAME")]
    pub signals: Vec<String>,
    /// Shift B by this many ms (positive: B's events count as later).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "MS",
        allow_hyphen_values = true
    )]
    pub offset_ms: f64,
    /// Stop at the first malformed line.
    #[arg(long)]
    pub strict: bool,
    /// Machine profile both traces were recorded with (their wire frames are read as the project's
    /// messages).
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// Machine profile of B when it differs from A's (`--profile`), e.g. the same scenario on
    /// another gateway.
    #[arg(long, value_name = "FILE")]
    pub profile_b: Option<PathBuf>,
    /// The traces are `candump -td` output (timestamps since the previous frame).
    #[arg(long)]
    pub delta_timestamps: bool,
}

/// Settings of [`diff_traces`].
#[derive(Debug, Clone, PartialEq)]
pub struct DiffOptions {
    /// Grid step, s.
    pub step_s: f64,
    /// Tolerance fraction of the DBC range.
    pub rel_tol: f64,
    /// `NAME=VALUE` overrides.
    pub tolerances: Vec<String>,
    /// Signals to compare (empty: all but counters and checksums).
    pub signals: Vec<String>,
    /// Shift of B, s.
    pub offset_s: f64,
    /// How to read A (`strict`, its profile).
    pub read_a: input::ReadOptions,
    /// How to read B.
    pub read_b: input::ReadOptions,
}

impl Default for DiffOptions {
    fn default() -> Self {
        Self {
            step_s: 0.01,
            rel_tol: 0.01,
            tolerances: Vec::new(),
            signals: Vec::new(),
            offset_s: 0.0,
            read_a: input::ReadOptions::default(),
            read_b: input::ReadOptions::default(),
        }
    }
}

/// The comparison of one signal.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalDiff {
    /// `Message.Signal`.
    pub name: String,
    /// DBC unit.
    pub unit: &'static str,
    /// Tolerance used.
    pub tolerance: f64,
    /// Grid points where both traces had a valid value.
    pub compared: u64,
    /// Grid points where exactly one trace had a valid value.
    pub one_sided: u64,
    /// First divergence: time (s), A, B.
    pub first_divergence: Option<(f64, f64, f64)>,
    /// Largest `|A - B|` and its time (s).
    pub max_abs: Option<(f64, f64)>,
    /// RMS of `A - B` over the compared points.
    pub rms: Option<f64>,
}

/// The whole comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct DiffReport {
    /// Records read from A and B.
    pub records: (u64, u64),
    /// Spans of A and B, s.
    pub spans_s: (f64, f64),
    /// Time compared, s.
    pub compared_s: f64,
    /// Per signal, diverging ones first by time of divergence, then by name.
    pub signals: Vec<SignalDiff>,
    /// Signals seen only in A, only in B.
    pub only_in: (Vec<String>, Vec<String>),
}

#[derive(Debug, Clone, Default)]
struct Acc {
    compared: u64,
    one_sided: u64,
    sum_sq: f64,
    max_abs: Option<(f64, f64)>,
    first: Option<(f64, f64, f64)>,
}

/// One side of the comparison: a record stream with its latest values.
struct Side<R: BufRead> {
    records: Records<R>,
    peeked: Option<TraceRecord>,
    first_ns: Option<u64>,
    last_ns: u64,
    count: u64,
    values: Vec<f64>,
    seen: Vec<bool>,
    offset_s: f64,
    strict: bool,
    label: &'static str,
}

impl<R: BufRead> Side<R> {
    fn new(input: R, offset_s: f64, read: &input::ReadOptions, label: &'static str) -> Self {
        let n = signals::all_signals().len();
        let strict = read.strict;
        Self {
            records: Records::with_options(input, read),
            peeked: None,
            first_ns: None,
            last_ns: 0,
            count: 0,
            values: vec![f64::NAN; n],
            seen: vec![false; n],
            offset_s,
            strict,
            label,
        }
    }

    /// Fills `peeked`; false at the end of the stream.
    fn peek(&mut self, diag: &mut dyn Write) -> anyhow::Result<bool> {
        while self.peeked.is_none() {
            match self.records.next() {
                None => return Ok(false),
                Some(Ok(rec)) => {
                    self.first_ns.get_or_insert(rec.timestamp_ns);
                    self.peeked = Some(rec);
                }
                Some(Err(
                    TraceError::Malformed { line, kind } | TraceError::Truncated { line, kind },
                )) => {
                    if self.strict {
                        anyhow::bail!("{}: line {line}: malformed: {kind}", self.label);
                    }
                    if self.records.malformed() <= input::MAX_REPORTED_LINES {
                        let _ = writeln!(
                            diag,
                            "warning: {}: line {line}: {kind} (skipped)",
                            self.label
                        );
                    }
                }
                Some(Err(e)) => {
                    return Err(anyhow::Error::new(e).context(format!("reading {}", self.label)));
                }
            }
        }
        Ok(true)
    }

    /// Time of the peeked record relative to this trace's start (plus the offset), s.
    fn peeked_time(&self) -> Option<f64> {
        let rec = self.peeked.as_ref()?;
        let first = self.first_ns.unwrap_or(rec.timestamp_ns);
        Some(rec.timestamp_ns.saturating_sub(first) as f64 * 1e-9 + self.offset_s)
    }

    fn apply_peeked(&mut self) {
        let Some(rec) = self.peeked.take() else {
            return;
        };
        self.count += 1;
        self.last_ns = self.last_ns.max(rec.timestamp_ns);
        let Some((msg_index, desc)) = signals::message_of(&rec.frame) else {
            return;
        };
        let data = rec.frame.data();
        if data.len() != usize::from(desc.dlc) {
            return;
        }
        let base = signals::first_column(msg_index);
        for (i, sig) in desc.signals.iter().enumerate() {
            if let (Some(v), Some(seen)) =
                (self.values.get_mut(base + i), self.seen.get_mut(base + i))
            {
                *v = signals::decode_signal(sig, data)
                    .value()
                    .unwrap_or(f64::NAN);
                *seen = true;
            }
        }
    }

    fn span_s(&self) -> f64 {
        self.first_ns
            .map_or(0.0, |f| self.last_ns.saturating_sub(f) as f64 * 1e-9)
    }
}

fn is_bookkeeping(s: &SignalRef) -> bool {
    matches!(
        s.signal().name,
        "AliveCounter" | "SequenceCounter" | "Checksum"
    )
}

fn selected_signals(opts: &DiffOptions) -> anyhow::Result<Vec<SignalRef>> {
    if opts.signals.is_empty() {
        return Ok(signals::all_signals()
            .iter()
            .filter(|s| !is_bookkeeping(s))
            .copied()
            .collect());
    }
    opts.signals
        .iter()
        .map(|n| signals::resolve_signal(n).map_err(anyhow::Error::msg))
        .collect()
}

fn tolerances(opts: &DiffOptions) -> anyhow::Result<Vec<f64>> {
    if !(opts.rel_tol.is_finite() && opts.rel_tol >= 0.0) {
        anyhow::bail!("--rel-tol must be a non-negative number");
    }
    let all = signals::all_signals();
    let mut tol: Vec<f64> = all
        .iter()
        .map(|s| (s.signal().max - s.signal().min).abs() * opts.rel_tol)
        .collect();
    let mut overrides: HashMap<usize, f64> = HashMap::new();
    for spec in &opts.tolerances {
        let (name, value) = spec
            .split_once('=')
            .with_context(|| format!("--tol {spec:?}: expected NAME=VALUE"))?;
        let value: f64 = value
            .trim()
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && *v >= 0.0)
            .with_context(|| format!("--tol {spec:?}: the value must be a non-negative number"))?;
        let name = name.trim();
        let matching: Vec<usize> = if name.contains('.') {
            vec![
                signals::resolve_signal(name)
                    .map_err(anyhow::Error::msg)?
                    .column,
            ]
        } else {
            all.iter()
                .filter(|s| s.signal().name.eq_ignore_ascii_case(name))
                .map(|s| s.column)
                .collect()
        };
        if matching.is_empty() {
            signals::resolve_signal(name).map_err(anyhow::Error::msg)?;
        }
        for c in matching {
            overrides.insert(c, value);
        }
    }
    for (c, v) in overrides {
        if let Some(t) = tol.get_mut(c) {
            *t = v;
        }
    }
    Ok(tol)
}

/// Compares two traces.
///
/// # Errors
/// Bad options, read errors, malformed lines with `strict`.
pub fn diff_traces<RA: BufRead, RB: BufRead>(
    a: RA,
    b: RB,
    opts: &DiffOptions,
    diag: &mut dyn Write,
) -> anyhow::Result<DiffReport> {
    if !(opts.step_s.is_finite() && opts.step_s > 0.0) {
        anyhow::bail!("--step-ms must be positive");
    }
    if !opts.offset_s.is_finite() {
        anyhow::bail!("--offset-ms must be a number");
    }
    let selected = selected_signals(opts)?;
    let tol = tolerances(opts)?;
    let mut side_a = Side::new(a, 0.0, &opts.read_a, "A");
    let mut side_b = Side::new(b, opts.offset_s, &opts.read_b, "B");
    let mut acc = vec![Acc::default(); selected.len()];
    let mut grid_index: u64 = 0;
    let mut compared_s = 0.0;
    let mut compare = |t: f64, side_a: &Side<RA>, side_b: &Side<RB>| {
        for (s, acc) in selected.iter().zip(acc.iter_mut()) {
            let (va, vb) = (
                side_a.values.get(s.column).copied().unwrap_or(f64::NAN),
                side_b.values.get(s.column).copied().unwrap_or(f64::NAN),
            );
            match (va.is_finite(), vb.is_finite()) {
                (true, true) => {
                    let d = va - vb;
                    acc.compared += 1;
                    acc.sum_sq += d * d;
                    if acc.max_abs.is_none_or(|(m, _)| d.abs() > m) {
                        acc.max_abs = Some((d.abs(), t));
                    }
                    let limit = tol.get(s.column).copied().unwrap_or(0.0);
                    if acc.first.is_none() && d.abs() > limit {
                        acc.first = Some((t, va, vb));
                    }
                }
                (false, false) => {}
                _ => {
                    // Before both sides have sent the message, a missing value is only startup.
                    if side_a.seen.get(s.column) == Some(&true)
                        && side_b.seen.get(s.column) == Some(&true)
                    {
                        acc.one_sided += 1;
                    }
                }
            }
        }
    };
    loop {
        let more_a = side_a.peek(diag)?;
        let more_b = side_b.peek(diag)?;
        if !more_a || !more_b {
            break;
        }
        let ta = side_a.peeked_time().unwrap_or(f64::INFINITY);
        let tb = side_b.peeked_time().unwrap_or(f64::INFINITY);
        let grid_t = grid_index as f64 * opts.step_s;
        let next = ta.min(tb);
        if next <= grid_t {
            if ta <= tb {
                side_a.apply_peeked();
            } else {
                side_b.apply_peeked();
            }
        } else {
            compare(grid_t, &side_a, &side_b);
            compared_s = grid_t;
            grid_index += 1;
        }
    }
    // Drain the rest for the counts and spans, without comparing.
    while side_a.peek(diag)? {
        side_a.apply_peeked();
    }
    while side_b.peek(diag)? {
        side_b.apply_peeked();
    }
    if let Some(e) = side_a.records.nothing_read(side_a.count) {
        return Err(e.context("reading A"));
    }
    if let Some(e) = side_b.records.nothing_read(side_b.count) {
        return Err(e.context("reading B"));
    }
    side_a.records.warn_at_end(diag);
    side_b.records.warn_at_end(diag);

    let mut only_a = Vec::new();
    let mut only_b = Vec::new();
    let mut out: Vec<SignalDiff> = Vec::new();
    for (s, acc) in selected.iter().zip(acc) {
        let (sa, sb) = (
            side_a.seen.get(s.column) == Some(&true),
            side_b.seen.get(s.column) == Some(&true),
        );
        match (sa, sb) {
            (true, false) => only_a.push(s.full_name()),
            (false, true) => only_b.push(s.full_name()),
            _ => {}
        }
        if !(sa && sb) {
            continue;
        }
        out.push(SignalDiff {
            name: s.full_name(),
            unit: s.signal().unit,
            tolerance: tol.get(s.column).copied().unwrap_or(0.0),
            compared: acc.compared,
            one_sided: acc.one_sided,
            first_divergence: acc.first,
            max_abs: acc.max_abs,
            rms: (acc.compared > 0).then(|| (acc.sum_sq / acc.compared as f64).sqrt()),
        });
    }
    out.sort_by(|x, y| {
        let tx = x.first_divergence.map_or(f64::INFINITY, |f| f.0);
        let ty = y.first_divergence.map_or(f64::INFINITY, |f| f.0);
        tx.total_cmp(&ty).then_with(|| x.name.cmp(&y.name))
    });
    Ok(DiffReport {
        records: (side_a.count, side_b.count),
        spans_s: (side_a.span_s(), side_b.span_s()),
        compared_s,
        signals: out,
        only_in: (only_a, only_b),
    })
}

fn with_unit(v: f64, unit: &str) -> String {
    if unit.is_empty() {
        format!("{v:.6}")
    } else {
        format!("{v:.6} {unit}")
    }
}

/// Formats the report as text.
pub fn format_report(r: &DiffReport, a: &str, b: &str) -> String {
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(
        s,
        "A: {a} ({} frames, {:.3} s)\nB: {b} ({} frames, {:.3} s)\ncompared over {:.3} s",
        r.records.0, r.spans_s.0, r.records.1, r.spans_s.1, r.compared_s
    );
    let diverging: Vec<&SignalDiff> = r
        .signals
        .iter()
        .filter(|d| d.first_divergence.is_some())
        .collect();
    match diverging.first() {
        Some(d) => {
            if let Some((t, va, vb)) = d.first_divergence {
                let _ = writeln!(
                    s,
                    "first divergence at {t:.3} s: {} |A-B| = {} (A {}, B {}; tolerance {})",
                    d.name,
                    with_unit((va - vb).abs(), d.unit),
                    with_unit(va, d.unit),
                    with_unit(vb, d.unit),
                    with_unit(d.tolerance, d.unit)
                );
            }
        }
        None => {
            let _ = writeln!(s, "no signal diverges beyond its tolerance");
        }
    }
    let _ = writeln!(
        s,
        "\n{:<44} {:>10} {:>14} {:>14} {:>14} {:>12} {:>8}",
        "signal", "first_s", "|A-B| there", "max |A-B|", "rms", "tolerance", "points"
    );
    for d in &r.signals {
        let (first_t, there) = d
            .first_divergence
            .map_or(("-".to_string(), "-".to_string()), |(t, va, vb)| {
                (format!("{t:.3}"), format!("{:.6}", (va - vb).abs()))
            });
        let _ = writeln!(
            s,
            "{:<44} {:>10} {:>14} {:>14} {:>14} {:>12} {:>8}{}",
            if d.unit.is_empty() {
                d.name.clone()
            } else {
                format!("{} [{}]", d.name, d.unit)
            },
            first_t,
            there,
            d.max_abs
                .map_or_else(|| "-".to_string(), |(m, _)| format!("{m:.6}")),
            d.rms.map_or_else(|| "-".to_string(), |v| format!("{v:.6}")),
            format!("{:.6}", d.tolerance),
            d.compared,
            if d.one_sided > 0 {
                format!("  ({} one-sided)", d.one_sided)
            } else {
                String::new()
            }
        );
    }
    if !r.only_in.0.is_empty() {
        let _ = writeln!(s, "\nonly in A: {}", r.only_in.0.join(", "));
    }
    if !r.only_in.1.is_empty() {
        let _ = writeln!(s, "\nonly in B: {}", r.only_in.1.join(", "));
    }
    s
}

/// Runs `trace diff`.
///
/// # Errors
/// As [`diff_traces`], and files that cannot be opened.
pub fn run(args: &DiffArgs) -> anyhow::Result<()> {
    if input::is_stdin(&args.a) && input::is_stdin(&args.b) {
        anyhow::bail!("only one of A and B can be stdin");
    }
    let read = |profile: Option<&Path>| -> anyhow::Result<input::ReadOptions> {
        Ok(input::ReadOptions {
            strict: args.strict,
            delta_timestamps: args.delta_timestamps,
            profile: input::load_profile(profile)?,
        })
    };
    let read_a = read(args.profile.as_deref())?;
    let read_b = read(args.profile_b.as_deref().or(args.profile.as_deref()))?;
    let a = input::open(&args.a)?;
    let b = input::open(&args.b)?;
    let opts = DiffOptions {
        step_s: args.step_ms * 1e-3,
        rel_tol: args.rel_tol,
        tolerances: args.tolerances.clone(),
        signals: args.signals.clone(),
        offset_s: args.offset_ms * 1e-3,
        read_a,
        read_b,
    };
    let report = diff_traces(a, b, &opts, &mut io::stderr())
        .with_context(|| format!("A {}, B {}", args.a.display(), args.b.display()))?;
    let text = format_report(
        &report,
        &args.a.display().to_string(),
        &args.b.display().to_string(),
    );
    let mut out = io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .context("writing the report")
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware_bridge::messages::{JointAngles, Message};

    fn angles_trace(boom: impl Fn(f64) -> f64, start_ns: u64) -> String {
        let mut s = String::new();
        for n in 0..200u64 {
            let t = n as f64 * 0.01;
            let frame = Message::JointAngles(JointAngles {
                boom_rad: boom(t),
                stick_rad: -1.5,
                bucket_rad: -1.0,
                swing_rad: 0.0,
            })
            .encode()
            .unwrap();
            s += &firmware_bridge::trace::format_line(
                start_ns + n * 10_000_000,
                "vcan0",
                &frame,
                None,
            );
            s.push('\n');
        }
        s
    }

    #[test]
    fn finds_the_first_divergence_and_its_size() {
        let a = angles_trace(|_| 0.5, 1_700_000_000_000_000_000);
        // B starts at another wall time; it drifts from t = 1.0 s at 0.1 rad/s.
        let b = angles_trace(|t| 0.5 + (t - 1.0).max(0.0) * 0.1, 5_000_000);
        let opts = DiffOptions {
            tolerances: vec!["BoomAngle=0.02".into()],
            ..DiffOptions::default()
        };
        let r = diff_traces(a.as_bytes(), b.as_bytes(), &opts, &mut io::sink()).unwrap();
        let boom = &r.signals[0];
        assert_eq!(boom.name, "JointAngles.BoomAngle");
        let (t, va, vb) = boom.first_divergence.unwrap();
        // 0.02 rad is exceeded just after t = 1.2 s.
        assert!((t - 1.21).abs() < 0.015, "{t}");
        assert!(((va - vb).abs() - 0.021).abs() < 0.002, "{va} {vb}");
        assert!(boom.rms.unwrap() > 0.0);
        // The constant stick angle never diverges.
        let stick = r
            .signals
            .iter()
            .find(|d| d.name == "JointAngles.StickAngle")
            .unwrap();
        assert_eq!(stick.first_divergence, None);
        assert_eq!(stick.rms, Some(0.0));
        let text = format_report(&r, "a", "b");
        assert!(text.contains("first divergence at 1.2"), "{text}");
    }

    #[test]
    fn identical_traces_do_not_diverge() {
        let a = angles_trace(|t| t.sin(), 0);
        let r = diff_traces(
            a.as_bytes(),
            a.as_bytes(),
            &DiffOptions::default(),
            &mut io::sink(),
        )
        .unwrap();
        assert!(r.signals.iter().all(|d| d.first_divergence.is_none()));
        assert!(r.compared_s > 1.9);
    }

    #[test]
    fn bad_tolerances_are_rejected() {
        let opts = DiffOptions {
            tolerances: vec!["BoomAngle".into()],
            ..DiffOptions::default()
        };
        assert!(diff_traces(&b""[..], &b""[..], &opts, &mut io::sink()).is_err());
        let opts = DiffOptions {
            tolerances: vec!["Nope=1".into()],
            ..DiffOptions::default()
        };
        assert!(diff_traces(&b""[..], &b""[..], &opts, &mut io::sink()).is_err());
    }
}
