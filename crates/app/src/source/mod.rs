//! Where samples come from: a chip driver polled over I2C (real or simulated), a serial line stream, or a flight
//! controller over MAVLink ([`mavlink`]).

pub mod clock;
pub mod mavlink;
pub mod sim;

use std::fmt::Debug;
use std::time::{Duration, Instant};

use magcal_driver::serial::{
    FORMATS, GarbageCounts, GarbageKind, Protocol, SerialSource, StreamStop,
};
use magcal_driver::{Error as ChipError, Magnetometer};

use magcal_mockhw::SharedBench;

use clock::Clock;

/// How many times a failed bus transfer is tried again before the recording stops.
pub const RETRIES: u32 = 3;
/// Wait before the first retry, s; it doubles for each further one.
pub const FIRST_BACKOFF_S: f64 = 0.005;
/// How often a chip's temperature is read, s (it changes slowly; some chips stop measuring to read it).
pub const TEMPERATURE_PERIOD_S: f64 = 1.0;
/// A chip with no new sample for this many sample periods (and at least 1 s) is reported as not measuring.
const SILENT_PERIODS: f64 = 20.0;
/// How long a serial source waits for a line before it lets the recorder look at Ctrl-C and the clock.
const SERIAL_POLL: Duration = Duration::from_millis(50);
/// How long a chip source waits for a sample before it lets the recorder look at Ctrl-C and the clock, s of the
/// device's clock.
const CHIP_POLL_S: f64 = 0.05;
/// How many of the garbage lines of a stream are placed ([`Source::skipped_at`]).
const PLACED_GARBAGE: usize = 5;

/// One sample from a device.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// Time on the device's clock, s.
    pub t_s: f64,
    /// Field, sensor axes, µT.
    pub mag_ut: [f64; 3],
    /// Temperature, °C, where the device gives one.
    pub temp_c: Option<f64>,
    /// Attitude quaternion `[w, x, y, z]` (sensor axes into NED), where the device gives one.
    pub quat: Option<[f64; 4]>,
    /// The current of the device's current channel ([`Source::current_channel`]), A, where it gives one.
    pub current_a: Option<f64>,
}

/// Why a source gave no sample.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SourceError {
    /// The device could not be opened.
    #[error("{device}: cannot open: {error}")]
    Open {
        /// The device string.
        device: String,
        /// What the system said.
        error: String,
    },
    /// The bus kept failing.
    #[error(
        "{device}: bus error after {samples} samples, {attempts} attempts (retried with back-off): {error}"
    )]
    Bus {
        /// The device string.
        device: String,
        /// Samples read before.
        samples: u64,
        /// Attempts made for this sample.
        attempts: u32,
        /// What the last attempt said.
        error: String,
    },
    /// The chip answered but produced no sample for too long.
    #[error(
        "{device}: no new sample for {waited_s:.2} s after {samples} samples (is it measuring?)"
    )]
    Silent {
        /// The device string.
        device: String,
        /// Samples read before.
        samples: u64,
        /// How long was waited, s.
        waited_s: f64,
    },
    /// The chip said something a working chip does not (wrong id, timeout, bad configuration).
    #[error("{device}: {error}")]
    Chip {
        /// The device string.
        device: String,
        /// What the driver said.
        error: String,
    },
    /// A serial device sent no sample for the idle timeout.
    #[error("{device}: no sample for {waited_s:.1} s after {samples} samples: {cause}")]
    NoSamples {
        /// The device string.
        device: String,
        /// Samples read before.
        samples: u64,
        /// How long was waited, s.
        waited_s: f64,
        /// What the line showed, and the likely cause.
        cause: String,
    },
    /// A serial device disconnected.
    #[error("{device}: disconnected after {samples} samples: {reason}")]
    Disconnected {
        /// The device string.
        device: String,
        /// Samples read before.
        samples: u64,
        /// What the port said.
        reason: String,
    },
}

