//! Campaigns: the independent jobs of a long command (`discrepancy eval`, `discrepancy fleet`) as
//! data, run in this process (rayon, the default) or on a Dask cluster, and gathered into the same
//! files either way (docs/campaigns.md).
//!
//! A command writes its [`Plan`] to `OUT/campaign/plan.json`: every [`Job`] with the exact
//! `excavator-ctl` command line that runs it, the files it reads and the files it writes, in
//! stages (a stage's jobs start once every job of the stages before is done). The executor runs the
//! jobs that are not done yet; a job is done when its marker `OUT/campaign/done/ID.json` holds its
//! command line, so a campaign interrupted anywhere resumes where it stopped, on either executor.
//! The command then gathers the jobs' outputs itself, from the files, so the in-process and the
//! cluster run write the same bytes.
//!
//! On Dask ([`Executor::Dask`]) this process writes the driver ([`DASK_DRIVER`]) beside the plan and
//! runs it with `python3`: it submits one task per job (the job's command line, run by the worker
//! as a subprocess in the shared work folder), retries a failed task, records every attempt, and
//! writes the done markers as the tasks finish. Workers need the `excavator-ctl` binary and the
//! shared folder, nothing else of this project.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::Context as _;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The Python driver of [`Executor::Dask`] (written to `OUT/campaign/dask_driver.py` and run by
/// `python3`; it needs the `distributed` package).
pub const DASK_DRIVER: &str = include_str!("dask_driver.py");

/// The version of `plan.json`'s layout.
pub const PLAN_FORMAT: u32 = 1;

/// The most retries of a failed job [`CampaignArgs::retries`] allows.
pub const MAX_RETRIES: u32 = 10;

/// The campaign folder of a command's output folder.
pub fn campaign_dir(out: &Path) -> PathBuf {
    out.join("campaign")
}

/// One independent job of a campaign.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Job {
    /// Unique in its plan; letters, digits, `-`, `_`, `.`, `+` and `=` (a file name).
    pub id: String,
    /// Every job of a stage starts after every job of the stages before it is done.
    pub stage: u32,
    /// The command line that runs the job, `excavator-ctl ...` (the worker's binary replaces the
    /// first word), run in the plan's work folder.
    pub argv: Vec<String>,
    /// What the job reads, relative to the work folder (files or folders).
    pub inputs: Vec<PathBuf>,
    /// What the job writes, relative to the work folder (files or folders).
    pub outputs: Vec<PathBuf>,
}

/// A campaign's jobs and where they run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// [`PLAN_FORMAT`].
    pub format: u32,
    /// Which command made the plan (`discrepancy-eval`, `discrepancy-fleet`):
    /// `excavator-ctl campaign job` rebuilds the job from it and [`Plan::args`].
    pub kind: String,
    /// The command's arguments after its name, as given (relative paths are the work folder's).
    pub args: Vec<String>,
    /// The folder the jobs run in (absolute; on a cluster, the same path on every worker).
    pub workdir: PathBuf,
    /// The command's output folder, relative to the work folder or absolute.
    pub out: PathBuf,
    /// The jobs, in stage order.
    pub jobs: Vec<Job>,
}

impl Plan {
    /// A plan of `kind` for the command `args` writing into `out`, run in the current folder.
    ///
    /// # Errors
    /// The current folder cannot be read; two jobs with one id; an id that is not a file name; a
    /// job whose stage comes before a stage already listed.
    pub fn new(kind: &str, args: Vec<String>, out: &Path, jobs: Vec<Job>) -> anyhow::Result<Self> {
        let workdir = std::env::current_dir().context("reading the current folder")?;
        let plan = Self {
            format: PLAN_FORMAT,
            kind: kind.to_owned(),
            args,
            workdir,
            out: out.to_path_buf(),
            jobs,
        };
        plan.check()?;
        Ok(plan)
    }

    /// The campaign folder, `OUT/campaign`.
    pub fn dir(&self) -> PathBuf {
        campaign_dir(&self.out)
    }

    /// `OUT/campaign/plan.json`.
    pub fn path(&self) -> PathBuf {
        self.dir().join("plan.json")
    }

