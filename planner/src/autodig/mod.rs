//! Autodig: the pressure-driven digging state machine of thesis 3.1 (Figs. 9-11) with the perception
//! enhancements of 3.2.
//!
//! A dig runs through [`Stage::BoomDown`], [`Stage::PreDig`], [`Stage::Dig`] and [`Stage::Capture`] to
//! [`Stage::Done`]. Joint angles decide when a stage ends; cylinder pressures, through the maps of
//! [`AutodigMaps`] (one curve set per soil hardness index, loaded from `config/autodig_maps.toml`), decide
//! the commands within Pre-Dig and Dig. The maps and their loading are in `maps`; this module is the
//! state machine.
//!
//! [`Autodig::step`] is synchronous, pure and clock-agnostic (`now_s` comes from the caller), does not
//! allocate, and never panics: the controller on CAN, the simulator tests and the planner's dig model run
//! the very same code. Invalid inputs give an [`AutodigError`]; the caller then sends [`NEUTRAL`].
//!
//! Conventions (docs/ARCHITECTURE.md): joint arrays are `[boom, stick, bucket]`; commands are fractions of
//! maximum cylinder velocity in `[-1, 1]`, positive = extend (boom up, stick in, bucket curl); absolute
//! angles are the plain, unwrapped sums `stick_abs = boom + stick`, `bucket_abs = boom + stick + bucket`.
//!
//! Map pressures are "percent of relief" of the **head** port of the cylinder named by the map: every map
//! input is the load of a cylinder pushing toward extension (bucket curling, stick pulling in, boom
//! lifting), which the head port carries. See docs/autodig.md.

use crate::input_check::{InputError, check, check_port_pressures};
use crate::kinematics::Joint;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

mod maps;

pub use maps::{AutodigMaps, BUILTIN_MAPS_TOML, Curve, CurveSet, MapKind, MapsError};

/// Neutral implement command `[boom, stick, bucket]`: what to send on any error.
pub const NEUTRAL: [f64; 3] = [0.0; 3];

/// Largest plausible joint angle magnitude (rad); beyond it the resolver reading is garbage.
const MAX_ANGLE_RAD: f64 = 4.0 * PI;
/// Tolerance on cylinder extension fractions before a reading counts as out of range.
const EXTENSION_SLACK: f64 = 0.1;
/// Plausible magnitude of the perception inputs (m^3, m).
const MAX_PERCEPTION: f64 = 100.0;

/// Autodig stages (Fig. 9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Stage {
    /// Lower the boom until ground contact is detected from the boom pressures.
    BoomDown,
    /// Bucket at 100 % bites in and curls to rho1; boom and stick follow the Fig. 10 maps.
    PreDig,
    /// Stick at 100 % pushes material into the bucket; boom and bucket follow the Fig. 11 maps.
    Dig,
    /// Boom and bucket at 100 %, stick at 0: capture the material and lift the bucket out.
    Capture,
    /// The dig is over; the command is neutral.
    Done,
}

impl Stage {
    const fn slot(self) -> usize {
        match self {
            Stage::BoomDown => 0,
            Stage::PreDig => 1,
            Stage::Dig => 2,
            Stage::Capture => 3,
            Stage::Done => 4,
        }
    }
}

/// Why a stage ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum EndReason {
    /// Boom-Down: boom pressures showed ground contact for the debounce time.
    GroundContact,
    /// Boom-Down: no contact within the timeout; the dig is abandoned.
    BoomDownTimeout,
    /// Pre-Dig: the bucket curled to rho1 (absolute).
    BucketAngleRho1,
    /// Dig (or Pre-Dig, Fig. 9 caption): the stick came in to beta (absolute).
    StickAngleBeta,
    /// Dig: the bucket curled to rho2 (absolute).
    BucketAngleRho2,
    /// Dig, perception enhancement (3.2): swept volume reached capacity x spill allowance.
    SweptVolumeFull,
    /// A cylinder reached the end of its stroke in the direction the stage drives it.
    CylinderLimit(Joint),
    /// Capture: the bucket reached rho3 after the boom condition was already met.
    BucketAngleRho3,
    /// Capture: the boom rose to gamma.
    BoomAngleGamma,
    /// Capture, perception enhancement (3.2): the bucket is above the terrain.
    BucketAboveTerrain,
}

/// Errors of Autodig's configuration and of a control step. Small and `Copy` for the hot path.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum AutodigError {
    /// An input is NaN or infinite.
    #[error("autodig input {input} is not finite")]
    NonFinite {
        /// Name of the input.
        input: &'static str,
    },
    /// An input is finite but outside its plausible range.
    #[error("autodig input {input} = {value} is out of range")]
    OutOfRange {
        /// Name of the input.
        input: &'static str,
        /// The offending value.
        value: f64,
    },
    /// `now_s` is earlier than the previous step's.
    #[error("autodig time went backwards: now {now_s} s < previous {previous_s} s")]
    TimeWentBackwards {
        /// The time passed in.
        now_s: f64,
        /// The previous step's time.
        previous_s: f64,
    },
    /// A configuration value is invalid.
    #[error("autodig config {field}: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong with it.
        reason: &'static str,
    },
}

impl InputError for AutodigError {
    fn non_finite(input: &'static str) -> Self {
        Self::NonFinite { input }
    }
    fn out_of_range(input: &'static str, value: f64) -> Self {
        Self::OutOfRange { input, value }
    }
}

/// Ground-contact detection in Boom-Down (thesis 3.1): the boom head pressure drops and/or the rod
/// pressure rises relative to a baseline measured while the boom lowers freely, held for `debounce_s`
/// so that shaking of the machine is not taken for contact.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactConfig {
    /// Time after entering Boom-Down before the baseline window opens (start-of-motion transient), s.
    /// Default 0.2.
    pub settle_s: f64,
    /// Length of the baseline window (mean head and rod pressure while lowering freely), s. Default 0.3.
    pub baseline_s: f64,
    /// Boom head pressure drop below the baseline that signals contact, Pa. Default 2.5e6.
    pub head_drop_pa: f64,
    /// Boom rod pressure rise above the baseline that signals contact, Pa. Default 2.5e6.
    pub rod_rise_pa: f64,
    /// Require both the head drop and the rod rise (else either one). Default false.
    pub require_both: bool,
    /// How long the contact signature must hold without a break, s. Default 0.15.
    pub debounce_s: f64,
    /// Give up (Done, [`EndReason::BoomDownTimeout`]) after this long in Boom-Down, s. Default 10.
    pub timeout_s: f64,
}

impl Default for ContactConfig {
    fn default() -> Self {
        Self {
            settle_s: 0.2,
            baseline_s: 0.3,
            head_drop_pa: 2.5e6,
            rod_rise_pa: 2.5e6,
            require_both: false,
            debounce_s: 0.15,
            timeout_s: 10.0,
        }
    }
}

