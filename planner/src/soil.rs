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
