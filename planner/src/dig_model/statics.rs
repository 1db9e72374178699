//! The static analysis the model steps through (Appendix): stroke tables from cylinder length to joint
//! angle and moment arm, gravity and the Jacobian in one pass over the joint angles, and the section's
//! surface as the dig cuts it.

use super::{DigModelError, Result, TABLE_POINTS};
use crate::kinematics::{Joint, Kinematics, KinematicsError};
use crate::machine::MachineConfig;
use crate::terrain::SectionProfile;

/// Joint angle and moment arm as functions of cylinder length, tabulated over the stroke.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct StrokeTable {
    pub(super) lo_m: f64,
    pub(super) hi_m: f64,
    pub(super) step_m: f64,
    pub(super) angle_rad: Vec<f64>,
    pub(super) arm_m: Vec<f64>,
}

impl StrokeTable {
    pub(super) fn new(kin: &Kinematics, joint: Joint) -> Result<Self> {
        let (lo, hi) = kin.stroke(joint);
        let step = (hi - lo) / (TABLE_POINTS - 1) as f64;
        let mut angle_rad = Vec::with_capacity(TABLE_POINTS);
        let mut arm_m = Vec::with_capacity(TABLE_POINTS);
        for k in 0..TABLE_POINTS {
            let a = kin
                .joint_angle(joint, lo + k as f64 * step)
                .map_err(DigModelError::Kinematics)?; // Eq. A5, A8-A13
            let r = kin
                .moment_arm(joint, a)
                .map_err(DigModelError::Kinematics)?; // Eqs. A6-A7, A15-A19
            if r.abs() < 1e-6 {
                return Err(DigModelError::Kinematics(KinematicsError::Singular {
                    what: "zero cylinder moment arm within the stroke",
                }));
            }
            angle_rad.push(a);
            arm_m.push(r);
        }
        Ok(Self {
            lo_m: lo,
            hi_m: hi,
            step_m: step,
            angle_rad,
            arm_m,
        })
    }

    /// `(angle, moment arm)` at length `l` (clamped to the stroke), linear between table points.
    #[inline]
    pub(super) fn lookup(&self, l: f64) -> (f64, f64) {
        let f = ((l - self.lo_m) / self.step_m).clamp(0.0, (TABLE_POINTS - 1) as f64);
        let k = (f as usize).min(TABLE_POINTS - 2);
        let t = f - k as f64;
        let lerp = |v: &[f64]| v[k] + t * (v[k + 1] - v[k]);
        (lerp(&self.angle_rad), lerp(&self.arm_m))
    }
}

/// Forward kinematics, the Jacobian (Eq. A3) and the gravity torques (Eq. A4) in one pass: one
/// `sin_cos` per joint instead of the three `linkage_points` evaluations of calling
/// [`Kinematics::forward`], [`Kinematics::jacobian`] and [`Kinematics::gravity_torques`] in turn
/// (tested equal to them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Statics {
    pub(super) foot: [f64; 2],
    /// Link lengths `l2, l3, l4` (boom, stick, bucket), m.
    pub(super) links: [f64; 3],
    /// Per link: mass, kg; centre-of-gravity distance, m; `cos` and `sin` of its angle to the link line.
    pub(super) masses: [(f64, f64, f64, f64); 3],
    /// Payload centroid: distance from the bucket pin, m; `cos` and `sin` of its angle to the bucket line.
    pub(super) payload: (f64, f64, f64),
}

/// What [`Statics::eval`] gives for one pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PoseStatics {
    pub(super) tip: [f64; 2],
    /// `sin`, `cos` of `bucket_abs`.
    pub(super) sin_bucket_abs: f64,
    pub(super) cos_bucket_abs: f64,
    /// First two rows of the Jacobian (Eq. A3): `d x / d q_j`, `d z / d q_j` (third row is all ones).
    pub(super) jx: [f64; 3],
    pub(super) jz: [f64; 3],
    /// Gravity torques `G` of the empty implement (Eq. A4), N m.
    pub(super) gravity_nm: [f64; 3],
    /// Horizontal distance from each joint to the payload centroid, m: the payload adds
    /// `g m_p payload_arm_m[i]` to `G_i`.
    pub(super) payload_arm_m: [f64; 3],
}

impl PoseStatics {
    /// Gravity torques with `payload_kg` in the bucket (Eq. A4), N m.
    #[inline]
    pub(super) fn gravity_with_payload(&self, payload_kg: f64) -> [f64; 3] {
        let w = crate::machine::GRAVITY_M_PER_S2 * payload_kg.max(0.0);
        [0, 1, 2].map(|i| self.gravity_nm[i] + w * self.payload_arm_m[i])
    }
}

impl Statics {
    pub(super) fn new(machine: &MachineConfig) -> Self {
        let m = &machine.masses;
        let link = |l: &crate::machine::LinkMass| {
            let (s, c) = l.cog_angle_rad.sin_cos();
            (l.mass_kg, l.cog_distance_m, c, s)
        };
        let (ps, pc) = machine.bucket.payload_centroid_angle_rad.sin_cos();
        Self {
            foot: [machine.base.boom_foot_x_m, machine.base.boom_foot_z_m],
            links: [
                machine.links.boom_m,
                machine.links.stick_m,
                machine.links.bucket_m,
            ],
            masses: [link(&m.boom), link(&m.stick), link(&m.bucket)],
            payload: (machine.bucket.payload_centroid_distance_m, pc, ps),
        }
    }

