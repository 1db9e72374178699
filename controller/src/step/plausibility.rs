//! Plausibility of the gateway's joint angles, a check that needs no key: between two accepted
//! `JointAngles` frames no joint can have moved faster than the machine's joints can move.
//!
//! A frame that breaks the bound is rejected (never given to the estimator) and raises
//! [`Fault::ImplausibleSensor`](crate::step::safety::Fault::ImplausibleSensor), which stops motion
//! and waits for the operator. This catches a second sender of `JointAngles` on the bus (a spoofed
//! stream interleaved with the gateway's, frozen or replayed from another pose) as soon as the real
//! and the forged angles part by more than one frame's worth of joint motion, and a resolver that
//! jumps. It cannot catch forged angles that follow the real ones within that bound: the
//! authenticated sensor path is what closes that (docs/protocol.md, "Threat model").
//!
//! The bound for joint `j` between frames `dt` apart is `max_speed_j * max(dt, T) + NOISE_RAD`, with
//! `T` the gateway's sensor period: frames that were delayed and arrive together (a loaded host, a
//! gateway catching up) are each one period of motion apart, and a long gap widens the bound with
//! it. The swing angle wraps at +-pi: its difference is taken on the circle.
//!
//! A frozen signal is the other finding ([`FrozenAngles`]): a joint whose angle stays bit-identical
//! for `safety.frozen_sensor_s` (default 1 s) while the controller holds its valve at least
//! [`OPEN_FRACTION`] open. A working resolver's noise changes the reading from frame to frame even
//! when the joint is stalled against the ground or at relief (the simulated resolvers' 0.2 mrad
//! against the DBC's 0.1 mrad resolution: two readings are equal about one time in seven), so only
//! a stuck sensor, a gateway repeating its last frame or a stream replayed from a still machine keeps
//! it. Position mode is not watched: the gateway, not the controller, opens the valves there.

use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// Allowance for resolver noise and the DBC's 0.0001 rad resolution between two frames, rad: ten
/// standard deviations of the difference of two readings of the simulated resolvers (0.2 mrad
/// each, `vcan_sim::sensors`). A real machine's resolvers need their own figure here.
pub const NOISE_RAD: f64 = 0.003;

/// A joint whose angle the gateway reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensedJoint {
    /// Boom.
    Boom,
    /// Stick.
    Stick,
    /// Bucket.
    Bucket,
    /// Swing (wraps at +-pi).
    Swing,
}

impl SensedJoint {
    /// In `JointAngles` order.
    pub const ALL: [SensedJoint; 4] = [Self::Boom, Self::Stick, Self::Bucket, Self::Swing];

    /// Lower-case name.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Boom => "boom",
            Self::Stick => "stick",
            Self::Bucket => "bucket",
            Self::Swing => "swing",
        }
    }
}

