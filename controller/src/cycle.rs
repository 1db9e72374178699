//! The work cycle (thesis chapters 3 and 6): scan, swing to the dig, Autodig or cleanup, weigh, swing to
//! the spoil pile, dump, return; and tracking backwards.
//!
//! Until the dig planner lands, the plan is a fixed, configurable list of [`Action`]s (dig at a swing
//! angle from a start pose, cleanup, track back a distance), repeated until the requested number of
//! digs. Per action the [`WorkCycle`] runs these phases:
//!
//! ```text
//! Dig / Cleanup:  Scan -> MoveToDig -> Autodig | Cleanup -> Autodig (Pre-Dig) -> Weigh -> SwingToDump
//!                 -> Dump -> (next action; its MoveToDig is the return swing)
//! TrackBack:      TrackBack
//! after the last: Return -> Finished
//! ```
//!
//! - **Scan**: asks the caller for a range scan ([`WorkCycle::take_scan_request`]) and waits for the
//!   terrain ([`WorkCycle::provide_terrain`]) up to a timeout; without one, Autodig runs with its plain
//!   angle rules.
//! - **Autodig** (planner's pure state machine) with the perception enhancements of 3.2: the pre-dig
//!   terrain section along the digging plane is kept, the volume swept over the cutting edge is
//!   integrated ([`planner::terrain::SweptVolume`]), Dig ends at bucket capacity x spill allowance and
//!   Capture ends as soon as the bucket is above that terrain.
//! - **Cleanup** (3.3): waypoints from [`planner::cleanup::Cleanup`] through inverse kinematics to the
//!   gateway's position mode, with the floor elevation detected on the first cleanup and reused
//!   ([`planner::cleanup::FloorEstimate`]), then the hand-over to Autodig in Pre-Dig.
//! - Swing, the implement moves and the tracks are closed by P-controllers on the valve commands.
//!
//! Per dig it records [`DigStats`]: weight (static payload estimate after Capture, Appendix A.2 with the
//! gravity model), time, energy (thesis 6.1: cylinder force times displacement, integrated), swept
//! volume, time in the ground and the action type.
//!
//! The cycle does no I/O and reads no clock; it moves only while the safety layer reports the machine
//! armed in the mode the current phase needs, and holds (neutral) otherwise.

use planner::autodig::{Autodig, AutodigConfig, AutodigInputs, AutodigMaps, EndReason, Stage};
use planner::cleanup::{
    Cleanup, CleanupConfig, CleanupInputs, CleanupOutput, CleanupPlan, FloorEstimate, FloorPolicy,
    HandOverReason,
};
use planner::kinematics::{BucketPose, Joint, JointAngles, Kinematics, wrap_angle};
use planner::machine::GRAVITY_M_PER_S2;
use planner::terrain::{SectionProfile, SweptVolume, TerrainError, TerrainGrid};
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::estimate::Estimator;
use crate::node::{Limits, ParamError, check, check_count, check_deg, toml_float};
use crate::safety::{ArmMode, ControlFault};

/// Valve direction per implement joint: +1 when cylinder extension raises the joint angle
/// (docs/ARCHITECTURE.md: boom up; stick and bucket extension lower their angles).
pub const JOINT_SIGN: [f64; 3] = [1.0, -1.0, -1.0];

/// MoveToDig stall escalation: a joint whose error has not shrunk by this much for
/// [`STALL_WAIT_S`] is stalled, rad (0.2 deg). Judged on the angle, not the rate signal: a
/// cylinder chattering in place reports a rate without getting anywhere.
const STALL_PROGRESS_RAD: f64 = 0.0035;

/// MoveToDig stall escalation: how long a joint may make no progress before its command grows, s.
const STALL_WAIT_S: f64 = 0.5;

const STALL_BOOST_PER_S: f64 = 0.25;

/// MoveToDig: while the stick or the bucket still has far to go, the tip is kept this far above the
/// highest known terrain between it and the start (the boom lifts first), m.
const MOVE_CLEARANCE_M: f64 = 0.4;

/// MoveToDig close enough: a move whose tip has come within this distance of the start's tip (r, z)
/// and has stopped getting closer begins the dig from there, m.
const MOVE_CLOSE_ENOUGH_M: f64 = 0.3;

/// MoveToDig close enough: how long the tip must have stopped getting closer (by 1 cm), s.
const MOVE_CLOSE_ENOUGH_WAIT_S: f64 = 2.0;

/// MoveToDig close enough: the largest remaining swing error, rad (2 deg).
const MOVE_CLOSE_ENOUGH_SWING_RAD: f64 = 0.035;

/// MoveToDig blocked: a commanded implement cylinder whose port has been at
/// [`RELIEF_RELIFT_FRACTION`] of relief this long, with the tip no longer getting closer (for
/// [`MOVE_CLOSE_ENOUGH_WAIT_S`]) and not close enough to dig, is pushing against something it cannot
/// move (the bucket's back or side on the terrain, which the map along the digging plane does not
/// show): the move is abandoned then, not at its time-out, s.
const MOVE_BLOCKED_S: f64 = 2.0;

/// MoveToDig: spacing of the terrain heights along the digging plane the clearance is judged on, m.
const CLEARANCE_STEP_M: f64 = 0.1;

/// Dump: a bucket that has not opened further for this long at full command is held (resting in the
/// spoil, or still in the cut: its port at relief); the boom then lifts while it keeps opening, s.
const STALL_RELIFT_S: f64 = 3.0;

/// Dump: a bucket whose opening port has stayed at or above this fraction of its relief pressure for
/// [`RELIEF_RELIFT_S`] is held too, even while it creeps open (a bucket pushed back into the spoil
/// pile yields slowly at relief); the boom lifts it clear.
const RELIEF_RELIFT_FRACTION: f64 = 0.9;

/// Dump: how long the opening port must stay near relief before the boom lifts, s.
const RELIEF_RELIFT_S: f64 = 0.5;

/// Where a dig or cleanup starts, before Autodig's Boom-Down (or the cleanup probe).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StartPose {
    /// Joint angles, degrees in files.
    Joints {
        /// Boom angle.
        #[serde(rename = "boom_deg", with = "planner::machine::degrees")]
        boom_rad: f64,
        /// Stick angle (relative to the boom).
        #[serde(rename = "stick_deg", with = "planner::machine::degrees")]
        stick_rad: f64,
        /// Bucket angle (relative to the stick).
        #[serde(rename = "bucket_deg", with = "planner::machine::degrees")]
        bucket_rad: f64,
    },
    /// A bucket tip pose in the base frame, solved by inverse kinematics.
    Tip {
        /// Tip `x`, m.
        x_m: f64,
        /// Tip `z`, m.
        z_m: f64,
        /// Absolute bucket angle, degrees in files.
        #[serde(rename = "bucket_abs_deg", with = "planner::machine::degrees")]
        bucket_abs_rad: f64,
    },
}

impl StartPose {
    /// The joint angles of this pose.
    ///
    /// # Errors
    /// [`ControllerError::Kinematics`] if the tip pose is out of reach or beyond the limits.
    pub fn resolve(&self, kin: &Kinematics) -> Result<JointAngles, ControllerError> {
        match *self {
            StartPose::Joints {
                boom_rad,
                stick_rad,
                bucket_rad,
            } => Ok(JointAngles {
                boom_rad,
                stick_rad,
                bucket_rad,
            }),
            StartPose::Tip {
                x_m,
                z_m,
                bucket_abs_rad,
            } => Ok(kin.inverse(&BucketPose {
                x_m,
                z_m,
                bucket_abs_rad,
            })?),
        }
    }
}

/// One step of the plan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Action {
    /// Autodig from `start` at swing angle `swing_rad`.
    Dig {
        /// Swing angle of the digging plane (degrees in files).
        #[serde(rename = "swing_deg", with = "planner::machine::degrees")]
        swing_rad: f64,
        /// Start pose above the dig.
        start: StartPose,
    },
    /// Floor cleanup along `plan`, then Autodig from Pre-Dig.
    Cleanup {
        /// Swing angle of the digging plane (degrees in files).
        #[serde(rename = "swing_deg", with = "planner::machine::degrees")]
        swing_rad: f64,
        /// Start pose above the floor at the start radius.
        start: StartPose,
        /// Start and minimum radius of the floor path.
        plan: CleanupPlan,
    },
    /// Track straight backwards by `distance_m` (> 0).
    TrackBack {
        /// Distance, m.
        distance_m: f64,
    },
}

/// The kind of an action, as reported in the statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionKind {
    /// Autodig.
    Dig,
    /// Cleanup followed by Autodig.
    Cleanup,
    /// Tracking backwards.
    TrackBack,
}

impl Action {
    /// The action's kind.
    pub fn kind(&self) -> ActionKind {
        match self {
            Action::Dig { .. } => ActionKind::Dig,
            Action::Cleanup { .. } => ActionKind::Cleanup,
            Action::TrackBack { .. } => ActionKind::TrackBack,
        }
    }

    fn swing_rad(&self) -> Option<f64> {
        match self {
            Action::Dig { swing_rad, .. } | Action::Cleanup { swing_rad, .. } => Some(*swing_rad),
            Action::TrackBack { .. } => None,
        }
    }
}

/// A P-controller on one valve: `command = sign * clamp(kp * error, +-max)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PGain {
    /// Proportional gain, command per unit of error (per rad or per m).
    pub kp: f64,
    /// Largest command magnitude, `(0, 1]`.
    pub max_command: f64,
    /// Smallest command magnitude outside the tolerance, `[0, max_command]`: an open-centre valve
    /// barely moves a loaded cylinder at small spool openings.
    #[serde(default)]
    pub min_command: f64,
    /// Rate feedback, command per rad/s (or m/s): damps the swing's large inertia. Default 0.
    #[serde(default)]
    pub kd: f64,
    /// The target counts as reached within this error (rad or m).
    pub tolerance: f64,
}

impl PGain {
    fn command(&self, error: f64) -> f64 {
        self.command_damped(error, 0.0)
    }

    fn command_damped(&self, error: f64, rate: f64) -> f64 {
        let u = self.kp * error - self.kd * rate;
        if !u.is_finite() || error.abs() <= self.tolerance {
            return 0.0;
        }
        let floor = self.min_command.clamp(0.0, self.max_command);
        u.abs().clamp(floor, self.max_command).copysign(u)
    }
}

/// The grid a range scan is binned into (world frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanGrid {
    /// West edge, m. Default -8.
    pub x_min_m: f64,
    /// South edge, m. Default -10.
    pub y_min_m: f64,
    /// Cell size, m. Default 0.1.
    pub cell_m: f64,
    /// Extent east, m. Default 24.
    pub size_x_m: f64,
    /// Extent north, m. Default 20.
    pub size_y_m: f64,
    /// Longest occlusion gap filled by interpolation, cells. Default 200 (the bench top behind the crest is in the shadow).
    pub max_gap_cells: usize,
}

impl Default for ScanGrid {
    fn default() -> Self {
        Self {
            x_min_m: -8.0,
            y_min_m: -10.0,
            cell_m: 0.1,
            size_x_m: 24.0,
            size_y_m: 20.0,
            max_gap_cells: 200,
        }
    }
}

impl ScanGrid {
    /// Bins world points `[x, y, z]` into a terrain map (planner::terrain, thesis 3.2). Allocates; call
    /// it outside the control step.
    ///
    /// # Errors
    /// [`ControllerError::Config`] with the terrain error's text (no points, gaps too large).
    pub fn terrain(&self, points: &[[f64; 3]]) -> Result<TerrainGrid, ControllerError> {
        let n = |size: f64| (size / self.cell_m).round().max(1.0) as usize;
        TerrainGrid::from_scan(
            points,
            self.x_min_m,
            self.y_min_m,
            self.cell_m,
            n(self.size_x_m),
            n(self.size_y_m),
            self.max_gap_cells,
        )
        .map_err(|e| ControllerError::Config {
            field: "scan",
            reason: e.to_string(),
        })
    }
}

