//! One cylinder's network (Figs. 17-18, Eq. 4): its input slots, its normalisation and its forward and
//! backward passes.

use super::MAX_HIDDEN;
use crate::kinematics::Joint;
use serde::{Deserialize, Serialize};

/// Input slots of a network with the orifice-law inputs; the coupled layout uses a prefix of five,
/// Fig. 17's networks a prefix of four (boom) or three (stick, bucket).
pub(super) const MAX_INPUTS: usize = 7;
/// Inputs of the coupled layout (own and partner command and force, previous velocity).
pub(super) const COUPLED_INPUTS: usize = 5;
/// Inputs of the coupled layout with the force rate ([`TrainConfig::force_rate_input`]).
pub(super) const FORCE_RATE_INPUTS: usize = 6;
/// Input slots: delayed own command, cylinder force, previous velocity, the delayed command and the
/// force of the cylinder sharing its flow (the partner: boom and bucket share a pump, the stick's pump
/// feeds the boom through the crossover). Fig. 17 gives the boom the bucket command (slot 3) only.
pub(super) const IN_COMMAND: usize = 0;
pub(super) const IN_FORCE: usize = 1;
pub(super) const IN_VELOCITY: usize = 2;
pub(super) const IN_PARTNER_COMMAND: usize = 3;
pub(super) const IN_PARTNER_FORCE: usize = 4;
/// Orifice-law drive of the own and the partner cylinder (Eq. 1): the delayed command times
/// `sqrt(1 - F / F_ref)`, the valve's pressure drop falling as the load on the inlet side approaches the
/// largest the cylinder held in the training data ([`orifice_drive`]).
pub(super) const IN_ORIFICE: usize = 5;
pub(super) const IN_PARTNER_ORIFICE: usize = 6;
/// In the all-cylinder layout ([`TrainConfig::third_inputs`]) the last two slots carry the delayed
/// command and the force of the third cylinder instead of the orifice drives.
pub(super) const IN_THIRD_COMMAND: usize = 5;
pub(super) const IN_THIRD_FORCE: usize = 6;
/// In the force-rate layout ([`TrainConfig::force_rate_input`]) slot 5 carries the rate of change of the
/// own cylinder force over the last step, N/s: Eq. 2's `dP/dt = beta (Q - A v) / V` ties it to the
/// difference between the valve's flow and the cylinder's displacement, i.e. to the velocity change the
/// command and force alone do not show (a load taken up or let go).
pub(super) const IN_FORCE_RATE: usize = 5;

/// The cylinder whose flow network `j` shares: boom <- bucket (shared pump), stick <- boom (crossover),
/// bucket <- boom (shared pump).
pub(super) const fn partner(j: usize) -> usize {
    match j {
        0 => 2,
        _ => 0,
    }
}

/// The cylinder that is neither `j` nor its partner: boom <- stick (the crossover brings pump 2's flow,
/// which the stick's load sets), stick <- bucket, bucket <- stick.
pub(super) const fn third(j: usize) -> usize {
    match j {
        1 => 2,
        _ => 1,
    }
}

/// Inputs of network `j` in Fig. 17's layout: the boom also sees the bucket command.
pub(super) const fn thesis_inputs(j: usize) -> usize {
    if j == 0 { 4 } else { 3 }
}

/// Hidden-unit activation (Fig. 16 uses a sigmoid; tanh is the same shape centred on zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// Hyperbolic tangent.
    #[default]
    Tanh,
    /// Logistic sigmoid `1 / (1 + e^-a)`.
    Sigmoid,
}

impl Activation {
    #[inline]
    fn apply(self, a: f64) -> f64 {
        match self {
            // tanh through one exp: libm's tanh is several times slower and dominated the step.
            // Exact to rounding; saturates to +-1 without NaN (exp overflows to inf or underflows to 0).
            Activation::Tanh => 1.0 - 2.0 / ((2.0 * a).exp() + 1.0),
            Activation::Sigmoid => 1.0 / (1.0 + (-a).exp()),
        }
    }

