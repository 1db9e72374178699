//! The thesis reproductions (`excavator-ctl experiment`) in a reduced run: the trends that hold today.
//! Those that do not (Table 1 read to the horizontal: the perception payload from the closest start is
//! 17 % short of full, the boom's lift at the stick's relief takes the edge out of the ground; Table
//! 2's swept volume and x3 energy; Fig. 52's soft-soil energy and its hard-soil half in the simulator)
//! are listed in docs/autodig.md and not asserted.

#![allow(clippy::unwrap_used)]

use clap::Parser as _;
use lab::experiment::{
    ExperimentArgs, Mean, ResultsArgs, StickAngleReading, full_bucket_kg, report, results_page,
    table1, table2,
};

/// `excavator-ctl experiment ARGS...` as the command line parses it.
#[derive(clap::Parser)]
struct Cli {
    #[command(flatten)]
    args: ExperimentArgs,
}

/// The command line's `experiment` arguments `args`, one run each, writing into `out`.
fn args(args: &[&str], out: &std::path::Path) -> ExperimentArgs {
    let tail = ["--runs", "1", "--out", out.to_str().unwrap()];
    let line = ["experiment"].iter().chain(args).chain(&tail);
    Cli::try_parse_from(line).unwrap().args
}

fn payload_spread_kg(m: &[Mean]) -> f64 {
    let (lo, hi) = m.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), x| {
        (lo.min(x.payload_kg), hi.max(x.payload_kg))
    });
    hi - lo
}

/// Table 1 (thesis 3.2) with the stick angles read as joint angles (the default): every start digs;
/// without the enhancements the fixed beta gives a longer dig and no less material the farther out
/// the dig starts; with them the payload is within 10 % across the starts (thesis 2418-2421 kg), the
/// time varies less than half as much as without them, and every perception dig is faster than the
/// plain one from the same start (thesis: "even when the payloads were similar, the perception
/// enhancements reduced the cycle time").
#[test]
fn table1_perception_is_consistent_and_faster() {
    let rows = table1(1, StickAngleReading::Joint).unwrap();
    assert_eq!(rows.len(), 3);
    for (stick, plain, with) in &rows {
        assert!(
            plain.completed == 1 && with.completed == 1,
            "{stick}: {rows:?}"
        );
        assert!(with.time_s < plain.time_s, "{stick}: {rows:?}");
    }
    let (plain, with): (Vec<_>, Vec<_>) =
        rows.iter().map(|(_, p, w)| (p.clone(), w.clone())).unzip();
    assert!(plain[0].time_s < plain[1].time_s, "{rows:?}");
    assert!(plain[1].time_s < plain[2].time_s, "{rows:?}");
    assert!(plain[0].payload_kg <= plain[1].payload_kg, "{rows:?}");
    assert!(plain[1].payload_kg <= plain[2].payload_kg, "{rows:?}");
    let top = with.iter().map(|m| m.payload_kg).fold(0.0, f64::max);
    assert!(payload_spread_kg(&with) < 0.1 * top, "{rows:?}");
    let time_spread = |m: &[Mean]| {
        let (lo, hi) = m.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), x| {
            (lo.min(x.time_s), hi.max(x.time_s))
        });
        hi - lo
    };
    assert!(time_spread(&with) < 0.5 * time_spread(&plain), "{rows:?}");
    // The report's checks say the same.
    assert!(
        lab::experiment::table1_checks(&rows).iter().all(|c| c.1),
        "{rows:?}"
    );
}

