//! Soil-tool property estimation (thesis 4.3.4-4.3.5, Fig. 27, Eqs. 22-24).
//!
//! Input: a window of [`SoilSample`]s, each the intersection geometry `Gamma` of the bucket with the
//! terrain ([`crate::soil::dig_geometry`]) and the measured soil force on the bucket tip (Appendix A.2).
//!
//! - Empirical model ([`fit_empirical`]): `F = Gamma Psi` per component `F_x, F_z, M_y` with
//!   `Gamma = (d^2, cos rho, alpha, V_s)` (Eqs. 21-22). The thesis forms the pseudo-inverse
//!   `(Gamma^T Gamma)^-1 Gamma^T F` (Eq. 23); we solve the same least-squares problem by an SVD of the
//!   column-scaled `Gamma`, which squares no condition number and detects a rank-deficient window.
//! - Analytical model ([`fit_analytical`]): the modified FEE of [`crate::soil`] (Eqs. 14-19) with
//!   `Psi = (gamma, beta, phi, delta, c)`, found by several trials of simulated annealing (acceptance of
//!   Eq. 24) followed by Powell's method from the best trial, minimising `J`, the RMS force error in `x`
//!   and `z` (4.3.4), inside a bounded parameter box.
//! - [`SoilWindow`]: the sliding window (about 300 samples, 4.3.5).
//! - [`cross_validate`]: the thesis's test (4.3.5, Figs. 28-31): each dig is predicted from properties
//!   estimated on the window of samples before it, the first digs from the last ones.
//!
//! The fits are deterministic for a seed, return typed errors for empty, degenerate or non-finite input,
//! and never return NaN.

use crate::kinematics::TipForce;
use crate::machine::GRAVITY_M_PER_S2;
use crate::optimize::brent;
use crate::soil::{DigGeometry, EmpiricalSoilModel, SoilError, SoilProperties, fee_tip_force};
use nalgebra::{DMatrix, Matrix3x4};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// The thesis's window size (4.3.5: "300 data points usually provided an adequate amount of data").
pub const DEFAULT_WINDOW_SAMPLES: usize = 300;
/// Parameters of the empirical model per force component (`Gamma` has four terms).
pub const EMPIRICAL_TERMS: usize = 4;
/// Singular values below this fraction of the largest (of the column-scaled `Gamma`) make a window
/// rank-deficient.
const RANK_TOLERANCE: f64 = 1e-9;
/// The denominator guard of [`crate::soil::fee_factors`].
const FEE_EPS: f64 = 1e-6;

/// Estimation errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimateError {
    /// No samples.
    #[error("empty sample window")]
    EmptyWindow,
    /// Fewer samples than parameters.
    #[error("{count} samples, the fit needs at least {needed}")]
    TooFewSamples {
        /// Samples given.
        count: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A sample holds NaN or infinity.
    #[error("sample {index} is not finite")]
    NonFiniteSample {
        /// Index in the window.
        index: usize,
    },
    /// A sample is outside the model's domain (negative depth or swept volume, vertical terrain).
    #[error("sample {index}: {what}")]
    InvalidSample {
        /// Index in the window.
        index: usize,
        /// What is wrong.
        what: &'static str,
    },
    /// The geometry matrix `Gamma` of the window does not have full column rank (e.g. flat terrain
    /// throughout: the `alpha` column is zero), so Eq. 22 has no unique solution.
    #[error(
        "degenerate window: Gamma has rank {rank} of {EMPIRICAL_TERMS} (condition {condition:.3e})"
    )]
    RankDeficient {
        /// Numerical rank.
        rank: usize,
        /// Ratio of the largest to the smallest singular value of the column-scaled `Gamma`.
        condition: f64,
    },
    /// The parameter box is invalid or leaves the physical range of [`SoilProperties::validate`].
    #[error("parameter bounds: {what}")]
    InvalidBounds {
        /// What is wrong.
        what: &'static str,
    },
    /// A configuration value is invalid.
    #[error("estimation config {field}: {reason}")]
    InvalidConfig {
        /// Field name.
        field: &'static str,
        /// What is wrong.
        reason: &'static str,
    },
    /// No parameters in the box give finite FEE forces for these samples (the wedge cannot fail).
    #[error("no soil properties in the box give finite forces for this window")]
    NoFeasibleStart,
    /// Too few digs to cross-validate.
    #[error("{count} digs, cross-validation needs at least {needed}")]
    NotEnoughDigs {
        /// Digs given.
        count: usize,
        /// Digs needed.
        needed: usize,
    },
    /// The soil model failed on a prediction.
    #[error(transparent)]
    Soil(#[from] SoilError),
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, EstimateError>;

/// One estimation sample: the bucket-terrain geometry and the measured soil force on the bucket.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SoilSample {
    /// `Gamma = (d, alpha, rho, V_s)`.
    pub geometry: DigGeometry,
    /// Measured soil force on the bucket tip, base frame (`F_x, F_z` N, `M_y` N m).
    pub force: TipForce,
}

/// Checks samples: finite, non-negative depth and swept volume, terrain not vertical.
fn validate_samples(samples: &[SoilSample], needed: usize) -> Result<()> {
    if samples.is_empty() {
        return Err(EstimateError::EmptyWindow);
    }
    if samples.len() < needed {
        return Err(EstimateError::TooFewSamples {
            count: samples.len(),
            needed,
        });
    }
    for (index, s) in samples.iter().enumerate() {
        let g = &s.geometry;
        let f = &s.force;
        let values = [
            g.depth_m,
            g.slope_rad,
            g.rake_rad,
            g.swept_volume_m3,
            f.fx_n,
            f.fz_n,
            f.my_nm,
        ];
        if values.iter().any(|v| !v.is_finite()) {
            return Err(EstimateError::NonFiniteSample { index });
        }
        if g.depth_m < 0.0 || g.swept_volume_m3 < 0.0 {
            return Err(EstimateError::InvalidSample {
                index,
                what: "negative depth or swept volume",
            });
        }
        if g.slope_rad.cos().abs() < FEE_EPS {
            return Err(EstimateError::InvalidSample {
                index,
                what: "vertical terrain",
            });
        }
    }
    Ok(())
}

