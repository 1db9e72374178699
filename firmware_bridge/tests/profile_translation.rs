//! Machine profiles (`firmware_bridge::profile`): the shipped default and the example of another
//! gateway load; every canonical message travels through the example's wire frames and back (the
//! authenticated ones bit for bit, so the gateway's checks pass on the rebuilt frame); bad profiles
//! are refused naming the file, the line and the quantity.

mod common;

use std::path::Path;

use firmware_bridge::messages::*;
use firmware_bridge::profile::{Profile, ProfileError, TranslateError};
use firmware_bridge::secoc::{Sealer, SessionKey, Verifier};
use firmware_bridge::{CanFrame, CanId};

const EXAMPLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../examples/other_gateway.toml"
);
const EXAMPLE_DBC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/other_gateway.dbc");
const DEFAULT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../profiles/default.toml");
const SESSION: u32 = 0x5EC0_0C01;

fn example() -> Profile {
    Profile::load(Path::new(EXAMPLE)).unwrap_or_else(|e| panic!("{e}"))
}

/// The sample messages as the controller and the gateway put them on the bus (control frames
/// sealed).
fn sealed_samples() -> Vec<(Message, CanFrame)> {
    let mut sealer = Sealer::new(&SessionKey::PUBLIC);
    sealer.set_session(SESSION);
    common::sample_messages()
        .into_iter()
        .map(|m| {
            let frame = sealer.seal(&m).expect("samples encode");
            (m, frame)
        })
        .collect()
}

#[test]
fn the_default_profile_file_is_the_identity() {
    let profile = Profile::load(Path::new(DEFAULT)).unwrap_or_else(|e| panic!("{e}"));
    assert!(profile.is_identity());
    for (_, frame) in sealed_samples() {
        assert_eq!(profile.to_wire(&frame), Ok(frame));
        assert_eq!(profile.from_wire(&frame), Ok(frame));
    }
}

#[test]
fn every_canonical_message_travels_through_the_example_gateway() {
    let profile = example();
    assert!(!profile.is_identity());
    let mut verifier = Verifier::new(&SessionKey::PUBLIC, SESSION);
    let (mut exact, mut approximate) = (0, 0);
    for (message, frame) in sealed_samples() {
        if firmware_bridge::profile::passes_through(message.descriptor().pgn) {
            // J1939 network management: the example gateway's bus is not J1939.
            assert_eq!(
                profile.to_wire(&frame),
                Err(TranslateError::NotOnThisBus(frame.id())),
                "{message:?}"
            );
            continue;
        }
        let wire = match profile.to_wire(&frame) {
            Ok(wire) => wire,
            Err(TranslateError::NotConstant { quantity, .. }) => {
                // The one sample with fail-safe Float: the example gateway has no such signal.
                assert!(quantity.ends_with(".FailSafeMode"), "{quantity}");
                continue;
            }
            Err(e) => panic!("{message:?}: {e}"),
        };
        assert!(
            matches!(wire.id(), CanId::Standard(_)),
            "{message:?} -> {wire:?}"
        );
        let back = profile
            .from_wire(&wire)
            .unwrap_or_else(|e| panic!("{wire:?}: {e}"));
        let decoded = Message::decode(&back).unwrap_or_else(|e| panic!("{message:?}: {e}"));
        if firmware_bridge::secoc::is_secured(message.descriptor().pgn) {
            assert_eq!(back, frame, "{message:?} must come back bit for bit");
            verifier
                .verify(&decoded, &back)
                .unwrap_or_else(|e| panic!("{message:?}: the rebuilt frame does not verify: {e}"));
            exact += 1;
        } else {
            common::assert_close(&decoded.message, &message, 1e-3);
            approximate += 1;
        }
    }
    println!(
        "{exact} control frames bit for bit, {approximate} sensor/status frames within resolution"
    );
    assert!(exact >= 8 && approximate >= 10);
}

#[test]
fn the_example_degrees_and_bar_are_on_the_wire() {
    let profile = example();
    let wire_dbc = profile.wire();
    let angles = Message::JointAngles(JointAngles {
        boom_rad: std::f64::consts::FRAC_PI_2,
        stick_rad: -1.0,
        bucket_rad: 0.0,
        swing_rad: 0.25,
    })
    .encode()
    .expect("encodes");
    let wire = profile.to_wire(&angles).expect("translates");
    let msg = wire_dbc.message("ArmAngles").expect("in the DBC");
    let values = msg.decode(wire.data()).expect("decodes");
    assert!((values[0].physical - 90.0).abs() < 0.006, "{values:?}");
    let measured = Message::AuxValveMeasured(AuxValveMeasured {
        cylinder: Cylinder::Stick,
        flow_percent: 50.0,
        state: ValveState::Extend,
        head_pressure_pa: 20.0e6,
        rod_pressure_pa: 1.0e6,
    })
    .encode()
    .expect("encodes");
    let wire = profile.to_wire(&measured).expect("translates");
    let msg = wire_dbc.message("ValveFeedback").expect("in the DBC");
    let named: Vec<(String, f64)> = msg
        .decode(wire.data())
        .expect("decodes")
        .iter()
        .map(|v| (msg.signals[v.index].name.clone(), v.physical))
        .collect();
    assert!(named.contains(&("CylinderIndex".into(), 1.0)), "{named:?}");
    assert!(named.contains(&("StickHead".into(), 200.0)), "{named:?}");
    assert!(named.contains(&("StickFlow".into(), 0.5)), "{named:?}");
}