/// Something that gives samples.
pub trait Source {
    /// The device string, for messages (`sim:lis3mdl`, `i2c:/dev/i2c-1:lis3mdl@0x1c`, `serial:/dev/ttyACM0:…`).
    fn device(&self) -> &str;
    /// The sensor's name for the recording's metadata.
    fn sensor(&self) -> String;
    /// The nominal sample rate, Hz, if known.
    fn rate_hz(&self) -> Option<f64>;
    /// Whether readings carry a temperature.
    fn has_temperature(&self) -> bool;
    /// Whether readings carry an attitude quaternion (a board that prints its own).
    fn has_quaternion(&self) -> bool {
        false
    }
    /// The name of the current channel readings carry (a flight controller's battery current, `i_battery`), if any.
    fn current_channel(&self) -> Option<String> {
        None
    }
    /// Metadata the device adds to the recording (what it was asked and gave, what it undid), as unknown keys.
    fn metadata(&self) -> Vec<(String, String)> {
        Vec::new()
    }
    /// The next sample, waiting for it on the device's clock; `None` when none came within a short wait, or the
    /// device gave a saturated sample (call again: the caller meanwhile looks at Ctrl-C and the clock). A saturated
    /// sample is not a field value: it is counted ([`Source::saturated`]) and skipped.
    fn next_reading(&mut self) -> Result<Option<Reading>, SourceError>;
    /// The time on the device's clock, s.
    fn now_s(&self) -> f64;
    /// Samples refused as saturated so far.
    fn saturated(&self) -> u64;
    /// Garbage lines skipped so far, for line streams.
    fn garbage(&self) -> Option<GarbageCounts>;
    /// Where the first garbage lines of a line stream were skipped: how many samples came before each, and what it
    /// was.
    fn skipped_at(&self) -> Vec<(u64, GarbageKind)> {
        Vec::new()
    }
    /// The simulated bench, for `sim` devices: its virtual hand performs the routine.
    fn bench(&self) -> Option<&SharedBench>;
    /// Whether the device's own clock may restart (a board that resets): the recording then notes its segments.
    fn clock_may_restart(&self) -> bool {
        false
    }
    /// Times (on the source's clock, s) at which the device's clock restarted and a new segment of time began,
    /// bridged by the host's clock.
    fn clock_restarts(&self) -> &[f64] {
        &[]
    }
    /// For a link that numbers its frames (MAVLink), the frames received and lost on it so far.
    fn link_loss(&self) -> Option<magcal_autopilot::LinkLoss> {
        None
    }
}

/// A chip driver polled for data-ready on a clock, with retries, temperature and saturation counting.
pub struct ChipSource<M, C> {
    device: String,
    mag: M,
    clock: C,
    rate_hz: f64,
    has_temperature: bool,
    samples: u64,
    saturated: u64,
    temp_c: Option<f64>,
    temp_read_s: f64,
    bench: Option<SharedBench>,
    /// Since when (device clock, s) no sample came.
    waiting_since_s: Option<f64>,
}

impl<M, C, E> ChipSource<M, C>
where
    M: Magnetometer<Error = ChipError<E>>,
    E: Debug,
    C: Clock,
{
    /// Initialises the chip (identify, reset, continuous mode), sets the rate nearest `rate_hz` and the range (the
    /// smallest that holds ±`range_ut`; the driver's default if `None`).
    pub fn start(
        device: String,
        mut mag: M,
        clock: C,
        rate_hz: f64,
        range_ut: Option<f64>,
    ) -> Result<ChipSource<M, C>, SourceError> {
        let chip = |e: ChipError<E>| SourceError::Chip {
            device: device.clone(),
            error: format!("cannot start the chip: {e}"),
        };
        mag.init().map_err(chip)?;
        let rate = f64::from(mag.set_rate_hz(rate_hz as f32).map_err(chip)?);
        if let Some(r) = range_ut {
            mag.set_range_ut(r as f32).map_err(chip)?;
        }
        let has_temperature = mag.info().has_temperature;
        Ok(ChipSource {
            device,
            mag,
            clock,
            rate_hz: rate,
            has_temperature,
            samples: 0,
            saturated: 0,
            temp_c: None,
            temp_read_s: f64::NEG_INFINITY,
            bench: None,
            waiting_since_s: None,
        })
    }

    /// The same source, telling the recorder about the simulated bench behind it.
    pub fn with_bench(mut self, bench: SharedBench) -> ChipSource<M, C> {
        self.bench = Some(bench);
        self
    }

    /// Runs `op` on the chip, trying again after a bus error up to [`RETRIES`] times with doubling back-off.
    fn retried<T>(
        &mut self,
        mut op: impl FnMut(&mut M) -> Result<T, ChipError<E>>,
    ) -> Result<T, ChipError<E>> {
        let mut backoff_s = FIRST_BACKOFF_S;
        let mut attempt = 0;
        loop {
            match op(&mut self.mag) {
                Err(ChipError::I2c(_)) if attempt < RETRIES => {
                    attempt += 1;
                    self.clock.sleep_s(backoff_s);
                    backoff_s *= 2.0;
                }
                other => return other,
            }
        }
    }

    fn bus_error(&self, e: &ChipError<E>) -> SourceError {
        match e {
            ChipError::I2c(_) => SourceError::Bus {
                device: self.device.clone(),
                samples: self.samples,
                attempts: RETRIES + 1,
                error: e.to_string(),
            },
            _ => SourceError::Chip {
                device: self.device.clone(),
                error: format!("after {} samples: {e}", self.samples),
            },
        }
    }
}

