//! The recorder behind `magcal-record`: a [`Source`] of samples, a routine that tells the operator (or the virtual
//! hand of a `sim` device) what to do, and an incremental, crash-safe [`RecordingWriter`].
//!
//! - **free**: the sensor is turned freely; every sample is written (with the board's attitude, when a serial
//!   board prints one); the recording stops when the live [`CoverageMap`] of the written samples reaches the
//!   target coverage of the sphere of field directions, after the longest duration, or on an interrupt (Ctrl-C).
//! - **cube24**: the 24 static poses of a cube jig against a reference edge ([`magcal_sim::cube24_poses`]). Each
//!   prompt names the face down and where the reference edge points. Once the sensor has left the last pose and has
//!   stayed still for a dwell (every axis' spread below a threshold), it has settled; from then on each sample that
//!   keeps it still (the last dwell's spread stays below the threshold, and the sample is within three thresholds
//!   of where it settled) is written at once with the pose's attitude quaternion, which gives the vector
//!   calibration its reference, until a dwell's worth is written and the pose is taken. A sample that moves ends
//!   the take: the rows written stay (they were still, at the pose), and the pose is taken once the jig settles
//!   again. Enter takes the next dwell whatever it holds. The settling dwell keeps the end of the move out.
//! - **motors**: a bench motor test. The vehicle is held still (props off or held down) while the operator raises the
//!   throttle to full and lowers it, twice, then blips it ([`motors::BLIPS`] quick steps up and back, which time the
//!   field's lag behind the current); magcal only reads (it never arms the vehicle or commands its motors).
//!   Every sample is written with its attitude and current; the live display shows the current and the field's
//!   change since the start ([`ThrottleWatch`]); the recording stops once the ramps and the blips are made
//!   ([`motors::RAMPS`] and [`motors::BLIPS`] reaching [`motors::RAMP_SHARE`] of the highest current). A device
//!   without a current channel is refused
//!   before the file is made. The field's magnitude is not watched for magnets: its change with the current is
//!   what is measured. Its fit is the current term alone (`magcal-fit`, [`crate::motors`]).
//!
//! The coverage map counts the samples written, by the definition the fit uses too
//! ([`magcal_calib::directions`]), so the recorder's figure and the fit's agree; in the cube routine that is the
//! poses' few directions, and no target applies. [`Quality`] gives MotionCal's figures of the samples written.
//! Both routines watch the field magnitude of every reading ([`MagnitudeWatch`]): a magnet or iron near the sensor,
//! which changes it, is said live and shown while it lasts; its samples are written but do not count as coverage.
//! Saturated samples (counted by the source) are not written.
//!
//! An existing file is never replaced unless asked ([`RecordOptions::force`]; [`crate::outputs`] says so before the
//! device is opened), and then only once the first sample is written (until then the old file stays; the path
//! itself is replaced, not what a link there points to); the file is locked while it is written, so a second
//! recorder, or any tool's output, on it is refused. The file is created (metadata and header flushed) before the
//! first sample, so an unwritable path fails before anything is recorded; rows reach the file as they are taken, at
//! least every [`FLUSH_INTERVAL`], so a killed recorder leaves a file that parses and holds all but the last
//! moments, and a failed write (a full disk, a file size limit) leaves whole lines only. Whatever the device does (a
//! chip saturated for minutes, a silent line), the loop ([`session`]) looks at Ctrl-C and the clock at least every
//! few tens of milliseconds. A device that fails (a bus that stays down after retries, a serial line that disconnects or goes
//! silent, outputs that stop changing) ends the recording with an error naming the device and how many samples the
//! file keeps.

pub mod coverage;
pub mod magnitude;
pub mod motors;
pub mod quality;
mod session;
pub mod still;
pub mod ui;

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use magcal_recording::{CreateOptions, Layout, Metadata, Note, RecordingWriter, Sample};
use magcal_sim::{CubePose, cube24_poses};

use crate::checks::EARTH_FIELD_UT;
use crate::device::{BadOption, DeviceSpec, positive_at_most, within};
use crate::source::sim;

pub use crate::source::{Reading, Skipped, Source, SourceError};
pub use coverage::CoverageMap;
pub use magnitude::{Disturbance, MagnitudeEvent, MagnitudeWatch};
pub use motors::{Throttle, ThrottleWatch};
pub use quality::Quality;
pub use still::StillWindow;
pub use ui::{Progress, Ui};

/// What the operator does during the recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Routine {
    /// Free rotation until the coverage target (a scalar calibration).
    Free,
    /// The 24 poses of a cube jig against a reference edge (a vector calibration).
    Cube24,
    /// A bench motor test: the vehicle held still while the throttle goes up and down (the current term only).
    Motors,
}

