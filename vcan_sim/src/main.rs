//! `excavator-sim`: the simulated excavator behind its CAN gateway.
fn main() {}
