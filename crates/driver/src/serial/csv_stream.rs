//! The native CSV line stream: the magcal-recording v1 columns, sent live.
//!
//! Firmware may first print comment lines (`# key: value` lines are kept as metadata, as in a
//! recording's header), then one header line naming its columns, then data lines:
//!
//! ```text
//! # sensor: qmc5883l
//! t,mx,my,mz,temp,gx,gy,gz,i_coil
//! 0.010,24.1,-33.7,-38.9,24.7,-0.19,-0.11,-0.11,0.25
//! ```
//!
//! Columns are those of magcal-recording v1: `t` (s), `mx,my,mz` (µT, required), `temp` (°C),
//! `qw,qx,qy,qz` (attitude quaternion), `gx,gy,gz` (rad/s), and any number of `i_<name>`
//! auxiliary channels, in any order. The groups `mx..mz`, `qw..qz` and `gx..gz` come whole.
//! A missing value is an empty field or `nan` (NaN in the [`Sample`]); the field itself must
//! not be missing.
//!
//! A valid header sets the columns; a later valid header (the board reset, perhaps with other
//! firmware) replaces them, and the lines after it are read by the new one. A header line that
//! names `mx,my,mz` but breaks the rules above is [`GarbageKind::BadHeader`] and changes nothing.
//! After the header, a line of numbers with the wrong field count is [`GarbageKind::FieldCount`]
//! (a half line), one with text in it [`GarbageKind::Unrecognized`] (other chatter).

use super::counts::GarbageKind;
use super::sample::Sample;

/// Column positions of a valid header.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Columns {
    /// The header line's fields, to recognise a repeat.
    names: Vec<String>,
    t: Option<usize>,
    mag: [usize; 3],
    temp: Option<usize>,
    quat: Option<[usize; 4]>,
    gyro: Option<[usize; 3]>,
    /// `(name without the i_ prefix, position)`.
    inputs: Vec<(String, usize)>,
}

const INPUT_PREFIX: &str = "i_";

fn is_input_name(name: &str) -> bool {
    !name.is_empty() && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
}

impl Columns {
    /// `None` when `fields` is no header at all (it does not name `mx`, `my` and `mz`);
    /// `Some(Err(BadHeader))` when it tries to be one and fails.
    fn parse(fields: &[&str]) -> Option<Result<Columns, GarbageKind>> {
        let find = |name: &str| fields.iter().position(|f| *f == name);
        let mag = [find("mx")?, find("my")?, find("mz")?];
        Some(Self::from_named(fields, mag).ok_or(GarbageKind::BadHeader))
    }

    fn from_named(fields: &[&str], mag: [usize; 3]) -> Option<Columns> {
        let find = |name: &str| fields.iter().position(|f| *f == name);
        let group = |names: &[&str]| -> Option<Option<Vec<usize>>> {
            let found: Vec<Option<usize>> = names.iter().map(|n| find(n)).collect();
            if found.iter().all(Option::is_none) {
                Some(None)
            } else {
                found.into_iter().collect::<Option<Vec<_>>>().map(Some)
            }
        };
        let quat = group(&["qw", "qx", "qy", "qz"])?.map(|v| [v[0], v[1], v[2], v[3]]);
        let gyro = group(&["gx", "gy", "gz"])?.map(|v| [v[0], v[1], v[2]]);
        let mut inputs = Vec::new();
        for (i, name) in fields.iter().enumerate() {
            if fields[..i].contains(name) {
                return None;
            }
            if let Some(input) = name.strip_prefix(INPUT_PREFIX) {
                if !is_input_name(input) {
                    return None;
                }
                inputs.push((input.to_string(), i));
            } else if !matches!(
                *name,
                "t" | "mx" | "my" | "mz" | "temp" | "qw" | "qx" | "qy" | "qz" | "gx" | "gy" | "gz"
            ) {
                return None;
            }
        }
        Some(Columns {
            names: fields.iter().map(|f| f.to_string()).collect(),
            t: find("t"),
            mag,
            temp: find("temp"),
            quat,
            gyro,
            inputs,
        })
    }
}

