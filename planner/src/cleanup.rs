//! Floor cleanup (thesis 3.3, Fig. 13): bucket-tip waypoints along the floor in the dig plane, sent at a
//! fixed rate to the gateway's closed-loop position mode, then a hand-over to Autodig in Pre-Dig.
//!
//! A [`Cleanup`] is a pure stepper, `step(inputs, now_s)`, like [`crate::autodig::Autodig`]:
//!
//! 1. **Probe** (only when the floor elevation is not known yet, or with [`FloorPolicy::DetectEveryTime`]):
//!    the tip is lowered slowly at the start radius until it stops following (the measured tip stays
//!    above the commanded one by `probe_lag_m` for `probe_debounce_s` and has stopped descending, after
//!    it had first followed the setpoint down: a position loop's lag is not contact); the floor
//!    elevation is the mean measured tip elevation over that held contact and is stored in the
//!    [`FloorEstimate`].
//!    **Descend** (floor known): the tip is lowered at the same speed to the known floor.
//! 2. **Follow**: waypoints toward the machine along the floor. At a fixed rate the spacing sets the
//!    speed, so the waypoints start close together and spread out, a velocity ramp up to a maximum speed
//!    that the position control can follow better than a step (3.3).
//! 3. **Hand-over** to Autodig in [`crate::autodig::Stage::PreDig`] when the stick reaches its angle
//!    limit (the bucket never goes under the tracks), when any cylinder pressure stays above a threshold
//!    for a set time, or at the end of the path (minimum radius).
//!
//! Detecting the floor once and reusing it is the change behind the thesis's Table 5 results; the
//! caller keeps the [`FloorEstimate`] from [`Cleanup::floor_estimate`] between cleanups.
//!
//! Frames and units: base frame of docs/ARCHITECTURE.md (`x` forward from the swing axis, `z` up, the
//! track ground at `z = 0`), m, rad, Pa, s. Absolute angles are `stick_abs = boom + stick` and
//! `bucket_abs = boom + stick + bucket`.

use crate::input_check::{InputError, check, check_port_pressures};
use crate::kinematics::Joint;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

const MAX_ANGLE_RAD: f64 = 4.0 * PI;
const MAX_COORD_M: f64 = 100.0;

/// Whether the floor elevation is detected once and reused, or on every cleanup.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FloorPolicy {
    /// Detect on the first cleanup and reuse the elevation afterwards (the Table 5 system).
    DetectOnce,
    /// Detect on every cleanup (the older behaviour, for comparison).
    DetectEveryTime,
}

/// The floor elevation used by cleanups, m in the base frame (`z`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FloorEstimate {
    z_m: Option<f64>,
    policy: FloorPolicy,
}

impl FloorEstimate {
    /// No floor detected yet.
    pub const fn new(policy: FloorPolicy) -> Self {
        Self { z_m: None, policy }
    }

    /// A floor elevation known in advance (e.g. from the plan), used as if detected.
    ///
    /// # Errors
    /// [`CleanupError::NonFinite`] if `z_m` is not finite.
    pub fn known(z_m: f64, policy: FloorPolicy) -> Result<Self, CleanupError> {
        if !z_m.is_finite() {
            return Err(CleanupError::NonFinite { input: "floor z_m" });
        }
        Ok(Self {
            z_m: Some(z_m),
            policy,
        })
    }

    /// The floor elevation, once detected, m.
    pub fn z_m(&self) -> Option<f64> {
        self.z_m
    }

    /// The policy.
    pub fn policy(&self) -> FloorPolicy {
        self.policy
    }

    /// Whether the next cleanup probes for the floor.
    pub fn needs_detection(&self) -> bool {
        self.z_m.is_none() || self.policy == FloorPolicy::DetectEveryTime
    }
}

/// Errors of cleanup configuration and steps.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum CleanupError {
    /// An input is NaN or infinite.
    #[error("cleanup input {input} is not finite")]
    NonFinite {
        /// Name of the input.
        input: &'static str,
    },
    /// An input is finite but implausible.
    #[error("cleanup input {input} = {value} is out of range")]
    OutOfRange {
        /// Name of the input.
        input: &'static str,
        /// The offending value.
        value: f64,
    },
    /// `now_s` is earlier than the previous step's.
    #[error("cleanup time went backwards: now {now_s} s < previous {previous_s} s")]
    TimeWentBackwards {
        /// The time passed in.
        now_s: f64,
        /// The previous step's time.
        previous_s: f64,
    },
    /// A configuration or plan value is invalid.
    #[error("cleanup config {field}: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The probe went `probe_max_depth_m` down without touching anything; the cleanup is abandoned
    /// (every later step returns this error too).
    #[error("cleanup found no floor within {depth_m} m below the start")]
    FloorNotFound {
        /// How far the probe went down, m.
        depth_m: f64,
    },
}

impl InputError for CleanupError {
    fn non_finite(input: &'static str) -> Self {
        Self::NonFinite { input }
    }
    fn out_of_range(input: &'static str, value: f64) -> Self {
        Self::OutOfRange { input, value }
    }
}

