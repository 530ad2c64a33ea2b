//! What the operator sees: prompts, and the live display — the coverage map with its legend, MotionCal-style quality
//! figures, a warning while the field's magnitude departs from the rest, and a progress bar; for the motors routine
//! the current and the field's change since the start instead of the map — redrawn in place on a
//! terminal (with echo off, so Enter and Ctrl-C leave no stale lines); plain progress lines otherwise. And the Enter
//! key.

use std::io::{BufRead, IsTerminal};
use std::sync::mpsc::{self, Receiver};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::Routine;
use super::coverage::CoverageMap;
use super::magnitude::Disturbance;
use super::motors::{BLIP_RISE_S, BLIPS, RAMP_SHARE, RAMPS, Throttle};
use super::quality::{MOTIONCAL_LIMITS, Quality};
use crate::tty::EchoOff;

/// What the recorder reports while it runs.
#[derive(Clone, Copy, Debug)]
pub struct Progress<'a> {
    /// Recording time, s.
    pub t_s: f64,
    /// Samples written.
    pub samples: u64,
    /// Directions the recorded samples cover.
    pub coverage: &'a CoverageMap,
    /// The free routine's coverage target, 0–1; none for the cube routine, whose poses are a few directions by
    /// design.
    pub target: Option<f64>,
    /// For the cube routine: poses taken, and of how many.
    pub poses: Option<(usize, usize)>,
    /// MotionCal-style figures of the recorded samples, once they determine a sphere.
    pub quality: Option<Quality>,
    /// The field's magnitude departing from the rest now (a magnet near), if it does.
    pub disturbance: Option<Disturbance>,
    /// For the motors routine: the throttle, once a current came.
    pub throttle: Option<Throttle>,
}

/// The motors routine's live lines: the current with its range, the ramps and the blips, the field's change since
/// the start.
fn throttle_lines(t: Option<&Throttle>) -> String {
    let Some(t) = t else {
        return "current —: none came yet\nfield change since the start —".to_owned();
    };
    let c = t.change_ut;
    format!(
        "current {:.1} A (lowest {:.1} A, highest {:.1} A); ramps {}/{RAMPS} up to {:.0} % of the highest and back\n\
         then blips {}/{BLIPS}: up to it within {BLIP_RISE_S:.1} s and back\n\
         field change since the start {:+.2}, {:+.2}, {:+.2} µT ({:.2} µT)",
        t.current_a,
        t.range_a.0,
        t.range_a.1,
        t.ramps,
        100.0 * RAMP_SHARE,
        t.blips,
        c[0],
        c[1],
        c[2],
        (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
    )
}

/// The live display's style from its template.
fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template)
        .expect("the template is valid")
        .progress_chars("=> ")
}

/// The motors routine's bar, counting `what` (" ramps", " blips").
fn motors_style(what: &str) -> ProgressStyle {
    style(&format!(
        "{{msg}}\n[{{bar:40}}] {{pos}}/{{len}}{what}  {{prefix}}"
    ))
}

/// The coverage map's legend.
fn legend(cube: bool) -> &'static str {
    if cube {
        "# the field's direction in a pose taken   . none yet   (seen from outside)"
    } else {
        "# a direction of the field seen   . not yet   (seen from outside)"
    }
}

/// The quality figures, two lines: all four for free rotation, variance and fit error for the cube's poses (whose
/// few directions are by design).
fn quality_lines(quality: Option<Quality>, cube: bool) -> String {
    let l = MOTIONCAL_LIMITS;
    let Some(q) = quality else {
        // Figures that do not mean anything yet are shown as such, not as thousands of per cent.
        let when = "— until samples lie on one sphere";
        return if cube {
            format!(
                "quality: variance —, fit error —\n  (MotionCal asks below {} and {} %: {when})",
                l.variance_pct, l.fit_error_pct
            )
        } else {
            format!(
                "quality: gaps —, variance —, wobble —, fit error —\n  (MotionCal asks below {}, {}, {} and {} %: \
                 {when})",
                l.gaps_pct, l.variance_pct, l.wobble_pct, l.fit_error_pct
            )
        };
    };
    let within = if q.within_motioncal_limits(!cube) {
        "all within"
    } else {
        "not yet"
    };
    if cube {
        format!(
            "quality: variance {:.1} %, fit error {:.1} %\n  (MotionCal asks below {} and {} %: {within})",
            q.variance_pct, q.fit_error_pct, l.variance_pct, l.fit_error_pct
        )
    } else {
        format!(
            "quality: gaps {:.1} %, variance {:.1} %, wobble {:.1} %, fit error {:.1} %\n  (MotionCal asks below {}, \
             {}, {} and {} %: {within})",
            q.gaps_pct,
            q.variance_pct,
            q.wobble_pct,
            q.fit_error_pct,
            l.gaps_pct,
            l.variance_pct,
            l.wobble_pct,
            l.fit_error_pct
        )
    }
}

