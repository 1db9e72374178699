//! `excavator-ctl model soil-cv`: the thesis's soil-model cross-validation (4.3.5, Figs. 28-31) on
//! measured digs.
//!
//! During a planned or predefined `demo` session the soil monitor pairs, every other control period
//! of Autodig, the bucket's intersection with the pre-dig terrain section (`Gamma = (d, alpha, rho,
//! V_s)`, 4.3.4) with the soil force on the tip estimated from the cylinder pressures (Appendix A.2,
//! Eq. A23). `demo` writes those samples per dig to `soil_samples.json` ([`SoilSamplesFile`]); this
//! command predicts each dig from the soil properties estimated on the `--window` samples just
//! before it (the empirical model by least squares, Eqs. 21-23; the analytical modified FEE by
//! simulated annealing and Powell's method, Eq. 24) and reports the mean absolute force error as a
//! percentage of the peak force (thesis: about 10 % for both on the real machine).

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use planner::estimate::{
    AnalyticalFitConfig, CrossValidationReport, DEFAULT_WINDOW_SAMPLES, SoilModelKind, SoilSample,
    cross_validate,
};

use onboard::record::SoilSamplesFile;

/// `excavator-ctl model soil-cv`
#[derive(Debug, Args)]
pub struct SoilCvArgs {
    /// `soil_samples.json` of a `demo` session (`--strategy planned` or `predefined`).
    #[arg(long, value_name = "FILE")]
    pub samples: PathBuf,
    /// Estimation window, samples just before each dig (4.3.5: about 300).
    #[arg(long, default_value_t = DEFAULT_WINDOW_SAMPLES)]
    pub window: usize,
    /// Use only the first N digs with samples (the thesis used 23).
    #[arg(long, value_name = "N")]
    pub digs: Option<usize>,
    /// Machine file for the bucket width (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
}

/// One model's cross-validation.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelCv {
    /// Digs with samples the model was validated on.
    pub digs: usize,
    /// Samples over those digs.
    pub samples: usize,
    /// The report, or why the cross-validation failed.
    pub result: Result<CrossValidationReport, String>,
    /// Wall time, s.
    pub wall_s: f64,
}

/// Both models' cross-validation.
#[derive(Debug, Clone, PartialEq)]
pub struct SoilCv {
    /// The empirical model (Eq. 21) on every sample.
    pub empirical: ModelCv,
    /// The analytical model (Eqs. 14-19) on the samples in the static FEE's domain
    /// ([`planner::estimate::SoilBounds::fee_domain`]).
    pub analytical: ModelCv,
}

fn model_cv(digs: &[Vec<SoilSample>], window: usize, kind: &SoilModelKind) -> ModelCv {
    let digs: Vec<Vec<SoilSample>> = digs.iter().filter(|d| !d.is_empty()).cloned().collect();
    let t = Instant::now();
    let result = cross_validate(&digs, window, kind).map_err(|e| e.to_string());
    ModelCv {
        digs: digs.len(),
        samples: digs.iter().map(Vec::len).sum(),
        result,
        wall_s: t.elapsed().as_secs_f64(),
    }
}

/// Cross-validates both soil models on `digs` (each a dig's samples, in order). The analytical
/// model sees only the samples inside the static FEE's domain for its estimation box.
#[must_use]
pub fn soil_cv(digs: &[Vec<SoilSample>], window: usize, bucket_width_m: f64) -> SoilCv {
    let config = AnalyticalFitConfig {
        bucket_width_m,
        ..AnalyticalFitConfig::default()
    };
    let in_domain: Vec<Vec<SoilSample>> = digs
        .iter()
        .map(|d| {
            d.iter()
                .filter(|s| config.bounds.fee_domain(&s.geometry))
                .copied()
                .collect()
        })
        .collect();
    SoilCv {
        empirical: model_cv(digs, window, &SoilModelKind::Empirical),
        analytical: model_cv(&in_domain, window, &SoilModelKind::Analytical(config)),
    }
}

/// The report `soil-cv` prints.
#[must_use]
pub fn report(cv: &SoilCv, window: usize) -> String {
    let mut s = format!(
        "Soil-model cross-validation (thesis 4.3.5): window {window} samples before each dig\n\n\
         | model | digs | samples | MAE | peak force | MAE % of peak | std | time |\n\
         |---|---|---|---|---|---|---|---|\n"
    );
    for (name, m) in [
        ("empirical (Eq. 21)", &cv.empirical),
        ("analytical (Eqs. 14-19), FEE domain", &cv.analytical),
    ] {
        match &m.result {
            Ok(r) => s.push_str(&format!(
                "| {name} | {} | {} ({} not predictable) | {:.1} kN | {:.1} kN | {:.1} % | {:.1} kN | {:.2} s |\n",
                m.digs,
                m.samples,
                r.digs.iter().map(|d| d.unpredictable).sum::<usize>(),
                r.mae_n / 1e3,
                r.peak_force_n / 1e3,
                r.mae_percent_of_peak,
                r.std_n / 1e3,
                m.wall_s
            )),
            Err(e) => s.push_str(&format!(
                "| {name} | {} | {} | failed: {e} | | | | {:.2} s |\n",
                m.digs, m.samples, m.wall_s
            )),
        }
    }
    s.push_str("\n(thesis, real machine: about 10 % of the peak force for both models)\n");
    s
}