    /// The job `id`.
    ///
    /// # Errors
    /// No such job in the plan.
    pub fn job(&self, id: &str) -> anyhow::Result<&Job> {
        self.jobs
            .iter()
            .find(|j| j.id == id)
            .ok_or_else(|| anyhow::anyhow!("no job {id:?} in the {} campaign's plan", self.kind))
    }

    /// The stages in order.
    fn stages(&self) -> Vec<u32> {
        let mut s: Vec<u32> = self.jobs.iter().map(|j| j.stage).collect();
        s.dedup();
        s
    }

    fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.format == PLAN_FORMAT,
            "plan format {} (this excavator-ctl reads {PLAN_FORMAT})",
            self.format
        );
        let mut seen = std::collections::BTreeSet::new();
        let mut stage = 0;
        for j in &self.jobs {
            anyhow::ensure!(
                !j.id.is_empty()
                    && j.id.len() <= 200
                    && j.id
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_.+=".contains(c))
                    && !j.id.starts_with('.'),
                "job id {:?}: letters, digits and -_.+= only, at most 200, not starting with '.'",
                j.id
            );
            anyhow::ensure!(seen.insert(&j.id), "job id {:?} twice in the plan", j.id);
            anyhow::ensure!(
                j.stage >= stage,
                "job {:?}: stage {} after stage {stage}",
                j.id,
                j.stage
            );
            anyhow::ensure!(
                j.argv.first().is_some_and(|a| a == "excavator-ctl"),
                "job {:?}: its command line must start with excavator-ctl",
                j.id
            );
            stage = j.stage;
        }
        Ok(())
    }

    /// Reads a plan file.
    ///
    /// # Errors
    /// The file cannot be read or is not a plan of [`PLAN_FORMAT`] (the error names the file).
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let plan: Self = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a campaign plan", path.display()))?;
        plan.check()
            .with_context(|| format!("{}: an invalid plan", path.display()))?;
        Ok(plan)
    }

    /// Writes `OUT/campaign/plan.json`.
    ///
    /// # Errors
    /// Creating the folder or writing the file.
    pub fn write(&self) -> anyhow::Result<()> {
        std::fs::create_dir_all(self.dir().join("done"))
            .with_context(|| format!("creating {}", self.dir().display()))?;
        write_atomic(&self.path(), &serde_json::to_string_pretty(self)?)
    }

    /// Every job, a line each: done (worker, attempts, wall and CPU time) or pending, then the
    /// count.
    pub fn status_text(&self) -> String {
        let mut s = String::new();
        let mut done = 0;
        for j in &self.jobs {
            let record = std::fs::read_to_string(self.marker(j))
                .ok()
                .and_then(|t| serde_json::from_str::<JobRecord>(&t).ok())
                .filter(|r| r.argv == j.argv);
            let line = match record {
                Some(r) => {
                    done += 1;
                    format!(
                        "done     {:<48} stage {} on {} ({} attempts, {:.1} s{})",
                        j.id,
                        j.stage,
                        r.worker,
                        r.attempts,
                        r.wall_s,
                        r.cpu_s.map_or(String::new(), |c| format!(", CPU {c:.1} s"))
                    )
                }
                None => format!("pending  {:<48} stage {}", j.id, j.stage),
            };
            s.push_str(&line);
            s.push('\n');
        }
        s.push_str(&format!(
            "{} campaign: {done} of {} jobs done\n",
            self.kind,
            self.jobs.len()
        ));
        s
    }

    /// The done marker of `job`.
    fn marker(&self, job: &Job) -> PathBuf {
        self.dir().join("done").join(format!("{}.json", job.id))
    }

    /// Whether `job` is done: its marker holds its command line.
    fn done(&self, job: &Job) -> bool {
        std::fs::read_to_string(self.marker(job))
            .ok()
            .and_then(|t| serde_json::from_str::<JobRecord>(&t).ok())
            .is_some_and(|r| r.argv == job.argv)
    }
}

