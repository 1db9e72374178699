//! The grid a range scan is binned into ([`ScanGrid`]).

use planner::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::check::{Limits, ParamError, check, check_count, toml_float};

/// The grid a range scan is binned into (world frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanGrid {
    /// West edge, m. Default -8.
    pub x_min_m: f64,
    /// South edge, m. Default -10.
    pub y_min_m: f64,
    /// Cell size, m. Default 0.1.
    pub cell_m: f64,
    /// Extent east, m. Default 24.
    pub size_x_m: f64,
    /// Extent north, m. Default 20.
    pub size_y_m: f64,
    /// Longest occlusion gap filled by interpolation, cells. Default 200 (the bench top behind the crest is in the shadow).
    pub max_gap_cells: usize,
}

impl Default for ScanGrid {
    fn default() -> Self {
        Self {
            x_min_m: -8.0,
            y_min_m: -10.0,
            cell_m: 0.1,
            size_x_m: 24.0,
            size_y_m: 20.0,
            max_gap_cells: 200,
        }
    }
}

impl ScanGrid {
    /// Bins world points `[x, y, z]` into a terrain map (planner::terrain, thesis 3.2). Allocates; call
    /// it outside the control step.
    ///
    /// # Errors
    /// [`ControllerError::Config`] with the terrain error's text (no points, gaps too large).
    pub fn terrain(&self, points: &[[f64; 3]]) -> Result<TerrainGrid, ControllerError> {
        let n = |size: f64| (size / self.cell_m).round().max(1.0) as usize;
        TerrainGrid::from_scan(
            points,
            self.x_min_m,
            self.y_min_m,
            self.cell_m,
            n(self.size_x_m),
            n(self.size_y_m),
            self.max_gap_cells,
        )
        .map_err(|e| ControllerError::Config {
            field: "scan",
            reason: e.to_string(),
        })
    }
}

impl ScanGrid {
    /// Checks `cycle.scan_grid`: finite edges, a cell size of 2 cm to 1 m, at most 4 million cells
    /// (as the simulator's terrain grid).
    ///
    /// # Errors
    /// The first [`ParamError`].
    pub fn validate(&self) -> Result<(), ParamError> {
        const S: &str = "cycle";
        let edge = Limits::closed(-1.0e4, 1.0e4, "m");
        check(S, "scan_grid.x_min_m", self.x_min_m, edge, "")?;
        check(S, "scan_grid.y_min_m", self.y_min_m, edge, "")?;
        check(
            S,
            "scan_grid.cell_m",
            self.cell_m,
            Limits::closed(0.02, 1.0, "m"),
            "",
        )?;
        let size = Limits::above(0.0, 2.0e4, "m");
        check(S, "scan_grid.size_x_m", self.size_x_m, size, "")?;
        check(S, "scan_grid.size_y_m", self.size_y_m, size, "")?;
        let cells = (self.size_x_m / self.cell_m) * (self.size_y_m / self.cell_m);
        if cells > 4.0e6 {
            return Err(ParamError::new(
                S,
                "scan_grid.cell_m",
                Some(toml_float(self.cell_m)),
                format!("gives {cells:.0} cells over the grid's size (at most 4e6)"),
            ));
        }
        check_count(
            S,
            "scan_grid.max_gap_cells",
            u64::try_from(self.max_gap_cells).unwrap_or(u64::MAX),
            0,
            100_000,
            "",
        )
    }
}
