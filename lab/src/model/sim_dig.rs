//! The simulator dig runner: one Autodig dig in the simulator (`vcan_sim::plant::Plant` in-process,
//! virtual time) closing the loop on the sensor readings, from a [`DigSetup`] (bench geometry, soil,
//! start, hardness index), optionally recorded as a `candump -L` trace with the frames the gateway and
//! the controller exchange. `generate-data` writes such traces; `compare` and the integration tests
//! run the dig model from the same starts.

use std::fs::File;
use std::io::BufWriter;

use anyhow::bail;
use firmware_bridge::messages::{
    Activity, AutodigStageCode, AuxValveCommand, ControllerHeartbeat, ControllerStatus, Message,
    RequestedMode, Valve,
};
use firmware_bridge::trace::{Direction, TraceWriter};
use planner::autodig::{Autodig, AutodigInputs, AutodigMaps, EndReason, Stage};
use planner::dig_model::{DigModel, DigModelConfig};
use planner::kinematics::{BucketPose, Joint, JointAngles, Kinematics};
use planner::terrain::{SectionProfile, SweptVolume};
use serde::{Deserialize, Serialize};
use vcan_sim::SimConfig;
use vcan_sim::soil_contact::World;

/// Control period, s.
pub(super) const PERIOD_S: f64 = crate::harness::PERIOD_S;
/// Physics steps per control period.
const PHYSICS_PER_PERIOD: usize = 10;
/// Neutral time recorded before and after each dig, s.
const IDLE_S: f64 = 0.3;
/// A simulated dig that has not ended by then is stopped, s.
const SIM_MAX_DIG_S: f64 = 20.0;
/// Section along the digging plane: start, end and step, m.
const SECTION_R: (f64, f64, f64) = (0.5, 12.0, 0.05);

/// A small deterministic generator (SplitMix64) for the dig setups.
#[derive(Debug, Clone)]
struct SplitMix(u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// One simulated dig: the bench, the soil and the start (Autodig starts in Pre-Dig there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigSetup {
    /// Dig number.
    pub index: usize,
    /// Simulator seed (sensor noise).
    pub seed: u64,
    /// Toe of the bench face, m from the machine.
    pub face_x_m: f64,
    /// Face angle, degrees.
    pub face_slope_deg: f64,
    /// Bench height, m.
    pub bench_height_m: f64,
    /// Soil cohesion, Pa.
    pub cohesion_pa: f64,
    /// Autodig hardness index.
    pub hardness_index: f64,
    /// Depth of the tip below the surface at the start, m.
    pub start_depth_m: f64,
    /// Start joint angles, rad.
    pub start: JointAngles,
    /// Factor on the soil's force on the bucket (thesis Table 2; the simulator's
    /// `soil_force_factor`, the dig model's force factor). 1 in files written before it existed.
    #[serde(default = "unit_factor")]
    pub soil_force_factor: f64,
}

fn unit_factor() -> f64 {
    1.0
}

/// The simulator configuration of a setup (default machine and bench, changed as the setup says).
///
/// # Errors
/// Loading the built-in files.
pub fn sim_config(setup: &DigSetup) -> anyhow::Result<SimConfig> {
    let mut cfg = SimConfig::load::<&str>(None, None, Some(setup.seed), &[])?;
    let s = &mut cfg.scenario;
    s.bench.face_x_m = setup.face_x_m;
    s.bench.face_slope_deg = setup.face_slope_deg;
    s.bench.height_m = setup.bench_height_m;
    s.soil.cohesion_pa = setup.cohesion_pa;
    s.start.boom_deg = setup.start.boom_rad.to_degrees();
    s.start.stick_deg = setup.start.stick_rad.to_degrees();
    s.start.bucket_deg = setup.start.bucket_rad.to_degrees();
    s.start.swing_deg = 0.0;
    if setup.soil_force_factor != 1.0 {
        s.soil_force_factor = Some(setup.soil_force_factor);
    }
    Ok(cfg)
}

