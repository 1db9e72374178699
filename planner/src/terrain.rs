//! Terrain: a 2.5-D elevation grid in the world frame, section profiles along the digging plane, grids
//! from range scans, volumes, cutting and spoil piles, and the swept-volume integrator of thesis 3.2
//! (Fig. 24).
//!
//! Cells may be unknown (never scanned); they are NaN inside the grid but never leak: queries return
//! [`TerrainError`] or `Option`. Cell `(i, j)` covers `[x0 + i res, x0 + (i+1) res) x [y0 + j res, ...)` and
//! its height is the surface at the cell centre. The base frame's `z = 0` is world `z = 0`
//! (see [`crate::kinematics::MachinePose`]).

use crate::kinematics::MachinePose;

/// Terrain errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TerrainError {
    /// Bad grid dimensions or resolution.
    #[error("invalid grid: {reason}")]
    InvalidGrid {
        /// Why.
        reason: String,
    },
    /// A bad argument (negative width, repose angle out of range...).
    #[error("invalid argument: {what}")]
    InvalidArgument {
        /// Which argument and why.
        what: &'static str,
    },
    /// A query outside the grid.
    #[error("({x_m:.3}, {y_m:.3}) is outside the terrain grid")]
    OutOfGrid {
        /// East, m.
        x_m: f64,
        /// North, m.
        y_m: f64,
    },
    /// A query that needs cells never observed.
    #[error("terrain unknown at ({x_m:.3}, {y_m:.3})")]
    Unknown {
        /// East, m.
        x_m: f64,
        /// North, m.
        y_m: f64,
    },
    /// NaN or infinite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A scan with no usable point inside the grid.
    #[error("no scan point falls inside the grid")]
    NoPoints,
    /// An occlusion gap larger than the interpolation allows.
    #[error(
        "occlusion gap of {cells} cells near ({x_m:.2}, {y_m:.2}) exceeds the {max_cells}-cell limit"
    )]
    LargeGap {
        /// Gap length in cells (the shorter of the two grid directions).
        cells: usize,
        /// The limit, cells.
        max_cells: usize,
        /// A cell in the gap, east, m.
        x_m: f64,
        /// A cell in the gap, north, m.
        y_m: f64,
    },
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, TerrainError>;

/// A 2.5-D elevation grid in the world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TerrainGrid {
    origin_x_m: f64,
    origin_y_m: f64,
    resolution_m: f64,
    nx: usize,
    ny: usize,
    /// Row-major `j * nx + i`; NaN = unknown.
    heights: Vec<f64>,
}

const MAX_CELLS: usize = 50_000_000;

impl TerrainGrid {
    /// A grid of `nx x ny` cells of size `resolution_m` with its lower-left corner at the origin, every cell
    /// at `height_m` (use [`Self::new_unknown`] for an unobserved grid).
    ///
    /// # Errors
    /// [`TerrainError::InvalidGrid`] for zero/huge sizes or a non-positive resolution,
    /// [`TerrainError::NonFinite`] for a non-finite origin or height.
    pub fn new_flat(
        origin_x_m: f64,
        origin_y_m: f64,
        resolution_m: f64,
        nx: usize,
        ny: usize,
        height_m: f64,
    ) -> Result<Self> {
        if !height_m.is_finite() {
            return Err(TerrainError::NonFinite { what: "height" });
        }
        let mut g = Self::new_unknown(origin_x_m, origin_y_m, resolution_m, nx, ny)?;
        g.heights.fill(height_m);
        Ok(g)
    }

    /// A grid with every cell unknown.
    ///
    /// # Errors
    /// As [`Self::new_flat`].
    pub fn new_unknown(
        origin_x_m: f64,
        origin_y_m: f64,
        resolution_m: f64,
        nx: usize,
        ny: usize,
    ) -> Result<Self> {
        if !(origin_x_m.is_finite() && origin_y_m.is_finite()) {
            return Err(TerrainError::NonFinite {
                what: "grid origin",
            });
        }
        if !(resolution_m.is_finite() && resolution_m > 0.0) {
            return Err(TerrainError::InvalidGrid {
                reason: format!("resolution {resolution_m} m"),
            });
        }
        if nx < 2 || ny < 2 || nx.saturating_mul(ny) > MAX_CELLS {
            return Err(TerrainError::InvalidGrid {
                reason: format!("{nx} x {ny} cells"),
            });
        }
        Ok(Self {
            origin_x_m,
            origin_y_m,
            resolution_m,
            nx,
            ny,
            heights: vec![f64::NAN; nx * ny],
        })
    }

    /// A grid whose cells take `f(x, y)` at their centres (non-finite values become unknown).
    ///
    /// # Errors
    /// As [`Self::new_flat`].
    pub fn from_fn(
        origin_x_m: f64,
        origin_y_m: f64,
        resolution_m: f64,
        nx: usize,
        ny: usize,
        f: impl Fn(f64, f64) -> f64,
    ) -> Result<Self> {
        let mut g = Self::new_unknown(origin_x_m, origin_y_m, resolution_m, nx, ny)?;
        for j in 0..ny {
            for i in 0..nx {
                let [x, y] = g.cell_center(i, j);
                let z = f(x, y);
                g.heights[j * nx + i] = if z.is_finite() { z } else { f64::NAN };
            }
        }
        Ok(g)
    }

    /// Cells along x.
    #[must_use]
    pub fn nx(&self) -> usize {
        self.nx
    }

    /// Cells along y.
    #[must_use]
    pub fn ny(&self) -> usize {
        self.ny
    }

