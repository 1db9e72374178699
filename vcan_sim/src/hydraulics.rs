//! Hydraulic system of the excavator (thesis 4.2.1, Fig. 15): two pumps, an open-centre valve stack,
//! relief valves, three cylinders and the swing motor.
//!
//! Model, per 1 ms physics step (possibly split into substeps):
//!
//! 1. **Valves.** Each spool position `s` in `[-1, 1]` opens a meter-in orifice (pump gallery -> inlet
//!    chamber, through a load-holding check valve), a meter-out orifice (outlet chamber -> tank) and
//!    closes its open-centre bypass (gallery -> tank). Orifice flow is `Q = Cd A sqrt(2 dP / rho)`
//!    (Eq. 1), regularised to a laminar (linear) law below `laminar_dp_pa` so the implicit solves have
//!    a finite slope. The bypasses of the valves on one pump are in series (the centre passage runs
//!    through every spool), so the effective bypass area is `1/A^2 = sum 1/A_i^2`.
//! 2. **Pumps.** Boom and bucket are on pump 1, stick and swing on pump 2 (thesis 4.2.1). Pump flow is
//!    `min(Q_max, W / P)` (flow limit and power destroke). A crossover spool opens when the boom command
//!    exceeds `crossover_start` and lets pump 2's flow reach the boom. The main relief valve of each
//!    gallery opens at `main_relief_pa`. The gallery pressure follows from the flow balance
//!    `Q_pump = Q_bypass + sum Q_meter_in + Q_relief`, solved by a bracketed Newton iteration (the
//!    balance is monotone in the pressure, so the root is unique).
//! 3. **Chambers.** Each chamber pressure obeys Eq. 2, `dP/dt = beta (Q_in - dV/dt) / V`, with port
//!    relief, anti-cavitation make-up and cross-piston leakage. It is integrated with backward
//!    (implicit) Euler in the pressure, solved by Newton per chamber: unconditionally stable for the
//!    stiff orifice-volume dynamics, whatever the chamber volume.
//! 4. **Mechanics.** Eq. 3, `M x'' = P1 A1 - P2 A2 - F`, with the external force `F` (gravity, payload,
//!    soil, via the Appendix relations) and friction, integrated semi-implicitly (velocity from the new
//!    pressures, then position), with end stops at the stroke limits.
//!
//! The swing motor uses the same chamber model with displacement `D` (m^3/rad) in place of the areas.
//! Everything here is pure computation; no clocks, no I/O.

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// Index of the boom actuator in actuator arrays.
pub const BOOM: usize = 0;
/// Index of the stick actuator.
pub const STICK: usize = 1;
/// Index of the bucket actuator.
pub const BUCKET: usize = 2;
/// Index of the swing motor.
pub const SWING: usize = 3;
/// Number of hydraulic actuators modelled with chambers (boom, stick, bucket, swing).
pub const N_ACTUATORS: usize = 4;

/// Hydraulic fluid and orifice constants.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FluidParams {
    /// Effective bulk modulus beta (Pa), lowered from ~1.6 GPa by entrained air (thesis 4.2.1).
    pub bulk_modulus_pa: f64,
    /// Oil density (kg/m^3).
    pub density_kg_per_m3: f64,
    /// Orifice discharge coefficient Cd (Eq. 1).
    pub discharge_coefficient: f64,
    /// Below this pressure drop an orifice is treated as laminar (linear), for solver slope (Pa).
    pub laminar_dp_pa: f64,
    /// Tank (return) pressure (Pa).
    pub tank_pressure_pa: f64,
}

impl Default for FluidParams {
    fn default() -> Self {
        Self {
            bulk_modulus_pa: 1.0e9,
            density_kg_per_m3: 850.0,
            discharge_coefficient: 0.7,
            laminar_dp_pa: 5.0e4,
            tank_pressure_pa: 2.0e5,
        }
    }
}

/// One hydraulic cylinder (or a pair acting together, as the two boom cylinders).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CylinderParams {
    /// Bore diameter (m).
    pub bore_m: f64,
    /// Rod diameter (m).
    pub rod_m: f64,
    /// Stroke (m).
    pub stroke_m: f64,
    /// Number of identical cylinders in parallel (2 for a boom).
    #[serde(default = "one")]
    pub count: u32,
    /// Dead volume of each chamber including hoses (m^3).
    #[serde(default = "default_dead_volume")]
    pub dead_volume_m3: f64,
}

fn one() -> u32 {
    1
}

fn default_dead_volume() -> f64 {
    2.0e-3
}

impl CylinderParams {
    /// Head-side (piston) area of all cylinders together (m^2).
    pub fn head_area_m2(&self) -> f64 {
        f64::from(self.count) * std::f64::consts::FRAC_PI_4 * self.bore_m * self.bore_m
    }

    /// Rod-side (annulus) area of all cylinders together (m^2).
    pub fn rod_area_m2(&self) -> f64 {
        f64::from(self.count)
            * std::f64::consts::FRAC_PI_4
            * (self.bore_m * self.bore_m - self.rod_m * self.rod_m)
    }
}

/// The swing motor and its gear reduction, seen from the upper structure.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SwingMotorParams {
    /// Displacement referred to the swing angle (motor displacement x gear ratio / 2 pi), m^3/rad.
    pub displacement_m3_per_rad: f64,
    /// Volume of each motor port with its hoses (m^3).
    pub port_volume_m3: f64,
    /// Port (cross-over) relief pressure of the swing circuit (Pa).
    pub relief_pa: f64,
}

impl Default for SwingMotorParams {
    fn default() -> Self {
        Self {
            // 20-25 t machines swing at ~11 rpm on ~200 L/min: 3.58e-3 / 1.15 rad/s.
            displacement_m3_per_rad: 3.1e-3,
            port_volume_m3: 3.0e-3,
            relief_pa: 28.0e6,
        }
    }
}

/// An open-centre spool valve section.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValveParams {
    /// Meter-in orifice area at full spool stroke (m^2).
    pub meter_in_area_m2: f64,
    /// Meter-out orifice area at full spool stroke (m^2).
    pub meter_out_area_m2: f64,
    /// Open-centre bypass area at neutral (m^2).
    pub bypass_area_m2: f64,
    /// Spool position (fraction) at which the bypass is fully closed.
    #[serde(default = "default_bypass_close")]
    pub bypass_close: f64,
    /// Spool overlap: spool position (fraction) where the metering orifices start to open.
    #[serde(default = "default_overlap")]
    pub overlap: f64,
}

fn default_bypass_close() -> f64 {
    0.75
}

fn default_overlap() -> f64 {
    0.05
}

impl ValveParams {
    fn metering_fraction(&self, spool: f64) -> f64 {
        ((spool.abs() - self.overlap) / (1.0 - self.overlap).max(1e-6)).clamp(0.0, 1.0)
    }

    /// Meter-in area for a spool position (m^2).
    pub fn meter_in_area(&self, spool: f64) -> f64 {
        self.meter_in_area_m2 * self.metering_fraction(spool)
    }

    /// Meter-out area for a spool position (m^2).
    pub fn meter_out_area(&self, spool: f64) -> f64 {
        self.meter_out_area_m2 * self.metering_fraction(spool)
    }

    /// Open-centre bypass area for a spool position (m^2).
    pub fn bypass_area(&self, spool: f64) -> f64 {
        self.bypass_area_m2 * (1.0 - spool.abs() / self.bypass_close.max(1e-6)).clamp(0.0, 1.0)
    }
}

/// One variable-displacement pump with its main relief valve.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PumpParams {
    /// Maximum flow at full displacement and rated engine speed (m^3/s).
    pub max_flow_m3_per_s: f64,
    /// Hydraulic power available to this pump before it destrokes (W).
    pub power_w: f64,
    /// Main relief cracking pressure (Pa).
    pub main_relief_pa: f64,
    /// Pressure rise above cracking at which the relief passes the full pump flow (Pa).
    pub relief_override_pa: f64,
}

impl Default for PumpParams {
    fn default() -> Self {
        Self {
            max_flow_m3_per_s: 215.0 / 60_000.0,
            power_w: 60_000.0,
            main_relief_pa: 34.3e6,
            relief_override_pa: 1.0e6,
        }
    }
}

impl PumpParams {
    /// Delivered flow at gallery pressure `p` (flow limit and power destroke), m^3/s.
    pub fn flow(&self, p: f64, saturation: f64) -> f64 {
        let q_max = self.max_flow_m3_per_s * (1.0 - saturation).clamp(0.0, 1.0);
        q_max.min(self.power_w / p.max(1.0))
    }

    /// Main relief flow at gallery pressure `p` (m^3/s).
    pub fn relief_flow(&self, p: f64) -> f64 {
        relief_flow(
            p,
            self.main_relief_pa,
            self.relief_override_pa,
            self.max_flow_m3_per_s,
        )
    }
}

/// All hydraulic parameters of the machine.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HydraulicParams {
    /// Fluid and orifice constants.
    pub fluid: FluidParams,
    /// Pump 1 (boom, bucket) and pump 2 (stick, swing).
    pub pumps: [PumpParams; 2],
    /// Boom, stick and bucket cylinders.
    pub cylinders: [CylinderParams; 3],
    /// Swing motor.
    pub swing: SwingMotorParams,
    /// Valve sections: boom, stick, bucket, swing.
    pub valves: [ValveParams; 4],
    /// Boom command (fraction) at which the crossover from pump 2 starts to open.
    pub crossover_start: f64,
    /// Boom command (fraction) at which the crossover is fully open.
    pub crossover_full: f64,
    /// Crossover orifice area when fully open (m^2).
    pub crossover_area_m2: f64,
    /// Port (overload) relief pressure of the cylinder chambers (Pa).
    pub port_relief_pa: f64,
    /// Nominal viscous damping of each cylinder (seals, N s/m); the `viscous_friction` effect adds to it.
    pub nominal_damping_n_s_per_m: f64,
    /// Nominal viscous damping of the swing (N m s/rad).
    pub swing_damping_n_m_s_per_rad: f64,
}

