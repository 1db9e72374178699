//! The implement linkage in the side view, in plain numbers: the boom and stick cylinder triangles
//! (law of cosines, Eqs. A5-A7), the bucket four-bar (Eqs. A8-A19), and the joint ranges the cylinder
//! strokes allow.
//!
//! It sits below both [`crate::machine`], which builds a [`Linkage`] from the description to check its
//! geometry when a machine file is read, and [`crate::kinematics`], which builds on the same linkage;
//! so the check and the kinematics cannot disagree, and neither module needs the other's.

/// Errors of the linkage geometry; [`crate::kinematics::KinematicsError`] carries each with the same text.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum LinkageError {
    /// A toggle of the four-bar (zero transmission).
    #[error("singular configuration: {what}")]
    Singular {
        /// What degenerated.
        what: &'static str,
    },
    /// The bucket four-bar cannot be assembled at this bucket angle.
    #[error("bucket four-bar cannot assemble at bucket angle {bucket_rad:.4} rad")]
    Infeasible {
        /// The bucket angle, rad.
        bucket_rad: f64,
    },
    /// The geometry is inconsistent.
    #[error("machine field `{field}`: {reason}")]
    Config {
        /// Dotted field path.
        field: String,
        /// Why.
        reason: String,
    },
}

/// Intermediate quantities of the bucket four-bar at one bucket angle (Eqs. A8-A14, Fig. A2).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BucketLinkageState {
    /// Side-link pivot to the bucket's H-link pin, m (Eq. A8).
    pub k1_m: f64,
    /// Angle at the rod-end joint between side link and H-link, rad (Eq. A9).
    pub theta1_rad: f64,
    /// Angle at the rod-end joint between cylinder and side link, rad (Eq. A14).
    pub theta2_rad: f64,
    /// Angle at the bucket's H-link pin between `e1` and the H-link, rad (Eq. A10).
    pub theta3_rad: f64,
    /// Bucket pin to the rod-end joint, m (Eq. A11).
    pub k2_m: f64,
    /// Angle at the bucket pin between the cylinder base and the rod-end joint, rad (Eq. A12).
    pub alpha_rad: f64,
    /// Bucket cylinder length, m (Eq. A13).
    pub cylinder_length_m: f64,
    /// Signed moment arm `dL4/dtheta4`, m/rad (Eqs. A15-A19; negative: extension curls).
    pub moment_arm_m: f64,
}

/// A cylinder mounted across a joint: the triangle of the two mount arms `a`, `b` and the cylinder
/// (Eq. A5, Fig. A1).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Mount {
    pub(crate) a: f64,
    pub(crate) b: f64,
    pub(crate) offset: f64,
    /// +1: gamma = theta + offset (boom); -1: gamma = offset - theta (stick).
    pub(crate) sense: f64,
}

impl Mount {
    pub(crate) fn gamma(&self, theta: f64) -> f64 {
        if self.sense > 0.0 {
            theta + self.offset
        } else {
            self.offset - theta
        }
    }

    pub(crate) fn theta(&self, gamma: f64) -> f64 {
        if self.sense > 0.0 {
            gamma - self.offset
        } else {
            self.offset - gamma
        }
    }

    pub(crate) fn length(&self, theta: f64) -> f64 {
        let g = self.gamma(theta);
        (self.a * self.a + self.b * self.b - 2.0 * self.a * self.b * g.cos())
            .max(0.0)
            .sqrt() // Eq. A5
    }

    /// Signed `dL/dtheta`: `a sin(alpha)` (Eqs. A6-A7) with the joint's sense.
    pub(crate) fn moment_arm(&self, theta: f64) -> f64 {
        let l = self.length(theta);
        if l <= 0.0 {
            return 0.0;
        }
        let c = (self.b * self.b - l * l - self.a * self.a) / (2.0 * l * self.a);
        let sin_alpha = (1.0 - c * c).max(0.0).sqrt(); // Eq. A6
        // The sqrt of Eq. A6 loses the sign; it is that of sin(gamma) for a mount in (0, pi).
        let sign = if self.gamma(theta).sin() >= 0.0 {
            1.0
        } else {
            -1.0
        };
        self.sense * sign * self.a * sin_alpha // Eq. A7's moment arm
    }
}

