//! The bucket in the soil: the true terrain (a [`planner::terrain::TerrainGrid`]) with soil properties
//! per cell and hard inclusions, the cutting edge removing material into the bucket, spill and dump
//! back onto the terrain, and the soil force on the bucket.
//!
//! - **Cutting.** Each step the cutting edge (the bucket width, across the digging plane) moves from its
//!   previous to its current world position and every cell above it is lowered to the edge
//!   ([`TerrainGrid::cut`]). The removed mass is summed cell by cell with each cell's density, so the
//!   ledger is exact: removed = in bucket + spilled ([`MassLedger`]).
//! - **Filling, spill, dump.** The bucket holds up to its capacity while the edge is in the soil; the
//!   excess spills. Out of the soil it holds `capacity x retention(opening angle)`: material pours out
//!   when the opening tips below the horizontal, which is how a dump empties it. Spilled and dumped
//!   material is deposited as a cone at the angle of repose under the bucket.
//! - **Force.** The modified Fundamental Earthmoving Equation for sloped terrain with the swept-volume
//!   surcharge (Eqs. 14-17), `F = d^2 w gamma g N_w + c w d N_c + V_s gamma g N_q`, from
//!   [`planner::soil::fee_force_n`] (the same equations the planner's models use), with the geometry
//!   `Gamma = (d, alpha, rho, V_s)` measured here on the true grid (no section is built). It is directed
//!   at the soil-tool friction angle `delta` from the blade normal (Eq. 18) for either direction of
//!   travel, acting at the cutting edge. The
//!   payload's weight acts at its centroid through the gravity torques (Eq. A4), which replaces the
//!   moment of Eq. 19. Moving down into the ground meets a bearing resistance, and a boulder is a stiff
//!   obstacle the edge cannot cut.
//! - **Layered ground.** A bench may declare the native ground below its floor elevation
//!   (`[native_soil]` in the scenario, [`World::native_soil`]): the compacted ground a bench stands on,
//!   harder than the loosened bench material. When the edge is below the floor the Eq. 17 terms are
//!   split by layer along the wedge of Fig. 25 (`layered_failure_force_n`): with `f` the share of
//!   the cut depth below the floor, the cohesion term (acting along the failure plane, whose length is
//!   proportional to `d`) takes `1 - f` of the bench's `c N_c` and `f` of the native one's; the weight
//!   term (the wedge's area, proportional to `d^2`: the part below the floor is the similar triangle
//!   of depth `f d`) takes `1 - f^2` and `f^2`; the surcharge (the swept bench material, `gamma` of
//!   the bench) is carried across the plane with `N_q` weighted `1 - f`, `f`. The friction angle of
//!   Eq. 18 is weighted by `f`, the edge's bearing takes the native soil over the share of its face
//!   below the floor, and the material cut below the floor has the native density. A cut entirely
//!   above the floor is computed exactly as without the layer.

use planner::kinematics::TipForce;
use planner::machine::GRAVITY_M_PER_S2;
use planner::soil::{DigGeometry, SoilProperties, fee_factors, fee_force_n};
use planner::terrain::{TerrainError, TerrainGrid};
use rand::{RngExt, SeedableRng};

use crate::scenario::{Boulder, Scenario, SoilSpec};

/// Soil properties `Psi` of a scenario soil (degrees in the file, radians here).
fn soil_properties(s: &SoilSpec) -> SoilProperties {
    SoilProperties {
        density_kg_per_m3: s.density_kg_per_m3,
        failure_angle_rad: s.failure_angle_deg.to_radians(),
        friction_angle_rad: s.friction_angle_deg.to_radians(),
        tool_friction_angle_rad: s.tool_friction_angle_deg.to_radians(),
        cohesion_pa: s.cohesion_pa,
    }
}

/// A soil with the hidden soil effects added (cohesion not below 0, density not below 100 kg/m^3).
fn with_effects(mut c: SoilProperties, effects: &SoilEffects) -> SoilProperties {
    c.cohesion_pa = (c.cohesion_pa + effects.cohesion_pa).max(0.0);
    c.density_kg_per_m3 = (c.density_kg_per_m3 + effects.density_kg_per_m3).max(100.0);
    c
}

/// Soil changes applied everywhere (the `soil_cohesion` and `soil_density` hidden effects).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SoilEffects {
    /// Added cohesion (Pa).
    pub cohesion_pa: f64,
    /// Added density (kg/m^3).
    pub density_kg_per_m3: f64,
}

/// Mass bookkeeping of the soil that the bucket has moved.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MassLedger {
    /// Mass cut from the terrain (kg).
    pub removed_kg: f64,
    /// Mass that left the bucket again (spill and dump, kg).
    pub spilled_kg: f64,
    /// Volume deposited back on the terrain (m^3).
    pub deposited_m3: f64,
}

/// What the bucket holds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BucketContent {
    /// Bank volume (m^3).
    pub volume_m3: f64,
    /// Mass (kg).
    pub mass_kg: f64,
}

/// The true world the machine digs in.
#[derive(Debug, Clone)]
pub struct World {
    /// True terrain heights.
    pub terrain: TerrainGrid,
    /// Soil properties per cell (row-major, as the terrain grid).
    soil: Vec<SoilProperties>,
    /// The scenario's default soil (cells outside every soil region).
    default_soil: SoilProperties,
    /// The native ground below `floor_elevation_m` (`None`: the cell soils all the way down).
    native_soil: Option<SoilProperties>,
    /// Elevation of the layer boundary, the bench's floor (m, world z).
    floor_elevation_m: f64,
    /// Summed-area table of the cells whose density differs from the default, `(nx + 1) x (ny + 1)`:
    /// a cut whose box holds none of them takes its mass from the removed volume in one product.
    odd_density_sums: Vec<u32>,
    /// Hard inclusions.
    pub boulders: Vec<Boulder>,
    /// Angle of repose of spilled material (rad).
    pub repose_rad: f64,
    /// Slope stability of the bench material after cuts (`[terrain] repose_deg`), off when `None`.
    slump: Option<Slump>,
}

/// The angle-of-repose relaxation of the bench material near the cuts ([`World::advance_slopes`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slump {
    /// `tan` of the bench material's angle of repose.
    tan_repose: f64,
    /// Cells `[i0, i1, j0, j1]` (inclusive) the bucket cut or a slump moved since the last pass.
    dirty: Option<[usize; 4]>,
    /// Time since the last pass, s (runs while something is dirty).
    clock_s: f64,
}

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
/// Sweeps of the relaxation over the whole grid that settle an undulating bench before the start.
const INITIAL_SETTLE_SWEEPS: usize = 400;
/// Undulation: Fourier modes of the random field and the height over the floor over which its
/// amplitude tapers to zero at the toe, m.
const UNDULATION_MODES: usize = 64;
const UNDULATION_TAPER_M: f64 = 0.5;

