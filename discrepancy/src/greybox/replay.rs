//! The replay: a prepared record through the (augmented) grey-box model, predicting every signal at
//! every sample from the measured state of that sample (equation-error, one step).

use super::hydraulics::{
    NeutralCache, PumpBalance, bypass_fraction, crossover_fraction, cylinder_velocity, metering,
    series_bypass,
};
use super::params::{Augmentation, GreyBoxParams};
use super::prefilter::prefilter_velocities;
use super::record::{CLAMPED_READING_PA, PreparedRecord, WARMUP_SAMPLES};
use super::spool::SpoolRelation;
use crate::effects::Candidate;
use crate::signal::{N_SIGNALS, Signal, SignalGroups};

/// Below this cylinder speed the actuator is at rest (stiction holds it), m/s.
const REST_SPEED_M_PER_S: f64 = 2.0e-3;

/// Replays a prepared record through the (augmented) grey-box model: the predicted value of every
/// signal at every sample (NaN where the measured one is undefined). Only the `groups` are computed;
/// the others are copied from `out` as it was (a cache of an earlier replay) or left NaN.
pub fn replay(
    rec: &PreparedRecord,
    params: &GreyBoxParams,
    aug: &Augmentation,
    groups: SignalGroups,
    out: &mut Vec<[f64; N_SIGNALS]>,
) {
    use Candidate as C;
    let n = rec.len();
    if out.len() != n {
        out.clear();
        out.resize(n, [f64::NAN; N_SIGNALS]);
    }
    let offset = aug.get(C::PressureSensorOffset);
    let resolver = aug.get(C::ResolverOffset);
    let leak = params.internal_leakage_m3_per_s_pa + aug.get(C::InternalLeakage).max(0.0);
    let sharing = aug.get(C::FlowSharing).clamp(0.0, 1.0);
    let max_flow =
        params.pump_max_flow_m3_per_s * (1.0 - aug.get(C::PumpSaturation)).clamp(0.0, 1.0);
    let coulomb = aug.get(C::CoulombFriction).max(0.0);
    let viscous = params.damping_n_s_per_m + aug.get(C::ViscousFriction).max(0.0);
    let cohesion = aug.get(C::SoilCohesion);
    // The links' masses against the records' (Eq. A4: the gravity forces are linear in each).
    let link_mass_change_kg = params
        .link_mass_kg
        .map_or([0.0; 3], |m| [0, 1, 2].map(|l| m[l] - rec.link_mass_kg[l]));
    let density = aug.get(C::SoilDensity);
    // The Eq. 2 compression flows scale with `1 / beta` (a bulk-modulus parameter candidate).
    let compression_scale = rec.compression_bulk_modulus_pa / params.bulk_modulus_pa;
    let spool = if groups.hydraulic || groups.pumps {
        rec.spool_cache
            .spools(&rec.samples, SpoolRelation::of(params, aug))
    } else {
        Default::default()
    };
    let mut neutral = [NeutralCache::default(); 2];
    for k in 0..n {
        let m = &rec.measured[k];
        let o = &mut out[k];
        // The pump pressures already in `out` (an earlier replay of this record: the model a fit
        // perturbs) start the pump solve closer to its root than the readings do.
        let prior_pump_pa = [o[3], o[4]];
        for s in 0..N_SIGNALS {
            if groups.contains(s) {
                o[s] = f64::NAN;
            }
        }
        if k < WARMUP_SAMPLES {
            continue;
        }
        let smp = &rec.samples[k];
        // The model sees the true pressures: readings less the sensor offset. A reading clamped at
        // the sensor's zero by a negative offset hides the true value; it is a chamber at tank.
        let tank = params.tank_pa;
        let true_pa = |p: f64| {
            if offset < 0.0 && p <= CLAMPED_READING_PA {
                tank
            } else {
                p - offset
            }
        };
        let head = smp.head_pa.map(true_pa);
        let rod = smp.rod_pa.map(true_pa);
        let pump = smp.pump_pa.map(true_pa);
        let sp = if groups.hydraulic || groups.pumps {
            spool[k]
        } else {
            [0.0; 4]
        };
        let share = (1.0 - sharing * sp[2].abs()).clamp(0.0, 1.0);
        let xfrac = crossover_fraction(params, sp[0]);
        if groups.hydraulic {
            for i in 0..3 {
                if !rec.velocity_gate[k][i] {
                    continue;
                }
                let gallery = pump[if i == 1 { 1 } else { 0 }];
                let cross =
                    (i == 0 && xfrac > 0.0).then_some((params.crossover_k * xfrac, pump[1]));
                o[i] = cylinder_velocity(
                    params,
                    i,
                    sp[i],
                    if i == 0 { share } else { 1.0 },
                    head[i],
                    rod[i],
                    gallery,
                    cross,
                    leak,
                    rec.compression[k][i].map(|c| c * compression_scale),
                    [
                        smp.head_pa[i] <= CLAMPED_READING_PA,
                        smp.rod_pa[i] <= CLAMPED_READING_PA,
                    ],
                );
            }
        }
        if groups.pumps {
            let inlet = |i: usize| if sp[i] >= 0.0 { head[i] } else { rod[i] };
            // Pump 1: boom and bucket; its bypass runs through both sections.
            let bypass1 = series_bypass(
                params.bypass_k,
                &[
                    bypass_fraction(params, sp[0]),
                    bypass_fraction(params, sp[2]),
                ],
            );
            let meter1 = [
                (
                    params.meter_in_k[0] * metering(params, sp[0]) * share,
                    inlet(0),
                ),
                (params.meter_in_k[2] * metering(params, sp[2]), inlet(2)),
            ];
            let balance1 = PumpBalance {
                max_flow,
                bypass_k: bypass1,
                fixed_demand: 0.0,
            };
            let start = |j: usize| match prior_pump_pa[j] {
                p if p.is_finite() && p > 0.0 => p - offset,
                _ => pump[j],
            };
            o[3] = (neutral[0].solve(params, balance1, &meter1, start(0)) + offset).max(0.0);
            // Pump 2: stick and swing, and the crossover to the boom (its spool closes the centre).
            let fractions = [
                bypass_fraction(params, sp[1]),
                bypass_fraction(params, sp[3]),
                1.0 - xfrac,
            ];
            let bypass2 = series_bypass(
                params.bypass_k,
                &fractions[..if xfrac > 0.0 { 3 } else { 2 }],
            );
            let swing_flow = if metering(params, sp[3]) > 0.0 {
                params.swing_displacement_m3_per_rad * smp.swing_rate_rad_per_s.abs()
            } else {
                0.0
            };
            let meter2 = [
                (params.meter_in_k[1] * metering(params, sp[1]), inlet(1)),
                (params.crossover_k * xfrac, inlet(0)),
            ];
            let balance2 = PumpBalance {
                max_flow,
                bypass_k: bypass2,
                fixed_demand: swing_flow,
            };
            o[4] = (neutral[1].solve(params, balance2, &meter2, start(1)) + offset).max(0.0);
        }
        if groups.force {
            for i in 0..3 {
                if m[5 + i].is_nan() {
                    continue;
                }
                let v = rec.velocity[k][i];
                // What the offset adds to the Eq. A20 force of the readings; a clamped chamber
                // reads zero instead of tank.
                let chamber = |reading: f64| {
                    if offset < 0.0 && reading <= CLAMPED_READING_PA {
                        -tank
                    } else {
                        offset
                    }
                };
                let sensor = params.head_area_m2[i] * chamber(smp.head_pa[i])
                    - params.rod_area_m2[i] * chamber(smp.rod_pa[i]);
                // Eq. 3 at the measured motion; the true angles are the readings less the offset.
                let links: f64 = (0..3)
                    .map(|l| link_mass_change_kg[l] * rec.gravity_force_per_kg[k][l][i])
                    .sum();
                let mut f = rec.gravity_force[k][i]
                    + links
                    + resolver * rec.gravity_force_per_rad[k][i]
                    + rec.mass[k][i] * rec.accel[k][i]
                    + viscous * v;
                // Dry friction opposes the motion. At rest (stiction) it takes an unknown value
                // within its limit; the prediction keeps none there rather than the one that fits
                // the measurement, which would reward any larger magnitude on the rest samples.
                if coulomb > 0.0 && v.abs() > REST_SPEED_M_PER_S {
                    f += coulomb * v.signum();
                }
                o[5 + i] = f + sensor;
            }
        }
        // End stops: the reading of a link at its stop is the stop's angle plus the offset.
        if groups.payload
            && let Some(t) = rec.payload[k]
        {
            o[Signal::PayloadMass.index()] =
                t.volume_m3 * (params.soil.density_kg_per_m3 + density) + offset * t.per_offset_pa;
        }
        if groups.stops && m[Signal::StopAngle.index()].is_finite() {
            o[Signal::StopAngle.index()] = resolver;
        }
        if groups.soil
            && let Some(t) = rec.soil[k]
        {
            let payload_shift = t.payload_volume_m3 * density;
            for a in 0..2 {
                // The measured force is computed with the nominal payload; a denser soil makes the
                // payload heavier, which the model carries on the prediction side.
                o[8 + a] = t.fee0[a] + cohesion * t.fee_per_pa[a] + density * t.fee_per_density[a]
                    - payload_shift * t.measured_per_kg[a];
            }
        }
    }
    if groups.hydraulic {
        prefilter_velocities(out);
    }
}

