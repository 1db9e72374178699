//! `summary.json` and `summary.md` of a session folder, which `demo` and `run` both write: the
//! per-dig records' totals, the thesis's Tables 3-5 figures (6.1, 6.2; Eqs. 26-27), how the session
//! ended, and the files it was made with.

use std::path::Path;

use anyhow::Context as _;
use controller::session::planned::PlannedSession;
use controller::session::snapshot::Strategy;
use controller::step::cycle::{Action, ActionKind};
use controller::step::node::ControllerNode;
use firmware_bridge::transport::{TraceClock, TraceTimeBase};
use serde::{Deserialize, Serialize};

use crate::record::{BenchSnapshot, DigRecord, SoilSamplesFile};

/// Which action source drives the session (`--strategy`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum DemoStrategy {
    /// The perception-based dig planner (5.1), default bench `config/bench_extended.toml`.
    #[default]
    Planned,
    /// The predefined excavation sequence (6.2), default bench `config/bench_extended.toml`.
    Predefined,
    /// The fixed demo plan or the `--config` file's plan, default bench `config/bench.toml`.
    Fixed,
}

impl DemoStrategy {
    /// The planned session's strategy, `None` for the fixed plan.
    #[must_use]
    pub fn session(self) -> Option<Strategy> {
        match self {
            Self::Planned => Some(Strategy::Planned),
            Self::Predefined => Some(Strategy::Predefined),
            Self::Fixed => None,
        }
    }

    /// The name in `summary.json`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Planned => "planned",
            Self::Predefined => "predefined",
            Self::Fixed => "fixed",
        }
    }
}

/// Totals of the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Totals {
    /// Digs completed (dig and cleanup actions).
    pub digs: usize,
    /// Dig actions.
    pub dig_actions: usize,
    /// Cleanup actions.
    pub cleanup_actions: usize,
    /// Track-back actions started.
    pub track_backs: usize,
    /// Sum of the weights, N.
    pub weight_n: f64,
    /// Mean weight per dig, N.
    pub mean_weight_n: f64,
    /// Mean time per dig, s.
    pub mean_time_s: f64,
    /// Mean energy per dig, kJ.
    pub mean_energy_kj: f64,
    /// Sum of the energies, kJ.
    pub energy_kj: f64,
    /// Sum of the swept volumes, m^3.
    pub swept_volume_m3: f64,
    /// Range scans taken.
    pub scans: usize,
    /// Virtual time of the session, s.
    pub sim_time_s: f64,
    /// Wall time of the session, s.
    pub wall_time_s: f64,
    /// Frames written to the trace.
    pub trace_frames: u64,
    /// Frames the trace recorder dropped (0 expected).
    pub trace_dropped: u64,
    /// Whether the plan finished (false: stopped by Ctrl-C or the time budget).
    pub finished: bool,
    /// The last fault of the safety layer, if any (`Display` text).
    pub last_fault: Option<String>,
}

/// Thesis Tables 3-5 figures of a session (6.1, 6.2).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SessionStats {
    /// Mean weight of the dig actions (normal digs), N.
    pub dig_mean_weight_n: f64,
    /// Mean time of the dig actions, s.
    pub dig_mean_time_s: f64,
    /// Mean energy of the dig actions, kJ.
    pub dig_mean_energy_kj: f64,
    /// Mean weight of the cleanup actions, N (0 without cleanups).
    pub cleanup_mean_weight_n: f64,
    /// Mean time of the cleanup actions, s.
    pub cleanup_mean_time_s: f64,
    /// Mean energy of the cleanup actions, kJ.
    pub cleanup_mean_energy_kj: f64,
    /// A full bucket's weight: capacity x bank density x g, N (the thesis's 25 000 N).
    pub full_bucket_n: f64,
    /// Share of all buckets (digs and cleanups) over half full (thesis test 3: 0.94).
    pub over_half_full: f64,
    /// Share of all buckets over a third full (thesis test 3: 0.98).
    pub over_third_full: f64,
    /// Eq. 26: mean weight / (12 s + mean time), N/s.
    pub productivity_n_per_s: f64,
    /// Eq. 27: mean energy / mean weight, kJ/N.
    pub energy_per_weight_kj_per_n: f64,
    /// Least-squares slope of the dig actions' weight over the dig number, N per dig (Fig. 60:
    /// the bucket fill must not decay).
    pub dig_weight_slope_n_per_dig: f64,
    /// Mean weight of the dig actions in the first half of the session, N.
    pub dig_mean_weight_first_half_n: f64,
    /// Mean weight of the dig actions in the second half, N.
    pub dig_mean_weight_second_half_n: f64,
}

