//! Magnetometer streams over USB-serial, and writing a calibration back to the firmware.
//!
//! Line formats ([`Protocol`]):
//!
//! - **MotionCal** ([`motioncal`]): the `Raw:ax,ay,az,gx,gy,gz,mx,my,mz` lines that PJRC's
//!   MotionCal and Adafruit's calibration sketches use (counts of 1/8192 g, 1/16 °/s, 0.1 µT).
//! - **Native CSV** ([`csv_stream`]): a header naming magcal-recording v1 columns, then data.
//! - **Patterns** ([`pattern`]): any line, read by a regular expression with named groups `mx`, `my`, `mz` (and
//!   `t`, `temp`, `qw`…), in a unit the device string names ([`unit`](mod@unit)); built in for the Adafruit Unified Sensor
//!   examples (`X: … Y: … Z: … uT`) and for three numbers a line (`x,y,z`).
//!
//! Lines are parsed without I/O ([`stream::StreamParser`]); garbage (noise, half lines, other
//! chatter) is skipped and counted by [`GarbageKind`], never fatal. [`SerialSource`] reads
//! them from a port: it tells an idle device from an unplugged one, and delivers everything
//! received before a disconnect.
//!
//! A calibration goes back as MotionCal's 68-byte packet ([`packet`]): hard-iron offset V,
//! field magnitude and symmetric soft-iron matrix S of `calibrated = S·(raw − V)`
//! ([`affine`] derives them from magcal's `B = A·m + b`). The firmware's `Cal1:`/`Cal2:` echo
//! confirms it ([`echo`], [`SerialSource::write_calibration`]).
//!
//! Tools take a device as `serial:PATH[:BAUD][:FORMAT][:unit=UNIT][:scale=K]`, FORMAT one of
//! `motioncal`, `csv`, `adafruit`, `xyz`, `pattern=REGEX`; [`DeviceSpec`] parses the part after `serial:`.
//!
//! ```no_run
//! use magcal_driver::serial::{DeviceSpec, StreamStop};
//!
//! let spec: DeviceSpec = "/dev/ttyACM0:115200:motioncal".parse()?;
//! let mut source = spec.open()?;
//! loop {
//!     match source.read_sample() {
//!         Ok(received) => println!("{:.3} s: {:?} µT", received.host_s, received.sample.mag_ut),
//!         Err(StreamStop::Idle { .. }) => continue,
//!         Err(StreamStop::Disconnected { reason }) => {
//!             eprintln!("device disconnected ({reason}); garbage: {}", source.counts().garbage);
//!             break;
//!         }
//!     }
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod affine;
pub mod counts;
pub mod csv_stream;
pub mod device;
pub mod echo;
pub mod lines;
pub mod motioncal;
pub mod packet;
pub mod pattern;
pub mod port;
pub mod sample;
pub mod stream;
pub mod unit;

pub use affine::{MotionCalModel, split_affine};
pub use counts::{GarbageCounts, GarbageKind, LineCounts};
pub use device::{DEFAULT_BAUD, DeviceSpec, DeviceSpecError, FORMATS, Protocol};
pub use echo::VerifyFailure;
pub use packet::{CalibrationPacket, PACKET_LEN, decode, encode};
pub use pattern::{LinePattern, PatternError, PatternKind};
pub use port::{
    DEFAULT_IDLE_TIMEOUT, Link, OpenError, Received, SerialSource, StreamStop, Verified,
    WriteError, open,
};
pub use sample::Sample;
pub use unit::{MagUnit, ValueScale};
