//! Normal equations accumulated per contiguous time block: every least-squares question the diagnosis asks (a fit
//! with any subset of columns, its residual, its held-out residual on a block, how much of a column the base model
//! absorbs) is answered from these sums without another pass over the samples.

use nalgebra::{DMatrix, DVector};

/// Neighbouring batches whose scores are taken as correlated (Bartlett weights, as Newey and West): a disturbance's
/// field that changes slowly as the sensor moves spans several batches.
const SCORE_LAGS: usize = 4;

/// `XᵀX`, `Xᵀy` and `yᵀy` of the rows of one block.
#[derive(Clone, Debug)]
pub(crate) struct BlockStats {
    pub xtx: DMatrix<f64>,
    pub xty: DVector<f64>,
    /// `−Σ cov(x, y)` of the rows' noise, where the regressors and the observation share the sensor's noise (the
    /// scalar method): added to `Xᵀy` by the errors-in-variables correction.
    pub xty_noise: DVector<f64>,
    pub yty: f64,
    /// Rows accumulated.
    pub rows: usize,
    /// Samples accumulated (a vector sample gives three rows).
    pub samples: usize,
}

impl BlockStats {
    pub fn new(columns: usize) -> BlockStats {
        BlockStats {
            xtx: DMatrix::zeros(columns, columns),
            xty: DVector::zeros(columns),
            xty_noise: DVector::zeros(columns),
            yty: 0.0,
            rows: 0,
            samples: 0,
        }
    }

    /// Adds one row given as (column, value) pairs, columns in increasing order (zero values may be left out). The
    /// products go to the lower triangle, a column at a time; [`BlockStats::symmetrise`] mirrors them.
    pub fn add_row(&mut self, entries: &[(usize, f64)], y: f64) {
        let n = self.xtx.nrows();
        let xtx = self.xtx.as_mut_slice();
        for (a, &(i, xi)) in entries.iter().enumerate() {
            self.xty[i] += xi * y;
            let column = &mut xtx[i * n..(i + 1) * n];
            for &(j, xj) in &entries[a..] {
                column[j] += xi * xj;
            }
        }
        self.yty += y * y;
        self.rows += 1;
    }

    /// Adds one row's `−cov(x, y)` of the noise, as (column, value) pairs.
    pub fn add_noise_cross(&mut self, entries: &[(usize, f64)]) {
        for &(i, v) in entries {
            self.xty_noise[i] += v;
        }
    }

    /// Mirrors the accumulated lower triangle into the upper one.
    pub fn symmetrise(&mut self) {
        let n = self.xtx.nrows();
        for i in 0..n {
            for j in 0..i {
                self.xtx[(j, i)] = self.xtx[(i, j)];
            }
        }
    }

    pub fn add(&mut self, other: &BlockStats) {
        self.xtx += &other.xtx;
        self.xty += &other.xty;
        self.xty_noise += &other.xty_noise;
        self.yty += other.yty;
        self.rows += other.rows;
        self.samples += other.samples;
    }
}

/// Rows summed a block at a time: every [`GRAM_BLOCK_ROWS`] rows, the columns that are zero throughout the block
/// are dropped and the rest summed as `Zᵀ·Z` by 4×4 tiles held in registers, where [`BlockStats::add_row`] loads and
/// stores the whole triangle for every row. The last column is the
/// observation `y`, so the triangle holds `XᵀX`, `Xᵀy` and `yᵀy`; the column sums are kept for the batch means.
/// Every sum is taken in the rows' order within a block and the blocks' order, whatever the thread.
#[derive(Clone, Debug)]
pub(crate) struct GramSums {
    /// Columns of a row, the observation last.
    width: usize,
    /// The block's rows, row-major.
    block: Vec<f64>,
    /// Rows in `block`.
    filled: usize,
    /// Per column, `Σ|z|` of the block's rows: zero when the column is zero throughout the block.
    size: Vec<f64>,
    /// The block's non-zero columns side by side, padded with zero columns to whole tiles.
    packed: Vec<f64>,
    /// The columns of `packed`.
    kept: Vec<usize>,
    /// Per column of `packed`, the block's sum.
    block_sums: Vec<f64>,
    /// `Σ zₐ·z_b` for `a ≤ b`, at `a·width + b`.
    gram: Vec<f64>,
    /// Per column, `Σ z`.
    sums: Vec<f64>,
    /// Rows summed.
    rows: usize,
}