impl<M, C, E> Source for ChipSource<M, C>
where
    M: Magnetometer<Error = ChipError<E>>,
    E: Debug,
    C: Clock,
{
    fn device(&self) -> &str {
        &self.device
    }

    fn sensor(&self) -> String {
        self.mag.info().kind.to_string()
    }

    fn rate_hz(&self) -> Option<f64> {
        Some(self.rate_hz)
    }

    fn has_temperature(&self) -> bool {
        self.has_temperature
    }

    /// Polls for data-ready for at most [`CHIP_POLL_S`] per call; no sample for [`SILENT_PERIODS`] periods
    /// (at least 1 s) across calls is an error. A saturated sample ends the call at once.
    fn next_reading(&mut self) -> Result<Option<Reading>, SourceError> {
        let period_s = 1.0 / self.rate_hz;
        let poll_s = period_s / 4.0;
        let give_up_s = (SILENT_PERIODS * period_s).max(1.0);
        let call_s = self.clock.now_s();
        let since_s = *self.waiting_since_s.get_or_insert(call_s);
        loop {
            match self.retried(|m| m.read_ut()) {
                Ok(m) => {
                    let t_s = self.clock.now_s();
                    if self.has_temperature && t_s - self.temp_read_s >= TEMPERATURE_PERIOD_S {
                        self.temp_c = self
                            .retried(|m| m.temperature_c())
                            .map_err(|e| self.bus_error(&e))?
                            .map(f64::from);
                        self.temp_read_s = t_s;
                    }
                    self.samples += 1;
                    self.waiting_since_s = None;
                    return Ok(Some(Reading {
                        t_s,
                        mag_ut: m.map(f64::from),
                        temp_c: self.temp_c,
                        quat: None,
                        current_a: None,
                    }));
                }
                Err(ChipError::NotReady) => {}
                Err(ChipError::Saturated) => {
                    // Measuring, but not a field value: count it, and let the recorder look at the clock.
                    self.saturated += 1;
                    self.waiting_since_s = None;
                    return Ok(None);
                }
                Err(e) => return Err(self.bus_error(&e)),
            }
            let now_s = self.clock.now_s();
            if now_s - since_s > give_up_s {
                return Err(SourceError::Silent {
                    device: self.device.clone(),
                    samples: self.samples,
                    waited_s: now_s - since_s,
                });
            }
            if now_s - call_s >= CHIP_POLL_S {
                return Ok(None);
            }
            self.clock.sleep_s(poll_s);
        }
    }

    fn now_s(&self) -> f64 {
        self.clock.now_s()
    }

    fn saturated(&self) -> u64 {
        self.saturated
    }

    fn garbage(&self) -> Option<GarbageCounts> {
        None
    }

    fn bench(&self) -> Option<&SharedBench> {
        self.bench.as_ref()
    }
}

/// The garbage lines a line stream skipped: how many of each kind, and where the first were.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Skipped {
    /// How many of each kind.
    pub counts: GarbageCounts,
    /// The first ones: how many samples came before each, and what it was.
    pub at: Vec<(u64, GarbageKind)>,
}

impl Skipped {
    /// What `source` skipped, for line streams.
    pub fn of(source: &dyn Source) -> Option<Skipped> {
        source.garbage().map(|counts| Skipped {
            counts,
            at: source.skipped_at(),
        })
    }
}

