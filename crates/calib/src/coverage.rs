//! Does a recording span the three dimensions? Checked before fitting, with advice when it does not.
//!
//! The spread of the raw readings is measured along the principal directions of their covariance. A rotation about a
//! single axis keeps the field's component along that axis constant, so the readings lie in a plane and neither the
//! vector nor the scalar fit can observe offset and scale along the plane's normal.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// A principal spread below this fraction of the largest is refused.
pub const REFUSE_RATIO: f64 = 0.1;
/// A principal spread below this fraction of the largest gets a warning.
pub const WARN_RATIO: f64 = 0.3;
/// Below this largest spread (µT) the sensor did not rotate at all.
pub(crate) const STILL_SPREAD_UT: f64 = 1.0;

/// The spread of the readings along their principal directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coverage {
    /// Standard deviation of the readings along each principal direction, µT, largest first.
    pub spread_ut: [f64; 3],
    /// The principal directions, unit vectors in sensor axes, in the same order.
    pub directions: [[f64; 3]; 3],
}

impl Coverage {
    /// Measures the spread of raw readings (µT), summed on all threads.
    pub fn of(raw_ut: &[[f64; 3]]) -> Coverage {
        let n = raw_ut.len().max(1) as f64;
        let sum = |r: std::ops::Range<usize>| {
            raw_ut[r]
                .iter()
                .fold(Vector3::zeros(), |acc, m| acc + Vector3::from(*m))
        };
        let mean = crate::chunks::fold(raw_ut.len(), sum, |a, b| a + b).unwrap_or_default() / n;
        let products = |r: std::ops::Range<usize>| {
            raw_ut[r].iter().fold(Matrix3::zeros(), |acc, m| {
                let d = Vector3::from(*m) - mean;
                acc + d * d.transpose()
            })
        };
        let cov = crate::chunks::fold(raw_ut.len(), products, |a, b| a + b).unwrap_or_default() / n;
        Coverage::from_covariance(&cov)
    }

    /// The spread along the principal directions of the readings' covariance matrix (µT²).
    pub(crate) fn from_covariance(cov: &Matrix3<f64>) -> Coverage {
        let eig = SymmetricEigen::new(*cov);
        let mut order = [0, 1, 2];
        order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
        Coverage {
            spread_ut: order.map(|i| eig.eigenvalues[i].max(0.0).sqrt()),
            directions: order.map(|i| {
                let v = eig.eigenvectors.column(i);
                // Sign: make the largest component positive, so messages read "+Z" rather than "−Z".
                let s = v[v.iamax()].signum();
                [v[0] * s, v[1] * s, v[2] * s]
            }),
        }
    }

    /// The weakest spread relative to the strongest (1 for a full sphere, 0 for a plane).
    pub fn ratio(&self) -> f64 {
        if self.spread_ut[0] > 0.0 {
            self.spread_ut[2] / self.spread_ut[0]
        } else {
            0.0
        }
    }

    /// Refuses coverage too poor to fit, saying which direction is unobserved and how to rotate.
    pub fn check(&self) -> Result<(), CoverageError> {
        let [s0, s1, s2] = self.spread_ut;
        if s0 < STILL_SPREAD_UT {
            return Err(CoverageError::Still { spread_ut: s0 });
        }
        if s1 < REFUSE_RATIO * s0 {
            return Err(CoverageError::OneDirection {
                observed: self.directions[0],
                spread_ut: [s0, s1],
            });
        }
        if s2 < REFUSE_RATIO * s0 {
            return Err(CoverageError::Planar {
                unobserved: self.directions[2],
                spread_ut: s2,
                largest_ut: s0,
            });
        }
        Ok(())
    }

    /// A warning when the weakest direction is observed, but poorly.
    pub fn warning(&self) -> Option<String> {
        (self.ratio() < WARN_RATIO).then(|| {
            format!(
                "coverage is thin along {} (spread {:.1} µT against {:.1} µT): uncertainties along it are large; \
                 {}",
                describe(self.directions[2]),
                self.spread_ut[2],
                self.spread_ut[0],
                advice(self.directions[2])
            )
        })
    }
}

