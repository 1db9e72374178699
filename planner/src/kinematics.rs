//! Linkage kinematics and statics of the boom/stick/bucket (thesis Appendix, Eqs. A1-A23).
//!
//! - Joint angles <-> cylinder lengths: boom and stick by the law of cosines (Eq. A5), the bucket through
//!   its four-bar (Eqs. A8-A14; the inverse by a safeguarded Newton solve on the monotonic stroke range).
//! - Moment arms `r_i = dL_i/dtheta_i` (Eqs. A6-A7; for the bucket Eqs. A15-A19) relate cylinder speeds to
//!   joint rates (`dL = r dtheta`) and cylinder forces to joint torques (`tau = F r`, virtual work).
//! - Forward kinematics to the bucket pin, the cutting-edge tip and the bucket pose `(x, z, bucket_abs)` in
//!   the base frame; swing and machine pose to the world; inverse kinematics with typed errors.
//! - Statics: the Jacobian (Eq. A3 in our sign convention), gravity torques (Eq. A4) including the payload,
//!   joint torques from tip forces (Eq. A2) and tip forces from cylinder pressures (Eqs. A20-A23).
//!
//! Sign conventions (docs/ARCHITECTURE.md): `z` up, angles counter-clockwise positive in the side view.
//! The thesis's Eq. A3 has `-l C` in its second row because its `z` points down; ours is `+l C`.
//! The tip force `f = (F_x, F_z, M_y)` is the force the soil exerts on the bucket, `M_y` counter-clockwise
//! positive (work-conjugate to `bucket_abs`). The thesis's `f` in Eq. A2 is the force of the bucket on the
//! soil (Eq. 18), i.e. `-f`; so here `tau = G - J^T f` (Eq. A2) and `f = J^-T (G - tau)` (Eq. A23).
//! `G` is the holding torque the actuators must supply against gravity.

pub use crate::linkage::BucketLinkageState;
use crate::linkage::{
    FourBar, LinkageError, Mount, add, dir, law_of_cosines_angle, norm, scale, sub,
};
use crate::machine::{GRAVITY_M_PER_S2, MachineConfig};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// An implement joint (Appendix indices 2, 3, 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Joint {
    /// Boom (index 2).
    Boom,
    /// Stick (index 3).
    Stick,
    /// Bucket (index 4).
    Bucket,
}

impl Joint {
    /// The three implement joints in array order.
    pub const ALL: [Joint; 3] = [Joint::Boom, Joint::Stick, Joint::Bucket];

    /// Index in `[boom, stick, bucket]` arrays.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Joint::Boom => 0,
            Joint::Stick => 1,
            Joint::Bucket => 2,
        }
    }
}

impl std::fmt::Display for Joint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Joint::Boom => "boom",
            Joint::Stick => "stick",
            Joint::Bucket => "bucket",
        })
    }
}

/// Kinematics and statics errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    /// A joint angle outside its configured limits.
    #[error("{joint} angle {angle_rad:.4} rad outside its limits [{min_rad:.4}, {max_rad:.4}]")]
    JointLimit {
        /// Which joint.
        joint: Joint,
        /// The offending angle, rad.
        angle_rad: f64,
        /// Lower limit, rad.
        min_rad: f64,
        /// Upper limit, rad.
        max_rad: f64,
    },
    /// A cylinder length outside its stroke.
    #[error("{joint} cylinder length {length_m:.4} m outside its stroke [{min_m:.4}, {max_m:.4}]")]
    CylinderLimit {
        /// Which cylinder.
        joint: Joint,
        /// The offending length, m.
        length_m: f64,
        /// Retracted length, m.
        min_m: f64,
        /// Extended length, m.
        max_m: f64,
    },
    /// The bucket pin of the target lies outside the boom+stick annulus.
    #[error(
        "target out of reach: bucket pin {distance_m:.3} m from the boom foot, reachable {min_m:.3}..{max_m:.3} m"
    )]
    OutOfReach {
        /// Distance from the boom foot pin to the required bucket pin, m.
        distance_m: f64,
        /// Closest reachable distance, m.
        min_m: f64,
        /// Farthest reachable distance, m.
        max_m: f64,
    },
    /// A singular configuration (zero moment arm, stretched stick, toggle of the four-bar).
    #[error("singular configuration: {what}")]
    Singular {
        /// What degenerated.
        what: &'static str,
    },
    /// NaN or infinite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// The bucket four-bar cannot be assembled at this bucket angle.
    #[error("bucket four-bar cannot assemble at bucket angle {bucket_rad:.4} rad")]
    LinkageInfeasible {
        /// The bucket angle, rad.
        bucket_rad: f64,
    },
    /// The machine geometry is inconsistent (reported by [`MachineConfig::validate`]).
    #[error("machine field `{field}`: {reason}")]
    Config {
        /// Dotted field path.
        field: String,
        /// Why.
        reason: String,
    },
}

impl From<LinkageError> for KinematicsError {
    fn from(e: LinkageError) -> Self {
        match e {
            LinkageError::Singular { what } => KinematicsError::Singular { what },
            LinkageError::Infeasible { bucket_rad } => {
                KinematicsError::LinkageInfeasible { bucket_rad }
            }
            LinkageError::Config { field, reason } => KinematicsError::Config { field, reason },
        }
    }
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, KinematicsError>;

/// `Ok` if `finite` holds, else [`KinematicsError::NonFinite`] naming `what`.
fn ensure_finite(finite: bool, what: &'static str) -> Result<()> {
    if finite {
        Ok(())
    } else {
        Err(KinematicsError::NonFinite { what })
    }
}

/// Implement joint angles, rad (docs/ARCHITECTURE.md).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct JointAngles {
    /// Boom line relative to base `x`.
    pub boom_rad: f64,
    /// Stick line relative to the boom line.
    pub stick_rad: f64,
    /// Bucket line (pin -> tip) relative to the stick line.
    pub bucket_rad: f64,
}

impl JointAngles {
    /// `[boom, stick, bucket]` as a vector.
    #[must_use]
    pub fn to_vector(self) -> Vector3<f64> {
        Vector3::new(self.boom_rad, self.stick_rad, self.bucket_rad)
    }

