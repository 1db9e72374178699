//! Shared by the controller's integration tests.

use controller::{ControllerConfig, ControllerNode};
use planner::autodig::AutodigMaps;
use planner::machine::MachineConfig;

/// A node for the default machine with the built-in Autodig maps and the default config.
pub fn node() -> ControllerNode {
    ControllerNode::new(
        &MachineConfig::default_machine().unwrap(),
        AutodigMaps::builtin().unwrap(),
        ControllerConfig::default(),
    )
    .unwrap()
}
