//! The cleanup and tracking planners (thesis 5.1.2, Figs. 49-51).
//!
//! **Material boundary.** Along swing angles every `swing_step` within the workspace the terrain
//! elevation, averaged across a bucket width, is searched from the machine's far reach inward; the first
//! radius where it exceeds `elevation_threshold_m` over the desired floor is the material boundary for
//! that swing angle (the only terrain-dependent feature both plans need).
//!
//! **Cleanup plans** start just beyond the boundary (`beyond_m`, capped at the reach) and run toward the
//! machine to `min_radius_m`. They are eliminated when too short to be worth executing, when they were
//! executed `max_tries` times at that swing angle and still limit the backward motion ("not
//! cleanable"), and next to a fresh wall (a face steeper than `wall_slope`, which must settle to its
//! angle of repose first). Where the material runs on past the reach at every swing angle there is no
//! pile to clean (a bench ahead). The cleanup planner picks the longest remaining plan; without one,
//! material running past the reach at only some angles (a remnant at the workspace's edge) is cleaned
//! from the reach, and after `max_tries` there it is "not cleanable" like any other plan.
//!
//! **Tracking distance** (Figs. 49-51): the smallest, over the remaining plans, of the machine-reach
//! constraint (the plan's far end stays within reach) and the sensor-view constraint (the material,
//! assumed to rise from its far edge at the repose angle `theta` = 45 degrees, stays in view of the
//! sensor at height `h` and radius `r_s`), with Fig. 51's formulas ([`reach_track_distance_m`],
//! [`view_track_distance_m`]). Eliminated plans do not limit it; material beyond the reach does
//! (backing away cannot bring it closer).

use super::coarse::{geometric_max_radius_m, reach_at_height_m};
use super::{PlanError, PlannerState, Result, non_negative, positive};
use crate::cleanup::CleanupPlan;
use crate::kinematics::{Kinematics, MachinePose};
use crate::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};

/// Cleanup planner settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CleanupConfig {
    /// Material: average elevation over the floor above this, m. Default 0.2 (higher: less cleaning,
    /// rougher floor).
    pub elevation_threshold_m: f64,
    /// Spacing of the examined swing angles. Default 5 deg.
    #[serde(rename = "swing_step_deg", with = "crate::machine::degrees")]
    pub swing_step_rad: f64,
    /// Radial search step, m. Default 0.1.
    pub search_step_m: f64,
    /// A plan starts this far beyond the material boundary, m. Default 0.3.
    pub beyond_m: f64,
    /// Where a cleanup path ends (the hand-over to Autodig near the tracks), m. Default 3.5.
    pub min_radius_m: f64,
    /// Plans shorter than this are not worth executing, m. Default 1.0.
    pub min_length_m: f64,
    /// Executions at one swing angle after which it is "not cleanable". Default 3.
    pub max_tries: u32,
    /// A fresh wall rises at least this much, m. Default 0.5.
    pub wall_height_m: f64,
    /// ... at least this steeply (steeper than any angle of repose). Default 60 deg.
    #[serde(rename = "wall_slope_deg", with = "crate::machine::degrees")]
    pub wall_slope_rad: f64,
    /// Bucket angle to the horizontal of a cleanup start (the controller's cleanup). Default -150 deg.
    #[serde(rename = "bucket_abs_deg", with = "crate::machine::degrees")]
    pub bucket_abs_rad: f64,
    /// The start pose is this far above the floor, m. Default 0.8.
    pub start_height_m: f64,
}

impl Default for CleanupConfig {
    fn default() -> Self {
        Self {
            elevation_threshold_m: 0.2,
            swing_step_rad: 5f64.to_radians(),
            search_step_m: 0.1,
            beyond_m: 0.3,
            min_radius_m: 3.5,
            min_length_m: 1.0,
            max_tries: 3,
            wall_height_m: 0.5,
            wall_slope_rad: 60f64.to_radians(),
            bucket_abs_rad: (-150f64).to_radians(),
            start_height_m: 0.8,
        }
    }
}