#[test]
fn unmapped_wire_frames_are_rejected() {
    let profile = example();
    for frame in [
        CanFrame::new_standard(0x7FF, &[0; 8]).expect("valid"),
        // A ValveFeedback with a cylinder index no canonical message uses.
        CanFrame::new_standard(0x220, &[0x30, 0, 0, 0, 0, 0, 0, 0]).expect("valid"),
        // The project's own boom command id means nothing to this gateway.
        CanFrame::new_extended(0x0CFE_3027, &[0; 8]).expect("valid"),
    ] {
        assert_eq!(
            profile.from_wire(&frame),
            Err(TranslateError::Unmapped(frame.id()))
        );
    }
    let short = CanFrame::new_standard(0x301, &[0; 4]).expect("valid");
    assert!(matches!(
        profile.from_wire(&short),
        Err(TranslateError::WrongLength { .. })
    ));
}

/// Loads the example with `edit` applied to its text, expecting a refusal.
fn refused(edit: impl Fn(&str) -> String) -> (String, Option<usize>) {
    let text = edit(&std::fs::read_to_string(EXAMPLE).expect("example exists"));
    let dbc = std::fs::read_to_string(EXAMPLE_DBC).expect("example DBC exists");
    match Profile::from_toml_str(&text, "broken.toml", Path::new(EXAMPLE_DBC), &dbc) {
        Ok(_) => panic!("the edited profile was accepted"),
        Err(ProfileError::Invalid { line, message, .. }) => (message, line),
        Err(e) => panic!("unexpected error kind: {e}"),
    }
}

fn line_of(text_edit: impl Fn(&str) -> String, needle: &str) -> usize {
    let text = text_edit(&std::fs::read_to_string(EXAMPLE).expect("example exists"));
    text.lines()
        .position(|l| l.contains(needle))
        .expect("needle in the text")
        + 1
}

#[test]
fn an_incomplete_profile_names_the_missing_quantity_and_line() {
    // A whole message left out.
    let drop_session = |t: &str| {
        t.replace("[messages.GatewaySession]\nwire = \"GwSession\"\n[messages.GatewaySession.signals]\nSessionId = \"Nonce\"\n", "")
    };
    let (message, line) = refused(drop_session);
    assert!(
        message.contains("missing quantity") && message.contains("GatewaySession"),
        "{message}"
    );
    assert!(line.is_some());
    // One signal left out whose name the wire message does not have.
    let drop_signal = |t: &str| {
        t.replace(
            "BucketAngle = { signal = \"BucketDeg\", scale = 57.29577951308232 }\n",
            "",
        )
    };
    let (message, line) = refused(drop_signal);
    assert!(message.contains("JointAngles.BucketAngle"), "{message}");
    assert_eq!(line, Some(line_of(drop_signal, "[messages.JointAngles]")));
}