impl std::fmt::Display for Skipped {
    /// How many lines of each kind, where the first were (after how many samples), and that a line that lost bytes
    /// yet still reads as a sample cannot be told from one.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let counts = &self.counts;
        write!(f, "garbage lines skipped: {} ({counts})", counts.total())?;
        if self.at.is_empty() {
            return Ok(());
        }
        let places: Vec<String> = self
            .at
            .iter()
            .map(|(n, kind)| format!("{n} ({kind})"))
            .collect();
        let more = counts.total().saturating_sub(self.at.len() as u64);
        write!(
            f,
            "; {} after sample {}{}: a line that lost bytes but still reads as a sample in range cannot be told \
             from one, so look at the rows there",
            if self.at.len() == 1 {
                "it came"
            } else {
                "the first came"
            },
            places.join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            }
        )
    }
}

/// Which clock a serial sample's time came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ClockKind {
    /// The board's `t` column.
    Device,
    /// The host's reception time.
    Host,
}

/// The last sample's time, as the clocks gave it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LastTime {
    kind: ClockKind,
    /// On the clock it came from, s.
    clock_s: f64,
    /// On the host's clock, s.
    host_s: f64,
}

/// Samples from a serial line stream (MotionCal `Raw:` lines, native CSV, or lines read by a pattern).
///
/// Time is the board's `t` where the stream has one, the host's reception time otherwise, and never runs backwards
/// or stands still: when the board's clock restarts (it reset), a new segment begins, continued from the last
/// sample's time by the gap the host saw, and is listed in [`Source::clock_restarts`]. No sample for the idle
/// timeout is an error naming the likely cause (silence, wrong baud rate, wrong protocol).
pub struct LineSource {
    device: String,
    source: SerialSource,
    samples: u64,
    last_t_s: f64,
    last: Option<LastTime>,
    /// Added to the current clock's time to make the recording's.
    offset_s: f64,
    restarts: Vec<f64>,
    idle_timeout: Duration,
    last_sample_at: Instant,
    /// Where the first garbage lines were skipped.
    skipped_at: Vec<(u64, GarbageKind)>,
}

impl LineSource {
    /// Reads from an open serial source; no sample for `idle_timeout` is an error.
    pub fn new(device: String, mut source: SerialSource, idle_timeout: Duration) -> LineSource {
        source.set_idle_timeout(SERIAL_POLL.min(idle_timeout));
        LineSource {
            device,
            source,
            samples: 0,
            last_t_s: 0.0,
            last: None,
            offset_s: 0.0,
            restarts: Vec::new(),
            idle_timeout,
            last_sample_at: Instant::now(),
            skipped_at: Vec::new(),
        }
    }

    /// Places the garbage lines skipped since `before` (the counts then), up to [`PLACED_GARBAGE`] in all.
    fn place_garbage(&mut self, before: &GarbageCounts) {
        let now = self.source.counts().garbage;
        for kind in GarbageKind::ALL {
            for _ in before.get(kind)..now.get(kind) {
                if self.skipped_at.len() < PLACED_GARBAGE {
                    self.skipped_at.push((self.samples, kind));
                }
            }
        }
    }

    /// The recording time of a sample with device time `device_t_s` (if finite) received at `host_s`.
    fn time_of(&mut self, device_t_s: Option<f64>, host_s: f64) -> f64 {
        let (kind, clock_s) = match device_t_s.filter(|t| t.is_finite()) {
            Some(t) => (ClockKind::Device, t),
            None => (ClockKind::Host, host_s),
        };
        let t_s = match self.last {
            None => clock_s,
            Some(last) if last.kind != kind || clock_s < last.clock_s => {
                // The board's clock restarted (or the stream lost its t): a new segment, bridged by the host.
                let t_s = self.last_t_s + (host_s - last.host_s).max(0.0);
                self.offset_s = t_s - clock_s;
                self.restarts.push(t_s);
                t_s
            }
            Some(_) => clock_s + self.offset_s,
        };
        self.last = Some(LastTime {
            kind,
            clock_s,
            host_s,
        });
        t_s.max(self.last_t_s)
    }

