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

pub(crate) use trace_tools::plot::err;
use trace_tools::plot::{LegendMark, color, draw_legend_column, tick_label};

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
/// each over the true terrain section along its plane before the dig (thin, faint, same colour),
/// coloured by dig number on the heat scale with its colour bar beside the chart. Each curve is
/// decimated to at most [`MAX_CURVE_POINTS`] points for the picture.
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
    let (first, last) = match (digs.first(), digs.last()) {
        (Some(a), Some(b)) => (f64::from(a.index), f64::from(b.index)),
        _ => (0.0, 1.0),
    };
    let dig_colour = |index: u32| {
        if last > first {
            heat((f64::from(index) - first) / (last - first))
        } else {
            heat(0.0)
        }
    };
    const WIDTH: u32 = 960;
    const HEIGHT: u32 = 560;
    svg_image((WIDTH, HEIGHT), |root| {
        let (plot, strip) = root.split_horizontally(WIDTH - COLOUR_BAR_STRIP_PX);
        let mut chart = ChartBuilder::on(&plot)
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
            .x_label_formatter(&tick_label)
            .y_label_formatter(&tick_label)
            .draw()
            .map_err(err)?;
        let xz = |points: &[TipPoint]| -> Vec<(f64, f64)> {
            let finite: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| p.x_m.is_finite() && p.z_m.is_finite())
                .map(|p| (p.x_m, p.z_m))
                .collect();
            decimate(&finite, MAX_CURVE_POINTS)
        };
        for d in digs {
            let c = dig_colour(d.index);
            chart
                .draw_series(LineSeries::new(xz(&d.section), c.mix(0.35).stroke_width(1)))
                .map_err(err)?;
            chart
                .draw_series(LineSeries::new(xz(&d.trajectory), c.stroke_width(2)))
                .map_err(err)?;
        }
        let (_, strip_h) = strip.dim_in_pixel();
        let (bar, key) = strip.split_vertically(strip_h.saturating_sub(90));
        draw_colour_bar(&bar, HEIGHT - 90, "dig number", (first, last), &|v| {
            format!("{:.0}", v.round())
        })?;
        draw_legend_column(
            &key,
            &[
                ("tip path".to_owned(), BLACK, LegendMark::Line),
                (
                    "terrain before".to_owned(),
                    RGBColor(170, 170, 170),
                    LegendMark::Line,
                ),
            ],
        )
    })
}

/// The most points of one curve in a session plot (the curves' shapes need no more at this size).
pub const MAX_CURVE_POINTS: usize = 240;

/// At most `max` of `points`, evenly spaced and keeping the first and the last.
fn decimate<T: Copy>(points: &[T], max: usize) -> Vec<T> {
    let max = max.max(2);
    if points.len() <= max {
        return points.to_vec();
    }
    let last = points.len() - 1;
    (0..max).map(|k| points[k * last / (max - 1)]).collect()
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

/// The colour scale of the elevation maps: the elevations its ends stand for, m. Maps meant to be
/// compared (a session's terrain before and after, its bench snapshots) share one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElevationScale {
    /// The elevation of the scale's low (blue) end, m.
    pub lo_m: f64,
    /// The elevation of the scale's high (red) end, m.
    pub hi_m: f64,
}

impl ElevationScale {
    /// The scale from the lowest to the highest cell of `terrains` (0..1 m when there is none, or
    /// all are level).
    pub fn spanning<'a>(terrains: impl IntoIterator<Item = &'a TerrainGrid>) -> Self {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for t in terrains {
            for j in 0..t.ny() {
                for i in 0..t.nx() {
                    if let Some(z) = t.cell(i, j).filter(|z| z.is_finite()) {
                        lo = lo.min(z);
                        hi = hi.max(z);
                    }
                }
            }
        }
        if lo < hi {
            Self { lo_m: lo, hi_m: hi }
        } else if lo.is_finite() {
            Self {
                lo_m: lo - 0.5,
                hi_m: lo + 0.5,
            }
        } else {
            Self {
                lo_m: 0.0,
                hi_m: 1.0,
            }
        }
    }

    /// The colour of elevation `z_m`.
    fn color(&self, z_m: f64) -> RGBColor {
        heat((z_m - self.lo_m) / (self.hi_m - self.lo_m))
    }
}

/// Where the machine was (world frame): the swing axis at each dig in order, and its pose
/// `[x, y, heading]` (m, m, rad) at the moment a map shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MachineTrack {
    /// The swing axis's positions in order, m.
    pub path: Vec<[f64; 2]>,
    /// The pose drawn as the machine's outline.
    pub pose: Option<[f64; 3]>,
}

