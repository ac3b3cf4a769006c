//! Runtime-dispatched kernels of the block backup.
//!
//! Two kernels carry nearly all of a sweep's arithmetic:
//! - [`Kernels::stage`]: one contraction stage, `out[(r A + a) P + p] = sum_e w_e in[(k_e R + r) P + p]`
//!   over the sparse rows of one block core (the same product as
//!   [`crate::backup::contract`]); [`Kernels::stage_at`] reads its input at any strides
//!   `in[k_e K + r S + p]` (the greedy decisions of `crate::view` read `V` in place);
//! - [`Kernels::last`]: the last stage fused with the maximum over actions: for each core `c`
//!   of the last block, `max_{a, p} sum_e w_e in[k_e P + p]` (or of its absolute value), so the
//!   per-core row of 625 expected values is never written out; it can also return each core's
//!   lowest maximising action in the same pass;
//! - [`Kernels::eval`] and [`Kernels::eval_pair`]: the last stage, or the last two, for one given
//!   action per core (the evaluation sweeps of modified policy iteration).
//!
//! Both are written once, generic over a small [`Isa`] trait (vector type, masked loads and
//! stores, fused multiply-add, maximum), and instantiated for AVX-512F, AVX2 + FMA, portable
//! arrays the compiler vectorises (`portable`, no intrinsics: the fast path off x86-64) and
//! scalar code, in `f32` and `f64`. The instance is chosen at run time from the CPU's features (a
//! distributed binary cannot assume the build machine's CPU); [`super::Kernel`] forces one,
//! for tests and benchmarks.
//!
//! Every instance sums the entries of a row in the same order with fused multiply-adds
//! (`acc = fma(w_e, x_e, acc)` from `acc = 0`), and fused multiply-add is exactly rounded, so
//! all instances return **bit-identical** results; the tests check that.
//!
//! Register blocking: a row is processed in blocks of up to 8 vectors (6 for AVX2 in `f64`)
//! kept in registers while every entry's input row streams through, so each loaded vector
//! feeds one fused multiply-add and nothing else touches memory. (Eight AVX2 `f32` vectors
//! took 17% less time than six on a Zen 3 host: `BENCHMARKS.md`.) The last vector of a block
//! is masked, so rows need no padding; inputs padded by [`INPUT_PAD`] elements let the portable
//! instance load whole vectors there too.
#![allow(unsafe_code)] // SIMD intrinsics: unaligned loads and stores through raw pointers.

use std::sync::OnceLock;
use std::vec::Vec;

use crate::real::Real;

/// Sparse rows whose columns are all below `n_cols`, validated once when built.
#[derive(Clone, Debug)]
pub(super) struct RowsBuf<T> {
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: Vec<T>,
    n_cols: usize,
}

/// A borrowed view of [`RowsBuf`]; only `RowsBuf::view` makes one, so the column bound holds.
#[derive(Clone, Copy, Debug)]
pub struct Rows<'a, T> {
    ptr: &'a [u32],
    col: &'a [u32],
    weight: &'a [T],
    n_cols: usize,
}

impl<T: Real> RowsBuf<T> {
    /// Validates compressed rows: `ptr` non-decreasing from 0 to `col.len()`, `col` and
    /// `weight` of equal length, every column below `n_cols`, every weight finite and
    /// non-negative (memberships; the last stage's pruning relies on it). `None` otherwise.
    pub(super) fn new(ptr: Vec<u32>, col: Vec<u32>, weight: Vec<T>, n_cols: usize) -> Option<Self> {
        Rows::checked(&ptr, &col, &weight, n_cols)?;
        Some(Self {
            ptr,
            col,
            weight,
            n_cols,
        })
    }

    pub(super) fn view(&self) -> Rows<'_, T> {
        Rows {
            ptr: &self.ptr,
            col: &self.col,
            weight: &self.weight,
            n_cols: self.n_cols,
        }
    }

    /// Number of entries.
    pub(super) fn nnz(&self) -> usize {
        self.col.len()
    }
}

impl<'a, T: Real> Rows<'a, T> {
    /// A view of borrowed compressed rows after the checks of [`RowsBuf::new`] (`None` if
    /// one fails).
    pub(crate) fn checked(
        ptr: &'a [u32],
        col: &'a [u32],
        weight: &'a [T],
        n_cols: usize,
    ) -> Option<Self> {
        let ok = !ptr.is_empty()
            && ptr[0] == 0
            && ptr.windows(2).all(|w| w[0] <= w[1])
            && *ptr.last()? as usize == col.len()
            && col.len() == weight.len()
            && col.iter().all(|&k| (k as usize) < n_cols)
            && weight.iter().all(|w| w.is_finite() && *w >= T::ZERO);
        ok.then_some(Self {
            ptr,
            col,
            weight,
            n_cols,
        })
    }
}

impl<'a, T> Rows<'a, T> {
    pub(super) fn n_rows(&self) -> usize {
        self.ptr.len() - 1
    }

    #[inline(always)]
    pub(super) fn row(&self, i: usize) -> (&'a [u32], &'a [T]) {
        let (s, e) = (self.ptr[i] as usize, self.ptr[i + 1] as usize);
        (&self.col[s..e], &self.weight[s..e])
    }
}

/// Where a stage reads its input: entry column `k`, leading index `r` and lane `p` at
/// `input[k * k_stride + r * r_stride + p]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Strides {
    /// Elements between consecutive columns.
    pub k_stride: usize,
    /// Elements between consecutive leading indices.
    pub r_stride: usize,
}

impl Strides {
    /// The dense layout `in[(k R + r) P + p]` of `r_len` leading indices of `p_len` lanes.
    #[inline]
    #[must_use]
    pub const fn dense(r_len: usize, p_len: usize) -> Self {
        Self {
            k_stride: r_len * p_len,
            r_stride: p_len,
        }
    }
}

/// One stage at any input strides: `out[(r A + a) P + p] = sum_e w_e in[k_e K + r S + p]`
/// (`K`, `S` = `strides`) over rows `first_row..first_row + A`, each sum in row order with
/// fused multiply-adds from 0.
#[allow(clippy::too_many_arguments)] // the stage's shape and buffers, spelled out
pub type StageFn<T> = fn(
    rows: Rows<'_, T>,
    first_row: usize,
    n_actions: usize,
    r_len: usize,
    p_len: usize,
    strides: Strides,
    input: &[T],
    out: &mut [T],
);

/// The fused last stage: `out[i] = max_{a,p} (|.| if `abs`) sum_e w_e in[k_e P + p]` over the
/// rows `(first_core + i) A + a`; with `args` (and not `abs`), also each core's lowest
/// `a P + p` whose expected value equals its maximum (the greedy product action).
///
/// `bounds` is scratch of at least [`last_scratch_len`] values.
pub type LastFn<T> = fn(
    rows: Rows<'_, T>,
    first_core: usize,
    n_actions: usize,
    p_len: usize,
    abs: bool,
    input: &[T],
    out: &mut [T],
    bounds: &mut [T],
    args: Option<&mut [u32]>,
);

/// Scratch the last stage needs: one bound per input row and register block (with the
/// narrowest register blocks of any instance).
pub(super) fn last_scratch_len(n_cols: usize, p_len: usize) -> usize {
    // The scalar instance's blocks (4 lanes) are the narrowest.
    n_cols * p_len.div_ceil(4).max(1)
}

