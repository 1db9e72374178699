//! vcan_sim (under construction).