    /// Cell size, m.
    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    /// Lower-left corner `[x, y]`, m.
    #[must_use]
    pub fn origin(&self) -> [f64; 2] {
        [self.origin_x_m, self.origin_y_m]
    }

    fn cell_area(&self) -> f64 {
        self.resolution_m * self.resolution_m
    }

    /// Centre of cell `(i, j)` in the world, m.
    #[must_use]
    pub fn cell_center(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.origin_x_m + (i as f64 + 0.5) * self.resolution_m,
            self.origin_y_m + (j as f64 + 0.5) * self.resolution_m,
        ]
    }

    /// The cell containing a world point, if inside the grid.
    #[must_use]
    pub fn cell_index(&self, x_m: f64, y_m: f64) -> Option<(usize, usize)> {
        let fx = (x_m - self.origin_x_m) / self.resolution_m;
        let fy = (y_m - self.origin_y_m) / self.resolution_m;
        if !(fx.is_finite() && fy.is_finite()) || fx < 0.0 || fy < 0.0 {
            return None;
        }
        // Truncation is the intent: the cell whose square contains the point.
        let (i, j) = (fx.floor() as usize, fy.floor() as usize);
        (i < self.nx && j < self.ny).then_some((i, j))
    }

    /// Height of cell `(i, j)`, `None` if unknown or outside.
    #[must_use]
    pub fn cell(&self, i: usize, j: usize) -> Option<f64> {
        if i >= self.nx || j >= self.ny {
            return None;
        }
        let h = self.heights[j * self.nx + i];
        h.is_finite().then_some(h)
    }

    /// The heights of row `j` (cells `(0..nx, j)`, NaN where unknown), `None` outside the grid.
    #[must_use]
    pub fn row(&self, j: usize) -> Option<&[f64]> {
        (j < self.ny).then(|| &self.heights[j * self.nx..(j + 1) * self.nx])
    }

    /// All heights, row-major `j * nx + i`, for in-place passes over many cells (NaN = unknown: a
    /// caller must write finite heights only, or NaN to mark a cell unknown).
    pub fn heights_mut(&mut self) -> &mut [f64] {
        &mut self.heights
    }

    /// Sets the height of cell `(i, j)`; `None` marks it unknown.
    ///
    /// # Errors
    /// [`TerrainError::InvalidArgument`] outside the grid, [`TerrainError::NonFinite`] for a NaN height.
    pub fn set_cell(&mut self, i: usize, j: usize, height_m: Option<f64>) -> Result<()> {
        if i >= self.nx || j >= self.ny {
            return Err(TerrainError::InvalidArgument {
                what: "cell index outside the grid",
            });
        }
        let v = match height_m {
            Some(h) if h.is_finite() => h,
            Some(_) => {
                return Err(TerrainError::NonFinite {
                    what: "cell height",
                });
            }
            None => f64::NAN,
        };
        self.heights[j * self.nx + i] = v;
        Ok(())
    }

    /// Number of known cells.
    #[must_use]
    pub fn known_cells(&self) -> usize {
        self.heights.iter().filter(|h| h.is_finite()).count()
    }

    /// Bilinear height between cell centres (constant over the outer half cell).
    ///
    /// # Errors
    /// [`TerrainError::OutOfGrid`], [`TerrainError::Unknown`] if a contributing cell is unknown,
    /// [`TerrainError::NonFinite`].
    #[inline]
    pub fn height_at(&self, x_m: f64, y_m: f64) -> Result<f64> {
        if !(x_m.is_finite() && y_m.is_finite()) {
            return Err(TerrainError::NonFinite {
                what: "query point",
            });
        }
        // On the grid (as `cell_index`). `fx, fy >= 0` here, so truncation is their floor, without
        // the library call `floor` is on the baseline x86-64 target (the simulator's contact model
        // calls this five times per contact step).
        let fx = (x_m - self.origin_x_m) / self.resolution_m;
        let fy = (y_m - self.origin_y_m) / self.resolution_m;
        if !(fx.is_finite() && fy.is_finite())
            || fx < 0.0
            || fy < 0.0
            || fx as usize >= self.nx
            || fy as usize >= self.ny
        {
            return Err(TerrainError::OutOfGrid { x_m, y_m });
        }
        let fx = (fx - 0.5).clamp(0.0, (self.nx - 1) as f64);
        let fy = (fy - 0.5).clamp(0.0, (self.ny - 1) as f64);
        let i0 = (fx as usize).min(self.nx - 2);
        let j0 = (fy as usize).min(self.ny - 2);
        let (tx, ty) = (fx - i0 as f64, fy - j0 as f64);
        let mut sum = 0.0;
        for (di, wx) in [(0, 1.0 - tx), (1, tx)] {
            for (dj, wy) in [(0, 1.0 - ty), (1, ty)] {
                let w = wx * wy;
                if w <= 0.0 {
                    continue;
                }
                let h = self
                    .cell(i0 + di, j0 + dj)
                    .ok_or(TerrainError::Unknown { x_m, y_m })?;
                sum += w * h;
            }
        }
        Ok(sum)
    }

    /// The section profile along the digging plane at `swing_rad`: heights at horizontal distances
    /// `r_start_m, r_start_m + step_m, ..` up to `r_end_m` from the swing axis (base-frame `x`).
    ///
    /// # Errors
    /// [`TerrainError::InvalidArgument`] for a bad range or step, or the first failing
    /// [`Self::height_at`].
    pub fn section(
        &self,
        pose: &MachinePose,
        swing_rad: f64,
        r_start_m: f64,
        r_end_m: f64,
        step_m: f64,
    ) -> Result<SectionProfile> {
        if !(r_start_m.is_finite()
            && r_end_m.is_finite()
            && step_m.is_finite()
            && swing_rad.is_finite())
        {
            return Err(TerrainError::NonFinite {
                what: "section range",
            });
        }
        if step_m <= 0.0 || r_end_m <= r_start_m {
            return Err(TerrainError::InvalidArgument {
                what: "section needs step > 0 and end > start",
            });
        }
        let n = ((r_end_m - r_start_m) / step_m).floor() as usize + 1;
        if n > MAX_CELLS {
            return Err(TerrainError::InvalidArgument {
                what: "section has too many samples",
            });
        }
        let heights = self
            .plane_samples(pose, swing_rad, r_start_m, step_m, n)
            .collect::<Result<Vec<_>>>()?;
        SectionProfile::new(r_start_m, step_m, heights)
    }

    /// The heights at `n` horizontal distances `r_start_m + k step_m` from the swing axis along the
    /// digging plane at `swing_rad`, as [`Self::height_at`] gives them.
    fn plane_samples(
        &self,
        pose: &MachinePose,
        swing_rad: f64,
        r_start_m: f64,
        step_m: f64,
        n: usize,
    ) -> impl Iterator<Item = Result<f64>> {
        (0..n).map(move |k| {
            let [x, y, _] = pose.world_from_base(swing_rad, r_start_m + k as f64 * step_m, 0.0);
            self.height_at(x, y)
        })
    }

    /// Heights along the digging plane at `swing_rad`, from `r_start_m` every `step_m` to `r_end_m`;
    /// `None` where the map is unknown or ends, and no samples for a bad range.
    #[must_use]
    pub fn plane_heights(
        &self,
        pose: &MachinePose,
        swing_rad: f64,
        r_start_m: f64,
        r_end_m: f64,
        step_m: f64,
    ) -> Vec<Option<f64>> {
        if !(r_start_m.is_finite() && r_end_m.is_finite() && step_m > 0.0 && r_end_m >= r_start_m) {
            return Vec::new();
        }
        // Bounded: the callers pass radii of a few metres and steps of centimetres.
        let n = (((r_end_m - r_start_m) / step_m).floor() as usize + 1).min(100_000);
        self.plane_samples(pose, swing_rad, r_start_m, step_m, n)
            .map(Result::ok)
            .collect()
    }

    /// The section along the digging plane at `swing_rad` (as [`Self::plane_heights`]) on a map that
    /// may have unknown cells: the unknown samples are filled from their known neighbours by `fill`.
    ///
    /// # Errors
    /// [`TerrainError::Unknown`] at the start of the range if no sample is known (or the range is bad),
    /// those of [`SectionProfile::new`] (fewer than two samples).
    pub fn plane_section(
        &self,
        pose: &MachinePose,
        swing_rad: f64,
        r_start_m: f64,
        r_end_m: f64,
        step_m: f64,
        fill: GapFill,
    ) -> Result<SectionProfile> {
        let raw = self.plane_heights(pose, swing_rad, r_start_m, r_end_m, step_m);
        let known: Vec<usize> = (0..raw.len()).filter(|&i| raw[i].is_some()).collect();
        let (Some(&first), Some(&last)) = (known.first(), known.last()) else {
            let [x_m, y_m, _] = pose.world_from_base(swing_rad, r_start_m, 0.0);
            return Err(TerrainError::Unknown { x_m, y_m });
        };
        let mut heights = Vec::with_capacity(raw.len());
        match fill {
            GapFill::Linear => {
                let mut prev = first;
                for (i, h) in raw.iter().enumerate() {
                    let v = match h {
                        Some(v) => {
                            prev = i;
                            *v
                        }
                        None if i < first => raw[first].unwrap_or(0.0),
                        None if i > last => raw[last].unwrap_or(0.0),
                        None => {
                            let next = known.iter().copied().find(|&k| k > i).unwrap_or(last);
                            let (a, b) = (raw[prev].unwrap_or(0.0), raw[next].unwrap_or(0.0));
                            let t = (i - prev) as f64 / (next - prev).max(1) as f64;
                            a + t * (b - a)
                        }
                    };
                    heights.push(v);
                }
            }
            GapFill::HoldLast => {
                // Before the first known sample: its height.
                let mut held = raw[first].unwrap_or(0.0);
                for h in &raw {
                    if let Some(v) = h {
                        held = *v;
                    }
                    heights.push(held);
                }
            }
        }
        SectionProfile::new(r_start_m, step_m, heights)
    }

    /// Builds a grid from range-scan points (world `[x, y, z]`): each cell takes the mean height of its
    /// points; unknown runs bounded by known cells on both sides along x or y (occlusion shadows) are
    /// filled by linear interpolation when at most `max_gap_cells` long. Unknown cells not bounded on both
    /// sides (outside the scanned area) stay unknown.
    ///
    /// # Errors
    /// [`TerrainError::NoPoints`] if no finite point lands in the grid, [`TerrainError::LargeGap`] for a
    /// bounded gap longer than `max_gap_cells` in both directions, or as [`Self::new_unknown`].
    pub fn from_scan(
        points: &[[f64; 3]],
        origin_x_m: f64,
        origin_y_m: f64,
        resolution_m: f64,
        nx: usize,
        ny: usize,
        max_gap_cells: usize,
    ) -> Result<Self> {
        let mut g = Self::new_unknown(origin_x_m, origin_y_m, resolution_m, nx, ny)?;
        let mut sum = vec![0.0; nx * ny];
        let mut count = vec![0u32; nx * ny];
        for p in points {
            if !p.iter().all(|v| v.is_finite()) {
                continue;
            }
            if let Some((i, j)) = g.cell_index(p[0], p[1]) {
                sum[j * nx + i] += p[2];
                count[j * nx + i] += 1;
            }
        }
        if count.iter().all(|&c| c == 0) {
            return Err(TerrainError::NoPoints);
        }
        for k in 0..nx * ny {
            if count[k] > 0 {
                g.heights[k] = sum[k] / f64::from(count[k]);
            }
        }
        let scanned = g.heights.clone();
        for j in 0..ny {
            for i in 0..nx {
                if scanned[j * nx + i].is_finite() {
                    continue;
                }
                let along_x = bounded_gap(&scanned, i, nx, |k| j * nx + k);
                let along_y = bounded_gap(&scanned, j, ny, |k| k * nx + i);
                let best = match (along_x, along_y) {
                    (Some(a), Some(b)) => Some(if a.len <= b.len { a } else { b }),
                    (a, b) => a.or(b),
                };
                let Some(gap) = best else { continue };
                if gap.len > max_gap_cells {
                    let [x_m, y_m] = g.cell_center(i, j);
                    return Err(TerrainError::LargeGap {
                        cells: gap.len,
                        max_cells: max_gap_cells,
                        x_m,
                        y_m,
                    });
                }
                g.heights[j * nx + i] = gap.value;
            }
        }
        Ok(g)
    }

    /// Volume of known terrain above `reference_z_m`, m^3.
    #[must_use]
    pub fn volume_above(&self, reference_z_m: f64) -> f64 {
        self.heights
            .iter()
            .filter(|h| h.is_finite())
            .map(|h| (h - reference_z_m).max(0.0))
            .sum::<f64>()
            * self.cell_area()
    }

    /// Moves a cutting edge of `width_m` (perpendicular to the digging plane of azimuth `azimuth_rad`) from
    /// `from` to `to` (world `[x, y, z]` of the edge centre) and lowers every known cell whose centre it
    /// passes over to the edge height there. Cells count when their centre's projection on the plane lies in
    /// the half-open interval swept by this step, so consecutive steps never cut a cell twice. Returns the
    /// removed volume, m^3, which equals the fall of [`Self::volume_above`].
    ///
    /// # Errors
    /// [`TerrainError::NonFinite`], [`TerrainError::InvalidArgument`] for a negative width.
    pub fn cut(
        &mut self,
        from: [f64; 3],
        to: [f64; 3],
        azimuth_rad: f64,
        width_m: f64,
    ) -> Result<f64> {
        if !(from.iter().chain(to.iter()).all(|v| v.is_finite())
            && azimuth_rad.is_finite()
            && width_m.is_finite())
        {
            return Err(TerrainError::NonFinite {
                what: "cutting edge",
            });
        }
        if width_m < 0.0 {
            return Err(TerrainError::InvalidArgument {
                what: "cutting width must not be negative",
            });
        }
        let (u, v) = (
            [azimuth_rad.cos(), azimuth_rad.sin()],
            [-azimuth_rad.sin(), azimuth_rad.cos()],
        );
        let proj = |p: [f64; 2]| (p[0] * u[0] + p[1] * u[1], p[0] * v[0] + p[1] * v[1]);
        let (s0, t0) = proj([from[0], from[1]]);
        let (s1, t1) = proj([to[0], to[1]]);
        if (s1 - s0).abs() < 1e-12 {
            return Ok(0.0);
        }
        let (smin, smax) = if s0 < s1 { (s0, s1) } else { (s1, s0) };
        // Bounding box of the swept quad, in cells.
        let half = 0.5 * width_m;
        let xs = [from[0] - half, from[0] + half, to[0] - half, to[0] + half];
        let ys = [from[1] - half, from[1] + half, to[1] - half, to[1] + half];
        let fold = |a: &[f64; 4], f: fn(f64, f64) -> f64| a.iter().copied().fold(a[0], f);
        let range = |lo: f64, hi: f64, o: f64, n: usize| {
            let a = ((lo - o) / self.resolution_m).floor().max(0.0) as usize;
            let b = (((hi - o) / self.resolution_m).ceil().max(0.0) as usize).min(n);
            (a, b)
        };
        let (i0, i1) = range(
            fold(&xs, f64::min),
            fold(&xs, f64::max),
            self.origin_x_m,
            self.nx,
        );
        let (j0, j1) = range(
            fold(&ys, f64::min),
            fold(&ys, f64::max),
            self.origin_y_m,
            self.ny,
        );
        let area = self.cell_area();
        let mut removed = 0.0;
        // `proj(cell_center(i, j))` is `x_i u + y_j v` per component: the column products once per
        // cut and the row products once per row, summed per cell (the same products and sums, so
        // bit for bit the same projections).
        let columns: Vec<(f64, f64)> = (i0..i1)
            .map(|i| {
                let x = self.cell_center(i, 0)[0];
                (x * u[0], x * v[0])
            })
            .collect();
        for j in j0..j1 {
            let y = self.cell_center(0, j)[1];
            let (yu, yv) = (y * u[1], y * v[1]);
            for (i, &(xu, xv)) in (i0..i1).zip(&columns) {
                let (sc, tc) = (xu + yu, xv + yv);
                // Half-open in the direction of travel: [start, end).
                let inside = if s1 < s0 {
                    sc > smin && sc <= smax
                } else {
                    sc >= smin && sc < smax
                };
                if !inside {
                    continue;
                }
                let lambda = (sc - s0) / (s1 - s0);
                let t_edge = t0 + lambda * (t1 - t0);
                if (tc - t_edge).abs() > half {
                    continue;
                }
                let z_edge = from[2] + lambda * (to[2] - from[2]);
                let k = j * self.nx + i;
                let h = self.heights[k];
                if h.is_finite() && h > z_edge {
                    removed += (h - z_edge) * area;
                    self.heights[k] = z_edge;
                }
            }
        }
        Ok(removed)
    }

    /// Deposits `volume_m3` as a conical spoil pile centred at `(x, y)` whose flanks stand at the angle of
    /// repose: cells rise to `max(h, apex - r tan(repose))`, the apex found by bisection so the added
    /// volume matches. Unknown cells take no material. Returns the deposited volume, m^3.
    ///
    /// # Errors
    /// [`TerrainError::NonFinite`], [`TerrainError::InvalidArgument`] for a negative volume or a repose
    /// angle outside (0, 90) degrees, [`TerrainError::OutOfGrid`] if the centre is outside the grid.
    pub fn deposit(&mut self, x_m: f64, y_m: f64, volume_m3: f64, repose_rad: f64) -> Result<f64> {
        if !(x_m.is_finite() && y_m.is_finite() && volume_m3.is_finite() && repose_rad.is_finite())
        {
            return Err(TerrainError::NonFinite { what: "deposit" });
        }
        if volume_m3 < 0.0 {
            return Err(TerrainError::InvalidArgument {
                what: "deposit volume must not be negative",
            });
        }
        if !(repose_rad > 0.0 && repose_rad < std::f64::consts::FRAC_PI_2 - 1e-6) {
            return Err(TerrainError::InvalidArgument {
                what: "angle of repose must lie in (0, 90) degrees",
            });
        }
        if self.cell_index(x_m, y_m).is_none() {
            return Err(TerrainError::OutOfGrid { x_m, y_m });
        }
        if volume_m3 == 0.0 {
            return Ok(0.0);
        }
        let slope = repose_rad.tan();
        let area = self.cell_area();
        let cells: Vec<(usize, f64, f64)> = (0..self.ny)
            .flat_map(|j| (0..self.nx).map(move |i| (i, j)))
            .filter_map(|(i, j)| {
                let h = self.cell(i, j)?;
                let [cx, cy] = self.cell_center(i, j);
                Some((j * self.nx + i, (cx - x_m).hypot(cy - y_m) * slope, h))
            })
            .collect();
        if cells.is_empty() {
            return Err(TerrainError::Unknown { x_m, y_m });
        }
        let added = |apex: f64| -> f64 {
            cells
                .iter()
                .map(|&(_, drop, h)| (apex - drop - h).max(0.0))
                .sum::<f64>()
                * area
        };
        let mut lo = cells
            .iter()
            .map(|c| c.1 + c.2)
            .fold(f64::INFINITY, f64::min);
        let mut hi = lo + 1.0;
        for _ in 0..200 {
            if added(hi) >= volume_m3 {
                break;
            }
            hi = lo + 2.0 * (hi - lo);
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if added(mid) < volume_m3 {
                lo = mid
            } else {
                hi = mid
            }
        }
        let apex = hi;
        let mut deposited = 0.0;
        for &(k, drop, h) in &cells {
            let add = (apex - drop - h).max(0.0);
            deposited += add * area;
            self.heights[k] = h + add;
        }
        Ok(deposited)
    }
}

