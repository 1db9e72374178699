//! The refined dig location planner (thesis 5.1.1.2, Figs. 45-48) and the dig quality (Fig. 46).
//!
//! A region is discretised into candidate starts `(d, alpha)` (Fig. 45): `d` is the distance of the
//! bucket tip from the region's near radial boundary along its centre line (20 cm steps), `alpha` the
//! angle of the bucket (pin -> tip line) from the inward normal of the local terrain profile (5 degree
//! steps), with the tip on the surface. Each candidate is checked against the **kinematic reachability
//! constraint** (inverse kinematics, joint limits, cylinder strokes); the reachable ones are run through
//! the forward dig model ([`crate::dig_model::DigModel::evaluate_many`], in parallel with the crate's
//! `parallel` feature) and those whose predicted dig goes below the desired floor violate the
//! **geometric shape constraint**. The others are scored by the dig quality and the planner picks the
//! best (an exhaustive search).
//!
//! Dig quality (Fig. 46): `Quality = w_v xi(V) + w_t psi(T) + w_e zeta(E)` with `w_v = 3`, `w_t = 2`,
//! `w_e = 1`, and zero when any factor is zero (the veto of the thesis's footnote). The piecewise-linear
//! factors, as read from Fig. 46 and its text:
//!
//! - `xi(V)`: 0 below `V_min`, rising linearly to `xi_max` at `V_max` (the bucket capacity), flat above;
//! - `psi(T)`: maximal at zero and falling linearly, `psi_max (1 - T / T_max)`, inside the acceptable
//!   range `[T_min, T_max)`, 0 outside it (a dig shorter than `T_min` ended abnormally);
//! - `zeta(E)`: `zeta_max (1 - E / E_max)` below `E_max`, 0 above.

use super::region::DigRegion;
use super::{PlanError, Result, non_negative, positive};
use crate::dig_model::{ActuatorDynamics, DigModel, DigModelError, DigSite, DigStart, DigSummary};
use crate::kinematics::{BucketPose, JointAngles, Kinematics, MachinePose};
use crate::terrain::{GapFill, TerrainGrid};
use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;

/// Most candidates one region may have (guards the allocation).
pub const MAX_CANDIDATES: usize = 20_000;

/// Refined planner settings (Fig. 45).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefinedConfig {
    /// Resolution of `d`, m. Default 0.2 (Fig. 45: "approximately 20 cm").
    pub d_step_m: f64,
    /// Resolution of `alpha`. Default 5 deg (Fig. 45).
    #[serde(rename = "alpha_step_deg", with = "crate::machine::degrees")]
    pub alpha_step_rad: f64,
    /// Smallest `alpha` (bucket rotated toward the machine from the surface normal). Default -10 deg.
    #[serde(rename = "alpha_min_deg", with = "crate::machine::degrees")]
    pub alpha_min_rad: f64,
    /// Largest `alpha`. Default 40 deg.
    #[serde(rename = "alpha_max_deg", with = "crate::machine::degrees")]
    pub alpha_max_rad: f64,
    /// The start tip sits this far below the surface (Autodig starts in Pre-Dig with the bucket on the
    /// terrain, thesis 4.1), m. Default 0.02.
    pub tip_depth_m: f64,
    /// The dig site's section starts this far from the swing axis (the tip moves toward the machine
    /// during a dig and must stay on the section), m. Default 1.0.
    pub section_start_m: f64,
    /// The section runs this far beyond the far boundary, m. Default 1.0.
    pub section_margin_m: f64,
    /// Section sample spacing, m. Default 0.05.
    pub section_step_m: f64,
    /// Starts with the bucket curled past this absolute angle (to the horizontal) are not evaluated
    /// ([`CandidateStatus::CurledStart`]): Autodig's Dig stage ends at `rho2` (-180 deg) and a start
    /// curled close to it ends after a short drag. Default -180 deg (no limit).
    #[serde(rename = "bucket_abs_min_deg", with = "crate::machine::degrees")]
    pub bucket_abs_min_rad: f64,
}