/// Cleanup parameters. Angles are radians in Rust, degrees in TOML/JSON.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CleanupConfig {
    /// Waypoint period, s: one waypoint per control step. Default: the control period (10 ms,
    /// `gateway_core::dbc::CONTROL_PERIOD`).
    pub period_s: f64,
    /// Tip speed at the first floor waypoints, m/s. Default 0.01.
    pub initial_speed_m_per_s: f64,
    /// Ramp acceleration, m/s^2. Default 0.1.
    pub ramp_accel_m_per_s2: f64,
    /// Maximum tip speed along the floor (largest spacing = this x period), m/s. Default 0.3.
    pub max_speed_m_per_s: f64,
    /// Lowering speed while probing for or descending to the floor, m/s. Default 0.1.
    pub descent_speed_m_per_s: f64,
    /// Probe contact: measured tip above the commanded one by at least this, m. Default 0.05.
    pub probe_lag_m: f64,
    /// Probe contact must hold this long, s. Default 0.2.
    pub probe_debounce_s: f64,
    /// Probe contact also needs the tip to have stopped: over the debounce window the measured tip
    /// descends by at most this fraction of the commanded descent. A position loop lags a lowering
    /// setpoint by a constant distance while still moving at the commanded speed, so the lag alone
    /// passed for contact (the demo's first cleanup "found" the floor 1.7 m up, in the air); a tip
    /// resting on the ground stops while the setpoint goes on down. Contact also needs the tip to have
    /// descended `probe_lag_m` from the probe's start first (the loop tracks; before it does, a tip
    /// that has not started moving looks stalled), so start the probe at least that far above the
    /// floor. In `[0, 1]`. Default 0.3.
    #[serde(default = "default_probe_stall_fraction")]
    pub probe_stall_fraction: f64,
    /// Probe gives up this far below the start, m. Default 1.5.
    pub probe_max_depth_m: f64,
    /// Absolute bucket angle held along the floor. Default -150 deg; [`CleanupConfig::levelling`]: -130:
    /// at -150 (edge 30 deg below the horizontal) the soil's reaction on a 0.2 m layer is mostly
    /// upward, it curls the bucket against the position loop (rod port at relief) and the edge rides
    /// over the layer; at -130 the edge cuts it (closed loop: residual 0.10 m at -130 and -125,
    /// 0.13-0.20 m at -135 to -150).
    #[serde(rename = "bucket_abs_deg", with = "crate::machine::degrees")]
    pub bucket_abs_rad: f64,
    /// Hand over when `stick_abs <= stick_limit` (stick in, bucket near the tracks). Default -115 deg.
    #[serde(rename = "stick_limit_deg", with = "crate::machine::degrees")]
    pub stick_limit_rad: f64,
    /// Relief pressures `[boom, stick, bucket]`, Pa. Default 34.3e6 each.
    pub relief_pressure_pa: [f64; 3],
    /// Pressure threshold in percent of relief: hand over when any port (head or rod) of any cylinder
    /// stays at or above it for `pressure_hold_s`. Default 85 ([`CleanupConfig::levelling`]: 90).
    pub pressure_threshold_pct: f64,
    /// How long the pressure must stay above the threshold without a break, s. Default 0.2
    /// ([`CleanupConfig::levelling`]: 1.0): the
    /// bucket cylinder holding its angle against the cut reaches relief in bursts; with 0.2 s cleanup
    /// handed over in the middle of the layer and Autodig from Pre-Dig there dug 0.25 m below the
    /// floor (0.5 s: 0.08 m, 1.0 s: 0.04 m below, in closed loop).
    pub pressure_hold_s: f64,
    /// After a probe, the pressure hand-over is not checked for this long once following starts, s.
    /// A probe ends only after the setpoint has gone `probe_lag_m` and more below a tip resting on the
    /// floor, so the position loop is pressing the edge into the floor at that moment (in closed loop:
    /// the bucket rod port at 36 MPa, above the threshold, and cleanup handed over 0.2 s into
    /// following, before the layer); the first waypoints at the floor elevation release it (in closed
    /// loop within about 0.5 s). Default 0 ([`CleanupConfig::levelling`]: 1.0).
    #[serde(default = "default_follow_settle_s")]
    pub follow_settle_s: f64,
    /// Follow waypoints run this far above the floor elevation, m: the tip skims the floor instead of
    /// being pressed into it. With the tip on a rigid floor any joint error of the position loop is
    /// taken up by the floor's reaction on the edge, which (tip trailing the pivot at -150 deg) curls
    /// the bucket against its loop until the rod port reaches relief. Default 0
    /// ([`CleanupConfig::levelling`]: 0.05).
    #[serde(default = "default_follow_clearance_m")]
    pub follow_clearance_m: f64,
    /// At the path end, hand over once the tip is within this of the end point, m. Default 0.05.
    pub arrive_tolerance_m: f64,
    /// At the path end, hand over at the latest this long after commanding the end point, s.
    /// Default 0.5.
    pub end_settle_s: f64,
}

fn default_probe_stall_fraction() -> f64 {
    0.3
}

fn default_follow_settle_s() -> f64 {
    0.0
}

fn default_follow_clearance_m() -> f64 {
    0.0
}

impl Default for CleanupConfig {
    fn default() -> Self {
        Self {
            period_s: gateway_core::dbc::CONTROL_PERIOD.as_secs_f64(),
            initial_speed_m_per_s: 0.01,
            ramp_accel_m_per_s2: 0.1,
            max_speed_m_per_s: 0.3,
            descent_speed_m_per_s: 0.1,
            probe_lag_m: 0.05,
            probe_debounce_s: 0.2,
            probe_stall_fraction: default_probe_stall_fraction(),
            probe_max_depth_m: 1.5,
            bucket_abs_rad: (-150.0_f64).to_radians(),
            stick_limit_rad: (-115.0_f64).to_radians(),
            relief_pressure_pa: [34.3e6; 3],
            pressure_threshold_pct: 85.0,
            pressure_hold_s: 0.2,
            follow_settle_s: default_follow_settle_s(),
            follow_clearance_m: default_follow_clearance_m(),
            arrive_tolerance_m: 0.05,
            end_settle_s: 0.5,
        }
    }
}