impl CleanupConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        non_negative("cleanup.elevation_threshold_m", self.elevation_threshold_m)?;
        positive("cleanup.swing_step_deg", self.swing_step_rad)?;
        positive("cleanup.search_step_m", self.search_step_m)?;
        non_negative("cleanup.beyond_m", self.beyond_m)?;
        positive("cleanup.min_radius_m", self.min_radius_m)?;
        non_negative("cleanup.min_length_m", self.min_length_m)?;
        positive("cleanup.wall_height_m", self.wall_height_m)?;
        non_negative("cleanup.start_height_m", self.start_height_m)?;
        if !(self.wall_slope_rad > 0.0 && self.wall_slope_rad < FRAC_PI_2) {
            return Err(PlanError::Config {
                field: "cleanup.wall_slope_deg",
                reason: "must lie in (0, 90) degrees".to_owned(),
            });
        }
        if !self.bucket_abs_rad.is_finite() {
            return Err(PlanError::Config {
                field: "cleanup.bucket_abs_deg",
                reason: "must be finite".to_owned(),
            });
        }
        Ok(())
    }

    /// The swing-angle bin of `swing_rad` (the key of the "not cleanable" counters).
    #[must_use]
    pub fn bin(&self, swing_rad: f64) -> Option<i32> {
        let b = (swing_rad / self.swing_step_rad).round();
        (b.is_finite() && b.abs() < 1e6).then_some(b as i32)
    }
}

/// Tracking planner settings (Fig. 51).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackingConfig {
    /// Maximum angle of repose of the material, `theta` of Fig. 51. Default 45 deg (5.1.2).
    #[serde(rename = "repose_deg", with = "crate::machine::degrees")]
    pub repose_rad: f64,
    /// Longest single track back, m (also the distance when nothing limits it). Default 3.0.
    pub max_distance_m: f64,
    /// The reach of Fig. 51 is the floor-level reach minus this margin, m. Default 0.2.
    pub reach_margin_m: f64,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            repose_rad: 45f64.to_radians(),
            max_distance_m: 3.0,
            reach_margin_m: 0.2,
        }
    }
}

impl TrackingConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if !(self.repose_rad > 0.0 && self.repose_rad < FRAC_PI_2) {
            return Err(PlanError::Config {
                field: "tracking.repose_deg",
                reason: "must lie in (0, 90) degrees".to_owned(),
            });
        }
        non_negative("tracking.max_distance_m", self.max_distance_m)?;
        non_negative("tracking.reach_margin_m", self.reach_margin_m)
    }
}

/// Machine-reach constraint of Fig. 51 (top view): how far the machine can move straight back and
/// still reach the material edge at `(x, y)` (base frame, `x` forward, `y` left) with horizontal reach
/// `reach_m`:
///
/// ```text
/// r  = sqrt(x^2 + y^2)                                              (Fig. 51)
/// d  = r cos(pi - sw) +- sqrt(r^2 cos^2(pi - sw) - (r^2 - reach^2))  (Fig. 51)
/// ```
///
/// `sw` is the swing angle of the edge. The two signs are the two solutions of the law of cosines
/// `reach^2 = r^2 + d^2 - 2 r d cos(pi - sw)` in the triangle (machine centre, moved centre, edge); with
/// `d` counted positive backwards, as here, the backward travel is the `+` root (the figure prints the
/// other root, which is the forward solution in this sign convention). It equals
/// `sqrt(reach^2 - y^2) - x`, the form of the sensor-view formula. Negative when the edge is already
/// beyond reach; `None` when no backward or forward motion brings it within reach.
#[must_use]
pub fn reach_track_distance_m(x_m: f64, y_m: f64, reach_m: f64) -> Option<f64> {
    let r = x_m.hypot(y_m); // Fig. 51
    let sw = y_m.atan2(x_m);
    let c = r * (PI - sw).cos();
    let disc = c * c - (r * r - reach_m * reach_m);
    (disc.is_finite() && disc >= 0.0).then(|| c + disc.sqrt()) // Fig. 51
}

