//! MoveToDig: swing to the dig and move the implement to the start pose (P-controllers, stall
//! escalation, terrain clearance, close enough, blocked at relief).

use planner::kinematics::{BucketPose, Joint, JointAngles, wrap_angle};

use crate::step::estimate::Estimator;
use crate::step::safety::ControlFault;

use super::action::Action;
use super::{CycleCommand, JOINT_SIGN, RELIEF_RELIFT_FRACTION, STALL_PROGRESS_RAD, WorkCycle};

/// MoveToDig stall escalation: how long a joint may make no progress before its command grows, s.
pub(super) const STALL_WAIT_S: f64 = 0.5;

pub(super) const STALL_BOOST_PER_S: f64 = 0.25;

/// MoveToDig: while the stick or the bucket still has far to go, the tip is kept this far above the
/// highest known terrain between it and the start (the boom lifts first), m.
pub(super) const MOVE_CLEARANCE_M: f64 = 0.4;

/// MoveToDig close enough: a move whose tip has come within this distance of the start's tip (r, z)
/// and has stopped getting closer begins the dig from there, m.
pub(super) const MOVE_CLOSE_ENOUGH_M: f64 = 0.3;

/// MoveToDig close enough: how long the tip must have stopped getting closer (by 1 cm), s.
pub(super) const MOVE_CLOSE_ENOUGH_WAIT_S: f64 = 2.0;

/// MoveToDig close enough: the largest remaining swing error, rad (2 deg).
pub(super) const MOVE_CLOSE_ENOUGH_SWING_RAD: f64 = 0.035;

/// MoveToDig blocked: a commanded implement cylinder whose port has been at
/// [`RELIEF_RELIFT_FRACTION`] of relief this long, with the tip no longer getting closer (for
/// [`MOVE_CLOSE_ENOUGH_WAIT_S`]) and not close enough to dig, is pushing against something it cannot
/// move (the bucket's back or side on the terrain, which the map along the digging plane does not
/// show): the move is abandoned then, not at its time-out, s.
pub(super) const MOVE_BLOCKED_S: f64 = 2.0;

/// MoveToDig blocked: relief episodes this close together count as one push, s. A bucket held in
/// the ground alternates between pushing at relief under its own command and being pushed to
/// relief against its closed valve while the boom tries to lift it free, a second apart.
pub(super) const MOVE_RELIEF_GAP_S: f64 = 1.0;

/// MoveToDig: spacing of the terrain heights along the digging plane the clearance is judged on, m.
pub(super) const CLEARANCE_STEP_M: f64 = 0.1;

impl WorkCycle {
    fn implement_toward(&self, q: &JointAngles, target: &JointAngles) -> ([f64; 3], bool) {
        let err = [
            target.boom_rad - q.boom_rad,
            target.stick_rad - q.stick_rad,
            target.bucket_rad - q.bucket_rad,
        ];
        let g = self.config.joint;
        let cmd = [0, 1, 2].map(|i| JOINT_SIGN[i] * g.command(err[i]));
        (cmd, err.iter().all(|e| e.abs() <= g.tolerance))
    }

    /// The time since the last step of a move with stall escalation (at most 0.1 s), s.
    pub(super) fn stall_step_s(&mut self, now_s: f64) -> f64 {
        let dt_s = self
            .last_move_s
            .map_or(0.0, |t| (now_s - t).clamp(0.0, 0.1));
        self.last_move_s = Some(now_s);
        dt_s
    }