impl Routine {
    /// The name used on the command line and in the recording's `routine` metadata.
    pub fn name(self) -> &'static str {
        match self {
            Routine::Free => "free",
            Routine::Cube24 => "cube24",
            Routine::Motors => "motors",
        }
    }

    /// The routine `device` gets when none is asked for: a simulated bench has its jig, on a known heading (the
    /// virtual hand puts the chip through the cube's 24 poses: the vector calibration); a real chip or board is most
    /// often turned by hand, without one, so it gets the free routine (the scalar calibration), which needs neither
    /// a jig nor the local field.
    pub fn default_for(device: &DeviceSpec) -> Routine {
        if device.is_sim() {
            Routine::Cube24
        } else {
            Routine::Free
        }
    }

    /// What the other routine would add to a calibration made with this one, said after its summary: the cube's
    /// poses give the vector method what the free routine's scalar one cannot see. Nothing for cube24.
    pub fn what_the_other_adds(self) -> Option<&'static str> {
        match self {
            Routine::Free => Some(
                "the free routine gives the scalar calibration (the field's magnitude only: the offset and the gains, \
                 not how the sensor's axes are turned against the board's); with a non-magnetic cube jig against an \
                 edge on a known heading and the local field (--location/--date), --routine cube24 gives the vector \
                 calibration, which adds that misalignment (it goes straight into the heading) and checks the fit \
                 against the field's direction",
            ),
            Routine::Cube24 | Routine::Motors => None,
        }
    }
}

/// How to record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordOptions {
    /// The routine.
    pub routine: Routine,
    /// The recording to write.
    pub out: PathBuf,
    /// Replace `out` if it exists (otherwise an existing file is an error and is left alone).
    pub force: bool,
    /// Metadata to write; the recorder fills in `sensor` (if absent), `sample_rate_hz`, `routine` and `started`.
    pub meta: Metadata,
    /// Unattended: never wait for Enter. A `sim` device's virtual hand performs the routine either way.
    pub auto: bool,
    /// Free routine: stop at this fraction of the sphere of directions (0–1).
    pub target_coverage: f64,
    /// Stop after this long in any case, s.
    pub max_duration_s: f64,
    /// Cube routine: how long a pose must be held still, s; its samples are the ones recorded.
    pub dwell_s: f64,
    /// Cube routine: the largest spread per axis (standard deviation over the dwell) that counts as still, µT.
    pub still_ut: f64,
    /// Virtual hand: how long it takes to move the jig to the next pose, s.
    pub transition_s: f64,
}

impl RecordOptions {
    /// Defaults: 90 % coverage, at most 10 minutes, 1 s dwell, still below 0.5 µT, 1.5 s moves, attended, never
    /// replacing a file.
    pub fn new(routine: Routine, out: PathBuf) -> RecordOptions {
        RecordOptions {
            routine,
            out,
            force: false,
            meta: Metadata::default(),
            auto: false,
            target_coverage: 0.9,
            max_duration_s: 600.0,
            dwell_s: 1.0,
            still_ut: 0.5,
            transition_s: 1.5,
        }
    }
}

/// The longest dwell, s: a pose held for longer is no better measured.
pub const MAX_DWELL_S: f64 = 60.0;
/// The shortest dwell, s: a pose held for less cannot be told still (and the device's rate may ask for more:
/// [`MIN_DWELL_SAMPLES`]).
pub const MIN_DWELL_S: f64 = 0.1;
/// The longest recording, s (a week).
pub const MAX_DURATION_S: f64 = 604_800.0;
/// The shortest `--max-duration`, s: less records too few samples to turn through any directions (1e-9 s wrote an
/// empty recording, exit 0).
pub const MIN_DURATION_S: f64 = 1.0;
/// The largest stillness threshold, µT.
pub const MAX_STILL_UT: f64 = 1000.0;
/// How often rows reach the file at least (half the half second a killed recorder may lose).
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(250);

impl RecordOptions {
    /// Checks the options before anything is opened: coverage a fraction in (0, 1], durations, dwell and stillness
    /// positive and within their ranges.
    pub fn check(&self) -> Result<(), BadOption> {
        if !(self.target_coverage > 0.0 && self.target_coverage <= 1.0) {
            return Err(BadOption(format!(
                "--coverage {}: must be a fraction in (0, 1]",
                self.target_coverage
            )));
        }
        positive_at_most("--max-duration", self.max_duration_s, MAX_DURATION_S, "s")?;
        if self.max_duration_s < MIN_DURATION_S {
            return Err(BadOption(format!(
                "--max-duration {} s: must be at least {MIN_DURATION_S} s (a calibration needs the sensor turned \
                 through many directions)",
                self.max_duration_s
            )));
        }
        within("--dwell", self.dwell_s, MIN_DWELL_S, MAX_DWELL_S, "s")?;
        positive_at_most("--still-ut", self.still_ut, MAX_STILL_UT, "µT")?;
        positive_at_most("transition", self.transition_s, MAX_DWELL_S, "s")
    }
}

/// The option that names the recording in magcal-record, said in [`RecordError::Exists`] and [`RecordError::Busy`].
const OUT_OPTION: &str = "--out";

/// Why a recording ended without an error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The free routine reached its coverage target.
    Coverage,
    /// The cube routine took all its poses.
    AllPoses,
    /// The motors routine's ramps and blips are made.
    Ramps,
    /// Interrupted (Ctrl-C).
    Interrupted,
    /// The longest duration passed.
    MaxDuration,
}