/// The bucket four-bar (Fig. A2): the H-link `e2`, the side link `e3`, the bucket's H-link pin at `e1`
/// from the bucket pin, the side-link pivot and the cylinder base on the stick.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FourBar {
    pub(crate) e1: f64,
    pub(crate) e2: f64,
    pub(crate) e3: f64,
    pub(crate) e1_angle: f64,
    /// Side-link pivot in the stick frame.
    pub(crate) s: [f64; 2],
    /// Cylinder base in the stick frame.
    pub(crate) c: [f64; 2],
}

pub(crate) fn dir(a: f64) -> [f64; 2] {
    [a.cos(), a.sin()]
}
pub(crate) fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}
pub(crate) fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}
pub(crate) fn scale(a: [f64; 2], k: f64) -> [f64; 2] {
    [a[0] * k, a[1] * k]
}
pub(crate) fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
pub(crate) fn norm(a: [f64; 2]) -> f64 {
    a[0].hypot(a[1])
}
pub(crate) fn perp(a: [f64; 2]) -> [f64; 2] {
    [-a[1], a[0]]
}
/// Unsigned angle between two vectors, rad.
pub(crate) fn angle_between(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] * b[1] - a[1] * b[0]).abs().atan2(dot(a, b))
}
pub(crate) fn law_of_cosines_angle(adj1: f64, adj2: f64, opposite: f64) -> f64 {
    ((adj1 * adj1 + adj2 * adj2 - opposite * opposite) / (2.0 * adj1 * adj2))
        .clamp(-1.0, 1.0)
        .acos()
}

impl FourBar {
    /// The four-bar from its link lengths `[e1, e2, e3]`, the angle of `e1` on the bucket, and the
    /// side-link pivot and the cylinder base on the stick as `(distance, angle)` from the bucket pin.
    pub(crate) fn new(
        links_m: [f64; 3],
        e1_angle_rad: f64,
        side_pivot: (f64, f64),
        cylinder_base: (f64, f64),
    ) -> Self {
        let [e1, e2, e3] = links_m;
        Self {
            e1,
            e2,
            e3,
            e1_angle: e1_angle_rad,
            s: scale(dir(side_pivot.1), side_pivot.0),
            c: scale(dir(cylinder_base.1), cylinder_base.0),
        }
    }

