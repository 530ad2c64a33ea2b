//! MotionCal-style figures of how well the samples recorded so far serve a calibration, updated live.
//!
//! PJRC's MotionCal shows four percentages and offers to send a calibration once all are below its limits
//! ([`MOTIONCAL_LIMITS`]). They are defined here as MotionCal defines them, on the recorder's own terms: the cells
//! of the shared grid ([`DirectionCoverage`], 98 equal-area cells where MotionCal has 100) and the readings'
//! distance `d` from the centre of the sphere they lie on (MotionCal measures them after its own calibration; the
//! recorder fits a sphere, so soft iron of a few per cent adds to variance and fit error):
//!
//! - **gaps**: each empty cell counts 1, a cell with one reading 0.2, with two 0.01; the sum over the cells, in per
//!   cent of their number. A sphere covered evenly goes to 0.
//! - **variance**: the standard deviation of `d` over its mean: how much the field's magnitude varies.
//! - **wobble**: the mean over the visited cells of (the cell's mean reading − the field's magnitude along the
//!   cell's centre direction), its length over the magnitude: uneven coverage or a centre the readings do not
//!   support.
//! - **fit error**: the RMS of the sphere's algebraic misfit `d² − R²` over `2·R²` (Freescale's fit error, which
//!   MotionCal shows): how far the readings are from one sphere.

use magcal_calib::directions::{DirectionCoverage, SETTLE_READINGS};

/// The four figures, per cent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quality {
    /// Directions not yet (or barely) visited, %.
    pub gaps_pct: f64,
    /// Spread of the field's magnitude, %.
    pub variance_pct: f64,
    /// Offset of the cells' means from the sphere, %.
    pub wobble_pct: f64,
    /// Misfit of the sphere, %.
    pub fit_error_pct: f64,
}

/// The limits below which MotionCal enables its "Send Cal" button.
pub const MOTIONCAL_LIMITS: Quality = Quality {
    gaps_pct: 15.0,
    variance_pct: 4.5,
    wobble_pct: 4.0,
    fit_error_pct: 5.0,
};

/// The figures are shown once the readings' distances from the sphere's centre spread by less than this fraction
/// of their mean (a sensor's soft iron and gain errors, a magnet passing, stay well below).
pub const MEANINGFUL_SPREAD: f64 = 0.25;

/// What an empty cell, one with one reading, and one with two add to the gaps (MotionCal's weights).
const GAP_WEIGHTS: [f64; 3] = [1.0, 0.2, 0.01];

impl Quality {
    /// The figures of the readings so far; `None` until they mean something: [`SETTLE_READINGS`] readings lying on
    /// the sphere fitted to them within [`MEANINGFUL_SPREAD`] (before, the sphere is one through a cluster of
    /// readings at rest or a short arc, a few µT across, and the figures run to thousands of per cent).
    pub fn of(coverage: &DirectionCoverage) -> Option<Quality> {
        let sphere = coverage.sphere()?;
        let r = coverage.radial();
        if r.n < SETTLE_READINGS as u64 || sphere.radius_ut <= 0.0 {
            return None;
        }
        let n = r.n as f64;
        let cells = coverage.cells();
        let gaps: f64 = cells
            .iter()
            .map(|c| GAP_WEIGHTS.get(c.count as usize).copied().unwrap_or(0.0))
            .sum();
        let mean_ut = r.sum_ut / n;
        let sd_ut = (r.sum_sq_ut2 / n - mean_ut * mean_ut).max(0.0).sqrt();
        let radius = sphere.radius_ut;
        let mut offset = [0.0; 3];
        let mut visited = 0usize;
        for (cell, c) in cells.iter().enumerate().filter(|(_, c)| c.count > 0) {
            let centre = coverage.grid().centre(cell);
            for k in 0..3 {
                offset[k] += c.sum_ut[k] / f64::from(c.count) - radius * centre[k];
            }
            visited += 1;
        }
        let wobble_ut = (offset.iter().map(|o| o * o).sum::<f64>()).sqrt() / visited.max(1) as f64;
        if sd_ut > MEANINGFUL_SPREAD * mean_ut {
            return None;
        }
        Some(Quality {
            gaps_pct: 100.0 * gaps / cells.len() as f64,
            variance_pct: 100.0 * sd_ut / mean_ut,
            wobble_pct: 100.0 * wobble_ut / radius,
            fit_error_pct: 100.0 * (r.misfit_sq_ut4 / n).sqrt() / (2.0 * radius * radius),
        })
    }

