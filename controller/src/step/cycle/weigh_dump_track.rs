//! After the dig: Weigh, SwingToDump, Dump (with the lift of a held bucket), and TrackBack.

use planner::kinematics::Joint;
use planner::machine::GRAVITY_M_PER_S2;

use crate::step::estimate::Estimator;
use crate::step::safety::ControlFault;

use super::weigh::{
    WEIGH_LIFT_MAX_S, WEIGH_LIFT_RAD, WEIGH_MAX_EXTRA_S, WEIGH_MAX_LIFTS, WEIGH_SUPPORTED_KG,
    WeighAverage,
};
use super::{
    CycleCommand, JOINT_SIGN, Phase, RELIEF_RELIFT_FRACTION, STALL_PROGRESS_RAD, WorkCycle,
};

/// Dump: a bucket that has not opened further for this long at full command is held (resting in the
/// spoil, or still in the cut: its port at relief); the boom then lifts while it keeps opening, s.
pub(super) const STALL_RELIFT_S: f64 = 3.0;

/// Dump: how long the opening port must stay near relief before the boom lifts, s.
pub(super) const RELIEF_RELIFT_S: f64 = 0.5;

impl WorkCycle {
    pub(super) fn step_weigh(&mut self, now_s: f64, est: &Estimator) -> CycleCommand {
        let s = est.state();
        let lift = CycleCommand::Valves([self.config.joint.max_command, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // Lifting a bucket the ground carried (below): full boom lift until the target angle or
        // the time limit, then the weighing starts over (settle, window).
        if let Some(r) = &mut self.record
            && let Some(target) = r.weigh_lift_to_rad
        {
            if s.joints.boom_rad < target && now_s - self.phase_since_s < WEIGH_LIFT_MAX_S {
                return lift;
            }
            r.weigh_lift_to_rad = None;
            r.weigh = WeighAverage::default();
            self.phase_since_s = now_s;
            return CycleCommand::Neutral;
        }
        let elapsed = now_s - self.phase_since_s;
        let settle = self.config.weigh_settle_s;
        if elapsed >= settle {
            let mut boundary = false;
            if let (Some(r), Some(w)) = (&mut self.record, est.payload_weight_n()) {
                boundary = r.weigh.push(w);
            }
            let window_done = elapsed >= settle + self.config.weigh_window_s;
            let give_up = elapsed >= settle + self.config.weigh_window_s + WEIGH_MAX_EXTRA_S;
            let steady = self.record.as_ref().is_none_or(|r| r.weigh.steady());
            if window_done && (steady || boundary || give_up) {
                if let Some(r) = &mut self.record
                    && let Some(w) = r.weigh.mean_n(boundary)
                {
                    if w < -WEIGH_SUPPORTED_KG * GRAVITY_M_PER_S2 {
                        if r.weigh_lifts < WEIGH_MAX_LIFTS {
                            r.weigh_lifts += 1;
                            r.weigh_lift_to_rad = Some(s.joints.boom_rad + WEIGH_LIFT_RAD);
                            tracing::info!(
                                weight_n = w,
                                lift = r.weigh_lifts,
                                "weigh: the ground carries the bucket; lifting and weighing again"
                            );
                            self.phase_since_s = now_s;
                            return lift;
                        }
                        tracing::warn!(
                            weight_n = w,
                            "weigh: still supported after lifting; weight unknown"
                        );
                        r.stats.weight_n = None;
                    } else {
                        r.stats.weight_n = Some(w);
                    }
                }
                tracing::debug!(
                    weight_n = ?self.record.as_ref().and_then(|r| r.stats.weight_n),
                    joints = ?s.joints,
                    extension = ?s.extension_fraction,
                    torque_nm = ?s.joint_torque_nm,
                    tip_z_m = s.tip.z_m,
                    "weighed"
                );
                self.set_phase(Phase::SwingToDump, now_s);
            }
        }
        CycleCommand::Neutral
    }

    /// Raise the boom to the carry angle, then swing to `target_rad`; Dump (or Finished) when there.
    pub(super) fn step_swing_to(
        &mut self,
        now_s: f64,
        est: &Estimator,
        target_rad: f64,
    ) -> Result<CycleCommand, ControlFault> {
        if self.timed_out(now_s) {
            return Err(ControlFault::Timeout("swing"));
        }
        let s = est.state();
        let carry = self.config.carry_boom_rad;
        let boom_err = carry - s.joints.boom_rad;
        let boom_clear = s.joints.boom_rad >= carry - 3.0 * self.config.joint.tolerance
            || s.tip.z_m >= self.config.carry_tip_z_m;
        // Full lift: at part command an open-centre valve bypasses most of the flow and the loaded
        // boom stalls.
        let boom = if boom_err > 0.0 && !boom_clear {
            self.config.joint.max_command
        } else {
            0.0
        };
        let dt_s = self.stall_step_s(now_s);
        let (swing, swing_done) = if boom_clear {
            self.swing_toward_escalated(now_s, dt_s, s.swing_rad, s.rates_rad_per_s[3], target_rad)
        } else {
            (0.0, false)
        };
        let rate_small = s.rates_rad_per_s[3].abs() < 0.1;
        if self.settled(swing_done && rate_small, now_s) {
            if self.phase == Phase::Return {
                tracing::info!(digs = self.digs_done, "work cycle finished");
                self.set_phase(Phase::Finished, now_s);
            } else {
                self.set_phase(Phase::Dump, now_s);
            }
            return Ok(CycleCommand::Neutral);
        }
        Ok(CycleCommand::Valves([boom, 0.0, 0.0, swing, 0.0, 0.0]))
    }

    pub(super) fn step_dump(
        &mut self,
        now_s: f64,
        est: &Estimator,
    ) -> Result<CycleCommand, ControlFault> {
        if self.timed_out(now_s) {
            return Err(ControlFault::Timeout("dump"));
        }
        let s = est.state();
        let tolerance = self.config.joint.tolerance;
        let err = self.config.dump_bucket_rad - s.joints.bucket_rad;
        // The bucket empties by its angle to the horizontal: a stick folded in at the end of the
        // dig leaves an opened bucket facing up enough to hold part of its load, which the next dig
        // and weighing would carry. The stick extends until the bucket faces down enough.
        let abs_err = self.config.dump_bucket_abs_rad - s.joints.bucket_abs_rad();
        let stick_max_rad = est.kinematics().joint_limits(Joint::Stick).1 - 0.05;
        let facing_down = abs_err <= tolerance || s.joints.stick_rad >= stick_max_rad;
        let open = err <= tolerance;
        if self.settled(open && facing_down, now_s)
            && now_s - self.settle_since_s.unwrap_or(now_s) >= self.config.dump_hold_s
        {
            if let Some(r) = self.record.take() {
                tracing::info!(
                    dig = r.stats.number(),
                    weight_n = %r
                        .stats
                        .weight_n
                        .map_or_else(|| "none".to_owned(), |w| format!("{w:.0}")),
                    time_s = %format_args!("{:.2}", r.stats.time_s),
                    energy_kj = %format_args!("{:.1}", r.stats.energy_kj()),
                    swept_m3 = %format_args!("{:.3}", r.stats.swept_volume_m3),
                    "dig done"
                );
                self.stats.push(r.stats);
                self.digs_done += 1;
            }
            self.swept = None;
            self.next_action(now_s);
            return Ok(CycleCommand::Neutral);
        }
        // Uncurl: the bucket cylinder retracts to open the bucket.
        let bucket = if open {
            0.0
        } else {
            JOINT_SIGN[2] * self.config.joint.max_command
        };
        // A bucket that cannot open (resting in the spoil, or still in the cut) is lifted clear by
        // the boom while it keeps opening.
        if !self.stall_best_rad[2].is_finite() || err < self.stall_best_rad[2] - STALL_PROGRESS_RAD
        {
            self.stall_best_rad[2] = err;
            self.stall_progress_s[2] = now_s;
        }
        // Opening retracts the bucket cylinder (`JOINT_SIGN`): the rod port carries the load.
        let at_relief = !open
            && s.rod_pressure_pa[2]
                >= RELIEF_RELIFT_FRACTION * self.autodig_config.relief_pressure_pa[2];
        self.relief_since_s = if at_relief {
            self.relief_since_s.or(Some(now_s))
        } else {
            None
        };
        let held_at_relief = self
            .relief_since_s
            .is_some_and(|since| now_s - since >= RELIEF_RELIFT_S);
        let boom_max_rad = est.kinematics().joint_limits(Joint::Boom).1 - 0.05;
        let boom = if !open
            && (now_s - self.stall_progress_s[2] > STALL_RELIFT_S || held_at_relief)
            && s.joints.boom_rad < boom_max_rad
        {
            self.config.joint.max_command
        } else {
            0.0
        };
        let stick = if facing_down {
            0.0
        } else {
            JOINT_SIGN[1] * self.config.joint.command(abs_err)
        };
        Ok(CycleCommand::Valves([boom, stick, bucket, 0.0, 0.0, 0.0]))
    }

    pub(super) fn step_track(
        &mut self,
        now_s: f64,
        est: &Estimator,
    ) -> Result<CycleCommand, ControlFault> {
        if self.timed_out(now_s) {
            return Err(ControlFault::Timeout("track back"));
        }
        let [l, r] = est.state().track_travel_m;
        let err = self.track_target_m - 0.5 * (l + r);
        let g = self.config.track;
        if self.settled(err.abs() <= g.tolerance, now_s) {
            self.terrain = None; // the machine moved: the old map's frame no longer fits the section
            self.next_action(now_s);
            return Ok(CycleCommand::Neutral);
        }
        let u = if err.abs() <= g.tolerance {
            0.0
        } else {
            g.command(err)
        };
        Ok(CycleCommand::Valves([0.0, 0.0, 0.0, 0.0, u, u]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::step::cycle::stats::DigRecord;
    use crate::step::cycle::{Action, ActionKind, CycleCommand, CycleConfig, Phase, WorkCycle};
    use crate::step::safety::ArmMode;

    use crate::step::cycle::test_support::{cycle, est_at, feed, feed_pressures, kin};
    use crate::step::estimate::Estimator;
    use crate::step::estimate::EstimatorConfig;

    #[test]
    fn track_back_moves_the_tracks_backwards_until_the_distance() {
        let mut c = cycle(CycleConfig {
            actions: vec![Action::TrackBack { distance_m: 1.0 }],
            repeat: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.3, -1.6, -0.9, 0.0], 5.0, 0.0);
        let out = c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(c.phase(), Phase::TrackBack);
        let CycleCommand::Valves(v) = out.command else {
            panic!()
        };
        assert!(v[4] < 0.0 && v[4] == v[5]);
        let mut t = 0.01;
        let mut e = est_at([0.3, -1.6, -0.9, 0.0], 4.0, t);
        while c.phase() != Phase::Return && t < 1.0 {
            feed(&mut e, [0.3, -1.6, -0.9, 0.0], 4.0, t);
            c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::Return);
    }

    fn weighing_cycle() -> WorkCycle {
        let mut c = cycle(CycleConfig::default());
        c.phase = Phase::Weigh;
        c.phase_since_s = 0.0;
        let mut record = DigRecord::started(0, ActionKind::Dig, 0.0, 0.0, false);
        record.stats.time_s = 5.0;
        c.record = Some(record);
        c
    }

    fn est_with_head(head_pa: f64) -> Estimator {
        let (k, m) = kin();
        let mut e = Estimator::new(k, m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
        feed_pressures(&mut e, [0.3, -1.6, -0.9, 0.0], 0.0, 0.0, head_pa, 1e6);
        e
    }

    #[test]
    fn weighing_averages_the_static_payload_estimate() {
        let mut c = weighing_cycle();
        // 16 MPa in every head at this pose: about 840 kg in the bucket.
        let e = est_with_head(16e6);
        let expect = e.payload_weight_n().unwrap();
        assert!(expect > 0.0, "{expect}");
        let mut t = 0.0;
        while c.phase() == Phase::Weigh && t < 3.0 {
            let out = c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            assert!(matches!(out.command, CycleCommand::Neutral), "{out:?}");
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::SwingToDump);
        let w = c.record.unwrap().stats.weight_n.unwrap();
        assert!((w - expect).abs() < 1e-6);
    }

    /// A bucket the ground carries weighs less than nothing: the boom lifts and the weighing starts
    /// over; still supported after the last lift, the weight is reported unknown, not negative.
    #[test]
    fn weighing_lifts_a_supported_bucket_and_never_reports_a_negative_payload() {
        let mut c = weighing_cycle();
        // 2 MPa in every head: the boom holds less than the empty implement (about -2300 kg).
        let e = est_with_head(2e6);
        assert!(e.payload_estimate_kg().unwrap() < -WEIGH_SUPPORTED_KG);
        let (mut t, mut lift_steps) = (0.0, 0);
        while c.phase() == Phase::Weigh && t < 30.0 {
            let out = c.step(t, &e, Some(ArmMode::Valve)).unwrap();
            if let CycleCommand::Valves(v) = out.command {
                assert!(v[0] > 0.0 && v[1..].iter().all(|x| *x == 0.0), "{v:?}");
                lift_steps += 1;
            }
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::SwingToDump);
        let r = c.record.unwrap();
        assert_eq!(r.weigh_lifts, WEIGH_MAX_LIFTS);
        // The boom never reaches the lift target here (the estimator does not move), so each lift
        // ends on its time limit.
        let expect_steps = f64::from(WEIGH_MAX_LIFTS) * WEIGH_LIFT_MAX_S / 0.01;
        assert!(
            (f64::from(lift_steps) - expect_steps).abs() <= 4.0,
            "{lift_steps}"
        );
        assert_eq!(r.stats.weight_n, None);
    }

    #[test]
    fn swing_to_dump_raises_the_boom_before_swinging() {
        let mut c = cycle(CycleConfig::default());
        c.phase = Phase::SwingToDump;
        let e = est_at([-0.4, -1.6, -0.9, 0.0], 0.0, 0.0);
        assert!(e.state().tip.z_m < c.config().carry_tip_z_m);
        let CycleCommand::Valves(v) = c.step(0.0, &e, Some(ArmMode::Valve)).unwrap().command else {
            panic!()
        };
        assert!(v[0] > 0.0 && v[3] == 0.0, "{v:?}");
        let e = est_at([0.8, -1.6, -0.9, 0.0], 0.0, 0.0);
        let CycleCommand::Valves(v) = c.step(0.01, &e, Some(ArmMode::Valve)).unwrap().command
        else {
            panic!()
        };
        assert!(v[0] == 0.0 && v[3] < 0.0, "{v:?}");
    }

    /// A cycle without scans, started and in its Dump phase.
    fn dumping() -> WorkCycle {
        let mut c = cycle(CycleConfig {
            scan: false,
            ..CycleConfig::default()
        });
        c.start();
        c.set_phase(Phase::Dump, 0.0);
        c
    }

    /// One Dump step with the bucket at `bucket_rad` and the bucket's rod at `rod_pa` (heads 8 MPa).
    fn dump_step(c: &mut WorkCycle, bucket_rad: f64, t: f64, rod_pa: f64) -> [f64; 6] {
        match dump_step_at(c, [0.5, -1.3, bucket_rad], t, rod_pa) {
            CycleCommand::Valves(v) => v,
            other => panic!("expected valve commands, got {other:?}"),
        }
    }

    /// One Dump step at the joint angles `[boom, stick, bucket]`.
    fn dump_step_at(c: &mut WorkCycle, q: [f64; 3], t: f64, rod_pa: f64) -> CycleCommand {
        let (k, m) = kin();
        let mut e = Estimator::new(k, m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
        feed_pressures(&mut e, [q[0], q[1], q[2], 1.0], 0.0, t, 8e6, rod_pa);
        c.step(t, &e, Some(ArmMode::Valve)).unwrap().command
    }

    /// A bucket opened to `dump_bucket_deg` on a stick folded in still faces up enough to hold part
    /// of its load: the stick extends until the bucket's angle to the horizontal reaches
    /// `dump_bucket_abs_deg`, and only then the dump holds and ends.
    #[test]
    fn a_dump_on_a_folded_stick_extends_it_until_the_bucket_faces_down() {
        let mut c = dumping();
        let hold = c.config.dump_hold_s;
        // Boom 46 deg, stick -145 deg, bucket 26 deg (open): the bucket at -73 deg.
        let folded = [0.8, -2.53, 0.45];
        let mut t = 0.0;
        while t < 2.0 * hold {
            let CycleCommand::Valves(v) = dump_step_at(&mut c, folded, t, 1e6) else {
                panic!("the dump ended with the bucket at -73 deg, at {t} s")
            };
            assert!(v[1] < 0.0, "the stick extends (JOINT_SIGN): {v:?}");
            assert_eq!(v[2], 0.0, "the bucket is open: {v:?}");
            t += 0.01;
        }
        assert_eq!(c.phase(), Phase::Dump);
        // Extended to -110 deg: the bucket at -38 deg faces down; the dump holds, then ends.
        let extended = [0.8, -1.92, 0.45];
        let since = t;
        while c.phase() == Phase::Dump {
            assert!(t < since + 2.0 * hold + 1.0, "the dump never ended");
            if let CycleCommand::Valves(v) = dump_step_at(&mut c, extended, t, 1e6) {
                assert_eq!(v[..3], [0.0; 3], "at {t} s");
            }
            t += 0.01;
        }
        assert!(t - since >= hold, "ended after {} s", t - since);
    }

    #[test]
    fn a_bucket_that_cannot_open_in_the_dump_is_lifted_clear() {
        let mut c = dumping();
        let commands =
            |c: &mut WorkCycle, bucket_rad: f64, t: f64| dump_step(c, bucket_rad, t, 1e6);
        let max = c.config.joint.max_command;
        let first = commands(&mut c, -1.5, 0.0);
        assert_eq!((first[0], first[2].abs()), (0.0, max), "uncurl only");
        // Opening: no lift.
        let mut t = 0.0;
        let mut q = -1.5;
        while t < 4.0 {
            t += 0.01;
            q += 0.002;
            assert_eq!(commands(&mut c, q, t)[0], 0.0, "at {t} s");
        }
        // Held (resting in the spoil): after STALL_RELIFT_S the boom lifts while the bucket opens.
        let held_from = t;
        while t < held_from + STALL_RELIFT_S + 0.1 {
            t += 0.01;
            let v = commands(&mut c, q, t);
            let expect = if t - held_from > STALL_RELIFT_S + 0.02 {
                max
            } else if t - held_from < STALL_RELIFT_S - 0.02 {
                0.0
            } else {
                v[0]
            };
            assert_eq!(v[0], expect, "at {t} s");
            assert_eq!(v[2].abs(), max);
        }
    }

    /// A bucket that creeps open against the spoil with its opening (rod) port at relief is held as
    /// well: the boom lifts it clear after RELIEF_RELIFT_S, although the angle keeps progressing.
    #[test]
    fn a_bucket_creeping_open_at_relief_is_lifted_clear() {
        let mut c = dumping();
        let relief = c.autodig_config.relief_pressure_pa[2];
        let commands = dump_step;
        let max = c.config.joint.max_command;
        // Opening at 0.4 rad/s with a light rod: no lift.
        let (mut t, mut q) = (0.0, -1.5);
        while t < 1.0 {
            t += 0.01;
            q += 0.004;
            assert_eq!(commands(&mut c, q, t, 5.0e6)[0], 0.0, "at {t} s");
        }
        // Creeping at 0.4 rad/s still, but the rod at relief: the boom lifts after RELIEF_RELIFT_S.
        let since = t;
        while t < since + RELIEF_RELIFT_S + 0.1 {
            t += 0.01;
            q += 0.004;
            let boom = commands(&mut c, q, t, 0.95 * relief)[0];
            if t - since > RELIEF_RELIFT_S + 0.02 {
                assert_eq!(boom, max, "at {t} s");
            } else if t - since < RELIEF_RELIFT_S - 0.02 {
                assert_eq!(boom, 0.0, "at {t} s");
            }
        }
        // The rod relieved: no lift.
        t += 0.01;
        q += 0.004;
        assert_eq!(commands(&mut c, q, t, 5.0e6)[0], 0.0);
    }
}