/// Coverage too poor for any fit.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CoverageError {
    /// The readings hardly vary: the sensor was not rotated.
    #[error(
        "the readings hardly vary (spread {spread_ut:.2} µT): the sensor was not rotated. \
         Turn it through all orientations (every face up and down) while recording."
    )]
    Still {
        /// Largest spread, µT.
        spread_ut: f64,
    },
    /// The readings vary along a single direction only.
    #[error(
        "the readings vary along one direction only ({}; spreads {:.1} and {:.1} µT): the sensor barely rotated. \
         Turn it through all orientations (every face up and down) while recording.",
        describe(*observed), spread_ut[0], spread_ut[1]
    )]
    OneDirection {
        /// The one direction observed, sensor axes.
        observed: [f64; 3],
        /// The two largest spreads, µT.
        spread_ut: [f64; 2],
    },
    /// The readings lie in a plane: a rotation about one axis.
    #[error(
        "planar rotation: the readings barely vary along {} (spread {:.2} µT against {:.1} µT), so offset and \
         scale along it are unobserved. The sensor turned about that axis only; {}",
        describe(*unobserved), spread_ut, largest_ut, advice(*unobserved)
    )]
    Planar {
        /// The unobserved direction (the rotation axis), sensor axes.
        unobserved: [f64; 3],
        /// Spread along it, µT.
        spread_ut: f64,
        /// Largest spread, µT.
        largest_ut: f64,
    },
}

/// "sensor axis ≈ +Z" for a direction close to an axis, the vector otherwise.
pub fn describe(d: [f64; 3]) -> String {
    let k = (0..3)
        .max_by(|&i, &j| d[i].abs().total_cmp(&d[j].abs()))
        .unwrap_or(0);
    let axis = ["X", "Y", "Z"][k];
    let sign = if d[k] >= 0.0 { "+" } else { "−" };
    if d[k].abs() > 0.95 {
        format!("sensor axis ≈ {sign}{axis}")
    } else {
        format!("sensor direction [{:.2}, {:.2}, {:.2}]", d[0], d[1], d[2])
    }
}

fn advice(d: [f64; 3]) -> String {
    format!(
        "also tip the sensor so that {} points along and against the field (lay it on its side and rotate again), \
         or use the cube24 routine.",
        describe(d).replace("sensor axis ≈ ", "")
    )
}

/// A grid of equal-area cells on the sphere of directions: latitude bands of equal height (equal area, by
/// Archimedes' hat-box theorem), each cut into the same number of longitude cells.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereGrid {
    bands: usize,
    per_band: usize,
    /// The pseudo-angle ([`pseudo_angle`]) of each longitude boundary but the first, in order.
    boundaries: Vec<f64>,
    /// The longitude cell of each of [`LONGITUDE_SLOTS`] equal slots of the pseudo-angle's range, or
    /// [`NEAR_BOUNDARY`] for a slot a boundary comes near.
    slots: Vec<u16>,
}

/// Slots of the pseudo-angle's range, −2 to 2, in [`SphereGrid`]'s table of longitude cells.
const LONGITUDE_SLOTS: usize = 1024;

/// A slot with a boundary in it or near it (the wrap at ±2 included): its longitudes are found the long way.
const NEAR_BOUNDARY: u16 = u16::MAX;

/// The slot of a finite pseudo-angle (`LONGITUDE_SLOTS` at 2).
fn slot(p: f64) -> usize {
    ((p + 2.0) * (LONGITUDE_SLOTS as f64 / 4.0)) as usize
}

/// A function of the direction `(x, y)` that increases with `atan2(y, x)` from −2 at −π to 2 at π, without a
/// transcendental function.
fn pseudo_angle(x: f64, y: f64) -> f64 {
    (1.0 - x / (x.abs() + y.abs())).copysign(y)
}

/// A pseudo-angle this close to a boundary's is decided by `atan2`, exactly as the grid is defined.
const BOUNDARY_MARGIN: f64 = 1e-9;

