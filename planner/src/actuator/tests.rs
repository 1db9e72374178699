//! Tests of the actuator model: training, prediction and the model file.
#![allow(clippy::unwrap_used)]

use super::dig::*;
use super::network::*;
use super::train::*;
use super::*;
use crate::synthetic::{
    ACTUATOR_DELAY_STEPS as PLANT_DELAY, ACTUATOR_DT_S as DT_S, ACTUATOR_V_MAX_M_PER_S as V_MAX,
    actuator_digs as synthetic_digs, smooth_signal,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// `text` (the JSON of `model`) reads back into a model that scores the same on `digs` (JSON
/// floats round-trip to within an ulp or so); returns it.
fn assert_round_trips(model: &ActuatorModel, text: &str, digs: &[ActuatorDig]) -> ActuatorModel {
    let back = ActuatorModel::from_json(text).unwrap();
    let (a, b) = (back.evaluate(digs).unwrap(), model.evaluate(digs).unwrap());
    for (x, y) in a.cylinders.iter().zip(&b.cylinders) {
        assert!((x.mae_m_per_s - y.mae_m_per_s).abs() < 1e-12);
    }
    back
}

/// `a` and `b` (a model and its JSON round trip) step alike for ten steps.
fn assert_steps_alike(a: &ActuatorModel, b: &ActuatorModel) {
    let mut s1 = a.initial_state([0.0; 3], [0.0; 3]).unwrap();
    let mut s2 = b.initial_state([0.0; 3], [0.0; 3]).unwrap();
    for _ in 0..10 {
        let va = a.step(&mut s1, [0.5, -0.3, 0.8], [1e5, -2e4, 5e4]).unwrap();
        let vb = b.step(&mut s2, [0.5, -0.3, 0.8], [1e5, -2e4, 5e4]).unwrap();
        for (x, y) in va.iter().zip(&vb) {
            assert!((x - y).abs() < 1e-9);
        }
    }
}

/// Training with `config` is refused as an invalid configuration.
fn assert_rejected(digs: &[ActuatorDig], config: &TrainConfig) {
    assert!(matches!(
        train(digs, config, |_| {}),
        Err(ActuatorError::InvalidConfig { .. })
    ));
}

fn test_config() -> TrainConfig {
    TrainConfig {
        dt_s: DT_S,
        delay_steps: PLANT_DELAY,
        teacher_forcing_epochs: 300,
        free_run_epochs: 300,
        ..TrainConfig::default()
    }
}

#[test]
fn learns_synthetic_hydraulics_within_five_percent() {
    let digs = synthetic_digs(20, 200, 7);
    let mut calls = 0;
    let (model, report) = train(&digs, &test_config(), |p| {
        calls += 1;
        assert!(p.done <= p.total);
    })
    .unwrap();
    assert!(calls > 0);
    for c in &report.test.cylinders {
        assert!(c.mae_percent_of_peak < 5.0, "{c:?}");
    }
    assert_eq!(
        model.training_summary().unwrap().digs.iter().sum::<usize>(),
        20
    );
}

#[test]
fn training_is_deterministic_for_a_seed() {
    let digs = synthetic_digs(4, 60, 3);
    let config = TrainConfig {
        teacher_forcing_epochs: 20,
        free_run_epochs: 10,
        ..test_config()
    };
    let (a, _) = train(&digs, &config, |_| {}).unwrap();
    let (b, _) = train(&digs, &config, |_| {}).unwrap();
    assert_eq!(a, b);
    let (c, _) = train(&digs, &TrainConfig { seed: 99, ..config }, |_| {}).unwrap();
    assert_ne!(a, c);
}

#[test]
fn json_round_trip_keeps_predictions() {
    let digs = synthetic_digs(4, 60, 5);
    let config = TrainConfig {
        teacher_forcing_epochs: 20,
        free_run_epochs: 5,
        ..test_config()
    };
    let (model, _) = train(&digs, &config, |_| {}).unwrap();
    let text = model.to_json().unwrap();
    assert!(text.contains(ACTUATOR_FORMAT));
    let back = assert_round_trips(&model, &text, &digs);
    assert_eq!(back.delay_steps(), model.delay_steps());
    let wrong_version = text.replace("\"version\": 1", "\"version\": 99");
    assert!(matches!(
        ActuatorModel::from_json(&wrong_version),
        Err(ActuatorError::InvalidModel(_))
    ));
    assert!(matches!(
        ActuatorModel::from_json("{}"),
        Err(ActuatorError::InvalidModel(_))
    ));
    let nan = text.replacen("\"output_bias\": ", "\"output_bias\": 1e999, \"x\": ", 1);
    assert!(ActuatorModel::from_json(&nan).is_err());
    // The coupled layout (every network sees its partner's command and force) round-trips too,
    // and its input names are checked.
    let coupled = TrainConfig {
        coupled_inputs: true,
        ..config
    };
    let (model, _) = train(&digs, &coupled, |_| {}).unwrap();
    let text = model.to_json().unwrap();
    assert!(text.contains("\"boom_force_n\"") && text.contains("\"bucket_force_n\""));
    assert_steps_alike(&model, &ActuatorModel::from_json(&text).unwrap());
    let renamed = text.replacen("\"boom_force_n\"", "\"swing_force_n\"", 1);
    assert!(ActuatorModel::from_json(&renamed).is_err());
    // The orifice layout stores its reference forces; without them the file is rejected.
    let orifice = TrainConfig {
        orifice_inputs: true,
        free_run_loss: FreeRunLoss::Absolute,
        ..coupled
    };
    let (model, _) = train(&digs, &orifice, |_| {}).unwrap();
    let text = model.to_json().unwrap();
    assert!(text.contains("\"bucket_orifice_drive\"") && text.contains("orifice_reference"));
    assert_steps_alike(&model, &ActuatorModel::from_json(&text).unwrap());
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    let mut stripped = value.clone();
    stripped["stick"]
        .as_object_mut()
        .unwrap()
        .remove("orifice_reference_force_n");
    assert!(ActuatorModel::from_json(&stripped.to_string()).is_err());
    let mut negative = value;
    negative["boom"]["orifice_reference_force_n"][0][1] = serde_json::json!(-1.0);
    assert!(ActuatorModel::from_json(&negative.to_string()).is_err());
    // Orifice inputs need the coupled layout.
    let bad = TrainConfig {
        coupled_inputs: false,
        ..orifice
    };
    assert!(matches!(
        train(&digs, &bad, |_| {}),
        Err(ActuatorError::InvalidConfig {
            field: "orifice_inputs",
            ..
        })
    ));
}

#[test]
fn orifice_drive_follows_the_square_root_of_the_pressure_drop() {
    let refs = [2.0e5, 1.0e5];
    // No load: the drive is the command.
    assert!((orifice_drive(0.5, 0.0, &refs) - 0.5).abs() < 1e-12);
    assert!((orifice_drive(-0.5, 0.0, &refs) + 0.5).abs() < 1e-12);
    // Extending against 3/4 of the reference: sqrt(1/4) of the command.
    assert!((orifice_drive(0.8, 1.5e5, &refs) - 0.4).abs() < 1e-12);
    // Retracting against a pulling load (negative force) uses the retracting reference.
    assert!((orifice_drive(-0.8, -0.75e5, &refs) + 0.4).abs() < 1e-12);
    // Stalled beyond the reference: zero, never NaN; an assisting load is capped at sqrt(2).
    assert_eq!(orifice_drive(1.0, 5.0e5, &refs), 0.0);
    assert!((orifice_drive(1.0, -1.0e7, &refs) - 2.0_f64.sqrt()).abs() < 1e-12);
    assert_eq!(orifice_drive(0.0, 1.0e5, &refs), 0.0);
}

#[test]
fn absolute_loss_is_smoothed_abs_with_its_derivative() {
    let (l, d) = FreeRunLoss::Absolute.of(0.5);
    assert!((l - (0.25_f64 + 1e-4).sqrt() + 0.01).abs() < 1e-12);
    assert!(d > 0.99 && d < 1.0);
    assert_eq!(FreeRunLoss::Absolute.of(0.0), (0.0, 0.0));
    let h = 1e-7;
    let (lp, _) = FreeRunLoss::Absolute.of(0.003 + h);
    let (lm, _) = FreeRunLoss::Absolute.of(0.003 - h);
    let (_, d) = FreeRunLoss::Absolute.of(0.003);
    assert!(((lp - lm) / (2.0 * h) - d).abs() < 1e-6);
    assert_eq!(FreeRunLoss::Squared.of(-0.5), (0.25, -1.0));
}

#[test]
fn force_noise_training_is_deterministic_and_validated() {
    let digs = synthetic_digs(6, 80, 12);
    let config = TrainConfig {
        teacher_forcing_epochs: 20,
        free_run_epochs: 10,
        force_noise: 0.5,
        ..test_config()
    };
    let (a, _) = train(&digs, &config, |_| {}).unwrap();
    let (b, _) = train(&digs, &config, |_| {}).unwrap();
    assert_eq!(a, b);
    let (c, _) = train(
        &digs,
        &TrainConfig {
            force_noise: 0.0,
            ..config.clone()
        },
        |_| {},
    )
    .unwrap();
    assert_ne!(a, c, "the offsets change the trained weights");
    let bad = TrainConfig {
        force_noise: -1.0,
        ..config
    };
    assert!(matches!(
        train(&digs, &bad, |_| {}),
        Err(ActuatorError::InvalidConfig {
            field: "force_noise",
            ..
        })
    ));
}

/// Synthetic valve whose dead band (spool overlap) acts on a lagged spool: delay, spool lag
/// `SPOOL_TAU_S`, overlap 0.3, then a short flow lag. Forces do not matter here.
const SPOOL_TAU_S: f64 = 0.12;
fn lagged_spool_digs(count: usize, steps: usize, seed: u64) -> Vec<ActuatorDig> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let gain = 1.0 - (-DT_S / SPOOL_TAU_S).exp();
    (0..count)
        .map(|_| {
            let u: Vec<Vec<f64>> = (0..3)
                .map(|_| smooth_signal(&mut rng, steps, 1.0, 12))
                .collect();
            let f = smooth_signal(&mut rng, steps, 1.0e5, 40);
            let (mut spool, mut v) = ([0.0_f64; 3], [0.0_f64; 3]);
            let mut samples = Vec::with_capacity(steps);
            for k in 0..steps {
                samples.push(ActuatorSample {
                    time_s: k as f64 * DT_S,
                    command: [u[0][k], u[1][k], u[2][k]],
                    force_n: [f[k]; 3],
                    velocity_m_per_s: v,
                });
                let d = k.saturating_sub(PLANT_DELAY);
                for j in 0..3 {
                    spool[j] += gain * (u[j][d] - spool[j]);
                    let open = (spool[j].abs() - 0.3).max(0.0) / 0.7;
                    let target = V_MAX * spool[j].signum() * open;
                    v[j] += 0.5 * (target - v[j]);
                }
            }
            ActuatorDig { samples }
        })
        .collect()
}