#[derive(Debug, Clone, Copy)]
struct Gap {
    len: usize,
    value: f64,
}

/// The unknown run containing index `at` along one grid line, if bounded by known cells on both sides:
/// its length and the linearly interpolated value at `at`.
fn bounded_gap(h: &[f64], at: usize, n: usize, index: impl Fn(usize) -> usize) -> Option<Gap> {
    let mut a = at;
    while a > 0 && !h[index(a)].is_finite() {
        a -= 1;
    }
    let mut b = at;
    while b + 1 < n && !h[index(b)].is_finite() {
        b += 1;
    }
    let (ha, hb) = (h[index(a)], h[index(b)]);
    if !(ha.is_finite() && hb.is_finite()) || a == at || b == at {
        return None;
    }
    let t = (at - a) as f64 / (b - a) as f64;
    Some(Gap {
        len: b - a - 1,
        value: ha + t * (hb - ha),
    })
}

/// How [`TerrainGrid::plane_section`] fills the samples that fall on unknown cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GapFill {
    /// Linear between the known neighbours; beyond the first and the last known sample, their heights
    /// (the dig planners).
    Linear,
    /// The last known height carried forward; before the first known sample, its height (the planned
    /// session's soil monitor).
    HoldLast,
}

/// Terrain heights along the digging plane, sampled every `step_m` from `r_start_m` (horizontal distance
/// from the swing axis, i.e. base-frame `x`).
#[derive(Debug, Clone, PartialEq)]
pub struct SectionProfile {
    r_start_m: f64,
    step_m: f64,
    heights: Vec<f64>,
}

