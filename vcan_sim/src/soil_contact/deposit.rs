//! Spilled and dumped material back on the terrain: a cone at the angle of repose under the bucket,
//! holding exactly the deposited volume.

use super::world::World;

impl World {
    /// Deposits `volume_m3` as a cone at the angle of repose centred on `(x, y)`, within 2.5 m.
    /// Returns the volume actually placed (0 when the point is off the map).
    pub fn deposit_local(&mut self, x_m: f64, y_m: f64, volume_m3: f64) -> f64 {
        if !(volume_m3 > 0.0 && x_m.is_finite() && y_m.is_finite()) {
            return 0.0;
        }
        let res = self.terrain.resolution_m();
        if self.terrain.cell_index(x_m, y_m).is_none() {
            return 0.0;
        }
        let slope = self.repose_rad.tan();
        let area = res * res;
        let target = volume_m3 / area;
        // A cell at height `h` and distance `r` from the centre has the base `h + r tan(repose)`: the
        // apex height at which the cone's flank reaches it. A cell rises to `max(h, apex - r tan)`.
        // 1. An upper bound of the apex. Over any set T of cells, the added volume
        //    `sum_T max(a - base, 0) >= |T| a - sum_T base`, so it reaches the target by
        //    `a = (target + sum_T base) / |T|`: the apex of T, and of the whole window (more cells hold
        //    more), is at most that. The apex of the cells within 1.5 times the cone's radius (on
        //    flat ground) is such a bound, and a tight one where the cone fits in them: Newton's
        //    method of step 3 over those cells alone (each iterate is the bound of the cells below
        //    it, so it stays an upper bound after any number of passes). Where the ground falls away
        //    (a bench face) their mean base alone left most of the 2.5 m window below the bound. A
        //    margin far above rounding is added.
        let cone_radius_m = (3.0 * volume_m3 / (std::f64::consts::PI * slope.max(1e-3))).cbrt();
        let near = ((1.5 * cone_radius_m / res).ceil() + 1.0).min(DEPOSIT_REACH_M / res);
        let mut near_bases = Vec::with_capacity(256);
        self.deposit_window([x_m, y_m], near, |_, _, h, d2| {
            near_bases.push(d2.sqrt() * slope + h);
        });
        let upper = match apex_from_above(&mut near_bases, target, f64::INFINITY) {
            Some((apex, _)) => apex + 1.0e-6 * (1.0 + apex.abs()),
            None => f64::INFINITY,
        };
        // 2. Only cells whose base is below that bound can receive material: the others are skipped
        //    without a square root. The apex of the kept cells is the apex of the whole window (the
        //    same lowest bases in the same order), and the skipped ones would add exactly zero.
        //    A block of cells of a row is skipped whole when its lowest cell cannot receive material
        //    even at the block's least distance from the centre (every cell's `d2` is at least that,
        //    its rise at most the lowest cell's, and the test is monotone under rounding): the same
        //    cells are kept, in the same order, without the square-distance test on most of the
        //    window where the ground around the cone is level.
        let mut cells = Vec::with_capacity(256);
        self.deposit_blocks(
            [x_m, y_m],
            DEPOSIT_REACH_M / res,
            |d2, lowest| {
                let rise = upper - lowest;
                rise > 0.0 && d2 * slope * slope < rise * rise
            },
            |i, j, h, d2| {
                let rise = upper - h;
                if rise > 0.0 && d2 * slope * slope < rise * rise {
                    cells.push((i, j, d2.sqrt() * slope + h));
                }
            },
        );
        // 3. The apex `a` solves `g(a) = sum max(a - base, 0) - target = 0`, with `g` convex, piecewise
        //    linear and increasing. Newton's method from the upper bound, `a' = a - g(a) / g'(a) =
        //    (target + sum of the bases below a) / their count` (step 1's bound over the cells below
        //    `a`), descends monotonically onto the root and stops on the exact linear piece once the
        //    set of cells below `a` no longer changes (usually within a few passes), without sorting.
        //    Only the order of the summation differs from sorting the bases (rounding level).
        let mut bases: Vec<f64> = cells.iter().map(|c| c.2).collect();
        let (mut apex, converged) =
            apex_from_above(&mut bases, target, upper).unwrap_or((upper, false));
        cells.retain(|c| c.2 < apex);
        if cells.is_empty() {
            return 0.0;
        }
        if !converged {
            // Many cells dropping out one pass at a time (not seen in practice): sort what is left.
            let mut bases: Vec<f64> = cells.iter().map(|c| c.2).collect();
            apex = cone_apex(&mut bases, target);
        }
        // Scale away the rounding so the placed volume matches exactly.
        let placed: f64 = cells.iter().map(|c| (apex - c.2).max(0.0)).sum::<f64>() * area;
        let scale = if placed > 0.0 {
            volume_m3 / placed
        } else {
            0.0
        };
        let mut total = 0.0;
        for &(i, j, base) in &cells {
            let add = (apex - base).max(0.0) * scale;
            if add > 0.0
                && let Some(h) = self.terrain.cell(i, j)
                && self.terrain.set_cell(i, j, Some(h + add)).is_ok()
            {
                total += add * area;
            }
        }
        total
    }

