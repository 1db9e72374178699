//! `excavator-ctl discrepancy fleet`: `discrepancy analyse` of every machine of a fleet, each
//! against its own reference, as a campaign (in-process or on a Dask cluster, [`lab::campaign`]),
//! and one table of what each machine shows: the outcome, the named effects, the parameters that
//! drifted, the signals nothing explains and the data's sufficiency (docs/campaigns.md).
//!
//! The fleet's folder holds one folder per machine:
//!
//! ```text
//! FLEET/NAME/sessions/*/       recorded sessions (trace.log, scans/), as `run --out` writes them
//! FLEET/NAME/reference.json    optional: its reference (`discrepancy analyse ... --reference`'s)
//! FLEET/NAME/reference/*/      or the healthy sessions to make it from
//! FLEET/NAME/machine.toml      optional: the machine file its controller reads
//! ```

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;
use lab::campaign::{CampaignArgs, Job, Plan};
use serde::{Deserialize, Serialize};

use crate::analysis::{AnalyseArgs, run_analysis};

/// The campaign kind of `discrepancy fleet`'s plans.
pub const CAMPAIGN_KIND: &str = "discrepancy-fleet";

/// Arguments of `discrepancy fleet`.
#[derive(Debug, Clone, Args)]
pub struct FleetArgs {
    /// The fleet's folder: one folder per machine with its sessions in `sessions/*/`, and
    /// optionally `reference.json` or healthy sessions in `reference/*/`, and `machine.toml`.
    #[arg(long, value_name = "DIR")]
    pub fleet: PathBuf,
    /// Output folder: `machines/NAME/` (each machine's analysis), `fleet.md`, `fleet.json`.
    #[arg(long, default_value = "out/discrepancy-fleet", value_name = "DIR")]
    pub out: PathBuf,
    /// Where the analyses run (in-process or a Dask cluster; docs/campaigns.md).
    #[command(flatten)]
    pub campaign: CampaignArgs,
}

/// One machine of the fleet, as found in its folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FleetMachine {
    /// The folder's name.
    pub name: String,
    /// Its session folders, sorted.
    pub sessions: Vec<PathBuf>,
    /// `reference.json`, or the healthy session folders of `reference/`.
    pub reference: Vec<PathBuf>,
    /// `machine.toml`, when there.
    pub machine: Option<PathBuf>,
}

