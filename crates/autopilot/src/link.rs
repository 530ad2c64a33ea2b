//! A MAVLink connection over any byte port: frames cut from a stream as bytes arrive ([`FrameBuffer`]), messages
//! sent with a sequence number ([`Connection::send`]), the autopilot found by its heartbeat
//! ([`Connection::wait_heartbeat`]), and an in-memory duplex for tests ([`duplex`]).
//!
//! A port is any `Read + Write`: a read that fails with `WouldBlock`, `TimedOut` or `Interrupted` means "nothing
//! yet" (a serial port with a short timeout, a non-blocking pseudo-terminal, [`MemoryPort`]); `Ok(0)` means the
//! other side is gone.

use std::collections::VecDeque;
use std::fmt;
use std::io::{self, ErrorKind, Read, Write};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError, channel};
use std::time::{Duration, Instant};

use mavlink::MavHeader;
use mavlink::dialects::common::{MavAutopilot, MavMessage};

/// The two start bytes, MAVLink 2 and MAVLink 1.
const STX_V2: u8 = 0xFD;
const STX_V1: u8 = 0xFE;

/// Bytes of a frame around its payload: MAVLink 2 (start, 9 header bytes, 2 checksum) and 13 more when signed;
/// MAVLink 1 (start, 5 header bytes, 2 checksum).
fn frame_len(buf: &[u8]) -> Option<usize> {
    match buf[0] {
        STX_V2 if buf.len() >= 3 => {
            let signed = buf[2] & 0x01 != 0;
            Some(12 + usize::from(buf[1]) + if signed { 13 } else { 0 })
        }
        STX_V1 if buf.len() >= 2 => Some(8 + usize::from(buf[1])),
        _ => None,
    }
}

/// Frames cut from a byte stream as it arrives: bytes that start no valid frame (a bad checksum, a message the
/// common dialect lacks, text) are skipped one at a time, so the next frame is found whatever came before it.
#[derive(Debug, Default)]
pub struct FrameBuffer {
    buf: Vec<u8>,
    /// Bytes pushed.
    pub bytes: u64,
    /// Frames read.
    pub frames: u64,
    /// Bytes skipped (no frame started there).
    pub skipped: u64,
}

impl FrameBuffer {
    /// An empty buffer.
    pub fn new() -> FrameBuffer {
        FrameBuffer::default()
    }

    /// Adds bytes received.
    pub fn push(&mut self, bytes: &[u8]) {
        self.bytes += bytes.len() as u64;
        self.buf.extend_from_slice(bytes);
    }

    /// The next whole frame's message, if one has arrived.
    pub fn next_message(&mut self) -> Option<(MavHeader, MavMessage)> {
        loop {
            let start = self.buf.iter().position(|b| *b == STX_V2 || *b == STX_V1);
            let Some(start) = start else {
                self.skipped += self.buf.len() as u64;
                self.buf.clear();
                return None;
            };
            self.skipped += start as u64;
            self.buf.drain(..start);
            let len = frame_len(&self.buf)?;
            if self.buf.len() < len {
                return None;
            }
            // The reader skips a frame whose checksum fails and takes the next valid one: a frame cut short (a
            // sender that gave up mid-frame) can hold a whole short frame in its declared length. Only a frame that
            // starts here and fills that length is this one; else the scan goes on from the next byte, and the
            // short frame is found in its turn.
            let message = mavlink::MavlinkReader::new(&self.buf[..len])
                .read_any_raw_message::<MavMessage>()
                .ok()
                .filter(|raw| match raw {
                    mavlink::MAVLinkMessageRaw::V1(f) => f.raw_bytes().len() == len,
                    mavlink::MAVLinkMessageRaw::V2(f) => f.raw_bytes().len() == len,
                })
                .and_then(|raw| {
                    let msg = <MavMessage as mavlink::Message>::parse(
                        raw.version(),
                        raw.message_id(),
                        raw.payload(),
                    )
                    .ok()?;
                    let header = MavHeader {
                        system_id: raw.system_id(),
                        component_id: raw.component_id(),
                        sequence: raw.sequence(),
                    };
                    Some((header, msg))
                });
            match message {
                Some(message) => {
                    self.buf.drain(..len);
                    self.frames += 1;
                    return Some(message);
                }
                None => {
                    self.skipped += 1;
                    self.buf.drain(..1);
                }
            }
        }
    }
}

