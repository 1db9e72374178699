//! The machine description: geometry, cylinders, masses, hydraulics and limits of a 20-25 t excavator
//! (thesis ch. 4.2.1 and Appendix, Figs. A1 and A2), read from TOML (`config/machine.toml`).
//!
//! Lengths are metres and masses kilograms everywhere. Angles are radians in the structs but degrees in
//! the file: a field `x_rad` is written `x_deg` in TOML (see [`degrees`]). Pressures are Pa, flows m^3/s.
//!
//! [`MachineConfig::from_toml_str`] parses and validates; a validation error names the field and, when the
//! text is at hand, its line. The geometric checks (cylinder strokes map to the joint limits, the bucket
//! four-bar is assemblable and monotonic) are those of the linkage the kinematics is built on
//! (`crate::linkage`), so a machine that loads is one the kinematics accepts.

use crate::linkage::{FourBar, Linkage, LinkageError, Mount};
use crate::toml_lines::{self, check_field, check_field_exp};
use gateway_core::range::Limits;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Standard gravity, m/s^2.
pub const GRAVITY_M_PER_S2: f64 = 9.81;

/// Errors reading or validating a machine file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{origin}: cannot read: {reason}")]
    Io {
        /// File name.
        origin: String,
        /// The I/O error text.
        reason: String,
    },
    /// The text is not valid TOML or does not match the schema (missing field, wrong type).
    #[error("{origin}{}: {message}", line_suffix(*line))]
    Parse {
        /// File name, or `<string>`.
        origin: String,
        /// 1-based line of the error, when known.
        line: Option<usize>,
        /// The parser's message (it names the field).
        message: String,
    },
    /// A field has a value that is out of range or inconsistent with the rest of the machine.
    #[error("{origin}{}: field `{field}`: {reason}", line_suffix(*line))]
    Invalid {
        /// File name, or `<string>`.
        origin: String,
        /// 1-based line of the field, when known.
        line: Option<usize>,
        /// Dotted path of the field, e.g. `hydraulics.relief_pressure_pa`.
        field: String,
        /// Why it is rejected.
        reason: String,
    },
}

fn line_suffix(line: Option<usize>) -> String {
    line.map(|l| format!(":{l}")).unwrap_or_default()
}

/// The machine file's tables that are simulator settings, not the machine's (the controller ignores
/// them): hidden effects and the gateway's NAME.
pub const SIMULATOR_TABLES: [&str; 2] = ["effects", "gateway_name"];

/// Splits the [`SIMULATOR_TABLES`] out of machine-file text, keeping line numbers (their lines
/// become blank in the returned machine text, and every other line is blank in theirs). Returns
/// `(machine text, [effects text, gateway name text])`.
pub fn split_simulator_tables(text: &str) -> (String, [String; 2]) {
    let mut machine = String::with_capacity(text.len());
    let mut tables = [String::new(), String::new()];
    let mut current: Option<usize> = None;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            let header = t.trim_start_matches('[').trim_end_matches(']').trim();
            current = SIMULATOR_TABLES.iter().position(|name| *name == header);
        }
        for (i, table) in tables.iter_mut().enumerate() {
            if current == Some(i) {
                table.push_str(line);
            }
            table.push('\n');
        }
        if current.is_none() {
            machine.push_str(line);
        }
        machine.push('\n');
    }
    (machine, tables)
}

/// Serde adapter: the struct holds radians, the file holds degrees.
pub mod degrees {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes radians as degrees.
    ///
    /// # Errors
    /// Those of the serializer.
    pub fn serialize<S: Serializer>(rad: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(rad.to_degrees())
    }

    /// Reads degrees into radians.
    ///
    /// # Errors
    /// Those of the deserializer (e.g. not a number).
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(f64::deserialize(d)?.to_radians())
    }
}

/// Where the boom foot pin sits in the base frame (origin on the swing axis at the ground, x forward, z up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseGeometry {
    /// Boom foot pin, forward of the swing axis, m.
    pub boom_foot_x_m: f64,
    /// Boom foot pin height above the ground the tracks stand on, m.
    pub boom_foot_z_m: f64,
}

/// Link lengths between pins (the `l_2`, `l_3`, `l_4` of Eq. A3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkLengths {
    /// Boom foot pin to stick pin, m.
    pub boom_m: f64,
    /// Stick pin to bucket pin, m.
    pub stick_m: f64,
    /// Bucket pin to cutting-edge tip, m.
    pub bucket_m: f64,
}

