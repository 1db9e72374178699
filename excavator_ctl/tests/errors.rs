//! Error messages a user meets first, pinned: one line, the cause once, the file, line and field.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::process::{Command, Output};

fn ctl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_excavator-ctl"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap()
}

/// `demo --effect typo` pointed to `--list-effects`, which `demo` lacked; `demo --list-effects`
/// prints the simulator's catalogue.
#[test]
fn demo_effect_errors_point_to_demos_own_list_of_effects() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let o = ctl(&[
        "demo",
        "--digs",
        "1",
        "--effect",
        "typo=1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("unknown effect `typo` (see --list-effects)"),
        "{err}"
    );
    let o = ctl(&["demo", "--list-effects"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        String::from_utf8_lossy(&o.stdout),
        vcan_sim::effects::registry_table()
    );
}

/// A profile whose DBC is missing: one line naming the profile's file and line, the cause once.
#[test]
fn a_missing_profile_dbc_is_one_line_naming_the_profile() {
    let dir = tempfile::tempdir().unwrap();
    let profile = dir.path().join("p.toml");
    let example = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/other_gateway.toml"
    );
    let text = std::fs::read_to_string(example).unwrap();
    let dbc_line = text.lines().position(|l| l.starts_with("dbc =")).unwrap() + 1;
    std::fs::write(&profile, text.replace("other_gateway.dbc", "gone.dbc")).unwrap();
    let log = dir.path().join("t.log");
    std::fs::write(&log, "(1.000000) vcan0 123#00\n").unwrap();
    let o = ctl(&[
        "trace",
        "stats",
        log.to_str().unwrap(),
        "--profile",
        profile.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        err.trim_end(),
        format!(
            "error: {}:{dbc_line}: dbc = \"gone.dbc\": cannot read {}: No such file or directory (os error 2)",
            profile.display(),
            dir.path().join("gone.dbc").display()
        )
    );
}