/// Sensor-view constraint of Fig. 51 (side and top view): the material is assumed to rise from its far
/// edge at `(x, y)` at the repose angle `theta`; it reaches the sensor height `h` (above the floor) at
/// `r_p = h / tan(theta)`; the machine may move back until its sensor, `r_s` from the swing axis, is
/// that far from the edge:
///
/// ```text
/// r_p = h / tan(theta)                   (Fig. 51)
/// d   = sqrt((r_p + r_s)^2 - y^2) - x     (Fig. 51)
/// ```
///
/// `None` when `|y| > r_p + r_s` (the edge is out of view at any travel) or for bad input.
#[must_use]
pub fn view_track_distance_m(
    x_m: f64,
    y_m: f64,
    sensor_height_m: f64,
    repose_rad: f64,
    sensor_radial_m: f64,
) -> Option<f64> {
    let r_p = sensor_height_m / repose_rad.tan(); // Fig. 51
    let k = (r_p + sensor_radial_m).powi(2) - y_m * y_m;
    (k.is_finite() && k >= 0.0 && r_p >= 0.0).then(|| k.sqrt() - x_m) // Fig. 51
}

/// The material boundary along one swing angle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaterialBoundary {
    /// Swing angle, rad.
    pub swing_rad: f64,
    /// Radius of the farthest material, m, if any between the reach and the minimum radius.
    pub r_m: Option<f64>,
    /// The search started inside material: it runs on past the reach (no pile; the bench).
    pub beyond_reach: bool,
}

/// Why a cleanup plan is (not) eligible (5.1.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CleanupStatus {
    /// Eligible.
    Valid,
    /// No material along this swing angle.
    NoMaterial,
    /// The material runs on past the reach: nothing to clean here (it still limits tracking).
    BeyondReach,
    /// Too short to be worth executing.
    TooShort,
    /// Executed `max_tries` times and still there.
    NotCleanable,
    /// Next to a fresh wall that must settle first.
    NextToWall,
}

/// Fig. 51's two limits on the backward travel for one cleanup plan, m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackingLimit {
    /// Machine-reach constraint (the plan's far end stays within reach).
    pub reach_m: f64,
    /// Sensor-view constraint (the material's far edge stays in view).
    pub view_m: f64,
}

impl TrackingLimit {
    /// The tighter one.
    #[must_use]
    pub fn min_m(&self) -> f64 {
        self.reach_m.min(self.view_m)
    }
}

/// One swing angle's cleanup candidate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CleanupCandidate {
    /// Swing angle, rad.
    pub swing_rad: f64,
    /// The material boundary.
    pub boundary: MaterialBoundary,
    /// The plan (start just beyond the boundary, end at the minimum radius), if there is material.
    pub plan: Option<CleanupPlan>,
    /// `start - min` radius, m.
    pub length_m: f64,
    /// Eligibility.
    pub status: CleanupStatus,
    /// Fig. 51's limits, for the candidates that limit the tracking distance.
    pub limit: Option<TrackingLimit>,
    /// Start tip pose of the cleanup (base frame): above the floor at the start radius.
    pub start: crate::kinematics::BucketPose,
}

/// The cleanup and tracking plans of one cycle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CleanupTrackPlan {
    /// Fig. 51's `reach`: the horizontal reach at floor level (minus the margin), m.
    pub reach_m: f64,
    /// Candidates per swing angle, rising swing.
    pub candidates: Vec<CleanupCandidate>,
    /// The chosen cleanup: the longest valid plan.
    pub chosen: Option<CleanupCandidate>,
    /// Allowed backward travel, m (0 when material at the reach forbids it; capped at
    /// `max_distance_m`).
    pub tracking_distance_m: f64,
    /// Swing angle of the candidate that limits the tracking distance, if any.
    pub limiting_swing_rad: Option<f64>,
    /// Whether any material was found along the examined swing angles.
    pub material_found: bool,
}

/// Geometry the cleanup and tracking planners need besides the terrain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Desired floor elevation (base frame), m.
    pub floor_z_m: f64,
    /// Bucket width (the averaging width and the wall neighbourhood), m.
    pub bucket_width_m: f64,
    /// Sensor height above the ground the tracks stand on, m (Fig. 51's `h` is above the floor).
    pub sensor_height_m: f64,
    /// Sensor radial offset `r_s`, m.
    pub sensor_radial_m: f64,
    /// Half angular extent of the examined swing angles, rad.
    pub angular_extent_rad: f64,
}

