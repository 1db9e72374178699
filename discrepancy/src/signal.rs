//! The signals the grey-box model predicts and the discrepancy workflow compares with the
//! measurements (cylinder velocities, pump pressures, cylinder and soil forces, end-stop angles, the
//! weighed payload), and the groups a replay recomputes. Shared by the grey-box replay, the
//! candidate library (which groups a candidate acts on), the statistics and the reports.

use serde::{Deserialize, Serialize};

/// The predicted signals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Signal {
    /// Boom cylinder velocity, m/s.
    BoomVelocity,
    /// Stick cylinder velocity, m/s.
    StickVelocity,
    /// Bucket cylinder velocity, m/s.
    BucketVelocity,
    /// Pump 1 (boom, bucket) pressure, Pa.
    Pump1Pressure,
    /// Pump 2 (stick, swing) pressure, Pa.
    Pump2Pressure,
    /// Boom cylinder force (Eq. A20), N.
    BoomForce,
    /// Stick cylinder force, N.
    StickForce,
    /// Bucket cylinder force, N.
    BucketForce,
    /// Soil force on the bucket, horizontal (base x), N.
    SoilForceX,
    /// Soil force on the bucket, vertical (base z), N.
    SoilForceZ,
    /// End-stop angle: the reading of a link pressed against a stroke end (at rest, the cylinder
    /// pushing it towards the end far beyond its weight) less the end's angle from the machine
    /// geometry (Appendix A, the cylinder stroke), rad.
    StopAngle,
    /// Payload mass while the work cycle weighs the bucket (valves neutral, implement held up): the
    /// static least-squares estimate from the joint torques less the links' gravity (Eqs. A20-A22),
    /// as the controller weighs, kg.
    PayloadMass,
}

/// Number of signals.
pub const N_SIGNALS: usize = 12;

impl Signal {
    /// Every signal in array order.
    pub const ALL: [Signal; N_SIGNALS] = [
        Signal::BoomVelocity,
        Signal::StickVelocity,
        Signal::BucketVelocity,
        Signal::Pump1Pressure,
        Signal::Pump2Pressure,
        Signal::BoomForce,
        Signal::StickForce,
        Signal::BucketForce,
        Signal::SoilForceX,
        Signal::SoilForceZ,
        Signal::StopAngle,
        Signal::PayloadMass,
    ];

    /// Index in signal arrays.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Signal::BoomVelocity => "boom_velocity",
            Signal::StickVelocity => "stick_velocity",
            Signal::BucketVelocity => "bucket_velocity",
            Signal::Pump1Pressure => "pump1_pressure",
            Signal::Pump2Pressure => "pump2_pressure",
            Signal::BoomForce => "boom_force",
            Signal::StickForce => "stick_force",
            Signal::BucketForce => "bucket_force",
            Signal::SoilForceX => "soil_force_x",
            Signal::SoilForceZ => "soil_force_z",
            Signal::StopAngle => "stop_angle",
            Signal::PayloadMass => "payload_mass",
        }
    }

    /// Unit of the signal.
    pub fn unit(self) -> &'static str {
        match self.index() {
            0..=2 => "m/s",
            3..=4 => "Pa",
            10 => "rad",
            11 => "kg",
            _ => "N",
        }
    }

    /// The cylinder (0 boom, 1 stick, 2 bucket) of a per-cylinder signal.
    pub fn cylinder(self) -> Option<usize> {
        match self.index() {
            i @ 0..=2 => Some(i),
            i @ 5..=7 => Some(i - 5),
            _ => None,
        }
    }
}

/// Which groups of signals a replay must recompute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SignalGroups {
    /// Cylinder velocities.
    pub hydraulic: bool,
    /// Pump pressures.
    pub pumps: bool,
    /// Cylinder forces.
    pub force: bool,
    /// Soil forces.
    pub soil: bool,
    /// End-stop angles.
    pub stops: bool,
    /// Payload mass at the weighing.
    pub payload: bool,
}

impl SignalGroups {
    /// Every group.
    pub const ALL: SignalGroups = SignalGroups {
        hydraulic: true,
        pumps: true,
        force: true,
        soil: true,
        stops: true,
        payload: true,
    };

    /// The groups of either.
    pub fn union(self, other: SignalGroups) -> SignalGroups {
        SignalGroups {
            hydraulic: self.hydraulic || other.hydraulic,
            pumps: self.pumps || other.pumps,
            force: self.force || other.force,
            soil: self.soil || other.soil,
            stops: self.stops || other.stops,
            payload: self.payload || other.payload,
        }
    }

    /// Whether the group of signal index `s` is among these.
    pub fn contains(&self, s: usize) -> bool {
        match s {
            0..=2 => self.hydraulic,
            3..=4 => self.pumps,
            5..=7 => self.force,
            8..=9 => self.soil,
            10 => self.stops,
            _ => self.payload,
        }
    }
}