#[test]
fn third_inputs_round_trip_and_are_validated() {
    let digs = synthetic_digs(4, 60, 8);
    let config = TrainConfig {
        teacher_forcing_epochs: 20,
        free_run_epochs: 5,
        coupled_inputs: true,
        third_inputs: true,
        ..test_config()
    };
    let (model, _) = train(&digs, &config, |_| {}).unwrap();
    let text = model.to_json().unwrap();
    // The boom network names the stick's command and force (the crossover), not orifice drives.
    assert!(text.contains("\"delayed_stick_command\""));
    assert!(text.contains("\"stick_force_n\""));
    assert!(!text.contains("orifice"));
    assert_round_trips(&model, &text, &digs);
    // The third cylinder's force changes the boom's prediction.
    let mut s1 = model.initial_state([0.0; 3], [0.5; 3]).unwrap();
    let mut s2 = s1;
    let v1 = model.step(&mut s1, [0.5; 3], [1e5, 0.0, 1e5]).unwrap();
    let v2 = model.step(&mut s2, [0.5; 3], [1e5, 2e5, 1e5]).unwrap();
    assert_ne!(v1[0], v2[0]);
    for bad in [
        TrainConfig {
            orifice_inputs: true,
            ..config.clone()
        },
        TrainConfig {
            coupled_inputs: false,
            ..config.clone()
        },
    ] {
        assert_rejected(&digs, &bad);
    }
}

