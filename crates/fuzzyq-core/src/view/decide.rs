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
//! buffers ([`super::PolicyView::decision_scratch_len`]) are sized by it and by each block's
//! span bound (the widest range of block cores those rows reach, found when the tables are
//! read).
//!
//! # `V` in decision order
//! With the tables, the `V` section holds `V` in **decision order**: row-major over the
//! blocks' cores, the blocks in contraction order (the first slowest). Core `(k_0, .., k_B-1)`
//! (block cores) is at `sum_b k_b B_b`, `B_b` the product of the later blocks' core counts, so
//! each block's cores lie at one stride and the last block's are contiguous.
//! [`super::PolicyView::value_strides`] gives each state variable's stride in that order.
//!
//! # A decision
//! Per block: the active block cores' rows are mixed into one row per block action (the
//! memberships times the rows, summed over the active block cores in their order, entries in
//! increasing block core). Then the stages contract `V` with them a block at a time, in
//! contraction order, every element a chain of fused multiply-adds from 0 over its row's
//! entries in order, and `Q(x, u) = rho~(x) + gamma E[q_index[u]]` with `rho~` the rewards
//! interpolated at `x`. The first stage reads `V` in place: its rows' columns are block cores
//! at the first block's stride, its leading index runs over the range of block cores the
//! second-to-last block's rows reach (at that block's stride) and its lanes over the range
//! the last block's rows reach (contiguous); the blocks between are visited one support core
//! at a time. So no box of `V` is gathered, and a block core inside a range but outside the
//! rows' support costs a lane, not a copy. Each element is the sum the solver's
//! `Operator::q_values` computes over its gathered box, term for term, so the bits are the
//! same. With `std` the stages run on the solver's run-time selected kernels; without it, on
//! scalar fused multiply-adds (`libm`): the same bits either way.

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
    /// The export's `V` is in its decision tables' order, which the model's backup does not
    /// read: take the decision from the tables ([`super::PolicyView::q_values`]), no model
    /// needed.
    DecisionOrder,
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
            Self::DecisionOrder => write!(
                f,
                "the exported policy's V is in its decision tables' order: take greedy decisions \
                 from the tables (q_values, greedy_action), without the model"
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
    /// Block cores.
    n_cores: usize,
    /// The support bound (from the file).
    max_support: usize,
    /// The span bound: the widest range of block cores one state's mixed rows reach.
    max_span: usize,
    /// Distance in `V` (decision order) between consecutive block cores.
    stride: usize,
    ptr: &'a [u32],
    col: &'a [u32],
    weight: &'a [T],
}

impl<T> Block<'_, T> {
    const EMPTY: Self = Self {
        dims: &[],
        n_actions: 0,
        n_cores: 0,
        max_support: 0,
        max_span: 0,
        stride: 0,
        ptr: &[],
        col: &[],
        weight: &[],
    };
}

/// How a block's mixed rows address the contraction (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    /// The first block: columns are block cores, read from `V` at the block's stride.
    First,
    /// A block between the second and the second-to-last: columns are positions in the
    /// rows' support, visited one support core at a time by the first stage.
    Support,
    /// The last two blocks: columns are positions in the range of block cores the rows
    /// reach (the first stage's leading index, then its lanes).
    Range,
}

/// The role of block `b` of `nb`.
fn role(b: usize, nb: usize) -> Role {
    if b == 0 {
        Role::First
    } else if b + 2 < nb {
        Role::Support
    } else {
        Role::Range
    }
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
    /// One stage buffer, padded.
    stage: usize,
    /// The last stage's transposed input, padded.
    last: usize,
    /// Most active cores of a state (`2^E`).
    cores: usize,
}