/// Which autopilot firmware is on the other end, by its heartbeat's `autopilot` field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Autopilot {
    /// ArduPilot (`MAV_AUTOPILOT_ARDUPILOTMEGA`).
    ArduPilot,
    /// PX4 (`MAV_AUTOPILOT_PX4`).
    Px4,
}

impl Autopilot {
    /// The autopilot a heartbeat names, if it is one of the two.
    pub fn of(field: MavAutopilot) -> Option<Autopilot> {
        match field {
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Some(Autopilot::ArduPilot),
            MavAutopilot::MAV_AUTOPILOT_PX4 => Some(Autopilot::Px4),
            _ => None,
        }
    }

    /// Its heartbeat's `autopilot` field.
    pub fn field(self) -> MavAutopilot {
        match self {
            Autopilot::ArduPilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            Autopilot::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
        }
    }

    /// `ardupilot` or `px4`.
    pub fn name(self) -> &'static str {
        match self {
            Autopilot::ArduPilot => "ardupilot",
            Autopilot::Px4 => "px4",
        }
    }
}

impl fmt::Display for Autopilot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Autopilot::ArduPilot => "ArduPilot",
            Autopilot::Px4 => "PX4",
        })
    }
}

/// Why the link gave no message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinkError {
    /// Nothing at all arrived.
    #[error(
        "{port}: nothing received in {waited_s:.1} s: is the autopilot powered and on this port (USB, or a \
         telemetry port with MAVLink enabled), at the right baud rate?"
    )]
    Silent {
        /// The port.
        port: String,
        /// How long was waited, s.
        waited_s: f64,
    },
    /// Bytes arrived, and no MAVLink frame in them.
    #[error(
        "{port}: {bytes} bytes in {waited_s:.1} s and no MAVLink frame in them (no valid 0xFD or 0xFE start, length \
         and checksum): is it an autopilot, at the right baud rate (ArduPilot's default 115200, PX4's USB any)? \
         It sends: {excerpt}"
    )]
    NotMavlink {
        /// The port.
        port: String,
        /// Bytes received.
        bytes: u64,
        /// How long was waited, s.
        waited_s: f64,
        /// The start of what arrived, escaped.
        excerpt: String,
    },
    /// MAVLink arrived, and no heartbeat of an ArduPilot or PX4 autopilot.
    #[error(
        "{port}: {frames} MAVLink frames in {waited_s:.1} s and no heartbeat of an ArduPilot or PX4 autopilot{seen}: \
         name the autopilot (mavlink:PATH:BAUD:ardupilot or :px4) if it is one"
    )]
    NoAutopilot {
        /// The port.
        port: String,
        /// Frames received.
        frames: u64,
        /// How long was waited, s.
        waited_s: f64,
        /// What heartbeats were seen, if any (`, only …`).
        seen: String,
    },
    /// The other side is gone.
    #[error("{port}: disconnected ({reason})")]
    Disconnected {
        /// The port.
        port: String,
        /// What the port said.
        reason: String,
    },
}

/// Frames the autopilot sent and the link lost, counted from the gaps in its sequence numbers (MAVLink numbers each
/// sender's frames 0–255 in turn).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkLoss {
    /// Frames received from the autopilot.
    pub received: u64,
    /// Frames it numbered between them that never came.
    pub lost: u64,
}

impl LinkLoss {
    /// The share of the autopilot's frames lost.
    pub fn share(&self) -> f64 {
        self.lost as f64 / (self.received + self.lost).max(1) as f64
    }
}

