//! The plots of `model compare`: the tip paths of the simulator and the dig model per dig over the
//! pre-dig terrain (`compare.svg`), and one dig's signals over time (`dig_N.svg`, thesis Figs. 35-38).

use std::path::Path;

use planner::dig_model::DigPrediction;

use super::comparison::DigComparison;
use super::sim_dig::{SimDig, SimSample};

/// The tip paths of the simulator and the dig model per dig over the pre-dig terrain (`compare.svg`).
pub(super) fn plot_compare(
    path: &Path,
    rows: &[(SimDig, DigComparison, DigPrediction)],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("drawing {}: {e}", path.display());
    let cols = rows.len().clamp(1, 4);
    let nrows = rows.len().div_ceil(cols).max(1);
    let root = SVGBackend::new(path, (360 * cols as u32, 300 * nrows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let areas = root.split_evenly((nrows, cols));
    for ((sim, cmp, pred), area) in rows.iter().zip(areas.iter()) {
        let xs = sim
            .samples
            .iter()
            .map(|s| s.tip_x_m)
            .chain(pred.samples.iter().map(|s| s.tip_x_m));
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in xs {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        let (x0, x1) = (x0 - 1.0, x1 + 1.0);
        let zs = sim
            .samples
            .iter()
            .map(|s| s.tip_z_m)
            .chain(pred.samples.iter().map(|s| s.tip_z_m));
        let (mut z0, mut z1) = (f64::INFINITY, f64::NEG_INFINITY);
        for z in zs {
            z0 = z0.min(z);
            z1 = z1.max(z);
        }
        let (z0, z1) = (z0.min(0.0) - 0.3, z1 + 0.3);
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("dig {}: RMS {:.2} m", cmp.index, cmp.trajectory_rms_m),
                ("sans-serif", 14),
            )
            .margin(6)
            .x_label_area_size(26)
            .y_label_area_size(36)
            .build_cartesian_2d(x0..x1, z0..z1)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("r [m]")
            .y_desc("z [m]")
            .draw()
            .map_err(|e| err(&e))?;
        let n = ((x1 - x0) / 0.05).ceil() as usize;
        let terrain: Vec<(f64, f64)> = (0..=n)
            .filter_map(|k| {
                let r = x0 + k as f64 * 0.05;
                sim.profile.height_at(r).ok().map(|h| (r, h))
            })
            .collect();
        chart
            .draw_series(LineSeries::new(terrain, BLACK.mix(0.5).stroke_width(1)))
            .map_err(|e| err(&e))?
            .label("terrain before")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLACK.mix(0.5)));
        chart
            .draw_series(LineSeries::new(
                sim.samples.iter().map(|s| (s.tip_x_m, s.tip_z_m)),
                BLUE.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label("simulator")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLUE));
        chart
            .draw_series(LineSeries::new(
                pred.samples.iter().map(|s| (s.tip_x_m, s.tip_z_m)),
                RED.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label("dig model")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], RED));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 10))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// One dig over time, simulator (solid) against the model (dashed), like the thesis's Figs. 35-38:
