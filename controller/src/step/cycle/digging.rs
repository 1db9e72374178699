//! The dig itself: Autodig with the perception enhancements, or cleanup then Autodig; energy and
//! swept volume integrated per step.

use planner::autodig::{Autodig, AutodigInputs, Stage};
use planner::cleanup::{Cleanup, CleanupInputs, CleanupOutput};
use planner::kinematics::BucketPose;
use planner::terrain::{SectionProfile, SweptVolume, TerrainError, TerrainGrid};

use crate::step::estimate::Estimator;
use crate::step::safety::ControlFault;

use super::action::Action;
use super::stats::DigRecord;
use super::{CycleCommand, Phase, WorkCycle};

impl WorkCycle {
    pub(super) fn begin_dig(&mut self, now_s: f64, est: &Estimator, action: &Action) {
        let s = est.state();
        let swing_rad = action.swing_rad().unwrap_or(s.swing_rad);
        // 3.2: keep the pre-dig terrain section along the digging plane.
        self.swept = None;
        if self.config.perception
            && let Some(terrain) = &self.terrain
        {
            match known_section(
                terrain,
                &s.pose,
                s.swing_rad,
                s.tip.x_m,
                self.config.section_r_min_m,
                self.config.section_r_max_m,
                self.config.section_step_m,
            )
            .and_then(|p| SweptVolume::new(p, self.bucket_width_m))
            {
                Ok(sv) => self.swept = Some(sv),
                Err(e) => {
                    tracing::warn!(error = %e, "no pre-dig section: digging without perception")
                }
            }
        }
        let perception = self.swept.is_some();
        let mut cfg = self.autodig_config;
        cfg.perception.end_dig_on_swept_volume = perception;
        cfg.perception.end_capture_above_terrain = perception;
        let kind = action.kind();
        self.record = Some(DigRecord::started(
            self.digs_done,
            kind,
            swing_rad,
            now_s,
            perception,
        ));
        match action {
            Action::Cleanup { plan, .. } => {
                match Cleanup::new(self.cleanup_config, *plan, self.floor) {
                    Ok(c) => {
                        self.cleanup = Some(c);
                        tracing::info!(dig = self.digs_done, "cleanup");
                        self.set_phase(Phase::Cleanup, now_s);
                    }
                    Err(e) => {
                        // Validated at construction except for the plan; skip the action.
                        tracing::warn!(error = %e, "invalid cleanup plan: skipped");
                        self.record = None;
                        self.next_action(now_s);
                    }
                }
            }
            _ => match Autodig::new(cfg, self.maps.clone()) {
                Ok(a) => {
                    self.autodig = Some(a);
                    tracing::info!(dig = self.digs_done, perception, "autodig");
                    self.set_phase(Phase::Autodig, now_s);
                }
                Err(e) => {
                    tracing::warn!(error = %e, "autodig config rejected: skipped");
                    self.record = None;
                    self.next_action(now_s);
                }
            },
        }
    }

    /// Energy (|F dL| summed over the cylinders) and ground-contact time since the last step.
    fn integrate(&mut self, now_s: f64, est: &Estimator, depth_m: Option<f64>) {
        let s = est.state();
        let Some(r) = &mut self.record else { return };
        if !s.derived_valid {
            r.last_lengths_m = None;
            return;
        }
        if let Some(prev) = r.last_lengths_m {
            let e: f64 = (0..3)
                .map(|i| (s.cylinder_force_n[i] * (s.cylinder_length_m[i] - prev[i])).abs())
                .sum();
            if e.is_finite() {
                r.stats.energy_j += e;
            }
        }
        if let (Some(t), Some(d)) = (r.last_s, depth_m)
            && d > 0.0
        {
            r.stats.ground_contact_time_s += (now_s - t).max(0.0);
        }
        r.last_lengths_m = Some(s.cylinder_length_m);
        r.last_s = Some(now_s);
    }

    pub(super) fn step_autodig(
        &mut self,
        now_s: f64,
        est: &Estimator,
    ) -> Result<CycleCommand, ControlFault> {
        let s = est.state();
        let (mut swept_m3, mut depth_m) = (None, None);
        if let Some(sv) = &mut self.swept {
            swept_m3 = sv.update(s.tip.x_m, s.tip.z_m).ok();
            depth_m = sv.depth_m(s.tip.x_m, s.tip.z_m).ok();
        }
        self.integrate(now_s, est, depth_m);
        let inputs = AutodigInputs {
            joint_rad: [s.joints.boom_rad, s.joints.stick_rad, s.joints.bucket_rad],
            head_pressure_pa: s.head_pressure_pa,
            rod_pressure_pa: s.rod_pressure_pa,
            extension_fraction: s.extension_fraction,
            swept_volume_m3: swept_m3,
            bucket_depth_m: depth_m,
        };
        let Some(autodig) = &mut self.autodig else {
            self.set_phase(Phase::Weigh, now_s);
            return Ok(CycleCommand::Neutral);
        };
        let out = autodig
            .step(&inputs, now_s)
            .map_err(ControlFault::Autodig)?;
        if let Some(end) = out.stage_end {
            tracing::info!(stage = ?end.stage, reason = ?end.reason, "autodig stage ended");
        }
        if out.stage == Stage::Done {
            if let Some(r) = &mut self.record {
                r.stats.end_reason = out.end_reason;
                r.stats.time_s = now_s - r.stats.start_time_s;
                r.stats.swept_volume_m3 = swept_m3.unwrap_or(0.0);
            }
            self.autodig = None;
            self.set_phase(Phase::Weigh, now_s);
            return Ok(CycleCommand::Neutral);
        }
        let c = out.command;
        Ok(CycleCommand::Valves([c[0], c[1], c[2], 0.0, 0.0, 0.0]))
    }

