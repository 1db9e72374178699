//! `experiment results`: the generated page docs/results.md (laid out by [`crate::results`]).

use super::*;

/// The results page: the scoreboard, Tables 1 and 2 and Fig. 52 in the simulator and the dig model,
/// the extended run over `args.seeds` seeds and the dig model's speed, each with the command that
/// prints it.
///
/// # Errors
/// As the reproductions and [`extended`].
pub fn results_page(args: &ResultsArgs) -> anyhow::Result<String> {
    use crate::results::{Page, Provenance, seeds_table};
    let runs = args.runs;
    let board = ScoreboardArgs {
        fig52: Fig52Args {
            sim: SimArgs {
                runs,
                maps: None,
                soil_contact: SoilContact::Implicit,
            },
            soils: Fig52Soils {
                soft_cohesion_kpa: FIG52_SOILS[0].1 / 1e3,
                hard_cohesion_kpa: FIG52_SOILS[1].1 / 1e3,
            },
            model: ModelStartArgs::default(),
            model_soils: ModelSoils::default(),
            out: OutArgs {
                out: args.sessions.clone(),
            },
        },
        table1: Table1Options {
            stick_angle: StickAngleReading::Joint,
        },
        table2: Table2Options {
            base_scale: TABLE2_BASE_SCALE,
            scaling: Table2Scaling::Soil,
        },
    };
    let (model, model_soils) = (&board.fig52.model, &board.fig52.model_soils);
    let rows = sim_rows(&board)?;
    let full_kg = full_bucket_kg()?;
    let mut page = Page::new(
        Provenance::now(),
        &format!(
            "The simulator runs in-process in virtual time on the default machine and benches \
             (`config/`), seeds 1..={runs}; the dig model is the shipped one \
             (`config/nominal_actuator.json`). Each section names the command that prints its \
             figures ({} build).",
            if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
        ),
    );
    let command = |which: &str| format!("excavator-ctl experiment {which} --runs {runs}");
    page.section(
        "The thesis's statements about Table 1, Table 2 and Fig. 52",
        &[command("scoreboard")],
        &scoreboard_markdown(&scoreboard_of(&rows, model, model_soils)?),
    );
    page.section(
        "Table 1 (thesis 3.2): the perception enhancements",
        &[command("table1")],
        &table1_markdown(&rows.table1, runs, board.table1.stick_angle),
    );
    page.section(
        "Table 2 (thesis 4.4): soil force x1, x2, x3",
        &[command("table2")],
        &format!(
            "### Simulator\n\n{}\n### Dig model\n\n{}",
            table2_markdown(&rows.table2, runs, &board.table2),
            crate::model::table2::report(model, None)?
        ),
    );
    page.section(
        "Fig. 52 (thesis 5.2): the soil hardness index",
        &[command("fig52")],
        &format!(
            "### Simulator\n\n{}\n### Dig model\n\n{}",
            fig52_markdown(&rows.fig52, runs, &board.fig52.soils, full_kg),
            crate::model::fig52::report(model, model_soils, None)?
        ),
    );
    let seeds: Vec<u64> = (1..=args.seeds).collect();
    let mut extended_runs = Vec::new();
    for &seed in &seeds {
        let out = args.sessions.join(format!("extended-seed-{seed}"));
        extended_runs.push(
            extended(args.digs, Some(seed), &out, None)
                .with_context(|| format!("extended run, seed {seed}"))?,
        );
    }
    page.section(
        &format!(
            "Extended operation (thesis 6.1-6.2, Tables 3-5, Fig. 60): {} digs per strategy",
            args.digs
        ),
        &seeds
            .iter()
            .map(|seed| format!("excavator-ctl experiment extended --digs {} --seed {seed}", args.digs))
            .collect::<Vec<_>>(),
        &format!(
            "The planned session and the predefined sequence (started at the median of the planned \
             starts) on the extended-operation bench; each command prints its seed's Tables 3-5.\n\n{}",
            seeds_table(&seeds, &extended_seed_rows(&extended_runs))
        ),
    );
    let speed = crate::model::speed::measure(model, 300)?;
    page.section(
        "Dig model speed (thesis 4.1)",
        &["excavator-ctl experiment results".to_owned()],
        &format!(
            "Table 2's x1 dig predicted {} times in this process; the fastest run is one the scheduler \
             did not interrupt (`cargo bench -p planner --bench dig_model` profiles the step).\n\n\
             | figure | value | target |\n|---|---|---|\n\
             | one {:.2} s dig ({} steps), fastest | {:.3} ms = {:.0}x real time | >= 10,000x |\n\
             | same, median run | {:.3} ms = {:.0}x | |\n",
            speed.runs,
            speed.dig_time_s,
            speed.steps,
            speed.fastest_s * 1e3,
            speed.real_time_factor(),
            speed.median_s * 1e3,
            speed.dig_time_s / speed.median_s
        ),
    );
    Ok(page.finish())
}

pub(super) fn results_report(args: &ResultsArgs) -> anyhow::Result<String> {
    let t0 = std::time::Instant::now();
    let page = results_page(args)?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&args.out, &page).with_context(|| format!("writing {}", args.out.display()))?;
    Ok(format!(
        "Wrote {} in {:.0} s (sessions in {})\n",
        args.out.display(),
        t0.elapsed().as_secs_f64(),
        args.sessions.display()
    ))
}