/// Attachment of the boom or stick cylinder across its joint (Fig. A1).
///
/// The included angle at the joint between `a` and `b` is `gamma = joint + gamma_offset` for the boom
/// (extension raises the boom) and `gamma = gamma_offset - joint` for the stick (extension pulls the stick
/// in), so the cylinder length `L = sqrt(a^2 + b^2 - 2 a b cos gamma)` (Eq. A5) grows with extension.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CylinderMount {
    /// Joint to the rod-end pin on the driven link (`a_i` of Fig. A1), m.
    pub a_m: f64,
    /// Joint to the cylinder base pin on the preceding link (`b_i` of Fig. A1), m.
    pub b_m: f64,
    /// Offset between the joint angle and the included angle `gamma_i`.
    #[serde(rename = "gamma_offset_deg", with = "degrees")]
    pub gamma_offset_rad: f64,
}

/// The bucket four-bar (Fig. A2), in the stick frame: origin at the bucket pin, angles counter-clockwise
/// from the stick line (stick pin -> bucket pin) in the side view.
///
/// The side link (`e3`) turns about a pivot on the stick (`e4` from the bucket pin); the H-link (`e2`)
/// joins the side link's free end (where the cylinder rod pins, "the rod-end joint") to a pin on the bucket
/// (`e1` from the bucket pin). The cylinder base is on the stick, `p` from the bucket pin. `h` and the
/// angle `beta` of Eq. A12 follow from `p`, `e4` and their directions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BucketLinkage {
    /// Bucket pin to the H-link pin on the bucket, m.
    pub e1_m: f64,
    /// H-link length (bucket's link pin to the rod-end joint), m.
    pub e2_m: f64,
    /// Side-link length (pivot on the stick to the rod-end joint), m.
    pub e3_m: f64,
    /// Bucket pin to the side-link pivot on the stick, m.
    pub e4_m: f64,
    /// Bucket pin to the bucket-cylinder base pin on the stick, m.
    pub p_m: f64,
    /// Direction of the bucket's H-link pin from the bucket pin, relative to the bucket line (pin -> tip).
    #[serde(rename = "e1_angle_deg", with = "degrees")]
    pub e1_angle_rad: f64,
    /// Direction of the side-link pivot from the bucket pin, relative to the stick line.
    #[serde(rename = "e4_angle_deg", with = "degrees")]
    pub e4_angle_rad: f64,
    /// Direction of the cylinder base from the bucket pin, relative to the stick line.
    #[serde(rename = "p_angle_deg", with = "degrees")]
    pub p_angle_rad: f64,
}

/// One hydraulic cylinder (or a pair acting together, `count = 2` for the boom).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cylinder {
    /// Cylinders acting in parallel.
    pub count: u32,
    /// Bore (piston) diameter, m.
    pub bore_m: f64,
    /// Rod diameter, m.
    pub rod_m: f64,
    /// Stroke, m.
    pub stroke_m: f64,
    /// Pin-to-pin length fully retracted, m.
    pub retracted_length_m: f64,
    /// Nominal unloaded full-command speed, m/s (normalises "fraction of maximum cylinder velocity").
    pub max_speed_m_per_s: f64,
}

impl Cylinder {
    /// Head-side (piston) area of all cylinders together, m^2 (`A_i1` of Eq. A20).
    #[must_use]
    pub fn head_area_m2(&self) -> f64 {
        f64::from(self.count) * std::f64::consts::PI * 0.25 * self.bore_m * self.bore_m
    }

    /// Rod-side (annulus) area of all cylinders together, m^2 (`A_i2` of Eq. A20).
    #[must_use]
    pub fn rod_area_m2(&self) -> f64 {
        self.head_area_m2()
            - f64::from(self.count) * std::f64::consts::PI * 0.25 * self.rod_m * self.rod_m
    }

    /// Pin-to-pin length fully extended, m.
    #[must_use]
    pub fn extended_length_m(&self) -> f64 {
        self.retracted_length_m + self.stroke_m
    }

    /// Cylinder force from head and rod pressures, N, positive pushing toward extension (Eq. A20).
    #[must_use]
    pub fn force_n(&self, head_pa: f64, rod_pa: f64) -> f64 {
        head_pa * self.head_area_m2() - rod_pa * self.rod_area_m2() // Eq. A20
    }
}

/// The three implement cylinders.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cylinders {
    /// Boom cylinder(s).
    pub boom: Cylinder,
    /// Stick cylinder.
    pub stick: Cylinder,
    /// Bucket cylinder.
    pub bucket: Cylinder,
}

/// Mass and centre of gravity of one link (Eq. A4), the centre given in the link's own frame: distance from
/// the link's proximal joint and angle from the link line (counter-clockwise positive in the side view).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkMass {
    /// Mass including the cylinders it carries, kg.
    pub mass_kg: f64,
    /// Proximal joint to the centre of gravity, m.
    pub cog_distance_m: f64,
    /// Angle of the centre of gravity from the link line.
    #[serde(rename = "cog_angle_deg", with = "degrees")]
    pub cog_angle_rad: f64,
}

/// Link masses (Eq. A4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkMasses {
    /// Boom.
    pub boom: LinkMass,
    /// Stick.
    pub stick: LinkMass,
    /// Empty bucket with its linkage.
    pub bucket: LinkMass,
}

