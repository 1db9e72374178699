//! State estimation from the gateway's sensing frames (thesis Appendix A.2).
//!
//! The [`Estimator`] is fed decoded messages with their receive time ([`Estimator::on_message`]) and,
//! once per control step, derives the quantities the controller needs ([`Estimator::update`]):
//!
//! - joint angles (resolvers) and low-pass filtered joint rates;
//! - cylinder head and rod pressures, cylinder lengths and extension fractions;
//! - cylinder forces `F = p_head A_head - p_rod A_rod` (Eq. A20), joint torques `tau = F r` (Eqs. A21,
//!   A22, with the signed moment arm `r = dL/dtheta` of `planner::kinematics`) and the bucket-tip force
//!   (soil on bucket) `f = J^-T (G - tau)` (Eq. A23, sign convention of docs/ARCHITECTURE.md);
//! - the tip pose by forward kinematics, pump pressures, track odometry and the machine's world pose
//!   dead-reckoned from the odometry;
//! - the static payload estimate used to weigh the bucket after Capture (thesis 6.1: "a static analysis
//!   on the linkage using cylinder pressures"): with the tip force zero, `tau = G(q, m)` (Eqs. A2, A4) is
//!   linear in the payload mass `m`, solved by least squares over the three joints.
//!
//! Every signal keeps the time it was last received ([`Estimator::age_s`]) so the safety layer can
//! detect stale or missing data. The gateway status also keeps when its 8-bit alive counter last
//! changed ([`Estimator::gateway_alive_age_s`]): a gateway that repeats a frozen status keeps the
//! status fresh by age, but not alive. Nothing here allocates after construction or panics.

use firmware_bridge::messages::{Cylinder, GatewayStatus, Message, is_next_alive};
use nalgebra::Vector3;
use planner::kinematics::{BucketPose, Joint, JointAngles, Kinematics, MachinePose, TipForce};
use planner::machine::GRAVITY_M_PER_S2;
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::check::{Limits, ParamError, check};

/// A signal the estimator tracks, with its own receive timestamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Signal {
    /// Resolver joint angles.
    JointAngles,
    /// Joint rates.
    JointRates,
    /// Boom cylinder port pressures.
    BoomPressure,
    /// Stick cylinder port pressures.
    StickPressure,
    /// Bucket cylinder port pressures.
    BucketPressure,
    /// Pump pressures.
    PumpPressures,
    /// Track odometry.
    TrackOdometry,
    /// Gateway status.
    GatewayStatus,
}

impl Signal {
    /// Every signal, in slot order.
    pub const ALL: [Signal; 8] = [
        Signal::JointAngles,
        Signal::JointRates,
        Signal::BoomPressure,
        Signal::StickPressure,
        Signal::BucketPressure,
        Signal::PumpPressures,
        Signal::TrackOdometry,
        Signal::GatewayStatus,
    ];

    /// The signals the control loop needs every period (100 Hz on the bus).
    pub const CONTROL: [Signal; 5] = [
        Signal::JointAngles,
        Signal::JointRates,
        Signal::BoomPressure,
        Signal::StickPressure,
        Signal::BucketPressure,
    ];

    const fn slot(self) -> usize {
        self as usize
    }

    fn pressure(cylinder: Cylinder) -> Self {
        match cylinder {
            Cylinder::Boom => Self::BoomPressure,
            Cylinder::Stick => Self::StickPressure,
            Cylinder::Bucket => Self::BucketPressure,
        }
    }
}

impl std::fmt::Display for Signal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Signal::JointAngles => "joint angles",
            Signal::JointRates => "joint rates",
            Signal::BoomPressure => "boom pressures",
            Signal::StickPressure => "stick pressures",
            Signal::BucketPressure => "bucket pressures",
            Signal::PumpPressures => "pump pressures",
            Signal::TrackOdometry => "track odometry",
            Signal::GatewayStatus => "gateway status",
        })
    }
}

