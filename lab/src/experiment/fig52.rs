//! Thesis Fig. 52 (5.2): soft and hard soil at hardness index 1 and 5, with its checks.

use super::*;

/// The soft and hard soils of Fig. 52 (cohesion, Pa): the default bench's soil and twice its cohesion.
///
/// The default bench's 5 kPa is the nominal soil of the default (implicit) plant
/// (docs/simulator.md, "Soil contact integration"). The index matters between the default soil and
/// about three times its cohesion; much harder, the Boom-Down contact alone loads all three cylinders
/// to relief and both indices fill a quarter of the bucket. On the implicit plant (seeds 1-3, fill of
/// index 1 / index 5): soft 4 kPa 99 / 95 %, hard 8 kPa 73 / 100 %; soft 5 kPa 98 / 88 %, hard 10
/// kPa 55 / 91 %; soft 6 kPa 96 / 86 %, hard 12 kPa 44 / 76 %.
pub const FIG52_SOILS: [(&str, f64); 2] = [("soft", 5_000.0), ("hard", 10_000.0)];

/// Fig. 52 rows: `(soil, hardness index, mean)`.
///
/// # Errors
/// As [`run_dig`].
pub fn fig52(seeds: u64) -> anyhow::Result<Vec<(&'static str, f64, Mean)>> {
    fig52_with(
        seeds,
        &AutodigMaps::builtin()?,
        SoilContactIntegration::default(),
        FIG52_SOILS,
    )
}

/// [`fig52`] with the given maps, plant and `(name, cohesion Pa)` soils.
///
/// # Errors
/// A cohesion that is not finite and >= 0; as [`run_dig`].
pub fn fig52_with(
    seeds: u64,
    maps: &AutodigMaps,
    contact: SoilContactIntegration,
    soils: [(&'static str, f64); 2],
) -> anyhow::Result<Vec<(&'static str, f64, Mean)>> {
    let base = SimConfig::load::<&str>(None, None, None, &[])?;
    let start = default_start();
    let mut rows = Vec::new();
    for (name, cohesion) in soils {
        anyhow::ensure!(
            cohesion.is_finite() && cohesion >= 0.0,
            "Fig. 52's {name} soil: cohesion {cohesion} Pa must be finite and >= 0"
        );
        let mut sim = base.clone();
        sim.scenario.soil.cohesion_pa = cohesion;
        sim.scenario.soil_contact = contact;
        for index in [1.0, 5.0] {
            let mut config = ControllerConfig::default();
            config.autodig.hardness_index = index;
            rows.push((name, index, runs(seeds, &sim, &config, maps, start)?));
        }
    }
    Ok(rows)
}

/// The full bucket's payload of the default machine at its rated density, kg (Fig. 52's fill).
///
/// # Errors
/// Loading the built-in machine file.
pub fn full_bucket_kg() -> anyhow::Result<f64> {
    Ok(planner::machine::MachineConfig::default_machine()?.rated_payload_kg())
}

/// The thesis's statements about Fig. 52 on the simulator's rows (fill: payload over the full
/// bucket's `full_kg`).
#[must_use]
pub fn fig52_checks(rows: &[(&'static str, f64, Mean)], full_kg: f64) -> Fig52Checks {
    let figures = |soil: &str, index: f64| {
        rows.iter()
            .find(|r| r.0 == soil && r.1 == index)
            .map_or((0.0, 0.0, 0.0), |(_, _, m)| {
                (m.payload_kg / full_kg, m.time_s, m.energy_kj)
            })
    };
    Fig52Checks::from_figures(
        [figures("soft", 1.0), figures("soft", 5.0)],
        [figures("hard", 1.0), figures("hard", 5.0)],
    )
}

/// Fig. 52 in the simulator: the table, the thesis's figure in words and the checks (fill: payload
/// over `full_kg`).
#[must_use]
pub fn fig52_markdown(
    rows: &[(&'static str, f64, Mean)],
    runs: u64,
    soils: &Fig52Soils,
    full_kg: f64,
) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Fig. 52: hardness index 1 and 5 in soft (c = {} kPa) and hard (c = {} kPa) soil ({runs} digs each; \
         fill = payload / {full_kg:.0} kg)\n",
        soils.soft_cohesion_kpa, soils.hard_cohesion_kpa
    );
    let _ = writeln!(s, "| soil | index | fill | time | energy | swept volume |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (soil, index, m) in rows {
        let _ = writeln!(
            s,
            "| {soil} | {index:.0} | {:.0} % | {:.2} s | {:.0} kJ | {:.2} m^3 |",
            100.0 * m.payload_kg / full_kg,
            m.time_s,
            m.energy_kj,
            m.swept_volume_m3
        );
    }
    let _ = writeln!(
        s,
        "\nThesis: soft soil, both indices fill the bucket; the higher index digs too deep, +60 % time \
         and +75 % energy. Hard soil: the low index fills about 50 %, the high index fully. \
         The thesis made the figure with its dig model (the dig model's section)."
    );
    write_checks(&mut s, fig52_checks(rows, full_kg).statements());
    s
}

pub(super) fn fig52_report(a: &Fig52Args) -> anyhow::Result<String> {
    let soils = a.soils.pa();
    let rows = fig52_with(
        a.sim.runs,
        &a.sim.autodig_maps()?,
        a.sim.soil_contact.into(),
        soils,
    )?;
    let full_kg = full_bucket_kg()?;
    let mut s = format!("{SIM_SECTION}{}", contact_note(&a.sim));
    s.push_str(&fig52_markdown(&rows, a.sim.runs, &a.soils, full_kg));
    let panels: Vec<_> = soils
        .iter()
        .map(|(soil, cohesion)| {
            let curves = rows
                .iter()
                .filter(|r| r.0 == *soil)
                .map(|(_, index, m)| {
                    curve(
                        format!(
                            "index {index:.0}: fill {:.0} %",
                            100.0 * m.payload_kg / full_kg
                        ),
                        m,
                    )
                })
                .collect();
            (
                format!("{soil} soil (c = {:.0} kPa)", cohesion / 1000.0),
                curves,
            )
        })
        .collect();
    s.push_str(&write_figure(
        &a.out.out,
        "fig52.svg",
        "Fig. 52: Autodig's soil hardness index 1 and 5",
        &panels,
    )?);
    s.push_str(MODEL_SECTION);
    s.push_str(&crate::model::fig52::report(
        &a.model,
        &a.model_soils,
        Some(&a.out.out),
    )?);
    Ok(s)
}
