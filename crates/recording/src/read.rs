//! The reader: what the file is (text, not compressed or binary), metadata lines by hand, then the header and data
//! rows with the `csv` crate, parsed straight into the column vectors. Line ends (`\n`, `\r\n`, `\r`) are made one
//! on the way in; columns are separated by commas, or by `;` or tabs when the header row names `mx,my,mz` that way.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use csv::{ByteRecord, ReaderBuilder, Terminator};

use crate::error::{ColumnRef, ReadError, ReadErrorKind, excerpt};
use crate::layout::{Header, MAG, Role};
use crate::limits::{self, Limit};
use crate::line_ends::LineEnds;
use crate::metadata::{MetaLine, Metadata, MetadataBuilder, classify_line};
use crate::recording::Recording;
use crate::sample::{group_or_nan, normalise_quat};

/// Buffer size for reading; large enough that the per-read overhead does not show.
const BUFFER_BYTES: usize = 256 * 1024;

/// The UTF-8 byte order mark some editors put at the start of a file.
const BOM: &[u8] = b"\xef\xbb\xbf";

/// A problem in a data row: the 0-based column, if it is in one field, and what.
type RowProblem = (Option<usize>, ReadErrorKind);

impl Recording {
    /// Reads a recording from a file; errors name the file as given.
    pub fn read(path: &Path) -> Result<Recording, ReadError> {
        let name = path.display().to_string();
        match File::open(path) {
            Ok(file) => Recording::from_reader(&name, file),
            Err(e) => Err(ReadError::new(&name, None, None, ReadErrorKind::Io(e))),
        }
    }

    /// Reads a recording from any byte source; `name` stands for the file in errors.
    pub fn from_reader<R: Read>(name: &str, reader: R) -> Result<Recording, ReadError> {
        let mut raw = BufReader::with_capacity(BUFFER_BYTES, reader);
        let start = raw
            .fill_buf()
            .map_err(|e| ReadError::new(name, None, None, ReadErrorKind::Io(e)))?;
        if let Some(kind) = not_text(start) {
            return Err(ReadError::new(name, None, None, kind));
        }
        let mut input = BufReader::with_capacity(BUFFER_BYTES, LineEnds::new(raw));
        let (meta, header_text, header_line) = read_metadata(name, &mut input)?;
        let separator = separator(&header_text)
            .map_err(|kind| ReadError::new(name, Some(header_line), None, kind))?;
        // Counted before the csv reader splits the row, which would take memory for every name.
        let columns = column_count(&header_text, separator);
        if columns > limits::MAX_COLUMNS {
            let kind = ReadErrorKind::TooManyColumns {
                found: columns,
                max: limits::MAX_COLUMNS,
            };
            return Err(ReadError::new(name, Some(header_line), None, kind));
        }
        let column_ref = |names: &[String], i: usize| ColumnRef {
            index: i + 1,
            name: names[i].clone(),
        };

        // The csv reader starts at the header line. Only '\n' ends a row (every line end is one by now), and a final
        // '\n' is added so that every row, the last one too, ends with one: the reader's line count after a row is
        // then always one past the row's last line.
        let rest = io::Cursor::new(header_text).chain(input).chain(&b"\n"[..]);
        let mut csv = ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .delimiter(separator)
            .terminator(Terminator::Any(b'\n'))
            .buffer_capacity(BUFFER_BYTES)
            .from_reader(rest);
        let mut record = ByteRecord::new();
        let read_error =
            |e: csv::Error| ReadError::new(name, None, None, ReadErrorKind::Io(e.into()));

        csv.read_byte_record(&mut record).map_err(read_error)?;
        let mut names = Vec::with_capacity(record.len());
        for (i, field) in record.iter().enumerate() {
            let Ok(text) = std::str::from_utf8(field.trim_ascii()) else {
                let column = ColumnRef {
                    index: i + 1,
                    name: String::from_utf8_lossy(field).into_owned(),
                };
                return Err(ReadError::new(
                    name,
                    Some(header_line),
                    Some(column),
                    ReadErrorKind::InvalidUtf8,
                ));
            };
            names.push(text.to_owned());
        }
        let header = Header::parse(&names).map_err(|(column, kind)| {
            ReadError::new(
                name,
                Some(header_line),
                column.map(|i| column_ref(&names, i)),
                kind,
            )
        })?;

        let mut rows = RowParser {
            roles: &header.roles,
            padding: header.padding,
            decimal_comma_possible: separator != b',',
            out: Recording::empty(meta, &header.layout),
        };
        while csv.read_byte_record(&mut record).map_err(read_error)? {
            if let Err((column, kind)) = rows.push(&record) {
                // The row's first line: the csv reader has counted the row's own '\n' and any inside quotes.
                let breaks_inside =
                    record.as_slice().iter().filter(|b| **b == b'\n').count() as u64;
                let line = header_line + csv.position().line().saturating_sub(2 + breaks_inside);
                return Err(ReadError::new(
                    name,
                    Some(line),
                    column.map(|i| column_ref(&names, i)),
                    kind,
                ));
            }
        }
        if rows.out.is_empty() {
            return Err(ReadError::new(name, None, None, ReadErrorKind::NoData));
        }
        Ok(rows.out)
    }
}