/// Elements a kernel's input may extend past the tensor to let every instance use its fastest
/// partial loads (the portable instance reads whole vectors at row tails and discards the
/// extra lanes). Inputs without them are still correct, on exact loads ([`Isa::OVERREAD`]).
pub(super) const INPUT_PAD: usize = 16;

/// Largest block action count for which the last stage prunes rows (a stack array).
const PRUNE_MAX_ACTIONS: usize = 64;

/// The last stage for one given action per core: `out[i] = sum_e w_e in[k_e P + p]` over the
/// row `(first_core + i) A + a`, where `policy[i] = a P + p` is the core's product action.
/// Entries are summed in the row's order with fused multiply-adds from 0, as [`LastFn`] does,
/// so for the greedy action the value is bit-identical to the core's maximum.
pub type EvalFn<T> = fn(
    rows: Rows<'_, T>,
    first_core: usize,
    n_actions: usize,
    p_len: usize,
    input: &[T],
    policy: &[u32],
    out: &mut [T],
);

/// The last two stages for one given action per core: for each core `c` of the last block,
/// with `policy[c] = (a_last A_b + a_b) P + p` and `p = q P_in + p_in` (`prior = (P, P_in)`),
/// `out[c] = sum_{(k, w) in last[c, a_last]} w sum_{(j, v) in block[core_b, a_b]} v in[((q J + j) R + k) P_in + p_in]`
/// (`J` the block's successor cores, `R` the last block's), both sums in row order with fused
/// multiply-adds from 0: the same arithmetic as the stage kernel followed by [`EvalFn`],
/// without computing the stage for every action. `P_in = P` is the stage kernel's layout
/// (`in[(j R + k) P + p]`); a smaller `P_in` reads the earlier stage's actions `q` as the
/// outermost index, the layout of a stage computed action by action along whole rows.
///
/// With `P_in = 1` (the input `[q][j][k]`, the last block's successors contiguous), the cores'
/// second-to-last stages are shared: each distinct (block action, `q`) pair of the cores'
/// actions is contracted once over every successor core `k` in vectors (the same chains, in
/// `scratch`), then each core sums its last row over it. `scratch` must hold
/// [`PairScratch::lens`] elements for this; with less, or `P_in > 1`, every core sums its own
/// products (the same bits).
pub type EvalPairFn<T> = fn(
    block: Rows<'_, T>,
    core_b: usize,
    last: Rows<'_, T>,
    n_actions: (usize, usize),
    prior: (usize, usize),
    input: &[T],
    policy: &[u32],
    out: &mut [T],
    scratch: PairScratch<'_, T>,
);

/// Scratch of [`EvalPairFn`]'s shared path.
pub struct PairScratch<'a, T> {
    /// The shared second-to-last stages, one row of successor cores each.
    pub inner: &'a mut [T],
    /// Per (block action, `q`): its row in `inner`, or `u32::MAX`.
    pub slots: &'a mut [u32],
}

impl<T> PairScratch<'_, T> {
    /// `(inner, slots)` lengths for `n` cores, `na_b` block actions, `p_len` prior actions and
    /// `r_len` successor cores of the last block.
    pub(crate) fn lens(n: usize, na_b: usize, p_len: usize, r_len: usize) -> (usize, usize) {
        let keys = na_b * p_len;
        (keys.min(n) * r_len, keys)
    }
}

/// The throughput probe: `iters` rounds of [`PEAK_CHAINS`] independent vector chains
/// `x = fma(x, a, b)` from `x = seed` (kept in registers, no memory traffic); returns the
/// largest final value so the work cannot be optimised away.
pub type PeakFn<T> = fn(iters: usize, seed: T, a: T, b: T) -> T;

/// Independent chains in the throughput probe: enough to cover the latency of every current
/// CPU's fused multiply-add units (two units of 4-cycle latency need 8).
pub(super) const PEAK_CHAINS: usize = 12;

/// The kernels of one instruction set for one scalar type.
pub struct Kernels<T> {
    /// `"avx512"`, `"avx2"`, `"portable"` or `"scalar"`.
    pub(super) name: &'static str,
    /// Lanes per vector.
    pub(super) lanes: usize,
    /// The fused multiply-add throughput probe ([`super::fma_peak`]).
    pub(super) peak: PeakFn<T>,
    /// One contraction stage at any input strides ([`Kernels::stage`] is the dense layout).
    pub(crate) stage_at: StageFn<T>,
    /// The last stage fused with the maximum (and the lowest maximiser).
    pub(super) last: LastFn<T>,
    /// The last stage for one given action per core (policy evaluation).
    pub(super) eval: EvalFn<T>,
    /// The last two stages for one given action per core.
    pub(super) eval_pair: EvalPairFn<T>,
}

impl<T> Kernels<T> {
    /// One contraction stage on the dense layout: `out[(r A + a) P + p] = sum_e w_e
    /// in[(k_e R + r) P + p]` (see the [module docs](self)).
    #[allow(clippy::too_many_arguments)] // the stage's shape and buffers, spelled out
    #[inline]
    pub(crate) fn stage(
        &self,
        rows: Rows<'_, T>,
        first_row: usize,
        n_actions: usize,
        r_len: usize,
        p_len: usize,
        input: &[T],
        out: &mut [T],
    ) {
        let strides = Strides::dense(r_len, p_len);
        (self.stage_at)(
            rows, first_row, n_actions, r_len, p_len, strides, input, out,
        );
    }
}

/// Elements a stage reads from its input (0 when it reads none): the last column's last
/// leading index's last lane, plus one. Panics on overflow (no valid input is that long).
fn stage_extent<T>(rows: &Rows<'_, T>, r_len: usize, p_len: usize, s: Strides) -> usize {
    if rows.n_cols == 0 || r_len == 0 || p_len == 0 {
        return 0;
    }
    (rows.n_cols - 1)
        .checked_mul(s.k_stride)
        .and_then(|k| k.checked_add((r_len - 1).checked_mul(s.r_stride)?))
        .and_then(|k| k.checked_add(p_len))
        .expect("stage input extent overflows")
}

#[allow(clippy::too_many_arguments)] // the stage's shape and buffers, spelled out
fn check_stage<T>(
    rows: &Rows<'_, T>,
    first_row: usize,
    na: usize,
    r_len: usize,
    p_len: usize,
    strides: Strides,
    input: &[T],
    out: &[T],
) {
    assert!(first_row + na <= rows.n_rows(), "stage rows out of range");
    assert!(
        stage_extent(rows, r_len, p_len, strides) <= input.len(),
        "stage input too short"
    );
    assert!(r_len * na * p_len <= out.len(), "stage output too short");
}

fn check_last<T>(
    rows: &Rows<'_, T>,
    first_core: usize,
    na: usize,
    p_len: usize,
    input: &[T],
    out: &[T],
) {
    assert!(
        (first_core + out.len()) * na <= rows.n_rows(),
        "last-stage rows out of range"
    );
    assert!(
        rows.n_cols * p_len <= input.len(),
        "last-stage input too short"
    );
    assert!(p_len > 0, "empty rows");
}