#[cfg(test)]
mod tests {
    use super::super::inertia::gravity_forces;
    use super::*;
    use crate::effects::CandidateEffect as _;
    use crate::{DigRecord, LoadTag, Sample, StageTag};
    use planner::kinematics::{Joint, JointAngles, Kinematics};
    use planner::machine::MachineConfig;

    /// A record of the bucket resting at its curl stop (readings offset by `offset_rad`), its
    /// cylinder pressing towards the stop with `press_n` of hydraulic force beyond gravity (negative:
    /// away from it).
    fn resting_at_stop(offset_rad: f64, press_n: f64) -> (DigRecord, MachineConfig, GreyBoxParams) {
        let cfg = MachineConfig::default_machine().unwrap();
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let kin = Kinematics::new(&cfg).unwrap();
        let (lo, _) = kin.stroke_limited_range(Joint::Bucket);
        let q = JointAngles {
            boom_rad: 0.5,
            stick_rad: -1.5,
            bucket_rad: lo,
        };
        let arm = kin.moment_arms(&q).unwrap()[2];
        let gravity = gravity_forces(&kin, &q).unwrap()[2];
        // Towards the lower end: the force's torque `F dL/dq` negative.
        let force = gravity - press_n * arm.signum();
        // Eq. A20 `p_h A_h - p_r A_r = F`, the other chamber at 0.3 MPa.
        let (ah, ar, low) = (params.head_area_m2[2], params.rod_area_m2[2], 3.0e5);
        let (head, rod) = if force >= 0.0 {
            ((force + low * ar) / ah, low)
        } else {
            (low, (low * ah - force) / ar)
        };
        let samples = (0..200)
            .map(|k| Sample {
                time_s: 0.01 * k as f64,
                angles_rad: [0.5 + offset_rad, -1.5 + offset_rad, lo + offset_rad],
                head_pa: [12.0e6, 6.0e6, head],
                rod_pa: [3.0e5, 3.0e5, rod],
                pump_pa: [2.0e6, 2.0e6],
                stage: StageTag::Outside,
                load: LoadTag::Loaded,
                ..Sample::default()
            })
            .collect();
        let record = DigRecord {
            index: 0,
            samples,
            section: None,
            lanes: Vec::new(),
        };
        (record, cfg, params)
    }

