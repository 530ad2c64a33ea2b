//! The magcal-recording v1 file format: the one format every magcal tool reads and writes, and that users can
//! write by hand.
//!
//! A recording is a CSV file with a metadata block in front:
//!
//! ```text
//! # magcal-recording v1
//! # sensor: lis3mdl
//! # sample_rate_hz: 100
//! # field_ned_ut: 19.8, 1.2, 45.3
//! t,mx,my,mz,temp,qw,qx,qy,qz
//! 0.000,12.345,-3.210,40.120,23.5,1,0,0,0
//! ```
//!
//! - Leading `# key: value` lines are [`Metadata`]; unknown keys are kept in order, `#` lines without a key are
//!   comments and ignored. The magic first line is optional, but any other version than `v1` is refused.
//! - Then one header row, in any column order: `t` (s), `mx,my,mz` (µT, required), `temp` (°C), `qw,qx,qy,qz`
//!   (unit quaternion, scalar first, Hamilton, rotating sensor-frame vectors into NED), `rx,ry,rz` (expected
//!   field, µT), `gx,gy,gz` (rad/s), any number of currents `i_<name>` (A). Other columns are carried as text.
//! - Then data rows. An empty field or `nan` marks a missing value of an optional channel; a group (`q`, `r`,
//!   `g`) with a missing field is missing as a whole. Values beyond what a column holds ([`limits`]) are refused.
//!   Blank lines are skipped.
//! - Files as other programs write them are read: `\r\n` and `\r` line ends, `;` or tab separators (when the
//!   header names `mx,my,mz` that way), known column names in any case, a spreadsheet's padding (trailing commas on
//!   metadata lines, empty trailing columns, rows of empty fields). Compressed, UTF-16 and binary files are named as
//!   such.
//!
//! [`Recording::read`] checks all of it and reports the first problem with file, line and column
//! ([`ReadError`], one [`ReadErrorKind`] per kind of failure), quoting at most a short escaped excerpt of the file.
//! [`Recording::write`] writes a whole recording atomically ([`atomic`]); [`RecordingWriter`] writes one row at a
//! time, locked, so that a killed recorder leaves a readable file and a second writer is refused. [`probe`] tells
//! whether a file holds a recording, however it was saved, before an output would replace it.
//!
//! ```
//! use magcal_recording::{Layout, Metadata, ReadErrorKind, Recording, RecordingWriter, Sample};
//!
//! let text = "# sensor: lis3mdl\nt,mx,my,mz,temp\n0.00,12.3,-3.2,40.1,\n0.01,12.4,-3.1,40.0,23.5\n";
//! let rec = Recording::from_reader("bench.csv", text.as_bytes())?;
//! assert_eq!(rec.len(), 2);
//! assert_eq!(rec.missing_counts().temp, Some(1));
//!
//! let err = Recording::from_reader("bench.csv", "t,mx,my,mz\n0,1,1.2.3,1\n".as_bytes()).unwrap_err();
//! assert!(matches!(err.kind(), ReadErrorKind::NotANumber(_)));
//! assert_eq!(err.to_string(), "bench.csv:2:3 (my): not a number: \"1.2.3\"");
//!
//! let dir = tempfile::tempdir()?;
//! let layout = Layout { t: true, ..Layout::default() };
//! let mut writer = RecordingWriter::create(&dir.path().join("live.csv"), &Metadata::default(), &layout)?;
//! writer.write_sample(&Sample { t_s: 0.0, mag_ut: [12.3, -3.2, 40.1], ..Sample::default() })?;
//! writer.finish()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod atomic;
mod blocks;
mod decimal;
mod error;
mod layout;
pub mod limits;
mod line_ends;
mod metadata;
pub mod probe;
mod read;
mod recording;
mod rows;
mod sample;
mod write;

pub use error::{ColumnRef, HeaderError, ReadError, ReadErrorKind};
pub use layout::Layout;
pub use metadata::{Date, DateError, Location, Metadata};
pub use read::{AttitudeToReference, ReadOptions};
pub use recording::{Channel, MissingCounts, Recording, Row, TextColumn};
pub use sample::{Sample, SampleError};
pub use write::{
    CURRENT_DECIMALS, CreateOptions, DEFAULT_FLUSH_INTERVAL, GYRO_DECIMALS, Note, QUAT_DECIMALS,
    RecordingWriter, T_DECIMALS, TEMP_DECIMALS, UT_DECIMALS,
};
