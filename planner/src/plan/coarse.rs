//! The coarse dig location planner (thesis 5.1.1.1, Fig. 44).
//!
//! - **Far radial boundary**, per region: the bench edge or the kinematic reach, whichever is nearer to
//!   the machine. The bench edge is where the terrain along the region's centre line stops exceeding
//!   `edge_threshold_m` over the desired floor (the far end of the first run of material met going out
//!   from the machine); the reach is the farthest radius at which a candidate start of the refined
//!   planner (tip on the surface, any of its bucket angles) is kinematically reachable.
//! - **Angular extent**: `+-angular_extent` (30 degrees) from the tracks, for stability.
//! - **Regions**: strips one bucket wide along evenly spaced swing angles, their number chosen so that
//!   the strips are adjacent at the far boundary (the reference reach at floor level); being strips of
//!   constant width they overlap near the machine, as in Fig. 44.
//! - **Order**: away from the spoil (truck) side: with the spoil on the right the regions are dug from
//!   right to left ("If the truck is parked on the excavator's left, the digging is ordered from left to
//!   right", so the boom need not rise as high to clear the material on the swing to the truck).
//!   [`super::PlannerState::region_pointer`] walks the regions in this order so the bench erodes evenly.

use super::refined::{RefinedConfig, start_pose};
use super::region::{DigRegion, FarLimit};
use super::{PlanError, Result, non_negative, positive};
use crate::kinematics::{Kinematics, MachinePose};
use crate::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};

/// Which side of the machine the spoil pile (or truck) is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpoilSide {
    /// Negative swing angles (clockwise seen from above): regions are dug from right to left.
    Right,
    /// Positive swing angles: regions are dug from left to right.
    Left,
}

/// Coarse planner settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoarseConfig {
    /// Half the angular extent of the workspace from the tracks' direction. Default 30 deg (5.1.1.1).
    #[serde(rename = "angular_extent_deg", with = "crate::machine::degrees")]
    pub angular_extent_rad: f64,
    /// Terrain higher than this over the desired floor is material (bench edge test), m. Default 0.3.
    pub edge_threshold_m: f64,
    /// Near radial boundary of every region, m from the swing axis. Default 3.0.
    pub near_radius_m: f64,
    /// Region width, m; 0 = the bucket width. Default 0.
    pub region_width_m: f64,
    /// Spoil (truck) side. Default right.
    pub spoil_side: SpoilSide,
    /// Sample spacing of the edge and reach search along a region's centre line, m. Default 0.1.
    pub search_step_m: f64,
}

impl Default for CoarseConfig {
    fn default() -> Self {
        Self {
            angular_extent_rad: 30f64.to_radians(),
            edge_threshold_m: 0.3,
            near_radius_m: 3.0,
            region_width_m: 0.0,
            spoil_side: SpoilSide::Right,
            search_step_m: 0.1,
        }
    }
}

impl CoarseConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if !(self.angular_extent_rad.is_finite()
            && self.angular_extent_rad > 0.0
            && self.angular_extent_rad < std::f64::consts::FRAC_PI_2)
        {
            return Err(PlanError::Config {
                field: "coarse.angular_extent_deg",
                reason: "must lie in (0, 90) degrees".to_owned(),
            });
        }
        non_negative("coarse.edge_threshold_m", self.edge_threshold_m)?;
        positive("coarse.near_radius_m", self.near_radius_m)?;
        non_negative("coarse.region_width_m", self.region_width_m)?;
        positive("coarse.search_step_m", self.search_step_m)
    }
}

/// The coarse plan: regions in dig order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoarsePlan {
    /// Regions, in dig order (index = position).
    pub regions: Vec<DigRegion>,
    /// The reference reach at floor level the regions were tiled at, m.
    pub reference_reach_m: f64,
    /// Desired floor elevation, m (base frame).
    pub floor_z_m: f64,
}

/// The farthest radius at which the machine can put the bucket tip, with the given bucket angle to the
/// horizontal, at height `z_m`, searched inward from the geometric maximum every `step_m`; `None` if
/// nothing is reachable down to `r_min_m`.
#[must_use]
pub fn reach_at_height_m(
    kin: &Kinematics,
    z_m: f64,
    bucket_abs_rad: f64,
    r_min_m: f64,
    step_m: f64,
) -> Option<f64> {
    let r_max = geometric_max_radius_m(kin);
    if !(z_m.is_finite() && bucket_abs_rad.is_finite() && step_m > 0.0 && r_min_m.is_finite()) {
        return None;
    }
    let n = (((r_max - r_min_m) / step_m).max(0.0).floor() as usize).min(100_000);
    (0..=n).map(|k| r_max - k as f64 * step_m).find(|&r| {
        kin.inverse(&crate::kinematics::BucketPose {
            x_m: r,
            z_m,
            bucket_abs_rad,
        })
        .is_ok()
    })
}