#[test]
fn a_bad_profile_names_the_quantity_and_line() {
    let typo = |t: &str| t.replace("\"StickDeg\"", "\"StikDeg\"");
    let (message, line) = refused(typo);
    assert!(
        message.contains("JointAngles.StickAngle") && message.contains("StikDeg"),
        "{message}"
    );
    assert_eq!(line, Some(line_of(typo, "StikDeg")));

    // An authenticated frame may not lose resolution: the heartbeat's MAC in 16 bits.
    let lossy = |t: &str| {
        t.replace(
            "Checksum = \"Crc\"",
            "Checksum = { signal = \"Crc\", scale = 0.5 }",
        )
    };
    let (message, line) = refused(lossy);
    assert!(
        message.contains("ControllerHeartbeat.Checksum") && message.contains("authenticated"),
        "{message}"
    );
    assert_eq!(line, Some(line_of(lossy, "scale = 0.5")));

    // #46 finding 9: a scale of 1e-300 read the boom as 0 rad forever; 1e308 overflows the wire.
    // The scale is a unit conversion, its magnitude 1e-6 to 1e6.
    for bad in [
        "1e-300", "1e308", "0.0", "-1e-7", "2e6", "nan", "inf", "-inf",
    ] {
        let edit = |t: &str| {
            t.replacen(
                "BoomAngle = { signal = \"BoomDeg\", scale = 57.29577951308232 }",
                &format!("BoomAngle = {{ signal = \"BoomDeg\", scale = {bad} }}"),
                1,
            )
        };
        let (message, line) = refused(edit);
        assert!(
            message.contains("JointAngles.BoomAngle") && message.contains("1e-6 to 1e6"),
            "{bad}: {message}"
        );
        assert_eq!(line, Some(line_of(edit, "signal = \"BoomDeg\"")), "{bad}");
    }
    let offset = |t: &str| {
        t.replacen(
            "scale = 57.29577951308232 }",
            "scale = 57.29577951308232, offset = inf }",
            1,
        )
    };
    let (message, _) = refused(offset);
    assert!(message.contains("offset finite"), "{message}");

    let no_mux = |t: &str| t.replacen("mux = 0\n", "", 1);
    let (message, _) = refused(no_mux);
    assert!(
        message.contains("AuxValveCommand_Boom") && message.contains("mux"),
        "{message}"
    );

    let twice = |t: &str| t.replacen("mux = 1\n", "mux = 0\n", 1);
    let (message, _) = refused(twice);
    assert!(message.contains("already carries"), "{message}");

    let syntax = |t: &str| t.replacen("wire = \"ArmRates\"", "wire = ArmRates", 1);
    let (_, line) = refused(syntax);
    assert_eq!(line, Some(line_of(syntax, "wire = ArmRates")));

    let unknown = |t: &str| format!("{t}\n[messages.JointAngels]\nwire = \"ArmAngles\"\n");
    let (message, _) = refused(unknown);
    assert!(message.contains("JointAngels"), "{message}");
}

#[test]
fn errors_name_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("gw.toml");
    std::fs::write(&path, "dbc = \"missing.dbc\"\n[messages]\n").expect("write");
    let err = Profile::load(&path).expect_err("no DBC");
    assert!(err.to_string().contains("missing.dbc"), "{err}");
    std::fs::write(
        dir.path().join("missing.dbc"),
        "VERSION \"\"\nBO_ 1 X: 8 A\n SG_ S : 60|8@1+ (1,0) [0|0] \"\" B\n",
    )
    .expect("write");
    let err = Profile::load(&path).expect_err("bad DBC");
    assert!(
        err.to_string().contains("missing.dbc") && err.to_string().contains("does not fit"),
        "{err}"
    );
}

