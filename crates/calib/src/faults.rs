//! Readings a fault of the sensor's output made, which no calibration model explains:
//! - **Clipped** by the sensor's range: an axis that sits at one value, its extreme over the recording, while the
//!   sensor turns. A real field can hold one component at its largest only while that axis points along the field,
//!   and then the other two components sit near their centre; clipped, the axis stays at its limit while the others
//!   sweep through much of their range. Left in, the clipped samples bend `A` (the tester's recording with `mz`
//!   clipped at 20 µT: A_zz 1.060 against 0.974, 5.9° of heading error where 1.9° was graded) and the diagnosis calls
//!   them magnets.
//! - **Frozen**: the same reading, all three axes to the last digit, [`FROZEN_RUN`] times in a row (a sensor that
//!   stopped converting, a driver that repeats its last value); the diagnosis called one "a constant field of 0.4 µT
//!   while the sensor hardly turned" in a recording graded good.

/// An axis counts as pinned at an extreme when at least this share of the samples hold exactly that value…
pub const MIN_SHARE: f64 = 0.005;
/// …and at least this many samples…
pub const MIN_SAMPLES: usize = 10;
/// …while one of the other two axes spreads (standard deviation) over at least this share of its half-range over
/// the recording: the sensor turned while the axis stood still.
pub const OTHER_SPREAD_SHARE: f64 = 0.2;

/// One axis pinned at one of its extremes.
#[derive(Clone, Debug, PartialEq)]
pub struct Pinned {
    /// 0, 1, 2 for x, y, z (sensor axes).
    pub axis: usize,
    /// The value it is pinned at, in the readings' units.
    pub value: f64,
    /// The samples at it.
    pub samples: usize,
}

/// The axes of `raw` (finite rows) pinned at an extreme while the sensor turned, at most one per axis and end. Two
/// passes, nothing allocated per row.
pub fn pinned(raw: &[[f64; 3]]) -> Vec<Pinned> {
    let finite = |m: &&[f64; 3]| m.iter().all(|v| v.is_finite());
    let (n, ranges) = crate::chunks::fold(
        raw.len(),
        |r| {
            raw[r].iter().filter(finite).fold(
                (0usize, [(f64::INFINITY, f64::NEG_INFINITY); 3]),
                |(n, r), m| {
                    (
                        n + 1,
                        std::array::from_fn(|k| (r[k].0.min(m[k]), r[k].1.max(m[k]))),
                    )
                },
            )
        },
        |(n, a), (m, b)| {
            (
                n + m,
                std::array::from_fn(|k| (a[k].0.min(b[k].0), a[k].1.max(b[k].1))),
            )
        },
    )
    .unwrap_or((0, [(f64::INFINITY, f64::NEG_INFINITY); 3]));
    let enough = MIN_SAMPLES.max((MIN_SHARE * n as f64).ceil() as usize);
    if n < enough {
        return Vec::new();
    }
    // Per axis and end (low, high): the samples at it, and the sums and squares of every axis over them.
    let at = crate::chunks::fold(
        raw.len(),
        |r| {
            let mut at = [[Moments::default(); 2]; 3];
            for m in raw[r].iter().filter(finite) {
                for (axis, ends) in at.iter_mut().enumerate() {
                    let (lo, hi) = ranges[axis];
                    if lo < hi && (m[axis] == lo || m[axis] == hi) {
                        ends[usize::from(m[axis] == hi)].add(m);
                    }
                }
            }
            at
        },
        |mut a, b| {
            for (x, y) in a.iter_mut().flatten().zip(b.iter().flatten()) {
                x.merge(y);
            }
            a
        },
    )
    .unwrap_or_default();
    let mut out = Vec::new();
    for (axis, ends) in at.iter().enumerate() {
        for (end, moments) in ends.iter().enumerate() {
            let others_turned = (0..3).filter(|&k| k != axis).any(|k| {
                let half_range = (ranges[k].1 - ranges[k].0) / 2.0;
                moments.spread(k) > OTHER_SPREAD_SHARE * half_range
            });
            if moments.n >= enough && others_turned {
                out.push(Pinned {
                    axis,
                    value: if end == 1 {
                        ranges[axis].1
                    } else {
                        ranges[axis].0
                    },
                    samples: moments.n,
                });
            }
        }
    }
    out
}

