//! Files as other programs write them, read as they are meant: CR-only line ends, `;` and tab separators, upper-case
//! column names, spreadsheet padding. Each reads to the same recording as the plain file, with errors on the right
//! line.

use magcal_recording::{ReadErrorKind, Recording};

const PLAIN: &str = "\
# magcal-recording v1
# sensor: lis3mdl
# field_ned_ut: 19.8, 1.2, 45.3
t,mx,my,mz,temp
0.00,12.5,-3.25,40.125,23.5
0.01,12.75,-3.5,40.25,
";

/// One dialect of the plain file.
struct Dialect {
    what: &'static str,
    text: String,
}

fn dialects() -> Vec<Dialect> {
    let d = |what, text: String| Dialect { what, text };
    vec![
        d(
            "CR-only line ends (classic Mac OS, some loggers)",
            PLAIN.replace('\n', "\r"),
        ),
        d("CRLF line ends", PLAIN.replace('\n', "\r\n")),
        d("mixed line ends", {
            let mut lines = PLAIN.lines();
            let mut text = String::new();
            for (i, end) in ["\r\n", "\r", "\n", "\r", "\r\n", "\r"].iter().enumerate() {
                text.push_str(lines.next().unwrap_or_else(|| panic!("line {i}")));
                text.push_str(end);
            }
            text
        }),
        d(
            "semicolons",
            PLAIN.replace("t,mx,my,mz,temp", "t;mx;my;mz;temp").replace(
                "0.00,12.5,-3.25,40.125,23.5\n0.01,12.75,-3.5,40.25,",
                "0.00;12.5;-3.25;40.125;23.5\n0.01;12.75;-3.5;40.25;",
            ),
        ),
        d("tabs", {
            let (head, rows) = PLAIN.split_at(PLAIN.find("t,mx").unwrap());
            format!("{head}{}", rows.replace(',', "\t"))
        }),
        d(
            "upper-case column names",
            PLAIN.replace("t,mx,my,mz,temp", "T,MX,MY,MZ,Temp"),
        ),
        d("spreadsheet padding (saved by Excel)", {
            // Every line padded to the widest row's 5 fields; the field line has 3 cells already.
            let mut text = String::new();
            for line in PLAIN.lines() {
                let cells = line.split(',').count();
                text.push_str(line);
                text.push_str(&",".repeat(5 - cells));
                text.push_str("\r\n");
            }
            text + ",,,,\r\n"
        }),
        d("spreadsheet padding beyond the header", {
            PLAIN
                .replace("# sensor: lis3mdl", "# sensor: lis3mdl,,,,,,,")
                .replace("t,mx,my,mz,temp", "t,mx,my,mz,temp,,,")
                .replace("23.5\n", "23.5,,\n")
        }),
    ]
}

#[test]
fn every_dialect_reads_as_the_plain_file() {
    let plain = Recording::from_reader("plain.csv", PLAIN.as_bytes()).unwrap();
    for d in dialects() {
        let rec = Recording::from_reader("rec.csv", d.text.as_bytes())
            .unwrap_or_else(|e| panic!("{}: {e}\n{:?}", d.what, d.text));
        // NaN (the missing temperature) is not equal to itself: compare what the recordings print as.
        assert_eq!(format!("{rec:?}"), format!("{plain:?}"), "{}", d.what);
    }
}

#[test]
fn errors_in_a_dialect_are_on_the_right_line() {
    for (what, text, line) in [
        ("CR only", "t,mx,my,mz\r0,1,2,3\r\r0.1,1,x,3\r", 4),
        ("CRLF", "t,mx,my,mz\r\n0,1,2,3\r\n\r\n0.1,1,x,3\r\n", 4),
        ("tabs", "# a: b\nt\tmx\tmy\tmz\n0\t1\tx\t3\n", 3),
    ] {
        let err = Recording::from_reader("rec.csv", text.as_bytes()).unwrap_err();
        assert!(
            matches!(err.kind(), ReadErrorKind::NotANumber(_)),
            "{what}: {err}"
        );
        assert_eq!(err.line(), Some(line), "{what}: {err}");
        assert_eq!(err.column().unwrap().name, "my", "{what}");
    }
    // Padding is empty fields only: a value after the header's last column is a long row.
    let err = Recording::from_reader("rec.csv", &b"mx,my,mz,,\n1,2,3,,4\n"[..]).unwrap_err();
    assert!(matches!(err.kind(), ReadErrorKind::LongRow { .. }), "{err}");
}
