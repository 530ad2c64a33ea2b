//! What the magcal command-line tools share: the reference field (with the World Magnetic Model), fitting a recording,
//! the heading error and the verdict, the human summary, the JSON report, the parameters file and applying it to a
//! recording, exports to other tools and how to use them, the seed-paper experiment, and the bench side: devices (simulated, Linux I2C, serial), the recorder and writing a calibration back to a device.
//!
//! The tools in `tools/` are thin: they parse arguments and call in here.

pub mod apply;
pub mod batch;
pub mod calibrate;
pub mod checks;
pub mod cli;
pub mod device;
pub mod effect_spec;
pub mod export;
pub mod field;
pub mod files;
pub mod fit;
pub mod flight;
pub mod heading;
pub mod howto;
pub mod motors;
pub mod outputs;
pub mod params;
pub mod plots;
pub mod readings;
pub mod record;
pub mod reference_heading;
pub mod report;
pub mod seed;
pub mod sim_options;
pub mod source;
pub mod summary;
pub mod truth;
pub mod tty;
pub mod uncertainty;
pub mod units;
pub mod verdict;
pub mod workflow;
pub mod writeback;
