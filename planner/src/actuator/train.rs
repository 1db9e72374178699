//! Training (thesis 4.2.3): the split into training, validation and test digs, teacher forcing, then
//! backpropagation through time on free-running rollouts with early stopping, by Adam.

use super::dig::{Sequence, clamp_command, resample};
use super::network::{
    Activation, COUPLED_INPUTS, FORCE_RATE_INPUTS, IN_FORCE, IN_FORCE_RATE, IN_ORIFICE,
    IN_PARTNER_FORCE, IN_PARTNER_ORIFICE, IN_THIRD_COMMAND, IN_THIRD_FORCE, IN_VELOCITY,
    MAX_INPUTS, Network, orifice_drive, partner, thesis_inputs, third,
};
use super::predict::{ActuatorModel, EvaluationReport, TrainingSummary, lag_gain};
use super::{ActuatorDig, ActuatorError, MAX_DELAY_STEPS, MAX_HIDDEN};
use crate::kinematics::Joint;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Predicted velocities are clamped to this multiple of the largest training velocity, so a free-running
/// rollout stays bounded whatever the inputs (cylinder speed is bounded by pump flow).
const VELOCITY_LIMIT_FACTOR: f64 = 1.5;

/// Training settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrainConfig {
    /// Model period, s (the samples are resampled to it). Default: the 10 ms control period.
    pub dt_s: f64,
    /// Fixed command delay in steps (Fig. 17), at most [`MAX_DELAY_STEPS`].
    pub delay_steps: usize,
    /// Hidden units per network (Fig. 18: five), 1 to [`MAX_HIDDEN`].
    pub hidden_units: usize,
    /// Hidden-unit activation.
    pub activation: Activation,
    /// Seed of the split and the initial weights; training is deterministic for a seed.
    pub seed: u64,
    /// Fraction of digs held out for early stopping (at least one dig).
    pub validation_fraction: f64,
    /// Fraction of digs held out for the reported error (at least one dig).
    pub test_fraction: f64,
    /// Full-batch epochs of teacher forcing.
    pub teacher_forcing_epochs: usize,
    /// Epochs of free-running backpropagation through time.
    pub free_run_epochs: usize,
    /// Adam step size for teacher forcing.
    pub learning_rate: f64,
    /// Adam step size for the free-running phase.
    pub free_run_learning_rate: f64,
    /// Free-running epochs without a validation improvement before stopping.
    pub patience: usize,
    /// Largest gradient norm (normalised units); larger gradients are scaled down.
    pub gradient_clip: f64,
    /// Every network also sees the delayed command and the force of the cylinder sharing its flow
    /// (boom and bucket: the shared, power-limited pump; stick: the crossover to the boom); `false` is
    /// Fig. 17's layout (only the boom sees the bucket command).
    pub coupled_inputs: bool,
    /// With the coupled inputs, every network also gets the orifice-law drive (Eq. 1) of its own and its
    /// partner's cylinder: the command times the square root of the pressure drop left for the valve,
    /// `u sqrt(1 - F / F_ref)`, which the tanh units cannot form from command and force alone.
    pub orifice_inputs: bool,
    /// Loss of the free-running phase and of early stopping.
    pub free_run_loss: FreeRunLoss,
    /// Standard deviation (in units of each force input's standard deviation) of a constant offset
    /// added to the force inputs of every training dig, drawn anew each free-running epoch: trains the
    /// networks to tolerate a force that is off by a load-dependent bias, as the dig model's statics
    /// are against the measured pressures. Zero: no augmentation.
    pub force_noise: f64,
    /// Time constant of the spool lag, s: the delayed commands pass a first-order lag
    /// (`s_k = s_{k-1} + a (u_{k-d} - s_{k-1})`, `a = 1 - exp(-dt / tau)`) before they enter the
    /// networks, an estimate of the spool position the valve's non-linear metering acts on (the pilot and
    /// main-stage lag behind the transport delay; the machine file's `lag_time_constant_s`). Zero: the
    /// delayed command itself (Fig. 17).
    pub command_lag_s: f64,
    /// With the coupled inputs, every network also gets the delayed command and the force of the third
    /// cylinder, so it sees all three valves and loads (the boom's crossover flow comes from the stick's
    /// pump and depends on the stick's load). Excludes `orifice_inputs`.
    pub third_inputs: bool,
    /// Digs per Adam step (mini-batches, reshuffled every epoch) in both phases; 0: the whole training
    /// set per step (full batch, one step per epoch). With 260 training digs and batches of 16 an epoch
    /// costs the same and makes 17 updates instead of one.
    pub batch_digs: usize,
    /// With the coupled inputs, every network also gets the rate of change of its own cylinder force
    /// over the last step (N/s; Eq. 2, input `IN_FORCE_RATE`). Excludes `orifice_inputs` and `third_inputs`.
    pub force_rate_input: bool,
    /// With `force_rate_input`: the probability with which a training dig's force rate is set to zero
    /// for one Adam step (drawn per dig and batch, both phases), so the networks also learn the
    /// quasi-static case in which the dig model uses them ([`ActuatorState::with_static_forces`](super::ActuatorState::with_static_forces)).
    pub force_rate_dropout: f64,
    /// Learning-rate schedule of both phases: the Adam step size falls from the phase's rate to this
    /// fraction of it over the phase's epochs along a half cosine (1: constant rate, as before). A
    /// falling rate lets mini-batch training settle instead of hopping around the minimum.
    pub final_rate_fraction: f64,
    /// Trainings per network from different initial weights and mini-batch orders (the split stays
    /// the seed's); the one with the lowest free-running validation loss is kept (never the test
    /// digs). 1: one training, as before.
    pub restarts: usize,
}

