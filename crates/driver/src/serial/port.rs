//! Reading samples from a serial port, and writing a MotionCal calibration to it.
//!
//! [`SerialSource`] owns the port. [`read_sample`](SerialSource::read_sample) returns the next
//! sample, or says why there is none:
//!
//! - [`StreamStop::Idle`]: no sample for the idle timeout. The port is still open; reading again
//!   resumes (the firmware may be paused, or waiting for its `Serial` to be opened).
//! - [`StreamStop::Disconnected`]: the device is gone (end of file, I/O error, hang-up: what an
//!   unplugged USB-serial adapter gives). Every line completed before that was delivered; an
//!   unterminated last line is counted as [`GarbageKind::Truncated`]. Reading again returns the
//!   same stop.
//!
//! Garbage never stops the stream; it is counted ([`SerialSource::counts`]).
//!
//! [`write_calibration`](SerialSource::write_calibration) sends a [`CalibrationPacket`] and
//! waits for the firmware's echo (see [`echo`](super::echo)).

use std::collections::VecDeque;
use std::fmt;
use std::io::{self, ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use serialport::{ClearBuffer, SerialPort};

use super::counts::{GarbageKind, LineCounts};
use super::device::{DeviceSpec, Protocol};
use super::echo::{EchoCheck, EchoProgress, VerifyFailure};
use super::lines::{LineSplitter, Piece};
use super::motioncal::Echo;
use super::packet::{CalibrationPacket, encode};
use super::sample::Sample;
use super::stream::{Parsed, StreamParser};

/// How long [`SerialSource::read_sample`] waits for a sample before reporting
/// [`StreamStop::Idle`], unless set otherwise.
pub const DEFAULT_IDLE_TIMEOUT: Duration = Duration::from_secs(2);

/// Bytes asked of the port per read.
const READ_CHUNK: usize = 1024;

/// The byte link under a [`SerialSource`]: a serial port, or any reader with a timeout.
pub trait Link: Read + Write {
    /// Sets how long one `read` (or `write`) may wait before failing with
    /// [`ErrorKind::TimedOut`].
    fn set_timeout(&mut self, timeout: Duration) -> io::Result<()>;

    /// Discards bytes received but not read yet.
    fn discard_input(&mut self) -> io::Result<()>;
}

impl Link for Box<dyn SerialPort> {
    fn set_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        SerialPort::set_timeout(self.as_mut(), timeout).map_err(io::Error::from)
    }

    fn discard_input(&mut self) -> io::Result<()> {
        self.clear(ClearBuffer::Input).map_err(io::Error::from)
    }
}

/// A sample and when it arrived.
#[derive(Clone, Debug, PartialEq)]
pub struct Received {
    /// Seconds since the source was opened, when the read that completed the line returned
    /// (lines that arrive in one read share it).
    pub host_s: f64,
    /// The sample.
    pub sample: Sample,
}

/// Why [`SerialSource::read_sample`] returned no sample.
#[derive(Clone, Debug, PartialEq)]
pub enum StreamStop {
    /// No sample within the idle timeout; the port is open, and reading may go on.
    Idle {
        /// How long was waited (s).
        waited_s: f64,
    },
    /// The device disconnected; nothing more will come.
    Disconnected {
        /// What the port said (`end of file`, `Broken pipe`, `Input/output error` …).
        reason: String,
    },
}

impl fmt::Display for StreamStop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StreamStop::Idle { waited_s } => write!(f, "no sample for {waited_s:.2} s"),
            StreamStop::Disconnected { reason } => write!(f, "device disconnected: {reason}"),
        }
    }
}

/// The port could not be opened.
#[derive(Debug)]
pub struct OpenError {
    /// The path tried.
    pub path: String,
    /// What the serial port library said.
    pub source: serialport::Error,
}

impl fmt::Display for OpenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot open serial port {}: {}", self.path, self.source)
    }
}

impl std::error::Error for OpenError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.source)
    }
}

/// A calibration write that was not confirmed.
#[derive(Debug)]
pub enum WriteError {
    /// Discarding input or sending the packet failed.
    Io(io::Error),
    /// The device disconnected (before or while waiting for the echo).
    Disconnected {
        /// What the port said.
        reason: String,
    },
    /// The echo did not confirm the calibration.
    Verification(VerifyFailure),
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WriteError::Io(e) => write!(f, "sending the calibration failed: {e}"),
            WriteError::Disconnected { reason } => write!(f, "device disconnected: {reason}"),
            WriteError::Verification(v) => write!(f, "calibration not confirmed: {v}"),
        }
    }
}

