//! `magcal`: the bench calibration workflow in one command.
fn main() {}
