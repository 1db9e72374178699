//! The soil relation of the replay: the terrain around the digging plane as the cutting edge and the
//! bucket's spill leave it, and the soil force a moving bucket meets on it.
//!
//! The pre-dig section (from the last scan) is spread across the digging plane into a local 2.5-D
//! grid and lowered to the measured path of the cutting edge as the dig goes on ([`CutSection`]):
//! the edge removes what is above it across the bucket width, so the depth, slope and the volume
//! that has passed into the bucket at each sample follow from the measured joint angles alone, as
//! they do on the machine (thesis 3.2, Fig. 24: the swept volume is the area between the pre-dig
//! surface and the edge's path times the bucket width). A full bucket cannot take more: what the
//! edge cuts beyond the capacity spills over the bucket's lip at the edge and piles up at the angle
//! of repose around it, where the edge meets it again (and out of the soil the bucket holds less
//! as its opening tips down), when the spill pile is on (below). The force is the planner's
//! moving-bucket soil model
//! ([`planner::soil::MovingBucketSoil`]: the modified FEE, Eqs. 14-17, directed by Eq. 18 for the
//! measured direction of travel, plus the bearing resistance of an edge or back pushed into the
//! soil), evaluated at the measured tip velocity on that surface.
//!
//! The spill pile is a model option (`GreyBoxParams::spill_pile`), off in the shipped model. The
//! simulator piles a full bucket's spill around the edge, and without it the replay's soil force is
//! biased on effect-free sessions like a density 690 kg/m^3 too high (with the spill deposits
//! switched off in the simulator the bias fell to 135 kg/m^3 and 127 Pa, docs/discrepancy.md); but
//! the pile this replay builds leaves the slope behind the edge flatter than the simulator's
//! (`tan alpha` -0.5 against -1.6 at 0.9 m depth), which near the wedge limit doubles the modelled
//! force, so with the option on the bias grew (-930 kg/m^3).

use planner::soil::{BearingParams, BucketMotion, MovingBucketSoil, SoilProperties};
use planner::terrain::{SectionProfile, TerrainGrid};

/// How far ahead of the edge (in its direction of travel) the uncut surface is read, m: the soil in
/// front of the blade stands at its pre-cut height there while the edge itself has cut the surface
/// down to its own height.
pub const SURFACE_AHEAD_M: f64 = 0.15;
/// Half the base over which the terrain slope `alpha` at the edge is measured, m.
pub const SLOPE_HALF_BASE_M: f64 = 0.25;
/// Half the width of the local grid across the digging plane, m: the reach of a spill pile.
pub const SPILL_REACH_M: f64 = 2.5;
/// Lateral distance from the plane beyond which the grid takes the terrain from the lanes beside the
/// section ([`CutSection::new`]), m: half the spacing of the lanes across the bucket width (0.25 m).
pub const LANE_FROM_M: f64 = 0.125;
/// Largest lateral distance from a lane at which the grid takes its terrain (half the spacing of the
/// outer lanes), m; farther from every lane, the section's.
pub const LANE_REACH_M: f64 = 0.25;
/// Out of the soil the bucket holds `capacity x clamp((opening_up + RETENTION_OFFSET) /
/// RETENTION_SPAN)`, `opening_up` the sine of the opening's elevation: full while the opening
/// faces up to 30 degrees below the horizontal, empty when it faces down 30 degrees past it.
pub const RETENTION_OFFSET: f64 = 0.5;
/// See [`RETENTION_OFFSET`].
pub const RETENTION_SPAN: f64 = 1.0;
/// Rate at which soil pours out of a bucket holding more than it can retain in the air, m^3/s.
pub const POUR_RATE_M3_PER_S: f64 = 3.0;
/// Spill leaves the bucket's lip in lumps: it lands when this much has gathered, m^3, ...
pub const SPILL_LUMP_M3: f64 = 0.05;
/// ... or when the first of it left the bucket this long ago, s.
pub const SPILL_LUMP_AGE_S: f64 = 0.25;

/// The terrain around the digging plane, lowered to the cutting edge's path and raised by the
/// bucket's spill, and what the bucket holds.
///
/// The local grid has the section's steps along the plane (`x` = distance from the swing axis) and
/// the same step across it (`y`, the plane at `y = 0`), out to [`SPILL_REACH_M`] each side; the
/// pre-dig terrain is taken as the section's height across the plane (the assumption behind the
/// swept volume = cut area x bucket width).
#[derive(Debug, Clone)]
pub struct CutSection {
    grid: TerrainGrid,
    width_m: f64,
    capacity_m3: f64,
    repose_rad: f64,
    removed_m3: f64,
    content_m3: f64,
    /// Spill on its way down: volume, where it left the lip (`r`), time since it started.
    pending_m3: f64,
    pending_at_m: f64,
    pending_age_s: f64,
}

