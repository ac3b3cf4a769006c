//! Greedy decisions from an exported policy's decision tables (`fuzzyq export --greedy`):
//! `Q(x, .)` at any state from the block path's tables and `V`, without the model and without
//! allocating, with the same sums in the same order as the solver's
//! `Operator::q_values`, so the greedy action is the one a rollout on the laptop takes.
//!
//! # The decision tables (after `V` in the file)
//! Every section is padded with zeros to a multiple of 8 bytes.
//!
//! | section | contents |
//! |---|---|
//! | shapes | `u32`: blocks `B`, 0, then per block its state variables, block actions, entries and support bound |
//! | state variables | `u32`: each block's state variables, increasing; the blocks partition the state |
//! | joint actions | `u32` per joint action: its position in the contraction's result, `[a_0][a_1]..` over the blocks |
//! | per block | `u32` row starts (`cores_b * actions_b + 1`), `u32` successor block cores, values: successor memberships |
//! | discount | one value, `gamma` |
//! | rewards | one value per core, `rho(x_d)` |
//!
//! Blocks come in contraction order (the block of the largest grid strides first). Block
//! cores are numbered row-major over the block's state variables. A block's support bound is
//! the most block cores the rows of one state's active block cores reach; the decision's
//! buffers ([`super::PolicyView::decision_scratch_len`]) are sized by it.
//!
//! # A decision
//! Per block: the active block cores' rows are mixed into one row per block action (the
//! memberships times the rows, summed over the active block cores in their order, entries in
//! increasing block core); the box of `V` over the blocks' supports is gathered; the stages
//! contract it a block at a time, every element a chain of fused multiply-adds from 0 over its
//! row's entries in order; then `Q(x, u) = rho~(x) + gamma E[q_index[u]]` with `rho~` the
//! rewards interpolated at `x`. With `std` the stages run on the solver's run-time selected
//! kernels; without it, on scalar fused multiply-adds (`libm`): the same bits either way.

use core::fmt;

use super::{Reader, ViewError, ViewReal};
use crate::error::EvalError;
use crate::limits::MAX_DIMS;
use crate::partition::{Partition, ProductPartition};

/// Spare elements after the box and stage buffers, so that vector kernels may load whole
/// vectors (the solver's `INPUT_PAD`).
const PAD: usize = 16;

/// Why a greedy decision from a view was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DecideError {
    /// The exported policy has no decision tables (export it with `--greedy`).
    NoTables,
    /// The exported policy has no `V` (it was exported with `--no-values`).
    NoValues,
    /// The state, a buffer or the scratch has the wrong length, or the state is not finite.
    Eval(EvalError),
}

impl From<EvalError> for DecideError {
    fn from(e: EvalError) -> Self {
        Self::Eval(e)
    }
}

impl fmt::Display for DecideError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoTables => write!(
                f,
                "the exported policy has no decision tables (export it with --greedy)"
            ),
            Self::NoValues => write!(
                f,
                "the exported policy has no V (it was exported with --no-values)"
            ),
            Self::Eval(e) => write!(f, "{e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecideError {}

/// One block's rows.
#[derive(Clone, Copy, Debug)]
struct Block<'a, T> {
    dims: &'a [u32],
    n_actions: usize,
    max_support: usize,
    ptr: &'a [u32],
    col: &'a [u32],
    weight: &'a [T],
}

impl<T> Block<'_, T> {
    const EMPTY: Self = Self {
        dims: &[],
        n_actions: 0,
        max_support: 0,
        ptr: &[],
        col: &[],
        weight: &[],
    };
}

/// Lengths of the scratch regions (elements).
#[derive(Clone, Copy, Debug, Default)]
struct Layout {
    /// Most block cores of a block.
    max_cores: usize,
    /// Sum over blocks of actions times support bound.
    mixed: usize,
    /// Sum over blocks of the support bound.
    support: usize,
    /// Sum over blocks of actions + 1.
    ptr: usize,
    /// Most active block cores of a block.
    active: usize,
    /// The box of `V`, padded.
    vbox: usize,
    /// One stage buffer, padded.
    stage: usize,
}

impl Layout {
    /// `(reals, u32s, u64s)` per region, in order.
    fn regions(&self) -> ([usize; 6], [usize; 8], [usize; 1]) {
        (
            [
                self.max_cores,
                self.mixed,
                self.active,
                self.vbox,
                self.stage,
                self.stage,
            ],
            [
                self.max_cores,
                self.max_cores,
                self.max_cores,
                self.max_cores,
                self.support,
                self.ptr,
                self.mixed,
                self.active,
            ],
            [self.support],
        )
    }

