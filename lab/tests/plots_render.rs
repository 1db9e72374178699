//! Every plot of a demo session rendered to PNG (resvg) and checked for what a reader needs: the
//! terrain maps' colour bar spans the data, legends sit inside the image and beside the plot area,
//! the files stay small. `write_docs_plots` (ignored) renders the plots of `demo --digs 30 --seed 1`
//! into docs/plots/ (docs/demo-output.md).

#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::sync::atomic::AtomicBool;

use clap::Parser as _;
use lab::demo::{DemoArgs, run_session};
use lab::plots::{ElevationScale, MachineTrack, terrain_svg};
use planner::terrain::TerrainGrid;
use resvg::tiny_skia::Pixmap;

/// The largest SVG a session plot may be, bytes (the maps' cells dominate).
const MAX_SVG_BYTES: u64 = 1_500_000;
/// The largest trajectories plot, bytes (decimated curves, no per-dig legend).
const MAX_TRAJECTORIES_BYTES: u64 = 400_000;

/// The legend and colour-bar titles of the session plots (besides the colour bars' `x.xx m`).
const LEGEND_TEXTS: [&str; 7] = [
    "cleanup",
    "tip path",
    "terrain before",
    "dig number",
    "elevation [m]",
    "track back",
    "thesis Table 4 mean",
];

/// `excavator-ctl demo`'s arguments from its command line.
#[derive(clap::Parser)]
struct Demo {
    #[command(flatten)]
    args: DemoArgs,
}

fn demo(out: &Path, digs: &str, seed: &str) {
    let args = Demo::try_parse_from([
        "demo",
        "--digs",
        digs,
        "--seed",
        seed,
        "--out",
        out.to_str().unwrap(),
    ])
    .unwrap()
    .args;
    run_session(&args, &AtomicBool::new(false)).unwrap();
}

fn render(svg: &str) -> Pixmap {
    let mut opt = resvg::usvg::Options::default();
    let fonts = opt.fontdb_mut();
    fonts.load_system_fonts();
    // The plots ask for "sans-serif", which fontdb maps to Arial unless told otherwise.
    if let Some(family) = ["DejaVu Sans", "Liberation Sans"].into_iter().find(|name| {
        fonts
            .faces()
            .any(|f| f.families.iter().any(|(n, _)| n == name))
    }) {
        fonts.set_sans_serif_family(family);
    }
    let tree = resvg::usvg::Tree::from_str(svg, &opt).unwrap();
    let size = tree.size().to_int_size();
    let mut pixmap = Pixmap::new(size.width(), size.height()).unwrap();
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pixmap.as_mut(),
    );
    pixmap
}

/// The `(x, y, text)` of every `<text>` element of `svg`.
fn texts(svg: &str) -> Vec<(f64, f64, String)> {
    let attr = |tag: &str, name: &str| -> Option<f64> {
        let at = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        tag[at..].split('"').next()?.parse().ok()
    };
    svg.split("<text")
        .skip(1)
        .filter_map(|rest| {
            let (tag, body) = rest.split_once('>')?;
            let text = body.split("</text>").next()?.trim().to_owned();
            Some((attr(tag, "x")?, attr(tag, "y")?, text))
        })
        .collect()
}

/// The `width` and `height` of `svg`'s root.
fn size_of(svg: &str) -> (f64, f64) {
    let root = svg.split('>').next().unwrap();
    let get = |name: &str| -> f64 {
        let at = root.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        root[at..].split('"').next().unwrap().parse().unwrap()
    };
    (get("width"), get("height"))
}

/// The colour bar's labels (`-2.00 m`) of a map, lowest and highest.
fn bar_ends(svg: &str) -> (f64, f64) {
    let values: Vec<f64> = texts(svg)
        .iter()
        .filter_map(|(_, _, t)| t.strip_suffix(" m")?.parse().ok())
        .collect();
    assert!(values.len() >= 2, "no colour bar labels");
    values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        })
}

/// Distinct colours in the rendered image.
fn colours(p: &Pixmap) -> usize {
    let mut seen: Vec<[u8; 3]> = p
        .pixels()
        .iter()
        .map(|c| [c.red(), c.green(), c.blue()])
        .collect();
    seen.sort_unstable();
    seen.dedup();
    seen.len()
}

