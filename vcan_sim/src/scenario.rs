//! Bench scenarios (`config/bench.toml`): the terrain the machine digs, its soil, hard inclusions,
//! the spoil pile, the machine's start pose, the noise seed and optional hidden effects.
//!
//! The world frame is `x` east, `y` north, `z` up (docs/ARCHITECTURE.md). The machine stands on the
//! ground plane `z = 0`; the bench is a block of soil of the given height ahead of it, with a sloped
//! face; digging should stop at `floor_elevation_m`. A bench may declare the native ground below that
//! floor (`[native_soil]`), harder than the bench material above it.
//!
//! Errors name the file, the line and the field: parse errors come with toml's span, validation errors
//! with the line of the offending key.

use std::path::Path;

use firmware_bridge::range::Limits;
use planner::toml_lines::{check_field, field_at_offset, line_of_field, line_of_offset};
use serde::Deserialize;

use crate::effects::{EffectError, EffectSet};

/// Errors reading a scenario.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("{origin}: cannot read: {reason}")]
    Io {
        /// File name.
        origin: String,
        /// The I/O error text.
        reason: String,
    },
    /// Bad TOML or a schema mismatch (the message names the field).
    #[error("{origin}:{line}: {message}")]
    Parse {
        /// File name or `<string>`.
        origin: String,
        /// 1-based line (0 when unknown).
        line: usize,
        /// Parser message.
        message: String,
    },
    /// A field has an invalid value.
    #[error("{origin}:{line}: field `{field}`: {reason}")]
    Invalid {
        /// File name or `<string>`.
        origin: String,
        /// 1-based line (0 when unknown).
        line: usize,
        /// Dotted field path.
        field: String,
        /// Why it is rejected.
        reason: String,
    },
}

/// Result alias for scenario parsing.
pub type Result<T> = std::result::Result<T, ScenarioError>;

/// Soil properties of the modified FEE (Eq. 17, Psi = (gamma, beta, phi, delta, c)).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SoilSpec {
    /// Bank density gamma (kg/m^3).
    pub density_kg_per_m3: f64,
    /// Cohesion c (Pa).
    pub cohesion_pa: f64,
    /// Soil-soil internal friction angle phi (degrees).
    pub friction_angle_deg: f64,
    /// Soil-tool friction angle delta (degrees).
    pub tool_friction_angle_deg: f64,
    /// Failure-surface angle beta (degrees).
    pub failure_angle_deg: f64,
}

impl Default for SoilSpec {
    fn default() -> Self {
        Self {
            density_kg_per_m3: 1700.0,
            cohesion_pa: 8000.0,
            friction_angle_deg: 35.0,
            tool_friction_angle_deg: 20.0,
            failure_angle_deg: 30.0,
        }
    }
}

/// A rectangular region (world x/y) with its own soil.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SoilRegion {
    /// West edge (m).
    pub x_min_m: f64,
    /// East edge (m).
    pub x_max_m: f64,
    /// South edge (m).
    pub y_min_m: f64,
    /// North edge (m).
    pub y_max_m: f64,
    /// The soil inside.
    pub soil: SoilSpec,
}

/// The bench geometry.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BenchSpec {
    /// Height of the bench top above the ground plane (m).
    pub height_m: f64,
    /// Width across the machine's heading, world `y` (m), centred on `center_y_m`.
    pub width_m: f64,
    /// Length along world `x` from the crest of the face (m).
    pub length_m: f64,
    /// World `x` of the toe of the face (m).
    pub face_x_m: f64,
    /// World `y` of the bench centre line (m).
    pub center_y_m: f64,
    /// Face angle to the horizontal (degrees).
    pub face_slope_deg: f64,
    /// Elevation of the floor to dig down to (m, world z).
    pub floor_elevation_m: f64,
    /// A cut instead of a block: the machine stands on the ground plane, which is the bench top, and
    /// the bench region is excavated `height_m` below it, its face descending from the crest at
    /// `face_x_m` (the thesis's extended-operation setting, ch. 6: the dig face recedes toward the
    /// machine, which tracks back). Default false.
    pub cut: bool,
}

