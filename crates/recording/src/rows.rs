//! One data row, checked and appended to the columns of a recording: what a row must hold, whichever way its line
//! was split into fields (by hand on the fast path, by the `csv` crate where a file has quotes).

use csv::ByteRecord;

use crate::decimal;
use crate::error::{ReadErrorKind, excerpt};
use crate::layout::Role;
use crate::limits::{self, Limit};
use crate::recording::Recording;
use crate::sample::{group_or_nan, normalise_quat};

/// A problem in a data row: the 0-based column, if it is in one field, and what.
pub(crate) type RowProblem = (Option<usize>, ReadErrorKind);

/// The fields of one row, however it was split.
pub(crate) trait Fields {
    /// Number of fields.
    fn len(&self) -> usize;
    /// Field `i` (`i < len()`), as in the file (not trimmed).
    fn get(&self, i: usize) -> &[u8];
}

impl Fields for ByteRecord {
    fn len(&self) -> usize {
        ByteRecord::len(self)
    }

    fn get(&self, i: usize) -> &[u8] {
        ByteRecord::get(self, i).unwrap_or_default()
    }
}

/// A line without quotes split at a separator, reusing its buffer of field ends from line to line.
#[derive(Debug, Default)]
pub(crate) struct SplitLine<'a> {
    line: &'a [u8],
    /// Where each field ends (the separator's index, or the line's length for the last).
    ends: Vec<usize>,
}

impl<'a> SplitLine<'a> {
    /// Splits `line` (without its line end) at every `separator`.
    pub(crate) fn split(&mut self, line: &'a [u8], separator: u8) {
        self.line = line;
        self.ends.clear();
        self.ends.extend(memchr::memchr_iter(separator, line));
        self.ends.push(line.len());
    }
}

impl Fields for SplitLine<'_> {
    fn len(&self) -> usize {
        self.ends.len()
    }

    fn get(&self, i: usize) -> &[u8] {
        let start = if i == 0 { 0 } else { self.ends[i - 1] + 1 };
        &self.line[start..self.ends[i]]
    }
}

/// Checks data rows and appends them to the columns of a recording.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RowParser<'h> {
    pub roles: &'h [Role],
    /// Empty fields a row may have after the header's last column (see [`crate::layout::Header::padding`]).
    pub padding: usize,
    /// Columns are not separated by commas, so `1,5` may be a number written with a decimal comma.
    pub decimal_comma_possible: bool,
}

/// What a run of rows needs to know of the rows before it, and tells about its own first row.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct TimeLink {
    /// `t` of the last row appended before (none at the start of the file, or where it is not known yet).
    pub previous_s: Option<f64>,
    /// `t` of the first row that reached the time check without a previous row to check it against.
    pub first_unchecked_s: Option<f64>,
}