impl Default for RefinedConfig {
    fn default() -> Self {
        Self {
            d_step_m: 0.2,
            alpha_step_rad: 5f64.to_radians(),
            alpha_min_rad: (-10f64).to_radians(),
            alpha_max_rad: 40f64.to_radians(),
            tip_depth_m: 0.02,
            section_start_m: 1.0,
            section_margin_m: 1.0,
            section_step_m: 0.05,
            bucket_abs_min_rad: (-180f64).to_radians(),
        }
    }
}

impl RefinedConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        positive("refined.d_step_m", self.d_step_m)?;
        positive("refined.alpha_step_deg", self.alpha_step_rad)?;
        for (f, v) in [
            ("refined.alpha_min_deg", self.alpha_min_rad),
            ("refined.alpha_max_deg", self.alpha_max_rad),
        ] {
            if !(v.is_finite() && v.abs() < FRAC_PI_2) {
                return Err(PlanError::Config {
                    field: f,
                    reason: "must lie in (-90, 90) degrees".to_owned(),
                });
            }
        }
        if self.alpha_max_rad < self.alpha_min_rad {
            return Err(PlanError::Config {
                field: "refined.alpha_max_deg",
                reason: "must not be below alpha_min_deg".to_owned(),
            });
        }
        if (self.alpha_max_rad - self.alpha_min_rad) / self.alpha_step_rad > 1000.0 {
            return Err(PlanError::Config {
                field: "refined.alpha_step_deg",
                reason: "too fine for the alpha range".to_owned(),
            });
        }
        super::finite("refined.bucket_abs_min_deg", self.bucket_abs_min_rad)?;
        non_negative("refined.tip_depth_m", self.tip_depth_m)?;
        positive("refined.section_start_m", self.section_start_m)?;
        non_negative("refined.section_margin_m", self.section_margin_m)?;
        positive("refined.section_step_m", self.section_step_m)
    }

    /// The candidate `alpha` values, rad, rising.
    #[must_use]
    pub fn alphas(&self) -> Vec<f64> {
        if !(self.alpha_step_rad > 0.0 && self.alpha_max_rad >= self.alpha_min_rad) {
            return Vec::new();
        }
        // Bounded by validate (at most 1000 steps); the cap keeps a bad config from allocating.
        let n = (((self.alpha_max_rad - self.alpha_min_rad) / self.alpha_step_rad + 1e-9).floor()
            as usize)
            .min(1000);
        (0..=n)
            .map(|k| self.alpha_min_rad + k as f64 * self.alpha_step_rad)
            .collect()
    }
}

/// Dig quality settings (Fig. 46).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QualityConfig {
    /// `w_v`. Default 3.
    pub w_volume: f64,
    /// `w_t`. Default 2.
    pub w_time: f64,
    /// `w_e`. Default 1.
    pub w_energy: f64,
    /// `V_min`, m^3. Default 0.5 (a third of the default 1.5 m^3 bucket).
    pub v_min_m3: f64,
    /// `V_max`, m^3; 0 = the bucket capacity (Fig. 46). Default 0.
    pub v_max_m3: f64,
    /// `T_min`, s. Default 1.0.
    pub t_min_s: f64,
    /// `T_max`, s. Default 15.0.
    pub t_max_s: f64,
    /// `E_max`, J. Default 600 kJ.
    pub e_max_j: f64,
    /// `xi_max`. Default 1.
    pub xi_max: f64,
    /// `psi_max`. Default 1.
    pub psi_max: f64,
    /// `zeta_max`. Default 1.
    pub zeta_max: f64,
}

impl Default for QualityConfig {
    fn default() -> Self {
        Self {
            w_volume: 3.0,
            w_time: 2.0,
            w_energy: 1.0,
            v_min_m3: 0.5,
            v_max_m3: 0.0,
            t_min_s: 1.0,
            t_max_s: 15.0,
            e_max_j: 600e3,
            xi_max: 1.0,
            psi_max: 1.0,
            zeta_max: 1.0,
        }
    }
}