impl Default for BenchSpec {
    fn default() -> Self {
        Self {
            height_m: 2.0,
            width_m: 10.0,
            length_m: 10.0,
            face_x_m: 5.0,
            center_y_m: 0.0,
            face_slope_deg: 45.0,
            floor_elevation_m: 0.0,
            cut: false,
        }
    }
}

/// The bench material's surface (`[terrain]`): slope stability after the bucket cuts and the seeded
/// initial undulation of the bench top and face. Both are off unless the bench declares them (the cut
/// then leaves exactly the swept shape and the bench is the regular block or cut of [`BenchSpec`]).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainSpec {
    /// Angle of repose of the bench material (degrees): ground the bucket has cut that is left steeper
    /// than this slumps to it (a mass-conserving relaxation of the height grid near the cuts,
    /// the `soil_contact` module). `None`: off.
    pub repose_deg: Option<f64>,
    /// Standard deviation of the seeded undulation added to the bench top and face above the floor, m
    /// (a smooth Gaussian random field drawn from the scenario seed). 0: off.
    pub undulation_std_m: f64,
    /// Correlation length of the undulation (Gaussian covariance `exp(-r^2 / (2 L^2))`), m.
    pub undulation_correlation_m: f64,
}

/// The terrain grid.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GridSpec {
    /// Cell size (m).
    pub cell_m: f64,
    /// West edge of the map (m).
    pub x_min_m: f64,
    /// South edge of the map (m).
    pub y_min_m: f64,
    /// Map size along x (m).
    pub size_x_m: f64,
    /// Map size along y (m).
    pub size_y_m: f64,
}

impl Default for GridSpec {
    fn default() -> Self {
        Self {
            cell_m: 0.1,
            x_min_m: -8.0,
            y_min_m: -10.0,
            size_x_m: 24.0,
            size_y_m: 20.0,
        }
    }
}

/// A hard inclusion: a sphere of rock the bucket cannot cut.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Boulder {
    /// Centre x (m).
    pub x_m: f64,
    /// Centre y (m).
    pub y_m: f64,
    /// Centre z (m).
    pub z_m: f64,
    /// Radius (m).
    pub radius_m: f64,
}

/// Hard inclusions: listed ones plus `random_count` drawn from the scenario seed inside the bench.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct BoulderSpec {
    /// Number of random boulders inside the bench volume.
    pub random_count: u32,
    /// Smallest random radius (m).
    pub min_radius_m: f64,
    /// Largest random radius (m).
    pub max_radius_m: f64,
    /// Explicit boulders.
    pub list: Vec<Boulder>,
}

/// Where the bucket is emptied.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SpoilSpec {
    /// Pile centre x (m).
    pub x_m: f64,
    /// Pile centre y (m).
    pub y_m: f64,
    /// Angle of repose of the dumped material (degrees).
    pub repose_deg: f64,
}

impl Default for SpoilSpec {
    fn default() -> Self {
        Self {
            x_m: 0.0,
            y_m: -6.0,
            repose_deg: 37.0,
        }
    }
}

/// The machine's start pose in the world and its joint angles (degrees).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StartPose {
    /// Swing-axis x (m).
    pub x_m: f64,
    /// Swing-axis y (m).
    pub y_m: f64,
    /// Heading of the tracks, counter-clockwise from world x (degrees).
    pub heading_deg: f64,
    /// Boom angle (degrees, docs/ARCHITECTURE.md).
    pub boom_deg: f64,
    /// Stick angle relative to the boom (degrees).
    pub stick_deg: f64,
    /// Bucket angle relative to the stick (degrees).
    pub bucket_deg: f64,
    /// Swing angle (degrees).
    pub swing_deg: f64,
}