/// The true terrain section along the digging plane of the machine at its scenario pose ([`SECTION_R`]).
///
/// # Errors
/// The section leaves the terrain grid.
pub(super) fn section_of(world: &World, cfg: &SimConfig) -> anyhow::Result<SectionProfile> {
    let pose = planner::kinematics::MachinePose {
        x_m: cfg.scenario.start.x_m,
        y_m: cfg.scenario.start.y_m,
        heading_rad: cfg.scenario.start.heading_deg.to_radians(),
    };
    Ok(world
        .terrain
        .section(&pose, 0.0, SECTION_R.0, SECTION_R.1, SECTION_R.2)?)
}

/// `n` setups drawn from `seed`. With `vary` the bench, cohesion and hardness index vary too
/// (training data); without, the default bench and soil and hardness 3 (comparison with the
/// nominal model), varying only the start.
///
/// # Errors
/// Loading the built-in files, or no reachable start found.
pub fn random_setups(n: usize, seed: u64, vary: bool) -> anyhow::Result<Vec<DigSetup>> {
    let base = SimConfig::load::<&str>(None, None, Some(seed), &[])?;
    let kin = Kinematics::new(&base.machine)?;
    let mut rng = SplitMix(seed ^ 0x05EE_DD16);
    let mut out = Vec::with_capacity(n);
    for index in 0..n {
        let mut found = None;
        for _ in 0..200 {
            let mut setup = DigSetup {
                index,
                seed: seed.wrapping_mul(1000).wrapping_add(index as u64),
                face_x_m: base.scenario.bench.face_x_m,
                face_slope_deg: base.scenario.bench.face_slope_deg,
                bench_height_m: base.scenario.bench.height_m,
                cohesion_pa: base.scenario.soil.cohesion_pa,
                hardness_index: 3.0,
                start_depth_m: rng.uniform(0.0, 0.05),
                start: JointAngles::default(),
                soil_force_factor: 1.0,
            };
            if vary {
                setup.face_x_m = rng.uniform(2.5, 4.0);
                setup.face_slope_deg = rng.uniform(30.0, 60.0);
                setup.bench_height_m = rng.uniform(1.2, 2.5);
                setup.cohesion_pa = rng.uniform(3e3, 16e3);
                setup.hardness_index = rng.uniform(1.0, 5.0);
            }
            let r = rng.uniform(setup.face_x_m + 0.8, 8.6);
            let bucket_abs = rng.uniform(-65.0_f64, -45.0).to_radians();
            let mut cfg = sim_config(&setup)?;
            cfg.scenario.start.boom_deg = 40.0;
            let world = World::from_scenario(&cfg.scenario)?;
            let profile = section_of(&world, &cfg)?;
            let z = profile.height_at(r)? - setup.start_depth_m;
            let Ok(q) = kin.inverse(&BucketPose {
                x_m: r,
                z_m: z,
                bucket_abs_rad: bucket_abs,
            }) else {
                continue;
            };
            // The stick out (thesis Table 1: -87 to -50 deg): Dig brings it in to beta.
            if q.stick_abs_rad().to_degrees() > -25.0 || q.stick_abs_rad().to_degrees() < -70.0 {
                continue;
            }
            setup.start = q;
            found = Some(setup);
            break;
        }
        match found {
            Some(s) => out.push(s),
            None => bail!("no reachable start found for dig {index}"),
        }
    }
    Ok(out)
}

/// One 10 ms sample of a simulated dig (from the sensor readings, as the controller sees them).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimSample {
    /// Time since the start of Autodig, s.
    pub time_s: f64,
    /// Tip `x` from the sensed angles, m.
    pub tip_x_m: f64,
    /// Tip `z`, m.
    pub tip_z_m: f64,
    /// Bucket angle to the horizontal, rad.
    pub bucket_abs_rad: f64,
    /// Autodig command.
    pub command: [f64; 3],
    /// Cylinder forces from the measured pressures (Eq. A20), N.
    pub force_n: [f64; 3],
    /// Head pressures, Pa.
    pub head_pa: [f64; 3],
    /// Rod pressures, Pa.
    pub rod_pa: [f64; 3],
    /// Sensed joint angles `[boom, stick, bucket]`, rad.
    pub joint_rad: [f64; 3],
    /// Autodig's stage for this command.
    pub stage: Stage,
    /// True soil force on the bucket `[F_x, F_z]` (the simulator's contact model), N.
    pub soil_force_n: [f64; 2],
    /// True cylinder velocities, m/s.
    pub velocity_m_per_s: [f64; 3],
    /// Swept volume so far (perception), m^3.
    pub swept_volume_m3: f64,
    /// Model soil force `[F_x, F_z]` at this pose and motion over the simulator's current terrain
    /// (open loop; only with `diagnose`), N.
    pub model_soil_force_n: Option<[f64; 2]>,
    /// Static cylinder forces at the true pose with the true soil force and bucket content
    /// (`tau = G - J^T f`, `F = tau / r`, Eqs. A2, A4, A7, A19; only with `diagnose`), N: what the
    /// model's statics make of the simulator's load, against the measured `force_n`.
    pub static_force_n: Option<[f64; 3]>,
}

