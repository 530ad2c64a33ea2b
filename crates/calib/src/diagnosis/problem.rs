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
use super::stats::{Batches, BlockStats, GramSums, Problem};
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

/// [`accumulate`] over the samples of one batch (`i·BATCHES/n` = `batch`). Each row is laid out in its own
/// columns — the vector method's axis `j` has only `A`'s row `j` and `b_j` of the base columns — with the candidates'
/// after them and the observation last, summed by [`GramSums`] per row kind and clean or not, and then put in the
/// design's columns.
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
    // A row's own columns: its base columns, the candidates', the observation.
    let base = if setup.vector { 4 } else { setup.n_base };
    let width = base + columns - setup.n_base + 1;
    let design_columns: Vec<Vec<usize>> = (0..dims)
        .map(|j| {
            let own_base = if setup.vector {
                4 * j..4 * j + 4
            } else {
                0..setup.n_base
            };
            own_base.chain(setup.n_base..columns).collect()
        })
        .collect();
    let mut part = BatchPart {
        clean: BlockStats::new(columns),
        other: BlockStats::new(columns),
        by_kind: vec![BlockStats::new(columns); if setup.vector { 3 } else { 0 }],
        batch: Batches::new(1, dims, columns),
        active: vec![0; cands.len()],
    };
    // Per row kind, the clean rows and the other included ones.
    let mut sums: Vec<[GramSums; 2]> = (0..dims)
        .map(|_| [GramSums::new(width), GramSums::new(width)])
        .collect();
    let first = (batch * n).div_ceil(AUTOCORRELATION_BATCHES);
    let end = ((batch + 1) * n).div_ceil(AUTOCORRELATION_BATCHES);
    let mut row = vec![0.0; width];
    let mut cross: Vec<(usize, f64)> = Vec::new();
    let mut regs: Vec<[[f64; 3]; 3]> = vec![[[0.0; 3]; 3]; cands.len()];
    let probes: Vec<Probes> = cands.iter().map(Candidate::probes).collect();
    for i in (first..end).filter(|&i| included[i]) {
        let ctx = s.context(i);
        for (reg, probe) in regs.iter_mut().zip(&probes) {
            *reg = probe.regressors(&ctx);
        }
        let mc = frames::sub(s.raw[i], setup.raw_mean);
        let (stats, which) = if clean[i] {
            (&mut part.clean, 0)
        } else {
            (&mut part.other, 1)
        };
        stats.samples += 1;
        for kind in &mut part.by_kind {
            kind.samples += 1;
        }
        if setup.vector {
            for (j, kind) in sums.iter_mut().enumerate() {
                row[..3].copy_from_slice(&mc);
                row[3] = 1.0;
                put_candidates(
                    &mut row[base..],
                    setup.n_base,
                    cands,
                    &mut part.active,
                    |c, k| -regs[c][k][j],
                );
                row[width - 1] = s.field[i][j];
                kind[which].push(&row);
            }
        } else {
            // ρ + J·Δ − u·G·θ ≈ 0 around the base fit (ρ: its residual), with the readings centred.
            let u = setup.unit[i];
            for (k, (r, q)) in SYM.iter().enumerate() {
                row[k] = if r == q {
                    u[*r] * mc[*q]
                } else {
                    u[*r] * mc[*q] + u[*q] * mc[*r]
                };
            }
            row[6..9].copy_from_slice(&u);
            put_candidates(
                &mut row[base..],
                setup.n_base,
                cands,
                &mut part.active,
                |c, k| -frames::dot(u, regs[c][k]),
            );
            row[width - 1] = -setup.base_rho(i);
            sums[0][which].push(&row);
            let rows = SampleRows {
                i,
                ctx,
                regs: &regs,
                mc,
            };
            if noise_cross(setup, cands, &probes, &rows, &mut cross) {
                stats.add_noise_cross(&cross);
            }
        }
    }
    for (j, (kind, columns)) in sums.iter_mut().zip(&design_columns).enumerate() {
        let [clean_rows, other_rows] = kind;
        clean_rows.add_to(&mut part.clean, columns);
        other_rows.add_to(&mut part.other, columns);
        if let Some(by_kind) = part.by_kind.get_mut(j) {
            clean_rows.add_to(by_kind, columns);
            other_rows.add_to(by_kind, columns);
        }
        clean_rows.add_sums_to(&mut part.batch, 0, j, columns);
        other_rows.add_sums_to(&mut part.batch, 0, j, columns);
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

/// Writes the candidates' values in `row`, from the design's column `first` on (`value(c, k)`: candidate `c`'s
/// parameter `k`), and counts the candidates that act in it (a value not zero).
fn put_candidates(
    row: &mut [f64],
    first: usize,
    cands: &[Candidate],
    active: &mut [usize],
    value: impl Fn(usize, usize) -> f64,
) {
    for (c, cand) in cands.iter().enumerate() {
        let mut acts = false;
        for k in 0..cand.n {
            let v = value(c, k);
            row[cand.first - first + k] = v;
            acts |= v != 0.0;
        }
        active[c] += usize::from(acts);
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
