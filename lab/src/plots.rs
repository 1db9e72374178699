//! SVG plots of a demo session (plotters): tip trajectories per dig over the terrain section, terrain
//! elevation maps before and after, and per-dig weight, time and energy. Each function returns the SVG
//! text; `demo` and the experiments write it. It draws the session records ([`onboard::record`]) and
//! nothing else of the lab.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use planner::terrain::TerrainGrid;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use onboard::record::{DigRecord, TipPoint};

use trace_tools::plot::color;
pub(crate) use trace_tools::plot::err;

/// Draws an SVG image of `size` pixels on a white background with `draw`, and returns its text.
fn svg_image(
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        draw(&root)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// Tip trajectories of every dig in the digging plane (base frame, x forward of the swing axis, z up),
/// each over the true terrain section along its plane before the dig (dashed, same colour).
///
/// # Errors
/// A plotting error (not expected for finite data).
pub fn trajectories_svg(digs: &[DigRecord]) -> anyhow::Result<String> {
    // The default bench's range, widened to the data (a cut bench lies below the ground plane).
    let zs = digs
        .iter()
        .flat_map(|d| d.trajectory.iter().chain(&d.section))
        .filter(|p| (1.0..=10.0).contains(&p.x_m) && p.z_m.is_finite())
        .map(|p| p.z_m);
    let (lo, hi) = zs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), z| {
        (a.min(z), b.max(z))
    });
    let z_lo = if lo.is_finite() {
        (lo - 0.3).min(-0.5)
    } else {
        -0.5
    };
    let z_hi = if hi.is_finite() {
        (hi + 0.5).max(4.5)
    } else {
        4.5
    };
    svg_image((900, 560), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "bucket-tip trajectories per dig over the pre-dig terrain section (base frame)",
                ("sans-serif", 16),
            )
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(1.0..10.0, z_lo..z_hi)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("x [m] (from the swing axis, along the digging plane)")
            .y_desc("z [m]")
            .draw()
            .map_err(err)?;
        for (i, d) in digs.iter().enumerate() {
            draw_tip_path(
                &mut chart,
                &d.section,
                &d.trajectory,
                color(i),
                format!("#{} {:?} swing {:.0} deg", d.index, d.action, d.swing_deg),
            )?;
        }
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        Ok(())
    })
}

/// One curve of [`tip_paths_svg`]: a dig's tip path over the terrain section it started on.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TipCurve {
    /// Legend text.
    pub label: String,
    /// The tip path, base frame.
    pub path: Vec<TipPoint>,
    /// The pre-dig terrain along the digging plane, base frame.
    pub section: Vec<TipPoint>,
}

/// Tip paths of a few digs side by side, one panel per `(title, curves)`, each curve over its pre-dig
/// terrain section (dashed, same colour), all panels on the same axes (thesis Figs. 39 and 52).
///
/// # Errors
/// A plotting error.
pub fn tip_paths_svg(title: &str, panels: &[(String, Vec<TipCurve>)]) -> anyhow::Result<String> {
    let finite = |p: &&TipPoint| p.x_m.is_finite() && p.z_m.is_finite();
    let paths = || {
        panels
            .iter()
            .flat_map(|(_, c)| c)
            .flat_map(|c| &c.path)
            .filter(finite)
    };
    let (x_lo, x_hi) = paths().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
        (a.min(p.x_m), b.max(p.x_m))
    });
    let (x_lo, x_hi) = if x_lo < x_hi {
        (x_lo - 1.0, x_hi + 1.0)
    } else {
        (1.0, 10.0)
    };
    let in_view = |p: &&TipPoint| (x_lo..=x_hi).contains(&p.x_m);
    let sections = panels
        .iter()
        .flat_map(|(_, c)| c)
        .flat_map(|c| &c.section)
        .filter(finite)
        .filter(in_view);
    let (z_lo, z_hi) = paths()
        .chain(sections)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.z_m), b.max(p.z_m))
        });
    let (z_lo, z_hi) = if z_lo < z_hi {
        (z_lo - 0.3, z_hi + 0.3)
    } else {
        (-1.0, 4.0)
    };
    let n = panels.len().max(1);
    svg_image((520 * n as u32, 480), |root| {
        let root = root.titled(title, ("sans-serif", 18)).map_err(err)?;
        for ((name, curves), area) in panels.iter().zip(root.split_evenly((1, n))) {
            let mut chart = ChartBuilder::on(&area)
                .caption(name, ("sans-serif", 14))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(45)
                .build_cartesian_2d(x_lo..x_hi, z_lo..z_hi)
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_desc("x [m] (from the swing axis)")
                .y_desc("z [m]")
                .draw()
                .map_err(err)?;
            for (i, c) in curves.iter().enumerate() {
                let section: Vec<TipPoint> = c.section.iter().filter(in_view).copied().collect();
                draw_tip_path(&mut chart, &section, &c.path, color(i), c.label.clone())?;
            }
            draw_legend(&mut chart, SeriesLabelPosition::LowerLeft)?;
        }
        Ok(())
    })
}

