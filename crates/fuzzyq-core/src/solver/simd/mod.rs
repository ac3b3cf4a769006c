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
//! The range of a sweep's changes ([`diff_range_by`]), a pass over every core outside these
//! kernels, is here too, so that it can run in AVX2 where the CPU has it.
//!
//! Both are written once, generic over a small [`Isa`] trait (vector type, masked loads and
//! stores, fused multiply-add, maximum), and instantiated for AVX-512F (+ VL), AVX2 + FMA, portable
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

/// Writes `na` rows of `r` values (`[a][r]`) as `r` rows of `na` values (`[r][a]`), the output
/// rows `r_stride` apart. Two to eight rows back to back (the first stages of every model
/// here) run with the row count fixed, which the compiler turns into vector shuffles.
pub(super) fn interleave<T: Copy>(src: &[T], na: usize, (out, r_stride): (&mut [T], usize)) {
    fn fixed<T: Copy, const NA: usize>(src: &[T], out: &mut [T]) {
        let r = src.len() / NA;
        let rows: [&[T]; NA] = core::array::from_fn(|a| &src[a * r..(a + 1) * r]);
        for (ri, o) in out.as_chunks_mut::<NA>().0[..r].iter_mut().enumerate() {
            for (x, row) in o.iter_mut().zip(&rows) {
                *x = row[ri];
            }
        }
    }
    match (na, r_stride) {
        (2, 2) => fixed::<T, 2>(src, out),
        (3, 3) => fixed::<T, 3>(src, out),
        (4, 4) => fixed::<T, 4>(src, out),
        (5, 5) => fixed::<T, 5>(src, out),
        (6, 6) => fixed::<T, 6>(src, out),
        (7, 7) => fixed::<T, 7>(src, out),
        (8, 8) => fixed::<T, 8>(src, out),
        _ => {
            let r = src.len() / na;
            for (ri, o) in out.chunks_mut(r_stride).take(r).enumerate() {
                for (a, x) in o[..na].iter_mut().enumerate() {
                    *x = src[a * r + ri];
                }
            }
        }
    }
}

/// Sparse rows whose columns are all below `n_cols`, validated once when built.
#[derive(Clone, Debug)]
pub(super) struct RowsBuf<T> {
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: Vec<T>,
    n_cols: usize,
    /// The rows merged by column in groups of one block core's actions, if made
    /// ([`RowsBuf::with_groups`]).
    groups: Option<GroupsBuf<T>>,
}

/// Most actions of a merged group, and the zero weights past the last step: at least the
/// lanes of every instance's vector, so that a whole vector loads from any step.
pub(super) const GROUP_LANES: usize = 16;

/// Rows merged by column in groups of `na` consecutive rows (one block core's actions): group
/// `g`'s steps `ptr[g]..ptr[g + 1]` read column `col[s]` with weight `weight[s lanes + a]` for
/// row `g na + a` (0 where that row has no entry there, and in the lanes from `na` to
/// `lanes`, the power of two from `na`). Each row's entries appear in its own order, so a
/// chain over the steps with fused multiply-adds from 0 sums every row as its own chain does,
/// plus products with weight 0, which change no finite sum (an exact `+0` sum stays `+0`).
///
/// A step holds `lanes` weights: the vector lanes of the kernel instance in use, or more
/// where there are more actions ([`RowsBuf::set_group_lanes`]). A vector loaded from a step
/// so reads whole steps on the instance it was laid out for, and on any other reads the next
/// step's weights in its lanes past `lanes` (past the last step, [`GROUP_LANES`] zeros),
/// which a caller ignores. On the paper's grid (5 actions) an AVX2 or portable step takes
/// 32 bytes, not 64 (a slab's steps 11 KB, not 23 KB, beside its 23 KB of input in a
/// first-level cache that may hold 32 KiB), while AVX-512 keeps its 64-byte steps, each
/// loaded whole (32-byte steps, half of them across two cache lines, were 4% slower there).
/// The steps start on a cache line ([`LineBuf`]), so that no step of up to 64 bytes spans two:
/// where the allocator had put them 16-48 bytes into a line, a plain full backup on AVX-512
/// was 2-3% slower.
#[derive(Clone, Debug)]
struct GroupsBuf<T> {
    na: usize,
    lanes: usize,
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: LineBuf<T>,
}

/// [`GROUP_LANES`] values from a 64-byte boundary: a cache line of `f32`, two of `f64`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Line<T>([T; GROUP_LANES]);

