//! The block backup path.
//!
//! # Tables
//! For block `b` with state variables `S_b` (`n_b` block cores: the product of their core
//! counts) and the distinct values `A_b` that its action components take over the joint
//! actions, the table holds one sparse row per (block core `c`, block action `a`): the
//! memberships of the block's successor `f_b(x_c, a)` over the block's cores. Rows are built by
//! stepping the full model from a representative state (the other variables at their first
//! core, the other action components from joint action 0) and checked against three more
//! contexts (all last cores with the last joint action, all middle cores, and a context that
//! varies from row to row): a declared block whose successor differs is refused. This is a
//! spot check, not a proof; `BackupPath::Generic` gives the reference to test against.
//!
//! # Contraction
//! With blocks taken in contraction order `0..B` (the reverse of the declaration order), the
//! expectation of `V` after joint action `u = (a_0, ..., a_{B-1})` from core `(c_0, ..., c_{B-1})`
//! is `sum_{k_0..k_{B-1}} prod_b T_b[c_b, a_b, k_b] V[k_0, ..., k_{B-1}]`. Stage `b` contracts
//! block `b` for a fixed `c_b`: from a tensor `[k_b][rest][prefix]` it produces
//! `[rest][a_b][prefix]`, where `rest` runs over the later blocks' cores and `prefix` over the
//! earlier blocks' actions. After the last stage a core's row holds one value per product
//! action index `p = sum_b a_b prod_{i<b} |A_i|`, which equals the joint index when the blocks
//! were declared in the joint action's radix order (no gather is needed then).
//!
//! # Terminal states
//! A terminal test on the joint successor does not factor over blocks. For a model that
//! declares terminal states, the tables also keep every block row's successor, and a one-time
//! scan assembles the joint successor of every (core, joint action) pair from them and records
//! the terminal pairs per core. Slabs without terminal pairs run exactly as before (fused last
//! stage); the others deliver full rows, whose terminal entries are set to 0 before the
//! reduction. [`BlockOperator::q_values`] takes the terminal pairs of the active cores back
//! out, as it does for absorbing goal cores.
//!
//! Cost per sweep on the paper grid (4 blocks of 45 cores and 5 actions, at most 4 successor
//! entries per row): about 1.25e10 multiply-adds, 82% of them in the last stage.

use std::boxed::Box;
use std::sync::{Mutex, PoisonError};
use std::vec::Vec;

use super::simd::{
    EvalIn, INPUT_PAD, InRows, Kernels, OutStrides, PairScratch, Rows, RowsBuf, Strides, interleave,
};
use super::{Operator, Reduce, SolveError, par};
use crate::action::JointActions;
use crate::model::Model;
use crate::partition::{MAX_DIMS, ProductPartition, Segment};
use crate::real::Real;

/// Bytes per cache line on the CPUs the kernels target (x86-64; most ARM cores).
const CACHE_LINE: usize = 64;

/// Elements of `T` per cache line.
const fn line_len<T>() -> usize {
    CACHE_LINE / core::mem::size_of::<T>()
}

/// Leading indices per piece of a first stage whose rows hold one value (see
/// [`BlockOperator::stage`]): 2,048 of them keep each piece's input stretches (one per
/// successor) and its `[a][r]` output in the second-level cache of any CPU the kernels
/// target, and far from the first level's limits of the rows' bookkeeping. The unit tests'
/// small grids use pieces of 7, so that they run several pieces and a shorter last one.
const FIRST_STAGE_PIECE: usize = if cfg!(test) { 7 } else { 2048 };

/// One block's sparse transition table.
struct BlockTable<T> {
    /// The block's state variables (grid dimensions).
    dims: Vec<usize>,
    /// Number of block cores.
    n_cores: usize,
    /// Number of distinct block actions.
    n_actions: usize,
    /// Row-major grid offset of each block core (its contribution to the flat grid index).
    grid_offset: Vec<usize>,
    /// One row per (block core, block action): the successor's memberships.
    rows: RowsBuf<T>,
    /// The block's successor values per (block core, block action), `dims.len()` each; kept
    /// only for a model with terminal states.
    succ: Vec<T>,
    /// Row-major strides of the block core index over `dims` (the last variable fastest).
    strides: Vec<usize>,
}

impl<T: Real> BlockTable<T> {
    fn row(&self, c: usize, a: usize) -> (&[u32], &[T]) {
        self.rows.view().row(c * self.n_actions + a)
    }
}

/// How the last stage delivers its results.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Last {
    /// Every core's row of expected values, one [`Out::Row`] per core.
    Rows,
    /// Fused with the maximum over actions (of the absolute value if `abs`): one
    /// [`Out::Max`] per run of the last block's cores.
    Max {
        /// Maximum of the absolute values.
        abs: bool,
    },
    /// The maximum and the lowest maximising action of each core: one [`Out::Arg`] per run.
    Argmax,
    /// The expected value under one given action per core (policy evaluation): one
    /// [`Out::Max`] per run.
    Eval,
}

