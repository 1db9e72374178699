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

use nalgebra::{Matrix3, Vector3};
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
    /// Centre of gravity of each link in the frame of its line `v` (joint -> next pin, of length
    /// `l`): `cog = joint + a v + b perp(v)` with `(a, b) = d / l (cos, sin)(cog angle)`.
    cog_in_link: [[f64; 2]; 3],
    /// The payload centroid in the same way on the bucket line (bucket pin -> tip).
    payload_in_bucket: [f64; 2],
    /// Extra inertia of cylinders, pins and oil reflected to each joint (kg m^2).
    joint_inertia_floor: [f64; 3],
}

/// The pose-dependent geometry of one load update, from one forward-kinematics evaluation (the
/// planner's [`Kinematics::linkage_points`], three sines and cosines): the pins, the links' centres
/// of gravity and the payload centroid. The Jacobian (Eq. A3), the gravity torques (Eq. A4) and the
/// inertias (Eq. A1) follow from these points without further trigonometry, where the planner's
/// functions evaluate the kinematics again for each (about 30 sines and cosines per update in all).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseFrame {
    /// Pin positions and the tip in the base frame.
    pub points: LinkagePoints,
    /// Centres of gravity of boom, stick and bucket `[x, z]` (m).
    pub cogs_m: [[f64; 2]; 3],
    /// Payload centroid `[x, z]` (m), as [`Kinematics::payload_centroid`].
    pub payload_centroid_m: [f64; 2],
}

impl PoseFrame {
    /// The pins `[boom foot, stick pin, bucket pin]` (the joints), each followed on its link by the
    /// next pin or the tip.
    fn joints(&self) -> [[f64; 2]; 3] {
        let p = &self.points;
        [p.boom_foot, p.stick_pin, p.bucket_pin]
    }

    /// The Jacobian of the tip `(x, z, bucket_abs)` (Eq. A3) from the points: column `i` is the tip
    /// about joint `i` turned by 90 degrees, `(-(z_tip - z_i), x_tip - x_i, 1)` (the planner's
    /// [`Kinematics::jacobian`] to rounding).
    pub fn jacobian(&self) -> Matrix3<f64> {
        let t = self.points.tip;
        let j = self.joints();
        Matrix3::new(
            -(t[1] - j[0][1]),
            -(t[1] - j[1][1]),
            -(t[1] - j[2][1]),
            t[0] - j[0][0],
            t[0] - j[1][0],
            t[0] - j[2][0],
            1.0,
            1.0,
            1.0,
        )
    }
}