impl Default for HydraulicParams {
    fn default() -> Self {
        let dead = default_dead_volume();
        let valve = |meter_in: f64, meter_out: f64| ValveParams {
            meter_in_area_m2: meter_in,
            meter_out_area_m2: meter_out,
            bypass_area_m2: 1.5e-4,
            bypass_close: default_bypass_close(),
            overlap: default_overlap(),
        };
        Self {
            fluid: FluidParams::default(),
            pumps: [PumpParams::default(); 2],
            cylinders: [
                CylinderParams {
                    bore_m: 0.120,
                    rod_m: 0.085,
                    stroke_m: 1.260,
                    count: 2,
                    dead_volume_m3: dead,
                },
                CylinderParams {
                    bore_m: 0.140,
                    rod_m: 0.100,
                    stroke_m: 1.504,
                    count: 1,
                    dead_volume_m3: dead,
                },
                CylinderParams {
                    bore_m: 0.120,
                    rod_m: 0.085,
                    stroke_m: 1.104,
                    count: 1,
                    dead_volume_m3: dead,
                },
            ],
            swing: SwingMotorParams::default(),
            valves: [
                valve(1.6e-4, 2.4e-4),
                valve(1.2e-4, 2.0e-4),
                valve(1.0e-4, 1.6e-4),
                valve(1.0e-4, 1.0e-4),
            ],
            crossover_start: 0.6,
            crossover_full: 0.9,
            crossover_area_m2: 1.2e-4,
            port_relief_pa: 37.0e6,
            nominal_damping_n_s_per_m: 5.0e4,
            swing_damping_n_m_s_per_rad: 5.0e3,
        }
    }
}

/// Pump that feeds each valve section (0-based pump index).
pub const VALVE_PUMP: [usize; N_ACTUATORS] = [0, 1, 0, 1];

/// Hydraulic effects applied inside the hydraulic model (the rest live in the plant and sensors).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HydraulicEffects {
    /// Boom-bucket flow sharing fraction.
    pub flow_sharing: f64,
    /// Fraction of the pump maximum flow lost.
    pub pump_saturation: f64,
    /// Coulomb friction of each cylinder (N).
    pub coulomb_friction_n: f64,
    /// Extra viscous friction of each cylinder (N s/m).
    pub viscous_friction_n_s_per_m: f64,
    /// Cross-piston leakage coefficient (m^3/(s Pa)).
    pub internal_leakage: f64,
}

/// External load on one actuator for the current step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActuatorLoad {
    /// Force the actuator must supply for static equilibrium (N, or N m for the swing), positive
    /// toward extension; the hydraulics sees it as `F` in Eq. 3.
    pub force: f64,
    /// Effective mass reflected to the actuator (kg, or kg m^2 for the swing).
    pub mass: f64,
    /// How the force changes with the linkage's actuator velocities, `dF/dv_j` for the boom, stick
    /// and bucket actuators (N s/m; zero for the swing). The soil's resistance on the bucket rises
    /// steeply with speed near rest; [`Hydraulics::step`] takes it implicitly, so a load held between
    /// contact updates cannot drive the actuators into a limit cycle.
    pub damping: [f64; 3],
    /// When true the actuator is blocked by a rigid obstacle in the extension direction.
    pub blocked_extend: bool,
    /// When true the actuator is blocked by a rigid obstacle in the retraction direction.
    pub blocked_retract: bool,
}

/// One step's valve openings: the meter-in areas and Eq. 1's orifices (the areas are fixed within
/// a step).
#[derive(Debug, Clone, Copy)]
struct StepValves {
    /// Meter-in area per actuator (m^2), after the flow sharing.
    meter_in: [f64; N_ACTUATORS],
    meter_in_orifice: [Orifice; N_ACTUATORS],
    meter_out_orifice: [Orifice; N_ACTUATORS],
    /// The series bypass of each pump's valves.
    bypass_orifice: [Orifice; 2],
    /// The boom crossover from pump 2 (m^2; zero when closed).
    crossover_area: f64,
    crossover_orifice: Orifice,
}

/// Inlet-chamber pressure seen by a meter-in orifice (the check valve blocks backflow).
fn inlet_pa(s: &ActuatorState, spool: f64) -> f64 {
    if spool >= 0.0 { s.head_pa } else { s.rod_pa }
}

/// One actuator's implicit mechanics (Eq. 3 with the oil stiffness of Eq. 2) before the loads'
/// velocity coupling is solved: `inertia v' = numerator`.
#[derive(Debug, Clone, Copy, Default)]
struct Pending {
    inertia: f64,
    numerator: f64,
    coulomb: f64,
    head0: f64,
    head_gain: f64,
    rod0: f64,
    rod_gain: f64,
}

/// State of one actuator.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActuatorState {
    /// Extension from fully retracted (m), or swing angle (rad).
    pub position: f64,
    /// Rate of `position` (m/s or rad/s).
    pub velocity: f64,
    /// Head (or swing port A) pressure (Pa).
    pub head_pa: f64,
    /// Rod (or swing port B) pressure (Pa).
    pub rod_pa: f64,
}

/// The hydraulic system state.
#[derive(Debug, Clone, PartialEq)]
pub struct Hydraulics {
    params: HydraulicParams,
    /// Derived from `params` once (they never change after construction).
    orifice_constants: OrificeConstants,
    /// Per valve, the reciprocals of the spans in its area laws (the same for every step).
    valve_spans: [ValveSpans; N_ACTUATORS],
    /// `1 / (crossover_full - crossover_start)`.
    inverse_crossover_span: f64,
    /// The valves that do not change with the spools, built once: each gallery's main relief, each
    /// actuator's port relief and the anti-cavitation make-up orifice.
    main_reliefs: [Relief; 2],
    port_reliefs: [Relief; N_ACTUATORS],
    makeup_orifice: Orifice,
    chambers: [Chambers; N_ACTUATORS],
    /// Chamber `[head, rod]` and gallery pressures one step back: the solvers start from the linear
    /// extrapolation of the last two steps, which saves Newton iterations while the machine moves.
    previous_chamber_pa: [[f64; 2]; N_ACTUATORS],
    previous_pump_pa: [f64; 2],
    /// Actuators: boom, stick, bucket, swing.
    pub actuators: [ActuatorState; N_ACTUATORS],
    /// Gallery (pump outlet) pressures (Pa).
    pub pump_pa: [f64; 2],
    /// Pump flows delivered in the last step (m^3/s).
    pub pump_flow_m3_per_s: [f64; 2],
    /// Whether the chamber solves may end on a Newton step they have not evaluated (within
    /// [`ACCEPT_UNEVALUATED_PA`] of the root); off only in the test that compares both.
    accept_unevaluated: bool,
    /// Whether a chamber with one open metering orifice takes Eq. 2's root in closed form
    /// ([`one_orifice_chamber_root`]) instead of the Newton solve; off only in the test that compares
    /// both.
    closed_form: bool,
}

/// The divisions of [`ValveParams`]'s area laws as products: `metering_fraction` divides by
/// `1 - overlap`, `bypass_area` by `bypass_close`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ValveSpans {
    inverse_metering: f64,
    inverse_bypass_close: f64,
}

/// Geometry of one actuator in the chamber model.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Chambers {
    area_head: f64,
    area_rod: f64,
    stroke: f64,
    dead: f64,
    rotary: bool,
}

impl Chambers {
    fn head_volume(&self, x: f64) -> f64 {
        if self.rotary {
            self.dead
        } else {
            self.dead + self.area_head * x.clamp(0.0, self.stroke)
        }
    }

    fn rod_volume(&self, x: f64) -> f64 {
        if self.rotary {
            self.dead
        } else {
            self.dead + self.area_rod * (self.stroke - x).clamp(0.0, self.stroke)
        }
    }
}

/// Signed orifice flow from a higher pressure `p_from` to `p_to` (Eq. 1), with a laminar region.
pub fn orifice_flow(fluid: &FluidParams, area_m2: f64, p_from: f64, p_to: f64) -> f64 {
    orifice(fluid, area_m2, p_from - p_to).0
}

/// Orifice flow and its derivative with respect to the pressure drop.
fn orifice(fluid: &FluidParams, area: f64, dp: f64) -> (f64, f64) {
    Orifice::new(&OrificeConstants::of(fluid), area).flow(dp)
}

/// The parts of Eq. 1 that depend only on the fluid, computed once per system.
#[derive(Debug, Clone, Copy, PartialEq)]
struct OrificeConstants {
    discharge_coefficient: f64,
    /// `sqrt(2 / rho)`.
    root_two_over_rho: f64,
    laminar_dp_pa: f64,
    /// `1 / sqrt(laminar_dp_pa)`.
    inverse_root_laminar_dp: f64,
}

impl OrificeConstants {
    fn of(fluid: &FluidParams) -> Self {
        Self {
            discharge_coefficient: fluid.discharge_coefficient,
            root_two_over_rho: (2.0 / fluid.density_kg_per_m3).sqrt(),
            laminar_dp_pa: fluid.laminar_dp_pa,
            inverse_root_laminar_dp: fluid.laminar_dp_pa.sqrt().recip(),
        }
    }
}

