//! Extended operation (thesis ch. 6): the planned session on the extended-operation bench
//! (`config/bench_extended.toml`) digs, cleans up and tracks back with no human input.

#![allow(clippy::unwrap_used)]

#[path = "support/markdown.rs"]
mod markdown;

use std::sync::atomic::AtomicBool;

use controller::step::cycle::ActionKind;
use lab::demo::{DemoArgs, DemoStrategy, run_session};

/// A short planned session: the planner digs, and once the face within reach is used up it backs up
/// (Fig. 42), all from the scans, in one process. (It cleans up when no dig reaches the quality
/// minimum and tracking is blocked by material near the tracks; since each bucket pass is carved
/// into the map and starts are approached 0.8 m up, the digs leave none: 0 cleanups in 25 digs here
/// and in 100 on the 2 m bench. The choice is tested in `planner::plan::{action, cleanup_track}`,
/// the cleanup itself in `closed_loop.rs`; the predefined sequence cleans up 47 times in the 100-dig
/// comparison, `excavator-ctl experiment extended --digs 100`.)
#[test]
fn planned_session_digs_and_backs_up() {
    let dir = tempfile::tempdir().unwrap();
    // The extended bench with a 1 m cut (floor 1 m below the tracks): half the material per metre
    // of face, so the first backup comes within a short session.
    let bench = dir.path().join("bench.toml");
    let text = lab::demo::EXTENDED_BENCH_TOML
        .replace("height_m = 2.0", "height_m = 1.0")
        .replace("floor_elevation_m = -2.0", "floor_elevation_m = -1.0");
    std::fs::write(&bench, text).unwrap();
    let mut args = DemoArgs::defaults(dir.path().join("planned"));
    args.bench = Some(bench);
    args.digs = 25;
    let s = run_session(&args, &AtomicBool::new(false)).unwrap();
    assert_eq!(s.strategy, "planned");
    let digs = s
        .digs
        .iter()
        .filter(|d| d.action == ActionKind::Dig)
        .count();
    assert!(digs >= 8, "{digs} digs: {}", s.end);
    assert!(s.backups >= 1, "no backup: {}", s.end);
    // Planned digs carry the planner's predicted quality and start, and the machine moved back.
    let first = s.digs.iter().find(|d| d.action == ActionKind::Dig).unwrap();
    assert!(first.quality.is_some_and(|q| q > 0.0) && first.planned_start.is_some());
    let xs: Vec<f64> = s.digs.iter().filter_map(|d| d.pose.map(|p| p[0])).collect();
    assert!(
        xs.iter().copied().fold(f64::INFINITY, f64::min) < -0.4,
        "{xs:?}"
    );
    // Digs into the fresh face fill the bucket: some over half of the 25 kN full bucket.
    let weights: Vec<f64> = s.digs.iter().filter_map(|d| d.weight_n).collect();
    assert!(
        weights.iter().any(|&w| w > 0.5 * s.stats.full_bucket_n),
        "{weights:?}"
    );
    let out = dir.path().join("planned");
    for f in [
        "summary.json",
        "summary.md",
        "dig_sequence.svg",
        "map_after.svg",
        "last_plan.json",
        "refined_grid.svg",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    for k in ["strategy", "backups", "cleanups"] {
        assert!(json.get(k).is_some(), "{k}");
    }
    assert!(json["digs"][0].get("quality").is_some());
    markdown::assert_tables_render(&std::fs::read_to_string(out.join("summary.md")).unwrap());
}

/// The predefined sequence (6.2) from given start joints: digs swing across the regions.
#[test]
fn predefined_sequence_runs_from_fixed_joints() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = DemoArgs::defaults(dir.path().join("predefined"));
    args.strategy = DemoStrategy::Predefined;
    args.digs = 3;
    args.predefined_joints = Some(planner::kinematics::JointAngles {
        boom_rad: 8f64.to_radians(),
        stick_rad: (-72f64).to_radians(),
        bucket_rad: (-50f64).to_radians(),
    });
    let s = run_session(&args, &AtomicBool::new(false)).unwrap();
    assert_eq!(s.strategy, "predefined");
    assert_eq!(s.digs.len(), 3, "{}", s.end);
    assert!(s.predefined_start_deg.is_some());
    let swings: Vec<f64> = s.digs.iter().map(|d| d.swing_deg).collect();
    assert!(swings.windows(2).all(|w| w[1] > w[0]), "{swings:?}");
}