/// Estimator parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorConfig {
    /// Time constant of the first-order low-pass filter on the joint rates, s. Default 0.03.
    pub rate_filter_time_constant_s: f64,
    /// The machine's world pose when the odometry first arrives (tracking dead-reckons from it).
    pub initial_pose: MachinePose,
    /// The static weighing leaves out a joint whose cylinder is within this extension fraction of a
    /// stroke end: the end stop then carries part of that joint's load (after Capture the bucket
    /// cylinder is typically at its end stop with relief pressure trapped in the head). Default 0.01.
    pub weigh_stroke_end_margin: f64,
}

impl EstimatorConfig {
    /// Checks that every parameter is finite and in range.
    ///
    /// # Errors
    /// The first [`ParamError`] (section `estimator`).
    pub fn validate(&self) -> Result<(), ParamError> {
        const S: &str = "estimator";
        check(
            S,
            "rate_filter_time_constant_s",
            self.rate_filter_time_constant_s,
            Limits::closed(0.0, 1.0, "s"),
            "",
        )?;
        // A negative margin counts every joint, end stops included (kept for experiments).
        check(
            S,
            "weigh_stroke_end_margin",
            self.weigh_stroke_end_margin,
            Limits::below(-1.0, 0.5, ""),
            "a fraction of the stroke",
        )?;
        let pose = &self.initial_pose;
        for (key, v) in [
            ("initial_pose.x_m", pose.x_m),
            ("initial_pose.y_m", pose.y_m),
        ] {
            check(S, key, v, Limits::closed(-1.0e6, 1.0e6, "m"), "")?;
        }
        check(
            S,
            "initial_pose.heading_rad",
            pose.heading_rad,
            Limits::closed(-10.0, 10.0, "rad"),
            "",
        )
    }
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            rate_filter_time_constant_s: 0.03,
            initial_pose: MachinePose::default(),
            weigh_stroke_end_margin: 0.01,
        }
    }
}

/// The estimated machine state. Arrays are `[boom, stick, bucket]` unless noted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineState {
    /// Implement joint angles, rad.
    pub joints: JointAngles,
    /// Swing angle, rad.
    pub swing_rad: f64,
    /// Filtered joint rates `[boom, stick, bucket, swing]`, rad/s.
    pub rates_rad_per_s: [f64; 4],
    /// Head-port pressures, Pa.
    pub head_pressure_pa: [f64; 3],
    /// Rod-port pressures, Pa.
    pub rod_pressure_pa: [f64; 3],
    /// Cylinder lengths (pin to pin), m.
    pub cylinder_length_m: [f64; 3],
    /// Cylinder extension fractions, 0 retracted, 1 extended.
    pub extension_fraction: [f64; 3],
    /// Cylinder forces, N, positive pushes toward extension (Eq. A20).
    pub cylinder_force_n: [f64; 3],
    /// Joint torques from the cylinder forces, N m (Eqs. A21, A22).
    pub joint_torque_nm: [f64; 3],
    /// Bucket-tip force, soil on bucket, base frame (Eq. A23), with an empty bucket; `None` where the
    /// Jacobian is singular or the linkage cannot be evaluated.
    pub tip_force: Option<TipForce>,
    /// Bucket tip pose in the base frame (forward kinematics).
    pub tip: BucketPose,
    /// Pump pressures `[pump1, pump2]`, Pa.
    pub pump_pressure_pa: [f64; 2],
    /// Track travel since gateway power-up `[left, right]`, m (backwards negative).
    pub track_travel_m: [f64; 2],
    /// The machine's world pose, dead-reckoned from the odometry.
    pub pose: MachinePose,
    /// The last gateway status.
    pub gateway: Option<GatewayStatus>,
    /// Whether the derived quantities (lengths, forces, tip) are valid for the current angles.
    pub derived_valid: bool,
}