/// The perception enhancements of thesis 3.2. When enabled but the per-step input is `None` (no
/// terrain), the plain angle rules apply alone for that step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    /// End Dig when the swept volume reaches `bucket_capacity_m3 * spill_allowance`. Default false.
    pub end_dig_on_swept_volume: bool,
    /// End Capture as soon as the bucket is above the terrain (instead of at gamma). Default false.
    pub end_capture_above_terrain: bool,
    /// Heaped bucket capacity, m^3. Default 1.2.
    pub bucket_capacity_m3: f64,
    /// Overestimate of the capacity that accounts for material spilling off the sides (3.2), >= 1.
    /// Default 1.15.
    pub spill_allowance: f64,
    /// The bucket counts as above the terrain when its depth below it is at most `-margin`, m.
    /// Default 0.0.
    pub above_terrain_margin_m: f64,
    /// While the swept-volume end is active (enabled and the volume known), Pre-Dig and Dig end at
    /// `stick_abs <= stick_limit` instead of at beta (or at beta if that is farther in). Thesis 3.2:
    /// without the enhancements "the stick angle at which digging ends is fixed", so a dig started
    /// close in ends with a small payload; with them the swept volume ends the dig and the payload
    /// stays consistent across the starts (Table 1). The limit only keeps the bucket from coming
    /// under the machine (as the cleanup's stick limit, 3.3). Default -120 deg.
    #[serde(rename = "stick_limit_deg", with = "crate::machine::degrees")]
    pub stick_limit_rad: f64,
}

impl Default for PerceptionConfig {
    fn default() -> Self {
        Self {
            end_dig_on_swept_volume: false,
            end_capture_above_terrain: false,
            bucket_capacity_m3: 1.2,
            spill_allowance: 1.15,
            above_terrain_margin_m: 0.0,
            stick_limit_rad: (-120.0_f64).to_radians(),
        }
    }
}

/// Autodig parameters. Angles are radians in Rust and degrees in TOML/JSON (`beta_deg`, ...).
///
/// The stage-end angles are absolute (to the horizontal) and machine dependent; the defaults suit the
/// default 20-25 t machine's ranges and are meant to be tuned.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutodigConfig {
    /// Dig ends when `stick_abs <= beta` (stick in, near vertical; Table 1 starts at -87..-50 deg).
    /// Default -100 deg.
    #[serde(rename = "beta_deg", with = "crate::machine::degrees")]
    pub beta_rad: f64,
    /// Pre-Dig ends when the bucket has curled to `bucket_abs <= rho1`. Default -80 deg: from an opened
    /// bucket (about -50 deg) the curl bites the edge in, and the stick does the rest in Dig.
    #[serde(rename = "rho1_deg", with = "crate::machine::degrees")]
    pub rho1_rad: f64,
    /// Dig ends when `bucket_abs <= rho2`. Default -180 deg.
    #[serde(rename = "rho2_deg", with = "crate::machine::degrees")]
    pub rho2_rad: f64,
    /// Capture needs `bucket_abs <= rho3` so material stays in during the swing. Default -210 deg.
    #[serde(rename = "rho3_deg", with = "crate::machine::degrees")]
    pub rho3_rad: f64,
    /// Capture (plain) needs `boom >= gamma` so the bucket clears the bench. Default 25 deg.
    #[serde(rename = "gamma_deg", with = "crate::machine::degrees")]
    pub gamma_rad: f64,
    /// Relief pressure of the boom, stick and bucket circuits, Pa: 100 % in the maps. Default 34.3e6 each.
    pub relief_pressure_pa: [f64; 3],
    /// Soil hardness index (fractional allowed; clamped to the maps' range). Default 3.
    pub hardness_index: f64,
    /// Boom command while lowering in Boom-Down, in [-1, 0). Default -0.5.
    pub boom_down_command: f64,
    /// A cylinder is at its stroke limit when its extension fraction is within this of 0 or 1.
    /// Default 0.01.
    pub cylinder_limit_margin: f64,
    /// Capture: while the bucket has not reached rho3 and its head pressure is at least this
    /// percent of relief, the boom keeps lifting even after its own end condition holds. The curl
    /// is then held by soil the pre-dig terrain (perception, 3.2) or gamma does not account for,
    /// such as the material spilled around the edge, and lifting frees it instead of holding the
    /// bucket at relief. 100 turns it off. Default 90.
    pub capture_lift_at_bucket_percent: f64,
    /// Ground-contact detection in Boom-Down.
    pub contact: ContactConfig,
    /// Perception enhancements (3.2).
    pub perception: PerceptionConfig,
}

impl Default for AutodigConfig {
    fn default() -> Self {
        Self {
            beta_rad: (-100.0_f64).to_radians(),
            rho1_rad: (-80.0_f64).to_radians(),
            rho2_rad: (-180.0_f64).to_radians(),
            rho3_rad: (-210.0_f64).to_radians(),
            gamma_rad: 25.0_f64.to_radians(),
            relief_pressure_pa: [34.3e6; 3],
            hardness_index: 3.0,
            boom_down_command: -0.5,
            cylinder_limit_margin: 0.01,
            capture_lift_at_bucket_percent: 90.0,
            contact: ContactConfig::default(),
            perception: PerceptionConfig::default(),
        }
    }
}

impl AutodigConfig {
    /// Parses a config from TOML text (missing fields take their defaults) and validates it.
    ///
    /// # Errors
    /// [`MapsError::Parse`] for bad TOML; validation failures are reported as `Parse` with the
    /// [`AutodigError::InvalidConfig`] text.
    pub fn from_toml_str(text: &str) -> Result<Self, MapsError> {
        let cfg: Self = toml::from_str(text).map_err(|e| MapsError::Parse(e.to_string()))?;
        cfg.validate()
            .map_err(|e| MapsError::Parse(e.to_string()))?;
        Ok(cfg)
    }

