//! `experiment hardness-fit` (thesis Fig. 53): the soil hardness index against the cohesion.

/// Fits the hardness regression of 5.2 by simulation ([`planner::plan::hardness::fit_hardness_regression`]
/// on [`planner::plan::hardness::default_sweep`] with the nominal dig model and the shipped quality
/// settings) and writes `hardness_regression.toml` and `fig53.svg` into `out`.
///
/// # Errors
/// Dig model, sweep or fit errors; I/O.
pub fn hardness_fit(out: &std::path::Path) -> anyhow::Result<planner::plan::hardness::HardnessFit> {
    use anyhow::Context as _;
    let model = planner::dig_model::DigModel::nominal().context("nominal dig model")?;
    hardness_fit_with(&model, out, "excavator-ctl experiment hardness-fit", None)
}

/// As [`hardness_fit`] with the dig model `model` (`source` names it in the file's header); with
/// `origin` the regression records it (`[origin]`, as `excavator-ctl calibrate` writes it).
///
/// # Errors
/// As [`hardness_fit`].
pub fn hardness_fit_with<A: planner::dig_model::ActuatorDynamics + Clone>(
    model: &planner::dig_model::DigModel<A>,
    out: &std::path::Path,
    source: &str,
    origin: Option<planner::origin::ArtefactOrigin>,
) -> anyhow::Result<planner::plan::hardness::HardnessFit> {
    use anyhow::Context as _;
    use planner::plan::hardness::{default_sweep, fit_hardness_regression};
    let sweep = default_sweep()?;
    let planner_cfg = planner::plan::PlannerConfig::nominal()?;
    let mut quality = planner_cfg.quality;
    if quality.v_max_m3 <= 0.0 {
        quality.v_max_m3 = model.config().autodig.perception.bucket_capacity_m3;
    }
    let mut fit = fit_hardness_regression(model, &sweep, &quality)?;
    fit.regression.origin = origin;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let header = format!(
        "Autodig soil hardness index from the average soil force (thesis 5.2, Eq. 25, Fig. 53):\n\
         index = intercept + slope_per_kn x |F(Gamma_typical)| / 1 kN, clamped to [min_index, max_index].\n\
         Fitted by `{source}` (planner::plan::hardness::fit_hardness_regression\n\
         on default_sweep(): {} soils x {} terrains x {} indices, config/planner.toml quality).\n\
         The {}; the line is used where its slope is at least {} standard errors from zero.",
        sweep.soils.len(),
        sweep.terrains.len(),
        sweep.indices.len(),
        hardness_line_note(&fit.line),
        planner::plan::hardness::SLOPE_T_MIN,
    );
    let path = out.join("hardness_regression.toml");
    std::fs::write(&path, fit.regression.to_toml(&header))
        .with_context(|| format!("writing {}", path.display()))?;
    let points: Vec<(f64, f64)> = fit
        .points
        .iter()
        .map(|p| (p.average_force_n / 1e3, p.best_index))
        .collect();
    let path = out.join("fig53.svg");
    std::fs::write(
        &path,
        crate::plots::hardness_fit_svg(
            &points,
            fit.regression.intercept,
            fit.regression.slope_per_kn,
        )?,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(fit)
}

/// How the hardness sweep's least-squares line became the regression, for the reports.
#[must_use]
pub fn hardness_line_note(line: &planner::plan::hardness::HardnessLine) -> String {
    let fit = format!(
        "least-squares line {:.3} + {:.5} x force/kN, r^2 {:.3}, slope t {:.2}",
        line.intercept, line.slope_per_kn, line.r_squared, line.slope_t
    );
    if line.slope_t.abs() >= planner::plan::hardness::SLOPE_T_MIN {
        fit
    } else {
        format!(
            "{fit}: the slope is not significant (|t| < {}), so the mean optimal index",
            planner::plan::hardness::SLOPE_T_MIN
        )
    }
}

pub(super) fn hardness_fit_report(out: &std::path::Path) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let out = out.join("hardness");
    let t0 = std::time::Instant::now();
    let fit = hardness_fit(&out)?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Fig. 53: optimal Autodig index per soil and terrain against the average soil force (Eq. 25)\n\n\
         | soil | terrain | average force (kN) | optimal index | quality |\n|---|---|---|---|---|"
    );
    for p in &fit.points {
        let _ = writeln!(
            s,
            "| {} | {} | {:.1}{} | {:.1} | {:.2} |",
            p.soil,
            p.terrain,
            p.average_force_n / 1e3,
            if p.analytical_fallback {
                " (analytical)"
            } else {
                ""
            },
            p.best_index,
            p.best_quality
        );
    }
    let r = &fit.regression;
    let _ = writeln!(
        s,
        "\nindex = {:.3} + {:.5} x force/kN (r^2 {:.3}, {} cases; {}) in {:.1} s; thesis: the index rises with the force.\n\
         Outputs: {} (hardness_regression.toml, fig53.svg)",
        r.intercept,
        r.slope_per_kn,
        r.r_squared,
        r.cases,
        hardness_line_note(&fit.line),
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(s)
}
