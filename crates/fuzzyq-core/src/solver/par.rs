//! The few data-parallel patterns the solver uses, on rayon with feature `parallel` and
//! sequential without. Each item is computed by exactly one task from its own inputs, so the
//! split never changes a result.

#[cfg(feature = "parallel")]
use rayon::prelude::*;

/// `out.chunks_mut(chunk)` with `f(state, chunk_index, chunk)`; `init` makes per-task state.
pub(super) fn for_each_chunk_mut<U, S, I, F>(out: &mut [U], chunk: usize, init: I, f: F)
where
    U: Send,
    I: Fn() -> S + Sync + Send,
    F: Fn(&mut S, usize, &mut [U]) + Sync + Send,
{
    #[cfg(feature = "parallel")]
    {
        out.par_chunks_mut(chunk)
            .enumerate()
            .for_each_init(init, |s, (i, c)| f(s, i, c));
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut s = init();
        for (i, c) in out.chunks_mut(chunk).enumerate() {
            f(&mut s, i, c);
        }
    }
}

/// [`for_each_chunk_mut`] where each chunk also gives a result, combined by `reduce` from
/// `identity` in a grouping that depends on the split (see [`map_reduce`]).
pub(super) fn map_reduce_chunks_mut<U, S, R, I, F, G>(
    out: &mut [U],
    chunk: usize,
    init: I,
    f: F,
    identity: R,
    reduce: G,
) -> R
where
    U: Send,
    R: Copy + Send + Sync,
    I: Fn() -> S + Sync + Send,
    F: Fn(&mut S, usize, &mut [U]) -> R + Sync + Send,
    G: Fn(R, R) -> R + Sync + Send,
{
    // Paired with as many `()`, which take no memory.
    let mut none = vec![(); out.len()];
    map_reduce_chunks_mut2(
        (out, &mut none),
        chunk,
        init,
        |s, i, c, _| f(s, i, c),
        identity,
        reduce,
    )
}

/// [`map_reduce_chunks_mut`] over two slices of equal length at once: `f(state, chunk_index,
/// a_chunk, b_chunk)`.
pub(super) fn map_reduce_chunks_mut2<A, B, S, R, I, F, G>(
    (a, b): (&mut [A], &mut [B]),
    chunk: usize,
    init: I,
    f: F,
    identity: R,
    reduce: G,
) -> R
where
    A: Send,
    B: Send,
    R: Copy + Send + Sync,
    I: Fn() -> S + Sync + Send,
    F: Fn(&mut S, usize, &mut [A], &mut [B]) -> R + Sync + Send,
    G: Fn(R, R) -> R + Sync + Send,
{
    assert_eq!(a.len(), b.len(), "slices of equal length");
    #[cfg(feature = "parallel")]
    {
        a.par_chunks_mut(chunk)
            .zip(b.par_chunks_mut(chunk))
            .enumerate()
            .map_init(init, |s, (i, (x, y))| f(s, i, x, y))
            .reduce(|| identity, &reduce)
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut s = init();
        a.chunks_mut(chunk)
            .zip(b.chunks_mut(chunk))
            .enumerate()
            .fold(identity, |r, (i, (x, y))| reduce(r, f(&mut s, i, x, y)))
    }
}

/// `(0..n).map(f)` collected in order; `min_len` items at least per task.
pub(super) fn map_indexed<R, S, I, F>(n: usize, min_len: usize, init: I, f: F) -> Vec<R>
where
    R: Send,
    I: Fn() -> S + Sync + Send,
    F: Fn(&mut S, usize) -> R + Sync + Send,
{
    #[cfg(feature = "parallel")]
    {
        (0..n)
            .into_par_iter()
            .with_min_len(min_len)
            .map_init(init, f)
            .collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        let _ = min_len;
        let mut s = init();
        (0..n).map(|i| f(&mut s, i)).collect()
    }
}

/// `(a(), b())`, `b` taken by another thread of the current pool while this one runs `a` where
/// one is free (in turn without feature `parallel`): the pool the caller runs in, never a
/// thread of its own, so that a caller's pool (the Python extension's, which must survive
/// `fork`) keeps all the work.
pub(super) fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (a(), b())
    }
}

/// `f()` on every thread of the pool at once (one call without feature `parallel`), for
/// measurements of the whole machine.
pub(super) fn broadcast<R, F>(f: F) -> Vec<R>
where
    R: Send,
    F: Fn() -> R + Sync,
{
    #[cfg(feature = "parallel")]
    {
        rayon::broadcast(|_| f())
    }
    #[cfg(not(feature = "parallel"))]
    {
        vec![f()]
    }
}

/// `map` over the ranges `chunk` items long that cover `0..n`, combined by `reduce` from
/// `identity`. The grouping of the combinations depends on the split, so `reduce` must give
/// the same result in any grouping and order (exactly: a maximum, a minimum, not a float sum).
pub(super) fn map_reduce<R, F, G>(n: usize, chunk: usize, identity: R, map: F, reduce: G) -> R
where
    R: Copy + Send + Sync,
    F: Fn(core::ops::Range<usize>) -> R + Sync + Send,
    G: Fn(R, R) -> R + Sync + Send,
{
    let range = move |i: usize| i * chunk..n.min((i + 1) * chunk);
    let chunks = n.div_ceil(chunk);
    #[cfg(feature = "parallel")]
    {
        (0..chunks)
            .into_par_iter()
            .map(|i| map(range(i)))
            .reduce(|| identity, &reduce)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (0..chunks).map(|i| map(range(i))).fold(identity, reduce)
    }
}
