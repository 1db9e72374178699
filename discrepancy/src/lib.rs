//! Model-discrepancy workflow: find where the model and the measurements disagree, name the
//! missing physical effect, add it to the model and show the gap shrink.
//!
//! Grey-box system identification in the spirit of residual analysis (MATLAB's `resid`), sparse term
//! selection and information criteria (BIC), specialised to the excavator's hydraulics and soil. Pure
//! computation: the controller reads traces and writes reports (`excavator-ctl discrepancy`).
//!
//! Layout (data flows top to bottom; each module imports only modules above it):
//! - this module: the measured records ([`Sample`], [`DigRecord`]), 100 Hz samples of one work cycle
//!   with the Autodig stage of every sample;
//! - [`signal`]: the predicted signals ([`Signal`]) and the groups a replay recomputes;
//! - [`effects`]: the candidate-effect library ([`Candidate`]): the effects of the catalogue
//!   [`planner::effects`], which the simulator hides, with how the grey-box model adds each;
//! - [`soil_replay`]: the pre-dig section cut along the measured edge path and the FEE force on it;
//! - [`greybox`]: the physical replay model ([`GreyBoxParams`], the nominal model the project ships in
//!   `config/nominal_greybox.json`) and its augmentation by named effects ([`Augmentation`]); it replays
//!   a record from the measured inputs and predicts cylinder velocities (Eq. 1 orifices), pump pressures
//!   (open-centre flow balance), cylinder forces (Eq. 3 with Appendix gravity and inertia) and the soil
//!   force on the bucket (FEE, Eqs. 14-18);
//! - [`parameters`]: the machine's own parameters as candidates (parameter drift), derived from the
//!   fields of its machine file that the grey-box parameters come from;
//! - [`stats`]: residuals per signal, stage and operating regime, whiteness and input cross-correlation;
//! - [`fit`]: bounded 1-D fits of each candidate on training digs, held-out BIC scoring, greedy forward
//!   selection and the uncertainty from the cost curvature;
//! - [`model`]: the augmented model file ([`AugmentedModel`]), and the grey-box actuator that implements
//!   [`planner::dig_model::ActuatorDynamics`] so the planner's dig model runs with it;
//! - [`read`] and [`session`]: session folders (`trace.log` + `scans/`) -> prepared records per dig;
//! - [`sufficiency`]: whether the sessions hold enough completed digs and samples to name anything;
//! - [`mod@reference`] and [`verdict`]: what "expected" is (the residual structure of sessions declared
//!   healthy) and every signal judged against it: expected, named, partly explained, unexplained;
//! - [`term`]: a new term suggested for a signal nothing explains (ensemble SINDy on a library of
//!   physical regressors);
//! - [`twin`]: the named effects and parameters as a simulator profile (machine file and effects),
//!   and the simulator's gap to the held-out digs before and after;
//! - [`report`]: `report.json`, `report.md`, the figures and `model.json` of an analysis;
//! - [`analysis`], [`record`], [`eval`], [`command`]: `excavator-ctl discrepancy analyse`,
//!   `record-reference` (the built-in reference of the default machine), `eval` and `bench`, and
//!   the subcommand dispatch.

pub mod analysis;
pub mod command;
pub mod effects;
pub mod eval;
pub mod fit;
pub mod fleet;
pub mod greybox;
pub mod model;
pub mod parameters;
pub mod plant;
pub mod read;
pub mod record;
pub mod reference;
pub mod report;
pub mod session;
pub mod signal;
pub mod soil_replay;
pub mod stats;
pub mod sufficiency;
pub mod term;
pub mod twin;
pub mod verdict;

pub use effects::Candidate;
pub use fit::{AnalysisConfig, AnalysisResult, NamedEffect, analyse};
pub use greybox::{
    Augmentation, GreyBoxParams, Signal, VELOCITY_PREFILTER_HALF, prefilter_velocities,
};
pub use model::{AugmentedModel, GreyBoxActuator};

use planner::terrain::SectionProfile;

/// Errors of the discrepancy workflow.
#[derive(Debug, thiserror::Error)]
pub enum DiscrepancyError {
    /// Not enough data to fit or score.
    #[error("not enough data: {0}")]
    NotEnoughData(String),
    /// A parameter or record value is not finite or out of range.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// The model file could not be parsed or has the wrong format.
    #[error("model file: {0}")]
    ModelFile(String),
    /// The machine geometry.
    #[error("kinematics: {0}")]
    Kinematics(#[from] planner::kinematics::KinematicsError),
    /// The machine description.
    #[error("machine: {0}")]
    Machine(String),
    /// Building the planner's dig model.
    #[error("dig model: {0}")]
    DigModel(#[from] planner::dig_model::DigModelError),
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, DiscrepancyError>;

/// The control period of the records, s ([`firmware_bridge::dbc::CONTROL_PERIOD`], 100 Hz).
pub const PERIOD_S: f64 = firmware_bridge::dbc::CONTROL_PERIOD.as_secs_f64();

/// Autodig stage of a sample (from the controller's `ControllerStatus`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum StageTag {
    /// Not in Autodig (swinging, dumping, returning, idle, cleanup waypoints).
    #[default]
    Outside,
    /// Boom-Down.
    BoomDown,
    /// Pre-Dig.
    PreDig,
    /// Dig.
    Dig,
    /// Capture.
    Capture,
}

impl StageTag {
    /// Every tag, in report order.
    pub const ALL: [StageTag; 5] = [
        StageTag::Outside,
        StageTag::BoomDown,
        StageTag::PreDig,
        StageTag::Dig,
        StageTag::Capture,
    ];

    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            StageTag::Outside => "outside_autodig",
            StageTag::BoomDown => "boom_down",
            StageTag::PreDig => "pre_dig",
            StageTag::Dig => "dig",
            StageTag::Capture => "capture",
        }
    }