    /// From a `[boom, stick, bucket]` vector.
    #[must_use]
    pub fn from_vector(v: &Vector3<f64>) -> Self {
        Self {
            boom_rad: v[0],
            stick_rad: v[1],
            bucket_rad: v[2],
        }
    }

    /// Stick angle to the horizontal (the thesis's "stick angle").
    #[must_use]
    pub fn stick_abs_rad(self) -> f64 {
        self.boom_rad + self.stick_rad
    }

    /// Bucket angle to the horizontal (the thesis's rho).
    #[must_use]
    pub fn bucket_abs_rad(self) -> f64 {
        self.boom_rad + self.stick_rad + self.bucket_rad
    }

    fn is_finite(self) -> bool {
        self.boom_rad.is_finite() && self.stick_rad.is_finite() && self.bucket_rad.is_finite()
    }

    fn get(self, joint: Joint) -> f64 {
        self.to_vector()[joint.index()]
    }
}

/// Pin-to-pin cylinder lengths, m.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CylinderLengths {
    /// Boom cylinder.
    pub boom_m: f64,
    /// Stick cylinder.
    pub stick_m: f64,
    /// Bucket cylinder.
    pub bucket_m: f64,
}

impl CylinderLengths {
    /// `[boom, stick, bucket]` as a vector.
    #[must_use]
    pub fn to_vector(self) -> Vector3<f64> {
        Vector3::new(self.boom_m, self.stick_m, self.bucket_m)
    }
}

/// Bucket pose in the base frame: cutting-edge tip and bucket angle to the horizontal.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BucketPose {
    /// Tip, forward of the swing axis, m.
    pub x_m: f64,
    /// Tip height above the track ground, m.
    pub z_m: f64,
    /// `bucket_abs`, rad.
    pub bucket_abs_rad: f64,
}

/// Pin positions of the linkage in the base frame, `[x, z]` in m.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LinkagePoints {
    /// Boom foot pin.
    pub boom_foot: [f64; 2],
    /// Stick pin (boom tip).
    pub stick_pin: [f64; 2],
    /// Bucket pin (stick tip).
    pub bucket_pin: [f64; 2],
    /// Cutting-edge tip.
    pub tip: [f64; 2],
}

/// Force and moment at the bucket tip in the base frame, exerted by the soil on the bucket.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TipForce {
    /// Forward component, N.
    pub fx_n: f64,
    /// Upward component, N.
    pub fz_n: f64,
    /// Moment in the digging plane, counter-clockwise positive, N m.
    pub my_nm: f64,
}

impl TipForce {
    /// `(F_x, F_z, M_y)` as a vector.
    #[must_use]
    pub fn to_vector(self) -> Vector3<f64> {
        Vector3::new(self.fx_n, self.fz_n, self.my_nm)
    }

    /// From an `(F_x, F_z, M_y)` vector.
    #[must_use]
    pub fn from_vector(v: &Vector3<f64>) -> Self {
        Self {
            fx_n: v[0],
            fz_n: v[1],
            my_nm: v[2],
        }
    }

    /// Magnitude of the force part, N.
    #[must_use]
    pub fn force_magnitude_n(self) -> f64 {
        self.fx_n.hypot(self.fz_n)
    }
}

/// Machine pose in the world frame (x east, y north, heading of the tracks from x, counter-clockwise).
/// The base frame's `z = 0` is taken as world `z = 0` (the floor the machine stands on).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MachinePose {
    /// East, m.
    pub x_m: f64,
    /// North, m.
    pub y_m: f64,
    /// Heading, rad.
    pub heading_rad: f64,
}

impl MachinePose {
    /// World point of a base-frame point `(x, z)` in the digging plane at swing angle `swing_rad`.
    #[must_use]
    pub fn world_from_base(&self, swing_rad: f64, x_m: f64, z_m: f64) -> [f64; 3] {
        let az = self.heading_rad + swing_rad;
        [self.x_m + x_m * az.cos(), self.y_m + x_m * az.sin(), z_m]
    }

    /// Azimuth of the digging plane in the world at swing angle `swing_rad`, rad.
    #[must_use]
    pub fn dig_plane_azimuth_rad(&self, swing_rad: f64) -> f64 {
        self.heading_rad + swing_rad
    }
}

/// Kinematics and statics of one machine, precomputed from its [`MachineConfig`].
#[derive(Debug, Clone)]
pub struct Kinematics {
    foot: [f64; 2],
    l2: f64,
    l3: f64,
    l4: f64,
    boom: Mount,
    stick: Mount,
    four_bar: FourBar,
    /// `[boom, stick, bucket]` (retracted, extended) lengths, m.
    stroke: [(f64, f64); 3],
    /// Configured joint limits `(min, max)`, rad.
    limits: [(f64, f64); 3],
    /// Joint ranges the strokes allow `(min, max)`, rad.
    stroke_range: [(f64, f64); 3],
    /// `(mass, cog distance, cog angle)` of boom, stick, bucket.
    masses: [(f64, f64, f64); 3],
    payload_centroid: (f64, f64),
    head_area: [f64; 3],
    rod_area: [f64; 3],
}

impl Kinematics {
    /// Precomputes the machine's kinematics and checks its geometry: the boom and stick mounts keep the
    /// included angle in (0, pi) over the stroke, the four-bar assembles and is monotonic over the bucket
    /// stroke, and the configured joint limits lie inside the stroke-limited ranges.
    ///
    /// # Errors
    /// [`KinematicsError::Config`] naming the offending field.
    pub fn new(cfg: &MachineConfig) -> Result<Self> {
        let cyl = &cfg.cylinders;
        let linkage = cfg.linkage();
        let stroke_range = linkage.stroke_ranges()?;
        Ok(Self {
            foot: [cfg.base.boom_foot_x_m, cfg.base.boom_foot_z_m],
            l2: cfg.links.boom_m,
            l3: cfg.links.stick_m,
            l4: cfg.links.bucket_m,
            boom: linkage.boom,
            stick: linkage.stick,
            four_bar: linkage.four_bar,
            stroke: linkage.stroke,
            limits: linkage.limits,
            stroke_range,
            masses: [
                (
                    cfg.masses.boom.mass_kg,
                    cfg.masses.boom.cog_distance_m,
                    cfg.masses.boom.cog_angle_rad,
                ),
                (
                    cfg.masses.stick.mass_kg,
                    cfg.masses.stick.cog_distance_m,
                    cfg.masses.stick.cog_angle_rad,
                ),
                (
                    cfg.masses.bucket.mass_kg,
                    cfg.masses.bucket.cog_distance_m,
                    cfg.masses.bucket.cog_angle_rad,
                ),
            ],
            payload_centroid: (
                cfg.bucket.payload_centroid_distance_m,
                cfg.bucket.payload_centroid_angle_rad,
            ),
            head_area: [
                cyl.boom.head_area_m2(),
                cyl.stick.head_area_m2(),
                cyl.bucket.head_area_m2(),
            ],
            rod_area: [
                cyl.boom.rod_area_m2(),
                cyl.stick.rod_area_m2(),
                cyl.bucket.rod_area_m2(),
            ],
        })
    }

