//! Worlds and contact inputs the soil-contact tests share.

use super::{ContactInput, World};
use crate::scenario::Scenario;

/// The default bench's geometry with the soils these tests' figures are written for, fixed here so a
/// recalibration of the bench's soil does not move them: bench material 8 kPa, the harder strip 20
/// kPa, no native ground under the floor.
pub(super) fn world() -> World {
    World::from_scenario(&fixture_bench()).unwrap()
}

/// [`world`]'s scenario.
pub(super) fn fixture_bench() -> Scenario {
    let mut s = Scenario::default_bench().unwrap();
    s.soil.cohesion_pa = 8000.0;
    for r in &mut s.soil_regions {
        r.soil.cohesion_pa = 20000.0;
    }
    s.native_soil = None;
    s
}

pub(super) fn input_at(x: f64, z: f64) -> ContactInput {
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

/// The extended-operation bench (`config/bench_extended.toml`: floor at -2 m, face from x 4 to
/// 6 m, the floor beyond) with its native ground, without it, or with the layer boundary moved.
pub(super) fn extended_world(native: bool, floor_m: f64) -> World {
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
pub(super) fn extended_world_with(
    terrain: Option<crate::scenario::TerrainSpec>,
) -> (Scenario, World) {
    let text = crate::scenario::EXTENDED_BENCH_TOML;
    let mut s = Scenario::from_toml_str_named(text, "bench_extended.toml").unwrap();
    if let Some(t) = terrain {
        s.terrain = t;
    }
    let w = World::from_scenario(&s).unwrap();
    (s, w)
}

pub(super) fn sum_heights(w: &World) -> f64 {
    let t = &w.terrain;
    (0..t.ny())
        .flat_map(|j| t.row(j).unwrap().iter().copied())
        .filter(|h| h.is_finite())
        .sum()
}

/// The steepest slope between 8-connected neighbours in a box, as an angle (degrees).
pub(super) fn steepest_deg(w: &World, i0: usize, i1: usize, j0: usize, j1: usize) -> f64 {
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
