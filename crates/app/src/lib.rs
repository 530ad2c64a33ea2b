//! magcal-app (skeleton).