    /// Stall escalation of a P-controller (the implement joints in MoveToDig, the swing in
    /// MoveToDig and the swings to and from the dump): the command of joint `i` (boom, stick,
    /// bucket, swing) that is commanded but has not come [`STALL_PROGRESS_RAD`] closer to its
    /// target for [`STALL_WAIT_S`] grows by [`STALL_BOOST_PER_S`] (up to `max`), and is held while
    /// the joint makes progress; a joint that reaches its tolerance or reverses starts from zero
    /// again. A valve whose dead band swallows the P-controller's last degrees (a swing resting
    /// 7 deg short of the dig, its boom waiting for it) opens until the joint moves.
    pub(super) fn escalate_stalled(
        &mut self,
        now_s: f64,
        dt_s: f64,
        i: usize,
        cmd: &mut f64,
        error_rad: f64,
        max: f64,
    ) {
        let err = error_rad.abs();
        let boost = &mut self.stall_boost[i];
        // Restart when the joint is not commanded or the command reverses.
        if *cmd == 0.0 || !err.is_finite() || (*boost != 0.0 && boost.signum() != cmd.signum()) {
            *boost = 0.0;
            self.stall_best_rad[i] = f64::INFINITY;
            return;
        }
        if !self.stall_best_rad[i].is_finite() || err < self.stall_best_rad[i] - STALL_PROGRESS_RAD
        {
            self.stall_best_rad[i] = err;
            self.stall_progress_s[i] = now_s;
        }
        let magnitude = if now_s - self.stall_progress_s[i] > STALL_WAIT_S {
            (boost.abs() + STALL_BOOST_PER_S * dt_s).min(max)
        } else {
            boost.abs()
        };
        *boost = magnitude.copysign(*cmd);
        *cmd = (cmd.abs() + magnitude).min(max).copysign(*cmd);
    }

    /// [`Self::swing_toward`] with stall escalation (joint 3).
    pub(super) fn swing_toward_escalated(
        &mut self,
        now_s: f64,
        dt_s: f64,
        swing_rad: f64,
        rate_rad_per_s: f64,
        target_rad: f64,
    ) -> (f64, bool) {
        let (mut swing, done) = self.swing_toward(swing_rad, rate_rad_per_s, target_rad);
        let max = self.config.swing.max_command;
        let err = wrap_angle(target_rad - swing_rad);
        if swing.signum() == err.signum() {
            self.escalate_stalled(now_s, dt_s, 3, &mut swing, err, max);
        } else {
            // Braking (the damping term outweighs the error): nothing to escalate, and the next
            // push toward the target starts from zero.
            self.stall_boost[3] = 0.0;
            self.stall_best_rad[3] = f64::INFINITY;
        }
        (swing, done)
    }

    pub(super) fn swing_toward(
        &self,
        swing_rad: f64,
        rate_rad_per_s: f64,
        target_rad: f64,
    ) -> (f64, bool) {
        let err = wrap_angle(target_rad - swing_rad);
        (
            self.config.swing.command_damped(err, rate_rad_per_s),
            err.abs() <= self.config.swing.tolerance,
        )
    }

