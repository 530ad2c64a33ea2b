//! magcal-mockhw (skeleton).
