//! Fixtures of the work cycle's tests: the default machine, a cycle on it, an estimator fed joint angles
//! and pressures.

use firmware_bridge::messages::{
    AuxValveMeasured, Cylinder, JointRates, Message, TrackOdometry, ValveState,
};
use planner::autodig::{AutodigConfig, AutodigMaps};
use planner::cleanup::CleanupConfig;
use planner::kinematics::Kinematics;
use planner::machine::MachineConfig;

use super::{CycleConfig, WorkCycle};
use crate::step::estimate::{Estimator, EstimatorConfig};

pub(super) fn kin() -> (Kinematics, MachineConfig) {
    let m = MachineConfig::default_machine().unwrap();
    (Kinematics::new(&m).unwrap(), m)
}

pub(super) fn cycle(config: CycleConfig) -> WorkCycle {
    let (k, m) = kin();
    WorkCycle::new(
        config,
        AutodigConfig::default(),
        AutodigMaps::builtin().unwrap(),
        CleanupConfig::default(),
        m.bucket.width_m,
        &k,
    )
    .unwrap()
}

/// An estimator that sees the machine at joint angles `q` (and swing) with `odo` travel.
pub(super) fn est_at(q: [f64; 4], odo: f64, t: f64) -> Estimator {
    let (k, m) = kin();
    let mut e = Estimator::new(k, m.tracks.gauge_m, EstimatorConfig::default()).unwrap();
    feed(&mut e, q, odo, t);
    e
}

pub(super) fn feed(e: &mut Estimator, q: [f64; 4], odo: f64, t: f64) {
    feed_pressures(e, q, odo, t, 8e6, 1e6);
}

pub(super) fn feed_pressures(
    e: &mut Estimator,
    q: [f64; 4],
    odo: f64,
    t: f64,
    head_pa: f64,
    rod_pa: f64,
) {
    feed_cylinder_pressures(e, q, odo, t, [[head_pa, rod_pa]; 3]);
}

/// [`feed_pressures`] with each cylinder's `[head, rod]` pressures (boom, stick, bucket), Pa.
pub(super) fn feed_cylinder_pressures(
    e: &mut Estimator,
    q: [f64; 4],
    odo: f64,
    t: f64,
    pressures_pa: [[f64; 2]; 3],
) {
    e.on_message(
        &Message::JointAngles(firmware_bridge::messages::JointAngles {
            boom_rad: q[0],
            stick_rad: q[1],
            bucket_rad: q[2],
            swing_rad: q[3],
        }),
        t,
    );
    e.on_message(&Message::JointRates(JointRates::default()), t);
    e.on_message(
        &Message::TrackOdometry(TrackOdometry {
            left_m: odo,
            right_m: odo,
        }),
        t,
    );
    for (c, [head_pa, rod_pa]) in Cylinder::ALL.into_iter().zip(pressures_pa) {
        e.on_message(
            &Message::AuxValveMeasured(AuxValveMeasured {
                cylinder: c,
                flow_percent: 0.0,
                state: ValveState::Block,
                head_pressure_pa: head_pa,
                rod_pressure_pa: rod_pa,
            }),
            t,
        );
    }
    e.update();
}
