//! The actuator model file (`actuator.json`): format name and version, the networks' weights and
//! normalisation, and the training summary.

use super::network::{
    Activation, COUPLED_INPUTS, FORCE_RATE_INPUTS, IN_VELOCITY, MAX_INPUTS, Network, partner,
    thesis_inputs, third,
};
use super::predict::{ActuatorModel, TrainingSummary, lag_gain};
use super::{ActuatorError, MAX_DELAY_STEPS, MAX_HIDDEN};
use crate::kinematics::Joint;
use serde::{Deserialize, Serialize};

/// The `format` field of an actuator model file.
pub const ACTUATOR_FORMAT: &str = "excavator-actuator-model";
/// The format version this code writes and reads.
pub const ACTUATOR_FORMAT_VERSION: u32 = 1;

/// Serialised form of one network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct NetworkFile {
    /// Input names in order.
    inputs: Vec<String>,
    activation: Activation,
    /// Per input: normalised = (raw - offset) / scale.
    input_offset: Vec<f64>,
    input_scale: Vec<f64>,
    /// Output velocity = normalised output * velocity_scale_m_per_s.
    velocity_scale_m_per_s: f64,
    /// Predictions are clamped to +- this speed.
    velocity_limit_m_per_s: f64,
    /// Hidden layer weights, one row per hidden unit.
    hidden_weights: Vec<Vec<f64>>,
    hidden_bias: Vec<f64>,
    output_weights: Vec<f64>,
    /// Linear shortcut from the inputs to the output (Eq. 4's `w_v v(t)` among them).
    shortcut_weights: Vec<f64>,
    output_bias: f64,
    /// Reference forces of the orifice drives, N, `[own, partner]` x `[extending, retracting]`; only in
    /// networks with the orifice inputs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    orifice_reference_force_n: Option<[[f64; 2]; 2]>,
}

fn input_names(j: usize, inputs: usize, with_third: bool) -> Vec<String> {
    let other = Joint::ALL[partner(j)];
    let t = Joint::ALL[third(j)];
    let (fifth, sixth) = if inputs == FORCE_RATE_INPUTS {
        ("force_rate_n_per_s".to_owned(), String::new())
    } else if with_third {
        (format!("delayed_{t}_command"), format!("{t}_force_n"))
    } else {
        ("orifice_drive".to_owned(), format!("{other}_orifice_drive"))
    };
    [
        "delayed_command".to_owned(),
        "force_n".to_owned(),
        "previous_velocity_m_per_s".to_owned(),
        format!("delayed_{other}_command"),
        format!("{other}_force_n"),
        fifth,
        sixth,
    ]
    .into_iter()
    .take(inputs)
    .collect()
}

impl From<&Network> for NetworkFile {
    fn from(net: &Network) -> Self {
        let p = &net.params;
        let hidden_weights = p
            .chunks_exact(net.inputs)
            .take(net.hidden)
            .map(<[f64]>::to_vec)
            .collect();
        let slice = |from: usize, len: usize| {
            p.get(from..from + len)
                .map(<[f64]>::to_vec)
                .unwrap_or_default()
        };
        Self {
            inputs: input_names(net.joint.index(), net.inputs, net.third),
            activation: net.activation,
            input_offset: net.input_offset[..net.inputs].to_vec(),
            input_scale: net.input_scale[..net.inputs].to_vec(),
            velocity_scale_m_per_s: net.velocity_scale,
            velocity_limit_m_per_s: net.output_limit * net.velocity_scale,
            hidden_weights,
            hidden_bias: slice(net.b1_at(), net.hidden),
            output_weights: slice(net.w2_at(), net.hidden),
            shortcut_weights: slice(net.skip_at(), net.inputs),
            output_bias: p.get(net.b2_at()).copied().unwrap_or(0.0),
            orifice_reference_force_n: (net.inputs == MAX_INPUTS && !net.third)
                .then_some(net.orifice_ref_n),
        }
    }
}

