//! The live coverage map: which directions of the field the sensor has seen, on the fitter's grid of cells, drawn as
//! the two hemispheres.

use std::fmt::Write as _;

use magcal_calib::coverage::SphereGrid;
use nalgebra::{Matrix4, Vector4};

/// The grid's nominal cell count, the fitter's (98 equal-area cells).
pub const CELLS: usize = 100;
/// The centre estimate has to move this far (µT) before the cells are counted again from all readings.
const RECENTRE_UT: f64 = 2.0;
/// The centre is estimated again after every this many readings.
const REFIT_EVERY: usize = 25;

/// Coverage of the sphere of field directions, measured from raw readings around a running estimate of their centre
/// (the hard-iron offset, roughly): the least-squares sphere through the readings, `|m|² = 2·c·m + k`, which is
/// linear in the centre `c` and finds it from a cap of the sphere too (the midpoint of each axis' extremes would
/// not, and would overstate the coverage of a half-turned sensor).
#[derive(Clone, Debug, PartialEq)]
pub struct CoverageMap {
    grid: SphereGrid,
    seen: Vec<bool>,
    readings: Vec<[f64; 3]>,
    /// Normal equations of the sphere fit: Σ x·xᵀ and Σ x·|m|² with x = (2m, 1).
    xtx: Matrix4<f64>,
    xty: Vector4<f64>,
    /// The centre the cells were counted around.
    centre_ut: [f64; 3],
}

impl Default for CoverageMap {
    fn default() -> CoverageMap {
        CoverageMap::new()
    }
}

impl CoverageMap {
    /// An empty map of [`CELLS`] cells.
    pub fn new() -> CoverageMap {
        let grid = SphereGrid::new(CELLS);
        let seen = vec![false; grid.len()];
        CoverageMap {
            grid,
            seen,
            readings: Vec::new(),
            xtx: Matrix4::zeros(),
            xty: Vector4::zeros(),
            centre_ut: [0.0; 3],
        }
    }

    /// Adds a raw reading, µT.
    pub fn add(&mut self, raw_ut: [f64; 3]) {
        self.readings.push(raw_ut);
        let x = Vector4::new(2.0 * raw_ut[0], 2.0 * raw_ut[1], 2.0 * raw_ut[2], 1.0);
        self.xtx += x * x.transpose();
        self.xty += x * (raw_ut[0] * raw_ut[0] + raw_ut[1] * raw_ut[1] + raw_ut[2] * raw_ut[2]);
        let n = self.readings.len();
        if n >= REFIT_EVERY
            && n.is_multiple_of(REFIT_EVERY)
            && let Some(centre) = self.fitted_centre()
        {
            let moved = (0..3)
                .map(|k| (centre[k] - self.centre_ut[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            if moved > RECENTRE_UT {
                self.centre_ut = centre;
                self.seen.iter_mut().for_each(|s| *s = false);
                for i in 0..n {
                    self.mark(self.readings[i]);
                }
                return;
            }
        }
        self.mark(raw_ut);
    }

    /// The centre of the least-squares sphere, if the readings determine one.
    fn fitted_centre(&self) -> Option<[f64; 3]> {
        let solution = self.xtx.cholesky()?.solve(&self.xty);
        let centre = [solution[0], solution[1], solution[2]];
        centre.iter().all(|c| c.is_finite()).then_some(centre)
    }

    fn mark(&mut self, raw_ut: [f64; 3]) {
        let d = std::array::from_fn(|k| raw_ut[k] - self.centre_ut[k]);
        if let Some(c) = self.grid.cell(d) {
            self.seen[c] = true;
        }
    }

    /// Readings added.
    pub fn len(&self) -> usize {
        self.readings.len()
    }

    /// Whether no reading was added.
    pub fn is_empty(&self) -> bool {
        self.readings.is_empty()
    }

    /// The fraction of cells visited, 0–1.
    pub fn fraction(&self) -> f64 {
        self.seen.iter().filter(|s| **s).count() as f64 / self.seen.len() as f64
    }

    /// Whether the direction of `d` (relative to the centre) was visited.
    fn visited(&self, d: [f64; 3]) -> bool {
        self.grid.cell(d).is_some_and(|c| self.seen[c])
    }

    /// The two hemispheres side by side (+Z up on the left, −Z on the right), as seen from outside along Z, in an
    /// equal-area projection: `#` visited, `.` not yet. `radius` is in text rows; columns are doubled for the
    /// shape of terminal characters.
    pub fn render(&self, radius: usize) -> String {
        let r = radius.max(2) as f64;
        let rows = 2 * radius + 1;
        let cols = 4 * radius + 1;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:^w$}   {:^w$}",
            "+Z hemisphere",
            "-Z hemisphere",
            w = cols
        );
        for i in 0..rows {
            for (h, sign) in [1.0f64, -1.0].into_iter().enumerate() {
                if h == 1 {
                    out.push_str("   ");
                }
                for j in 0..cols {
                    // Disk coordinates in [-1, 1]; y up the screen.
                    let x = (j as f64 - 2.0 * r) / (2.0 * r);
                    let y = (r - i as f64) / r;
                    let rho2 = x * x + y * y;
                    if rho2 > 1.0 {
                        out.push(' ');
                        continue;
                    }
                    // Lambert azimuthal equal-area: ρ = √2·sin(θ/2) maps the disk onto the hemisphere.
                    let p2 = 2.0 * rho2;
                    let z = 1.0 - p2 / 2.0;
                    let s = (1.0 - p2 / 4.0).max(0.0).sqrt() * std::f64::consts::SQRT_2;
                    // Seen from below, the −Z hemisphere is mirrored in x.
                    let d = [sign * x * s, y * s, sign * z];
                    out.push(if self.visited(d) { '#' } else { '.' });
                }
            }
            out.push('\n');
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fibonacci_sphere(n: usize, radius: f64, centre: [f64; 3]) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let z = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                let phi = i as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                [
                    centre[0] + radius * r * phi.cos(),
                    centre[1] + radius * r * phi.sin(),
                    centre[2] + radius * z,
                ]
            })
            .collect()
    }

