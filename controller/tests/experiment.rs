//! The thesis reproductions (`excavator-ctl experiment`) in a reduced run: the trends that hold today.
//! Those that do not (Table 1's consistent payload with perception; Table 2's swept volume and x3
//! energy; Fig. 52's soft-soil energy) are listed in docs/autodig.md and not asserted.

#![allow(clippy::unwrap_used)]

use controller::experiment::{ExperimentArgs, Which, report, table1, table2};

/// Regression: the -87 and -70 degree starts timed out in the move to the dig (the stick swept the
/// bucket onto the bench face while the boom was still low).
#[test]
fn table1_digs_from_every_start_and_plain_payload_rises_with_reach() {
    let rows = table1(1).unwrap();
    assert_eq!(rows.len(), 3);
    for (stick, plain, with) in &rows {
        assert!(
            plain.completed == 1 && with.completed == 1,
            "{stick}: {rows:?}"
        );
    }
    // Without the enhancements the fixed beta gives more material the farther out the dig starts.
    assert!(rows[0].1.payload_kg < rows[1].1.payload_kg, "{rows:?}");
    assert!(rows[1].1.payload_kg < rows[2].1.payload_kg, "{rows:?}");
}

#[test]
fn energy_rises_from_the_nominal_soil_force() {
    let rows = table2(1).unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows.iter().all(|(_, m)| m.completed == 1), "{rows:?}");
    assert!(rows[0].1.payload_kg > 0.8 * 2550.0, "{rows:?}");
    assert!(rows[1].1.energy_kj > rows[0].1.energy_kj, "{rows:?}");
    // Autodig slows the bucket in the harder soil (thesis 4.4): the dig takes longer at x2.
    assert!(rows[1].1.time_s > rows[0].1.time_s, "{rows:?}");
    // x3 is not asserted: its energy is within the seed spread of x2's (docs/autodig.md, "Retuning
    // the Dig maps": not reproduced).
}

#[test]
fn fig52_report_prints_the_thesis_comparison() {
    let text = report(&ExperimentArgs {
        which: Which::Fig52,
        runs: 1,
        digs: 100,
        out: "out/experiment".into(),
        planner: None,
        maps: None,
        base_scale: controller::experiment::TABLE2_BASE_SCALE,
    })
    .unwrap();
    assert!(
        text.contains("| soft | 1 |") && text.contains("| hard | 5 |"),
        "{text}"
    );
    assert!(text.contains("Thesis"), "{text}");
}

/// Fig. 52's effect of the hardness index: in the hard soil the high index fills more and spends less
/// energy per kilogram than the low one; in the soft soil the low index is faster.
#[test]
fn fig52_high_index_does_better_in_hard_soil() {
    let rows = controller::experiment::fig52(1).unwrap();
    let get = |soil: &str, index: f64| {
        rows.iter()
            .find(|(s, i, _)| *s == soil && *i == index)
            .map(|r| r.2)
            .unwrap()
    };
    let (soft1, soft5) = (get("soft", 1.0), get("soft", 5.0));
    let (hard1, hard5) = (get("hard", 1.0), get("hard", 5.0));
    assert!(rows.iter().all(|(_, _, m)| m.completed == 1), "{rows:?}");
    assert!(hard5.payload_kg > 1.2 * hard1.payload_kg, "{rows:?}");
    assert!(
        hard5.energy_kj / hard5.payload_kg < hard1.energy_kj / hard1.payload_kg,
        "{rows:?}"
    );
    assert!(soft1.time_s < soft5.time_s, "{rows:?}");
    // In the soft soil the low index fills the bucket too (Fig. 52, top).
    assert!(soft1.payload_kg > 0.95 * 2550.0, "{rows:?}");
}
