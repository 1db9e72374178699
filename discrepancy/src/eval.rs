//! `excavator-ctl discrepancy eval`: sessions generated in-process by the demo (`demo::run_session`)
//! with one hidden simulator effect each (every effect of the library at a small and a large
//! magnitude, several seeds), with a plant change outside the library ([`crate::plant`]), and
//! effect-free sessions, each analysed from its folder (trace.log + scans only, told nothing)
//! against a reference of healthy sessions generated at other seeds; the confusion table of hidden
//! against named effects, with the magnitude errors and the held-out residual reductions, and the
//! outcomes (expected, named, partly explained, unexplained) per kind of case. `discrepancy bench`
//! times the analysis.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use crate::Candidate;
use crate::effects::CandidateEffect as _;
use anyhow::Context as _;
use clap::Args;
use serde::{Deserialize, Serialize};

use crate::analysis::{AnalyseArgs, load_reference, run_analysis};
use crate::plant::{PlantChange, PlantFile, PlantOp, default_plant_changes};
use crate::session::{load_machine, load_model};
use crate::verdict::Outcome;
use lab::demo::{DemoArgs, DemoStrategy, SoilContact, run_session};

/// Arguments of `discrepancy eval`.
#[derive(Debug, Clone, Args)]
pub struct EvalArgs {
    /// CI size: six effects (one per signal family) at the large magnitude, one seed, one
    /// effect-free session, 4 digs each.
    #[arg(long)]
    pub quick: bool,
    /// Seeds per effect and magnitude (full run).
    #[arg(long, default_value_t = 2, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// Effect-free sessions (full run).
    #[arg(long, default_value_t = 6, value_name = "N")]
    pub nominal_sessions: u64,
    /// Digs per session (at least 2: the analysis holds some out).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..))]
    pub digs: Option<u32>,
    /// Only these effects (names; default all).
    #[arg(long = "only", value_name = "NAME")]
    pub only: Vec<String>,
    /// Output folder (sessions/, reports/, eval.json, eval.md).
    #[arg(long, default_value = "out/discrepancy-eval", value_name = "DIR")]
    pub out: PathBuf,
    /// Generate the sessions on the simulator with this soil-contact integration (default: the
    /// default plant's, `implicit`, which the nominal model is calibrated on; `held`: plant version
    /// `held-1`, with the contact chatter; docs/simulator.md).
    #[arg(long, value_enum, value_name = "HOW")]
    pub soil_contact: Option<SoilContact>,
    /// The action source of the generated sessions (default: `planned`, the session `demo` runs,
    /// on its extended bench; with --quick `fixed`, the fixed plan on config/bench.toml).
    #[arg(long, value_enum, value_name = "HOW")]
    pub strategy: Option<DemoStrategy>,
    /// Plant changes outside the effect library, FILE:KEY*FACTOR or FILE:KEY=VALUE with FILE
    /// `machine` or `bench` (repeatable; `default`: the built-in list of `crate::plant`).
    #[arg(long = "plant", value_name = "CHANGE")]
    pub plant: Vec<String>,
    /// Healthy sessions generated at their own seeds (300, 301, ...) as the recorded reference
    /// every case is also judged against (0: the default path alone; at most 1 with --quick).
    #[arg(long, default_value_t = 2, value_name = "N")]
    pub reference_sessions: u64,
    /// Added to every seed of the evaluation (the cases' 11, 100-, 200-, 400-, 600- and the
    /// reference's 300-): another base is a fresh set of sessions. It must keep clear of the
    /// built-in reference's seeds (8501-8504), which the default path judges against.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub seed_base: u64,
    /// Leave out the effect-library cases (plant changes and effect-free sessions only).
    #[arg(long)]
    pub no_effects: bool,
    /// Leave out the pairs of effects hidden together.
    #[arg(long)]
    pub no_pairs: bool,
    /// Also time one analysis (`discrepancy bench`, its sessions under `OUT/bench`) and write both
    /// as a generated results page to this file (e.g. docs/discrepancy-results.md), with the
    /// command line, the date and the commit.
    #[arg(long, value_name = "FILE")]
    pub results: Option<PathBuf>,
    /// Where the sessions and analyses run (in-process or a Dask cluster; docs/campaigns.md).
    #[command(flatten)]
    pub campaign: lab::campaign::CampaignArgs,
}

impl EvalArgs {
    /// The defaults of the command line with `out` as the output folder.
    pub fn new(out: PathBuf) -> Self {
        Self {
            quick: false,
            seeds: 2,
            nominal_sessions: 6,
            digs: None,
            only: Vec::new(),
            out,
            soil_contact: None,
            strategy: None,
            plant: Vec::new(),
            reference_sessions: 2,
            seed_base: 0,
            no_effects: false,
            no_pairs: false,
            results: None,
            campaign: lab::campaign::CampaignArgs::default(),
        }
    }

    /// The strategy of the generated sessions.
    pub fn strategy(&self) -> DemoStrategy {
        self.strategy.unwrap_or(if self.quick {
            DemoStrategy::Fixed
        } else {
            DemoStrategy::Planned
        })
    }

    /// The plant changes to evaluate.
    ///
    /// # Errors
    /// A change that does not parse.
    pub fn plant_changes(&self) -> anyhow::Result<Vec<PlantChange>> {
        let mut out = Vec::new();
        for p in &self.plant {
            if p == "default" {
                out.extend(default_plant_changes());
            } else {
                out.push(p.parse().map_err(anyhow::Error::msg)?);
            }
        }
        Ok(out)
    }
}

/// What a case hides from the analysis.
#[derive(Debug, Clone, PartialEq)]
pub enum Hidden {
    /// Nothing: an effect-free session.
    None,
    /// An effect of the library at a magnitude.
    Effect(Candidate, f64),
    /// Two effects of the library hidden together.
    Pair([(Candidate, f64); 2]),
    /// A plant change outside the library.
    Plant(PlantChange),
}

impl Hidden {
    /// The kind of case: `effect`, `plant` or `none`.
    pub fn kind(&self) -> &'static str {
        match self {
            Hidden::None => "none",
            Hidden::Effect(..) => "effect",
            Hidden::Pair(_) => "pair",
            Hidden::Plant(_) => "plant",
        }
    }

    /// The hidden effect's magnitude (0 for the others).
    pub fn magnitude(&self) -> f64 {
        match self {
            Hidden::Effect(_, v) => *v,
            _ => 0.0,
        }
    }

    /// What is hidden, as `eval.json`'s `hidden`: the effect's name, the plant change, `none`.
    pub fn name(&self) -> String {
        match self {
            Hidden::None => "none".into(),
            Hidden::Effect(c, _) => c.name().into(),
            Hidden::Pair([(a, _), (b, _)]) => format!("{}+{}", a.name(), b.name()),
            Hidden::Plant(p) => p.to_string(),
        }
    }
}

/// Arguments of `discrepancy bench`.
#[derive(Debug, Clone, Args)]
pub struct BenchArgs {
    /// Digs of the measured and the reference session.
    #[arg(long, default_value_t = 16, value_name = "N", value_parser = clap::value_parser!(u32).range(2..))]
    pub digs: u32,
    /// Output folder for the generated sessions, the reference and the report.
    #[arg(long, default_value = "out/discrepancy-bench", value_name = "DIR")]
    pub out: PathBuf,
}

/// The small and large magnitude of every effect in the evaluation (inside the simulator's ranges).
pub fn magnitudes(c: Candidate) -> [f64; 2] {
    match c {
        Candidate::ValveDeadband => [0.05, 0.15],
        Candidate::TransportDelay => [0.03, 0.1],
        Candidate::HydraulicLag => [0.05, 0.2],
        Candidate::FlowSharing => [0.3, 0.7],
        Candidate::PumpSaturation => [0.15, 0.4],
        Candidate::CoulombFriction => [5000.0, 20000.0],
        Candidate::ViscousFriction => [2.0e5, 8.0e5],
        Candidate::InternalLeakage => [3.0e-12, 1.0e-11],
        Candidate::PressureSensorOffset => [2.0e5, -8.0e5],
        // Beyond the safety layer's 1 degree tolerance (0.017 rad) a resolver offset stops the machine
        // at the first stroke end it drives a joint to: the bucket curls to its stop in every Capture
        // (-0.04 ended the session in the first dig), the boom rises to its top stop (+0.04 would
        // read 1.054 rad there against a limit of 1.032), so the large case is just inside it
        // (docs/discrepancy.md, 2026-11-22 resolver offset).
        Candidate::ResolverOffset => [0.01, -0.015],
        Candidate::SoilCohesion => [10_000.0, 40_000.0],
        Candidate::SoilDensity => [200.0, 600.0],
    }
}

