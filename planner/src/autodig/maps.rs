//! The Autodig maps (thesis Figs. 10-11): per soil hardness index, the piecewise-linear curves from a
//! cylinder's head pressure (percent of relief) to a command (percent of maximum velocity), and
//! their loading from TOML (`config/autodig_maps.toml`) with errors naming the curve and the point.

use serde::{Deserialize, Serialize};

/// The shipped maps, `config/autodig_maps.toml`, embedded at compile time (see [`AutodigMaps::builtin`]).
pub const BUILTIN_MAPS_TOML: &str = include_str!("../../../config/autodig_maps.toml");

/// Errors loading or validating [`AutodigMaps`]; they name the curve and the point.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapsError {
    /// The TOML text does not parse or has the wrong shape.
    #[error("autodig maps: {0}")]
    Parse(String),
    /// A curve has fewer than two points.
    #[error("autodig curve {curve}: needs at least 2 points, has {count}")]
    TooFewPoints {
        /// Curve name, e.g. `hardness[2] (index 3).dig_bucket`.
        curve: String,
        /// Number of points.
        count: usize,
    },
    /// A point coordinate is NaN or infinite.
    #[error("autodig curve {curve}, point {point}: not finite")]
    NonFinite {
        /// Curve name.
        curve: String,
        /// Index of the point (0-based).
        point: usize,
    },
    /// Pressures must rise strictly from point to point.
    #[error(
        "autodig curve {curve}, point {point}: pressure {x} % does not rise above {previous_x} %"
    )]
    NotIncreasing {
        /// Curve name.
        curve: String,
        /// Index of the point (0-based).
        point: usize,
        /// Its pressure, percent of relief.
        x: f64,
        /// The previous point's pressure.
        previous_x: f64,
    },
    /// Pressure outside 0..=100 % of relief.
    #[error("autodig curve {curve}, point {point}: pressure {x} % outside 0..=100")]
    PressureOutOfRange {
        /// Curve name.
        curve: String,
        /// Index of the point (0-based).
        point: usize,
        /// Its pressure, percent of relief.
        x: f64,
    },
    /// Command outside -100..=100 % of maximum cylinder velocity.
    #[error("autodig curve {curve}, point {point}: command {y} % outside -100..=100")]
    CommandOutOfRange {
        /// Curve name.
        curve: String,
        /// Index of the point (0-based).
        point: usize,
        /// Its command, percent.
        y: f64,
    },
    /// No `[[hardness]]` curve set.
    #[error("autodig maps: no [[hardness]] curve set")]
    NoCurveSets,
    /// Hardness indices must be finite and rise strictly.
    #[error("autodig maps: hardness[{position}] index {index} is not finite or does not rise")]
    HardnessNotIncreasing {
        /// Position of the set in the file (0-based).
        position: usize,
        /// Its index.
        index: f64,
    },
}

/// A piecewise-linear map from percent pressure (x) to percent command (y); ends hold outside the range.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(transparent)]
pub struct Curve {
    points: Vec<[f64; 2]>,
}

impl Curve {
    /// Builds a validated curve named `name` (used in errors).
    ///
    /// # Errors
    /// [`MapsError`] naming the curve and point when there are fewer than two points, a value is not
    /// finite, x does not rise strictly or leaves 0..=100, or y leaves -100..=100.
    pub fn new(name: &str, points: Vec<[f64; 2]>) -> Result<Self, MapsError> {
        if points.len() < 2 {
            return Err(MapsError::TooFewPoints {
                curve: name.to_owned(),
                count: points.len(),
            });
        }
        for (i, &[x, y]) in points.iter().enumerate() {
            if !x.is_finite() || !y.is_finite() {
                return Err(MapsError::NonFinite {
                    curve: name.to_owned(),
                    point: i,
                });
            }
            if !(0.0..=100.0).contains(&x) {
                return Err(MapsError::PressureOutOfRange {
                    curve: name.to_owned(),
                    point: i,
                    x,
                });
            }
            if !(-100.0..=100.0).contains(&y) {
                return Err(MapsError::CommandOutOfRange {
                    curve: name.to_owned(),
                    point: i,
                    y,
                });
            }
            if i > 0 && x <= points[i - 1][0] {
                return Err(MapsError::NotIncreasing {
                    curve: name.to_owned(),
                    point: i,
                    x,
                    previous_x: points[i - 1][0],
                });
            }
        }
        Ok(Self { points })
    }