impl LinkMasses {
    /// The links `[boom, stick, bucket]`.
    #[must_use]
    pub fn links(&self) -> [&LinkMass; 3] {
        [&self.boom, &self.stick, &self.bucket]
    }

    /// The links `[boom, stick, bucket]`, to change.
    pub fn links_mut(&mut self) -> [&mut LinkMass; 3] {
        [&mut self.boom, &mut self.stick, &mut self.bucket]
    }

    /// The masses `[boom, stick, bucket]`, kg.
    #[must_use]
    pub fn mass_kg(&self) -> [f64; 3] {
        self.links().map(|l| l.mass_kg)
    }
}

/// The bucket as a container.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BucketSpec {
    /// Cutting-edge width, m (`w` of Eq. 17).
    pub width_m: f64,
    /// Heaped capacity, m^3.
    pub capacity_m3: f64,
    /// Rated material density the capacity is quoted for, kg/m^3.
    pub rated_density_kg_per_m3: f64,
    /// Bucket pin to the centroid of the payload, m (the centroid `x_c` of Eq. 19 follows from the pose).
    pub payload_centroid_distance_m: f64,
    /// Angle of the payload centroid from the bucket line (pin -> tip).
    #[serde(rename = "payload_centroid_angle_deg", with = "degrees")]
    pub payload_centroid_angle_rad: f64,
}

/// Hydraulic system (thesis 4.2.1, Fig. 15; Eqs. 1-2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hydraulics {
    /// Main relief pressure, Pa.
    pub relief_pressure_pa: f64,
    /// Tank (return) pressure, Pa.
    pub tank_pressure_pa: f64,
    /// Number of main pumps (boom+bucket on one, stick+swing on the other).
    pub pump_count: u32,
    /// Maximum flow of each pump, m^3/s.
    pub pump_max_flow_m3_per_s: f64,
    /// Engine power available to the pumps before they destroke, W.
    pub max_engine_power_w: f64,
    /// Valve orifice discharge coefficient `C_d` (Eq. 1), for `Q = C_d A sqrt(dP)` with `dP` in Pa.
    pub valve_discharge_coefficient: f64,
    /// Fully open valve metering area, m^2 (Eq. 1).
    pub valve_max_area_m2: f64,
    /// Open-centre bleed-off area at neutral, m^2.
    pub valve_bleed_area_m2: f64,
    /// Boom command fraction above which the crossover valve adds the other pump's spare flow.
    pub crossover_command: f64,
    /// Fixed transport delay from command to valve motion, s.
    pub transport_delay_s: f64,
    /// First-order lag time constant of pressure/flow build-up, s.
    pub lag_time_constant_s: f64,
    /// Effective oil bulk modulus, Pa (Eq. 2).
    pub bulk_modulus_pa: f64,
}

/// Joint limits (software limits, inside what the cylinder strokes allow).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointLimits {
    /// Boom, lowest.
    #[serde(rename = "boom_min_deg", with = "degrees")]
    pub boom_min_rad: f64,
    /// Boom, highest.
    #[serde(rename = "boom_max_deg", with = "degrees")]
    pub boom_max_rad: f64,
    /// Stick relative to the boom, most curled in.
    #[serde(rename = "stick_min_deg", with = "degrees")]
    pub stick_min_rad: f64,
    /// Stick relative to the boom, farthest out.
    #[serde(rename = "stick_max_deg", with = "degrees")]
    pub stick_max_rad: f64,
    /// Bucket relative to the stick, most curled.
    #[serde(rename = "bucket_min_deg", with = "degrees")]
    pub bucket_min_rad: f64,
    /// Bucket relative to the stick, most open.
    #[serde(rename = "bucket_max_deg", with = "degrees")]
    pub bucket_max_rad: f64,
}

/// Swing drive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Swing {
    /// Maximum swing rate, rad/s.
    pub max_rate_rad_per_s: f64,
    /// Maximum swing acceleration, rad/s^2.
    pub max_accel_rad_per_s2: f64,
    /// Upper-structure moment of inertia about the swing axis (empty implement), kg m^2.
    pub inertia_kg_m2: f64,
}

/// Undercarriage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tracks {
    /// Track gauge (centre to centre), m.
    pub gauge_m: f64,
    /// Overall track length, m.
    pub length_m: f64,
    /// Shoe width, m.
    pub shoe_width_m: f64,
    /// Maximum travel speed, m/s.
    pub max_speed_m_per_s: f64,
}

/// Range-sensor mount (Fig. 51: `h` and `r_s`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorMount {
    /// Sensor height above the ground the tracks stand on, m (`h` of Fig. 51).
    pub height_m: f64,
    /// Radial distance from the swing axis to the sensor, m (`r_s` of Fig. 51).
    pub radial_offset_m: f64,
    /// Direction of the sensor from the swing axis relative to the digging plane (positive = left).
    #[serde(rename = "bearing_deg", with = "degrees")]
    pub bearing_rad: f64,
}

