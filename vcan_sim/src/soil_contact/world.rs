//! The true world the machine digs in: the terrain grid built from a scenario's bench (with its
//! seeded undulation), the soil of every cell and the native ground below the floor, the boulders,
//! and the hidden soil effects applied to the soil at a point.

use planner::soil::SoilProperties;
use planner::terrain::{TerrainError, TerrainGrid};
use rand::{RngExt, SeedableRng};

use crate::scenario::{Boulder, Scenario, SoilSpec};

/// Soil properties `Psi` of a scenario soil (degrees in the file, radians here).
pub(super) fn soil_properties(s: &SoilSpec) -> SoilProperties {
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

/// The true world the machine digs in.
#[derive(Debug, Clone)]
pub struct World {
    /// True terrain heights.
    pub terrain: TerrainGrid,
    /// Soil properties per cell (row-major, as the terrain grid).
    pub(super) soil: Vec<SoilProperties>,
    /// The scenario's default soil (cells outside every soil region).
    pub(super) default_soil: SoilProperties,
    /// The native ground below `floor_elevation_m` (`None`: the cell soils all the way down).
    pub(super) native_soil: Option<SoilProperties>,
    /// Elevation of the layer boundary, the bench's floor (m, world z).
    pub(super) floor_elevation_m: f64,
    /// Summed-area table of the cells whose density differs from the default, `(nx + 1) x (ny + 1)`:
    /// a cut whose box holds none of them takes its mass from the removed volume in one product.
    pub(super) odd_density_sums: Vec<u32>,
    /// Hard inclusions.
    pub boulders: Vec<Boulder>,
    /// Angle of repose of spilled material (rad).
    pub repose_rad: f64,
    /// Slope stability of the bench material after cuts (`[terrain] repose_deg`), off when `None`.
    pub(super) slump: Option<Slump>,
}

/// The angle-of-repose relaxation of the bench material near the cuts ([`World::advance_slopes`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Slump {
    /// `tan` of the bench material's angle of repose.
    pub(super) tan_repose: f64,
    /// Cells `[i0, i1, j0, j1]` (inclusive) the bucket cut or a slump moved since the last pass.
    pub(super) dirty: Option<[usize; 4]>,
    /// Time since the last pass, s (runs while something is dirty).
    pub(super) clock_s: f64,
}

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
    pub(super) fn default_density_in(&self, i0: usize, i1: usize, j0: usize, j1: usize) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soil_contact::fixtures::*;

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
}