impl RowParser<'_> {
    /// A numeric field (trimmed): NaN when empty or `nan` (any case, any sign). Decimal numbers are parsed by
    /// `fast-float2`; anything else (`inf`, `nan`, a sign alone, errors) by the standard library, which decides what
    /// is accepted.
    fn number(&self, field: &[u8]) -> Result<f64, ReadErrorKind> {
        if field.is_empty() {
            return Ok(f64::NAN);
        }
        let digits = match field[0] {
            b'-' | b'+' => &field[1..],
            _ => field,
        };
        if digits
            .first()
            .is_some_and(|b| b.is_ascii_digit() || *b == b'.')
            && let Ok(value) = fast_float2::parse::<f64, _>(field)
        {
            return Ok(value);
        }
        let text = std::str::from_utf8(field).map_err(|_| ReadErrorKind::InvalidUtf8)?;
        text.parse().map_err(|_| {
            if self.decimal_comma_possible && text.replace(',', ".").parse::<f64>().is_ok() {
                ReadErrorKind::DecimalComma(excerpt(text))
            } else {
                ReadErrorKind::NotANumber(excerpt(text))
            }
        })
    }

    /// Checks one row and appends it to `out`; blank lines (and rows of empty fields only) are skipped. `time`
    /// carries `t` from row to row.
    pub(crate) fn push(
        &self,
        record: &impl Fields,
        out: &mut Recording,
        time: &mut TimeLink,
    ) -> Result<(), RowProblem> {
        let expected = self.roles.len();
        let found = record.len();
        let empty = |i: usize| record.get(i).trim_ascii().is_empty();
        let first = record.get(0).trim_ascii();
        if first.is_empty() && (1..found).all(empty) {
            return Ok(());
        }
        if first.starts_with(b"#") {
            return Err((None, ReadErrorKind::LineAfterHeader));
        }
        if found < expected {
            return Err((None, ReadErrorKind::ShortRow { expected, found }));
        }
        let padded = found <= expected + self.padding && (expected..found).all(empty);
        if found > expected && !padded {
            return Err((None, ReadErrorKind::LongRow { expected, found }));
        }

        let mut t_s = f64::NAN;
        let mut mag_ut = [f64::NAN; 3];
        let mut temp_c = f64::NAN;
        let mut quat = [f64::NAN; 4];
        let mut ref_ut = [f64::NAN; 3];
        let mut gyro_rad_s = [f64::NAN; 3];
        let mut time_column = 0;
        for (k, role) in self.roles.iter().enumerate() {
            let field = record.get(k);
            let at = |kind: ReadErrorKind| (Some(k), kind);
            let trimmed = field.trim_ascii();
            let numeric = || self.number(trimmed).map_err(at);
            // The field as text, for messages (valid UTF-8: it parsed, or the error would have said otherwise).
            let text = || String::from_utf8_lossy(trimmed);
            let optional = |limit: Limit| -> Result<f64, RowProblem> {
                let value = numeric()?;
                if value.is_infinite() {
                    return Err(at(ReadErrorKind::Infinite(excerpt(&text()))));
                }
                within(&text, value, limit).map_err(at)
            };
            match *role {
                Role::Time => {
                    let value = numeric()?;
                    if !value.is_finite() {
                        return Err(at(ReadErrorKind::NonFiniteTime(excerpt(&text()))));
                    }
                    t_s = within(&text, value, limits::TIME).map_err(at)?;
                    time_column = k;
                }
                Role::Mag(a) => {
                    let value = numeric()?;
                    if trimmed.is_empty() {
                        return Err(at(ReadErrorKind::EmptyMag));
                    }
                    if !value.is_finite() {
                        return Err(at(ReadErrorKind::NonFiniteMag(excerpt(&text()))));
                    }
                    mag_ut[a] = within(&text, value, limits::FIELD).map_err(at)?;
                }
                Role::Temp => temp_c = optional(limits::TEMP)?,
                Role::Quat(a) => quat[a] = optional(limits::UNBOUNDED)?,
                Role::Ref(a) => ref_ut[a] = optional(limits::FIELD)?,
                Role::Gyro(a) => gyro_rad_s[a] = optional(limits::GYRO)?,
                Role::Current(j) => {
                    let value = optional(limits::CURRENT)?;
                    out.currents[j].values.push(value);
                }
                Role::Extra(j) => {
                    let text =
                        std::str::from_utf8(field).map_err(|_| at(ReadErrorKind::InvalidUtf8))?;
                    out.extra[j].values.push(text.to_owned());
                }
            }
        }

        if let Some(t) = &mut out.t_s {
            match time.previous_s {
                Some(previous_s) if t_s < previous_s => {
                    return Err((
                        Some(time_column),
                        ReadErrorKind::TimeBackwards { previous_s, t_s },
                    ));
                }
                Some(_) => {}
                None => time.first_unchecked_s = Some(t_s),
            }
            time.previous_s = Some(t_s);
            t.push(t_s);
        }
        out.mag_ut.push(mag_ut);
        if let Some(temp) = &mut out.temp_c {
            temp.push(temp_c);
        }
        if let Some(q) = &mut out.quat {
            let quat = group_or_nan(quat);
            if quat[0].is_nan() {
                q.push(quat);
            } else {
                q.push(
                    normalise_quat(quat)
                        .map_err(|norm| (None, ReadErrorKind::QuatNotUnit { norm }))?,
                );
            }
        }
        if let Some(r) = &mut out.ref_ut {
            r.push(group_or_nan(ref_ut));
        }
        if let Some(g) = &mut out.gyro_rad_s {
            g.push(group_or_nan(gyro_rad_s));
        }
        Ok(())
    }
}

