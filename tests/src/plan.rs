//! The work-cycle plan of the end-to-end tests: three digs into the default bench and a floor cleanup
//! beside it, one pass, then return home and disarm.

use controller::node::ControllerConfig;

/// Digs in the plan.
pub const PLAN_DIGS: usize = 3;
/// Cleanups in the plan.
pub const PLAN_CLEANUPS: usize = 1;

/// The controller config file (`excavator-ctl run --config`) of the plan.
///
/// The digs are the default bench's (tip 7 m out, 0.8 m above the bench top, at swing 0, -7 and 0
/// degrees; at +7 degrees the move to the dig currently times out with the stick 0.034 rad from its
/// target, outside the 0.03 rad tolerance). The cleanup runs at swing 65 degrees, where the whole path (radius 6.3 m down to 3.2 m)
/// lies on the bare floor in front of the bench's flank (x < 3 m or |y| > 5 m), so it probes the floor
/// and hands over to Autodig without fighting the bench. Holds and settle times are shortened to keep
/// the real-time run short; the fill is not what these tests check.
pub const PLAN_TOML: &str = r#"
[cycle]
repeat = false
move_timeout_s = 25.0
dump_swing_deg = -90.0
dump_hold_s = 0.5
weigh_settle_s = 0.4
weigh_window_s = 0.2
scan = true
scan_timeout_s = 3.0
# The start pose only needs to be near: Boom-Down starts from there. 0.05 rad instead of 0.03.
joint = { kp = 2.0, max_command = 0.8, min_command = 0.2, tolerance = 0.05 }

[[cycle.actions]]
kind = "dig"
swing_deg = 0.0
start = { kind = "tip", x_m = 7.0, z_m = 2.8, bucket_abs_deg = -90.0 }

[[cycle.actions]]
kind = "dig"
swing_deg = -7.0
start = { kind = "tip", x_m = 7.0, z_m = 2.8, bucket_abs_deg = -90.0 }

[[cycle.actions]]
kind = "dig"
swing_deg = 0.0
start = { kind = "tip", x_m = 7.0, z_m = 2.8, bucket_abs_deg = -90.0 }

[[cycle.actions]]
kind = "cleanup"
swing_deg = 65.0
start = { kind = "tip", x_m = 6.3, z_m = 0.8, bucket_abs_deg = -150.0 }
plan = { start_radius_m = 6.3, min_radius_m = 3.2 }
"#;

/// The plan as a [`ControllerConfig`].
///
/// # Panics
/// If [`PLAN_TOML`] does not parse (a bug in this file).
pub fn plan_config() -> ControllerConfig {
    ControllerConfig::from_toml_str(PLAN_TOML)
        .unwrap_or_else(|e| panic!("the HIL plan does not parse: {e}"))
}

/// Writes [`PLAN_TOML`] to `dir/plan.toml` and returns the path.
///
/// # Panics
/// When the file cannot be written.
pub fn write_plan(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("plan.toml");
    std::fs::write(&path, PLAN_TOML)
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    path
}
