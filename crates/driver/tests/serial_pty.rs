//! Serial streams over pseudo-terminal pairs, against firmware simulated in a thread.
//!
//! Each test opens a pty pair. The library opens the slave's path as it would open
//! `/dev/ttyACM0` (through `serialport`); the simulated firmware owns the master. Closing the
//! master is unplugging the device. Steps that depend on each other are ordered by channels,
//! never by sleeping; the only sleeps are the firmware's own pace and waits for a full buffer.

use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use magcal_driver::serial::echo::FieldMismatch;
use magcal_driver::serial::motioncal::EchoKind;
use magcal_driver::serial::packet::{DecodeError, SIGNATURE, crc16};
use magcal_driver::serial::{
    self, CalibrationPacket, DeviceSpec, GarbageCounts, GarbageKind, PACKET_LEN, Protocol,
    Received, SerialSource, StreamStop, VerifyFailure, WriteError, decode,
};
use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use nix::unistd::ttyname;

const BAUD: u32 = 115_200;
/// Lines between two calibration echoes of the simulated firmware (Adafruit's sketches: about
/// 100, at 100 Hz).
const ECHO_EVERY: u32 = 100;
/// Only ever waited out when something is broken.
const PATIENCE: Duration = Duration::from_secs(5);

/// A pty pair: the library's source on the slave, and the master for the firmware
/// (raw, non-blocking).
fn connect(protocol: Protocol) -> (SerialSource, File) {
    let pty = openpty(None, None).expect("openpty");
    let mut termios = tcgetattr(&pty.master).expect("tcgetattr");
    cfmakeraw(&mut termios);
    tcsetattr(&pty.master, SetArg::TCSANOW, &termios).expect("raw mode");
    fcntl(&pty.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).expect("non-blocking master");
    let path = ttyname(&pty.slave).expect("slave path");
    let path = path.to_str().expect("utf-8 path");
    let mut source = serial::open(path, BAUD, protocol).expect("open the pty slave as a port");
    source.set_idle_timeout(PATIENCE);
    drop(pty.slave); // the source has its own descriptor
    (source, File::from(pty.master))
}

/// `Raw:` line number `i`: the magnetometer x count is `i`, so gaps and repeats show.
fn raw_line(i: u32) -> String {
    format!("Raw:{},-20,8192,16,-16,0,{i},-{i},500\r\n", i % 100)
}

fn mag_count(received: &Received) -> u32 {
    (received.sample.mag_ut[0] * 10.0).round() as u32
}

/// What goes wrong on the firmware's side of a calibration write.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    /// Nothing: it echoes what it holds (3 decimals on `Cal1:`, 4 on `Cal2:`, as Adafruit's
    /// sketches).
    None,
    /// With the hard-iron y offset off by 1 µT (a bad store).
    FlipHardIronY,
    /// With a `Cal2:` line garbled (a comma lost on the wire).
    GarbleCal2,
    /// It prints no echo at all (firmware that takes packets silently).
    NoEcho,
    /// Line noise flips a bit in what it receives, so the packet fails its CRC.
    NoisyLine,
}

/// The device end: what firmware on a microcontroller does with its USB-serial port.
struct Firmware {
    port: File,
    /// Bytes received, not yet taken as a packet (its `receiveCalibration` buffer).
    rx: Vec<u8>,
    /// The calibration it holds.
    cal: CalibrationPacket,
    /// False once the tool's side is gone.
    alive: bool,
}

impl Firmware {
    fn new(port: File) -> Self {
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        Firmware {
            port,
            rx: Vec::new(),
            cal: CalibrationPacket::magnetic([0.0; 3], 50.0, identity).unwrap(),
            alive: true,
        }
    }

