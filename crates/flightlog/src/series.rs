//! Time series as logged (time in µs since the autopilot started) and their values between samples: linear for
//! numbers and vectors, the shorter normalised blend for quaternions.

/// A value that can be blended between two samples: `a·(1−w) + b·w`.
pub trait Blend: Copy {
    /// The value a fraction `w` of the way from `a` to `b`.
    fn blend(a: Self, b: Self, w: f64) -> Self;
}

impl Blend for f64 {
    fn blend(a: f64, b: f64, w: f64) -> f64 {
        a + (b - a) * w
    }
}

impl Blend for [f64; 3] {
    fn blend(a: [f64; 3], b: [f64; 3], w: f64) -> [f64; 3] {
        std::array::from_fn(|k| a[k] + (b[k] - a[k]) * w)
    }
}

impl Blend for [f64; 4] {
    /// Normalised linear blend along the shorter arc (q and −q are the same turn).
    fn blend(a: [f64; 4], b: [f64; 4], w: f64) -> [f64; 4] {
        let sign = if (0..4).map(|k| a[k] * b[k]).sum::<f64>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let q: [f64; 4] = std::array::from_fn(|k| a[k] * (1.0 - w) + sign * b[k] * w);
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        q.map(|v| v / n)
    }
}

/// Samples in time order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series<T> {
    /// Time of each sample, µs since the autopilot started, never decreasing.
    pub t_us: Vec<u64>,
    /// The values.
    pub values: Vec<T>,
}

impl<T: Blend> Series<T> {
    /// Appends a sample; one older than the last is dropped (a log's samples of one topic are in time order).
    pub fn push(&mut self, t_us: u64, value: T) {
        if self.t_us.last().is_none_or(|last| t_us >= *last) {
            self.t_us.push(t_us);
            self.values.push(value);
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_us.len()
    }

    /// True without samples.
    pub fn is_empty(&self) -> bool {
        self.t_us.is_empty()
    }

    /// The last value at or before `t_us` (a value held until the next one), `None` before the first.
    pub fn held_at(&self, t_us: u64) -> Option<T> {
        let i = self.t_us.partition_point(|t| *t <= t_us);
        (i > 0).then(|| self.values[i - 1])
    }

    /// The value at `t_us`, blended between the samples around it; `None` outside the series or where the samples
    /// around it are more than `max_gap_us` apart.
    pub fn at(&self, t_us: u64, max_gap_us: u64) -> Option<T> {
        let i = self.t_us.partition_point(|t| *t <= t_us);
        if i == 0 {
            return None;
        }
        let (t0, v0) = (self.t_us[i - 1], self.values[i - 1]);
        if t0 == t_us {
            return Some(v0);
        }
        let (t1, v1) = (*self.t_us.get(i)?, self.values[i]);
        if t1 - t0 > max_gap_us {
            return None;
        }
        Some(T::blend(v0, v1, (t_us - t0) as f64 / (t1 - t0) as f64))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_between_samples_are_blended_and_gaps_are_none() {
        let mut s = Series::default();
        s.push(0, 0.0);
        s.push(10, 1.0);
        s.push(5, 9.0); // out of order: dropped
        s.push(1000, 2.0);
        assert_eq!(s.len(), 3);
        assert_eq!(s.at(5, 100), Some(0.5));
        assert_eq!(s.at(10, 100), Some(1.0));
        assert_eq!(s.at(500, 100), None);
        assert_eq!(s.at(2000, 100_000), None);
        assert_eq!(s.held_at(999), Some(1.0));
        assert_eq!(s.held_at(5000), Some(2.0));
    }

    #[test]
    fn quaternions_blend_along_the_shorter_arc() {
        let a = [1.0, 0.0, 0.0, 0.0];
        let b = [-(0.5f64.sqrt()), 0.0, 0.0, -(0.5f64.sqrt())]; // 90° about z, sign flipped
        let q = <[f64; 4]>::blend(a, b, 0.5);
        let angle = 2.0 * q[0].abs().acos().to_degrees();
        assert!((angle - 45.0).abs() < 1e-9, "{angle}");
    }
}
