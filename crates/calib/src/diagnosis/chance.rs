//! What the recording's own noise makes by chance, anywhere in it: the one rule every gross span must beat to be a
//! finding.
//!
//! A span's evidence is its excess energy over the noise, `S = Σ (min(|e|²/σ², G²) − d)` over its samples (`e` the
//! residual, `σ` the residual's scale per axis, `d` the residual's dimensions: three, or one for |B|; each sample
//! counted up to the gross threshold `G` = [`crate::robust::GROSS_SIGMA`] scales, beyond which the noise's own tail
//! cannot be measured, since the samples there are the ones in question: one sample is one sample, however far
//! out, and a span is strong by how many of its samples stand out).
//!
//! The noise is measured from the recording itself: the residual of every sample outside the findings and their
//! tails ([`judge`]), taken as one series and cut into blocks of 1, 2, 4, 8 and 16 samples. The
//! blocks' energies carry what the noise's tails, its quantisation and its autocorrelation (within a block) make of
//! a stretch's energy; their empirical cumulant generating function `K_m(λ) = ln mean exp(λ·S_block)` bounds the
//! chance that `L/m` blocks in a row (at least four: the longest block that fits four times in the span) add up to
//! at least `S` (Chernoff: `P ≤ exp((L/m)·K_m(λ) − λ·S)` for every
//! `λ > 0`, the smallest over a grid taken). The chance *anywhere in the recording* is that bound times the number of
//! windows of the span's length in the recording, times the number of lengths searched (`log2 n`). A span whose
//! chance is above [`FALSE_ALARM`] is not a finding: it is a glitch, as is a single sample, and a span shorter than
//! [`GLITCH_S`] (too short to be a field that came and went — a magnet passing a few centimetres from the sensor at a
//! hand's speed takes longer — so one reading's or one reference sample's fault, whatever its size).
//!
//! Derivation and figures: docs/diagnosis.md ("One rule for every finding").

use rayon::prelude::*;

use crate::robust::GROSS_SIGMA;

/// The false-alarm rate per recording a finding is judged at.
pub(crate) const FALSE_ALARM: f64 = 0.01;
/// Spans shorter than this are glitches, whatever their size, s: a magnet passing 3 cm from the sensor at 1 m/s, the
/// fastest a hand moves one past a bench, changes the field over about this long.
pub(crate) const GLITCH_S: f64 = 0.03;
/// At most this many rounds of judging the spans against the noise outside the findings ([`judge`]).
const MAX_ROUNDS: usize = 8;
/// The block lengths the noise is cut into, samples: the longest is as far as its autocorrelation is measured.
const BLOCKS: [usize; 5] = [1, 2, 4, 8, 16];
/// Fewest blocks a span is bounded as the sum of (but for spans shorter than this: one sample a block).
const PER_SPAN: usize = 4;
/// Fewest blocks of one length the noise's distribution is measured from; with fewer, the noise cannot say what a
/// span is (it is then taken for what it looks like).
const MIN_BLOCKS: usize = 50;
/// The Chernoff bound's `λ`, per squared scale: `STEPS` values spaced evenly in the logarithm from `LAMBDA.0` to
/// `LAMBDA.1`.
const LAMBDA: (f64, f64) = (1e-3, 4.0);
/// How many values of `λ` the bound is taken over.
const STEPS: usize = 48;

/// The noise of one residual, as the chance of a stretch's energy.
pub(crate) struct Chance {
    /// Per block length in [`BLOCKS`]: the cumulant generating function of the blocks' energies at each `λ` of
    /// [`lambdas`]; `None` with fewer than [`MIN_BLOCKS`] blocks.
    cgf: [Option<Vec<f64>>; BLOCKS.len()],
    /// Samples in the recording.
    samples: usize,
}

