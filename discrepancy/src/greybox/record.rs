//! Record preparation: the per-sample quantities of a measured record that no candidate effect
//! changes (kinematics, measured velocities, accelerations and forces, the soil and payload terms),
//! computed once, and which samples enter each signal ([`PreparedRecord`]).

use nalgebra::Vector3;

use super::inertia::{cylinder_masses, gravity_forces};
use super::params::GreyBoxParams;
use super::prefilter::prefilter_velocities;
use super::soil::{SoilTerms, soil_terms_of};
use super::spool::SpoolCache;
use super::weighing::{PayloadTerms, WEIGH_MIN_FILL, WEIGH_SETTLE_S, weigh_accel, weighed_payload};
use crate::signal::{N_SIGNALS, Signal};
use crate::soil_replay::CutSection;
use crate::{DigRecord, LoadTag, Result, Sample, StageTag};
use planner::kinematics::{Joint, JointAngles, Kinematics, TipForce};
use planner::machine::MachineConfig;

/// Samples at the start of a record, and after a gap in it, whose spool state is still unknown (the
/// commands before them are).
pub const WARMUP_SAMPLES: usize = 50;

/// A pause between two samples longer than this is a gap in the record, s (the reader leaves out the
/// samples under the gateway's position mode, whose spools the gateway set itself): the spool
/// integration (`spool::spools`) steps over it as one sample and comes out of it with the state before it.
const GAP_S: f64 = 0.05;

/// A chamber above this fraction of the main relief's cracking pressure, under a command beyond the
/// spool overlap, means the cylinder pushes against something (for the boom, its rod: its heads
/// carry the links' weight, up to the relief for a heavy boom lifting).
const PRESSING_RELIEF_FRACTION: f64 = 0.9;

/// A lowering boom whose cylinder force is below this fraction of the links' weight on it rests
/// the bucket on something (a lighter boom of the parameter changes, 5-25 %, stays far above; at
/// half the weight, the dips of a lowering's start left out 15 % of the boom's free-air samples).
const BOOM_GROUND_FRACTION: f64 = 0.25;

/// The samples at which some cylinder pushes against an obstacle (the ground, a pile, its own
/// stop): from a chamber above [`PRESSING_RELIEF_FRACTION`] of the relief under a command beyond
/// the spool overlap, for as long as that command keeps its direction (the push goes on after the
/// pressure falls back while the bucket digs in or the ground gives way: effect-free session
/// seed 505 of the planned bench, the bucket opened onto the ground at 37 MPa and went on at
/// 20-28 MPa for a second, a bucket-force residual of 144 kN that made the session 8x its
/// reference). The cylinder forces are no free-air forces there.
///
/// The boom also pushes when, lowering, its cylinder force (Eq. A20) falls below
/// [`BOOM_GROUND_FRACTION`] of the links' weight on it (`boom_gravity_n`, Eq. A4, per sample): in
/// free air the steadily lowering boom's force holds that weight up; far below it, the ground
/// carries the bucket, at any pressure. That sample alone is left out, not the rest of the
/// lowering: the force also dips as a lowering starts and the links accelerate down, and a latch
/// left out half the boom's free-air samples. (Effect-free session none_s202 of the planned bench: the
/// boom lowered the bucket onto the bench at 3.8 MPa head and 4.2 MPa rod, and 13 samples 80-280
/// kN below the model made the session 11x its reference in the boom force.)
fn pressing(samples: &[Sample], params: &GreyBoxParams, boom_gravity_n: &[f64]) -> Vec<bool> {
    let limit_pa = PRESSING_RELIEF_FRACTION * params.relief_pa;
    let mut direction = [0.0f64; 3];
    samples
        .iter()
        .zip(boom_gravity_n)
        .map(|(s, gravity_n)| {
            let on_ground = s.command[0] < -params.overlap
                && *gravity_n > 0.0
                && s.head_pa[0] * params.head_area_m2[0] - s.rod_pa[0] * params.rod_area_m2[0]
                    < BOOM_GROUND_FRACTION * gravity_n;
            for i in 0..3 {
                let u = s.command[i];
                let open = u.abs() > params.overlap;
                if !open || u.signum() != direction[i] {
                    direction[i] = 0.0;
                }
                // The boom's heads carry the links' weight: near the relief while it lifts, they
                // say the load is heavy (a heavier boom), not that something is in the way; its rod
                // pushes the bucket down onto something.
                let pushing_pa = if i == 0 {
                    s.rod_pa[i]
                } else {
                    s.head_pa[i].max(s.rod_pa[i])
                };
                if open && pushing_pa > limit_pa {
                    direction[i] = u.signum();
                }
            }
            on_ground || direction.iter().any(|d| *d != 0.0)
        })
        .collect()
}

/// Samples up to this long after one where a stick or bucket chamber reads the relief are held
/// from outside too, s: a bucket held in the ground alternates, about a second apart, between
/// being pushed to the relief against its closed valve while the boom tries to lift it free and
/// pushing under its own command at part of the relief.
const HELD_AFTER_S: f64 = 1.0;
/// ... and up to this long before it, s: the contact builds the pressure up to the relief in
/// about 0.15 s (16, 24, then 37 MPa at none_s203); the free-air lowering that ends on the ground
/// a second before stays in.
const HELD_BEFORE_S: f64 = 0.25;