/// A gap of this many sequence numbers or more is no loss: the autopilot's numbering restarted (a reboot) or a
/// frame came out of order (UDP) or twice.
const SEQUENCE_RESTART: u8 = 128;
/// Frames further apart than this are not compared: the link was silent (a reboot, which restarts the numbering,
/// or a dead link, which the recorder says itself).
const SEQUENCE_SILENCE: Duration = Duration::from_millis(500);
/// A gap that ends on one of these first numbers may be a reboot's restart of the numbering, not a loss: it is
/// undone if the autopilot's clock is found to have gone back within [`SUSPECT_FOR`] (the recorder sees it in the
/// first compass message after the reboot, which may wait for its streams to be asked for again).
const RESTART_NUMBERS: u8 = 16;
/// See [`RESTART_NUMBERS`].
const SUSPECT_FOR: Duration = Duration::from_secs(5);

/// A MAVLink connection to one autopilot over `P`; see the [module docs](self).
pub struct Connection<P> {
    port: P,
    name: String,
    frames: FrameBuffer,
    /// The first bytes received, for a message when they are no MAVLink.
    first_bytes: Vec<u8>,
    sequence: u8,
    /// The autopilot's system and component id, once its heartbeat arrived.
    target: Option<(u8, u8)>,
    autopilot: Option<Autopilot>,
    disconnected: Option<String>,
    /// Messages received while a caller waited for something else (the newest 10000).
    pub backlog: VecDeque<(MavHeader, MavMessage)>,
    /// The autopilot's frames received and lost, once its heartbeat came.
    loss: LinkLoss,
    /// The autopilot's last sequence number, and when its frame was read.
    last_sequence: Option<(u8, Instant)>,
    /// The last gap counted that ended on one of the first numbers, and when (a reboot's, if the autopilot's clock
    /// is found to have restarted soon after: [`Connection::numbering_restarted`]).
    suspect_gap: Option<(u64, Instant)>,
}

/// Our own ids: a ground station (system 255) of MAVLink's "mission planner" component (190).
const OWN_SYSTEM: u32 = 255;
const OWN_COMPONENT: u8 = 190;
/// Messages kept in the backlog at most.
const BACKLOG: usize = 10_000;

impl<P: Read + Write> Connection<P> {
    /// A connection over `port`, named `name` in messages.
    pub fn new(port: P, name: &str) -> Connection<P> {
        Connection {
            port,
            name: name.to_owned(),
            frames: FrameBuffer::new(),
            first_bytes: Vec::new(),
            sequence: 0,
            target: None,
            autopilot: None,
            disconnected: None,
            backlog: VecDeque::new(),
            loss: LinkLoss::default(),
            last_sequence: None,
            suspect_gap: None,
        }
    }

    /// The autopilot's frames received and lost on the link so far (from its heartbeat on).
    pub fn link_loss(&self) -> LinkLoss {
        self.loss
    }

    /// Says that the autopilot restarted (its clock went back): the gap in its numbering that a reboot's first
    /// frames made, if one was counted, was no loss.
    pub fn numbering_restarted(&mut self) {
        if let Some((gap, at)) = self.suspect_gap.take()
            && at.elapsed() < SUSPECT_FOR
        {
            self.loss.lost -= gap;
        }
    }

    /// Counts a frame with `header` if the autopilot sent it.
    fn count(&mut self, header: &MavHeader) {
        if self.target != Some((header.system_id as u8, header.component_id)) {
            return;
        }
        let now = Instant::now();
        if let Some((last, at)) = self.last_sequence {
            let gap = header.sequence.wrapping_sub(last).wrapping_sub(1);
            if gap > 0 && gap < SEQUENCE_RESTART && now.duration_since(at) < SEQUENCE_SILENCE {
                self.loss.lost += u64::from(gap);
                if header.sequence < RESTART_NUMBERS {
                    self.suspect_gap = Some((u64::from(gap), now));
                }
            }
        }
        self.last_sequence = Some((header.sequence, now));
        self.loss.received += 1;
    }