/// Rows per block of [`GramSums`]: the block and its packed copy stay in the first-level cache.
const GRAM_BLOCK_ROWS: usize = 64;
/// Columns per side of a tile of [`GramSums`].
const TILE: usize = 4;

impl GramSums {
    /// Sums of rows of `width` columns, the observation last.
    pub fn new(width: usize) -> GramSums {
        GramSums {
            width,
            block: vec![0.0; GRAM_BLOCK_ROWS * width],
            filled: 0,
            size: vec![0.0; width],
            packed: Vec::with_capacity(GRAM_BLOCK_ROWS * width.next_multiple_of(TILE)),
            kept: Vec::with_capacity(width),
            block_sums: Vec::with_capacity(width.next_multiple_of(TILE)),
            gram: vec![0.0; width * width],
            sums: vec![0.0; width],
            rows: 0,
        }
    }

    /// Adds one row (`width` values, the observation last).
    pub fn push(&mut self, row: &[f64]) {
        let at = self.filled * self.width;
        self.block[at..at + self.width].copy_from_slice(row);
        for (size, v) in self.size.iter_mut().zip(row) {
            *size += v.abs();
        }
        self.filled += 1;
        if self.filled == GRAM_BLOCK_ROWS {
            self.flush();
        }
    }

    /// Sums the rows of the block so far into the totals.
    fn flush(&mut self) {
        let rows = self.filled;
        if rows == 0 {
            return;
        }
        self.kept.clear();
        self.kept
            .extend((0..self.width).filter(|&c| self.size[c] != 0.0));
        let used = self.kept.len();
        let stride = used.next_multiple_of(TILE);
        self.packed.clear();
        self.packed.resize(rows * stride, 0.0);
        self.block_sums.clear();
        self.block_sums.resize(stride, 0.0);
        for (row, out) in self
            .block
            .chunks_exact(self.width)
            .zip(self.packed.chunks_exact_mut(stride))
        {
            for (z, &c) in out.iter_mut().zip(&self.kept) {
                *z = row[c];
            }
            for (sum, z) in self.block_sums.iter_mut().zip(out.iter()) {
                *sum += z;
            }
        }
        for (&c, sum) in self.kept.iter().zip(&self.block_sums) {
            self.sums[c] += sum;
        }
        for a0 in (0..used).step_by(TILE) {
            for b0 in (a0..used).step_by(TILE) {
                let tile = gram_tile(&self.packed, stride, a0, b0);
                for (a, tile_row) in tile.iter().enumerate().take(used - a0) {
                    let from = if a0 == b0 { a } else { 0 };
                    let ca = self.kept[a0 + a];
                    for (b, v) in tile_row.iter().enumerate().take(used - b0).skip(from) {
                        self.gram[ca * self.width + self.kept[b0 + b]] += v;
                    }
                }
            }
        }
        self.rows += rows;
        self.filled = 0;
        self.size.fill(0.0);
    }

    /// Adds the rows summed so far to `stats`, column `a` of a row going to its column `columns[a]` (increasing;
    /// the observation has none).
    pub fn add_to(&mut self, stats: &mut BlockStats, columns: &[usize]) {
        self.flush();
        let y = self.width - 1;
        for (a, &i) in columns.iter().enumerate() {
            // The lower triangle, as [`BlockStats::add_row`] fills it.
            for (b, &j) in columns.iter().enumerate().skip(a) {
                stats.xtx[(j, i)] += self.gram[a * self.width + b];
            }
            stats.xty[i] += self.gram[a * self.width + y];
        }
        stats.yty += self.gram[y * self.width + y];
        stats.rows += self.rows;
    }

    /// Adds the rows' column sums to `batches`' batch `batch`, row kind `dim`, mapped as in [`GramSums::add_to`].
    pub fn add_sums_to(
        &mut self,
        batches: &mut Batches,
        batch: usize,
        dim: usize,
        columns: &[usize],
    ) {
        self.flush();
        let slot = batch * batches.dims + dim;
        for (&i, s) in columns.iter().zip(&self.sums) {
            batches.sx[slot * batches.columns + i] += s;
        }
        batches.sy[slot] += self.sums[self.width - 1];
        batches.count[slot] += self.rows;
    }
}