/// A done marker, `OUT/campaign/done/ID.json`: how the job ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    /// The job's id.
    pub id: String,
    /// Its command line.
    pub argv: Vec<String>,
    /// `local` or the Dask worker's address.
    pub worker: String,
    /// Attempts, this one included (a worker lost mid-job counts as one).
    pub attempts: u32,
    /// Wall time of the successful attempt, s.
    pub wall_s: f64,
    /// CPU time of the successful attempt (user and system), s; `None` in-process, where the jobs
    /// share the process.
    pub cpu_s: Option<f64>,
    /// The attempt's peak resident memory, KiB (`None` in-process).
    pub max_rss_kib: Option<u64>,
}

/// Where a campaign's jobs run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Executor {
    /// In this process, on its rayon pool.
    Local,
    /// On the Dask cluster whose scheduler listens at `address` (`tcp://HOST:PORT`).
    Dask {
        /// `tcp://HOST:PORT`.
        address: String,
    },
}

impl std::str::FromStr for Executor {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        if s == "local" {
            return Ok(Self::Local);
        }
        let Some(rest) = s.strip_prefix("dask://") else {
            return Err(format!("{s:?}: local or dask://HOST:PORT"));
        };
        let (host, port) = rest
            .rsplit_once(':')
            .ok_or_else(|| format!("{s:?}: dask://HOST:PORT needs the scheduler's port"))?;
        let host_ok = !host.is_empty()
            && host
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-._[]:".contains(c));
        if !host_ok {
            return Err(format!(
                "{s:?}: the host {host:?} is not a host name or address"
            ));
        }
        match port.parse::<u16>() {
            Ok(p) if p > 0 => Ok(Self::Dask {
                address: format!("tcp://{host}:{p}"),
            }),
            _ => Err(format!("{s:?}: the port {port:?} is not 1-65535")),
        }
    }
}

/// The campaign options of a command.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct CampaignArgs {
    /// Where the independent jobs run: `local` (this process, every core) or `dask://HOST:PORT`
    /// (the Dask scheduler's address; the output folder must be shared with the workers at the
    /// same path; docs/campaigns.md).
    #[arg(long, default_value = "local", value_name = "WHERE")]
    pub executor: Executor,
    /// Retries of a failed job before the campaign reports it and stops (a worker lost mid-job
    /// is Dask's to reschedule and does not count).
    #[arg(long, default_value_t = 2, value_name = "N",
          value_parser = clap::value_parser!(u32).range(0..=i64::from(MAX_RETRIES)))]
    pub retries: u32,
    /// The `excavator-ctl` the Dask workers run (default: this one's path, which the workers
    /// must see; `excavator-ctl` alone: their PATH's).
    #[arg(long, value_name = "PATH")]
    pub worker_binary: Option<PathBuf>,
    /// Rayon threads of each job on a Dask worker (one per worker thread: start the workers with
    /// `--nthreads 1` per core).
    #[arg(long, default_value_t = 1, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=256))]
    pub threads_per_job: u32,
    /// Write the plan (OUT/campaign/plan.json) and stop: run its jobs by hand or with another
    /// engine, then run the command again to gather.
    #[arg(long)]
    pub plan_only: bool,
}

impl Default for CampaignArgs {
    fn default() -> Self {
        Self {
            executor: Executor::Local,
            retries: 2,
            worker_binary: None,
            threads_per_job: 1,
            plan_only: false,
        }
    }
}

/// What a campaign run did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CampaignReport {
    /// Jobs in the plan.
    pub jobs: usize,
    /// Jobs found done (by an earlier run) and not run again.
    pub resumed: usize,
    /// Jobs run now.
    pub ran: usize,
    /// Of those, the ones that took more than one attempt, with their attempts.
    pub retried: Vec<(String, u32)>,
    /// Wall time of the run, s.
    pub wall_s: f64,
    /// Per job run now: CPU s (cluster jobs).
    pub cpu_s: Vec<f64>,
    /// The largest peak memory of a job, KiB (cluster jobs).
    pub max_rss_kib: Option<u64>,
    /// Bytes the jobs run now read (their inputs: what a worker fetches from the shared folder).
    pub bytes_in: u64,
    /// Bytes the jobs run now wrote (their outputs).
    pub bytes_out: u64,
}