    /// The port's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The autopilot, once its heartbeat arrived (or as set).
    pub fn autopilot(&self) -> Option<Autopilot> {
        self.autopilot
    }

    /// The autopilot's system and component id, once its heartbeat arrived.
    pub fn target(&self) -> Option<(u8, u8)> {
        self.target
    }

    /// Bytes and frames received so far.
    pub fn received(&self) -> (u64, u64) {
        (self.frames.bytes, self.frames.frames)
    }

    /// Sends `msg` as a MAVLink 2 frame.
    pub fn send(&mut self, msg: &MavMessage) -> Result<(), LinkError> {
        let header = MavHeader {
            system_id: OWN_SYSTEM,
            component_id: OWN_COMPONENT,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let mut bytes = Vec::with_capacity(64);
        mavlink::write_v2_msg(&mut bytes, header, msg).expect("writing to a Vec");
        self.port
            .write_all(&bytes)
            .and_then(|()| self.port.flush())
            .map_err(|e| LinkError::Disconnected {
                port: self.name.clone(),
                reason: e.to_string(),
            })
    }

    /// The next message, waiting until `deadline`; `Ok(None)` when none came by then.
    pub fn next_message(
        &mut self,
        deadline: Instant,
    ) -> Result<Option<(MavHeader, MavMessage)>, LinkError> {
        let mut buf = [0u8; 512];
        loop {
            if let Some(m) = self.frames.next_message() {
                self.count(&m.0);
                return Ok(Some(m));
            }
            if let Some(reason) = &self.disconnected {
                return Err(LinkError::Disconnected {
                    port: self.name.clone(),
                    reason: reason.clone(),
                });
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            match self.port.read(&mut buf) {
                Ok(0) => self.disconnected = Some("end of file".to_owned()),
                Ok(n) => {
                    if self.first_bytes.len() < 64 {
                        let take = n.min(64 - self.first_bytes.len());
                        self.first_bytes.extend_from_slice(&buf[..take]);
                    }
                    self.frames.push(&buf[..n]);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(2));
                }
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::Interrupted) => {}
                Err(e) => self.disconnected = Some(e.to_string()),
            }
        }
    }

    /// Keeps a message a caller did not wait for.
    pub(crate) fn keep(&mut self, m: (MavHeader, MavMessage)) {
        if self.backlog.len() >= BACKLOG {
            self.backlog.pop_front();
        }
        self.backlog.push_back(m);
    }

    /// Waits up to `timeout` for the heartbeat of an ArduPilot or PX4 autopilot and returns which; with `assume`,
    /// any autopilot's heartbeat (component 1, the autopilot's) will do and is taken to be that one. Other messages
    /// go to the [`backlog`](Self::backlog). The error says whether nothing, no MAVLink or no autopilot arrived.
    pub fn wait_heartbeat(
        &mut self,
        timeout: Duration,
        assume: Option<Autopilot>,
    ) -> Result<Autopilot, LinkError> {
        let start = Instant::now();
        let deadline = start + timeout;
        let mut seen = Vec::new();
        while let Some((header, msg)) = self.next_message(deadline)? {
            if let MavMessage::HEARTBEAT(h) = &msg {
                let found = Autopilot::of(h.autopilot);
                let is_autopilot = h.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID;
                if let Some(a) = assume.filter(|_| is_autopilot).or(found) {
                    self.target = Some((header.system_id as u8, header.component_id));
                    self.autopilot = Some(a);
                    self.count(&header);
                    return Ok(a);
                }
                let what = format!("{:?}", h.autopilot);
                if !seen.contains(&what) {
                    seen.push(what);
                }
            } else {
                self.keep((header, msg));
            }
        }
        let waited_s = start.elapsed().as_secs_f64();
        let port = self.name.clone();
        Err(if self.frames.bytes == 0 {
            LinkError::Silent { port, waited_s }
        } else if self.frames.frames == 0 {
            LinkError::NotMavlink {
                port,
                bytes: self.frames.bytes,
                waited_s,
                excerpt: self.first_bytes.escape_ascii().to_string(),
            }
        } else {
            LinkError::NoAutopilot {
                port,
                frames: self.frames.frames,
                waited_s,
                seen: if seen.is_empty() {
                    String::new()
                } else {
                    format!(", only {}", seen.join(", "))
                },
            }
        })
    }
}

