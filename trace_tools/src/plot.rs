//! `trace plot`: signals over time as an SVG, and the `dig` preset.
//!
//! `--signal NAME...` draws the chosen signals over time (seconds after the first frame), one panel per
//! unit so that signals sharing a unit share an axis. `--preset dig` draws a dig as stacked panels:
//! joint angles, cylinder head and rod pressures, the implement valve commands (signed fractions of
//! maximum cylinder velocity, `AuxValveCommand::to_fraction`) and the Autodig stage from
//! `ControllerStatus`; beside them the bucket-tip path in the x-z plane of the base frame, computed from
//! every `JointAngles` frame with the forward kinematics of the default machine (`--machine FILE` for
//! another one) and coloured by the Autodig stage in force. Both can be combined (the chosen signals
//! become extra panels).
//!
//! Memory stays bounded on long traces: each series keeps at most `--max-points` points, keeping every
//! k-th sample and doubling k (halving the stored points) whenever it fills up. Short spikes can
//! therefore fall between the kept samples of a very long trace; `--from`/`--to` zoom in.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use firmware_bridge::messages::{AutodigStageCode, Message};
use planner::kinematics::{self, Kinematics};
use planner::machine::MachineConfig;
use plotters::prelude::*;

use super::InputArgs;
use super::input;
use super::signals::{self, SignalRef};

/// A plotters error as an `anyhow` error.
pub fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing the plot: {e}")
}

/// Plot presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Preset {
    /// Joint angles, pressures, valve commands, Autodig stage and the bucket-tip path.
    Dig,
}

/// `trace plot` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct PlotArgs {
    /// The trace.
    #[command(flatten)]
    pub input: InputArgs,
    /// A signal to draw (`BoomAngle` or `Message.Signal`); repeatable.
    #[arg(long = "signal", value_name = "NAME")]
    pub signals: Vec<String>,
    /// A preset layout.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Output SVG file.
    #[arg(long)]
    pub out: PathBuf,
    /// Machine description for the bucket-tip path (default: the bundled 20-25 t machine).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
    /// Start of the time window, seconds after the first frame.
    #[arg(long, value_name = "S")]
    pub from: Option<f64>,
    /// End of the time window, seconds after the first frame.
    #[arg(long, value_name = "S")]
    pub to: Option<f64>,
    /// Most points kept per series.
    #[arg(long, default_value_t = 5000)]
    pub max_points: usize,
    /// Image width, px.
    #[arg(long, default_value_t = 1400)]
    pub width: u32,
}

/// A bounded, decimated series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Kept points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    stride: u64,
    seen: u64,
    cap: usize,
}

impl Series {
    /// An empty series keeping at most `cap` points (at least 2).
    pub fn new(label: impl Into<String>, cap: usize) -> Self {
        Self {
            label: label.into(),
            points: Vec::new(),
            stride: 1,
            seen: 0,
            cap: cap.max(2),
        }
    }

    /// Adds a sample; non-finite values are dropped.
    pub fn push(&mut self, x: f64, y: f64) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let keep = self.seen.is_multiple_of(self.stride);
        self.seen += 1;
        if !keep {
            return;
        }
        self.points.push((x, y));
        if self.points.len() >= self.cap {
            let mut i = 0;
            self.points.retain(|_| {
                i += 1;
                i % 2 == 1
            });
            self.stride = self.stride.saturating_mul(2);
        }
    }
}

/// How a panel is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PanelKind {
    Lines,
    Stage,
}

/// One stacked time panel.
#[derive(Debug, Clone)]
struct Panel {
    title: String,
    y_desc: String,
    kind: PanelKind,
    series: Vec<Series>,
}

/// Everything the plot collects while streaming.
#[derive(Debug)]
struct PlotData {
    panels: Vec<Panel>,
    /// message index -> (signal index, panel, series, factor from the signal's unit to the panel's)
    by_message: HashMap<usize, Vec<(usize, usize, usize, f64)>>,
    dig: Option<DigPanels>,
    first_ns: Option<u64>,
    from_s: Option<f64>,
    to_s: Option<f64>,
}

#[derive(Debug)]
struct DigPanels {
    angles: usize,
    pressures: usize,
    commands: usize,
    stage: usize,
    kin: Kinematics,
    current_stage: AutodigStageCode,
    /// Tip path, one series per Autodig stage code (0..=5).
    tip: Vec<Series>,
}

