//! The training-data reader: actuator training digs from `candump -L` traces (Eq. A20 forces from the
//! pressures, cylinder velocities through the moment arms from the sampled rates or the slope of the
//! resolver angles), segmented into digs, optionally with the forces the dig model's statics would
//! feed the networks instead of the measured ones.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use firmware_bridge::messages::{Activity, Message};
use planner::actuator::{ActuatorDig, ActuatorSample};
use planner::dig_model::DigModel;
use planner::kinematics::{JointAngles, Kinematics};
use planner::terrain::{SectionProfile, SweptVolume};
use vcan_sim::soil_contact::World;

use super::sim_dig::{DigSetup, section_of, sim_config};
use crate::trace_samples::{BusSample, SampleSink, read_samples};

/// Cylinder speeds above this are sensor glitches (pump flow over the smallest area is far lower), m/s.
const MAX_CYLINDER_SPEED_M_PER_S: f64 = 1.5;

/// Which measured signal the training and evaluation cylinder velocities come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum VelocitySource {
    /// Moment arm times the sampled joint rate (`JointRates`). When a cylinder stalls deep in the soil
    /// the simulator's rate can be a phantom (docs/simulator.md, Known issues).
    #[default]
    Rates,
    /// Moment arm times the slope of the resolver angles (`JointAngles`): a least-squares line over
    /// `2 ANGLE_SLOPE_HALF_WINDOW + 1` samples, i.e. the velocity that integrates to the positions
    /// the dig model predicts.
    Angles,
}

/// Which cylinder forces the networks are trained and evaluated with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ForceSource {
    /// From the measured head and rod pressures (Eq. A20).
    #[default]
    Measured,
    /// What the dig model feeds the networks: the statics `F = (G - J^T f) / r` (Eqs. A2, A4, A7,
    /// A19, clamped to the port relief) with the model's soil force `f` (`DigModel::soil_force_at`,
    /// the nominal soil with the dig's cohesion) at the trace's pose and cylinder velocities, over the
    /// pre-dig section lowered to the sensed tip path, and the payload of the sensed swept volume.
    /// Needs `model generate-data`'s `setups.json` next to the traces (the pre-dig section and soil).
    Statics,
    /// Training only: every dig twice, once with the measured and once with the statics forces (same
    /// target velocities), so the networks learn what both force signals share and stay usable with
    /// the dig model's statics. Evaluation with `mixed` uses the measured forces.
    Mixed,
}

#[derive(Debug, Clone, Copy)]
struct Tagged {
    sample: TraceSample,
    /// Moment arms at the sample's pose, m.
    arms: [f64; 3],
    /// Sensed joint angles `[boom, stick, bucket]`, rad.
    angles_rad: [f64; 3],
    /// `Some(dig index)` when a ControllerStatus said Dig or Cleanup.
    dig: Option<u16>,
}

/// Half width, in samples, of the least-squares slope that turns the resolver angles into rates
/// ([`VelocitySource::Angles`]): 11 samples at 100 Hz. The resolvers are quantised to 14 bits
/// (3.8e-4 rad) with 2e-4 rad of noise; a one-step difference would carry 0.03 rad/s of noise, the
/// slope over 0.1 s about 0.002 rad/s.
pub const ANGLE_SLOPE_HALF_WINDOW: usize = 5;

/// One training sample of a trace with both velocity signals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceSample {
    /// The sample, its velocities from the sampled joint rates ([`VelocitySource::Rates`]).
    pub sample: ActuatorSample,
    /// Cylinder velocities from the slope of the resolver angles ([`VelocitySource::Angles`]), m/s.
    pub angle_velocity_m_per_s: [f64; 3],
    /// Sensed joint angles `[boom, stick, bucket]`, rad.
    pub angles_rad: [f64; 3],
    /// Measured head-side pressures `[boom, stick, bucket]`, Pa (diagnosis: `evaluate --dump`).
    pub head_pa: [f64; 3],
    /// Measured rod-side pressures `[boom, stick, bucket]`, Pa.
    pub rod_pa: [f64; 3],
    /// Measured pump gallery pressures `[pump 1 (boom, bucket), pump 2 (stick, swing)]`, Pa (0 in
    /// traces without `PumpPressures`).
    pub pump_pa: [f64; 2],
    /// Autodig stage of the latest `ControllerStatus` (0 without one).
    pub stage: u8,
}