impl Default for MachineState {
    fn default() -> Self {
        Self {
            joints: JointAngles::default(),
            swing_rad: 0.0,
            rates_rad_per_s: [0.0; 4],
            head_pressure_pa: [0.0; 3],
            rod_pressure_pa: [0.0; 3],
            cylinder_length_m: [0.0; 3],
            extension_fraction: [0.0; 3],
            cylinder_force_n: [0.0; 3],
            joint_torque_nm: [0.0; 3],
            tip_force: None,
            tip: BucketPose::default(),
            pump_pressure_pa: [0.0; 2],
            track_travel_m: [0.0; 2],
            pose: MachinePose::default(),
            gateway: None,
            derived_valid: false,
        }
    }
}

/// The angle of one implement joint.
pub fn joint_angle(q: &JointAngles, joint: Joint) -> f64 {
    match joint {
        Joint::Boom => q.boom_rad,
        Joint::Stick => q.stick_rad,
        Joint::Bucket => q.bucket_rad,
    }
}

/// The state estimator.
#[derive(Debug, Clone)]
pub struct Estimator {
    kin: Kinematics,
    config: EstimatorConfig,
    gauge_m: f64,
    state: MachineState,
    received_s: [Option<f64>; Signal::ALL.len()],
    odometry_origin_m: Option<[f64; 2]>,
    /// The last gateway status alive counter and when it last changed (bus time, s).
    gateway_alive: Option<(u8, f64)>,
    gateway_alive_errors: u64,
}

impl Estimator {
    /// An estimator for the machine described by `kin`; `gauge_m` is the track gauge (for the heading
    /// change of differential tracking).
    ///
    /// # Errors
    /// [`ControllerError::Config`] for a parameter [`EstimatorConfig::validate`] refuses.
    pub fn new(
        kin: Kinematics,
        gauge_m: f64,
        config: EstimatorConfig,
    ) -> Result<Self, ControllerError> {
        config.validate()?;
        let mut state = MachineState {
            pose: config.initial_pose,
            ..MachineState::default()
        };
        state.tip = kin.forward(&state.joints);
        Ok(Self {
            kin,
            config,
            gauge_m: if gauge_m.is_finite() && gauge_m > 0.1 {
                gauge_m
            } else {
                2.0
            },
            state,
            received_s: [None; Signal::ALL.len()],
            odometry_origin_m: None,
            gateway_alive: None,
            gateway_alive_errors: 0,
        })
    }

    /// The kinematics in use.
    pub fn kinematics(&self) -> &Kinematics {
        &self.kin
    }

    /// The track odometry reading `[left, right]` (m) the dead-reckoned pose belongs to, once one
    /// arrived.
    pub fn odometry_m(&self) -> Option<[f64; 2]> {
        self.odometry_origin_m.map(|_| self.state.track_travel_m)
    }

    /// Continues the dead reckoning of a saved session: the machine stood at `pose` when the track
    /// odometry read `odometry_m`, so the next readings move it on from there as if this estimator
    /// had run throughout (a controller restarted while the gateway kept counting). Without a saved
    /// reading the reckoning starts at `pose` from the first reading.
    pub fn continue_from(&mut self, pose: MachinePose, odometry_m: Option<[f64; 2]>) {
        self.config.initial_pose = pose;
        self.state.pose = pose;
        self.odometry_origin_m = odometry_m;
    }

    /// The current estimate.
    pub fn state(&self) -> &MachineState {
        &self.state
    }

    /// When `signal` was last received (bus time, s).
    pub fn last_received_s(&self, signal: Signal) -> Option<f64> {
        self.received_s[signal.slot()]
    }

    /// Age of `signal` at `now_s`, s; infinite if never received.
    pub fn age_s(&self, signal: Signal, now_s: f64) -> f64 {
        self.received_s[signal.slot()].map_or(f64::INFINITY, |t| now_s - t)
    }

    /// How long the gateway status alive counter has not changed at `now_s`, s: 0 right after a
    /// status with a new counter, growing while the gateway repeats the same one; infinite if no status
    /// ever arrived.
    pub fn gateway_alive_age_s(&self, now_s: f64) -> f64 {
        self.gateway_alive
            .map_or(f64::INFINITY, |(_, changed_s)| now_s - changed_s)
    }

