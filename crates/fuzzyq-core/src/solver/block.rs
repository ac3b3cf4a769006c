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
//! Cost per sweep on the paper grid (4 blocks of 45 cores and 5 actions, at most 4 successor
//! entries per row): about 1.25e10 multiply-adds, 82% of them in the last stage.

use std::vec::Vec;

use super::{Operator, Reduce, SolveError, par};
use crate::action::JointActions;
use crate::backup::{SparseRows, contract};
use crate::model::Model;
use crate::partition::{MAX_DIMS, Partition, ProductPartition};
use crate::real::Real;

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
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: Vec<T>,
}

impl<T: Real> BlockTable<T> {
    fn rows(&self) -> SparseRows<'_, T> {
        SparseRows {
            ptr: &self.ptr,
            col: &self.col,
            weight: &self.weight,
        }
    }

    fn row(&self, c: usize, a: usize) -> (&[u32], &[T]) {
        let i = c * self.n_actions + a;
        let (s, e) = (self.ptr[i] as usize, self.ptr[i + 1] as usize);
        (&self.col[s..e], &self.weight[s..e])
    }
}

pub(super) struct BlockOperator<T> {
    /// Tables in contraction order.
    tables: Vec<BlockTable<T>>,
    /// Per stage: product of the later blocks' core counts.
    r_len: Vec<usize>,
    /// Per stage: product of the earlier blocks' action counts.
    p_len: Vec<usize>,
    /// Product action count.
    product_len: usize,
    /// Joint index -> product index, `None` when they coincide.
    map: Option<Vec<u32>>,
}

/// Sub-partition over a block's state variables.
fn sub_partition<'a, T: Real>(
    grid: &ProductPartition<'a, T>,
    dims: &[usize],
) -> ProductPartition<'a, T> {
    let mut parts = [grid.dim(0); MAX_DIMS];
    for (p, &e) in parts.iter_mut().zip(dims) {
        *p = grid.dim(e);
    }
    let parts: &[Partition<'a, T>] = &parts[..dims.len()];
    ProductPartition::from_partitions(parts).expect("a block of a valid grid is a valid grid")
}

/// Compressed rows of `(block core, weight)` entries, with block cores renumbered by `local`.
fn local_rows<T: Real, R: Iterator<Item = (usize, T)>>(
    rows: impl Iterator<Item = R>,
    local: &[u32],
) -> (Vec<u32>, Vec<u32>, Vec<T>) {
    let mut ptr = vec![0u32];
    let mut col = Vec::new();
    let mut weight = Vec::new();
    for row in rows {
        for (k, w) in row {
            col.push(local[k]);
            weight.push(w);
        }
        ptr.push(col.len() as u32);
    }
    (ptr, col, weight)
}

/// The values of `dims` in `x`.
fn x_block<T: Real>(x: &[T], dims: &[usize]) -> Vec<T> {
    dims.iter().map(|&d| x[d]).collect()
}

