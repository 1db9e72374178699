//! The hydraulic relations: the metering orifices (Eq. 1), the cylinder velocity from continuity
//! with leakage and oil compression (Eq. 2), the open-centre pump flow balance (thesis 4.2.1, Fig.
//! 15) and the steady-state velocity the grey-box actuator uses.

use super::params::GreyBoxParams;

/// An inlet chamber reading this far above its supply (pump gallery, crossover) has its load check
/// shut, Pa: ten standard deviations of the difference of two readings with the transducer noise
/// (0.05 MPa each), so that noise does not toggle the balance.
const LOAD_CHECK_MARGIN_PA: f64 = 7.0e5;
/// A chamber behind a closed spool reading less than this above tank may be taking make-up oil
/// through its anti-cavitation check valve, Pa: four standard deviations of the transducer noise.
const MAKEUP_MARGIN_PA: f64 = 2.0e5;

/// Laminar-regularised orifice flow (Eq. 1) for a constant `k = Cd A sqrt(2/rho)`, positive for `dp > 0`.
#[inline]
fn orifice(k: f64, dp: f64, laminar_dp_pa: f64) -> f64 {
    orifice_and_slope(k, dp, laminar_dp_pa).0
}

/// [`orifice`]'s flow and its derivative in `dp` (the pump solve's Newton steps).
#[inline]
fn orifice_and_slope(k: f64, dp: f64, laminar_dp_pa: f64) -> (f64, f64) {
    if k <= 0.0 {
        (0.0, 0.0)
    } else if dp.abs() < laminar_dp_pa {
        let root = laminar_dp_pa.sqrt();
        (k * dp / root, k / root)
    } else {
        let root = dp.abs().sqrt();
        (k * root * dp.signum(), 0.5 * k / root)
    }
}

pub(super) fn metering(params: &GreyBoxParams, spool: f64) -> f64 {
    ((spool.abs() - params.overlap) / (1.0 - params.overlap)).clamp(0.0, 1.0)
}

pub(super) fn bypass_fraction(params: &GreyBoxParams, spool: f64) -> f64 {
    (1.0 - spool.abs() / params.bypass_close).clamp(0.0, 1.0)
}

pub(super) fn crossover_fraction(params: &GreyBoxParams, boom_spool: f64) -> f64 {
    ((boom_spool.abs() - params.crossover_start) / (params.crossover_full - params.crossover_start))
        .clamp(0.0, 1.0)
}

/// Series bypass constant of the valves `fractions` (1/k^2 = sum 1/k_i^2), zero if one is closed.
pub(super) fn series_bypass(k: f64, fractions: &[f64]) -> f64 {
    let mut inv = 0.0;
    for f in fractions {
        if *f <= 0.0 {
            return 0.0;
        }
        inv += 1.0 / (k * f).powi(2);
    }
    if inv > 0.0 { inv.sqrt().recip() } else { 0.0 }
}

