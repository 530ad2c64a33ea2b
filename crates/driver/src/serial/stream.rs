//! One parser for a whole line stream: protocol dispatch and counting, without I/O.

use super::counts::{GarbageKind, LineCounts};
use super::csv_stream::{CsvLine, CsvStream};
use super::device::Protocol;
use super::motioncal::{self, Echo, EchoKind, MotionCalLine};
use super::sample::Sample;

/// What one line was.
#[derive(Clone, Debug, PartialEq)]
pub enum Parsed {
    /// A sample.
    Sample(Sample),
    /// A well-formed `Cal1:`/`Cal2:` calibration echo.
    Echo(Echo),
    /// A line that starts like a calibration echo but is garbled (also counted as garbage).
    BadEcho {
        /// The echo it claims to be.
        echo: EchoKind,
        /// How it is garbled.
        kind: GarbageKind,
        /// The line as received.
        line: String,
    },
    /// A native CSV header line.
    Header,
    /// A native CSV comment line.
    Comment,
    /// A skipped line.
    Garbage(GarbageKind),
}

/// Parses and counts the lines of one stream.
///
/// `Cal1:`/`Cal2:` echoes are recognised in both protocols, so that firmware printing CSV can
/// still take and confirm a MotionCal calibration packet.
#[derive(Clone, Debug)]
pub struct StreamParser {
    protocol: Protocol,
    csv: CsvStream,
    counts: LineCounts,
}

/// Whether a sample's values are within what a recording holds ([`magcal_recording::limits`]), so that the
/// recorder can write it.
fn fits_a_recording(s: &Sample) -> bool {
    use magcal_recording::limits::{
        MAX_CURRENT_A, MAX_FIELD_UT, MAX_GYRO_RAD_S, MAX_T_S, MAX_TEMP_C, QUAT_NORM_TOLERANCE,
    };
    // NaN is a missing value, not one out of range; an infinite one is out of range.
    let within = |values: &[f64], max: f64| values.iter().all(|v| v.is_nan() || v.abs() <= max);
    let unit = |q: [f64; 4]| {
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        norm.is_nan() || (norm - 1.0).abs() <= QUAT_NORM_TOLERANCE
    };
    s.mag_ut.iter().all(|v| v.is_finite())
        && within(&s.mag_ut, MAX_FIELD_UT)
        && within(&[s.t_s.unwrap_or(f64::NAN)], MAX_T_S)
        && within(&[s.temp_c.unwrap_or(f64::NAN)], MAX_TEMP_C)
        && within(&s.gyro_rad_s.unwrap_or([f64::NAN; 3]), MAX_GYRO_RAD_S)
        && within(&s.inputs, MAX_CURRENT_A)
        && s.quat_wxyz.is_none_or(unit)
}

/// Whether `bytes` is a line of text: printable ASCII (tabs allowed), or with `utf8` any UTF-8 without control
/// characters (pattern formats may print `µT`).
fn as_text(bytes: &[u8], utf8: bool) -> Option<&str> {
    if utf8 {
        return std::str::from_utf8(bytes)
            .ok()
            .filter(|t| !t.chars().any(|c| c != '\t' && c.is_control()));
    }
    if bytes
        .iter()
        .all(|&b| b == b'\t' || (0x20..0x7f).contains(&b))
    {
        std::str::from_utf8(bytes).ok()
    } else {
        None
    }
}

impl StreamParser {
    /// A parser for `protocol` that has seen nothing.
    pub fn new(protocol: Protocol) -> Self {
        StreamParser {
            protocol,
            csv: CsvStream::new(),
            counts: LineCounts::default(),
        }
    }

    /// The protocol parsed.
    pub fn protocol(&self) -> &Protocol {
        &self.protocol
    }

    /// Counters so far.
    pub fn counts(&self) -> &LineCounts {
        &self.counts
    }

    /// The CSV stream state (header, input names, metadata); unused for MotionCal.
    pub fn csv(&self) -> &CsvStream {
        &self.csv
    }

    /// Counts a line that never reached [`parse`](Self::parse): overlong, or truncated.
    pub fn count_garbage(&mut self, kind: GarbageKind) {
        self.counts.lines += 1;
        self.counts.garbage.add(kind);
    }

    /// Parses and counts one line (without its terminator; empty lines are not lines).
    pub fn parse(&mut self, line: &[u8]) -> Parsed {
        let parsed = match self.classify(line) {
            Parsed::Sample(s) if !fits_a_recording(&s) => Parsed::Garbage(GarbageKind::OutOfRange),
            other => other,
        };
        let c = &mut self.counts;
        c.lines += 1;
        match &parsed {
            Parsed::Sample(_) => c.samples += 1,
            Parsed::Echo(_) => c.echoes += 1,
            Parsed::Header => c.headers += 1,
            Parsed::Comment => c.comments += 1,
            Parsed::BadEcho { kind, .. } | Parsed::Garbage(kind) => c.garbage.add(*kind),
        }
        parsed
    }

