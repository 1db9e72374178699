//! Thesis Fig. 52 (5.2) with the dig model, the way the thesis made it (the dig model's part of
//! `excavator-ctl experiment fig52`).
//!
//! "The model of the digging process was used to generate a trajectory of the bucket through the
//! ground for two separate settings" of Autodig's soil hardness index, in a soft and in a much harder
//! soil, from the same start over the same terrain. The thesis states: in the soft soil both indices
//! fill the bucket, the higher one goes too deep and costs 60 % more time and 75 % more energy; in the
//! hard soil the lower index fills the bucket about half, the higher one fully.
//!
//! Here: the planner's dig model ([`planner::dig_model`]: actuator networks, modified FEE soil of Eqs.
//! 14-18 with bearing, the same Autodig code), Table 2's start on the default bench, hardness index 1
//! and 5, soils that differ in cohesion only. The thesis does not give its two soils, so the report
//! prints the whole cohesion sweep ([`SWEEP_COHESION_PA`]) before the chosen pair; the default pair
//! (6 and 12 kPa, the same 1:2 ratio as the simulator's) was read off that sweep
//! (docs/models.md, "Fig. 52").

use std::path::Path;

use anyhow::{Context as _, bail};
use clap::Args;
use planner::dig_model::{DigEnd, DigModel, DigPrediction, DigSite, DigStart, SoilModel};
use serde::Serialize;

use super::start::{ModelStartArgs, default_section, default_site, predicted_tip_path};
use crate::plots::{TipCurve, write_tip_paths};
use crate::thesis::{FULL_FILL, Fig52Checks, HALF_FILL, THESIS_SOFT_COST, pct, write_checks};

/// The cohesions of the printed sweep, Pa (the dig model's soil, config/dig_model.toml, is 8 kPa).
pub const SWEEP_COHESION_PA: [f64; 7] = [4e3, 6e3, 8e3, 12e3, 16e3, 24e3, 32e3];
/// The two Autodig soil hardness indices compared (the ends of the maps' range).
pub const INDICES: [f64; 2] = [1.0, 5.0];
/// The default soft and hard soils' cohesion, kPa (read off the sweep; see the module docs).
pub const SOIL_PAIR_KPA: (f64, f64) = (6.0, 12.0);

/// The soft and the hard soil of Fig. 52 with the dig model.
#[derive(Debug, Clone, Copy, PartialEq, Args)]
pub struct ModelSoils {
    /// Dig model: cohesion of the soft soil, kPa.
    #[arg(id = "model_soft_cohesion_kpa", long = "model-soft-cohesion-kpa", value_name = "KPA", default_value_t = SOIL_PAIR_KPA.0)]
    pub soft_cohesion_kpa: f64,
    /// Dig model: cohesion of the hard soil, kPa.
    #[arg(id = "model_hard_cohesion_kpa", long = "model-hard-cohesion-kpa", value_name = "KPA", default_value_t = SOIL_PAIR_KPA.1)]
    pub hard_cohesion_kpa: f64,
}

impl Default for ModelSoils {
    /// The command-line defaults ([`SOIL_PAIR_KPA`]).
    fn default() -> Self {
        Self {
            soft_cohesion_kpa: SOIL_PAIR_KPA.0,
            hard_cohesion_kpa: SOIL_PAIR_KPA.1,
        }
    }
}

/// One predicted dig of the figure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Fig52Dig {
    /// The soil's cohesion, Pa.
    pub cohesion_pa: f64,
    /// Autodig's soil hardness index.
    pub hardness_index: f64,
    /// Dig time, s.
    pub time_s: f64,
    /// Volume swept over the cutting edge, m^3.
    pub swept_volume_m3: f64,
    /// Swept volume over the bucket's capacity (can exceed 1: the excess spills).
    pub fill: f64,
    /// Energy, kJ.
    pub energy_kj: f64,
    /// Lowest tip height, base frame, m.
    pub min_tip_z_m: f64,
    /// What ended the dig.
    pub end: DigEnd,
}

