//! Soil-tool interaction models (thesis 4.3): the modified Fundamental Earthmoving Equation for sloped
//! terrain with swept volume (Eqs. 14-19), the empirical linear model (Eq. 21), and the intersection
//! geometry `Gamma` of the bucket with a terrain section.
//!
//! Conventions:
//! - Soil `Psi = (gamma, beta, phi, delta, c)`: [`SoilProperties`]. Geometry `Gamma = (d, alpha, rho, V_s)`:
//!   [`DigGeometry`].
//! - `alpha` is the terrain slope along the digging plane, positive when the ground rises away from the
//!   machine (a bench face in front of it).
//! - `rho` carries the thesis's sign: negative in a normal digging attitude (Eq. 25's typical rake is -45
//!   degrees). Its magnitude `-rho` is the classical rake between the blade and the soil surface that the
//!   wedge analysis of Fig. 25 uses in Eqs. 14-17, while Eq. 18 uses the signed `rho` to turn the force into
//!   the base frame. With these two readings Eq. 18 is exactly the wedge force rotated into our base
//!   frame (x away from the machine, z up, the bucket pulled toward the machine).
//! - Eq. 18 gives the force of the bucket on the soil. [`fee_tip_force`] returns the force of the soil on
//!   the bucket (the [`TipForce`] convention of docs/ARCHITECTURE.md), i.e. its negative, with the
//!   payload moment of Eq. 19.

use crate::kinematics::{BucketPose, TipForce, wrap_angle};
use crate::machine::GRAVITY_M_PER_S2;
use crate::terrain::{SectionProfile, TerrainError};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Soil model errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SoilError {
    /// NaN or infinite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A soil property or geometry value outside its physical range.
    #[error("out of range: {what}")]
    OutOfRange {
        /// Which value and its range.
        what: &'static str,
    },
    /// A singular denominator in Eqs. 14-17 (the wedge cannot fail, or a degenerate angle).
    #[error("singular soil-tool geometry: {what}")]
    Singular {
        /// Which denominator.
        what: &'static str,
    },
    /// The terrain section could not be queried.
    #[error(transparent)]
    Terrain(#[from] TerrainError),
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, SoilError>;

/// Soil-tool properties `Psi = (gamma, beta, phi, delta, c)` (thesis 4.3.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SoilProperties {
    /// Density `gamma`, kg/m^3.
    pub density_kg_per_m3: f64,
    /// Failure-surface angle `beta`, rad.
    pub failure_angle_rad: f64,
    /// Soil-soil friction angle `phi`, rad.
    pub friction_angle_rad: f64,
    /// Soil-tool friction angle `delta`, rad.
    pub tool_friction_angle_rad: f64,
    /// Cohesion `c`, Pa.
    pub cohesion_pa: f64,
}

impl SoilProperties {
    /// A typical moist, moderately cohesive earth: 1700 kg/m^3, beta 40, phi 35, delta 20 degrees,
    /// c 20 kPa (the order of the thesis's test site, Figs. 31 and 33).
    #[must_use]
    pub fn typical() -> Self {
        Self {
            density_kg_per_m3: 1700.0,
            failure_angle_rad: 40f64.to_radians(),
            friction_angle_rad: 35f64.to_radians(),
            tool_friction_angle_rad: 20f64.to_radians(),
            cohesion_pa: 20e3,
        }
    }

    /// Checks ranges: density > 0, 0 < beta < 90 deg, 0 <= phi, delta < 90 deg, c >= 0.
    ///
    /// # Errors
    /// [`SoilError::NonFinite`] or [`SoilError::OutOfRange`].
    pub fn validate(&self) -> Result<()> {
        let v = [
            self.density_kg_per_m3,
            self.failure_angle_rad,
            self.friction_angle_rad,
            self.tool_friction_angle_rad,
            self.cohesion_pa,
        ];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(SoilError::NonFinite {
                what: "soil properties",
            });
        }
        let right = 0.5 * PI;
        if self.density_kg_per_m3 <= 0.0 {
            return Err(SoilError::OutOfRange {
                what: "density must be positive",
            });
        }
        if !(self.failure_angle_rad > 0.0 && self.failure_angle_rad < right) {
            return Err(SoilError::OutOfRange {
                what: "failure angle beta must lie in (0, 90) degrees",
            });
        }
        if !(0.0..right).contains(&self.friction_angle_rad) {
            return Err(SoilError::OutOfRange {
                what: "friction angle phi must lie in [0, 90) degrees",
            });
        }
        if !(0.0..right).contains(&self.tool_friction_angle_rad) {
            return Err(SoilError::OutOfRange {
                what: "tool friction angle delta must lie in [0, 90) degrees",
            });
        }
        if self.cohesion_pa < 0.0 {
            return Err(SoilError::OutOfRange {
                what: "cohesion must not be negative",
            });
        }
        Ok(())
    }
}

/// Intersection geometry `Gamma = (d, alpha, rho, V_s)` (thesis 4.3.3, Fig. 25).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigGeometry {
    /// Depth of the tip below the surface, perpendicular to it, m.
    pub depth_m: f64,
    /// Terrain slope, rad, positive rising away from the machine.
    pub slope_rad: f64,
    /// Rake angle relative to the surface in the thesis's sign (negative when digging), rad.
    pub rake_rad: f64,
    /// Swept volume `V_s`, m^3.
    pub swept_volume_m3: f64,
}

/// The thesis's typical geometry (Eq. 25): depth 1 m, rake -45 deg, terrain 30 deg, swept volume 0.75 m^3.
pub const GAMMA_TYPICAL: DigGeometry = DigGeometry {
    depth_m: 1.0,
    slope_rad: 30.0 * PI / 180.0,
    rake_rad: -45.0 * PI / 180.0,
    swept_volume_m3: 0.75,
};

impl DigGeometry {
    fn validate(&self) -> Result<()> {
        if ![
            self.depth_m,
            self.slope_rad,
            self.rake_rad,
            self.swept_volume_m3,
        ]
        .iter()
        .all(|x| x.is_finite())
        {
            return Err(SoilError::NonFinite {
                what: "dig geometry",
            });
        }
        if self.depth_m < 0.0 || self.swept_volume_m3 < 0.0 {
            return Err(SoilError::OutOfRange {
                what: "depth and swept volume must not be negative",
            });
        }
        Ok(())
    }
}

