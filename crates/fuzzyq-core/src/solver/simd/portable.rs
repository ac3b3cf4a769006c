//! The portable instance of [`Isa`]: plain arrays and loops, no intrinsics, written so the
//! compiler's vectorisers turn each lane loop into one vector instruction.
//!
//! A vector is `[T; N]` (8 lanes of `f32`, 4 of `f64`: one 256-bit register on x86-64 AVX2,
//! two 128-bit registers on AArch64 NEON); each operation is a loop over the lanes that LLVM's
//! SLP vectoriser maps to one instruction, the fused multiply-add through `mul_add` (an exactly
//! rounded `llvm.fma`, a single instruction wherever the target has FMA). The maximum is
//! `if a > b { a } else { b }`, the pattern x86's `maxps` implements exactly. Sums run in the
//! same order as every other instance's, so the results are bit-identical to theirs.
//!
//! Partial vectors (a row's tail) are where portable code loses most: a variable-length loop
//! becomes a call to `memcpy` and the accumulators leave registers, and even fixed-size copies
//! (one per length) break the vectoriser's lanes apart (the instance ran at 31% and 69% of the
//! AVX2 one that way). So a partial load reads the whole vector and leaves the extra lanes as
//! they are (every caller masks them out again; zeroing them with a select made the vectoriser
//! assemble each load from pieces), which needs the input to extend a vector past the tensor:
//! the block path pads its stage buffers by [`super::INPUT_PAD`]; on unpadded inputs (`V`
//! itself, read by the first stage) the stage kernel runs `Portable<false>`, whose partial
//! loads copy one fixed-size head per length, and the last stage the scalar instance (same
//! bits). Partial stores copy one fixed-size head per length (they must not write past the
//! row). The maximiser's searches are the instance's own ([`Isa::first_equal`],
//! [`Isa::first_equal_rows`]): lane-wise minima of the matching indices, where the defaults'
//! bit masks would be widened lane by lane. A horizontal maximum starts from the vector in
//! memory: built straight on the multiply-adds before it, LLVM's narrower reduction tree split
//! them into two-lane pieces.
//!
//! On x86-64 the instance is compiled with AVX2 + FMA enabled (see `instance!` in the parent
//! module), which is how the tests and benchmarks compare it with the hand-written AVX2
//! instance on the same machine; elsewhere it is compiled for the target's baseline.
#![allow(unsafe_code)] // unaligned loads and stores through raw pointers.

use super::Isa;

/// Portable instance. With `PADDED`, partial loads read the whole vector and zero the lanes
/// past the row (the input must extend [`Isa::OVERREAD`] elements past the tensor, which the
/// kernels check); without, they copy exactly the row's lanes, one fixed-size copy per length.
pub(super) struct Portable<const PADDED: bool>;

