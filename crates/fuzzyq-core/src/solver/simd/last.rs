//! The last stage of the instances: fused with the maximum over actions (pruned by row
//! bounds, optionally keeping the lowest maximiser: [`super::Kernels::last`]), and for one given
//! action per core, alone or with the stage before it ([`super::Kernels::eval`],
//! [`super::Kernels::eval_pair`]).

use super::*;

/// The expected values of one (core, action) row for one register block.
#[inline(always)]
pub(super) unsafe fn row_block<T: Copy, I: Isa<T>, const NV: usize>(
    cols: &[u32],
    ws: &[T],
    input: *const T,
    stride: usize,
    m: I::M,
) -> [I::V; NV] {
    macro_rules! fixed {
        ($ne:literal) => {{
            let mut xs = [input; $ne];
            let mut wv = [I::zero(); $ne];
            for e in 0..$ne {
                xs[e] = input.add(cols[e] as usize * stride);
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
            _ => accumulate_any::<T, I, NV>(cols, ws, input, stride, m),
        }
    }
}

/// Last-stage body for one register block: the running maximum over every action's row.
#[inline(always)]
pub(super) unsafe fn last_block<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    stride: usize,
    p0: usize,
    m: I::M,
    input: *const T,
) -> T {
    unsafe {
        let mut best = [I::neg_inf(); NV];
        for a in 0..na {
            let (cols, ws) = rows.row(c * na + a);
            let acc = row_block::<T, I, NV>(cols, ws, input.add(p0), stride, m);
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
pub(super) unsafe fn argmax_block<T: Copy, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    c: usize,
    a: usize,
    na: usize,
    (p_len, stride): (usize, usize),
    p0: usize,
    m: I::M,
    input: *const T,
    target: T,
) -> Option<usize> {
    unsafe {
        let (cols, ws) = rows.row(c * na + a);
        let acc = row_block::<T, I, NV>(cols, ws, input.add(p0), stride, m);
        I::first_equal::<NV>(&acc, target, m).map(|i| a * p_len + p0 + i)
    }
}

/// The maximum (of the absolute value if `ABS`) over the valid lanes of one register block of
/// one input row.
#[inline(always)]
pub(super) unsafe fn row_bound<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    x: *const T,
    m: I::M,
) -> T {
    unsafe {
        // The lanes' maxima in a vector (a tree), then one horizontal reduction (the maximum
        // is exact in any order); the masked-off lanes of the last vector are minus infinity.
        let mut v = [I::neg_inf(); NV];
        for (j, x_j) in v.iter_mut().enumerate() {
            *x_j = if j + 1 == NV {
                I::load_part(x.add(j * I::LANES), m)
            } else {
                I::load(x.add(j * I::LANES))
            };
        }
        I::reduce_max(block_max::<T, I, NV, ABS>(&v, m), I::mask(I::LANES))
    }
}

/// The lane-wise maximum of a register block's vectors (of their absolute values if `ABS`),
/// the last vector's masked-off lanes minus infinity: a pairwise tree, whose depth, not the
/// vector count, sets the latency (the maximum is exact in any order).
#[inline(always)]
pub(super) unsafe fn block_max<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    acc: &[I::V; NV],
    m: I::M,
) -> I::V {
    unsafe {
        let mut v = *acc;
        for (j, x) in v.iter_mut().enumerate() {
            if ABS {
                *x = I::abs(*x);
            }
            if j + 1 == NV {
                *x = I::load_part_from(*x, m);
            }
        }
        let mut n = NV;
        while n > 1 {
            let half = n / 2;
            for j in 0..half {
                v[j] = I::max(v[j], v[j + n - half]);
            }
            n -= half;
        }
        v[0]
    }
}

/// The maximum over the valid lanes of one (core, action) row in one register block.
#[inline(always)]
pub(super) unsafe fn row_max<T: Copy, I: Isa<T>, const NV: usize, const ABS: bool>(
    cols: &[u32],
    ws: &[T],
    input: *const T,
    stride: usize,
    m: I::M,
) -> T {
    unsafe {
        let acc = row_block::<T, I, NV>(cols, ws, input, stride, m);
        I::reduce_max(block_max::<T, I, NV, ABS>(&acc, m), I::mask(I::LANES))
    }
}

/// `sum_e w_e x[k_e]` over one row, in the row's order with fused multiply-adds from 0: the
/// columns must index `x` (the rows' columns are below their `n_cols`, which is `x`'s length
/// at every caller).
#[inline(always)]
pub(super) unsafe fn row_dot<T: Real, I: Isa<T>>(cols: &[u32], ws: &[T], x: &[T]) -> T {
    debug_assert!(cols.iter().all(|&k| (k as usize) < x.len()));
    // SAFETY: every column indexes `x` (above).
    unsafe { row_dot_strided::<T, I>(cols, ws, x.as_ptr(), 1) }
}

/// `sum_e w_e x[k_e S]` over one row (`S` the input's row stride), in the row's order with
/// fused multiply-adds from 0. Rows of 8, 4 and 2 entries (the cube or square of two
/// memberships per variable) run unrolled: a loop whose trip count changes from row to row
/// mispredicts its exit about once a row.
///
/// # Safety
/// `x.add(k * stride)` must be readable for every column `k` of the row.
#[inline(always)]
pub(super) unsafe fn row_dot_strided<T: Real, I: Isa<T>>(
    cols: &[u32],
    ws: &[T],
    x: *const T,
    stride: usize,
) -> T {
    let mut acc = T::ZERO;
    macro_rules! fixed {
        ($ne:literal) => {{
            for e in 0..$ne {
                acc = unsafe { I::fma1(ws[e], *x.add(cols[e] as usize * stride), acc) };
            }
        }};
    }
    match cols.len() {
        8 => fixed!(8),
        4 => fixed!(4),
        2 => fixed!(2),
        _ => {
            for (&k, &w) in cols.iter().zip(ws) {
                acc = unsafe { I::fma1(w, *x.add(k as usize * stride), acc) };
            }
        }
    }
    acc
}

/// The `i`-th row a pruned core visits: `top` (the largest bound) first, then the others in
/// order.
#[inline(always)]
fn visit_order(i: usize, top: usize) -> usize {
    match i {
        0 => top,
        _ if i <= top => i - 1,
        _ => i,
    }
}

/// The upper bounds of the rows of core `c`'s actions (`ub[a]`, see [`last_block_pruned`])
/// and the action of the largest (the lowest on ties), the same on every instance.
///
/// Where the rows are kept merged in groups of the core's actions
/// ([`RowsBuf::with_groups`]) and a vector holds a lane per action, the bounds are first one
/// chain of vector multiply-adds over the group's steps (on the paper's grid 8 steps
/// instead of 20 scalar multiply-adds with each row's bookkeeping). Each lane is its row's
/// own chain with zero products between its entries, so when every lane is finite the lanes
/// are the rows' chains bit for bit (on x86 the largest is then picked from the vector:
/// [`Isa::MASK_COMPARES`]). Otherwise (a zero weight times an infinite bound is NaN in a
/// lane whose row has no such product) the bounds are computed again row by row, as where
/// there are no groups: one scalar chain per row. Every instance so has the scalar one's
/// bounds and choice; a NaN lane once skipped a row that could hold the maximum (a first
/// row of bound minus infinity ended the visits).
#[inline(always)]
unsafe fn row_bounds<T: Real, I: Isa<T>>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    bounds: &[T],
    ub: &mut [T; PRUNE_MAX_ACTIONS],
) -> usize {
    if let Some((cols, ws)) = rows.group(c, na).filter(|_| na <= I::LANES) {
        // The vector is stored straight into `ub` (lanes past `na` hold chains of other
        // weights, never read): a copy of `na` lanes would be a call to `memmove` per core,
        // 2-3% of a full backup.
        const { assert!(GROUP_LANES <= PRUNE_MAX_ACTIONS) };
        // SAFETY: `GROUP_LANES >= I::LANES` values are readable from every step's weights
        // and writable in `ub`, and every column indexes `bounds` (the rows' columns are
        // below their `n_cols`, `bounds`' length at every caller).
        unsafe {
            let mut acc = I::zero();
            for (s, &k) in cols.iter().enumerate() {
                debug_assert!((k as usize) < bounds.len());
                let b = I::splat(*bounds.get_unchecked(k as usize));
                acc = I::fma(I::load(ws.at(s)), b, acc);
            }
            if I::MASK_COMPARES {
                // `0 x + 0` is 0 exactly when `x` is finite.
                let mk = I::mask(na);
                let finite = I::fma(acc, I::zero(), I::zero());
                if I::equal_bits(finite, T::ZERO, mk) == (1u64 << na) - 1 {
                    I::store(ub.as_mut_ptr(), acc);
                    // The largest from the vector, not from `ub` (each scalar compare would
                    // wait for the store): finite, so the maximum is exact and its lowest
                    // lane the scalar loop's choice below.
                    let bits = I::equal_bits(acc, I::reduce_max(acc, mk), mk);
                    // A branch per action, not `trailing_zeros`: the CPU predicts the row
                    // and starts on it before the bounds are known (an index computed from
                    // the bits made the row's loads wait for them: 23% slower).
                    for a in 0..na - 1 {
                        if bits & (1 << a) != 0 {
                            return a;
                        }
                    }
                    return na - 1;
                }
            } else {
                I::store(ub.as_mut_ptr(), acc);
                if ub[..na].iter().all(|u| u.is_finite()) {
                    return top_bound(&ub[..na]);
                }
            }
        }
    }
    // Every row's chain first (independent, so they overlap).
    for (a, u) in ub[..na].iter_mut().enumerate() {
        let (cols, ws) = rows.row(c * na + a);
        *u = unsafe { row_dot::<T, I>(cols, ws, bounds) };
    }
    top_bound(&ub[..na])
}