impl std::fmt::Display for SensedJoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The fastest each joint can turn, rad/s (`[safety.max_joint_speed_rad_per_s]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JointSpeeds {
    /// Boom, rad/s. Default 2.0 (the default machine's boom reaches 0.8 rad/s).
    pub boom: f64,
    /// Stick, rad/s. Default 2.0 (0.8 rad/s).
    pub stick: f64,
    /// Bucket, rad/s. Default 8.0: the default machine's dump reaches 2.9 rad/s, and the bucket of
    /// a machine with a 40 % heavier boom 5.1 rad/s between two frames.
    pub bucket: f64,
    /// Swing, rad/s. Default 2.0 (1.0 rad/s).
    pub swing: f64,
}

impl Default for JointSpeeds {
    fn default() -> Self {
        Self {
            boom: 2.0,
            stick: 2.0,
            bucket: 8.0,
            swing: 2.0,
        }
    }
}

impl JointSpeeds {
    /// In `JointAngles` order, with their names.
    #[must_use]
    pub const fn by_joint(&self) -> [(SensedJoint, f64); 4] {
        [
            (SensedJoint::Boom, self.boom),
            (SensedJoint::Stick, self.stick),
            (SensedJoint::Bucket, self.bucket),
            (SensedJoint::Swing, self.swing),
        ]
    }
}

/// The smallest valve command, as a fraction of full flow, under which a joint must move: the
/// frozen-signal check watches a joint only while its valve is held at least this far open.
pub const OPEN_FRACTION: f64 = 0.3;

/// A rejected frame: what is implausible in it. Also the fault it raises
/// ([`Fault::ImplausibleSensor`](crate::step::safety::Fault::ImplausibleSensor)), whose text is this
/// one's.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Implausible {
    /// A joint moved farther since the last accepted frame than it can turn.
    #[error(
        "implausible joint angles: the {joint} moved {jump_rad:.4} rad between two frames, at most \
         {allowed_rad:.4} rad is possible (a second sender of JointAngles, or a resolver fault)"
    )]
    Jump {
        /// The joint.
        joint: SensedJoint,
        /// How far it moved since the last accepted frame, rad.
        jump_rad: f64,
        /// How far it could have moved, rad.
        allowed_rad: f64,
    },
    /// A joint's angle stayed bit-identical while its valve was held open.
    #[error(
        "implausible joint angles: the {joint} angle has not changed for {for_s:.2} s while its \
         valve was held at least {min_fraction:.2} open (a frozen resolver, or a gateway or replay \
         repeating one frame)"
    )]
    Frozen {
        /// The joint.
        joint: SensedJoint,
        /// How long the angle has not changed with the valve open, s.
        for_s: f64,
        /// The smallest valve command over that time, fraction of full flow.
        min_fraction: f64,
    },
}

impl Implausible {
    /// The joint the finding is about.
    #[must_use]
    pub const fn joint(&self) -> SensedJoint {
        match self {
            Self::Jump { joint, .. } | Self::Frozen { joint, .. } => *joint,
        }
    }
}

/// The last accepted joint angles and when they came.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnglePlausibility {
    last: Option<([f64; 4], f64)>,
}

impl AnglePlausibility {
    /// Checks `angles` (boom, stick, bucket, swing, rad) received at `time_s` against the last
    /// accepted frame; accepted angles become the reference for the next frame, rejected ones do not.
    ///
    /// # Errors
    /// The first joint that moved farther than `speeds` allow in the time since the last accepted
    /// frame (at least `period_s`).
    pub fn check(
        &mut self,
        angles: [f64; 4],
        time_s: f64,
        speeds: &JointSpeeds,
        period_s: f64,
    ) -> Result<(), Implausible> {
        if let Some((last, last_s)) = self.last {
            let dt = (time_s - last_s).max(period_s);
            for (((joint, speed), now), was) in speeds.by_joint().into_iter().zip(angles).zip(last)
            {
                let jump_rad = if joint == SensedJoint::Swing {
                    ((now - was + PI).rem_euclid(TAU) - PI).abs()
                } else {
                    (now - was).abs()
                };
                let allowed_rad = speed * dt + NOISE_RAD;
                // A NaN jump is not accepted either.
                if jump_rad.is_nan() || jump_rad > allowed_rad {
                    return Err(Implausible::Jump {
                        joint,
                        jump_rad,
                        allowed_rad,
                    });
                }
            }
        }
        self.last = Some((angles, time_s));
        Ok(())
    }
}

/// Since when one joint's reading has been the same with its valve open.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Unchanged {
    angle_bits: u64,
    since_s: f64,
    min_fraction: f64,
}

/// The frozen-signal watch over the four joints (module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrozenAngles {
    joints: [Option<Unchanged>; 4],
}

impl FrozenAngles {
    /// Takes an accepted frame's `angles` (boom, stick, bucket, swing, rad) received at `time_s`,
    /// with the valve commands in force (`valves`, boom, stick, bucket, swing in `[-1, 1]`; `None`
    /// when the controller drives no valves).
    ///
    /// # Errors
    /// The first joint whose angle has been bit-identical for `window_s` or longer with its valve
    /// held at least [`OPEN_FRACTION`] open all that time. The watch of that joint starts again.
    pub fn check(
        &mut self,
        angles: [f64; 4],
        time_s: f64,
        valves: Option<[f64; 4]>,
        window_s: f64,
    ) -> Result<(), Implausible> {
        let mut finding = None;
        for (k, (state, joint)) in self.joints.iter_mut().zip(SensedJoint::ALL).enumerate() {
            let fraction = valves.map_or(0.0, |v| v[k].abs());
            let bits = angles[k].to_bits();
            *state = match *state {
                _ if fraction.is_nan() || fraction < OPEN_FRACTION => None,
                Some(u) if u.angle_bits == bits => {
                    let u = Unchanged {
                        min_fraction: u.min_fraction.min(fraction),
                        ..u
                    };
                    let for_s = time_s - u.since_s;
                    if finding.is_none() && for_s >= window_s {
                        finding = Some(Implausible::Frozen {
                            joint,
                            for_s,
                            min_fraction: u.min_fraction,
                        });
                        None
                    } else {
                        Some(u)
                    }
                }
                _ => Some(Unchanged {
                    angle_bits: bits,
                    since_s: time_s,
                    min_fraction: fraction,
                }),
            };
        }
        finding.map_or(Ok(()), Err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: f64 = 0.01;

    /// A boom moving at `rate` rad/s from 0.5 rad: its angles every period.
    fn moving(rate: f64, k: usize) -> [f64; 4] {
        #[allow(clippy::cast_precision_loss)]
        let t = k as f64 * T;
        [0.5 + rate * t, -1.6, -0.9, 0.0]
    }

    #[test]
    fn a_joint_at_the_machines_speeds_passes() {
        let speeds = JointSpeeds::default();
        let mut p = AnglePlausibility::default();
        for k in 0..500 {
            #[allow(clippy::cast_precision_loss)]
            let t = k as f64 * T;
            // Every joint near its largest speed at once, the bucket at 5.1 rad/s.
            let q = [0.5 + 1.9 * t, -1.6 - 1.9 * t, -0.9 + 5.1 * t, 1.9 * t];
            assert_eq!(p.check(q, t, &speeds, T), Ok(()), "frame {k}");
        }
    }

    #[test]
    fn frames_delayed_and_delivered_together_pass() {
        let speeds = JointSpeeds::default();
        let mut p = AnglePlausibility::default();
        // Ten frames generated 10 ms apart arrive within 1 ms after a 100 ms stall.
        assert!(p.check(moving(1.0, 0), 0.0, &speeds, T).is_ok());
        for k in 1..=10 {
            #[allow(clippy::cast_precision_loss)]
            let t = 0.1 + k as f64 * 1e-4;
            assert!(p.check(moving(1.0, k), t, &speeds, T).is_ok(), "frame {k}");
        }
    }

    #[test]
    fn the_swing_angle_wraps_at_pi() {
        let speeds = JointSpeeds::default();
        let mut p = AnglePlausibility::default();
        let q = |s: f64| [0.5, -1.6, -0.9, s];
        assert!(p.check(q(PI - 0.004), 0.0, &speeds, T).is_ok());
        assert!(p.check(q(-PI + 0.004), T, &speeds, T).is_ok());
    }

    #[test]
    fn a_frozen_stream_interleaved_with_the_real_one_is_rejected_within_100_ms() {
        // The attack of issue #46 item 3: after each real frame a forged one with the angles of
        // the start, while the boom moves at 0.5 rad/s.
        let speeds = JointSpeeds::default();
        let mut p = AnglePlausibility::default();
        let frozen = moving(0.5, 0);
        let mut rejected_at = None;
        for k in 0..100 {
            #[allow(clippy::cast_precision_loss)]
            let t = k as f64 * T;
            let real = p.check(moving(0.5, k), t, &speeds, T);
            let forged = p.check(frozen, t + 0.001, &speeds, T);
            if let Some(e) = real.err().or(forged.err()) {
                let Implausible::Jump {
                    joint,
                    jump_rad,
                    allowed_rad,
                } = e
                else {
                    panic!("{e}")
                };
                assert_eq!(joint, SensedJoint::Boom);
                assert!(jump_rad > allowed_rad);
                rejected_at = Some(t);
                break;
            }
        }
        let t = rejected_at.expect("the forged stream was never rejected");
        assert!(t <= 0.1, "rejected {t} s after the forging began");
    }

    #[test]
    fn a_resolver_jump_and_a_nan_are_rejected_and_not_taken_as_the_reference() {
        let speeds = JointSpeeds::default();
        let mut p = AnglePlausibility::default();
        assert!(p.check(moving(0.0, 0), 0.0, &speeds, T).is_ok());
        let mut jumped = moving(0.0, 1);
        jumped[2] += 0.3;
        let e = p.check(jumped, T, &speeds, T).unwrap_err();
        assert_eq!(e.joint(), SensedJoint::Bucket);
        let mut nan = moving(0.0, 2);
        nan[1] = f64::NAN;
        assert_eq!(
            p.check(nan, 2.0 * T, &speeds, T).unwrap_err().joint(),
            SensedJoint::Stick
        );
        // The reference is still the first frame: the next real frame passes.
        assert!(p.check(moving(0.0, 3), 3.0 * T, &speeds, T).is_ok());
    }

    /// Readings of a still joint with the simulated resolvers' noise (0.2 mrad), quantised to the
    /// DBC's 0.1 mrad, from a small deterministic generator.
    fn noisy_still(k: usize) -> f64 {
        // A Weyl sequence's fractional part as a uniform in [0, 1), two of them summed for a
        // rounded bell: +-0.35 mrad.
        #[allow(clippy::cast_precision_loss)]
        let u = |a: f64| (k as f64 * a).fract();
        let noise = (u(0.618_033_988_7) + u(0.414_213_562_4) - 1.0) * 3.5e-4;
        ((0.5 + noise) / 1e-4).round() * 1e-4
    }

    #[test]
    fn a_frozen_angle_with_its_valve_open_is_found_after_the_window() {
        let mut w = FrozenAngles::default();
        let window_s = 1.0;
        let boom_open = Some([0.6, 0.0, 0.0, 0.0]);
        let mut found = None;
        for k in 0..200 {
            #[allow(clippy::cast_precision_loss)]
            let t = k as f64 * T;
            if let Err(e) = w.check([0.5, -1.6, -0.9, 0.0], t, boom_open, window_s) {
                found = Some((t, e));
                break;
            }
        }
        let (t, e) = found.expect("the frozen boom was not found");
        assert!((t - window_s).abs() < 1e-9, "found at {t} s");
        assert_eq!(
            e,
            Implausible::Frozen {
                joint: SensedJoint::Boom,
                for_s: t,
                min_fraction: 0.6
            }
        );
        assert_eq!(
            e.to_string(),
            "implausible joint angles: the boom angle has not changed for 1.00 s while its valve \
             was held at least 0.60 open (a frozen resolver, or a gateway or replay repeating one \
             frame)"
        );
    }

    #[test]
    fn a_still_joint_with_a_closed_valve_or_a_noisy_reading_is_not_frozen() {
        let mut w = FrozenAngles::default();
        for k in 0..1000 {
            #[allow(clippy::cast_precision_loss)]
            let t = k as f64 * T;
            // Boom stalled with its valve open (noisy readings); stick frozen, valve just under
            // the open fraction; bucket frozen with no valves driven half of the time; swing
            // frozen, its valve opening and closing every 0.5 s.
            let valves = [
                0.9,
                OPEN_FRACTION - 0.01,
                0.8,
                if (k / 50) % 2 == 0 { 0.7 } else { 0.0 },
            ];
            let driven = (k / 20) % 2 == 0;
            let q = [noisy_still(k), -1.6, -0.9, 0.2];
            let r = if driven {
                w.check(q, t, Some(valves), 1.0)
            } else {
                w.check(q, t, None, 1.0)
            };
            assert_eq!(r, Ok(()), "frame {k}");
        }
    }

    #[test]
    fn the_noise_model_changes_a_still_reading_most_frames() {
        let changed = (1..1000)
            .filter(|&k| noisy_still(k).to_bits() != noisy_still(k - 1).to_bits())
            .count();
        assert!(changed > 500, "{changed} of 999 readings changed");
        let longest_same = (1..1000)
            .scan(0, |run, k| {
                *run = if noisy_still(k).to_bits() == noisy_still(k - 1).to_bits() {
                    *run + 1
                } else {
                    0
                };
                Some(*run)
            })
            .max();
        assert!(longest_same < Some(10), "{longest_same:?}");
    }
}