impl World {
    /// Builds the terrain, soil map and boulders of a scenario.
    ///
    /// # Errors
    /// A [`TerrainError`] for an invalid grid.
    pub fn from_scenario(s: &Scenario) -> Result<Self, TerrainError> {
        let g = &s.grid;
        let nx = ((g.size_x_m / g.cell_m).round() as usize).max(2);
        let ny = ((g.size_y_m / g.cell_m).round() as usize).max(2);
        let b = s.bench;
        let slope = b.face_slope_deg.to_radians().tan();
        let terrain = TerrainGrid::from_fn(g.x_min_m, g.y_min_m, g.cell_m, nx, ny, |x, y| {
            let inside_y = (y - b.center_y_m).abs() <= 0.5 * b.width_m;
            let inside_x = x >= b.face_x_m && x <= b.face_x_m + b.length_m;
            if inside_y && inside_x {
                let rise = ((x - b.face_x_m) * slope).min(b.height_m);
                if b.cut { -rise } else { rise }
            } else {
                0.0
            }
        })?;
        let mut terrain = terrain;
        if s.terrain.undulation_std_m > 0.0 {
            add_undulation(
                &mut terrain,
                s.seed,
                s.terrain.undulation_std_m,
                s.terrain.undulation_correlation_m,
                b.floor_elevation_m,
            );
        }
        let default = soil_properties(&s.soil);
        let mut soil = vec![default; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let [x, y] = terrain.cell_center(i, j);
                for r in &s.soil_regions {
                    if (r.x_min_m..=r.x_max_m).contains(&x) && (r.y_min_m..=r.y_max_m).contains(&y)
                    {
                        soil[j * nx + i] = soil_properties(&r.soil);
                    }
                }
            }
        }
        let mut odd_density_sums = vec![0u32; (nx + 1) * (ny + 1)];
        for j in 0..ny {
            for i in 0..nx {
                let odd =
                    u32::from(soil[j * nx + i].density_kg_per_m3 != default.density_kg_per_m3);
                odd_density_sums[(j + 1) * (nx + 1) + i + 1] = odd
                    + odd_density_sums[j * (nx + 1) + i + 1]
                    + odd_density_sums[(j + 1) * (nx + 1) + i]
                    - odd_density_sums[j * (nx + 1) + i];
            }
        }
        let mut boulders = s.boulders.list.clone();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s.seed ^ 0xB0B0_1DE5);
        for _ in 0..s.boulders.random_count {
            let radius = rng.random_range(s.boulders.min_radius_m..=s.boulders.max_radius_m);
            let along = rng.random_range(0.0..=b.length_m.max(1e-3));
            let y = b.center_y_m + rng.random_range(-0.5..=0.5) * b.width_m;
            let (x, z) = if b.cut {
                // In the material behind the crest, above the cut's floor.
                (
                    b.face_x_m - along,
                    -rng.random_range(0.0..=b.height_m.max(1e-3)),
                )
            } else {
                let x = b.face_x_m + along;
                let top = ((x - b.face_x_m) * slope).min(b.height_m);
                (x, rng.random_range(0.0..=top.max(1e-3)))
            };
            boulders.push(Boulder {
                x_m: x,
                y_m: y,
                z_m: z,
                radius_m: radius,
            });
        }
        let mut world = Self {
            terrain,
            soil,
            default_soil: default,
            native_soil: s.native_soil.as_ref().map(soil_properties),
            floor_elevation_m: b.floor_elevation_m,
            odd_density_sums,
            boulders,
            repose_rad: s.spoil.repose_deg.to_radians(),
            slump: s.terrain.repose_deg.map(|deg| Slump {
                tan_repose: deg.to_radians().tan(),
                dirty: None,
                clock_s: 0.0,
            }),
        };
        // An undulating bench that slumps starts at rest: where the undulation left the ground
        // steeper than the repose angle (on the face) it has already slumped.
        if world.slump.is_some() && s.terrain.undulation_std_m > 0.0 {
            world.relax_slopes([0, nx - 1, 0, ny - 1], INITIAL_SETTLE_SWEEPS);
        }
        Ok(world)
    }

    /// Whether the bench material slumps after cuts (`[terrain] repose_deg` declared).
    pub fn slumps(&self) -> bool {
        self.slump.is_some()
    }

    /// Marks the cells `i0..i1`, `j0..j1` (exclusive ends) as cut, for the next relaxation pass.
    fn note_cut(&mut self, i0: usize, i1: usize, j0: usize, j1: usize) {
        if let Some(slump) = &mut self.slump
            && i1 > i0
            && j1 > j0
        {
            slump.dirty = Some(union(slump.dirty, [i0, i1 - 1, j0, j1 - 1]));
        }
    }

    /// Advances the slope relaxation by `dt_s` (called by [`SoilContact::step`] while the edge is
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

    /// Soil at a world point (the default cell at the map edge), with the soil effects applied.
    pub fn soil_at(&self, x_m: f64, y_m: f64, effects: &SoilEffects) -> SoilProperties {
        let nx = self.terrain.nx();
        let (i, j) = self.terrain.cell_index(x_m, y_m).unwrap_or((0, 0));
        let c = self
            .soil
            .get(j * nx + i)
            .copied()
            .unwrap_or(SoilProperties {
                density_kg_per_m3: 1700.0,
                cohesion_pa: 0.0,
                friction_angle_rad: 0.6,
                tool_friction_angle_rad: 0.35,
                failure_angle_rad: 0.5,
            });
        with_effects(c, effects)
    }

    /// The native ground below the floor elevation with the soil effects applied (`None` when the
    /// bench declares no layer), and that elevation (m, world z).
    pub fn native_soil(&self, effects: &SoilEffects) -> Option<(SoilProperties, f64)> {
        self.native_soil
            .map(|native| (with_effects(native, effects), self.floor_elevation_m))
    }

    /// Whether every cell in columns `i0..i1` and rows `j0..j1` has the default density.
    fn default_density_in(&self, i0: usize, i1: usize, j0: usize, j1: usize) -> bool {
        let w = self.terrain.nx() + 1;
        let at = |i: usize, j: usize| self.odd_density_sums.get(j * w + i).copied();
        match (at(i1, j1), at(i0, j1), at(i1, j0), at(i0, j0)) {
            (Some(a), Some(b), Some(c), Some(d)) => a + d == b + c,
            _ => false,
        }
    }

    /// Terrain height at a world point; 0 (the ground plane) outside the map or where unknown.
    pub fn height(&self, x_m: f64, y_m: f64) -> f64 {
        self.height_known(x_m, y_m).unwrap_or(0.0)
    }

    /// [`TerrainGrid::height_at`] (bilinear between cell centres), `None` where it is an error (off
    /// the map, unknown cells, not finite).
    pub fn height_known(&self, x_m: f64, y_m: f64) -> Option<f64> {
        self.terrain.height_at(x_m, y_m).ok()
    }

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