impl std::error::Error for WriteError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            WriteError::Io(e) => Some(e),
            WriteError::Disconnected { .. } => None,
            WriteError::Verification(v) => Some(v),
        }
    }
}

/// A confirmed calibration write.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verified {
    /// From sending the packet to the confirming echo (s).
    pub elapsed_s: f64,
    /// Echoes skipped on the way: stale ones, and a garbled one let pass
    /// (see [`echo`](super::echo)).
    pub echoes_skipped: u32,
}

/// Why [`SerialSource::next_line`] stopped waiting.
enum Wait {
    Deadline,
    Disconnected(String),
}

/// Samples from a serial line stream, with counters; see the [module docs](self).
pub struct SerialSource<L: Link = Box<dyn SerialPort>> {
    link: L,
    splitter: LineSplitter,
    parser: StreamParser,
    opened: Instant,
    idle_timeout: Duration,
    /// Time of the read that completed the lines now in the splitter (s since `opened`).
    chunk_host_s: f64,
    /// Samples that arrived while a calibration write waited for its echo.
    queued: VecDeque<Received>,
    disconnected: Option<String>,
    last_stop: Option<StreamStop>,
    /// The last `Cal1:` and `Cal2:` echoes seen: the calibration the firmware last showed.
    last_echoes: [Option<Echo>; 2],
    /// Bytes read from the link.
    bytes_received: u64,
    /// The start of the last garbage line, escaped.
    last_garbage: Option<String>,
}

/// At most this many bytes of a garbage line are kept for messages.
const GARBAGE_EXCERPT_BYTES: usize = 40;

/// Opens the port at `path` (8N1, no flow control) and reads `protocol` lines from it.
pub fn open(path: &str, baud: u32, protocol: Protocol) -> Result<SerialSource, OpenError> {
    let port = serialport::new(path, baud)
        .timeout(DEFAULT_IDLE_TIMEOUT)
        .open()
        .map_err(|source| OpenError {
            path: path.to_string(),
            source,
        })?;
    Ok(SerialSource::new(port, protocol))
}

impl DeviceSpec {
    /// Opens the device this spec names; see [`open`].
    pub fn open(&self) -> Result<SerialSource, OpenError> {
        open(&self.path, self.baud, self.protocol.clone())
    }
}

impl<L: Link> SerialSource<L> {
    /// Reads `protocol` lines from `link`, with [`DEFAULT_IDLE_TIMEOUT`]. Host times count
    /// from now.
    pub fn new(link: L, protocol: Protocol) -> Self {
        SerialSource {
            link,
            splitter: LineSplitter::new(),
            parser: StreamParser::new(protocol),
            opened: Instant::now(),
            idle_timeout: DEFAULT_IDLE_TIMEOUT,
            chunk_host_s: 0.0,
            queued: VecDeque::new(),
            disconnected: None,
            last_stop: None,
            last_echoes: [None; 2],
            bytes_received: 0,
            last_garbage: None,
        }
    }

    /// Bytes received so far (lines, garbage and all).
    pub fn bytes_received(&self) -> u64 {
        self.bytes_received
    }

    /// The start of the last garbage line received (at most 40 bytes, control characters and invalid UTF-8
    /// escaped), for messages that say what the device sends.
    pub fn last_garbage(&self) -> Option<&str> {
        self.last_garbage.as_deref()
    }

    /// Sets how long [`read_sample`](Self::read_sample) waits for a sample.
    pub fn set_idle_timeout(&mut self, timeout: Duration) {
        self.idle_timeout = timeout;
    }

    /// The line protocol read.
    pub fn protocol(&self) -> &Protocol {
        self.parser.protocol()
    }

    /// Counters of the lines read so far.
    pub fn counts(&self) -> &LineCounts {
        self.parser.counts()
    }

    /// Names of the native CSV `i_<name>` columns, in the order of [`Sample::inputs`].
    pub fn input_names(&self) -> Vec<&str> {
        self.parser.csv().input_names()
    }

    /// `(key, value)` of the native CSV stream's `# key: value` lines so far.
    pub fn metadata(&self) -> &[(String, String)] {
        self.parser.csv().metadata()
    }

    /// Why the last [`read_sample`](Self::read_sample) returned no sample; `None` after a sample.
    pub fn last_stop(&self) -> Option<&StreamStop> {
        self.last_stop.as_ref()
    }