/// One end of an in-memory duplex ([`duplex`]): what one end writes the other reads. A read waits at most 20 ms
/// and then fails with `TimedOut`, as a serial port with a timeout does; once the other end is dropped, reads give
/// `Ok(0)` and writes `BrokenPipe`.
#[derive(Debug)]
pub struct MemoryPort {
    rx: Receiver<Vec<u8>>,
    tx: Sender<Vec<u8>>,
    pending: VecDeque<u8>,
    timeout: Duration,
}

impl MemoryPort {
    /// Sets how long a read waits for bytes; zero: not at all (`WouldBlock`, as a non-blocking port).
    pub fn set_read_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }
}

/// Two connected [`MemoryPort`]s.
pub fn duplex() -> (MemoryPort, MemoryPort) {
    let (a_tx, b_rx) = channel();
    let (b_tx, a_rx) = channel();
    (
        MemoryPort {
            rx: a_rx,
            tx: a_tx,
            pending: VecDeque::new(),
            timeout: Duration::from_millis(20),
        },
        MemoryPort {
            rx: b_rx,
            tx: b_tx,
            pending: VecDeque::new(),
            timeout: Duration::from_millis(20),
        },
    )
}

impl Read for MemoryPort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.pending.is_empty() {
            if self.timeout.is_zero() {
                match self.rx.try_recv() {
                    Ok(bytes) => self.pending.extend(bytes),
                    Err(TryRecvError::Empty) => return Err(ErrorKind::WouldBlock.into()),
                    Err(TryRecvError::Disconnected) => return Ok(0),
                }
            } else {
                match self.rx.recv_timeout(self.timeout) {
                    Ok(bytes) => self.pending.extend(bytes),
                    Err(RecvTimeoutError::Timeout) => return Err(ErrorKind::TimedOut.into()),
                    Err(RecvTimeoutError::Disconnected) => return Ok(0),
                }
            }
        }
        while let Ok(bytes) = self.rx.try_recv() {
            self.pending.extend(bytes);
        }
        let n = buf.len().min(self.pending.len());
        for (slot, byte) in buf.iter_mut().zip(self.pending.drain(..n)) {
            *slot = byte;
        }
        Ok(n)
    }
}

impl Write for MemoryPort {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.tx
            .send(buf.to_vec())
            .map_err(|_| io::Error::from(ErrorKind::BrokenPipe))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::{HEARTBEAT_DATA, MavMessage};

