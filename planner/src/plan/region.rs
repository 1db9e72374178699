//! A dig region (thesis 5.1.1.1, Fig. 44): the strip of the workspace the coarse planner
//! ([`super::coarse`]) lays out and the refined planner ([`super::refined`]) searches for the best dig.

use serde::{Deserialize, Serialize};

/// Which constraint set a region's far boundary (5.1.1.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FarLimit {
    /// The bench edge is nearer than the reach.
    BenchEdge,
    /// The kinematic reach is nearer (or the material runs on past it).
    Reach,
}

/// One dig region: a strip one bucket wide along a swing angle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigRegion {
    /// Position in the dig order (0 = next to the spoil side).
    pub index: usize,
    /// Swing angle of the centre line, rad (counter-clockwise from the tracks, positive = left).
    pub swing_rad: f64,
    /// Half the angular width at the far boundary (strips are adjacent there), rad.
    pub half_angle_rad: f64,
    /// Strip width, m.
    pub width_m: f64,
    /// Near radial boundary, m.
    pub near_r_m: f64,
    /// Far radial boundary: the nearer of the bench edge and the reach, m.
    pub far_r_m: f64,
    /// Which one it is.
    pub far_limit: FarLimit,
    /// The bench edge along the centre line, if one lies within the searched range, m.
    pub edge_r_m: Option<f64>,
    /// The kinematic reach along the centre line, m.
    pub reach_r_m: f64,
    /// Whether any material (terrain over the threshold) lies between the near and far boundaries.
    pub has_material: bool,
}