    fn classify(&mut self, line: &[u8]) -> Parsed {
        let utf8 = matches!(self.protocol, Protocol::Pattern(_));
        let Some(text) = as_text(line, utf8) else {
            return Parsed::Garbage(GarbageKind::Binary);
        };
        if let Some((echo, result)) = motioncal::parse_echo(text) {
            return match result {
                Ok(e) => Parsed::Echo(e),
                Err(kind) => Parsed::BadEcho {
                    echo,
                    kind,
                    line: text.to_string(),
                },
            };
        }
        match &self.protocol {
            Protocol::MotionCal => match motioncal::parse_line(text) {
                Ok(MotionCalLine::Raw(raw)) => Parsed::Sample(raw.to_sample()),
                Ok(MotionCalLine::Echo(e)) => Parsed::Echo(e),
                Err(kind) => Parsed::Garbage(kind),
            },
            Protocol::Csv => match self.csv.parse_line(text) {
                Ok(CsvLine::Sample(s)) => Parsed::Sample(s),
                Ok(CsvLine::Header) => Parsed::Header,
                Ok(CsvLine::Comment) => Parsed::Comment,
                Err(kind) => Parsed::Garbage(kind),
            },
            Protocol::Pattern(p) => match p.parse_line(text) {
                Ok(s) => Parsed::Sample(s),
                Err(kind) => Parsed::Garbage(kind),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motioncal_stream_counts_every_line_once() {
        let mut p = StreamParser::new(Protocol::MotionCal);
        let lines: [&[u8]; 8] = [
            b"Raw:1,2,3,4,5,6,7,8,9",
            b"Raw:1,2,3",
            b"\x00\xff\x13binary",
            b"Uni:0.1,0.2",
            b"Cal1:0,0,0,0,0,0,0,0,0,50",
            b"Cal2:1,0,0,0,1,0,0,0,x",
            b"Raw:1,2,3,4,5,6,7,8,y",
            "Raw:1,2,3,4,5,6,7,8,9\u{b5}".as_bytes(),
        ];
        let parsed: Vec<Parsed> = lines.iter().map(|l| p.parse(l)).collect();
        assert!(matches!(parsed[0], Parsed::Sample(_)));
        assert!(matches!(parsed[4], Parsed::Echo(Echo::Cal1(_))));
        assert_eq!(
            parsed[5],
            Parsed::BadEcho {
                echo: EchoKind::Cal2,
                kind: GarbageKind::BadNumber,
                line: "Cal2:1,0,0,0,1,0,0,0,x".into()
            }
        );
        p.count_garbage(GarbageKind::Overlong);
        let c = p.counts();
        assert_eq!((c.lines, c.samples, c.echoes), (9, 1, 1));
        let g = &c.garbage;
        assert_eq!(g.get(GarbageKind::FieldCount), 1);
        assert_eq!(g.get(GarbageKind::Binary), 2);
        assert_eq!(g.get(GarbageKind::Unrecognized), 1);
        assert_eq!(g.get(GarbageKind::BadNumber), 2);
        assert_eq!(g.get(GarbageKind::Overlong), 1);
        assert_eq!(
            c.lines,
            c.samples + c.echoes + c.headers + c.comments + g.total()
        );
    }

    #[test]
    fn samples_beyond_what_a_recording_holds_are_garbage() {
        let mut p = StreamParser::new(Protocol::MotionCal);
        // A line that lost bytes: 0.1 µT units, −4.2·10⁶ µT.
        assert_eq!(
            p.parse(b"Raw:0,0,8192,0,0,0,-42000000,10,20"),
            Parsed::Garbage(GarbageKind::OutOfRange)
        );
        assert!(matches!(
            p.parse(b"Raw:0,0,8192,0,0,0,-420000,10,20"),
            Parsed::Sample(_)
        ));
        let mut p = StreamParser::new(Protocol::Csv);
        assert_eq!(p.parse(b"t,mx,my,mz,temp"), Parsed::Header);
        for line in [&b"0.1,1,2,3,20000"[..], b"1e12,1,2,3,20", b"0.1,1e7,2,3,20"] {
            assert_eq!(
                p.parse(line),
                Parsed::Garbage(GarbageKind::OutOfRange),
                "{}",
                String::from_utf8_lossy(line)
            );
        }
        assert!(matches!(p.parse(b"0.2,1,2,3,20"), Parsed::Sample(_)));
        assert_eq!(p.counts().garbage.get(GarbageKind::OutOfRange), 3);
    }

    #[test]
    fn csv_stream_goes_through_the_csv_parser() {
        let mut p = StreamParser::new(Protocol::Csv);
        assert_eq!(p.parse(b"1,2,3"), Parsed::Garbage(GarbageKind::NoHeader));
        assert_eq!(p.parse(b"# units: uT"), Parsed::Comment);
        assert_eq!(p.parse(b"t,mx,my,mz,i_coil"), Parsed::Header);
        let Parsed::Sample(s) = p.parse(b"0.5,1,2,3,0.25") else {
            panic!("no sample");
        };
        assert_eq!(
            (s.t_s, s.mag_ut, s.inputs),
            (Some(0.5), [1.0, 2.0, 3.0], vec![0.25])
        );
        assert_eq!(
            p.parse(b"Raw:1,2,3,4,5,6,7,8,9"),
            Parsed::Garbage(GarbageKind::Unrecognized)
        );
        assert!(matches!(
            p.parse(b"Cal1:0,0,0,0,0,0,0,0,0,50"),
            Parsed::Echo(_)
        ));
        assert_eq!(p.csv().input_names(), ["coil"]);
        let c = p.counts();
        assert_eq!(
            (c.lines, c.samples, c.headers, c.comments, c.echoes),
            (6, 1, 1, 1, 1)
        );
    }
}
