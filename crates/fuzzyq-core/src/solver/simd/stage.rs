//! The contraction stage of the instances ([`super::Kernels::stage`] and
//! [`super::Kernels::stage_at`]): register blocks of a row accumulated entry by entry, narrow
//! rows several leading indices at a time, and the split of a row into register blocks.
//!
//! # Merged actions
//! Row by row, a stage loads one input vector per fused multiply-add: every entry of every
//! row loads its input, so loads (many of them across two cache lines), not multiply-adds,
//! bound it. The rows of one block core's actions mostly share their columns (the successors
//! of nearby actions overlap), so [`Merged`] lists the rows' entries as steps by column, each step
//! naming the actions that take it, and [`stage_merged`] loads each step's input once for
//! all of them, with one register block per action. Each action's entries still run in row
//! order from zero, one fused multiply-add each, so the sums are the ones [`accumulate`]
//! forms: the same bits.
//!
//! # Packed rows
//! Rows of a few values (the point masses' second stage: 5 values in 16 lanes) fill a
//! fraction of a vector. Where the rows of consecutive leading indices follow each other in
//! the input and the instance stores any range of lanes in one masked store
//! ([`Isa::RANGE_STORES`]: AVX-512), [`stage_flat`] runs them packed: whole vectors along
//! the flat input, several rows each, and each vector stored row by row into its place. The
//! same sums again; only the stores are split.

use super::*;