/// The vector operations the kernels need. All methods are `unsafe`: they require the CPU
/// features of the instance (the kernels are only entered after detection), and the pointer
/// methods require the addressed lanes to be in bounds.
trait Isa<T: Copy> {
    type V: Copy;
    type M: Copy;
    /// Lanes per vector.
    const LANES: usize;
    /// Vectors per register block.
    const BLOCK: usize;
    /// Elements past a tensor's end that [`Isa::load_part`] may read (and discard): 0 for
    /// instances with masked loads. The kernels run such an instance only on inputs that
    /// long ([`INPUT_PAD`] covers every instance): the stage kernel runs [`Isa::Exact`] on
    /// shorter ones (the first stage reads `V`), the last stage the scalar instance (the block
    /// path always passes it a padded stage buffer; other callers may not).
    const OVERREAD: usize;
    /// The instance's variant without over-reads (`Self` where `OVERREAD` is 0).
    type Exact: Isa<T>;
    unsafe fn zero() -> Self::V;
    unsafe fn neg_inf() -> Self::V;
    unsafe fn splat(x: T) -> Self::V;
    /// Mask of the first `n` lanes (`1 <= n <= LANES`).
    unsafe fn mask(n: usize) -> Self::M;
    unsafe fn load(p: *const T) -> Self::V;
    /// Loads the masked lanes; the others are zero and their memory is not read.
    unsafe fn load_part(p: *const T, m: Self::M) -> Self::V;
    unsafe fn store(p: *mut T, v: Self::V);
    /// Stores the masked lanes only (the first `n`, which `m` selects).
    unsafe fn store_part(p: *mut T, v: Self::V, m: Self::M, n: usize);
    /// The first masked lane equal to `t`.
    unsafe fn first_equal(v: Self::V, t: T, m: Self::M) -> Option<usize>;
    unsafe fn fma(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    unsafe fn max(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn abs(a: Self::V) -> Self::V;
    /// Maximum over the masked lanes.
    unsafe fn reduce_max(v: Self::V, m: Self::M) -> T;
    /// `v` with the lanes outside `m` set to minus infinity.
    unsafe fn load_part_from(v: Self::V, m: Self::M) -> Self::V;
    /// Scalar fused multiply-add (for rows of one lane).
    unsafe fn fma1(a: T, b: T, c: T) -> T;
    unsafe fn max1(a: T, b: T) -> T;
}

/// One register block of one row: `acc[j] = sum_e w_e x_e[j]` over `NE` entries whose input
/// rows start at `xs[e]`. Entries are added in order, each as a fused multiply-add.
#[inline(always)]
unsafe fn accumulate<T: Copy, I: Isa<T>, const NV: usize, const NE: usize>(
    xs: &[*const T; NE],
    ws: &[I::V; NE],
    m: I::M,
) -> [I::V; NV] {
    unsafe {
        let mut acc = [I::zero(); NV];
        for e in 0..NE {
            for (j, a) in acc.iter_mut().enumerate() {
                let p = xs[e].add(j * I::LANES);
                let v = if j + 1 == NV {
                    I::load_part(p, m)
                } else {
                    I::load(p)
                };
                *a = I::fma(ws[e], v, *a);
            }
        }
        acc
    }
}

/// [`accumulate`] for a row of any length (more entries than the unrolled cases).
#[inline(always)]
unsafe fn accumulate_any<T: Copy, I: Isa<T>, const NV: usize>(
    cols: &[u32],
    ws: &[T],
    base: *const T,
    k_stride: usize,
    m: I::M,
) -> [I::V; NV] {
    unsafe {
        let mut acc = [I::zero(); NV];
        for (&k, &w) in cols.iter().zip(ws) {
            let wv = I::splat(w);
            let x = base.add(k as usize * k_stride);
            for (j, a) in acc.iter_mut().enumerate() {
                let p = x.add(j * I::LANES);
                let v = if j + 1 == NV {
                    I::load_part(p, m)
                } else {
                    I::load(p)
                };
                *a = I::fma(wv, v, *a);
            }
        }
        acc
    }
}

/// [`accumulate_any`] for `NR` consecutive leading indices (`r_stride` apart) at once: one
/// chain per index and vector, each summing the entries in order.
#[inline(always)]
unsafe fn accumulate_any_rows<T: Copy, I: Isa<T>, const NV: usize, const NR: usize>(
    cols: &[u32],
    ws: &[T],
    base: *const T,
    (k_stride, r_stride): (usize, usize),
    m: I::M,
) -> [[I::V; NV]; NR] {
    unsafe {
        let mut acc = [[I::zero(); NV]; NR];
        for (&k, &w) in cols.iter().zip(ws) {
            let wv = I::splat(w);
            let x = base.add(k as usize * k_stride);
            for (i, row) in acc.iter_mut().enumerate() {
                for (j, a) in row.iter_mut().enumerate() {
                    let p = x.add(i * r_stride + j * I::LANES);
                    let v = if j + 1 == NV {
                        I::load_part(p, m)
                    } else {
                        I::load(p)
                    };
                    *a = I::fma(wv, v, *a);
                }
            }
        }
        acc
    }
}

/// Stores one register block (the last vector masked).
#[inline(always)]
unsafe fn store_block<T: Copy, I: Isa<T>, const NV: usize>(
    o: *mut T,
    acc: &[I::V; NV],
    m: I::M,
    tail: usize,
) {
    unsafe {
        for (j, &v) in acc.iter().enumerate() {
            if j + 1 == NV {
                I::store_part(o.add(j * I::LANES), v, m, tail);
            } else {
                I::store(o.add(j * I::LANES), v);
            }
        }
    }
}

/// Stage rows of one action with exactly `NE` entries: pointers and broadcast weights are
/// set up once and advance along `r`.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn stage_rows<T: Copy, I: Isa<T>, const NV: usize, const NE: usize>(
    cols: &[u32],
    ws: &[T],
    input: *const T,
    k_stride: usize,
    in_step: usize,
    r_len: usize,
    out: *mut T,
    out_step: usize,
    m: I::M,
    tail: usize,
) {
    unsafe {
        let mut xs = [input; NE];
        let mut wv = [I::zero(); NE];
        for e in 0..NE {
            xs[e] = input.add(cols[e] as usize * k_stride);
            wv[e] = I::splat(ws[e]);
        }
        let mut o = out;
        for _ in 0..r_len {
            let acc = accumulate::<T, I, NV, NE>(&xs, &wv, m);
            store_block::<T, I, NV>(o, &acc, m, tail);
            for x in xs.iter_mut() {
                *x = x.add(in_step);
            }
            o = o.add(out_step);
        }
    }
}

/// Stage body for one register block of `NV` vectors at offset `p0` of every output row.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn stage_block<T: Copy, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    first_row: usize,
    na: usize,
    (r_len, p_len): (usize, usize),
    strides: Strides,
    p0: usize,
    m: I::M,
    tail: usize,
    input: *const T,
    out: *mut T,
) {
    unsafe {
        let Strides { k_stride, r_stride } = strides;
        let out_step = na * p_len;
        // Narrow rows: several leading indices at a time (8 chains in all, enough to hide
        // the fused multiply-add's latency), every action's row on them before the next
        // (their inputs stay in the first-level cache).
        if NV == 1 && r_len >= 8 {
            return stage_narrow::<T, I, NV, 8>(
                rows,
                first_row,
                na,
                (r_len, p_len),
                strides,
                p0,
                m,
                tail,
                input,
                out,
            );
        }
        if NV == 2 && r_len >= 4 {
            return stage_narrow::<T, I, NV, 4>(
                rows,
                first_row,
                na,
                (r_len, p_len),
                strides,
                p0,
                m,
                tail,
                input,
                out,
            );
        }
        for a in 0..na {
            let (cols, ws) = rows.row(first_row + a);
            let inp = input.add(p0);
            let o = out.add(a * p_len + p0);
            match cols.len() {
                0 => {
                    let zero = [I::zero(); NV];
                    for r in 0..r_len {
                        store_block::<T, I, NV>(o.add(r * out_step), &zero, m, tail);
                    }
                }
                1 => stage_rows::<T, I, NV, 1>(
                    cols, ws, inp, k_stride, r_stride, r_len, o, out_step, m, tail,
                ),
                2 => stage_rows::<T, I, NV, 2>(
                    cols, ws, inp, k_stride, r_stride, r_len, o, out_step, m, tail,
                ),
                3 => stage_rows::<T, I, NV, 3>(
                    cols, ws, inp, k_stride, r_stride, r_len, o, out_step, m, tail,
                ),
                4 => stage_rows::<T, I, NV, 4>(
                    cols, ws, inp, k_stride, r_stride, r_len, o, out_step, m, tail,
                ),
                _ => {
                    for r in 0..r_len {
                        let acc = accumulate_any::<T, I, NV>(
                            cols,
                            ws,
                            inp.add(r * r_stride),
                            k_stride,
                            m,
                        );
                        store_block::<T, I, NV>(o.add(r * out_step), &acc, m, tail);
                    }
                }
            }
        }
    }
}