impl SessionStats {
    /// The statistics of `digs`, with a full bucket of `full_bucket_n`.
    #[must_use]
    pub fn of(digs: &[DigRecord], full_bucket_n: f64) -> Self {
        let mean = |v: &[f64]| {
            if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let pick = |kind: ActionKind, f: fn(&DigRecord) -> f64| -> Vec<f64> {
            digs.iter().filter(|d| d.action == kind).map(f).collect()
        };
        let weight = |d: &DigRecord| d.weight_n.unwrap_or(0.0);
        let share = |k: f64| {
            if digs.is_empty() {
                0.0
            } else {
                digs.iter()
                    .filter(|d| weight(d) > k * full_bucket_n)
                    .count() as f64
                    / digs.len() as f64
            }
        };
        let w_all: Vec<f64> = digs.iter().map(weight).collect();
        let t_all: Vec<f64> = digs.iter().map(|d| d.time_s).collect();
        let e_all: Vec<f64> = digs.iter().map(|d| d.energy_kj).collect();
        let dig_w: Vec<(f64, f64)> = digs
            .iter()
            .filter(|d| d.action == ActionKind::Dig)
            .map(|d| (f64::from(d.index), weight(d)))
            .collect();
        let slope = {
            let n = dig_w.len() as f64;
            let (mx, my) = (
                dig_w.iter().map(|p| p.0).sum::<f64>() / n.max(1.0),
                dig_w.iter().map(|p| p.1).sum::<f64>() / n.max(1.0),
            );
            let sxx: f64 = dig_w.iter().map(|p| (p.0 - mx).powi(2)).sum();
            let sxy: f64 = dig_w.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
            if sxx > 0.0 { sxy / sxx } else { 0.0 }
        };
        let half = digs.len() / 2;
        let halves = |first: bool| -> Vec<f64> {
            digs.iter()
                .enumerate()
                .filter(|(i, d)| d.action == ActionKind::Dig && ((*i < half) == first))
                .map(|(_, d)| weight(d))
                .collect()
        };
        let (mw, mt, me) = (mean(&w_all), mean(&t_all), mean(&e_all));
        Self {
            dig_mean_weight_n: mean(&pick(ActionKind::Dig, weight)),
            dig_mean_time_s: mean(&pick(ActionKind::Dig, |d| d.time_s)),
            dig_mean_energy_kj: mean(&pick(ActionKind::Dig, |d| d.energy_kj)),
            cleanup_mean_weight_n: mean(&pick(ActionKind::Cleanup, weight)),
            cleanup_mean_time_s: mean(&pick(ActionKind::Cleanup, |d| d.time_s)),
            cleanup_mean_energy_kj: mean(&pick(ActionKind::Cleanup, |d| d.energy_kj)),
            full_bucket_n,
            over_half_full: share(0.5),
            over_third_full: share(1.0 / 3.0),
            productivity_n_per_s: mw / (12.0 + mt), // Eq. 26
            energy_per_weight_kj_per_n: if mw > 0.0 { me / mw } else { 0.0 }, // Eq. 27
            dig_weight_slope_n_per_dig: slope,
            dig_mean_weight_first_half_n: mean(&halves(true)),
            dig_mean_weight_second_half_n: mean(&halves(false)),
        }
    }
}

/// Planning-cycle timing of a session (wall clock, this process).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PlanningStats {
    /// Planning cycles run.
    pub cycles: usize,
    /// Mean wall time per cycle, ms.
    pub mean_ms: f64,
    /// Longest cycle, ms.
    pub max_ms: f64,
}

