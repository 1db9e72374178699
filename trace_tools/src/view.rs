//! The Foxglove view of a session: topics, frame ids and the messages (Foxglove's well-known schemas,
//! protobuf) that the live stream (`excavator-ctl demo --live`) and `trace convert --to mcap` both
//! write, so one layout (`docs/foxglove-layout.json`) opens a running session and a recording.
//!
//! | topic | schema | what |
//! | --- | --- | --- |
//! | `/tf` | `foxglove.FrameTransforms` | `world -> base -> house -> boom -> stick -> bucket -> tip` from the controller's estimate |
//! | `/terrain` | `foxglove.Grid` | the controller's terrain map (`elevation`, m, NaN unknown), after each scan |
//! | `/scene` | `foxglove.SceneUpdate` | the machine's links, the floor, the planned dig, the spoil pile |
//! | `/signals` | `excavator.Signals` (JSON) | pressures, valve commands, activity, Autodig stage, swept volume, safety state, faults |
//! | `/log` | `foxglove.Log` | session events (digs, phases, faults, scans) |
//!
//! Frames: `world` is the terrain map's frame (x east, y north, z up); `base` is the undercarriage
//! (the machine pose), `house` turns with the swing, `boom`, `stick` and `bucket` have `x` along
//! their link lines (boom foot -> stick pin -> bucket pin -> tip, docs/ARCHITECTURE.md) and `tip`
//! is the cutting edge. A joint angle, counter-clockwise positive in the side view, is a rotation of
//! `-angle` about the link frame's `y` axis. Timestamps are the session's clock (virtual time in
//! `demo`, the candump timestamps in a trace).

use foxglove::messages::{
    Color, CubePrimitive, FrameTransform, FrameTransforms, Grid, LinePrimitive, Log,
    PackedElementField, Point3, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive,
    Timestamp, Vector2, Vector3, line_primitive, log::Level, packed_element_field::NumericType,
};
use foxglove::{Encode, Schema};
use nalgebra::UnitQuaternion;
use planner::kinematics::{JointAngles, Kinematics, MachinePose};
use planner::terrain::TerrainGrid;
use serde::Serialize;

/// Topic of the machine's frame transforms.
pub const TOPIC_TRANSFORMS: &str = "/tf";
/// Topic of the terrain map.
pub const TOPIC_TERRAIN: &str = "/terrain";
/// Topic of the 3D scene entities.
pub const TOPIC_SCENE: &str = "/scene";
/// Topic of the session's signals (plots).
pub const TOPIC_SIGNALS: &str = "/signals";
/// Topic of the session's events.
pub const TOPIC_LOG: &str = "/log";

/// The world frame (terrain map).
pub const FRAME_WORLD: &str = "world";
/// The undercarriage: the machine pose in the world.
pub const FRAME_BASE: &str = "base";
/// The upper structure, turned by the swing.
pub const FRAME_HOUSE: &str = "house";
/// The boom: origin at the boom foot pin, `x` toward the stick pin.
pub const FRAME_BOOM: &str = "boom";
/// The stick: origin at the stick pin, `x` toward the bucket pin.
pub const FRAME_STICK: &str = "stick";
/// The bucket: origin at the bucket pin, `x` toward the cutting edge.
pub const FRAME_BUCKET: &str = "bucket";
/// The cutting-edge tip.
pub const FRAME_TIP: &str = "tip";

/// A Foxglove timestamp of a session time in ns.
#[must_use]
pub fn timestamp(time_ns: u64) -> Timestamp {
    let sec = u32::try_from(time_ns / 1_000_000_000).unwrap_or(u32::MAX);
    // The remainder is below 1e9 and fits.
    let nsec = u32::try_from(time_ns % 1_000_000_000).unwrap_or(0);
    Timestamp::new(sec, nsec)
}

/// Session seconds as ns (negative and non-finite times clamp to 0).
#[must_use]
pub fn time_ns(time_s: f64) -> u64 {
    if time_s.is_finite() && time_s > 0.0 {
        (time_s * 1e9).round() as u64
    } else {
        0
    }
}