/// [`stage_block`] for narrow rows, `NR` leading indices at a time (`r_len >= NR`): the last
/// `NR` end at `r_len`, computing a few rows twice (the same values).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn stage_narrow<T: Copy, I: Isa<T>, const NV: usize, const NR: usize>(
    rows: &Rows<'_, T>,
    first_row: usize,
    na: usize,
    (r_len, p_len): (usize, usize),
    strides: Strides,
    p0: usize,
    m: I::M,
    tail: usize,
    input: *const T,
    out: *mut T,
) {
    unsafe {
        let Strides { k_stride, r_stride } = strides;
        let out_step = na * p_len;
        let mut r = 0;
        while r < r_len {
            let at = r.min(r_len - NR);
            for a in 0..na {
                let (cols, ws) = rows.row(first_row + a);
                let accs = accumulate_any_rows::<T, I, NV, NR>(
                    cols,
                    ws,
                    input.add(p0 + at * r_stride),
                    (k_stride, r_stride),
                    m,
                );
                let o = out.add(a * p_len + p0);
                for (i, acc) in accs.iter().enumerate() {
                    store_block::<T, I, NV>(o.add((at + i) * out_step), acc, m, tail);
                }
            }
            r = at + NR;
        }
    }
}

/// Splits a row of `p_len` lanes into register blocks: `(vectors, offset, lanes in the last
/// vector)`. An iterator, not a callback: closures do not inherit `#[target_feature]`, and the
/// intrinsics must inline into the feature-enabled kernel.
struct Blocks {
    p_len: usize,
    lanes: usize,
    block: usize,
    p0: usize,
}

impl Blocks {
    #[inline(always)]
    fn new(p_len: usize, lanes: usize, block: usize) -> Self {
        Self {
            p_len,
            lanes,
            block,
            p0: 0,
        }
    }
}

impl Iterator for Blocks {
    type Item = (usize, usize, usize);

    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        if self.p0 >= self.p_len {
            return None;
        }
        let rem = self.p_len - self.p0;
        let nv = rem.div_ceil(self.lanes).min(self.block);
        let span = (nv * self.lanes).min(rem);
        let item = (nv, self.p0, span - (nv - 1) * self.lanes);
        self.p0 += span;
        Some(item)
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)] // the stage's shape and buffers, spelled out
unsafe fn stage_impl<T: Real, I: Isa<T>>(
    rows: Rows<'_, T>,
    first_row: usize,
    na: usize,
    r_len: usize,
    p_len: usize,
    strides: Strides,
    input: &[T],
    out: &mut [T],
) {
    check_stage(&rows, first_row, na, r_len, p_len, strides, input, out);
    let ip = input.as_ptr();
    let op = out.as_mut_ptr();
    let Strides { k_stride, r_stride } = strides;
    unsafe {
        if p_len == 1 {
            // Rows of one value (the first stage): scalar fused multiply-adds along `r`.
            for a in 0..na {
                let (cols, ws) = rows.row(first_row + a);
                for r in 0..r_len {
                    let mut acc = T::ZERO;
                    for (&k, &w) in cols.iter().zip(ws) {
                        acc = I::fma1(w, *ip.add(k as usize * k_stride + r * r_stride), acc);
                    }
                    *op.add(r * na + a) = acc;
                }
            }
            return;
        }
        if I::OVERREAD > 0 && input.len() < stage_extent(&rows, r_len, p_len, strides) + I::OVERREAD
        {
            // Vector loads on an unpadded input (the first stage reads `V` this way): the
            // instance's exact variant (rows of one value, above, never load vectors).
            return stage_impl::<T, I::Exact>(
                rows, first_row, na, r_len, p_len, strides, input, out,
            );
        }
        for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::BLOCK) {
            let m = I::mask(tail);
            let args = (
                &rows,
                first_row,
                na,
                (r_len, p_len),
                strides,
                p0,
                m,
                tail,
                ip,
                op,
            );
            match nv {
                1 => stage_block::<T, I, 1>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                2 => stage_block::<T, I, 2>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                3 => stage_block::<T, I, 3>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                4 => stage_block::<T, I, 4>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                5 => stage_block::<T, I, 5>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                6 => stage_block::<T, I, 6>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                7 => stage_block::<T, I, 7>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
                _ => stage_block::<T, I, 8>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8, args.9,
                ),
            }
        }
    }
}

/// The expected values of one (core, action) row for one register block.
#[inline(always)]
unsafe fn row_block<T: Copy, I: Isa<T>, const NV: usize>(
    cols: &[u32],
    ws: &[T],
    input: *const T,
    p_len: usize,
    m: I::M,
) -> [I::V; NV] {
    macro_rules! fixed {
        ($ne:literal) => {{
            let mut xs = [input; $ne];
            let mut wv = [I::zero(); $ne];
            for e in 0..$ne {
                xs[e] = input.add(cols[e] as usize * p_len);
                wv[e] = I::splat(ws[e]);
            }
            accumulate::<T, I, NV, $ne>(&xs, &wv, m)
        }};
    }
    unsafe {
        match cols.len() {
            1 => fixed!(1),
            2 => fixed!(2),
            3 => fixed!(3),
            4 => fixed!(4),
            _ => accumulate_any::<T, I, NV>(cols, ws, input, p_len, m),
        }
    }
}

/// Last-stage body for one register block: the running maximum over every action's row.
#[inline(always)]
unsafe fn last_block<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    p_len: usize,
    p0: usize,
    m: I::M,
    input: *const T,
) -> T {
    unsafe {
        let mut best = [I::neg_inf(); NV];
        for a in 0..na {
            let (cols, ws) = rows.row(c * na + a);
            let acc = row_block::<T, I, NV>(cols, ws, input.add(p0), p_len, m);
            for (b, &v) in best.iter_mut().zip(&acc) {
                *b = I::max(*b, if ABS { I::abs(v) } else { v });
            }
        }
        let all = I::mask(I::LANES);
        let mut out = I::reduce_max(best[NV - 1], m);
        for &b in &best[..NV - 1] {
            out = I::max1(out, I::reduce_max(b, all));
        }
        out
    }
}