/// One register block of one row: `acc[j] = sum_e w_e x_e[j]` over `NE` entries whose input
/// rows start at `xs[e]`. Entries are added in order, each as a fused multiply-add.
#[inline(always)]
pub(super) unsafe fn accumulate<T: Copy, I: Isa<T>, const NV: usize, const NE: usize>(
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
pub(super) unsafe fn accumulate_any<T: Copy, I: Isa<T>, const NV: usize>(
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
pub(super) unsafe fn accumulate_any_rows<T: Copy, I: Isa<T>, const NV: usize, const NR: usize>(
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
pub(super) unsafe fn store_block<T: Copy, I: Isa<T>, const NV: usize>(
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
pub(super) unsafe fn stage_rows<T: Copy, I: Isa<T>, const NV: usize, const NE: usize>(
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
pub(super) unsafe fn stage_block<T: Copy, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    first_row: usize,
    na: usize,
    r_len: usize,
    (strides, os): (Strides, OutStrides),
    p0: usize,
    m: I::M,
    tail: usize,
    input: *const T,
    out: *mut T,
) {
    unsafe {
        let Strides { k_stride, r_stride } = strides;
        let out_step = os.r_stride;
        // Narrow rows: several leading indices at a time (8 chains in all, enough to hide
        // the fused multiply-add's latency), every action's row on them before the next
        // (their inputs stay in the first-level cache).
        if NV == 1 && r_len >= 8 {
            return stage_narrow::<T, I, NV, 8>(
                rows,
                first_row,
                na,
                r_len,
                (strides, os),
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
                r_len,
                (strides, os),
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
            let o = out.add(a * os.a_stride + p0);
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
pub(super) unsafe fn stage_narrow<T: Copy, I: Isa<T>, const NV: usize, const NR: usize>(
    rows: &Rows<'_, T>,
    first_row: usize,
    na: usize,
    r_len: usize,
    (strides, os): (Strides, OutStrides),
    p0: usize,
    m: I::M,
    tail: usize,
    input: *const T,
    out: *mut T,
) {
    unsafe {
        let Strides { k_stride, r_stride } = strides;
        let out_step = os.r_stride;
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
                let o = out.add(a * os.a_stride + p0);
                for (i, acc) in accs.iter().enumerate() {
                    store_block::<T, I, NV>(o.add((at + i) * out_step), acc, m, tail);
                }
            }
            r = at + NR;
        }
    }
}

/// Vectors per action's register block of a packed stage ([`stage_flat`]).
const FLAT_BLOCK: usize = 4;

/// Most steps of a [`Merged`] group (longer groups take the row-by-row path).
const MAX_STEPS: usize = 32;

/// The rows of `NA` consecutive actions merged by column: step `s` reads column `cols[s]`
/// for the actions whose bit is set in `masks[s]`, with weights `ws[s]`, as
/// [`Rows::merge_by_column`] merges them (every row's entries in their order; rows sorted by
/// column share every common column).
pub(super) struct Merged<T, const NA: usize> {
    pub(super) n: usize,
    pub(super) cols: [u32; MAX_STEPS],
    pub(super) masks: [u8; MAX_STEPS],
    pub(super) ws: [[T; NA]; MAX_STEPS],
}

impl<T: Real, const NA: usize> Merged<T, NA> {
    /// Merges rows `first_row .. first_row + NA`; `None` past [`MAX_STEPS`] steps.
    #[cfg(test)]
    pub(super) fn new(rows: &Rows<'_, T>, first_row: usize) -> Option<Self> {
        let mut m = Self::empty();
        m.merge(rows, first_row).then_some(m)
    }

    /// No steps.
    #[inline(always)]
    fn empty() -> Self {
        const { assert!(NA <= 8, "action masks are u8") };
        Self {
            n: 0,
            cols: [0; MAX_STEPS],
            masks: [0; MAX_STEPS],
            ws: [[T::ZERO; NA]; MAX_STEPS],
        }
    }

    /// Merges rows `first_row .. first_row + NA` into these (empty) steps, in place (a merge
    /// returned by value was a `memmove` of the whole struct per call); `false` past
    /// [`MAX_STEPS`] steps.
    #[inline(always)]
    fn merge(&mut self, rows: &Rows<'_, T>, first_row: usize) -> bool {
        let n = rows.merge_by_column::<NA>(first_row, NA, MAX_STEPS, |step, k, a, w| {
            self.cols[step] = k;
            self.masks[step] |= 1 << a;
            self.ws[step][a] = w;
        });
        self.n = n.unwrap_or(0);
        n.is_some()
    }
}

/// One register block of every merged action: `NR` leading indices (`r_stride` apart) of
/// `NV` vectors from `base` (the last vector masked by `m`), each step's inputs loaded once
/// and added into the block of every action that takes it, in row order from zero.
#[inline(always)]
unsafe fn merged_block<T: Real, I: Isa<T>, const NA: usize, const NV: usize, const NR: usize>(
    merged: &Merged<T, NA>,
    base: *const T,
    (k_stride, r_stride): (usize, usize),
    m: I::M,
) -> [[[I::V; NV]; NR]; NA] {
    let mut acc = [[[unsafe { I::zero() }; NV]; NR]; NA];
    for s in 0..merged.n {
        let x = unsafe { base.add(merged.cols[s] as usize * k_stride) };
        let mut xv = [[unsafe { I::zero() }; NV]; NR];
        for (i, row) in xv.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                // SAFETY: the caller's block lies within the input (the last vector's
                // masked lanes within it or discarded).
                unsafe {
                    let p = x.add(i * r_stride + j * I::LANES);
                    *v = if j + 1 == NV {
                        I::load_part(p, m)
                    } else {
                        I::load(p)
                    };
                }
            }
        }
        let bits = merged.masks[s];
        for (a, blocks) in acc.iter_mut().enumerate() {
            if bits & (1 << a) != 0 {
                let w = unsafe { I::splat(merged.ws[s][a]) };
                for (block, xs) in blocks.iter_mut().zip(&xv) {
                    for (acc, &v) in block.iter_mut().zip(xs) {
                        *acc = unsafe { I::fma(w, v, *acc) };
                    }
                }
            }
        }
    }
    acc
}

/// A stage over merged actions for one register block of `NV` vectors at offset `p0` of
/// every output row, `NR` leading indices at a time (the last `NR` end at `r_len`, computing
/// a few rows twice: the same values): each step's inputs loaded once and added into the
/// register block of every action that takes it.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
pub(super) unsafe fn stage_merged<
    T: Real,
    I: Isa<T>,
    const NA: usize,
    const NV: usize,
    const NR: usize,
>(
    merged: &Merged<T, NA>,
    r_len: usize,
    (strides, os): (Strides, OutStrides),
    p0: usize,
    m: I::M,
    tail: usize,
    input: *const T,
    out: *mut T,
) {
    unsafe {
        if NR > 1 && r_len < NR {
            let strides = (strides, os);
            return stage_merged::<T, I, NA, NV, 1>(
                merged, r_len, strides, p0, m, tail, input, out,
            );
        }
        let Strides { k_stride, r_stride } = strides;
        let mut r = 0;
        while r < r_len {
            let at = r.min(r_len - NR);
            let base = input.add(at * r_stride + p0);
            let acc = merged_block::<T, I, NA, NV, NR>(merged, base, (k_stride, r_stride), m);
            for (a, blocks) in acc.iter().enumerate() {
                for (i, block) in blocks.iter().enumerate() {
                    let o = out.add((at + i) * os.r_stride + a * os.a_stride + p0);
                    store_block::<T, I, NV>(o, block, m, tail);
                }
            }
            r = at + NR;
        }
    }
}

/// [`stage_merged`] over every register block of the rows, for `NA` actions, or
/// [`stage_flat`] where the rows pack (an instance with range stores, rows of at most half a
/// vector back to back, at least one packed block of them); `false` when the rows do not
/// merge into [`MAX_STEPS`] steps (nothing written then).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn stage_merged_rows<T: Real, I: Isa<T>, const NA: usize>(
    rows: &Rows<'_, T>,
    first_row: usize,
    (r_len, p_len): (usize, usize),
    strides: (Strides, OutStrides),
    input: *const T,
    out: *mut T,
) -> bool {
    let mut merged = Merged::<T, NA>::empty();
    if !merged.merge(rows, first_row) {
        return false;
    }
    let (s, os) = strides;
    if I::RANGE_STORES
        && 2 * p_len <= I::LANES
        && s.r_stride == p_len
        && r_len * p_len >= FLAT_BLOCK * I::LANES
    {
        // Rows of at most half a vector, back to back: packed.
        let shape = (r_len, p_len);
        unsafe { stage_flat::<T, I, NA, FLAT_BLOCK>(&merged, shape, s.k_stride, os, input, out) };
        return true;
    }
    // Rows of several register blocks run a few leading indices at a time, every block of
    // them before the next few: each block reads the input's lines that the one before it
    // just read, instead of the whole slab's input again after it (more than a 32 KiB
    // first-level cache holds on the paper's grid with 8-lane vectors). The same values,
    // computed in the same order each.
    let chunk = if Blocks::new(p_len, I::LANES, I::MERGED).nth(1).is_some() {
        MERGED_CHUNK
    } else {
        r_len
    };
    for r0 in (0..r_len).step_by(chunk.max(1)) {
        let r_len = chunk.min(r_len - r0);
        // SAFETY: leading index `r0` and the `r_len` after it are within the caller's
        // input and output.
        let (input, out) = unsafe { (input.add(r0 * s.r_stride), out.add(r0 * os.r_stride)) };
        unsafe { merged_blocks::<T, I, NA>(&merged, (r_len, p_len), strides, input, out) };
    }
    true
}

/// Leading indices in a chunk of [`stage_merged_rows`] over several register blocks.
const MERGED_CHUNK: usize = 4;

/// [`stage_merged`] for every register block of the rows, one after the other.
#[inline(always)]
unsafe fn merged_blocks<T: Real, I: Isa<T>, const NA: usize>(
    merged: &Merged<T, NA>,
    (r_len, p_len): (usize, usize),
    strides: (Strides, OutStrides),
    input: *const T,
    out: *mut T,
) {
    unsafe {
        for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::MERGED) {
            let m = I::mask(tail);
            let args = (merged, r_len, strides, p0, m, tail, input, out);
            // `NV * NR` vectors per action: `I::MERGED` of them.
            match (nv, I::MERGED) {
                (1, 4) => stage_merged::<T, I, NA, 1, 4>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                ),
                (1, _) => stage_merged::<T, I, NA, 1, 2>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                ),
                (2, 4) => stage_merged::<T, I, NA, 2, 2>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                ),
                (2, _) => stage_merged::<T, I, NA, 2, 1>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                ),
                (3, _) => stage_merged::<T, I, NA, 3, 1>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                ),
                _ => stage_merged::<T, I, NA, 4, 1>(
                    args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                ),
            }
        }
    }
}

