//! Lines of any format, read by a regular expression with named groups (the `regex` crate's syntax).
//!
//! A pattern names the field components `mx`, `my`, `mz` (required) and may name `t` (s) or `t_ms` (ms, as
//! Arduino's `millis()` gives it), `temp` (°C) and the attitude quaternion `qw`, `qx`, `qy`, `qz` (all four or none;
//! scalar first, rotating sensor axes into NED as in the recording format). It is searched for in each line
//! (anchor it with `^…$` to match whole lines); a line it does not match is [`GarbageKind::Unrecognized`], one whose
//! captured field is no number [`GarbageKind::BadNumber`]. An optional group that took no part in the match gives a
//! missing value (NaN). Field values are converted to µT by the pattern's [`ValueScale`].
//!
//! Two built-in patterns cover common library examples:
//!
//! - [`LinePattern::adafruit`]: the Adafruit Unified Sensor examples, `X: 12.34  Y: -5.67  Z: 40.10  uT`
//!   (HMC5883, LSM303) or `\tX: 12.34 \tY: -5.67 \tZ: 40.10 uTesla` (LIS3MDL, MLX90393), in µT. The unit is
//!   required at the end, so the raw-count lines some of these examples print first are not taken for µT.
//! - [`LinePattern::xyz`]: three numbers, `x,y,z` (commas, semicolons, tabs or spaces between them).

use std::fmt;

use regex::Regex;

use super::counts::GarbageKind;
use super::sample::Sample;
use super::unit::ValueScale;

/// The named groups a pattern may hold.
pub const GROUPS: [&str; 10] = [
    "mx", "my", "mz", "t", "t_ms", "temp", "qw", "qx", "qy", "qz",
];

/// A decimal number as firmware prints it.
const NUMBER: &str = r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?";

/// Which pattern: a built-in one, or the user's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatternKind {
    /// Adafruit Unified Sensor example lines, µT.
    Adafruit,
    /// Three numbers a line.
    Xyz,
    /// A regular expression from the device string.
    Custom,
}

/// A compiled line pattern with its unit; see the [module docs](self).
#[derive(Clone, Debug)]
pub struct LinePattern {
    kind: PatternKind,
    /// The expression as given (the built-ins' own for them).
    source: String,
    regex: Regex,
    mag: [usize; 3],
    /// The time group and its seconds per unit.
    t: Option<(usize, f64)>,
    temp: Option<usize>,
    quat: Option<[usize; 4]>,
    scale: ValueScale,
}

impl PartialEq for LinePattern {
    fn eq(&self, other: &Self) -> bool {
        self.kind == other.kind && self.source == other.source && self.scale == other.scale
    }
}

/// Why a pattern was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PatternError {
    /// Not a valid regular expression (what the `regex` crate said).
    Syntax(String),
    /// `mx`, `my` or `mz` is not named.
    MissingGroup(&'static str),
    /// A named group that means nothing here.
    UnknownGroup(String),
    /// Some of `qw,qx,qy,qz` named, not all.
    PartialQuaternion,
    /// Both `t` and `t_ms` named.
    TwoTimes,
    /// A control character (a tab or line end typed into the device string).
    ControlCharacter,
}

impl fmt::Display for PatternError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PatternError::Syntax(e) => write!(f, "the pattern is not a valid regular expression: {e}"),
            PatternError::MissingGroup(g) => write!(
                f,
                "the pattern has no group named {g}: name the field's components (?P<mx>…), (?P<my>…), (?P<mz>…)"
            ),
            PatternError::UnknownGroup(g) => write!(
                f,
                "the pattern names a group {g:?}, which means nothing here (named groups: {}; leave other groups \
                 unnamed)",
                GROUPS.join(", ")
            ),
            PatternError::PartialQuaternion => {
                f.write_str("the pattern names some of qw, qx, qy, qz: name all four or none")
            }
            PatternError::TwoTimes => f.write_str("the pattern names both t and t_ms: name one"),
            PatternError::ControlCharacter => f.write_str(
                "the pattern holds a control character: write a tab as \\t (the pattern is matched within one line)",
            ),
        }
    }
}

