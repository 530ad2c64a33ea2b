//! Which directions of the field a recording covers: the one definition of coverage, shared by the recorder (live,
//! as rows are written) and the fit (over the rows of the file, in their order), so both say the same.
//!
//! [`DirectionCoverage`] takes raw readings (µT, sensor axes) one at a time, in the order they were recorded:
//!
//! 1. The least-squares sphere through the accepted readings ([`SphereSums`]) is fitted again every so often; its
//!    centre is the hard-iron offset, roughly.
//! 2. Each accepted reading's direction from that centre falls in a cell of a [`SphereGrid`] of
//!    [`COVERAGE_CELLS`]. The coverage is the fraction of cells holding a reading.
//! 3. Once the sphere is settled — [`SETTLE_READINGS`] readings covering [`SETTLE_FRACTION`] of the cells, their
//!    distances from the centre within [`SETTLE_MISFIT`] of the radius (RMS) — a reading off it
//!    ([`Sphere::departs`]: a magnet or iron near the sensor) is rejected: it enters neither the sphere nor the
//!    cells, so a magnet neither moves the centre nor adds directions.
//!
//! Before it settles, a burst of readings off the sphere the others lie on ([`DirectionCoverage::drop_burst`]: a magnet
//! passed early) is rejected too, once the readings show it.
//!
//! Cells are counted again from all accepted readings whenever the centre or the radius moves by more than
//! [`RECENTRE_UT`], and once more around the final sphere by [`DirectionCoverage::finish`]. Until the readings
//! determine a sphere (they spread in three dimensions, over more than a µT), no direction is known and nothing is
//! covered: a sensor that did not turn, or turned about one axis only, covers 0 %.

use crate::coverage::SphereGrid;
use crate::sphere::{Sphere, SphereSums};

/// The nominal cell count of the grid (98 equal-area cells).
pub const COVERAGE_CELLS: usize = 100;
/// Accepted readings before the sphere may settle…
pub const SETTLE_READINGS: usize = 200;
/// …and the fraction of the cells they must cover: a cap of the sphere does not determine it well enough to judge
/// the readings to come.
pub const SETTLE_FRACTION: f64 = 0.25;
/// …and the readings must lie on it within this fraction of its radius (RMS): a sphere that fits them worse (a
/// short arc, strong soft iron) cannot judge a departure of [`OFF_SPHERE`](crate::sphere::OFF_SPHERE).
pub const SETTLE_MISFIT: f64 = 0.05;
/// The cells are counted again when the sphere's centre or radius moves this far, µT.
pub const RECENTRE_UT: f64 = 2.0;
/// The sphere is fitted again after this many accepted readings at least…
const REFIT_EVERY: usize = 25;
/// …and after this fraction of those so far (so a long recording costs a bounded number of fits).
const REFIT_FRACTION: f64 = 0.02;
/// Concentration steps of [`DirectionCoverage::drop_burst`]…
const BURST_STEPS: usize = 5;
/// …each fitting this share of the readings, those nearest the last sphere…
const BURST_KEEP: f64 = 0.75;
/// …and the readings off the sphere they find are a burst when they lie within a stretch of at most this share of
/// the readings.
const BURST_SHARE: f64 = 0.3;
/// A burst is looked for again once the readings have grown by this share.
const BURST_AGAIN_SHARE: f64 = 0.25;
/// At most this many readings of a recording are looked at by [`recorded_fraction`] (evenly spaced).
pub const RECORDED_READINGS: usize = 100_000;

/// What the readings of one cell add up to, relative to the sphere's centre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CellSums {
    /// Readings in the cell.
    pub count: u32,
    /// Their sum, relative to the centre, µT.
    pub sum_ut: [f64; 3],
}

/// Sums over the counted readings of their distance `d` from the sphere's centre, µT.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RadialSums {
    /// Readings.
    pub n: u64,
    /// Σ d, µT.
    pub sum_ut: f64,
    /// Σ d², µT².
    pub sum_sq_ut2: f64,
    /// Σ (d² − R²)², the algebraic misfit of the sphere of radius R, µT⁴.
    pub misfit_sq_ut4: f64,
}

/// Coverage of the sphere of field directions, reading by reading; see the [module docs](self).
#[derive(Clone, Debug, PartialEq)]
pub struct DirectionCoverage {
    grid: SphereGrid,
    /// The accepted readings, µT.
    readings: Vec<[f64; 3]>,
    sums: SphereSums,
    /// The sphere the cells are counted around; `None` (nothing counted) until the readings determine one.
    sphere: Option<Sphere>,
    settled: bool,
    cells: Vec<CellSums>,
    radial: RadialSums,
    rejected: u64,
    next_refit: usize,
    /// The readings before which no burst is looked for again.
    next_burst: usize,
}

