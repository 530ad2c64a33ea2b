//! Noticing a field that departs from the rest while the sensor is turned: a magnet or a piece of iron near it.
//!
//! The readings of an undisturbed sensor lie on one ellipsoid around the hard-iron offset, its radii the field's
//! magnitude times each axis' gain: an uncalibrated chip's gains differ by 20 % (the shared HMC5883L's Z), which a
//! sphere takes for a magnet whenever the sensor turns from one axis to another. So the watch judges each reading
//! by the running fit of an axis-aligned ellipsoid ([`Ellipsoid`]: the offset and a gain per axis, what the
//! calibration will find), fitted again every so often, robustly, to the readings it accepted. Once the fit has
//! settled — [`SETTLE_READINGS`] readings covering [`SETTLE_FRACTION`] of the directions, on the ellipsoid within
//! [`SETTLE_MISFIT`] (RMS), its gains within [`MAX_GAIN_RATIO`] of each other, the readings spread along every
//! axis ([`AXIS_SEEN`]) — a reading whose corrected
//! magnitude differs from the rest's by more than [`OFF_SPHERE`] of it (and at least [`MIN_OFF_SPHERE_UT`])
//! departs, and never enters the fit. [`PERSIST`] departing readings in a row make a disturbance, as many back on
//! the ellipsoid end it.

use magcal_calib::directions::{
    DirectionCoverage, SETTLE_FRACTION, SETTLE_MISFIT, SETTLE_READINGS,
};
use magcal_calib::sphere::{MIN_OFF_SPHERE_UT, OFF_SPHERE};
use nalgebra::{Matrix6, Vector6};

/// Readings in a row that start (or end) a disturbance.
pub const PERSIST: u32 = 10;

/// The ellipsoid settles only with its largest radius within this factor of its smallest: the gains of a chip and
/// its soft iron differ by tens of per cent, not by half, and a fit that says so is not determined yet.
pub const MAX_GAIN_RATIO: f64 = 1.6;

/// The ellipsoid settles once the readings spread along each axis over this fraction of its diameter there.
pub const AXIS_SEEN: f64 = 0.6;

/// The ellipsoid is fitted again after this many accepted readings at least…
const REFIT_EVERY: usize = 25;
/// …and after this fraction of those so far (so a long recording costs a bounded number of fits).
const REFIT_FRACTION: f64 = 0.02;
/// Concentration steps of the robust fit, each on this share of the readings nearest the last ellipsoid.
const TRIM_STEPS: usize = 3;
const TRIM_KEEP: f64 = 0.8;
/// The ellipsoid is fitted to at most this many of the accepted readings, evenly spaced.
const FIT_READINGS: usize = 4000;

/// An axis-aligned ellipsoid in raw sensor axes: the readings' offset and a radius per axis (the field's magnitude
/// times the axis' gain), µT.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    /// The centre, µT.
    pub centre_ut: [f64; 3],
    /// The radius along each axis, µT.
    pub radii_ut: [f64; 3],
}

impl Ellipsoid {
    /// The least-squares ellipsoid `Σ a_k·x_k² + d_k·x_k = 1` through `readings` (centred and scaled first, for
    /// conditioning); `None` when they do not determine one with positive radii.
    pub fn fit(readings: &[[f64; 3]]) -> Option<Ellipsoid> {
        let n = readings.len();
        if n < 6 {
            return None;
        }
        let mean: [f64; 3] =
            std::array::from_fn(|k| readings.iter().map(|m| m[k]).sum::<f64>() / n as f64);
        let scale = (readings
            .iter()
            .map(|m| (0..3).map(|k| (m[k] - mean[k]).powi(2)).sum::<f64>())
            .sum::<f64>()
            / n as f64)
            .sqrt();
        if scale.is_nan() || scale <= 1e-9 {
            return None;
        }
        let mut xtx = Matrix6::<f64>::zeros();
        let mut xty = Vector6::<f64>::zeros();
        for m in readings {
            let x: [f64; 3] = std::array::from_fn(|k| (m[k] - mean[k]) / scale);
            let row = Vector6::new(x[0] * x[0], x[1] * x[1], x[2] * x[2], x[0], x[1], x[2]);
            xtx += row * row.transpose();
            xty += row;
        }
        let p = xtx.cholesky()?.solve(&xty);
        let a = [p[0], p[1], p[2]];
        if a.iter().any(|&v| v.is_nan() || v <= 0.0) {
            return None;
        }
        let c: [f64; 3] = std::array::from_fn(|k| -p[k + 3] / (2.0 * a[k]));
        let g = 1.0 + (0..3).map(|k| a[k] * c[k] * c[k]).sum::<f64>();
        if g.is_nan() || g <= 0.0 {
            return None;
        }
        let e = Ellipsoid {
            centre_ut: std::array::from_fn(|k| mean[k] + scale * c[k]),
            radii_ut: std::array::from_fn(|k| scale * (g / a[k]).sqrt()),
        };
        e.radii_ut.iter().all(|r| r.is_finite()).then_some(e)
    }