    /// Why no sample came for `waited_s`: what the line showed, and its likely cause.
    fn silence(&self, waited_s: f64) -> SourceError {
        let counts = self.source.counts();
        let garbage = &counts.garbage;
        let bytes = self.source.bytes_received();
        let noise = garbage.get(GarbageKind::Binary) + garbage.get(GarbageKind::Overlong);
        let protocol = self.source.protocol();
        let last = self
            .source
            .last_garbage()
            .map(|g| format!(" (the last: \"{g}\")"))
            .unwrap_or_default();
        let cause = if self.samples > 0 {
            format!(
                "the board stopped sending samples (hung, or reset and waiting?){}; check it and record again",
                if garbage.total() > 0 {
                    format!("; garbage lines so far: {}", garbage.total())
                } else {
                    String::new()
                }
            )
        } else if bytes == 0 {
            "nothing at all was received: is the board running and streaming, on this port? (some sketches wait \
             for a command, or print only when the port is opened)"
                .to_owned()
        } else if noise * 2 >= counts.lines.max(1) {
            format!(
                "{bytes} bytes received but no readable line: wrong baud rate? give the board's rate in the \
                 device string, serial:PATH:BAUD (this one: {})",
                self.device
            )
        } else if matches!(protocol, Protocol::Csv) && garbage.get(GarbageKind::NoHeader) > 0 {
            format!(
                "{} lines of numbers but no header line naming mx,my,mz: the board printed its header before the \
                 port was opened; reset it while recording",
                garbage.get(GarbageKind::NoHeader)
            )
        } else {
            format!(
                "{} lines received, none a {} sample{last}: wrong format? {} reads {}; the device string's format \
                 is one of {FORMATS} (serial:PATH[:BAUD][:FORMAT])",
                counts.lines,
                protocol.name(),
                protocol.name(),
                protocol.shape()
            )
        };
        SourceError::NoSamples {
            device: self.device.clone(),
            samples: self.samples,
            waited_s,
            cause,
        }
    }
}

impl Source for LineSource {
    fn device(&self) -> &str {
        &self.device
    }

    fn sensor(&self) -> String {
        format!("serial ({} stream)", self.source.protocol().name())
    }

    fn rate_hz(&self) -> Option<f64> {
        None
    }

    /// Native CSV streams may carry `temp`, and patterns with a `temp` group; MotionCal lines never do.
    fn has_temperature(&self) -> bool {
        match self.source.protocol() {
            Protocol::Csv => true,
            Protocol::Pattern(p) => p.has_temperature(),
            Protocol::MotionCal => false,
        }
    }

    /// Patterns with `qw,qx,qy,qz` groups carry the board's attitude.
    fn has_quaternion(&self) -> bool {
        matches!(self.source.protocol(), Protocol::Pattern(p) if p.has_quaternion())
    }

    /// The next sample, or `None` after a short wait; no sample for the idle timeout is an error, and so is a
    /// disconnect.
    fn next_reading(&mut self) -> Result<Option<Reading>, SourceError> {
        let before = self.source.counts().garbage;
        let read = self.source.read_sample();
        self.place_garbage(&before);
        match read {
            Ok(r) => {
                self.samples += 1;
                self.last_sample_at = Instant::now();
                let t_s = self.time_of(r.sample.t_s, r.host_s);
                self.last_t_s = t_s;
                Ok(Some(Reading {
                    t_s,
                    mag_ut: r.sample.mag_ut,
                    temp_c: r.sample.temp_c.filter(|t| t.is_finite()),
                    quat: r.sample.quat_wxyz,
                    current_a: None,
                }))
            }
            Err(StreamStop::Idle { .. }) => {
                let waited = self.last_sample_at.elapsed();
                if waited >= self.idle_timeout {
                    return Err(self.silence(waited.as_secs_f64()));
                }
                Ok(None)
            }
            Err(StreamStop::Disconnected { reason }) => Err(SourceError::Disconnected {
                device: self.device.clone(),
                samples: self.samples,
                reason,
            }),
        }
    }

    fn now_s(&self) -> f64 {
        self.last_t_s
    }

    fn saturated(&self) -> u64 {
        0
    }

    fn garbage(&self) -> Option<GarbageCounts> {
        Some(self.source.counts().garbage)
    }

    fn skipped_at(&self) -> Vec<(u64, GarbageKind)> {
        self.skipped_at.clone()
    }

    fn bench(&self) -> Option<&SharedBench> {
        None
    }

    fn clock_may_restart(&self) -> bool {
        true
    }

    fn clock_restarts(&self) -> &[f64] {
        &self.restarts
    }
}
