//! Frames a controller sends, shared by the integration tests.

// Test helpers panic on bad fixtures by design.
#![allow(clippy::unwrap_used)]

use firmware_bridge::CanFrame;
use firmware_bridge::messages::{
    AuxValveCommand, ControllerHeartbeat, Message, RequestedMode, Valve,
};

/// A heartbeat requesting valve mode with the alive counter `alive` (mod 16).
pub fn heartbeat(alive: u8) -> CanFrame {
    ControllerHeartbeat {
        mode: RequestedMode::ArmValve,
        alive_counter: alive % 16,
    }
    .to_frame()
    .unwrap()
}

/// A valve command of `u` in `[-1, 1]` for `valve`.
pub fn valve_command(valve: Valve, u: f64) -> CanFrame {
    Message::AuxValveCommand(AuxValveCommand::from_fraction(valve, u).unwrap())
        .encode()
        .unwrap()
}
