//! magcal-sim (skeleton).