/// What a session produced (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DemoSummary {
    /// The command that made the session: `demo` or `run` (empty in summaries written before it was
    /// recorded).
    #[serde(default)]
    pub command: String,
    /// The error that ended the session, if one did (`end` is then `error`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The action source: `planned`, `predefined` or `fixed`.
    #[serde(default)]
    pub strategy: String,
    /// The bench scenario's name.
    #[serde(default)]
    pub bench: String,
    /// Track-back actions completed.
    #[serde(default)]
    pub backups: usize,
    /// Cleanup actions completed.
    #[serde(default)]
    pub cleanups: usize,
    /// Why the session ended (`dig count reached`, `bench removed: ...`, `nothing left to do`,
    /// `stopped`, `time budget`).
    #[serde(default)]
    pub end: String,
    /// Tables 3-5 figures.
    #[serde(default)]
    pub stats: SessionStats,
    /// Planning-cycle timing (planned strategy).
    #[serde(default)]
    pub planning: PlanningStats,
    /// The predefined sequence's start joints `[boom, stick, bucket]`, degrees (predefined strategy).
    #[serde(default)]
    pub predefined_start_deg: Option<[f64; 3]>,
    /// The simulator's seed.
    pub seed: u64,
    /// The simulator's soil-contact integration, `held` or `implicit` (docs/simulator.md; `held` in
    /// summaries written before it was recorded); `null` for a session on a bus, which does not know
    /// what it dug against.
    #[serde(default = "held")]
    pub soil_contact: Option<String>,
    /// The hidden effects given on the command line.
    pub effects: Vec<String>,
    /// The simulated machine's own file (`--plant-machine`), when it is not the controller's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant_machine: Option<FileRecord>,
    /// The machine profile both ends spoke on the bus (`--profile`), when not the project's protocol.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<FileRecord>,
    /// What stamped the trace's frames: `virtual` (`demo`: session time since the fixed epoch of
    /// docs/demo-output.md), `kernel` (`run`: the socket's kernel receive timestamps) or
    /// `wall_at_read` (`run` without them); absent in summaries written before it was recorded.
    #[serde(default)]
    pub trace_clock: Option<TraceClock>,
    /// The CAN interface's link when `run` started (bitrate, state, `restart-ms`, listen-only; none
    /// of them for a vcan); absent for `demo`, which has no interface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub can_link: Option<firmware_bridge::transport::LinkStatus>,
    /// Per dig.
    pub digs: Vec<DigRecord>,
    /// Totals.
    pub totals: Totals,
}

/// A file a session was made with (`summary.json` `plant_machine`, `profile`): which file, and its
/// content's hash, so the session says which plant or which gateway's protocol made it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRecord {
    /// The file as given.
    pub path: String,
    /// SHA-256 of its bytes, lower-case hex.
    pub sha256: String,
}

impl FileRecord {
    /// The record of the file at `path`.
    ///
    /// # Errors
    /// Reading the file.
    pub fn of(path: &Path) -> anyhow::Result<Self> {
        use sha2::Digest as _;
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let digest = sha2::Sha256::digest(&bytes);
        Ok(Self {
            path: path.display().to_string(),
            sha256: digest.iter().map(|b| format!("{b:02x}")).collect(),
        })
    }
}

impl DemoSummary {
    /// The summary with its wall-clock figures zeroed: `totals.wall_time_s` and the planning cycles'
    /// `planning.mean_ms` and `planning.max_ms` (how long this process took, not what the session
    /// did). Everything else follows from the arguments and the seed: two sessions of one `demo`
    /// command are equal after this (docs/demo-output.md, "Reproducibility").
    #[must_use]
    pub fn without_wall_clock(mut self) -> Self {
        self.totals.wall_time_s = 0.0;
        self.planning.mean_ms = 0.0;
        self.planning.max_ms = 0.0;
        self
    }
}

/// The soil contact of a summary written before it was recorded: the plant was `held` then.
#[expect(
    clippy::unnecessary_wraps,
    reason = "serde's default of an Option field returns the Option"
)]
fn held() -> Option<String> {
    Some("held".to_owned())
}

/// The session-time base of the trace at `trace` (its frames' session time for the scans and
/// per-dig records beside it): the clock recorded in the `summary.json` of its folder, else, without
/// a summary (a session still running or killed, a bare trace), the one its first frame shows
/// ([`TraceTimeBase`]).
///
/// # Errors
/// A `summary.json` beside the trace that cannot be read, or whose `trace_clock` is not a clock.
pub fn trace_time_base(trace: &Path) -> anyhow::Result<TraceTimeBase> {
    #[derive(Deserialize)]
    struct Recorded {
        #[serde(default)]
        trace_clock: Option<TraceClock>,
    }
    let summary = trace
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .join("summary.json");
    let clock = match std::fs::read_to_string(&summary) {
        Ok(text) => {
            serde_json::from_str::<Recorded>(&text)
                .with_context(|| format!("{}: reading trace_clock", summary.display()))?
                .trace_clock
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e).with_context(|| format!("reading {}", summary.display())),
    };
    Ok(TraceTimeBase::new(clock))
}