/// What a run delivers: for the core(s) starting at its first argument.
enum Out<'a, T> {
    Row(&'a [T]),
    Max(&'a [T]),
    Arg(&'a [T], &'a [u32]),
}

/// Per-task buffers of the block path.
struct Work<T> {
    /// One output buffer per stage.
    stages: Vec<Vec<T>>,
    /// Everything else the stages use.
    extra: Extra<T>,
    /// Reduction buffers.
    reduce: super::ReduceWork<T>,
}

/// Buffers besides the stage outputs.
struct Extra<T> {
    /// A piece of a stage over rows of one value computed transposed (`[a][r]`), before it
    /// is interleaved into `[r][a]` ([`BlockOperator::first_stage_piece_len`]).
    scratch: Vec<T>,
    /// Maxima of a run of last-block cores.
    maxima: Vec<T>,
    /// Argmaxes of a run of last-block cores.
    args: Vec<u32>,
    /// Row bounds of the pruned last stage.
    bounds: Vec<T>,
    /// The evaluation's shared second-to-last stages ([`PairScratch`]).
    pair_inner: Vec<T>,
    /// Their rows by (block action, prior actions).
    pair_slots: Vec<u32>,
}

pub(super) struct BlockOperator<T: 'static> {
    /// Tables in contraction order.
    tables: Vec<BlockTable<T>>,
    /// The kernels chosen for this CPU.
    kernels: &'static Kernels<T>,
    /// Per stage: product of the later blocks' core counts.
    r_len: Vec<usize>,
    /// Per stage: product of the earlier blocks' action counts.
    p_len: Vec<usize>,
    /// Joint index -> product index, `None` when they coincide.
    map: Option<Vec<u32>>,
    /// The (core, joint action) pairs whose successor is terminal, if the model has terminal
    /// states.
    terminals: Option<Terminals>,
    /// What [`Self::q_values`] needs besides the tables (boxed: the operator stays small).
    q: Box<QPlan<T>>,
}

/// Index maps and buffers of [`BlockOperator::q_values`].
struct QPlan<T> {
    /// Per grid variable: its stride in the internal core index.
    internal_strides: Vec<usize>,
    /// Per joint action: its position in the contraction's result (block actions in gather
    /// order, the first slowest).
    q_index: Vec<u32>,
    /// Blocks in the order `V` is gathered and contracted (the block of the largest grid
    /// strides outermost, so the innermost loop reads nearby values).
    gather_order: Vec<usize>,
    /// Buffers, kept between calls (one per concurrent caller).
    work: Mutex<Vec<QWork<T>>>,
}

/// The terminal (core, joint action) pairs, by internal core index.
struct Terminals {
    /// Core `i`'s terminal joint actions are `actions[ptr[i]..ptr[i + 1]]`, increasing.
    ptr: Vec<usize>,
    /// Joint action indices.
    actions: Vec<u32>,
    /// Per slab: whether any of its cores has a terminal pair.
    slab: Vec<bool>,
}

impl<T: Real> BlockOperator<T> {
    pub(super) fn new<M: Model<T> + Sync + ?Sized>(
        model: &M,
        grid: &ProductPartition<'_, T>,
        joint: &JointActions<'_, T>,
    ) -> Result<Self, SolveError> {
        let e = grid.n_dims();
        let nb = model.n_blocks();
        check_blocks(model, e, joint.dim())?;
        let m = joint.n_joint();
        let terminal = model.has_terminal_states();
        let mut tables = Vec::with_capacity(nb);
        // Per joint action, each block's action index (in contraction order).
        let mut block_action = vec![vec![0u32; m]; nb];
        for (level, b) in (0..nb).rev().enumerate() {
            let block = model.block(b);
            let dims = block.state_dims.to_vec();
            let comps = block.action_components;
            let sub = sub_partition(grid, &dims);
            let tuples = action_tuples(joint, comps, &mut block_action[level]);
            let Some(given) = model.block_rows(b) else {
                tables.push(stepped_table(
                    model, grid, joint, b, dims, comps, &tuples, &sub,
                )?);
                continue;
            };
            if terminal {
                return Err(SolveError::BlockDeclaration {
                    block: b,
                    reason: "a model with terminal states cannot give its block tables",
                });
            }
            let (rows, grid_offset) = given_rows(&given, comps, &tuples, &sub, grid, &dims)
                .map_err(|reason| SolveError::BlockDeclaration { block: b, reason })?;
            tables.push(BlockTable {
                dims,
                n_cores: sub.n_cores(),
                n_actions: tuples.len(),
                grid_offset,
                rows,
                succ: Vec::new(),
                strides: sub.strides().to_vec(),
            });
        }
        Self::assemble(model, grid, tables, &block_action, m)
    }

    /// The operator of the block `tables` (contraction order; `block_action[b][u]`: joint
    /// action `u`'s action of block `b`): the stages' lengths, the joint actions' product
    /// indices, the decisions' plan, and the terminal successors of a model with terminal
    /// states.
    fn assemble<M: Model<T> + Sync + ?Sized>(
        model: &M,
        grid: &ProductPartition<'_, T>,
        tables: Vec<BlockTable<T>>,
        block_action: &[Vec<u32>],
        m: usize,
    ) -> Result<Self, SolveError> {
        let (e, nb) = (grid.n_dims(), tables.len());
        let terminal = model.has_terminal_states();
        let mut r_len = vec![1usize; nb];
        let mut p_len = vec![1usize; nb];
        for b in (0..nb.saturating_sub(1)).rev() {
            r_len[b] = r_len[b + 1] * tables[b + 1].n_cores;
        }
        let mut product: u64 = 1;
        for b in 0..nb {
            p_len[b] = product as usize;
            product = product
                .checked_mul(tables[b].n_actions as u64)
                .filter(|&p| p <= u64::from(u32::MAX))
                .ok_or(SolveError::TooLarge {
                    what: "product of block action sets",
                })?;
        }
        let product_len = product as usize;
        let map: Vec<u32> = (0..m)
            .map(|u| {
                (0..nb)
                    .map(|b| block_action[b][u] as usize * p_len[b])
                    .sum::<usize>() as u32
            })
            .collect();
        let identity = product_len == m && map.iter().enumerate().all(|(u, &p)| p as usize == u);
        let mut internal_strides = vec![0usize; e];
        for (t, &r) in tables.iter().zip(&r_len) {
            for (&d, &s) in t.dims.iter().zip(&t.strides) {
                internal_strides[d] = s * r;
            }
        }
        let min_stride = |b: usize| {
            tables[b]
                .dims
                .iter()
                .map(|&d| grid.strides()[d])
                .min()
                .unwrap_or(0)
        };
        let mut gather_order: Vec<usize> = (0..nb).collect();
        gather_order.sort_by_key(|&b| core::cmp::Reverse(min_stride(b)));
        // Position of block action tuple (a_0, ..., a_{B-1}) in the decisions' contraction,
        // the blocks in gather order with the first slowest.
        let mut suffix = vec![1usize; nb];
        for l in (0..nb.saturating_sub(1)).rev() {
            suffix[gather_order[l]] =
                suffix[gather_order[l + 1]] * tables[gather_order[l + 1]].n_actions;
        }
        let q_index = map
            .iter()
            .map(|&p| {
                (0..nb)
                    .map(|b| (p as usize / p_len[b]) % tables[b].n_actions * suffix[b])
                    .sum::<usize>() as u32
            })
            .collect();
        let mut op = Self {
            tables,
            kernels: super::simd::select_real::<T>(None).expect("the scalar kernels always exist"),
            r_len,
            p_len,
            map: (!identity).then_some(map),
            terminals: None,
            q: Box::new(QPlan {
                internal_strides,
                q_index,
                gather_order,
                work: Mutex::new(Vec::new()),
            }),
        };
        op.lay_out_groups();
        if terminal {
            op.terminals = Some(op.scan_terminals(model, e, m));
        }
        Ok(op)
    }