/// One orifice of fixed area: Eq. 1 with its constant folded in, evaluated many times per step.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Orifice {
    /// `Cd A sqrt(2 / rho)`; zero when closed.
    k: f64,
    /// Slope of the laminar region, `k / sqrt(laminar dp)`.
    laminar_slope: f64,
    laminar_dp_pa: f64,
}

impl Orifice {
    fn new(c: &OrificeConstants, area: f64) -> Self {
        if area <= 0.0 {
            return Self {
                k: 0.0,
                laminar_slope: 0.0,
                laminar_dp_pa: c.laminar_dp_pa,
            };
        }
        // Eq. 1: Q = Cd A sqrt(2 dP / rho); the thesis folds 2/rho into the constant.
        let k = c.discharge_coefficient * area * c.root_two_over_rho;
        Self {
            k,
            laminar_slope: k * c.inverse_root_laminar_dp,
            laminar_dp_pa: c.laminar_dp_pa,
        }
    }

    /// Flow, its derivative and `|d^2 Q / d(dp)^2| = k / (4 |dp|^1.5)` (zero in the laminar region).
    /// The flow and derivative are those of [`Self::flow`], bit for bit.
    #[inline]
    fn flow_with_curvature(&self, dp: f64) -> (f64, f64, f64) {
        if self.k == 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let mag = dp.abs();
        if mag < self.laminar_dp_pa {
            (self.laminar_slope * dp, self.laminar_slope, 0.0)
        } else {
            let root = mag.sqrt();
            let half_inverse = 0.5 / mag;
            let q = self.k * root;
            let slope = q * half_inverse;
            (q * dp.signum(), slope, slope * half_inverse)
        }
    }

    /// Flow for the pressure drop `dp` and its derivative, with a laminar region for solver slope.
    #[inline]
    fn flow(&self, dp: f64) -> (f64, f64) {
        if self.k == 0.0 {
            return (0.0, 0.0);
        }
        let mag = dp.abs();
        if mag < self.laminar_dp_pa {
            (self.laminar_slope * dp, self.laminar_slope)
        } else {
            // dQ/d(dp) = k / (2 sqrt(dp)) = Q / (2 dp): the division by dp runs alongside the square
            // root instead of after it (the solves are bound by this chain's latency).
            let root = mag.sqrt();
            let half_inverse = 0.5 / mag;
            let q = self.k * root;
            (q * dp.signum(), q * half_inverse)
        }
    }
}

/// A relief valve: no flow up to `crack`, linear above it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Relief {
    crack: f64,
    slope: f64,
}

impl Relief {
    fn new(crack: f64, override_pa: f64, rated_flow: f64) -> Self {
        Self {
            crack,
            slope: rated_flow / override_pa.max(1.0),
        }
    }

    #[inline]
    fn flow(&self, p: f64) -> (f64, f64) {
        if p <= self.crack {
            (0.0, 0.0)
        } else {
            (self.slope * (p - self.crack), self.slope)
        }
    }
}

/// Relief valve flow (linear above cracking).
fn relief_flow(p: f64, crack: f64, override_pa: f64, rated_flow: f64) -> f64 {
    Relief::new(crack, override_pa, rated_flow).flow(p).0
}

/// Solves `f(p) = 0` for a function decreasing in `p`, by Newton steps kept inside a bracket
/// that bisection shrinks; `f` returns the value and its derivative.
fn solve_decreasing(f: impl FnMut(f64) -> (f64, f64), guess: f64, lo: f64, hi: f64) -> f64 {
    solve_decreasing_accepting(f, |_, _, _| None, guess, lo, hi).0
}

/// Bound (Pa) on the error of a Newton step accepted without evaluating the residual at it. The
/// solvers' own tolerance is 10 Pa; the pressure sensors resolve 5 kPa.
const ACCEPT_UNEVALUATED_PA: f64 = 1.0;