impl QualityConfig {
    /// Checks ranges (`V_max = 0` means "the bucket capacity" and is resolved by the planner).
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        for (f, v) in [
            ("quality.w_volume", self.w_volume),
            ("quality.w_time", self.w_time),
            ("quality.w_energy", self.w_energy),
            ("quality.v_min_m3", self.v_min_m3),
            ("quality.v_max_m3", self.v_max_m3),
            ("quality.t_min_s", self.t_min_s),
        ] {
            non_negative(f, v)?;
        }
        for (f, v) in [
            ("quality.t_max_s", self.t_max_s),
            ("quality.e_max_j", self.e_max_j),
            ("quality.xi_max", self.xi_max),
            ("quality.psi_max", self.psi_max),
            ("quality.zeta_max", self.zeta_max),
        ] {
            positive(f, v)?;
        }
        if self.v_max_m3 > 0.0 && self.v_max_m3 <= self.v_min_m3 {
            return Err(PlanError::Config {
                field: "quality.v_max_m3",
                reason: "must exceed v_min_m3".to_owned(),
            });
        }
        if self.t_max_s <= self.t_min_s {
            return Err(PlanError::Config {
                field: "quality.t_max_s",
                reason: "must exceed t_min_s".to_owned(),
            });
        }
        Ok(())
    }

    /// `xi(V)` of Fig. 46: 0 below `V_min`, linear to `xi_max` at `V_max`, flat above. NaN gives 0.
    #[must_use]
    pub fn xi(&self, volume_m3: f64) -> f64 {
        if !(volume_m3.is_finite() && volume_m3 > self.v_min_m3) {
            return 0.0;
        }
        let span = self.v_max_m3 - self.v_min_m3;
        if span <= 0.0 {
            return self.xi_max;
        }
        self.xi_max * ((volume_m3 - self.v_min_m3) / span).min(1.0)
    }

    /// `psi(T)` of Fig. 46: `psi_max (1 - T / T_max)` for `T_min <= T < T_max`, else 0.
    #[must_use]
    pub fn psi(&self, time_s: f64) -> f64 {
        if !(time_s.is_finite() && time_s >= self.t_min_s && time_s < self.t_max_s) {
            return 0.0;
        }
        self.psi_max * (1.0 - time_s / self.t_max_s)
    }

    /// `zeta(E)` of Fig. 46: `zeta_max (1 - E / E_max)` for `0 <= E < E_max`, else 0.
    #[must_use]
    pub fn zeta(&self, energy_j: f64) -> f64 {
        if !(energy_j.is_finite() && energy_j >= 0.0 && energy_j < self.e_max_j) {
            return 0.0;
        }
        self.zeta_max * (1.0 - energy_j / self.e_max_j)
    }

    /// The dig quality of a predicted dig (5.1.1.2), with the veto.
    #[must_use]
    pub fn quality(&self, summary: &DigSummary) -> DigQuality {
        self.quality_of(summary.swept_volume_m3, summary.time_s, summary.energy_j)
    }

    /// The dig quality from volume, time and energy.
    #[must_use]
    pub fn quality_of(&self, volume_m3: f64, time_s: f64, energy_j: f64) -> DigQuality {
        let (xi, psi, zeta) = (self.xi(volume_m3), self.psi(time_s), self.zeta(energy_j));
        let vetoed = xi <= 0.0 || psi <= 0.0 || zeta <= 0.0;
        DigQuality {
            xi,
            psi,
            zeta,
            quality: if vetoed {
                0.0
            } else {
                self.w_volume * xi + self.w_time * psi + self.w_energy * zeta
            },
            vetoed,
        }
    }
}

/// The factors and the combined quality of one dig (Fig. 46).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigQuality {
    /// `xi(V)`.
    pub xi: f64,
    /// `psi(T)`.
    pub psi: f64,
    /// `zeta(E)`.
    pub zeta: f64,
    /// `w_v xi + w_t psi + w_e zeta`, or 0 when vetoed.
    pub quality: f64,
    /// Whether a zero factor vetoed the dig.
    pub vetoed: bool,
}

/// How a candidate fared (the colours of Figs. 47/48's top-right plot).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CandidateStatus {
    /// Violates the kinematic reachability constraint.
    Unreachable,
    /// Reachable, but the predicted dig penetrates the floor (blue in Figs. 47/48).
    PenetratesFloor,
    /// Reachable and above the floor: evaluated by the dig quality (red).
    Valid,
    /// The dig model could not predict it (e.g. the tip left the mapped section).
    ModelFailed,
    /// Reachable, but the bucket is curled past `refined.bucket_abs_min_deg` (not evaluated).
    CurledStart,
}