impl CleanupConfig {
    /// The settings that level a floor in closed loop against the simulator (thesis 3.3: a 0.2 m layer
    /// removed to 0.10 m, never more than 0.04 m below the floor; `docs/autodig.md`): no pressure
    /// hand-over for 1 s after a probe, waypoints 0.05 m above the floor, bucket at -130 deg, pressure
    /// hand-over at 90 % held 1 s; the rest as [`CleanupConfig::default`]. Not the default yet: with
    /// them the planned extended session (`controller/tests/extended.rs`) chose only cleanups in 25
    /// actions, not investigated.
    pub fn levelling() -> Self {
        Self {
            bucket_abs_rad: (-130.0_f64).to_radians(),
            pressure_threshold_pct: 90.0,
            pressure_hold_s: 1.0,
            follow_settle_s: 1.0,
            follow_clearance_m: 0.05,
            ..Self::default()
        }
    }

    /// Checks ranges and finiteness.
    ///
    /// # Errors
    /// [`CleanupError::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<(), CleanupError> {
        let bad = |field, reason| Err(CleanupError::InvalidConfig { field, reason });
        let positive = [
            ("period_s", self.period_s),
            ("initial_speed_m_per_s", self.initial_speed_m_per_s),
            ("ramp_accel_m_per_s2", self.ramp_accel_m_per_s2),
            ("max_speed_m_per_s", self.max_speed_m_per_s),
            ("descent_speed_m_per_s", self.descent_speed_m_per_s),
            ("probe_lag_m", self.probe_lag_m),
            ("probe_max_depth_m", self.probe_max_depth_m),
            ("pressure_threshold_pct", self.pressure_threshold_pct),
            ("arrive_tolerance_m", self.arrive_tolerance_m),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, "must be finite and > 0");
            }
        }
        let non_negative = [
            ("probe_debounce_s", self.probe_debounce_s),
            ("pressure_hold_s", self.pressure_hold_s),
            ("end_settle_s", self.end_settle_s),
            ("follow_settle_s", self.follow_settle_s),
            ("follow_clearance_m", self.follow_clearance_m),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, "must be finite and >= 0");
            }
        }
        if !(0.0..=1.0).contains(&self.probe_stall_fraction) {
            return bad("probe_stall_fraction", "must be in [0, 1]");
        }
        if self.initial_speed_m_per_s > self.max_speed_m_per_s {
            return bad("initial_speed_m_per_s", "must not exceed max_speed_m_per_s");
        }
        for (field, a) in [
            ("bucket_abs_deg", self.bucket_abs_rad),
            ("stick_limit_deg", self.stick_limit_rad),
        ] {
            if !(a.is_finite() && a.abs() <= MAX_ANGLE_RAD) {
                return bad(field, "must be finite and within +-720 deg");
            }
        }
        if self
            .relief_pressure_pa
            .iter()
            .any(|p| !(p.is_finite() && *p > 0.0))
        {
            return bad("relief_pressure_pa", "must be finite and > 0");
        }
        Ok(())
    }

    /// Distance travelled along the floor `t_s` after the ramp starts (3.3): speed rises linearly from
    /// `initial_speed` at `ramp_accel` and is capped at `max_speed`, m.
    pub fn ramp_distance_m(&self, t_s: f64) -> f64 {
        let t = t_s.max(0.0);
        let (v0, a, vmax) = (
            self.initial_speed_m_per_s,
            self.ramp_accel_m_per_s2,
            self.max_speed_m_per_s,
        );
        let t_ramp = (vmax - v0) / a;
        if t <= t_ramp {
            v0 * t + 0.5 * a * t * t
        } else {
            v0 * t_ramp + 0.5 * a * t_ramp * t_ramp + vmax * (t - t_ramp)
        }
    }
}

/// Where one cleanup runs in the dig plane (from the cleanup planner).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CleanupPlan {
    /// Radius at which the tip reaches the floor, just beyond the material boundary, m.
    pub start_radius_m: f64,
    /// Smallest radius the tip may reach (keeps the bucket off the tracks), m; `< start_radius_m`.
    pub min_radius_m: f64,
}

/// Sensor inputs of one cleanup step (the caller computes the tip from the joint angles).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CleanupInputs {
    /// Measured bucket tip `x` in the base frame, m.
    pub tip_x_m: f64,
    /// Measured bucket tip `z` in the base frame, m.
    pub tip_z_m: f64,
    /// Absolute stick angle `boom + stick`, rad.
    pub stick_abs_rad: f64,
    /// Head-port pressures `[boom, stick, bucket]`, Pa.
    pub head_pressure_pa: [f64; 3],
    /// Rod-port pressures `[boom, stick, bucket]`, Pa.
    pub rod_pressure_pa: [f64; 3],
}

impl CleanupInputs {
    fn validate(&self) -> Result<(), CleanupError> {
        check("tip_x_m", self.tip_x_m, -MAX_COORD_M, MAX_COORD_M)?;
        check("tip_z_m", self.tip_z_m, -MAX_COORD_M, MAX_COORD_M)?;
        check(
            "stick_abs_rad",
            self.stick_abs_rad,
            -MAX_ANGLE_RAD,
            MAX_ANGLE_RAD,
        )?;
        for j in 0..3 {
            check_port_pressures(j, self.head_pressure_pa[j], self.rod_pressure_pa[j])?;
        }
        Ok(())
    }
}