/// Cylinder velocity from the two metering orifices and the measured pressures (Eq. 1, continuity).
#[allow(clippy::too_many_arguments)]
pub(super) fn cylinder_velocity(
    params: &GreyBoxParams,
    i: usize,
    spool: f64,
    meter_in_scale: f64,
    head_pa: f64,
    rod_pa: f64,
    gallery_pa: f64,
    crossover: Option<(f64, f64)>,
    leak: f64,
    compression: [f64; 2],
    clamped: [bool; 2],
) -> f64 {
    let (ah, ar) = (params.head_area_m2[i], params.rod_area_m2[i]);
    let leak_flow = leak * (head_pa - rod_pa);
    let [c_head, c_rod] = compression;
    let a = metering(params, spool);
    if a <= 0.0 && !params.chamber_balance {
        // Closed spool, without the chamber balance: only the cross-piston leakage moves it.
        return -leak_flow / ah;
    }
    // With the chamber balance, a chamber below tank pressure is filled through its
    // anti-cavitation check valve as well (an unknown make-up inflow).
    let makeup_below = if params.chamber_balance {
        params.tank_pa
    } else {
        f64::NEG_INFINITY
    };
    // Behind a closed spool, a chamber whose reading sits at the sensor's zero (`clamped`:
    // `[head, rod]`) may be below tank as well, whatever a negative pressure offset takes its true value for, and its pressure rate
    // (the Eq. 2 compression) is not seen: its balance is unknown too. (Session
    // pressure_sensor_offset_-800000: the stick pulled out with its head at 0, read as a chamber at
    // tank under the fitted offset, predicted the stick at rest, and the offset fitted 0.)
    let fed = |p: f64, clamped: bool| p < makeup_below || (params.chamber_balance && clamped);
    let (head_fed, rod_fed) = (fed(head_pa, clamped[0]), fed(rod_pa, clamped[1]));
    if a <= 0.0 {
        // Closed spool: the piston moves by the oil that leaks across it and by the compression of
        // the trapped oil (Eq. 2): head `0 = A_h v + L dp + C_h`, rod `0 = -A_r v - L dp + C_r`;
        // the two estimates weighted as `A^2` (inverse to the variance a flow error gives them).
        // A chamber below tank pressure draws make-up oil through its anti-cavitation check valve,
        // so its own balance is unknown and only the other chamber's counts; so may one that reads
        // within the reading noise of tank ([`MAKEUP_MARGIN_PA`]): the check valve passes a large
        // flow for a small deficit, so an expanding chamber sits at tank taking it. (Session
        // internal_leakage_1e-11: the stick drifting out at 3-10 cm/s behind its closed spool, rod
        // 21-31 MPa, head 0.26-0.36 MPa; the head's balance, weighted in whenever the noise put
        // its reading above 0.3 MPa, predicted less than half the speed the rod's outflow gave.)
        let near_tank = |p: f64| params.chamber_balance && p < params.tank_pa + MAKEUP_MARGIN_PA;
        let v_head = -(leak_flow + c_head) / ah;
        let v_rod = (c_rod - leak_flow) / ar;
        let w_head = if head_fed || near_tank(head_pa) {
            0.0
        } else {
            ah * ah
        };
        let w_rod = if rod_fed || near_tank(rod_pa) {
            0.0
        } else {
            ar * ar
        };
        if w_head + w_rod <= 0.0 {
            return 0.0;
        }
        return (w_head * v_head + w_rod * v_rod) / (w_head + w_rod);
    }
    let lam = params.laminar_dp_pa;
    let k_in = params.meter_in_k[i] * a * meter_in_scale;
    let k_out = params.meter_out_k[i] * a;
    let tank = params.tank_pa;
    let (p_in, p_out, a_in, a_out) = if spool > 0.0 {
        (head_pa, rod_pa, ah, ar)
    } else {
        (rod_pa, head_pa, ar, ah)
    };
    // A clamped inlet reading is either a lightly loaded inlet near tank (its meter-in drop from the
    // pump is large and known well enough) or an inlet below tank fed by make-up while the load
    // overruns the piston; in the second case the outlet carries the load, its drop well clear of
    // the reading noise, and the meter-out estimate is the one to take. (Session
    // pressure_sensor_offset_-800000: the stick running out with its head at 0 and the rod
    // metering the load; bucket moves with both chambers near tank.)
    let clamped_in = if spool > 0.0 { clamped[0] } else { clamped[1] };
    let in_fed = p_in < makeup_below
        || (params.chamber_balance && clamped_in && p_out - params.tank_pa > LOAD_CHECK_MARGIN_PA);
    let dp_in = gallery_pa - p_in;
    let mut q_in = if dp_in > 0.0 {
        orifice(k_in, dp_in, lam)
    } else {
        0.0
    };
    // An inlet chamber below tank pressure (an overrunning load) is filled through its
    // anti-cavitation check valve as well: the meter-in orifice does not bound its flow, and the
    // meter-out orifice alone sets the speed.
    let mut w_in = if dp_in > 2.0e5 && k_in > 0.0 && !in_fed {
        dp_in * a_in * a_in / (k_in * k_in)
    } else {
        0.0
    };
    if let Some((xk, cross_pa)) = crossover {
        let dpx = cross_pa - p_in;
        if dpx > 0.0 && xk > 0.0 {
            q_in += orifice(xk, dpx, lam);
            if !in_fed {
                w_in = w_in.max(dpx * a_in * a_in / ((k_in + xk) * (k_in + xk)));
            }
        }
    }
    let dp_out = (p_out - tank).max(0.0);
    let q_out = orifice(k_out, dp_out, lam);
    let mut w_out = dp_out.max(1.0e4) * a_out * a_out / (k_out * k_out);
    // With the chamber balance, a piston driven against the spool's direction by its load: the
    // inlet chamber is pressed above its supply and the load check shuts the meter-in, so the inlet
    // is a dead end whose own continuity `0 = +-A v + L dp + C` (Eq. 2) gives the speed, as behind a
    // closed spool; the outlet chamber expands instead of draining, filled from the tank through
    // its meter-out orifice in reverse and its anti-cavitation check valve, a flow its balance
    // (which only drains) cannot give. (Effect-free session none_s200: the stick pulled out at
    // 0.1-0.27 m/s against a retract command, rod 7-35 MPa and rising above a 6 MPa pump, head at
    // 0; the outlet's balance predicted 0, and its cross-piston leakage `L (p_h - p_r)` was the only
    // term that moved towards the measurement.) Taken on the inlet's excess over the supply, which
    // a pressure offset leaves alone, not on the outlet's reading: with an offset of -0.8 MPa every
    // draining outlet at tank reads 0 as well.
    let supply_pa = match crossover {
        Some((xk, cross_pa)) if xk > 0.0 => gallery_pa.max(cross_pa),
        _ => gallery_pa,
    };
    if params.chamber_balance && p_in > supply_pa + LOAD_CHECK_MARGIN_PA {
        w_in = 1.0;
        w_out = 0.0;
    }
    // Continuity with leakage L (p_h - p_r) from head to rod and the oil compression C (Eq. 2):
    //   head: Q_head_in = A_h v + L dp + C_h,  rod: Q_rod_in = -A_r v - L dp + C_r.
    let (v_in, v_out) = if spool > 0.0 {
        (
            (q_in - leak_flow - c_head) / ah,
            (q_out - leak_flow + c_rod) / ar,
        )
    } else {
        (
            -(q_in + leak_flow - c_rod) / ar,
            -(q_out + leak_flow + c_head) / ah,
        )
    };
    (w_in * v_in + w_out * v_out) / (w_in + w_out)
}

