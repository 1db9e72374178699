//! The terrain map the dig planner keeps current from successive range scans (thesis 5.3: "The Dig
//! planner receives the range data from the Sensor Interface, and packages it into the terrain map").
//!
//! Each scan's points are binned into the map's cells (mean height per cell). A cell hit by the new scan
//! takes the new height: the terrain changes as it is dug, so the latest observation wins over older
//! ones. A cell the scan did not hit keeps its old height (occluded or out of view this time). A cell
//! never observed before takes the occlusion-gap interpolation of
//! [`crate::terrain::TerrainGrid::from_scan`] when the scan bounds it on both sides.
//!
//! With the sensor's position ([`TerrainMapper::integrate_from`]) the rays also carve free space: a
//! ray that passed over a cell before its hit shows the terrain there is no higher than the ray, so a
//! known cell higher than that is lowered to it. This is what keeps material that was dug out of
//! sight (behind a fresh wall, Fig. 50's occlusion) from staying in the map: a cell not hit keeps its
//! old height only as far as the rays passing over it allow.

use super::{PlanError, Result};
use crate::terrain::{TerrainError, TerrainGrid};

/// A terrain map updated scan by scan.
#[derive(Debug, Clone, PartialEq)]
pub struct TerrainMapper {
    grid: TerrainGrid,
    max_gap_cells: usize,
    scans: u64,
}

/// What one scan changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MapUpdate {
    /// Cells hit by the scan's points.
    pub observed_cells: usize,
    /// Cells newly known from the gap interpolation.
    pub interpolated_cells: usize,
    /// Points outside the map or not finite (ignored).
    pub ignored_points: usize,
    /// Known cells lowered because a ray passed over them below their height
    /// ([`TerrainMapper::integrate_from`]).
    pub carved_cells: usize,
}

impl TerrainMapper {
    /// An empty map (every cell unknown) of `nx x ny` cells of `resolution_m` with its lower-left
    /// corner at the origin; gaps up to `max_gap_cells` between observed cells are interpolated for
    /// cells never observed.
    ///
    /// # Errors
    /// [`PlanError::Terrain`] for a bad grid.
    pub fn new(
        origin_x_m: f64,
        origin_y_m: f64,
        resolution_m: f64,
        nx: usize,
        ny: usize,
        max_gap_cells: usize,
    ) -> Result<Self> {
        Ok(Self {
            grid: TerrainGrid::new_unknown(origin_x_m, origin_y_m, resolution_m, nx, ny)?,
            max_gap_cells,
            scans: 0,
        })
    }

    /// A mapper starting from an existing map (e.g. a survey before the first scan).
    #[must_use]
    pub fn from_grid(grid: TerrainGrid, max_gap_cells: usize) -> Self {
        Self {
            grid,
            max_gap_cells,
            scans: 0,
        }
    }

    /// The current map.
    #[must_use]
    pub fn grid(&self) -> &TerrainGrid {
        &self.grid
    }

    /// Scans fused so far.
    #[must_use]
    pub fn scans(&self) -> u64 {
        self.scans
    }

    /// Puts back a saved map with `scans` fused (a resumed session). The grid must have this map's
    /// geometry (origin, resolution, size); the map is unchanged otherwise.
    ///
    /// # Errors
    /// [`PlanError::Terrain`] with [`TerrainError::InvalidArgument`] for another geometry.
    pub fn restore(&mut self, grid: TerrainGrid, scans: u64) -> Result<()> {
        let same = grid.nx() == self.grid.nx()
            && grid.ny() == self.grid.ny()
            && grid.origin() == self.grid.origin()
            && grid.resolution_m() == self.grid.resolution_m();
        if !same {
            return Err(PlanError::Terrain(TerrainError::InvalidArgument {
                what: "the saved map's grid differs from this map's",
            }));
        }
        self.grid = grid;
        self.scans = scans;
        Ok(())
    }

    /// Fuses one scan (world-frame points `[x, y, z]`).
    ///
    /// # Errors
    /// [`PlanError::Terrain`] with [`TerrainError::NoPoints`] if no finite point falls in the map (the
    /// map is unchanged).
    pub fn integrate(&mut self, points: &[[f64; 3]]) -> Result<MapUpdate> {
        self.integrate_impl(None, points)
    }

