//! The reader: what the file is (text, not compressed or binary), metadata lines by hand, the header row with the
//! `csv` crate, then the data rows on both cores ([`crate::blocks`]), parsed straight into the column vectors. Line
//! ends (`\n`, `\r\n`, `\r`) are made one on the way in; columns are separated by commas, or by `;` or tabs when the
//! header row names `mx,my,mz` that way.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use csv::ByteRecord;

use crate::blocks::{Rows, Split, csv_reader};
use crate::error::{CUT_OFF, ColumnRef, ReadError, ReadErrorKind, excerpt, header_as_read};
use crate::layout::{Header, MAG, Role};
use crate::limits;
use crate::line_ends::LineEnds;
use crate::metadata::{MetaLine, Metadata, MetadataBuilder, classify_line};
use crate::recording::Recording;
use crate::rows::RowParser;

/// Buffer size for reading the start of a file (its kind, the metadata).
const BUFFER_BYTES: usize = 256 * 1024;

/// The UTF-8 byte order mark some editors put at the start of a file.
pub(crate) const BOM: &[u8] = b"\xef\xbb\xbf";

/// The attitude turned into the expected field in sensor axes, `[w, x, y, z]` (normalised) → µT.
pub type AttitudeToReference<'a> = &'a (dyn Fn([f64; 4]) -> [f64; 3] + Sync);

/// What the reader keeps of what it reads.
#[derive(Clone, Copy, Default)]
pub struct ReadOptions<'a> {
    /// When the file has attitude quaternions and no `rx,ry,rz` columns, each quaternion is turned into the expected
    /// field by this function as its block is read and only that is kept (`ref_ut`; `quat` is `None`): 24 bytes a
    /// row instead of the quaternion's 32, and no second column made from them afterwards. For a caller that needs
    /// the attitude only through the expected field of a known world field.
    pub attitude_to_reference: Option<AttitudeToReference<'a>>,
    /// The temperature column is checked as always but not kept (`temp_c` is `None`): for a caller that does not
    /// use it.
    pub skip_temperature: bool,
    /// The attitude and expected field columns are checked as always but not kept (`quat` and `ref_ut` are `None`;
    /// `attitude_to_reference` is then not used): for a caller that fits the magnitude only.
    pub skip_attitude: bool,
}

impl std::fmt::Debug for ReadOptions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReadOptions")
            .field(
                "attitude_to_reference",
                &self.attitude_to_reference.map(|_| "fn"),
            )
            .field("skip_temperature", &self.skip_temperature)
            .field("skip_attitude", &self.skip_attitude)
            .finish()
    }
}

impl Recording {
    /// Reads a recording from a file; errors name the file as given.
    pub fn read(path: &Path) -> Result<Recording, ReadError> {
        Recording::read_with(path, ReadOptions::default())
    }

    /// [`Recording::read`], keeping what `options` say.
    pub fn read_with(path: &Path, options: ReadOptions) -> Result<Recording, ReadError> {
        let name = path.display().to_string();
        match File::open(path) {
            Ok(file) => {
                let split = Split {
                    size_bytes: file.metadata().ok().map(|m| m.len()),
                    ..Split::DEFAULT
                };
                read_split(&name, file, split, options)
            }
            Err(e) => Err(ReadError::new(&name, None, None, ReadErrorKind::Io(e))),
        }
    }

    /// Reads a recording from any byte source; `name` stands for the file in errors.
    pub fn from_reader<R: Read>(name: &str, reader: R) -> Result<Recording, ReadError> {
        read_split(name, reader, Split::DEFAULT, ReadOptions::default())
    }

    /// The metadata of a recording file alone (what a caller may need to decide how to read the rows), with the
    /// errors [`Recording::read`] would give for it.
    pub fn read_metadata(path: &Path) -> Result<Metadata, ReadError> {
        let name = path.display().to_string();
        let file = File::open(path)
            .map_err(|e| ReadError::new(&name, None, None, ReadErrorKind::Io(e)))?;
        Ok(read_start(&name, file)?.meta)
    }
}

/// The start of a file, read up to and including the header line.
struct Start<R> {
    meta: Metadata,
    /// The header line (without a byte order mark) and its 1-based line number.
    header: (Vec<u8>, u64),
    /// The rest of the file, line ends made one.
    input: BufReader<LineEnds<BufReader<R>>>,
}

/// The start of a file: checked to be text, then its metadata block and header line (see [`read_metadata`]).
fn read_start<R: Read>(name: &str, reader: R) -> Result<Start<R>, ReadError> {
    let mut raw = BufReader::with_capacity(BUFFER_BYTES, reader);
    let start = raw
        .fill_buf()
        .map_err(|e| ReadError::new(name, None, None, ReadErrorKind::Io(e)))?;
    if let Some(kind) = not_text(start) {
        return Err(ReadError::new(name, None, None, kind));
    }
    let mut input = BufReader::with_capacity(BUFFER_BYTES, LineEnds::new(raw));
    let (meta, header_text, header_line) = read_metadata(name, &mut input)?;
    Ok(Start {
        meta,
        header: (header_text, header_line),
        input,
    })
}

