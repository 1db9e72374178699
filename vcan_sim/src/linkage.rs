//! The boom/stick/bucket linkage seen from the hydraulics: cylinder extension <-> joint angle, the
//! loads that gravity, payload and soil put on each cylinder, and the mass each cylinder drives.
//!
//! Geometry and statics come from [`planner::kinematics::Kinematics`] (Appendix): joint angles from
//! cylinder lengths by the law of cosines (Eq. A5) and the bucket four-bar (Eqs. A8-A14); the joint
//! torques the actuators must supply `tau = G - J^T f` (Eq. A2 with Eq. A3 and the gravity torques of
//! Eq. A4, payload included), and cylinder forces `F = tau / r` (Eqs. A7 and A19), where
//! `r = dL/dtheta` is the signed moment arm.
//!
//! The inertia is the diagonal of the joint-space mass matrix `M(q)` of Eq. A1 (links as rods about
//! their centres of gravity plus the payload as a point mass), reflected to each cylinder as
//! `M_i / r_i^2`. The Coriolis terms of Eq. A1 are neglected (slow motion, as in the thesis's A2).

use nalgebra::Vector3;
use planner::kinematics::{JointAngles, Kinematics, KinematicsError, LinkagePoints, TipForce};
use planner::machine::MachineConfig;

/// Stroke geometry and statics of the implement.
#[derive(Debug, Clone)]
pub struct Linkage {
    kin: Kinematics,
    /// Retracted pin-to-pin lengths `[boom, stick, bucket]` (m).
    retracted_m: [f64; 3],
    /// Strokes (m).
    stroke_m: [f64; 3],
    /// `(mass, cog distance, cog angle)` per link.
    masses: [(f64, f64, f64); 3],
    link_lengths: [f64; 3],
    /// Extra inertia of cylinders, pins and oil reflected to each joint (kg m^2).
    joint_inertia_floor: [f64; 3],
}

/// The linkage state derived from cylinder extensions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkageState {
    /// Joint angles.
    pub q: JointAngles,
    /// Signed moment arms `dL/dtheta` (m/rad).
    pub arms: [f64; 3],
}

impl Linkage {
    /// Builds the linkage of a machine.
    ///
    /// # Errors
    /// A [`KinematicsError`] when the machine's geometry is inconsistent.
    pub fn new(cfg: &MachineConfig) -> Result<Self, KinematicsError> {
        let kin = Kinematics::new(cfg)?;
        let joints = planner::kinematics::Joint::ALL;
        let mut retracted_m = [0.0; 3];
        let mut stroke_m = [0.0; 3];
        for (i, joint) in joints.iter().enumerate() {
            let (lo, hi) = kin.stroke(*joint);
            retracted_m[i] = lo;
            stroke_m[i] = hi - lo;
        }
        let m = &cfg.masses;
        Ok(Self {
            kin,
            retracted_m,
            stroke_m,
            masses: [
                (m.boom.mass_kg, m.boom.cog_distance_m, m.boom.cog_angle_rad),
                (
                    m.stick.mass_kg,
                    m.stick.cog_distance_m,
                    m.stick.cog_angle_rad,
                ),
                (
                    m.bucket.mass_kg,
                    m.bucket.cog_distance_m,
                    m.bucket.cog_angle_rad,
                ),
            ],
            link_lengths: [cfg.links.boom_m, cfg.links.stick_m, cfg.links.bucket_m],
            joint_inertia_floor: [2000.0, 500.0, 100.0],
        })
    }

    /// The planner's kinematics for this machine.
    pub fn kinematics(&self) -> &Kinematics {
        &self.kin
    }

    /// Cylinder strokes `[boom, stick, bucket]` (m).
    pub fn strokes_m(&self) -> [f64; 3] {
        self.stroke_m
    }

    /// Cylinder extensions (from fully retracted) for joint angles.
    ///
    /// # Errors
    /// When an angle is outside what the cylinder stroke allows.
    pub fn extensions(&self, q: &JointAngles) -> Result<[f64; 3], KinematicsError> {
        let lengths = self.kin.cylinder_lengths(q)?;
        let l = [lengths.boom_m, lengths.stick_m, lengths.bucket_m];
        Ok([0, 1, 2].map(|i| (l[i] - self.retracted_m[i]).clamp(0.0, self.stroke_m[i])))
    }

    /// Joint angles and moment arms for cylinder extensions (clamped to the strokes).
    ///
    /// # Errors
    /// Only for non-finite input or an infeasible four-bar.
    pub fn state(&self, extensions_m: [f64; 3]) -> Result<LinkageState, KinematicsError> {
        let joints = planner::kinematics::Joint::ALL;
        let mut angles = [0.0; 3];
        let mut arms = [0.0; 3];
        for (i, joint) in joints.iter().enumerate() {
            let length = self.retracted_m[i] + extensions_m[i].clamp(0.0, self.stroke_m[i]);
            angles[i] = self.kin.joint_angle(*joint, length)?;
            arms[i] = self.kin.moment_arm(*joint, angles[i])?;
        }
        Ok(LinkageState {
            q: JointAngles {
                boom_rad: angles[0],
                stick_rad: angles[1],
                bucket_rad: angles[2],
            },
            arms,
        })
    }

    /// Cylinder forces that hold gravity, payload and the soil force (soil on bucket, base frame):
    /// `tau = G - J^T f` (Eq. A2), `F = tau / r` (Eqs. A7, A19). Positive pushes toward extension.
    pub fn cylinder_loads(&self, s: &LinkageState, soil: &TipForce, payload_kg: f64) -> [f64; 3] {
        let tau = self
            .kin
            .joint_torques_from_tip_force(&s.q, soil, payload_kg);
        Self::cylinder_forces(s, &tau)
    }