    /// Fuses one scan taken from the sensor at `origin` (world frame) and carves the free space the
    /// rays crossed: a known cell the ray passed over below its stored height is lowered to the ray's
    /// height there (the stored material cannot be there, or the ray would have hit it).
    ///
    /// # Errors
    /// As [`Self::integrate`]; [`PlanError::NonFinite`] for a non-finite origin.
    pub fn integrate_from(&mut self, origin: [f64; 3], points: &[[f64; 3]]) -> Result<MapUpdate> {
        if !origin.iter().all(|v| v.is_finite()) {
            return Err(PlanError::NonFinite {
                what: "sensor origin",
            });
        }
        self.integrate_impl(Some(origin), points)
    }

    fn integrate_impl(
        &mut self,
        origin: Option<[f64; 3]>,
        points: &[[f64; 3]],
    ) -> Result<MapUpdate> {
        let (nx, ny) = (self.grid.nx(), self.grid.ny());
        let mut sum = vec![0.0; nx * ny];
        let mut count = vec![0u32; nx * ny];
        let mut update = MapUpdate::default();
        for p in points {
            let cell = if p.iter().all(|v| v.is_finite()) {
                self.grid.cell_index(p[0], p[1])
            } else {
                None
            };
            match cell {
                Some((i, j)) => {
                    sum[j * nx + i] += p[2];
                    count[j * nx + i] += 1;
                }
                None => update.ignored_points += 1,
            }
        }
        if count.iter().all(|&c| c == 0) {
            return Err(PlanError::Terrain(TerrainError::NoPoints));
        }
        // Occlusion fills for cells never observed: only when the scan bounds the gap.
        let [ox, oy] = self.grid.origin();
        let interpolated = TerrainGrid::from_scan(
            points,
            ox,
            oy,
            self.grid.resolution_m(),
            nx,
            ny,
            self.max_gap_cells,
        )
        .ok();
        for j in 0..ny {
            for i in 0..nx {
                let k = j * nx + i;
                if count[k] > 0 {
                    self.grid
                        .set_cell(i, j, Some(sum[k] / f64::from(count[k])))?;
                    update.observed_cells += 1;
                } else if self.grid.cell(i, j).is_none()
                    && let Some(h) = interpolated.as_ref().and_then(|g| g.cell(i, j))
                {
                    self.grid.set_cell(i, j, Some(h))?;
                    update.interpolated_cells += 1;
                }
            }
        }
        if let Some(o) = origin {
            update.carved_cells = self.carve(o, points, &count);
        }
        self.scans += 1;
        Ok(update)
    }