/// The chart type of the tip-path plots: base-frame `x` and `z`, m.
/// Writes [`tip_paths_svg`] of `panels` as `dir/name` (creating `dir`) and returns its path.
///
/// # Errors
/// Drawing, creating the folder or writing the file.
pub fn write_tip_paths(
    dir: &Path,
    name: &str,
    title: &str,
    panels: &[(String, Vec<TipCurve>)],
) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(name);
    std::fs::write(&path, tip_paths_svg(title, panels)?)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

type TipChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws one dig's tip path (solid, labelled) over its pre-dig terrain section (dashed, the same
/// colour); points that are not finite are left out.
fn draw_tip_path(
    chart: &mut TipChart<'_, '_>,
    section: &[TipPoint],
    path: &[TipPoint],
    col: RGBColor,
    label: String,
) -> anyhow::Result<()> {
    let xz = |points: &[TipPoint]| -> Vec<(f64, f64)> {
        points
            .iter()
            .filter(|p| p.x_m.is_finite() && p.z_m.is_finite())
            .map(|p| (p.x_m, p.z_m))
            .collect()
    };
    chart
        .draw_series(DashedLineSeries::new(
            xz(section),
            4,
            3,
            col.mix(0.5).stroke_width(1),
        ))
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(xz(path), col.stroke_width(2)))
        .map_err(err)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], col));
    Ok(())
}

/// The legend box of the tip-path plots.
fn draw_legend<'a, 'b: 'a>(
    chart: &mut TipChart<'a, 'b>,
    position: SeriesLabelPosition,
) -> anyhow::Result<()> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 11))
        .draw()
        .map_err(err)
}

/// A terrain elevation map (world frame, x east, y north) of the region around the machine, 0.2 m
/// cells, colour from blue (low) to red (high).
///
/// # Errors
/// A plotting error.
pub fn terrain_svg(terrain: &TerrainGrid, title: &str) -> anyhow::Result<String> {
    const X: (f64, f64) = (-4.0, 14.0);
    const Y: (f64, f64) = (-9.0, 9.0);
    const CELL: f64 = 0.2;
    const Z: (f64, f64) = (0.0, 2.5);
    svg_image((760, 680), |root| {
        let (map, legend) = root.split_horizontally(680);
        let mut chart = ChartBuilder::on(&map)
            .caption(title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(X.0..X.1, Y.0..Y.1)
            .map_err(err)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x east [m]")
            .y_desc("y north [m]")
            .draw()
            .map_err(err)?;
        let nx = ((X.1 - X.0) / CELL).round() as usize;
        let ny = ((Y.1 - Y.0) / CELL).round() as usize;
        let mut cells = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let x = X.0 + CELL * i as f64;
                let y = Y.0 + CELL * j as f64;
                if let Ok(z) = terrain.height_at(x + 0.5 * CELL, y + 0.5 * CELL) {
                    cells.push(Rectangle::new(
                        [(x, y), (x + CELL, y + CELL)],
                        heat((z - Z.0) / (Z.1 - Z.0)).filled(),
                    ));
                }
            }
        }
        chart.draw_series(cells).map_err(err)?;
        // The machine's swing axis at the start.
        chart
            .draw_series(std::iter::once(Circle::new((0.0, 0.0), 4, BLACK.filled())))
            .map_err(err)?;
        // Colour bar.
        let steps = 20;
        for k in 0..steps {
            let f = k as f64 / f64::from(steps);
            let y0 = 600 - (k * 26);
            legend
                .draw(&Rectangle::new([(20, y0 - 26), (45, y0)], heat(f).filled()))
                .map_err(err)?;
        }
        for k in 0..=5 {
            let z = Z.0 + (Z.1 - Z.0) * f64::from(k) / 5.0;
            let y = 600 - k * 104;
            legend
                .draw(&Text::new(
                    format!("{z:.1} m"),
                    (48, y - 6),
                    ("sans-serif", 11),
                ))
                .map_err(err)?;
        }
        Ok(())
    })
}

