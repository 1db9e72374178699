//! The plan's actions: where a dig or cleanup starts ([`StartPose`]), the action itself ([`Action`])
//! and its kind as the statistics report it ([`ActionKind`]).

use planner::cleanup::CleanupPlan;
use planner::kinematics::{BucketPose, JointAngles, Kinematics};
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::check::{Limits, ParamError, check, check_deg};

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
    /// A dig of the default bench at `swing_deg`: tip 7.5 m out (stick at about -45 degrees
    /// absolute), 0.4 m above the bench top, bucket opened to -55 degrees so Pre-Dig's curl bites the
    /// edge in; Boom-Down lowers it onto the bench.
    pub fn bench_dig(swing_deg: f64) -> Self {
        Action::Dig {
            swing_rad: swing_deg.to_radians(),
            start: StartPose::Tip {
                x_m: 7.5,
                z_m: 2.4,
                bucket_abs_rad: (-55.0_f64).to_radians(),
            },
        }
    }

    /// The action's kind.
    pub fn kind(&self) -> ActionKind {
        match self {
            Action::Dig { .. } => ActionKind::Dig,
            Action::Cleanup { .. } => ActionKind::Cleanup,
            Action::TrackBack { .. } => ActionKind::TrackBack,
        }
    }

    pub(super) fn swing_rad(&self) -> Option<f64> {
        match self {
            Action::Dig { swing_rad, .. } | Action::Cleanup { swing_rad, .. } => Some(*swing_rad),
            Action::TrackBack { .. } => None,
        }
    }
}

impl Action {
    /// Checks the `i`-th action of a plan (`cycle.actions.i.*`).
    pub(super) fn validate(&self, i: usize) -> Result<(), ParamError> {
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