/// A bucket-tip setpoint for the gateway's position mode, base frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    /// Tip `x`, m.
    pub x_m: f64,
    /// Tip `z`, m.
    pub z_m: f64,
    /// Absolute bucket angle, rad.
    pub bucket_abs_rad: f64,
}

/// Why the waypoint following ended (3.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum HandOverReason {
    /// The stick reached its angle limit (never under the tracks).
    StickAngleLimit,
    /// A port of this cylinder stayed above the pressure threshold for the hold time.
    HighPressure(Joint),
    /// The path ended at the minimum radius.
    MinRadius,
}

/// Result of one cleanup step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum CleanupOutput {
    /// Send this setpoint.
    Waypoint(Waypoint),
    /// Stop following; start Autodig in Pre-Dig (`Autodig::starting_in(.., Stage::PreDig)`). Repeated on
    /// every later step.
    HandOver(HandOverReason),
}

/// Phase of a cleanup.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CleanupPhase {
    /// Lowering slowly at the start radius to detect the floor.
    Probe,
    /// Lowering to the known floor elevation.
    Descend,
    /// Following the floor toward the machine with the velocity ramp.
    Follow,
    /// Handed over to Autodig.
    HandedOver,
    /// No floor found; the cleanup is abandoned.
    Failed,
}

/// The cleanup waypoint generator.
#[derive(Debug, Clone, PartialEq)]
pub struct Cleanup {
    config: CleanupConfig,
    plan: CleanupPlan,
    floor: FloorEstimate,
    phase: CleanupPhase,
    phase_start_s: Option<f64>,
    last_now_s: Option<f64>,
    start_z_m: Option<f64>,
    probe_since_s: Option<f64>,
    /// Measured tip elevation when the current probe contact window opened, m.
    probe_window_z_m: f64,
    probe_z_sum_m: f64,
    probe_z_count: u32,
    high_since_s: Option<f64>,
    /// Following started from a probe contact (the edge is pressed into the floor).
    probed: bool,
    end_commanded_s: Option<f64>,
    hand_over: Option<HandOverReason>,
    failed_depth_m: f64,
}

impl Cleanup {
    /// A cleanup for `plan` using the floor estimate kept from earlier cleanups.
    ///
    /// # Errors
    /// [`CleanupError::InvalidConfig`] for a bad config or plan (non-finite radii, or
    /// `min_radius_m >= start_radius_m`).
    pub fn new(
        config: CleanupConfig,
        plan: CleanupPlan,
        floor: FloorEstimate,
    ) -> Result<Self, CleanupError> {
        config.validate()?;
        if !(plan.start_radius_m.is_finite() && plan.min_radius_m.is_finite()) {
            return Err(CleanupError::InvalidConfig {
                field: "plan",
                reason: "radii must be finite",
            });
        }
        if plan.min_radius_m >= plan.start_radius_m {
            return Err(CleanupError::InvalidConfig {
                field: "plan.min_radius_m",
                reason: "must be below start_radius_m",
            });
        }
        let phase = if floor.needs_detection() {
            CleanupPhase::Probe
        } else {
            CleanupPhase::Descend
        };
        Ok(Self {
            config,
            plan,
            floor,
            phase,
            phase_start_s: None,
            last_now_s: None,
            start_z_m: None,
            probe_since_s: None,
            probe_window_z_m: 0.0,
            probe_z_sum_m: 0.0,
            probe_z_count: 0,
            high_since_s: None,
            probed: false,
            end_commanded_s: None,
            hand_over: None,
            failed_depth_m: 0.0,
        })
    }

    /// The current phase.
    pub fn phase(&self) -> CleanupPhase {
        self.phase
    }

    /// The floor estimate, updated once the probe detects the floor; keep it for the next cleanup.
    pub fn floor_estimate(&self) -> FloorEstimate {
        self.floor
    }