    /// Cylinder forces for joint torques with the tabulated moment arms, `F = tau / r` (Eqs. A7, A19);
    /// zero at a vanishing arm.
    pub fn cylinder_forces(s: &LinkageState, tau: &Vector3<f64>) -> [f64; 3] {
        [0, 1, 2].map(|i| {
            let r = s.arms[i];
            if r.abs() < 1e-4 { 0.0 } else { tau[i] / r }
        })
    }

    /// Diagonal of the joint-space inertia `M(q)` (Eq. A1), kg m^2, with the payload at its centroid.
    pub fn joint_inertias(&self, s: &LinkageState, payload_kg: f64) -> [f64; 3] {
        self.joint_inertias_at(s, &self.kin.linkage_points(&s.q), payload_kg)
    }

    /// [`Self::joint_inertias`] with the linkage points of `s.q` already computed.
    pub fn joint_inertias_at(
        &self,
        s: &LinkageState,
        p: &LinkagePoints,
        payload_kg: f64,
    ) -> [f64; 3] {
        let joints = [p.boom_foot, p.stick_pin, p.bucket_pin];
        let abs = [s.q.boom_rad, s.q.stick_abs_rad(), s.q.bucket_abs_rad()];
        let mut bodies = [(0.0, [0.0, 0.0], 0.0); 4];
        for n in 0..3 {
            let (m, d, ang) = self.masses[n];
            let c = [
                joints[n][0] + d * (abs[n] + ang).cos(),
                joints[n][1] + d * (abs[n] + ang).sin(),
            ];
            // A slender rod about its centre: m l^2 / 12.
            bodies[n] = (m, c, m * self.link_lengths[n].powi(2) / 12.0);
        }
        bodies[3] = (
            payload_kg.max(0.0),
            self.kin.payload_centroid(&s.q),
            0.05 * payload_kg.max(0.0),
        );
        let mut out = self.joint_inertia_floor;
        for (i, joint) in joints.iter().enumerate() {
            for (n, (m, c, own)) in bodies.iter().enumerate() {
                if n >= i {
                    let d2 = (c[0] - joint[0]).powi(2) + (c[1] - joint[1]).powi(2);
                    out[i] += m * d2 + own;
                }
            }
        }
        out
    }

    /// Effective masses each cylinder drives, `M_ii / r_i^2` (kg).
    pub fn cylinder_masses(&self, s: &LinkageState, payload_kg: f64) -> [f64; 3] {
        self.cylinder_masses_at(s, &self.kin.linkage_points(&s.q), payload_kg)
    }

    /// [`Self::cylinder_masses`] with the linkage points of `s.q` already computed.
    pub fn cylinder_masses_at(
        &self,
        s: &LinkageState,
        points: &LinkagePoints,
        payload_kg: f64,
    ) -> [f64; 3] {
        let inertia = self.joint_inertias_at(s, points, payload_kg);
        [0, 1, 2].map(|i| inertia[i] / s.arms[i].powi(2).max(1e-4))
    }

    /// Joint rates from cylinder velocities (rad/s).
    pub fn joint_rates(&self, s: &LinkageState, velocities_m_per_s: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|i| {
            if s.arms[i].abs() < 1e-6 {
                0.0
            } else {
                velocities_m_per_s[i] / s.arms[i]
            }
        })
    }

    /// Tip velocity in the base frame `[vx, vz]` for joint rates (Jacobian rows 1-2, Eq. A3).
    pub fn tip_velocity(&self, s: &LinkageState, rates: [f64; 3]) -> [f64; 2] {
        let j = self.kin.jacobian(&s.q);
        let v = j * Vector3::new(rates[0], rates[1], rates[2]);
        [v[0], v[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn linkage() -> Linkage {
        Linkage::new(&MachineConfig::default_machine().unwrap()).unwrap()
    }

    #[test]
    fn extensions_and_state_round_trip() {
        let l = linkage();
        let q = JointAngles {
            boom_rad: 0.3,
            stick_rad: -1.6,
            bucket_rad: -1.0,
        };
        let x = l.extensions(&q).unwrap();
        let s = l.state(x).unwrap();
        assert!((s.q.boom_rad - q.boom_rad).abs() < 1e-6);
        assert!((s.q.stick_rad - q.stick_rad).abs() < 1e-6);
        assert!((s.q.bucket_rad - q.bucket_rad).abs() < 1e-6);
        assert!(s.arms[0] > 0.0 && s.arms[1] < 0.0 && s.arms[2] < 0.0);
    }

    #[test]
    fn gravity_loads_push_the_boom_cylinder_and_scale_with_payload() {
        let l = linkage();
        let s = l
            .state(
                l.extensions(&JointAngles {
                    boom_rad: 0.2,
                    stick_rad: -1.5,
                    bucket_rad: -1.0,
                })
                .unwrap(),
            )
            .unwrap();
        let empty = l.cylinder_loads(&s, &TipForce::default(), 0.0);
        let full = l.cylinder_loads(&s, &TipForce::default(), 2500.0);
        assert!(empty[0] > 5.0e4, "boom holds the implement: {empty:?}");
        assert!(full[0] > empty[0]);
        let m = l.cylinder_masses(&s, 0.0);
        assert!(m.iter().all(|m| m.is_finite() && *m > 100.0), "{m:?}");
    }
}
