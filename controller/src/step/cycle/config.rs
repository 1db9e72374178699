//! The work cycle's parameters ([`CycleConfig`]), its P-controllers ([`PGain`]) and their validation.

use planner::cleanup::FloorPolicy;
use serde::{Deserialize, Serialize};

use crate::check::{Limits, ParamError, check, check_count, check_deg};

use super::action::Action;
use super::scan_grid::ScanGrid;

/// Work cycle parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CycleConfig {
    /// The plan. Default: three digs into the default bench, straight ahead and 7 degrees to each side.
    pub actions: Vec<Action>,
    /// Start over at the first action after the last one. Default true.
    pub repeat: bool,
    /// Stop after this many digs (dig and cleanup actions). Default none (`repeat` false: one pass).
    pub max_digs: Option<u32>,
    /// Swing angle of the spoil pile, degrees in files. Default -90 (the default bench's pile).
    #[serde(rename = "dump_swing_deg", with = "planner::machine::degrees")]
    pub dump_swing_rad: f64,
    /// Swing angle to return to after the last action, degrees in files. Default 0.
    #[serde(rename = "home_swing_deg", with = "planner::machine::degrees")]
    pub home_swing_rad: f64,
    /// Boom angle to raise to before swinging, degrees in files. Default 42 (the bucket clears the
    /// default bench's top).
    #[serde(rename = "carry_boom_deg", with = "planner::machine::degrees")]
    pub carry_boom_rad: f64,
    /// ... or until the bucket tip is this high (base frame), whichever comes first, m. Default 2.8
    /// (0.8 m above the default bench's top).
    pub carry_tip_z_m: f64,
    /// Bucket joint angle (relative to the stick) that empties the bucket, degrees in files. Default 20.
    #[serde(rename = "dump_bucket_deg", with = "planner::machine::degrees")]
    pub dump_bucket_rad: f64,
    /// Bucket angle to the horizontal (the thesis's rho, `boom + stick + bucket`) at or above which
    /// the bucket empties, degrees in files: the opening then faces at least 45 degrees below the
    /// horizontal, steeper than a soil's angle of repose. A dump that reaches `dump_bucket_deg`
    /// below it (the stick folded in at the end of a dig) extends the stick until the bucket gets
    /// there or the stick reaches its limit. Default -45.
    #[serde(rename = "dump_bucket_abs_deg", with = "planner::machine::degrees")]
    pub dump_bucket_abs_rad: f64,
    /// Hold the dump pose this long, s. Default 1.0.
    pub dump_hold_s: f64,
    /// Implement P-controllers (error in rad). Default kp 2, max 0.8, tolerance 0.03 rad.
    pub joint: PGain,
    /// Swing P-controller (error in rad). Default kp 1.5, max 0.7, tolerance 0.03 rad.
    pub swing: PGain,
    /// Track P-controller (error in m). Default kp 1.0, max 0.6, tolerance 0.05 m.
    pub track: PGain,
    /// A target must hold this long to count as reached, s. Default 0.2.
    pub settle_s: f64,
    /// A move (to the dig, to the dump, the dump itself, tracking) that takes longer is a fault, s.
    /// Default 40.
    pub move_timeout_s: f64,
    /// Ask for a range scan before each dig. Default true.
    pub scan: bool,
    /// Wait this long for the scan, then dig without perception, s. Default 5.
    pub scan_timeout_s: f64,
    /// Use the perception enhancements when a terrain map is available. Default true.
    pub perception: bool,
    /// Pre-dig section along the digging plane: from this radius, m. Default 1.
    pub section_r_min_m: f64,
    /// Pre-dig section: to this radius, m. Default 12.
    pub section_r_max_m: f64,
    /// Pre-dig section: sample spacing, m. Default 0.05.
    pub section_step_m: f64,
    /// Wait this long after Capture before weighing, s. Default 0.8.
    pub weigh_settle_s: f64,
    /// Average the payload estimate over at least this window, s. Default 1.0: the implement keeps
    /// oscillating on its oil columns after the valves close (about 2 Hz on the default machine, the
    /// static estimate swinging by +-35 %), and a 0.3 s window, part of one period, read up to 20 %
    /// off. Weigh therefore ends at the first whole period of that oscillation after the window (at
    /// most 1 s later; a steady estimate ends at the window), so a short window stays unbiased.
    pub weigh_window_s: f64,
    /// Detect the floor on the first cleanup and reuse it (Table 5), or every time.
    pub floor_policy: FloorPolicy,
    /// A cleanup's probe contact above this elevation (base frame: the track ground is z = 0) is
    /// material, not the floor, and is not kept for later cleanups: the machine stands on the floor
    /// it levels, or above it in a cut. (The demo's first cleanup started over what the digs had left
    /// of the bench and "detected" the floor 1.68 m up; every later cleanup reused it.) m. Default 0.3.
    pub floor_max_z_m: f64,
    /// An action of the plan abandoned on a control fault (a move timing out, the floor not found,
    /// Autodig rejecting its inputs) is tried again this many times before the plan goes on with the
    /// next one. Plans pushed by the planner (`crate::session::planned`) are not retried: it plans again from the
    /// new terrain. Default 1.
    pub retries: u32,
    /// The grid scans are binned into.
    pub scan_grid: ScanGrid,
}