    /// One step at time `now_s` (s, any monotonic clock; call it every `period_s`). No allocation, no
    /// panics.
    ///
    /// # Errors
    /// Bad inputs ([`CleanupError::NonFinite`], [`CleanupError::OutOfRange`],
    /// [`CleanupError::TimeWentBackwards`]): hold position or go neutral; the state is kept but running
    /// debounce timers restart. [`CleanupError::FloorNotFound`] once the probe gave up.
    pub fn step(
        &mut self,
        inputs: &CleanupInputs,
        now_s: f64,
    ) -> Result<CleanupOutput, CleanupError> {
        if self.phase == CleanupPhase::Failed {
            return Err(CleanupError::FloorNotFound {
                depth_m: self.failed_depth_m,
            });
        }
        if let Some(reason) = self.hand_over {
            return Ok(CleanupOutput::HandOver(reason));
        }
        let checked = if !now_s.is_finite() {
            Err(CleanupError::NonFinite { input: "now_s" })
        } else if let Some(previous_s) = self.last_now_s.filter(|&p| now_s < p) {
            Err(CleanupError::TimeWentBackwards { now_s, previous_s })
        } else {
            inputs.validate()
        };
        if let Err(e) = checked {
            self.probe_since_s = None;
            self.probe_z_sum_m = 0.0;
            self.probe_z_count = 0;
            self.high_since_s = None;
            return Err(e);
        }
        self.last_now_s = Some(now_s);
        let start_z = *self.start_z_m.get_or_insert(inputs.tip_z_m);
        let phase_start = *self.phase_start_s.get_or_insert(now_s);

        // 3.3: the stick-angle limit ends following in every phase.
        if inputs.stick_abs_rad <= self.config.stick_limit_rad {
            return Ok(self.finish(HandOverReason::StickAngleLimit));
        }
        let settling = self.phase == CleanupPhase::Follow
            && self.probed
            && now_s - phase_start < self.config.follow_settle_s;
        if settling {
            self.high_since_s = None;
        } else if self.phase != CleanupPhase::Probe
            && let Some(joint) = self.high_pressure(inputs, now_s)
        {
            return Ok(self.finish(HandOverReason::HighPressure(joint)));
        }

        let cfg = self.config;
        let t_k = self.scheduled_time(now_s, phase_start);
        match self.phase {
            CleanupPhase::Probe => {
                let depth = (cfg.descent_speed_m_per_s * t_k).min(cfg.probe_max_depth_m);
                let z_cmd = start_z - depth;
                if inputs.tip_z_m - z_cmd >= cfg.probe_lag_m {
                    let since = match self.probe_since_s {
                        Some(s) => s,
                        None => {
                            self.probe_window_z_m = inputs.tip_z_m;
                            *self.probe_since_s.insert(now_s)
                        }
                    };
                    self.probe_z_sum_m += inputs.tip_z_m;
                    self.probe_z_count = self.probe_z_count.saturating_add(1);
                    if now_s - since >= cfg.probe_debounce_s {
                        let window_s = now_s - since;
                        let fallen_m = self.probe_window_z_m - inputs.tip_z_m;
                        let stalled = fallen_m
                            <= cfg.probe_stall_fraction * cfg.descent_speed_m_per_s * window_s;
                        // The loop must have been tracking first: at the start of the descent a
                        // position loop (valve deadband, open-centre bypass) lags while the tip has
                        // not moved yet, which looks like a stall too.
                        let tracked = start_z - self.probe_window_z_m >= cfg.probe_lag_m;
                        if stalled && tracked {
                            let floor_z = self.probe_z_sum_m / f64::from(self.probe_z_count.max(1));
                            self.floor.z_m = Some(floor_z);
                            self.probed = true;
                            return Ok(self.begin_follow(now_s));
                        }
                        // Still descending, or not yet moving: the position loop's lag, not contact.
                        // Open a new window.
                        self.probe_since_s = Some(now_s);
                        self.probe_window_z_m = inputs.tip_z_m;
                        self.probe_z_sum_m = inputs.tip_z_m;
                        self.probe_z_count = 1;
                    }
                } else {
                    self.probe_since_s = None;
                    self.probe_z_sum_m = 0.0;
                    self.probe_z_count = 0;
                    if depth >= cfg.probe_max_depth_m {
                        self.phase = CleanupPhase::Failed;
                        self.failed_depth_m = depth;
                        return Err(CleanupError::FloorNotFound { depth_m: depth });
                    }
                }
                Ok(self.waypoint(self.plan.start_radius_m, z_cmd))
            }
            CleanupPhase::Descend => {
                let follow_z = self.floor.z_m.unwrap_or(start_z) + cfg.follow_clearance_m;
                let z_cmd = start_z - cfg.descent_speed_m_per_s * t_k;
                if z_cmd <= follow_z {
                    return Ok(self.begin_follow(now_s));
                }
                Ok(self.waypoint(self.plan.start_radius_m, z_cmd))
            }
            CleanupPhase::Follow => {
                let follow_z = self.floor.z_m.unwrap_or(start_z) + cfg.follow_clearance_m;
                let x_cmd = self.plan.start_radius_m - cfg.ramp_distance_m(t_k);
                if x_cmd > self.plan.min_radius_m {
                    return Ok(self.waypoint(x_cmd, follow_z));
                }
                let end_s = *self.end_commanded_s.get_or_insert(now_s);
                let arrived = (inputs.tip_x_m - self.plan.min_radius_m).abs()
                    <= cfg.arrive_tolerance_m
                    && (inputs.tip_z_m - follow_z).abs() <= cfg.arrive_tolerance_m;
                if arrived || now_s - end_s >= cfg.end_settle_s {
                    return Ok(self.finish(HandOverReason::MinRadius));
                }
                Ok(self.waypoint(self.plan.min_radius_m, follow_z))
            }
            CleanupPhase::HandedOver | CleanupPhase::Failed => {
                // Handled above; kept total so a future phase cannot fall through to a panic.
                Ok(self.finish(HandOverReason::MinRadius))
            }
        }
    }

    /// Time of the waypoint due at `now_s`: waypoints are on a fixed `period_s` grid from the phase start.
    fn scheduled_time(&self, now_s: f64, phase_start_s: f64) -> f64 {
        let k = ((now_s - phase_start_s) / self.config.period_s + 1e-9)
            .floor()
            .max(0.0);
        k * self.config.period_s
    }

    fn begin_follow(&mut self, now_s: f64) -> CleanupOutput {
        self.phase = CleanupPhase::Follow;
        self.phase_start_s = Some(now_s);
        let z = self.floor.z_m.unwrap_or_default() + self.config.follow_clearance_m;
        self.waypoint(self.plan.start_radius_m, z)
    }

    fn finish(&mut self, reason: HandOverReason) -> CleanupOutput {
        self.phase = CleanupPhase::HandedOver;
        self.hand_over = Some(reason);
        CleanupOutput::HandOver(reason)
    }

