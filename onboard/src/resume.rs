//! A resumable `run`: the session folder's part of the saved state ([`RunRecords`]: the records of
//! `summary.json` and `soil_samples.json`, the scan count and the session's time so far), the
//! writer that saves every checkpoint of the session driver off the control loop ([`StateWriter`]),
//! and the trace a resumed session appends to ([`open_trace`]).
//!
//! The driver's checkpoint and these records are written together, as one
//! [`controller::session::session_state::SessionState`] in `session_state.json`, with
//! [`controller::session::state_file::save`] (temp, fsync, rename): a controller killed at any moment leaves
//! the state of the last completed action, and `run --resume DIR` goes on from there. What was
//! written after that checkpoint is not duplicated: the scans are numbered on from the saved count
//! (a later scan file is overwritten by the resumed session's), the records of `summary.json` come
//! from the state, and the trace keeps every frame that was on the bus (the interrupted action's
//! frames, then the resumed session's; a line torn by the kill is cut off).

use std::io::{Read as _, Seek as _};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::thread::JoinHandle;

use anyhow::Context as _;
use controller::session::session_state::{FORMAT, SessionIdentity, SessionState};
use controller::session::snapshot::DriverSnapshot;
use controller::session::state_file::{self, FieldError, Validate, finite};
use firmware_bridge::trace::Recorder;
use serde::{Deserialize, Serialize};

use crate::record::{DigRecord, SoilSamplesFile};

/// The session folder's records in a saved run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunRecords {
    /// The finished digs and cleanups, in order (`summary.json`'s `digs`; without the tip paths,
    /// which only the running process plots).
    pub digs: Vec<DigRecord>,
    /// Their soil samples (`soil_samples.json`).
    pub soil_samples: SoilSamplesFile,
    /// Scans written to `scans/` up to the checkpoint.
    pub scans: usize,
    /// Session time up to the checkpoint, s.
    pub session_time_s: f64,
    /// Wall time up to the checkpoint, s.
    pub wall_time_s: f64,
    /// The session's dig count (`run --digs`; none: until the planner ends the session), which
    /// `--resume` keeps unless `--digs` is given again.
    #[serde(default)]
    pub max_digs: Option<u32>,
}

impl Validate for RunRecords {
    fn validate(&self) -> Result<(), FieldError> {
        for (k, d) in self.digs.iter().enumerate() {
            if d.index as usize != k {
                return Err(FieldError::new(
                    format!("digs[{k}].index"),
                    format!("{} where {k} is next", d.index),
                ));
            }
        }
        finite("session_time_s", self.session_time_s)?;
        if self.max_digs == Some(0) {
            return Err(FieldError::new(
                "max_digs",
                "0: a session digs at least once",
            ));
        }
        finite("wall_time_s", self.wall_time_s)
    }
}

/// The state file of a run.
pub type RunState = SessionState<RunRecords>;

/// The state file in `dir`.
#[must_use]
pub fn state_path(dir: &Path) -> PathBuf {
    dir.join(controller::session::session_state::STATE_FILE_NAME)
}

/// Saves the checkpoints of a session on its own thread, in order, so the control loop never waits
/// for the disk. A checkpoint that finds the queue full (the disk is far behind: checkpoints come
/// one per action, seconds apart) is dropped and counted; the next one carries the session on.
#[derive(Debug)]
pub struct StateWriter {
    tx: Option<SyncSender<Box<RunState>>>,
    thread: Option<JoinHandle<StateWriterStats>>,
    dropped: u64,
}

/// What a [`StateWriter`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StateWriterStats {
    /// States saved.
    pub saved: u64,
    /// States dropped because the queue was full.
    pub dropped: u64,
    /// Saves that failed (each logged); the last error.
    pub failed: u64,
    /// The last failure.
    pub last_error: Option<String>,
}

/// Checkpoints queued for the writer at most.
const STATE_QUEUE: usize = 4;

impl StateWriter {
    /// A writer saving to `path`.
    ///
    /// # Errors
    /// The thread cannot be started.
    pub fn spawn(path: PathBuf) -> anyhow::Result<Self> {
        let (tx, rx) = mpsc::sync_channel::<Box<RunState>>(STATE_QUEUE);
        let thread = std::thread::Builder::new()
            .name("session-state".into())
            .spawn(move || {
                let mut stats = StateWriterStats::default();
                for state in rx {
                    match state_file::save(&path, &*state) {
                        Ok(()) => stats.saved += 1,
                        Err(e) => {
                            tracing::error!(error = %e, "saving the session state");
                            stats.failed += 1;
                            stats.last_error = Some(e.to_string());
                        }
                    }
                }
                stats
            })
            .context("starting the session-state writer")?;
        Ok(Self {
            tx: Some(tx),
            thread: Some(thread),
            dropped: 0,
        })
    }

    /// Queues a checkpoint (never blocks).
    pub fn save(&mut self, state: RunState) {
        let Some(tx) = &self.tx else { return };
        match tx.try_send(Box::new(state)) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.dropped += 1;
                tracing::warn!(
                    dropped = self.dropped,
                    "session state not saved: the writer is behind"
                );
            }
            Err(TrySendError::Disconnected(_)) => {
                self.dropped += 1;
                tracing::error!("session state not saved: the writer is gone");
            }
        }
    }

    /// Waits until every queued checkpoint is on the disk.
    pub fn finish(mut self) -> StateWriterStats {
        self.tx = None;
        let mut stats = self
            .thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default();
        stats.dropped += self.dropped;
        stats
    }
}