impl std::error::Error for PatternError {}

impl LinePattern {
    /// The Adafruit Unified Sensor examples' lines (µT).
    pub fn adafruit() -> LinePattern {
        let unit = r"(?:uTesla|uT|µT)";
        let expr = format!(
            r"(?:^|\s)X:\s*(?P<mx>{NUMBER})\s*(?:{unit}\s+)?Y:\s*(?P<my>{NUMBER})\s*(?:{unit}\s+)?Z:\s*(?P<mz>{NUMBER})\s*{unit}\s*$"
        );
        Self::build(PatternKind::Adafruit, expr, ValueScale::default())
            .expect("the built-in pattern is valid")
    }

    /// Three numbers a line, in `scale`'s unit.
    pub fn xyz(scale: ValueScale) -> LinePattern {
        let sep = r"(?:\s*[,;]\s*|\s+)";
        let expr =
            format!(r"^\s*(?P<mx>{NUMBER}){sep}(?P<my>{NUMBER}){sep}(?P<mz>{NUMBER})\s*[,;]?\s*$");
        Self::build(PatternKind::Xyz, expr, scale).expect("the built-in pattern is valid")
    }

    /// The user's pattern, in `scale`'s unit.
    pub fn custom(expr: &str, scale: ValueScale) -> Result<LinePattern, PatternError> {
        if expr.chars().any(char::is_control) {
            return Err(PatternError::ControlCharacter);
        }
        Self::build(PatternKind::Custom, expr.to_owned(), scale)
    }

    fn build(
        kind: PatternKind,
        source: String,
        scale: ValueScale,
    ) -> Result<LinePattern, PatternError> {
        let regex = Regex::new(&source).map_err(|e| PatternError::Syntax(e.to_string()))?;
        let mut found = [None; GROUPS.len()];
        for (index, name) in regex.capture_names().enumerate() {
            let Some(name) = name else { continue };
            let k = GROUPS
                .iter()
                .position(|g| *g == name)
                .ok_or_else(|| PatternError::UnknownGroup(name.to_owned()))?;
            found[k] = Some(index);
        }
        let group = |name: &'static str| found[GROUPS.iter().position(|g| *g == name).unwrap()];
        let required = |name: &'static str| group(name).ok_or(PatternError::MissingGroup(name));
        let mag = [required("mx")?, required("my")?, required("mz")?];
        let t = match (group("t"), group("t_ms")) {
            (Some(_), Some(_)) => return Err(PatternError::TwoTimes),
            (Some(i), None) => Some((i, 1.0)),
            (None, Some(i)) => Some((i, 1e-3)),
            (None, None) => None,
        };
        let quat = match ["qw", "qx", "qy", "qz"].map(group) {
            [Some(w), Some(x), Some(y), Some(z)] => Some([w, x, y, z]),
            [None, None, None, None] => None,
            _ => return Err(PatternError::PartialQuaternion),
        };
        Ok(LinePattern {
            kind,
            source,
            regex,
            mag,
            t,
            temp: group("temp"),
            quat,
            scale,
        })
    }

    /// Which pattern this is.
    pub fn kind(&self) -> PatternKind {
        self.kind
    }

    /// The regular expression.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// How field values become µT.
    pub fn scale(&self) -> ValueScale {
        self.scale
    }

    /// Whether samples carry a temperature (a `temp` group).
    pub fn has_temperature(&self) -> bool {
        self.temp.is_some()
    }

    /// Whether samples carry an attitude quaternion (`qw,qx,qy,qz` groups).
    pub fn has_quaternion(&self) -> bool {
        self.quat.is_some()
    }