/// Loss of the free-running (BPTT) phase and of early stopping on the validation digs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FreeRunLoss {
    /// Mean squared error.
    #[default]
    Squared,
    /// Mean absolute error (smoothed within 1 % of the velocity scale): the reported measure.
    Absolute,
}

/// Smoothing width of [`FreeRunLoss::Absolute`], normalised velocity units.
const ABS_LOSS_SMOOTHING: f64 = 0.01;

impl FreeRunLoss {
    /// Loss of one error `e` and its derivative.
    #[inline]
    pub(super) fn of(self, e: f64) -> (f64, f64) {
        match self {
            FreeRunLoss::Squared => (e * e, 2.0 * e),
            FreeRunLoss::Absolute => {
                let r = (e * e + ABS_LOSS_SMOOTHING * ABS_LOSS_SMOOTHING).sqrt();
                (r - ABS_LOSS_SMOOTHING, e / r)
            }
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            dt_s: gateway_core::dbc::CONTROL_PERIOD.as_secs_f64(),
            delay_steps: 3,
            hidden_units: 5,
            activation: Activation::Tanh,
            seed: 1,
            validation_fraction: 0.15,
            test_fraction: 0.2,
            teacher_forcing_epochs: 300,
            free_run_epochs: 400,
            learning_rate: 0.02,
            free_run_learning_rate: 0.005,
            patience: 60,
            gradient_clip: 1.0,
            coupled_inputs: false,
            orifice_inputs: false,
            free_run_loss: FreeRunLoss::Squared,
            force_noise: 0.0,
            command_lag_s: 0.0,
            third_inputs: false,
            batch_digs: 0,
            force_rate_input: false,
            force_rate_dropout: 0.0,
            final_rate_fraction: 1.0,
            restarts: 1,
        }
    }
}

impl TrainConfig {
    fn validate(&self) -> Result<(), ActuatorError> {
        let bad = |field, reason| Err(ActuatorError::InvalidConfig { field, reason });
        if !(self.dt_s.is_finite() && self.dt_s > 0.0) {
            return bad("dt_s", "must be positive and finite");
        }
        if self.delay_steps > MAX_DELAY_STEPS {
            return bad("delay_steps", "exceeds MAX_DELAY_STEPS");
        }
        if self.hidden_units == 0 || self.hidden_units > MAX_HIDDEN {
            return bad("hidden_units", "must be 1..=MAX_HIDDEN");
        }
        if self.orifice_inputs && !self.coupled_inputs {
            return bad("orifice_inputs", "needs coupled_inputs");
        }
        if self.force_rate_input
            && (self.orifice_inputs || self.third_inputs || !self.coupled_inputs)
        {
            return bad(
                "force_rate_input",
                "needs coupled_inputs and excludes orifice_inputs and third_inputs",
            );
        }
        if !(self.force_rate_dropout.is_finite() && (0.0..=1.0).contains(&self.force_rate_dropout))
        {
            return bad("force_rate_dropout", "must be in [0, 1]");
        }
        if self.third_inputs && (self.orifice_inputs || !self.coupled_inputs) {
            return bad(
                "third_inputs",
                "needs coupled_inputs and excludes orifice_inputs",
            );
        }
        for (field, value) in [
            ("validation_fraction", self.validation_fraction),
            ("test_fraction", self.test_fraction),
        ] {
            if !(value.is_finite() && (0.0..0.5).contains(&value)) {
                return bad(field, "must be in [0, 0.5)");
            }
        }
        if !(self.final_rate_fraction.is_finite()
            && self.final_rate_fraction > 0.0
            && self.final_rate_fraction <= 1.0)
        {
            return bad("final_rate_fraction", "must be in (0, 1]");
        }
        if self.restarts == 0 {
            return bad("restarts", "must be at least 1");
        }
        if !(self.force_noise.is_finite() && self.force_noise >= 0.0) {
            return bad("force_noise", "must be finite and not negative");
        }
        if !(self.command_lag_s.is_finite() && self.command_lag_s >= 0.0) {
            return bad("command_lag_s", "must be finite and not negative");
        }
        for (field, value) in [
            ("learning_rate", self.learning_rate),
            ("free_run_learning_rate", self.free_run_learning_rate),
            ("gradient_clip", self.gradient_clip),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return bad(field, "must be positive and finite");
            }
        }
        Ok(())
    }
}

