//! What the dig-model commands share: the dig model (the shipped one or an `--model` file), the
//! machine file, the default bench's site and a start on it ([`ModelStartArgs`]: Table 2's and Fig.
//! 52's start), and the tip paths of predicted digs for the plots.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;
use planner::actuator::ActuatorModel;
use planner::dig_model::{DigModel, DigPrediction, DigSite, DigStart};
use planner::kinematics::BucketPose;
use vcan_sim::SimConfig;
use vcan_sim::soil_contact::World;

use super::sim_dig::section_of;

/// The dig model and its start on the default bench (Table 2's and Fig. 52's with the dig model).
#[derive(Debug, Clone, Args)]
pub struct ModelStartArgs {
    /// Dig model: actuator networks (default: the shipped config/nominal_actuator.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Dig model: start distance of the tip from the swing axis, m.
    #[arg(long, default_value_t = 7.8)]
    pub start_r: f64,
    /// Dig model: start bucket angle to the horizontal, degrees.
    #[arg(long, default_value_t = -55.0)]
    pub start_bucket_deg: f64,
    /// Dig model: start depth of the tip below the surface, m.
    #[arg(long, default_value_t = 0.02)]
    pub start_depth: f64,
}

impl Default for ModelStartArgs {
    /// The command-line defaults.
    fn default() -> Self {
        Self {
            model: None,
            start_r: 7.8,
            start_bucket_deg: -55.0,
            start_depth: 0.02,
        }
    }
}

impl ModelStartArgs {
    /// The dig model (the shipped one or `--model`'s actuator networks).
    ///
    /// # Errors
    /// Reading or parsing `--model`.
    pub fn load_model(&self) -> anyhow::Result<DigModel> {
        load_model(self.model.as_deref())
    }

    /// The start on `site`.
    ///
    /// # Errors
    /// `start_r` outside the site's section.
    pub fn start(&self, site: &DigSite) -> anyhow::Result<DigStart> {
        tip_start(site, self.start_r, self.start_depth, self.start_bucket_deg)
    }

    /// "tip D m deep at r = R m on the default bench, bucket B deg", for report headers.
    #[must_use]
    pub fn describe(&self) -> String {
        format!(
            "tip {:.2} m deep at r = {:.2} m on the default bench, bucket {:.0} deg",
            self.start_depth, self.start_r, self.start_bucket_deg
        )
    }
}

/// The dig model with the actuator networks of `path`, or the shipped one.
///
/// # Errors
/// Reading or parsing `path`.
pub(super) fn load_model(path: Option<&Path>) -> anyhow::Result<DigModel> {
    let nominal = DigModel::nominal()?;
    match path {
        None => Ok(nominal),
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            let actuator =
                ActuatorModel::from_json(&text).with_context(|| format!("{}", p.display()))?;
            Ok(nominal.with_actuator(actuator)?)
        }
    }
}

/// The default bench's site (config/bench.toml) as the machine at its start pose sees it.
///
/// # Errors
/// Loading the built-in files.
pub fn default_site() -> anyhow::Result<DigSite> {
    let cfg = SimConfig::load::<&str>(None, None, None, &[])?;
    let world = World::from_scenario(&cfg.scenario)?;
    Ok(DigSite::new(
        section_of(&world, &cfg)?,
        cfg.scenario.bench.floor_elevation_m,
    )?)
}

/// A dig start with the tip `start_depth_m` under the surface of `site` at `start_r` m from the swing
/// axis and the bucket at `start_bucket_deg` to the horizontal (Table 2's and Fig. 52's start).
///
/// # Errors
/// `start_r` outside the site's section.
pub(super) fn tip_start(
    site: &DigSite,
    start_r: f64,
    start_depth_m: f64,
    start_bucket_deg: f64,
) -> anyhow::Result<DigStart> {
    Ok(DigStart::Pose(BucketPose {
        x_m: start_r,
        z_m: site.profile().height_at(start_r)? - start_depth_m,
        bucket_abs_rad: start_bucket_deg.to_radians(),
    }))
}

/// The tip path of a predicted dig, for the tip-path plots.
pub(super) fn predicted_tip_path(p: &DigPrediction) -> Vec<onboard::record::TipPoint> {
    p.samples
        .iter()
        .map(|s| onboard::record::TipPoint {
            x_m: s.tip_x_m,
            z_m: s.tip_z_m,
        })
        .collect()
}

/// The section of the default bench as [`TipPoint`]s (every 0.05 m from 1 to 12 m).
pub(super) fn default_section() -> anyhow::Result<Vec<onboard::record::TipPoint>> {
    let site = default_site()?;
    Ok((0..=220)
        .filter_map(|k| {
            let r = 1.0 + 0.05 * f64::from(k);
            site.profile()
                .height_at(r)
                .ok()
                .map(|z| onboard::record::TipPoint { x_m: r, z_m: z })
        })
        .collect())
}
