//! The serial device string `PATH[:BAUD][:motioncal|csv]`, as the tools take it after `serial:`.

use std::fmt;
use std::str::FromStr;

/// Baud rate when the device string names none (what MotionCal and Adafruit's sketches use).
pub const DEFAULT_BAUD: u32 = 115_200;

/// Which lines the firmware prints.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Protocol {
    /// MotionCal-compatible `Raw:` lines (and `Cal1:`/`Cal2:` echoes).
    #[default]
    MotionCal,
    /// The native CSV stream (magcal-recording v1 columns).
    Csv,
}

impl Protocol {
    /// The name used in device strings: `motioncal` or `csv`.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::MotionCal => "motioncal",
            Protocol::Csv => "csv",
        }
    }
}

impl fmt::Display for Protocol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Protocol {
    type Err = DeviceSpecError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "motioncal" => Ok(Protocol::MotionCal),
            "csv" => Ok(Protocol::Csv),
            other => Err(DeviceSpecError::Protocol(other.to_string())),
        }
    }
}

/// A parsed device string.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceSpec {
    /// Path of the port, e.g. `/dev/ttyACM0` or `COM3`.
    pub path: String,
    /// Baud rate.
    pub baud: u32,
    /// Line protocol.
    pub protocol: Protocol,
}

/// Why a device string was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeviceSpecError {
    /// No path before the options.
    EmptyPath,
    /// The baud rate is zero or too large.
    Baud(String),
    /// The protocol is neither `motioncal` nor `csv`.
    Protocol(String),
}

impl fmt::Display for DeviceSpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceSpecError::EmptyPath => f.write_str("serial device has no path"),
            DeviceSpecError::Baud(b) => write!(f, "bad baud rate {b:?}"),
            DeviceSpecError::Protocol(p) => {
                write!(f, "unknown protocol {p:?} (expected motioncal or csv)")
            }
        }
    }
}

impl std::error::Error for DeviceSpecError {}

/// Whether a device-string part is meant as a baud rate: digits only.
fn is_baud_like(part: &str) -> bool {
    !part.is_empty() && part.bytes().all(|b| b.is_ascii_digit())
}

impl FromStr for DeviceSpec {
    type Err = DeviceSpecError;

    /// Parses `PATH[:BAUD][:motioncal|csv]` from the right, so a path may itself hold colons
    /// (`/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0`): a last part that is a
    /// protocol name is the protocol, then a last part of digits only is the baud rate.
    /// A baud rate that is out of range (`/dev/ttyUSB0:0`), or an unknown protocol word after a
    /// baud rate (`/dev/ttyUSB0:9600:nmea`), is an error rather than part of the path.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut rest = s;
        let mut protocol = Protocol::default();
        if let Some((head, last)) = rest.rsplit_once(':') {
            match last.parse::<Protocol>() {
                Ok(p) => {
                    protocol = p;
                    rest = head;
                }
                Err(e)
                    if last.bytes().all(|b| b.is_ascii_alphabetic())
                        && is_baud_like(head.rsplit_once(':').map_or("", |(_, b)| b)) =>
                {
                    return Err(e);
                }
                Err(_) => {}
            }
        }
        let mut baud = DEFAULT_BAUD;
        if let Some((head, last)) = rest.rsplit_once(':')
            && is_baud_like(last)
        {
            baud = last
                .parse()
                .ok()
                .filter(|&b| b > 0)
                .ok_or_else(|| DeviceSpecError::Baud(last.to_string()))?;
            rest = head;
        }
        if rest.is_empty() {
            return Err(DeviceSpecError::EmptyPath);
        }
        Ok(DeviceSpec {
            path: rest.to_string(),
            baud,
            protocol,
        })
    }
}

impl fmt::Display for DeviceSpec {
    /// `PATH:BAUD:PROTOCOL`, which parses back to the same spec.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.path, self.baud, self.protocol)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(s: &str) -> Result<(String, u32, Protocol), DeviceSpecError> {
        s.parse::<DeviceSpec>()
            .map(|d| (d.path, d.baud, d.protocol))
    }

    #[test]
    fn defaults_and_options() {
        let p = |s: &str| s.to_string();
        assert_eq!(
            spec("/dev/ttyACM0"),
            Ok((p("/dev/ttyACM0"), 115_200, Protocol::MotionCal))
        );
        assert_eq!(
            spec("/dev/ttyUSB1:9600"),
            Ok((p("/dev/ttyUSB1"), 9600, Protocol::MotionCal))
        );
        assert_eq!(spec("COM3:csv"), Ok((p("COM3"), 115_200, Protocol::Csv)));
        assert_eq!(
            spec("COM3:230400:csv"),
            Ok((p("COM3"), 230_400, Protocol::Csv))
        );
        assert_eq!(
            spec("/dev/ttyACM0:115200:motioncal"),
            Ok((p("/dev/ttyACM0"), 115_200, Protocol::MotionCal))
        );
    }

    #[test]
    fn paths_with_colons_survive() {
        let by_path = "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0";
        assert_eq!(spec(by_path).unwrap().0, by_path);
        assert_eq!(
            spec(&format!("{by_path}:57600:csv")).unwrap(),
            (by_path.to_string(), 57_600, Protocol::Csv)
        );
    }

    #[test]
    fn refusals() {
        assert_eq!(spec(""), Err(DeviceSpecError::EmptyPath));
        assert_eq!(spec(":9600"), Err(DeviceSpecError::EmptyPath));
        assert_eq!(
            spec("csv"),
            Ok(("csv".to_string(), 115_200, Protocol::MotionCal))
        );
        assert_eq!(spec(":csv"), Err(DeviceSpecError::EmptyPath));
        assert_eq!(
            spec("/dev/ttyUSB0:0"),
            Err(DeviceSpecError::Baud("0".into()))
        );
        assert!(matches!(
            spec("/dev/ttyUSB0:99999999999"),
            Err(DeviceSpecError::Baud(_))
        ));
        assert_eq!(
            spec("/dev/ttyUSB0:9600:nmea"),
            Err(DeviceSpecError::Protocol("nmea".into()))
        );
    }

    #[test]
    fn display_round_trips() {
        let d: DeviceSpec = "/dev/ttyACM0:csv".parse().unwrap();
        assert_eq!(d.to_string(), "/dev/ttyACM0:115200:csv");
        assert_eq!(d.to_string().parse::<DeviceSpec>(), Ok(d));
    }
}