/// The warning shown while the field's magnitude departs from the rest, two lines.
fn disturbance_lines(d: &Disturbance) -> String {
    format!(
        "! the field is {:.1} µT, not the {:.1} µT of the rest, since t = {:.1} s\n  a magnet or iron near the \
         sensor? Move it away (not counted as coverage)",
        d.magnitude_ut, d.usual_ut, d.since_s
    )
}

/// The operator's side of a recording.
pub trait Ui {
    /// A prompt or a note, shown as a line.
    fn message(&mut self, text: &str);
    /// Progress; called after every sample (an implementation decides how often to show it).
    fn progress(&mut self, p: &Progress<'_>);
    /// Whether Enter was pressed since the last call.
    fn enter_pressed(&mut self) -> bool;
    /// The recording is over: leave the live display's last state, and the terminal as it was.
    fn finish(&mut self);
}

/// Lines from standard input, read in a background thread: each one is an Enter.
#[derive(Debug)]
pub struct EnterKey {
    lines: Receiver<()>,
}

impl EnterKey {
    /// Starts listening to standard input.
    pub fn listen() -> EnterKey {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines() {
                if line.is_err() || tx.send(()).is_err() {
                    break;
                }
            }
        });
        EnterKey { lines: rx }
    }

    /// Whether a line came since the last call.
    pub fn pressed(&self) -> bool {
        let mut any = false;
        while self.lines.try_recv().is_ok() {
            any = true;
        }
        any
    }
}

/// A terminal: the live display redrawn in place (indicatif) on standard output, with echo off.
pub struct TerminalUi {
    bar: ProgressBar,
    enter: Option<EnterKey>,
    routine: Routine,
    echo_off: Option<EchoOff>,
}

impl TerminalUi {
    /// A live display on standard output, with echo off; `enter` listens for the Enter key (none when unattended).
    /// The bar counts the `routine`'s progress: coverage, poses or throttle ramps.
    pub fn new(enter: Option<EnterKey>, routine: Routine) -> TerminalUi {
        let mut ui = TerminalUi::on(ProgressDrawTarget::stdout(), enter, routine);
        ui.echo_off = EchoOff::new();
        ui
    }

    /// A live display drawn to `target`.
    fn on(target: ProgressDrawTarget, enter: Option<EnterKey>, routine: Routine) -> TerminalUi {
        let (len, bar_style) = match routine {
            Routine::Cube24 => (24, style("{msg}\n[{bar:40}] {pos}/{len} poses  {prefix}")),
            Routine::Free => (
                100,
                style("{msg}\n[{bar:40}] {pos:>3}% of the sphere  {prefix}"),
            ),
            Routine::Motors => (RAMPS as u64, motors_style(" ramps")),
        };
        let bar = ProgressBar::with_draw_target(Some(len), target);
        bar.set_style(bar_style);
        TerminalUi {
            bar,
            enter,
            routine,
            echo_off: None,
        }
    }
}

impl Ui for TerminalUi {
    fn message(&mut self, text: &str) {
        self.bar.println(text);
    }

