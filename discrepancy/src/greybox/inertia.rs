//! Gravity and inertia seen at the cylinders: the links' gravity forces (Eq. A4 over the moment
//! arms) and the reflected masses of the links and of the payload (Eq. A1).

use nalgebra::Vector3;

use planner::kinematics::{JointAngles, Kinematics, TipForce};
use planner::machine::MachineConfig;

/// Reflected masses of the cylinders, kg (diagonal of the joint-space inertia over the squared moment
/// arms; links as slender rods, Eq. A1).
pub(super) fn cylinder_masses(
    kin: &Kinematics,
    cfg: &MachineConfig,
    floor: &[f64; 3],
    q: &JointAngles,
    arms: &Vector3<f64>,
) -> [f64; 3] {
    let p = kin.linkage_points(q);
    let joints = [p.boom_foot, p.stick_pin, p.bucket_pin];
    let abs = [q.boom_rad, q.stick_abs_rad(), q.bucket_abs_rad()];
    let m = &cfg.masses;
    let links = [
        (&m.boom, cfg.links.boom_m),
        (&m.stick, cfg.links.stick_m),
        (&m.bucket, cfg.links.bucket_m),
    ];
    let mut bodies = [Body::default(); 3];
    for (n, (link, length)) in links.iter().enumerate() {
        let c = [
            joints[n][0] + link.cog_distance_m * (abs[n] + link.cog_angle_rad).cos(),
            joints[n][1] + link.cog_distance_m * (abs[n] + link.cog_angle_rad).sin(),
        ];
        bodies[n] = Body {
            link: n,
            mass_kg: link.mass_kg,
            centroid: c,
            own_inertia_kg_m2: link.mass_kg * length * length / 12.0,
        };
    }
    reflected_masses(*floor, &joints, &bodies, arms)
}

/// A rigid body carried by a link (`0` boom, `1` stick, `2` bucket) for the inertia sums of Eq. A1.
#[derive(Debug, Clone, Copy, Default)]
struct Body {
    link: usize,
    mass_kg: f64,
    centroid: [f64; 2],
    own_inertia_kg_m2: f64,
}

/// Reflected mass at each cylinder, kg: the moment of inertia about joint `i` of every body on
/// link `i` or beyond it (`m d^2 + I_own`, Eq. A1), added to `start_kg_m2`, over the cylinder's
/// moment arm squared.
fn reflected_masses(
    start_kg_m2: [f64; 3],
    joints: &[[f64; 2]; 3],
    bodies: &[Body],
    arms: &Vector3<f64>,
) -> [f64; 3] {
    let mut out = start_kg_m2;
    for (i, joint) in joints.iter().enumerate() {
        for b in bodies.iter().filter(|b| b.link >= i) {
            let d2 = (b.centroid[0] - joint[0]).powi(2) + (b.centroid[1] - joint[1]).powi(2);
            out[i] += b.mass_kg * d2 + b.own_inertia_kg_m2;
        }
    }
    [0, 1, 2].map(|i| out[i] / arms[i].powi(2).max(1e-4))
}

pub(super) fn gravity_forces(kin: &Kinematics, q: &JointAngles) -> Option<[f64; 3]> {
    let f = kin
        .cylinder_forces_from_tip_force(q, &TipForce::default(), 0.0)
        .ok()?;
    Some([f[0], f[1], f[2]])
}

/// Radius of gyration of the payload about its own centroid, m (`0.05 m^2` per kg, the simulator's
/// value: a heap of soil about a metre across).
const PAYLOAD_GYRATION_M: f64 = 0.2236;

/// Reflected mass of one kilogram of payload at each cylinder, kg/kg: `(d_i^2 + k^2) / r_i^2`, `d_i`
/// the distance of the payload centroid from joint `i`, `k` its radius of gyration, `r_i` the
/// cylinder's moment arm (Eq. A1 with the payload as one more body, as [`cylinder_masses`] treats
/// the links). `None` at a singular pose.
pub(super) fn payload_reflected_mass_per_kg(kin: &Kinematics, q: &JointAngles) -> Option<[f64; 3]> {
    let arms = kin.moment_arms(q).ok()?;
    let p = kin.linkage_points(q);
    let payload = Body {
        link: 2,
        mass_kg: 1.0,
        centroid: kin.payload_centroid(q),
        own_inertia_kg_m2: PAYLOAD_GYRATION_M * PAYLOAD_GYRATION_M,
    };
    Some(reflected_masses(
        [0.0; 3],
        &[p.boom_foot, p.stick_pin, p.bucket_pin],
        &[payload],
        &arms,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The payload's reflected mass at each cylinder is its kinetic energy per unit cylinder speed:
    /// moving one joint alone turns the payload (centroid and own inertia) about that joint, so
    /// `m_i = (|dc/dq_i|^2 + k^2) / r_i^2` with the centroid's speed `dc/dq_i` taken numerically.
    #[test]
    fn payload_reflected_mass_is_its_kinetic_energy_per_cylinder_speed() {
        let cfg = MachineConfig::default_machine().unwrap();
        let kin = Kinematics::new(&cfg).unwrap();
        let q = JointAngles {
            boom_rad: 0.3,
            stick_rad: -1.6,
            bucket_rad: -1.0,
        };
        let per_kg = payload_reflected_mass_per_kg(&kin, &q).unwrap();
        let arms = kin.moment_arms(&q).unwrap();
        let h = 1e-6;
        for i in 0..3 {
            let mut moved = q;
            match i {
                0 => moved.boom_rad += h,
                1 => moved.stick_rad += h,
                _ => moved.bucket_rad += h,
            }
            let (a, b) = (kin.payload_centroid(&q), kin.payload_centroid(&moved));
            let speed2 = ((b[0] - a[0]) / h).powi(2) + ((b[1] - a[1]) / h).powi(2);
            let expected = (speed2 + PAYLOAD_GYRATION_M.powi(2)) / arms[i].powi(2);
            assert!(
                (per_kg[i] - expected).abs() < 1e-4 * expected,
                "cylinder {i}: {} against {expected}",
                per_kg[i]
            );
        }
        // The boom carries the payload farthest from its joint: the most inertia per kg.
        assert!(per_kg[0] * arms[0].powi(2) > per_kg[2] * arms[2].powi(2));
    }
}