/// The lowest `a * p_len + p` whose expected value equals `target` in one register block,
/// scanning actions in order (`None` if no lane matches).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn argmax_block<T: Copy, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    c: usize,
    a: usize,
    na: usize,
    p_len: usize,
    p0: usize,
    m: I::M,
    input: *const T,
    target: T,
) -> Option<usize> {
    unsafe {
        let (cols, ws) = rows.row(c * na + a);
        let acc = row_block::<T, I, NV>(cols, ws, input.add(p0), p_len, m);
        let all = I::mask(I::LANES);
        for (j, &v) in acc.iter().enumerate() {
            let mask = if j + 1 == NV { m } else { all };
            if let Some(lane) = I::first_equal(v, target, mask) {
                return Some(a * p_len + p0 + j * I::LANES + lane);
            }
        }
        None
    }
}

/// The maximum (of the absolute value if `ABS`) over the valid lanes of one register block of
/// one input row.
#[inline(always)]
unsafe fn row_bound<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    x: *const T,
    m: I::M,
) -> T {
    unsafe {
        // The lanes' maxima in a vector, then one horizontal reduction (the maximum is exact
        // in any order); the masked-off lanes of the last vector are minus infinity.
        let mut top = I::neg_inf();
        for j in 0..NV {
            let last = j + 1 == NV;
            let v = if last {
                I::load_part(x.add(j * I::LANES), m)
            } else {
                I::load(x.add(j * I::LANES))
            };
            let v = if ABS { I::abs(v) } else { v };
            top = I::max(top, if last { I::load_part_from(v, m) } else { v });
        }
        I::reduce_max(top, I::mask(I::LANES))
    }
}

/// The maximum over the valid lanes of one (core, action) row in one register block.
#[inline(always)]
unsafe fn row_max<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    cols: &[u32],
    ws: &[T],
    input: *const T,
    p_len: usize,
    m: I::M,
) -> T {
    unsafe {
        let acc = row_block::<T, I, NV>(cols, ws, input, p_len, m);
        let all = I::mask(I::LANES);
        let mut best = I::neg_inf();
        for (j, &v) in acc.iter().enumerate() {
            let v = if ABS { I::abs(v) } else { v };
            if j + 1 == NV {
                best = I::max(best, I::load_part_from(v, m));
            } else {
                best = I::max(best, v);
            }
        }
        I::reduce_max(best, all)
    }
}

/// One register block of the last stage for core `c`, pruned: rows are visited in decreasing
/// order of an upper bound of their values, and the visit stops at the first row whose bound
/// does not exceed the best value found. Memberships are non-negative and fused multiply-add rounds
/// monotonically, so `fma(w_e, bound_e, ...)` (the same chain as the row's) bounds every
/// computed value of the row: the result is bit-identical to visiting every row.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn last_block_pruned<T: Real, I: Isa<T>, const NV: usize, const ABS: bool>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    p_len: usize,
    p0: usize,
    m: I::M,
    input: *const T,
    bounds: &[T],
    mut best: T,
) -> T {
    unsafe {
        let mut ub = [T::ZERO; PRUNE_MAX_ACTIONS];
        let mut order = [0u8; PRUNE_MAX_ACTIONS];
        for a in 0..na {
            let (cols, ws) = rows.row(c * na + a);
            let mut b = T::ZERO;
            for (&k, &w) in cols.iter().zip(ws) {
                b = I::fma1(w, bounds[k as usize], b);
            }
            // Insertion into `order`, by decreasing bound.
            let mut i = a;
            while i > 0 && ub[order[i - 1] as usize] < b {
                order[i] = order[i - 1];
                i -= 1;
            }
            order[i] = a as u8;
            ub[a] = b;
        }
        for &a in &order[..na] {
            let a = a as usize;
            // A row whose bound does not exceed the best cannot raise the maximum.
            if ub[a] <= best {
                break;
            }
            let (cols, ws) = rows.row(c * na + a);
            let v = row_max::<T, I, NV, ABS>(cols, ws, input.add(p0), p_len, m);
            best = I::max1(best, v);
        }
        best
    }
}

/// [`last_block_pruned`] that also keeps the lowest index `a * p_len + p` holding the
/// maximum (`best_idx`, `usize::MAX` before any). Rows whose bound equals the best so far are
/// still visited (they may tie at a lower index); rows whose bound is below it cannot hold the
/// maximum. The maximum is the same bits as [`last_block_pruned`]'s, and the index the one
/// [`argmax_impl`] finds.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn last_block_pruned_arg<T: Real, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    p_len: usize,
    p0: usize,
    m: I::M,
    input: *const T,
    bounds: &[T],
    (mut best, mut best_idx): (T, usize),
) -> (T, usize) {
    unsafe {
        let mut ub = [T::ZERO; PRUNE_MAX_ACTIONS];
        let mut order = [0u8; PRUNE_MAX_ACTIONS];
        for a in 0..na {
            let (cols, ws) = rows.row(c * na + a);
            let mut b = T::ZERO;
            for (&k, &w) in cols.iter().zip(ws) {
                b = I::fma1(w, bounds[k as usize], b);
            }
            let mut i = a;
            while i > 0 && ub[order[i - 1] as usize] < b {
                order[i] = order[i - 1];
                i -= 1;
            }
            order[i] = a as u8;
            ub[a] = b;
        }
        let all = I::mask(I::LANES);
        for &a in &order[..na] {
            let a = a as usize;
            if ub[a] < best {
                break;
            }
            let (cols, ws) = rows.row(c * na + a);
            let acc = row_block::<T, I, NV>(cols, ws, input.add(p0), p_len, m);
            let mut top = I::neg_inf();
            for (j, &v) in acc.iter().enumerate() {
                top = I::max(
                    top,
                    if j + 1 == NV {
                        I::load_part_from(v, m)
                    } else {
                        v
                    },
                );
            }
            let v = I::reduce_max(top, all);
            if v < best {
                continue;
            }
            let mut idx = usize::MAX;
            for (j, &x) in acc.iter().enumerate() {
                let mask = if j + 1 == NV { m } else { all };
                if let Some(lane) = I::first_equal(x, v, mask) {
                    idx = a * p_len + p0 + j * I::LANES + lane;
                    break;
                }
            }
            if v > best || idx < best_idx {
                best = v;
                best_idx = idx;
            }
        }
        (best, best_idx)
    }
}

macro_rules! by_nv {
    ($nv:expr, $f:ident::<$t:ty, $i:ty, _ $(, $c:ident)*>($($arg:expr),* $(,)?)) => {
        match $nv {
            1 => $f::<$t, $i, 1 $(, $c)*>($($arg),*),
            2 => $f::<$t, $i, 2 $(, $c)*>($($arg),*),
            3 => $f::<$t, $i, 3 $(, $c)*>($($arg),*),
            4 => $f::<$t, $i, 4 $(, $c)*>($($arg),*),
            5 => $f::<$t, $i, 5 $(, $c)*>($($arg),*),
            6 => $f::<$t, $i, 6 $(, $c)*>($($arg),*),
            7 => $f::<$t, $i, 7 $(, $c)*>($($arg),*),
            _ => $f::<$t, $i, 8 $(, $c)*>($($arg),*),
        }
    };
}

