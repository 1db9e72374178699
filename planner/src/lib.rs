//! planner (under construction).

pub mod autodig;