    /// What the port said when the device disconnected; `None` while it is connected.
    pub fn disconnected(&self) -> Option<&str> {
        self.disconnected.as_deref()
    }

    /// The next sample, waiting at most the idle timeout for it.
    pub fn read_sample(&mut self) -> Result<Received, StreamStop> {
        if let Some(received) = self.queued.pop_front() {
            self.last_stop = None;
            return Ok(received);
        }
        let start = Instant::now();
        let stop = loop {
            match self.next_line(start + self.idle_timeout) {
                Ok((host_s, Parsed::Sample(sample))) => {
                    self.last_stop = None;
                    return Ok(Received { host_s, sample });
                }
                Ok(_) => {}
                Err(Wait::Deadline) => {
                    break StreamStop::Idle {
                        waited_s: start.elapsed().as_secs_f64(),
                    };
                }
                Err(Wait::Disconnected(reason)) => break StreamStop::Disconnected { reason },
            }
        };
        self.last_stop = Some(stop.clone());
        Err(stop)
    }

    /// Sends `packet` and waits up to `timeout` for the firmware's `Cal1:`/`Cal2:` echo to
    /// confirm it. Adafruit's sketches print their echo about once a second, so give it a few
    /// seconds.
    ///
    /// Input received but not yet read when the packet goes out is discarded: it may hold echoes
    /// of the old calibration. Echoes identical to the last ones read before (see
    /// [`last_echoes`](Self::last_echoes)) are taken as stale. Samples that arrive while waiting
    /// are kept for [`read_sample`](Self::read_sample).
    pub fn write_calibration(
        &mut self,
        packet: &CalibrationPacket,
        timeout: Duration,
    ) -> Result<Verified, WriteError> {
        if let Some(reason) = &self.disconnected {
            return Err(WriteError::Disconnected {
                reason: reason.clone(),
            });
        }
        while let Some(piece) = self.splitter.next_piece() {
            if let Some((host_s, Parsed::Sample(sample))) = self.parse_piece(piece) {
                self.queued.push_back(Received { host_s, sample });
            }
        }
        self.link.discard_input().map_err(WriteError::Io)?;
        if self.splitter.take_partial() {
            self.parser.count_garbage(GarbageKind::Truncated);
        }
        let start = Instant::now();
        self.link.set_timeout(timeout).map_err(WriteError::Io)?;
        self.link
            .write_all(&encode(packet))
            .and_then(|()| self.link.flush())
            .map_err(WriteError::Io)?;
        let previous: Vec<Echo> = self.last_echoes.iter().flatten().copied().collect();
        let mut check = EchoCheck::new(packet, &previous);
        loop {
            let progress = match self.next_line(start + timeout) {
                Ok((host_s, Parsed::Sample(sample))) => {
                    self.queued.push_back(Received { host_s, sample });
                    continue;
                }
                Ok((_, Parsed::Echo(echo))) => check.feed(&echo),
                Ok((_, Parsed::BadEcho { echo, kind, line })) => {
                    check.feed_corrupted(echo, kind, &line)
                }
                Ok(_) => continue,
                Err(Wait::Deadline) => {
                    let waited_s = start.elapsed().as_secs_f64();
                    return Err(WriteError::Verification(check.timed_out(waited_s)));
                }
                Err(Wait::Disconnected(reason)) => {
                    return Err(WriteError::Disconnected { reason });
                }
            };
            match progress {
                EchoProgress::Pending => {}
                EchoProgress::Confirmed => {
                    return Ok(Verified {
                        elapsed_s: start.elapsed().as_secs_f64(),
                        echoes_skipped: check.echoes_skipped(),
                    });
                }
                EchoProgress::Failed(failure) => return Err(WriteError::Verification(failure)),
            }
        }
    }

    /// The last `Cal1:` and `Cal2:` echoes read: the calibration the firmware last showed.
    pub fn last_echoes(&self) -> impl Iterator<Item = &Echo> {
        self.last_echoes.iter().flatten()
    }