    /// Whether every figure is below MotionCal's limit (gaps and wobble only if `coverage_counts`: the cube
    /// routine's poses are few directions by design).
    pub fn within_motioncal_limits(&self, coverage_counts: bool) -> bool {
        let l = MOTIONCAL_LIMITS;
        self.variance_pct < l.variance_pct
            && self.fit_error_pct < l.fit_error_pct
            && (!coverage_counts || (self.gaps_pct < l.gaps_pct && self.wobble_pct < l.wobble_pct))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Readings around `centre`, turning through every direction (a scrambled spiral), with the magnitude varying
    /// by `ripple` (a fraction) with the direction.
    fn turning(n: usize, centre: [f64; 3], ripple: f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let j = (i * 7919) % n;
                let z = -1.0 + 2.0 * (j as f64 + 0.5) / n as f64;
                let phi = j as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                let m = 50.0 * (1.0 + ripple * (3.0 * phi).sin());
                [
                    centre[0] + m * r * phi.cos(),
                    centre[1] + m * r * phi.sin(),
                    centre[2] + m * z,
                ]
            })
            .collect()
    }

    fn quality(readings: &[[f64; 3]]) -> Quality {
        let mut c = DirectionCoverage::new();
        readings.iter().for_each(|m| {
            c.add(*m);
        });
        c.finish();
        Quality::of(&c).unwrap()
    }

    #[test]
    fn a_whole_sphere_passes_motioncals_limits_and_a_cap_has_gaps_and_wobble() {
        let q = quality(&turning(5000, [20.0, -10.0, 30.0], 0.0));
        assert!(
            q.gaps_pct < 1.0 && q.variance_pct < 1e-6 && q.fit_error_pct < 1e-6,
            "{q:?}"
        );
        assert!(q.wobble_pct < 0.1, "{q:?}");
        assert!(q.within_motioncal_limits(true));
        let cap: Vec<[f64; 3]> = turning(5000, [0.0; 3], 0.0)
            .into_iter()
            .filter(|m| m[2] > 10.0)
            .collect();
        let q = quality(&cap);
        assert!((55.0..70.0).contains(&q.gaps_pct), "{q:?}");
        // The cells' means fall short of the sphere on one side only: an offset along the cap's axis.
        assert!(
            q.wobble_pct > 0.5 && !q.within_motioncal_limits(true),
            "{q:?}"
        );
        assert!(q.within_motioncal_limits(false), "{q:?}");
    }

    #[test]
    fn a_varying_magnitude_shows_in_variance_and_fit_error() {
        let q = quality(&turning(5000, [5.0, 5.0, 5.0], 0.08));
        // A ±8 % sine ripple: 8/√2 = 5.7 % RMS.
        assert!((q.variance_pct - 5.7).abs() < 0.5, "{q:?}");
        assert!((q.fit_error_pct - 5.7).abs() < 1.0, "{q:?}");
        assert!(!q.within_motioncal_limits(true));
    }

    #[test]
    fn no_figures_before_the_readings_determine_a_sphere() {
        let mut c = DirectionCoverage::new();
        c.add([1.0, 2.0, 3.0]);
        assert_eq!(Quality::of(&c), None);
    }

    /// Issue 34: a sensor held still, then barely moved, gives a sphere a µT across through its noise, and figures
    /// of "fit error 35169.6 %": none are shown until the readings lie on one sphere.
    #[test]
    fn no_figures_from_a_sphere_through_a_cluster_of_readings() {
        let mut c = DirectionCoverage::new();
        // 500 readings within 1.5 µT of one field (on the sphere to come), as at rest with noise and a tremor.
        let mut state = 12345u64;
        let mut noise = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..500 {
            c.add([
                20.0 + 3.0 * noise(),
                -10.0 + 3.0 * noise(),
                80.0 + 3.0 * noise(),
            ]);
        }
        assert!(c.sphere().is_some(), "the cluster determines a sphere");
        assert_eq!(Quality::of(&c), None);
        for m in turning(1000, [20.0, -10.0, 30.0], 0.0) {
            c.add(m);
        }
        c.finish();
        assert!(Quality::of(&c).is_some());
    }
}