/// The thesis's statements about Fig. 52 on `[index 1, index 5]` of the soft and of the hard soil.
#[must_use]
pub fn pair_checks(soft: &[Fig52Dig; 2], hard: &[Fig52Dig; 2]) -> Fig52Checks {
    let figures = |d: &Fig52Dig| (d.fill, d.time_s, d.energy_kj);
    Fig52Checks::from_figures(
        [figures(&soft[0]), figures(&soft[1])],
        [figures(&hard[0]), figures(&hard[1])],
    )
}

/// The dig model's dig from `start` over `site` in a soil of `cohesion_pa` (the model's analytical soil
/// otherwise) with Autodig's hardness `index`.
///
/// # Errors
/// A model whose soil is not the analytical one (Fig. 52 varies the soil's coefficients), a cohesion
/// or index the model refuses, or the dig model's errors.
pub fn predict(
    model: &DigModel,
    cohesion_pa: f64,
    index: f64,
    start: &DigStart,
    site: &DigSite,
) -> anyhow::Result<(Fig52Dig, DigPrediction)> {
    let mut m = model.clone();
    let SoilModel::Analytical(mut soil) = m.config().soil else {
        bail!(
            "Fig. 52 varies the analytical soil's cohesion; this model's soil is the empirical one"
        );
    };
    soil.cohesion_pa = cohesion_pa;
    m.set_soil(SoilModel::Analytical(soil))
        .with_context(|| format!("cohesion {cohesion_pa} Pa"))?;
    m.set_hardness_index(index)
        .with_context(|| format!("hardness index {index}"))?;
    let capacity_m3 = m.config().autodig.perception.bucket_capacity_m3;
    let p = m.predict(start, site)?;
    let s = &p.summary;
    Ok((
        Fig52Dig {
            cohesion_pa,
            hardness_index: index,
            time_s: s.time_s,
            swept_volume_m3: s.swept_volume_m3,
            fill: s.swept_volume_m3 / capacity_m3,
            energy_kj: s.energy_kj(),
            min_tip_z_m: s.min_tip_z_m,
            end: s.end,
        },
        p,
    ))
}

/// Index 1 and index 5 in a soil of `cohesion_pa`.
///
/// # Errors
/// As [`predict`].
pub fn pair(
    model: &DigModel,
    cohesion_pa: f64,
    start: &DigStart,
    site: &DigSite,
) -> anyhow::Result<[(Fig52Dig, DigPrediction); 2]> {
    Ok([
        predict(model, cohesion_pa, INDICES[0], start, site)?,
        predict(model, cohesion_pa, INDICES[1], start, site)?,
    ])
}

/// The cohesion grid of the pattern bands: from, to, step, Pa.
pub const BAND_GRID_PA: (f64, f64, f64) = (1e3, 32e3, 1e3);

/// The cohesions of [`BAND_GRID_PA`] at which the soft-soil half of the thesis's statements holds (both
/// indices fill, index 5 costs time and energy) and those at which the hard-soil half holds (index 1
/// about half, index 5 full).
///
/// # Errors
/// As [`predict`].
pub fn bands(
    model: &DigModel,
    start: &DigStart,
    site: &DigSite,
) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let (from, to, step) = BAND_GRID_PA;
    let mut soft = Vec::new();
    let mut hard = Vec::new();
    // Integer steps: no accumulated rounding in the grid.
    let n = ((to - from) / step).round() as u32;
    for k in 0..=n {
        let c = from + step * f64::from(k);
        let [(lo, _), (hi, _)] = pair(model, c, start, site)?;
        let checks = pair_checks(&[lo, hi], &[lo, hi]);
        if checks.soft_both_full && checks.soft_high_index_costs {
            soft.push(c);
        }
        if checks.hard_low_index_half && checks.hard_high_index_full {
            hard.push(c);
        }
    }
    Ok((soft, hard))
}