/// The pump-side terms of one pump's flow balance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PumpBalance {
    /// Maximum pump flow, m^3/s.
    pub(super) max_flow: f64,
    /// Open-centre bypass constant, m^3/(s sqrt(Pa)).
    pub(super) bypass_k: f64,
    /// Flow taken regardless of the pressure (the swing motor), m^3/s.
    pub(super) fixed_demand: f64,
}

/// The last gallery pressure solved with every metering orifice of a pump closed: then the balance
/// depends on the pump terms alone, the same at every sample of a record where the pump only
/// bypasses (idle, scans, swinging with the arm at rest), so one solve serves them all.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct NeutralCache {
    last: Option<(PumpBalance, f64)>,
}

impl NeutralCache {
    pub(super) fn solve(
        &mut self,
        params: &GreyBoxParams,
        b: PumpBalance,
        meter_in: &[(f64, f64)],
        guess: f64,
    ) -> f64 {
        if meter_in.iter().any(|(k, _)| *k > 0.0) {
            return pump_pressure(params, b, meter_in, guess);
        }
        if let Some((key, p)) = self.last
            && key == b
        {
            return p;
        }
        let p = pump_pressure(params, b, &[], guess);
        self.last = Some((b, p));
        p
    }
}

/// The pump balance is solved to this pressure, Pa.
const SOLVE_TOLERANCE_PA: f64 = 1.0e3;

/// Most steps of the pump solve (Newton or bisection); the bisection alone needs about 16 on the
/// whole window from the tank to above the relief.
const SOLVE_MAX_STEPS: usize = 60;