    /// Carves the swath of a bucket pass: the bucket tip moved along `path` (world frame, one digging
    /// plane) and the bucket is `width_m` wide across `lateral` (the horizontal unit vector across the
    /// plane), so no material stays above the tip there; known cells within half the width of the path
    /// higher than the tip are lowered to it. This is the map's dead reckoning of a dig: the toe of a
    /// receding face lies behind its crest from the sensor (Fig. 50's occlusion), so without it the
    /// material dug there stayed in the map until a ray passed low enough, and the planner kept choosing
    /// digs in material already removed. Returns the cells lowered; unknown cells stay unknown (the
    /// next scan sees them).
    pub fn carve_swath(&mut self, path: &[[f64; 3]], lateral: [f64; 2], width_m: f64) -> usize {
        let norm = lateral[0].hypot(lateral[1]);
        if !(norm > 0.0 && norm.is_finite() && width_m.is_finite() && width_m > 0.0) {
            return 0;
        }
        let (lx, ly) = (lateral[0] / norm, lateral[1] / norm);
        let res = self.grid.resolution_m();
        let step = 0.5 * res;
        let half = 0.5 * width_m;
        // Bounded: bucket widths of metres, steps of centimetres.
        let n_across = ((2.0 * half / step).ceil() as usize).min(10_000);
        let mut lowered = std::collections::BTreeSet::new();
        let finite: Vec<&[f64; 3]> = path
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .collect();
        let mut lower = |grid: &mut TerrainGrid, x: f64, y: f64, z: f64| {
            for k in 0..=n_across {
                let o = -half + k as f64 * (2.0 * half / n_across.max(1) as f64);
                let Some((i, j)) = grid.cell_index(x + o * lx, y + o * ly) else {
                    continue;
                };
                if let Some(h) = grid.cell(i, j)
                    && h > z
                    && grid.set_cell(i, j, Some(z)).is_ok()
                {
                    lowered.insert((i, j));
                }
            }
        };
        for w in finite.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            let n = ((len / step).ceil() as usize).clamp(1, 100_000);
            for k in 0..=n {
                let t = k as f64 / n as f64;
                lower(
                    &mut self.grid,
                    a[0] + t * (b[0] - a[0]),
                    a[1] + t * (b[1] - a[1]),
                    a[2] + t * (b[2] - a[2]),
                );
            }
        }
        if let [p] = finite.as_slice() {
            lower(&mut self.grid, p[0], p[1], p[2]);
        }
        lowered.len()
    }

    /// Lowers known cells the rays from `o` passed over below their height; cells hit by this scan
    /// (`hit_count > 0`) keep their measured height. Returns the cells lowered.
    fn carve(&mut self, o: [f64; 3], points: &[[f64; 3]], hit_count: &[u32]) -> usize {
        let nx = self.grid.nx();
        let res = self.grid.resolution_m();
        let step = 0.5 * res;
        let mut lowered = vec![false; hit_count.len()];
        let mut count = 0;
        for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
            let (dx, dy, dz) = (p[0] - o[0], p[1] - o[1], p[2] - o[2]);
            let horizontal = dx.hypot(dy);
            // Stop a cell short of the hit: the hit cell itself is measured.
            let n = ((horizontal - res) / step).floor();
            if n.is_nan() || n < 1.0 {
                continue;
            }
            // Bounded: scan ranges are tens of metres, the step centimetres.
            for k in 1..=(n as usize).min(100_000) {
                let t = k as f64 * step / horizontal;
                let (x, y, z) = (o[0] + t * dx, o[1] + t * dy, o[2] + t * dz);
                let Some((i, j)) = self.grid.cell_index(x, y) else {
                    continue;
                };
                let c = j * nx + i;
                if hit_count.get(c).copied().unwrap_or(0) > 0 {
                    continue;
                }
                if let Some(h) = self.grid.cell(i, j)
                    && h > z
                    && self.grid.set_cell(i, j, Some(z)).is_ok()
                    && !std::mem::replace(&mut lowered[c], true)
                {
                    count += 1;
                }
            }
        }
        count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points every 0.1 m (one per cell centre) over `[x0, x1] x [-0.95, 0.95]` at height `z`.
    fn scan(x0: f64, x1: f64, z: f64) -> Vec<[f64; 3]> {
        let nx = ((x1 - x0) / 0.1).round() as i32 + 1;
        (0..nx)
            .flat_map(|i| {
                (0..20).map(move |j| [x0 + f64::from(i) * 0.1, -0.95 + f64::from(j) * 0.1, z])
            })
            .collect()
    }

    #[test]
    fn new_points_replace_old_cells_and_unobserved_cells_stay() {
        let mut m = TerrainMapper::new(0.0, -1.0, 0.1, 40, 20, 3).expect("mapper");
        let u = m.integrate(&scan(0.05, 3.95, 2.0)).expect("first");
        assert_eq!(u.observed_cells, 40 * 20);
        // The second scan sees only the near half, dug down to 1 m.
        m.integrate(&scan(0.05, 1.95, 1.0)).expect("second");
        assert_eq!(m.scans(), 2);
        assert!((m.grid().height_at(1.0, 0.0).expect("near") - 1.0).abs() < 1e-12);
        assert!((m.grid().height_at(3.0, 0.0).expect("far") - 2.0).abs() < 1e-12);
    }

    #[test]
    fn gaps_are_filled_only_where_never_observed_and_bad_points_ignored() {
        let mut m = TerrainMapper::new(0.0, -1.0, 0.1, 40, 20, 5).expect("mapper");
        // Points on both sides of a 3-cell gap (x in [1.5, 1.8)): interpolated.
        let mut pts = scan(0.05, 1.45, 1.0);
        pts.extend(scan(1.85, 3.95, 2.0));
        pts.push([f64::NAN, 0.0, 0.0]);
        pts.push([100.0, 0.0, 0.0]);
        let u = m.integrate(&pts).expect("scan");
        assert_eq!(u.ignored_points, 2);
        assert!(u.interpolated_cells > 0);
        let mid = m.grid().height_at(1.65, 0.0).expect("filled");
        assert!(mid > 1.0 && mid < 2.0, "{mid}");
        // A later scan with a gap there keeps the old (filled) heights rather than re-interpolating.
        m.integrate(&scan(0.05, 0.95, 0.5)).expect("partial");
        assert!((m.grid().height_at(1.65, 0.0).expect("kept") - mid).abs() < 1e-12);
        // No usable point: an error, the map unchanged.
        let before = m.grid().clone();
        assert!(m.integrate(&[[f64::NAN; 3]]).is_err());
        assert_eq!(m.grid(), &before);
    }

    #[test]
    fn rays_carve_material_dug_out_of_sight() {
        let mut m = TerrainMapper::new(0.0, -1.0, 0.1, 40, 20, 3).expect("mapper");
        m.integrate(&scan(0.05, 3.95, 2.0)).expect("first");
        // Material at x in [2, 3) was dug to 0.5 m, out of sight; the sensor at (0, 0, 4) sees the
        // ground at x = 3.5 (height 0.5) over it: the ray passes x = 2.5 at z = 4 - 3.5 * 2.5 / 3.5.
        let origin = [0.0, 0.0, 4.0];
        let hit = [[3.55, 0.05, 0.5]];
        let u = m.integrate_from(origin, &hit).expect("second");
        assert!(u.carved_cells > 0);
        let h = m.grid().height_at(2.55, 0.05).expect("carved");
        let ray = 4.0 - 3.5 * 2.55 / 3.55;
        assert!((h - ray).abs() < 0.1 && h < 2.0, "{h} vs ray {ray}");
        // Cells the ray did not cross keep their height; the hit cell takes the measurement.
        assert!((m.grid().height_at(2.55, 0.85).expect("aside") - 2.0).abs() < 1e-12);
        assert!((m.grid().height_at(3.55, 0.05).expect("hit") - 0.5).abs() < 1e-12);
        assert!(m.integrate_from([f64::NAN, 0.0, 0.0], &hit).is_err());
    }

    #[test]
    fn a_bucket_pass_carves_its_swath_only() {
        let mut m = TerrainMapper::new(0.0, -1.0, 0.1, 40, 20, 3).expect("mapper");
        m.integrate(&scan(0.05, 3.95, 2.0)).expect("first");
        // The tip dragged from x = 3 down to 1 m and in to x = 1 along y = 0, a 1 m wide bucket.
        let path = [
            [3.0, 0.0, 2.5],
            [3.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [0.8, 0.0, 2.5],
        ];
        let n = m.carve_swath(&path, [0.0, 1.0], 1.0);
        assert!(n > 0);
        assert!((m.grid().height_at(2.05, 0.05).expect("in") - 1.0).abs() < 1e-9);
        assert!((m.grid().height_at(2.05, 0.45).expect("edge") - 1.0).abs() < 1e-9);
        // Beside the swath and beyond its ends: unchanged; above the terrain the pass changes nothing.
        assert!((m.grid().height_at(2.05, 0.75).expect("aside") - 2.0).abs() < 1e-12);
        assert!((m.grid().height_at(3.55, 0.05).expect("beyond") - 2.0).abs() < 1e-12);
        assert_eq!(
            m.carve_swath(&[[2.0, 0.0, 3.0], [1.0, 0.0, 3.0]], [0.0, 1.0], 1.0),
            0
        );
        assert_eq!(m.carve_swath(&path, [0.0, 0.0], 1.0), 0);
    }
}
