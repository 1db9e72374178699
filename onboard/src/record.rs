//! The records of a session folder: the per-dig records of `summary.json` ([`DigRecord`], with the
//! tip paths the plots draw, [`TipPoint`]), the soil estimator's samples of `soil_samples.json`
//! ([`SoilSamplesFile`]), and [`SessionRecords`], which keeps them from the session driver's events
//! as `run` and `demo` go. `demo` adds the simulated world's truth through [`Truth`]; a session on a
//! machine has none.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use controller::session::driver::{SessionDriver, SessionEvent};
use controller::session::planned::PlannedSession;
use controller::session::snapshot::PlannedDig;
use controller::step::cycle::{Action, ActionKind, DigStats, Phase, StartPose};
use controller::step::node::ControllerNode;
use planner::estimate::SoilSample;
use planner::kinematics::MachinePose;
use planner::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};

/// A point of a tip trajectory in the digging plane (base frame), m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TipPoint {
    /// Distance from the swing axis, m.
    pub x_m: f64,
    /// Height above the ground plane, m.
    pub z_m: f64,
}

/// One dig (or cleanup) of the session, as written to `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigRecord {
    /// The dig's index in the session, from 0 (`summary.md` shows [`DigRecord::number`]).
    pub index: u32,
    /// `dig` or `cleanup`.
    pub action: ActionKind,
    /// Swing angle of the digging plane, degrees.
    pub swing_deg: f64,
    /// The start pose of the action (tip pose or joints; degrees).
    pub start_pose: Option<StartPose>,
    /// Weight of the material from the static estimate after Capture, N (thesis 6.1).
    pub weight_n: Option<f64>,
    /// The simulator's true payload at the end of the dig, kg (for comparison with `weight_n`).
    pub true_payload_kg: f64,
    /// From the start of Boom-Down (or of the cleanup) to the end of Capture, s.
    pub time_s: f64,
    /// Time the tip was below the pre-dig terrain, s.
    pub ground_contact_time_s: f64,
    /// Integral of |cylinder force x displacement|, kJ (thesis 6.1).
    pub energy_kj: f64,
    /// Volume swept over the cutting edge (3.2), m^3.
    pub swept_volume_m3: f64,
    /// Why Autodig ended (`Debug` of the planner's end reason).
    pub end_reason: Option<String>,
    /// Whether the perception enhancements were active.
    pub perception: bool,
    /// The planner's predicted Fig. 46 quality of the chosen dig (planned digs only).
    #[serde(default)]
    pub quality: Option<f64>,
    /// The planner's predicted swept volume of the chosen dig, m^3 (planned digs only).
    #[serde(default)]
    pub predicted_volume_m3: Option<f64>,
    /// The planner's predicted dig time, s (planned digs only).
    #[serde(default)]
    pub predicted_time_s: Option<f64>,
    /// The planner's predicted dig energy, kJ (planned digs only).
    #[serde(default)]
    pub predicted_energy_kj: Option<f64>,
    /// The lowest tip height the dig model predicted, base frame, m (planned digs only).
    #[serde(default)]
    pub predicted_min_tip_z_m: Option<f64>,
    /// Where the bucket met the terrain: the first tip point of the action below the true pre-dig
    /// surface, `(r, z)` in the base frame, m.
    #[serde(default)]
    pub contact_start: Option<[f64; 2]>,
    /// The lowest tip height of the executed action, base frame, m.
    #[serde(default)]
    pub min_tip_z_m: Option<f64>,
    /// Autodig's soil hardness index for this dig.
    #[serde(default)]
    pub hardness_index: Option<f64>,
    /// The machine's dead-reckoned world pose `[x, y, heading]` (m, m, rad) during the dig.
    #[serde(default)]
    pub pose: Option<[f64; 3]>,
    /// The planner's start tip `[r, z, bucket_abs_deg]` in the base frame (planned digs; the
    /// bucket is brought above it and Boom-Down lowers it there).
    #[serde(default)]
    pub planned_start: Option<[f64; 3]>,
    /// RMS difference between the planner's terrain map and the true terrain along the digging plane
    /// (r 3 to 10 m) at the start of the dig, m (planned and predefined strategies).
    #[serde(default)]
    pub map_error_m: Option<f64>,
    /// Mean of (planner's map - true terrain) along the digging plane over the stretch the bucket
    /// sweeps, from 1.5 m inside the planned start to 0.2 m beyond it, m (planned digs; positive:
    /// the map shows material that is not there).
    #[serde(default)]
    pub map_bias_at_start_m: Option<f64>,
    /// The tip trajectory during the dig, base frame.
    #[serde(skip)]
    pub trajectory: Vec<TipPoint>,
    /// The true terrain along the digging plane before the dig, `(r, z)` in the base frame.
    #[serde(skip)]
    pub section: Vec<TipPoint>,
}