/// The merged stage for `na` actions, if it applies (2 to 6 actions, one register block
/// each, whose rows merge into [`MAX_STEPS`] steps); `false` when the caller must run the
/// rows one by one.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn try_stage_merged<T: Real, I: Isa<T>>(
    rows: &Rows<'_, T>,
    first_row: usize,
    na: usize,
    shape: (usize, usize),
    strides: (Strides, OutStrides),
    input: *const T,
    out: *mut T,
) -> bool {
    unsafe {
        match na {
            2 => stage_merged_rows::<T, I, 2>(rows, first_row, shape, strides, input, out),
            3 => stage_merged_rows::<T, I, 3>(rows, first_row, shape, strides, input, out),
            4 => stage_merged_rows::<T, I, 4>(rows, first_row, shape, strides, input, out),
            5 => stage_merged_rows::<T, I, 5>(rows, first_row, shape, strides, input, out),
            6 => stage_merged_rows::<T, I, 6>(rows, first_row, shape, strides, input, out),
            _ => false,
        }
    }
}

/// A merged stage over rows of a few values packed along the input: with rows `p_len` apart
/// (`r_stride == p_len`), the leading indices' rows follow each other, so each register block
/// of `NV` whole vectors spans several rows, and each vector's lanes are stored row by row
/// ([`Isa::store_range`]). Each value is the same sum as in [`stage_merged`] (each action's
/// entries in row order from zero): the same bits. The last block ends at the input's end
/// (`r_len * p_len >= NV * LANES`), computing a few values twice (the same values).
#[inline(always)]
unsafe fn stage_flat<T: Real, I: Isa<T>, const NA: usize, const NV: usize>(
    merged: &Merged<T, NA>,
    (r_len, p_len): (usize, usize),
    k_stride: usize,
    os: OutStrides,
    input: *const T,
    out: *mut T,
) {
    let flat = r_len * p_len;
    let span = NV * I::LANES;
    let mut f = 0;
    unsafe {
        let all = I::mask(I::LANES);
        while f < flat {
            let at = f.min(flat - span);
            let acc = merged_block::<T, I, NA, NV, 1>(merged, input.add(at), (k_stride, 0), all);
            // Row `r` and the offset in it of each vector's first lane.
            let mut r = at / p_len;
            let mut off = at - r * p_len;
            for j in 0..NV {
                let mut lo = 0;
                while lo < I::LANES {
                    let row_end = lo + p_len - off;
                    let hi = row_end.min(I::LANES);
                    // Lane `i` in `lo..hi` goes to `r R + a A + off + (i - lo)`.
                    let lane0 = (r * os.r_stride + off).wrapping_sub(lo);
                    for (a, [block]) in acc.iter().enumerate() {
                        let p = out.wrapping_add(lane0.wrapping_add(a * os.a_stride));
                        I::store_range(p, block[j], lo, hi);
                    }
                    if hi == row_end {
                        (r, off) = (r + 1, 0);
                    } else {
                        off += hi - lo;
                    }
                    lo = hi;
                }
            }
            f = at + span;
        }
    }
}