impl Default for DirectionCoverage {
    fn default() -> DirectionCoverage {
        DirectionCoverage::new()
    }
}

impl DirectionCoverage {
    /// Nothing covered yet.
    pub fn new() -> DirectionCoverage {
        let grid = SphereGrid::new(COVERAGE_CELLS);
        let cells = vec![CellSums::default(); grid.len()];
        DirectionCoverage {
            grid,
            readings: Vec::new(),
            sums: SphereSums::default(),
            sphere: None,
            settled: false,
            cells,
            radial: RadialSums::default(),
            rejected: 0,
            next_refit: REFIT_EVERY,
            next_burst: 0,
        }
    }

    /// Takes the next raw reading (µT). Returns whether it was accepted: `false` for one off the settled sphere (and
    /// for a reading that is not finite).
    pub fn add(&mut self, raw_ut: [f64; 3]) -> bool {
        if !raw_ut.iter().all(|v| v.is_finite()) {
            return false;
        }
        if self.settled && self.sphere.is_some_and(|s| s.departs(raw_ut)) {
            self.rejected += 1;
            return false;
        }
        self.readings.push(raw_ut);
        self.sums.add(raw_ut);
        self.mark(raw_ut);
        let n = self.readings.len();
        if n >= self.next_refit {
            self.next_refit = n + REFIT_EVERY.max((REFIT_FRACTION * n as f64) as usize);
            self.refit(false);
            if !self.settled
                && n >= SETTLE_READINGS.max(self.next_burst)
                && self.misfit() > SETTLE_MISFIT
            {
                // Not at every refit: a sphere that never settles costs O(n) in all.
                self.next_burst = n + (BURST_AGAIN_SHARE * n as f64) as usize;
                self.drop_burst();
            }
        }
        if !self.settled
            && n >= SETTLE_READINGS
            && self.fraction() >= SETTLE_FRACTION
            && self.misfit() <= SETTLE_MISFIT
        {
            self.settled = true;
        }
        true
    }

    /// Before the sphere settles, a burst of readings off the sphere the rest lie on (a magnet passed early) keeps it
    /// from settling and bends the centre every other reading is counted around: found by concentration steps (the
    /// sphere of the readings nearest the last one), its readings are rejected, as a settled sphere would have, when
    /// they lie within one stretch of at most [`BURST_SHARE`] of the readings. Readings off it all along (a strong
    /// soft iron) are no burst.
    fn drop_burst(&mut self) {
        let Some(mut sphere) = self.sums.sphere() else {
            return;
        };
        for _ in 0..BURST_STEPS {
            let mut off: Vec<f64> = self
                .readings
                .iter()
                .map(|m| (sphere.distance_ut(*m) - sphere.radius_ut).abs())
                .collect();
            let keep = (BURST_KEEP * off.len() as f64) as usize;
            let cut = *off.select_nth_unstable_by(keep, f64::total_cmp).1;
            let mut sums = SphereSums::default();
            for m in &self.readings {
                if (sphere.distance_ut(*m) - sphere.radius_ut).abs() <= cut {
                    sums.add(*m);
                }
            }
            let Some(next) = sums.sphere() else {
                return;
            };
            sphere = next;
        }
        let off: Vec<usize> = (0..self.readings.len())
            .filter(|&i| sphere.departs(self.readings[i]))
            .collect();
        let (Some(&first), Some(&last)) = (off.first(), off.last()) else {
            return;
        };
        if (last + 1 - first) as f64 > BURST_SHARE * self.readings.len() as f64 {
            return;
        }
        let mut k = 0;
        self.readings.retain(|_| {
            k += 1;
            off.binary_search(&(k - 1)).is_err()
        });
        self.rejected += off.len() as u64;
        self.sums = SphereSums::default();
        for m in &self.readings {
            self.sums.add(*m);
        }
        self.refit(true);
    }

    /// The RMS of the counted readings' distance from the sphere, over its radius (infinite without a sphere).
    fn misfit(&self) -> f64 {
        let (Some(s), r) = (self.sphere, self.radial) else {
            return f64::INFINITY;
        };
        if r.n == 0 {
            return f64::INFINITY;
        }
        let n = r.n as f64;
        let radius = s.radius_ut;
        // Σ (d − R)² = Σ d² − 2R·Σ d + n·R².
        let sq = (r.sum_sq_ut2 - 2.0 * radius * r.sum_ut + n * radius * radius).max(0.0);
        (sq / n).sqrt() / radius
    }

    /// Counts the cells once more around the sphere of all accepted readings (the final figure).
    pub fn finish(&mut self) {
        self.refit(true);
    }

