//! planner (under construction).