/// Values from a cache line's start, for the merged steps' weights: a 64-byte step so starts
/// a line, and a whole-vector AVX-512 load of it reads one line, not two. (A `Vec<T>` starts
/// wherever the allocator puts it, 16 bytes apart on this platform's `malloc`.)
#[derive(Clone, Debug)]
struct LineBuf<T> {
    lines: Vec<Line<T>>,
    len: usize,
}

impl<T: Real> LineBuf<T> {
    /// `len` zeros.
    fn zeroed(len: usize) -> Self {
        const { assert!(size_of::<Line<T>>() == GROUP_LANES * size_of::<T>()) };
        let lines = vec![Line([T::ZERO; GROUP_LANES]); len.div_ceil(GROUP_LANES)];
        Self { lines, len }
    }

    /// The values.
    fn as_slice(&self) -> &[T] {
        // SAFETY: a `Line<T>` is `GROUP_LANES` values of `T` without padding (the assertion
        // in `zeroed`, the only constructor), so the lines are `lines.len() * GROUP_LANES >=
        // len` initialised values back to back.
        unsafe { core::slice::from_raw_parts(self.lines.as_ptr().cast::<T>(), self.len) }
    }

    /// The values, to write.
    fn as_mut_slice(&mut self) -> &mut [T] {
        // SAFETY: as in `as_slice`, borrowed uniquely through `self`.
        unsafe { core::slice::from_raw_parts_mut(self.lines.as_mut_ptr().cast::<T>(), self.len) }
    }
}

/// A borrowed view of [`GroupsBuf`].
#[derive(Clone, Copy, Debug)]
struct Groups<'a, T> {
    na: usize,
    lanes: usize,
    ptr: &'a [u32],
    col: &'a [u32],
    weight: &'a [T],
}

/// The weights of one group's merged steps ([`Rows::group`]): `lanes` per step, then the
/// next steps' (or zeros past the last one), so that a vector of up to [`GROUP_LANES`]
/// lanes loads from any step.
#[derive(Clone, Copy, Debug)]
pub(super) struct StepWeights<'a, T> {
    weight: &'a [T],
    lanes: usize,
}

impl<'a, T> StepWeights<'a, T> {
    /// Step `s`'s weights, one per action of the group (and zeros up to `lanes`).
    #[cfg(test)]
    pub(super) fn step(&self, s: usize) -> &'a [T] {
        &self.weight[s * self.lanes..(s + 1) * self.lanes]
    }

    /// Step `s`'s first weight, followed by at least [`GROUP_LANES`] readable values.
    #[inline(always)]
    pub(super) fn at(&self, s: usize) -> *const T {
        debug_assert!(s * self.lanes + GROUP_LANES <= self.weight.len());
        // SAFETY: in bounds or one past the end (the debug assertion; callers pass a step
        // of the group, and the group's weights run `GROUP_LANES` past its last step).
        unsafe { self.weight.as_ptr().add(s * self.lanes) }
    }
}

