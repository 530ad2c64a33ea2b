//! The serial device string `PATH[:BAUD][:FORMAT][:unit=UNIT][:scale=K]`, as the tools take it after `serial:`.
//!
//! FORMAT is `motioncal` (the default), `csv`, `adafruit`, `xyz` or `pattern=REGEX` (see [`Protocol`]). `unit=` and
//! `scale=` say what the numbers of `xyz` and `pattern=` lines are ([`ValueScale`]); the other formats fix their
//! unit. `pattern=` takes the rest of the string (a regular expression may hold colons), except `:unit=…` and
//! `:scale=…` options at its very end.

use std::fmt;
use std::str::FromStr;

use super::pattern::{LinePattern, PatternKind};
use super::unit::{MagUnit, ValueScale};

/// Baud rate when the device string names none (what MotionCal and Adafruit's sketches use).
pub const DEFAULT_BAUD: u32 = 115_200;

/// Which lines the firmware prints.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Protocol {
    /// MotionCal-compatible `Raw:` lines (and `Cal1:`/`Cal2:` echoes).
    #[default]
    MotionCal,
    /// The native CSV stream (magcal-recording v1 columns).
    Csv,
    /// Lines read by a pattern: the Adafruit examples' (`adafruit`), three numbers (`xyz`), or the user's
    /// (`pattern=REGEX`).
    Pattern(LinePattern),
}

/// The formats' names, for messages.
pub const FORMATS: &str = "motioncal, csv, adafruit, xyz or pattern=REGEX";

impl Protocol {
    /// The format's name: `motioncal`, `csv`, `adafruit`, `xyz` or `pattern`.
    pub fn name(&self) -> &'static str {
        match self {
            Protocol::MotionCal => "motioncal",
            Protocol::Csv => "csv",
            Protocol::Pattern(p) => match p.kind() {
                PatternKind::Adafruit => "adafruit",
                PatternKind::Xyz => "xyz",
                PatternKind::Custom => "pattern",
            },
        }
    }

    /// What a line of this format looks like, for messages.
    pub fn shape(&self) -> String {
        match self {
            Protocol::MotionCal => "Raw:ax,ay,az,gx,gy,gz,mx,my,mz lines of integers".to_owned(),
            Protocol::Csv => "a header naming mx,my,mz, then lines of numbers".to_owned(),
            Protocol::Pattern(p) => match p.kind() {
                PatternKind::Adafruit => {
                    "lines like \"X: 12.34  Y: -5.67  Z: 40.10  uT\"".to_owned()
                }
                PatternKind::Xyz => "lines of three numbers, x,y,z".to_owned(),
                PatternKind::Custom => format!("lines matching {}", p.source()),
            },
        }
    }
}

impl fmt::Display for Protocol {
    /// The device-string form of the format and its options.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Protocol::Pattern(p) => write!(f, "{p}"),
            other => f.write_str(other.name()),
        }
    }
}

/// A parsed device string.
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceSpec {
    /// Path of the port, e.g. `/dev/ttyACM0` or `COM3`.
    pub path: String,
    /// Baud rate.
    pub baud: u32,
    /// Line format.
    pub protocol: Protocol,
}

/// Why a device string was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeviceSpecError {
    /// No path before the options.
    EmptyPath,
    /// The baud rate is zero or too large.
    Baud(String),
    /// A word after the baud rate that is no format.
    Protocol(String),
    /// An option (`key=value`) that is unknown, repeated, or has a bad value.
    Option(String),
    /// `unit=` or `scale=` with a format that fixes its unit.
    UnitFixed(&'static str),
    /// The pattern cannot work.
    Pattern(String),
}

impl fmt::Display for DeviceSpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceSpecError::EmptyPath => f.write_str("serial device has no path"),
            DeviceSpecError::Baud(b) => write!(f, "bad baud rate {b:?}"),
            DeviceSpecError::Protocol(p) => {
                write!(f, "unknown format {p:?} (expected {FORMATS})")
            }
            DeviceSpecError::Option(why) => f.write_str(why),
            DeviceSpecError::UnitFixed(format) => write!(
                f,
                "unit= and scale= are for xyz and pattern= lines; {format} lines fix their unit ({})",
                match *format {
                    "motioncal" => "Raw: counts of 0.1 µT",
                    _ => "µT",
                }
            ),
            DeviceSpecError::Pattern(why) => f.write_str(why),
        }
    }
}