/// [`Recording::from_reader`] with the data cut for the threads as `split` says, keeping what `options` say.
pub(crate) fn read_split<R: Read>(
    name: &str,
    reader: R,
    split: Split,
    options: ReadOptions,
) -> Result<Recording, ReadError> {
    let Start {
        meta,
        header: (header_text, header_line),
        input,
    } = read_start(name, reader)?;
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
    let io_error = |e: io::Error| ReadError::new(name, None, None, ReadErrorKind::Io(e));

    // A header with a quote may go on over several lines: the csv reader then reads the whole file from the header
    // on, as it would any file with quotes; otherwise it reads the header line alone and the rows are read in blocks.
    let quoted = header_text.contains(&b'"') || split.sequential;
    let (mut csv, mut input): (_, Option<Box<dyn Read>>) = if quoted {
        let all = io::Cursor::new(header_text).chain(input);
        (csv_reader(Box::new(all) as Box<dyn Read>, separator), None)
    } else {
        let header = Box::new(io::Cursor::new(header_text)) as Box<dyn Read>;
        (
            csv_reader(header, separator),
            Some(Box::new(input) as Box<dyn Read>),
        )
    };
    let mut record = ByteRecord::new();
    csv.read_byte_record(&mut record)
        .map_err(|e| io_error(e.into()))?;
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
        if names.first().is_some_and(|n| n.starts_with("Raw:")) {
            return ReadError::new(name, Some(header_line), None, ReadErrorKind::MotionCalLog);
        }
        let note = matches!(kind, ReadErrorKind::MissingColumn(_))
            .then(|| header_as_read(header_line, &names));
        ReadError::new(
            name,
            Some(header_line),
            column.map(|i| column_ref(&names, i)),
            kind,
        )
        .with_note(note)
    })?;

    let mut out = Recording::empty(meta, &header.layout);
    // The attitude is turned into the expected field only where the file has no expected field of its own.
    let to_reference = options
        .attitude_to_reference
        .filter(|_| header.layout.quat && !header.layout.reference && !options.skip_attitude);
    if to_reference.is_some() {
        out.quat = None;
        out.ref_ut = Some(Vec::new());
    }
    if options.skip_temperature {
        out.temp_c = None;
    }
    if options.skip_attitude {
        out.quat = None;
        out.ref_ut = None;
    }
    let rows = Rows {
        parser: RowParser {
            roles: &header.roles,
            padding: header.padding,
            decimal_comma_possible: separator != b',',
        },
        separator,
        layout: &header.layout,
        time_column: header.roles.iter().position(|r| *r == Role::Time),
        to_reference,
        reshaped: to_reference.is_some() || options.skip_temperature || options.skip_attitude,
    };
    let read = match input.take() {
        Some(rest) => rows.read(rest, header_line + 1, &mut out, split),
        None => rows.quoted(&mut csv, (header_line, true), &mut out, Default::default()),
    };
    match read {
        Ok(()) => {}
        Err(Ok(problem)) => {
            let column = problem.column.map(|i| column_ref(&names, i));
            let note = problem.cut_off.then(|| CUT_OFF.to_owned());
            let error = ReadError::new(name, Some(problem.line), column, problem.kind);
            return Err(error.with_note(note));
        }
        Err(Err(e)) => return Err(io_error(e)),
    }
    if out.is_empty() {
        return Err(ReadError::new(name, None, None, ReadErrorKind::NoData));
    }
    Ok(out)
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
pub(crate) const COMPRESSED: [(&[u8], &str); 5] = [
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_counted_outside_quotes() {
        assert_eq!(column_count(b"mx,my,mz", b','), 3);
        assert_eq!(column_count(b"mx,\"a,b\",mz,\"say \"\"x,y\"\"\"", b','), 4);
        assert_eq!(column_count(b"mx;my;mz,x", b';'), 3);
    }

    /// The message of reading `text`.
    fn message(text: &[u8]) -> String {
        Recording::from_reader("rec.csv", text)
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn a_missing_field_column_names_the_columns_the_header_was_read_as() {
        let msg = message(b"# a: b\nt,mx_uT,my_uT,mz_uT\n0,1,2,3\n");
        assert_eq!(
            msg,
            "rec.csv:2: missing required column \"mx\" (mx, my and mz are required); the header line 2 was read as 4 \
             columns: \"t\", \"mx_uT\", \"my_uT\", \"mz_uT\"; name the field columns mx, my and mz (no units in \
             the name) and separate the columns with commas (or ';' or tabs)"
        );
        let msg = message(b"t mx my mz\n0 1 2 3\n");
        assert!(msg.contains("read as 1 column: \"t mx my mz\";"), "{msg}");
        let wide: Vec<String> = (0..500).map(|i| format!("c{i}")).collect();
        let msg = message(format!("{}\n1\n", wide.join(",")).as_bytes());
        assert!(
            msg.contains("500 columns: \"c0\", ") && msg.contains("\"c7\", … (492 more);"),
            "{msg}"
        );
        assert!(msg.len() < 400, "{} bytes of message", msg.len());
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
