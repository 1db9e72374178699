//! firmware_bridge (under construction).