fn transform(
    time_ns: u64,
    parent: &str,
    child: &str,
    t: [f64; 3],
    q: UnitQuaternion<f64>,
) -> FrameTransform {
    FrameTransform {
        timestamp: Some(timestamp(time_ns)),
        parent_frame_id: parent.to_owned(),
        child_frame_id: child.to_owned(),
        translation: Some(Vector3 {
            x: t[0],
            y: t[1],
            z: t[2],
        }),
        rotation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

/// A rotation of a joint angle (counter-clockwise in the side view) about the link frame's `y`.
fn pitch(angle_rad: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(0.0, -angle_rad, 0.0)
}

/// The machine's frames at `time_ns` for joint angles `joints`, swing `swing_rad` and world pose
/// `pose` (module docs). Non-finite inputs give identity rotations and zero translations for the
/// affected frames rather than NaN, which the viewer would reject.
#[must_use]
pub fn machine_transforms(
    kin: &Kinematics,
    joints: &JointAngles,
    swing_rad: f64,
    pose: &MachinePose,
    time_ns: u64,
) -> FrameTransforms {
    let f = |v: f64| if v.is_finite() { v } else { 0.0 };
    let [l2, l3, l4] = kin.link_lengths();
    let [foot_x, foot_z] = kin.boom_foot();
    let yaw = |a: f64| UnitQuaternion::from_euler_angles(0.0, 0.0, f(a));
    let none = UnitQuaternion::identity();
    FrameTransforms {
        transforms: vec![
            transform(
                time_ns,
                FRAME_WORLD,
                FRAME_BASE,
                [f(pose.x_m), f(pose.y_m), 0.0],
                yaw(pose.heading_rad),
            ),
            transform(time_ns, FRAME_BASE, FRAME_HOUSE, [0.0; 3], yaw(swing_rad)),
            transform(
                time_ns,
                FRAME_HOUSE,
                FRAME_BOOM,
                [foot_x, 0.0, foot_z],
                pitch(f(joints.boom_rad)),
            ),
            transform(
                time_ns,
                FRAME_BOOM,
                FRAME_STICK,
                [l2, 0.0, 0.0],
                pitch(f(joints.stick_rad)),
            ),
            transform(
                time_ns,
                FRAME_STICK,
                FRAME_BUCKET,
                [l3, 0.0, 0.0],
                pitch(f(joints.bucket_rad)),
            ),
            transform(time_ns, FRAME_BUCKET, FRAME_TIP, [l4, 0.0, 0.0], none),
        ],
    }
}

/// The terrain map as a `Grid` in the world frame: one `elevation` (float32, m) per cell, NaN where
/// the map has no height.
#[must_use]
pub fn terrain_grid(grid: &TerrainGrid, time_ns: u64) -> Grid {
    let (nx, ny) = (grid.nx(), grid.ny());
    let mut data = Vec::with_capacity(nx * ny * 4);
    for j in 0..ny {
        for i in 0..nx {
            let z = grid.cell(i, j).unwrap_or(f64::NAN) as f32;
            data.extend_from_slice(&z.to_le_bytes());
        }
    }
    let [ox, oy] = grid.origin();
    let cell = grid.resolution_m();
    let u32_of = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    Grid {
        timestamp: Some(timestamp(time_ns)),
        frame_id: FRAME_WORLD.to_owned(),
        pose: Some(Pose {
            position: Some(Vector3 {
                x: ox,
                y: oy,
                z: 0.0,
            }),
            orientation: Some(Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }),
        }),
        column_count: u32_of(nx),
        cell_size: Some(Vector2 { x: cell, y: cell }),
        row_stride: u32_of(nx * 4),
        cell_stride: 4,
        fields: vec![PackedElementField {
            name: "elevation".to_owned(),
            offset: 0,
            r#type: NumericType::Float32 as i32,
        }],
        data: data.into(),
    }
}

const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

fn point(p: [f64; 3]) -> Point3 {
    Point3 {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

fn identity_pose(position: [f64; 3]) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: position[0],
            y: position[1],
            z: position[2],
        }),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    }
}

