//! Broken recordings: each is refused with its own error kind, and the message names file, line and column.

use std::collections::BTreeSet;
use std::mem::discriminant;

use magcal_recording::{ReadErrorKind as K, Recording};

/// One broken recording: what it is, its bytes, the kind expected, how the message starts, and a word it holds.
struct Case {
    what: &'static str,
    input: &'static [u8],
    kind: fn(&K) -> bool,
    prefix: &'static str,
    says: &'static str,
}

const OK_ROWS: &str = "t,mx,my,mz\n0,1,2,3\n";

fn cases() -> Vec<Case> {
    vec![
        Case {
            what: "zero bytes",
            input: b"",
            kind: |k| matches!(k, K::Empty),
            prefix: "rec.csv: ",
            says: "empty file",
        },
        Case {
            what: "only blank lines",
            input: b"\n  \r\n\n",
            kind: |k| matches!(k, K::Empty),
            prefix: "rec.csv: ",
            says: "empty file",
        },
        Case {
            what: "version 2",
            input: b"# magcal-recording v2\nt,mx,my,mz\n0,1,2,3\n",
            kind: |k| matches!(k, K::UnsupportedVersion { found } if found == "v2"),
            prefix: "rec.csv:1: ",
            says: "unsupported format version",
        },
        Case {
            what: "field with two numbers",
            input: b"# magcal-recording v1\n# field_ned_ut: 1,2\nt,mx,my,mz\n0,1,2,3\n",
            kind: |k| matches!(k, K::BadMetadata { key, .. } if key == "field_ned_ut"),
            prefix: "rec.csv:2: ",
            says: "malformed metadata value",
        },
        Case {
            what: "negative sample rate",
            input: b"# sensor: x\n\n# sample_rate_hz: -5\nmx,my,mz\n1,2,3\n",
            kind: |k| matches!(k, K::BadMetadata { key, .. } if key == "sample_rate_hz"),
            prefix: "rec.csv:3: ",
            says: "> 0",
        },
        Case {
            what: "impossible date",
            input: b"# date: 2021-13-40\nmx,my,mz\n1,2,3\n",
            kind: |k| matches!(k, K::BadMetadata { key, .. } if key == "date"),
            prefix: "rec.csv:1: ",
            says: "month 13",
        },
        Case {
            what: "location out of range",
            input: b"# location: 95, 0, 10\nmx,my,mz\n1,2,3\n",
            kind: |k| matches!(k, K::BadMetadata { key, .. } if key == "location"),
            prefix: "rec.csv:1: ",
            says: "latitude",
        },
        Case {
            what: "metadata key twice",
            input: b"# sensor: a\n# sensor: b\nmx,my,mz\n1,2,3\n",
            kind: |k| matches!(k, K::DuplicateMetadata { key } if key == "sensor"),
            prefix: "rec.csv:2: ",
            says: "duplicate metadata key",
        },
        Case {
            what: "metadata only",
            input: b"# magcal-recording v1\n# sensor: x\n\n",
            kind: |k| matches!(k, K::MissingHeader { data_first: false }),
            prefix: "rec.csv: ",
            says: "missing header",
        },
        Case {
            what: "data where the header belongs",
            input: b"# sensor: x\n1,2,3\n4,5,6\n",
            kind: |k| matches!(k, K::MissingHeader { data_first: true }),
            prefix: "rec.csv:2: ",
            says: "missing header",
        },
        Case {
            what: "no mz column",
            input: b"t,mx,my\n0,1,2\n",
            kind: |k| matches!(k, K::MissingColumn("mz")),
            prefix: "rec.csv:1: ",
            says: "missing required column \"mz\"",
        },
        Case {
            what: "mx twice",
            input: b"t,mx,my,mz,mx\n0,1,2,3,4\n",
            kind: |k| matches!(k, K::DuplicateColumn(n) if n == "mx"),
            prefix: "rec.csv:1:5 (mx): ",
            says: "duplicate column name",
        },
        Case {
            what: "empty column name",
            input: b"mx,my,mz,,temp\n1,2,3,4,5\n",
            kind: |k| matches!(k, K::EmptyColumnName),
            prefix: "rec.csv:1:4 (): ",
            says: "empty column name",
        },
        Case {
            what: "quaternion without qz",
            input: b"mx,my,mz,qw,qx,qy\n1,2,3,1,0,0\n",
            kind: |k| matches!(k, K::IncompleteGroup { missing, .. } if missing == "qz"),
            prefix: "rec.csv:1: ",
            says: "incomplete column group",
        },
        Case {
            what: "gyro without gx",
            input: b"mx,my,mz,gz,gy\n1,2,3,0,0\n",
            kind: |k| matches!(k, K::IncompleteGroup { missing, .. } if missing == "gx"),
            prefix: "rec.csv:1: ",
            says: "lacks gx",
        },
        Case {
            what: "two decimal points",
            input: b"# magcal-recording v1\nt,mx,my,mz\n0,1,2,3\n0.01,1,2,3\n\n0.02,1,2,3\n0.03,1,2,3\n0.04,1,2,3\n\
                     0.05,1,2,3\n0.06,1,2,3\n0.07,1,2,3\n0.08,1,2,3\n0.09,1,1.2.3,3\n",
            kind: |k| matches!(k, K::NotANumber(t) if t == "1.2.3"),
            prefix: "rec.csv:13:3 (my): ",
            says: "not a number: \"1.2.3\"",
        },
        Case {
            what: "text in a current",
            input: b"mx,my,mz,i_motor\n1,2,3,0.5\n1,2,3,high\n",
            kind: |k| matches!(k, K::NotANumber(t) if t == "high"),
            prefix: "rec.csv:3:4 (i_motor): ",
            says: "not a number",
        },
        Case {
            what: "nan in my",
            input: b"mx,my,mz\n1,NaN,3\n",
            kind: |k| matches!(k, K::NonFiniteMag(_)),
            prefix: "rec.csv:2:2 (my): ",
            says: "must be finite",
        },
        Case {
            what: "inf in mz",
            input: b"mx,my,mz\n1,2,-inf\n",
            kind: |k| matches!(k, K::NonFiniteMag(_)),
            prefix: "rec.csv:2:3 (mz): ",
            says: "must be finite",
        },
        Case {
            what: "empty mx",
            input: b"t,mx,my,mz\n0,,2,3\n",
            kind: |k| matches!(k, K::EmptyMag),
            prefix: "rec.csv:2:2 (mx): ",
            says: "empty magnetic field value",
        },
        Case {
            what: "infinite temperature",
            input: b"mx,my,mz,temp\n1,2,3,inf\n",
            kind: |k| matches!(k, K::Infinite(_)),
            prefix: "rec.csv:2:4 (temp): ",
            says: "infinite value",
        },
        Case {
            what: "short row",
            input: b"t,mx,my,mz\n0,1,2,3\n0.1,1,2\n",
            kind: |k| matches!(k, K::ShortRow { expected: 4, found: 3 }),
            prefix: "rec.csv:3: ",
            says: "short row",
        },
        Case {
            what: "long row",
            input: b"t,mx,my,mz\n0,1,2,3,4\n",
            kind: |k| matches!(k, K::LongRow { expected: 4, found: 5 }),
            prefix: "rec.csv:2: ",
            says: "long row",
        },
        Case {
            what: "nan time",
            input: b"t,mx,my,mz\n0,1,2,3\nnan,1,2,3\n",
            kind: |k| matches!(k, K::NonFiniteTime(_)),
            prefix: "rec.csv:3:1 (t): ",
            says: "t must be a finite number",
        },
        Case {
            what: "empty time",
            input: b"mx,my,mz,t\n1,2,3,\n",
            kind: |k| matches!(k, K::NonFiniteTime(_)),
            prefix: "rec.csv:2:4 (t): ",
            says: "t must be a finite number",
        },
        Case {
            what: "time going backwards",
            input: b"t,mx,my,mz\n1,1,2,3\n1,1,2,3\n0.5,1,2,3\n",
            kind: |k| matches!(k, K::TimeBackwards { previous_s: 1.0, t_s: 0.5 }),
            prefix: "rec.csv:4:1 (t): ",
            says: "goes backwards",
        },
        Case {
            what: "quaternion of norm 0.9",
            input: b"mx,my,mz,qw,qx,qy,qz\n1,2,3,1,0,0,0\n1,2,3,0.9,0,0,0\n",
            kind: |k| matches!(k, K::QuatNotUnit { .. }),
            prefix: "rec.csv:3: ",
            says: "far from unit length",
        },
        Case {
            what: "zero quaternion",
            input: b"mx,my,mz,qw,qx,qy,qz\n1,2,3,0,0,0,0\n",
            kind: |k| matches!(k, K::QuatNotUnit { .. }),
            prefix: "rec.csv:2: ",
            says: "all zero: a row without an attitude leaves its quaternion columns empty or nan",
        },
        Case {
            what: "a quaternion in a BNO055's fixed point (Q14)",
            input: b"mx,my,mz,qw,qx,qy,qz\n1,2,3,16384,0,0,0\n",
            kind: |k| matches!(k, K::QuatNotUnit { .. }),
            prefix: "rec.csv:2: ",
            says: "divide the quaternion columns by 16384",
        },
        Case {
            what: "metadata after the header",
            input: b"mx,my,mz\n1,2,3\n# sensor: late\n4,5,6\n",
            kind: |k| matches!(k, K::LineAfterHeader),
            prefix: "rec.csv:3: ",
            says: "after the header",
        },
        Case {
            what: "header only",
            input: b"# magcal-recording v1\nt,mx,my,mz\n\n",
            kind: |k| matches!(k, K::NoData),
            prefix: "rec.csv: ",
            says: "no data rows",
        },
        Case {
            what: "latin-1 in a text column",
            input: b"mx,my,mz,note\n1,2,3,ok\n1,2,3,caf\xe9\n",
            kind: |k| matches!(k, K::InvalidUtf8),
            prefix: "rec.csv:3:4 (note): ",
            says: "invalid UTF-8",
        },
        Case {
            what: "latin-1 in metadata",
            input: b"# sensor: \xff\nmx,my,mz\n1,2,3\n",
            kind: |k| matches!(k, K::InvalidUtf8),
            prefix: "rec.csv:1: ",
            says: "invalid UTF-8",
        },
        Case {
            what: "latin-1 in the header",
            input: b"mx,my,mz,\xb5T\n1,2,3,4\n",
            kind: |k| matches!(k, K::InvalidUtf8),
            prefix: "rec.csv:1:4 (",
            says: "invalid UTF-8",
        },
        Case {
            what: "a gzip-compressed recording",
            input: b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03\x4b\xcc\x2b\xa9\x00\x00",
            kind: |k| matches!(k, K::Compressed { format: "gzip" }),
            prefix: "rec.csv: ",
            says: "a gzip file, not a recording: decompress it first",
        },
        Case {
            what: "a zip archive",
            input: b"PK\x03\x04\x14\x00\x00\x00rec.csv",
            kind: |k| matches!(k, K::Compressed { format: "zip" }),
            prefix: "rec.csv: ",
            says: "zip file",
        },
        Case {
            what: "binary data",
            input: b"\x7fELF\x02\x01\x01\x00\x00\x00\x1b[2J",
            kind: |k| matches!(k, K::Binary { offset: 7 }),
            prefix: "rec.csv: ",
            says: "binary data (a NUL byte at byte 7)",
        },
        Case {
            what: "UTF-16 text",
            input: b"\xff\xfem\x00x\x00,\x00",
            kind: |k| matches!(k, K::Utf16),
            prefix: "rec.csv: ",
            says: "save the recording as UTF-8",
        },
        Case {
            what: "1e308 in a row",
            input: b"t,mx,my,mz\n0,1,2,3\n0.01,1,1e308,3\n",
            kind: |k| matches!(k, K::OutOfRange { value, unit: "\u{b5}T", .. } if value == "1e308"),
            prefix: "rec.csv:3:3 (my): ",
            says: "out of range: \"1e308\"",
        },
        Case {
            what: "a time far beyond any clock",
            input: b"t,mx,my,mz\n1e300,1,2,3\n",
            kind: |k| matches!(k, K::OutOfRange { unit: "s", .. }),
            prefix: "rec.csv:2:1 (t): ",
            says: "out of range",
        },
        Case {
            what: "a Unix timestamp in milliseconds",
            input: b"t,mx,my,mz\n1732700000000,1,2,3\n",
            kind: |k| matches!(k, K::OutOfRange { unit: "s", .. }),
            prefix: "rec.csv:2:1 (t): ",
            says: "t is in seconds: a timestamp in milliseconds or nanoseconds divided by 1000 or 10⁹",
        },
        Case {
            what: "semicolons that name no mx,my,mz",
            input: b"time;Bx;By;Bz\n0;1;2;3\n",
            kind: |k| matches!(k, K::Separator { separator: ';' }),
            prefix: "rec.csv:1: ",
            says: "separated by ;",
        },
        Case {
            what: "a MotionCal board's serial output saved as it came",
            input: b"Raw:-12,40,8190,1,-2,0,153,-87,412\nRaw:-11,41,8191,0,-1,1,152,-88,413\n",
            kind: |k| matches!(k, K::MotionCalLog),
            prefix: "rec.csv:1: ",
            says: "divided by 10",
        },
        Case {
            what: "a decimal comma in a ;-separated file",
            input: b"t;mx;my;mz\n0;1,5;2;3\n",
            kind: |k| matches!(k, K::DecimalComma(t) if t == "1,5"),
            prefix: "rec.csv:2:2 (mx): ",
            says: "decimal comma",
        },
    ]
}