impl RowParser<'_> {
    /// The fast path for a plain row: every numeric field a decimal number or empty, nothing to trim, exactly as
    /// many fields as the header, every value within its limits, `t` not going backwards, a unit quaternion. Appends
    /// it and returns true; returns false, with `out` and `time` as they were, for anything else, which
    /// [`RowParser::push`] then reads (and refuses or accepts alike).
    pub(crate) fn push_plain(
        &self,
        line: &[u8],
        separator: u8,
        out: &mut Recording,
        time: &mut TimeLink,
    ) -> bool {
        let mut t_s = f64::NAN;
        let mut mag_ut = [f64::NAN; 3];
        let mut temp_c = f64::NAN;
        let mut quat = [f64::NAN; 4];
        let mut ref_ut = [f64::NAN; 3];
        let mut gyro_rad_s = [f64::NAN; 3];
        // Current and text columns are appended as they are read, and cut back if the row is not plain after all.
        let rows = out.mag_ut.len();
        let give_up = |out: &mut Recording| {
            out.currents
                .iter_mut()
                .for_each(|c| c.values.truncate(rows));
            out.extra.iter_mut().for_each(|c| c.values.truncate(rows));
            false
        };
        let last = self.roles.len() - 1;
        let mut pos = 0;
        for (k, role) in self.roles.iter().enumerate() {
            // The field ends at a separator, or at the line's end for the last one.
            let at_end = |end: usize| {
                if k == last {
                    end == line.len()
                } else {
                    line.get(end) == Some(&separator)
                }
            };
            let value = if let Role::Extra(j) = role {
                let end = memchr::memchr(separator, &line[pos..]).map_or(line.len(), |i| pos + i);
                let Ok(text) = std::str::from_utf8(&line[pos..end]) else {
                    return give_up(out);
                };
                if !at_end(end) {
                    return give_up(out);
                }
                out.extra[*j].values.push(text.to_owned());
                pos = end;
                f64::NAN
            } else if at_end(pos) {
                f64::NAN
            } else {
                let rest = &line[pos..];
                let digits = match rest.first() {
                    Some(b'-' | b'+') => &rest[1..],
                    _ => rest,
                };
                if !digits
                    .first()
                    .is_some_and(|b| b.is_ascii_digit() || *b == b'.')
                {
                    return give_up(out);
                }
                let parsed = decimal::parse_plain(rest)
                    .or_else(|| fast_float2::parse_partial::<f64, _>(rest).ok());
                let Some((value, used)) = parsed else {
                    return give_up(out);
                };
                pos += used;
                if !at_end(pos) || !value.is_finite() {
                    return give_up(out);
                }
                value
            };
            let limit = match *role {
                Role::Time => {
                    t_s = value;
                    limits::TIME
                }
                Role::Mag(a) => {
                    mag_ut[a] = value;
                    limits::FIELD
                }
                Role::Temp => {
                    temp_c = value;
                    limits::TEMP
                }
                Role::Quat(a) => {
                    quat[a] = value;
                    limits::UNBOUNDED
                }
                Role::Ref(a) => {
                    ref_ut[a] = value;
                    limits::FIELD
                }
                Role::Gyro(a) => {
                    gyro_rad_s[a] = value;
                    limits::GYRO
                }
                Role::Current(j) => {
                    out.currents[j].values.push(value);
                    limits::CURRENT
                }
                Role::Extra(_) => limits::UNBOUNDED,
            };
            if limit.exceeded_by(value) {
                return give_up(out);
            }
            pos += 1;
        }
        // Required values present, t in order, a quaternion of unit length.
        if mag_ut.iter().any(|v| v.is_nan()) || (out.t_s.is_some() && t_s.is_nan()) {
            return give_up(out);
        }
        if let Some(previous_s) = time.previous_s
            && out.t_s.is_some()
            && t_s < previous_s
        {
            return give_up(out);
        }
        let quat = group_or_nan(quat);
        let quat = if quat[0].is_nan() {
            quat
        } else {
            match normalise_quat(quat) {
                Ok(q) => q,
                Err(_) => return give_up(out),
            }
        };

        if let Some(t) = &mut out.t_s {
            if time.previous_s.is_none() {
                time.first_unchecked_s = Some(t_s);
            }
            time.previous_s = Some(t_s);
            t.push(t_s);
        }
        out.mag_ut.push(mag_ut);
        if let Some(temp) = &mut out.temp_c {
            temp.push(temp_c);
        }
        if let Some(q) = &mut out.quat {
            q.push(quat);
        }
        if let Some(r) = &mut out.ref_ut {
            r.push(group_or_nan(ref_ut));
        }
        if let Some(g) = &mut out.gyro_rad_s {
            g.push(group_or_nan(gyro_rad_s));
        }
        true
    }
}

/// `value` if it is within `limit`; an out-of-range error quoting the field's text otherwise.
fn within<'t>(
    text: &impl Fn() -> std::borrow::Cow<'t, str>,
    value: f64,
    limit: Limit,
) -> Result<f64, ReadErrorKind> {
    if limit.exceeded_by(value) {
        return Err(ReadErrorKind::OutOfRange {
            value: excerpt(&text()),
            limit: limit.max,
            unit: limit.unit,
            hint: limit.hint,
        });
    }
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_parse_as_the_standard_library_parses_them() {
        let parser = RowParser {
            roles: &[],
            padding: 0,
            decimal_comma_possible: false,
        };
        let cases = [
            "0",
            "-0",
            "+1",
            "1.",
            ".5",
            "-.5",
            "+.5e3",
            "1e5",
            "1E-5",
            "1e+5",
            "1e",
            "1e+",
            "e5",
            ".",
            "-",
            "+",
            "1.2.3",
            "0x10",
            "1_0",
            "inf",
            "-inf",
            "+Infinity",
            "infinity",
            "infx",
            "nan",
            "NaN",
            "-nan",
            "+nan",
            "nan(1)",
            "1e400",
            "-1e400",
            "1e-400",
            "4.9e-324",
            "2.2250738585072014e-308",
            "179769313486231570000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
             000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
             000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
             00000000000000",
            "0.1000000000000000055511151231257827021181583404541015625",
            "9007199254740993",
            "00012.5000",
            "12.345",
            "1,5",
            " 1",
            "1 ",
            "--1",
            "+-1",
            "1e1.5",
            "1.5e05",
        ];
        for text in cases {
            let ours = parser.number(text.as_bytes());
            let std = text.parse::<f64>();
            match (ours, std) {
                (Ok(a), Ok(b)) => {
                    assert!(
                        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                        "{text}: {a} vs {b}"
                    )
                }
                (Err(_), Err(_)) => {}
                (a, b) => panic!("{text:?}: {a:?} vs {b:?}"),
            }
        }
    }
}
