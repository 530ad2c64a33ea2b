//! Flight controllers over MAVLink, on the `mavlink` crate: what they send a calibration needs, in physical units
//! ([`mod@telemetry`]). The device for `magcal-record`, the bench motor routine and the write-back of parameters are
//! not built yet (docs/flight-logs.md, "Not done").

pub mod telemetry;

pub use telemetry::{ReadError, Telemetry, read_stream, telemetry};
