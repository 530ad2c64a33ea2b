//! Noticing a field that departs from the rest while the sensor is turned: a magnet or a piece of iron near it.
//!
//! The readings of an undisturbed sensor lie on one ellipsoid, nearly a sphere (soft iron is a few per cent), around
//! the hard-iron offset. A running least-squares sphere through the readings, `|m|² = 2·c·m + k`, gives that centre
//! and the field magnitude `R`; once the readings cover enough of the sphere to determine it, a reading whose
//! distance from the centre differs from `R` by more than [`DEPARTURE`] of it (and at least [`MIN_DEPARTURE_UT`])
//! departs. [`PERSIST`] departing readings in a row make a disturbance, as many back on the sphere end it. Departing
//! readings never enter the sphere, so a disturbance cannot move it.

use nalgebra::{Matrix4, Vector4};

/// A reading departs when its distance from the centre differs from the field magnitude by this fraction of it…
pub const DEPARTURE: f64 = 0.15;
/// …and by at least this much, µT.
pub const MIN_DEPARTURE_UT: f64 = 5.0;
/// Readings in a row that start (or end) a disturbance.
pub const PERSIST: u32 = 10;
/// Readings the sphere needs before it is trusted…
const MIN_READINGS: usize = 200;
/// …and the fraction of the sphere of directions they must cover.
const MIN_COVERAGE: f64 = 0.4;
/// The sphere is fitted again after every this many readings.
const REFIT_EVERY: usize = 25;

/// A change the watch reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MagnitudeEvent {
    /// The field magnitude departed from the rest's at `t_s`.
    Departed {
        /// When, s.
        t_s: f64,
        /// The magnitude of the reading that made it a disturbance, µT.
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

/// The running sphere and the state of the watch.
#[derive(Clone, Debug, PartialEq)]
pub struct MagnitudeWatch {
    /// Normal equations of the sphere fit: Σ x·xᵀ and Σ x·|m|² with x = (2m, 1).
    xtx: Matrix4<f64>,
    xty: Vector4<f64>,
    fitted: usize,
    /// Centre and radius, µT, once determined.
    sphere: Option<([f64; 3], f64)>,
    /// Readings in a row on the other side of the threshold from the current state.
    run: u32,
    /// Start of the disturbance under way, s.
    disturbed_since_s: Option<f64>,
    /// Readings that departed, in all.
    departed: u64,
}

impl Default for MagnitudeWatch {
    fn default() -> MagnitudeWatch {
        MagnitudeWatch::new()
    }
}

impl MagnitudeWatch {
    /// A watch that has seen nothing.
    pub fn new() -> MagnitudeWatch {
        MagnitudeWatch {
            xtx: Matrix4::zeros(),
            xty: Vector4::zeros(),
            fitted: 0,
            sphere: None,
            run: 0,
            disturbed_since_s: None,
            departed: 0,
        }
    }

    /// Readings that departed from the rest's magnitude so far.
    pub fn departed(&self) -> u64 {
        self.departed
    }

    /// The rest's field magnitude, µT, once determined.
    pub fn usual_ut(&self) -> Option<f64> {
        self.sphere.map(|(_, r)| r)
    }

    /// Looks at the reading `raw_ut` taken at `t_s`, with the sphere of directions covered to `coverage` (0–1) so
    /// far. Returns whether it departs (it is then left out of the sphere), and a change of state if there is one.
    pub fn add(
        &mut self,
        t_s: f64,
        raw_ut: [f64; 3],
        coverage: f64,
    ) -> (bool, Option<MagnitudeEvent>) {
        let Some((centre, radius)) = self.sphere else {
            self.fit_in(raw_ut);
            if self.fitted >= MIN_READINGS && coverage >= MIN_COVERAGE {
                self.sphere = self.solve();
            }
            return (false, None);
        };
        let distance = (0..3)
            .map(|k| (raw_ut[k] - centre[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let departs = (distance - radius).abs() > (DEPARTURE * radius).max(MIN_DEPARTURE_UT);
        let disturbed = self.disturbed_since_s.is_some();
        self.run = if departs != disturbed {
            self.run + 1
        } else {
            0
        };
        let mut event = None;
        if self.run >= PERSIST {
            self.run = 0;
            event = Some(match self.disturbed_since_s.take() {
                Some(since) => MagnitudeEvent::Returned {
                    t_s,
                    lasted_s: t_s - since,
                },
                None => {
                    self.disturbed_since_s = Some(t_s);
                    MagnitudeEvent::Departed {
                        t_s,
                        magnitude_ut: distance,
                        usual_ut: radius,
                    }
                }
            });
        }
        if departs {
            self.departed += 1;
        } else {
            self.fit_in(raw_ut);
            if self.fitted.is_multiple_of(REFIT_EVERY)
                && let Some(sphere) = self.solve()
            {
                self.sphere = Some(sphere);
            }
        }
        (departs, event)
    }

    fn fit_in(&mut self, m: [f64; 3]) {
        let x = Vector4::new(2.0 * m[0], 2.0 * m[1], 2.0 * m[2], 1.0);
        self.xtx += x * x.transpose();
        self.xty += x * (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        self.fitted += 1;
    }

    /// The least-squares sphere, if the readings determine one.
    fn solve(&self) -> Option<([f64; 3], f64)> {
        let s = self.xtx.cholesky()?.solve(&self.xty);
        let centre = [s[0], s[1], s[2]];
        let r2 = s[3] + centre.iter().map(|c| c * c).sum::<f64>();
        (r2 > 0.0 && r2.is_finite()).then(|| (centre, r2.sqrt()))
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
            let coverage = (i as f64 / 1000.0).min(1.0);
            let (departs, event) = w.add(t_s, m, coverage);
            assert_eq!(departs, (15.0..20.0).contains(&t_s), "t = {t_s}");
            events.extend(event);
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
        assert_eq!(w.departed(), 500);
        assert!(
            (w.usual_ut().unwrap() - 50.0).abs() < 1e-6,
            "the magnet never entered the sphere"
        );
    }
}
