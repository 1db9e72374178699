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

/// Safety timing for the TCG VM: `config/vm.toml`, the file the README's vcan section gives `run` in
/// a VM (appended to the plan by [`write_plan`] there). Natively the defaults apply.
pub const VM_SAFETY_TOML: &str = include_str!("../../config/vm.toml");

/// The simulation policy of the HIL sessions run natively (merged over the plan by [`write_plan`]
/// outside the VM): they drive the simulator over vcan on a host shared with other tests, and check
/// that a session rides through a transient fault (a spoofed frame, a false stale-sensor fault).
/// `run` accepts `auto_rearm` on a virtual CAN only. What a real machine does after a fault (it
/// waits for the operator) is checked by the controller's and the lab's tests.
pub const SIM_SAFETY_TOML: &str = "[safety]\nauto_rearm = true\n";

/// `plan` (a controller config file) with the keys of [`VM_SAFETY_TOML`] over its own, table by table.
///
/// # Panics
/// When either does not parse as TOML (a bug in this file or in `config/vm.toml`).
pub fn with_vm_timing(plan: &str) -> String {
    overlay(plan, "config/vm.toml", VM_SAFETY_TOML)
}

/// `plan` with the keys of `over` (named `name` in panics) over its own, table by table: appending
/// the two files would repeat a table, which TOML refuses.
fn overlay(plan: &str, name: &str, over: &str) -> String {
    let parse = |name: &str, text: &str| {
        text.parse::<toml::Table>()
            .unwrap_or_else(|e| panic!("{name} is not TOML: {e}"))
    };
    let mut merged = parse("the plan", plan);
    for (section, keys) in parse(name, over) {
        let toml::Value::Table(keys) = keys else {
            panic!("{name}: `{section}` is not a table")
        };
        let entry = merged
            .entry(section)
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let toml::Value::Table(table) = entry {
            table.extend(keys);
        }
    }
    toml::to_string(&merged).unwrap_or_else(|e| panic!("the merged plan: {e}"))
}

/// Writes the plan to `dir/plan.toml` (with [`VM_SAFETY_TOML`] and a longer move timeout inside the
/// VM, with [`SIM_SAFETY_TOML`] natively) and returns the path.
///
/// # Panics
/// When the file cannot be written.
pub fn write_plan(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("plan.toml");
    let text = if crate::env::in_vm() {
        with_vm_timing(&PLAN_TOML.replace("move_timeout_s = 25.0", "move_timeout_s = 60.0"))
    } else {
        overlay(PLAN_TOML, "SIM_SAFETY_TOML", SIM_SAFETY_TOML)
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
        let text = super::with_vm_timing(super::PLAN_TOML);
        let config = controller::ControllerConfig::from_toml_str(&text).unwrap();
        assert_eq!(config.safety.max_auto_rearms, 1000);
        assert!((config.cycle.scan_timeout_s - 30.0).abs() < 1e-12);
        // The plan's own keys stay where the VM file says nothing.
        assert_eq!(config.cycle.max_digs, Some(4));
        // The VM opts in to the simulation policy; so do the native sessions.
        assert!(
            config.safety.auto_rearm,
            "config/vm.toml opts in to auto_rearm"
        );
        let native = super::overlay(super::PLAN_TOML, "sim", super::SIM_SAFETY_TOML);
        let native = controller::ControllerConfig::from_toml_str(&native).unwrap();
        assert!(native.safety.auto_rearm);
        assert_eq!(native.cycle.max_digs, Some(4));
        // And the file alone, as `run --config config/vm.toml` reads it.
        assert!(controller::ControllerConfig::from_toml_str(super::VM_SAFETY_TOML).is_ok());
    }
}