    /// The `[pressure_pct, command_pct]` points.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Command (percent) at `pressure_pct`. NaN input gives the first point's command.
    pub fn eval(&self, pressure_pct: f64) -> f64 {
        let pts = &self.points;
        let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
            return 0.0; // unreachable for a validated curve; neutral is the safe answer
        };
        if pressure_pct.is_nan() || pressure_pct <= first[0] {
            return first[1];
        }
        if pressure_pct >= last[0] {
            return last[1];
        }
        for w in pts.windows(2) {
            let ([x0, y0], [x1, y1]) = (w[0], w[1]);
            if pressure_pct <= x1 {
                return y0 + (y1 - y0) * (pressure_pct - x0) / (x1 - x0);
            }
        }
        last[1]
    }
}

/// The curves for one soil hardness index (Figs. 10, 11).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurveSet {
    /// The soil hardness index of this set.
    pub index: f64,
    /// Pre-Dig boom command from bucket head pressure (Fig. 10).
    pub predig_boom: Curve,
    /// Dig boom command from stick head pressure (Fig. 11).
    pub dig_boom: Curve,
    /// Dig bucket command from bucket head pressure (Fig. 11).
    pub dig_bucket: Curve,
}

/// Which map to evaluate (for [`AutodigMaps::eval`] and the plots of the lab).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MapKind {
    /// Pre-Dig stick command from stick pressure (one curve for all indices).
    PreDigStick,
    /// Pre-Dig boom command from bucket pressure.
    PreDigBoom,
    /// Dig boom command from stick pressure.
    DigBoom,
    /// Dig bucket command from bucket pressure.
    DigBucket,
}

impl MapKind {
    /// All maps, in plot order.
    pub const ALL: [MapKind; 4] = [
        MapKind::PreDigBoom,
        MapKind::PreDigStick,
        MapKind::DigBoom,
        MapKind::DigBucket,
    ];

