//! The thesis's 23-dig cross-validation of the soil models (4.3.5, Fig. 31) on synthetic FEE digs:
//! each dig predicted from the properties fitted on the others, for the empirical and the analytical
//! model.
//!
//! `cargo run -p planner --release --features synthetic --example soil_cross_validation`
//! (add `parallel` to the features to run the digs on all cores).

use planner::estimate::{
    AnalyticalFitConfig, DEFAULT_WINDOW_SAMPLES, SoilModelKind, cross_validate,
};
use planner::synthetic::{FEE_BUCKET_WIDTH_M, fee_digs};

fn main() -> Result<(), planner::estimate::EstimateError> {
    let digs = fee_digs(23, 1000.0, 23);
    let config = AnalyticalFitConfig {
        bucket_width_m: FEE_BUCKET_WIDTH_M,
        ..Default::default()
    };
    for (name, kind) in [
        ("empirical", SoilModelKind::Empirical),
        ("analytical", SoilModelKind::Analytical(config)),
    ] {
        let start = std::time::Instant::now();
        let r = cross_validate(&digs, DEFAULT_WINDOW_SAMPLES, &kind)?;
        println!(
            "{name}: MAE {:.0} N (std {:.0} N) = {:.2} % of peak {:.0} N, in {:.2?}",
            r.mae_n,
            r.std_n,
            r.mae_percent_of_peak,
            r.peak_force_n,
            start.elapsed()
        );
    }
    Ok(())
}
