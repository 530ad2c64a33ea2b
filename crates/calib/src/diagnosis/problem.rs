//! The problem of a round: the normal equations of the design — the base model's columns and every candidate's —
//! over the included samples, summed per autocorrelation batch on all threads (each batch within one
//! cross-validation block) and merged in order, so that fits on any column subset, blocked cross-validation,
//! absorption, autocorrelation and cluster-robust covariances need no second pass ([`Problem`]).

use nalgebra::DVector;

use crate::chunks;
use crate::effects::Context;
use crate::frames;

use super::candidates::{Candidate, Probes};
use super::fitted::SYM;
use super::setup::Setup;
use super::stats::{Batches, BlockStats, Problem};
use super::{AUTOCORRELATION_BATCHES, CV_BLOCKS};

/// The step (µT) of the field along which the scalar method's regressors are differentiated for their noise.
const NOISE_STEP_UT: f64 = 0.01;

/// One batch's normal equations: its clean rows and its other included ones apart (the batch lies within one
/// cross-validation block), its batch sums, and per candidate the rows where it acts.
struct BatchPart {
    clean: BlockStats,
    other: BlockStats,
    /// Every included row by row kind (the vector method's axes; none in the scalar method).
    by_kind: Vec<BlockStats>,
    batch: Batches,
    active: Vec<usize>,
}

/// The normal equations of the `included` samples per block (and of the `clean` ones apart), counting where each
/// candidate acts (into `cands`). Each batch of the autocorrelation lies within one block and is summed on its own,
/// on all threads; the batches are merged in order.
pub(crate) fn accumulate(
    setup: &Setup<'_>,
    cands: &mut [Candidate],
    included: &[bool],
    clean: &[bool],
) -> Problem {
    let columns = cands.last().map_or(setup.n_base, |c| c.first + c.n);
    let dims = if setup.vector { 3 } else { 1 };
    let parts = chunks::parts(AUTOCORRELATION_BATCHES, |batch| {
        accumulate_batch(setup, batch, cands, included, clean, columns)
    });
    let mut blocks: Vec<BlockStats> = (0..CV_BLOCKS).map(|_| BlockStats::new(columns)).collect();
    let mut clean_blocks = blocks.clone();
    let mut batches = Batches::new(AUTOCORRELATION_BATCHES, dims, columns);
    let mut batch_stats = Vec::with_capacity(parts.len());
    let mut active = vec![0usize; cands.len()];
    let mut by_kind = vec![BlockStats::new(columns); if setup.vector { 3 } else { 0 }];
    for (batch, part) in parts.iter().enumerate() {
        for (kind, rows) in by_kind.iter_mut().zip(&part.by_kind) {
            kind.add(rows);
        }
        let b = batch / (AUTOCORRELATION_BATCHES / CV_BLOCKS);
        blocks[b].add(&part.clean);
        blocks[b].add(&part.other);
        clean_blocks[b].add(&part.clean);
        batches.put(batch, &part.batch);
        let mut all = part.clean.clone();
        all.add(&part.other);
        batch_stats.push(all);
        for (a, p) in active.iter_mut().zip(&part.active) {
            *a += p;
        }
    }
    for (c, cand) in cands.iter_mut().enumerate() {
        cand.active_rows = active[c];
    }
    let mut noise_var = DVector::zeros(columns);
    if setup.vector {
        for j in 0..3 {
            for k in 0..3 {
                noise_var[4 * j + k] = setup.input.noise.floor_ut[k].powi(2);
            }
        }
    }
    Problem::new(
        blocks,
        clean_blocks,
        batches,
        batch_stats,
        by_kind,
        noise_var,
    )
}

/// What one sample's rows are built from: its context, its candidates' regressors and its centred reading.
struct SampleRows<'c> {
    i: usize,
    ctx: Context<'c>,
    regs: &'c [[[f64; 3]; 3]],
    /// The raw reading less the readings' mean, µT.
    mc: [f64; 3],
}

