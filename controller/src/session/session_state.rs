//! A resumable session: what the session driver saves after every completed action and puts back
//! into a fresh controller (`excavator-ctl run --resume DIR`).
//!
//! The [`SessionDriver`] takes a [`DriverSnapshot`] whenever the work cycle stands between actions
//! (Idle, the finished dig's bookkeeping done, the planner not out) and a new action has completed
//! or been pushed since the last one ([`SessionDriver::checkpoint`]): the work cycle's plan, index,
//! statistics, floor and hardness index; the dead-reckoned pose with the odometry reading it belongs
//! to; the planner's terrain map, state, soil estimate, predefined sequence and position; the
//! driver's counters and soil window. The caller that owns the session folder adds its own records
//! (`R`, e.g. the per-dig records of `summary.json`) and an identity of the machine, bench and
//! configuration, and writes the whole [`SessionState`] with [`crate::session::state_file::save`] (atomic:
//! a process killed at any moment leaves the previous state or the new one).
//!
//! [`load`] treats the file as untrusted input ([`crate::session::state_file::load`]: the file and field of
//! every error) and refuses a state of another format, machine, bench, seed, strategy or
//! configuration, naming the `identity` field that differs.

use std::path::Path;

use serde::{Deserialize, Serialize};

#[cfg(doc)]
use crate::session::driver::SessionDriver;
use crate::session::snapshot::DriverSnapshot;
use crate::session::state_file::{self, FieldError, StateFileError, Validate};

/// The state file's name in the session folder.
pub const STATE_FILE_NAME: &str = "session_state.json";

/// The format of [`SessionState`]; a file of another format is refused.
pub const FORMAT: u32 = 1;

/// What a saved session belongs to: a state is resumed only on the same machine, bench, seed,
/// strategy and configuration. The machine and the configuration are fingerprints
/// ([`fingerprint`]) of their full settings.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionIdentity {
    /// Fingerprint of the machine file.
    pub machine: String,
    /// The bench's name.
    pub bench: String,
    /// The bench's seed.
    pub seed: u64,
    /// `planned`, `predefined` or `fixed`.
    pub strategy: String,
    /// Fingerprint of the controller config (without the dig count), the planner settings and the
    /// Autodig maps.
    pub config: String,
}

impl SessionIdentity {
    /// The first field in which this (saved) identity differs from `current`.
    ///
    /// # Errors
    /// `identity.<field>`: what was saved and what this run has.
    pub fn check(&self, current: &Self) -> Result<(), FieldError> {
        let fields = [
            ("machine", &self.machine, &current.machine),
            ("bench", &self.bench, &current.bench),
            ("strategy", &self.strategy, &current.strategy),
            ("config", &self.config, &current.config),
        ];
        for (name, saved, now) in fields {
            if saved != now {
                return Err(FieldError::new(
                    format!("identity.{name}"),
                    format!("saved by a session with {saved:?}, this run has {now:?}"),
                ));
            }
        }
        if self.seed != current.seed {
            return Err(FieldError::new(
                "identity.seed",
                format!(
                    "saved by a session with seed {}, this run has {}",
                    self.seed, current.seed
                ),
            ));
        }
        Ok(())
    }
}

/// A short fingerprint of `value`'s settings: FNV-1a (64 bit) of its JSON, hex. JSON of the same
/// value is the same bytes (fields in declaration order, shortest round-trip floats), so equal
/// settings give equal fingerprints.
#[must_use]
pub fn fingerprint<T: Serialize + ?Sized>(value: &T) -> String {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0100_0000_01b3;
    let bytes = serde_json::to_vec(value).unwrap_or_default();
    let hash = bytes
        .iter()
        .fold(OFFSET, |h, b| (h ^ u64::from(*b)).wrapping_mul(PRIME));
    format!("{hash:016x}")
}

/// A saved session: format, identity, the driver's state and the caller's records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionState<R> {
    /// [`FORMAT`].
    pub format: u32,
    /// What it belongs to.
    pub identity: SessionIdentity,
    /// The session driver.
    pub driver: DriverSnapshot,
    /// The caller's records (e.g. the per-dig records of `summary.json`).
    pub records: R,
}

impl<R: Validate> Validate for SessionState<R> {
    fn validate(&self) -> Result<(), FieldError> {
        if self.format != FORMAT {
            return Err(FieldError::new(
                "format",
                format!("format {} (this controller reads {FORMAT})", self.format),
            ));
        }
        self.driver.validate().map_err(|e| e.within("driver"))?;
        self.records.validate().map_err(|e| e.within("records"))
    }
}

