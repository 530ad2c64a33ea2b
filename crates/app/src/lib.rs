//! What the magcal command-line tools share: the reference field (with the World Magnetic Model), fitting a recording,
//! the human summary, the JSON report, the parameters file, exports to other tools, and the seed-paper experiment.
//!
//! The tools in `tools/` are thin: they parse arguments and call in here.

pub mod calibrate;
pub mod export;
pub mod field;
pub mod files;
pub mod params;
pub mod report;
pub mod seed;
pub mod summary;
