//! A pseudo-terminal pair for the serial tests: the tools open the slave by its path, as they would open
//! `/dev/ttyACM0`; the simulated firmware of `magcal-mockhw` owns the master. Dropping the master is unplugging the
//! board.

#![allow(dead_code, reason = "each test binary uses a different part")]

use std::fs::File;
use std::os::fd::OwnedFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::{self, JoinHandle};

use magcal_mockhw::firmware::{FirmwareConfig, FirmwareReport, MotionCalFirmware};
use nix::fcntl::{FcntlArg, FdFlag, OFlag, fcntl};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use nix::unistd::ttyname;

/// The two ends of a pseudo-terminal.
pub struct Pty {
    /// The board's end (raw, non-blocking).
    pub master: File,
    /// What the tools open.
    pub slave_path: String,
    /// Held open so the line stays up between the tools' runs.
    _slave: OwnedFd,
}

/// Opens a pseudo-terminal pair.
pub fn open() -> Pty {
    let pty = openpty(None, None).expect("openpty");
    let mut termios = tcgetattr(&pty.master).expect("tcgetattr");
    cfmakeraw(&mut termios);
    tcsetattr(&pty.master, SetArg::TCSANOW, &termios).expect("raw mode");
    fcntl(&pty.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).expect("non-blocking master");
    // The tools run as child processes: they must not inherit the board's end (or the line never hangs up).
    for fd in [&pty.master, &pty.slave] {
        fcntl(fd, FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC)).expect("close-on-exec");
    }
    let slave_path = ttyname(&pty.slave)
        .expect("slave path")
        .to_str()
        .expect("utf-8 path")
        .to_owned();
    Pty {
        master: File::from(pty.master),
        slave_path,
        _slave: pty.slave,
    }
}

/// Runs the firmware on `master` in a thread until it unplugs itself or `stop` is set.
pub fn firmware(
    master: File,
    config: FirmwareConfig,
    stop: Arc<AtomicBool>,
) -> JoinHandle<FirmwareReport> {
    thread::spawn(move || {
        MotionCalFirmware::new(master, config)
            .expect("a valid bench")
            .run(|| stop.load(Ordering::Relaxed))
    })
}
