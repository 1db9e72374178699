//! `excavator-ctl`: the excavator controller.
fn main() {}