    /// Writes all of `bytes`, waiting while the pty buffer is full.
    fn send(&mut self, bytes: &[u8]) {
        let mut rest = bytes;
        while self.alive && !rest.is_empty() {
            match self.port.write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    thread::sleep(Duration::from_micros(200));
                }
                Err(_) => self.alive = false,
            }
        }
    }

    fn send_raw(&mut self, i: u32) {
        self.send(raw_line(i).as_bytes());
    }

    /// Takes what the tool sent: finds 117, 84, collects 68 bytes, accepts them if the CRC of
    /// all 68 is zero, else looks for the next signature.
    fn receive(&mut self, fault: Fault) -> Vec<Result<CalibrationPacket, DecodeError>> {
        let mut buf = [0u8; 256];
        loop {
            match self.port.read(&mut buf) {
                Ok(n) if n > 0 => {
                    if fault == Fault::NoisyLine {
                        buf[(n - 1).min(30)] ^= 0x04;
                    }
                    self.rx.extend_from_slice(&buf[..n]);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                _ => {
                    self.alive = false;
                    break;
                }
            }
        }
        let mut packets = Vec::new();
        loop {
            match self.rx.windows(2).position(|w| w == SIGNATURE) {
                Some(start) => drop(self.rx.drain(..start)),
                None => {
                    let keep_last = self.rx.last() == Some(&SIGNATURE[0]);
                    self.rx.drain(..self.rx.len() - usize::from(keep_last));
                    break;
                }
            }
            let Some(bytes) = self.rx.get(..PACKET_LEN) else {
                break;
            };
            let accepted = crc16(bytes) == 0; // the firmware's own test
            let result = decode(bytes.try_into().unwrap());
            assert_eq!(accepted, result.is_ok(), "{result:?}");
            let used = if result.is_ok() { PACKET_LEN } else { 2 };
            self.rx.drain(..used);
            packets.push(result);
        }
        packets
    }

    /// Prints `Cal1:` and `Cal2:`.
    fn echo(&mut self, fault: Fault) {
        if fault == Fault::NoEcho {
            return;
        }
        let mut cal1 = self.cal.values()[..10].to_vec();
        if fault == Fault::FlipHardIronY {
            cal1[7] += 1.0;
        }
        let cal1: Vec<String> = cal1.iter().map(|v| format!("{v:.3}")).collect();
        let cal2: Vec<String> = self
            .cal
            .soft_iron()
            .iter()
            .flatten()
            .map(|v| format!("{v:.4}"))
            .collect();
        let mut cal2 = cal2.join(",");
        if fault == Fault::GarbleCal2 {
            cal2 = cal2.replacen(',', "", 1);
        }
        let text = format!("Cal1:{}\r\nCal2:{cal2}\r\n", cal1.join(","));
        self.send(text.as_bytes());
    }
}

/// Runs firmware that streams `Raw:` lines, echoes its calibration every [`ECHO_EVERY`] lines
/// and right after a packet (taken or refused), and reports each packet it took; until told
/// to stop.
fn spawn_calibration_firmware(
    port: File,
    fault: Fault,
) -> (Sender<()>, Receiver<CalibrationPacket>, JoinHandle<()>) {
    let (stop_tx, stop_rx) = mpsc::channel();
    let (taken_tx, taken_rx) = mpsc::channel();
    let handle = thread::spawn(move || {
        let mut fw = Firmware::new(port);
        let mut i = 0;
        while fw.alive && stop_rx.try_recv() == Err(TryRecvError::Empty) {
            for result in fw.receive(fault) {
                match result {
                    Ok(packet) => {
                        fw.cal = packet;
                        fw.send(b"Wrote calibration\r\n");
                        fw.echo(fault);
                        taken_tx.send(packet).unwrap();
                    }
                    Err(e) => {
                        fw.send(format!("bad calibration packet: {e}\r\n").as_bytes());
                        fw.echo(fault); // still the old calibration
                    }
                }
            }
            fw.send_raw(i);
            if i % ECHO_EVERY == ECHO_EVERY - 1 {
                fw.echo(fault);
            }
            i += 1;
            thread::sleep(Duration::from_millis(1)); // the firmware's sample rate
        }
    });
    (stop_tx, taken_rx, handle)
}

/// Reads until `n` samples have arrived.
fn read_n(source: &mut SerialSource, n: usize) -> Vec<Received> {
    (0..n)
        .map(|_| source.read_sample().expect("a sample"))
        .collect()
}

