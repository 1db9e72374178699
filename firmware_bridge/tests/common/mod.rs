//! Fixtures shared by the integration tests.
#![allow(dead_code)]
// Values like 3.1416 are the DBC range limits and on-grid fixtures, not approximations of pi.
#![allow(clippy::approx_constant)]

use firmware_bridge::messages::*;

/// Deterministic messages covering every DBC message at least once, with values across the ranges
/// (negative, extremes, fine resolution).
pub fn sample_messages() -> Vec<Message> {
    let mut out = Vec::new();
    let fractions = [0.5, -0.25, 0.0, 1.0, -1.0, 0.3337];
    for (valve, fraction) in Valve::ALL.into_iter().zip(fractions) {
        out.push(Message::AuxValveCommand(
            AuxValveCommand::from_fraction(valve, fraction).expect("fraction in range"),
        ));
    }
    out.push(Message::AuxValveCommand(AuxValveCommand {
        valve: Valve::Bucket,
        flow_percent: 0.0,
        state: ValveState::Float,
        fail_safe: FailSafeMode::Float,
    }));
    for (cylinder, head) in Cylinder::ALL.into_iter().zip([20.5e6, 0.0, 99.995e6]) {
        out.push(Message::AuxValveMeasured(AuxValveMeasured {
            cylinder,
            flow_percent: 12.3475,
            state: ValveState::Retract,
            head_pressure_pa: head,
            rod_pressure_pa: 3.115e6,
        }));
    }
    out.push(Message::JointAngles(JointAngles {
        boom_rad: 0.5236,
        stick_rad: -1.2345,
        bucket_rad: -2.0001,
        swing_rad: 3.1415,
    }));
    out.push(Message::JointAngles(JointAngles {
        boom_rad: -3.1416,
        stick_rad: 3.1416,
        bucket_rad: 0.0,
        swing_rad: -0.0001,
    }));
    out.push(Message::JointRates(JointRates {
        boom_rad_per_s: 0.123,
        stick_rad_per_s: -0.456,
        bucket_rad_per_s: 1.5,
        swing_rad_per_s: -0.02,
    }));
    out.push(Message::PumpPressures(PumpPressures {
        pump1_pa: 32.5e6,
        pump2_pa: 0.0,
    }));
    out.push(Message::TrackOdometry(TrackOdometry {
        left_m: -12.3456,
        right_m: 100.0001,
    }));
    out.push(Message::GatewayStatus(GatewayStatus {
        mode: GatewayMode::ArmedValve,
        faults: GatewayFaults(GatewayFaults::WATCHDOG_TIMEOUT | GatewayFaults::E_STOP),
        alive_counter: 200,
        unexpected_frames: 3,
        rejected_frames: 65535,
    }));
    out.push(Message::PositionSetpoint(PositionSetpoint {
        boom_rad: 0.5,
        stick_rad: -1.0,
        bucket_rad: 0.6994,
        swing_rad: -3.0,
    }));
    out.push(Message::GatewaySession(GatewaySession {
        session_id: 0xDEAD_BEEF,
    }));
    out.push(Message::ControllerHeartbeat(ControllerHeartbeat {
        mode: RequestedMode::ArmValve,
        alive_counter: 5,
    }));
    out.push(Message::ControllerHeartbeat(ControllerHeartbeat {
        mode: RequestedMode::EStop,
        alive_counter: 15,
    }));
    out.push(Message::ControllerStatus(ControllerStatus {
        activity: Activity::Cleanup,
        stage: AutodigStageCode::Capture,
        dig_index: 64255,
        hardness_index: 2.35,
        swept_volume_m3: 1.2345,
        fault_reason: 17,
        alive_counter: 9,
    }));
    out.push(Message::AddressClaimed(AddressClaimed {
        name: firmware_bridge::address_claim::CONTROLLER_NAME,
    }));
    out.push(Message::RequestPgn(RequestPgn {
        pgn: firmware_bridge::address_claim::ADDRESS_CLAIMED_PGN,
    }));
    out.push(Message::Dm1(sample_dm1()));
    out
}