/// Adds a smooth Gaussian random field of standard deviation `std_m` and correlation length
/// `correlation_m` (covariance `std^2 exp(-r^2 / (2 L^2))`) to the cells above `floor_m`, tapered to
/// zero over [`UNDULATION_TAPER_M`] above the floor so the toe meets the floor, and never below it.
/// The field is the spectral sum of [`UNDULATION_MODES`] random cosines (the randomisation method,
/// Shinozuka & Deodatis 1991): `n(x) = sqrt(2 / M) sum cos(k_m . x + phi_m)`, wave vectors
/// `k_m ~ N(0, I / L^2)` (the Gaussian covariance's spectral density), phases uniform, unit variance;
/// drawn from `seed`, so a scenario and seed give the same bench.
fn add_undulation(
    terrain: &mut TerrainGrid,
    seed: u64,
    std_m: f64,
    correlation_m: f64,
    floor_m: f64,
) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x005E_ED0F_BE4C);
    let (nx, ny) = (terrain.nx(), terrain.ny());
    let xs: Vec<f64> = (0..nx).map(|i| terrain.cell_center(i, 0)[0]).collect();
    let ys: Vec<f64> = (0..ny).map(|j| terrain.cell_center(0, j)[1]).collect();
    let mut field = vec![0.0; nx * ny];
    let mut normal = || {
        // Box-Muller.
        let u1: f64 = rng.random_range(f64::EPSILON..1.0);
        let u2: f64 = rng.random_range(0.0..1.0);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let modes: Vec<[f64; 2]> = (0..2 * UNDULATION_MODES)
        .map(|_| normal())
        .collect::<Vec<_>>()
        .chunks(2)
        .map(|k| [k[0] / correlation_m, k[1] / correlation_m])
        .collect();
    let amplitude = std_m * (2.0 / UNDULATION_MODES as f64).sqrt();
    for k in modes {
        let phase = rng.random_range(0.0..std::f64::consts::TAU);
        // cos(kx x + phi + ky y) = cos(kx x + phi) cos(ky y) - sin(kx x + phi) sin(ky y).
        let (sx, cx): (Vec<f64>, Vec<f64>) =
            xs.iter().map(|x| (k[0] * x + phase).sin_cos()).unzip();
        for (j, y) in ys.iter().enumerate() {
            let (sy, cy) = (k[1] * y).sin_cos();
            for i in 0..nx {
                field[j * nx + i] += amplitude * (cx[i] * cy - sx[i] * sy);
            }
        }
    }
    let h = terrain.heights_mut();
    for (h, n) in h.iter_mut().zip(field) {
        if h.is_finite() && *h > floor_m {
            let taper = ((*h - floor_m) / UNDULATION_TAPER_M).clamp(0.0, 1.0);
            *h = (*h + taper * n).max(floor_m);
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

/// Geometry of the bucket for one contact step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactInput {
    /// Cutting-edge centre in the world `[x, y, z]`.
    pub tip_world: [f64; 3],
    /// Cutting edge in the base frame `[x, z]` (x = distance from the swing axis).
    pub tip_base: [f64; 2],
    /// Bucket pin in the base frame `[x, z]`.
    pub pin_base: [f64; 2],
    /// Tip velocity in the base frame `[vx, vz]`.
    pub tip_velocity_base: [f64; 2],
    /// `bucket_abs`: bucket line (pin -> tip) to the horizontal (rad).
    pub bucket_abs_rad: f64,
    /// Azimuth of the digging plane in the world (rad).
    pub azimuth_rad: f64,
    /// Machine position in the world `[x, y]` (the swing axis).
    pub machine_xy: [f64; 2],
    /// Bucket width (m).
    pub width_m: f64,
    /// Bucket capacity (m^3).
    pub capacity_m3: f64,
}

/// The soil-bucket interaction state.
#[derive(Debug, Clone, Default)]
pub struct SoilContact {
    /// What the bucket holds.
    pub content: BucketContent,
    /// Mass bookkeeping.
    pub ledger: MassLedger,
    last_tip: Option<[f64; 3]>,
    pending_spill_m3: f64,
    pending_at: [f64; 2],
    pending_age_s: f64,
    /// Whether the edge was in the soil in the last step.
    pub in_contact: bool,
}

/// Velocity scale (m/s) over which soil resistance builds up from rest (creep regularisation).
const CREEP_SPEED_M_PER_S: f64 = 0.01;
/// Thickness of the cutting edge (with its teeth) that bears on the soil when it is pushed in tip
/// first, m.
const EDGE_THICKNESS_M: f64 = 0.05;
/// Length of the bucket's back (bottom plate) that bears on the soil when it is pushed in, m.
const BACK_BEARING_LENGTH_M: f64 = 0.25;
/// Boulder contact stiffness (N/m) and damping (N s/m).
const BOULDER_STIFFNESS: f64 = 2.0e7;
const BOULDER_DAMPING: f64 = 2.0e5;

/// The soil's force on the bucket as a function of the tip velocity, for the geometry of one contact
/// step: the FEE failure force (Eq. 18) and the bearing of the edge and of the back, each mobilised
/// from rest over the creep speed (1 cm/s), plus a force that does not depend on the velocity (the
/// boulders). The plant evaluates it at every physics step with the current velocity and takes its
/// velocity gradient implicitly: the mobilisation is a steep damper (force / creep speed, ~1e7 N s/m)
/// that, held explicitly over a 5 ms contact step against the oil column, drove the stick into a
/// 100 Hz limit cycle with load swings of about 1 MN.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ContactLaw {
    /// Fully mobilised FEE failure force (N).
    pub failure_n: f64,
    /// Blade direction (edge toward the pin), base frame.
    pub blade: [f64; 2],
    /// `(sin, cos)` of the soil-tool friction angle delta.
    pub friction: (f64, f64),
    /// Fully mobilised bearing force of the edge pushed in tip first (N), along `blade`.
    pub edge_n: f64,
    /// Fully mobilised bearing force of the back pushed in (N), along `opening`.
    pub back_n: f64,
    /// Direction the bucket opening faces, base frame.
    pub opening: [f64; 2],
    /// Force independent of the velocity (boulders; penalty and damping held for the step), N.
    pub held: [f64; 2],
}

impl ContactLaw {
    /// The force on the bucket at tip velocity `v` (base frame `[vx, vz]`).
    pub fn force(&self, v: [f64; 2]) -> TipForce {
        let (f, _) = self.evaluate(v, false);
        TipForce {
            fx_n: f[0],
            fz_n: f[1],
            my_nm: 0.0,
        }
    }

    /// `d force / d v` (2 x 2, row = force component, column = velocity component) at `v`, with the
    /// directions of the forces held (the travel direction at `v`).
    pub fn gradient(&self, v: [f64; 2]) -> [[f64; 2]; 2] {
        self.evaluate(v, true).1
    }

    fn evaluate(&self, v: [f64; 2], want_gradient: bool) -> ([f64; 2], [[f64; 2]; 2]) {
        let mut force = self.held;
        let mut grad = [[0.0; 2]; 2];
        // `scale * tanh(s / creep)` along `dir`, with `s` of gradient `ds` in the velocity.
        let mut add = |scale: f64, s: f64, ds: [f64; 2], dir: [f64; 2]| {
            let x = s / CREEP_SPEED_M_PER_S;
            let t = x.tanh();
            force[0] += scale * t * dir[0];
            force[1] += scale * t * dir[1];
            if want_gradient {
                let slope = scale * (1.0 - t * t) / CREEP_SPEED_M_PER_S;
                for r in 0..2 {
                    for c in 0..2 {
                        grad[r][c] += slope * dir[r] * ds[c];
                    }
                }
            }
        };
        let b = self.blade;
        if self.failure_n != 0.0 {
            // The normal into the soil ahead of the edge, on the side the edge travels.
            let travel_sign = if v[0] > 0.0 { 1.0 } else { -1.0 };
            let mut n = [b[1], -b[0]];
            if n[0] * travel_sign < 0.0 {
                n = [-n[0], -n[1]];
            }
            let (sd, cd) = self.friction;
            // Eq. 18 on the bucket: against the normal, and up the blade by friction.
            let dir = [-cd * n[0] + sd * b[0], -cd * n[1] + sd * b[1]];
            let speed = v[0].hypot(v[1]);
            let ds = if speed > 1e-12 {
                [v[0] / speed, v[1] / speed]
            } else {
                [0.0, 0.0]
            };
            add(self.failure_n, speed, ds, dir);
        }
        let tip_first = -(v[0] * b[0] + v[1] * b[1]);
        if self.edge_n != 0.0 && tip_first > 0.0 {
            add(self.edge_n, tip_first, [-b[0], -b[1]], b);
        }
        let o = self.opening;
        let back_first = -(v[0] * o[0] + v[1] * o[1]);
        if self.back_n != 0.0 && back_first > 0.0 {
            add(self.back_n, back_first, [-o[0], -o[1]], o);
        }
        (force, grad)
    }
}

impl SoilContact {
    /// Moves the edge, cuts the terrain, updates the bucket content and returns the force of the soil
    /// on the bucket (base frame, at the cutting edge).
    pub fn step(
        &mut self,
        world: &mut World,
        input: &ContactInput,
        dt_s: f64,
        effects: &SoilEffects,
    ) -> TipForce {
        self.step_law(world, input, dt_s, effects)
            .force(input.tip_velocity_base)
    }

    /// As [`Self::step`], returning the force as a function of the tip velocity (for the geometry
    /// of this step) instead of its value at `input.tip_velocity_base`.
    pub fn step_law(
        &mut self,
        world: &mut World,
        input: &ContactInput,
        dt_s: f64,
        effects: &SoilEffects,
    ) -> ContactLaw {
        let tip = input.tip_world;
        if !tip.iter().all(|v| v.is_finite()) {
            return ContactLaw::default();
        }
        // 1. Cut along the edge's path and move the material into the bucket.
        if let Some(prev) = self.last_tip {
            self.cut(world, prev, tip, input, effects);
        }
        self.last_tip = Some(tip);

        // Fast path: the edge well above the ground around it and nothing in the bucket to spill.
        let ground = world.height(tip[0], tip[1]);
        if tip[2] > ground + 0.6 && self.content.volume_m3 <= 0.0 && self.pending_spill_m3 <= 0.0 {
            self.in_contact = false;
            world.advance_slopes(dt_s);
            let boulder = self.boulder_force(world, input);
            return ContactLaw {
                held: [boulder.fx_n, boulder.fz_n],
                ..ContactLaw::default()
            };
        }

        // 2. Soil geometry at the edge (Gamma = (d, alpha, rho, V_s)).
        let u = [input.azimuth_rad.cos(), input.azimuth_rad.sin()];
        // Terrain height `offset` metres farther out along the digging plane than the edge.
        let at_r = |offset: f64| world.height(tip[0] + offset * u[0], tip[1] + offset * u[1]);
        let v = input.tip_velocity_base;
        let ahead = if v[0] > 0.0 { 0.15 } else { -0.15 };
        // `at_r(0.0)` is `ground` (the same point on the same terrain).
        let surface = ground.max(at_r(ahead));
        let depth_vertical = surface - tip[2];
        self.in_contact = depth_vertical > 0.0;

        let mut law = ContactLaw::default();
        if self.in_contact {
            let alpha = ((at_r(0.25) - at_r(-0.25)) / 0.5).atan();
            let soil = world.soil_at(tip[0], tip[1], effects);
            // Eq. 17 measures d perpendicular to the terrain.
            let d = depth_vertical * alpha.cos();
            // Blade direction (up from the edge toward the pin) and the normal into the soil ahead.
            let b = [
                input.pin_base[0] - input.tip_base[0],
                input.pin_base[1] - input.tip_base[1],
            ];
            let nb = b[0].hypot(b[1]).max(1e-9);
            let b = [b[0] / nb, b[1] / nb];
            let travel_sign = if v[0] > 0.0 { 1.0 } else { -1.0 };
            // Rake angle (Fig. 25): between the blade and the terrain surface behind the edge.
            let blade_from_travel = b[1].atan2(b[0] * travel_sign);
            let rho = (std::f64::consts::PI - blade_from_travel + alpha * travel_sign)
                .clamp(0.1, std::f64::consts::PI - 0.1);
            let gamma = DigGeometry {
                depth_m: d,
                slope_rad: alpha,
                rake_rad: -rho, // the thesis's sign (planner::soil)
                swept_volume_m3: self.content.volume_m3,
            };
            // The native ground below the floor (layered benches): the share of the cut depth below
            // the floor (the wedge's failure plane runs from the edge up to the surface) and the
            // share of the edge's bearing face below it.
            let native = world.native_soil(effects);
            let (native, below, edge_below) = match native {
                Some((native, floor_m)) if tip[2] < floor_m => (
                    native,
                    ((floor_m - tip[2]) / depth_vertical).clamp(0.0, 1.0),
                    ((floor_m - tip[2]) / EDGE_THICKNESS_M).clamp(0.0, 1.0),
                ),
                _ => (soil, 0.0, 0.0),
            };
            // Without depth below the floor this is the bench soil's failure_force_n.
            let f = layered_failure_force_n(&soil, &native, below, &gamma, input.width_m);
            // Eq. 18: the tool force on the soil is at delta from the blade normal; on the bucket it is
            // the opposite: against the normal, and up the blade by friction (`ContactLaw`),
            // mobilised from rest over the creep speed. On a layered cut delta is weighted by the
            // share of the blade's contact below the floor.
            let delta = (1.0 - below) * soil.tool_friction_angle_rad
                + below * native.tool_friction_angle_rad;
            law.failure_n = f;
            law.blade = b;
            law.friction = delta.sin_cos();
            // Bearing resistance (bearing pressure c N_c + gamma g d N_q + q0): the cutting edge pushed in
            // tip first (its speed along the bucket line, pin -> tip) bears on its face, bucket width x
            // EDGE_THICKNESS_M, directed back up the blade; the bucket's back (bottom plate) pushed into
            // the soil (speed against the opening) bears over width x BACK_BEARING_LENGTH_M, directed
            // toward the opening. Motion into the opening meets the FEE wedge above. (A plate area for
            // any downward motion stopped a sharp edge at the surface with ~1e5 N.)
            // On a layered cut the native ground bears over the share of the edge's face below the
            // floor (the same share for the back plate, which rides behind the edge).
            let bearing = |s: &SoilProperties| {
                s.cohesion_pa * 40.0
                    + s.density_kg_per_m3 * GRAVITY_M_PER_S2 * d.max(0.0) * 30.0
                    + 2.0e4
            };
            let pressure = if edge_below > 0.0 {
                (1.0 - edge_below) * bearing(&soil) + edge_below * bearing(&native)
            } else {
                bearing(&soil)
            };
            law.edge_n = pressure * input.width_m * EDGE_THICKNESS_M;
            // The opening faces bucket_abs - 90 degrees (as in `spill`).
            let (sa, ca) = input.bucket_abs_rad.sin_cos();
            law.opening = [sa, -ca];
            law.back_n = pressure * input.width_m * BACK_BEARING_LENGTH_M;
        }
        let boulder = self.boulder_force(world, input);
        law.held = [boulder.fx_n, boulder.fz_n];
        // 3. Capacity, spill and dump.
        self.spill(world, input, dt_s);
        // 4. Ground the cuts left steeper than its angle of repose slumps (benches that declare it),
        //    once the edge is out of the soil: while it cuts, the bucket holds the walls around it
        //    and the soil failing ahead of the edge goes into the bucket (the cut and Eq. 17 above),
        //    not into the cells under the bucket behind the edge.
        if !self.in_contact {
            world.advance_slopes(dt_s);
        }
        law
    }

    /// Boulders: a stiff obstacle the edge cannot cut (penalty force along the outward normal).
    fn boulder_force(&self, world: &World, input: &ContactInput) -> TipForce {
        let tip = input.tip_world;
        let u = [input.azimuth_rad.cos(), input.azimuth_rad.sin()];
        let v = input.tip_velocity_base;
        let mut force = [0.0, 0.0];
        for boulder in &world.boulders {
            let rel = [
                tip[0] - boulder.x_m,
                tip[1] - boulder.y_m,
                tip[2] - boulder.z_m,
            ];
            let dist = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt();
            let pen = boulder.radius_m - dist;
            if pen > 0.0 && dist > 1e-9 {
                let normal_h = (rel[0] * u[0] + rel[1] * u[1]) / dist;
                let normal_z = rel[2] / dist;
                let v_n = v[0] * normal_h + v[1] * normal_z;
                let push = (BOULDER_STIFFNESS * pen - BOULDER_DAMPING * v_n).max(0.0);
                force[0] += push * normal_h;
                force[1] += push * normal_z;
            }
        }
        TipForce {
            fx_n: force[0],
            fz_n: force[1],
            my_nm: 0.0,
        }
    }

    fn cut(
        &mut self,
        world: &mut World,
        from: [f64; 3],
        to: [f64; 3],
        input: &ContactInput,
        effects: &SoilEffects,
    ) {
        let t = &world.terrain;
        let res = t.resolution_m();
        let [ox, oy] = t.origin();
        let half = 0.5 * input.width_m + res;
        let xs = [from[0] - half, from[0] + half, to[0] - half, to[0] + half];
        let ys = [from[1] - half, from[1] + half, to[1] - half, to[1] + half];
        let lo_hi = |a: &[f64; 4]| {
            (
                a.iter().copied().fold(f64::INFINITY, f64::min),
                a.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            )
        };
        let ((x0, x1), (y0, y1)) = (lo_hi(&xs), lo_hi(&ys));
        let lowest = world
            .height_known(to[0], to[1])
            .unwrap_or(f64::INFINITY)
            .max(
                world
                    .height_known(from[0], from[1])
                    .unwrap_or(f64::INFINITY),
            );
        // Nothing to cut when the edge stays well above the ground around it.
        if from[2].min(to[2]) > lowest + 0.5 {
            return;
        }
        let i0 = (((x0 - ox) / res).floor().max(0.0) as usize).min(t.nx());
        let i1 = (((x1 - ox) / res).ceil().max(0.0) as usize).min(t.nx());
        let j0 = (((y0 - oy) / res).floor().max(0.0) as usize).min(t.ny());
        let j1 = (((y1 - oy) / res).ceil().max(0.0) as usize).min(t.ny());
        let area = res * res;
        // The native ground of a layered bench has its own density below the floor.
        let native_below = world
            .native_soil
            .filter(|_| from[2].min(to[2]) < world.floor_elevation_m)
            .map(|n| n.density_kg_per_m3);
        let (volume, mass) = if native_below.is_none() && world.default_density_in(i0, i1, j0, j1) {
            // One soil density under the whole edge path: the mass is the removed volume times it.
            let Ok(volume) = world
                .terrain
                .cut(from, to, input.azimuth_rad, input.width_m)
            else {
                return;
            };
            let density = world.default_soil.density_kg_per_m3 + effects.density_kg_per_m3;
            (volume, volume * density)
        } else {
            // The cells whose density differs from the default, with their heights before the cut
            // (rows without any skipped by the summed-area table): the mass is the removed volume
            // times the default density plus, for each of them, its removed volume times the
            // difference (the same mass as summing every cell with its own density, to rounding,
            // without copying the whole box).
            // Below the floor of a layered bench every cell of the box is visited: the part of its
            // removed column below the floor has the native density.
            let nx = t.nx();
            let default_density = world.default_soil.density_kg_per_m3;
            let mut odd = Vec::new();
            for j in j0..j1 {
                if native_below.is_none() && world.default_density_in(i0, i1, j, j + 1) {
                    continue;
                }
                for i in i0..i1 {
                    let excess = world.soil[j * nx + i].density_kg_per_m3 - default_density;
                    if excess != 0.0 || native_below.is_some() {
                        odd.push((i, j, excess, t.cell(i, j).unwrap_or(f64::NAN)));
                    }
                }
            }
            let Ok(volume) = world
                .terrain
                .cut(from, to, input.azimuth_rad, input.width_m)
            else {
                return;
            };
            let mut mass = volume * (default_density + effects.density_kg_per_m3);
            let floor_m = world.floor_elevation_m;
            for (i, j, excess, h0) in odd {
                let h1 = world.terrain.cell(i, j).unwrap_or(h0);
                if h0.is_finite() && h1 < h0 {
                    match native_below {
                        Some(native) => {
                            // The column [h1, h0] splits at the floor: above it the cell's soil,
                            // below it the native ground.
                            let under = (h0.min(floor_m) - h1).max(0.0);
                            mass += (h0 - h1 - under) * area * excess
                                + under * area * (native - default_density);
                        }
                        None => mass += (h0 - h1) * area * excess,
                    }
                }
            }
            (volume, mass)
        };
        if volume > 0.0 {
            world.note_cut(i0, i1, j0, j1);
        }
        self.ledger.removed_kg += mass;
        self.content.volume_m3 += volume;
        self.content.mass_kg += mass;
    }

    fn spill(&mut self, world: &mut World, input: &ContactInput, dt_s: f64) {
        let c = &mut self.content;
        // The opening faces bucket_abs - 90 degrees; it holds while that points up.
        let opening_up = (input.bucket_abs_rad - std::f64::consts::FRAC_PI_2).sin();
        let retention = if self.in_contact {
            1.0
        } else {
            ((opening_up + 0.5) / 1.0).clamp(0.0, 1.0)
        };
        let holdable = input.capacity_m3 * retention;
        if c.volume_m3 > holdable && c.volume_m3 > 0.0 {
            // Overflow while digging is immediate; pouring out in the air takes time.
            let out = if self.in_contact {
                c.volume_m3 - holdable
            } else {
                (c.volume_m3 - holdable).min(3.0 * dt_s.max(0.0))
            };
            let mass = c.mass_kg * out / c.volume_m3;
            c.volume_m3 -= out;
            c.mass_kg -= mass;
            if c.volume_m3 <= 1e-12 {
                // Give the last crumbs' mass to the spill so the ledger closes exactly.
                self.ledger.spilled_kg += c.mass_kg;
                c.volume_m3 = 0.0;
                c.mass_kg = 0.0;
            }
            self.ledger.spilled_kg += mass;
            self.pending_spill_m3 += out;
            self.pending_at = [input.tip_world[0], input.tip_world[1]];
        }
        if self.pending_spill_m3 > 0.0 {
            self.pending_age_s += dt_s.max(0.0);
        }
        // Deposit in batches (a cone fit is costly): 0.05 m^3 or every 0.25 s.
        if self.pending_spill_m3 > 0.05
            || (self.pending_spill_m3 > 0.0 && self.pending_age_s > 0.25)
        {
            self.pending_age_s = 0.0;
            let placed = world.deposit_local(
                self.pending_at[0],
                self.pending_at[1],
                self.pending_spill_m3,
            );
            self.ledger.deposited_m3 += placed;
            self.pending_spill_m3 = 0.0;
        }
    }
}

/// Closest approach of the rake to the wedge's failure limit, rad. Eq. 17's denominator
/// `cos(rho + delta) + sin(rho + delta) cot(beta + phi)` equals `sin(beta + phi + rho + delta) /
/// sin(beta + phi)` and vanishes as the rake plus the three friction and failure angles reach 180
/// degrees, where the FEE force grows without bound (a blade flipping its direction of travel inside a
/// full bucket gave 12 MN, two orders of magnitude above the thesis's ~1e5 N digging forces). A blade at
/// or past that rake still bulldozes the soil ahead of it, so the force is evaluated at the rake this
/// far from the limit: it saturates (at about four times the force at a typical 45 degree rake) instead
/// of diverging or vanishing.
const RAKE_LIMIT_MARGIN_RAD: f64 = 0.17;

/// The FEE force magnitude on the bucket (Eqs. 14-17, [`planner::soil::fee_force_n`]), N. Zero out of
/// the soil and for soil properties outside their physical range; near or past the wedge's failure
/// limit the rake is held [`RAKE_LIMIT_MARGIN_RAD`] from it, so the simulator never sees an unbounded
/// force.
fn failure_force_n(soil: &SoilProperties, gamma: &DigGeometry, width_m: f64) -> f64 {
    if gamma.depth_m <= 0.0 {
        return 0.0;
    }
    fee_force_n(soil, &rake_within_limit(soil, gamma), width_m).unwrap_or(0.0)
}

/// The geometry with the rake held [`RAKE_LIMIT_MARGIN_RAD`] from the wedge's failure limit of `soil`.
fn rake_within_limit(soil: &SoilProperties, gamma: &DigGeometry) -> DigGeometry {
    let limit = std::f64::consts::PI
        - soil.failure_angle_rad
        - soil.friction_angle_rad
        - soil.tool_friction_angle_rad;
    let rake = (-gamma.rake_rad).min(limit - RAKE_LIMIT_MARGIN_RAD);
    DigGeometry {
        rake_rad: -rake,
        ..*gamma
    }
}

/// The FEE force magnitude on the bucket for a cut reaching from the bench material (`upper`) into
/// the native ground below the floor (`lower`), N: Eq. 17's terms split along the wedge of Fig. 25,
/// with `below` the share of the cut depth `d` under the floor (the failure plane is straight from
/// the edge to the surface, so the same share of its length):
///
/// `F = d^2 w g [(1 - f^2) gamma_u N_w,u + f^2 gamma_l N_w,l] + w d [(1 - f) c_u N_c,u + f c_l N_c,l]
///      + V_s gamma_u g [(1 - f) N_q,u + f N_q,l]`
///
/// The weight term is the wedge's area (`~ d^2`; the part below the floor is the similar triangle of
/// depth `f d`), the cohesion term acts along the failure plane (`~ d`), and the surcharge is the
/// swept bench material carried across that plane. Each layer's factors are its own (Eq. 17), with the
/// rake held from its own failure limit as in [`failure_force_n`]. `below = 0` gives
/// [`failure_force_n`] of the upper soil exactly, `below = 1` the lower soil's wedge under the bench
/// material's surcharge. A layering approximation (a superposition of the two wedges' terms), not a
/// two-layer wedge analysis: the failure plane's angle is not re-solved for the layers.
fn layered_failure_force_n(
    upper: &SoilProperties,
    lower: &SoilProperties,
    below: f64,
    gamma: &DigGeometry,
    width_m: f64,
) -> f64 {
    let f = below.clamp(0.0, 1.0);
    if f <= 0.0 {
        return failure_force_n(upper, gamma, width_m);
    }
    if gamma.depth_m <= 0.0 || !(width_m.is_finite() && width_m > 0.0) {
        return 0.0;
    }
    let (Ok(nu), Ok(nl)) = (
        fee_factors(upper, &rake_within_limit(upper, gamma)),
        fee_factors(lower, &rake_within_limit(lower, gamma)),
    ) else {
        return 0.0;
    };
    let g = GRAVITY_M_PER_S2;
    let d = gamma.depth_m;
    let weight = d
        * d
        * width_m
        * g
        * ((1.0 - f * f) * upper.density_kg_per_m3 * nu.n_w
            + f * f * lower.density_kg_per_m3 * nl.n_w);
    let cohesion =
        width_m * d * ((1.0 - f) * upper.cohesion_pa * nu.n_c + f * lower.cohesion_pa * nl.n_c);
    let surcharge =
        gamma.swept_volume_m3 * upper.density_kg_per_m3 * g * ((1.0 - f) * nu.n_q + f * nl.n_q);
    let force = weight + cohesion + surcharge;
    if force.is_finite() {
        force.max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn world() -> World {
        World::from_scenario(&Scenario::default_bench().unwrap()).unwrap()
    }

    fn input_at(x: f64, z: f64) -> ContactInput {
        ContactInput {
            tip_world: [x, 0.0, z],
            tip_base: [x, z],
            pin_base: [x + 0.3, z + 1.4],
            tip_velocity_base: [-0.5, 0.0],
            bucket_abs_rad: -1.78,
            azimuth_rad: 0.0,
            machine_xy: [0.0, 0.0],
            width_m: 1.3,
            capacity_m3: 1.5,
        }
    }

    #[test]
    fn failure_force_is_the_planners_fee_and_grows_with_depth_cohesion_and_swept_volume() {
        let soil = soil_properties(&SoilSpec::default());
        let at = |d: f64, swept_m3: f64| DigGeometry {
            depth_m: d,
            slope_rad: 0.0,
            rake_rad: -1.2,
            swept_volume_m3: swept_m3,
        };
        let f1 = failure_force_n(&soil, &at(0.2, 0.0), 1.3);
        let f2 = failure_force_n(&soil, &at(0.4, 0.0), 1.3);
        let f3 = failure_force_n(&soil, &at(0.4, 0.5), 1.3);
        assert!(f1 > 0.0 && f2 > f1 && f3 > f2);
        assert_eq!(f3, fee_force_n(&soil, &at(0.4, 0.5), 1.3).unwrap());
        let hard = SoilProperties {
            cohesion_pa: 50_000.0,
            ..soil
        };
        assert!(failure_force_n(&hard, &at(0.4, 0.0), 1.3) > f2);
        assert_eq!(failure_force_n(&soil, &at(0.0, 0.0), 1.3), 0.0);
        // Near, at and past the wedge's failure limit (rake + delta + beta + phi = 180 degrees) the
        // force saturates at its value RAKE_LIMIT_MARGIN_RAD from the limit: bounded, not zero.
        let limit = std::f64::consts::PI
            - soil.failure_angle_rad
            - soil.friction_angle_rad
            - soil.tool_friction_angle_rad;
        let at_rake = |rake: f64| {
            let g = DigGeometry {
                rake_rad: -rake,
                ..at(0.4, 0.2)
            };
            failure_force_n(&soil, &g, 1.3)
        };
        let saturated = at_rake(limit - RAKE_LIMIT_MARGIN_RAD);
        assert!(
            saturated > f3 && saturated < 10.0 * f3,
            "{saturated} vs {f3}"
        );
        for rake in [limit - 1e-4, limit, limit + 0.3, 3.0] {
            assert_eq!(at_rake(rake), saturated, "rake {rake}");
        }
    }

    /// Done-when: the mass removed from the terrain equals the mass in the bucket plus spill.
    #[test]
    fn mass_removed_equals_bucket_plus_spill() {
        let mut w = world();
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        // Drag the edge 0.6 m deep through the bench face toward the machine, long enough to overfill.
        let mut x = 12.0;
        while x > 7.0 {
            contact.step(&mut w, &input_at(x, 1.2), 1e-3, &effects);
            x -= 0.0005;
        }
        let l = contact.ledger;
        assert!(l.removed_kg > 1000.0, "{l:?}");
        assert!(l.spilled_kg > 0.0, "the bucket overflowed: {l:?}");
        assert!((contact.content.volume_m3 - 1.5).abs() < 1e-6);
        let balance = l.removed_kg - contact.content.mass_kg - l.spilled_kg;
        assert!(balance.abs() < 1e-6 * l.removed_kg, "{balance} kg");
        // Dump: lift out of the soil and open the bucket; everything leaves and is deposited.
        let mut dump = input_at(2.0, 4.0);
        dump.bucket_abs_rad = -0.6;
        for _ in 0..2000 {
            contact.step(&mut w, &dump, 1e-3, &effects);
        }
        assert_eq!(contact.content.mass_kg, 0.0);
        let l = contact.ledger;
        assert!((l.removed_kg - l.spilled_kg).abs() < 1e-6 * l.removed_kg);
    }

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
    fn height_known_is_the_grids_bilinear_height_bit_for_bit() {
        let mut w = world();
        // Unknown cells and rough ground near the bench face.
        w.terrain.set_cell(130, 100, None).unwrap();
        for j in 90..110 {
            for i in 120..140 {
                if let Some(h) = w.terrain.cell(i, j) {
                    let bump = 0.3 * ((i * 7 + j * 13) % 11) as f64 / 11.0;
                    w.terrain.set_cell(i, j, Some(h + bump)).unwrap();
                }
            }
        }
        let [ox, oy] = w.terrain.origin();
        let (nx, ny) = (w.terrain.nx() as f64, w.terrain.ny() as f64);
        let res = w.terrain.resolution_m();
        let (mut known, mut checked) = (0, 0);
        for a in -40..440 {
            for b in -40..440 {
                let x = ox + (a as f64 * 0.013 + 0.0007 * b as f64) * nx * res / 5.0;
                let y = oy + (b as f64 * 0.011 - 0.0003 * a as f64) * ny * res / 5.0;
                let expected = w.terrain.height_at(x, y).ok();
                assert_eq!(
                    w.height_known(x, y).map(f64::to_bits),
                    expected.map(f64::to_bits),
                    "({x}, {y})"
                );
                known += usize::from(expected.is_some());
                checked += 1;
            }
        }
        // Cell centres and edges exactly, and points that are not finite.
        for (i, j) in [(0, 0), (130, 100), (129, 100), (131, 101)] {
            let [x, y] = w.terrain.cell_center(i, j);
            for (x, y) in [(x, y), (x - 0.5 * res, y), (x, y + 0.5 * res)] {
                assert_eq!(
                    w.height_known(x, y).map(f64::to_bits),
                    w.terrain.height_at(x, y).ok().map(f64::to_bits)
                );
            }
        }
        assert_eq!(w.height_known(f64::NAN, 0.0), None);
        assert!(
            known > checked / 4 && known < checked,
            "{known} of {checked} on the map"
        );
    }

    #[test]
    fn soil_resists_a_moving_edge_and_a_boulder_stops_it() {
        let mut w = world();
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        contact.step(&mut w, &input_at(9.0, 1.5), 1e-3, &effects);
        let f = contact.step(&mut w, &input_at(8.9995, 1.5), 1e-3, &effects);
        assert!(
            f.fx_n > 1000.0,
            "soil pushes back against travel toward the machine: {f:?}"
        );
        w.boulders.push(Boulder {
            x_m: 8.0,
            y_m: 0.0,
            z_m: 1.5,
            radius_m: 0.3,
        });
        let f = contact.step(&mut w, &input_at(8.25, 1.5), 1e-3, &effects);
        assert!(f.fx_n > 5.0e5, "{f:?}");
    }

    /// Regression: a bearing force of ~1.1e5 N (a 0.25 m plate under any downward motion) stopped a
    /// sharp edge 1 cm into the bench top, so Autodig could not penetrate. Pushed in tip first the edge
    /// meets only its edge bearing and the shallow FEE wedge; the bucket's back pushed in bears over
    /// the plate.
    #[test]
    fn edge_pushed_in_tip_first_penetrates_but_the_back_bears() {
        let effects = SoilEffects::default();
        let pushed_down = |bucket_abs: f64| {
            let mut w = world();
            let mut contact = SoilContact::default();
            let mut i = input_at(8.0, 1.95);
            i.bucket_abs_rad = bucket_abs;
            i.pin_base = [8.0 - 1.5 * bucket_abs.cos(), 1.95 - 1.5 * bucket_abs.sin()];
            i.tip_velocity_base = [0.0, -0.2];
            contact.step(&mut w, &i, 1e-3, &effects);
            let f = contact.step(&mut w, &i, 1e-3, &effects);
            f.fx_n.hypot(f.fz_n)
        };
        let tip_first = pushed_down(-std::f64::consts::FRAC_PI_2);
        assert!(tip_first > 0.0 && tip_first < 3.0e4, "{tip_first} N");
        let back_first = pushed_down(-std::f64::consts::PI);
        assert!(back_first > 1.0e5, "{back_first} N");
    }

    /// The extended-operation bench (`config/bench_extended.toml`: floor at -2 m, face from x 4 to
    /// 6 m, the floor beyond) with its native ground, without it, or with the layer boundary moved.
    fn extended_world(native: bool, floor_m: f64) -> World {
        let text = crate::scenario::EXTENDED_BENCH_TOML;
        let mut s = Scenario::from_toml_str_named(text, "bench_extended.toml").unwrap();
        assert!(
            s.native_soil.is_some(),
            "the extended bench declares its native ground"
        );
        if !native {
            s.native_soil = None;
        }
        s.bench.floor_elevation_m = floor_m;
        // The regular face (no slump, no undulation): these tests are about the layered force.
        s.terrain = crate::scenario::TerrainSpec::default();
        World::from_scenario(&s).unwrap()
    }

    /// The extended bench with its `[terrain]` as declared, or as given.
    fn extended_world_with(terrain: Option<crate::scenario::TerrainSpec>) -> (Scenario, World) {
        let text = crate::scenario::EXTENDED_BENCH_TOML;
        let mut s = Scenario::from_toml_str_named(text, "bench_extended.toml").unwrap();
        if let Some(t) = terrain {
            s.terrain = t;
        }
        let w = World::from_scenario(&s).unwrap();
        (s, w)
    }

    fn sum_heights(w: &World) -> f64 {
        let t = &w.terrain;
        (0..t.ny())
            .flat_map(|j| t.row(j).unwrap().iter().copied())
            .filter(|h| h.is_finite())
            .sum()
    }

    /// The steepest slope between 8-connected neighbours in a box, as an angle (degrees).
    fn steepest_deg(w: &World, i0: usize, i1: usize, j0: usize, j1: usize) -> f64 {
        let t = &w.terrain;
        let res = t.resolution_m();
        let mut worst: f64 = 0.0;
        for j in j0..j1 {
            for i in i0..i1 {
                let h = t.cell(i, j).unwrap();
                for (di, dj) in [(1, 0), (0, 1), (1, 1)] {
                    let d = res * ((di * di + dj * dj) as f64).sqrt();
                    let g = (h - t.cell(i + di, j + dj).unwrap()).abs() / d;
                    worst = worst.max(g.atan().to_degrees());
                }
                if i > 0 {
                    let g = (h - t.cell(i - 1, j + 1).unwrap()).abs() / (res * 2f64.sqrt());
                    worst = worst.max(g.atan().to_degrees());
                }
            }
        }
        worst
    }

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

    #[test]
    fn a_dig_with_slumping_keeps_the_ledger_and_the_terrain_volume_exact() {
        let spec = crate::scenario::TerrainSpec {
            repose_deg: Some(45.0),
            ..Default::default()
        };
        let (_, mut w) = extended_world_with(Some(spec));
        let before = sum_heights(&w);
        let area = w.terrain.resolution_m().powi(2);
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        // 0.5 m deep through the face toward the machine (crest at 4 m, toe at 6 m; above the
        // floor, so every cut cell has the bench density), then out.
        let mut x: f64 = 5.4;
        while x > 3.5 {
            let z = (4.0 - x).clamp(-1.4, 0.0) - 0.5;
            contact.step(&mut w, &input_at(x, z), 5e-3, &effects);
            x -= 0.0025;
        }
        let mut out = input_at(3.0, 3.0);
        out.bucket_abs_rad = -0.6;
        for _ in 0..1000 {
            contact.step(&mut w, &out, 5e-3, &effects);
        }
        let l = contact.ledger;
        assert!(l.removed_kg > 500.0, "{l:?}");
        assert!(
            (l.removed_kg - contact.content.mass_kg - l.spilled_kg).abs() < 1e-9 * l.removed_kg
        );
        // Heights summed: what left the terrain is the cut volume less what was deposited back,
        // with the slumps moving material in between.
        let cut_m3 = l.removed_kg / 1700.0;
        let change_m3 = (before - sum_heights(&w)) * area;
        assert!(
            (change_m3 - (cut_m3 - l.deposited_m3)).abs() < 1e-6,
            "{change_m3} vs {cut_m3} - {}",
            l.deposited_m3
        );
        assert!(w.slump.unwrap().dirty.is_none(), "settled within 5 s");
    }

    #[test]
    fn the_undulation_has_the_declared_spread_is_smooth_and_leaves_the_floor() {
        let spec = crate::scenario::TerrainSpec {
            repose_deg: None,
            undulation_std_m: 0.1,
            undulation_correlation_m: 1.5,
        };
        let (s, w) = extended_world_with(Some(spec));
        let (_, plain) = extended_world_with(Some(crate::scenario::TerrainSpec::default()));
        // On the bench top behind the crest: the field itself.
        let mut d = Vec::new();
        let mut step = Vec::new();
        let mut y = -9.0;
        while y < 9.0 {
            let mut x = -19.0;
            while x < 3.0 {
                d.push(w.height(x, y) - plain.height(x, y));
                step.push(w.height(x + 0.1, y) - w.height(x, y));
                x += 0.1;
            }
            y += 0.1;
        }
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let std = (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        let rms_step = (step.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        eprintln!("mean {mean:.3} m, std {std:.3} m, rms step over 0.1 m {rms_step:.4} m");
        assert!((0.07..0.13).contains(&std), "{std}");
        assert!(mean.abs() < 0.05, "{mean}");
        // Smooth: the slope's rms is std / L (0.067 for 0.1 m over 1.5 m), a step of 0.0067 m.
        assert!(rms_step < 0.012, "{rms_step}");
        // The floor beyond the toe is untouched and nothing is below it.
        assert_eq!(w.height(10.0, 0.0), -2.0);
        for j in 0..w.terrain.ny() {
            for &h in w.terrain.row(j).unwrap() {
                assert!(h >= s.bench.floor_elevation_m);
            }
        }
        // With the bench material's repose angle declared it starts at rest: nothing steeper.
        let (_, settled) = extended_world_with(Some(crate::scenario::TerrainSpec {
            repose_deg: Some(45.0),
            ..spec
        }));
        let (nx, ny) = (settled.terrain.nx(), settled.terrain.ny());
        let steepest = steepest_deg(&settled, 1, nx - 2, 0, ny - 2);
        assert!(steepest < 45.1, "{steepest}");
        assert!((sum_heights(&settled) - sum_heights(&w)).abs() < 1e-6);
        // The same seed gives the same bench, another seed another one.
        let (_, again) = extended_world_with(Some(spec));
        assert_eq!(again.terrain, w.terrain);
        let mut s2 = s.clone();
        s2.seed += 1;
        assert_ne!(World::from_scenario(&s2).unwrap().terrain, w.terrain);
    }

    /// Drags the edge toward the machine at height `z` from `x0` for `length_m`; returns the soil
    /// force on the last step and the contact state (content, ledger).
    fn drag(w: &mut World, x0: f64, z: f64, length_m: f64) -> (TipForce, SoilContact) {
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        let mut x = x0;
        let mut f = TipForce::default();
        while x > x0 - length_m {
            f = contact.step(w, &input_at(x, z), 1e-3, &effects);
            x -= 0.0005;
        }
        (f, contact)
    }

    #[test]
    fn layered_fee_splits_the_terms_and_is_the_upper_soils_fee_without_depth_below() {
        let upper = soil_properties(&SoilSpec::default());
        let lower = soil_properties(&SoilSpec {
            density_kg_per_m3: 2000.0,
            cohesion_pa: 40_000.0,
            friction_angle_deg: 38.0,
            tool_friction_angle_deg: 22.0,
            failure_angle_deg: 30.0,
        });
        let gamma = DigGeometry {
            depth_m: 0.4,
            slope_rad: 0.0,
            rake_rad: -1.0,
            swept_volume_m3: 0.5,
        };
        let upper_only = failure_force_n(&upper, &gamma, 1.3);
        assert_eq!(
            layered_failure_force_n(&upper, &lower, 0.0, &gamma, 1.3),
            upper_only
        );
        // Harder the more of the cut is below the floor, continuous at the boundary.
        let mut last = upper_only;
        for f in [1e-6, 0.1, 0.25, 0.5, 0.75, 1.0] {
            let layered = layered_failure_force_n(&upper, &lower, f, &gamma, 1.3);
            assert!(layered > last, "share {f}: {layered} <= {last}");
            last = layered;
        }
        let near = layered_failure_force_n(&upper, &lower, 1e-6, &gamma, 1.3);
        assert!((near - upper_only).abs() < 1e-3 * upper_only);
        // All of it below: the lower soil's wedge (Eq. 17) under the upper soil's surcharge.
        let n = fee_factors(&lower, &gamma).unwrap();
        let g = GRAVITY_M_PER_S2;
        let expected = 0.4 * 0.4 * 1.3 * 2000.0 * g * n.n_w
            + 40_000.0 * 1.3 * 0.4 * n.n_c
            + 0.5 * 1700.0 * g * n.n_q;
        assert!(
            (last - expected).abs() < 1e-9 * expected,
            "{last} vs {expected}"
        );
        // The same soil in both layers: the one-soil FEE for any share.
        for f in [0.3, 1.0] {
            let same = layered_failure_force_n(&upper, &upper, f, &gamma, 1.3);
            assert!((same - upper_only).abs() < 1e-9 * upper_only);
        }
    }

    /// A cut 0.3 m below the floor meets the native ground: harder than the same cut (the same
    /// surface, depth and edge path) where the layer boundary lies below it, and the material it
    /// takes has the native density; a cut entirely above the floor is unchanged by the layer.
    #[test]
    fn a_cut_below_the_floor_is_harder_and_a_cut_above_it_is_unchanged() {
        // On the floor beyond the toe (surface z -2 m), the edge at -2.3 m.
        let (below, below_contact) = drag(&mut extended_world(true, -2.0), 8.0, -2.3, 0.2);
        let (above, above_contact) = drag(&mut extended_world(true, -3.0), 8.0, -2.3, 0.2);
        let (plain, plain_contact) = drag(&mut extended_world(false, -3.0), 8.0, -2.3, 0.2);
        assert!(above.fx_n > 1000.0, "{above:?}");
        assert!(
            below.fx_n > 2.0 * above.fx_n,
            "below the floor {below:?}, above it {above:?}"
        );
        assert_eq!(above, plain);
        // The same volume cut, at the native density below the floor.
        let (vb, va) = (
            below_contact.content.volume_m3,
            above_contact.content.volume_m3,
        );
        assert!(va > 0.05 && (vb - va).abs() < 1e-9, "{vb} vs {va} m^3");
        let density = below_contact.content.mass_kg / vb;
        assert!((density - 2000.0).abs() < 1e-6, "{density} kg/m^3");
        assert!((above_contact.content.mass_kg / va - 1700.0).abs() < 1e-6);
        assert_eq!(above_contact.content, plain_contact.content);
        // Through the face above the floor (x 5 m, z -1.5 m, floor -2 m): the same force, bucket
        // content and terrain with the layer as without it.
        let mut layered = extended_world(true, -2.0);
        let mut single = extended_world(false, -2.0);
        let (a, ac) = drag(&mut layered, 6.0, -1.5, 1.0);
        let (b, bc) = drag(&mut single, 6.0, -1.5, 1.0);
        assert!(ac.content.volume_m3 > 0.1, "{:?}", ac.content);
        assert_eq!(a, b);
        assert_eq!(ac.content, bc.content);
        assert_eq!(ac.ledger, bc.ledger);
        // Mass bookkeeping holds across the layers.
        let l = below_contact.ledger;
        let balance = l.removed_kg - below_contact.content.mass_kg - l.spilled_kg;
        assert!(balance.abs() < 1e-9 * l.removed_kg, "{balance} kg");
    }

    /// A cut that starts in the bench material above the floor and goes below it takes the native
    /// density only for the part below the floor.
    #[test]
    fn a_cut_across_the_floor_splits_its_mass_at_the_floor() {
        // At the toe (x 6 -> 5.6 m: the face from z -2 up to -1.6 m) with the edge at -2.2 m: 0.2 m
        // of native ground under the face material.
        let (_, layered) = drag(&mut extended_world(true, -2.0), 6.0, -2.2, 0.4);
        let (_, single) = drag(&mut extended_world(false, -2.0), 6.0, -2.2, 0.4);
        let v = layered.content.volume_m3;
        assert!((v - single.content.volume_m3).abs() < 1e-9);
        let density = layered.content.mass_kg / v;
        assert!(density > 1750.0 && density < 1990.0, "{density} kg/m^3");
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