/// What was recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordSummary {
    /// The file.
    pub path: PathBuf,
    /// Rows written.
    pub samples: u64,
    /// Recording time, s.
    pub duration_s: f64,
    /// Fraction of the sphere of directions the written samples cover (the fit's definition, so its figure).
    pub coverage: f64,
    /// Cube poses taken.
    pub poses: usize,
    /// Motors routine: throttle ramps made ([`motors::RAMPS`] asked for).
    pub ramps: usize,
    /// Motors routine: throttle blips made after the ramps ([`motors::BLIPS`] asked for).
    pub blips: usize,
    /// Samples the chip refused as saturated (not recorded).
    pub saturated: u64,
    /// Readings whose field magnitude departed from the rest's (a magnet or iron nearby; recorded, not counted as
    /// coverage).
    pub disturbed: u64,
    /// Times at which the device's clock restarted and a new segment of time began, s of recording time.
    pub clock_restarts: Vec<f64>,
    /// Frames a numbered link (MAVLink) lost.
    pub link_loss: Option<magcal_autopilot::LinkLoss>,
    /// Garbage lines skipped (line streams).
    pub garbage: Option<Skipped>,
    /// No sample came, and the file `--force` was to replace was left as it was.
    pub untouched: bool,
    /// Why it stopped.
    pub stop: Stop,
}

impl RecordSummary {
    /// What the recording lacks when it stopped before its routine's target (Ctrl-C, the longest duration): how far
    /// it got, and what to do. A fit of it may be refused (too few directions to fix the offset) or loose.
    pub fn shortfall(&self, opts: &RecordOptions) -> Option<String> {
        if !matches!(self.stop, Stop::Interrupted | Stop::MaxDuration) {
            return None;
        }
        let poses = cube24_poses().len();
        let got = match opts.routine {
            Routine::Free if self.coverage < opts.target_coverage => format!(
                "{:.0} % of the sphere covered, of the {:.0} % aimed at",
                100.0 * self.coverage,
                100.0 * opts.target_coverage
            ),
            Routine::Cube24 if self.poses < poses => {
                format!("{} of the {poses} poses taken", self.poses)
            }
            Routine::Motors if self.ramps < motors::RAMPS => {
                return Some(format!(
                    "the recording stopped short of its routine: {} of the {} throttle ramps made (up to at least \
                     {:.0} % of the highest current and back). A fit may find no current term, or a loose one: \
                     record again, raising the throttle slowly to full and back, twice, then blipping it {} times",
                    self.ramps,
                    motors::RAMPS,
                    100.0 * motors::RAMP_SHARE,
                    motors::BLIPS
                ));
            }
            Routine::Motors if self.blips < motors::BLIPS => {
                return Some(format!(
                    "the recording stopped short of its routine: the ramps made, {} of the {} throttle blips (up to \
                     at least {:.0} % of the highest current within {:.1} s, and back). The coefficients hold; the \
                     lag of the field behind the current may not be determined: record again with the blips",
                    self.blips,
                    motors::BLIPS,
                    100.0 * motors::RAMP_SHARE,
                    motors::BLIP_RISE_S
                ));
            }
            _ => return None,
        };
        Some(format!(
            "the recording stopped short of its routine: {got}. A fit may be refused (too few directions to fix the \
             offset) or loose: record again, turning the sensor through every orientation{}",
            match opts.routine {
                Routine::Free | Routine::Motors => "",
                Routine::Cube24 => " (all 24 poses)",
            }
        ))
    }
}

