//! The work site as the controller knows it (`site.toml`): what a planned session needs about the
//! place it digs, and nothing about the simulated world.
//!
//! - `[work_area]`: the terrain map's grid in the site frame (the area the range scans are binned
//!   on and the planner plans over; thesis 5.1: the map of the bench).
//! - `[floor]`: the target floor elevation the digs, cleanups and tracking plans work to (thesis
//!   5.1.2, the "desired floor").
//! - `[machine]`: where the machine stands at the start of the session in the site frame (its
//!   joints come from its own sensors); the session dead-reckons from there (Appendix A.2).
//! - `[material]`: the bank density of the material, for the full bucket's weight the statistics
//!   compare each dig with (thesis 6.1: "25 000 N").
//!
//! The site frame is the simulator's world frame on a simulated bench: x forward along the tracks at
//! the start, z up, z = 0 the ground the machine stands on (docs/ARCHITECTURE.md). A simulator bench
//! file holds a site and the simulated world's truth (soil, boulders, initial terrain); its site part
//! is `vcan_sim::scenario::Scenario::site`, and `config/site.toml` is the extended bench's.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::machine::ConfigError;
use crate::toml_lines;
use gateway_core::range::Limits;

/// The bundled site of the extended-operation bench (`config/site.toml`, the default of `run`).
pub const EXTENDED_SITE_TOML: &str = include_str!("../../config/site.toml");

/// The most cells a work area may have (a 4 km^2 area at 0.1 m): the map is allocated up front.
pub const MAX_CELLS: f64 = 4.0e6;

/// The terrain map's grid in the site frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkArea {
    /// Cell size, m.
    pub cell_m: f64,
    /// West edge (smallest x), m.
    pub x_min_m: f64,
    /// South edge (smallest y), m.
    pub y_min_m: f64,
    /// Extent along x, m.
    pub size_x_m: f64,
    /// Extent along y, m.
    pub size_y_m: f64,
}

impl WorkArea {
    /// Cells along x and y (at least one each).
    #[must_use]
    pub fn cells(&self) -> (usize, usize) {
        let n = |size: f64| (size / self.cell_m).round().max(1.0) as usize;
        (n(self.size_x_m), n(self.size_y_m))
    }

    /// Whether the point `(x, y)` of the site frame lies on the area.
    #[must_use]
    pub fn contains(&self, x_m: f64, y_m: f64) -> bool {
        (self.x_min_m..=self.x_min_m + self.size_x_m).contains(&x_m)
            && (self.y_min_m..=self.y_min_m + self.size_y_m).contains(&y_m)
    }
}

/// The target floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Floor {
    /// Elevation in the site frame, m (negative: below the ground the machine stands on).
    pub elevation_m: f64,
}

/// The machine's pose at the start of the session, site frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineStart {
    /// Swing-axis x, m.
    pub x_m: f64,
    /// Swing-axis y, m.
    pub y_m: f64,
    /// Heading of the tracks, counter-clockwise from site x, degrees.
    pub heading_deg: f64,
}

/// The material dug.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Bank density, kg/m^3.
    pub bulk_density_kg_per_m3: f64,
}

/// A work site (`site.toml`; module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Site {
    /// Human-readable name (recorded in the session's summary and identity).
    pub name: String,
    /// The terrain map's grid.
    pub work_area: WorkArea,
    /// The target floor.
    pub floor: Floor,
    /// The machine's start pose.
    pub machine: MachineStart,
    /// The material.
    pub material: Material,
}

impl Site {
    /// The extended-operation bench's site (`config/site.toml`, compiled in).
    ///
    /// # Errors
    /// Only if the bundled file is broken, which the tests rule out.
    pub fn extended_bench() -> Result<Self, ConfigError> {
        Self::from_toml_str_named(EXTENDED_SITE_TOML, "config/site.toml")
    }

    /// Reads, parses and checks a site file; errors name the file, line and field.
    ///
    /// # Errors
    /// [`ConfigError::Io`] when the file cannot be read, else as [`Self::from_toml_str_named`].
    pub fn from_toml_file(path: &Path) -> Result<Self, ConfigError> {
        let origin = path.display().to_string();
        let text = crate::config_file::read_text(path).map_err(|reason| ConfigError::Io {
            origin: origin.clone(),
            reason,
        })?;
        Self::from_toml_str_named(&text, &origin)
    }