    /// Words (`u64`) of scratch for values of `value_bytes` bytes.
    fn words(&self, value_bytes: usize) -> usize {
        let (reals, u32s, u64s) = self.regions();
        reals
            .iter()
            .map(|&n| (n * value_bytes).div_ceil(8))
            .chain(u32s.iter().map(|&n| n.div_ceil(2)))
            .chain(u64s)
            .sum()
    }
}

/// The decision tables of an exported policy, checked and borrowed in place.
#[derive(Clone, Copy, Debug)]
pub(super) struct Decisions<'a, T> {
    n_blocks: usize,
    blocks: [Block<'a, T>; MAX_DIMS],
    q_index: &'a [u32],
    gamma: T,
    rewards: &'a [T],
    layout: Layout,
}

/// A header field or section of the decision tables is invalid.
fn bad(what: &'static str) -> ViewError {
    ViewError::Header { what }
}

impl<'a, T: ViewReal> Decisions<'a, T> {
    /// Reads and checks the tables after `V` for `grid` and `n_joint` joint actions.
    pub(super) fn read(
        r: &mut Reader<'a>,
        grid: &ProductPartition<'a, T>,
        n_joint: usize,
    ) -> Result<Self, ViewError> {
        let e = grid.n_dims();
        let head: &[u32] = r.section(2)?;
        let nb = head[0] as usize;
        if nb == 0 || nb > e || head[1] != 0 {
            return Err(bad("number of decision blocks"));
        }
        let shapes: &[u32] = r.section(4 * nb)?;
        let n_dims: usize = shapes.chunks_exact(4).map(|s| s[0] as usize).sum();
        if n_dims != e {
            return Err(bad("decision block state variables"));
        }
        let dims: &[u32] = r.section(e)?;
        let q_index: &[u32] = r.section(n_joint)?;
        let mut blocks = [Block::EMPTY; MAX_DIMS];
        let mut seen = [false; MAX_DIMS];
        let (mut at, mut product) = (0usize, 1usize);
        let mut layout = Layout::default();
        let mut box_len = 1usize;
        for (b, s) in shapes.chunks_exact(4).enumerate() {
            let (k, n_actions, nnz, max_support) =
                (s[0] as usize, s[1] as usize, s[2] as usize, s[3] as usize);
            let bd = &dims[at..at + k];
            at += k;
            let mut n_cores = 1usize;
            for (j, &d) in bd.iter().enumerate() {
                let d = d as usize;
                if d >= e || seen[d] || (j > 0 && bd[j - 1] as usize >= d) {
                    return Err(bad("decision block state variables"));
                }
                seen[d] = true;
                n_cores = n_cores
                    .checked_mul(grid.dim(d).n_cores())
                    .ok_or(bad("decision block cores"))?;
            }
            if k == 0 || n_actions == 0 || max_support == 0 || max_support > n_cores {
                return Err(bad("decision block shape"));
            }
            let n_rows = n_cores
                .checked_mul(n_actions)
                .ok_or(bad("decision block shape"))?;
            let ptr: &[u32] = r.section(n_rows + 1)?;
            let col: &[u32] = r.section(nnz)?;
            let weight: &[T] = r.section(nnz)?;
            // Every row holds a successor's memberships, so none is empty (an empty support
            // would leave a decision nothing to contract).
            let rows_ok = ptr[0] == 0
                && ptr.windows(2).all(|w| w[0] < w[1])
                && ptr[n_rows] as usize == nnz
                && col.iter().all(|&c| (c as usize) < n_cores)
                && weight.iter().all(|w| w.is_finite() && *w >= T::ZERO);
            if !rows_ok {
                return Err(bad("decision block rows"));
            }
            product = product
                .checked_mul(n_actions)
                .filter(|&p| p <= u32::MAX as usize)
                .ok_or(bad("decision block actions"))?;
            blocks[b] = Block {
                dims: bd,
                n_actions,
                max_support,
                ptr,
                col,
                weight,
            };
            let big = || bad("decision buffers");
            layout.max_cores = layout.max_cores.max(n_cores);
            layout.mixed += n_actions.checked_mul(max_support).ok_or_else(big)?;
            layout.support += max_support;
            layout.ptr += n_actions + 1;
            layout.active = layout.active.max(1 << k);
            box_len = box_len.checked_mul(max_support).ok_or_else(big)?;
        }
        // Stage `l` writes `(prod_{j <= l} A_j) (prod_{j > l} S_j)` values.
        let mut stage = 0usize;
        let mut rest = box_len;
        let mut p = 1usize;
        for b in &blocks[..nb] {
            rest /= b.max_support;
            p *= b.n_actions;
            stage = stage.max(p.checked_mul(rest).ok_or(bad("decision buffers"))?);
        }
        layout.vbox = box_len.checked_add(PAD).ok_or(bad("decision buffers"))?;
        layout.stage = stage + PAD;
        if q_index.iter().any(|&q| q as usize >= product) {
            return Err(bad("decision joint actions"));
        }
        let gamma = r.section::<T>(1)?[0];
        if !(gamma >= T::ZERO && gamma < T::ONE) {
            return Err(bad("discount"));
        }
        let rewards: &[T] = r.section(grid.n_cores())?;
        if !rewards.iter().all(|x| x.is_finite()) {
            return Err(bad("rewards"));
        }
        Ok(Self {
            n_blocks: nb,
            blocks,
            q_index,
            gamma,
            rewards,
            layout,
        })
    }