    /// The last gateway status alive counter.
    pub fn gateway_alive_counter(&self) -> Option<u8> {
        self.gateway_alive.map(|(counter, _)| counter)
    }

    /// Gateway status frames whose alive counter was not the successor of the previous one (repeated
    /// or skipped): lost or duplicated status frames, for logs.
    pub fn gateway_alive_errors(&self) -> u64 {
        self.gateway_alive_errors
    }

    /// The oldest of the control signals ([`Signal::CONTROL`]) at `now_s` and its age.
    pub fn stalest_control_signal(&self, now_s: f64) -> (Signal, f64) {
        let mut worst = (Signal::JointAngles, f64::NEG_INFINITY);
        for s in Signal::CONTROL {
            let age = self.age_s(s, now_s);
            // NaN ages (non-finite timestamps) count as stale.
            if age.is_nan() || age > worst.1 {
                worst = (s, if age.is_nan() { f64::INFINITY } else { age });
            }
        }
        worst
    }

    /// Takes one decoded message from the gateway received at `time_s`. Returns whether it was a sensing
    /// or status message the estimator consumed. Non-finite values are not stored, so the signal goes
    /// stale instead.
    pub fn on_message(&mut self, message: &Message, time_s: f64) -> bool {
        let s = &mut self.state;
        let signal = match message {
            Message::JointAngles(a) => {
                let v = [a.boom_rad, a.stick_rad, a.bucket_rad, a.swing_rad];
                if !v.iter().all(|x| x.is_finite()) {
                    return true;
                }
                s.joints = JointAngles {
                    boom_rad: a.boom_rad,
                    stick_rad: a.stick_rad,
                    bucket_rad: a.bucket_rad,
                };
                s.swing_rad = a.swing_rad;
                Signal::JointAngles
            }
            Message::JointRates(r) => {
                let raw = [
                    r.boom_rad_per_s,
                    r.stick_rad_per_s,
                    r.bucket_rad_per_s,
                    r.swing_rad_per_s,
                ];
                if !raw.iter().all(|x| x.is_finite()) {
                    return true;
                }
                let tau = self.config.rate_filter_time_constant_s.max(0.0);
                let alpha = match self.received_s[Signal::JointRates.slot()] {
                    Some(prev) if tau > 0.0 => {
                        let dt = (time_s - prev).clamp(0.0, 1.0);
                        dt / (tau + dt)
                    }
                    _ => 1.0,
                };
                for (f, x) in s.rates_rad_per_s.iter_mut().zip(raw) {
                    *f += alpha * (x - *f);
                }
                Signal::JointRates
            }
            Message::AuxValveMeasured(m) => {
                if !(m.head_pressure_pa.is_finite() && m.rod_pressure_pa.is_finite()) {
                    return true;
                }
                let i = usize::from(m.cylinder.number());
                if let (Some(h), Some(r)) =
                    (s.head_pressure_pa.get_mut(i), s.rod_pressure_pa.get_mut(i))
                {
                    *h = m.head_pressure_pa;
                    *r = m.rod_pressure_pa;
                }
                Signal::pressure(m.cylinder)
            }
            Message::PumpPressures(p) => {
                s.pump_pressure_pa = [p.pump1_pa, p.pump2_pa];
                Signal::PumpPressures
            }
            Message::TrackOdometry(o) => {
                if !(o.left_m.is_finite() && o.right_m.is_finite()) {
                    return true;
                }
                let origin = *self.odometry_origin_m.get_or_insert([o.left_m, o.right_m]);
                s.track_travel_m = [o.left_m, o.right_m];
                let left = o.left_m - origin[0];
                let right = o.right_m - origin[1];
                // Straight-line dead reckoning along the mean heading; tracking here is straight
                // backwards, so the arc approximation is exact enough.
                let init = self.config.initial_pose;
                let dheading = (right - left) / self.gauge_m;
                let heading = init.heading_rad + dheading;
                let mid = init.heading_rad + 0.5 * dheading;
                let travel = 0.5 * (left + right);
                s.pose = MachinePose {
                    x_m: init.x_m + travel * mid.cos(),
                    y_m: init.y_m + travel * mid.sin(),
                    heading_rad: heading,
                };
                Signal::TrackOdometry
            }
            Message::GatewayStatus(g) => {
                s.gateway = Some(*g);
                self.gateway_alive = match self.gateway_alive {
                    // The same counter again: received, but the gateway did not move on.
                    Some((prev, changed_s)) if prev == g.alive_counter => {
                        self.gateway_alive_errors += 1;
                        Some((prev, changed_s))
                    }
                    Some((prev, _)) => {
                        if !is_next_alive(prev, g.alive_counter, 8) {
                            self.gateway_alive_errors += 1;
                        }
                        Some((g.alive_counter, time_s))
                    }
                    None => Some((g.alive_counter, time_s)),
                };
                Signal::GatewayStatus
            }
            Message::AuxValveCommand(_)
            | Message::PositionSetpoint(_)
            | Message::ControllerHeartbeat(_)
            | Message::GatewaySession(_)
            | Message::ControllerStatus(_)
            | Message::AddressClaimed(_)
            | Message::RequestPgn(_)
            | Message::Dm1(_) => return false,
        };
        self.received_s[signal.slot()] = Some(time_s);
        true
    }