/// The checkpoint `driver` of a run, with the records so far.
#[must_use]
pub fn run_state(
    identity: &SessionIdentity,
    driver: DriverSnapshot,
    records: RunRecords,
) -> RunState {
    SessionState {
        format: FORMAT,
        identity: identity.clone(),
        driver,
        records,
    }
}

/// Opens the session's trace: a new file, or (`append`, a resumed session) the end of the existing
/// one, with a line the kill tore cut off. Returns the recorder and the frames already in the file.
///
/// # Errors
/// The file cannot be created, read or cut.
pub fn open_trace(path: &Path, interface: &str, append: bool) -> anyhow::Result<(Recorder, u64)> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    if !append || !path.exists() {
        let r = Recorder::create(path, interface)
            .with_context(|| format!("creating trace {}", path.display()))?;
        return Ok((r, 0));
    }
    let frames = cut_torn_line(path).with_context(|| format!("trace {}", path.display()))?;
    let r = Recorder::append(path, interface)
        .with_context(|| format!("opening trace {}", path.display()))?;
    Ok((r, frames))
}

/// Cuts `path` after its last complete line; returns the complete lines.
fn cut_torn_line(path: &Path) -> std::io::Result<u64> {
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)?;
    let mut lines = 0_u64;
    let mut complete = 0_u64;
    let mut offset = 0_u64;
    let mut buf = vec![0_u8; 1 << 16];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        for (i, b) in buf[..n].iter().enumerate() {
            if *b == b'\n' {
                lines += 1;
                complete = offset + i as u64 + 1;
            }
        }
        offset += n as u64;
    }
    if complete < offset {
        tracing::warn!(
            bytes = offset - complete,
            "the trace ends in a torn line (the controller was killed): cut off"
        );
        f.set_len(complete)?;
        f.seek(std::io::SeekFrom::End(0))?;
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_torn_trace_line_is_cut_and_complete_lines_counted() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("trace.log");
        std::fs::write(
            &path,
            "(0.1) vcan0 123#00 R\n(0.2) vcan0 123#01 T\n(0.3) vca",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(cut_torn_line(&path).ok(), Some(2));
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(text.ends_with("123#01 T\n"), "{text:?}");
        assert_eq!(cut_torn_line(&path).ok(), Some(2));
    }

    /// A record with every float field set from `v` (cycled).
    fn record(v: &[f64]) -> DigRecord {
        let f = |k: usize| v[k % v.len()];
        DigRecord {
            index: 0,
            action: controller::step::cycle::ActionKind::Dig,
            swing_deg: f(0),
            start_pose: None,
            weight_n: Some(f(1)),
            true_payload_kg: f(2),
            time_s: f(3),
            ground_contact_time_s: f(4),
            energy_kj: f(5),
            swept_volume_m3: f(6),
            end_reason: None,
            perception: true,
            quality: Some(f(7)),
            predicted_volume_m3: Some(f(8)),
            predicted_time_s: Some(f(9)),
            predicted_energy_kj: Some(f(10)),
            predicted_min_tip_z_m: Some(f(11)),
            contact_start: Some([f(12), f(13)]),
            min_tip_z_m: Some(f(14)),
            hardness_index: Some(f(15)),
            pose: Some([f(16), f(17), f(18)]),
            planned_start: Some([f(19), f(20), f(21)]),
            map_error_m: Some(f(22)),
            map_bias_at_start_m: Some(f(23)),
            trajectory: Vec::new(),
            section: Vec::new(),
        }
    }

    proptest::proptest! {
        /// A saved record reads back bit for bit (`--resume` continues from exactly what was saved).
        #[test]
        fn saved_records_read_back_bit_identically(
            v in proptest::collection::vec(proptest::num::f64::NORMAL | proptest::num::f64::SUBNORMAL, 24),
        ) {
            let records = RunRecords {
                digs: vec![record(&v)],
                session_time_s: v[0].abs(),
                wall_time_s: v[1].abs(),
                ..RunRecords::default()
            };
            let text = serde_json::to_string(&records).unwrap_or_default();
            let back: RunRecords = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"));
            let bits = |r: &RunRecords| serde_json::to_value(r).map(|v| v.to_string()).unwrap_or_default();
            proptest::prop_assert_eq!(bits(&back), bits(&records));
            proptest::prop_assert_eq!(back.digs[0].predicted_energy_kj.map(f64::to_bits), records.digs[0].predicted_energy_kj.map(f64::to_bits));
            proptest::prop_assert_eq!(back.session_time_s.to_bits(), records.session_time_s.to_bits());
        }
    }

    #[test]
    fn records_with_a_gap_are_refused_by_index() {
        let mut r = RunRecords::default();
        assert_eq!(r.validate(), Ok(()));
        r.session_time_s = f64::NAN;
        assert_eq!(
            r.validate().map_err(|e| e.field),
            Err("session_time_s".to_owned())
        );
    }
}