impl DigRecord {
    /// The dig number people see, from 1 (`controller::step::cycle::dig_number`).
    pub const fn number(&self) -> u32 {
        controller::step::cycle::dig_number(self.index)
    }
}

/// The soil samples of one dig (an element of `soil_samples.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SoilDigSamples {
    /// The dig's index in `summary.json`'s `digs`.
    pub index: u32,
    /// Its samples in time order: `Gamma` and the measured tip force (base frame).
    pub samples: Vec<SoilSample>,
}

/// `soil_samples.json` as `demo` writes it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SoilSamplesFile {
    /// Per dig with samples, in dig order.
    pub digs: Vec<SoilDigSamples>,
}

impl SoilSamplesFile {
    /// Reads and checks a `soil_samples.json`.
    ///
    /// # Errors
    /// The file cannot be read, is not a samples file, or holds no dig with samples.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let file: Self = serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: not a soil_samples.json", path.display()))?;
        anyhow::ensure!(
            file.digs.iter().any(|d| !d.samples.is_empty()),
            "{}: no dig with soil samples (a `demo --strategy planned|predefined` session writes them)",
            path.display()
        );
        Ok(file)
    }
}

/// The simulated world's truth that `demo` adds to each dig's record (a session on a machine has
/// none).
pub trait Truth {
    /// The true terrain along the digging plane at `swing_rad` (base frame `(r, z)`).
    fn section(&self, swing_rad: f64) -> Vec<TipPoint>;
    /// The true mass in the bucket, kg.
    fn payload_kg(&self) -> f64;
}

/// A dig's record as it begins: the action, the planner's prediction, and with the simulator at hand
/// its truth (the terrain along the digging plane, the map's error against it).
fn begin_record(
    node: &ControllerNode,
    truth: Option<&dyn Truth>,
    session: Option<&PlannedSession>,
    info: &PlannedDig,
    pose: MachinePose,
    done: usize,
) -> DigRecord {
    let action = node.action().copied();
    let swing_rad = node.state().swing_rad;
    let truth = truth.map_or_else(Vec::new, |t| t.section(swing_rad));
    let map_error_m = session.and_then(|s| {
        let errs: Vec<f64> = truth
            .iter()
            .filter(|p| (3.0..=10.0).contains(&p.x_m))
            .filter_map(|p| {
                let [x, y, _] = pose.world_from_base(swing_rad, p.x_m, 0.0);
                s.terrain()
                    .height_at(x, y)
                    .ok()
                    .map(|h| (h - p.z_m).powi(2))
            })
            .collect();
        (!errs.is_empty()).then(|| (errs.iter().sum::<f64>() / errs.len() as f64).sqrt())
    });
    let map_bias_at_start_m = match (session, info.start) {
        (Some(s), Some([r_start, ..])) => {
            let errs: Vec<f64> = truth
                .iter()
                .filter(|p| (r_start - 1.5..=r_start + 0.2).contains(&p.x_m))
                .filter_map(|p| {
                    let [x, y, _] = pose.world_from_base(swing_rad, p.x_m, 0.0);
                    s.terrain().height_at(x, y).ok().map(|h| h - p.z_m)
                })
                .collect();
            (!errs.is_empty()).then(|| errs.iter().sum::<f64>() / errs.len() as f64)
        }
        _ => None,
    };
    DigRecord {
        index: u32::try_from(done).unwrap_or(u32::MAX),
        action: action.map_or(ActionKind::Dig, |a| a.kind()),
        swing_deg: swing_rad.to_degrees(),
        start_pose: match action {
            Some(Action::Dig { start, .. } | Action::Cleanup { start, .. }) => Some(start),
            _ => None,
        },
        weight_n: None,
        true_payload_kg: 0.0,
        time_s: 0.0,
        ground_contact_time_s: 0.0,
        energy_kj: 0.0,
        swept_volume_m3: 0.0,
        end_reason: None,
        perception: false,
        quality: info.quality,
        predicted_volume_m3: info.volume_m3,
        predicted_time_s: info.time_s,
        predicted_energy_kj: info.energy_kj,
        predicted_min_tip_z_m: info.min_tip_z_m,
        contact_start: None,
        min_tip_z_m: None,
        hardness_index: Some(node.cycle().hardness_index()),
        pose: Some([pose.x_m, pose.y_m, pose.heading_rad]),
        planned_start: info.start,
        map_error_m,
        map_bias_at_start_m,
        trajectory: Vec::new(),
        section: truth,
    }
}