impl Default for StartPose {
    fn default() -> Self {
        Self {
            x_m: 0.0,
            y_m: 0.0,
            heading_deg: 0.0,
            boom_deg: 20.0,
            stick_deg: -100.0,
            bucket_deg: -60.0,
            swing_deg: 0.0,
        }
    }
}

/// One bench scenario.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// Human-readable name.
    pub name: String,
    /// Seed for sensor noise and random boulders.
    pub seed: u64,
    /// Bench geometry.
    pub bench: BenchSpec,
    /// Terrain grid.
    pub grid: GridSpec,
    /// Default soil.
    pub soil: SoilSpec,
    /// Regions with other soil (later ones win).
    pub soil_regions: Vec<SoilRegion>,
    /// The native ground below `bench.floor_elevation_m` (`[native_soil]`), when the bench declares
    /// it: a layered ground whose lower layer has its own soil everywhere on the map (the soil
    /// regions apply above the floor only); see the `soil_contact` module for how a cut that reaches
    /// it is resisted. `None` (the default): one soil from the surface down, as before.
    pub native_soil: Option<SoilSpec>,
    /// Slope stability and initial undulation of the bench material (`[terrain]`, off when absent).
    pub terrain: TerrainSpec,
    /// Hard inclusions.
    pub boulders: BoulderSpec,
    /// Spoil pile.
    pub spoil: SpoilSpec,
    /// Machine start pose.
    pub start: StartPose,
    /// Hidden effects (`name = value`), off when absent.
    pub effects: std::collections::BTreeMap<String, f64>,
    /// Multiplies the soil's force on the bucket (`soil_force_factor = 2.0`; the cutting force of
    /// Eq. 17, bearing and boulder contact) without changing the soil itself: what the bucket holds
    /// weighs the same. Thesis 4.4, Table 2: "the force output of the analytical model was multiplied
    /// by the force factor". `None` (the default): 1.
    pub soil_force_factor: Option<f64>,
    /// How the plant integrates the soil's force (`soil_contact = "held"`); `implicit` when absent.
    pub soil_contact: SoilContactIntegration,
}

/// How the plant integrates the soil's force on the bucket (docs/simulator.md, "Soil contact
/// integration").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SoilContactIntegration {
    /// The force at the tip velocity of each 5 ms contact update, held until the next: the plant of
    /// plant version `held-1`, kept to reproduce results made on it. Where the soil's resistance exceeds
    /// what the cylinders hold (harder soil, a force factor of 2 or more) its steep mobilisation near
    /// rest (about force / 1 cm/s) held against the oil column makes it chatter.
    Held,
    /// The force as a function of the tip velocity, evaluated at every 1 ms physics step and its
    /// velocity gradient taken implicitly by the hydraulics (one 3x3 solve): no chatter; the soil
    /// resists steadily, so the same soil digs harder than with `held`.
    #[default]
    Implicit,
}

/// The bundled default scenario (`config/bench.toml`).
pub const DEFAULT_BENCH_TOML: &str = include_str!("../../config/bench.toml");

/// The bundled extended-operation bench (`config/bench_extended.toml`, thesis ch. 6).
pub const EXTENDED_BENCH_TOML: &str = include_str!("../../config/bench_extended.toml");

impl Scenario {
    /// The bench's site part: what the controller knows of the place (planner::site): the terrain
    /// map's grid, the floor, the machine's start pose and the bench material's density. The rest of
    /// the bench (soil strength, native ground, boulders, undulation, spoil pile, joints, effects) is
    /// the simulated world's truth, which a controller never reads.
    #[must_use]
    pub fn site(&self) -> planner::site::Site {
        use planner::site::{Floor, MachineStart, Material, Site, WorkArea};
        let g = &self.grid;
        Site {
            name: self.name.clone(),
            work_area: WorkArea {
                cell_m: g.cell_m,
                x_min_m: g.x_min_m,
                y_min_m: g.y_min_m,
                size_x_m: g.size_x_m,
                size_y_m: g.size_y_m,
            },
            floor: Floor {
                elevation_m: self.bench.floor_elevation_m,
            },
            machine: MachineStart {
                x_m: self.start.x_m,
                y_m: self.start.y_m,
                heading_deg: self.start.heading_deg,
            },
            material: Material {
                bulk_density_kg_per_m3: self.soil.density_kg_per_m3,
            },
        }
    }