/// How a session ended and what it was, for [`session_summary`].
#[derive(Debug, Clone)]
pub struct SessionEnd<'a> {
    /// The command: `demo` or `run`.
    pub command: &'static str,
    /// The action source.
    pub strategy: DemoStrategy,
    /// The bench's or the site's name.
    pub bench: String,
    /// The simulator's seed.
    pub seed: u64,
    /// The simulator's soil-contact integration (`None` on a bus).
    pub soil_contact: Option<String>,
    /// The hidden effects.
    pub effects: Vec<String>,
    /// A full bucket's weight, N.
    pub full_bucket_n: f64,
    /// Why it ended.
    pub end: String,
    /// Track backs begun.
    pub track_backs: usize,
    /// Track backs done.
    pub backups: usize,
    /// Wall time of each planning cycle, ms.
    pub plan_ms: &'a [f64],
    /// Scans taken.
    pub scans: usize,
    /// Session (simulated or scaled) time, s.
    pub session_time_s: f64,
    /// Wall time, s.
    pub wall_time_s: f64,
    /// The trace recorder's counts.
    pub trace: firmware_bridge::trace::RecorderStats,
    /// What stamped the trace.
    pub trace_clock: TraceClock,
}

/// `summary.json` of a session: the records, their totals and Tables 3-5 figures.
#[must_use]
pub fn session_summary(
    records: Vec<DigRecord>,
    end: SessionEnd<'_>,
    node: &ControllerNode,
    session: Option<&PlannedSession>,
) -> DemoSummary {
    let n = records.len();
    let mean = |f: &dyn Fn(&DigRecord) -> f64| {
        if n == 0 {
            0.0
        } else {
            records.iter().map(f).sum::<f64>() / n as f64
        }
    };
    let cleanups = records
        .iter()
        .filter(|r| r.action == ActionKind::Cleanup)
        .count();
    let totals = Totals {
        digs: n,
        dig_actions: records
            .iter()
            .filter(|r| r.action == ActionKind::Dig)
            .count(),
        cleanup_actions: cleanups,
        track_backs: end.track_backs,
        weight_n: records.iter().filter_map(|r| r.weight_n).sum(),
        mean_weight_n: mean(&|r| r.weight_n.unwrap_or(0.0)),
        mean_time_s: mean(&|r| r.time_s),
        mean_energy_kj: mean(&|r| r.energy_kj),
        energy_kj: records.iter().map(|r| r.energy_kj).sum(),
        swept_volume_m3: records.iter().map(|r| r.swept_volume_m3).sum(),
        scans: end.scans,
        sim_time_s: end.session_time_s,
        wall_time_s: end.wall_time_s,
        trace_frames: end.trace.recorded,
        trace_dropped: end.trace.dropped,
        finished: node.finished(),
        last_fault: node.last_fault().map(|f| f.to_string()),
    };
    let plan_ms = end.plan_ms;
    let planning = if plan_ms.is_empty() {
        PlanningStats::default()
    } else {
        PlanningStats {
            cycles: plan_ms.len(),
            mean_ms: plan_ms.iter().sum::<f64>() / plan_ms.len() as f64,
            max_ms: plan_ms.iter().copied().fold(0.0, f64::max),
        }
    };
    DemoSummary {
        command: end.command.to_owned(),
        error: None,
        strategy: end.strategy.name().to_owned(),
        bench: end.bench,
        backups: end.backups,
        cleanups,
        end: end.end,
        stats: SessionStats::of(&records, end.full_bucket_n),
        planning,
        predefined_start_deg: session.and_then(|s| s.predefined()).map(|p| {
            [
                p.start.boom_rad.to_degrees(),
                p.start.stick_rad.to_degrees(),
                p.start.bucket_rad.to_degrees(),
            ]
        }),
        seed: end.seed,
        soil_contact: end.soil_contact,
        effects: end.effects,
        plant_machine: None,
        profile: None,
        trace_clock: Some(end.trace_clock),
        can_link: None,
        digs: records,
        totals,
    }
}

/// Writes `soil_samples.json`.
///
/// # Errors
/// Writing the file.
pub fn write_soil_samples(out: &Path, samples: &SoilSamplesFile) -> anyhow::Result<()> {
    let path = out.join("soil_samples.json");
    std::fs::write(&path, serde_json::to_vec(samples)?)
        .with_context(|| format!("writing {}", path.display()))
}

