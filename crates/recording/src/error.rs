//! Errors of the reader: where in the file ([`ReadError`]) and what went wrong ([`ReadErrorKind`]).

use std::fmt;

/// A column of the header row, as named in errors.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ColumnRef {
    /// 1-based position of the column in the header row.
    pub index: usize,
    /// The column's name in the header row.
    pub name: String,
}

/// Why a recording could not be read, and where: file name, 1-based line in the file and, where one applies,
/// the column.
///
/// Displays as `name:line:column (colname): message`, `name:line: message` for line-level problems, or
/// `name: message` for problems with the file as a whole; the message may end with a note of what the reader saw
/// (`; …`).
#[derive(Debug)]
pub struct ReadError(Box<Inner>);

#[derive(Debug)]
struct Inner {
    file: String,
    line: Option<u64>,
    column: Option<ColumnRef>,
    kind: ReadErrorKind,
    /// What the reader adds to the kind's message where it knows more (the header as read, a file cut off).
    note: Option<String>,
}

impl ReadError {
    pub(crate) fn new(
        file: &str,
        line: Option<u64>,
        column: Option<ColumnRef>,
        kind: ReadErrorKind,
    ) -> ReadError {
        ReadError(Box::new(Inner {
            file: file.to_owned(),
            line,
            column,
            kind,
            note: None,
        }))
    }

    /// The error with `note` added to its message, if there is one.
    pub(crate) fn with_note(mut self, note: Option<String>) -> ReadError {
        self.0.note = note;
        self
    }

    /// What went wrong (for matching on the kind of failure).
    pub fn kind(&self) -> &ReadErrorKind {
        &self.0.kind
    }

    /// The file name (or the name given to [`crate::Recording::from_reader`]).
    pub fn file(&self) -> &str {
        &self.0.file
    }

    /// 1-based line in the file, when the problem is on one line.
    pub fn line(&self) -> Option<u64> {
        self.0.line
    }

    /// The column, when the problem is in one field.
    pub fn column(&self) -> Option<&ColumnRef> {
        self.0.column.as_ref()
    }
}

/// At most this many characters of a file's text are quoted in an error.
pub(crate) const EXCERPT_CHARS: usize = 40;

/// The first [`EXCERPT_CHARS`] characters of `text`, with `…` when there were more. Errors show it with `{:?}`, which
/// escapes control characters, so that a broken file never prints raw bytes (escape sequences) to a terminal.
pub(crate) fn excerpt(text: &str) -> String {
    match text.char_indices().nth(EXCERPT_CHARS) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_owned(),
    }
}

impl fmt::Display for ReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file())?;
        if let Some(line) = self.line() {
            write!(f, ":{line}")?;
            if let Some(col) = self.column() {
                let name = excerpt(&col.name);
                write!(f, ":{} ({})", col.index, name.escape_debug())?;
            }
        }
        write!(f, ": {}", self.kind())?;
        if let Some(note) = &self.0.note {
            write!(f, "; {note}")?;
        }
        Ok(())
    }
}

/// At most this many column names are quoted in [`header_as_read`].
const HEADER_NAMES_SHOWN: usize = 8;

/// A note for [`ReadErrorKind::MissingColumn`]: the columns the header line was split into (at most
/// [`HEADER_NAMES_SHOWN`], each a short escaped excerpt), and how the columns should be named and separated.
pub(crate) fn header_as_read(line: u64, names: &[String]) -> String {
    let n = names.len();
    let mut shown: Vec<String> = names
        .iter()
        .take(HEADER_NAMES_SHOWN)
        .map(|name| format!("{:?}", excerpt(name)))
        .collect();
    if n > HEADER_NAMES_SHOWN {
        shown.push(format!("… ({} more)", n - HEADER_NAMES_SHOWN));
    }
    let columns = if n == 1 { "column" } else { "columns" };
    format!(
        "the header line {line} was read as {n} {columns}: {}; name the field columns mx, my and mz (no units in \
         the name) and separate the columns with commas (or ';' or tabs)",
        shown.join(", ")
    )
}