/// The empirical model fitted to a window, with its fit error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EmpiricalFit {
    /// Coefficients `Psi` per component (Eq. 21).
    pub model: EmpiricalSoilModel,
    /// RMS residual `[F_x, F_z]` force magnitude error on the window, N (the `J` of 4.3.4).
    pub rms_error_n: f64,
    /// RMS residual of `M_y`, N m.
    pub rms_moment_error_nm: f64,
    /// Condition number of the column-scaled `Gamma`.
    pub condition: f64,
}

/// Fits the empirical model by least squares (Eqs. 22-23) per component `F_x, F_z, M_y`.
///
/// # Errors
/// [`EstimateError::EmptyWindow`], [`EstimateError::TooFewSamples`] (fewer than four),
/// [`EstimateError::NonFiniteSample`], [`EstimateError::InvalidSample`],
/// [`EstimateError::RankDeficient`] when `Gamma` does not have full column rank.
pub fn fit_empirical(samples: &[SoilSample]) -> Result<EmpiricalFit> {
    validate_samples(samples, EMPIRICAL_TERMS)?;
    let n = samples.len();
    let mut gamma = DMatrix::<f64>::zeros(n, EMPIRICAL_TERMS);
    let mut forces = DMatrix::<f64>::zeros(n, 3);
    for (i, s) in samples.iter().enumerate() {
        for (j, x) in EmpiricalSoilModel::features(&s.geometry)
            .into_iter()
            .enumerate()
        {
            gamma[(i, j)] = x;
        }
        forces[(i, 0)] = s.force.fx_n;
        forces[(i, 1)] = s.force.fz_n;
        forces[(i, 2)] = s.force.my_nm;
    }
    // Column scaling makes the rank test independent of the units of each term.
    let mut scale = [1.0; EMPIRICAL_TERMS];
    for (j, s) in scale.iter_mut().enumerate() {
        let norm = gamma.column(j).norm();
        if norm > 0.0 {
            *s = norm;
            gamma.column_mut(j).unscale_mut(norm);
        }
    }
    let svd = gamma.clone().svd(true, true);
    let (max_sv, min_sv) = svd
        .singular_values
        .iter()
        .fold((0.0_f64, f64::INFINITY), |(hi, lo), &s| {
            (hi.max(s), lo.min(s))
        });
    let condition = if min_sv > 0.0 {
        max_sv / min_sv
    } else {
        f64::INFINITY
    };
    let rank = svd
        .singular_values
        .iter()
        .filter(|&&s| s > RANK_TOLERANCE * max_sv)
        .count();
    if rank < EMPIRICAL_TERMS || !condition.is_finite() {
        return Err(EstimateError::RankDeficient { rank, condition });
    }
    let psi = svd
        .solve(&forces, RANK_TOLERANCE * max_sv)
        .map_err(|_| EstimateError::RankDeficient { rank, condition })?; // Eq. 23 via the SVD
    let residual = &gamma * &psi - &forces;
    let mut coef = Matrix3x4::<f64>::zeros();
    for c in 0..3 {
        for j in 0..EMPIRICAL_TERMS {
            coef[(c, j)] = psi[(j, c)] / scale[j];
        }
    }
    if coef.iter().any(|v| !v.is_finite()) {
        return Err(EstimateError::RankDeficient { rank, condition });
    }
    let row = |c: usize| std::array::from_fn(|j| coef[(c, j)]);
    let nf = n as f64;
    let sq = |c: usize| residual.column(c).norm_squared();
    Ok(EmpiricalFit {
        model: EmpiricalSoilModel {
            fx: row(0),
            fz: row(1),
            my: row(2),
        },
        rms_error_n: ((sq(0) + sq(1)) / nf).sqrt(),
        rms_moment_error_nm: (sq(2) / nf).sqrt(),
        condition,
    })
}

/// The box the analytical search stays in.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SoilBounds {
    /// Lower corner.
    pub lower: SoilProperties,
    /// Upper corner.
    pub upper: SoilProperties,
}

impl Default for SoilBounds {
    /// Wide bounds for earth from loose sand to stiff clay: gamma 1000-2500 kg/m^3, beta 15-75 deg,
    /// phi 15-50 deg, delta 5-40 deg, c 0-100 kPa.
    fn default() -> Self {
        Self {
            lower: SoilProperties {
                density_kg_per_m3: 1000.0,
                failure_angle_rad: 15f64.to_radians(),
                friction_angle_rad: 15f64.to_radians(),
                tool_friction_angle_rad: 5f64.to_radians(),
                cohesion_pa: 0.0,
            },
            upper: SoilProperties {
                density_kg_per_m3: 2500.0,
                failure_angle_rad: 75f64.to_radians(),
                friction_angle_rad: 50f64.to_radians(),
                tool_friction_angle_rad: 40f64.to_radians(),
                cohesion_pa: 100e3,
            },
        }
    }
}

impl SoilBounds {
    /// Whether the wedge of Eqs. 14-17 can fail for `geometry` in the soil at the middle of the box:
    /// Eq. 17's denominator `cos(rho + delta) + sin(rho + delta) cot(beta + phi) = sin(beta + phi +
    /// rho + delta) / sin(beta + phi)` is positive there (`rho` the classical rake of Fig. 25,
    /// `-rake_rad`), by [`crate::soil::WEDGE_LIMIT_MARGIN_RAD`] short of the limit where the force
    /// diverges. The static FEE does not describe a bucket whose cutting face is turned further
    /// back (an opened bucket pulled in): a window of such samples leaves the analytical fit a sliver of
    /// the box where every sample is finite, or none ([`EstimateError::NoFeasibleStart`]).
    #[must_use]
    pub fn fee_domain(&self, geometry: &DigGeometry) -> bool {
        let mid = |lo: f64, hi: f64| 0.5 * (lo + hi);
        let angles = mid(self.lower.failure_angle_rad, self.upper.failure_angle_rad)
            + mid(self.lower.friction_angle_rad, self.upper.friction_angle_rad)
            + mid(
                self.lower.tool_friction_angle_rad,
                self.upper.tool_friction_angle_rad,
            );
        let total = angles - geometry.rake_rad;
        total.is_finite()
            && total > crate::soil::WEDGE_LIMIT_MARGIN_RAD
            && total < std::f64::consts::PI - crate::soil::WEDGE_LIMIT_MARGIN_RAD
    }
}