/// The three factors of Eq. 17.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeeFactors {
    /// Wedge-weight factor `N_w`.
    pub n_w: f64,
    /// Cohesion factor `N_c`.
    pub n_c: f64,
    /// Swept-volume (surcharge) factor `N_q`.
    pub n_q: f64,
}

const EPS: f64 = 1e-6;

/// The factors `N_w, N_c, N_q` of the modified FEE for sloped terrain (Eq. 17, from Eqs. 14-16).
///
/// The wedge weight factor uses `max(cot(beta) - tan(alpha), 0)`: when the terrain is steeper than the
/// failure plane the unshaded wedge of Fig. 25 vanishes (Eq. 15 would give a negative weight).
///
/// # Errors
/// [`SoilError::Singular`] when `sin(beta)`, `sin(beta + phi)` or `cos(alpha)` vanish, or when the
/// denominator `cos(rho + delta) + sin(rho + delta) cot(beta + phi)` is not positive (the wedge cannot
/// fail: the tool force is unbounded); validation errors of the inputs.
pub fn fee_factors(psi: &SoilProperties, gamma: &DigGeometry) -> Result<FeeFactors> {
    psi.validate()?;
    gamma.validate()?;
    let beta = psi.failure_angle_rad;
    let bp = beta + psi.friction_angle_rad;
    let alpha = gamma.slope_rad;
    let rho_c = -gamma.rake_rad; // classical rake magnitude of Fig. 25
    if beta.sin().abs() < EPS {
        return Err(SoilError::Singular {
            what: "sin(beta) = 0",
        });
    }
    if bp.sin().abs() < EPS {
        return Err(SoilError::Singular {
            what: "sin(beta + phi) = 0",
        });
    }
    if alpha.cos().abs() < EPS {
        return Err(SoilError::Singular {
            what: "vertical terrain (cos(alpha) = 0)",
        });
    }
    let cot_beta = beta.cos() / beta.sin();
    let cot_bp = bp.cos() / bp.sin();
    let den = (rho_c + psi.tool_friction_angle_rad).cos()
        + (rho_c + psi.tool_friction_angle_rad).sin() * cot_bp;
    if den < EPS {
        return Err(SoilError::Singular {
            what: "cos(rho + delta) + sin(rho + delta) cot(beta + phi) <= 0",
        });
    }
    let slope_term = alpha.cos() + alpha.sin() * cot_bp;
    let wedge = (cot_beta - alpha.tan()).max(0.0); // Eq. 15
    Ok(FeeFactors {
        n_w: wedge * slope_term / (2.0 * den), // Eq. 17
        n_c: (1.0 + cot_beta * cot_bp) / den,  // Eq. 17
        n_q: slope_term / den,                 // Eq. 17
    })
}

/// Magnitude of the tool force on the soil wedge, N: `F = d^2 w gamma g N_w + c w d N_c + V_s gamma g N_q`
/// (Eq. 17; Eq. 14 with Eqs. 15-16). Never negative: soil does not pull the bucket in.
///
/// # Errors
/// As [`fee_factors`]; [`SoilError::OutOfRange`] for a non-positive width.
pub fn fee_force_n(psi: &SoilProperties, gamma: &DigGeometry, width_m: f64) -> Result<f64> {
    if !(width_m.is_finite() && width_m > 0.0) {
        return Err(SoilError::OutOfRange {
            what: "bucket width must be positive",
        });
    }
    let n = fee_factors(psi, gamma)?;
    let g = GRAVITY_M_PER_S2;
    let d = gamma.depth_m;
    let f = d * d * width_m * psi.density_kg_per_m3 * g * n.n_w
        + psi.cohesion_pa * width_m * d * n.n_c
        + gamma.swept_volume_m3 * psi.density_kg_per_m3 * g * n.n_q; // Eq. 17
    Ok(f.max(0.0))
}

/// The soil force on the bucket in the base frame with the payload moment (Eqs. 17-19).
///
/// `F_x, F_z` are the negatives of Eq. 18 (which gives the bucket's force on the soil);
/// `M_y = -F_g x_c` (Eq. 19) is the moment of the swept material's weight `F_g = V_s gamma g` about the
/// tip, counter-clockwise positive, with `x_c` the horizontal offset of the payload centroid from the tip
/// (positive away from the machine, [`crate::kinematics::Kinematics::centroid_offset_x_m`]).
///
/// # Errors
/// As [`fee_force_n`]; [`SoilError::NonFinite`] for a non-finite `x_c`.
pub fn fee_tip_force(
    psi: &SoilProperties,
    gamma: &DigGeometry,
    width_m: f64,
    centroid_offset_x_m: f64,
) -> Result<TipForce> {
    if !centroid_offset_x_m.is_finite() {
        return Err(SoilError::NonFinite {
            what: "centroid offset x_c",
        });
    }
    let f = fee_force_n(psi, gamma, width_m)?;
    let (rho, alpha, delta) = (gamma.rake_rad, gamma.slope_rad, psi.tool_friction_angle_rad);
    let fx_on_soil = f * (delta.cos() * (rho - alpha).sin() - delta.sin() * (rho - alpha).cos()); // Eq. 18
    let fz_on_soil = f * (delta.cos() * (rho - alpha).cos() + delta.sin() * (rho - alpha).sin()); // Eq. 18
    let f_g = gamma.swept_volume_m3 * psi.density_kg_per_m3 * GRAVITY_M_PER_S2;
    Ok(TipForce {
        fx_n: -fx_on_soil,
        fz_n: -fz_on_soil,
        my_nm: -f_g * centroid_offset_x_m, // Eq. 19
    })
}

/// The empirical soil model (Eq. 21): each force component is linear in
/// `Gamma = (d^2, cos(rho), alpha, V_s)` with its own coefficients `Psi_i` (soil on bucket, base frame).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EmpiricalSoilModel {
    /// Coefficients for `F_x`, N per unit of each feature.
    pub fx: [f64; 4],
    /// Coefficients for `F_z`.
    pub fz: [f64; 4],
    /// Coefficients for `M_y`.
    pub my: [f64; 4],
}

impl EmpiricalSoilModel {
    /// The feature vector `(d^2, cos(rho), alpha, V_s)` of a geometry (thesis 4.3.3).
    #[must_use]
    pub fn features(gamma: &DigGeometry) -> [f64; 4] {
        [
            gamma.depth_m * gamma.depth_m,
            gamma.rake_rad.cos(),
            gamma.slope_rad,
            gamma.swept_volume_m3,
        ]
    }

