//! The generic backup path: step the model for every core and joint action, interpolate `V`
//! over the successor's active cores. Internal order is the grid's row-major order.
//!
//! For a [tabulated](crate::Model::tabulated) model the successors' active cores and weights
//! are computed once, at construction, and every sweep reads them. A
//! [terminal](crate::Model::is_terminal) successor gets no entries, so its expected value is 0.

use std::sync::atomic::{AtomicBool, Ordering};
use std::vec::Vec;

use super::{GENERIC_SLAB, Operator, Reduce, ReduceWork, SolveError, par};
use crate::backup::expected_values;
use crate::model::Model;
use crate::real::Real;

pub(super) struct GenericOperator<T> {
    /// Precomputed successors of a tabulated model: entries `ptr[d M + u] .. ptr[d M + u + 1]`.
    table: Option<Successors<T>>,
}

/// The successors' active cores and weights of every (core, joint action) pair.
struct Successors<T> {
    ptr: Vec<usize>,
    col: Vec<u32>,
    weight: Vec<T>,
}

/// Per-task buffers.
struct Work<T> {
    x: Vec<T>,
    scratch: Vec<T>,
    ev: Vec<T>,
    reduce: ReduceWork<T>,
}

impl<T: Real> GenericOperator<T> {
    /// The generic path; for a tabulated model, with its successors' memberships precomputed.
    pub(super) fn new<M: Model<T> + Sync + ?Sized>(
        model: &M,
        grid: &crate::partition::ProductPartition<'_, T>,
        n_joint: usize,
        table: Option<crate::model::Tabulated<'_, T>>,
    ) -> Self {
        let terminal = model.has_terminal_states();
        let table = table.map(|t| {
            let e = grid.n_dims();
            let per_core = par::map_indexed(
                grid.n_cores(),
                64,
                || (),
                |(), d| {
                    let mut lens = Vec::with_capacity(n_joint);
                    let mut entries = Vec::new();
                    for u in 0..n_joint {
                        let i = (d * n_joint + u) * e;
                        let before = entries.len();
                        let next = &t.next_states[i..i + e];
                        if !(terminal && model.is_terminal(next)) {
                            grid.active_unchecked(next).for_each(|k, w| {
                                if w != T::ZERO {
                                    entries.push((k as u32, w));
                                }
                            });
                        }
                        lens.push(entries.len() - before);
                    }
                    (lens, entries)
                },
            );
            let mut ptr = Vec::with_capacity(grid.n_cores() * n_joint + 1);
            let mut col = Vec::new();
            let mut weight = Vec::new();
            ptr.push(0);
            for (lens, entries) in per_core {
                for l in lens {
                    ptr.push(ptr.last().expect("non-empty") + l);
                }
                for (k, w) in entries {
                    col.push(k);
                    weight.push(w);
                }
            }
            Successors { ptr, col, weight }
        });
        Self { table }
    }

    fn work<M: Model<T> + Sync + ?Sized>(op: &Operator<'_, T, M>) -> Work<T> {
        let e = op.state_dim();
        Work {
            x: vec![T::ZERO; e],
            scratch: vec![T::ZERO; e + op.joint.dim()],
            ev: vec![T::ZERO; op.joint.n_joint()],
            reduce: op.reduce_work(),
        }
    }

    /// Reduces core `i` against `v`; flags a non-finite successor.
    fn core<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        i: usize,
        kind: Reduce,
        w: &mut Work<T>,
        failed: &AtomicBool,
    ) -> (T, u32) {
        if let Some(t) = &self.table {
            let m = w.ev.len();
            for (u, ev) in w.ev.iter_mut().enumerate() {
                let (s, e) = (t.ptr[i * m + u], t.ptr[i * m + u + 1]);
                let mut acc = T::ZERO;
                for (&k, &wt) in t.col[s..e].iter().zip(&t.weight[s..e]) {
                    acc += wt * v[k as usize];
                }
                *ev = acc;
            }
        } else if !op.is_goal(i) {
            op.core_state(i, &mut w.x);
            if expected_values(
                op.model,
                &op.grid,
                &op.joint,
                v,
                &w.x,
                &mut w.scratch,
                &mut w.ev,
            )
            .is_err()
            {
                failed.store(true, Ordering::Relaxed);
                w.ev.fill(T::ZERO);
            }
        }
        op.reduce(i, &w.ev, kind, &mut w.reduce)
    }

    fn check(failed: &AtomicBool) -> Result<(), SolveError> {
        if failed.load(Ordering::Relaxed) {
            Err(SolveError::NonFinite { what: "successor" })
        } else {
            Ok(())
        }
    }

    /// Reduces every core against `v` into `out`, keeping `pick` of each `(value, action)`.
    pub(super) fn each_core<U: Send, M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        out: &mut [U],
        kind: Reduce,
        pick: impl Fn((T, u32)) -> U + Sync + Send,
    ) -> Result<(), SolveError> {
        let failed = AtomicBool::new(false);
        par::for_each_chunk_mut(
            out,
            GENERIC_SLAB,
            || Self::work(op),
            |w, s, chunk| {
                for (j, o) in chunk.iter_mut().enumerate() {
                    *o = pick(self.core(op, v, s * GENERIC_SLAB + j, kind, w, &failed));
                }
            },
        );
        Self::check(&failed)
    }

    pub(super) fn sweep_async<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &mut [T],
    ) -> Result<f64, SolveError> {
        let failed = AtomicBool::new(false);
        let n = v.len();
        let mut dv = 0.0f64;
        let mut start = 0;
        while start < n {
            let len = GENERIC_SLAB.min(n - start);
            let read: &[T] = v;
            let new = par::map_indexed(
                len,
                16,
                || Self::work(op),
                |w, j| self.core(op, read, start + j, Reduce::Max, w, &failed).0,
            );
            for (o, x) in v[start..start + len].iter_mut().zip(new) {
                dv = dv.max((x.to_f64() - o.to_f64()).abs());
                *o = x;
            }
            start += len;
        }
        Self::check(&failed).map(|()| dv)
    }

    pub(super) fn abs_max<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        dv: &[T],
    ) -> Result<T, SolveError> {
        let failed = AtomicBool::new(false);
        let n = dv.len();
        let slabs = n.div_ceil(GENERIC_SLAB);
        let maxima = par::map_indexed(
            slabs,
            1,
            || Self::work(op),
            |w, s| {
                let mut m = T::ZERO;
                for i in s * GENERIC_SLAB..((s + 1) * GENERIC_SLAB).min(n) {
                    m = m.max_of(self.core(op, dv, i, Reduce::AbsMax, w, &failed).0);
                }
                m
            },
        );
        Self::check(&failed)?;
        Ok(maxima.into_iter().fold(T::ZERO, T::max_of))
    }
}

/// Refuses `n` cores for a solver whose tables index cores in 32 bits (the generic backup
/// path, Q-iteration); the block path indexes them in `usize`.
pub(super) fn check_u32_cores(n: usize, what: &'static str) -> Result<(), SolveError> {
    if u32::try_from(n).is_err() {
        return Err(SolveError::TooLarge { what });
    }
    Ok(())
}
