//! The thesis reproductions (`excavator-ctl experiment`) in a reduced run (seed 1): the trends that
//! hold on the default plant. Those that do not (Table 1's plain payload growing with reach: the plain
//! dig from the closest start already fills the bucket; Table 2's time, volume and energy from x1 to
//! x2: the x2 soil stalls the stick at relief; Fig. 52's soft-soil energy at seed 1) are listed in
//! docs/experiments.md and not asserted.

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
/// without the enhancements the fixed beta gives a longer dig the farther out the dig starts; with
/// them the payload is within 10 % across the starts (thesis 2418-2421 kg), the
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
    let top = with.iter().map(|m| m.payload_kg).fold(0.0, f64::max);
    assert!(payload_spread_kg(&with) < 0.1 * top, "{rows:?}");
    let time_spread = |m: &[Mean]| {
        let (lo, hi) = m.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), x| {
            (lo.min(x.time_s), hi.max(x.time_s))
        });
        hi - lo
    };
    assert!(time_spread(&with) < 0.5 * time_spread(&plain), "{rows:?}");
    // The report's checks say the same, except the plain payload's growth with reach: the plain dig
    // from the closest start fills the bucket too.
    let checks = lab::experiment::table1_checks(&rows);
    assert_eq!(checks.len(), 4, "{checks:?}");
    assert!(
        checks
            .iter()
            .all(|c| c.1 || c.0.contains("payload grows with reach")),
        "{checks:?}"
    );
}

/// Table 1 with the stick angles read to the horizontal: every start digs; without the enhancements
/// the fixed beta gives a longer dig the farther out the dig starts and less material from the
/// closest start; with them the payload is more consistent across the starts than without, the
/// closest start brings more than without them (thesis: 2418 against 1880 kg), and from the far start
/// the dig brings no less and is faster.
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
    // The two nearer starts may end in the same 10 ms step (4.22 s each at seed 1).
    assert!(plain[0].time_s <= plain[1].time_s, "{rows:?}");
    assert!(plain[1].time_s < plain[2].time_s, "{rows:?}");
    assert!(
        payload_spread_kg(&with) < 0.7 * payload_spread_kg(&plain),
        "{rows:?}"
    );
    assert!(with[0].payload_kg > 1.2 * plain[0].payload_kg, "{rows:?}");
    // Both may be full buckets, equal to rounding.
    assert!(
        with[2].payload_kg >= plain[2].payload_kg * (1.0 - 1e-9),
        "{rows:?}"
    );
    assert!(with[2].time_s < plain[2].time_s - 0.5, "{rows:?}");
}

/// Table 2 (thesis 4.4): every dig completes, the nominal soil nearly fills the bucket, and from x2 to
/// x3 the dig is shorter and sweeps less, as in the thesis. From x1 to x2 the thesis's time, volume
/// and energy rise; here the x2 soil stalls the stick at relief and the dig ends shallow
/// (docs/experiments.md), so that step is not asserted.
#[test]
fn table2_harder_soil_digs_shorter_from_x2_to_x3() {
    let rows = table2(1).unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows.iter().all(|(_, m)| m.completed == 1), "{rows:?}");
    assert!(
        rows[0].1.payload_kg > 0.8 * full_bucket_kg().unwrap(),
        "{rows:?}"
    );
    assert!(rows[2].1.time_s < rows[1].1.time_s, "{rows:?}");
    assert!(
        rows[2].1.swept_volume_m3 < rows[1].1.swept_volume_m3,
        "{rows:?}"
    );
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

/// Fig. 52's effect of the hardness index: in the hard soil the high index fills the bucket (>= 85 %)
/// and the low one about half (35-65 %, as in the thesis); in the soft soil the low index fills the
/// bucket and is faster.
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
    assert!(hard5.payload_kg >= 0.85 * full_kg, "{rows:?}");
    assert!(
        (0.35 * full_kg..=0.65 * full_kg).contains(&hard1.payload_kg),
        "{rows:?}"
    );
    assert!(soft1.time_s < soft5.time_s, "{rows:?}");
    // In the soft soil the low index fills the bucket too (Fig. 52, top).
    assert!(soft1.payload_kg > 0.95 * full_kg, "{rows:?}");
}

/// The scoreboard covers all 22 statements; what this project claims reproduced holds in it at seed 1:
/// Table 1 and Fig. 52 in the simulator (all four statements each), and Fig. 52 in the dig model but
/// for the hard soil's half fill at index 1 (docs/models.md, "Fig. 52"), which differs.
#[test]
fn scoreboard_shows_table1_and_fig52_reproduced() {
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
    let holds = |prefix: &str| {
        let of: Vec<_> = rows.iter().filter(|l| l.starts_with(prefix)).collect();
        assert!(!of.is_empty(), "{prefix}: {table}");
        of.iter().all(|l| l.ends_with("| as in the thesis |"))
    };
    for result in [
        "| Table 1 (simulator) |",
        "| Fig. 52 (simulator) |",
        "| Fig. 52 (dig model) |",
    ] {
        assert_eq!(rows.iter().filter(|l| l.starts_with(result)).count(), 4);
    }
    assert!(holds("| Table 1 (simulator) |"), "{table}");
    assert!(holds("| Fig. 52 (simulator) |"), "{table}");
    for statement in ["soft soil", "hard soil, index 5"] {
        assert!(
            holds(&format!("| Fig. 52 (dig model) | {statement}")),
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
