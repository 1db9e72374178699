//! The whole machine as a pure physics plant: valve commands in, motion, pressures, terrain change and
//! sensor readings out, stepped at 1 kHz by [`Plant::step`].
//!
//! Per step: hidden command effects (dead band) -> fixed transport delay -> spool lag (plus the
//! `hydraulic_lag` effect) -> linkage state from cylinder extensions -> soil contact (cutting, filling,
//! FEE force) -> cylinder loads (gravity, payload, soil; Appendix) -> hydraulics (Eqs. 1-3) -> tracks.

use std::collections::VecDeque;

use firmware_bridge::range::Limits;
use planner::kinematics::{Joint, JointAngles, MachinePose, TipForce};
use planner::machine::MachineConfig;
use planner::terrain::TerrainGrid;
use serde::Serialize;

use crate::effects::{Effect, EffectSet};
use crate::hydraulics::{
    ActuatorLoad, BOOM, BUCKET, HydraulicEffects, HydraulicParams, Hydraulics, N_ACTUATORS, STICK,
    SWING,
};
use crate::linkage::{Linkage, LinkageState, PoseFrame};
use crate::scenario::{Scenario, SoilContactIntegration};
use crate::sensors::{
    Scan, ScanCast, ScanRequest, SensedTruth, SensorEffects, SensorReadings, SensorSpec, Sensors,
    cast_scan,
};
use crate::soil_contact::{
    ContactInput, ContactLaw, MassLedger, SoilContact, SoilEffects, TravelSide, World,
};

/// Physics step (s): 1 kHz.
pub const PHYSICS_DT_S: f64 = 1.0e-3;
/// Soil contact (cutting, fill, the geometry of the FEE force) and the linkage loads run every this
/// many physics steps (5 ms, 200 Hz) and are held in between; the hydraulics run every step, and so
/// does the soil force's velocity dependence ([`ContactLaw`]) with
/// [`SoilContactIntegration::Implicit`]. The bucket edge moves ~1-3 mm in 5 ms, far below a terrain
/// cell.
pub const SOIL_SUBSTEPS: u64 = 5;
/// Most solves of one physics step in the soil (`Plant::step_in_soil`).
const SOIL_ITERATIONS: u32 = 8;
/// How far the soil's force at a step's end may be from the step's linearisation of it, N (the
/// soil resists a digging bucket with 20-200 kN).
const LINEARISATION_TOLERANCE_N: f64 = 5_000.0;
/// Track speed time constant (s).
const TRACK_TIME_CONSTANT_S: f64 = 0.3;
/// Table resolution for angle(length) and arm(length) lookups.
const TABLE_POINTS: usize = 2001;

