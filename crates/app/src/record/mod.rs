//! The recorder behind `magcal-record`: a [`Source`] of samples, a routine that tells the operator (or the virtual
//! hand of a `sim` device) what to do, and an incremental, crash-safe [`RecordingWriter`].
//!
//! - **free**: the sensor is turned freely; every sample is written; the recording stops when the live
//!   [`CoverageMap`] reaches the target coverage of the sphere of field directions, after the longest duration, or
//!   on an interrupt (Ctrl-C).
//! - **cube24**: the 24 static poses of a cube jig against a reference edge ([`magcal_sim::cube24_poses`]). Each
//!   prompt names the face down and where the reference edge points. Once the sensor has left the last pose and has
//!   stayed still for a dwell (every axis' spread below a threshold), it has settled; the next dwell is recorded if
//!   it stays still too (Enter records the next dwell whatever it holds). The dwell's samples are written with the
//!   pose's attitude quaternion, which gives the vector calibration its reference; the settling dwell keeps the end
//!   of the move out of them.
//!
//! The file is created (metadata and header flushed) before the first sample, so an unwritable path fails before
//! anything is recorded; rows reach the file at least every half second, so a killed recorder leaves a file that
//! parses and holds all but the last moments. A device that fails (a bus that stays down after retries, a serial
//! line that disconnects, outputs that stop changing) ends the recording with an error naming the device and how
//! many samples the file keeps.

pub mod clock;
pub mod coverage;
pub mod sim;
pub mod source;
pub mod still;
pub mod ui;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use magcal_driver::serial::GarbageCounts;
use magcal_recording::{Layout, Metadata, RecordingWriter, Sample};
use magcal_sim::{CubePose, cube24_poses};

use crate::device::DeviceSpec;

pub use coverage::CoverageMap;
pub use source::{Reading, Source, SourceError};
pub use still::StillWindow;
pub use ui::{Progress, Ui};

/// What the operator does during the recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Routine {
    /// Free rotation until the coverage target (a scalar calibration).
    Free,
    /// The 24 poses of a cube jig against a reference edge (a vector calibration).
    Cube24,
}

impl Routine {
    /// The name used on the command line and in the recording's `routine` metadata.
    pub fn name(self) -> &'static str {
        match self {
            Routine::Free => "free",
            Routine::Cube24 => "cube24",
        }
    }
}

/// How to record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordOptions {
    /// The routine.
    pub routine: Routine,
    /// The recording to write (created or truncated).
    pub out: PathBuf,
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
    /// Defaults: 90 % coverage, at most 10 minutes, 1 s dwell, still below 0.5 µT, 1.5 s moves, attended.
    pub fn new(routine: Routine, out: PathBuf) -> RecordOptions {
        RecordOptions {
            routine,
            out,
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

/// Why a recording ended without an error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The free routine reached its coverage target.
    Coverage,
    /// The cube routine took all its poses.
    AllPoses,
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
    /// Fraction of the sphere of directions seen.
    pub coverage: f64,
    /// Cube poses taken.
    pub poses: usize,
    /// Samples the chip refused as saturated.
    pub saturated: u64,
    /// Garbage lines skipped (line streams).
    pub garbage: Option<GarbageCounts>,
    /// Why it stopped.
    pub stop: Stop,
}

/// Why a recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created: nothing was recorded.
    #[error("cannot create the recording {}: {source}; nothing was recorded", path.display())]
    Create {
        /// The path.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// Writing a row failed.
    #[error("writing {} failed after {kept} samples: {source}", path.display())]
    Write {
        /// The path.
        path: PathBuf,
        /// Rows accepted before.
        kept: u64,
        /// What the system said.
        source: std::io::Error,
    },
    /// The device failed; the file keeps what was recorded.
    #[error(
        "{error}; {} keeps the {kept} samples recorded before{}",
        path.display(),
        garbage.as_deref().map(|g| format!("; garbage lines skipped: {} ({g})", g.total())).unwrap_or_default()
    )]
    Device {
        /// What the device did.
        error: SourceError,
        /// The path.
        path: PathBuf,
        /// Rows in the file.
        kept: u64,
        /// Garbage lines skipped (line streams).
        garbage: Option<Box<GarbageCounts>>,
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

/// Identical consecutive readings that mean the outputs are stuck: this many, or two seconds' worth if more.
const STUCK_REPEATS: u64 = 100;
/// A pose counts as left when the field's mean moved this far from where the last pose was taken, µT.
const MOVED_UT: f64 = 5.0;

/// Where the cube routine is with the current pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PoseState {
    /// The last pose was taken: waiting for the jig to leave it.
    AwaitMove,
    /// Waiting for a dwell of stillness (the jig settles in the new pose).
    AwaitStill,
    /// Settled: the next dwell is recorded, if it stays still (or Enter was pressed).
    Hold,
}