macro_rules! portable_isa {
    ($t:ty, $n:literal, [$($k:literal),*]) => {
        impl<const PADDED: bool> Isa<$t> for Portable<PADDED> {
            type V = [$t; $n];
            /// The number of active lanes.
            type M = usize;
            const LANES: usize = $n;
            const BLOCK: usize = 8;
            const MERGED: usize = 2;
            const OVERREAD: usize = if PADDED { $n } else { 0 };
            type Exact = Portable<false>;
            type Narrow = Self;
            #[inline(always)]
            unsafe fn zero() -> [$t; $n] {
                [0.0; $n]
            }
            #[inline(always)]
            unsafe fn neg_inf() -> [$t; $n] {
                [<$t>::NEG_INFINITY; $n]
            }
            #[inline(always)]
            unsafe fn splat(x: $t) -> [$t; $n] {
                [x; $n]
            }
            #[inline(always)]
            unsafe fn mask(n: usize) -> usize {
                n
            }
            #[inline(always)]
            unsafe fn load(p: *const $t) -> [$t; $n] {
                // SAFETY: the caller guarantees the `$n` lanes are in bounds.
                unsafe { p.cast::<[$t; $n]>().read_unaligned() }
            }
            #[inline(always)]
            unsafe fn load_part(p: *const $t, m: usize) -> [$t; $n] {
                if !PADDED {
                    // SAFETY: lanes below `m` are in bounds.
                    return unsafe {
                        match m {
                            $($k => load_first::<$t, $n, $k>(p),)*
                            _ => Self::load(p),
                        }
                    };
                }
                // The whole vector: the lanes past `m` hold whatever follows the row, which
                // every caller masks out again. (Zeroing them with a select made the
                // vectoriser assemble each load from four pieces.)
                // SAFETY: the kernels checked that the whole vector is in bounds.
                unsafe { Self::load(p) }
            }
            #[inline(always)]
            unsafe fn store(p: *mut $t, v: [$t; $n]) {
                // SAFETY: the caller guarantees the `$n` lanes are in bounds.
                unsafe { p.cast::<[$t; $n]>().write_unaligned(v) }
            }
            #[inline(always)]
            unsafe fn store_part(p: *mut $t, v: [$t; $n], _m: usize, n: usize) {
                // SAFETY: lanes below `n` are in bounds.
                unsafe {
                    match n {
                        $($k => store_first::<$t, $n, $k>(p, v),)*
                        _ => Self::store(p, v),
                    }
                }
            }
            #[inline(always)]
            unsafe fn equal_bits(v: [$t; $n], t: $t, m: usize) -> u64 {
                // `&` on the two tests, not `&&`: no branch per lane. (Only the default
                // searches call this, and the instance overrides both.)
                let mut bits = 0u64;
                for (i, &x) in v.iter().enumerate() {
                    bits |= u64::from((i < m) & (x == t)) << i;
                }
                bits
            }
            /// The lowest matching index by a lane-wise minimum over the vectors, then one
            /// across the lanes: vector compares, blends and minima. (The default's bit mask
            /// has no vector form here: the vectoriser widened every lane's bit to 64 bits.)
            #[inline(always)]
            unsafe fn first_equal<const NV: usize>(
                acc: &[[$t; $n]; NV],
                t: $t,
                m: usize,
            ) -> Option<usize> {
                first_equal_block(acc, t, m)
            }
            /// As [`Isa::first_equal`]: lane-wise minima of the matching indices over the
            /// rows, then one across the lanes.
            #[inline(always)]
            unsafe fn first_equal_rows(
                rows: &[[$t; $n]],
                t: $t,
                m: usize,
                row_len: usize,
            ) -> Option<usize> {
                first_equal_in_rows(rows, t, m, row_len)
            }
            #[inline(always)]
            unsafe fn fma(a: [$t; $n], b: [$t; $n], c: [$t; $n]) -> [$t; $n] {
                let mut r = c;
                for i in 0..$n {
                    r[i] = a[i].mul_add(b[i], c[i]);
                }
                r
            }
            #[inline(always)]
            unsafe fn max(a: [$t; $n], b: [$t; $n]) -> [$t; $n] {
                let mut r = b;
                for i in 0..$n {
                    r[i] = if a[i] > b[i] { a[i] } else { b[i] };
                }
                r
            }
            #[inline(always)]
            unsafe fn abs(a: [$t; $n]) -> [$t; $n] {
                let mut r = a;
                for x in &mut r {
                    *x = x.abs();
                }
                r
            }
            #[inline(always)]
            unsafe fn reduce_max(v: [$t; $n], m: usize) -> $t {
                // The vector passes through memory first (`black_box`, a store and a load):
                // without it, LLVM's SLP vectoriser built the reduction's halving tree (4,
                // then 2 lanes wide) back through the register block's multiply-adds, which
                // it then ran two lanes at a time with the accumulators on the stack (a plain
                // full backup 0.25 s instead of 0.19 s; BENCHMARKS.md). Only speed depends on
                // it: the values are the same either way.
                let v = core::hint::black_box(v);
                let mut w = [<$t>::NEG_INFINITY; $n];
                for i in 0..$n {
                    w[i] = if i < m { v[i] } else { <$t>::NEG_INFINITY };
                }
                let mut half = $n / 2;
                while half > 0 {
                    for i in 0..half {
                        w[i] = if w[i + half] > w[i] { w[i + half] } else { w[i] };
                    }
                    half /= 2;
                }
                w[0]
            }
            #[inline(always)]
            unsafe fn load_part_from(v: [$t; $n], m: usize) -> [$t; $n] {
                // A select on the lane index (a compare and a blend), as in `load_part`: a
                // loop from `m` stored lane by lane to the stack and stalled the reload.
                let mut r = v;
                #[allow(clippy::needless_range_loop)] // this form vectorises; iterators did not
                for i in 0..$n {
                    r[i] = if i < m { v[i] } else { <$t>::NEG_INFINITY };
                }
                r
            }
            #[inline(always)]
            unsafe fn fma1(a: $t, b: $t, c: $t) -> $t {
                a.mul_add(b, c)
            }
            #[inline(always)]
            unsafe fn max1(a: $t, b: $t) -> $t {
                if a >= b { a } else { b }
            }
        }
    };
}
portable_isa!(f32, 8, [1, 2, 3, 4, 5, 6, 7]);
portable_isa!(f64, 4, [1, 2, 3]);