fn to_array(p: &SoilProperties) -> [f64; 5] {
    [
        p.density_kg_per_m3,
        p.failure_angle_rad,
        p.friction_angle_rad,
        p.tool_friction_angle_rad,
        p.cohesion_pa,
    ]
}

fn from_array(a: [f64; 5]) -> SoilProperties {
    SoilProperties {
        density_kg_per_m3: a[0],
        failure_angle_rad: a[1],
        friction_angle_rad: a[2],
        tool_friction_angle_rad: a[3],
        cohesion_pa: a[4],
    }
}

impl SoilBounds {
    /// Checks that both corners are physical ([`SoilProperties::validate`]) and `lower <= upper`.
    ///
    /// # Errors
    /// [`EstimateError::InvalidBounds`].
    pub fn validate(&self) -> Result<()> {
        let bad = |what| Err(EstimateError::InvalidBounds { what });
        if self.lower.validate().is_err() {
            return bad("lower corner outside the physical range");
        }
        if self.upper.validate().is_err() {
            return bad("upper corner outside the physical range");
        }
        if to_array(&self.lower)
            .iter()
            .zip(&to_array(&self.upper))
            .any(|(lo, hi)| lo > hi)
        {
            return bad("lower exceeds upper");
        }
        Ok(())
    }

    /// Whether `psi` lies in the box.
    #[must_use]
    pub fn contains(&self, psi: &SoilProperties) -> bool {
        let (lo, hi, p) = (to_array(&self.lower), to_array(&self.upper), to_array(psi));
        (0..5).all(|i| p[i] >= lo[i] && p[i] <= hi[i])
    }
}

/// Settings of the analytical fit (4.3.4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AnalyticalFitConfig {
    /// Cutting-edge width `w` of Eq. 17, m.
    pub bucket_width_m: f64,
    /// Parameter box.
    pub bounds: SoilBounds,
    /// Simulated-annealing trials (each from a random start); the best seeds Powell's method.
    pub trials: usize,
    /// Moves per trial.
    pub steps_per_trial: usize,
    /// Initial temperature, as a fraction of the trial's starting `J`.
    pub initial_temperature: f64,
    /// Cooling factor `k` of Eq. 24: the temperature after `n` moves is `T0 / (1 + k n)`.
    pub cooling: f64,
    /// Initial move size, as a fraction of each parameter's range; it shrinks linearly to a tenth.
    pub initial_step: f64,
    /// Largest number of Powell iterations (each a line search along every direction).
    pub powell_iterations: usize,
    /// Relative decrease of `J` below which Powell's method stops.
    pub tolerance: f64,
    /// Seed; the fit is deterministic for a seed.
    pub seed: u64,
}

impl Default for AnalyticalFitConfig {
    fn default() -> Self {
        Self {
            bucket_width_m: 1.5,
            bounds: SoilBounds::default(),
            trials: 4,
            steps_per_trial: 400,
            initial_temperature: 0.2,
            cooling: 0.05,
            initial_step: 0.25,
            powell_iterations: 10,
            tolerance: 1e-7,
            seed: 1,
        }
    }
}

impl AnalyticalFitConfig {
    fn validate(&self) -> Result<()> {
        let bad = |field, reason| Err(EstimateError::InvalidConfig { field, reason });
        if !(self.bucket_width_m.is_finite() && self.bucket_width_m > 0.0) {
            return bad("bucket_width_m", "must be positive and finite");
        }
        if self.trials == 0 {
            return bad("trials", "must be at least 1");
        }
        for (field, v) in [
            ("initial_temperature", self.initial_temperature),
            ("initial_step", self.initial_step),
            ("tolerance", self.tolerance),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, "must be positive and finite");
            }
        }
        if !(self.cooling.is_finite() && self.cooling >= 0.0) {
            return bad("cooling", "must be non-negative and finite");
        }
        self.bounds.validate()
    }
}

/// The analytical model fitted to a window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AnalyticalFit {
    /// Estimated `Psi = (gamma, beta, phi, delta, c)`.
    pub properties: SoilProperties,
    /// `J`: RMS `(F_x, F_z)` force error on the window, N.
    pub rms_error_n: f64,
    /// `J` after simulated annealing alone, N.
    pub annealing_rms_error_n: f64,
    /// Evaluations of `J`.
    pub evaluations: usize,
}

/// One sample with everything that does not depend on `Psi` precomputed, so that `J` costs a few
/// multiplications per sample. [`fee_tip_force`] is the reference: `tests::objective_matches_soil_model`
/// checks this copy of Eqs. 17-18 against it.
#[derive(Debug, Clone, Copy)]
struct Precomputed {
    d: f64,
    d2: f64,
    vs: f64,
    cos_alpha: f64,
    sin_alpha: f64,
    tan_alpha: f64,
    cos_rake: f64,
    sin_rake: f64,
    sin_rho_alpha: f64,
    cos_rho_alpha: f64,
    fx: f64,
    fz: f64,
}

impl Precomputed {
    fn new(s: &SoilSample) -> Self {
        let g = &s.geometry;
        let rho_c = -g.rake_rad; // the classical rake of Fig. 25, as in soil::fee_factors
        let rho_alpha = g.rake_rad - g.slope_rad; // Eq. 18
        Self {
            d: g.depth_m,
            d2: g.depth_m * g.depth_m,
            vs: g.swept_volume_m3,
            cos_alpha: g.slope_rad.cos(),
            sin_alpha: g.slope_rad.sin(),
            tan_alpha: g.slope_rad.tan(),
            cos_rake: rho_c.cos(),
            sin_rake: rho_c.sin(),
            sin_rho_alpha: rho_alpha.sin(),
            cos_rho_alpha: rho_alpha.cos(),
            fx: s.force.fx_n,
            fz: s.force.fz_n,
        }
    }
}