/// Watches for readings that repeat exactly.
struct StuckWatch {
    last: Option<[f64; 3]>,
    repeats: u64,
    from: u64,
    limit: u64,
}

impl StuckWatch {
    /// Whether the outputs look stuck after `r`, the `n`-th reading.
    fn stuck(&mut self, r: [f64; 3], n: u64) -> bool {
        if self.last == Some(r) {
            self.repeats += 1;
        } else {
            self.last = Some(r);
            self.repeats = 1;
            self.from = n;
        }
        self.repeats >= self.limit
    }
}

/// The writer with its bookkeeping.
struct Out {
    writer: RecordingWriter,
    layout: Layout,
    t0_s: f64,
}

impl Out {
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
            ..Sample::default()
        };
        self.writer
            .write_sample(&sample)
            .map_err(|source| RecordError::Write {
                path: self.writer.path().to_owned(),
                kept: self.writer.rows(),
                source,
            })
    }

    fn rows(&self) -> u64 {
        self.writer.rows()
    }

    fn path(&self) -> &Path {
        self.writer.path()
    }

    fn finish(self) -> Result<(), RecordError> {
        let path = self.writer.path().to_owned();
        let kept = self.writer.rows();
        self.writer
            .finish()
            .map_err(|source| RecordError::Write { path, kept, source })
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
    let cube = opts.routine == Routine::Cube24;
    let layout = Layout {
        t: true,
        temp: source.has_temperature(),
        quat: cube,
        ..Layout::default()
    };
    let mut meta = opts.meta.clone();
    meta.sensor.get_or_insert_with(|| source.sensor());
    meta.sample_rate_hz = source.rate_hz();
    meta.routine = Some(opts.routine.name().to_owned());
    meta.started = Some(utc_rfc3339(SystemTime::now()));
    let writer = RecordingWriter::create(&opts.out, &meta, &layout).map_err(|source| {
        RecordError::Create {
            path: opts.out.clone(),
            source,
        }
    })?;
    let mut out = Out {
        writer,
        layout,
        t0_s: source.now_s(),
    };
    let result = run(source, opts, ui, interrupt, &mut out);
    ui.finish();
    let kept = out.rows();
    let finished = out.finish();
    match (result, finished) {
        (Ok(mut summary), Ok(())) => {
            summary.samples = kept;
            Ok(summary)
        }
        (Err(e), _) | (Ok(_), Err(e)) => Err(e),
    }
}