    fn waypoint(&self, x_m: f64, z_m: f64) -> CleanupOutput {
        CleanupOutput::Waypoint(Waypoint {
            x_m,
            z_m,
            bucket_abs_rad: self.config.bucket_abs_rad,
        })
    }

    /// The cylinder with a port above the threshold for the hold time, if any (3.3: "exceeds some
    /// threshold for a brief period of time").
    fn high_pressure(&mut self, inputs: &CleanupInputs, now_s: f64) -> Option<Joint> {
        let cfg = &self.config;
        let high = [Joint::Boom, Joint::Stick, Joint::Bucket]
            .into_iter()
            .find(|j| {
                let i = j.index();
                let limit = cfg.pressure_threshold_pct / 100.0 * cfg.relief_pressure_pa[i];
                inputs.head_pressure_pa[i] >= limit || inputs.rod_pressure_pa[i] >= limit
            });
        let Some(joint) = high else {
            self.high_since_s = None;
            return None;
        };
        let since = *self.high_since_s.get_or_insert(now_s);
        (now_s - since >= cfg.pressure_hold_s).then_some(joint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT_S: f64 = 0.01;
    const START_RADIUS_M: f64 = 7.0;
    const MIN_RADIUS_M: f64 = 4.0;
    const START_Z_M: f64 = 0.2;
    /// Where the ground actually is under the start radius.
    const TRUE_FLOOR_Z_M: f64 = -1.0;
    const LOW_PRESSURE_PA: f64 = 5.0e6;
    const HIGH_PRESSURE_PA: f64 = 32.0e6;
    const STICK_OUT_RAD: f64 = -1.0;

    fn plan() -> CleanupPlan {
        CleanupPlan {
            start_radius_m: START_RADIUS_M,
            min_radius_m: MIN_RADIUS_M,
        }
    }

    fn inputs_at(x: f64, z: f64) -> CleanupInputs {
        CleanupInputs {
            tip_x_m: x,
            tip_z_m: z,
            stick_abs_rad: STICK_OUT_RAD,
            head_pressure_pa: [LOW_PRESSURE_PA; 3],
            rod_pressure_pa: [LOW_PRESSURE_PA; 3],
        }
    }

    /// A perfect position controller on ground at `TRUE_FLOOR_Z_M`: the tip follows the last waypoint
    /// but cannot go below the ground.
    fn simulate(cleanup: &mut Cleanup, max_s: f64) -> (Vec<Waypoint>, Option<HandOverReason>, f64) {
        let mut tip = (START_RADIUS_M, START_Z_M);
        let mut points = Vec::new();
        let mut t = 0.0;
        while t < max_s {
            match cleanup
                .step(&inputs_at(tip.0, tip.1), t)
                .expect("valid step")
            {
                CleanupOutput::Waypoint(w) => {
                    tip = (w.x_m, w.z_m.max(TRUE_FLOOR_Z_M));
                    points.push(w);
                }
                CleanupOutput::HandOver(r) => return (points, Some(r), t),
            }
            t += DT_S;
        }
        (points, None, t)
    }

    #[test]
    fn ramp_spacing_grows_monotonically_to_the_cap() {
        let cfg = CleanupConfig::default();
        let floor = FloorEstimate::known(TRUE_FLOOR_Z_M, FloorPolicy::DetectOnce).expect("finite");
        let mut c = Cleanup::new(cfg, plan(), floor).expect("valid");
        let (points, reason, _) = simulate(&mut c, 60.0);
        assert_eq!(reason, Some(HandOverReason::MinRadius));
        let floor_pts: Vec<f64> = points
            .iter()
            .filter(|w| w.z_m == TRUE_FLOOR_Z_M + cfg.follow_clearance_m && w.x_m > MIN_RADIUS_M)
            .map(|w| w.x_m)
            .collect();
        let spacing: Vec<f64> = floor_pts.windows(2).map(|w| w[0] - w[1]).collect();
        let cap = cfg.max_speed_m_per_s * cfg.period_s;
        assert!(
            spacing[0] < 0.1 * cap,
            "first spacing {} should be small",
            spacing[0]
        );
        for w in spacing.windows(2) {
            assert!(w[1] >= w[0] - 1e-12, "spacing shrank: {} -> {}", w[0], w[1]);
        }
        assert!(spacing.iter().all(|&s| s <= cap + 1e-12));
        assert!(
            spacing.iter().any(|&s| (s - cap).abs() < 1e-9),
            "spacing reaches the cap"
        );
    }

    #[test]
    fn probe_detects_floor_once_and_reuses_it() {
        let cfg = CleanupConfig::default();
        let mut c =
            Cleanup::new(cfg, plan(), FloorEstimate::new(FloorPolicy::DetectOnce)).expect("valid");
        assert_eq!(c.phase(), CleanupPhase::Probe);
        let (_, reason, _) = simulate(&mut c, 60.0);
        assert_eq!(reason, Some(HandOverReason::MinRadius));
        let floor = c.floor_estimate();
        let z = floor.z_m().expect("detected");
        assert!((z - TRUE_FLOOR_Z_M).abs() < 1e-9, "floor {z}");
        assert!(!floor.needs_detection());
        let next = Cleanup::new(cfg, plan(), floor).expect("valid");
        assert_eq!(next.phase(), CleanupPhase::Descend);

        let every = FloorEstimate::known(z, FloorPolicy::DetectEveryTime).expect("finite");
        assert!(every.needs_detection());
        assert_eq!(
            Cleanup::new(cfg, plan(), every).expect("valid").phase(),
            CleanupPhase::Probe
        );
    }

    /// Regression: the probe leaves the edge pressed into the floor with the bucket rod port at relief;
    /// following handed over on that pressure 0.2 s after it began. Now the pressure is ignored for
    /// `follow_settle_s`, the waypoints run `follow_clearance_m` above the floor, and a pressure that
    /// stays high after that still hands over.
    #[test]
    fn probe_pressure_is_not_a_hand_over_while_following_settles() {
        let cfg = CleanupConfig::levelling();
        let mut c =
            Cleanup::new(cfg, plan(), FloorEstimate::new(FloorPolicy::DetectOnce)).expect("valid");
        let mut tip = (START_RADIUS_M, START_Z_M);
        let mut t = 0.0;
        let mut pressed = inputs_at(tip.0, tip.1);
        while c.phase() == CleanupPhase::Probe && t < 60.0 {
            pressed = inputs_at(tip.0, tip.1);
            if tip.1 <= TRUE_FLOOR_Z_M {
                pressed.rod_pressure_pa[Joint::Bucket.index()] = HIGH_PRESSURE_PA;
            }
            if let CleanupOutput::Waypoint(w) = c.step(&pressed, t).expect("valid step") {
                tip = (w.x_m, w.z_m.max(TRUE_FLOOR_Z_M));
            }
            t += DT_S;
        }
        assert_eq!(c.phase(), CleanupPhase::Follow);
        let follow_start = t - DT_S;
        // Pressure still high: no hand-over during the settle time, one after settle + hold.
        let mut handed_over_at = None;
        while t < follow_start + cfg.follow_settle_s + cfg.pressure_hold_s + 0.1 {
            pressed.tip_z_m = TRUE_FLOOR_Z_M;
            match c.step(&pressed, t).expect("valid step") {
                CleanupOutput::Waypoint(w) => {
                    assert!(
                        (w.z_m - (TRUE_FLOOR_Z_M + cfg.follow_clearance_m)).abs() < 1e-9,
                        "{w:?}"
                    );
                }
                CleanupOutput::HandOver(r) => {
                    assert_eq!(r, HandOverReason::HighPressure(Joint::Bucket));
                    handed_over_at = Some(t);
                    break;
                }
            }
            t += DT_S;
        }
        let at = handed_over_at.expect("a lasting pressure still hands over");
        assert!(
            at - follow_start >= cfg.follow_settle_s + cfg.pressure_hold_s - 2.0 * DT_S,
            "handed over {} s into following",
            at - follow_start
        );
    }

    /// Regression: a position loop that lags the lowering setpoint by more than `probe_lag_m` while
    /// still descending at the commanded speed was taken for floor contact in the air.
    #[test]
    fn a_lagging_position_loop_is_not_floor_contact() {
        let cfg = CleanupConfig::default();
        // First-order position loop: steady lag = descent speed / gain = 0.2 m, four times probe_lag.
        const LOOP_GAIN_PER_S: f64 = 0.5;
        let mut c =
            Cleanup::new(cfg, plan(), FloorEstimate::new(FloorPolicy::DetectOnce)).expect("valid");
        let mut tip_z = START_Z_M;
        let mut t = 0.0;
        let mut max_lag = 0.0_f64;
        while c.phase() == CleanupPhase::Probe && t < 60.0 {
            match c
                .step(&inputs_at(START_RADIUS_M, tip_z), t)
                .expect("valid step")
            {
                CleanupOutput::Waypoint(w) => {
                    if tip_z > TRUE_FLOOR_Z_M + 0.01 {
                        max_lag = max_lag.max(tip_z - w.z_m);
                    }
                    tip_z += (w.z_m - tip_z) * LOOP_GAIN_PER_S * DT_S;
                    tip_z = tip_z.max(TRUE_FLOOR_Z_M);
                }
                CleanupOutput::HandOver(r) => panic!("hand-over {r:?} while probing"),
            }
            t += DT_S;
        }
        assert!(max_lag > 3.0 * cfg.probe_lag_m, "lag {max_lag} m");
        let z = c.floor_estimate().z_m().expect("detected");
        assert!((z - TRUE_FLOOR_Z_M).abs() < 0.02, "floor {z} m");
    }

    #[test]
    fn probe_without_ground_fails() {
        let cfg = CleanupConfig::default();
        let mut c =
            Cleanup::new(cfg, plan(), FloorEstimate::new(FloorPolicy::DetectOnce)).expect("valid");
        let mut t = 0.0;
        let mut result = Ok(CleanupOutput::HandOver(HandOverReason::MinRadius));
        // The tip follows every waypoint: nothing is under it.
        let mut tip = (START_RADIUS_M, START_Z_M);
        for _ in 0..5000 {
            result = c.step(&inputs_at(tip.0, tip.1), t);
            match result {
                Ok(CleanupOutput::Waypoint(w)) => tip = (w.x_m, w.z_m),
                _ => break,
            }
            t += DT_S;
        }
        assert!(matches!(result, Err(CleanupError::FloorNotFound { .. })));
        assert!(matches!(
            c.step(&inputs_at(tip.0, tip.1), t + DT_S),
            Err(CleanupError::FloorNotFound { .. })
        ));
    }

    #[test]
    fn stick_limit_hands_over() {
        let floor = FloorEstimate::known(TRUE_FLOOR_Z_M, FloorPolicy::DetectOnce).expect("finite");
        let cfg = CleanupConfig::default();
        let mut c = Cleanup::new(cfg, plan(), floor).expect("valid");
        let mut i = inputs_at(START_RADIUS_M, START_Z_M);
        assert!(matches!(c.step(&i, 0.0), Ok(CleanupOutput::Waypoint(_))));
        i.stick_abs_rad = cfg.stick_limit_rad - 0.01;
        assert_eq!(
            c.step(&i, DT_S),
            Ok(CleanupOutput::HandOver(HandOverReason::StickAngleLimit))
        );
        assert_eq!(c.phase(), CleanupPhase::HandedOver);
        // Sticky.
        i.stick_abs_rad = STICK_OUT_RAD;
        assert_eq!(
            c.step(&i, 2.0 * DT_S),
            Ok(CleanupOutput::HandOver(HandOverReason::StickAngleLimit))
        );
    }

    #[test]
    fn pressure_condition_needs_the_hold_time() {
        let floor = FloorEstimate::known(START_Z_M, FloorPolicy::DetectOnce).expect("finite");
        let cfg = CleanupConfig::default();
        let mut c = Cleanup::new(cfg, plan(), floor).expect("valid");
        let low = inputs_at(START_RADIUS_M, START_Z_M);
        let mut high = low;
        high.rod_pressure_pa[1] = HIGH_PRESSURE_PA; // 93 % of relief on the stick rod port
        let mut t = 0.0;
        assert!(matches!(c.step(&low, t), Ok(CleanupOutput::Waypoint(_))));
        // A spike shorter than the hold time, interrupted by a normal reading.
        let spike_steps = (cfg.pressure_hold_s / DT_S) as usize / 2;
        for _ in 0..spike_steps {
            t += DT_S;
            assert!(matches!(c.step(&high, t), Ok(CleanupOutput::Waypoint(_))));
        }
        t += DT_S;
        assert!(matches!(c.step(&low, t), Ok(CleanupOutput::Waypoint(_))));
        // Held for the hold time: hand over.
        let t0 = t + DT_S;
        let mut out = c.step(&high, t0).expect("valid");
        while t < t0 + cfg.pressure_hold_s + DT_S {
            t += DT_S;
            out = c.step(&high, t).expect("valid");
            if matches!(out, CleanupOutput::HandOver(_)) {
                assert!(
                    t - t0 >= cfg.pressure_hold_s - 1e-9,
                    "handed over after {} s",
                    t - t0
                );
                break;
            }
        }
        assert_eq!(
            out,
            CleanupOutput::HandOver(HandOverReason::HighPressure(Joint::Stick))
        );
    }

    #[test]
    fn bad_inputs_are_errors_and_bad_plans_rejected() {
        let floor = FloorEstimate::new(FloorPolicy::DetectOnce);
        let cfg = CleanupConfig::default();
        let mut c = Cleanup::new(cfg, plan(), floor).expect("valid");
        let mut i = inputs_at(START_RADIUS_M, START_Z_M);
        i.tip_z_m = f64::NAN;
        assert_eq!(
            c.step(&i, 0.0),
            Err(CleanupError::NonFinite { input: "tip_z_m" })
        );
        i.tip_z_m = START_Z_M;
        i.head_pressure_pa[2] = 1.0e9;
        assert!(matches!(
            c.step(&i, 0.0),
            Err(CleanupError::OutOfRange { .. })
        ));
        i.head_pressure_pa[2] = LOW_PRESSURE_PA;
        assert!(c.step(&i, 1.0).is_ok());
        assert!(matches!(
            c.step(&i, 0.5),
            Err(CleanupError::TimeWentBackwards { .. })
        ));
        let backwards = CleanupPlan {
            start_radius_m: 3.0,
            min_radius_m: 4.0,
        };
        assert!(Cleanup::new(cfg, backwards, floor).is_err());
        let nan_cfg = CleanupConfig {
            max_speed_m_per_s: f64::NAN,
            ..cfg
        };
        assert!(Cleanup::new(nan_cfg, plan(), floor).is_err());
        assert!(FloorEstimate::known(f64::INFINITY, FloorPolicy::DetectOnce).is_err());
    }

    fn arb_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -50.0..50.0f64,
            3 => -1.0e8..1.0e8f64,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
        ]
    }

