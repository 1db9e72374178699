//! Plant changes outside the effect library, for the evaluation: one physical parameter of the
//! simulated machine (a field of the machine file) or of its ground (a field of the bench file)
//! scaled or set, as a real machine differs from its model (a bore, a mass, a relief setting, a
//! discharge coefficient, the oil's bulk modulus, the soil's friction angle). The analysis is told
//! nothing and reads the default machine file, so the change is a discrepancy no candidate of the
//! library is named after.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

/// Which file the changed field is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlantFile {
    /// The machine file (`config/machine.toml`).
    Machine,
    /// The bench scenario file (the strategy's default bench).
    Bench,
}

/// How the field changes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlantOp {
    /// Multiplied by this factor.
    Scale(f64),
    /// Set to this value.
    Set(f64),
}

/// One changed field: `machine:hydraulics.valve_discharge_coefficient*0.85`,
/// `bench:soil.friction_angle_deg=40`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlantChange {
    /// The file.
    pub file: PlantFile,
    /// Dotted key of the field (tables, then the field).
    pub key: String,
    /// The change.
    pub op: PlantOp,
}

impl fmt::Display for PlantChange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = match self.file {
            PlantFile::Machine => "machine",
            PlantFile::Bench => "bench",
        };
        match self.op {
            PlantOp::Scale(x) => write!(f, "{file}:{}*{x}", self.key),
            PlantOp::Set(x) => write!(f, "{file}:{}={x}", self.key),
        }
    }
}

impl FromStr for PlantChange {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let usage = || {
            format!(
                "plant change {s:?}: expected FILE:KEY*FACTOR or FILE:KEY=VALUE with FILE machine \
                 or bench (e.g. machine:cylinders.boom.bore_m*1.075)"
            )
        };
        let (file, rest) = s.split_once(':').ok_or_else(usage)?;
        let file = match file {
            "machine" => PlantFile::Machine,
            "bench" => PlantFile::Bench,
            _ => return Err(usage()),
        };
        let (key, op) = if let Some((k, v)) = rest.split_once('*') {
            (k, PlantOp::Scale(v.trim().parse().map_err(|_| usage())?))
        } else if let Some((k, v)) = rest.split_once('=') {
            (k, PlantOp::Set(v.trim().parse().map_err(|_| usage())?))
        } else {
            return Err(usage());
        };
        let value = match op {
            PlantOp::Scale(x) | PlantOp::Set(x) => x,
        };
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) || !value.is_finite() {
            return Err(usage());
        }
        Ok(Self {
            file,
            key: key.to_string(),
            op,
        })
    }
}

impl PlantChange {
    /// A name usable as a folder name.
    pub fn slug(&self) -> String {
        self.to_string()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    }

    /// `text` (a TOML file) with the field changed.
    ///
    /// # Errors
    /// The text does not parse, or the field is missing or not a number.
    pub fn apply(&self, text: &str) -> anyhow::Result<String> {
        let mut doc: toml::Table = toml::from_str(text)?;
        let parts: Vec<&str> = self.key.split('.').collect();
        let (field, tables) = parts
            .split_last()
            .ok_or_else(|| anyhow::anyhow!("empty key"))?;
        let mut table = &mut doc;
        for t in tables {
            table = table
                .get_mut(*t)
                .and_then(toml::Value::as_table_mut)
                .ok_or_else(|| anyhow::anyhow!("{self}: no table [{t}]"))?;
        }
        let old = match table.get(*field) {
            Some(toml::Value::Float(x)) => *x,
            Some(toml::Value::Integer(i)) => *i as f64,
            _ => anyhow::bail!("{self}: no number field {field}"),
        };
        let new = match self.op {
            PlantOp::Scale(x) => old * x,
            PlantOp::Set(x) => x,
        };
        table.insert((*field).to_string(), toml::Value::Float(new));
        Ok(toml::to_string(&doc)?)
    }
}

/// The plant changes of `eval --plant default`: the failure cases of an independent review (a
/// parameter of the machine or its ground 5-50 % off, none of them an effect of the library).
pub fn default_plant_changes() -> Vec<PlantChange> {
    [
        "machine:hydraulics.valve_discharge_coefficient*0.85",
        "machine:cylinders.boom.bore_m*1.075",
        "machine:hydraulics.bulk_modulus_pa*0.5",
        "machine:masses.stick.mass_kg*1.2",
        "machine:hydraulics.relief_pressure_pa=30e6",
        "machine:hydraulics.max_engine_power_w=80e3",
        "machine:hydraulics.tank_pressure_pa=1e6",
        "bench:soil.friction_angle_deg=40",
    ]
    .iter()
    .filter_map(|s| s.parse().ok())
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plant_change_parses_applies_and_says_what_is_wrong() {
        let c: PlantChange = "machine:cylinders.boom.bore_m*1.075".parse().unwrap();
        assert_eq!(c.to_string(), "machine:cylinders.boom.bore_m*1.075");
        let text = c.apply(planner::machine::DEFAULT_MACHINE_TOML).unwrap();
        let m = planner::machine::MachineConfig::from_toml_str_named(&text, "changed").unwrap();
        let base = planner::machine::MachineConfig::default_machine().unwrap();
        assert!((m.cylinders.boom.bore_m - 1.075 * base.cylinders.boom.bore_m).abs() < 1e-12);
        let set: PlantChange = "machine:hydraulics.relief_pressure_pa=30e6"
            .parse()
            .unwrap();
        let m = planner::machine::MachineConfig::from_toml_str_named(
            &set.apply(planner::machine::DEFAULT_MACHINE_TOML).unwrap(),
            "changed",
        )
        .unwrap();
        assert_eq!(m.hydraulics.relief_pressure_pa, 30e6);
        for bad in [
            "boom*2",
            "engine:x=1",
            "machine:x",
            "machine:a..b=1",
            "machine:x=nan",
        ] {
            assert!(bad.parse::<PlantChange>().is_err(), "{bad}");
        }
        let missing: PlantChange = "machine:hydraulics.no_such_field*2".parse().unwrap();
        let e = missing
            .apply(planner::machine::DEFAULT_MACHINE_TOML)
            .unwrap_err();
        assert!(e.to_string().contains("no number field"), "{e}");
        assert_eq!(default_plant_changes().len(), 8);
    }
}