const STAGES: [(AutodigStageCode, &str); 6] = [
    (AutodigStageCode::None, "none"),
    (AutodigStageCode::BoomDown, "boom down"),
    (AutodigStageCode::PreDig, "pre-dig"),
    (AutodigStageCode::Dig, "dig"),
    (AutodigStageCode::Capture, "capture"),
    (AutodigStageCode::Done, "done"),
];

/// The project's plot palette (matplotlib's tab10 order), used by every figure of the trace tools and
/// the lab.
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// The `i`-th colour of [`PALETTE`], cycling.
pub fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// A tick label without noise: at most three decimals, trailing zeros dropped (`10`, `2.5`, `0.125`),
/// and `0` for a negative zero. Every axis of the project's plots uses it.
pub fn tick_label(v: &f64) -> String {
    if !v.is_finite() {
        return String::new();
    }
    let digits = if v.abs() >= 100.0 { 0 } else { 3 };
    let text = format!("{v:.digits$}");
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    };
    if text == "-0" { "0".to_owned() } else { text }
}

/// How a legend entry of [`draw_legend_column`] shows its series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LegendMark {
    /// A line.
    Line,
    /// A dashed line.
    Dashed,
    /// A filled box (bars, map cells).
    Box,
    /// A dot (scatter points).
    Dot,
}

/// One legend entry: the series' name, colour and mark.
pub type LegendEntry = (String, RGBColor, LegendMark);

/// Draws `entries` as a column of legend lines from the top left of `area`, an area beside the chart
/// (never over its data); entries that do not fit are left out and counted in a last line.
///
/// # Errors
/// A drawing error.
pub fn draw_legend_column<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[LegendEntry],
) -> anyhow::Result<()> {
    const ROW_PX: i32 = 16;
    let (_, height) = area.dim_in_pixel();
    let rows = (i32::try_from(height).unwrap_or(i32::MAX) - 8) / ROW_PX;
    let shown = usize::try_from(rows.max(0)).unwrap_or(0).min(entries.len());
    let shown = if shown < entries.len() {
        shown.saturating_sub(1)
    } else {
        shown
    };
    for (k, (label, c, mark)) in entries.iter().take(shown).enumerate() {
        let y = 8 + ROW_PX * i32::try_from(k).unwrap_or(0) + ROW_PX / 2;
        let c = *c;
        match mark {
            LegendMark::Line => {
                area.draw(&PathElement::new(vec![(4, y), (22, y)], c.stroke_width(2)))
            }
            LegendMark::Dashed => area
                .draw(&PathElement::new(vec![(4, y), (9, y)], c.stroke_width(1)))
                .and_then(|()| {
                    area.draw(&PathElement::new(vec![(13, y), (18, y)], c.stroke_width(1)))
                }),
            LegendMark::Box => area.draw(&Rectangle::new([(6, y - 5), (20, y + 5)], c.filled())),
            LegendMark::Dot => area.draw(&Circle::new((13, y), 4, c.filled())),
        }
        .map_err(err)?;
        area.draw(&Text::new(label.clone(), (27, y - 6), ("sans-serif", 12)))
            .map_err(err)?;
    }
    if shown < entries.len() {
        let y = 8 + ROW_PX * i32::try_from(shown).unwrap_or(0);
        area.draw(&Text::new(
            format!("(+{} more)", entries.len() - shown),
            (27, y + 2),
            ("sans-serif", 12),
        ))
        .map_err(err)?;
    }
    Ok(())
}

