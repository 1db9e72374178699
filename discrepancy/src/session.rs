//! Measured sessions: the machine and model files, every dig of session folders read and prepared
//! for the replay, and what an analysis of them gives ([`Analysis`]).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use planner::machine::MachineConfig;

use crate::greybox::PreparedRecord;
use crate::{AnalysisResult, AugmentedModel, read};

/// The outcome of an analysis.
pub struct Analysis {
    /// What the planner's analysis found.
    pub result: AnalysisResult,
    /// The model it started from.
    pub model: AugmentedModel,
    /// The prepared records.
    pub records: Vec<PreparedRecord>,
    /// Sessions left out because they could not be read, with the reason (only when other
    /// sessions could be).
    pub skipped_sessions: Vec<SkippedSession>,
    /// The reference the residuals were judged against (`--reference`).
    pub reference: Option<crate::reference::Reference>,
    /// The verdict against it.
    pub verdict: Option<crate::verdict::Verdict>,
    /// Data-sufficiency and other warnings.
    pub warnings: Vec<String>,
    /// The updated twin: the simulator profile and its gap to the held-out digs (`None` when the
    /// simulator could not be re-run on them: a warning says why).
    pub twin: Option<(crate::twin::TwinProfile, crate::twin::TwinReport)>,
}

/// A session folder left out of an analysis (`report.json`'s `skipped_sessions`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct SkippedSession {
    /// The folder.
    pub session: PathBuf,
    /// Why it could not be read (the error's whole cause chain).
    pub reason: String,
}

/// Loads the machine file or the built-in one.
///
/// # Errors
/// Reading or parsing the file.
pub fn load_machine(path: Option<&Path>) -> anyhow::Result<MachineConfig> {
    Ok(match path {
        Some(p) => MachineConfig::from_toml_file(p)?,
        None => MachineConfig::default_machine()?,
    })
}

/// Loads a model file or the shipped nominal model.
///
/// # Errors
/// Reading or parsing the file.
pub fn load_model(path: Option<&Path>) -> anyhow::Result<AugmentedModel> {
    Ok(match path {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            AugmentedModel::from_json(&text).with_context(|| format!("model {}", p.display()))?
        }
        None => AugmentedModel::nominal()?,
    })
}

/// Reads and prepares every dig of the sessions (dig indices renumbered so they are unique across
/// sessions).
///
/// # Errors
/// Reading a session; a record the model cannot prepare.
pub fn prepare_sessions(
    dirs: &[PathBuf],
    machine: &MachineConfig,
    model: &AugmentedModel,
) -> anyhow::Result<Vec<PreparedRecord>> {
    let (records, skipped) = prepare_readable_sessions(dirs, machine, model)?;
    match skipped.into_iter().next() {
        Some(s) => Err(anyhow::anyhow!(
            "reading session {}: {}",
            s.session.display(),
            s.reason
        )),
        None => Ok(records),
    }
}

/// As [`prepare_sessions`], but a session that cannot be read (a trace without the controller's
/// status, a folder without a trace) is left out and returned with its reason, so one bad folder
/// among many does not lose the others.
///
/// # Errors
/// No session readable (the first one's reason); a record the model cannot prepare.
pub fn prepare_readable_sessions(
    dirs: &[PathBuf],
    machine: &MachineConfig,
    model: &AugmentedModel,
) -> anyhow::Result<(Vec<PreparedRecord>, Vec<SkippedSession>)> {
    let mut records = Vec::new();
    let mut skipped = Vec::new();
    for dir in dirs {
        let digs = match read::read_session(dir, machine) {
            Ok(digs) => digs,
            Err(e) => {
                skipped.push(SkippedSession {
                    session: dir.clone(),
                    reason: format!("{e:#}"),
                });
                continue;
            }
        };
        for mut d in digs {
            d.index = records.len() as u32;
            records.push(PreparedRecord::new(&d, machine, &model.params)?);
        }
    }
    if records.is_empty()
        && let Some(s) = skipped.first()
    {
        anyhow::bail!("reading session {}: {}", s.session.display(), s.reason);
    }
    Ok((records, skipped))
}
