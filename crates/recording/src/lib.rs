//! magcal-recording (skeleton).