    /// The default bench (`config/bench.toml`, compiled in).
    ///
    /// # Errors
    /// Only if the bundled file is broken, which the tests rule out.
    pub fn default_bench() -> Result<Self> {
        Self::from_toml_str_named(DEFAULT_BENCH_TOML, "config/bench.toml")
    }

    /// Reads a scenario file.
    ///
    /// # Errors
    /// [`ScenarioError::Io`], [`ScenarioError::Parse`] or [`ScenarioError::Invalid`], naming the file.
    pub fn from_toml_file(path: &Path) -> Result<Self> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Io {
            origin: origin.clone(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str_named(&text, &origin)
    }

    /// Parses and validates scenario text; errors name `origin`, the line and the field.
    ///
    /// # Errors
    /// [`ScenarioError::Parse`] or [`ScenarioError::Invalid`].
    pub fn from_toml_str_named(text: &str, origin: &str) -> Result<Self> {
        let scenario: Self = toml::from_str(text).map_err(|e| {
            let offset = e.span().map(|s| s.start);
            let line = offset.map_or(0, |o| line_of_offset(text, o));
            let mut message = e.message().trim().to_owned();
            if let Some(field) = offset.and_then(|o| field_at_offset(text, o))
                && !message.contains(&field)
            {
                message = format!("field `{field}`: {message}");
            }
            ScenarioError::Parse {
                origin: origin.to_owned(),
                line,
                message,
            }
        })?;
        scenario
            .validate()
            .map_err(|(field, reason)| ScenarioError::Invalid {
                origin: origin.to_owned(),
                line: line_of_field(text, &field).unwrap_or(0),
                field,
                reason,
            })?;
        Ok(scenario)
    }

    /// The hidden effects set in the file.
    ///
    /// # Errors
    /// An unknown name or out-of-range value (already rejected by validation).
    pub fn effect_set(&self) -> std::result::Result<EffectSet, EffectError> {
        let mut set = EffectSet::nominal();
        for (name, value) in &self.effects {
            set.set_by_name(name, *value)?;
        }
        Ok(set)
    }

    /// Checks every value; returns `(field path, reason)` for the first problem.
    ///
    /// # Errors
    /// The first invalid field.
    pub fn validate(&self) -> std::result::Result<(), (String, String)> {
        fn positive(field: &str, v: f64) -> std::result::Result<(), (String, String)> {
            check_field(field, v, Limits::POSITIVE)
        }
        fn within(
            field: &str,
            v: f64,
            lo: f64,
            hi: f64,
        ) -> std::result::Result<(), (String, String)> {
            check_field(field, v, Limits::closed(lo, hi, ""))
        }
        if let Some(k) = self.soil_force_factor {
            within("soil_force_factor", k, 0.0, 10.0)?;
        }
        fn soil(prefix: &str, s: &SoilSpec) -> std::result::Result<(), (String, String)> {
            // Natural soils stay under 2500 kg/m^3; the thesis's force-factor experiments (Table 2)
            // scale density with cohesion by up to x3, hence the wider bound.
            within(
                &format!("{prefix}.density_kg_per_m3"),
                s.density_kg_per_m3,
                500.0,
                10_000.0,
            )?;
            within(&format!("{prefix}.cohesion_pa"), s.cohesion_pa, 0.0, 1.0e6)?;
            within(
                &format!("{prefix}.friction_angle_deg"),
                s.friction_angle_deg,
                5.0,
                60.0,
            )?;
            within(
                &format!("{prefix}.tool_friction_angle_deg"),
                s.tool_friction_angle_deg,
                0.0,
                45.0,
            )?;
            within(
                &format!("{prefix}.failure_angle_deg"),
                s.failure_angle_deg,
                5.0,
                80.0,
            )
        }
        // Positions: finite and on a map of at most 10 km either way.
        let position = |field: &str, v: f64| within(field, v, -1.0e4, 1.0e4);
        let b = &self.bench;
        within("bench.height_m", b.height_m, 0.0, 20.0)?;
        positive("bench.width_m", b.width_m)?;
        positive("bench.length_m", b.length_m)?;
        within("bench.width_m", b.width_m, 0.0, 1.0e4)?;
        within("bench.length_m", b.length_m, 0.0, 1.0e4)?;
        within("bench.face_slope_deg", b.face_slope_deg, 10.0, 90.0)?;
        within("bench.floor_elevation_m", b.floor_elevation_m, -5.0, 5.0)?;
        within("bench.face_x_m", b.face_x_m, -1.0e3, 1.0e3)?;
        within("bench.center_y_m", b.center_y_m, -1.0e3, 1.0e3)?;
        let g = &self.grid;
        position("grid.x_min_m", g.x_min_m)?;
        position("grid.y_min_m", g.y_min_m)?;
        within("grid.cell_m", g.cell_m, 0.02, 1.0)?;
        positive("grid.size_x_m", g.size_x_m)?;
        positive("grid.size_y_m", g.size_y_m)?;
        let cells = (g.size_x_m / g.cell_m) * (g.size_y_m / g.cell_m);
        if cells > 4.0e6 {
            return Err((
                "grid.cell_m".into(),
                format!("grid would have {cells:.0} cells (max 4e6)"),
            ));
        }
        soil("soil", &self.soil)?;
        if let Some(native) = &self.native_soil {
            soil("native_soil", native)?;
        }
        for (i, r) in self.soil_regions.iter().enumerate() {
            for (key, v) in [
                ("x_min_m", r.x_min_m),
                ("x_max_m", r.x_max_m),
                ("y_min_m", r.y_min_m),
                ("y_max_m", r.y_max_m),
            ] {
                position(&format!("soil_regions.{i}.{key}"), v)?;
            }
            soil(&format!("soil_regions.{i}.soil"), &r.soil)?;
            if !(r.x_max_m > r.x_min_m && r.y_max_m > r.y_min_m) {
                return Err((format!("soil_regions.{i}.x_max_m"), "empty region".into()));
            }
        }
        let t = &self.terrain;
        if let Some(repose) = t.repose_deg {
            within("terrain.repose_deg", repose, 15.0, 60.0)?;
        }
        within("terrain.undulation_std_m", t.undulation_std_m, 0.0, 1.0)?;
        if t.undulation_std_m > 0.0 {
            within(
                "terrain.undulation_correlation_m",
                t.undulation_correlation_m,
                0.2,
                20.0,
            )?;
        }
        let bo = &self.boulders;
        if bo.random_count > 0 {
            positive("boulders.min_radius_m", bo.min_radius_m)?;
            within("boulders.max_radius_m", bo.max_radius_m, 0.0, 5.0)?;
            if bo.max_radius_m < bo.min_radius_m {
                return Err((
                    "boulders.max_radius_m".into(),
                    "must be >= min_radius_m".into(),
                ));
            }
        }
        if bo.random_count > 1000 {
            return Err(("boulders.random_count".into(), "at most 1000".into()));
        }
        for (i, boulder) in bo.list.iter().enumerate() {
            for (key, v) in [
                ("x_m", boulder.x_m),
                ("y_m", boulder.y_m),
                ("z_m", boulder.z_m),
            ] {
                position(&format!("boulders.list.{i}.{key}"), v)?;
            }
            within(
                &format!("boulders.list.{i}.radius_m"),
                boulder.radius_m,
                0.01,
                5.0,
            )?;
        }
        within("spoil.repose_deg", self.spoil.repose_deg, 10.0, 60.0)?;
        position("spoil.x_m", self.spoil.x_m)?;
        position("spoil.y_m", self.spoil.y_m)?;
        let s = &self.start;
        position("start.x_m", s.x_m)?;
        position("start.y_m", s.y_m)?;
        within("start.boom_deg", s.boom_deg, -90.0, 90.0)?;
        within("start.stick_deg", s.stick_deg, -180.0, 0.0)?;
        within("start.bucket_deg", s.bucket_deg, -180.0, 90.0)?;
        within("start.swing_deg", s.swing_deg, -360.0, 360.0)?;
        within("start.heading_deg", s.heading_deg, -360.0, 360.0)?;
        for (name, value) in &self.effects {
            EffectSet::nominal()
                .set_by_name(name, *value)
                .map_err(|e| (format!("effects.{name}"), e.to_string()))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `config/site.toml` is the extended bench's site part (the default site of `run` and the
    /// default bench of `demo` describe one place).
    #[test]
    fn the_bundled_site_is_the_extended_benchs() {
        let bench =
            Scenario::from_toml_str_named(EXTENDED_BENCH_TOML, "config/bench_extended.toml")
                .unwrap();
        assert_eq!(bench.site(), planner::site::Site::extended_bench().unwrap());
        bench.site().validate().unwrap();
        Scenario::default_bench()
            .unwrap()
            .site()
            .validate()
            .unwrap();
    }

    #[test]
    fn bundled_bench_parses() {
        let s = Scenario::default_bench().unwrap();
        assert!(s.bench.height_m > 0.0);
        assert!(s.effect_set().unwrap().active().is_empty());
    }

    /// `soil_contact` picks the plant's soil-force integration; absent it is `implicit`, and a
    /// value that is neither is an error naming the key.
    #[test]
    fn soil_contact_parses_with_implicit_as_default() {
        assert_eq!(
            Scenario::default_bench().unwrap().soil_contact,
            SoilContactIntegration::Implicit
        );
        let s = Scenario::from_toml_str_named("soil_contact = \"held\"\n", "b.toml").unwrap();
        assert_eq!(s.soil_contact, SoilContactIntegration::Held);
        let msg = Scenario::from_toml_str_named("soil_contact = \"smooth\"\n", "b.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("b.toml:1:") && msg.contains("soil_contact"),
            "{msg}"
        );
    }

    #[test]
    fn parse_error_names_file_line_and_field() {
        let text = "seed = 1\n[bench]\nheight_m = \"tall\"\n";
        let err = Scenario::from_toml_str_named(text, "b.toml").unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.starts_with("b.toml:3:") && msg.contains("bench.height_m"),
            "{msg}"
        );
        let text = "seed = 1\n[bench]\nhieght_m = 2.0\n";
        let msg = Scenario::from_toml_str_named(text, "b.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("b.toml:3:") && msg.contains("hieght_m"),
            "{msg}"
        );
    }

    #[test]
    fn invalid_value_names_file_line_and_field() {
        let text = "seed = 1\n\n[bench]\nwidth_m = 3.0\nheight_m = -2.0\n";
        let err = Scenario::from_toml_str_named(text, "b.toml").unwrap_err();
        assert_eq!(
            err,
            ScenarioError::Invalid {
                origin: "b.toml".into(),
                line: 5,
                field: "bench.height_m".into(),
                reason: "must be finite and in [0, 20], got -2".into(),
            }
        );
        let text = "[effects]\nbogus = 1.0\n";
        let msg = Scenario::from_toml_str_named(text, "b.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("b.toml:2: field `effects.bogus`"), "{msg}");
    }

    #[test]
    fn native_soil_is_off_unless_declared_and_validated() {
        assert_eq!(
            Scenario::from_toml_str_named("", "b.toml")
                .unwrap()
                .native_soil,
            None
        );
        assert!(Scenario::default_bench().unwrap().native_soil.is_some());
        let text = "[bench]\nfloor_elevation_m = -2.0\n[native_soil]\ncohesion_pa = 40000.0\n";
        let s = Scenario::from_toml_str_named(text, "b.toml").unwrap();
        let native = s.native_soil.unwrap();
        assert_eq!(native.cohesion_pa, 40000.0);
        assert_eq!(
            native.density_kg_per_m3,
            SoilSpec::default().density_kg_per_m3
        );
        let text = "[native_soil]\ncohesion_pa = 40000.0\nfriction_angle_deg = 95.0\n";
        let msg = Scenario::from_toml_str_named(text, "b.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("b.toml:3: field `native_soil.friction_angle_deg`"),
            "{msg}"
        );
    }

    #[test]
    fn terrain_surface_is_off_unless_declared_and_validated() {
        assert_eq!(
            Scenario::default_bench().unwrap().terrain,
            TerrainSpec::default()
        );
        let text = "[terrain]\nrepose_deg = 45.0\nundulation_std_m = 0.1\nundulation_correlation_m = 1.5\n";
        let t = Scenario::from_toml_str_named(text, "b.toml")
            .unwrap()
            .terrain;
        assert_eq!(t.repose_deg, Some(45.0));
        assert_eq!(t.undulation_std_m, 0.1);
        let text = "[terrain]\nundulation_std_m = 0.1\nundulation_correlation_m = 0.0\n";
        let msg = Scenario::from_toml_str_named(text, "b.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("b.toml:3: field `terrain.undulation_correlation_m`"),
            "{msg}"
        );
        let text = "[terrain]\nrepose_deg = 80.0\n";
        assert!(Scenario::from_toml_str_named(text, "b.toml").is_err());
    }

    #[test]
    fn effects_in_file_become_an_effect_set() {
        let text = "[effects]\ntransport_delay = 0.05\n";
        let s = Scenario::from_toml_str_named(text, "b.toml").unwrap();
        let set = s.effect_set().unwrap();
        assert_eq!(set.get(crate::effects::Effect::TransportDelay), 0.05);
    }

    /// Positions, radii and sizes that were only range-checked on some keys: NaN and infinities are
    /// refused everywhere, with the line of the key (also inside an array of tables).
    #[test]
    fn non_finite_positions_are_refused_with_their_line() {
        for (text, field, line) in [
            ("[grid]\nx_min_m = nan\n", "grid.x_min_m", 2),
            ("[spoil]\ny_m = inf\n", "spoil.y_m", 2),
            ("[start]\nx_m = -inf\n", "start.x_m", 2),
            ("[bench]\nwidth_m = 1e308\n", "bench.width_m", 2),
            (
                "[boulders]\nrandom_count = 2\nmin_radius_m = 0.1\nmax_radius_m = inf\n",
                "boulders.max_radius_m",
                4,
            ),
            (
                "[[soil_regions]]\nx_min_m = 0.0\nx_max_m = 1.0\ny_min_m = 0.0\ny_max_m = 1.0\n\
                 soil = {}\n[[soil_regions]]\nx_min_m = 0.0\nx_max_m = nan\ny_min_m = 0.0\n\
                 y_max_m = 1.0\nsoil = {}\n",
                "soil_regions.1.x_max_m",
                9,
            ),
            (
                "[boulders]\nlist = [{ x_m = 1.0, y_m = 1.0, z_m = nan, radius_m = 0.3 }]\n",
                "boulders.list.0.z_m",
                2,
            ),
        ] {
            let err = Scenario::from_toml_str_named(text, "b.toml").unwrap_err();
            assert!(
                matches!(&err, ScenarioError::Invalid { field: f, line: l, .. } if f == field && *l == line),
                "{text}: {err}"
            );
        }
    }
}