/// A borrowed view of [`RowsBuf`]; only `RowsBuf::view` makes one, so the column bound holds.
#[derive(Clone, Copy, Debug)]
pub struct Rows<'a, T> {
    ptr: &'a [u32],
    col: &'a [u32],
    weight: &'a [T],
    n_cols: usize,
    groups: Option<Groups<'a, T>>,
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
            groups: None,
        })
    }

    /// These rows, also merged by column in groups of `na` consecutive rows (one block
    /// core's actions; see [`GroupsBuf`]), for the pruned last stage's row bounds. Unchanged
    /// unless `na` is 2 to [`GROUP_LANES`] and divides the row count.
    pub(super) fn with_groups(mut self, na: usize) -> Self {
        let n_rows = self.ptr.len() - 1;
        if !(2..=GROUP_LANES).contains(&na) || !n_rows.is_multiple_of(na) {
            return self;
        }
        let lanes = na.next_power_of_two();
        let (mut ptr, mut col, mut weight) = (vec![0], Vec::new(), Vec::new());
        let view = self.view();
        for first in (0..n_rows).step_by(na) {
            let base = col.len();
            view.merge_by_column::<GROUP_LANES>(first, na, usize::MAX, |step, k, a, w| {
                if base + step == col.len() {
                    col.push(k);
                    weight.resize(weight.len() + lanes, T::ZERO);
                }
                weight[(base + step) * lanes + a] = w;
            });
            ptr.push(col.len() as u32);
        }
        weight.resize(weight.len() + GROUP_LANES, T::ZERO);
        let mut g = GroupsBuf {
            na,
            lanes,
            ptr,
            col,
            weight: LineBuf::zeroed(weight.len()),
        };
        g.weight.as_mut_slice().copy_from_slice(&weight);
        self.groups = Some(g);
        self
    }

    /// Lays the merged steps out `vector_lanes` weights apart, or more where a group has
    /// more actions (see [`GroupsBuf`]); the weights themselves do not change.
    pub(super) fn set_group_lanes(&mut self, vector_lanes: usize) {
        let Some(g) = self.groups.as_mut() else {
            return;
        };
        let lanes = g.na.next_power_of_two().max(vector_lanes).min(GROUP_LANES);
        if lanes == g.lanes {
            return;
        }
        let n_steps = g.col.len();
        let mut weight = LineBuf::zeroed(n_steps * lanes + GROUP_LANES);
        let to = weight.as_mut_slice();
        for s in 0..n_steps {
            let from = &g.weight.as_slice()[s * g.lanes..s * g.lanes + g.na];
            to[s * lanes..s * lanes + g.na].copy_from_slice(from);
        }
        g.weight = weight;
        g.lanes = lanes;
    }

    pub(super) fn view(&self) -> Rows<'_, T> {
        Rows {
            ptr: &self.ptr,
            col: &self.col,
            weight: &self.weight,
            n_cols: self.n_cols,
            groups: self.groups.as_ref().map(|g| Groups {
                na: g.na,
                lanes: g.lanes,
                ptr: &g.ptr,
                col: &g.col,
                weight: g.weight.as_slice(),
            }),
        }
    }

    /// The compressed rows: row starts, columns and weights.
    pub(super) fn parts(&self) -> (&[u32], &[u32], &[T]) {
        (&self.ptr, &self.col, &self.weight)
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
            groups: None,
        })
    }
}