fn packet() -> CalibrationPacket {
    CalibrationPacket::magnetic(
        [-3.35, -0.74, -40.79],
        45.0,
        [
            [0.965, 0.018, 0.010],
            [0.018, 0.960, 0.003],
            [0.010, 0.003, 1.080],
        ],
    )
    .unwrap()
}

#[test]
fn injected_garbage_is_counted_by_kind_and_unplugging_ends_the_stream_cleanly() {
    const LINES: u32 = 300;
    let started = Instant::now();
    let (mut source, master) = connect(Protocol::MotionCal);
    let (unplug_tx, unplug_rx) = mpsc::channel::<()>();
    let firmware = thread::spawn(move || {
        let mut fw = Firmware::new(master);
        let mut injected = GarbageCounts::default();
        // Opened in the middle of a line: its tail comes first.
        fw.send(b"8192,16,-16,0,1,2,3\r\n");
        injected.add(GarbageKind::Unrecognized);
        fw.send(b"Calibration filesys test\r\nLoaded existing calibration\r\n");
        injected.add(GarbageKind::Unrecognized);
        injected.add(GarbageKind::Unrecognized);
        let mut overlong = vec![b'A'; 3000];
        overlong.extend_from_slice(b"\r\n");
        let garbage: [(&[u8], GarbageKind); 7] = [
            (b"\x01\xfe\x80\x00\x1bnoise\xff\r\n", GarbageKind::Binary),
            (b"Raw:1,2,3\r\n", GarbageKind::FieldCount),
            (
                b"Raw:1,2,3Raw:4,5,6,7,8,9,10,11,12\r\n",
                GarbageKind::FieldCount,
            ),
            (b"Raw:1,2,3,4,5,6,7,8,x\r\n", GarbageKind::BadNumber),
            (
                b"Uni:0.01,0.02,9.81,0.0000,0.0000,0.0000,12.30,-45.60,0.70\r\n",
                GarbageKind::Unrecognized,
            ),
            (b"Cal1:0.000,0.000,0.0\r\n", GarbageKind::FieldCount), // a cut-short echo
            (&overlong, GarbageKind::Overlong),
        ];
        for i in 0..LINES {
            fw.send_raw(i);
            if i % 10 == 5 {
                let (bytes, kind) = garbage[(i as usize / 10) % garbage.len()];
                fw.send(bytes);
                injected.add(kind);
            }
        }
        // Everything is sent: wait until the tool has read it, then pull the plug.
        unplug_rx.recv().unwrap();
        drop(fw);
        injected
    });

    let received = read_n(&mut source, LINES as usize);
    unplug_tx.send(()).unwrap();
    let stop = source.read_sample().expect_err("the device is gone");
    let injected = firmware.join().unwrap();

    assert!(matches!(stop, StreamStop::Disconnected { .. }), "{stop:?}");
    assert_eq!(source.last_stop(), Some(&stop));
    assert!(source.disconnected().is_some());
    assert_eq!(
        source.read_sample().expect_err("still gone"),
        stop,
        "a disconnect is final"
    );
    let counts: Vec<u32> = received.iter().map(mag_count).collect();
    assert_eq!(
        counts,
        (0..LINES).collect::<Vec<_>>(),
        "every line, in order"
    );
    assert!(received.windows(2).all(|w| w[0].host_s <= w[1].host_s));
    let first = &received[0].sample;
    assert_eq!(first.accel_g, Some([0.0, -20.0 / 8192.0, 1.0]));
    assert!((first.gyro_rad_s.unwrap()[0] - 1f64.to_radians()).abs() < 1e-15);
    assert!((first.mag_ut[2] - 50.0).abs() < 1e-12);

    let c = source.counts();
    assert_eq!(c.samples, u64::from(LINES));
    assert_eq!(
        c.garbage, injected,
        "garbage counted by kind: {}",
        c.garbage
    );
    assert_eq!(c.echoes, 0);
    assert_eq!(c.lines, c.samples + c.garbage.total());
    assert!(
        started.elapsed() < Duration::from_secs(2),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn unplugging_mid_stream_keeps_everything_received() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (unplug_tx, unplug_rx) = mpsc::channel::<()>();
    let firmware = thread::spawn(move || {
        let mut fw = Firmware::new(master);
        let mut sent = 0;
        while unplug_rx.try_recv() == Err(TryRecvError::Empty) {
            fw.send_raw(sent);
            sent += 1;
        }
        sent // dropping the master here, lines still in flight
    });

    let mut received = read_n(&mut source, 100);
    unplug_tx.send(()).unwrap();
    let stop = loop {
        match source.read_sample() {
            Ok(r) => received.push(r),
            Err(stop) => break stop,
        }
    };
    let sent = firmware.join().unwrap();

    assert!(matches!(stop, StreamStop::Disconnected { .. }), "{stop:?}");
    let counts: Vec<u32> = received.iter().map(mag_count).collect();
    let n = counts.len() as u32;
    assert_eq!(counts, (0..n).collect::<Vec<_>>(), "no gap, no repeat");
    assert!(n <= sent, "{n} received of {sent} sent");
    let c = source.counts();
    assert_eq!(c.samples, u64::from(n));
    assert!(
        c.garbage.total() <= 1 && c.garbage.total() == c.garbage.get(GarbageKind::Truncated),
        "at most the line cut by the unplug: {}",
        c.garbage
    );
}

#[test]
fn an_idle_device_is_not_a_disconnected_one() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (go_tx, go_rx) = mpsc::channel::<()>();
    let firmware = thread::spawn(move || {
        let mut fw = Firmware::new(master);
        (0..3).for_each(|i| fw.send_raw(i));
        go_rx.recv().unwrap(); // paused until the tool has seen the silence
        (3..5).for_each(|i| fw.send_raw(i));
        go_rx.recv().unwrap();
    });

    read_n(&mut source, 3);
    source.set_idle_timeout(Duration::from_millis(150));
    assert_eq!(source.by_ref().count(), 0, "iteration stops at the silence");
    let Some(StreamStop::Idle { waited_s }) = source.last_stop() else {
        panic!("expected idle, got {:?}", source.last_stop());
    };
    assert!((0.15..2.0).contains(waited_s), "{waited_s}");
    assert!(source.disconnected().is_none());
    source.set_idle_timeout(PATIENCE);
    go_tx.send(()).unwrap();
    let resumed: Vec<u32> = read_n(&mut source, 2).iter().map(mag_count).collect();
    assert_eq!(resumed, [3, 4]);
    go_tx.send(()).unwrap();
    firmware.join().unwrap();
    assert!(matches!(
        source.read_sample(),
        Err(StreamStop::Disconnected { .. })
    ));
}