    /// Parses and checks site text from `origin` (a file name for the errors).
    ///
    /// # Errors
    /// [`ConfigError::Parse`] for bad TOML or a schema mismatch, [`ConfigError::Invalid`] for a value
    /// out of its physical range or inconsistent with the rest of the site.
    pub fn from_toml_str_named(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let site: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_owned(),
            line: e.span().map(|s| toml_lines::line_of_offset(text, s.start)),
            message: e.message().trim().to_owned(),
        })?;
        site.validate()
            .map_err(|(field, reason)| ConfigError::Invalid {
                origin: origin.to_owned(),
                line: toml_lines::line_of_field(text, &field),
                field,
                reason,
            })?;
        Ok(site)
    }

    /// The site as a file's text (the tables of [`EXTENDED_SITE_TOML`], without its comments).
    ///
    /// # Errors
    /// Only if serialisation fails, which a site of finite numbers never does.
    pub fn to_toml_string(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(self)
    }

    /// Checks every field's physical range and the site's consistency.
    ///
    /// # Errors
    /// `(field path, reason)` of the first problem.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let within = |field: &str, v: f64, lo: f64, hi: f64| {
            toml_lines::check_field(field, v, Limits::closed(lo, hi, ""))
        };
        if self.name.trim().is_empty() || self.name.len() > 200 {
            return Err(("name".into(), "must be 1 to 200 characters".into()));
        }
        let a = &self.work_area;
        // A bucket is about 1 m wide: cells from 2 cm (a scanner's resolution) to 1 m.
        within("work_area.cell_m", a.cell_m, 0.02, 1.0)?;
        // Positions: a site of at most 10 km either way of its origin.
        within("work_area.x_min_m", a.x_min_m, -1.0e4, 1.0e4)?;
        within("work_area.y_min_m", a.y_min_m, -1.0e4, 1.0e4)?;
        within("work_area.size_x_m", a.size_x_m, a.cell_m, 2.0e3)?;
        within("work_area.size_y_m", a.size_y_m, a.cell_m, 2.0e3)?;
        let (nx, ny) = a.cells();
        if (nx as f64) * (ny as f64) > MAX_CELLS {
            return Err((
                "work_area.cell_m".into(),
                format!(
                    "{nx} x {ny} cells: at most {MAX_CELLS:.0} (a larger cell or a smaller area)"
                ),
            ));
        }
        // Deeper than any excavator reaches below its tracks, or higher than it reaches above.
        within("floor.elevation_m", self.floor.elevation_m, -20.0, 20.0)?;
        let m = &self.machine;
        within("machine.x_m", m.x_m, -1.0e4, 1.0e4)?;
        within("machine.y_m", m.y_m, -1.0e4, 1.0e4)?;
        within("machine.heading_deg", m.heading_deg, -360.0, 360.0)?;
        if !a.contains(m.x_m, m.y_m) {
            return Err((
                "machine.x_m".into(),
                format!(
                    "the machine at ({}, {}) m stands outside the work area x {}..{} m, y {}..{} m",
                    m.x_m,
                    m.y_m,
                    a.x_min_m,
                    a.x_min_m + a.size_x_m,
                    a.y_min_m,
                    a.y_min_m + a.size_y_m
                ),
            ));
        }
        // Natural soils and broken rock in the bank: about 1100 (peat, loose) to 2700 kg/m^3.
        within(
            "material.bulk_density_kg_per_m3",
            self.material.bulk_density_kg_per_m3,
            500.0,
            3000.0,
        )?;
        Ok(())
    }

    /// The weight of a full bucket of `capacity_m3` of this material, N (thesis 6.1).
    #[must_use]
    pub fn full_bucket_n(&self, capacity_m3: f64) -> f64 {
        capacity_m3 * self.material.bulk_density_kg_per_m3 * crate::machine::GRAVITY_M_PER_S2
    }

    /// The machine's start pose as the estimator takes it.
    #[must_use]
    pub fn start_pose(&self) -> crate::kinematics::MachinePose {
        crate::kinematics::MachinePose {
            x_m: self.machine.x_m,
            y_m: self.machine.y_m,
            heading_rad: self.machine.heading_deg.to_radians(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundled_site_loads_and_round_trips() {
        let site = Site::extended_bench().unwrap();
        assert_eq!(site.floor.elevation_m, -2.0);
        let again = Site::from_toml_str_named(&site.to_toml_string().unwrap(), "again").unwrap();
        assert_eq!(again, site);
        // 1.5 m^3 of 1700 kg/m^3: the thesis's 25 000 N.
        assert!((site.full_bucket_n(1.5) - 25_015.5).abs() < 1.0);
    }

    /// Out-of-range and inconsistent values are refused naming the file, line and field.
    #[test]
    fn bad_values_name_the_file_line_and_field() {
        let cases = [
            ("cell_m = 0.1", "cell_m = 1e-300", "work_area.cell_m"),
            ("cell_m = 0.1", "cell_m = 0.02", "work_area.cell_m"), // 1800 x 1000 cells: fine
            ("size_x_m = 36.0", "size_x_m = 1e308", "work_area.size_x_m"),
            (
                "elevation_m = -2.0",
                "elevation_m = nan",
                "floor.elevation_m",
            ),
            (
                "heading_deg = 0.0",
                "heading_deg = 1e9",
                "machine.heading_deg",
            ),
            ("x_m = 0.0", "x_m = 100.0", "machine.x_m"),
            (
                "bulk_density_kg_per_m3 = 1700.0",
                "bulk_density_kg_per_m3 = 1e308",
                "material.bulk_density_kg_per_m3",
            ),
        ];
        for (from, to, field) in cases {
            assert!(EXTENDED_SITE_TOML.contains(from), "{from}");
            let text = EXTENDED_SITE_TOML.replacen(from, to, 1);
            let got = Site::from_toml_str_named(&text, "site.toml");
            if to == "cell_m = 0.02" {
                assert!(got.is_ok(), "{got:?}");
                continue;
            }
            let e = got.unwrap_err().to_string();
            let line = text.lines().position(|l| l.contains(to)).unwrap() + 1;
            assert!(
                e.starts_with(&format!("site.toml:{line}: field `{field}`")),
                "{to}: {e}"
            );
        }
        let e = Site::from_toml_str_named("name = \"x\"\n[floor]\nelevation = 1\n", "s.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("s.toml:"), "{e}");
    }
}