    /// Parses one line (without its terminator).
    pub fn parse_line(&self, line: &str) -> Result<Sample, GarbageKind> {
        let Some(caps) = self.regex.captures(line) else {
            return Err(if self.kind == PatternKind::Xyz && numbers_only(line) {
                GarbageKind::FieldCount
            } else {
                GarbageKind::Unrecognized
            });
        };
        // A group that took no part in the match is a missing value; one that did must hold a number.
        let value = |i: usize| -> Result<f64, GarbageKind> {
            match caps.get(i) {
                None => Ok(f64::NAN),
                Some(m) => number(m.as_str()).ok_or(GarbageKind::BadNumber),
            }
        };
        let ut_per_value = self.scale.ut_per_value();
        let mut mag_ut = [0.0; 3];
        for (k, &i) in self.mag.iter().enumerate() {
            mag_ut[k] = value(i)? * ut_per_value;
        }
        if !mag_ut.iter().all(|v| v.is_finite()) {
            return Err(GarbageKind::BadNumber);
        }
        let t_s = match self.t {
            Some((i, s_per_unit)) => Some(value(i)? * s_per_unit),
            None => None,
        };
        let temp_c = self.temp.map(value).transpose()?;
        let quat_wxyz = match self.quat {
            Some([w, x, y, z]) => Some([value(w)?, value(x)?, value(y)?, value(z)?]),
            None => None,
        };
        Ok(Sample {
            t_s,
            temp_c,
            quat_wxyz,
            ..Sample::mag_only(mag_ut)
        })
    }
}