/// A DM1 with every lamp field different and a DTC of the controller's table.
pub fn sample_dm1() -> Dm1 {
    let dtc = firmware_bridge::dm1::CONTROLLER_DTCS[3];
    Dm1 {
        lamps: Lamps {
            malfunction_indicator: LampState {
                status: LampStatus::NotAvailable,
                flash: LampFlash::DoNotFlash,
            },
            red_stop: LampState {
                status: LampStatus::On,
                flash: LampFlash::FastFlash,
            },
            amber_warning: LampState {
                status: LampStatus::Off,
                flash: LampFlash::SlowFlash,
            },
            protect: LampState {
                status: LampStatus::Reserved,
                flash: LampFlash::Reserved,
            },
        },
        dtc: Dtc {
            spn: dtc.spn,
            fmi: dtc.fmi,
            occurrence_count: 126,
        },
    }
}

/// The messages the DBC lists once per sender (`AddressClaimed_Gateway`, `DM1_Gateway`), as the
/// gateway sends them from `0x80`.
pub fn gateway_sourced_samples() -> Vec<(Message, firmware_bridge::CanFrame)> {
    let gateway_dtc = firmware_bridge::dm1::GATEWAY_DTCS[4];
    let dm1 = Message::Dm1(Dm1 {
        dtc: Dtc {
            spn: gateway_dtc.spn,
            fmi: gateway_dtc.fmi,
            occurrence_count: 1,
        },
        ..sample_dm1()
    });
    let claim = Message::AddressClaimed(AddressClaimed {
        name: firmware_bridge::address_claim::GATEWAY_NAME,
    });
    [claim, dm1]
        .into_iter()
        .map(|m| {
            let frame = m
                .encode_from(firmware_bridge::GATEWAY_ADDRESS)
                .expect("sample encodes");
            (m, frame)
        })
        .collect()
}

/// True if the external tool can be used. If not: fails the test when `EXCAVATOR_REQUIRE_TOOLS=1`
/// (the project's test script sets it), otherwise prints that the test is skipped.
pub fn tool_available(name: &str, program: &str, args: &[&str], install_hint: &str) -> bool {
    let ok = std::process::Command::new(program)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        return true;
    }
    if std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() == Ok("1") {
        panic!(
            "{name} is required (EXCAVATOR_REQUIRE_TOOLS=1) but not available; install it with: {install_hint}"
        );
    }
    println!(
        "SKIPPED: {name} is not installed ({install_hint}); set EXCAVATOR_REQUIRE_TOOLS=1 to make this a failure"
    );
    false
}

/// Asserts two messages are the same variant with signal values equal to float precision.
pub fn assert_same(got: &Message, want: &Message) {
    let (a, b) = (got.signal_values(), want.signal_values());
    assert_eq!(
        std::mem::discriminant(got),
        std::mem::discriminant(want),
        "{got:?} vs {want:?}"
    );
    assert_eq!(got.descriptor().name, want.descriptor().name);
    for ((name, x), (_, y)) in a.iter().zip(&b) {
        assert!(
            (x - y).abs() <= 1e-9 * (1.0 + y.abs()),
            "{name}: {x} vs {y} ({got:?} vs {want:?})"
        );
    }
}

/// Asserts two messages are the same variant with every signal value within `tolerance * (1 + |want|)`
/// (a translation through coarser wire units).
pub fn assert_close(got: &Message, want: &Message, tolerance: f64) {
    assert_eq!(got.descriptor().name, want.descriptor().name);
    for ((name, x), (_, y)) in got.signal_values().iter().zip(&want.signal_values()) {
        assert!(
            (x - y).abs() <= tolerance * (1.0 + y.abs()),
            "{name}: {x} vs {y} ({got:?} vs {want:?})"
        );
    }
}