/// The whole machine (one `config/machine.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineConfig {
    /// Human-readable name.
    pub name: String,
    /// Operating mass, kg.
    pub operating_mass_kg: f64,
    /// Boom foot pin in the base frame.
    pub base: BaseGeometry,
    /// Link lengths.
    pub links: LinkLengths,
    /// Boom cylinder attachment (Fig. A1, joint 2).
    pub boom_mount: CylinderMount,
    /// Stick cylinder attachment (Fig. A1, joint 3).
    pub stick_mount: CylinderMount,
    /// Bucket four-bar (Fig. A2).
    pub bucket_linkage: BucketLinkage,
    /// Cylinders.
    pub cylinders: Cylinders,
    /// Link masses and centres of gravity (Eq. A4).
    pub masses: LinkMasses,
    /// The bucket as a container.
    pub bucket: BucketSpec,
    /// Hydraulics.
    pub hydraulics: Hydraulics,
    /// Joint limits.
    pub limits: JointLimits,
    /// Swing drive.
    pub swing: Swing,
    /// Tracks.
    pub tracks: Tracks,
    /// Range-sensor mount.
    pub sensor: SensorMount,
}

/// The default machine file, compiled in so tests and tools have a machine without I/O.
pub const DEFAULT_MACHINE_TOML: &str = include_str!("../../config/machine.toml");

impl MachineConfig {
    /// The default 20-25 t machine (`config/machine.toml`).
    ///
    /// # Errors
    /// Only if the bundled file is broken, which the tests rule out.
    pub fn default_machine() -> Result<Self, ConfigError> {
        Self::from_toml_str_named(DEFAULT_MACHINE_TOML, "config/machine.toml")
    }

    /// The machine file at `path`, or without one the built-in machine (`config/machine.toml`): what a
    /// command's `--machine` option means.
    ///
    /// # Errors
    /// As [`Self::from_toml_file`]; every error names the file (`config/machine.toml` for the built-in
    /// one), and the line and field where it can.
    pub fn load_or_default(path: Option<&Path>) -> Result<Self, ConfigError> {
        match path {
            Some(p) => Self::from_toml_file(p),
            None => Self::default_machine(),
        }
    }

    /// Reads a machine file as the controller does: its simulator tables ([`SIMULATOR_TABLES`]: a
    /// simulated machine's hidden effects and its gateway's NAME) ignored, errors naming the file,
    /// line and field; the built-in machine without a path.
    ///
    /// # Errors
    /// As [`Self::from_toml_file`].
    pub fn controller_file(path: Option<&Path>) -> Result<Self, ConfigError> {
        let Some(path) = path else {
            return Self::default_machine();
        };
        let origin = path.display().to_string();
        let text = crate::config_file::read_text(path).map_err(|reason| ConfigError::Io {
            origin: origin.clone(),
            reason,
        })?;
        Self::from_toml_str_named(&split_simulator_tables(&text).0, &origin)
    }

