//! The grey-box replay model: a physical model of the valves, pumps, cylinders, links and soil with
//! few parameters, driven by the measured inputs of a trace (valve commands, measured pressures and
//! motion, the pre-dig terrain section) and predicting the measured signals sample by sample.
//!
//! The prediction is an equation-error (one-step) replay: every relation is evaluated at the measured
//! state of its own sample, so model errors never accumulate along a dig (the limit of multiple
//! shooting with one-sample windows). Only the spool state is integrated along the record, from the
//! commands alone (it has no measured counterpart). Relations, per 10 ms sample:
//!
//! - spool: dead band, fixed transport delay, first-order lag (Eq. 2's compressibility and the pilot
//!   stage folded into one time constant), integrated at 1 ms from the zero-order-held commands;
//! - cylinder velocity (Eq. 1): meter-in `Q = k_in a(s) sqrt(p_pump - p_inlet)` and meter-out
//!   `Q = k_out a(s) sqrt(p_outlet - p_tank)` orifices with the measured pressures, flow continuity
//!   `Q = A v` (plus cross-piston leakage), the two estimates combined with weights inverse to their
//!   sensitivity to pressure noise;
//! - pump pressure: the open-centre flow balance `Q_pump(p) = Q_bypass(p) + sum Q_meter_in(p) +
//!   Q_relief(p)` with `Q_pump = min(Q_max, W / p)` (thesis 4.2.1, Fig. 15), solved for the gallery
//!   pressure with the measured chamber pressures;
//! - cylinder force (Eq. 3 with Eq. A20): `p_h A_h - p_r A_r = F_gravity(q) + M(q) a + c v + friction`
//!   with the Appendix gravity torques (Eq. A4) over the moment arms (Eqs. A7, A19), only where the
//!   bucket is empty and out of the soil;
//! - soil force on the bucket (Eqs. A20-A23 from the measured pressures) against the modified FEE
//!   (Eqs. 14-18) on the pre-dig section, in the soil stages.

// Per-cylinder and per-signal arrays run in parallel; indexing them by one counter is clearer here
// than zipping four iterators.
#![allow(clippy::needless_range_loop)]

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::soil_replay::{self, CutSection};
use super::{DigRecord, DiscrepancyError, LoadTag, Result};
use planner::kinematics::{Joint, JointAngles, Kinematics, TipForce, payload_least_squares};
use planner::machine::MachineConfig;
use planner::soil::{BearingParams, SoilProperties};

/// Physics substep of the spool integration, s (the simulator's and the valve's 1 kHz).
const SPOOL_DT_S: f64 = 0.001;
/// Substeps per record sample.
const SUBSTEPS: usize = 10;
/// Samples at the start of a record, and after a gap in it, whose spool state is still unknown (the
/// commands before them are).
pub const WARMUP_SAMPLES: usize = 50;

/// A pause between two samples longer than this is a gap in the record, s (the reader leaves out the
/// samples under the gateway's position mode, whose spools the gateway set itself): the spool
/// integration ([`spools`]) steps over it as one sample and comes out of it with the state before it.
const GAP_S: f64 = 0.05;

/// Whether each sample is at least [`WARMUP_SAMPLES`] past the start of its record or the last gap.
/// (Effect-free session none_s200: in the Dig stage that followed a cleanup the stick moved at 0.22
/// m/s on the spool the gateway had opened, the replay's spools came out of the gap closed and
/// predicted 0 to 0.14 m/s for 0.2 s: 25 samples that made nearly all of the stick velocity's
/// residual sum of squares in that session.)
fn warmed_up(samples: &[super::Sample]) -> Vec<bool> {
    let mut since = 0usize;
    samples
        .iter()
        .enumerate()
        .map(|(k, s)| {
            if k > 0 && s.time_s - samples[k - 1].time_s > GAP_S {
                since = 0;
            }
            since += 1;
            since > WARMUP_SAMPLES
        })
        .collect()
}
/// Below this cylinder speed the actuator is at rest (stiction holds it), m/s.
const REST_SPEED_M_PER_S: f64 = 2.0e-3;
/// Smallest cylinder speed at which a sample enters that cylinder's force signal, m/s (well above
/// the resolver-rate noise of a resting link, a few mm/s).
const MOVING_SPEED_M_PER_S: f64 = 0.02;
/// Largest cylinder acceleration at which a sample enters the force signals, m/s^2.
const QUASI_STATIC_ACCEL_M_PER_S2: f64 = 0.5;
/// Samples (0.3 s) a cylinder's valve command must have been open (beyond the spool overlap) for a
/// sample to enter that cylinder's force signal.
const SPOOL_OPEN_SAMPLES: usize = 30;
/// An inlet chamber reading this far above its supply (pump gallery, crossover) has its load check
/// shut, Pa: ten standard deviations of the difference of two readings with the transducer noise
/// (0.05 MPa each), so that noise does not toggle the balance.
const LOAD_CHECK_MARGIN_PA: f64 = 7.0e5;
/// A chamber behind a closed spool reading less than this above tank may be taking make-up oil
/// through its anti-cavitation check valve, Pa: four standard deviations of the transducer noise.
const MAKEUP_MARGIN_PA: f64 = 2.0e5;
/// An open valve's velocity relation is noise-dominated, and the sample stays out of the velocity
/// signal, when its inlet reads within this of its supply (no meter-in estimate: the load, not the
/// valve, sets the speed) and its outlet within [`NOISY_OUTLET_DP_PA`] of tank, Pa. The meter-in
/// estimate is weighted out below this drop in `cylinder_velocity`.
const NOISY_INLET_DP_PA: f64 = 2.0e5;
/// See [`NOISY_INLET_DP_PA`]: an outlet drop of 0.5 MPa gives the meter-out flow to about 7 % with the
/// transducer noise (0.05 MPa per reading, `sqrt(2) 0.05 / (2 x 0.5)`), Pa.
const NOISY_OUTLET_DP_PA: f64 = 5.0e5;
/// A measured cylinder velocity that zig-zags by more than this from one sample to the next and back
/// is an oscillation at the sampling's Nyquist rate (the oil column of a link hanging behind a closed
/// spool, its other chamber emptied), which no model sampled at 100 Hz can follow; the sample stays
/// out of the velocity signal, m/s (about five standard deviations of the difference of two
/// resolver-rate readings of a resting link).
const ALIASED_ZIGZAG_M_PER_S: f64 = 0.02;
/// Pressure readings at or below this are taken as clamped at the sensor's zero, Pa.
const CLAMPED_READING_PA: f64 = 1.0e3;
/// Margin from the stroke ends where the end stops may carry force, m.
const STROKE_MARGIN_M: f64 = 0.01;
/// End-stop relation: a link whose reading is within this of a stroke-limited end of its range may be
/// at that end stop, rad (the offsets it can see; beyond 1 degree the controller's safety layer
/// stops the machine at the first stop it reaches, docs/discrepancy.md).
const STOP_WINDOW_RAD: f64 = 0.05;
/// End-stop relation: largest resolver rate of a link at rest, rad/s.
const STOP_REST_RATE_RAD_PER_S: f64 = 0.005;
/// End-stop relation: the cylinder force beyond the one holding the link against gravity must push
/// the link towards the end by more than this, N, plus what the heaviest payload could take: twice
/// the largest dry friction of the effect library (50 kN), so a link held by stiction or by oil
/// trapped at a modest pressure short of the stop is not taken for one at the stop.
const STOP_PRESS_FORCE_N: f64 = 100_000.0;

/// The predicted signals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Signal {
    /// Boom cylinder velocity, m/s.
    BoomVelocity,
    /// Stick cylinder velocity, m/s.
    StickVelocity,
    /// Bucket cylinder velocity, m/s.
    BucketVelocity,
    /// Pump 1 (boom, bucket) pressure, Pa.
    Pump1Pressure,
    /// Pump 2 (stick, swing) pressure, Pa.
    Pump2Pressure,
    /// Boom cylinder force (Eq. A20), N.
    BoomForce,
    /// Stick cylinder force, N.
    StickForce,
    /// Bucket cylinder force, N.
    BucketForce,
    /// Soil force on the bucket, horizontal (base x), N.
    SoilForceX,
    /// Soil force on the bucket, vertical (base z), N.
    SoilForceZ,
    /// End-stop angle: the reading of a link pressed against a stroke end (at rest, the cylinder
    /// pushing it towards the end far beyond its weight) less the end's angle from the machine
    /// geometry (Appendix A, the cylinder stroke), rad.
    StopAngle,
    /// Payload mass while the work cycle weighs the bucket (valves neutral, implement held up): the
    /// static least-squares estimate from the joint torques less the links' gravity (Eqs. A20-A22),
    /// as the controller weighs, kg.
    PayloadMass,
}

/// Number of signals.
pub const N_SIGNALS: usize = 12;

impl Signal {
    /// Every signal in array order.
    pub const ALL: [Signal; N_SIGNALS] = [
        Signal::BoomVelocity,
        Signal::StickVelocity,
        Signal::BucketVelocity,
        Signal::Pump1Pressure,
        Signal::Pump2Pressure,
        Signal::BoomForce,
        Signal::StickForce,
        Signal::BucketForce,
        Signal::SoilForceX,
        Signal::SoilForceZ,
        Signal::StopAngle,
        Signal::PayloadMass,
    ];

    /// Index in signal arrays.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Signal::BoomVelocity => "boom_velocity",
            Signal::StickVelocity => "stick_velocity",
            Signal::BucketVelocity => "bucket_velocity",
            Signal::Pump1Pressure => "pump1_pressure",
            Signal::Pump2Pressure => "pump2_pressure",
            Signal::BoomForce => "boom_force",
            Signal::StickForce => "stick_force",
            Signal::BucketForce => "bucket_force",
            Signal::SoilForceX => "soil_force_x",
            Signal::SoilForceZ => "soil_force_z",
            Signal::StopAngle => "stop_angle",
            Signal::PayloadMass => "payload_mass",
        }
    }

    /// Unit of the signal.
    pub fn unit(self) -> &'static str {
        match self.index() {
            0..=2 => "m/s",
            3..=4 => "Pa",
            10 => "rad",
            11 => "kg",
            _ => "N",
        }
    }

    /// The cylinder (0 boom, 1 stick, 2 bucket) of a per-cylinder signal.
    pub fn cylinder(self) -> Option<usize> {
        match self.index() {
            i @ 0..=2 => Some(i),
            i @ 5..=7 => Some(i - 5),
            _ => None,
        }
    }
}

