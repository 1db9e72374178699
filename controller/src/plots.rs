//! SVG plots of a demo session (plotters): tip trajectories per dig over the terrain section, terrain
//! elevation maps before and after, and per-dig weight, time and energy. Each function returns the SVG
//! text; [`crate::demo`] writes it.

use planner::terrain::TerrainGrid;
use plotters::prelude::*;

use crate::demo::DigRecord;

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing the plot: {e}")
}

fn color(i: usize) -> RGBColor {
    const C: [RGBColor; 8] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(23, 190, 207),
    ];
    C[i % C.len()]
}

/// Tip trajectories of every dig in the digging plane (base frame, x forward of the swing axis, z up),
/// each over the true terrain section along its plane before the dig (dashed, same colour).
///
/// # Errors
/// A plotting error (not expected for finite data).
pub fn trajectories_svg(digs: &[DigRecord]) -> anyhow::Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "bucket-tip trajectories per dig over the pre-dig terrain section (base frame)",
                ("sans-serif", 16),
            )
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(1.0..10.0, -0.5..4.5)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("x [m] (from the swing axis, along the digging plane)")
            .y_desc("z [m]")
            .draw()
            .map_err(err)?;
        for (i, d) in digs.iter().enumerate() {
            let c = color(i);
            let section: Vec<(f64, f64)> = d.section.iter().map(|p| (p.x_m, p.z_m)).collect();
            chart
                .draw_series(DashedLineSeries::new(
                    section,
                    4,
                    3,
                    c.mix(0.5).stroke_width(1),
                ))
                .map_err(err)?;
            let path: Vec<(f64, f64)> = d
                .trajectory
                .iter()
                .filter(|p| p.x_m.is_finite() && p.z_m.is_finite())
                .map(|p| (p.x_m, p.z_m))
                .collect();
            chart
                .draw_series(LineSeries::new(path, c.stroke_width(2)))
                .map_err(err)?
                .label(format!(
                    "#{} {:?} swing {:.0} deg",
                    d.index, d.action, d.swing_deg
                ))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 11))
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
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
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 680)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
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
        root.present().map_err(err)?;
    }
    Ok(svg)
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
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 720)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
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
            let mut chart = ChartBuilder::on(area)
                .caption(label, ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(28)
                .y_label_area_size(50)
                .build_cartesian_2d(-0.5..(n - 0.5), 0.0..top)
                .map_err(err)?;
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
                    let c = if d.action == crate::cycle::ActionKind::Cleanup {
                        color(1)
                    } else {
                        color(0)
                    };
                    let x = i as f64;
                    Rectangle::new([(x - 0.35, 0.0), (x + 0.35, get(d))], c.filled())
                }))
                .map_err(err)?;
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(-0.5, thesis), (n - 0.5, thesis)],
                    5,
                    4,
                    BLACK.mix(0.6).stroke_width(1),
                ))
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}