/// The session folders (holding `trace.log`) directly under `dir`, sorted; none when `dir` is not
/// there.
fn session_folders(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let p = e
            .with_context(|| format!("reading {}", dir.display()))?
            .path();
        if p.join("trace.log").is_file() {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// The machines of the fleet folder, sorted by name.
///
/// # Errors
/// The folder cannot be read; a machine's name that is not letters, digits, `-`, `_` and `.`
/// (it names its job and its output folder).
pub fn fleet_machines(root: &Path) -> anyhow::Result<Vec<FleetMachine>> {
    let mut out = Vec::new();
    let entries =
        std::fs::read_dir(root).with_context(|| format!("reading the fleet {}", root.display()))?;
    for e in entries {
        let dir = e
            .with_context(|| format!("reading the fleet {}", root.display()))?
            .path();
        if !dir.is_dir() {
            continue;
        }
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        anyhow::ensure!(
            !name.starts_with('.')
                && name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)),
            "{}: a machine's folder name must be letters, digits, '-', '_' and '.'",
            dir.display()
        );
        let reference_file = dir.join("reference.json");
        let reference = if reference_file.is_file() {
            vec![reference_file]
        } else {
            session_folders(&dir.join("reference"))?
        };
        let machine = Some(dir.join("machine.toml")).filter(|m| m.is_file());
        out.push(FleetMachine {
            sessions: session_folders(&dir.join("sessions"))?,
            name,
            reference,
            machine,
        });
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// `OUT/machines/NAME`: a machine's analysis.
fn machine_out(args: &FleetArgs, m: &FleetMachine) -> PathBuf {
    args.out.join("machines").join(&m.name)
}

/// The `discrepancy analyse` command line of a machine (after `excavator-ctl discrepancy
/// analyse`).
fn analyse_words(args: &FleetArgs, m: &FleetMachine) -> Vec<String> {
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let mut v = vec![
        "--quiet".to_owned(),
        "--out".to_owned(),
        s(&machine_out(args, m)),
    ];
    v.push("--measured".into());
    v.extend(m.sessions.iter().map(|p| s(p)));
    if !m.reference.is_empty() {
        v.push("--reference".into());
        v.extend(m.reference.iter().map(|p| s(p)));
    }
    if let Some(f) = &m.machine {
        v.push("--machine".into());
        v.push(s(f));
    }
    v
}

/// The fleet's jobs: one `discrepancy analyse` per machine with sessions.
fn fleet_jobs(args: &FleetArgs, machines: &[FleetMachine]) -> Vec<Job> {
    machines
        .iter()
        .filter(|m| !m.sessions.is_empty())
        .map(|m| Job {
            id: m.name.clone(),
            stage: 0,
            argv: ["excavator-ctl", "discrepancy", "analyse"]
                .map(String::from)
                .into_iter()
                .chain(analyse_words(args, m))
                .collect(),
            inputs: m
                .sessions
                .iter()
                .chain(&m.reference)
                .chain(&m.machine)
                .cloned()
                .collect(),
            outputs: vec![machine_out(args, m)],
        })
        .collect()
}

/// `discrepancy analyse`'s arguments.
#[derive(Debug, clap::Parser)]
#[command(no_binary_name = true)]
struct AnalyseCommandLine {
    #[command(flatten)]
    args: AnalyseArgs,
}

/// Runs a fleet job in this process: what its command line does.
fn run_fleet_job(job: &Job) -> anyhow::Result<()> {
    use clap::Parser as _;
    let args = AnalyseCommandLine::try_parse_from(&job.argv[3..])
        .with_context(|| format!("job {}: its command line {:?}", job.id, job.argv))?
        .args;
    run_analysis(&args).with_context(|| format!("analysing machine {}", job.id))?;
    Ok(())
}

/// One machine's row of the fleet's table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MachineRow {
    /// The machine's folder name.
    pub machine: String,
    /// Sessions analysed.
    pub sessions: usize,
    /// Sessions left out as unreadable.
    pub skipped_sessions: usize,
    /// Digs analysed.
    pub digs: usize,
    /// Against its reference: `expected`, `named`, `partly_explained`, `unexplained`,
    /// `not_judged`; `none` without a reference; `no sessions`.
    pub outcome: String,
    /// Named effects: name, magnitude, unit.
    pub effects: Vec<(String, f64, String)>,
    /// Machine parameters named as drifted: key, magnitude, unit.
    pub parameters: Vec<(String, f64, String)>,
    /// Signals beyond the reference after the named effects, with their ratio to it.
    pub unexplained: Vec<(String, f64)>,
    /// The analysis's data-sufficiency warnings.
    pub warnings: Vec<String>,
}

/// A machine's row from its `report.json`.
fn machine_row(m: &FleetMachine, report: &Path) -> anyhow::Result<MachineRow> {
    let text =
        std::fs::read_to_string(report).with_context(|| format!("reading {}", report.display()))?;
    let r: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not an analysis report", report.display()))?;
    let named = |kind: &str| -> Vec<(String, f64, String)> {
        r["named_effects"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|e| e["kind"] == kind)
            .map(|e| {
                (
                    e["name"].as_str().unwrap_or_default().to_owned(),
                    e["magnitude"].as_f64().unwrap_or(f64::NAN),
                    e["unit"].as_str().unwrap_or_default().to_owned(),
                )
            })
            .collect()
    };
    Ok(MachineRow {
        machine: m.name.clone(),
        sessions: m.sessions.len(),
        skipped_sessions: r["skipped_sessions"].as_array().map_or(0, Vec::len),
        digs: r["digs"]
            .as_u64()
            .and_then(|d| usize::try_from(d).ok())
            .ok_or_else(|| anyhow::anyhow!("{}: no digs", report.display()))?,
        outcome: r["outcome"].as_str().unwrap_or("none").to_owned(),
        effects: named("effect"),
        parameters: named("parameter"),
        unexplained: r["unexplained"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|u| {
                (
                    u["signal"].as_str().unwrap_or_default().to_owned(),
                    u["ratio_to_expected"].as_f64().unwrap_or(f64::NAN),
                )
            })
            .collect(),
        warnings: r["warnings"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|w| w.as_str().map(str::to_owned))
            .collect(),
    })
}

/// The fleet's table, one line per machine.
pub fn fleet_text(rows: &[MachineRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| machine | sessions | digs | outcome | named effects | parameter drift | unexplained | warnings |"
    );
    let _ = writeln!(s, "|---|---:|---:|---|---|---|---|---:|");
    let list = |v: &[(String, f64, String)]| {
        if v.is_empty() {
            "-".to_owned()
        } else {
            v.iter()
                .map(|(n, m, u)| format!("{n} {m:.3e} {u}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    for r in rows {
        let unexplained = if r.unexplained.is_empty() {
            "-".to_owned()
        } else {
            r.unexplained
                .iter()
                .map(|(sig, x)| format!("{sig} x{x:.1}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let sessions = if r.skipped_sessions > 0 {
            format!("{} ({} unreadable)", r.sessions, r.skipped_sessions)
        } else {
            r.sessions.to_string()
        };
        let _ = writeln!(
            s,
            "| {} | {sessions} | {} | {} | {} | {} | {unexplained} | {} |",
            r.machine,
            r.digs,
            r.outcome,
            list(&r.effects),
            list(&r.parameters),
            r.warnings.len()
        );
    }
    let flagged = rows
        .iter()
        .filter(|r| !matches!(r.outcome.as_str(), "expected" | "no sessions"))
        .count();
    let _ = writeln!(
        s,
        "\n{} machines, {flagged} not as expected (named effects, drift or unexplained signals, or not judged)",
        rows.len()
    );
    s
}

/// Runs the fleet's analyses as a campaign, prints the table, writes `fleet.md` and `fleet.json`.
///
/// # Errors
/// The fleet folder cannot be read or holds no machine; an analysis that failed on its last
/// attempt; writing the outputs.
pub fn run_fleet(args: &FleetArgs) -> anyhow::Result<Vec<MachineRow>> {
    let machines = fleet_machines(&args.fleet)?;
    anyhow::ensure!(
        !machines.is_empty(),
        "the fleet {} holds no machine folder (FLEET/NAME/sessions/*/trace.log)",
        args.fleet.display()
    );
    let command = [
        "--fleet",
        &args.fleet.to_string_lossy(),
        "--out",
        &args.out.to_string_lossy(),
    ]
    .map(String::from)
    .to_vec();
    let plan = Plan::new(
        CAMPAIGN_KIND,
        command,
        &args.out,
        fleet_jobs(args, &machines),
    )?;
    let Some(report) = lab::campaign::execute(&plan, &args.campaign, &run_fleet_job)? else {
        println!(
            "plan of {} jobs written to {}",
            plan.jobs.len(),
            plan.path().display()
        );
        return Ok(Vec::new());
    };
    println!("{}", report.line());
    let rows: Vec<MachineRow> = machines
        .iter()
        .map(|m| {
            if m.sessions.is_empty() {
                Ok(MachineRow {
                    machine: m.name.clone(),
                    sessions: 0,
                    skipped_sessions: 0,
                    digs: 0,
                    outcome: "no sessions".into(),
                    effects: Vec::new(),
                    parameters: Vec::new(),
                    unexplained: Vec::new(),
                    warnings: Vec::new(),
                })
            } else {
                machine_row(m, &machine_out(args, m).join("report.json"))
            }
        })
        .collect::<anyhow::Result<_>>()?;
    let text = fleet_text(&rows);
    print!("{text}");
    lab::campaign::write_atomic(&args.out.join("fleet.md"), &text)?;
    lab::campaign::write_atomic(
        &args.out.join("fleet.json"),
        &serde_json::to_string_pretty(&rows)?,
    )?;
    Ok(rows)
}

/// A fleet plan's job `id` (`excavator-ctl campaign job`): its `discrepancy analyse`.
///
/// # Errors
/// No such job; a job that is not an analysis; the analysis's errors.
pub fn run_planned_job(plan: &Plan, id: &str) -> anyhow::Result<()> {
    let job = plan.job(id)?;
    anyhow::ensure!(
        job.argv.get(1..3) == Some(&["discrepancy".to_owned(), "analyse".to_owned()][..]),
        "job {id:?} of the fleet plan is not a `discrepancy analyse`"
    );
    run_fleet_job(job)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn machines_sessions_references_and_machine_files_are_found() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
        let touch = |p: &Path| {
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, "").unwrap();
        };
        touch(&root.join("b/sessions/s2/trace.log"));
        touch(&root.join("b/sessions/s1/trace.log"));
        touch(&root.join("b/sessions/not-a-session/notes.txt"));
        touch(&root.join("b/reference/h1/trace.log"));
        touch(&root.join("b/machine.toml"));
        touch(&root.join("a/reference.json"));
        touch(&root.join("a/reference/h1/trace.log"));
        std::fs::create_dir_all(root.join("c")).unwrap();
        let m = fleet_machines(root).unwrap();
        assert_eq!(
            m.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(),
            ["a", "b", "c"]
        );
        assert!(m[0].sessions.is_empty());
        assert_eq!(m[0].reference, [root.join("a/reference.json")]);
        assert_eq!(
            m[1].sessions,
            [root.join("b/sessions/s1"), root.join("b/sessions/s2")]
        );
        assert_eq!(m[1].reference, [root.join("b/reference/h1")]);
        assert_eq!(m[1].machine, Some(root.join("b/machine.toml")));
        let args = FleetArgs {
            fleet: root.to_path_buf(),
            out: root.join("out"),
            campaign: CampaignArgs::default(),
        };
        // A machine without sessions gets no job; the job is the analysis's command line.
        let jobs = fleet_jobs(&args, &m);
        assert_eq!(jobs.len(), 1);
        use clap::Parser as _;
        let parsed = AnalyseCommandLine::try_parse_from(&jobs[0].argv[3..])
            .unwrap()
            .args;
        assert_eq!(parsed.measured, m[1].sessions);
        assert_eq!(parsed.reference, m[1].reference);
        assert_eq!(parsed.machine, m[1].machine);
        assert_eq!(parsed.out, root.join("out/machines/b"));
        assert!(parsed.quiet);
    }

    #[test]
    fn a_machine_folder_with_a_bad_name_is_refused_by_name() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(tmp.path().join("bad name")).unwrap();
        let e = fleet_machines(tmp.path()).unwrap_err().to_string();
        assert!(e.contains("bad name"), "{e}");
    }
}