/// Grid cohesions as contiguous kPa ranges, e.g. "1-8 kPa, 10 kPa", or "none".
fn ranges_kpa(cohesions_pa: &[f64]) -> String {
    let step = BAND_GRID_PA.2;
    let mut parts: Vec<(f64, f64)> = Vec::new();
    for &c in cohesions_pa {
        match parts.last_mut() {
            Some((_, hi)) if (c - *hi - step).abs() < 1e-6 * step => *hi = c,
            _ => parts.push((c, c)),
        }
    }
    if parts.is_empty() {
        return "none".to_string();
    }
    parts
        .iter()
        .map(|&(lo, hi)| {
            if lo == hi {
                format!("{:.0} kPa", lo / 1e3)
            } else {
                format!("{:.0}-{:.0} kPa", lo / 1e3, hi / 1e3)
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn change(from: f64, to: f64) -> String {
    format!("{:+.0} %", 100.0 * (to / from - 1.0))
}

/// The four checks on the soft and hard soils of `soils_kpa` (cohesion) from `start`.
///
/// # Errors
/// As [`predict`].
pub fn checks(
    model: &DigModel,
    soils_kpa: (f64, f64),
    start: &DigStart,
    site: &DigSite,
) -> anyhow::Result<Fig52Checks> {
    let soft = pair(model, soils_kpa.0 * 1e3, start, site)?;
    let hard = pair(model, soils_kpa.1 * 1e3, start, site)?;
    Ok(pair_checks(
        &[soft[0].0, soft[1].0],
        &[hard[0].0, hard[1].0],
    ))
}

/// Fig. 52 with the dig model from `start` (the dig model's part of `experiment fig52`): the cohesion
/// sweep, the bands where each half of the figure holds, the pair `soils` next to the thesis, the
/// checks and, with `out`, the four predicted tip paths in `out/fig52_model.svg`.
///
/// # Errors
/// As [`predict`]; writing the plot.
pub fn report(
    start_args: &ModelStartArgs,
    soils: &ModelSoils,
    out_dir: Option<&Path>,
) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let model = start_args.load_model()?;
    let site = default_site()?;
    let start = start_args.start(&site)?;
    let mut out = String::new();
    writeln!(
        out,
        "Fig. 52 with the dig model ({}; soils differ in cohesion only)\n",
        start_args.describe()
    )?;
    writeln!(
        out,
        "Sweep: fill of the bucket (swept volume / capacity), time, energy, lowest tip z\n"
    )?;
    writeln!(
        out,
        "| cohesion | index 1 | index 5 | index 5 vs 1: time, energy |"
    )?;
    writeln!(out, "|---|---|---|---|")?;
    let cell = |d: &Fig52Dig| {
        format!(
            "{}, {:.2} s, {:.0} kJ, {:.2} m",
            pct(d.fill),
            d.time_s,
            d.energy_kj,
            d.min_tip_z_m
        )
    };
    for c in SWEEP_COHESION_PA {
        let [(lo, _), (hi, _)] = pair(&model, c, &start, &site)?;
        writeln!(
            out,
            "| {:.0} kPa | {} | {} | {}, {} |",
            c / 1e3,
            cell(&lo),
            cell(&hi),
            change(lo.time_s, hi.time_s),
            change(lo.energy_kj, hi.energy_kj)
        )?;
    }
    let (soft_band, hard_band) = bands(&model, &start, &site)?;
    writeln!(
        out,
        "\nOn a {:.0} kPa grid from {:.0} to {:.0} kPa, the soft-soil pattern (both fill, index 5 costs time \
         and energy) holds at {}; the hard-soil pattern (index 1 {}-{}, index 5 >= {}) at {}.",
        BAND_GRID_PA.2 / 1e3,
        BAND_GRID_PA.0 / 1e3,
        BAND_GRID_PA.1 / 1e3,
        ranges_kpa(&soft_band),
        pct(HALF_FILL.0),
        pct(HALF_FILL.1),
        pct(FULL_FILL),
        ranges_kpa(&hard_band)
    )?;
    let soft = pair(&model, soils.soft_cohesion_kpa * 1e3, &start, &site)?;
    let hard = pair(&model, soils.hard_cohesion_kpa * 1e3, &start, &site)?;
    let s = [soft[0].0, soft[1].0];
    let h = [hard[0].0, hard[1].0];
    writeln!(
        out,
        "\nFig. 52: soft soil {:.1} kPa, hard soil {:.1} kPa\n",
        soils.soft_cohesion_kpa, soils.hard_cohesion_kpa
    )?;
    writeln!(out, "| | dig model | thesis |")?;
    writeln!(out, "|---|---|---|")?;
    writeln!(
        out,
        "| soft: fill index 1 / 5 | {} / {} | full / full |",
        pct(s[0].fill),
        pct(s[1].fill)
    )?;
    writeln!(
        out,
        "| soft: index 5's extra time, energy | {}, {} | {:+.0} %, {:+.0} % |",
        change(s[0].time_s, s[1].time_s),
        change(s[0].energy_kj, s[1].energy_kj),
        100.0 * THESIS_SOFT_COST.0,
        100.0 * THESIS_SOFT_COST.1
    )?;
    writeln!(
        out,
        "| soft: lowest tip z index 1 / 5 | {:.2} / {:.2} m | index 5 \"too deep\" |",
        s[0].min_tip_z_m, s[1].min_tip_z_m
    )?;
    writeln!(
        out,
        "| hard: fill index 1 / 5 | {} / {} | 50 % / full |",
        pct(h[0].fill),
        pct(h[1].fill)
    )?;
    let checks = pair_checks(&s, &h);
    write_checks(&mut out, checks.statements());
    if let Some(dir) = out_dir {
        let section = default_section()?;
        let curves = |digs: &[(Fig52Dig, DigPrediction); 2]| {
            digs.iter()
                .map(|(d, p)| TipCurve {
                    label: format!(
                        "index {:.0}: {} full, {:.2} s, {:.0} kJ",
                        d.hardness_index,
                        pct(d.fill),
                        d.time_s,
                        d.energy_kj
                    ),
                    path: predicted_tip_path(p),
                    section: section.clone(),
                })
                .collect::<Vec<_>>()
        };
        let panels = [
            (
                format!("soft soil, cohesion {:.1} kPa", soils.soft_cohesion_kpa),
                curves(&soft),
            ),
            (
                format!("hard soil, cohesion {:.1} kPa", soils.hard_cohesion_kpa),
                curves(&hard),
            ),
        ];
        let path = write_tip_paths(
            dir,
            "fig52_model.svg",
            "Fig. 52 with the dig model: hardness index 1 and 5 in a soft and a hard soil",
            &panels,
        )?;
        writeln!(
            out,
            "\nTrajectories (the predicted tip over the bench section): {}",
            path.display()
        )?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped dig model at the command's defaults shows three of the thesis's Fig. 52 statements:
    /// in the soft soil both indices fill and index 5 costs time and energy; in the hard soil index 5
    /// fills. Its index 1 fills less in the hard soil than index 5 there and than itself in the soft
    /// soil, but more than half (docs/models.md, "Fig. 52": no cohesion on the sweep shows both hard
    /// soil statements with these networks).
    #[test]
    fn the_shipped_dig_model_shows_fig52s_pattern_but_for_the_half_fill() {
        let (a, soils) = (ModelStartArgs::default(), ModelSoils::default());
        let model = a.load_model().unwrap();
        let site = default_site().unwrap();
        let start = a.start(&site).unwrap();
        let soft = pair(&model, soils.soft_cohesion_kpa * 1e3, &start, &site).unwrap();
        let hard = pair(&model, soils.hard_cohesion_kpa * 1e3, &start, &site).unwrap();
        let checks = pair_checks(&[soft[0].0, soft[1].0], &[hard[0].0, hard[1].0]);
        let figures = format!(
            "{checks:?}: soft {:?} / {:?}, hard {:?} / {:?}",
            soft[0].0, soft[1].0, hard[0].0, hard[1].0
        );
        assert!(
            checks.soft_both_full && checks.soft_high_index_costs && checks.hard_high_index_full,
            "{figures}"
        );
        assert!(
            hard[0].0.fill < hard[1].0.fill && hard[0].0.fill < soft[0].0.fill,
            "{figures}"
        );
    }

    /// The checks are not true of any four digs: the soft soil's pair fails the hard soil's checks.
    #[test]
    fn the_checks_tell_a_soft_soil_from_a_hard_one() {
        let dig = |fill, time_s, energy_kj| Fig52Dig {
            cohesion_pa: 6e3,
            hardness_index: 1.0,
            time_s,
            swept_volume_m3: 1.5 * fill,
            fill,
            energy_kj,
            min_tip_z_m: -1.0,
            end: DigEnd::TimeLimit,
        };
        let soft = [dig(1.3, 3.0, 200.0), dig(1.9, 4.5, 230.0)];
        let hard = [dig(0.5, 3.0, 200.0), dig(0.9, 4.0, 300.0)];
        assert!(pair_checks(&soft, &hard).all());
        let c = pair_checks(&soft, &soft);
        assert!(!c.hard_low_index_half && c.hard_high_index_full && !c.all());
        let c = pair_checks(&hard, &hard);
        assert!(!c.soft_both_full && c.soft_high_index_costs);
        // A cheaper index 5 in the soft soil is not the thesis's figure.
        let cheap = [dig(1.3, 3.0, 200.0), dig(1.9, 2.5, 230.0)];
        assert!(!pair_checks(&cheap, &hard).soft_high_index_costs);
    }

    /// Bad input is a clear error, never a panic: a cohesion that is negative or not a number, a start
    /// outside the bench's section or out of the machine's reach.
    #[test]
    fn bad_soils_and_starts_are_errors() {
        let start = ModelStartArgs::default();
        let model = start.load_model().unwrap();
        let site = default_site().unwrap();
        let dig_start = start.start(&site).unwrap();
        for c in [-1e3, f64::NAN, f64::INFINITY] {
            let e = predict(&model, c, 1.0, &dig_start, &site).unwrap_err();
            assert!(format!("{e:#}").contains("cohesion"), "{e:#}");
        }
        assert!(predict(&model, 6e3, f64::NAN, &dig_start, &site).is_err());
        for r in [30.0, 2.0] {
            let a = ModelStartArgs {
                start_r: r,
                ..ModelStartArgs::default()
            };
            let e = report(&a, &ModelSoils::default(), None);
            assert!(e.is_err(), "start r = {r} m");
        }
    }

    #[test]
    fn ranges_join_neighbouring_grid_points() {
        assert_eq!(ranges_kpa(&[]), "none");
        assert_eq!(
            ranges_kpa(&[1e3, 2e3, 3e3, 5e3, 7e3, 8e3]),
            "1-3 kPa, 5 kPa, 7-8 kPa"
        );
    }

    /// With an output folder the report writes the figure with both soils' panels, and the report names every check.
    #[test]
    fn fig52_writes_the_figure_and_the_checks() {
        let dir = tempfile::tempdir().unwrap();
        let text = report(
            &ModelStartArgs::default(),
            &ModelSoils::default(),
            Some(dir.path()),
        )
        .unwrap();
        for c in SWEEP_COHESION_PA {
            assert!(text.contains(&format!("| {:.0} kPa |", c / 1e3)), "{text}");
        }
        assert_eq!(
            text.matches("as in the thesis").count()
                + text.matches("differs from the thesis").count(),
            4,
            "{text}"
        );
        let svg = std::fs::read_to_string(dir.path().join("fig52_model.svg")).unwrap();
        assert!(
            svg.contains("soft soil, cohesion 6.0 kPa")
                && svg.contains("hard soil, cohesion 12.0 kPa")
        );
        assert_eq!(svg.matches("index 1:").count(), 2);
    }
}