impl CutSection {
    /// Starts from the pre-dig section and the `lanes` beside it (`(lateral offset, section)`; the
    /// section stands for the terrain where no lane covers it), for a bucket of `width_m` and
    /// `capacity_m3` whose spill stands at `repose_rad`. `None` for a section the grid cannot hold (a step that is not
    /// positive).
    #[must_use]
    pub fn new(
        section: &SectionProfile,
        lanes: &[(f64, SectionProfile)],
        width_m: f64,
        capacity_m3: f64,
        repose_rad: f64,
    ) -> Option<Self> {
        let step = section.step_m();
        let nx = ((section.r_end_m() - section.r_start_m()) / step).round() as usize + 1;
        let ny = 2 * (SPILL_REACH_M / step).round() as usize + 1;
        let origin = [section.r_start_m() - 0.5 * step, -(ny as f64) * 0.5 * step];
        // The section on the plane (within half a lane spacing), elsewhere the nearest lane where the
        // scan saw the ground there, else the section: the ground across the bucket width is not the
        // section's all across (a neighbouring dig's trench, an earlier spill pile).
        let grid = TerrainGrid::from_fn(origin[0], origin[1], step, nx.max(2), ny, |r, y| {
            let centre = section
                .height_at(r.min(section.r_end_m()))
                .unwrap_or(f64::NAN);
            if y.abs() < LANE_FROM_M {
                return centre;
            }
            lanes
                .iter()
                .filter(|(o, _)| (o - y).abs() <= LANE_REACH_M + 1e-9)
                .min_by(|a, b| (a.0 - y).abs().total_cmp(&(b.0 - y).abs()))
                .and_then(|(_, l)| l.height_at(r).ok())
                .unwrap_or(centre)
        })
        .ok()?;
        Some(Self {
            grid,
            width_m,
            capacity_m3,
            repose_rad,
            removed_m3: 0.0,
            content_m3: 0.0,
            pending_m3: 0.0,
            pending_at_m: f64::NAN,
            pending_age_s: 0.0,
        })
    }

    /// Volume cut from the terrain so far (spill not subtracted), m^3.
    #[must_use]
    pub fn removed_m3(&self) -> f64 {
        self.removed_m3
    }

    /// What the bucket holds (bank volume), m^3: the cut volume less what [`Self::spill`] let out
    /// (without it, the whole cut volume: the caller caps it at the capacity).
    #[must_use]
    pub fn content_m3(&self) -> f64 {
        self.content_m3
    }

    /// Moves the edge from `from` to `to` (base frame `[r, z]`): every grid point within half the
    /// bucket width of the edge's straight path and above it is lowered to it (the simulator's and the
    /// machine's cut, thesis 3.2), and the volume goes into the bucket.
    pub fn cut(&mut self, from: [f64; 2], to: [f64; 2]) {
        if !(from.iter().chain(&to).all(|v| v.is_finite())) {
            return;
        }
        if let Ok(v) = self.grid.cut(
            [from[0], 0.0, from[1]],
            [to[0], 0.0, to[1]],
            0.0,
            self.width_m,
        ) {
            self.removed_m3 += v;
            self.content_m3 += v;
        }
    }

    /// After a sample's cut: a bucket holding more than it can (its capacity while the edge is in the
    /// soil, less as its opening tips down in the air) spills the excess at the edge (in the soil at
    /// once, in the air at [`POUR_RATE_M3_PER_S`] over `dt_s`), and the spill piles up at the angle of
    /// repose around the edge's position `tip` (`[r, z]`) where it left the lip, in lumps
    /// ([`SPILL_LUMP_M3`], [`SPILL_LUMP_AGE_S`]). `in_soil` as [`Self::motion`]'s depth > 0.
    pub fn spill(&mut self, tip: [f64; 2], bucket_abs_rad: f64, in_soil: bool, dt_s: f64) {
        let out = self.pour(bucket_abs_rad, in_soil, dt_s);
        if out > 0.0 {
            self.pending_m3 += out;
            self.pending_at_m = tip[0];
        }
        if self.pending_m3 > 0.0 {
            self.pending_age_s += dt_s.max(0.0);
        }
        if self.pending_m3 > SPILL_LUMP_M3
            || (self.pending_m3 > 0.0 && self.pending_age_s > SPILL_LUMP_AGE_S)
        {
            if self.pending_at_m.is_finite() {
                self.deposit(self.pending_at_m, self.pending_m3);
            }
            self.pending_m3 = 0.0;
            self.pending_age_s = 0.0;
        }
    }

