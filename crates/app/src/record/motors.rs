//! The motors routine's watch over the throttle: the current now and its range, the ramps made (the current raised
//! to near the highest seen and lowered again), the blips made after them, and how far the field has moved since the
//! start.
//!
//! A ramp counts once the current has risen to [`RAMP_SHARE`] of the range seen (from the lowest current up) and
//! come back below [`RETURN_SHARE`] of it; at the end only the ramps whose peak reached [`RAMP_SHARE`] of the whole
//! range count, so a first timid ramp followed by a full one is one ramp. A range below [`MIN_RANGE_A`] is no
//! throttle at all (the current's own noise at idle).
//!
//! Once the ramps are made, the routine asks for [`BLIPS`] blips: the throttle snapped up and back. A blip is a rise
//! and fall as a ramp's whose rise, from the last current below [`RETURN_SHARE`] of the range to the first at
//! [`RAMP_SHARE`], took at most [`BLIP_RISE_S`]. The slow ramps give the coefficients; the blips give the lag of the
//! field behind the current, whose information is `Σ (k·dI/dt)²/σ²`: a slow ramp carries little of it.

/// Ramps the routine asks for.
pub const RAMPS: usize = 2;
/// A ramp's peak must reach this share of the current's range (from the lowest current).
pub const RAMP_SHARE: f64 = 0.6;
/// A ramp ends when the current falls below this share of the range.
pub const RETURN_SHARE: f64 = 0.2;
/// Blips the routine asks for after the ramps: enough that the lag is found to a few milliseconds with a
/// coefficient of 0.05 µT/A on each axis (docs/autopilot.md).
pub const BLIPS: usize = 10;
/// A blip's rise, from below [`RETURN_SHARE`] of the range to [`RAMP_SHARE`] of it, takes at most this long, s.
pub const BLIP_RISE_S: f64 = 0.3;
/// The smallest range of current that makes ramps, A.
pub const MIN_RANGE_A: f64 = 1.0;
/// Readings averaged for the field at the start.
const START_READINGS: usize = 10;

/// What the operator is shown of the throttle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Throttle {
    /// The current now, A.
    pub current_a: f64,
    /// The lowest and highest current so far, A.
    pub range_a: (f64, f64),
    /// Ramps made that reach [`RAMP_SHARE`] of the range.
    pub ramps: usize,
    /// Blips made after the ramps that reach [`RAMP_SHARE`] of the range.
    pub blips: usize,
    /// The field's change since the start, sensor axes, µT.
    pub change_ut: [f64; 3],
}

/// The watch; see the [module docs](self).
#[derive(Clone, Debug, Default)]
pub struct ThrottleWatch {
    start_sum_ut: [f64; 3],
    start_n: usize,
    last: Option<Throttle>,
    lowest_a: f64,
    highest_a: f64,
    /// The peak of the ramp under way, if the current is up, and whether it rose within [`BLIP_RISE_S`].
    up: Option<(f64, bool)>,
    /// When the current was last below [`RETURN_SHARE`] of the range, s.
    low_at_s: f64,
    peaks_a: Vec<f64>,
    blip_peaks_a: Vec<f64>,
}

impl ThrottleWatch {
    /// A watch that has seen nothing.
    pub fn new() -> ThrottleWatch {
        ThrottleWatch {
            lowest_a: f64::INFINITY,
            highest_a: f64::NEG_INFINITY,
            ..ThrottleWatch::default()
        }
    }

    /// Takes a reading at `t_s` (s): its field (µT) and current (A; a reading without one changes nothing but the
    /// field's start).
    pub fn add(&mut self, t_s: f64, mag_ut: [f64; 3], current_a: Option<f64>) {
        if self.start_n < START_READINGS {
            (0..3).for_each(|k| self.start_sum_ut[k] += mag_ut[k]);
            self.start_n += 1;
        }
        let start = self.start_sum_ut.map(|s| s / self.start_n as f64);
        let Some(i) = current_a.filter(|i| i.is_finite()) else {
            return;
        };
        self.lowest_a = self.lowest_a.min(i);
        self.highest_a = self.highest_a.max(i);
        let range = self.highest_a - self.lowest_a;
        let share = (i - self.lowest_a) / range;
        if range >= MIN_RANGE_A {
            match self.up {
                None if share >= RAMP_SHARE => {
                    self.up = Some((i, t_s - self.low_at_s <= BLIP_RISE_S));
                }
                Some((peak, quick)) if share < RETURN_SHARE => {
                    if self.ramps() < RAMPS || !quick {
                        self.peaks_a.push(peak);
                    } else {
                        self.blip_peaks_a.push(peak);
                    }
                    self.up = None;
                }
                Some((peak, quick)) => self.up = Some((peak.max(i), quick)),
                None => {}
            }
        }
        if range < MIN_RANGE_A || share < RETURN_SHARE {
            self.low_at_s = t_s;
        }
        self.last = Some(Throttle {
            current_a: i,
            range_a: (self.lowest_a, self.highest_a),
            ramps: self.ramps(),
            blips: self.blips(),
            change_ut: std::array::from_fn(|k| mag_ut[k] - start[k]),
        });
    }

