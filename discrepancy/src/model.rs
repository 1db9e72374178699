//! The augmented model file the workflow writes and the planner loads: the grey-box parameters, the
//! named effects with their magnitudes, and a grey-box actuator implementing
//! [`ActuatorDynamics`] so the planner's [`DigModel`] predicts digs with the corrected model.

use serde::{Deserialize, Serialize};

use super::effects::Candidate;
use super::greybox::{Augmentation, GreyBoxParams, bypass_constant, steady_velocity};
use super::{DiscrepancyError, Result};
use planner::dig_model::{ActuatorDynamics, DigModel, DigModelError};

/// `format` of the model file.
pub const MODEL_FORMAT: &str = "excavator-greybox-model";
/// `version` of the model file.
pub const MODEL_VERSION: u32 = 1;
/// The nominal grey-box model the project ships (`config/nominal_greybox.json`).
pub const NOMINAL_MODEL_JSON: &str = include_str!("../../config/nominal_greybox.json");

/// One effect in the model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelEffect {
    /// The simulator's effect name.
    pub name: String,
    /// Magnitude in the simulator's unit.
    pub magnitude: f64,
    /// Standard uncertainty.
    pub uncertainty: f64,
}

/// The model file: grey-box parameters plus named effects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AugmentedModel {
    /// Always [`MODEL_FORMAT`].
    pub format: String,
    /// Always [`MODEL_VERSION`].
    pub version: u32,
    /// Where the model came from (free text).
    pub provenance: String,
    /// The nominal parameters.
    pub params: GreyBoxParams,
    /// The effects added to them (empty for the nominal model).
    pub effects: Vec<ModelEffect>,
    /// The command that calibrated it and the plant version of its data (`excavator-ctl
    /// calibrate`); absent in models an analysis writes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<planner::origin::ArtefactOrigin>,
}

impl AugmentedModel {
    /// The nominal model the project ships.
    ///
    /// # Errors
    /// Only if the compiled-in file is broken (a test checks it is not).
    pub fn nominal() -> Result<Self> {
        Self::from_json(NOMINAL_MODEL_JSON)
    }

    /// A model from its parameters and effects.
    pub fn new(params: GreyBoxParams, effects: Vec<ModelEffect>, provenance: String) -> Self {
        Self {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            provenance,
            params,
            effects,
            origin: None,
        }
    }

    /// The model with its origin recorded.
    #[must_use]
    pub fn with_origin(mut self, origin: planner::origin::ArtefactOrigin) -> Self {
        self.origin = Some(origin);
        self
    }

    /// Parses and checks a model file (format, version, parameters, effect names and ranges).
    ///
    /// # Errors
    /// [`DiscrepancyError::ModelFile`] or [`DiscrepancyError::Invalid`].
    pub fn from_json(text: &str) -> Result<Self> {
        let m: Self =
            serde_json::from_str(text).map_err(|e| DiscrepancyError::ModelFile(e.to_string()))?;
        if m.format != MODEL_FORMAT || m.version != MODEL_VERSION {
            return Err(DiscrepancyError::ModelFile(format!(
                "expected format {MODEL_FORMAT} version {MODEL_VERSION}, got {} {}",
                m.format, m.version
            )));
        }
        m.params.validate()?;
        m.augmentation()?;
        Ok(m)
    }

    /// The model as pretty JSON.
    ///
    /// # Errors
    /// Only if serialisation fails, which it cannot for these plain values.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| DiscrepancyError::ModelFile(e.to_string()))
    }

    /// The effects as an [`Augmentation`].
    ///
    /// # Errors
    /// [`DiscrepancyError::Invalid`] for an unknown name or a magnitude outside its range.
    pub fn augmentation(&self) -> Result<Augmentation> {
        let mut aug = Augmentation::nominal();
        for e in &self.effects {
            let c = Candidate::from_name(&e.name)
                .ok_or_else(|| DiscrepancyError::Invalid(format!("unknown effect {}", e.name)))?;
            let (lo, hi) = c.range();
            if !(e.magnitude.is_finite() && (lo..=hi).contains(&e.magnitude)) {
                return Err(DiscrepancyError::Invalid(format!(
                    "effect {} = {} outside [{lo}, {hi}]",
                    e.name, e.magnitude
                )));
            }
            aug.set(c, e.magnitude);
        }
        Ok(aug)
    }

    /// The grey-box actuator of this model.
    ///
    /// # Errors
    /// As [`Self::augmentation`].
    pub fn actuator(&self) -> Result<GreyBoxActuator> {
        GreyBoxActuator::new(self.params.clone(), self.augmentation()?)
    }

    /// The planner's dig model (default machine, `config/dig_model.toml`, built-in maps) with this
    /// model's actuator; the soil effects raise the dig model's FEE cohesion and density.
    ///
    /// # Errors
    /// As [`DigModel::nominal`], [`DigModel::with_actuator`], [`DigModel::set_soil`].
    pub fn dig_model(&self) -> Result<DigModel<GreyBoxActuator>> {
        let aug = self.augmentation()?;
        let mut model = DigModel::nominal()?.with_actuator(self.actuator()?)?;
        if let planner::dig_model::SoilModel::Analytical(mut psi) = model.config().soil {
            psi.cohesion_pa += aug.get(Candidate::SoilCohesion);
            psi.density_kg_per_m3 += aug.get(Candidate::SoilDensity);
            model.set_soil(planner::dig_model::SoilModel::Analytical(psi))?;
        }
        Ok(model)
    }
}