/// The nominal grey-box parameters: "the nominal model the project ships" (`config/nominal_greybox.json`).
/// Geometry and masses come from the machine file; these are the hydraulic and soil constants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GreyBoxParams {
    /// Head areas `[boom, stick, bucket]` (all cylinders of a joint together), m^2.
    pub head_area_m2: [f64; 3],
    /// Rod (annulus) areas, m^2.
    pub rod_area_m2: [f64; 3],
    /// Tank (return) pressure, Pa.
    pub tank_pa: f64,
    /// Meter-in orifice constant at full spool, `Cd A sqrt(2/rho)` (Eq. 1), m^3/(s sqrt(Pa)).
    pub meter_in_k: [f64; 3],
    /// Meter-out orifice constant at full spool, m^3/(s sqrt(Pa)).
    pub meter_out_k: [f64; 3],
    /// Open-centre bypass constant of one valve at neutral, m^3/(s sqrt(Pa)).
    pub bypass_k: f64,
    /// Below this pressure drop the orifices are laminar (linear), Pa.
    pub laminar_dp_pa: f64,
    /// Spool overlap: fraction of the stroke before the metering orifices open.
    pub overlap: f64,
    /// Spool fraction at which the bypass is closed.
    pub bypass_close: f64,
    /// Boom command where the crossover from pump 2 starts to open.
    pub crossover_start: f64,
    /// Boom command where it is fully open.
    pub crossover_full: f64,
    /// Crossover orifice constant, m^3/(s sqrt(Pa)).
    pub crossover_k: f64,
    /// Maximum flow of each pump, m^3/s.
    pub pump_max_flow_m3_per_s: f64,
    /// Power of each pump before it destrokes, W.
    pub pump_power_w: f64,
    /// Main relief pressure, Pa.
    pub relief_pa: f64,
    /// Pressure over the relief setting at which it passes the full pump flow, Pa.
    pub relief_override_pa: f64,
    /// Swing motor displacement per swing radian, m^3/rad.
    pub swing_displacement_m3_per_rad: f64,
    /// Fixed command-to-spool delay, s.
    pub transport_delay_s: f64,
    /// Spool first-order lag, s.
    pub lag_time_constant_s: f64,
    /// Viscous damping of the seals of each cylinder, N s/m.
    pub damping_n_s_per_m: f64,
    /// Inertia of cylinders, pins and oil reflected to each joint, kg m^2.
    pub inertia_floor_kg_m2: [f64; 3],
    /// Nominal soil (FEE `Psi`).
    pub soil: SoilProperties,
    /// Multiplies the FEE force (calibrated on nominal digs).
    pub soil_force_factor: f64,
    /// Bearing resistance of an edge or back pushed into the soil (the planner's moving-bucket soil
    /// model, [`planner::soil::MovingBucketSoil`]).
    #[serde(default)]
    pub bearing: BearingParams,
    /// Effective bulk modulus of oil and hoses (Eq. 2 `beta`), Pa.
    #[serde(default = "default_bulk_modulus_pa")]
    pub bulk_modulus_pa: f64,
    /// Oil volume of a chamber at its stroke end (hoses, valve ports), m^3.
    #[serde(default = "default_dead_volume_m3")]
    pub dead_volume_m3: f64,
    /// The Eq. 2 chamber balance in the velocity relation: oil compression at the measured pressure
    /// rates, and no meter-in bound on a chamber below tank pressure (anti-cavitation make-up).
    #[serde(default)]
    pub chamber_balance: bool,
    /// Cross-piston leakage of the nominal model, m^3/(s Pa) (calibrated on effect-free sessions;
    /// the `internal_leakage` candidate adds to it).
    #[serde(default)]
    pub internal_leakage_m3_per_s_pa: f64,

    /// The spill of a full bucket on the terrain in the soil relation: what the edge cuts beyond the
    /// capacity piles up around the edge at [`Self::spill_repose_rad`], and out of the soil the
    /// bucket holds less as its opening tips down ([`soil_replay::CutSection::spill`]). Off: the
    /// spill leaves the terrain untouched and the bucket holds the cut volume up to its capacity.
    #[serde(default)]
    pub spill_pile: bool,
    /// Angle of repose of the soil a full bucket spills at its edge, rad.
    #[serde(default = "default_spill_repose_rad")]
    pub spill_repose_rad: f64,
}

fn default_spill_repose_rad() -> f64 {
    37f64.to_radians()
}

fn default_bulk_modulus_pa() -> f64 {
    1.2e9
}

fn default_dead_volume_m3() -> f64 {
    2.0e-3
}

impl GreyBoxParams {
    /// Physical first guesses from a machine file (Eq. 1 constants from its valve area and discharge
    /// coefficient; the boom section passes two cylinders' flow, so 1.3 times the area; meter-out
    /// areas 1.6 times the meter-in ones, a usual valve-catalogue ratio), the soil of
    /// `config/dig_model.toml`. [`super::AugmentedModel::nominal`] holds these after calibration on
    /// nominal traces.
    pub fn from_machine(cfg: &MachineConfig) -> Self {
        let h = &cfg.hydraulics;
        let cyl = [
            &cfg.cylinders.boom,
            &cfg.cylinders.stick,
            &cfg.cylinders.bucket,
        ];
        let k = h.valve_discharge_coefficient * h.valve_max_area_m2;
        let pumps = f64::from(h.pump_count.max(1));
        Self {
            head_area_m2: cyl.map(|c| c.head_area_m2()),
            rod_area_m2: cyl.map(|c| c.rod_area_m2()),
            tank_pa: h.tank_pressure_pa,
            meter_in_k: [1.3 * k, k, k],
            meter_out_k: [1.6 * 1.3 * k, 1.6 * k, 1.6 * k],
            bypass_k: h.valve_discharge_coefficient * h.valve_bleed_area_m2 * 2f64.sqrt(),
            laminar_dp_pa: 5.0e4,
            overlap: 0.05,
            bypass_close: 0.75,
            crossover_start: h.crossover_command.clamp(0.05, 0.95),
            crossover_full: (h.crossover_command + 0.2).min(1.0),
            crossover_k: k,
            pump_max_flow_m3_per_s: h.pump_max_flow_m3_per_s,
            pump_power_w: h.max_engine_power_w / pumps,
            relief_pa: h.relief_pressure_pa,
            relief_override_pa: 1.0e6,
            swing_displacement_m3_per_rad: 3.1e-3,
            transport_delay_s: h.transport_delay_s,
            lag_time_constant_s: h.lag_time_constant_s,
            damping_n_s_per_m: 5.0e4,
            inertia_floor_kg_m2: [2000.0, 500.0, 100.0],
            soil: SoilProperties {
                density_kg_per_m3: 1700.0,
                failure_angle_rad: 30f64.to_radians(),
                friction_angle_rad: 35f64.to_radians(),
                tool_friction_angle_rad: 20f64.to_radians(),
                cohesion_pa: 8000.0,
            },
            soil_force_factor: 1.0,
            bearing: BearingParams::default(),
            bulk_modulus_pa: h.bulk_modulus_pa,
            dead_volume_m3: default_dead_volume_m3(),
            internal_leakage_m3_per_s_pa: 0.0,
            chamber_balance: false,
            spill_pile: false,
            spill_repose_rad: default_spill_repose_rad(),
        }
    }

    /// Checks that every parameter is finite and physically meaningful.
    ///
    /// # Errors
    /// [`DiscrepancyError::Invalid`] naming the first bad parameter.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("head_area_m2", self.head_area_m2.iter().all(|v| *v > 0.0)),
            ("rod_area_m2", self.rod_area_m2.iter().all(|v| *v > 0.0)),
            ("meter_in_k", self.meter_in_k.iter().all(|v| *v > 0.0)),
            ("meter_out_k", self.meter_out_k.iter().all(|v| *v > 0.0)),
            ("bypass_k", self.bypass_k > 0.0),
            ("laminar_dp_pa", self.laminar_dp_pa > 0.0),
            ("pump_max_flow_m3_per_s", self.pump_max_flow_m3_per_s > 0.0),
            ("pump_power_w", self.pump_power_w > 0.0),
            ("relief_pa", self.relief_pa > self.tank_pa),
            ("relief_override_pa", self.relief_override_pa > 0.0),
            ("lag_time_constant_s", self.lag_time_constant_s > 0.0),
            ("transport_delay_s", self.transport_delay_s >= 0.0),
            ("overlap", (0.0..0.9).contains(&self.overlap)),
            (
                "bypass_close",
                self.bypass_close > 0.0 && self.bypass_close <= 1.0,
            ),
            ("crossover", self.crossover_full > self.crossover_start),
            ("soil_force_factor", self.soil_force_factor >= 0.0),
            ("damping_n_s_per_m", self.damping_n_s_per_m >= 0.0),
            ("bulk_modulus_pa", self.bulk_modulus_pa > 0.0),
            ("dead_volume_m3", self.dead_volume_m3 > 0.0),
            (
                "internal_leakage_m3_per_s_pa",
                self.internal_leakage_m3_per_s_pa >= 0.0,
            ),
            (
                "spill_repose_rad",
                self.spill_repose_rad > 0.0 && self.spill_repose_rad < 1.5,
            ),
        ];
        for (name, ok) in positive {
            if !ok {
                return Err(DiscrepancyError::Invalid(format!(
                    "grey-box parameter {name}"
                )));
            }
        }
        let all = self
            .head_area_m2
            .iter()
            .chain(&self.rod_area_m2)
            .chain(&self.meter_in_k)
            .chain(&self.meter_out_k)
            .chain(&self.inertia_floor_kg_m2)
            .chain(&[
                self.tank_pa,
                self.crossover_k,
                self.swing_displacement_m3_per_rad,
                self.soil.cohesion_pa,
                self.soil.density_kg_per_m3,
            ])
            .all(|v| v.is_finite());
        if !all {
            return Err(DiscrepancyError::Invalid(
                "grey-box parameters must be finite".into(),
            ));
        }
        self.bearing
            .validate()
            .map_err(|e| DiscrepancyError::Invalid(format!("grey-box bearing parameters: {e}")))?;
        Ok(())
    }
}

/// Magnitudes of the candidate effects added to the nominal model, indexed by
/// [`super::Candidate::index`], in the simulator's units. All zero is the nominal model.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Augmentation {
    /// Magnitude per candidate.
    pub values: [f64; super::effects::N_CANDIDATES],
}

impl Augmentation {
    /// The nominal model.
    pub fn nominal() -> Self {
        Self::default()
    }

    /// Magnitude of one candidate.
    pub fn get(&self, c: super::Candidate) -> f64 {
        self.values[c.index()]
    }

    /// Sets one candidate's magnitude.
    pub fn set(&mut self, c: super::Candidate, value: f64) {
        self.values[c.index()] = value;
    }
}

/// Per-sample quantities of a record that do not depend on the candidate effects (kinematics, measured
/// velocities and forces, FEE factors), computed once.
#[derive(Debug, Clone)]
pub struct PreparedRecord {
    /// Dig index.
    pub index: u32,
    /// The samples of the record.
    pub samples: Vec<super::Sample>,
    /// Measured value of every signal (NaN where it is not defined); the velocity signals through
    /// the prefilter ([`prefilter_velocities`]).
    pub measured: Vec<[f64; N_SIGNALS]>,
    /// Whether each cylinder's raw measured velocity enters the velocity signal at the sample (the
    /// samples the replay predicts, before the prefilter).
    velocity_gate: Vec<[bool; 3]>,
    /// Measured cylinder velocities, m/s.
    velocity: Vec<[f64; 3]>,
    /// Measured cylinder accelerations (central differences), m/s^2.
    accel: Vec<[f64; 3]>,
    /// Oil flow taken by the compression of each cylinder's `[head, rod]` chamber (Eq. 2:
    /// `V / beta dp/dt`, the measured pressures' central differences), m^3/s.
    compression: Vec<[[f64; 2]; 3]>,
    /// Cylinder forces holding the links against gravity at the measured angles, N.
    gravity_force: Vec<[f64; 3]>,
    /// Their derivative with respect to a common offset of the three resolvers, N/rad.
    gravity_force_per_rad: Vec<[f64; 3]>,
    /// Reflected cylinder masses, kg.
    mass: Vec<[f64; 3]>,
    /// Soil: measured tip force at zero payload `[fx, fz]` and its change per kg of payload, the
    /// payload volume, the FEE force at nominal soil and its change per Pa of cohesion and per kg/m^3.
    soil: Vec<Option<SoilTerms>>,
    /// Payload: the terms of the weighing samples.
    payload: Vec<Option<PayloadTerms>>,
}