    /// Predicted force `f = sum_i Gamma_i Psi_i` per component (Eq. 21).
    ///
    /// # Errors
    /// [`SoilError::NonFinite`] for a non-finite geometry or coefficient.
    pub fn evaluate(&self, gamma: &DigGeometry) -> Result<TipForce> {
        let x = Self::features(gamma);
        let dot = |c: &[f64; 4]| c.iter().zip(x.iter()).map(|(a, b)| a * b).sum::<f64>(); // Eq. 21
        let f = TipForce {
            fx_n: dot(&self.fx),
            fz_n: dot(&self.fz),
            my_nm: dot(&self.my),
        };
        if [f.fx_n, f.fz_n, f.my_nm].iter().all(|v| v.is_finite()) {
            Ok(f)
        } else {
            Err(SoilError::NonFinite {
                what: "empirical model input or coefficients",
            })
        }
    }
}

/// Whether the bucket touches the soil, and if so the geometry `Gamma`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Contact {
    /// The tip is at or above the surface.
    NotInContact,
    /// The tip is below the surface.
    InContact(DigGeometry),
}

/// Intersects a bucket pose (base frame) with the terrain section of its digging plane to get `Gamma`
/// (thesis 4.3.4): depth of the tip below the surface measured perpendicular to the local surface, the
/// local slope, and the rake of the cutting edge relative to the surface. The blade is taken along the
/// bucket line (tip -> bucket pin), so the classical rake to the surface is `bucket_abs + 180 deg - alpha`
/// and the thesis-signed `rho` its negative. `V_s` comes from the swept-volume integrator
/// ([`crate::terrain::SweptVolume`]).
///
/// # Errors
/// [`SoilError::NonFinite`], [`SoilError::OutOfRange`] for a negative `V_s`, [`SoilError::Terrain`] when
/// the tip lies outside the profile.
pub fn dig_geometry(
    pose: &BucketPose,
    profile: &SectionProfile,
    swept_volume_m3: f64,
) -> Result<Contact> {
    if ![pose.x_m, pose.z_m, pose.bucket_abs_rad, swept_volume_m3]
        .iter()
        .all(|v| v.is_finite())
    {
        return Err(SoilError::NonFinite {
            what: "bucket pose or swept volume",
        });
    }
    if swept_volume_m3 < 0.0 {
        return Err(SoilError::OutOfRange {
            what: "swept volume must not be negative",
        });
    }
    let surface = profile.height_at(pose.x_m)?;
    let vertical_depth = surface - pose.z_m;
    if vertical_depth <= 0.0 {
        return Ok(Contact::NotInContact);
    }
    let alpha = profile.slope_at(pose.x_m)?;
    let blade_abs = wrap_angle(pose.bucket_abs_rad + PI);
    let rake_classical = wrap_angle(blade_abs - alpha);
    Ok(Contact::InContact(DigGeometry {
        depth_m: vertical_depth * alpha.cos(),
        slope_rad: alpha,
        rake_rad: -rake_classical,
        swept_volume_m3,
    }))
}

/// Closest approach of the rake to the wedge's failure limit, rad. Eq. 17's denominator
/// `cos(rho + delta) + sin(rho + delta) cot(beta + phi) = sin(beta + phi + rho + delta) / sin(beta + phi)`
/// vanishes as the rake plus the three angles reach 180 degrees: there the wedge cannot fail and the
/// FEE force grows without bound. A blade at or past that rake still bulldozes the soil ahead of it, so
/// [`MovingBucketSoil`] evaluates the force at the rake this far from the limit (it saturates at about
/// four times the force at a typical 45 degree rake) instead of diverging or, as a bare Eq. 17 would
/// suggest, vanishing. The simulator's soil contact (`vcan_sim::soil_contact`) uses the same margin.
pub const WEDGE_LIMIT_MARGIN_RAD: f64 = 0.17;

/// Bearing resistance of a bucket pushed into the soil (not cut by it), the part of the soil force that
/// the wedge analysis of Eqs. 14-17 leaves out: the cutting edge pushed in tip first bears on its face,
/// the bucket's back (bottom plate) pushed into the soil bears over a strip of it. The bearing pressure
/// has the form of Terzaghi's bearing capacity, `c N_c + gamma g d N_q + q0` (the same terms as Eq. 9),
/// and both resistances build up from rest over `creep_speed_m_per_s` (`tanh(v / v_creep)`), as the FEE
/// force does. The defaults are the simulator's soil contact (`vcan_sim::soil_contact`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BearingParams {
    /// Thickness of the cutting edge (with its teeth) that bears when pushed in tip first, m.
    pub edge_thickness_m: f64,
    /// Length of the bucket's back (bottom plate) that bears when pushed in, m.
    pub back_length_m: f64,
    /// Cohesion bearing factor `N_c`.
    pub cohesion_factor: f64,
    /// Depth (overburden) bearing factor `N_q`.
    pub depth_factor: f64,
    /// Bearing pressure at the surface of a cohesionless soil `q0`, Pa.
    pub surface_pressure_pa: f64,
    /// Speed over which the soil resistance builds up from rest, m/s.
    pub creep_speed_m_per_s: f64,
}

impl Default for BearingParams {
    fn default() -> Self {
        Self {
            edge_thickness_m: 0.05,
            back_length_m: 0.25,
            cohesion_factor: 40.0,
            depth_factor: 30.0,
            surface_pressure_pa: 2.0e4,
            creep_speed_m_per_s: 0.01,
        }
    }
}

impl BearingParams {
    /// Checks that every value is finite and not negative, and the creep speed positive.
    ///
    /// # Errors
    /// [`SoilError::NonFinite`] or [`SoilError::OutOfRange`].
    pub fn validate(&self) -> Result<()> {
        let v = [
            self.edge_thickness_m,
            self.back_length_m,
            self.cohesion_factor,
            self.depth_factor,
            self.surface_pressure_pa,
            self.creep_speed_m_per_s,
        ];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(SoilError::NonFinite {
                what: "bearing parameters",
            });
        }
        if v.iter().any(|x| *x < 0.0) || self.creep_speed_m_per_s <= 0.0 {
            return Err(SoilError::OutOfRange {
                what: "bearing parameters must not be negative, the creep speed positive",
            });
        }
        Ok(())
    }

    /// Bearing pressure `c N_c + gamma g d N_q + q0` at a depth `d` (perpendicular), Pa.
    #[must_use]
    pub fn pressure_pa(&self, psi: &SoilProperties, depth_m: f64) -> f64 {
        psi.cohesion_pa * self.cohesion_factor
            + psi.density_kg_per_m3 * GRAVITY_M_PER_S2 * depth_m.max(0.0) * self.depth_factor
            + self.surface_pressure_pa
    }
}