/// Splits a row of `p_len` lanes into register blocks: `(vectors, offset, lanes in the last
/// vector)`. An iterator, not a callback: closures do not inherit `#[target_feature]`, and the
/// intrinsics must inline into the feature-enabled kernel.
pub(super) struct Blocks {
    p_len: usize,
    lanes: usize,
    block: usize,
    p0: usize,
}

impl Blocks {
    #[inline(always)]
    pub(super) fn new(p_len: usize, lanes: usize, block: usize) -> Self {
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
pub(super) unsafe fn stage_impl<T: Real, I: Isa<T>>(
    rows: Rows<'_, T>,
    first_row: usize,
    na: usize,
    (r_len, p_len): (usize, usize),
    strides: Strides,
    out_strides: OutStrides,
    input: &[T],
    out: &mut [T],
) {
    check_stage(
        &rows,
        first_row,
        na,
        r_len,
        p_len,
        strides,
        out_strides,
        input,
        out,
    );
    let os = out_strides;
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
                    *op.add(r * os.r_stride + a * os.a_stride) = acc;
                }
            }
            return;
        }
        if I::OVERREAD > 0 && input.len() < stage_extent(&rows, r_len, p_len, strides) + I::OVERREAD
        {
            // Vector loads on an unpadded input (the first stage reads `V` this way): the
            // instance's exact variant (rows of one value, above, never load vectors).
            let shape = (r_len, p_len);
            return stage_impl::<T, I::Exact>(rows, first_row, na, shape, strides, os, input, out);
        }
        if try_stage_merged::<T, I>(&rows, first_row, na, (r_len, p_len), (strides, os), ip, op) {
            return;
        }
        for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::BLOCK) {
            let m = I::mask(tail);
            let args = (
                &rows,
                first_row,
                na,
                r_len,
                (strides, os),
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