/// The payload terms of one weighing sample: what the payload signal is made of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PayloadTerms {
    /// Soil in the bucket by the replay (the volume cut, up to the capacity), m^3.
    pub volume_m3: f64,
    /// Change of the weighed payload per Pa of a common pressure-sensor offset, kg/Pa.
    pub per_offset_pa: f64,
}

/// The soil terms of one sample (base frame `[x, z]`, N): what the soil signals are made of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SoilTerms {
    /// Measured soil force on the bucket at zero payload (Eqs. A20-A23).
    pub measured0: [f64; 2],
    /// Change of the measured soil force per kg of payload.
    pub measured_per_kg: [f64; 2],
    /// Soil in the bucket (the volume cut less what spilled, up to the capacity), m^3.
    pub payload_volume_m3: f64,
    /// Vertical depth of the edge below the cut surface, m.
    pub depth_m: f64,
    /// Terrain slope at the edge, `tan(alpha)`.
    pub slope_tan: f64,
    /// Modelled soil force at the nominal soil.
    pub fee0: [f64; 2],
    /// Its change per Pa of cohesion.
    pub fee_per_pa: [f64; 2],
    /// Its change per kg/m^3 of density.
    pub fee_per_density: [f64; 2],
}

/// Reflected masses of the cylinders, kg (diagonal of the joint-space inertia over the squared moment
/// arms; links as slender rods, Eq. A1).
fn cylinder_masses(
    kin: &Kinematics,
    cfg: &MachineConfig,
    floor: &[f64; 3],
    q: &JointAngles,
    arms: &Vector3<f64>,
) -> [f64; 3] {
    let p = kin.linkage_points(q);
    let joints = [p.boom_foot, p.stick_pin, p.bucket_pin];
    let abs = [q.boom_rad, q.stick_abs_rad(), q.bucket_abs_rad()];
    let m = &cfg.masses;
    let links = [
        (&m.boom, cfg.links.boom_m),
        (&m.stick, cfg.links.stick_m),
        (&m.bucket, cfg.links.bucket_m),
    ];
    let mut bodies = [Body::default(); 3];
    for (n, (link, length)) in links.iter().enumerate() {
        let c = [
            joints[n][0] + link.cog_distance_m * (abs[n] + link.cog_angle_rad).cos(),
            joints[n][1] + link.cog_distance_m * (abs[n] + link.cog_angle_rad).sin(),
        ];
        bodies[n] = Body {
            link: n,
            mass_kg: link.mass_kg,
            centroid: c,
            own_inertia_kg_m2: link.mass_kg * length * length / 12.0,
        };
    }
    reflected_masses(*floor, &joints, &bodies, arms)
}

/// A rigid body carried by a link (`0` boom, `1` stick, `2` bucket) for the inertia sums of Eq. A1.
#[derive(Debug, Clone, Copy, Default)]
struct Body {
    link: usize,
    mass_kg: f64,
    centroid: [f64; 2],
    own_inertia_kg_m2: f64,
}

/// Reflected mass at each cylinder, kg: the moment of inertia about joint `i` of every body on
/// link `i` or beyond it (`m d^2 + I_own`, Eq. A1), added to `start_kg_m2`, over the cylinder's
/// moment arm squared.
fn reflected_masses(
    start_kg_m2: [f64; 3],
    joints: &[[f64; 2]; 3],
    bodies: &[Body],
    arms: &Vector3<f64>,
) -> [f64; 3] {
    let mut out = start_kg_m2;
    for (i, joint) in joints.iter().enumerate() {
        for b in bodies.iter().filter(|b| b.link >= i) {
            let d2 = (b.centroid[0] - joint[0]).powi(2) + (b.centroid[1] - joint[1]).powi(2);
            out[i] += b.mass_kg * d2 + b.own_inertia_kg_m2;
        }
    }
    [0, 1, 2].map(|i| out[i] / arms[i].powi(2).max(1e-4))
}

fn gravity_forces(kin: &Kinematics, q: &JointAngles) -> Option<[f64; 3]> {
    let f = kin
        .cylinder_forces_from_tip_force(q, &TipForce::default(), 0.0)
        .ok()?;
    Some([f[0], f[1], f[2]])
}