#[test]
fn force_rate_input_round_trips_and_is_held_at_zero_for_static_forces() {
    let digs = synthetic_digs(6, 60, 9);
    let config = TrainConfig {
        teacher_forcing_epochs: 20,
        free_run_epochs: 5,
        coupled_inputs: true,
        force_rate_input: true,
        batch_digs: 2,
        ..test_config()
    };
    let (model, _) = train(&digs, &config, |_| {}).unwrap();
    let text = model.to_json().unwrap();
    assert!(text.contains("\"force_rate_n_per_s\""));
    assert_round_trips(&model, &text, &digs);
    // A force step moves the prediction through the rate; with static forces it does not.
    let dynamic = model.initial_state([0.0; 3], [0.5; 3]).unwrap();
    let (mut d, mut s, mut flat) = (dynamic, dynamic.with_static_forces(), dynamic);
    for state in [&mut d, &mut s, &mut flat] {
        model.step(state, [0.5; 3], [1e5; 3]).unwrap();
    }
    let vd = model.step(&mut d, [0.5; 3], [2e5; 3]).unwrap();
    let vs = model.step(&mut s, [0.5; 3], [2e5; 3]).unwrap();
    assert_ne!(vd, vs);
    // The static state equals a dynamic one whose previous force was already the new force.
    let mut f = model.initial_state([0.0; 3], [0.5; 3]).unwrap();
    f.force_n = Some([2e5; 3]);
    f.velocity_m_per_s = flat.velocity_m_per_s;
    f.spool = flat.spool;
    f.head = flat.head;
    f.commands = flat.commands;
    assert_eq!(model.step(&mut f, [0.5; 3], [2e5; 3]).unwrap(), vs);
    // Mini-batches and dropout are deterministic for a seed; dropout needs a valid probability.
    let dropout = TrainConfig {
        force_rate_dropout: 0.5,
        ..config.clone()
    };
    assert_eq!(
        train(&digs, &dropout, |_| {}).unwrap().0,
        train(&digs, &dropout, |_| {}).unwrap().0
    );
    for bad in [
        TrainConfig {
            third_inputs: true,
            ..config.clone()
        },
        TrainConfig {
            force_rate_dropout: 1.5,
            ..config.clone()
        },
    ] {
        assert_rejected(&digs, &bad);
    }
}