impl MachineTrack {
    /// The track of `digs` (their dead-reckoned poses), the machine drawn at the last one.
    pub fn of_digs(digs: &[DigRecord]) -> Self {
        let mut track = Self::default();
        for pose in digs.iter().filter_map(|d| d.pose) {
            track = track.at(pose);
        }
        track
    }

    /// The track ending at `pose` (the machine drawn there).
    #[must_use]
    pub fn at(mut self, pose: [f64; 3]) -> Self {
        let p = [pose[0], pose[1]];
        if self
            .path
            .last()
            .is_none_or(|q| (q[0] - p[0]).hypot(q[1] - p[1]) > 0.05)
        {
            self.path.push(p);
        }
        self.pose = Some(pose);
        self
    }
}

/// The width of the colour bar's strip right of an elevation map, px.
const COLOUR_BAR_STRIP_PX: u32 = 110;

/// An elevation map (world frame, x east, y north) of `terrain` over `window` (`[x0, x1, y0, y1]`,
/// m) in `cell`-sized squares coloured on `scale`, with a colour bar labelled in m, and the machine's
/// path (dashed) and outline (tracks, heading, swing axis) from `track`.
fn elevation_map_svg(
    terrain: &TerrainGrid,
    window: [f64; 4],
    cell_m: f64,
    scale: ElevationScale,
    track: &MachineTrack,
    title: &str,
) -> anyhow::Result<String> {
    let [x0, x1, y0, y1] = window;
    let map_w = 700u32;
    let map_h = (f64::from(map_w - 60) * (y1 - y0) / (x1 - x0)).clamp(240.0, 900.0) as u32 + 80;
    let nx = ((x1 - x0) / cell_m).round().max(1.0) as usize;
    let ny = ((y1 - y0) / cell_m).round().max(1.0) as usize;
    svg_image((map_w + COLOUR_BAR_STRIP_PX, map_h), |root| {
        let (map, bar) = root.split_horizontally(map_w);
        let mut chart = ChartBuilder::on(&map)
            .caption(title, ("sans-serif", 15))
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x east [m]")
            .y_desc("y north [m]")
            .x_label_formatter(&tick_label)
            .y_label_formatter(&tick_label)
            .draw()
            .map_err(err)?;
        let mut cells = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let x = x0 + cell_m * i as f64;
                let y = y0 + cell_m * j as f64;
                if let Ok(z) = terrain.height_at(x + 0.5 * cell_m, y + 0.5 * cell_m)
                    && z.is_finite()
                {
                    cells.push(Rectangle::new(
                        [(x, y), (x + cell_m, y + cell_m)],
                        scale.color(z).filled(),
                    ));
                }
            }
        }
        chart.draw_series(cells).map_err(err)?;
        if track.path.len() > 1 {
            chart
                .draw_series(DashedLineSeries::new(
                    track.path.iter().map(|p| (p[0], p[1])),
                    6,
                    4,
                    BLACK.stroke_width(2),
                ))
                .map_err(err)?;
        }
        if let Some([mx, my, h]) = track.pose {
            // The tracks' 4.45 m x 3 m footprint and the heading.
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
                .draw_series([
                    PathElement::new(outline, BLACK.stroke_width(2)),
                    PathElement::new(vec![(mx, my), corner(3.5, 0.0)], BLACK.stroke_width(2)),
                ])
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Circle::new((mx, my), 4, BLACK.filled())))
                .map_err(err)?;
        }
        draw_colour_bar(
            &bar,
            map_h,
            "elevation [m]",
            (scale.lo_m, scale.hi_m),
            &|z| format!("{z:.2} m"),
        )
    })
}

/// A colour bar of the heat scale in its strip beside a chart: `title` above it, the values `ends`
/// at its low and high ends and three ticks between them, each labelled with `label`.
fn draw_colour_bar(
    bar: &DrawingArea<SVGBackend<'_>, Shift>,
    height_px: u32,
    title: &str,
    ends: (f64, f64),
    label: &dyn Fn(f64) -> String,
) -> anyhow::Result<()> {
    const TOP: i32 = 60;
    const STEPS: i32 = 40;
    let span = i32::try_from(height_px.saturating_sub(140))
        .unwrap_or(200)
        .max(80);
    bar.draw(&Text::new(
        title.to_owned(),
        (4, TOP - 22),
        ("sans-serif", 12),
    ))
    .map_err(err)?;
    for k in 0..STEPS {
        let f = (f64::from(k) + 0.5) / f64::from(STEPS);
        let y_lo = TOP + span - k * span / STEPS;
        let y_hi = TOP + span - (k + 1) * span / STEPS;
        bar.draw(&Rectangle::new([(10, y_hi), (34, y_lo)], heat(f).filled()))
            .map_err(err)?;
    }
    for k in 0..=4 {
        let z = ends.0 + (ends.1 - ends.0) * f64::from(k) / 4.0;
        let y = TOP + span - k * span / 4;
        bar.draw(&PathElement::new(vec![(34, y), (39, y)], BLACK))
            .map_err(err)?;
        bar.draw(&Text::new(label(z), (42, y - 6), ("sans-serif", 11)))
            .map_err(err)?;
    }
    Ok(())
}