    /// Checks ranges and finiteness.
    ///
    /// # Errors
    /// [`AutodigError::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<(), AutodigError> {
        let bad = |field, reason| Err(AutodigError::InvalidConfig { field, reason });
        let angles = [
            ("beta_deg", self.beta_rad),
            ("rho1_deg", self.rho1_rad),
            ("rho2_deg", self.rho2_rad),
            ("rho3_deg", self.rho3_rad),
            ("gamma_deg", self.gamma_rad),
        ];
        for (field, a) in angles {
            if !a.is_finite() || a.abs() > MAX_ANGLE_RAD {
                return bad(field, "must be finite and within +-720 deg");
            }
        }
        if self
            .relief_pressure_pa
            .iter()
            .any(|p| !p.is_finite() || *p <= 0.0)
        {
            return bad("relief_pressure_pa", "must be finite and > 0");
        }
        if !self.hardness_index.is_finite() {
            return bad("hardness_index", "must be finite");
        }
        if !(self.boom_down_command.is_finite()
            && self.boom_down_command < 0.0
            && self.boom_down_command >= -1.0)
        {
            return bad("boom_down_command", "must be in [-1, 0)");
        }
        if !(0.0..0.5).contains(&self.cylinder_limit_margin) {
            return bad("cylinder_limit_margin", "must be in [0, 0.5)");
        }
        if !(self.capture_lift_at_bucket_percent > 0.0
            && self.capture_lift_at_bucket_percent <= 100.0)
        {
            return bad("capture_lift_at_bucket_percent", "must be in (0, 100]");
        }
        let c = &self.contact;
        let times = [
            ("contact.settle_s", c.settle_s),
            ("contact.baseline_s", c.baseline_s),
            ("contact.debounce_s", c.debounce_s),
            ("contact.timeout_s", c.timeout_s),
        ];
        for (field, t) in times {
            if !(t.is_finite() && t >= 0.0) {
                return bad(field, "must be finite and >= 0");
            }
        }
        if !(c.head_drop_pa.is_finite() && c.head_drop_pa > 0.0) {
            return bad("contact.head_drop_pa", "must be finite and > 0");
        }
        if !(c.rod_rise_pa.is_finite() && c.rod_rise_pa > 0.0) {
            return bad("contact.rod_rise_pa", "must be finite and > 0");
        }
        let p = &self.perception;
        if !(p.bucket_capacity_m3.is_finite() && p.bucket_capacity_m3 > 0.0) {
            return bad("perception.bucket_capacity_m3", "must be finite and > 0");
        }
        if !(p.spill_allowance.is_finite() && p.spill_allowance >= 1.0) {
            return bad("perception.spill_allowance", "must be finite and >= 1");
        }
        if !p.above_terrain_margin_m.is_finite() {
            return bad("perception.above_terrain_margin_m", "must be finite");
        }
        if !(p.stick_limit_rad.is_finite() && p.stick_limit_rad.abs() <= MAX_ANGLE_RAD) {
            return bad(
                "perception.stick_limit_deg",
                "must be finite and within +-720 deg",
            );
        }
        Ok(())
    }
}

/// Sensor inputs of one Autodig step. Arrays are `[boom, stick, bucket]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AutodigInputs {
    /// Joint angles `[boom, stick (relative to boom), bucket (relative to stick)]`, rad.
    pub joint_rad: [f64; 3],
    /// Head-port pressures, Pa.
    pub head_pressure_pa: [f64; 3],
    /// Rod-port pressures, Pa.
    pub rod_pressure_pa: [f64; 3],
    /// Cylinder extension fractions, 0 = fully retracted, 1 = fully extended (limit detection).
    pub extension_fraction: [f64; 3],
    /// Perception (3.2): volume swept over the bucket's cutting edge since the dig began, m^3.
    pub swept_volume_m3: Option<f64>,
    /// Perception (3.2): depth of the bucket below the terrain, m; <= 0 means above it.
    pub bucket_depth_m: Option<f64>,
}

impl AutodigInputs {
    /// Absolute stick angle to the horizontal, `boom + stick`, rad (unwrapped).
    pub fn stick_abs_rad(&self) -> f64 {
        self.joint_rad[0] + self.joint_rad[1]
    }

    /// Absolute bucket angle to the horizontal, `boom + stick + bucket`, rad (unwrapped).
    pub fn bucket_abs_rad(&self) -> f64 {
        self.joint_rad[0] + self.joint_rad[1] + self.joint_rad[2]
    }

    fn validate(&self) -> Result<(), AutodigError> {
        const ANGLE: [&str; 3] = ["boom_rad", "stick_rad", "bucket_rad"];
        const EXT: [&str; 3] = [
            "boom extension_fraction",
            "stick extension_fraction",
            "bucket extension_fraction",
        ];
        for j in 0..3 {
            check(ANGLE[j], self.joint_rad[j], -MAX_ANGLE_RAD, MAX_ANGLE_RAD)?;
            check_port_pressures(j, self.head_pressure_pa[j], self.rod_pressure_pa[j])?;
            check(
                EXT[j],
                self.extension_fraction[j],
                -EXTENSION_SLACK,
                1.0 + EXTENSION_SLACK,
            )?;
        }
        if let Some(v) = self.swept_volume_m3 {
            check("swept_volume_m3", v, -MAX_PERCEPTION, MAX_PERCEPTION)?;
        }
        if let Some(d) = self.bucket_depth_m {
            check("bucket_depth_m", d, -MAX_PERCEPTION, MAX_PERCEPTION)?;
        }
        Ok(())
    }
}

/// A stage that ended, and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StageEnd {
    /// The stage that ended.
    pub stage: Stage,
    /// Why it ended.
    pub reason: EndReason,
}

/// Result of one Autodig step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutodigOutput {
    /// Implement command `[boom, stick, bucket]`, each finite in [-1, 1], positive = extend.
    pub command: [f64; 3],
    /// The stage after this step (the command belongs to it).
    pub stage: Stage,
    /// The last stage that ended during this step, if any (several may end in one step).
    pub stage_end: Option<StageEnd>,
    /// Once [`Stage::Done`]: the reason the dig ended (the reason of the last stage that ended).
    pub end_reason: Option<EndReason>,
}

#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct BoomDownState {
    head_sum_pa: f64,
    rod_sum_pa: f64,
    samples: u32,
    contact_since_s: Option<f64>,
}

/// The Autodig state machine. Build one per dig with [`Autodig::new`] or [`Autodig::starting_in`].
#[derive(Debug, Clone, PartialEq)]
pub struct Autodig {
    config: AutodigConfig,
    maps: AutodigMaps,
    hardness: f64,
    stage: Stage,
    stage_start_s: Option<f64>,
    last_now_s: Option<f64>,
    boom_down: BoomDownState,
    capture_bucket_ok: bool,
    ends: [Option<EndReason>; 5],
    last_end: Option<EndReason>,
}

impl Autodig {
    /// A new dig starting in [`Stage::BoomDown`].
    ///
    /// # Errors
    /// [`AutodigError::InvalidConfig`] from [`AutodigConfig::validate`].
    pub fn new(config: AutodigConfig, maps: AutodigMaps) -> Result<Self, AutodigError> {
        Self::starting_in(config, maps, Stage::BoomDown)
    }

    /// A new dig starting in `stage` (cleanup hands over in [`Stage::PreDig`], thesis 3.3).
    ///
    /// # Errors
    /// [`AutodigError::InvalidConfig`] from [`AutodigConfig::validate`].
    pub fn starting_in(
        config: AutodigConfig,
        maps: AutodigMaps,
        stage: Stage,
    ) -> Result<Self, AutodigError> {
        config.validate()?;
        let (lo, hi) = maps.hardness_range();
        let hardness = config.hardness_index.clamp(lo, hi);
        Ok(Self {
            config,
            maps,
            hardness,
            stage,
            stage_start_s: None,
            last_now_s: None,
            boom_down: BoomDownState::default(),
            capture_bucket_ok: false,
            ends: [None; 5],
            last_end: None,
        })
    }

