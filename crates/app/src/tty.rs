//! The terminal under the live display: while it runs, keys typed are not echoed. An echoed Enter or `^C` moves the
//! cursor down a line, and a display redrawn in place then leaves its old top line on the screen. The terminal's
//! settings come back when the display ends, and on a second Ctrl-C that exits at once ([`restore`]).

use std::io::IsTerminal;
use std::sync::Mutex;

use nix::sys::termios::{LocalFlags, SetArg, Termios, tcgetattr, tcsetattr};

/// The settings to restore, while echo is off.
static SAVED: Mutex<Option<Termios>> = Mutex::new(None);

/// Echo is off while this lives.
#[derive(Debug)]
pub struct EchoOff(());

impl EchoOff {
    /// Turns echo off on standard input, if it is a terminal (`None` otherwise, or if it cannot be).
    pub fn new() -> Option<EchoOff> {
        let stdin = std::io::stdin();
        if !stdin.is_terminal() {
            return None;
        }
        let saved = tcgetattr(&stdin).ok()?;
        let mut quiet = saved.clone();
        quiet
            .local_flags
            .remove(LocalFlags::ECHO | LocalFlags::ECHONL);
        let mut slot = SAVED.lock().unwrap_or_else(|e| e.into_inner());
        tcsetattr(&stdin, SetArg::TCSANOW, &quiet).ok()?;
        *slot = Some(saved);
        Some(EchoOff(()))
    }
}

impl Drop for EchoOff {
    fn drop(&mut self) {
        restore();
    }
}

/// Puts the terminal's settings back if echo is off; does nothing otherwise.
pub fn restore() {
    let mut slot = SAVED.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(saved) = slot.take() {
        let _ = tcsetattr(std::io::stdin(), SetArg::TCSANOW, &saved);
    }
}
