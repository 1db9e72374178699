//! Slope stability of the bench material: ground the bucket cut steeper than the angle of repose
//! slumps to it (a mass-conserving cellular relaxation of the height grid near the cuts).

use super::world::World;

/// Period of the slope relaxation passes, s (5 Hz: a slump of a 1 m wall of 0.1 m cells settles
/// within a few seconds of simulated time).
const SLUMP_PERIOD_S: f64 = 0.2;
/// Gauss-Seidel sweeps per pass (fewer when a sweep moves nothing).
const SLUMP_SWEEPS: usize = 4;
/// Share of half a neighbour pair's excess height over the repose limit moved per visit (1 sets the
/// pair exactly at the limit).
const SLUMP_RATE: f64 = 1.0;
/// Cells added around the cut or moved cells for the next pass (how far a slump spreads per pass).
const SLUMP_MARGIN_CELLS: usize = 3;
/// Smallest height moved between two cells, m (below it the pair counts as at rest).
const SLUMP_MIN_MOVE_M: f64 = 1.0e-4;

impl World {
    /// Marks the cells `i0..i1`, `j0..j1` (exclusive ends) as cut, for the next relaxation pass.
    pub(super) fn note_cut(&mut self, i0: usize, i1: usize, j0: usize, j1: usize) {
        if let Some(slump) = &mut self.slump
            && i1 > i0
            && j1 > j0
        {
            slump.dirty = Some(union(slump.dirty, [i0, i1 - 1, j0, j1 - 1]));
        }
    }

    /// Advances the slope relaxation by `dt_s` (called by [`super::SoilContact::step`] while the edge is
    /// out of the soil): every `SLUMP_PERIOD_S` while cells are dirty, one
    /// pass of [`Self::relax_slopes`] over them and `SLUMP_MARGIN_CELLS` around; the cells it moved
    /// stay dirty for the next pass, so a slump spreads and settles over a few passes. Nothing to do
    /// (one branch) when the bench does not slump or nothing was cut.
    pub fn advance_slopes(&mut self, dt_s: f64) {
        let Some(slump) = &mut self.slump else {
            return;
        };
        let Some(dirty) = slump.dirty else {
            return;
        };
        slump.clock_s += dt_s.max(0.0);
        if slump.clock_s < SLUMP_PERIOD_S {
            return;
        }
        slump.clock_s = 0.0;
        let m = SLUMP_MARGIN_CELLS;
        let window = [
            dirty[0].saturating_sub(m),
            dirty[1] + m,
            dirty[2].saturating_sub(m),
            dirty[3] + m,
        ];
        let moved = self.relax_slopes(window, SLUMP_SWEEPS);
        if let Some(slump) = &mut self.slump {
            slump.dirty = moved;
        }
    }

    /// Angle-of-repose relaxation (avalanching) of the cells `window = [i0, i1, j0, j1]` (inclusive,
    /// clipped to the grid): `sweeps` Gauss-Seidel sweeps over the pairs of 8-connected neighbours
    /// inside the window; where the height difference of a pair exceeds `tan(repose)` times their
    /// distance, `SLUMP_RATE` of half the excess moves from the higher cell to the lower one (half
    /// the excess would leave the pair at the repose slope). Height moves between cells of equal
    /// area, so the terrain's volume is conserved (to rounding). Below the floor of a layered bench
    /// the native ground does not slump (a cell gives material down to the floor at most). Returns
    /// the cells that moved (inclusive box), `None` when none did or the bench does not slump.
    ///
    /// The standard cellular relaxation of a granular surface to its angle of repose (a sandpile or
    /// "thermal erosion" model: Bak, Tang & Wiesenfeld 1987; Musgrave, Kolb & Mace 1989; Sumner,
    /// O'Brien & Hodgins 1998 for excavated soil).
    pub fn relax_slopes(&mut self, window: [usize; 4], sweeps: usize) -> Option<[usize; 4]> {
        let tan = self.slump?.tan_repose;
        let (nx, ny) = (self.terrain.nx(), self.terrain.ny());
        let res = self.terrain.resolution_m();
        let full = [
            window[0].min(nx - 1),
            window[1].min(nx - 1),
            window[2].min(ny - 1),
            window[3].min(ny - 1),
        ];
        let floor_m = if self.native_soil.is_some() {
            self.floor_elevation_m
        } else {
            f64::NEG_INFINITY
        };
        let axis = tan * res;
        let diagonal = axis * std::f64::consts::SQRT_2;
        let h = self.terrain.heights_mut();
        let mut moved: Option<[usize; 4]> = None;
        let mut w = full;
        for _ in 0..sweeps {
            let [i0, i1, j0, j1] = w;
            let mut swept: Option<[usize; 4]> = None;
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let a = j * nx + i;
                    // East, north, north-east, north-west: every pair of the window once.
                    if i < i1 {
                        relax_pair(h, a, a + 1, axis, floor_m, nx, &mut swept);
                    }
                    if j < j1 {
                        relax_pair(h, a, a + nx, axis, floor_m, nx, &mut swept);
                        if i < i1 {
                            relax_pair(h, a, a + nx + 1, diagonal, floor_m, nx, &mut swept);
                        }
                        if i > i0 {
                            relax_pair(h, a, a + nx - 1, diagonal, floor_m, nx, &mut swept);
                        }
                    }
                }
            }
            let Some(b) = swept else {
                break;
            };
            moved = Some(union(moved, b));
            // The next sweep: where this one moved material, one cell around, within the window.
            w = [
                b[0].saturating_sub(1).max(full[0]),
                (b[1] + 1).min(full[1]),
                b[2].saturating_sub(1).max(full[2]),
                (b[3] + 1).min(full[3]),
            ];
        }
        moved
    }
}