    /// The four-bar at bucket angle `theta4` (relative to the stick line).
    ///
    /// Positions are solved with vectors in the stick frame (origin at the bucket pin, x along the stick
    /// line) so the configuration's orientation is never lost; the named quantities are those of the
    /// thesis's successive law-of-cosines chain (Eqs. A8-A14), which the bucket range can leave (the angle
    /// gamma_4 passes 180 degrees near full curl, where Eq. A10's sum of two acos no longer holds).
    pub(crate) fn state(&self, theta4: f64) -> Result<BucketLinkageState, LinkageError> {
        let h = scale(dir(theta4 + self.e1_angle), self.e1); // bucket's H-link pin
        let d = sub(h, self.s);
        let k1 = norm(d); // Eq. A8: k1^2 = e4^2 + e1^2 - 2 e4 e1 cos(gamma4)
        if k1 < 1e-9 {
            return Err(LinkageError::Infeasible { bucket_rad: theta4 });
        }
        let cos_psi = (self.e3 * self.e3 + k1 * k1 - self.e2 * self.e2) / (2.0 * self.e3 * k1);
        if !(-1.0..=1.0).contains(&cos_psi) {
            return Err(LinkageError::Infeasible { bucket_rad: theta4 });
        }
        let psi = cos_psi.acos();
        let dn = scale(d, 1.0 / k1);
        let (sp, cp) = psi.sin_cos();
        let side_dir = [dn[0] * cp - dn[1] * sp, dn[0] * sp + dn[1] * cp];
        let r = add(self.s, scale(side_dir, self.e3)); // rod-end joint
        let theta1 = law_of_cosines_angle(self.e3, self.e2, k1); // Eq. A9
        let theta3 = angle_between(scale(h, -1.0), sub(r, h)); // Eq. A10
        let k2 = norm(r); // Eq. A11
        let alpha = angle_between(self.c, r); // Eq. A12: acos(...) - beta
        let cyl = sub(r, self.c);
        let l4 = norm(cyl); // Eq. A13
        let theta2 = angle_between(scale(cyl, -1.0), sub(self.s, r)); // Eq. A14
        // Eqs. A15-A19 by virtual work: the H-pin moves with perp(h) per unit bucket rate, the rod-end
        // joint turns about the side-link pivot, and the H-link's length is constant.
        let rh = sub(r, h);
        let den = dot(perp(sub(r, self.s)), rh);
        if den.abs() < 1e-12 || l4 < 1e-9 {
            return Err(LinkageError::Singular {
                what: "bucket four-bar at toggle",
            });
        }
        let omega3 = dot(perp(h), rh) / den;
        let v_r = scale(perp(sub(r, self.s)), omega3);
        let moment_arm = dot(cyl, v_r) / l4;
        Ok(BucketLinkageState {
            k1_m: k1,
            theta1_rad: theta1,
            theta2_rad: theta2,
            theta3_rad: theta3,
            k2_m: k2,
            alpha_rad: alpha,
            cylinder_length_m: l4,
            moment_arm_m: moment_arm,
        })
    }
}

/// The implement linkage of one machine: what its geometric checks and its kinematics need.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Linkage {
    /// Boom cylinder mount (`gamma = theta + offset`).
    pub(crate) boom: Mount,
    /// Stick cylinder mount (`gamma = offset - theta`).
    pub(crate) stick: Mount,
    /// Bucket four-bar.
    pub(crate) four_bar: FourBar,
    /// `[boom, stick, bucket]` (retracted, extended) cylinder lengths, m.
    pub(crate) stroke: [(f64, f64); 3],
    /// Configured joint limits `(min, max)`, rad.
    pub(crate) limits: [(f64, f64); 3],
}

const LIMIT_NAMES: [(&str, &str); 3] = [
    ("limits.boom_min_deg", "limits.boom_max_deg"),
    ("limits.stick_min_deg", "limits.stick_max_deg"),
    ("limits.bucket_min_deg", "limits.bucket_max_deg"),
];

impl Linkage {
    /// Checks the geometry and returns the joint ranges `(min, max)` the cylinder strokes allow, rad,
    /// `[boom, stick, bucket]`: the boom and stick mounts keep the included angle in (0, pi) over the
    /// stroke, the four-bar assembles and is monotonic over the bucket stroke, and the configured joint
    /// limits lie inside the stroke-limited ranges.
    ///
    /// # Errors
    /// [`LinkageError::Config`] naming the offending field; the four-bar's errors where the bracket
    /// search of the bucket's stroke ends meets them.
    pub(crate) fn stroke_ranges(&self) -> Result<[(f64, f64); 3], LinkageError> {
        let mut stroke_range = [(0.0, 0.0); 3];
        for (i, (mount, name)) in [(self.boom, "boom"), (self.stick, "stick")]
            .into_iter()
            .enumerate()
        {
            let (lo, hi) = self.stroke[i];
            let reach = (mount.a - mount.b).abs()..=(mount.a + mount.b);
            if !reach.contains(&lo) || !reach.contains(&hi) {
                return Err(LinkageError::Config {
                    field: format!("{name}_mount.a_m"),
                    reason: format!(
                        "the {name} cylinder stroke {lo:.3}..{hi:.3} m cannot span a triangle with a and b"
                    ),
                });
            }
            let t_lo = mount.theta(law_of_cosines_angle(mount.a, mount.b, lo));
            let t_hi = mount.theta(law_of_cosines_angle(mount.a, mount.b, hi));
            stroke_range[i] = (t_lo.min(t_hi), t_lo.max(t_hi));
        }
        stroke_range[2] = self.bucket_stroke_range()?;
        for (i, (lo_name, hi_name)) in LIMIT_NAMES.iter().enumerate() {
            let (lo, hi) = self.limits[i];
            let (slo, shi) = stroke_range[i];
            if lo < slo - 1e-9 {
                return Err(LinkageError::Config {
                    field: (*lo_name).into(),
                    reason: format!(
                        "{:.2} deg is beyond what the cylinder stroke reaches ({:.2} deg)",
                        lo.to_degrees(),
                        slo.to_degrees()
                    ),
                });
            }
            if hi > shi + 1e-9 {
                return Err(LinkageError::Config {
                    field: (*hi_name).into(),
                    reason: format!(
                        "{:.2} deg is beyond what the cylinder stroke reaches ({:.2} deg)",
                        hi.to_degrees(),
                        shi.to_degrees()
                    ),
                });
            }
        }
        // The stick must not stretch straight (Jacobian singular at sin(stick) = 0, Eq. A23).
        let (slo, shi) = self.limits[1];
        if slo.sin() * shi.sin() <= 0.0 || slo.sin().abs() < 0.05 || shi.sin().abs() < 0.05 {
            return Err(LinkageError::Config {
                field: "limits.stick_max_deg".into(),
                reason: "the stick range must stay clear of 0 and 180 degrees (singular Jacobian)"
                    .into(),
            });
        }
        Ok(stroke_range)
    }