    fn progress(&mut self, p: &Progress<'_>) {
        match (p.poses, self.routine) {
            (Some((taken, _)), _) => self.bar.set_position(taken as u64),
            (None, Routine::Motors) => match p.throttle {
                // The ramps made, the bar counts the blips.
                Some(t) if t.ramps >= RAMPS => {
                    if self.bar.length() != Some(BLIPS as u64) {
                        self.bar.set_style(motors_style(" blips"));
                        self.bar.set_length(BLIPS as u64);
                    }
                    self.bar.set_position(t.blips as u64);
                }
                t => self.bar.set_position(t.map_or(0, |t| t.ramps) as u64),
            },
            (None, _) => self
                .bar
                .set_position((100.0 * p.coverage.fraction()).floor() as u64),
        }
        let target = p
            .target
            .map(|t| format!(", target {:.0} %", 100.0 * t))
            .unwrap_or_default();
        self.bar
            .set_prefix(format!("{:.1} s, {} samples{target}", p.t_s, p.samples));
        if self.routine == Routine::Motors {
            self.bar.set_message(throttle_lines(p.throttle.as_ref()));
            return;
        }
        let cube = self.routine == Routine::Cube24;
        let mut text = p.coverage.render(5);
        text += legend(cube);
        text.push('\n');
        text += &quality_lines(p.quality, cube);
        if let Some(d) = &p.disturbance {
            text.push('\n');
            text += &disturbance_lines(d);
        }
        self.bar.set_message(text);
    }

    fn enter_pressed(&mut self) -> bool {
        self.enter.as_ref().is_some_and(EnterKey::pressed)
    }

    fn finish(&mut self) {
        self.bar.abandon();
        self.echo_off = None;
    }
}

/// Not a terminal (a pipe, a log, a test): a progress line per second of recording time, and the last one at the
/// end.
pub struct PlainUi {
    enter: Option<EnterKey>,
    next_line_s: f64,
    /// The latest progress line, if it was not printed.
    pending: Option<String>,
}

impl PlainUi {
    /// Plain lines; `enter` listens for the Enter key (none when unattended).
    pub fn new(enter: Option<EnterKey>) -> PlainUi {
        PlainUi {
            enter,
            next_line_s: 0.0,
            pending: None,
        }
    }
}

impl Ui for PlainUi {
    fn message(&mut self, text: &str) {
        show(text);
    }

    fn progress(&mut self, p: &Progress<'_>) {
        let due = p.t_s >= self.next_line_s;
        let routine = match (p.poses, p.target) {
            _ if p.throttle.is_some() => throttle_lines(p.throttle.as_ref()).replace('\n', "; "),
            (Some((taken, n)), _) => format!("poses {taken}/{n}"),
            (None, Some(target)) => format!(
                "coverage {:.0} % (target {:.0} %)",
                100.0 * p.coverage.fraction(),
                100.0 * target
            ),
            (None, None) => format!("coverage {:.0} %", 100.0 * p.coverage.fraction()),
        };
        let quality = if p.throttle.is_some() {
            String::new()
        } else {
            format!(
                "; {}",
                quality_lines(p.quality, p.poses.is_some()).replace("\n ", "")
            )
        };
        let line = format!(
            "recording: t={:.2} s, samples={}, {routine}{quality}",
            p.t_s, p.samples
        );
        if due {
            self.next_line_s = p.t_s.floor() + 1.0;
            self.pending = None;
            show(&line);
        } else {
            self.pending = Some(line);
        }
    }

    fn enter_pressed(&mut self) -> bool {
        self.enter.as_ref().is_some_and(EnterKey::pressed)
    }

    fn finish(&mut self) {
        if let Some(line) = self.pending.take() {
            show(&line);
        }
    }
}

/// A line on standard output. One that cannot be written is not worth stopping a recording for: the file holds the
/// samples, and the summary at the end reports a failing output.
fn show(line: &str) {
    let _ = crate::sayln!("{line}");
}

/// The live display of `routine` when standard output is a terminal, plain lines otherwise. Unattended (`auto`),
/// nothing listens for Enter.
pub fn for_stdout(auto: bool, routine: Routine) -> Box<dyn Ui> {
    let enter = (!auto).then(EnterKey::listen);
    if std::io::stdout().is_terminal() {
        Box::new(TerminalUi::new(enter, routine))
    } else {
        Box::new(PlainUi::new(enter))
    }
}