/// One dig of a trace with both velocity signals ([`read_training_digs`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TraceDig {
    /// Samples in time order.
    pub samples: Vec<TraceSample>,
}

impl TraceDig {
    /// The dig as actuator training data with the velocities from `source`.
    #[must_use]
    pub fn to_actuator_dig(&self, source: VelocitySource) -> ActuatorDig {
        ActuatorDig {
            samples: self
                .samples
                .iter()
                .map(|s| match source {
                    VelocitySource::Rates => s.sample,
                    VelocitySource::Angles => ActuatorSample {
                        velocity_m_per_s: s.angle_velocity_m_per_s,
                        ..s.sample
                    },
                })
                .collect(),
        }
    }
}

/// Least-squares slope of `angles` against `times` over the samples `lo..=hi`, rad/s.
fn angle_slope(tagged: &[Tagged], lo: usize, hi: usize) -> [f64; 3] {
    let window = &tagged[lo..=hi];
    let n = window.len() as f64;
    let t_mean = window.iter().map(|s| s.sample.sample.time_s).sum::<f64>() / n;
    let stt: f64 = window
        .iter()
        .map(|s| (s.sample.sample.time_s - t_mean).powi(2))
        .sum();
    [0, 1, 2].map(|j| {
        if stt <= 0.0 {
            return 0.0;
        }
        let q_mean = window.iter().map(|s| s.angles_rad[j]).sum::<f64>() / n;
        window
            .iter()
            .map(|s| (s.sample.sample.time_s - t_mean) * (s.angles_rad[j] - q_mean))
            .sum::<f64>()
            / stt
    })
}