    /// The current stage.
    pub fn stage(&self) -> Stage {
        self.stage
    }

    /// The configuration.
    pub fn config(&self) -> &AutodigConfig {
        &self.config
    }

    /// The maps.
    pub fn maps(&self) -> &AutodigMaps {
        &self.maps
    }

    /// The soil hardness index in use (after clamping to the maps' range).
    pub fn hardness_index(&self) -> f64 {
        self.hardness
    }

    /// Sets the soil hardness index (thesis 5.2: the planner may update its estimate online); clamped
    /// to the maps' range. Returns the index in use.
    ///
    /// # Errors
    /// [`AutodigError::NonFinite`] if `index` is NaN or infinite (the index is left unchanged).
    pub fn set_hardness_index(&mut self, index: f64) -> Result<f64, AutodigError> {
        if !index.is_finite() {
            return Err(AutodigError::NonFinite {
                input: "hardness_index",
            });
        }
        let (lo, hi) = self.maps.hardness_range();
        self.hardness = index.clamp(lo, hi);
        Ok(self.hardness)
    }

    /// Why `stage` ended in this dig, if it has.
    pub fn stage_end_reason(&self, stage: Stage) -> Option<EndReason> {
        self.ends[stage.slot()]
    }

    /// One control step at time `now_s` (any monotonic clock, s). No allocation, no panics.
    ///
    /// # Errors
    /// [`AutodigError::NonFinite`] / [`AutodigError::OutOfRange`] for a bad input and
    /// [`AutodigError::TimeWentBackwards`]: send [`NEUTRAL`]. The state is kept, except that a running
    /// contact debounce restarts, so a later valid step continues the dig.
    pub fn step(
        &mut self,
        inputs: &AutodigInputs,
        now_s: f64,
    ) -> Result<AutodigOutput, AutodigError> {
        if !now_s.is_finite() {
            self.boom_down.contact_since_s = None;
            return Err(AutodigError::NonFinite { input: "now_s" });
        }
        if let Some(previous_s) = self.last_now_s
            && now_s < previous_s
        {
            self.boom_down.contact_since_s = None;
            return Err(AutodigError::TimeWentBackwards { now_s, previous_s });
        }
        if let Err(e) = inputs.validate() {
            self.boom_down.contact_since_s = None;
            return Err(e);
        }
        self.last_now_s = Some(now_s);
        self.stage_start_s.get_or_insert(now_s);

        // Stage ends may cascade within one step (e.g. Pre-Dig starting already past rho1); bounded by
        // the number of stages.
        let mut stage_end = None;
        for _ in 0..5 {
            let Some(reason) = self.check_end(inputs, now_s) else {
                break;
            };
            stage_end = Some(StageEnd {
                stage: self.stage,
                reason,
            });
            self.ends[self.stage.slot()] = Some(reason);
            self.last_end = Some(reason);
            self.stage = self.next_stage(reason);
            self.stage_start_s = Some(now_s);
            self.boom_down = BoomDownState::default();
            self.capture_bucket_ok = false;
        }
        let command = self.command(inputs);
        Ok(AutodigOutput {
            command,
            stage: self.stage,
            stage_end,
            end_reason: if self.stage == Stage::Done {
                self.last_end
            } else {
                None
            },
        })
    }

    fn next_stage(&self, reason: EndReason) -> Stage {
        match (self.stage, reason) {
            (Stage::BoomDown, EndReason::GroundContact) => Stage::PreDig,
            (Stage::BoomDown, _) => Stage::Done,
            (Stage::PreDig, _) => Stage::Dig,
            (Stage::Dig, _) => Stage::Capture,
            (Stage::Capture | Stage::Done, _) => Stage::Done,
        }
    }

    fn at_extend_limit(&self, inputs: &AutodigInputs, joint: Joint) -> bool {
        inputs.extension_fraction[joint.index()] >= 1.0 - self.config.cylinder_limit_margin
    }

    fn at_retract_limit(&self, inputs: &AutodigInputs, joint: Joint) -> bool {
        inputs.extension_fraction[joint.index()] <= self.config.cylinder_limit_margin
    }

    fn pressure_pct(&self, inputs: &AutodigInputs, joint: Joint) -> f64 {
        let j = joint.index();
        (100.0 * inputs.head_pressure_pa[j] / self.config.relief_pressure_pa[j]).clamp(0.0, 100.0)
    }

    /// The end condition of the current stage, if met now. Updates the Boom-Down and Capture memory.
    fn check_end(&mut self, inputs: &AutodigInputs, now_s: f64) -> Option<EndReason> {
        let cfg = &self.config;
        let stick_abs = inputs.stick_abs_rad();
        let bucket_abs = inputs.bucket_abs_rad();
        let beta = self.stick_end_rad(inputs);
        match self.stage {
            Stage::BoomDown => self.check_contact(inputs, now_s),
            // Pre-Dig ends at rho1 (Fig. 9). The Fig. 9 caption also names beta for Pre-Dig; a stick
            // already in at beta ends it too (Dig then ends at once on beta).
            Stage::PreDig => {
                if bucket_abs <= cfg.rho1_rad {
                    Some(EndReason::BucketAngleRho1)
                } else if stick_abs <= beta {
                    Some(EndReason::StickAngleBeta)
                } else if self.at_extend_limit(inputs, Joint::Bucket) {
                    Some(EndReason::CylinderLimit(Joint::Bucket))
                } else {
                    None
                }
            }
            Stage::Dig => {
                let p = &cfg.perception;
                let full = p.bucket_capacity_m3 * p.spill_allowance;
                if p.end_dig_on_swept_volume && inputs.swept_volume_m3.is_some_and(|v| v >= full) {
                    Some(EndReason::SweptVolumeFull)
                } else if stick_abs <= beta {
                    Some(EndReason::StickAngleBeta)
                } else if bucket_abs <= cfg.rho2_rad {
                    Some(EndReason::BucketAngleRho2)
                } else if self.at_extend_limit(inputs, Joint::Stick) {
                    Some(EndReason::CylinderLimit(Joint::Stick))
                } else if self.at_extend_limit(inputs, Joint::Bucket) {
                    Some(EndReason::CylinderLimit(Joint::Bucket))
                } else {
                    None
                }
            }
            Stage::Capture => {
                let bucket_reason = if bucket_abs <= cfg.rho3_rad {
                    Some(EndReason::BucketAngleRho3)
                } else if self.at_extend_limit(inputs, Joint::Bucket) {
                    Some(EndReason::CylinderLimit(Joint::Bucket))
                } else {
                    None
                };
                let boom_reason = self.capture_boom_reason(inputs);
                let bucket_was_ok = self.capture_bucket_ok;
                self.capture_bucket_ok = bucket_reason.is_some();
                match (bucket_reason, boom_reason) {
                    // Report whichever condition completed last.
                    (Some(b), Some(_)) if !bucket_was_ok => Some(b),
                    (Some(_), Some(m)) => Some(m),
                    _ => None,
                }
            }
            Stage::Done => None,
        }
    }

