//! A simulated serial board: firmware in the style of PJRC's MotionCal and Adafruit's calibration sketches, written
//! from their protocol (not their code).
//!
//! It streams `Raw:ax,ay,az,gx,gy,gz,mx,my,mz` lines (accelerometer in 1/8192 g, gyro in 1/16 °/s, magnetometer in
//! 0.1 µT), magcal's native CSV (`t,mx,my,mz,temp` after a header, `t` on the board's own clock), or the lines of
//! other sketches ([`Output`]: the Adafruit Unified Sensor example, raw counts `x,y,z`, a line of its own in gauss),
//! computed from a
//! [`Bench`] whose hand tumbles the board, mixes in garbage lines if asked (line noise, half lines, other chatter),
//! takes MotionCal's 68-byte calibration packet (signature 117, 84; CRC-16/MODBUS over all 68 bytes must be zero),
//! and prints what it holds as `Cal1:`/`Cal2:` echoes: right after taking a packet and every so many lines. It can
//! echo faithfully, with a wrong value (a bad store), or not at all, and it can be unplugged after a number of lines
//! (it returns, and dropping its port closes the line).
//!
//! Board faults ([`BoardFault`]): it can fall silent while staying connected, reset (a boot banner, its header
//! again, possibly another one, and its clock starting again from zero), or run at another baud rate than the port
//! (every byte arrives garbled).
//!
//! It works on any byte port; tests give it the master side of a pseudo-terminal, and the tools open the slave side
//! as they would open `/dev/ttyACM0`.

use std::fmt::Write as _;
use std::io::{ErrorKind, Read, Write};
use std::thread;
use std::time::{Duration, Instant};

use magcal_sim::SimError;
use magcal_sim::bench::{Bench, BenchConfig, BenchSample};

/// Length of a MotionCal calibration packet, bytes.
const PACKET_BYTES: usize = 68;
/// How long the board stays connected after its last line before it is unplugged.
const UNPLUG_SETTLE: Duration = Duration::from_millis(200);
/// A line the port cannot take for this long (nobody reads the other side) is dropped, as a board's full USB buffer
/// drops it: the firmware goes on, and sees when it is told to stop.
const SEND_TIMEOUT: Duration = Duration::from_secs(10);
/// The two bytes a packet starts with.
const PACKET_SIGNATURE: [u8; 2] = [117, 84];

/// How the firmware prints its calibration back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EchoMode {
    /// As it holds it: `Cal1:` with 3 decimals, `Cal2:` with 4, as Adafruit's sketches print.
    Faithful,
    /// With the hard-iron y offset 1 µT off what was received (a corrupted store).
    CorruptHardIron,
    /// Never (firmware that takes packets but prints nothing back).
    Never,
}

/// What the board prints.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Output {
    /// MotionCal `Raw:` lines.
    MotionCal,
    /// magcal's native CSV: `# sensor:` and a header line, then `t,mx,my,mz,temp` (t on the board's clock, s).
    Csv,
    /// The Adafruit Unified Sensor example (HMC5883): a sensor-details banner, then `X: 12.34  Y: -5.67  Z: 40.10  uT`
    /// (µT, two decimals, as Arduino prints a float).
    Adafruit,
    /// Three integers a line, `x,y,z`: raw counts of this many µT each.
    XyzCounts(f64),
    /// A line of the board's own: `t=12340ms mag=[0.24100 -0.33700 -0.38900] G temp=24.70C q=[w x y z]`, time in
    /// ms on the board's clock, the field in gauss (five decimals), the attitude quaternion (sensor to NED).
    Gauss,
}