    /// Fits the sphere again; counts the cells again if it moved (or always, with `force`).
    fn refit(&mut self, force: bool) {
        let Some(new) = self.sums.sphere() else {
            return;
        };
        let moved = self.sphere.is_none_or(|old| {
            let shift = (0..3)
                .map(|k| (new.centre_ut[k] - old.centre_ut[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            shift > RECENTRE_UT || (new.radius_ut - old.radius_ut).abs() > RECENTRE_UT
        });
        if moved || force {
            self.sphere = Some(new);
            self.recount();
        }
    }

    fn recount(&mut self) {
        self.cells.fill(CellSums::default());
        self.radial = RadialSums::default();
        for i in 0..self.readings.len() {
            self.mark(self.readings[i]);
        }
    }

    fn mark(&mut self, raw_ut: [f64; 3]) {
        let Some(s) = self.sphere else {
            return;
        };
        let d = s.relative_ut(raw_ut);
        if let Some(c) = self.grid.cell(d) {
            let cell = &mut self.cells[c];
            cell.count += 1;
            (0..3).for_each(|k| cell.sum_ut[k] += d[k]);
        }
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let r = &mut self.radial;
        r.n += 1;
        r.sum_ut += d2.sqrt();
        r.sum_sq_ut2 += d2;
        r.misfit_sq_ut4 += (d2 - s.radius_ut * s.radius_ut).powi(2);
    }

    /// The fraction of cells holding a reading, 0–1.
    pub fn fraction(&self) -> f64 {
        self.cells.iter().filter(|c| c.count > 0).count() as f64 / self.cells.len() as f64
    }

    /// The grid.
    pub fn grid(&self) -> &SphereGrid {
        &self.grid
    }

    /// The readings of each cell (indexed as the grid's cells).
    pub fn cells(&self) -> &[CellSums] {
        &self.cells
    }

    /// The sphere the cells are counted around, once the readings determine one.
    pub fn sphere(&self) -> Option<Sphere> {
        self.sphere
    }

    /// Whether the sphere is settled: readings off it are rejected from now on.
    pub fn is_settled(&self) -> bool {
        self.settled
    }

    /// Distances of the counted readings from the centre (only while there is a sphere).
    pub fn radial(&self) -> RadialSums {
        self.radial
    }

    /// Readings accepted.
    pub fn len(&self) -> usize {
        self.readings.len()
    }

    /// Whether no reading was accepted.
    pub fn is_empty(&self) -> bool {
        self.readings.is_empty()
    }

    /// Readings rejected as off the settled sphere.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }
}

/// The coverage of a recording's raw readings, in their order: [`DirectionCoverage`] over them, finished. A
/// recording of more than [`RECORDED_READINGS`] is thinned evenly to that many.
pub fn recorded_fraction(raw_ut: &[[f64; 3]]) -> f64 {
    fraction_of(raw_ut.len(), |i| Some(raw_ut[i]))
}

/// [`recorded_fraction`] of `n` rows in their order, row `i` giving `reading(i)` (µT; `None` for a row left out:
/// the directions a fit's own rows cover).
pub fn fraction_of(n: usize, reading: impl Fn(usize) -> Option<[f64; 3]>) -> f64 {
    let stride = n.div_ceil(RECORDED_READINGS).max(1);
    let mut coverage = DirectionCoverage::new();
    for m in (0..n).step_by(stride).filter_map(reading) {
        coverage.add(m);
    }
    coverage.finish();
    coverage.fraction()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Readings on a sphere of radius 50 µT around `centre`, turning through every direction (a golden-angle
    /// spiral visited in a scrambled order).
    fn turning(n: usize, centre: [f64; 3]) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let j = (i * 7919) % n;
                let z = -1.0 + 2.0 * (j as f64 + 0.5) / n as f64;
                let phi = j as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                [
                    centre[0] + 50.0 * r * phi.cos(),
                    centre[1] + 50.0 * r * phi.sin(),
                    centre[2] + 50.0 * z,
                ]
            })
            .collect()
    }

    #[test]
    fn a_whole_sphere_around_an_offset_is_covered_and_half_is_half() {
        let offset = [40.0, -30.0, 20.0];
        let all = turning(3000, offset);
        assert!(recorded_fraction(&all) > 0.99);
        let upper: Vec<[f64; 3]> = all.into_iter().filter(|m| m[2] > offset[2]).collect();
        let f = recorded_fraction(&upper);
        assert!((f - 0.5).abs() < 0.08, "{f}");
        let mut c = DirectionCoverage::new();
        upper.iter().for_each(|m| assert!(c.add(*m)));
        c.finish();
        let s = c.sphere().unwrap();
        assert!(
            (0..3).all(|k| (s.centre_ut[k] - offset[k]).abs() < 1e-6),
            "{s:?}"
        );
        assert_eq!(c.fraction(), f);
    }

    #[test]
    fn a_magnet_after_the_sphere_settled_adds_no_direction_and_does_not_move_it() {
        let offset = [30.0, -20.0, 10.0];
        let clean = turning(3000, offset);
        let mut disturbed = clean.clone();
        // 300 readings in a row, half-way through, with 150 µT more along x and 100 µT less along z.
        for m in &mut disturbed[1500..1800] {
            m[0] += 150.0;
            m[2] -= 100.0;
        }
        let mut c = DirectionCoverage::new();
        let accepted = disturbed.iter().filter(|m| c.add(**m)).count();
        assert_eq!((accepted, c.rejected()), (2700, 300));
        c.finish();
        let s = c.sphere().unwrap();
        assert!(
            (0..3).all(|k| (s.centre_ut[k] - offset[k]).abs() < 1e-6),
            "{s:?}"
        );
        let without: Vec<[f64; 3]> = clean[..1500]
            .iter()
            .chain(&clean[1800..])
            .copied()
            .collect();
        assert_eq!(recorded_fraction(&disturbed), recorded_fraction(&without));
    }

    #[test]
    fn a_magnet_before_the_sphere_settled_is_dropped_once_the_readings_show_it() {
        // 150 readings of 300 µT more along x early on (the sphere cannot have settled): it kept the sphere from
        // ever settling, and the coverage around the bent centre stayed at a few per cent for the whole recording.
        let offset = [30.0, -20.0, 10.0];
        let clean = turning(3000, offset);
        let mut disturbed = clean.clone();
        for m in &mut disturbed[100..250] {
            m[0] += 300.0;
        }
        let mut c = DirectionCoverage::new();
        disturbed.iter().for_each(|m| {
            c.add(*m);
        });
        c.finish();
        assert!(c.is_settled());
        assert_eq!(c.rejected(), 150);
        let s = c.sphere().unwrap();
        assert!(
            (0..3).all(|k| (s.centre_ut[k] - offset[k]).abs() < 1e-6),
            "{s:?}"
        );
        let without: Vec<[f64; 3]> = clean[..100].iter().chain(&clean[250..]).copied().collect();
        assert_eq!(c.fraction(), recorded_fraction(&without));
    }

    #[test]
    fn readings_off_a_sphere_all_along_are_no_burst() {
        // An ellipsoid 30 % longer along x than the others: its readings along x lie off the sphere every time the
        // sensor points that way, not in one stretch; none is rejected before the sphere settles.
        let offset = [5.0, 5.0, 5.0];
        let stretched: Vec<[f64; 3]> = turning(3000, [0.0; 3])
            .iter()
            .map(|m| [offset[0] + 1.3 * m[0], offset[1] + m[1], offset[2] + m[2]])
            .collect();
        let mut c = DirectionCoverage::new();
        for m in &stretched[..1000] {
            c.add(*m);
        }
        assert_eq!(c.rejected(), 0);
    }

    #[test]
    fn readings_that_determine_no_sphere_cover_nothing() {
        assert_eq!(recorded_fraction(&[[10.0, 20.0, 30.0]; 50]), 0.0);
        // Turned about z only: a ring, whose sphere is not determined.
        let ring: Vec<[f64; 3]> = (0..720)
            .map(|i| {
                let a = (f64::from(i) / 2.0).to_radians();
                [25.0 * a.cos() + 5.0, 25.0 * a.sin(), 43.0]
            })
            .collect();
        assert_eq!(recorded_fraction(&ring), 0.0);
        // A whole sphere of 0.5 units: gauss read as µT, or a sensor that only shook.
        let small: Vec<[f64; 3]> = turning(2000, [0.0; 3])
            .iter()
            .map(|m| m.map(|v| v / 100.0))
            .collect();
        assert_eq!(recorded_fraction(&small), 0.0);
        assert_eq!(recorded_fraction(&[]), 0.0);
        assert_eq!(recorded_fraction(&[[f64::NAN, 0.0, 1.0]]), 0.0);
    }

    #[test]
    fn the_live_figure_before_finishing_is_close_to_the_final_one() {
        let mut c = DirectionCoverage::new();
        for m in turning(1000, [5.0, 60.0, -40.0]) {
            c.add(m);
        }
        let live = c.fraction();
        c.finish();
        assert!(
            (live - c.fraction()).abs() < 0.03,
            "{live} then {}",
            c.fraction()
        );
        let r = c.radial();
        assert_eq!(r.n, 1000);
        assert!((r.sum_ut / 1000.0 - 50.0).abs() < 1e-6 && r.misfit_sq_ut4 < 1e-6);
    }
}