/// The index of the largest bound, the lowest on ties (a NaN bound is never larger, nor a
/// bound larger than a NaN first one).
#[inline(always)]
fn top_bound<T: Real>(ub: &[T]) -> usize {
    let mut top = 0;
    for a in 1..ub.len() {
        top = if ub[a] > ub[top] { a } else { top };
    }
    top
}

/// One register block of the last stage for core `c`, pruned: each row gets an upper bound of
/// its values, the row of the largest bound is visited first, and every other row only if its
/// bound exceeds the best value found by then (once the values have settled, one row per core
/// is visited). Memberships are non-negative and fused multiply-add rounds monotonically, so
/// `fma(w_e, bound_e, ...)` (the same chain as the row's) bounds every computed value of the
/// row: the result is bit-identical to visiting every row. There is no sort: the order of the
/// other rows does not change the maximum, and a sort's data-dependent branches cost more than
/// the rare extra visit they would save.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
pub(super) unsafe fn last_block_pruned<T: Real, I: Isa<T>, const NV: usize, const ABS: bool>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    stride: usize,
    p0: usize,
    m: I::M,
    input: *const T,
    bounds: &[T],
    mut best: T,
) -> T {
    unsafe {
        let mut ub = [T::ZERO; PRUNE_MAX_ACTIONS];
        let top = row_bounds::<T, I>(rows, c, na, bounds, &mut ub);
        // The row of the largest bound first, then the others whose bound exceeds the best
        // by then: a row whose bound does not exceed the best cannot raise the maximum.
        for i in 0..na {
            let a = visit_order(i, top);
            if ub[a] <= best {
                if i == 0 {
                    break;
                }
                continue;
            }
            let (cols, ws) = rows.row(c * na + a);
            let v = row_max::<T, I, NV, ABS>(cols, ws, input.add(p0), stride, m);
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
pub(super) unsafe fn last_block_pruned_arg<T: Real, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    (p_len, stride): (usize, usize),
    p0: usize,
    m: I::M,
    input: *const T,
    bounds: &[T],
    (mut best, mut best_idx): (T, usize),
) -> (T, usize) {
    unsafe {
        let mut ub = [T::ZERO; PRUNE_MAX_ACTIONS];
        let top = row_bounds::<T, I>(rows, c, na, bounds, &mut ub);
        let all = I::mask(I::LANES);
        // As in `last_block_pruned` (no closure: it would not inherit the kernel's target
        // features).
        for i in 0..na {
            let a = visit_order(i, top);
            if ub[a] < best {
                if i == 0 {
                    break;
                }
                continue;
            }
            // A row whose bound only ties the best can hold the maximum only at its own
            // indices, from `a * p_len + p0` on: none lower than the best's index, if that
            // one is lower.
            if ub[a] == best && a * p_len + p0 > best_idx {
                continue;
            }
            let (cols, ws) = rows.row(c * na + a);
            let acc = row_block::<T, I, NV>(cols, ws, input.add(p0), stride, m);
            let v = I::reduce_max(block_max::<T, I, NV, false>(&acc, m), all);
            if v < best {
                continue;
            }
            let idx = I::first_equal::<NV>(&acc, v, m).map_or(usize::MAX, |i| a * p_len + p0 + i);
            if v > best || idx < best_idx {
                best = v;
                best_idx = idx;
            }
        }
        (best, best_idx)
    }
}

/// The maximum of core `c`'s rows when a row fits one vector (`p_len <= LANES`, mask `m`), and
/// the lowest index `a * p_len + p` holding it: every row is computed once and kept, the
/// maximum taken lane-wise and then across lanes, and the rows compared with it in order.
/// The same values as [`last_block`]'s and the index [`argmax_impl`] finds.
#[inline(always)]
unsafe fn last_narrow_arg<T: Real, I: Isa<T>>(
    rows: &Rows<'_, T>,
    c: usize,
    na: usize,
    InRows { p_len, stride }: InRows,
    m: I::M,
    input: *const T,
) -> (T, u32) {
    debug_assert!(na <= PRUNE_MAX_ACTIONS && p_len <= I::LANES);
    unsafe {
        let mut accs = [core::mem::MaybeUninit::<I::V>::uninit(); PRUNE_MAX_ACTIONS];
        let mut lanes = I::neg_inf();
        for (a, slot) in accs[..na].iter_mut().enumerate() {
            let (cols, ws) = rows.row(c * na + a);
            let [acc] = row_block::<T, I, 1>(cols, ws, input, stride, m);
            lanes = I::max(lanes, I::load_part_from(acc, m));
            slot.write(acc);
        }
        let best = I::reduce_max(lanes, I::mask(I::LANES));
        // SAFETY: the first `na` slots were written above.
        let rows = core::slice::from_raw_parts(accs.as_ptr().cast::<I::V>(), na);
        // Only a NaN maximum matches no lane.
        (
            best,
            I::first_equal_rows(rows, best, m, p_len).unwrap_or(0) as u32,
        )
    }
}

/// [`last_block_pruned`] for one register block (`p0`, mask) of every core
/// `first_core + i`, from and into its running maximum `out[i]`.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn cores_pruned<T: Real, I: Isa<T>, const NV: usize, const ABS: bool>(
    rows: &Rows<'_, T>,
    first_core: usize,
    na: usize,
    stride: usize,
    (p0, m): (usize, I::M),
    input: *const T,
    bounds: &[T],
    out: &mut [T],
) {
    for (i, o) in out.iter_mut().enumerate() {
        let c = first_core + i;
        *o = unsafe {
            last_block_pruned::<T, I, NV, ABS>(rows, c, na, stride, p0, m, input, bounds, *o)
        };
    }
}

/// [`last_block_pruned_arg`] for one register block (`p0`, mask) of every core
/// `first_core + i`, from and into its running maximum `out[i]` and index `args[i]`
/// (`u32::MAX` before any; indices fit `u32`: [`Kernels::last`]'s contract).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape, spelled out
unsafe fn cores_pruned_arg<T: Real, I: Isa<T>, const NV: usize>(
    rows: &Rows<'_, T>,
    first_core: usize,
    na: usize,
    shape: (usize, usize),
    (p0, m): (usize, I::M),
    input: *const T,
    bounds: &[T],
    out: &mut [T],
    args: &mut [u32],
) {
    for (i, (o, arg)) in out.iter_mut().zip(args.iter_mut()).enumerate() {
        let c = first_core + i;
        let idx = if *arg == u32::MAX {
            usize::MAX
        } else {
            *arg as usize
        };
        let (v, idx) = unsafe {
            last_block_pruned_arg::<T, I, NV>(rows, c, na, shape, p0, m, input, bounds, (*o, idx))
        };
        *o = v;
        *arg = if idx == usize::MAX {
            u32::MAX
        } else {
            idx as u32
        };
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

/// One register block's bound of every input row (`n_cols` rows, `stride` apart), into
/// `bounds[..n_cols]`, computed just before the block's visits (so one block's bounds are
/// all the scratch holds). A plain full backup on
/// the paper's grid ran 3-6% faster so than with every block's bounds first (Zen 5, in
/// alternation; BENCHMARKS.md), though a simulated 32 KiB first-level cache missed no less.
/// An `#[inline(always)]` function, not a closure: the closure lost the kernel's vector
/// features and ran three times slower.
#[inline(always)]
unsafe fn block_bounds<T: Real, I: Isa<T>, const ABS: bool>(
    input: *const T,
    (n_cols, stride): (usize, usize),
    (nv, p0, tail): (usize, usize, usize),
    bounds: &mut [T],
) {
    // SAFETY: the caller's block of every row lies within the input (`last_impl`'s checks).
    unsafe {
        let m = I::mask(tail);
        let b = &mut bounds[..n_cols];
        for (k, bk) in b.iter_mut().enumerate() {
            *bk = by_nv!(nv, row_bound::<T, I, _, ABS>(input.add(k * stride + p0), m));
        }
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tensor's shape and scratch, spelled out
pub(super) unsafe fn last_impl<T: Real, I: Isa<T>, const ABS: bool>(
    rows: Rows<'_, T>,
    first_core: usize,
    na: usize,
    shape: InRows,
    input: &[T],
    out: &mut [T],
    bounds: &mut [T],
    mut args: Option<&mut [u32]>,
) {
    check_last(&rows, first_core, na, shape, input, out);
    let InRows { p_len, stride } = shape;
    if let Some(a) = &args {
        assert_eq!(a.len(), out.len(), "one action per core");
    }
    if I::OVERREAD > 0 && input.len() < shape.extent(rows.n_cols) + I::OVERREAD {
        return (scalar::<T>().last)(rows, first_core, na, shape, ABS, input, out, bounds, args);
    }
    let ip = input.as_ptr();
    let n_cols = rows.n_cols;
    // A row's bound costs one scalar multiply-add per entry, as much as the row itself when
    // the row fits one vector: prune only rows of several vectors; rows of one are all kept.
    let narrow = na <= PRUNE_MAX_ACTIONS && p_len <= I::LANES;
    if narrow && p_len <= <I::Narrow as Isa<T>>::LANES && <I::Narrow as Isa<T>>::LANES < I::LANES {
        // Rows that fit the narrower instance's vectors: the same sums in fewer lanes.
        return unsafe {
            last_impl::<T, I::Narrow, ABS>(rows, first_core, na, shape, input, out, bounds, args)
        };
    }
    let prune = na <= PRUNE_MAX_ACTIONS && !narrow;
    if prune {
        assert!(bounds.len() >= n_cols, "last-stage scratch too short");
    }
    unsafe {
        if let Some(args) = args.as_deref_mut().filter(|_| narrow && !ABS) {
            let m = I::mask(p_len);
            for (i, (o, arg)) in out.iter_mut().zip(args.iter_mut()).enumerate() {
                let (v, idx) = last_narrow_arg::<T, I>(&rows, first_core + i, na, shape, m, ip);
                *o = v;
                *arg = idx;
            }
            return;
        }
        if prune {
            // Register block by register block, each over every core (the block's dispatch
            // and bounds once per call, not per core); a core's running maximum is kept in
            // its output (and its index in `args`): each core still sees its blocks in order,
            // so the same bits.
            let neg_inf = T::from_f64(f64::NEG_INFINITY);
            out.fill(neg_inf);
            if let Some(args) = args.as_deref_mut().filter(|_| !ABS) {
                args.fill(u32::MAX);
                for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::BLOCK) {
                    block_bounds::<T, I, ABS>(ip, (n_cols, stride), (nv, p0, tail), bounds);
                    let b = &bounds[..n_cols];
                    let block = (p0, I::mask(tail));
                    let shape = (p_len, stride);
                    by_nv!(
                        nv,
                        cores_pruned_arg::<T, I, _>(
                            &rows, first_core, na, shape, block, ip, b, out, args
                        )
                    );
                }
                // Every row was computed by the same arithmetic, so some lane holds the
                // maximum (`u32::MAX` only if it is NaN).
                for arg in args.iter_mut().filter(|a| **a == u32::MAX) {
                    *arg = 0;
                }
                return;
            }
            for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::BLOCK) {
                block_bounds::<T, I, ABS>(ip, (n_cols, stride), (nv, p0, tail), bounds);
                let b = &bounds[..n_cols];
                let block = (p0, I::mask(tail));
                by_nv!(
                    nv,
                    cores_pruned::<T, I, _, ABS>(&rows, first_core, na, stride, block, ip, b, out)
                );
            }
        } else {
            for (i, o) in out.iter_mut().enumerate() {
                let c = first_core + i;
                let mut best = T::from_f64(f64::NEG_INFINITY);
                for (nv, p0, tail) in Blocks::new(p_len, I::LANES, I::BLOCK) {
                    let m = I::mask(tail);
                    let v = by_nv!(
                        nv,
                        last_block::<T, I, _, ABS>(&rows, c, na, stride, p0, m, ip)
                    );
                    best = I::max1(best, v);
                }
                *o = best;
            }
        }
    }
    if let Some(args) = args {
        // Without pruning (more actions than the stack arrays hold): a separate scan.
        unsafe { argmax_impl::<T, I>(rows, first_core, na, shape, input, out, args) };
    }
}

#[inline(always)]
pub(super) unsafe fn argmax_impl<T: Real, I: Isa<T>>(
    rows: Rows<'_, T>,
    first_core: usize,
    na: usize,
    shape: InRows,
    input: &[T],
    maxima: &[T],
    out: &mut [u32],
) {
    assert_eq!(maxima.len(), out.len(), "one maximum per core");
    check_last(&rows, first_core, na, shape, input, maxima);
    let p_len = shape.p_len;
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
                    let args = (&rows, c, a, na, (p_len, shape.stride), p0, m, ip, target);
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
pub(super) unsafe fn eval_impl<T: Real, I: Isa<T>>(
    rows: Rows<'_, T>,
    first_core: usize,
    na: usize,
    shape: EvalIn,
    input: &[T],
    policy: &[u32],
    out: &mut [T],
) {
    assert_eq!(policy.len(), out.len(), "one action per core");
    assert!(
        (first_core + out.len()) * na <= rows.n_rows(),
        "last-stage rows out of range"
    );
    assert!(shape.p_len > 0, "empty rows");
    assert!(
        shape.extent(rows.n_cols) <= input.len(),
        "evaluation input too short"
    );
    let EvalIn {
        p_len,
        stride,
        lane,
    } = shape;
    #[inline(always)]
    unsafe fn each<T: Real, I: Isa<T>>(
        (rows, first_core, na, stride, lane): (Rows<'_, T>, usize, usize, usize, usize),
        input: &[T],
        policy: &[u32],
        out: &mut [T],
        p_len: usize,
        split: impl Fn(usize) -> (usize, usize),
    ) {
        for (i, (o, &u)) in out.iter_mut().zip(policy).enumerate() {
            let u = u as usize;
            assert!(
                u < na * p_len,
                "policy action beyond the product action set"
            );
            let (a, p) = split(u);
            let (cols, ws) = rows.row((first_core + i) * na + a);
            // SAFETY: the extent check above bounds lane `p < p_len` of every column's row.
            let x = unsafe { input.as_ptr().add(p * lane) };
            *o = unsafe { row_dot_strided::<T, I>(cols, ws, x, stride) };
        }
    }
    let args = (rows, first_core, na, stride, lane);
    // A power of two (the robots' 4 prior actions) splits the action by a shift and a mask,
    // not a division on every core's chain of dependent loads; a unit stride (the robots'
    // action-major input) takes no multiply per entry either.
    unsafe {
        if p_len.is_power_of_two() {
            let (shift, mask) = (p_len.trailing_zeros(), p_len - 1);
            let split = |u| (u >> shift, u & mask);
            if stride == 1 {
                let args = (rows, first_core, na, 1, lane);
                each::<T, I>(args, input, policy, out, p_len, split);
            } else {
                each::<T, I>(args, input, policy, out, p_len, split);
            }
        } else {
            each::<T, I>(args, input, policy, out, p_len, |u| (u / p_len, u % p_len));
        }
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)] // the kernel's signature
pub(super) unsafe fn eval_pair_impl<T: Real, I: Isa<T>>(
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
                        (1, r_len),
                        Strides {
                            k_stride: r_len,
                            r_stride: r_len,
                        },
                        OutStrides::dense(1, r_len),
                        &input[q * q_stride..],
                        &mut inner[slot * r_len..(slot + 1) * r_len],
                    );
                }
            }
            let row = &inner[slot * r_len..(slot + 1) * r_len];
            let (cols, ws) = last.row(c * na_last + a_last);
            *o = unsafe { row_dot::<T, I>(cols, ws, row) };
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