/// A captured number: decimal, finite (`nan`, `inf` and Arduino's `ovf` are not).
fn number(text: &str) -> Option<f64> {
    text.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Whether a line holds only numbers and separators (an `xyz` line with the wrong count).
fn numbers_only(line: &str) -> bool {
    let mut fields = line
        .split([',', ';', ' ', '\t'])
        .filter(|f| !f.is_empty())
        .peekable();
    fields.peek().is_some() && fields.all(|f| number(f).is_some())
}

impl fmt::Display for LinePattern {
    /// The device-string form: `adafruit`, `xyz[:unit=…][:scale=…]`, `[unit=…:][scale=…:]pattern=REGEX`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            PatternKind::Adafruit => f.write_str("adafruit"),
            PatternKind::Xyz => write!(f, "xyz{}", self.scale.options()),
            PatternKind::Custom => {
                let options = self.scale.options();
                let options = options.strip_prefix(':').unwrap_or_default();
                let sep = if options.is_empty() { "" } else { ":" };
                write!(f, "{options}{sep}pattern={}", self.source)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::unit::MagUnit;
    use super::*;

    fn mag(p: &LinePattern, line: &str) -> [f64; 3] {
        match p.parse_line(line) {
            Ok(s) => s.mag_ut,
            Err(e) => panic!("{line:?}: {e}"),
        }
    }

    #[test]
    fn adafruit_example_lines_and_not_their_raw_lines() {
        let p = LinePattern::adafruit();
        for line in [
            "X: 12.34  Y: -5.67  Z: 40.10  uT",
            "\tX: 12.34 \tY: -5.67 \tZ: 40.10 uTesla ",
            "Mag X: 12.34 µT Y: -5.67 µT Z: 40.10 µT",
        ] {
            assert_eq!(mag(&p, line), [12.34, -5.67, 40.10], "{line:?}");
        }
        for (line, kind) in [
            (
                "X:  1234  \tY:  -567  \tZ:  4010",
                GarbageKind::Unrecognized,
            ),
            (
                "Accel X: 0.1  Y: 0.2  Z: 9.8  m/s^2",
                GarbageKind::Unrecognized,
            ),
            ("X: 12.34  Y: nan  Z: 40.10  uT", GarbageKind::Unrecognized),
            (
                "------------------------------------",
                GarbageKind::Unrecognized,
            ),
        ] {
            assert_eq!(p.parse_line(line), Err(kind), "{line:?}");
        }
        assert_eq!(p.to_string(), "adafruit");
    }

    #[test]
    fn xyz_lines_in_a_unit_and_the_wrong_count_of_numbers() {
        let p = LinePattern::xyz(ValueScale::default());
        for line in [
            "12.5,-3,40",
            " 12.5 ; -3 ; 40 ",
            "12.5\t-3\t40",
            "12.5 -3 40,",
            "1.25e1,-3.0,4e1",
        ] {
            assert_eq!(mag(&p, line), [12.5, -3.0, 40.0], "{line:?}");
        }
        assert_eq!(p.parse_line("1,2"), Err(GarbageKind::FieldCount));
        assert_eq!(p.parse_line("0.5,1,2,3"), Err(GarbageKind::FieldCount));
        assert_eq!(p.parse_line("x=1,2,3"), Err(GarbageKind::Unrecognized));
        let counts = LinePattern::xyz(ValueScale {
            unit: MagUnit::Microtesla,
            scale: 0.15,
            stated: true,
        });
        assert_eq!(mag(&counts, "100,-200,300"), [15.0, -30.0, 45.0]);
        assert_eq!(counts.to_string(), "xyz:scale=0.15");
    }

    #[test]
    fn a_custom_pattern_with_time_temperature_quaternion_and_gauss() {
        let expr = r"^t=(?P<t_ms>\d+) B=\((?P<mx>[^,]+),(?P<my>[^,]+),(?P<mz>[^)]+)\) G(?: T=(?P<temp>\S+))? q=(?P<qw>\S+) (?P<qx>\S+) (?P<qy>\S+) (?P<qz>\S+)$";
        let gauss = ValueScale {
            unit: MagUnit::Gauss,
            scale: 1.0,
            stated: true,
        };
        let p = LinePattern::custom(expr, gauss).unwrap();
        assert!(p.has_quaternion() && p.has_temperature());
        let s = p
            .parse_line("t=1250 B=(0.2,-0.05,0.45) G T=24.5 q=1 0 0 0")
            .unwrap();
        assert_eq!(s.t_s, Some(1.25));
        assert!((s.mag_ut[0] - 20.0).abs() < 1e-12 && (s.mag_ut[2] - 45.0).abs() < 1e-12);
        assert_eq!(s.temp_c, Some(24.5));
        assert_eq!(s.quat_wxyz, Some([1.0, 0.0, 0.0, 0.0]));
        let s = p
            .parse_line("t=1260 B=(0.2,-0.05,0.45) G q=1 0 0 0")
            .unwrap();
        assert!(
            s.temp_c.unwrap().is_nan(),
            "an optional group left out is a missing value"
        );
        assert_eq!(
            p.parse_line("t=1270 B=(0.2,x,0.45) G q=1 0 0 0"),
            Err(GarbageKind::BadNumber)
        );
        assert_eq!(p.parse_line("hello"), Err(GarbageKind::Unrecognized));
        assert_eq!(p.to_string(), format!("unit=gauss:pattern={expr}"));
    }

    #[test]
    fn patterns_that_cannot_work_are_refused_saying_why() {
        let us = ValueScale::default();
        let refused = |expr: &str| LinePattern::custom(expr, us).unwrap_err();
        assert!(matches!(refused(r"(?P<mx>\d+"), PatternError::Syntax(_)));
        assert_eq!(
            refused(r"(?P<mx>\S+) (?P<my>\S+)"),
            PatternError::MissingGroup("mz")
        );
        assert_eq!(
            refused(r"(?P<mx>\S+) (?P<my>\S+) (?P<mz>\S+) (?P<ax>\S+)"),
            PatternError::UnknownGroup("ax".into())
        );
        assert_eq!(
            refused(r"(?P<mx>\S+) (?P<my>\S+) (?P<mz>\S+) (?P<qw>\S+)"),
            PatternError::PartialQuaternion
        );
        assert_eq!(
            refused(r"(?P<t>\S+) (?P<t_ms>\S+) (?P<mx>\S+) (?P<my>\S+) (?P<mz>\S+)"),
            PatternError::TwoTimes
        );
        assert_eq!(
            refused("(?P<mx>\\S+)\t(?P<my>\\S+) (?P<mz>\\S+)"),
            PatternError::ControlCharacter
        );
        let e = refused(r"(?P<mX>\S+)").to_string();
        assert!(e.contains("\"mX\"") && e.contains("mx, my, mz"), "{e}");
    }
}