/// `origin + a v + b perp(v)` with `v = to - origin`, `perp(v) = (-v_z, v_x)`.
fn point_on_line(origin: [f64; 2], to: [f64; 2], [a, b]: [f64; 2]) -> [f64; 2] {
    let v = [to[0] - origin[0], to[1] - origin[1]];
    [
        origin[0] + a * v[0] - b * v[1],
        origin[1] + a * v[1] + b * v[0],
    ]
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
        let link_lengths = [cfg.links.boom_m, cfg.links.stick_m, cfg.links.bucket_m];
        let in_link = |d: f64, angle: f64, length: f64| {
            let (sin, cos) = angle.sin_cos();
            [d * cos / length, d * sin / length]
        };
        let cog_in_link = [
            in_link(m.boom.cog_distance_m, m.boom.cog_angle_rad, link_lengths[0]),
            in_link(
                m.stick.cog_distance_m,
                m.stick.cog_angle_rad,
                link_lengths[1],
            ),
            in_link(
                m.bucket.cog_distance_m,
                m.bucket.cog_angle_rad,
                link_lengths[2],
            ),
        ];
        let payload_in_bucket = in_link(
            cfg.bucket.payload_centroid_distance_m,
            cfg.bucket.payload_centroid_angle_rad,
            link_lengths[2],
        );
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
            link_lengths,
            cog_in_link,
            payload_in_bucket,
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

    /// The pose geometry of joint angles `q` for [`Self::cylinder_loads_at`],
    /// [`Self::cylinder_masses_at`] and [`Self::tip_velocity_at`].
    pub fn frame(&self, q: &JointAngles) -> PoseFrame {
        let points = self.kin.linkage_points(q);
        let ends = [points.stick_pin, points.bucket_pin, points.tip];
        let joints = [points.boom_foot, points.stick_pin, points.bucket_pin];
        PoseFrame {
            points,
            cogs_m: [0, 1, 2].map(|n| point_on_line(joints[n], ends[n], self.cog_in_link[n])),
            payload_centroid_m: point_on_line(
                points.bucket_pin,
                points.tip,
                self.payload_in_bucket,
            ),
        }
    }

    /// Joint torques the actuators supply at the pose `frame`: `tau = G - J^T f` (Eq. A2) with the
    /// gravity torques `G_i = g sum_{n >= i} m_n (x_n - x_i)` of the links and the payload (Eq. A4),
    /// or without gravity `-J^T f` (the planner's [`Kinematics::joint_torques_from_tip_force`] and
    /// [`Kinematics::gravity_torques`] to rounding).
    pub fn joint_torques_at(
        &self,
        frame: &PoseFrame,
        soil: &TipForce,
        payload_kg: f64,
        gravity: bool,
    ) -> Vector3<f64> {
        let soil_torques = frame.jacobian().transpose() * soil.to_vector();
        if !gravity {
            return -soil_torques;
        }
        let joints = frame.joints();
        let bodies = [
            (self.masses[0].0, frame.cogs_m[0][0]),
            (self.masses[1].0, frame.cogs_m[1][0]),
            (self.masses[2].0, frame.cogs_m[2][0]),
            (payload_kg.max(0.0), frame.payload_centroid_m[0]),
        ];
        let g = planner::kinematics::gravity_torques_of_bodies(
            [joints[0][0], joints[1][0], joints[2][0]],
            &bodies,
        ); // Eq. A4
        g - soil_torques // Eq. A2
    }

    /// [`Self::cylinder_loads`] at the pose `frame` (of `s.q`); without `gravity` only the soil force.
    pub fn cylinder_loads_at(
        &self,
        s: &LinkageState,
        frame: &PoseFrame,
        soil: &TipForce,
        payload_kg: f64,
        gravity: bool,
    ) -> [f64; 3] {
        Self::cylinder_forces(s, &self.joint_torques_at(frame, soil, payload_kg, gravity))
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
        self.joint_inertias_at(&self.frame(&s.q), payload_kg)
    }

    /// [`Self::joint_inertias`] at the pose `frame`.
    pub fn joint_inertias_at(&self, frame: &PoseFrame, payload_kg: f64) -> [f64; 3] {
        let joints = frame.joints();
        // The links as slender rods about their centres (own inertia m l^2 / 12), and the payload.
        let rod = |n: usize| {
            let m = self.masses[n].0;
            (m, frame.cogs_m[n], m * self.link_lengths[n].powi(2) / 12.0)
        };
        let bodies = [
            rod(0),
            rod(1),
            rod(2),
            (
                payload_kg.max(0.0),
                frame.payload_centroid_m,
                0.05 * payload_kg.max(0.0),
            ),
        ];
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
        self.cylinder_masses_at(s, &self.frame(&s.q), payload_kg)
    }

    /// [`Self::cylinder_masses`] at the pose `frame` (of `s.q`).
    pub fn cylinder_masses_at(
        &self,
        s: &LinkageState,
        frame: &PoseFrame,
        payload_kg: f64,
    ) -> [f64; 3] {
        let inertia = self.joint_inertias_at(frame, payload_kg);
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

    /// [`Self::tip_velocity`] at the pose `frame`.
    pub fn tip_velocity_at(&self, frame: &PoseFrame, rates: [f64; 3]) -> [f64; 2] {
        let v = frame.jacobian() * Vector3::new(rates[0], rates[1], rates[2]);
        [v[0], v[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner::machine::GRAVITY_M_PER_S2;

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
    fn pose_frame_matches_the_planners_kinematics_to_rounding() {
        let l = linkage();
        let kin = l.kinematics();
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-12 * (scale + b.abs());
        let soil = TipForce {
            fx_n: -3.0e4,
            fz_n: 1.2e4,
            my_nm: 2.0e3,
        };
        for (boom, stick, bucket) in [
            (0.3, -1.6, -1.0),
            (0.9, -2.2, -2.4),
            (-0.2, -0.9, 0.4),
            (0.5, -1.3, -0.2),
        ] {
            let q = JointAngles {
                boom_rad: boom,
                stick_rad: stick,
                bucket_rad: bucket,
            };
            let f = l.frame(&q);
            assert_eq!(f.points, kin.linkage_points(&q));
            let c = kin.payload_centroid(&q);
            assert!(close(f.payload_centroid_m[0], c[0], 10.0), "{q:?}");
            assert!(close(f.payload_centroid_m[1], c[1], 10.0), "{q:?}");
            let (ja, jb) = (f.jacobian(), kin.jacobian(&q));
            for k in 0..9 {
                assert!(close(ja[k], jb[k], 10.0), "{q:?} {ja} {jb}");
            }
            for payload in [0.0, 2500.0] {
                let ta = l.joint_torques_at(&f, &soil, payload, true);
                let tb = kin.joint_torques_from_tip_force(&q, &soil, payload);
                let tc = l.joint_torques_at(&f, &soil, payload, false);
                let td = -(kin.jacobian(&q).transpose() * soil.to_vector());
                for i in 0..3 {
                    assert!(close(ta[i], tb[i], 1.0e5), "{q:?} {ta} {tb}");
                    assert!(close(tc[i], td[i], 1.0e5), "{q:?} {tc} {td}");
                }
            }
            // The inertias against the links' centres of gravity by their angles (Eq. A1).
            let g = kin.gravity_torques(&q, 0.0);
            let joints = [f.points.boom_foot, f.points.stick_pin, f.points.bucket_pin];
            let abs = [q.boom_rad, q.stick_abs_rad(), q.bucket_abs_rad()];
            let mut g_by_angles = [0.0; 3];
            for n in 0..3 {
                let (m, d, ang) = l.masses[n];
                let cog = [
                    joints[n][0] + d * (abs[n] + ang).cos(),
                    joints[n][1] + d * (abs[n] + ang).sin(),
                ];
                assert!(close(f.cogs_m[n][0], cog[0], 10.0), "{q:?} link {n}");
                assert!(close(f.cogs_m[n][1], cog[1], 10.0), "{q:?} link {n}");
                for (i, joint) in joints.iter().enumerate().take(n + 1) {
                    g_by_angles[i] += GRAVITY_M_PER_S2 * m * (cog[0] - joint[0]);
                }
            }
            for i in 0..3 {
                assert!(close(g[i], g_by_angles[i], 1.0e5), "{q:?} {g}");
            }
            let s = LinkageState {
                q,
                arms: [0.3, -0.4, -0.25],
            };
            let v = l.tip_velocity_at(&f, [0.1, -0.2, 0.3]);
            let w = l.tip_velocity(&s, [0.1, -0.2, 0.3]);
            assert!(
                close(v[0], w[0], 1.0) && close(v[1], w[1], 1.0),
                "{v:?} {w:?}"
            );
        }
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