#[test]
fn rate_schedule_falls_from_the_rate_to_its_fraction() {
    assert_eq!(scheduled_rate(0.01, 1.0, 7, 100), 0.01);
    assert!((scheduled_rate(0.01, 0.1, 1, 100) - 0.01).abs() < 1e-15);
    assert!((scheduled_rate(0.01, 0.1, 100, 100) - 0.001).abs() < 1e-15);
    assert!((scheduled_rate(0.01, 0.1, 50, 99) - 0.0055).abs() < 1e-15);
    let rates: Vec<f64> = (1..=100)
        .map(|e| scheduled_rate(0.01, 0.1, e, 100))
        .collect();
    assert!(rates.windows(2).all(|w| w[1] < w[0]));
}

#[test]
fn restarts_keep_the_lowest_validation_loss_and_are_validated() {
    let digs = synthetic_digs(8, 60, 5);
    let config = TrainConfig {
        teacher_forcing_epochs: 15,
        free_run_epochs: 10,
        coupled_inputs: true,
        force_rate_input: true,
        batch_digs: 2,
        final_rate_fraction: 0.1,
        ..test_config()
    };
    let (one, one_report) = train(&digs, &config, |_| {}).unwrap();
    let three = TrainConfig {
        restarts: 3,
        ..config.clone()
    };
    let mut last_total = 0;
    let (many, many_report) = train(&digs, &three, |p| last_total = p.total).unwrap();
    assert_eq!(last_total, 3 * 3 * 25);
    // The first training of each network is the single training, so the kept one is no worse on
    // the validation digs, and the split (hence the test digs) is the same.
    for j in 0..3 {
        assert!(many_report.validation_loss[j] <= one_report.validation_loss[j]);
    }
    assert_eq!(one_report.test_digs, many_report.test_digs);
    assert_eq!(many, train(&digs, &three, |_| {}).unwrap().0);
    assert_ne!(one, many, "no restart won on any network");
    // Held at zero, the force rate changes the free-running figures of a force-rate network.
    let test: Vec<ActuatorDig> = one_report
        .test_digs
        .iter()
        .map(|&i| digs[i].clone())
        .collect();
    assert_eq!(one.evaluate(&test).unwrap(), one_report.test);
    assert_ne!(one.evaluate_static(&test).unwrap(), one_report.test);
    for bad in [
        TrainConfig {
            restarts: 0,
            ..config.clone()
        },
        TrainConfig {
            final_rate_fraction: 0.0,
            ..config.clone()
        },
        TrainConfig {
            final_rate_fraction: 1.5,
            ..config.clone()
        },
    ] {
        assert_rejected(&digs, &bad);
    }
}

