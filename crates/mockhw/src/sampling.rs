//! What every twin needs: conversions paced by the output data rate, and fields turned into counts.

use std::cell::RefCell;
use std::rc::Rc;

use magcal_sim::bench::Bench;

use crate::fault::Faults;

/// A bench shared by a chip twin (which samples it) and a recorder (which tells its hand what to do).
pub type SharedBench = Rc<RefCell<Bench>>;

/// Conversions at a fixed period from a start time: the first finishes one period after the start.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Ticker {
    /// Period, s; `None` while stopped.
    period_s: Option<f64>,
    /// When the next conversion finishes, s.
    next_s: f64,
}

impl Ticker {
    /// Starts converting every `period_s` from `now_s` (restarting if running).
    pub(crate) fn start(&mut self, now_s: f64, period_s: f64) {
        self.period_s = Some(period_s);
        self.next_s = now_s + period_s;
    }

    /// Stops converting.
    pub(crate) fn stop(&mut self) {
        self.period_s = None;
    }

    /// Whether conversions are running.
    pub(crate) fn is_running(&self) -> bool {
        self.period_s.is_some()
    }

    /// The conversions finished by `now_s` and not taken yet: the time of the newest and how many there were.
    pub(crate) fn take(&mut self, now_s: f64) -> Option<(f64, u64)> {
        let period = self.period_s?;
        if now_s < self.next_s {
            return None;
        }
        let n = ((now_s - self.next_s) / period).floor() as u64 + 1;
        let newest = self.next_s + (n - 1) as f64 * period;
        self.next_s += n as f64 * period;
        Some((newest, n))
    }
}

/// What a chip converts at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Measurement {
    /// The field at the sensing element, sensor axes, µT (the bench's raw reading plus any magnet).
    pub raw_ut: [f64; 3],
    /// Die temperature, °C.
    pub temp_c: f64,
    /// Whether the output registers are stuck (a [`Fault::StuckData`](crate::Fault::StuckData)): the twin then
    /// leaves them as they are.
    pub stuck: bool,
}

/// What a twin may look at while it handles a transaction.
pub(crate) struct Env<'a> {
    /// The time of the transaction, s.
    pub now_s: f64,
    bench: &'a RefCell<Bench>,
    faults: &'a Faults,
}

impl<'a> Env<'a> {
    pub(crate) fn new(now_s: f64, bench: &'a RefCell<Bench>, faults: &'a Faults) -> Env<'a> {
        Env {
            now_s,
            bench,
            faults,
        }
    }

    /// The conversion at `t_s`.
    pub(crate) fn measure(&self, t_s: f64) -> Measurement {
        let s = self.bench.borrow_mut().sample(t_s);
        let magnet = self.faults.magnet_ut(t_s);
        Measurement {
            raw_ut: std::array::from_fn(|k| s.raw_ut[k] + magnet[k]),
            temp_c: s.temp_c,
            stuck: self.faults.stuck(t_s),
        }
    }

    /// The die temperature at `t_s`, °C (no noise: the temperature channels' own resolution dominates).
    pub(crate) fn temperature_c(&self, t_s: f64) -> f64 {
        self.bench.borrow().temperature_c(t_s)
    }
}

/// A field in counts of `lsb_ut`, rounded, and whether it had to be clipped to `min..=max`.
pub(crate) fn counts(field_ut: f64, lsb_ut: f64, min: i32, max: i32) -> (i32, bool) {
    let c = (field_ut / lsb_ut).round();
    if c < f64::from(min) {
        (min, true)
    } else if c > f64::from(max) {
        (max, true)
    } else {
        (c as i32, false)
    }
}

/// A 16-bit two's-complement word as `[low, high]`, or `[high, low]` when `big_endian`.
pub(crate) fn word_bytes(value: i16, big_endian: bool) -> [u8; 2] {
    if big_endian {
        value.to_be_bytes()
    } else {
        value.to_le_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ticker_reports_the_newest_conversion_and_how_many_passed() {
        let mut t = Ticker::default();
        assert_eq!(t.take(10.0), None);
        t.start(1.0, 0.1);
        assert_eq!(t.take(1.05), None);
        let (newest, n) = t.take(1.1).unwrap();
        assert!((newest - 1.1).abs() < 1e-12 && n == 1);
        let (newest, n) = t.take(1.45).unwrap();
        assert!((newest - 1.4).abs() < 1e-9 && n == 3);
        assert_eq!(t.take(1.45), None);
        t.stop();
        assert!(!t.is_running() && t.take(5.0).is_none());
    }

    #[test]
    fn counts_round_and_clip() {
        assert_eq!(counts(1.0, 0.15, -10, 10), (7, false));
        assert_eq!(counts(-100.0, 1.0, -10, 10), (-10, true));
        assert_eq!(counts(100.0, 1.0, -10, 10), (10, true));
        assert_eq!(word_bytes(0x1234, false), [0x34, 0x12]);
        assert_eq!(word_bytes(0x1234, true), [0x12, 0x34]);
    }
}