/// A terrain elevation map of the region around the machine's work (world frame, x east, y north):
/// the region in front of its start (x -4..14 m, y -9..9 m) widened to the machine's whole path,
/// within the terrain, 0.2 m cells, colours on `scale`; the machine's path and pose from `track`.
///
/// # Errors
/// A plotting error.
pub fn terrain_svg(
    terrain: &TerrainGrid,
    scale: ElevationScale,
    track: &MachineTrack,
    title: &str,
) -> anyhow::Result<String> {
    const MARGIN_M: f64 = 4.0;
    let [ox, oy] = terrain.origin();
    let res = terrain.resolution_m();
    let (gx1, gy1) = (
        ox + res * terrain.nx() as f64,
        oy + res * terrain.ny() as f64,
    );
    let mut w = [-4.0_f64, 14.0, -9.0, 9.0];
    for p in &track.path {
        w = [
            w[0].min(p[0] - MARGIN_M),
            w[1].max(p[0] + MARGIN_M),
            w[2].min(p[1] - MARGIN_M),
            w[3].max(p[1] + MARGIN_M),
        ];
    }
    let window = [w[0].max(ox), w[1].min(gx1), w[2].max(oy), w[3].min(gy1)];
    let window = if window[0] < window[1] && window[2] < window[3] {
        window
    } else {
        [ox, gx1, oy, gy1]
    };
    elevation_map_svg(terrain, window, 0.2, scale, track, title)
}

/// The bench after some digs (thesis Fig. 55): true terrain elevation over the whole map (world frame,
/// 0.3 m cells, colours on `scale`), the machine's path and its tracks and heading from `track`.
///
/// # Errors
/// A plotting error.
pub fn bench_svg(
    terrain: &TerrainGrid,
    scale: ElevationScale,
    track: &MachineTrack,
    title: &str,
) -> anyhow::Result<String> {
    let [ox, oy] = terrain.origin();
    let res = terrain.resolution_m();
    let window = [
        ox,
        ox + res * terrain.nx() as f64,
        oy,
        oy + res * terrain.ny() as f64,
    ];
    elevation_map_svg(terrain, window, 0.3, scale, track, title)
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

/// Per-dig weight (kN), time (s) and energy (kJ), three panels, bars by dig number (dig actions
/// blue, cleanups orange), with the thesis's Table 4 dig means as dashed lines; the legend beside the
/// panels.
///
/// # Errors
/// A plotting error.
pub fn dig_stats_svg(digs: &[DigRecord]) -> anyhow::Result<String> {
    type Get = fn(&DigRecord) -> f64;
    let series: [(&str, &str, Get, f64); 3] = [
        (
            "bucket weight per dig (thesis Table 4 digs: 21.2 kN)",
            "weight [kN]",
            |d| d.weight_n.unwrap_or(0.0) * 1e-3,
            21.2,
        ),
        (
            "time per dig (thesis: 5.8 s)",
            "time [s]",
            |d| d.time_s,
            5.8,
        ),
        (
            "energy per dig (thesis: 212 kJ)",
            "energy [kJ]",
            |d| d.energy_kj,
            212.0,
        ),
    ];
    let panels = series.map(|(title, y, get, level)| Panel {
        title: title.to_owned(),
        y_desc: y,
        top: digs.iter().map(get).fold(level, f64::max),
        level: Some(level),
    });
    per_dig_panels_svg(
        digs,
        (860, 720),
        "thesis Table 4 mean",
        |chart, panel| {
            let (_, _, get, _) = series[panel];
            chart
                .draw_series(digs.iter().map(|d| {
                    let x = f64::from(d.index);
                    Rectangle::new(
                        [(x - 0.35, 0.0), (x + 0.35, get(d))],
                        action_color(d).filled(),
                    )
                }))
                .map_err(err)?;
            Ok(())
        },
        &panels,
        LegendMark::Box,
    )
}

/// One panel of [`per_dig_panels_svg`].
struct Panel {
    title: String,
    y_desc: &'static str,
    /// The largest value drawn.
    top: f64,
    /// The dashed reference level, if any.
    level: Option<f64>,
}

/// A chart in the coordinates of plotters' SVG drawing, both axes `f64`.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The width of the legend strip beside the per-dig panels, px.
const PANEL_LEGEND_PX: u32 = 150;

/// Stacked per-dig panels of `digs` (x: the dig number), each drawn by `draw(chart, panel index)`
/// over its axes, dashed level and the session's backups (grey vertical lines between two digs whose
/// machine poses differ); the legend (dig actions, cleanups as `mark`, the level named `level_name`,
/// backups) in a strip beside the panels.
fn per_dig_panels_svg(
    digs: &[DigRecord],
    size: (u32, u32),
    level_name: &str,
    draw: impl Fn(&mut Chart<'_, '_>, usize) -> anyhow::Result<()>,
    panels: &[Panel],
    mark: LegendMark,
) -> anyhow::Result<String> {
    let (first, last) = match (digs.first(), digs.last()) {
        (Some(a), Some(b)) => (f64::from(a.index), f64::from(b.index)),
        _ => (0.0, 1.0),
    };
    let backups: Vec<f64> = digs
        .windows(2)
        .filter_map(|w| match (w[0].pose, w[1].pose) {
            (Some(a), Some(b)) if (a[0] - b[0]).hypot(a[1] - b[1]) > 0.2 => {
                Some(f64::from(w[1].index) - 0.5)
            }
            _ => None,
        })
        .collect();
    svg_image(size, |root| {
        let (left, strip) = root.split_horizontally(size.0 - PANEL_LEGEND_PX);
        for (k, (area, panel)) in left
            .split_evenly((panels.len().max(1), 1))
            .iter()
            .zip(panels)
            .enumerate()
        {
            let top = panel.top.max(1e-3) * 1.15;
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d((first - 0.5)..(last + 0.5), 0.0..top)
                .map_err(err)?;
            let whole = |v: &f64| {
                if (v - v.round()).abs() < 1e-6 {
                    format!("{:.0}", v.round())
                } else {
                    String::new()
                }
            };
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_desc("dig")
                .y_desc(panel.y_desc)
                .x_labels(digs.len().clamp(2, 20))
                .x_label_formatter(&whole)
                .y_label_formatter(&tick_label)
                .draw()
                .map_err(err)?;
            for &b in &backups {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(b, 0.0), (b, top)],
                        BACKUP.stroke_width(1),
                    )))
                    .map_err(err)?;
            }
            draw(&mut chart, k)?;
            if let Some(y) = panel.level {
                chart
                    .draw_series(DashedLineSeries::new(
                        vec![(first - 0.5, y), (last + 0.5, y)],
                        5,
                        4,
                        LEVEL.stroke_width(1),
                    ))
                    .map_err(err)?;
            }
        }
        let mut entries = vec![
            ("dig".to_owned(), color(0), mark),
            ("cleanup".to_owned(), color(1), mark),
            (level_name.to_owned(), LEVEL, LegendMark::Dashed),
        ];
        if !backups.is_empty() {
            entries.push(("track back".to_owned(), BACKUP, LegendMark::Line));
        }
        draw_legend_column(&strip.margin(30, 0, 0, 0), &entries)
    })
}