/// The grid of `λ` the Chernoff bound is minimised over.
fn lambdas() -> impl Iterator<Item = f64> {
    let (lo, hi) = (LAMBDA.0.ln(), LAMBDA.1.ln());
    (0..STEPS).map(move |j| (lo + (hi - lo) * j as f64 / (STEPS - 1) as f64).exp())
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
        let cgf = BLOCKS.map(|m| {
            let sums: Vec<f64> = excess.chunks_exact(m).map(|c| c.iter().sum()).collect();
            (sums.len() >= MIN_BLOCKS).then(|| {
                let ln_count = (sums.len() as f64).ln();
                // Each λ on its own thread's turn, its sum in sample order: the same on any number of threads.
                let grid: Vec<f64> = lambdas().collect();
                grid.par_iter()
                    .map(|&l| {
                        let top = sums.iter().fold(f64::MIN, |a, &s| a.max(l * s));
                        top + sums.iter().map(|&s| (l * s - top).exp()).sum::<f64>().ln() - ln_count
                    })
                    .collect()
            })
        });
        Chance {
            cgf,
            samples: sizes.len(),
        }
    }

    /// Whether a span of `len` samples lasting `duration_s` (`None` without time) whose energy over the noise, less
    /// its strongest sample's, is `evidence` is a finding: long enough to be one, and its other samples less likely
    /// than [`FALSE_ALARM`] to be made by the noise anywhere in the recording.
    pub(crate) fn is_finding(&self, len: usize, duration_s: Option<f64>, evidence: f64) -> bool {
        long_enough(len, duration_s) && self.anywhere(len - 1, evidence) < FALSE_ALARM
    }

    /// The chance that the noise makes a stretch of `len` samples with at least `evidence` anywhere in the
    /// recording, over every length searched. Zero when the noise is too short a series to tell (the span is then
    /// taken for what it looks like).
    pub(crate) fn anywhere(&self, len: usize, evidence: f64) -> f64 {
        let len = len.max(1);
        // The longest block measured that fits in the span [`PER_SPAN`] times (or one sample): the bound then
        // reaches beyond the largest block the noise made, where its empirical distribution ends.
        let Some((m, cgf)) = BLOCKS.iter().zip(&self.cgf).rev().find_map(|(&m, k)| {
            k.as_ref()
                .filter(|_| m == 1 || m * PER_SPAN <= len)
                .map(|k| (m, k))
        }) else {
            return 0.0;
        };
        let blocks = len as f64 / m as f64;
        let ln_window = lambdas()
            .zip(cgf)
            .map(|(l, k)| blocks * k - l * evidence)
            .fold(0.0, f64::min);
        let windows = (self.samples as f64 / len as f64).max(1.0);
        let lengths = (self.samples.max(2) as f64).log2().ceil();
        (ln_window.exp() * windows * lengths).min(1.0)
    }
}

/// Which of the spans `[a, b)` (lasting `duration_s`) of a residual of sizes `sizes` are findings, judged against
/// the recording's own noise: every sample outside the findings and their tails, its gross samples too (they are
/// the noise's tail, which a span of a few samples is judged by). Judged in rounds: first against the recording
/// outside every span that could be a finding (none must lift what it is judged against; the spans too short to be
/// one are the noise's own), then with the spans that were not put back, until the judgement settles.
pub(crate) fn judge(
    sizes: &[f64],
    spans: &[(usize, usize, Option<f64>)],
    scale: f64,
    dims: f64,
) -> Vec<bool> {
    // Without its strongest sample: no one reading makes a finding, however far out (a spike next to two readings
    // of ordinary noise is no field, and the recording may hold no other spike to measure the noise's tail by).
    let evidence: Vec<f64> = spans
        .iter()
        .map(|&(a, b, _)| {
            let (sum, strongest) = excesses(&sizes[a..b], scale, dims)
                .fold((0.0, 0.0_f64), |(sum, top), x| (sum + x, top.max(x)));
            sum - strongest
        })
        .collect();
    let mut findings: Vec<bool> = spans
        .iter()
        .map(|&(a, b, d)| long_enough(b - a, d))
        .collect();
    // A span too short to be one is no finding whatever the noise: without any other, nothing to measure.
    if !findings.contains(&true) {
        return findings;
    }
    for _ in 0..MAX_ROUNDS {
        let mut noise = vec![true; sizes.len()];
        for (&(a, b, _), _) in spans.iter().zip(&findings).filter(|(_, f)| **f) {
            // A disturbance fades into the noise beyond its span's edges (a magnet's field as the cube of its
            // distance): as long again on either side is its tail, not the noise.
            let margin = b - a;
            noise[a.saturating_sub(margin)..(b + margin).min(sizes.len())].fill(false);
        }
        let chance = Chance::of(sizes, &noise, scale, dims);
        let next: Vec<bool> = spans
            .iter()
            .zip(&evidence)
            .map(|(&(a, b, d), &e)| chance.is_finding(b - a, d, e))
            .collect();
        if next == findings {
            break;
        }
        findings = next;
    }
    findings
}

/// Whether a span of `len` samples lasting `duration_s` could be a finding: more than one sample, and no shorter
/// than [`GLITCH_S`].
fn long_enough(len: usize, duration_s: Option<f64>) -> bool {
    len > 1 && duration_s.is_none_or(|d| d >= GLITCH_S)
}

/// The evidence of each sample of `sizes` with a finite size.
fn excesses(sizes: &[f64], scale: f64, dims: f64) -> impl Iterator<Item = f64> + '_ {
    sizes
        .iter()
        .filter(|s| s.is_finite())
        .map(move |s| excess(*s, scale, dims))
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

    /// The energy of samples `[a, b)` of a residual of sizes `sizes` over the noise.
    fn evidence(sizes: &[f64], (a, b): (usize, usize), scale: f64, dims: f64) -> f64 {
        excesses(&sizes[a..b], scale, dims).sum()
    }

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
            .map(|a| evidence(&s, (a, a + 16), 1.0, 3.0))
            .fold(f64::MIN, f64::max);
        assert!(
            !chance.is_finding(16, None, largest),
            "{}",
            chance.anywhere(16, largest)
        );
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