/// One decision's scratch, carved from the caller's `u64` words by [`Layout::carve`]: values
/// of the solution's type, `u32` indices and `u64` offsets, each region named for its job.
struct Scratch<'s, T> {
    /// A mixed row's sum per block core, while it is built.
    dense: &'s mut [T],
    /// The mixed rows' weights (every block's, one after the other).
    mixed_w: &'s mut [T],
    /// The memberships of a block's active block cores.
    mu: &'s mut [T],
    /// The last stage's input, transposed.
    transposed: &'s mut [T],
    /// The stages' outputs, in turn.
    s0: &'s mut [T],
    s1: &'s mut [T],
    /// The memberships of the state's active cores.
    core_mu: &'s mut [T],
    /// The block cores a mixed row reaches.
    hit: &'s mut [u32],
    /// Marks of the block cores a mixed row has reached.
    touched: &'s mut [u32],
    /// Marks of the block cores in a block's support.
    in_support: &'s mut [u32],
    /// A support core's position in its support.
    local: &'s mut [u32],
    /// Every support block's support cores.
    support: &'s mut [u32],
    /// The mixed rows' row pointers and columns.
    mixed_ptr: &'s mut [u32],
    mixed_col: &'s mut [u32],
    /// A block's active block cores.
    act: &'s mut [u32],
    /// The support cores' offsets in `V`.
    offsets: &'s mut [u64],
    /// The state's active cores.
    core_index: &'s mut [usize],
}

/// What [`mix_blocks`](Decisions::mix_blocks) found of each block: the columns of its mixed
/// rows (`sizes`), the first block core of a range block (`first`) and where its support,
/// mixed entries and row pointers start in the scratch (`spans`).
struct Mixing {
    sizes: [usize; MAX_DIMS],
    first: [usize; MAX_DIMS],
    spans: [(usize, usize, usize); MAX_DIMS],
}

impl Layout {
    /// `(reals, u32s, u64s)` per region, in order.
    fn regions(&self) -> ([usize; 7], [usize; 8], [usize; 2]) {
        (
            [
                self.max_cores,
                self.mixed,
                self.active,
                self.last,
                self.stage,
                self.stage,
                self.cores,
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
            [self.support, self.cores],
        )
    }

    /// The regions of `scratch` (at least [`words`](Self::words) long) for values of type
    /// `T`.
    fn carve<'s, T: ViewReal>(&self, scratch: &'s mut [u64]) -> Scratch<'s, T> {
        let (reals, u32s, u64s) = self.regions();
        let mut rest = scratch;
        let mut take_real = |n: usize| {
            let (a, b) = core::mem::take(&mut rest).split_at_mut((n * size_of::<T>()).div_ceil(8));
            rest = b;
            &mut bytemuck::cast_slice_mut::<u64, T>(a)[..n]
        };
        let dense = take_real(reals[0]);
        let mixed_w = take_real(reals[1]);
        let mu = take_real(reals[2]);
        let transposed = take_real(reals[3]);
        let s0 = take_real(reals[4]);
        let s1 = take_real(reals[5]);
        let core_mu = take_real(reals[6]);
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
        let (offsets, rest) = rest.split_at_mut(u64s[0]);
        let core_index =
            &mut bytemuck::cast_slice_mut::<u64, usize>(&mut rest[..u64s[1]])[..u64s[1]];
        Scratch {
            dense,
            mixed_w,
            mu,
            transposed,
            s0,
            s1,
            core_mu,
            hit,
            touched,
            in_support,
            local,
            support,
            mixed_ptr,
            mixed_col,
            act,
            offsets,
            core_index,
        }
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

