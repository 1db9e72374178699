//! The records of a session folder that several parts of the lab share: the per-dig records of
//! `summary.json` ([`DigRecord`], with the tip paths the plots draw, [`TipPoint`]) and the soil
//! estimator's samples of `soil_samples.json` ([`SoilSamplesFile`]). `demo` writes them, the plots
//! draw them, `model soil-cv` and the experiments read them; this module depends on none of those.

use std::path::Path;

use anyhow::Context as _;
use controller::cycle::{ActionKind, StartPose};
use planner::estimate::SoilSample;
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
    /// The dig number people see, from 1 (`controller::cycle::dig_number`).
    pub const fn number(&self) -> u32 {
        controller::cycle::dig_number(self.index)
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