/// The dead band acts on the lagged spool, which the networks cannot rebuild from the delayed
/// command: with the spool estimate as input the test error is about half (1.3 % against 2.4 % of
/// the peak speed, mean of the three networks).
#[test]
fn spool_lag_input_learns_a_lagged_dead_band() {
    let digs = lagged_spool_digs(24, 200, 21);
    let config = TrainConfig {
        teacher_forcing_epochs: 400,
        free_run_epochs: 400,
        hidden_units: 8,
        ..test_config()
    };
    let mean = |r: &TrainReport| {
        r.test
            .cylinders
            .iter()
            .map(|c| c.mae_percent_of_peak)
            .sum::<f64>()
            / 3.0
    };
    let (_, plain) = train(&digs, &config, |_| {}).unwrap();
    let lagged_config = TrainConfig {
        command_lag_s: SPOOL_TAU_S,
        ..config
    };
    let (model, lagged) = train(&digs, &lagged_config, |_| {}).unwrap();
    assert!(
        mean(&lagged) < 0.75 * mean(&plain),
        "spool-lag inputs {:.2} % against delayed commands {:.2} %",
        mean(&lagged),
        mean(&plain)
    );
    // The file keeps the lag; a step on it feeds the lagged command: from rest, a full command
    // reaches the networks as 1 - exp(-dt / tau) after the delay, not as a step.
    let back = ActuatorModel::from_json(&model.to_json().unwrap()).unwrap();
    assert_eq!(back.command_lag_s(), SPOOL_TAU_S);
    let mut state = model.initial_state([0.0; 3], [0.0; 3]).unwrap();
    for _ in 0..=PLANT_DELAY {
        model.step(&mut state, [1.0; 3], [0.0; 3]).unwrap();
    }
    let gain = 1.0 - (-DT_S / SPOOL_TAU_S).exp();
    assert!(state.spool.iter().all(|s| (s - gain).abs() < 1e-12));
    let bad = TrainConfig {
        command_lag_s: -0.1,
        ..lagged_config
    };
    assert!(matches!(
        train(&digs, &bad, |_| {}),
        Err(ActuatorError::InvalidConfig { .. })
    ));
}

#[test]
fn split_digs_matches_training() {
    let digs = synthetic_digs(10, 60, 4);
    let config = TrainConfig {
        teacher_forcing_epochs: 2,
        free_run_epochs: 1,
        ..test_config()
    };
    let (_, report) = train(&digs, &config, |_| {}).unwrap();
    let split = split_digs(digs.len(), &config).unwrap();
    assert_eq!(split.test, report.test_digs);
    assert_eq!(split.validation, report.validation_digs);
    assert_eq!(split.train, report.train_digs);
    assert!(matches!(
        split_digs(2, &config),
        Err(ActuatorError::NotEnoughDigs { .. })
    ));
}