/// Autodig commands, joint angles, head pressures, soil force magnitude (with the model's force at the
/// simulator's pose, open loop, dotted) and swept volume.
pub(super) fn plot_dig_series(
    path: &Path,
    sim: &SimDig,
    cmp: &DigComparison,
    pred: &DigPrediction,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("drawing {}: {e}", path.display());
    type Series = (Vec<(f64, f64)>, RGBColor, bool, &'static str);
    let colors = [RED, BLUE, RGBColor(0, 150, 0)];
    let names = ["boom", "stick", "bucket"];
    let t_end = sim
        .samples
        .last()
        .map_or(0.0, |s| s.time_s)
        .max(pred.samples.last().map_or(0.0, |s| s.time_s))
        .max(0.1);
    let mut panels: Vec<(&str, Vec<Series>)> = Vec::new();
    let per_joint = |sim_of: &dyn Fn(&SimSample) -> [f64; 3],
                     model_of: &dyn Fn(&planner::dig_model::DigSample) -> [f64; 3]|
     -> Vec<Series> {
        let mut v = Vec::new();
        for j in 0..3 {
            v.push((
                sim.samples
                    .iter()
                    .map(|s| (s.time_s, sim_of(s)[j]))
                    .collect(),
                colors[j],
                false,
                names[j],
            ));
            v.push((
                pred.samples
                    .iter()
                    .map(|s| (s.time_s, model_of(s)[j]))
                    .collect(),
                colors[j],
                true,
                names[j],
            ));
        }
        v
    };
    panels.push((
        "Autodig command (Fig. 35)",
        per_joint(&|s| s.command, &|s| s.command),
    ));
    panels.push((
        "joint angle [deg] (Fig. 37)",
        per_joint(&|s| s.joint_rad.map(f64::to_degrees), &|s| {
            s.joint_rad.map(f64::to_degrees)
        }),
    ));
    panels.push((
        "cylinder force [kN] (dotted: statics at the simulator's pose and soil force)",
        {
            let mut v = per_joint(&|s| s.force_n.map(|f| f * 1e-3), &|s| {
                s.force_n.map(|f| f * 1e-3)
            });
            for j in 0..3 {
                v.push((
                    sim.samples
                        .iter()
                        .filter_map(|s| s.static_force_n.map(|f| (s.time_s, f[j] * 1e-3)))
                        .collect(),
                    RGBColor(
                        colors[j].0 / 2 + 128,
                        colors[j].1 / 2 + 128,
                        colors[j].2 / 2 + 128,
                    ),
                    false,
                    "",
                ));
            }
            v
        },
    ));
    panels.push((
        "head pressure [MPa] (Fig. 38)",
        per_joint(&|s| s.head_pa.map(|p| p * 1e-6), &|s| {
            s.head_pa.map(|p| p * 1e-6)
        }),
    ));
    panels.push((
        "soil force [kN]",
        vec![
            (
                sim.samples
                    .iter()
                    .map(|s| (s.time_s, s.soil_force_n[0].hypot(s.soil_force_n[1]) * 1e-3))
                    .collect(),
                BLACK,
                false,
                "simulator",
            ),
            (
                pred.samples
                    .iter()
                    .map(|s| (s.time_s, s.soil_force.fx_n.hypot(s.soil_force.fz_n) * 1e-3))
                    .collect(),
                BLACK,
                true,
                "model",
            ),
            (
                sim.samples
                    .iter()
                    .filter_map(|s| {
                        s.model_soil_force_n
                            .map(|m| (s.time_s, m[0].hypot(m[1]) * 1e-3))
                    })
                    .collect(),
                RGBColor(200, 120, 0),
                false,
                "model at the simulator's pose",
            ),
        ],
    ));
    panels.push((
        "swept volume [m^3]",
        vec![
            (
                sim.samples
                    .iter()
                    .map(|s| (s.time_s, s.swept_volume_m3))
                    .collect(),
                BLACK,
                false,
                "simulator",
            ),
            (
                pred.samples
                    .iter()
                    .map(|s| (s.time_s, s.swept_volume_m3))
                    .collect(),
                BLACK,
                true,
                "model",
            ),
        ],
    ));
    let root = SVGBackend::new(path, (900, 230 * panels.len() as u32 + 30)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(
            &format!(
                "dig {}: simulator (solid) vs dig model (dashed); time {:+.0} %, energy {:+.0} %, volume {:+.0} %",
                cmp.index, cmp.error_percent[0], cmp.error_percent[1], cmp.error_percent[2]
            ),
            ("sans-serif", 16),
        )
        .map_err(|e| err(&e))?;
    let areas = root.split_evenly((panels.len(), 1));
    for ((title, series), area) in panels.iter().zip(areas.iter()) {
        // The 0.5-99.5 % range of the values: the simulator's soil chatter (200 Hz spikes through the
        // statics) would otherwise flatten every other curve.
        let mut ys: Vec<f64> = series
            .iter()
            .flat_map(|(pts, ..)| pts.iter().map(|p| p.1))
            .filter(|y| y.is_finite())
            .collect();
        ys.sort_by(f64::total_cmp);
        let (mut y0, mut y1) = match (ys.first(), ys.last()) {
            (Some(_), Some(_)) => {
                let at = |q: f64| ys[((ys.len() - 1) as f64 * q).round() as usize];
                (at(0.005), at(0.995))
            }
            _ => (0.0, 1.0),
        };
        if y1 <= y0 {
            (y0, y1) = (y0 - 0.5, y0 + 0.5);
        }
        let pad = 0.05 * (y1 - y0).max(1e-3);
        let mut chart = ChartBuilder::on(area)
            .caption(*title, ("sans-serif", 13))
            .margin(5)
            .x_label_area_size(22)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..t_end, (y0 - pad)..(y1 + pad))
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .draw()
            .map_err(|e| err(&e))?;
        for (pts, color, dashed, name) in series {
            let style = color.stroke_width(if *dashed { 1 } else { 2 });
            if *dashed {
                chart
                    .draw_series(DashedLineSeries::new(pts.iter().copied(), 6, 4, style))
                    .map_err(|e| err(&e))?;
            } else {
                let drawn = chart
                    .draw_series(LineSeries::new(pts.iter().copied(), style))
                    .map_err(|e| err(&e))?;
                if !name.is_empty() {
                    drawn
                        .label(*name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], style));
                }
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 10))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