/// Table 1 with the stick angles read to the horizontal: every start digs; without the enhancements
/// the fixed beta gives more material and a longer dig the farther out the dig starts; with them the
/// payload is more consistent across the starts than without, the closest start brings more than
/// without them (thesis: 2418 against 1880 kg), and where the payloads are alike (the far start, both
/// full) the dig is faster.
#[test]
fn table1_read_to_the_horizontal_perception_is_more_consistent() {
    let rows = table1(1, StickAngleReading::Absolute).unwrap();
    assert_eq!(rows.len(), 3);
    for (stick, plain, with) in &rows {
        assert!(
            plain.completed == 1 && with.completed == 1,
            "{stick}: {rows:?}"
        );
    }
    let (plain, with): (Vec<_>, Vec<_>) =
        rows.iter().map(|(_, p, w)| (p.clone(), w.clone())).unzip();
    assert!(plain[0].payload_kg < plain[1].payload_kg, "{rows:?}");
    // The two farther starts both fill the bucket (2550 kg, up to rounding).
    assert!(
        plain[1].payload_kg <= plain[2].payload_kg + 1e-6,
        "{rows:?}"
    );
    // The two nearer starts may end in the same 10 ms step (4.22 s each at seed 1).
    assert!(plain[0].time_s <= plain[1].time_s, "{rows:?}");
    assert!(plain[1].time_s < plain[2].time_s, "{rows:?}");
    assert!(
        payload_spread_kg(&with) < 0.7 * payload_spread_kg(&plain),
        "{rows:?}"
    );
    assert!(with[0].payload_kg > 1.2 * plain[0].payload_kg, "{rows:?}");
    assert!(
        (with[2].payload_kg - plain[2].payload_kg).abs() < 0.05 * plain[2].payload_kg,
        "{rows:?}"
    );
    assert!(with[2].time_s < plain[2].time_s - 0.5, "{rows:?}");
}

#[test]
fn energy_rises_from_the_nominal_soil_force() {
    let rows = table2(1).unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows.iter().all(|(_, m)| m.completed == 1), "{rows:?}");
    assert!(
        rows[0].1.payload_kg > 0.8 * full_bucket_kg().unwrap(),
        "{rows:?}"
    );
    assert!(rows[1].1.energy_kj > rows[0].1.energy_kj, "{rows:?}");
    // Autodig slows the bucket in the harder soil (thesis 4.4): the dig takes longer at x2.
    assert!(rows[1].1.time_s > rows[0].1.time_s, "{rows:?}");
    // x3 is not asserted: its energy is within the seed spread of x2's (docs/autodig.md, "Retuning
    // the Dig maps": not reproduced).
}

#[test]
fn fig52_report_prints_the_thesis_comparison() {
    let out = tempfile::tempdir().unwrap();
    let text = report(&args(&["fig52"], out.path())).unwrap();
    assert!(
        text.contains("| soft | 1 |") && text.contains("| hard | 5 |"),
        "{text}"
    );
    assert!(text.contains("Thesis"), "{text}");
    // The trajectory plot: both soils' panels, both indices' curves, each a drawn path.
    let svg = std::fs::read_to_string(out.path().join("fig52.svg")).unwrap();
    assert!(
        svg.contains("hard soil") && svg.contains("soft soil"),
        "{svg}"
    );
    assert_eq!(svg.matches("index 5: fill").count(), 2, "{svg}");
    assert!(svg.matches("<polyline").count() >= 8, "{svg}");
    // The dig model's section follows the simulator's, with its own figure.
    let model = text.find("## Dig model").unwrap();
    assert!(text.find("## Simulator").unwrap() < model, "{text}");
    assert!(
        text[model..].contains("Fig. 52 with the dig model"),
        "{text}"
    );
    assert!(out.path().join("fig52_model.svg").exists());
}

