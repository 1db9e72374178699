//! The machine's own physical parameters as candidates (parameter drift): a bore, the valve
//! discharge coefficient, the relief or tank pressure, the pump flow, the engine power, the bulk
//! modulus, named by the machine file's key (`hydraulics.valve_discharge_coefficient`) with the
//! fitted value in that file's units, so an engineer can write it back.
//!
//! One source of truth: the candidates are derived from the machine file itself. Every numeric field
//! of the [`MachineConfig`] is scaled by 10 %; those that change the grey-box parameters
//! [`GreyBoxParams::from_machine`] derives from the file are candidates. A candidate's value is
//! applied to the model in use (calibrated, maybe augmented) as the relative change it makes to the
//! derived parameters: a discharge coefficient 0.85 times the file's scales every orifice constant of
//! the model by 0.85, whatever the calibration made of them.
//!
//! What is left to the effect library: the spool's delay and lag (the `transport_delay` and
//! `hydraulic_lag` effects add to them, and a parameter of the same action would tie with them).
//! The link masses are candidates through `GreyBoxParams::link_mass_kg`: the prepared records carry
//! each cylinder's gravity force per kg of each link (Eq. A4 is linear in the masses), and a link's
//! mass is fitted and scored on the cylinder forces ([`ParameterLibrary::groups_of`]). What is not a
//! candidate yet: the fields that act only through the prepared records otherwise (the links'
//! centres of gravity, the cylinders' force areas at the measured pressures), which would need the
//! records prepared again for every trial value.

use serde::Serialize;

use crate::greybox::{GreyBoxParams, SignalGroups};
use crate::{DiscrepancyError, Result};
use planner::machine::MachineConfig;

/// Grey-box fields whose change the effect library already fits (an effect of the same action):
/// a machine field that changes only these is left to the effects.
const COVERED_BY_EFFECTS: [&str; 3] = [
    "transport_delay_s",
    "lag_time_constant_s",
    "pump_max_flow_m3_per_s",
];

/// The relative step that decides whether a machine field moves the grey-box parameters.
const PROBE_FACTOR: f64 = 1.1;

/// The range of the fitted factor on a machine field (a bulk modulus half the file's, a relief
/// twice): what a machine's own dimensions, masses and settings can be off by.
pub const FACTOR_RANGE: (f64, f64) = (0.5, 2.0);

/// The range of the fitted factor on the return line's pressure (`hydraulics.tank_pressure_pa`):
/// a few tenths of a MPa set by the return filter and the cooler, which a loaded filter raises
/// several times over (a 1 MPa return line against a file's 0.3 MPa is 3.3 times; fitted within
/// `FACTOR_RANGE` it stopped at the bound, and a stick bore 25 % off was named for it at one seed).
pub const TANK_FACTOR_RANGE: (f64, f64) = (0.25, 5.0);

/// The factor range of a machine field (`TANK_FACTOR_RANGE` for the return line's pressure,
/// `FACTOR_RANGE` for every other).
#[must_use]
pub fn factor_range(key: &str) -> (f64, f64) {
    if key == "hydraulics.tank_pressure_pa" {
        TANK_FACTOR_RANGE
    } else {
        FACTOR_RANGE
    }
}

/// One machine-file field as a candidate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MachineParameter {
    /// Dotted key of the field (tables, then the field), as in the machine file.
    pub key: String,
    /// Its value in the machine file, in the file's units.
    pub nominal: f64,
    /// Unit of the value (from the field name's suffix, the file's convention).
    pub unit: &'static str,
}

/// The parameter candidates of a machine, and how a trial value changes the grey-box model.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterLibrary {
    /// The machine file as a TOML table.
    table: toml::Table,
    /// The grey-box parameters derived from the unchanged file.
    derived: serde_json::Value,
    /// The candidates.
    pub parameters: Vec<MachineParameter>,
}

impl ParameterLibrary {
    /// The candidates of a machine: every numeric field of its file that changes the grey-box
    /// parameters derived from it, except those only the effect library's timing effects change.
    ///
    /// # Errors
    /// [`DiscrepancyError::Machine`] when the machine does not serialise.
    pub fn derive(machine: &MachineConfig) -> Result<Self> {
        let text = toml::to_string(machine)
            .map_err(|e| DiscrepancyError::Machine(format!("machine file: {e}")))?;
        let table: toml::Table = toml::from_str(&text)
            .map_err(|e| DiscrepancyError::Machine(format!("machine file: {e}")))?;
        let derived = derived_json(machine)?;
        let mut library = Self {
            table,
            derived,
            parameters: Vec::new(),
        };
        let mut leaves = Vec::new();
        float_leaves(&library.table, "", &mut leaves);
        for (key, nominal) in leaves {
            if nominal == 0.0 {
                continue;
            }
            let Ok(changed) = library.derived_at(&key, nominal * PROBE_FACTOR) else {
                continue;
            };
            let mut fields = Vec::new();
            changed_fields(&library.derived, &changed, "", &mut fields);
            if fields
                .iter()
                .any(|f| !COVERED_BY_EFFECTS.contains(&f.as_str()))
            {
                library.parameters.push(MachineParameter {
                    unit: unit_of(&key),
                    key,
                    nominal,
                });
            }
        }
        Ok(library)
    }