/// The pairs of effects the evaluation hides together: effects on different signal families, and
/// the confusable ones the issue named (a delay with a lag; a pressure offset with a friction,
/// both on the forces).
pub const PAIRS: [[(Candidate, f64); 2]; 6] = [
    [
        (Candidate::TransportDelay, 0.05),
        (Candidate::HydraulicLag, 0.1),
    ],
    [
        (Candidate::PumpSaturation, 0.3),
        (Candidate::CoulombFriction, 10_000.0),
    ],
    [
        (Candidate::PressureSensorOffset, -5.0e5),
        (Candidate::ViscousFriction, 4.0e5),
    ],
    [
        (Candidate::ValveDeadband, 0.05),
        (Candidate::SoilDensity, 400.0),
    ],
    [
        (Candidate::FlowSharing, 0.6),
        (Candidate::InternalLeakage, 1.0e-11),
    ],
    [
        (Candidate::HydraulicLag, 0.1),
        (Candidate::ResolverOffset, -0.015),
    ],
];

/// How a pair of hidden effects was reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PairOutcome {
    /// Both named, each within 25 % of its magnitude.
    Both,
    /// Reported as an ambiguous pair of the two (neither named, both fits given).
    Ambiguous,
    /// One of them named within 25 %, the other not (or off by more).
    One,
    /// Neither named.
    Neither,
}

impl PairOutcome {
    /// Name for tables.
    pub fn name(self) -> &'static str {
        match self {
            PairOutcome::Both => "both",
            PairOutcome::Ambiguous => "ambiguous",
            PairOutcome::One => "one",
            PairOutcome::Neither => "neither",
        }
    }
}

/// The outcome of a pair from what the analysis named and reported ambiguous.
fn pair_outcome(
    pair: &[(Candidate, f64); 2],
    named: &[crate::NamedEffect],
    ambiguous: &[[String; 2]],
) -> PairOutcome {
    let within = |(c, v): &(Candidate, f64)| {
        named
            .iter()
            .any(|e| e.name == c.name() && ((e.magnitude - v) / v.abs()).abs() <= 0.25)
    };
    let found = pair.iter().filter(|p| within(p)).count();
    let names = pair.map(|(c, _)| c.name());
    if found == 2 {
        PairOutcome::Both
    } else if ambiguous
        .iter()
        .any(|a| a.contains(&names[0].to_string()) && a.contains(&names[1].to_string()))
    {
        PairOutcome::Ambiguous
    } else if found == 1 {
        PairOutcome::One
    } else {
        PairOutcome::Neither
    }
}

/// One evaluation case and its outcome.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CaseResult {
    /// Case name (also the session folder name).
    pub case: String,
    /// Which reference the analysis judged against ([`EvalPath::name`]).
    pub path: String,
    /// Hidden effect name, or `none`.
    pub hidden: String,
    /// Hidden magnitude (0 for none).
    pub hidden_magnitude: f64,
    /// Seed.
    pub seed: u64,
    /// Digs analysed.
    pub digs: usize,
    /// First named effect, or `none`.
    pub named: String,
    /// Every named effect with magnitude and uncertainty.
    #[serde(deserialize_with = "null_as_nan::triples")]
    pub named_all: Vec<(String, f64, f64)>,
    /// The ambiguous pairs the analysis reported (neither named).
    pub ambiguous: Vec<[String; 2]>,
    /// Magnitude error of the hidden effect's fit, % (when named correctly).
    pub magnitude_error_percent: Option<f64>,
    /// Largest held-out RMS reduction among the hidden effect's signals, % (negative = fell).
    pub best_rms_change_percent: Option<f64>,
    /// Which signal that was.
    pub best_signal: Option<String>,
    /// The same on the samples where the augmented model acts (`SignalRms::acted`), %.
    pub best_acted_rms_change_percent: Option<f64>,
    /// `effect`, `plant` or `none`.
    pub kind: String,
    /// The verdict against the reference (`expected`, `named`, `partly_explained`,
    /// `unexplained`, `not_judged`); `None` without a reference or when the analysis failed.
    pub outcome: Option<Outcome>,
    /// Signals beyond the reference after the named effects, with their ratio to it.
    pub unexplained: Vec<(String, f64)>,
    /// The largest held-out ratio to the reference over the judged signals, before and after the
    /// named effects.
    pub max_ratio: Option<(f64, f64)>,
    /// Data-sufficiency warnings of the analysis.
    pub warnings: usize,
    /// For a pair of hidden effects, how it was reported.
    pub pair: Option<PairOutcome>,
    /// What the analysis wrote into the twin's profile (machine-file keys and effect names).
    pub twin_written: Vec<String>,
    /// The twin's free-air gap to the held-out digs over the nominal plant's, per group
    /// ([`crate::twin::GAP_GROUPS`]); empty without a twin re-run.
    #[serde(deserialize_with = "null_as_nan::map")]
    pub twin_ratio: BTreeMap<String, f64>,
}

/// JSON writes a NaN as `null`: read back as NaN, so a case file holds what the case had.
mod null_as_nan {
    use std::collections::BTreeMap;

    use serde::{Deserialize, Deserializer};

    pub fn map<'de, D: Deserializer<'de>>(d: D) -> Result<BTreeMap<String, f64>, D::Error> {
        let m = BTreeMap::<String, Option<f64>>::deserialize(d)?;
        Ok(m.into_iter()
            .map(|(k, v)| (k, v.unwrap_or(f64::NAN)))
            .collect())
    }

    pub fn triples<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<(String, f64, f64)>, D::Error> {
        let v = Vec::<(String, Option<f64>, Option<f64>)>::deserialize(d)?;
        Ok(v.into_iter()
            .map(|(n, a, b)| (n, a.unwrap_or(f64::NAN), b.unwrap_or(f64::NAN)))
            .collect())
    }
}

impl CaseResult {
    /// A case whose session could not be generated or analysed (counted as a miss, named `error`).
    fn failed(case: String, hidden: &Hidden, seed: u64, path: EvalPath) -> Self {
        Self {
            case,
            path: path.name().into(),
            hidden: hidden.name(),
            hidden_magnitude: hidden.magnitude(),
            seed,
            digs: 0,
            named: "error".into(),
            named_all: Vec::new(),
            ambiguous: Vec::new(),
            magnitude_error_percent: None,
            best_rms_change_percent: None,
            best_signal: None,
            best_acted_rms_change_percent: None,
            kind: hidden.kind().into(),
            outcome: None,
            unexplained: Vec::new(),
            max_ratio: None,
            warnings: 0,
            pair: None,
            twin_written: Vec::new(),
            twin_ratio: BTreeMap::new(),
        }
    }
}

fn signals_of(c: Candidate) -> Vec<&'static str> {
    let g = c.groups();
    crate::Signal::ALL
        .iter()
        .filter(|s| g.contains(s.index()))
        .map(|s| s.name())
        .collect()
}

/// Whether `session` holds a finished `demo` session to reuse: `demo` writes `summary.json` after it
/// has closed the trace, so a session without it was interrupted (its trace may be cut short, e.g. a
/// run killed by a closed pipe) and is removed, to be generated again.
///
/// # Errors
/// Removing an interrupted session.
fn session_complete(session: &std::path::Path) -> anyhow::Result<bool> {
    if session.join("summary.json").exists() {
        return Ok(true);
    }
    if session.exists() {
        std::fs::remove_dir_all(session)
            .with_context(|| format!("removing the interrupted session {}", session.display()))?;
    }
    Ok(false)
}

/// Where a generated session of `case` goes and whether it is there already; the demo settings of
/// the strategy, soil contact and seed.
struct SessionPlan {
    case: String,
    demo: DemoArgs,
}

