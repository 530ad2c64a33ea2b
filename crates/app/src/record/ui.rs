//! What the operator sees: prompts, the live coverage map and progress bar on a terminal, plain progress lines
//! otherwise; and the Enter key.

use std::io::{BufRead, IsTerminal};
use std::sync::mpsc::{self, Receiver};

use indicatif::{ProgressBar, ProgressStyle};

use super::coverage::CoverageMap;

/// What the recorder reports while it runs.
#[derive(Clone, Copy, Debug)]
pub struct Progress<'a> {
    /// Recording time, s.
    pub t_s: f64,
    /// Samples written.
    pub samples: u64,
    /// Directions seen.
    pub coverage: &'a CoverageMap,
    /// The coverage the free routine stops at, 0–1.
    pub target: f64,
    /// For the cube routine: poses taken, and of how many.
    pub poses: Option<(usize, usize)>,
}

/// The operator's side of a recording.
pub trait Ui {
    /// A prompt or a note, shown as a line.
    fn message(&mut self, text: &str);
    /// Progress; called after every sample (an implementation decides how often to show it).
    fn progress(&mut self, p: &Progress<'_>);
    /// Whether Enter was pressed since the last call.
    fn enter_pressed(&mut self) -> bool;
    /// The recording is over: clear any live display.
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

/// A terminal: the coverage map redrawn in place above a progress bar (indicatif).
pub struct TerminalUi {
    bar: ProgressBar,
    enter: Option<EnterKey>,
    cube: Option<usize>,
}

impl TerminalUi {
    /// A live display; `enter` listens for the Enter key (none when unattended). `cube_poses` makes the bar count
    /// poses instead of coverage.
    pub fn new(enter: Option<EnterKey>, cube_poses: Option<usize>) -> TerminalUi {
        let (len, template) = match cube_poses {
            Some(n) => (n as u64, "{msg}\n[{bar:40}] {pos}/{len} poses  {prefix}"),
            None => (100, "{msg}\n[{bar:40}] {pos:>3}% of the sphere  {prefix}"),
        };
        let bar = ProgressBar::new(len);
        bar.set_style(
            ProgressStyle::with_template(template)
                .expect("the template is valid")
                .progress_chars("=> "),
        );
        TerminalUi {
            bar,
            enter,
            cube: cube_poses,
        }
    }
}

impl Ui for TerminalUi {
    fn message(&mut self, text: &str) {
        self.bar.println(text);
    }

    fn progress(&mut self, p: &Progress<'_>) {
        match (self.cube, p.poses) {
            (Some(_), Some((taken, _))) => self.bar.set_position(taken as u64),
            _ => self
                .bar
                .set_position((100.0 * p.coverage.fraction()).floor() as u64),
        }
        let target = match p.poses {
            Some(_) => String::new(),
            None => format!(", target {:.0} %", 100.0 * p.target),
        };
        self.bar
            .set_prefix(format!("{:.1} s, {} samples{target}", p.t_s, p.samples));
        self.bar.set_message(p.coverage.render(5));
    }

    fn enter_pressed(&mut self) -> bool {
        self.enter.as_ref().is_some_and(EnterKey::pressed)
    }

    fn finish(&mut self) {
        self.bar.abandon();
    }
}

/// Not a terminal (a pipe, a log, a test): a progress line per second of recording time.
pub struct PlainUi {
    enter: Option<EnterKey>,
    next_line_s: f64,
}

impl PlainUi {
    /// Plain lines; `enter` listens for the Enter key (none when unattended).
    pub fn new(enter: Option<EnterKey>) -> PlainUi {
        PlainUi {
            enter,
            next_line_s: 0.0,
        }
    }
}

impl Ui for PlainUi {
    fn message(&mut self, text: &str) {
        println!("{text}");
    }

    fn progress(&mut self, p: &Progress<'_>) {
        if p.t_s < self.next_line_s {
            return;
        }
        self.next_line_s = p.t_s.floor() + 1.0;
        let poses = p
            .poses
            .map(|(taken, n)| format!(", poses {taken}/{n}"))
            .unwrap_or_default();
        println!(
            "recording: t={:.2} s, samples={}, coverage {:.0} % (target {:.0} %){poses}",
            p.t_s,
            p.samples,
            100.0 * p.coverage.fraction(),
            100.0 * p.target
        );
    }

    fn enter_pressed(&mut self) -> bool {
        self.enter.as_ref().is_some_and(EnterKey::pressed)
    }

    fn finish(&mut self) {}
}

/// The live display when standard output is a terminal, plain lines otherwise. Unattended (`auto`), nothing
/// listens for Enter.
pub fn for_stdout(auto: bool, cube_poses: Option<usize>) -> Box<dyn Ui> {
    let enter = (!auto).then(EnterKey::listen);
    if std::io::stdout().is_terminal() {
        Box::new(TerminalUi::new(enter, cube_poses))
    } else {
        Box::new(PlainUi::new(enter))
    }
}