fn heat(f: f64) -> RGBColor {
    let f = if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        0.0
    };
    // Blue -> green -> yellow -> red.
    let (r, g, b) = if f < 0.33 {
        let t = f / 0.33;
        (0.1, 0.3 + 0.5 * t, 0.8 - 0.4 * t)
    } else if f < 0.66 {
        let t = (f - 0.33) / 0.33;
        (0.1 + 0.85 * t, 0.8 + 0.1 * t, 0.4 - 0.3 * t)
    } else {
        let t = (f - 0.66) / 0.34;
        (0.95, 0.9 - 0.7 * t, 0.1)
    };
    RGBColor((r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8)
}

/// Per-dig weight (kN), time (s) and energy (kJ), three panels, bars by dig number (cleanups hatched
/// in a lighter shade), with the thesis's Table 4 dig means as dashed lines.
///
/// # Errors
/// A plotting error.
pub fn dig_stats_svg(digs: &[DigRecord]) -> anyhow::Result<String> {
    svg_image((760, 720), |root| {
        let panels = root.split_evenly((3, 1));
        let n = digs.len().max(1) as f64;
        type Get = fn(&DigRecord) -> f64;
        let series: [(&str, Get, f64); 3] = [
            (
                "weight [kN] (thesis Table 4 digs: 21.2)",
                |d| d.weight_n.unwrap_or(0.0) * 1e-3,
                21.2,
            ),
            ("time [s] (thesis: 5.8)", |d| d.time_s, 5.8),
            ("energy [kJ] (thesis: 212)", |d| d.energy_kj, 212.0),
        ];
        for (area, (label, get, thesis)) in panels.iter().zip(series) {
            let top = digs.iter().map(get).fold(thesis, f64::max).max(1e-3) * 1.15;
            let mut chart = dig_panel(area, label, n, top)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_desc("dig")
                .x_labels(digs.len().clamp(2, 20))
                .x_label_formatter(&|v| format!("{:.0}", v.round()))
                .draw()
                .map_err(err)?;
            chart
                .draw_series(digs.iter().enumerate().map(|(i, d)| {
                    let x = i as f64;
                    Rectangle::new(
                        [(x - 0.35, 0.0), (x + 0.35, get(d))],
                        action_color(d).filled(),
                    )
                }))
                .map_err(err)?;
            draw_level(&mut chart, n, thesis)?;
        }
        Ok(())
    })
}

/// A chart in the coordinates of plotters' SVG drawing, both axes `f64`.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// One panel of the per-dig statistics: dig numbers `0..n` along x, `0..top` up.
fn dig_panel<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, Shift>,
    label: &str,
    n: f64,
    top: f64,
) -> anyhow::Result<Chart<'a, 'b>> {
    ChartBuilder::on(area)
        .caption(label, ("sans-serif", 14))
        .margin(8)
        .x_label_area_size(28)
        .y_label_area_size(50)
        .build_cartesian_2d(-0.5..(n - 0.5), 0.0..top)
        .map_err(err)
}

/// A dig's colour in the per-dig panels: cleanups orange, other actions blue.
fn action_color(d: &DigRecord) -> RGBColor {
    if d.action == controller::step::cycle::ActionKind::Cleanup {
        color(1)
    } else {
        color(0)
    }
}

/// A dashed level at `y` across a per-dig panel of `n` digs.
fn draw_level(chart: &mut Chart<'_, '_>, n: f64, y: f64) -> anyhow::Result<()> {
    chart
        .draw_series(DashedLineSeries::new(
            vec![(-0.5, y), (n - 0.5, y)],
            5,
            4,
            BLACK.mix(0.6).stroke_width(1),
        ))
        .map_err(err)?;
    Ok(())
}