    /// The candidate of a key.
    pub fn find(&self, key: &str) -> Option<usize> {
        self.parameters.iter().position(|p| p.key == key)
    }

    /// The grey-box parameters the machine file derives with `key` set to `value`.
    fn derived_at(&self, key: &str, value: f64) -> Result<serde_json::Value> {
        let mut table = self.table.clone();
        let mut node = &mut table;
        let parts: Vec<&str> = key.split('.').collect();
        let (field, tables) = parts
            .split_last()
            .ok_or_else(|| DiscrepancyError::Invalid("empty machine key".into()))?;
        for t in tables {
            node = node
                .get_mut(*t)
                .and_then(toml::Value::as_table_mut)
                .ok_or_else(|| DiscrepancyError::Invalid(format!("machine key {key}")))?;
        }
        node.insert((*field).to_string(), toml::Value::Float(value));
        let text = toml::to_string(&table)
            .map_err(|e| DiscrepancyError::Machine(format!("machine file: {e}")))?;
        let machine = MachineConfig::from_toml_str(&text)
            .map_err(|e| DiscrepancyError::Invalid(format!("{key} = {value}: {e}")))?;
        derived_json(&machine)
    }

    /// `params` with candidate `i` at `factor` times the file's value: every grey-box field the
    /// change moves is scaled by the ratio it makes to the derived one (or shifted by the
    /// difference where that is zero).
    ///
    /// # Errors
    /// [`DiscrepancyError::Invalid`] when the machine file is not valid at that value.
    pub fn apply(&self, params: &GreyBoxParams, i: usize, factor: f64) -> Result<GreyBoxParams> {
        let p = &self.parameters[i];
        let changed = self.derived_at(&p.key, p.nominal * factor)?;
        let mut current = serde_json::to_value(params)
            .map_err(|e| DiscrepancyError::Invalid(format!("grey-box parameters: {e}")))?;
        rescale(&mut current, &self.derived, &changed);
        let out: GreyBoxParams = serde_json::from_value(current)
            .map_err(|e| DiscrepancyError::Invalid(format!("grey-box parameters: {e}")))?;
        out.validate()?;
        Ok(out)
    }

    /// The signals the parameter candidate of machine-file `key` is fitted and scored on: a link's
    /// mass (`masses.*.mass_kg`) on the cylinder forces (its gravity, Eq. A4; the weighed payload,
    /// weighed through the same links, is left to the reference's bias check), every other on the
    /// velocity and pump-pressure relations (the replay takes the grey-box parameters there; the
    /// forces are prepared with the file's areas).
    pub fn groups_of(key: &str) -> SignalGroups {
        let mass = key.starts_with("masses.") && key.ends_with(".mass_kg");
        SignalGroups {
            hydraulic: !mass,
            pumps: !mass,
            force: mass,
            soil: false,
            stops: false,
            payload: false,
        }
    }
}

fn derived_json(machine: &MachineConfig) -> Result<serde_json::Value> {
    serde_json::to_value(GreyBoxParams::from_machine(machine))
        .map_err(|e| DiscrepancyError::Invalid(format!("grey-box parameters: {e}")))
}

/// Every float field of a TOML table, by dotted key.
fn float_leaves(table: &toml::Table, prefix: &str, out: &mut Vec<(String, f64)>) {
    for (k, v) in table {
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Float(x) if x.is_finite() => out.push((key, *x)),
            toml::Value::Table(t) => float_leaves(t, &key, out),
            _ => {}
        }
    }
}

/// Top-level grey-box fields whose values differ between `a` and `b`.
fn changed_fields(
    a: &serde_json::Value,
    b: &serde_json::Value,
    field: &str,
    out: &mut Vec<String>,
) {
    use serde_json::Value as V;
    match (a, b) {
        (V::Object(x), V::Object(y)) => {
            for (k, va) in x {
                if let Some(vb) = y.get(k) {
                    let f = if field.is_empty() { k.as_str() } else { field };
                    changed_fields(va, vb, f, out);
                }
            }
        }
        (V::Array(x), V::Array(y)) => {
            for (va, vb) in x.iter().zip(y) {
                changed_fields(va, vb, field, out);
            }
        }
        (V::Number(x), V::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap_or(0.0), y.as_f64().unwrap_or(0.0));
            if (x - y).abs() > 1e-12 * x.abs().max(y.abs()) && !out.iter().any(|o| o == field) {
                out.push(field.to_string());
            }
        }
        _ => {}
    }
}