impl SphereGrid {
    /// A grid of about `cells` cells (`bands = round(√(cells/2))`, as many cells per band as keeps the total near
    /// `cells`: 98 for 100).
    pub fn new(cells: usize) -> SphereGrid {
        let bands = ((cells as f64 / 2.0).sqrt().round() as usize).max(1);
        let per_band = ((cells as f64 / bands as f64).round() as usize).max(1);
        let boundaries: Vec<f64> = (1..per_band)
            .map(|k| {
                let lon = k as f64 * std::f64::consts::TAU / per_band as f64 - std::f64::consts::PI;
                pseudo_angle(lon.cos(), lon.sin())
            })
            .collect();
        // A slot is decided by the table only if every pseudo-angle in it, give or take twice the margin (far more
        // than the rounding of `slot`), is clear of every boundary: the long way would find the same cell.
        let width = 4.0 / LONGITUDE_SLOTS as f64;
        let margin = 2.0 * BOUNDARY_MARGIN;
        let slots = (0..LONGITUDE_SLOTS)
            .map(|i| {
                let (lo, hi) = (-2.0 + i as f64 * width, -2.0 + (i + 1) as f64 * width);
                let near = [-2.0, 2.0]
                    .iter()
                    .chain(&boundaries)
                    .any(|b| *b > lo - margin && *b < hi + margin);
                let cell = boundaries.partition_point(|b| *b <= lo);
                match u16::try_from(cell) {
                    Ok(c) if !near && c != NEAR_BOUNDARY => c,
                    _ => NEAR_BOUNDARY,
                }
            })
            .collect();
        SphereGrid {
            bands,
            per_band,
            boundaries,
            slots,
        }
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.bands * self.per_band
    }

    /// Always false: a grid has at least one cell.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The cell of a direction (any length); `None` for a zero or non-finite vector.
    pub fn cell(&self, d: [f64; 3]) -> Option<usize> {
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if !(n.is_finite() && n > 0.0) {
            return None;
        }
        let z = (d[2] / n).clamp(-1.0, 1.0);
        let band = (((z + 1.0) / 2.0 * self.bands as f64) as usize).min(self.bands - 1);
        Some(band * self.per_band + self.longitude_cell(d[0], d[1]))
    }

    /// The longitude cell of `(x, y)`: `⌊(atan2(y, x) + π)/2π · per_band⌋`, from the table of slots of the
    /// pseudo-angle, or the long way ([`SphereGrid::longitude_cell_searched`]) in a slot a boundary comes near.
    fn longitude_cell(&self, x: f64, y: f64) -> usize {
        let p = pseudo_angle(x, y);
        if p.is_finite()
            && let Some(&cell) = self.slots.get(slot(p))
            && cell != NEAR_BOUNDARY
        {
            return usize::from(cell);
        }
        self.longitude_cell_searched(x, y, p)
    }

    /// The longitude cell of `(x, y)` with pseudo-angle `p`, found by comparing `p` with the boundaries', and by
    /// `atan2` itself near one of them (or near ±π, or without a horizontal part).
    fn longitude_cell_searched(&self, x: f64, y: f64, p: f64) -> usize {
        let cell = self.boundaries.partition_point(|b| *b <= p);
        // The boundaries either side (±2 at the ends, where the longitude wraps).
        let below = cell.checked_sub(1).map_or(-2.0, |k| self.boundaries[k]);
        let above = self.boundaries.get(cell).copied().unwrap_or(2.0);
        let near = |b: f64| (p - b).abs() < BOUNDARY_MARGIN;
        if !p.is_finite() || near(below) || near(above) {
            let lon = y.atan2(x) + std::f64::consts::PI;
            return ((lon / std::f64::consts::TAU * self.per_band as f64) as usize)
                .min(self.per_band - 1);
        }
        cell
    }

    /// The centre of cell `cell` (a unit vector): the middle of its band in z, of its longitudes in azimuth.
    pub fn centre(&self, cell: usize) -> [f64; 3] {
        let (band, k) = (cell / self.per_band, cell % self.per_band);
        let z = -1.0 + (2.0 * band as f64 + 1.0) / self.bands as f64;
        let lon =
            (k as f64 + 0.5) * std::f64::consts::TAU / self.per_band as f64 - std::f64::consts::PI;
        let r = (1.0 - z * z).max(0.0).sqrt();
        [r * lon.cos(), r * lon.sin(), z]
    }
}