    /// Recomputes the derived quantities (lengths, forces, torques, tip force and pose) from the latest
    /// angles and pressures. Call once per control step after feeding the frames.
    pub fn update(&mut self) {
        let s = &mut self.state;
        let q = s.joints;
        s.tip = self.kin.forward(&q);
        let head = Vector3::from(s.head_pressure_pa);
        let rod = Vector3::from(s.rod_pressure_pa);
        let force = self.kin.cylinder_forces_from_pressures(&head, &rod); // Eq. A20
        s.cylinder_force_n = [force[0], force[1], force[2]];
        let mut valid = true;
        for joint in Joint::ALL {
            let i = joint.index();
            match self.kin.cylinder_length(joint, joint_angle(&q, joint)) {
                Ok(len) if len.is_finite() => {
                    let (lo, hi) = self.kin.stroke(joint);
                    s.cylinder_length_m[i] = len;
                    s.extension_fraction[i] = if hi > lo {
                        ((len - lo) / (hi - lo)).clamp(-0.5, 1.5)
                    } else {
                        0.5
                    };
                }
                _ => valid = false,
            }
        }
        match self.kin.joint_torques_from_cylinder_forces(&q, &force) {
            // Eqs. A21, A22
            Ok(tau) => {
                s.joint_torque_nm = [tau[0], tau[1], tau[2]];
                // Eq. A23; the payload is unknown while digging and its weight is small against the
                // digging forces (thesis 3.2), so the empty-bucket gravity model is used.
                s.tip_force = self.kin.tip_force_from_joint_torques(&q, &tau, 0.0).ok();
            }
            Err(_) => {
                valid = false;
                s.tip_force = None;
            }
        }
        s.derived_valid = valid;
    }