/// Scales every number of `current` whose derived value changes from `from` to `to` by their ratio.
fn rescale(current: &mut serde_json::Value, from: &serde_json::Value, to: &serde_json::Value) {
    use serde_json::Value as V;
    match (current, from, to) {
        (V::Object(c), V::Object(f), V::Object(t)) => {
            for (k, vc) in c.iter_mut() {
                if let (Some(vf), Some(vt)) = (f.get(k), t.get(k)) {
                    rescale(vc, vf, vt);
                }
            }
        }
        (V::Array(c), V::Array(f), V::Array(t)) => {
            for ((vc, vf), vt) in c.iter_mut().zip(f).zip(t) {
                rescale(vc, vf, vt);
            }
        }
        (V::Number(c), V::Number(f), V::Number(t)) => {
            let (x, a, b) = (
                c.as_f64().unwrap_or(0.0),
                f.as_f64().unwrap_or(0.0),
                t.as_f64().unwrap_or(0.0),
            );
            if a == b {
                return;
            }
            let y = if a != 0.0 { x * b / a } else { x + b - a };
            if let Some(n) = serde_json::Number::from_f64(y) {
                *c = n;
            }
        }
        _ => {}
    }
}

/// The unit of a machine-file field from its name's suffix (the file's naming convention).
fn unit_of(key: &str) -> &'static str {
    const SUFFIXES: [(&str, &str); 9] = [
        ("_m3_per_s", "m^3/s"),
        ("_m_per_s", "m/s"),
        ("_m2", "m^2"),
        ("_m3", "m^3"),
        ("_pa", "Pa"),
        ("_kg", "kg"),
        ("_w", "W"),
        ("_deg", "deg"),
        ("_m", "m"),
    ];
    SUFFIXES
        .iter()
        .find(|(s, _)| key.ends_with(s))
        .map_or("1", |(_, u)| u)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The candidates come from the machine file: the discharge coefficient, a bore, the relief,
    /// the bulk modulus and the link masses are among them with the file's values; the spool's
    /// delay (an effect of the library), the links' centres of gravity (prepared into the records)
    /// and the link lengths (no grey-box parameter) are not. A link's mass acts on the cylinder
    /// forces, the others on the velocities and pump pressures.
    #[test]
    fn parameter_candidates_are_the_machine_fields_the_model_derives_from() {
        let machine = MachineConfig::default_machine().unwrap();
        let lib = ParameterLibrary::derive(&machine).unwrap();
        let keys: Vec<&str> = lib.parameters.iter().map(|p| p.key.as_str()).collect();
        let h = &machine.hydraulics;
        for (key, value, unit) in [
            (
                "hydraulics.valve_discharge_coefficient",
                h.valve_discharge_coefficient,
                "1",
            ),
            ("cylinders.boom.bore_m", machine.cylinders.boom.bore_m, "m"),
            ("hydraulics.relief_pressure_pa", h.relief_pressure_pa, "Pa"),
            ("hydraulics.bulk_modulus_pa", h.bulk_modulus_pa, "Pa"),
            ("masses.stick.mass_kg", machine.masses.stick.mass_kg, "kg"),
            ("masses.bucket.mass_kg", machine.masses.bucket.mass_kg, "kg"),
        ] {
            let p = &lib.parameters[lib.find(key).unwrap_or_else(|| panic!("{key}: {keys:?}"))];
            assert_eq!(p.nominal, value, "{key}");
            assert_eq!(p.unit, unit, "{key}");
        }
        for key in [
            "hydraulics.transport_delay_s",
            "hydraulics.pump_max_flow_m3_per_s",
            "masses.bucket.cog_distance_m",
            "links.boom_m",
        ] {
            assert!(lib.find(key).is_none(), "{key}: {keys:?}");
        }
        let mass = ParameterLibrary::groups_of("masses.stick.mass_kg");
        assert!(mass.force && !mass.hydraulic && !mass.pumps && !mass.payload);
        let bore = ParameterLibrary::groups_of("cylinders.boom.bore_m");
        assert!(!bore.force && bore.hydraulic && bore.pumps);
    }

    /// A trial value changes the model in use by the ratio it makes to the derived parameters:
    /// a discharge coefficient 0.85 times the file's scales the calibrated orifice constants by
    /// 0.85 and leaves the calibrated delay alone; a boom bore changes the boom's areas only.
    #[test]
    fn a_trial_value_rescales_the_calibrated_model() {
        let machine = MachineConfig::default_machine().unwrap();
        let lib = ParameterLibrary::derive(&machine).unwrap();
        let model = crate::AugmentedModel::nominal().unwrap().params;
        let cd = lib.find("hydraulics.valve_discharge_coefficient").unwrap();
        let p = lib.apply(&model, cd, 0.85).unwrap();
        for i in 0..3 {
            assert!((p.meter_in_k[i] / model.meter_in_k[i] - 0.85).abs() < 1e-9);
            assert!((p.meter_out_k[i] / model.meter_out_k[i] - 0.85).abs() < 1e-9);
        }
        assert!((p.bypass_k / model.bypass_k - 0.85).abs() < 1e-9);
        assert_eq!(p.transport_delay_s, model.transport_delay_s);
        assert_eq!(p.head_area_m2, model.head_area_m2);
        let bore = lib.find("cylinders.boom.bore_m").unwrap();
        let p = lib.apply(&model, bore, 1.075).unwrap();
        assert!((p.head_area_m2[0] / model.head_area_m2[0] - 1.075f64.powi(2)).abs() < 1e-9);
        assert_eq!(p.head_area_m2[1..], model.head_area_m2[1..]);
        assert_eq!(p.meter_in_k, model.meter_in_k);
    }
}