/// Something wrong with the board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardFault {
    /// After this many sample lines it sends nothing more, but stays connected (hung, or waiting for a command).
    SilentAfter(u64),
    /// After this many sample lines it resets: [`BOOT_S`] of bench time without output, a boot banner, its header
    /// again (CSV), and its clock starting again from zero. With `new_header` the header after the reset names other
    /// columns in another order (`temp,mz,my,mx,t,i_coil`), as new firmware would.
    ResetAfter {
        /// Sample lines before the reset.
        lines: u64,
        /// Print another header after the reset.
        new_header: bool,
    },
    /// The port runs at another baud rate than the board: every byte arrives garbled (high bit set, so no line
    /// ever ends).
    WrongBaud,
    /// The sample line after this many lost bytes on the way and reads as a field of −4.2·10⁶ µT on x (MotionCal
    /// `Raw:` and CSV output; the line still counts as sent).
    CorruptedAt(u64),
}

/// How long a reset board takes to boot, s of bench time.
pub const BOOT_S: f64 = 0.5;

/// The header of the CSV output, and the one after a reset with a new header.
const CSV_HEADER: &str = "t,mx,my,mz,temp";
const NEW_CSV_HEADER: &str = "temp,mz,my,mx,t,i_coil";

/// What the firmware does.
#[derive(Clone, Debug, PartialEq)]
pub struct FirmwareConfig {
    /// The bench the board sits on (its hand tumbles it at 1 rad/s).
    pub bench: BenchConfig,
    /// Samples per second of bench time, Hz (one `Raw:` line per sample).
    pub sample_rate_hz: f64,
    /// Lines per second of wall time (the port is a pseudo-terminal, so faster than the baud rate is fine).
    pub lines_per_wall_s: f64,
    /// After every this many `Raw:` lines, one garbage line.
    pub garbage_every: Option<u64>,
    /// Unplug after this many `Raw:` lines; `None`: run until told to stop or the other side is gone.
    pub raw_lines: Option<u64>,
    /// How calibrations are echoed.
    pub echo: EchoMode,
    /// `Raw:` lines between two periodic echoes.
    pub echo_every: u64,
    /// What it prints.
    pub output: Output,
    /// What is wrong with it, if anything.
    pub fault: Option<BoardFault>,
}

impl FirmwareConfig {
    /// Streams at 100 Hz of bench time, 2000 lines per wall second, echoing faithfully every 100 lines, no garbage,
    /// until stopped.
    pub fn new(bench: BenchConfig) -> FirmwareConfig {
        FirmwareConfig {
            bench,
            sample_rate_hz: 100.0,
            lines_per_wall_s: 2000.0,
            garbage_every: None,
            raw_lines: None,
            echo: EchoMode::Faithful,
            echo_every: 100,
            output: Output::MotionCal,
            fault: None,
        }
    }
}

/// What the firmware did, for a test to compare with what the tool saw.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FirmwareReport {
    /// `Raw:` lines sent.
    pub raw_lines: u64,
    /// Garbage lines sent.
    pub garbage_lines: u64,
    /// Packets taken (CRC good).
    pub packets_accepted: u32,
    /// Packets refused (CRC bad).
    pub packets_rejected: u32,
    /// The calibration held at the end, as the 16 floats of the packet (accelerometer, gyro, hard iron, field,
    /// soft-iron diagonal, soft-iron off-diagonal).
    pub calibration: [f32; 16],
    /// Why it stopped: unplugged after its lines, told to stop, or the other side went away.
    pub stopped: String,
    /// Bench time of every sample line sent, s (the truth a recording's `t` is compared with).
    pub sample_times_s: Vec<f64>,
    /// The field every sample line printed, as the board measured it before printing, µT.
    pub sample_mag_ut: Vec<[f64; 3]>,
    /// The board's attitude at every sample line (sensor to NED, `[w, x, y, z]`).
    pub sample_quat: Vec<[f64; 4]>,
}

/// The firmware; see the [module docs](self).
pub struct MotionCalFirmware<P> {
    port: P,
    config: FirmwareConfig,
    bench: Bench,
    rx: Vec<u8>,
    report: FirmwareReport,
    alive: bool,
    /// Bench time of the board's boot: its clock `t` counts from here.
    boot_s: f64,
    /// The CSV header in use.
    header: &'static str,
}