    /// The gravity forces of a record prepared on the machine file, with a 20 % heavier stick in
    /// the model's link masses, are those of the record prepared on a file with that stick (Eq.
    /// A4 is linear in each link's mass), and the nominal masses change nothing.
    #[test]
    fn a_heavier_link_in_the_model_moves_the_gravity_forces_as_a_heavier_file() {
        let (record, cfg, params) = resting_at_stop(0.0, 2.0e4);
        let mut nominal = PreparedRecord::new(&record, &cfg, &params).unwrap();
        let mut heavy_cfg = cfg.clone();
        heavy_cfg.masses.stick.mass_kg *= 1.2;
        let mut heavy = PreparedRecord::new(&record, &heavy_cfg, &params).unwrap();
        // A measured force at every sample, so the replay predicts one there (the record rests:
        // its own force samples are moving ones only).
        for rec in [&mut nominal, &mut heavy] {
            for m in &mut rec.measured {
                m[5..8].fill(0.0);
            }
        }
        let masses = |m: &MachineConfig| Some(m.masses.mass_kg());
        for k in 0..nominal.len() {
            let g = nominal.gravity_force[k];
            let dm = heavy_cfg.masses.stick.mass_kg - cfg.masses.stick.mass_kg;
            for i in 0..3 {
                let moved = g[i] + dm * nominal.gravity_force_per_kg[k][1][i];
                let truth = heavy.gravity_force[k][i];
                assert!(
                    (moved - truth).abs() < 1e-6 * truth.abs().max(1.0),
                    "{k} {i}"
                );
            }
        }
        assert!(
            nominal
                .gravity_force_per_kg
                .iter()
                .any(|d| d[1][0].abs() > 1.0)
        );
        // The replay's forces: the heavier model on the nominal record against the nominal model
        // on the heavier record, wherever a force is predicted.
        let groups = SignalGroups {
            force: true,
            ..SignalGroups::default()
        };
        let with_masses = |p: &GreyBoxParams, m| GreyBoxParams {
            link_mass_kg: m,
            ..p.clone()
        };
        let (mut a, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
        let aug = Augmentation::nominal();
        replay(
            &nominal,
            &with_masses(&params, masses(&heavy_cfg)),
            &aug,
            groups,
            &mut a,
        );
        replay(
            &heavy,
            &with_masses(&params, masses(&heavy_cfg)),
            &aug,
            groups,
            &mut b,
        );
        replay(
            &nominal,
            &with_masses(&params, masses(&cfg)),
            &aug,
            groups,
            &mut c,
        );
        let mut d = Vec::new();
        replay(&nominal, &with_masses(&params, None), &aug, groups, &mut d);
        let predicted = b
            .iter()
            .flat_map(|o| &o[5..8])
            .filter(|f| f.is_finite())
            .count();
        assert!(predicted > 0, "no force predicted");
        for k in 0..a.len() {
            for j in 5..8 {
                if b[k][j].is_finite() {
                    assert!((a[k][j] - b[k][j]).abs() < 1e-6 * b[k][j].abs().max(1.0));
                }
                assert!(c[k][j].total_cmp(&d[k][j]).is_eq(), "{k} {j}");
            }
        }
    }

    fn stop_signal(rec: &PreparedRecord) -> Vec<f64> {
        rec.measured
            .iter()
            .map(|m| m[Signal::StopAngle.index()])
            .filter(|v| v.is_finite())
            .collect()
    }

    /// A bucket pressed into its curl stop reads the stop's angle plus the resolver offset, for
    /// either sign of the offset (a reading beyond the stroke-limited range included), and the
    /// replay with that offset predicts it; a bucket pressed away from the stop, or only with a
    /// force dry friction or a full bucket's payload could take, is not at the stop.
    #[test]
    fn end_stop_reads_the_resolver_offset() {
        for offset in [0.012, -0.015, 0.0] {
            let (record, cfg, params) = resting_at_stop(offset, 250_000.0);
            let rec = PreparedRecord::new(&record, &cfg, &params).unwrap();
            let stops = stop_signal(&rec);
            assert_eq!(stops.len(), 200 - WARMUP_SAMPLES, "offset {offset}");
            assert!(stops.iter().all(|v| (v - offset).abs() < 1e-9), "{stops:?}");
            let mut aug = Augmentation::nominal();
            aug.set(crate::Candidate::ResolverOffset, offset);
            let groups = crate::Candidate::ResolverOffset.groups();
            assert!(groups.stops && !groups.hydraulic && !groups.force);
            let mut out = Vec::new();
            replay(&rec, &params, &aug, SignalGroups::ALL, &mut out);
            for (m, p) in rec.measured.iter().zip(&out) {
                let j = Signal::StopAngle.index();
                if m[j].is_finite() {
                    assert!((m[j] - p[j]).abs() < 1e-9);
                } else {
                    assert!(p[j].is_nan());
                }
            }
        }
        // Away from the stop; within dry friction; within what holding a full bucket needs.
        for press in [-250_000.0, 40_000.0, 150_000.0] {
            let (record, cfg, params) = resting_at_stop(0.01, press);
            let rec = PreparedRecord::new(&record, &cfg, &params).unwrap();
            assert!(stop_signal(&rec).is_empty(), "pressing {press} N");
        }
    }
}
