//! The metadata block: `# key: value` lines before the header row.

use std::collections::HashSet;
use std::fmt;
use std::str::FromStr;

use crate::error::{ReadErrorKind, excerpt};
use crate::limits::{MAX_FIELD_UT, MAX_SAMPLE_RATE_HZ};

/// First line of every file this crate writes; files without it are accepted.
pub(crate) const MAGIC: &str = "# magcal-recording v1";

/// The word that opens the magic line, followed by the format version.
pub(crate) const MAGIC_WORD: &str = "magcal-recording";

/// Metadata keys this crate types and validates; every other key lands in [`Metadata::other`].
pub(crate) const KNOWN_KEYS: [&str; 8] = [
    "sensor",
    "serial",
    "sample_rate_hz",
    "field_ned_ut",
    "location",
    "date",
    "routine",
    "started",
];

/// The metadata of a recording. Typed keys are validated when read; unknown keys are kept in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Metadata {
    /// `sensor`: which magnetometer (free text).
    pub sensor: Option<String>,
    /// `serial`: the board's own identifier (free text, e.g. its serial number), as `magcal-record --serial` writes
    /// it; a batch's table names the board by it.
    pub serial: Option<String>,
    /// `sample_rate_hz`: nominal sample rate, > 0.
    pub sample_rate_hz: Option<f64>,
    /// `field_ned_ut`: the local geomagnetic field in world NED axes (north, east, down), µT.
    pub field_ned_ut: Option<[f64; 3]>,
    /// `location`: where the recording was made.
    pub location: Option<Location>,
    /// `date`: the day of the recording.
    pub date: Option<Date>,
    /// `routine`: what was done during the recording (free text).
    pub routine: Option<String>,
    /// `started`: when the recording started (free text, e.g. an RFC 3339 timestamp).
    pub started: Option<String>,
    /// Unknown keys and their values, in file order (e.g. `units`, `field_source`).
    pub other: Vec<(String, String)>,
}

/// Where a recording was made (metadata key `location: lat_deg, lon_deg, alt_m`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    /// Latitude, degrees north, in [-90, 90].
    pub lat_deg: f64,
    /// Longitude, degrees east, in [-180, 180].
    pub lon_deg: f64,
    /// Altitude above mean sea level, m.
    pub alt_m: f64,
}

/// A calendar date (metadata key `date`). Displays as `YYYY-MM-DD`; [`FromStr`] and [`Date::new`] validate it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Date {
    /// Year, 0 to 9999.
    pub year: i32,
    /// Month, 1 to 12.
    pub month: u8,
    /// Day of the month, 1 to the month's length (leap years counted).
    pub day: u8,
}

/// Why a date is invalid.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DateError {
    /// The text is not of the form `YYYY-MM-DD`.
    #[error("expected YYYY-MM-DD")]
    Format,
    /// The year is outside 0..=9999.
    #[error("year {0} out of range 0..=9999")]
    Year(i32),
    /// The month is outside 1..=12.
    #[error("month {0} out of range 1..=12")]
    Month(u8),
    /// The day does not exist in that month.
    #[error("day {day} does not exist in {year:04}-{month:02}")]
    Day {
        /// The year.
        year: i32,
        /// The month.
        month: u8,
        /// The day.
        day: u8,
    },
}

impl Date {
    /// A validated date.
    pub fn new(year: i32, month: u8, day: u8) -> Result<Date, DateError> {
        if !(0..=9999).contains(&year) {
            return Err(DateError::Year(year));
        }
        if !(1..=12).contains(&month) {
            return Err(DateError::Month(month));
        }
        let leap = year % 4 == 0 && (year % 100 != 0 || year % 400 == 0);
        let days = match month {
            2 if leap => 29,
            2 => 28,
            4 | 6 | 9 | 11 => 30,
            _ => 31,
        };
        if day == 0 || day > days {
            return Err(DateError::Day { year, month, day });
        }
        Ok(Date { year, month, day })
    }
}