impl SessionPlan {
    fn new(
        out: &std::path::Path,
        base: &str,
        seed: u64,
        digs: u32,
        soil_contact: Option<SoilContact>,
        strategy: DemoStrategy,
    ) -> Self {
        let mut case = base.to_string();
        // Sessions of another plant or strategy must not be reused for this one.
        if soil_contact == Some(SoilContact::Held) {
            case.push_str("_held");
        }
        if strategy != DemoStrategy::Fixed {
            case.push('_');
            case.push_str(strategy.name());
        }
        // Nor sessions of an earlier plant version. `demo`'s defaults but for what the case sets.
        let demo = DemoArgs {
            digs,
            seed: Some(seed),
            quiet: true,
            soil_contact,
            strategy,
            ..DemoArgs::defaults(
                out.join("sessions")
                    .join(vcan_sim::PLANT_VERSION)
                    .join(&case),
            )
        };
        Self { case, demo }
    }

    /// Generates the session unless a finished one is there.
    fn generate(&self) -> anyhow::Result<PathBuf> {
        let summary = self.demo.out.join("summary.json");
        // A machine plant change made before the plant had its own file changed the controller's
        // machine too: such a session is not this case's.
        if self.demo.plant_machine.is_some()
            && std::fs::read_to_string(&summary).is_ok_and(|t| !t.contains("\"plant_machine\""))
        {
            std::fs::remove_dir_all(&self.demo.out)
                .with_context(|| format!("removing {}", self.demo.out.display()))?;
        }
        if !session_complete(&self.demo.out)? {
            run_session(&self.demo, &AtomicBool::new(false))
                .with_context(|| format!("generating session {}", self.case))?;
        }
        Ok(self.demo.out.clone())
    }
}

/// Writes the changed machine or bench file of a plant change and points the demo at it: a
/// machine change is the simulated machine's file alone (`demo --plant-machine`), the controller
/// keeps the default machine file, as a real machine differs from the file its controller reads.
fn apply_plant(
    plan: &mut SessionPlan,
    change: &PlantChange,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    let (base, name) = match change.file {
        PlantFile::Machine => (planner::machine::DEFAULT_MACHINE_TOML, "machine"),
        PlantFile::Bench if plan.demo.strategy == DemoStrategy::Fixed => {
            (vcan_sim::scenario::DEFAULT_BENCH_TOML, "bench")
        }
        PlantFile::Bench => (vcan_sim::scenario::EXTENDED_BENCH_TOML, "bench_extended"),
    };
    let dir = out.join("plant");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    // One file per case: the seeds of a change run in parallel, and a file written while another
    // case reads it is a truncated file.
    let path = dir.join(format!("{}_{name}.toml", plan.case));
    std::fs::write(&path, change.apply(base)?)
        .with_context(|| format!("writing {}", path.display()))?;
    match change.file {
        PlantFile::Machine => plan.demo.plant_machine = Some(path),
        PlantFile::Bench => plan.demo.bench = Some(path),
    }
    Ok(())
}

/// The two paths every case is analysed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EvalPath {
    /// `analyse` without `--reference`, as a user runs it first: the default machine is judged
    /// against the built-in reference (`config/nominal_reference.json`).
    Default,
    /// `analyse --reference FILE` with the reference of the evaluation's own healthy sessions.
    Recorded,
}

impl EvalPath {
    /// Name in `eval.json` and the tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Default => "default",
            Self::Recorded => "recorded",
        }
    }

    fn title(self) -> &'static str {
        match self {
            Self::Default => {
                "Default path: `analyse` without --reference (the built-in reference of the default machine)"
            }
            Self::Recorded => {
                "With a recorded reference: `analyse --reference` the evaluation's healthy sessions"
            }
        }
    }
}

/// Generates the case's session and analyses it on each path (`reference`: the recorded
/// reference; without it, the default path alone). A path whose analysis fails counts as a
/// miss, named `error`.
fn run_case(
    args: &EvalArgs,
    hidden: &Hidden,
    seed: u64,
    digs: u32,
    reference: Option<&std::path::Path>,
) -> Vec<CaseResult> {
    let paths: Vec<(EvalPath, Option<&std::path::Path>)> =
        std::iter::once((EvalPath::Default, None))
            .chain(reference.map(|r| (EvalPath::Recorded, Some(r))))
            .collect();
    let session = match case_session(args, hidden, seed, digs) {
        Ok(s) => s,
        Err(e) => {
            return paths
                .iter()
                .map(|(p, _)| {
                    CaseResult::failed(
                        format!("{}_s{seed} ({e:#})", hidden.name()),
                        hidden,
                        seed,
                        *p,
                    )
                })
                .collect();
        }
    };
    paths
        .iter()
        .map(|(p, r)| {
            analyse_case(hidden, seed, &session, *p, *r, &args.out).unwrap_or_else(|e| {
                CaseResult::failed(
                    format!("{}_s{seed} ({e:#})", hidden.name()),
                    hidden,
                    seed,
                    *p,
                )
            })
        })
        .collect()
}

/// The base name of a case's session folder.
fn case_base(hidden: &Hidden, seed: u64) -> String {
    match hidden {
        Hidden::Effect(c, v) => format!("{}_{v}_s{seed}", c.name()),
        Hidden::Pair([(a, va), (b, vb)]) => {
            format!("{}_{va}+{}_{vb}_s{seed}", a.name(), b.name())
        }
        Hidden::Plant(p) => format!("plant_{}_s{seed}", p.slug()),
        Hidden::None => format!("none_s{seed}"),
    }
}

/// The case's session folder (generated unless a finished one is there) and its name.
fn case_session(
    args: &EvalArgs,
    hidden: &Hidden,
    seed: u64,
    digs: u32,
) -> anyhow::Result<(String, PathBuf)> {
    let out = &args.out;
    let base = case_base(hidden, seed);
    let mut plan = SessionPlan::new(out, &base, seed, digs, args.soil_contact, args.strategy());
    match hidden {
        Hidden::Effect(c, v) => plan.demo.effects = vec![format!("{}={v}", c.name())],
        Hidden::Pair(pair) => {
            plan.demo.effects = pair
                .iter()
                .map(|(c, v)| format!("{}={v}", c.name()))
                .collect();
        }
        Hidden::Plant(p) => apply_plant(&mut plan, p, out)?,
        Hidden::None => {}
    }
    let session = plan.generate()?;
    Ok((plan.case, session))
}

fn analyse_case(
    hidden: &Hidden,
    seed: u64,
    (case, session): &(String, PathBuf),
    path: EvalPath,
    reference: Option<&std::path::Path>,
    out: &std::path::Path,
) -> anyhow::Result<CaseResult> {
    let case = case.clone();
    let mut analyse_args = AnalyseArgs::new(
        vec![session.clone()],
        out.join("reports").join(path.name()).join(&case),
    );
    analyse_args.reference = reference.map(|r| vec![r.to_path_buf()]).unwrap_or_default();
    let analysis = run_analysis(&analyse_args).with_context(|| format!("analysing {case}"))?;
    let r = &analysis.result;
    let ambiguous: Vec<[String; 2]> = r
        .ambiguous
        .iter()
        .map(|a| a.candidates.clone().map(|c| c.name))
        .collect();
    let named = match (r.named_effects.first(), ambiguous.first()) {
        (Some(e), _) => e.name.to_string(),
        (None, Some([a, b])) => format!("ambiguous({a}|{b})"),
        (None, None) => "none".to_string(),
    };
    let (mut magnitude_error_percent, mut best_rms_change_percent, mut best_signal) =
        (None, None, None);
    let mut best_acted_rms_change_percent = None;
    if let Hidden::Effect(c, v) = hidden {
        let (c, v) = (*c, *v);
        if let Some(e) = r.named_effects.iter().find(|e| e.name == c.name()) {
            magnitude_error_percent = Some(100.0 * (e.magnitude - v) / v.abs());
        }
        let sigs = signals_of(c);
        if let Some(m) = r
            .rms
            .iter()
            .filter(|m| sigs.contains(&m.signal) && m.samples > 0 && m.before > 0.0)
            .min_by(|a, b| (a.after / a.before).total_cmp(&(b.after / b.before)))
        {
            best_rms_change_percent = Some(crate::report::reduction_percent(m.before, m.after));
            best_signal = Some(m.signal.to_string());
        }
        best_acted_rms_change_percent = r
            .rms
            .iter()
            .filter(|m| sigs.contains(&m.signal) && m.acted.0 > 0 && m.acted.1 > 0.0)
            .map(|m| crate::report::reduction_percent(m.acted.1, m.acted.2))
            .min_by(f64::total_cmp);
    }
    if let Hidden::Plant(p) = hidden {
        magnitude_error_percent = parameter_error_percent(p, &r.named_effects);
    }
    let pair = match hidden {
        Hidden::Pair(p) => Some(pair_outcome(p, &r.named_effects, &ambiguous)),
        _ => None,
    };
    let verdict = analysis.verdict.as_ref();
    let max_ratio = verdict.and_then(|v| {
        v.signals
            .iter()
            .filter(|s| s.outcome != Outcome::NotJudged)
            .map(|s| (s.ratio_before, s.ratio_after))
            .reduce(|a, b| (a.0.max(b.0), a.1.max(b.1)))
    });
    Ok(CaseResult {
        case,
        path: path.name().into(),
        hidden: hidden.name(),
        hidden_magnitude: hidden.magnitude(),
        seed,
        digs: analysis.records.len(),
        named,
        named_all: r
            .named_effects
            .iter()
            .map(|e| (e.name.to_string(), e.magnitude, e.uncertainty))
            .collect(),
        ambiguous,
        magnitude_error_percent,
        best_rms_change_percent,
        best_signal,
        best_acted_rms_change_percent,
        kind: hidden.kind().into(),
        outcome: verdict.map(|v| v.outcome),
        unexplained: verdict.map_or_else(Vec::new, |v| {
            v.unexplained
                .iter()
                .map(|u| (u.signal.to_string(), u.ratio_to_expected))
                .collect()
        }),
        max_ratio,
        warnings: analysis.warnings.len(),
        pair,
        twin_written: analysis.twin.as_ref().map_or_else(Vec::new, |(_, t)| {
            t.parameters
                .iter()
                .chain(&t.effects)
                .map(|v| v.name.clone())
                .collect()
        }),
        twin_ratio: analysis
            .twin
            .as_ref()
            .map_or_else(BTreeMap::new, |(_, t)| t.ratio.clone()),
    })
}

