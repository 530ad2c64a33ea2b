//! The devices the tools talk to, as the command line names them:
//!
//! - `sim[:CHIP]`: a register-level twin of CHIP (default `lis3mdl`) on a simulated bench; the default, so a newcomer
//!   needs no hardware.
//! - `i2c:/dev/i2c-N:CHIP[@ADDR]`: a chip on a Linux I2C bus (linux-embedded-hal), at ADDR (`0x1e` or `30`) or the
//!   chip's default address.
//! - `serial:PATH[:BAUD][:FORMAT][:unit=UNIT][:scale=K]`: a board streaming lines: MotionCal `Raw:` lines (the
//!   default), native CSV, the Adafruit Unified Sensor examples' `X: … Y: … Z: … uT`, three numbers `x,y,z`, or any
//!   line a `pattern=REGEX` with named groups `mx`, `my`, `mz` reads (see [`magcal_driver::serial`]).
//! - `mavlink:PATH[:BAUD][:ardupilot|px4]`: a flight controller speaking MAVLink on a serial port (default 115200
//!   baud), or `mavlink:udp:HOST:PORT[:ardupilot|px4]` over UDP (a simulator or a telemetry router: this machine's
//!   address listened on, another's sent to; [`magcal_autopilot::udp`]); which autopilot it is comes from its
//!   heartbeat unless named. `magcal-record` records its compass with
//!   the autopilot's calibration undone, its attitude, battery current and IMU temperature
//!   ([`crate::source::mavlink`]); `magcal-fit --write-to` sets its calibration parameters
//!   ([`crate::writeback::write_back_autopilot`]).

use std::fmt;
use std::io::{Read, Write};
use std::str::FromStr;
use std::time::Duration;

use magcal_autopilot::{Autopilot, UdpPort};
use magcal_driver::serial::{DeviceSpec as SerialSpec, PatternKind, Protocol};
use magcal_driver::{AnyMagnetometer, ChipKind};
pub use magcal_mockhw::Fault;
use mavlink::dialects::common::{HEARTBEAT_DATA, MavAutopilot, MavMessage, MavType};

use crate::cli::number;
use crate::source::clock::WallClock;
use crate::source::mavlink::MavlinkSource;
use crate::source::{ChipSource, LineSource, Source, SourceError};

/// Chip of `sim` without one.
pub const DEFAULT_SIM_CHIP: ChipKind = ChipKind::Lis3mdl;

/// The device syntax, for `--help` texts.
pub const DEVICE_HELP: &str = "sim[:CHIP] (a simulated chip, the default) | i2c:/dev/i2c-N:CHIP[@ADDR] (Linux I2C) | \
serial:PATH[:BAUD][:FORMAT][:unit=UNIT][:scale=K] (a streaming board; FORMAT motioncal, csv, adafruit, xyz or \
pattern=REGEX) | mavlink:PATH[:BAUD][:ardupilot|px4] or mavlink:udp:HOST:PORT[:ardupilot|px4] (a flight \
controller over MAVLink, serial or UDP); CHIP is lis3mdl, \
lis2mdl, qmc5883l, hmc5883l or mmc5983ma";

/// The baud rate of `mavlink:PATH` without one: ArduPilot's default on its telemetry ports (USB takes any).
pub const DEFAULT_MAVLINK_BAUD: u32 = 115_200;

/// A parsed device string.
#[derive(Clone, Debug, PartialEq)]
pub enum DeviceSpec {
    /// A simulated chip.
    Sim {
        /// Which chip.
        chip: ChipKind,
    },
    /// A chip on a Linux I2C bus.
    I2c {
        /// The bus device, e.g. `/dev/i2c-1`.
        path: String,
        /// Which chip.
        chip: ChipKind,
        /// Its 7-bit address, if not the chip's default.
        address: Option<u8>,
    },
    /// A board on a serial port.
    Serial(SerialSpec),
    /// A flight controller speaking MAVLink.
    Mavlink {
        /// Its serial port or UDP address.
        link: MavlinkLink,
        /// The autopilot, if named (otherwise its heartbeat says).
        autopilot: Option<Autopilot>,
    },
}