    /// The stage buffers for `blocks` (`sizes[b]`: block `b`'s support bound for
    /// [`Role::Support`], span bound for [`Role::Range`]), padded; `None` on overflow.
    fn stages<T>(blocks: &[Block<'_, T>]) -> Option<(usize, usize)> {
        let nb = blocks.len();
        let a0 = blocks[0].n_actions;
        if nb == 1 {
            return Some((a0 + PAD, PAD));
        }
        let r = if nb >= 3 { blocks[nb - 2].max_span } else { 1 };
        let p = blocks[nb - 1].max_span;
        let tail = r.checked_mul(a0)?.checked_mul(p)?;
        let inner = &blocks[1..nb.saturating_sub(2).max(1)];
        let mut combos = 1usize;
        for b in inner {
            combos = combos.checked_mul(b.max_support)?;
        }
        let mut stage = combos.checked_mul(tail)?;
        let mut lead = 1usize;
        for b in inner {
            combos /= b.max_support;
            lead = lead.checked_mul(b.n_actions)?;
            stage = stage.max(lead.checked_mul(combos)?.checked_mul(tail)?);
        }
        if nb >= 3 {
            lead = lead.checked_mul(blocks[nb - 2].n_actions)?;
            stage = stage.max(lead.checked_mul(a0)?.checked_mul(p)?);
        }
        let m = lead.checked_mul(a0)?;
        stage = stage.max(m.checked_mul(blocks[nb - 1].n_actions)?);
        Some((stage.checked_add(PAD)?, p.checked_mul(m)?.checked_add(PAD)?))
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
    /// Each state variable's stride in `V` (decision order).
    value_strides: [usize; MAX_DIMS],
}

/// A header field or section of the decision tables is invalid.
fn bad(what: &'static str) -> ViewError {
    ViewError::Header { what }
}

/// The widest range of block cores (last minus first, plus one) that the rows of one cell's
/// corner cores reach over every action: the span bound of a block whose rows are
/// `ptr`/`col` over the variables with core counts `counts` (row-major), `n_actions` rows per
/// block core.
fn span_bound(counts: &[usize], n_actions: usize, ptr: &[u32], col: &[u32]) -> usize {
    let k = counts.len();
    let n_cores: usize = counts.iter().product();
    let mut best = 0;
    for cell in 0..n_cores {
        let (mut lo, mut hi) = (u32::MAX, 0u32);
        for corner in 0..(1usize << k) {
            let (mut c, mut stride, mut inside) = (0usize, 1usize, true);
            for j in (0..k).rev() {
                let lower = (cell / stride) % counts[j];
                let i = lower + ((corner >> j) & 1);
                inside &= i < counts[j];
                c += i * stride;
                stride *= counts[j];
            }
            if !inside {
                continue;
            }
            let rows = c * n_actions..(c + 1) * n_actions;
            for &s in &col[ptr[rows.start] as usize..ptr[rows.end] as usize] {
                lo = lo.min(s);
                hi = hi.max(s);
            }
        }
        if lo <= hi {
            best = best.max((hi - lo) as usize + 1);
        }
    }
    best
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
        let big = || bad("decision buffers");
        for (b, s) in shapes.chunks_exact(4).enumerate() {
            let (k, n_actions, nnz, max_support) =
                (s[0] as usize, s[1] as usize, s[2] as usize, s[3] as usize);
            let bd = &dims[at..at + k];
            at += k;
            let mut counts = [0usize; MAX_DIMS];
            let mut n_cores = 1usize;
            for (j, &d) in bd.iter().enumerate() {
                let d = d as usize;
                if d >= e || seen[d] || (j > 0 && bd[j - 1] as usize >= d) {
                    return Err(bad("decision block state variables"));
                }
                seen[d] = true;
                counts[j] = grid.dim(d).n_cores();
                n_cores = n_cores
                    .checked_mul(counts[j])
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
                n_cores,
                max_support,
                max_span: span_bound(&counts[..k], n_actions, ptr, col),
                stride: 0,
                ptr,
                col,
                weight,
            };
            layout.max_cores = layout.max_cores.max(n_cores);
            layout.mixed += n_actions.checked_mul(max_support).ok_or_else(big)?;
            layout.support += max_support;
            layout.ptr += n_actions + 1;
            layout.active = layout.active.max(1 << k);
        }
        // Decision order: the strides of the blocks, then of each block's variables.
        let mut value_strides = [0usize; MAX_DIMS];
        let mut stride = 1usize;
        for t in blocks[..nb].iter_mut().rev() {
            t.stride = stride;
            let mut s = stride;
            for &d in t.dims.iter().rev() {
                value_strides[d as usize] = s;
                s *= grid.dim(d as usize).n_cores();
            }
            stride = stride.checked_mul(t.n_cores).ok_or_else(big)?;
        }
        (layout.stage, layout.last) = Layout::stages(&blocks[..nb]).ok_or_else(big)?;
        layout.cores = 1 << e;
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
            value_strides,
        })
    }

    /// Words of scratch a decision needs.
    pub(super) fn scratch_words(&self) -> usize {
        self.layout.words(core::mem::size_of::<T>())
    }

    /// Each state variable's stride in `V` (decision order).
    pub(super) fn value_strides(&self) -> [usize; MAX_DIMS] {
        self.value_strides
    }

    /// `out[u] = Q(x, u)` from `v` (decision order) on `grid` (see the [module docs](self)).
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
        let mut sc = self.layout.carve::<T>(&mut scratch[..words]);
        sc.touched.fill(0);
        sc.in_support.fill(0);
        let nb = self.n_blocks;
        let Mixing {
            sizes,
            first,
            spans,
        } = self.mix_blocks(grid, x, &mut sc)?;

        let mixed = |b: usize| {
            let (_, at_m, at_p) = spans[b];
            let a = self.blocks[b].n_actions;
            let ptr = &sc.mixed_ptr[at_p..at_p + a + 1];
            let nnz = ptr[a] as usize;
            Mixed {
                ptr,
                col: &sc.mixed_col[at_m..at_m + nnz],
                weight: &sc.mixed_w[at_m..at_m + nnz],
                n_cols: sizes[b],
            }
        };

        // The first stage, from `V` in place: `[S_1]..[S_B-3][R][a_0][P]` (support cores of
        // the blocks between, the range `R` of block B-2's cores, block 0's actions, the
        // range `P` of the last block's cores).
        let a0 = self.blocks[0].n_actions;
        let stride0 = self.blocks[0].stride;
        // Output positions of the block actions after the last stage: `a_0` fastest, then
        // the blocks between in order, the last block's slowest.
        let mut place = [0usize; MAX_DIMS];
        let ev: &[T] = if nb == 1 {
            stage(mixed(0), 1, 1, (stride0, 0), v, &mut sc.s0[..a0]);
            place[0] = 1;
            &sc.s0[..a0]
        } else {
            let (r_len, r_stride) = if nb >= 3 {
                (sizes[nb - 2], self.blocks[nb - 2].stride)
            } else {
                (1, 0)
            };
            let p_len = sizes[nb - 1];
            let tail = first[nb - 1] + if nb >= 3 { first[nb - 2] * r_stride } else { 0 };
            let chunk = r_len * a0 * p_len;
            let inner = 1..nb.saturating_sub(2).max(1);
            let offs = |b: usize, i: usize| sc.offsets[spans[b].0 + i] as usize;
            let mut digit = [0usize; MAX_DIMS];
            let mut g: usize = inner.clone().map(|b| offs(b, 0)).sum();
            let combos: usize = sizes[inner.clone()].iter().product();
            for o in sc.s0[..combos * chunk].chunks_exact_mut(chunk) {
                let here = g;
                // The next combination, the last of the blocks between fastest.
                for l in inner.clone().rev() {
                    g -= offs(l, digit[l]);
                    digit[l] += 1;
                    if digit[l] < sizes[l] {
                        g += offs(l, digit[l]);
                        break;
                    }
                    digit[l] = 0;
                    g += offs(l, 0);
                }
                stage(
                    mixed(0),
                    r_len,
                    p_len,
                    (stride0, r_stride),
                    &v[here + tail..],
                    o,
                );
            }
            // The blocks between, then block B-2: `[lead][k][rest]` to `[lead][a][rest]`.
            let mut lead = 1usize;
            let mut rest = combos * chunk;
            for b in 1..nb - 1 {
                let (k, a) = (sizes[b], self.blocks[b].n_actions);
                rest /= k;
                for i in 0..lead {
                    let o = &mut sc.s1[i * a * rest..(i + 1) * a * rest];
                    stage(mixed(b), 1, rest, (rest, rest), &sc.s0[i * k * rest..], o);
                }
                lead *= a;
                core::mem::swap(&mut sc.s0, &mut sc.s1);
            }
            // The last block contracts the lanes: `[m][P]` transposed to `[P][m]`, then one
            // stage gives `[a_B-1][m]`.
            let m = lead * a0;
            for (i, row) in sc.s0[..m * p_len].chunks_exact(p_len).enumerate() {
                for (j, &y) in row.iter().enumerate() {
                    sc.transposed[j * m + i] = y;
                }
            }
            let a_last = self.blocks[nb - 1].n_actions;
            stage(
                mixed(nb - 1),
                1,
                m,
                (m, m),
                sc.transposed,
                &mut sc.s1[..a_last * m],
            );
            place[0] = 1;
            let mut step = a0;
            for b in (1..nb - 1).rev() {
                place[b] = step;
                step *= self.blocks[b].n_actions;
            }
            place[nb - 1] = m;
            core::mem::swap(&mut sc.s0, &mut sc.s1);
            &sc.s0[..a_last * m]
        };

        // `E` in the tables' order, then `Q`.
        let n: usize = self.blocks[..nb].iter().map(|t| t.n_actions).product();
        let by_q = &mut sc.s1[..n];
        self.reorder(ev, &place, by_q);
        // The active cores listed first (the weights of `for_each`, one product each), so
        // that the rewards' loads overlap.
        let n_active = active
            .write_to(sc.core_index, sc.core_mu)
            .ok_or(EvalError::Length {
                what: "decision scratch (active cores)",
                expected: active.len(),
                found: sc.core_index.len(),
            })?;
        let mut reward = T::ZERO;
        for (&d, &m) in sc.core_index[..n_active]
            .iter()
            .zip(&sc.core_mu[..n_active])
        {
            reward += m * self.rewards[d];
        }
        for (o, &q) in out.iter_mut().zip(self.q_index) {
            *o = reward + self.gamma * by_q[q as usize];
        }
        Ok(())
    }

    /// Mixes every block's transition rows at `x` (the rows of its active block cores,
    /// weighted by their memberships) into `sc`'s mixed rows: entries in increasing block
    /// core, zeros left out, columns as the block's role numbers them, and (support blocks)
    /// the support's offsets in `V`.
    fn mix_blocks(
        &self,
        grid: &ProductPartition<'a, T>,
        x: &[T],
        sc: &mut Scratch<'_, T>,
    ) -> Result<Mixing, EvalError> {
        let nb = self.n_blocks;
        let mut sizes = [0usize; MAX_DIMS];
        let mut first = [0usize; MAX_DIMS];
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
                sc.act[n_act] = c as u32;
                sc.mu[n_act] = m;
                n_act += 1;
            });
            let sup = &mut sc.support[at_s..at_s + t.max_support];
            let mut n_sup = 0;
            let (mut lo, mut hi) = (u32::MAX, 0u32);
            let ptr = &mut sc.mixed_ptr[at_p..at_p + t.n_actions + 1];
            let cols = &mut sc.mixed_col[at_m..at_m + t.n_actions * t.max_support];
            let ws = &mut sc.mixed_w[at_m..at_m + t.n_actions * t.max_support];
            let mut nnz = 0;
            ptr[0] = 0;
            for a in 0..t.n_actions {
                let mut n_hit = 0;
                for (&c, &m) in sc.act[..n_act].iter().zip(&sc.mu[..n_act]) {
                    let row = c as usize * t.n_actions + a;
                    let (s, end) = (t.ptr[row] as usize, t.ptr[row + 1] as usize);
                    for (&kc, &wk) in t.col[s..end].iter().zip(&t.weight[s..end]) {
                        let kc = kc as usize;
                        if sc.touched[kc] == 0 {
                            sc.touched[kc] = 1;
                            sc.dense[kc] = T::ZERO;
                            sc.hit[n_hit] = kc as u32;
                            n_hit += 1;
                        }
                        sc.dense[kc] += m * wk;
                    }
                }
                sc.hit[..n_hit].sort_unstable();
                if n_hit > 0 {
                    lo = lo.min(sc.hit[0]);
                    hi = hi.max(sc.hit[n_hit - 1]);
                }
                for &kc in &sc.hit[..n_hit] {
                    let kc = kc as usize;
                    sc.touched[kc] = 0;
                    if sc.in_support[kc] == 0 {
                        sc.in_support[kc] = 1;
                        // Bounded by the file's support bound, checked against the rows.
                        let slot = sup.get_mut(n_sup).ok_or(EvalError::OutOfRange {
                            what: "decision block sc.support",
                            index: n_sup,
                            len: t.max_support,
                        })?;
                        *slot = kc as u32;
                        n_sup += 1;
                    }
                    if sc.dense[kc] != T::ZERO {
                        cols[nnz] = kc as u32;
                        ws[nnz] = sc.dense[kc];
                        nnz += 1;
                    }
                }
                ptr[a + 1] = nnz as u32;
            }
            let sup = &mut sup[..n_sup];
            for &kc in sup.iter() {
                sc.in_support[kc as usize] = 0;
            }
            match role(b, nb) {
                Role::First => sizes[b] = t.n_cores,
                Role::Support => {
                    sup.sort_unstable();
                    let offs = &mut sc.offsets[at_s..at_s + n_sup];
                    for (i, (&kc, o)) in sup.iter().zip(offs.iter_mut()).enumerate() {
                        sc.local[kc as usize] = i as u32;
                        *o = (kc as usize * t.stride) as u64;
                    }
                    for c in &mut cols[..nnz] {
                        *c = sc.local[*c as usize];
                    }
                    sizes[b] = n_sup;
                }
                Role::Range => {
                    // Every row holds an entry (checked when read), so the range is not empty.
                    let span = (hi - lo) as usize + 1;
                    if span > t.max_span {
                        return Err(EvalError::OutOfRange {
                            what: "decision block range",
                            index: span,
                            len: t.max_span,
                        });
                    }
                    for c in &mut cols[..nnz] {
                        *c -= lo;
                    }
                    sizes[b] = span;
                    first[b] = lo as usize;
                }
            }
            spans[b] = (at_s, at_m, at_p);
            at_s += t.max_support;
            at_m += t.n_actions * t.max_support;
            at_p += t.n_actions + 1;
        }
        Ok(Mixing {
            sizes,
            first,
            spans,
        })
    }

    /// `E`, the last stage's output `ev` (block `b`'s action at stride `place[b]`), into
    /// `by_q` in the tables' order (`[a_0][a_1]..`, the first slowest), visited like an
    /// odometer.
    fn reorder(&self, ev: &[T], place: &[usize; MAX_DIMS], by_q: &mut [T]) {
        let nb = self.n_blocks;
        let mut digit = [0usize; MAX_DIMS];
        let mut pos = 0usize;
        for y in by_q.iter_mut() {
            *y = ev[pos];
            for l in (0..nb).rev() {
                digit[l] += 1;
                pos += place[l];
                if digit[l] < self.blocks[l].n_actions {
                    break;
                }
                pos -= digit[l] * place[l];
                digit[l] = 0;
            }
        }
    }
}

