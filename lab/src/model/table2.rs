//! Thesis Table 2 (4.4) with the dig model, the way the thesis made it: one start, the soil force
//! times 1, 2 and 3 (the dig model's part of `excavator-ctl experiment table2`).

use std::path::Path;

use planner::dig_model::DigModel;
use serde::{Deserialize, Serialize};

use crate::plots::{TipCurve, write_tip_paths};
use crate::thesis::{THESIS_TABLE2, table2_checks, write_checks};

use super::start::{ModelStartArgs, default_section, default_site, predicted_tip_path, tip_start};

/// One row of Table 2 as the dig model predicts it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Table2Row {
    /// Force factor.
    pub force_factor: f64,
    /// Dig time, s.
    pub time_s: f64,
    /// Swept volume, m^3.
    pub volume_m3: f64,
    /// Energy, kJ.
    pub energy_kj: f64,
}

/// Table 2 with `model` from the tip at `start_r` on the default bench.
///
/// # Errors
/// The dig model's errors.
pub fn table2_rows(
    model: &DigModel,
    start_r: f64,
    start_depth_m: f64,
    start_bucket_deg: f64,
) -> anyhow::Result<Vec<Table2Row>> {
    Ok(
        table2_predictions(model, start_r, start_depth_m, start_bucket_deg)?
            .into_iter()
            .map(|(row, _)| row)
            .collect(),
    )
}

/// [`table2_rows`] with each factor's predicted dig.
fn table2_predictions(
    model: &DigModel,
    start_r: f64,
    start_depth_m: f64,
    start_bucket_deg: f64,
) -> anyhow::Result<Vec<(Table2Row, planner::dig_model::DigPrediction)>> {
    let site = default_site()?;
    let start = tip_start(&site, start_r, start_depth_m, start_bucket_deg)?;
    let mut rows = Vec::new();
    for factor in [1.0, 2.0, 3.0] {
        let mut m = model.clone();
        m.set_force_factor(factor)?;
        let p = m.predict(&start, &site)?;
        let s = &p.summary;
        rows.push((
            Table2Row {
                force_factor: factor,
                time_s: s.time_s,
                volume_m3: s.swept_volume_m3,
                energy_kj: s.energy_kj(),
            },
            p,
        ));
    }
    Ok(rows)
}

/// Table 2 with the dig model from `start`: the table next to the thesis's, whether each of the
/// thesis's statements holds and, with `out`, the three predicted tip paths over the bench section
/// (thesis Fig. 39) in `out/fig39_model.svg`.
///
/// # Errors
/// Reading the model, the dig model's errors, writing the plot.
pub fn report(start: &ModelStartArgs, out: Option<&Path>) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let model = start.load_model()?;
    let predicted = table2_predictions(
        &model,
        start.start_r,
        start.start_depth,
        start.start_bucket_deg,
    )?;
    let rows: Vec<Table2Row> = predicted.iter().map(|(r, _)| *r).collect();
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(s, "Table 2 with the dig model ({})\n", start.describe());
    let _ = writeln!(
        s,
        "| factor | time | swept volume | energy | thesis: time, volume, energy |\n|---|---|---|---|---|"
    );
    for (r, t) in rows.iter().zip(THESIS_TABLE2) {
        let _ = writeln!(
            s,
            "| {:.1} | {:.2} s | {:.2} m^3 | {:.1} kJ | {:.1} s, {:.1} m^3, {:.0} kJ |",
            r.force_factor, r.time_s, r.volume_m3, r.energy_kj, t.1, t.2, t.3
        );
    }
    let figures = |r: &Table2Row| (r.time_s, r.volume_m3, r.energy_kj);
    if let [a, b, c] = rows.as_slice() {
        write_checks(&mut s, table2_checks([figures(a), figures(b), figures(c)]));
    }
    if let Some(dir) = out {
        let section = default_section()?;
        let curves = predicted
            .iter()
            .map(|(r, p)| TipCurve {
                label: format!(
                    "force factor {:.0}: {:.2} m^3, {:?}",
                    r.force_factor, r.volume_m3, p.summary.end
                ),
                path: predicted_tip_path(p),
                section: section.clone(),
            })
            .collect();
        let path = write_tip_paths(
            dir,
            "fig39_model.svg",
            "Fig. 39 with the dig model: the same start at three soil force levels",
            &[(String::new(), curves)],
        )?;
        let _ = writeln!(
            s,
            "\nTrajectories (the predicted tip over the bench section): {}",
            path.display()
        );
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `experiment table2` draws the three predicted digs, each over the bench section.
    #[test]
    fn table2_writes_the_three_predicted_paths() {
        let dir = tempfile::tempdir().unwrap();
        let text = report(&ModelStartArgs::default(), Some(dir.path())).unwrap();
        assert_eq!(text.matches("\n| ").count(), 4, "{text}");
        let svg = std::fs::read_to_string(dir.path().join("fig39_model.svg")).unwrap();
        for k in 1..=3 {
            assert!(svg.contains(&format!("force factor {k}:")), "{svg}");
        }
        // Three paths and three dashed sections (a dashed line is drawn as one polyline a dash).
        assert!(svg.matches("<polyline").count() >= 6, "{svg}");
    }
}