    /// Parses a piece from the splitter; `None` for an overlong line (counted).
    fn parse_piece(&mut self, piece: Piece) -> Option<(f64, Parsed)> {
        match piece {
            Piece::Line(line) => {
                let parsed = self.parser.parse(&line);
                match &parsed {
                    Parsed::Echo(echo) => self.last_echoes[echo.kind().index()] = Some(*echo),
                    Parsed::Garbage(_) | Parsed::BadEcho { .. } => {
                        let start = &line[..line.len().min(GARBAGE_EXCERPT_BYTES)];
                        let mut text: String =
                            String::from_utf8_lossy(start).escape_debug().collect();
                        if line.len() > start.len() {
                            text.push('…');
                        }
                        self.last_garbage = Some(text);
                    }
                    _ => {}
                }
                Some((self.chunk_host_s, parsed))
            }
            Piece::Overlong => {
                self.parser.count_garbage(GarbageKind::Overlong);
                None
            }
        }
    }

    /// The next line, reading until `deadline`.
    fn next_line(&mut self, deadline: Instant) -> Result<(f64, Parsed), Wait> {
        let mut buf = [0u8; READ_CHUNK];
        loop {
            if let Some(piece) = self.splitter.next_piece() {
                match self.parse_piece(piece) {
                    Some(line) => return Ok(line),
                    None => continue,
                }
            }
            if let Some(reason) = &self.disconnected {
                return Err(Wait::Disconnected(reason.clone()));
            }
            let Some(remaining) = deadline.checked_duration_since(Instant::now()) else {
                return Err(Wait::Deadline);
            };
            if let Err(e) = self.link.set_timeout(remaining) {
                self.disconnect(e.to_string());
                continue;
            }
            match self.link.read(&mut buf) {
                Ok(0) => self.disconnect("end of file".to_string()),
                Ok(n) => {
                    self.chunk_host_s = self.opened.elapsed().as_secs_f64();
                    self.bytes_received += n as u64;
                    self.splitter.push(&buf[..n]);
                }
                Err(e) if is_transient(e.kind()) => {}
                Err(e) => self.disconnect(e.to_string()),
            }
        }
    }

    fn disconnect(&mut self, reason: String) {
        if self.splitter.take_partial() {
            self.parser.count_garbage(GarbageKind::Truncated);
        }
        self.disconnected = Some(reason);
    }
}

/// Read errors that are no disconnect: a timeout, a signal, a non-blocking port with nothing.
fn is_transient(kind: ErrorKind) -> bool {
    matches!(
        kind,
        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
    )
}

impl<L: Link> Iterator for SerialSource<L> {
    type Item = Received;

    /// The next sample; `None` at an idle timeout or a disconnect ([`SerialSource::last_stop`]
    /// tells which). After an idle timeout, iterating again resumes.
    fn next(&mut self) -> Option<Received> {
        self.read_sample().ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::motioncal::EchoKind;
    use crate::serial::packet::PACKET_LEN;
    use std::cell::RefCell;
    use std::rc::Rc;

    /// A link that plays scripted reads; running out of script is silence until the timeout.
    #[derive(Default)]
    struct Script {
        reads: VecDeque<io::Result<Vec<u8>>>,
        /// Reads queued each time a whole packet has been written (the firmware's answer).
        answer: Vec<io::Result<Vec<u8>>>,
        written: Vec<u8>,
        timeout: Duration,
    }

    #[derive(Clone, Default)]
    struct Shared(Rc<RefCell<Script>>);

    impl Shared {
        fn push(&self, bytes: &[u8]) {
            self.0.borrow_mut().reads.push_back(Ok(bytes.to_vec()));
        }

        fn push_err(&self, kind: ErrorKind) {
            self.0.borrow_mut().reads.push_back(Err(kind.into()));
        }

        fn answer(&self, bytes: &[u8]) {
            self.0.borrow_mut().answer.push(Ok(bytes.to_vec()));
        }
    }

    impl Read for Shared {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let next = self.0.borrow_mut().reads.pop_front();
            match next {
                Some(Ok(bytes)) => {
                    buf[..bytes.len()].copy_from_slice(&bytes);
                    Ok(bytes.len())
                }
                Some(Err(e)) => Err(e),
                None => {
                    std::thread::sleep(self.0.borrow().timeout);
                    Err(ErrorKind::TimedOut.into())
                }
            }
        }
    }

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let mut s = self.0.borrow_mut();
            s.written.extend_from_slice(buf);
            if s.written.len().is_multiple_of(PACKET_LEN) {
                let answer = std::mem::take(&mut s.answer);
                s.reads.extend(answer);
            }
            Ok(buf.len())
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Link for Shared {
        fn set_timeout(&mut self, timeout: Duration) -> io::Result<()> {
            self.0.borrow_mut().timeout = timeout;
            Ok(())
        }

        fn discard_input(&mut self) -> io::Result<()> {
            self.0.borrow_mut().reads.clear();
            Ok(())
        }
    }