/// Training phase, for progress reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainPhase {
    /// One-step prediction from the measured previous velocity.
    TeacherForcing,
    /// Backpropagation through time on free-running rollouts.
    FreeRun,
}

/// One progress report, sent after every epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainProgress {
    /// The network being trained.
    pub joint: Joint,
    /// The phase.
    pub phase: TrainPhase,
    /// Epoch within the phase (1-based).
    pub epoch: usize,
    /// Epochs planned for the phase.
    pub epochs: usize,
    /// Epochs done over all networks and phases (for a progress bar).
    pub done: usize,
    /// Epochs planned over all networks and phases; early stopping may end before.
    pub total: usize,
    /// Training loss this epoch (mean squared normalised velocity error).
    pub train_loss: f64,
    /// Free-running validation loss (mean squared normalised velocity error).
    pub validation_loss: f64,
}

/// What [`train`] did and how well the model predicts held-out digs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// Indices (into the input) of the digs trained on.
    pub train_digs: Vec<usize>,
    /// Indices of the digs used for early stopping.
    pub validation_digs: Vec<usize>,
    /// Indices of the held-out test digs.
    pub test_digs: Vec<usize>,
    /// Free-running epochs run per network `[boom, stick, bucket]` before early stopping.
    pub free_run_epochs: [usize; 3],
    /// Best free-running validation loss per network (mean squared normalised error).
    pub validation_loss: [f64; 3],
    /// Errors on the held-out test digs.
    pub test: EvaluationReport,
}

/// The networks' command inputs over a sequence: the commands delayed by `delay` steps (the delay line
/// starts full of the first command, as [`ActuatorModel::initial_state`] fills it), then lagged with
/// `gain` (the spool estimate, starting at the first command), as [`ActuatorModel::step`] computes them.
fn spool_inputs(command: &[[f64; 3]], delay: usize, gain: f64) -> Vec<[f64; 3]> {
    let mut spool = command
        .first()
        .copied()
        .map(clamp_command)
        .unwrap_or([0.0; 3]);
    (0..command.len())
        .map(|k| {
            let delayed = clamp_command(command[k.saturating_sub(delay)]);
            for (s, u) in spool.iter_mut().zip(delayed) {
                *s += gain * (u - *s);
            }
            spool
        })
        .collect()
}

/// One network's training data: per step the normalised exogenous inputs (slot [`IN_VELOCITY`] unused)
/// and the normalised measured velocity.
#[derive(Clone)]
struct NetSequence {
    exo: Vec<[f64; MAX_INPUTS]>,
    target: Vec<f64>,
}

fn net_sequences(
    net: &Network,
    j: usize,
    seqs: &[Sequence],
    delay: usize,
    gain: f64,
) -> Vec<NetSequence> {
    seqs.iter()
        .map(|seq| {
            let n = seq.len();
            let mut exo = Vec::with_capacity(n);
            let mut target = Vec::with_capacity(n);
            let spool = spool_inputs(&seq.command, delay, gain);
            for (k, delayed) in spool.iter().enumerate() {
                let previous = &seq.force[k.saturating_sub(1)];
                let mut x =
                    net.normalise(&net.raw_inputs(j, delayed, &seq.force[k], previous, 0.0));
                x[IN_VELOCITY] = 0.0;
                exo.push(x);
                target.push(seq.velocity[k][j] / net.velocity_scale);
            }
            NetSequence { exo, target }
        })
        .collect()
}