/// The samples at which something outside holds the implement: from [`HELD_BEFORE_S`] before to
/// [`HELD_AFTER_S`] after a sample where a chamber of the stick or the bucket reads above
/// [`PRESSING_RELIEF_FRACTION`] of the relief away from its stroke ends (`in_stroke`: at its end
/// the stop holds the trapped oil, as for the curled full bucket at the relief all through the
/// carry), under its own command or behind its closed valve. In free air neither the links'
/// weight nor their inertia drives these cylinders that far. The boom is left out: its chambers
/// bounce to relief on their oil columns behind its closed valve while the swing turns.
/// (Effect-free session none_s203 of the planned bench: a move to a cleanup's start held the
/// bucket in the floor for 3 s, the bucket's rod at 37 MPa behind its closed valve while the boom
/// lifted at full command with 1 MPa in its heads; boom-force residuals of 380 kN made the
/// session 23x its reference.)
fn held_from_outside(
    samples: &[Sample],
    params: &GreyBoxParams,
    in_stroke: &[[bool; 3]],
) -> Vec<bool> {
    let limit_pa = PRESSING_RELIEF_FRACTION * params.relief_pa;
    let held_at: Vec<f64> = samples
        .iter()
        .zip(in_stroke)
        .filter(|(s, inside)| (1..3).any(|i| inside[i] && s.head_pa[i].max(s.rod_pa[i]) > limit_pa))
        .map(|(s, _)| s.time_s)
        .collect();
    samples
        .iter()
        .map(|s| {
            // The first held sample not earlier than HELD_AFTER_S before this one (sorted times).
            let first = held_at.partition_point(|t| *t < s.time_s - HELD_AFTER_S);
            held_at
                .get(first)
                .is_some_and(|t| *t <= s.time_s + HELD_BEFORE_S)
        })
        .collect()
}

/// Whether each sample is at least [`WARMUP_SAMPLES`] past the start of its record or the last gap.
/// (Effect-free session none_s200: in the Dig stage that followed a cleanup the stick moved at 0.22
/// m/s on the spool the gateway had opened, the replay's spools came out of the gap closed and
/// predicted 0 to 0.14 m/s for 0.2 s: 25 samples that made nearly all of the stick velocity's
/// residual sum of squares in that session.)
pub fn warmed_up(samples: &[Sample]) -> Vec<bool> {
    let mut since = 0usize;
    samples
        .iter()
        .enumerate()
        .map(|(k, s)| {
            if k > 0 && s.time_s - samples[k - 1].time_s > GAP_S {
                since = 0;
            }
            since += 1;
            since > WARMUP_SAMPLES
        })
        .collect()
}

/// Smallest cylinder speed at which a sample enters that cylinder's force signal, m/s (well above
/// the resolver-rate noise of a resting link, a few mm/s).
const MOVING_SPEED_M_PER_S: f64 = 0.02;
/// Largest cylinder acceleration at which a sample enters the force signals, m/s^2.
const QUASI_STATIC_ACCEL_M_PER_S2: f64 = 0.5;
/// Samples (0.3 s) a cylinder's valve command must have been open (beyond the spool overlap) for a
/// sample to enter that cylinder's force signal.
const SPOOL_OPEN_SAMPLES: usize = 30;

/// An open valve's velocity relation is noise-dominated, and the sample stays out of the velocity
/// signal, when its inlet reads within this of its supply (no meter-in estimate: the load, not the
/// valve, sets the speed) and its outlet within [`NOISY_OUTLET_DP_PA`] of tank, Pa. The meter-in
/// estimate is weighted out below this drop in `cylinder_velocity`.
const NOISY_INLET_DP_PA: f64 = 2.0e5;
/// See [`NOISY_INLET_DP_PA`]: an outlet drop of 0.5 MPa gives the meter-out flow to about 7 % with the
/// transducer noise (0.05 MPa per reading, `sqrt(2) 0.05 / (2 x 0.5)`), Pa.
const NOISY_OUTLET_DP_PA: f64 = 5.0e5;
/// A measured cylinder velocity that zig-zags by more than this from one sample to the next and back
/// is an oscillation at the sampling's Nyquist rate (the oil column of a link hanging behind a closed
/// spool, its other chamber emptied), which no model sampled at 100 Hz can follow; the sample stays
/// out of the velocity signal, m/s (about five standard deviations of the difference of two
/// resolver-rate readings of a resting link).
const ALIASED_ZIGZAG_M_PER_S: f64 = 0.02;
/// Pressure readings at or below this are taken as clamped at the sensor's zero, Pa.
pub(super) const CLAMPED_READING_PA: f64 = 1.0e3;
/// Margin from the stroke ends where the end stops may carry force, m.
const STROKE_MARGIN_M: f64 = 0.01;
/// End-stop relation: a link whose reading is within this of a stroke-limited end of its range may be
/// at that end stop, rad (the offsets it can see; beyond 1 degree the controller's safety layer
/// stops the machine at the first stop it reaches, docs/discrepancy.md).
const STOP_WINDOW_RAD: f64 = 0.05;
/// End-stop relation: largest resolver rate of a link at rest, rad/s.
const STOP_REST_RATE_RAD_PER_S: f64 = 0.005;
/// End-stop relation: the cylinder force beyond the one holding the link against gravity must push
/// the link towards the end by more than this, N, plus what the heaviest payload could take: twice
/// the largest dry friction of the effect library (50 kN), so a link held by stiction or by oil
/// trapped at a modest pressure short of the stop is not taken for one at the stop.
const STOP_PRESS_FORCE_N: f64 = 100_000.0;