    #[test]
    fn the_grid_is_the_fitters_and_every_cell_can_be_hit() {
        let g = SphereGrid::new(CELLS);
        let cap: Vec<[f64; 3]> = fibonacci_sphere(4000, 1.0, [0.0; 3])
            .into_iter()
            .filter(|p| p[0] > 0.3 || p[2] < -0.5)
            .collect();
        let mut seen = vec![false; g.len()];
        for p in &cap {
            seen[g.cell(*p).unwrap()] = true;
        }
        let fraction = seen.iter().filter(|s| **s).count() as f64 / g.len() as f64;
        let fitter = magcal_calib::coverage::sphere_fraction(cap.iter().copied(), CELLS);
        assert!((fraction - fitter).abs() < 1e-12, "{fraction} vs {fitter}");
        let mut hits = vec![0usize; g.len()];
        for p in fibonacci_sphere(100_000, 1.0, [0.0; 3]) {
            hits[g.cell(p).unwrap()] += 1;
        }
        let mean = 100_000.0 / g.len() as f64;
        assert!(
            hits.iter()
                .all(|&h| (h as f64) > 0.5 * mean && (h as f64) < 2.5 * mean),
            "{hits:?}"
        );
        assert_eq!(g.cell([0.0; 3]), None);
    }

    #[test]
    fn a_full_sphere_around_an_offset_is_covered_and_half_is_half() {
        let mut m = CoverageMap::new();
        for p in fibonacci_sphere(3000, 50.0, [30.0, -20.0, 10.0]) {
            m.add(p);
        }
        assert!(m.fraction() > 0.99, "{}", m.fraction());
        assert!(!m.render(4).contains('.'));
        let mut half = CoverageMap::new();
        // The upper half of a sphere with its rim: the centre estimate is still right in x, y, off in z.
        for p in fibonacci_sphere(3000, 50.0, [0.0; 3])
            .into_iter()
            .filter(|p| p[2] > 0.0)
        {
            half.add(p);
        }
        let f = half.fraction();
        assert!((0.3..0.7).contains(&f), "{f}");
        let text = half.render(4);
        assert!(text.contains('#') && text.contains('.'));
        assert_eq!(text.lines().count(), 1 + 9);
    }
}