/// One candidate start `(d, alpha)` (Fig. 45) and its evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Distance of the tip from the near radial boundary, m.
    pub d_m: f64,
    /// Bucket angle from the surface's inward normal, rad.
    pub alpha_rad: f64,
    /// The start pose (base frame, in the region's digging plane).
    pub pose: BucketPose,
    /// Status.
    pub status: CandidateStatus,
    /// The predicted dig, for reachable candidates the model could run.
    pub summary: Option<DigSummary>,
    /// The quality, for valid candidates.
    pub quality: Option<DigQuality>,
}

/// The dig the refined planner chose: a start the controller can execute.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigChoice {
    /// The region (dig order index).
    pub region_index: usize,
    /// Swing angle of the digging plane, rad.
    pub swing_rad: f64,
    /// `d`, m.
    pub d_m: f64,
    /// `alpha`, rad.
    pub alpha_rad: f64,
    /// The start tip pose, base frame.
    pub pose: BucketPose,
    /// The start joint angles (inverse kinematics, stick under the boom).
    pub joints: JointAngles,
    /// The predicted dig.
    pub summary: DigSummary,
    /// Its quality.
    pub quality: DigQuality,
}

/// The evaluated grid of one region (for plots like Figs. 47/48) and the best dig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefinedPlan {
    /// The region.
    pub region: DigRegion,
    /// `d` values, m (rows of the grid).
    pub d_values_m: Vec<f64>,
    /// `alpha` values, rad (columns).
    pub alpha_values_rad: Vec<f64>,
    /// Candidates, row-major: `candidates[i * alpha_values.len() + j]` is `(d_i, alpha_j)`.
    pub candidates: Vec<Candidate>,
    /// The section the digs were predicted over (`r`, height) for the plot.
    pub section: Vec<[f64; 2]>,
    /// The best valid candidate with a quality above zero.
    pub best: Option<DigChoice>,
}

impl RefinedPlan {
    /// Candidates with a given status.
    pub fn count(&self, status: CandidateStatus) -> usize {
        self.candidates
            .iter()
            .filter(|c| c.status == status)
            .count()
    }
}

/// The start pose of Fig. 45 at radius `r_m` on a surface of height `surface_z_m` and slope
/// `slope_rad` (rising away from the machine): the tip `tip_depth_m` below the surface and the bucket
/// line at `alpha_rad` from the inward normal, whose angle to the horizontal is `slope - 90 deg`.
#[must_use]
pub fn start_pose(
    r_m: f64,
    surface_z_m: f64,
    slope_rad: f64,
    alpha_rad: f64,
    tip_depth_m: f64,
) -> BucketPose {
    BucketPose {
        x_m: r_m,
        z_m: surface_z_m - tip_depth_m,
        bucket_abs_rad: slope_rad - FRAC_PI_2 + alpha_rad,
    }
}