/// A simulated dig and its statistics (measured like the controller's `DigStats`).
#[derive(Debug, Clone, PartialEq)]
pub struct SimDig {
    /// The setup.
    pub setup: DigSetup,
    /// The pre-dig section along the digging plane (true terrain).
    pub profile: SectionProfile,
    /// Samples from the start of Autodig.
    pub samples: Vec<SimSample>,
    /// Dig time, s.
    pub time_s: f64,
    /// `sum |F dL|` from the measured pressures (Eq. A20) and sensed angles, J.
    pub energy_j: f64,
    /// Swept volume over the pre-dig section along the sensed tip path, m^3.
    pub swept_volume_m3: f64,
    /// Bank volume in the bucket at the end (the simulator's ledger), m^3.
    pub bucket_volume_m3: f64,
    /// Autodig's end reason (`None`: stopped at the time limit).
    pub end: Option<EndReason>,
    /// True joint angles when Autodig started (the machine may settle during the idle time before).
    pub start_joints: JointAngles,
}

fn stage_code(stage: Stage) -> AutodigStageCode {
    match stage {
        Stage::BoomDown => AutodigStageCode::BoomDown,
        Stage::PreDig => AutodigStageCode::PreDig,
        Stage::Dig => AutodigStageCode::Dig,
        Stage::Capture => AutodigStageCode::Capture,
        Stage::Done => AutodigStageCode::Done,
    }
}

struct Recorder<'a> {
    writer: Option<&'a mut TraceWriter<BufWriter<File>>>,
}

impl Recorder<'_> {
    fn emit(&mut self, t_s: f64, msg: Message, dir: Direction) -> anyhow::Result<()> {
        if let Some(w) = self.writer.as_deref_mut() {
            let frame = msg.encode()?;
            w.write((t_s * 1e9).round() as u64, &frame, dir)?;
        }
        Ok(())
    }
}

/// Runs one dig in the simulator: neutral for 0.3 s, Autodig from Pre-Dig on the sensor readings
/// (with the perception enhancements over the true pre-dig section), neutral for 0.3 s; records the
/// frames into `trace` if given.
///
/// # Errors
/// Building the plant, Autodig errors, encoding or writing frames.
pub fn run_sim_dig(
    setup: &DigSetup,
    trace: Option<&mut TraceWriter<BufWriter<File>>>,
) -> anyhow::Result<SimDig> {
    run_sim_dig_diagnosed(setup, trace, None)
}