/// Why a recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file exists, and replacing it was not asked for: nothing was recorded, the file is untouched.
    #[error(
        "{} exists: a recording is never replaced; choose another {option}, or add --force to replace it (nothing \
         was recorded)",
        path.display()
    )]
    Exists {
        /// The path.
        path: PathBuf,
        /// The option that names the output (`--out`; see [`RecordError::for_option`]).
        option: &'static str,
    },
    /// Another process holds the file's lock (another recorder is writing it): nothing was recorded.
    #[error(
        "{} is being written by another recorder (it holds the file's lock): choose another {option} (nothing was \
         recorded)",
        path.display()
    )]
    Busy {
        /// The path.
        path: PathBuf,
        /// The option that names the output (`--out`; see [`RecordError::for_option`]).
        option: &'static str,
    },
    /// The file could not be created: nothing was recorded.
    #[error("cannot create the recording {}: {io}; nothing was recorded", path.display())]
    Create {
        /// The path.
        path: PathBuf,
        /// What the system said (in the message, so not a source: it would be said twice).
        io: std::io::Error,
    },
    /// Writing rows failed (a full disk, say); the file holds whole lines only, and parses.
    #[error(
        "writing {} failed: {io}; the file keeps the {kept} samples written before (whole lines: it parses)",
        path.display()
    )]
    Write {
        /// The path.
        path: PathBuf,
        /// Rows in the file.
        kept: u64,
        /// What the system said (in the message, so not a source: it would be said twice).
        io: std::io::Error,
    },
    /// The device failed; the file keeps what was recorded.
    #[error(
        "{error}; {}{}",
        if *untouched {
            format!("no sample was recorded, and {} was left as it was", path.display())
        } else {
            format!("{} keeps the {kept} samples recorded before", path.display())
        },
        garbage.as_deref().map(|g| format!("; {g}")).unwrap_or_default()
    )]
    Device {
        /// What the device did.
        error: SourceError,
        /// The path.
        path: PathBuf,
        /// Rows in the file.
        kept: u64,
        /// Garbage lines skipped (line streams).
        garbage: Option<Box<Skipped>>,
        /// No sample came, and the file `--force` was to replace was left as it was.
        untouched: bool,
    },
    /// A cube dwell too short at the device's rate: nothing was recorded.
    #[error(
        "--dwell {} s holds {:.0} samples at the {rate_hz} Hz the device gives: a pose needs at least \
         {MIN_DWELL_SAMPLES} to tell a still jig from a moving one; give --dwell {:.2} or more (nothing was recorded)",
        crate::cli::number(*dwell_s),
        (dwell_s * rate_hz).round(),
        MIN_DWELL_SAMPLES / rate_hz
    )]
    Dwell {
        /// The dwell asked for, s.
        dwell_s: f64,
        /// The device's rate, Hz.
        rate_hz: f64,
    },
    /// The motors routine on a device that gives no current: nothing was recorded.
    #[error(
        "{device}: the motors routine needs the current the motors draw, and this device gives none (a flight \
         controller's battery current comes as BATTERY_STATUS: is its battery monitor set up, and does this link \
         carry that stream?); nothing was recorded"
    )]
    NoCurrent {
        /// The device string.
        device: String,
    },
    /// The device's outputs stopped changing.
    #[error(
        "{device}: the output is stuck at {value:?} µT: {repeats} identical samples in a row from sample {from} on \
         (a real sensor's noise changes every sample); {} keeps the {kept} samples recorded before",
        path.display()
    )]
    Stuck {
        /// The device string.
        device: String,
        /// The repeated reading.
        value: [f64; 3],
        /// How many times in a row.
        repeats: u64,
        /// Row number where the repetition began.
        from: u64,
        /// The path.
        path: PathBuf,
        /// Rows in the file.
        kept: u64,
    },
}

impl RecordError {
    /// The error with `option` as the option to choose another output with, for a tool whose output is named by
    /// another option than magcal-record's `--out` (magcal's `--out-dir`).
    pub fn for_option(mut self, option: &'static str) -> RecordError {
        if let RecordError::Exists { option: o, .. } | RecordError::Busy { option: o, .. } =
            &mut self
        {
            *o = option;
        }
        self
    }
}

/// A pose counts as left when the field's mean moved this far from where the last pose was taken, µT.
const MOVED_UT: f64 = 5.0;

/// Where the cube routine is with the current pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PoseState {
    /// The last pose was taken: waiting for the jig to leave it.
    AwaitMove,
    /// Waiting for a dwell of stillness (the jig settles in the new pose).
    AwaitStill,
    /// Settled: samples are taken while they keep it still (or whatever they hold, after Enter).
    Hold,
}

/// The writer with its bookkeeping.
struct Out {
    writer: RecordingWriter,
    layout: Layout,
    t0_s: f64,
}

/// The metadata note that says how many of a numbered link's frames were lost ([`Source::link_loss`]).
pub const LINK_NOTE: &str = "link_lost";
/// Room for the link note, bytes.
const LINK_WIDTH: usize = 120;

/// The link note's value.
fn link_note(loss: Option<&magcal_autopilot::LinkLoss>) -> String {
    match loss {
        None => "counted when the recording ends (it is still recording, or did not end cleanly)"
            .to_owned(),
        Some(l) => format!(
            "{} of the autopilot's {} frames ({:.2} %: gaps in its sequence numbers)",
            l.lost,
            l.received + l.lost,
            100.0 * l.share()
        ),
    }
}

/// The metadata note that lists the segments of a recording's time.
pub const SEGMENTS_NOTE: &str = "segments";
/// Room for the segments note, bytes.
const SEGMENTS_WIDTH: usize = 160;

/// The segments note's value: how many, and where the later ones begin.
fn segments_note(restarts_s: &[f64]) -> String {
    if restarts_s.is_empty() {
        return "1".to_owned();
    }
    let times: Vec<String> = restarts_s.iter().map(|t| format!("{t:.3}")).collect();
    let mut note = String::new();
    for shown in (1..=times.len()).rev() {
        let more = times.len() - shown;
        let list = times[..shown].join(", ");
        let tail = if more > 0 {
            format!(" and {more} more")
        } else {
            String::new()
        };
        note = format!(
            "{} (the device's clock restarted at t = {list}{tail} s; each new segment continues from the host's clock)",
            restarts_s.len() + 1
        );
        if note.len() <= SEGMENTS_WIDTH {
            break;
        }
    }
    note
}