/// Rows (each its columns and weights) merged by column: each step reads the smallest
/// column among the rows' next entries, and every row whose next entry reads it takes the
/// step, so each row's entries appear in its own order (rows need not be sorted). Calls
/// `take(step, column, row, weight)` for each row taking each step, in order; returns the
/// number of steps, or `None` once there would be more than `max_steps`. At most `N` rows
/// (a bound known at compile time, so that the loops over the rows unroll where it is small).
#[inline(always)]
pub(crate) fn merge_rows<T: Copy, const N: usize>(
    rows: &[(&[u32], &[T])],
    max_steps: usize,
    mut take: impl FnMut(usize, u32, usize, T),
) -> Option<usize> {
    assert!(rows.len() <= N, "at most N rows");
    let mut heads = [0usize; N];
    let heads = &mut heads[..rows.len()];
    let mut n = 0;
    loop {
        let mut next = u32::MAX;
        for (&(cols, _), &h) in rows.iter().zip(heads.iter()) {
            if let Some(&k) = cols.get(h) {
                next = next.min(k);
            }
        }
        if next == u32::MAX {
            return Some(n);
        }
        if n == max_steps {
            return None;
        }
        for (a, (&(cols, ws), h)) in rows.iter().zip(heads.iter_mut()).enumerate() {
            if cols.get(*h) == Some(&next) {
                take(n, next, a, ws[*h]);
                *h += 1;
            }
        }
        n += 1;
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

    /// Rows `first .. first + na` (`na <= N`) merged by column ([`merge_rows`]), for the
    /// merged stage (`stage::Merged`, per call) and [`RowsBuf::with_groups`] (once per
    /// table). (`N` bounds the rows at compile time: the merged stage passes its action count,
    /// so that the loops over the rows unroll.)
    #[inline(always)]
    pub(super) fn merge_by_column<const N: usize>(
        &self,
        first: usize,
        na: usize,
        max_steps: usize,
        take: impl FnMut(usize, u32, usize, T),
    ) -> Option<usize>
    where
        T: Copy,
    {
        let entries: [(&[u32], &[T]); N] = core::array::from_fn(|a| {
            if a < na {
                self.row(first + a)
            } else {
                (&[][..], &[][..])
            }
        });
        merge_rows::<T, N>(&entries[..na], max_steps, take)
    }

    /// The merged steps of rows `g na .. (g + 1) na` (see [`GroupsBuf`]), if these rows were
    /// merged in groups of `na`.
    #[inline(always)]
    pub(super) fn group(&self, g: usize, na: usize) -> Option<(&'a [u32], StepWeights<'a, T>)> {
        let gr = self.groups.as_ref().filter(|gr| gr.na == na)?;
        let (s, e) = (gr.ptr[g] as usize, gr.ptr[g + 1] as usize);
        let weight = &gr.weight[s * gr.lanes..e * gr.lanes + GROUP_LANES];
        let lanes = gr.lanes;
        Some((&gr.col[s..e], StepWeights { weight, lanes }))
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

/// Where a stage writes its output: leading index `r`, action `a` and lane `p` at
/// `out[r * r_stride + a * a_stride + p]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutStrides {
    /// Elements between consecutive leading indices.
    pub r_stride: usize,
    /// Elements between consecutive actions.
    pub a_stride: usize,
}

impl OutStrides {
    /// The dense layout `out[(r A + a) P + p]` of `n_actions` actions of `p_len` lanes.
    #[inline]
    #[must_use]
    pub const fn dense(n_actions: usize, p_len: usize) -> Self {
        Self {
            r_stride: n_actions * p_len,
            a_stride: p_len,
        }
    }
}

/// One stage at any strides: `out[r R' + a A' + p] = sum_e w_e in[k_e K + r S + p]` (`K`, `S`
/// = `strides`, `R'`, `A'` = `out_strides`) over rows `first_row..first_row + A`, each sum in
/// row order with fused multiply-adds from 0.
#[allow(clippy::too_many_arguments)] // the stage's shape and buffers, spelled out
pub type StageFn<T> = fn(
    rows: Rows<'_, T>,
    first_row: usize,
    n_actions: usize,
    r_len: usize,
    p_len: usize,
    strides: Strides,
    out_strides: OutStrides,
    input: &[T],
    out: &mut [T],
);

/// The last stage's input: one row of `p_len` lanes (the earlier blocks' actions) per
/// successor core, `stride` elements apart: `in[k S + p]`. A stride past `p_len` pads each row
/// (to whole cache lines, say); the padding is never read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InRows {
    /// Lanes per row.
    pub p_len: usize,
    /// Elements from one row to the next (`>= p_len`).
    pub stride: usize,
}

impl InRows {
    /// Rows of `p_len` lanes, back to back.
    pub const fn dense(p_len: usize) -> Self {
        Self {
            p_len,
            stride: p_len,
        }
    }

    /// Elements that `n_rows` rows span (the last one unpadded).
    pub(crate) fn extent(self, n_rows: usize) -> usize {
        n_rows.saturating_sub(1) * self.stride + self.p_len
    }
}

/// The evaluation kernel's input ([`EvalFn`]): lane `p` of successor core `k`'s row at
/// `in[k S + p L]`. [`InRows`] is the case `L = 1`; `S = 1, L = R` reads the stage before
/// computed action by action along whole rows (`[p][k]`, `R` successor cores).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EvalIn {
    /// Lanes per row.
    pub p_len: usize,
    /// Elements from one successor core to the next (`S`).
    pub stride: usize,
    /// Elements from one lane to the next (`L`).
    pub lane: usize,
}

impl EvalIn {
    /// The layout `[p][k]` of `p_len` rows of `n_k` successor cores each.
    pub const fn transposed(p_len: usize, n_k: usize) -> Self {
        Self {
            p_len,
            stride: 1,
            lane: n_k,
        }
    }

    /// The last element the rows over `n_k` successor cores read, plus one (0 for none).
    fn extent(self, n_k: usize) -> usize {
        if n_k == 0 || self.p_len == 0 {
            return 0;
        }
        (n_k - 1)
            .checked_mul(self.stride)
            .and_then(|x| x.checked_add((self.p_len - 1).checked_mul(self.lane)?))
            .and_then(|x| x.checked_add(1))
            .expect("evaluation input extent overflows")
    }
}

impl From<InRows> for EvalIn {
    fn from(r: InRows) -> Self {
        Self {
            p_len: r.p_len,
            stride: r.stride,
            lane: 1,
        }
    }
}

/// The fused last stage: `out[i] = max_{a,p} (|.| if `abs`) sum_e w_e in[k_e S + p]` over the
/// rows `(first_core + i) A + a`; with `args` (and not `abs`), also each core's lowest
/// `a P + p` whose expected value equals its maximum (the greedy product action).
///
/// `bounds` is scratch of at least one value per input row (`rows`' column count): the row
/// bounds of one register block at a time.
pub type LastFn<T> = fn(
    rows: Rows<'_, T>,
    first_core: usize,
    n_actions: usize,
    shape: InRows,
    abs: bool,
    input: &[T],
    out: &mut [T],
    bounds: &mut [T],
    args: Option<&mut [u32]>,
);

