//! Virtual time, shared by a simulated chip and whoever waits for it.

use std::cell::Cell;
use std::rc::Rc;

use embedded_hal::delay::DelayNs;

/// A clock that moves only when told to: by a delay, or by bus traffic (each I2C transaction takes its bit time).
///
/// Clones share the same time, so a recorder that waits through [`DelayNs`] and the chip twin that decides from the
/// time which conversions have finished agree on it; a two-minute routine then runs in well under a second of wall
/// time. Time starts at zero and counts nanoseconds.
#[derive(Clone, Debug, Default)]
pub struct VirtualClock {
    now_ns: Rc<Cell<u64>>,
}

impl VirtualClock {
    /// A clock at t = 0.
    pub fn new() -> VirtualClock {
        VirtualClock::default()
    }

    /// The time, ns.
    pub fn now_ns(&self) -> u64 {
        self.now_ns.get()
    }

    /// The time, s.
    pub fn now_s(&self) -> f64 {
        self.now_ns.get() as f64 * 1e-9
    }

    /// Moves time forwards by `ns`.
    pub fn advance_ns(&self, ns: u64) {
        self.now_ns.set(self.now_ns.get().saturating_add(ns));
    }

    /// Moves time forwards by `s` seconds (negative or NaN: not at all).
    pub fn advance_s(&self, s: f64) {
        if s > 0.0 {
            self.advance_ns((s * 1e9).round() as u64);
        }
    }
}

impl DelayNs for VirtualClock {
    fn delay_ns(&mut self, ns: u32) {
        self.advance_ns(u64::from(ns));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clones_share_time_and_delays_advance_it() {
        let clock = VirtualClock::new();
        let mut other = clock.clone();
        other.delay_ms(1500);
        assert_eq!(clock.now_ns(), 1_500_000_000);
        clock.advance_s(0.25);
        assert!((other.now_s() - 1.75).abs() < 1e-12);
        clock.advance_s(-1.0);
        clock.advance_s(f64::NAN);
        assert_eq!(clock.now_ns(), 1_750_000_000);
    }
}