    fn frame(msg: &MavMessage, seq: u8) -> Vec<u8> {
        let mut out = Vec::new();
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        };
        mavlink::write_v2_msg(&mut out, header, msg).unwrap();
        out
    }

    #[test]
    fn frames_are_cut_from_bytes_arriving_in_pieces_with_garbage_between() {
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            ..HEARTBEAT_DATA::default()
        });
        let mut bytes = b"noise \xfd\x09 more".to_vec();
        bytes.extend(frame(&hb, 0));
        let mut damaged = frame(&hb, 1);
        damaged[12] ^= 0xff;
        bytes.extend(damaged);
        bytes.extend(frame(&hb, 2));
        let mut buffer = FrameBuffer::new();
        let mut got = Vec::new();
        for piece in bytes.chunks(3) {
            buffer.push(piece);
            while let Some((h, _)) = buffer.next_message() {
                got.push(h.sequence);
            }
        }
        assert_eq!(got, [0, 2]);
        assert_eq!(buffer.frames, 2);
    }

    #[test]
    fn a_frame_cut_short_loses_neither_the_short_frame_it_spans_nor_the_next() {
        let imu = MavMessage::RAW_IMU(mavlink::dialects::common::RAW_IMU_DATA {
            time_usec: 123_456_789,
            xmag: -89,
            ymag: 775,
            zmag: -37,
            ..Default::default()
        });
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
        // The first RAW_IMU's sender gave up after 10 bytes; a heartbeat (21 bytes) lies within its declared length.
        let cut = frame(&imu, 0);
        assert!(cut.len() > 10 + frame(&hb, 1).len());
        let mut bytes = cut[..10].to_vec();
        bytes.extend(frame(&hb, 1));
        bytes.extend(frame(&imu, 2));
        let mut buffer = FrameBuffer::new();
        buffer.push(&bytes);
        let mut got = Vec::new();
        while let Some((h, _)) = buffer.next_message() {
            got.push(h.sequence);
        }
        assert_eq!(got, [1, 2]);
    }

    #[test]
    fn frames_lost_are_counted_from_the_autopilots_sequence_numbers_but_not_a_reboots_restart() {
        let (mut board, ours) = duplex();
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            ..HEARTBEAT_DATA::default()
        });
        let mut conn = Connection::new(ours, "p");
        board.write_all(&frame(&hb, 250)).unwrap();
        conn.wait_heartbeat(Duration::from_millis(200), None)
            .unwrap();
        // 251, 252 lost; 253–255 and 0–4 came (the numbering wraps); 5–9 lost; 10–200 came; then a reboot: 0, 1, 2.
        let mut bytes = Vec::new();
        for seq in (253..=255).chain(0..=4).chain(10..=200).chain(0..=2) {
            bytes.extend(frame(&hb, seq));
        }
        // Another sender's frames are not the autopilot's.
        let mut other = Vec::new();
        mavlink::write_v2_msg(
            &mut other,
            MavHeader {
                system_id: 42,
                component_id: 1,
                sequence: 100,
            },
            &hb,
        )
        .unwrap();
        bytes.extend(other);
        board.write_all(&bytes).unwrap();
        let deadline = Instant::now() + Duration::from_millis(200);
        let mut got = 0;
        while got < 203 {
            if conn.next_message(deadline).unwrap().is_some() {
                got += 1;
            }
        }
        // Until the autopilot's clock is found to have gone back, the reboot's gap (200 → 0) counts as 55 lost.
        assert_eq!(
            conn.link_loss(),
            LinkLoss {
                received: 203,
                lost: 2 + 5 + 55
            }
        );
        // A gap that ends on one of the first numbers is undone when the autopilot is found to have rebooted.
        conn.numbering_restarted();
        assert_eq!(conn.link_loss().lost, 7);
        assert!((conn.link_loss().share() - 7.0 / 210.0).abs() < 1e-12);
    }

    #[test]
    fn a_port_of_text_is_no_mavlink_and_a_quiet_one_is_silent() {
        let (mut board, ours) = duplex();
        board.write_all(b"Raw:1,2,3,4,5,6,7,8,9\r\n").unwrap();
        let mut conn = Connection::new(ours, "/dev/ttyACM0");
        let err = conn
            .wait_heartbeat(Duration::from_millis(200), None)
            .unwrap_err();
        assert!(
            err.to_string()
                .starts_with("/dev/ttyACM0: 23 bytes in 0.2 s and no MAVLink frame"),
            "{err}"
        );
        assert!(
            err.to_string()
                .ends_with("It sends: Raw:1,2,3,4,5,6,7,8,9\\r\\n")
        );
        let (_board, ours) = duplex();
        let err = Connection::new(ours, "p")
            .wait_heartbeat(Duration::from_millis(100), None)
            .unwrap_err();
        assert!(matches!(err, LinkError::Silent { .. }), "{err}");
    }
}
