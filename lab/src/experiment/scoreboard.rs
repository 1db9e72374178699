//! The scoreboard: every statement of the thesis about Tables 1, 2 and Fig. 52, with its verdict.

use super::*;

/// One line of the scoreboard: the result, one of the thesis's statements about it, and whether it
/// holds here.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Score {
    /// The thesis result and where it was reproduced, e.g. "Table 2 (dig model)".
    pub result: String,
    /// The statement.
    pub statement: String,
    /// Whether it holds.
    pub holds: bool,
}

/// The simulator's rows of Table 1, Table 2 and Fig. 52.
#[derive(Debug, Clone, PartialEq)]
pub struct SimRows {
    /// Table 1: `(stick angle, plain, with perception)`.
    pub table1: Vec<(f64, Mean, Mean)>,
    /// Table 2: `(force factor, mean)`.
    pub table2: Vec<(f64, Mean)>,
    /// Fig. 52: `(soil, hardness index, mean)`.
    pub fig52: Vec<(&'static str, f64, Mean)>,
}

/// Table 1, Table 2 and Fig. 52 in the simulator with `args`' runs, maps, plant, Table 1 reading,
/// Table 2 scaling and Fig. 52 soils.
///
/// # Errors
/// As the reproductions.
pub fn sim_rows(args: &ScoreboardArgs) -> anyhow::Result<SimRows> {
    let f52 = &args.fig52;
    let maps = f52.sim.autodig_maps()?;
    let contact = f52.sim.soil_contact.into();
    let runs = f52.sim.runs;
    Ok(SimRows {
        table1: table1_with(runs, &maps, contact, args.table1.stick_angle)?,
        table2: table2_with(
            runs,
            &maps,
            args.table2.base_scale,
            args.table2.scaling,
            contact,
        )?,
        fig52: fig52_with(runs, &maps, contact, f52.soils.pa())?,
    })
}

/// Every statement of the thesis about Table 1, Table 2 and Fig. 52, checked in the simulator (with
/// `args`' runs, maps, plant, Table 1 reading, Table 2 scaling and Fig. 52 soils) and in the dig model
/// (`args`' model and start, by default the shipped model from Table 2's start, and its Fig. 52
/// soils).
///
/// # Errors
/// As the reproductions.
pub fn scoreboard(args: &ScoreboardArgs) -> anyhow::Result<Vec<Score>> {
    let f52 = &args.fig52;
    scoreboard_of(&sim_rows(args)?, &f52.model, &f52.model_soils)
}

/// The scoreboard of the simulator's `rows` and the dig model from `model` in `model_soils`.
///
/// # Errors
/// The dig model's errors.
pub fn scoreboard_of(
    rows: &SimRows,
    model: &ModelStartArgs,
    model_soils: &ModelSoils,
) -> anyhow::Result<Vec<Score>> {
    let mut scores = Vec::new();
    let mut add = |result: &str, checks: Vec<(String, bool)>| {
        scores.extend(checks.into_iter().map(|(statement, holds)| Score {
            result: result.to_owned(),
            statement,
            holds,
        }));
    };
    let owned = |c: &[(&str, bool)]| c.iter().map(|(s, b)| ((*s).to_owned(), *b)).collect();
    add("Table 1 (simulator)", owned(&table1_checks(&rows.table1)));
    let figures = |m: &Mean| (m.time_s, m.swept_volume_m3, m.energy_kj);
    if let [(_, a), (_, b), (_, c)] = rows.table2.as_slice() {
        add(
            "Table 2 (simulator)",
            owned(&table2_checks([figures(a), figures(b), figures(c)])),
        );
    }
    add(
        "Fig. 52 (simulator)",
        fig52_checks(&rows.fig52, full_bucket_kg()?)
            .statements()
            .to_vec(),
    );
    let dig_model = model.load_model()?;
    let site = crate::model::start::default_site()?;
    let dig_start = model.start(&site)?;
    let model_rows = crate::model::table2::table2_rows(
        &dig_model,
        model.start_r,
        model.start_depth,
        model.start_bucket_deg,
    )?;
    let figures = |r: &crate::model::table2::Table2Row| (r.time_s, r.volume_m3, r.energy_kj);
    if let [a, b, c] = model_rows.as_slice() {
        add(
            "Table 2 (dig model)",
            owned(&table2_checks([figures(a), figures(b), figures(c)])),
        );
    }
    let f52_model = crate::model::fig52::checks(
        &dig_model,
        (model_soils.soft_cohesion_kpa, model_soils.hard_cohesion_kpa),
        &dig_start,
        &site,
    )?;
    add("Fig. 52 (dig model)", f52_model.statements().to_vec());
    Ok(scores)
}

/// The scoreboard as a Markdown table with the count of statements that hold.
#[must_use]
pub fn scoreboard_markdown(scores: &[Score]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from("| result | the thesis's statement | here |\n|---|---|---|\n");
    for sc in scores {
        // Writing into a String cannot fail.
        let _ = writeln!(
            s,
            "| {} | {} | {} |",
            sc.result,
            sc.statement,
            thesis_verdict(sc.holds)
        );
    }
    let _ = writeln!(
        s,
        "\n{} of {} statements hold.",
        scores.iter().filter(|sc| sc.holds).count(),
        scores.len()
    );
    s
}

pub(super) fn scoreboard_report(a: &ScoreboardArgs) -> anyhow::Result<String> {
    let table = scoreboard_markdown(&scoreboard(a)?);
    let out = &a.fig52.out.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join("scoreboard.md");
    std::fs::write(&path, &table).with_context(|| format!("writing {}", path.display()))?;
    Ok(format!(
        "The thesis's statements about Table 1, Table 2 and Fig. 52 ({} runs each in the \
         simulator; the dig model from Table 2's start)\n\n{table}\nWritten to {}\n",
        a.fig52.sim.runs,
        path.display()
    ))
}