/// [`accumulate`] over the samples of one batch (`i·BATCHES/n` = `batch`); a candidate's zero regressors are left
/// out of the rows.
fn accumulate_batch(
    setup: &Setup<'_>,
    batch: usize,
    cands: &[Candidate],
    included: &[bool],
    clean: &[bool],
    columns: usize,
) -> BatchPart {
    let s = setup.samples;
    let n = s.len();
    let dims = if setup.vector { 3 } else { 1 };
    let mut part = BatchPart {
        clean: BlockStats::new(columns),
        other: BlockStats::new(columns),
        by_kind: vec![BlockStats::new(columns); if setup.vector { 3 } else { 0 }],
        batch: Batches::new(1, dims, columns),
        active: vec![0; cands.len()],
    };
    let first = (batch * n).div_ceil(AUTOCORRELATION_BATCHES);
    let end = ((batch + 1) * n).div_ceil(AUTOCORRELATION_BATCHES);
    let mut entries: Vec<(usize, f64)> = Vec::with_capacity(columns);
    let mut cross: Vec<(usize, f64)> = Vec::new();
    let mut regs: Vec<[[f64; 3]; 3]> = vec![[[0.0; 3]; 3]; cands.len()];
    let probes: Vec<Probes> = cands.iter().map(Candidate::probes).collect();
    for i in (first..end).filter(|&i| included[i]) {
        let ctx = s.context(i);
        for (reg, probe) in regs.iter_mut().zip(&probes) {
            *reg = probe.regressors(&ctx);
        }
        let mc = frames::sub(s.raw[i], setup.raw_mean);
        let stats = if clean[i] {
            &mut part.clean
        } else {
            &mut part.other
        };
        stats.samples += 1;
        for kind in &mut part.by_kind {
            kind.samples += 1;
        }
        let row = SampleRows {
            i,
            ctx,
            regs: &regs,
            mc,
        };
        if setup.vector {
            for j in 0..3 {
                entries.clear();
                entries.extend((0..3).map(|k| (4 * j + k, mc[k])));
                entries.push((4 * j + 3, 1.0));
                push_candidates(&mut entries, cands, &mut part.active, |c, k| -regs[c][k][j]);
                stats.add_row(&entries, s.field[i][j]);
                part.by_kind[j].add_row(&entries, s.field[i][j]);
                part.batch.add_row(0, j, &entries, s.field[i][j]);
            }
        } else {
            // ρ + J·Δ − u·G·θ ≈ 0 around the base fit (ρ: its residual), with the readings centred.
            let u = setup.unit[i];
            entries.clear();
            for (k, (r, q)) in SYM.iter().enumerate() {
                let d = if r == q {
                    u[*r] * mc[*q]
                } else {
                    u[*r] * mc[*q] + u[*q] * mc[*r]
                };
                entries.push((k, d));
            }
            entries.extend((0..3).map(|k| (6 + k, u[k])));
            push_candidates(&mut entries, cands, &mut part.active, |c, k| {
                -frames::dot(u, regs[c][k])
            });
            let rho = setup.base_rho(i);
            stats.add_row(&entries, -rho);
            part.batch.add_row(0, 0, &entries, -rho);
            if noise_cross(setup, cands, &probes, &row, &mut cross) {
                stats.add_noise_cross(&cross);
            }
        }
    }
    part
}