impl std::error::Error for DeviceSpecError {}

/// Whether a device-string part is meant as a baud rate: digits only.
fn is_baud_like(part: &str) -> bool {
    !part.is_empty() && part.bytes().all(|b| b.is_ascii_digit())
}

/// The options `unit=` and `scale=`, as given.
#[derive(Default)]
struct UnitOptions {
    unit: Option<MagUnit>,
    scale: Option<f64>,
}

impl UnitOptions {
    /// Takes `part` if it is a `unit=` or `scale=` option; `Ok(false)` if it is no option at all.
    fn take(&mut self, part: &str) -> Result<bool, DeviceSpecError> {
        let Some((key, value)) = part.split_once('=') else {
            return Ok(false);
        };
        let twice = || DeviceSpecError::Option(format!("{key}= is given twice"));
        match key {
            "unit" => {
                let unit = value.parse().map_err(DeviceSpecError::Option)?;
                if self.unit.replace(unit).is_some() {
                    return Err(twice());
                }
            }
            "scale" => {
                let scale = ValueScale::parse_scale(value).map_err(DeviceSpecError::Option)?;
                if self.scale.replace(scale).is_some() {
                    return Err(twice());
                }
            }
            _ if key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') => {
                return Err(DeviceSpecError::Option(format!(
                    "unknown option {key}= (expected unit=, scale= or pattern=)"
                )));
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    fn given(&self) -> bool {
        self.unit.is_some() || self.scale.is_some()
    }

    fn value_scale(&self) -> ValueScale {
        ValueScale {
            unit: self.unit.unwrap_or_default(),
            scale: self.scale.unwrap_or(1.0),
            stated: self.given(),
        }
    }
}

/// The format word `part` names, if any (`pattern=` is handled before).
fn format_word(part: &str) -> Option<&'static str> {
    ["motioncal", "csv", "adafruit", "xyz"]
        .into_iter()
        .find(|w| *w == part)
}

impl FromStr for DeviceSpec {
    type Err = DeviceSpecError;

    /// Parses `PATH[:BAUD][:FORMAT][:unit=UNIT][:scale=K]` from the right, so a path may itself hold colons
    /// (`/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0`): options, then a format word, then a last part of
    /// digits only (the baud rate). `pattern=REGEX` takes everything after it but trailing options. A baud rate that
    /// is out of range (`/dev/ttyUSB0:0`), or an unknown word after a baud rate (`/dev/ttyUSB0:9600:nmea`), is an
    /// error rather than part of the path.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut options = UnitOptions::default();
        let (mut rest, mut pattern) = match s.split_once(":pattern=") {
            Some((head, expr)) => (head, Some(expr)),
            None => (s, None),
        };
        if let Some(expr) = &mut pattern {
            while let Some((head, last)) = expr.rsplit_once(':') {
                if !(last.starts_with("unit=") || last.starts_with("scale=")) {
                    break;
                }
                options.take(last)?;
                *expr = head;
            }
        }
        while let Some((head, last)) = rest.rsplit_once(':') {
            if !options.take(last)? {
                break;
            }
            rest = head;
        }
        let mut word = None;
        if pattern.is_none()
            && let Some((head, last)) = rest.rsplit_once(':')
        {
            match format_word(last) {
                Some(w) => {
                    word = Some(w);
                    rest = head;
                }
                None if last.bytes().all(|b| b.is_ascii_alphabetic())
                    && is_baud_like(head.rsplit_once(':').map_or("", |(_, b)| b)) =>
                {
                    return Err(DeviceSpecError::Protocol(last.to_string()));
                }
                None => {}
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
        let protocol = match (pattern, word) {
            (Some(expr), _) => Protocol::Pattern(
                LinePattern::custom(expr, options.value_scale())
                    .map_err(|e| DeviceSpecError::Pattern(e.to_string()))?,
            ),
            (None, Some("xyz")) => Protocol::Pattern(LinePattern::xyz(options.value_scale())),
            (None, fixed) => {
                let name = fixed.unwrap_or("motioncal");
                if options.given() {
                    return Err(DeviceSpecError::UnitFixed(name));
                }
                match name {
                    "csv" => Protocol::Csv,
                    "adafruit" => Protocol::Pattern(LinePattern::adafruit()),
                    _ => Protocol::MotionCal,
                }
            }
        };
        Ok(DeviceSpec {
            path: rest.to_string(),
            baud,
            protocol,
        })
    }
}

impl fmt::Display for DeviceSpec {
    /// `PATH:BAUD:FORMAT[:options]` (`PATH:BAUD[:options]:pattern=REGEX`), which parses back to the same spec.
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
        for text in [
            "/dev/ttyACM0:115200:adafruit",
            "/dev/ttyACM0:9600:xyz:unit=mG:scale=2",
            "/dev/ttyACM0:9600:xyz:unit=uT",
            "/dev/ttyACM0:115200:unit=gauss:pattern=^X:(?P<mx>\\S+) Y:(?P<my>\\S+) Z:(?P<mz>\\S+)$",
        ] {
            let d: DeviceSpec = text.parse().unwrap();
            assert_eq!(d.to_string(), text);
        }
    }