#[test]
fn step_delays_the_command_and_stays_bounded() {
    let digs = synthetic_digs(4, 60, 9);
    let config = TrainConfig {
        teacher_forcing_epochs: 30,
        free_run_epochs: 5,
        ..test_config()
    };
    let (model, _) = train(&digs, &config, |_| {}).unwrap();
    let mut state = model.initial_state([0.0; 3], [0.0; 3]).unwrap();
    let mut twin = state;
    // Until the delay has passed, a full command and a neutral one give the same prediction.
    for _ in 0..PLANT_DELAY {
        let a = model.step(&mut state, [1.0; 3], [0.0; 3]).unwrap();
        let b = model.step(&mut twin, [0.0; 3], [0.0; 3]).unwrap();
        assert_eq!(a, b);
    }
    for _ in 0..2000 {
        let v = model
            .step(&mut state, [5.0, -1.0, 1.0], [1e9, -1e9, 0.0])
            .unwrap();
        assert!(v.iter().all(|x| x.is_finite() && x.abs() < 10.0));
    }
    let before = state;
    assert!(
        model
            .step(&mut state, [f64::NAN, 0.0, 0.0], [0.0; 3])
            .is_err()
    );
    assert!(
        model
            .step(&mut state, [0.0; 3], [0.0, f64::INFINITY, 0.0])
            .is_err()
    );
    assert_eq!(state, before);
    assert!(model.initial_state([f64::NAN; 3], [0.0; 3]).is_err());
}

#[test]
fn bad_training_data_gives_typed_errors() {
    let config = test_config();
    let digs = synthetic_digs(4, 30, 1);
    assert!(matches!(
        train(&digs[..2], &config, |_| {}),
        Err(ActuatorError::NotEnoughDigs { .. })
    ));
    let mut nan = digs.clone();
    nan[1].samples[3].force_n[2] = f64::NAN;
    assert!(matches!(
        train(&nan, &config, |_| {}),
        Err(ActuatorError::NonFiniteSample { dig: 1, sample: 3 })
    ));
    let mut back = digs.clone();
    back[2].samples[5].time_s = 0.0;
    assert!(matches!(
        train(&back, &config, |_| {}),
        Err(ActuatorError::TimeNotIncreasing { dig: 2, .. })
    ));
    let mut big = digs.clone();
    big[0].samples[0].command[0] = 100.0;
    assert!(matches!(
        train(&big, &config, |_| {}),
        Err(ActuatorError::CommandOutOfRange { .. })
    ));
    let mut short = digs.clone();
    short[3].samples.truncate(1);
    assert!(matches!(
        train(&short, &config, |_| {}),
        Err(ActuatorError::DigTooShort { dig: 3, .. })
    ));
    let mut long = digs.clone();
    long[1].samples.last_mut().unwrap().time_s = 1e12;
    assert!(matches!(
        train(&long, &config, |_| {}),
        Err(ActuatorError::DigTooLong { dig: 1, .. })
    ));
    let mut still = digs.clone();
    for dig in &mut still {
        dig.samples
            .iter_mut()
            .for_each(|s| s.velocity_m_per_s[1] = 0.0);
    }
    assert!(matches!(
        train(&still, &config, |_| {}),
        Err(ActuatorError::DegenerateData {
            joint: Joint::Stick
        })
    ));
    let bad = TrainConfig {
        delay_steps: MAX_DELAY_STEPS + 1,
        ..config.clone()
    };
    assert!(matches!(
        train(&digs, &bad, |_| {}),
        Err(ActuatorError::InvalidConfig { .. })
    ));
    let bad = TrainConfig {
        hidden_units: 0,
        ..config
    };
    assert!(matches!(
        train(&digs, &bad, |_| {}),
        Err(ActuatorError::InvalidConfig { .. })
    ));
}

#[test]
fn model_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<ActuatorModel>();
    check::<ActuatorState>();
}