    /// Configured joint limits `(min, max)`, rad.
    #[must_use]
    pub fn joint_limits(&self, joint: Joint) -> (f64, f64) {
        self.limits[joint.index()]
    }

    /// Joint range `(min, max)` the cylinder stroke allows, rad.
    #[must_use]
    pub fn stroke_limited_range(&self, joint: Joint) -> (f64, f64) {
        self.stroke_range[joint.index()]
    }

    /// Cylinder `(retracted, extended)` lengths, m.
    #[must_use]
    pub fn stroke(&self, joint: Joint) -> (f64, f64) {
        self.stroke[joint.index()]
    }

    /// Link lengths `[boom, stick, bucket]`, m.
    #[must_use]
    pub fn link_lengths(&self) -> [f64; 3] {
        [self.l2, self.l3, self.l4]
    }

    /// Boom foot pin in the base frame `[x, z]`, m.
    #[must_use]
    pub fn boom_foot(&self) -> [f64; 2] {
        self.foot
    }

    /// Checks the angles against the configured joint limits.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] or the first [`KinematicsError::JointLimit`].
    pub fn check_limits(&self, q: &JointAngles) -> Result<()> {
        ensure_finite(q.is_finite(), "joint angles")?;
        for joint in Joint::ALL {
            let (min_rad, max_rad) = self.limits[joint.index()];
            let angle_rad = q.get(joint);
            if angle_rad < min_rad - 1e-9 || angle_rad > max_rad + 1e-9 {
                return Err(KinematicsError::JointLimit {
                    joint,
                    angle_rad,
                    min_rad,
                    max_rad,
                });
            }
        }
        Ok(())
    }

    /// The bucket four-bar quantities at a bucket angle (Eqs. A8-A14 and the moment arm of A15-A19).
    ///
    /// # Errors
    /// [`KinematicsError::LinkageInfeasible`] where the linkage cannot assemble,
    /// [`KinematicsError::Singular`] at a toggle, [`KinematicsError::NonFinite`].
    pub fn bucket_linkage(&self, bucket_rad: f64) -> Result<BucketLinkageState> {
        ensure_finite(bucket_rad.is_finite(), "bucket angle")?;
        Ok(self.four_bar.state(bucket_rad)?)
    }

    /// Cylinder length for one joint angle, m (Eq. A5; bucket Eqs. A8-A13). Does not check the stroke.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`]; for the bucket, those of [`Self::bucket_linkage`].
    pub fn cylinder_length(&self, joint: Joint, angle_rad: f64) -> Result<f64> {
        ensure_finite(angle_rad.is_finite(), "joint angle")?;
        Ok(match joint {
            Joint::Boom => self.boom.length(angle_rad),
            Joint::Stick => self.stick.length(angle_rad),
            Joint::Bucket => self.four_bar.state(angle_rad)?.cylinder_length_m,
        })
    }

    /// Signed moment arm `dL/dtheta`, m/rad: boom `> 0`, stick and bucket `< 0` (Eqs. A6-A7, A15-A19).
    ///
    /// # Errors
    /// As [`Self::cylinder_length`].
    pub fn moment_arm(&self, joint: Joint, angle_rad: f64) -> Result<f64> {
        ensure_finite(angle_rad.is_finite(), "joint angle")?;
        Ok(match joint {
            Joint::Boom => self.boom.moment_arm(angle_rad),
            Joint::Stick => self.stick.moment_arm(angle_rad),
            Joint::Bucket => self.four_bar.state(angle_rad)?.moment_arm_m,
        })
    }

    /// Joint angle from a cylinder length (inverse of Eq. A5; for the bucket a safeguarded Newton solve of
    /// Eqs. A8-A13 on the stroke-limited range).
    ///
    /// # Errors
    /// [`KinematicsError::CylinderLimit`] outside the stroke (1 mm tolerance), [`KinematicsError::NonFinite`].
    pub fn joint_angle(&self, joint: Joint, length_m: f64) -> Result<f64> {
        ensure_finite(length_m.is_finite(), "cylinder length")?;
        let (min_m, max_m) = self.stroke[joint.index()];
        if length_m < min_m - 1e-3 || length_m > max_m + 1e-3 {
            return Err(KinematicsError::CylinderLimit {
                joint,
                length_m,
                min_m,
                max_m,
            });
        }
        let length = length_m.clamp(min_m, max_m);
        match joint {
            Joint::Boom => {
                Ok(self
                    .boom
                    .theta(law_of_cosines_angle(self.boom.a, self.boom.b, length)))
            }
            Joint::Stick => {
                Ok(self
                    .stick
                    .theta(law_of_cosines_angle(self.stick.a, self.stick.b, length)))
            }
            Joint::Bucket => {
                // L4 falls monotonically from the curl end (lo) to the open end (hi).
                let (mut lo, mut hi) = self.stroke_range[2];
                let mut t = lo + (hi - lo) * (max_m - length) / (max_m - min_m);
                for _ in 0..60 {
                    let s = self.four_bar.state(t)?;
                    let f = s.cylinder_length_m - length;
                    if f.abs() < 1e-12 {
                        break;
                    }
                    if f > 0.0 {
                        lo = t
                    } else {
                        hi = t
                    }
                    let newton = t - f / s.moment_arm_m;
                    t = if newton > lo && newton < hi {
                        newton
                    } else {
                        0.5 * (lo + hi)
                    };
                    if hi - lo < 1e-13 {
                        break;
                    }
                }
                Ok(t)
            }
        }
    }

