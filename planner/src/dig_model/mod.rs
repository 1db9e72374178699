//! The combined forward dig model (thesis 4.1, Fig. 14): what happens if Autodig starts from a
//! candidate bucket pose over a terrain section.
//!
//! Three interlinked predictions are stepped at the control period (10 ms, 100 Hz):
//!
//! 1. **Actuators** ([`ActuatorDynamics`], by default the recurrent networks of
//!    [`crate::actuator::ActuatorModel`], Eq. 4, Figs. 17-18): cylinder velocities from the commands and
//!    cylinder forces, integrated to cylinder lengths (trapezoid), turned into joint angles through
//!    tabulated stroke tables (Eq. A5, A8-A14) and the bucket pose by forward kinematics.
//! 2. **Soil** ([`SoilModel`]): the bucket pose and its motion over the terrain section give
//!    `Gamma = (d, alpha, rho, V_s)` (`V_s` from [`crate::terrain::SweptVolume`], at most the bucket
//!    capacity). The analytical model ([`crate::soil::MovingBucketSoil`]) is the modified FEE (Eqs.
//!    14-18) for the direction the tip actually travels, held short of the wedge's failure limit where
//!    Eq. 17 has no solution (an open bucket pulled in: the soil then resists more, not less), plus the
//!    bearing resistance of the edge and the bucket's back pushed into the soil
//!    ([`crate::soil::BearingParams`]); depth and slope are measured on the section as the dig cuts it
//!    (lowered to the tip's path, as the machine's terrain is). The empirical model (Eq. 21) uses the
//!    pre-dig geometry ([`crate::soil::dig_geometry`]). The result is multiplied by the force factor of
//!    Table 2.
//! 3. **Autodig** ([`crate::autodig::Autodig`], the very same step the controller runs, with the
//!    perception enhancements of 3.2: swept volume and bucket-above-terrain): commands from joint
//!    angles, cylinder extensions and head pressures.
//!
//! The link between them is the static analysis of the Appendix: the soil force and gravity give the
//! joint torques `tau = G - J^T f` (Eq. A2, A4) and the cylinder forces `F = tau / r` (Eqs. A7, A19).
//! Forward kinematics, the Jacobian and `G` come from one pass over the joint angles (three `sin_cos`
//! per step); the tip velocity for the soil model is `J q'` with `q' = v_cyl / r`.
//!
//! # Pressures from forces (the inverse of Eq. A20)
//!
//! `F = p_head A_head - p_rod A_rod` has one equation and two unknowns. The model uses the static split
//! the simulator settles to at rest and the machine shows under load: the loaded side carries the force
//! and the other side sits at the return-line pressure `p_tank` (`hydraulics.tank_pressure_pa`):
//! `F >= 0`: `p_head = (F + p_tank A_rod) / A_head`, `p_rod = p_tank`; `F < 0`: `p_head = p_tank`,
//! `p_rod = (-F + p_tank A_head) / A_rod`. Both are clamped to the port-relief pressure (1.08 x main
//! relief), which a real cylinder cannot exceed. Autodig's maps read head pressures (docs/autodig.md),
//! so the meter-out back pressure of a moving cylinder, which this split leaves out, is the main
//! difference from measured head pressures.
//!
//! # Payload
//!
//! Eq. 19's moment `M_y = -F_g x_c` is the moment about the tip of the swept material's weight. The
//! analytical model carries that weight (force and moment) through the payload term of Eq. A4 instead,
//! with the payload `min(V_s, capacity) x gamma`, as the simulator does; the empirical model's fitted
//! `M_y` already contains it, so it adds no payload.
//!
//! # Outputs and guarantees
//!
//! [`DigModel::predict_into`] fills a caller-provided [`DigTrace`] (preallocated, never grown in the
//! loop) and returns a [`DigSummary`]: time, energy `sum_i |F_i dL_i|` (the controller's dig statistic,
//! thesis 6.1), swept volume, floor-penetration flag and end reason. [`DigModel::evaluate`] skips the
//! trace; [`DigModel::evaluate_many`] evaluates candidate starts in parallel (rayon, with the crate's
//! `parallel` feature). A prediction is deterministic; the model is immutable and `Send + Sync`. The only allocations are per dig (a copy
//! of the section for the swept-volume integrator and of Autodig's maps), none per step. Bad input gives
//! a [`DigModelError`], never NaN or a panic.
//!
//! Layout: `actuator` (the actuator dynamics it steps), `config` (settings and the shipped files),
//! `prediction` (the site and start it predicts from, the trace and summary it gives), `statics` (the
//! stroke tables, the static analysis and the cut surface); this module holds the stepping loop.

use crate::actuator::{ActuatorError, ActuatorModel};
use crate::autodig::{Autodig, AutodigError, AutodigInputs, AutodigMaps, MapsError, Stage};
use crate::kinematics::{BucketPose, Joint, JointAngles, Kinematics, KinematicsError, TipForce};
use crate::machine::{ConfigError, MachineConfig};
use crate::soil::{
    BearingParams, BucketMotion, Contact, MovingBucketSoil, SoilError, dig_geometry, fee_tip_force,
};
use crate::terrain::{SectionProfile, SweptVolume, TerrainError};