/// The routine itself; `out` is finished by the caller whatever happens.
fn run(
    source: &mut dyn Source,
    opts: &RecordOptions,
    ui: &mut dyn Ui,
    interrupt: &AtomicBool,
    out: &mut Out,
) -> Result<RecordSummary, RecordError> {
    let cube = opts.routine == Routine::Cube24;
    let device = source.device().to_owned();
    let rate_hz = source.rate_hz().unwrap_or(100.0);
    let mut stuck = StuckWatch {
        last: None,
        repeats: 0,
        from: 0,
        limit: STUCK_REPEATS.max((2.0 * rate_hz) as u64),
    };
    let mut map = CoverageMap::new();
    let poses = cube24_poses();
    let mut window = StillWindow::new((opts.dwell_s * rate_hz).round() as usize);
    let mut taken = 0usize;
    let mut state = PoseState::AwaitStill;
    let mut last_pose_mean: Option<[f64; 3]> = None;
    let mut manual_take = false;
    let mut saturated_told = 0;
    let t0_s = out.t0_s;
    let device_failed = |error: SourceError, out: &Out, source: &dyn Source| RecordError::Device {
        error,
        path: out.path().to_owned(),
        kept: out.rows(),
        garbage: source.garbage().map(Box::new),
    };

    match opts.routine {
        Routine::Free => {
            ui.message(&format!(
                "free rotation: turn the sensor through every orientation until {:.0} % of the sphere is covered \
                 (Ctrl-C stops early; the file keeps everything)",
                100.0 * opts.target_coverage
            ));
            if let Some(bench) = source.bench() {
                ui.message("sim: the virtual hand tumbles the sensor");
                bench.borrow_mut().hand_mut().tumble(source.now_s(), 1.0);
            }
        }
        Routine::Cube24 => prompt_pose(source, opts, ui, 0, &poses[0]),
    }

    let stop = loop {
        if interrupt.load(Ordering::Relaxed) {
            break Stop::Interrupted;
        }
        let r = match source.next_reading() {
            Ok(r) => r,
            Err(e) => return Err(device_failed(e, out, source)),
        };
        let t_s = r.t_s - t0_s;
        if t_s > opts.max_duration_s {
            break Stop::MaxDuration;
        }
        if source.saturated() > saturated_told {
            ui.message(&format!(
                "{device}: {} samples saturated so far (field out of the chip's range: a magnet nearby?); they \
                 are not recorded",
                source.saturated()
            ));
            saturated_told = source.saturated();
        }
        let n = map.len() as u64;
        if stuck.stuck(r.mag_ut, n) {
            return Err(RecordError::Stuck {
                device,
                value: r.mag_ut,
                repeats: stuck.repeats,
                from: stuck.from,
                path: out.path().to_owned(),
                kept: out.rows(),
            });
        }
        map.add(r.mag_ut);
        match opts.routine {
            Routine::Free => {
                out.write(&r, None)?;
                if map.fraction() >= opts.target_coverage {
                    ui.progress(&progress(t_s, out, &map, opts, None));
                    break Stop::Coverage;
                }
            }
            Routine::Cube24 => {
                if !manual_take && ui.enter_pressed() {
                    manual_take = true;
                    state = PoseState::Hold;
                    window.clear();
                }
                window.push(r);
                let full = window.is_full();
                let still = window.is_still(opts.still_ut);
                match state {
                    PoseState::AwaitMove if full => {
                        let mean = window.mean_ut();
                        let away = last_pose_mean.is_none_or(|m| {
                            (0..3).map(|k| (mean[k] - m[k]).powi(2)).sum::<f64>().sqrt() > MOVED_UT
                        });
                        if away || !still {
                            state = PoseState::AwaitStill;
                        }
                    }
                    PoseState::AwaitStill if still => {
                        // Still for a dwell: the jig has settled. Record the next dwell.
                        state = PoseState::Hold;
                        window.clear();
                    }
                    PoseState::Hold if full && !(still || manual_take) => {
                        state = PoseState::AwaitStill
                    }
                    _ => {}
                }
                if state == PoseState::Hold
                    && window.is_full()
                    && (manual_take || window.is_still(opts.still_ut))
                {
                    let pose = &poses[taken];
                    let mean = window.mean_ut();
                    let held = window.take();
                    for w in &held {
                        out.write(w, Some(pose.quat))?;
                    }
                    ui.message(&format!(
                        "  taken: {} samples, mean [{:.2}, {:.2}, {:.2}] µT{}",
                        held.len(),
                        mean[0],
                        mean[1],
                        mean[2],
                        if manual_take { " (Enter)" } else { "" }
                    ));
                    taken += 1;
                    last_pose_mean = Some(mean);
                    state = PoseState::AwaitMove;
                    manual_take = false;
                    if taken == poses.len() {
                        ui.progress(&progress(t_s, out, &map, opts, Some(taken)));
                        break Stop::AllPoses;
                    }
                    prompt_pose(source, opts, ui, taken, &poses[taken]);
                }
            }
        }
        ui.progress(&progress(t_s, out, &map, opts, cube.then_some(taken)));
    };
    Ok(RecordSummary {
        path: out.path().to_owned(),
        samples: out.rows(),
        duration_s: source.now_s() - t0_s,
        coverage: map.fraction(),
        poses: taken,
        saturated: source.saturated(),
        garbage: source.garbage(),
        stop,
    })
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
    opts: &RecordOptions,
    taken: Option<usize>,
) -> Progress<'a> {
    Progress {
        t_s,
        samples: out.rows(),
        coverage: map,
        target: opts.target_coverage,
        poses: taken.map(|t| (t, 24)),
    }
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
    use std::time::Duration;

    #[test]
    fn timestamps_are_utc_civil_dates() {
        let at = |s: u64| utc_rfc3339(UNIX_EPOCH + Duration::from_secs(s));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(at(1_763_700_000), "2025-11-21T04:40:00Z");
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