impl SectionProfile {
    /// A profile from samples.
    ///
    /// # Errors
    /// [`TerrainError::InvalidArgument`] for fewer than two samples or a non-positive step,
    /// [`TerrainError::NonFinite`] for non-finite values.
    pub fn new(r_start_m: f64, step_m: f64, heights: Vec<f64>) -> Result<Self> {
        if !(r_start_m.is_finite() && step_m.is_finite()) || heights.iter().any(|h| !h.is_finite())
        {
            return Err(TerrainError::NonFinite {
                what: "section profile",
            });
        }
        if step_m <= 0.0 || heights.len() < 2 {
            return Err(TerrainError::InvalidArgument {
                what: "profile needs step > 0 and two samples",
            });
        }
        Ok(Self {
            r_start_m,
            step_m,
            heights,
        })
    }

    /// A profile from a function of `r`.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn from_fn(
        r_start_m: f64,
        r_end_m: f64,
        step_m: f64,
        f: impl Fn(f64) -> f64,
    ) -> Result<Self> {
        if !(step_m > 0.0
            && r_end_m > r_start_m
            && ((r_end_m - r_start_m) / step_m) < MAX_CELLS as f64)
        {
            return Err(TerrainError::InvalidArgument {
                what: "profile needs step > 0 and end > start",
            });
        }
        let n = ((r_end_m - r_start_m) / step_m).floor() as usize + 1;
        Self::new(
            r_start_m,
            step_m,
            (0..n).map(|k| f(r_start_m + k as f64 * step_m)).collect(),
        )
    }

    /// First sample distance, m.
    #[must_use]
    pub fn r_start_m(&self) -> f64 {
        self.r_start_m
    }

    /// Last sample distance, m.
    #[must_use]
    pub fn r_end_m(&self) -> f64 {
        self.r_start_m + (self.heights.len() - 1) as f64 * self.step_m
    }

    /// Sample spacing, m.
    #[must_use]
    pub fn step_m(&self) -> f64 {
        self.step_m
    }

    fn locate(&self, r_m: f64) -> Result<(usize, f64)> {
        if !r_m.is_finite() {
            return Err(TerrainError::NonFinite {
                what: "profile distance",
            });
        }
        if r_m < self.r_start_m - 1e-9 || r_m > self.r_end_m() + 1e-9 {
            return Err(TerrainError::OutOfGrid { x_m: r_m, y_m: 0.0 });
        }
        let f = ((r_m - self.r_start_m) / self.step_m).max(0.0);
        let k = (f.floor() as usize).min(self.heights.len() - 2);
        Ok((k, (f - k as f64).clamp(0.0, 1.0)))
    }

    /// Surface height at distance `r_m`, m (linear between samples).
    ///
    /// # Errors
    /// [`TerrainError::OutOfGrid`] outside the profile, [`TerrainError::NonFinite`].
    pub fn height_at(&self, r_m: f64) -> Result<f64> {
        let (k, t) = self.locate(r_m)?;
        Ok(self.heights[k] + t * (self.heights[k + 1] - self.heights[k]))
    }

    /// Terrain slope angle at `r_m`, rad, positive when the ground rises away from the machine.
    ///
    /// # Errors
    /// As [`Self::height_at`].
    pub fn slope_at(&self, r_m: f64) -> Result<f64> {
        let (k, _) = self.locate(r_m)?;
        Ok((self.heights[k + 1] - self.heights[k]).atan2(self.step_m))
    }

    /// Whether every given base-frame point `[x, z]` (e.g. the tip and the bucket's heel) is above the
    /// surface: the end-of-Capture test of thesis 3.2. Points beyond the profile count as above.
    ///
    /// # Errors
    /// [`TerrainError::NonFinite`].
    pub fn is_above(&self, points: &[[f64; 2]]) -> Result<bool> {
        for p in points {
            match self.height_at(p[0]) {
                Ok(h) if p[1] <= h => return Ok(false),
                Ok(_) | Err(TerrainError::OutOfGrid { .. }) => {}
                Err(e) => return Err(e),
            }
            if !p[1].is_finite() {
                return Err(TerrainError::NonFinite {
                    what: "point height",
                });
            }
        }
        Ok(true)
    }
}