/// Elements a kernel's input may extend past the tensor to let every instance use its fastest
/// partial loads (the portable instance reads whole vectors at row tails and discards the
/// extra lanes). Inputs without them are still correct, on exact loads ([`Isa::OVERREAD`]).
pub(super) const INPUT_PAD: usize = 16;

/// Largest block action count for which the last stage prunes rows, or keeps every row of
/// one vector to find the maximiser in one pass (stack arrays).
const PRUNE_MAX_ACTIONS: usize = 64;

/// The last stage for one given action per core: `out[i] = sum_e w_e in[k_e S + p L]` over the
/// row `(first_core + i) A + a`, where `policy[i] = a P + p` is the core's product action
/// ([`EvalIn`]: `L = 1` for the fused last stage's layout).
/// Entries are summed in the row's order with fused multiply-adds from 0, as [`LastFn`] does,
/// so for the greedy action the value is bit-identical to the core's maximum.
pub type EvalFn<T> = fn(
    rows: Rows<'_, T>,
    first_core: usize,
    n_actions: usize,
    shape: EvalIn,
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
        let out_strides = OutStrides::dense(n_actions, p_len);
        (self.stage_at)(
            rows,
            first_row,
            n_actions,
            r_len,
            p_len,
            strides,
            out_strides,
            input,
            out,
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
    out_strides: OutStrides,
    input: &[T],
    out: &[T],
) {
    assert!(first_row + na <= rows.n_rows(), "stage rows out of range");
    assert!(
        stage_extent(rows, r_len, p_len, strides) <= input.len(),
        "stage input too short"
    );
    let out_extent = if r_len == 0 || na == 0 || p_len == 0 {
        0
    } else {
        (r_len - 1)
            .checked_mul(out_strides.r_stride)
            .and_then(|x| x.checked_add((na - 1).checked_mul(out_strides.a_stride)?))
            .and_then(|x| x.checked_add(p_len))
            .expect("stage output extent overflows")
    };
    assert!(out_extent <= out.len(), "stage output too short");
}

fn check_last<T>(
    rows: &Rows<'_, T>,
    first_core: usize,
    na: usize,
    shape: InRows,
    input: &[T],
    out: &[T],
) {
    assert!(
        (first_core + out.len()) * na <= rows.n_rows(),
        "last-stage rows out of range"
    );
    assert!(shape.p_len > 0, "empty rows");
    assert!(shape.stride >= shape.p_len, "last-stage rows overlap");
    assert!(
        shape.extent(rows.n_cols) <= input.len(),
        "last-stage input too short"
    );
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
    /// Vectors per action's register block in a merged stage (`stage::Merged`): up to six
    /// actions' blocks and one step's input stay in registers.
    const MERGED: usize;
    /// Elements past a tensor's end that [`Isa::load_part`] may read (and discard): 0 for
    /// instances with masked loads. The kernels run such an instance only on inputs that
    /// long ([`INPUT_PAD`] covers every instance): the stage kernel runs [`Isa::Exact`] on
    /// shorter ones (the first stage reads `V`), the last stage the scalar instance (the block
    /// path always passes it a padded stage buffer; other callers may not).
    const OVERREAD: usize;
    /// The instance's variant without over-reads (`Self` where `OVERREAD` is 0).
    type Exact: Isa<T>;
    /// The instance the last stage runs rows of at most its `LANES` lanes on, when that is
    /// fewer than this instance's: AVX2 under AVX-512 (whose CPUs all have it), so that the
    /// robots' rows of 4 lanes fill half a vector, not a quarter; `Self` elsewhere. Every
    /// instance gives the same bits.
    type Narrow: Isa<T>;
    unsafe fn zero() -> Self::V;
    unsafe fn neg_inf() -> Self::V;
    unsafe fn splat(x: T) -> Self::V;
    /// Mask of the first `n` lanes (`1 <= n <= LANES`).
    unsafe fn mask(n: usize) -> Self::M;
    unsafe fn load(p: *const T) -> Self::V;
    /// Loads the masked lanes. The others are zero and their memory is not read, except in
    /// an instance that over-reads ([`Isa::OVERREAD`]), where they hold the memory past the
    /// lanes: every caller masks them out again before they reach a result.
    unsafe fn load_part(p: *const T, m: Self::M) -> Self::V;
    unsafe fn store(p: *mut T, v: Self::V);
    /// Stores the masked lanes only (the first `n`, which `m` selects).
    unsafe fn store_part(p: *mut T, v: Self::V, m: Self::M, n: usize);
    /// Whether [`Isa::store_range`] is a single masked store, so that a stage over rows of a
    /// few values runs them packed, several rows per vector (`stage::stage_flat`).
    const RANGE_STORES: bool = false;
    /// Whether [`Isa::equal_bits`] is a vector compare into a bit mask (x86), so that the
    /// pruned last stage picks its first row from the vector of row bounds; elsewhere the
    /// bits cost a test per lane and the bounds are compared one by one.
    const MASK_COMPARES: bool = false;
    /// Stores lanes `lo..hi` (`lo < hi <= LANES`) to `p + lo ..`; no other lane's memory is
    /// touched, so `p` itself may point before the buffer (it is only offset, never read).
    /// Called only on instances with [`Isa::RANGE_STORES`], which implement it.
    unsafe fn store_range(_p: *mut T, _v: Self::V, _lo: usize, _hi: usize) {
        unreachable!("range stores only on instances with RANGE_STORES")
    }
    /// Bit `i` set for each masked lane `i` equal to `t`.
    unsafe fn equal_bits(v: Self::V, t: T, m: Self::M) -> u64;
    /// The lowest valid lane `j * LANES + lane` of a register block equal to `t` (the last
    /// vector's lanes masked by `m`). By default the lanes' equalities gathered into one bit
    /// mask ([`Isa::equal_bits`]), without a branch per vector.
    #[inline(always)]
    unsafe fn first_equal<const NV: usize>(acc: &[Self::V; NV], t: T, m: Self::M) -> Option<usize> {
        const {
            assert!(
                NV * Self::LANES <= 128,
                "a register block's lanes fit a u128"
            )
        };
        let all = unsafe { Self::mask(Self::LANES) };
        let mut bits = 0u128;
        for (j, &x) in acc.iter().enumerate() {
            let mask = if j + 1 == NV { m } else { all };
            bits |= u128::from(unsafe { Self::equal_bits(x, t, mask) }) << (j * Self::LANES);
        }
        (bits != 0).then(|| bits.trailing_zeros() as usize)
    }
    /// The lowest `r * row_len + lane` over rows of one vector each (`row_len` lanes, those
    /// `m` selects) whose lane equals `t`. By default every row's matching lanes at their
    /// index in one word when all fit 64 bits (the lowest set bit, without a branch on which
    /// row holds it: a mispredicted branch per core would keep the next core's rows from
    /// starting), else row by row.
    #[inline(always)]
    unsafe fn first_equal_rows(
        rows: &[Self::V],
        t: T,
        m: Self::M,
        row_len: usize,
    ) -> Option<usize> {
        if rows.len() * row_len <= 64 {
            let mut all = 0u64;
            for (r, &x) in rows.iter().enumerate() {
                all |= unsafe { Self::equal_bits(x, t, m) } << (r * row_len);
            }
            return (all != 0).then(|| all.trailing_zeros() as usize);
        }
        // A loop, not a closure: a closure would not inherit the kernel's target features.
        for (r, &x) in rows.iter().enumerate() {
            let bits = unsafe { Self::equal_bits(x, t, m) };
            if bits != 0 {
                return Some(r * row_len + bits.trailing_zeros() as usize);
            }
        }
        None
    }
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

mod last;
mod stage;

use last::*;
use stage::*;

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
            const MERGED: usize = 2;
            const OVERREAD: usize = 0;
            type Exact = Self;
            type Narrow = Self;
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
            unsafe fn equal_bits(v: $t, t: $t, m: bool) -> u64 {
                u64::from(m && v == t)
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
                out_strides: OutStrides,
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
                    out_strides: OutStrides,
                    input: &[$t],
                    out: &mut [$t],
                ) {
                    unsafe {
                        stage_impl::<$t, $isa>(
                            rows, first_row, na, (r_len, p_len), strides, out_strides, input, out,
                        )
                    }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: the features were just detected; `stage_impl` checks every bound its
                // pointer arithmetic relies on (`check_stage`, and the rows' column bound).
                unsafe { inner(rows, first_row, na, r_len, p_len, strides, out_strides, input, out) }
            }

            #[allow(clippy::too_many_arguments)] // the kernel's signature
            fn last(
                rows: Rows<'_, $t>,
                first_core: usize,
                na: usize,
                shape: InRows,
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
                    shape: InRows,
                    abs: bool,
                    input: &[$t],
                    out: &mut [$t],
                    bounds: &mut [$t],
                    args: Option<&mut [u32]>,
                ) {
                    unsafe {
                        if abs {
                            last_impl::<$t, $isa, true>(rows, first_core, na, shape, input, out, bounds, args)
                        } else {
                            last_impl::<$t, $isa, false>(rows, first_core, na, shape, input, out, bounds, args)
                        }
                    }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: as above, with `check_last` and the scratch length check.
                unsafe { inner(rows, first_core, na, shape, abs, input, out, bounds, args) }
            }

            fn eval(
                rows: Rows<'_, $t>,
                first_core: usize,
                na: usize,
                shape: EvalIn,
                input: &[$t],
                policy: &[u32],
                out: &mut [$t],
            ) {
                $(#[target_feature(enable = $features)])?
                unsafe fn inner(
                    rows: Rows<'_, $t>,
                    first_core: usize,
                    na: usize,
                    shape: EvalIn,
                    input: &[$t],
                    policy: &[u32],
                    out: &mut [$t],
                ) {
                    unsafe { eval_impl::<$t, $isa>(rows, first_core, na, shape, input, policy, out) }
                }
                assert!($detect, "CPU features missing for this kernel");
                // SAFETY: as above; `eval_impl` checks the policy's actions and the lengths.
                unsafe { inner(rows, first_core, na, shape, input, policy, out) }
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

/// The range `(min, max)` of `value(a[i]) - b[i]` in `f64` (`(inf, -inf)` for none; NaN
/// differences skipped), for the iteration drivers' change statistics: over eight
/// independent lanes so that the comparisons do not wait on each other. Exact minima and
/// maxima, so any split of the cores combined by `min` and `max` gives the same range.
///
/// It runs once per slab of every sweep, over every core: on x86-64 with AVX2 it runs in
/// AVX2 minima and maxima ([`diff_range_avx2`]; the crate's baseline is SSE2). The same
/// operations lane by lane, so the same range either way.
pub(in crate::solver) fn diff_range_by<T: Real, U>(
    a: &[U],
    b: &[T],
    value: &impl Fn(&U) -> T,
) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU has AVX2 (checked above).
        return unsafe { diff_range_avx2(a, b, value) };
    }
    diff_range_lanes(a, b, value)
}

/// [`diff_range_lanes`] in AVX2 intrinsics: element `i` in lane `i % 8` of two vectors of
/// four, each lane's bound updated by `vminpd(d, lo)` (`d < lo ? d : lo`, the lanes'
/// comparison exactly, NaN and signed zeros included), the tail and the final fold as there.
/// Left to the compiler, the eight lanes' comparisons came out as mask shuffles: 3-4 cycles
/// per element, a tenth of a Khepera run.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn diff_range_avx2<T: Real, U>(a: &[U], b: &[T], value: &impl Fn(&U) -> T) -> (f64, f64) {
    use core::arch::x86_64::{
        __m256d, _mm256_max_pd, _mm256_min_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_storeu_pd,
    };
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let d = |x: &U, y: &T| value(x).to_f64() - y.to_f64();
    let four = |x: &[U], y: &[T]| -> __m256d {
        _mm256_set_pd(
            d(&x[3], &y[3]),
            d(&x[2], &y[2]),
            d(&x[1], &y[1]),
            d(&x[0], &y[0]),
        )
    };
    let (mut lo0, mut lo1) = (_mm256_set1_pd(f64::INFINITY), _mm256_set1_pd(f64::INFINITY));
    let neg = f64::NEG_INFINITY;
    let (mut hi0, mut hi1) = (_mm256_set1_pd(neg), _mm256_set1_pd(neg));
    let (ac, at) = a.as_chunks::<8>();
    let (bc, bt) = b.as_chunks::<8>();
    for (x, y) in ac.iter().zip(bc) {
        let (d0, d1) = (four(&x[..4], &y[..4]), four(&x[4..], &y[4..]));
        lo0 = _mm256_min_pd(d0, lo0);
        lo1 = _mm256_min_pd(d1, lo1);
        hi0 = _mm256_max_pd(d0, hi0);
        hi1 = _mm256_max_pd(d1, hi1);
    }
    let (mut lo, mut hi) = ([0.0f64; 8], [0.0f64; 8]);
    // SAFETY: each store writes four `f64` into an array of eight, at 0 or 4.
    unsafe {
        _mm256_storeu_pd(lo.as_mut_ptr(), lo0);
        _mm256_storeu_pd(lo.as_mut_ptr().add(4), lo1);
        _mm256_storeu_pd(hi.as_mut_ptr(), hi0);
        _mm256_storeu_pd(hi.as_mut_ptr().add(4), hi1);
    }
    for (x, y) in at.iter().zip(bt) {
        range_lane(&mut lo[0], &mut hi[0], d(x, y));
    }
    let lo = lo.iter().fold(f64::INFINITY, |m, &x| m.min(x));
    let hi = hi.iter().fold(f64::NEG_INFINITY, |m, &x| m.max(x));
    (lo, hi)
}

/// One lane's running bounds; a NaN `d` keeps them (the comparison is false).
#[inline(always)]
fn range_lane(lo: &mut f64, hi: &mut f64, d: f64) {
    *lo = if d < *lo { d } else { *lo };
    *hi = if d > *hi { d } else { *hi };
}

/// [`diff_range_by`]'s loop, inlined into each of its compilations: eight lanes, each a
/// separate pair of running bounds (an array of them vectorises into mask shuffles; separate
/// scalars into plain vector minima and maxima).
#[inline(always)]
fn diff_range_lanes<T: Real, U>(a: &[U], b: &[T], value: &impl Fn(&U) -> T) -> (f64, f64) {
    let lane = range_lane;
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let d = |x: &U, y: &T| value(x).to_f64() - y.to_f64();
    let inf = f64::INFINITY;
    let (mut l0, mut l1, mut l2, mut l3) = (inf, inf, inf, inf);
    let (mut l4, mut l5, mut l6, mut l7) = (inf, inf, inf, inf);
    let (mut h0, mut h1, mut h2, mut h3) = (-inf, -inf, -inf, -inf);
    let (mut h4, mut h5, mut h6, mut h7) = (-inf, -inf, -inf, -inf);
    let (ac, at) = a.as_chunks::<8>();
    let (bc, bt) = b.as_chunks::<8>();
    for (x, y) in ac.iter().zip(bc) {
        lane(&mut l0, &mut h0, d(&x[0], &y[0]));
        lane(&mut l1, &mut h1, d(&x[1], &y[1]));
        lane(&mut l2, &mut h2, d(&x[2], &y[2]));
        lane(&mut l3, &mut h3, d(&x[3], &y[3]));
        lane(&mut l4, &mut h4, d(&x[4], &y[4]));
        lane(&mut l5, &mut h5, d(&x[5], &y[5]));
        lane(&mut l6, &mut h6, d(&x[6], &y[6]));
        lane(&mut l7, &mut h7, d(&x[7], &y[7]));
    }
    for (x, y) in at.iter().zip(bt) {
        lane(&mut l0, &mut h0, d(x, y));
    }
    let lo = [l0, l1, l2, l3, l4, l5, l6, l7];
    let hi = [h0, h1, h2, h3, h4, h5, h6, h7];
    let lo = lo.iter().fold(inf, |m, &x| m.min(x));
    let hi = hi.iter().fold(-inf, |m, &x| m.max(x));
    (lo, hi)
}

#[cfg(fuzzyq_avx512)]
fn has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("fma")
}

#[cfg(target_arch = "x86_64")]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

// The scalar instance needs no features: its "detection" is `true`.
instance!(scalar_f32, "scalar", f32, Scalar, [], true);
instance!(scalar_f64, "scalar", f64, Scalar, [], true);
// The AVX-512 instances: on x86-64, but not in a development build on a CPU without AVX-512
// (build.rs).
#[cfg(fuzzyq_avx512)]
instance!(
    avx512_f32,
    "avx512",
    f32,
    x86::Avx512,
    ["avx512f,avx512vl,fma"],
    has_avx512()
);
#[cfg(fuzzyq_avx512)]
instance!(
    avx512_f64,
    "avx512",
    f64,
    x86::Avx512,
    ["avx512f,avx512vl,fma"],
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
                        #[cfg(fuzzyq_avx512)]
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

/// Whether the instance was left out of this build for its build machine's CPU
/// (a development build, or `FUZZYQ_KERNELS=host`: build.rs), rather than being foreign to the
/// target.
pub(crate) fn left_out(kernel: super::Kernel) -> bool {
    cfg!(target_arch = "x86_64") && !cfg!(fuzzyq_avx512) && kernel == super::Kernel::Avx512
}

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