/// One pair of neighbour cells `a`, `b` of the relaxation ([`World::relax_slopes`]): where their
/// height difference exceeds `limit` (`tan(repose)` times their distance), `SLUMP_RATE` of half the
/// excess moves from the higher to the lower cell, the higher one not below `floor_m`; moves under
/// `SLUMP_MIN_MOVE_M` are left. Adds both cells to `moved` when material moved.
#[inline]
fn relax_pair(
    h: &mut [f64],
    a: usize,
    b: usize,
    limit: f64,
    floor_m: f64,
    nx: usize,
    moved: &mut Option<[usize; 4]>,
) {
    let diff = h[a] - h[b];
    // NaN for an unknown cell.
    if diff.is_nan() || diff.abs() <= limit {
        return;
    }
    let (high, low) = if diff > 0.0 { (a, b) } else { (b, a) };
    let q = (0.5 * SLUMP_RATE * (diff.abs() - limit)).min(h[high] - floor_m);
    if q <= SLUMP_MIN_MOVE_M {
        return;
    }
    h[high] -= q;
    h[low] += q;
    let (ia, ja, ib, jb) = (a % nx, a / nx, b % nx, b / nx);
    *moved = Some(union(
        *moved,
        [ia.min(ib), ia.max(ib), ja.min(jb), ja.max(jb)],
    ));
}

/// The smallest box `[i0, i1, j0, j1]` (inclusive) holding `a` (if any) and `b`.
fn union(a: Option<[usize; 4]>, b: [usize; 4]) -> [usize; 4] {
    match a {
        Some(a) => [
            a[0].min(b[0]),
            a[1].max(b[1]),
            a[2].min(b[2]),
            a[3].max(b[3]),
        ],
        None => b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soil_contact::fixtures::*;

    #[test]
    fn a_vertical_cut_wall_slumps_to_the_repose_angle_and_conserves_volume() {
        let spec = crate::scenario::TerrainSpec {
            repose_deg: Some(40.0),
            ..Default::default()
        };
        let (_, mut w) = extended_world_with(Some(spec));
        // A 1 m deep, 1 m wide trench with vertical walls in the bench top behind the crest.
        let (i0, j0) = w.terrain.cell_index(-3.0, -0.5).unwrap();
        let (i1, j1) = w.terrain.cell_index(-2.0, 0.5).unwrap();
        for j in j0..j1 {
            for i in i0..i1 {
                let h = w.terrain.cell(i, j).unwrap();
                w.terrain.set_cell(i, j, Some(h - 1.0)).unwrap();
            }
        }
        let before = sum_heights(&w);
        assert!(steepest_deg(&w, i0 - 20, i1 + 20, j0 - 20, j1 + 20) > 80.0);
        // A cut marks the cells; passes run every SLUMP_PERIOD_S until nothing moves.
        w.note_cut(i0, i1, j0, j1);
        let mut passes = 0;
        while w.slump.unwrap().dirty.is_some() && passes < 10_000 {
            w.advance_slopes(SLUMP_PERIOD_S);
            passes += 1;
        }
        let after = sum_heights(&w);
        eprintln!("{passes} passes; volume {before} -> {after} (cell heights summed)");
        assert!(passes > 3 && passes < 10_000, "{passes}");
        assert!(
            (after - before).abs() < 1e-9 * before.abs().max(1.0),
            "{before} {after}"
        );
        // At rest every slope is within the move threshold of the repose angle.
        let steepest = steepest_deg(&w, i0 - 20, i1 + 20, j0 - 20, j1 + 20);
        assert!(steepest < 40.5, "{steepest} deg");
        // The trench was partly filled: its bottom rose, the rim fell.
        let mid = w.height(-2.5, 0.0);
        assert!(mid > -0.9, "{mid}");
        assert!(w.height(-3.1, 0.0) < -0.05);
        // The undisturbed 45 degree face far from the trench is untouched (nothing marked there).
        assert!((w.height(5.0, 3.0) + 1.0).abs() < 1e-9);
    }

    #[test]
    fn the_native_ground_below_the_floor_does_not_slump() {
        let spec = crate::scenario::TerrainSpec {
            repose_deg: Some(30.0),
            ..Default::default()
        };
        let (_, mut w) = extended_world_with(Some(spec));
        // A 0.5 m deep hole below the floor beyond the toe.
        let (i0, j0) = w.terrain.cell_index(8.0, -0.5).unwrap();
        let (i1, j1) = w.terrain.cell_index(9.0, 0.5).unwrap();
        for j in j0..j1 {
            for i in i0..i1 {
                w.terrain.set_cell(i, j, Some(-2.5)).unwrap();
            }
        }
        let before = sum_heights(&w);
        w.relax_slopes([i0 - 10, i1 + 10, j0 - 10, j1 + 10], 500);
        assert_eq!(sum_heights(&w), before);
        assert_eq!(w.height(8.5, 0.0), -2.5, "the hole stays: native ground");
        assert!(steepest_deg(&w, i0 - 5, i1 + 5, j0 - 5, j1 + 5) > 75.0);
        // Without the layer the same soil slumps into it.
        let (mut s, _) = extended_world_with(Some(spec));
        s.native_soil = None;
        let mut w = World::from_scenario(&s).unwrap();
        for j in j0..j1 {
            for i in i0..i1 {
                w.terrain.set_cell(i, j, Some(-2.5)).unwrap();
            }
        }
        w.relax_slopes([i0 - 10, i1 + 10, j0 - 10, j1 + 10], 500);
        let steepest = steepest_deg(&w, i0 - 5, i1 + 5, j0 - 5, j1 + 5);
        assert!(steepest < 30.5, "{steepest}");
        assert!(w.height(8.0, 0.0) > -2.4, "the rim fell in");
    }
}