impl Out {
    /// Creates the file `opts.out` (metadata and header flushed, locked) for a recording from `source`.
    fn create(source: &dyn Source, opts: &RecordOptions) -> Result<Out, RecordError> {
        let layout = Layout {
            t: true,
            temp: source.has_temperature(),
            quat: opts.routine == Routine::Cube24 || source.has_quaternion(),
            currents: source.current_channel().into_iter().collect(),
            ..Layout::default()
        };
        let mut meta = opts.meta.clone();
        meta.other.extend(source.metadata());
        meta.sensor.get_or_insert_with(|| source.sensor());
        meta.sample_rate_hz = source.rate_hz();
        meta.routine = Some(opts.routine.name().to_owned());
        meta.started = Some(utc_rfc3339(SystemTime::now()));
        let create = CreateOptions {
            overwrite: opts.force,
            notes: source
                .clock_may_restart()
                .then(|| Note {
                    key: SEGMENTS_NOTE.to_owned(),
                    value: segments_note(&[]),
                    width: SEGMENTS_WIDTH,
                })
                .into_iter()
                .chain(source.link_loss().map(|_| Note {
                    key: LINK_NOTE.to_owned(),
                    value: link_note(None),
                    width: LINK_WIDTH,
                }))
                .collect(),
        };
        let path = &opts.out;
        let writer = RecordingWriter::create_with(path, &meta, &layout, &create)
            .map_err(|io| match io.kind() {
                std::io::ErrorKind::AlreadyExists => RecordError::Exists {
                    path: path.clone(),
                    option: OUT_OPTION,
                },
                std::io::ErrorKind::WouldBlock => RecordError::Busy {
                    path: path.clone(),
                    option: OUT_OPTION,
                },
                // A folder that is not there is named: the system's "No such file" does not say which.
                std::io::ErrorKind::NotFound => RecordError::Create {
                    path: path.clone(),
                    io: std::io::Error::other(format!(
                        "its folder {} does not exist",
                        magcal_recording::atomic::folder_of(path).display()
                    )),
                },
                _ => RecordError::Create {
                    path: path.clone(),
                    io,
                },
            })?
            .with_flush_interval(FLUSH_INTERVAL);
        Ok(Out {
            writer,
            layout,
            t0_s: source.now_s(),
        })
    }

    fn write(&mut self, r: &Reading, quat: Option<[f64; 4]>) -> Result<(), RecordError> {
        let sample = Sample {
            t_s: r.t_s - self.t0_s,
            mag_ut: r.mag_ut,
            temp_c: if self.layout.temp {
                r.temp_c.unwrap_or(f64::NAN)
            } else {
                f64::NAN
            },
            quat: quat.unwrap_or([f64::NAN; 4]),
            currents_a: if self.layout.currents.is_empty() {
                Vec::new()
            } else {
                vec![r.current_a.unwrap_or(f64::NAN)]
            },
            ..Sample::default()
        };
        self.writer
            .write_sample(&sample)
            .map_err(|source| self.write_failed(source))
    }

    /// Writes buffered rows out if they have waited long enough (when no sample came).
    fn flush_if_due(&mut self) -> Result<(), RecordError> {
        self.writer
            .flush_if_due()
            .map_err(|source| self.write_failed(source))
    }

    /// Notes the segments of time after a restart of the device's clock.
    fn note_segments(&mut self, restarts_s: &[f64]) -> Result<(), RecordError> {
        let relative: Vec<f64> = restarts_s.iter().map(|t| t - self.t0_s).collect();
        self.writer
            .set_note(SEGMENTS_NOTE, &segments_note(&relative))
            .map_err(|source| self.write_failed(source))
    }

    /// Notes the frames the link lost, as counted at the end.
    fn note_link(&mut self, loss: &magcal_autopilot::LinkLoss) -> Result<(), RecordError> {
        self.writer
            .set_note(LINK_NOTE, &link_note(Some(loss)))
            .map_err(|source| self.write_failed(source))
    }

    fn write_failed(&self, source: std::io::Error) -> RecordError {
        RecordError::Write {
            path: self.writer.path().to_owned(),
            kept: self.writer.rows_in_file(),
            io: source,
        }
    }

    fn rows(&self) -> u64 {
        self.writer.rows()
    }

    fn path(&self) -> &Path {
        self.writer.path()
    }

    /// Writes what is buffered and syncs; returns the rows the file holds, whether a file it was to replace was
    /// left as it was (no row came), and the error if that failed.
    fn finish(mut self) -> (u64, bool, Result<(), RecordError>) {
        let flushed = self.writer.flush();
        let kept = self.writer.rows_in_file();
        let untouched = self.writer.replacing();
        let path = self.path().to_owned();
        let result = match flushed {
            Ok(()) => self.writer.finish(),
            Err(e) => Err(e),
        };
        (
            kept,
            untouched,
            result.map_err(|io| RecordError::Write { path, kept, io }),
        )
    }
}

/// The metadata a recording from `spec` starts with, added to `meta`: the device string; for `sim` devices the
/// seed, and the simulated bench's world field unless `meta` states the field already.
pub fn device_metadata(spec: &DeviceSpec, sim_seed: u64, mut meta: Metadata) -> Metadata {
    meta.other.push(("device".to_owned(), spec.to_string()));
    if spec.is_sim() {
        if meta.field_ned_ut.is_none() && meta.location.is_none() {
            meta.field_ned_ut = Some(sim::FIELD_NED_UT);
        }
        meta.other.push((
            "simulated".to_owned(),
            format!("magcal-record {spec}, seed {sim_seed}"),
        ));
    }
    meta
}