fn entity(time_ns: u64, frame: &str, id: &str, frame_locked: bool) -> SceneEntity {
    SceneEntity {
        timestamp: Some(timestamp(time_ns)),
        frame_id: frame.to_owned(),
        id: id.to_owned(),
        frame_locked,
        ..SceneEntity::default()
    }
}

/// The machine drawn in its own frames: the undercarriage and the house as boxes, each link as a
/// line along its frame's `x` (they follow `/tf`).
#[must_use]
pub fn machine_entities(kin: &Kinematics, track_length_m: f64, time_ns: u64) -> Vec<SceneEntity> {
    let [l2, l3, l4] = kin.link_lengths();
    let [_, foot_z] = kin.boom_foot();
    let body = rgba(0.95, 0.7, 0.1, 0.8);
    let mut tracks = entity(time_ns, FRAME_BASE, "machine/undercarriage", true);
    tracks.cubes.push(CubePrimitive {
        pose: Some(identity_pose([0.0, 0.0, 0.45])),
        size: Some(Vector3 {
            x: track_length_m,
            y: 2.8,
            z: 0.9,
        }),
        color: Some(rgba(0.3, 0.3, 0.3, 0.8)),
    });
    let mut house = entity(time_ns, FRAME_HOUSE, "machine/house", true);
    house.cubes.push(CubePrimitive {
        pose: Some(identity_pose([-1.0, 0.0, foot_z.max(1.2) * 0.5 + 0.5])),
        size: Some(Vector3 {
            x: 3.5,
            y: 2.6,
            z: foot_z.max(1.2) - 0.2,
        }),
        color: Some(body),
    });
    let link = |frame: &str, id: &str, length_m: f64| {
        let mut e = entity(time_ns, frame, id, true);
        e.lines.push(LinePrimitive {
            r#type: line_primitive::Type::LineStrip as i32,
            thickness: 0.25,
            points: vec![point([0.0; 3]), point([length_m, 0.0, 0.0])],
            color: Some(body),
            ..LinePrimitive::default()
        });
        e
    };
    vec![
        tracks,
        house,
        link(FRAME_BOOM, "machine/boom", l2),
        link(FRAME_STICK, "machine/stick", l3),
        link(FRAME_BUCKET, "machine/bucket", l4),
    ]
}

/// The floor the planner digs to: a thin square slab at `floor_z_m`, `size_m` wide, centred on
/// `centre` (world x, y).
#[must_use]
pub fn floor_entity(floor_z_m: f64, centre: [f64; 2], size_m: f64, time_ns: u64) -> SceneEntity {
    let mut e = entity(time_ns, FRAME_WORLD, "plan/floor", false);
    e.cubes.push(CubePrimitive {
        pose: Some(identity_pose([centre[0], centre[1], floor_z_m - 0.01])),
        size: Some(Vector3 {
            x: size_m,
            y: size_m,
            z: 0.02,
        }),
        color: Some(rgba(0.2, 0.5, 0.9, 0.25)),
    });
    e
}

/// The chosen dig: its planned start (world point) as a sphere and the digging plane from the swing
/// axis `axis` (world x, y) out to the start as a line.
#[must_use]
pub fn dig_entity(axis: [f64; 2], start: [f64; 3], time_ns: u64) -> SceneEntity {
    let mut e = entity(time_ns, FRAME_WORLD, "plan/dig", false);
    e.spheres.push(SpherePrimitive {
        pose: Some(identity_pose(start)),
        size: Some(Vector3 {
            x: 0.4,
            y: 0.4,
            z: 0.4,
        }),
        color: Some(rgba(0.1, 0.9, 0.2, 0.9)),
    });
    e.lines.push(LinePrimitive {
        r#type: line_primitive::Type::LineStrip as i32,
        thickness: 0.05,
        points: vec![point([axis[0], axis[1], start[2]]), point(start)],
        color: Some(rgba(0.1, 0.9, 0.2, 0.9)),
        ..LinePrimitive::default()
    });
    e
}