/// The 4×4 tile of `Zᵀ·Z` at columns `a0…` and `b0…` of the rows of `packed` (`stride` values a row).
fn gram_tile(packed: &[f64], stride: usize, a0: usize, b0: usize) -> [[f64; TILE]; TILE] {
    let mut tile = [[0.0; TILE]; TILE];
    for row in packed.chunks_exact(stride) {
        let za = &row[a0..a0 + TILE];
        let zb = &row[b0..b0 + TILE];
        for (t, x) in tile.iter_mut().zip(za) {
            for (v, z) in t.iter_mut().zip(zb) {
                *v += x * z;
            }
        }
    }
    tile
}

/// Per contiguous batch of samples and per row kind (calibrated axis), the sums `Σx` and `Σy`: the residual's batch
/// means for any coefficients, hence the residual's autocorrelation by the method of batch means.
#[derive(Clone, Debug)]
pub(crate) struct Batches {
    dims: usize,
    columns: usize,
    sx: Vec<f64>,
    sy: Vec<f64>,
    count: Vec<usize>,
}

impl Batches {
    pub fn new(batches: usize, dims: usize, columns: usize) -> Batches {
        Batches {
            dims,
            columns,
            sx: vec![0.0; batches * dims * columns],
            sy: vec![0.0; batches * dims],
            count: vec![0; batches * dims],
        }
    }

    /// Sets batch `batch` to the only batch of `part`.
    pub fn put(&mut self, batch: usize, part: &Batches) {
        let slots = batch * self.dims..(batch + 1) * self.dims;
        self.sx[slots.start * self.columns..slots.end * self.columns].copy_from_slice(&part.sx);
        self.sy[slots.clone()].copy_from_slice(&part.sy);
        self.count[slots].copy_from_slice(&part.count);
    }

    /// Adds one row of kind `dim` to batch `batch`.
    pub fn add_row(&mut self, batch: usize, dim: usize, entries: &[(usize, f64)], y: f64) {
        let slot = batch * self.dims + dim;
        for &(i, x) in entries {
            self.sx[slot * self.columns + i] += x;
        }
        self.sy[slot] += y;
        self.count[slot] += 1;
    }

    /// The integrated autocorrelation factor of the residual under a solution (`sigma2`: its variance per row):
    /// `L·Var(batch means)/σ²`, 1 for white noise, larger when neighbouring residuals are alike.
    pub fn autocorrelation(&self, sol: &Solution, sigma2: f64) -> f64 {
        let slots = self.count.len();
        let (mut sum, mut used) = (0.0, 0usize);
        let mut means = vec![0.0; slots];
        for (slot, mean) in means.iter_mut().enumerate() {
            let n = self.count[slot];
            if n == 0 {
                continue;
            }
            let fitted: f64 = sol
                .columns
                .iter()
                .zip(sol.beta.iter())
                .map(|(&c, b)| self.sx[slot * self.columns + c] * b)
                .sum();
            *mean = (self.sy[slot] - fitted) / n as f64;
            sum += *mean;
            used += 1;
        }
        if used < 2 || sigma2 <= 0.0 {
            return 1.0;
        }
        let centre = sum / used as f64;
        let (mut var_sum, mut len_sum) = (0.0, 0.0);
        for slot in 0..slots {
            let n = self.count[slot];
            if n > 0 {
                var_sum += n as f64 * (means[slot] - centre).powi(2);
                len_sum += 1.0;
            }
        }
        // Σ n_b·(m_b − m̄)² / (B − 1) estimates L·Var(m_b) for batches of (nearly) equal length.
        var_sum / (len_sum - 1.0) / sigma2
    }
}

/// The residual sum of squares of a block's rows under a solution.
fn rss_of(block: &BlockStats, sol: &Solution) -> f64 {
    let k = sol.columns.len();
    let mut quad = 0.0;
    let mut lin = 0.0;
    for r in 0..k {
        let i = sol.columns[r];
        lin += sol.beta[r] * block.xty[i];
        for s in 0..k {
            quad += sol.beta[r] * block.xtx[(i, sol.columns[s])] * sol.beta[s];
        }
    }
    (block.yty - 2.0 * lin + quad).max(0.0)
}

/// A least-squares solution on a subset of columns.
#[derive(Clone, Debug)]
pub(crate) struct Solution {
    /// The columns, in order.
    pub columns: Vec<usize>,
    /// Coefficients, one per column.
    pub beta: DVector<f64>,
    /// `(X_SᵀX_S)⁻¹` (for standard errors).
    pub inverse: DMatrix<f64>,
    /// Residual sum of squares on the fitted rows.
    pub rss: f64,
}