/// Reads the metadata block line by line, up to and including the header line. Returns the metadata, the
/// header line (without a byte order mark) and its 1-based line number.
fn read_metadata(
    name: &str,
    input: &mut impl BufRead,
) -> Result<(Metadata, Vec<u8>, u64), ReadError> {
    let at = |line: Option<u64>, kind: ReadErrorKind| ReadError::new(name, line, None, kind);
    let mut meta = MetadataBuilder::default();
    let mut line: Vec<u8> = Vec::new();
    let mut line_no: u64 = 0;
    let mut seen_content = false;
    loop {
        line.clear();
        let n = input
            .read_until(b'\n', &mut line)
            .map_err(|e| at(None, ReadErrorKind::Io(e)))?;
        if n == 0 {
            let kind = if seen_content {
                ReadErrorKind::MissingHeader { data_first: false }
            } else {
                ReadErrorKind::Empty
            };
            return Err(at(None, kind));
        }
        line_no += 1;
        if line_no == 1 && line.starts_with(BOM) {
            line.drain(..BOM.len());
        }
        let text = line.trim_ascii();
        if text.is_empty() {
            continue;
        }
        seen_content = true;
        if !text.starts_with(b"#") {
            return Ok((meta.finish(), line, line_no));
        }
        let text =
            std::str::from_utf8(text).map_err(|_| at(Some(line_no), ReadErrorKind::InvalidUtf8))?;
        match classify_line(text) {
            MetaLine::Magic(version) if version != "v1" => {
                let found = excerpt(version);
                return Err(at(
                    Some(line_no),
                    ReadErrorKind::UnsupportedVersion { found },
                ));
            }
            MetaLine::Pair(key, value) => meta
                .set(key, value)
                .map_err(|kind| at(Some(line_no), kind))?,
            MetaLine::Magic(_) | MetaLine::Comment => {}
        }
    }
}

/// The signatures of compressed files, and what they are.
const COMPRESSED: [(&[u8], &str); 5] = [
    (b"\x1f\x8b", "gzip"),
    (b"BZh", "bzip2"),
    (b"\xfd7zXZ\x00", "xz"),
    (b"\x28\xb5\x2f\xfd", "zstd"),
    (b"PK\x03\x04", "zip"),
];

/// Why the start of a file shows it is no text recording: compressed, UTF-16 or binary.
fn not_text(start: &[u8]) -> Option<ReadErrorKind> {
    if let Some((_, format)) = COMPRESSED
        .iter()
        .find(|(magic, _)| start.starts_with(magic))
    {
        return Some(ReadErrorKind::Compressed { format });
    }
    if start.starts_with(b"\xff\xfe") || start.starts_with(b"\xfe\xff") {
        return Some(ReadErrorKind::Utf16);
    }
    let nul = start.iter().position(|b| *b == 0)?;
    Some(ReadErrorKind::Binary { offset: nul as u64 })
}

/// The column separator of a file: the first of `,`, `;` and tab by which the header row names `mx`, `my` and `mz`
/// (any case); a comma if none does, unless the row has no comma and a `;` or a tab, which is an error naming it.
fn separator(header: &[u8]) -> Result<u8, ReadErrorKind> {
    let names_mag = |separator: u8| {
        let mut found = [false; 3];
        for field in header.split(|b| *b == separator) {
            let field = field.trim_ascii();
            if let Some(k) = MAG
                .iter()
                .position(|m| field.eq_ignore_ascii_case(m.as_bytes()))
            {
                found[k] = true;
                if found.iter().all(|f| *f) {
                    return true;
                }
            }
        }
        false
    };
    if let Some(s) = [b',', b';', b'\t'].into_iter().find(|s| names_mag(*s)) {
        return Ok(s);
    }
    if !header.contains(&b',')
        && let Some(s) = [b';', b'\t'].into_iter().find(|s| header.contains(s))
    {
        return Err(ReadErrorKind::Separator {
            separator: char::from(s),
        });
    }
    Ok(b',')
}

/// The number of fields of a CSV line: separators outside quotes, plus one.
fn column_count(line: &[u8], separator: u8) -> usize {
    let mut quoted = false;
    let mut n = 1;
    for &b in line {
        if b == b'"' {
            quoted = !quoted;
        } else if b == separator && !quoted {
            n += 1;
        }
    }
    n
}

/// Parses data rows into the columns of a recording.
struct RowParser<'h> {
    roles: &'h [Role],
    /// Empty fields a row may have after the header's last column (see [`Header::padding`]).
    padding: usize,
    /// Columns are not separated by commas, so `1,5` may be a number written with a decimal comma.
    decimal_comma_possible: bool,
    out: Recording,
}