/// [`run_sim_dig`], and with `diagnose` the model's soil force at every sample's true pose and cylinder
/// velocities over the simulator's current (cut) terrain and true bucket content (open loop: is the
/// soil force in the model the simulator's?).
///
/// # Errors
/// As [`run_sim_dig`].
pub fn run_sim_dig_diagnosed(
    setup: &DigSetup,
    trace: Option<&mut TraceWriter<BufWriter<File>>>,
    diagnose: Option<&DigModel>,
) -> anyhow::Result<SimDig> {
    let cfg = sim_config(setup)?;
    let mut plant = cfg.build()?;
    let kin = Kinematics::new(&cfg.machine)?;
    let profile = section_of(&plant.world, &cfg)?;
    let mut swept = SweptVolume::new(profile.clone(), cfg.machine.bucket.width_m)?;
    let mut ad_cfg = DigModelConfig::nominal()?.autodig;
    ad_cfg.relief_pressure_pa = [cfg.machine.hydraulics.relief_pressure_pa; 3];
    ad_cfg.perception.bucket_capacity_m3 = cfg.machine.bucket.capacity_m3;
    ad_cfg.hardness_index = setup.hardness_index;
    let mut autodig = Autodig::starting_in(ad_cfg, AutodigMaps::builtin()?, Stage::PreDig)?;
    let cyl = &cfg.machine.cylinders;
    let areas = [&cyl.boom, &cyl.stick, &cyl.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
    let strokes = Joint::ALL.map(|j| kin.stroke(j));
    let dig_index = u16::try_from(setup.index % 60_000).unwrap_or(0);

    let mut rec = Recorder { writer: trace };
    let idle_steps = (IDLE_S / PERIOD_S).round() as usize;
    let max_dig_steps = (SIM_MAX_DIG_S / PERIOD_S).round() as usize;
    let mut samples = Vec::with_capacity(max_dig_steps);
    let mut energy_j = 0.0;
    let mut last_len: Option<[f64; 3]> = None;
    let mut dig_start_s = None;
    let mut dig_time_s = 0.0;
    let mut end = None;
    let mut post = 0usize;
    let mut command = [0.0; 3];
    let mut stage = Stage::PreDig;
    let mut alive = 0u8;
    let mut start_joints = setup.start;
    for step in 0usize.. {
        let t = plant.time_s();
        let r = plant.read_sensors();
        // The gateway's sensor frames.
        // (Pump pressures every step: this trace is the model's training data, not a bus schedule.)
        for msg in vcan_sim::node::sensor_messages(&plant, &r, command) {
            rec.emit(t, msg, Direction::Receive)?;
        }
        rec.emit(t, vcan_sim::node::pump_message(&r), Direction::Receive)?;

        // The controller's step.
        let q = JointAngles {
            boom_rad: r.angles_rad[0],
            stick_rad: r.angles_rad[1],
            bucket_rad: r.angles_rad[2],
        };
        let mut activity = Activity::Idle;
        match (dig_start_s, end.is_some() || post > 0) {
            (None, _) if step < idle_steps => command = [0.0; 3],
            (_, false) => {
                if dig_start_s.is_none() {
                    start_joints = plant.joint_angles();
                }
                let t0 = *dig_start_s.get_or_insert(t);
                activity = Activity::Dig;
                let tip = kin.forward(&q);
                let swept_m3 = swept.update(tip.x_m, tip.z_m).ok();
                let depth_m = swept.depth_m(tip.x_m, tip.z_m).ok();
                let mut len = [0.0; 3];
                let mut ext = [0.0; 3];
                let mut force = [0.0; 3];
                for (j, joint) in Joint::ALL.iter().enumerate() {
                    len[j] = kin.cylinder_length(*joint, q.to_vector()[j])?;
                    ext[j] =
                        ((len[j] - strokes[j].0) / (strokes[j].1 - strokes[j].0)).clamp(0.0, 1.0);
                    force[j] = r.head_pa[j] * areas[j].0 - r.rod_pa[j] * areas[j].1; // Eq. A20
                }
                if let Some(prev) = last_len {
                    energy_j += (0..3)
                        .map(|j| (force[j] * (len[j] - prev[j])).abs())
                        .sum::<f64>();
                }
                last_len = Some(len);
                let inputs = AutodigInputs {
                    joint_rad: [q.boom_rad, q.stick_rad, q.bucket_rad],
                    head_pressure_pa: r.head_pa,
                    rod_pressure_pa: r.rod_pa,
                    extension_fraction: ext,
                    swept_volume_m3: swept_m3,
                    bucket_depth_m: depth_m,
                };
                let out = autodig.step(&inputs, t - t0)?;
                stage = out.stage;
                command = out.command;
                let truth = plant.true_state();
                let velocity = [0, 1, 2].map(|i| plant.hydraulics.actuators[i].velocity);
                let static_force_n = diagnose
                    .map(|_| {
                        kin.cylinder_forces_from_tip_force(
                            &plant.joint_angles(),
                            &planner::kinematics::TipForce {
                                fx_n: truth.soil_force_n[0],
                                fz_n: truth.soil_force_n[1],
                                my_nm: 0.0,
                            },
                            plant.contact.content.mass_kg,
                        )
                    })
                    .transpose()?
                    .map(|f| [f[0], f[1], f[2]]);
                let model_soil_force_n = match diagnose {
                    Some(m) => {
                        let now = section_of(&plant.world, &cfg)?;
                        let f = m.soil_force_at(
                            &plant.joint_angles(),
                            velocity,
                            &now,
                            plant.contact.content.volume_m3,
                        )?;
                        // `soil_force_at` is before the force factor; the simulator's is after.
                        let k = setup.soil_force_factor;
                        Some([k * f.fx_n, k * f.fz_n])
                    }
                    None => None,
                };
                samples.push(SimSample {
                    time_s: t - t0,
                    tip_x_m: tip.x_m,
                    tip_z_m: tip.z_m,
                    bucket_abs_rad: tip.bucket_abs_rad,
                    command,
                    force_n: force,
                    head_pa: r.head_pa,
                    rod_pa: r.rod_pa,
                    joint_rad: [q.boom_rad, q.stick_rad, q.bucket_rad],
                    stage: out.stage,
                    soil_force_n: truth.soil_force_n,
                    velocity_m_per_s: velocity,
                    swept_volume_m3: swept.volume_m3(),
                    model_soil_force_n,
                    static_force_n,
                });
                if out.stage == Stage::Done || samples.len() > max_dig_steps {
                    end = out.end_reason;
                    dig_time_s = t - t0;
                    post = 1;
                    command = [0.0; 3];
                }
            }
            (_, true) => {
                command = [0.0; 3];
                post += 1;
            }
        }
        for (i, valve) in Valve::ALL.iter().enumerate() {
            let u = if i < 3 { command[i] } else { 0.0 };
            rec.emit(
                t,
                Message::AuxValveCommand(AuxValveCommand::from_fraction(*valve, u)?),
                Direction::Transmit,
            )?;
        }
        rec.emit(
            t,
            Message::ControllerHeartbeat(ControllerHeartbeat {
                mode: RequestedMode::ArmValve,
                alive_counter: alive,
            }),
            Direction::Transmit,
        )?;
        if step % 5 == 0 {
            rec.emit(
                t,
                Message::ControllerStatus(ControllerStatus {
                    activity,
                    stage: if activity == Activity::Dig {
                        stage_code(stage)
                    } else {
                        AutodigStageCode::None
                    },
                    dig_index,
                    hardness_index: setup.hardness_index.clamp(0.0, 12.5),
                    swept_volume_m3: swept.volume_m3().clamp(0.0, 6.4),
                    fault_reason: 0,
                    alive_counter: alive,
                }),
                Direction::Transmit,
            )?;
        }
        alive = (alive + 1) % 16;
        if post > idle_steps {
            break;
        }
        for _ in 0..PHYSICS_PER_PERIOD {
            plant.step([command[0], command[1], command[2], 0.0, 0.0, 0.0]);
        }
    }
    Ok(SimDig {
        setup: setup.clone(),
        profile,
        samples,
        time_s: dig_time_s,
        energy_j,
        swept_volume_m3: swept.volume_m3(),
        bucket_volume_m3: plant.contact.content.volume_m3,
        end,
        start_joints,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `compare --force-factor` reaches the simulator through the setup; `setups.json` files written
    /// before the field existed load with factor 1.
    #[test]
    fn a_setup_carries_the_soil_force_factor_to_the_simulator() {
        let mut setup = random_setups(1, 7, false).unwrap().remove(0);
        assert_eq!(setup.soil_force_factor, 1.0);
        assert_eq!(sim_config(&setup).unwrap().scenario.soil_force_factor, None);
        setup.soil_force_factor = 2.0;
        assert_eq!(
            sim_config(&setup).unwrap().scenario.soil_force_factor,
            Some(2.0)
        );
        let mut json = serde_json::to_value(&setup).unwrap();
        json.as_object_mut().unwrap().remove("soil_force_factor");
        let old: DigSetup = serde_json::from_value(json).unwrap();
        assert_eq!(old.soil_force_factor, 1.0);
    }
}