/// Mean and standard deviation.
fn mean_std(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count().max(1) as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// Builds an untrained network for cylinder `j` with normalisation from the training sequences.
fn new_network(
    j: usize,
    seqs: &[Sequence],
    config: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> Result<Network, ActuatorError> {
    let joint = Joint::ALL[j];
    let inputs = match (config.coupled_inputs, config.orifice_inputs) {
        (true, true) => MAX_INPUTS,
        (true, false) if config.third_inputs => MAX_INPUTS,
        (true, false) if config.force_rate_input => FORCE_RATE_INPUTS,
        (true, false) => COUPLED_INPUTS,
        (false, _) => thesis_inputs(j),
    };
    let velocities = seqs
        .iter()
        .flat_map(|s| s.velocity.iter().map(move |v| v[j]));
    let (_, v_std) = mean_std(velocities.clone());
    let v_peak = velocities.fold(0.0_f64, |m, v| m.max(v.abs()));
    if !(v_std > 1e-9 && v_peak > 0.0) {
        return Err(ActuatorError::DegenerateData { joint });
    }
    let (f_mean, f_std) = mean_std(seqs.iter().flat_map(|s| s.force.iter().map(move |f| f[j])));
    let mut input_offset = [0.0; MAX_INPUTS];
    let mut input_scale = [1.0; MAX_INPUTS];
    input_offset[IN_FORCE] = f_mean;
    input_scale[IN_FORCE] = if f_std > 1e-9 { f_std } else { 1.0 };
    let o = partner(j);
    let (p_mean, p_std) = mean_std(seqs.iter().flat_map(|s| s.force.iter().map(move |f| f[o])));
    input_offset[IN_PARTNER_FORCE] = p_mean;
    input_scale[IN_PARTNER_FORCE] = if p_std > 1e-9 { p_std } else { 1.0 };
    input_scale[IN_VELOCITY] = v_std;
    // Orifice drives: reference forces are the largest loads held each way (5 % margin).
    let reference = |c: usize| {
        let (mut ext, mut ret) = (0.0_f64, 0.0_f64);
        for f in seqs.iter().flat_map(|s| s.force.iter().map(move |f| f[c])) {
            ext = ext.max(f);
            ret = ret.max(-f);
        }
        [ext, ret].map(|r| if r > 1.0 { 1.05 * r } else { 1.0 })
    };
    let orifice_ref_n = [reference(j), reference(o)];
    for (slot, c, refs) in [
        (IN_ORIFICE, j, &orifice_ref_n[0]),
        (IN_PARTNER_ORIFICE, o, &orifice_ref_n[1]),
    ] {
        let drives = seqs.iter().flat_map(|s| {
            s.command
                .iter()
                .zip(&s.force)
                .map(move |(u, f)| orifice_drive(u[c].clamp(-1.0, 1.0), f[c], refs))
        });
        let (mean, std) = mean_std(drives);
        input_offset[slot] = mean;
        input_scale[slot] = if std > 1e-9 { std } else { 1.0 };
    }
    if config.force_rate_input {
        let rates = seqs.iter().flat_map(|s| {
            s.force
                .windows(2)
                .map(move |w| (w[1][j] - w[0][j]) / config.dt_s)
        });
        let (mean, std) = mean_std(rates);
        input_offset[IN_FORCE_RATE] = mean;
        input_scale[IN_FORCE_RATE] = if std > 1e-9 { std } else { 1.0 };
    }
    if config.third_inputs {
        // The third cylinder's command stays as it is (a fraction), its force is standardised.
        let t = third(j);
        let (t_mean, t_std) = mean_std(seqs.iter().flat_map(|s| s.force.iter().map(move |f| f[t])));
        input_offset[IN_THIRD_COMMAND] = 0.0;
        input_scale[IN_THIRD_COMMAND] = 1.0;
        input_offset[IN_THIRD_FORCE] = t_mean;
        input_scale[IN_THIRD_FORCE] = if t_std > 1e-9 { t_std } else { 1.0 };
    }
    let hidden = config.hidden_units;
    let count = Network::param_count(inputs, hidden);
    let bound = 1.0 / (inputs as f64).sqrt();
    let mut params: Vec<f64> = (0..count)
        .map(|_| rng.random_range(-bound..bound))
        .collect();
    let net = Network {
        joint,
        inputs,
        hidden,
        activation: config.activation,
        input_offset,
        input_scale,
        velocity_scale: v_std,
        output_limit: VELOCITY_LIMIT_FACTOR * v_peak / v_std,
        orifice_ref_n,
        third: config.third_inputs,
        rate_per_s: 1.0 / config.dt_s,
        params: Vec::new(),
    };
    // Start the shortcut near Eq. 4's slow first-order response: v(t+1) = 0.9 v(t) + ...
    for (i, p) in params[net.skip_at()..net.b2_at()].iter_mut().enumerate() {
        *p = if i == IN_VELOCITY { 0.9 } else { 0.0 };
    }
    params[net.b2_at()] = 0.0;
    Ok(Network { params, ..net })
}

/// Adam optimiser state.
struct Adam {
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
    rate: f64,
}

impl Adam {
    fn new(n: usize, rate: f64) -> Self {
        Self {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
            rate,
        }
    }

    fn update(&mut self, params: &mut [f64], grad: &[f64]) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        for (((p, g), m), v) in params
            .iter_mut()
            .zip(grad)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            *m = B1 * *m + (1.0 - B1) * g;
            *v = B2 * *v + (1.0 - B2) * g * g;
            *p -= self.rate * (*m / c1) / ((*v / c2).sqrt() + 1e-8);
        }
    }
}

