//! What the recording's own noise makes by chance, anywhere in it: the one rule every gross span must beat to be a
//! finding.
//!
//! A span's evidence is its excess energy over the noise, `S = Σ (min(|e|²/σ², G²) − d)` over its samples (`e` the
//! residual, `σ` the residual's scale per axis, `d` the residual's dimensions: three, or one for |B|; each sample
//! counted up to the gross threshold `G` = [`crate::robust::GROSS_SIGMA`] scales, beyond which the noise's own tail
//! cannot be measured, since the samples there are the ones in question: one sample is one sample, however far
//! out, and a span is strong by how many of its samples stand out). The noise is measured
//! from the recording itself: the residual of the samples outside every gross span, taken as one series, whose
//! windows of the span's length show what its tails, its quantisation and its autocorrelation make of a window's
//! energy. The chance that the noise makes a window at least as strong *anywhere in the recording* is the tail of
//! those windows' energies (empirical where there are windows that far out, an exponential fitted to the top
//! [`TAIL_SHARE`] beyond), times the number of independent windows of that length in the recording, times the
//! number of lengths searched (window lengths in powers of two). A span whose chance is above [`FALSE_ALARM`] is not
//! a finding: it is a glitch, as is a single sample, and a span shorter than [`GLITCH_S`] (too short to be a field
//! that came and went — a magnet passing a few centimetres from the sensor at a hand's speed takes longer — so one
//! reading's or one reference sample's fault, whatever its size).
//!
//! Derivation and figures: docs/diagnosis.md ("One rule for every finding").

use std::collections::HashMap;
use std::sync::Mutex;

use crate::robust::GROSS_SIGMA;

/// The false-alarm rate per recording a finding is judged at.
pub(crate) const FALSE_ALARM: f64 = 0.01;
/// Spans shorter than this are glitches, whatever their size, s: a magnet passing 3 cm from the sensor at 1 m/s, the
/// fastest a hand moves one past a bench, changes the field over about this long.
pub(crate) const GLITCH_S: f64 = 0.03;
/// The share of the windows' energies the exponential tail is fitted to.
const TAIL_SHARE: f64 = 0.05;
/// Fewest windows a tail is fitted from; with fewer, the noise cannot say what a span of that length is.
const MIN_WINDOWS: usize = 40;

/// The noise of one residual, as the chance of a window's energy.
pub(crate) struct Chance {
    /// Per sample outside every gross span, in order: `|e|²/σ² − d`.
    excess: Vec<f64>,
    /// Prefix sums of `excess`.
    prefix: Vec<f64>,
    /// Samples in the recording.
    samples: usize,
    /// The fitted tail per window length (a power of two): its threshold, its share of windows above it, its mean
    /// excess; `None` when there are too few windows.
    tails: Mutex<HashMap<usize, Option<Tail>>>,
}

/// The exponential tail of the windows' energies of one length.
#[derive(Clone, Copy, Debug)]
struct Tail {
    /// Energies at or above this are in the tail.
    threshold: f64,
    /// The share of windows in the tail.
    share: f64,
    /// Their mean excess over the threshold.
    mean_excess: f64,
}

impl Chance {
    /// The noise of the residual sizes `sizes` (per sample: the residual's norm, or |ρ|) on the samples `clean`, with
    /// the scale `scale` per axis and `dims` dimensions.
    pub(crate) fn of(sizes: &[f64], clean: &[bool], scale: f64, dims: f64) -> Chance {
        let excess: Vec<f64> = sizes
            .iter()
            .zip(clean)
            .filter(|(s, c)| **c && s.is_finite())
            .map(|(s, _)| excess(*s, scale, dims))
            .collect();
        let mut prefix = Vec::with_capacity(excess.len() + 1);
        prefix.push(0.0);
        for x in &excess {
            prefix.push(prefix.last().copied().unwrap_or(0.0) + x);
        }
        Chance {
            excess,
            prefix,
            samples: sizes.len(),
            tails: Mutex::new(HashMap::new()),
        }
    }

    /// The energy of samples `[a, b)` of a residual of sizes `sizes` over the noise (`scale`, `dims` as in [`of`]).
    ///
    /// [`of`]: Chance::of
    pub(crate) fn evidence(sizes: &[f64], (a, b): (usize, usize), scale: f64, dims: f64) -> f64 {
        sizes[a..b]
            .iter()
            .filter(|s| s.is_finite())
            .map(|s| excess(*s, scale, dims))
            .sum()
    }

    /// Whether a span of `len` samples lasting `duration_s` (`None` without time) with energy `evidence` over the
    /// noise is a finding: more than one sample, no shorter than [`GLITCH_S`], and less likely than [`FALSE_ALARM`] to
    /// be made by the noise anywhere in the recording.
    pub(crate) fn is_finding(&self, len: usize, duration_s: Option<f64>, evidence: f64) -> bool {
        len > 1
            && duration_s.is_none_or(|d| d >= GLITCH_S)
            && self.anywhere(len, evidence) < FALSE_ALARM
    }