/// Reads the training digs of one trace: samples at every `JointAngles` frame with the latest
/// commands, pressures (-> Eq. A20 forces) and cylinder velocities through the moment arms, both from
/// the sampled rates and from the slope of the resolver angles ([`TraceSample`]), segmented by
/// `ControllerStatus` (activity Dig or Cleanup, per dig index) or, in traces without it, by command
/// activity (runs of non-neutral commands, split by 1 s of neutral).
///
/// # Errors
/// Opening or reading the file.
pub fn read_training_digs(
    path: &Path,
    kin: &Kinematics,
    areas: [(f64, f64); 3],
) -> anyhow::Result<Vec<TraceDig>> {
    /// The samples with the latest rates, tagged with their dig.
    struct Sink<'a> {
        kin: &'a Kinematics,
        areas: [(f64, f64); 3],
        tagged: Vec<Tagged>,
        seen_status: bool,
    }
    impl SampleSink for Sink<'_> {
        fn message(&mut self, _time_s: f64, message: &Message) {
            self.seen_status |= matches!(message, Message::ControllerStatus(_));
        }
        fn sample(&mut self, s: &BusSample) {
            let [boom_rad, stick_rad, bucket_rad, _] = s.angles_rad;
            let q = JointAngles {
                boom_rad,
                stick_rad,
                bucket_rad,
            };
            let (Some(w), Ok(arms)) = (s.rates_rad_per_s, self.kin.moment_arms(&q)) else {
                return;
            };
            let (head, rod, areas) = (s.head_pa, s.rod_pa, self.areas);
            let sample = ActuatorSample {
                time_s: s.time_s,
                command: [s.command[0], s.command[1], s.command[2]],
                force_n: [0, 1, 2].map(|j| head[j] * areas[j].0 - rod[j] * areas[j].1), // Eq. A20
                velocity_m_per_s: [0, 1, 2].map(|j| arms[j] * w[j]),
            };
            let dig = s.status.and_then(|st| {
                matches!(st.activity, Activity::Dig | Activity::Cleanup).then_some(st.dig_index)
            });
            let angles_rad = [boom_rad, stick_rad, bucket_rad];
            if sample
                .force_n
                .iter()
                .chain(&sample.velocity_m_per_s)
                .chain(&angles_rad)
                .all(|v| v.is_finite())
            {
                self.tagged.push(Tagged {
                    sample: TraceSample {
                        sample,
                        angle_velocity_m_per_s: [0.0; 3],
                        angles_rad,
                        head_pa: head,
                        rod_pa: rod,
                        pump_pa: s.pump_pa,
                        stage: s.status.map_or(0, |st| st.stage as u8),
                    },
                    arms: [arms[0], arms[1], arms[2]],
                    angles_rad,
                    dig,
                });
            }
        }
    }
    let mut sink = Sink {
        kin,
        areas,
        tagged: Vec::new(),
        seen_status: false,
    };
    read_samples(path, &mut sink)?;
    let Sink {
        mut tagged,
        seen_status,
        ..
    } = sink;
    // Angle-derived velocities: the slope over the neighbouring samples of the same run (no gap
    // above 50 ms), at the sample's moment arms.
    let run_start: Vec<usize> = {
        let mut start = 0;
        (0..tagged.len())
            .map(|k| {
                if k > 0
                    && tagged[k].sample.sample.time_s - tagged[k - 1].sample.sample.time_s > 0.05
                {
                    start = k;
                }
                start
            })
            .collect()
    };
    let mut run_end = vec![0; tagged.len()];
    for k in (0..tagged.len()).rev() {
        run_end[k] = if k + 1 < tagged.len() && run_start[k + 1] == run_start[k] {
            run_end[k + 1]
        } else {
            k
        };
    }
    for k in 0..tagged.len() {
        let lo = k.saturating_sub(ANGLE_SLOPE_HALF_WINDOW).max(run_start[k]);
        let hi = (k + ANGLE_SLOPE_HALF_WINDOW).min(run_end[k]);
        let w = angle_slope(&tagged, lo, hi);
        let arms = tagged[k].arms;
        tagged[k].sample.angle_velocity_m_per_s = [0, 1, 2].map(|j| arms[j] * w[j]);
    }
    let mut digs = Vec::new();
    let mut current: Vec<TraceSample> = Vec::new();
    let mut current_key: Option<u16> = None;
    let mut neutral_since: Option<f64> = None;
    let finish = |current: &mut Vec<TraceSample>, digs: &mut Vec<TraceDig>| {
        if current.len() >= 50 {
            digs.push(TraceDig {
                samples: std::mem::take(current),
            });
        } else {
            current.clear();
        }
    };
    for s in &tagged {
        let key = if seen_status {
            s.dig
        } else {
            // Command activity: a dig runs while some command is non-neutral, until 1 s of neutral.
            let active = s.sample.sample.command.iter().any(|u| u.abs() > 1e-3);
            if active {
                neutral_since = None;
                Some(0)
            } else {
                let since = *neutral_since.get_or_insert(s.sample.sample.time_s);
                (s.sample.sample.time_s - since < 1.0 && !current.is_empty()).then_some(0)
            }
        };
        if key != current_key {
            finish(&mut current, &mut digs);
            current_key = key;
        }
        if key.is_some() {
            current.push(s.sample);
        }
    }
    finish(&mut current, &mut digs);
    Ok(digs)
}