/// `tanh` through one `exp` (libm's `tanh` is several times slower); exact to rounding, saturating
/// without NaN.
#[inline]
fn fast_tanh(a: f64) -> f64 {
    if a > 20.0 {
        1.0
    } else if a < -20.0 {
        -1.0
    } else {
        1.0 - 2.0 / ((2.0 * a).exp() + 1.0)
    }
}

/// The share of the FEE wedge on the outward side (the edge travelling away from the machine, `+x`)
/// at tip velocity `v_m_per_s` (base frame `[vx, vz]`), and its gradient in the velocity (s/m): the
/// wedge forms ahead of the edge on the side it travels (Fig. 25), so the outward side's share is
/// `(1 + vx / sqrt(|v|^2 + v_creep^2)) / 2`, the cosine of the travel's angle from the horizontal
/// smoothed at rest over the creep speed; the inward side has the rest. An edge moving straight up
/// or down has half of each, and the share turns over smoothly where the travel does. The
/// simulator's contact law and [`MovingBucketSoil`] both take it from here.
#[must_use]
pub fn outward_wedge_share(v_m_per_s: [f64; 2], creep_speed_m_per_s: f64) -> (f64, [f64; 2]) {
    let [vx, vz] = v_m_per_s;
    let c2 = creep_speed_m_per_s * creep_speed_m_per_s;
    let r2 = vx * vx + vz * vz + c2;
    let r = r2.sqrt();
    if !(r.is_finite() && r > 0.0) {
        return (0.5, [0.0; 2]);
    }
    let r3 = r2 * r;
    (
        0.5 * (1.0 + vx / r),
        [0.5 * (vz * vz + c2) / r3, -0.5 * vx * vz / r3],
    )
}

/// The soil force on a moving bucket, with the soil constants of Eq. 17 precomputed for one `Psi` (the
/// dig model evaluates it every 10 ms step): the modified FEE (Eqs. 14-17) for either direction of
/// travel, directed by Eq. 18 (at `delta` from the blade normal, the blade along the bucket line), held
/// [`WEDGE_LIMIT_MARGIN_RAD`] short of the wedge's failure limit, mobilised from rest over the creep
/// speed, plus the bearing resistance of [`BearingParams`]. The wedge forms ahead of the edge on the
/// side it travels (Fig. 25); each side's share is `(1 +- vx / sqrt(|v|^2 + v_creep^2)) / 2`, the
/// cosine of the travel's angle from the horizontal smoothed at rest, as in the simulator's contact
/// law (plant `implicit-2`): an edge moving straight up meets half of each side's wedge.
///
/// For a bucket pulled toward the machine at speed below the limit the FEE part equals
/// [`fee_tip_force`] (tested), which is Eq. 18 written with the signed rake; the vector form here
/// also covers a bucket pushed away from the machine (the rake is then measured from the other side
/// of the blade).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingBucketSoil {
    psi: SoilProperties,
    bearing: BearingParams,
    width_m: f64,
    cot_beta: f64,
    cot_bp: f64,
    n_c_numerator: f64,
    weight_n_per_m3: f64,
    sin_delta: f64,
    cos_delta: f64,
    /// Largest classical rake used for the FEE magnitude, rad.
    max_rake_rad: f64,
}

/// Where the bucket is and how it moves, for [`MovingBucketSoil::force`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BucketMotion {
    /// `sin(bucket_abs)` (bucket line pin -> tip to the horizontal).
    pub sin_bucket_abs: f64,
    /// `cos(bucket_abs)`.
    pub cos_bucket_abs: f64,
    /// Tip velocity in the base frame `[vx, vz]`, m/s.
    pub tip_velocity_m_per_s: [f64; 2],
    /// Depth of the tip below the current surface, measured vertically, m (> 0 in the soil).
    pub vertical_depth_m: f64,
    /// Terrain slope `alpha` at the tip, as `tan(alpha)` (rising away from the machine positive).
    pub slope_tan: f64,
    /// Soil in the bucket (swept volume, at most the capacity), m^3.
    pub swept_volume_m3: f64,
}

impl BucketMotion {
    /// The speeds at which the bearing resistances are pushed in, m/s: `[tip first, back first]`,
    /// the tip velocity against the blade (tip -> pin) and against the direction the opening faces.
    /// Each bearing acts only while its speed is positive, mobilised from rest over the creep speed
    /// ([`MovingBucketSoil::force`]).
    #[must_use]
    pub fn bearing_speeds_m_per_s(&self) -> [f64; 2] {
        let v = self.tip_velocity_m_per_s;
        let b = self.blade();
        let o = self.opening();
        [-(v[0] * b[0] + v[1] * b[1]), -(v[0] * o[0] + v[1] * o[1])]
    }

    /// The blade: from the tip up the bucket line to the pin (unit, base frame).
    fn blade(&self) -> [f64; 2] {
        [-self.cos_bucket_abs, -self.sin_bucket_abs]
    }

    /// The direction the opening faces, `bucket_abs - 90 degrees` (unit, base frame).
    fn opening(&self) -> [f64; 2] {
        [self.sin_bucket_abs, -self.cos_bucket_abs]
    }
}