fn clip(grad: &mut [f64], max_norm: f64) {
    let norm = grad.iter().map(|g| g * g).sum::<f64>().sqrt();
    if norm > max_norm {
        let k = max_norm / norm;
        grad.iter_mut().for_each(|g| *g *= k);
    }
}

/// The predicted steps in `data` (a sequence's first sample only starts it), at least one: the
/// losses are means over them.
fn step_count(data: &[&NetSequence]) -> f64 {
    data.iter()
        .map(|s| s.target.len().saturating_sub(1))
        .sum::<usize>()
        .max(1) as f64
}

/// Teacher-forced loss and gradient: every step sees the measured previous velocity.
fn teacher_forced(net: &Network, params: &[f64], data: &[&NetSequence], grad: &mut [f64]) -> f64 {
    grad.iter_mut().for_each(|g| *g = 0.0);
    let count = step_count(data);
    let mut hidden = [0.0; MAX_HIDDEN];
    let mut loss = 0.0;
    for seq in data {
        for k in 0..seq.target.len().saturating_sub(1) {
            let mut x = seq.exo[k];
            x[IN_VELOCITY] = seq.target[k];
            let e = net.forward(params, &x, &mut hidden) - seq.target[k + 1];
            loss += e * e;
            net.backward(params, &x, &hidden, 2.0 * e / count, grad);
        }
    }
    loss / count
}

/// Free-running loss, and with `grad` its gradient by backpropagation through time.
fn free_run(
    net: &Network,
    params: &[f64],
    data: &[&NetSequence],
    loss_kind: FreeRunLoss,
    force_offsets: &[[f64; 2]],
    mut grad: Option<&mut [f64]>,
) -> f64 {
    if let Some(g) = grad.as_deref_mut() {
        g.iter_mut().for_each(|g| *g = 0.0);
    }
    let count = step_count(data);
    let mut loss = 0.0;
    let mut xs: Vec<[f64; MAX_INPUTS]> = Vec::new();
    let mut hs: Vec<[f64; MAX_HIDDEN]> = Vec::new();
    let mut errs: Vec<(f64, bool)> = Vec::new();
    for (i, seq) in data.iter().enumerate() {
        let offset = force_offsets.get(i).copied().unwrap_or([0.0; 2]);
        let steps = seq.target.len().saturating_sub(1);
        xs.clear();
        hs.clear();
        errs.clear();
        let mut y = seq.target.first().copied().unwrap_or(0.0);
        for k in 0..steps {
            let mut x = seq.exo[k];
            x[IN_VELOCITY] = y;
            x[IN_FORCE] += offset[0];
            if net.inputs > IN_PARTNER_FORCE {
                x[IN_PARTNER_FORCE] += offset[1];
            }
            let mut hidden = [0.0; MAX_HIDDEN];
            let raw = net.forward(params, &x, &mut hidden);
            let clamped = raw.is_nan() || raw.abs() > net.output_limit;
            y = if raw.is_finite() {
                raw.clamp(-net.output_limit, net.output_limit)
            } else {
                0.0
            };
            let (l, dl) = loss_kind.of(y - seq.target[k + 1]);
            loss += l;
            xs.push(x);
            hs.push(hidden);
            errs.push((dl, clamped));
        }
        if let Some(g) = grad.as_deref_mut() {
            let mut carry = 0.0;
            for k in (0..steps).rev() {
                let (dl, clamped) = errs[k];
                let dy = dl / count + carry;
                carry = if clamped {
                    0.0
                } else {
                    net.backward(params, &xs[k], &hs[k], dy, g)
                };
            }
        }
    }
    loss / count
}