/// What a CSV line was.
#[derive(Clone, Debug, PartialEq)]
pub enum CsvLine {
    /// A data line.
    Sample(Sample),
    /// A header (the first, a repeat, or a new one that replaces it).
    Header,
    /// A `#` comment; `# key: value` comments are also kept as [`CsvStream::metadata`].
    Comment,
}

/// Parser state of one native CSV stream: its header and metadata.
#[derive(Clone, Debug, Default)]
pub struct CsvStream {
    columns: Option<Columns>,
    metadata: Vec<(String, String)>,
}

/// A value field: a number, or NaN when empty or `nan`.
fn optional_value(field: &str) -> Option<f64> {
    let field = field.trim();
    if field.is_empty() || field.eq_ignore_ascii_case("nan") {
        return Some(f64::NAN);
    }
    field.parse().ok()
}

impl CsvStream {
    /// A stream that has seen nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Whether a header has been seen.
    pub fn has_header(&self) -> bool {
        self.columns.is_some()
    }

    /// Names of the `i_<name>` columns (without the `i_` prefix), in the order of
    /// [`Sample::inputs`]; empty before the header.
    pub fn input_names(&self) -> Vec<&str> {
        self.columns
            .iter()
            .flat_map(|c| c.inputs.iter().map(|(name, _)| name.as_str()))
            .collect()
    }

    /// `(key, value)` of every `# key: value` comment seen, in order.
    pub fn metadata(&self) -> &[(String, String)] {
        &self.metadata
    }