/// The swept-volume integrator of thesis 3.2 and Fig. 24: the terrain profile is stored before the dig,
/// and as the cutting edge moves toward the machine the area between that surface and the tip's path is
/// accumulated; times the bucket width it is the volume `V_s` that has passed over the edge into the
/// bucket. Only new ground counts (the edge's closest approach so far), so backing out and re-entering
/// does not count soil twice.
#[derive(Debug, Clone)]
pub struct SweptVolume {
    profile: SectionProfile,
    width_m: f64,
    area_m2: f64,
    front_r_m: f64,
    last: Option<[f64; 2]>,
}

impl SweptVolume {
    /// Starts integrating over the pre-dig `profile` for a bucket `width_m` wide.
    ///
    /// # Errors
    /// [`TerrainError::InvalidArgument`] for a non-positive width.
    pub fn new(profile: SectionProfile, width_m: f64) -> Result<Self> {
        if !(width_m.is_finite() && width_m > 0.0) {
            return Err(TerrainError::InvalidArgument {
                what: "bucket width must be positive",
            });
        }
        Ok(Self {
            profile,
            width_m,
            area_m2: 0.0,
            front_r_m: f64::INFINITY,
            last: None,
        })
    }

    /// The pre-dig profile.
    #[must_use]
    pub fn profile(&self) -> &SectionProfile {
        &self.profile
    }