/// The readable summary table (`summary.md`, also printed at the end of `demo`).
pub fn summary_markdown(s: &DemoSummary) -> String {
    use std::fmt::Write as _;
    let mut m = String::new();
    let t = &s.totals;
    // Writing into a String cannot fail.
    let _ = writeln!(
        m,
        "# excavator-ctl {}\n\nseed {}, effects [{}]; {} digs ({} dig, {} cleanup), {} track backs, {} scans; \
         {:.1} s simulated in {:.1} s wall{}\n",
        if s.command.is_empty() {
            "demo"
        } else {
            &s.command
        },
        s.seed,
        s.effects.join(", "),
        t.digs,
        t.dig_actions,
        t.cleanup_actions,
        t.track_backs,
        t.scans,
        t.sim_time_s,
        t.wall_time_s,
        if t.finished { "" } else { " (stopped early)" }
    );
    if let Some(link) = &s.can_link {
        let _ = writeln!(m, "CAN link at start: {link}.\n");
    }
    if !s.strategy.is_empty() && s.strategy != "fixed" {
        m.push_str(&tables_markdown(s));
    }
    let _ = writeln!(
        m,
        "| # | action | swing (deg) | weight (N) | true payload (kg) | time (s) | energy (kJ) | swept (m^3) | end |"
    );
    let _ = writeln!(m, "|---|---|---|---|---|---|---|---|---|");
    for d in &s.digs {
        let _ = writeln!(
            m,
            "| {} | {:?} | {:.0} | {} | {:.0} | {:.1} | {:.0} | {:.2} | {} |",
            d.number(),
            d.action,
            d.swing_deg,
            d.weight_n.map_or("-".to_owned(), |w| format!("{w:.0}")),
            d.true_payload_kg,
            d.time_s,
            d.energy_kj,
            d.swept_volume_m3,
            d.end_reason.as_deref().unwrap_or("-")
        );
    }
    let _ = writeln!(
        m,
        "| mean | | | {:.0} | | {:.1} | {:.0} | | |\n\nThesis Table 3 (tests 1-3, per dig): weight 18917-22654 N, time 6.7-10.2 s, \
         energy 213-252 kJ; Table 4: digs 21201 N, 5.8 s, 212 kJ.",
        t.mean_weight_n, t.mean_time_s, t.mean_energy_kj
    );
    if let Some(f) = &t.last_fault {
        let _ = writeln!(m, "\nLast safety event: {f}.");
    }
    m
}

/// Tables 3-5 of the thesis for one session: the run (Table 3), dig against cleanup actions
/// (Table 4), the per-cycle means with Eqs. 26-27 (Table 5), the share of buckets over half full
/// (Fig. 56) and the fill trend (Fig. 60).
pub fn tables_markdown(s: &DemoSummary) -> String {
    use std::fmt::Write as _;
    let mut m = String::new();
    let t = &s.totals;
    let st = &s.stats;
    // Writing into a String cannot fail.
    let _ = writeln!(
        m,
        "Strategy `{}` on \"{}\"; ended: {}.\n",
        s.strategy, s.bench, s.end
    );
    let _ = writeln!(
        m,
        "Table 3 (run):\n\n| digs | backups | weight (N) | time (s) | energy (kJ) |\n|---|---|---|---|---|\n| {} | {} | {:.0} | {:.1} | {:.0} |\n\
         | thesis test 3 | 109, 6 | 21300 | 7.6 | 252 |\n",
        t.digs, s.backups, t.mean_weight_n, t.mean_time_s, t.mean_energy_kj
    );
    let _ = writeln!(
        m,
        "Table 4 (actions):\n\n| | count | weight (N) | time (s) | energy (kJ) |\n|---|---|---|---|---|\n\
         | dig actions | {} | {:.0} | {:.1} | {:.0} |\n| cleanup actions | {} | {:.0} | {:.1} | {:.0} |\n\
         | thesis digs / cleanups | | 21201 / 21590 | 5.8 / 12.8 | 212 / 366 |\n",
        t.dig_actions,
        st.dig_mean_weight_n,
        st.dig_mean_time_s,
        st.dig_mean_energy_kj,
        s.cleanups,
        st.cleanup_mean_weight_n,
        st.cleanup_mean_time_s,
        st.cleanup_mean_energy_kj
    );
    let _ = writeln!(
        m,
        "Buckets over half full: {:.0} % (over a third: {:.0} %; full bucket {:.0} N; thesis test 3: 94 %, 98 %). \
         Productivity (Eq. 26) {:.0} N/s, energy per weight (Eq. 27) {:.2} J/N. Dig-action weight trend {:+.0} N per dig; \
         first half {:.0} N, second half {:.0} N (Fig. 60).",
        100.0 * st.over_half_full,
        100.0 * st.over_third_full,
        st.full_bucket_n,
        st.productivity_n_per_s,
        1e3 * st.energy_per_weight_kj_per_n,
        st.dig_weight_slope_n_per_dig,
        st.dig_mean_weight_first_half_n,
        st.dig_mean_weight_second_half_n
    );
    if s.planning.cycles > 0 {
        let _ = writeln!(
            m,
            "\nPlanning: {} cycles, mean {:.0} ms, longest {:.0} ms (wall clock, this process).",
            s.planning.cycles, s.planning.mean_ms, s.planning.max_ms
        );
    }
    if let Some(q) = s.predefined_start_deg {
        let _ = writeln!(
            m,
            "\nPredefined start joints (boom, stick, bucket): {:.1}, {:.1}, {:.1} deg.",
            q[0], q[1], q[2]
        );
    }
    m.push('\n');
    m
}