/// Terrain elevation averaged across a bucket width at radius `r_m` along `swing_rad`.
fn average_elevation(
    grid: &TerrainGrid,
    pose: &MachinePose,
    swing_rad: f64,
    r_m: f64,
    width_m: f64,
) -> Option<f64> {
    let az = pose.heading_rad + swing_rad;
    let (c, s) = (az.cos(), az.sin());
    let (mut sum, mut n) = (0.0, 0u32);
    for k in [-0.5, -0.25, 0.0, 0.25, 0.5] {
        let lat = k * width_m;
        let x = pose.x_m + r_m * c - lat * s;
        let y = pose.y_m + r_m * s + lat * c;
        if let Ok(h) = grid.height_at(x, y) {
            sum += h;
            n += 1;
        }
    }
    (n > 0).then(|| sum / f64::from(n))
}

/// The cleanup and tracking plans (5.1.2) for the machine at `pose`.
///
/// # Errors
/// [`PlanError::Config`], [`PlanError::NonFinite`], [`PlanError::NoWorkspace`] if the floor cannot be
/// reached beyond the cleanup's minimum radius.
pub fn plan_cleanup_and_tracking(
    grid: &TerrainGrid,
    pose: &MachinePose,
    kin: &Kinematics,
    geo: Geometry,
    cfg: &CleanupConfig,
    track: &TrackingConfig,
    state: &PlannerState,
) -> Result<CleanupTrackPlan> {
    cfg.validate()?;
    track.validate()?;
    if ![
        pose.x_m,
        pose.y_m,
        pose.heading_rad,
        geo.floor_z_m,
        geo.bucket_width_m,
        geo.sensor_height_m,
        geo.sensor_radial_m,
        geo.angular_extent_rad,
    ]
    .iter()
    .all(|v| v.is_finite())
    {
        return Err(PlanError::NonFinite {
            what: "pose or machine geometry",
        });
    }
    // Floor-level reach with the cleanup's bucket angle (where a cleanup path starts).
    let floor_reach = reach_at_height_m(
        kin,
        geo.floor_z_m + 0.05,
        cfg.bucket_abs_rad,
        cfg.min_radius_m,
        0.05,
    )
    .or_else(|| {
        reach_at_height_m(
            kin,
            geo.floor_z_m + 0.05,
            -FRAC_PI_2,
            cfg.min_radius_m,
            0.05,
        )
    })
    .ok_or(PlanError::NoWorkspace {
        what: "the floor cannot be reached beyond the cleanup's minimum radius",
    })?;
    let reach = (floor_reach - track.reach_margin_m).max(cfg.min_radius_m);
    let search_from = geometric_max_radius_m(kin).min(reach + 0.5);
    let threshold = geo.floor_z_m + cfg.elevation_threshold_m;
    // Sensor height above the floor (Fig. 51's h).
    let h = geo.sensor_height_m - geo.floor_z_m;
    // Bounded: the extent is below 90 degrees and the step is validated positive; cap anyway.
    let n_half = ((geo.angular_extent_rad / cfg.swing_step_rad + 1e-9).floor() as i64).min(1000);
    let wall_run = cfg.wall_height_m / cfg.wall_slope_rad.tan();

    let tried_out = |swing: f64| {
        cfg.bin(swing)
            .and_then(|bin| state.cleanup_tries.get(&bin))
            .is_some_and(|&t| t >= cfg.max_tries)
    };
    let mut candidates = Vec::new();
    let mut walls = Vec::new();
    for k in -n_half..=n_half {
        let swing = k as f64 * cfg.swing_step_rad;
        let elev = |r: f64| average_elevation(grid, pose, swing, r, geo.bucket_width_m);
        // Search from the far reach inward on the average elevation.
        let n =
            (((search_from - cfg.min_radius_m) / cfg.search_step_m).max(0.0) as usize).min(100_000);
        let mut boundary = None;
        for i in 0..=n {
            let r = search_from - i as f64 * cfg.search_step_m;
            if elev(r).is_some_and(|z| z > threshold) {
                boundary = Some((r, i == 0));
                break;
            }
        }
        let b = MaterialBoundary {
            swing_rad: swing,
            r_m: boundary.map(|(r, _)| r),
            beyond_reach: boundary.is_some_and(|(_, at_start)| at_start),
        };
        // A fresh wall: a rise of wall_height over wall_run or less, near the boundary.
        let wall = b.r_m.is_some_and(|rb| {
            let lo = (rb - 1.0).max(cfg.min_radius_m);
            let steps = (((rb + 0.5 - lo) / cfg.search_step_m).max(0.0) as usize).min(10_000);
            (0..=steps).any(|i| {
                let r = lo + i as f64 * cfg.search_step_m;
                match (elev(r), elev(r + wall_run)) {
                    (Some(a), Some(c)) => (c - a).abs() >= cfg.wall_height_m,
                    _ => false,
                }
            })
        });
        walls.push(wall);
        let start_r = b.r_m.map(|r| (r + cfg.beyond_m).min(reach));
        let length = start_r.map_or(0.0, |s| (s - cfg.min_radius_m).max(0.0));
        let status = match b.r_m {
            None => CleanupStatus::NoMaterial,
            Some(_) if b.beyond_reach && tried_out(swing) => CleanupStatus::NotCleanable,
            Some(_) if b.beyond_reach => CleanupStatus::BeyondReach,
            Some(_) if length < cfg.min_length_m => CleanupStatus::TooShort,
            Some(_)
                if cfg
                    .bin(swing)
                    .and_then(|bin| state.cleanup_tries.get(&bin))
                    .is_some_and(|&t| t >= cfg.max_tries) =>
            {
                CleanupStatus::NotCleanable
            }
            Some(_) => CleanupStatus::Valid,
        };
        let plan = start_r
            .filter(|&s| s > cfg.min_radius_m)
            .map(|s| CleanupPlan {
                start_radius_m: s,
                min_radius_m: cfg.min_radius_m,
            });
        let start = crate::kinematics::BucketPose {
            x_m: start_r.unwrap_or(reach),
            z_m: geo.floor_z_m + cfg.start_height_m,
            bucket_abs_rad: cfg.bucket_abs_rad,
        };
        candidates.push(CleanupCandidate {
            swing_rad: swing,
            boundary: b,
            plan,
            length_m: length,
            status,
            limit: None,
            start,
        });
    }
    // Regions adjacent to a wall (within a bucket width at the boundary) are not cleaned.
    for i in 0..candidates.len() {
        let Some(rb) = candidates[i].boundary.r_m else {
            continue;
        };
        let reach_angle = geo.bucket_width_m / rb.max(1e-3);
        let near_wall = candidates.iter().zip(&walls).any(|(c, &w)| {
            w && (c.swing_rad - candidates[i].swing_rad).abs() <= reach_angle + 1e-9
        });
        if near_wall && candidates[i].status == CleanupStatus::Valid {
            candidates[i].status = CleanupStatus::NextToWall;
        }
    }
    // Fig. 51 limits for the plans that count: valid ones, and material beyond the reach.
    let mut tracking = track.max_distance_m;
    let mut limiting = None;
    for c in &mut candidates {
        if !matches!(c.status, CleanupStatus::Valid | CleanupStatus::BeyondReach) {
            continue;
        }
        let (Some(rb), Some(p)) = (c.boundary.r_m, c.plan.as_ref()) else {
            if c.status == CleanupStatus::BeyondReach {
                // Material at the reach: the machine cannot back away from it.
                c.limit = Some(TrackingLimit {
                    reach_m: 0.0,
                    view_m: 0.0,
                });
                if tracking > 0.0 {
                    tracking = 0.0;
                    limiting = Some(c.swing_rad);
                }
            }
            continue;
        };
        let (sx, sy) = (
            p.start_radius_m * c.swing_rad.cos(),
            p.start_radius_m * c.swing_rad.sin(),
        );
        let (bx, by) = (rb * c.swing_rad.cos(), rb * c.swing_rad.sin());
        let reach_d = reach_track_distance_m(sx, sy, reach)
            .unwrap_or(0.0)
            .max(0.0);
        let view_d = view_track_distance_m(bx, by, h, track.repose_rad, geo.sensor_radial_m)
            .unwrap_or(0.0)
            .max(0.0);
        let lim = TrackingLimit {
            reach_m: reach_d,
            view_m: view_d,
        };
        c.limit = Some(lim);
        if lim.min_m() < tracking {
            tracking = lim.min_m();
            limiting = Some(c.swing_rad);
        }
    }
    // The longest valid plan; ties keep the first (rightmost) for determinism.
    let longest = |status: CleanupStatus| {
        candidates
            .iter()
            .filter(|c| c.status == status && c.plan.is_some())
            .fold(None::<&CleanupCandidate>, |best, c| match best {
                Some(b) if b.length_m >= c.length_m => Some(b),
                _ => Some(c),
            })
            .copied()
    };
    // Without a valid plan, material running past the reach at some swing angles (a remnant at the
    // workspace's edge after a backup, not a bench ahead at every angle) is cleaned from the reach:
    // that removes the farthest material (5.1.2), and after `max_tries` the angle is "not cleanable"
    // and stops limiting the tracking distance, as the thesis's repeated cleanups do.
    let all_beyond = candidates.iter().all(|c| c.boundary.beyond_reach);
    let chosen = longest(CleanupStatus::Valid).or_else(|| {
        if all_beyond {
            None
        } else {
            longest(CleanupStatus::BeyondReach)
        }
    });
    let material_found = candidates.iter().any(|c| c.boundary.r_m.is_some());
    Ok(CleanupTrackPlan {
        reach_m: reach,
        candidates,
        chosen,
        tracking_distance_m: tracking.max(0.0),
        limiting_swing_rad: limiting,
        material_found,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::MachineConfig;

    fn kin() -> Kinematics {
        Kinematics::new(&MachineConfig::default_machine().expect("machine")).expect("kin")
    }

    /// The plans for the machine at the origin with the default geometry and tracking settings.
    fn plan_on(grid: &TerrainGrid, cfg: &CleanupConfig, state: &PlannerState) -> CleanupTrackPlan {
        plan_cleanup_and_tracking(
            grid,
            &MachinePose::default(),
            &kin(),
            geo(),
            cfg,
            &TrackingConfig::default(),
            state,
        )
        .expect("plan")
    }

    fn geo() -> Geometry {
        Geometry {
            floor_z_m: 0.0,
            bucket_width_m: 1.3,
            sensor_height_m: 3.1,
            sensor_radial_m: 1.0,
            angular_extent_rad: 30f64.to_radians(),
        }
    }

    #[test]
    fn fig51_reach_formula_matches_hand_computed_values() {
        // Straight ahead: r = 5, reach = 9 -> back 4 m.
        let d = reach_track_distance_m(5.0, 0.0, 9.0).expect("d");
        assert!((d - 4.0).abs() < 1e-12, "{d}");
        // (x, y) = (4, 3): r = 5, sw = atan2(3, 4); cos(pi - sw) = -0.8;
        // d = 5 (-0.8) + sqrt(25 0.64 - (25 - 81)) = -4 + sqrt(72) = 4.48528...
        let d = reach_track_distance_m(4.0, 3.0, 9.0).expect("d");
        assert!((d - (72f64.sqrt() - 4.0)).abs() < 1e-12, "{d}");
        // Same as sqrt(reach^2 - y^2) - x.
        assert!((d - ((81.0f64 - 9.0).sqrt() - 4.0)).abs() < 1e-12);
        // Edge beyond the reach: negative (cannot back up).
        assert!(reach_track_distance_m(9.5, 0.0, 9.0).expect("d") < 0.0);
        // Sideways beyond the reach: no solution.
        assert!(reach_track_distance_m(0.0, 9.5, 9.0).is_none());
    }

    #[test]
    fn fig51_view_formula_matches_hand_computed_values() {
        // h = 3.1, theta = 45 deg -> r_p = 3.1; r_s = 1.0: r_p + r_s = 4.1.
        // Edge at (3, 0): d = 4.1 - 3 = 1.1.
        let d = view_track_distance_m(3.0, 0.0, 3.1, 45f64.to_radians(), 1.0).expect("d");
        assert!((d - 1.1).abs() < 1e-9, "{d}");
        // Edge at (2, 2): d = sqrt(4.1^2 - 4) - 2 = sqrt(12.81) - 2 = 1.579...
        let d = view_track_distance_m(2.0, 2.0, 3.1, 45f64.to_radians(), 1.0).expect("d");
        assert!((d - (12.81f64.sqrt() - 2.0)).abs() < 1e-9, "{d}");
        // A steeper repose angle shortens r_p: h / tan(60) = 1.7898...
        let d = view_track_distance_m(3.0, 0.0, 3.1, 60f64.to_radians(), 1.0).expect("d");
        assert!((d - (3.1 / 3f64.sqrt() + 1.0 - 3.0)).abs() < 1e-9, "{d}");
        assert!(view_track_distance_m(0.0, 5.0, 3.1, 45f64.to_radians(), 1.0).is_none());
    }

    /// Floor with a pile of `height_m` between `r0` and `r1` m ahead (within +-y_half m).
    fn pile(r0: f64, r1: f64, y_half: f64, height_m: f64) -> TerrainGrid {
        TerrainGrid::from_fn(-5.0, -10.0, 0.1, 200, 200, move |x, y| {
            if x >= r0 && x <= r1 && y.abs() <= y_half {
                height_m
            } else {
                0.0
            }
        })
        .expect("grid")
    }

    #[test]
    fn boundary_cleanup_and_tracking_on_a_pile() {
        let grid = pile(4.0, 6.0, 1.0, 0.4);
        let state = PlannerState::default();
        let p = plan_on(&grid, &CleanupConfig::default(), &state);
        assert!(p.material_found);
        let ahead = p
            .candidates
            .iter()
            .find(|c| c.swing_rad.abs() < 1e-9)
            .expect("swing 0");
        // The boundary is the pile's far side, searched inward with the bucket-width average.
        let rb = ahead.boundary.r_m.expect("boundary");
        assert!((rb - 6.0).abs() <= 0.15, "{rb}");
        assert_eq!(ahead.status, CleanupStatus::Valid);
        let plan = ahead.plan.expect("plan");
        assert!((plan.start_radius_m - (rb + 0.3)).abs() < 1e-9);
        assert!((plan.min_radius_m - 3.5).abs() < 1e-12);
        // Far to the side there is no material.
        assert!(
            p.candidates
                .iter()
                .any(|c| c.status == CleanupStatus::NoMaterial)
        );
        // The chosen plan is the longest valid one.
        let chosen = p.chosen.expect("chosen");
        assert!(
            p.candidates
                .iter()
                .filter(|c| c.status == CleanupStatus::Valid)
                .all(|c| c.length_m <= chosen.length_m)
        );
        // Tracking: the sensor view (edge at ~6 m: 4.1 - 6 < 0) forbids backing up here.
        assert!(p.tracking_distance_m < 1e-9, "{}", p.tracking_distance_m);
    }

    #[test]
    fn tracking_is_the_min_of_reach_and_view_over_valid_plans() {
        // A low pile close to the machine: the view constraint allows some travel.
        let grid = pile(3.0, 3.6, 1.0, 0.4);
        let cfg = CleanupConfig {
            min_radius_m: 2.0,
            ..CleanupConfig::default()
        };
        let p = plan_on(&grid, &cfg, &PlannerState::default());
        let limits: Vec<f64> = p
            .candidates
            .iter()
            .filter(|c| c.status == CleanupStatus::Valid)
            .filter_map(|c| c.limit.map(|l| l.min_m()))
            .collect();
        assert!(!limits.is_empty());
        let min = limits.iter().copied().fold(f64::INFINITY, f64::min);
        assert!((p.tracking_distance_m - min.min(3.0)).abs() < 1e-12);
        // Edge at ~3.6 m straight ahead: view limit ~4.1 - 3.6 = 0.5 m, reach limit several metres.
        let ahead = p
            .candidates
            .iter()
            .find(|c| c.swing_rad.abs() < 1e-9)
            .expect("ahead");
        let l = ahead.limit.expect("limit");
        assert!(l.view_m < l.reach_m, "{l:?}");
        assert!((l.view_m - (4.1 - ahead.boundary.r_m.expect("rb"))).abs() < 1e-9);
    }

    #[test]
    fn not_cleanable_after_max_tries_and_too_short_plans_are_dropped() {
        let grid = pile(4.0, 6.0, 1.0, 0.4);
        let cfg = CleanupConfig::default();
        let mut state = PlannerState::default();
        let run = |state: &PlannerState| plan_on(&grid, &cfg, state);
        let first = run(&state).chosen.expect("chosen");
        for _ in 0..cfg.max_tries - 1 {
            state.record_cleanup(first.swing_rad, &cfg);
        }
        let again = run(&state);
        let same = again
            .candidates
            .iter()
            .find(|c| (c.swing_rad - first.swing_rad).abs() < 1e-9)
            .expect("same swing");
        assert_eq!(same.status, CleanupStatus::Valid);
        state.record_cleanup(first.swing_rad, &cfg);
        let after = run(&state);
        let same = after
            .candidates
            .iter()
            .find(|c| (c.swing_rad - first.swing_rad).abs() < 1e-9)
            .expect("same swing");
        assert_eq!(same.status, CleanupStatus::NotCleanable);
        assert!(same.limit.is_none());
        assert_ne!(
            after.chosen.map(|c| c.swing_rad),
            Some(first.swing_rad),
            "a not-cleanable swing angle is not chosen"
        );
        // Too short: a pile right at the minimum radius.
        let near = pile(3.4, 3.7, 1.0, 0.4);
        let p = plan_on(&near, &cfg, &PlannerState::default());
        let ahead = p
            .candidates
            .iter()
            .find(|c| c.swing_rad.abs() < 1e-9)
            .expect("ahead");
        assert_eq!(ahead.status, CleanupStatus::TooShort);
    }

    #[test]
    fn fresh_walls_and_the_bench_beyond_reach() {
        // A vertical 1.5 m wall: steeper than repose, so its neighbourhood is not cleaned.
        let grid = pile(6.0, 6.6, 1.0, 1.5);
        let p = plan_on(&grid, &CleanupConfig::default(), &PlannerState::default());
        let ahead = p
            .candidates
            .iter()
            .find(|c| c.swing_rad.abs() < 1e-9)
            .expect("ahead");
        assert_eq!(ahead.status, CleanupStatus::NextToWall);
        // A bench running past the reach: nothing to clean, no backing up.
        let bench = pile(3.0, 40.0, 40.0, 2.0);
        let p = plan_on(&bench, &CleanupConfig::default(), &PlannerState::default());
        assert!(
            p.candidates
                .iter()
                .all(|c| c.status == CleanupStatus::BeyondReach)
        );
        assert!(p.chosen.is_none());
        assert_eq!(p.tracking_distance_m, 0.0);
    }

    #[test]
    fn a_remnant_past_the_reach_at_the_edge_is_cleaned_then_given_up() {
        // Material running past the reach only on the left edge of the workspace (y > 3 m), a small
        // pile straight ahead: the valid pile is chosen first.
        let grid = TerrainGrid::from_fn(-8.0, -10.0, 0.1, 240, 200, |x, y| {
            if y > 3.0 && x > 3.0 {
                2.0
            } else if (4.0..4.6).contains(&x) && y.abs() < 1.0 {
                // Lower than a fresh wall (0.5 m), higher than the threshold (0.2 m).
                0.45
            } else {
                0.0
            }
        })
        .expect("grid");
        let run = |state: &PlannerState| plan_on(&grid, &CleanupConfig::default(), state);
        let p = run(&PlannerState::default());
        assert!(
            p.candidates
                .iter()
                .any(|c| c.status == CleanupStatus::BeyondReach)
        );
        assert_eq!(p.chosen.map(|c| c.status), Some(CleanupStatus::Valid));
        assert_eq!(p.tracking_distance_m, 0.0);
        // With every valid angle tried out, the remnant is cleaned from the reach.
        let cfg = CleanupConfig::default();
        let mut state = PlannerState::default();
        for c in p
            .candidates
            .iter()
            .filter(|c| c.status == CleanupStatus::Valid)
        {
            for _ in 0..cfg.max_tries {
                state.record_cleanup(c.swing_rad, &cfg);
            }
        }
        let p = run(&state);
        let chosen = p.chosen.expect("the remnant");
        assert_eq!(chosen.status, CleanupStatus::BeyondReach);
        assert!((chosen.plan.expect("plan").start_radius_m - p.reach_m).abs() < 1e-9);
        // Tried out there too: not cleanable, it no longer holds the machine.
        for c in p
            .candidates
            .iter()
            .filter(|c| c.status == CleanupStatus::BeyondReach)
        {
            for _ in 0..cfg.max_tries {
                state.record_cleanup(c.swing_rad, &cfg);
            }
        }
        let p = run(&state);
        assert!(
            p.candidates
                .iter()
                .all(|c| c.status != CleanupStatus::BeyondReach)
        );
        assert!(p.chosen.is_none());
        assert!(p.tracking_distance_m > 0.0, "{}", p.tracking_distance_m);
    }
}