    /// Cylinder lengths for a set of joint angles, checked against the strokes.
    ///
    /// # Errors
    /// [`KinematicsError::CylinderLimit`] (1 mm tolerance), or those of [`Self::cylinder_length`].
    pub fn cylinder_lengths(&self, q: &JointAngles) -> Result<CylinderLengths> {
        let mut out = [0.0; 3];
        for joint in Joint::ALL {
            let length_m = self.cylinder_length(joint, q.get(joint))?;
            let (min_m, max_m) = self.stroke[joint.index()];
            if length_m < min_m - 1e-3 || length_m > max_m + 1e-3 {
                return Err(KinematicsError::CylinderLimit {
                    joint,
                    length_m,
                    min_m,
                    max_m,
                });
            }
            out[joint.index()] = length_m;
        }
        Ok(CylinderLengths {
            boom_m: out[0],
            stick_m: out[1],
            bucket_m: out[2],
        })
    }

    /// Joint angles from cylinder lengths.
    ///
    /// # Errors
    /// As [`Self::joint_angle`].
    pub fn joint_angles(&self, lengths: &CylinderLengths) -> Result<JointAngles> {
        Ok(JointAngles {
            boom_rad: self.joint_angle(Joint::Boom, lengths.boom_m)?,
            stick_rad: self.joint_angle(Joint::Stick, lengths.stick_m)?,
            bucket_rad: self.joint_angle(Joint::Bucket, lengths.bucket_m)?,
        })
    }

    /// The three signed moment arms `dL_i/dtheta_i`, m/rad.
    ///
    /// # Errors
    /// As [`Self::moment_arm`].
    pub fn moment_arms(&self, q: &JointAngles) -> Result<Vector3<f64>> {
        Ok(Vector3::new(
            self.moment_arm(Joint::Boom, q.boom_rad)?,
            self.moment_arm(Joint::Stick, q.stick_rad)?,
            self.moment_arm(Joint::Bucket, q.bucket_rad)?,
        ))
    }

    /// Cylinder velocities from joint rates, m/s (`dL/dt = r dtheta/dt`).
    ///
    /// # Errors
    /// As [`Self::moment_arm`].
    pub fn cylinder_velocities(
        &self,
        q: &JointAngles,
        rates_rad_per_s: &Vector3<f64>,
    ) -> Result<Vector3<f64>> {
        Ok(self.moment_arms(q)?.component_mul(rates_rad_per_s))
    }

    /// Joint rates from cylinder velocities, rad/s.
    ///
    /// # Errors
    /// [`KinematicsError::Singular`] at a zero moment arm, or as [`Self::moment_arm`].
    pub fn joint_rates(
        &self,
        q: &JointAngles,
        velocities_m_per_s: &Vector3<f64>,
    ) -> Result<Vector3<f64>> {
        let r = self.nonzero_arms(q)?;
        Ok(velocities_m_per_s.component_div(&r))
    }

    fn nonzero_arms(&self, q: &JointAngles) -> Result<Vector3<f64>> {
        let r = self.moment_arms(q)?;
        if r.iter().any(|x| x.abs() < 1e-6) {
            return Err(KinematicsError::Singular {
                what: "zero cylinder moment arm",
            });
        }
        Ok(r)
    }

    /// Pin positions in the base frame (forward kinematics; does not check limits).
    #[must_use]
    pub fn linkage_points(&self, q: &JointAngles) -> LinkagePoints {
        let a2 = q.boom_rad;
        let a3 = a2 + q.stick_rad;
        let a4 = a3 + q.bucket_rad;
        let stick_pin = add(self.foot, scale(dir(a2), self.l2));
        let bucket_pin = add(stick_pin, scale(dir(a3), self.l3));
        let tip = add(bucket_pin, scale(dir(a4), self.l4));
        LinkagePoints {
            boom_foot: self.foot,
            stick_pin,
            bucket_pin,
            tip,
        }
    }

    /// Bucket pose (tip and `bucket_abs`) in the base frame.
    #[must_use]
    pub fn forward(&self, q: &JointAngles) -> BucketPose {
        let p = self.linkage_points(q);
        BucketPose {
            x_m: p.tip[0],
            z_m: p.tip[1],
            bucket_abs_rad: q.bucket_abs_rad(),
        }
    }

    /// Tip in the world at swing angle `swing_rad` for a machine pose.
    #[must_use]
    pub fn tip_in_world(&self, q: &JointAngles, swing_rad: f64, pose: &MachinePose) -> [f64; 3] {
        let t = self.forward(q);
        pose.world_from_base(swing_rad, t.x_m, t.z_m)
    }

    /// Payload centroid in the base frame `[x, z]`, m.
    #[must_use]
    pub fn payload_centroid(&self, q: &JointAngles) -> [f64; 2] {
        let p = self.linkage_points(q);
        let (d, ang) = self.payload_centroid;
        add(p.bucket_pin, scale(dir(q.bucket_abs_rad() + ang), d))
    }

    /// Horizontal offset of the payload centroid from the cutting edge, `x_c` of Eq. 19, m (positive when
    /// the centroid is farther from the machine than the tip).
    #[must_use]
    pub fn centroid_offset_x_m(&self, q: &JointAngles) -> f64 {
        self.payload_centroid(q)[0] - self.linkage_points(q).tip[0]
    }