    pub(super) fn step_move_to_dig(
        &mut self,
        now_s: f64,
        est: &Estimator,
    ) -> Result<CycleCommand, ControlFault> {
        let (Some(action), Some(target)) = (
            self.config.actions.get(self.action_index).copied(),
            self.starts.get(self.action_index).copied(),
        ) else {
            self.next_action(now_s);
            return Ok(CycleCommand::Neutral);
        };
        let s = est.state();
        if self.timed_out(now_s) {
            let swing = action.swing_rad().unwrap_or(s.swing_rad);
            let ground_at_tip =
                self.highest_terrain(&s.pose, swing, (s.tip.x_m - 0.05, s.tip.x_m + 0.05));
            let target_tip = est.kinematics().forward(&target);
            tracing::warn!(
                ?ground_at_tip,
                target_z = target_tip.z_m,
                tip_x_m = s.tip.x_m,
                boom_err_deg = (target.boom_rad - s.joints.boom_rad).to_degrees(),
                stick_err_deg = (target.stick_rad - s.joints.stick_rad).to_degrees(),
                bucket_err_deg = (target.bucket_rad - s.joints.bucket_rad).to_degrees(),
                swing_err_deg = action
                    .swing_rad()
                    .map(|t| wrap_angle(t - s.swing_rad).to_degrees()),
                lifted = self.lifted,
                tip_z_m = s.tip.z_m,
                tip_error_m = (s.tip.x_m - target_tip.x_m).hypot(s.tip.z_m - target_tip.z_m),
                best_tip_error_m = self.move_best_m,
                since_progress_s = now_s - self.move_progress_s,
                joints_deg = ?[s.joints.boom_rad, s.joints.stick_rad, s.joints.bucket_rad]
                    .map(f64::to_degrees),
                clearing = self.clearing,
                "move to the dig timed out"
            );
            return Err(ControlFault::Timeout("move to the dig"));
        }
        let (mut implement, implement_done) = self.implement_toward(&s.joints, &target);
        // Lift first: while the tip is well below the start pose only the boom moves (up), so the
        // bucket is not dragged through the ground; the swing waits until the boom is up too.
        let target_tip = est.kinematics().forward(&target);
        let target_z = target_tip.z_m;
        // Latched: once lifted, the boom's P-controller alone settles it. Re-entering the full lift
        // whenever a gravity-assisted lowering overshot made a limit cycle (boom +-4 degrees) that
        // timed out the move.
        let low = !self.lifted && s.tip.z_m < target_z - 0.2;
        if !low {
            self.lifted = true;
        }
        // Boom up first, boom down last: bringing the stick in (or out) at a boom still below its
        // target sweeps the bucket down through the bench (from the dump pose to a start close in, at
        // a stick of -87 degrees, it came to rest on the face with the boom stalled 4 degrees short).
        let boom_band = 3.0 * self.config.joint.tolerance;
        // Terrain clearance: with the boom at its start angle, swinging the stick through the
        // vertical or opening the bucket sweeps the tip up to 0.7 m below the start height, into the
        // bench top when the start is down the face (the bucket then stalled in the cut, the stick
        // 16 deg short, and the move timed out). While the stick or the bucket has far to go, the boom
        // goal is the angle that keeps the tip clear of the known terrain between the tip and the
        // start; the boom comes down to the start angle last.
        // The swing must be done too before the boom comes down: a bucket lowered onto the face
        // while the swing still turns is dragged sideways through the soil and the swing stalls
        // short of its tolerance.
        let swing_far = action
            .swing_rad()
            .is_some_and(|t| wrap_angle(t - s.swing_rad).abs() > self.config.swing.tolerance);
        let far = swing_far
            || [
                target.stick_rad - s.joints.stick_rad,
                target.bucket_rad - s.joints.bucket_rad,
            ]
            .iter()
            .any(|e| e.abs() > boom_band);
        let clear_z = if far {
            let r = (s.tip.x_m.min(target_tip.x_m), s.tip.x_m.max(target_tip.x_m));
            let swing = action.swing_rad().unwrap_or(s.swing_rad);
            self.highest_terrain(&s.pose, swing, r)
                .map(|h| h + MOVE_CLEARANCE_M)
        } else {
            None
        };
        let boom_goal = clear_z.map_or(target.boom_rad, |z| {
            target.boom_rad.max(boom_for_tip_z(est, &s.joints, z))
        });
        // Clearing: the tip sank 0.1 m below the clearance height (the stick or bucket swept it
        // down); the boom lifts alone until the tip is 0.1 m above it (hysteresis, so the stick
        // and bucket do not stop and go every period).
        self.clearing = match clear_z {
            Some(z) if self.clearing => s.tip.z_m < z + 0.1,
            Some(z) => s.tip.z_m < z - 0.1,
            None => false,
        };
        let boom_err = boom_goal - s.joints.boom_rad;
        if low || self.clearing || boom_err > boom_band {
            // Full lift: at part command the open-centre bypass keeps the gallery below the boom's
            // holding pressure and the loaded boom stalls (as in SwingToDump).
            implement = [self.config.joint.max_command, 0.0, 0.0];
        } else if far && (boom_err < -boom_band || boom_goal > target.boom_rad) {
            // Lowering waits only for the large stick and bucket moves: their last degrees at the
            // P-controller's minimum command crawl, and the boom would wait seconds for them. Held
            // too while the clearance goal is above the start angle (the P-controller would lower
            // it toward the start).
            implement[0] = 0.0;
        }
        let dt_s = self.stall_step_s(now_s);
        let max = self.config.joint.max_command;
        let error_rad = [
            target.boom_rad - s.joints.boom_rad,
            target.stick_rad - s.joints.stick_rad,
            target.bucket_rad - s.joints.bucket_rad,
        ];
        for (i, cmd) in implement.iter_mut().enumerate() {
            self.escalate_stalled(now_s, dt_s, i, cmd, error_rad[i], max);
        }
        let boom_clear =
            !low && s.joints.boom_rad >= target.boom_rad - 3.0 * self.config.joint.tolerance;
        let (swing, swing_done) = match action.swing_rad() {
            Some(t) if boom_clear => {
                self.swing_toward_escalated(now_s, dt_s, s.swing_rad, s.rates_rad_per_s[3], t)
            }
            Some(_) => (0.0, false),
            None => (0.0, true),
        };
        // Blocked: a commanded cylinder pushing at relief (the port its valve command pressurises:
        // extending, a positive command, fills the head), or a stick or bucket pushed to relief
        // against its closed valve (something outside holds it). The boom's chambers bounce to
        // relief on their oil columns behind its closed valve while the swing turns; they do not
        // count.
        let relief = &self.autodig_config.relief_pressure_pa;
        let at_relief = (0..3).any(|i| {
            let u = implement[i];
            let port_pa = if u > 0.0 {
                Some(s.head_pressure_pa[i])
            } else if u < 0.0 {
                Some(s.rod_pressure_pa[i])
            } else if i == 0 {
                None
            } else {
                Some(s.head_pressure_pa[i].max(s.rod_pressure_pa[i]))
            };
            port_pa.is_some_and(|p| p >= RELIEF_RELIFT_FRACTION * relief[i])
        });
        if at_relief {
            self.relief_seen_s = now_s;
        }
        self.relief_since_s = if now_s - self.relief_seen_s <= MOVE_RELIEF_GAP_S {
            self.relief_since_s.or(Some(now_s))
        } else {
            None
        };
        if self.settled(implement_done && swing_done, now_s)
            || self.close_enough(now_s, est, &target_tip, &action)
        {
            self.begin_dig(now_s, est, &action);
            return Ok(CycleCommand::Neutral);
        }
        let blocked = self
            .relief_since_s
            .is_some_and(|since| now_s - since >= MOVE_BLOCKED_S)
            && now_s - self.move_progress_s >= MOVE_CLOSE_ENOUGH_WAIT_S;
        if blocked {
            tracing::warn!(
                best_tip_error_m = self.move_best_m,
                joints_deg = ?[s.joints.boom_rad, s.joints.stick_rad, s.joints.bucket_rad]
                    .map(f64::to_degrees),
                "move to the dig blocked: pushing at relief without getting closer"
            );
            return Err(ControlFault::Blocked("move to the dig"));
        }
        Ok(CycleCommand::Valves([
            implement[0],
            implement[1],
            implement[2],
            swing,
            0.0,
            0.0,
        ]))
    }