    /// Static payload estimate, kg: with the bucket still and clear of the ground the tip force is zero,
    /// so the measured joint torques equal the gravity torques `G(q, m)` (Eqs. A2, A4), which are linear
    /// in the payload mass `m`; least squares over the joints whose cylinder is off its end stops.
    ///
    /// A cylinder at a stroke end does not carry its joint's load alone (the end stop takes a share, and
    /// a valve closed after the cylinder was driven into the stop traps up to relief pressure), so that
    /// joint is left out. An end stop between two links is an internal force of the links beyond the
    /// joints closer to the base, so their equations stay exact: after Capture (bucket curled into its
    /// stop) the boom and stick torques alone weigh the payload. `None` if the derived state is invalid,
    /// every joint is at an end stop, or the payload has no lever arm.
    ///
    /// Static means still: the hydraulic oil columns let the implement oscillate for seconds after the
    /// valves close (at about 2 Hz on the default machine, boom pressure swinging by +-30 % of the
    /// static value), so average this over whole oscillation periods (the work cycle's Weigh window).
    pub fn payload_estimate_kg(&self) -> Option<f64> {
        let s = &self.state;
        if !s.derived_valid {
            return None;
        }
        let g0 = self.kin.gravity_torques(&s.joints, 0.0);
        let a = self.kin.gravity_torques(&s.joints, 1.0) - g0;
        let margin = self.config.weigh_stroke_end_margin;
        let usable = s.extension_fraction.map(|e| e > margin && e < 1.0 - margin);
        let excess = [0, 1, 2].map(|i| s.joint_torque_nm[i] - g0[i]);
        planner::kinematics::payload_least_squares(&[a[0], a[1], a[2]], &excess, usable)
    }

