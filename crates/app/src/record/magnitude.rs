//! Noticing a field that departs from the rest while the sensor is turned: a magnet or a piece of iron near it.
//!
//! The readings of an undisturbed sensor lie on one ellipsoid, nearly a sphere (soft iron is a few per cent), around
//! the hard-iron offset. The watch follows every reading with the coverage's own sphere ([`DirectionCoverage`]):
//! once it has settled, a reading whose distance from the centre differs from the radius by more than
//! [`OFF_SPHERE`](magcal_calib::sphere::OFF_SPHERE) of it (and at least
//! [`MIN_OFF_SPHERE_UT`](magcal_calib::sphere::MIN_OFF_SPHERE_UT)) departs, and never enters the sphere. [`PERSIST`]
//! departing readings in a row make a disturbance, as many back on the sphere end it.

use magcal_calib::directions::DirectionCoverage;

/// Readings in a row that start (or end) a disturbance.
pub const PERSIST: u32 = 10;

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

/// A disturbance under way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disturbance {
    /// Since when, s.
    pub since_s: f64,
    /// The magnitude of the last departing reading, µT.
    pub magnitude_ut: f64,
    /// The rest's, µT.
    pub usual_ut: f64,
}

/// The sphere of every reading and the state of the watch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MagnitudeWatch {
    coverage: DirectionCoverage,
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

    /// The rest's field magnitude, µT, once the sphere has settled.
    pub fn usual_ut(&self) -> Option<f64> {
        self.coverage
            .is_settled()
            .then(|| self.coverage.sphere().map(|s| s.radius_ut))
            .flatten()
    }

    /// The disturbance under way, if any.
    pub fn disturbance(&self) -> Option<Disturbance> {
        self.disturbance
    }

    /// Looks at the reading `raw_ut` taken at `t_s` (every reading, recorded or not); returns a change of state if
    /// there is one.
    pub fn add(&mut self, t_s: f64, raw_ut: [f64; 3]) -> Option<MagnitudeEvent> {
        let sphere = self.coverage.sphere();
        let departs = !self.coverage.add(raw_ut) && self.coverage.is_settled();
        self.last_departed = departs;
        let (Some(sphere), true) = (sphere, self.coverage.is_settled()) else {
            return None;
        };
        if departs {
            self.last_departing_ut = sphere.distance_ut(raw_ut);
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
                    usual_ut: sphere.radius_ut,
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