/// Runs `model soil-cv`.
///
/// # Errors
/// As [`SoilSamplesFile::read`] and [`soil_cv`]; an unreadable machine file.
pub fn run(args: &SoilCvArgs) -> anyhow::Result<()> {
    let file = SoilSamplesFile::read(&args.samples)?;
    let machine = planner::machine::MachineConfig::load_or_default(args.machine.as_deref())?;
    let mut digs: Vec<Vec<SoilSample>> = file
        .digs
        .into_iter()
        .map(|d| d.samples)
        .filter(|s| !s.is_empty())
        .collect();
    if let Some(n) = args.digs {
        digs.truncate(n);
    }
    let cv = soil_cv(&digs, args.window, machine.bucket.width_m);
    print!("{}", report(&cv, args.window));
    match &cv.empirical.result {
        Ok(_) => Ok(()),
        Err(e) => anyhow::bail!("empirical cross-validation failed: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner::soil::{DigGeometry, SoilProperties, fee_tip_force};

    const WIDTH_M: f64 = 1.5;

    fn soil() -> SoilProperties {
        SoilProperties {
            density_kg_per_m3: 1800.0,
            failure_angle_rad: 35f64.to_radians(),
            friction_angle_rad: 30f64.to_radians(),
            tool_friction_angle_rad: 18f64.to_radians(),
            cohesion_pa: 20e3,
        }
    }

    /// Digs of FEE forces (Eqs. 14-19) for `soil()` over a spread of geometries; with `far_back`,
    /// every other sample has its cutting face turned back beyond the static FEE's domain (its force
    /// a plausible measured one, not the FEE's).
    fn digs(far_back: bool) -> Vec<Vec<SoilSample>> {
        (0..6)
            .map(|k| {
                (0..60)
                    .map(|i| {
                        let t = f64::from(i) / 59.0;
                        let geometry = DigGeometry {
                            depth_m: 0.1 + 0.6 * t + 0.05 * f64::from(k),
                            slope_rad: (5.0 + 3.0 * f64::from(k)).to_radians(),
                            rake_rad: (-20.0 - 40.0 * t).to_radians(),
                            swept_volume_m3: 1.2 * t,
                        };
                        if far_back && i % 2 == 1 {
                            let geometry = DigGeometry {
                                rake_rad: -170f64.to_radians(),
                                ..geometry
                            };
                            let force = planner::kinematics::TipForce {
                                fx_n: 30e3,
                                fz_n: -5e3,
                                my_nm: 0.0,
                            };
                            return SoilSample { geometry, force };
                        }
                        let force = fee_tip_force(&soil(), &geometry, WIDTH_M, 0.0).unwrap();
                        SoilSample { geometry, force }
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_analytical_model_recovers_fee_digs_and_sees_only_its_domain() {
        let cv = soil_cv(&digs(false), 300, WIDTH_M);
        let a = cv.analytical.result.as_ref().unwrap();
        assert_eq!(cv.analytical.samples, 360);
        assert!(a.mae_percent_of_peak < 2.0, "{a:?}");
        assert!(cv.empirical.result.is_ok());

        // Samples outside the domain are left out of the analytical fit, not fatal to it.
        let cv = soil_cv(&digs(true), 300, WIDTH_M);
        assert_eq!(cv.empirical.samples, 360);
        assert_eq!(cv.analytical.samples, 180);
        let a = cv.analytical.result.as_ref().unwrap();
        assert!(a.mae_percent_of_peak < 2.0, "{a:?}");
        let text = report(&cv, 300);
        assert!(
            text.contains("| analytical") && text.contains("180"),
            "{text}"
        );
    }

    #[test]
    fn a_corrupt_or_empty_samples_file_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("bad.json");
        std::fs::write(&bad, b"{\"digs\": [1, 2").unwrap();
        let e = SoilSamplesFile::read(&bad).unwrap_err();
        assert!(
            format!("{e:#}").contains("not a soil_samples.json"),
            "{e:#}"
        );
        let empty = dir.path().join("empty.json");
        std::fs::write(&empty, br#"{"digs": [{"index": 0, "samples": []}]}"#).unwrap();
        let e = SoilSamplesFile::read(&empty).unwrap_err();
        assert!(
            format!("{e:#}").contains("no dig with soil samples"),
            "{e:#}"
        );
        assert!(SoilSamplesFile::read(&dir.path().join("missing.json")).is_err());
    }
}