/// The spoil pile: where the bucket dumps (world point), a translucent cylinder-like marker.
#[must_use]
pub fn spoil_entity(at: [f64; 3], time_ns: u64) -> SceneEntity {
    let mut e = entity(time_ns, FRAME_WORLD, "plan/spoil", false);
    e.spheres.push(SpherePrimitive {
        pose: Some(identity_pose(at)),
        size: Some(Vector3 {
            x: 2.0,
            y: 2.0,
            z: 1.0,
        }),
        color: Some(rgba(0.6, 0.4, 0.2, 0.5)),
    });
    e
}

/// A scene update replacing `entities`.
#[must_use]
pub fn scene(entities: Vec<SceneEntity>) -> SceneUpdate {
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// A session event for `/log`.
#[must_use]
pub fn log(time_ns: u64, level: Level, message: String) -> Log {
    Log {
        timestamp: Some(timestamp(time_ns)),
        level: level as i32,
        message,
        name: "excavator".to_owned(),
        file: String::new(),
        line: 0,
    }
}

/// Cylinder port and pump pressures, Pa.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Pressures {
    /// Boom cylinder head side.
    pub boom_head: Option<f64>,
    /// Boom cylinder rod side.
    pub boom_rod: Option<f64>,
    /// Stick cylinder head side.
    pub stick_head: Option<f64>,
    /// Stick cylinder rod side.
    pub stick_rod: Option<f64>,
    /// Bucket cylinder head side.
    pub bucket_head: Option<f64>,
    /// Bucket cylinder rod side.
    pub bucket_rod: Option<f64>,
    /// Pump 1.
    pub pump1: Option<f64>,
    /// Pump 2.
    pub pump2: Option<f64>,
}

/// Valve commands as fractions of maximum cylinder velocity in `[-1, 1]`, positive = extend.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ValveCommands {
    /// Boom.
    pub boom: Option<f64>,
    /// Stick.
    pub stick: Option<f64>,
    /// Bucket.
    pub bucket: Option<f64>,
    /// Swing.
    pub swing: Option<f64>,
    /// Left track.
    pub left_track: Option<f64>,
    /// Right track.
    pub right_track: Option<f64>,
}

impl ValveCommands {
    /// From `[boom, stick, bucket, swing, left track, right track]`.
    #[must_use]
    pub fn from_array(v: [Option<f64>; 6]) -> Self {
        Self {
            boom: v[0],
            stick: v[1],
            bucket: v[2],
            swing: v[3],
            left_track: v[4],
            right_track: v[5],
        }
    }
}

/// Joint angles, degrees (what a person reads on a plot).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct JointsDeg {
    /// Boom.
    pub boom: Option<f64>,
    /// Stick.
    pub stick: Option<f64>,
    /// Bucket.
    pub bucket: Option<f64>,
    /// Swing.
    pub swing: Option<f64>,
}

/// One sample of the session's signals (`/signals`), JSON with a JSON Schema ([`SIGNALS_SCHEMA`]).
/// `null` where the source does not know a value (a trace has no safety state; a session before the
/// first frame has no pressures).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Signals {
    /// Pressures, Pa.
    pub pressure_pa: Pressures,
    /// Valve commands, fractions.
    pub valve_command: ValveCommands,
    /// Joint angles, degrees.
    pub joints_deg: JointsDeg,
    /// Bucket tip in the base frame `[x, z]`, m.
    pub tip_m: Option<[f64; 2]>,
    /// Work-cycle activity (the `ControllerStatus` names: `Idle`, `Dig`, `SwingToDump`, ...).
    pub activity: Option<String>,
    /// Autodig stage name (`None`, `BoomDown`, `PreDig`, `Dig`, `Capture`, `Done`).
    pub autodig_stage: Option<String>,
    /// Autodig stage code (the `ControllerStatus` value, for plots).
    pub autodig_stage_code: Option<u8>,
    /// Number of the current dig.
    pub dig_index: Option<u32>,
    /// Autodig hardness index in use.
    pub hardness_index: Option<f64>,
    /// Swept volume of the current dig, m^3.
    pub swept_volume_m3: Option<f64>,
    /// Safety state (`Disarmed`, `Arming`, `Armed`, `Faulted`, `ListenOnly`, `Shutdown`).
    pub safety_state: Option<String>,
    /// The active fault's code (0 healthy).
    pub fault_code: Option<u8>,
    /// The active fault, in words.
    pub fault: Option<String>,
    /// Faults so far.
    pub fault_count: Option<u64>,
}