impl<T: Real> BlockOperator<T> {
    pub(super) fn new<M: Model<T> + ?Sized>(
        model: &M,
        grid: &ProductPartition<'_, T>,
        joint: &JointActions<'_, T>,
    ) -> Result<Self, SolveError> {
        let e = grid.n_dims();
        let nb = model.n_blocks();
        let mut count = vec![0usize; e];
        for b in 0..nb {
            let block = model.block(b);
            if block.state_dims.is_empty() {
                return Err(SolveError::BlockDeclaration {
                    block: b,
                    reason: "it has no state variables",
                });
            }
            for &d in block.state_dims {
                if d >= e {
                    return Err(SolveError::BlockDeclaration {
                        block: b,
                        reason: "it names a state variable beyond the state's length",
                    });
                }
                count[d] += 1;
            }
            if block.action_components.iter().any(|&c| c >= joint.dim()) {
                return Err(SolveError::BlockDeclaration {
                    block: b,
                    reason: "it names an action component beyond the joint action's length",
                });
            }
        }
        if let Some(dim) = count.iter().position(|&c| c != 1) {
            return Err(SolveError::BlockCoverage {
                dim,
                count: count[dim],
            });
        }

        let m = joint.n_joint();
        let a_dim = joint.dim();
        let mut uvec = vec![T::ZERO; a_dim];
        let mut base_u = vec![T::ZERO; a_dim];
        joint.vector_unchecked(0, &mut base_u);
        let base_x: Vec<T> = grid.dims().iter().map(|p| p.first()).collect();
        // Check contexts: (core index of every variable, joint action), the third varying
        // with the row `r`.
        let context = |kind: usize, r: usize, x: &mut [T], u: &mut [T]| {
            for (e, (xe, p)) in x.iter_mut().zip(grid.dims()).enumerate() {
                let n = p.n_cores();
                let k = match kind {
                    0 => n - 1,
                    1 => n / 2,
                    _ => (r * 7 + e * 5 + 3) % n,
                };
                *xe = p.cores()[k];
            }
            let ju = match kind {
                0 => m - 1,
                1 => m / 2,
                _ => (r * 31 + 17) % m,
            };
            joint.vector_unchecked(ju, u);
        };
        let mut alt_x = base_x.clone();
        let mut alt_u = base_u.clone();

        let mut tables = Vec::with_capacity(nb);
        // Per joint action, each block's action index (in contraction order).
        let mut block_action = vec![vec![0u32; m]; nb];
        for (level, b) in (0..nb).rev().enumerate() {
            let block = model.block(b);
            let dims = block.state_dims.to_vec();
            let comps = block.action_components;
            let sub = sub_partition(grid, &dims);

            // Distinct action tuples in order of first appearance over joint indices.
            let mut tuples: Vec<Vec<T>> = Vec::new();
            for u in 0..m {
                joint.vector_unchecked(u, &mut uvec);
                let t: Vec<T> = comps.iter().map(|&c| uvec[c]).collect();
                let a = match tuples.iter().position(|x| *x == t) {
                    Some(a) => a,
                    None => {
                        tuples.push(t);
                        tuples.len() - 1
                    }
                };
                block_action[level][u] = a as u32;
            }

            let n_cores = sub.n_cores();
            let n_actions = tuples.len();
            let mut ptr = Vec::with_capacity(n_cores * n_actions + 1);
            let mut col = Vec::new();
            let mut weight = Vec::new();
            ptr.push(0u32);
            let mut x = base_x.clone();
            let mut next = vec![T::ZERO; e];
            let mut next_alt = vec![T::ZERO; e];
            let mut sub_x = vec![T::ZERO; dims.len()];
            let mut ua = base_u.clone();
            let mut grid_offset = Vec::with_capacity(n_cores);
            let mut idx = vec![0usize; dims.len()];
            for c in 0..n_cores {
                sub.core_state(c, &mut sub_x)?;
                sub.unravel(c, &mut idx)?;
                grid_offset.push(
                    dims.iter()
                        .zip(&idx)
                        .map(|(&d, &i)| i * grid.strides()[d])
                        .sum(),
                );
                for (&d, &v) in dims.iter().zip(&sub_x) {
                    x[d] = v;
                }
                for (a, t) in tuples.iter().enumerate() {
                    for (&comp, &v) in comps.iter().zip(t) {
                        ua[comp] = v;
                    }
                    model.step(&x, &ua, &mut next);
                    for (j, &d) in dims.iter().enumerate() {
                        if !next[d].is_finite() {
                            return Err(SolveError::NonFinite { what: "successor" });
                        }
                        sub_x[j] = next[d];
                    }
                    for kind in 0..3 {
                        context(kind, c * n_actions + a, &mut alt_x, &mut alt_u);
                        for (&d, &v) in dims.iter().zip(&x_block(&x, &dims)) {
                            alt_x[d] = v;
                        }
                        for (&comp, &v) in comps.iter().zip(t) {
                            alt_u[comp] = v;
                        }
                        model.step(&alt_x, &alt_u, &mut next_alt);
                        if dims.iter().any(|&d| next[d] != next_alt[d]) {
                            return Err(SolveError::BlockMismatch { block: b });
                        }
                    }
                    sub.active_unchecked(&sub_x).for_each(|k, w| {
                        if w != T::ZERO {
                            col.push(k as u32);
                            weight.push(w);
                        }
                    });
                    let len = u32::try_from(col.len()).map_err(|_| SolveError::TooLarge {
                        what: "block transition table",
                    })?;
                    ptr.push(len);
                }
            }
            tables.push(BlockTable {
                dims,
                n_cores,
                n_actions,
                grid_offset,
                ptr,
                col,
                weight,
            });
        }

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
        Ok(Self {
            tables,
            r_len,
            p_len,
            product_len,
            map: (!identity).then_some(map),
        })
    }