#[test]
fn the_gateways_rates_and_timeouts_come_from_its_dbc_and_the_profile() {
    use firmware_bridge::profile::GatewayTiming;
    let default = Profile::load(Path::new(DEFAULT)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(default.timing(), GatewayTiming::canonical());
    assert_eq!(
        GatewayTiming::canonical(),
        GatewayTiming {
            sensor_period_ms: 10,
            pump_period_ms: 20,
            odometry_period_ms: 50,
            status_period_ms: 50,
            heartbeat_period_ms: 50,
            command_period_ms: 50,
            heartbeat_timeout_ms: 100,
            command_timeout_ms: 100,
        }
    );
    // The example's DBC's GenMsgCycleTime, the tracks' `period_ms` and its `[timeouts]`.
    assert_eq!(
        example().timing(),
        GatewayTiming {
            sensor_period_ms: 20,
            pump_period_ms: 40,
            odometry_period_ms: 100,
            status_period_ms: 100,
            heartbeat_period_ms: 50,
            command_period_ms: 50,
            heartbeat_timeout_ms: 100,
            command_timeout_ms: 100,
        }
    );
}

#[test]
fn inconsistent_rates_and_timeouts_are_refused_naming_the_line() {
    // One of the messages sent together at another period.
    let apart = |t: &str| {
        t.replacen(
            "[messages.JointRates]\nwire = \"ArmRates\"\n",
            "[messages.JointRates]\nwire = \"ArmRates\"\nperiod_ms = 30\n",
            1,
        )
    };
    let (message, line) = refused(apart);
    assert!(
        message.contains("JointRates: period 30 ms") && message.contains("JointAngles"),
        "{message}"
    );
    assert_eq!(line, Some(line_of(apart, "period_ms = 30")));
    // A watchdog shorter than two heartbeat periods.
    let short = |t: &str| t.replacen("heartbeat_ms = 100", "heartbeat_ms = 90", 1);
    let (message, line) = refused(short);
    assert!(
        message.contains("timeouts.heartbeat_ms = 90") && message.contains("ControllerHeartbeat"),
        "{message}"
    );
    assert_eq!(line, Some(line_of(short, "heartbeat_ms = 90")));
    // The default command timeout (100 ms) cannot cover a 60 ms track command period.
    let slow = |t: &str| {
        t.replacen("command_ms = 100\n", "", 1)
            .replacen("period_ms = 50", "period_ms = 60", 1)
    };
    let (message, line) = refused(slow);
    assert!(
        message.contains("timeouts.command_ms = 100 (the default)")
            && message.contains("AuxValveCommand_LeftTrack (60 ms)"),
        "{message}"
    );
    assert_eq!(line, Some(line_of(slow, "period_ms = 60")));
    for bad in ["period_ms = 0", "period_ms = -5", "period_ms = 20000"] {
        let edit = |t: &str| t.replacen("period_ms = 50", bad, 1);
        let (message, line) = refused(edit);
        assert!(
            message.contains("must be 1 to 10000 ms"),
            "{bad}: {message}"
        );
        assert_eq!(line, Some(line_of(edit, bad)));
    }
    // #46 finding 9: a watchdog of 10 s let the machine move on 10 s after the controller fell
    // silent; every timeout that bounds motion is at most ISO 11783-7's 100 ms.
    for bad in [
        "heartbeat_ms = 10000",
        "heartbeat_ms = 200",
        "heartbeat_ms = 101",
        "heartbeat_ms = 0",
        "command_ms = 120",
        "command_ms = -1",
    ] {
        let key = bad.split(' ').next().unwrap();
        let edit = |t: &str| t.replacen(&format!("{key} = 100"), bad, 1);
        let (message, line) = refused(edit);
        assert!(
            message.contains(&format!("timeouts.{bad}")) && message.contains("1 to 100 ms"),
            "{bad}: {message}"
        );
        assert_eq!(line, Some(line_of(edit, bad)), "{bad}");
    }
    let float = |t: &str| t.replacen("period_ms = 50", "period_ms = nan", 1);
    let (_, line) = refused(float);
    assert_eq!(line, Some(line_of(float, "period_ms = nan")));
}

/// `[addresses]` checks the DBC's ids against the declared addresses (it never rewrites them).
#[test]
fn declared_addresses_must_be_the_ones_the_ids_carry() {
    let default = std::fs::read_to_string(DEFAULT).expect("default profile");
    let load = |addresses: &str| {
        let text = default.replacen(
            "\n[messages.",
            &format!("\n[addresses]\n{addresses}\n\n[messages."),
            1,
        );
        Profile::from_toml_str(
            &text,
            "gw.toml",
            Path::new("excavator.dbc"),
            firmware_bridge::dbc::DBC_TEXT,
        )
    };
    let profile = load("controller = 0x27\ngateway = 0x80").unwrap_or_else(|e| panic!("{e}"));
    assert!(profile.is_identity());
    let err = load("controller = 0x28").expect_err("another source address");
    let text = err.to_string();
    assert!(
        text.starts_with("gw.toml:")
            && text.contains("AuxValveCommand_Boom")
            && text.contains("source address 0x27, but the controller's is 0x28"),
        "{text}"
    );
    let err = load("gateway = 0x81").expect_err("another gateway");
    assert!(err.to_string().contains("the gateway's is 0x81"), "{err}");
    // 11-bit ids carry no address.
    let (message, _) = refused(|t: &str| {
        t.replacen(
            "[timeouts]",
            "[addresses]\ncontroller = 0x27\n\n[timeouts]",
            1,
        )
    });
    assert!(
        message.contains("11-bit id, which carries no address"),
        "{message}"
    );
}

/// #46 finding 9: a DBC with two messages on one CAN id was loaded (a frame meant either). Refused,
/// naming the DBC file, the line of the second message and both names.
#[test]
fn a_dbc_with_a_duplicate_can_id_is_refused_naming_its_line() {
    let text = std::fs::read_to_string(EXAMPLE).expect("example exists");
    let dbc = std::fs::read_to_string(EXAMPLE_DBC).expect("example DBC exists");
    // ArmRates (770) moved onto ArmAngles's id (769).
    let dup = dbc.replacen("BO_ 770 ArmRates:", "BO_ 769 ArmRates:", 1);
    let line = dup
        .lines()
        .position(|l| l.starts_with("BO_ 769 ArmRates:"))
        .unwrap()
        + 1;
    let err = Profile::from_toml_str(&text, "gw.toml", Path::new("gw.dbc"), &dup)
        .expect_err("a duplicate id was accepted");
    let message = err.to_string();
    assert!(
        message.starts_with("gw.dbc:")
            && message.contains(&format!("line {line}"))
            && message.contains("ArmRates")
            && message.contains("ArmAngles")
            && message.contains("0x301"),
        "{message}"
    );
}