/// Where a flight controller's MAVLink comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum MavlinkLink {
    /// A serial port (USB or a telemetry radio).
    Serial {
        /// The port, e.g. `/dev/ttyACM0`.
        path: String,
        /// Its baud rate.
        baud: u32,
    },
    /// UDP (a simulator or a telemetry router).
    Udp {
        /// `HOST:PORT`: listened on if this machine's and free, else sent to.
        host_port: String,
    },
}

/// A byte port MAVLink goes over: a serial port or a [`UdpPort`].
pub trait MavlinkPort: Read + Write + Send {}

impl<T: Read + Write + Send> MavlinkPort for T {}

impl MavlinkLink {
    /// The port's name in messages: its path, or `udp:HOST:PORT`.
    pub fn name(&self) -> String {
        match self {
            MavlinkLink::Serial { path, .. } => path.clone(),
            MavlinkLink::Udp { host_port } => format!("udp:{host_port}"),
        }
    }

    /// Opens the port: a serial port 8N1 with reads waiting at most 20 ms, or a UDP socket; one that sends to an
    /// address first sends a ground station's heartbeat, so that a router answers it.
    pub fn open(&self) -> Result<Box<dyn MavlinkPort>, String> {
        match self {
            MavlinkLink::Serial { path, baud } => serialport::new(path, *baud)
                .timeout(Duration::from_millis(20))
                .open()
                .map(|p| Box::new(p) as Box<dyn MavlinkPort>)
                .map_err(|e| format!("cannot open serial port {path}: {e}")),
            MavlinkLink::Udp { host_port } => {
                let mut port = UdpPort::open(host_port)
                    .map_err(|e| format!("cannot open UDP {host_port}: {e}"))?;
                if port.sends_first() {
                    let mut hello = Vec::new();
                    mavlink::write_v2_msg(
                        &mut hello,
                        mavlink::MavHeader {
                            system_id: 255,
                            component_id: 190,
                            sequence: 0,
                        },
                        &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                            mavtype: MavType::MAV_TYPE_GCS,
                            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                            ..HEARTBEAT_DATA::default()
                        }),
                    )
                    .expect("writing to a Vec");
                    port.write_all(&hello)
                        .map_err(|e| format!("cannot send to UDP {host_port}: {e}"))?;
                }
                Ok(Box::new(port))
            }
        }
    }
}

impl DeviceSpec {
    /// The chip, for I2C and simulated devices.
    pub fn chip(&self) -> Option<ChipKind> {
        match self {
            DeviceSpec::Sim { chip } | DeviceSpec::I2c { chip, .. } => Some(*chip),
            DeviceSpec::Serial(_) | DeviceSpec::Mavlink { .. } => None,
        }
    }

    /// Whether this is a simulated device.
    pub fn is_sim(&self) -> bool {
        matches!(self, DeviceSpec::Sim { .. })
    }

    /// A note to show before recording when the device's numbers are read in a unit nobody stated: `xyz` and
    /// `pattern=` lines without `unit=` or `scale=` are taken as µT.
    pub fn unit_note(&self) -> Option<String> {
        let DeviceSpec::Serial(s) = self else {
            return None;
        };
        match &s.protocol {
            Protocol::Pattern(p) if p.kind() != PatternKind::Adafruit && !p.scale().stated => {
                Some(format!(
                    "note: the numbers of the {} lines are read as µT; if the board prints gauss, mG, nT or raw counts, \
                 add :unit=gauss|mG|nT or :scale=K (K µT per count) to the device string",
                    s.protocol.name()
                ))
            }
            _ => None,
        }
    }
}

impl Default for DeviceSpec {
    fn default() -> DeviceSpec {
        DeviceSpec::Sim {
            chip: DEFAULT_SIM_CHIP,
        }
    }
}

/// A device string that does not parse; the message says what is wrong and gives the syntax.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("bad device {text:?}: {why}; expected {DEVICE_HELP}")]
pub struct DeviceSpecError {
    /// The string given.
    pub text: String,
    /// What is wrong with it.
    pub why: String,
}