/// [`solve_decreasing`] that may also end on a Newton step it has not evaluated: `accept(p, newton,
/// slope)` (asked only for a step of 10 Pa or more that stays inside the bracket) returns the root
/// from that step when the step from the last evaluated `p` is known to land within
/// [`ACCEPT_UNEVALUATED_PA`] of it. Returns the root and whether it came from such a step.
fn solve_decreasing_accepting(
    mut f: impl FnMut(f64) -> (f64, f64),
    mut accept: impl FnMut(f64, f64, f64) -> Option<f64>,
    guess: f64,
    lo: f64,
    hi: f64,
) -> (f64, bool) {
    let (mut lo, mut hi) = (lo, hi);
    // Whether the residual has been evaluated at each end of the bracket.
    let (mut lo_seen, mut hi_seen) = (false, false);
    let mut p = guess.clamp(lo, hi);
    for _ in 0..40 {
        let (value, slope) = f(p);
        if value.abs() < 1e-12 {
            return (p, false);
        }
        if value > 0.0 {
            (lo, lo_seen) = (p, true);
        } else {
            (hi, hi_seen) = (p, true);
        }
        let newton = if slope < 0.0 {
            p - value / slope
        } else {
            f64::NAN
        };
        // Converged when the Newton step is below 10 Pa (far below the 5 kPa sensor resolution).
        // At a root found to rounding the step may end a hair outside the bracket: clamp it.
        if (newton - p).abs() < 10.0 {
            return (newton.clamp(lo, hi), false);
        }
        let inside = newton > lo && newton < hi;
        if inside && let Some(root) = accept(p, newton, slope) {
            return (root.clamp(lo, hi), true);
        }
        let next = if inside {
            newton
        } else if newton <= lo && !lo_seen {
            // The root may lie at the lower bound (a chamber emptied to zero): look there first.
            lo
        } else if newton >= hi && !hi_seen {
            hi
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo < 10.0 {
            return (next, false);
        }
        p = next;
    }
    (p, false)
}

/// How oil can enter or leave a chamber this step, for [`chamber_root_without_solver`].
#[derive(Debug, Clone, Copy)]
enum ChamberPath<'a> {
    /// No open path (spool centred or inside its overlap, no leakage).
    DeadEnd,
    /// Fed from the gallery at the given pressure through this meter-in orifice only.
    In(&'a Orifice, f64),
    /// Drained to tank through this meter-out orifice only (and the make-up orifice, second, below
    /// tank pressure).
    Out(&'a Orifice, &'a Orifice),
    /// Crossover or leakage: left to the Newton solve.
    Solve,
}

/// Eq. 2's backward-Euler root and the piston's oil stiffness `dP'/d(dV/dt) = -c / (1 - c dQ/dP')`
/// for a chamber that needs no solver, when the root lies between tank pressure and the port relief's
/// cracking pressure `crack_pa` (make-up and relief shut there); `None` otherwise.
/// - A dead-ended chamber exchanges no oil, so Eq. 2 is linear and its root `P' = P - c dV/dt` is
///   exact, with no inflow slope (the solver landed on it to rounding after one evaluation).
/// - With `closed_form`, a chamber with one open metering orifice takes
///   [`one_orifice_chamber_root`]; a drained chamber drawn below tank pressure takes it with the
///   meter-out and make-up orifices as one (both from tank; the root between zero and tank).
#[inline(always)]
fn chamber_root_without_solver(
    path: ChamberPath<'_>,
    p_old: f64,
    c: f64,
    dvdt: f64,
    tank_pa: f64,
    crack_pa: f64,
    closed_form: bool,
) -> Option<(f64, f64)> {
    let base = p_old + c * (0.0 - dvdt);
    let (pn, slope) = match path {
        ChamberPath::DeadEnd => (base, 0.0),
        ChamberPath::In(orifice, gallery) if closed_form => {
            one_orifice_chamber_root(orifice, true, gallery, base, c)?
        }
        ChamberPath::Out(orifice, makeup) if closed_form => {
            match one_orifice_chamber_root(orifice, false, tank_pa, base, c) {
                Some(root) => root,
                None => {
                    // Drawn below tank pressure (`base < tank`): oil flows back in from tank
                    // through the meter-out orifice and the make-up orifice alike, two orifices from
                    // one pressure with one laminar limit, i.e. one orifice of their summed
                    // constants; the root lies between zero (the solver's bracket) and tank.
                    debug_assert_eq!(orifice.laminar_dp_pa, makeup.laminar_dp_pa);
                    let both = Orifice {
                        k: orifice.k + makeup.k,
                        laminar_slope: orifice.laminar_slope + makeup.laminar_slope,
                        laminar_dp_pa: orifice.laminar_dp_pa,
                    };
                    let (pn, slope) = one_orifice_chamber_root(&both, true, tank_pa, base, c)?;
                    return (pn >= 0.0 && pn <= tank_pa)
                        .then(|| (pn, c / (1.0 - c * slope).max(1.0)));
                }
            }
        }
        _ => return None,
    };
    (pn >= tank_pa && pn <= crack_pa).then(|| (pn, c / (1.0 - c * slope).max(1.0)))
}

/// Eq. 2's backward-Euler root `P' = base + c Q(P')` (`base = P - c dV/dt`) for a chamber whose only
/// open path is `orifice` (Eq. 1 with its laminar region) from the fixed pressure `fixed_pa` into it
/// (`supplied`: a gallery through a meter-in orifice and its check valve) or from it to `fixed_pa`
/// (tank, through a meter-out orifice). With the drop `dp = u^2` across the orifice (`g - P'` or
/// `P' - tank`) both cases read `dp + c Q(dp) = C` with `C = g - base` or `base - tank`, increasing in
/// `dp`: in the laminar region `dp = C / (1 + c k_l)`, else `u^2 + c k u - C = 0`, whose positive root
/// `u = 2 C / (c k + sqrt((c k)^2 + 4 C))` is taken in the form without cancellation. Returns the
/// chamber pressure and the inflow slope `dQ/dP'` there. When `C <= 0` a supplied chamber's check
/// valve shuts and the root is `base` (no flow, slope zero); a drained chamber at `C = 0` sits at tank
/// pressure (no flow, the laminar slope), below that it would fall below tank, where the make-up
/// opens: `None`. The caller checks that the root lies where the make-up and the
/// port relief are shut.
#[inline]
fn one_orifice_chamber_root(
    orifice: &Orifice,
    supplied: bool,
    fixed_pa: f64,
    base: f64,
    c: f64,
) -> Option<(f64, f64)> {
    let drive = if supplied {
        fixed_pa - base
    } else {
        base - fixed_pa
    };
    if orifice.k == 0.0 || drive.is_nan() {
        return None;
    }
    if drive <= 0.0 {
        // A supplied chamber at or above its gallery: the check valve holds, no oil flows, and the
        // root is `base` itself (a stall against the main relief). A drained chamber below tank
        // would draw through the make-up: left to the solver.
        return if supplied {
            Some((base, 0.0))
        } else if drive == 0.0 {
            // Exactly at tank pressure: no flow, the meter-out's laminar slope (two-way).
            Some((fixed_pa, -orifice.laminar_slope))
        } else {
            None
        };
    }
    let laminar_dp = drive / (1.0 + c * orifice.laminar_slope);
    let (dp, slope) = if laminar_dp < orifice.laminar_dp_pa {
        (laminar_dp, -orifice.laminar_slope)
    } else {
        let b = c * orifice.k;
        let u = 2.0 * drive / (b + (b * b + 4.0 * drive).sqrt());
        (u * u, -0.5 * orifice.k / u)
    };
    let pn = if supplied {
        fixed_pa - dp
    } else {
        fixed_pa + dp
    };
    Some((pn, slope))
}

/// Whether an orifice term of a chamber balance is in the same regime (closed, laminar, turbulent;
/// Eq. 1 with its laminar region) at the pressure drops `dp0` and `dp1`, and, when turbulent, `dp1` is
/// within half of `dp0` of it, where `|Q''| ~ |dp|^-1.5` has grown at most 2^1.5-fold. `one_way`: a
/// check valve closes it for `dp <= 0` (meter-in, crossover, make-up).
#[inline]
fn same_orifice_regime(dp0: f64, dp1: f64, laminar_dp: f64, one_way: bool) -> bool {
    if one_way && dp0 <= 0.0 {
        return dp1 <= 0.0;
    }
    let (m0, m1) = (dp0.abs(), dp1.abs());
    if m0 < laminar_dp {
        m1 < laminar_dp && (!one_way || dp1 > 0.0)
    } else {
        m1 >= laminar_dp && (dp0 > 0.0) == (dp1 > 0.0) && m1 >= 0.5 * m0
    }
}

impl Hydraulics {
    /// A system at rest: pressures at tank, actuators at the given positions.
    pub fn new(params: HydraulicParams, positions: [f64; N_ACTUATORS]) -> Self {
        let tank = params.fluid.tank_pressure_pa;
        let mut actuators = [ActuatorState::default(); N_ACTUATORS];
        for (state, position) in actuators.iter_mut().zip(positions) {
            *state = ActuatorState {
                position,
                velocity: 0.0,
                head_pa: tank,
                rod_pa: tank,
            };
        }
        Self {
            params,
            orifice_constants: OrificeConstants::of(&params.fluid),
            valve_spans: params.valves.map(|v| ValveSpans {
                inverse_metering: (1.0 - v.overlap).max(1e-6).recip(),
                inverse_bypass_close: v.bypass_close.max(1e-6).recip(),
            }),
            inverse_crossover_span: (params.crossover_full - params.crossover_start)
                .max(1e-6)
                .recip(),
            main_reliefs: params.pumps.map(|pp| {
                Relief::new(
                    pp.main_relief_pa,
                    pp.relief_override_pa,
                    pp.max_flow_m3_per_s,
                )
            }),
            port_reliefs: [0, 1, 2, 3].map(|i| {
                let relief_pa = if i == SWING {
                    params.swing.relief_pa
                } else {
                    params.port_relief_pa
                };
                Relief::new(
                    relief_pa,
                    1.0e6,
                    params.pumps[VALVE_PUMP[i]].max_flow_m3_per_s,
                )
            }),
            makeup_orifice: Orifice::new(&OrificeConstants::of(&params.fluid), 1.0e-4),
            chambers: [0, 1, 2, 3].map(|i| Self::chambers_of(&params, i)),
            previous_chamber_pa: [[tank; 2]; N_ACTUATORS],
            previous_pump_pa: [tank; 2],
            actuators,
            pump_pa: [tank; 2],
            pump_flow_m3_per_s: [0.0; 2],
            accept_unevaluated: true,
            closed_form: true,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &HydraulicParams {
        &self.params
    }

    fn chambers(&self, i: usize) -> Chambers {
        self.chambers[i]
    }

    fn chambers_of(params: &HydraulicParams, i: usize) -> Chambers {
        if i == SWING {
            let d = params.swing.displacement_m3_per_rad;
            Chambers {
                area_head: d,
                area_rod: d,
                stroke: f64::INFINITY,
                dead: params.swing.port_volume_m3,
                rotary: true,
            }
        } else {
            let c = &params.cylinders[i];
            Chambers {
                area_head: c.head_area_m2(),
                area_rod: c.rod_area_m2(),
                stroke: c.stroke_m,
                dead: c.dead_volume_m3,
                rotary: false,
            }
        }
    }

    /// Piston speed that the given flow into the head side produces (m/s), for tests and docs.
    pub fn head_area_m2(&self, i: usize) -> f64 {
        self.chambers(i).area_head
    }

    /// Rod-side area of actuator `i` (m^2), or the swing displacement.
    pub fn rod_area_m2(&self, i: usize) -> f64 {
        self.chambers(i).area_rod
    }

    /// Stroke of actuator `i` (m); infinite for the swing.
    pub fn stroke_m(&self, i: usize) -> f64 {
        self.chambers(i).stroke
    }

    /// Force (or torque) the actuator produces from its chamber pressures (Eq. A20).
    pub fn actuator_force(&self, i: usize) -> f64 {
        let ch = self.chambers(i);
        let s = &self.actuators[i];
        s.head_pa * ch.area_head - s.rod_pa * ch.area_rod
    }

    /// Advances the hydraulics by `dt_s` with the spool positions (after delay and lag, in [-1, 1]),
    /// the external loads and the hydraulic effects: the valve openings, then (1) the gallery
    /// pressures, (2) the chamber pressures and (3) each actuator's implicit mechanics, the loads'
    /// velocity coupling, and the motion.
    pub fn step(
        &mut self,
        dt_s: f64,
        spools: [f64; N_ACTUATORS],
        loads: &[ActuatorLoad; N_ACTUATORS],
        effects: &HydraulicEffects,
    ) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let spools = spools.map(|s| {
            if s.is_finite() {
                s.clamp(-1.0, 1.0)
            } else {
                0.0
            }
        });
        let valves = self.valve_openings(&spools, effects);
        self.solve_galleries(&valves, &spools, effects);
        // 2 and 3. Chamber pressures (implicit Euler of Eq. 2) and mechanics (Eq. 3).
        let pending: [Pending; N_ACTUATORS] = std::array::from_fn(|i| {
            self.implicit_mechanics(i, &valves, &spools, loads, effects, dt_s)
        });
        let v_solved = self.coupled_velocities(&pending, loads, dt_s);
        self.integrate_motion(&pending, &v_solved, loads, dt_s);
    }

    /// This step's valve areas and their orifices, from the clamped spools.
    fn valve_openings(
        &self,
        spools: &[f64; N_ACTUATORS],
        effects: &HydraulicEffects,
    ) -> StepValves {
        let p = &self.params;
        let oc = self.orifice_constants;
        // Valve areas ([`ValveParams::meter_in_area`], `meter_out_area`, `bypass_area`, with the
        // divisions by constant spans done once in `Hydraulics::new`).
        let mut meter_in = [0.0; N_ACTUATORS];
        let mut meter_out = [0.0; N_ACTUATORS];
        let mut valve_bypass = [0.0; N_ACTUATORS];
        for i in 0..N_ACTUATORS {
            let (valve, spans, spool) = (&p.valves[i], &self.valve_spans[i], spools[i].abs());
            let fraction = ((spool - valve.overlap) * spans.inverse_metering).clamp(0.0, 1.0);
            meter_in[i] = valve.meter_in_area_m2 * fraction;
            meter_out[i] = valve.meter_out_area_m2 * fraction;
            valve_bypass[i] =
                valve.bypass_area_m2 * (1.0 - spool * spans.inverse_bypass_close).clamp(0.0, 1.0);
        }
        // Hidden effect: the bucket spool steals boom meter-in flow on the shared pump.
        meter_in[BOOM] *= (1.0 - effects.flow_sharing * spools[BUCKET].abs()).clamp(0.0, 1.0);
        let boom_cmd = spools[BOOM].abs();
        let crossover_fraction =
            ((boom_cmd - p.crossover_start) * self.inverse_crossover_span).clamp(0.0, 1.0);
        let crossover_area = p.crossover_area_m2 * crossover_fraction;
        // Series bypass of the valves on each pump: 1/A^2 = sum 1/A_i^2.
        let mut bypass = [0.0; 2];
        for (pump, bypass_area) in bypass.iter_mut().enumerate() {
            let mut inv_sq = 0.0;
            let mut closed = false;
            for i in 0..N_ACTUATORS {
                if VALVE_PUMP[i] == pump {
                    let a = valve_bypass[i];
                    if a <= 0.0 {
                        closed = true;
                    } else {
                        inv_sq += 1.0 / (a * a);
                    }
                }
            }
            // The crossover spool sits in pump 2's centre passage and closes it as it opens.
            if pump == 1 && crossover_area > 0.0 {
                let a = p.valves[BOOM].bypass_area_m2 * (1.0 - crossover_fraction);
                if a <= 0.0 {
                    closed = true;
                } else {
                    inv_sq += 1.0 / (a * a);
                }
            }
            *bypass_area = if closed || inv_sq <= 0.0 {
                0.0
            } else {
                inv_sq.sqrt().recip()
            };
        }

        // Eq. 1 constants of this step's orifices (the areas are fixed within a step).
        let meter_in_orifice = meter_in.map(|a| Orifice::new(&oc, a));
        let meter_out_orifice = meter_out.map(|a| Orifice::new(&oc, a));
        let bypass_orifice = bypass.map(|a| Orifice::new(&oc, a));
        let crossover_orifice = Orifice::new(&oc, crossover_area);
        StepValves {
            meter_in,
            meter_in_orifice,
            meter_out_orifice,
            bypass_orifice,
            crossover_area,
            crossover_orifice,
        }
    }

    /// Stage 1: the gallery pressures and pump flows of this step.
    fn solve_galleries(
        &mut self,
        valves: &StepValves,
        spools: &[f64; N_ACTUATORS],
        effects: &HydraulicEffects,
    ) {
        let p = &self.params;
        let tank = p.fluid.tank_pressure_pa;
        let StepValves {
            meter_in,
            meter_in_orifice,
            bypass_orifice,
            crossover_area,
            crossover_orifice,
            ..
        } = *valves;
        // 1. Gallery pressures from the flow balance (monotone decreasing in p).
        let mut new_pump = self.pump_pa;
        let mut pump_flow = [0.0; 2];
        for pump in 0..2 {
            let pp = p.pumps[pump];
            let acts = &self.actuators;
            let main_relief = self.main_reliefs[pump];
            // `PumpParams::flow` and its slope with one division: `min(Q_max, W / p)`.
            let q_max = pp.max_flow_m3_per_s * (1.0 - effects.pump_saturation).clamp(0.0, 1.0);
            let balance = |pg: f64| {
                let inverse_p = pg.max(1.0).recip();
                let destroked = pp.power_w * inverse_p;
                let (mut value, mut slope) = if destroked < q_max {
                    (destroked, -destroked * inverse_p)
                } else {
                    (q_max, 0.0)
                };
                let (qb, db) = bypass_orifice[pump].flow(pg - tank);
                value -= qb;
                slope -= db;
                for i in 0..N_ACTUATORS {
                    if VALVE_PUMP[i] == pump && meter_in[i] > 0.0 {
                        let dp = pg - inlet_pa(&acts[i], spools[i]);
                        if dp > 0.0 {
                            let (q, d) = meter_in_orifice[i].flow(dp);
                            value -= q;
                            slope -= d;
                        }
                    }
                }
                if pump == 1 && crossover_area > 0.0 {
                    let dp = pg - inlet_pa(&acts[BOOM], spools[BOOM]);
                    if dp > 0.0 {
                        let (q, d) = crossover_orifice.flow(dp);
                        value -= q;
                        slope -= d;
                    }
                }
                let (qr, dr) = main_relief.flow(pg);
                (value - qr, slope - dr)
            };
            let hi = pp.main_relief_pa + 20.0 * pp.relief_override_pa;
            let guess = 2.0 * self.pump_pa[pump] - self.previous_pump_pa[pump];
            new_pump[pump] = solve_decreasing(balance, guess, tank, hi);
            pump_flow[pump] = pp.flow(new_pump[pump], effects.pump_saturation);
        }
        self.previous_pump_pa = self.pump_pa;
        self.pump_pa = new_pump;
        self.pump_flow_m3_per_s = pump_flow;
    }

    /// Stages 2 and 3 for actuator `i`: its chamber pressures (implicit Euler of Eq. 2) and its
    /// mechanics (Eq. 3) with the oil stiffness, before the loads' velocity coupling.
    fn implicit_mechanics(
        &self,
        i: usize,
        valves: &StepValves,
        spools: &[f64; N_ACTUATORS],
        loads: &[ActuatorLoad; N_ACTUATORS],
        effects: &HydraulicEffects,
        dt_s: f64,
    ) -> Pending {
        let p = &self.params;
        let oc = self.orifice_constants;
        let tank = p.fluid.tank_pressure_pa;
        let StepValves {
            meter_in_orifice,
            meter_out_orifice,
            crossover_area,
            crossover_orifice,
            ..
        } = *valves;
        let makeup_orifice = self.makeup_orifice;
        let ch = self.chambers(i);
        let spool = spools[i];
        let state = self.actuators[i];
        let gallery = self.pump_pa[VALVE_PUMP[i]];
        let cross = if i == BOOM && crossover_area > 0.0 {
            self.pump_pa[1]
        } else {
            f64::NAN
        };
        let relief_pa = if i == SWING {
            p.swing.relief_pa
        } else {
            p.port_relief_pa
        };
        let port_relief = self.port_reliefs[i];
        let (meter_in_i, meter_out_i) = (meter_in_orifice[i], meter_out_orifice[i]);
        let leak = if i == SWING {
            0.0
        } else {
            effects.internal_leakage
        };
        let laminar_dp = oc.laminar_dp_pa;
        let has_cross = cross.is_finite();
        // Net flow into a chamber at pressure `pc` (value, d/dpc), excluding the piston motion,
        // and d^2/dpc^2 (signed, and the sum of its terms' magnitudes).
        let chamber_inflow = |pc: f64, supplied: bool, drained: bool, other: f64| {
            let mut q = 0.0;
            let mut d = 0.0;
            let (mut dd, mut dd_abs) = (0.0, 0.0);
            if supplied {
                // d^2/dpc^2 of Q(gallery - pc) is Q''(dp) = -|Q''| for dp > 0.
                let (qi, di, ci) = meter_in_i.flow_with_curvature(gallery - pc);
                if qi > 0.0 {
                    q += qi;
                    d -= di;
                    dd -= ci;
                    dd_abs += ci;
                }
                if has_cross {
                    let (qx, dx, cx) = crossover_orifice.flow_with_curvature(cross - pc);
                    if qx > 0.0 {
                        q += qx;
                        d -= dx;
                        dd -= cx;
                        dd_abs += cx;
                    }
                }
            }
            if drained {
                // d^2/dpc^2 of -Q(pc - tank) is -Q''(dp) = sign(dp) |Q''|.
                let dp = pc - tank;
                let (qo, dout, co) = meter_out_i.flow_with_curvature(dp);
                q -= qo;
                d -= dout;
                dd += co.copysign(dp);
                dd_abs += co;
            }
            // Port relief to tank and anti-cavitation make-up from tank.
            let (qr, dr) = port_relief.flow(pc);
            q -= qr;
            d -= dr;
            if pc < tank {
                let (qm, dm, cm) = makeup_orifice.flow_with_curvature(tank - pc);
                q += qm;
                d -= dm;
                dd -= cm;
                dd_abs += cm;
            }
            // Cross-piston leakage (hidden effect), from this chamber to the other.
            q -= leak * (pc - other);
            d -= leak;
            (q, d, dd, dd_abs)
        };
        // Whether every term of `chamber_inflow` is in the same regime at `p0` and `p1` (no kink
        // between them; turbulent orifices within half their drop).
        let same_regime = |p0: f64, p1: f64, supplied: bool, drained: bool| {
            (!supplied
                || meter_in_i.k == 0.0
                || same_orifice_regime(gallery - p0, gallery - p1, laminar_dp, true))
                && (!supplied
                    || !has_cross
                    || crossover_orifice.k == 0.0
                    || same_orifice_regime(cross - p0, cross - p1, laminar_dp, true))
                && (!drained
                    || meter_out_i.k == 0.0
                    || same_orifice_regime(p0 - tank, p1 - tank, laminar_dp, false))
                && (p0 <= port_relief.crack) == (p1 <= port_relief.crack)
                && same_orifice_regime(tank - p0, tank - p1, laminar_dp, true)
        };
        let head_in = spool > 0.0;
        let head_out = spool < 0.0;
        let v = state.velocity;
        // Eq. 2 in backward Euler: P' = P + dt beta / V (Q_in(P') - dV/dt).
        let previous = self.previous_chamber_pa[i];
        let solve_chamber =
            |p_old: f64, p_before: f64, c: f64, dvdt: f64, supplied: bool, drained: bool, other| {
                // The inflow slope at the last pressure the solver evaluated: within its 10 Pa tolerance
                // of the root, so it stands in for the slope at the root without another evaluation.
                // With it, the second derivative there (signed, and its terms' magnitudes).
                let last = std::cell::Cell::new((0.0, 0.0, 0.0, 0.0));
                let residual = |pn: f64| {
                    let (q, dq, ddq, ddq_abs) = chamber_inflow(pn, supplied, drained, other);
                    last.set((dq, ddq, ddq_abs, pn));
                    (p_old + c * (q - dvdt) - pn, c * dq - 1.0)
                };
                // R(P') = P + c (Q(P') - dV/dt) - P' has R' = c Q' - 1 <= -1 and R'' = c Q''. A
                // Newton step s from p0 that crosses no kink lands at R(p0 + s) = R''(xi) s^2 / 2
                // (Taylor), within |R''| s^2 / 2 of the root, with |Q''| at most 2^1.5 times its
                // value at p0 (same_orifice_regime). The known part of it, R''(p0) s^2 / 2, is taken
                // off (one more Newton step, with R'(p0)): the error left is of third order in s, and
                // no bias accumulates in a slowly filling dead-end chamber.
                let accept_unevaluated = self.accept_unevaluated;
                let accept = |p0: f64, p1: f64, slope: f64| {
                    let s = p1 - p0;
                    let (_, dd, dd_abs, _) = last.get();
                    (accept_unevaluated
                        && 0.5 * 2.83 * c * dd_abs * s * s <= ACCEPT_UNEVALUATED_PA
                        && same_regime(p0, p1, supplied, drained))
                    .then(|| p1 - 0.5 * c * dd * s * s / slope)
                };
                let guess = 2.0 * p_old - p_before;
                let (pn, accepted) =
                    solve_decreasing_accepting(residual, accept, guess, 0.0, relief_pa + 50.0e6);
                let (mut d, dd, _, at) = last.get();
                if accepted {
                    // The step was not evaluated: carry the slope along it (first order; smooth).
                    d += dd * (pn - at);
                }
                // Stiffness of the chamber seen by the piston: dP'/d(dV/dt) = -c / (1 - c dQ/dP).
                (pn, c / (1.0 - c * d).max(1.0))
            };
        // The chambers that need no solver (`chamber_root_without_solver`): the path of oil
        // into or out of each, and Eq. 2's factor `c = beta dt / V`.
        let path = |supplied: bool, drained: bool| {
            if leak != 0.0 || (supplied && has_cross) {
                ChamberPath::Solve
            } else if supplied && meter_in_i.k > 0.0 {
                ChamberPath::In(&meter_in_i, gallery)
            } else if drained && meter_out_i.k > 0.0 {
                ChamberPath::Out(&meter_out_i, &makeup_orifice)
            } else {
                ChamberPath::DeadEnd
            }
        };
        let (head_dvdt, rod_dvdt) = (ch.area_head * v, -ch.area_rod * v);
        let c_head = p.fluid.bulk_modulus_pa * dt_s / ch.head_volume(state.position).max(1e-6);
        let c_rod = p.fluid.bulk_modulus_pa * dt_s / ch.rod_volume(state.position).max(1e-6);
        let (head0, head_gain) = chamber_root_without_solver(
            path(head_in, head_out),
            state.head_pa,
            c_head,
            head_dvdt,
            tank,
            port_relief.crack,
            self.closed_form,
        )
        .unwrap_or_else(|| {
            solve_chamber(
                state.head_pa,
                previous[0],
                c_head,
                head_dvdt,
                head_in,
                head_out,
                state.rod_pa,
            )
        });
        let (rod0, rod_gain) = chamber_root_without_solver(
            path(head_out, head_in),
            state.rod_pa,
            c_rod,
            rod_dvdt,
            tank,
            port_relief.crack,
            self.closed_form,
        )
        .unwrap_or_else(|| {
            solve_chamber(
                state.rod_pa,
                previous[1],
                c_rod,
                rod_dvdt,
                head_out,
                head_in,
                state.head_pa,
            )
        });

        // Eq. 3: M x'' = P1 A1 - P2 A2 - F. The piston velocity enters Eq. 2 through dV/dt, so the
        // new pressures are linear in the new velocity v':
        //   P_head' = head0 - g_h A_h (v' - v),  P_rod' = rod0 + g_r A_r (v' - v),
        // and Eq. 3 is solved for v' with that oil stiffness (implicit in v', hence no
        // oscillator instability however stiff the oil column or coarse the step).
        let load = loads[i];
        let mass = load.mass.max(1.0);
        let (damping, coulomb) = if i == SWING {
            (p.swing_damping_n_m_s_per_rad, 0.0)
        } else {
            (
                p.nominal_damping_n_s_per_m + effects.viscous_friction_n_s_per_m,
                effects.coulomb_friction_n,
            )
        };
        let stiffness =
            head_gain * ch.area_head * ch.area_head + rod_gain * ch.area_rod * ch.area_rod;
        let drive0 = head0 * ch.area_head - rod0 * ch.area_rod - load.force;
        let inertia = mass + dt_s * (damping + stiffness);
        Pending {
            inertia,
            numerator: mass * v + dt_s * (drive0 + stiffness * v),
            coulomb,
            head0,
            head_gain,
            rod0,
            rod_gain,
        }
    }

    /// The new velocities: each actuator's `inertia v' = numerator`, solved jointly for the linkage
    /// when the loads depend on its velocities.
    fn coupled_velocities(
        &self,
        pending: &[Pending; N_ACTUATORS],
        loads: &[ActuatorLoad; N_ACTUATORS],
        dt_s: f64,
    ) -> [f64; N_ACTUATORS] {
        // The loads' velocity dependence (soil resistance, `ActuatorLoad::damping`) is implicit too:
        // F(v') = F(v) + D (v' - v) couples the linkage's three actuators,
        //   (diag(inertia) + dt D) v' = numerator + dt D v.
        let mut v_solved = [0.0; N_ACTUATORS];
        for i in 0..N_ACTUATORS {
            v_solved[i] = pending[i].numerator / pending[i].inertia;
        }
        let coupled = loads[..SWING]
            .iter()
            .any(|l| l.damping.iter().any(|&d| d != 0.0 && d.is_finite()));
        if coupled {
            let v_old = Vector3::new(
                self.actuators[0].velocity,
                self.actuators[1].velocity,
                self.actuators[2].velocity,
            );
            let d = Matrix3::from_fn(|i, j| {
                let x = loads[i].damping[j];
                if x.is_finite() { x } else { 0.0 }
            });
            let a = Matrix3::from_diagonal(&Vector3::from_fn(|i, _| pending[i].inertia)) + dt_s * d;
            let b = Vector3::from_fn(|i, _| pending[i].numerator) + dt_s * d * v_old;
            if let Some(v) = a.lu().solve(&b).filter(|v| v.iter().all(|x| x.is_finite())) {
                v_solved[..SWING].copy_from_slice(v.as_slice());
            }
        }
        v_solved
    }

    /// Friction, blocking and end stops on the solved velocities, then the new positions and the
    /// chamber pressures at the new velocities.
    fn integrate_motion(
        &mut self,
        pending: &[Pending; N_ACTUATORS],
        v_solved: &[f64; N_ACTUATORS],
        loads: &[ActuatorLoad; N_ACTUATORS],
        dt_s: f64,
    ) {
        for i in 0..N_ACTUATORS {
            let ch = self.chambers(i);
            let state = self.actuators[i];
            let load = loads[i];
            let Pending {
                inertia,
                coulomb,
                head0,
                head_gain,
                rod0,
                rod_gain,
                ..
            } = pending[i];
            let v = state.velocity;
            let mut v_new = v_solved[i];
            // Coulomb friction with stiction: it can stop the actuator but never reverse it.
            let dv_friction = dt_s * coulomb / inertia;
            v_new = if v_new.abs() <= dv_friction {
                0.0
            } else {
                v_new - dv_friction * v_new.signum()
            };
            if (load.blocked_extend && v_new > 0.0) || (load.blocked_retract && v_new < 0.0) {
                v_new = 0.0;
            }
            let mut x_new = state.position + dt_s * v_new;
            // End stops at the stroke limits (inelastic).
            if !ch.rotary {
                if x_new <= 0.0 {
                    x_new = 0.0;
                    v_new = v_new.max(0.0);
                } else if x_new >= ch.stroke {
                    x_new = ch.stroke;
                    v_new = v_new.min(0.0);
                }
            }
            let head = (head0 - head_gain * ch.area_head * (v_new - v)).max(0.0);
            let rod = (rod0 + rod_gain * ch.area_rod * (v_new - v)).max(0.0);
            self.previous_chamber_pa[i] = [state.head_pa, state.rod_pa];
            self.actuators[i] = ActuatorState {
                position: x_new,
                velocity: v_new,
                head_pa: head,
                rod_pa: rod,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT_S: f64 = 1.0e-3;
    /// Effective masses for no-load tests (kg): heavy enough to be realistic, no gravity.
    const TEST_MASS_KG: [f64; N_ACTUATORS] = [2.0e4, 1.0e4, 4.0e3, 6.0e4];

    fn free_loads() -> [ActuatorLoad; N_ACTUATORS] {
        TEST_MASS_KG.map(|mass| ActuatorLoad {
            mass,
            ..ActuatorLoad::default()
        })
    }

    fn run(h: &mut Hydraulics, spools: [f64; 4], loads: &[ActuatorLoad; 4], seconds: f64) {
        let eff = HydraulicEffects::default();
        for _ in 0..(seconds / DT_S).round() as usize {
            h.step(DT_S, spools, loads, &eff);
        }
    }

    /// The cross-piston leakage effect lets a cylinder held by its rod chamber behind a closed
    /// spool drift at `L (p_rod - p_head) / A_rod`: the rod chamber loses the leak flow and the
    /// head, at tank, takes it and make-up oil.
    #[test]
    fn leakage_lets_a_held_cylinder_drift_at_the_leak_flow_over_its_area() {
        let params = HydraulicParams::default();
        let leak = 1.0e-11;
        let eff = HydraulicEffects {
            internal_leakage: leak,
            ..HydraulicEffects::default()
        };
        let mut h = Hydraulics::new(params, [0.5, 0.5, 0.5, 0.0]);
        let mut loads = free_loads();
        let rod_pa = 30.0e6;
        loads[STICK].force = -rod_pa * h.rod_area_m2(STICK);
        for _ in 0..2000 {
            h.step(DT_S, [0.0; 4], &loads, &eff);
        }
        let a = h.actuators[STICK];
        let expected = leak * (a.rod_pa - a.head_pa) / h.rod_area_m2(STICK);
        assert!(
            (a.velocity - expected).abs() < 0.05 * expected,
            "drift {} m/s against {expected} m/s ({a:?})",
            a.velocity
        );
    }

    #[test]
    fn orifice_flow_follows_eq1_and_is_continuous_at_laminar_limit() {
        let fluid = FluidParams::default();
        let area = 1.0e-4;
        let q = orifice_flow(&fluid, area, 1.0e6, 0.0);
        let expected = 0.7 * area * (2.0 * 1.0e6 / 850.0_f64).sqrt();
        assert!((q - expected).abs() < 1e-12);
        let below = orifice_flow(&fluid, area, fluid.laminar_dp_pa * (1.0 - 1e-9), 0.0);
        let above = orifice_flow(&fluid, area, fluid.laminar_dp_pa * (1.0 + 1e-9), 0.0);
        assert!((below - above).abs() < 1e-9);
        assert_eq!(orifice_flow(&fluid, area, 0.0, 1.0e6), -q);
    }

    #[test]
    fn neutral_valves_bleed_pump_flow_to_tank_at_low_pressure() {
        let params = HydraulicParams::default();
        let mut h = Hydraulics::new(params, [0.5, 0.5, 0.5, 0.0]);
        run(&mut h, [0.0; 4], &free_loads(), 0.5);
        for pump in 0..2 {
            assert!(h.pump_pa[pump] < 3.0e6, "standby {}", h.pump_pa[pump]);
        }
        for a in &h.actuators {
            assert!(a.velocity.abs() < 1e-3, "{a:?}");
        }
    }

    #[test]
    fn full_command_against_no_load_moves_each_cylinder_at_flow_limited_speed() {
        let params = HydraulicParams::default();
        let q = params.pumps[0].max_flow_m3_per_s;
        for (i, sign) in [(BOOM, 1.0), (STICK, 1.0), (BUCKET, 1.0), (STICK, -1.0)] {
            let mut h = Hydraulics::new(params, [0.5, 0.7, 0.5, 0.0]);
            let mut spools = [0.0; 4];
            spools[i] = sign;
            run(&mut h, spools, &free_loads(), 0.8);
            let area = if sign > 0.0 {
                h.head_area_m2(i)
            } else {
                h.rod_area_m2(i)
            };
            // The boom also gets pump 2's flow through the crossover at full command.
            let flow = if i == BOOM { 2.0 * q } else { q };
            let expected = sign * flow / area;
            let got = h.actuators[i].velocity;
            assert!(
                (got - expected).abs() < 0.03 * expected.abs(),
                "actuator {i}: {got} m/s, flow limit {expected} m/s"
            );
        }
    }

    #[test]
    fn cylinder_against_rigid_obstacle_stalls_at_relief_pressure() {
        let params = HydraulicParams::default();
        let relief = params.pumps[0].main_relief_pa;
        for i in [BOOM, STICK, BUCKET] {
            let mut h = Hydraulics::new(params, [0.5; 4]);
            let mut loads = free_loads();
            loads[i].blocked_extend = true;
            let mut spools = [0.0; 4];
            spools[i] = 1.0;
            run(&mut h, spools, &loads, 1.0);
            let a = h.actuators[i];
            assert_eq!(a.velocity, 0.0);
            assert!(
                (a.head_pa - relief).abs() < 0.03 * relief,
                "actuator {i}: head {} Pa, relief {relief} Pa",
                a.head_pa
            );
        }
    }

    #[test]
    fn end_stop_stalls_at_relief_too() {
        let params = HydraulicParams::default();
        let mut h = Hydraulics::new(params, [params.cylinders[0].stroke_m - 0.01, 0.5, 0.5, 0.0]);
        run(&mut h, [1.0, 0.0, 0.0, 0.0], &free_loads(), 1.0);
        let a = h.actuators[BOOM];
        assert_eq!(a.position, params.cylinders[0].stroke_m);
        assert!((a.head_pa - params.pumps[0].main_relief_pa).abs() < 0.03 * 34.3e6);
    }

    #[test]
    fn heavy_load_is_held_at_neutral_and_lifted_when_commanded() {
        let params = HydraulicParams::default();
        let mut h = Hydraulics::new(params, [0.5, 0.5, 0.5, 0.0]);
        let mut loads = free_loads();
        loads[BOOM].force = 2.0e5; // 200 kN of gravity on the boom cylinders.
        loads[BOOM].mass = 1.0e5;
        run(&mut h, [0.0; 4], &loads, 3.0);
        let before = h.actuators[BOOM].position;
        run(&mut h, [0.0; 4], &loads, 1.0);
        let held = h.actuators[BOOM];
        assert!((held.position - before).abs() < 1e-3, "drift {held:?}");
        assert!((h.actuator_force(BOOM) - 2.0e5).abs() < 0.1 * 2.0e5);
        run(&mut h, [1.0, 0.0, 0.0, 0.0], &loads, 1.0);
        assert!(h.actuators[BOOM].velocity > 0.1);
    }

    /// Stability proof by test: with tiny chamber volumes (very stiff Eq. 2, oil-column natural
    /// frequency above 2 kHz) and steps up to 50 times coarser than the smallest, the implicit scheme
    /// stays bounded, never goes below zero pressure, and converges to the same steady velocities.
    #[test]
    fn implicit_pressure_integration_is_stable_for_stiff_volumes_and_coarse_steps() {
        let mut params = HydraulicParams::default();
        for c in &mut params.cylinders {
            c.dead_volume_m3 = 1.0e-5;
        }
        params.swing.port_volume_m3 = 1.0e-5;
        params.fluid.bulk_modulus_pa = 1.8e9;
        let eff = HydraulicEffects::default();
        let mut finals = Vec::new();
        for dt in [1.0e-4, 1.0e-3, 5.0e-3] {
            let mut h = Hydraulics::new(params, [0.6, 0.75, 0.55, 0.0]);
            let steps = (1.0 / dt) as usize;
            for k in 0..steps {
                // Reverse every command at mid-run: a violent pressure transient.
                let cmd = if k < steps / 2 { 1.0 } else { -1.0 };
                h.step(dt, [cmd, -cmd, 0.8 * cmd, cmd], &free_loads(), &eff);
                for a in &h.actuators {
                    assert!(a.head_pa.is_finite() && a.rod_pa.is_finite());
                    assert!((0.0..40.0e6).contains(&a.head_pa), "dt {dt}: {a:?}");
                    assert!((0.0..40.0e6).contains(&a.rod_pa), "dt {dt}: {a:?}");
                    assert!(a.velocity.abs() < 2.0, "dt {dt}: {a:?}");
                }
            }
            finals.push(h.actuators.map(|a| a.velocity));
        }
        for coarse in &finals[1..] {
            for i in 0..N_ACTUATORS {
                let reference = finals[0][i];
                assert!(
                    (coarse[i] - reference).abs() < 0.1 * reference.abs() + 1e-3,
                    "actuator {i}: {} vs {reference}",
                    coarse[i]
                );
            }
        }
    }

    /// Regression: a Newton step that landed on the root left a residual at rounding level (not
    /// below 1e-12), the next Newton step then fell on the bracket's edge and the solver bisected the
    /// whole 87 MPa bracket down to 10 Pa (~25 evaluations, and an answer anywhere within 10 Pa).
    #[test]
    fn root_found_to_rounding_ends_the_solve_without_bisecting() {
        // A chamber-like residual: linear plus a square-root orifice term, root near 2.7e5 Pa.
        let residual = |p: f64| {
            let q = 5.4e-6 * (2.0e7 - p).sqrt();
            (
                2.7e5 + 5.0e8 * (q - 2.4e-2) - p,
                -5.0e8 * 5.4e-6 / (2.0 * (2.0e7 - p).sqrt()) - 1.0,
            )
        };
        let mut evaluations = 0;
        let root = solve_decreasing(
            |p| {
                evaluations += 1;
                residual(p)
            },
            2.6e5,
            0.0,
            8.7e7,
        );
        assert!(evaluations <= 4, "{evaluations} evaluations");
        assert!(
            residual(root).0.abs() < 1e-3,
            "residual {}",
            residual(root).0
        );
        // A root below the lower bound (a chamber drained below zero) is clamped to it at once.
        let mut evaluations = 0;
        let clamped = solve_decreasing(
            |p| {
                evaluations += 1;
                (-2.2e5 - 1.3 * p, -1.3)
            },
            5.0e3,
            0.0,
            8.7e7,
        );
        assert_eq!(clamped, 0.0);
        assert!(evaluations <= 2, "{evaluations} evaluations");
    }

    /// The scripted run of the side-by-side tests, `(seconds, spools)`: full and partial commands,
    /// reversals, the crossover, stalls at the end stops and relief (each test then adds its ending).
    const MIXED_RUN: [(f64, [f64; 4]); 6] = [
        (1.0, [0.7, -0.5, 0.6, 0.3]),
        (1.5, [-0.4, 0.9, -0.3, -0.5]),
        (1.0, [1.0, 0.0, 0.0, 0.4]),
        (2.5, [0.0, -1.0, -1.0, 0.0]),
        (0.5, [0.2, 0.3, 1.0, 0.8]),
        (0.3, [-1.0, 1.0, -1.0, -1.0]),
    ];

    /// Runs `a` and `b` through `script` (seconds, spools) with the same loads and effects and returns
    /// the largest pressure (Pa) and velocity difference over all steps; asserts the end positions
    /// agree within 1e-7.
    fn run_side_by_side(
        a: &mut Hydraulics,
        b: &mut Hydraulics,
        script: &[(f64, [f64; 4])],
        loads: &[ActuatorLoad; N_ACTUATORS],
        effects: &HydraulicEffects,
    ) -> (f64, f64) {
        let (mut dp_max, mut dv_max) = (0.0_f64, 0.0_f64);
        for &(seconds, spools) in script {
            for _ in 0..(seconds / DT_S).round() as usize {
                a.step(DT_S, spools, loads, effects);
                b.step(DT_S, spools, loads, effects);
                for (x, y) in a.actuators.iter().zip(&b.actuators) {
                    dp_max = dp_max.max((x.head_pa - y.head_pa).abs());
                    dp_max = dp_max.max((x.rod_pa - y.rod_pa).abs());
                    dv_max = dv_max.max((x.velocity - y.velocity).abs());
                }
            }
        }
        eprintln!("max differences: {dp_max} Pa, {dv_max} m/s");
        for (x, y) in a.actuators.iter().zip(&b.actuators) {
            assert!((x.position - y.position).abs() < 1e-7, "{x:?} vs {y:?}");
        }
        (dp_max, dv_max)
    }

    /// The chamber solves' unevaluated Newton steps (accepted within 1 Pa of the root by the Taylor
    /// bound, then corrected by the known second-order term) against solving every chamber until the
    /// step is below 10 Pa, as before: on a scripted run with gravity-like loads, leakage, full and
    /// partial commands, reversals, the crossover, stalls at the end stops and relief (dead-end
    /// chambers filling for seconds), and neutral, the pressures agree within 1 Pa (measured 0.07 Pa)
    /// and the velocities within 1e-7 m/s or rad/s (measured 2.5e-9) at every step, the positions
    /// within 1e-7 at the end.
    #[test]
    fn unevaluated_newton_steps_agree_with_solving_each_chamber_to_10_pa() {
        let params = HydraulicParams::default();
        let start = [0.4, 0.6, 0.3, 0.0];
        let mut fast = Hydraulics::new(params, start);
        let mut exact = Hydraulics::new(params, start);
        exact.accept_unevaluated = false;
        let loads = gravity_like_loads();
        let effects = HydraulicEffects {
            internal_leakage: 2e-12,
            ..HydraulicEffects::default()
        };
        let script: Vec<_> = MIXED_RUN.into_iter().chain([(1.0, [0.0; 4])]).collect();
        let (dp_max, dv_max) = run_side_by_side(&mut fast, &mut exact, &script, &loads, &effects);
        assert!(dp_max < 1.0, "pressures differ by up to {dp_max} Pa");
        assert!(dv_max < 1e-7, "velocities differ by up to {dv_max}");
    }

    /// The closed-form root of a chamber with one open metering orifice against solving Eq. 2's
    /// backward-Euler residual by bisection to rounding, over supplied and drained chambers with
    /// laminar and turbulent drops: the residual there is zero to rounding and the slope is Eq. 1's.
    #[test]
    fn one_orifice_chamber_root_solves_eq2_exactly() {
        let oc = OrificeConstants::of(&FluidParams::default());
        for area in [2.0e-6, 5.0e-5, 3.0e-4] {
            let orifice = Orifice::new(&oc, area);
            for c in [1.0e8, 2.0e9, 5.0e10] {
                for (supplied, fixed) in [(true, 2.5e7), (false, 2.0e5)] {
                    for base in [
                        -3.0e6, 1.0e5, 1.999e5, 2.0e5, 2.01e5, 4.0e5, 5.0e6, 2.49e7, 2.5e7, 2.6e7,
                    ] {
                        let root = one_orifice_chamber_root(&orifice, supplied, fixed, base, c);
                        // The meter-in's check valve shuts for a drop of zero or less.
                        let inflow = |pn: f64| {
                            let (q, d) =
                                orifice.flow(if supplied { fixed - pn } else { pn - fixed });
                            if supplied {
                                if q > 0.0 { (q, -d) } else { (0.0, 0.0) }
                            } else {
                                (-q, -d)
                            }
                        };
                        let residual = |pn: f64| base + c * inflow(pn).0 - pn;
                        let drive = if supplied { fixed - base } else { base - fixed };
                        let Some((pn, slope)) = root else {
                            assert!(!supplied && drive < 0.0, "no root for drive {drive}");
                            continue;
                        };
                        if drive <= 0.0 && supplied {
                            // The check valve holds: no flow, the root is `base`.
                            assert!(pn == base && slope == 0.0 && residual(pn) == 0.0);
                            continue;
                        }
                        if drive == 0.0 {
                            // A drained chamber at tank pressure: no flow, Eq. 1's laminar slope.
                            assert!(pn == fixed && slope == -orifice.laminar_slope);
                            assert!(residual(pn) == 0.0);
                            continue;
                        }
                        // Bisection on the decreasing residual between the fixed pressure and base.
                        let (mut lo, mut hi) = if supplied {
                            (base, fixed)
                        } else {
                            (fixed, base)
                        };
                        for _ in 0..200 {
                            let mid = 0.5 * (lo + hi);
                            if residual(mid) > 0.0 {
                                lo = mid
                            } else {
                                hi = mid
                            }
                        }
                        let scale = drive.max(1.0);
                        assert!(
                            (pn - 0.5 * (lo + hi)).abs() <= 1e-9 * scale,
                            "area {area} c {c} supplied {supplied} base {base}: {pn} vs {lo}"
                        );
                        let expected = inflow(pn).1;
                        assert!(
                            (slope - expected).abs() <= 1e-9 * expected.abs(),
                            "slope {slope} vs {expected}"
                        );
                    }
                }
            }
        }
    }

    /// The side-by-side runs' loads: a gravity-like force of 0.8 N per kg of [`TEST_MASS_KG`].
    fn gravity_like_loads() -> [ActuatorLoad; 4] {
        TEST_MASS_KG.map(|mass| ActuatorLoad {
            force: 0.8 * mass,
            mass,
            ..ActuatorLoad::default()
        })
    }

    /// The closed-form chamber roots against the Newton solves they replace, on the scripted run of
    /// the test above without leakage (where the closed form applies to every chamber with one open
    /// metering orifice): pressures within the Newton solves' 10 Pa tolerance (measured 0.97 Pa),
    /// velocities within 1e-7 (measured 2.9e-8) at every step, positions within 1e-7 at the end.
    #[test]
    fn closed_form_chamber_roots_agree_with_the_newton_solves() {
        let params = HydraulicParams::default();
        let start = [0.4, 0.6, 0.3, 0.0];
        let mut fast = Hydraulics::new(params, start);
        let mut newton = Hydraulics::new(params, start);
        newton.closed_form = false;
        let loads = gravity_like_loads();
        let effects = HydraulicEffects::default();
        let script: Vec<_> = MIXED_RUN
            .into_iter()
            .chain([(0.5, [0.05, -0.08, 0.1, 0.02]), (1.0, [0.0; 4])])
            .collect();
        let (dp_max, dv_max) = run_side_by_side(&mut fast, &mut newton, &script, &loads, &effects);
        assert!(dp_max < 10.0, "pressures differ by up to {dp_max} Pa");
        assert!(dv_max < 1e-7, "velocities differ by up to {dv_max}");
    }

    #[test]
    fn power_destroke_limits_flow_at_high_pressure() {
        let pump = PumpParams::default();
        assert_eq!(pump.flow(1.0e6, 0.0), pump.max_flow_m3_per_s);
        assert!((pump.flow(30.0e6, 0.0) - 60_000.0 / 30.0e6).abs() < 1e-12);
        assert!((pump.flow(1.0e6, 0.5) - 0.5 * pump.max_flow_m3_per_s).abs() < 1e-12);
    }

    #[test]
    fn flow_sharing_effect_slows_the_boom_when_the_bucket_moves() {
        let params = HydraulicParams::default();
        let eff = HydraulicEffects {
            flow_sharing: 0.8,
            ..HydraulicEffects::default()
        };
        let loads = free_loads();
        let speed = |effects: &HydraulicEffects| {
            let mut h = Hydraulics::new(params, [0.3, 0.3, 0.3, 0.0]);
            for _ in 0..800 {
                h.step(DT_S, [0.5, 0.0, 0.8, 0.0], &loads, effects);
            }
            h.actuators[BOOM].velocity
        };
        assert!(speed(&eff) < 0.8 * speed(&HydraulicEffects::default()));
    }

    #[test]
    fn garbage_inputs_do_not_produce_nan() {
        let mut h = Hydraulics::new(HydraulicParams::default(), [0.5; 4]);
        let loads = free_loads();
        h.step(
            DT_S,
            [f64::NAN, f64::INFINITY, -7.0, 0.2],
            &loads,
            &HydraulicEffects::default(),
        );
        h.step(f64::NAN, [0.0; 4], &loads, &HydraulicEffects::default());
        for a in &h.actuators {
            assert!(a.position.is_finite() && a.head_pa.is_finite());
        }
    }
}