/// The scalar method's noise cross terms of one sample's row, into `cross`; whether there are any. The observation
/// −ρ and every regressor carry the same reading noise n: −ρ's is −(Aᵀu)·n, a regressor x's is ∇x·n, so
/// cov(x, −ρ) = −∇x·d with d = Σₙ·Aᵀu. Left in, it is a correlation the fit would credit to whatever regressor the
/// noise bends most (a cubic in the field): its derivative along d, per column, corrects Xᵀy.
fn noise_cross(
    setup: &Setup<'_>,
    cands: &[Candidate],
    probes: &[Probes],
    row: &SampleRows<'_>,
    cross: &mut Vec<(usize, f64)>,
) -> bool {
    let (s, i, mc, regs) = (setup.samples, row.i, row.mc, row.regs);
    let u = setup.unit[i];
    let f = setup.input.noise.floor_ut;
    let au = frames::mat_t_vec(&setup.base.a, u);
    let d: [f64; 3] = std::array::from_fn(|k| f[k] * f[k] * au[k]);
    let ad = frames::mat_vec(&setup.base.a, d);
    let size = frames::norm(ad);
    if size.is_nan() || size <= 0.0 {
        return false;
    }
    let field = s.field[i];
    let du = frames::scale(
        frames::sub(ad, frames::scale(u, frames::dot(u, ad))),
        1.0 / frames::norm(field),
    );
    cross.clear();
    for (k, (r, q)) in SYM.iter().enumerate() {
        let mut g = du[*r] * mc[*q] + u[*r] * d[*q];
        if r != q {
            g += du[*q] * mc[*r] + u[*q] * d[*r];
        }
        cross.push((k, g));
    }
    cross.extend((0..3).map(|k| (6 + k, du[k])));
    let mut shifted = row.ctx;
    shifted.field_ut = frames::add(field, frames::scale(ad, NOISE_STEP_UT / size));
    for (c, (cand, probe)) in cands.iter().zip(probes).enumerate() {
        let moved = probe.regressors(&shifted);
        for k in 0..cand.n {
            let dreg = frames::scale(frames::sub(moved[k], regs[c][k]), size / NOISE_STEP_UT);
            let g = -(frames::dot(du, regs[c][k]) + frames::dot(u, dreg));
            if g != 0.0 {
                cross.push((cand.first + k, g));
            }
        }
    }
    true
}

/// Appends the candidates' values in a row (`value(c, k)`: candidate `c`'s parameter `k`), the zeros left out, and
/// counts the candidates that act in it.
fn push_candidates(
    entries: &mut Vec<(usize, f64)>,
    cands: &[Candidate],
    active: &mut [usize],
    value: impl Fn(usize, usize) -> f64,
) {
    for (c, cand) in cands.iter().enumerate() {
        let before = entries.len();
        entries.extend(
            (0..cand.n)
                .map(|k| (cand.first + k, value(c, k)))
                .filter(|(_, v)| *v != 0.0),
        );
        if entries.len() > before {
            active[c] += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::candidates::{self, candidates};
    use super::super::testbench::{Bench, with_setup};
    use super::*;
    use crate::effects::EffectId;

    #[test]
    fn the_normal_equations_count_the_included_and_clean_rows_and_where_each_candidate_acts() {
        let bench = Bench::new(1500, &[], 8);
        with_setup(&bench, |setup, residual| {
            let n = setup.samples.len();
            let clean: Vec<bool> = (0..n).map(|i| !(100..300).contains(&i)).collect();
            let included: Vec<bool> = (0..n).map(|i| !(100..200).contains(&i)).collect();
            let offer = candidates::offer(setup, residual, &clean, Vec::new());
            let (mut cands, _) = candidates(&offer, setup.n_base);
            let problem = accumulate(setup, &mut cands, &included, &clean);
            // Three rows a sample in the vector method.
            assert_eq!(problem.total.rows, 3 * (n - 100));
            assert_eq!(problem.clean_total.rows, 3 * (n - 200));
            assert_eq!(problem.blocks.len(), CV_BLOCKS);
            // The current bias acts where the current is on.
            let on = (0..n)
                .filter(|&i| included[i] && bench.current_a[setup.samples.rows[i]] != 0.0)
                .count();
            let current = cands
                .iter()
                .find(|c| c.id() == EffectId::CurrentBias)
                .unwrap();
            assert_eq!(current.active_rows, 3 * on);
            // The temperature's effects act everywhere (it never sits at its mean exactly).
            assert_eq!(cands[0].active_rows, 3 * (n - 100));
        });
    }
}