/// The mini-batches of one epoch: `order` reshuffled with `rng` and cut into runs of `size` digs (the
/// last one shorter); `size` 0 or at least the number of digs: one batch of all digs, in order.
fn batches(order: &mut [usize], size: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<usize>> {
    if size == 0 || size >= order.len() {
        return vec![order.to_vec()];
    }
    for i in (1..order.len()).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    order.chunks(size).map(<[usize]>::to_vec).collect()
}

/// For [`TrainConfig::force_rate_dropout`]: per dig of `batch`, a copy with the force-rate input at
/// zero (normalised `-offset / scale`) with the configured probability, otherwise `None`.
fn rate_dropout(
    net: &Network,
    batch: &[usize],
    data: &[NetSequence],
    config: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> Vec<Option<NetSequence>> {
    let p = config.force_rate_dropout;
    if !(p > 0.0 && net.inputs == FORCE_RATE_INPUTS) {
        return vec![None; batch.len()];
    }
    let zero = -net.input_offset[IN_FORCE_RATE] / net.input_scale[IN_FORCE_RATE];
    batch
        .iter()
        .map(|&i| {
            (rng.random::<f64>() < p).then(|| {
                let mut seq = data[i].clone();
                seq.exo.iter_mut().for_each(|x| x[IN_FORCE_RATE] = zero);
                seq
            })
        })
        .collect()
}

/// The sequences of `batch`, the dropped-out copies where there are any.
fn batch_data<'a>(
    batch: &[usize],
    data: &'a [NetSequence],
    dropped: &'a [Option<NetSequence>],
) -> Vec<&'a NetSequence> {
    batch
        .iter()
        .zip(dropped)
        .map(|(&i, d)| d.as_ref().unwrap_or(&data[i]))
        .collect()
}

/// The share of the training steps in `batch` (to sum the batches' mean losses to the epoch's mean).
fn batch_weight(batch: &[&NetSequence], all: &[NetSequence]) -> f64 {
    let steps = |s: &NetSequence| s.target.len().saturating_sub(1);
    let total = all.iter().map(steps).sum::<usize>().max(1) as f64;
    batch.iter().map(|s| steps(s)).sum::<usize>() as f64 / total
}

/// The split of digs (by index) into training, validation and test sets.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DigSplit {
    /// Training digs.
    pub train: Vec<usize>,
    /// Validation digs (early stopping).
    pub validation: Vec<usize>,
    /// Held-out test digs (the reported error).
    pub test: Vec<usize>,
}

/// The split [`train`] uses for `count` digs and `config`'s seed and fractions, so a model can be
/// evaluated later on the same held-out test digs.
///
/// # Errors
/// [`ActuatorError::InvalidConfig`], [`ActuatorError::NotEnoughDigs`] (fewer than three).
pub fn split_digs(count: usize, config: &TrainConfig) -> Result<DigSplit, ActuatorError> {
    config.validate()?;
    if count < 3 {
        return Err(ActuatorError::NotEnoughDigs { count, needed: 3 });
    }
    Ok(split_with(
        count,
        config,
        &mut ChaCha8Rng::seed_from_u64(config.seed),
    ))
}

/// Shuffles `0..count` with `rng` and splits it; `count >= 3`.
fn split_with(count: usize, config: &TrainConfig, rng: &mut ChaCha8Rng) -> DigSplit {
    let mut order: Vec<usize> = (0..count).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    let n = count as f64;
    let n_test = ((config.test_fraction * n).round() as usize).max(1);
    let n_val = ((config.validation_fraction * n).round() as usize).max(1);
    let (test, rest) = order.split_at(n_test.min(order.len() - 2));
    let (validation, train) = rest.split_at(n_val.min(rest.len() - 1));
    DigSplit {
        train: train.to_vec(),
        validation: validation.to_vec(),
        test: test.to_vec(),
    }
}

/// One network's training ([`train`]): what it needs besides the generator.
struct NetworkTraining<'a> {
    j: usize,
    config: &'a TrainConfig,
    train_seqs: &'a [Sequence],
    val_seqs: &'a [Sequence],
    /// Epochs done before this training (progress).
    done: usize,
    /// Epochs planned in all (progress).
    total: usize,
}

/// A trained network with its free-running epochs and best validation loss.
struct NetworkRun {
    network: Network,
    free_run_epochs: usize,
    validation_loss: f64,
}

/// The Adam step size of `epoch` (1-based) of `epochs`: [`TrainConfig::final_rate_fraction`]'s half
/// cosine from `rate` down to `fraction x rate`.
pub(super) fn scheduled_rate(rate: f64, fraction: f64, epoch: usize, epochs: usize) -> f64 {
    if epochs <= 1 || fraction >= 1.0 {
        return rate;
    }
    let progress = (epoch.saturating_sub(1)) as f64 / (epochs - 1) as f64;
    rate * (fraction + (1.0 - fraction) * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos()))
}