/// The JSON Schema of [`Signals`].
pub const SIGNALS_SCHEMA: &str = r#"{
  "title": "excavator.Signals",
  "type": "object",
  "properties": {
    "pressure_pa": {"type": "object", "properties": {
      "boom_head": {"type": ["number", "null"]}, "boom_rod": {"type": ["number", "null"]},
      "stick_head": {"type": ["number", "null"]}, "stick_rod": {"type": ["number", "null"]},
      "bucket_head": {"type": ["number", "null"]}, "bucket_rod": {"type": ["number", "null"]},
      "pump1": {"type": ["number", "null"]}, "pump2": {"type": ["number", "null"]}}},
    "valve_command": {"type": "object", "properties": {
      "boom": {"type": ["number", "null"]}, "stick": {"type": ["number", "null"]},
      "bucket": {"type": ["number", "null"]}, "swing": {"type": ["number", "null"]},
      "left_track": {"type": ["number", "null"]}, "right_track": {"type": ["number", "null"]}}},
    "joints_deg": {"type": "object", "properties": {
      "boom": {"type": ["number", "null"]}, "stick": {"type": ["number", "null"]},
      "bucket": {"type": ["number", "null"]}, "swing": {"type": ["number", "null"]}}},
    "tip_m": {"type": ["array", "null"], "items": {"type": "number"}},
    "activity": {"type": ["string", "null"]},
    "autodig_stage": {"type": ["string", "null"]},
    "autodig_stage_code": {"type": ["integer", "null"]},
    "dig_index": {"type": ["integer", "null"]},
    "hardness_index": {"type": ["number", "null"]},
    "swept_volume_m3": {"type": ["number", "null"]},
    "safety_state": {"type": ["string", "null"]},
    "fault_code": {"type": ["integer", "null"]},
    "fault": {"type": ["string", "null"]},
    "fault_count": {"type": ["integer", "null"]}
  }
}"#;

impl Encode for Signals {
    type Error = serde_json::Error;

    fn get_schema() -> Option<Schema> {
        Some(Schema::new(
            "excavator.Signals",
            "jsonschema",
            SIGNALS_SCHEMA.as_bytes(),
        ))
    }

    fn get_message_encoding() -> String {
        "json".to_owned()
    }

    fn encode(&self, buf: &mut impl foxglove::bytes::BufMut) -> Result<(), Self::Error> {
        serde_json::to_writer(foxglove::bytes::BufMut::writer(buf), self)
    }
}

/// Finite values only: NaN and infinities become `None` (JSON has no NaN).
#[must_use]
pub fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// What the view shows of the controller's estimate (`controller::step::estimate::MachineState`): the
/// angles, the pose, the pressures and the tip, as plain values. A live view copies this much on the
/// control loop and leaves the messages to its publisher.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EstimateSample {
    /// Implement joint angles, rad.
    pub joints: JointAngles,
    /// Swing angle, rad.
    pub swing_rad: f64,
    /// The dead-reckoned world pose of the base.
    pub pose: MachinePose,
    /// Head-port pressures `[boom, stick, bucket]`, Pa.
    pub head_pressure_pa: [f64; 3],
    /// Rod-port pressures `[boom, stick, bucket]`, Pa.
    pub rod_pressure_pa: [f64; 3],
    /// Pump pressures `[pump1, pump2]`, Pa.
    pub pump_pressure_pa: [f64; 2],
    /// Bucket tip `[x, z]` in the base frame (forward kinematics), m.
    pub tip_m: [f64; 2],
    /// Whether the tip is valid for the current angles.
    pub derived_valid: bool,
}

