//! Telling a still sensor from a moving one: the spread of the last readings over a dwell time.

use std::collections::VecDeque;

use crate::source::Reading;

/// The last `len` readings, and whether they are still.
#[derive(Clone, Debug, PartialEq)]
pub struct StillWindow {
    len: usize,
    readings: VecDeque<Reading>,
}

impl StillWindow {
    /// A window of `len` readings (at least 2).
    pub fn new(len: usize) -> StillWindow {
        StillWindow {
            len: len.max(2),
            readings: VecDeque::with_capacity(len.max(2)),
        }
    }

    /// How many readings make the window full.
    pub fn capacity(&self) -> usize {
        self.len
    }

    /// Adds a reading, dropping the oldest when full.
    pub fn push(&mut self, r: Reading) {
        if self.readings.len() == self.len {
            self.readings.pop_front();
        }
        self.readings.push_back(r);
    }

    /// Whether the window holds `capacity` readings.
    pub fn is_full(&self) -> bool {
        self.readings.len() == self.len
    }

    /// Forgets every reading.
    pub fn clear(&mut self) {
        self.readings.clear();
    }

    /// Mean field, µT.
    pub fn mean_ut(&self) -> [f64; 3] {
        let n = self.readings.len().max(1) as f64;
        std::array::from_fn(|k| self.readings.iter().map(|r| r.mag_ut[k]).sum::<f64>() / n)
    }

    /// Standard deviation per axis, µT.
    pub fn spread_ut(&self) -> [f64; 3] {
        let mean = self.mean_ut();
        let n = self.readings.len().max(2) as f64 - 1.0;
        std::array::from_fn(|k| {
            (self
                .readings
                .iter()
                .map(|r| (r.mag_ut[k] - mean[k]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        })
    }

    /// Full, and no axis spreads more than `threshold_ut`.
    pub fn is_still(&self, threshold_ut: f64) -> bool {
        self.is_full() && self.spread_ut().iter().all(|s| *s <= threshold_ut)
    }

    /// The readings, oldest first; the window is left empty.
    pub fn take(&mut self) -> Vec<Reading> {
        self.readings.drain(..).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(x: f64) -> Reading {
        Reading {
            t_s: 0.0,
            mag_ut: [x, 10.0, -5.0],
            temp_c: None,
            quat: None,
            current_a: None,
        }
    }

    #[test]
    fn noise_is_still_and_a_turn_is_not() {
        let mut w = StillWindow::new(50);
        for i in 0..49 {
            w.push(r(20.0 + 0.3 * ((i * 7 % 11) as f64 / 5.0 - 1.0)));
        }
        assert!(!w.is_still(0.5), "not full yet");
        w.push(r(20.0));
        assert!(w.is_still(0.5));
        assert!((w.mean_ut()[0] - 20.0).abs() < 0.1);
        for i in 0..25 {
            w.push(r(20.0 + i as f64));
        }
        assert!(!w.is_still(0.5));
        assert_eq!(w.take().len(), 50);
        assert!(!w.is_full());
    }
}