    /// The readings' ellipsoid fitted robustly: [`TRIM_STEPS`] times again on the [`TRIM_KEEP`] of them nearest
    /// the last one, so that a burst of disturbed readings does not bend it; and the RMS of those readings' relative
    /// distance from it.
    pub fn fit_robust(readings: &[[f64; 3]]) -> Option<(Ellipsoid, f64)> {
        let mut e = Ellipsoid::fit(readings)?;
        let mut kept: Vec<[f64; 3]> = readings.to_vec();
        for _ in 0..TRIM_STEPS {
            let mut off: Vec<f64> = readings.iter().map(|m| e.relative_off(*m).abs()).collect();
            let keep = ((TRIM_KEEP * off.len() as f64) as usize).min(off.len() - 1);
            let cut = *off.select_nth_unstable_by(keep, f64::total_cmp).1;
            kept = readings
                .iter()
                .copied()
                .filter(|m| e.relative_off(*m).abs() <= cut)
                .collect();
            e = Ellipsoid::fit(&kept)?;
        }
        let misfit = (kept.iter().map(|m| e.relative_off(*m).powi(2)).sum::<f64>()
            / kept.len().max(1) as f64)
            .sqrt();
        Some((e, misfit))
    }

    /// The field's magnitude: the mean radius, µT.
    pub fn radius_ut(&self) -> f64 {
        self.radii_ut.iter().sum::<f64>() / 3.0
    }

    /// A reading's magnitude with the offset taken out and each axis' gain made the mean's, µT.
    pub fn corrected_ut(&self, m: [f64; 3]) -> f64 {
        (1.0 + self.relative_off(m)) * self.radius_ut()
    }

    /// How far a reading is from the ellipsoid, as a fraction of its radius along the reading's direction.
    pub fn relative_off(&self, m: [f64; 3]) -> f64 {
        (0..3)
            .map(|k| ((m[k] - self.centre_ut[k]) / self.radii_ut[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            - 1.0
    }

    /// Whether a reading is off the ellipsoid ([`OFF_SPHERE`] of the radius, and [`MIN_OFF_SPHERE_UT`]).
    pub fn departs(&self, m: [f64; 3]) -> bool {
        let off = self.relative_off(m).abs();
        off > OFF_SPHERE && off * self.radius_ut() > MIN_OFF_SPHERE_UT
    }

    /// The largest radius over the smallest.
    fn gain_ratio(&self) -> f64 {
        let max = self.radii_ut.iter().copied().fold(f64::MIN, f64::max);
        let min = self.radii_ut.iter().copied().fold(f64::MAX, f64::min);
        max / min
    }
}

/// Whether `readings` spread along every axis of `e` over [`AXIS_SEEN`] of its diameter there: only then are its
/// three gains and its centre determined, not guessed from a cap of directions.
fn sees_every_axis(e: &Ellipsoid, readings: &[[f64; 3]]) -> bool {
    (0..3).all(|k| {
        let (low, high) =
            readings
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), m| {
                    let u = (m[k] - e.centre_ut[k]) / e.radii_ut[k];
                    (lo.min(u), hi.max(u))
                });
        high - low >= 2.0 * AXIS_SEEN
    })
}

/// A change the watch reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MagnitudeEvent {
    /// The field magnitude departed from the rest's at `t_s`.
    Departed {
        /// When, s.
        t_s: f64,
        /// The magnitude of the reading that made it a disturbance (its offset and gains corrected), µT.
        magnitude_ut: f64,
        /// The rest's, µT.
        usual_ut: f64,
    },
    /// The magnitude is back to the rest's at `t_s`.
    Returned {
        /// When, s.
        t_s: f64,
        /// How long the disturbance lasted, s.
        lasted_s: f64,
    },
}