/// Work cycle parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CycleConfig {
    /// The plan. Default: three digs into the default bench, straight ahead and 7 degrees to each side.
    pub actions: Vec<Action>,
    /// Start over at the first action after the last one. Default true.
    pub repeat: bool,
    /// Stop after this many digs (dig and cleanup actions). Default none (`repeat` false: one pass).
    pub max_digs: Option<u32>,
    /// Swing angle of the spoil pile, degrees in files. Default -90 (the default bench's pile).
    #[serde(rename = "dump_swing_deg", with = "planner::machine::degrees")]
    pub dump_swing_rad: f64,
    /// Swing angle to return to after the last action, degrees in files. Default 0.
    #[serde(rename = "home_swing_deg", with = "planner::machine::degrees")]
    pub home_swing_rad: f64,
    /// Boom angle to raise to before swinging, degrees in files. Default 42 (the bucket clears the
    /// default bench's top).
    #[serde(rename = "carry_boom_deg", with = "planner::machine::degrees")]
    pub carry_boom_rad: f64,
    /// ... or until the bucket tip is this high (base frame), whichever comes first, m. Default 2.8
    /// (0.8 m above the default bench's top).
    pub carry_tip_z_m: f64,
    /// Bucket joint angle (relative to the stick) that empties the bucket, degrees in files. Default 20.
    #[serde(rename = "dump_bucket_deg", with = "planner::machine::degrees")]
    pub dump_bucket_rad: f64,
    /// Hold the dump pose this long, s. Default 1.0.
    pub dump_hold_s: f64,
    /// Implement P-controllers (error in rad). Default kp 2, max 0.8, tolerance 0.03 rad.
    pub joint: PGain,
    /// Swing P-controller (error in rad). Default kp 1.5, max 0.7, tolerance 0.03 rad.
    pub swing: PGain,
    /// Track P-controller (error in m). Default kp 1.0, max 0.6, tolerance 0.05 m.
    pub track: PGain,
    /// A target must hold this long to count as reached, s. Default 0.2.
    pub settle_s: f64,
    /// A move (to the dig, to the dump, the dump itself, tracking) that takes longer is a fault, s.
    /// Default 40.
    pub move_timeout_s: f64,
    /// Ask for a range scan before each dig. Default true.
    pub scan: bool,
    /// Wait this long for the scan, then dig without perception, s. Default 5.
    pub scan_timeout_s: f64,
    /// Use the perception enhancements when a terrain map is available. Default true.
    pub perception: bool,
    /// Pre-dig section along the digging plane: from this radius, m. Default 1.
    pub section_r_min_m: f64,
    /// Pre-dig section: to this radius, m. Default 12.
    pub section_r_max_m: f64,
    /// Pre-dig section: sample spacing, m. Default 0.05.
    pub section_step_m: f64,
    /// Wait this long after Capture before weighing, s. Default 0.8.
    pub weigh_settle_s: f64,
    /// Average the payload estimate over at least this window, s. Default 1.0: the implement keeps
    /// oscillating on its oil columns after the valves close (about 2 Hz on the default machine, the
    /// static estimate swinging by +-35 %), and a 0.3 s window, part of one period, read up to 20 %
    /// off. Weigh therefore ends at the first whole period of that oscillation after the window (at
    /// most 1 s later; a steady estimate ends at the window), so a short window stays unbiased.
    pub weigh_window_s: f64,
    /// Detect the floor on the first cleanup and reuse it (Table 5), or every time.
    pub floor_policy: FloorPolicy,
    /// A cleanup's probe contact above this elevation (base frame: the track ground is z = 0) is
    /// material, not the floor, and is not kept for later cleanups: the machine stands on the floor
    /// it levels, or above it in a cut. (The demo's first cleanup started over what the digs had left
    /// of the bench and "detected" the floor 1.68 m up; every later cleanup reused it.) m. Default 0.3.
    pub floor_max_z_m: f64,
    /// An action of the plan abandoned on a control fault (a move timing out, the floor not found,
    /// Autodig rejecting its inputs) is tried again this many times before the plan goes on with the
    /// next one. Plans pushed by the planner (`crate::planned`) are not retried: it plans again from the
    /// new terrain. Default 1.
    pub retries: u32,
    /// The grid scans are binned into.
    pub scan_grid: ScanGrid,
}

impl Default for CycleConfig {
    fn default() -> Self {
        let dig = |swing_deg: f64| Action::Dig {
            swing_rad: swing_deg.to_radians(),
            // The default bench's start: tip 7.5 m out (stick at about -45 degrees absolute), 0.4 m
            // above the bench top, bucket opened to -55 degrees so Pre-Dig's curl bites the edge in;
            // Boom-Down lowers it onto the bench.
            start: StartPose::Tip {
                x_m: 7.5,
                z_m: 2.4,
                bucket_abs_rad: (-55.0_f64).to_radians(),
            },
        };
        Self {
            actions: vec![dig(0.0), dig(7.0), dig(-7.0)],
            repeat: true,
            max_digs: None,
            dump_swing_rad: (-90.0_f64).to_radians(),
            home_swing_rad: 0.0,
            carry_boom_rad: 42.0_f64.to_radians(),
            carry_tip_z_m: 2.8,
            dump_bucket_rad: 20.0_f64.to_radians(),
            dump_hold_s: 1.0,
            joint: PGain {
                kp: 2.0,
                max_command: 0.8,
                min_command: 0.2,
                kd: 0.0,
                tolerance: 0.03,
            },
            swing: PGain {
                kp: 1.5,
                max_command: 0.7,
                min_command: 0.15,
                kd: 1.0,
                tolerance: 0.03,
            },
            track: PGain {
                kp: 1.0,
                max_command: 0.6,
                min_command: 0.2,
                kd: 0.0,
                tolerance: 0.05,
            },
            settle_s: 0.2,
            move_timeout_s: 40.0,
            scan: true,
            scan_timeout_s: 5.0,
            perception: true,
            section_r_min_m: 1.0,
            section_r_max_m: 12.0,
            section_step_m: 0.05,
            weigh_settle_s: 0.8,
            weigh_window_s: 1.0,
            floor_policy: FloorPolicy::DetectOnce,
            floor_max_z_m: 0.3,
            retries: 1,
            scan_grid: ScanGrid::default(),
        }
    }
}

impl CycleConfig {
    /// Checks every parameter: finite, in range and consistent (a move's settle time inside its
    /// timeout, the pre-dig section and the scan grid of bounded size, P-controllers whose smallest
    /// command does not exceed their largest), and every action of the plan (angles, poses, cleanup
    /// radii, tracking distances). Angles are checked in degrees, as the file writes them.
    ///
    /// # Errors
    /// The first [`ParamError`] (section `cycle`).
    pub fn validate(&self) -> Result<(), ParamError> {
        const S: &str = "cycle";
        for (i, action) in self.actions.iter().enumerate() {
            action.validate(i)?;
        }
        if let Some(n) = self.max_digs {
            check_count(S, "max_digs", u64::from(n), 1, 100_000, "")?;
        }
        check_count(S, "retries", u64::from(self.retries), 0, 100, "")?;
        let swing = Limits::closed(-360.0, 360.0, "deg");
        check_deg(S, "dump_swing_deg", self.dump_swing_rad, swing)?;
        check_deg(S, "home_swing_deg", self.home_swing_rad, swing)?;
        check_deg(
            S,
            "carry_boom_deg",
            self.carry_boom_rad,
            Limits::closed(-90.0, 90.0, "deg"),
        )?;
        check_deg(
            S,
            "dump_bucket_deg",
            self.dump_bucket_rad,
            Limits::closed(-180.0, 180.0, "deg"),
        )?;
        let height = Limits::closed(-20.0, 20.0, "m");
        check(S, "carry_tip_z_m", self.carry_tip_z_m, height, "")?;
        check(S, "floor_max_z_m", self.floor_max_z_m, height, "")?;
        check(
            S,
            "move_timeout_s",
            self.move_timeout_s,
            Limits::above(0.0, 3600.0, "s"),
            "",
        )?;
        for (key, v) in [
            ("settle_s", self.settle_s),
            ("dump_hold_s", self.dump_hold_s),
        ] {
            check(
                S,
                key,
                v,
                Limits::open(0.0, self.move_timeout_s, "s"),
                "positive and shorter than move_timeout_s",
            )?;
        }
        check(
            S,
            "scan_timeout_s",
            self.scan_timeout_s,
            Limits::above(0.0, 600.0, "s"),
            "",
        )?;
        check(
            S,
            "weigh_settle_s",
            self.weigh_settle_s,
            Limits::closed(0.0, 60.0, "s"),
            "",
        )?;
        check(
            S,
            "weigh_window_s",
            self.weigh_window_s,
            Limits::above(0.0, 60.0, "s"),
            "",
        )?;
        check(
            S,
            "section_r_min_m",
            self.section_r_min_m,
            Limits::closed(0.0, 50.0, "m"),
            "",
        )?;
        check(
            S,
            "section_r_max_m",
            self.section_r_max_m,
            Limits::above(self.section_r_min_m, 50.0, "m"),
            "beyond section_r_min_m",
        )?;
        check(
            S,
            "section_step_m",
            self.section_step_m,
            Limits::closed(0.005, 1.0, "m"),
            "",
        )?;
        for (key, gain) in [
            ("joint", &self.joint),
            ("swing", &self.swing),
            ("track", &self.track),
        ] {
            gain.validate(key)?;
        }
        self.scan_grid.validate()
    }
}

impl Action {
    /// Checks the `i`-th action of a plan (`cycle.actions.i.*`).
    fn validate(&self, i: usize) -> Result<(), ParamError> {
        const S: &str = "cycle";
        let key = |k: &str| format!("actions.{i}.{k}");
        let (swing_rad, start) = match self {
            Action::TrackBack { distance_m } => {
                return check(
                    S,
                    &key("distance_m"),
                    *distance_m,
                    Limits::above(0.0, 100.0, "m"),
                    "",
                );
            }
            Action::Dig { swing_rad, start } => (*swing_rad, start),
            Action::Cleanup {
                swing_rad,
                start,
                plan,
            } => {
                let radius = Limits::above(0.0, 50.0, "m");
                check(
                    S,
                    &key("plan.start_radius_m"),
                    plan.start_radius_m,
                    radius,
                    "",
                )?;
                check(
                    S,
                    &key("plan.min_radius_m"),
                    plan.min_radius_m,
                    Limits::below(0.0, plan.start_radius_m, "m"),
                    "below plan.start_radius_m",
                )?;
                (*swing_rad, start)
            }
        };
        check_deg(
            S,
            &key("swing_deg"),
            swing_rad,
            Limits::closed(-360.0, 360.0, "deg"),
        )?;
        let angle = Limits::closed(-360.0, 360.0, "deg");
        match *start {
            StartPose::Joints {
                boom_rad,
                stick_rad,
                bucket_rad,
            } => {
                check_deg(S, &key("start.boom_deg"), boom_rad, angle)?;
                check_deg(S, &key("start.stick_deg"), stick_rad, angle)?;
                check_deg(S, &key("start.bucket_deg"), bucket_rad, angle)
            }
            StartPose::Tip {
                x_m,
                z_m,
                bucket_abs_rad,
            } => {
                let reach = Limits::closed(-50.0, 50.0, "m");
                check(S, &key("start.x_m"), x_m, reach, "")?;
                check(S, &key("start.z_m"), z_m, reach, "")?;
                check_deg(
                    S,
                    &key("start.bucket_abs_deg"),
                    bucket_abs_rad,
                    Limits::closed(-720.0, 720.0, "deg"),
                )
            }
        }
    }
}

impl PGain {
    /// Checks a controller `cycle.<name>`: gains finite, commands in `(0, 1]` with the smallest not
    /// above the largest, a positive tolerance.
    fn validate(&self, name: &str) -> Result<(), ParamError> {
        const S: &str = "cycle";
        let key = |k: &str| format!("{name}.{k}");
        check(S, &key("kp"), self.kp, Limits::above(0.0, 100.0, ""), "")?;
        check(S, &key("kd"), self.kd, Limits::closed(0.0, 100.0, ""), "")?;
        check(
            S,
            &key("max_command"),
            self.max_command,
            Limits::above(0.0, 1.0, ""),
            "",
        )?;
        check(
            S,
            &key("min_command"),
            self.min_command,
            Limits::closed(0.0, self.max_command, ""),
            "at most max_command",
        )?;
        check(
            S,
            &key("tolerance"),
            self.tolerance,
            Limits::above(0.0, 1.0, "rad or m"),
            "",
        )
    }
}

impl ScanGrid {
    /// Checks `cycle.scan_grid`: finite edges, a cell size of 2 cm to 1 m, at most 4 million cells
    /// (as the simulator's terrain grid).
    ///
    /// # Errors
    /// The first [`ParamError`].
    pub fn validate(&self) -> Result<(), ParamError> {
        const S: &str = "cycle";
        let edge = Limits::closed(-1.0e4, 1.0e4, "m");
        check(S, "scan_grid.x_min_m", self.x_min_m, edge, "")?;
        check(S, "scan_grid.y_min_m", self.y_min_m, edge, "")?;
        check(
            S,
            "scan_grid.cell_m",
            self.cell_m,
            Limits::closed(0.02, 1.0, "m"),
            "",
        )?;
        let size = Limits::above(0.0, 2.0e4, "m");
        check(S, "scan_grid.size_x_m", self.size_x_m, size, "")?;
        check(S, "scan_grid.size_y_m", self.size_y_m, size, "")?;
        let cells = (self.size_x_m / self.cell_m) * (self.size_y_m / self.cell_m);
        if cells > 4.0e6 {
            return Err(ParamError::new(
                S,
                "scan_grid.cell_m",
                Some(toml_float(self.cell_m)),
                format!("gives {cells:.0} cells over the grid's size (at most 4e6)"),
            ));
        }
        check_count(
            S,
            "scan_grid.max_gap_cells",
            u64::try_from(self.max_gap_cells).unwrap_or(u64::MAX),
            0,
            100_000,
            "",
        )
    }
}