    /// MoveToDig close enough: the tip within [`MOVE_CLOSE_ENOUGH_M`] of the start's tip, the swing
    /// within [`MOVE_CLOSE_ENOUGH_SWING_RAD`], and no 1 cm of progress for
    /// [`MOVE_CLOSE_ENOUGH_WAIT_S`]. A bucket that rests on the face a few degrees short of its start
    /// pose (its last degrees stalled against the soil) starts Autodig there: Boom-Down and Pre-Dig
    /// begin from wherever the bucket is, and waiting for the time-out would abandon the action.
    fn close_enough(
        &mut self,
        now_s: f64,
        est: &Estimator,
        target_tip: &BucketPose,
        action: &Action,
    ) -> bool {
        let s = est.state();
        let dist = (s.tip.x_m - target_tip.x_m).hypot(s.tip.z_m - target_tip.z_m);
        if !dist.is_finite() {
            return false;
        }
        if dist < self.move_best_m - 0.01 {
            self.move_best_m = dist;
            self.move_progress_s = now_s;
        }
        let swing_ok = action
            .swing_rad()
            .is_none_or(|t| wrap_angle(t - s.swing_rad).abs() <= MOVE_CLOSE_ENOUGH_SWING_RAD);
        let stopped = now_s - self.move_progress_s >= MOVE_CLOSE_ENOUGH_WAIT_S;
        if dist <= MOVE_CLOSE_ENOUGH_M && swing_ok && stopped {
            tracing::info!(
                tip_error_m = dist,
                "move to the dig: stopped close to the start, digging from here"
            );
            return true;
        }
        false
    }