/// The refined plan over `region` (5.1.1.2): every candidate `(d, alpha)`, its status and quality, and
/// the best dig.
///
/// # Errors
/// [`PlanError::Config`], [`PlanError::NonFinite`], [`PlanError::Terrain`] when the region's section
/// is entirely unknown. Failures of single candidates are statuses.
pub fn refine<A: ActuatorDynamics>(
    model: &DigModel<A>,
    grid: &TerrainGrid,
    pose: &MachinePose,
    region: &DigRegion,
    floor_z_m: f64,
    cfg: &RefinedConfig,
    quality: &QualityConfig,
) -> Result<RefinedPlan> {
    cfg.validate()?;
    quality.validate()?;
    if !(region.near_r_m.is_finite() && region.far_r_m.is_finite() && region.swing_rad.is_finite())
    {
        return Err(PlanError::NonFinite { what: "region" });
    }
    if !floor_z_m.is_finite() {
        return Err(PlanError::NonFinite {
            what: "floor elevation",
        });
    }
    let span = (region.far_r_m - region.near_r_m).max(0.0);
    let n_d = ((span / cfg.d_step_m + 1e-9).floor() as usize + 1).min(MAX_CANDIDATES);
    let d_values: Vec<f64> = (0..n_d).map(|i| i as f64 * cfg.d_step_m).collect();
    let alphas = cfg.alphas();
    if n_d.saturating_mul(alphas.len()) > MAX_CANDIDATES {
        return Err(PlanError::Config {
            field: "refined",
            reason: format!("{} candidates exceed {MAX_CANDIDATES}", n_d * alphas.len()),
        });
    }
    let r0 = cfg.section_start_m.min(region.near_r_m);
    let r1 = region.far_r_m + cfg.section_margin_m;
    // Unknown samples (occlusion shadows) filled linearly between their known neighbours.
    let profile = grid.plane_section(
        pose,
        region.swing_rad,
        r0,
        r1,
        cfg.section_step_m,
        GapFill::Linear,
    )?;
    let section: Vec<[f64; 2]> = (0..)
        .map(|k| r0 + f64::from(k) * cfg.section_step_m)
        .take_while(|&r| r <= profile.r_end_m() + 1e-9)
        .filter_map(|r| profile.height_at(r).ok().map(|h| [r, h]))
        .collect();
    let site = DigSite::new(profile, floor_z_m)?;
    let kin = model.kinematics();

    let mut candidates = Vec::with_capacity(n_d * alphas.len());
    let mut starts = Vec::new();
    let mut start_of = Vec::new();
    for &d in &d_values {
        let r = region.near_r_m + d;
        let (z, slope) = match (site.profile().height_at(r), site.profile().slope_at(r)) {
            (Ok(z), Ok(s)) => (z, s),
            _ => (f64::NAN, 0.0),
        };
        for &alpha in &alphas {
            let p = start_pose(r, z, slope, alpha, cfg.tip_depth_m);
            let reachable = z.is_finite() && kin.inverse(&p).is_ok();
            let curled = p.bucket_abs_rad < cfg.bucket_abs_min_rad;
            if reachable && !curled {
                start_of.push(candidates.len());
                starts.push(DigStart::Pose(p));
            }
            candidates.push(Candidate {
                d_m: d,
                alpha_rad: alpha,
                pose: p,
                status: if reachable && curled {
                    CandidateStatus::CurledStart
                } else {
                    CandidateStatus::Unreachable
                },
                summary: None,
                quality: None,
            });
        }
    }
    // The expensive part: the forward dig model on every reachable candidate (in parallel with the
    // `parallel` feature).
    let results = model.evaluate_many(&starts, &site);
    for (k, res) in start_of.iter().zip(results) {
        let Some(c) = candidates.get_mut(*k) else {
            continue;
        };
        match res {
            Ok(s) if s.floor_penetration => {
                c.status = CandidateStatus::PenetratesFloor;
                c.summary = Some(s);
            }
            Ok(s) => {
                c.status = CandidateStatus::Valid;
                c.quality = Some(quality.quality(&s));
                c.summary = Some(s);
            }
            Err(DigModelError::Unreachable(_)) => c.status = CandidateStatus::Unreachable,
            Err(_) => c.status = CandidateStatus::ModelFailed,
        }
    }
    let best = select_best(&candidates, region, kin, |_| false);
    Ok(RefinedPlan {
        region: *region,
        d_values_m: d_values,
        alpha_values_rad: alphas,
        candidates,
        section,
        best,
    })
}

