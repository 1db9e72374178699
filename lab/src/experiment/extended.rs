//! `experiment extended` (thesis 6.1-6.2, Tables 3-5, Fig. 60): planned sessions against the
//! thesis's extended results.

use super::*;

/// The two sessions of the extended-operation comparison (6.2).
#[derive(Debug, Clone)]
pub struct ExtendedRuns {
    /// The perception-based dig planner.
    pub planned: crate::demo::DemoSummary,
    /// The predefined excavation sequence, started at the median of the planner's starts.
    pub predefined: crate::demo::DemoSummary,
}

/// Runs a planned session of `digs` on the extended-operation bench, then the predefined sequence
/// with the median of the planner's dig starts (6.2's "virtual expert"), each written to its folder
/// under `out` (docs/demo-output.md), and the Fig. 60 plot (`out/fig60.svg`). Both sessions run with
/// the simulator seed `seed` (`None`: the bench file's).
///
/// # Errors
/// As [`crate::demo::run_session`]; no planned dig to take the median of.
pub fn extended(
    digs: u32,
    seed: Option<u64>,
    out: &std::path::Path,
    planner: Option<&std::path::Path>,
) -> anyhow::Result<ExtendedRuns> {
    use crate::demo::{DemoArgs, DemoStrategy, dig_starts, run_session};
    use anyhow::Context as _;
    let stop = std::sync::atomic::AtomicBool::new(false);
    let mut args = DemoArgs::defaults(out.join("planned"));
    args.quiet = true;
    args.digs = digs;
    args.seed = seed;
    args.planner = planner.map(std::path::Path::to_path_buf);
    args.bench_after = vec![12, digs / 2];
    let planned = run_session(&args, &stop).context("planned session")?;
    let median = controller::session::planned::median_joints(&dig_starts(&planned.digs))
        .context("the planned session made no dig to take the median start of")?;
    let mut args = DemoArgs::defaults(out.join("predefined"));
    args.quiet = true;
    args.strategy = DemoStrategy::Predefined;
    args.digs = digs;
    args.seed = seed;
    args.planner = planner.map(std::path::Path::to_path_buf);
    args.bench_after = vec![12, digs / 2];
    args.predefined_joints = Some(median);
    let predefined = run_session(&args, &stop).context("predefined session")?;
    let path = out.join("fig60.svg");
    std::fs::write(
        &path,
        crate::plots::weight_sequence_svg(&planned.digs, &predefined.digs)?,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(ExtendedRuns {
        planned,
        predefined,
    })
}

/// The comparison of [`extended`] as Tables 3-5 with the targets.
pub fn extended_markdown(runs: &ExtendedRuns) -> String {
    use std::fmt::Write as _;
    let (p, d) = (&runs.planned, &runs.predefined);
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Extended operation on \"{}\" (thesis 6.1-6.2): the dig planner and the predefined sequence\n",
        p.bench
    );
    let _ = writeln!(
        s,
        "Table 3: | strategy | digs | backups | cleanups | weight (N) | time (s) | energy (kJ) | ended |\n|---|---|---|---|---|---|---|---|"
    );
    for r in [p, d] {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.0} | {:.1} | {:.0} | {} |",
            r.strategy,
            r.totals.digs,
            r.backups,
            r.cleanups,
            r.totals.mean_weight_n,
            r.totals.mean_time_s,
            r.totals.mean_energy_kj,
            r.end
        );
    }
    let _ = writeln!(
        s,
        "| thesis test 3 | 109 | 6 | | 21300 | 7.6 | 252 | bench removed |\n"
    );
    let _ = writeln!(
        s,
        "Table 4: | strategy | dig actions: weight, time, energy | cleanup actions: weight, time, energy |\n|---|---|---|"
    );
    for r in [p, d] {
        let t = &r.stats;
        let _ = writeln!(
            s,
            "| {} | {:.0} N, {:.1} s, {:.0} kJ | {:.0} N, {:.1} s, {:.0} kJ |",
            r.strategy,
            t.dig_mean_weight_n,
            t.dig_mean_time_s,
            t.dig_mean_energy_kj,
            t.cleanup_mean_weight_n,
            t.cleanup_mean_time_s,
            t.cleanup_mean_energy_kj
        );
    }
    let _ = writeln!(
        s,
        "| thesis test 3 | 21201 N, 5.8 s, 212 kJ | 21590 N, 12.8 s, 366 kJ |\n"
    );
    let _ = writeln!(
        s,
        "Table 5 (per cycle): | strategy | weight (N) | time (s) | energy (kJ) | productivity Eq. 26 (N/s) | energy/weight Eq. 27 (J/N) |\n|---|---|---|---|---|---|"
    );
    for r in [p, d] {
        let _ = writeln!(
            s,
            "| {} | {:.0} | {:.1} | {:.0} | {:.0} | {:.2} |",
            r.strategy,
            r.totals.mean_weight_n,
            r.totals.mean_time_s,
            r.totals.mean_energy_kj,
            r.stats.productivity_n_per_s,
            1e3 * r.stats.energy_per_weight_kj_per_n
        );
    }
    let _ = writeln!(
        s,
        "| thesis planner / predefined | 23992 / 19397 | 7.5 / 6.5 | 272 / 147 | | |\n"
    );
    let gain = if d.stats.dig_mean_weight_n > 0.0 {
        100.0 * (p.stats.dig_mean_weight_n / d.stats.dig_mean_weight_n - 1.0)
    } else {
        f64::NAN
    };
    let ok = |b: bool| if b { "met" } else { "NOT met" };
    let _ = writeln!(
        s,
        "Targets of the extended run (thesis ch. 6):\n\
         - planned: {} digs (>= 100), {} backups (>= 3), no human input: {}\n\
         - buckets over half full: {:.0} % (>= 94 %; thesis test 3: 94 %): {}\n\
         - payload per normal dig, planner over predefined: {:+.0} % (>= +30 %; thesis +42 %): {}\n\
         - bucket fill over the run (Fig. 60, normal digs): planner {:.0} N first half, {:.0} N second half \
         (trend {:+.0} N/dig); predefined {:.0} N, {:.0} N (trend {:+.0} N/dig); planner does not decay: {}",
        p.totals.digs,
        p.backups,
        ok(p.totals.digs >= 100 && p.backups >= 3),
        100.0 * p.stats.over_half_full,
        ok(p.stats.over_half_full >= 0.94),
        gain,
        ok(gain >= 30.0),
        p.stats.dig_mean_weight_first_half_n,
        p.stats.dig_mean_weight_second_half_n,
        p.stats.dig_weight_slope_n_per_dig,
        d.stats.dig_mean_weight_first_half_n,
        d.stats.dig_mean_weight_second_half_n,
        d.stats.dig_weight_slope_n_per_dig,
        ok(p.stats.dig_mean_weight_second_half_n >= 0.9 * p.stats.dig_mean_weight_first_half_n)
    );
    s
}