impl CampaignReport {
    /// One line: jobs, resumed, retries, CPU time per job.
    pub fn line(&self) -> String {
        let mut s = format!(
            "campaign: {} jobs, {} done before, {} run in {:.1} s",
            self.jobs, self.resumed, self.ran, self.wall_s
        );
        if !self.retried.is_empty() {
            let list: Vec<String> = self
                .retried
                .iter()
                .map(|(id, n)| format!("{id} ({n} attempts)"))
                .collect();
            s.push_str(&format!("; retried: {}", list.join(", ")));
        }
        if !self.cpu_s.is_empty() {
            let mut c = self.cpu_s.clone();
            c.sort_by(f64::total_cmp);
            s.push_str(&format!(
                "; CPU per job median {:.1} s, max {:.1} s",
                c[c.len() / 2],
                c[c.len() - 1]
            ));
        }
        if let Some(m) = self.max_rss_kib {
            s.push_str(&format!(", peak memory {:.0} MiB", m as f64 / 1024.0));
        }
        if self.ran > 0 {
            s.push_str(&format!(
                "; {:.1} MB in, {:.1} MB out",
                self.bytes_in as f64 / 1e6,
                self.bytes_out as f64 / 1e6
            ));
        }
        s
    }
}

/// Runs the plan's jobs that are not done on `args.executor`, stage by stage: in-process each job
/// is `run_job(job)`, which must do what the job's command line does; on Dask the workers run the
/// command lines. Writes the plan first; with `--plan-only` that is all (returns `None`).
///
/// # Errors
/// Writing the plan; a job that failed on its last attempt (every failure is listed, the jobs that
/// finished keep their markers: running the command again resumes); the Dask driver could not be
/// started or lost the scheduler.
pub fn execute(
    plan: &Plan,
    args: &CampaignArgs,
    run_job: &(dyn Fn(&Job) -> anyhow::Result<()> + Sync),
) -> anyhow::Result<Option<CampaignReport>> {
    plan.write()?;
    if args.plan_only {
        return Ok(None);
    }
    let t = Instant::now();
    let mut report = CampaignReport {
        jobs: plan.jobs.len(),
        ..CampaignReport::default()
    };
    for stage in plan.stages() {
        let pending: Vec<&Job> = plan
            .jobs
            .iter()
            .filter(|j| j.stage == stage && !plan.done(j))
            .collect();
        report.resumed += plan.jobs.iter().filter(|j| j.stage == stage).count() - pending.len();
        if pending.is_empty() {
            continue;
        }
        match &args.executor {
            Executor::Local => run_local(plan, &pending, args.retries, run_job)?,
            Executor::Dask { address } => run_dask(plan, &pending, args, address)?,
        }
        let missing: Vec<&str> = pending
            .iter()
            .filter(|j| !plan.done(j))
            .map(|j| j.id.as_str())
            .collect();
        anyhow::ensure!(
            missing.is_empty(),
            "stage {stage}: jobs {missing:?} did not finish; run the command again to resume"
        );
        for j in &pending {
            let r: JobRecord = serde_json::from_str(&std::fs::read_to_string(plan.marker(j))?)?;
            report.ran += 1;
            if r.attempts > 1 {
                report.retried.push((r.id.clone(), r.attempts));
            }
            report.cpu_s.extend(r.cpu_s);
            report.max_rss_kib = report.max_rss_kib.max(r.max_rss_kib);
            report.bytes_in += bytes_under(&plan.workdir, &j.inputs);
            report.bytes_out += bytes_under(&plan.workdir, &j.outputs);
        }
    }
    report.wall_s = t.elapsed().as_secs_f64();
    write_atomic(
        &plan.dir().join("report.json"),
        &serde_json::to_string_pretty(&report)?,
    )?;
    Ok(Some(report))
}

