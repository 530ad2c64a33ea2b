//! Time as a recorder sees it: the wall clock for real devices, a virtual clock shared with the twin for `sim`.

use std::time::{Duration, Instant};

use magcal_mockhw::VirtualClock;

/// What a source waits with and reads its time from.
pub trait Clock {
    /// Seconds since the recording's clock started.
    fn now_s(&self) -> f64;
    /// Waits `s` seconds.
    fn sleep_s(&mut self, s: f64);
}

/// Real time: waiting sleeps.
#[derive(Clone, Copy, Debug)]
pub struct WallClock {
    start: Instant,
}

impl WallClock {
    /// A clock at zero now.
    pub fn new() -> WallClock {
        WallClock {
            start: Instant::now(),
        }
    }
}

impl Default for WallClock {
    fn default() -> WallClock {
        WallClock::new()
    }
}

impl Clock for WallClock {
    fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    fn sleep_s(&mut self, s: f64) {
        if s > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(s));
        }
    }
}

/// A simulated device's clock: waiting advances the virtual time the chip twin runs on. Paced, it also keeps the
/// virtual time from running ahead of the wall clock (to watch a simulated recording, or to kill it midway).
#[derive(Clone, Debug)]
pub struct SimClock {
    clock: VirtualClock,
    paced_from: Option<Instant>,
}

impl SimClock {
    /// Runs as fast as the computer can (a two-minute routine in well under a second).
    pub fn fast(clock: VirtualClock) -> SimClock {
        SimClock {
            clock,
            paced_from: None,
        }
    }

    /// Runs at the pace of the wall clock.
    pub fn paced(clock: VirtualClock) -> SimClock {
        SimClock {
            clock,
            paced_from: Some(Instant::now()),
        }
    }
}

impl Clock for SimClock {
    fn now_s(&self) -> f64 {
        self.clock.now_s()
    }

    fn sleep_s(&mut self, s: f64) {
        self.clock.advance_s(s);
        if let Some(from) = self.paced_from {
            let ahead = self.clock.now_s() - from.elapsed().as_secs_f64();
            if ahead > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fast_sim_clock_only_moves_virtual_time() {
        let v = VirtualClock::new();
        let mut c = SimClock::fast(v.clone());
        let wall = Instant::now();
        c.sleep_s(3600.0);
        assert!((v.now_s() - 3600.0).abs() < 1e-9);
        assert!(wall.elapsed() < Duration::from_secs(1));
    }

    #[test]
    fn a_paced_sim_clock_keeps_to_the_wall_clock() {
        let mut c = SimClock::paced(VirtualClock::new());
        let wall = Instant::now();
        for _ in 0..10 {
            c.sleep_s(0.01);
        }
        assert!(wall.elapsed() >= Duration::from_millis(95));
        assert!((c.now_s() - 0.1).abs() < 1e-9);
    }
}