/// Per-sample quantities of a record that do not depend on the candidate effects (kinematics, measured
/// velocities and forces, FEE factors), computed once.
#[derive(Debug, Clone)]
pub struct PreparedRecord {
    /// Dig index.
    pub index: u32,
    /// The samples of the record.
    pub samples: Vec<Sample>,
    /// Measured value of every signal (NaN where it is not defined); the velocity signals through
    /// the prefilter ([`prefilter_velocities`]).
    pub measured: Vec<[f64; N_SIGNALS]>,
    /// Whether each cylinder's raw measured velocity enters the velocity signal at the sample (the
    /// samples the replay predicts, before the prefilter).
    pub(super) velocity_gate: Vec<[bool; 3]>,
    /// Measured cylinder velocities, m/s.
    pub(super) velocity: Vec<[f64; 3]>,
    /// Measured cylinder accelerations (central differences), m/s^2.
    pub(super) accel: Vec<[f64; 3]>,
    /// Oil flow taken by the compression of each cylinder's `[head, rod]` chamber (Eq. 2:
    /// `V / beta dp/dt`, the measured pressures' central differences), m^3/s.
    pub(super) compression: Vec<[[f64; 2]; 3]>,
    /// The bulk modulus `compression` was computed with, Pa (a replay with another one scales it).
    pub(super) compression_bulk_modulus_pa: f64,
    /// Cylinder forces holding the links against gravity at the measured angles, N.
    pub(super) gravity_force: Vec<[f64; 3]>,
    /// Their derivative with respect to a common offset of the three resolvers, N/rad.
    pub(super) gravity_force_per_rad: Vec<[f64; 3]>,
    /// Their derivative with respect to each link's mass `[boom, stick, bucket][cylinder]`, N/kg.
    pub(super) gravity_force_per_kg: Vec<[[f64; 3]; 3]>,
    /// The link masses `gravity_force` was computed with (the machine file's), kg.
    pub(super) link_mass_kg: [f64; 3],
    /// Reflected cylinder masses, kg.
    pub(super) mass: Vec<[f64; 3]>,
    /// Soil: measured tip force at zero payload `[fx, fz]` and its change per kg of payload, the
    /// payload volume, the FEE force at nominal soil and its change per Pa of cohesion and per kg/m^3.
    pub(super) soil: Vec<Option<SoilTerms>>,
    /// Payload: the terms of the weighing samples.
    pub(super) payload: Vec<Option<PayloadTerms>>,
    /// The spool positions of the last replay.
    pub(super) spool_cache: SpoolCache,
}

impl PreparedRecord {
    /// Measured cylinder velocities per sample (the resolver rates times the moment arms,
    /// before the prefilter), m/s.
    pub fn cylinder_velocities(&self) -> &[[f64; 3]] {
        &self.velocity
    }