impl RowParser<'_> {
    /// A numeric field: NaN when empty or `nan` (any case, any sign).
    fn number(&self, text: &str) -> Result<f64, ReadErrorKind> {
        if text.is_empty() {
            return Ok(f64::NAN);
        }
        text.parse().map_err(|_| {
            if self.decimal_comma_possible && text.replace(',', ".").parse::<f64>().is_ok() {
                ReadErrorKind::DecimalComma(excerpt(text))
            } else {
                ReadErrorKind::NotANumber(excerpt(text))
            }
        })
    }
}

/// `value` if it is within `limit`; an out-of-range error quoting `text` otherwise.
fn within(text: &str, value: f64, limit: Limit) -> Result<f64, ReadErrorKind> {
    if limit.exceeded_by(value) {
        return Err(ReadErrorKind::OutOfRange {
            value: excerpt(text),
            limit: limit.max,
            unit: limit.unit,
        });
    }
    Ok(value)
}

impl RowParser<'_> {
    /// Checks one record and appends it; blank lines (and rows of empty fields only) are skipped.
    fn push(&mut self, record: &ByteRecord) -> Result<(), RowProblem> {
        let expected = self.roles.len();
        let found = record.len();
        let first = record.get(0).unwrap_or_default().trim_ascii();
        if first.is_empty() && record.iter().all(|f| f.trim_ascii().is_empty()) {
            return Ok(());
        }
        if first.starts_with(b"#") {
            return Err((None, ReadErrorKind::LineAfterHeader));
        }
        if found < expected {
            return Err((None, ReadErrorKind::ShortRow { expected, found }));
        }
        let padded = found <= expected + self.padding
            && record
                .iter()
                .skip(expected)
                .all(|f| f.trim_ascii().is_empty());
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
        for (k, (field, role)) in record.iter().zip(self.roles).enumerate() {
            let at = |kind: ReadErrorKind| (Some(k), kind);
            let numeric = || -> Result<(&str, f64), RowProblem> {
                let text = std::str::from_utf8(field.trim_ascii())
                    .map_err(|_| at(ReadErrorKind::InvalidUtf8))?;
                Ok((text, self.number(text).map_err(at)?))
            };
            let optional = |limit: Limit| -> Result<f64, RowProblem> {
                let (text, value) = numeric()?;
                if value.is_infinite() {
                    return Err(at(ReadErrorKind::Infinite(excerpt(text))));
                }
                within(text, value, limit).map_err(at)
            };
            match *role {
                Role::Time => {
                    let (text, value) = numeric()?;
                    if !value.is_finite() {
                        return Err(at(ReadErrorKind::NonFiniteTime(excerpt(text))));
                    }
                    t_s = within(text, value, limits::TIME).map_err(at)?;
                    time_column = k;
                }
                Role::Mag(a) => {
                    let (text, value) = numeric()?;
                    if text.is_empty() {
                        return Err(at(ReadErrorKind::EmptyMag));
                    }
                    if !value.is_finite() {
                        return Err(at(ReadErrorKind::NonFiniteMag(excerpt(text))));
                    }
                    mag_ut[a] = within(text, value, limits::FIELD).map_err(at)?;
                }
                Role::Temp => temp_c = optional(limits::TEMP)?,
                Role::Quat(a) => quat[a] = optional(limits::UNBOUNDED)?,
                Role::Ref(a) => ref_ut[a] = optional(limits::FIELD)?,
                Role::Gyro(a) => gyro_rad_s[a] = optional(limits::GYRO)?,
                Role::Current(j) => {
                    let value = optional(limits::CURRENT)?;
                    self.out.currents[j].values.push(value);
                }
                Role::Extra(j) => {
                    let text =
                        std::str::from_utf8(field).map_err(|_| at(ReadErrorKind::InvalidUtf8))?;
                    self.out.extra[j].values.push(text.to_owned());
                }
            }
        }

        let out = &mut self.out;
        if let Some(t) = &mut out.t_s {
            if let Some(&previous_s) = t.last()
                && t_s < previous_s
            {
                return Err((
                    Some(time_column),
                    ReadErrorKind::TimeBackwards { previous_s, t_s },
                ));
            }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_counted_outside_quotes() {
        assert_eq!(column_count(b"mx,my,mz", b','), 3);
        assert_eq!(column_count(b"mx,\"a,b\",mz,\"say \"\"x,y\"\"\"", b','), 4);
        assert_eq!(column_count(b"mx;my;mz,x", b';'), 3);
    }

    #[test]
    fn a_header_of_more_columns_than_a_recording_has_is_refused() {
        let mut text = b"mx,my,mz".to_vec();
        for i in 0..limits::MAX_COLUMNS {
            text.extend(format!(",c{i}").as_bytes());
        }
        text.extend(b"\n1,2,3\n");
        let err = Recording::from_reader("wide.csv", &text[..]).unwrap_err();
        assert!(matches!(
            err.kind(),
            ReadErrorKind::TooManyColumns { found, .. } if *found == limits::MAX_COLUMNS + 3
        ));
        assert_eq!(err.line(), Some(1));
    }
}