pub(super) fn extended_report(args: &ExtendedArgs) -> anyhow::Result<String> {
    let out = args.out.out.join("extended");
    let runs = extended(args.digs, args.seed, &out, args.planner.as_deref())?;
    let text = extended_markdown(&runs);
    let path = out.join("comparison.md");
    std::fs::write(&path, &text).map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    Ok(format!(
        "{text}\nOutputs: {} (planned/, predefined/, fig60.svg, comparison.md)\n",
        out.display()
    ))
}

/// The extended run's headline figures over several seeds (`experiment results`).
#[must_use]
pub fn extended_seed_rows(runs: &[ExtendedRuns]) -> Vec<crate::results::SeedRow> {
    use crate::results::{Better, SeedRow};
    /// The planner's gain over the predefined sequence, %.
    fn gain(planned: f64, predefined: f64) -> f64 {
        if predefined > 0.0 {
            100.0 * (planned / predefined - 1.0)
        } else {
            f64::NAN
        }
    }
    type Figure = (&'static str, Better, usize, fn(&ExtendedRuns) -> f64);
    #[rustfmt::skip] // A table: one figure a line.
    let figures: [Figure; 10] = [
        ("planned: actions (digs and cleanups)", Better::Higher, 0, |r| r.planned.totals.digs as f64),
        ("planned: backups", Better::Higher, 0, |r| r.planned.backups as f64),
        ("planned: cleanups", Better::Neither, 0, |r| r.planned.cleanups as f64),
        ("planned: buckets over half full, % (target >= 94; thesis test 3: 94)", Better::Higher, 0,
            |r| 100.0 * r.planned.stats.over_half_full),
        ("payload per normal dig, planner over predefined, % (target >= +30; thesis +42)", Better::Higher, 0,
            |r| gain(r.planned.stats.dig_mean_weight_n, r.predefined.stats.dig_mean_weight_n)),
        ("weight per cycle, planner over predefined, %", Better::Higher, 0,
            |r| gain(r.planned.totals.mean_weight_n, r.predefined.totals.mean_weight_n)),
        ("planned: productivity, Eq. 26, N/s", Better::Higher, 0, |r| r.planned.stats.productivity_n_per_s),
        ("predefined: productivity, Eq. 26, N/s", Better::Neither, 0, |r| r.predefined.stats.productivity_n_per_s),
        ("planned: energy per weight, Eq. 27, J/N", Better::Lower, 2,
            |r| 1e3 * r.planned.stats.energy_per_weight_kj_per_n),
        ("planned: trend of the normal digs' weight (Fig. 60), N per dig", Better::Higher, 0,
            |r| r.planned.stats.dig_weight_slope_n_per_dig),
    ];
    figures
        .iter()
        .map(|(name, better, decimals, f)| SeedRow {
            name: (*name).to_owned(),
            values: runs.iter().map(f).collect(),
            better: *better,
            decimals: *decimals,
        })
        .collect()
}