#[test]
fn a_calibration_is_taken_by_the_firmware_and_confirmed_by_its_echo() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (stop, taken, firmware) = spawn_calibration_firmware(master, Fault::None);

    read_n(&mut source, ECHO_EVERY as usize + 10); // past an echo of the old calibration
    let sent = packet();
    let verified = source
        .write_calibration(&sent, PATIENCE)
        .expect("confirmed");
    let held = taken.recv_timeout(PATIENCE).expect("the firmware took it");
    assert_eq!(held, sent, "bit for bit, after the CRC check");
    assert!(verified.elapsed_s < PATIENCE.as_secs_f64(), "{verified:?}");
    // Samples that came with the echo were kept (those queued before the packet went out
    // were discarded with any stale echo).
    let after: Vec<u32> = read_n(&mut source, 10).iter().map(mag_count).collect();
    assert!(after.windows(2).all(|w| w[1] > w[0]), "{after:?}");

    stop.send(()).unwrap();
    firmware.join().unwrap();
    assert!(taken.try_recv().is_err(), "one packet, taken once");
    let c = source.counts();
    assert!(c.echoes >= 2);
    assert!(
        c.garbage.get(GarbageKind::Unrecognized) >= 1,
        "\"Wrote calibration\""
    );
}

#[test]
fn a_corrupted_echo_fails_the_verification_and_says_what_differed() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (stop, taken, firmware) = spawn_calibration_firmware(master, Fault::FlipHardIronY);
    // Past an echo of the old calibration: the first wrong echo after it fails at once.
    read_n(&mut source, ECHO_EVERY as usize + 10);
    let sent = packet();
    let error = source
        .write_calibration(&sent, PATIENCE)
        .expect_err("the echo is wrong");
    assert_eq!(taken.recv_timeout(PATIENCE).unwrap(), sent);
    stop.send(()).unwrap();
    firmware.join().unwrap();

    let WriteError::Verification(VerifyFailure::Mismatch { echo, fields }) = &error else {
        panic!("expected a mismatch, got {error:?}");
    };
    assert_eq!(*echo, EchoKind::Cal1);
    let [
        FieldMismatch {
            field,
            sent: value_sent,
            echoed,
            ..
        },
    ] = fields.as_slice()
    else {
        panic!("one value differs: {fields:?}");
    };
    assert_eq!(*field, "hard_iron_ut[1]");
    assert!((value_sent - -0.74).abs() < 1e-6);
    assert!((echoed - 0.26).abs() < 1e-9, "{echoed}");
    let message = error.to_string();
    assert!(message.contains("hard_iron_ut[1] sent"), "{message}");
}

