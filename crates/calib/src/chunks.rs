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

/// Like [`fold`], over every `s`-th chunk only, `s` the least stride that leaves about `most` samples (between half
/// of it and a chunk more; all chunks when `n <= most`): for statistics that a few hundred thousand samples already
/// give to a fraction of a per cent, spread over the whole recording.
pub(crate) fn fold_spread<T: Send>(
    n: usize,
    most: usize,
    each: impl Fn(Range<usize>) -> T + Sync,
    merge: impl Fn(T, T) -> T,
) -> Option<T> {
    let stride = n.div_ceil(most.max(1)).max(1);
    if stride == 1 {
        return fold(n, each, merge);
    }
    let picked: Vec<usize> = (0..n.div_ceil(CHUNK)).step_by(stride).collect();
    parts(picked.len(), |k| {
        let c = picked[k];
        each(c * CHUNK..((c + 1) * CHUNK).min(n))
    })
    .into_iter()
    .reduce(merge)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The samples a fold visits, in order.
    fn visited(n: usize, most: usize) -> Vec<usize> {
        fold_spread(
            n,
            most,
            |r| r.collect::<Vec<_>>(),
            |mut a, b| {
                a.extend(b);
                a
            },
        )
        .unwrap_or_default()
    }

    #[test]
    fn a_spread_fold_visits_every_sample_up_to_its_limit() {
        assert_eq!(
            visited(5 * CHUNK + 7, 6 * CHUNK),
            (0..5 * CHUNK + 7).collect::<Vec<_>>()
        );
        assert!(visited(0, CHUNK).is_empty());
    }

    #[test]
    fn a_spread_fold_takes_whole_chunks_across_the_samples() {
        let n = 40 * CHUNK + 123;
        let seen = visited(n, 10 * CHUNK);
        assert!(seen.len() <= 10 * CHUNK, "{}", seen.len());
        assert!(seen.len() >= 5 * CHUNK, "{}", seen.len());
        // Whole chunks, from the first to near the end.
        assert_eq!(seen[0], 0);
        assert!(*seen.last().unwrap() >= n - 5 * CHUNK);
        for w in seen.chunks(CHUNK) {
            assert!(w.windows(2).all(|p| p[1] == p[0] + 1));
        }
    }
}