impl fmt::Display for Date {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:04}-{:02}-{:02}", self.year, self.month, self.day)
    }
}

impl FromStr for Date {
    type Err = DateError;

    fn from_str(s: &str) -> Result<Date, DateError> {
        let b = s.as_bytes();
        let shape_ok = b.len() == 10
            && b[4] == b'-'
            && b[7] == b'-'
            && b.iter()
                .enumerate()
                .all(|(i, c)| i == 4 || i == 7 || c.is_ascii_digit());
        if !shape_ok {
            return Err(DateError::Format);
        }
        let num = |r: std::ops::Range<usize>| {
            b[r].iter()
                .fold(0i32, |acc, c| acc * 10 + i32::from(c - b'0'))
        };
        let month = u8::try_from(num(5..7)).map_err(|_| DateError::Format)?;
        let day = u8::try_from(num(8..10)).map_err(|_| DateError::Format)?;
        Date::new(num(0..4), month, day)
    }
}

/// What one `#` line of the metadata block holds.
pub(crate) enum MetaLine<'a> {
    /// The magic line with its version text (`v1` for this format).
    Magic(&'a str),
    /// A `key: value` pair, both trimmed.
    Pair(&'a str, &'a str),
    /// A comment: no `:`, or nothing before it; ignored.
    Comment,
}

/// Characters a spreadsheet pads a line with when it saves a file as CSV (`# sensor: x,,,,`): stripped from the end
/// of metadata lines, so a value never ends with one.
pub(crate) const PADDING: [char; 3] = [',', ';', '\t'];

/// Splits a `#` line (without its line terminator) into what it holds. Trailing [`PADDING`] is no part of it.
pub(crate) fn classify_line(line: &str) -> MetaLine<'_> {
    let body = line.trim_start().strip_prefix('#').unwrap_or(line);
    let body = body.trim_end_matches(|c: char| PADDING.contains(&c) || c.is_whitespace());
    let body = body.trim();
    if let Some(version) = body.strip_prefix(MAGIC_WORD) {
        return MetaLine::Magic(version.trim());
    }
    match body.split_once(':') {
        Some((key, value)) if !key.trim().is_empty() => MetaLine::Pair(key.trim(), value.trim()),
        _ => MetaLine::Comment,
    }
}

/// Metadata as the reader collects it: with the unknown keys seen so far in a set, so that a file with very many
/// keys is read in linear time.
#[derive(Debug, Default)]
pub(crate) struct MetadataBuilder {
    meta: Metadata,
    other_keys: HashSet<String>,
}

impl MetadataBuilder {
    /// Stores one `key: value` pair, validating typed keys and refusing repeated ones.
    pub(crate) fn set(&mut self, key: &str, value: &str) -> Result<(), ReadErrorKind> {
        if !KNOWN_KEYS.contains(&key) && !self.other_keys.insert(key.to_owned()) {
            return Err(ReadErrorKind::DuplicateMetadata { key: excerpt(key) });
        }
        self.meta.set(key, value)
    }

    /// The metadata read.
    pub(crate) fn finish(self) -> Metadata {
        self.meta
    }
}