    fn source(protocol: Protocol) -> (SerialSource<Shared>, Shared) {
        let link = Shared::default();
        let mut source = SerialSource::new(link.clone(), protocol);
        source.set_idle_timeout(Duration::from_millis(20));
        (source, link)
    }

    fn packet() -> CalibrationPacket {
        CalibrationPacket::magnetic(
            [1.5, -2.25, 30.0],
            48.0,
            [[1.1, 0.02, 0.0], [0.02, 0.9, -0.01], [0.0, -0.01, 1.0]],
        )
        .unwrap()
    }

    const CAL1: &[u8] = b"Cal1:0.000,0.000,0.000,0.000,0.000,0.000,1.500,-2.250,30.000,48.000\r\n";
    const CAL2: &[u8] =
        b"Cal2:1.1000,0.0200,0.0000,0.0200,0.9000,-0.0100,0.0000,-0.0100,1.0000\r\n";
    const OLD_CAL1: &[u8] =
        b"Cal1:0.000,0.000,0.000,0.000,0.000,0.000,0.000,0.000,0.000,50.000\r\n";

    #[test]
    fn delivers_every_complete_line_then_reports_the_disconnect() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.push(b"Raw:0,0,8192,0,0,0,100,200,300\r\nRaw:0,0,8192,0,");
        link.push(b"0,0,101,201,301\r\nUni:1,2\r\nRaw:0,0,81");
        link.push(&[]);
        let first = s.read_sample().unwrap();
        assert_eq!(
            first.sample.mag_ut.map(|v| (v * 10.0).round()),
            [100.0, 200.0, 300.0]
        );
        assert!(first.host_s >= 0.0);
        assert_eq!(s.read_sample().unwrap().sample.mag_ut[0].round(), 10.0);
        let stop = StreamStop::Disconnected {
            reason: "end of file".into(),
        };
        assert_eq!(s.read_sample(), Err(stop.clone()));
        assert_eq!(s.read_sample(), Err(stop.clone()), "stays disconnected");
        assert_eq!(s.last_stop(), Some(&stop));
        assert_eq!(s.disconnected(), Some("end of file"));
        let c = s.counts();
        assert_eq!((c.lines, c.samples), (4, 2));
        assert_eq!(c.garbage.get(GarbageKind::Truncated), 1);
        assert_eq!(c.garbage.get(GarbageKind::Unrecognized), 1);
    }

    #[test]
    fn an_io_error_is_a_disconnect_and_timeouts_are_not() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.push_err(ErrorKind::TimedOut);
        link.push_err(ErrorKind::Interrupted);
        link.push(b"Raw:0,0,0,0,0,0,1,2,3\n");
        link.push_err(ErrorKind::BrokenPipe);
        assert!(s.read_sample().is_ok());
        let Err(StreamStop::Disconnected { reason }) = s.read_sample() else {
            panic!("expected a disconnect");
        };
        assert_eq!(reason, io::Error::from(ErrorKind::BrokenPipe).to_string());
        assert_eq!(s.counts().garbage.total(), 0);
    }

    #[test]
    fn idle_is_reported_and_reading_resumes() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.push(b"garbage only\n");
        let Err(StreamStop::Idle { waited_s }) = s.read_sample() else {
            panic!("expected idle");
        };
        assert!(waited_s >= 0.019, "{waited_s}");
        assert!(s.disconnected().is_none());
        link.push(b"Raw:0,0,0,0,0,0,1,2,3\n");
        let samples: Vec<Received> = s.by_ref().collect();
        assert_eq!(samples.len(), 1);
        assert!(matches!(s.last_stop(), Some(StreamStop::Idle { .. })));
    }

    #[test]
    fn bytes_and_the_last_garbage_line_are_kept_for_messages() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.push(b"Uni:1,2\n\x1b[2Jhello\xff\n");
        assert!(s.read_sample().is_err());
        assert_eq!(s.bytes_received(), 19);
        assert_eq!(s.last_garbage(), Some("\\u{1b}[2Jhello\u{fffd}"));
    }

    #[test]
    fn overlong_noise_is_counted_and_skipped() {
        let (mut s, link) = source(Protocol::Csv);
        link.push(b"mx,my,mz\n");
        link.push(&[b'7'; 1000]);
        link.push(&[b'7'; 1000]);
        link.push(b"\n1,2,3\n");
        assert_eq!(s.read_sample().unwrap().sample.mag_ut, [1.0, 2.0, 3.0]);
        assert_eq!(s.counts().garbage.get(GarbageKind::Overlong), 1);
    }

    #[test]
    fn a_calibration_is_confirmed_and_samples_meanwhile_are_kept() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.push(b"Raw:0,0,0,0,0,0,1,1,1\nRaw:0,0,0,0,0,0,2,2,2\nRaw:0,0");
        link.push(OLD_CAL1);
        link.answer(b",0,0,0,0,3,3,3\nRaw:0,0,0,0,0,0,4,4,4\nWrote calibration\n");
        link.answer(CAL1);
        link.answer(CAL2);
        assert!(
            s.read_sample().is_ok(),
            "sample 1 read; sample 2 and a partial line buffered"
        );
        let verified = s
            .write_calibration(&packet(), Duration::from_secs(1))
            .unwrap();
        assert_eq!(
            verified.echoes_skipped, 0,
            "the old echo was discarded unread"
        );
        assert_eq!(link.0.borrow().written, encode(&packet()));
        let rest: Vec<f64> = s.by_ref().map(|r| r.sample.mag_ut[0]).collect();
        assert_eq!(
            rest.len(),
            2,
            "sample 2 and sample 4; sample 3 lost its start"
        );
        assert!((rest[0] - 0.2).abs() < 1e-12 && (rest[1] - 0.4).abs() < 1e-12);
        let g = &s.counts().garbage;
        assert_eq!(g.get(GarbageKind::Truncated), 1);
        assert_eq!(
            g.get(GarbageKind::Unrecognized),
            2,
            "the tail of sample 3, the chatter"
        );
    }

    #[test]
    fn a_wrong_echo_fails_with_what_differs() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.answer(CAL2);
        link.answer(OLD_CAL1); // may be the old calibration: waited past
        link.answer(OLD_CAL1);
        let started = Instant::now();
        let Err(WriteError::Verification(VerifyFailure::Mismatch { fields, .. })) =
            s.write_calibration(&packet(), Duration::from_millis(40))
        else {
            panic!("expected a mismatch");
        };
        assert!(
            started.elapsed() >= Duration::from_millis(40),
            "failed at the timeout"
        );
        let names: Vec<&str> = fields.iter().map(|m| m.field).collect();
        assert_eq!(
            names,
            [
                "hard_iron_ut[0]",
                "hard_iron_ut[1]",
                "hard_iron_ut[2]",
                "field_ut"
            ]
        );
    }

    #[test]
    fn echoes_of_the_calibration_shown_before_are_stale() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.push(OLD_CAL1);
        link.push(b"Raw:0,0,0,0,0,0,1,1,1\n");
        assert!(s.read_sample().is_ok());
        assert_eq!(s.last_echoes().count(), 1);
        for _ in 0..3 {
            link.answer(OLD_CAL1);
        }
        link.answer(CAL2);
        link.answer(CAL1);
        let verified = s
            .write_calibration(&packet(), Duration::from_secs(1))
            .unwrap();
        assert_eq!(verified.echoes_skipped, 3);
        for _ in 0..3 {
            link.answer(CAL1);
        }
        let mut other = packet();
        other.field_ut = 47.0;
        let Err(WriteError::Verification(failure)) =
            s.write_calibration(&other, Duration::from_millis(30))
        else {
            panic!("expected a verification failure");
        };
        assert!(
            matches!(
                failure,
                VerifyFailure::Unchanged {
                    echo: EchoKind::Cal1,
                    ..
                }
            ),
            "{failure:?}"
        );
    }

    #[test]
    fn no_echo_times_out_and_a_gone_device_is_refused() {
        let (mut s, link) = source(Protocol::MotionCal);
        link.answer(CAL1);
        let Err(WriteError::Verification(failure)) =
            s.write_calibration(&packet(), Duration::from_millis(30))
        else {
            panic!("expected a verification failure");
        };
        assert!(
            matches!(failure, VerifyFailure::Missing { ref missing, .. } if missing.len() == 1)
        );
        link.push(&[]);
        assert!(s.read_sample().is_err());
        assert!(matches!(
            s.write_calibration(&packet(), Duration::from_millis(30)),
            Err(WriteError::Disconnected { .. })
        ));
    }
}