/// Statistics of one dig or cleanup (thesis 6.1, Tables 3 and 4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigStats {
    /// Dig number, from 0.
    pub index: u32,
    /// Dig or cleanup.
    pub action: ActionKind,
    /// Swing angle of the digging plane, rad.
    pub swing_rad: f64,
    /// When the dig began (Boom-Down or the cleanup probe), s (bus time).
    pub start_time_s: f64,
    /// Duration from the start of Boom-Down (or of the cleanup) to the end of Capture, s.
    pub time_s: f64,
    /// Time the bucket tip was below the pre-dig terrain, s (thesis 6.1); 0 without a terrain map.
    pub ground_contact_time_s: f64,
    /// Energy: the integral of |cylinder force x cylinder displacement| summed over the three
    /// cylinders during the dig, J (thesis 6.1; energy spent lowering against a holding pressure counts
    /// too, as the pumps deliver it).
    pub energy_j: f64,
    /// Volume swept over the cutting edge (3.2), m^3; 0 without a terrain map.
    pub swept_volume_m3: f64,
    /// Weight of the material from the static payload estimate after Capture, N (`None` if the
    /// estimate was unavailable).
    pub weight_n: Option<f64>,
    /// Why Autodig ended.
    pub end_reason: Option<EndReason>,
    /// Why cleanup waypoint following ended (cleanups only).
    pub hand_over: Option<HandOverReason>,
    /// The floor elevation used by a cleanup, m (base frame).
    pub floor_z_m: Option<f64>,
    /// Whether the perception enhancements were active.
    pub perception: bool,
}

impl DigStats {
    /// Energy in kJ (the unit of the thesis's tables).
    pub fn energy_kj(&self) -> f64 {
        self.energy_j * 1e-3
    }
}

/// The phase of the work cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Phase {
    /// Not started.
    Idle,
    /// Waiting for a range scan.
    Scan,
    /// Swinging to the dig and moving the implement to the start pose.
    MoveToDig,
    /// Autodig running.
    Autodig,
    /// Cleanup waypoints in position mode.
    Cleanup,
    /// Holding still after Capture to weigh the payload.
    Weigh,
    /// Raising the boom and swinging to the spoil pile.
    SwingToDump,
    /// Uncurling the bucket over the pile.
    Dump,
    /// Tracking backwards.
    TrackBack,
    /// Swinging home after the last action.
    Return,
    /// All done.
    Finished,
}

impl Phase {
    /// The gateway mode this phase needs (`None`: stay disarmed).
    pub const fn mode(self) -> Option<ArmMode> {
        match self {
            Phase::Idle | Phase::Finished => None,
            Phase::Cleanup => Some(ArmMode::Position),
            _ => Some(ArmMode::Valve),
        }
    }
}

/// What the cycle wants sent this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CycleCommand {
    /// All valves neutral.
    Neutral,
    /// Valve commands `[boom, stick, bucket, swing, left track, right track]` in `[-1, 1]`.
    Valves([f64; 6]),
    /// Position setpoints `[boom, stick, bucket, swing]`, rad.
    Position([f64; 4]),
}

/// The cycle's output for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput {
    /// The gateway mode needed now.
    pub want: Option<ArmMode>,
    /// The command (meaningful only when armed in `want`).
    pub command: CycleCommand,
}

#[derive(Debug, Clone, Copy)]
struct DigRecord {
    stats: DigStats,
    last_lengths_m: Option<[f64; 3]>,
    last_s: Option<f64>,
    weigh: WeighAverage,
    /// Weigh found the implement supported: lifts so far and the boom angle of the current lift.
    weigh_lifts: u32,
    weigh_lift_to_rad: Option<f64>,
}

/// Weigh: deviations of the payload estimate from its running mean smaller than this do not count as a
/// side change of the implement's oscillation (noise), N.
const WEIGH_DEADBAND_N: f64 = 1_000.0;
/// Weigh: how long past `weigh_settle_s + weigh_window_s` to wait for the end of a whole oscillation
/// period before falling back to the plain mean, s (two periods of the default machine's 2 Hz).
const WEIGH_MAX_EXTRA_S: f64 = 1.0;
/// Weigh: a payload estimate below minus this is not a payload but a bucket the ground carries (a dig
/// or cleanup that ended with the bucket resting on the soil: the boom cylinder then holds less than
/// the empty implement's weight, seen as -2500 to -4800 kg in 100-dig sessions), kg. The boom lifts
/// [`WEIGH_LIFT_RAD`] and the weighing starts over, at most [`WEIGH_MAX_LIFTS`] times; after that the
/// weight is reported unknown.
const WEIGH_SUPPORTED_KG: f64 = 300.0;
/// Weigh: the boom lift that takes a supported bucket off the ground, rad (about 8.6 deg: 0.5-0.8 m
/// at the tip on the default machine).
const WEIGH_LIFT_RAD: f64 = 0.15;
/// Weigh: lifts before the weight is reported unknown.
const WEIGH_MAX_LIFTS: u32 = 2;
/// Weigh: a lift that takes longer ends anyway (a boom against its stop or stalled), s.
const WEIGH_LIFT_MAX_S: f64 = 3.0;

/// The payload estimate averaged over whole periods of the implement's oscillation (Weigh).
///
/// After the valves close the implement keeps swinging on its oil columns (about 2 Hz on the default
/// machine) and the static estimate with it, by +-10 kN after a dig and up to +-35 kN after a cleanup
/// (measured in the simulator). A window that is not a whole number of periods reads part of a swing:
/// with the HIL plan's 0.2 s window (`tests/src/plan.rs`) the same full bucket (25 kN) read -5..63 kN.
/// So the mean is taken from the first time the estimate crosses its running mean to a crossing an
/// even number of crossings later (whole periods), the first one after the configured window; a steady
/// estimate (never outside the deadband) is averaged over the window as before.
#[derive(Debug, Clone, Copy, Default)]
struct WeighAverage {
    /// Every sample since the settle time (the reference level for the crossings), N.
    all_sum_n: f64,
    all_samples: u32,
    /// Samples from the first crossing on, N.
    sum_n: f64,
    samples: u32,
    /// The same up to (without) the latest whole-period boundary, N.
    whole_sum_n: f64,
    whole_samples: u32,
    /// Side of the reference of the last sample outside the deadband.
    above: Option<bool>,
    crossings: u32,
}

impl WeighAverage {
    /// Adds a sample; returns whether it starts a new whole period (it is then not yet in the mean).
    fn push(&mut self, weight_n: f64) -> bool {
        self.all_sum_n += weight_n;
        self.all_samples += 1;
        let reference = self.all_sum_n / f64::from(self.all_samples);
        let deviation = weight_n - reference;
        let mut crossed = false;
        if deviation.abs() > WEIGH_DEADBAND_N {
            let above = deviation > 0.0;
            if self.above.is_some_and(|a| a != above) {
                self.crossings += 1;
                crossed = true;
            }
            self.above = Some(above);
        }
        let boundary = crossed && self.crossings >= 3 && self.crossings % 2 == 1;
        if boundary {
            self.whole_sum_n = self.sum_n;
            self.whole_samples = self.samples;
        }
        if self.crossings >= 1 {
            self.sum_n += weight_n;
            self.samples += 1;
        }
        boundary
    }

    /// No sample has left the deadband around the running mean.
    fn steady(&self) -> bool {
        self.above.is_none()
    }

    /// The mean over whole periods if `at_boundary`, else over every sample.
    fn mean_n(&self, at_boundary: bool) -> Option<f64> {
        if at_boundary && self.whole_samples > 0 {
            Some(self.whole_sum_n / f64::from(self.whole_samples))
        } else if self.all_samples > 0 {
            Some(self.all_sum_n / f64::from(self.all_samples))
        } else {
            None
        }
    }
}

/// The work cycle state machine.
#[derive(Debug, Clone)]
pub struct WorkCycle {
    config: CycleConfig,
    autodig_config: AutodigConfig,
    maps: AutodigMaps,
    cleanup_config: CleanupConfig,
    bucket_width_m: f64,
    starts: Vec<JointAngles>,
    started: bool,
    phase: Phase,
    phase_since_s: f64,
    settle_since_s: Option<f64>,
    action_index: usize,
    digs_done: u32,
    autodig: Option<Autodig>,
    cleanup: Option<Cleanup>,
    swept: Option<SweptVolume>,
    floor: FloorEstimate,
    terrain: Option<TerrainGrid>,
    terrain_fresh: bool,
    scan_request: bool,
    record: Option<DigRecord>,
    stats: Vec<DigStats>,
    track_target_m: f64,
    last_now_s: f64,
    /// MoveToDig: the tip has been lifted to the start height once (lift-first is not re-entered).
    lifted: bool,
    /// MoveToDig stall escalation per implement joint: the extra command magnitude
    /// ([`STALL_BOOST_PER_S`]), the smallest error so far and when it last shrank
    /// ([`STALL_PROGRESS_RAD`]); and the time of the last move step.
    stall_boost: [f64; 3],
    stall_best_rad: [f64; 3],
    stall_progress_s: [f64; 3],
    /// Dump: since when the bucket's opening port has been near relief ([`RELIEF_RELIFT_FRACTION`]);
    /// MoveToDig: since when a commanded implement cylinder's port has been near relief
    /// ([`MOVE_BLOCKED_S`]).
    relief_since_s: Option<f64>,
    last_move_s: Option<f64>,
    /// MoveToDig close enough: the tip's least distance to the start's tip so far and when it last
    /// shrank by 1 cm.
    move_best_m: f64,
    move_progress_s: f64,
    /// MoveToDig: the boom is lifting the tip back to its terrain clearance.
    clearing: bool,
    /// MoveToDig: the terrain heights along the start's digging plane, every [`CLEARANCE_STEP_M`]
    /// from the swing axis (NaN where unknown); filled on the first use in a move.
    clearance_profile: Vec<f64>,
    /// Hook for an external action source (`crate::planned`): hold in Idle when the actions run out.
    external_plan: bool,
    /// Control faults of the current action so far.
    failed_attempts: u32,
    /// The current action was abandoned and is tried again when the bucket has been emptied.
    retry_pending: bool,
}

impl WorkCycle {
    /// A cycle for the machine of `kin` (resolves the start poses).
    ///
    /// # Errors
    /// [`ControllerError`] for an invalid config, an unreachable start pose, or invalid Autodig or
    /// cleanup parameters.
    pub fn new(
        config: CycleConfig,
        autodig_config: AutodigConfig,
        maps: AutodigMaps,
        cleanup_config: CleanupConfig,
        bucket_width_m: f64,
        kin: &Kinematics,
    ) -> Result<Self, ControllerError> {
        config.validate()?;
        autodig_config.validate()?;
        cleanup_config.validate()?;
        let mut starts = Vec::with_capacity(config.actions.len());
        for a in &config.actions {
            starts.push(match a {
                Action::Dig { start, .. } | Action::Cleanup { start, .. } => start.resolve(kin)?,
                Action::TrackBack { .. } => JointAngles::default(),
            });
        }
        let floor = FloorEstimate::new(config.floor_policy);
        Ok(Self {
            config,
            autodig_config,
            maps,
            cleanup_config,
            bucket_width_m,
            starts,
            started: false,
            phase: Phase::Idle,
            phase_since_s: 0.0,
            settle_since_s: None,
            action_index: 0,
            digs_done: 0,
            autodig: None,
            cleanup: None,
            swept: None,
            floor,
            terrain: None,
            terrain_fresh: false,
            scan_request: false,
            record: None,
            stats: Vec::new(),
            track_target_m: 0.0,
            last_now_s: 0.0,
            lifted: false,
            stall_boost: [0.0; 3],
            stall_best_rad: [f64::INFINITY; 3],
            stall_progress_s: [0.0; 3],
            relief_since_s: None,
            last_move_s: None,
            move_best_m: f64::INFINITY,
            move_progress_s: 0.0,
            clearing: false,
            clearance_profile: Vec::new(),
            external_plan: false,
            failed_attempts: 0,
            retry_pending: false,
        })
    }

    /// Hook for an external action source (the dig planner, `crate::planned`): with `on`, the cycle
    /// holds neutral in Idle when its actions run out (instead of returning home) until
    /// [`Self::push_action`] adds one.
    pub fn set_external_plan(&mut self, on: bool) {
        self.external_plan = on;
    }

    /// Hook for the online soil hardness index (thesis 5.2, `crate::planned`): the index Autodig uses
    /// from the next dig on. Non-finite values are ignored.
    pub fn set_hardness_index(&mut self, index: f64) {
        if index.is_finite() {
            self.autodig_config.hardness_index = index;
        }
    }