/// Trains network `ctx.j` (teacher forcing, then free-running BPTT with early stopping on the
/// validation digs) and returns the weights with the lowest free-running validation loss.
fn train_network(
    ctx: &NetworkTraining<'_>,
    rng: &mut ChaCha8Rng,
    progress: &mut impl FnMut(&TrainProgress),
) -> Result<NetworkRun, ActuatorError> {
    let NetworkTraining {
        j,
        config,
        train_seqs,
        val_seqs,
        mut done,
        total,
    } = *ctx;
    let joint = Joint::ALL[j];
    let mut net = new_network(j, train_seqs, config, rng)?;
    let gain = lag_gain(config.dt_s, config.command_lag_s);
    let train_data = net_sequences(&net, j, train_seqs, config.delay_steps, gain);
    let val_owned = net_sequences(&net, j, val_seqs, config.delay_steps, gain);
    let val_data: Vec<&NetSequence> = val_owned.iter().collect();
    let mut params = std::mem::take(&mut net.params);
    let mut grad = vec![0.0; params.len()];
    let mut best = (
        free_run(&net, &params, &val_data, config.free_run_loss, &[], None),
        params.clone(),
    );
    let mut free_run_epochs = 0;
    // After every epoch of either phase: count it and tell the caller.
    let mut report = |phase, epoch, epochs, train_loss, validation_loss| {
        done += 1;
        progress(&TrainProgress {
            joint,
            phase,
            epoch,
            epochs,
            done,
            total,
            train_loss,
            validation_loss,
        });
    };

    let mut adam = Adam::new(params.len(), config.learning_rate);
    let mut order: Vec<usize> = (0..train_data.len()).collect();
    for epoch in 1..=config.teacher_forcing_epochs {
        adam.rate = scheduled_rate(
            config.learning_rate,
            config.final_rate_fraction,
            epoch,
            config.teacher_forcing_epochs,
        );
        let mut train_loss = 0.0;
        for batch in batches(&mut order, config.batch_digs, rng) {
            let dropped = rate_dropout(&net, &batch, &train_data, config, rng);
            let data = batch_data(&batch, &train_data, &dropped);
            train_loss +=
                teacher_forced(&net, &params, &data, &mut grad) * batch_weight(&data, &train_data);
            clip(&mut grad, config.gradient_clip);
            adam.update(&mut params, &grad);
        }
        let val = free_run(&net, &params, &val_data, config.free_run_loss, &[], None);
        if val < best.0 {
            best = (val, params.clone());
        }
        report(
            TrainPhase::TeacherForcing,
            epoch,
            config.teacher_forcing_epochs,
            train_loss,
            val,
        );
    }

    // Continue from the best free-running weights so far: teacher forcing can end on weights whose
    // free run is poor even when an earlier epoch's was good.
    params.clone_from(&best.1);
    let mut adam = Adam::new(params.len(), config.free_run_learning_rate);
    let mut since_best = 0;
    let mut offsets = vec![[0.0; 2]; train_data.len()];
    for epoch in 1..=config.free_run_epochs {
        adam.rate = scheduled_rate(
            config.free_run_learning_rate,
            config.final_rate_fraction,
            epoch,
            config.free_run_epochs,
        );
        if config.force_noise > 0.0 {
            let normal = |rng: &mut ChaCha8Rng| {
                // Box-Muller.
                let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
                (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
            };
            for o in &mut offsets {
                *o = [
                    config.force_noise * normal(rng),
                    config.force_noise * normal(rng),
                ];
            }
        }
        let mut train_loss = 0.0;
        let mut diverged = false;
        for batch in batches(&mut order, config.batch_digs, rng) {
            let dropped = rate_dropout(&net, &batch, &train_data, config, rng);
            let data = batch_data(&batch, &train_data, &dropped);
            let offs: Vec<[f64; 2]> = batch.iter().map(|&i| offsets[i]).collect();
            let loss = free_run(
                &net,
                &params,
                &data,
                config.free_run_loss,
                &offs,
                Some(&mut grad),
            );
            if !loss.is_finite() || grad.iter().any(|g| !g.is_finite()) {
                diverged = true;
                break;
            }
            train_loss += loss * batch_weight(&data, &train_data);
            clip(&mut grad, config.gradient_clip);
            adam.update(&mut params, &grad);
        }
        if diverged {
            break;
        }
        let val = free_run(&net, &params, &val_data, config.free_run_loss, &[], None);
        free_run_epochs = epoch;
        report(
            TrainPhase::FreeRun,
            epoch,
            config.free_run_epochs,
            train_loss,
            val,
        );
        if val < best.0 {
            best = (val, params.clone());
            since_best = 0;
        } else {
            since_best += 1;
            if since_best >= config.patience {
                break;
            }
        }
    }
    let (validation_loss, best_params) = best;
    if best_params.iter().any(|p| !p.is_finite()) {
        return Err(ActuatorError::Diverged { joint });
    }
    net.params = best_params;
    Ok(NetworkRun {
        network: net,
        free_run_epochs,
        validation_loss,
    })
}

/// Trains the three networks on `digs` (thesis 4.2.3): splits the digs (deterministically for the
/// seed) into training, validation and test sets, trains each network with teacher forcing and then
/// free-running backpropagation through time with early stopping on the validation digs, and reports
/// the free-running error on the test digs. `progress` is called after every epoch.
///
/// # Errors
/// [`ActuatorError::InvalidConfig`], [`ActuatorError::NotEnoughDigs`] (fewer than three), the sample
/// errors of [`ActuatorModel::evaluate`], [`ActuatorError::DegenerateData`] if a cylinder never moves,
/// [`ActuatorError::Diverged`] if the weights become non-finite.
pub fn train(
    digs: &[ActuatorDig],
    config: &TrainConfig,
    mut progress: impl FnMut(&TrainProgress),
) -> Result<(ActuatorModel, TrainReport), ActuatorError> {
    config.validate()?;
    if digs.len() < 3 {
        return Err(ActuatorError::NotEnoughDigs {
            count: digs.len(),
            needed: 3,
        });
    }
    let seqs = digs
        .iter()
        .enumerate()
        .map(|(i, d)| resample(d, i, config.dt_s))
        .collect::<Result<Vec<_>, _>>()?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let DigSplit {
        train: train_digs,
        validation: validation_digs,
        test: test_digs,
    } = split_with(digs.len(), config, &mut rng);
    let (train_digs, validation_digs, test_digs) = (&train_digs, &validation_digs, &test_digs);
    let pick = |idx: &[usize]| idx.iter().map(|&i| seqs[i].clone()).collect::<Vec<_>>();
    let (train_seqs, val_seqs) = (pick(train_digs), pick(validation_digs));

    let per_net = config.teacher_forcing_epochs + config.free_run_epochs;
    let total = 3 * per_net * config.restarts;
    let mut done = 0;
    let mut networks = Vec::with_capacity(3);
    let mut free_run_epochs = [0; 3];
    let mut validation_loss = [0.0; 3];
    for j in 0..3 {
        let mut kept: Option<NetworkRun> = None;
        for restart in 0..config.restarts {
            // The first training draws from the split's generator (as before restarts existed), the
            // others from their own, seeded from the seed, the network and the restart.
            let mut own;
            let rng = if restart == 0 {
                &mut rng
            } else {
                own = ChaCha8Rng::seed_from_u64(
                    config
                        .seed
                        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                        .wrapping_add((restart * 3 + j) as u64),
                );
                &mut own
            };
            let ctx = NetworkTraining {
                j,
                config,
                train_seqs: &train_seqs,
                val_seqs: &val_seqs,
                done,
                total,
            };
            let run = train_network(&ctx, rng, &mut progress)?;
            done += per_net;
            if kept
                .as_ref()
                .is_none_or(|k| run.validation_loss < k.validation_loss)
            {
                kept = Some(run);
            }
        }
        let Some(run) = kept else {
            return Err(ActuatorError::Diverged {
                joint: Joint::ALL[j],
            });
        };
        free_run_epochs[j] = run.free_run_epochs;
        validation_loss[j] = run.validation_loss;
        networks.push(run.network);
    }
    let networks: [Network; 3] = networks
        .try_into()
        .map_err(|_| ActuatorError::Diverged { joint: Joint::Boom })?;
    let mut model = ActuatorModel {
        dt_s: config.dt_s,
        delay_steps: config.delay_steps,
        command_lag_s: config.command_lag_s,
        lag_gain: lag_gain(config.dt_s, config.command_lag_s),
        networks,
        training: None,
    };
    let test_set: Vec<ActuatorDig> = test_digs.iter().map(|&i| digs[i].clone()).collect();
    let test = model.evaluate(&test_set)?;
    model.training = Some(TrainingSummary {
        seed: config.seed,
        digs: [train_digs.len(), validation_digs.len(), test_digs.len()],
        test_mae_percent_of_peak: test.cylinders.map(|c| c.mae_percent_of_peak),
        origin: None,
    });
    let report = TrainReport {
        train_digs: train_digs.to_vec(),
        validation_digs: validation_digs.to_vec(),
        test_digs: test_digs.to_vec(),
        free_run_epochs,
        validation_loss,
        test,
    };
    Ok((model, report))
}