#[test]
fn a_garbled_echo_fails_the_verification() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (stop, taken, firmware) = spawn_calibration_firmware(master, Fault::GarbleCal2);
    read_n(&mut source, 5);
    let error = source
        .write_calibration(&packet(), PATIENCE)
        .expect_err("the echo is garbled");
    taken.recv_timeout(PATIENCE).unwrap();
    stop.send(()).unwrap();
    firmware.join().unwrap();

    let WriteError::Verification(VerifyFailure::Corrupted { echo, kind, line }) = &error else {
        panic!("expected a garbled echo, got {error:?}");
    };
    assert_eq!((*echo, *kind), (EchoKind::Cal2, GarbageKind::FieldCount));
    // The first garbled line is let pass; the second may still show the old calibration.
    assert!(line.starts_with("Cal2:"), "{line}");
}

#[test]
fn a_missing_echo_fails_the_verification_after_the_timeout() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (stop, taken, firmware) = spawn_calibration_firmware(master, Fault::NoEcho);
    read_n(&mut source, 5);
    let started = Instant::now();
    let error = source
        .write_calibration(&packet(), Duration::from_millis(300))
        .expect_err("no echo");
    let waited = started.elapsed();
    taken
        .recv_timeout(PATIENCE)
        .expect("the firmware took it all the same");
    assert!(source.read_sample().is_ok(), "the stream goes on");
    stop.send(()).unwrap();
    firmware.join().unwrap();

    let WriteError::Verification(VerifyFailure::Missing { missing, waited_s }) = &error else {
        panic!("expected a missing echo, got {error:?}");
    };
    assert_eq!(missing, &[EchoKind::Cal1, EchoKind::Cal2]);
    assert!((0.3..2.0).contains(waited_s), "{waited_s}");
    assert!(waited < Duration::from_secs(2), "{waited:?}");
}