/// Gallery pressure of one pump from its flow balance (Eqs. 1-2 at the pump: supply less the
/// bypass, the open meter-in orifices and the relief), solved by Newton's method from `guess_pa`
/// (the measured pump pressure or an earlier replay's prediction, usually within a few hundred
/// kPa of the root), safeguarded by bisection: the balance falls monotonically with the pressure,
/// so the root is unique and every evaluation narrows a bracket `[tank, top]` around it; a Newton
/// step that would leave the bracket (at a kink of the balance: the power limit, a laminar-turbulent
/// change, the relief) is replaced by its midpoint.
fn pump_pressure(
    params: &GreyBoxParams,
    b: PumpBalance,
    meter_in: &[(f64, f64)],
    guess_pa: f64,
) -> f64 {
    let lam = params.laminar_dp_pa;
    let tank = params.tank_pa;
    let relief_slope = params.pump_max_flow_m3_per_s / params.relief_override_pa;
    // The balance (flow surplus, m^3/s) and its slope in the pressure.
    let balance = |p: f64| {
        let supply = params.pump_power_w / p.max(1.0);
        let (mut f, mut df) = if supply < b.max_flow {
            (supply, -supply / p.max(1.0))
        } else {
            (b.max_flow, 0.0)
        };
        f -= b.fixed_demand;
        let mut take = |k: f64, dp: f64| {
            let (q, dq) = orifice_and_slope(k, dp, lam);
            f -= q;
            df -= dq;
        };
        take(b.bypass_k, p - tank);
        for (k, p_in) in meter_in {
            if p > *p_in {
                take(*k, p - p_in);
            }
        }
        if p > params.relief_pa {
            f -= relief_slope * (p - params.relief_pa);
            df -= relief_slope;
        }
        (f, df)
    };
    // Above `top` the relief alone takes 20 times the pump's flow: the balance is negative there.
    let top = params.relief_pa + 20.0 * params.relief_override_pa;
    let (mut lo, mut hi) = (tank, top);
    let mut tank_checked = false;
    let mut p = if guess_pa.is_finite() {
        guess_pa.clamp(tank, top)
    } else {
        0.5 * (tank + top)
    };
    for _ in 0..SOLVE_MAX_STEPS {
        let (f, df) = balance(p);
        if f == 0.0 {
            return p;
        }
        if f > 0.0 {
            lo = p;
        } else {
            hi = p;
        }
        let newton = p - f / df;
        let next = if newton > lo && newton < hi {
            newton
        } else {
            // A step out of the bracket toward the tank: the tank itself may be the answer
            // (nothing demanded and no bypass flow to push).
            if lo <= tank && !tank_checked {
                tank_checked = true;
                if balance(tank).0 <= 0.0 {
                    return tank;
                }
            }
            0.5 * (lo + hi)
        };
        if (next - p).abs() < SOLVE_TOLERANCE_PA || hi - lo < SOLVE_TOLERANCE_PA {
            return next;
        }
        p = next;
    }
    p
}