    /// Calls `f(i, j, height, squared distance from the point)` for the known cells within `reach`
    /// cells of the cell holding `point` (which is on the map), row by row.
    fn deposit_window(&self, point: [f64; 2], reach: f64, f: impl FnMut(usize, usize, f64, f64)) {
        self.deposit_blocks(point, reach, |_, _| true, f);
    }

    /// [`Self::deposit_window`] over the blocks of up to [`DEPOSIT_BLOCK`] cells of a row for which
    /// `keep(lower bound of the blocks' squared distances from the point, lowest known height in
    /// the block)` holds (the lowest height is infinite when none is known). Cells are visited in
    /// the same order as by the whole window.
    fn deposit_blocks(
        &self,
        point: [f64; 2],
        reach: f64,
        mut keep: impl FnMut(f64, f64) -> bool,
        mut f: impl FnMut(usize, usize, f64, f64),
    ) {
        let t = &self.terrain;
        let [x_m, y_m] = point;
        let Some((ci, cj)) = t.cell_index(x_m, y_m) else {
            return;
        };
        let reach = reach.ceil() as isize;
        let (nx, ny) = (t.nx() as isize, t.ny() as isize);
        let (i0, i1) = (
            (ci as isize - reach).max(0) as usize,
            (ci as isize + reach).min(nx - 1) as usize,
        );
        let (j0, j1) = (
            (cj as isize - reach).max(0) as usize,
            (cj as isize + reach).min(ny - 1) as usize,
        );
        // The squared x distances of the window's columns, once (the same products as per cell, so
        // `dx^2 + dy^2` is bit for bit the same), and the smallest of each block.
        let dx2: Vec<f64> = (i0..i1 + 1)
            .map(|i| {
                let dx = t.cell_center(i, j0)[0] - x_m;
                dx * dx
            })
            .collect();
        let block_dx2: Vec<f64> = dx2
            .chunks(DEPOSIT_BLOCK)
            .map(|c| c.iter().copied().fold(f64::INFINITY, f64::min))
            .collect();
        for j in j0..j1 + 1 {
            let Some(heights) = t.row(j) else {
                continue;
            };
            let heights = &heights[i0..i1 + 1];
            let dy = t.cell_center(i0, j)[1] - y_m;
            let dy2 = dy * dy;
            for (b, (block, block_dx2)) in heights.chunks(DEPOSIT_BLOCK).zip(&block_dx2).enumerate()
            {
                // The lowest known height (`h < lowest` is false for the NaN of an unknown cell).
                let lowest = block.iter().fold(
                    f64::INFINITY,
                    |lowest, &h| if h < lowest { h } else { lowest },
                );
                if !keep(block_dx2 + dy2, lowest) {
                    continue;
                }
                let k0 = b * DEPOSIT_BLOCK;
                for (k, &h) in block.iter().enumerate() {
                    // Heights are finite or NaN (unknown), as `TerrainGrid::cell` reads them.
                    if h.is_finite() {
                        f(i0 + k0 + k, j, h, dx2[k0 + k] + dy2);
                    }
                }
            }
        }
    }
}

/// Cells per block of a row in [`World::deposit_blocks`].
const DEPOSIT_BLOCK: usize = 8;

/// How far from its centre a spill or dump cone may reach (m).
const DEPOSIT_REACH_M: f64 = 2.5;
/// Newton passes of the cone apex before falling back to sorting the bases.
const APEX_NEWTON_PASSES: usize = 24;

/// Newton's method for the apex `a` of a cone of `target` (volume / cell area) over cells with the
/// given bases, from `start` (at or above the apex, or infinite): `a' = (target + sum of the bases
/// below a) / their count` (see `World::deposit_local`, step 3). Drops from `bases` the cells at or
/// above the last iterate. Returns the last iterate (an upper bound of the apex, whether converged or
/// not) and whether it converged within [`APEX_NEWTON_PASSES`]; `None` when no base is below
/// `start`.
fn apex_from_above(bases: &mut Vec<f64>, target: f64, start: f64) -> Option<(f64, bool)> {
    let mut apex = start;
    let mut last = None;
    for _ in 0..APEX_NEWTON_PASSES {
        bases.retain(|&b| b < apex);
        let (sum, count) = bases
            .iter()
            .fold((0.0, 0.0), |(sum, count), &b| (sum + b, count + 1.0));
        if count == 0.0 {
            return last.map(|a| (a, false));
        }
        let next = (target + sum) / count;
        if next >= apex {
            return Some((apex, true));
        }
        apex = next;
        last = Some(apex);
    }
    last.map(|a| (a, false))
}

