//! planner (under construction).

pub mod autodig;
pub mod cleanup;
