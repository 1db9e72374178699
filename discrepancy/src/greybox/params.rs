//! The grey-box model's parameters: the nominal hydraulic and soil constants
//! ([`GreyBoxParams`], `config/nominal_greybox.json`) and the magnitudes of the candidate effects
//! added to them ([`Augmentation`]).

use serde::{Deserialize, Serialize};

use crate::effects::{Candidate, N_CANDIDATES};
use crate::{DiscrepancyError, Result};
use planner::machine::MachineConfig;
use planner::soil::{BearingParams, SoilProperties};

/// The nominal grey-box parameters: "the nominal model the project ships" (`config/nominal_greybox.json`).
/// Geometry and masses come from the machine file; these are the hydraulic and soil constants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GreyBoxParams {
    /// Link masses `[boom, stick, bucket]` (the machine file's `masses.*.mass_kg`), kg: the
    /// replay's gravity forces are the prepared records' (their machine's masses) plus the
    /// difference times their derivative per kg (Eq. A4, linear in each link's mass). `None` in a
    /// model file written before it: the records' own masses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_mass_kg: Option<[f64; 3]>,
    /// Head areas `[boom, stick, bucket]` (all cylinders of a joint together), m^2.
    pub head_area_m2: [f64; 3],
    /// Rod (annulus) areas, m^2.
    pub rod_area_m2: [f64; 3],
    /// Tank (return) pressure, Pa.
    pub tank_pa: f64,
    /// Meter-in orifice constant at full spool, `Cd A sqrt(2/rho)` (Eq. 1), m^3/(s sqrt(Pa)).
    pub meter_in_k: [f64; 3],
    /// Meter-out orifice constant at full spool, m^3/(s sqrt(Pa)).
    pub meter_out_k: [f64; 3],
    /// Open-centre bypass constant of one valve at neutral, m^3/(s sqrt(Pa)).
    pub bypass_k: f64,
    /// Below this pressure drop the orifices are laminar (linear), Pa.
    pub laminar_dp_pa: f64,
    /// Spool overlap: fraction of the stroke before the metering orifices open.
    pub overlap: f64,
    /// Spool fraction at which the bypass is closed.
    pub bypass_close: f64,
    /// Boom command where the crossover from pump 2 starts to open.
    pub crossover_start: f64,
    /// Boom command where it is fully open.
    pub crossover_full: f64,
    /// Crossover orifice constant, m^3/(s sqrt(Pa)).
    pub crossover_k: f64,
    /// Maximum flow of each pump, m^3/s.
    pub pump_max_flow_m3_per_s: f64,
    /// Power of each pump before it destrokes, W.
    pub pump_power_w: f64,
    /// Main relief pressure, Pa.
    pub relief_pa: f64,
    /// Pressure over the relief setting at which it passes the full pump flow, Pa.
    pub relief_override_pa: f64,
    /// Swing motor displacement per swing radian, m^3/rad.
    pub swing_displacement_m3_per_rad: f64,
    /// Fixed command-to-spool delay, s.
    pub transport_delay_s: f64,
    /// Spool first-order lag, s.
    pub lag_time_constant_s: f64,
    /// Viscous damping of the seals of each cylinder, N s/m.
    pub damping_n_s_per_m: f64,
    /// Inertia of cylinders, pins and oil reflected to each joint, kg m^2.
    pub inertia_floor_kg_m2: [f64; 3],
    /// Nominal soil (FEE `Psi`).
    pub soil: SoilProperties,
    /// Multiplies the FEE force (calibrated on nominal digs).
    pub soil_force_factor: f64,
    /// Bearing resistance of an edge or back pushed into the soil (the planner's moving-bucket soil
    /// model, [`planner::soil::MovingBucketSoil`]).
    #[serde(default)]
    pub bearing: BearingParams,
    /// Effective bulk modulus of oil and hoses (Eq. 2 `beta`), Pa.
    #[serde(default = "default_bulk_modulus_pa")]
    pub bulk_modulus_pa: f64,
    /// Oil volume of a chamber at its stroke end (hoses, valve ports), m^3.
    #[serde(default = "default_dead_volume_m3")]
    pub dead_volume_m3: f64,
    /// The Eq. 2 chamber balance in the velocity relation: oil compression at the measured pressure
    /// rates, and no meter-in bound on a chamber below tank pressure (anti-cavitation make-up).
    #[serde(default)]
    pub chamber_balance: bool,
    /// Cross-piston leakage of the nominal model, m^3/(s Pa) (calibrated on effect-free sessions;
    /// the `internal_leakage` candidate adds to it).
    #[serde(default)]
    pub internal_leakage_m3_per_s_pa: f64,

    /// The spill of a full bucket on the terrain in the soil relation: what the edge cuts beyond the
    /// capacity piles up around the edge at [`Self::spill_repose_rad`], and out of the soil the
    /// bucket holds less as its opening tips down ([`crate::soil_replay::CutSection::spill`]). Off: the
    /// spill leaves the terrain untouched and the bucket holds the cut volume up to its capacity.
    #[serde(default)]
    pub spill_pile: bool,
    /// Angle of repose of the soil a full bucket spills at its edge, rad.
    #[serde(default = "default_spill_repose_rad")]
    pub spill_repose_rad: f64,
}