/// The bench after some digs (thesis Fig. 55): true terrain elevation over the whole map (world frame,
/// 0.3 m cells, colour from the lowest to the highest elevation), the machine's tracks and heading.
///
/// # Errors
/// A plotting error.
pub fn bench_svg(terrain: &TerrainGrid, pose: [f64; 3], title: &str) -> anyhow::Result<String> {
    const CELL: f64 = 0.3;
    let [ox, oy] = terrain.origin();
    let res = terrain.resolution_m();
    let (x1, y1) = (
        ox + res * terrain.nx() as f64,
        oy + res * terrain.ny() as f64,
    );
    let nx = ((x1 - ox) / CELL).floor().max(1.0) as usize;
    let ny = ((y1 - oy) / CELL).floor().max(1.0) as usize;
    let mut z_lo = f64::INFINITY;
    let mut z_hi = f64::NEG_INFINITY;
    let mut samples = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let x = ox + CELL * i as f64;
            let y = oy + CELL * j as f64;
            if let Ok(z) = terrain.height_at(x + 0.5 * CELL, y + 0.5 * CELL)
                && z.is_finite()
            {
                z_lo = z_lo.min(z);
                z_hi = z_hi.max(z);
                samples.push((x, y, z));
            }
        }
    }
    if z_hi.is_nan() || z_lo.is_nan() || z_hi <= z_lo {
        z_lo = 0.0;
        z_hi = 1.0;
    }
    let width_px = 760u32;
    let height_px =
        (f64::from(width_px - 80) * (y1 - oy) / (x1 - ox)).clamp(200.0, 900.0) as u32 + 90;
    svg_image((width_px + 80, height_px), |root| {
        let (map, legend) = root.split_horizontally(width_px);
        let mut chart = ChartBuilder::on(&map)
            .caption(title, ("sans-serif", 15))
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(ox..x1, oy..y1)
            .map_err(err)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x east [m]")
            .y_desc("y north [m]")
            .draw()
            .map_err(err)?;
        chart
            .draw_series(samples.iter().map(|&(x, y, z)| {
                Rectangle::new(
                    [(x, y), (x + CELL, y + CELL)],
                    heat((z - z_lo) / (z_hi - z_lo)).filled(),
                )
            }))
            .map_err(err)?;
        // The machine: its tracks (4.45 m x 3 m footprint) and the heading.
        let [mx, my, h] = pose;
        let (c, s) = (h.cos(), h.sin());
        let corner = |a: f64, b: f64| (mx + a * c - b * s, my + a * s + b * c);
        let outline = vec![
            corner(-2.2, -1.5),
            corner(2.2, -1.5),
            corner(2.2, 1.5),
            corner(-2.2, 1.5),
            corner(-2.2, -1.5),
        ];
        chart
            .draw_series(std::iter::once(PathElement::new(
                outline,
                BLACK.stroke_width(2),
            )))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(mx, my), corner(3.5, 0.0)],
                BLACK.stroke_width(2),
            )))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(Circle::new((mx, my), 4, BLACK.filled())))
            .map_err(err)?;
        let steps = 20;
        let bar_h = (height_px.saturating_sub(140) / 20).max(5) as i32;
        for k in 0..steps {
            let f = f64::from(k) / f64::from(steps);
            let y0 = 60 + (steps - k) * bar_h;
            legend
                .draw(&Rectangle::new(
                    [(15, y0 - bar_h), (38, y0)],
                    heat(f).filled(),
                ))
                .map_err(err)?;
        }
        for k in 0..=4 {
            let z = z_lo + (z_hi - z_lo) * f64::from(k) / 4.0;
            let y = 60 + steps * bar_h - k * steps * bar_h / 4;
            legend
                .draw(&Text::new(
                    format!("{z:.1} m"),
                    (40, y - 6),
                    ("sans-serif", 11),
                ))
                .map_err(err)?;
        }
        Ok(())
    })
}

