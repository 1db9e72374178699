//! The example controller config the package installs (packaging/controller.toml) loads with the
//! real loader, and the defaults it spells out are the code's.

use controller::config::ControllerConfig;
use controller::step::cycle::ActionKind;
use controller::step::safety::SafetyConfig;

/// The example, as the package ships it.
const EXAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../packaging/controller.toml");

#[test]
fn the_packaged_example_config_loads_and_states_the_true_defaults() {
    let config = ControllerConfig::from_toml_file(std::path::Path::new(EXAMPLE))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(config.safety, SafetyConfig::default());
    let kinds: Vec<ActionKind> = config.cycle.actions.iter().map(|a| a.kind()).collect();
    assert_eq!(
        kinds,
        [
            ActionKind::Dig,
            ActionKind::Dig,
            ActionKind::Cleanup,
            ActionKind::TrackBack
        ]
    );
    assert_eq!(config.cycle.max_digs, Some(3));
    assert!(!config.cycle.repeat);
    let default = ControllerConfig::default().cycle;
    assert_eq!(config.cycle.dump_swing_rad, default.dump_swing_rad);
    assert_eq!(config.cycle.scan_timeout_s, default.scan_timeout_s);
    assert_eq!(config.security.key_file, None);
}

/// `/dev/zero` as `--config` once grew without bound (24 GB, then the OOM killer): refused at once.
#[cfg(unix)]
#[test]
fn dev_zero_as_the_config_is_refused_at_once() {
    let started = std::time::Instant::now();
    let e = ControllerConfig::from_toml_file(std::path::Path::new("/dev/zero"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/dev/zero"), "{e}");
    assert!(started.elapsed() < std::time::Duration::from_secs(1), "{e}");
}