/// A disturbance under way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disturbance {
    /// Since when, s.
    pub since_s: f64,
    /// The magnitude of the last departing reading (its offset and gains corrected), µT.
    pub magnitude_ut: f64,
    /// The rest's, µT.
    pub usual_ut: f64,
}

/// The running ellipsoid of the readings and the state of the watch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MagnitudeWatch {
    /// The directions the readings cover (for the settling only).
    coverage: DirectionCoverage,
    /// The readings accepted, µT.
    readings: Vec<[f64; 3]>,
    /// The running ellipsoid, once the readings determine one.
    ellipsoid: Option<Ellipsoid>,
    /// Its misfit (RMS, relative).
    misfit: f64,
    /// Whether it judges the readings yet.
    settled: bool,
    next_refit: usize,
    /// Readings in a row on the other side of the threshold from the current state.
    run: u32,
    /// The disturbance under way.
    disturbance: Option<Disturbance>,
    /// The magnitude of the last departing reading, µT.
    last_departing_ut: f64,
    /// Whether the last reading departed.
    last_departed: bool,
}

impl MagnitudeWatch {
    /// A watch that has seen nothing.
    pub fn new() -> MagnitudeWatch {
        MagnitudeWatch::default()
    }

    /// Whether the last reading looked at departed from the rest's magnitude.
    pub fn last_departed(&self) -> bool {
        self.last_departed
    }

    /// The rest's field magnitude (the ellipsoid's mean radius), µT, once the ellipsoid has settled.
    pub fn usual_ut(&self) -> Option<f64> {
        self.settled
            .then(|| self.ellipsoid.map(|e| e.radius_ut()))
            .flatten()
    }

    /// The running ellipsoid, once the readings determine one.
    pub fn ellipsoid(&self) -> Option<Ellipsoid> {
        self.ellipsoid
    }

    /// The disturbance under way, if any.
    pub fn disturbance(&self) -> Option<Disturbance> {
        self.disturbance
    }

    /// Fits the ellipsoid again if it is due, and settles it when it may.
    fn refit(&mut self) {
        let n = self.readings.len();
        if n < self.next_refit {
            return;
        }
        self.next_refit = n + REFIT_EVERY.max((REFIT_FRACTION * n as f64) as usize);
        // At most FIT_READINGS of them, evenly spaced: a long recording's refits stay cheap.
        let stride = n.div_ceil(FIT_READINGS);
        let sample: Vec<[f64; 3]> = self.readings.iter().step_by(stride).copied().collect();
        let Some((e, misfit)) = Ellipsoid::fit_robust(&sample) else {
            return;
        };
        if self.settled && e.gain_ratio() > MAX_GAIN_RATIO {
            // Keep judging by the last good one.
            return;
        }
        self.ellipsoid = Some(e);
        self.misfit = misfit;
        if !self.settled
            && n >= SETTLE_READINGS
            && self.coverage.fraction() >= SETTLE_FRACTION
            && misfit <= SETTLE_MISFIT
            && e.gain_ratio() <= MAX_GAIN_RATIO
            && sees_every_axis(&e, &sample)
        {
            self.settled = true;
        }
    }