    /// Words of scratch a decision needs.
    pub(super) fn scratch_words(&self) -> usize {
        self.layout.words(core::mem::size_of::<T>())
    }

    /// `out[u] = Q(x, u)` from `v` on `grid` (see the [module docs](self)).
    pub(super) fn q_values(
        &self,
        grid: &ProductPartition<'a, T>,
        v: &[T],
        x: &[T],
        scratch: &mut [u64],
        out: &mut [T],
    ) -> Result<(), EvalError> {
        crate::error::check_len("Q-values", self.q_index.len(), out.len())?;
        let words = self.scratch_words();
        crate::error::check_at_least("decision scratch (u64 words)", words, scratch.len())?;
        let active = grid.active(x)?;
        let (reals, u32s, u64s) = self.layout.regions();
        let mut rest = &mut scratch[..words];
        let mut take_real = |n: usize| {
            let (a, b) = core::mem::take(&mut rest).split_at_mut((n * size_of::<T>()).div_ceil(8));
            rest = b;
            &mut bytemuck::cast_slice_mut::<u64, T>(a)[..n]
        };
        let dense = take_real(reals[0]);
        let mixed_w = take_real(reals[1]);
        let mu = take_real(reals[2]);
        let vbox = take_real(reals[3]);
        let mut s0 = take_real(reals[4]);
        let mut s1 = take_real(reals[5]);
        let mut take_u32 = |n: usize| {
            let (a, b) = core::mem::take(&mut rest).split_at_mut(n.div_ceil(2));
            rest = b;
            &mut bytemuck::cast_slice_mut::<u64, u32>(a)[..n]
        };
        let hit = take_u32(u32s[0]);
        let touched = take_u32(u32s[1]);
        let in_support = take_u32(u32s[2]);
        let local = take_u32(u32s[3]);
        let support = take_u32(u32s[4]);
        let mixed_ptr = take_u32(u32s[5]);
        let mixed_col = take_u32(u32s[6]);
        let act = take_u32(u32s[7]);
        let offsets = &mut rest[..u64s[0]];
        touched.fill(0);
        in_support.fill(0);

        // Per block: the mixed rows (entries in increasing block core, zeros left out), then
        // their columns as positions in the block's support, and the support's grid offsets.
        let nb = self.n_blocks;
        let mut sizes = [0usize; MAX_DIMS];
        let (mut at_s, mut at_m, mut at_p) = (0usize, 0usize, 0usize);
        let mut spans = [(0usize, 0usize, 0usize); MAX_DIMS];
        for (b, t) in self.blocks[..nb].iter().enumerate() {
            let mut parts = [grid.dim(0); MAX_DIMS];
            let mut xb = [T::ZERO; MAX_DIMS];
            for (j, &d) in t.dims.iter().enumerate() {
                parts[j] = grid.dim(d as usize);
                xb[j] = x[d as usize];
            }
            let k = t.dims.len();
            // The tables were checked when read (1 to `MAX_DIMS` distinct variables of a
            // valid grid), so this cannot fail.
            let sub = ProductPartition::from_partitions(&parts[..k] as &[Partition<'a, T>])
                .map_err(|_| EvalError::OutOfRange {
                    what: "decision block state variables",
                    index: k,
                    len: MAX_DIMS,
                })?;
            let mut n_act = 0;
            sub.active_unchecked(&xb[..k]).for_each(|c, m| {
                act[n_act] = c as u32;
                mu[n_act] = m;
                n_act += 1;
            });
            let sup = &mut support[at_s..at_s + t.max_support];
            let mut n_sup = 0;
            let ptr = &mut mixed_ptr[at_p..at_p + t.n_actions + 1];
            let cols = &mut mixed_col[at_m..at_m + t.n_actions * t.max_support];
            let ws = &mut mixed_w[at_m..at_m + t.n_actions * t.max_support];
            let mut nnz = 0;
            ptr[0] = 0;
            for a in 0..t.n_actions {
                let mut n_hit = 0;
                for (&c, &m) in act[..n_act].iter().zip(&mu[..n_act]) {
                    let row = c as usize * t.n_actions + a;
                    let (s, end) = (t.ptr[row] as usize, t.ptr[row + 1] as usize);
                    for (&kc, &wk) in t.col[s..end].iter().zip(&t.weight[s..end]) {
                        let kc = kc as usize;
                        if touched[kc] == 0 {
                            touched[kc] = 1;
                            dense[kc] = T::ZERO;
                            hit[n_hit] = kc as u32;
                            n_hit += 1;
                        }
                        dense[kc] += m * wk;
                    }
                }
                hit[..n_hit].sort_unstable();
                for &kc in &hit[..n_hit] {
                    let kc = kc as usize;
                    touched[kc] = 0;
                    if in_support[kc] == 0 {
                        in_support[kc] = 1;
                        // Bounded by the file's support bound, checked against the rows.
                        let slot = sup.get_mut(n_sup).ok_or(EvalError::OutOfRange {
                            what: "decision block support",
                            index: n_sup,
                            len: t.max_support,
                        })?;
                        *slot = kc as u32;
                        n_sup += 1;
                    }
                    if dense[kc] != T::ZERO {
                        cols[nnz] = kc as u32;
                        ws[nnz] = dense[kc];
                        nnz += 1;
                    }
                }
                ptr[a + 1] = nnz as u32;
            }
            let sup = &mut sup[..n_sup];
            sup.sort_unstable();
            let offs = &mut offsets[at_s..at_s + n_sup];
            for (i, (&kc, o)) in sup.iter().zip(offs.iter_mut()).enumerate() {
                in_support[kc as usize] = 0;
                local[kc as usize] = i as u32;
                // The block core's grid offset: its variables' indices times their strides.
                let mut c = kc as usize;
                let mut g = 0usize;
                for &d in t.dims.iter().rev() {
                    let d = d as usize;
                    let n = grid.dim(d).n_cores();
                    g += (c % n) * grid.strides()[d];
                    c /= n;
                }
                *o = g as u64;
            }
            for c in &mut cols[..nnz] {
                *c = local[*c as usize];
            }
            sizes[b] = n_sup;
            spans[b] = (at_s, at_m, at_p);
            at_s += t.max_support;
            at_m += t.n_actions * t.max_support;
            at_p += t.n_actions + 1;
        }

        // The box of V over the supports, the first block slowest, copied an inner row at a
        // time with the outer blocks' combinations visited like an odometer.
        let box_len: usize = sizes[..nb].iter().product();
        {
            let inner = &offsets[spans[nb - 1].0..spans[nb - 1].0 + sizes[nb - 1]];
            let mut digit = [0usize; MAX_DIMS];
            let offset = |b: usize, i: usize| offsets[spans[b].0 + i] as usize;
            let mut g: usize = (0..nb - 1).map(|b| offset(b, 0)).sum();
            'combos: for dst in vbox[..box_len].chunks_exact_mut(sizes[nb - 1]) {
                for (d, &o) in dst.iter_mut().zip(inner) {
                    *d = v[g + o as usize];
                }
                let mut l = nb - 1;
                loop {
                    if l == 0 {
                        break 'combos;
                    }
                    l -= 1;
                    g -= offset(l, digit[l]);
                    digit[l] += 1;
                    if digit[l] < sizes[l] {
                        g += offset(l, digit[l]);
                        break;
                    }
                    digit[l] = 0;
                    g += offset(l, 0);
                }
            }
        }

        // The stages, `[p][k][r]` to `[p][a][r]`, a block at a time.
        let mut r = box_len;
        let mut p = 1usize;
        let mut input_is_box = true;
        for (b, t) in self.blocks[..nb].iter().enumerate() {
            let (k, a) = (sizes[b], t.n_actions);
            r /= k;
            let (_, at_m, at_p) = spans[b];
            let ptr = &mixed_ptr[at_p..at_p + a + 1];
            let nnz = ptr[a] as usize;
            let cols = &mixed_col[at_m..at_m + nnz];
            let ws = &mixed_w[at_m..at_m + nnz];
            let input: &[T] = if input_is_box { vbox } else { s1 };
            stage(ptr, cols, ws, k, p, r, input, &mut s0[..p * a * r]);
            p *= a;
            core::mem::swap(&mut s0, &mut s1);
            input_is_box = false;
        }
        let ev = &s1[..p];

        // The interpolated reward, then Q.
        let mut reward = T::ZERO;
        active.for_each(|d, m| reward += m * self.rewards[d]);
        for (o, &q) in out.iter_mut().zip(self.q_index) {
            *o = reward + self.gamma * ev[q as usize];
        }
        Ok(())
    }
}

/// One stage for each of `p` leading indices `i`: `out[(i A + a) r + j] = sum_e w_e
/// input[(i K + k_e) r + j]` over row `a`'s entries in order (`K = n_cols` columns), fused
/// multiply-adds from 0: on the solver's run-time selected kernels with `std`, else on
/// [`stage_scalar`] (the same bits).
#[allow(clippy::too_many_arguments)] // a stage's shape and buffers, spelled out.
fn stage<T: ViewReal>(
    ptr: &[u32],
    col: &[u32],
    weight: &[T],
    n_cols: usize,
    p: usize,
    r: usize,
    input: &[T],
    out: &mut [T],
) {
    let a = ptr.len() - 1;
    #[cfg(feature = "std")]
    let (kernels, rows) = (
        crate::solver::simd::select_real::<T>(None).expect("the scalar kernels exist"),
        crate::solver::simd::Rows::checked(ptr, col, weight, n_cols)
            .expect("mixed rows hold memberships over their support"),
    );
    for (i, o) in out.chunks_exact_mut(a * r).take(p).enumerate() {
        // The chunk's input runs on into the next chunks' (or the padding).
        let input = &input[i * n_cols * r..];
        #[cfg(feature = "std")]
        (kernels.stage)(rows, 0, a, 1, r, input, o);
        #[cfg(not(feature = "std"))]
        stage_scalar(ptr, col, weight, r, input, o);
    }
}

/// One stage (one leading index) on scalar fused multiply-adds: the same bits as the solver's
/// kernels (each element's chain in the same order, every step rounded once).
#[cfg_attr(all(feature = "std", not(test)), allow(dead_code))]
fn stage_scalar<T: ViewReal>(
    ptr: &[u32],
    col: &[u32],
    weight: &[T],
    r: usize,
    input: &[T],
    out: &mut [T],
) {
    for (a, o) in out.chunks_exact_mut(r).enumerate() {
        let (s, e) = (ptr[a] as usize, ptr[a + 1] as usize);
        for (j, o) in o.iter_mut().enumerate() {
            let mut acc = T::ZERO;
            for (&k, &w) in col[s..e].iter().zip(&weight[s..e]) {
                acc = T::fma(w, input[k as usize * r + j], acc);
            }
            *o = acc;
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// The scalar stage of a `no_std` build gives the bits of the solver's kernels.
    #[test]
    fn the_scalar_stage_has_the_kernels_bits() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for (n_cols, r, a) in [(3, 1, 2), (7, 5, 4), (12, 33, 5), (20, 100, 3)] {
            let (mut ptr, mut col, mut w) = (vec![0u32], Vec::new(), Vec::new());
            for _ in 0..a {
                for k in 0..n_cols {
                    if next() < 0.6 {
                        col.push(k as u32);
                        w.push(next() as f32);
                    }
                }
                ptr.push(col.len() as u32);
            }
            let input: Vec<f32> = (0..n_cols * r + PAD)
                .map(|_| (next() * 200.0 - 100.0) as f32)
                .collect();
            let (mut x, mut y) = (vec![0.0f32; a * r], vec![0.0f32; a * r]);
            stage(&ptr, &col, &w, n_cols, 1, r, &input, &mut x);
            stage_scalar(&ptr, &col, &w, r, &input, &mut y);
            let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&x), bits(&y), "{n_cols} columns, r = {r}");
        }
    }
}