/// Identical readings in a row that make a frozen output: the physical recordings repeat one at most 4 times (host
/// loggers that write a sample twice), and noise makes 25 in a row of a live sensor all but impossible.
pub const FROZEN_RUN: usize = 25;

/// The runs of at least [`FROZEN_RUN`] identical readings in `raw`, as ranges `[start, end)`.
pub fn frozen_runs(raw: &[[f64; 3]]) -> Vec<(usize, usize)> {
    // Most recordings repeat no reading at all: counted on all threads first.
    let repeats = crate::chunks::fold(
        raw.len(),
        |r| r.filter(|&i| i > 0 && raw[i] == raw[i - 1]).count(),
        |a, b| a + b,
    )
    .unwrap_or(0);
    let mut runs = Vec::new();
    if repeats + 1 < FROZEN_RUN {
        return runs;
    }
    let mut start = 0;
    for i in 1..=raw.len() {
        if i == raw.len() || raw[i] != raw[start] {
            if i - start >= FROZEN_RUN {
                runs.push((start, i));
            }
            start = i;
        }
    }
    runs
}

/// Per row of `raw`, whether it holds a pinned value of `pinned`.
pub fn rows_pinned(raw: &[[f64; 3]], pinned: &[Pinned]) -> Vec<bool> {
    raw.iter()
        .map(|m| pinned.iter().any(|p| m[p.axis] == p.value))
        .collect()
}

/// Count, sums and sums of squares of readings.
#[derive(Clone, Copy, Default)]
struct Moments {
    n: usize,
    sum: [f64; 3],
    squares: [f64; 3],
}

impl Moments {
    fn add(&mut self, m: &[f64; 3]) {
        self.n += 1;
        for k in 0..3 {
            self.sum[k] += m[k];
            self.squares[k] += m[k] * m[k];
        }
    }

    fn merge(&mut self, o: &Moments) {
        self.n += o.n;
        for k in 0..3 {
            self.sum[k] += o.sum[k];
            self.squares[k] += o.squares[k];
        }
    }

    /// The standard deviation of axis `k`.
    fn spread(&self, k: usize) -> f64 {
        let n = self.n.max(1) as f64;
        let mean = self.sum[k] / n;
        (self.squares[k] / n - mean * mean).max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Readings of a 50 µT field turned through every direction (a spiral over the sphere), offset by `b`.
    fn sphere(n: usize, b: [f64; 3]) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = i as f64 * 2.399_963;
                [
                    50.0 * r * phi.cos() + b[0],
                    50.0 * r * phi.sin() + b[1],
                    50.0 * z + b[2],
                ]
            })
            .collect()
    }

    #[test]
    fn a_clipped_axis_is_pinned_and_an_unclipped_one_is_not() {
        let clean = sphere(4000, [5.0, -3.0, 10.0]);
        assert!(pinned(&clean).is_empty());
        let clipped: Vec<[f64; 3]> = clean.iter().map(|m| [m[0], m[1], m[2].min(40.0)]).collect();
        let p = pinned(&clipped);
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!((p[0].axis, p[0].value), (2, 40.0));
        let rows = rows_pinned(&clipped, &p);
        assert_eq!(rows.iter().filter(|r| **r).count(), p[0].samples);
        assert!(p[0].samples > 200, "{p:?}");
    }

    #[test]
    fn a_frozen_output_is_a_run_of_identical_readings() {
        let mut rec = sphere(1000, [0.0; 3]);
        let frozen = rec[300];
        rec[300..340].fill(frozen);
        let repeated = rec[600];
        rec[600..604].fill(repeated);
        assert_eq!(frozen_runs(&rec), vec![(300, 340)]);
        assert!(frozen_runs(&sphere(1000, [0.0; 3])).is_empty());
    }

    /// Quantised readings repeat their extreme while the axis points along the field, but the other axes then sit
    /// near their centre: not a clip.
    #[test]
    fn a_rest_along_the_field_is_not_a_clip() {
        let mut rec = sphere(4000, [0.0; 3]);
        rec.extend(std::iter::repeat_n([0.3, -0.2, 50.0], 400));
        let quantised: Vec<[f64; 3]> = rec
            .iter()
            .map(|m| m.map(|v| (v / 0.15).round() * 0.15))
            .collect();
        assert!(pinned(&quantised).is_empty());
    }
}
