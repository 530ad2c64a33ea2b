//! `magcal-record` (being written).
fn main() {}