fn chip(text: &str, name: &str) -> Result<ChipKind, DeviceSpecError> {
    name.parse().map_err(|e| DeviceSpecError {
        text: text.to_owned(),
        why: format!("{name:?}: {e}"),
    })
}

fn address(text: &str, a: &str) -> Result<u8, DeviceSpecError> {
    let parsed = match a.strip_prefix("0x").or_else(|| a.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16).ok(),
        None => a.parse().ok(),
    };
    parsed
        .filter(|v| (0x08..=0x77).contains(v))
        .ok_or_else(|| DeviceSpecError {
            text: text.to_owned(),
            why: format!("I2C address {a:?} is not a 7-bit address in 0x08–0x77"),
        })
}

/// Why `text` is no device, with the device string it most likely means: a path names its kind first
/// (`serial:/dev/ttyUSB0`, `i2c:/dev/i2c-1:CHIP`).
fn unknown_kind(text: &str) -> String {
    let path = text.split(':').next().unwrap_or(text);
    let name = path.rsplit('/').next().unwrap_or(path);
    if name.starts_with("i2c") {
        format!(
            "unknown kind of device: an I2C bus is named with its chip, as in i2c:{path}:lis3mdl"
        )
    } else if path.starts_with('/')
        || name.starts_with("tty")
        || name.starts_with("cu.")
        || name.starts_with("COM")
    {
        format!("unknown kind of device: a serial port is named serial:{text}")
    } else {
        "unknown kind of device".to_owned()
    }
}

/// `PATH[:BAUD][:ardupilot|px4]` or `udp:HOST:PORT[:ardupilot|px4]` of a `mavlink:` device.
fn mavlink_spec(rest: &str) -> Result<DeviceSpec, String> {
    let mut parts: Vec<&str> = rest.split(':').collect();
    let autopilot = match parts.last().map(|p| p.to_ascii_lowercase()) {
        Some(p) if p == "ardupilot" => Some(Autopilot::ArduPilot),
        Some(p) if p == "px4" => Some(Autopilot::Px4),
        _ => None,
    };
    if autopilot.is_some() {
        parts.pop();
    }
    if parts.first() == Some(&"udp") {
        let host_port = parts[1..].join(":");
        let port_ok = host_port
            .rsplit_once(':')
            .is_some_and(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok());
        if !port_ok {
            return Err(format!(
                "udp:{host_port} is not HOST:PORT, as in mavlink:udp:127.0.0.1:14550"
            ));
        }
        return Ok(DeviceSpec::Mavlink {
            link: MavlinkLink::Udp { host_port },
            autopilot,
        });
    }
    let baud = match parts.last() {
        Some(b) if parts.len() > 1 && !b.is_empty() && b.bytes().all(|c| c.is_ascii_digit()) => {
            let baud: u32 = b
                .parse()
                .ok()
                .filter(|v| (300..=4_000_000).contains(v))
                .ok_or_else(|| format!("baud rate {b} is not one in 300–4000000"))?;
            parts.pop();
            baud
        }
        _ => DEFAULT_MAVLINK_BAUD,
    };
    let path = parts.join(":");
    if path.is_empty() {
        return Err("no serial port path, as in mavlink:/dev/ttyACM0:115200".to_owned());
    }
    Ok(DeviceSpec::Mavlink {
        link: MavlinkLink::Serial { path, baud },
        autopilot,
    })
}

impl FromStr for DeviceSpec {
    type Err = DeviceSpecError;