#[test]
fn each_broken_recording_has_its_own_kind_and_location() {
    let mut kinds = BTreeSet::new();
    for case in cases() {
        let err = Recording::from_reader("rec.csv", case.input)
            .expect_err(&format!("{}: should be refused", case.what));
        let msg = err.to_string();
        assert!(
            (case.kind)(err.kind()),
            "{}: wrong kind {:?} ({msg})",
            case.what,
            err.kind()
        );
        assert!(
            msg.starts_with(case.prefix),
            "{}: message {msg:?} should start with {:?}",
            case.what,
            case.prefix
        );
        assert!(
            msg.contains(case.says),
            "{}: message {msg:?} should say {:?}",
            case.what,
            case.says
        );
        assert_eq!(err.file(), "rec.csv");
        kinds.insert(format!("{:?}", discriminant(err.kind())));
    }
    assert!(kinds.len() >= 26, "only {} distinct kinds", kinds.len());
}

#[test]
fn errors_quote_a_short_escaped_excerpt_never_the_whole_file() {
    // A CR-less, LF-less binary-ish text: one long "line" with escape sequences in it.
    let mut text = b"# magcal-recording ".to_vec();
    text.extend(b"\x1b[31m".repeat(2000));
    let err = Recording::from_reader("rec.csv", &text[..]).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err.kind(), K::UnsupportedVersion { .. }), "{msg}");
    assert!(!msg.contains('\x1b'), "raw escape bytes in {msg:?}");
    assert!(msg.contains("\\u{1b}[31m") && msg.contains('…'), "{msg}");
    assert!(msg.len() < 300, "{} bytes of message", msg.len());

    let long_name = format!("mx,my,mz,{}\n1,2,3,4\n1,2,3\n", "\u{1b}x".repeat(500));
    let err = Recording::from_reader("rec.csv", long_name.as_bytes()).unwrap_err();
    assert!(matches!(err.kind(), K::ShortRow { .. }));
    let long_field = format!("mx,my,mz\n1,2,{}\n", "9\u{7}".repeat(500));
    let msg = Recording::from_reader("rec.csv", long_field.as_bytes())
        .unwrap_err()
        .to_string();
    assert!(msg.len() < 200 && !msg.contains('\u{7}'), "{msg:?}");
    let column = format!("mx,my,mz,i_{}\n1,2,3,x\n", "\u{1b}".repeat(500));
    let msg = Recording::from_reader("rec.csv", column.as_bytes())
        .unwrap_err()
        .to_string();
    assert!(
        msg.starts_with("rec.csv:2:4 (i_\\u{1b}") && !msg.contains('\u{1b}') && msg.len() < 400,
        "{msg:?}"
    );
}