    /// The chance that the noise makes a window of `len` samples with at least `evidence` anywhere in the
    /// recording, over every window length searched. Zero when the noise is too short a series to tell (the span
    /// is then taken for what it looks like).
    pub(crate) fn anywhere(&self, len: usize, evidence: f64) -> f64 {
        let len = len.max(1).next_power_of_two();
        let Some(tail) = self.tail(len) else {
            return 0.0;
        };
        let per_window = if evidence < tail.threshold {
            1.0
        } else {
            tail.share * (-(evidence - tail.threshold) / tail.mean_excess).exp()
        };
        let windows = (self.samples as f64 / len as f64).max(1.0);
        let lengths = (self.samples.max(2) as f64).log2().ceil();
        (per_window * windows * lengths).min(1.0)
    }

    /// The tail of the windows' energies of length `len` (a power of two), fitted once.
    fn tail(&self, len: usize) -> Option<Tail> {
        if let Some(t) = self.tails.lock().expect("no panic while held").get(&len) {
            return *t;
        }
        let t = self.fit_tail(len);
        self.tails
            .lock()
            .expect("no panic while held")
            .insert(len, t);
        t
    }

    /// Fits the tail of the energies of windows of `len` samples, taken every half window.
    fn fit_tail(&self, len: usize) -> Option<Tail> {
        let n = self.excess.len();
        if n < len {
            return None;
        }
        let step = (len / 2).max(1);
        let mut energies: Vec<f64> = (0..=n - len)
            .step_by(step)
            .map(|a| self.prefix[a + len] - self.prefix[a])
            .collect();
        if energies.len() < MIN_WINDOWS {
            return None;
        }
        let k = ((TAIL_SHARE * energies.len() as f64).ceil() as usize).max(5);
        let m = energies.len();
        let (_, &mut threshold, top) = energies.select_nth_unstable_by(m - k, f64::total_cmp);
        let mean_excess =
            top.iter().map(|e| e - threshold).sum::<f64>() / top.len().max(1) as f64;
        Some(Tail {
            threshold,
            share: k as f64 / m as f64,
            mean_excess: mean_excess.max(f64::MIN_POSITIVE),
        })
    }
}

/// One sample's evidence: its squared size in scales, up to the gross threshold's, less the noise's own.
fn excess(size: f64, scale: f64, dims: f64) -> f64 {
    (size / scale).powi(2).min(GROSS_SIGMA * GROSS_SIGMA) - dims
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal, StudentT};

    use super::*;

    /// Residual norms of `n` samples of three-axis noise drawn by `draw`, unit scale.
    fn sizes(n: usize, mut draw: impl FnMut() -> f64) -> Vec<f64> {
        (0..n)
            .map(|_| (0..3).map(|_| draw().powi(2)).sum::<f64>().sqrt())
            .collect()
    }

    #[test]
    fn the_noise_makes_its_own_largest_windows_often_and_a_field_never() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let s = sizes(20_000, || normal.sample(&mut rng));
        let clean = vec![true; s.len()];
        let chance = Chance::of(&s, &clean, 1.0, 3.0);
        // The noise's own largest window of 16 samples is no finding.
        let largest = (0..s.len() - 16)
            .map(|a| Chance::evidence(&s, (a, a + 16), 1.0, 3.0))
            .fold(f64::MIN, f64::max);
        assert!(!chance.is_finding(16, None, largest), "{}", chance.anywhere(16, largest));
        // A field of 2 σ per axis for 16 samples is (4·3·16 = 192 over the noise's ~0 ± 40).
        assert!(chance.is_finding(16, None, 192.0));
        // A single sample, however large, is a glitch; so is a strong span shorter than a field can be.
        assert!(!chance.is_finding(1, None, 1e6));
        assert!(!chance.is_finding(2, Some(0.02), 1e6));
        assert!(chance.is_finding(2, Some(0.1), 1e6));
    }

    #[test]
    fn heavier_tails_raise_what_a_window_must_beat() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let t = StudentT::new(3.0).unwrap();
        let gauss = sizes(20_000, || normal.sample(&mut rng));
        let heavy = sizes(20_000, || t.sample(&mut rng) / 3f64.sqrt());
        let clean = vec![true; 20_000];
        let (g, h) = (
            Chance::of(&gauss, &clean, 1.0, 3.0),
            Chance::of(&heavy, &clean, 1.0, 3.0),
        );
        assert!(h.anywhere(8, 120.0) > g.anywhere(8, 120.0));
    }
}