/// Cylinder velocity the grey-box model gives for a spool position and a cylinder force, used by
/// [`crate::GreyBoxActuator`]: the meter-in and meter-out orifices in series with the force balance
/// `p_h A_h - p_r A_r = F` (Eqs. 1, 3 in steady state), fed by the pump flow `q_max` available to this
/// cylinder, which splits between the cylinder and the open-centre bypass of constant `bypass_k`
/// (Fig. 15). The speed is found by bisection: the flow left for the cylinder falls as the speed, and
/// with it the pump pressure, rises.
#[allow(clippy::too_many_arguments)]
pub fn steady_velocity(
    params: &GreyBoxParams,
    i: usize,
    spool: f64,
    meter_in_scale: f64,
    force_n: f64,
    q_max: f64,
    bypass_k: f64,
    leak: f64,
) -> f64 {
    let a = metering(params, spool);
    if a <= 0.0 || q_max <= 0.0 {
        return 0.0;
    }
    let (ah, ar) = (params.head_area_m2[i], params.rod_area_m2[i]);
    let (a_in, a_out, load) = if spool > 0.0 {
        (ah, ar, force_n)
    } else {
        (ar, ah, -force_n)
    };
    let k_in = (params.meter_in_k[i] * a * meter_in_scale).max(1e-12);
    let k_out = (params.meter_out_k[i] * a).max(1e-12);
    let tank = params.tank_pa;
    let lam = params.laminar_dp_pa;
    // Surplus of pump flow over what the cylinder and the bypass take at speed u (>= 0): outlet
    // pressure from the meter-out drop, inlet from the force balance, pump from the meter-in drop.
    let surplus = |u: f64| {
        let p_out = tank + (a_out * u / k_out).powi(2);
        let p_in = ((load + a_out * p_out) / a_in).max(0.0);
        let q = a_in * u + leak * (p_in - p_out).abs();
        let p_pump = p_in + (q / k_in).powi(2);
        if p_pump > params.relief_pa {
            return -1.0;
        }
        q_max.min(params.pump_power_w / p_pump.max(1.0)) - q - orifice(bypass_k, p_pump - tank, lam)
    };
    let (mut lo, mut hi) = (0.0, q_max / a_in);
    if surplus(lo) <= 0.0 {
        return 0.0;
    }
    if surplus(hi) >= 0.0 {
        return hi * spool.signum();
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if surplus(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo * spool.signum()
}

/// Open-centre bypass constant of a pump whose sections have the given spool positions.
pub fn bypass_constant(params: &GreyBoxParams, spools: [f64; 2]) -> f64 {
    series_bypass(params.bypass_k, &spools.map(|s| bypass_fraction(params, s)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chamber balance: a closed spool moves by the compression flows of both chambers (each
    /// alone gives the same speed when they agree), and an inlet chamber below tank pressure leaves
    /// the speed to the meter-out orifice; without the option neither changes the relation.
    #[test]
    fn chamber_balance_compression_and_makeup() {
        let mut params = crate::AugmentedModel::nominal().unwrap().params;
        // The relation itself, without the shipped model's chamber balance and calibrated leakage.
        params.chamber_balance = false;
        params.internal_leakage_m3_per_s_pa = 0.0;
        let (ah, ar) = (params.head_area_m2[1], params.rod_area_m2[1]);
        let v = -0.02;
        // Retracting at 2 cm/s with closed ports: the head is compressed, the rod expands.
        let comp = [-ah * v, ar * v];
        let closed = |p: &GreyBoxParams| {
            cylinder_velocity(
                p, 1, 0.0, 1.0, 8.0e6, 4.0e6, 9.0e6, None, 0.0, comp, [false; 2],
            )
        };
        assert_eq!(closed(&params), 0.0);
        params.chamber_balance = true;
        assert!((closed(&params) - v).abs() < 1e-12, "{}", closed(&params));
        // Extending with the head (inlet) below tank: the meter-out estimate alone.
        let overrun = |p: &GreyBoxParams, head: f64| {
            cylinder_velocity(
                p, 1, 0.8, 1.0, head, 6.0e6, 10.0e6, None, 0.0, [0.0; 2], [false; 2],
            )
        };
        let k_out = params.meter_out_k[1] * metering(&params, 0.8);
        let meter_out_only = orifice(k_out, 6.0e6 - params.tank_pa, params.laminar_dp_pa) / ar;
        assert!((overrun(&params, 1.0e5) - meter_out_only).abs() < 1e-9);
        params.chamber_balance = false;
        assert!((overrun(&params, 1.0e5) - meter_out_only).abs() > 1e-3);
        // Pulled out at 0.2 m/s against a retract command: the rod (inlet) pressed to 20 MPa above
        // a 6 MPa pump, its load check shut, the head (outlet) at 0 filling by make-up. The rod's
        // own balance gives the speed; the outlet's, which can only drain, gave none.
        params.chamber_balance = true;
        let pulled = 0.2;
        let comp = [0.0, ar * pulled];
        let dead_end = |p: &GreyBoxParams, clamped: [bool; 2]| {
            cylinder_velocity(
                p, 1, -0.5, 1.0, 0.0, 20.0e6, 6.0e6, None, 0.0, comp, clamped,
            )
        };
        for clamped in [[false; 2], [true, false]] {
            assert!((dead_end(&params, clamped) - pulled).abs() < 1e-12);
        }
        // The rod just above the pump (within the reading noise): the balance as before.
        let near = cylinder_velocity(
            &params, 1, -0.5, 1.0, 0.0, 6.2e6, 6.0e6, None, 0.0, comp, [false; 2],
        );
        assert!(near.abs() < 0.05, "{near}");
        // Behind a closed spool, a clamped head reading leaves the speed to the rod's balance.
        let closed_clamped = cylinder_velocity(
            &params,
            1,
            0.0,
            1.0,
            params.tank_pa,
            20.0e6,
            6.0e6,
            None,
            0.0,
            comp,
            [true, false],
        );
        assert!((closed_clamped - pulled).abs() < 1e-12, "{closed_clamped}");
    }

    /// The solve's ends: a demand above the pump's flow leaves the gallery at the tank, and a
    /// pump with every path closed (no bypass, no open valve) rises above the relief until the
    /// relief takes the pump's whole flow, from any start.
    #[test]
    fn pump_pressure_at_the_tank_and_over_the_relief() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let starved = PumpBalance {
            max_flow: params.pump_max_flow_m3_per_s,
            bypass_k: params.bypass_k,
            fixed_demand: 2.0 * params.pump_max_flow_m3_per_s,
        };
        let closed = PumpBalance {
            max_flow: params.pump_max_flow_m3_per_s,
            bypass_k: 0.0,
            fixed_demand: 0.0,
        };
        // Above the relief the supply is power-limited: P / p = (p - relief) q_max / override.
        let (r, o, q) = (
            params.relief_pa,
            params.relief_override_pa,
            params.pump_max_flow_m3_per_s,
        );
        let supply = |p: f64| (params.pump_power_w / p).min(q);
        for guess in [f64::NAN, 0.0, 3.0e5, 1.0e7, r, 1.0e9] {
            assert_eq!(pump_pressure(&params, starved, &[], guess), params.tank_pa);
            let p = pump_pressure(&params, closed, &[(0.0, 0.0)], guess);
            let surplus = supply(p) - q * (p - r) / o;
            assert!(
                p > r && surplus.abs() * o / q < 2.0e3,
                "guess {guess}: {p}, {surplus}"
            );
        }
    }

    /// The warm-started solve finds the flow balance's unique root from any starting guess, and the
    /// neutral-valve cache returns what a fresh solve gives.
    #[test]
    fn pump_pressure_does_not_depend_on_the_guess_and_the_neutral_cache_is_exact() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let b = PumpBalance {
            max_flow: params.pump_max_flow_m3_per_s,
            bypass_k: 0.3 * params.bypass_k,
            fixed_demand: 0.0,
        };
        let meter = [(0.5 * params.meter_in_k[0], 8.0e6), (0.0, 0.0)];
        let reference = pump_pressure(&params, b, &meter, f64::NAN);
        assert!(
            reference > params.tank_pa && reference < params.relief_pa + 2.0e6,
            "{reference}"
        );
        for guess in [0.0, 1.0e5, 5.0e6, 9.0e6, 2.0e7, 4.0e7, 1.0e9] {
            let p = pump_pressure(&params, b, &meter, guess);
            let q = pump_pressure(&params, b, &meter, 0.5 * guess + 1.0e5);
            assert!(
                (q - reference).abs() < 2.0e3,
                "guess {}: {q} vs {reference}",
                0.5 * guess + 1.0e5
            );
            assert!(
                (p - reference).abs() < 2.0e3,
                "guess {guess}: {p} vs {reference}"
            );
        }
        let neutral = PumpBalance {
            bypass_k: params.bypass_k,
            ..b
        };
        let fresh = pump_pressure(&params, neutral, &[], 1.0e6);
        let mut cache = NeutralCache::default();
        let closed = [(0.0, 5.0e6)];
        assert_eq!(cache.solve(&params, neutral, &closed, 1.0e6), fresh);
        assert_eq!(cache.solve(&params, neutral, &closed, 3.0e6), fresh);
        // An open orifice is never served from the cache.
        let open = cache.solve(&params, neutral, &meter, 1.0e6);
        assert!((open - pump_pressure(&params, neutral, &meter, 1.0e6)).abs() < 1e-9);
    }
}