/// The statistics of a session in dig order (thesis Fig. 56): weight (kN) with the half-full line,
/// time (s) and energy (kJ); dig actions blue, cleanups orange; backups as grey vertical lines.
///
/// # Errors
/// A plotting error.
pub fn dig_sequence_svg(digs: &[DigRecord], full_bucket_n: f64) -> anyhow::Result<String> {
    svg_image((860, 760), |root| {
        let panels = root.split_evenly((3, 1));
        let n = digs.len().max(1) as f64;
        // A backup happened between two digs whose machine poses differ.
        let backups: Vec<f64> = digs
            .windows(2)
            .filter_map(|w| match (w[0].pose, w[1].pose) {
                (Some(a), Some(b)) if (a[0] - b[0]).hypot(a[1] - b[1]) > 0.2 => {
                    Some(f64::from(w[1].index) - 0.5)
                }
                _ => None,
            })
            .collect();
        type Get = fn(&DigRecord) -> f64;
        let half = 0.5 * full_bucket_n * 1e-3;
        let series: [(String, Get, Option<f64>); 3] = [
            (
                format!("weight [kN] (dashed: half full, {half:.1} kN)"),
                |d| d.weight_n.unwrap_or(0.0) * 1e-3,
                Some(half),
            ),
            ("time [s]".to_owned(), |d| d.time_s, None),
            ("energy [kJ]".to_owned(), |d| d.energy_kj, None),
        ];
        for (area, (label, get, line)) in panels.iter().zip(series) {
            let top = digs
                .iter()
                .map(get)
                .fold(line.unwrap_or(0.0), f64::max)
                .max(1e-3)
                * 1.15;
            let mut chart = dig_panel(area, &label, n, top)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_desc("dig")
                .draw()
                .map_err(err)?;
            for &b in &backups {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(b, 0.0), (b, top)],
                        BLACK.mix(0.3).stroke_width(1),
                    )))
                    .map_err(err)?;
            }
            chart
                .draw_series(
                    digs.iter()
                        .enumerate()
                        .map(|(i, d)| Circle::new((i as f64, get(d)), 3, action_color(d).filled())),
                )
                .map_err(err)?;
            if let Some(v) = line {
                draw_level(&mut chart, n, v)?;
            }
        }
        Ok(())
    })
}

/// The bucket weights of the dig actions in order for two strategies (thesis Fig. 60): the planner
/// (x) and the predefined sequence (o), each with its least-squares trend line.
///
/// # Errors
/// A plotting error.
pub fn weight_sequence_svg(
    planned: &[DigRecord],
    predefined: &[DigRecord],
) -> anyhow::Result<String> {
    let pick = |digs: &[DigRecord]| -> Vec<(f64, f64)> {
        digs.iter()
            .filter(|d| d.action == controller::step::cycle::ActionKind::Dig)
            .enumerate()
            .map(|(i, d)| (i as f64, d.weight_n.unwrap_or(0.0) * 1e-3))
            .collect()
    };
    let (a, b) = (pick(planned), pick(predefined));
    let n = a.len().max(b.len()).max(2) as f64;
    let top = a.iter().chain(&b).map(|p| p.1).fold(1.0, f64::max) * 1.15;
    let trend = |pts: &[(f64, f64)]| -> Option<Vec<(f64, f64)>> {
        let m = pts.len() as f64;
        if m < 2.0 {
            return None;
        }
        let (mx, my) = (
            pts.iter().map(|p| p.0).sum::<f64>() / m,
            pts.iter().map(|p| p.1).sum::<f64>() / m,
        );
        let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        let k = if sxx > 0.0 { sxy / sxx } else { 0.0 };
        let x1 = pts.last().map_or(0.0, |p| p.0);
        Some(vec![(0.0, my - k * mx), (x1, my + k * (x1 - mx))])
    };
    svg_image((860, 440), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "bucket weight of the normal digs in order: x planner, o predefined sequence (Fig. 60)",
                ("sans-serif", 15),
            )
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(50)
            .build_cartesian_2d(-0.5..(n - 0.5), 0.0..top)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("dig action")
            .y_desc("weight [kN]")
            .draw()
            .map_err(err)?;
        let (ca, cb) = (color(0), color(3));
        chart
            .draw_series(
                a.iter()
                    .map(|&(x, y)| Cross::new((x, y), 4, ca.stroke_width(2))),
            )
            .map_err(err)?
            .label("perception-based dig planner")
            .legend(move |(x, y)| Cross::new((x + 8, y), 4, ca.stroke_width(2)));
        chart
            .draw_series(
                b.iter()
                    .map(|&(x, y)| Circle::new((x, y), 4, cb.stroke_width(2))),
            )
            .map_err(err)?
            .label("predefined excavation sequence")
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, cb.stroke_width(2)));
        for (pts, c) in [(&a, ca), (&b, cb)] {
            if let Some(line) = trend(pts) {
                chart
                    .draw_series(DashedLineSeries::new(line, 6, 4, c.stroke_width(1)))
                    .map_err(err)?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
        Ok(())
    })
}