/// The objective `J` of 4.3.4 over precomputed samples.
struct Objective<'a> {
    samples: &'a [Precomputed],
    width_m: f64,
    lower: [f64; 5],
    range: [f64; 5],
    evaluations: usize,
}

impl Objective<'_> {
    fn params(&self, u: &[f64; 5]) -> [f64; 5] {
        std::array::from_fn(|i| self.lower[i] + u[i].clamp(0.0, 1.0) * self.range[i])
    }

    /// `J(Psi)`, the RMS force error in `x` and `z` (4.3.4), for `Psi` at unit-box coordinates `u`;
    /// infinite where the wedge of Eqs. 14-17 cannot fail for some sample.
    fn eval(&mut self, u: &[f64; 5]) -> f64 {
        self.evaluations += 1;
        let [density, beta, phi, delta, cohesion] = self.params(u);
        let bp = beta + phi;
        let (sin_beta, sin_bp) = (beta.sin(), bp.sin());
        if sin_beta.abs() < FEE_EPS || sin_bp.abs() < FEE_EPS {
            return f64::INFINITY;
        }
        let cot_beta = beta.cos() / sin_beta;
        let cot_bp = bp.cos() / sin_bp;
        let (sin_d, cos_d) = delta.sin_cos();
        let weight = density * GRAVITY_M_PER_S2;
        let w = self.width_m;
        let n_c_num = 1.0 + cot_beta * cot_bp;
        let mut sum = 0.0;
        for s in self.samples {
            let cos_rd = s.cos_rake * cos_d - s.sin_rake * sin_d; // cos(rho + delta)
            let sin_rd = s.sin_rake * cos_d + s.cos_rake * sin_d; // sin(rho + delta)
            let den = cos_rd + sin_rd * cot_bp; // Eq. 17 denominator
            if den < FEE_EPS {
                return f64::INFINITY;
            }
            let slope = s.cos_alpha + s.sin_alpha * cot_bp;
            let wedge = (cot_beta - s.tan_alpha).max(0.0); // Eq. 15
            // Eq. 17: F = d^2 w gamma g N_w + c w d N_c + V_s gamma g N_q
            let f = (s.d2 * w * weight * wedge * slope * 0.5
                + cohesion * w * s.d * n_c_num
                + s.vs * weight * slope)
                / den;
            let f = f.max(0.0);
            // Eq. 18, negated: the soil's force on the bucket.
            let fx = -f * (cos_d * s.sin_rho_alpha - sin_d * s.cos_rho_alpha);
            let fz = -f * (cos_d * s.cos_rho_alpha + sin_d * s.sin_rho_alpha);
            sum += (fx - s.fx).powi(2) + (fz - s.fz).powi(2);
        }
        let j = (sum / self.samples.len().max(1) as f64).sqrt();
        if j.is_finite() { j } else { f64::INFINITY }
    }
}

/// Moves `x` back into `[0, 1]` by reflection at the walls.
fn reflect(x: f64) -> f64 {
    let x = if x < 0.0 { -x } else { x };
    let x = if x > 1.0 { 2.0 - x } else { x };
    x.clamp(0.0, 1.0)
}

/// One trial of simulated annealing from a random feasible start (4.3.4). Returns the best point and
/// its `J`, or `None` if no feasible start was found.
fn anneal(
    obj: &mut Objective<'_>,
    config: &AnalyticalFitConfig,
    rng: &mut ChaCha8Rng,
) -> Option<([f64; 5], f64)> {
    const START_TRIES: usize = 200;
    let mut start = None;
    for _ in 0..START_TRIES {
        let u: [f64; 5] = std::array::from_fn(|_| rng.random_range(0.0..=1.0));
        let j = obj.eval(&u);
        if j.is_finite() {
            start = Some((u, j));
            break;
        }
    }
    let (mut u, mut j1) = start?;
    let mut best = (u, j1);
    // Temperatures relative to the starting error, so the schedule does not depend on force units.
    let j_ref = j1.max(f64::MIN_POSITIVE);
    let steps = config.steps_per_trial.max(1);
    for n in 0..steps {
        let frac = n as f64 / steps as f64;
        let step = config.initial_step * (1.0 - 0.9 * frac);
        let mut cand = u;
        for x in &mut cand {
            *x = reflect(*x + step * rng.random_range(-1.0..=1.0));
        }
        let j2 = obj.eval(&cand);
        if !j2.is_finite() {
            continue;
        }
        // Eq. 24: accept a worse set with probability exp(-(J2 - J1) / kT). The thesis lets the
        // probability fall as the trials accumulate; here the temperature kT = T0 / (1 + k n).
        let temperature = config.initial_temperature / (1.0 + config.cooling * n as f64);
        let accept =
            j2 <= j1 || rng.random_range(0.0..1.0) < (-(j2 - j1) / (j_ref * temperature)).exp();
        if accept {
            u = cand;
            j1 = j2;
            if j1 < best.1 {
                best = (u, j1);
            }
        }
    }
    Some(best)
}

/// A line search stops when the best step is within this of both ends of its bracket (the unit box's
/// coordinates are of order one).
const LINE_SEARCH_TOLERANCE: f64 = 2e-4;
/// At most this many evaluations of `J` per line search.
const LINE_SEARCH_ITERATIONS: usize = 40;