    /// What the bucket cannot hold leaves it, as in [`Self::spill`], without piling it up on the
    /// section (the soil poured out in the air, away from the cut): returns that volume, m^3.
    pub fn pour(&mut self, bucket_abs_rad: f64, in_soil: bool, dt_s: f64) -> f64 {
        // The opening faces bucket_abs - 90 degrees; it holds while that points up.
        let opening_up = (bucket_abs_rad - std::f64::consts::FRAC_PI_2).sin();
        let retention = if in_soil {
            1.0
        } else {
            ((opening_up + RETENTION_OFFSET) / RETENTION_SPAN).clamp(0.0, 1.0)
        };
        let holdable = self.capacity_m3 * retention;
        if self.content_m3 <= holdable {
            return 0.0;
        }
        let out = if in_soil {
            self.content_m3 - holdable
        } else {
            (self.content_m3 - holdable).min(POUR_RATE_M3_PER_S * dt_s.max(0.0))
        };
        self.content_m3 -= out;
        out
    }

    /// Piles `volume_m3` up as a cone at the angle of repose centred on the plane at `r_m`: every
    /// grid point within [`SPILL_REACH_M`] rises to `max(h, apex - dist tan(repose))`, the apex such
    /// that the added volume is `volume_m3` (what the simulator's spill does, `TerrainGrid::deposit`
    /// restricted to the reach).
    fn deposit(&mut self, r_m: f64, volume_m3: f64) {
        let tan = self.repose_rad.tan();
        if !(volume_m3 > 0.0 && tan.is_finite() && tan > 0.0) {
            return;
        }
        let res = self.grid.resolution_m();
        let Some((ci, _)) = self.grid.cell_index(r_m, 0.0) else {
            return;
        };
        let reach = (SPILL_REACH_M / res).ceil() as usize;
        let (nx, ny) = (self.grid.nx(), self.grid.ny());
        let mut cells = Vec::with_capacity(4 * reach * reach);
        for j in 0..ny {
            for i in ci.saturating_sub(reach)..(ci + reach + 1).min(nx) {
                let Some(h) = self.grid.cell(i, j) else {
                    continue;
                };
                let [x, y] = self.grid.cell_center(i, j);
                let dist = (x - r_m).hypot(y);
                if dist <= SPILL_REACH_M {
                    cells.push((j * nx + i, h + dist * tan));
                }
            }
        }
        if cells.is_empty() {
            return;
        }
        // The apex `a` solves `sum max(a - base, 0) = volume / area`: with the bases sorted, the
        // first `k` cells hold `k b_k - sum_{<k}` up to the next base.
        let target = volume_m3 / (res * res);
        let mut bases: Vec<f64> = cells.iter().map(|c| c.1).collect();
        bases.sort_unstable_by(f64::total_cmp);
        let mut sum = 0.0;
        let mut apex = f64::NAN;
        for (k, &b) in bases.iter().enumerate() {
            if k > 0 && k as f64 * b - sum >= target {
                apex = (target + sum) / k as f64;
                break;
            }
            sum += b;
        }
        if apex.is_nan() {
            apex = (target + sum) / bases.len() as f64;
        }
        let heights = self.grid.heights_mut();
        for (idx, base) in cells {
            if base < apex {
                heights[idx] += apex - base;
            }
        }
    }

    /// Surface height on the digging plane at `r_m` (bilinear between grid points), or `None` off
    /// the grid.
    #[must_use]
    pub fn height_at(&self, r_m: f64) -> Option<f64> {
        self.grid.height_at(r_m, 0.0).ok()
    }