/// Longest delay line of the actuator state, control periods.
const MAX_DELAY_STEPS: usize = 64;
/// The dig model's step, s: the records' control period.
const DT_S: f64 = crate::PERIOD_S;

/// The grey-box actuator (steady-state Eqs. 1-3 behind the spool delay and lag) with its effects.
#[derive(Debug, Clone, PartialEq)]
pub struct GreyBoxActuator {
    params: GreyBoxParams,
    aug: Augmentation,
}

/// Per-dig state of [`GreyBoxActuator`]: the delay line of commands and the spool lags.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GreyBoxState {
    delay: [[f64; 3]; MAX_DELAY_STEPS],
    head: usize,
    spool1: [f64; 3],
    spool2: [f64; 3],
}

impl GreyBoxActuator {
    /// An actuator from parameters and an augmentation.
    ///
    /// # Errors
    /// [`DiscrepancyError::Invalid`] for bad parameters or a delay longer than the state holds.
    pub fn new(params: GreyBoxParams, aug: Augmentation) -> Result<Self> {
        params.validate()?;
        let delay = params.transport_delay_s + aug.get(Candidate::TransportDelay);
        if delay / DT_S >= (MAX_DELAY_STEPS - 1) as f64 {
            return Err(DiscrepancyError::Invalid(format!(
                "delay {delay} s too long"
            )));
        }
        Ok(Self { params, aug })
    }
}

impl ActuatorDynamics for GreyBoxActuator {
    type State = GreyBoxState;

    fn dt_s(&self) -> f64 {
        DT_S
    }

    fn initial_state(&self) -> planner::dig_model::Result<GreyBoxState> {
        Ok(GreyBoxState {
            delay: [[0.0; 3]; MAX_DELAY_STEPS],
            head: 0,
            spool1: [0.0; 3],
            spool2: [0.0; 3],
        })
    }

