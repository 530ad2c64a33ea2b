//! Acceptance (issue 9, the recorder's screen): `magcal-record` runs in a pseudo-terminal as in a person's terminal
//! (its controlling terminal, echo on, 100 columns); keys are typed into it — Enter, then Ctrl-C as the terminal
//! sends it — and what it wrote is rendered by a terminal emulator (vt100). The screen after Ctrl-C holds the live
//! display once (no stale lines from earlier frames, no echoed `^C` or blank lines), the summary right below it, and
//! the terminal's echo is back on. The cube routine's screen shows no coverage target and no gaps figure.

use std::fs::File;
use std::io::{Read, Write};
use std::num::NonZeroU16;
use std::os::fd::OwnedFd;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use nix::pty::{Winsize, openpty};
use nix::sys::termios::{LocalFlags, tcgetattr};

const ROWS: u16 = 60;
const COLS: u16 = 100;

/// What a run left on the screen.
struct Screen {
    /// The screen's rows, trailing blanks trimmed.
    lines: Vec<String>,
    /// Whether the terminal echoes again after the recorder exited.
    echo_after: bool,
    /// Whether the live display came up (and the keys were typed).
    ready: bool,
    /// Whether the recorder exited by itself within the time allowed.
    exited: bool,
}

fn render(bytes: &[u8]) -> Vec<String> {
    let size = |n| NonZeroU16::new(n).unwrap();
    let mut parser = vt100::Parser::new(size(ROWS), size(COLS), 0);
    parser.process(bytes);
    parser
        .screen()
        .rows(0, COLS)
        .map(|r| r.trim_end().to_owned())
        .collect()
}

/// Runs `magcal-record ARGS` on a new pseudo-terminal (its controlling terminal, through `setsid -c`), waits for the
/// live display to show `ready`, types `keys` (each after a pause), and renders the screen once the recorder exits.
fn run_in_terminal(args: &[&str], ready: &str, keys: &[&[u8]]) -> Screen {
    let size = Winsize {
        ws_row: ROWS,
        ws_col: COLS,
        ws_xpixel: 0,
        ws_ypixel: 0,
    };
    let pty = openpty(Some(&size), None).expect("openpty");
    let slave = |pty: &OwnedFd| Stdio::from(pty.try_clone().expect("dup"));
    let mut child = Command::new("setsid")
        .arg("-c")
        .arg(env!("CARGO_BIN_EXE_magcal-record"))
        .args(args)
        .env("TERM", "xterm-256color")
        .stdin(slave(&pty.slave))
        .stdout(slave(&pty.slave))
        .stderr(slave(&pty.slave))
        .spawn()
        .expect("setsid (util-linux) runs the recorder");
    drop(pty.slave);
    let mut master = File::from(pty.master);
    let output = Arc::new(Mutex::new(Vec::new()));
    let reader = {
        let mut master = master.try_clone().unwrap();
        let output = output.clone();
        thread::spawn(move || {
            let mut buf = [0u8; 4096];
            // Ends with an error (EIO) once the recorder's side is closed.
            while let Ok(n) = master.read(&mut buf) {
                if n == 0 {
                    break;
                }
                output.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        })
    };
    let shown = |what: &str| {
        let bytes = output.lock().unwrap().clone();
        render(&bytes).iter().any(|l| l.contains(what))
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    while !shown(ready) && Instant::now() < deadline {
        thread::sleep(Duration::from_millis(50));
    }
    let came_up = shown(ready);
    if came_up {
        for key in keys {
            thread::sleep(Duration::from_millis(400));
            let _ = master.write_all(key);
        }
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline && matches!(child.try_wait(), Ok(None)) {
        thread::sleep(Duration::from_millis(20));
    }
    let exited = matches!(child.try_wait(), Ok(Some(_)));
    if !exited {
        let _ = child.kill();
    }
    let _ = child.wait();
    let echo_after = tcgetattr(&master)
        .unwrap()
        .local_flags
        .contains(LocalFlags::ECHO);
    reader.join().unwrap();
    let bytes = output.lock().unwrap().clone();
    Screen {
        lines: render(&bytes),
        echo_after,
        ready: came_up,
        exited,
    }
}

fn count(lines: &[String], what: &str) -> usize {
    lines.iter().filter(|l| l.contains(what)).count()
}

#[test]
fn after_enter_and_ctrl_c_the_screen_holds_no_stale_lines() {
    let dir = tempfile::tempdir().unwrap();
    let free = dir.path().join("free.csv");
    let cube = dir.path().join("cube.csv");
    let free_run = {
        let free = free.to_str().unwrap().to_owned();
        thread::spawn(move || {
            run_in_terminal(
                &[
                    "--device",
                    "sim:lis3mdl",
                    "--routine",
                    "free",
                    "--realtime",
                    "--out",
                    &free,
                ],
                "quality: gaps",
                &[b"\r", b"\r", b"\x03"],
            )
        })
    };
    let cube = run_in_terminal(
        &[
            "--device",
            "sim:lis3mdl",
            "--routine",
            "cube24",
            "--realtime",
            "--out",
            cube.to_str().unwrap(),
        ],
        "poses  ",
        &[b"\r", b"\x03"],
    );
    let free = free_run.join().unwrap();
    for (routine, screen, bar) in [
        ("free", &free, "% of the sphere  "),
        ("cube24", &cube, "poses  "),
    ] {
        let lines = &screen.lines;
        assert!(screen.ready, "{routine}: no live display: {lines:#?}");
        assert!(
            screen.exited,
            "{routine}: Ctrl-C ended the recording: {lines:#?}"
        );
        assert!(screen.echo_after, "{routine}: the terminal echoes again");
        for once in [
            "recording sim:lis3mdl to",
            "+Z hemisphere",
            "(seen from outside)",
            "quality:",
            bar,
        ] {
            assert_eq!(
                count(lines, once),
                1,
                "{routine}: {once:?} once: {lines:#?}"
            );
        }
        assert_eq!(count(lines, "^C"), 0, "{routine}: {lines:#?}");
        // The live display's last frame, then the summary right below it.
        let bar_at = lines.iter().position(|l| l.contains(bar)).unwrap();
        assert!(
            lines[bar_at + 1].starts_with("recorded ")
                && lines[bar_at + 1].contains("(interrupted)"),
            "{routine}: {lines:#?}"
        );
        // Interrupted short of its target: it says so rather than sending the user on to a fit.
        assert!(
            lines[bar_at + 2].starts_with("the recording stopped short of its routine"),
            "{routine}: {lines:#?}"
        );
        // No blank line inside the output: an echoed Enter would leave one.
        let first = lines
            .iter()
            .position(|l| l.starts_with("recording sim:"))
            .unwrap();
        assert!(
            lines[first..=bar_at + 2].iter().all(|l| !l.is_empty()),
            "{routine}: {lines:#?}"
        );
    }
    for once in ["target 90 %", "quality: gaps", "(MotionCal asks below"] {
        assert_eq!(count(&free.lines, once), 1, "{once:?}: {:#?}", free.lines);
    }
    assert_eq!(count(&cube.lines, "target"), 0, "{:#?}", cube.lines);
    assert_eq!(count(&cube.lines, "gaps"), 0, "{:#?}", cube.lines);
}
