//! The shipped artefacts fitted on the simulated plant (`config/`) record the current plant version:
//! a change to the plant (a bump of `vcan_sim::PLANT_VERSION`, which `vcan_sim/tests/plant_version.rs`
//! forces on any change to its behaviour) cannot leave a stale calibration behind silently.

// Test helpers panic on setup failure by design (clippy only exempts `#[test]` bodies).
#![allow(clippy::unwrap_used)]

use std::path::Path;

use calibration::{ARTEFACTS, recorded_plant_version};

#[test]
fn every_shipped_calibrated_artefact_records_the_current_plant_version() {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config");
    let mut stale = Vec::new();
    for name in ARTEFACTS {
        let path = config.join(name);
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let recorded = recorded_plant_version(name, &text)
            .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        if recorded.as_deref() != Some(vcan_sim::PLANT_VERSION) {
            stale.push(format!("config/{name} records plant version {recorded:?}"));
        }
    }
    assert!(
        stale.is_empty(),
        "the default plant is version {}, but {}. Run `excavator-ctl calibrate --out DIR --install \
         config` and commit the artefacts with its calibration.md.",
        vcan_sim::PLANT_VERSION,
        stale.join("; ")
    );
}