    fn step(
        &self,
        state: &mut GreyBoxState,
        command: [f64; 3],
        force_n: [f64; 3],
    ) -> planner::dig_model::Result<[f64; 3]> {
        if !command.iter().chain(&force_n).all(|v| v.is_finite()) {
            return Err(DigModelError::NonFinite {
                what: "grey-box actuator input",
            });
        }
        let p = &self.params;
        let a = &self.aug;
        let deadband = a.get(Candidate::ValveDeadband).max(0.0);
        let cmd = command.map(|u| {
            let u = u.clamp(-1.0, 1.0);
            u.signum() * (u.abs() - deadband).max(0.0)
        });
        state.head = (state.head + 1) % MAX_DELAY_STEPS;
        state.delay[state.head] = cmd;
        let delay_steps = (p.transport_delay_s + a.get(Candidate::TransportDelay).max(0.0)) / DT_S;
        let d0 = delay_steps.floor() as usize;
        let frac = delay_steps - d0 as f64;
        let at = |d: usize| state.delay[(state.head + MAX_DELAY_STEPS - d) % MAX_DELAY_STEPS];
        let (c0, c1) = (at(d0), at(d0 + 1));
        // Exact first-order responses over one period (the lag and the extra lag, Eq. 2's dynamics).
        let a1 = 1.0 - (-DT_S / p.lag_time_constant_s).exp();
        let extra = a.get(Candidate::HydraulicLag).max(0.0);
        let a2 = if extra > 0.0 {
            1.0 - (-DT_S / extra).exp()
        } else {
            1.0
        };
        for i in 0..3 {
            let target = c0[i] + frac * (c1[i] - c0[i]);
            state.spool1[i] += (target - state.spool1[i]) * a1;
            state.spool2[i] += (state.spool1[i] - state.spool2[i]) * a2;
        }
        let s = state.spool2;
        let q_max =
            p.pump_max_flow_m3_per_s * (1.0 - a.get(Candidate::PumpSaturation)).clamp(0.0, 1.0);
        let share =
            (1.0 - a.get(Candidate::FlowSharing).clamp(0.0, 1.0) * s[2].abs()).clamp(0.0, 1.0);
        let leak = p.internal_leakage_m3_per_s_pa + a.get(Candidate::InternalLeakage).max(0.0);
        // Pump 1 feeds boom and bucket in proportion to their spool openings; pump 2 the stick.
        let (ob, ok) = (s[0].abs(), s[2].abs());
        let split = if ob + ok > 0.0 { ob / (ob + ok) } else { 0.5 };
        let bypass1 = bypass_constant(p, [s[0], s[2]]);
        let bypass2 = bypass_constant(p, [s[1], 0.0]);
        let friction = |v: f64| -> f64 {
            a.get(Candidate::CoulombFriction).max(0.0) * v.signum()
                + (p.damping_n_s_per_m + a.get(Candidate::ViscousFriction).max(0.0)) * v
        };
        let mut v = [
            steady_velocity(
                p,
                0,
                s[0],
                share,
                force_n[0],
                q_max * split,
                bypass1 * split,
                leak,
            ),
            steady_velocity(p, 1, s[1], 1.0, force_n[1], q_max, bypass2, leak),
            steady_velocity(
                p,
                2,
                s[2],
                1.0,
                force_n[2],
                q_max * (1.0 - split),
                bypass1 * (1.0 - split),
                leak,
            ),
        ];
        // Friction as extra load (Eq. 3): one correction with the first speed's direction.
        for (i, vi) in v.iter_mut().enumerate() {
            if *vi != 0.0 {
                let flow = [q_max * split, q_max, q_max * (1.0 - split)][i];
                let bypass = [bypass1 * split, bypass2, bypass1 * (1.0 - split)][i];
                let scale = if i == 0 { share } else { 1.0 };
                *vi = steady_velocity(
                    p,
                    i,
                    s[i],
                    scale,
                    force_n[i] + friction(*vi),
                    flow,
                    bypass,
                    leak,
                );
            }
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_nominal_model_parses_and_round_trips() {
        let m = AugmentedModel::nominal().unwrap();
        // Its effects are those the calibration on healthy sessions named, each in its provenance.
        assert!(
            m.effects.iter().all(|e| m.provenance.contains(&e.name)),
            "{:?} against {}",
            m.effects,
            m.provenance
        );
        let back = AugmentedModel::from_json(&m.to_json().unwrap()).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn model_file_rejects_unknown_effects_and_bad_format() {
        let mut m = AugmentedModel::nominal().unwrap();
        m.effects.push(ModelEffect {
            name: "bogus".into(),
            magnitude: 1.0,
            uncertainty: 0.0,
        });
        assert!(AugmentedModel::from_json(&m.to_json().unwrap()).is_err());
        let mut m = AugmentedModel::nominal().unwrap();
        m.format = "other".into();
        assert!(AugmentedModel::from_json(&m.to_json().unwrap()).is_err());
    }

    #[test]
    fn deadband_stops_small_commands_and_the_dig_model_runs_with_the_actuator() {
        let mut m = AugmentedModel::nominal().unwrap();
        let act = m.actuator().unwrap();
        let mut st = act.initial_state().unwrap();
        let mut v = [0.0; 3];
        for _ in 0..100 {
            v = act
                .step(&mut st, [0.0, 0.15, 0.0], [0.0, 2.0e4, 0.0])
                .unwrap();
        }
        assert!(v[1] > 0.005, "a 15 % stick command moves it: {v:?}");
        m.effects.push(ModelEffect {
            name: "valve_deadband".into(),
            magnitude: 0.2,
            uncertainty: 0.01,
        });
        let act = m.actuator().unwrap();
        let mut st = act.initial_state().unwrap();
        for _ in 0..100 {
            v = act
                .step(&mut st, [0.0, 0.15, 0.0], [0.0, 2.0e4, 0.0])
                .unwrap();
        }
        assert_eq!(v[1], 0.0, "inside the dead band");
        assert!(act.step(&mut st, [f64::NAN, 0.0, 0.0], [0.0; 3]).is_err());
        let model = m.dig_model().unwrap();
        let start = planner::dig_model::DigStart::Pose(planner::kinematics::BucketPose {
            x_m: 7.5,
            z_m: 1.5,
            bucket_abs_rad: (-55f64).to_radians(),
        });
        let site = planner::dig_model::DigSite::new(
            planner::terrain::SectionProfile::from_fn(2.0, 12.0, 0.1, |_| 1.5).unwrap(),
            0.0,
        )
        .unwrap();
        let summary = model.evaluate(&start, &site).unwrap();
        assert!(
            summary.time_s > 0.5 && summary.energy_j.is_finite(),
            "{summary:?}"
        );
    }
}
