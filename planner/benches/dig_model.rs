//! Dig-model benchmark (thesis 4.1): time of one dig prediction on one core and its
//! x-real-time factor (target >= 10,000x: a 6 s dig in < 0.6 ms; the thesis's model took about 16 ms on
//! 1999 hardware), a profile of the inner step's parts, and the parallel speed-up of `evaluate_many`
//! over candidate starts (rayon).
//!
//! The machine this runs on is shared, so next to the wall time it prints the thread's CPU time (from
//! `/proc/thread-self/schedstat`, nanoseconds on the CPU, which waiting for a core does not inflate),
//! the best of several batches, and the load average.
//!
//! `cargo bench -p planner --features parallel --bench dig_model`

#![allow(clippy::unwrap_used)]

use std::hint::black_box;
use std::time::Instant;

use planner::actuator::ActuatorModel;
use planner::dig_model::{DigModel, DigSite, DigStart, NOMINAL_ACTUATOR_JSON};
use planner::kinematics::BucketPose;
use planner::soil::{BearingParams, BucketMotion, MovingBucketSoil, SoilProperties};
use planner::terrain::SectionProfile;

/// The default bench seen from the machine: floor 0, 45 degree face from 3 m to the 2 m top at 5 m.
fn bench_height(r: f64) -> f64 {
    (r - 3.0).clamp(0.0, 2.0)
}

fn start(r: f64) -> DigStart {
    DigStart::Pose(BucketPose {
        x_m: r,
        z_m: bench_height(r) - 0.02,
        bucket_abs_rad: (-55.0_f64).to_radians(),
    })
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".to_owned())
}

/// CPU time of this thread so far, ns (`None` where the kernel does not report it). The kernel
/// updates it at context switches and timer ticks, so it is only meaningful over many milliseconds.
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Timing of `f` over `batches` batches of `reps` calls: the fastest batch's wall time per call (a
/// batch the scheduler did not interrupt: the cost on a free core), the median batch's, and the mean
/// thread CPU time per call over all batches (s).
fn time_it(batches: usize, reps: usize, mut f: impl FnMut()) -> (f64, f64, Option<f64>) {
    let mut walls = Vec::with_capacity(batches);
    let c0 = thread_cpu_ns();
    for _ in 0..batches {
        let t0 = Instant::now();
        for _ in 0..reps {
            f();
        }
        walls.push(t0.elapsed().as_secs_f64() / reps as f64);
    }
    let cpu = match (c0, thread_cpu_ns()) {
        (Some(a), Some(b)) => Some((b - a) as f64 * 1e-9 / (batches * reps) as f64),
        _ => None,
    };
    walls.sort_by(f64::total_cmp);
    (walls[0], walls[walls.len() / 2], cpu)
}