    /// Finds the bucket angles at the two stroke ends on the monotonic branch containing the limits.
    fn bucket_stroke_range(&self) -> Result<(f64, f64), LinkageError> {
        let bad = |reason: String| LinkageError::Config {
            field: "bucket_linkage.e1_angle_deg".into(),
            reason,
        };
        let (lmin, lmax) = self.stroke[2];
        let (qlo, qhi) = self.limits[2];
        let step = 0.25_f64.to_radians();
        // Walk from the middle of the limits outward while the linkage assembles and L falls as the
        // bucket opens (extension curls, so dL/dtheta < 0).
        let mid = 0.5 * (qlo + qhi);
        let arm_ok = |t: f64| {
            self.four_bar
                .state(t)
                .ok()
                .filter(|s| s.moment_arm_m < -1e-4)
        };
        let Some(s_mid) = arm_ok(mid) else {
            return Err(bad(
                "the bucket four-bar does not assemble (or curls the wrong way) mid-range".into(),
            ));
        };
        let _ = s_mid;
        // Toward curl (theta falls, L grows) until L >= lmax.
        let mut t = mid;
        let mut curl_end = None;
        for _ in 0..2000 {
            let tn = t - step;
            match arm_ok(tn) {
                Some(s) if s.cylinder_length_m >= lmax => {
                    curl_end = Some((tn, t));
                    break;
                }
                Some(_) => t = tn,
                None => break,
            }
        }
        let mut t = mid;
        let mut open_end = None;
        for _ in 0..2000 {
            let tn = t + step;
            match arm_ok(tn) {
                Some(s) if s.cylinder_length_m <= lmin => {
                    open_end = Some((t, tn));
                    break;
                }
                Some(_) => t = tn,
                None => break,
            }
        }
        let (Some(curl), Some(open)) = (curl_end, open_end) else {
            return Err(bad(
                "the bucket cylinder stroke is not reached on a monotonic branch of the four-bar"
                    .into(),
            ));
        };
        let lo = self.bisect_bucket(lmax, curl.0, curl.1)?;
        let hi = self.bisect_bucket(lmin, open.0, open.1)?;
        Ok((lo, hi))
    }

    /// Bisection for `L4(theta) = length` on a bracket where L4 is monotonic decreasing.
    fn bisect_bucket(&self, length: f64, mut lo: f64, mut hi: f64) -> Result<f64, LinkageError> {
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.four_bar.state(mid)?.cylinder_length_m > length {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(0.5 * (lo + hi))
    }
}