impl PlotData {
    fn new(
        signal_refs: &[SignalRef],
        preset: Option<Preset>,
        kin: Option<Kinematics>,
        max_points: usize,
    ) -> Self {
        let mut data = Self {
            panels: Vec::new(),
            by_message: HashMap::new(),
            dig: None,
            first_ns: None,
            from_s: None,
            to_s: None,
        };
        if let (Some(Preset::Dig), Some(kin)) = (preset, kin) {
            let mk = |labels: &[&str]| -> Vec<Series> {
                labels.iter().map(|l| Series::new(*l, max_points)).collect()
            };
            let panel = |title: &str, y: &str, kind, series| Panel {
                title: title.to_string(),
                y_desc: y.to_string(),
                kind,
                series,
            };
            data.panels.push(panel(
                "joint angles",
                "angle [rad]",
                PanelKind::Lines,
                mk(&["boom", "stick", "bucket", "swing"]),
            ));
            data.panels.push(panel(
                "cylinder pressures",
                "pressure [MPa]",
                PanelKind::Lines,
                mk(&[
                    "boom head",
                    "boom rod",
                    "stick head",
                    "stick rod",
                    "bucket head",
                    "bucket rod",
                ]),
            ));
            data.panels.push(panel(
                "valve commands (fraction of max cylinder velocity, + extend)",
                "command [1]",
                PanelKind::Lines,
                mk(&["boom", "stick", "bucket", "swing"]),
            ));
            data.panels.push(panel(
                "Autodig stage (ControllerStatus)",
                "stage",
                PanelKind::Stage,
                mk(&["stage"]),
            ));
            data.dig = Some(DigPanels {
                angles: 0,
                pressures: 1,
                commands: 2,
                stage: 3,
                kin,
                current_stage: AutodigStageCode::None,
                tip: STAGES
                    .iter()
                    .map(|(_, n)| Series::new(*n, max_points))
                    .collect(),
            });
        }
        // Chosen signals: one panel per unit.
        let mut unit_panel: HashMap<&'static str, usize> = HashMap::new();
        for s in signal_refs {
            let (unit, factor) = display_unit(s.signal().unit);
            let p = *unit_panel.entry(unit).or_insert_with(|| {
                data.panels.push(Panel {
                    title: if unit.is_empty() {
                        "signals".to_string()
                    } else {
                        format!("signals [{unit}]")
                    },
                    y_desc: if unit.is_empty() {
                        "value".to_string()
                    } else {
                        format!("[{unit}]")
                    },
                    kind: PanelKind::Lines,
                    series: Vec::new(),
                });
                data.panels.len() - 1
            });
            if let Some(panel) = data.panels.get_mut(p) {
                panel.series.push(Series::new(s.full_name(), max_points));
                let idx = panel.series.len() - 1;
                data.by_message
                    .entry(s.msg_index)
                    .or_default()
                    .push((s.sig_index, p, idx, factor));
            }
        }
        data
    }

    fn push(&mut self, panel: usize, series: usize, t: f64, v: f64) {
        if let Some(s) = self
            .panels
            .get_mut(panel)
            .and_then(|p| p.series.get_mut(series))
        {
            s.push(t, v);
        }
    }

    fn add(&mut self, rec: &firmware_bridge::trace::TraceRecord) {
        let first = *self.first_ns.get_or_insert(rec.timestamp_ns);
        let t = rec.timestamp_ns.saturating_sub(first) as f64 * 1e-9;
        let outside = self.from_s.is_some_and(|f| t < f) || self.to_s.is_some_and(|e| t > e);
        let frame = &rec.frame;
        let Some((msg_index, desc)) = signals::message_of(frame) else {
            return;
        };
        if frame.data().len() != usize::from(desc.dlc) {
            return;
        }
        if !outside && let Some(entries) = self.by_message.get(&msg_index).cloned() {
            for (sig_index, panel, series, factor) in entries {
                if let Some(sig) = desc.signals.get(sig_index)
                    && let Some(v) = signals::decode_signal(sig, frame.data()).value()
                {
                    self.push(panel, series, t, v * factor);
                }
            }
        }
        let Some(dig) = &mut self.dig else {
            return;
        };
        let Ok(decoded) = Message::decode(frame) else {
            return;
        };
        let mut pushes: Vec<(usize, usize, f64)> = Vec::new();
        match decoded.message {
            Message::ControllerStatus(s) => {
                dig.current_stage = s.stage;
                pushes.push((dig.stage, 0, f64::from(s.stage as u8)));
            }
            Message::JointAngles(a) => {
                pushes.extend([
                    (dig.angles, 0, a.boom_rad),
                    (dig.angles, 1, a.stick_rad),
                    (dig.angles, 2, a.bucket_rad),
                    (dig.angles, 3, a.swing_rad),
                ]);
                if !outside {
                    let pose = dig.kin.forward(&kinematics::JointAngles {
                        boom_rad: a.boom_rad,
                        stick_rad: a.stick_rad,
                        bucket_rad: a.bucket_rad,
                    });
                    if let Some(s) = dig.tip.get_mut(dig.current_stage as usize) {
                        s.push(pose.x_m, pose.z_m);
                    }
                }
            }
            Message::AuxValveMeasured(m) => {
                let c = usize::from(m.cylinder.number());
                pushes.push((dig.pressures, 2 * c, m.head_pressure_pa * 1e-6));
                pushes.push((dig.pressures, 2 * c + 1, m.rod_pressure_pa * 1e-6));
            }
            Message::AuxValveCommand(c) if c.valve.number() < 4 => {
                pushes.push((dig.commands, usize::from(c.valve.number()), c.to_fraction()));
            }
            _ => {}
        }
        if outside {
            return;
        }
        for (panel, series, v) in pushes {
            self.push(panel, series, t, v);
        }
    }
}