/// The apex height of a cone of `target` (volume / cell area) over cells with the given bases: the
/// added volume `sum max(apex - base, 0)` is piecewise linear in the apex, so walk the bases upwards
/// until the cells below the apex hold the volume, then solve that linear piece. Sorts `bases`.
fn cone_apex(bases: &mut [f64], target: f64) -> f64 {
    bases.sort_unstable_by(f64::total_cmp);
    let mut sum = 0.0;
    for (k, &b) in bases.iter().enumerate() {
        // With the k lowest cells filled, raising the apex to `b` holds `k b - sum`.
        if k > 0 && k as f64 * b - sum >= target {
            return (target + sum) / k as f64;
        }
        sum += b;
    }
    (target + sum) / bases.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soil_contact::fixtures::*;

    /// The cone deposit as it was before the apex bound: every cell of the 2.5 m window sorted.
    fn deposit_by_full_sort(world: &mut World, x_m: f64, y_m: f64, volume_m3: f64) -> f64 {
        let t = &world.terrain;
        let res = t.resolution_m();
        let (ci, cj) = t.cell_index(x_m, y_m).unwrap();
        let reach = (DEPOSIT_REACH_M / res).ceil() as isize;
        let slope = world.repose_rad.tan();
        let mut cells = Vec::new();
        for j in (cj as isize - reach).max(0)..=(cj as isize + reach).min(t.ny() as isize - 1) {
            for i in (ci as isize - reach).max(0)..=(ci as isize + reach).min(t.nx() as isize - 1) {
                let (i, j) = (i as usize, j as usize);
                if let Some(h) = t.cell(i, j) {
                    let [cx, cy] = t.cell_center(i, j);
                    let (dx, dy) = (cx - x_m, cy - y_m);
                    cells.push((i, j, (dx * dx + dy * dy).sqrt() * slope + h));
                }
            }
        }
        let area = res * res;
        let mut bases: Vec<f64> = cells.iter().map(|c| c.2).collect();
        let apex = cone_apex(&mut bases, volume_m3 / area);
        let placed: f64 = cells.iter().map(|c| (apex - c.2).max(0.0)).sum::<f64>() * area;
        let mut total = 0.0;
        for &(i, j, base) in &cells {
            let add = (apex - base).max(0.0) * (volume_m3 / placed);
            if add > 0.0 {
                let h = world.terrain.cell(i, j).unwrap();
                world.terrain.set_cell(i, j, Some(h + add)).unwrap();
                total += add * area;
            }
        }
        total
    }

    /// The apex bound only skips cells that receive nothing, and the Newton apex lands on the sorted
    /// apex's linear piece: the terrain after a series of spills and dumps on rough ground (bench
    /// face, edges of the map, earlier cones) equals the whole window sorted to rounding (1e-12 m per
    /// cell; only the order of a sum differs), and the placed volumes are the same to 1e-12.
    #[test]
    fn cone_deposit_with_the_apex_bound_equals_the_full_window() {
        let mut fast = world();
        // Rough ground: a pit and a ridge near the bench face.
        for j in 90..110 {
            for i in 120..140 {
                let h = fast.terrain.cell(i, j).unwrap();
                let bump = 0.3 * ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.4;
                fast.terrain.set_cell(i, j, Some(h + bump)).unwrap();
            }
        }
        let mut full = fast.clone();
        let before = fast.clone();
        let deposits = [
            (5.2, 0.1, 0.05),
            (5.2, 0.1, 0.05),
            (4.0, -0.3, 1.5),
            (13.0, 0.0, 0.3),
            (-7.95, -9.95, 0.8),
            (5.3, 0.2, 0.02),
            (2.0, 1.0, 2.5),
        ];
        for (x, y, v) in deposits {
            let a = fast.deposit_local(x, y, v);
            let b = deposit_by_full_sort(&mut full, x, y, v);
            assert!(
                (a - b).abs() <= 1e-12 * b.abs(),
                "placed at ({x}, {y}): {a} vs {b}"
            );
        }
        let mut raised = 0;
        for j in 0..fast.terrain.ny() {
            for i in 0..fast.terrain.nx() {
                let (a, b) = (fast.terrain.cell(i, j), full.terrain.cell(i, j));
                let (Some(a), Some(b)) = (a, b) else {
                    assert_eq!(a.is_some(), b.is_some(), "cell ({i}, {j})");
                    continue;
                };
                assert!((a - b).abs() < 1e-12, "cell ({i}, {j}): {a} vs {b}");
                if before.terrain.cell(i, j).is_some_and(|h0| b > h0 + 1e-6) {
                    raised += 1;
                }
            }
        }
        assert!(raised > 100, "the deposits raised {raised} cells");
    }

    #[test]
    fn deposit_local_conserves_volume() {
        let mut w = world();
        let before = w.terrain.volume_above(-1.0);
        let placed = w.deposit_local(0.0, -6.0, 1.2);
        let after = w.terrain.volume_above(-1.0);
        assert!((placed - 1.2).abs() < 1e-9);
        assert!((after - before - 1.2).abs() < 1e-6);
    }
}