/// Weights that keep any cell of direction from outweighing the rest: each sample's `base` weight, scaled down in a
/// cell whose total exceeds twice the median occupied cell's so that it holds no more (MotionCal and ArduPilot thin
/// their samples by such cells; a still stretch is one direction, however long). `cell` is each sample's cell of a
/// grid of `cells` cells.
pub fn capped_cell_weights(cell: &[usize], base: &[f64], cells: usize) -> Vec<f64> {
    // Each chunk's totals per cell, merged in order; the weights on all threads.
    let totals = |r: std::ops::Range<usize>| {
        let mut count = vec![0.0; cells];
        for (c, w) in cell[r.clone()].iter().zip(&base[r]) {
            count[*c] += w;
        }
        count
    };
    let count = crate::chunks::fold(cell.len(), totals, |mut x, y| {
        x.iter_mut().zip(&y).for_each(|(x, y)| *x += y);
        x
    })
    .unwrap_or_else(|| vec![0.0; cells]);
    let mut occupied: Vec<f64> = count.iter().copied().filter(|c| *c > 0.0).collect();
    if occupied.is_empty() {
        return base.to_vec();
    }
    let mid = occupied.len() / 2;
    let cap = 2.0 * *occupied.select_nth_unstable_by(mid, f64::total_cmp).1;
    crate::chunks::map(cell.len(), |i| base[i] * (cap / count[cell[i]]).min(1.0))
}