    /// The product index of joint action `u`.
    fn product_index(&self, u: usize) -> usize {
        self.map.as_ref().map_or(u, |m| m[u] as usize)
    }

    /// Writes the joint successor of block cores `cores` (contraction order) under joint
    /// action `u` into `x`, from the blocks' stored successors.
    fn assemble_successor(&self, cores: &[usize], u: usize, x: &mut [T]) {
        let p = self.product_index(u);
        for (b, t) in self.tables.iter().enumerate() {
            let a = (p / self.p_len[b]) % t.n_actions;
            let k = t.dims.len();
            let s = &t.succ[(cores[b] * t.n_actions + a) * k..][..k];
            for (&d, &v) in t.dims.iter().zip(s) {
                x[d] = v;
            }
        }
    }

    /// Finds every (core, joint action) pair whose successor is terminal (once, in parallel
    /// over slabs).
    fn scan_terminals<M: Model<T> + Sync + ?Sized>(
        &self,
        model: &M,
        e: usize,
        m: usize,
    ) -> Terminals {
        let nb = self.tables.len();
        let slab = self.slab_len();
        let per_slab = par::map_indexed(
            self.tables[0].n_cores,
            1,
            || (vec![T::ZERO; e], vec![0usize; nb]),
            |(x, cores), c0| {
                cores.fill(0);
                cores[0] = c0;
                let mut lens = Vec::with_capacity(slab);
                let mut actions = Vec::new();
                for _ in 0..slab {
                    let before = actions.len();
                    for u in 0..m {
                        self.assemble_successor(cores, u, x);
                        if model.is_terminal(x) {
                            actions.push(u as u32);
                        }
                    }
                    lens.push(actions.len() - before);
                    // Next core of the slab: an odometer over the later blocks.
                    for b in (1..nb).rev() {
                        cores[b] += 1;
                        if cores[b] < self.tables[b].n_cores {
                            break;
                        }
                        cores[b] = 0;
                    }
                }
                (lens, actions)
            },
        );
        let mut ptr = Vec::with_capacity(self.tables[0].n_cores * slab + 1);
        let mut actions = Vec::new();
        let mut has = Vec::with_capacity(per_slab.len());
        ptr.push(0);
        for (lens, a) in per_slab {
            has.push(!a.is_empty());
            for l in lens {
                ptr.push(ptr.last().expect("non-empty") + l);
            }
            actions.extend(a);
        }
        Terminals {
            ptr,
            actions,
            slab: has,
        }
    }

    /// The terminal joint actions of core `internal` (empty without terminal states).
    fn terminal_actions(&self, internal: usize) -> &[u32] {
        match &self.terminals {
            None => &[],
            Some(t) => &t.actions[t.ptr[internal]..t.ptr[internal + 1]],
        }
    }

    /// How slab `c0`'s last stage delivers for the reduction `kind`: fused unless the slab
    /// has terminal pairs (their entries must be zeroed in full rows first).
    fn last_for(&self, fused: Option<Last>, c0: usize) -> Last {
        match &self.terminals {
            Some(t) if t.slab[c0] => Last::Rows,
            _ => fused.unwrap_or(Last::Rows),
        }
    }

    pub(super) fn joint_to_product(&self) -> Option<&[u32]> {
        self.map.as_deref()
    }

    pub(super) fn slab_len(&self) -> usize {
        self.r_len[0]
    }

    /// Uses the kernels `choice`, if this CPU can run them.
    pub(super) fn set_kernel(&mut self, choice: super::Kernel) -> Result<(), SolveError> {
        self.kernels = super::simd::select_real::<T>(Some(choice))
            .ok_or(SolveError::KernelUnavailable(choice))?;
        self.lay_out_groups();
        Ok(())
    }

    /// The tables' merged steps laid out for the kernels' vectors (the same weights).
    fn lay_out_groups(&mut self) {
        for t in &mut self.tables {
            t.rows.set_group_lanes(self.kernels.lanes);
        }
    }