/// A note for a [`ReadErrorKind::ShortRow`] that is the file's last line and has no line end.
pub(crate) const CUT_OFF: &str = "the file ends in the middle of this line (cut off, e.g. a logger stopped while \
                                  writing): remove this last line and the rest can be read";

/// No source: the system's error of [`ReadErrorKind::Io`] is said in the message, and an error chain printed whole
/// would say it twice.
impl std::error::Error for ReadError {}

/// What went wrong while reading a recording. One variant per kind of failure. Text quoted from the file is at most
/// a short excerpt, shown escaped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadErrorKind {
    /// The file could not be opened or read (the system's error is in the message, not a source).
    #[error("cannot read: {0}")]
    Io(std::io::Error),
    /// The file holds nothing but blank lines (or nothing at all).
    #[error("empty file")]
    Empty,
    /// The file is compressed (its first bytes are a compressor's signature).
    #[error("a {format} file, not a recording: decompress it first")]
    Compressed {
        /// The compression format: `gzip`, `bzip2`, `xz`, `zstd` or `zip`.
        format: &'static str,
    },
    /// The file is UTF-16 text (it starts with a UTF-16 byte order mark).
    #[error("UTF-16 text: save the recording as UTF-8 (or plain ASCII) text")]
    Utf16,
    /// The file holds binary data (a NUL byte near its start), not text.
    #[error("binary data (a NUL byte at byte {offset}), not a text recording")]
    Binary {
        /// 0-based offset of the first NUL byte.
        offset: u64,
    },
    /// The magic line names a version of the format other than v1.
    #[error("unsupported format version {found:?} (this reader understands magcal-recording v1)")]
    UnsupportedVersion {
        /// The version text found after `magcal-recording`.
        found: String,
    },
    /// A known metadata key has a value that does not parse or is out of range.
    #[error("malformed metadata value for {key:?}: {value:?}: {reason}")]
    BadMetadata {
        /// The metadata key.
        key: String,
        /// The value as written.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A metadata key appears twice.
    #[error("duplicate metadata key {key:?}")]
    DuplicateMetadata {
        /// The repeated key.
        key: String,
    },
    /// There is metadata but no header row, or the first row after the metadata is data, not column names.
    #[error("missing header row{}", if *data_first { ": the first row after the metadata holds numbers" } else { "" })]
    MissingHeader {
        /// True if a row of numbers stands where the header should be.
        data_first: bool,
    },
    /// The file is a MotionCal-style board's serial output saved as it came (`Raw:` lines), not a recording.
    #[error(
        "MotionCal serial output (Raw:ax,ay,az,gx,gy,gz,mx,my,mz lines), not a recording: record the board with \
         magcal-record --device serial:PORT (it reads these lines), or make this a recording: a header line mx,my,mz \
         and, on each line, the last three numbers divided by 10 (MotionCal's counts are 0.1 µT)"
    )]
    MotionCalLog,
    /// One of the required columns `mx`, `my`, `mz` is not in the header.
    #[error("missing required column {0:?} (mx, my and mz are required)")]
    MissingColumn(&'static str),
    /// The header row is separated by something other than commas (`;`, tab) and names no `mx,my,mz` that way
    /// either.
    #[error(
        "the header row is separated by {} and does not name mx, my and mz (columns are separated by commas; ';' \
         and tabs are read when the header names mx, my and mz)",
        separator.escape_debug()
    )]
    Separator {
        /// The separator seen.
        separator: char,
    },
    /// The header row has more columns than a recording can have ([`crate::limits::MAX_COLUMNS`]).
    #[error("the header row has {found} columns; a recording has at most {max}")]
    TooManyColumns {
        /// Columns in the header row.
        found: usize,
        /// The most a recording may have.
        max: usize,
    },
    /// Two columns of the header have the same name.
    #[error("duplicate column name {0:?}")]
    DuplicateColumn(String),
    /// A column of the header has an empty name.
    #[error("empty column name")]
    EmptyColumnName,
    /// Only part of a column group (`qw..qz`, `rx..rz`, `gx..gz`) is in the header.
    #[error("incomplete column group: has {present} but lacks {missing}")]
    IncompleteGroup {
        /// The group's columns that are present, comma separated.
        present: String,
        /// The group's columns that are absent, comma separated.
        missing: String,
    },
    /// A numeric field is neither a number, empty, nor `nan`.
    #[error("not a number: {0:?}")]
    NotANumber(String),
    /// A numeric field written with a decimal comma (`1,5`), in a file whose columns are separated by `;` or tabs.
    #[error("not a number: {0:?} (a decimal comma? write numbers with a decimal point)")]
    DecimalComma(String),
    /// A finite number beyond what the column can hold (see [`crate::limits`]).
    #[error("out of range: {value:?} (this column holds at most ±{limit:e} {unit}{hint})")]
    OutOfRange {
        /// The number as written.
        value: String,
        /// The largest magnitude the column accepts.
        limit: f64,
        /// The column's unit.
        unit: &'static str,
        /// What the number most likely is, when something is (it starts with "; "), or "".
        hint: &'static str,
    },
    /// `mx`, `my` or `mz` is NaN or infinite.
    #[error("magnetic field must be finite, got {0:?}")]
    NonFiniteMag(String),
    /// `mx`, `my` or `mz` is empty.
    #[error("empty magnetic field value (mx, my and mz are required in every row)")]
    EmptyMag,
    /// An optional numeric channel holds an infinite value (missing values are written as an empty field or `nan`).
    #[error("infinite value {0:?} (write a missing value as an empty field or nan)")]
    Infinite(String),
    /// A data row has fewer fields than the header.
    #[error("short row: {found} fields, the header has {expected}")]
    ShortRow {
        /// Number of columns in the header.
        expected: usize,
        /// Number of fields in the row.
        found: usize,
    },
    /// A data row has more fields than the header.
    #[error("long row: {found} fields, the header has {expected}")]
    LongRow {
        /// Number of columns in the header.
        expected: usize,
        /// Number of fields in the row.
        found: usize,
    },
    /// `t` is empty, NaN or infinite.
    #[error("t must be a finite number in every row, got {0:?}")]
    NonFiniteTime(String),
    /// `t` is smaller than in the row before.
    #[error(
        "t goes backwards: {t_s} s after {previous_s} s (the rows must be in time order: sort them by t; where a \
         device's clock restarted, make t go on from where it was, or leave the t column out to fit without times)"
    )]
    TimeBackwards {
        /// `t` in the previous data row.
        previous_s: f64,
        /// `t` in this row.
        t_s: f64,
    },
    /// A complete quaternion whose norm is outside 1 ± 0.01.
    #[error("quaternion far from unit length: |q| = {norm}{}", quat_norm_hint(*norm))]
    QuatNotUnit {
        /// The quaternion's norm.
        norm: f64,
    },
    /// A `#` line (metadata or comment) after the header row.
    #[error("metadata or comment line after the header row (metadata must come before the header)")]
    LineAfterHeader,
    /// The header is followed by no data row.
    #[error("no data rows")]
    NoData,
    /// The bytes of a line or field are not valid UTF-8.
    #[error("invalid UTF-8")]
    InvalidUtf8,
}

/// Metadata or a layout that would not read back as itself if written (see [`crate::Recording::new`] and
/// [`crate::RecordingWriter::create`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("cannot write this header: {0}")]
pub struct HeaderError(pub String);

/// Fixed-point scales quaternions are written in: Q14 (BNO055, BNO08x), Q15, Q30 (the MPU's DMP), and ×10⁴.
const QUAT_FIXED_POINT: [f64; 4] = [16_384.0, 32_768.0, 1_073_741_824.0, 10_000.0];

/// What a quaternion's norm far from 1 most likely means: written in fixed point (the scale to divide by), or all
/// zeros for a missing attitude; "" otherwise.
fn quat_norm_hint(norm: f64) -> String {
    if norm == 0.0 {
        return " (all zero: a row without an attitude leaves its quaternion columns empty or nan)"
            .to_owned();
    }
    QUAT_FIXED_POINT
        .iter()
        .find(|k| (norm / **k - 1.0).abs() <= 0.02)
        .map_or_else(String::new, |k| {
            format!(" (written in fixed point? divide the quaternion columns by {k})")
        })
}