/// The plots of a session folder, drawn by a layer above this crate (the lab's SVG figures): `run`
/// and `demo` write the data files themselves and hand the pictures to this.
pub trait SessionPlots: Send + Sync {
    /// Draws the plots of `summary` into `out`: the planned `session`'s figures when there is one,
    /// and the terrain `snapshots` (Fig. 55).
    ///
    /// # Errors
    /// Drawing or writing a file.
    fn write(
        &self,
        out: &Path,
        summary: &DemoSummary,
        session: Option<&PlannedSession>,
        snapshots: &[BenchSnapshot],
    ) -> anyhow::Result<()>;
}

/// Writes `summary.json`, `summary.md` and `plan.json` (the cycle's `plan`).
///
/// # Errors
/// Writing the files.
pub fn write_files(out: &Path, summary: &DemoSummary, plan: &[Action]) -> anyhow::Result<()> {
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let p = out.join(name);
        std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))
    };
    write("summary.json", &serde_json::to_vec_pretty(summary)?)?;
    write("summary.md", summary_markdown(summary).as_bytes())?;
    write("plan.json", &serde_json::to_vec_pretty(plan)?)
}

/// Writes the planner's last cycle (`last_plan.json`: coarse regions, best dig, cleanup and tracking
/// limits, the action chosen).
///
/// # Errors
/// Writing the file.
pub fn write_last_plan(out: &Path, s: &PlannedSession) -> anyhow::Result<()> {
    if let Some(p) = s.steps().iter().rev().find_map(|st| st.plan.as_ref()) {
        let last = serde_json::json!({
            "coarse": p.coarse,
            "best_dig": p.best_dig,
            "cleanup_track": p.cleanup_track,
            "action": p.action.kind().map(|k| format!("{k:?}")),
        });
        let path = out.join("last_plan.json");
        std::fs::write(&path, serde_json::to_vec_pretty(&last)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clock comes from the `summary.json` beside the trace; without one, from the first frame;
    /// a summary whose clock is not one is an error naming the file.
    #[test]
    fn the_trace_time_base_follows_the_recorded_clock() {
        let dir = tempfile::tempdir().unwrap();
        let trace = dir.path().join("trace.log");
        let summary = dir.path().join("summary.json");
        let wall_ns = 1_790_000_000_000_000_000;
        let mut bare = trace_time_base(&trace).unwrap();
        assert_eq!(bare.clock(), None);
        assert_eq!(
            bare.session_ns(TraceClock::Virtual.trace_ns(20_000_000)),
            20_000_000
        );

        std::fs::write(&summary, r#"{"seed": 1, "trace_clock": "kernel"}"#).unwrap();
        let mut kernel = trace_time_base(&trace).unwrap();
        assert_eq!(kernel.clock(), Some(TraceClock::Kernel));
        assert_eq!(kernel.session_ns(wall_ns), 0);
        assert_eq!(kernel.session_ns(wall_ns + 7), 7);

        std::fs::write(&summary, r#"{"trace_clock": "virtual"}"#).unwrap();
        let mut virt = trace_time_base(&trace).unwrap();
        assert_eq!(virt.session_ns(TraceClock::Virtual.trace_ns(5)), 5);

        std::fs::write(&summary, r#"{"trace_clock": "sundial"}"#).unwrap();
        let err = format!("{:#}", trace_time_base(&trace).unwrap_err());
        assert!(
            err.contains("summary.json") && err.contains("sundial"),
            "{err}"
        );
    }
}