    /// Derivative expressed through the output `h = act(a)`.
    #[inline]
    fn derivative_from_output(self, h: f64) -> f64 {
        match self {
            Activation::Tanh => 1.0 - h * h,
            Activation::Sigmoid => h * (1.0 - h),
        }
    }
}

/// One cylinder's network with its normalisation (private layout; see `file::NetworkFile` for the file).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Network {
    pub(super) joint: Joint,
    pub(super) inputs: usize,
    pub(super) hidden: usize,
    pub(super) activation: Activation,
    pub(super) input_offset: [f64; MAX_INPUTS],
    pub(super) input_scale: [f64; MAX_INPUTS],
    /// Velocity scale, m/s: the normalised output and previous-velocity input are `v / velocity_scale`.
    pub(super) velocity_scale: f64,
    /// Clamp on the normalised output.
    pub(super) output_limit: f64,
    /// Reference forces of the orifice drive, N, `[own, partner]`, each `[extending, retracting]`
    /// (positive magnitudes).
    pub(super) orifice_ref_n: [[f64; 2]; 2],
    /// The last two slots carry the third cylinder's command and force (not the orifice drives).
    pub(super) third: bool,
    /// `1 / dt`, 1/s: turns a force change over one step into the force rate ([`IN_FORCE_RATE`]).
    pub(super) rate_per_s: f64,
    /// `W1` (hidden x inputs, row-major), `b1` (hidden), `w2` (hidden), `s` (inputs), `b2`.
    pub(super) params: Vec<f64>,
}

impl Network {
    pub(super) fn param_count(inputs: usize, hidden: usize) -> usize {
        hidden * inputs + 2 * hidden + inputs + 1
    }
    pub(super) fn b1_at(&self) -> usize {
        self.hidden * self.inputs
    }
    pub(super) fn w2_at(&self) -> usize {
        self.b1_at() + self.hidden
    }
    pub(super) fn skip_at(&self) -> usize {
        self.w2_at() + self.hidden
    }
    pub(super) fn b2_at(&self) -> usize {
        self.skip_at() + self.inputs
    }

    /// Normalised forward pass; `hidden_out` receives the hidden activations. Unclamped.
    #[inline]
    pub(super) fn forward(
        &self,
        params: &[f64],
        x: &[f64; MAX_INPUTS],
        hidden_out: &mut [f64; MAX_HIDDEN],
    ) -> f64 {
        let (n, h) = (self.inputs, self.hidden);
        let (w1, rest) = params.split_at(h * n);
        let (b1, rest) = rest.split_at(h);
        let (w2, rest) = rest.split_at(h);
        let (skip, rest) = rest.split_at(n);
        let mut y = rest.first().copied().unwrap_or(0.0);
        for (i, (row, (&b, &w_out))) in w1.chunks_exact(n).zip(b1.iter().zip(w2)).enumerate() {
            let a = b + row.iter().zip(x).map(|(w, xi)| w * xi).sum::<f64>();
            let act = self.activation.apply(a);
            if let Some(slot) = hidden_out.get_mut(i) {
                *slot = act;
            }
            y += w_out * act;
        }
        y + skip.iter().zip(x).map(|(s, xi)| s * xi).sum::<f64>()
    }