    /// True when the cycle waits for the next action from an external source.
    pub fn needs_action(&self) -> bool {
        self.external_plan
            && self.started
            && self.phase == Phase::Idle
            && self.action_index >= self.config.actions.len()
            && !self.finished_digs()
    }

    /// Appends an action to the plan (its start pose resolved now).
    ///
    /// # Errors
    /// [`ControllerError::Kinematics`] for an unreachable start, [`ControllerError::Config`] for a
    /// non-positive track distance.
    pub fn push_action(&mut self, action: Action, kin: &Kinematics) -> Result<(), ControllerError> {
        let start = match &action {
            Action::Dig { start, .. } | Action::Cleanup { start, .. } => start.resolve(kin)?,
            Action::TrackBack { distance_m } => {
                if !(distance_m.is_finite() && *distance_m > 0.0) {
                    return Err(ControllerError::Config {
                        field: "actions.track_back.distance_m",
                        reason: "must be finite and > 0".to_owned(),
                    });
                }
                JointAngles::default()
            }
        };
        self.config.actions.push(action);
        self.starts.push(start);
        Ok(())
    }

    /// Starts (or resumes) the plan at the next step.
    pub fn start(&mut self) {
        self.started = true;
    }

    /// Ends the plan: the machine holds neutral and disarms.
    pub fn stop(&mut self) {
        self.started = false;
        self.autodig = None;
        self.cleanup = None;
        self.phase = Phase::Finished;
    }