/// Boom foot + boom + stick + bucket: no tip is farther from the swing axis.
pub(crate) fn geometric_max_radius_m(kin: &Kinematics) -> f64 {
    let [l2, l3, l4] = kin.link_lengths();
    kin.boom_foot()[0] + l2 + l3 + l4
}

/// The coarse plan (5.1.1.1) for the machine at `pose` on `grid`.
///
/// # Errors
/// [`PlanError::NonFinite`] for a bad pose or floor, [`PlanError::Config`] for bad settings,
/// [`PlanError::NoWorkspace`] if the machine cannot reach the floor anywhere beyond the near radius.
pub fn plan_regions(
    grid: &TerrainGrid,
    pose: &MachinePose,
    kin: &Kinematics,
    bucket_width_m: f64,
    floor_z_m: f64,
    cfg: &CoarseConfig,
    refined: &RefinedConfig,
) -> Result<CoarsePlan> {
    cfg.validate()?;
    refined.validate()?;
    if !(pose.x_m.is_finite() && pose.y_m.is_finite() && pose.heading_rad.is_finite()) {
        return Err(PlanError::NonFinite {
            what: "machine pose",
        });
    }
    if !floor_z_m.is_finite() {
        return Err(PlanError::NonFinite {
            what: "floor elevation",
        });
    }
    let width = if cfg.region_width_m > 0.0 {
        cfg.region_width_m
    } else {
        bucket_width_m
    };
    positive("region width (bucket width)", width)?;
    let alphas = refined.alphas();
    // Reference reach: the tip on a flat floor, best over the candidate bucket angles.
    let reference = alphas
        .iter()
        .filter_map(|&a| {
            let p = start_pose(0.0, floor_z_m, 0.0, a, refined.tip_depth_m);
            reach_at_height_m(
                kin,
                p.z_m,
                p.bucket_abs_rad,
                cfg.near_radius_m,
                cfg.search_step_m,
            )
        })
        .fold(None, |m: Option<f64>, r| Some(m.map_or(r, |m| m.max(r))))
        .ok_or(PlanError::NoWorkspace {
            what: "the floor cannot be reached beyond the near radius",
        })?;
    if reference <= cfg.near_radius_m + width.min(1.0) * 0.5 {
        return Err(PlanError::NoWorkspace {
            what: "reach at floor level barely exceeds the near radius",
        });
    }
    let extent = 2.0 * cfg.angular_extent_rad;
    let per_region = width / reference;
    // Bounded by the 180 degree extent over a bucket width of centimetres at most.
    let n = ((extent / per_region).ceil() as usize).clamp(1, 10_000);
    let spacing = extent / n as f64;
    let max_r = geometric_max_radius_m(kin);
    let mut regions = Vec::with_capacity(n);
    for k in 0..n {
        let swing = match cfg.spoil_side {
            SpoilSide::Right => -cfg.angular_extent_rad + (k as f64 + 0.5) * spacing,
            SpoilSide::Left => cfg.angular_extent_rad - (k as f64 + 0.5) * spacing,
        };
        let heights = grid.plane_heights(pose, swing, cfg.near_radius_m, max_r, cfg.search_step_m);
        let r_of = |i: usize| cfg.near_radius_m + i as f64 * cfg.search_step_m;
        let threshold = floor_z_m + cfg.edge_threshold_m;
        // Reach along the line: the farthest known sample where some candidate start is reachable.
        let mut reach = None;
        for (i, h) in heights.iter().enumerate().rev() {
            let Some(h) = *h else { continue };
            let r = r_of(i);
            if alphas.iter().any(|&a| {
                kin.inverse(&start_pose(r, h, 0.0, a, refined.tip_depth_m))
                    .is_ok()
            }) {
                reach = Some(r);
                break;
            }
        }
        let reach = reach.unwrap_or(reference);
        // Bench edge: the far end of the first run of material going out.
        let first = heights
            .iter()
            .position(|h| h.is_some_and(|h| h > threshold));
        let edge = first.and_then(|f| {
            heights[f..]
                .iter()
                .position(|h| h.is_some_and(|h| h <= threshold))
                .map(|len| r_of(f + len))
        });
        let (far, far_limit) = match edge {
            Some(e) if e < reach => (e, FarLimit::BenchEdge),
            _ => (reach, FarLimit::Reach),
        };
        let has_material = first.is_some_and(|f| r_of(f) <= far);
        regions.push(DigRegion {
            index: k,
            swing_rad: swing,
            half_angle_rad: 0.5 * spacing,
            width_m: width,
            near_r_m: cfg.near_radius_m,
            far_r_m: far.max(cfg.near_radius_m),
            far_limit,
            edge_r_m: edge,
            reach_r_m: reach,
            has_material,
        });
    }
    Ok(CoarsePlan {
        regions,
        reference_reach_m: reference,
        floor_z_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::MachineConfig;

    /// A bench whose top (2 m) ends at `edge_m` from the machine: beyond it the terrain drops to the
    /// floor (the thesis's machine digs the bench it faces back to its edge).
    fn bench_with_edge(edge_m: f64) -> TerrainGrid {
        TerrainGrid::from_fn(-5.0, -10.0, 0.1, 200, 200, |x, _| {
            if x < 3.0 {
                0.0
            } else if x < 5.0 {
                x - 3.0
            } else if x < edge_m {
                2.0
            } else {
                0.0
            }
        })
        .expect("grid")
    }

    fn kin() -> Kinematics {
        Kinematics::new(&MachineConfig::default_machine().expect("machine")).expect("kin")
    }

    const WIDTH_M: f64 = 1.3;

    /// The coarse plan with the default kinematics, a `WIDTH_M` bucket and default refined settings.
    fn plan_at(
        grid: &TerrainGrid,
        pose: &MachinePose,
        floor_z_m: f64,
        cfg: &CoarseConfig,
    ) -> Result<CoarsePlan> {
        plan_regions(
            grid,
            pose,
            &kin(),
            WIDTH_M,
            floor_z_m,
            cfg,
            &RefinedConfig::default(),
        )
    }

    #[test]
    fn regions_cover_the_angular_extent_and_are_adjacent_at_the_far_boundary() {
        let grid = bench_with_edge(30.0);
        let cfg = CoarseConfig::default();
        let plan = plan_at(&grid, &MachinePose::default(), 0.0, &cfg).expect("plan");
        let n = plan.regions.len();
        assert!(n >= 5, "{n}");
        let a = cfg.angular_extent_rad;
        // Spoil on the right: dig order runs from the rightmost region to the left.
        let first = plan.regions[0];
        let last = plan.regions[n - 1];
        assert!((first.swing_rad - first.half_angle_rad + a).abs() < 1e-9);
        assert!((last.swing_rad + last.half_angle_rad - a).abs() < 1e-9);
        for w in plan.regions.windows(2) {
            assert!(w[1].swing_rad > w[0].swing_rad);
            // Adjacent at the far boundary: neighbours touch there (centre spacing x reach <= width).
            let gap = (w[1].swing_rad - w[0].swing_rad) * plan.reference_reach_m;
            assert!(gap <= WIDTH_M + 1e-9 && gap > 0.7 * WIDTH_M, "{gap}");
            // Overlapping near the machine: the strips' angular half-width there exceeds the spacing/2.
            let near_half = (0.5 * WIDTH_M / w[0].near_r_m).atan();
            assert!(near_half > 0.5 * (w[1].swing_rad - w[0].swing_rad));
        }
        // The bench runs past the reach: the reach is the far boundary.
        for r in &plan.regions {
            assert_eq!(r.far_limit, FarLimit::Reach);
            assert!((r.far_r_m - r.reach_r_m).abs() < 1e-12);
            assert!(r.has_material);
            assert!(r.far_r_m > 8.0 && r.far_r_m < 10.5, "{r:?}");
        }
        // Spoil on the left reverses the order.
        let left = CoarseConfig {
            spoil_side: SpoilSide::Left,
            ..cfg
        };
        let plan_l = plan_at(&grid, &MachinePose::default(), 0.0, &left).expect("plan");
        assert!(plan_l.regions[0].swing_rad > 0.0 && plan_l.regions[n - 1].swing_rad < 0.0);
    }

    #[test]
    fn a_bench_edge_nearer_than_the_reach_is_the_far_boundary() {
        let grid = bench_with_edge(7.0);
        let plan = plan_at(
            &grid,
            &MachinePose::default(),
            0.0,
            &CoarseConfig::default(),
        )
        .expect("plan");
        for r in &plan.regions {
            assert_eq!(r.far_limit, FarLimit::BenchEdge, "{r:?}");
            // Along a swing angle the edge (x = 7) lies at 7 / cos(swing).
            let expected = 7.0 / r.swing_rad.cos();
            assert!((r.far_r_m - expected).abs() <= 0.15, "{r:?} vs {expected}");
            assert!(r.far_r_m < r.reach_r_m);
        }
    }

    #[test]
    fn flat_floor_has_no_material_and_bad_input_is_an_error() {
        let grid = TerrainGrid::new_flat(-5.0, -10.0, 0.1, 200, 200, 0.0).expect("grid");
        let plan = plan_at(
            &grid,
            &MachinePose::default(),
            0.0,
            &CoarseConfig::default(),
        )
        .expect("plan");
        assert!(plan.regions.iter().all(|r| !r.has_material));
        let nan = MachinePose {
            x_m: f64::NAN,
            ..MachinePose::default()
        };
        assert!(plan_at(&grid, &nan, 0.0, &CoarseConfig::default()).is_err());
        // A floor far below anything reachable.
        assert!(matches!(
            plan_at(
                &grid,
                &MachinePose::default(),
                -40.0,
                &CoarseConfig::default()
            ),
            Err(PlanError::NoWorkspace { .. })
        ));
    }
}