/// The unit a signal of `unit` is drawn in, and the factor to it: pressures in MPa (a tick reads
/// `35`, not `35000000`), everything else as decoded.
fn display_unit(unit: &'static str) -> (&'static str, f64) {
    match unit {
        "Pa" => ("MPa", 1e-6),
        other => (other, 1.0),
    }
}

/// The ground line of the tip path.
const GROUND: RGBColor = RGBColor(150, 150, 150);

/// The width of the legend strip right of each time panel, px.
const LEGEND_STRIP_PX: u32 = 150;

fn range_of<'a>(points: impl Iterator<Item = &'a (f64, f64)>) -> Option<((f64, f64), (f64, f64))> {
    let mut r: Option<((f64, f64), (f64, f64))> = None;
    for &(x, y) in points {
        r = Some(match r {
            None => ((x, x), (y, y)),
            Some(((x0, x1), (y0, y1))) => ((x0.min(x), x1.max(x)), (y0.min(y), y1.max(y))),
        });
    }
    r
}

/// Widens a degenerate range and adds a margin.
fn padded(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        let d = (lo.abs() * 0.1).max(0.5);
        return (lo - d, hi + d);
    }
    let m = (hi - lo) * 0.05;
    (lo - m, hi + m)
}

fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    panel: &Panel,
    x_range: (f64, f64),
) -> anyhow::Result<()> {
    let (y0, y1) = match panel.kind {
        PanelKind::Stage => (-0.5, 5.5),
        PanelKind::Lines => {
            let r = range_of(panel.series.iter().flat_map(|s| s.points.iter()));
            r.map_or((0.0, 1.0), |(_, (lo, hi))| padded(lo, hi))
        }
    };
    let (width, _) = area.dim_in_pixel();
    let (area, legend) = area.split_horizontally(width.saturating_sub(LEGEND_STRIP_PX));
    let mut chart = ChartBuilder::on(&area)
        .caption(&panel.title, ("sans-serif", 15))
        .margin(6)
        .x_label_area_size(28)
        .y_label_area_size(70)
        .build_cartesian_2d(x_range.0..x_range.1, y0..y1)
        .map_err(err)?;
    let stage_label = |v: &f64| -> String {
        let i = v.round();
        if (v - i).abs() < 1e-6 && (0.0..=5.0).contains(&i) {
            STAGES[i as usize].1.to_string()
        } else {
            String::new()
        }
    };
    let mut mesh = chart.configure_mesh();
    mesh.x_desc("t [s]")
        .y_desc(panel.y_desc.as_str())
        .x_label_formatter(&tick_label);
    if panel.kind == PanelKind::Stage {
        mesh.y_labels(6).y_label_formatter(&stage_label);
    } else {
        mesh.y_label_formatter(&tick_label);
    }
    mesh.draw().map_err(err)?;
    let mut entries: Vec<LegendEntry> = Vec::new();
    for (i, s) in panel.series.iter().enumerate() {
        if s.points.is_empty() {
            continue;
        }
        let c = color(i);
        let points: Vec<(f64, f64)> = match panel.kind {
            PanelKind::Lines => s.points.clone(),
            // Stage changes are steps, not ramps.
            PanelKind::Stage => {
                let mut out = Vec::with_capacity(2 * s.points.len());
                for w in s.points.windows(2) {
                    out.push(w[0]);
                    out.push((w[1].0, w[0].1));
                }
                if let Some(last) = s.points.last() {
                    out.push(*last);
                }
                out
            }
        };
        chart
            .draw_series(LineSeries::new(points, c.stroke_width(1)))
            .map_err(err)?;
        entries.push((s.label.clone(), c, LegendMark::Line));
    }
    // Below the caption, level with the plot area.
    draw_legend_column(&legend.margin(28, 0, 0, 0), &entries)?;
    Ok(())
}