mod actuator;
mod config;
mod prediction;
mod statics;

pub use actuator::ActuatorDynamics;
pub use config::{DEFAULT_DIG_MODEL_TOML, DigModelConfig, NOMINAL_ACTUATOR_JSON, SoilModel};
pub use prediction::{DigEnd, DigPrediction, DigSample, DigSite, DigStart, DigSummary, DigTrace};
use statics::{CutSurface, PoseStatics, Statics, StrokeTable};

/// Port-relief pressure as a multiple of the main relief (the simulator's overload reliefs).
const PORT_RELIEF_FACTOR: f64 = 1.08;
/// Points per stroke of the angle/moment-arm tables (0.6 mm spacing on a 1.2 m stroke).
const TABLE_POINTS: usize = 2001;
/// Longest dig the model will run, s (guards the trace buffer size).
pub const MAX_DIG_TIME_S: f64 = 600.0;

/// Dig model errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DigModelError {
    /// A configuration value is invalid.
    #[error("dig model config {field}: {reason}")]
    Config {
        /// The field.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The machine file.
    #[error(transparent)]
    Machine(#[from] ConfigError),
    /// The Autodig maps.
    #[error(transparent)]
    Maps(#[from] MapsError),
    /// A NaN or infinite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// The start pose cannot be reached (inverse kinematics, joint limits or cylinder strokes).
    #[error("start pose unreachable: {0}")]
    Unreachable(KinematicsError),
    /// Kinematics failed during the dig (e.g. a singular moment arm).
    #[error("kinematics: {0}")]
    Kinematics(KinematicsError),
    /// The terrain section is unusable (empty, degenerate, unknown cells in the grid).
    #[error("terrain: {0}")]
    Terrain(#[from] TerrainError),
    /// The bucket tip left the terrain section (a gap in the section or too short a section).
    #[error(
        "bucket tip at r = {r_m:.3} m outside the terrain section [{r_start_m:.3}, {r_end_m:.3}] m"
    )]
    OutsideTerrain {
        /// Tip distance from the swing axis, m.
        r_m: f64,
        /// Section start, m.
        r_start_m: f64,
        /// Section end, m.
        r_end_m: f64,
    },
    /// The soil model.
    #[error("soil model: {0}")]
    Soil(#[from] SoilError),
    /// The actuator model.
    #[error("actuator model: {0}")]
    Actuator(#[from] ActuatorError),
    /// Autodig rejected an input or its configuration.
    #[error("autodig: {0}")]
    Autodig(#[from] AutodigError),
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, DigModelError>;

/// The combined dig model (Fig. 14): actuator dynamics `A` + soil model + Autodig.
#[derive(Debug, Clone)]
pub struct DigModel<A: ActuatorDynamics = ActuatorModel> {
    kin: Kinematics,
    tables: [StrokeTable; 3],
    actuator: A,
    config: DigModelConfig,
    maps: AutodigMaps,
    bucket_width_m: f64,
    capacity_m3: f64,
    head_area_m2: [f64; 3],
    rod_area_m2: [f64; 3],
    tank_pa: f64,
    port_relief_pa: f64,
    statics: Statics,
    /// The analytical soil model with its constants precomputed (`None` with the empirical model).
    moving_soil: Option<MovingBucketSoil>,
}

impl DigModel<ActuatorModel> {
    /// The nominal model the project ships: the default machine, the actuator networks of
    /// `config/nominal_actuator.json`, the soil and limits of `config/dig_model.toml` and the built-in
    /// Autodig maps (all compiled in).
    ///
    /// # Errors
    /// Only if a shipped file is broken (tested).
    pub fn nominal() -> Result<Self> {
        Self::new(
            &MachineConfig::default_machine()?,
            ActuatorModel::from_json(NOMINAL_ACTUATOR_JSON)?,
            AutodigMaps::builtin()?,
            DigModelConfig::nominal()?,
        )
    }
}

impl<A: ActuatorDynamics> DigModel<A> {
    /// A model for `machine` with the given actuator dynamics, Autodig maps and settings. Autodig's
    /// relief pressures and bucket capacity are set from the machine, as the controller does.
    ///
    /// # Errors
    /// [`DigModelError::Kinematics`] for an inconsistent machine, [`DigModelError::Config`] for bad
    /// settings or an actuator period that is not positive.
    pub fn new(
        machine: &MachineConfig,
        actuator: A,
        maps: AutodigMaps,
        mut config: DigModelConfig,
    ) -> Result<Self> {
        let kin = Kinematics::new(machine).map_err(DigModelError::Kinematics)?;
        let relief = machine.hydraulics.relief_pressure_pa;
        config.autodig.relief_pressure_pa = [relief; 3];
        config.autodig.perception.bucket_capacity_m3 = machine.bucket.capacity_m3;
        config.validate()?;
        let dt = actuator.dt_s();
        if !(dt.is_finite() && dt > 0.0 && dt <= 0.1) {
            return Err(DigModelError::Config {
                field: "actuator.dt_s",
                reason: format!("{dt} s; must be in (0, 0.1]"),
            });
        }
        let tables = [
            StrokeTable::new(&kin, Joint::Boom)?,
            StrokeTable::new(&kin, Joint::Stick)?,
            StrokeTable::new(&kin, Joint::Bucket)?,
        ];
        let c = &machine.cylinders;
        let cyl = [&c.boom, &c.stick, &c.bucket];
        let moving_soil = Self::moving_soil_for(&config, machine.bucket.width_m)?;
        Ok(Self {
            kin,
            tables,
            actuator,
            moving_soil,
            statics: Statics::new(machine),
            config,
            maps,
            bucket_width_m: machine.bucket.width_m,
            capacity_m3: machine.bucket.capacity_m3,
            head_area_m2: cyl.map(|c| c.head_area_m2()),
            rod_area_m2: cyl.map(|c| c.rod_area_m2()),
            tank_pa: machine.hydraulics.tank_pressure_pa.max(0.0),
            port_relief_pa: PORT_RELIEF_FACTOR * relief,
        })
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &DigModelConfig {
        &self.config
    }

    /// The actuator dynamics.
    #[must_use]
    pub fn actuator(&self) -> &A {
        &self.actuator
    }

    /// The machine's kinematics.
    #[must_use]
    pub fn kinematics(&self) -> &Kinematics {
        &self.kin
    }

    /// The same model with another actuator (e.g. one augmented with named effects).
    ///
    /// # Errors
    /// As [`DigModel::new`] for the actuator period.
    pub fn with_actuator<B: ActuatorDynamics>(self, actuator: B) -> Result<DigModel<B>> {
        let dt = actuator.dt_s();
        if !(dt.is_finite() && dt > 0.0 && dt <= 0.1) {
            return Err(DigModelError::Config {
                field: "actuator.dt_s",
                reason: format!("{dt} s; must be in (0, 0.1]"),
            });
        }
        Ok(DigModel {
            kin: self.kin,
            tables: self.tables,
            actuator,
            config: self.config,
            maps: self.maps,
            bucket_width_m: self.bucket_width_m,
            capacity_m3: self.capacity_m3,
            head_area_m2: self.head_area_m2,
            rod_area_m2: self.rod_area_m2,
            tank_pa: self.tank_pa,
            port_relief_pa: self.port_relief_pa,
            statics: self.statics,
            moving_soil: self.moving_soil,
        })
    }

    fn moving_soil_for(config: &DigModelConfig, width_m: f64) -> Result<Option<MovingBucketSoil>> {
        match &config.soil {
            SoilModel::Analytical(psi) => Ok(Some(
                MovingBucketSoil::new(psi, &config.bearing, width_m).map_err(|e| {
                    DigModelError::Config {
                        field: "soil",
                        reason: e.to_string(),
                    }
                })?,
            )),
            SoilModel::Empirical(_) => Ok(None),
        }
    }

    /// Replaces the soil model (e.g. with properties estimated online, [`crate::estimate`]).
    ///
    /// # Errors
    /// [`DigModelError::Config`] for invalid properties or coefficients (the model is unchanged).
    pub fn set_soil(&mut self, soil: SoilModel) -> Result<()> {
        let mut cfg = self.config.clone();
        cfg.soil = soil;
        cfg.validate()?;
        self.moving_soil = Self::moving_soil_for(&cfg, self.bucket_width_m)?;
        self.config = cfg;
        Ok(())
    }

    /// Sets the bearing resistance of the edge and the bucket's back (analytical soil model).
    ///
    /// # Errors
    /// [`DigModelError::Config`] for invalid parameters (the model is unchanged).
    pub fn set_bearing(&mut self, bearing: BearingParams) -> Result<()> {
        let mut cfg = self.config.clone();
        cfg.bearing = bearing;
        cfg.validate()?;
        self.moving_soil = Self::moving_soil_for(&cfg, self.bucket_width_m)?;
        self.config = cfg;
        Ok(())
    }

    /// Sets the force factor of Table 2 (multiplies the soil force).
    ///
    /// # Errors
    /// [`DigModelError::Config`] unless finite and >= 0.
    pub fn set_force_factor(&mut self, factor: f64) -> Result<()> {
        if !(factor.is_finite() && factor >= 0.0) {
            return Err(DigModelError::Config {
                field: "force_factor",
                reason: format!("{factor}; must be finite and >= 0"),
            });
        }
        self.config.force_factor = factor;
        Ok(())
    }

    /// Sets the soil hardness index Autodig uses (thesis 5.2).
    ///
    /// # Errors
    /// [`DigModelError::Config`] for a non-finite index.
    pub fn set_hardness_index(&mut self, index: f64) -> Result<()> {
        if !index.is_finite() {
            return Err(DigModelError::Config {
                field: "autodig.hardness_index",
                reason: "must be finite".to_owned(),
            });
        }
        self.config.autodig.hardness_index = index;
        Ok(())
    }

    /// The step period, s.
    #[must_use]
    pub fn dt_s(&self) -> f64 {
        self.actuator.dt_s()
    }

    /// Steps a dig of the configured time limit takes, plus one: the trace capacity that never
    /// truncates.
    #[must_use]
    pub fn max_steps(&self) -> usize {
        (self.config.max_time_s / self.dt_s()).ceil() as usize + 2
    }

    /// A trace buffer large enough for any dig of this model.
    #[must_use]
    pub fn new_trace(&self) -> DigTrace {
        DigTrace::with_capacity(self.max_steps())
    }

    /// The joint angles of a start, checked against joint limits and cylinder strokes.
    ///
    /// # Errors
    /// [`DigModelError::NonFinite`], [`DigModelError::Unreachable`].
    pub fn start_joints(&self, start: &DigStart) -> Result<JointAngles> {
        let q = match start {
            DigStart::Pose(p) => {
                if !(p.x_m.is_finite() && p.z_m.is_finite() && p.bucket_abs_rad.is_finite()) {
                    return Err(DigModelError::NonFinite { what: "start pose" });
                }
                self.kin.inverse(p).map_err(DigModelError::Unreachable)?
            }
            DigStart::Joints(q) => {
                if !(q.boom_rad.is_finite() && q.stick_rad.is_finite() && q.bucket_rad.is_finite())
                {
                    return Err(DigModelError::NonFinite {
                        what: "start joint angles",
                    });
                }
                *q
            }
        };
        self.kin
            .cylinder_lengths(&q)
            .map_err(DigModelError::Unreachable)?;
        Ok(q)
    }

    /// Predicts a dig with its trajectory.
    ///
    /// # Errors
    /// As [`Self::predict_into`].
    pub fn predict(&self, start: &DigStart, site: &DigSite) -> Result<DigPrediction> {
        let mut trace = self.new_trace();
        let summary = self.predict_into(start, site, Some(&mut trace))?;
        Ok(DigPrediction {
            summary,
            samples: trace.samples,
        })
    }

    /// Predicts a dig's statistics only (what the dig planner needs).
    ///
    /// # Errors
    /// As [`Self::predict_into`].
    pub fn evaluate(&self, start: &DigStart, site: &DigSite) -> Result<DigSummary> {
        self.predict_into(start, site, None)
    }

    /// Evaluates candidate starts over one site, the results in the order given: in parallel (rayon)
    /// with the crate's `parallel` feature, one after the other without it.
    pub fn evaluate_many(&self, starts: &[DigStart], site: &DigSite) -> Vec<Result<DigSummary>> {
        crate::par::map_indices(starts.len(), |i| self.evaluate(&starts[i], site))
    }

    /// Runs the model from `start` over `site` until Autodig ends or the time limit (thesis 4.1),
    /// recording into `trace` if given (cleared first; never grown).
    ///
    /// # Errors
    /// [`DigModelError::NonFinite`] / [`DigModelError::Unreachable`] for the start,
    /// [`DigModelError::OutsideTerrain`] if the tip leaves the section, and the errors of the actuator
    /// dynamics or Autodig (which reject NaN rather than propagate it).
    pub fn predict_into(
        &self,
        start: &DigStart,
        site: &DigSite,
        mut trace: Option<&mut DigTrace>,
    ) -> Result<DigSummary> {
        if let Some(t) = trace.as_deref_mut() {
            t.clear();
        }
        let q0 = self.start_joints(start)?;
        let lengths = self
            .kin
            .cylinder_lengths(&q0)
            .map_err(DigModelError::Unreachable)?;
        let mut len_m = [lengths.boom_m, lengths.stick_m, lengths.bucket_m];
        let profile = site.profile();
        let tip0 = self.kin.forward(&q0);
        self.check_inside(profile, tip0.x_m)?;

        let dt = self.dt_s();
        let mut act = self.actuator.initial_state()?;
        let mut autodig =
            Autodig::starting_in(self.config.autodig, self.maps.clone(), Stage::PreDig)?;
        let mut swept = SweptVolume::new(profile.clone(), self.bucket_width_m)?;
        let mut surface = CutSurface::new(profile)?;
        let density = match &self.config.soil {
            SoilModel::Analytical(p) => p.density_kg_per_m3,
            SoilModel::Empirical(_) => 0.0,
        };
        let floor_limit = site.floor_z_m - self.config.floor_tolerance_m;
        let max_steps = (self.config.max_time_s / dt).ceil() as usize;
        let factor = self.config.force_factor;

        let mut velocity = [0.0; 3];
        let mut energy_j = 0.0;
        let mut min_z = f64::INFINITY;
        let mut peak_force = 0.0_f64;
        let mut floor_penetration = false;
        let mut end = DigEnd::TimeLimit;
        let mut steps = 0usize;
        let mut time_s = 0.0;
        let mut last_tip = [tip0.x_m, tip0.z_m];
        for k in 0..=max_steps {
            time_s = k as f64 * dt;
            steps = k;
            // Actuator positions -> joint angles and moment arms (Eq. A5, A8-A19).
            let mut q_arr = [0.0; 3];
            let mut arms = [0.0; 3];
            for j in 0..3 {
                let (a, r) = self.tables[j].lookup(len_m[j]);
                q_arr[j] = a;
                arms[j] = r;
            }
            let st0 = self.statics.eval(&q_arr);
            let pose = BucketPose {
                x_m: st0.tip[0],
                z_m: st0.tip[1],
                bucket_abs_rad: q_arr[0] + q_arr[1] + q_arr[2],
            };
            self.check_inside(profile, pose.x_m)?;
            min_z = min_z.min(pose.z_m);
            floor_penetration |= pose.z_m < floor_limit;

            // Perception (3.2): swept volume and depth below the pre-dig surface.
            let swept_m3 = swept.update(pose.x_m, pose.z_m)?;
            let depth_m = swept.depth_m(pose.x_m, pose.z_m)?;
            surface.cut(last_tip, st0.tip);
            last_tip = st0.tip;

            // Soil force (Eqs. 14-18 with bearing, or Eq. 21) times the force factor (Table 2).
            let v_s = swept_m3.min(self.capacity_m3);
            let mut tip_v = [0.0; 2];
            for j in 0..3 {
                let rate = velocity[j] / arms[j];
                tip_v[0] += st0.jx[j] * rate;
                tip_v[1] += st0.jz[j] * rate;
            }
            let f = match &self.moving_soil {
                Some(soil) => soil.force(&Self::motion(&surface, &st0, tip_v, v_s))?,
                None => self.soil_force(&pose, profile, v_s)?,
            };
            let soil = TipForce {
                fx_n: factor * f.fx_n,
                fz_n: factor * f.fz_n,
                my_nm: factor * f.my_nm,
            };
            peak_force = peak_force.max(soil.fx_n.hypot(soil.fz_n));
            let payload_kg = v_s * density;

            // Statics: tau = G - J^T f (Eq. A2, A4), F = tau / r (Eqs. A7, A19).
            let gravity = st0.gravity_with_payload(payload_kg);
            let mut force_n = [0.0; 3];
            let mut head_pa = [0.0; 3];
            let mut rod_pa = [0.0; 3];
            let mut extension = [0.0; 3];
            for j in 0..3 {
                let tau = gravity[j] - (st0.jx[j] * soil.fx_n + st0.jz[j] * soil.fz_n + soil.my_nm);
                let f = tau / arms[j];
                if !f.is_finite() {
                    return Err(DigModelError::NonFinite {
                        what: "cylinder force",
                    });
                }
                // The cylinder cannot hold more than its port relief allows.
                force_n[j] = f.clamp(
                    -self.port_relief_pa * self.rod_area_m2[j],
                    self.port_relief_pa * self.head_area_m2[j],
                );
                (head_pa[j], rod_pa[j]) = self.pressures(j, force_n[j]);
                let t = &self.tables[j];
                extension[j] = ((len_m[j] - t.lo_m) / (t.hi_m - t.lo_m)).clamp(0.0, 1.0);
            }

            let inputs = AutodigInputs {
                joint_rad: q_arr,
                head_pressure_pa: head_pa,
                rod_pressure_pa: rod_pa,
                extension_fraction: extension,
                swept_volume_m3: Some(swept_m3),
                bucket_depth_m: Some(depth_m),
            };
            let out = autodig.step(&inputs, time_s)?;
            if let Some(t) = trace.as_deref_mut() {
                t.push(DigSample {
                    time_s,
                    stage: out.stage,
                    tip_x_m: pose.x_m,
                    tip_z_m: pose.z_m,
                    bucket_abs_rad: pose.bucket_abs_rad,
                    joint_rad: q_arr,
                    command: out.command,
                    head_pa,
                    rod_pa,
                    force_n,
                    velocity_m_per_s: velocity,
                    soil_force: soil,
                    swept_volume_m3: swept_m3,
                });
            }
            if out.stage == Stage::Done {
                end = out.end_reason.map_or(DigEnd::TimeLimit, DigEnd::Autodig);
                break;
            }
            if k == max_steps {
                break;
            }
            // Actuators (Eq. 4): next velocities, integrated (trapezoid) to cylinder lengths.
            let next = self.actuator.step(&mut act, out.command, force_n)?;
            for j in 0..3 {
                if !next[j].is_finite() {
                    return Err(DigModelError::NonFinite {
                        what: "actuator velocity",
                    });
                }
                let t = &self.tables[j];
                let new_len = (len_m[j] + 0.5 * (velocity[j] + next[j]) * dt).clamp(t.lo_m, t.hi_m);
                energy_j += (force_n[j] * (new_len - len_m[j])).abs();
                len_m[j] = new_len;
            }
            velocity = next;
        }
        Ok(DigSummary {
            time_s,
            energy_j,
            swept_volume_m3: swept.volume_m3(),
            floor_penetration,
            min_tip_z_m: min_z,
            end,
            steps,
            peak_soil_force_n: peak_force,
        })
    }

    /// The bucket's motion over the current (cut) surface, measured as the simulator's soil contact
    /// does: depth below the higher of the surface at the tip and 0.15 m ahead in the direction of
    /// travel, slope over +-0.25 m.
    #[inline]
    fn motion(surface: &CutSurface, st: &PoseStatics, tip_v: [f64; 2], v_s: f64) -> BucketMotion {
        let [x, z] = st.tip;
        let ahead = if tip_v[0] > 0.0 { 0.15 } else { -0.15 };
        let top = surface.height(x).max(surface.height(x + ahead));
        BucketMotion {
            sin_bucket_abs: st.sin_bucket_abs,
            cos_bucket_abs: st.cos_bucket_abs,
            tip_velocity_m_per_s: tip_v,
            vertical_depth_m: top - z,
            slope_tan: (surface.height(x + 0.25) - surface.height(x - 0.25)) / 0.5,
            swept_volume_m3: v_s,
        }
    }

    /// The soil force the model applies (before the force factor) to a bucket at `q` moving with
    /// cylinder velocities `velocity_m_per_s` over `surface_profile` (the current terrain along the
    /// digging plane), with `swept_volume_m3` in the bucket (capped at the capacity). For diagnostics:
    /// comparing the model's soil force with measured forces along a recorded dig.
    ///
    /// # Errors
    /// [`DigModelError::Kinematics`] for a pose outside the strokes, [`DigModelError::Soil`],
    /// [`DigModelError::Terrain`].
    pub fn soil_force_at(
        &self,
        q: &JointAngles,
        velocity_m_per_s: [f64; 3],
        surface_profile: &SectionProfile,
        swept_volume_m3: f64,
    ) -> Result<TipForce> {
        let arms = self.kin.moment_arms(q).map_err(DigModelError::Kinematics)?;
        let q_arr = [q.boom_rad, q.stick_rad, q.bucket_rad];
        let st = self.statics.eval(&q_arr);
        let mut tip_v = [0.0; 2];
        for j in 0..3 {
            let rate = velocity_m_per_s[j] / arms[j];
            tip_v[0] += st.jx[j] * rate;
            tip_v[1] += st.jz[j] * rate;
        }
        let v_s = swept_volume_m3.min(self.capacity_m3);
        match &self.moving_soil {
            Some(soil) => Ok(soil.force(&Self::motion(
                &CutSurface::new(surface_profile)?,
                &st,
                tip_v,
                v_s,
            ))?),
            None => {
                let pose = self.kin.forward(q);
                self.soil_force(&pose, surface_profile, v_s)
            }
        }
    }

    fn check_inside(&self, profile: &SectionProfile, r_m: f64) -> Result<()> {
        if !r_m.is_finite() {
            return Err(DigModelError::NonFinite {
                what: "tip position",
            });
        }
        if r_m < profile.r_start_m() || r_m > profile.r_end_m() {
            return Err(DigModelError::OutsideTerrain {
                r_m,
                r_start_m: profile.r_start_m(),
                r_end_m: profile.r_end_m(),
            });
        }
        Ok(())
    }

    /// The soil force of the empirical model (Eq. 21) at the pre-dig geometry, before the force factor.
    /// (The analytical model goes through [`MovingBucketSoil`], which also knows the direction of
    /// travel, the wedge-limit saturation and the bearing resistance.)
    #[inline]
    fn soil_force(
        &self,
        pose: &BucketPose,
        profile: &SectionProfile,
        v_s: f64,
    ) -> Result<TipForce> {
        let Contact::InContact(gamma) = dig_geometry(pose, profile, v_s)? else {
            return Ok(TipForce::default());
        };
        let f = match &self.config.soil {
            // Eq. 19's moment is carried by the payload term of Eq. A4 (module docs): x_c = 0 here.
            SoilModel::Analytical(psi) => {
                match fee_tip_force(psi, &gamma, self.bucket_width_m, 0.0) {
                    Ok(f) => f,
                    Err(SoilError::Singular { .. }) => TipForce::default(),
                    Err(e) => return Err(e.into()),
                }
            }
            SoilModel::Empirical(m) => m.evaluate(&gamma)?, // Eq. 21
        };
        Ok(f)
    }

    /// Head and rod pressure for a cylinder force (module docs: the static split, inverse of Eq. A20).
    #[inline]
    fn pressures(&self, j: usize, force_n: f64) -> (f64, f64) {
        let (ah, ar, pt) = (self.head_area_m2[j], self.rod_area_m2[j], self.tank_pa);
        let (head, rod) = if force_n >= 0.0 {
            ((force_n + pt * ar) / ah, pt)
        } else {
            (pt, (-force_n + pt * ah) / ar)
        };
        (
            head.clamp(0.0, self.port_relief_pa),
            rod.clamp(0.0, self.port_relief_pa),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::MachinePose;
    use crate::soil::{EmpiricalSoilModel, SoilProperties};
    use crate::terrain::TerrainGrid;

    /// The default bench (config/bench.toml) seen from the machine at the origin: floor at 0, a
    /// 45 degree face from 3 m to the 2 m top at 5 m.
    fn bench_height(r: f64) -> f64 {
        (r - 3.0).clamp(0.0, 2.0)
    }

    const START_R_M: f64 = 7.8;
    const START_BUCKET_DEG: f64 = -55.0;
    const START_DEPTH_M: f64 = 0.02;

    fn site() -> DigSite {
        let p = SectionProfile::from_fn(0.5, 12.0, 0.05, bench_height).expect("profile");
        DigSite::new(p, 0.0).expect("site")
    }

    fn start() -> DigStart {
        DigStart::Pose(BucketPose {
            x_m: START_R_M,
            z_m: bench_height(START_R_M) - START_DEPTH_M,
            bucket_abs_rad: START_BUCKET_DEG.to_radians(),
        })
    }

    const _: () = {
        const fn assert_send_sync<T: Send + Sync>() {}
        assert_send_sync::<DigModel>();
        assert_send_sync::<DigSite>();
        assert_send_sync::<DigPrediction>();
    };

    #[test]
    fn fused_statics_equal_the_kinematics_functions() {
        let machine = MachineConfig::default_machine().expect("machine");
        let kin = Kinematics::new(&machine).expect("kin");
        let st = Statics::new(&machine);
        for (k, payload) in [(0, 0.0), (1, 800.0), (2, 2500.0), (3, 100.0)] {
            let q = JointAngles {
                boom_rad: -0.4 + 0.3 * f64::from(k),
                stick_rad: -1.9 + 0.25 * f64::from(k),
                bucket_rad: -1.5 + 0.6 * f64::from(k),
            };
            let e = st.eval(&[q.boom_rad, q.stick_rad, q.bucket_rad]);
            let gravity = e.gravity_with_payload(payload);
            let pose = kin.forward(&q);
            assert!((e.tip[0] - pose.x_m).abs() < 1e-12 && (e.tip[1] - pose.z_m).abs() < 1e-12);
            assert!((e.sin_bucket_abs - pose.bucket_abs_rad.sin()).abs() < 1e-12);
            let j = kin.jacobian(&q);
            let g = kin.gravity_torques(&q, payload);
            for c in 0..3 {
                assert!((e.jx[c] - j[(0, c)]).abs() < 1e-12);
                assert!((e.jz[c] - j[(1, c)]).abs() < 1e-12);
                assert!((gravity[c] - g[c]).abs() < 1e-9 * g[c].abs().max(1.0));
            }
        }
    }

    #[test]
    fn cut_surface_follows_the_tip_path_below_the_section() {
        let p = SectionProfile::from_fn(0.0, 10.0, 0.05, |_| 1.0).expect("profile");
        let mut c = CutSurface::new(&p).expect("surface");
        c.cut([8.0, 0.5], [7.0, 0.7]);
        assert!((c.height(7.5) - 0.6).abs() < 1e-9);
        assert!((c.height(8.5) - 1.0).abs() < 1e-12 && (c.height(6.5) - 1.0).abs() < 1e-12);
        // Above the surface nothing changes; beyond the section the end samples hold.
        c.cut([5.0, 2.0], [4.0, 2.0]);
        assert!((c.height(4.5) - 1.0).abs() < 1e-12);
        assert!((c.height(-3.0) - 1.0).abs() < 1e-12 && (c.height(30.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn nominal_model_loads_from_the_shipped_files() {
        let m = DigModel::nominal().expect("nominal");
        assert!((m.dt_s() - 0.01).abs() < 1e-12);
        assert!(matches!(m.config().soil, SoilModel::Analytical(_)));
        assert_eq!(m.config().force_factor, 1.0);
    }

    #[test]
    fn a_dig_on_the_default_bench_fills_a_reasonable_volume() {
        let m = DigModel::nominal().expect("nominal");
        let p = m.predict(&start(), &site()).expect("prediction");
        let s = p.summary;
        assert!(matches!(s.end, DigEnd::Autodig(_)), "{s:?}");
        assert!((0.5..3.0).contains(&s.swept_volume_m3), "{s:?}");
        assert!((1.5..15.0).contains(&s.time_s), "{s:?}");
        assert!(s.energy_kj() > 10.0 && s.energy_kj() < 1000.0, "{s:?}");
        assert!(!s.floor_penetration, "{s:?}");
        assert_eq!(p.samples.len(), s.steps + 1);
        assert!(p.samples.iter().all(|x| x.tip_x_m.is_finite()
            && x.tip_z_m.is_finite()
            && x.head_pa.iter().chain(&x.rod_pa).all(|v| v.is_finite())));
        // The tip ends nearer the machine than it started, and the dig went below the surface.
        let last = p.samples.last().expect("samples");
        assert!(last.tip_x_m < START_R_M, "{last:?}");
        assert!(s.min_tip_z_m < bench_height(START_R_M) - 0.2, "{s:?}");
    }

    #[test]
    fn predictions_are_deterministic_and_parallel_evaluation_matches() {
        let m = DigModel::nominal().expect("nominal");
        let a = m.predict(&start(), &site()).expect("a");
        let b = m.predict(&start(), &site()).expect("b");
        assert_eq!(a, b);
        let starts: Vec<DigStart> = (0..6)
            .map(|i| {
                let r = 5.8 + 0.3 * f64::from(i);
                DigStart::Pose(BucketPose {
                    x_m: r,
                    z_m: bench_height(r) - START_DEPTH_M,
                    bucket_abs_rad: START_BUCKET_DEG.to_radians(),
                })
            })
            .collect();
        let par = m.evaluate_many(&starts, &site());
        for (s, p) in starts.iter().zip(&par) {
            assert_eq!(&m.evaluate(s, &site()), p);
        }
        assert_eq!(par[0], m.evaluate(&starts[0], &site()));
        // A trace buffer is reused without growing.
        let mut trace = DigTrace::with_capacity(10);
        let s = m
            .predict_into(&start(), &site(), Some(&mut trace))
            .expect("short");
        assert_eq!(trace.samples().len(), 10);
        assert!(trace.truncated() && s.steps > 10);
    }

    #[test]
    fn floor_penetration_is_flagged_below_floor_minus_tolerance() {
        let m = DigModel::nominal().expect("nominal");
        let deep = m.evaluate(&start(), &site()).expect("dig");
        let floor_above =
            DigSite::new(site().profile().clone(), deep.min_tip_z_m + 0.2).expect("site");
        assert!(
            m.evaluate(&start(), &floor_above)
                .expect("dig")
                .floor_penetration
        );
        let floor_just_above = DigSite::new(
            site().profile().clone(),
            deep.min_tip_z_m + 0.5 * m.config().floor_tolerance_m,
        )
        .expect("site");
        assert!(
            !m.evaluate(&start(), &floor_just_above)
                .expect("dig")
                .floor_penetration
        );
    }

    #[test]
    fn bad_input_gives_typed_errors() {
        let mut m = DigModel::nominal().expect("nominal");
        let nan = DigStart::Pose(BucketPose {
            x_m: f64::NAN,
            z_m: 1.0,
            bucket_abs_rad: -1.5,
        });
        assert!(matches!(
            m.evaluate(&nan, &site()),
            Err(DigModelError::NonFinite { .. })
        ));
        let far = DigStart::Pose(BucketPose {
            x_m: 30.0,
            z_m: 0.0,
            bucket_abs_rad: -1.5,
        });
        assert!(matches!(
            m.evaluate(&far, &site()),
            Err(DigModelError::Unreachable(_))
        ));
        let bent = DigStart::Joints(JointAngles {
            boom_rad: 3.0,
            stick_rad: 0.0,
            bucket_rad: 0.0,
        });
        assert!(matches!(
            m.evaluate(&bent, &site()),
            Err(DigModelError::Unreachable(_))
        ));
        // A section that stops short of the tip: a gap in the terrain.
        let short = DigSite::new(
            SectionProfile::from_fn(0.5, 4.0, 0.05, bench_height).expect("p"),
            0.0,
        )
        .expect("site");
        assert!(matches!(
            m.evaluate(&start(), &short),
            Err(DigModelError::OutsideTerrain { .. })
        ));
        assert!(DigSite::new(site().profile().clone(), f64::NAN).is_err());
        assert!(SectionProfile::new(0.0, 0.1, vec![]).is_err());
        assert!(SectionProfile::new(0.0, 0.1, vec![1.0, f64::NAN]).is_err());
        // Unknown cells in a grid are a typed error, not a guessed section.
        let mut grid = TerrainGrid::new_flat(-1.0, -2.0, 0.1, 140, 40, 0.0).expect("grid");
        grid.set_cell(60, 20, None).expect("gap");
        let pose = MachinePose {
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: 0.0,
        };
        assert!(matches!(
            DigSite::from_grid(&grid, &pose, 0.0, 1.0, 12.0, 0.05, 0.0),
            Err(DigModelError::Terrain(_))
        ));
        assert!(m.set_force_factor(f64::NAN).is_err());
        assert!(m.set_force_factor(-1.0).is_err());
        assert!(m.set_hardness_index(f64::INFINITY).is_err());
        let bad_soil = SoilProperties {
            failure_angle_rad: f64::NAN,
            ..SoilProperties::typical()
        };
        assert!(m.set_soil(SoilModel::Analytical(bad_soil)).is_err());
        assert!(DigModelConfig::from_toml_str("force_factor = 1").is_err());
        // Whatever the force factor, results stay finite (the cylinders saturate at relief).
        for factor in [0.0, 1.0, 3.0, 50.0] {
            m.set_force_factor(factor).expect("factor");
            let s = m.evaluate(&start(), &site()).expect("dig");
            assert!(
                s.time_s.is_finite() && s.energy_j.is_finite() && s.swept_volume_m3.is_finite()
            );
        }
    }

    #[test]
    fn empirical_soil_model_runs_and_force_factor_scales_the_soil_force() {
        let mut m = DigModel::nominal().expect("nominal");
        let base = m.predict(&start(), &site()).expect("dig");
        m.set_force_factor(2.0).expect("factor");
        let doubled = m.predict(&start(), &site()).expect("dig");
        // Same first contact step: twice the soil force.
        let first = |p: &DigPrediction| {
            p.samples
                .iter()
                .find(|s| s.soil_force.fx_n.abs() > 1.0)
                .copied()
                .expect("contact")
        };
        let (a, b) = (first(&base), first(&doubled));
        assert_eq!(a.time_s, b.time_s);
        assert!(
            (b.soil_force.fx_n - 2.0 * a.soil_force.fx_n).abs() < 1e-6 * a.soil_force.fx_n.abs()
        );
        m.set_soil(SoilModel::Empirical(EmpiricalSoilModel {
            fx: [2.0e4, 1.0e4, 5.0e3, 3.0e4],
            fz: [-1.0e4, -5.0e3, 0.0, -2.0e4],
            my: [0.0, 0.0, 0.0, -8.0e3],
        }))
        .expect("soil");
        let e = m.evaluate(&start(), &site()).expect("empirical dig");
        assert!(e.time_s > 0.0 && e.swept_volume_m3 > 0.0, "{e:?}");
    }
}
