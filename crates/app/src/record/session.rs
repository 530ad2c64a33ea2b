//! The recording loop: readings taken one by one, watched (a restarting clock, stuck outputs, the field's magnitude,
//! the readings' unit, saturation) and handed to the routine, until it is done, Ctrl-C, the longest duration, or the
//! device fails. A source that gives no reading for a while (a saturated chip, a silent line) hands back control
//! every few tens of milliseconds at most, so Ctrl-C and `--max-duration` are heeded and the rows taken reach the
//! file whatever the device does.

use std::sync::atomic::{AtomicBool, Ordering};

use super::{
    CoverageMap, Cube, MagnitudeEvent, MagnitudeWatch, Out, Reading, RecordError, RecordOptions,
    RecordSummary, Routine, Skipped, Source, SourceError, Stop, ThrottleWatch, Ui, cube_step,
    motors, progress, prompt_pose, units_note,
};

/// Identical consecutive readings that mean the outputs are stuck: this many, or two seconds' worth if more.
const STUCK_REPEATS: u64 = 100;
/// While a chip stays saturated, how often it is said again, s of device time.
const SATURATION_REMINDER_S: f64 = 2.0;

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

/// A recording in progress: what the loop keeps between readings.
struct Session<'o> {
    opts: &'o RecordOptions,
    device: String,
    t0_s: f64,
    stuck: StuckWatch,
    map: CoverageMap,
    magnitude: MagnitudeWatch,
    units_told: bool,
    jig: Cube,
    throttle: ThrottleWatch,
    /// Whether the motors routine said the ramps were made and the blips are next.
    blips_told: bool,
    seen: u64,
    /// Rows written while the magnitude departed (between cube poses, readings are looked at and not written).
    disturbed: u64,
    /// Saturated samples said so far, when last said (device time, s), and whether no reading came since.
    saturated_told: (u64, f64, bool),
    restarts_told: usize,
}

/// Records from `source` into `out` as `opts` say; `out` is finished by the caller whatever happens.
pub(super) fn run(
    source: &mut dyn Source,
    opts: &RecordOptions,
    ui: &mut dyn Ui,
    interrupt: &AtomicBool,
    out: &mut Out,
) -> Result<RecordSummary, RecordError> {
    let mut s = Session::new(source, opts, out.t0_s);
    s.start(source, ui);
    let stop = loop {
        if interrupt.load(Ordering::Relaxed) {
            break Stop::Interrupted;
        }
        let reading = source
            .next_reading()
            .map_err(|e| s.device_failed(e, out, source))?;
        s.tell_saturation(source, ui, reading.is_some());
        let Some(r) = reading else {
            // No reading for a moment: the rows taken reach the file, and the clock is looked at.
            out.flush_if_due()?;
            if source.now_s() - s.t0_s > opts.max_duration_s {
                break Stop::MaxDuration;
            }
            continue;
        };
        if let Some(stop) = s.take(&r, source, ui, out)? {
            break stop;
        }
    };
    s.map.finish();
    let link_loss = source.link_loss();
    if let Some(loss) = &link_loss {
        out.note_link(loss)?;
    }
    Ok(RecordSummary {
        path: out.path().to_owned(),
        samples: out.rows(),
        duration_s: source.now_s() - s.t0_s,
        coverage: s.map.fraction(),
        poses: s.jig.taken,
        ramps: s.throttle.throttle().map_or(0, |t| t.ramps),
        blips: s.throttle.throttle().map_or(0, |t| t.blips),
        saturated: source.saturated(),
        disturbed: s.disturbed,
        clock_restarts: source.clock_restarts().iter().map(|t| t - s.t0_s).collect(),
        link_loss,
        garbage: Skipped::of(source),
        untouched: false,
        stop,
    })
}

/// How to blip the throttle, in words.
fn blip_how() -> String {
    format!(
        "snap it from idle to high (at least {:.0} % of the highest current, within {:.1} s) and back after about \
         half a second, resting a second at idle between blips (the quick steps time the field's lag behind the \
         current)",
        100.0 * motors::RAMP_SHARE,
        motors::BLIP_RISE_S
    )
}

