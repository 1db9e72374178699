//! Update the twin: what an analysis named, written as a simulator profile, and the gap between the
//! measured sessions and the simulator re-run with it.
//!
//! - **The profile** ([`TwinProfile`]): the machine file the analysis read with every named
//!   parameter's fitted value written at its key (the rest of the file, comments and layout
//!   included, as it was), and the named effects as the simulator takes them (`demo --effect
//!   NAME=VALUE`, or the `[effects]` table of a bench or machine file). `demo --plant-machine
//!   twin/machine.toml --effect ...` runs the updated twin.
//! - **The gap** ([`simulator_gap`]): the simulator's own plant ([`vcan_sim::plant::Plant`]) re-run
//!   on the measured commands of the held-out digs, in windows of [`WINDOW_SAMPLES`] that each
//!   start from the measured state (cylinder extensions and rates from the resolvers, the chamber
//!   and pump pressures; multiple shooting, so the error cannot drift away over a whole dig), the
//!   spools warmed up on the commands before as the grey-box replay's are ([`WARMUP_SAMPLES`],
//!   no gap in the record: [`warmed_up`]). Its cylinder velocities and pressures are
//!   compared with the measured ones, per signal group, with the nominal plant (the machine file,
//!   no effect) and with the twin's. Only samples with the empty bucket in free air outside Autodig
//!   are re-run: the re-run has no terrain (the measured one after earlier digs is not known to the
//!   simulator) and no payload.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::greybox::{PreparedRecord, WARMUP_SAMPLES, warmed_up};
use crate::{AnalysisResult, DiscrepancyError, LoadTag, Result, Sample, StageTag};
use planner::effects::Effect;
use planner::kinematics::JointAngles;
use planner::machine::MachineConfig;
use vcan_sim::effects::EffectSet;
use vcan_sim::plant::{PHYSICS_DT_S, Plant};
use vcan_sim::scenario::Scenario;

/// Samples of one re-run window from the measured state (0.5 s).
pub const WINDOW_SAMPLES: usize = 50;

/// Samples between a command in a record and the physics it acts on beyond the machine file's
/// transport delay: the gateway applies a command frame at its next control period (the shipped
/// grey-box model's 70 ms delay against the file's 60 ms is the same period).
pub const COMMAND_LAG_SAMPLES: usize = 1;

/// How far the re-run's terrain is lowered out of the bucket's reach, m.
const NO_TERRAIN_DROP_M: f64 = 100.0;

/// One value of the profile: a machine-file key or an effect name, with its value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProfileValue {
    /// Machine-file key (dotted) or effect name.
    pub name: String,
    /// The value (machine file's units, or the effect's).
    pub value: f64,
    /// Its unit.
    pub unit: &'static str,
}

/// The simulator profile of an analysis: a machine file and the effects.
#[derive(Debug, Clone, PartialEq)]
pub struct TwinProfile {
    /// The machine file's text with the named parameters written in.
    pub machine_toml: String,
    /// The named parameters, at their keys.
    pub parameters: Vec<ProfileValue>,
    /// The named effects.
    pub effects: Vec<ProfileValue>,
    /// Named effects the simulator cannot hide at their value (a change below the starting
    /// model's calibration, such as less flow sharing than the nominal model's), written at the
    /// end of the simulator's range instead: what was named, and what was written.
    pub clamped: Vec<String>,
}

/// `text` (a machine file) with the number at dotted `key` set to `value`; everything else (other
/// values, comments, layout) unchanged.
///
/// # Errors
/// [`DiscrepancyError::Machine`] when the text does not parse or the key is not a number in it.
pub fn set_machine_value(text: &str, key: &str, value: f64) -> Result<String> {
    let bad = |why: String| DiscrepancyError::Machine(format!("writing {key} = {value}: {why}"));
    if !value.is_finite() {
        return Err(bad("not finite".into()));
    }
    let mut doc: toml_edit::DocumentMut = text.parse().map_err(|e| bad(format!("{e}")))?;
    let parts: Vec<&str> = key.split('.').collect();
    let (field, tables) = parts.split_last().ok_or_else(|| bad("empty key".into()))?;
    let mut item = doc.as_item_mut();
    for t in tables {
        item = item
            .get_mut(t)
            .filter(|i| i.is_table_like())
            .ok_or_else(|| bad(format!("no table {t}")))?;
    }
    let slot = item
        .get_mut(field)
        .filter(|i| i.is_float() || i.is_integer())
        .ok_or_else(|| bad(format!("no number field {field}")))?;
    let decor = slot.as_value().map(|v| v.decor().clone());
    let mut new = toml_edit::Value::from(value);
    if let Some(d) = decor {
        *new.decor_mut() = d;
    }
    *slot = toml_edit::Item::Value(new);
    Ok(doc.to_string())
}