    /// The stick angle that ends Pre-Dig and Dig: beta, or with the swept-volume end active (3.2) the
    /// perception stick limit if that is farther in.
    fn stick_end_rad(&self, inputs: &AutodigInputs) -> f64 {
        let p = &self.config.perception;
        if p.end_dig_on_swept_volume && inputs.swept_volume_m3.is_some() {
            p.stick_limit_rad.min(self.config.beta_rad)
        } else {
            self.config.beta_rad
        }
    }

    /// Capture's boom-side condition: above the terrain (3.2) if enabled and known, else gamma.
    fn capture_boom_reason(&self, inputs: &AutodigInputs) -> Option<EndReason> {
        let p = &self.config.perception;
        if p.end_capture_above_terrain
            && inputs
                .bucket_depth_m
                .is_some_and(|d| d <= -p.above_terrain_margin_m)
        {
            Some(EndReason::BucketAboveTerrain)
        } else if inputs.joint_rad[0] >= self.config.gamma_rad {
            Some(EndReason::BoomAngleGamma)
        } else if self.at_extend_limit(inputs, Joint::Boom) {
            Some(EndReason::CylinderLimit(Joint::Boom))
        } else {
            None
        }
    }

    /// Boom-Down contact detection (thesis 3.1): baseline while lowering freely, then a held head drop
    /// and/or rod rise.
    fn check_contact(&mut self, inputs: &AutodigInputs, now_s: f64) -> Option<EndReason> {
        let c = self.config.contact;
        let t = now_s - self.stage_start_s.unwrap_or(now_s);
        if t >= c.timeout_s {
            return Some(EndReason::BoomDownTimeout);
        }
        if self.at_retract_limit(inputs, Joint::Boom) {
            return Some(EndReason::CylinderLimit(Joint::Boom));
        }
        let head = inputs.head_pressure_pa[0];
        let rod = inputs.rod_pressure_pa[0];
        let bd = &mut self.boom_down;
        if t < c.settle_s {
            return None;
        }
        if t < c.settle_s + c.baseline_s || bd.samples == 0 {
            bd.head_sum_pa += head;
            bd.rod_sum_pa += rod;
            bd.samples = bd.samples.saturating_add(1);
            return None;
        }
        let n = f64::from(bd.samples);
        let head_drop = bd.head_sum_pa / n - head >= c.head_drop_pa;
        let rod_rise = rod - bd.rod_sum_pa / n >= c.rod_rise_pa;
        let signature = if c.require_both {
            head_drop && rod_rise
        } else {
            head_drop || rod_rise
        };
        if !signature {
            bd.contact_since_s = None;
            return None;
        }
        let since = *bd.contact_since_s.get_or_insert(now_s);
        (now_s - since >= c.debounce_s).then_some(EndReason::GroundContact)
    }

