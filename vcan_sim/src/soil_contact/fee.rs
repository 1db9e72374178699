//! The soil's failure force on the blade: the modified Fundamental Earthmoving Equation (Eqs. 14-17,
//! [`planner::soil::fee_force_n`]) with the rake held from the wedge's failure limit, and its split
//! by layer for a cut reaching into the native ground below a bench's floor (Fig. 25).

use planner::machine::GRAVITY_M_PER_S2;
use planner::soil::{DigGeometry, SoilProperties, fee_factors, fee_force_n};

/// Closest approach of the rake to the wedge's failure limit, rad. Eq. 17's denominator
/// `cos(rho + delta) + sin(rho + delta) cot(beta + phi)` equals `sin(beta + phi + rho + delta) /
/// sin(beta + phi)` and vanishes as the rake plus the three friction and failure angles reach 180
/// degrees, where the FEE force grows without bound (a blade flipping its direction of travel inside a
/// full bucket gave 12 MN, two orders of magnitude above the thesis's ~1e5 N digging forces). A blade at
/// or past that rake still bulldozes the soil ahead of it, so the force is evaluated at the rake this
/// far from the limit: it saturates (at about four times the force at a typical 45 degree rake) instead
/// of diverging or vanishing.
const RAKE_LIMIT_MARGIN_RAD: f64 = 0.17;

/// The FEE force magnitude on the bucket (Eqs. 14-17, [`planner::soil::fee_force_n`]), N. Zero out of
/// the soil and for soil properties outside their physical range; near or past the wedge's failure
/// limit the rake is held [`RAKE_LIMIT_MARGIN_RAD`] from it, so the simulator never sees an unbounded
/// force.
fn failure_force_n(soil: &SoilProperties, gamma: &DigGeometry, width_m: f64) -> f64 {
    if gamma.depth_m <= 0.0 {
        return 0.0;
    }
    fee_force_n(soil, &rake_within_limit(soil, gamma), width_m).unwrap_or(0.0)
}

/// The geometry with the rake held [`RAKE_LIMIT_MARGIN_RAD`] from the wedge's failure limit of `soil`.
fn rake_within_limit(soil: &SoilProperties, gamma: &DigGeometry) -> DigGeometry {
    let limit = std::f64::consts::PI
        - soil.failure_angle_rad
        - soil.friction_angle_rad
        - soil.tool_friction_angle_rad;
    let rake = (-gamma.rake_rad).min(limit - RAKE_LIMIT_MARGIN_RAD);
    DigGeometry {
        rake_rad: -rake,
        ..*gamma
    }
}