    /// The motion of the bucket relative to the current surface for
    /// [`MovingBucketSoil::force`]: vertical depth below the higher of the surface at the edge and
    /// [`SURFACE_AHEAD_M`] ahead of it in the direction of travel, the slope over
    /// `2 x` [`SLOPE_HALF_BASE_M`] around it, and the bucket's content as the swept volume. `None`
    /// off the section.
    #[must_use]
    pub fn motion(
        &self,
        tip: [f64; 2],
        bucket_abs_rad: f64,
        tip_velocity_m_per_s: [f64; 2],
    ) -> Option<BucketMotion> {
        let ahead = if tip_velocity_m_per_s[0] > 0.0 {
            SURFACE_AHEAD_M
        } else {
            -SURFACE_AHEAD_M
        };
        let surface = self.height_at(tip[0])?.max(self.height_at(tip[0] + ahead)?);
        let slope_tan = (self.height_at(tip[0] + SLOPE_HALF_BASE_M)?
            - self.height_at(tip[0] - SLOPE_HALF_BASE_M)?)
            / (2.0 * SLOPE_HALF_BASE_M);
        let (sin_bucket_abs, cos_bucket_abs) = bucket_abs_rad.sin_cos();
        Some(BucketMotion {
            sin_bucket_abs,
            cos_bucket_abs,
            tip_velocity_m_per_s,
            vertical_depth_m: surface - tip[1],
            slope_tan,
            swept_volume_m3: self.content_m3.clamp(0.0, self.capacity_m3),
        })
    }
}