    proptest! {
        #[test]
        fn arbitrary_inputs_never_panic_and_waypoints_are_finite(
            detect in any::<bool>(),
            steps in proptest::collection::vec(
                (arb_f64(), arb_f64(), arb_f64(), proptest::array::uniform3(arb_f64()),
                 proptest::array::uniform3(arb_f64()), 0.0..0.05f64),
                1..200,
            ),
        ) {
            let floor = if detect {
                FloorEstimate::new(FloorPolicy::DetectEveryTime)
            } else {
                FloorEstimate::known(TRUE_FLOOR_Z_M, FloorPolicy::DetectOnce).expect("finite")
            };
            let mut c = Cleanup::new(CleanupConfig::default(), plan(), floor).expect("valid");
            let mut t = 0.0;
            for (x, z, stick, head, rod, dt) in steps {
                t += dt;
                let i = CleanupInputs {
                    tip_x_m: x,
                    tip_z_m: z,
                    stick_abs_rad: stick,
                    head_pressure_pa: head,
                    rod_pressure_pa: rod,
                };
                if let Ok(CleanupOutput::Waypoint(w)) = c.step(&i, t) {
                    prop_assert!(w.x_m.is_finite() && w.z_m.is_finite() && w.bucket_abs_rad.is_finite());
                    prop_assert!(w.x_m >= MIN_RADIUS_M - 1e-9 && w.x_m <= START_RADIUS_M + 1e-9);
                }
            }
        }
    }
}