    fn from_str(s: &str) -> Result<DeviceSpec, DeviceSpecError> {
        let bad = |why: &str| DeviceSpecError {
            text: s.to_owned(),
            why: why.to_owned(),
        };
        let (kind, rest) = match s.split_once(':') {
            Some((k, r)) => (k, Some(r)),
            None => (s, None),
        };
        match (kind, rest) {
            ("sim", None) => Ok(DeviceSpec::default()),
            ("sim", Some(c)) => Ok(DeviceSpec::Sim { chip: chip(s, c)? }),
            ("i2c", Some(rest)) => {
                let (path, target) = rest.rsplit_once(':').ok_or_else(|| {
                    bad("an I2C device needs a bus and a chip, as in i2c:/dev/i2c-1:lis3mdl")
                })?;
                if path.is_empty() {
                    return Err(bad("no I2C bus path"));
                }
                let (name, addr) = match target.split_once('@') {
                    Some((n, a)) => (n, Some(address(s, a)?)),
                    None => (target, None),
                };
                Ok(DeviceSpec::I2c {
                    path: path.to_owned(),
                    chip: chip(s, name)?,
                    address: addr,
                })
            }
            ("serial", Some(rest)) => rest
                .parse()
                .map(DeviceSpec::Serial)
                .map_err(|e| bad(&e.to_string())),
            ("mavlink", Some(rest)) => mavlink_spec(rest).map_err(|why| bad(&why)),
            ("i2c" | "serial" | "mavlink", None) => Err(bad("missing the part after the colon")),
            _ => Err(bad(&unknown_kind(s))),
        }
    }
}

impl fmt::Display for DeviceSpec {
    /// The form [`FromStr`] reads.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceSpec::Sim { chip } => write!(f, "sim:{chip}"),
            DeviceSpec::I2c {
                path,
                chip,
                address: Some(a),
            } => write!(f, "i2c:{path}:{chip}@{a:#04x}"),
            DeviceSpec::I2c { path, chip, .. } => write!(f, "i2c:{path}:{chip}"),
            DeviceSpec::Serial(s) => write!(f, "serial:{s}"),
            DeviceSpec::Mavlink { link, autopilot } => {
                match link {
                    MavlinkLink::Serial { path, baud } => write!(f, "mavlink:{path}:{baud}")?,
                    MavlinkLink::Udp { host_port } => write!(f, "mavlink:udp:{host_port}")?,
                }
                if let Some(a) = autopilot {
                    write!(f, ":{}", a.name())?;
                }
                Ok(())
            }
        }
    }
}

/// How to open a device for recording.
#[derive(Clone, Debug, PartialEq)]
pub struct OpenOptions {
    /// Output data rate to ask the chip for, Hz (the nearest it has is used).
    pub rate_hz: f64,
    /// Full-scale range to ask for, ± µT (the smallest that holds it); the driver's default if `None`.
    pub range_ut: Option<f64>,
    /// `sim`: the seed of the simulated sensor and bench.
    pub sim_seed: u64,
    /// `sim`: faults to inject.
    pub sim_faults: Vec<Fault>,
    /// `sim`: keep virtual time to the wall clock instead of running as fast as possible.
    pub sim_paced: bool,
    /// `sim`: where the bench's jig edge (the virtual hand's north) points, degrees east of true north.
    pub sim_jig_heading_deg: f64,
    /// `serial`: no sample for this long is an error naming the likely cause, s.
    pub idle_timeout_s: f64,
}

impl Default for OpenOptions {
    /// 100 Hz, the driver's range, seed 1, no faults, as fast as possible, the jig on true north, 5 s serial idle
    /// timeout.
    fn default() -> OpenOptions {
        OpenOptions {
            rate_hz: 100.0,
            range_ut: None,
            sim_seed: 1,
            sim_faults: Vec::new(),
            sim_paced: false,
            sim_jig_heading_deg: 0.0,
            idle_timeout_s: 5.0,
        }
    }
}

/// The fastest output data rate one may ask for, Hz (the supported chips reach 1000 Hz).
pub const MAX_RATE_HZ: f64 = 10_000.0;
/// The largest full-scale range one may ask for, ± µT (the supported chips reach ±4915 µT).
pub const MAX_RANGE_UT: f64 = 100_000.0;
/// The longest serial idle timeout, s.
pub const MAX_IDLE_TIMEOUT_S: f64 = 3600.0;

/// An option out of its range, said before anything is opened.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadOption(pub String);