    /// Swept volume so far, m^3.
    #[must_use]
    pub fn volume_m3(&self) -> f64 {
        self.area_m2 * self.width_m
    }

    /// Depth of a tip `(x, z)` below the pre-dig surface, m (negative above; vertical, not perpendicular).
    ///
    /// # Errors
    /// As [`SectionProfile::height_at`].
    pub fn depth_m(&self, tip_x_m: f64, tip_z_m: f64) -> Result<f64> {
        Ok(self.profile.height_at(tip_x_m)? - tip_z_m)
    }

    /// Advances the tip to base-frame `(x, z)` and returns the swept volume so far, m^3.
    ///
    /// # Errors
    /// [`TerrainError::NonFinite`]; a tip beyond the profile adds nothing.
    pub fn update(&mut self, tip_x_m: f64, tip_z_m: f64) -> Result<f64> {
        if !(tip_x_m.is_finite() && tip_z_m.is_finite()) {
            return Err(TerrainError::NonFinite {
                what: "tip position",
            });
        }
        let Some([r0, z0]) = self.last.replace([tip_x_m, tip_z_m]) else {
            self.front_r_m = tip_x_m;
            return Ok(self.volume_m3());
        };
        let (r1, z1) = (tip_x_m, tip_z_m);
        let hi = r0.min(self.front_r_m);
        if r1 < hi {
            let lo = r1.max(self.profile.r_start_m()).min(hi);
            let hi_c = hi.min(self.profile.r_end_m());
            if hi_c > lo {
                let n = (((hi_c - lo) / (0.5 * self.profile.step_m())).ceil() as usize)
                    .clamp(1, 10_000);
                let z_at = |r: f64| z0 + (r - r0) / (r1 - r0) * (z1 - z0);
                let depth = |r: f64| {
                    self.profile
                        .height_at(r)
                        .map(|h| (h - z_at(r)).max(0.0))
                        .unwrap_or(0.0)
                };
                let dr = (hi_c - lo) / n as f64;
                let mut area = 0.0;
                for k in 0..n {
                    let a = lo + k as f64 * dr;
                    area += 0.5 * (depth(a) + depth(a + dr)) * dr; // trapezoid over the path
                }
                self.area_m2 += area;
            }
            self.front_r_m = r1;
        }
        Ok(self.volume_m3())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const RES_M: f64 = 0.1;

    /// A bench: floor at 0, a 30 degree face from x = 6 m rising to a 2 m top.
    fn bench(x: f64) -> f64 {
        ((x - 6.0) * 30f64.to_radians().tan()).clamp(0.0, 2.0)
    }

    fn bench_grid() -> TerrainGrid {
        TerrainGrid::from_fn(0.0, -3.0, RES_M, 150, 60, |x, _| bench(x)).expect("grid")
    }

    #[test]
    fn bilinear_is_exact_on_planes_and_unknown_never_leaks() {
        let mut g = TerrainGrid::from_fn(0.0, 0.0, RES_M, 20, 20, |x, y| 0.3 * x - 0.2 * y + 1.0)
            .expect("grid");
        let h = g.height_at(0.77, 1.23).expect("h");
        assert!((h - (0.3 * 0.77 - 0.2 * 1.23 + 1.0)).abs() < 1e-12);
        g.set_cell(7, 12, None).expect("set");
        assert!(matches!(
            g.height_at(0.75, 1.25),
            Err(TerrainError::Unknown { .. })
        ));
        assert!(matches!(
            g.height_at(5.0, 0.5),
            Err(TerrainError::OutOfGrid { .. })
        ));
        assert!(matches!(
            g.height_at(f64::NAN, 0.5),
            Err(TerrainError::NonFinite { .. })
        ));
        assert!(g.volume_above(0.0).is_finite());
    }

    #[test]
    fn section_follows_the_dig_plane() {
        let g = bench_grid();
        let pose = MachinePose {
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: 0.0,
        };
        let p = g.section(&pose, 0.0, 1.0, 14.0, 0.05).expect("section");
        assert!((p.height_at(7.0).expect("h") - bench(7.0)).abs() < 0.02);
        assert!((p.slope_at(7.0).expect("slope") - 30f64.to_radians()).abs() < 0.02);
        // Swung 90 degrees the plane runs along +y where the grid ends at 3 m.
        assert!(
            g.section(&pose, std::f64::consts::FRAC_PI_2, 1.0, 8.0, 0.1)
                .is_err()
        );
    }

    #[test]
    fn plane_section_fills_unknown_samples_linearly_or_by_holding_the_last() {
        // Heights = x, unknown below 1.5 m, from 3 to 5 m and beyond 8 m: along the x axis every
        // metre from 1 to 9 m the samples at 1, 3, 4, 5, 8 and 9 m are unknown.
        let unknown = |x: f64| x < 1.5 || (3.0..5.0).contains(&x) || x > 8.0;
        let g = TerrainGrid::from_fn(0.0, -1.0, 0.1, 100, 20, |x, _| {
            if unknown(x) { f64::NAN } else { x }
        })
        .expect("grid");
        let pose = MachinePose::default();
        let heights = |fill| {
            let p = g
                .plane_section(&pose, 0.0, 1.0, 9.0, 1.0, fill)
                .expect("section");
            (1..=9)
                .map(|r| p.height_at(f64::from(r)).expect("h"))
                .collect::<Vec<_>>()
        };
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
        let linear = heights(GapFill::Linear);
        assert!(
            close(&linear, &[2.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 7.0, 7.0]),
            "{linear:?}"
        );
        let held = heights(GapFill::HoldLast);
        assert!(
            close(&held, &[2.0, 2.0, 2.0, 2.0, 2.0, 6.0, 7.0, 7.0, 7.0]),
            "{held:?}"
        );
        // Swung 90 degrees the plane leaves the grid at 1 m: nothing known.
        assert!(matches!(
            g.plane_section(
                &pose,
                std::f64::consts::FRAC_PI_2,
                1.0,
                9.0,
                1.0,
                GapFill::HoldLast
            ),
            Err(TerrainError::Unknown { .. })
        ));
        assert!(g.plane_heights(&pose, 0.0, 2.0, 1.0, 1.0).is_empty());
    }

    #[test]
    fn cut_volume_equals_grid_volume_change() {
        let mut g = bench_grid();
        let before = g.volume_above(-10.0);
        let mut removed = 0.0;
        // A curved dig path toward the machine in 1 mm steps along the x axis.
        let mut prev = [10.0, 0.0, 1.6];
        for k in 1..=4000 {
            let x = 10.0 - f64::from(k) * 0.001;
            let z = 1.6 - 0.8 * (std::f64::consts::PI * (10.0 - x) / 4.0).sin();
            let next = [x, 0.03, z];
            removed += g.cut(prev, next, 0.0, 1.3).expect("cut");
            prev = next;
        }
        let after = g.volume_above(-10.0);
        assert!(removed > 1.0, "{removed}");
        assert!(
            (before - after - removed).abs() < 1e-9,
            "{before} {after} {removed}"
        );
    }

    #[test]
    fn deposit_conserves_volume_and_respects_repose() {
        let mut g = TerrainGrid::new_flat(0.0, 0.0, RES_M, 100, 100, 0.0).expect("grid");
        let v = g
            .deposit(5.0, 5.0, 1.5, 35f64.to_radians())
            .expect("deposit");
        assert!((v - 1.5).abs() < 1e-6);
        assert!((g.volume_above(0.0) - 1.5).abs() < 1e-6);
        let tan = 35f64.to_radians().tan();
        for j in 0..99 {
            for i in 0..99 {
                let (a, b, c) = (g.cell(i, j), g.cell(i + 1, j), g.cell(i, j + 1));
                if let (Some(a), Some(b), Some(c)) = (a, b, c) {
                    assert!(
                        (a - b).abs() <= tan * RES_M + 1e-9 && (a - c).abs() <= tan * RES_M + 1e-9
                    );
                }
            }
        }
        assert!(g.deposit(5.0, 5.0, 1.0, 1.6).is_err());
    }

    #[test]
    fn scan_fills_small_gaps_and_rejects_large_ones() {
        let mut pts = Vec::new();
        for j in 0..20 {
            for i in 0..40 {
                let (x, y) = (0.05 + 0.1 * f64::from(i), 0.05 + 0.1 * f64::from(j));
                let shadow = (1.5..1.8).contains(&x); // 3-cell occlusion shadow
                if !shadow {
                    pts.push([x, y, 0.5 * x]);
                }
            }
        }
        let g = TerrainGrid::from_scan(&pts, 0.0, 0.0, 0.1, 40, 20, 4).expect("small gap filled");
        assert!((g.height_at(1.65, 1.0).expect("filled") - 0.825).abs() < 1e-9);
        let big: Vec<[f64; 3]> = pts
            .iter()
            .copied()
            .filter(|p| !(1.0..2.5).contains(&p[0]))
            .collect();
        assert!(matches!(
            TerrainGrid::from_scan(&big, 0.0, 0.0, 0.1, 40, 20, 4),
            Err(TerrainError::LargeGap { .. })
        ));
        assert!(matches!(
            TerrainGrid::from_scan(&[], 0.0, 0.0, 0.1, 40, 20, 4),
            Err(TerrainError::NoPoints)
        ));
    }

    #[test]
    fn swept_volume_of_a_straight_cut_is_depth_times_length_times_width() {
        let flat = SectionProfile::from_fn(0.0, 12.0, 0.05, |_| 1.0).expect("profile");
        let mut sv = SweptVolume::new(flat, 1.3).expect("sv");
        sv.update(9.0, 0.5).expect("start");
        for k in 1..=300 {
            sv.update(9.0 - f64::from(k) * 0.01, 0.5).expect("step");
        }
        // Backing out and re-entering counts nothing new.
        sv.update(8.0, 0.5).expect("back");
        sv.update(6.0, 0.5).expect("again");
        assert!(
            (sv.volume_m3() - 0.5 * 3.0 * 1.3).abs() < 1e-9,
            "{}",
            sv.volume_m3()
        );
        let p = sv.profile().clone();
        assert!(!p.is_above(&[[5.0, 0.9]]).expect("q"));
        assert!(p.is_above(&[[5.0, 1.1], [5.5, 1.2]]).expect("q"));
    }

    proptest! {
        #[test]
        fn cut_conserves_mass_for_random_edges(x0 in 0.0f64..15.0, x1 in 0.0f64..15.0, y in -2.0f64..2.0, z0 in -0.5f64..2.5, z1 in -0.5f64..2.5, az in -3.2f64..3.2, w in 0.0f64..2.0) {
            let mut g = bench_grid();
            let before = g.volume_above(-10.0);
            let removed = g.cut([x0, y, z0], [x1, y + 0.3, z1], az, w).expect("cut");
            prop_assert!(removed >= 0.0);
            prop_assert!((before - g.volume_above(-10.0) - removed).abs() < 1e-9);
        }
    }
}