/// For a `sim` device whose recording states a field other than the simulated bench's (`--field-ned`, or
/// `--location`/`--date`), what to tell the user: the bench keeps its own field, and a fit against the stated one is a
/// fit against a wrong reference.
pub fn sim_field_note(spec: &DeviceSpec, meta: &Metadata) -> Option<String> {
    if !spec.is_sim() {
        return None;
    }
    let differs = match meta.field_ned_ut {
        Some(f) => (0..3).any(|k| (f[k] - sim::FIELD_NED_UT[k]).abs() > 1e-9),
        None => meta.location.is_some(),
    };
    differs.then(|| {
        let f = sim::FIELD_NED_UT;
        format!(
            "note: the simulated bench's field is {}, {}, {} µT NED whatever the field given says; the recording's \
             metadata keeps the field given, so a fit against it is a fit against a wrong reference field (leave \
             --field-ned and --location out to fit against the bench's own)",
            f[0], f[1], f[2]
        )
    })
}

/// The prompt for a cube pose.
pub fn pose_prompt(k: usize, pose: &CubePose) -> String {
    let edge = if pose.face_down.ends_with('X') {
        "+Z"
    } else {
        "+X"
    };
    format!(
        "pose {}/24: {} face down, {edge} edge (the reference edge) pointing {} — hold it still against the edge",
        k + 1,
        pose.face_down,
        pose.heading
    )
}

/// Records from `source` as `opts` say, until the routine is done, `interrupt` is set, or the device fails.
pub fn record(
    source: &mut dyn Source,
    opts: &RecordOptions,
    ui: &mut dyn Ui,
    interrupt: &AtomicBool,
) -> Result<RecordSummary, RecordError> {
    check_dwell(source, opts)?;
    check_current(source, opts)?;
    let mut out = Out::create(source, opts)?;
    let result = session::run(source, opts, ui, interrupt, &mut out);
    ui.finish();
    let (kept, untouched, finished) = out.finish();
    match (result, finished) {
        (Ok(mut summary), Ok(())) => {
            summary.samples = kept;
            summary.untouched = untouched;
            Ok(summary)
        }
        (Err(mut e), _) => {
            // The file may have lost its last buffered rows with the error: count what it holds.
            match &mut e {
                RecordError::Device {
                    kept: k,
                    untouched: u,
                    ..
                } => (*k, *u) = (kept, untouched),
                RecordError::Stuck { kept: k, .. } => *k = kept,
                _ => {}
            }
            Err(e)
        }
        (Ok(_), Err(e)) => Err(e),
    }
}

/// Fewest samples a cube pose's dwell may hold: fewer cannot tell a still jig from a moving one.
pub const MIN_DWELL_SAMPLES: f64 = 10.0;

/// Refuses, once the device's rate is known and before the file is made, a cube dwell of fewer than
/// [`MIN_DWELL_SAMPLES`].
fn check_dwell(source: &dyn Source, opts: &RecordOptions) -> Result<(), RecordError> {
    let rate_hz = source.rate_hz().unwrap_or(DEFAULT_RATE_HZ);
    if opts.routine == Routine::Cube24 && (opts.dwell_s * rate_hz).round() < MIN_DWELL_SAMPLES {
        return Err(RecordError::Dwell {
            dwell_s: opts.dwell_s,
            rate_hz,
        });
    }
    Ok(())
}

/// Refuses, before the file is made, the motors routine on a device without a current channel.
fn check_current(source: &dyn Source, opts: &RecordOptions) -> Result<(), RecordError> {
    if opts.routine == Routine::Motors && source.current_channel().is_none() {
        return Err(RecordError::NoCurrent {
            device: source.device().to_owned(),
        });
    }
    Ok(())
}

/// The rate a source that does not say its own is taken to have, Hz.
const DEFAULT_RATE_HZ: f64 = 100.0;

/// Where the cube routine is with the current pose.
struct Cube {
    poses: Vec<CubePose>,
    window: StillWindow,
    taken: usize,
    state: PoseState,
    /// Where the jig settled (the mean of the settling dwell), µT.
    settled_ut: [f64; 3],
    /// Rows written for the pose being taken: how many, and their sum (for the mean), µT.
    held: usize,
    held_sum_ut: [f64; 3],
    last_pose_mean: Option<[f64; 3]>,
    manual_take: bool,
}

impl Cube {
    fn new(dwell_len: usize) -> Cube {
        Cube {
            poses: cube24_poses().to_vec(),
            window: StillWindow::new(dwell_len),
            taken: 0,
            state: PoseState::AwaitStill,
            settled_ut: [0.0; 3],
            held: 0,
            held_sum_ut: [0.0; 3],
            last_pose_mean: None,
            manual_take: false,
        }
    }

    fn start_hold(&mut self) {
        self.state = PoseState::Hold;
        self.settled_ut = self.window.mean_ut();
        self.held = 0;
        self.held_sum_ut = [0.0; 3];
    }

    /// Whether reading `r` keeps the settled jig still: the last dwell's spread stays below the threshold, and `r`
    /// is within three thresholds of where it settled.
    fn steady(&self, r: &Reading, still_ut: f64) -> bool {
        self.window.is_still(still_ut)
            && (0..3).all(|k| (r.mag_ut[k] - self.settled_ut[k]).abs() <= 3.0 * still_ut)
    }
}