impl EstimateSample {
    /// The sample of `state`.
    #[must_use]
    pub fn of(state: &controller::step::estimate::MachineState) -> Self {
        Self {
            joints: state.joints,
            swing_rad: state.swing_rad,
            pose: state.pose,
            head_pressure_pa: state.head_pressure_pa,
            rod_pressure_pa: state.rod_pressure_pa,
            pump_pressure_pa: state.pump_pressure_pa,
            tip_m: [state.tip.x_m, state.tip.z_m],
            derived_valid: state.derived_valid,
        }
    }
}

/// The signals the controller's estimate gives: pressures, joint angles, tip.
#[must_use]
pub fn estimate_signals(e: &EstimateSample) -> Signals {
    let h = e.head_pressure_pa;
    let r = e.rod_pressure_pa;
    let p = e.pump_pressure_pa;
    let q = e.joints;
    Signals {
        pressure_pa: Pressures {
            boom_head: finite(h[0]),
            boom_rod: finite(r[0]),
            stick_head: finite(h[1]),
            stick_rod: finite(r[1]),
            bucket_head: finite(h[2]),
            bucket_rod: finite(r[2]),
            pump1: finite(p[0]),
            pump2: finite(p[1]),
        },
        joints_deg: JointsDeg {
            boom: finite(q.boom_rad.to_degrees()),
            stick: finite(q.stick_rad.to_degrees()),
            bucket: finite(q.bucket_rad.to_degrees()),
            swing: finite(e.swing_rad.to_degrees()),
        },
        tip_m: e
            .derived_valid
            .then_some(e.tip_m)
            .filter(|t| t.iter().all(|v| v.is_finite())),
        ..Signals::default()
    }
}