    /// Parses and validates a machine from TOML text.
    ///
    /// # Errors
    /// [`ConfigError::Parse`] for bad TOML or schema mismatch, [`ConfigError::Invalid`] for out-of-range or
    /// inconsistent values.
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        Self::from_toml_str_named(text, "<string>")
    }

    /// Reads, parses and validates a machine file; errors name the file, line and field.
    ///
    /// # Errors
    /// As [`Self::from_toml_str`], plus [`ConfigError::Io`] when the file cannot be read.
    pub fn from_toml_file(path: &Path) -> Result<Self, ConfigError> {
        let origin = path.display().to_string();
        let text = crate::config_file::read_text(path).map_err(|reason| ConfigError::Io {
            origin: origin.clone(),
            reason,
        })?;
        Self::from_toml_str_named(&text, &origin)
    }

    /// Parses and validates, naming `origin` in errors.
    ///
    /// # Errors
    /// As [`Self::from_toml_str`].
    pub fn from_toml_str_named(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            line: e.span().map(|s| toml_lines::line_of_offset(text, s.start)),
            message: e.message().to_string(),
        })?;
        cfg.validate()
            .map_err(|(field, reason)| ConfigError::Invalid {
                origin: origin.to_string(),
                line: toml_lines::line_of_field(text, &field),
                field,
                reason,
            })?;
        Ok(cfg)
    }

    /// Checks every field and the geometric consistency of the machine.
    ///
    /// # Errors
    /// `(field path, reason)` for the first problem found.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let mut checks: Vec<(String, f64)> = [
            ("operating_mass_kg", self.operating_mass_kg),
            ("base.boom_foot_z_m", self.base.boom_foot_z_m),
            ("links.boom_m", self.links.boom_m),
            ("links.stick_m", self.links.stick_m),
            ("links.bucket_m", self.links.bucket_m),
            ("boom_mount.a_m", self.boom_mount.a_m),
            ("boom_mount.b_m", self.boom_mount.b_m),
            ("stick_mount.a_m", self.stick_mount.a_m),
            ("stick_mount.b_m", self.stick_mount.b_m),
            ("bucket_linkage.e1_m", self.bucket_linkage.e1_m),
            ("bucket_linkage.e2_m", self.bucket_linkage.e2_m),
            ("bucket_linkage.e3_m", self.bucket_linkage.e3_m),
            ("bucket_linkage.e4_m", self.bucket_linkage.e4_m),
            ("bucket_linkage.p_m", self.bucket_linkage.p_m),
            ("bucket.width_m", self.bucket.width_m),
            ("bucket.capacity_m3", self.bucket.capacity_m3),
            (
                "bucket.rated_density_kg_per_m3",
                self.bucket.rated_density_kg_per_m3,
            ),
            (
                "hydraulics.relief_pressure_pa",
                self.hydraulics.relief_pressure_pa,
            ),
            (
                "hydraulics.pump_max_flow_m3_per_s",
                self.hydraulics.pump_max_flow_m3_per_s,
            ),
            (
                "hydraulics.max_engine_power_w",
                self.hydraulics.max_engine_power_w,
            ),
            (
                "hydraulics.valve_discharge_coefficient",
                self.hydraulics.valve_discharge_coefficient,
            ),
            (
                "hydraulics.valve_max_area_m2",
                self.hydraulics.valve_max_area_m2,
            ),
            (
                "hydraulics.lag_time_constant_s",
                self.hydraulics.lag_time_constant_s,
            ),
            (
                "hydraulics.bulk_modulus_pa",
                self.hydraulics.bulk_modulus_pa,
            ),
            ("swing.max_rate_rad_per_s", self.swing.max_rate_rad_per_s),
            (
                "swing.max_accel_rad_per_s2",
                self.swing.max_accel_rad_per_s2,
            ),
            ("swing.inertia_kg_m2", self.swing.inertia_kg_m2),
            ("tracks.gauge_m", self.tracks.gauge_m),
            ("tracks.length_m", self.tracks.length_m),
            ("tracks.shoe_width_m", self.tracks.shoe_width_m),
            ("tracks.max_speed_m_per_s", self.tracks.max_speed_m_per_s),
            ("sensor.height_m", self.sensor.height_m),
        ]
        .iter()
        .map(|(n, v)| ((*n).to_string(), *v))
        .collect();
        for (name, c) in [
            ("boom", &self.cylinders.boom),
            ("stick", &self.cylinders.stick),
            ("bucket", &self.cylinders.bucket),
        ] {
            checks.push((format!("cylinders.{name}.bore_m"), c.bore_m));
            checks.push((format!("cylinders.{name}.rod_m"), c.rod_m));
            checks.push((format!("cylinders.{name}.stroke_m"), c.stroke_m));
            checks.push((
                format!("cylinders.{name}.retracted_length_m"),
                c.retracted_length_m,
            ));
            checks.push((
                format!("cylinders.{name}.max_speed_m_per_s"),
                c.max_speed_m_per_s,
            ));
        }
        for (name, m) in [
            ("boom", &self.masses.boom),
            ("stick", &self.masses.stick),
            ("bucket", &self.masses.bucket),
        ] {
            checks.push((format!("masses.{name}.mass_kg"), m.mass_kg));
        }
        for (field, v) in checks {
            check_field(&field, v, Limits::POSITIVE)?;
        }
        let finite: [(&str, f64); 22] = [
            ("base.boom_foot_x_m", self.base.boom_foot_x_m),
            (
                "boom_mount.gamma_offset_deg",
                self.boom_mount.gamma_offset_rad,
            ),
            (
                "stick_mount.gamma_offset_deg",
                self.stick_mount.gamma_offset_rad,
            ),
            (
                "bucket_linkage.e1_angle_deg",
                self.bucket_linkage.e1_angle_rad,
            ),
            (
                "bucket_linkage.e4_angle_deg",
                self.bucket_linkage.e4_angle_rad,
            ),
            (
                "bucket_linkage.p_angle_deg",
                self.bucket_linkage.p_angle_rad,
            ),
            (
                "masses.boom.cog_distance_m",
                self.masses.boom.cog_distance_m,
            ),
            ("masses.boom.cog_angle_deg", self.masses.boom.cog_angle_rad),
            (
                "masses.stick.cog_distance_m",
                self.masses.stick.cog_distance_m,
            ),
            (
                "masses.stick.cog_angle_deg",
                self.masses.stick.cog_angle_rad,
            ),
            (
                "masses.bucket.cog_distance_m",
                self.masses.bucket.cog_distance_m,
            ),
            (
                "masses.bucket.cog_angle_deg",
                self.masses.bucket.cog_angle_rad,
            ),
            (
                "bucket.payload_centroid_distance_m",
                self.bucket.payload_centroid_distance_m,
            ),
            (
                "bucket.payload_centroid_angle_deg",
                self.bucket.payload_centroid_angle_rad,
            ),
            (
                "hydraulics.tank_pressure_pa",
                self.hydraulics.tank_pressure_pa,
            ),
            (
                "hydraulics.valve_bleed_area_m2",
                self.hydraulics.valve_bleed_area_m2,
            ),
            (
                "hydraulics.crossover_command",
                self.hydraulics.crossover_command,
            ),
            (
                "hydraulics.transport_delay_s",
                self.hydraulics.transport_delay_s,
            ),
            ("sensor.radial_offset_m", self.sensor.radial_offset_m),
            ("sensor.bearing_deg", self.sensor.bearing_rad),
            ("limits.boom_min_deg", self.limits.boom_min_rad),
            ("limits.boom_max_deg", self.limits.boom_max_rad),
        ];
        for (field, v) in finite {
            check_field(field, v, Limits::FINITE)?;
        }
        for (field, v) in [
            (
                "hydraulics.tank_pressure_pa",
                self.hydraulics.tank_pressure_pa,
            ),
            (
                "hydraulics.valve_bleed_area_m2",
                self.hydraulics.valve_bleed_area_m2,
            ),
            (
                "hydraulics.transport_delay_s",
                self.hydraulics.transport_delay_s,
            ),
            ("sensor.radial_offset_m", self.sensor.radial_offset_m),
        ] {
            check_field(field, v, Limits::NON_NEGATIVE)?;
        }
        // Physical ranges, generous for the excavator class: a value beyond them is a typo or an
        // attack (relief at 1e308 Pa disables every 90 %-of-relief rule).
        let h = &self.hydraulics;
        let mut ranges: Vec<(String, f64, f64, f64)> = vec![
            (
                "operating_mass_kg".into(),
                self.operating_mass_kg,
                500.0,
                200e3,
            ),
            ("links.boom_m".into(), self.links.boom_m, 0.1, 20.0),
            ("links.stick_m".into(), self.links.stick_m, 0.1, 20.0),
            ("links.bucket_m".into(), self.links.bucket_m, 0.05, 5.0),
            ("bucket.width_m".into(), self.bucket.width_m, 0.1, 5.0),
            (
                "bucket.capacity_m3".into(),
                self.bucket.capacity_m3,
                0.005,
                20.0,
            ),
            (
                "bucket.rated_density_kg_per_m3".into(),
                self.bucket.rated_density_kg_per_m3,
                500.0,
                4000.0,
            ),
            (
                "hydraulics.relief_pressure_pa".into(),
                h.relief_pressure_pa,
                5e6,
                50e6,
            ),
            (
                "hydraulics.tank_pressure_pa".into(),
                h.tank_pressure_pa,
                0.0,
                2e6,
            ),
            (
                "hydraulics.pump_max_flow_m3_per_s".into(),
                h.pump_max_flow_m3_per_s,
                1e-5,
                0.02,
            ),
            (
                "hydraulics.max_engine_power_w".into(),
                h.max_engine_power_w,
                1e3,
                1e6,
            ),
            (
                "hydraulics.valve_discharge_coefficient".into(),
                h.valve_discharge_coefficient,
                1e-4,
                1.0,
            ),
            (
                "hydraulics.valve_max_area_m2".into(),
                h.valve_max_area_m2,
                1e-7,
                1e-2,
            ),
            (
                "hydraulics.transport_delay_s".into(),
                h.transport_delay_s,
                0.0,
                1.0,
            ),
        ];
        for (name, m) in [
            ("boom", &self.masses.boom),
            ("stick", &self.masses.stick),
            ("bucket", &self.masses.bucket),
        ] {
            ranges.push((format!("masses.{name}.mass_kg"), m.mass_kg, 1.0, 50e3));
        }
        for (field, v, lo, hi) in ranges {
            check_field_exp(&field, v, Limits::closed(lo, hi, ""))?;
        }
        if h.valve_bleed_area_m2 >= h.valve_max_area_m2 {
            return Err((
                "hydraulics.valve_bleed_area_m2".into(),
                format!(
                    "must be below the valve's full area (hydraulics.valve_max_area_m2 = {:e}), got {:e}",
                    h.valve_max_area_m2, h.valve_bleed_area_m2
                ),
            ));
        }
        check_field(
            "hydraulics.crossover_command",
            self.hydraulics.crossover_command,
            Limits::closed(0.0, 1.0, ""),
        )?;
        if self.hydraulics.tank_pressure_pa >= self.hydraulics.relief_pressure_pa {
            return Err((
                "hydraulics.tank_pressure_pa".into(),
                "must be below the relief pressure".into(),
            ));
        }
        if self.hydraulics.pump_count == 0 {
            return Err(("hydraulics.pump_count".into(), "must be at least 1".into()));
        }
        for (name, c) in [
            ("boom", &self.cylinders.boom),
            ("stick", &self.cylinders.stick),
            ("bucket", &self.cylinders.bucket),
        ] {
            if c.count == 0 {
                return Err((
                    format!("cylinders.{name}.count"),
                    "must be at least 1".into(),
                ));
            }
            if c.rod_m >= c.bore_m {
                return Err((
                    format!("cylinders.{name}.rod_m"),
                    format!(
                        "rod {} m must be thinner than the bore {} m",
                        c.rod_m, c.bore_m
                    ),
                ));
            }
            if c.stroke_m >= c.retracted_length_m {
                return Err((
                    format!("cylinders.{name}.stroke_m"),
                    "a cylinder cannot stroke more than its retracted length".into(),
                ));
            }
        }
        let l = &self.limits;
        for (field, lo, hi) in [
            ("limits.boom_max_deg", l.boom_min_rad, l.boom_max_rad),
            ("limits.stick_max_deg", l.stick_min_rad, l.stick_max_rad),
            ("limits.bucket_max_deg", l.bucket_min_rad, l.bucket_max_rad),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err((
                    field.into(),
                    "joint limits must be finite with min < max".into(),
                ));
            }
        }
        check_field(
            "bucket.payload_centroid_distance_m",
            self.bucket.payload_centroid_distance_m,
            Limits::NON_NEGATIVE,
        )?;
        // The geometry: the strokes must reach the joint limits, the four-bar must assemble.
        self.linkage().stroke_ranges().map_err(|e| match e {
            LinkageError::Config { field, reason } => (field, reason),
            other => ("limits".to_string(), other.to_string()),
        })?;
        Ok(())
    }

    /// The implement linkage of this machine in plain numbers: what the geometric checks of
    /// [`Self::validate`] and the kinematics are computed on.
    pub(crate) fn linkage(&self) -> Linkage {
        let cyl = &self.cylinders;
        let bl = &self.bucket_linkage;
        let lim = &self.limits;
        Linkage {
            boom: Mount {
                a: self.boom_mount.a_m,
                b: self.boom_mount.b_m,
                offset: self.boom_mount.gamma_offset_rad,
                sense: 1.0,
            },
            stick: Mount {
                a: self.stick_mount.a_m,
                b: self.stick_mount.b_m,
                offset: self.stick_mount.gamma_offset_rad,
                sense: -1.0,
            },
            four_bar: FourBar::new(
                [bl.e1_m, bl.e2_m, bl.e3_m],
                bl.e1_angle_rad,
                (bl.e4_m, bl.e4_angle_rad),
                (bl.p_m, bl.p_angle_rad),
            ),
            stroke: [
                (cyl.boom.retracted_length_m, cyl.boom.extended_length_m()),
                (cyl.stick.retracted_length_m, cyl.stick.extended_length_m()),
                (
                    cyl.bucket.retracted_length_m,
                    cyl.bucket.extended_length_m(),
                ),
            ],
            limits: [
                (lim.boom_min_rad, lim.boom_max_rad),
                (lim.stick_min_rad, lim.stick_max_rad),
                (lim.bucket_min_rad, lim.bucket_max_rad),
            ],
        }
    }

    /// Full-bucket payload at the rated density, kg.
    #[must_use]
    pub fn rated_payload_kg(&self) -> f64 {
        self.bucket.capacity_m3 * self.bucket.rated_density_kg_per_m3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn dev_zero_as_a_machine_file_is_refused_at_once() {
        let started = std::time::Instant::now();
        for load in [
            |p: &Path| MachineConfig::from_toml_file(p),
            |p: &Path| MachineConfig::controller_file(Some(p)),
        ] {
            let e = load(Path::new("/dev/zero")).unwrap_err().to_string();
            assert!(
                e.contains("/dev/zero") && e.contains("not a regular file"),
                "{e}"
            );
        }
        assert!(started.elapsed() < std::time::Duration::from_secs(1));
    }

    #[test]
    fn default_machine_parses_and_validates() {
        let m = MachineConfig::default_machine().expect("default machine");
        assert!(m.links.boom_m > 5.0 && m.links.boom_m < 6.5);
        // 1.5 m^3 at 1700 kg/m^3 is about 25 kN of payload.
        let payload_n = m.rated_payload_kg() * GRAVITY_M_PER_S2;
        assert!((20e3..30e3).contains(&payload_n), "{payload_n}");
    }

    #[test]
    fn serde_round_trip_keeps_the_machine() {
        let m = MachineConfig::default_machine().expect("default machine");
        let text = toml::to_string(&m).expect("serialize");
        let back = MachineConfig::from_toml_str(&text).expect("reparse");
        assert!((back.boom_mount.gamma_offset_rad - m.boom_mount.gamma_offset_rad).abs() < 1e-12);
        assert_eq!(back.cylinders, m.cylinders);
    }

    #[test]
    fn invalid_value_names_file_line_and_field() {
        let text = DEFAULT_MACHINE_TOML
            .replace("relief_pressure_pa = 34.3e6", "relief_pressure_pa = -1.0");
        assert_ne!(text, DEFAULT_MACHINE_TOML, "fixture line must exist");
        let err = MachineConfig::from_toml_str_named(&text, "m.toml").expect_err("must fail");
        let expected_line = text
            .lines()
            .position(|l| l.starts_with("relief_pressure_pa"))
            .map(|i| i + 1);
        match &err {
            ConfigError::Invalid {
                origin,
                line,
                field,
                ..
            } => {
                assert_eq!(origin, "m.toml");
                assert_eq!(field, "hydraulics.relief_pressure_pa");
                assert_eq!(*line, expected_line);
            }
            other => panic!("unexpected {other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.starts_with("m.toml:") && msg.contains("relief_pressure_pa"),
            "{msg}"
        );
    }

    /// Implausible machine files once accepted (relief 1e308 Pa disabled the 90 %-of-relief rules;
    /// 1e308 kg masses; a bleed area larger than the valve): each refused naming file, line, field.
    #[test]
    fn implausible_machine_values_are_refused_with_file_line_and_field() {
        let huge = ["1e308", "1e30", "-1e308", "0.0"];
        let mut cases: Vec<(&str, &str, String, &str)> = Vec::new();
        for (line_start, field) in [
            (
                "relief_pressure_pa = 34.3e6",
                "hydraulics.relief_pressure_pa",
            ),
            ("operating_mass_kg = 22000.0", "operating_mass_kg"),
            ("mass_kg = 1850.0", "masses.boom.mass_kg"),
            ("mass_kg = 950.0", "masses.stick.mass_kg"),
            ("mass_kg = 1000.0", "masses.bucket.mass_kg"),
            (
                "pump_max_flow_m3_per_s = 3.583e-3",
                "hydraulics.pump_max_flow_m3_per_s",
            ),
            (
                "max_engine_power_w = 110e3",
                "hydraulics.max_engine_power_w",
            ),
            ("valve_max_area_m2 = 1.2e-4", "hydraulics.valve_max_area_m2"),
        ] {
            let key = line_start.split(" = ").next().unwrap_or_default();
            for v in huge {
                cases.push((line_start, field, format!("{key} = {v}"), key));
            }
        }
        for v in ["1.2e-4", "2e-4", "1e308"] {
            cases.push((
                "valve_bleed_area_m2 = 0.8e-4",
                "hydraulics.valve_bleed_area_m2",
                format!("valve_bleed_area_m2 = {v}"),
                "valve_bleed_area_m2",
            ));
        }
        for (old, field, new, key) in &cases {
            assert!(DEFAULT_MACHINE_TOML.contains(old), "fixture {old}");
            let text = DEFAULT_MACHINE_TOML.replacen(old, new, 1);
            let err = MachineConfig::from_toml_str_named(&text, "m.toml")
                .expect_err(&format!("{new} accepted"));
            let ConfigError::Invalid {
                origin,
                line,
                field: got,
                ..
            } = &err
            else {
                panic!("{new}: {err:?}");
            };
            assert_eq!(origin, "m.toml");
            assert_eq!(got, field, "{new}: {err}");
            let at = line.unwrap_or_else(|| panic!("{new}: no line: {err}"));
            let line_text = text.lines().nth(at - 1).unwrap_or_default();
            assert!(
                line_text.trim_start().starts_with(key),
                "{new}: line {at} {line_text:?}"
            );
        }
        assert_eq!(cases.len(), 35, "the table's cases");
    }

    #[test]
    fn parse_error_names_line_and_field() {
        let text = DEFAULT_MACHINE_TOML.replace("bore_m = 0.140", "bore_m = \"wide\"");
        let err = MachineConfig::from_toml_str_named(&text, "m.toml").expect_err("must fail");
        match err {
            ConfigError::Parse {
                line: Some(l),
                message,
                ..
            } => {
                assert!(l > 1);
                assert!(!message.is_empty());
            }
            other => panic!("unexpected {other:?}"),
        }
    }

    #[test]
    fn stroke_that_cannot_reach_the_limits_is_rejected() {
        let text = DEFAULT_MACHINE_TOML.replace("boom_max_deg = 55.0", "boom_max_deg = 85.0");
        assert_ne!(text, DEFAULT_MACHINE_TOML);
        let err = MachineConfig::from_toml_str(&text).expect_err("must fail");
        assert!(err.to_string().contains("limits.boom_max_deg"), "{err}");
    }

    #[test]
    fn unknown_field_is_a_parse_error() {
        let text = DEFAULT_MACHINE_TOML.replace("[swing]", "[swing]\nbogus = 1.0");
        assert!(matches!(
            MachineConfig::from_toml_str(&text),
            Err(ConfigError::Parse { .. })
        ));
    }
}
