//! The `excavator-sim` command line as a user meets it: the effect catalogue it lists, and the clear
//! errors (naming the flag or the file, exit status 1 or clap's 2) for input it cannot run with.

use std::process::{Command, Output};

fn sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_excavator-sim"))
        .args(args)
        .output()
        .expect("excavator-sim starts")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// `--list-effects --json` is the catalogue of `vcan_sim::effects`, row for row, and the table
/// names every effect.
#[test]
fn the_listed_effects_are_the_catalogue() {
    let out = sim(&["--list-effects", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let listed: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    let expected: serde_json::Value =
        serde_json::from_str(&vcan_sim::effects::registry_json().expect("catalogue as JSON"))
            .expect("catalogue JSON");
    assert_eq!(listed, expected);
    let table = sim(&["--list-effects"]);
    let text = String::from_utf8_lossy(&table.stdout);
    for row in vcan_sim::effects::registry() {
        assert!(text.contains(row.name), "{} missing from\n{text}", row.name);
    }
}

/// Input the simulator cannot run with ends it at once with a message naming what is wrong; it
/// never starts on a half-read machine.
#[test]
fn bad_input_is_refused_naming_the_flag_or_the_file() {
    let cases: [(&[&str], &str); 5] = [
        (&["--iface", "vcan0", "--effect", "bogus=1"], "bogus"),
        (
            &["--iface", "vcan0", "--effect", "transport_delay=1e9"],
            "transport_delay",
        ),
        (
            &["--iface", "vcan0", "--machine", "/nonexistent/machine.toml"],
            "/nonexistent/machine.toml",
        ),
        (&["bench", "--seconds", "1e308"], "--seconds"),
        (&[], "--iface is required"),
    ];
    for (args, named) in cases {
        let out = sim(args);
        assert!(!out.status.success(), "{args:?} ran");
        let err = stderr(&out);
        assert!(err.contains(named), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    // A typo in a flag's value is clap's usage error.
    let out = sim(&["--seed", "twelve", "--list-effects"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--seed"), "{}", stderr(&out));
}
