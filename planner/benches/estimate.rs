//! Benchmarks of soil estimation and the actuator step (prints figures, asserts nothing).
//!
//! `cargo bench -p planner --bench estimate`. Targets: empirical fit under 50 us and analytical
//! fit under 20 ms on 300 samples (thesis, SGI R10000: 8 ms and 3400 ms). If `python3` with SciPy is
//! available, the same analytical fit is run with `benches/scipy_anneal.py` (SciPy `dual_annealing` +
//! Powell) on the same samples and both times, the speed ratio and both RMS errors are printed.

#![allow(missing_docs)]

use planner::actuator::{ActuatorDig, ActuatorSample, TrainConfig, train};
use planner::estimate::{AnalyticalFitConfig, SoilSample, fit_analytical, fit_empirical};
use planner::kinematics::TipForce;
use planner::soil::{DigGeometry, SoilProperties, fee_tip_force};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::io::Write;
use std::process::Command;
use std::time::{Duration, Instant};

const WIDTH_M: f64 = 1.5;
const WINDOW: usize = 300;
const DIG_SAMPLES: usize = 50;
const NOISE_N: f64 = 1000.0;

/// 300 samples of six synthetic digs, forces from the modified FEE with uniform noise.
fn samples() -> Vec<SoilSample> {
    let psi = SoilProperties {
        density_kg_per_m3: 1800.0,
        failure_angle_rad: 35f64.to_radians(),
        friction_angle_rad: 30f64.to_radians(),
        tool_friction_angle_rad: 18f64.to_radians(),
        cohesion_pa: 25e3,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut out = Vec::with_capacity(WINDOW);
    while out.len() < WINDOW {
        let slope = rng.random_range(5f64.to_radians()..35f64.to_radians());
        let depth_max = rng.random_range(0.3..0.8);
        let mut vs = 0.0;
        for k in 0..DIG_SAMPLES {
            let s = k as f64 / (DIG_SAMPLES - 1) as f64;
            let depth = depth_max * (std::f64::consts::PI * s).sin() + 0.02;
            vs += depth * 0.04;
            let geometry = DigGeometry {
                depth_m: depth,
                slope_rad: slope + rng.random_range(-0.05..0.05),
                rake_rad: (-60.0 + 40.0 * s + rng.random_range(-3.0..3.0)).to_radians(),
                swept_volume_m3: vs,
            };
            let Ok(f) = fee_tip_force(&psi, &geometry, WIDTH_M, 0.4) else {
                continue;
            };
            let force = TipForce {
                fx_n: f.fx_n + rng.random_range(-NOISE_N..NOISE_N),
                fz_n: f.fz_n + rng.random_range(-NOISE_N..NOISE_N),
                my_nm: f.my_nm + rng.random_range(-NOISE_N..NOISE_N),
            };
            out.push(SoilSample { geometry, force });
        }
    }
    out.truncate(WINDOW);
    out
}

/// Mean time per call over at least `min_runs` runs and `min_time`.
fn time_per_call(min_runs: usize, min_time: Duration, mut f: impl FnMut()) -> Duration {
    f(); // warm-up
    let start = Instant::now();
    let mut runs = 0u32;
    while (runs as usize) < min_runs || start.elapsed() < min_time {
        f();
        runs += 1;
    }
    start.elapsed() / runs
}

fn scipy_comparison(
    samples: &[SoilSample],
    config: &AnalyticalFitConfig,
    rust_time: Duration,
    rust_rms: f64,
) {
    let path = std::env::temp_dir().join(format!("planner-bench-soil-{}.csv", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut file = std::fs::File::create(&path)?;
        writeln!(file, "depth_m,slope_rad,rake_rad,swept_volume_m3,fx_n,fz_n")?;
        for s in samples {
            let g = &s.geometry;
            writeln!(
                file,
                "{:e},{:e},{:e},{:e},{:e},{:e}",
                g.depth_m, g.slope_rad, g.rake_rad, g.swept_volume_m3, s.force.fx_n, s.force.fz_n
            )?;
        }
        Ok(())
    };
    if let Err(e) = write() {
        println!("scipy comparison: cannot write {}: {e}", path.display());
        return;
    }
    let corner = |p: &SoilProperties| {
        [
            p.density_kg_per_m3,
            p.failure_angle_rad,
            p.friction_angle_rad,
            p.tool_friction_angle_rad,
            p.cohesion_pa,
        ]
        .map(|v| format!("{v:e}"))
        .join(",")
    };
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/scipy_anneal.py");
    let output = Command::new("python3")
        .arg(script)
        .arg(&path)
        .arg(format!("{:e}", config.bucket_width_m))
        .arg(corner(&config.bounds.lower))
        .arg(corner(&config.bounds.upper))
        .arg(config.seed.to_string())
        .output();
    let _ = std::fs::remove_file(&path);
    let output = match output {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            println!(
                "scipy comparison skipped: {}",
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
            return;
        }
        Err(e) => {
            println!("scipy comparison skipped: python3 not runnable ({e})");
            return;
        }
    };
    let text = String::from_utf8_lossy(&output.stdout);
    let Ok(result) = serde_json::from_str::<serde_json::Value>(text.trim()) else {
        println!("scipy comparison: unreadable output {text:?}");
        return;
    };
    let field = |k: &str| {
        result
            .get(k)
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(f64::NAN)
    };
    let scipy_time = field("time_s");
    println!(
        "scipy dual_annealing + Powell: {:.1} ms, RMS {:.1} N, {} evaluations, params {}",
        scipy_time * 1e3,
        field("rms_n"),
        field("evaluations"),
        result
            .get("params")
            .map(ToString::to_string)
            .unwrap_or_default()
    );
    println!(
        "analytical fit: rust {:.2} ms (RMS {:.1} N) vs scipy {:.1} ms (RMS {:.1} N): rust {:.0}x faster",
        rust_time.as_secs_f64() * 1e3,
        rust_rms,
        scipy_time * 1e3,
        field("rms_n"),
        scipy_time / rust_time.as_secs_f64()
    );
}

/// A small actuator model trained on synthetic first-order hydraulics, for timing the step.
fn actuator_step_time() -> Option<Duration> {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let digs: Vec<ActuatorDig> = (0..4)
        .map(|_| {
            let mut v = [0.0_f64; 3];
            let mut u = [0.0_f64; 3];
            let samples = (0..200)
                .map(|k| {
                    if k % 25 == 0 {
                        u = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
                    }
                    let force_n = std::array::from_fn(|_| rng.random_range(-1e5..1e5));
                    let sample = ActuatorSample {
                        time_s: k as f64 * 0.01,
                        command: u,
                        force_n,
                        velocity_m_per_s: v,
                    };
                    for j in 0..3 {
                        v[j] += 0.1 * (0.25 * u[j] - v[j]);
                    }
                    sample
                })
                .collect();
            ActuatorDig { samples }
        })
        .collect();
    let config = TrainConfig {
        teacher_forcing_epochs: 50,
        free_run_epochs: 10,
        ..TrainConfig::default()
    };
    let (model, _) = train(&digs, &config, |_| {}).ok()?;
    let mut state = model.initial_state([0.0; 3], [0.0; 3]).ok()?;
    const STEPS: u32 = 1_000_000;
    let start = Instant::now();
    for k in 0..STEPS {
        let c = f64::from(k % 200) / 100.0 - 1.0;
        let v = model.step(
            &mut state,
            black_box([c, -c, 0.5 * c]),
            black_box([1e4, -2e4, 3e4]),
        );
        black_box(v.ok());
    }
    Some(start.elapsed() / STEPS)
}

fn main() {
    let samples = samples();
    let empirical = time_per_call(1000, Duration::from_millis(500), || {
        black_box(fit_empirical(black_box(&samples)).ok());
    });
    let fit = fit_empirical(&samples);
    println!(
        "empirical fit (Eqs. 22-23, SVD), {} samples: {:.1} us per fit (target < 50 us; thesis 8 ms), RMS {:.1} N",
        samples.len(),
        empirical.as_secs_f64() * 1e6,
        fit.map(|f| f.rms_error_n).unwrap_or(f64::NAN)
    );

    let config = AnalyticalFitConfig {
        bucket_width_m: WIDTH_M,
        ..AnalyticalFitConfig::default()
    };
    let analytical = time_per_call(10, Duration::from_secs(1), || {
        black_box(fit_analytical(black_box(&samples), &config).ok());
    });
    match fit_analytical(&samples, &config) {
        Ok(fit) => {
            println!(
                "analytical fit (annealing {} x {} + Powell), {} samples: {:.2} ms per fit (target < 20 ms; \
                 thesis 3400 ms), RMS {:.1} N (annealing alone {:.1} N), {} evaluations, noise RMS {:.1} N",
                config.trials,
                config.steps_per_trial,
                samples.len(),
                analytical.as_secs_f64() * 1e3,
                fit.rms_error_n,
                fit.annealing_rms_error_n,
                fit.evaluations,
                NOISE_N * (2.0_f64 / 3.0).sqrt()
            );
            println!("  estimated Psi: {:?}", fit.properties);
            scipy_comparison(&samples, &config, analytical, fit.rms_error_n);
        }
        Err(e) => println!("analytical fit failed: {e}"),
    }

    match actuator_step_time() {
        Some(t) => println!(
            "actuator model step (3 networks, 5 hidden units): {:.1} ns",
            t.as_secs_f64() * 1e9
        ),
        None => println!("actuator model step: training the benchmark model failed"),
    }
}
