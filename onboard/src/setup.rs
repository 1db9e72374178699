//! The configuration of a session from the files a machine has: the machine file, the site
//! ([`planner::site`]), the controller config, the Autodig maps, the planner settings, the hardness
//! regression and the machine profile. `run` builds its session from these alone; `demo` builds the
//! same from the site part of its bench (`vcan_sim::scenario::Scenario::site`), so the two cannot
//! drift apart.

use std::path::Path;
use std::sync::Arc;

use anyhow::Context as _;
use controller::ControllerConfig;
use controller::session::planned::PlannedSession;
use controller::session::snapshot::Strategy;
use firmware_bridge::profile::Profile;
use planner::autodig::AutodigMaps;
use planner::machine::MachineConfig;
use planner::plan::{HardnessRegression, PlannerConfig, TerrainMapper};
use planner::site::Site;

use crate::summary::DemoStrategy;

/// Carry and dump height of the bucket tip on the planned and predefined strategies, m.
pub const EXTENDED_CARRY_TIP_Z_M: f64 = 4.0;
/// Joint tolerance of the moves to the dig on the planned and predefined strategies, rad.
pub const EXTENDED_JOINT_TOLERANCE_RAD: f64 = 0.06;
/// ... or boom angle, degrees, whichever comes first.
pub const EXTENDED_CARRY_BOOM_DEG: f64 = 55.0;

/// The controller config of a session of `strategy` on `site`: the `config` file or the built-in
/// defaults; for the planned and predefined strategies an empty plan (the session pushes the
/// actions), the carry and tolerances of an eroding bench, the estimator starting at the site's
/// machine pose and the scans binned on its work area. The fixed strategy keeps the file's plan as
/// it is. The dig count is the caller's.
///
/// # Errors
/// Reading or checking the config file (file, line and field).
pub fn controller_config(
    strategy: DemoStrategy,
    config: Option<&Path>,
    site: &Site,
    predefined_plain: bool,
) -> anyhow::Result<ControllerConfig> {
    let mut config = match config {
        Some(p) => ControllerConfig::from_toml_file(p).context("controller config")?,
        None => ControllerConfig::default(),
    };
    if strategy == DemoStrategy::Fixed {
        return Ok(config);
    }
    config.cycle.actions.clear();
    config.cycle.repeat = false;
    // The spoil is cast beside the tract onto the bench top and piles up there over a long
    // session: carry and dump well above it (the default 2.8 m tip height is 0.8 m over the
    // default bench's top; the uncurling bucket's tip swings down about 1.5 m).
    config.cycle.carry_tip_z_m = config.cycle.carry_tip_z_m.max(EXTENDED_CARRY_TIP_Z_M);
    // The start is approached 0.4 m above the planned tip and Boom-Down lowers it onto the
    // terrain, so a few degrees of implement error only change where Boom-Down starts; the
    // P-controller's minimum command cannot lift a boom that overshot a 0.03 rad tolerance
    // downward (the move timed out 2 degrees short).
    config.cycle.joint.tolerance = config
        .cycle
        .joint
        .tolerance
        .max(EXTENDED_JOINT_TOLERANCE_RAD);
    config.cycle.carry_boom_rad = config
        .cycle
        .carry_boom_rad
        .max(EXTENDED_CARRY_BOOM_DEG.to_radians());
    if strategy == DemoStrategy::Predefined {
        // Thesis 6.2: the floor detected once and reused "was not implemented for the predefined
        // excavation sequence": its cleanups detect the floor every time.
        config.cycle.floor_policy = planner::cleanup::FloorPolicy::DetectEveryTime;
        if predefined_plain {
            // Plain Autodig (3.1): Dig ends on its fixed beta, Capture on its fixed gamma.
            config.cycle.perception = false;
        }
    }
    config.estimator.initial_pose = site.start_pose();
    let a = &site.work_area;
    let grid = &mut config.cycle.scan_grid;
    grid.x_min_m = a.x_min_m;
    grid.y_min_m = a.y_min_m;
    grid.cell_m = a.cell_m;
    grid.size_x_m = a.size_x_m;
    grid.size_y_m = a.size_y_m;
    Ok(config)
}

/// The controller's machine: the machine file (its simulator tables ignored), the built-in one
/// without a path.
///
/// # Errors
/// Reading or checking the file (file, line and field).
pub fn machine(path: Option<&Path>) -> anyhow::Result<MachineConfig> {
    MachineConfig::controller_file(path).context("machine file")
}

/// The site: the file at `path`, the extended bench's (`config/site.toml`) without one.
///
/// # Errors
/// Reading or checking the file (file, line and field).
pub fn site(path: Option<&Path>) -> anyhow::Result<Site> {
    match path {
        Some(p) => Site::from_toml_file(p).context("site file"),
        None => Site::extended_bench().context("built-in site"),
    }
}

/// The Autodig maps: the file at `path`, the built-in ones without.
///
/// # Errors
/// Reading or checking the file.
pub fn maps(path: Option<&Path>) -> anyhow::Result<AutodigMaps> {
    match path {
        Some(p) => {
            let text = planner::config_file::read_text(p)
                .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", p.display()))
                .context("reading the Autodig maps")?;
            AutodigMaps::from_toml_str(&text)
                .with_context(|| format!("Autodig maps {}", p.display()))
        }
        None => AutodigMaps::builtin().context("built-in Autodig maps"),
    }
}

/// The planner settings: the file at `path` or the built-in one, with the desired floor at the
/// site's target floor.
///
/// # Errors
/// Reading or parsing the file.
pub fn planner_config(path: Option<&Path>, site: &Site) -> anyhow::Result<PlannerConfig> {
    let mut cfg = match path {
        Some(p) => {
            let text = planner::config_file::read_text(p)
                .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", p.display()))
                .context("reading the planner config")?;
            PlannerConfig::from_toml_str(&text)
                .with_context(|| format!("planner config {}", p.display()))?
        }
        None => PlannerConfig::nominal().context("built-in planner config")?,
    };
    cfg.floor_z_m = site.floor.elevation_m;
    Ok(cfg)
}

/// The planned session of `strategy` for `machine` on `site`: the planner with `planner`'s
/// settings, a terrain map on the site's work area, the hardness regression (`hardness` or the
/// built-in one).
///
/// # Errors
/// Reading the regression, planner construction.
pub fn planned_session(
    machine: &MachineConfig,
    planner: PlannerConfig,
    site: &Site,
    strategy: Strategy,
    hardness: Option<&Path>,
) -> anyhow::Result<PlannedSession> {
    let a = &site.work_area;
    let (nx, ny) = a.cells();
    let mapper = TerrainMapper::new(
        a.x_min_m,
        a.y_min_m,
        a.cell_m,
        nx,
        ny,
        controller::step::cycle::ScanGrid::default().max_gap_cells,
    )
    .context("terrain map")?;
    let mut session =
        PlannedSession::new(machine, planner, mapper, strategy).context("planned session")?;
    if let Some(p) = hardness {
        let text = planner::config_file::read_text(p)
            .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", p.display()))
            .context("reading the hardness regression")?;
        session.set_regression(
            HardnessRegression::from_toml_str(&text)
                .with_context(|| format!("hardness regression {}", p.display()))?,
        );
    }
    Ok(session)
}

/// The machine profile at `path`, if one is given: checked completely before anything runs.
///
/// # Errors
/// The profile's error, one line naming the file, the line and the quantity.
pub fn load_profile(path: Option<&Path>) -> anyhow::Result<Option<Arc<Profile>>> {
    Ok(path.map(Profile::load).transpose()?.map(Arc::new))
}