/// Fig. 52's effect of the hardness index: in the hard soil the high index fills the bucket and the low
/// one only partly (thesis: about half; here about 80 %), and the high index spends less energy per
/// kilogram; in the soft soil both fill and the low index is faster.
#[test]
fn fig52_high_index_does_better_in_hard_soil() {
    let rows = lab::experiment::fig52(1).unwrap();
    let full_kg = full_bucket_kg().unwrap();
    let get = |soil: &str, index: f64| {
        rows.iter()
            .find(|(s, i, _)| *s == soil && *i == index)
            .map(|r| r.2.clone())
            .unwrap()
    };
    let (soft1, soft5) = (get("soft", 1.0), get("soft", 5.0));
    let (hard1, hard5) = (get("hard", 1.0), get("hard", 5.0));
    assert!(rows.iter().all(|(_, _, m)| m.completed == 1), "{rows:?}");
    assert!(hard5.payload_kg > 1.2 * hard1.payload_kg, "{rows:?}");
    assert!(hard5.payload_kg > 0.95 * full_kg, "{rows:?}");
    assert!(hard1.payload_kg < 0.9 * full_kg, "{rows:?}");
    assert!(
        hard5.energy_kj / hard5.payload_kg < hard1.energy_kj / hard1.payload_kg,
        "{rows:?}"
    );
    assert!(soft1.time_s < soft5.time_s, "{rows:?}");
    // In the soft soil the low index fills the bucket too (Fig. 52, top).
    assert!(soft1.payload_kg > 0.95 * full_kg, "{rows:?}");
}

/// The scoreboard covers all 22 statements; what this project claims reproduced holds in it: Table 1
/// in the simulator (joint reading) and Fig. 52 in the dig model, all four statements each.
#[test]
fn scoreboard_shows_table1_and_the_dig_model_fig52_reproduced() {
    let out = tempfile::tempdir().unwrap();
    // One run of the reproductions: the report writes the table it prints to scoreboard.md.
    let text = report(&args(&["scoreboard"], out.path())).unwrap();
    let table = std::fs::read_to_string(out.path().join("scoreboard.md")).unwrap();
    assert!(text.contains(&table), "{text}");
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| result"))
        .collect();
    assert_eq!(rows.len(), 22, "{table}");
    for result in ["| Table 1 (simulator) |", "| Fig. 52 (dig model) |"] {
        let of: Vec<_> = rows.iter().filter(|l| l.starts_with(result)).collect();
        assert_eq!(of.len(), 4, "{table}");
        assert!(
            of.iter().all(|l| l.ends_with("| as in the thesis |")),
            "{table}"
        );
    }
}

/// `experiment results` on a tiny run: the header, then each section with the command that made it,
/// its date and commit, and its table.
#[test]
fn results_page_names_the_command_date_and_commit_of_every_table() {
    let dir = tempfile::tempdir().unwrap();
    let page = results_page(&ResultsArgs {
        out: dir.path().join("results.md"),
        runs: 1,
        digs: 2,
        seeds: 1,
        sessions: dir.path().to_path_buf(),
    })
    .unwrap();
    assert_eq!(page.lines().next(), Some(lab::results::HEADER), "{page}");
    let sections: Vec<&str> = page.split("\n## ").skip(1).collect();
    let titles: Vec<&str> = sections.iter().map(|s| s.lines().next().unwrap()).collect();
    for (title, command) in [
        ("The thesis's statements", "scoreboard --runs 1"),
        ("Table 1", "table1 --runs 1"),
        ("Table 2", "table2 --runs 1"),
        ("Fig. 52", "fig52 --runs 1"),
        ("Extended operation", "extended --digs 2 --seed 1"),
        ("Dig model speed", "results"),
    ] {
        let section = sections
            .iter()
            .find(|s| s.starts_with(title))
            .unwrap_or_else(|| panic!("no section {title}: {titles:?}"));
        let made = section.lines().nth(2).unwrap();
        assert!(
            made.starts_with(&format!("`excavator-ctl experiment {command}` ("))
                && made.contains(", commit "),
            "{title}: {made}"
        );
        assert!(section.contains("\n|---|"), "{title}: no table\n{section}");
    }
    assert_eq!(sections.len(), 6, "{titles:?}");
    assert!(page.contains("statements hold."), "{page}");
    assert!(
        page.contains("| figure | seed 1 | median | worst |"),
        "{page}"
    );
}