impl<'o> Session<'o> {
    fn new(source: &dyn Source, opts: &'o RecordOptions, t0_s: f64) -> Session<'o> {
        let rate_hz = source.rate_hz().unwrap_or(100.0);
        Session {
            opts,
            device: source.device().to_owned(),
            t0_s,
            stuck: StuckWatch {
                last: None,
                repeats: 0,
                from: 0,
                limit: STUCK_REPEATS.max((2.0 * rate_hz) as u64),
            },
            map: CoverageMap::new(),
            magnitude: MagnitudeWatch::new(),
            units_told: false,
            jig: Cube::new((opts.dwell_s * rate_hz).round() as usize),
            throttle: ThrottleWatch::new(),
            blips_told: false,
            seen: 0,
            disturbed: 0,
            saturated_told: (0, f64::NEG_INFINITY, false),
            restarts_told: 0,
        }
    }

    /// Tells the operator what to do first; a `sim` device's virtual hand starts doing it.
    fn start(&mut self, source: &mut dyn Source, ui: &mut dyn Ui) {
        match self.opts.routine {
            Routine::Free => {
                ui.message(&format!(
                    "free rotation: turn the sensor in one spot, about its own centre and away from metal, through \
                     every orientation until {:.0} % of the sphere is covered (Ctrl-C stops early; the file keeps \
                     everything)",
                    100.0 * self.opts.target_coverage
                ));
                if let Some(bench) = source.bench() {
                    ui.message("sim: the virtual hand tumbles the sensor");
                    bench.borrow_mut().hand_mut().tumble(source.now_s(), 1.0);
                }
            }
            Routine::Cube24 => prompt_pose(source, self.opts, ui, 0, &self.jig.poses[0]),
            Routine::Motors => ui.message(&format!(
                "motor test: hold the vehicle still (props off or held down); raise the throttle slowly to full and \
                 back, {}; then blip it {} times: {} (magcal only reads: it never arms the vehicle or commands its \
                 motors; Ctrl-C stops early, the file keeps everything)",
                match motors::RAMPS {
                    2 => "twice".to_owned(),
                    n => format!("{n} times"),
                },
                motors::BLIPS,
                blip_how()
            )),
        }
    }

    fn device_failed(&self, error: SourceError, out: &Out, source: &dyn Source) -> RecordError {
        RecordError::Device {
            error,
            path: out.path().to_owned(),
            kept: out.rows(),
            garbage: Skipped::of(source).map(Box::new),
            untouched: false,
        }
    }

    /// Says when samples saturate: at the first of a run of them, then every [`SATURATION_REMINDER_S`] while they
    /// go on.
    fn tell_saturation(&mut self, source: &dyn Source, ui: &mut dyn Ui, got_reading: bool) {
        let (told, told_at_s, in_run) = self.saturated_told;
        let n = source.saturated();
        let now_s = source.now_s();
        if n > told && (!in_run || now_s - told_at_s >= SATURATION_REMINDER_S) {
            ui.message(&format!(
                "{}: {n} samples saturated so far (field out of the chip's range: a magnet nearby? move it away); \
                 they are not recorded",
                self.device
            ));
            self.saturated_told = (n, now_s, true);
        }
        if got_reading {
            self.saturated_told.2 = false;
        }
    }

    /// Takes one reading: watches it, hands it to the routine, flushes and shows progress. Returns why the
    /// recording stops, if it does.
    fn take(
        &mut self,
        r: &Reading,
        source: &mut dyn Source,
        ui: &mut dyn Ui,
        out: &mut Out,
    ) -> Result<Option<Stop>, RecordError> {
        let t_s = r.t_s - self.t0_s;
        if t_s > self.opts.max_duration_s {
            return Ok(Some(Stop::MaxDuration));
        }
        self.watch(r, t_s, source, ui, out)?;
        let cube = self.opts.routine == Routine::Cube24;
        let rows = out.rows();
        let done = match self.opts.routine {
            Routine::Motors => {
                out.write(r, r.quat)?;
                self.throttle.add(t_s, r.mag_ut, r.current_a);
                if !self.blips_told
                    && self
                        .throttle
                        .throttle()
                        .is_some_and(|t| t.ramps >= motors::RAMPS)
                {
                    self.blips_told = true;
                    ui.message(&format!(
                        "ramps made; now blip the throttle {} times: {}",
                        motors::BLIPS,
                        blip_how()
                    ));
                }
                self.throttle.done()
            }
            Routine::Free => {
                out.write(r, r.quat)?;
                self.map.add(r.mag_ut);
                // The live figure counts around a sphere up to 2 µT old: the stop is decided on the final one.
                self.map.fraction() >= self.opts.target_coverage && {
                    self.map.finish();
                    self.map.fraction() >= self.opts.target_coverage
                }
            }
            Routine::Cube24 => {
                cube_step(&mut self.jig, r, source, self.opts, ui, out, &mut self.map)?
            }
        };
        if out.rows() > rows {
            self.disturbed += u64::from(self.magnitude.last_departed());
        }
        let taken = cube.then_some(self.jig.taken);
        let throttle = self.throttle.throttle();
        if done {
            ui.progress(&progress(
                t_s,
                out,
                &self.map,
                &self.magnitude,
                self.opts,
                taken,
                throttle,
            ));
            return Ok(Some(match self.opts.routine {
                Routine::Free => Stop::Coverage,
                Routine::Cube24 => Stop::AllPoses,
                Routine::Motors => Stop::Ramps,
            }));
        }
        // Rows taken a while ago reach the file even when no row follows them (between two cube poses).
        out.flush_if_due()?;
        ui.progress(&progress(
            t_s,
            out,
            &self.map,
            &self.magnitude,
            self.opts,
            taken,
            throttle,
        ));
        Ok(None)
    }

    /// Watches a reading at recording time `t_s`: a restart of the device's clock (noted in the file), outputs
    /// stuck (an error), the field's magnitude departing or returning, the readings' unit.
    fn watch(
        &mut self,
        r: &Reading,
        t_s: f64,
        source: &dyn Source,
        ui: &mut dyn Ui,
        out: &mut Out,
    ) -> Result<(), RecordError> {
        let restarts = source.clock_restarts();
        if restarts.len() > self.restarts_told {
            ui.message(&format!(
                "{}: the device's clock restarted (a reset?) at t = {:.3} s: time goes on from the host's clock, \
                 as segment {} (noted in the file's metadata)",
                self.device,
                restarts[restarts.len() - 1] - self.t0_s,
                restarts.len() + 1
            ));
            self.restarts_told = restarts.len();
            out.note_segments(restarts)?;
        }
        self.seen += 1;
        if self.stuck.stuck(r.mag_ut, self.seen - 1) {
            return Err(RecordError::Stuck {
                device: self.device.clone(),
                value: r.mag_ut,
                repeats: self.stuck.repeats,
                from: self.stuck.from,
                path: out.path().to_owned(),
                kept: out.rows(),
            });
        }
        // The motor test's field changes with the current by design: no magnet is looked for.
        if self.opts.routine == Routine::Motors {
            return Ok(());
        }
        match self.magnitude.add(t_s, r.mag_ut) {
            Some(MagnitudeEvent::Departed {
                t_s,
                magnitude_ut,
                usual_ut,
            }) => ui.message(&format!(
                "t = {t_s:.1} s: the field magnitude is {magnitude_ut:.1} µT, not the {usual_ut:.1} µT of the rest (the \
                 sensor's offset and gains as fitted so far taken out): a magnet or iron near the sensor? Move it \
                 away; these samples are recorded but do not count as coverage"
            )),
            Some(MagnitudeEvent::Returned { t_s, lasted_s }) => ui.message(&format!(
                "t = {t_s:.1} s: the field magnitude is back to the rest's (disturbed for {lasted_s:.1} s)"
            )),
            None => {}
        }
        if !self.units_told
            && let Some(usual_ut) = self.magnitude.usual_ut()
        {
            self.units_told = true;
            if let Some(note) = units_note(usual_ut) {
                ui.message(&note);
            }
        }
        Ok(())
    }
}