    /// Plot title: stage, commanded joint and input pressure.
    pub const fn title(self) -> &'static str {
        match self {
            MapKind::PreDigStick => "Pre-Dig stick command vs stick head pressure (Fig. 10)",
            MapKind::PreDigBoom => "Pre-Dig boom command vs bucket head pressure (Fig. 10)",
            MapKind::DigBoom => "Dig boom command vs stick head pressure (Fig. 11)",
            MapKind::DigBucket => "Dig bucket command vs bucket head pressure (Fig. 11)",
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSet {
    index: f64,
    predig_boom: Vec<[f64; 2]>,
    dig_boom: Vec<[f64; 2]>,
    dig_bucket: Vec<[f64; 2]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaps {
    predig_stick: Vec<[f64; 2]>,
    hardness: Vec<RawSet>,
}

/// All Autodig maps: the Pre-Dig stick curve and one [`CurveSet`] per soil hardness index.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AutodigMaps {
    predig_stick: Curve,
    sets: Vec<CurveSet>,
}

impl AutodigMaps {
    /// Parses and validates maps from TOML text (format: `config/autodig_maps.toml`).
    ///
    /// # Errors
    /// [`MapsError::Parse`] for bad TOML or shape; otherwise the validation errors of [`Curve::new`],
    /// [`MapsError::NoCurveSets`] and [`MapsError::HardnessNotIncreasing`].
    pub fn from_toml_str(text: &str) -> Result<Self, MapsError> {
        let raw: RawMaps = toml::from_str(text).map_err(|e| MapsError::Parse(e.to_string()))?;
        let predig_stick = Curve::new("predig_stick", raw.predig_stick)?;
        if raw.hardness.is_empty() {
            return Err(MapsError::NoCurveSets);
        }
        let mut sets = Vec::with_capacity(raw.hardness.len());
        for (pos, s) in raw.hardness.into_iter().enumerate() {
            let prev = sets.last().map(|p: &CurveSet| p.index);
            if !s.index.is_finite() || prev.is_some_and(|p| s.index <= p) {
                return Err(MapsError::HardnessNotIncreasing {
                    position: pos,
                    index: s.index,
                });
            }
            let name = |c: &str| format!("hardness[{pos}] (index {}).{c}", s.index);
            sets.push(CurveSet {
                index: s.index,
                predig_boom: Curve::new(&name("predig_boom"), s.predig_boom)?,
                dig_boom: Curve::new(&name("dig_boom"), s.dig_boom)?,
                dig_bucket: Curve::new(&name("dig_bucket"), s.dig_bucket)?,
            });
        }
        Ok(Self { predig_stick, sets })
    }

    /// The maps shipped in `config/autodig_maps.toml` (embedded at compile time).
    ///
    /// # Errors
    /// As [`AutodigMaps::from_toml_str`]; the unit tests check the shipped file loads.
    pub fn builtin() -> Result<Self, MapsError> {
        Self::from_toml_str(BUILTIN_MAPS_TOML)
    }

    /// The Pre-Dig stick curve (same for every index).
    pub fn predig_stick(&self) -> &Curve {
        &self.predig_stick
    }

    /// The curve sets, by rising hardness index.
    pub fn curve_sets(&self) -> &[CurveSet] {
        &self.sets
    }

    /// Lowest and highest hardness index with a curve set.
    pub fn hardness_range(&self) -> (f64, f64) {
        let lo = self.sets.first().map_or(0.0, |s| s.index);
        let hi = self.sets.last().map_or(0.0, |s| s.index);
        (lo, hi)
    }

    /// Command in percent from map `kind` at `pressure_pct` for soil hardness index `hardness`.
    ///
    /// A fractional index blends the outputs of the neighbouring curve sets linearly (the online index
    /// estimate of thesis 5.2 is continuous); indices outside the range use the nearest set. No allocation.
    pub fn eval(&self, kind: MapKind, hardness: f64, pressure_pct: f64) -> f64 {
        let pick = |s: &CurveSet| match kind {
            MapKind::PreDigStick => self.predig_stick.eval(pressure_pct),
            MapKind::PreDigBoom => s.predig_boom.eval(pressure_pct),
            MapKind::DigBoom => s.dig_boom.eval(pressure_pct),
            MapKind::DigBucket => s.dig_bucket.eval(pressure_pct),
        };
        if kind == MapKind::PreDigStick {
            return self.predig_stick.eval(pressure_pct);
        }
        let Some(first) = self.sets.first() else {
            return 0.0; // unreachable for validated maps
        };
        if hardness.is_nan() || hardness <= first.index {
            return pick(first);
        }
        for w in self.sets.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if hardness <= b.index {
                let t = (hardness - a.index) / (b.index - a.index);
                return (1.0 - t) * pick(a) + t * pick(b);
            }
        }
        self.sets.last().map_or(0.0, pick)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn maps() -> AutodigMaps {
        AutodigMaps::builtin().expect("shipped maps are valid")
    }

    #[test]
    fn shipped_maps_load_with_five_indices() {
        let m = maps();
        assert_eq!(m.hardness_range(), (1.0, 5.0));
        assert_eq!(m.curve_sets().len(), 5);
    }

    #[test]
    fn maps_errors_name_curve_and_point() {
        let bad = BUILTIN_MAPS_TOML.replace(
            "predig_boom = [[0, -30], [55, -30], [75, 0], [94, 100], [100, 100]]",
            "predig_boom = [[0, -30], [55, -30], [50, 0]]",
        );
        match AutodigMaps::from_toml_str(&bad) {
            Err(MapsError::NotIncreasing { curve, point, .. }) => {
                assert_eq!(curve, "hardness[4] (index 5).predig_boom");
                assert_eq!(point, 2);
            }
            other => panic!("expected NotIncreasing, got {other:?}"),
        }
        let bad = BUILTIN_MAPS_TOML.replace("[85, 0], [100, 0]]", "[85, 0], [120, 0]]");
        assert!(matches!(
            AutodigMaps::from_toml_str(&bad),
            Err(MapsError::PressureOutOfRange { point: 4, .. })
        ));
        let bad = BUILTIN_MAPS_TOML.replace("[[0, 100], [77, 100]", "[[0, 150], [77, 100]");
        assert!(matches!(
            AutodigMaps::from_toml_str(&bad),
            Err(MapsError::CommandOutOfRange { point: 0, .. })
        ));
        assert!(matches!(
            AutodigMaps::from_toml_str("predig_stick = 3"),
            Err(MapsError::Parse(_))
        ));
    }
}