/// Minimises `J` along `dir` from `p` inside the unit box. Updates `p` and returns the new `J`.
fn line_minimise(obj: &mut Objective<'_>, p: &mut [f64; 5], dir: &[f64; 5], fp: f64) -> f64 {
    let (mut t_lo, mut t_hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for (x, d) in p.iter().zip(dir) {
        if d.abs() > 1e-12 {
            let (a, b) = ((0.0 - x) / d, (1.0 - x) / d);
            t_lo = t_lo.max(a.min(b));
            t_hi = t_hi.min(a.max(b));
        }
    }
    if !(t_lo.is_finite() && t_hi.is_finite()) || t_hi - t_lo < 1e-12 {
        return fp;
    }
    let base = *p;
    let at =
        |t: f64| -> [f64; 5] { std::array::from_fn(|i| (base[i] + t * dir[i]).clamp(0.0, 1.0)) };
    let (t, ft) = brent(
        &mut |t| obj.eval(&at(t)),
        (t_lo, t_hi),
        [(0.0, fp); 3],
        LINE_SEARCH_TOLERANCE,
        LINE_SEARCH_ITERATIONS,
    );
    if ft < fp {
        *p = at(t);
        ft
    } else {
        fp
    }
}

/// Powell's conjugate-direction method (Press et al., as cited in 4.3.4) in the unit box.
fn powell(
    obj: &mut Objective<'_>,
    start: [f64; 5],
    f_start: f64,
    config: &AnalyticalFitConfig,
) -> ([f64; 5], f64) {
    let mut dirs: [[f64; 5]; 5] =
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 }));
    let (mut p, mut fp) = (start, f_start);
    for _ in 0..config.powell_iterations {
        let (p0, f0) = (p, fp);
        let (mut biggest, mut i_big) = (0.0, 0);
        for (i, dir) in dirs.iter().enumerate() {
            let before = fp;
            fp = line_minimise(obj, &mut p, dir, fp);
            if before - fp > biggest {
                biggest = before - fp;
                i_big = i;
            }
        }
        if 2.0 * (f0 - fp) <= config.tolerance * (f0.abs() + fp.abs()) + 1e-12 {
            break;
        }
        let new_dir: [f64; 5] = std::array::from_fn(|i| p[i] - p0[i]);
        let extrapolated: [f64; 5] = std::array::from_fn(|i| (2.0 * p[i] - p0[i]).clamp(0.0, 1.0));
        let fe = obj.eval(&extrapolated);
        if fe < f0 {
            let t = 2.0 * (f0 - 2.0 * fp + fe) * (f0 - fp - biggest).powi(2)
                - biggest * (f0 - fe).powi(2);
            if t < 0.0 {
                fp = line_minimise(obj, &mut p, &new_dir, fp);
                dirs[i_big] = dirs[4];
                dirs[4] = new_dir;
            }
        }
    }
    (p, fp)
}

/// Fits the analytical (modified FEE) model: several simulated-annealing trials, then Powell's method
/// from the best (4.3.4), minimising `J`, the RMS `(F_x, F_z)` force error, inside `config.bounds`.
///
/// # Errors
/// [`EstimateError::EmptyWindow`], [`EstimateError::TooFewSamples`] (fewer than five),
/// [`EstimateError::NonFiniteSample`], [`EstimateError::InvalidSample`],
/// [`EstimateError::InvalidConfig`], [`EstimateError::InvalidBounds`],
/// [`EstimateError::NoFeasibleStart`] when no trial finds a finite `J`.
pub fn fit_analytical(
    samples: &[SoilSample],
    config: &AnalyticalFitConfig,
) -> Result<AnalyticalFit> {
    config.validate()?;
    validate_samples(samples, 5)?;
    let pre: Vec<Precomputed> = samples.iter().map(Precomputed::new).collect();
    let lower = to_array(&config.bounds.lower);
    let upper = to_array(&config.bounds.upper);
    let mut obj = Objective {
        samples: &pre,
        width_m: config.bucket_width_m,
        lower,
        range: std::array::from_fn(|i| upper[i] - lower[i]),
        evaluations: 0,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut best: Option<([f64; 5], f64)> = None;
    for _ in 0..config.trials {
        if let Some((u, j)) = anneal(&mut obj, config, &mut rng)
            && best.is_none_or(|(_, jb)| j < jb)
        {
            best = Some((u, j));
        }
    }
    let (u, j_anneal) = best.ok_or(EstimateError::NoFeasibleStart)?;
    let (u, j) = powell(&mut obj, u, j_anneal, config);
    let properties = from_array(obj.params(&u));
    // Clamping to the box keeps the result physical; check it anyway rather than trust arithmetic.
    if !config.bounds.contains(&properties) || properties.validate().is_err() || !j.is_finite() {
        return Err(EstimateError::NoFeasibleStart);
    }
    Ok(AnalyticalFit {
        properties,
        rms_error_n: j,
        annealing_rms_error_n: j_anneal,
        evaluations: obj.evaluations,
    })
}

/// `J` of given properties on a window: the RMS `(F_x, F_z)` force error, N, computed with
/// [`fee_tip_force`].
///
/// # Errors
/// Sample errors as [`fit_analytical`]; [`EstimateError::Soil`] where the model is singular.
pub fn analytical_rms_error_n(
    samples: &[SoilSample],
    properties: &SoilProperties,
    bucket_width_m: f64,
) -> Result<f64> {
    validate_samples(samples, 1)?;
    let mut sum = 0.0;
    for s in samples {
        let f = fee_tip_force(properties, &s.geometry, bucket_width_m, 0.0)?;
        sum += (f.fx_n - s.force.fx_n).powi(2) + (f.fz_n - s.force.fz_n).powi(2);
    }
    Ok((sum / samples.len() as f64).sqrt())
}

/// A sliding window of the most recent samples (4.3.5: about 300).
#[derive(Debug, Clone, PartialEq)]
pub struct SoilWindow {
    capacity: usize,
    samples: VecDeque<SoilSample>,
}

impl SoilWindow {
    /// An empty window holding at most `capacity` samples (at least one).
    #[must_use]
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            capacity,
            // A huge capacity must not allocate (or abort) up front.
            samples: VecDeque::with_capacity(capacity.min(4096)),
        }
    }

    /// Adds a sample, dropping the oldest when full.
    pub fn push(&mut self, sample: SoilSample) {
        if self.samples.len() == self.capacity {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
    }

    /// Samples held.
    #[must_use]
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether the window is empty.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The samples, oldest first, without making them contiguous.
    pub fn iter(&self) -> impl Iterator<Item = &SoilSample> {
        self.samples.iter()
    }

    /// The samples, oldest first.
    pub fn samples(&mut self) -> &[SoilSample] {
        self.samples.make_contiguous()
    }

    /// [`fit_empirical`] on the window.
    ///
    /// # Errors
    /// As [`fit_empirical`].
    pub fn fit_empirical(&mut self) -> Result<EmpiricalFit> {
        fit_empirical(self.samples())
    }

    /// [`fit_analytical`] on the window.
    ///
    /// # Errors
    /// As [`fit_analytical`].
    pub fn fit_analytical(&mut self, config: &AnalyticalFitConfig) -> Result<AnalyticalFit> {
        fit_analytical(self.samples(), config)
    }
}