/// `Ok` if `value` is a finite number in `(0, max]`; otherwise an error naming the option, what was given and the
/// range.
pub fn positive_at_most(option: &str, value: f64, max: f64, unit: &str) -> Result<(), BadOption> {
    if value.is_finite() && value > 0.0 && value <= max {
        return Ok(());
    }
    Err(BadOption(format!(
        "{option} {} {unit}: must be a number > 0 and at most {max} {unit}",
        number(value)
    )))
}

/// `Ok` if `value` is a number in `[min, max]`; otherwise an error naming the option, what was given (in a short
/// form) and the range.
pub fn within(option: &str, value: f64, min: f64, max: f64, unit: &str) -> Result<(), BadOption> {
    if (min..=max).contains(&value) {
        return Ok(());
    }
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    Err(BadOption(format!(
        "{option} {}{unit}: must be a number from {} to {}{unit}",
        number(value),
        number(min),
        number(max)
    )))
}

impl OpenOptions {
    /// Checks the options for `spec` before anything is opened: rate, range, idle timeout and jig heading in their
    /// ranges, and
    /// the rate within a factor of ten of what the chip offers.
    pub fn check(&self, spec: &DeviceSpec) -> Result<(), BadOption> {
        positive_at_most("--rate", self.rate_hz, MAX_RATE_HZ, "Hz")?;
        if let Some(range) = self.range_ut {
            positive_at_most("--range-ut", range, MAX_RANGE_UT, "µT")?;
        }
        positive_at_most(
            "--idle-timeout",
            self.idle_timeout_s,
            MAX_IDLE_TIMEOUT_S,
            "s",
        )?;
        within(
            "--sim-jig-heading",
            self.sim_jig_heading_deg,
            -180.0,
            180.0,
            "°",
        )?;
        if let Some(chip) = spec.chip() {
            let rates = chip.info().rates_hz;
            let (slowest, fastest) = (f64::from(rates[0]), f64::from(rates[rates.len() - 1]));
            if self.rate_hz < slowest / 10.0 || self.rate_hz > fastest * 10.0 {
                return Err(BadOption(format!(
                    "--rate {} Hz: the {chip} runs at {slowest}–{fastest} Hz",
                    number(self.rate_hz)
                )));
            }
        }
        Ok(())
    }
}