    /// The payload weight from [`Self::payload_estimate_kg`], N.
    pub fn payload_weight_n(&self) -> Option<f64> {
        self.payload_estimate_kg().map(|m| m * GRAVITY_M_PER_S2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware_bridge::messages::{AuxValveMeasured, JointRates, TrackOdometry, ValveState};
    use planner::machine::MachineConfig;

    /// A dig-like pose well inside the limits.
    const Q: JointAngles = JointAngles {
        boom_rad: 0.2,
        stick_rad: -1.4,
        bucket_rad: -0.8,
    };

    fn estimator() -> Estimator {
        let m = MachineConfig::default_machine().expect("machine");
        let kin = Kinematics::new(&m).expect("kinematics");
        Estimator::new(kin, m.tracks.gauge_m, EstimatorConfig::default()).expect("estimator")
    }

    fn angles(q: JointAngles, swing: f64) -> Message {
        Message::JointAngles(firmware_bridge::messages::JointAngles {
            boom_rad: q.boom_rad,
            stick_rad: q.stick_rad,
            bucket_rad: q.bucket_rad,
            swing_rad: swing,
        })
    }

    fn pressures(cylinder: Cylinder, head: f64, rod: f64) -> Message {
        Message::AuxValveMeasured(AuxValveMeasured {
            cylinder,
            flow_percent: 0.0,
            state: ValveState::Block,
            head_pressure_pa: head,
            rod_pressure_pa: rod,
        })
    }

    /// Feeds the pressures that hold the pose against gravity with `payload_kg` in the bucket.
    fn feed_static(e: &mut Estimator, payload_kg: f64) {
        let kin = e.kinematics().clone();
        let tau = kin.gravity_torques(&Q, payload_kg);
        let force = kin
            .cylinder_forces_from_joint_torques(&Q, &tau)
            .expect("forces");
        let m = MachineConfig::default_machine().expect("machine");
        let cyl = [m.cylinders.boom, m.cylinders.stick, m.cylinders.bucket];
        e.on_message(&angles(Q, 0.0), 0.0);
        for (i, c) in Cylinder::ALL.into_iter().enumerate() {
            // Put the whole force on one port, as a holding cylinder does.
            let (head, rod) = if force[i] >= 0.0 {
                (force[i] / cyl[i].head_area_m2(), 0.0)
            } else {
                (0.0, -force[i] / cyl[i].rod_area_m2())
            };
            e.on_message(&pressures(c, head, rod), 0.0);
        }
        e.update();
    }

    #[test]
    fn static_holding_pressures_give_zero_tip_force_and_the_payload() {
        let mut e = estimator();
        feed_static(&mut e, 2000.0);
        let s = e.state();
        assert!(s.derived_valid);
        let f = s.tip_force.expect("tip force");
        // With an empty-bucket gravity model the payload shows up as a downward tip force of m g.
        assert!(f.fx_n.abs() < 1.0, "{f:?}");
        assert!((f.fz_n + 2000.0 * GRAVITY_M_PER_S2).abs() < 5.0, "{f:?}");
        let m = e.payload_estimate_kg().expect("payload");
        assert!((m - 2000.0).abs() < 0.5, "{m}");
        assert!((e.payload_weight_n().expect("w") - 2000.0 * GRAVITY_M_PER_S2).abs() < 5.0);
    }

    /// Regression: after Capture the bucket cylinder sits in its end stop with relief pressure trapped
    /// in the head; weighing it with the bucket joint read the payload about 21 % high.
    #[test]
    fn weighing_leaves_out_a_cylinder_in_its_end_stop() {
        let mut e = estimator();
        let kin = e.kinematics().clone();
        // The bucket angle at which its cylinder is fully extended (curled into the stop).
        let (lo, hi) = kin.stroke_limited_range(Joint::Bucket);
        let at_stop = [lo, hi]
            .into_iter()
            .find(|&b| {
                let len = kin.cylinder_length(Joint::Bucket, b).expect("length");
                let (r, x) = kin.stroke(Joint::Bucket);
                (len - x).abs() < 1e-6 * (x - r)
            })
            .expect("an end of the stroke-limited range is full extension");
        let q = JointAngles {
            bucket_rad: at_stop,
            ..Q
        };
        let payload_kg = 2500.0;
        let tau = kin.gravity_torques(&q, payload_kg);
        let mut force = kin
            .cylinder_forces_from_joint_torques(&q, &tau)
            .expect("forces");
        // The end stop: the bucket cylinder pushes on far beyond what gravity needs.
        force[2] += 5.0e5;
        let m = MachineConfig::default_machine().expect("machine");
        let cyl = [m.cylinders.boom, m.cylinders.stick, m.cylinders.bucket];
        let feed = |e: &mut Estimator| {
            e.on_message(&angles(q, 0.0), 0.0);
            for (i, c) in Cylinder::ALL.into_iter().enumerate() {
                let (head, rod) = if force[i] >= 0.0 {
                    (force[i] / cyl[i].head_area_m2(), 0.0)
                } else {
                    (0.0, -force[i] / cyl[i].rod_area_m2())
                };
                e.on_message(&pressures(c, head, rod), 0.0);
            }
            e.update();
        };
        feed(&mut e);
        assert!(e.state().extension_fraction[2] > 0.99);
        let est = e.payload_estimate_kg().expect("payload");
        assert!((est - payload_kg).abs() < 1.0, "{est} kg");
        // Counting the bucket joint (a negative margin) takes the end-stop force for payload.
        let mut counting_all = Estimator::new(
            kin,
            m.tracks.gauge_m,
            EstimatorConfig {
                weigh_stroke_end_margin: -1.0,
                ..EstimatorConfig::default()
            },
        )
        .expect("estimator");
        feed(&mut counting_all);
        let biased = counting_all.payload_estimate_kg().expect("payload");
        assert!((biased - payload_kg).abs() > 100.0, "{biased} kg");
    }

    #[test]
    fn cylinder_force_is_head_minus_rod_times_areas() {
        let mut e = estimator();
        e.on_message(&angles(Q, 0.0), 0.0);
        e.on_message(&pressures(Cylinder::Stick, 10e6, 4e6), 0.0);
        e.update();
        let m = MachineConfig::default_machine().expect("machine");
        let c = m.cylinders.stick;
        let expect = 10e6 * c.head_area_m2() - 4e6 * c.rod_area_m2(); // Eq. A20
        assert!((e.state().cylinder_force_n[1] - expect).abs() < 1e-6);
        let r = e
            .kinematics()
            .moment_arm(Joint::Stick, Q.stick_rad)
            .expect("arm");
        assert!((e.state().joint_torque_nm[1] - expect * r).abs() < 1e-6);
    }

    #[test]
    fn tip_pose_and_extension_follow_the_angles() {
        let mut e = estimator();
        e.on_message(&angles(Q, 0.3), 1.0);
        e.update();
        let s = e.state();
        let fk = e.kinematics().forward(&Q);
        assert_eq!(s.tip, fk);
        assert_eq!(s.swing_rad, 0.3);
        assert!(s.extension_fraction.iter().all(|x| (0.0..=1.0).contains(x)));
    }

    #[test]
    fn rates_are_low_pass_filtered() {
        let mut e = estimator();
        let rates = |v: f64| {
            Message::JointRates(JointRates {
                boom_rad_per_s: v,
                ..Default::default()
            })
        };
        e.on_message(&rates(0.0), 0.0);
        e.on_message(&rates(1.0), 0.01);
        let r = e.state().rates_rad_per_s[0];
        // alpha = 0.01 / (0.03 + 0.01)
        assert!((r - 0.25).abs() < 1e-12, "{r}");
        for k in 2..100 {
            e.on_message(&rates(1.0), f64::from(k) * 0.01);
        }
        assert!((e.state().rates_rad_per_s[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn ages_track_each_signal() {
        let mut e = estimator();
        assert!(e.age_s(Signal::JointAngles, 1.0).is_infinite());
        e.on_message(&angles(Q, 0.0), 1.0);
        assert!((e.age_s(Signal::JointAngles, 1.03) - 0.03).abs() < 1e-12);
        let (sig, age) = e.stalest_control_signal(1.03);
        assert_ne!(sig, Signal::JointAngles);
        assert!(age.is_infinite());
    }

    #[test]
    fn odometry_dead_reckons_backwards_along_the_heading() {
        let mut e = estimator();
        let odo = |l: f64, r: f64| {
            Message::TrackOdometry(TrackOdometry {
                left_m: l,
                right_m: r,
            })
        };
        e.on_message(&odo(10.0, 10.0), 0.0);
        e.on_message(&odo(8.5, 8.5), 1.0);
        let p = e.state().pose;
        assert!((p.x_m + 1.5).abs() < 1e-12 && p.y_m.abs() < 1e-12);
    }

    fn status(alive_counter: u8) -> Message {
        Message::GatewayStatus(GatewayStatus {
            mode: firmware_bridge::messages::GatewayMode::ArmedValve,
            faults: firmware_bridge::messages::GatewayFaults(0),
            alive_counter,
            unexpected_frames: 0,
            rejected_frames: 0,
        })
    }

    #[test]
    fn gateway_alive_age_grows_while_the_status_repeats_its_counter() {
        let mut e = estimator();
        assert!(e.gateway_alive_age_s(0.0).is_infinite());
        e.on_message(&status(254), 0.0);
        e.on_message(&status(255), 0.1);
        e.on_message(&status(0), 0.2);
        assert_eq!(e.gateway_alive_age_s(0.25), 0.25 - 0.2);
        assert_eq!(e.gateway_alive_errors(), 0);
        // Frozen: the status keeps arriving (fresh by age) with the same counter.
        for k in 3..10 {
            e.on_message(&status(0), f64::from(k) * 0.1);
        }
        assert!(e.age_s(Signal::GatewayStatus, 0.9) < 1e-9);
        assert!((e.gateway_alive_age_s(0.9) - 0.7).abs() < 1e-9);
        assert_eq!(e.gateway_alive_counter(), Some(0));
        assert_eq!(e.gateway_alive_errors(), 7);
        // A skip (lost frames) is counted but is a change: alive again.
        e.on_message(&status(5), 1.0);
        assert_eq!(e.gateway_alive_age_s(1.0), 0.0);
        assert_eq!(e.gateway_alive_errors(), 8);
    }

    #[test]
    fn non_finite_values_are_not_stored() {
        let mut e = estimator();
        e.on_message(&angles(Q, 0.0), 0.0);
        let bad = JointAngles {
            boom_rad: f64::NAN,
            ..Q
        };
        assert!(e.on_message(&angles(bad, 0.0), 0.5));
        assert_eq!(e.state().joints, Q);
        assert_eq!(e.last_received_s(Signal::JointAngles), Some(0.0));
    }
}