#[cfg(test)]
mod tests {
    use std::io;
    use std::sync::{Arc, Mutex};

    use indicatif::TermLike;

    use super::*;

    /// A terminal emulator (vt100) that indicatif draws to.
    #[derive(Clone)]
    struct Screen(Arc<Mutex<vt100::Parser>>);

    impl std::fmt::Debug for Screen {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("Screen")
        }
    }

    impl Screen {
        fn new() -> Screen {
            let size = |n| std::num::NonZeroU16::new(n).unwrap();
            Screen(Arc::new(Mutex::new(vt100::Parser::new(
                size(40),
                size(100),
                0,
            ))))
        }

        fn send(&self, bytes: &str) -> io::Result<()> {
            self.0.lock().unwrap().process(bytes.as_bytes());
            Ok(())
        }

        /// The screen's rows, trailing blanks trimmed.
        fn lines(&self) -> Vec<String> {
            let parser = self.0.lock().unwrap();
            parser
                .screen()
                .rows(0, 100)
                .map(|r| r.trim_end().to_owned())
                .collect()
        }
    }

    impl TermLike for Screen {
        fn width(&self) -> u16 {
            100
        }
        fn height(&self) -> u16 {
            40
        }
        fn move_cursor_up(&self, n: usize) -> io::Result<()> {
            self.send(&format!("\x1b[{n}A"))
        }
        fn move_cursor_down(&self, n: usize) -> io::Result<()> {
            self.send(&format!("\x1b[{n}B"))
        }
        fn move_cursor_right(&self, n: usize) -> io::Result<()> {
            self.send(&format!("\x1b[{n}C"))
        }
        fn move_cursor_left(&self, n: usize) -> io::Result<()> {
            self.send(&format!("\x1b[{n}D"))
        }
        fn write_line(&self, s: &str) -> io::Result<()> {
            self.send(&format!("{s}\r\n"))
        }
        fn write_str(&self, s: &str) -> io::Result<()> {
            self.send(s)
        }
        fn clear_line(&self) -> io::Result<()> {
            self.send("\r\x1b[2K")
        }
        fn flush(&self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn the_screen_shows_the_map_its_legend_the_figures_and_a_magnet_while_it_lasts() {
        let screen = Screen::new();
        let mut ui = TerminalUi::on(
            ProgressDrawTarget::term_like(Box::new(screen.clone())),
            None,
            Routine::Free,
        );
        let mut map = CoverageMap::new();
        for i in 0..2000 {
            let z = -1.0 + 2.0 * (i as f64 + 0.5) / 2000.0;
            let phi = i as f64 * 2.399963;
            let r = (1.0 - z * z).sqrt();
            map.add([50.0 * r * phi.cos() + 10.0, 50.0 * r * phi.sin(), 50.0 * z]);
        }
        let quality = Quality::of(map.directions());
        assert!(quality.is_some());
        let magnet = Disturbance {
            since_s: 20.1,
            magnitude_ut: 144.6,
            usual_ut: 46.9,
        };
        let progress = |t_s: f64, disturbance: Option<Disturbance>| Progress {
            t_s,
            samples: (100.0 * t_s) as u64,
            coverage: &map,
            target: Some(0.9),
            poses: None,
            quality,
            disturbance,
            throttle: None,
        };
        ui.message("free rotation: turn the sensor");
        ui.progress(&progress(20.0, None));
        ui.progress(&progress(21.0, Some(magnet)));
        ui.message("t = 20.1 s: the field magnitude is 144.6 µT");
        let during = screen.lines();
        let count =
            |lines: &[String], what: &str| lines.iter().filter(|l| l.contains(what)).count();
        assert_eq!(
            count(&during, "! the field is 144.6 µT, not the 46.9 µT"),
            1,
            "{during:#?}"
        );
        assert_eq!(
            count(&during, "a magnet or iron near the sensor? Move it away"),
            1
        );
        ui.progress(&progress(26.0, None));
        ui.finish();
        let after = screen.lines();
        for (what, n) in [
            ("free rotation: turn the sensor", 1),
            ("t = 20.1 s: the field magnitude is 144.6 µT", 1),
            ("+Z hemisphere", 1),
            ("# a direction of the field seen", 1),
            ("quality: gaps", 1),
            ("% of the sphere  26.0 s, 2600 samples, target 90 %", 1),
            ("! the field is", 0),
        ] {
            assert_eq!(count(&after, what), n, "{what}: {after:#?}");
        }
    }

    #[test]
    fn the_motors_routine_shows_the_current_the_ramps_and_the_field_change() {
        let screen = Screen::new();
        let mut ui = TerminalUi::on(
            ProgressDrawTarget::term_like(Box::new(screen.clone())),
            None,
            Routine::Motors,
        );
        let map = CoverageMap::new();
        let throttle = Throttle {
            current_a: 24.5,
            range_a: (1.5, 30.0),
            ramps: 1,
            blips: 0,
            change_ut: [0.5, -3.0, 12.25],
        };
        let progress = |t_s, throttle| Progress {
            t_s,
            samples: 1550,
            coverage: &map,
            target: None,
            poses: None,
            quality: None,
            disturbance: None,
            throttle: Some(throttle),
        };
        ui.progress(&progress(31.0, throttle));
        let text = screen.lines().join("\n");
        for what in [
            "current 24.5 A (lowest 1.5 A, highest 30.0 A); ramps 1/2 up to 60 % of the highest and back",
            "then blips 0/10: up to it within 0.3 s and back",
            "field change since the start +0.50, -3.00, +12.25 µT (12.62 µT)",
            "1/2 ramps  31.0 s, 1550 samples",
        ] {
            assert!(text.contains(what), "{what}: {text}");
        }
        // The ramps made, the bar counts the blips.
        let blipping = Throttle {
            ramps: 2,
            blips: 3,
            ..throttle
        };
        ui.progress(&progress(40.0, blipping));
        ui.finish();
        let lines = screen.lines();
        let text = lines.join("\n");
        for what in ["then blips 3/10", "3/10 blips  40.0 s"] {
            assert!(text.contains(what), "{what}: {lines:#?}");
        }
        assert!(
            !text.contains("quality") && !text.contains("hemisphere"),
            "{lines:#?}"
        );
        for line in throttle_lines(Some(&throttle))
            .lines()
            .chain(throttle_lines(None).lines())
        {
            assert!(line.chars().count() <= 100, "{line}");
        }
    }

    #[test]
    fn the_cube_routine_shows_no_gaps_and_every_line_fits_80_columns() {
        let q = Quality {
            gaps_pct: 75.0,
            variance_pct: 1.0,
            wobble_pct: 6.0,
            fit_error_pct: 1.2,
        };
        let cube = quality_lines(Some(q), true);
        assert!(
            cube.contains("variance 1.0 %")
                && !cube.contains("gaps")
                && cube.contains("all within"),
            "{cube}"
        );
        let free = quality_lines(Some(q), false);
        assert!(
            free.contains("gaps 75.0 %")
                && free.contains("wobble 6.0 %")
                && free.ends_with("not yet)"),
            "{free}"
        );
        assert!(legend(true).contains("pose"));
        let d = Disturbance {
            since_s: 120.5,
            magnitude_ut: 144.6,
            usual_ut: 46.9,
        };
        // Before the figures mean something (issue 34): a dash for each, not thousands of per cent.
        let (cube_none, free_none) = (quality_lines(None, true), quality_lines(None, false));
        assert!(
            cube_none.starts_with("quality: variance —, fit error —")
                && !cube_none.contains("gaps"),
            "{cube_none}"
        );
        assert!(
            free_none.starts_with("quality: gaps —, variance —, wobble —, fit error —"),
            "{free_none}"
        );
        let text = [
            legend(true),
            legend(false),
            &cube,
            &free,
            &cube_none,
            &free_none,
            &disturbance_lines(&d),
        ]
        .join("\n");
        for line in text.lines() {
            assert!(line.chars().count() <= 80, "{line}");
        }
    }
}
