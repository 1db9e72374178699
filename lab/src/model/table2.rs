//! `excavator-ctl model table2`: thesis Table 2 (4.4) with the dig model, the way the thesis made it:
//! one start, the soil force times 1, 2 and 3.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use planner::dig_model::DigModel;
use serde::{Deserialize, Serialize};

use crate::thesis::{THESIS_TABLE2, table2_checks, thesis_verdict};

use super::start::{ModelStartArgs, default_section, default_site, predicted_tip_path, tip_start};

/// Arguments of `model table2`.
#[derive(Debug, Args)]
pub struct Table2Args {
    /// The model and its start.
    #[command(flatten)]
    pub start: ModelStartArgs,
    /// Also write the three predicted tip paths over the bench section (thesis Fig. 39) to
    /// `DIR/fig39_model.svg`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

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

/// Runs `model table2`.
///
/// # Errors
/// Reading the model, the dig model's errors, writing the plot.
pub fn run(a: &Table2Args) -> anyhow::Result<()> {
    let model = a.start.load_model()?;
    let predicted = table2_predictions(
        &model,
        a.start.start_r,
        a.start.start_depth,
        a.start.start_bucket_deg,
    )?;
    let rows: Vec<Table2Row> = predicted.iter().map(|(r, _)| *r).collect();
    println!("Table 2 with the dig model ({})", a.start.describe());
    println!(
        "  force factor  time [s]  volume [m^3]  energy [kJ]   | thesis: time  volume  energy"
    );
    for (r, t) in rows.iter().zip(THESIS_TABLE2) {
        println!(
            "  {:>12.1}  {:>8.2}  {:>12.2}  {:>11.1}   |        {:>5.1}  {:>6.1}  {:>6.0}",
            r.force_factor, r.time_s, r.volume_m3, r.energy_kj, t.1, t.2, t.3
        );
    }
    let figures = |r: &Table2Row| (r.time_s, r.volume_m3, r.energy_kj);
    for (statement, ok) in table2_checks([figures(&rows[0]), figures(&rows[1]), figures(&rows[2])])
    {
        println!("  {statement}: {}", thesis_verdict(ok));
    }
    if let Some(dir) = &a.out {
        let section = default_section()?;
        let curves = predicted
            .iter()
            .map(|(r, p)| crate::plots::TipCurve {
                label: format!(
                    "force factor {:.0}: {:.2} m^3, {:?}",
                    r.force_factor, r.volume_m3, p.summary.end
                ),
                path: predicted_tip_path(p),
                section: section.clone(),
            })
            .collect();
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join("fig39_model.svg");
        std::fs::write(
            &path,
            crate::plots::tip_paths_svg(
                "Fig. 39 with the dig model: the same start at three soil force levels",
                &[(String::new(), curves)],
            )?,
        )
        .with_context(|| format!("writing {}", path.display()))?;
        println!("  trajectories: {}", path.display());
    }
    let mut out = std::io::stdout().lock();
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `model table2 --out DIR` draws the three predicted digs, each over the bench section.
    #[test]
    fn table2_writes_the_three_predicted_paths() {
        let dir = tempfile::tempdir().unwrap();
        run(&Table2Args {
            start: ModelStartArgs::default(),
            out: Some(dir.path().to_path_buf()),
        })
        .unwrap();
        let svg = std::fs::read_to_string(dir.path().join("fig39_model.svg")).unwrap();
        for k in 1..=3 {
            assert!(svg.contains(&format!("force factor {k}:")), "{svg}");
        }
        // Three paths and three dashed sections (a dashed line is drawn as one polyline a dash).
        assert!(svg.matches("<polyline").count() >= 6, "{svg}");
    }
}