    /// Precomputes the kinematic and soil terms of a record.
    ///
    /// # Errors
    /// [`crate::DiscrepancyError`] when the record is invalid or the machine geometry cannot be built.
    pub fn new(record: &DigRecord, cfg: &MachineConfig, params: &GreyBoxParams) -> Result<Self> {
        record.validate()?;
        params.validate()?;
        let kin = Kinematics::new(cfg)?;
        let n = record.samples.len();
        let strokes = Joint::ALL.map(|j| kin.stroke(j));
        let mut velocity = vec![[0.0; 3]; n];
        let mut gravity_force = vec![[f64::NAN; 3]; n];
        let mut gravity_force_per_rad = vec![[0.0; 3]; n];
        let mut gravity_force_per_kg = vec![[[0.0; 3]; 3]; n];
        let link_mass_kg = cfg.masses.mass_kg();
        // The machine with each link 100 kg heavier (the gravity forces are linear in each mass).
        const D_KG: f64 = 100.0;
        let heavier: Vec<Kinematics> = (0..3)
            .map(|l| {
                let mut c = cfg.clone();
                c.masses.links_mut()[l].mass_kg += D_KG;
                Kinematics::new(&c)
            })
            .collect::<std::result::Result<_, _>>()?;
        let mut mass = vec![[0.0; 3]; n];
        let mut in_stroke = vec![[false; 3]; n];
        let mut chamber_strokes = vec![None; n];
        let mut arms_at = vec![[0.0; 3]; n];
        // The cylinder forces a full bucket of the model's soil adds (the payload is unknown outside
        // the soil: a loaded boom held up short of its top stop needs about 250 kN more than the
        // empty links, which is no push into the stop).
        let mut payload_force = vec![[f64::NAN; 3]; n];
        let full_payload_kg = cfg.bucket.capacity_m3 * params.soil.density_kg_per_m3;
        let stop_angles = Joint::ALL.map(|j| kin.stroke_limited_range(j));
        const D_RAD: f64 = 1e-3;
        for (k, s) in record.samples.iter().enumerate() {
            let q = JointAngles {
                boom_rad: s.angles_rad[0],
                stick_rad: s.angles_rad[1],
                bucket_rad: s.angles_rad[2],
            };
            let Ok(arms) = kin.moment_arms(&q) else {
                continue;
            };
            velocity[k] = [0, 1, 2].map(|i| arms[i] * s.rates_rad_per_s[i]);
            arms_at[k] = [arms[0], arms[1], arms[2]];
            if let Ok(len) = kin.cylinder_lengths(&q) {
                let len = len.to_vector();
                chamber_strokes[k] = Some([len[0], len[1], len[2]]);
                in_stroke[k] = [0, 1, 2].map(|i| {
                    len[i] > strokes[i].0 + STROKE_MARGIN_M
                        && len[i] < strokes[i].1 - STROKE_MARGIN_M
                });
            }
            if let Some(g) = gravity_forces(&kin, &q) {
                gravity_force[k] = g;
                if let Ok(f) =
                    kin.cylinder_forces_from_tip_force(&q, &TipForce::default(), full_payload_kg)
                {
                    payload_force[k] = [0, 1, 2].map(|i| f[i] - g[i]);
                }
                // The true angles are the readings minus the offset: dF/d(offset) = -dF/dq.
                let shifted = JointAngles {
                    boom_rad: q.boom_rad - D_RAD,
                    stick_rad: q.stick_rad - D_RAD,
                    bucket_rad: q.bucket_rad - D_RAD,
                };
                if let Some(g2) = gravity_forces(&kin, &shifted) {
                    gravity_force_per_rad[k] = [0, 1, 2].map(|i| (g2[i] - g[i]) / D_RAD);
                }
                for (l, kin_l) in heavier.iter().enumerate() {
                    if let Some(g2) = gravity_forces(kin_l, &q) {
                        gravity_force_per_kg[k][l] = [0, 1, 2].map(|i| (g2[i] - g[i]) / D_KG);
                    }
                }
            }
            mass[k] = cylinder_masses(&kin, cfg, &params.inertia_floor_kg_m2, &q, &arms);
        }
        let mut accel = vec![[0.0; 3]; n];
        let mut compression = vec![[[0.0; 2]; 3]; n];
        // Central differences over one sample each side: the oil-column oscillations of a stopping
        // link are a few hertz, which wider stencils would attenuate.
        for k in 1..n.saturating_sub(1) {
            let (before, after) = (&record.samples[k - 1], &record.samples[k + 1]);
            let dt = after.time_s - before.time_s;
            if dt > 0.0 {
                accel[k] = [0, 1, 2].map(|i| (velocity[k + 1][i] - velocity[k - 1][i]) / dt);
                // Eq. 2: the chamber volume at the measured stroke, dead volume included.
                if let (true, Some(len)) = (params.chamber_balance, chamber_strokes[k]) {
                    compression[k] = [0, 1, 2].map(|i| {
                        let x = (len[i] - strokes[i].0).clamp(0.0, strokes[i].1 - strokes[i].0);
                        let v_head = params.dead_volume_m3 + params.head_area_m2[i] * x;
                        let v_rod = params.dead_volume_m3
                            + params.rod_area_m2[i] * (strokes[i].1 - strokes[i].0 - x);
                        let dh = (after.head_pa[i] - before.head_pa[i]) / dt;
                        let dr = (after.rod_pa[i] - before.rod_pa[i]) / dt;
                        [
                            v_head / params.bulk_modulus_pa * dh,
                            v_rod / params.bulk_modulus_pa * dr,
                        ]
                    });
                }
            }
        }
        // Samples where a resolver rate disagrees with the angle's own derivative (a link held at an
        // end stop or a bad sensor) are left out; so are the cylinder forces while some cylinder is
        // stalled under a large command or pushes with its relief pressure (the bucket pushing on
        // the ground or an obstacle).
        let mut consistent = vec![[true; 3]; n];
        let boom_gravity_n: Vec<f64> = gravity_force.iter().map(|g| g[0]).collect();
        let mut stalled = pressing(&record.samples, params, &boom_gravity_n);
        for (k, held) in held_from_outside(&record.samples, params, &in_stroke)
            .into_iter()
            .enumerate()
        {
            stalled[k] |= held;
        }
        for k in 2..n.saturating_sub(2) {
            let dt = record.samples[k + 2].time_s - record.samples[k - 2].time_s;
            for i in 0..3 {
                let rate = record.samples[k].rates_rad_per_s[i];
                let fd = (record.samples[k + 2].angles_rad[i]
                    - record.samples[k - 2].angles_rad[i])
                    / dt.max(1e-3);
                consistent[k][i] = (rate - fd).abs() < 0.03 + 0.2 * rate.abs();
                if record.samples[k].command[i].abs() > 0.15 && rate.abs() < 0.005 {
                    stalled[k] = true;
                }
            }
        }
        let mut measured = vec![[f64::NAN; N_SIGNALS]; n];
        let warm = warmed_up(&record.samples);
        let mut soil_terms = vec![None; n];
        let mut payload_terms = vec![None; n];
        let mut weighing_since = f64::NAN;
        // The section along the digging plane as the edge leaves it (cut in the Autodig stages, when
        // the bucket is in the digging plane), and the tip of the previous sample.
        let mut cut = record.section.as_ref().and_then(|section| {
            CutSection::new(
                section,
                &record.lanes,
                cfg.bucket.width_m,
                cfg.bucket.capacity_m3,
                params.spill_repose_rad,
            )
        });
        let mut last_tip: Option<[f64; 2]> = None;
        let mut open_for = [0usize; 3];
        for (k, s) in record.samples.iter().enumerate() {
            let q = JointAngles {
                boom_rad: s.angles_rad[0],
                stick_rad: s.angles_rad[1],
                bucket_rad: s.angles_rad[2],
            };
            let pose = kin.forward(&q);
            let tip = [pose.x_m, pose.z_m];
            let rates = Vector3::new(
                s.rates_rad_per_s[0],
                s.rates_rad_per_s[1],
                s.rates_rad_per_s[2],
            );
            let tip_v = kin.jacobian(&q) * rates; // Eq. A3
            let tip_velocity = [tip_v[0], tip_v[1]];
            if let Some(c) = cut.as_mut() {
                if s.stage == StageTag::Outside {
                    last_tip = None;
                } else {
                    if let Some(prev) = last_tip {
                        c.cut(prev, tip);
                    }
                    last_tip = Some(tip);
                }
            }
            // After this sample's soil terms, the bucket spills what it cannot hold (on the
            // section, for the samples after it).
            let spill_dt_s = record
                .samples
                .get(k + 1)
                .map_or(crate::PERIOD_S, |next| next.time_s - s.time_s);
            let spill = |c: &mut CutSection| {
                let in_soil = s.stage != StageTag::Outside
                    && c.motion(tip, pose.bucket_abs_rad, tip_velocity)
                        .is_some_and(|m| m.vertical_depth_m > 0.0);
                if params.spill_pile && s.stage != StageTag::Outside {
                    c.spill(tip, pose.bucket_abs_rad, in_soil, spill_dt_s);
                } else {
                    c.pour(pose.bucket_abs_rad, in_soil, spill_dt_s);
                }
            };
            let m = &mut measured[k];
            if !warm[k] {
                if let Some(c) = cut.as_mut() {
                    spill(c);
                }
                continue;
            }
            let all_consistent = consistent[k].iter().all(|c| *c);
            // A chamber above what the main relief lets a pump deliver (cracking plus override) is
            // pressed by its load, and its port relief (set above the main relief to take load
            // shocks) may be passing oil to tank at a rate the model does not know: that cylinder's
            // flow balance says nothing. (Effect-free session none_s200: the stick pulled out at
            // 0.13-0.24 m/s behind its closed spool for a second at a time, rod 37.2-37.6 MPa, head
            // at 0, while the bucket dumped; the balance without the relief flow predicted 0, and
            // the cross-piston leakage `L (p_h - p_r)` was the only term that pointed that way:
            // half of the leakage-like residual that had the nominal model carry 3.1e-12
            // m^3/(s Pa) of leakage the simulator does not have.)
            let pump_limit_pa = params.relief_pa + params.relief_override_pa;
            for i in 0..3 {
                // (effect-free sessions of a simulator with a stiffer soil contact: the bucket
                // pressing into the soil with its head at the pump pressure, 11 % of the Dig samples
                // and half the bucket velocity residual there; the stick hanging on its rod's oil
                // column with the head emptied by leakage.)
                let noisy = load_limited(params, s, i)
                    || (k > 0
                        && k + 1 < n
                        && aliased_zigzag(velocity[k - 1][i], velocity[k][i], velocity[k + 1][i]));
                if in_stroke[k][i]
                    && consistent[k][i]
                    && !noisy
                    && s.head_pa[i].max(s.rod_pa[i]) < pump_limit_pa
                {
                    m[i] = velocity[k][i];
                }
            }
            m[3] = s.pump_pa[0];
            m[4] = s.pump_pa[1];
            // Eq. 3 is used quasi-statically: the oil-column oscillations of a stopping link are
            // faster than 100 Hz sampling resolves, so samples with a large measured acceleration
            // are left out of the force signals.
            let steady = accel[k]
                .iter()
                .all(|a| a.abs() < QUASI_STATIC_ACCEL_M_PER_S2);
            // Only moving cylinders: at rest, dry friction (stiction) holds any force up to its
            // limit and oil trapped behind closed spools keeps whatever pressure it had, so a
            // resting cylinder's force says nothing definite about the model.
            // A cylinder whose valve has been closed within the last SPOOL_OPEN_SAMPLES moves only as
            // the oil column behind the closed spool springs back and forth: its force is then
            // mostly the inertia of that oscillation, which 100 Hz samples do not resolve.
            for i in 0..3 {
                open_for[i] = if s.command[i].abs() > params.overlap {
                    open_for[i] + 1
                } else {
                    0
                };
            }
            // Boom-Down ends when the bucket meets the ground, which then carries part of the
            // links' weight (effect-free sessions: boom force 49 kN measured against 184 kN of
            // gravity there), so it is not free air for the force relation.
            let free_air = s.load == LoadTag::EmptyFreeAir && s.stage != StageTag::BoomDown;
            if free_air && all_consistent && !stalled[k] && steady {
                for i in 0..3 {
                    // A chamber reading at the sensor's zero hides its true pressure (anything
                    // up to the magnitude of a negative offset), and with it the force.
                    let readable =
                        s.head_pa[i] > CLAMPED_READING_PA && s.rod_pa[i] > CLAMPED_READING_PA;
                    if in_stroke[k][i]
                        && open_for[i] > SPOOL_OPEN_SAMPLES
                        && readable
                        && gravity_force[k][i].is_finite()
                        && velocity[k][i].abs() > MOVING_SPEED_M_PER_S
                    {
                        m[5 + i] = s.head_pa[i] * params.head_area_m2[i]
                            - s.rod_pa[i] * params.rod_area_m2[i]; // Eq. A20
                    }
                }
            }
            // End stops: a link at rest within STOP_WINDOW_RAD of a stroke-limited end, pressed
            // towards it by far more than its weight and any dry friction could hold (in free air
            // or carrying: neither the ground nor the soil holds it), rests at that end, whose
            // angle the machine geometry fixes; its reading less that angle is the resolver's
            // offset (end-stop calibration). The bucket rests curled at its stop, the oil behind the
            // closed spool at 5-32 MPa, for most of every work cycle.
            if s.load != LoadTag::InSoil && s.stage == StageTag::Outside {
                for i in 0..3 {
                    if s.rates_rad_per_s[i].abs() >= STOP_REST_RATE_RAD_PER_S
                        || !gravity_force[k][i].is_finite()
                        || !payload_force[k][i].is_finite()
                    {
                        continue;
                    }
                    let (lo, hi) = stop_angles[i];
                    let a = s.angles_rad[i];
                    let toward = if (a - lo).abs() < STOP_WINDOW_RAD {
                        Some((lo, -1.0))
                    } else if (a - hi).abs() < STOP_WINDOW_RAD {
                        Some((hi, 1.0))
                    } else {
                        None
                    };
                    let Some((end, dir)) = toward else {
                        continue;
                    };
                    // Virtual work: the joint torque of a cylinder force is the force times the
                    // moment arm (dL/dq).
                    let excess = s.head_pa[i] * params.head_area_m2[i]
                        - s.rod_pa[i] * params.rod_area_m2[i]
                        - gravity_force[k][i];
                    // Both in the direction of the end (`sign(dL/dq) dir` positive); a payload
                    // held in that direction could be what the cylinder pushes against.
                    let towards = arms_at[k][i].signum() * dir;
                    let payload = (payload_force[k][i] * towards).max(0.0);
                    if excess * towards > STOP_PRESS_FORCE_N + payload {
                        m[Signal::StopAngle.index()] = a - end;
                    }
                }
            }
            // The payload, weighed as the controller does: valves neutral, the implement held up,
            // the settling time after the valves closed, each cylinder away from its stroke ends.
            let neutral = s
                .command
                .iter()
                .chain([&s.swing_command])
                .all(|u| u.abs() <= params.overlap);
            if s.load != LoadTag::Weighing {
                weighing_since = f64::NAN;
            } else if weighing_since.is_nan() || !neutral {
                weighing_since = s.time_s;
            }
            if s.time_s - weighing_since >= WEIGH_SETTLE_S
                && neutral
                && let (Some(len), Some(c)) = (chamber_strokes[k], cut.as_ref())
                && let Some((mass_kg, per_offset_pa)) = weighed_payload(
                    &kin,
                    params,
                    s,
                    &q,
                    &arms_at[k],
                    &len,
                    &strokes,
                    (mass[k], weigh_accel(&velocity, &record.samples, k)),
                )
            {
                let volume_m3 = c.content_m3().clamp(0.0, cfg.bucket.capacity_m3);
                // A full bucket only: it holds its capacity, which the cut volume beyond it does not
                // change. A part-filled one holds what the cut put in less what poured out as it
                // left the soil with its opening tipped down, which this replay does not follow
                // (the 40 kPa cohesion sessions, 0.3-0.6 m^3 cut: 450-690 kg weighed against
                // 570-900 kg for the cut volume).
                if volume_m3 >= WEIGH_MIN_FILL * cfg.bucket.capacity_m3 {
                    m[Signal::PayloadMass.index()] = mass_kg;
                    payload_terms[k] = Some(PayloadTerms {
                        volume_m3,
                        per_offset_pa,
                    });
                }
            }
            // The soil signals in the Dig stage: in the PreDig penetration the bearing resistance
            // dominates, which switches with the direction of the edge's motion at the creep speed
            // and so hangs on the noise of the measured rates; in Capture the full bucket spills
            // around its edge and the edge chatters over that pile, a terrain the replay does not
            // rebuild (effect-free sessions none_s200-203: Capture residual 31-35 kN RMS in x with
            // a +8-9 kN mean in z, against 8-10 kN RMS and +-2 kN in Dig; docs/discrepancy.md,
            // 2026-11-22 and 2026-11-25 soil effects).
            let cutting = s.stage == StageTag::Dig;
            if let (true, true, Some(section)) = (cutting, all_consistent, &cut) {
                soil_terms[k] = soil_terms_of(
                    &kin,
                    cfg,
                    params,
                    s,
                    section,
                    tip_velocity,
                    velocity[k],
                    accel[k],
                    mass[k],
                );
                if let Some(t) = soil_terms[k] {
                    let payload = t.payload_volume_m3 * params.soil.density_kg_per_m3;
                    m[8] = t.measured0[0] + payload * t.measured_per_kg[0];
                    m[9] = t.measured0[1] + payload * t.measured_per_kg[1];
                }
            }
            if let Some(c) = cut.as_mut() {
                spill(c);
            }
        }
        // A weighing that lifts the bucket and weighs again (the controller found it carried by the
        // ground) weighed the ground before the lift: those samples are out. (The last sample of a
        // weighing carries the first command of the swing to the dump, which is no lift.)
        let (mut lift_follows, mut weighed_after) = (false, false);
        for k in (0..n).rev() {
            let s = &record.samples[k];
            if s.load != LoadTag::Weighing {
                (lift_follows, weighed_after) = (false, false);
            } else if s.command.iter().any(|u| u.abs() > params.overlap) {
                lift_follows |= weighed_after;
            } else {
                weighed_after = true;
                if lift_follows {
                    measured[k][Signal::PayloadMass.index()] = f64::NAN;
                    payload_terms[k] = None;
                }
            }
        }
        // The force relation's inertia term takes the accelerations over +-0.05 s: a one-sample
        // difference turns the resolver-rate noise (3 mm/s) into 0.2 m/s^2, 30 kN on the boom's
        // reflected mass, in a measured force that is smooth (effect-free sessions, boom lifting:
        // held-out boom force RMS 30.7 -> 5.8 kN, stick 2.7 -> 1.0 kN). The soil force keeps the
        // one-sample difference (the soil terms above): there the +-0.05 s one lost both 10 kPa
        // cohesion sessions (the bucket's motion in the cut changes within 0.05 s).
        let accel = (0..n)
            .map(|k| weigh_accel(&velocity, &record.samples, k))
            .collect();
        // The velocity signals are compared through the prefilter (the replay filters its
        // predictions the same way); which samples the relation predicts is decided on the raw ones.
        let velocity_gate = measured
            .iter()
            .map(|m| [0, 1, 2].map(|i| m[i].is_finite()))
            .collect();
        prefilter_velocities(&mut measured);
        Ok(Self {
            index: record.index,
            samples: record.samples.clone(),
            measured,
            velocity_gate,
            velocity,
            accel,
            compression,
            compression_bulk_modulus_pa: params.bulk_modulus_pa,
            spool_cache: SpoolCache::default(),
            gravity_force,
            gravity_force_per_rad,
            gravity_force_per_kg,
            link_mass_kg,
            mass,
            soil: soil_terms,
            payload: payload_terms,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// The soil terms of every sample (`None` outside the soil signals).
    pub fn soil_terms(&self) -> &[Option<SoilTerms>] {
        &self.soil
    }

    /// True for a record without samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

/// Whether cylinder `i`'s velocity relation is noise-dominated at sample `s`: its valve open, its
/// inlet reading within [`NOISY_INLET_DP_PA`] of its supply either way (the load, not the valve,
/// limits the flow, `cylinder_velocity` weights the meter-in estimate out, and the load check is
/// not clearly shut either: an inlet well above its supply is a dead end whose own balance gives
/// the speed) and its outlet within
/// [`NOISY_OUTLET_DP_PA`] of tank, so neither metering orifice's drop is known better than the
/// reading noise.
fn load_limited(params: &GreyBoxParams, s: &Sample, i: usize) -> bool {
    let u = s.command[i];
    let (p_in, p_out) = if u > 0.0 {
        (s.head_pa[i], s.rod_pa[i])
    } else {
        (s.rod_pa[i], s.head_pa[i])
    };
    // The boom also takes pump 2's flow through the crossover; the stick is on pump 2.
    let supply = match i {
        0 => s.pump_pa[0].max(s.pump_pa[1]),
        1 => s.pump_pa[1],
        _ => s.pump_pa[0],
    };
    u.abs() > params.overlap
        && (supply - p_in).abs() < NOISY_INLET_DP_PA
        && p_out - params.tank_pa < NOISY_OUTLET_DP_PA
}

/// Whether a measured velocity zig-zags (`before -> now -> after`) by more than
/// [`ALIASED_ZIGZAG_M_PER_S`] each way: an oscillation at the sampling's Nyquist rate.
fn aliased_zigzag(before: f64, now: f64, after: f64) -> bool {
    let (back, ahead) = (now - before, after - now);
    back.abs() > ALIASED_ZIGZAG_M_PER_S
        && ahead.abs() > ALIASED_ZIGZAG_M_PER_S
        && back * ahead < 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spool state is unknown for [`WARMUP_SAMPLES`] at the start of a record and after every gap
    /// in it (samples the reader left out), and known elsewhere.
    #[test]
    fn samples_after_a_gap_warm_up_again() {
        let times = (0..200)
            .map(|k| 0.01 * f64::from(k))
            .chain((0..200).map(|k| 10.0 + 0.01 * f64::from(k)));
        let samples: Vec<crate::Sample> = times
            .map(|time_s| crate::Sample {
                time_s,
                ..Default::default()
            })
            .collect();
        let warm = warmed_up(&samples);
        for (k, w) in warm.iter().enumerate() {
            let since = if k < 200 { k } else { k - 200 };
            assert_eq!(*w, since >= WARMUP_SAMPLES, "sample {k}");
        }
    }

    /// A bucket opened onto the ground: its rod reaches the relief under the opening command, and
    /// the push lasts while that command holds its direction, after the pressure falls back; it ends
    /// when the valve closes or the command turns.
    #[test]
    fn a_push_from_the_relief_lasts_while_the_command_keeps_its_direction() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let sample = |u: f64, rod_pa: f64| {
            let mut s = crate::Sample::default();
            s.command[2] = u;
            s.rod_pa[2] = rod_pa;
            s.head_pa[0] = 0.95 * params.relief_pa; // the boom lifting heavy links: no push
            s
        };
        let relief = params.relief_pa;
        let samples = [
            sample(-0.2, 5.0e6),
            sample(-0.2, 0.95 * relief),
            sample(-0.2, 0.6 * relief),
            sample(-0.25, 0.7 * relief),
            sample(0.0, 0.7 * relief),
            sample(-0.2, 0.7 * relief),
            sample(-0.2, 0.95 * relief),
            sample(0.3, 0.7 * relief),
        ];
        assert_eq!(
            pressing(&samples, &params, &[f64::NAN; 8]),
            [false, true, true, true, false, false, true, false]
        );
    }

    /// A lowering boom whose force falls below a quarter of the links' weight on it rests the
    /// bucket on the ground, at any pressure (that sample only); lifting, or lowering while it
    /// holds the weight, it does not.
    #[test]
    fn a_lowering_boom_that_stops_holding_its_links_rests_on_the_ground() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let gravity_n = 200e3;
        let sample = |u: f64, force_n: f64| {
            let mut s = crate::Sample::default();
            s.command[0] = u;
            s.rod_pa[0] = 4.0e6;
            s.head_pa[0] = (force_n + s.rod_pa[0] * params.rod_area_m2[0]) / params.head_area_m2[0];
            s
        };
        let samples = [
            sample(-0.3, 190e3),
            sample(-0.3, 20e3),
            sample(-0.3, 150e3),
            sample(0.3, 20e3),
            sample(-0.3, -10e3),
        ];
        assert_eq!(
            pressing(&samples, &params, &[gravity_n; 5]),
            [false, true, false, false, true]
        );
    }

    /// A stick or bucket chamber at the relief marks the samples from a quarter second before it
    /// to a second after, whether its valve is closed or open; at its stroke end, or the boom's
    /// chambers at the relief, it does not.
    #[test]
    fn a_bucket_pushed_to_relief_is_held_from_outside_for_a_second_after() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let relief = params.relief_pa;
        let sample = |time_s: f64, u: f64, bucket_rod_pa: f64, boom_head_pa: f64| {
            let mut s = crate::Sample {
                time_s,
                ..Default::default()
            };
            s.command[2] = u;
            s.rod_pa[2] = bucket_rod_pa;
            s.head_pa[0] = boom_head_pa;
            s
        };
        let quiet = 5.0e6;
        let samples = [
            sample(0.0, 0.0, quiet, 0.0),
            sample(0.8, 0.0, quiet, 0.0),
            sample(1.0, 0.0, 0.95 * relief, 0.0),
            sample(1.9, 0.0, quiet, 0.0),
            sample(2.1, 0.0, quiet, 0.0),
            sample(3.0, -0.5, 0.95 * relief, 0.0),
            sample(3.5, 0.0, quiet, 0.0),
            sample(6.0, 0.0, 0.95 * relief, 0.0),
            sample(8.0, 0.0, quiet, 0.95 * relief),
        ];
        let mut in_stroke = [[true; 3]; 9];
        // The bucket at its stroke end at 6 s.
        in_stroke[7][2] = false;
        assert_eq!(
            held_from_outside(&samples, &params, &in_stroke),
            [false, true, true, true, false, true, true, false, false]
        );
    }

    /// A bucket pressing into the soil with its head at the pump pressure and its rod at tank is
    /// load-limited (neither orifice's drop is known); with 3 MPa across its meter-in, with its
    /// valve closed, or with its outlet loaded it is not.
    #[test]
    fn load_limited_needs_both_drops_within_the_noise() {
        let params = crate::AugmentedModel::nominal().unwrap().params;
        let mut s = crate::Sample::default();
        s.command[2] = 0.8;
        s.pump_pa = [20.0e6, 2.0e6];
        s.head_pa[2] = 19.9e6;
        s.rod_pa[2] = params.tank_pa + 0.2e6;
        assert!(load_limited(&params, &s, 2));
        let mut metering = s;
        metering.head_pa[2] = 17.0e6;
        assert!(!load_limited(&params, &metering, 2));
        let mut closed = s;
        closed.command[2] = 0.0;
        assert!(!load_limited(&params, &closed, 2));
        let mut loaded_outlet = s;
        loaded_outlet.rod_pa[2] = 3.0e6;
        assert!(!load_limited(&params, &loaded_outlet, 2));
        // Retracting: the rod is the inlet. The stick is on pump 2.
        let mut stick = crate::Sample::default();
        stick.command[1] = -0.5;
        stick.pump_pa = [2.0e6, 15.0e6];
        stick.rod_pa[1] = 14.95e6;
        stick.head_pa[1] = params.tank_pa;
        assert!(load_limited(&params, &stick, 1));
        // An inlet well above its supply (load check shut) is not.
        stick.pump_pa = [15.0e6, 2.0e6];
        assert!(!load_limited(&params, &stick, 1));
    }

    #[test]
    fn aliased_zigzag_is_a_large_reversal_both_ways() {
        assert!(aliased_zigzag(0.10, 0.16, 0.09));
        assert!(aliased_zigzag(0.0, -0.03, 0.0));
        // A steady ramp, a step, and resolver noise (a few mm/s) are not.
        assert!(!aliased_zigzag(0.0, 0.05, 0.10));
        assert!(!aliased_zigzag(0.0, 0.2, 0.2));
        assert!(!aliased_zigzag(0.0, 0.006, -0.004));
    }
}