#[test]
fn a_native_csv_stream_with_garbage() {
    let (mut source, master) = connect(Protocol::Csv);
    let (unplug_tx, unplug_rx) = mpsc::channel::<()>();
    let firmware = thread::spawn(move || {
        let mut fw = Firmware::new(master);
        let mut text = String::from("0.99,1,2,3,24.5,0.1,0.2,0.3,0.5\r\n"); // before the header
        text += "# magcal-recording v1\r\n# sensor: simulated\r\n# sample_rate_hz: 100\r\n";
        text += "t,mx,my,mz,temp,gx,gy,gz,i_coil\r\n";
        for i in 0..50 {
            text += &format!(
                "{:.2},{i}.5,-20,40,24.5,0.01,nan,,{}\r\n",
                f64::from(i) * 0.01,
                i % 2
            );
            match i {
                10 => text += "0.1,2,3\r\n",                         // half line
                20 => text += "0.2,x,3,4,24.5,0,0,0,0\r\n",          // not a number
                30 => text += "booting...\r\n",                      // chatter
                40 => text += "t,mx,my,mz,temp,gx,gy,gz,i_coil\r\n", // reset: same header
                _ => {}
            }
        }
        fw.send(text.as_bytes());
        unplug_rx.recv().unwrap();
    });

    let received = read_n(&mut source, 50);
    unplug_tx.send(()).unwrap();
    firmware.join().unwrap();
    assert!(matches!(
        source.read_sample(),
        Err(StreamStop::Disconnected { .. })
    ));

    let last = &received[49].sample;
    assert_eq!(last.t_s, Some(0.49));
    assert_eq!(last.mag_ut, [49.5, -20.0, 40.0]);
    assert_eq!(last.temp_c, Some(24.5));
    let gyro = last.gyro_rad_s.unwrap();
    assert!(gyro[0] == 0.01 && gyro[1].is_nan() && gyro[2].is_nan());
    assert_eq!(last.inputs, [1.0]);
    assert_eq!(last.quat_wxyz, None);
    assert_eq!(source.input_names(), ["coil"]);
    let metadata = [("sensor", "simulated"), ("sample_rate_hz", "100")];
    let metadata = metadata.map(|(k, v)| (k.to_string(), v.to_string()));
    assert_eq!(source.metadata(), metadata);
    let c = source.counts();
    assert_eq!((c.samples, c.headers, c.comments), (50, 2, 3));
    let g = &c.garbage;
    let kinds = [
        (GarbageKind::NoHeader, 1),
        (GarbageKind::FieldCount, 1),
        (GarbageKind::BadNumber, 1),
        (GarbageKind::Unrecognized, 1),
    ];
    for (kind, n) in kinds {
        assert_eq!(g.get(kind), n, "{kind}: {g}");
    }
    assert_eq!(g.total(), 4);
}

#[test]
fn adafruit_lines_in_utf8_are_read_and_the_raw_lines_before_them_skipped() {
    // The LIS3MDL example prints raw counts, then µT (here with the `µT` a UTF-8 sketch may print).
    let adafruit: DeviceSpec = "/dev/null:adafruit".parse().unwrap();
    let (mut source, master) = connect(adafruit.protocol);
    let (unplug_tx, unplug_rx) = mpsc::channel::<()>();
    let firmware = thread::spawn(move || {
        let mut fw = Firmware::new(master);
        let mut text = String::from("Adafruit LIS3MDL test!\r\nLIS3MDL Found!\r\n");
        for i in 0..40 {
            text += &format!("\nX:  {}  \tY:  -567  \tZ:  4010\r\n", 100 * i);
            text += &format!("\tX: {i}.25 µT\tY: -5.67 µT\tZ: 40.10 µT\r\n");
        }
        fw.send(text.as_bytes());
        unplug_rx.recv().unwrap();
    });
    let received = read_n(&mut source, 40);
    unplug_tx.send(()).unwrap();
    firmware.join().unwrap();
    assert!(matches!(
        source.read_sample(),
        Err(StreamStop::Disconnected { .. })
    ));
    assert_eq!(received[39].sample.mag_ut, [39.25, -5.67, 40.10]);
    let c = source.counts();
    assert_eq!(c.samples, 40);
    assert_eq!(
        c.garbage.get(GarbageKind::Unrecognized),
        42,
        "the banner and the raw lines: {}",
        c.garbage
    );
    assert_eq!(c.garbage.total(), 42);
}

#[test]
fn a_packet_garbled_on_the_wire_is_reported_as_not_taken() {
    let (mut source, master) = connect(Protocol::MotionCal);
    let (stop, taken, firmware) = spawn_calibration_firmware(master, Fault::NoisyLine);
    // Past an echo of the old calibration, so that its later echoes are known to be stale.
    read_n(&mut source, ECHO_EVERY as usize + 10);
    let error = source
        .write_calibration(&packet(), Duration::from_millis(600))
        .expect_err("the firmware refused the packet");
    stop.send(()).unwrap();
    firmware.join().unwrap();

    assert!(taken.try_recv().is_err(), "no packet passed the CRC check");
    let WriteError::Verification(VerifyFailure::Unchanged { echo, .. }) = &error else {
        panic!("expected the old calibration to stay, got {error:?}");
    };
    assert_eq!(*echo, EchoKind::Cal1);
    assert!(
        error.to_string().contains("previous calibration"),
        "{error}"
    );
}