    /// Name of the kernel instance in use (`"avx512"`, `"avx2"`, `"portable"` or `"scalar"`).
    pub(super) fn kernel_name(&self) -> &'static str {
        self.kernels.name
    }

    /// Multiply-adds of one sweep: stage `b` runs once per combination of the earlier blocks'
    /// cores, over every stored entry of its table, `R_b * P_b` lanes each.
    pub(super) fn multiply_adds(&self) -> f64 {
        let mut contexts = 1.0;
        let mut total = 0.0;
        for (b, t) in self.tables.iter().enumerate() {
            total += contexts * t.rows.nnz() as f64 * (self.r_len[b] * self.p_len[b]) as f64;
            contexts *= t.n_cores as f64;
        }
        total
    }

    /// Length of stage `b`'s output for one block core.
    fn stage_len(&self, b: usize) -> usize {
        self.r_len[b] * self.tables[b].n_actions * self.p_len[b]
    }

    /// Length of the scratch in which [`Self::stage`] computes a piece of a stage whose rows
    /// hold one value (the first stage; a later one after blocks of one action): one piece,
    /// not the whole stage, since every task of a Gauss-Seidel sweep makes fresh buffers
    /// and a larger one costs its page faults each time.
    fn first_stage_piece_len(&self) -> usize {
        (0..self.tables.len())
            .filter(|&b| self.p_len[b] == 1)
            .map(|b| FIRST_STAGE_PIECE.min(self.r_len[b]) * self.tables[b].n_actions)
            .max()
            .unwrap_or(0)
    }

    /// The fused last stage's input rows when the stage before it computes them (`None` for
    /// a single block, whose last stage reads `V`): each successor core's row of prior
    /// actions padded so that the last stage, which loads every vector of a row once per
    /// entry of a core's rows, never loads across two cache lines. A row longer than a line
    /// is padded to whole lines; a shorter one to a power of two, which divides the line,
    /// so rows of four values stay four values apart (the input stays small).
    fn last_in(&self) -> Option<InRows> {
        let nb = self.tables.len();
        let p_len = self.p_len[nb - 1];
        let stride = if p_len <= line_len::<T>() {
            p_len.next_power_of_two()
        } else {
            p_len.next_multiple_of(line_len::<T>())
        };
        (nb >= 2).then_some(InRows { p_len, stride })
    }

    /// Length of the buffer of stage `b`'s output: its own, padded past the end for the
    /// kernels' fastest loads, and for the stage before the fused last one, the padded
    /// rows of [`Self::last_in`] and room to start them on a cache line.
    fn stage_buffer_len(&self, b: usize) -> usize {
        match self.last_in() {
            // (The padded rows span at least the dense ones.)
            Some(shape) if b + 2 == self.tables.len() => {
                shape.extent(self.r_len[b]) + INPUT_PAD + line_len::<T>()
            }
            _ => self.stage_len(b) + INPUT_PAD,
        }
    }

    /// The rows of stage `level`: `rows0` for the first (the block's own rows, or those rows
    /// with their columns renumbered into a halo of input slabs), the block's own otherwise.
    #[inline]
    fn rows<'r>(&'r self, rows0: Rows<'r, T>, level: usize) -> Rows<'r, T> {
        if level == 0 {
            rows0
        } else {
            self.tables[level].rows.view()
        }
    }

    /// Fresh per-task buffers.
    fn work<M: Model<T> + Sync + ?Sized>(&self, op: &Operator<'_, T, M>) -> Work<T> {
        let last = self.tables.last().expect("at least one block");
        let nb = self.tables.len();
        let (pair_inner, pair_slots) = if nb >= 3 {
            let block = &self.tables[nb - 2];
            PairScratch::<T>::lens(
                last.n_cores,
                block.n_actions,
                self.p_len[nb - 2],
                last.n_cores,
            )
        } else {
            (0, 0)
        };
        Work {
            stages: self
                .tables
                .iter()
                .enumerate()
                .map(|(b, _)| vec![T::ZERO; self.stage_buffer_len(b)])
                .collect(),
            extra: Extra {
                scratch: vec![T::ZERO; self.first_stage_piece_len()],
                maxima: vec![T::ZERO; last.n_cores],
                args: vec![0; last.n_cores],
                bounds: vec![T::ZERO; last.n_cores],
                pair_inner: vec![T::ZERO; pair_inner],
                pair_slots: vec![0; pair_slots],
            },
            reduce: op.reduce_work(),
        }
    }

    /// Stage `level` for block core `c`: `out = T_level[c] x input`. A stage over rows of one
    /// value (the first stage) runs transposed, as `n_actions` long rows, then interleaves.
    /// Its output rows (one per core of the later blocks) are `r_stride` elements apart.
    #[allow(clippy::too_many_arguments)] // the stage's context, spelled out
    fn stage(
        &self,
        rows0: Rows<'_, T>,
        level: usize,
        c: usize,
        input: &[T],
        (out, r_stride): (&mut [T], usize),
        scratch: &mut [T],
    ) {
        let t = &self.tables[level];
        let rows = self.rows(rows0, level);
        let (r, p, na) = (self.r_len[level], self.p_len[level], t.n_actions);
        if p == 1 && r > 1 && na > 1 {
            // Rows of one value: each action's row along `r` in whole vectors (`[a][r]`), then
            // interleaved to `[r][a]`, a piece of `r` at a time so that the actions reread
            // their input and the interleave rereads their output from cache (the same sums).
            let strides = Strides {
                k_stride: r,
                r_stride: 0,
            };
            for r0 in (0..r).step_by(FIRST_STAGE_PIECE) {
                let n = FIRST_STAGE_PIECE.min(r - r0);
                let piece = &mut scratch[..na * n];
                let out_strides = OutStrides {
                    r_stride: 0,
                    a_stride: n,
                };
                let input = &input[r0..];
                (self.kernels.stage_at)(rows, c * na, na, 1, n, strides, out_strides, input, piece);
                interleave(piece, na, (&mut out[r0 * r_stride..], r_stride));
            }
        } else {
            let out_strides = OutStrides {
                r_stride,
                a_stride: p,
            };
            let strides = Strides::dense(r, p);
            (self.kernels.stage_at)(rows, c * na, na, r, p, strides, out_strides, input, out);
        }
    }

    /// The fused last stage on `input` for the last-block cores `first..first + n`;
    /// `policy` holds their product actions for [`Last::Eval`].
    #[allow(clippy::too_many_arguments)] // the stage's context, spelled out
    fn last_stage<'w>(
        &self,
        rows0: Rows<'_, T>,
        level: usize,
        first: usize,
        n: usize,
        (input, shape): (&[T], InRows),
        last: Last,
        extra: &'w mut Extra<T>,
        policy: &[u32],
    ) -> Out<'w, T> {
        let t = &self.tables[level];
        let (rows, na) = (self.rows(rows0, level), t.n_actions);
        let m = &mut extra.maxima[..n];
        let bounds = &mut extra.bounds;
        match last {
            Last::Max { abs } => {
                (self.kernels.last)(rows, first, na, shape, abs, input, m, bounds, None);
                Out::Max(m)
            }
            Last::Argmax => {
                let a = &mut extra.args[..n];
                let args = Some(&mut *a);
                (self.kernels.last)(rows, first, na, shape, false, input, m, bounds, args);
                Out::Arg(m, a)
            }
            Last::Eval => {
                (self.kernels.eval)(rows, first, na, shape.into(), input, &policy[..n], m);
                Out::Max(m)
            }
            Last::Rows => unreachable!("rows are not fused"),
        }
    }

    /// Runs stage `level` for block core `c` on `input`, then the later stages for every core
    /// of the later blocks, delivering the results as `last` says; `local` numbers the cores
    /// among those sharing the blocks before `level`, and `policy` holds the product actions
    /// of those cores for [`Last::Eval`] (empty otherwise).
    #[allow(clippy::too_many_arguments)] // recursion state, spelled out
    fn run<E: FnMut(usize, Out<'_, T>)>(
        &self,
        rows0: Rows<'_, T>,
        level: usize,
        c: usize,
        input: &[T],
        stages: &mut [Vec<T>],
        extra: &mut Extra<T>,
        local: usize,
        last: Last,
        policy: &[u32],
        emit: &mut E,
    ) {
        let nb = self.tables.len();
        let pol = |first: usize, n: usize| {
            if policy.is_empty() {
                policy
            } else {
                &policy[first..first + n]
            }
        };
        if last != Last::Rows && level + 1 == nb {
            // A single block: this stage is the last one, for core `c` alone.
            let input = (input, InRows::dense(self.p_len[level]));
            let out = self.last_stage(rows0, level, c, 1, input, last, extra, pol(local, 1));
            emit(local, out);
            return;
        }
        let (out, deeper) = stages.split_first_mut().expect("one buffer per stage");
        if last == Last::Eval && level + 3 == nb {
            // The stage before the last two, action by action along whole rows (`[a][r][p]`,
            // full vectors), then the last two stages for the given actions only: a few
            // products per core instead of the next stage for every action. Every element is
            // the same sum as in a full backup, so evaluating the greedy actions gives its bits.
            let t = &self.tables[level];
            let (na, rp) = (t.n_actions, self.r_len[level] * self.p_len[level]);
            let rows = self.rows(rows0, level);
            self.kernels
                .stage(rows, c * na, na, 1, rp, input, &mut out[..na * rp]);
            let prior = (self.p_len[level + 1], self.p_len[level]);
            self.eval_pairs(level, out, prior, extra, local, policy, emit);
            return;
        }
        if last == Last::Eval && level + 4 == nb && self.p_len[level] == 1 {
            let bufs = (&mut out[..], &mut *deeper);
            self.eval_before_three(rows0, level, c, input, bufs, extra, local, policy, emit);
            return;
        }
        if last == Last::Eval && level + 2 == nb && self.p_len[level] == 1 {
            // Two blocks: the first stage action by action along whole rows (`[a][r]`, as its
            // pieces compute it) and the last stage reading each core's action from that
            // layout (no interleave). The same sums in the same order, so the same bits.
            let t = &self.tables[level];
            let (na, r) = (t.n_actions, self.r_len[level]);
            let rows = self.rows(rows0, level);
            let staged = &mut out[..na * r];
            self.kernels.stage(rows, c * na, na, 1, r, input, staged);
            let next = &self.tables[level + 1];
            let n = next.n_cores;
            let m = &mut extra.maxima[..n];
            let shape = EvalIn::transposed(na, r);
            let rows = self.rows(rows0, level + 1);
            (self.kernels.eval)(rows, 0, next.n_actions, shape, staged, pol(local * n, n), m);
            emit(local * n, Out::Max(m));
            return;
        }
        if let Some(shape) = self
            .last_in()
            .filter(|_| last != Last::Rows && level + 2 == nb)
        {
            // Into the padded rows the fused last stage reads, from a cache line on (the
            // buffer has a line's room for it; `align_offset` may decline, which only costs
            // speed).
            let start = match out.as_ptr().align_offset(CACHE_LINE) {
                s if s <= line_len::<T>() => s,
                _ => 0,
            };
            let out = &mut out[start..];
            self.stage(
                rows0,
                level,
                c,
                input,
                (out, shape.stride),
                &mut extra.scratch,
            );
            let n = self.tables[level + 1].n_cores;
            let input = (&*out, shape);
            let out = self.last_stage(
                rows0,
                level + 1,
                0,
                n,
                input,
                last,
                extra,
                pol(local * n, n),
            );
            emit(local * n, out);
            return;
        }
        let dense = self.tables[level].n_actions * self.p_len[level];
        self.stage(rows0, level, c, input, (out, dense), &mut extra.scratch);
        if level + 1 == nb {
            emit(local, Out::Row(&out[..self.stage_len(level)]));
            return;
        }
        let next = &self.tables[level + 1];
        for c2 in 0..next.n_cores {
            self.run(
                rows0,
                level + 1,
                c2,
                out,
                deeper,
                extra,
                local * next.n_cores + c2,
                last,
                policy,
                emit,
            );
        }
    }

    /// [`run`](Self::run) evaluating the greedy actions where four blocks remain from
    /// `level`, whose rows have no prior actions: the first stage action by action (`[a][r]`,
    /// as the transposed first stage computes it), then the stage before the last two for each
    /// of the next block's cores with the prior actions outermost, `[a'][a][r']`: the last
    /// block's successors are then contiguous, and the last two stages share each (block
    /// action, prior actions) pair's contraction among the cores that take it. The same sums
    /// in the same order, so the same bits.
    #[allow(clippy::too_many_arguments)] // run's recursion state
    fn eval_before_three<E: FnMut(usize, Out<'_, T>)>(
        &self,
        rows0: Rows<'_, T>,
        level: usize,
        c: usize,
        input: &[T],
        (out, deeper): (&mut [T], &mut [Vec<T>]),
        extra: &mut Extra<T>,
        local: usize,
        policy: &[u32],
        emit: &mut E,
    ) {
        let t = &self.tables[level];
        let (na, r) = (t.n_actions, self.r_len[level]);
        let rows = self.rows(rows0, level);
        self.kernels
            .stage(rows, c * na, na, 1, r, input, &mut out[..na * r]);
        let next = &self.tables[level + 1];
        let (na1, r1) = (next.n_actions, self.r_len[level + 1]);
        let out1 = deeper.first_mut().expect("one buffer per stage");
        let strides = Strides {
            k_stride: r1,
            r_stride: next.n_cores * r1,
        };
        // Every action of the next block in one call (their rows merged), into `[a'][a][r']`.
        let out_strides = OutStrides {
            r_stride: r1,
            a_stride: na * r1,
        };
        let rows1 = next.rows.view();
        for c1 in 0..next.n_cores {
            let o = &mut out1[..na1 * na * r1];
            (self.kernels.stage_at)(rows1, c1 * na1, na1, na, r1, strides, out_strides, out, o);
            let local1 = local * next.n_cores + c1;
            self.eval_pairs(level + 1, out1, (na1 * na, 1), extra, local1, policy, emit);
        }
    }

    /// The last two stages for the given actions of the cores under block core `local` of
    /// block `level` (every core of block `level + 1`, then of the last block), from `input`,
    /// the stage before them in the layout `prior = (P, P_in)` says (see
    /// [`super::simd::EvalPairFn`]).
    #[allow(clippy::too_many_arguments)] // recursion state, spelled out
    fn eval_pairs<E: FnMut(usize, Out<'_, T>)>(
        &self,
        level: usize,
        input: &[T],
        prior: (usize, usize),
        extra: &mut Extra<T>,
        local: usize,
        policy: &[u32],
        emit: &mut E,
    ) {
        let (block, next) = (&self.tables[level + 1], &self.tables[level + 2]);
        let n = next.n_cores;
        let Extra {
            maxima,
            pair_inner,
            pair_slots,
            ..
        } = extra;
        for c2 in 0..block.n_cores {
            let first = (local * block.n_cores + c2) * n;
            let m = &mut maxima[..n];
            let scratch = PairScratch {
                inner: pair_inner,
                slots: pair_slots,
            };
            (self.kernels.eval_pair)(
                block.rows.view(),
                c2,
                next.rows.view(),
                (block.n_actions, next.n_actions),
                prior,
                input,
                &policy[first..first + n],
                m,
                scratch,
            );
            emit(first, Out::Max(m));
        }
    }

    /// Every core of slab `c0` against `v` (internal order), sequentially.
    fn slab<E: FnMut(usize, Out<'_, T>)>(
        &self,
        c0: usize,
        v: &[T],
        w: &mut Work<T>,
        last: Last,
        emit: &mut E,
    ) {
        let rows0 = self.tables[0].rows.view();
        self.run(
            rows0,
            0,
            c0,
            v,
            &mut w.stages,
            &mut w.extra,
            0,
            last,
            &[],
            emit,
        );
    }

    /// Whether the last stage can be fused with the reduction `kind`: the maximum over the
    /// product actions is the maximum over joint actions (identity map) and, for `Max`, the
    /// reward does not depend on the action.
    ///
    /// A single block is never fused: there a slab is one core, and the fused kernel bounds
    /// every row of its input (all of `V`) on each call, which would make a sweep quadratic
    /// in the number of cores. Full rows cost only the table's entries, and the stage kernel
    /// sums them in the same order (same bits).
    fn fused<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        kind: Reduce,
    ) -> Option<Last> {
        match kind {
            _ if self.map.is_some() || self.tables.len() == 1 => None,
            Reduce::Max if op.rewards.is_some() => Some(Last::Max { abs: false }),
            Reduce::Argmax if op.rewards.is_some() => Some(Last::Argmax),
            Reduce::AbsMax => Some(Last::Max { abs: true }),
            _ => None,
        }
    }

    /// Stores what a run delivered for the cores `base + first ..` into `out` (indices offset
    /// by `shift`), reducing rows as `kind` says.
    #[allow(clippy::too_many_arguments)] // the reduction's context, spelled out
    fn deliver<U, M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        kind: Reduce,
        base: usize,
        shift: usize,
        first: usize,
        values: Out<'_, T>,
        out: &mut [U],
        work: &mut super::ReduceWork<T>,
        pick: &impl Fn((T, u32)) -> U,
    ) {
        let at = first - shift;
        match values {
            Out::Row(ev) => {
                let core = base + first;
                let terminal = self.terminal_actions(core);
                let r = if terminal.is_empty() {
                    op.reduce(core, ev, kind, work)
                } else {
                    // Transitions into terminal states have no future value.
                    let mut row = core::mem::take(&mut work.ev);
                    row.clear();
                    row.extend_from_slice(ev);
                    for &u in terminal {
                        row[self.product_index(u as usize)] = T::ZERO;
                    }
                    let r = op.reduce(core, &row, kind, work);
                    work.ev = row;
                    r
                };
                out[at] = pick(r);
            }
            Out::Max(m) if kind != Reduce::AbsMax => {
                op.finish_run(base + first, (m, &[]), &mut out[at..], pick);
            }
            Out::Max(m) => {
                for (i, &x) in m.iter().enumerate() {
                    out[at + i] = pick((op.finish_abs(base + first + i, x), 0));
                }
            }
            Out::Arg(m, a) => op.finish_run(base + first, (m, a), &mut out[at..], pick),
        }
    }

    /// Reduces every core against `v` (internal order) into `out`, keeping `pick` of each
    /// `(value, action)` result: `V` for [`Reduce::Max`], actions for [`Reduce::Argmax`].
    pub(super) fn each_core<U: Send, M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        out: &mut [U],
        kind: Reduce,
        pick: impl Fn((T, u32)) -> U + Sync + Send,
    ) {
        let slab = self.slab_len();
        par::for_each_chunk_mut(
            out,
            slab,
            || self.work(op),
            |w, c0, chunk| {
                let rows0 = self.tables[0].rows.view();
                self.slab_into(op, rows0, v, kind, None, c0, w, chunk, &pick);
            },
        );
    }

    /// [`Self::each_core`], or with `policy` one policy-evaluation sweep
    /// `out[i] = rho_i + gamma (P_{policy[i]} v)_i` (`policy` holds joint actions, which equal
    /// product actions where [`Self::can_evaluate`] holds: the early stages run as in a full
    /// backup, the one before the last two action by action along whole rows, and the last two
    /// compute one row per core); either way also the range of `value(out[i]) - v[i]` over
    /// every core ([`super::sweeps::diff_range_by`]), taken slab by slab while the slab's
    /// results are still in cache: the pass over both buffers that the iteration drivers'
    /// change statistics would otherwise need.
    #[allow(clippy::too_many_arguments)] // each_core's arguments, and the value to compare
    pub(super) fn each_core_range<U: Send, M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        policy: Option<&[u32]>,
        out: &mut [U],
        kind: Reduce,
        pick: impl Fn((T, u32)) -> U + Sync + Send,
        value: impl Fn(&U) -> T + Sync + Send,
    ) -> (f64, f64) {
        debug_assert!(policy.is_none() || self.can_evaluate(op));
        let slab = self.slab_len();
        par::map_reduce_chunks_mut(
            out,
            slab,
            || self.work(op),
            |w, c0, chunk| {
                let first = c0 * slab;
                let pol = policy.map(|p| &p[first..first + chunk.len()]);
                let rows0 = self.tables[0].rows.view();
                self.slab_into(op, rows0, v, kind, pol, c0, w, chunk, &pick);
                super::sweeps::diff_range_by(chunk, &v[first..first + chunk.len()], &value)
            },
            (f64::INFINITY, f64::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        )
    }

    /// A full backup of `v` into `values` with every core's greedy joint action in `actions`,
    /// and the range of `values - v`: [`Self::each_core_range`] with [`Reduce::Argmax`],
    /// each slab's (value, action) pairs kept in a slab-sized scratch and split into the two
    /// outputs while still in cache, instead of a buffer of pairs over every core.
    pub(super) fn each_core_greedy<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        values: &mut [T],
        actions: &mut [u32],
    ) -> (f64, f64) {
        let slab = self.slab_len();
        par::map_reduce_chunks_mut2(
            (values, actions),
            slab,
            || (self.work(op), Vec::new()),
            |(w, pairs), c0, vs, us| {
                pairs.clear();
                pairs.resize(vs.len(), (T::ZERO, 0));
                let rows0 = self.tables[0].rows.view();
                self.slab_into(op, rows0, v, Reduce::Argmax, None, c0, w, pairs, &|r| r);
                super::split_pairs(pairs, vs, us);
                let first = c0 * slab;
                super::sweeps::diff_range_by(vs, &v[first..first + vs.len()], &|&x: &T| x)
            },
            (f64::INFINITY, f64::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        )
    }

    /// Reduces every core of slab `c0` against `v` into `chunk` (one entry per slab core).
    /// With `policy` (the slab's actions), evaluates them instead ([`Last::Eval`]).
    #[allow(clippy::too_many_arguments)] // the reduction's context, spelled out
    fn slab_into<U, M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        rows0: Rows<'_, T>,
        v: &[T],
        kind: Reduce,
        policy: Option<&[u32]>,
        c0: usize,
        w: &mut Work<T>,
        chunk: &mut [U],
        pick: &impl Fn((T, u32)) -> U,
    ) {
        let last = match policy {
            Some(_) => Last::Eval,
            None => self.last_for(self.fused(op, kind), c0),
        };
        let base = c0 * self.slab_len();
        let Work {
            stages,
            extra,
            reduce,
        } = w;
        self.run(
            rows0,
            0,
            c0,
            v,
            stages,
            extra,
            0,
            last,
            policy.unwrap_or(&[]),
            &mut |first, values| {
                self.deliver(op, kind, base, 0, first, values, chunk, reduce, pick);
            },
        );
    }

    /// Number of slabs: the cores of the first contracted block. Slab `c0` is the internal
    /// range `c0 * slab_len() .. (c0 + 1) * slab_len()` of `V`.
    pub(super) fn n_slabs(&self) -> usize {
        self.tables[0].n_cores
    }

    /// The input slabs that the backup of the output slabs `slabs` reads: the columns of the
    /// first block's rows for those cores (every action), sorted, each once. Only the first
    /// stage reads `V`; the later ones read its output.
    pub(super) fn input_slabs(&self, slabs: core::ops::Range<usize>) -> Vec<u32> {
        let t = &self.tables[0];
        let rows = t.rows.view();
        let mut halo: Vec<u32> = (slabs.start * t.n_actions..slabs.end * t.n_actions)
            .flat_map(|r| rows.row(r).0.iter().copied())
            .collect();
        halo.sort_unstable();
        halo.dedup();
        halo
    }

    /// The first block's rows for the output slabs `slabs`, their columns renumbered to their
    /// positions in `halo` (strictly increasing slab indices); every other row empty, since
    /// only the range's rows run. `None` if a column is not in `halo`.
    pub(super) fn halo_rows(
        &self,
        slabs: &core::ops::Range<usize>,
        halo: &[u32],
    ) -> Option<RowsBuf<T>> {
        let t = &self.tables[0];
        let rows = t.rows.view();
        let range = slabs.start * t.n_actions..slabs.end * t.n_actions;
        let (mut ptr, mut col, mut weight) = (vec![0u32; range.start + 1], Vec::new(), Vec::new());
        for r in range {
            let (c, w) = rows.row(r);
            for &k in c {
                col.push(halo.binary_search(&k).ok()? as u32);
            }
            weight.extend_from_slice(w);
            ptr.push(col.len() as u32);
        }
        ptr.resize(rows.n_rows() + 1, col.len() as u32);
        RowsBuf::new(ptr, col, weight, halo.len())
    }

    /// [`Self::each_core`] for the output slabs `slabs` alone, reading `v_halo`: the input
    /// slabs of the halo that `rows0` ([`Self::halo_rows`]) was renumbered into, one after
    /// another. `out` holds the range's cores; with `policy` (their actions), evaluates them
    /// instead. Every core gets the bits of the full sweep: the first stage's rows are the
    /// same rows over renumbered columns, so each sum reads the same values in the same order.
    #[allow(clippy::too_many_arguments)] // the reduction's context, spelled out
    pub(super) fn each_core_in<U: Send, M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        slabs: core::ops::Range<usize>,
        rows0: &RowsBuf<T>,
        v_halo: &[T],
        policy: Option<&[u32]>,
        out: &mut [U],
        kind: Reduce,
        pick: impl Fn((T, u32)) -> U + Sync + Send,
    ) {
        let slab = self.slab_len();
        par::for_each_chunk_mut(
            out,
            slab,
            || self.work(op),
            |w, i, chunk| {
                let pol = policy.map(|p| &p[i * slab..i * slab + chunk.len()]);
                let c0 = slabs.start + i;
                self.slab_into(op, rows0.view(), v_halo, kind, pol, c0, w, chunk, &pick);
            },
        );
    }

    /// Whether [`Self::evaluate`] can run for `op`: the last stage fuses (several blocks, the
    /// identity action map, a state-only reward) and no slab has terminal pairs.
    pub(super) fn can_evaluate<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
    ) -> bool {
        self.fused(op, Reduce::Max).is_some() && self.terminals.is_none()
    }

    pub(super) fn sweep_async<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &mut [T],
    ) -> f64 {
        let slab = self.slab_len();
        let n0 = self.tables[0].n_cores;
        let fused = self.fused(op, Reduce::Max);
        let mut w = self.work(op);
        let mut reduce = op.reduce_work();
        let mut dv = 0.0f64;
        let mut fresh = vec![T::ZERO; slab];
        let keep = |r: (T, u32)| r.0;
        for c0 in 0..n0 {
            let last = self.last_for(fused, c0);
            if self.tables.len() == 1 {
                // One block: the slab is one core; plain Gauss-Seidel.
                self.slab(c0, v, &mut w, last, &mut |first, values| {
                    self.deliver(
                        op,
                        Reduce::Max,
                        c0 * slab,
                        0,
                        first,
                        values,
                        &mut fresh,
                        &mut reduce,
                        &keep,
                    );
                });
            } else {
                // Stage 0 reads V as earlier slabs left it; the later stages only read its
                // output, so they run in parallel over the second block's cores.
                let (w0, _) = w.stages.split_first_mut().expect("one buffer per stage");
                let rows0 = self.tables[0].rows.view();
                let dense = self.tables[0].n_actions * self.p_len[0];
                self.stage(rows0, 0, c0, v, (w0, dense), &mut w.extra.scratch);
                let w0 = &w.stages[0];
                let chunk_len = self.r_len[1];
                par::for_each_chunk_mut(
                    &mut fresh,
                    chunk_len,
                    || self.work(op),
                    |t, c1, chunk| {
                        let Work {
                            stages,
                            extra,
                            reduce,
                        } = t;
                        let shift = c1 * chunk_len;
                        self.run(
                            rows0,
                            1,
                            c1,
                            w0,
                            &mut stages[1..],
                            extra,
                            c1,
                            last,
                            &[],
                            &mut |first, values| {
                                self.deliver(
                                    op,
                                    Reduce::Max,
                                    c0 * slab,
                                    shift,
                                    first,
                                    values,
                                    chunk,
                                    reduce,
                                    &keep,
                                );
                            },
                        );
                    },
                );
            }
            for (o, &x) in v[c0 * slab..(c0 + 1) * slab].iter_mut().zip(&fresh) {
                dv = dv.max((x.to_f64() - o.to_f64()).abs());
                *o = x;
            }
        }
        dv
    }

    pub(super) fn abs_max<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        dv: &[T],
    ) -> T {
        // One slab's values at a time, per task; the maximum is exact in any order.
        let slab = self.slab_len();
        let maxima = par::map_indexed(
            self.tables[0].n_cores,
            1,
            || (self.work(op), vec![T::ZERO; slab]),
            |(w, buf), c0| {
                let rows0 = self.tables[0].rows.view();
                self.slab_into(
                    op,
                    rows0,
                    dv,
                    Reduce::AbsMax,
                    None,
                    c0,
                    w,
                    buf,
                    &|r: (T, u32)| r.0,
                );
                buf.iter().copied().fold(T::ZERO, T::max_of)
            },
        );
        maxima.into_iter().fold(T::ZERO, T::max_of)
    }
}

#[path = "block_decide.rs"]
pub(super) mod decide;
#[path = "block_order.rs"]
mod order;
#[path = "block_plan.rs"]
mod plan;
#[path = "block_tables.rs"]
mod tables;
use decide::QWork;
use tables::{action_tuples, check_blocks, given_rows, stepped_table, sub_partition};

#[cfg(test)]
#[path = "block_tests.rs"]
mod tests;