/// The FEE force magnitude on the bucket for a cut reaching from the bench material (`upper`) into
/// the native ground below the floor (`lower`), N: Eq. 17's terms split along the wedge of Fig. 25,
/// with `below` the share of the cut depth `d` under the floor (the failure plane is straight from
/// the edge to the surface, so the same share of its length):
///
/// `F = d^2 w g [(1 - f^2) gamma_u N_w,u + f^2 gamma_l N_w,l] + w d [(1 - f) c_u N_c,u + f c_l N_c,l]
///      + V_s gamma_u g [(1 - f) N_q,u + f N_q,l]`
///
/// The weight term is the wedge's area (`~ d^2`; the part below the floor is the similar triangle of
/// depth `f d`), the cohesion term acts along the failure plane (`~ d`), and the surcharge is the
/// swept bench material carried across that plane. Each layer's factors are its own (Eq. 17), with the
/// rake held from its own failure limit as in [`failure_force_n`]. `below = 0` gives
/// [`failure_force_n`] of the upper soil exactly, `below = 1` the lower soil's wedge under the bench
/// material's surcharge. A layering approximation (a superposition of the two wedges' terms), not a
/// two-layer wedge analysis: the failure plane's angle is not re-solved for the layers.
pub(super) fn layered_failure_force_n(
    upper: &SoilProperties,
    lower: &SoilProperties,
    below: f64,
    gamma: &DigGeometry,
    width_m: f64,
) -> f64 {
    let f = below.clamp(0.0, 1.0);
    if f <= 0.0 {
        return failure_force_n(upper, gamma, width_m);
    }
    if gamma.depth_m <= 0.0 || !(width_m.is_finite() && width_m > 0.0) {
        return 0.0;
    }
    let (Ok(nu), Ok(nl)) = (
        fee_factors(upper, &rake_within_limit(upper, gamma)),
        fee_factors(lower, &rake_within_limit(lower, gamma)),
    ) else {
        return 0.0;
    };
    let g = GRAVITY_M_PER_S2;
    let d = gamma.depth_m;
    let weight = d
        * d
        * width_m
        * g
        * ((1.0 - f * f) * upper.density_kg_per_m3 * nu.n_w
            + f * f * lower.density_kg_per_m3 * nl.n_w);
    let cohesion =
        width_m * d * ((1.0 - f) * upper.cohesion_pa * nu.n_c + f * lower.cohesion_pa * nl.n_c);
    let surcharge =
        gamma.swept_volume_m3 * upper.density_kg_per_m3 * g * ((1.0 - f) * nu.n_q + f * nl.n_q);
    let force = weight + cohesion + surcharge;
    if force.is_finite() {
        force.max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::super::world::soil_properties;
    use super::*;
    use crate::scenario::SoilSpec;

    #[test]
    fn failure_force_is_the_planners_fee_and_grows_with_depth_cohesion_and_swept_volume() {
        let soil = soil_properties(&SoilSpec::default());
        let at = |d: f64, swept_m3: f64| DigGeometry {
            depth_m: d,
            slope_rad: 0.0,
            rake_rad: -1.2,
            swept_volume_m3: swept_m3,
        };
        let f1 = failure_force_n(&soil, &at(0.2, 0.0), 1.3);
        let f2 = failure_force_n(&soil, &at(0.4, 0.0), 1.3);
        let f3 = failure_force_n(&soil, &at(0.4, 0.5), 1.3);
        assert!(f1 > 0.0 && f2 > f1 && f3 > f2);
        assert_eq!(f3, fee_force_n(&soil, &at(0.4, 0.5), 1.3).unwrap());
        let hard = SoilProperties {
            cohesion_pa: 50_000.0,
            ..soil
        };
        assert!(failure_force_n(&hard, &at(0.4, 0.0), 1.3) > f2);
        assert_eq!(failure_force_n(&soil, &at(0.0, 0.0), 1.3), 0.0);
        // Near, at and past the wedge's failure limit (rake + delta + beta + phi = 180 degrees) the
        // force saturates at its value RAKE_LIMIT_MARGIN_RAD from the limit: bounded, not zero.
        let limit = std::f64::consts::PI
            - soil.failure_angle_rad
            - soil.friction_angle_rad
            - soil.tool_friction_angle_rad;
        let at_rake = |rake: f64| {
            let g = DigGeometry {
                rake_rad: -rake,
                ..at(0.4, 0.2)
            };
            failure_force_n(&soil, &g, 1.3)
        };
        let saturated = at_rake(limit - RAKE_LIMIT_MARGIN_RAD);
        assert!(
            saturated > f3 && saturated < 10.0 * f3,
            "{saturated} vs {f3}"
        );
        for rake in [limit - 1e-4, limit, limit + 0.3, 3.0] {
            assert_eq!(at_rake(rake), saturated, "rake {rake}");
        }
    }

    #[test]
    fn layered_fee_splits_the_terms_and_is_the_upper_soils_fee_without_depth_below() {
        let upper = soil_properties(&SoilSpec::default());
        let lower = soil_properties(&SoilSpec {
            density_kg_per_m3: 2000.0,
            cohesion_pa: 40_000.0,
            friction_angle_deg: 38.0,
            tool_friction_angle_deg: 22.0,
            failure_angle_deg: 30.0,
        });
        let gamma = DigGeometry {
            depth_m: 0.4,
            slope_rad: 0.0,
            rake_rad: -1.0,
            swept_volume_m3: 0.5,
        };
        let upper_only = failure_force_n(&upper, &gamma, 1.3);
        assert_eq!(
            layered_failure_force_n(&upper, &lower, 0.0, &gamma, 1.3),
            upper_only
        );
        // Harder the more of the cut is below the floor, continuous at the boundary.
        let mut last = upper_only;
        for f in [1e-6, 0.1, 0.25, 0.5, 0.75, 1.0] {
            let layered = layered_failure_force_n(&upper, &lower, f, &gamma, 1.3);
            assert!(layered > last, "share {f}: {layered} <= {last}");
            last = layered;
        }
        let near = layered_failure_force_n(&upper, &lower, 1e-6, &gamma, 1.3);
        assert!((near - upper_only).abs() < 1e-3 * upper_only);
        // All of it below: the lower soil's wedge (Eq. 17) under the upper soil's surcharge.
        let n = fee_factors(&lower, &gamma).unwrap();
        let g = GRAVITY_M_PER_S2;
        let expected = 0.4 * 0.4 * 1.3 * 2000.0 * g * n.n_w
            + 40_000.0 * 1.3 * 0.4 * n.n_c
            + 0.5 * 1700.0 * g * n.n_q;
        assert!(
            (last - expected).abs() < 1e-9 * expected,
            "{last} vs {expected}"
        );
        // The same soil in both layers: the one-soil FEE for any share.
        for f in [0.3, 1.0] {
            let same = layered_failure_force_n(&upper, &upper, f, &gamma, 1.3);
            assert!((same - upper_only).abs() < 1e-9 * upper_only);
        }
    }
}