    /// The command of the current stage (Figs. 9-11), finite and within [-1, 1].
    fn command(&self, inputs: &AutodigInputs) -> [f64; 3] {
        let h = self.hardness;
        let map = |kind, joint| self.maps.eval(kind, h, self.pressure_pct(inputs, joint)) / 100.0;
        let cmd = match self.stage {
            Stage::BoomDown => [self.config.boom_down_command, 0.0, 0.0],
            // Fig. 10: bucket 100 %; boom regulates the bucket's load, stick its own.
            Stage::PreDig => [
                map(MapKind::PreDigBoom, Joint::Bucket),
                map(MapKind::PreDigStick, Joint::Stick),
                1.0,
            ],
            // Fig. 11: stick 100 %; boom regulates the stick's load, bucket its own.
            Stage::Dig => [
                map(MapKind::DigBoom, Joint::Stick),
                1.0,
                map(MapKind::DigBucket, Joint::Bucket),
            ],
            // 3.1: boom and bucket 100 %, stick 0. Each stops once its own end condition holds, so
            // the bucket is not driven into its end stop (relief) while the boom finishes, and it
            // curls again if lifting the boom rotates it back past rho3. A curl held near relief
            // keeps the boom lifting (`capture_lift_at_bucket_percent`).
            Stage::Capture => {
                let bucket_ok = inputs.bucket_abs_rad() <= self.config.rho3_rad
                    || self.at_extend_limit(inputs, Joint::Bucket);
                let bucket_held = !bucket_ok
                    && self.config.capture_lift_at_bucket_percent < 100.0
                    && self.pressure_pct(inputs, Joint::Bucket)
                        >= self.config.capture_lift_at_bucket_percent;
                let boom_ok = self.capture_boom_reason(inputs).is_some() && !bucket_held;
                [
                    if boom_ok { 0.0 } else { 1.0 },
                    0.0,
                    if bucket_ok { 0.0 } else { 1.0 },
                ]
            }
            Stage::Done => NEUTRAL,
        };
        cmd.map(|c| {
            if c.is_finite() {
                c.clamp(-1.0, 1.0)
            } else {
                0.0
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT_S: f64 = 0.01;
    const RELIEF_PA: f64 = 34.3e6;
    /// Boom pressures while the boom lowers freely (head holds the weight).
    const FREE_HEAD_PA: f64 = 8.0e6;
    const FREE_ROD_PA: f64 = 2.0e6;
    /// Boom pressures with the bucket resting on the ground.
    const CONTACT_HEAD_PA: f64 = 3.0e6;
    const CONTACT_ROD_PA: f64 = 6.0e6;
    /// Start pose: boom 0 deg, stick -70 deg (absolute -70), bucket 20 deg (absolute -50, opened).
    const START_JOINTS_DEG: [f64; 3] = [0.0, -70.0, 20.0];

    fn maps() -> AutodigMaps {
        AutodigMaps::builtin().expect("shipped maps are valid")
    }

    fn joints(deg: [f64; 3]) -> [f64; 3] {
        deg.map(f64::to_radians)
    }

    fn free_lowering() -> AutodigInputs {
        AutodigInputs {
            joint_rad: joints(START_JOINTS_DEG),
            head_pressure_pa: [FREE_HEAD_PA, 1.0e6, 1.0e6],
            rod_pressure_pa: [FREE_ROD_PA, 1.0e6, 1.0e6],
            extension_fraction: [0.5; 3],
            swept_volume_m3: None,
            bucket_depth_m: None,
        }
    }

    fn on_ground() -> AutodigInputs {
        let mut i = free_lowering();
        i.head_pressure_pa[0] = CONTACT_HEAD_PA;
        i.rod_pressure_pa[0] = CONTACT_ROD_PA;
        i
    }

    /// Steps `inputs` from `t0` for `duration_s`; returns the last output and the time reached.
    fn run(
        ad: &mut Autodig,
        inputs: &AutodigInputs,
        t0: f64,
        duration_s: f64,
    ) -> (AutodigOutput, f64) {
        let mut t = t0;
        let mut out = ad.step(inputs, t).expect("valid inputs");
        while t < t0 + duration_s {
            t += DT_S;
            out = ad.step(inputs, t).expect("valid inputs");
        }
        (out, t)
    }

    fn in_stage(stage: Stage, config: AutodigConfig) -> Autodig {
        Autodig::starting_in(config, maps(), stage).expect("valid config")
    }

    #[test]
    fn scripted_trace_runs_all_stages_in_order() {
        let mut ad = Autodig::new(AutodigConfig::default(), maps()).expect("valid");
        let mut seen = vec![Stage::BoomDown];
        let mut t = 0.0;
        let note = |s: Stage, seen: &mut Vec<Stage>| {
            if seen.last() != Some(&s) {
                seen.push(s);
            }
        };
        // Boom-Down: free lowering, then contact held long enough.
        let (out, t1) = run(&mut ad, &free_lowering(), t, 1.0);
        assert_eq!(out.stage, Stage::BoomDown);
        assert!(out.command[0] < 0.0 && out.command[1] == 0.0 && out.command[2] == 0.0);
        let (out, t1) = run(&mut ad, &on_ground(), t1 + DT_S, 0.3);
        note(out.stage, &mut seen);
        t = t1;
        // Pre-Dig: bucket curls from -50 to rho1 (-80).
        let mut i = on_ground();
        for bucket_rel in (-20..=15).map(|d| -f64::from(d)) {
            i.joint_rad = joints([0.0, -70.0, bucket_rel]);
            t += DT_S;
            let out = ad.step(&i, t).expect("valid");
            note(out.stage, &mut seen);
        }
        // Dig: stick comes in to beta (-100).
        for stick_rel in (70..=101).map(|d| -f64::from(d)) {
            i.joint_rad = joints([0.0, stick_rel, -60.0]);
            t += DT_S;
            let out = ad.step(&i, t).expect("valid");
            note(out.stage, &mut seen);
        }
        assert_eq!(
            ad.stage_end_reason(Stage::Dig),
            Some(EndReason::StickAngleBeta)
        );
        // Capture: bucket curls to rho3 (-210 absolute) and the boom rises to gamma (25).
        let mut last = None;
        for k in 0..=30 {
            let k = f64::from(k);
            i.joint_rad = joints([k, -101.0, -60.0 - 3.0 * k]);
            t += DT_S;
            let out = ad.step(&i, t).expect("valid");
            note(out.stage, &mut seen);
            last = Some(out);
        }
        assert_eq!(
            seen,
            [
                Stage::BoomDown,
                Stage::PreDig,
                Stage::Dig,
                Stage::Capture,
                Stage::Done
            ]
        );
        let last = last.expect("stepped");
        assert_eq!(last.command, NEUTRAL);
        assert!(last.end_reason.is_some());
        assert_eq!(
            ad.stage_end_reason(Stage::BoomDown),
            Some(EndReason::GroundContact)
        );
        assert_eq!(
            ad.stage_end_reason(Stage::PreDig),
            Some(EndReason::BucketAngleRho1)
        );
    }

    #[test]
    fn debounce_rejects_short_pressure_spike() {
        let cfg = AutodigConfig::default();
        let mut ad = Autodig::new(cfg, maps()).expect("valid");
        let (_, t) = run(&mut ad, &free_lowering(), 0.0, 1.0);
        // A spike shorter than the debounce time, as from shaking.
        let spike_s = cfg.contact.debounce_s * 0.5;
        let (out, t) = run(&mut ad, &on_ground(), t + DT_S, spike_s);
        assert_eq!(out.stage, Stage::BoomDown);
        let (out, t) = run(&mut ad, &free_lowering(), t + DT_S, 0.5);
        assert_eq!(out.stage, Stage::BoomDown);
        // Held contact is detected.
        let (out, _) = run(
            &mut ad,
            &on_ground(),
            t + DT_S,
            cfg.contact.debounce_s + 2.0 * DT_S,
        );
        assert_eq!(out.stage, Stage::PreDig);
        assert_eq!(out.command[2], 1.0);
    }

    #[test]
    fn contact_before_baseline_is_not_detected() {
        let mut ad = Autodig::new(AutodigConfig::default(), maps()).expect("valid");
        // Resting on the ground from the start: the baseline is the ground pressure, no change.
        let (out, _) = run(&mut ad, &on_ground(), 0.0, 2.0);
        assert_eq!(out.stage, Stage::BoomDown);
    }

    #[test]
    fn boom_down_times_out() {
        let cfg = AutodigConfig::default();
        let mut ad = Autodig::new(cfg, maps()).expect("valid");
        let (out, _) = run(&mut ad, &free_lowering(), 0.0, cfg.contact.timeout_s + DT_S);
        assert_eq!(out.stage, Stage::Done);
        assert_eq!(out.end_reason, Some(EndReason::BoomDownTimeout));
        assert_eq!(out.command, NEUTRAL);
    }

    #[test]
    fn predig_ends_at_rho1_and_on_bucket_limit() {
        let mut ad = in_stage(Stage::PreDig, AutodigConfig::default());
        let mut i = free_lowering();
        assert_eq!(ad.step(&i, 0.0).expect("valid").stage, Stage::PreDig);
        i.joint_rad = joints([0.0, -70.0, -11.0]); // bucket_abs -81 < rho1 -80
        let out = ad.step(&i, 0.01).expect("valid");
        assert_eq!(out.stage, Stage::Dig);
        assert_eq!(
            out.stage_end,
            Some(StageEnd {
                stage: Stage::PreDig,
                reason: EndReason::BucketAngleRho1
            })
        );
        assert_eq!(out.command[1], 1.0, "Dig drives the stick at 100 %");

        let mut ad = in_stage(Stage::PreDig, AutodigConfig::default());
        let mut i = free_lowering();
        i.extension_fraction[2] = 1.0;
        let out = ad.step(&i, 0.0).expect("valid");
        assert_eq!(
            out.stage_end.map(|e| e.reason),
            Some(EndReason::CylinderLimit(Joint::Bucket))
        );
    }

    #[test]
    fn dig_ends_on_each_condition() {
        type Edit = fn(&mut AutodigInputs);
        let cases: [(Edit, EndReason); 4] = [
            (
                |i| i.joint_rad = joints([0.0, -101.0, -30.0]),
                EndReason::StickAngleBeta,
            ),
            (
                |i| i.joint_rad = joints([0.0, -90.0, -91.0]),
                EndReason::BucketAngleRho2,
            ),
            (
                |i| i.extension_fraction[1] = 0.995,
                EndReason::CylinderLimit(Joint::Stick),
            ),
            (
                |i| i.extension_fraction[2] = 1.0,
                EndReason::CylinderLimit(Joint::Bucket),
            ),
        ];
        for (edit, reason) in cases {
            let mut ad = in_stage(Stage::Dig, AutodigConfig::default());
            let mut i = free_lowering();
            i.joint_rad = joints([0.0, -80.0, -40.0]);
            assert_eq!(ad.step(&i, 0.0).expect("valid").stage, Stage::Dig);
            edit(&mut i);
            let out = ad.step(&i, 0.01).expect("valid");
            assert_eq!(out.stage, Stage::Capture, "{reason:?}");
            assert_eq!(ad.stage_end_reason(Stage::Dig), Some(reason));
        }
    }

    #[test]
    fn swept_volume_ends_dig_only_with_perception() {
        let mut i = free_lowering();
        i.joint_rad = joints([0.0, -80.0, -40.0]);
        i.swept_volume_m3 = Some(1.5); // above 1.2 * 1.15 = 1.38
        let mut ad = in_stage(Stage::Dig, AutodigConfig::default());
        assert_eq!(ad.step(&i, 0.0).expect("valid").stage, Stage::Dig);

        let mut cfg = AutodigConfig::default();
        cfg.perception.end_dig_on_swept_volume = true;
        let mut ad = in_stage(Stage::Dig, cfg);
        i.swept_volume_m3 = Some(1.3);
        assert_eq!(ad.step(&i, 0.0).expect("valid").stage, Stage::Dig);
        i.swept_volume_m3 = Some(1.4);
        let out = ad.step(&i, 0.01).expect("valid");
        assert_eq!(
            out.stage_end.map(|e| e.reason),
            Some(EndReason::SweptVolumeFull)
        );
    }

    /// Table 1 (3.2): a dig started close in reached beta after a few degrees of stick travel with a
    /// small payload; with the swept-volume end active the stick goes on to the perception limit.
    #[test]
    fn swept_volume_end_replaces_beta_by_the_stick_limit() {
        let mut i = free_lowering();
        // stick_abs -105: past beta (-100), short of the perception limit (-120).
        i.joint_rad = joints([0.0, -105.0, -20.0]);
        i.swept_volume_m3 = Some(0.5);
        let mut cfg = AutodigConfig::default();
        let mut ad = in_stage(Stage::Dig, cfg);
        let out = ad.step(&i, 0.0).expect("valid");
        assert_eq!(
            out.stage_end.map(|e| e.reason),
            Some(EndReason::StickAngleBeta)
        );
        cfg.perception.end_dig_on_swept_volume = true;
        let mut ad = in_stage(Stage::Dig, cfg);
        assert_eq!(ad.step(&i, 0.0).expect("valid").stage, Stage::Dig);
        // Without a volume (no terrain) the plain angle rules apply.
        i.swept_volume_m3 = None;
        let out = ad.step(&i, 0.01).expect("valid");
        assert_eq!(
            out.stage_end.map(|e| e.reason),
            Some(EndReason::StickAngleBeta)
        );
        let mut ad = in_stage(Stage::Dig, cfg);
        i.swept_volume_m3 = Some(0.5);
        i.joint_rad = joints([0.0, -121.0, -20.0]);
        let out = ad.step(&i, 0.0).expect("valid");
        assert_eq!(
            out.stage_end.map(|e| e.reason),
            Some(EndReason::StickAngleBeta)
        );
    }

    #[test]
    fn capture_ends_at_rho3_and_gamma_or_above_terrain() {
        let mut i = free_lowering();
        // Bucket curled past rho3 (-210), boom below gamma, bucket out of the ground.
        i.joint_rad = joints([10.0, -100.0, -125.0]);
        i.bucket_depth_m = Some(-0.1);
        let mut ad = in_stage(Stage::Capture, AutodigConfig::default());
        let out = ad.step(&i, 0.0).expect("valid");
        assert_eq!(out.stage, Stage::Capture);
        assert_eq!(
            out.command,
            [1.0, 0.0, 0.0],
            "bucket stops at rho3, boom keeps rising"
        );
        i.joint_rad = joints([26.0, -100.0, -140.0]);
        let out = ad.step(&i, 0.01).expect("valid");
        assert_eq!(out.stage, Stage::Done);
        assert_eq!(out.end_reason, Some(EndReason::BoomAngleGamma));

        let mut cfg = AutodigConfig::default();
        cfg.perception.end_capture_above_terrain = true;
        let mut ad = in_stage(Stage::Capture, cfg);
        i.joint_rad = joints([10.0, -100.0, -125.0]);
        i.bucket_depth_m = Some(0.2);
        assert_eq!(ad.step(&i, 0.0).expect("valid").stage, Stage::Capture);
        i.bucket_depth_m = Some(-0.01);
        let out = ad.step(&i, 0.01).expect("valid");
        assert_eq!(out.end_reason, Some(EndReason::BucketAboveTerrain));

        // Boom at gamma first, bucket not yet at rho3: the bucket's arrival ends it.
        let mut ad = in_stage(Stage::Capture, AutodigConfig::default());
        i.joint_rad = joints([30.0, -100.0, -100.0]);
        let out = ad.step(&i, 0.0).expect("valid");
        assert_eq!(out.command, [0.0, 0.0, 1.0]);
        i.joint_rad = joints([30.0, -100.0, -141.0]);
        let out = ad.step(&i, 0.01).expect("valid");
        assert_eq!(out.end_reason, Some(EndReason::BucketAngleRho3));

        // Boom done, bucket short of rho3 and held at relief: the boom lifts it free; with the
        // pressure down again it stops.
        let mut ad = in_stage(Stage::Capture, AutodigConfig::default());
        i.joint_rad = joints([30.0, -100.0, -100.0]);
        i.head_pressure_pa[Joint::Bucket.index()] = 0.95 * RELIEF_PA;
        assert_eq!(ad.step(&i, 0.0).expect("valid").command, [1.0, 0.0, 1.0]);
        i.head_pressure_pa[Joint::Bucket.index()] = 0.5 * RELIEF_PA;
        assert_eq!(ad.step(&i, 0.01).expect("valid").command, [0.0, 0.0, 1.0]);
        let off = AutodigConfig {
            capture_lift_at_bucket_percent: 100.0,
            ..AutodigConfig::default()
        };
        let mut ad = in_stage(Stage::Capture, off);
        i.head_pressure_pa[Joint::Bucket.index()] = RELIEF_PA;
        assert_eq!(ad.step(&i, 0.0).expect("valid").command, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn higher_hardness_raises_bucket_pressure_threshold_for_boom_lift() {
        let m = maps();
        // The lowest bucket pressure at which Pre-Dig starts to lift the boom, per index.
        let threshold = |h: f64| {
            (0..=1000)
                .map(|k| f64::from(k) / 10.0)
                .find(|&p| m.eval(MapKind::PreDigBoom, h, p) > 1.0)
        };
        let mut previous = None;
        for h in [1.0, 1.5, 2.0, 3.0, 4.0, 4.5, 5.0] {
            let t = threshold(h).expect("boom lifts below relief");
            if let Some(p) = previous {
                assert!(t > p, "index {h}: threshold {t} % not above {p} %");
            }
            previous = Some(t);
        }
        // The same holds through the state machine at a fixed bucket pressure.
        let mut i = free_lowering();
        i.head_pressure_pa[2] = 0.5 * RELIEF_PA;
        let boom_cmd = |h: f64| {
            let cfg = AutodigConfig {
                hardness_index: h,
                ..AutodigConfig::default()
            };
            in_stage(Stage::PreDig, cfg)
                .step(&i, 0.0)
                .expect("valid")
                .command[0]
        };
        assert!(boom_cmd(1.0) > boom_cmd(3.0) && boom_cmd(3.0) > boom_cmd(5.0));
    }

    #[test]
    fn soft_soil_scoops_hard_soil_waits_all_back_off_near_relief() {
        let m = maps();
        assert_eq!(m.eval(MapKind::DigBucket, 1.0, 5.0), 100.0);
        assert_eq!(m.eval(MapKind::DigBucket, 5.0, 5.0), 0.0);
        for h in [1.0, 2.0, 3.0, 4.0, 5.0] {
            assert!(m.eval(MapKind::DigBucket, h, 98.0) < 20.0, "index {h}");
        }
        // Stick map falls with its own pressure, the same for every index.
        assert!(m.eval(MapKind::PreDigStick, 1.0, 10.0) > m.eval(MapKind::PreDigStick, 1.0, 80.0));
        assert_eq!(
            m.eval(MapKind::PreDigStick, 1.0, 50.0),
            m.eval(MapKind::PreDigStick, 5.0, 50.0)
        );
    }

    #[test]
    fn fractional_index_interpolates() {
        let m = maps();
        let a = m.eval(MapKind::DigBucket, 2.0, 15.0);
        let b = m.eval(MapKind::DigBucket, 3.0, 15.0);
        let mid = m.eval(MapKind::DigBucket, 2.5, 15.0);
        assert!((mid - 0.5 * (a + b)).abs() < 1e-9);
        assert_eq!(
            m.eval(MapKind::DigBucket, 0.0, 15.0),
            m.eval(MapKind::DigBucket, 1.0, 15.0)
        );
        assert_eq!(
            m.eval(MapKind::DigBucket, 9.0, 15.0),
            m.eval(MapKind::DigBucket, 5.0, 15.0)
        );
    }

    #[test]
    fn nan_input_gives_error_and_state_is_kept() {
        let mut ad = in_stage(Stage::Dig, AutodigConfig::default());
        let mut i = free_lowering();
        i.head_pressure_pa[1] = f64::NAN;
        assert_eq!(
            ad.step(&i, 0.0),
            Err(AutodigError::NonFinite {
                input: "stick head_pressure_pa"
            })
        );
        i.head_pressure_pa[1] = 1.0e6;
        i.joint_rad[0] = f64::INFINITY;
        assert!(matches!(
            ad.step(&i, 0.01),
            Err(AutodigError::NonFinite { .. })
        ));
        i.joint_rad[0] = 0.0;
        i.extension_fraction[0] = 3.0;
        assert!(matches!(
            ad.step(&i, 0.02),
            Err(AutodigError::OutOfRange { .. })
        ));
        i.extension_fraction[0] = 0.5;
        assert!(matches!(
            ad.step(&i, f64::NAN),
            Err(AutodigError::NonFinite { input: "now_s" })
        ));
        assert_eq!(ad.step(&i, 0.03).expect("valid").stage, Stage::Dig);
        assert!(matches!(
            ad.step(&i, 0.02),
            Err(AutodigError::TimeWentBackwards { .. })
        ));
    }

    #[test]
    fn config_uses_degrees_in_toml() {
        let cfg = AutodigConfig::from_toml_str(
            "beta_deg = -95.0\n[perception]\nend_dig_on_swept_volume = true\n",
        )
        .expect("valid");
        assert!((cfg.beta_rad - (-95.0_f64).to_radians()).abs() < 1e-12);
        assert!(cfg.perception.end_dig_on_swept_volume);
        assert_eq!(cfg.rho1_rad, AutodigConfig::default().rho1_rad);
        assert!(AutodigConfig::from_toml_str("hardness_index = nan").is_err());
        assert!(AutodigConfig::from_toml_str("boom_down_command = 0.5").is_err());
    }

    fn arb_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -1.0e8..1.0e8f64,
            2 => -10.0..10.0f64,
            2 => -0.2..1.2f64,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(f64::NEG_INFINITY),
        ]
    }

    fn arb_inputs() -> impl Strategy<Value = AutodigInputs> {
        (
            proptest::array::uniform3(arb_f64()),
            proptest::array::uniform3(arb_f64()),
            proptest::array::uniform3(arb_f64()),
            proptest::array::uniform3(arb_f64()),
            proptest::option::of(arb_f64()),
            proptest::option::of(arb_f64()),
        )
            .prop_map(|(j, h, r, e, v, d)| AutodigInputs {
                joint_rad: j,
                head_pressure_pa: h,
                rod_pressure_pa: r,
                extension_fraction: e,
                swept_volume_m3: v,
                bucket_depth_m: d,
            })
    }

    proptest! {
        #[test]
        fn commands_stay_finite_and_bounded(
            start in 0usize..5,
            hardness in -2.0..8.0f64,
            steps in proptest::collection::vec((arb_inputs(), 0.0..0.05f64), 1..60),
        ) {
            let stage = [Stage::BoomDown, Stage::PreDig, Stage::Dig, Stage::Capture, Stage::Done][start];
            let cfg = AutodigConfig {
                hardness_index: hardness,
                perception: PerceptionConfig {
                    end_dig_on_swept_volume: true,
                    end_capture_above_terrain: true,
                    ..PerceptionConfig::default()
                },
                ..AutodigConfig::default()
            };
            let mut ad = in_stage(stage, cfg);
            let mut t = 0.0;
            for (inputs, dt) in steps {
                t += dt;
                if let Ok(out) = ad.step(&inputs, t) {
                    for c in out.command {
                        prop_assert!(c.is_finite() && (-1.0..=1.0).contains(&c));
                    }
                }
            }
        }
    }
}