impl Metadata {
    /// Stores one `key: value` pair, validating typed keys. Repeats of unknown keys are the caller's to find.
    fn set(&mut self, key: &str, value: &str) -> Result<(), ReadErrorKind> {
        let bad = |reason: String| ReadErrorKind::BadMetadata {
            key: excerpt(key),
            value: excerpt(value),
            reason,
        };
        let duplicate = || ReadErrorKind::DuplicateMetadata { key: excerpt(key) };
        if has_control(key) || has_control(value) {
            return Err(bad("control character in a metadata line".into()));
        }
        match key {
            "sensor" => put(&mut self.sensor, value.to_owned()).ok_or_else(duplicate),
            "serial" => put(&mut self.serial, value.to_owned()).ok_or_else(duplicate),
            "routine" => put(&mut self.routine, value.to_owned()).ok_or_else(duplicate),
            "started" => put(&mut self.started, value.to_owned()).ok_or_else(duplicate),
            "sample_rate_hz" => {
                let rate: f64 = value.parse().map_err(|_| bad("not a number".into()))?;
                if !(rate.is_finite() && rate > 0.0 && rate <= MAX_SAMPLE_RATE_HZ) {
                    return Err(bad(format!(
                        "must be a number > 0 and at most {MAX_SAMPLE_RATE_HZ:e}"
                    )));
                }
                put(&mut self.sample_rate_hz, rate).ok_or_else(duplicate)
            }
            "field_ned_ut" => {
                let field = parse_triple(value).map_err(bad)?;
                if field.iter().any(|v| v.abs() > MAX_FIELD_UT) {
                    return Err(bad(format!("out of range (at most {MAX_FIELD_UT:e} µT)")));
                }
                put(&mut self.field_ned_ut, field).ok_or_else(duplicate)
            }
            "location" => {
                let [lat_deg, lon_deg, alt_m] = parse_triple(value).map_err(bad)?;
                let location = Location {
                    lat_deg,
                    lon_deg,
                    alt_m,
                };
                location.check().map_err(|e| bad(e.into()))?;
                put(&mut self.location, location).ok_or_else(duplicate)
            }
            "date" => {
                let date: Date = value.parse().map_err(|e: DateError| bad(e.to_string()))?;
                put(&mut self.date, date).ok_or_else(duplicate)
            }
            _ => {
                self.other.push((key.to_owned(), value.to_owned()));
                Ok(())
            }
        }
    }

    /// The metadata as `(key, value)` pairs in the order they are written: typed keys first, then
    /// [`Metadata::other`].
    pub fn pairs(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        let mut push = |k: &str, v: Option<String>| {
            if let Some(v) = v {
                out.push((k.to_owned(), v));
            }
        };
        push("sensor", self.sensor.clone());
        push("serial", self.serial.clone());
        push("sample_rate_hz", self.sample_rate_hz.map(|r| r.to_string()));
        push(
            "field_ned_ut",
            self.field_ned_ut.map(|[n, e, d]| format!("{n}, {e}, {d}")),
        );
        push(
            "location",
            self.location
                .map(|l| format!("{}, {}, {}", l.lat_deg, l.lon_deg, l.alt_m)),
        );
        push("date", self.date.map(|d| d.to_string()));
        push("routine", self.routine.clone());
        push("started", self.started.clone());
        out.extend(self.other.iter().cloned());
        out
    }

    /// Checks that the metadata can be written and read back as it is: typed values in range, text without line
    /// breaks or surrounding blanks, unknown keys that are neither known keys nor the magic word, without `:`,
    /// and not repeated.
    pub(crate) fn check(&self) -> Result<(), String> {
        if let Some(rate) = self.sample_rate_hz
            && !(rate.is_finite() && rate > 0.0 && rate <= MAX_SAMPLE_RATE_HZ)
        {
            return Err(format!(
                "sample_rate_hz must be a number > 0 and at most {MAX_SAMPLE_RATE_HZ:e}, got {rate}"
            ));
        }
        if let Some(field) = self.field_ned_ut
            && !field
                .iter()
                .all(|v| v.is_finite() && v.abs() <= MAX_FIELD_UT)
        {
            return Err(format!(
                "field_ned_ut must be finite and at most {MAX_FIELD_UT:e} µT, got {field:?}"
            ));
        }
        if let Some(location) = self.location {
            location.check().map_err(str::to_owned)?;
        }
        if let Some(date) = self.date {
            Date::new(date.year, date.month, date.day).map_err(|e| format!("date: {e}"))?;
        }
        let texts = [
            ("sensor", &self.sensor),
            ("serial", &self.serial),
            ("routine", &self.routine),
            ("started", &self.started),
        ];
        for (key, value) in texts {
            if let Some(value) = value {
                check_text(key, value)?;
            }
        }
        let mut seen = HashSet::with_capacity(self.other.len());
        for (key, value) in &self.other {
            let plain =
                !key.is_empty() && key.trim() == key && !key.contains(':') && !has_control(key);
            if !plain || key.starts_with(MAGIC_WORD) || KNOWN_KEYS.contains(&key.as_str()) {
                return Err(format!(
                    "metadata key {key:?} cannot be written as an unknown key"
                ));
            }
            if !seen.insert(key.as_str()) {
                return Err(format!("metadata key {key:?} repeated"));
            }
            check_text(key, value)?;
        }
        Ok(())
    }
}