    /// Accumulates the parameter gradient of one step for an output gradient `g` (d loss / d y) and
    /// returns d loss / d x[IN_VELOCITY], the gradient carried back through the recurrence.
    #[inline]
    pub(super) fn backward(
        &self,
        params: &[f64],
        x: &[f64; MAX_INPUTS],
        hid: &[f64; MAX_HIDDEN],
        g: f64,
        grad: &mut [f64],
    ) -> f64 {
        let (n, h) = (self.inputs, self.hidden);
        let (b1_at, w2_at, skip_at, b2_at) =
            (self.b1_at(), self.w2_at(), self.skip_at(), self.b2_at());
        let mut carry = 0.0;
        if let Some(gb) = grad.get_mut(b2_at) {
            *gb += g;
        }
        for i in 0..n {
            if let (Some(gs), Some(&xi)) = (grad.get_mut(skip_at + i), x.get(i)) {
                *gs += g * xi;
            }
        }
        carry += g * params.get(skip_at + IN_VELOCITY).copied().unwrap_or(0.0);
        for j in 0..h {
            let hj = hid.get(j).copied().unwrap_or(0.0);
            let w2j = params.get(w2_at + j).copied().unwrap_or(0.0);
            if let Some(gw) = grad.get_mut(w2_at + j) {
                *gw += g * hj;
            }
            let ga = g * w2j * self.activation.derivative_from_output(hj);
            if let Some(gb) = grad.get_mut(b1_at + j) {
                *gb += ga;
            }
            for i in 0..n {
                if let (Some(gw), Some(&xi)) = (grad.get_mut(j * n + i), x.get(i)) {
                    *gw += ga * xi;
                }
            }
            carry += ga * params.get(j * n + IN_VELOCITY).copied().unwrap_or(0.0);
        }
        carry
    }

    /// Raw (physical) inputs of this network (cylinder `j`): delayed command, force, previous velocity,
    /// the partner's delayed command and force, the own and the partner's orifice drive (a network with
    /// fewer inputs ignores the last slots; for the boom the partner is the bucket, Fig. 17).
    #[inline]
    pub(super) fn raw_inputs(
        &self,
        j: usize,
        delayed: &[f64; 3],
        force_n: &[f64; 3],
        previous_force_n: &[f64; 3],
        velocity: f64,
    ) -> [f64; MAX_INPUTS] {
        let o = partner(j);
        let mut raw = [0.0; MAX_INPUTS];
        raw[IN_COMMAND] = delayed[j];
        raw[IN_FORCE] = force_n[j];
        raw[IN_VELOCITY] = velocity;
        raw[IN_PARTNER_COMMAND] = delayed[o];
        raw[IN_PARTNER_FORCE] = force_n[o];
        if self.inputs == FORCE_RATE_INPUTS {
            raw[IN_FORCE_RATE] = (force_n[j] - previous_force_n[j]) * self.rate_per_s;
        } else if self.third {
            let t = third(j);
            raw[IN_THIRD_COMMAND] = delayed[t];
            raw[IN_THIRD_FORCE] = force_n[t];
        } else if self.inputs == MAX_INPUTS {
            let [own, other] = &self.orifice_ref_n;
            raw[IN_ORIFICE] = orifice_drive(delayed[j], force_n[j], own);
            raw[IN_PARTNER_ORIFICE] = orifice_drive(delayed[o], force_n[o], other);
        }
        raw
    }

    /// Normalised inputs from physical ones (slot [`IN_VELOCITY`] is the previous velocity in m/s).
    #[inline]
    pub(super) fn normalise(&self, raw: &[f64; MAX_INPUTS]) -> [f64; MAX_INPUTS] {
        let mut x = [0.0; MAX_INPUTS];
        for (i, xi) in x.iter_mut().enumerate().take(self.inputs) {
            *xi = (raw[i] - self.input_offset[i]) / self.input_scale[i];
        }
        x
    }
}

/// Orifice-law drive (Eq. 1, `Q = k A sqrt(dP)`): the command `u` times the square root of the
/// pressure drop left across the meter-in orifice, `sqrt(1 - F / F_ext)` when extending (the head side
/// carries the load `F`) and `sqrt(1 + F / F_ret)` when retracting, with the reference forces
/// `[F_ext, F_ret]` the largest loads the cylinder held in the training data (the supply pressure is
/// bounded by the relief). The root's argument is kept in `[0, 2]`; zero at a neutral command.
#[inline]
pub(super) fn orifice_drive(u: f64, force_n: f64, reference_n: &[f64; 2]) -> f64 {
    let drop = if u > 0.0 {
        1.0 - force_n / reference_n[0]
    } else {
        1.0 + force_n / reference_n[1]
    };
    u * drop.clamp(0.0, 2.0).sqrt()
}
