//! The contraction stage of the instances ([`super::Kernels::stage`] and
//! [`super::Kernels::stage_at`]): register blocks of a row accumulated entry by entry, narrow
//! rows several leading indices at a time, and the split of a row into register blocks.

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
pub(super) unsafe fn stage_narrow<T: Copy, I: Isa<T>, const NV: usize, const NR: usize>(
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