/// A dig's record at its end: the controller's statistics and the tip path.
fn finish_record(c: &mut DigRecord, d: &DigStats, tip_path: &[(f64, f64)]) {
    c.trajectory = tip_path
        .iter()
        .map(|&(x_m, z_m)| TipPoint { x_m, z_m })
        .collect();
    c.index = d.index;
    c.action = d.action;
    c.swing_deg = d.swing_rad.to_degrees();
    c.weight_n = d.weight_n;
    c.time_s = d.time_s;
    c.ground_contact_time_s = d.ground_contact_time_s;
    c.energy_kj = d.energy_kj();
    c.swept_volume_m3 = d.swept_volume_m3;
    c.end_reason = d.end_reason.map(|r| format!("{r:?}"));
    c.perception = d.perception;
    c.min_tip_z_m = c
        .trajectory
        .iter()
        .map(|p| p.z_m)
        .filter(|z| z.is_finite())
        .reduce(f64::min);
    c.contact_start = c.trajectory.iter().find_map(|p| {
        let below = c
            .section
            .iter()
            .min_by(|a, b| (a.x_m - p.x_m).abs().total_cmp(&(b.x_m - p.x_m).abs()))
            .is_some_and(|s| (s.x_m - p.x_m).abs() < 0.05 && p.z_m < s.z_m - 0.02);
        below.then_some([p.x_m, p.z_m])
    });
}

/// The true terrain after some digs (Fig. 55), with the machine's pose then.
#[derive(Debug, Clone)]
pub struct BenchSnapshot {
    /// Digs done.
    pub digs: usize,
    /// Track backs done.
    pub backups: usize,
    /// The simulator's terrain.
    pub terrain: TerrainGrid,
    /// The machine's true world pose `[x, y, heading]`.
    pub pose: [f64; 3],
}

/// The records of a session as it runs, from the session driver's events: the scans written to
/// `scans/`, one [`DigRecord`] per dig and cleanup, and their soil samples. `demo` and `run` keep
/// them alike; `demo` adds the simulator's truth.
#[derive(Debug)]
pub struct SessionRecords {
    scans_dir: PathBuf,
    /// Scans written.
    pub scans: usize,
    /// Finished digs and cleanups.
    pub records: Vec<DigRecord>,
    current: Option<DigRecord>,
    /// Every dig's soil samples (4.3.5), for `soil_samples.json` and `model soil-cv`.
    pub soil_samples: SoilSamplesFile,
}

impl SessionRecords {
    /// Records whose scans go to `scans_dir` (created by the caller).
    #[must_use]
    pub fn new(scans_dir: PathBuf) -> Self {
        Self {
            scans_dir,
            scans: 0,
            records: Vec::new(),
            current: None,
            soil_samples: SoilSamplesFile::default(),
        }
    }

    /// Takes one event of `driver` for `node`, with the simulator's truth when `truth` is given.
    /// Returns whether a dig or cleanup finished.
    ///
    /// # Errors
    /// Writing a scan.
    pub fn on_event(
        &mut self,
        node: &ControllerNode,
        driver: &SessionDriver,
        truth: Option<&dyn Truth>,
        event: &SessionEvent,
    ) -> anyhow::Result<bool> {
        match event {
            SessionEvent::Scanned(scan) => {
                let path = self.scans_dir.join(format!("scan_{:04}.json", self.scans));
                std::fs::write(&path, serde_json::to_vec(scan)?)
                    .with_context(|| format!("writing {}", path.display()))?;
                self.scans += 1;
            }
            SessionEvent::PhaseChanged { to, .. } => {
                if *to == Phase::Weigh
                    && let (Some(c), Some(t)) = (&mut self.current, truth)
                {
                    c.true_payload_kg = t.payload_kg();
                }
            }
            SessionEvent::DigStarted { planned, pose } => {
                self.current = Some(begin_record(
                    node,
                    truth,
                    driver.session(),
                    planned,
                    *pose,
                    self.records.len(),
                ));
            }
            SessionEvent::DigFinished {
                index,
                tip_path,
                soil_samples,
            } => {
                let (Some(mut c), Some(d)) = (self.current.take(), node.statistics().get(*index))
                else {
                    return Ok(false);
                };
                finish_record(&mut c, d, tip_path);
                if !soil_samples.is_empty() {
                    self.soil_samples.digs.push(SoilDigSamples {
                        index: c.index,
                        samples: soil_samples.clone(),
                    });
                }
                self.records.push(c);
                return Ok(true);
            }
        }
        Ok(false)
    }
}