/// Reads the digs of `traces` for training or evaluation (cut short at implausible sampled rates).
pub(super) fn load_trace_digs(
    traces: &[PathBuf],
    machine: &planner::machine::MachineConfig,
    forces: ForceSource,
) -> anyhow::Result<Vec<TraceDig>> {
    let kin = Kinematics::new(machine)?;
    let c = &machine.cylinders;
    let areas = [&c.boom, &c.stick, &c.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
    let mut digs = Vec::new();
    let mut implausible = 0usize;
    let mut setups: std::collections::HashMap<PathBuf, Vec<DigSetup>> =
        std::collections::HashMap::new();
    let mut model = match forces {
        ForceSource::Measured | ForceSource::Mixed => None,
        ForceSource::Statics => Some(DigModel::nominal()?),
    };
    for path in traces {
        let mut trace_digs = read_training_digs(path, &kin, areas)?;
        if let Some(model) = model.as_mut() {
            let setup = trace_setup(path, &mut setups)?;
            for dig in &mut trace_digs {
                replace_with_statics(dig, &setup, model, &kin, machine)?;
            }
        }
        for mut dig in trace_digs {
            // A cylinder faster than the pumps can drive it is a glitch, not hydraulics: keep the
            // dig up to it.
            if let Some(k) = dig.samples.iter().position(|s| {
                s.sample
                    .velocity_m_per_s
                    .iter()
                    .any(|v| v.abs() > MAX_CYLINDER_SPEED_M_PER_S)
            }) {
                implausible += 1;
                dig.samples.truncate(k);
            }
            if dig.samples.len() >= 50 {
                digs.push(dig);
            }
        }
    }
    if implausible > 0 {
        println!(
            "cut {implausible} dig(s) short at a cylinder speed above {MAX_CYLINDER_SPEED_M_PER_S} m/s"
        );
    }
    if digs.len() < 3 {
        bail!(
            "found {} digs in the traces; training needs at least 3",
            digs.len()
        );
    }
    Ok(digs)
}

/// The setup of a `model generate-data` trace (`dig_NNN.log`) from `setups.json` in its folder.
fn trace_setup(
    path: &Path,
    cache: &mut std::collections::HashMap<PathBuf, Vec<DigSetup>>,
) -> anyhow::Result<DigSetup> {
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let index: usize = path
        .file_stem()
        .and_then(|s| s.to_str())
        .and_then(|s| s.strip_prefix("dig_"))
        .and_then(|s| s.parse().ok())
        .with_context(|| {
            format!(
                "--forces statics needs generate-data traces named dig_NNN.log, not {}",
                path.display()
            )
        })?;
    if !cache.contains_key(&dir) {
        let file = dir.join("setups.json");
        let text = std::fs::read_to_string(&file)
            .with_context(|| format!("reading {} (--forces statics)", file.display()))?;
        cache.insert(dir.clone(), serde_json::from_str(&text)?);
    }
    cache
        .get(&dir)
        .and_then(|v| v.iter().find(|s| s.index == index))
        .cloned()
        .with_context(|| format!("no setup {index} in {}/setups.json", dir.display()))
}

/// Replaces the measured forces of `dig` by the ones the dig model would feed the networks at the
/// recorded states ([`ForceSource::Statics`]): the model's soil force for the pose and the sampled
/// cylinder velocities over the pre-dig section lowered to the sensed tip path (the dig model's cut
/// surface), with the payload of the sensed swept volume (perception, 3.2), through the statics
/// `F = (G - J^T f) / r` (Eqs. A2, A4, A7, A19), clamped to the port relief as in the dig model.
fn replace_with_statics(
    dig: &mut TraceDig,
    setup: &DigSetup,
    model: &mut DigModel,
    kin: &Kinematics,
    machine: &planner::machine::MachineConfig,
) -> anyhow::Result<()> {
    let cfg = sim_config(setup)?;
    let world = World::from_scenario(&cfg.scenario)?;
    let profile = section_of(&world, &cfg)?;
    let soil = &cfg.scenario.soil;
    let psi = planner::soil::SoilProperties {
        density_kg_per_m3: soil.density_kg_per_m3,
        failure_angle_rad: soil.failure_angle_deg.to_radians(),
        friction_angle_rad: soil.friction_angle_deg.to_radians(),
        tool_friction_angle_rad: soil.tool_friction_angle_deg.to_radians(),
        cohesion_pa: soil.cohesion_pa,
    };
    model.set_soil(planner::dig_model::SoilModel::Analytical(psi))?;
    let capacity = machine.bucket.capacity_m3;
    let port_relief = STATICS_PORT_RELIEF_FACTOR * machine.hydraulics.relief_pressure_pa;
    let c = &machine.cylinders;
    let areas = [&c.boom, &c.stick, &c.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
    let mut swept = SweptVolume::new(profile.clone(), machine.bucket.width_m)?;
    let (r0, step) = (profile.r_start_m(), profile.step_m());
    let n = ((profile.r_end_m() - r0) / step).round() as usize + 1;
    let mut heights: Vec<f64> = (0..n)
        .map(|k| profile.height_at((r0 + k as f64 * step).min(profile.r_end_m())))
        .collect::<Result<_, _>>()?;
    let mut last_tip: Option<[f64; 2]> = None;
    for s in &mut dig.samples {
        let [b, st, bu] = s.angles_rad;
        let q = JointAngles {
            boom_rad: b,
            stick_rad: st,
            bucket_rad: bu,
        };
        let tip = kin.forward(&q);
        let v_s = swept.update(tip.x_m, tip.z_m)?.min(capacity);
        // The cut surface: the section lowered to the straight path between successive tips.
        if let Some(from) = last_tip {
            let to = [tip.x_m, tip.z_m];
            let dx = to[0] - from[0];
            if dx.abs() > 1e-12 {
                let (lo, hi) = (from[0].min(to[0]), from[0].max(to[0]));
                for (k, h) in heights.iter_mut().enumerate() {
                    let r = r0 + k as f64 * step;
                    if r >= lo && r <= hi {
                        *h = h.min(from[1] + (r - from[0]) / dx * (to[1] - from[1]));
                    }
                }
            }
        }
        last_tip = Some([tip.x_m, tip.z_m]);
        let surface = SectionProfile::new(r0, step, heights.clone())?;
        let f = model.soil_force_at(&q, s.sample.velocity_m_per_s, &surface, v_s)?;
        let forces = kin.cylinder_forces_from_tip_force(&q, &f, v_s * psi.density_kg_per_m3)?;
        for j in 0..3 {
            let f = forces[j];
            if !f.is_finite() {
                bail!(
                    "non-finite statics force in the replay of dig {}",
                    setup.index
                );
            }
            s.sample.force_n[j] = f.clamp(-port_relief * areas[j].1, port_relief * areas[j].0);
        }
    }
    Ok(())
}

/// Port-relief pressure as a multiple of the main relief, as the dig model clamps its statics.
const STATICS_PORT_RELIEF_FACTOR: f64 = 1.08;

/// The digs of `traces` with the velocities from `source` and the forces from `forces`.
pub(super) fn load_digs(
    traces: &[PathBuf],
    machine: &planner::machine::MachineConfig,
    source: VelocitySource,
    forces: ForceSource,
) -> anyhow::Result<Vec<ActuatorDig>> {
    let mut digs: Vec<ActuatorDig> = load_trace_digs(traces, machine, forces)?
        .iter()
        .map(|d| d.to_actuator_dig(source))
        .collect();
    if forces == ForceSource::Mixed {
        let statics = load_trace_digs(traces, machine, ForceSource::Statics)?;
        digs.extend(statics.iter().map(|d| d.to_actuator_dig(source)));
    }
    Ok(digs)
}

#[cfg(test)]
mod tests {
    use std::fs::File;
    use std::io::BufWriter;

    use firmware_bridge::trace::TraceWriter;

    use super::*;
    use crate::model::sim_dig::{random_setups, run_sim_dig};

    /// A training trace cut mid-line (a logger stopped on the machine) was an error that lost the
    /// whole file; the digs before the cut are read.
    #[test]
    fn a_training_trace_cut_mid_line_keeps_what_precedes_the_cut() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dig_000.log");
        let setup = random_setups(1, 3, false).unwrap().remove(0);
        let mut w = TraceWriter::new(BufWriter::new(File::create(&path).unwrap()), "vcan0", true);
        run_sim_dig(&setup, Some(&mut w)).unwrap();
        w.flush().unwrap();
        drop(w);
        let machine = planner::machine::MachineConfig::default_machine().unwrap();
        let kin = Kinematics::new(&machine).unwrap();
        let c = &machine.cylinders;
        let areas = [&c.boom, &c.stick, &c.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
        let count = |digs: &[TraceDig]| digs.iter().map(|d| d.samples.len()).sum::<usize>();
        let whole = count(&read_training_digs(&path, &kin, areas).unwrap());
        assert!(whole > 100, "{whole} samples");
        let text = std::fs::read_to_string(&path).unwrap();
        // Cut two thirds in, inside a line.
        let mut cut_at = text.len() * 2 / 3;
        while text.as_bytes()[cut_at - 1] == b'\n' {
            cut_at += 1;
        }
        std::fs::write(&path, &text[..cut_at]).unwrap();
        let cut = count(&read_training_digs(&path, &kin, areas).unwrap());
        assert!(cut > 0 && cut < whole, "{cut} of {whole} samples");
    }

    fn tagged_at(t: f64, angles_rad: [f64; 3]) -> Tagged {
        Tagged {
            sample: TraceSample {
                sample: ActuatorSample {
                    time_s: t,
                    command: [0.0; 3],
                    force_n: [0.0; 3],
                    velocity_m_per_s: [0.0; 3],
                },
                angle_velocity_m_per_s: [0.0; 3],
                angles_rad,
                head_pa: [0.0; 3],
                rod_pa: [0.0; 3],
                pump_pa: [0.0; 2],
                stage: 0,
            },
            arms: [1.0; 3],
            angles_rad,
            dig: None,
        }
    }

    #[test]
    fn angle_slope_recovers_the_rate_of_quantised_resolver_angles() {
        // Ramps at 0.2, -0.05 and 0 rad/s, quantised to 14 bits like the simulator's resolvers.
        let quantum = std::f64::consts::TAU / 16384.0;
        let rates = [0.2, -0.05, 0.0];
        let tagged: Vec<Tagged> = (0..40)
            .map(|k| {
                let t = k as f64 * 0.01;
                tagged_at(t, rates.map(|w| (0.3 + w * t / quantum).round() * quantum))
            })
            .collect();
        let w = angle_slope(&tagged, 10, 20);
        for j in 0..3 {
            assert!(
                (w[j] - rates[j]).abs() < 0.01,
                "joint {j}: {} against {}",
                w[j],
                rates[j]
            );
        }
        // A single sample has no slope.
        assert_eq!(angle_slope(&tagged, 5, 5), [0.0; 3]);
    }

    #[test]
    fn a_generated_trace_reads_back_with_both_velocities_and_statics_forces() {
        let dir = tempfile::tempdir().unwrap();
        let setups = random_setups(3, 3, true).unwrap();
        let mut paths = Vec::new();
        for setup in &setups {
            let path = dir.path().join(format!("dig_{:03}.log", setup.index));
            let mut w =
                TraceWriter::new(BufWriter::new(File::create(&path).unwrap()), "vcan0", true);
            run_sim_dig(setup, Some(&mut w)).unwrap();
            w.flush().unwrap();
            paths.push(path);
        }
        std::fs::write(
            dir.path().join("setups.json"),
            serde_json::to_string(&setups).unwrap(),
        )
        .unwrap();
        let machine = planner::machine::MachineConfig::default_machine().unwrap();
        let measured = load_trace_digs(&paths, &machine, ForceSource::Measured).unwrap();
        let statics = load_trace_digs(&paths, &machine, ForceSource::Statics).unwrap();
        assert_eq!(measured.len(), 3);
        assert_eq!(statics.len(), 3);
        // The two velocity signals describe the same motion: their means over the dig agree to a
        // small fraction of the peak speed (they differ sample by sample by noise and smoothing).
        for (dig, j) in measured.iter().flat_map(|d| [(d, 0), (d, 1), (d, 2)]) {
            let s = &dig.samples;
            let peak = s
                .iter()
                .map(|x| x.sample.velocity_m_per_s[j].abs())
                .fold(0.0, f64::max);
            let mean_rate = s.iter().map(|x| x.sample.velocity_m_per_s[j]).sum::<f64>();
            let mean_angle = s.iter().map(|x| x.angle_velocity_m_per_s[j]).sum::<f64>();
            let n = s.len() as f64;
            assert!(
                ((mean_rate - mean_angle) / n).abs() < 0.05 * peak,
                "cylinder {j}: mean {} against {} m/s, peak {peak}",
                mean_rate / n,
                mean_angle / n
            );
        }
        // Statics forces: finite, within the port relief, not the measured ones, and the same samples
        // otherwise.
        let relief = STATICS_PORT_RELIEF_FACTOR * machine.hydraulics.relief_pressure_pa;
        let c = &machine.cylinders;
        let head = [&c.boom, &c.stick, &c.bucket].map(|c| c.head_area_m2());
        let mut differs = false;
        let pairs = measured.iter().zip(&statics).flat_map(|(m, s)| {
            assert_eq!(m.samples.len(), s.samples.len());
            m.samples.iter().zip(&s.samples)
        });
        for (m, s) in pairs {
            assert_eq!(m.sample.time_s, s.sample.time_s);
            assert_eq!(m.sample.velocity_m_per_s, s.sample.velocity_m_per_s);
            for ((f, a), fm) in s.sample.force_n.iter().zip(head).zip(m.sample.force_n) {
                assert!(f.is_finite() && *f <= relief * a + 1e-6);
                differs |= (f - fm).abs() > 1.0;
            }
        }
        assert!(differs);
    }
}