fn default_spill_repose_rad() -> f64 {
    37f64.to_radians()
}

fn default_bulk_modulus_pa() -> f64 {
    1.2e9
}

fn default_dead_volume_m3() -> f64 {
    2.0e-3
}

impl GreyBoxParams {
    /// Physical first guesses from a machine file (Eq. 1 constants from its valve area and discharge
    /// coefficient; the boom section passes two cylinders' flow, so 1.3 times the area; meter-out
    /// areas 1.6 times the meter-in ones, a usual valve-catalogue ratio), the soil of the default
    /// bench (`config/bench_extended.toml`, the ground the planned sessions dig; a test ties the two).
    /// [`crate::AugmentedModel::nominal`] holds these after calibration on nominal traces.
    pub fn from_machine(cfg: &MachineConfig) -> Self {
        let h = &cfg.hydraulics;
        let cyl = [
            &cfg.cylinders.boom,
            &cfg.cylinders.stick,
            &cfg.cylinders.bucket,
        ];
        let k = h.valve_discharge_coefficient * h.valve_max_area_m2;
        let pumps = f64::from(h.pump_count.max(1));
        Self {
            link_mass_kg: Some(cfg.masses.mass_kg()),
            head_area_m2: cyl.map(|c| c.head_area_m2()),
            rod_area_m2: cyl.map(|c| c.rod_area_m2()),
            tank_pa: h.tank_pressure_pa,
            meter_in_k: [1.3 * k, k, k],
            meter_out_k: [1.6 * 1.3 * k, 1.6 * k, 1.6 * k],
            bypass_k: h.valve_discharge_coefficient * h.valve_bleed_area_m2 * 2f64.sqrt(),
            laminar_dp_pa: 5.0e4,
            overlap: 0.05,
            bypass_close: 0.75,
            crossover_start: h.crossover_command.clamp(0.05, 0.95),
            crossover_full: (h.crossover_command + 0.2).min(1.0),
            crossover_k: k,
            pump_max_flow_m3_per_s: h.pump_max_flow_m3_per_s,
            pump_power_w: h.max_engine_power_w / pumps,
            relief_pa: h.relief_pressure_pa,
            relief_override_pa: 1.0e6,
            swing_displacement_m3_per_rad: 3.1e-3,
            transport_delay_s: h.transport_delay_s,
            lag_time_constant_s: h.lag_time_constant_s,
            damping_n_s_per_m: 5.0e4,
            inertia_floor_kg_m2: [2000.0, 500.0, 100.0],
            soil: SoilProperties {
                density_kg_per_m3: 1700.0,
                failure_angle_rad: 30f64.to_radians(),
                friction_angle_rad: 35f64.to_radians(),
                tool_friction_angle_rad: 20f64.to_radians(),
                cohesion_pa: 5000.0,
            },
            soil_force_factor: 1.0,
            bearing: BearingParams::default(),
            bulk_modulus_pa: h.bulk_modulus_pa,
            dead_volume_m3: default_dead_volume_m3(),
            internal_leakage_m3_per_s_pa: 0.0,
            chamber_balance: false,
            spill_pile: false,
            spill_repose_rad: default_spill_repose_rad(),
        }
    }