#[test]
fn the_spec_example_message() {
    let err = Recording::from_reader("rec.csv", &b"t,mx,my,mz\n0,1,1.2.3,1\n"[..]).unwrap_err();
    assert_eq!(err.to_string(), "rec.csv:2:3 (my): not a number: \"1.2.3\"");
    assert_eq!(err.line(), Some(2));
    assert_eq!(
        err.column().map(|c| (c.index, c.name.as_str())),
        Some((3, "my"))
    );
}

#[test]
fn line_numbers_count_blank_lines_crlf_and_quoted_line_breaks() {
    let crlf = b"# a: b\r\n\r\nmx,my,mz\r\n\r\n1,2,3\r\n\r\n1,x,3\r\n";
    let err = Recording::from_reader("rec.csv", &crlf[..]).unwrap_err();
    assert!(err.to_string().starts_with("rec.csv:7:2 (my): "), "{err}");

    let quoted = b"mx,my,mz,note\n1,2,3,\"two\nlines\"\n\n1,2,x,n\n";
    let err = Recording::from_reader("rec.csv", &quoted[..]).unwrap_err();
    assert!(err.to_string().starts_with("rec.csv:5:3 (mz): "), "{err}");

    let no_final_newline = b"mx,my,mz\n1,2,3\n1,2,y";
    let err = Recording::from_reader("rec.csv", &no_final_newline[..]).unwrap_err();
    assert!(err.to_string().starts_with("rec.csv:3:3 (mz): "), "{err}");

    let bom = b"\xef\xbb\xbfmx,my,mz\n1,2,3\n1,2\n";
    let err = Recording::from_reader("rec.csv", &bom[..]).unwrap_err();
    assert!(err.to_string().starts_with("rec.csv:3: short row"), "{err}");
}