/// Text values are trimmed when read, trailing [`PADDING`] is stripped, and a line break would end the line.
fn check_text(key: &str, value: &str) -> Result<(), String> {
    if has_control(value) || value.trim() != value || value.ends_with(PADDING) {
        return Err(format!(
            "metadata value of {key:?} has a control character, surrounding blanks or a trailing ',' or ';': \
             {value:?}"
        ));
    }
    Ok(())
}

/// Control characters other than tab (a lone CR, say) have no place in a metadata line: other tools may break the
/// line there.
fn has_control(text: &str) -> bool {
    text.chars().any(|c| c.is_control() && c != '\t')
}

impl Location {
    /// Checks the ranges of latitude and longitude and that the altitude is finite.
    fn check(&self) -> Result<(), &'static str> {
        if !(-90.0..=90.0).contains(&self.lat_deg) {
            return Err("latitude must be within [-90, 90] degrees");
        }
        if !(-180.0..=180.0).contains(&self.lon_deg) {
            return Err("longitude must be within [-180, 180] degrees");
        }
        if !self.alt_m.is_finite() {
            return Err("altitude must be finite");
        }
        Ok(())
    }
}

/// Sets a slot that must still be empty; `None` if it already held a value.
fn put<T>(slot: &mut Option<T>, value: T) -> Option<()> {
    if slot.is_some() {
        return None;
    }
    *slot = Some(value);
    Some(())
}