#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape and scratch, spelled out
unsafe fn last_impl<T: Real, I: Isa<T>, const ABS: bool>(
    rows: Rows<'_, T>,
    first_core: usize,
    na: usize,
    p_len: usize,
    input: &[T],
    out: &mut [T],
    bounds: &mut [T],
    mut args: Option<&mut [u32]>,
) {
    check_last(&rows, first_core, na, p_len, input, out);
    if let Some(a) = &args {
        assert_eq!(a.len(), out.len(), "one action per core");
    }
    if I::OVERREAD > 0 && input.len() < rows.n_cols * p_len + I::OVERREAD {
        return (scalar::<T>().last)(rows, first_core, na, p_len, ABS, input, out, bounds, args);
    }
    let ip = input.as_ptr();
    let n_cols = rows.n_cols;
    let prune = na <= PRUNE_MAX_ACTIONS;
    if prune {
        let n_blocks = Blocks::new(p_len, I::LANES, I::BLOCK).count();
        assert!(
            bounds.len() >= n_cols * n_blocks,
            "last-stage scratch too short"
        );
    }
    unsafe {
        if prune {
            for (bi, (nv, p0, tail)) in Blocks::new(p_len, I::LANES, I::BLOCK).enumerate() {
                let m = I::mask(tail);
                for k in 0..n_cols {
                    let x = ip.add(k * p_len + p0);
                    bounds[bi * n_cols + k] = by_nv!(nv, row_bound::<T, I, _, ABS>(x, m));
                }
            }
        }
        if let Some(args) = args.as_deref_mut().filter(|_| prune && !ABS) {
            for (i, (o, arg)) in out.iter_mut().zip(args.iter_mut()).enumerate() {
                let c = first_core + i;
                let mut best = (T::from_f64(f64::NEG_INFINITY), usize::MAX);
                for (bi, (nv, p0, tail)) in Blocks::new(p_len, I::LANES, I::BLOCK).enumerate() {
                    let m = I::mask(tail);
                    let b = &bounds[bi * n_cols..(bi + 1) * n_cols];
                    best = by_nv!(
                        nv,
                        last_block_pruned_arg::<T, I, _>(&rows, c, na, p_len, p0, m, ip, b, best)
                    );
                }
                *o = best.0;
                // Every row was computed by the same arithmetic, so some lane holds the maximum.
                *arg = if best.1 == usize::MAX {
                    0
                } else {
                    best.1 as u32
                };
            }
            return;
        }
        for (i, o) in out.iter_mut().enumerate() {
            let c = first_core + i;
            let mut best = T::from_f64(f64::NEG_INFINITY);
            for (bi, (nv, p0, tail)) in Blocks::new(p_len, I::LANES, I::BLOCK).enumerate() {
                let m = I::mask(tail);
                best = if prune {
                    let b = &bounds[bi * n_cols..(bi + 1) * n_cols];
                    by_nv!(
                        nv,
                        last_block_pruned::<T, I, _, ABS>(&rows, c, na, p_len, p0, m, ip, b, best)
                    )
                } else {
                    let v = by_nv!(
                        nv,
                        last_block::<T, I, _, ABS>(&rows, c, na, p_len, p0, m, ip)
                    );
                    I::max1(best, v)
                };
            }
            *o = best;
        }
    }
    if let Some(args) = args {
        // Without pruning (more actions than the stack arrays hold): a separate scan.
        unsafe { argmax_impl::<T, I>(rows, first_core, na, p_len, input, out, args) };
    }
}

#[inline(always)]
unsafe fn argmax_impl<T: Real, I: Isa<T>>(
    rows: Rows<'_, T>,
    first_core: usize,
    na: usize,
    p_len: usize,
    input: &[T],
    maxima: &[T],
    out: &mut [u32],
) {
    assert_eq!(maxima.len(), out.len(), "one maximum per core");
    check_last(&rows, first_core, na, p_len, input, maxima);
    let ip = input.as_ptr();
    unsafe {
        for (i, o) in out.iter_mut().enumerate() {
            let c = first_core + i;
            let target = maxima[i];
            let mut found = None;
            'actions: for a in 0..na {
                let mut hit = None;
                for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::BLOCK) {
                    let m = I::mask(tail);
                    let args = (&rows, c, a, na, p_len, p0, m, ip, target);
                    hit = match nv {
                        1 => argmax_block::<T, I, 1>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        2 => argmax_block::<T, I, 2>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        3 => argmax_block::<T, I, 3>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        4 => argmax_block::<T, I, 4>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        5 => argmax_block::<T, I, 5>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        6 => argmax_block::<T, I, 6>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        7 => argmax_block::<T, I, 7>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                        _ => argmax_block::<T, I, 8>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7, args.8,
                        ),
                    };
                    if hit.is_some() {
                        break;
                    }
                }
                if hit.is_some() {
                    found = hit;
                    break 'actions;
                }
            }
            // The maximum was computed by the same arithmetic, so it is always found.
            *o = found.unwrap_or(0) as u32;
        }
    }
}

#[inline(always)]
unsafe fn eval_impl<T: Real, I: Isa<T>>(
    rows: Rows<'_, T>,
    first_core: usize,
    na: usize,
    p_len: usize,
    input: &[T],
    policy: &[u32],
    out: &mut [T],
) {
    assert_eq!(policy.len(), out.len(), "one action per core");
    check_last(&rows, first_core, na, p_len, input, out);
    for (i, (o, &u)) in out.iter_mut().zip(policy).enumerate() {
        let u = u as usize;
        assert!(
            u < na * p_len,
            "policy action beyond the product action set"
        );
        let (cols, ws) = rows.row((first_core + i) * na + u / p_len);
        let p = u % p_len;
        let mut acc = T::ZERO;
        for (&k, &w) in cols.iter().zip(ws) {
            // SAFETY: `check_last` bounds every column's row of `p_len` values in `input`.
            acc = unsafe { I::fma1(w, *input.get_unchecked(k as usize * p_len + p), acc) };
        }
        *o = acc;
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)] // the kernel's signature
unsafe fn eval_pair_impl<T: Real, I: Isa<T>>(
    block: Rows<'_, T>,
    core_b: usize,
    last: Rows<'_, T>,
    (na_b, na_last): (usize, usize),
    (p_len, p_in): (usize, usize),
    input: &[T],
    policy: &[u32],
    out: &mut [T],
    scratch: PairScratch<'_, T>,
) {
    let r_len = last.n_cols;
    let n = out.len();
    assert_eq!(policy.len(), n, "one action per core");
    assert!(
        (core_b + 1) * na_b <= block.n_rows(),
        "block rows out of range"
    );
    assert!(n * na_last <= last.n_rows(), "last-stage rows out of range");
    assert!(p_len > 0, "empty rows");
    assert!(
        p_in > 0 && p_len.is_multiple_of(p_in),
        "inner prior actions must divide the prior actions"
    );
    assert!(
        block.n_cols * r_len * p_len <= input.len(),
        "stage input too short"
    );
    let q_stride = block.n_cols * r_len;
    let (inner_len, keys) = PairScratch::<T>::lens(n, na_b, p_len, r_len);
    if p_in == 1 && scratch.inner.len() >= inner_len && scratch.slots.len() >= keys {
        // Shared: each (block action, q) once over every successor core, in vectors.
        let PairScratch { inner, slots } = scratch;
        slots[..keys].fill(u32::MAX);
        let mut n_shared = 0usize;
        for (c, (o, &u)) in out.iter_mut().zip(policy).enumerate() {
            let u = u as usize;
            assert!(
                u < na_last * keys,
                "policy action beyond the product action set"
            );
            let (a_last, key) = (u / keys, u % keys);
            let mut slot = slots[key] as usize;
            if slot == u32::MAX as usize {
                slot = n_shared;
                slots[key] = slot as u32;
                n_shared += 1;
                let (a_b, q) = (key / p_len, key % p_len);
                // `inner[slot][k] = sum_j v_j input[(q J + j) R + k]`: the stage kernel's
                // chain for every `k` at once.
                unsafe {
                    stage_impl::<T, I>(
                        block,
                        core_b * na_b + a_b,
                        1,
                        1,
                        r_len,
                        Strides {
                            k_stride: r_len,
                            r_stride: r_len,
                        },
                        &input[q * q_stride..],
                        &mut inner[slot * r_len..(slot + 1) * r_len],
                    );
                }
            }
            let row = &inner[slot * r_len..(slot + 1) * r_len];
            let (cols, ws) = last.row(c * na_last + a_last);
            let mut acc = T::ZERO;
            for (&k, &w) in cols.iter().zip(ws) {
                acc = unsafe { I::fma1(w, row[k as usize], acc) };
            }
            *o = acc;
        }
        return;
    }
    for (c, (o, &u)) in out.iter_mut().zip(policy).enumerate() {
        let u = u as usize;
        assert!(
            u < na_last * na_b * p_len,
            "policy action beyond the product action set"
        );
        let (a_last, rest) = (u / (na_b * p_len), u % (na_b * p_len));
        let (a_b, p) = (rest / p_len, rest % p_len);
        let (q, p) = (p / p_in, p % p_in);
        let (cols_b, ws_b) = block.row(core_b * na_b + a_b);
        let (cols, ws) = last.row(c * na_last + a_last);
        let mut acc = T::ZERO;
        for (&k, &w) in cols.iter().zip(ws) {
            let mut inner = T::ZERO;
            for (&j, &v) in cols_b.iter().zip(ws_b) {
                let at = ((q * q_stride + j as usize * r_len) + k as usize) * p_in + p;
                // SAFETY: `q < p_len / p_in`, `j < block.n_cols` and `k < r_len` (the rows'
                // column bounds), so `at` is below the input length checked above.
                inner = unsafe { I::fma1(v, *input.get_unchecked(at), inner) };
            }
            acc = unsafe { I::fma1(w, inner, acc) };
        }
        *o = acc;
    }
}

