//! Passes over the samples on all threads: the samples are cut into chunks of a fixed size, each chunk is reduced
//! on its own, and the chunks' results are merged in order. The chunks do not depend on the number of threads, so a
//! sum comes out the same on any machine.

use std::ops::Range;

use rayon::prelude::*;

/// Samples per chunk.
pub(crate) const CHUNK: usize = 1 << 14;

/// The chunks of `0..n`, each reduced by `each`, merged in order by `merge`; `None` when `n` is 0.
pub(crate) fn fold<T: Send>(
    n: usize,
    each: impl Fn(Range<usize>) -> T + Sync,
    merge: impl Fn(T, T) -> T,
) -> Option<T> {
    let chunks = n.div_ceil(CHUNK);
    if chunks <= 1 {
        return (chunks == 1).then(|| each(0..n));
    }
    let parts: Vec<T> = (0..chunks)
        .into_par_iter()
        .map(|c| each(c * CHUNK..((c + 1) * CHUNK).min(n)))
        .collect();
    parts.into_iter().reduce(merge)
}

/// `f(i)` for every `i` in `0..n`, computed on all threads.
pub(crate) fn map<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let mut out = Vec::with_capacity(n);
    if n <= CHUNK {
        out.extend((0..n).map(f));
    } else {
        (0..n)
            .into_par_iter()
            .with_min_len(CHUNK / 4)
            .map(&f)
            .collect_into_vec(&mut out);
    }
    out
}

/// `f(k)` for every part `k` in `0..parts`, computed on all threads, in order: for passes whose parts are fixed by
/// the data rather than by [`CHUNK`].
pub(crate) fn parts<T: Send>(parts: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    (0..parts).into_par_iter().map(&f).collect()
}