    fn pattern(s: &str) -> LinePattern {
        match s.parse::<DeviceSpec>().map(|d| d.protocol) {
            Ok(Protocol::Pattern(p)) => p,
            other => panic!("{s}: {other:?}"),
        }
    }

    #[test]
    fn line_formats_and_their_units() {
        assert_eq!(
            pattern("/dev/ttyACM0:adafruit").kind(),
            PatternKind::Adafruit
        );
        let xyz = pattern("/dev/ttyACM0:9600:xyz:scale=0.0917");
        assert_eq!(
            (
                xyz.kind(),
                xyz.scale().unit,
                xyz.scale().scale,
                xyz.scale().stated
            ),
            (PatternKind::Xyz, MagUnit::Microtesla, 0.0917, true)
        );
        assert_eq!(pattern("COM3:xyz").scale(), ValueScale::default());
        // A pattern may hold colons; options may come before or after it.
        let expr = r"^X: (?P<mx>\S+) Y: (?P<my>\S+) Z: (?P<mz>\S+) G$";
        for text in [
            format!("/dev/ttyUSB0:unit=gauss:pattern={expr}"),
            format!("/dev/ttyUSB0:pattern={expr}:unit=gauss"),
            format!("/dev/ttyUSB0:115200:scale=1:pattern={expr}:unit=G"),
        ] {
            let p = pattern(&text);
            assert_eq!(
                (p.source(), p.scale().unit),
                (expr, MagUnit::Gauss),
                "{text}"
            );
            assert_eq!(text.parse::<DeviceSpec>().unwrap().path, "/dev/ttyUSB0");
        }
        let by_path = "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0";
        let d: DeviceSpec = format!("{by_path}:57600:xyz:unit=nT").parse().unwrap();
        assert_eq!((d.path.as_str(), d.baud), (by_path, 57_600));
    }

    #[test]
    fn unit_options_and_patterns_that_cannot_work_are_refused() {
        let e = |s: &str| s.parse::<DeviceSpec>().unwrap_err().to_string();
        for (text, says) in [
            (
                "/dev/ttyACM0:motioncal:unit=gauss",
                "motioncal lines fix their unit (Raw: counts of 0.1 µT)",
            ),
            ("/dev/ttyACM0:scale=2", "motioncal lines fix their unit"),
            ("/dev/ttyACM0:csv:unit=nT", "csv lines fix their unit (µT)"),
            (
                "/dev/ttyACM0:adafruit:scale=0.1",
                "adafruit lines fix their unit",
            ),
            ("/dev/ttyACM0:xyz:unit=tesla", "unknown unit \"tesla\""),
            (
                "/dev/ttyACM0:xyz:scale=-1",
                "scale \"-1\" is not a number > 0",
            ),
            ("/dev/ttyACM0:xyz:scale=1:scale=2", "scale= is given twice"),
            ("/dev/ttyACM0:xyz:units=gauss", "unknown option units="),
            ("/dev/ttyACM0:pattern=(?P<mx>\\S+)", "no group named my"),
            (
                "/dev/ttyACM0:pattern=(?P<mx>[",
                "not a valid regular expression",
            ),
            (
                "/dev/ttyACM0:9600:nmea",
                "unknown format \"nmea\" (expected motioncal, csv, adafruit, xyz",
            ),
        ] {
            let got = e(text);
            assert!(got.contains(says), "{text}: {got}");
        }
    }
}