/// CRC-16/MODBUS: reflected polynomial 0xA001, initial value 0xFFFF.
fn crc16_modbus(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// The calibration a board holds before it is sent one: zero offsets, field 50 µT, identity soft iron.
const DEFAULT_CALIBRATION: [f32; 16] = [
    0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 50.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0,
];

impl<P: Read + Write> MotionCalFirmware<P> {
    /// Firmware on `port` (which should not block on reads: a non-blocking pseudo-terminal master).
    pub fn new(port: P, config: FirmwareConfig) -> Result<MotionCalFirmware<P>, SimError> {
        let mut bench = Bench::new(config.bench.clone())?;
        bench.hand_mut().tumble(0.0, 1.0);
        Ok(MotionCalFirmware {
            port,
            config,
            bench,
            rx: Vec::new(),
            report: FirmwareReport {
                calibration: DEFAULT_CALIBRATION,
                ..FirmwareReport::default()
            },
            alive: true,
            boot_s: 0.0,
            header: CSV_HEADER,
        })
    }

    /// Runs until unplugged (after [`FirmwareConfig::raw_lines`]), until `stop()` says so, or until the other side
    /// is gone; returns what it did. The port is dropped on return: that is the unplug.
    pub fn run(mut self, stop: impl Fn() -> bool) -> FirmwareReport {
        let start = Instant::now();
        let wall_per_bench_s = self.config.sample_rate_hz / self.config.lines_per_wall_s;
        let mut i: u64 = 0;
        let mut bench_t_s = 0.0;
        if matches!(self.config.output, Output::Csv | Output::Adafruit) {
            self.banner();
        }
        self.report.stopped = loop {
            if !self.alive {
                break "the other side went away".to_owned();
            }
            if stop() {
                break "told to stop".to_owned();
            }
            if self.config.raw_lines.is_some_and(|n| i >= n) {
                // The cable is pulled a moment after the last line went out: a pseudo-terminal's hang-up discards
                // what the other side has not read yet, which would lose lines no real board loses.
                thread::sleep(UNPLUG_SETTLE);
                break format!("unplugged after {i} Raw: lines");
            }
            let due = Duration::from_secs_f64(bench_t_s * wall_per_bench_s);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                thread::sleep(wait);
            }
            self.receive();
            match self.config.fault {
                Some(BoardFault::SilentAfter(n)) if i >= n => {
                    thread::sleep(Duration::from_millis(5));
                    continue;
                }
                Some(BoardFault::ResetAfter { lines, new_header })
                    if i == lines && self.boot_s == 0.0 =>
                {
                    bench_t_s += BOOT_S;
                    self.boot_s = bench_t_s;
                    if new_header {
                        self.header = NEW_CSV_HEADER;
                    }
                    let wait = Duration::from_secs_f64(BOOT_S * wall_per_bench_s);
                    thread::sleep(wait);
                    self.banner();
                }
                _ => {}
            }
            let sample = self.bench.sample(bench_t_s);
            let mut line = self.sample_line(&sample);
            if self.config.fault == Some(BoardFault::CorruptedAt(i)) {
                line = self.corrupted(&line);
            }
            self.send(line.as_bytes());
            self.report.sample_mag_ut.push(sample.raw_ut);
            self.report.sample_quat.push(sample.quat);
            self.report.sample_times_s.push(bench_t_s);
            self.report.raw_lines += 1;
            i += 1;
            bench_t_s += 1.0 / self.config.sample_rate_hz;
            if let Some(every) = self.config.garbage_every
                && i.is_multiple_of(every)
            {
                let garbage = GARBAGE[(i / every) as usize % GARBAGE.len()];
                self.send(garbage);
                self.report.garbage_lines += 1;
            }
            if i.is_multiple_of(self.config.echo_every.max(1)) {
                self.echo();
            }
        };
        self.report
    }

    /// What the board prints when it boots (for CSV and the Adafruit example, also when it starts; the other boards
    /// only after a reset, as their first boot happened before the port was opened): a line of chatter, for CSV its
    /// metadata and header, for the Adafruit example its sensor details.
    fn banner(&mut self) {
        let text = match self.config.output {
            Output::Csv => format!(
                "booting magcal CSV sketch\r\n# sensor: simulated board\r\n{}\r\n",
                self.header
            ),
            Output::Adafruit => {
                "HMC5883 Magnetometer Test\r\n\r\n------------------------------------\r\n\
                 Sensor:       HMC5883\r\nMax Value:    800.00 uT\r\nMin Value:    -800.00 uT\r\n\
                 Resolution:   0.20 uT\r\n------------------------------------\r\n\r\n"
                    .to_owned()
            }
            _ => "MotionCal-compatible sketch: streaming\r\n".to_owned(),
        };
        self.send(text.as_bytes());
    }

    /// The line of a bench sample in the board's output format.
    fn sample_line(&self, s: &BenchSample) -> String {
        let t_s = s.t_s;
        match self.config.output {
            Output::MotionCal => raw_line(s),
            Output::Csv => {
                let t = format!("{:.3}", t_s - self.boot_s);
                let [x, y, z] = s.raw_ut.map(|v| format!("{v:.2}"));
                let temp = format!("{:.2}", s.temp_c);
                let fields = if self.header == CSV_HEADER {
                    [t, x, y, z, temp].join(",")
                } else {
                    [temp, z, y, x, t, "0.000".to_owned()].join(",")
                };
                fields + "\r\n"
            }
            Output::Adafruit => {
                let [x, y, z] = s.raw_ut;
                format!("X: {x:.2}  Y: {y:.2}  Z: {z:.2}  uT\r\n")
            }
            Output::XyzCounts(ut_per_count) => {
                let [x, y, z] = s.raw_ut.map(|v| (v / ut_per_count).round() as i64);
                format!("{x},{y},{z}\r\n")
            }
            Output::Gauss => {
                let ms = ((t_s - self.boot_s) * 1000.0).round() as i64;
                let [x, y, z] = s.raw_ut.map(|v| v / 100.0);
                let [w, qx, qy, qz] = s.quat;
                format!(
                    "t={ms}ms mag=[{x:.5} {y:.5} {z:.5}] G temp={:.2}C q=[{w:.5} {qx:.5} {qy:.5} {qz:.5}]\r\n",
                    s.temp_c
                )
            }
        }
    }

    /// A sample line whose x field lost bytes: −4.2·10⁶ µT (in the output's unit).
    fn corrupted(&self, line: &str) -> String {
        let (prefix, body) = line.split_at(if line.starts_with("Raw:") { 4 } else { 0 });
        let mut fields: Vec<&str> = body.trim_end().split(',').collect();
        let (at, value) = match self.config.output {
            Output::MotionCal => (6, "-42000000"),
            _ => (1, "-4200000.00"),
        };
        if let Some(f) = fields.get_mut(at) {
            *f = value;
        }
        format!("{prefix}{}\r\n", fields.join(","))
    }

    /// Prints the calibration held.
    fn echo(&mut self) {
        let mut c = self.report.calibration;
        match self.config.echo {
            EchoMode::Never => return,
            EchoMode::CorruptHardIron => c[7] += 1.0,
            EchoMode::Faithful => {}
        }
        let cal1: Vec<String> = c[..10].iter().map(|v| format!("{v:.3}")).collect();
        let [xx, yy, zz, xy, xz, yz] = [c[10], c[11], c[12], c[13], c[14], c[15]];
        let cal2: Vec<String> = [xx, xy, xz, xy, yy, yz, xz, yz, zz]
            .iter()
            .map(|v| format!("{v:.4}"))
            .collect();
        let text = format!("Cal1:{}\r\nCal2:{}\r\n", cal1.join(","), cal2.join(","));
        self.send(text.as_bytes());
    }

    /// Takes what arrived: finds the signature, takes 68 bytes if their CRC is good, else looks further.
    fn receive(&mut self) {
        let mut buf = [0u8; 256];
        loop {
            match self.port.read(&mut buf) {
                Ok(0) => {
                    self.alive = false;
                    break;
                }
                Ok(n) => self.rx.extend_from_slice(&buf[..n]),
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted =>
                {
                    break;
                }
                Err(_) => {
                    self.alive = false;
                    break;
                }
            }
        }
        let mut took = false;
        while let Some(at) = self.rx.windows(2).position(|w| w == PACKET_SIGNATURE) {
            if self.rx.len() < at + PACKET_BYTES {
                self.rx.drain(..at);
                break;
            }
            let packet: Vec<u8> = self.rx[at..at + PACKET_BYTES].to_vec();
            if crc16_modbus(&packet) == 0 {
                for (k, chunk) in packet[2..66].chunks_exact(4).enumerate() {
                    self.report.calibration[k] =
                        f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
                }
                self.report.packets_accepted += 1;
                self.rx.drain(..at + PACKET_BYTES);
                took = true;
            } else {
                self.report.packets_rejected += 1;
                self.rx.drain(..at + 1);
            }
        }
        if took {
            self.echo();
        }
    }

    /// Writes all of `bytes`, waiting while the port's buffer is full. At a wrong baud rate they arrive garbled.
    fn send(&mut self, bytes: &[u8]) {
        let garbled: Vec<u8>;
        let mut rest = bytes;
        if self.config.fault == Some(BoardFault::WrongBaud) {
            garbled = bytes.iter().map(|b| b.rotate_left(3) | 0x80).collect();
            rest = &garbled;
        }
        let mut blocked_since: Option<Instant> = None;
        while self.alive && !rest.is_empty() {
            match self.port.write(rest) {
                Ok(0) => self.alive = false,
                Ok(n) => {
                    rest = &rest[n..];
                    blocked_since = None;
                }
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted =>
                {
                    if blocked_since.get_or_insert_with(Instant::now).elapsed() > SEND_TIMEOUT {
                        return;
                    }
                    thread::sleep(Duration::from_micros(200));
                    self.receive();
                }
                Err(_) => self.alive = false,
            }
        }
    }
}