impl TwinProfile {
    /// The profile of an analysis's result on the machine file `machine_text`: its named effects
    /// and parameters, and of an ambiguous pair the one the augmented model carries (the better one
    /// alone), as `model.json` does.
    ///
    /// # Errors
    /// A parameter key that is not a number of the file, or a file that no longer validates.
    pub fn of(machine_text: &str, r: &AnalysisResult) -> Result<Self> {
        let named = r
            .named_effects
            .iter()
            .map(|e| (e.name.as_str(), e.kind, e.magnitude, e.unit));
        let carried = r
            .ambiguous
            .iter()
            .map(|a| &a.candidates[0])
            .map(|c| (c.name.as_str(), c.kind, c.alone, c.unit));
        let mut profile = Self {
            machine_toml: machine_text.to_string(),
            parameters: Vec::new(),
            effects: Vec::new(),
            clamped: Vec::new(),
        };
        for (name, kind, named_value, unit) in named.chain(carried) {
            let mut value = named_value;
            if kind != "parameter"
                && let Some((lo, hi)) = Effect::from_name(name).map(Effect::range)
                && !(lo..=hi).contains(&value)
            {
                value = value.clamp(lo, hi);
                profile.clamped.push(format!(
                    "{name} {named_value:.4e} is outside the simulator's range {lo:e}..{hi:e}; \
                     the twin has {value:e}"
                ));
            }
            let v = ProfileValue {
                name: name.to_string(),
                value,
                unit,
            };
            if kind == "parameter" {
                profile.machine_toml = set_machine_value(&profile.machine_toml, name, value)?;
                profile.parameters.push(v);
            } else {
                profile.effects.push(v);
            }
        }
        profile.machine()?;
        Ok(profile)
    }

    /// The profile's machine.
    ///
    /// # Errors
    /// [`DiscrepancyError::Machine`] naming the field when it does not validate.
    pub fn machine(&self) -> Result<MachineConfig> {
        MachineConfig::from_toml_str_named(&self.machine_toml, "twin/machine.toml")
            .map_err(|e| DiscrepancyError::Machine(e.to_string()))
    }

    /// The effects as the simulator's effect set.
    ///
    /// # Errors
    /// An effect the simulator does not know or out of its range.
    pub fn effect_set(&self) -> Result<EffectSet> {
        let mut set = EffectSet::nominal();
        for e in &self.effects {
            set.set_by_name(&e.name, e.value)
                .map_err(|err| DiscrepancyError::Invalid(format!("effect {}: {err}", e.name)))?;
        }
        Ok(set)
    }

    /// `effects.toml`: the effects as an `[effects]` table (a bench or machine file's).
    pub fn effects_toml(&self) -> String {
        let mut s = String::from(
            "# Effects named by excavator-ctl discrepancy (the simulator's names and units);\n\
             # demo --effect NAME=VALUE, or a bench file's [effects] table.\n[effects]\n",
        );
        for e in &self.effects {
            s.push_str(&format!("{} = {:e}\n", e.name, e.value));
        }
        s
    }

    /// The `demo` options that run the twin, machine file at `machine_path`.
    pub fn demo_options(&self, machine_path: &str) -> String {
        let mut s = format!("--plant-machine {machine_path}");
        for e in &self.effects {
            s.push_str(&format!(" --effect {}={:e}", e.name, e.value));
        }
        s
    }
}

/// The signal groups of the re-run, with their unit.
pub const GAP_GROUPS: [(&str, &str); 3] = [
    ("cylinder_velocity", "m/s"),
    ("pump_pressure", "Pa"),
    ("chamber_pressure", "Pa"),
];