/// Which soil model to cross-validate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum SoilModelKind {
    /// The empirical model (Eq. 21) by least squares.
    Empirical,
    /// The modified FEE (Eqs. 14-19) by annealing and Powell's method.
    Analytical(AnalyticalFitConfig),
}

/// A soil model with estimated properties, ready to predict forces.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum FittedSoilModel {
    /// Empirical coefficients (Eq. 21).
    Empirical(EmpiricalSoilModel),
    /// Modified FEE properties (Eqs. 14-19) and the bucket width, m.
    Analytical {
        /// Estimated `Psi`.
        properties: SoilProperties,
        /// Cutting-edge width, m.
        bucket_width_m: f64,
    },
}

impl FittedSoilModel {
    /// Fits `kind` to `samples` ([`fit_empirical`] or [`fit_analytical`]).
    ///
    /// # Errors
    /// As the fit.
    pub fn fit(samples: &[SoilSample], kind: &SoilModelKind) -> Result<Self> {
        Ok(match kind {
            SoilModelKind::Empirical => Self::Empirical(fit_empirical(samples)?.model),
            SoilModelKind::Analytical(config) => Self::Analytical {
                properties: fit_analytical(samples, config)?.properties,
                bucket_width_m: config.bucket_width_m,
            },
        })
    }

    /// Predicted soil force on the bucket (base frame). `centroid_offset_x_m` is the payload centroid's
    /// offset from the tip for the analytical model's moment (Eq. 19); the empirical model ignores it.
    ///
    /// # Errors
    /// [`EstimateError::Soil`] for non-finite input or a singular FEE geometry.
    pub fn predict(&self, geometry: &DigGeometry, centroid_offset_x_m: f64) -> Result<TipForce> {
        Ok(match self {
            Self::Empirical(model) => model.evaluate(geometry)?,
            Self::Analytical {
                properties,
                bucket_width_m,
            } => fee_tip_force(properties, geometry, *bucket_width_m, centroid_offset_x_m)?,
        })
    }
}

/// Prediction error of one dig in [`cross_validate`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigError {
    /// Dig index.
    pub dig: usize,
    /// Samples predicted.
    pub samples: usize,
    /// Samples the fitted model could not evaluate (singular FEE geometry, Eq. 17), not predicted.
    #[serde(default)]
    pub unpredictable: usize,
    /// Samples in the estimation window.
    pub window_samples: usize,
    /// Mean absolute error of the force magnitude `|(F_x, F_z)|`, N.
    pub mae_n: f64,
}

/// Result of [`cross_validate`] (the thesis's Fig. 31 figures).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrossValidationReport {
    /// Per-dig errors.
    pub digs: Vec<DigError>,
    /// Mean absolute force-magnitude error over all predicted samples, N.
    pub mae_n: f64,
    /// Standard deviation of the absolute error, N.
    pub std_n: f64,
    /// Peak measured force magnitude, N.
    pub peak_force_n: f64,
    /// `mae_n` as a percentage of the peak (thesis: about 10 %).
    pub mae_percent_of_peak: f64,
}