    /// Parses one line (without its terminator).
    pub fn parse_line(&mut self, line: &str) -> Result<CsvLine, GarbageKind> {
        if let Some(comment) = line.strip_prefix('#') {
            if let Some((key, value)) = comment.split_once(':') {
                let key = key.trim();
                if !key.is_empty() && !key.contains(char::is_whitespace) {
                    self.metadata
                        .push((key.to_string(), value.trim().to_string()));
                }
            }
            return Ok(CsvLine::Comment);
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if let Some(header) = Columns::parse(&fields) {
            self.columns = Some(header?);
            return Ok(CsvLine::Header);
        }
        let numeric = fields.iter().all(|f| optional_value(f).is_some());
        let columns = match &self.columns {
            Some(columns) => columns,
            None if numeric => return Err(GarbageKind::NoHeader),
            None => return Err(GarbageKind::Unrecognized),
        };
        if fields.len() != columns.names.len() {
            return Err(if numeric {
                GarbageKind::FieldCount
            } else {
                GarbageKind::Unrecognized
            });
        }
        let values = fields
            .iter()
            .map(|f| optional_value(f))
            .collect::<Option<Vec<f64>>>()
            .ok_or(GarbageKind::BadNumber)?;
        let mag_ut = columns.mag.map(|i| values[i]);
        if !mag_ut.iter().all(|v| v.is_finite()) {
            return Err(GarbageKind::BadNumber);
        }
        Ok(CsvLine::Sample(Sample {
            t_s: columns.t.map(|i| values[i]),
            mag_ut,
            accel_g: None,
            gyro_rad_s: columns.gyro.map(|g| g.map(|i| values[i])),
            temp_c: columns.temp.map(|i| values[i]),
            quat_wxyz: columns.quat.map(|q| q.map(|i| values[i])),
            inputs: columns.inputs.iter().map(|&(_, i)| values[i]).collect(),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(stream: &mut CsvStream, line: &str) -> Sample {
        match stream.parse_line(line) {
            Ok(CsvLine::Sample(s)) => s,
            other => panic!("{line:?} gave {other:?}"),
        }
    }

    #[test]
    fn full_header_maps_every_column() {
        let mut s = CsvStream::new();
        assert_eq!(s.parse_line("# sensor: hmc5883l"), Ok(CsvLine::Comment));
        assert_eq!(s.parse_line("# a comment"), Ok(CsvLine::Comment));
        assert_eq!(
            s.parse_line("i_coil,t,mx,my,mz,temp,qw,qx,qy,qz,gx,gy,gz,i_motor_2"),
            Ok(CsvLine::Header)
        );
        assert_eq!(s.input_names(), ["coil", "motor_2"]);
        assert_eq!(
            s.metadata(),
            [("sensor".to_string(), "hmc5883l".to_string())]
        );
        let x = sample(&mut s, "0.5,1.25,10,-20,30,24.5,1,0,0,0,0.1,0.2,0.3,-1");
        assert_eq!(x.t_s, Some(1.25));
        assert_eq!(x.mag_ut, [10.0, -20.0, 30.0]);
        assert_eq!(x.temp_c, Some(24.5));
        assert_eq!(x.quat_wxyz, Some([1.0, 0.0, 0.0, 0.0]));
        assert_eq!(x.gyro_rad_s, Some([0.1, 0.2, 0.3]));
        assert_eq!(x.inputs, [0.5, -1.0]);
        assert_eq!(x.accel_g, None);
    }

    #[test]
    fn minimal_header_and_missing_values() {
        let mut s = CsvStream::new();
        assert_eq!(s.parse_line("mz,my,mx"), Ok(CsvLine::Header));
        let x = sample(&mut s, "3,2,1");
        assert_eq!(x, Sample::mag_only([1.0, 2.0, 3.0]));
        s = CsvStream::new();
        s.parse_line("t,mx,my,mz,gx,gy,gz").unwrap();
        let x = sample(&mut s, ",1,2,3,nan,,0.5");
        assert!(x.t_s.unwrap().is_nan());
        let g = x.gyro_rad_s.unwrap();
        assert!(g[0].is_nan() && g[1].is_nan() && g[2] == 0.5);
    }

    #[test]
    fn garbage_is_classified() {
        let mut s = CsvStream::new();
        assert_eq!(s.parse_line("1,2,3"), Err(GarbageKind::NoHeader));
        assert_eq!(s.parse_line("hello there"), Err(GarbageKind::Unrecognized));
        for bad_header in [
            "mx,my,mz,ax",
            "mx,my,mz,qw,qx",
            "mx,my,mz,mx",
            "mx,my,mz,i_",
            "mx,my,mz,i_a b",
        ] {
            assert_eq!(
                s.parse_line(bad_header),
                Err(GarbageKind::BadHeader),
                "{bad_header}"
            );
        }
        assert!(!s.has_header());
        s.parse_line("t,mx,my,mz").unwrap();
        assert_eq!(
            s.parse_line("t,mx,my,mz"),
            Ok(CsvLine::Header),
            "repeat after a reset"
        );
        assert_eq!(s.parse_line("0.1,1,2"), Err(GarbageKind::FieldCount));
        assert_eq!(s.parse_line("0.1,1,2,3,4"), Err(GarbageKind::FieldCount));
        assert_eq!(
            s.parse_line("Wrote calibration"),
            Err(GarbageKind::Unrecognized)
        );
        assert_eq!(s.parse_line("0.1,1,x,3"), Err(GarbageKind::BadNumber));
        assert_eq!(s.parse_line("0.1,1,nan,3"), Err(GarbageKind::BadNumber));
        assert_eq!(s.parse_line("0.1,1,inf,3"), Err(GarbageKind::BadNumber));
        assert_eq!(sample(&mut s, " 0.1 , 1 ,2,3").mag_ut, [1.0, 2.0, 3.0]);
    }

    #[test]
    fn a_new_header_replaces_the_columns() {
        let mut s = CsvStream::new();
        s.parse_line("t,mx,my,mz").unwrap();
        assert_eq!(sample(&mut s, "5,1,2,3").t_s, Some(5.0));
        assert_eq!(
            s.parse_line("mz,my,mx,i_coil"),
            Ok(CsvLine::Header),
            "a reset board's new firmware"
        );
        let x = sample(&mut s, "3,2,1,0.5");
        assert_eq!(
            (x.t_s, x.mag_ut, x.inputs),
            (None, [1.0, 2.0, 3.0], vec![0.5])
        );
        assert_eq!(s.input_names(), ["coil"]);
        assert_eq!(s.parse_line("mx,my,mz,qw"), Err(GarbageKind::BadHeader));
        assert_eq!(
            sample(&mut s, "3,2,1,0.25").inputs,
            [0.25],
            "a bad header changes nothing"
        );
    }
}