    /// Of `peaks_a`, those that reached [`RAMP_SHARE`] of the whole range.
    fn full(&self, peaks_a: &[f64]) -> usize {
        let range = self.highest_a - self.lowest_a;
        if range < MIN_RANGE_A {
            return 0;
        }
        peaks_a
            .iter()
            .filter(|&&p| p - self.lowest_a >= RAMP_SHARE * range)
            .count()
    }

    /// Ramps made whose peak reached [`RAMP_SHARE`] of the whole range.
    fn ramps(&self) -> usize {
        self.full(&self.peaks_a)
    }

    /// Blips made after the ramps whose peak reached [`RAMP_SHARE`] of the whole range.
    fn blips(&self) -> usize {
        self.full(&self.blip_peaks_a)
    }

    /// The throttle as last seen, once a current came.
    pub fn throttle(&self) -> Option<Throttle> {
        self.last
    }

    /// Whether the routine's ramps and blips are made.
    pub fn done(&self) -> bool {
        self.ramps() >= RAMPS && self.blips() >= BLIPS
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A watch fed `currents` every `dt_s` seconds.
    fn watch_at(currents: &[f64], dt_s: f64) -> ThrottleWatch {
        let mut w = ThrottleWatch::new();
        for (k, &i) in currents.iter().enumerate() {
            w.add(k as f64 * dt_s, [10.0, 0.0, 0.0], Some(i));
        }
        w
    }

    /// Currents 0.1 s apart: a ramp of 41 of them rises from 20 % to 60 % of its range in 0.8 s.
    fn watch(currents: &[f64]) -> ThrottleWatch {
        watch_at(currents, 0.1)
    }

    fn ramp(peak: f64) -> Vec<f64> {
        (0..=20)
            .chain((0..20).rev())
            .map(|k| 2.0 + (peak - 2.0) * k as f64 / 20.0)
            .collect()
    }

    /// A blip at 0.1 s a reading: idle, then the peak at once for 0.5 s.
    fn blip(peak: f64) -> Vec<f64> {
        [vec![2.0; 10], vec![peak; 5]].concat()
    }

    #[test]
    fn ramps_count_when_up_to_near_the_highest_and_down_again() {
        let one = watch(&ramp(30.0));
        assert_eq!(one.throttle().unwrap().ramps, 1);
        assert!(!one.done());
        let two = watch(&[ramp(30.0), ramp(25.0)].concat());
        let t = two.throttle().unwrap();
        assert_eq!(
            (t.range_a, t.ramps, t.blips, t.change_ut),
            ((2.0, 30.0), 2, 0, [0.0; 3])
        );
        assert!(!two.done(), "the blips are still to come");
        // A timid first ramp, then a full one: one ramp (the first reached 18 % of the range).
        assert_eq!(
            watch(&[ramp(7.0), ramp(30.0)].concat())
                .throttle()
                .unwrap()
                .ramps,
            1
        );
        // An idle current's noise is no ramp.
        let idle: Vec<f64> = (0..400).map(|k| 0.3 + 0.2 * (k % 2) as f64).collect();
        assert_eq!(watch(&idle).throttle().unwrap().ramps, 0);
    }

    #[test]
    fn blips_count_after_the_ramps_when_the_current_rises_quickly() {
        let ramps = [ramp(30.0), ramp(30.0)].concat();
        let blips: Vec<f64> = (0..BLIPS).flat_map(|_| blip(28.0)).chain([2.0]).collect();
        let w = watch(&[ramps.clone(), blips.clone()].concat());
        let t = w.throttle().unwrap();
        assert_eq!((t.ramps, t.blips), (2, BLIPS));
        assert!(w.done());
        // Blips before the ramps: the first two are the ramps, the rest blips (and the slow ramps after them
        // ramps); a slow ramp after the ramps is no blip; a timid blip is none.
        let first = watch(&[blips.clone(), ramps.clone()].concat());
        let t = first.throttle().unwrap();
        assert_eq!((t.ramps, t.blips), (4, BLIPS - 2));
        let slow = watch(&[ramps.clone(), ramp(30.0), blip(10.0), vec![2.0]].concat());
        assert_eq!(slow.throttle().unwrap().blips, 0);
        // The rise is timed from the last current below 20 % of the range: a step rises within one reading.
        let fast = watch_at(&[ramps, blips].concat(), 0.25);
        assert_eq!(fast.throttle().unwrap().blips, BLIPS);
    }

    #[test]
    fn the_field_moves_from_the_mean_of_the_first_readings() {
        let mut w = ThrottleWatch::new();
        for k in 0..10 {
            w.add(0.02 * k as f64, [k as f64, 0.0, 0.0], Some(1.0));
        }
        w.add(0.2, [14.5, 1.0, -2.0], Some(11.0));
        assert_eq!(w.throttle().unwrap().change_ut, [10.0, 1.0, -2.0]);
        assert_eq!(w.throttle().unwrap().current_a, 11.0);
        w.add(0.22, [14.5, 1.0, -2.0], None);
        assert_eq!(w.throttle().unwrap().current_a, 11.0);
    }
}