fn draw_tip_path(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    tip: &[Series],
) -> anyhow::Result<()> {
    let r = range_of(tip.iter().flat_map(|s| s.points.iter()));
    let ((x0, x1), (z0, z1)) = r.map_or(((0.0, 10.0), (-2.0, 4.0)), |((a, b), (c, d))| {
        (padded(a, b), padded(c.min(0.0), d.max(0.0)))
    });
    let (_, height) = area.dim_in_pixel();
    let (area, legend) = area.split_vertically(height.saturating_sub(110));
    let mut chart = ChartBuilder::on(&area)
        .caption(
            "bucket-tip path (base frame, side view)",
            ("sans-serif", 15),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, z0..z1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x [m] (forward of the swing axis)")
        .y_desc("z [m]")
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .draw()
        .map_err(err)?;
    // The ground the tracks stand on.
    chart
        .draw_series(LineSeries::new(
            vec![(x0, 0.0), (x1, 0.0)],
            GROUND.stroke_width(1),
        ))
        .map_err(err)?;
    let mut entries: Vec<LegendEntry> =
        vec![("ground (z = 0)".to_owned(), GROUND, LegendMark::Line)];
    for (i, s) in tip.iter().enumerate() {
        if s.points.is_empty() {
            continue;
        }
        let c = color(i);
        chart
            .draw_series(s.points.iter().map(move |&p| Circle::new(p, 1, c.filled())))
            .map_err(err)?;
        entries.push((format!("Autodig stage: {}", s.label), c, LegendMark::Dot));
    }
    draw_legend_column(&legend.margin(0, 0, 60, 0), &entries)?;
    Ok(())
}

/// What [`plot_trace`] drew.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlotSummary {
    /// Records read.
    pub records: u64,
    /// Points drawn per series label (time panels, then tip-path stages).
    pub points: Vec<(String, usize)>,
}

/// Options of [`plot_trace`].
#[derive(Debug, Clone, PartialEq)]
pub struct PlotOptions {
    /// Signals to draw.
    pub signals: Vec<String>,
    /// Preset.
    pub preset: Option<Preset>,
    /// Machine file for the tip path.
    pub machine: Option<PathBuf>,
    /// Time window, s after the first frame.
    pub from_s: Option<f64>,
    /// Time window end.
    pub to_s: Option<f64>,
    /// Most points per series.
    pub max_points: usize,
    /// Image width, px.
    pub width: u32,
    /// How to read the trace (`--strict`, its profile).
    pub read: input::ReadOptions,
}

impl Default for PlotOptions {
    fn default() -> Self {
        Self {
            signals: Vec::new(),
            preset: None,
            machine: None,
            from_s: None,
            to_s: None,
            max_points: 5000,
            width: 1400,
            read: input::ReadOptions::default(),
        }
    }
}