fn main() {
    println!("load average: {}", load_average());
    let model = DigModel::nominal().unwrap();
    let site = DigSite::new(
        SectionProfile::from_fn(0.5, 12.0, 0.05, bench_height).unwrap(),
        0.0,
    )
    .unwrap();
    let one = start(7.8);
    let summary = model.evaluate(&one, &site).unwrap();
    let (best, median, cpu) = time_it(1000, 1, || {
        black_box(model.evaluate(black_box(&one), &site).unwrap());
    });
    let steps = summary.steps.max(1) as f64;
    println!(
        "one dig prediction: {:.2} s dig, {} steps; 1000 runs: fastest {:.3} ms = {:.0}x real time (target >= 10,000x), {:.0} ns/step; median {:.3} ms ({:.0}x)",
        summary.time_s,
        summary.steps,
        best * 1e3,
        summary.time_s / best,
        best / steps * 1e9,
        median * 1e3,
        summary.time_s / median,
    );
    if let Some(cpu) = cpu {
        println!(
            "  mean thread CPU time per dig {:.3} ms = {:.0}x real time, {:.0} ns/step",
            cpu * 1e3,
            summary.time_s / cpu,
            cpu / steps * 1e9,
        );
    }
    println!(
        "  a 6 s dig (600 steps) at the fastest rate: {:.3} ms (target < 0.6 ms)",
        best / steps * 600.0 * 1e3
    );
    let mut trace = model.new_trace();
    let (best_trace, _, _) = time_it(300, 1, || {
        black_box(model.predict_into(&one, &site, Some(&mut trace)).unwrap());
    });
    println!(
        "  with the trajectory recorded (preallocated trace): fastest {:.3} ms",
        best_trace * 1e3
    );

    // Profile: the parts of one step measured on their own (fastest batch, ns per call).
    let actuator = ActuatorModel::from_json(NOMINAL_ACTUATOR_JSON).unwrap();
    let mut state = actuator.initial_state([0.0; 3], [0.0; 3]).unwrap();
    let (act, _, _) = time_it(300, 100, || {
        black_box(
            actuator
                .step(
                    &mut state,
                    black_box([0.4, 1.0, 0.7]),
                    black_box([2e5, 1.5e5, 1e5]),
                )
                .unwrap(),
        );
    });
    let soil =
        MovingBucketSoil::new(&SoilProperties::typical(), &BearingParams::default(), 1.3).unwrap();
    let motion = BucketMotion {
        sin_bucket_abs: (-1.9_f64).sin(),
        cos_bucket_abs: (-1.9_f64).cos(),
        tip_velocity_m_per_s: [-0.4, -0.05],
        vertical_depth_m: 0.4,
        slope_tan: 0.3,
        swept_volume_m3: 0.6,
    };
    let (soil_s, _, _) = time_it(300, 100, || {
        black_box(soil.force(black_box(&motion)).unwrap());
    });
    let per_step = best / steps * 1e9;
    let (act_ns, soil_ns) = (act * 1e9, soil_s * 1e9);
    let share = |ns: f64| 100.0 * ns / per_step;
    println!(
        "  profile per step ({per_step:.0} ns): actuator networks ({} hidden units) {act_ns:.0} ns ({:.0} %), soil force (FEE + bearing) {soil_ns:.0} ns ({:.0} %), the rest (kinematics, statics, swept volume, cut surface, Autodig) {:.0} ns ({:.0} %)",
        actuator.hidden_units(),
        share(act_ns),
        share(soil_ns),
        per_step - act_ns - soil_ns,
        share(per_step - act_ns - soil_ns)
    );

    // Another actuator file side by side (same run, same load): `DIG_BENCH_ACTUATOR=FILE`.
    if let Ok(path) = std::env::var("DIG_BENCH_ACTUATOR") {
        let text = std::fs::read_to_string(&path).unwrap();
        let other = ActuatorModel::from_json(&text).unwrap();
        let other_model = model.clone().with_actuator(other.clone()).unwrap();
        let other_summary = other_model.evaluate(&one, &site).unwrap();
        let (other_best, _, _) = time_it(1000, 1, || {
            black_box(other_model.evaluate(black_box(&one), &site).unwrap());
        });
        let mut state = other.initial_state([0.0; 3], [0.0; 3]).unwrap();
        let (other_act, _, _) = time_it(300, 100, || {
            black_box(
                other
                    .step(
                        &mut state,
                        black_box([0.4, 1.0, 0.7]),
                        black_box([2e5, 1.5e5, 1e5]),
                    )
                    .unwrap(),
            );
        });
        let other_per_step = other_best / other_summary.steps.max(1) as f64 * 1e9;
        println!(
            "  {path} ({} hidden units): {:.2} s dig, fastest {:.3} ms, {other_per_step:.0} ns/step ({:.2}x the shipped), networks {:.0} ns ({:.2}x); a 6 s dig {:.3} ms (target < 0.6 ms)",
            other.hidden_units(),
            other_summary.time_s,
            other_best * 1e3,
            other_per_step / per_step,
            other_act * 1e9,
            other_act / act,
            other_per_step * 600.0 * 1e-6,
        );
    }

    // Candidates as the refined planner makes them.
    let starts: Vec<DigStart> = (0..300).map(|i| start(5.5 + 0.01 * f64::from(i))).collect();
    let t0 = Instant::now();
    let serial: Vec<_> = starts.iter().map(|s| model.evaluate(s, &site)).collect();
    let t_serial = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let parallel = model.evaluate_many(&starts, &site);
    let t_parallel = t0.elapsed().as_secs_f64();
    assert_eq!(
        serial, parallel,
        "parallel evaluation must match the serial one"
    );
    let ok = parallel.iter().filter(|r| r.is_ok()).count();
    println!(
        "{} candidates ({} evaluated without error): serial {:.1} ms, evaluate_many (rayon, {} threads) {:.1} ms, speed-up {:.2}x",
        starts.len(),
        ok,
        t_serial * 1e3,
        rayon::current_num_threads(),
        t_parallel * 1e3,
        t_serial / t_parallel
    );
    println!("load average: {}", load_average());
}
