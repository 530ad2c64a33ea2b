//! magcal-calib (skeleton).
