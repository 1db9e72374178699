//! Actuator network training on synthetic hydraulics (thesis 4.2.3): the held-out error for a few
//! schedules and network sizes, to see what the free-running phase and more units buy.
//!
//! `cargo run -p planner --release --features synthetic --example actuator_training`

use planner::actuator::{TrainConfig, train};
use planner::synthetic::{ACTUATOR_DELAY_STEPS, ACTUATOR_DT_S, actuator_digs};

fn main() -> Result<(), planner::actuator::ActuatorError> {
    let digs = actuator_digs(30, 250, 11);
    for (tf, fr, hidden) in [(300, 0, 5), (300, 400, 5), (1000, 1000, 5), (300, 400, 8)] {
        let config = TrainConfig {
            dt_s: ACTUATOR_DT_S,
            delay_steps: ACTUATOR_DELAY_STEPS,
            teacher_forcing_epochs: tf,
            free_run_epochs: fr,
            hidden_units: hidden,
            ..TrainConfig::default()
        };
        let start = std::time::Instant::now();
        let (_, report) = train(&digs, &config, |_| {})?;
        let pct = report.test.cylinders.map(|c| c.mae_percent_of_peak);
        println!(
            "tf {tf} fr {fr} hidden {hidden}: test {pct:.2?} % epochs {:?} val {:.4?} in {:.2?}",
            report.free_run_epochs,
            report.validation_loss,
            start.elapsed()
        );
    }
    Ok(())
}
