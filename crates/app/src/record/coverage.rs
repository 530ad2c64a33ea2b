//! The live coverage map: which directions of the field the recorded samples cover, by the one definition the fit
//! uses too ([`DirectionCoverage`]: the cells of the sphere of directions around the readings' own sphere, a
//! magnet's readings left out), drawn as the two hemispheres.

use std::fmt::Write as _;

use magcal_calib::directions::DirectionCoverage;

/// The coverage of the recorded samples, drawn.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CoverageMap {
    directions: DirectionCoverage,
}

impl CoverageMap {
    /// An empty map.
    pub fn new() -> CoverageMap {
        CoverageMap::default()
    }

    /// Adds a recorded raw reading, µT; returns whether it counts (not off the settled sphere: a magnet near).
    pub fn add(&mut self, raw_ut: [f64; 3]) -> bool {
        self.directions.add(raw_ut)
    }

    /// Counts the cells once more around the final sphere: the figure the fit gives for the same rows.
    pub fn finish(&mut self) {
        self.directions.finish();
    }

    /// The coverage, reading by reading.
    pub fn directions(&self) -> &DirectionCoverage {
        &self.directions
    }

    /// The fraction of the sphere of directions covered, 0–1.
    pub fn fraction(&self) -> f64 {
        self.directions.fraction()
    }

    /// Whether the direction of `d` (relative to the centre) was visited.
    fn visited(&self, d: [f64; 3]) -> bool {
        let c = &self.directions;
        c.grid()
            .cell(d)
            .is_some_and(|cell| c.cells()[cell].count > 0)
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
    fn a_full_sphere_around_an_offset_is_drawn_full_and_half_is_half() {
        let mut m = CoverageMap::new();
        for p in fibonacci_sphere(3000, 50.0, [30.0, -20.0, 10.0]) {
            m.add(p);
        }
        assert!(m.fraction() > 0.99, "{}", m.fraction());
        assert!(!m.render(4).contains('.'));
        let mut half = CoverageMap::new();
        for p in fibonacci_sphere(3000, 50.0, [0.0; 3])
            .into_iter()
            .filter(|p| p[2] > 0.0)
        {
            half.add(p);
        }
        let text = half.render(4);
        assert_eq!(text.lines().count(), 1 + 9);
        // The +Z pole (the left disk's centre) is seen, the −Z pole (the right disk's) is not.
        let middle: Vec<char> = text.lines().nth(5).unwrap().chars().collect();
        assert_eq!((middle[8], middle[17 + 3 + 8]), ('#', '.'), "{text}");
        assert!(text.contains('#') && text.contains('.'));
    }
}