impl Default for CycleConfig {
    fn default() -> Self {
        Self {
            actions: vec![
                Action::bench_dig(0.0),
                Action::bench_dig(7.0),
                Action::bench_dig(-7.0),
            ],
            repeat: true,
            max_digs: None,
            dump_swing_rad: (-90.0_f64).to_radians(),
            home_swing_rad: 0.0,
            carry_boom_rad: 42.0_f64.to_radians(),
            carry_tip_z_m: 2.8,
            dump_bucket_rad: 20.0_f64.to_radians(),
            dump_bucket_abs_rad: (-45.0_f64).to_radians(),
            dump_hold_s: 1.0,
            joint: PGain {
                kp: 2.0,
                max_command: 0.8,
                min_command: 0.2,
                kd: 0.0,
                tolerance: 0.03,
            },
            swing: PGain {
                kp: 1.5,
                max_command: 0.7,
                min_command: 0.15,
                kd: 1.0,
                tolerance: 0.03,
            },
            track: PGain {
                kp: 1.0,
                max_command: 0.6,
                min_command: 0.2,
                kd: 0.0,
                tolerance: 0.05,
            },
            settle_s: 0.2,
            move_timeout_s: 40.0,
            scan: true,
            scan_timeout_s: 5.0,
            perception: true,
            section_r_min_m: 1.0,
            section_r_max_m: 12.0,
            section_step_m: 0.05,
            weigh_settle_s: 0.8,
            weigh_window_s: 1.0,
            floor_policy: FloorPolicy::DetectOnce,
            floor_max_z_m: 0.3,
            retries: 1,
            scan_grid: ScanGrid::default(),
        }
    }
}

impl CycleConfig {
    /// Checks every parameter: finite, in range and consistent (a move's settle time inside its
    /// timeout, the pre-dig section and the scan grid of bounded size, P-controllers whose smallest
    /// command does not exceed their largest), and every action of the plan (angles, poses, cleanup
    /// radii, tracking distances). Angles are checked in degrees, as the file writes them.
    ///
    /// # Errors
    /// The first [`ParamError`] (section `cycle`).
    pub fn validate(&self) -> Result<(), ParamError> {
        const S: &str = "cycle";
        for (i, action) in self.actions.iter().enumerate() {
            action.validate(i)?;
        }
        if let Some(n) = self.max_digs {
            check_count(S, "max_digs", u64::from(n), 1, 100_000, "")?;
        }
        check_count(S, "retries", u64::from(self.retries), 0, 100, "")?;
        let swing = Limits::closed(-360.0, 360.0, "deg");
        check_deg(S, "dump_swing_deg", self.dump_swing_rad, swing)?;
        check_deg(S, "home_swing_deg", self.home_swing_rad, swing)?;
        check_deg(
            S,
            "carry_boom_deg",
            self.carry_boom_rad,
            Limits::closed(-90.0, 90.0, "deg"),
        )?;
        check_deg(
            S,
            "dump_bucket_deg",
            self.dump_bucket_rad,
            Limits::closed(-180.0, 180.0, "deg"),
        )?;
        check_deg(
            S,
            "dump_bucket_abs_deg",
            self.dump_bucket_abs_rad,
            Limits::closed(-90.0, 90.0, "deg"),
        )?;
        let height = Limits::closed(-20.0, 20.0, "m");
        check(S, "carry_tip_z_m", self.carry_tip_z_m, height, "")?;
        check(S, "floor_max_z_m", self.floor_max_z_m, height, "")?;
        check(
            S,
            "move_timeout_s",
            self.move_timeout_s,
            Limits::above(0.0, 3600.0, "s"),
            "",
        )?;
        for (key, v) in [
            ("settle_s", self.settle_s),
            ("dump_hold_s", self.dump_hold_s),
        ] {
            check(
                S,
                key,
                v,
                Limits::open(0.0, self.move_timeout_s, "s"),
                "positive and shorter than move_timeout_s",
            )?;
        }
        check(
            S,
            "scan_timeout_s",
            self.scan_timeout_s,
            Limits::above(0.0, 600.0, "s"),
            "",
        )?;
        check(
            S,
            "weigh_settle_s",
            self.weigh_settle_s,
            Limits::closed(0.0, 60.0, "s"),
            "",
        )?;
        check(
            S,
            "weigh_window_s",
            self.weigh_window_s,
            Limits::above(0.0, 60.0, "s"),
            "",
        )?;
        check(
            S,
            "section_r_min_m",
            self.section_r_min_m,
            Limits::closed(0.0, 50.0, "m"),
            "",
        )?;
        check(
            S,
            "section_r_max_m",
            self.section_r_max_m,
            Limits::above(self.section_r_min_m, 50.0, "m"),
            "beyond section_r_min_m",
        )?;
        check(
            S,
            "section_step_m",
            self.section_step_m,
            Limits::closed(0.005, 1.0, "m"),
            "",
        )?;
        for (key, gain) in [
            ("joint", &self.joint),
            ("swing", &self.swing),
            ("track", &self.track),
        ] {
            gain.validate(key)?;
        }
        self.scan_grid.validate()
    }
}