/// The simulator's gap to measured samples: RMS of re-run less measured per signal and group.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimulatorGap {
    /// RMS per group ([`GAP_GROUPS`]).
    pub groups: BTreeMap<String, f64>,
    /// RMS per signal.
    pub signals: BTreeMap<String, f64>,
    /// Samples compared.
    pub samples: usize,
    /// Windows re-run.
    pub windows: usize,
}

const SIGNALS: [(&str, usize); 11] = [
    ("boom_velocity", 0),
    ("stick_velocity", 0),
    ("bucket_velocity", 0),
    ("pump1_pressure", 1),
    ("pump2_pressure", 1),
    ("boom_head_pressure", 2),
    ("boom_rod_pressure", 2),
    ("stick_head_pressure", 2),
    ("stick_rod_pressure", 2),
    ("bucket_head_pressure", 2),
    ("bucket_rod_pressure", 2),
];

/// Whether a sample is re-run: empty bucket in free air, outside Autodig.
fn free_air(s: &Sample) -> bool {
    s.stage == StageTag::Outside && s.load == LoadTag::EmptyFreeAir
}

/// The plant of `machine` with `effects`, its terrain out of reach.
fn plant_without_terrain(machine: &MachineConfig, effects: EffectSet) -> Result<Plant> {
    let scenario =
        Scenario::default_bench().map_err(|e| DiscrepancyError::Invalid(format!("bench: {e}")))?;
    let mut plant = Plant::new(machine, &scenario, effects)
        .map_err(|e| DiscrepancyError::Machine(format!("simulator: {e}")))?;
    for h in plant.world.terrain.heights_mut() {
        *h -= NO_TERRAIN_DROP_M;
    }
    Ok(plant)
}

/// Sets the plant's actuators to the measured state of `s` (readings less the sensor effects the
/// plant has). `false` when the angles are outside the linkage.
fn set_measured_state(plant: &mut Plant, s: &Sample) -> bool {
    let fx = *plant.effects();
    let p_off = fx.get(Effect::PressureSensorOffset);
    let q_off = fx.get(Effect::ResolverOffset);
    let q = JointAngles {
        boom_rad: s.angles_rad[0] - q_off,
        stick_rad: s.angles_rad[1] - q_off,
        bucket_rad: s.angles_rad[2] - q_off,
    };
    let Ok(x) = plant.linkage().extensions(&q) else {
        return false;
    };
    let Some(v) = measured_velocities(plant, s) else {
        return false;
    };
    let a = &mut plant.hydraulics.actuators;
    for (i, cylinder) in a.iter_mut().take(3).enumerate() {
        cylinder.position = x[i];
        cylinder.velocity = v[i];
        cylinder.head_pa = (s.head_pa[i] - p_off).max(0.0);
        cylinder.rod_pa = (s.rod_pa[i] - p_off).max(0.0);
    }
    a[3].position = s.swing_rad;
    a[3].velocity = s.swing_rate_rad_per_s;
    plant.hydraulics.pump_pa = s.pump_pa.map(|p| (p - p_off).max(0.0));
    true
}

/// One control period of the plant on the commands of sample `s`.
fn step_period(plant: &mut Plant, s: &Sample) {
    let steps = (crate::PERIOD_S / PHYSICS_DT_S).round() as usize;
    let u = [
        s.command[0],
        s.command[1],
        s.command[2],
        s.swing_command,
        0.0,
        0.0,
    ];
    for _ in 0..steps {
        plant.step(u);
    }
}

/// The measured cylinder velocities of `s` (resolver rates times the moment arms at the measured
/// angles less the plant's resolver offset), m/s; `None` outside the linkage.
fn measured_velocities(plant: &Plant, s: &Sample) -> Option<[f64; 3]> {
    let q_off = plant.effects().get(Effect::ResolverOffset);
    let q = JointAngles {
        boom_rad: s.angles_rad[0] - q_off,
        stick_rad: s.angles_rad[1] - q_off,
        bucket_rad: s.angles_rad[2] - q_off,
    };
    let x = plant.linkage().extensions(&q).ok()?;
    let link = plant.linkage().state(x).ok()?;
    Some([0, 1, 2].map(|i| s.rates_rad_per_s[i] * link.arms[i]))
}