/// The best valid candidate with a quality above zero, skipping those `excluded` says (exhaustive
/// search; ties keep the first, smallest `d` then smallest `alpha`: deterministic).
pub fn select_best(
    candidates: &[Candidate],
    region: &DigRegion,
    kin: &Kinematics,
    excluded: impl Fn(&Candidate) -> bool,
) -> Option<DigChoice> {
    let mut best: Option<(usize, f64)> = None;
    for (i, c) in candidates.iter().enumerate() {
        if let Some(q) = c.quality
            && q.quality > 0.0
            && best.is_none_or(|(_, bq)| q.quality > bq)
            && !excluded(c)
        {
            best = Some((i, q.quality));
        }
    }
    let c = candidates.get(best?.0)?;
    match (c.summary, c.quality, kin.inverse(&c.pose)) {
        (Some(summary), Some(quality), Ok(joints)) => Some(DigChoice {
            region_index: region.index,
            swing_rad: region.swing_rad,
            d_m: c.d_m,
            alpha_rad: c.alpha_rad,
            pose: c.pose,
            joints,
            summary,
            quality,
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q() -> QualityConfig {
        QualityConfig {
            v_max_m3: 1.5,
            ..QualityConfig::default()
        }
    }

    #[test]
    fn fig46_functions_are_piecewise_linear() {
        let q = q();
        // xi: 0 below V_min, linear to 1 at V_max = capacity, flat above.
        assert_eq!(q.xi(0.0), 0.0);
        assert_eq!(q.xi(0.5), 0.0);
        assert!((q.xi(1.0) - 0.5).abs() < 1e-12);
        assert!((q.xi(1.5) - 1.0).abs() < 1e-12);
        assert!((q.xi(2.7) - 1.0).abs() < 1e-12);
        assert_eq!(q.xi(f64::NAN), 0.0);
        // psi: maximal at zero, linear down to 0 at T_max; 0 below T_min.
        assert_eq!(q.psi(0.5), 0.0);
        assert!((q.psi(3.0) - 0.8).abs() < 1e-12);
        assert!((q.psi(7.5) - 0.5).abs() < 1e-12);
        assert_eq!(q.psi(15.0), 0.0);
        assert_eq!(q.psi(f64::INFINITY), 0.0);
        // zeta: maximal at zero, linear down to 0 at E_max.
        assert!((q.zeta(0.0) - 1.0).abs() < 1e-12);
        assert!((q.zeta(150e3) - 0.75).abs() < 1e-12);
        assert_eq!(q.zeta(600e3), 0.0);
        assert_eq!(q.zeta(-1.0), 0.0);
    }

    #[test]
    fn quality_is_weighted_3_2_1_and_any_zero_factor_vetoes() {
        let q = q();
        let g = q.quality_of(1.5, 3.0, 150e3);
        assert!(
            (g.quality - (3.0 * 1.0 + 2.0 * 0.8 + 0.75)).abs() < 1e-12,
            "{g:?}"
        );
        assert!(!g.vetoed);
        // Each factor alone at zero vetoes the dig, however good the others.
        for (v, t, e) in [(0.4, 3.0, 150e3), (1.5, 20.0, 150e3), (1.5, 3.0, 700e3)] {
            let g = q.quality_of(v, t, e);
            assert!(g.vetoed && g.quality == 0.0, "{g:?}");
        }
        // More volume (up to V_max) is better; past V_max time decides (Fig. 47).
        assert!(q.quality_of(1.2, 5.0, 2e5).quality > q.quality_of(0.9, 5.0, 2e5).quality);
        assert!(q.quality_of(1.6, 4.0, 2e5).quality > q.quality_of(2.0, 5.0, 2e5).quality);
    }

    #[test]
    fn quality_config_validation() {
        assert!(QualityConfig::default().validate().is_ok());
        let bad = QualityConfig {
            t_max_s: 0.5,
            ..QualityConfig::default()
        };
        assert!(bad.validate().is_err());
        let bad = QualityConfig {
            v_max_m3: 0.2,
            ..QualityConfig::default()
        };
        assert!(bad.validate().is_err());
        let bad = QualityConfig {
            e_max_j: f64::NAN,
            ..QualityConfig::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn candidate_grid_follows_fig45_resolution() {
        let cfg = RefinedConfig::default();
        let a = cfg.alphas();
        assert_eq!(a.len(), 11);
        assert!((a[1] - a[0] - 5f64.to_radians()).abs() < 1e-12);
        // alpha = 0 on flat ground points the bucket straight down; on a 45 degree face it points
        // into the face along the normal.
        let p = start_pose(6.0, 2.0, 0.0, 0.0, 0.02);
        assert!((p.bucket_abs_rad + FRAC_PI_2).abs() < 1e-12 && (p.z_m - 1.98).abs() < 1e-12);
        let p = start_pose(4.0, 1.0, 45f64.to_radians(), 0.0, 0.0);
        assert!((p.bucket_abs_rad.to_degrees() + 45.0).abs() < 1e-9);
    }
}
