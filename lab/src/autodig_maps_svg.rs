//! The Autodig map figures of docs/autodig.md (thesis Figs. 10-11): each map's command against the
//! head pressure of its input cylinder, one curve per soil hardness index. Written by
//! `cargo run -p lab --example autodig_maps -- docs`.

use planner::autodig::{AutodigMaps, Curve, MapKind};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The file docs/autodig.md shows map `kind` from.
#[must_use]
pub fn file_name(kind: MapKind) -> &'static str {
    match kind {
        MapKind::PreDigBoom => "autodig_predig_boom.svg",
        MapKind::PreDigStick => "autodig_predig_stick.svg",
        MapKind::DigBoom => "autodig_dig_boom.svg",
        MapKind::DigBucket => "autodig_dig_bucket.svg",
    }
}

/// Writes the four map figures into `dir` ([`file_name`]) and returns their paths.
///
/// # Errors
/// Writing a file.
pub fn write_map_svgs(maps: &AutodigMaps, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    MapKind::ALL
        .into_iter()
        .map(|kind| {
            let path = dir.join(file_name(kind));
            std::fs::write(&path, map_svg(maps, kind))?;
            Ok(path)
        })
        .collect()
}

/// An SVG plot (std only) of map `kind` of `maps` for every hardness index: x = percent of relief
/// pressure (head port), y = percent command; one polyline and legend entry per curve.
#[must_use]
pub fn map_svg(maps: &AutodigMaps, kind: MapKind) -> String {
    const W: f64 = 520.0;
    const H: f64 = 300.0;
    const L: f64 = 60.0; // left margin
    const T: f64 = 30.0; // top margin
    const PW: f64 = 360.0;
    const PH: f64 = 220.0;
    const COLORS: [&str; 6] = [
        "#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02",
    ];
    let px = |x: f64| L + PW * x / 100.0;
    // y spans 0..100 unless some curve commands retraction, then -100..100.
    let any_negative = maps
        .predig_stick()
        .points()
        .iter()
        .chain(maps.curve_sets().iter().flat_map(|set| {
            [&set.predig_boom, &set.dig_boom, &set.dig_bucket]
                .into_iter()
                .flat_map(|c| c.points())
        }))
        .any(|p| p[1] < 0.0);
    let y_lo = if any_negative { -100.0 } else { 0.0 };
    let py = |y: f64| T + PH * (100.0 - y) / (100.0 - y_lo);
    let mut s = String::new();
    // Writing into a String cannot fail, so the fmt::Results below are ignored.
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{H}\" font-family=\"sans-serif\" font-size=\"11\">\n\
         <rect width=\"{W}\" height=\"{H}\" fill=\"white\"/>\n\
         <text x=\"{L}\" y=\"18\" font-size=\"12\">{}</text>\n",
        kind.title()
    );
    for v in [0.0, 25.0, 50.0, 75.0, 100.0] {
        let _ = writeln!(
            s,
            "<line x1=\"{0:.1}\" y1=\"{1:.1}\" x2=\"{0:.1}\" y2=\"{2:.1}\" stroke=\"#ddd\"/>\
             <text x=\"{0:.1}\" y=\"{3:.1}\" text-anchor=\"middle\">{v}</text>",
            px(v),
            T,
            T + PH,
            T + PH + 14.0
        );
    }
    let y_ticks = if any_negative {
        [-100.0, -50.0, 0.0, 50.0, 100.0]
    } else {
        [0.0, 25.0, 50.0, 75.0, 100.0]
    };
    for v in y_ticks {
        let _ = writeln!(
            s,
            "<line x1=\"{0:.1}\" y1=\"{1:.1}\" x2=\"{2:.1}\" y2=\"{1:.1}\" stroke=\"#ddd\"/>\
             <text x=\"{3:.1}\" y=\"{4:.1}\" text-anchor=\"end\">{v}</text>",
            L,
            py(v),
            L + PW,
            L - 6.0,
            py(v) + 4.0
        );
    }
    let _ = writeln!(
        s,
        "<rect x=\"{L}\" y=\"{T}\" width=\"{PW}\" height=\"{PH}\" fill=\"none\" stroke=\"black\"/>\n\
         <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">pressure, % of relief (head port)</text>\n\
         <text x=\"14\" y=\"{:.1}\" transform=\"rotate(-90 14 {:.1})\" text-anchor=\"middle\">command, % of max velocity</text>",
        L + PW / 2.0,
        H - 8.0,
        T + PH / 2.0,
        T + PH / 2.0
    );
    let curves: Vec<(String, &Curve)> = match kind {
        MapKind::PreDigStick => vec![("all indices".to_owned(), maps.predig_stick())],
        _ => maps
            .curve_sets()
            .iter()
            .map(|set| {
                let c = match kind {
                    MapKind::PreDigBoom => &set.predig_boom,
                    MapKind::DigBoom => &set.dig_boom,
                    _ => &set.dig_bucket,
                };
                (format!("index {}", set.index), c)
            })
            .collect(),
    };
    for (i, (label, c)) in curves.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let pts: Vec<String> = c
            .points()
            .iter()
            .map(|&[x, y]| format!("{:.1},{:.1}", px(x), py(y)))
            .collect();
        let _ = writeln!(
            s,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"2\"/>\n\
             <line x1=\"{2:.1}\" y1=\"{3:.1}\" x2=\"{4:.1}\" y2=\"{3:.1}\" stroke=\"{color}\" stroke-width=\"2\"/>\
             <text x=\"{5:.1}\" y=\"{6:.1}\">{1}</text>",
            pts.join(" "),
            label,
            L + PW + 12.0,
            T + 10.0 + 16.0 * i as f64,
            L + PW + 30.0,
            L + PW + 34.0,
            T + 14.0 + 16.0 * i as f64
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The polylines of a figure, each as its `[x, y]` points in SVG coordinates.
    fn polylines(svg: &str) -> Vec<Vec<[f64; 2]>> {
        svg.split("<polyline points=\"")
            .skip(1)
            .map(|rest| {
                rest.split('"')
                    .next()
                    .unwrap_or_default()
                    .split(' ')
                    .map(|xy| {
                        let (x, y) = xy.split_once(',').expect("x,y");
                        [x.parse().expect("x"), y.parse().expect("y")]
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn each_figure_draws_every_curve_of_its_map_in_the_plot_frame() {
        let maps = AutodigMaps::builtin().expect("shipped maps");
        let sets = maps.curve_sets();
        for kind in MapKind::ALL {
            let svg = map_svg(&maps, kind);
            assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
            assert!(svg.contains(kind.title()), "{kind:?}");
            let curves: Vec<&Curve> = match kind {
                MapKind::PreDigStick => vec![maps.predig_stick()],
                MapKind::PreDigBoom => sets.iter().map(|s| &s.predig_boom).collect(),
                MapKind::DigBoom => sets.iter().map(|s| &s.dig_boom).collect(),
                MapKind::DigBucket => sets.iter().map(|s| &s.dig_bucket).collect(),
            };
            // One polyline per curve, with a legend entry naming its hardness index.
            let lines = polylines(&svg);
            assert_eq!(lines.len(), curves.len(), "{kind:?}");
            if kind == MapKind::PreDigStick {
                assert!(svg.contains(">all indices</text>"));
            } else {
                for set in sets {
                    assert!(
                        svg.contains(&format!(">index {}</text>", set.index)),
                        "{kind:?}"
                    );
                }
            }
            // The shipped maps command retraction somewhere, so y spans -100..100 %: the plot frame
            // (x 60..420, y 30..250) maps x = p % to 60 + 3.6 p and y = c % to 140 - 1.1 c.
            assert!(svg.contains(">-100</text>"));
            for (line, curve) in lines.iter().zip(&curves) {
                assert_eq!(line.len(), curve.points().len());
                for (&[sx, sy], &[p, c]) in line.iter().zip(curve.points()) {
                    assert!(
                        (sx - (60.0 + 3.6 * p)).abs() <= 0.051,
                        "{kind:?} {p} -> {sx}"
                    );
                    assert!(
                        (sy - (140.0 - 1.1 * c)).abs() <= 0.051,
                        "{kind:?} {c} -> {sy}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_figures_are_written_under_the_names_the_docs_show() {
        let dir = tempfile::tempdir().expect("tempdir");
        let maps = AutodigMaps::builtin().expect("shipped maps");
        let paths = write_map_svgs(&maps, dir.path()).expect("write");
        assert_eq!(paths.len(), 4);
        let docs = include_str!("../../docs/autodig.md");
        for path in &paths {
            let name = path.file_name().and_then(|n| n.to_str()).expect("name");
            assert!(docs.contains(&format!("]({name})")), "{name}");
            assert!(
                std::fs::read_to_string(path)
                    .expect("read")
                    .starts_with("<svg")
            );
        }
    }
}