impl MovingBucketSoil {
    /// Precomputes the constants for soil `psi`, bearing parameters and a bucket `width_m`.
    ///
    /// # Errors
    /// Validation errors of `psi` and `bearing`; [`SoilError::OutOfRange`] for a non-positive width;
    /// [`SoilError::Singular`] for `sin(beta + phi) = 0`.
    pub fn new(psi: &SoilProperties, bearing: &BearingParams, width_m: f64) -> Result<Self> {
        psi.validate()?;
        bearing.validate()?;
        if !(width_m.is_finite() && width_m > 0.0) {
            return Err(SoilError::OutOfRange {
                what: "bucket width must be positive",
            });
        }
        let beta = psi.failure_angle_rad;
        let bp = beta + psi.friction_angle_rad;
        if bp.sin().abs() < EPS {
            return Err(SoilError::Singular {
                what: "sin(beta + phi) = 0",
            });
        }
        let cot_beta = beta.cos() / beta.sin();
        let cot_bp = bp.cos() / bp.sin();
        let (sin_delta, cos_delta) = psi.tool_friction_angle_rad.sin_cos();
        Ok(Self {
            psi: *psi,
            bearing: *bearing,
            width_m,
            cot_beta,
            cot_bp,
            n_c_numerator: 1.0 + cot_beta * cot_bp,
            weight_n_per_m3: psi.density_kg_per_m3 * GRAVITY_M_PER_S2,
            sin_delta,
            cos_delta,
            max_rake_rad: PI - bp - psi.tool_friction_angle_rad - WEDGE_LIMIT_MARGIN_RAD,
        })
    }

    /// The soil properties.
    #[must_use]
    pub fn properties(&self) -> &SoilProperties {
        &self.psi
    }

    /// Eq. 17's magnitude at perpendicular depth `d`, slope `alpha` (given as `cos`, `sin`, `tan`) and
    /// classical rake `rake_rad` (held short of the failure limit), N.
    #[inline]
    fn fee_magnitude_n(
        &self,
        d: f64,
        cos_a: f64,
        sin_a: f64,
        tan_a: f64,
        rake_rad: f64,
        v_s: f64,
    ) -> f64 {
        let rake = rake_rad.min(self.max_rake_rad);
        let (s, c) = (rake + self.psi.tool_friction_angle_rad).sin_cos();
        let den = c + s * self.cot_bp; // Eq. 17
        if den < EPS {
            return 0.0;
        }
        let slope_term = cos_a + sin_a * self.cot_bp;
        let wedge = (self.cot_beta - tan_a).max(0.0); // Eq. 15
        let f = d * d * self.width_m * self.weight_n_per_m3 * wedge * slope_term / (2.0 * den)
            + self.psi.cohesion_pa * self.width_m * d * self.n_c_numerator / den
            + v_s * self.weight_n_per_m3 * slope_term / den; // Eq. 17
        f.max(0.0)
    }

