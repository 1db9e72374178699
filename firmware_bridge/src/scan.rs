//! The range-scan wire types: what the controller asks the machine's range sensor for ([`ScanRequest`])
//! and the terrain points it gets back ([`Scan`]). They travel as JSON lines over a local socket
//! (Ethernet on a real machine; `docs/scan-protocol.md`), beside the CAN protocol, and are written as
//! `scans/scan_NNNN.json` in a session folder.

use serde::{Deserialize, Serialize};

/// What to scan, relative to the sensor's heading (radians, counts).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ScanRequest {
    /// First azimuth relative to the sensor heading (rad, counter-clockwise).
    pub azimuth_min_rad: f64,
    /// Last azimuth.
    pub azimuth_max_rad: f64,
    /// Number of azimuths (1..=2000).
    pub azimuth_count: usize,
    /// Lowest elevation (rad, negative looks down).
    pub elevation_min_rad: f64,
    /// Highest elevation.
    pub elevation_max_rad: f64,
    /// Number of elevations (1..=2000).
    pub elevation_count: usize,
    /// Maximum range (m).
    pub max_range_m: f64,
}

impl Default for ScanRequest {
    fn default() -> Self {
        Self {
            azimuth_min_rad: -0.7,
            azimuth_max_rad: 0.7,
            azimuth_count: 121,
            elevation_min_rad: -1.2,
            elevation_max_rad: -0.05,
            elevation_count: 81,
            max_range_m: 30.0,
        }
    }
}

impl ScanRequest {
    /// The request with counts and ranges clamped to what the emulator serves.
    pub fn sanitised(&self) -> Self {
        let finite = |v: f64, d: f64| if v.is_finite() { v } else { d };
        let d = Self::default();
        Self {
            azimuth_min_rad: finite(self.azimuth_min_rad, d.azimuth_min_rad).clamp(-3.2, 3.2),
            azimuth_max_rad: finite(self.azimuth_max_rad, d.azimuth_max_rad).clamp(-3.2, 3.2),
            azimuth_count: self.azimuth_count.clamp(1, 2000),
            elevation_min_rad: finite(self.elevation_min_rad, d.elevation_min_rad)
                .clamp(-1.57, 1.57),
            elevation_max_rad: finite(self.elevation_max_rad, d.elevation_max_rad)
                .clamp(-1.57, 1.57),
            elevation_count: self.elevation_count.clamp(1, 2000),
            max_range_m: finite(self.max_range_m, d.max_range_m).clamp(0.5, 100.0),
        }
    }
}

/// The range sensor's pose in the world.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorPose {
    /// East (m).
    pub x_m: f64,
    /// North (m).
    pub y_m: f64,
    /// Up (m).
    pub z_m: f64,
    /// Heading of the scan centre (rad, counter-clockwise from east).
    pub heading_rad: f64,
}

/// One terrain scan: world points `[x, y, z]` (m) and the sensor pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scan {
    /// Simulation time of the scan (s).
    pub time_s: f64,
    /// Where the sensor was.
    pub sensor: SensorPose,
    /// Hits, world frame.
    pub points: Vec<[f64; 3]>,
}