/// Errors building a plant.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// The machine geometry is inconsistent.
    #[error("machine geometry: {0}")]
    Kinematics(#[from] planner::kinematics::KinematicsError),
    /// The scenario's terrain could not be built.
    #[error("terrain: {0}")]
    Terrain(#[from] planner::terrain::TerrainError),
    /// The start pose is outside the cylinder strokes.
    #[error("start pose: {0}")]
    StartPose(String),
    /// A machine or scenario value the plant cannot run with (not finite, out of range).
    #[error("{field}: {reason}")]
    Config {
        /// Dotted field of the machine or scenario file.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

/// Longest command-to-motion delay of a machine file, s (`hydraulics.transport_delay_s`; the
/// `transport_delay` effect adds at most 0.3 s). The plant holds one queued command per 1 ms step of
/// it, so an unbounded delay would be an unbounded allocation.
pub const MAX_TRANSPORT_DELAY_S: f64 = 0.5;
/// The range of a machine file's `hydraulics.transport_delay_s` the plant takes, 0 to
/// [`MAX_TRANSPORT_DELAY_S`] s: the one rule of the plant's check and the loader's (which names the
/// line).
pub const TRANSPORT_DELAY_LIMITS: Limits = Limits::closed(0.0, MAX_TRANSPORT_DELAY_S, "s");

/// Checks the machine and scenario values the plant's timing and memory depend on (the loaders check
/// them too, with the file and line; this keeps plants built in code from skipping them).
///
/// # Errors
/// [`PlantError::Config`] naming the field.
pub fn check_config(cfg: &MachineConfig, scenario: &Scenario) -> Result<(), PlantError> {
    let config = |(field, reason)| PlantError::Config { field, reason };
    cfg.validate().map_err(config)?;
    scenario.validate().map_err(config)?;
    let delay = cfg.hydraulics.transport_delay_s;
    TRANSPORT_DELAY_LIMITS
        .check(delay)
        .map_err(|e| PlantError::Config {
            field: "hydraulics.transport_delay_s".into(),
            reason: format!("{delay} s: {e}"),
        })
}

impl HydraulicParams {
    /// Hydraulic parameters for a machine file: cylinders, relief, pumps, valve areas, crossover and
    /// bulk modulus from `[cylinders]` and `[hydraulics]`, the rest from [`HydraulicParams::default`].
    pub fn from_machine(cfg: &MachineConfig) -> Self {
        let mut p = Self::default();
        let h = &cfg.hydraulics;
        let cyl = [
            &cfg.cylinders.boom,
            &cfg.cylinders.stick,
            &cfg.cylinders.bucket,
        ];
        for (dst, src) in p.cylinders.iter_mut().zip(cyl) {
            dst.bore_m = src.bore_m;
            dst.rod_m = src.rod_m;
            dst.stroke_m = src.stroke_m;
            dst.count = src.count.max(1);
        }
        p.fluid.tank_pressure_pa = h.tank_pressure_pa;
        p.fluid.bulk_modulus_pa = h.bulk_modulus_pa;
        // The machine file gives Cd sqrt(2 / rho) (Eq. 1 folds the density into the constant).
        p.fluid.discharge_coefficient =
            h.valve_discharge_coefficient / (2.0 / p.fluid.density_kg_per_m3).sqrt();
        let pumps = f64::from(h.pump_count.max(1));
        for pump in &mut p.pumps {
            pump.max_flow_m3_per_s = h.pump_max_flow_m3_per_s;
            pump.power_w = h.max_engine_power_w / pumps;
            pump.main_relief_pa = h.relief_pressure_pa;
        }
        p.port_relief_pa = h.relief_pressure_pa * 1.08;
        for (i, valve) in p.valves.iter_mut().enumerate() {
            // The boom section passes two cylinders' worth of flow.
            let scale = if i == BOOM { 1.3 } else { 1.0 };
            valve.meter_in_area_m2 = h.valve_max_area_m2 * scale;
            valve.meter_out_area_m2 = 1.6 * h.valve_max_area_m2 * scale;
            valve.bypass_area_m2 = h.valve_bleed_area_m2 * 2.0_f64.sqrt();
        }
        p.crossover_start = h.crossover_command.clamp(0.05, 0.95);
        p.crossover_full = (h.crossover_command + 0.2).min(1.0);
        p
    }
}

/// Lookup of joint angle and moment arm by cylinder extension (uniform samples, linear interpolation).
#[derive(Debug, Clone)]
struct StrokeTable {
    stroke_m: f64,
    angle: Vec<f64>,
    arm: Vec<f64>,
}

impl StrokeTable {
    fn lookup(&self, x: f64) -> (f64, f64) {
        let n = self.angle.len() - 1;
        let f = (x / self.stroke_m).clamp(0.0, 1.0) * n as f64;
        // `f >= 0`: truncation is its floor (without the libm call of `floor`).
        let i = (f as usize).min(n - 1);
        let t = f - i as f64;
        (
            self.angle[i] + t * (self.angle[i + 1] - self.angle[i]),
            self.arm[i] + t * (self.arm[i + 1] - self.arm[i]),
        )
    }
}

/// The machine's true state, for state logs and tests (never sent on the bus).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrueState {
    /// Simulation time (s).
    pub time_s: f64,
    /// `[boom, stick, bucket, swing]` (rad).
    pub angles_rad: [f64; 4],
    /// Their rates (rad/s).
    pub rates_rad_per_s: [f64; 4],
    /// Cylinder extensions from fully retracted `[boom, stick, bucket]` (m).
    pub extensions_m: [f64; 3],
    /// Head pressures (Pa).
    pub head_pa: [f64; 3],
    /// Rod pressures (Pa).
    pub rod_pa: [f64; 3],
    /// Pump pressures (Pa).
    pub pump_pa: [f64; 2],
    /// Machine pose `[x, y, heading]` in the world.
    pub pose: [f64; 3],
    /// Bucket tip in the world `[x, y, z]`.
    pub tip_world: [f64; 3],
    /// Bucket content (kg).
    pub payload_kg: f64,
    /// Soil force on the bucket `[Fx, Fz]` in the base frame (N).
    pub soil_force_n: [f64; 2],
}

/// The rays of a scan to cast off the plant's step ([`Plant::prepare_scan`]): the terrain as it was
/// when the scan was asked for, the sensor's pose and the request.
#[derive(Debug, Clone)]
pub struct PendingScan {
    terrain: TerrainGrid,
    origin: [f64; 3],
    heading_rad: f64,
    request: ScanRequest,
    time_s: f64,
}

impl PendingScan {
    /// Casts the rays ([`crate::sensors::cast_scan`]): the costly, pure part of a scan.
    #[must_use]
    pub fn cast(&self) -> ScanCast {
        cast_scan(
            &self.terrain,
            self.origin,
            self.heading_rad,
            &self.request,
            self.time_s,
        )
    }
}

/// The whole simulated machine.
#[derive(Debug, Clone)]
pub struct Plant {
    cfg: MachineConfig,
    linkage: Linkage,
    tables: [StrokeTable; 3],
    /// Hydraulic system state.
    pub hydraulics: Hydraulics,
    /// The true world (terrain, soil, boulders).
    pub world: World,
    /// Bucket-soil state (content, mass ledger).
    pub contact: SoilContact,
    effects: EffectSet,
    pose: MachinePose,
    track_speed: [f64; 2],
    odometry_m: [f64; 2],
    delay: VecDeque<[f64; 6]>,
    spool: [f64; 6],
    spool2: [f64; 6],
    /// The linkage state of the extensions at the last 200 Hz load update (or start); `link_stale`
    /// when the hydraulics have moved since. The loads need it at 200 Hz only, so it is refreshed
    /// there (and computed on demand by the accessors), not every step.
    link: LinkageState,
    link_stale: bool,
    soil_force: TipForce,
    /// The soil's force as a function of the tip velocity, from the last contact update; evaluated
    /// at every physics step.
    contact_law: ContactLaw,
    /// Per boom, stick, bucket actuator: the tip velocity per unit actuator velocity (`[vx, vz]`,
    /// Eq. A3 through the cylinder arms) and the actuator load per unit tip force (`[per fx, per
    /// fz]`), at the last contact update.
    tip_per_actuator: [[f64; 2]; 3],
    load_per_tip_force: [[f64; 2]; 3],
    /// [`Scenario::soil_force_factor`] (1 when absent).
    soil_force_factor: f64,
    /// [`Scenario::soil_contact`].
    contact_integration: SoilContactIntegration,
    sensors: Sensors,
    time_s: f64,
    steps: u64,
    /// The loads at the last contact update (gravity, payload, reflected masses; the soil's force
    /// too with [`SoilContactIntegration::Held`], see [`Self::loads`]).
    cached_loads: [ActuatorLoad; N_ACTUATORS],
    /// Gravity on or off (off for no-load hydraulic tests).
    pub gravity: bool,
}

impl Plant {
    /// Builds the machine on a scenario with hidden effects.
    ///
    /// # Errors
    /// [`PlantError`] for a machine or scenario value [`check_config`] refuses, an inconsistent
    /// machine, a bad grid or an unreachable start pose.
    pub fn new(
        cfg: &MachineConfig,
        scenario: &Scenario,
        effects: EffectSet,
    ) -> Result<Self, PlantError> {
        check_config(cfg, scenario)?;
        let linkage = Linkage::new(cfg)?;
        let kin = linkage.kinematics();
        let strokes = linkage.strokes_m();
        let mut tables = Vec::with_capacity(3);
        for (i, joint) in Joint::ALL.iter().enumerate() {
            let (lo, _) = kin.stroke(*joint);
            let mut angle = Vec::with_capacity(TABLE_POINTS);
            let mut arm = Vec::with_capacity(TABLE_POINTS);
            for k in 0..TABLE_POINTS {
                let x = strokes[i] * k as f64 / (TABLE_POINTS - 1) as f64;
                let a = kin.joint_angle(*joint, lo + x)?;
                angle.push(a);
                arm.push(kin.moment_arm(*joint, a)?);
            }
            tables.push(StrokeTable {
                stroke_m: strokes[i],
                angle,
                arm,
            });
        }
        let tables: [StrokeTable; 3] = tables
            .try_into()
            .map_err(|_| PlantError::StartPose("table construction".into()))?;
        let st = &scenario.start;
        let q0 = JointAngles {
            boom_rad: st.boom_deg.to_radians(),
            stick_rad: st.stick_deg.to_radians(),
            bucket_rad: st.bucket_deg.to_radians(),
        };
        let x0 = linkage
            .extensions(&q0)
            .map_err(|e| PlantError::StartPose(e.to_string()))?;
        let hparams = HydraulicParams::from_machine(cfg);
        let hydraulics = Hydraulics::new(hparams, [x0[0], x0[1], x0[2], st.swing_deg.to_radians()]);
        let world = World::from_scenario(scenario)?;
        let link = linkage.state(x0)?;
        let delay_steps = ((cfg.hydraulics.transport_delay_s + effects.get(Effect::TransportDelay))
            / PHYSICS_DT_S)
            .round()
            .max(0.0) as usize;
        let mut plant = Self {
            cfg: cfg.clone(),
            linkage,
            tables,
            hydraulics,
            world,
            contact: SoilContact::default(),
            effects,
            pose: MachinePose {
                x_m: st.x_m,
                y_m: st.y_m,
                heading_rad: st.heading_deg.to_radians(),
            },
            track_speed: [0.0; 2],
            odometry_m: [0.0; 2],
            delay: VecDeque::from(vec![[0.0; 6]; delay_steps]),
            spool: [0.0; 6],
            spool2: [0.0; 6],
            link,
            link_stale: false,
            soil_force: TipForce::default(),
            contact_law: ContactLaw::default(),
            tip_per_actuator: [[0.0; 2]; 3],
            load_per_tip_force: [[0.0; 2]; 3],
            soil_force_factor: scenario.soil_force_factor.unwrap_or(1.0),
            contact_integration: scenario.soil_contact,
            sensors: Sensors::new(SensorSpec::default(), scenario.seed),
            time_s: 0.0,
            steps: 0,
            cached_loads: [ActuatorLoad::default(); N_ACTUATORS],
            gravity: true,
        };
        plant.settle();
        Ok(plant)
    }

    /// Pressurises the cylinders to hold the start pose, so the run starts at rest.
    fn settle(&mut self) {
        let loads = self.loads(&self.linkage.frame(&self.link.q));
        let tank = self.hydraulics.params().fluid.tank_pressure_pa;
        for (i, load) in loads.iter().enumerate().take(3) {
            let (ah, ar) = (
                self.hydraulics.params().cylinders[i].head_area_m2(),
                self.hydraulics.params().cylinders[i].rod_area_m2(),
            );
            let a = &mut self.hydraulics.actuators[i];
            let f = load.force;
            if f >= 0.0 {
                a.head_pa = (f + tank * ar) / ah;
                a.rod_pa = tank;
            } else {
                a.head_pa = tank;
                a.rod_pa = (-f + tank * ah) / ar;
            }
        }
    }

    /// Simulation time (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The machine description.
    pub fn config(&self) -> &MachineConfig {
        &self.cfg
    }

    /// The hidden effects in force.
    pub fn effects(&self) -> &EffectSet {
        &self.effects
    }

    /// The linkage model.
    pub fn linkage(&self) -> &Linkage {
        &self.linkage
    }

    /// Machine pose in the world.
    pub fn pose(&self) -> MachinePose {
        self.pose
    }

    /// Places the machine at `pose` in the world, tracks at rest (trucked to another bench); the
    /// joints, the hydraulics, the bucket's content and the track odometry stay as they are.
    pub fn place(&mut self, pose: MachinePose) {
        self.pose = pose;
        self.track_speed = [0.0; 2];
    }

    /// Current joint angles of the implement.
    pub fn joint_angles(&self) -> JointAngles {
        self.link().q
    }

    /// Mass bookkeeping of the soil the bucket moved.
    pub fn mass_ledger(&self) -> MassLedger {
        self.contact.ledger
    }

    fn payload_kg(&self) -> f64 {
        self.contact.content.mass_kg
    }

    /// The linkage state of the current cylinder extensions (stroke tables).
    fn link(&self) -> LinkageState {
        if self.link_stale {
            self.link_from_tables()
        } else {
            self.link
        }
    }

    fn link_from_tables(&self) -> LinkageState {
        let mut arms = [0.0; 3];
        let mut angles = [0.0; 3];
        for i in 0..3 {
            let (a, r) = self.tables[i].lookup(self.hydraulics.actuators[i].position);
            angles[i] = a;
            arms[i] = r;
        }
        LinkageState {
            q: JointAngles {
                boom_rad: angles[0],
                stick_rad: angles[1],
                bucket_rad: angles[2],
            },
            arms,
        }
    }

    /// Loads on the actuators at the current pose, with its geometry. With
    /// [`SoilContactIntegration::Held`] they include the soil's force of this contact update; with
    /// [`SoilContactIntegration::Implicit`] they are the loads without it, and the maps
    /// [`Self::step`] applies the soil's force and its velocity gradient through
    /// (`tip_per_actuator`, `load_per_tip_force`).
    fn loads(&mut self, frame: &PoseFrame) -> [ActuatorLoad; N_ACTUATORS] {
        let payload = self.payload_kg();
        let loads_with = |soil: &TipForce| {
            self.linkage
                .cylinder_loads_at(&self.link, frame, soil, payload, self.gravity)
        };
        let held = self.contact_integration == SoilContactIntegration::Held;
        let forces = if held {
            loads_with(&self.soil_force)
        } else {
            loads_with(&TipForce::default())
        };
        // The cylinder loads are linear in the tip force (Eqs. A19-A23).
        if !held {
            let per_fx = loads_with(&TipForce {
                fx_n: 1.0,
                ..TipForce::default()
            });
            let per_fz = loads_with(&TipForce {
                fz_n: 1.0,
                ..TipForce::default()
            });
            for i in 0..3 {
                self.load_per_tip_force[i] = [per_fx[i] - forces[i], per_fz[i] - forces[i]];
                let mut unit = [0.0; 3];
                unit[i] = 1.0;
                let rates = self.linkage.joint_rates(&self.link, unit);
                self.tip_per_actuator[i] = self.linkage.tip_velocity_at(frame, rates);
            }
        }
        let masses = self.linkage.cylinder_masses_at(&self.link, frame, payload);
        let tip_x_m = frame.points.tip[0];
        let swing_inertia = self.cfg.swing.inertia_kg_m2 + payload * tip_x_m * tip_x_m;
        [
            ActuatorLoad {
                force: forces[0],
                mass: masses[0],
                ..ActuatorLoad::default()
            },
            ActuatorLoad {
                force: forces[1],
                mass: masses[1],
                ..ActuatorLoad::default()
            },
            ActuatorLoad {
                force: forces[2],
                mass: masses[2],
                ..ActuatorLoad::default()
            },
            ActuatorLoad {
                force: 0.0,
                mass: swing_inertia,
                ..ActuatorLoad::default()
            },
        ]
    }

    fn soil_contact(&mut self, dt: f64, frame: &PoseFrame) {
        let points = &frame.points;
        let fx = self.effects;
        let rates = self.linkage.joint_rates(
            &self.link,
            [0, 1, 2].map(|i| self.hydraulics.actuators[i].velocity),
        );
        let tip_v = self.linkage.tip_velocity_at(frame, rates);
        let swing = self.hydraulics.actuators[SWING].position;
        let input = ContactInput {
            tip_world: self
                .pose
                .world_from_base(swing, points.tip[0], points.tip[1]),
            tip_base: points.tip,
            pin_base: points.bucket_pin,
            tip_velocity_base: tip_v,
            bucket_abs_rad: self.link.q.bucket_abs_rad(),
            azimuth_rad: self.pose.dig_plane_azimuth_rad(swing),
            machine_xy: [self.pose.x_m, self.pose.y_m],
            width_m: self.cfg.bucket.width_m,
            capacity_m3: self.cfg.bucket.capacity_m3,
        };
        let soil_fx = SoilEffects {
            cohesion_pa: fx.get(Effect::SoilCohesion),
            density_kg_per_m3: fx.get(Effect::SoilDensity),
        };
        self.contact_law = self.contact.step_law(&mut self.world, &input, dt, &soil_fx);
        if self.contact_integration == SoilContactIntegration::Held {
            self.contact_law.travel = TravelSide::Sign;
            // The force at this update's velocity, held for the next SOIL_SUBSTEPS steps.
            self.soil_force = self.scaled(self.contact_law.force(tip_v));
        }
    }

    /// The tip's velocity (base frame `[vx, vz]`, m/s) at the actuators' velocities, through the
    /// linkage's Jacobian at the last soil update's pose.
    fn tip_velocity(&self) -> [f64; 2] {
        let mut v_tip = [0.0; 2];
        for (i, j) in self.tip_per_actuator.iter().enumerate() {
            let v = self.hydraulics.actuators[i].velocity;
            v_tip[0] += j[0] * v;
            v_tip[1] += j[1] * v;
        }
        v_tip
    }

    /// `f` times [`Scenario::soil_force_factor`] (Table 2).
    fn scaled(&self, f: TipForce) -> TipForce {
        let k = self.soil_force_factor;
        TipForce {
            fx_n: k * f.fx_n,
            fz_n: k * f.fz_n,
            my_nm: k * f.my_nm,
        }
    }

    /// The loads at the current actuator velocities: the cached loads plus the soil's force from
    /// the contact law, with its velocity gradient `dF_i/dv_j = a_i . G . J_j` for the hydraulics'
    /// implicit step (`ActuatorLoad::damping`).
    fn loads_with_soil(&mut self) -> [ActuatorLoad; N_ACTUATORS] {
        let v_tip = self.tip_velocity();
        self.loads_with_soil_at(v_tip, v_tip)
    }

    /// As [`Self::loads_with_soil`], with the soil's force linearised at the tip velocity `v_lin`
    /// instead of at the current one, `v_now`: the load is the force at `v_lin` carried to `v_now`
    /// along the gradient, which the step then follows from `v_now`.
    fn loads_with_soil_at(
        &mut self,
        v_now: [f64; 2],
        v_lin: [f64; 2],
    ) -> [ActuatorLoad; N_ACTUATORS] {
        let mut loads = self.cached_loads;
        let law = &self.contact_law;
        if *law == ContactLaw::default() {
            self.soil_force = TipForce::default();
            return loads;
        }
        let k = self.soil_force_factor;
        let g = law.gradient(v_lin);
        let at = law.force(v_lin);
        let f = [0, 1].map(|r| {
            [at.fx_n, at.fz_n][r]
                + g[r][0] * (v_now[0] - v_lin[0])
                + g[r][1] * (v_now[1] - v_lin[1])
        });
        self.soil_force = self.scaled(TipForce {
            fx_n: f[0],
            fz_n: f[1],
            my_nm: 0.0,
        });
        for (i, load) in loads.iter_mut().take(3).enumerate() {
            let a = self.load_per_tip_force[i];
            load.force += a[0] * self.soil_force.fx_n + a[1] * self.soil_force.fz_n;
            // a . G (the load on actuator i per unit tip velocity), then . J_j.
            let ag = [
                k * (a[0] * g[0][0] + a[1] * g[1][0]),
                k * (a[0] * g[0][1] + a[1] * g[1][1]),
            ];
            for (j, tip) in self.tip_per_actuator.iter().enumerate() {
                load.damping[j] = ag[0] * tip[0] + ag[1] * tip[1];
            }
        }
        loads
    }

    /// One hydraulics step of `dt` with the soil's force implicit in the new velocities. The step
    /// linearises the force at a tip velocity and solves the three linkage velocities with that
    /// gradient; where the force at the step's end misses the linearisation by more than
    /// [`LINEARISATION_TOLERANCE_N`] (the travel turned within the step: the force turns over
    /// within a few creep speeds, which a gradient taken at the start does not see, and the step
    /// would overshoot the turn and ring across it), the step is solved again from the same state
    /// with the force linearised at the last solve's end, then halfway between the last two points
    /// (Newton, damped so that ends on either side of a turn close in on it), at most
    /// [`SOIL_ITERATIONS`] times.
    fn step_in_soil(&mut self, dt: f64, valves: [f64; N_ACTUATORS], hfx: &HydraulicEffects) {
        let start = self.hydraulics.clone();
        let v_start = self.tip_velocity();
        let mut v_lin = v_start;
        for iteration in 0..SOIL_ITERATIONS {
            if iteration > 0 {
                self.hydraulics = start.clone();
            }
            let loads = self.loads_with_soil_at(v_start, v_lin);
            self.hydraulics.step(dt, valves, &loads, hfx);
            let v_end = self.tip_velocity();
            let law = &self.contact_law;
            let (at, g, end) = (law.force(v_lin), law.gradient(v_lin), law.force(v_end));
            // The force the step applied at its end (the linearisation), and what it missed.
            let applied = [0, 1].map(|r| {
                [at.fx_n, at.fz_n][r]
                    + g[r][0] * (v_end[0] - v_lin[0])
                    + g[r][1] * (v_end[1] - v_lin[1])
            });
            let miss = (end.fx_n - applied[0]).hypot(end.fz_n - applied[1]);
            self.soil_force = self.scaled(TipForce {
                fx_n: applied[0],
                fz_n: applied[1],
                my_nm: 0.0,
            });
            if self.soil_force_factor * miss <= LINEARISATION_TOLERANCE_N {
                return;
            }
            v_lin = if iteration == 0 {
                v_end
            } else {
                [0.5 * (v_lin[0] + v_end[0]), 0.5 * (v_lin[1] + v_end[1])]
            };
        }
    }

    /// Advances the machine by one physics step [`PHYSICS_DT_S`] with the valve commands
    /// `[boom, stick, bucket, swing, left track, right track]` in `[-1, 1]` (non-finite -> 0).
    pub fn step(&mut self, commands: [f64; 6]) {
        let dt = PHYSICS_DT_S;
        let fx = self.effects;
        // Hidden effect: valve dead band.
        let deadband = fx.get(Effect::ValveDeadband);
        let cmd = commands.map(|u| {
            let u = if u.is_finite() {
                u.clamp(-1.0, 1.0)
            } else {
                0.0
            };
            u.signum() * (u.abs() - deadband).max(0.0)
        });
        // Fixed transport delay (nominal plus the hidden effect).
        let delayed = if self.delay.is_empty() {
            cmd
        } else {
            self.delay.push_back(cmd);
            self.delay.pop_front().unwrap_or(cmd)
        };
        // Spool (pilot and main stage) lag, then the hidden extra lag in series.
        let tau = self.cfg.hydraulics.lag_time_constant_s.max(dt);
        let extra = fx.get(Effect::HydraulicLag);
        for (i, target) in delayed.iter().enumerate() {
            self.spool[i] += (target - self.spool[i]) * (dt / tau).min(1.0);
            self.spool2[i] = if extra > 0.0 {
                self.spool2[i] + (self.spool[i] - self.spool2[i]) * (dt / extra).min(1.0)
            } else {
                self.spool[i]
            };
        }
        let spools = self.spool2;

        // Soil contact at the current pose (the cut, the fill and the contact law) and the loads of
        // gravity and payload on the cylinders (Appendix), at 200 Hz: they depend on the pose, which
        // moves little in 5 ms. The soil's force depends steeply on the velocity as well, so it is
        // evaluated from the contact law at every step and its gradient taken implicitly.
        if self.steps.is_multiple_of(SOIL_SUBSTEPS) {
            if self.link_stale {
                self.link = self.link_from_tables();
                self.link_stale = false;
            }
            let frame = self.linkage.frame(&self.link.q);
            self.soil_contact(dt * SOIL_SUBSTEPS as f64, &frame);
            self.cached_loads = self.loads(&frame);
        }
        self.steps += 1;
        let hfx = HydraulicEffects {
            flow_sharing: fx.get(Effect::FlowSharing),
            pump_saturation: fx.get(Effect::PumpSaturation),
            coulomb_friction_n: fx.get(Effect::CoulombFriction),
            viscous_friction_n_s_per_m: fx.get(Effect::ViscousFriction),
            internal_leakage: fx.get(Effect::InternalLeakage),
        };
        let valves = [spools[BOOM], spools[STICK], spools[BUCKET], spools[SWING]];
        match self.contact_integration {
            SoilContactIntegration::Held => {
                self.hydraulics.step(dt, valves, &self.cached_loads, &hfx);
            }
            SoilContactIntegration::Implicit if self.contact_law == ContactLaw::default() => {
                let loads = self.loads_with_soil();
                self.hydraulics.step(dt, valves, &loads, &hfx);
            }
            SoilContactIntegration::Implicit => self.step_in_soil(dt, valves, &hfx),
        }
        self.link_stale = true;

        // Tracks: speed follows the command with a lag; odometry and pose by differential drive.
        let vmax = self.cfg.tracks.max_speed_m_per_s;
        for (k, speed) in self.track_speed.iter_mut().enumerate() {
            *speed += (spools[4 + k] * vmax - *speed) * (dt / TRACK_TIME_CONSTANT_S);
            self.odometry_m[k] += *speed * dt;
        }
        let v = 0.5 * (self.track_speed[0] + self.track_speed[1]);
        let omega = (self.track_speed[1] - self.track_speed[0]) / self.cfg.tracks.gauge_m.max(0.1);
        self.pose.heading_rad += omega * dt;
        // Standing still (the common case) the position cannot change: skip the trigonometry.
        if v != 0.0 {
            let (sin, cos) = self.pose.heading_rad.sin_cos();
            self.pose.x_m += v * cos * dt;
            self.pose.y_m += v * sin * dt;
        }
        self.time_s += dt;
    }

    /// The true values the sensors see.
    pub fn sensed_truth(&self) -> SensedTruth {
        let a = &self.hydraulics.actuators;
        let link = self.link();
        let rates = self
            .linkage
            .joint_rates(&link, [a[0].velocity, a[1].velocity, a[2].velocity]);
        SensedTruth {
            angles_rad: [
                link.q.boom_rad,
                link.q.stick_rad,
                link.q.bucket_rad,
                a[SWING].position,
            ],
            rates_rad_per_s: [rates[0], rates[1], rates[2], a[SWING].velocity],
            head_pa: [a[0].head_pa, a[1].head_pa, a[2].head_pa],
            rod_pa: [a[0].rod_pa, a[1].rod_pa, a[2].rod_pa],
            pump_pa: self.hydraulics.pump_pa,
            odometry_m: self.odometry_m,
        }
    }

    /// Reads every sensor (noise, quantisation and the sensor hidden effects applied).
    pub fn read_sensors(&mut self) -> SensorReadings {
        let truth = self.sensed_truth();
        let fx = SensorEffects {
            pressure_offset_pa: self.effects.get(Effect::PressureSensorOffset),
            resolver_offset_rad: self.effects.get(Effect::ResolverOffset),
        };
        self.sensors.read(&truth, &fx)
    }

    /// Scans the terrain from the range sensor on the cab (machine file `[sensor]`), pointing along
    /// the digging plane.
    pub fn scan(&mut self, request: &ScanRequest) -> Scan {
        let (origin, az) = self.scan_sensor_pose();
        self.sensors
            .scan(&self.world, origin, az, request, self.time_s)
    }

    /// [`Self::scan`] in two parts, for a caller that casts the rays elsewhere while the plant goes
    /// on (the real-time simulator): the rays to cast, with a copy of the terrain as it is now. Its
    /// [`PendingScan::cast`] and then [`Self::finish_scan`] give the scan [`Self::scan`] would have
    /// given now, up to the range noise drawn later from the same generator.
    pub fn prepare_scan(&self, request: &ScanRequest) -> PendingScan {
        let (origin, heading_rad) = self.scan_sensor_pose();
        PendingScan {
            terrain: self.world.terrain.clone(),
            origin,
            heading_rad,
            request: *request,
            time_s: self.time_s,
        }
    }

    /// The scan of rays cast from a [`PendingScan`]: the range noise added.
    pub fn finish_scan(&mut self, cast: ScanCast) -> Scan {
        self.sensors.add_range_noise(cast)
    }

    /// The range sensor's origin (world, m) and heading (rad): on the cab (machine file `[sensor]`),
    /// pointing along the digging plane.
    fn scan_sensor_pose(&self) -> ([f64; 3], f64) {
        let s = &self.cfg.sensor;
        let swing = self.hydraulics.actuators[SWING].position;
        let az = self.pose.dig_plane_azimuth_rad(swing);
        let mount_az = az + s.bearing_rad;
        let origin = [
            self.pose.x_m + s.radial_offset_m * mount_az.cos(),
            self.pose.y_m + s.radial_offset_m * mount_az.sin(),
            s.height_m,
        ];
        (origin, az)
    }

    /// The true state (for state logs and tests).
    pub fn true_state(&self) -> TrueState {
        let t = self.sensed_truth();
        let a = &self.hydraulics.actuators;
        let swing = a[SWING].position;
        let tip = self.linkage.kinematics().forward(&self.link().q);
        TrueState {
            time_s: self.time_s,
            angles_rad: t.angles_rad,
            rates_rad_per_s: t.rates_rad_per_s,
            extensions_m: [a[0].position, a[1].position, a[2].position],
            head_pa: t.head_pa,
            rod_pa: t.rod_pa,
            pump_pa: t.pump_pa,
            pose: [self.pose.x_m, self.pose.y_m, self.pose.heading_rad],
            tip_world: self.pose.world_from_base(swing, tip.x_m, tip.z_m),
            payload_kg: self.payload_kg(),
            soil_force_n: [self.soil_force.fx_n, self.soil_force.fz_n],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant(effects: EffectSet) -> Plant {
        Plant::new(
            &MachineConfig::default_machine().unwrap(),
            &Scenario::default_bench().unwrap(),
            effects,
        )
        .unwrap()
    }

    /// Table 2's force factor scales the soil's force on the bucket: the two machines move alike
    /// until the bucket first touches the soil, and then the force of one is twice the other's (to
    /// 1 %: the force reported is the one the implicit step applied at its end, where the bucket
    /// resisted twice as much has slowed a little more).
    #[test]
    fn soil_force_factor_scales_the_force_on_the_bucket() {
        let mut scenario = Scenario::default_bench().unwrap();
        let machine = MachineConfig::default_machine().unwrap();
        let mut one = Plant::new(&machine, &scenario, EffectSet::nominal()).unwrap();
        scenario.soil_force_factor = Some(2.0);
        scenario.validate().unwrap();
        let mut two = Plant::new(&machine, &scenario, EffectSet::nominal()).unwrap();
        let mut touched = false;
        for _ in 0..(20.0 / PHYSICS_DT_S) as usize {
            // Boom down, stick out: the bucket comes down onto the bench.
            one.step([-0.6, -0.3, 0.0, 0.0, 0.0, 0.0]);
            two.step([-0.6, -0.3, 0.0, 0.0, 0.0, 0.0]);
            let (f1, f2) = (one.true_state().soil_force_n, two.true_state().soil_force_n);
            if f1[0].hypot(f1[1]) > 1.0 {
                assert!(
                    (f2[0] - 2.0 * f1[0]).abs() < 1e-2 * f1[0].abs().max(1.0),
                    "{f1:?} {f2:?}"
                );
                assert!(
                    (f2[1] - 2.0 * f1[1]).abs() < 1e-2 * f1[1].abs().max(1.0),
                    "{f1:?} {f2:?}"
                );
                touched = true;
                break;
            }
        }
        assert!(touched, "the bucket never reached the soil");
        scenario.soil_force_factor = Some(-1.0);
        assert!(scenario.validate().is_err());
    }

    /// The bucket pushed into the bench and then held (valves neutral) while a leaking stick lets it
    /// creep: the soil's force settles to what holds the creeping bucket instead of swinging between
    /// full resistance and none at every contact update (the limit cycle of a steep damper held
    /// explicitly for 5 ms against the oil column: with [`SoilContactIntegration::Held`] 179 kN,
    /// jumping by up to 218 kN per step). On the default bench (5 kPa); with the wedge on the side
    /// of `sign(vx)` (plant `implicit-1`) it still rang there, by up to 325 kN per step, as the
    /// creeping edge's travel turned.
    #[test]
    fn a_bucket_held_in_the_soil_rests_without_chatter_with_implicit_contact() {
        let mut scenario = Scenario::default_bench().unwrap();
        scenario.soil_contact = SoilContactIntegration::Implicit;
        let mut p = Plant::new(
            &MachineConfig::default_machine().unwrap(),
            &scenario,
            EffectSet::from_args(&["internal_leakage=1e-11"]).unwrap(),
        )
        .unwrap();
        let mut pushed = 0;
        for _ in 0..(20.0 / PHYSICS_DT_S) as usize {
            p.step([-0.6, -0.3, 0.0, 0.0, 0.0, 0.0]);
            let f = p.true_state().soil_force_n;
            if f[0].hypot(f[1]) > 1.0 {
                pushed += 1;
            }
            if pushed >= 500 {
                break;
            }
        }
        assert!(pushed >= 500, "the bucket never reached the soil");
        let mut forces = Vec::new();
        for _ in 0..3000 {
            p.step([0.0; 6]);
            forces.push(p.true_state().soil_force_n);
        }
        // After a settling second: the largest change of the force from one 1 ms step to the next.
        let held = &forces[1000..];
        let largest_jump = held
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .fold(0.0, f64::max);
        let largest = held.iter().map(|f| f[0].hypot(f[1])).fold(0.0, f64::max);
        // Before the contact law was evaluated per step: 179 kN, jumping by up to 218 kN per step.
        assert!(
            largest > 1.0e3,
            "the soil no longer holds the bucket: {largest} N"
        );
        assert!(
            largest_jump < 2.0e3,
            "the force jumps by {largest_jump} N per step (largest {largest} N)"
        );
    }

    #[test]
    fn starts_at_the_scenario_pose_and_holds_it_at_neutral() {
        let mut p = plant(EffectSet::nominal());
        let q0 = p.joint_angles();
        assert!((q0.boom_rad - 41f64.to_radians()).abs() < 1e-3);
        for _ in 0..2000 {
            p.step([0.0; 6]);
        }
        let q = p.joint_angles();
        assert!((q.boom_rad - q0.boom_rad).abs() < 5e-3, "{q:?} vs {q0:?}");
        assert!((q.stick_rad - q0.stick_rad).abs() < 5e-3);
        assert!((q.bucket_rad - q0.bucket_rad).abs() < 5e-3);
    }

    #[test]
    fn commands_move_joints_in_the_documented_directions() {
        let mut p = plant(EffectSet::nominal());
        let q0 = p.joint_angles();
        for _ in 0..1000 {
            p.step([0.5, 0.5, 0.5, 0.5, 0.5, 0.5]);
        }
        let q = p.joint_angles();
        assert!(q.boom_rad > q0.boom_rad, "boom extension raises the boom");
        assert!(
            q.stick_rad < q0.stick_rad,
            "stick extension pulls the stick in"
        );
        assert!(q.bucket_rad < q0.bucket_rad, "bucket extension curls");
        assert!(p.true_state().angles_rad[3] > 0.0);
        assert!(p.pose().x_m > 0.0, "tracks forward");
    }

    #[test]
    fn transport_delay_effect_delays_motion() {
        let moved_at = |fx: EffectSet| {
            let mut p = plant(fx);
            let x0 = p.hydraulics.actuators[STICK].position;
            for k in 0..1000 {
                p.step([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
                if (p.hydraulics.actuators[STICK].position - x0).abs() > 1e-3 {
                    return k;
                }
            }
            1000
        };
        let nominal = moved_at(EffectSet::nominal());
        let delayed = moved_at(EffectSet::from_args(&["transport_delay=0.1"]).unwrap());
        assert!(
            (delayed as i64 - nominal as i64 - 100).abs() <= 3,
            "{nominal} {delayed}"
        );
    }
}