/// The `Raw:` line of a bench sample.
fn raw_line(s: &BenchSample) -> String {
    let r = magcal_calib::frames::quat_to_matrix(s.quat);
    // Specific force of a board at rest: 1 g up, i.e. −D in NED, seen in the board's axes.
    let accel_g = magcal_calib::frames::mat_t_vec(&r, [0.0, 0.0, -1.0]);
    let mut line = String::from("Raw:");
    let values = accel_g
        .iter()
        .map(|g| g * 8192.0)
        .chain(s.omega_rad_s.iter().map(|w| w.to_degrees() * 16.0))
        .chain(s.raw_ut.iter().map(|m| m * 10.0));
    for (k, v) in values.enumerate() {
        let sep = if k == 0 { "" } else { "," };
        let _ = write!(line, "{sep}{}", v.round() as i64);
    }
    line.push_str("\r\n");
    line
}

/// Garbage lines, one of each kind a line stream meets: line noise, a half line, other chatter, a garbled number.
const GARBAGE: [&[u8]; 4] = [
    b"\x00\xfe\x13\x7f\r\n",
    b"Raw:12,-40\r\n",
    b"Uni:0.012,-0.980,0.051\r\n",
    b"Raw:1,2,8190,0,0,0,123,4x5,-300\r\n",
];

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    /// A port that reads from a script and records writes.
    struct Loopback {
        input: Cursor<Vec<u8>>,
        output: Vec<u8>,
    }

    impl Read for Loopback {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.input.read(buf)?;
            if n == 0 {
                return Err(ErrorKind::WouldBlock.into());
            }
            Ok(n)
        }
    }

    impl Write for Loopback {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.output.extend_from_slice(buf);
            Ok(buf.len())
        }

        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn packet(values: [f32; 16]) -> Vec<u8> {
        let mut p = PACKET_SIGNATURE.to_vec();
        for v in values {
            p.extend_from_slice(&v.to_le_bytes());
        }
        let crc = crc16_modbus(&p);
        p.extend_from_slice(&crc.to_le_bytes());
        p
    }

    #[test]
    fn a_corrupted_line_reads_as_a_field_out_of_range() {
        for (output, field) in [
            (Output::MotionCal, ",-42000000,"),
            (Output::Csv, ",-4200000.00,"),
        ] {
            let mut config = FirmwareConfig::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1));
            config.output = output;
            config.lines_per_wall_s = 1e6;
            config.raw_lines = Some(5);
            config.fault = Some(BoardFault::CorruptedAt(2));
            let (report, text) = run(Vec::new(), config);
            assert_eq!(report.raw_lines, 5);
            let lines: Vec<&str> = text.lines().filter(|l| l.contains(field)).collect();
            assert_eq!(lines.len(), 1, "{output:?}: {text}");
        }
    }

    #[test]
    fn the_crc_is_modbus() {
        // The standard check value of CRC-16/MODBUS.
        assert_eq!(crc16_modbus(b"123456789"), 0x4B37);
        let p = packet(DEFAULT_CALIBRATION);
        assert_eq!(crc16_modbus(&p), 0);
    }

    fn run(input: Vec<u8>, config: FirmwareConfig) -> (FirmwareReport, String) {
        let mut port = Loopback {
            input: Cursor::new(input),
            output: Vec::new(),
        };
        let report = MotionCalFirmware::new(&mut port, config)
            .unwrap()
            .run(|| false);
        (report, String::from_utf8_lossy(&port.output).into_owned())
    }

    #[test]
    fn streams_raw_lines_with_garbage_and_takes_a_good_packet() {
        let mut values = DEFAULT_CALIBRATION;
        values[6..10].copy_from_slice(&[1.5, -2.25, 30.0, 48.0]);
        let mut bad = packet(values);
        bad[20] ^= 1;
        let mut input = b"noise".to_vec();
        input.extend(bad);
        input.extend(packet(values));
        let mut config = FirmwareConfig::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1));
        config.raw_lines = Some(40);
        config.garbage_every = Some(10);
        config.echo_every = 1000;
        config.lines_per_wall_s = 1e6;
        let (report, text) = run(input, config);
        assert_eq!((report.raw_lines, report.garbage_lines), (40, 4));
        assert_eq!((report.packets_accepted, report.packets_rejected), (1, 1));
        assert_eq!(report.calibration, values);
        assert!(report.stopped.contains("unplugged after 40"));
        assert!(
            text.contains(
                "Cal1:0.000,0.000,0.000,0.000,0.000,0.000,1.500,-2.250,30.000,48.000\r\n"
            )
        );
        assert!(
            text.contains(
                "Cal2:1.0000,0.0000,0.0000,0.0000,1.0000,0.0000,0.0000,0.0000,1.0000\r\n"
            )
        );
        let raw: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("Raw:") && l.len() > 20)
            .collect();
        assert!(raw.len() >= 40);
        // The magnetometer counts are the bench's field in 0.1 µT: an ideal sensor reads the world's magnitude.
        let m: Vec<f64> = raw[0]
            .split(',')
            .skip(6)
            .map(|v| v.parse::<f64>().unwrap() / 10.0)
            .collect();
        let norm = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        assert!(
            (norm - (20f64 * 20.0 + 45.0 * 45.0).sqrt()).abs() < 0.2,
            "{norm}"
        );
    }

    #[test]
    fn a_csv_board_resets_with_a_new_header_and_its_clock_restarts() {
        let mut config = FirmwareConfig::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1));
        config.raw_lines = Some(6);
        config.output = Output::Csv;
        config.fault = Some(BoardFault::ResetAfter {
            lines: 3,
            new_header: true,
        });
        config.lines_per_wall_s = 1e6;
        let (report, text) = run(Vec::new(), config);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[1..3], ["# sensor: simulated board", CSV_HEADER]);
        assert!(lines[3].starts_with("0.000,") && lines[5].starts_with("0.020,"));
        assert_eq!(lines[8], NEW_CSV_HEADER);
        let t_after: Vec<&str> = lines[9..12]
            .iter()
            .map(|l| l.split(',').nth(4).unwrap())
            .collect();
        assert_eq!(t_after, ["0.000", "0.010", "0.020"]);
        assert_eq!(report.sample_times_s[3], 0.03 + BOOT_S);
    }

    #[test]
    fn silent_and_wrong_baud_boards() {
        let mut config = FirmwareConfig::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1));
        config.fault = Some(BoardFault::WrongBaud);
        config.raw_lines = Some(5);
        config.lines_per_wall_s = 1e6;
        let (_, text) = run(Vec::new(), config.clone());
        assert!(!text.is_empty() && !text.contains('\n') && !text.contains("Raw:"));
        config.fault = Some(BoardFault::SilentAfter(2));
        let stop_at = Instant::now() + Duration::from_millis(50);
        let mut port = Loopback {
            input: Cursor::new(Vec::new()),
            output: Vec::new(),
        };
        let report = MotionCalFirmware::new(&mut port, config)
            .unwrap()
            .run(|| Instant::now() > stop_at);
        assert_eq!(
            (report.raw_lines, report.stopped.as_str()),
            (2, "told to stop")
        );
    }

    #[test]
    fn other_sketches_print_their_own_lines_of_the_same_field() {
        let lines_of = |output: Output| {
            let mut config = FirmwareConfig::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1));
            config.raw_lines = Some(3);
            config.echo_every = 1000;
            config.lines_per_wall_s = 1e6;
            config.output = output;
            let (report, text) = run(Vec::new(), config);
            let lines: Vec<String> = text.lines().map(str::to_owned).collect();
            (report, lines)
        };
        let (report, lines) = lines_of(Output::Adafruit);
        assert_eq!(lines[0], "HMC5883 Magnetometer Test");
        let [x, y, z] = report.sample_mag_ut[2];
        assert_eq!(
            lines.last().unwrap(),
            &format!("X: {x:.2}  Y: {y:.2}  Z: {z:.2}  uT")
        );
        let (report, lines) = lines_of(Output::XyzCounts(0.15));
        let counts = report.sample_mag_ut[0].map(|v| (v / 0.15).round() as i64);
        assert_eq!(
            lines[0],
            format!("{},{},{}", counts[0], counts[1], counts[2])
        );
        let (report, lines) = lines_of(Output::Gauss);
        let [x, ..] = report.sample_mag_ut[1];
        assert!(
            lines[1].starts_with(&format!("t=10ms mag=[{:.5} ", x / 100.0))
                && lines[1].contains(" G temp="),
            "{}",
            lines[1]
        );
        assert_eq!(report.sample_quat.len(), 3);
    }

    #[test]
    fn a_corrupting_firmware_echoes_a_wrong_hard_iron() {
        let mut config = FirmwareConfig::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1));
        config.raw_lines = Some(5);
        config.echo_every = 5;
        config.echo = EchoMode::CorruptHardIron;
        config.lines_per_wall_s = 1e6;
        let (_, text) = run(Vec::new(), config);
        assert!(text.contains("Cal1:0.000,0.000,0.000,0.000,0.000,0.000,0.000,1.000,0.000,50.000"));
    }
}