    /// Inverse kinematics: joint angles placing the tip at `(x, z)` with `bucket_abs`, stick folded
    /// under the boom (stick angle negative), checked against joint limits and cylinder strokes.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`], [`KinematicsError::OutOfReach`], [`KinematicsError::JointLimit`],
    /// [`KinematicsError::CylinderLimit`].
    pub fn inverse(&self, pose: &BucketPose) -> Result<JointAngles> {
        ensure_finite(
            pose.x_m.is_finite() && pose.z_m.is_finite() && pose.bucket_abs_rad.is_finite(),
            "bucket pose",
        )?;
        let pin = sub(
            [pose.x_m, pose.z_m],
            scale(dir(pose.bucket_abs_rad), self.l4),
        );
        let d = sub(pin, self.foot);
        let r = norm(d);
        let (min_m, max_m) = ((self.l2 - self.l3).abs(), self.l2 + self.l3);
        let c3 = (r * r - self.l2 * self.l2 - self.l3 * self.l3) / (2.0 * self.l2 * self.l3);
        if !(-1.0..=1.0).contains(&c3) {
            return Err(KinematicsError::OutOfReach {
                distance_m: r,
                min_m,
                max_m,
            });
        }
        let stick = -c3.acos();
        let boom =
            d[1].atan2(d[0]) - (self.l3 * stick.sin()).atan2(self.l2 + self.l3 * stick.cos());
        let bucket = wrap_angle(pose.bucket_abs_rad - boom - stick);
        let q = JointAngles {
            boom_rad: wrap_angle(boom),
            stick_rad: stick,
            bucket_rad: bucket,
        };
        self.check_limits(&q)?;
        self.cylinder_lengths(&q)?;
        Ok(q)
    }

    /// The Jacobian of the tip `(x, z, bucket_abs)` with respect to `(boom, stick, bucket)` (Eq. A3, with
    /// `z` up: the second row is `+l C` where the thesis has `-l C`).
    #[must_use]
    pub fn jacobian(&self, q: &JointAngles) -> Matrix3<f64> {
        let a2 = q.boom_rad;
        let a3 = a2 + q.stick_rad;
        let a4 = a3 + q.bucket_rad;
        let (s2, c2) = a2.sin_cos();
        let (s23, c23) = a3.sin_cos();
        let (s234, c234) = a4.sin_cos();
        let (l2, l3, l4) = (self.l2, self.l3, self.l4);
        // Eq. A3
        Matrix3::new(
            -l2 * s2 - l3 * s23 - l4 * s234,
            -l3 * s23 - l4 * s234,
            -l4 * s234,
            l2 * c2 + l3 * c23 + l4 * c234,
            l3 * c23 + l4 * c234,
            l4 * c234,
            1.0,
            1.0,
            1.0,
        )
    }

    /// Holding torques against gravity `G`, N m (Eq. A4), with `payload_kg` at the payload centroid.
    /// `G_i = g sum_{n >= i} m_n l_in cos(psi_in)`: `l_in cos(psi_in)` is the horizontal distance from
    /// joint `i` to the centre of gravity of link `n`.
    #[must_use]
    pub fn gravity_torques(&self, q: &JointAngles, payload_kg: f64) -> Vector3<f64> {
        let p = self.linkage_points(q);
        let joints = [p.boom_foot, p.stick_pin, p.bucket_pin];
        let abs = [q.boom_rad, q.stick_abs_rad(), q.bucket_abs_rad()];
        let mut bodies: [(f64, f64); 4] = [(0.0, 0.0); 4]; // (mass, cog x)
        for n in 0..3 {
            let (m, d, ang) = self.masses[n];
            bodies[n] = (m, joints[n][0] + d * (abs[n] + ang).cos());
        }
        bodies[3] = (payload_kg.max(0.0), self.payload_centroid(q)[0]);
        gravity_torques_of_bodies([joints[0][0], joints[1][0], joints[2][0]], &bodies)
    }

    /// Joint torques the actuators must supply to hold a tip force `f` (soil on bucket): `tau = G - J^T f`
    /// (Eq. A2 with the thesis's `f` = bucket on soil = `-f`).
    #[must_use]
    pub fn joint_torques_from_tip_force(
        &self,
        q: &JointAngles,
        f: &TipForce,
        payload_kg: f64,
    ) -> Vector3<f64> {
        self.gravity_torques(q, payload_kg) - self.jacobian(q).transpose() * f.to_vector() // Eq. A2
    }

    /// Cylinder forces from joint torques, N (`F = tau / r`: Eq. A7 for boom and stick, Eq. A19 for the
    /// bucket; positive pushes toward extension).
    ///
    /// # Errors
    /// [`KinematicsError::Singular`] at a zero moment arm, or as [`Self::moment_arm`].
    pub fn cylinder_forces_from_joint_torques(
        &self,
        q: &JointAngles,
        tau: &Vector3<f64>,
    ) -> Result<Vector3<f64>> {
        let r = self.nonzero_arms(q)?;
        Ok(tau.component_div(&r)) // Eqs. A7, A19
    }

    /// Joint torques from cylinder forces, N m (`tau = F r`: Eq. A21 for boom and stick, Eq. A22 for the
    /// bucket).
    ///
    /// # Errors
    /// As [`Self::moment_arm`].
    pub fn joint_torques_from_cylinder_forces(
        &self,
        q: &JointAngles,
        forces_n: &Vector3<f64>,
    ) -> Result<Vector3<f64>> {
        Ok(self.moment_arms(q)?.component_mul(forces_n)) // Eqs. A21, A22
    }

    /// Cylinder forces needed to hold a tip force (soil on bucket) against gravity and payload, N
    /// (Eqs. A2, A7, A19).
    ///
    /// # Errors
    /// As [`Self::cylinder_forces_from_joint_torques`].
    pub fn cylinder_forces_from_tip_force(
        &self,
        q: &JointAngles,
        f: &TipForce,
        payload_kg: f64,
    ) -> Result<Vector3<f64>> {
        let tau = self.joint_torques_from_tip_force(q, f, payload_kg);
        self.cylinder_forces_from_joint_torques(q, &tau)
    }

    /// Tip force (soil on bucket) from joint torques: `f = J^-T (G - tau)` (Eq. A23).
    ///
    /// # Errors
    /// [`KinematicsError::Singular`] when the stick is stretched (`det J = l2 l3 sin(stick) = 0`),
    /// [`KinematicsError::NonFinite`].
    pub fn tip_force_from_joint_torques(
        &self,
        q: &JointAngles,
        tau: &Vector3<f64>,
        payload_kg: f64,
    ) -> Result<TipForce> {
        ensure_finite(
            q.is_finite() && tau.iter().all(|x| x.is_finite()) && payload_kg.is_finite(),
            "joint angles, torques or payload",
        )?;
        if q.stick_rad.sin().abs() < 1e-6 {
            return Err(KinematicsError::Singular {
                what: "stick stretched (Jacobian singular)",
            });
        }
        let jt = self.jacobian(q).transpose();
        let rhs = self.gravity_torques(q, payload_kg) - tau;
        let f = jt.lu().solve(&rhs).ok_or(KinematicsError::Singular {
            what: "Jacobian not invertible",
        })?; // Eq. A23
        Ok(TipForce::from_vector(&f))
    }