/// The plant's readings (sensor effects added, no noise) less the measured ones, per signal;
/// `None` where the measured angles are outside the linkage.
fn errors(plant: &Plant, s: &Sample) -> Option<[f64; 11]> {
    let t = plant.sensed_truth();
    let p_off = plant.effects().get(Effect::PressureSensorOffset);
    let v = measured_velocities(plant, s)?;
    let mut e = [0.0; 11];
    for i in 0..3 {
        e[i] = plant.hydraulics.actuators[i].velocity - v[i];
        e[5 + 2 * i] = t.head_pa[i] + p_off - s.head_pa[i];
        e[6 + 2 * i] = t.rod_pa[i] + p_off - s.rod_pa[i];
    }
    for i in 0..2 {
        e[3 + i] = t.pump_pa[i] + p_off - s.pump_pa[i];
    }
    Some(e)
}

/// The gap between the simulator of `machine` with `effects` and the measured `records` (module
/// docs).
///
/// # Errors
/// The simulator cannot be built of the machine; no sample could be re-run.
pub fn simulator_gap(
    records: &[&PreparedRecord],
    machine: &MachineConfig,
    effects: EffectSet,
) -> Result<SimulatorGap> {
    let base = plant_without_terrain(machine, effects)?;
    let mut sse = [0.0; 11];
    let (mut samples, mut windows) = (0usize, 0usize);
    for rec in records {
        let s = &rec.samples;
        let mut plant = base.clone();
        // The sample up to which the plant's spools have followed the commands.
        let mut in_step_until = 0usize;
        // Samples with the spool state known: no gap in the record in the warm-up before them.
        let warm = warmed_up(s);
        let mut k = WARMUP_SAMPLES + COMMAND_LAG_SAMPLES;
        while k + 1 < s.len() {
            if !free_air(&s[k]) || !warm[k] {
                k += 1;
                continue;
            }
            if in_step_until != k {
                for w in k - WARMUP_SAMPLES..k {
                    set_measured_state(&mut plant, &s[w]);
                    step_period(&mut plant, &s[w - COMMAND_LAG_SAMPLES]);
                }
            }
            if !set_measured_state(&mut plant, &s[k]) {
                in_step_until = 0;
                k += 1;
                continue;
            }
            windows += 1;
            let mut j = k;
            while j + 1 < s.len() && j < k + WINDOW_SAMPLES && free_air(&s[j + 1]) && warm[j + 1] {
                step_period(&mut plant, &s[j - COMMAND_LAG_SAMPLES]);
                if let Some(e) = errors(&plant, &s[j + 1])
                    && e.iter().all(|v| v.is_finite())
                {
                    for (acc, v) in sse.iter_mut().zip(e) {
                        *acc += v * v;
                    }
                    samples += 1;
                }
                j += 1;
            }
            in_step_until = j;
            k = j.max(k + 1);
        }
    }
    if samples == 0 {
        return Err(DiscrepancyError::NotEnoughData(
            "no held-out sample with the empty bucket in free air to re-run the simulator on"
                .into(),
        ));
    }
    let n = samples as f64;
    let mut signals = BTreeMap::new();
    let mut groups = BTreeMap::new();
    for (g, (group, _)) in GAP_GROUPS.iter().enumerate() {
        let members: Vec<usize> = (0..SIGNALS.len()).filter(|&i| SIGNALS[i].1 == g).collect();
        let mean_sq = members.iter().map(|&i| sse[i]).sum::<f64>() / (n * members.len() as f64);
        groups.insert((*group).to_string(), mean_sq.sqrt());
    }
    for (i, (name, _)) in SIGNALS.iter().enumerate() {
        signals.insert((*name).to_string(), (sse[i] / n).sqrt());
    }
    Ok(SimulatorGap {
        groups,
        signals,
        samples,
        windows,
    })
}

/// `report.json`'s `twin`: the profile written and the gap before and after.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TwinReport {
    /// The machine file written (in the output folder).
    pub machine_file: String,
    /// The effects file written.
    pub effects_file: String,
    /// The named parameters written into the machine file.
    pub parameters: Vec<ProfileValue>,
    /// The named effects.
    pub effects: Vec<ProfileValue>,
    /// The `demo` options that run the twin.
    pub demo_options: String,
    /// Named effects written at the end of the simulator's range ([`TwinProfile::clamped`]).
    pub clamped: Vec<String>,
    /// The simulator's gap to the held-out digs with the nominal plant (the machine file, no
    /// effect).
    pub gap_before: SimulatorGap,
    /// The same with the twin's plant.
    pub gap_after: SimulatorGap,
    /// `gap_after / gap_before` per group.
    pub ratio: BTreeMap<String, f64>,
    /// Wall time of the re-runs, s.
    pub wall_s: f64,
}