    /// Looks at the reading `raw_ut` taken at `t_s` (every reading, recorded or not); returns a change of state if
    /// there is one.
    pub fn add(&mut self, t_s: f64, raw_ut: [f64; 3]) -> Option<MagnitudeEvent> {
        self.last_departed = false;
        if !raw_ut.iter().all(|v| v.is_finite()) {
            return None;
        }
        let judge = self.ellipsoid.filter(|_| self.settled);
        let departs = judge.is_some_and(|e| e.departs(raw_ut));
        self.last_departed = departs;
        if !departs {
            self.coverage.add(raw_ut);
            self.readings.push(raw_ut);
            self.refit();
        }
        let e = judge?;
        if departs {
            self.last_departing_ut = e.corrected_ut(raw_ut);
            if let Some(d) = &mut self.disturbance {
                d.magnitude_ut = self.last_departing_ut;
            }
        }
        self.run = if departs != self.disturbance.is_some() {
            self.run + 1
        } else {
            0
        };
        if self.run < PERSIST {
            return None;
        }
        self.run = 0;
        Some(match self.disturbance.take() {
            Some(d) => MagnitudeEvent::Returned {
                t_s,
                lasted_s: t_s - d.since_s,
            },
            None => {
                let d = Disturbance {
                    since_s: t_s,
                    magnitude_ut: self.last_departing_ut,
                    usual_ut: e.radius_ut(),
                };
                self.disturbance = Some(d);
                MagnitudeEvent::Departed {
                    t_s,
                    magnitude_ut: d.magnitude_ut,
                    usual_ut: d.usual_ut,
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Readings on a sphere of radius 50 µT around an offset, turning through every direction.
    fn reading(i: usize) -> [f64; 3] {
        let z = -1.0 + 2.0 * ((i * 7919) % 1000) as f64 / 1000.0;
        let phi = i as f64 * 2.399963;
        let r = (1.0 - z * z).sqrt();
        [
            30.0 + 50.0 * r * phi.cos(),
            -20.0 + 50.0 * r * phi.sin(),
            10.0 + 50.0 * z,
        ]
    }

    /// Issue 34: an uncalibrated sensor, its Z gain 20 % low (as the shared HMC5883L's), turned through every
    /// direction: the sphere of the readings took the field along Z for a magnet 8 times; the running ellipsoid
    /// takes its gains out and says nothing — but still notices a magnet of 30 µT (which changes the magnitude by a sixth at least).
    #[test]
    fn an_axis_gain_error_is_no_magnet_and_a_magnet_still_is() {
        let gains = [1.0, 0.95, 0.8];
        let sensor = |i: usize| -> [f64; 3] {
            let m = reading(i);
            let centre = [30.0, -20.0, 10.0];
            std::array::from_fn(|k| centre[k] + gains[k] * (m[k] - centre[k]))
        };
        for magnet_ut in [0.0, 30.0] {
            let mut w = MagnitudeWatch::new();
            let mut events = Vec::new();
            for i in 0..6000 {
                let t_s = i as f64 * 0.01;
                let mut m = sensor(i);
                if (40.0..45.0).contains(&t_s) {
                    m[1] += magnet_ut;
                }
                events.extend(w.add(t_s, m));
            }
            if magnet_ut == 0.0 {
                assert!(events.is_empty(), "{events:?}");
                let e = w.ellipsoid().unwrap();
                assert!(
                    (0..3).all(|k| (e.radii_ut[k] - 50.0 * gains[k]).abs() < 0.01),
                    "{e:?}"
                );
            } else {
                assert!(
                    matches!(events.first(), Some(MagnitudeEvent::Departed { t_s, .. }) if (40.0..40.5).contains(t_s)),
                    "{events:?}"
                );
            }
        }
    }

    #[test]
    fn a_magnet_is_noticed_and_its_end_too_and_turning_alone_is_not() {
        let mut w = MagnitudeWatch::new();
        let mut events = Vec::new();
        for i in 0..3000 {
            let t_s = i as f64 * 0.01;
            let mut m = reading(i);
            // A magnet adds 150 µT along x from 15 s to 20 s.
            if (15.0..20.0).contains(&t_s) {
                m[0] += 150.0;
            }
            events.extend(w.add(t_s, m));
            assert_eq!(w.last_departed(), (15.0..20.0).contains(&t_s), "t = {t_s}");
            assert_eq!(
                w.disturbance().is_some(),
                (15.09..20.09).contains(&t_s),
                "t = {t_s}"
            );
        }
        assert_eq!(events.len(), 2, "{events:?}");
        let MagnitudeEvent::Departed { t_s, usual_ut, .. } = events[0] else {
            panic!("{events:?}");
        };
        assert!(
            (t_s - 15.09).abs() < 0.005 && (usual_ut - 50.0).abs() < 0.01,
            "{events:?}"
        );
        let MagnitudeEvent::Returned { lasted_s, .. } = events[1] else {
            panic!("{events:?}");
        };
        assert!((lasted_s - 5.0).abs() < 0.05, "{lasted_s}");
        assert!(
            (w.usual_ut().unwrap() - 50.0).abs() < 1e-6,
            "the magnet never entered the sphere"
        );
    }
}