/// The jobs on this process's rayon pool, each tried `1 + retries` times.
fn run_local(
    plan: &Plan,
    jobs: &[&Job],
    retries: u32,
    run_job: &(dyn Fn(&Job) -> anyhow::Result<()> + Sync),
) -> anyhow::Result<()> {
    let failures: Vec<String> = jobs
        .par_iter()
        .filter_map(|job| {
            let mut last = None;
            for attempt in 1..=1 + retries {
                let t = Instant::now();
                match run_job(job) {
                    Ok(()) => {
                        let record = JobRecord {
                            id: job.id.clone(),
                            argv: job.argv.clone(),
                            worker: "local".into(),
                            attempts: attempt,
                            wall_s: t.elapsed().as_secs_f64(),
                            cpu_s: None,
                            max_rss_kib: None,
                        };
                        return serde_json::to_string_pretty(&record)
                            .map_err(anyhow::Error::from)
                            .and_then(|text| write_atomic(&plan.marker(job), &text))
                            .err()
                            .map(|e| format!("{}: {e:#}", job.id));
                    }
                    Err(e) => {
                        tracing::warn!("job {} attempt {attempt} failed: {e:#}", job.id);
                        last = Some(e);
                    }
                }
            }
            last.map(|e| format!("{} ({} attempts): {e:#}", job.id, 1 + retries))
        })
        .collect();
    anyhow::ensure!(
        failures.is_empty(),
        "{} jobs failed: {}",
        failures.len(),
        failures.join("; ")
    );
    Ok(())
}

/// The jobs on the Dask cluster at `address`, by the driver.
fn run_dask(plan: &Plan, jobs: &[&Job], args: &CampaignArgs, address: &str) -> anyhow::Result<()> {
    let dir = plan.dir();
    let driver = dir.join("dask_driver.py");
    write_atomic(&driver, DASK_DRIVER)?;
    let ids: Vec<&str> = jobs.iter().map(|j| j.id.as_str()).collect();
    let pending = dir.join("pending.json");
    write_atomic(&pending, &serde_json::to_string(&ids)?)?;
    let binary = match &args.worker_binary {
        Some(b) => b.clone(),
        None => std::env::current_exe().context("finding this excavator-ctl's path")?,
    };
    let status = Command::new("python3")
        .arg(&driver)
        .arg("--scheduler")
        .arg(address)
        .arg("--plan")
        .arg(plan.path())
        .arg("--pending")
        .arg(&pending)
        .arg("--binary")
        .arg(&binary)
        .arg("--retries")
        .arg(args.retries.to_string())
        .arg("--threads-per-job")
        .arg(args.threads_per_job.to_string())
        .status()
        .context("starting the Dask driver (python3 with the distributed package)")?;
    anyhow::ensure!(
        status.success(),
        "the Dask driver ({}) {status}; the jobs that finished are kept: run the command again \
         to resume",
        driver.display()
    );
    Ok(())
}

/// Writes `text` to `path` through a temporary file in the same folder, so a reader (or a job
/// killed mid-write) never leaves a part of it.
///
/// # Errors
/// Creating the folder, writing or renaming.
pub fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}