/// The soil force on the bucket `[fx, fz]` (base frame, N) for soil `psi`: the moving-bucket soil
/// model (Eqs. 14-18 plus bearing). `None` for an invalid soil or motion.
#[must_use]
pub fn soil_force(
    psi: &SoilProperties,
    bearing: &BearingParams,
    width_m: f64,
    motion: &BucketMotion,
) -> Option<[f64; 2]> {
    let model = MovingBucketSoil::new(psi, bearing, width_m).ok()?;
    let f = model.force(motion).ok()?;
    (f.fx_n.is_finite() && f.fz_n.is_finite()).then_some([f.fx_n, f.fz_n])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(h: f64) -> SectionProfile {
        SectionProfile::new(2.0, 0.1, vec![h; 81]).expect("profile")
    }

    fn drag(s: &mut CutSection, from_r: f64, to_r: f64, z: f64) {
        let mut prev = [from_r, z];
        let n = ((from_r - to_r).abs() / 0.01).round() as usize;
        for k in 1..=n {
            let next = [from_r + (to_r - from_r) * k as f64 / n as f64, z];
            s.cut(prev, next);
            prev = next;
        }
    }

    #[test]
    fn the_edge_lowers_the_surface_and_the_removed_volume_is_the_cut() {
        let mut s = CutSection::new(&flat(1.0), &[], 1.3, 10.0, 0.65).expect("grid");
        // A level pass 0.3 m deep from r = 8 to r = 6 (toward the machine) in 1 cm steps.
        drag(&mut s, 8.0, 6.0, 0.7);
        // 2 m long, 0.3 m deep, 1.3 m wide (to the grid points inside the path).
        let v = s.removed_m3();
        assert!((v - 0.78).abs() < 0.1, "{v}");
        assert!((s.content_m3() - v).abs() < 1e-12);
        assert!((s.height_at(7.0).expect("on") - 0.7).abs() < 1e-9);
        assert!((s.height_at(9.0).expect("on") - 1.0).abs() < 1e-9);
        // Cutting the same path again removes nothing.
        drag(&mut s, 8.0, 6.0, 0.7);
        assert!((s.removed_m3() - v).abs() < 1e-12);
        assert!(s.height_at(20.0).is_none());
    }

    #[test]
    fn lanes_across_the_bucket_width_set_the_ground_the_edge_cuts() {
        // The section at 1.0 m; 0.5 m beside the plane (each side) a neighbouring trench already
        // cut to 0.7 m, 0.25 m beside it the ground at 1.0 m.
        let lanes = [
            (0.25, flat(1.0)),
            (-0.25, flat(1.0)),
            (0.5, flat(0.7)),
            (-0.5, flat(0.7)),
        ];
        let mut s = CutSection::new(&flat(1.0), &lanes, 1.3, 10.0, 0.65).expect("grid");
        drag(&mut s, 8.0, 6.0, 0.7);
        // The 13 grid rows across the 1.3 m width: the seven within 0.3 m of the plane hold 0.3 m
        // above the edge, the six beyond (nearest the 0.5 m lanes) nothing.
        let v = s.removed_m3();
        assert!((v - 7.0 * 0.1 * 2.0 * 0.3).abs() < 0.05, "{v}");
        // Without the lanes the section stands for the whole width.
        let mut flat_all = CutSection::new(&flat(1.0), &[], 1.3, 10.0, 0.65).expect("grid");
        drag(&mut flat_all, 8.0, 6.0, 0.7);
        assert!(flat_all.removed_m3() > v + 0.3, "{}", flat_all.removed_m3());
    }

    #[test]
    fn a_full_bucket_spills_a_cone_at_the_edge_that_conserves_volume() {
        let mut s = CutSection::new(&flat(1.0), &[], 1.3, 0.5, 37f64.to_radians()).expect("grid");
        drag(&mut s, 8.0, 6.0, 0.7);
        let cut = s.removed_m3();
        assert!(cut > 0.6, "{cut}");
        let before: f64 = s.grid.heights_mut().iter().sum();
        // In the soil: everything above the capacity spills at once (and lands: more than a lump).
        s.spill([6.0, 0.7], -2.0, true, 0.01);
        assert!((s.content_m3() - 0.5).abs() < 1e-12);
        let after: f64 = s.grid.heights_mut().iter().sum();
        let placed = (after - before) * 0.01;
        assert!(
            (placed - (cut - 0.5)).abs() < 1e-9,
            "{placed} vs {}",
            cut - 0.5
        );
        // The pile stands at the edge, higher than the cut floor there, and falls off with distance.
        let at = s.height_at(6.0).expect("on");
        assert!(at > 0.75, "{at}");
        assert!(s.height_at(6.5).expect("on") < at);
        // In the air with the opening facing down, it pours out at the pour rate.
        s.spill([6.0, 3.0], 0.0, false, 0.01);
        assert!((s.content_m3() - (0.5 - POUR_RATE_M3_PER_S * 0.01)).abs() < 1e-12);
        // With the opening up it holds.
        let held = s.content_m3();
        s.spill([6.0, 3.0], -std::f64::consts::PI, false, 0.01);
        assert!((s.content_m3() - held).abs() < 1e-12);
    }

    /// Pouring lets out what the bucket cannot hold as `spill` does, but piles nothing up.
    #[test]
    fn a_bucket_tipped_in_the_air_pours_out_without_a_pile() {
        let mut s = CutSection::new(&flat(1.0), &[], 1.3, 0.5, 37f64.to_radians()).expect("grid");
        drag(&mut s, 8.0, 6.0, 0.7);
        let before: f64 = s.grid.heights_mut().iter().sum();
        // In the soil: down to the capacity at once.
        let out = s.pour(-2.0, true, 0.01);
        assert!((s.content_m3() - 0.5).abs() < 1e-12 && out > 0.1, "{out}");
        // Opening up: it holds; opening down: it pours at the pour rate.
        assert_eq!(s.pour(-std::f64::consts::PI, false, 0.01), 0.0);
        let out = s.pour(0.0, false, 0.01);
        assert!((out - POUR_RATE_M3_PER_S * 0.01).abs() < 1e-12, "{out}");
        let after: f64 = s.grid.heights_mut().iter().sum();
        assert_eq!(before, after);
    }

    #[test]
    fn depth_is_read_ahead_of_the_edge_in_its_direction_of_travel() {
        let mut s = CutSection::new(&flat(1.0), &[], 1.3, 1.5, 0.65).expect("grid");
        drag(&mut s, 8.0, 7.0, 0.6);
        // Moving toward the machine (vx < 0): the uncut surface 0.15 m ahead is at 1.0 m.
        let m = s
            .motion([7.0, 0.6], -2.0, [-0.5, 0.0])
            .expect("on the section");
        assert!((m.vertical_depth_m - 0.4).abs() < 1e-9, "{m:?}");
        assert!((m.swept_volume_m3 - s.content_m3()).abs() < 1e-12);
        // Moving away (vx > 0) over the cut: the surface there is the cut one.
        let m = s
            .motion([7.5, 0.6], -2.0, [0.5, 0.0])
            .expect("on the section");
        assert!(m.vertical_depth_m.abs() < 1e-9, "{m:?}");
        let f = soil_force(
            &SoilProperties::typical(),
            &BearingParams::default(),
            1.3,
            &s.motion([7.0, 0.6], -2.0, [-0.5, 0.0]).expect("on"),
        )
        .expect("force");
        assert!(
            f[0] > 0.0,
            "soil pushes a bucket pulled in away from the machine: {f:?}"
        );
    }
}