    pub(super) fn step_cleanup(
        &mut self,
        now_s: f64,
        est: &Estimator,
    ) -> Result<CycleCommand, ControlFault> {
        let s = est.state();
        self.integrate(now_s, est, None);
        let swing = self
            .config
            .actions
            .get(self.action_index)
            .and_then(Action::swing_rad)
            .unwrap_or(s.swing_rad);
        let inputs = CleanupInputs {
            tip_x_m: s.tip.x_m,
            tip_z_m: s.tip.z_m,
            stick_abs_rad: s.joints.stick_abs_rad(),
            head_pressure_pa: s.head_pressure_pa,
            rod_pressure_pa: s.rod_pressure_pa,
        };
        let Some(cleanup) = &mut self.cleanup else {
            self.set_phase(Phase::Weigh, now_s);
            return Ok(CycleCommand::Neutral);
        };
        match cleanup
            .step(&inputs, now_s)
            .map_err(ControlFault::Cleanup)?
        {
            CleanupOutput::Waypoint(w) => {
                let q = est
                    .kinematics()
                    .inverse(&BucketPose {
                        x_m: w.x_m,
                        z_m: w.z_m,
                        bucket_abs_rad: w.bucket_abs_rad,
                    })
                    .map_err(|_| ControlFault::Kinematics("cleanup waypoint out of reach"))?;
                Ok(CycleCommand::Position([
                    q.boom_rad,
                    q.stick_rad,
                    q.bucket_rad,
                    swing,
                ]))
            }
            CleanupOutput::HandOver(reason) => {
                let used = cleanup.floor_estimate();
                match used.z_m() {
                    Some(z) if z > self.config.floor_max_z_m => tracing::warn!(
                        floor_z_m = z,
                        max_z_m = self.config.floor_max_z_m,
                        "cleanup contact above the track ground is material, not the floor: not kept"
                    ),
                    _ => self.floor = used,
                }
                tracing::info!(?reason, floor_z_m = ?used.z_m(), "cleanup hand-over to Autodig");
                if let Some(r) = &mut self.record {
                    r.stats.hand_over = Some(reason);
                    r.stats.floor_z_m = used.z_m();
                }
                self.cleanup = None;
                // Hand over in Pre-Dig (3.3), with the perception enhancements if a section exists.
                let mut cfg = self.autodig_config;
                let perception = self.swept.is_some();
                cfg.perception.end_dig_on_swept_volume = perception;
                cfg.perception.end_capture_above_terrain = perception;
                let a = Autodig::starting_in(cfg, self.maps.clone(), Stage::PreDig)
                    .map_err(ControlFault::Autodig)?;
                self.autodig = Some(a);
                self.set_phase(Phase::Autodig, now_s);
                Ok(CycleCommand::Neutral)
            }
        }
    }
}

/// The terrain section along the digging plane from `r_min_m` to `r_max_m`, cut to the run of known
/// cells that contains the tip's radius `tip_r_m` (or the longest known run): the range sensor does
/// not see the ground right under the boom, and the map has no cells beyond its scan.
pub(super) fn known_section(
    terrain: &TerrainGrid,
    pose: &planner::kinematics::MachinePose,
    swing_rad: f64,
    tip_r_m: f64,
    r_min_m: f64,
    r_max_m: f64,
    step_m: f64,
) -> Result<SectionProfile, TerrainError> {
    let n = ((r_max_m - r_min_m) / step_m).floor().clamp(1.0, 10_000.0) as usize + 1;
    let heights: Vec<Option<f64>> = (0..n)
        .map(|k| {
            let r = r_min_m + k as f64 * step_m;
            let [x, y, _] = pose.world_from_base(swing_rad, r, 0.0);
            terrain.height_at(x, y).ok().filter(|h| h.is_finite())
        })
        .collect();
    // Runs of known samples: (start, end exclusive).
    let mut runs = Vec::new();
    let mut start = None;
    for (k, h) in heights.iter().enumerate() {
        match (h, start) {
            (Some(_), None) => start = Some(k),
            (None, Some(s0)) => {
                runs.push((s0, k));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s0) = start {
        runs.push((s0, n));
    }
    let tip_k = ((tip_r_m - r_min_m) / step_m).round();
    let containing = runs
        .iter()
        .copied()
        .find(|&(a, b)| tip_k >= a as f64 && tip_k < b as f64);
    let (a, b) = containing
        .or_else(|| runs.iter().copied().max_by_key(|&(a, b)| b - a))
        .ok_or(TerrainError::InvalidArgument {
            what: "no known terrain along the digging plane",
        })?;
    let values = heights[a..b].iter().map(|h| h.unwrap_or(0.0)).collect();
    SectionProfile::new(r_min_m + a as f64 * step_m, step_m, values)
}