/// A P-controller on one valve: `command = sign * clamp(kp * error, +-max)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PGain {
    /// Proportional gain, command per unit of error (per rad or per m).
    pub kp: f64,
    /// Largest command magnitude, `(0, 1]`.
    pub max_command: f64,
    /// Smallest command magnitude outside the tolerance, `[0, max_command]`: an open-centre valve
    /// barely moves a loaded cylinder at small spool openings.
    #[serde(default)]
    pub min_command: f64,
    /// Rate feedback, command per rad/s (or m/s): damps the swing's large inertia. Default 0.
    #[serde(default)]
    pub kd: f64,
    /// The target counts as reached within this error (rad or m).
    pub tolerance: f64,
}

impl PGain {
    pub(super) fn command(&self, error: f64) -> f64 {
        self.command_damped(error, 0.0)
    }

    pub(super) fn command_damped(&self, error: f64, rate: f64) -> f64 {
        let u = self.kp * error - self.kd * rate;
        if !u.is_finite() || error.abs() <= self.tolerance {
            return 0.0;
        }
        let floor = self.min_command.clamp(0.0, self.max_command);
        u.abs().clamp(floor, self.max_command).copysign(u)
    }
}

impl PGain {
    /// Checks a controller `cycle.<name>`: gains finite, commands in `(0, 1]` with the smallest not
    /// above the largest, a positive tolerance.
    pub(super) fn validate(&self, name: &str) -> Result<(), ParamError> {
        const S: &str = "cycle";
        let key = |k: &str| format!("{name}.{k}");
        check(S, &key("kp"), self.kp, Limits::above(0.0, 100.0, ""), "")?;
        check(S, &key("kd"), self.kd, Limits::closed(0.0, 100.0, ""), "")?;
        check(
            S,
            &key("max_command"),
            self.max_command,
            Limits::above(0.0, 1.0, ""),
            "",
        )?;
        check(
            S,
            &key("min_command"),
            self.min_command,
            Limits::closed(0.0, self.max_command, ""),
            "at most max_command",
        )?;
        check(
            S,
            &key("tolerance"),
            self.tolerance,
            Limits::above(0.0, 1.0, "rad or m"),
            "",
        )
    }
}

#[cfg(test)]
mod tests {

    use crate::step::cycle::{Action, CycleConfig, StartPose};

    use planner::cleanup::CleanupPlan;

    #[test]
    fn config_round_trips_through_toml() {
        let cfg = CycleConfig {
            actions: vec![
                Action::Cleanup {
                    swing_rad: 0.1,
                    start: StartPose::Joints {
                        boom_rad: 0.2,
                        stick_rad: -1.5,
                        bucket_rad: -1.0,
                    },
                    plan: CleanupPlan {
                        start_radius_m: 7.0,
                        min_radius_m: 4.0,
                    },
                },
                Action::TrackBack { distance_m: 2.0 },
            ],
            ..CycleConfig::default()
        };
        let text = toml::to_string(&cfg).unwrap();
        let back: CycleConfig = toml::from_str(&text).unwrap();
        assert_eq!(back.actions.len(), 2);
        assert!((back.dump_swing_rad - cfg.dump_swing_rad).abs() < 1e-12);
        assert!(matches!(back.actions[1], Action::TrackBack { distance_m } if distance_m == 2.0));
        let bad = CycleConfig {
            actions: vec![Action::TrackBack { distance_m: -1.0 }],
            ..CycleConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