#[test]
fn the_terrain_map_colours_span_the_excavation_and_show_the_machine_where_it_is() {
    // A bench cut to -2 m in front of the machine, a spoil pile at +1.5 m, the machine tracked back
    // to x = -13 m.
    let terrain = TerrainGrid::from_fn(-30.0, -15.0, 0.1, 500, 300, |x, y| {
        if (3.0..9.0).contains(&x) && y.abs() < 4.0 {
            -2.0
        } else if (x - 2.0).hypot(y + 7.0) < 1.5 {
            1.5
        } else {
            0.0
        }
    })
    .unwrap();
    let scale = ElevationScale::spanning([&terrain]);
    assert_eq!((scale.lo_m, scale.hi_m), (-2.0, 1.5));
    let track = MachineTrack::default()
        .at([0.0, 0.0, 0.0])
        .at([-13.0, 0.0, 0.0]);
    let svg = terrain_svg(&terrain, scale, &track, "test").unwrap();
    let (lo, hi) = bar_ends(&svg);
    assert!(
        lo <= -2.0 && hi >= 1.5 && hi - lo <= 3.6,
        "colour bar {lo}..{hi}"
    );
    // The map's x ticks reach the machine at -13 m.
    let min_x_tick = texts(&svg)
        .iter()
        .filter_map(|(_, _, t)| t.parse::<f64>().ok())
        .fold(f64::INFINITY, f64::min);
    assert!(min_x_tick <= -13.0, "the map stops at {min_x_tick} m");
    let png = render(&svg);
    // Pit, ground, pile and the colour bar's gradient: many colours, not one square.
    assert!(colours(&png) > 30, "{} colours", colours(&png));
}

#[test]
fn every_session_plot_renders_with_its_legends_beside_the_plot_area() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    demo(&out, "6", "1");
    let mut seen = 0;
    for entry in std::fs::read_dir(&out).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "svg") {
            continue;
        }
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        let svg = std::fs::read_to_string(&path).unwrap();
        let bytes = svg.len() as u64;
        let bound = if name == "trajectories.svg" {
            MAX_TRAJECTORIES_BYTES
        } else {
            MAX_SVG_BYTES
        };
        assert!(bytes <= bound, "{name}: {bytes} bytes");
        let png = render(&svg);
        let (w, h) = size_of(&svg);
        assert_eq!((f64::from(png.width()), f64::from(png.height())), (w, h));
        for (x, y, t) in texts(&svg) {
            assert!(
                (0.0..w).contains(&x) && (0.0..h).contains(&y),
                "{name}: {t:?} at ({x}, {y}) outside {w}x{h}"
            );
        }
        // Legend entries stand in the strip right of the plot area.
        let strip_px = match name.as_str() {
            "trajectories.svg" | "terrain_before.svg" | "terrain_after.svg" => 110.0,
            n if n.starts_with("bench_after_") => 110.0,
            "dig_stats.svg" | "dig_sequence.svg" => 150.0,
            _ => continue,
        };
        let mut legend_texts = 0;
        for (x, _, t) in texts(&svg) {
            let legend = LEGEND_TEXTS.contains(&t.as_str())
                || t.starts_with("half full")
                || t.ends_with(" m") && t.contains('.');
            if legend {
                legend_texts += 1;
                assert!(
                    x >= w - strip_px,
                    "{name}: legend {t:?} at x {x} over the plot"
                );
            }
        }
        assert!(legend_texts >= 2, "{name}: no legend");
        if name.starts_with("terrain_") || name.starts_with("bench_after_") {
            assert!(colours(&png) > 20, "{name}: {} colours", colours(&png));
        }
        seen += 1;
    }
    assert!(seen >= 6, "{seen} plots");
}

#[test]
fn the_bench_snapshots_and_terrain_maps_share_one_colour_scale() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    demo(&out, "6", "2");
    let ends = |name: &str| bar_ends(&std::fs::read_to_string(out.join(name)).unwrap());
    let before = ends("terrain_before.svg");
    assert_eq!(ends("terrain_after.svg"), before);
    let benches: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| {
            let n = e.unwrap().file_name().into_string().unwrap();
            n.starts_with("bench_after_").then_some(n)
        })
        .collect();
    assert!(!benches.is_empty());
    for b in benches {
        assert_eq!(ends(&b), before, "{b}");
    }
}

/// Renders the plots of `demo --digs 30 --seed 1` into docs/plots/ as PNG (docs/demo-output.md):
/// `cargo test --profile checked -p lab --test plots_render -- --ignored write_docs_plots`.
#[test]
#[ignore = "writes docs/plots/"]
fn write_docs_plots() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    demo(&out, "30", "1");
    let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/plots");
    std::fs::create_dir_all(&docs).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.unwrap().file_name().into_string().ok())
        .filter(|n| n.ends_with(".svg"))
        .collect();
    names.sort();
    for name in names {
        let svg = std::fs::read_to_string(out.join(&name)).unwrap();
        let png = docs.join(name.replace(".svg", ".png"));
        render(&svg).save_png(&png).unwrap();
        println!("{}", png.display());
    }
}