#[test]
fn a_missing_file_is_an_io_error_naming_it() {
    let err = Recording::read(std::path::Path::new("/nonexistent/dir/nope.csv")).unwrap_err();
    assert!(matches!(err.kind(), K::Io(_)));
    assert!(
        err.to_string()
            .starts_with("/nonexistent/dir/nope.csv: cannot read"),
        "{err}"
    );
    // The system's reason is in the message, and not chained again as a source (an error chain printed whole would
    // say it twice).
    assert!(err.to_string().contains("No such file"), "{err}");
    assert!(std::error::Error::source(&err).is_none());
}

#[test]
fn valid_rows_around_the_cases_are_fine() {
    // Guards the table: the row shapes it breaks are accepted when not broken.
    assert_eq!(
        Recording::from_reader("ok.csv", OK_ROWS.as_bytes())
            .unwrap()
            .len(),
        1
    );
    let q = b"mx,my,mz,qw,qx,qy,qz\n1,2,3,1.009,0,0,0\n1,2,3,,0,0,0\n1,2,3,nan,nan,nan,nan\n";
    let rec = Recording::from_reader("ok.csv", &q[..]).unwrap();
    assert_eq!(rec.quat.as_ref().unwrap()[0], [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(rec.missing_counts().quat, Some(2));
}