impl TwinReport {
    /// Per group ([`GAP_GROUPS`]): name, unit, gap before, after, and their ratio (NaN where
    /// missing).
    pub fn rows(&self) -> Vec<(&'static str, &'static str, f64, f64, f64)> {
        let get = |m: &BTreeMap<String, f64>, g: &str| m.get(g).copied().unwrap_or(f64::NAN);
        GAP_GROUPS
            .iter()
            .map(|&(g, unit)| {
                (
                    g,
                    unit,
                    get(&self.gap_before.groups, g),
                    get(&self.gap_after.groups, g),
                    get(&self.ratio, g),
                )
            })
            .collect()
    }
}

/// The twin of an analysis on the machine file `machine_text`, re-run on the held-out `records`.
///
/// # Errors
/// As [`TwinProfile::of`] and [`simulator_gap`].
pub fn update_twin(
    machine_text: &str,
    r: &AnalysisResult,
    records: &[&PreparedRecord],
) -> Result<(TwinProfile, TwinReport)> {
    let t = std::time::Instant::now();
    let profile = TwinProfile::of(machine_text, r)?;
    let nominal = MachineConfig::from_toml_str_named(machine_text, "machine file")
        .map_err(|e| DiscrepancyError::Machine(e.to_string()))?;
    let gap_before = simulator_gap(records, &nominal, EffectSet::nominal())?;
    let gap_after = if profile.parameters.is_empty() && profile.effects.is_empty() {
        gap_before.clone()
    } else {
        simulator_gap(records, &profile.machine()?, profile.effect_set()?)?
    };
    let ratio = gap_before
        .groups
        .iter()
        .map(|(g, b)| {
            let a = gap_after.groups.get(g).copied().unwrap_or(f64::NAN);
            (g.clone(), if *b > 0.0 { a / b } else { 1.0 })
        })
        .collect();
    let report = TwinReport {
        machine_file: "twin/machine.toml".into(),
        effects_file: "twin/effects.toml".into(),
        parameters: profile.parameters.clone(),
        effects: profile.effects.clone(),
        demo_options: profile.demo_options("twin/machine.toml"),
        clamped: profile.clamped.clone(),
        gap_before,
        gap_after,
        ratio,
        wall_s: t.elapsed().as_secs_f64(),
    };
    Ok((profile, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::NamedEffect;
    use planner::machine::DEFAULT_MACHINE_TOML;

    /// The written file loads, has the fitted value at the key, and is otherwise the nominal file
    /// line for line (comments included) and value for value.
    /// A named effect the simulator cannot hide at its value (less flow sharing than the nominal
    /// model's calibration: a negative change) is written at the end of its range and said so;
    /// one within the range is written as named.
    #[test]
    fn an_effect_outside_the_simulators_range_is_written_at_its_end() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let named = |name: &str, magnitude: f64| NamedEffect {
            name: name.to_string(),
            kind: "effect",
            magnitude,
            uncertainty: 1e-3,
            unit: "",
            description: String::new(),
            heldout_delta_bic: 100.0,
            fitted_jointly_with: None,
        };
        let result = AnalysisResult {
            named_effects: vec![named("flow_sharing", -0.037), named("hydraulic_lag", 0.1)],
            ambiguous: Vec::new(),
            augmentation: crate::Augmentation::nominal(),
            params,
            rounds: Vec::new(),
            rms: Vec::new(),
            localisation: Vec::new(),
            train_digs: Vec::new(),
            test_digs: Vec::new(),
            train_samples: Vec::new(),
            sigma: Vec::new(),
            kappa: Vec::new(),
        };
        let profile = TwinProfile::of(DEFAULT_MACHINE_TOML, &result).unwrap();
        let value = |n: &str| profile.effects.iter().find(|e| e.name == n).unwrap().value;
        assert_eq!(value("flow_sharing"), 0.0);
        assert_eq!(value("hydraulic_lag"), 0.1);
        assert_eq!(profile.clamped.len(), 1, "{:?}", profile.clamped);
        assert!(profile.clamped[0].starts_with("flow_sharing"));
        assert!(profile.effect_set().is_ok());
    }

    #[test]
    fn a_written_machine_file_has_the_fitted_value_and_nothing_else_changed() {
        let key = "hydraulics.relief_pressure_pa";
        let text = set_machine_value(DEFAULT_MACHINE_TOML, key, 27.5e6).unwrap();
        let written = MachineConfig::from_toml_str(&text).unwrap();
        let nominal = MachineConfig::default_machine().unwrap();
        assert_eq!(written.hydraulics.relief_pressure_pa, 27.5e6);
        let mut back = written.clone();
        back.hydraulics.relief_pressure_pa = nominal.hydraulics.relief_pressure_pa;
        assert_eq!(back, nominal, "only the key changed");
        let changed: Vec<(&str, &str)> = DEFAULT_MACHINE_TOML
            .lines()
            .zip(text.lines())
            .filter(|(a, b)| a != b)
            .collect();
        assert_eq!(changed.len(), 1, "{changed:?}");
        assert!(changed[0].1.trim_start().starts_with("relief_pressure_pa"));
        assert_eq!(DEFAULT_MACHINE_TOML.lines().count(), text.lines().count());
        // A key in a nested table, an integer-valued field, and the errors.
        let bore =
            set_machine_value(DEFAULT_MACHINE_TOML, "cylinders.boom.bore_m", 0.1505).unwrap();
        assert_eq!(
            MachineConfig::from_toml_str(&bore)
                .unwrap()
                .cylinders
                .boom
                .bore_m,
            0.1505
        );
        for (bad, value) in [
            ("hydraulics.no_such_field", 1.0),
            ("no_table.x", 1.0),
            (key, f64::NAN),
        ] {
            let e = set_machine_value(DEFAULT_MACHINE_TOML, bad, value).unwrap_err();
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    /// The nominal plant re-run on its own clean motion has a small gap; a plant with a 30 %
    /// pump saturation re-run on the same measured states differs from it.
    #[test]
    fn the_re_run_follows_the_plant_it_is_given() {
        let machine = MachineConfig::default_machine().unwrap();
        let mut plant = plant_without_terrain(&machine, EffectSet::nominal()).unwrap();
        // A "measured" record of the nominal plant itself: boom up and stick out, swing still.
        let mut samples = Vec::new();
        for k in 0..400 {
            let u = if k < 100 { 0.0 } else { 0.6 };
            let t = plant.sensed_truth();
            samples.push(Sample {
                time_s: k as f64 * crate::PERIOD_S,
                command: [u, -u, 0.0],
                angles_rad: [t.angles_rad[0], t.angles_rad[1], t.angles_rad[2]],
                rates_rad_per_s: [
                    t.rates_rad_per_s[0],
                    t.rates_rad_per_s[1],
                    t.rates_rad_per_s[2],
                ],
                swing_rad: t.angles_rad[3],
                head_pa: t.head_pa,
                rod_pa: t.rod_pa,
                pump_pa: t.pump_pa,
                ..Sample::default()
            });
            // The plant acts on a command one control period late, as the gateway does.
            let k = samples.len() - 1;
            step_period(&mut plant, &samples[k.saturating_sub(COMMAND_LAG_SAMPLES)]);
        }
        let rec = crate::DigRecord {
            index: 0,
            samples,
            section: None,
            lanes: Vec::new(),
        };
        let prepared = PreparedRecord::new(
            &rec,
            &machine,
            &crate::AugmentedModel::nominal().unwrap().params,
        )
        .unwrap();
        let own = simulator_gap(&[&prepared], &machine, EffectSet::nominal()).unwrap();
        let mut sat = EffectSet::nominal();
        sat.set_by_name("pump_saturation", 0.3).unwrap();
        let other = simulator_gap(&[&prepared], &machine, sat).unwrap();
        assert!(own.samples > 300 && own.windows >= 7, "{own:?}");
        let (a, b) = (
            own.groups["cylinder_velocity"],
            other.groups["cylinder_velocity"],
        );
        assert!(b > 3.0 * a && b > 1e-3, "own {a:.2e}, saturated {b:.2e}");
    }
}
