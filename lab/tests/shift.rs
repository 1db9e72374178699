//! The shift under faults, short: six simulated minutes with one fault of each kind.

use lab::shift::{FaultKind, ShiftArgs, run_shift};

#[test]
fn a_short_shift_under_faults_has_no_unsafe_output_and_recovers_from_every_fault() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let args = ShiftArgs {
        hours: 6.0 / 60.0,
        seed: 2,
        faults_per_hour: 70.0,
        // Six minutes are a handful of actions: the share is not checked here.
        actions_target: 0.0,
        out: dir.path().to_path_buf(),
    };
    let report = run_shift(&args).unwrap_or_else(|e| panic!("{e:#}"));
    let text = report.markdown();
    assert_eq!(report.unsafe_outputs, 0, "{text}");
    assert_eq!(report.fault_log.len(), FaultKind::ALL.len(), "{text}");
    for row in &report.faults {
        assert_eq!(row.count, 1, "{text}");
        assert_eq!(row.detected, 1, "{:?} not detected\n{text}", row.kind);
        assert_eq!(row.recovered, 1, "{:?} not recovered\n{text}", row.kind);
    }
    assert!(
        report.faulted.actions > 0 && report.reference.actions > 0,
        "{text}"
    );
    for file in ["shift.md", "shift.json"] {
        assert!(dir.path().join(file).exists(), "{file}");
    }
}