/// One reading of the cube routine: moves the pose state on and writes the reading if it is taken. Returns whether
/// all poses are taken.
fn cube_step(
    jig: &mut Cube,
    r: &Reading,
    source: &mut dyn Source,
    opts: &RecordOptions,
    ui: &mut dyn Ui,
    out: &mut Out,
    map: &mut CoverageMap,
) -> Result<bool, RecordError> {
    if !jig.manual_take && ui.enter_pressed() {
        jig.manual_take = true;
        jig.start_hold();
    }
    jig.window.push(*r);
    let full = jig.window.is_full();
    let still = jig.window.is_still(opts.still_ut);
    match jig.state {
        PoseState::AwaitMove if full => {
            let mean = jig.window.mean_ut();
            let away = jig.last_pose_mean.is_none_or(|m| {
                (0..3).map(|k| (mean[k] - m[k]).powi(2)).sum::<f64>().sqrt() > MOVED_UT
            });
            if away || !still {
                jig.state = PoseState::AwaitStill;
            }
        }
        // Still for a dwell: the jig has settled. Take the samples that keep it still.
        PoseState::AwaitStill if still => {
            jig.start_hold();
            return Ok(false);
        }
        _ => {}
    }
    if jig.state != PoseState::Hold {
        return Ok(false);
    }
    if !(jig.manual_take || jig.steady(r, opts.still_ut)) {
        jig.state = PoseState::AwaitStill;
        if jig.held > 0 {
            ui.message(&format!(
                "  moved after {} samples of the pose: hold it still against the edge",
                jig.held
            ));
        }
        return Ok(false);
    }
    let pose = &jig.poses[jig.taken];
    out.write(r, Some(pose.quat))?;
    map.add(r.mag_ut);
    jig.held += 1;
    (0..3).for_each(|k| jig.held_sum_ut[k] += r.mag_ut[k]);
    if jig.held < jig.window.capacity() {
        return Ok(false);
    }
    let mean = jig.held_sum_ut.map(|s| s / jig.held as f64);
    ui.message(&format!(
        "  taken: {} samples, mean [{:.2}, {:.2}, {:.2}] µT{}",
        jig.held,
        mean[0],
        mean[1],
        mean[2],
        if jig.manual_take { " (Enter)" } else { "" }
    ));
    jig.taken += 1;
    jig.last_pose_mean = Some(mean);
    jig.state = PoseState::AwaitMove;
    jig.manual_take = false;
    jig.window.clear();
    if jig.taken == jig.poses.len() {
        return Ok(true);
    }
    let next = jig.poses[jig.taken];
    prompt_pose(source, opts, ui, jig.taken, &next);
    Ok(false)
}

/// Prompts for pose `k`; a `sim` device's virtual hand starts moving the jig there.
fn prompt_pose(
    source: &mut dyn Source,
    opts: &RecordOptions,
    ui: &mut dyn Ui,
    k: usize,
    pose: &CubePose,
) {
    ui.message(&pose_prompt(k, pose));
    if let Some(bench) = source.bench() {
        bench
            .borrow_mut()
            .hand_mut()
            .move_to(source.now_s(), pose.quat, opts.transition_s);
    }
}

fn progress<'a>(
    t_s: f64,
    out: &Out,
    map: &'a CoverageMap,
    magnitude: &MagnitudeWatch,
    opts: &RecordOptions,
    taken: Option<usize>,
    throttle: Option<Throttle>,
) -> Progress<'a> {
    Progress {
        throttle,
        t_s,
        samples: out.rows(),
        coverage: map,
        target: (opts.routine == Routine::Free).then_some(opts.target_coverage),
        poses: taken.map(|t| (t, 24)),
        quality: Quality::of(map.directions()),
        disturbance: magnitude.disturbance(),
    }
}

/// What the rest's field magnitude says about the readings' unit, when it is far from the Earth's field in µT.
fn units_note(usual_ut: f64) -> Option<String> {
    let (low, high) = EARTH_FIELD_UT;
    if (0.5 * low..=1.5 * high).contains(&usual_ut) {
        return None;
    }
    Some(format!(
        "the field's magnitude is {usual_ut:.3} in the readings' units, where the Earth's is {low:.0}–{high:.0} µT: \
         the readings are not µT (raw counts, gauss, nT?). A serial board's unit is set in the device string \
         (:unit=gauss|mG|nT or :scale=K); the fit will warn and can still calibrate"
    ))
}