#[inline(always)]
unsafe fn peak_impl<T: Real, I: Isa<T>>(iters: usize, seed: T, a: T, b: T) -> T {
    unsafe {
        let (a, b) = (I::splat(a), I::splat(b));
        let mut acc = [I::splat(seed); PEAK_CHAINS];
        for _ in 0..iters {
            for x in &mut acc {
                *x = I::fma(*x, a, b);
            }
        }
        let mut m = acc[0];
        for &x in &acc[1..] {
            m = I::max(m, x);
        }
        I::reduce_max(m, I::mask(I::LANES))
    }
}

/// Scalar instance: one lane, `mul_add` for the fused multiply-add.
struct Scalar;

macro_rules! scalar_isa {
    ($t:ty) => {
        impl Isa<$t> for Scalar {
            type V = $t;
            type M = bool;
            const LANES: usize = 1;
            const BLOCK: usize = 4;
            const OVERREAD: usize = 0;
            type Exact = Self;
            #[inline(always)]
            unsafe fn zero() -> $t {
                0.0
            }
            #[inline(always)]
            unsafe fn neg_inf() -> $t {
                <$t>::NEG_INFINITY
            }
            #[inline(always)]
            unsafe fn splat(x: $t) -> $t {
                x
            }
            #[inline(always)]
            unsafe fn mask(n: usize) -> bool {
                n >= 1
            }
            #[inline(always)]
            unsafe fn load(p: *const $t) -> $t {
                unsafe { *p }
            }
            #[inline(always)]
            unsafe fn load_part(p: *const $t, m: bool) -> $t {
                if m { unsafe { *p } } else { 0.0 }
            }
            #[inline(always)]
            unsafe fn store(p: *mut $t, v: $t) {
                unsafe { *p = v }
            }
            #[inline(always)]
            unsafe fn store_part(p: *mut $t, v: $t, m: bool, _n: usize) {
                if m {
                    unsafe { *p = v }
                }
            }
            #[inline(always)]
            unsafe fn first_equal(v: $t, t: $t, m: bool) -> Option<usize> {
                (m && v == t).then_some(0)
            }
            #[inline(always)]
            unsafe fn fma(a: $t, b: $t, c: $t) -> $t {
                a.mul_add(b, c)
            }
            #[inline(always)]
            unsafe fn max(a: $t, b: $t) -> $t {
                if a >= b { a } else { b }
            }
            #[inline(always)]
            unsafe fn abs(a: $t) -> $t {
                a.abs()
            }
            #[inline(always)]
            unsafe fn reduce_max(v: $t, _m: bool) -> $t {
                v
            }
            #[inline(always)]
            unsafe fn load_part_from(v: $t, m: bool) -> $t {
                if m { v } else { <$t>::NEG_INFINITY }
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
scalar_isa!(f32);
scalar_isa!(f64);

mod portable;
#[cfg(target_arch = "x86_64")]
mod x86;

/// Declares one instance: a module of `unsafe` inner functions compiled with the instance's
/// target features, safe wrappers that check the features (a cached atomic load) before
/// entering them, and the instance's [`Kernels`] as `KERNELS`.
macro_rules! instance {
    ($module:ident, $label:literal, $t:ty, $isa:ty, [$($features:literal)?], $detect:expr) => {
        mod $module {
            use super::*;

            #[allow(clippy::too_many_arguments)] // the kernel's signature
            fn stage_at(
                rows: Rows<'_, $t>,
                first_row: usize,
                na: usize,
                r_len: usize,
                p_len: usize,
                strides: Strides,
                input: &[$t],
                out: &mut [$t],
            ) {
                $(#[target_feature(enable = $features)])?
                #[allow(clippy::too_many_arguments)] // the kernel's signature
                unsafe fn inner(
                    rows: Rows<'_, $t>,
                    first_row: usize,
                    na: usize,
                    r_len: usize,
                    p_len: usize,
                    strides: Strides,
                    input: &[$t],
                    out: &mut [$t],
                ) {
                    unsafe {
                        stage_impl::<$t, $isa>(
                            rows, first_row, na, r_len, p_len, strides, input, out,
                        )
                    }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: the features were just detected; `stage_impl` checks every bound its
                // pointer arithmetic relies on (`check_stage`, and the rows' column bound).
                unsafe { inner(rows, first_row, na, r_len, p_len, strides, input, out) }
            }

            #[allow(clippy::too_many_arguments)] // the kernel's signature
            fn last(
                rows: Rows<'_, $t>,
                first_core: usize,
                na: usize,
                p_len: usize,
                abs: bool,
                input: &[$t],
                out: &mut [$t],
                bounds: &mut [$t],
                args: Option<&mut [u32]>,
            ) {
                $(#[target_feature(enable = $features)])?
                #[allow(clippy::too_many_arguments)] // the kernel's signature
                unsafe fn inner(
                    rows: Rows<'_, $t>,
                    first_core: usize,
                    na: usize,
                    p_len: usize,
                    abs: bool,
                    input: &[$t],
                    out: &mut [$t],
                    bounds: &mut [$t],
                    args: Option<&mut [u32]>,
                ) {
                    unsafe {
                        if abs {
                            last_impl::<$t, $isa, true>(rows, first_core, na, p_len, input, out, bounds, args)
                        } else {
                            last_impl::<$t, $isa, false>(rows, first_core, na, p_len, input, out, bounds, args)
                        }
                    }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: as above, with `check_last` and the scratch length check.
                unsafe { inner(rows, first_core, na, p_len, abs, input, out, bounds, args) }
            }

            fn eval(
                rows: Rows<'_, $t>,
                first_core: usize,
                na: usize,
                p_len: usize,
                input: &[$t],
                policy: &[u32],
                out: &mut [$t],
            ) {
                $(#[target_feature(enable = $features)])?
                unsafe fn inner(
                    rows: Rows<'_, $t>,
                    first_core: usize,
                    na: usize,
                    p_len: usize,
                    input: &[$t],
                    policy: &[u32],
                    out: &mut [$t],
                ) {
                    unsafe { eval_impl::<$t, $isa>(rows, first_core, na, p_len, input, policy, out) }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: as above; `eval_impl` checks the policy's actions and the lengths.
                unsafe { inner(rows, first_core, na, p_len, input, policy, out) }
            }

            #[allow(clippy::too_many_arguments)] // the kernel's signature
            fn eval_pair(
                block: Rows<'_, $t>,
                core_b: usize,
                last: Rows<'_, $t>,
                n_actions: (usize, usize),
                prior: (usize, usize),
                input: &[$t],
                policy: &[u32],
                out: &mut [$t],
                scratch: PairScratch<'_, $t>,
            ) {
                $(#[target_feature(enable = $features)])?
                #[allow(clippy::too_many_arguments)] // the kernel's signature
                unsafe fn inner(
                    block: Rows<'_, $t>,
                    core_b: usize,
                    last: Rows<'_, $t>,
                    n_actions: (usize, usize),
                    prior: (usize, usize),
                    input: &[$t],
                    policy: &[u32],
                    out: &mut [$t],
                    scratch: PairScratch<'_, $t>,
                ) {
                    unsafe {
                        eval_pair_impl::<$t, $isa>(
                            block, core_b, last, n_actions, prior, input, policy, out, scratch,
                        )
                    }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: as above; `eval_pair_impl` checks the actions and the lengths.
                unsafe {
                    inner(block, core_b, last, n_actions, prior, input, policy, out, scratch)
                }
            }

            fn peak(iters: usize, seed: $t, a: $t, b: $t) -> $t {
                $(#[target_feature(enable = $features)])?
                unsafe fn inner(iters: usize, seed: $t, a: $t, b: $t) -> $t {
                    unsafe { peak_impl::<$t, $isa>(iters, seed, a, b) }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: the features were just detected; no memory is touched.
                unsafe { inner(iters, seed, a, b) }
            }

            pub(super) const KERNELS: Kernels<$t> = Kernels {
                name: $label,
                lanes: <$isa as Isa<$t>>::LANES,
                peak,
                stage_at,
                last,
                eval,
                eval_pair,
            };
        }
    };
}

#[cfg(target_arch = "x86_64")]
fn has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("fma")
}

#[cfg(target_arch = "x86_64")]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

// The scalar instance needs no features: its "detection" is `true`.
instance!(scalar_f32, "scalar", f32, Scalar, [], true);
instance!(scalar_f64, "scalar", f64, Scalar, [], true);
#[cfg(target_arch = "x86_64")]
instance!(
    avx512_f32,
    "avx512",
    f32,
    x86::Avx512,
    ["avx512f,fma"],
    has_avx512()
);
#[cfg(target_arch = "x86_64")]
instance!(
    avx512_f64,
    "avx512",
    f64,
    x86::Avx512,
    ["avx512f,fma"],
    has_avx512()
);
#[cfg(target_arch = "x86_64")]
instance!(avx2_f32, "avx2", f32, x86::Avx2, ["avx2,fma"], has_avx2());
#[cfg(target_arch = "x86_64")]
instance!(avx2_f64, "avx2", f64, x86::Avx2, ["avx2,fma"], has_avx2());
// The portable instance: on x86-64 compiled with AVX2 + FMA (so it can be compared with the
// hand-written AVX2 kernels on the same machine, and runs at full width there), elsewhere for
// the target's baseline, where `mul_add` is one instruction on every 64-bit ARM CPU.
#[cfg(target_arch = "x86_64")]
instance!(
    portable_f32,
    "portable",
    f32,
    portable::Portable<true>,
    ["avx2,fma"],
    has_avx2()
);
#[cfg(target_arch = "x86_64")]
instance!(
    portable_f64,
    "portable",
    f64,
    portable::Portable<true>,
    ["avx2,fma"],
    has_avx2()
);
#[cfg(not(target_arch = "x86_64"))]
instance!(
    portable_f32,
    "portable",
    f32,
    portable::Portable<true>,
    [],
    true
);
#[cfg(not(target_arch = "x86_64"))]
instance!(
    portable_f64,
    "portable",
    f64,
    portable::Portable<true>,
    [],
    true
);

/// The kernel instances of a scalar type, best first; only those the CPU supports.
pub(crate) trait KernelSet: Sized + 'static {
    /// All instances this CPU can run, best first (scalar last).
    fn available() -> &'static [Kernels<Self>];
}

macro_rules! kernel_set {
    ($t:ty, $scalar:ident, $portable:ident, $avx2:ident, $avx512:ident) => {
        impl KernelSet for $t {
            fn available() -> &'static [Kernels<$t>] {
                static SET: OnceLock<Vec<Kernels<$t>>> = OnceLock::new();
                SET.get_or_init(|| {
                    let mut v = Vec::new();
                    #[cfg(target_arch = "x86_64")]
                    {
                        if has_avx512() {
                            v.push($avx512::KERNELS);
                        }
                        if has_avx2() {
                            v.push($avx2::KERNELS);
                            v.push($portable::KERNELS);
                        }
                    }
                    #[cfg(not(target_arch = "x86_64"))]
                    v.push($portable::KERNELS);
                    v.push($scalar::KERNELS);
                    v
                })
            }
        }
    };
}

kernel_set!(f32, scalar_f32, portable_f32, avx2_f32, avx512_f32);
kernel_set!(f64, scalar_f64, portable_f64, avx2_f64, avx512_f64);

/// The instance to use: `choice` if given (`None` if this CPU cannot run it), else the best
/// available.
pub(crate) fn select<T: KernelSet>(choice: Option<super::Kernel>) -> Option<&'static Kernels<T>> {
    let all = T::available();
    match choice {
        None => all.first(),
        Some(k) => all.iter().find(|i| i.name == k.name()),
    }
}

/// The scalar instance of `T` (always available): over-reading instances run it on inputs
/// without padding (a function pointer, so its code is not inlined into theirs again).
fn scalar<T: Real>() -> &'static Kernels<T> {
    select_real::<T>(Some(super::Kernel::Scalar)).expect("the scalar instance always runs")
}

/// [`select`] for any [`Real`]: the solver is generic over `Real`, whose two types both have
/// kernel sets; the `f32` or `f64` instance is found by its type, so `Real` (which is
/// `no_std`) need not know about the kernels.
pub(crate) fn select_real<T: Real>(choice: Option<super::Kernel>) -> Option<&'static Kernels<T>> {
    use core::any::Any;
    let f32s: Option<&'static dyn Any> = select::<f32>(choice).map(|k| k as &dyn Any);
    let f64s: Option<&'static dyn Any> = select::<f64>(choice).map(|k| k as &dyn Any);
    f32s.and_then(|k| k.downcast_ref::<Kernels<T>>())
        .or_else(|| f64s.and_then(|k| k.downcast_ref::<Kernels<T>>()))
}

#[cfg(test)]
mod tests;