/// The `ControllerStatus` fields (what the controller reports on the bus) into `signals`.
pub fn apply_status(signals: &mut Signals, status: &firmware_bridge::messages::ControllerStatus) {
    signals.activity = Some(format!("{:?}", status.activity));
    signals.autodig_stage = Some(format!("{:?}", status.stage));
    signals.autodig_stage_code = Some(status.stage as u8);
    signals.dig_index = Some(u32::from(status.dig_index));
    signals.hardness_index = finite(status.hardness_index);
    signals.swept_volume_m3 = finite(status.swept_volume_m3);
    signals.fault_code = Some(status.fault_reason);
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner::machine::MachineConfig;

    fn kin() -> Kinematics {
        Kinematics::new(&MachineConfig::default_machine().unwrap()).unwrap()
    }

    /// Composing the frames gives the tip the kinematics compute (the frame chain and the sign
    /// convention of the joint rotations agree with `Kinematics::forward`).
    #[test]
    fn frame_chain_puts_the_tip_where_the_kinematics_do() {
        let kin = kin();
        let q = JointAngles {
            boom_rad: 0.6,
            stick_rad: -1.9,
            bucket_rad: -0.7,
        };
        let swing = 0.4;
        let pose = MachinePose {
            x_m: 3.0,
            y_m: -2.0,
            heading_rad: 0.3,
        };
        let tf = machine_transforms(&kin, &q, swing, &pose, 5);
        let mut iso = nalgebra::Isometry3::identity();
        for t in &tf.transforms {
            let v = t.translation.unwrap();
            let r = t.rotation.unwrap();
            iso *= nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(v.x, v.y, v.z),
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(r.w, r.x, r.y, r.z)),
            );
        }
        let tip = iso.translation.vector;
        let want = kin.tip_in_world(&q, swing, &pose);
        let z = kin.forward(&q).z_m;
        assert!((tip.x - want[0]).abs() < 1e-9, "{tip:?} vs {want:?}");
        assert!((tip.y - want[1]).abs() < 1e-9, "{tip:?} vs {want:?}");
        assert!((tip.z - z).abs() < 1e-9, "{tip:?} vs {z}");
        assert_eq!(tf.transforms.last().unwrap().child_frame_id, FRAME_TIP);
    }

    #[test]
    fn terrain_grid_has_one_float_per_cell_and_nan_for_unknown() {
        let mut g = TerrainGrid::new_unknown(-2.0, 1.0, 0.5, 4, 3).unwrap();
        g.set_cell(1, 2, Some(1.25)).unwrap();
        let m = terrain_grid(&g, 0);
        assert_eq!(m.column_count, 4);
        assert_eq!(m.row_stride, 16);
        assert_eq!(m.data.len(), 4 * 3 * 4);
        let at = |i: usize, j: usize| {
            let o = j * 16 + i * 4;
            f32::from_le_bytes(m.data[o..o + 4].try_into().unwrap())
        };
        assert_eq!(at(1, 2), 1.25);
        assert!(at(0, 0).is_nan());
        assert_eq!(m.pose.unwrap().position.unwrap().x, -2.0);
    }

    #[test]
    fn signals_match_their_schema() {
        let schema: serde_json::Value = serde_json::from_str(SIGNALS_SCHEMA).unwrap();
        let mut s = estimate_signals(&EstimateSample::default());
        s.pressure_pa.pump1 = finite(f64::NAN);
        let mut buf = Vec::new();
        s.encode(&mut buf).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        let props = schema["properties"].as_object().unwrap();
        for (key, value) in v.as_object().unwrap() {
            let sub = props
                .get(key)
                .unwrap_or_else(|| panic!("{key} not in the schema"));
            if let Some(obj) = value.as_object() {
                let sub = sub["properties"].as_object().unwrap();
                for k in obj.keys() {
                    assert!(sub.contains_key(k), "{key}.{k} not in the schema");
                }
            }
        }
        assert!(v["pressure_pa"]["pump1"].is_null());
        assert_eq!(v["joints_deg"]["boom"], 0.0);
    }

    /// The shipped Foxglove layout names only topics of the view and fields of `/signals`, so it
    /// cannot drift from what the stream and the MCAP export write.
    #[test]
    fn the_shipped_layout_names_only_view_topics_and_signal_fields() {
        let layout: serde_json::Value =
            serde_json::from_str(include_str!("../../docs/foxglove-layout.json")).unwrap();
        let sample = serde_json::to_value(Signals::default()).unwrap();
        let topics = [
            TOPIC_TRANSFORMS,
            TOPIC_TERRAIN,
            TOPIC_SCENE,
            TOPIC_SIGNALS,
            TOPIC_LOG,
        ];
        let mut paths = Vec::new();
        fn collect(v: &serde_json::Value, out: &mut Vec<String>) {
            match v {
                serde_json::Value::String(s) if s.starts_with('/') => out.push(s.clone()),
                serde_json::Value::Array(a) => a.iter().for_each(|x| collect(x, out)),
                serde_json::Value::Object(o) => {
                    for (k, x) in o {
                        if k.starts_with('/') {
                            out.push(k.clone());
                        }
                        collect(x, out);
                    }
                }
                _ => {}
            }
        }
        collect(&layout["configById"], &mut paths);
        assert!(paths.len() > 10, "{paths:?}");
        for path in &paths {
            let (topic, fields) = path.split_once('.').unwrap_or((path, ""));
            assert!(topics.contains(&topic), "{path}: no such topic");
            if !fields.is_empty() {
                assert_eq!(topic, TOPIC_SIGNALS, "{path}");
                let mut v = &sample;
                for f in fields.split('.') {
                    v = v
                        .get(f)
                        .unwrap_or_else(|| panic!("{path}: no field {f} in Signals"));
                }
            }
        }
    }

    #[test]
    fn timestamps_split_seconds_and_nanoseconds() {
        let t = timestamp(time_ns(12.25));
        assert_eq!((t.sec(), t.nsec()), (12, 250_000_000));
        assert_eq!(time_ns(-1.0), 0);
        assert_eq!(time_ns(f64::NAN), 0);
    }
}