/// Fraction of the sphere of directions visited, on a [`SphereGrid`] of about `cells` equal-area cells.
pub fn sphere_fraction(directions: impl IntoIterator<Item = [f64; 3]>, cells: usize) -> f64 {
    let grid = SphereGrid::new(cells);
    let mut seen = vec![false; grid.len()];
    for d in directions {
        if let Some(c) = grid.cell(d) {
            seen[c] = true;
        }
    }
    seen.iter().filter(|s| **s).count() as f64 / grid.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turntable(axis_tilt_deg: f64) -> Vec<[f64; 3]> {
        // Field 50 µT at 60° inclination; the sensor turns about its Z axis, tilted by `axis_tilt_deg`.
        (0..720)
            .map(|i| {
                let a = (i as f64 / 2.0).to_radians();
                let (h, v) = (25.0, 43.3);
                let tilt = axis_tilt_deg.to_radians();
                let x = h * a.cos();
                let y = h * a.sin();
                [
                    x,
                    y * tilt.cos() - v * tilt.sin(),
                    y * tilt.sin() + v * tilt.cos() + 5.0,
                ]
            })
            .collect()
    }

    #[test]
    fn a_turntable_rotation_is_refused_naming_the_axis() {
        let err = Coverage::of(&turntable(0.0)).check().unwrap_err();
        match &err {
            CoverageError::Planar { unobserved, .. } => assert!(unobserved[2].abs() > 0.99),
            other => panic!("{other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.contains("planar rotation") && msg.contains("≈ +Z"),
            "{msg}"
        );
        assert!(msg.contains("tip the sensor"), "{msg}");
    }

    #[test]
    fn a_still_sensor_and_a_line_are_refused() {
        let still = vec![[10.0, 20.0, 30.0]; 100];
        assert!(matches!(
            Coverage::of(&still).check(),
            Err(CoverageError::Still { .. })
        ));
        let line: Vec<[f64; 3]> = (0..100)
            .map(|i| [i as f64, 0.01 * (i % 3) as f64, 0.0])
            .collect();
        assert!(matches!(
            Coverage::of(&line).check(),
            Err(CoverageError::OneDirection { .. })
        ));
    }

    #[test]
    fn the_table_of_longitudes_gives_the_cells_of_the_search() {
        // Directions at every slot's edges and just either side (pseudo-angle p on the diamond |x| + |y| = 1), and
        // around the sphere, on grids of several sizes.
        let on_diamond = |p: f64| {
            let x = 1.0 - p.abs();
            (x, (1.0 - x.abs()).copysign(p))
        };
        for cells in [8, 100, 1000, 5000] {
            let grid = SphereGrid::new(cells);
            let mut cases = Vec::new();
            for i in 0..=LONGITUDE_SLOTS {
                let edge = -2.0 + 4.0 * i as f64 / LONGITUDE_SLOTS as f64;
                for step in [-1e-9, -1e-15, 0.0, 1e-15, 1e-9, 1e-3] {
                    cases.push(on_diamond((edge + step).clamp(-2.0, 2.0)));
                }
            }
            cases.extend((0..20_000).map(|i| {
                let a = i as f64 * 2.399963;
                (a.cos() * (0.1 + (i % 5) as f64), a.sin())
            }));
            for (x, y) in cases {
                let p = pseudo_angle(x, y);
                assert_eq!(
                    grid.longitude_cell(x, y),
                    grid.longitude_cell_searched(x, y, p),
                    "{cells} cells: ({x}, {y})"
                );
            }
            // Most slots are decided by the table.
            let table = grid.slots.iter().filter(|s| **s != NEAR_BOUNDARY).count();
            assert!(
                table > LONGITUDE_SLOTS / 2 || cells > 1000,
                "{cells}: {table}"
            );
        }
    }

    #[test]
    fn longitude_cells_are_those_of_atan2() {
        let grid = SphereGrid::new(100);
        let by_atan2 = |x: f64, y: f64| {
            let lon = y.atan2(x) + std::f64::consts::PI;
            ((lon / std::f64::consts::TAU * grid.per_band as f64) as usize).min(grid.per_band - 1)
        };
        let mut cases = vec![
            (1.0, 0.0),
            (1.0, -0.0),
            (-1.0, 0.0),
            (-1.0, -0.0),
            (0.0, 1.0),
            (0.0, -1.0),
        ];
        // Every boundary, and just either side of it.
        for k in 0..=grid.per_band {
            let lon =
                k as f64 * std::f64::consts::TAU / grid.per_band as f64 - std::f64::consts::PI;
            for step in [-1e-7, -1e-12, 0.0, 1e-12, 1e-7] {
                cases.push(((lon + step).cos(), (lon + step).sin()));
            }
        }
        cases.extend((0..10_000).map(|i| {
            let a = i as f64 * 2.399963;
            (
                a.cos() * (1.0 + (i % 7) as f64),
                a.sin() * (1.0 + (i % 7) as f64),
            )
        }));
        for (x, y) in cases {
            assert_eq!(grid.longitude_cell(x, y), by_atan2(x, y), "({x}, {y})");
        }
    }

    #[test]
    fn every_cell_centre_lies_in_its_cell() {
        let grid = SphereGrid::new(100);
        for cell in 0..grid.len() {
            let c = grid.centre(cell);
            assert!((c.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
            assert_eq!(grid.cell(c), Some(cell));
        }
    }

    #[test]
    fn a_full_sphere_passes_without_warning() {
        let pts: Vec<[f64; 3]> = (0..2000)
            .map(|i| {
                let z = -1.0 + 2.0 * (i as f64 + 0.5) / 2000.0;
                let phi = i as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                [50.0 * r * phi.cos(), 50.0 * r * phi.sin(), 50.0 * z]
            })
            .collect();
        let c = Coverage::of(&pts);
        assert!(c.check().is_ok() && c.warning().is_none());
        assert!((sphere_fraction(pts.iter().copied(), 100) - 1.0).abs() < 1e-9);
        let north: Vec<[f64; 3]> = pts.iter().copied().filter(|p| p[2] > 0.0).collect();
        let f = sphere_fraction(north, 100);
        assert!((f - 0.5).abs() < 0.08, "{f}");
        // Equal-area cells: uniformly spread directions fill every cell about equally.
        let grid = SphereGrid::new(100);
        assert_eq!(grid.len(), 98);
        let mut counts = vec![0usize; grid.len()];
        for p in &pts {
            counts[grid.cell(*p).unwrap()] += 1;
        }
        let (lo, hi) = (counts.iter().min().unwrap(), counts.iter().max().unwrap());
        assert!(
            *lo >= 15 && *hi <= 26,
            "{lo}..{hi} points per cell for 2000/98 = 20.4"
        );
    }
}
