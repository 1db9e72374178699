//! The work-cycle plan of the end-to-end tests: three digs into the default bench and a floor cleanup
//! beside it (repeated until four completed), then return home and disarm; and the machine's key both
//! ends of a session are provisioned with ([`write_key_file`]).

use std::path::{Path, PathBuf};

use controller::ControllerConfig;

/// Digs in the plan.
pub const PLAN_DIGS: usize = 3;
/// Cleanups in the plan.
pub const PLAN_CLEANUPS: usize = 1;

/// The controller config file (`excavator-ctl run --config`) of the plan.
///
/// The digs start from the default bench's start pose (tip 7.5 m out, 0.4 m above the bench top,
/// bucket opened to -55 degrees) at swing 0, -7 and 0 degrees. Four actions are asked for, repeating
/// the list: a dig or cleanup abandoned on a control fault (a move timing out, the floor not found)
/// does not count and is tried again (up to twice), so the plan goes on until four have completed. The cleanup runs at swing 65 degrees, where the whole path (radius 6.3 m down to 3.2 m)
/// lies on the bare floor in front of the bench's flank (x < 3 m or |y| > 5 m), so it probes the floor
/// and hands over to Autodig without fighting the bench. Holds and settle times are shortened to keep
/// the real-time run short; the fill is not what these tests check.
pub const PLAN_TOML: &str = r#"
[cycle]
repeat = true
max_digs = 4
retries = 2
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
start = { kind = "tip", x_m = 7.5, z_m = 2.4, bucket_abs_deg = -55.0 }

[[cycle.actions]]
kind = "dig"
swing_deg = -7.0
start = { kind = "tip", x_m = 7.5, z_m = 2.4, bucket_abs_deg = -55.0 }

[[cycle.actions]]
kind = "dig"
swing_deg = 0.0
start = { kind = "tip", x_m = 7.5, z_m = 2.4, bucket_abs_deg = -55.0 }

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

/// Safety timing for the TCG VM (appended to the plan by [`write_plan`] there). Measured in the VM on
/// the shared 2-core CI machine at load 8-9: the controller's 10 ms loop ran 60-77 steps/s with gaps
/// up to 320 ms, so the default 30 ms sensor age stopped the machine every second and the default
/// five automatic re-arms ran out before the first dig. Natively the defaults apply.
///
/// The sensor age was 0.25 s here; the controller now refuses ages beyond the gateway's 100 ms
/// watchdog (issue #23), so the VM profile uses the largest age it accepts and relies on the
/// automatic re-arms for the longer gaps: the simulation policy `auto_rearm` (as [`SIM_SAFETY_TOML`]).
pub const VM_SAFETY_TOML: &str = r#"
[safety]
sensor_max_age_s = 0.1
status_max_age_s = 0.6
arm_timeout_s = 2.0
auto_rearm = true
max_auto_rearms = 1000
"#;

/// The simulation policy of the HIL sessions run natively (appended to the plan by [`write_plan`]
/// outside the VM): they drive the simulator over vcan, on a host shared with other tests, and check
/// that a session rides through a transient fault (a spoofed frame, a false stale-sensor fault);
/// `run` accepts `auto_rearm` on a vcan only. What a real machine does after a fault (it waits for
/// the operator) is checked by the controller's and the lab's tests.
pub const SIM_SAFETY_TOML: &str = r#"
[safety]
auto_rearm = true
"#;

/// Writes the plan to `dir/plan.toml` (with [`VM_SAFETY_TOML`] and a longer move timeout inside the
/// VM) and returns the path.
///
/// # Panics
/// When the file cannot be written.
pub fn write_plan(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("plan.toml");
    let text = if crate::env::in_vm() {
        PLAN_TOML.replace("move_timeout_s = 25.0", "move_timeout_s = 60.0") + VM_SAFETY_TOML
    } else {
        PLAN_TOML.to_owned() + SIM_SAFETY_TOML
    };
    std::fs::write(&path, text).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    path
}

/// Writes a fresh random machine key (32 hex digits from `/dev/urandom`) to `dir/machine.key`, readable
/// by its owner only, as `excavator-sim --key-file` and `excavator-ctl run --key-file` require. `dir`
/// must support Unix permissions (a temporary directory, not a shared folder of the VM).
///
/// # Panics
/// When `/dev/urandom` cannot be read or the file cannot be written.
pub fn write_key_file(dir: &Path) -> PathBuf {
    use std::io::Read as _;
    use std::os::unix::fs::PermissionsExt as _;
    let mut key = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut key))
        .unwrap_or_else(|e| panic!("cannot read /dev/urandom: {e}"));
    let hex: String = key.iter().map(|b| format!("{b:02x}")).collect();
    let path = dir.join("machine.key");
    std::fs::write(&path, format!("{hex}\n"))
        .and_then(|()| std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)))
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    path
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_vm_profile_parses_with_the_plan() {
        let text = super::PLAN_TOML.to_owned() + super::VM_SAFETY_TOML;
        let config = controller::ControllerConfig::from_toml_str(&text);
        assert!(
            config.is_ok_and(|c| c.safety.max_auto_rearms == 1000 && c.safety.auto_rearm),
            "the VM profile opts in to the simulation policy"
        );
        let native = controller::ControllerConfig::from_toml_str(
            &(super::PLAN_TOML.to_owned() + super::SIM_SAFETY_TOML),
        );
        assert!(native.is_ok_and(|c| c.safety.auto_rearm));
    }
}