/// The thesis's cross-validation (4.3.5): for each dig, estimates the soil properties on the
/// `window_samples` samples just before it (wrapping round to the last digs for the first ones, never
/// including the dig itself), predicts the dig, and reports the mean absolute error of the force magnitude
/// `|(F_x, F_z)|` as a percentage of the peak measured force. Digs run in parallel with the crate's
/// `parallel` feature; the result is deterministic either way.
///
/// # Errors
/// [`EstimateError::NotEnoughDigs`] (fewer than two), [`EstimateError::InvalidConfig`] for a zero
/// window, and the fit errors. Samples the fitted model cannot evaluate are counted in
/// [`DigError::unpredictable`], not errors.
pub fn cross_validate(
    digs: &[Vec<SoilSample>],
    window_samples: usize,
    model: &SoilModelKind,
) -> Result<CrossValidationReport> {
    if digs.len() < 2 {
        return Err(EstimateError::NotEnoughDigs {
            count: digs.len(),
            needed: 2,
        });
    }
    if window_samples == 0 {
        return Err(EstimateError::InvalidConfig {
            field: "window_samples",
            reason: "must be positive",
        });
    }
    for dig in digs {
        validate_samples(dig, 0).or_else(|e| {
            if e == EstimateError::EmptyWindow {
                Ok(())
            } else {
                Err(e)
            }
        })?;
    }
    let total_samples = digs.iter().map(Vec::len).sum::<usize>();
    let per_dig: Vec<(DigError, Vec<f64>)> =
        crate::par::map_indices(digs.len(), |i| -> Result<(DigError, Vec<f64>)> {
            // Walk back from dig i - 1, wrapping, until the window is full; oldest first.
            let mut window: Vec<SoilSample> = Vec::with_capacity(window_samples.min(total_samples));
            for back in 1..digs.len() {
                let dig = &digs[(i + digs.len() - back) % digs.len()];
                let take = (window_samples - window.len()).min(dig.len());
                window.splice(0..0, dig[dig.len() - take..].iter().copied());
                if window.len() == window_samples {
                    break;
                }
            }
            let fitted = FittedSoilModel::fit(&window, model)?;
            let predict = |g: &DigGeometry| fitted.predict(g, 0.0);
            // A sample whose geometry the fitted model cannot evaluate (the static FEE's wedge
            // cannot fail there, Eq. 17) is not predicted; it is counted.
            let mut unpredictable = 0;
            let mut errors = Vec::with_capacity(digs[i].len());
            for s in &digs[i] {
                match predict(&s.geometry) {
                    Ok(f) => {
                        errors.push((f.force_magnitude_n() - s.force.force_magnitude_n()).abs())
                    }
                    Err(EstimateError::Soil(_)) => unpredictable += 1,
                    Err(e) => return Err(e),
                }
            }
            let mae_n = if errors.is_empty() {
                0.0
            } else {
                errors.iter().sum::<f64>() / errors.len() as f64
            };
            Ok((
                DigError {
                    dig: i,
                    samples: errors.len(),
                    unpredictable,
                    window_samples: window.len(),
                    mae_n,
                },
                errors,
            ))
        })
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let all: Vec<f64> = per_dig
        .iter()
        .flat_map(|(_, e)| e.iter().copied())
        .collect();
    let n = all.len().max(1) as f64;
    let mae_n = all.iter().sum::<f64>() / n;
    let std_n = (all.iter().map(|e| (e - mae_n).powi(2)).sum::<f64>() / n).sqrt();
    let peak_force_n = digs
        .iter()
        .flatten()
        .map(|s| s.force.force_magnitude_n())
        .fold(0.0, f64::max);
    Ok(CrossValidationReport {
        digs: per_dig.into_iter().map(|(d, _)| d).collect(),
        mae_n,
        std_n,
        peak_force_n,
        mae_percent_of_peak: if peak_force_n > 0.0 {
            100.0 * mae_n / peak_force_n
        } else {
            0.0
        },
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    use crate::synthetic::{
        FEE_BUCKET_WIDTH_M as WIDTH_M, FEE_DIG_SAMPLES as DIG_SAMPLES, dig_geometries, fee_digs,
        fee_soil as psi_true, with_noise,
    };

    const EMPIRICAL_TRUE: EmpiricalSoilModel = EmpiricalSoilModel {
        fx: [40e3, 15e3, 20e3, 30e3],
        fz: [-30e3, -10e3, 5e3, -25e3],
        my: [2e3, -1e3, 3e3, 8e3],
    };

    fn empirical_window(noise_n: f64, seed: u64) -> Vec<SoilSample> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..6)
            .flat_map(|_| dig_geometries(&mut rng))
            .collect::<Vec<_>>()
            .into_iter()
            .map(|geometry| SoilSample {
                geometry,
                force: with_noise(
                    EMPIRICAL_TRUE.evaluate(&geometry).unwrap(),
                    &mut rng,
                    noise_n,
                ),
            })
            .collect()
    }

    #[test]
    fn objective_matches_soil_model() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let bounds = SoilBounds::default();
        for _ in 0..200 {
            let geometry = dig_geometries(&mut rng)[rng.random_range(0..DIG_SAMPLES)];
            let u: [f64; 5] = std::array::from_fn(|_| rng.random_range(0.0..=1.0));
            let lower = to_array(&bounds.lower);
            let range: [f64; 5] = std::array::from_fn(|i| to_array(&bounds.upper)[i] - lower[i]);
            let sample = SoilSample {
                geometry,
                force: TipForce::default(),
            };
            let pre = [Precomputed::new(&sample)];
            let mut obj = Objective {
                samples: &pre,
                width_m: WIDTH_M,
                lower,
                range,
                evaluations: 0,
            };
            let j = obj.eval(&u);
            let psi = from_array(obj.params(&u));
            match fee_tip_force(&psi, &geometry, WIDTH_M, 0.0) {
                Ok(f) => {
                    let reference = f.force_magnitude_n();
                    assert!(
                        (j - reference).abs() <= 1e-9 * reference.max(1.0),
                        "{j} vs {reference}"
                    );
                }
                Err(_) => assert!(j.is_infinite()),
            }
        }
    }

    #[test]
    fn empirical_fit_recovers_known_coefficients() {
        let noise = 500.0;
        let window = empirical_window(noise, 1);
        assert_eq!(window.len(), DEFAULT_WINDOW_SAMPLES);
        let fit = fit_empirical(&window).unwrap();
        for (got, want) in [
            (fit.model.fx, EMPIRICAL_TRUE.fx),
            (fit.model.fz, EMPIRICAL_TRUE.fz),
            (fit.model.my, EMPIRICAL_TRUE.my),
        ] {
            for (g, w) in got.iter().zip(&want) {
                // Within 3 % of the largest coefficient: noise is 1-2 % of the forces.
                assert!((g - w).abs() < 0.03 * 40e3, "{got:?} vs {want:?}");
            }
        }
        // Uniform noise of +-500 N has an RMS of 289 N per component, 408 N for (x, z).
        assert!(fit.rms_error_n < 450.0, "{}", fit.rms_error_n);
        let exact = fit_empirical(&empirical_window(0.0, 1)).unwrap();
        for (g, w) in exact.model.fx.iter().zip(&EMPIRICAL_TRUE.fx) {
            assert!((g - w).abs() < 1e-6 * w.abs());
        }
    }

    #[test]
    fn analytical_fit_recovers_known_soil() {
        let noise = 1000.0;
        let window: Vec<SoilSample> = fee_digs(6, noise, 2).into_iter().flatten().collect();
        let fit = fit_analytical(
            &window,
            &AnalyticalFitConfig {
                bucket_width_m: WIDTH_M,
                ..Default::default()
            },
        )
        .unwrap();
        let noise_rms = noise * (2.0_f64 / 3.0).sqrt();
        assert!(fit.rms_error_n < 1.1 * noise_rms, "{fit:?}");
        assert!(fit.rms_error_n <= fit.annealing_rms_error_n);
        let reference = analytical_rms_error_n(&window, &fit.properties, WIDTH_M).unwrap();
        assert!((reference - fit.rms_error_n).abs() < 1e-6 * reference);
        let (p, t) = (fit.properties, psi_true());
        assert!(
            (p.density_kg_per_m3 - t.density_kg_per_m3).abs() < 0.15 * t.density_kg_per_m3,
            "{p:?}"
        );
        assert!(
            (p.cohesion_pa - t.cohesion_pa).abs() < 0.15 * t.cohesion_pa,
            "{p:?}"
        );
        for (got, want) in [
            (p.failure_angle_rad, t.failure_angle_rad),
            (p.friction_angle_rad, t.friction_angle_rad),
            (p.tool_friction_angle_rad, t.tool_friction_angle_rad),
        ] {
            assert!((got - want).abs() < 5f64.to_radians(), "{p:?}");
        }
    }

    #[test]
    fn fits_are_deterministic_for_a_seed() {
        let window: Vec<SoilSample> = fee_digs(6, 1000.0, 3).into_iter().flatten().collect();
        let config = AnalyticalFitConfig {
            bucket_width_m: WIDTH_M,
            steps_per_trial: 100,
            ..Default::default()
        };
        let a = fit_analytical(&window, &config).unwrap();
        let b = fit_analytical(&window, &config).unwrap();
        assert_eq!(a, b);
        assert_eq!(
            fit_empirical(&window).unwrap(),
            fit_empirical(&window).unwrap()
        );
    }

    #[test]
    fn degenerate_windows_give_typed_errors() {
        let config = AnalyticalFitConfig::default();
        assert_eq!(fit_empirical(&[]), Err(EstimateError::EmptyWindow));
        assert_eq!(
            fit_analytical(&[], &config),
            Err(EstimateError::EmptyWindow)
        );
        let window = empirical_window(100.0, 5);
        assert!(matches!(
            fit_empirical(&window[..3]),
            Err(EstimateError::TooFewSamples {
                count: 3,
                needed: 4
            })
        ));
        let mut nan = window.clone();
        nan[7].force.fz_n = f64::NAN;
        assert_eq!(
            fit_empirical(&nan),
            Err(EstimateError::NonFiniteSample { index: 7 })
        );
        assert_eq!(
            fit_analytical(&nan, &config),
            Err(EstimateError::NonFiniteSample { index: 7 })
        );
        let mut negative = window.clone();
        negative[2].geometry.depth_m = -1.0;
        assert!(matches!(
            fit_empirical(&negative),
            Err(EstimateError::InvalidSample { index: 2, .. })
        ));
        // Flat terrain throughout: the alpha column of Gamma is zero.
        let mut flat = window.clone();
        flat.iter_mut().for_each(|s| s.geometry.slope_rad = 0.0);
        assert!(matches!(
            fit_empirical(&flat),
            Err(EstimateError::RankDeficient { rank: 3, .. })
        ));
        // One repeated sample: rank 1.
        let same = vec![window[10]; 50];
        assert!(matches!(
            fit_empirical(&same),
            Err(EstimateError::RankDeficient { rank: 1, .. })
        ));
        let mut bad = config;
        bad.bounds.lower.failure_angle_rad = -0.1;
        assert!(matches!(
            fit_analytical(&window, &bad),
            Err(EstimateError::InvalidBounds { .. })
        ));
        let mut bad = config;
        bad.bounds.lower.cohesion_pa = 2e5;
        assert!(matches!(
            fit_analytical(&window, &bad),
            Err(EstimateError::InvalidBounds { .. })
        ));
        let bad = AnalyticalFitConfig {
            bucket_width_m: f64::NAN,
            ..config
        };
        assert!(matches!(
            fit_analytical(&window, &bad),
            Err(EstimateError::InvalidConfig { .. })
        ));
        let bad = AnalyticalFitConfig {
            trials: 0,
            ..config
        };
        assert!(matches!(
            fit_analytical(&window, &bad),
            Err(EstimateError::InvalidConfig { .. })
        ));
        // Forces that no soil explains still give a finite fit, never NaN.
        let mut wild = window.clone();
        wild.iter_mut().for_each(|s| s.force.fx_n = 1e12);
        let fit = fit_analytical(
            &wild,
            &AnalyticalFitConfig {
                steps_per_trial: 50,
                ..config
            },
        )
        .unwrap();
        assert!(fit.rms_error_n.is_finite() && config.bounds.contains(&fit.properties));
    }

    #[test]
    fn sliding_window_keeps_the_latest_samples() {
        let samples = empirical_window(0.0, 6);
        let mut window = SoilWindow::new(100);
        assert!(window.is_empty());
        for s in &samples {
            window.push(*s);
        }
        assert_eq!(window.len(), 100);
        assert_eq!(window.samples(), &samples[samples.len() - 100..]);
        assert!(window.fit_empirical().is_ok());
    }

    #[test]
    fn cross_validation_reports_percent_of_peak() {
        let digs = fee_digs(10, 1000.0, 8);
        let report =
            cross_validate(&digs, DEFAULT_WINDOW_SAMPLES, &SoilModelKind::Empirical).unwrap();
        assert_eq!(report.digs.len(), 10);
        assert!(
            report
                .digs
                .iter()
                .all(|d| d.window_samples == DEFAULT_WINDOW_SAMPLES && d.samples == DIG_SAMPLES)
        );
        assert!(
            report.mae_percent_of_peak > 0.0 && report.mae_percent_of_peak < 10.0,
            "{report:?}"
        );
        let config = AnalyticalFitConfig {
            bucket_width_m: WIDTH_M,
            steps_per_trial: 200,
            ..Default::default()
        };
        let analytical = cross_validate(
            &digs,
            DEFAULT_WINDOW_SAMPLES,
            &SoilModelKind::Analytical(config),
        )
        .unwrap();
        assert!(analytical.mae_percent_of_peak < 5.0, "{analytical:?}");
        assert!(matches!(
            cross_validate(&digs[..1], 300, &SoilModelKind::Empirical),
            Err(EstimateError::NotEnoughDigs { .. })
        ));
        // Windows smaller than the other digs together wrap round without the predicted dig.
        let small = cross_validate(&digs[..3], usize::MAX, &SoilModelKind::Empirical).unwrap();
        assert!(
            small
                .digs
                .iter()
                .all(|d| d.window_samples == 2 * DIG_SAMPLES)
        );
    }
}