/// The bytes under `paths` (files, or folders walked), relative to `workdir`.
pub fn bytes_under(workdir: &Path, paths: &[PathBuf]) -> u64 {
    fn walk(p: &Path) -> u64 {
        match std::fs::symlink_metadata(p) {
            Ok(m) if m.is_dir() => std::fs::read_dir(p)
                .map(|d| d.flatten().map(|e| walk(&e.path())).sum())
                .unwrap_or(0),
            Ok(m) => m.len(),
            Err(_) => 0,
        }
    }
    paths.iter().map(|p| walk(&workdir.join(p))).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(id: &str, stage: u32) -> Job {
        Job {
            id: id.into(),
            stage,
            argv: vec!["excavator-ctl".into(), "campaign".into(), id.into()],
            inputs: vec![],
            outputs: vec![PathBuf::from(format!("o/{id}"))],
        }
    }

    /// `CampaignArgs::default()` (what library callers get) is the command line's defaults.
    #[test]
    fn the_default_campaign_options_are_the_command_lines() {
        use clap::Parser as _;
        #[derive(clap::Parser)]
        #[command(no_binary_name = true)]
        struct Cli {
            #[command(flatten)]
            campaign: CampaignArgs,
        }
        let parsed = Cli::try_parse_from(Vec::<String>::new()).unwrap().campaign;
        assert_eq!(parsed, CampaignArgs::default());
    }

    #[test]
    fn executors_parse_and_bad_addresses_are_refused() {
        assert_eq!("local".parse::<Executor>(), Ok(Executor::Local));
        assert_eq!(
            "dask://127.0.0.1:8786".parse::<Executor>(),
            Ok(Executor::Dask {
                address: "tcp://127.0.0.1:8786".into()
            })
        );
        for bad in [
            "ray://h:1",
            "dask://",
            "dask://h",
            "dask://h:0",
            "dask://h:70000",
            "dask://:8786",
            "dask://h;rm -rf /:1",
        ] {
            assert!(bad.parse::<Executor>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_plan_with_a_repeated_id_a_bad_id_or_stages_out_of_order_is_refused() {
        let out = Path::new("o");
        assert!(Plan::new("k", vec![], out, vec![job("a", 0), job("b", 1)]).is_ok());
        assert!(Plan::new("k", vec![], out, vec![job("a", 0), job("a", 0)]).is_err());
        assert!(Plan::new("k", vec![], out, vec![job("a", 1), job("b", 0)]).is_err());
        for bad in ["", "../x", "a/b", ".hidden", "a b"] {
            assert!(
                Plan::new("k", vec![], out, vec![job(bad, 0)]).is_err(),
                "{bad}"
            );
        }
        let mut other = job("c", 0);
        other.argv[0] = "sh".into();
        assert!(Plan::new("k", vec![], out, vec![other]).is_err());
    }

    /// In-process: every job runs once, a failing one is retried and reported, a second run
    /// resumes (runs nothing that is done), and a changed command line runs again.
    #[test]
    fn local_runs_retry_resume_and_rerun_a_changed_job() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let plan = Plan::new(
            "k",
            vec![],
            &out,
            vec![job("a", 0), job("b", 0), job("c", 1)],
        )
        .unwrap();
        let runs = std::sync::Mutex::new(Vec::new());
        let run = |j: &Job| {
            let mut r = runs.lock().unwrap();
            r.push(j.id.clone());
            // `b` fails on its first attempt.
            if j.id == "b" && r.iter().filter(|x| *x == "b").count() == 1 {
                anyhow::bail!("first attempt of b");
            }
            Ok(())
        };
        let args = CampaignArgs::default();
        let report = execute(&plan, &args, &run).unwrap().unwrap();
        assert_eq!((report.jobs, report.ran, report.resumed), (3, 3, 0));
        assert_eq!(report.retried, vec![("b".to_string(), 2)]);
        // Stage 1 after stage 0.
        assert_eq!(runs.lock().unwrap().last().map(String::as_str), Some("c"));
        runs.lock().unwrap().clear();
        let again = execute(&plan, &args, &run).unwrap().unwrap();
        assert_eq!((again.ran, again.resumed), (0, 3));
        assert!(runs.lock().unwrap().is_empty());
        let mut changed = plan.clone();
        changed.jobs[2].argv.push("--more".into());
        let third = execute(&changed, &args, &run).unwrap().unwrap();
        assert_eq!((third.ran, third.resumed), (1, 2));
        assert_eq!(Plan::read(&plan.path()).unwrap(), changed);
    }

    #[test]
    fn a_job_failing_every_attempt_fails_the_campaign_and_keeps_the_others() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let plan = Plan::new("k", vec![], &out, vec![job("a", 0), job("b", 0)]).unwrap();
        let run = |j: &Job| {
            anyhow::ensure!(j.id != "b", "b always fails");
            Ok(())
        };
        let args = CampaignArgs {
            retries: 1,
            ..CampaignArgs::default()
        };
        let e = execute(&plan, &args, &run).unwrap_err().to_string();
        assert!(e.contains("b (2 attempts): b always fails"), "{e}");
        assert!(plan.done(&plan.jobs[0]) && !plan.done(&plan.jobs[1]));
    }
}
