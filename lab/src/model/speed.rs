//! The dig model's speed: wall time of one dig prediction against the dig's own duration (the
//! real-time factor; thesis 4.1, target >= 10,000x). `cargo bench -p planner --bench dig_model`
//! profiles the step; this is the figure the results page gives.

use std::hint::black_box;
use std::time::Instant;

use super::start::{ModelStartArgs, default_site};

/// The timing of one dig prediction repeated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Speed {
    /// The predicted dig's duration, s.
    pub dig_time_s: f64,
    /// Its steps (10 ms each).
    pub steps: usize,
    /// Predictions timed.
    pub runs: usize,
    /// The fastest prediction's wall time (one the scheduler did not interrupt), s.
    pub fastest_s: f64,
    /// The median prediction's wall time, s.
    pub median_s: f64,
}

impl Speed {
    /// The dig's duration over the fastest prediction's wall time.
    #[must_use]
    pub fn real_time_factor(&self) -> f64 {
        self.dig_time_s / self.fastest_s
    }
}

/// Times `runs` predictions (at least one) of the dig from `start` on the default bench.
///
/// # Errors
/// Reading the model; the dig model's errors.
pub fn measure(start: &ModelStartArgs, runs: usize) -> anyhow::Result<Speed> {
    let model = start.load_model()?;
    let site = default_site()?;
    let dig_start = start.start(&site)?;
    let summary = model.evaluate(&dig_start, &site)?;
    let mut walls = Vec::with_capacity(runs.max(1));
    for _ in 0..runs.max(1) {
        let t0 = Instant::now();
        black_box(model.evaluate(black_box(&dig_start), &site)?);
        walls.push(t0.elapsed().as_secs_f64());
    }
    walls.sort_by(f64::total_cmp);
    Ok(Speed {
        dig_time_s: summary.time_s,
        steps: summary.steps,
        runs: walls.len(),
        fastest_s: walls[0],
        median_s: walls[walls.len() / 2],
    })
}