    /// Checks that every parameter is finite and physically meaningful.
    ///
    /// # Errors
    /// [`DiscrepancyError::Invalid`] naming the first bad parameter.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("head_area_m2", self.head_area_m2.iter().all(|v| *v > 0.0)),
            ("rod_area_m2", self.rod_area_m2.iter().all(|v| *v > 0.0)),
            (
                "link_mass_kg",
                self.link_mass_kg
                    .is_none_or(|m| m.iter().all(|v| v.is_finite() && *v > 0.0)),
            ),
            ("meter_in_k", self.meter_in_k.iter().all(|v| *v > 0.0)),
            ("meter_out_k", self.meter_out_k.iter().all(|v| *v > 0.0)),
            ("bypass_k", self.bypass_k > 0.0),
            ("laminar_dp_pa", self.laminar_dp_pa > 0.0),
            ("pump_max_flow_m3_per_s", self.pump_max_flow_m3_per_s > 0.0),
            ("pump_power_w", self.pump_power_w > 0.0),
            ("relief_pa", self.relief_pa > self.tank_pa),
            ("relief_override_pa", self.relief_override_pa > 0.0),
            ("lag_time_constant_s", self.lag_time_constant_s > 0.0),
            ("transport_delay_s", self.transport_delay_s >= 0.0),
            ("overlap", (0.0..0.9).contains(&self.overlap)),
            (
                "bypass_close",
                self.bypass_close > 0.0 && self.bypass_close <= 1.0,
            ),
            ("crossover", self.crossover_full > self.crossover_start),
            ("soil_force_factor", self.soil_force_factor >= 0.0),
            ("damping_n_s_per_m", self.damping_n_s_per_m >= 0.0),
            ("bulk_modulus_pa", self.bulk_modulus_pa > 0.0),
            ("dead_volume_m3", self.dead_volume_m3 > 0.0),
            (
                "internal_leakage_m3_per_s_pa",
                self.internal_leakage_m3_per_s_pa >= 0.0,
            ),
            (
                "spill_repose_rad",
                self.spill_repose_rad > 0.0 && self.spill_repose_rad < 1.5,
            ),
        ];
        for (name, ok) in positive {
            if !ok {
                return Err(DiscrepancyError::Invalid(format!(
                    "grey-box parameter {name}"
                )));
            }
        }
        let all = self
            .head_area_m2
            .iter()
            .chain(&self.rod_area_m2)
            .chain(&self.meter_in_k)
            .chain(&self.meter_out_k)
            .chain(&self.inertia_floor_kg_m2)
            .chain(&[
                self.tank_pa,
                self.crossover_k,
                self.swing_displacement_m3_per_rad,
                self.soil.cohesion_pa,
                self.soil.density_kg_per_m3,
            ])
            .all(|v| v.is_finite());
        if !all {
            return Err(DiscrepancyError::Invalid(
                "grey-box parameters must be finite".into(),
            ));
        }
        self.bearing
            .validate()
            .map_err(|e| DiscrepancyError::Invalid(format!("grey-box bearing parameters: {e}")))?;
        Ok(())
    }
}

/// Magnitudes of the candidate effects added to the nominal model, indexed by
/// [`Candidate::index`], in the simulator's units. All zero is the nominal model.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Augmentation {
    /// Magnitude per candidate.
    pub values: [f64; N_CANDIDATES],
}

impl Augmentation {
    /// The nominal model.
    pub fn nominal() -> Self {
        Self::default()
    }

    /// Magnitude of one candidate.
    pub fn get(&self, c: Candidate) -> f64 {
        self.values[c.index()]
    }

    /// Sets one candidate's magnitude.
    pub fn set(&mut self, c: Candidate, value: f64) {
        self.values[c.index()] = value;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::AugmentedModel;
    use vcan_sim::scenario::{EXTENDED_BENCH_TOML, Scenario};

    /// The nominal soil is the bench material of the default bench, the ground the measured and the
    /// reference sessions are dug in, in the first guesses and in the shipped model alike.
    #[test]
    fn the_nominal_soil_is_the_default_benchs() {
        let bench =
            Scenario::from_toml_str_named(EXTENDED_BENCH_TOML, "config/bench_extended.toml")
                .expect("bundled bench")
                .soil;
        let machine = MachineConfig::default_machine().expect("bundled machine");
        let shipped = AugmentedModel::nominal()
            .expect("shipped model")
            .params
            .soil;
        for soil in [GreyBoxParams::from_machine(&machine).soil, shipped] {
            assert_eq!(soil.density_kg_per_m3, bench.density_kg_per_m3);
            assert_eq!(soil.cohesion_pa, bench.cohesion_pa);
            let deg = [
                soil.friction_angle_rad,
                soil.tool_friction_angle_rad,
                soil.failure_angle_rad,
            ]
            .map(f64::to_degrees);
            let want = [
                bench.friction_angle_deg,
                bench.tool_friction_angle_deg,
                bench.failure_angle_deg,
            ];
            for (got, want) in deg.iter().zip(want) {
                assert!((got - want).abs() < 1e-9, "{got} vs {want}");
            }
        }
    }
}