/// The dashed reference level of the per-dig panels.
const LEVEL: RGBColor = RGBColor(90, 90, 90);
/// The backups' lines in the per-dig panels.
const BACKUP: RGBColor = RGBColor(180, 180, 180);

/// A dig's colour in the per-dig panels: cleanups orange, other actions blue.
fn action_color(d: &DigRecord) -> RGBColor {
    if d.action == controller::step::cycle::ActionKind::Cleanup {
        color(1)
    } else {
        color(0)
    }
}

/// The statistics of a session in dig order (thesis Fig. 56): weight (kN) with the half-full line,
/// time (s) and energy (kJ); dig actions blue, cleanups orange; backups as grey vertical lines; the
/// legend beside the panels.
///
/// # Errors
/// A plotting error.
pub fn dig_sequence_svg(digs: &[DigRecord], full_bucket_n: f64) -> anyhow::Result<String> {
    type Get = fn(&DigRecord) -> f64;
    let half = 0.5 * full_bucket_n * 1e-3;
    let series: [(&str, &str, Get, Option<f64>); 3] = [
        (
            "bucket weight per dig",
            "weight [kN]",
            |d| d.weight_n.unwrap_or(0.0) * 1e-3,
            Some(half),
        ),
        ("time per dig", "time [s]", |d| d.time_s, None),
        ("energy per dig", "energy [kJ]", |d| d.energy_kj, None),
    ];
    let panels = series.map(|(title, y, get, level)| Panel {
        title: title.to_owned(),
        y_desc: y,
        top: digs.iter().map(get).fold(level.unwrap_or(0.0), f64::max),
        level,
    });
    per_dig_panels_svg(
        digs,
        (900, 760),
        &format!("half full ({half:.1} kN)"),
        |chart, panel| {
            let (_, _, get, _) = series[panel];
            chart
                .draw_series(digs.iter().map(|d| {
                    Circle::new((f64::from(d.index), get(d)), 3, action_color(d).filled())
                }))
                .map_err(err)?;
            Ok(())
        },
        &panels,
        LegendMark::Dot,
    )
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