/// A block's mixed rows: one per block action, `n_cols` columns.
#[derive(Clone, Copy)]
struct Mixed<'s, T> {
    ptr: &'s [u32],
    col: &'s [u32],
    weight: &'s [T],
    /// Read by the run-time selected kernels' row check (`std` only).
    #[cfg_attr(not(feature = "std"), allow(dead_code))]
    n_cols: usize,
}

/// One stage, `out[(r A + a) P + p] = sum_e w_e input[k_e K + r S + p]` for `r < r_len`,
/// `p < p_len` (`(K, S)` = `strides`) over row `a`'s entries in order, fused multiply-adds
/// from 0: on the solver's run-time selected kernels with `std`, else on [`stage_scalar`]
/// (the same bits).
fn stage<T: ViewReal>(
    rows: Mixed<'_, T>,
    r_len: usize,
    p_len: usize,
    strides: (usize, usize),
    input: &[T],
    out: &mut [T],
) {
    #[cfg(feature = "std")]
    {
        use crate::solver::simd::{OutStrides, Rows, Strides, select_real};
        let kernels = select_real::<T>(None).expect("the scalar kernels exist");
        let checked = Rows::checked(rows.ptr, rows.col, rows.weight, rows.n_cols)
            .expect("mixed rows hold memberships over their columns");
        let (k_stride, r_stride) = strides;
        let a = rows.ptr.len() - 1;
        let strides = Strides { k_stride, r_stride };
        let dense = OutStrides::dense(a, p_len);
        (kernels.stage_at)(checked, 0, a, r_len, p_len, strides, dense, input, out);
    }
    #[cfg(not(feature = "std"))]
    stage_scalar(rows, r_len, p_len, strides, input, out);
}

