//! The dig model's settings (`config/dig_model.toml`): the soil model, the force factor and the
//! limits, with the shipped files embedded.

use super::{DigModelError, MAX_DIG_TIME_S, Result};
use crate::autodig::AutodigConfig;
use crate::soil::{BearingParams, EmpiricalSoilModel, SoilProperties};
use serde::{Deserialize, Serialize};

/// The shipped dig-model settings (`config/dig_model.toml`): soil Psi, force factor, limits.
pub const DEFAULT_DIG_MODEL_TOML: &str = include_str!("../../../config/dig_model.toml");
/// The shipped actuator networks (`config/nominal_actuator.json`), trained on simulator traces by
/// `excavator-ctl model train`.
pub const NOMINAL_ACTUATOR_JSON: &str = include_str!("../../../config/nominal_actuator.json");

/// The soil-tool model (thesis 4.3.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SoilModel {
    /// The modified FEE with soil properties `Psi` (Eqs. 14-18).
    Analytical(SoilProperties),
    /// The empirical model, linear in `Gamma` (Eq. 21).
    Empirical(EmpiricalSoilModel),
}

impl From<crate::estimate::FittedSoilModel> for SoilModel {
    fn from(m: crate::estimate::FittedSoilModel) -> Self {
        match m {
            crate::estimate::FittedSoilModel::Empirical(e) => SoilModel::Empirical(e),
            crate::estimate::FittedSoilModel::Analytical { properties, .. } => {
                SoilModel::Analytical(properties)
            }
        }
    }
}

/// Dig-model settings (`config/dig_model.toml`).
#[derive(Debug, Clone, PartialEq)]
pub struct DigModelConfig {
    /// The soil model.
    pub soil: SoilModel,
    /// Multiplies the soil force (thesis Table 2: 1, 2, 3). Must be finite and >= 0.
    pub force_factor: f64,
    /// A dig that has not ended by then ends with [`DigEnd::TimeLimit`](super::DigEnd::TimeLimit), s.
    pub max_time_s: f64,
    /// Floor penetration: tip below the floor elevation minus this, m.
    pub floor_tolerance_m: f64,
    /// Autodig settings (relief pressures and bucket capacity are taken from the machine).
    pub autodig: AutodigConfig,
    /// Bearing resistance of the edge and the bucket's back pushed into the soil (with the analytical
    /// soil model; the empirical model's fit contains whatever the soil did).
    pub bearing: BearingParams,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SoilFile {
    density_kg_per_m3: f64,
    failure_angle_deg: f64,
    friction_angle_deg: f64,
    tool_friction_angle_deg: f64,
    cohesion_pa: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ConfigFile {
    force_factor: f64,
    max_time_s: f64,
    floor_tolerance_m: f64,
    soil: SoilFile,
    #[serde(default)]
    autodig: AutodigConfig,
    #[serde(default)]
    bearing: BearingParams,
}

impl DigModelConfig {
    /// Parses and validates the TOML of `config/dig_model.toml`.
    ///
    /// # Errors
    /// [`DigModelError::Config`] naming the problem.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let f: ConfigFile = toml::from_str(text).map_err(|e| DigModelError::Config {
            field: "dig_model.toml",
            reason: e.to_string(),
        })?;
        let s = f.soil;
        let cfg = Self {
            soil: SoilModel::Analytical(SoilProperties {
                density_kg_per_m3: s.density_kg_per_m3,
                failure_angle_rad: s.failure_angle_deg.to_radians(),
                friction_angle_rad: s.friction_angle_deg.to_radians(),
                tool_friction_angle_rad: s.tool_friction_angle_deg.to_radians(),
                cohesion_pa: s.cohesion_pa,
            }),
            force_factor: f.force_factor,
            max_time_s: f.max_time_s,
            floor_tolerance_m: f.floor_tolerance_m,
            autodig: f.autodig,
            bearing: f.bearing,
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// The shipped settings ([`DEFAULT_DIG_MODEL_TOML`]).
    ///
    /// # Errors
    /// As [`Self::from_toml_str`] (the shipped file is tested).
    pub fn nominal() -> Result<Self> {
        Self::from_toml_str(DEFAULT_DIG_MODEL_TOML)
    }

    /// Checks ranges and finiteness.
    ///
    /// # Errors
    /// [`DigModelError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |field, reason: &str| {
            Err(DigModelError::Config {
                field,
                reason: reason.to_owned(),
            })
        };
        if !(self.force_factor.is_finite() && self.force_factor >= 0.0) {
            return bad("force_factor", "must be finite and >= 0");
        }
        if !(self.max_time_s.is_finite()
            && self.max_time_s > 0.0
            && self.max_time_s <= MAX_DIG_TIME_S)
        {
            return bad("max_time_s", "must be in (0, 600] s");
        }
        if !(self.floor_tolerance_m.is_finite() && self.floor_tolerance_m >= 0.0) {
            return bad("floor_tolerance_m", "must be finite and >= 0");
        }
        self.bearing.validate().map_err(|e| DigModelError::Config {
            field: "bearing",
            reason: e.to_string(),
        })?;
        match &self.soil {
            SoilModel::Analytical(p) => p.validate().map_err(|e| DigModelError::Config {
                field: "soil",
                reason: e.to_string(),
            })?,
            SoilModel::Empirical(m) => {
                if m.fx
                    .iter()
                    .chain(&m.fz)
                    .chain(&m.my)
                    .any(|c| !c.is_finite())
                {
                    return bad("soil", "empirical coefficients must be finite");
                }
            }
        }
        self.autodig.validate().map_err(|e| DigModelError::Config {
            field: "autodig",
            reason: e.to_string(),
        })
    }
}