/// The error of a named machine parameter against a machine plant change of the same key, in % of
/// the change (`None` when the change is not named as its parameter).
fn parameter_error_percent(p: &PlantChange, named: &[crate::NamedEffect]) -> Option<f64> {
    if p.file != PlantFile::Machine {
        return None;
    }
    let e = named
        .iter()
        .find(|e| e.kind == "parameter" && e.name == p.key)?;
    let machine = planner::machine::MachineConfig::default_machine().ok()?;
    let library = crate::parameters::ParameterLibrary::derive(&machine).ok()?;
    let nominal = library.parameters[library.find(&p.key)?].nominal;
    let truth = match p.op {
        PlantOp::Scale(f) => nominal * f,
        PlantOp::Set(v) => v,
    };
    (truth != nominal).then(|| 100.0 * (e.magnitude - truth) / (truth - nominal))
}

/// The outcomes against the reference per kind of case, and per plant change over its seeds (the
/// median and the worst largest ratio to the reference, not the best).
pub fn outcome_text(results: &[CaseResult]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let judged: Vec<&CaseResult> = results.iter().filter(|c| c.outcome.is_some()).collect();
    if judged.is_empty() {
        return s;
    }
    let outcomes = [
        Outcome::Expected,
        Outcome::Named,
        Outcome::PartlyExplained,
        Outcome::Unexplained,
        Outcome::NotJudged,
    ];
    let _ = writeln!(
        s,
        "\noutcomes against the reference (rows: kind of case; columns: outcome)"
    );
    let _ = write!(s, "{:<10}", "kind");
    for o in outcomes {
        let _ = write!(s, "{:>18}", o.name());
    }
    let _ = writeln!(s, "{:>8}", "error");
    for kind in ["effect", "pair", "plant", "none"] {
        let cases: Vec<&CaseResult> = results.iter().filter(|c| c.kind == kind).collect();
        if cases.is_empty() {
            continue;
        }
        let _ = write!(s, "{kind:<10}");
        for o in outcomes {
            let n = cases.iter().filter(|c| c.outcome == Some(o)).count();
            let _ = write!(s, "{n:>18}");
        }
        let errors = cases.iter().filter(|c| c.named == "error").count();
        let _ = writeln!(s, "{errors:>8}");
    }
    // Judged cases of a kind, and how many of them were judged expected.
    let of_kind = |kind: &str| -> (Vec<&CaseResult>, usize) {
        let cases: Vec<&CaseResult> = judged.iter().copied().filter(|c| c.kind == kind).collect();
        let expected = cases
            .iter()
            .filter(|c| c.outcome == Some(Outcome::Expected))
            .count();
        (cases, expected)
    };
    let (clean, ok) = of_kind("none");
    if !clean.is_empty() {
        let _ = writeln!(
            s,
            "effect-free sessions judged expected (no false alarm): {ok}/{}",
            clean.len()
        );
    }
    let (plant, silent) = of_kind("plant");
    if !plant.is_empty() {
        let _ = writeln!(
            s,
            "plant changes reported silently as expected: {silent}/{} (the rest unexplained, partly explained or named)",
            plant.len()
        );
        let mut names: Vec<&str> = Vec::new();
        for c in &plant {
            if !names.contains(&c.hidden.as_str()) {
                names.push(c.hidden.as_str());
            }
        }
        let _ = writeln!(
            s,
            "{:<52} {:>6} {:>26} {:>22}  outcomes",
            "plant change", "seeds", "max ratio before (med/worst)", "after (med/worst)"
        );
        for name in names {
            let cases: Vec<&&CaseResult> = plant.iter().filter(|c| c.hidden == name).collect();
            let mut before: Vec<f64> = cases
                .iter()
                .filter_map(|c| c.max_ratio.map(|r| r.0))
                .collect();
            let mut after: Vec<f64> = cases
                .iter()
                .filter_map(|c| c.max_ratio.map(|r| r.1))
                .collect();
            // The worst seed of a plant change is the one closest to passing as healthy: the
            // lowest ratio.
            let med_worst = |v: &mut Vec<f64>| -> String {
                if v.is_empty() {
                    return "-".into();
                }
                v.sort_by(f64::total_cmp);
                format!("{:.1}/{:.1}", v[v.len() / 2], v[0])
            };
            let _ = writeln!(
                s,
                "{:<52} {:>6} {:>26} {:>22}  {}",
                name,
                cases.len(),
                med_worst(&mut before),
                med_worst(&mut after),
                cases
                    .iter()
                    .map(|c| format!(
                        "{}{}{}",
                        c.outcome.map_or("error", Outcome::name),
                        if c.named == "none" || c.named == "error" {
                            String::new()
                        } else {
                            format!(" ({})", c.named)
                        },
                        c.magnitude_error_percent
                            .map_or(String::new(), |e| format!(" {e:+.0} % of the change"))
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            );
        }
    }
    let _ = writeln!(
        s,
        "\nper judged case: outcome, largest ratio before -> after, beyond the reference"
    );
    for c in &judged {
        let _ = writeln!(
            s,
            "{:<60} {:<17} {:>12} {}",
            c.case,
            c.outcome.map_or("-", Outcome::name),
            c.max_ratio
                .map_or("-".into(), |(b, a)| format!("{b:.1}->{a:.1}")),
            c.unexplained
                .iter()
                .map(|(sig, r)| format!("{sig} {r:.1}x"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    s
}

/// The pairs of hidden effects: each case's outcome, what was named, and the share reported right
/// (both named within 25 %, or reported as ambiguous).
pub fn pairs_text(results: &[CaseResult]) -> String {
    use std::fmt::Write as _;
    let pairs: Vec<&CaseResult> = results.iter().filter(|c| c.kind == "pair").collect();
    let mut s = String::new();
    if pairs.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "\npairs of hidden effects (both: each named within 25 %; ambiguous: reported as a pair that cannot be told apart)"
    );
    for c in &pairs {
        let _ = writeln!(
            s,
            "{:<60} {:<10} named {}{}",
            c.case,
            c.pair.map_or("error", PairOutcome::name),
            if c.named_all.is_empty() {
                "nothing".to_string()
            } else {
                c.named_all
                    .iter()
                    .map(|(n, m, _)| format!("{n}={m:.3e}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            },
            if c.ambiguous.is_empty() {
                String::new()
            } else {
                format!(
                    "; ambiguous {}",
                    c.ambiguous
                        .iter()
                        .map(|[a, b]| format!("{a}|{b}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        );
    }
    let right = pairs
        .iter()
        .filter(|c| matches!(c.pair, Some(PairOutcome::Both | PairOutcome::Ambiguous)))
        .count();
    let _ = writeln!(
        s,
        "pairs reported right (both named within 25 % or ambiguous): {right}/{} ({:.0} %, target >= 90 %)",
        pairs.len(),
        100.0 * right as f64 / pairs.len() as f64
    );
    s
}

/// Whether a written profile changes the simulator in free air, where the twin's gap is measured:
/// anything but the soil effects (the re-run has no terrain and no payload).
fn acts_in_free_air(written: &[String]) -> bool {
    written
        .iter()
        .any(|n| n != Candidate::SoilCohesion.name() && n != Candidate::SoilDensity.name())
}

/// The twin: for every case whose profile changes the simulator in free air, its gap to the
/// held-out digs over the nominal plant's per group, and the share of cases in which the mean of
/// the groups' ratios is at most one half.
pub fn twin_text(results: &[CaseResult]) -> String {
    use std::fmt::Write as _;
    let cases: Vec<&CaseResult> = results
        .iter()
        .filter(|c| acts_in_free_air(&c.twin_written) && !c.twin_ratio.is_empty())
        .collect();
    let mut s = String::new();
    if cases.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "\nthe twin: the simulator re-run on the held-out digs' commands with the written profile, \
         its free-air gap over the nominal plant's (cases whose profile acts in free air)"
    );
    let groups: Vec<&str> = crate::twin::GAP_GROUPS.iter().map(|(g, _)| *g).collect();
    let _ = write!(s, "{:<60}", "case");
    for g in &groups {
        let _ = write!(s, " {g:>17}");
    }
    let _ = writeln!(s, "  written");
    let mut halved = 0;
    let mut means = Vec::new();
    for c in &cases {
        let _ = write!(s, "{:<60}", c.case);
        let ratios: Vec<f64> = groups
            .iter()
            .map(|g| c.twin_ratio.get(*g).copied().unwrap_or(f64::NAN))
            .collect();
        for r in &ratios {
            let _ = write!(s, " {r:>17.2}");
        }
        let _ = writeln!(s, "  {}", c.twin_written.join(", "));
        let finite: Vec<f64> = ratios.into_iter().filter(|r| r.is_finite()).collect();
        if !finite.is_empty() {
            let mean = finite.iter().sum::<f64>() / finite.len() as f64;
            means.push(mean);
            if mean <= 0.5 {
                halved += 1;
            }
        }
    }
    let _ = writeln!(
        s,
        "gap halved (mean of the groups' ratios <= 0.5): {halved}/{} ({:.0} %); mean ratio median {:.2}, worst {:.2}",
        cases.len(),
        100.0 * halved as f64 / cases.len() as f64,
        lab::results::median(&means),
        means.iter().copied().fold(f64::NAN, f64::max),
    );
    s
}

/// The confusion table and the summary figures as text.
pub fn confusion_text(results: &[CaseResult]) -> String {
    use std::fmt::Write as _;
    let mut rows: Vec<String> = Candidate::ALL
        .iter()
        .map(|c| c.name().to_string())
        .collect();
    rows.push("none".into());
    let short = |n: &str| -> String {
        n.split('_')
            .map(|w| w.chars().next().unwrap_or('?'))
            .collect::<String>()
    };
    let mut s = String::new();
    let _ = writeln!(
        s,
        "confusion table (rows: hidden effect, columns: named effect; first named)"
    );
    let _ = write!(s, "{:<24}", "hidden \\ named");
    for r in &rows {
        let _ = write!(s, "{:>5}", short(r));
    }
    let _ = writeln!(s, "  correct");
    for hidden in &rows {
        let cases: Vec<&CaseResult> = results.iter().filter(|c| &c.hidden == hidden).collect();
        if cases.is_empty() {
            continue;
        }
        let _ = write!(s, "{:<24}", hidden);
        for named in &rows {
            let n = cases.iter().filter(|c| &c.named == named).count();
            let _ = write!(
                s,
                "{:>5}",
                if n == 0 {
                    ".".to_string()
                } else {
                    n.to_string()
                }
            );
        }
        let ok = cases.iter().filter(|c| &c.named == hidden).count();
        let _ = writeln!(s, "  {ok}/{}", cases.len());
    }
    let _ = writeln!(
        s,
        "(column codes: first letters of the names, e.g. vd = valve_deadband, pso = pressure_sensor_offset)"
    );
    let with: Vec<&CaseResult> = results.iter().filter(|c| c.kind == "effect").collect();
    let without: Vec<&CaseResult> = results.iter().filter(|c| c.hidden == "none").collect();
    let named_ok = with.iter().filter(|c| c.named == c.hidden).count();
    let mag_ok = with
        .iter()
        .filter(|c| {
            c.named == c.hidden && c.magnitude_error_percent.is_some_and(|e| e.abs() <= 25.0)
        })
        .count();
    let rms_ok = with
        .iter()
        .filter(|c| c.best_rms_change_percent.is_some_and(|e| e <= -50.0))
        .count();
    let acted_ok = with
        .iter()
        .filter(|c| c.best_acted_rms_change_percent.is_some_and(|e| e <= -50.0))
        .count();
    let none_ok = without.iter().filter(|c| c.named == "none").count();
    let pct = |a: usize, b: usize| {
        if b > 0 {
            100.0 * a as f64 / b as f64
        } else {
            0.0
        }
    };
    let _ = writeln!(
        s,
        "hidden effect named correctly: {named_ok}/{} ({:.0} %, target >= 90 %)",
        with.len(),
        pct(named_ok, with.len())
    );
    let _ = writeln!(
        s,
        "  and magnitude within 25 %: {mag_ok}/{} ({:.0} %)",
        with.len(),
        pct(mag_ok, with.len())
    );
    let _ = writeln!(
        s,
        "held-out RMS of the effect's most affected signal fell >= 50 %: {rms_ok}/{} ({:.0} %)",
        with.len(),
        pct(rms_ok, with.len())
    );
    let _ = writeln!(
        s,
        "  on the samples where the augmented model acts: {acted_ok}/{} ({:.0} %)",
        with.len(),
        pct(acted_ok, with.len())
    );
    let _ = writeln!(
        s,
        "effect-free sessions with no effect named: {none_ok}/{} ({:.0} %, target >= 90 %)",
        without.len(),
        pct(none_ok, without.len())
    );
    let _ = writeln!(s, "\nper case:");
    let _ = writeln!(
        s,
        "{:<40} {:>5} {:<24} {:>10} {:>12} {:>8}",
        "case", "digs", "named", "mag err %", "rms change %", "acted %"
    );
    for c in results {
        let _ = writeln!(
            s,
            "{:<40} {:>5} {:<24} {:>10} {:>12} {:>8}",
            c.case,
            c.digs,
            c.named,
            c.magnitude_error_percent
                .map_or("-".into(), |e| format!("{e:+.1}")),
            c.best_rms_change_percent
                .map_or("-".into(), |e| format!("{e:+.1}")),
            c.best_acted_rms_change_percent
                .map_or("-".into(), |e| format!("{e:+.1}")),
        );
    }
    s
}

/// The cases of an evaluation.
///
/// # Errors
/// A plant change that does not parse.
pub fn cases(args: &EvalArgs) -> anyhow::Result<Vec<(Hidden, u64)>> {
    let mut effects: Vec<Candidate> = Candidate::ALL.to_vec();
    if !args.only.is_empty() {
        effects.retain(|c| args.only.iter().any(|n| n == c.name()));
    }
    if args.no_effects {
        effects.clear();
    }
    let plant = args.plant_changes()?;
    let mut out = Vec::new();
    if args.quick {
        let quick = [
            Candidate::ValveDeadband,
            Candidate::PumpSaturation,
            Candidate::CoulombFriction,
            Candidate::PressureSensorOffset,
            Candidate::TransportDelay,
            Candidate::FlowSharing,
        ];
        for c in quick.iter().filter(|c| effects.contains(c)) {
            out.push((Hidden::Effect(*c, magnitudes(*c)[1]), 11));
        }
        for p in plant {
            out.push((Hidden::Plant(p), 11));
        }
        out.push((Hidden::None, 11));
        return Ok(based(out, args.seed_base));
    }
    for seed in 0..args.seeds {
        for c in &effects {
            for m in magnitudes(*c) {
                out.push((Hidden::Effect(*c, m), 100 + seed));
            }
        }
        for p in &plant {
            out.push((Hidden::Plant(p.clone()), 400 + seed));
        }
        if !args.no_pairs && !args.no_effects && args.only.is_empty() {
            for pair in PAIRS {
                out.push((Hidden::Pair(pair), 600 + seed));
            }
        }
    }
    for seed in 0..args.nominal_sessions {
        out.push((Hidden::None, 200 + seed));
    }
    Ok(based(out, args.seed_base))
}

/// The cases with `base` added to their seeds.
fn based(cases: Vec<(Hidden, u64)>, base: u64) -> Vec<(Hidden, u64)> {
    cases
        .into_iter()
        .map(|(h, seed)| (h, seed.saturating_add(base)))
        .collect()
}

/// The seeds of the recorded reference's healthy sessions.
fn reference_seeds(args: &EvalArgs) -> Vec<u64> {
    let n = if args.quick {
        args.reference_sessions.min(1)
    } else {
        args.reference_sessions
    };
    (0..n)
        .map(|i| args.seed_base.saturating_add(300 + i))
        .collect()
}

/// Refuses an evaluation whose sessions share a seed with the built-in reference's: the default
/// path would judge sessions against themselves.
///
/// # Errors
/// The seeds that overlap.
fn check_seeds_clear_of_builtin(cases: &[(Hidden, u64)], reference: &[u64]) -> anyhow::Result<()> {
    let builtin = crate::reference::Reference::builtin()?;
    let Some(rec) = builtin.recording else {
        return Ok(());
    };
    let mut clash: Vec<u64> = cases
        .iter()
        .map(|(_, s)| *s)
        .chain(reference.iter().copied())
        .filter(|s| rec.seeds.contains(s))
        .collect();
    clash.sort_unstable();
    clash.dedup();
    anyhow::ensure!(
        clash.is_empty(),
        "--seed-base {}: seeds {clash:?} are the built-in reference's ({:?}); choose another base",
        cases.first().map_or(0, |c| c.1),
        rec.seeds
    );
    Ok(())
}

/// The campaign kind of `discrepancy eval`'s plans (`excavator-ctl campaign job` runs their jobs
/// with [`run_planned_job`]).
pub const CAMPAIGN_KIND: &str = "discrepancy-eval";

/// One job of the evaluation's campaign.
#[derive(Debug, Clone)]
enum EvalJob {
    /// A healthy reference session at a seed.
    ReferenceSession(u64),
    /// The reference fitted on the reference sessions (`OUT/reference.json`).
    Reference,
    /// A case: its session generated and analysed on each path (`OUT/campaign/cases/ID.json`).
    Case(Hidden, u64),
}

/// The reference sessions' plan at `seed`.
fn reference_session(args: &EvalArgs, seed: u64, digs: u32) -> SessionPlan {
    SessionPlan::new(
        &args.out,
        &format!("reference_s{seed}"),
        seed,
        digs,
        args.soil_contact,
        args.strategy(),
    )
}

/// `OUT/reference.json`, the evaluation's recorded reference (when it has reference sessions).
fn reference_path(args: &EvalArgs) -> Option<PathBuf> {
    (!reference_seeds(args).is_empty()).then(|| args.out.join("reference.json"))
}

/// A job id of the case: its session's base name in file-name characters, after its index.
fn case_id(index: usize, hidden: &Hidden, seed: u64) -> String {
    let name: String = case_base(hidden, seed)
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.+=".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("case-{index:03}-{name}")
}

/// The evaluation's jobs with the campaign's description of each.
///
/// # Errors
/// A plant change that does not parse; seeds that overlap the built-in reference's.
fn eval_jobs(args: &EvalArgs) -> anyhow::Result<Vec<(EvalJob, lab::campaign::Job)>> {
    let digs = eval_digs(args);
    let list = cases(args)?;
    let ref_seeds = reference_seeds(args);
    check_seeds_clear_of_builtin(&list, &ref_seeds)?;
    let plan_file = lab::campaign::campaign_dir(&args.out).join("plan.json");
    let job = |id: String, stage, inputs, outputs| lab::campaign::Job {
        argv: [
            "excavator-ctl",
            "campaign",
            "job",
            "--plan",
            &plan_file.to_string_lossy(),
            "--job",
            &id,
        ]
        .map(String::from)
        .to_vec(),
        id,
        stage,
        inputs,
        outputs,
    };
    let mut jobs = Vec::new();
    let mut ref_sessions = Vec::new();
    for &seed in &ref_seeds {
        let session = reference_session(args, seed, digs).demo.out;
        ref_sessions.push(session.clone());
        jobs.push((
            EvalJob::ReferenceSession(seed),
            job(format!("reference-s{seed}"), 0, vec![], vec![session]),
        ));
    }
    let reference = reference_path(args);
    if let Some(r) = &reference {
        jobs.push((
            EvalJob::Reference,
            job("reference".into(), 1, ref_sessions, vec![r.clone()]),
        ));
    }
    for (i, (hidden, seed)) in list.into_iter().enumerate() {
        let id = case_id(i, &hidden, seed);
        let session = SessionPlan::new(
            &args.out,
            &case_base(&hidden, seed),
            seed,
            digs,
            args.soil_contact,
            args.strategy(),
        );
        let mut outputs = vec![case_file(args, &id), session.demo.out];
        let mut paths = vec![EvalPath::Default];
        paths.extend(reference.as_ref().map(|_| EvalPath::Recorded));
        outputs.extend(
            paths
                .into_iter()
                .map(|p| args.out.join("reports").join(p.name()).join(&session.case)),
        );
        let j = job(id, 2, reference.iter().cloned().collect(), outputs);
        jobs.push((EvalJob::Case(hidden, seed), j));
    }
    Ok(jobs)
}

/// `OUT/campaign/cases/ID.json`: a case's results on each path.
fn case_file(args: &EvalArgs, id: &str) -> PathBuf {
    lab::campaign::campaign_dir(&args.out)
        .join("cases")
        .join(format!("{id}.json"))
}

/// Digs per session.
fn eval_digs(args: &EvalArgs) -> u32 {
    args.digs.unwrap_or(if args.quick { 4 } else { 16 })
}

/// Runs one job of the evaluation's campaign.
///
/// # Errors
/// Generating a reference session or fitting the reference (a case never fails: a case whose
/// session cannot be generated or analysed is a miss, named `error`); writing the outputs.
fn run_eval_job(args: &EvalArgs, job: &EvalJob, id: &str) -> anyhow::Result<()> {
    let digs = eval_digs(args);
    match job {
        EvalJob::ReferenceSession(seed) => {
            reference_session(args, *seed, digs).generate().map(|_| ())
        }
        EvalJob::Reference => {
            let sessions: Vec<PathBuf> = reference_seeds(args)
                .into_iter()
                .map(|seed| reference_session(args, seed, digs).generate())
                .collect::<anyhow::Result<_>>()?;
            let machine = load_machine(None)?;
            let model = load_model(None)?;
            let reference = load_reference(&sessions, &machine, &model)?
                .ok_or_else(|| anyhow::anyhow!("no reference sessions"))?;
            let path = args.out.join("reference.json");
            lab::campaign::write_atomic(&path, &reference.to_json()?)
        }
        EvalJob::Case(hidden, seed) => {
            let r = run_case(args, hidden, *seed, digs, reference_path(args).as_deref());
            lab::campaign::write_atomic(&case_file(args, id), &serde_json::to_string(&r)?)
        }
    }
}

/// The arguments of `discrepancy eval` as its command line (without the campaign options, which
/// do not change a job): the plan's `args`, which [`run_planned_job`] parses back.
fn eval_argv(a: &EvalArgs) -> Vec<String> {
    let mut v: Vec<String> = Vec::new();
    let mut push = |k: &str, val: String| {
        v.push(k.to_owned());
        v.push(val);
    };
    push("--seeds", a.seeds.to_string());
    push("--nominal-sessions", a.nominal_sessions.to_string());
    if let Some(d) = a.digs {
        push("--digs", d.to_string());
    }
    for o in &a.only {
        push("--only", o.clone());
    }
    push("--out", a.out.to_string_lossy().into_owned());
    if let Some(c) = a.soil_contact {
        push("--soil-contact", value_name(c));
    }
    if let Some(st) = a.strategy {
        push("--strategy", value_name(st));
    }
    for p in &a.plant {
        push("--plant", p.clone());
    }
    push("--reference-sessions", a.reference_sessions.to_string());
    push("--seed-base", a.seed_base.to_string());
    if let Some(r) = &a.results {
        push("--results", r.to_string_lossy().into_owned());
    }
    for (on, flag) in [
        (a.quick, "--quick"),
        (a.no_effects, "--no-effects"),
        (a.no_pairs, "--no-pairs"),
    ] {
        if on {
            v.push(flag.into());
        }
    }
    v
}

/// A value's name on the command line.
fn value_name(v: impl clap::ValueEnum) -> String {
    v.to_possible_value()
        .map(|p| p.get_name().to_owned())
        .unwrap_or_default()
}

/// `discrepancy eval`'s arguments parsed from [`eval_argv`]'s words.
#[derive(Debug, clap::Parser)]
#[command(no_binary_name = true)]
struct EvalCommandLine {
    #[command(flatten)]
    args: EvalArgs,
}

/// Runs the job `id` of a `discrepancy eval` plan (`excavator-ctl campaign job`): the arguments
/// parsed from the plan, the job found among the ones they make.
///
/// # Errors
/// Arguments that do not parse; a job the arguments do not make, or whose command line differs
/// from the plan's (a plan of another version); the job's own errors.
pub fn run_planned_job(plan: &lab::campaign::Plan, id: &str) -> anyhow::Result<()> {
    use clap::Parser as _;
    let args = EvalCommandLine::try_parse_from(&plan.args)
        .with_context(|| format!("the plan's arguments {:?}", plan.args))?
        .args;
    let planned = plan.job(id)?;
    let (job, spec) = eval_jobs(&args)?
        .into_iter()
        .find(|(_, j)| j.id == id)
        .ok_or_else(|| anyhow::anyhow!("the plan's arguments make no job {id:?}"))?;
    anyhow::ensure!(
        &spec == planned,
        "job {id:?}: the plan holds {planned:?}, this excavator-ctl makes {spec:?} (a plan of \
         another version: make it again)"
    );
    run_eval_job(&args, &job, id)
}

/// Runs the evaluation as a campaign (in-process by default), prints the table, writes
/// `eval.json` and `eval.md`.
///
/// # Errors
/// A session that cannot be generated or analysed; a job that failed; writing the outputs.
pub fn run_eval(args: &EvalArgs) -> anyhow::Result<()> {
    let digs = eval_digs(args);
    let t = Instant::now();
    let jobs = eval_jobs(args)?;
    let plan = lab::campaign::Plan::new(
        CAMPAIGN_KIND,
        eval_argv(args),
        &args.out,
        jobs.iter().map(|(_, j)| j.clone()).collect(),
    )?;
    let bar = indicatif::ProgressBar::new(jobs.len() as u64);
    if !std::io::IsTerminal::is_terminal(&std::io::stdout()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let run = |spec: &lab::campaign::Job| {
        let job = jobs
            .iter()
            .find(|(_, j)| j.id == spec.id)
            .map(|(j, _)| j)
            .ok_or_else(|| anyhow::anyhow!("no job {}", spec.id))?;
        let r = run_eval_job(args, job, &spec.id);
        bar.inc(1);
        r
    };
    let report = lab::campaign::execute(&plan, &args.campaign, &run)?;
    bar.finish_and_clear();
    let Some(report) = report else {
        println!(
            "plan of {} jobs written to {}",
            plan.jobs.len(),
            plan.path().display()
        );
        return Ok(());
    };
    println!("{}", report.line());
    let mut results: Vec<CaseResult> = Vec::new();
    for (_, j) in jobs.iter().filter(|(j, _)| matches!(j, EvalJob::Case(..))) {
        let path = case_file(args, &j.id);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let r: Vec<CaseResult> = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a case's results", path.display()))?;
        results.extend(r);
    }
    let text = [EvalPath::Default, EvalPath::Recorded]
        .into_iter()
        .filter_map(|path| {
            let of_path: Vec<CaseResult> = results
                .iter()
                .filter(|r| r.path == path.name())
                .cloned()
                .collect();
            (!of_path.is_empty()).then(|| {
                format!(
                    "=== {} ===\n\n{}{}{}{}\n",
                    path.title(),
                    confusion_text(&of_path),
                    pairs_text(&of_path),
                    outcome_text(&of_path),
                    twin_text(&of_path)
                )
            })
        })
        .collect::<String>();
    print!("{text}");
    println!(
        "{} cases in {:.0} s (generation and analysis, {})",
        results.len(),
        t.elapsed().as_secs_f64(),
        match &args.campaign.executor {
            lab::campaign::Executor::Local =>
                format!("in-process, {} rayon threads", rayon::current_num_threads()),
            lab::campaign::Executor::Dask { address } => format!("on the Dask cluster {address}"),
        }
    );
    std::fs::write(
        args.out.join("eval.json"),
        serde_json::to_string_pretty(&results)?,
    )
    .context("writing eval.json")?;
    std::fs::write(args.out.join("eval.md"), format!("```\n{text}```\n"))
        .context("writing eval.md")?;
    if let Some(page) = &args.results {
        let bench = bench_text(&BenchArgs {
            digs: 16,
            out: args.out.join("bench"),
        })?;
        print!("{bench}");
        let command = std::iter::once("excavator-ctl".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" ");
        std::fs::write(page, results_page(&command, digs, &text, &bench))
            .with_context(|| format!("writing {}", page.display()))?;
    }
    Ok(())
}

/// The generated results page of the workflow: the evaluation's tables and the timing of one
/// analysis, under the command that made them.
fn results_page(command: &str, digs: u32, eval: &str, bench: &str) -> String {
    let provenance = lab::results::Provenance::now();
    format!(
        "Generated by `{command}`; do not edit.\n\n# Discrepancy workflow: results\n\n\
         Made on {} at commit {}, plant `{}`. Sessions generated fresh by the in-process demo \
         ({digs} digs each, the default planned bench unless the command says otherwise), each \
         analysed from its folder twice: on the default path (`analyse` without `--reference`, \
         judged against the built-in reference of the default machine) and against the \
         `reference.json` of the evaluation's healthy sessions (seeds 300 and on, plus the \
         command's `--seed-base`); what the tables mean is in [discrepancy.md](discrepancy.md) (Evaluation).\n\n\
         ## Evaluation\n\n```\n{eval}```\n\n## One analysis, timed (`discrepancy bench`)\n\n\
         ```\n{bench}```\n",
        provenance.date,
        provenance.commit,
        vcan_sim::PLANT_VERSION,
    )
}

/// Times `discrepancy analyse` of one session of `args.digs` digs on one core, as a user runs it:
/// against a `reference.json` (made first, from a healthy session of as many digs), every step
/// included (read and prepare, the candidate fits, the verdict, the term suggestion, the twin's
/// re-run, the report). Both sessions are generated first unless they are in `args.out`: the
/// measured one on the default planned bench with a 0.3 pump saturation hidden (seed 400; a
/// valve dead band of 0.1 stalls the planned session before its first dig is complete), the
/// healthy one at seed 300. Prints the wall and CPU time and the load average.
///
/// # Errors
/// Generating or analysing the sessions.
pub fn run_bench(args: &BenchArgs) -> anyhow::Result<()> {
    print!("{}", bench_text(args)?);
    Ok(())
}

/// [`run_bench`]'s measurement, as the text it prints.
///
/// # Errors
/// As [`run_bench`].
pub fn bench_text(args: &BenchArgs) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let mut text = String::new();
    let generate = |dir: PathBuf, seed: u64, effects: Vec<String>| -> anyhow::Result<PathBuf> {
        if !session_complete(&dir)? {
            // A user's session, as the measurement says it times: `demo`'s defaults.
            let demo = DemoArgs {
                digs: args.digs,
                seed: Some(seed),
                quiet: true,
                effects,
                ..DemoArgs::defaults(dir.clone())
            };
            run_session(&demo, &AtomicBool::new(false))
                .with_context(|| format!("generating the bench session {}", dir.display()))?;
        }
        Ok(dir)
    };
    let session = generate(
        args.out.join("session"),
        400,
        vec!["pump_saturation=0.3".into()],
    )?;
    let healthy = generate(args.out.join("healthy"), 300, Vec::new())?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("one-thread pool")?;
    let timed = |f: &mut dyn FnMut() -> anyhow::Result<()>| -> anyhow::Result<(f64, Option<f64>)> {
        let t = Instant::now();
        let cpu0 = process_cpu_s();
        f()?;
        let cpu = process_cpu_s().zip(cpu0).map(|(b, a)| b - a);
        Ok((t.elapsed().as_secs_f64(), cpu))
    };
    let reference_file = args.out.join("reference.json");
    let (ref_wall, ref_cpu) = pool.install(|| {
        timed(&mut || {
            let reference = load_reference(
                std::slice::from_ref(&healthy),
                &load_machine(None)?,
                &load_model(None)?,
            )?
            .context("no reference")?;
            std::fs::create_dir_all(&args.out)?;
            std::fs::write(&reference_file, reference.to_json()?)
                .with_context(|| format!("writing {}", reference_file.display()))
        })
    })?;
    let mut analyse_args = AnalyseArgs::new(vec![session], args.out.join("report"));
    analyse_args.reference = vec![reference_file];
    let mut outcome = None;
    let (wall, cpu) = pool.install(|| {
        timed(&mut || {
            outcome = Some(run_analysis(&analyse_args)?);
            Ok(())
        })
    })?;
    let cpu_text = |c: Option<f64>| c.map_or_else(|| "n/a".to_string(), |c| format!("{c:.2} s"));
    let _ = writeln!(
        text,
        "discrepancy bench: one analysis of {} digs against a reference.json, one core: wall {wall:.2} s, CPU {} (target < 10 s)",
        args.digs,
        cpu_text(cpu)
    );
    let _ = writeln!(
        text,
        "  (the reference from {} healthy digs, once: wall {ref_wall:.2} s, CPU {})",
        args.digs,
        cpu_text(ref_cpu)
    );
    if let Some(a) = &outcome {
        let _ = writeln!(
            text,
            "  named {:?}, ambiguous {}, outcome {}",
            a.result
                .named_effects
                .iter()
                .map(|e| format!("{}={:.3e}", e.name, e.magnitude))
                .collect::<Vec<_>>(),
            a.result.ambiguous.len(),
            a.verdict
                .as_ref()
                .map_or("not judged", |v| v.outcome.name())
        );
    }
    let _ = writeln!(
        text,
        "CPU time is what one unshared core would take; the wall time grows with the machine's load"
    );
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let _ = writeln!(text, "load average: {}", load.trim());
    Ok(text)
}

/// CPU time (user + system) of this process so far, s, from `/proc/self/stat` (Linux; `None`
/// elsewhere). Fields 14 and 15 in clock ticks of 1/100 s (USER_HZ).
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) is in parentheses and may contain spaces: count after it.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plan's arguments are the command's own: every option away from its default, written by
    /// `eval_argv` and parsed back as `campaign job` does, gives the same arguments (the campaign
    /// options aside, which change no job); the defaults write the defaults.
    #[test]
    fn a_plans_arguments_parse_back_to_the_commands() {
        use clap::Parser as _;
        let parse = |words: &[String]| EvalCommandLine::try_parse_from(words).unwrap().args;
        let defaults = parse(&[]);
        let plain = EvalArgs::new(defaults.out.clone());
        assert_eq!(
            format!("{:?}", parse(&eval_argv(&plain))),
            format!("{plain:?}")
        );
        assert_eq!(format!("{defaults:?}"), format!("{plain:?}"));
        let mut a = EvalArgs::new(PathBuf::from("/tmp/some eval"));
        a.quick = true;
        a.seeds = 3;
        a.nominal_sessions = 9;
        a.digs = Some(5);
        a.only = vec!["hydraulic_lag".into(), "soil_density".into()];
        a.soil_contact = Some(SoilContact::Held);
        a.strategy = Some(DemoStrategy::Fixed);
        a.plant = vec!["hydraulic_lag=0.05".into()];
        a.reference_sessions = 4;
        a.seed_base = 1000;
        a.no_effects = true;
        a.no_pairs = true;
        a.results = Some(PathBuf::from("/tmp/results.md"));
        let back = parse(&eval_argv(&a));
        a.campaign = back.campaign.clone();
        assert_eq!(format!("{back:?}"), format!("{a:?}"));
    }

    /// The twin's table counts the cases whose profile acts in free air, and a case halves the gap
    /// when the mean of its groups' ratios is at most one half; a soil effect alone (not measured
    /// in free air) and a case without a re-run are left out.
    #[test]
    fn the_twin_table_counts_the_cases_whose_gap_halved() {
        let case = |name: &str, written: &[&str], ratios: [f64; 3]| {
            let mut c = CaseResult::failed(name.into(), &Hidden::None, 1, EvalPath::Recorded);
            c.twin_written = written.iter().map(|w| (*w).to_string()).collect();
            c.twin_ratio = crate::twin::GAP_GROUPS
                .iter()
                .zip(ratios)
                .map(|((g, _), r)| ((*g).to_string(), r))
                .collect();
            c
        };
        let results = [
            case("lag", &["hydraulic_lag"], [0.1, 0.2, 0.3]),
            case("bore", &["cylinders.boom.bore_m"], [0.9, 0.5, 0.4]),
            case("density", &["soil_density"], [1.0, 1.0, 1.0]),
            case("nothing", &[], [1.0, 1.0, 1.0]),
        ];
        let text = twin_text(&results);
        assert!(text.contains("lag") && text.contains("bore"), "{text}");
        assert!(
            !text.contains("density") && !text.contains("nothing"),
            "{text}"
        );
        assert!(
            text.contains("gap halved (mean of the groups' ratios <= 0.5): 1/2 (50 %)"),
            "{text}"
        );
        assert!(text.contains("median 0.40, worst 0.60"), "{text}");
        assert_eq!(twin_text(&results[2..]), "");
    }

    #[test]
    fn an_interrupted_session_is_generated_again() {
        let dir = tempfile::tempdir().unwrap();
        let session = dir.path().join("none_s200");
        std::fs::create_dir_all(session.join("scans")).unwrap();
        std::fs::write(session.join("trace.log"), "(0.000000) vcan0 0CFF0101#").unwrap();
        assert!(!session_complete(&session).unwrap());
        assert!(!session.exists(), "the interrupted session is removed");
        std::fs::create_dir_all(&session).unwrap();
        std::fs::write(session.join("trace.log"), "").unwrap();
        std::fs::write(session.join("summary.json"), "{}").unwrap();
        assert!(session_complete(&session).unwrap());
        assert!(
            session.join("trace.log").exists(),
            "a finished session is kept"
        );
    }

    /// Every evaluation magnitude is one the simulator accepts for the effect of that name (eval
    /// hides it as `--effect NAME=VALUE`).
    #[test]
    fn the_evaluation_magnitudes_are_in_the_simulators_ranges() {
        let pairs = PAIRS.iter().flatten().copied();
        let singles = Candidate::ALL
            .iter()
            .flat_map(|c| magnitudes(*c).map(|m| (*c, m)));
        for (c, m) in singles.chain(pairs) {
            let mut set = vcan_sim::effects::EffectSet::nominal();
            if let Err(e) = set.apply_arg(&format!("{}={m}", c.name())) {
                panic!("{e}");
            }
        }
    }

    /// A pair is right when both are named within 25 % or the two are reported ambiguous; one
    /// named with the other's magnitude folded in is not.
    #[test]
    fn a_pair_is_right_both_named_or_ambiguous_not_one_with_the_others_share() {
        let named = |list: &[(&str, f64)]| -> Vec<crate::NamedEffect> {
            list.iter()
                .map(|(n, m)| crate::NamedEffect {
                    name: (*n).to_string(),
                    kind: "effect",
                    magnitude: *m,
                    uncertainty: 0.0,
                    unit: "s",
                    description: String::new(),
                    heldout_delta_bic: 100.0,
                    fitted_jointly_with: None,
                })
                .collect()
        };
        let pair = PAIRS[0];
        let both = named(&[("transport_delay", 0.055), ("hydraulic_lag", 0.09)]);
        assert_eq!(pair_outcome(&pair, &both, &[]), PairOutcome::Both);
        let lumped = named(&[("transport_delay", 0.138)]);
        assert_eq!(pair_outcome(&pair, &lumped, &[]), PairOutcome::Neither);
        let one = named(&[("transport_delay", 0.05)]);
        assert_eq!(pair_outcome(&pair, &one, &[]), PairOutcome::One);
        let ambiguous = [["hydraulic_lag".to_string(), "transport_delay".to_string()]];
        assert_eq!(pair_outcome(&pair, &[], &ambiguous), PairOutcome::Ambiguous);
    }
}