    /// The highest known terrain (base-frame z) along the digging plane at `swing_rad` between the
    /// radii `r_m.0..=r_m.1`, or `None` without a terrain map or known cells there. The plane's
    /// heights (every [`CLEARANCE_STEP_M`] out to `section_r_max_m`) are looked up once per move and
    /// kept in `clearance_profile`; each control period only takes the maximum over the range.
    fn highest_terrain(
        &mut self,
        pose: &planner::kinematics::MachinePose,
        swing_rad: f64,
        r_m: (f64, f64),
    ) -> Option<f64> {
        let terrain = self.terrain.as_ref()?;
        if self.clearance_profile.is_empty() {
            let n = (self.config.section_r_max_m / CLEARANCE_STEP_M)
                .ceil()
                .clamp(0.0, 1000.0) as usize;
            self.clearance_profile.extend((0..=n).map(|k| {
                let [x, y, _] = pose.world_from_base(swing_rad, k as f64 * CLEARANCE_STEP_M, 0.0);
                terrain.height_at(x, y).unwrap_or(f64::NAN)
            }));
        }
        let (a, b) = r_m;
        if !(a.is_finite() && b.is_finite()) {
            return None;
        }
        let last = self.clearance_profile.len().saturating_sub(1) as f64;
        let ka = (a / CLEARANCE_STEP_M).floor().clamp(0.0, last) as usize;
        let kb = (b / CLEARANCE_STEP_M).ceil().clamp(0.0, last) as usize;
        self.clearance_profile
            .get(ka..=kb)?
            .iter()
            .copied()
            .filter(|h| h.is_finite())
            .reduce(f64::max)
    }
}