    /// The configuration.
    pub fn config(&self) -> &CycleConfig {
        &self.config
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Autodig's stage while it runs.
    pub fn autodig_stage(&self) -> Option<Stage> {
        self.autodig.as_ref().map(Autodig::stage)
    }

    /// The index of the current action in the plan.
    pub fn action_index(&self) -> usize {
        self.action_index
    }

    /// The current action.
    pub fn action(&self) -> Option<&Action> {
        self.config.actions.get(self.action_index)
    }

    /// Digs completed (dig and cleanup actions).
    pub fn digs_done(&self) -> u32 {
        self.digs_done
    }

    /// Statistics of the completed digs.
    pub fn stats(&self) -> &[DigStats] {
        &self.stats
    }

    /// The floor estimate kept between cleanups.
    pub fn floor(&self) -> FloorEstimate {
        self.floor
    }

    /// The terrain map in use.
    pub fn terrain(&self) -> Option<&TerrainGrid> {
        self.terrain.as_ref()
    }

    /// The soil hardness index Autodig is configured with.
    pub fn hardness_index(&self) -> f64 {
        self.autodig
            .as_ref()
            .map_or(self.autodig_config.hardness_index, Autodig::hardness_index)
    }

    /// Whether a dig or cleanup is in progress (from the move to the dig to the end of the dump).
    pub fn in_dig(&self) -> bool {
        self.record.is_some()
            || (matches!(self.phase, Phase::Scan | Phase::MoveToDig)
                && self
                    .action()
                    .is_some_and(|a| a.kind() != ActionKind::TrackBack))
    }

    /// The swept volume of the running dig, m^3.
    pub fn swept_volume_m3(&self) -> Option<f64> {
        self.swept.as_ref().map(SweptVolume::volume_m3)
    }

    /// True once after the cycle asked for a range scan.
    pub fn take_scan_request(&mut self) -> bool {
        std::mem::take(&mut self.scan_request)
    }

    /// Hands over a terrain map (from a range scan); used by the next dig.
    pub fn provide_terrain(&mut self, terrain: TerrainGrid) {
        self.terrain = Some(terrain);
        self.terrain_fresh = true;
        self.clearance_profile.clear();
    }

    /// Called by the node when a fault stopped motion: a failed action is abandoned (its partial
    /// statistics are dropped), the bucket emptied, and the action tried again up to
    /// [`CycleConfig::retries`] times before the plan goes on with the next one; any other fault pauses
    /// the current phase, which resumes after the re-arm.
    pub fn on_fault(&mut self, control: bool) {
        if let Some(r) = &mut self.record {
            // The motion stopped: do not integrate across the gap.
            r.last_lengths_m = None;
            r.last_s = None;
        }
        self.settle_since_s = None;
        if control {
            let retry = !self.external_plan && self.failed_attempts < self.config.retries;
            if retry {
                self.failed_attempts += 1;
                tracing::warn!(
                    action = self.action_index,
                    attempt = self.failed_attempts + 1,
                    "action abandoned: it is tried again"
                );
            } else {
                tracing::warn!(action = self.action_index, "action abandoned: going on");
            }
            self.retry_pending = retry;
            self.autodig = None;
            self.cleanup = None;
            self.swept = None;
            self.record = None;
            if matches!(
                self.phase,
                Phase::MoveToDig | Phase::Autodig | Phase::Cleanup | Phase::Weigh
            ) {
                // Raise and empty whatever is in the bucket before going on.
                self.phase = Phase::SwingToDump;
            } else {
                if !std::mem::take(&mut self.retry_pending) {
                    self.action_index += 1;
                    self.failed_attempts = 0;
                }
                self.phase = Phase::Idle;
            }
        }
    }

    fn set_phase(&mut self, phase: Phase, now_s: f64) {
        tracing::debug!(?phase, "work cycle phase");
        self.phase = phase;
        self.phase_since_s = now_s;
        self.settle_since_s = None;
        self.lifted = false;
        self.stall_boost = [0.0; 3];
        self.stall_best_rad = [f64::INFINITY; 3];
        self.relief_since_s = None;
        self.last_move_s = None;
        self.move_best_m = f64::INFINITY;
        self.move_progress_s = now_s;
        self.clearing = false;
        self.clearance_profile.clear();
    }

    fn hold(&self) -> CycleOutput {
        CycleOutput {
            want: self.phase.mode(),
            command: CycleCommand::Neutral,
        }
    }

    /// True when `done` has held for `settle_s`.
    fn settled(&mut self, done: bool, now_s: f64) -> bool {
        if !done {
            self.settle_since_s = None;
            return false;
        }
        let since = *self.settle_since_s.get_or_insert(now_s);
        now_s - since >= self.config.settle_s
    }

    fn timed_out(&self, now_s: f64) -> bool {
        now_s - self.phase_since_s > self.config.move_timeout_s
    }

    /// One period at `now_s` with the estimate; `armed` is the mode the safety layer allows motion in.
    ///
    /// # Errors
    /// [`ControlFault`] when Autodig or cleanup reject their inputs, a waypoint is out of reach, or a
    /// move times out: send neutral, then call [`Self::on_fault`] with `control = true`.
    pub fn step(
        &mut self,
        now_s: f64,
        est: &Estimator,
        armed: Option<ArmMode>,
    ) -> Result<CycleOutput, ControlFault> {
        self.last_now_s = now_s;
        if self.phase == Phase::Idle {
            if !self.started {
                return Ok(self.hold());
            }
            self.begin_action(now_s, est);
        }
        let want = self.phase.mode();
        if want.is_some() && armed != want && self.phase != Phase::Scan {
            // Not (yet) allowed to move: hold, and keep the phase's clock from counting the wait.
            self.phase_since_s = now_s;
            self.settle_since_s = None;
            if let Some(r) = &mut self.record {
                r.last_lengths_m = None;
                r.last_s = None;
            }
            return Ok(self.hold());
        }
        let command = match self.phase {
            Phase::Idle | Phase::Finished => CycleCommand::Neutral,
            Phase::Scan => self.step_scan(now_s),
            Phase::MoveToDig => self.step_move_to_dig(now_s, est)?,
            Phase::Autodig => self.step_autodig(now_s, est)?,
            Phase::Cleanup => self.step_cleanup(now_s, est)?,
            Phase::Weigh => self.step_weigh(now_s, est),
            Phase::SwingToDump => self.step_swing_to(now_s, est, self.config.dump_swing_rad)?,
            Phase::Dump => self.step_dump(now_s, est)?,
            Phase::TrackBack => self.step_track(now_s, est)?,
            Phase::Return => self.step_swing_to(now_s, est, self.config.home_swing_rad)?,
        };
        Ok(CycleOutput {
            want: self.phase.mode(),
            command,
        })
    }

    fn finished_digs(&self) -> bool {
        self.config.max_digs.is_some_and(|n| self.digs_done >= n)
    }

    fn begin_action(&mut self, now_s: f64, est: &Estimator) {
        if self.action_index >= self.config.actions.len() {
            if self.external_plan && !self.finished_digs() {
                return; // hold in Idle until push_action
            }
            if self.config.repeat && !self.config.actions.is_empty() && !self.finished_digs() {
                self.action_index = 0;
            } else {
                self.set_phase(Phase::Return, now_s);
                return;
            }
        }
        if self.finished_digs() {
            self.set_phase(Phase::Return, now_s);
            return;
        }
        match self.config.actions.get(self.action_index) {
            Some(Action::TrackBack { distance_m }) => {
                let [l, r] = est.state().track_travel_m;
                self.track_target_m = 0.5 * (l + r) - distance_m;
                tracing::info!(distance_m, "tracking backwards");
                self.set_phase(Phase::TrackBack, now_s);
            }
            Some(_) => {
                if self.config.scan {
                    self.scan_request = true;
                    self.terrain_fresh = false;
                    self.set_phase(Phase::Scan, now_s);
                } else {
                    self.set_phase(Phase::MoveToDig, now_s);
                }
            }
            None => self.set_phase(Phase::Return, now_s),
        }
    }

    fn next_action(&mut self, now_s: f64) {
        if !std::mem::take(&mut self.retry_pending) {
            self.action_index += 1;
            self.failed_attempts = 0;
        }
        self.phase = Phase::Idle;
        self.phase_since_s = now_s;
    }

    fn step_scan(&mut self, now_s: f64) -> CycleCommand {
        if self.terrain_fresh {
            self.set_phase(Phase::MoveToDig, now_s);
        } else if now_s - self.phase_since_s > self.config.scan_timeout_s {
            tracing::warn!("no range scan in time: digging without the perception enhancements");
            self.set_phase(Phase::MoveToDig, now_s);
        }
        CycleCommand::Neutral
    }

    fn implement_toward(&self, q: &JointAngles, target: &JointAngles) -> ([f64; 3], bool) {
        let err = [
            target.boom_rad - q.boom_rad,
            target.stick_rad - q.stick_rad,
            target.bucket_rad - q.bucket_rad,
        ];
        let g = self.config.joint;
        let cmd = [0, 1, 2].map(|i| JOINT_SIGN[i] * g.command(err[i]));
        (cmd, err.iter().all(|e| e.abs() <= g.tolerance))
    }

    /// Stall escalation of the move's P-controller: the command of a joint that is commanded but
    /// has not come [`STALL_PROGRESS_RAD`] closer to its target for [`STALL_WAIT_S`] grows by
    /// [`STALL_BOOST_PER_S`] (up to `max_command`), and is held while the joint makes progress; a
    /// joint that reaches its tolerance or reverses starts from zero again.
    fn escalate_stalled(&mut self, now_s: f64, implement: &mut [f64; 3], error_rad: [f64; 3]) {
        let dt_s = self
            .last_move_s
            .map_or(0.0, |t| (now_s - t).clamp(0.0, 0.1));
        self.last_move_s = Some(now_s);
        let max = self.config.joint.max_command;
        for (i, cmd) in implement.iter_mut().enumerate() {
            let err = error_rad[i].abs();
            let boost = &mut self.stall_boost[i];
            // Restart when the joint is not commanded or the command reverses.
            if *cmd == 0.0 || !err.is_finite() || (*boost != 0.0 && boost.signum() != cmd.signum())
            {
                *boost = 0.0;
                self.stall_best_rad[i] = f64::INFINITY;
                continue;
            }
            if !self.stall_best_rad[i].is_finite()
                || err < self.stall_best_rad[i] - STALL_PROGRESS_RAD
            {
                self.stall_best_rad[i] = err;
                self.stall_progress_s[i] = now_s;
            }
            let magnitude = if now_s - self.stall_progress_s[i] > STALL_WAIT_S {
                (boost.abs() + STALL_BOOST_PER_S * dt_s).min(max)
            } else {
                boost.abs()
            };
            *boost = magnitude.copysign(*cmd);
            *cmd = (cmd.abs() + magnitude).min(max).copysign(*cmd);
        }
    }

    fn swing_toward(&self, swing_rad: f64, rate_rad_per_s: f64, target_rad: f64) -> (f64, bool) {
        let err = wrap_angle(target_rad - swing_rad);
        (
            self.config.swing.command_damped(err, rate_rad_per_s),
            err.abs() <= self.config.swing.tolerance,
        )
    }

    fn step_move_to_dig(
        &mut self,
        now_s: f64,
        est: &Estimator,
    ) -> Result<CycleCommand, ControlFault> {
        let (Some(action), Some(target)) = (
            self.config.actions.get(self.action_index).copied(),
            self.starts.get(self.action_index).copied(),
        ) else {
            self.next_action(now_s);
            return Ok(CycleCommand::Neutral);
        };
        let s = est.state();
        if self.timed_out(now_s) {
            let swing = action.swing_rad().unwrap_or(s.swing_rad);
            let ground_at_tip =
                self.highest_terrain(&s.pose, swing, (s.tip.x_m - 0.05, s.tip.x_m + 0.05));
            let target_tip = est.kinematics().forward(&target);
            tracing::warn!(
                ?ground_at_tip,
                target_z = target_tip.z_m,
                tip_x_m = s.tip.x_m,
                boom_err_deg = (target.boom_rad - s.joints.boom_rad).to_degrees(),
                stick_err_deg = (target.stick_rad - s.joints.stick_rad).to_degrees(),
                bucket_err_deg = (target.bucket_rad - s.joints.bucket_rad).to_degrees(),
                swing_err_deg = action
                    .swing_rad()
                    .map(|t| wrap_angle(t - s.swing_rad).to_degrees()),
                lifted = self.lifted,
                tip_z_m = s.tip.z_m,
                tip_error_m = (s.tip.x_m - target_tip.x_m).hypot(s.tip.z_m - target_tip.z_m),
                best_tip_error_m = self.move_best_m,
                since_progress_s = now_s - self.move_progress_s,
                joints_deg = ?[s.joints.boom_rad, s.joints.stick_rad, s.joints.bucket_rad]
                    .map(f64::to_degrees),
                clearing = self.clearing,
                "move to the dig timed out"
            );
            return Err(ControlFault::Timeout("move to the dig"));
        }
        let (mut implement, implement_done) = self.implement_toward(&s.joints, &target);
        // Lift first: while the tip is well below the start pose only the boom moves (up), so the
        // bucket is not dragged through the ground; the swing waits until the boom is up too.
        let target_tip = est.kinematics().forward(&target);
        let target_z = target_tip.z_m;
        // Latched: once lifted, the boom's P-controller alone settles it. Re-entering the full lift
        // whenever a gravity-assisted lowering overshot made a limit cycle (boom +-4 degrees) that
        // timed out the move.
        let low = !self.lifted && s.tip.z_m < target_z - 0.2;
        if !low {
            self.lifted = true;
        }
        // Boom up first, boom down last: bringing the stick in (or out) at a boom still below its
        // target sweeps the bucket down through the bench (from the dump pose to a start close in, at
        // a stick of -87 degrees, it came to rest on the face with the boom stalled 4 degrees short).
        let boom_band = 3.0 * self.config.joint.tolerance;
        // Terrain clearance: with the boom at its start angle, swinging the stick through the
        // vertical or opening the bucket sweeps the tip up to 0.7 m below the start height, into the
        // bench top when the start is down the face (the bucket then stalled in the cut, the stick
        // 16 deg short, and the move timed out). While the stick or the bucket has far to go, the boom
        // goal is the angle that keeps the tip clear of the known terrain between the tip and the
        // start; the boom comes down to the start angle last.
        // The swing must be done too before the boom comes down: a bucket lowered onto the face
        // while the swing still turns is dragged sideways through the soil and the swing stalls
        // short of its tolerance.
        let swing_far = action
            .swing_rad()
            .is_some_and(|t| wrap_angle(t - s.swing_rad).abs() > self.config.swing.tolerance);
        let far = swing_far
            || [
                target.stick_rad - s.joints.stick_rad,
                target.bucket_rad - s.joints.bucket_rad,
            ]
            .iter()
            .any(|e| e.abs() > boom_band);
        let clear_z = if far {
            let r = (s.tip.x_m.min(target_tip.x_m), s.tip.x_m.max(target_tip.x_m));
            let swing = action.swing_rad().unwrap_or(s.swing_rad);
            self.highest_terrain(&s.pose, swing, r)
                .map(|h| h + MOVE_CLEARANCE_M)
        } else {
            None
        };
        let boom_goal = clear_z.map_or(target.boom_rad, |z| {
            target.boom_rad.max(boom_for_tip_z(est, &s.joints, z))
        });
        // Clearing: the tip sank 0.1 m below the clearance height (the stick or bucket swept it
        // down); the boom lifts alone until the tip is 0.1 m above it (hysteresis, so the stick
        // and bucket do not stop and go every period).
        self.clearing = match clear_z {
            Some(z) if self.clearing => s.tip.z_m < z + 0.1,
            Some(z) => s.tip.z_m < z - 0.1,
            None => false,
        };
        let boom_err = boom_goal - s.joints.boom_rad;
        if low || self.clearing || boom_err > boom_band {
            // Full lift: at part command the open-centre bypass keeps the gallery below the boom's
            // holding pressure and the loaded boom stalls (as in SwingToDump).
            implement = [self.config.joint.max_command, 0.0, 0.0];
        } else if far && (boom_err < -boom_band || boom_goal > target.boom_rad) {
            // Lowering waits only for the large stick and bucket moves: their last degrees at the
            // P-controller's minimum command crawl, and the boom would wait seconds for them. Held
            // too while the clearance goal is above the start angle (the P-controller would lower
            // it toward the start).
            implement[0] = 0.0;
        }
        self.escalate_stalled(
            now_s,
            &mut implement,
            [
                target.boom_rad - s.joints.boom_rad,
                target.stick_rad - s.joints.stick_rad,
                target.bucket_rad - s.joints.bucket_rad,
            ],
        );
        let boom_clear =
            !low && s.joints.boom_rad >= target.boom_rad - 3.0 * self.config.joint.tolerance;
        let (swing, swing_done) = match action.swing_rad() {
            Some(t) if boom_clear => self.swing_toward(s.swing_rad, s.rates_rad_per_s[3], t),
            Some(_) => (0.0, false),
            None => (0.0, true),
        };
        // Blocked: a commanded cylinder pushing at relief (the port its valve command pressurises:
        // extending, a positive command, fills the head).
        let relief = &self.autodig_config.relief_pressure_pa;
        let at_relief = (0..3).any(|i| {
            let u = implement[i];
            let port_pa = if u > 0.0 {
                s.head_pressure_pa[i]
            } else {
                s.rod_pressure_pa[i]
            };
            u != 0.0 && port_pa >= RELIEF_RELIFT_FRACTION * relief[i]
        });
        self.relief_since_s = if at_relief {
            self.relief_since_s.or(Some(now_s))
        } else {
            None
        };
        if self.settled(implement_done && swing_done, now_s)
            || self.close_enough(now_s, est, &target_tip, &action)
        {
            self.begin_dig(now_s, est, &action);
            return Ok(CycleCommand::Neutral);
        }
        let blocked = self
            .relief_since_s
            .is_some_and(|since| now_s - since >= MOVE_BLOCKED_S)
            && now_s - self.move_progress_s >= MOVE_CLOSE_ENOUGH_WAIT_S;
        if blocked {
            tracing::warn!(
                best_tip_error_m = self.move_best_m,
                joints_deg = ?[s.joints.boom_rad, s.joints.stick_rad, s.joints.bucket_rad]
                    .map(f64::to_degrees),
                "move to the dig blocked: pushing at relief without getting closer"
            );
            return Err(ControlFault::Blocked("move to the dig"));
        }
        Ok(CycleCommand::Valves([
            implement[0],
            implement[1],
            implement[2],
            swing,
            0.0,
            0.0,
        ]))
    }

    /// MoveToDig close enough: the tip within [`MOVE_CLOSE_ENOUGH_M`] of the start's tip, the swing
    /// within [`MOVE_CLOSE_ENOUGH_SWING_RAD`], and no 1 cm of progress for
    /// [`MOVE_CLOSE_ENOUGH_WAIT_S`]. A bucket that rests on the face a few degrees short of its start
    /// pose (its last degrees stalled against the soil) starts Autodig there: Boom-Down and Pre-Dig
    /// begin from wherever the bucket is, and waiting for the time-out would abandon the action.
    fn close_enough(
        &mut self,
        now_s: f64,
        est: &Estimator,
        target_tip: &BucketPose,
        action: &Action,
    ) -> bool {
        let s = est.state();
        let dist = (s.tip.x_m - target_tip.x_m).hypot(s.tip.z_m - target_tip.z_m);
        if !dist.is_finite() {
            return false;
        }
        if dist < self.move_best_m - 0.01 {
            self.move_best_m = dist;
            self.move_progress_s = now_s;
        }
        let swing_ok = action
            .swing_rad()
            .is_none_or(|t| wrap_angle(t - s.swing_rad).abs() <= MOVE_CLOSE_ENOUGH_SWING_RAD);
        let stopped = now_s - self.move_progress_s >= MOVE_CLOSE_ENOUGH_WAIT_S;
        if dist <= MOVE_CLOSE_ENOUGH_M && swing_ok && stopped {
            tracing::info!(
                tip_error_m = dist,
                "move to the dig: stopped close to the start, digging from here"
            );
            return true;
        }
        false
    }

    /// The highest known terrain (base-frame z) along the digging plane at `swing_rad` between the
    /// radii `r_m.0..=r_m.1`, or `None` without a terrain map or known cells there. The plane's
    /// heights (every [`CLEARANCE_STEP_M`] out to `section_r_max_m`) are looked up once per move and
    /// kept in `clearance_profile`; each control period only takes the maximum over the range.
    fn highest_terrain(
        &mut self,
        pose: &planner::kinematics::MachinePose,
        swing_rad: f64,
        r_m: (f64, f64),
    ) -> Option<f64> {
        let terrain = self.terrain.as_ref()?;
        if self.clearance_profile.is_empty() {
            let n = (self.config.section_r_max_m / CLEARANCE_STEP_M)
                .ceil()
                .clamp(0.0, 1000.0) as usize;
            self.clearance_profile.extend((0..=n).map(|k| {
                let [x, y, _] = pose.world_from_base(swing_rad, k as f64 * CLEARANCE_STEP_M, 0.0);
                terrain.height_at(x, y).unwrap_or(f64::NAN)
            }));
        }
        let (a, b) = r_m;
        if !(a.is_finite() && b.is_finite()) {
            return None;
        }
        let last = self.clearance_profile.len().saturating_sub(1) as f64;
        let ka = (a / CLEARANCE_STEP_M).floor().clamp(0.0, last) as usize;
        let kb = (b / CLEARANCE_STEP_M).ceil().clamp(0.0, last) as usize;
        self.clearance_profile
            .get(ka..=kb)?
            .iter()
            .copied()
            .filter(|h| h.is_finite())
            .reduce(f64::max)
    }

    fn begin_dig(&mut self, now_s: f64, est: &Estimator, action: &Action) {
        let s = est.state();
        let swing_rad = action.swing_rad().unwrap_or(s.swing_rad);
        // 3.2: keep the pre-dig terrain section along the digging plane.
        self.swept = None;
        if self.config.perception
            && let Some(terrain) = &self.terrain
        {
            match known_section(
                terrain,
                &s.pose,
                s.swing_rad,
                s.tip.x_m,
                self.config.section_r_min_m,
                self.config.section_r_max_m,
                self.config.section_step_m,
            )
            .and_then(|p| SweptVolume::new(p, self.bucket_width_m))
            {
                Ok(sv) => self.swept = Some(sv),
                Err(e) => {
                    tracing::warn!(error = %e, "no pre-dig section: digging without perception")
                }
            }
        }
        let perception = self.swept.is_some();
        let mut cfg = self.autodig_config;
        cfg.perception.end_dig_on_swept_volume = perception;
        cfg.perception.end_capture_above_terrain = perception;
        let kind = action.kind();
        self.record = Some(DigRecord {
            stats: DigStats {
                index: self.digs_done,
                action: kind,
                swing_rad,
                start_time_s: now_s,
                time_s: 0.0,
                ground_contact_time_s: 0.0,
                energy_j: 0.0,
                swept_volume_m3: 0.0,
                weight_n: None,
                end_reason: None,
                hand_over: None,
                floor_z_m: None,
                perception,
            },
            last_lengths_m: None,
            last_s: None,
            weigh: WeighAverage::default(),
            weigh_lifts: 0,
            weigh_lift_to_rad: None,
        });
        match action {
            Action::Cleanup { plan, .. } => {
                match Cleanup::new(self.cleanup_config, *plan, self.floor) {
                    Ok(c) => {
                        self.cleanup = Some(c);
                        tracing::info!(dig = self.digs_done, "cleanup");
                        self.set_phase(Phase::Cleanup, now_s);
                    }
                    Err(e) => {
                        // Validated at construction except for the plan; skip the action.
                        tracing::warn!(error = %e, "invalid cleanup plan: skipped");
                        self.record = None;
                        self.next_action(now_s);
                    }
                }
            }
            _ => match Autodig::new(cfg, self.maps.clone()) {
                Ok(a) => {
                    self.autodig = Some(a);
                    tracing::info!(dig = self.digs_done, perception, "autodig");
                    self.set_phase(Phase::Autodig, now_s);
                }
                Err(e) => {
                    tracing::warn!(error = %e, "autodig config rejected: skipped");
                    self.record = None;
                    self.next_action(now_s);
                }
            },
        }
    }

    /// Energy (|F dL| summed over the cylinders) and ground-contact time since the last step.
    fn integrate(&mut self, now_s: f64, est: &Estimator, depth_m: Option<f64>) {
        let s = est.state();
        let Some(r) = &mut self.record else { return };
        if !s.derived_valid {
            r.last_lengths_m = None;
            return;
        }
        if let Some(prev) = r.last_lengths_m {
            let e: f64 = (0..3)
                .map(|i| (s.cylinder_force_n[i] * (s.cylinder_length_m[i] - prev[i])).abs())
                .sum();
            if e.is_finite() {
                r.stats.energy_j += e;
            }
        }
        if let (Some(t), Some(d)) = (r.last_s, depth_m)
            && d > 0.0
        {
            r.stats.ground_contact_time_s += (now_s - t).max(0.0);
        }
        r.last_lengths_m = Some(s.cylinder_length_m);
        r.last_s = Some(now_s);
    }

    fn step_autodig(&mut self, now_s: f64, est: &Estimator) -> Result<CycleCommand, ControlFault> {
        let s = est.state();
        let (mut swept_m3, mut depth_m) = (None, None);
        if let Some(sv) = &mut self.swept {
            swept_m3 = sv.update(s.tip.x_m, s.tip.z_m).ok();
            depth_m = sv.depth_m(s.tip.x_m, s.tip.z_m).ok();
        }
        self.integrate(now_s, est, depth_m);
        let inputs = AutodigInputs {
            joint_rad: [s.joints.boom_rad, s.joints.stick_rad, s.joints.bucket_rad],
            head_pressure_pa: s.head_pressure_pa,
            rod_pressure_pa: s.rod_pressure_pa,
            extension_fraction: s.extension_fraction,
            swept_volume_m3: swept_m3,
            bucket_depth_m: depth_m,
        };
        let Some(autodig) = &mut self.autodig else {
            self.set_phase(Phase::Weigh, now_s);
            return Ok(CycleCommand::Neutral);
        };
        let out = autodig
            .step(&inputs, now_s)
            .map_err(ControlFault::Autodig)?;
        if let Some(end) = out.stage_end {
            tracing::info!(stage = ?end.stage, reason = ?end.reason, "autodig stage ended");
        }
        if out.stage == Stage::Done {
            if let Some(r) = &mut self.record {
                r.stats.end_reason = out.end_reason;
                r.stats.time_s = now_s - r.stats.start_time_s;
                r.stats.swept_volume_m3 = swept_m3.unwrap_or(0.0);
            }
            self.autodig = None;
            self.set_phase(Phase::Weigh, now_s);
            return Ok(CycleCommand::Neutral);
        }
        let c = out.command;
        Ok(CycleCommand::Valves([c[0], c[1], c[2], 0.0, 0.0, 0.0]))
    }

    fn step_cleanup(&mut self, now_s: f64, est: &Estimator) -> Result<CycleCommand, ControlFault> {
        let s = est.state();
        self.integrate(now_s, est, None);
        let swing = self
            .config
            .actions
            .get(self.action_index)
            .and_then(Action::swing_rad)
            .unwrap_or(s.swing_rad);
        let inputs = CleanupInputs {
            tip_x_m: s.tip.x_m,
            tip_z_m: s.tip.z_m,
            stick_abs_rad: s.joints.stick_abs_rad(),
            head_pressure_pa: s.head_pressure_pa,
            rod_pressure_pa: s.rod_pressure_pa,
        };
        let Some(cleanup) = &mut self.cleanup else {
            self.set_phase(Phase::Weigh, now_s);
            return Ok(CycleCommand::Neutral);
        };
        match cleanup
            .step(&inputs, now_s)
            .map_err(ControlFault::Cleanup)?
        {
            CleanupOutput::Waypoint(w) => {
                let q = est
                    .kinematics()
                    .inverse(&BucketPose {
                        x_m: w.x_m,
                        z_m: w.z_m,
                        bucket_abs_rad: w.bucket_abs_rad,
                    })
                    .map_err(|_| ControlFault::Kinematics("cleanup waypoint out of reach"))?;
                Ok(CycleCommand::Position([
                    q.boom_rad,
                    q.stick_rad,
                    q.bucket_rad,
                    swing,
                ]))
            }
            CleanupOutput::HandOver(reason) => {
                let used = cleanup.floor_estimate();
                match used.z_m() {
                    Some(z) if z > self.config.floor_max_z_m => tracing::warn!(
                        floor_z_m = z,
                        max_z_m = self.config.floor_max_z_m,
                        "cleanup contact above the track ground is material, not the floor: not kept"
                    ),
                    _ => self.floor = used,
                }
                tracing::info!(?reason, floor_z_m = ?used.z_m(), "cleanup hand-over to Autodig");
                if let Some(r) = &mut self.record {
                    r.stats.hand_over = Some(reason);
                    r.stats.floor_z_m = used.z_m();
                }
                self.cleanup = None;
                // Hand over in Pre-Dig (3.3), with the perception enhancements if a section exists.
                let mut cfg = self.autodig_config;
                let perception = self.swept.is_some();
                cfg.perception.end_dig_on_swept_volume = perception;
                cfg.perception.end_capture_above_terrain = perception;
                let a = Autodig::starting_in(cfg, self.maps.clone(), Stage::PreDig)
                    .map_err(ControlFault::Autodig)?;
                self.autodig = Some(a);
                self.set_phase(Phase::Autodig, now_s);
                Ok(CycleCommand::Neutral)
            }
        }
    }

    fn step_weigh(&mut self, now_s: f64, est: &Estimator) -> CycleCommand {
        let s = est.state();
        let lift = CycleCommand::Valves([self.config.joint.max_command, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // Lifting a bucket the ground carried (below): full boom lift until the target angle or
        // the time limit, then the weighing starts over (settle, window).
        if let Some(r) = &mut self.record
            && let Some(target) = r.weigh_lift_to_rad
        {
            if s.joints.boom_rad < target && now_s - self.phase_since_s < WEIGH_LIFT_MAX_S {
                return lift;
            }
            r.weigh_lift_to_rad = None;
            r.weigh = WeighAverage::default();
            self.phase_since_s = now_s;
            return CycleCommand::Neutral;
        }
        let elapsed = now_s - self.phase_since_s;
        let settle = self.config.weigh_settle_s;
        if elapsed >= settle {
            let mut boundary = false;
            if let (Some(r), Some(w)) = (&mut self.record, est.payload_weight_n()) {
                boundary = r.weigh.push(w);
            }
            let window_done = elapsed >= settle + self.config.weigh_window_s;
            let give_up = elapsed >= settle + self.config.weigh_window_s + WEIGH_MAX_EXTRA_S;
            let steady = self.record.as_ref().is_none_or(|r| r.weigh.steady());
            if window_done && (steady || boundary || give_up) {
                if let Some(r) = &mut self.record
                    && let Some(w) = r.weigh.mean_n(boundary)
                {
                    if w < -WEIGH_SUPPORTED_KG * GRAVITY_M_PER_S2 {
                        if r.weigh_lifts < WEIGH_MAX_LIFTS {
                            r.weigh_lifts += 1;
                            r.weigh_lift_to_rad = Some(s.joints.boom_rad + WEIGH_LIFT_RAD);
                            tracing::info!(
                                weight_n = w,
                                lift = r.weigh_lifts,
                                "weigh: the ground carries the bucket; lifting and weighing again"
                            );
                            self.phase_since_s = now_s;
                            return lift;
                        }
                        tracing::warn!(
                            weight_n = w,
                            "weigh: still supported after lifting; weight unknown"
                        );
                        r.stats.weight_n = None;
                    } else {
                        r.stats.weight_n = Some(w);
                    }
                }
                tracing::debug!(
                    weight_n = ?self.record.as_ref().and_then(|r| r.stats.weight_n),
                    joints = ?s.joints,
                    extension = ?s.extension_fraction,
                    torque_nm = ?s.joint_torque_nm,
                    tip_z_m = s.tip.z_m,
                    "weighed"
                );
                self.set_phase(Phase::SwingToDump, now_s);
            }
        }
        CycleCommand::Neutral
    }

    /// Raise the boom to the carry angle, then swing to `target_rad`; Dump (or Finished) when there.
    fn step_swing_to(
        &mut self,
        now_s: f64,
        est: &Estimator,
        target_rad: f64,
    ) -> Result<CycleCommand, ControlFault> {
        if self.timed_out(now_s) {
            return Err(ControlFault::Timeout("swing"));
        }
        let s = est.state();
        let carry = self.config.carry_boom_rad;
        let boom_err = carry - s.joints.boom_rad;
        let boom_clear = s.joints.boom_rad >= carry - 3.0 * self.config.joint.tolerance
            || s.tip.z_m >= self.config.carry_tip_z_m;
        // Full lift: at part command an open-centre valve bypasses most of the flow and the loaded
        // boom stalls.
        let boom = if boom_err > 0.0 && !boom_clear {
            self.config.joint.max_command
        } else {
            0.0
        };
        let (swing, swing_done) = if boom_clear {
            self.swing_toward(s.swing_rad, s.rates_rad_per_s[3], target_rad)
        } else {
            (0.0, false)
        };
        let rate_small = s.rates_rad_per_s[3].abs() < 0.1;
        if self.settled(swing_done && rate_small, now_s) {
            if self.phase == Phase::Return {
                tracing::info!(digs = self.digs_done, "work cycle finished");
                self.set_phase(Phase::Finished, now_s);
            } else {
                self.set_phase(Phase::Dump, now_s);
            }
            return Ok(CycleCommand::Neutral);
        }
        Ok(CycleCommand::Valves([boom, 0.0, 0.0, swing, 0.0, 0.0]))
    }

    fn step_dump(&mut self, now_s: f64, est: &Estimator) -> Result<CycleCommand, ControlFault> {
        if self.timed_out(now_s) {
            return Err(ControlFault::Timeout("dump"));
        }
        let s = est.state();
        let err = self.config.dump_bucket_rad - s.joints.bucket_rad;
        let open = err <= self.config.joint.tolerance;
        if self.settled(open, now_s)
            && now_s - self.settle_since_s.unwrap_or(now_s) >= self.config.dump_hold_s
        {
            if let Some(r) = self.record.take() {
                tracing::info!(
                    dig = r.stats.index,
                    weight_n = ?r.stats.weight_n,
                    time_s = r.stats.time_s,
                    energy_kj = r.stats.energy_kj(),
                    swept_m3 = r.stats.swept_volume_m3,
                    "dig done"
                );
                self.stats.push(r.stats);
                self.digs_done += 1;
            }
            self.swept = None;
            self.next_action(now_s);
            return Ok(CycleCommand::Neutral);
        }
        // Uncurl: the bucket cylinder retracts to open the bucket.
        let bucket = if open {
            0.0
        } else {
            JOINT_SIGN[2] * self.config.joint.max_command
        };
        // A bucket that cannot open (resting in the spoil, or still in the cut) is lifted clear by
        // the boom while it keeps opening.
        if !self.stall_best_rad[2].is_finite() || err < self.stall_best_rad[2] - STALL_PROGRESS_RAD
        {
            self.stall_best_rad[2] = err;
            self.stall_progress_s[2] = now_s;
        }
        // Opening retracts the bucket cylinder (`JOINT_SIGN`): the rod port carries the load.
        let at_relief = !open
            && s.rod_pressure_pa[2]
                >= RELIEF_RELIFT_FRACTION * self.autodig_config.relief_pressure_pa[2];
        self.relief_since_s = if at_relief {
            self.relief_since_s.or(Some(now_s))
        } else {
            None
        };
        let held_at_relief = self
            .relief_since_s
            .is_some_and(|since| now_s - since >= RELIEF_RELIFT_S);
        let boom_max_rad = est.kinematics().joint_limits(Joint::Boom).1 - 0.05;
        let boom = if !open
            && (now_s - self.stall_progress_s[2] > STALL_RELIFT_S || held_at_relief)
            && s.joints.boom_rad < boom_max_rad
        {
            self.config.joint.max_command
        } else {
            0.0
        };
        Ok(CycleCommand::Valves([boom, 0.0, bucket, 0.0, 0.0, 0.0]))
    }

    fn step_track(&mut self, now_s: f64, est: &Estimator) -> Result<CycleCommand, ControlFault> {
        if self.timed_out(now_s) {
            return Err(ControlFault::Timeout("track back"));
        }
        let [l, r] = est.state().track_travel_m;
        let err = self.track_target_m - 0.5 * (l + r);
        let g = self.config.track;
        if self.settled(err.abs() <= g.tolerance, now_s) {
            self.terrain = None; // the machine moved: the old map's frame no longer fits the section
            self.next_action(now_s);
            return Ok(CycleCommand::Neutral);
        }
        let u = if err.abs() <= g.tolerance {
            0.0
        } else {
            g.command(err)
        };
        Ok(CycleCommand::Valves([0.0, 0.0, 0.0, 0.0, u, u]))
    }
}

/// The terrain section along the digging plane from `r_min_m` to `r_max_m`, cut to the run of known
/// cells that contains the tip's radius `tip_r_m` (or the longest known run): the range sensor does
/// not see the ground right under the boom, and the map has no cells beyond its scan.
/// The boom angle that puts the tip at base-frame height `z_m` with the stick and bucket of `joints`
/// (bisection between the current boom angle and the boom's upper limit; the limit if even that
/// leaves the tip lower, the current angle if the tip is already higher).
fn boom_for_tip_z(est: &Estimator, joints: &JointAngles, z_m: f64) -> f64 {
    let k = est.kinematics();
    let z_at = |boom_rad: f64| {
        k.forward(&JointAngles {
            boom_rad,
            ..*joints
        })
        .z_m
    };
    let (mut lo, mut hi) = (joints.boom_rad, k.joint_limits(Joint::Boom).1 - 0.05);
    if !(z_m.is_finite() && lo < hi) || z_at(lo) >= z_m {
        return lo;
    }
    if z_at(hi) <= z_m {
        return hi;
    }
    // The tip rises with the boom over its range (the boom foot is behind and below the tip).
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if z_at(mid) < z_m {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

fn known_section(
    terrain: &TerrainGrid,
    pose: &planner::kinematics::MachinePose,
    swing_rad: f64,
    tip_r_m: f64,
    r_min_m: f64,
    r_max_m: f64,
    step_m: f64,
) -> Result<SectionProfile, TerrainError> {
    let n = ((r_max_m - r_min_m) / step_m).floor().clamp(1.0, 10_000.0) as usize + 1;
    let heights: Vec<Option<f64>> = (0..n)
        .map(|k| {
            let r = r_min_m + k as f64 * step_m;
            let [x, y, _] = pose.world_from_base(swing_rad, r, 0.0);
            terrain.height_at(x, y).ok().filter(|h| h.is_finite())
        })
        .collect();
    // Runs of known samples: (start, end exclusive).
    let mut runs = Vec::new();
    let mut start = None;
    for (k, h) in heights.iter().enumerate() {
        match (h, start) {
            (Some(_), None) => start = Some(k),
            (None, Some(s0)) => {
                runs.push((s0, k));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s0) = start {
        runs.push((s0, n));
    }
    let tip_k = ((tip_r_m - r_min_m) / step_m).round();
    let containing = runs
        .iter()
        .copied()
        .find(|&(a, b)| tip_k >= a as f64 && tip_k < b as f64);
    let (a, b) = containing
        .or_else(|| runs.iter().copied().max_by_key(|&(a, b)| b - a))
        .ok_or(TerrainError::InvalidArgument {
            what: "no known terrain along the digging plane",
        })?;
    let values = heights[a..b].iter().map(|h| h.unwrap_or(0.0)).collect();
    SectionProfile::new(r_min_m + a as f64 * step_m, step_m, values)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::EstimatorConfig;
    use firmware_bridge::messages::{
        AuxValveMeasured, Cylinder, JointRates, Message, TrackOdometry, ValveState,
    };
    use planner::machine::MachineConfig;

    fn kin() -> (Kinematics, MachineConfig) {
        let m = MachineConfig::default_machine().unwrap();
        (Kinematics::new(&m).unwrap(), m)
    }

    fn cycle(config: CycleConfig) -> WorkCycle {
        let (k, m) = kin();
        WorkCycle::new(
            config,
            AutodigConfig::default(),
            AutodigMaps::builtin().unwrap(),
            CleanupConfig::default(),
            m.bucket.width_m,
            &k,
        )
        .unwrap()
    }

    /// An estimator that sees the machine at joint angles `q` (and swing) with `odo` travel.
    fn est_at(q: [f64; 4], odo: f64, t: f64) -> Estimator {
        let (k, m) = kin();
        let mut e = Estimator::new(k, m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
        feed(&mut e, q, odo, t);
        e
    }

    fn feed(e: &mut Estimator, q: [f64; 4], odo: f64, t: f64) {
        feed_pressures(e, q, odo, t, 8e6, 1e6);
    }

    fn feed_pressures(e: &mut Estimator, q: [f64; 4], odo: f64, t: f64, head_pa: f64, rod_pa: f64) {
        e.on_message(
            &Message::JointAngles(firmware_bridge::messages::JointAngles {
                boom_rad: q[0],
                stick_rad: q[1],
                bucket_rad: q[2],
                swing_rad: q[3],
            }),
            t,
        );
        e.on_message(&Message::JointRates(JointRates::default()), t);
        e.on_message(
            &Message::TrackOdometry(TrackOdometry {
                left_m: odo,
                right_m: odo,
            }),
            t,
        );
        for c in Cylinder::ALL {
            e.on_message(
                &Message::AuxValveMeasured(AuxValveMeasured {
                    cylinder: c,
                    flow_percent: 0.0,
                    state: ValveState::Block,
                    head_pressure_pa: head_pa,
                    rod_pressure_pa: rod_pa,
                }),
                t,
            );
        }
        e.update();
    }

    #[test]
    fn default_start_pose_is_reachable_and_inside_the_limits() {
        let (k, _) = kin();
        for a in CycleConfig::default().actions {
            if let Action::Dig { start, .. } = a {
                let q = start.resolve(&k).expect("reachable");
                k.check_limits(&q).expect("limits");
                let stick_abs = q.stick_abs_rad().to_degrees();
                assert!((-100.0..-20.0).contains(&stick_abs), "{stick_abs}");
            }
        }
    }

    #[test]
    fn idle_until_started_and_wants_no_arming() {
        let mut c = cycle(CycleConfig::default());
        let e = est_at([0.3, -1.6, -0.9, 0.0], 0.0, 0.0);
        let out = c.step(0.0, &e, None).unwrap();
        assert_eq!(out.want, None);
        assert_eq!(out.command, CycleCommand::Neutral);
        c.start();
        let out = c.step(0.01, &e, None).unwrap();
        assert_eq!(c.phase(), Phase::Scan);
        assert!(c.take_scan_request());
        assert!(!c.take_scan_request());
        assert_eq!(out.want, Some(ArmMode::Valve));
    }

    #[test]
    fn holds_neutral_until_armed() {
        let mut c = cycle(CycleConfig {
            scan: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.0, -1.6, -0.9, 0.5], 0.0, 0.0);
        let out = c.step(0.0, &e, None).unwrap();
        assert_eq!(c.phase(), Phase::MoveToDig);
        assert_eq!(out.command, CycleCommand::Neutral);
        let out = c.step(0.01, &e, Some(ArmMode::Valve)).unwrap();
        let CycleCommand::Valves(v) = out.command else {
            panic!("{out:?}")
        };
        // Boom below the start pose: raise first (extend), no swing yet.
        assert!(v[0] > 0.0, "{v:?}");
    }

    #[test]
    fn p_controllers_have_the_documented_signs() {
        let c = cycle(CycleConfig::default());
        let q = JointAngles {
            boom_rad: 0.0,
            stick_rad: -1.0,
            bucket_rad: -1.0,
        };
        let target = JointAngles {
            boom_rad: 0.1,
            stick_rad: -1.1,
            bucket_rad: -0.9,
        };
        let (cmd, done) = c.implement_toward(&q, &target);
        assert!(!done);
        // Boom up = extend; stick angle down = extend; bucket angle up (open) = retract.
        assert!(cmd[0] > 0.0 && cmd[1] > 0.0 && cmd[2] < 0.0, "{cmd:?}");
        let (s, _) = c.swing_toward(0.0, 0.0, -1.0);
        assert!((-0.7..0.0).contains(&s));
        let (s, _) = c.swing_toward(3.0, 0.0, -3.0);
        assert!(s > 0.0, "wraps the short way");
    }

    #[test]
    fn track_back_moves_the_tracks_backwards_until_the_distance() {
        let mut c = cycle(CycleConfig {
            actions: vec![Action::TrackBack { distance_m: 1.0 }],
            repeat: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.3, -1.6, -0.9, 0.0], 5.0, 0.0);
        let out = c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(c.phase(), Phase::TrackBack);
        let CycleCommand::Valves(v) = out.command else {
            panic!()
        };
        assert!(v[4] < 0.0 && v[4] == v[5]);
        let mut t = 0.01;
        let mut e = est_at([0.3, -1.6, -0.9, 0.0], 4.0, t);
        while c.phase() != Phase::Return && t < 1.0 {
            feed(&mut e, [0.3, -1.6, -0.9, 0.0], 4.0, t);
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::Return);
    }

    /// Regression (HIL cleanup): a 0.2 s window read the oscillating estimate of a full bucket
    /// (25 kN) at -5..63 kN; the mean over whole periods does not depend on where the window falls.
    #[test]
    fn weighing_averages_whole_periods_of_the_oscillation() {
        let (true_n, amp_n, hz) = (25_000.0, 30_000.0, 2.0);
        for phase in [0.0, 0.7, 1.9, 3.0, 4.4, 5.5] {
            let mut a = WeighAverage::default();
            let mut short = (0.0, 0);
            let mut t = 0.0_f64;
            let mean = loop {
                let w = true_n
                    + amp_n
                        * (-0.3 * t).exp()
                        * (2.0 * std::f64::consts::PI * hz * t + phase).sin();
                let boundary = a.push(w);
                if t < 0.2 {
                    short = (short.0 + w, short.1 + 1);
                }
                if t >= 0.2 && boundary {
                    break a.mean_n(true).unwrap();
                }
                t += 0.01;
                assert!(t < 2.0, "no whole period found");
            };
            assert!(
                (mean - true_n).abs() < 0.1 * true_n,
                "phase {phase}: {mean}"
            );
            // Ends within about one period after the window.
            assert!(t < 0.2 + 0.5 + 0.3, "phase {phase}: {t}");
            let short_mean = short.0 / f64::from(short.1);
            if phase == 0.7 {
                assert!((short_mean - true_n).abs() > 0.3 * true_n, "{short_mean}");
            }
        }
        // A steady estimate is averaged over the window.
        let mut a = WeighAverage::default();
        for _ in 0..20 {
            assert!(!a.push(20_000.0));
        }
        assert!(a.steady());
        assert_eq!(a.mean_n(false), Some(20_000.0));
    }

    fn weighing_cycle() -> WorkCycle {
        let mut c = cycle(CycleConfig::default());
        c.phase = Phase::Weigh;
        c.phase_since_s = 0.0;
        c.record = Some(DigRecord {
            stats: DigStats {
                index: 0,
                action: ActionKind::Dig,
                swing_rad: 0.0,
                start_time_s: 0.0,
                time_s: 5.0,
                ground_contact_time_s: 0.0,
                energy_j: 0.0,
                swept_volume_m3: 0.0,
                weight_n: None,
                end_reason: None,
                hand_over: None,
                floor_z_m: None,
                perception: false,
            },
            last_lengths_m: None,
            last_s: None,
            weigh: WeighAverage::default(),
            weigh_lifts: 0,
            weigh_lift_to_rad: None,
        });
        c
    }

    fn est_with_head(head_pa: f64) -> Estimator {
        let (k, m) = kin();
        let mut e = Estimator::new(k, m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
        feed_pressures(&mut e, [0.3, -1.6, -0.9, 0.0], 0.0, 0.0, head_pa, 1e6);
        e
    }

    #[test]
    fn weighing_averages_the_static_payload_estimate() {
        let mut c = weighing_cycle();
        // 16 MPa in every head at this pose: about 840 kg in the bucket.
        let e = est_with_head(16e6);
        let expect = e.payload_weight_n().unwrap();
        assert!(expect > 0.0, "{expect}");
        let mut t = 0.0;
        while c.phase() == Phase::Weigh && t < 3.0 {
            let out = c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            assert!(matches!(out.command, CycleCommand::Neutral), "{out:?}");
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::SwingToDump);
        let w = c.record.unwrap().stats.weight_n.unwrap();
        assert!((w - expect).abs() < 1e-6);
    }

    /// A bucket the ground carries weighs less than nothing: the boom lifts and the weighing starts
    /// over; still supported after the last lift, the weight is reported unknown, not negative.
    #[test]
    fn weighing_lifts_a_supported_bucket_and_never_reports_a_negative_payload() {
        let mut c = weighing_cycle();
        // 2 MPa in every head: the boom holds less than the empty implement (about -2300 kg).
        let e = est_with_head(2e6);
        assert!(e.payload_estimate_kg().unwrap() < -WEIGH_SUPPORTED_KG);
        let (mut t, mut lift_steps) = (0.0, 0);
        while c.phase() == Phase::Weigh && t < 30.0 {
            let out = c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            if let CycleCommand::Valves(v) = out.command {
                assert!(v[0] > 0.0 && v[1..].iter().all(|x| *x == 0.0), "{v:?}");
                lift_steps += 1;
            }
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::SwingToDump);
        let r = c.record.unwrap();
        assert_eq!(r.weigh_lifts, WEIGH_MAX_LIFTS);
        // The boom never reaches the lift target here (the estimator does not move), so each lift
        // ends on its time limit.
        let expect_steps = f64::from(WEIGH_MAX_LIFTS) * WEIGH_LIFT_MAX_S / 0.01;
        assert!(
            (f64::from(lift_steps) - expect_steps).abs() <= 4.0,
            "{lift_steps}"
        );
        assert_eq!(r.stats.weight_n, None);
    }

    #[test]
    fn swing_to_dump_raises_the_boom_before_swinging() {
        let mut c = cycle(CycleConfig::default());
        c.phase = Phase::SwingToDump;
        let e = est_at([-0.4, -1.6, -0.9, 0.0], 0.0, 0.0);
        assert!(e.state().tip.z_m < c.config().carry_tip_z_m);
        let CycleCommand::Valves(v) = c.step(0.0, &e, Some(ArmMode::Valve)).unwrap().command else {
            panic!()
        };
        assert!(v[0] > 0.0 && v[3] == 0.0, "{v:?}");
        let e = est_at([0.8, -1.6, -0.9, 0.0], 0.0, 0.0);
        let CycleCommand::Valves(v) = c.step(0.01, &e, Some(ArmMode::Valve)).unwrap().command
        else {
            panic!()
        };
        assert!(v[0] == 0.0 && v[3] < 0.0, "{v:?}");
    }

    #[test]
    fn a_control_fault_abandons_the_dig_and_empties_the_bucket() {
        let mut c = cycle(CycleConfig {
            scan: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.3, -1.6, -0.9, 0.0], 0.0, 0.0);
        c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(c.phase(), Phase::MoveToDig);
        c.on_fault(true);
        assert_eq!(c.phase(), Phase::SwingToDump);
        assert!(c.stats().is_empty());
    }

    #[test]
    fn an_abandoned_action_is_tried_again_then_skipped() {
        let mut c = cycle(CycleConfig {
            actions: vec![
                Action::TrackBack { distance_m: 1.0 },
                Action::TrackBack { distance_m: 2.0 },
            ],
            repeat: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.3, -1.6, -0.9, 0.0], 5.0, 0.0);
        c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!((c.phase(), c.action_index()), (Phase::TrackBack, 0));
        c.on_fault(true);
        c.step(0.1, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(
            (c.phase(), c.action_index()),
            (Phase::TrackBack, 0),
            "retried once"
        );
        c.on_fault(true);
        c.step(0.2, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(
            (c.phase(), c.action_index()),
            (Phase::TrackBack, 1),
            "then skipped"
        );
        // The next action has its own retry.
        c.on_fault(true);
        c.step(0.3, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!((c.phase(), c.action_index()), (Phase::TrackBack, 1));
    }

    /// A started cycle whose one action is a dig from these joint angles, no scan, straight ahead.
    fn moving_to(boom_rad: f64, stick_rad: f64, bucket_rad: f64) -> WorkCycle {
        let mut c = cycle(CycleConfig {
            scan: false,
            actions: vec![Action::Dig {
                swing_rad: 0.0,
                start: StartPose::Joints {
                    boom_rad,
                    stick_rad,
                    bucket_rad,
                },
            }],
            ..CycleConfig::default()
        });
        c.start();
        c
    }

    #[test]
    fn a_stalled_move_opens_its_valve_further_and_holds_while_it_progresses() {
        // Target: boom, bucket and swing where the machine is; the stick 0.1 rad (5.7 deg) short.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let mut c = moving_to(boom, stick - 0.1, bucket);
        let stick_command = |c: &mut WorkCycle, q_stick: f64, t: f64| {
            let e = est_at([boom, q_stick, bucket, 0.0], 0.0, t);
            match c.step(t, &e, Some(ArmMode::Valve)).unwrap().command {
                CycleCommand::Valves(v) => v[1].abs(),
                other => panic!("expected valve commands, got {other:?}"),
            }
        };
        let first = stick_command(&mut c, stick, 0.0);
        assert!((first - 0.2).abs() < 1e-9, "P-controller minimum: {first}");
        // Not moving: after STALL_WAIT_S the command grows at STALL_BOOST_PER_S.
        let mut t = 0.0;
        let mut last = first;
        while t < 2.0 {
            t += 0.01;
            last = stick_command(&mut c, stick, t);
        }
        let expected = 0.2 + STALL_BOOST_PER_S * (2.0 - STALL_WAIT_S);
        assert!((last - expected).abs() < 0.02, "{last} vs {expected}");
        // Progress (0.3 deg closer each step, 3 deg in all): the command is held, not grown further.
        let mut q = stick;
        for _ in 0..10 {
            t += 0.01;
            q -= 0.005;
            let now = stick_command(&mut c, q, t);
            assert!(now <= last + 1e-9 && now > 0.5, "{now} vs {last}");
            last = now;
        }
    }

    #[test]
    fn a_move_stopped_close_to_the_start_digs_from_there() {
        // The stick 0.03 rad (1.7 deg, tip ~0.1 m) short of its start and not getting closer (its
        // bucket resting on the face): the dig begins after MOVE_CLOSE_ENOUGH_WAIT_S, not at the
        // move's time-out.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let mut c = moving_to(boom, stick - 0.03, bucket);
        let e = est_at([boom, stick, bucket, 0.0], 0.0, 0.0);
        let mut t = 0.0;
        while t < MOVE_CLOSE_ENOUGH_WAIT_S - 0.1 {
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            assert_eq!(c.phase(), Phase::MoveToDig, "at {t} s");
            t += 0.01;
        }
        while t < MOVE_CLOSE_ENOUGH_WAIT_S + 0.2 {
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::Autodig);
        // Far from the start (the stick 0.3 rad short) it keeps moving.
        let mut c = moving_to(boom, stick - 0.3, bucket);
        let mut t = 0.0;
        while t < 3.0 {
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::MoveToDig);
    }

    #[test]
    fn a_move_blocked_at_relief_is_abandoned_before_its_time_out() {
        // The stick 0.1 rad short of its start (the tip more than MOVE_CLOSE_ENOUGH_M off) and
        // pushing at relief without getting closer: the move is given up once it has been blocked
        // MOVE_BLOCKED_S and has not progressed for MOVE_CLOSE_ENOUGH_WAIT_S, not at the move's
        // time-out; not at relief, it keeps moving.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let (k, m) = kin();
        let tip = |q_stick: f64| {
            k.forward(&JointAngles {
                boom_rad: boom,
                stick_rad: q_stick,
                bucket_rad: bucket,
            })
        };
        let (a, b) = (tip(stick), tip(stick - 0.1));
        assert!((a.x_m - b.x_m).hypot(a.z_m - b.z_m) > MOVE_CLOSE_ENOUGH_M);
        for (head_pa, blocked) in [(34.0e6, true), (8.0e6, false)] {
            let mut c = moving_to(boom, stick - 0.1, bucket);
            let mut e =
                Estimator::new(k.clone(), m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
            let mut t = 0.0;
            let mut fault = None;
            while t < 5.0 && fault.is_none() {
                feed_pressures(&mut e, [boom, stick, bucket, 0.0], 0.0, t, head_pa, 1e6);
                fault = c.step(t, &e, Some(ArmMode::Valve)).err();
                t += 0.01;
            }
            if blocked {
                assert_eq!(fault, Some(ControlFault::Blocked("move to the dig")), "{t}");
                assert!(
                    t >= MOVE_BLOCKED_S.max(MOVE_CLOSE_ENOUGH_WAIT_S) && t < 3.0,
                    "{t}"
                );
            } else {
                assert_eq!(fault, None);
                assert_eq!(c.phase(), Phase::MoveToDig);
            }
        }
    }

    /// A cycle without scans, started and in its Dump phase.
    fn dumping() -> WorkCycle {
        let mut c = cycle(CycleConfig {
            scan: false,
            ..CycleConfig::default()
        });
        c.start();
        c.set_phase(Phase::Dump, 0.0);
        c
    }

    /// One Dump step with the bucket at `bucket_rad` and the bucket's rod at `rod_pa` (heads 8 MPa).
    fn dump_step(c: &mut WorkCycle, bucket_rad: f64, t: f64, rod_pa: f64) -> [f64; 6] {
        let (k, m) = kin();
        let mut e = Estimator::new(k, m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
        feed_pressures(&mut e, [0.5, -1.3, bucket_rad, 1.0], 0.0, t, 8e6, rod_pa);
        match c.step(t, &e, Some(ArmMode::Valve)).unwrap().command {
            CycleCommand::Valves(v) => v,
            other => panic!("expected valve commands, got {other:?}"),
        }
    }

    #[test]
    fn a_bucket_that_cannot_open_in_the_dump_is_lifted_clear() {
        let mut c = dumping();
        let commands =
            |c: &mut WorkCycle, bucket_rad: f64, t: f64| dump_step(c, bucket_rad, t, 1e6);
        let max = c.config.joint.max_command;
        let first = commands(&mut c, -1.5, 0.0);
        assert_eq!((first[0], first[2].abs()), (0.0, max), "uncurl only");
        // Opening: no lift.
        let mut t = 0.0;
        let mut q = -1.5;
        while t < 4.0 {
            t += 0.01;
            q += 0.002;
            assert_eq!(commands(&mut c, q, t)[0], 0.0, "at {t} s");
        }
        // Held (resting in the spoil): after STALL_RELIFT_S the boom lifts while the bucket opens.
        let held_from = t;
        while t < held_from + STALL_RELIFT_S + 0.1 {
            t += 0.01;
            let v = commands(&mut c, q, t);
            let expect = if t - held_from > STALL_RELIFT_S + 0.02 {
                max
            } else if t - held_from < STALL_RELIFT_S - 0.02 {
                0.0
            } else {
                v[0]
            };
            assert_eq!(v[0], expect, "at {t} s");
            assert_eq!(v[2].abs(), max);
        }
    }

    /// A bucket that creeps open against the spoil with its opening (rod) port at relief is held as
    /// well: the boom lifts it clear after RELIEF_RELIFT_S, although the angle keeps progressing.
    #[test]
    fn a_bucket_creeping_open_at_relief_is_lifted_clear() {
        let mut c = dumping();
        let relief = c.autodig_config.relief_pressure_pa[2];
        let commands = dump_step;
        let max = c.config.joint.max_command;
        // Opening at 0.4 rad/s with a light rod: no lift.
        let (mut t, mut q) = (0.0, -1.5);
        while t < 1.0 {
            t += 0.01;
            q += 0.004;
            assert_eq!(commands(&mut c, q, t, 5.0e6)[0], 0.0, "at {t} s");
        }
        // Creeping at 0.4 rad/s still, but the rod at relief: the boom lifts after RELIEF_RELIFT_S.
        let since = t;
        while t < since + RELIEF_RELIFT_S + 0.1 {
            t += 0.01;
            q += 0.004;
            let boom = commands(&mut c, q, t, 0.95 * relief)[0];
            if t - since > RELIEF_RELIFT_S + 0.02 {
                assert_eq!(boom, max, "at {t} s");
            } else if t - since < RELIEF_RELIFT_S - 0.02 {
                assert_eq!(boom, 0.0, "at {t} s");
            }
        }
        // The rod relieved: no lift.
        t += 0.01;
        q += 0.004;
        assert_eq!(commands(&mut c, q, t, 5.0e6)[0], 0.0);
    }

    #[test]
    fn moves_time_out() {
        let mut c = cycle(CycleConfig {
            scan: false,
            move_timeout_s: 1.0,
            // The dump's hold must fit its timeout (`CycleConfig::validate`).
            dump_hold_s: 0.5,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([-0.5, -1.6, -0.9, 1.0], 0.0, 0.0);
        c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        let err = c.step(2.0, &e, Some(ArmMode::Valve)).unwrap_err();
        assert_eq!(err, ControlFault::Timeout("move to the dig"));
    }

    #[test]
    fn config_round_trips_through_toml() {
        let cfg = CycleConfig {
            actions: vec![
                Action::Cleanup {
                    swing_rad: 0.1,
                    start: StartPose::Joints {
                        boom_rad: 0.2,
                        stick_rad: -1.5,
                        bucket_rad: -1.0,
                    },
                    plan: CleanupPlan {
                        start_radius_m: 7.0,
                        min_radius_m: 4.0,
                    },
                },
                Action::TrackBack { distance_m: 2.0 },
            ],
            ..CycleConfig::default()
        };
        let text = toml::to_string(&cfg).unwrap();
        let back: CycleConfig = toml::from_str(&text).unwrap();
        assert_eq!(back.actions.len(), 2);
        assert!((back.dump_swing_rad - cfg.dump_swing_rad).abs() < 1e-12);
        assert!(matches!(back.actions[1], Action::TrackBack { distance_m } if distance_m == 2.0));
        let bad = CycleConfig {
            actions: vec![Action::TrackBack { distance_m: -1.0 }],
            ..CycleConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