    /// True in the stages where the bucket is in the soil.
    pub fn in_soil(self) -> bool {
        matches!(self, StageTag::PreDig | StageTag::Dig | StageTag::Capture)
    }
}

/// What the machine is doing in a sample, as far as the loads are concerned.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum LoadTag {
    /// Empty bucket in free air (returning, swinging to the dig, Boom-Down before contact): the
    /// cylinder forces are gravity, inertia and friction only.
    #[default]
    EmptyFreeAir,
    /// Bucket in the soil (Autodig Pre-Dig, Dig, Capture; cleanup).
    InSoil,
    /// Carrying or dumping a payload of unknown mass.
    Loaded,
    /// The work cycle's Weigh after a dig: valves neutral, the loaded implement held up in the air
    /// (briefly lifted if the ground carried it) while the controller averages its static payload
    /// estimate.
    Weighing,
    /// An empty bucket outside Autodig within [`read::GROUND_CLEARANCE_M`] of the ground the last
    /// scan saw: it may rest on the ground or drag through a pile, which then carries part of the
    /// links' weight or pushes on the bucket, so its cylinder forces are not free-air forces.
    NearGround,
}

/// One 100 Hz sample of a measured trace, aligned at the resolver frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Session time, s (a trace's timestamps through `lab::demo::trace_time_base`, the scans' time).
    pub time_s: f64,
    /// Valve commands `[boom, stick, bucket]` in force from this sample to the next, `[-1, 1]`.
    pub command: [f64; 3],
    /// Swing valve command, `[-1, 1]`.
    pub swing_command: f64,
    /// Measured joint angles `[boom, stick, bucket]`, rad.
    pub angles_rad: [f64; 3],
    /// Measured joint rates, rad/s.
    pub rates_rad_per_s: [f64; 3],
    /// Measured swing rate, rad/s.
    pub swing_rate_rad_per_s: f64,
    /// Measured swing angle, rad (the digging plane's azimuth is the machine heading plus it).
    pub swing_rad: f64,
    /// Measured head pressures, Pa.
    pub head_pa: [f64; 3],
    /// Measured rod pressures, Pa.
    pub rod_pa: [f64; 3],
    /// Measured pump pressures, Pa.
    pub pump_pa: [f64; 2],
    /// Autodig stage.
    pub stage: StageTag,
    /// Load situation.
    pub load: LoadTag,
    /// Swept volume the controller reported for this dig so far, m^3 (0 outside Autodig).
    pub swept_volume_m3: f64,
    /// The controller reported the Track activity: the machine base moves.
    pub tracking: bool,
}

/// One work cycle of a measured trace (the samples of one dig index: approach, Autodig, swing to the
/// dump, dump, return), with the terrain section along its digging plane before the dig.
#[derive(Debug, Clone)]
pub struct DigRecord {
    /// Dig index from the controller's status.
    pub index: u32,
    /// Samples at 100 Hz in time order.
    pub samples: Vec<Sample>,
    /// Terrain section along the digging plane from the last scan before the dig, base frame.
    pub section: Option<SectionProfile>,
    /// Sections parallel to it from the same scan, `(lateral offset m, section)` (left positive):
    /// the terrain beside the cut, where a full bucket's spill spreads.
    pub lanes: Vec<(f64, SectionProfile)>,
}

impl DigRecord {
    /// Checks that the record is usable: at least 100 samples, all finite, times increasing.
    ///
    /// # Errors
    /// [`DiscrepancyError::NotEnoughData`] or [`DiscrepancyError::Invalid`].
    pub fn validate(&self) -> Result<()> {
        if self.samples.len() < 100 {
            return Err(DiscrepancyError::NotEnoughData(format!(
                "dig {} has {} samples (< 100)",
                self.index,
                self.samples.len()
            )));
        }
        for (k, s) in self.samples.iter().enumerate() {
            let finite = s
                .command
                .iter()
                .chain(&s.angles_rad)
                .chain(&s.rates_rad_per_s)
                .chain(&s.head_pa)
                .chain(&s.rod_pa)
                .chain(&s.pump_pa)
                .chain([&s.time_s, &s.swing_command, &s.swing_rate_rad_per_s])
                .all(|v| v.is_finite());
            if !finite {
                return Err(DiscrepancyError::Invalid(format!(
                    "dig {} sample {k} is not finite",
                    self.index
                )));
            }
            if k > 0 && s.time_s <= self.samples[k - 1].time_s {
                return Err(DiscrepancyError::Invalid(format!(
                    "dig {} sample {k}: time does not increase",
                    self.index
                )));
            }
        }
        Ok(())
    }
}