/// The optimal Autodig index against the average soil force (thesis Fig. 53): one point per soil
/// and terrain case, and the fitted regression line (dashed).
///
/// # Errors
/// A plotting error.
pub fn hardness_fit_svg(
    points: &[(f64, f64)],
    intercept: f64,
    slope_per_kn: f64,
) -> anyhow::Result<String> {
    let x_hi = points.iter().map(|p| p.0).fold(1.0, f64::max) * 1.1;
    svg_image((760, 480), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "optimal Autodig hardness index vs average soil force (Fig. 53)",
                ("sans-serif", 15),
            )
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..x_hi, 0.0..5.5)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("average soil force |F(Gamma_typical)| [kN] (Eq. 25)")
            .y_desc("optimal index")
            .draw()
            .map_err(err)?;
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                    .map(|&(x, y)| Circle::new((x, y), 3, color(0).filled())),
            )
            .map_err(err)?;
        chart
            .draw_series(DashedLineSeries::new(
                vec![(0.0, intercept), (x_hi, intercept + slope_per_kn * x_hi)],
                6,
                4,
                BLACK.stroke_width(2),
            ))
            .map_err(err)?;
        Ok(())
    })
}

/// The refined planner's evaluated candidate grid of one region (thesis Figs. 47/48). Left: the
/// terrain section along the region's centre line (base frame), the floor, and the start tip of every
/// evaluated candidate coloured by its quality, the chosen start circled. Right: the grid of candidates
/// `(d, alpha)` (Fig. 45), each cell coloured by its Fig. 46 quality (green low, red high, out of
/// `max_quality`), vetoed ones (a zero factor) light grey, floor-penetrating ones dark blue (as in the
/// thesis), unreachable ones white, ones curled past the start limit lilac, ones the dig model could
/// not predict black; the chosen dig outlined.
///
/// # Errors
/// A plotting error; an empty grid.
pub fn refined_grid_svg(
    plan: &planner::plan::refined::RefinedPlan,
    floor_z_m: f64,
    max_quality: f64,
    title: &str,
) -> anyhow::Result<String> {
    use planner::plan::refined::CandidateStatus;
    let (Some(&d_last), Some(&a0), Some(&a1)) = (
        plan.d_values_m.last(),
        plan.alpha_values_rad.first(),
        plan.alpha_values_rad.last(),
    ) else {
        anyhow::bail!("refined plan without candidates");
    };
    let d_step = plan
        .d_values_m
        .get(1)
        .map_or(0.2, |d1| d1 - plan.d_values_m[0]);
    let a_step = plan
        .alpha_values_rad
        .get(1)
        .map_or(5f64.to_radians(), |x| x - a0)
        .to_degrees();
    let (a0, a1) = (a0.to_degrees(), a1.to_degrees());
    let max_q = if max_quality > 0.0 { max_quality } else { 6.0 };
    // Quality -> green (0) .. red (max): the upper two thirds of the heat scale, so no blue.
    let q_color = |q: f64| heat(0.33 + 0.67 * (q / max_q).clamp(0.0, 1.0));
    let floor_blue = RGBColor(30, 40, 150);
    let vetoed = RGBColor(205, 205, 205);
    let curled = RGBColor(200, 170, 230);
    let best = plan
        .best
        .as_ref()
        .map(|b| (b.d_m, b.alpha_rad.to_degrees()));
    svg_image((1100, 520), |root| {
        let root = root.titled(title, ("sans-serif", 16)).map_err(err)?;
        let (left, right) = root.split_horizontally(520);

        // Left: section and start tips.
        let r0 = plan.section.first().map_or(0.0, |p| p[0]);
        let r1 = plan.section.last().map_or(1.0, |p| p[0]).max(r0 + 1.0);
        let zs = plan.section.iter().map(|p| p[1]).chain([floor_z_m]);
        let zmin = zs.clone().fold(f64::INFINITY, f64::min) - 0.3;
        let zmax = zs.fold(f64::NEG_INFINITY, f64::max) + 0.3;
        let mut chart = ChartBuilder::on(&left)
            .caption(
                format!(
                    "section at swing {:.1} deg, starts (d from {:.1} m)",
                    plan.region.swing_rad.to_degrees(),
                    plan.region.near_r_m
                ),
                ("sans-serif", 13),
            )
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(44)
            .build_cartesian_2d(r0..r1, zmin..zmax)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("r [m] from the swing axis")
            .y_desc("z [m]")
            .draw()
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(
                plan.section.iter().map(|p| (p[0], p[1])),
                BLACK.stroke_width(2),
            ))
            .map_err(err)?
            .label("terrain (planner's map)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(2)));
        chart
            .draw_series(DashedLineSeries::new(
                vec![(r0, floor_z_m), (r1, floor_z_m)],
                5,
                4,
                floor_blue.stroke_width(1),
            ))
            .map_err(err)?
            .label("floor")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], floor_blue));
        chart
            .draw_series(plan.candidates.iter().filter_map(|c| {
                let q = c.quality?.quality;
                (q > 0.0).then(|| Circle::new((c.pose.x_m, c.pose.z_m), 3, q_color(q).filled()))
            }))
            .map_err(err)?;
        if let Some(b) = &plan.best {
            chart
                .draw_series(std::iter::once(Circle::new(
                    (b.pose.x_m, b.pose.z_m),
                    8,
                    BLACK.stroke_width(2),
                )))
                .map_err(err)?
                .label(format!(
                    "chosen: d {:.1} m, alpha {:.0} deg, V {:.2} m^3, Q {:.2}",
                    b.d_m,
                    b.alpha_rad.to_degrees(),
                    b.summary.swept_volume_m3,
                    b.quality.quality
                ))
                .legend(|(x, y)| Circle::new((x + 8, y), 5, BLACK.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .position(SeriesLabelPosition::LowerRight)
            .label_font(("sans-serif", 11))
            .draw()
            .map_err(err)?;

        // Right: the (d, alpha) grid.
        let mut chart = ChartBuilder::on(&right)
            .caption(
                format!(
                    "candidates: quality 0..{max_q:.0} green..red; grey vetoed, blue floor, white unreachable, lilac curled, black model failed"
                ),
                ("sans-serif", 12),
            )
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(44)
            .build_cartesian_2d(
                -0.5 * d_step..d_last + 0.5 * d_step,
                (a0 - 0.5 * a_step)..(a1 + 0.5 * a_step),
            )
            .map_err(err)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("d [m] from the region's near boundary")
            .y_desc("alpha [deg] from the surface normal")
            .draw()
            .map_err(err)?;
        chart
            .draw_series(plan.candidates.iter().map(|c| {
                let fill = match (c.status, c.quality) {
                    (CandidateStatus::Valid, Some(q)) if q.quality > 0.0 => q_color(q.quality),
                    (CandidateStatus::Valid, _) => vetoed,
                    (CandidateStatus::PenetratesFloor, _) => floor_blue,
                    (CandidateStatus::Unreachable, _) => WHITE,
                    (CandidateStatus::ModelFailed, _) => BLACK,
                    (CandidateStatus::CurledStart, _) => curled,
                };
                let a = c.alpha_rad.to_degrees();
                Rectangle::new(
                    [
                        (c.d_m - 0.45 * d_step, a - 0.45 * a_step),
                        (c.d_m + 0.45 * d_step, a + 0.45 * a_step),
                    ],
                    fill.filled(),
                )
            }))
            .map_err(err)?;
        chart
            .draw_series(plan.candidates.iter().map(|c| {
                let a = c.alpha_rad.to_degrees();
                Rectangle::new(
                    [
                        (c.d_m - 0.45 * d_step, a - 0.45 * a_step),
                        (c.d_m + 0.45 * d_step, a + 0.45 * a_step),
                    ],
                    BLACK.mix(0.15).stroke_width(1),
                )
            }))
            .map_err(err)?;
        if let Some((d, a)) = best {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [
                        (d - 0.5 * d_step, a - 0.5 * a_step),
                        (d + 0.5 * d_step, a + 0.5 * a_step),
                    ],
                    BLACK.stroke_width(3),
                )))
                .map_err(err)?;
        }
        Ok(())
    })
}