    #[inline]
    pub(super) fn eval(&self, q: &[f64; 3]) -> PoseStatics {
        let [l2, l3, l4] = self.links;
        let (s2, c2) = q[0].sin_cos();
        let (s23, c23) = (q[0] + q[1]).sin_cos();
        let (s234, c234) = (q[0] + q[1] + q[2]).sin_cos();
        let stick_pin = [self.foot[0] + l2 * c2, self.foot[1] + l2 * s2];
        let bucket_pin = [stick_pin[0] + l3 * c23, stick_pin[1] + l3 * s23];
        let tip = [bucket_pin[0] + l4 * c234, bucket_pin[1] + l4 * s234];
        // Eq. A3 (z up)
        let jx = [
            -l2 * s2 - l3 * s23 - l4 * s234,
            -l3 * s23 - l4 * s234,
            -l4 * s234,
        ];
        let jz = [
            l2 * c2 + l3 * c23 + l4 * c234,
            l3 * c23 + l4 * c234,
            l4 * c234,
        ];
        // Eq. A4: G_i = g sum_{n >= i} m_n (x_n - x_i), the payload riding on the bucket.
        let joints_x = [self.foot[0], stick_pin[0], bucket_pin[0]];
        let abs_cs = [(c2, s2), (c23, s23), (c234, s234)];
        let mut body = [(0.0, 0.0); 3];
        for n in 0..3 {
            let (mass, d, ca, sa) = self.masses[n];
            let (c, s) = abs_cs[n];
            body[n] = (mass, joints_x[n] + d * (c * ca - s * sa));
        }
        let (pd, pca, psa) = self.payload;
        let payload_x = bucket_pin[0] + pd * (c234 * pca - s234 * psa);
        let mut gravity_nm = [0.0; 3];
        for (i, g) in gravity_nm.iter_mut().enumerate() {
            let xi = joints_x[i];
            let sum: f64 = body[i..].iter().map(|(m, x)| m * (x - xi)).sum();
            *g = crate::machine::GRAVITY_M_PER_S2 * sum;
        }
        PoseStatics {
            tip,
            sin_bucket_abs: s234,
            cos_bucket_abs: c234,
            jx,
            jz,
            gravity_nm,
            payload_arm_m: joints_x.map(|x| payload_x - x),
        }
    }
}

/// The terrain along the digging plane as the dig cuts it: the pre-dig section lowered to the tip's
/// path wherever the tip passed below it (the simulator cuts its grid the same way), so the soil
/// geometry (depth, slope) is measured on the current surface as on a real machine.
#[derive(Debug, Clone)]
pub(super) struct CutSurface {
    pub(super) r_start_m: f64,
    pub(super) step_m: f64,
    pub(super) heights: Vec<f64>,
}

impl CutSurface {
    pub(super) fn new(profile: &SectionProfile) -> Result<Self> {
        let step = profile.step_m();
        let n = ((profile.r_end_m() - profile.r_start_m()) / step).round() as usize + 1;
        let mut heights = Vec::with_capacity(n);
        for k in 0..n {
            let r = (profile.r_start_m() + k as f64 * step).min(profile.r_end_m());
            heights.push(profile.height_at(r)?);
        }
        Ok(Self {
            r_start_m: profile.r_start_m(),
            step_m: step,
            heights,
        })
    }

    /// Height at `r` (linear between samples, the end samples beyond the section), m.
    #[inline]
    pub(super) fn height(&self, r_m: f64) -> f64 {
        let last = self.heights.len() - 1;
        let f = ((r_m - self.r_start_m) / self.step_m).clamp(0.0, last as f64);
        let k = (f as usize).min(last - 1);
        let t = f - k as f64;
        self.heights[k] + t * (self.heights[k + 1] - self.heights[k])
    }

    /// Lowers the samples between two tip positions to the straight path between them.
    #[inline]
    pub(super) fn cut(&mut self, from: [f64; 2], to: [f64; 2]) {
        let (lo, hi) = if from[0] < to[0] {
            (from[0], to[0])
        } else {
            (to[0], from[0])
        };
        let dx = to[0] - from[0];
        if dx.abs() < 1e-12 {
            return;
        }
        let last = self.heights.len() - 1;
        let k0 = ((lo - self.r_start_m) / self.step_m).ceil().max(0.0) as usize;
        let k1 = (((hi - self.r_start_m) / self.step_m).floor().max(-1.0) + 1.0) as usize;
        for k in k0..k1.min(last + 1) {
            let r = self.r_start_m + k as f64 * self.step_m;
            let z = from[1] + (r - from[0]) / dx * (to[1] - from[1]);
            if z < self.heights[k] {
                self.heights[k] = z;
            }
        }
    }
}