impl NetworkFile {
    fn into_network(self, joint: Joint, dt_s: f64) -> Result<Network, ActuatorError> {
        let bad = |what: &str| {
            Err(ActuatorError::InvalidModel(format!(
                "{joint} network: {what}"
            )))
        };
        let j = joint.index();
        let inputs = self.input_offset.len();
        if inputs != thesis_inputs(j)
            && inputs != COUPLED_INPUTS
            && inputs != FORCE_RATE_INPUTS
            && inputs != MAX_INPUTS
        {
            return bad(
                "input count is neither Fig. 17's, the coupled, the force-rate nor the orifice layout",
            );
        }
        let with_third = inputs == MAX_INPUTS && self.inputs == input_names(j, inputs, true);
        let orifice_ref_n = match (
            inputs == MAX_INPUTS && !with_third,
            self.orifice_reference_force_n,
        ) {
            (false, None) => [[1.0; 2]; 2],
            (true, Some(r)) if r.iter().flatten().all(|f| f.is_finite() && *f > 0.0) => r,
            (true, _) => return bad("orifice reference forces missing or not positive"),
            (false, Some(_)) => return bad("orifice reference forces without orifice inputs"),
        };
        if self.inputs != input_names(j, inputs, with_third) {
            return bad("input names do not match the layout");
        }
        let hidden = self.hidden_weights.len();
        if hidden == 0 || hidden > MAX_HIDDEN {
            return bad("hidden unit count outside 1..=MAX_HIDDEN");
        }
        if self.input_offset.len() != inputs
            || self.input_scale.len() != inputs
            || self.shortcut_weights.len() != inputs
            || self.hidden_weights.iter().any(|row| row.len() != inputs)
        {
            return bad("input count does not match the cylinder");
        }
        if self.hidden_bias.len() != hidden || self.output_weights.len() != hidden {
            return bad("hidden layer sizes disagree");
        }
        let mut params = Vec::with_capacity(Network::param_count(inputs, hidden));
        for row in &self.hidden_weights {
            params.extend_from_slice(row);
        }
        params.extend_from_slice(&self.hidden_bias);
        params.extend_from_slice(&self.output_weights);
        params.extend_from_slice(&self.shortcut_weights);
        params.push(self.output_bias);
        if params
            .iter()
            .chain(&self.input_offset)
            .any(|v| !v.is_finite())
        {
            return bad("non-finite weight or offset");
        }
        if self
            .input_scale
            .iter()
            .any(|s| !(s.is_finite() && *s > 0.0))
        {
            return bad("input scale not positive");
        }
        let vs = self.velocity_scale_m_per_s;
        let limit = self.velocity_limit_m_per_s;
        if !(vs.is_finite() && vs > 0.0 && limit.is_finite() && limit > 0.0) {
            return bad("velocity scale or limit not positive");
        }
        if (self.input_scale[IN_VELOCITY] - vs).abs() > 1e-12 * vs
            || self.input_offset[IN_VELOCITY] != 0.0
        {
            return bad("previous-velocity normalisation must equal the output's");
        }
        let mut input_offset = [0.0; MAX_INPUTS];
        let mut input_scale = [1.0; MAX_INPUTS];
        input_offset[..inputs].copy_from_slice(&self.input_offset);
        input_scale[..inputs].copy_from_slice(&self.input_scale);
        Ok(Network {
            joint,
            inputs,
            hidden,
            activation: self.activation,
            input_offset,
            input_scale,
            velocity_scale: vs,
            output_limit: limit / vs,
            orifice_ref_n,
            third: with_third,
            rate_per_s: 1.0 / dt_s,
            params,
        })
    }
}

/// Serialised form of the model (`actuator.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct ModelFile {
    format: String,
    version: u32,
    dt_s: f64,
    delay_steps: usize,
    /// Spool lag time constant, s (0: the networks see the delayed command itself).
    #[serde(default, skip_serializing_if = "is_zero")]
    command_lag_s: f64,
    boom: NetworkFile,
    stick: NetworkFile,
    bucket: NetworkFile,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    training: Option<TrainingSummary>,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl ActuatorModel {
    /// The model as JSON (`actuator.json`).
    ///
    /// # Errors
    /// [`ActuatorError::InvalidModel`] if serialisation fails (it does not for a valid model).
    pub fn to_json(&self) -> Result<String, ActuatorError> {
        let [boom, stick, bucket] = &self.networks;
        let file = ModelFile {
            format: ACTUATOR_FORMAT.to_owned(),
            version: ACTUATOR_FORMAT_VERSION,
            dt_s: self.dt_s,
            delay_steps: self.delay_steps,
            command_lag_s: self.command_lag_s,
            boom: boom.into(),
            stick: stick.into(),
            bucket: bucket.into(),
            training: self.training.clone(),
        };
        serde_json::to_string_pretty(&file).map_err(|e| ActuatorError::InvalidModel(e.to_string()))
    }

    /// Reads a model written by [`to_json`](Self::to_json), checking the format, version and dimensions.
    ///
    /// # Errors
    /// [`ActuatorError::InvalidModel`] for malformed JSON, another format or version, or inconsistent or
    /// non-finite weights.
    pub fn from_json(text: &str) -> Result<Self, ActuatorError> {
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| ActuatorError::InvalidModel(e.to_string()))?;
        let format = value.get("format").and_then(serde_json::Value::as_str);
        if format != Some(ACTUATOR_FORMAT) {
            return Err(ActuatorError::InvalidModel(format!(
                "format {format:?}, expected {ACTUATOR_FORMAT:?}"
            )));
        }
        let version = value.get("version").and_then(serde_json::Value::as_u64);
        if version != Some(u64::from(ACTUATOR_FORMAT_VERSION)) {
            return Err(ActuatorError::InvalidModel(format!(
                "version {version:?}, this build reads {ACTUATOR_FORMAT_VERSION}"
            )));
        }
        let file: ModelFile = serde_json::from_value(value)
            .map_err(|e| ActuatorError::InvalidModel(e.to_string()))?;
        if !(file.dt_s.is_finite() && file.dt_s > 0.0) {
            return Err(ActuatorError::InvalidModel("dt_s not positive".to_owned()));
        }
        if file.delay_steps > MAX_DELAY_STEPS {
            return Err(ActuatorError::InvalidModel(
                "delay_steps exceeds MAX_DELAY_STEPS".to_owned(),
            ));
        }
        if !(file.command_lag_s.is_finite() && file.command_lag_s >= 0.0) {
            return Err(ActuatorError::InvalidModel(
                "command_lag_s negative or not finite".to_owned(),
            ));
        }
        let networks = [
            file.boom.into_network(Joint::Boom, file.dt_s)?,
            file.stick.into_network(Joint::Stick, file.dt_s)?,
            file.bucket.into_network(Joint::Bucket, file.dt_s)?,
        ];
        if networks
            .iter()
            .any(|n| n.activation != networks[0].activation || n.hidden != networks[0].hidden)
        {
            return Err(ActuatorError::InvalidModel(
                "networks differ in size or activation".to_owned(),
            ));
        }
        Ok(Self {
            dt_s: file.dt_s,
            delay_steps: file.delay_steps,
            command_lag_s: file.command_lag_s,
            lag_gain: lag_gain(file.dt_s, file.command_lag_s),
            networks,
            training: file.training,
        })
    }
}