    /// Tip force (soil on bucket) from cylinder forces (Eqs. A21-A23).
    ///
    /// # Errors
    /// As [`Self::tip_force_from_joint_torques`].
    pub fn tip_force_from_cylinder_forces(
        &self,
        q: &JointAngles,
        forces_n: &Vector3<f64>,
        payload_kg: f64,
    ) -> Result<TipForce> {
        let tau = self.joint_torques_from_cylinder_forces(q, forces_n)?;
        self.tip_force_from_joint_torques(q, &tau, payload_kg)
    }

    /// Cylinder forces from head and rod pressures `[boom, stick, bucket]`, N (Eq. A20).
    #[must_use]
    pub fn cylinder_forces_from_pressures(
        &self,
        head_pa: &Vector3<f64>,
        rod_pa: &Vector3<f64>,
    ) -> Vector3<f64> {
        Vector3::from_fn(|i, _| head_pa[i] * self.head_area[i] - rod_pa[i] * self.rod_area[i]) // Eq. A20
    }

    /// Tip force (soil on bucket) from measured cylinder pressures (Eqs. A20-A23).
    ///
    /// # Errors
    /// As [`Self::tip_force_from_joint_torques`].
    pub fn tip_force_from_pressures(
        &self,
        q: &JointAngles,
        head_pa: &Vector3<f64>,
        rod_pa: &Vector3<f64>,
        payload_kg: f64,
    ) -> Result<TipForce> {
        let forces = self.cylinder_forces_from_pressures(head_pa, rod_pa);
        self.tip_force_from_cylinder_forces(q, &forces, payload_kg)
    }
}

/// Least-squares payload mass from the joints that may weigh it, kg: `m` minimising
/// `sum_i (excess_i - m regressor_i)^2` over the joints with `usable[i]`, where `excess` is the joint
/// torque beyond what the empty implement needs (Eqs. A21-A22 less the links' A19 gravity torques)
/// and `regressor` the torque one kilogram of payload adds (its gravity torque, A19, and where the
/// implement accelerates its inertia). `None` when no usable joint carries a regressor. Linear in
/// `excess`, so the same call gives the estimate's change for a change of the torques.
#[must_use]
pub fn payload_least_squares(
    regressor: &[f64; 3],
    excess_torque_nm: &[f64; 3],
    usable: [bool; 3],
) -> Option<f64> {
    let (mut num, mut denom) = (0.0, 0.0);
    for i in (0..3).filter(|i| usable[*i]) {
        num += regressor[i] * excess_torque_nm[i];
        denom += regressor[i] * regressor[i];
    }
    if !(denom.is_finite() && denom > 1e-9) {
        return None;
    }
    let m = num / denom;
    m.is_finite().then_some(m)
}

/// Wraps an angle to `(-pi, pi]`.
#[must_use]
pub fn wrap_angle(a: f64) -> f64 {
    let mut x = (a + PI).rem_euclid(2.0 * PI) - PI;
    if x <= -PI {
        x += 2.0 * PI;
    }
    x
}

