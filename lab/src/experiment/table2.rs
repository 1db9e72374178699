//! Thesis Table 2 (4.4): the soil force scaled by 1, 2 and 3, in the simulator and the dig model.

use super::*;

/// Table 2's soil of force factor 1: the default bench's soil with cohesion and density scaled by this.
pub const TABLE2_BASE_SCALE: f64 = 1.0;

/// Table 2 rows: `(force factor, mean)`, perception on, default start, base soil
/// [`TABLE2_BASE_SCALE`].
///
/// # Errors
/// As [`run_dig`].
pub fn table2(seeds: u64) -> anyhow::Result<Vec<(f64, Mean)>> {
    table2_with(
        seeds,
        &AutodigMaps::builtin()?,
        TABLE2_BASE_SCALE,
        Table2Scaling::Soil,
        SoilContactIntegration::default(),
    )
}

/// [`table2`] with the given maps and base soil scale.
///
/// # Errors
/// As [`run_dig`]; a base scale that is not finite and positive.
pub fn table2_with(
    seeds: u64,
    maps: &AutodigMaps,
    base_scale: f64,
    scaling: Table2Scaling,
    contact: SoilContactIntegration,
) -> anyhow::Result<Vec<(f64, Mean)>> {
    anyhow::ensure!(
        base_scale.is_finite() && base_scale > 0.0,
        "--base-scale {base_scale}: must be finite and positive"
    );
    let base = SimConfig::load::<&str>(None, None, None, &[])?;
    let config = ControllerConfig::default();
    let start = default_start();
    let mut rows = Vec::new();
    for k in [1.0, 2.0, 3.0] {
        let mut sim = base.clone();
        sim.scenario.soil_contact = contact;
        match scaling {
            Table2Scaling::Force => {
                scale_soil(&mut sim, base_scale);
                sim.scenario.soil_force_factor = Some(k);
            }
            Table2Scaling::Soil => scale_soil(&mut sim, k * base_scale),
        }
        rows.push((k, runs(seeds, &sim, &config, maps, start)?));
    }
    Ok(rows)
}

pub(super) fn scale_soil(sim: &mut SimConfig, k: f64) {
    sim.scenario.soil.cohesion_pa *= k;
    sim.scenario.soil.density_kg_per_m3 *= k;
    for r in &mut sim.scenario.soil_regions {
        r.soil.cohesion_pa *= k;
        r.soil.density_kg_per_m3 *= k;
    }
}

/// Table 2 in the simulator: the table next to the thesis's and the checks.
#[must_use]
pub fn table2_markdown(rows: &[(f64, Mean)], runs: u64, options: &Table2Options) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Table 2: soil force x1, x2, x3 ({}, base soil scaled by {}; {runs} digs each)\n",
        match options.scaling {
            Table2Scaling::Force => "the soil's force on the bucket times the factor",
            Table2Scaling::Soil => "cohesion and density times the factor",
        },
        options.base_scale,
    );
    let _ = writeln!(
        s,
        "| factor | time | swept volume | energy | payload | thesis: time, volume, energy |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for ((k, m), t) in rows.iter().zip(THESIS_TABLE2) {
        let _ = writeln!(
            s,
            "| {k:.1} | {:.2} s | {:.2} m^3 | {:.0} kJ | {:.0} kg | {} s, {} m^3, {} kJ |",
            m.time_s, m.swept_volume_m3, m.energy_kj, m.payload_kg, t.1, t.2, t.3
        );
    }
    let figures = |m: &Mean| (m.time_s, m.swept_volume_m3, m.energy_kj);
    if let [(_, a), (_, b), (_, c)] = rows {
        write_checks(&mut s, table2_checks([figures(a), figures(b), figures(c)]));
    }
    s
}

pub(super) fn table2_report(a: &Table2Args) -> anyhow::Result<String> {
    let rows = table2_with(
        a.sim.runs,
        &a.sim.autodig_maps()?,
        a.table2.base_scale,
        a.table2.scaling,
        a.sim.soil_contact.into(),
    )?;
    let mut s = format!("{SIM_SECTION}{}", contact_note(&a.sim));
    s.push_str(&table2_markdown(&rows, a.sim.runs, &a.table2));
    let curves = rows
        .iter()
        .map(|(k, m)| curve(format!("force factor {k:.0}"), m))
        .collect();
    s.push_str(&write_figure(
        &a.out.out,
        "fig39.svg",
        "Fig. 39 / Table 2: the same dig at three soil force levels",
        &[(String::new(), curves)],
    )?);
    s.push_str(MODEL_SECTION);
    s.push_str(&crate::model::table2::report(&a.model, Some(&a.out.out))?);
    Ok(s)
}