/// Which rows a fit uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Rows {
    /// Every included row: the clean ones and those of modelled disturbances.
    All,
    /// The clean rows only (outside every gross span).
    Clean,
}

/// The blocks of a problem and the correction to apply to the normal matrix when fitting (errors in variables).
#[derive(Clone, Debug)]
pub(crate) struct Problem {
    /// Per cross-validation block, every included row.
    pub blocks: Vec<BlockStats>,
    /// Per block, the clean rows (a subset of `blocks`): what held-out residuals are judged on.
    pub clean: Vec<BlockStats>,
    pub batches: Batches,
    /// Per autocorrelation batch, every included row: the scores of a fit batch by batch, for standard errors that
    /// see residuals correlated with the regressors over stretches of time.
    pub batch_stats: Vec<BlockStats>,
    /// Per row kind (the vector method's calibrated axis), every included row: each axis' own residual variance.
    pub by_kind: Vec<BlockStats>,
    /// All included rows.
    pub total: BlockStats,
    /// The clean rows.
    pub clean_total: BlockStats,
    /// Per column, the variance subtracted per sample from `XᵀX` when fitting (the raw noise on `A`'s columns).
    pub noise_var: DVector<f64>,
}

impl Problem {
    pub fn new(
        mut blocks: Vec<BlockStats>,
        mut clean: Vec<BlockStats>,
        batches: Batches,
        mut batch_stats: Vec<BlockStats>,
        mut by_kind: Vec<BlockStats>,
        noise_var: DVector<f64>,
    ) -> Problem {
        let columns = noise_var.len();
        let sum = |bs: &mut Vec<BlockStats>| {
            let mut total = BlockStats::new(columns);
            for b in bs.iter_mut() {
                b.symmetrise();
                total.add(b);
            }
            total
        };
        let total = sum(&mut blocks);
        let clean_total = sum(&mut clean);
        for b in batch_stats.iter_mut().chain(&mut by_kind) {
            b.symmetrise();
        }
        Problem {
            blocks,
            clean,
            batches,
            batch_stats,
            by_kind,
            total,
            clean_total,
            noise_var,
        }
    }

    fn set(&self, rows: Rows) -> &[BlockStats] {
        match rows {
            Rows::All => &self.blocks,
            Rows::Clean => &self.clean,
        }
    }

    /// Least squares on `columns` over the `rows` of every block except `held_out`; with `corrected`, the
    /// errors-in-variables correction is subtracted from the normal matrix (for parameter estimates; tests compare
    /// plain least squares). Columns without support in the fitted blocks (zero throughout them, e.g. a transient
    /// inside the held-out block) are left out of that fit, their coefficient zero.
    pub fn solve_on(
        &self,
        rows: Rows,
        columns: &[usize],
        held_out: Option<usize>,
        corrected: bool,
    ) -> Option<Solution> {
        let set = self.set(rows);
        let fitted = || {
            set.iter()
                .enumerate()
                .filter(move |(b, _)| Some(*b) != held_out)
        };
        let supported: Vec<usize> = columns
            .iter()
            .copied()
            .filter(|&i| fitted().map(|(_, block)| block.xtx[(i, i)]).sum::<f64>() > 1e-300)
            .collect();
        let k = supported.len();
        let mut xtx = DMatrix::zeros(k, k);
        let mut xty = DVector::<f64>::zeros(k);
        // The correction of Xᵀy for the noise it shares with the regressors, apart: the residuals use the plain one.
        let mut xty_noise = DVector::<f64>::zeros(k);
        let mut yty = 0.0;
        for (_, block) in fitted() {
            for (r, &i) in supported.iter().enumerate() {
                xty[r] += block.xty[i];
                for (s, &j) in supported.iter().enumerate() {
                    xtx[(r, s)] += block.xtx[(i, j)];
                }
                if corrected {
                    xtx[(r, r)] -= block.samples as f64 * self.noise_var[i];
                    xty_noise[r] += block.xty_noise[i];
                }
            }
            yty += block.yty;
        }
        let inverse = xtx
            .clone()
            .cholesky()
            .map(|c| c.inverse())
            .or_else(|| xtx.clone().try_inverse())?;
        let beta: DVector<f64> = &inverse * (&xty + &xty_noise);
        // RSS of the fitted rows with these coefficients (the uncorrected quadratic form: actual residuals).
        let mut rss = yty - 2.0 * beta.dot(&xty);
        for (_, block) in fitted() {
            for (r, &i) in supported.iter().enumerate() {
                for (s, &j) in supported.iter().enumerate() {
                    rss += beta[r] * block.xtx[(i, j)] * beta[s];
                }
            }
        }
        Some(Solution {
            columns: supported,
            beta,
            inverse,
            rss: rss.max(0.0),
        })
    }