    pub(super) fn joint_to_product(&self) -> Option<&[u32]> {
        self.map.as_deref()
    }

    fn slab_len(&self) -> usize {
        self.r_len[0]
    }

    /// Internal index (contraction order, first block slowest) -> row-major grid index.
    pub(super) fn to_grid_index(&self, internal: usize) -> usize {
        let mut g = 0;
        for (b, t) in self.tables.iter().enumerate() {
            let c = (internal / self.r_len[b]) % t.n_cores;
            g += t.grid_offset[c];
        }
        g
    }

    /// Stage output buffers, one per stage.
    fn bufs(&self) -> Vec<Vec<T>> {
        self.tables
            .iter()
            .enumerate()
            .map(|(b, t)| vec![T::ZERO; self.r_len[b] * t.n_actions * self.p_len[b]])
            .collect()
    }

    /// Runs stage `level` for block core `c` on `input`, then the later stages for every core
    /// of the later blocks; `emit(local, ev)` receives each core's expected values, `local`
    /// being the core's index among those sharing the blocks before `level`.
    fn run<E: FnMut(usize, &[T])>(
        &self,
        level: usize,
        c: usize,
        input: &[T],
        bufs: &mut [Vec<T>],
        local: usize,
        emit: &mut E,
    ) {
        let t = &self.tables[level];
        let (out, deeper) = bufs.split_first_mut().expect("one buffer per stage");
        contract(
            t.rows(),
            c * t.n_actions,
            t.n_actions,
            t.n_cores,
            self.r_len[level],
            self.p_len[level],
            input,
            out,
        )
        .expect("block tables and buffers are sized at construction");
        if level + 1 == self.tables.len() {
            emit(local, out);
        } else {
            let n = self.tables[level + 1].n_cores;
            for c2 in 0..n {
                self.run(level + 1, c2, out, deeper, local * n + c2, emit);
            }
        }
    }

