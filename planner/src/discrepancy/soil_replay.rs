//! The soil relation of the replay: the terrain along the digging plane as the cutting edge leaves
//! it, and the soil force a moving bucket meets on it.
//!
//! The pre-dig section (from the last scan) is lowered to the measured path of the cutting edge as
//! the dig goes on ([`CutSection`]): the edge removes what is above it, so the depth, slope and the
//! volume that has passed into the bucket at each sample follow from the measured joint angles
//! alone, as they do on the machine (thesis 3.2, Fig. 24: the swept volume is the area between the
//! pre-dig surface and the edge's path times the bucket width). The force is the planner's moving-
//! bucket soil model ([`crate::soil::MovingBucketSoil`]: the modified FEE, Eqs. 14-17, directed by
//! Eq. 18 for the measured direction of travel, plus the bearing resistance of an edge or back pushed
//! into the soil), evaluated at the measured tip velocity.

use crate::soil::{BearingParams, BucketMotion, MovingBucketSoil, SoilProperties};
use crate::terrain::SectionProfile;

/// How far ahead of the edge (in its direction of travel) the uncut surface is read, m: the soil in
/// front of the blade stands at its pre-cut height there while the edge itself has cut the surface
/// down to its own height.
pub const SURFACE_AHEAD_M: f64 = 0.15;
/// Half the base over which the terrain slope `alpha` at the edge is measured, m.
pub const SLOPE_HALF_BASE_M: f64 = 0.25;

/// The section along the digging plane, lowered to the cutting edge's path.
#[derive(Debug, Clone)]
pub struct CutSection {
    r_start_m: f64,
    step_m: f64,
    heights: Vec<f64>,
    removed_area_m2: f64,
}

impl CutSection {
    /// Starts from the pre-dig section.
    #[must_use]
    pub fn new(section: &SectionProfile) -> Self {
        let step = section.step_m();
        let n = ((section.r_end_m() - section.r_start_m()) / step).round() as usize + 1;
        let heights = (0..n)
            .map(|k| {
                let r = (section.r_start_m() + k as f64 * step).min(section.r_end_m());
                section.height_at(r).unwrap_or(f64::NAN)
            })
            .collect();
        Self {
            r_start_m: section.r_start_m(),
            step_m: step,
            heights,
            removed_area_m2: 0.0,
        }
    }

    /// Area removed so far (in the digging plane), m^2; times the bucket width it is the volume cut.
    #[must_use]
    pub fn removed_area_m2(&self) -> f64 {
        self.removed_area_m2
    }

    /// Moves the edge from `from` to `to` (base frame `[r, z]`) and lowers every section point
    /// between them that is above the edge's straight path to it (the simulator's cut, thesis 3.2).
    pub fn cut(&mut self, from: [f64; 2], to: [f64; 2]) {
        if !(from.iter().chain(&to).all(|v| v.is_finite())) {
            return;
        }
        let (lo, hi) = if from[0] < to[0] {
            (from[0], to[0])
        } else {
            (to[0], from[0])
        };
        let k0 = ((lo - self.r_start_m) / self.step_m).ceil().max(0.0) as usize;
        let k1 = ((hi - self.r_start_m) / self.step_m).floor();
        if k1 < 0.0 {
            return;
        }
        let k1 = (k1 as usize).min(self.heights.len().saturating_sub(1));
        let dr = to[0] - from[0];
        for k in k0..=k1 {
            if k >= self.heights.len() {
                break;
            }
            let r = self.r_start_m + k as f64 * self.step_m;
            let z = if dr.abs() < 1e-12 {
                from[1].min(to[1])
            } else {
                from[1] + (r - from[0]) / dr * (to[1] - from[1])
            };
            let h = &mut self.heights[k];
            if h.is_finite() && *h > z {
                self.removed_area_m2 += (*h - z) * self.step_m;
                *h = z;
            }
        }
    }

    /// Surface height at `r_m` (linear between points), or `None` off the section.
    #[must_use]
    pub fn height_at(&self, r_m: f64) -> Option<f64> {
        let f = (r_m - self.r_start_m) / self.step_m;
        if !f.is_finite() || f < 0.0 || f > (self.heights.len() - 1) as f64 {
            return None;
        }
        let k = (f.floor() as usize).min(self.heights.len() - 2);
        let t = f - k as f64;
        let h = self.heights[k] + t * (self.heights[k + 1] - self.heights[k]);
        h.is_finite().then_some(h)
    }

    /// The motion of the bucket relative to the current surface for
    /// [`MovingBucketSoil::force`]: vertical depth below the higher of the surface at the edge and
    /// [`SURFACE_AHEAD_M`] ahead of it in the direction of travel, the slope over
    /// `2 x` [`SLOPE_HALF_BASE_M`] around it. `None` off the section.
    #[must_use]
    pub fn motion(
        &self,
        tip: [f64; 2],
        bucket_abs_rad: f64,
        tip_velocity_m_per_s: [f64; 2],
        swept_volume_m3: f64,
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
            swept_volume_m3: swept_volume_m3.max(0.0),
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

    #[test]
    fn the_edge_lowers_the_surface_and_the_removed_area_is_the_cut() {
        let mut s = CutSection::new(&flat(1.0));
        // A level pass 0.3 m deep from r = 8 to r = 6 (toward the machine) in 1 cm steps.
        let mut prev = [8.0, 0.7];
        for k in 1..=200 {
            let next = [8.0 - 0.01 * f64::from(k), 0.7];
            s.cut(prev, next);
            prev = next;
        }
        // 2 m long and 0.3 m deep, the ends counted to the section points inside the path.
        assert!(
            (s.removed_area_m2() - 0.63).abs() < 0.031,
            "{}",
            s.removed_area_m2()
        );
        assert!((s.height_at(7.0).expect("on") - 0.7).abs() < 1e-9);
        assert!((s.height_at(9.0).expect("on") - 1.0).abs() < 1e-9);
        // Cutting the same path again removes nothing.
        let before = s.removed_area_m2();
        s.cut([8.0, 0.7], [6.0, 0.7]);
        assert!((s.removed_area_m2() - before).abs() < 1e-12);
        assert!(s.height_at(20.0).is_none());
    }

    #[test]
    fn depth_is_read_ahead_of_the_edge_in_its_direction_of_travel() {
        let mut s = CutSection::new(&flat(1.0));
        s.cut([8.0, 0.6], [7.0, 0.6]);
        // Moving toward the machine (vx < 0): the uncut surface 0.15 m ahead is at 1.0 m.
        let m = s
            .motion([7.0, 0.6], -2.0, [-0.5, 0.0], 0.2)
            .expect("on the section");
        assert!((m.vertical_depth_m - 0.4).abs() < 1e-9, "{m:?}");
        // Moving away (vx > 0) over the cut: the surface there is the cut one.
        let m = s
            .motion([7.5, 0.6], -2.0, [0.5, 0.0], 0.2)
            .expect("on the section");
        assert!(m.vertical_depth_m.abs() < 1e-9, "{m:?}");
        let f = soil_force(
            &SoilProperties::typical(),
            &BearingParams::default(),
            1.3,
            &s.motion([7.0, 0.6], -2.0, [-0.5, 0.0], 0.2).expect("on"),
        )
        .expect("force");
        assert!(
            f[0] > 0.0,
            "soil pushes a bucket pulled in away from the machine: {f:?}"
        );
    }
}