/// `YYYY-MM-DDTHH:MM:SSZ` for a system time (UTC).
pub fn utc_rfc3339(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Days since 1970-01-01 to a civil date (the proleptic Gregorian calendar), by eras of 400 years.
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 34: without --routine, a real device gets the free routine (no jig needed), the simulated bench (which
    /// has its jig) the cube's poses; the free routine says what the cube's would add.
    #[test]
    fn the_default_routine_needs_no_jig_on_a_real_device() {
        for (device, routine) in [
            ("sim", Routine::Cube24),
            ("sim:qmc5883l", Routine::Cube24),
            ("i2c:/dev/i2c-1:lis3mdl", Routine::Free),
            ("serial:/dev/ttyACM0", Routine::Free),
        ] {
            let spec: DeviceSpec = device.parse().unwrap();
            assert_eq!(Routine::default_for(&spec), routine, "{device}");
        }
        let adds = Routine::Free.what_the_other_adds().unwrap();
        assert!(
            adds.contains("--routine cube24") && adds.contains("misalignment"),
            "{adds}"
        );
        assert_eq!(Routine::Cube24.what_the_other_adds(), None);
    }

    #[test]
    fn timestamps_are_utc_civil_dates() {
        let at = |s: u64| utc_rfc3339(UNIX_EPOCH + Duration::from_secs(s));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(at(1_763_700_000), "2025-11-21T04:40:00Z");
    }

    #[test]
    fn the_segments_note_fits_its_room() {
        assert_eq!(segments_note(&[]), "1");
        assert_eq!(
            segments_note(&[12.5]),
            "2 (the device's clock restarted at t = 12.500 s; each new segment continues from the host's clock)"
        );
        let many: Vec<f64> = (0..50).map(|i| 10.0 * f64::from(i)).collect();
        let note = segments_note(&many);
        assert!(
            note.len() <= SEGMENTS_WIDTH && note.starts_with("51 (") && note.contains("more s;"),
            "{note}"
        );
    }

    #[test]
    fn options_out_of_range_are_refused_before_anything_is_opened() {
        let ok = RecordOptions::new(Routine::Cube24, "x.csv".into());
        assert!(ok.check().is_ok());
        for (edit, says) in [
            (
                (|o: &mut RecordOptions| o.dwell_s = 1e30) as fn(&mut RecordOptions),
                "--dwell 1e30 s",
            ),
            (
                |o| o.dwell_s = 1e7,
                "--dwell 10000000 s: must be a number from 0.1 to 60 s",
            ),
            (
                |o| o.dwell_s = 1e-30,
                "--dwell 1e-30 s: must be a number from 0.1 to 60 s",
            ),
            (|o| o.dwell_s = f64::NAN, "--dwell NaN"),
            (|o| o.max_duration_s = -1.0, "--max-duration -1"),
            (
                |o| o.max_duration_s = 1e-9,
                "--max-duration 0.000000001 s: must be at least 1 s",
            ),
            (|o| o.still_ut = 0.0, "--still-ut 0"),
            (|o| o.target_coverage = 1.5, "--coverage 1.5"),
        ] {
            let mut o = ok.clone();
            edit(&mut o);
            let e = o.check().unwrap_err().to_string();
            assert!(e.starts_with(says), "{e}");
        }
    }

    #[test]
    fn a_refusal_names_the_option_of_the_tool() {
        let path = PathBuf::from("out/recording.csv");
        let exists = RecordError::Exists {
            path: path.clone(),
            option: OUT_OPTION,
        };
        assert_eq!(
            exists.to_string(),
            "out/recording.csv exists: a recording is never replaced; choose another --out, or add --force to \
             replace it (nothing was recorded)"
        );
        let exists = exists.for_option("--out-dir").to_string();
        assert!(
            exists.contains("choose another --out-dir, or add --force")
                && !exists.contains("--out,"),
            "{exists}"
        );
        let busy = RecordError::Busy {
            path,
            option: OUT_OPTION,
        };
        let busy = busy.for_option("--out-dir").to_string();
        assert!(busy.contains("choose another --out-dir (nothing"), "{busy}");
    }

    /// A motors recording stopped before its two ramps says so, and what to do.
    #[test]
    fn a_motor_test_stopped_short_says_how_many_ramps_it_made() {
        let opts = RecordOptions::new(Routine::Motors, "m.csv".into());
        let mut summary = RecordSummary {
            path: "m.csv".into(),
            samples: 500,
            duration_s: 10.0,
            coverage: 0.0,
            poses: 0,
            ramps: 1,
            blips: 0,
            saturated: 0,
            disturbed: 0,
            clock_restarts: Vec::new(),
            link_loss: None,
            garbage: None,
            untouched: false,
            stop: Stop::MaxDuration,
        };
        let short = summary.shortfall(&opts).unwrap();
        assert!(
            short.contains("1 of the 2 throttle ramps made")
                && short.contains("to full and back, twice"),
            "{short}"
        );
        summary.ramps = 2;
        summary.blips = 3;
        let short = summary.shortfall(&opts).unwrap();
        assert!(
            short.contains("the ramps made, 3 of the 10 throttle blips")
                && short.contains("the lag of the field behind the current may not be determined"),
            "{short}"
        );
        summary.stop = Stop::Ramps;
        assert_eq!(summary.shortfall(&opts), None);
        assert_eq!(Routine::Motors.name(), "motors");
        assert_eq!(Routine::Motors.what_the_other_adds(), None);
    }

    #[test]
    fn prompts_name_the_face_and_the_heading() {
        let poses = cube24_poses();
        let p = pose_prompt(0, &poses[0]);
        assert!(p.starts_with("pose 1/24: −Z face down, +X edge"), "{p}");
        assert!(p.contains("north"));
        assert!(pose_prompt(9, &poses[9]).contains("+Z edge"));
    }
}
