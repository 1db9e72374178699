//! Frames a controller sends, shared by the integration tests.

// Test helpers panic on bad fixtures by design.
#![allow(clippy::unwrap_used)]

use firmware_bridge::CanFrame;
use firmware_bridge::gateway::Gateway;
use firmware_bridge::messages::{
    AuxValveCommand, ControllerHeartbeat, Message, RequestedMode, Valve,
};
use firmware_bridge::secoc::{Sealer, SessionKey};

/// The controller's side: its frames sealed for the gateway's current session, as the controller
/// seals them after reading `GatewaySession`.
pub struct Link(Sealer);

impl Link {
    /// A link without a provisioned key.
    pub fn new() -> Self {
        Self(Sealer::new(&SessionKey::PUBLIC))
    }

    fn seal(&mut self, gateway: &Gateway, message: Message) -> CanFrame {
        self.0.set_session(gateway.session().session_id);
        self.0.seal(&message).unwrap()
    }

    /// A heartbeat requesting valve mode with the alive counter `alive` (mod 16).
    pub fn heartbeat(&mut self, gateway: &Gateway, alive: u8) -> CanFrame {
        let hb = ControllerHeartbeat {
            mode: RequestedMode::ArmValve,
            alive_counter: alive % 16,
        };
        self.seal(gateway, Message::ControllerHeartbeat(hb))
    }

    /// A valve command of `u` in `[-1, 1]` for `valve`.
    pub fn valve_command(&mut self, gateway: &Gateway, valve: Valve, u: f64) -> CanFrame {
        let cmd = AuxValveCommand::from_fraction(valve, u).unwrap();
        self.seal(gateway, Message::AuxValveCommand(cmd))
    }
}