/// [`stage`] on scalar fused multiply-adds: the same bits as the solver's kernels (each
/// element's chain in the same order, every step rounded once).
#[cfg_attr(all(feature = "std", not(test)), allow(dead_code))]
fn stage_scalar<T: ViewReal>(
    rows: Mixed<'_, T>,
    r_len: usize,
    p_len: usize,
    (k_stride, r_stride): (usize, usize),
    input: &[T],
    out: &mut [T],
) {
    let a = rows.ptr.len() - 1;
    for (i, o) in out.chunks_exact_mut(p_len).take(r_len * a).enumerate() {
        let (r, u) = (i / a, i % a);
        let (s, e) = (rows.ptr[u] as usize, rows.ptr[u + 1] as usize);
        for (p, o) in o.iter_mut().enumerate() {
            let mut acc = T::ZERO;
            for (&k, &w) in rows.col[s..e].iter().zip(&rows.weight[s..e]) {
                acc = T::fma(w, input[k as usize * k_stride + r * r_stride + p], acc);
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
        // (columns, leading indices, lanes, actions, strides or dense)
        for (n_cols, r_len, p_len, a, strides) in [
            (3, 1, 1, 2, None),
            (7, 1, 5, 4, None),
            (12, 1, 33, 5, None),
            (20, 1, 100, 3, None),
            (9, 4, 17, 5, None),
            (9, 4, 17, 5, Some((400, 23))),
            (5, 3, 1, 2, Some((7, 2))),
            (6, 1, 40, 3, Some((50, 0))),
        ] {
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
            let strides = strides.unwrap_or((r_len * p_len, p_len));
            let extent = (n_cols - 1) * strides.0 + (r_len - 1) * strides.1 + p_len;
            let input: Vec<f32> = (0..extent + PAD)
                .map(|_| (next() * 200.0 - 100.0) as f32)
                .collect();
            let rows = Mixed {
                ptr: &ptr,
                col: &col,
                weight: &w,
                n_cols,
            };
            let n = r_len * a * p_len;
            let (mut x, mut y) = (vec![0.0f32; n], vec![0.0f32; n]);
            // Unpadded (as `V` is read) and padded inputs.
            stage(rows, r_len, p_len, strides, &input[..extent], &mut x);
            stage_scalar(rows, r_len, p_len, strides, &input, &mut y);
            let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&x),
                bits(&y),
                "{n_cols} columns, R = {r_len}, P = {p_len}"
            );
            stage(rows, r_len, p_len, strides, &input, &mut x);
            assert_eq!(bits(&x), bits(&y), "padded");
        }
    }
}