    /// Soil force on the bucket (base frame, at the tip; `M_y = 0`: the payload's weight acts through
    /// the gravity torques). Zero out of the soil (`vertical_depth_m <= 0`).
    ///
    /// # Errors
    /// [`SoilError::NonFinite`] for non-finite motion values, [`SoilError::OutOfRange`] for a negative
    /// swept volume.
    #[inline]
    pub fn force(&self, m: &BucketMotion) -> Result<TipForce> {
        let v = m.tip_velocity_m_per_s;
        if !(m.sin_bucket_abs.is_finite()
            && m.cos_bucket_abs.is_finite()
            && v[0].is_finite()
            && v[1].is_finite()
            && m.vertical_depth_m.is_finite()
            && m.slope_tan.is_finite()
            && m.swept_volume_m3.is_finite())
        {
            return Err(SoilError::NonFinite {
                what: "bucket motion",
            });
        }
        if m.swept_volume_m3 < 0.0 {
            return Err(SoilError::OutOfRange {
                what: "swept volume must not be negative",
            });
        }
        if m.vertical_depth_m <= 0.0 {
            return Ok(TipForce::default());
        }
        let sec = (1.0 + m.slope_tan * m.slope_tan).sqrt();
        let (cos_a, sin_a) = (1.0 / sec, m.slope_tan / sec);
        let alpha = m.slope_tan.atan();
        let d = m.vertical_depth_m * cos_a; // Eq. 17 measures d perpendicular to the terrain
        // The blade: from the tip up the bucket line to the pin.
        let b = m.blade();
        let speed = v[0].hypot(v[1]);
        let creep = self.bearing.creep_speed_m_per_s;
        let mobilised = fast_tanh(speed / creep);
        // The wedge forms ahead of the edge on the side it travels, each side by its share.
        let (share_out, _) = outward_wedge_share(v, creep);
        let (mut fx, mut fz) = (0.0, 0.0);
        for (travel, share) in [(1.0, share_out), (-1.0, 1.0 - share_out)] {
            if share <= 0.0 {
                continue;
            }
            // The blade's normal facing this travel.
            let mut n = [b[1], -b[0]];
            if n[0] * travel < 0.0 {
                n = [-n[0], -n[1]];
            }
            // Classical rake (Fig. 25): between the blade and the terrain surface behind the edge.
            let blade_from_travel = b[1].atan2(b[0] * travel);
            let rake = (PI - blade_from_travel + alpha * travel).clamp(0.1, PI - 0.1);
            let f = self.fee_magnitude_n(d, cos_a, sin_a, m.slope_tan, rake, m.swept_volume_m3)
                * share
                * mobilised;
            // Eq. 18: the bucket's force on the soil is at delta from the blade normal; on the
            // bucket the opposite: against the normal and up the blade by friction.
            fx += f * (-self.cos_delta * n[0] + self.sin_delta * b[0]);
            fz += f * (-self.cos_delta * n[1] + self.sin_delta * b[1]);
        }
        // Bearing: the edge pushed in tip first, the back pushed against the soil.
        let pressure = self.bearing.pressure_pa(&self.psi, d);
        let [v_tip_first, v_back_first] = m.bearing_speeds_m_per_s();
        if v_tip_first > 0.0 {
            let edge = pressure
                * self.width_m
                * self.bearing.edge_thickness_m
                * fast_tanh(v_tip_first / creep);
            fx += edge * b[0];
            fz += edge * b[1];
        }
        let opening = m.opening();
        if v_back_first > 0.0 {
            let back = pressure
                * self.width_m
                * self.bearing.back_length_m
                * fast_tanh(v_back_first / creep);
            fx += back * opening[0];
            fz += back * opening[1];
        }
        Ok(TipForce {
            fx_n: fx,
            fz_n: fz,
            my_nm: 0.0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const WIDTH_M: f64 = 1.3;

    fn eq12(psi: &SoilProperties, g: &DigGeometry, w: f64) -> f64 {
        // Eq. 12 (flat terrain), written with the consistent d^2 w gamma g N_w weight term.
        let (b, bp, rc) = (
            psi.failure_angle_rad,
            psi.failure_angle_rad + psi.friction_angle_rad,
            -g.rake_rad,
        );
        let cot = |x: f64| x.cos() / x.sin();
        let den = (rc + psi.tool_friction_angle_rad).cos()
            + (rc + psi.tool_friction_angle_rad).sin() * cot(bp);
        let n_w = cot(b) / (2.0 * den);
        let n_c = (1.0 + cot(b) * cot(bp)) / den;
        let n_q = 1.0 / den;
        let gg = psi.density_kg_per_m3 * GRAVITY_M_PER_S2;
        g.depth_m * g.depth_m * w * gg * n_w
            + psi.cohesion_pa * w * g.depth_m * n_c
            + g.swept_volume_m3 * gg * n_q
    }

    #[test]
    fn gamma_typical_gives_forces_of_the_thesis_order() {
        let f = fee_tip_force(&SoilProperties::typical(), &GAMMA_TYPICAL, WIDTH_M, 0.35)
            .expect("force");
        let mag = f.force_magnitude_n();
        assert!((3e4..3e5).contains(&mag), "{mag}");
        // The soil pushes the bucket away from the machine and down while it is pulled in and lifted.
        assert!(f.fx_n > 0.0, "{f:?}");
        // On flat ground the soil also pushes the bucket down (Eq. 18: rho - alpha - delta = -65 deg).
        let flat = DigGeometry {
            slope_rad: 0.0,
            ..GAMMA_TYPICAL
        };
        let f_flat =
            fee_tip_force(&SoilProperties::typical(), &flat, WIDTH_M, 0.35).expect("force");
        assert!(f_flat.fx_n > 0.0 && f_flat.fz_n < 0.0, "{f_flat:?}");
        assert!(f.my_nm < 0.0);
        let hard = SoilProperties {
            cohesion_pa: 30e3,
            ..SoilProperties::typical()
        };
        let mag_hard = fee_tip_force(&hard, &GAMMA_TYPICAL, WIDTH_M, 0.35)
            .expect("force")
            .force_magnitude_n();
        assert!(mag_hard > mag && mag_hard < 2e5, "{mag_hard}");
    }

    #[test]
    fn flat_terrain_reduces_to_eq12() {
        let psi = SoilProperties::typical();
        for rake_deg in [-30.0_f64, -45.0, -60.0, -80.0] {
            let g = DigGeometry {
                slope_rad: 0.0,
                rake_rad: rake_deg.to_radians(),
                ..GAMMA_TYPICAL
            };
            let a = fee_force_n(&psi, &g, WIDTH_M).expect("eq17");
            let b = eq12(&psi, &g, WIDTH_M);
            assert!((a - b).abs() < 1e-9 * b, "{a} vs {b}");
        }
    }

    #[test]
    fn eq12_with_surcharge_has_the_structure_of_eq9() {
        // Eq. 9: F = (gamma g d^2 N_gamma + c d N_c + q d N_q) w. Its N_c is Eq. 12's N_c; its surcharge
        // Q = q d (cot rho + cot beta) (Eq. 8) enters as Q w N_q(12), which is Eq. 12's V_s term when the
        // surcharge weight Q w equals V_s gamma g; N_gamma exceeds N_w(12) by the material above the blade.
        let psi = SoilProperties::typical();
        let g = DigGeometry {
            slope_rad: 0.0,
            ..GAMMA_TYPICAL
        };
        let n12 = fee_factors(&psi, &g).expect("factors");
        let (b, bp, rc, dl) = (
            psi.failure_angle_rad,
            psi.failure_angle_rad + psi.friction_angle_rad,
            -g.rake_rad,
            psi.tool_friction_angle_rad,
        );
        let cot = |x: f64| x.cos() / x.sin();
        let den = (rc + dl).cos() + (rc + dl).sin() * cot(bp);
        let n9_gamma = (cot(rc) + cot(b)) / (2.0 * den);
        let n9_c = (1.0 + cot(b) * cot(bp)) / den;
        let n9_q = (cot(rc) + cot(b)) / den;
        assert!((n9_c - n12.n_c).abs() < 1e-12);
        assert!((n9_q - (cot(rc) + cot(b)) * n12.n_q).abs() < 1e-12);
        assert!((n9_gamma - n12.n_w - cot(rc) / (2.0 * den)).abs() < 1e-12);
        // Force equality with the surcharge written as a swept volume.
        let (d, q_pa) = (g.depth_m, 5e3);
        let f9 = (psi.cohesion_pa * d * n9_c + q_pa * d * n9_q) * WIDTH_M;
        let vs =
            q_pa * d * (cot(rc) + cot(b)) * WIDTH_M / (psi.density_kg_per_m3 * GRAVITY_M_PER_S2);
        let g12 = DigGeometry {
            swept_volume_m3: vs,
            ..g
        };
        let f12 = psi.cohesion_pa * WIDTH_M * d * n12.n_c
            + vs * psi.density_kg_per_m3 * GRAVITY_M_PER_S2 * n12.n_q;
        assert!((f9 - f12).abs() < 1e-9 * f9);
        assert!(fee_force_n(&psi, &g12, WIDTH_M).expect("f") > f12); // plus the wedge weight
    }

    #[test]
    fn singular_denominators_are_typed_errors() {
        let psi = SoilProperties::typical();
        // rho_c + delta = 180 - (beta + phi) makes the denominator vanish.
        let rc =
            PI - (psi.failure_angle_rad + psi.friction_angle_rad) - psi.tool_friction_angle_rad;
        let g = DigGeometry {
            rake_rad: -rc,
            ..GAMMA_TYPICAL
        };
        assert!(matches!(
            fee_force_n(&psi, &g, WIDTH_M),
            Err(SoilError::Singular { .. })
        ));
        let vertical = DigGeometry {
            slope_rad: 0.5 * PI,
            ..GAMMA_TYPICAL
        };
        assert!(matches!(
            fee_force_n(&psi, &vertical, WIDTH_M),
            Err(SoilError::Singular { .. })
        ));
        let bad = SoilProperties {
            failure_angle_rad: 0.0,
            ..psi
        };
        assert!(matches!(
            fee_force_n(&bad, &GAMMA_TYPICAL, WIDTH_M),
            Err(SoilError::OutOfRange { .. })
        ));
        let nan = DigGeometry {
            depth_m: f64::NAN,
            ..GAMMA_TYPICAL
        };
        assert!(matches!(
            fee_force_n(&psi, &nan, WIDTH_M),
            Err(SoilError::NonFinite { .. })
        ));
    }

    #[test]
    fn empirical_model_is_linear_in_gamma() {
        let m = EmpiricalSoilModel {
            fx: [2.0e4, 1.0e4, 5.0e3, 3.0e4],
            fz: [-1.0e4, -5.0e3, 0.0, -2.0e4],
            my: [0.0, 0.0, 0.0, -8.0e3],
        };
        let f = m.evaluate(&GAMMA_TYPICAL).expect("f");
        let x = EmpiricalSoilModel::features(&GAMMA_TYPICAL);
        assert!((x[1] - (-45f64).to_radians().cos()).abs() < 1e-12);
        let expect = 2.0e4 * 1.0 + 1.0e4 * x[1] + 5.0e3 * x[2] + 3.0e4 * 0.75;
        assert!((f.fx_n - expect).abs() < 1e-9);
        assert!((f.my_nm + 6.0e3).abs() < 1e-9);
    }

    #[test]
    fn geometry_from_pose_and_profile() {
        // A 30 degree face rising away from the machine from x = 6 m.
        let profile = SectionProfile::from_fn(0.0, 15.0, 0.05, |x| {
            ((x - 6.0) * 30f64.to_radians().tan()).clamp(0.0, 3.0)
        })
        .expect("profile");
        let x = 8.0;
        let surface = profile.height_at(x).expect("h");
        let alpha = 30f64.to_radians();
        // Tip 1 m below the face (perpendicular), bucket_abs so that the rake is -45 degrees.
        let pose = BucketPose {
            x_m: x,
            z_m: surface - 1.0 / alpha.cos(),
            bucket_abs_rad: (75.0 - 180.0f64).to_radians(),
        };
        let Contact::InContact(g) = dig_geometry(&pose, &profile, 0.75).expect("gamma") else {
            panic!("tip is below the surface");
        };
        assert!((g.depth_m - 1.0).abs() < 1e-9, "{g:?}");
        assert!((g.slope_rad - alpha).abs() < 1e-9);
        assert!((g.rake_rad - GAMMA_TYPICAL.rake_rad).abs() < 1e-9, "{g:?}");
        let above = BucketPose {
            z_m: surface + 0.1,
            ..pose
        };
        assert_eq!(
            dig_geometry(&above, &profile, 0.0).expect("ok"),
            Contact::NotInContact
        );
        let outside = BucketPose { x_m: 40.0, ..pose };
        assert!(matches!(
            dig_geometry(&outside, &profile, 0.0),
            Err(SoilError::Terrain(_))
        ));
    }

    fn motion_toward_machine(bucket_abs_rad: f64, depth_m: f64, slope_rad: f64) -> BucketMotion {
        BucketMotion {
            sin_bucket_abs: bucket_abs_rad.sin(),
            cos_bucket_abs: bucket_abs_rad.cos(),
            tip_velocity_m_per_s: [-0.4, 0.0],
            vertical_depth_m: depth_m,
            slope_tan: slope_rad.tan(),
            swept_volume_m3: 0.5,
        }
    }

    const NO_BEARING: BearingParams = BearingParams {
        edge_thickness_m: 0.0,
        back_length_m: 0.0,
        cohesion_factor: 0.0,
        depth_factor: 0.0,
        surface_pressure_pa: 0.0,
        creep_speed_m_per_s: 1e-6,
    };

    #[test]
    fn moving_bucket_force_is_eq_17_18_when_pulled_in_below_the_wedge_limit() {
        let psi = SoilProperties::typical();
        let soil = MovingBucketSoil::new(&psi, &NO_BEARING, WIDTH_M).expect("soil");
        let profile =
            SectionProfile::from_fn(0.0, 15.0, 0.05, |x| 0.3 * (x - 4.0)).expect("profile");
        for (bucket_abs_deg, slope_deg) in [(-130.0_f64, 0.0_f64), (-150.0, 10.0), (-110.0, -5.0)] {
            let slope = slope_deg.to_radians();
            let m = motion_toward_machine(bucket_abs_deg.to_radians(), 0.4, slope);
            let f = soil.force(&m).expect("force");
            let pose = BucketPose {
                x_m: 8.0,
                z_m: profile.height_at(8.0).expect("h") - 0.4,
                bucket_abs_rad: bucket_abs_deg.to_radians(),
            };
            let Contact::InContact(g) = dig_geometry(&pose, &profile, 0.5).expect("gamma") else {
                panic!("in contact");
            };
            let g = DigGeometry {
                slope_rad: slope,
                depth_m: 0.4 * slope.cos(),
                rake_rad: -(wrap_angle(bucket_abs_deg.to_radians() + PI) - slope),
                ..g
            };
            let e = fee_tip_force(&psi, &g, WIDTH_M, 0.0).expect("eq 17");
            assert!(
                (f.fx_n - e.fx_n).abs() < 1e-6 * e.fx_n.abs().max(1.0),
                "{f:?} {e:?}"
            );
            assert!(
                (f.fz_n - e.fz_n).abs() < 1e-6 * e.fz_n.abs().max(1.0),
                "{f:?} {e:?}"
            );
        }
    }

    /// Regression: a bucket pulled in at an open attitude (rake past the wedge's failure limit) got no
    /// soil force at all in the dig model (Eq. 17's singular denominator mapped to zero), so it dove
    /// 1 m deeper than the simulated machine, whose soil saturates there.
    #[test]
    fn force_past_the_wedge_limit_saturates_instead_of_vanishing() {
        let psi = SoilProperties::typical();
        let soil = MovingBucketSoil::new(&psi, &NO_BEARING, WIDTH_M).expect("soil");
        let limit =
            PI - psi.failure_angle_rad - psi.friction_angle_rad - psi.tool_friction_angle_rad;
        // Rake = blade_abs on flat ground, blade_abs = bucket_abs + 180 degrees.
        let at_rake = |rake: f64| {
            let f = soil
                .force(&motion_toward_machine(rake - PI, 0.4, 0.0))
                .expect("force");
            f.fx_n.hypot(f.fz_n)
        };
        let saturated = at_rake(limit - WEDGE_LIMIT_MARGIN_RAD);
        assert!(saturated > 2.0 * at_rake(45f64.to_radians()), "{saturated}");
        for rake in [limit - 1e-3, limit + 0.2, 2.9] {
            assert!(
                (at_rake(rake) - saturated).abs() < 1e-6 * saturated,
                "rake {rake}"
            );
        }
    }

    /// The wedge's outward share: half of each side for an edge moving straight up, nearly all on
    /// the side the edge travels at speed, continuous across `vx = 0`, its gradient the share's
    /// derivative; and the moving-bucket force turns over smoothly with it.
    #[test]
    fn the_wedge_turns_over_smoothly_with_the_travel() {
        let creep = 0.01;
        assert!((outward_wedge_share([0.0, 0.3], creep).0 - 0.5).abs() < 1e-12);
        assert!(outward_wedge_share([0.4, 0.0], creep).0 > 0.999);
        assert!(outward_wedge_share([-0.4, 0.0], creep).0 < 0.001);
        assert_eq!(outward_wedge_share([f64::NAN, 0.0], creep), (0.5, [0.0; 2]));
        let h = 1e-8;
        for v in [[0.0, 0.3], [0.003, -0.004], [-0.3, 0.1], [0.2, 0.05]] {
            let (_, g) = outward_wedge_share(v, creep);
            for c in 0..2 {
                let (mut up, mut down) = (v, v);
                up[c] += h;
                down[c] -= h;
                let numeric = (outward_wedge_share(up, creep).0
                    - outward_wedge_share(down, creep).0)
                    / (2.0 * h);
                assert!(
                    (g[c] - numeric).abs() < 1e-5 * numeric.abs().max(1.0),
                    "{v:?} {c}"
                );
            }
        }
        let soil =
            MovingBucketSoil::new(&SoilProperties::typical(), &NO_BEARING, WIDTH_M).expect("soil");
        let rising = |vx: f64| {
            let mut m = motion_toward_machine(-130f64.to_radians(), 0.4, 0.0);
            m.tip_velocity_m_per_s = [vx, 0.3];
            soil.force(&m).expect("force")
        };
        let (a, b) = (rising(-1e-6), rising(1e-6));
        assert!(
            (a.fx_n - b.fx_n).hypot(a.fz_n - b.fz_n) < 1.0,
            "{a:?} {b:?}"
        );
    }

    /// The bearing speeds are the tip velocity against the blade (tip -> pin) and against the
    /// opening, and the force has a bearing exactly where its speed is positive.
    #[test]
    fn bearing_speeds_are_the_pushes_of_the_edge_and_of_the_back() {
        let psi = SoilProperties::typical();
        let bearing = BearingParams::default();
        let soil = MovingBucketSoil::new(&psi, &bearing, WIDTH_M).expect("soil");
        // Bucket line vertical (tip below the pin): the blade points up, the opening toward -x.
        let base = motion_toward_machine(-0.5 * PI, 0.3, 0.0);
        let m = |v: [f64; 2]| BucketMotion {
            tip_velocity_m_per_s: v,
            ..base
        };
        let [edge, back] = m([0.1, -0.2]).bearing_speeds_m_per_s();
        assert!(
            (edge - 0.2).abs() < 1e-12 && (back - 0.1).abs() < 1e-12,
            "{edge} {back}"
        );
        let [edge, back] = m([-0.1, 0.2]).bearing_speeds_m_per_s();
        assert!(
            (edge + 0.2).abs() < 1e-12 && (back + 0.1).abs() < 1e-12,
            "{edge} {back}"
        );
        // Pushed down: the edge bears (up the blade); drawn up: no bearing, the FEE alone.
        let down = soil.force(&m([-0.1, -0.2])).expect("force");
        let up = soil.force(&m([-0.1, 0.2])).expect("force");
        let edge_n = bearing.pressure_pa(&psi, 0.3) * WIDTH_M * bearing.edge_thickness_m;
        assert!(
            down.fz_n - up.fz_n > 0.9 * edge_n,
            "{down:?} {up:?} {edge_n}"
        );
    }

    #[test]
    fn bearing_resists_pushing_the_edge_in_and_nothing_acts_above_ground() {
        let psi = SoilProperties::typical();
        let bearing = BearingParams::default();
        let soil = MovingBucketSoil::new(&psi, &bearing, WIDTH_M).expect("soil");
        // Bucket line vertical (tip below the pin), pushed straight down: the edge bears, up the blade.
        let down = BucketMotion {
            tip_velocity_m_per_s: [0.0, -0.2],
            ..motion_toward_machine(-0.5 * PI, 0.3, 0.0)
        };
        let f = soil.force(&down).expect("force");
        let edge = bearing.pressure_pa(&psi, 0.3) * WIDTH_M * bearing.edge_thickness_m;
        assert!(f.fz_n > 0.9 * edge, "{f:?} vs {edge}");
        let above = BucketMotion {
            vertical_depth_m: -0.1,
            ..down
        };
        assert_eq!(soil.force(&above).expect("force"), TipForce::default());
        let nan = BucketMotion {
            slope_tan: f64::NAN,
            ..down
        };
        assert!(matches!(soil.force(&nan), Err(SoilError::NonFinite { .. })));
        let bad = BearingParams {
            creep_speed_m_per_s: 0.0,
            ..bearing
        };
        assert!(MovingBucketSoil::new(&psi, &bad, WIDTH_M).is_err());
    }

    proptest! {
        #[test]
        fn fee_never_panics_or_returns_nan(d in -1.0f64..3.0, a in -2.0f64..2.0, r in -4.0f64..4.0, v in -1.0f64..3.0, b in -0.5f64..2.0, p in -0.5f64..2.0, dl in -0.5f64..2.0, c in -1e4f64..1e5) {
            let psi = SoilProperties { density_kg_per_m3: 1700.0, failure_angle_rad: b, friction_angle_rad: p, tool_friction_angle_rad: dl, cohesion_pa: c };
            let g = DigGeometry { depth_m: d, slope_rad: a, rake_rad: r, swept_volume_m3: v };
            if let Ok(f) = fee_tip_force(&psi, &g, WIDTH_M, 0.3) {
                prop_assert!(f.fx_n.is_finite() && f.fz_n.is_finite() && f.my_nm.is_finite());
            }
        }
    }
}