/// Eq. A4 from positions: `G_i = g sum_{n >= i} m_n (x_n - x_i)`, N m, with `joint_x_m` the
/// horizontal positions of the boom foot, stick pin and bucket pin, and `bodies` the (mass kg, centre of
/// gravity x m) of boom, stick, bucket and payload. The payload rides on the bucket (link 4), so it
/// loads every joint.
#[must_use]
#[inline]
pub fn gravity_torques_of_bodies(joint_x_m: [f64; 3], bodies: &[(f64, f64); 4]) -> Vector3<f64> {
    let mut g = Vector3::zeros();
    for (i, xi) in joint_x_m.iter().enumerate() {
        let mut sum = 0.0;
        for (m, x) in &bodies[i..] {
            sum += m * (x - xi);
        }
        g[i] = GRAVITY_M_PER_S2 * sum; // Eq. A4
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn kin() -> Kinematics {
        let m = MachineConfig::default_machine().expect("default machine");
        Kinematics::new(&m).expect("kinematics")
    }

    /// A mid-dig fixture pose: boom slightly down, stick near vertical, bucket partly curled.
    const FIXTURE: JointAngles = JointAngles {
        boom_rad: -0.35,
        stick_rad: -1.20,
        bucket_rad: -0.60,
    };

    fn in_limits(k: &Kinematics, u: [f64; 3]) -> JointAngles {
        let l = |j: Joint, t: f64| {
            let (lo, hi) = k.joint_limits(j);
            lo + (hi - lo) * t
        };
        JointAngles {
            boom_rad: l(Joint::Boom, u[0]),
            stick_rad: l(Joint::Stick, u[1]),
            bucket_rad: l(Joint::Bucket, u[2]),
        }
    }

    #[test]
    fn linkage_errors_keep_their_text_as_kinematics_errors() {
        // The machine file's geometric check reports the linkage's text, Kinematics::new its own.
        for e in [
            LinkageError::Singular { what: "toggle" },
            LinkageError::Infeasible { bucket_rad: 0.5 },
            LinkageError::Config {
                field: "limits.boom_max_deg".into(),
                reason: "too far".into(),
            },
        ] {
            assert_eq!(KinematicsError::from(e.clone()).to_string(), e.to_string());
        }
    }

    #[test]
    fn stroke_ranges_are_realistic() {
        let k = kin();
        let deg = |j| {
            let (a, b) = k.stroke_limited_range(j);
            (a.to_degrees(), b.to_degrees())
        };
        let (b0, b1) = deg(Joint::Boom);
        assert!(
            (-65.0..=-50.0).contains(&b0) && (50.0..=65.0).contains(&b1),
            "boom {b0} {b1}"
        );
        let (s0, s1) = deg(Joint::Stick);
        assert!(
            (-165.0..=-145.0).contains(&s0) && (-45.0..=-30.0).contains(&s1),
            "stick {s0} {s1}"
        );
        let (k0, k1) = deg(Joint::Bucket);
        assert!((k1 - k0) > 165.0 && (k1 - k0) < 190.0, "bucket {k0} {k1}");
        // Sign conventions: boom extension raises, stick and bucket extension curl in.
        assert!(k.moment_arm(Joint::Boom, 0.0).expect("arm") > 0.3);
        assert!(k.moment_arm(Joint::Stick, -1.5).expect("arm") < -0.3);
        assert!(k.moment_arm(Joint::Bucket, -0.5).expect("arm") < -0.1);
    }

    #[test]
    fn fixture_pose_forward_and_inverse() {
        let k = kin();
        let p = k.forward(&FIXTURE);
        // Independent evaluation of the chain.
        let (a2, a3, a4) = (-0.35_f64, -1.55_f64, -2.15_f64);
        let x = 0.20 + 5.70 * a2.cos() + 2.90 * a3.cos() + 1.50 * a4.cos();
        let z = 2.00 + 5.70 * a2.sin() + 2.90 * a3.sin() + 1.50 * a4.sin();
        assert!((p.x_m - x).abs() < 1e-12 && (p.z_m - z).abs() < 1e-12);
        let q = k.inverse(&p).expect("reachable");
        assert!((q.to_vector() - FIXTURE.to_vector()).norm() < 1e-9);
    }

    #[test]
    fn inverse_reports_typed_errors() {
        let k = kin();
        let far = BucketPose {
            x_m: 20.0,
            z_m: 0.0,
            bucket_abs_rad: -1.5,
        };
        assert!(matches!(
            k.inverse(&far),
            Err(KinematicsError::OutOfReach { .. })
        ));
        let nan = BucketPose {
            x_m: f64::NAN,
            z_m: 0.0,
            bucket_abs_rad: 0.0,
        };
        assert!(matches!(
            k.inverse(&nan),
            Err(KinematicsError::NonFinite { .. })
        ));
        // Reachable position but a bucket attitude outside the bucket's range.
        let mut p = k.forward(&FIXTURE);
        p.bucket_abs_rad += 2.6;
        assert!(matches!(
            k.inverse(&p),
            Err(KinematicsError::JointLimit {
                joint: Joint::Bucket,
                ..
            })
        ));
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let k = kin();
        let j = k.jacobian(&FIXTURE);
        let h = 1e-6;
        for c in 0..3 {
            let mut qp = FIXTURE.to_vector();
            let mut qm = qp;
            qp[c] += h;
            qm[c] -= h;
            let pp = k.forward(&JointAngles::from_vector(&qp));
            let pm = k.forward(&JointAngles::from_vector(&qm));
            let fd = [
                (pp.x_m - pm.x_m) / (2.0 * h),
                (pp.z_m - pm.z_m) / (2.0 * h),
                (pp.bucket_abs_rad - pm.bucket_abs_rad) / (2.0 * h),
            ];
            for r in 0..3 {
                assert!(
                    (j[(r, c)] - fd[r]).abs() < 1e-6,
                    "J[{r},{c}] {} vs {}",
                    j[(r, c)],
                    fd[r]
                );
            }
        }
    }

    #[test]
    fn bucket_moment_arm_matches_eqs_a17_a18_and_finite_differences() {
        let k = kin();
        let (lo, hi) = k.joint_limits(Joint::Bucket);
        for i in 0..=20 {
            let t = lo + (hi - lo) * f64::from(i) / 20.0;
            let s = k.bucket_linkage(t).expect("assembles");
            // Eq. A17 (= -sin(theta1)/sin(theta2) by Lami) and Eq. A18 give |F4/tau4|.
            let lami = k.four_bar.e1 * s.theta3_rad.sin() * s.theta2_rad.sin() / s.theta1_rad.sin();
            let a17 = (s.theta1_rad + s.theta2_rad).cos()
                - (s.theta1_rad + s.theta2_rad).sin() / s.theta2_rad.tan();
            assert!((a17.abs() - s.theta1_rad.sin() / s.theta2_rad.sin()).abs() < 1e-9);
            assert!(
                (s.moment_arm_m.abs() - lami).abs() < 1e-9,
                "{} vs {lami}",
                s.moment_arm_m
            );
            let h = 1e-6;
            let fd = (k.cylinder_length(Joint::Bucket, t + h).expect("l")
                - k.cylinder_length(Joint::Bucket, t - h).expect("l"))
                / (2.0 * h);
            assert!(
                (fd - s.moment_arm_m).abs() < 1e-6,
                "{fd} vs {}",
                s.moment_arm_m
            );
        }
    }

    #[test]
    fn gravity_torques_match_potential_energy_gradient() {
        let k = kin();
        let payload = MachineConfig::default_machine()
            .expect("default machine")
            .rated_payload_kg();
        // G = dV/dq with V = sum m g z_cog: the holding torque equals the potential gradient.
        let pot = |q: &JointAngles| -> f64 {
            let p = k.linkage_points(q);
            let joints = [p.boom_foot, p.stick_pin, p.bucket_pin];
            let abs = [q.boom_rad, q.stick_abs_rad(), q.bucket_abs_rad()];
            let mut v = payload * GRAVITY_M_PER_S2 * k.payload_centroid(q)[1];
            for n in 0..3 {
                let (m, d, a) = k.masses[n];
                v += m * GRAVITY_M_PER_S2 * (joints[n][1] + d * (abs[n] + a).sin());
            }
            v
        };
        let g = k.gravity_torques(&FIXTURE, payload);
        for c in 0..3 {
            let h = 1e-6;
            let mut qp = FIXTURE.to_vector();
            let mut qm = qp;
            qp[c] += h;
            qm[c] -= h;
            let fd = (pot(&JointAngles::from_vector(&qp)) - pot(&JointAngles::from_vector(&qm)))
                / (2.0 * h);
            assert!(
                (fd - g[c]).abs() < 1e-3 * g[c].abs().max(1.0),
                "{c}: {fd} vs {}",
                g[c]
            );
        }
    }

    #[test]
    fn thesis_peak_forces_are_within_the_machines_capacity() {
        // Relief pressure on the head sides gives tip forces of the order of the thesis's 142 kN peak.
        let m = MachineConfig::default_machine().expect("default");
        let k = Kinematics::new(&m).expect("kin");
        let relief = m.hydraulics.relief_pressure_pa;
        let bucket_f = m.cylinders.bucket.force_n(relief, 0.0);
        let tau = k
            .moment_arm(Joint::Bucket, FIXTURE.bucket_rad)
            .expect("arm")
            * bucket_f;
        let breakout_n = tau.abs() / m.links.bucket_m;
        assert!((80e3..250e3).contains(&breakout_n), "{breakout_n}");
    }

    #[test]
    fn working_envelope_is_that_of_a_20_to_25_t_machine() {
        let m = MachineConfig::default_machine().expect("default");
        let k = Kinematics::new(&m).expect("kin");
        let (mut reach, mut depth, mut height) = (0.0_f64, 0.0_f64, 0.0_f64);
        let n = 40;
        for a in 0..=n {
            for b in 0..=n {
                let f = |i: i32| f64::from(i) / f64::from(n);
                let q = in_limits(&k, [f(a), f(b), 0.5]);
                let pin = k.linkage_points(&q).bucket_pin;
                // The bucket can point the tip straight out, down or up from its pin.
                reach = reach.max(pin[0] + k.l4);
                depth = depth.min(pin[1] - k.l4);
                height = height.max(pin[1] + k.l4);
            }
        }
        let relief = m.hydraulics.relief_pressure_pa;
        let (mut bucket_n, mut stick_n) = (0.0_f64, 0.0_f64);
        for i in 0..=n {
            let t = f64::from(i) / f64::from(n);
            let q = in_limits(&k, [0.5, t, t]);
            let r = k.moment_arms(&q).expect("arms");
            bucket_n = bucket_n.max((m.cylinders.bucket.force_n(relief, 0.0) * r[2]).abs() / k.l4);
            stick_n =
                stick_n.max((m.cylinders.stick.force_n(relief, 0.0) * r[1]).abs() / (k.l3 + k.l4));
        }
        println!(
            "reach {reach:.2} m, dig depth {:.2} m, height {height:.2} m, bucket breakout {:.0} kN, stick crowd {:.0} kN",
            -depth,
            bucket_n / 1e3,
            stick_n / 1e3
        );
        assert!((9.0..11.5).contains(&reach), "{reach}");
        assert!((5.5..8.0).contains(&-depth), "{depth}");
        assert!((100e3..200e3).contains(&bucket_n) && (70e3..160e3).contains(&stick_n));
    }

    proptest! {
        #[test]
        fn angle_length_angle_round_trip(u in proptest::array::uniform3(0.0f64..=1.0)) {
            let k = kin();
            let q = in_limits(&k, u);
            let l = k.cylinder_lengths(&q).expect("within stroke");
            let back = k.joint_angles(&l).expect("inverse");
            prop_assert!((back.to_vector() - q.to_vector()).norm() < 1e-9);
        }

        #[test]
        fn virtual_work_holds(u in proptest::array::uniform3(0.0f64..=1.0), f in proptest::array::uniform3(-1e5f64..1e5)) {
            // sum F_i dL_i == sum tau_j dtheta_j for a small motion.
            let k = kin();
            let q = in_limits(&k, [0.05 + 0.9 * u[0], 0.05 + 0.9 * u[1], 0.05 + 0.9 * u[2]]);
            let forces = Vector3::from(f);
            let tau = k.joint_torques_from_cylinder_forces(&q, &forces).expect("tau");
            let dq = Vector3::new(1e-6, -2e-6, 1.5e-6);
            let l0 = k.cylinder_lengths(&q).expect("l0").to_vector();
            let l1 = k.cylinder_lengths(&JointAngles::from_vector(&(q.to_vector() + dq))).expect("l1").to_vector();
            let w_cyl = forces.dot(&(l1 - l0));
            let w_joint = tau.dot(&dq);
            prop_assert!((w_cyl - w_joint).abs() <= 1e-6 * (1.0 + w_joint.abs()) + 1e-7, "{} vs {}", w_cyl, w_joint);
        }

        #[test]
        fn tip_force_round_trips_through_cylinders(u in proptest::array::uniform3(0.05f64..=0.95), f in proptest::array::uniform3(-1e5f64..1e5), payload in 0.0f64..3000.0) {
            let k = kin();
            let q = in_limits(&k, u);
            let f = TipForce { fx_n: f[0], fz_n: f[1], my_nm: f[2] * 0.3 };
            let forces = k.cylinder_forces_from_tip_force(&q, &f, payload).expect("forces");
            let back = k.tip_force_from_cylinder_forces(&q, &forces, payload).expect("back");
            prop_assert!((back.to_vector() - f.to_vector()).norm() < 1e-6 * (1.0 + f.to_vector().norm()));
            // force -> torque -> force
            let tau = k.joint_torques_from_cylinder_forces(&q, &forces).expect("tau");
            let f2 = k.cylinder_forces_from_joint_torques(&q, &tau).expect("f2");
            prop_assert!((f2 - forces).norm() < 1e-6 * (1.0 + forces.norm()));
        }

        #[test]
        fn forward_inverse_round_trip(u in proptest::array::uniform3(0.0f64..=1.0)) {
            let k = kin();
            let q = in_limits(&k, u);
            let back = k.inverse(&k.forward(&q)).expect("reachable");
            prop_assert!((back.to_vector() - q.to_vector()).norm() < 1e-8);
        }

        #[test]
        fn arbitrary_inputs_never_panic(a in proptest::num::f64::ANY, b in proptest::num::f64::ANY, c in proptest::num::f64::ANY) {
            let k = kin();
            let q = JointAngles { boom_rad: a, stick_rad: b, bucket_rad: c };
            let _ = k.cylinder_lengths(&q);
            let _ = k.inverse(&BucketPose { x_m: a, z_m: b, bucket_abs_rad: c });
            let _ = k.joint_angle(Joint::Bucket, a);
            let _ = k.tip_force_from_joint_torques(&q, &Vector3::new(a, b, c), 0.0);
        }
    }
}