/// The boom angle that puts the tip at base-frame height `z_m` with the stick and bucket of `joints`
/// (bisection between the current boom angle and the boom's upper limit; the limit if even that
/// leaves the tip lower, the current angle if the tip is already higher).
pub(super) fn boom_for_tip_z(est: &Estimator, joints: &JointAngles, z_m: f64) -> f64 {
    let k = est.kinematics();
    let z_at = |boom_rad: f64| {
        k.forward(&JointAngles {
            boom_rad,
            ..*joints
        })
        .z_m
    };
    let (mut lo, mut hi) = (joints.boom_rad, k.joint_limits(Joint::Boom).1 - 0.05);
    if !(z_m.is_finite() && lo < hi) || z_at(lo) >= z_m {
        return lo;
    }
    if z_at(hi) <= z_m {
        return hi;
    }
    // The tip rises with the boom over its range (the boom foot is behind and below the tip).
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if z_at(mid) < z_m {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::step::cycle::{Action, CycleCommand, CycleConfig, Phase, StartPose, WorkCycle};
    use crate::step::safety::{ArmMode, ControlFault};

    use crate::step::cycle::test_support::{
        cycle, est_at, feed_cylinder_pressures, feed_pressures, kin,
    };
    use crate::step::estimate::Estimator;
    use crate::step::estimate::EstimatorConfig;
    use planner::kinematics::JointAngles;

    #[test]
    fn p_controllers_have_the_documented_signs() {
        let c = cycle(CycleConfig::default());
        let q = JointAngles {
            boom_rad: 0.0,
            stick_rad: -1.0,
            bucket_rad: -1.0,
        };
        let target = JointAngles {
            boom_rad: 0.1,
            stick_rad: -1.1,
            bucket_rad: -0.9,
        };
        let (cmd, done) = c.implement_toward(&q, &target);
        assert!(!done);
        // Boom up = extend; stick angle down = extend; bucket angle up (open) = retract.
        assert!(cmd[0] > 0.0 && cmd[1] > 0.0 && cmd[2] < 0.0, "{cmd:?}");
        let (s, _) = c.swing_toward(0.0, 0.0, -1.0);
        assert!((-0.7..0.0).contains(&s));
        let (s, _) = c.swing_toward(3.0, 0.0, -3.0);
        assert!(s > 0.0, "wraps the short way");
    }

    /// A started cycle whose one action is a dig from these joint angles, no scan, straight ahead.
    fn moving_to(boom_rad: f64, stick_rad: f64, bucket_rad: f64) -> WorkCycle {
        let mut c = cycle(CycleConfig {
            scan: false,
            actions: vec![Action::Dig {
                swing_rad: 0.0,
                start: StartPose::Joints {
                    boom_rad,
                    stick_rad,
                    bucket_rad,
                },
            }],
            ..CycleConfig::default()
        });
        c.start();
        c
    }

    #[test]
    fn a_stalled_move_opens_its_valve_further_and_holds_while_it_progresses() {
        // Target: boom, bucket and swing where the machine is; the stick 0.1 rad (5.7 deg) short.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let mut c = moving_to(boom, stick - 0.1, bucket);
        let stick_command = |c: &mut WorkCycle, q_stick: f64, t: f64| {
            let e = est_at([boom, q_stick, bucket, 0.0], 0.0, t);
            match c.step(t, &e, Some(ArmMode::Valve)).unwrap().command {
                CycleCommand::Valves(v) => v[1].abs(),
                other => panic!("expected valve commands, got {other:?}"),
            }
        };
        let first = stick_command(&mut c, stick, 0.0);
        assert!((first - 0.2).abs() < 1e-9, "P-controller minimum: {first}");
        // Not moving: after STALL_WAIT_S the command grows at STALL_BOOST_PER_S.
        let mut t = 0.0;
        let mut last = first;
        while t < 2.0 {
            t += 0.01;
            last = stick_command(&mut c, stick, t);
        }
        let expected = 0.2 + STALL_BOOST_PER_S * (2.0 - STALL_WAIT_S);
        assert!((last - expected).abs() < 0.02, "{last} vs {expected}");
        // Progress (0.3 deg closer each step, 3 deg in all): the command is held, not grown further.
        let mut q = stick;
        for _ in 0..10 {
            t += 0.01;
            q -= 0.005;
            let now = stick_command(&mut c, q, t);
            assert!(now <= last + 1e-9 && now > 0.5, "{now} vs {last}");
            last = now;
        }
    }

    #[test]
    fn a_swing_stalled_short_of_the_dig_opens_its_valve_further() {
        // The implement at its start, the swing 0.12 rad (7 deg) short and not moving (its command
        // inside a valve's dead band): the swing command grows as a stalled joint's does, so the
        // boom, which comes down only after the swing, is not left waiting for the time-out.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let mut c = moving_to(boom, stick, bucket);
        let swing_command = |c: &mut WorkCycle, t: f64| {
            let e = est_at([boom, stick, bucket, -0.12], 0.0, t);
            match c.step(t, &e, Some(ArmMode::Valve)).unwrap().command {
                CycleCommand::Valves(v) => v[3],
                other => panic!("expected valve commands, got {other:?}"),
            }
        };
        let first = swing_command(&mut c, 0.0);
        let p_command = CycleConfig::default().swing.command(0.12);
        assert!((first - p_command).abs() < 1e-9, "{first} vs {p_command}");
        let mut t = 0.0;
        let mut last = first;
        while t < 2.0 {
            t += 0.01;
            last = swing_command(&mut c, t);
        }
        let expected = p_command + STALL_BOOST_PER_S * (2.0 - STALL_WAIT_S);
        assert!(
            last > 0.0 && (last - expected).abs() < 0.02,
            "{last} vs {expected}"
        );
        // Braking (moving fast toward the target, the damping term outweighs the error): the
        // escalation does not push the brake harder.
        let (brake, _) = c.swing_toward_escalated(t + 0.01, 0.01, -0.12, 0.5, 0.0);
        let plain = c.swing_toward(-0.12, 0.5, 0.0).0;
        assert!(
            brake < 0.0 && (brake - plain).abs() < 1e-12,
            "{brake} vs {plain}"
        );
    }

    #[test]
    fn a_move_stopped_close_to_the_start_digs_from_there() {
        // The stick 0.03 rad (1.7 deg, tip ~0.1 m) short of its start and not getting closer (its
        // bucket resting on the face): the dig begins after MOVE_CLOSE_ENOUGH_WAIT_S, not at the
        // move's time-out.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let mut c = moving_to(boom, stick - 0.03, bucket);
        let e = est_at([boom, stick, bucket, 0.0], 0.0, 0.0);
        let mut t = 0.0;
        while t < MOVE_CLOSE_ENOUGH_WAIT_S - 0.1 {
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            assert_eq!(c.phase(), Phase::MoveToDig, "at {t} s");
            t += 0.01;
        }
        while t < MOVE_CLOSE_ENOUGH_WAIT_S + 0.2 {
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::Autodig);
        // Far from the start (the stick 0.3 rad short) it keeps moving.
        let mut c = moving_to(boom, stick - 0.3, bucket);
        let mut t = 0.0;
        while t < 3.0 {
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::MoveToDig);
    }

    #[test]
    fn a_move_blocked_at_relief_is_abandoned_before_its_time_out() {
        // The stick 0.1 rad short of its start (the tip more than MOVE_CLOSE_ENOUGH_M off) and
        // pushing at relief without getting closer: the move is given up once it has been blocked
        // MOVE_BLOCKED_S and has not progressed for MOVE_CLOSE_ENOUGH_WAIT_S, not at the move's
        // time-out; not at relief, it keeps moving.
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let (k, m) = kin();
        let tip = |q_stick: f64| {
            k.forward(&JointAngles {
                boom_rad: boom,
                stick_rad: q_stick,
                bucket_rad: bucket,
            })
        };
        let (a, b) = (tip(stick), tip(stick - 0.1));
        assert!((a.x_m - b.x_m).hypot(a.z_m - b.z_m) > MOVE_CLOSE_ENOUGH_M);
        for (head_pa, blocked) in [(34.0e6, true), (8.0e6, false)] {
            let mut c = moving_to(boom, stick - 0.1, bucket);
            let mut e =
                Estimator::new(k.clone(), m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
            let mut t = 0.0;
            let mut fault = None;
            while t < 5.0 && fault.is_none() {
                feed_pressures(&mut e, [boom, stick, bucket, 0.0], 0.0, t, head_pa, 1e6);
                fault = c.step(t, &e, Some(ArmMode::Valve)).err();
                t += 0.01;
            }
            if blocked {
                assert_eq!(fault, Some(ControlFault::Blocked("move to the dig")), "{t}");
                assert!(
                    t >= MOVE_BLOCKED_S.max(MOVE_CLOSE_ENOUGH_WAIT_S) && t < 3.0,
                    "{t}"
                );
            } else {
                assert_eq!(fault, None);
                assert_eq!(c.phase(), Phase::MoveToDig);
            }
        }
    }

    /// A bucket held in the ground: its rod reaches the relief against its closed valve every
    /// second (the boom tries to lift it free) and falls back between; with the stick pushing at
    /// normal pressures and the tip getting no closer, the move is blocked within a few seconds.
    /// Without the bucket's relief it keeps moving.
    #[test]
    fn a_bucket_pushed_to_relief_against_its_closed_valve_blocks_the_move() {
        let (boom, stick, bucket) = (0.2, -1.3, -0.5);
        let (k, m) = kin();
        for (peak_pa, blocked) in [(37.0e6, true), (20.0e6, false)] {
            let mut c = moving_to(boom, stick - 0.1, bucket);
            let mut e =
                Estimator::new(k.clone(), m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
            let (mut t, mut fault) = (0.0, None);
            while t < 8.0 && fault.is_none() {
                // At the peak for 0.2 s of every second.
                let bucket_rod_pa = if t % 1.0 < 0.2 { peak_pa } else { 5.0e6 };
                let pressures = [[8.0e6, 1.0e6], [8.0e6, 1.0e6], [1.0e6, bucket_rod_pa]];
                feed_cylinder_pressures(&mut e, [boom, stick, bucket, 0.0], 0.0, t, pressures);
                let out = c.step(t, &e, Some(ArmMode::Valve));
                if let Ok(out) = &out
                    && let CycleCommand::Valves(v) = out.command
                {
                    assert_eq!(v[2], 0.0, "the bucket's valve stays closed");
                }
                fault = out.err();
                t += 0.01;
            }
            if blocked {
                assert_eq!(fault, Some(ControlFault::Blocked("move to the dig")), "{t}");
                assert!(t < 4.0, "{t}");
            } else {
                assert_eq!(fault, None);
            }
        }
    }

    #[test]
    fn moves_time_out() {
        let mut c = cycle(CycleConfig {
            scan: false,
            move_timeout_s: 1.0,
            // The dump's hold must fit its timeout (`CycleConfig::validate`).
            dump_hold_s: 0.5,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([-0.5, -1.6, -0.9, 1.0], 0.0, 0.0);
        c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        let err = c.step(2.0, &e, Some(ArmMode::Valve)).unwrap_err();
        assert_eq!(err, ControlFault::Timeout("move to the dig"));
    }
}