/// What to say when the I2C bus `path` cannot be opened (`error`, the system's words): a missing bus device is
/// most often I2C not enabled; a refused one, a user outside the `i2c` group. Both say how to check.
fn i2c_open_error(path: &str, error: &str) -> String {
    let bus = path
        .rsplit_once("i2c-")
        .map(|(_, n)| n)
        .filter(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        .unwrap_or("N");
    let check = format!("check the bus and the chip with `i2cdetect -y {bus}` (i2c-tools)");
    if !std::path::Path::new(path).exists() {
        format!(
            "{path} does not exist ({error}): enable I2C (on a Raspberry Pi: sudo raspi-config, Interface Options, \
             I2C, then reboot) or name the bus that exists (ls /dev/i2c-*); {check}"
        )
    } else if error.contains("ermission denied") {
        format!(
            "{path}: {error}: add your user to the i2c group (sudo adduser $USER i2c, then log in again); {check}"
        )
    } else {
        format!("{path}: {error}; {check}")
    }
}

/// Opens a device for recording: a simulated chip, a chip on a Linux I2C bus (initialised for continuous
/// measurement), or a serial stream.
pub fn open(spec: &DeviceSpec, opts: &OpenOptions) -> Result<Box<dyn Source>, SourceError> {
    let device = spec.to_string();
    match spec {
        DeviceSpec::Sim { chip } => Ok(Box::new(crate::source::sim::open(
            *chip,
            opts.sim_seed,
            &opts.sim_faults,
            opts.sim_paced,
            opts.rate_hz,
            opts.range_ut,
            opts.sim_jig_heading_deg,
        )?)),
        DeviceSpec::I2c {
            path,
            chip,
            address,
        } => {
            let bus = magcal_driver::linux::I2cdev::new(path).map_err(|e| SourceError::Open {
                device: device.clone(),
                error: i2c_open_error(path, &e.to_string()),
            })?;
            let mag = AnyMagnetometer::with_address(
                *chip,
                bus,
                address.unwrap_or(chip.default_address()),
            );
            Ok(Box::new(ChipSource::start(
                device,
                mag,
                WallClock::new(),
                opts.rate_hz,
                opts.range_ut,
            )?))
        }
        DeviceSpec::Serial(s) => {
            let source = s.open().map_err(|e| SourceError::Open {
                device: device.clone(),
                error: e.to_string(),
            })?;
            let idle = Duration::from_secs_f64(opts.idle_timeout_s);
            Ok(Box::new(LineSource::new(device, source, idle)))
        }
        DeviceSpec::Mavlink { link, autopilot } => {
            let port = link.open().map_err(|error| SourceError::Open {
                device: device.clone(),
                error,
            })?;
            let idle = Duration::from_secs_f64(opts.idle_timeout_s);
            Ok(Box::new(MavlinkSource::start(
                device,
                port,
                &link.name(),
                *autopilot,
                opts.rate_hz,
                idle,
            )?))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Result<DeviceSpec, DeviceSpecError> {
        s.parse()
    }

    #[test]
    fn every_kind_parses_and_prints_back() {
        assert_eq!(
            p("sim"),
            Ok(DeviceSpec::Sim {
                chip: ChipKind::Lis3mdl
            })
        );
        assert_eq!(
            p("sim:HMC5883L"),
            Ok(DeviceSpec::Sim {
                chip: ChipKind::Hmc5883l
            })
        );
        assert_eq!(
            p("i2c:/dev/i2c-1:lis2mdl"),
            Ok(DeviceSpec::I2c {
                path: "/dev/i2c-1".into(),
                chip: ChipKind::Lis2mdl,
                address: None
            })
        );
        assert_eq!(
            p("i2c:/dev/i2c-1:lis3mdl@0x1e"),
            Ok(DeviceSpec::I2c {
                path: "/dev/i2c-1".into(),
                chip: ChipKind::Lis3mdl,
                address: Some(0x1E)
            })
        );
        assert_eq!(
            p("i2c:/dev/i2c-7:qmc5883l@13").unwrap().to_string(),
            "i2c:/dev/i2c-7:qmc5883l@0x0d"
        );
        assert_eq!(
            p("mavlink:/dev/ttyACM0"),
            Ok(DeviceSpec::Mavlink {
                link: MavlinkLink::Serial {
                    path: "/dev/ttyACM0".into(),
                    baud: 115_200
                },
                autopilot: None
            })
        );
        assert_eq!(
            p("mavlink:udp:localhost:14550:PX4"),
            Ok(DeviceSpec::Mavlink {
                link: MavlinkLink::Udp {
                    host_port: "localhost:14550".into()
                },
                autopilot: Some(Autopilot::Px4)
            })
        );
        for text in [
            "mavlink:/dev/ttyACM0:57600",
            "mavlink:/dev/ttyUSB1:921600:px4",
            "mavlink:udp:127.0.0.1:14550",
            "mavlink:udp:[::1]:14550:ardupilot",
        ] {
            assert_eq!(p(text).unwrap().to_string(), text);
        }
        assert_eq!(
            p("mavlink:/dev/ttyACM0:ArduPilot").unwrap().to_string(),
            "mavlink:/dev/ttyACM0:115200:ardupilot"
        );
        assert!(p("mavlink:/dev/ttyACM0:12").is_err());
        assert!(p("mavlink:udp:14550").is_err());
        assert!(p("mavlink:udp:localhost:99999").is_err());
        let DeviceSpec::Serial(s) = p("serial:/dev/ttyACM0:230400:csv").unwrap() else {
            panic!("not serial");
        };
        assert_eq!(
            (s.path.as_str(), s.baud, s.protocol),
            ("/dev/ttyACM0", 230_400, Protocol::Csv)
        );
        for text in [
            "sim:mmc5983ma",
            "i2c:/dev/i2c-1:hmc5883l",
            "serial:/dev/ttyUSB0:115200:motioncal",
        ] {
            assert_eq!(p(text).unwrap().to_string(), text);
        }
    }

    #[test]
    fn numbers_in_an_unstated_unit_get_a_note() {
        let note = |s: &str| p(s).unwrap().unit_note();
        let said = note("serial:/dev/ttyUSB0:xyz").unwrap();
        assert!(
            said.contains("xyz lines are read as µT") && said.contains(":unit="),
            "{said}"
        );
        assert!(
            note("serial:/dev/ttyUSB0:pattern=(?P<mx>\\S+),(?P<my>\\S+),(?P<mz>\\S+)").is_some()
        );
        for stated in [
            "serial:/dev/ttyUSB0:xyz:unit=uT",
            "serial:/dev/ttyUSB0:xyz:scale=0.15",
            "serial:/dev/ttyUSB0:adafruit",
            "serial:/dev/ttyUSB0",
            "sim",
        ] {
            assert_eq!(note(stated), None, "{stated}");
        }
    }

    #[test]
    fn options_out_of_range_are_refused_naming_the_option() {
        let sim = DeviceSpec::default();
        assert!(OpenOptions::default().check(&sim).is_ok());
        let hmc = p("sim:hmc5883l").unwrap();
        for (spec, rate_hz, says) in [
            (
                &sim,
                1e12,
                "--rate 1000000000000 Hz: must be a number > 0 and at most 10000 Hz",
            ),
            (&sim, f64::NAN, "--rate NaN Hz"),
            (&sim, 0.0, "--rate 0 Hz"),
            (
                &hmc,
                5000.0,
                "--rate 5000 Hz: the hmc5883l runs at 0.75–75 Hz",
            ),
        ] {
            let opts = OpenOptions {
                rate_hz,
                ..OpenOptions::default()
            };
            let e = opts.check(spec).unwrap_err().to_string();
            assert!(e.contains(says), "{rate_hz}: {e}");
        }
        let opts = OpenOptions {
            range_ut: Some(-1.0),
            ..OpenOptions::default()
        };
        assert!(opts.check(&sim).unwrap_err().0.starts_with("--range-ut -1"));
    }

    #[test]
    fn a_missing_i2c_bus_says_how_to_enable_and_check_it() {
        let spec = p("i2c:/nonexistent/i2c-1:lis3mdl").unwrap();
        let Err(e) = open(&spec, &OpenOptions::default()) else {
            panic!("opened a bus that does not exist");
        };
        let e = e.to_string();
        for says in [
            "/nonexistent/i2c-1 does not exist",
            "enable I2C",
            "raspi-config",
            "i2cdetect -y 1",
        ] {
            assert!(e.contains(says), "{says:?} in {e}");
        }
        let denied = i2c_open_error("/", "Permission denied (os error 13)");
        assert!(
            denied.contains("i2c group") && denied.contains("i2cdetect -y N"),
            "{denied}"
        );
    }

    #[test]
    fn refusals_say_what_is_wrong_and_give_the_syntax() {
        for (text, why) in [
            ("sim:lis3", "unknown chip"),
            ("i2c:/dev/i2c-1", "needs a bus and a chip"),
            ("i2c:/dev/i2c-1:lis3mdl@0x90", "not a 7-bit address"),
            ("i2c:/dev/i2c-1:lis3mdl@zz", "not a 7-bit address"),
            ("i2c::lis3mdl", "no I2C bus path"),
            ("serial:/dev/ttyUSB0:0", "baud"),
            ("spi:/dev/spidev0.0", "unknown kind"),
            ("/dev/ttyUSB0", "a serial port is named serial:/dev/ttyUSB0"),
            ("/dev/ttyACM0:115200", "named serial:/dev/ttyACM0:115200"),
            ("COM3", "named serial:COM3"),
            ("/dev/i2c-1", "as in i2c:/dev/i2c-1:lis3mdl"),
            ("/dev/i2c-1:lis3mdl", "as in i2c:/dev/i2c-1:lis3mdl"),
            ("serial", "missing"),
        ] {
            let e = p(text).unwrap_err().to_string();
            assert!(
                e.contains(why) && e.contains("i2c:/dev/i2c-N:CHIP[@ADDR]"),
                "{text}: {e}"
            );
        }
    }
}