/// Parses `a, b, c`: exactly three finite numbers.
fn parse_triple(value: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = value.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected 3 comma-separated numbers, got {}",
            parts.len()
        ));
    }
    let mut out = [0.0_f64; 3];
    for (slot, part) in out.iter_mut().zip(&parts) {
        *slot = part
            .parse()
            .map_err(|_| format!("{:?} is not a number", excerpt(part)))?;
        if !slot.is_finite() {
            return Err(format!("{part:?} is not finite"));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn date_parses_and_validates() {
        assert_eq!(
            "2024-02-29".parse(),
            Ok(Date {
                year: 2024,
                month: 2,
                day: 29
            })
        );
        assert_eq!(
            "2000-02-29".parse::<Date>().map(|d| d.to_string()),
            Ok("2000-02-29".into())
        );
        assert!(matches!(
            "1900-02-29".parse::<Date>(),
            Err(DateError::Day { .. })
        ));
        assert_eq!("2021-13-40".parse::<Date>(), Err(DateError::Month(13)));
        assert!(matches!(
            "2021-04-31".parse::<Date>(),
            Err(DateError::Day { .. })
        ));
        for bad in [
            "2021-1-01",
            "21-01-01",
            "2021/01/01",
            "2021-01-01x",
            "+021-01-01",
            "",
        ] {
            assert_eq!(bad.parse::<Date>(), Err(DateError::Format), "{bad}");
        }
        assert_eq!(Date::new(10000, 1, 1), Err(DateError::Year(10000)));
        assert_eq!(
            Date {
                year: 7,
                month: 3,
                day: 4
            }
            .to_string(),
            "0007-03-04"
        );
    }

    #[test]
    fn lines_are_classified() {
        assert!(matches!(
            classify_line("# magcal-recording v1"),
            MetaLine::Magic("v1")
        ));
        assert!(matches!(
            classify_line("#magcal-recording v2 "),
            MetaLine::Magic("v2")
        ));
        assert!(matches!(
            classify_line("# sensor:  lis3mdl "),
            MetaLine::Pair("sensor", "lis3mdl")
        ));
        assert!(matches!(
            classify_line("#   just a note"),
            MetaLine::Comment
        ));
        assert!(matches!(classify_line("#"), MetaLine::Comment));
        assert!(matches!(classify_line("# : no key"), MetaLine::Comment));
    }

    #[test]
    fn spreadsheet_padding_is_stripped() {
        assert!(matches!(
            classify_line("# magcal-recording v1,,,,,,"),
            MetaLine::Magic("v1")
        ));
        assert!(matches!(
            classify_line("# field_ned_ut: 19.8, 1.2, 45.3,,, "),
            MetaLine::Pair("field_ned_ut", "19.8, 1.2, 45.3")
        ));
        assert!(matches!(
            classify_line("# sensor: lis3mdl;;;\t"),
            MetaLine::Pair("sensor", "lis3mdl")
        ));
        let m = Metadata {
            routine: Some("a,".into()),
            ..Metadata::default()
        };
        assert!(m.check().is_err(), "would not read back");
    }

    #[test]
    fn serial_is_a_known_key_read_and_written() {
        let mut m = MetadataBuilder::default();
        m.set("serial", "SN-0042").unwrap();
        assert!(matches!(
            m.set("serial", "SN-0043"),
            Err(ReadErrorKind::DuplicateMetadata { .. })
        ));
        let m = m.finish();
        assert_eq!(m.serial.as_deref(), Some("SN-0042"));
        assert!(m.other.is_empty());
        assert!(
            m.pairs()
                .contains(&("serial".to_owned(), "SN-0042".to_owned()))
        );
        assert!(m.check().is_ok());
        let bad = Metadata {
            serial: Some(" padded".into()),
            ..Metadata::default()
        };
        assert!(bad.check().is_err());
    }

    #[test]
    fn typed_values_are_validated() {
        let mut m = MetadataBuilder::default();
        assert!(m.set("field_ned_ut", "1,2").is_err());
        assert!(m.set("field_ned_ut", "1,2,x").is_err());
        assert!(m.set("field_ned_ut", "1,2,inf").is_err());
        assert!(m.set("sample_rate_hz", "-5").is_err());
        assert!(m.set("sample_rate_hz", "0").is_err());
        assert!(m.set("sample_rate_hz", "NaN").is_err());
        assert!(m.set("location", "91, 0, 0").is_err());
        assert!(m.set("location", "0, 181, 0").is_err());
        assert!(m.set("s\rensor", "x").is_err());
        assert!(m.set("routine", "a\u{7}b").is_err());
        assert!(m.set("field_ned_ut", "1,2,1e308").is_err());
        assert!(m.set("sample_rate_hz", "1e300").is_err());
        m.set("location", "52.5, 13.3, 50").unwrap();
        m.set("field_ned_ut", " 19.8, 1.2 ,45.3").unwrap();
        assert_eq!(m.meta.field_ned_ut, Some([19.8, 1.2, 45.3]));
        assert!(matches!(
            m.set("location", "1,2,3"),
            Err(ReadErrorKind::DuplicateMetadata { .. })
        ));
        m.set("units", "uT").unwrap();
        assert!(matches!(
            m.set("units", "nT"),
            Err(ReadErrorKind::DuplicateMetadata { .. })
        ));
        let mut m = m.finish();
        assert!(m.check().is_ok());
        m.other.push(("units".into(), "x".into()));
        assert!(m.check().is_err(), "repeated");
        m.other.pop();
        m.other.push(("sensor".into(), "x".into()));
        assert!(m.check().is_err());
    }
}