    /// [`Problem::solve_on`] every included row.
    pub fn solve(
        &self,
        columns: &[usize],
        held_out: Option<usize>,
        corrected: bool,
    ) -> Option<Solution> {
        self.solve_on(Rows::All, columns, held_out, corrected)
    }

    /// Residual sum of squares of the clean rows of block `b` under a solution.
    pub fn block_rss(&self, b: usize, sol: &Solution) -> f64 {
        rss_of(&self.clean[b], sol)
    }

    /// Residual sum of squares of all clean rows under a solution.
    pub fn clean_rss(&self, sol: &Solution) -> f64 {
        rss_of(&self.clean_total, sol)
    }

    /// The residual's autocorrelation factor under a solution, at least 1 (see [`Batches::autocorrelation`]).
    pub fn autocorrelation(&self, sol: &Solution) -> f64 {
        let sigma2 = sol.rss / self.total.rows.max(1) as f64;
        self.batches.autocorrelation(sol, sigma2).max(1.0)
    }

    /// The covariance of a solution fitted on every included row from the residual's variance, allowing for
    /// autocorrelated residuals ([`Problem::autocorrelation`]) and for row kinds of unequal noise (a chip's axes: most
    /// are noisier along z): `τ·(XᵀX)⁻¹·(Σ_k s_k²·X_kᵀX_k)·(XᵀX)⁻¹`, `s_k²` kind k's residual variance per row (the
    /// degrees of freedom shared in proportion to the rows), `X_kᵀX_k` its errors-in-variables-corrected normal
    /// matrix. With one kind, or equal variances, `τ·s²·(XᵀX)⁻¹`.
    pub fn model_covariance(&self, sol: &Solution) -> DMatrix<f64> {
        let rows = self.total.rows.max(1) as f64;
        let dof = (rows - sol.columns.len() as f64).max(1.0);
        let tau = self.autocorrelation(sol);
        let kinds: Vec<&BlockStats> = self.by_kind.iter().filter(|b| b.rows > 0).collect();
        if kinds.len() < 2 {
            return &sol.inverse * (sol.rss / dof * tau);
        }
        let k = sol.columns.len();
        let mut meat = DMatrix::zeros(k, k);
        for kind in kinds {
            let s2 = rss_of(kind, sol) / kind.rows as f64 * rows / dof;
            for (r, &i) in sol.columns.iter().enumerate() {
                for (c, &j) in sol.columns.iter().enumerate() {
                    meat[(r, c)] += s2 * kind.xtx[(i, j)];
                }
                // The errors-in-variables correction of the columns this kind's rows hold.
                if kind.xtx[(i, i)] > 0.0 {
                    meat[(r, r)] -= s2 * kind.samples as f64 * self.noise_var[i];
                }
            }
        }
        &sol.inverse * meat * &sol.inverse * tau
    }

    /// The cluster-robust (sandwich) covariance of a solution fitted on every included row, with the batches as
    /// clusters: `(XᵀX)⁻¹·M·(XᵀX)⁻¹·B/(B−1)`, `M = Σ_b s_b·s_bᵀ` plus the products of neighbours up to [`SCORE_LAGS`]
    /// apart with Bartlett weights (Newey–West), `s_b` the batch's score at the solution (its errors-in-variables
    /// correction included). Unlike the covariance from the residual variance, it grows when residuals that vary
    /// with the regressors gather in some stretches of the recording (a disturbance's tail below the gross
    /// threshold), which bias the fit as much as they scatter it. `None` with fewer than two batches.
    pub fn cluster_covariance(&self, sol: &Solution) -> Option<DMatrix<f64>> {
        let k = sol.columns.len();
        let used: Vec<&BlockStats> = self.batch_stats.iter().filter(|b| b.rows > 0).collect();
        if used.len() < 2 {
            return None;
        }
        let scores: Vec<DVector<f64>> = used
            .iter()
            .map(|b| {
                DVector::from_iterator(
                    k,
                    sol.columns.iter().enumerate().map(|(r, &i)| {
                        let mut v = b.xty[i]
                            + b.xty_noise[i]
                            + b.samples as f64 * self.noise_var[i] * sol.beta[r];
                        for (s, &j) in sol.columns.iter().enumerate() {
                            v -= b.xtx[(i, j)] * sol.beta[s];
                        }
                        v
                    }),
                )
            })
            .collect();
        let mut meat = DMatrix::zeros(k, k);
        for lag in 0..=SCORE_LAGS.min(scores.len() - 1) {
            let w = 1.0 - lag as f64 / (SCORE_LAGS + 1) as f64;
            for (x, y) in scores.iter().zip(&scores[lag..]) {
                meat.ger(w, x, y, 1.0);
                if lag > 0 {
                    meat.ger(w, y, x, 1.0);
                }
            }
        }
        let clusters = used.len() as f64;
        Some(&sol.inverse * meat * &sol.inverse * (clusters / (clusters - 1.0)))
    }