impl PreparedRecord {
    /// Precomputes the kinematic and soil terms of a record.
    ///
    /// # Errors
    /// [`DiscrepancyError`] when the record is invalid or the machine geometry cannot be built.
    pub fn new(record: &DigRecord, cfg: &MachineConfig, params: &GreyBoxParams) -> Result<Self> {
        record.validate()?;
        params.validate()?;
        let kin = Kinematics::new(cfg)?;
        let n = record.samples.len();
        let strokes = Joint::ALL.map(|j| kin.stroke(j));
        let mut velocity = vec![[0.0; 3]; n];
        let mut gravity_force = vec![[f64::NAN; 3]; n];
        let mut gravity_force_per_rad = vec![[0.0; 3]; n];
        let mut mass = vec![[0.0; 3]; n];
        let mut in_stroke = vec![[false; 3]; n];
        let mut chamber_strokes = vec![None; n];
        let mut arms_at = vec![[0.0; 3]; n];
        // The cylinder forces a full bucket of the model's soil adds (the payload is unknown outside
        // the soil: a loaded boom held up short of its top stop needs about 250 kN more than the
        // empty links, which is no push into the stop).
        let mut payload_force = vec![[f64::NAN; 3]; n];
        let full_payload_kg = cfg.bucket.capacity_m3 * params.soil.density_kg_per_m3;
        let stop_angles = Joint::ALL.map(|j| kin.stroke_limited_range(j));
        const D_RAD: f64 = 1e-3;
        for (k, s) in record.samples.iter().enumerate() {
            let q = JointAngles {
                boom_rad: s.angles_rad[0],
                stick_rad: s.angles_rad[1],
                bucket_rad: s.angles_rad[2],
            };
            let Ok(arms) = kin.moment_arms(&q) else {
                continue;
            };
            velocity[k] = [0, 1, 2].map(|i| arms[i] * s.rates_rad_per_s[i]);
            arms_at[k] = [arms[0], arms[1], arms[2]];
            if let Ok(len) = kin.cylinder_lengths(&q) {
                let len = len.to_vector();
                chamber_strokes[k] = Some([len[0], len[1], len[2]]);
                in_stroke[k] = [0, 1, 2].map(|i| {
                    len[i] > strokes[i].0 + STROKE_MARGIN_M
                        && len[i] < strokes[i].1 - STROKE_MARGIN_M
                });
            }
            if let Some(g) = gravity_forces(&kin, &q) {
                gravity_force[k] = g;
                if let Ok(f) =
                    kin.cylinder_forces_from_tip_force(&q, &TipForce::default(), full_payload_kg)
                {
                    payload_force[k] = [0, 1, 2].map(|i| f[i] - g[i]);
                }
                // The true angles are the readings minus the offset: dF/d(offset) = -dF/dq.
                let shifted = JointAngles {
                    boom_rad: q.boom_rad - D_RAD,
                    stick_rad: q.stick_rad - D_RAD,
                    bucket_rad: q.bucket_rad - D_RAD,
                };
                if let Some(g2) = gravity_forces(&kin, &shifted) {
                    gravity_force_per_rad[k] = [0, 1, 2].map(|i| (g2[i] - g[i]) / D_RAD);
                }
            }
            mass[k] = cylinder_masses(&kin, cfg, &params.inertia_floor_kg_m2, &q, &arms);
        }
        let mut accel = vec![[0.0; 3]; n];
        let mut compression = vec![[[0.0; 2]; 3]; n];
        // Central differences over one sample each side: the oil-column oscillations of a stopping
        // link are a few hertz, which wider stencils would attenuate.
        for k in 1..n.saturating_sub(1) {
            let (before, after) = (&record.samples[k - 1], &record.samples[k + 1]);
            let dt = after.time_s - before.time_s;
            if dt > 0.0 {
                accel[k] = [0, 1, 2].map(|i| (velocity[k + 1][i] - velocity[k - 1][i]) / dt);
                // Eq. 2: the chamber volume at the measured stroke, dead volume included.
                if let (true, Some(len)) = (params.chamber_balance, chamber_strokes[k]) {
                    compression[k] = [0, 1, 2].map(|i| {
                        let x = (len[i] - strokes[i].0).clamp(0.0, strokes[i].1 - strokes[i].0);
                        let v_head = params.dead_volume_m3 + params.head_area_m2[i] * x;
                        let v_rod = params.dead_volume_m3
                            + params.rod_area_m2[i] * (strokes[i].1 - strokes[i].0 - x);
                        let dh = (after.head_pa[i] - before.head_pa[i]) / dt;
                        let dr = (after.rod_pa[i] - before.rod_pa[i]) / dt;
                        [
                            v_head / params.bulk_modulus_pa * dh,
                            v_rod / params.bulk_modulus_pa * dr,
                        ]
                    });
                }
            }
        }
        // Samples where a resolver rate disagrees with the angle's own derivative (a link held at an
        // end stop or a bad sensor) are left out; so are the cylinder forces while some cylinder is
        // stalled under a large command (the bucket pushing on the ground or an obstacle).
        let mut consistent = vec![[true; 3]; n];
        let mut stalled = vec![false; n];
        for k in 2..n.saturating_sub(2) {
            let dt = record.samples[k + 2].time_s - record.samples[k - 2].time_s;
            for i in 0..3 {
                let rate = record.samples[k].rates_rad_per_s[i];
                let fd = (record.samples[k + 2].angles_rad[i]
                    - record.samples[k - 2].angles_rad[i])
                    / dt.max(1e-3);
                consistent[k][i] = (rate - fd).abs() < 0.03 + 0.2 * rate.abs();
                if record.samples[k].command[i].abs() > 0.15 && rate.abs() < 0.005 {
                    stalled[k] = true;
                }
            }
        }
        let mut measured = vec![[f64::NAN; N_SIGNALS]; n];
        let warm = warmed_up(&record.samples);
        let mut soil_terms = vec![None; n];
        let mut payload_terms = vec![None; n];
        let mut weighing_since = f64::NAN;
        // The section along the digging plane as the edge leaves it (cut in the Autodig stages, when
        // the bucket is in the digging plane), and the tip of the previous sample.
        let mut cut = record.section.as_ref().and_then(|section| {
            CutSection::new(
                section,
                &record.lanes,
                cfg.bucket.width_m,
                cfg.bucket.capacity_m3,
                params.spill_repose_rad,
            )
        });
        let mut last_tip: Option<[f64; 2]> = None;
        let mut open_for = [0usize; 3];
        for (k, s) in record.samples.iter().enumerate() {
            let q = JointAngles {
                boom_rad: s.angles_rad[0],
                stick_rad: s.angles_rad[1],
                bucket_rad: s.angles_rad[2],
            };
            let pose = kin.forward(&q);
            let tip = [pose.x_m, pose.z_m];
            let rates = Vector3::new(
                s.rates_rad_per_s[0],
                s.rates_rad_per_s[1],
                s.rates_rad_per_s[2],
            );
            let tip_v = kin.jacobian(&q) * rates; // Eq. A3
            let tip_velocity = [tip_v[0], tip_v[1]];
            if let Some(c) = cut.as_mut() {
                if s.stage == super::StageTag::Outside {
                    last_tip = None;
                } else {
                    if let Some(prev) = last_tip {
                        c.cut(prev, tip);
                    }
                    last_tip = Some(tip);
                }
            }
            // After this sample's soil terms, the bucket spills what it cannot hold (on the
            // section, for the samples after it).
            let spill_dt_s = record
                .samples
                .get(k + 1)
                .map_or(0.01, |next| next.time_s - s.time_s);
            let spill = |c: &mut CutSection| {
                if params.spill_pile && s.stage != super::StageTag::Outside {
                    let in_soil = c
                        .motion(tip, pose.bucket_abs_rad, tip_velocity)
                        .is_some_and(|m| m.vertical_depth_m > 0.0);
                    c.spill(tip, pose.bucket_abs_rad, in_soil, spill_dt_s);
                }
            };
            let m = &mut measured[k];
            if !warm[k] {
                if let Some(c) = cut.as_mut() {
                    spill(c);
                }
                continue;
            }
            let all_consistent = consistent[k].iter().all(|c| *c);
            // A chamber above what the main relief lets a pump deliver (cracking plus override) is
            // pressed by its load, and its port relief (set above the main relief to take load
            // shocks) may be passing oil to tank at a rate the model does not know: that cylinder's
            // flow balance says nothing. (Effect-free session none_s200: the stick pulled out at
            // 0.13-0.24 m/s behind its closed spool for a second at a time, rod 37.2-37.6 MPa, head
            // at 0, while the bucket dumped; the balance without the relief flow predicted 0, and
            // the cross-piston leakage `L (p_h - p_r)` was the only term that pointed that way:
            // half of the leakage-like residual that had the nominal model carry 3.1e-12
            // m^3/(s Pa) of leakage the simulator does not have.)
            let pump_limit_pa = params.relief_pa + params.relief_override_pa;
            for i in 0..3 {
                // (effect-free sessions of a simulator with a stiffer soil contact: the bucket
                // pressing into the soil with its head at the pump pressure, 11 % of the Dig samples
                // and half the bucket velocity residual there; the stick hanging on its rod's oil
                // column with the head emptied by leakage.)
                let noisy = load_limited(params, s, i)
                    || (k > 0
                        && k + 1 < n
                        && aliased_zigzag(velocity[k - 1][i], velocity[k][i], velocity[k + 1][i]));
                if in_stroke[k][i]
                    && consistent[k][i]
                    && !noisy
                    && s.head_pa[i].max(s.rod_pa[i]) < pump_limit_pa
                {
                    m[i] = velocity[k][i];
                }
            }
            m[3] = s.pump_pa[0];
            m[4] = s.pump_pa[1];
            // Eq. 3 is used quasi-statically: the oil-column oscillations of a stopping link are
            // faster than 100 Hz sampling resolves, so samples with a large measured acceleration
            // are left out of the force signals.
            let steady = accel[k]
                .iter()
                .all(|a| a.abs() < QUASI_STATIC_ACCEL_M_PER_S2);
            // Only moving cylinders: at rest, dry friction (stiction) holds any force up to its
            // limit and oil trapped behind closed spools keeps whatever pressure it had, so a
            // resting cylinder's force says nothing definite about the model.
            // A cylinder whose valve has been closed within the last SPOOL_OPEN_SAMPLES moves only as
            // the oil column behind the closed spool springs back and forth: its force is then
            // mostly the inertia of that oscillation, which 100 Hz samples do not resolve.
            for i in 0..3 {
                open_for[i] = if s.command[i].abs() > params.overlap {
                    open_for[i] + 1
                } else {
                    0
                };
            }
            // Boom-Down ends when the bucket meets the ground, which then carries part of the
            // links' weight (effect-free sessions: boom force 49 kN measured against 184 kN of
            // gravity there), so it is not free air for the force relation.
            let free_air = s.load == LoadTag::EmptyFreeAir && s.stage != super::StageTag::BoomDown;
            if free_air && all_consistent && !stalled[k] && steady {
                for i in 0..3 {
                    // A chamber reading at the sensor's zero hides its true pressure (anything
                    // up to the magnitude of a negative offset), and with it the force.
                    let readable =
                        s.head_pa[i] > CLAMPED_READING_PA && s.rod_pa[i] > CLAMPED_READING_PA;
                    if in_stroke[k][i]
                        && open_for[i] > SPOOL_OPEN_SAMPLES
                        && readable
                        && gravity_force[k][i].is_finite()
                        && velocity[k][i].abs() > MOVING_SPEED_M_PER_S
                    {
                        m[5 + i] = s.head_pa[i] * params.head_area_m2[i]
                            - s.rod_pa[i] * params.rod_area_m2[i]; // Eq. A20
                    }
                }
            }
            // End stops: a link at rest within STOP_WINDOW_RAD of a stroke-limited end, pressed
            // towards it by far more than its weight and any dry friction could hold (in free air
            // or carrying: neither the ground nor the soil holds it), rests at that end, whose
            // angle the machine geometry fixes; its reading less that angle is the resolver's
            // offset (end-stop calibration). The bucket rests curled at its stop, the oil behind the
            // closed spool at 5-32 MPa, for most of every work cycle.
            if s.load != LoadTag::InSoil && s.stage == super::StageTag::Outside {
                for i in 0..3 {
                    if s.rates_rad_per_s[i].abs() >= STOP_REST_RATE_RAD_PER_S
                        || !gravity_force[k][i].is_finite()
                        || !payload_force[k][i].is_finite()
                    {
                        continue;
                    }
                    let (lo, hi) = stop_angles[i];
                    let a = s.angles_rad[i];
                    let toward = if (a - lo).abs() < STOP_WINDOW_RAD {
                        Some((lo, -1.0))
                    } else if (a - hi).abs() < STOP_WINDOW_RAD {
                        Some((hi, 1.0))
                    } else {
                        None
                    };
                    let Some((end, dir)) = toward else {
                        continue;
                    };
                    // Virtual work: the joint torque of a cylinder force is the force times the
                    // moment arm (dL/dq).
                    let excess = s.head_pa[i] * params.head_area_m2[i]
                        - s.rod_pa[i] * params.rod_area_m2[i]
                        - gravity_force[k][i];
                    // Both in the direction of the end (`sign(dL/dq) dir` positive); a payload
                    // held in that direction could be what the cylinder pushes against.
                    let towards = arms_at[k][i].signum() * dir;
                    let payload = (payload_force[k][i] * towards).max(0.0);
                    if excess * towards > STOP_PRESS_FORCE_N + payload {
                        m[Signal::StopAngle.index()] = a - end;
                    }
                }
            }
            // The payload, weighed as the controller does: valves neutral, the implement held up,
            // the settling time after the valves closed, each cylinder away from its stroke ends.
            let neutral = s
                .command
                .iter()
                .chain([&s.swing_command])
                .all(|u| u.abs() <= params.overlap);
            if s.load != LoadTag::Weighing {
                weighing_since = f64::NAN;
            } else if weighing_since.is_nan() || !neutral {
                weighing_since = s.time_s;
            }
            if s.time_s - weighing_since >= WEIGH_SETTLE_S
                && neutral
                && let (Some(len), Some(c)) = (chamber_strokes[k], cut.as_ref())
                && let Some((mass_kg, per_offset_pa)) = weighed_payload(
                    &kin,
                    params,
                    s,
                    &q,
                    &arms_at[k],
                    &len,
                    &strokes,
                    (mass[k], weigh_accel(&velocity, &record.samples, k)),
                )
            {
                let volume_m3 = c.content_m3().clamp(0.0, cfg.bucket.capacity_m3);
                // A full bucket only: it holds its capacity, which the cut volume beyond it does not
                // change. A part-filled one holds what the cut put in less what poured out as it
                // left the soil with its opening tipped down, which this replay does not follow
                // (the 40 kPa cohesion sessions, 0.3-0.6 m^3 cut: 450-690 kg weighed against
                // 570-900 kg for the cut volume).
                if volume_m3 >= WEIGH_MIN_FILL * cfg.bucket.capacity_m3 {
                    m[Signal::PayloadMass.index()] = mass_kg;
                    payload_terms[k] = Some(PayloadTerms {
                        volume_m3,
                        per_offset_pa,
                    });
                }
            }
            // The soil signals in the Dig stage: in the PreDig penetration the bearing resistance
            // dominates, which switches with the direction of the edge's motion at the creep speed
            // and so hangs on the noise of the measured rates; in Capture the full bucket spills
            // around its edge and the edge chatters over that pile, a terrain the replay does not
            // rebuild (effect-free sessions none_s200-203: Capture residual 31-35 kN RMS in x with
            // a +8-9 kN mean in z, against 8-10 kN RMS and +-2 kN in Dig; docs/discrepancy.md,
            // 2026-11-22 and 2026-11-25 soil effects).
            let cutting = s.stage == super::StageTag::Dig;
            if let (true, true, Some(section)) = (cutting, all_consistent, &cut) {
                soil_terms[k] = soil_terms_of(
                    &kin,
                    cfg,
                    params,
                    s,
                    section,
                    tip_velocity,
                    velocity[k],
                    accel[k],
                    mass[k],
                );
                if let Some(t) = soil_terms[k] {
                    let payload = t.payload_volume_m3 * params.soil.density_kg_per_m3;
                    m[8] = t.measured0[0] + payload * t.measured_per_kg[0];
                    m[9] = t.measured0[1] + payload * t.measured_per_kg[1];
                }
            }
            if let Some(c) = cut.as_mut() {
                spill(c);
            }
        }
        // A weighing that lifts the bucket and weighs again (the controller found it carried by the
        // ground) weighed the ground before the lift: those samples are out. (The last sample of a
        // weighing carries the first command of the swing to the dump, which is no lift.)
        let (mut lift_follows, mut weighed_after) = (false, false);
        for k in (0..n).rev() {
            let s = &record.samples[k];
            if s.load != LoadTag::Weighing {
                (lift_follows, weighed_after) = (false, false);
            } else if s.command.iter().any(|u| u.abs() > params.overlap) {
                lift_follows |= weighed_after;
            } else {
                weighed_after = true;
                if lift_follows {
                    measured[k][Signal::PayloadMass.index()] = f64::NAN;
                    payload_terms[k] = None;
                }
            }
        }
        // The force relation's inertia term takes the accelerations over +-0.05 s: a one-sample
        // difference turns the resolver-rate noise (3 mm/s) into 0.2 m/s^2, 30 kN on the boom's
        // reflected mass, in a measured force that is smooth (effect-free sessions, boom lifting:
        // held-out boom force RMS 30.7 -> 5.8 kN, stick 2.7 -> 1.0 kN). The soil force keeps the
        // one-sample difference (the soil terms above): there the +-0.05 s one lost both 10 kPa
        // cohesion sessions (the bucket's motion in the cut changes within 0.05 s).
        let accel = (0..n)
            .map(|k| weigh_accel(&velocity, &record.samples, k))
            .collect();
        // The velocity signals are compared through the prefilter (the replay filters its
        // predictions the same way); which samples the relation predicts is decided on the raw ones.
        let velocity_gate = measured
            .iter()
            .map(|m| [0, 1, 2].map(|i| m[i].is_finite()))
            .collect();
        prefilter_velocities(&mut measured);
        Ok(Self {
            index: record.index,
            samples: record.samples.clone(),
            measured,
            velocity_gate,
            velocity,
            accel,
            compression,
            gravity_force,
            gravity_force_per_rad,
            mass,
            soil: soil_terms,
            payload: payload_terms,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// The soil terms of every sample (`None` outside the soil signals).
    pub fn soil_terms(&self) -> &[Option<SoilTerms>] {
        &self.soil
    }

    /// True for a record without samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

/// Slowest tip speed at which a sample enters the soil signals, m/s: the soil force builds up from
/// rest over the creep speed (1 cm/s), so below a few times it the force hangs on the speed itself;
/// a stalled bucket's force is that of whatever holds it.
const SOIL_MOVING_SPEED_M_PER_S: f64 = 0.05;

/// Radius of gyration of the payload about its own centroid, m (`0.05 m^2` per kg, the simulator's
/// value: a heap of soil about a metre across).
const PAYLOAD_GYRATION_M: f64 = 0.2236;

/// Uncertainty of the replay's terrain slope `tan(alpha)` at the edge (the section's 0.1 m medians
/// cut by the measured edge path, differenced over +-[`soil_replay::SLOPE_HALF_BASE_M`]).
const SLOPE_TRUST_TAN: f64 = 0.1;

/// Largest change of the modelled soil force (either component) that an error of
/// [`SLOPE_TRUST_TAN`] in the slope may make for a sample to enter the soil signals, N: about the
/// relation's own residual RMS in the Dig stage of the effect-free sessions (8-10 kN).
const SLOPE_SENSITIVITY_N: f64 = 1.0e4;

/// Time the controller's Weigh lets the implement settle before it averages, s (the work cycle's
/// `weigh_settle_s` default): the oil columns ring for a while after the valves close.
const WEIGH_SETTLE_S: f64 = 0.8;

/// Half width of the central difference of the cylinder velocities that gives the accelerations of
/// the weighing, samples: the implement's oscillation while it is weighed is about 1.5 Hz, which a
/// difference over +-0.05 s keeps (sin(0.47)/0.47 = 0.96) while it averages out the rate noise that a
/// one-sample difference amplifies (per-sample payload scatter 116-476 kg against 400 kg with it).
const WEIGH_ACCEL_HALF_SAMPLES: usize = 5;

/// Cylinder accelerations at sample `k` for the weighing (see [`WEIGH_ACCEL_HALF_SAMPLES`]), m/s^2.
fn weigh_accel(velocity: &[[f64; 3]], samples: &[super::Sample], k: usize) -> [f64; 3] {
    let h = WEIGH_ACCEL_HALF_SAMPLES;
    let (Some(lo), hi) = (k.checked_sub(h), k + h) else {
        return [0.0; 3];
    };
    if hi >= samples.len() {
        return [0.0; 3];
    }
    let dt = samples[hi].time_s - samples[lo].time_s;
    if dt <= 0.0 {
        return [0.0; 3];
    }
    [0, 1, 2].map(|i| (velocity[hi][i] - velocity[lo][i]) / dt)
}

/// Smallest bucket fill (fraction of the capacity, by the replay's cut volume) that is weighed.
const WEIGH_MIN_FILL: f64 = 0.95;

/// Fraction of a cylinder's stroke at either end within which it does not take part in the weighing
/// (the controller's `weigh_stroke_end_margin`): a cylinder on its end stop carries an unknown force.
const WEIGH_STROKE_END_MARGIN: f64 = 0.01;

/// The payload estimate of one sample, kg, and its change per Pa of a common pressure offset: the
/// least-squares mass `m` of `tau - M acc - g0 = m (a + r b acc)` over the cylinders away from their
/// stroke ends (`tau` the joint torques of the Eq. A20 forces, Eqs. A21-A22; `M acc` the links'
/// reflected inertia; `g0` the links' gravity torques and `a` the gravity torque per kg of payload at
/// its centroid, Eq. A19; `r b acc` the payload's own inertia per kg, Eq. A1 with the payload as a
/// body). The controller weighs statically and averages over whole periods of the implement's
/// oscillation on its oil columns (about 1.5 Hz, +-40 % of the payload); per sample, the inertia
/// takes that oscillation out.
#[allow(clippy::too_many_arguments)]
fn weighed_payload(
    kin: &Kinematics,
    params: &GreyBoxParams,
    s: &super::Sample,
    q: &JointAngles,
    arms: &[f64; 3],
    len: &[f64; 3],
    strokes: &[(f64, f64); 3],
    (mass, accel): ([f64; 3], [f64; 3]),
) -> Option<(f64, f64)> {
    let g0 = kin.gravity_torques(q, 0.0);
    let a = kin.gravity_torques(q, 1.0) - g0;
    let per_kg = payload_reflected_mass_per_kg(kin, q)?;
    let usable = [0, 1, 2].map(|i| {
        let (lo, hi) = strokes[i];
        let e = (len[i] - lo) / (hi - lo);
        e > WEIGH_STROKE_END_MARGIN && e < 1.0 - WEIGH_STROKE_END_MARGIN
    });
    let regressor = [0, 1, 2].map(|i| a[i] + arms[i] * per_kg[i] * accel[i]);
    let excess = [0, 1, 2].map(|i| {
        let force = s.head_pa[i] * params.head_area_m2[i] - s.rod_pa[i] * params.rod_area_m2[i]; // Eq. A20
        arms[i] * (force - mass[i] * accel[i]) - g0[i]
    });
    // A common offset adds `(A_h - A_r) offset` to every force (A20).
    let per_pa_torque =
        [0, 1, 2].map(|i| arms[i] * (params.head_area_m2[i] - params.rod_area_m2[i]));
    let m = payload_least_squares(&regressor, &excess, usable)?;
    let per_pa = payload_least_squares(&regressor, &per_pa_torque, usable)?;
    Some((m, per_pa))
}

/// Reflected mass of one kilogram of payload at each cylinder, kg/kg: `(d_i^2 + k^2) / r_i^2`, `d_i`
/// the distance of the payload centroid from joint `i`, `k` its radius of gyration, `r_i` the
/// cylinder's moment arm (Eq. A1 with the payload as one more body, as [`cylinder_masses`] treats
/// the links). `None` at a singular pose.
fn payload_reflected_mass_per_kg(kin: &Kinematics, q: &JointAngles) -> Option<[f64; 3]> {
    let arms = kin.moment_arms(q).ok()?;
    let p = kin.linkage_points(q);
    let payload = Body {
        link: 2,
        mass_kg: 1.0,
        centroid: kin.payload_centroid(q),
        own_inertia_kg_m2: PAYLOAD_GYRATION_M * PAYLOAD_GYRATION_M,
    };
    Some(reflected_masses(
        [0.0; 3],
        &[p.boom_foot, p.stick_pin, p.bucket_pin],
        &[payload],
        &arms,
    ))
}

/// The soil terms of one sample: the measured tip force (Eqs. A20-A23 from the pressures, less
/// inertia and seal damping) at zero payload and per kg of payload, and the modelled soil force
/// ([`soil_replay`]) on the section cut so far, at nominal soil and per unit of cohesion and density
/// (the force is affine in both: Eqs. 14-17 and the bearing pressure are linear in `c` and `gamma`).
#[allow(clippy::too_many_arguments)]
fn soil_terms_of(
    kin: &Kinematics,
    cfg: &MachineConfig,
    params: &GreyBoxParams,
    s: &super::Sample,
    section: &CutSection,
    tip_velocity: [f64; 2],
    velocity: [f64; 3],
    accel: [f64; 3],
    mass: [f64; 3],
) -> Option<SoilTerms> {
    let q = JointAngles {
        boom_rad: s.angles_rad[0],
        stick_rad: s.angles_rad[1],
        bucket_rad: s.angles_rad[2],
    };
    let pose = kin.forward(&q);
    if tip_velocity[0].hypot(tip_velocity[1]) < SOIL_MOVING_SPEED_M_PER_S {
        return None;
    }
    let width = cfg.bucket.width_m;
    // What the bucket holds: the volume cut from the terrain less what spilled (at most the
    // capacity; the spill is on the section).
    let volume = section.content_m3().clamp(0.0, cfg.bucket.capacity_m3);
    let motion = section.motion([pose.x_m, pose.z_m], pose.bucket_abs_rad, tip_velocity)?;
    if motion.vertical_depth_m <= 0.0 {
        return None;
    }
    // Measured soil force: Eq. A20 forces less inertia and seal damping, then Eq. A23.
    let forces = Vector3::from_fn(|i, _| {
        s.head_pa[i] * params.head_area_m2[i]
            - s.rod_pa[i] * params.rod_area_m2[i]
            - mass[i] * accel[i]
            - params.damping_n_s_per_m * velocity[i]
    });
    // The payload moves with the bucket: its inertia adds to every joint's (Eq. A1 with the payload
    // as a body at its centroid), so a loaded cylinder needs `m_p (d^2 + k^2) / r^2 a` more force
    // to accelerate, linear in the payload like its weight. Without it the inertia subtracted in
    // the Dig stage was short by the payload's part (the boom's reflected mass is about 0.5e6 kg
    // and its mean `M a` over the stage about -47 kN in the effect-free session none_s200), which
    // biased the measured soil force by -2.6 / +2.6 kN (x / z), like a soil 300 kg/m^3 lighter
    // (docs/discrepancy.md, 2026-11-25 soil effects).
    let per_kg = payload_reflected_mass_per_kg(kin, &q)?;
    let loaded = Vector3::from_fn(|i, _| forces[i] - 1000.0 * per_kg[i] * accel[i]);
    let f0 = kin.tip_force_from_cylinder_forces(&q, &forces, 0.0).ok()?;
    let f1 = kin
        .tip_force_from_cylinder_forces(&q, &loaded, 1000.0)
        .ok()?;
    let force =
        |psi: &SoilProperties| soil_replay::soil_force(psi, &params.bearing, width, &motion);
    let base = force(&params.soil)?;
    // Only where the replay's terrain is good enough for the force: near the wedge limit Eq. 17's
    // slope terms make the force steep in the slope at the edge, which the replay knows to about
    // SLOPE_TRUST_TAN (effect-free sessions: residuals of -16 to -53 kN where the modelled force
    // rose fastest with density, on the flatter faces, against +-2 kN elsewhere).
    for d in [-SLOPE_TRUST_TAN, SLOPE_TRUST_TAN] {
        let mut tilted = motion;
        tilted.slope_tan += d;
        let g = soil_replay::soil_force(&params.soil, &params.bearing, width, &tilted)?;
        if (g[0] - base[0]).abs().max((g[1] - base[1]).abs()) > SLOPE_SENSITIVITY_N {
            return None;
        }
    }
    let mut more_c = params.soil;
    more_c.cohesion_pa += 1000.0;
    let mut more_gamma = params.soil;
    more_gamma.density_kg_per_m3 += 100.0;
    let fc = force(&more_c)?;
    let fg = force(&more_gamma)?;
    let k = params.soil_force_factor;
    let out = SoilTerms {
        measured0: [f0.fx_n, f0.fz_n],
        measured_per_kg: [(f1.fx_n - f0.fx_n) / 1000.0, (f1.fz_n - f0.fz_n) / 1000.0],
        payload_volume_m3: volume,
        depth_m: motion.vertical_depth_m,
        slope_tan: motion.slope_tan,
        fee0: [k * base[0], k * base[1]],
        fee_per_pa: [
            k * (fc[0] - base[0]) / 1000.0,
            k * (fc[1] - base[1]) / 1000.0,
        ],
        fee_per_density: [k * (fg[0] - base[0]) / 100.0, k * (fg[1] - base[1]) / 100.0],
    };
    let all = out
        .measured0
        .iter()
        .chain(&out.measured_per_kg)
        .chain(&out.fee0)
        .chain(&out.fee_per_pa)
        .chain(&out.fee_per_density)
        .all(|v| v.is_finite());
    all.then_some(out)
}

/// Spool positions `[boom, stick, bucket, swing]` at every sample of a record: dead band, delay and lag
/// (nominal and augmented) integrated at 1 ms over the zero-order-held commands.
pub fn spools(
    samples: &[super::Sample],
    params: &GreyBoxParams,
    aug: &Augmentation,
) -> Vec<[f64; 4]> {
    use super::Candidate as C;
    let n = samples.len();
    let deadband = aug.get(C::ValveDeadband).max(0.0);
    let band = |u: f64| {
        let u = u.clamp(-1.0, 1.0);
        u.signum() * (u.abs() - deadband).max(0.0)
    };
    let cmd: Vec<[f64; 4]> = samples
        .iter()
        .map(|s| {
            [
                band(s.command[0]),
                band(s.command[1]),
                band(s.command[2]),
                band(s.swing_command),
            ]
        })
        .collect();
    let delay_ms =
        ((params.transport_delay_s + aug.get(C::TransportDelay).max(0.0)) / SPOOL_DT_S).max(0.0);
    let d0 = delay_ms.floor() as usize;
    let frac = delay_ms - d0 as f64;
    // Command in force during 1 ms step j (sample j / 10 holds it); before the record: the first one.
    let at = |j: isize| -> [f64; 4] {
        if j < 0 {
            cmd[0]
        } else {
            cmd[((j as usize) / SUBSTEPS).min(n - 1)]
        }
    };
    let tau = params.lag_time_constant_s.max(SPOOL_DT_S);
    let extra = aug.get(C::HydraulicLag).max(0.0);
    let a1 = (SPOOL_DT_S / tau).min(1.0);
    let a2 = if extra > 0.0 {
        (SPOOL_DT_S / extra).min(1.0)
    } else {
        1.0
    };
    let mut s1 = at(-(d0 as isize) - 1);
    let mut s2 = s1;
    let mut out = vec![[0.0; 4]; n];
    if n == 0 {
        return out;
    }
    out[0] = s2;
    for (k, slot) in out.iter_mut().enumerate().skip(1) {
        for sub in 0..SUBSTEPS {
            let j = ((k - 1) * SUBSTEPS + sub) as isize;
            let c0 = at(j - d0 as isize);
            let c1 = at(j - d0 as isize - 1);
            for a in 0..4 {
                let target = c0[a] + frac * (c1[a] - c0[a]);
                s1[a] += (target - s1[a]) * a1;
                s2[a] += (s1[a] - s2[a]) * a2;
            }
        }
        *slot = s2;
    }
    out
}

/// Laminar-regularised orifice flow (Eq. 1) for a constant `k = Cd A sqrt(2/rho)`, positive for `dp > 0`.
#[inline]
fn orifice(k: f64, dp: f64, laminar_dp_pa: f64) -> f64 {
    if k <= 0.0 {
        0.0
    } else if dp.abs() < laminar_dp_pa {
        k * dp / laminar_dp_pa.sqrt()
    } else {
        k * dp.abs().sqrt() * dp.signum()
    }
}

fn metering(params: &GreyBoxParams, spool: f64) -> f64 {
    ((spool.abs() - params.overlap) / (1.0 - params.overlap)).clamp(0.0, 1.0)
}

fn bypass_fraction(params: &GreyBoxParams, spool: f64) -> f64 {
    (1.0 - spool.abs() / params.bypass_close).clamp(0.0, 1.0)
}

fn crossover_fraction(params: &GreyBoxParams, boom_spool: f64) -> f64 {
    ((boom_spool.abs() - params.crossover_start) / (params.crossover_full - params.crossover_start))
        .clamp(0.0, 1.0)
}

/// Series bypass constant of the valves `fractions` (1/k^2 = sum 1/k_i^2), zero if one is closed.
fn series_bypass(k: f64, fractions: &[f64]) -> f64 {
    let mut inv = 0.0;
    for f in fractions {
        if *f <= 0.0 {
            return 0.0;
        }
        inv += 1.0 / (k * f).powi(2);
    }
    if inv > 0.0 { inv.sqrt().recip() } else { 0.0 }
}

/// Whether cylinder `i`'s velocity relation is noise-dominated at sample `s`: its valve open, its
/// inlet reading within [`NOISY_INLET_DP_PA`] of its supply either way (the load, not the valve,
/// limits the flow, `cylinder_velocity` weights the meter-in estimate out, and the load check is
/// not clearly shut either: an inlet well above its supply is a dead end whose own balance gives
/// the speed) and its outlet within
/// [`NOISY_OUTLET_DP_PA`] of tank, so neither metering orifice's drop is known better than the
/// reading noise.
fn load_limited(params: &GreyBoxParams, s: &super::Sample, i: usize) -> bool {
    let u = s.command[i];
    let (p_in, p_out) = if u > 0.0 {
        (s.head_pa[i], s.rod_pa[i])
    } else {
        (s.rod_pa[i], s.head_pa[i])
    };
    // The boom also takes pump 2's flow through the crossover; the stick is on pump 2.
    let supply = match i {
        0 => s.pump_pa[0].max(s.pump_pa[1]),
        1 => s.pump_pa[1],
        _ => s.pump_pa[0],
    };
    u.abs() > params.overlap
        && (supply - p_in).abs() < NOISY_INLET_DP_PA
        && p_out - params.tank_pa < NOISY_OUTLET_DP_PA
}

/// Whether a measured velocity zig-zags (`before -> now -> after`) by more than
/// [`ALIASED_ZIGZAG_M_PER_S`] each way: an oscillation at the sampling's Nyquist rate.
fn aliased_zigzag(before: f64, now: f64, after: f64) -> bool {
    let (back, ahead) = (now - before, after - now);
    back.abs() > ALIASED_ZIGZAG_M_PER_S
        && ahead.abs() > ALIASED_ZIGZAG_M_PER_S
        && back * ahead < 0.0
}

/// Cylinder velocity from the two metering orifices and the measured pressures (Eq. 1, continuity).
#[allow(clippy::too_many_arguments)]
fn cylinder_velocity(
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
struct PumpBalance {
    /// Maximum pump flow, m^3/s.
    max_flow: f64,
    /// Open-centre bypass constant, m^3/(s sqrt(Pa)).
    bypass_k: f64,
    /// Flow taken regardless of the pressure (the swing motor), m^3/s.
    fixed_demand: f64,
}

/// The last gallery pressure solved with every metering orifice of a pump closed: then the balance
/// depends on the pump terms alone, the same at every sample of a record where the pump only
/// bypasses (idle, scans, swinging with the arm at rest), so one solve serves them all.
#[derive(Debug, Clone, Copy, Default)]
struct NeutralCache {
    last: Option<(PumpBalance, f64)>,
}

impl NeutralCache {
    fn solve(
        &mut self,
        params: &GreyBoxParams,
        b: PumpBalance,
        meter_in: &[(f64, f64)],
        guess_pa: f64,
    ) -> f64 {
        if meter_in.iter().any(|(k, _)| *k > 0.0) {
            return pump_pressure(params, b, meter_in, guess_pa);
        }
        if let Some((key, p)) = self.last
            && key == b
        {
            return p;
        }
        let p = pump_pressure(params, b, &[], guess_pa);
        self.last = Some((b, p));
        p
    }
}

/// Gallery pressure of one pump from its flow balance, solved by regula falsi (the balance falls
/// monotonically with the pressure, so the root is unique), starting from a bracket around
/// `guess_pa` (the measured pump pressure: a few evaluations instead of a dozen).
fn pump_pressure(
    params: &GreyBoxParams,
    b: PumpBalance,
    meter_in: &[(f64, f64)],
    guess_pa: f64,
) -> f64 {
    let lam = params.laminar_dp_pa;
    let tank = params.tank_pa;
    let relief_slope = params.pump_max_flow_m3_per_s / params.relief_override_pa;
    let balance = |p: f64| {
        let mut f = b.max_flow.min(params.pump_power_w / p.max(1.0)) - b.fixed_demand;
        f -= orifice(b.bypass_k, p - tank, lam);
        for (k, p_in) in meter_in {
            if p > *p_in {
                f -= orifice(*k, p - p_in, lam);
            }
        }
        if p > params.relief_pa {
            f -= relief_slope * (p - params.relief_pa);
        }
        f
    };
    let top = params.relief_pa + 20.0 * params.relief_override_pa;
    let f_tank = balance(tank);
    if f_tank <= 0.0 {
        return tank;
    }
    // Bracket: grow a window around the guess until the balance changes sign in it.
    let guess = if guess_pa.is_finite() {
        guess_pa.clamp(tank, top)
    } else {
        0.5 * (tank + top)
    };
    let mut step = 2.5e5;
    let (mut lo, mut hi) = ((guess - step).max(tank), (guess + step).min(top));
    let (mut f_lo, mut f_hi) = (if lo <= tank { f_tank } else { balance(lo) }, balance(hi));
    while f_lo <= 0.0 || f_hi > 0.0 {
        step *= 4.0;
        if f_lo <= 0.0 {
            hi = lo;
            f_hi = f_lo;
            lo = (lo - step).max(tank);
            f_lo = if lo <= tank { f_tank } else { balance(lo) };
        } else {
            if hi >= top {
                return top;
            }
            lo = hi;
            f_lo = f_hi;
            hi = (hi + step).min(top);
            f_hi = balance(hi);
        }
    }
    // Regula falsi with the Illinois modification: a few evaluations to 1 kPa.
    let mut side = 0;
    for _ in 0..60 {
        if hi - lo < 1.0e3 {
            break;
        }
        let p = (lo * (-f_hi) + hi * f_lo) / (f_lo - f_hi);
        let f = balance(p);
        if f == 0.0 {
            return p;
        }
        if f > 0.0 {
            lo = p;
            f_lo = f;
            if side == 1 {
                f_hi *= 0.5;
            }
            side = 1;
        } else {
            hi = p;
            f_hi = f;
            if side == -1 {
                f_lo *= 0.5;
            }
            side = -1;
        }
    }
    0.5 * (lo + hi)
}

/// Which groups of signals a replay must recompute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignalGroups {
    /// Cylinder velocities.
    pub hydraulic: bool,
    /// Pump pressures.
    pub pumps: bool,
    /// Cylinder forces.
    pub force: bool,
    /// Soil forces.
    pub soil: bool,
    /// End-stop angles.
    pub stops: bool,
    /// Payload mass at the weighing.
    pub payload: bool,
}

impl SignalGroups {
    /// Every group.
    pub const ALL: SignalGroups = SignalGroups {
        hydraulic: true,
        pumps: true,
        force: true,
        soil: true,
        stops: true,
        payload: true,
    };

    /// Whether the group of signal index `s` is among these.
    pub fn contains(&self, s: usize) -> bool {
        match s {
            0..=2 => self.hydraulic,
            3..=4 => self.pumps,
            5..=7 => self.force,
            8..=9 => self.soil,
            10 => self.stops,
            _ => self.payload,
        }
    }
}

/// Replays a prepared record through the (augmented) grey-box model: the predicted value of every
/// signal at every sample (NaN where the measured one is undefined). Only the `groups` are computed;
/// the others are copied from `out` as it was (a cache of an earlier replay) or left NaN.
pub fn replay(
    rec: &PreparedRecord,
    params: &GreyBoxParams,
    aug: &Augmentation,
    groups: SignalGroups,
    out: &mut Vec<[f64; N_SIGNALS]>,
) {
    use super::Candidate as C;
    let n = rec.len();
    if out.len() != n {
        out.clear();
        out.resize(n, [f64::NAN; N_SIGNALS]);
    }
    let offset = aug.get(C::PressureSensorOffset);
    let resolver = aug.get(C::ResolverOffset);
    let leak = params.internal_leakage_m3_per_s_pa + aug.get(C::InternalLeakage).max(0.0);
    let sharing = aug.get(C::FlowSharing).clamp(0.0, 1.0);
    let max_flow =
        params.pump_max_flow_m3_per_s * (1.0 - aug.get(C::PumpSaturation)).clamp(0.0, 1.0);
    let coulomb = aug.get(C::CoulombFriction).max(0.0);
    let viscous = params.damping_n_s_per_m + aug.get(C::ViscousFriction).max(0.0);
    let cohesion = aug.get(C::SoilCohesion);
    let density = aug.get(C::SoilDensity);
    let spool = if groups.hydraulic || groups.pumps {
        spools(&rec.samples, params, aug)
    } else {
        Vec::new()
    };
    let mut neutral = [NeutralCache::default(); 2];
    for k in 0..n {
        let m = &rec.measured[k];
        let o = &mut out[k];
        for s in 0..N_SIGNALS {
            if groups.contains(s) {
                o[s] = f64::NAN;
            }
        }
        if k < WARMUP_SAMPLES {
            continue;
        }
        let smp = &rec.samples[k];
        // The model sees the true pressures: readings less the sensor offset. A reading clamped at
        // the sensor's zero by a negative offset hides the true value; it is a chamber at tank.
        let tank = params.tank_pa;
        let true_pa = |p: f64| {
            if offset < 0.0 && p <= CLAMPED_READING_PA {
                tank
            } else {
                p - offset
            }
        };
        let head = smp.head_pa.map(true_pa);
        let rod = smp.rod_pa.map(true_pa);
        let pump = smp.pump_pa.map(true_pa);
        let sp = if groups.hydraulic || groups.pumps {
            spool[k]
        } else {
            [0.0; 4]
        };
        let share = (1.0 - sharing * sp[2].abs()).clamp(0.0, 1.0);
        let xfrac = crossover_fraction(params, sp[0]);
        if groups.hydraulic {
            for i in 0..3 {
                if !rec.velocity_gate[k][i] {
                    continue;
                }
                let gallery = pump[if i == 1 { 1 } else { 0 }];
                let cross =
                    (i == 0 && xfrac > 0.0).then_some((params.crossover_k * xfrac, pump[1]));
                o[i] = cylinder_velocity(
                    params,
                    i,
                    sp[i],
                    if i == 0 { share } else { 1.0 },
                    head[i],
                    rod[i],
                    gallery,
                    cross,
                    leak,
                    rec.compression[k][i],
                    [
                        smp.head_pa[i] <= CLAMPED_READING_PA,
                        smp.rod_pa[i] <= CLAMPED_READING_PA,
                    ],
                );
            }
        }
        if groups.pumps {
            let inlet = |i: usize| if sp[i] >= 0.0 { head[i] } else { rod[i] };
            // Pump 1: boom and bucket; its bypass runs through both sections.
            let bypass1 = series_bypass(
                params.bypass_k,
                &[
                    bypass_fraction(params, sp[0]),
                    bypass_fraction(params, sp[2]),
                ],
            );
            let meter1 = [
                (
                    params.meter_in_k[0] * metering(params, sp[0]) * share,
                    inlet(0),
                ),
                (params.meter_in_k[2] * metering(params, sp[2]), inlet(2)),
            ];
            let balance1 = PumpBalance {
                max_flow,
                bypass_k: bypass1,
                fixed_demand: 0.0,
            };
            o[3] = (neutral[0].solve(params, balance1, &meter1, pump[0]) + offset).max(0.0);
            // Pump 2: stick and swing, and the crossover to the boom (its spool closes the centre).
            let fractions = [
                bypass_fraction(params, sp[1]),
                bypass_fraction(params, sp[3]),
                1.0 - xfrac,
            ];
            let bypass2 = series_bypass(
                params.bypass_k,
                &fractions[..if xfrac > 0.0 { 3 } else { 2 }],
            );
            let swing_flow = if metering(params, sp[3]) > 0.0 {
                params.swing_displacement_m3_per_rad * smp.swing_rate_rad_per_s.abs()
            } else {
                0.0
            };
            let meter2 = [
                (params.meter_in_k[1] * metering(params, sp[1]), inlet(1)),
                (params.crossover_k * xfrac, inlet(0)),
            ];
            let balance2 = PumpBalance {
                max_flow,
                bypass_k: bypass2,
                fixed_demand: swing_flow,
            };
            o[4] = (neutral[1].solve(params, balance2, &meter2, pump[1]) + offset).max(0.0);
        }
        if groups.force {
            for i in 0..3 {
                if m[5 + i].is_nan() {
                    continue;
                }
                let v = rec.velocity[k][i];
                // What the offset adds to the Eq. A20 force of the readings; a clamped chamber
                // reads zero instead of tank.
                let chamber = |reading: f64| {
                    if offset < 0.0 && reading <= CLAMPED_READING_PA {
                        -tank
                    } else {
                        offset
                    }
                };
                let sensor = params.head_area_m2[i] * chamber(smp.head_pa[i])
                    - params.rod_area_m2[i] * chamber(smp.rod_pa[i]);
                // Eq. 3 at the measured motion; the true angles are the readings less the offset.
                let mut f = rec.gravity_force[k][i]
                    + resolver * rec.gravity_force_per_rad[k][i]
                    + rec.mass[k][i] * rec.accel[k][i]
                    + viscous * v;
                // Dry friction opposes the motion. At rest (stiction) it takes an unknown value
                // within its limit; the prediction keeps none there rather than the one that fits
                // the measurement, which would reward any larger magnitude on the rest samples.
                if coulomb > 0.0 && v.abs() > REST_SPEED_M_PER_S {
                    f += coulomb * v.signum();
                }
                o[5 + i] = f + sensor;
            }
        }
        // End stops: the reading of a link at its stop is the stop's angle plus the offset.
        if groups.payload
            && let Some(t) = rec.payload[k]
        {
            o[Signal::PayloadMass.index()] =
                t.volume_m3 * (params.soil.density_kg_per_m3 + density) + offset * t.per_offset_pa;
        }
        if groups.stops && m[Signal::StopAngle.index()].is_finite() {
            o[Signal::StopAngle.index()] = resolver;
        }
        if groups.soil
            && let Some(t) = rec.soil[k]
        {
            let payload_shift = t.payload_volume_m3 * density;
            for a in 0..2 {
                // The measured force is computed with the nominal payload; a denser soil makes the
                // payload heavier, which the model carries on the prediction side.
                o[8 + a] = t.fee0[a] + cohesion * t.fee_per_pa[a] + density * t.fee_per_density[a]
                    - payload_shift * t.measured_per_kg[a];
            }
        }
    }
    if groups.hydraulic {
        prefilter_velocities(out);
    }
}

/// Half width of the velocity signals' prefilter, samples: a centred moving average over
/// `2 h + 1 = 5` samples (50 ms; -3 dB at 9 Hz, first zero at 20 Hz).
pub const VELOCITY_PREFILTER_HALF: usize = 2;

/// Prefilters the velocity signals (the first three) in place: each becomes the centred moving
/// average over `2 VELOCITY_PREFILTER_HALF + 1` samples, NaN unless every sample of the window is
/// defined. Measurement and prediction go through the same linear filter, so their difference is
/// the prefiltered prediction error (Ljung, System Identification, 7.3: the prefilter weights the
/// error to the band where the model is meant to hold). The velocity relation (Eqs. 1-2) is
/// quasi-static, meant for what 100 Hz samples resolve of the oil flow; above about 10 Hz the
/// measured rate is the rate sensor's white noise (2e-3 rad/s, 3-4 mm/s of cylinder speed at rest
/// in every session) and the oil columns' aliased oscillations, which no candidate effect predicts.
/// Unfiltered, that noise floor was most of the residual an augmented model left (session
/// internal_leakage_1e-11: held-out stick velocity RMS 8.3 -> 5.0 mm/s raw, 6.2 -> 1.9 mm/s
/// through this filter; docs/discrepancy.md).
pub fn prefilter_velocities(series: &mut [[f64; N_SIGNALS]]) {
    const H: usize = VELOCITY_PREFILTER_HALF;
    const W: usize = 2 * H + 1;
    let n = series.len();
    for i in 0..3 {
        // In place (the replay runs this on every candidate evaluation): the raw values of the
        // window `k - H ..= k + H` in a ring, the ones before `k` already overwritten in `series`.
        let mut ring = [f64::NAN; W];
        for (k, slot) in ring.iter_mut().enumerate().take(H.min(n)) {
            *slot = series[k][i];
        }
        for k in 0..n {
            ring[(k + H) % W] = series.get(k + H).map_or(f64::NAN, |s| s[i]);
            series[k][i] = if k >= H && k + H < n {
                let window = (k - H..=k + H).map(|j| ring[j % W]);
                if window.clone().all(f64::is_finite) {
                    window.sum::<f64>() / W as f64
                } else {
                    f64::NAN
                }
            } else {
                f64::NAN
            };
        }
    }
}

/// Cylinder velocity the grey-box model gives for a spool position and a cylinder force, used by
/// [`super::GreyBoxActuator`]: the meter-in and meter-out orifices in series with the force balance
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
        let mut params = super::super::AugmentedModel::nominal().unwrap().params;
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

    /// The warm-started solve finds the flow balance's unique root from any starting guess, and the
    /// neutral-valve cache returns what a fresh solve gives.
    #[test]
    fn pump_pressure_does_not_depend_on_the_guess_and_the_neutral_cache_is_exact() {
        let params = super::super::AugmentedModel::nominal().unwrap().params;
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

#[cfg(test)]
mod stop_tests {
    use super::*;
    use crate::{LoadTag, Sample, StageTag};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A record of the bucket resting at its curl stop (readings offset by `offset_rad`), its
    /// cylinder pressing towards the stop with `press_n` of hydraulic force beyond gravity (negative:
    /// away from it).
    fn resting_at_stop(offset_rad: f64, press_n: f64) -> (DigRecord, MachineConfig, GreyBoxParams) {
        let cfg = MachineConfig::default_machine().unwrap();
        let params = super::super::AugmentedModel::nominal().unwrap().params;
        let kin = Kinematics::new(&cfg).unwrap();
        let (lo, _) = kin.stroke_limited_range(Joint::Bucket);
        let q = JointAngles {
            boom_rad: 0.5,
            stick_rad: -1.5,
            bucket_rad: lo,
        };
        let arm = kin.moment_arms(&q).unwrap()[2];
        let gravity = gravity_forces(&kin, &q).unwrap()[2];
        // Towards the lower end: the force's torque `F dL/dq` negative.
        let force = gravity - press_n * arm.signum();
        // Eq. A20 `p_h A_h - p_r A_r = F`, the other chamber at 0.3 MPa.
        let (ah, ar, low) = (params.head_area_m2[2], params.rod_area_m2[2], 3.0e5);
        let (head, rod) = if force >= 0.0 {
            ((force + low * ar) / ah, low)
        } else {
            (low, (low * ah - force) / ar)
        };
        let samples = (0..200)
            .map(|k| Sample {
                time_s: 0.01 * k as f64,
                angles_rad: [0.5 + offset_rad, -1.5 + offset_rad, lo + offset_rad],
                head_pa: [12.0e6, 6.0e6, head],
                rod_pa: [3.0e5, 3.0e5, rod],
                pump_pa: [2.0e6, 2.0e6],
                stage: StageTag::Outside,
                load: LoadTag::Loaded,
                ..Sample::default()
            })
            .collect();
        let record = DigRecord {
            index: 0,
            samples,
            section: None,
            lanes: Vec::new(),
        };
        (record, cfg, params)
    }

    fn stop_signal(rec: &PreparedRecord) -> Vec<f64> {
        rec.measured
            .iter()
            .map(|m| m[Signal::StopAngle.index()])
            .filter(|v| v.is_finite())
            .collect()
    }

    /// A bucket pressed into its curl stop reads the stop's angle plus the resolver offset, for
    /// either sign of the offset (a reading beyond the stroke-limited range included), and the
    /// replay with that offset predicts it; a bucket pressed away from the stop, or only with a
    /// force dry friction or a full bucket's payload could take, is not at the stop.
    #[test]
    fn end_stop_reads_the_resolver_offset() {
        for offset in [0.012, -0.015, 0.0] {
            let (record, cfg, params) = resting_at_stop(offset, 250_000.0);
            let rec = PreparedRecord::new(&record, &cfg, &params).unwrap();
            let stops = stop_signal(&rec);
            assert_eq!(stops.len(), 200 - WARMUP_SAMPLES, "offset {offset}");
            assert!(stops.iter().all(|v| (v - offset).abs() < 1e-9), "{stops:?}");
            let mut aug = Augmentation::nominal();
            aug.set(super::super::Candidate::ResolverOffset, offset);
            let groups = super::super::Candidate::ResolverOffset.groups();
            assert!(groups.stops && !groups.hydraulic && !groups.force);
            let mut out = Vec::new();
            replay(&rec, &params, &aug, SignalGroups::ALL, &mut out);
            for (m, p) in rec.measured.iter().zip(&out) {
                let j = Signal::StopAngle.index();
                if m[j].is_finite() {
                    assert!((m[j] - p[j]).abs() < 1e-9);
                } else {
                    assert!(p[j].is_nan());
                }
            }
        }
        // Away from the stop; within dry friction; within what holding a full bucket needs.
        for press in [-250_000.0, 40_000.0, 150_000.0] {
            let (record, cfg, params) = resting_at_stop(0.01, press);
            let rec = PreparedRecord::new(&record, &cfg, &params).unwrap();
            assert!(stop_signal(&rec).is_empty(), "pressing {press} N");
        }
    }

    /// The payload's reflected mass at each cylinder is its kinetic energy per unit cylinder speed:
    /// moving one joint alone turns the payload (centroid and own inertia) about that joint, so
    /// `m_i = (|dc/dq_i|^2 + k^2) / r_i^2` with the centroid's speed `dc/dq_i` taken numerically.
    #[test]
    fn payload_reflected_mass_is_its_kinetic_energy_per_cylinder_speed() {
        let cfg = MachineConfig::default_machine().unwrap();
        let kin = Kinematics::new(&cfg).unwrap();
        let q = JointAngles {
            boom_rad: 0.3,
            stick_rad: -1.6,
            bucket_rad: -1.0,
        };
        let per_kg = payload_reflected_mass_per_kg(&kin, &q).unwrap();
        let arms = kin.moment_arms(&q).unwrap();
        let h = 1e-6;
        for i in 0..3 {
            let mut moved = q;
            match i {
                0 => moved.boom_rad += h,
                1 => moved.stick_rad += h,
                _ => moved.bucket_rad += h,
            }
            let (a, b) = (kin.payload_centroid(&q), kin.payload_centroid(&moved));
            let speed2 = ((b[0] - a[0]) / h).powi(2) + ((b[1] - a[1]) / h).powi(2);
            let expected = (speed2 + PAYLOAD_GYRATION_M.powi(2)) / arms[i].powi(2);
            assert!(
                (per_kg[i] - expected).abs() < 1e-4 * expected,
                "cylinder {i}: {} against {expected}",
                per_kg[i]
            );
        }
        // The boom carries the payload farthest from its joint: the most inertia per kg.
        assert!(per_kg[0] * arms[0].powi(2) > per_kg[2] * arms[2].powi(2));
    }

    /// The spool state is unknown for [`WARMUP_SAMPLES`] at the start of a record and after every gap
    /// in it (samples the reader left out), and known elsewhere.
    #[test]
    fn samples_after_a_gap_warm_up_again() {
        let times = (0..200)
            .map(|k| 0.01 * f64::from(k))
            .chain((0..200).map(|k| 10.0 + 0.01 * f64::from(k)));
        let samples: Vec<super::super::Sample> = times
            .map(|time_s| super::super::Sample {
                time_s,
                ..Default::default()
            })
            .collect();
        let warm = warmed_up(&samples);
        for (k, w) in warm.iter().enumerate() {
            let since = if k < 200 { k } else { k - 200 };
            assert_eq!(*w, since >= WARMUP_SAMPLES, "sample {k}");
        }
    }

    /// A bucket pressing into the soil with its head at the pump pressure and its rod at tank is
    /// load-limited (neither orifice's drop is known); with 3 MPa across its meter-in, with its
    /// valve closed, or with its outlet loaded it is not.
    #[test]
    fn load_limited_needs_both_drops_within_the_noise() {
        let params = super::super::AugmentedModel::nominal().unwrap().params;
        let mut s = super::super::Sample::default();
        s.command[2] = 0.8;
        s.pump_pa = [20.0e6, 2.0e6];
        s.head_pa[2] = 19.9e6;
        s.rod_pa[2] = params.tank_pa + 0.2e6;
        assert!(load_limited(&params, &s, 2));
        let mut metering = s;
        metering.head_pa[2] = 17.0e6;
        assert!(!load_limited(&params, &metering, 2));
        let mut closed = s;
        closed.command[2] = 0.0;
        assert!(!load_limited(&params, &closed, 2));
        let mut loaded_outlet = s;
        loaded_outlet.rod_pa[2] = 3.0e6;
        assert!(!load_limited(&params, &loaded_outlet, 2));
        // Retracting: the rod is the inlet. The stick is on pump 2.
        let mut stick = super::super::Sample::default();
        stick.command[1] = -0.5;
        stick.pump_pa = [2.0e6, 15.0e6];
        stick.rod_pa[1] = 14.95e6;
        stick.head_pa[1] = params.tank_pa;
        assert!(load_limited(&params, &stick, 1));
        // An inlet well above its supply (load check shut) is not.
        stick.pump_pa = [15.0e6, 2.0e6];
        assert!(!load_limited(&params, &stick, 1));
    }

    /// The prefilter keeps a bias (what a missing effect leaves), divides white noise's variance by
    /// the window, needs a whole window of defined samples and leaves the other signals alone.
    #[test]
    fn prefilter_keeps_a_bias_and_cuts_white_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let mut uniform = || rng.random::<f64>() - 0.5;
        let n = 20_000;
        let mut series: Vec<[f64; N_SIGNALS]> = (0..n)
            .map(|_| {
                let mut s = [7.0; N_SIGNALS];
                s[0] = 0.01 + uniform();
                s[1] = 0.02;
                s
            })
            .collect();
        series[100][1] = f64::NAN;
        prefilter_velocities(&mut series);
        let width = 2 * VELOCITY_PREFILTER_HALF + 1;
        let h = VELOCITY_PREFILTER_HALF;
        assert!(series[..h].iter().all(|s| s[0].is_nan()));
        assert!(series[n - h..].iter().all(|s| s[0].is_nan()));
        assert!((100 - h..=100 + h).all(|k| series[k][1].is_nan()));
        assert!((series[100 + h + 1][1] - 0.02).abs() < 1e-15);
        assert!(
            series
                .iter()
                .all(|s| s[3] == 7.0 && s[N_SIGNALS - 1] == 7.0)
        );
        let x: Vec<f64> = series
            .iter()
            .map(|s| s[0])
            .filter(|v| v.is_finite())
            .collect();
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64;
        assert!((mean - 0.01).abs() < 0.005, "{mean}");
        let white = 1.0 / 12.0;
        let ratio = var / (white / width as f64);
        assert!((0.9..1.1).contains(&ratio), "{ratio}");
    }

    #[test]
    fn aliased_zigzag_is_a_large_reversal_both_ways() {
        assert!(aliased_zigzag(0.10, 0.16, 0.09));
        assert!(aliased_zigzag(0.0, -0.03, 0.0));
        // A steady ramp, a step, and resolver noise (a few mm/s) are not.
        assert!(!aliased_zigzag(0.0, 0.05, 0.10));
        assert!(!aliased_zigzag(0.0, 0.2, 0.2));
        assert!(!aliased_zigzag(0.0, 0.006, -0.004));
    }

    /// The weighing recovers the payload that set the pressures (the cylinder forces of a held
    /// payload, Eq. A19, as head or rod pressure), statically and while the implement accelerates
    /// (the links' and the payload's reflected inertia added to the forces), leaves out a cylinder
    /// at its stroke end, and its offset term is the estimate's change for a common pressure offset.
    #[test]
    fn weighing_recovers_the_held_payload() {
        let cfg = MachineConfig::default_machine().unwrap();
        let kin = Kinematics::new(&cfg).unwrap();
        let params = super::super::AugmentedModel::nominal().unwrap().params;
        let q = JointAngles {
            boom_rad: 0.5,
            stick_rad: -1.2,
            bucket_rad: -0.6,
        };
        let strokes = Joint::ALL.map(|j| kin.stroke(j));
        let len = kin.cylinder_lengths(&q).unwrap().to_vector();
        let len = [len[0], len[1], len[2]];
        let arms = kin.moment_arms(&q).unwrap();
        let arms = [arms[0], arms[1], arms[2]];
        let mass = cylinder_masses(
            &kin,
            &cfg,
            &params.inertia_floor_kg_m2,
            &q,
            &Vector3::from(arms),
        );
        let per_kg = payload_reflected_mass_per_kg(&kin, &q).unwrap();
        let payload_kg = 2550.0;
        let sample_for = |accel: [f64; 3], offset_pa: f64| {
            let held = kin
                .cylinder_forces_from_tip_force(&q, &TipForce::default(), payload_kg)
                .unwrap();
            let mut s = super::super::Sample::default();
            for i in 0..3 {
                let f = held[i] + (mass[i] + payload_kg * per_kg[i]) * accel[i];
                if f >= 0.0 {
                    s.head_pa[i] = f / params.head_area_m2[i];
                } else {
                    s.rod_pa[i] = -f / params.rod_area_m2[i];
                }
                s.head_pa[i] += offset_pa;
                s.rod_pa[i] += offset_pa;
            }
            s
        };
        let weigh = |s: &super::super::Sample, accel: [f64; 3], len: &[f64; 3]| {
            weighed_payload(&kin, &params, s, &q, &arms, len, &strokes, (mass, accel)).unwrap()
        };
        let (m, per_pa) = weigh(&sample_for([0.0; 3], 0.0), [0.0; 3], &len);
        assert!((m - payload_kg).abs() < 1e-6 * payload_kg, "static: {m} kg");
        let accel = [0.3, -0.2, 0.4];
        let (m, _) = weigh(&sample_for(accel, 0.0), accel, &len);
        // The payload's inertia enters the least squares through its regressor: exact up to the
        // weighting of the cylinders.
        assert!(
            (m - payload_kg).abs() < 1e-3 * payload_kg,
            "accelerating: {m} kg"
        );
        // A common offset moves the estimate by its offset term.
        let offset = 2.0e5;
        let (m_off, _) = weigh(&sample_for([0.0; 3], offset), [0.0; 3], &len);
        assert!(
            (m_off - payload_kg - offset * per_pa).abs() < 1e-6 * payload_kg,
            "offset: {m_off} kg, per Pa {per_pa}"
        );
        // About 10 kg for a 0.2 MPa offset on this pose.
        assert!(
            per_pa.abs() > 1e-5,
            "the offset term is not negligible: {per_pa}"
        );
        // A cylinder at its stroke end does not take part: the other two still weigh the payload.
        let mut at_end = len;
        at_end[2] = strokes[2].1;
        let (m_end, _) = weigh(&sample_for([0.0; 3], 0.0), [0.0; 3], &at_end);
        assert!(
            (m_end - payload_kg).abs() < 1e-6 * payload_kg,
            "at the end: {m_end} kg"
        );
    }
}