    /// Every core of slab `c0` against `v` (internal order), sequentially.
    fn slab<E: FnMut(usize, &[T])>(&self, c0: usize, v: &[T], bufs: &mut [Vec<T>], emit: &mut E) {
        self.run(0, c0, v, bufs, 0, emit);
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
            || (self.bufs(), op.reduce_work()),
            |(bufs, work), c0, chunk| {
                self.slab(c0, v, bufs, &mut |local, ev| {
                    chunk[local] = pick(op.reduce(c0 * slab + local, ev, kind, work));
                });
            },
        );
    }

    pub(super) fn sweep_async<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &mut [T],
    ) -> f64 {
        let slab = self.slab_len();
        let n0 = self.tables[0].n_cores;
        let mut bufs = self.bufs();
        let mut work = op.reduce_work();
        let mut dv = 0.0f64;
        let mut fresh = vec![T::ZERO; slab];
        for c0 in 0..n0 {
            if self.tables.len() == 1 {
                // One block: the slab is one core; plain Gauss-Seidel.
                let mut val = T::ZERO;
                self.slab(c0, v, &mut bufs, &mut |_, ev| {
                    val = op.reduce(c0, ev, Reduce::Max, &mut work).0;
                });
                fresh[0] = val;
            } else {
                // Stage 0 reads V as earlier slabs left it; the later stages only read its
                // output, so they run in parallel over the second block's cores.
                let t = &self.tables[0];
                contract(
                    t.rows(),
                    c0 * t.n_actions,
                    t.n_actions,
                    t.n_cores,
                    self.r_len[0],
                    1,
                    v,
                    &mut bufs[0],
                )
                .expect("block tables and buffers are sized at construction");
                let w0 = &bufs[0];
                let chunk_len = self.r_len[1];
                par::for_each_chunk_mut(
                    &mut fresh,
                    chunk_len,
                    || (self.bufs(), op.reduce_work()),
                    |(bufs, work), c1, chunk| {
                        self.run(1, c1, w0, &mut bufs[1..], c1, &mut |local, ev| {
                            let i = c0 * slab + local;
                            chunk[local - c1 * chunk_len] = op.reduce(i, ev, Reduce::Max, work).0;
                        });
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
        let slab = self.slab_len();
        let maxima = par::map_indexed(
            self.tables[0].n_cores,
            1,
            || (self.bufs(), op.reduce_work()),
            |(bufs, work), c0| {
                let mut m = T::ZERO;
                self.slab(c0, dv, bufs, &mut |local, ev| {
                    m = m.max_of(op.reduce(c0 * slab + local, ev, Reduce::AbsMax, work).0);
                });
                m
            },
        );
        maxima.into_iter().fold(T::ZERO, T::max_of)
    }

    /// `Q(x, .)` at any state from `v` in grid order (see [`Operator::q_values`]).
    ///
    /// The active cores of `x` are the products of each block's active block cores, and their
    /// memberships the products of the block memberships, so
    /// `sum_d mu_d(x) P[d, u] V = sum_k prod_b (sum_{c_b} mu_{c_b} T_b[c_b, a_b, k_b]) V[k]`:
    /// the same contraction with one mixed row per block and action, over the box of
    /// successor cores those rows reach.
    pub(super) fn q_values<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        x: &[T],
        out: &mut [T],
    ) -> Result<(), SolveError> {
        let grid = &op.grid;
        let active = grid.active(x)?;
        let nb = self.tables.len();

        // Per block: active block cores with memberships, the mixed rows and their support.
        struct Mixed<T> {
            support: Vec<usize>,
            /// Block core -> position in `support`.
            local: Vec<u32>,
            ptr: Vec<u32>,
            col: Vec<u32>,
            weight: Vec<T>,
        }
        let mut mixed: Vec<Mixed<T>> = Vec::with_capacity(nb);
        for t in &self.tables {
            let sub = sub_partition(grid, &t.dims);
            let xs: Vec<T> = t.dims.iter().map(|&d| x[d]).collect();
            let mut act = Vec::new();
            sub.active_unchecked(&xs).for_each(|c, w| act.push((c, w)));
            let mut dense = vec![T::ZERO; t.n_cores];
            let mut touched = vec![false; t.n_cores];
            let mut rows: Vec<Vec<(usize, T)>> = Vec::with_capacity(t.n_actions);
            for a in 0..t.n_actions {
                dense.fill(T::ZERO);
                let mut hit = Vec::new();
                for &(c, mu) in &act {
                    let (cols, ws) = t.row(c, a);
                    for (&k, &w) in cols.iter().zip(ws) {
                        if !hit.contains(&(k as usize)) {
                            hit.push(k as usize);
                        }
                        dense[k as usize] += mu * w;
                    }
                }
                hit.sort_unstable();
                for &k in &hit {
                    touched[k] = true;
                }
                rows.push(hit.iter().map(|&k| (k, dense[k])).collect());
            }
            let support: Vec<usize> = (0..t.n_cores).filter(|&k| touched[k]).collect();
            let mut local = vec![u32::MAX; t.n_cores];
            for (i, &k) in support.iter().enumerate() {
                local[k] = i as u32;
            }
            let (ptr, col, weight) = local_rows(rows.iter().map(|r| r.iter().copied()), &local);
            mixed.push(Mixed {
                support,
                local,
                ptr,
                col,
                weight,
            });
        }

        // The box of V over the supports, first block slowest.
        let box_len: usize = mixed.iter().map(|m| m.support.len()).product();
        let mut vbox = vec![T::ZERO; box_len];
        let mut idx = vec![0usize; nb];
        for slot in vbox.iter_mut() {
            let g: usize = (0..nb)
                .map(|b| self.tables[b].grid_offset[mixed[b].support[idx[b]]])
                .sum();
            *slot = v[g];
            for b in (0..nb).rev() {
                idx[b] += 1;
                if idx[b] < mixed[b].support.len() {
                    break;
                }
                idx[b] = 0;
            }
        }

        // Contract the box with the given rows (one row per block action for each block).
        let contract_box = |rows: &dyn Fn(usize) -> (Vec<u32>, Vec<u32>, Vec<T>)| -> Vec<T> {
            let mut input = vbox.clone();
            let mut p = 1usize;
            for b in 0..nb {
                let k = mixed[b].support.len();
                let r: usize = mixed[b + 1..].iter().map(|m| m.support.len()).product();
                let a = self.tables[b].n_actions;
                let (ptr, col, weight) = rows(b);
                let mut out = vec![T::ZERO; r * a * p];
                contract(
                    SparseRows {
                        ptr: &ptr,
                        col: &col,
                        weight: &weight,
                    },
                    0,
                    a,
                    k,
                    r,
                    p,
                    &input,
                    &mut out,
                )
                .expect("mixed rows are sized to the box");
                input = out;
                p *= a;
            }
            input
        };
        let ev_mixed = contract_box(&|b| {
            let m = &mixed[b];
            (m.ptr.clone(), m.col.clone(), m.weight.clone())
        });

        // Rewards of the active cores, and the goal cores' expectations to take back out.
        let e = op.state_dim();
        let mj = op.joint.n_joint();
        let mut xd = vec![T::ZERO; e];
        let mut uvec = vec![T::ZERO; op.joint.dim()];
        let mut reward_mix = vec![T::ZERO; mj];
        let mut goal_ev = vec![T::ZERO; self.product_len];
        let mut any_goal = false;
        let depends = op.model.reward_depends_on_action();
        let mut cores = Vec::new();
        active.for_each(|d, mu| cores.push((d, mu)));
        for &(d, mu) in &cores {
            grid.core_state(d, &mut xd)?;
            if depends {
                for (u, r) in reward_mix.iter_mut().enumerate() {
                    op.joint.vector_unchecked(u, &mut uvec);
                    *r += mu * op.model.reward(&xd, &uvec);
                }
            } else {
                op.joint.vector_unchecked(0, &mut uvec);
                let rd = op.model.reward(&xd, &uvec);
                for r in reward_mix.iter_mut() {
                    *r += mu * rd;
                }
            }
            if op.backup.absorbing_goal && op.model.is_goal(&xd) {
                any_goal = true;
                // This core's block cores, to contract its pure rows.
                let block_cores: Vec<usize> = self
                    .tables
                    .iter()
                    .map(|t| {
                        let sub = sub_partition(grid, &t.dims);
                        let xs: Vec<T> = t.dims.iter().map(|&dd| xd[dd]).collect();
                        let mut c = 0;
                        sub.active_unchecked(&xs).for_each(|k, _| c = k);
                        c
                    })
                    .collect();
                let ev_d = contract_box(&|b| {
                    let t = &self.tables[b];
                    let rows = (0..t.n_actions).map(|a| {
                        let (cols, ws) = t.row(block_cores[b], a);
                        cols.iter().map(|&k| k as usize).zip(ws.iter().copied())
                    });
                    local_rows(rows, &mixed[b].local)
                });
                for (g, &x) in goal_ev.iter_mut().zip(&ev_d) {
                    *g += mu * x;
                }
            }
        }
        let gamma = op.gamma;
        for (u, o) in out.iter_mut().enumerate() {
            let p = self.map.as_ref().map_or(u, |m| m[u] as usize);
            let ev = if any_goal {
                ev_mixed[p] - goal_ev[p]
            } else {
                ev_mixed[p]
            };
            *o = reward_mix[u] + gamma * ev;
        }
        Ok(())
    }
}
