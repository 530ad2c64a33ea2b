//! Flight controllers over MAVLink, on the `mavlink` crate: what they send a calibration needs, in physical units
//! ([`mod@telemetry`]); a connection over any byte port that finds the autopilot by its heartbeat ([`link`]), a
//! serial port or UDP ([`udp`]); the parameter protocol, a write-back that leaves the autopilot's previous values when
//! it fails, and `.param` files ([`params`]); the requests for the streams a recording needs ([`streams`]). The bench
//! motor routine is not built yet (docs/autopilot.md, "Not done").

pub mod link;
pub mod params;
pub mod streams;
pub mod telemetry;
pub mod udp;

pub use link::{Autopilot, Connection, FrameBuffer, LinkError, LinkLoss, MemoryPort, duplex};
pub use params::{
    ParamError, ParamValue, WriteFailure, param_file, parse_param_file, read_all, write_all,
};
pub use telemetry::{ReadError, Telemetry, read_stream, telemetry};
pub use udp::UdpPort;
