//! The generic backup path: step the model for every core and joint action, interpolate `V`
//! over the successor's active cores. Internal order is the grid's row-major order.

use std::sync::atomic::{AtomicBool, Ordering};
use std::vec::Vec;

use super::{GENERIC_SLAB, Operator, Reduce, ReduceWork, SolveError, par};
use crate::backup::expected_values;
use crate::model::Model;
use crate::real::Real;

pub(super) struct GenericOperator;

/// Per-task buffers.
struct Work<T> {
    x: Vec<T>,
    scratch: Vec<T>,
    ev: Vec<T>,
    reduce: ReduceWork<T>,
}

impl GenericOperator {
    fn work<T: Real, M: Model<T> + Sync + ?Sized>(op: &Operator<'_, T, M>) -> Work<T> {
        let e = op.state_dim();
        Work {
            x: vec![T::ZERO; e],
            scratch: vec![T::ZERO; e + op.joint.dim()],
            ev: vec![T::ZERO; op.joint.n_joint()],
            reduce: op.reduce_work(),
        }
    }

    /// Reduces core `i` against `v`; flags a non-finite successor.
    fn core<T: Real, M: Model<T> + Sync + ?Sized>(
        op: &Operator<'_, T, M>,
        v: &[T],
        i: usize,
        kind: Reduce,
        w: &mut Work<T>,
        failed: &AtomicBool,
    ) -> (T, u32) {
        if !op.is_goal(i) {
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
    pub(super) fn each_core<T: Real, U: Send, M: Model<T> + Sync + ?Sized>(
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
                    *o = pick(Self::core(op, v, s * GENERIC_SLAB + j, kind, w, &failed));
                }
            },
        );
        Self::check(&failed)
    }

    pub(super) fn sweep_async<T: Real, M: Model<T> + Sync + ?Sized>(
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
                |w, j| Self::core(op, read, start + j, Reduce::Max, w, &failed).0,
            );
            for (o, x) in v[start..start + len].iter_mut().zip(new) {
                dv = dv.max((x.to_f64() - o.to_f64()).abs());
                *o = x;
            }
            start += len;
        }
        Self::check(&failed).map(|()| dv)
    }

    pub(super) fn abs_max<T: Real, M: Model<T> + Sync + ?Sized>(
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
                    m = m.max_of(Self::core(op, dv, i, Reduce::AbsMax, w, &failed).0);
                }
                m
            },
        );
        Self::check(&failed)?;
        Ok(maxima.into_iter().fold(T::ZERO, T::max_of))
    }
}
