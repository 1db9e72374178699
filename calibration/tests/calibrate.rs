//! `excavator-ctl calibrate` end to end at a toy size: every artefact is written, parses, records
//! its origin and the plant version, and `--install` puts them into a config folder.

// Test helpers panic on setup failure by design (clippy only exempts `#[test]` bodies).
#![allow(clippy::unwrap_used)]

use calibration::{ARTEFACTS, CalibrateArgs, recorded_plant_version};

#[test]
fn a_small_calibration_writes_stamped_artefacts_and_installs_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = tempfile::tempdir().unwrap();
    let mut args = CalibrateArgs::new(dir.path().join("cal"));
    args.seed = 1;
    args.sessions = 1;
    args.digs = 4;
    args.eval_sessions = 2;
    args.eval_digs = 3;
    args.healthy_sessions = 1;
    args.healthy_digs = 6;
    // Networks from a few epochs: rough, but the hardness sweep keeps enough cases with them.
    args.train_options = [
        "--epochs",
        "20",
        "--teacher-epochs",
        "20",
        "--restarts",
        "1",
    ]
    .map(String::from)
    .to_vec();
    args.install = Some(config.path().to_path_buf());
    let report = calibration::run(&args).unwrap();

    assert_eq!(report.plant_version, vcan_sim::PLANT_VERSION);
    assert_eq!(report.sessions.len(), 4);
    assert_eq!(report.networks_fresh.len(), 2);
    assert!(report.networks_fresh.iter().all(|e| e.digs > 0));
    for v in report
        .networks_fresh_median
        .iter()
        .chain(&report.networks_fresh_worst)
    {
        assert!(v.is_finite() && *v > 0.0, "{report:?}");
    }
    assert!(report.networks_fresh_median[0] <= report.networks_fresh_worst[0]);
    for a in ARTEFACTS {
        let text = std::fs::read_to_string(config.path().join(a)).unwrap();
        assert_eq!(
            recorded_plant_version(a, &text).unwrap().as_deref(),
            Some(vcan_sim::PLANT_VERSION),
            "{a}"
        );
        assert!(text.contains("excavator-ctl calibrate --seed 1"), "{a}");
    }
    let md = std::fs::read_to_string(args.out.join("calibration.md")).unwrap();
    assert!(
        md.contains("nominal_greybox.json") && md.contains("Wall time"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(args.out.join("calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["plant_version"], vcan_sim::PLANT_VERSION);
}

#[test]
fn a_file_that_is_not_an_artefact_or_records_no_origin_is_told_apart() {
    assert!(recorded_plant_version("machine.toml", "").is_err());
    let unstamped = "intercept = 3.0\nslope_per_kn = 0.0\nmin_index = 1.0\nmax_index = 5.0\n";
    assert_eq!(
        recorded_plant_version("hardness_regression.toml", unstamped).unwrap(),
        None
    );
}