/// Loads the state in `path` and checks that it belongs to `identity` (module docs).
///
/// # Errors
/// [`StateFileError`] naming the file and the field: unreadable, not JSON, a field missing,
/// mistyped or out of range, another format, or an `identity` field that differs.
pub fn load<R>(path: &Path, identity: &SessionIdentity) -> Result<SessionState<R>, StateFileError>
where
    R: serde::de::DeserializeOwned + Validate,
{
    let state: SessionState<R> = state_file::load(path)?;
    state
        .identity
        .check(identity)
        .map_err(|e| StateFileError::field(path, e))?;
    Ok(state)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::snapshot::{PlannedSnapshot, StepSnapshot, Strategy, TerrainSnapshot};
    use crate::step::cycle::{Action, CycleSnapshot};
    use planner::cleanup::{FloorEstimate, FloorPolicy};
    use planner::kinematics::MachinePose;
    use planner::plan::PlannerState;
    use planner::terrain::TerrainGrid;

    /// The records of a caller: none.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    struct NoRecords {}

    impl Validate for NoRecords {
        fn validate(&self) -> Result<(), FieldError> {
            Ok(())
        }
    }

    fn identity() -> SessionIdentity {
        SessionIdentity {
            machine: fingerprint("machine"),
            bench: "bench".into(),
            seed: 1,
            strategy: "planned".into(),
            config: fingerprint("config"),
        }
    }

    fn state() -> SessionState<NoRecords> {
        let mut grid = TerrainGrid::new_unknown(0.0, -2.0, 0.5, 4, 3).unwrap();
        grid.set_cell(1, 2, Some(1.25)).unwrap();
        SessionState {
            format: FORMAT,
            identity: identity(),
            driver: DriverSnapshot {
                cycle: CycleSnapshot {
                    actions: vec![Action::TrackBack { distance_m: 1.3 }],
                    action_index: 1,
                    digs_done: 0,
                    stats: Vec::new(),
                    floor: FloorEstimate::new(FloorPolicy::DetectOnce),
                    hardness_index: 3.0,
                },
                pose: MachinePose::default(),
                odometry_m: Some([-1.3, -1.3]),
                planned: Vec::new(),
                plan_ms: vec![120.0],
                soil_window: Vec::new(),
                track_backs: 1,
                backups: 1,
                predefined_joints: None,
                over: None,
                session: Some(PlannedSnapshot {
                    strategy: Strategy::Planned,
                    planner: PlannerState::default(),
                    terrain: TerrainSnapshot::of(&grid),
                    map_scans: 2,
                    predefined: None,
                    predefined_index: 0,
                    soil_estimate: None,
                    dig_starts: Vec::new(),
                    unconfirmed_digs: Vec::new(),
                    steps: vec![StepSnapshot {
                        action: Action::TrackBack { distance_m: 1.3 },
                        pose: MachinePose::default(),
                    }],
                    finished: false,
                    end_reason: None,
                }),
            },
            records: NoRecords {},
        }
    }

    #[test]
    fn a_saved_state_loads_back_with_its_unknown_map_cells() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(STATE_FILE_NAME);
        state_file::save(&path, &state()).unwrap();
        let back: SessionState<NoRecords> = load(&path, &identity()).unwrap();
        assert_eq!(back, state());
        let grid = back.driver.session.unwrap().terrain.grid().unwrap();
        assert_eq!(grid.cell(1, 2), Some(1.25));
        assert_eq!(grid.cell(0, 0), None);
        assert_eq!(grid.known_cells(), 1);
    }

    #[test]
    fn a_state_of_another_bench_machine_or_config_is_refused_naming_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(STATE_FILE_NAME);
        state_file::save(&path, &state()).unwrap();
        let others = [
            (
                "identity.bench",
                SessionIdentity {
                    bench: "other".into(),
                    ..identity()
                },
            ),
            (
                "identity.machine",
                SessionIdentity {
                    machine: fingerprint("other machine"),
                    ..identity()
                },
            ),
            (
                "identity.config",
                SessionIdentity {
                    config: fingerprint("other config"),
                    ..identity()
                },
            ),
            (
                "identity.seed",
                SessionIdentity {
                    seed: 2,
                    ..identity()
                },
            ),
        ];
        for (field, other) in others {
            match load::<NoRecords>(&path, &other) {
                Err(StateFileError::Field {
                    path: p, field: f, ..
                }) => {
                    assert_eq!((p.as_path(), f.as_str()), (path.as_path(), field));
                }
                r => panic!("{field}: {r:?}"),
            }
        }
    }

    #[test]
    fn a_broken_or_foreign_state_is_refused_naming_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(STATE_FILE_NAME);
        let good = serde_json::to_value(state()).unwrap();
        let mut bad_cells = good.clone();
        bad_cells["driver"]["session"]["terrain"]["heights_m"] = serde_json::json!([1.0]);
        let mut bad_index = good.clone();
        bad_index["driver"]["cycle"]["action_index"] = serde_json::json!(7);
        let mut bad_format = good.clone();
        bad_format["format"] = serde_json::json!(99);
        let mut bad_action = good;
        bad_action["driver"]["cycle"]["actions"][0]["distance_m"] = serde_json::json!("far");
        let cases = [
            (bad_cells, "driver.session.terrain.heights_m"),
            (bad_index, "driver.cycle.action_index"),
            (bad_format, "format"),
            // Internally tagged: serde names the action, not its field.
            (bad_action, "driver.cycle.actions[0]"),
            // A summary.json handed over as a state.
            (
                serde_json::json!({"strategy": "planned", "digs": []}),
                "digs",
            ),
        ];
        for (json, field) in cases {
            std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
            match load::<NoRecords>(&path, &identity()) {
                Err(StateFileError::Field {
                    path: p, field: f, ..
                }) => {
                    assert_eq!((p.as_path(), f.as_str()), (path.as_path(), field));
                }
                r => panic!("{field}: {r:?}"),
            }
        }
    }
}
