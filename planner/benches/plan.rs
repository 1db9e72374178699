//! Benchmark of one full planning cycle (thesis 5.1): coarse plan, refined plan over one region
//! (about 300 candidates through the dig model), cleanup and tracking plans and Fig. 42's selection,
//! on the default bench (config/bench.toml), with rayon pools of 1 and 2 threads.
//!
//! `cargo bench -p planner --features parallel --bench plan` (release). Prints the time per cycle on one core and the
//! speed-up with two. Target: under 100 ms on one core.

use planner::dig_model::DigModel;
use planner::kinematics::MachinePose;
use planner::machine::MachineConfig;
use planner::plan::{CandidateStatus, Planner, PlannerConfig, PlannerState};
use planner::terrain::TerrainGrid;
use std::time::Instant;

/// The default bench seen from the machine at the origin: a 2 m bench, face toe at x = 3 m rising at
/// 45 degrees to the crest at 5 m, 10 m long and 10 m wide (y in [-5, 5]).
fn default_bench() -> Result<TerrainGrid, Box<dyn std::error::Error>> {
    Ok(TerrainGrid::from_fn(-8.0, -10.0, 0.1, 240, 200, |x, y| {
        if y.abs() > 5.0 || x > 13.0 {
            0.0
        } else {
            (x - 3.0).clamp(0.0, 2.0)
        }
    })?)
}

fn run(threads: usize, cycles: usize) -> Result<(f64, usize, usize), Box<dyn std::error::Error>> {
    let machine = MachineConfig::default_machine()?;
    let mut cfg = PlannerConfig::nominal()?;
    // Exactly one region per cycle, as the thesis's planner.
    cfg.action.search_all_regions = false;
    let planner = Planner::new(&machine, DigModel::nominal()?, cfg)?;
    let grid = default_bench()?;
    let pose = MachinePose::default();
    let mut state = PlannerState::default();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let mut times = Vec::with_capacity(cycles);
    let (mut candidates, mut evaluated) = (0, 0);
    for k in 0..cycles {
        // Walk the regions as the session would (the middle regions have the most reachable starts).
        state.region_pointer = 3 + k % 2;
        let t0 = Instant::now();
        let plan = pool.install(|| planner.plan(&grid, &pose, &state))?;
        times.push(t0.elapsed().as_secs_f64());
        let r = plan.refined.first().ok_or("no refined plan")?;
        candidates = r.candidates.len();
        evaluated = r.candidates.len() - r.count(CandidateStatus::Unreachable);
        std::hint::black_box(plan);
    }
    times.sort_by(f64::total_cmp);
    if threads == 1 {
        // The serial parts: the coarse plan and the cleanup/tracking plans.
        let t0 = Instant::now();
        let coarse = planner.coarse(&grid, &pose)?;
        let t_coarse = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let ct = planner.cleanup_and_tracking(&grid, &pose, &state)?;
        let t_ct = t0.elapsed().as_secs_f64();
        println!(
            "  serial parts (1 thread): coarse {:.1} ms ({} regions), cleanup + tracking {:.1} ms ({} swing angles)",
            t_coarse * 1e3,
            coarse.regions.len(),
            t_ct * 1e3,
            ct.candidates.len()
        );
    }
    Ok((times[times.len() / 2], candidates, evaluated))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cycles = std::env::var("PLAN_BENCH_CYCLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let (t1, n, evaluated) = run(1, cycles)?;
    let (t2, _, _) = run(2, cycles)?;
    println!(
        "planning cycle (coarse + refined over one region + cleanup + tracking), median of {cycles}:"
    );
    println!("  candidates {n}, reachable and run through the dig model {evaluated}");
    println!(
        "  1 thread : {:8.1} ms per cycle ({:.3} ms per dig evaluated)",
        t1 * 1e3,
        t1 * 1e3 / evaluated.max(1) as f64
    );
    println!(
        "  2 threads: {:8.1} ms per cycle, speed-up {:.2}x",
        t2 * 1e3,
        t1 / t2
    );
    println!(
        "  target < 100 ms on one core: {}",
        if t1 < 0.1 { "met" } else { "NOT met" }
    );
    Ok(())
}