/// [`Isa::first_equal`] of the portable instance: lane-wise minima of the matching indices
/// over the block's vectors (the last vector's lanes from `m` on never match), then one across
/// the lanes.
#[inline(always)]
fn first_equal_block<T: Copy + PartialEq, const N: usize, const NV: usize>(
    acc: &[[T; N]; NV],
    t: T,
    m: usize,
) -> Option<usize> {
    let mut low = [u32::MAX; N];
    // Lanes past `m` in the last vector never match.
    let past = past_lanes::<N>(m);
    // The vectors one by one, unrolled by hand: as a loop, the vectoriser kept the block in
    // memory (the loop's scalar body was too large to unroll).
    macro_rules! vectors {
        ($($j:literal)*) => {$(
            if $j < NV {
                let off = if $j + 1 == NV { past } else { [0; N] };
                min_step(&mut low, &acc[$j], t, ($j * N) as u32, &off);
            }
        )*};
    }
    vectors!(0 1 2 3 4 5 6 7);
    for j in 8..NV {
        let off = if j + 1 == NV { past } else { [0; N] };
        min_step(&mut low, &acc[j], t, (j * N) as u32, &off);
    }
    lowest(low)
}

/// [`Isa::first_equal_rows`] of the portable instance: as [`first_equal_block`], every row's
/// lanes from `m` on never matching; the first eight rows unrolled (each behind a test of the
/// row count, the same for every core of a run).
#[inline(always)]
fn first_equal_in_rows<T: Copy + PartialEq, const N: usize>(
    rows: &[[T; N]],
    t: T,
    m: usize,
    row_len: usize,
) -> Option<usize> {
    let mut low = [u32::MAX; N];
    let past = past_lanes::<N>(m);
    macro_rules! rows {
        ($($r:literal)*) => {$(
            if $r < rows.len() {
                min_step(&mut low, &rows[$r], t, ($r * row_len) as u32, &past);
            }
        )*};
    }
    rows!(0 1 2 3 4 5 6 7);
    for (r, x) in rows.iter().enumerate().skip(8) {
        min_step(&mut low, x, t, (r * row_len) as u32, &past);
    }
    lowest(low)
}

/// All ones in the lanes from `m` on (or-ed into their indices, they never win a minimum),
/// zero below.
#[inline(always)]
fn past_lanes<const N: usize>(m: usize) -> [u32; N] {
    let mut past = [0u32; N];
    for (i, p) in past.iter_mut().enumerate() {
        *p = if (i as u32) < m as u32 { 0 } else { u32::MAX };
    }
    past
}

/// Lane `i` of `x` equal to `t` offers index `base + i`, or-ed with `off[i]` (all ones for a
/// lane that must not match), to the lane-wise minima `low`.
#[inline(always)]
fn min_step<T: Copy + PartialEq, const N: usize>(
    low: &mut [u32; N],
    x: &[T; N],
    t: T,
    base: u32,
    off: &[u32; N],
) {
    for i in 0..N {
        let idx = (base + i as u32) | off[i];
        low[i] = low[i].min(if x[i] == t { idx } else { u32::MAX });
    }
}

/// The least of the lane-wise minima `low` (a tree of vector minima), `None` if every lane
/// is all ones (no match).
#[inline(always)]
fn lowest<const N: usize>(mut low: [u32; N]) -> Option<usize> {
    let mut half = N / 2;
    while half > 0 {
        for i in 0..half {
            low[i] = low[i].min(low[i + half]);
        }
        half /= 2;
    }
    (low[0] != u32::MAX).then_some(low[0] as usize)
}

/// The first `K` lanes from `p`, the others zero.
///
/// # Safety
/// `K` values from `p` must be readable; `K <= N`.
#[inline(always)]
unsafe fn load_first<T: Copy + Default, const N: usize, const K: usize>(p: *const T) -> [T; N] {
    let mut v = [T::default(); N];
    // SAFETY: the caller's contract.
    let head = unsafe { p.cast::<[T; K]>().read_unaligned() };
    v[..K].copy_from_slice(&head);
    v
}

/// Stores the first `K` lanes of `v` at `p`.
///
/// # Safety
/// `K` values from `p` must be writable; `K <= N`.
#[inline(always)]
unsafe fn store_first<T: Copy + Default, const N: usize, const K: usize>(p: *mut T, v: [T; N]) {
    let mut head = [T::default(); K];
    head.copy_from_slice(&v[..K]);
    // SAFETY: the caller's contract.
    unsafe { p.cast::<[T; K]>().write_unaligned(head) }
}