/// Plots `input` into the SVG file `out`.
///
/// # Errors
/// Nothing to plot, bad signal names, an invalid machine file, read and write errors.
pub fn plot_trace<R: std::io::BufRead>(
    input: R,
    out: &Path,
    opts: &PlotOptions,
    diag: &mut dyn std::io::Write,
) -> anyhow::Result<PlotSummary> {
    if opts.signals.is_empty() && opts.preset.is_none() {
        anyhow::bail!("nothing to plot: give --signal NAME (repeatable) or --preset dig");
    }
    let refs: Vec<SignalRef> = opts
        .signals
        .iter()
        .map(|n| signals::resolve_signal(n).map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<_>>()?;
    let kin = if opts.preset == Some(Preset::Dig) {
        let machine =
            MachineConfig::load_or_default(opts.machine.as_deref()).context("machine file")?;
        Some(Kinematics::new(&machine).context("machine kinematics")?)
    } else {
        None
    };
    let mut data = PlotData::new(&refs, opts.preset, kin, opts.max_points);
    data.from_s = opts.from_s;
    data.to_s = opts.to_s;
    let read = input::for_each_record(input, opts.read.clone(), diag, |rec| {
        data.add(&rec);
        Ok(true)
    })?;

    let all_points = data
        .panels
        .iter()
        .flat_map(|p| p.series.iter())
        .flat_map(|s| s.points.iter());
    let x_range = range_of(all_points).map_or((0.0, 1.0), |((lo, hi), _)| {
        if hi - lo < 1e-9 {
            (lo, lo + 1.0)
        } else {
            (lo, hi)
        }
    });
    let width = opts.width.clamp(400, 10_000);
    let panel_height = 230u32;
    let height = (panel_height * data.panels.len().max(1) as u32).max(500);
    {
        let root = SVGBackend::new(out, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let time_area = if let Some(dig) = &data.dig {
            let (left, right) = root.split_horizontally(width * 64 / 100);
            draw_tip_path(&right, &dig.tip)?;
            left
        } else {
            root.clone()
        };
        let areas = time_area.split_evenly((data.panels.len().max(1), 1));
        for (panel, area) in data.panels.iter().zip(areas.iter()) {
            draw_panel(area, panel, x_range)?;
        }
        root.present()
            .map_err(err)
            .with_context(|| format!("writing {}", out.display()))?;
    }
    let mut points: Vec<(String, usize)> = data
        .panels
        .iter()
        .flat_map(|p| p.series.iter())
        .map(|s| (s.label.clone(), s.points.len()))
        .collect();
    if let Some(dig) = &data.dig {
        points.extend(
            dig.tip
                .iter()
                .map(|s| (format!("tip {}", s.label), s.points.len())),
        );
    }
    for (label, n) in &points {
        if *n == 0 && !label.starts_with("tip ") {
            let _ = writeln!(diag, "warning: no data for {label}");
        }
    }
    Ok(PlotSummary {
        records: read.records,
        points,
    })
}

/// Runs `trace plot`.
///
/// # Errors
/// As [`plot_trace`].
pub fn run(args: &PlotArgs) -> anyhow::Result<()> {
    let read = args.input.read_options()?;
    let reader = input::open(&args.input.file)?;
    let opts = PlotOptions {
        signals: args.signals.clone(),
        preset: args.preset,
        machine: args.machine.clone(),
        from_s: args.from,
        to_s: args.to,
        max_points: args.max_points,
        width: args.width,
        read,
    };
    let summary = plot_trace(reader, &args.out, &opts, &mut std::io::stderr())
        .with_context(|| format!("plotting {}", args.input.file.display()))?;
    eprintln!(
        "{}: {} record(s) read, {} series drawn",
        args.out.display(),
        summary.records,
        summary.points.iter().filter(|(_, n)| *n > 0).count()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_stay_bounded_and_keep_the_span() {
        let mut s = Series::new("x", 100);
        for i in 0..100_000 {
            s.push(f64::from(i), 1.0);
        }
        assert!(s.points.len() < 100);
        assert_eq!(s.points[0].0, 0.0);
        assert!(s.points.last().unwrap().0 > 90_000.0);
        s.push(f64::NAN, 1.0);
        assert!(s.points.iter().all(|p| p.0.is_finite()));
    }

    #[test]
    fn ticks_carry_no_noise() {
        for (v, text) in [
            (10.0, "10"),
            (2.5, "2.5"),
            (0.125, "0.125"),
            (-0.0, "0"),
            (-1.5, "-1.5"),
            (35.0, "35"),
            (1e-5, "0"),
            (212.4, "212"),
        ] {
            assert_eq!(tick_label(&v), text);
        }
        assert_eq!(tick_label(&f64::NAN), "");
    }

    /// The `<text>` contents of an SVG.
    fn svg_texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .filter_map(|r| {
                Some(
                    r.split_once('>')?
                        .1
                        .split("</text>")
                        .next()?
                        .trim()
                        .to_owned(),
                )
            })
            .collect()
    }

    #[test]
    fn a_pressure_plot_names_its_series_and_ticks_in_mpa() {
        let mut trace = Vec::new();
        crate::synth::write_candump(
            &mut trace,
            &crate::synth::SynthConfig {
                frames: 4000,
                ..Default::default()
            },
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("p.svg");
        let opts = PlotOptions {
            signals: vec!["AuxValveMeasured_Boom.ExtendPortPressure".to_owned()],
            preset: Some(Preset::Dig),
            ..Default::default()
        };
        plot_trace(trace.as_slice(), &out, &opts, &mut std::io::sink()).unwrap();
        let texts = svg_texts(&std::fs::read_to_string(&out).unwrap());
        // Every series named, the single one too.
        for name in [
            "AuxValveMeasured_Boom.ExtendPortPressure",
            "boom head",
            "stick",
            "Autodig stage: dig",
        ] {
            assert!(texts.iter().any(|t| t == name), "{name} not in {texts:?}");
        }
        assert!(texts.iter().any(|t| t == "[MPa]"), "{texts:?}");
        assert!(texts.iter().any(|t| t == "pressure [MPa]"), "{texts:?}");
        // No tick like 35000000.0 or 10.0.
        for t in &texts {
            if let Ok(v) = t.parse::<f64>() {
                assert!(v.abs() < 1e4 && !t.ends_with(".0"), "tick {t}");
            }
        }
    }

    #[test]
    fn degenerate_ranges_are_widened() {
        let (a, b) = padded(2.0, 2.0);
        assert!(a < 2.0 && b > 2.0);
        assert_eq!(padded(f64::NAN, 1.0), (0.0, 1.0));
    }
}