    /// Blocked cross-validation: the held-out residual sum of squares of the clean rows, summed over the blocks,
    /// each predicted by a fit on the other blocks' `rows`.
    pub fn cv_rss_on(&self, rows: Rows, columns: &[usize]) -> Option<f64> {
        (0..self.blocks.len())
            .map(|b| {
                self.solve_on(rows, columns, Some(b), true)
                    .map(|s| self.block_rss(b, &s))
            })
            .sum()
    }

    /// [`Problem::cv_rss_on`] fitted on every included row.
    pub fn cv_rss(&self, columns: &[usize]) -> Option<f64> {
        self.cv_rss_on(Rows::All, columns)
    }

    /// Of the columns `cand`, the largest fraction of any combination that is NOT explained by the columns `base`:
    /// 0 means the base absorbs the candidate entirely.
    pub fn unabsorbed_fraction(&self, base: &[usize], cand: &[usize]) -> f64 {
        let x = &self.total.xtx;
        let pick = |rows: &[usize], cols: &[usize]| {
            DMatrix::from_fn(rows.len(), cols.len(), |r, s| x[(rows[r], cols[s])])
        };
        let gg = pick(cand, cand);
        let bb = pick(base, base);
        let bg = pick(base, cand);
        let Some(bb_inv) = bb.clone().cholesky().map(|c| c.inverse()) else {
            return 0.0;
        };
        let residual = &gg - bg.transpose() * bb_inv * &bg;
        // Generalised eigenproblem residual·v = λ·gg·v, via gg^(-1/2).
        let Some(chol) = gg.clone().cholesky() else {
            return 0.0;
        };
        let l_inv = chol
            .l()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::zeros(cand.len(), cand.len()));
        let m = &l_inv * residual * l_inv.transpose();
        let sym = (&m + m.transpose()) / 2.0;
        sym.symmetric_eigenvalues()
            .iter()
            .copied()
            .fold(0.0, f64::max)
            .clamp(0.0, 1.0)
    }

    /// How the base columns take up a candidate: the coefficients of regressing the candidate's columns on the base.
    pub fn absorption_coefficients(&self, base: &[usize], cand: &[usize]) -> Option<DMatrix<f64>> {
        let x = &self.total.xtx;
        let bb = DMatrix::from_fn(base.len(), base.len(), |r, s| x[(base[r], base[s])]);
        let bg = DMatrix::from_fn(base.len(), cand.len(), |r, s| x[(base[r], cand[s])]);
        Some(bb.cholesky()?.solve(&bg))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line_problem() -> Problem {
        // y = 2 + 3x over x = 0..40, four blocks of ten, plus a useless constant-ish column that duplicates column 0.
        let mut blocks = vec![BlockStats::new(3); 4];
        for i in 0..40 {
            let x = i as f64;
            let noise = if i % 2 == 0 { 0.1 } else { -0.1 };
            blocks[i / 10].add_row(&[(0, 1.0), (1, x), (2, 2.0)], 2.0 + 3.0 * x + noise);
            blocks[i / 10].samples += 1;
        }
        Problem::new(
            blocks.clone(),
            blocks,
            Batches::new(1, 1, 3),
            Vec::new(),
            Vec::new(),
            DVector::zeros(3),
        )
    }

    #[test]
    fn rows_summed_a_block_at_a_time_give_the_sums_row_by_row() {
        // 150 rows (two whole blocks and a part) of six columns in the design, laid out as five of a row's own and
        // the observation; column 2 acts only in rows 70..100, so whole blocks leave it out.
        let columns = [0, 2, 3, 4, 5];
        let mut one_by_one = BlockStats::new(6);
        let mut blocked = BlockStats::new(6);
        let mut by_block = GramSums::new(columns.len() + 1);
        let mut batches = Batches::new(1, 1, 6);
        let (mut sx, mut sy) = ([0.0; 6], 0.0);
        for i in 0..150 {
            let x = i as f64 / 10.0;
            let window = if (70..100).contains(&i) { x - 8.0 } else { 0.0 };
            let row = [1.0, window, x.sin(), x * x, -0.5 * x, 0.3 + x.cos()];
            let entries: Vec<(usize, f64)> = columns
                .iter()
                .zip(&row)
                .map(|(&c, &v)| (c, v))
                .filter(|(_, v)| *v != 0.0)
                .collect();
            one_by_one.add_row(&entries, row[5]);
            for &(c, v) in &entries {
                sx[c] += v;
            }
            sy += row[5];
            by_block.push(&row);
        }
        by_block.add_to(&mut blocked, &columns);
        by_block.add_sums_to(&mut batches, 0, 0, &columns);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()));
        for i in 0..6 {
            for j in 0..6 {
                assert!(
                    close(blocked.xtx[(i, j)], one_by_one.xtx[(i, j)]),
                    "{i} {j}"
                );
            }
            assert!(close(blocked.xty[i], one_by_one.xty[i]), "{i}");
            assert!(close(batches.sx[i], sx[i]), "{i}");
        }
        assert!(close(blocked.yty, one_by_one.yty) && close(batches.sy[0], sy));
        assert_eq!((blocked.rows, batches.count[0]), (150, 150));
    }

    #[test]
    fn solves_predicts_and_cross_validates() {
        let p = line_problem();
        let s = p.solve(&[0, 1], None, false).unwrap();
        assert!((s.beta[0] - 2.0).abs() < 0.05 && (s.beta[1] - 3.0).abs() < 0.01);
        assert!((s.rss - 40.0 * 0.01).abs() < 0.01, "{}", s.rss);
        let total: f64 = (0..4).map(|b| p.block_rss(b, &s)).sum();
        assert!((total - s.rss).abs() < 1e-6);
        let cv = p.cv_rss(&[0, 1]).unwrap();
        assert!(cv > s.rss && cv < 2.0 * s.rss, "{cv}");
        let intercept_only = p.cv_rss(&[0]).unwrap();
        assert!(intercept_only > 100.0 * cv);
    }

    #[test]
    fn each_row_kind_brings_its_own_noise_to_the_covariance() {
        // Two kinds of rows, each with its own intercept: kind 0 with noise ±0.1, kind 1 with ±1.
        let n = 100;
        let mut kinds = vec![BlockStats::new(2); 2];
        for i in 0..n {
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            kinds[0].add_row(&[(0, 1.0)], 1.0 + 0.1 * sign);
            kinds[1].add_row(&[(1, 1.0)], 2.0 + sign);
        }
        let mut all = kinds[0].clone();
        all.add(&kinds[1]);
        let p = Problem::new(
            vec![all.clone()],
            vec![all],
            Batches::new(1, 2, 2),
            Vec::new(),
            kinds,
            DVector::zeros(2),
        );
        let sol = p.solve(&[0, 1], None, true).unwrap();
        let cov = p.model_covariance(&sol);
        // Each intercept's variance is its own kind's σ²/n (the degrees of freedom shared: 200 rows, 2 columns),
        // where one pooled variance would give both (0.01 + 1)/2/n.
        let dof = 200.0 / 198.0;
        assert!((cov[(0, 0)] - 0.01 / 100.0 * dof).abs() < 1e-12, "{cov}");
        assert!((cov[(1, 1)] - 1.0 / 100.0 * dof).abs() < 1e-12, "{cov}");
        assert!(cov[(0, 1)].abs() < 1e-15);
    }

    #[test]
    fn a_duplicate_column_is_fully_absorbed() {
        let p = line_problem();
        assert!(p.unabsorbed_fraction(&[0, 1], &[2]) < 1e-9);
        assert!(p.unabsorbed_fraction(&[0], &[1]) > 0.2);
        let coef = p.absorption_coefficients(&[0, 1], &[2]).unwrap();
        assert!((coef[(0, 0)] - 2.0).abs() < 1e-9 && coef[(1, 0)].abs() < 1e-9);
    }
}
