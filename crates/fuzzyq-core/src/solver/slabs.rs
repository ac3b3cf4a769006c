//! Slabs: the block backup of a range of output slabs from only the input slabs it reads,
//! the entry points for holding `V` in shards (processes, machines) instead of one buffer.
//!
//! On the block path `V` is kept in an internal order in which the first contracted block is
//! the slowest index: slab `c0` is the contiguous range `c0 * slab_len .. (c0 + 1) * slab_len`
//! of that order, one core of the first block times every core of the others. Only the first
//! stage of a backup reads `V`, and it reads, for slab `c0`, the slabs that the first block's
//! successors of core `c0` reach in one step (every action): a few neighbours. So a shard
//! of output slabs needs only a bounded halo of input slabs ([`Operator::input_slabs`]), and
//! its backup ([`Operator::apply_slabs`], [`Operator::greedy_slabs`],
//! [`Operator::evaluate_slabs`]) gives every core the bits of the full sweep.
//!
//! Everything else a sweep does (the change, extrapolation, the stopping rules) reduces
//! maxima and minima over cores, so a driver combining shards in any grouping gets the
//! single-process results.

use core::ops::Range;
use std::vec::Vec;

use super::simd::RowsBuf;
use super::{Operator, Path, Reduce, SolveError};
use crate::error::check_len;
use crate::model::Model;
use crate::real::Real;

/// How the block path lays out `V` in slabs (internal order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlabLayout {
    /// Number of slabs (the first contracted block's cores).
    pub n_slabs: usize,
    /// Cores per slab (the product of the other blocks' core counts).
    pub slab_len: usize,
}

impl<T: Real, M: Model<T> + Sync + ?Sized> Operator<'_, T, M> {
    /// The slab layout of `V`, or `None` on the generic path (which has no slabs).
    #[must_use]
    pub fn slab_layout(&self) -> Option<SlabLayout> {
        match &self.path {
            Path::Block(b) => Some(SlabLayout {
                n_slabs: b.n_slabs(),
                slab_len: b.slab_len(),
            }),
            Path::Generic(_) => None,
        }
    }

    /// The input slabs that the backup of the output slabs `slabs` reads (sorted, each once):
    /// the halo to fetch before [`Self::apply_slabs`]. It does not depend on `V` or on a
    /// policy.
    pub fn input_slabs(&self, slabs: Range<usize>) -> Result<Vec<u32>, SolveError> {
        let (b, _) = self.slab_range(&slabs)?;
        Ok(b.input_slabs(slabs))
    }

    /// The backup `max_u (rho + gamma P v)` of the cores of output slabs `slabs` (internal
    /// order, `out` holding `slabs.len() * slab_len` values), from `v_halo`: the input slabs
    /// `halo` of `V` (internal order) one after another. `halo` must be strictly increasing
    /// and contain [`Self::input_slabs`]; more slabs are allowed. Bit for bit the matching
    /// part of a full sweep ([`Self::apply`] in internal order), for any thread count.
    pub fn apply_slabs(
        &self,
        slabs: Range<usize>,
        halo: &[u32],
        v_halo: &[T],
        out: &mut [T],
    ) -> Result<(), SolveError> {
        let (b, rows0) = self.slab_check(&slabs, halo, v_halo, out.len())?;
        b.each_core_in(self, slabs, &rows0, v_halo, None, out, Reduce::Max, |r| r.0);
        Ok(())
    }

    /// The greedy joint actions of the cores of output slabs `slabs` (internal order; the
    /// lowest-index maximiser, as [`Self::greedy`]), from the halo as in
    /// [`Self::apply_slabs`].
    pub fn greedy_slabs(
        &self,
        slabs: Range<usize>,
        halo: &[u32],
        v_halo: &[T],
        out: &mut [u32],
    ) -> Result<(), SolveError> {
        let (b, rows0) = self.slab_check(&slabs, halo, v_halo, out.len())?;
        b.each_core_in(
            self,
            slabs,
            &rows0,
            v_halo,
            None,
            out,
            Reduce::Argmax,
            |r| r.1,
        );
        Ok(())
    }

    /// [`Self::apply_slabs`] and [`Self::greedy_slabs`] in one pass: each core's backed-up
    /// value into `out` and its greedy joint action into `actions` (the full backup of
    /// modified policy iteration).
    pub fn backup_greedy_slabs(
        &self,
        slabs: Range<usize>,
        halo: &[u32],
        v_halo: &[T],
        out: &mut [T],
        actions: &mut [u32],
    ) -> Result<(), SolveError> {
        let (b, rows0) = self.slab_check(&slabs, halo, v_halo, out.len())?;
        check_len("actions", out.len(), actions.len())?;
        let mut pairs = std::vec![(T::ZERO, 0u32); out.len()];
        b.each_core_in(
            self,
            slabs,
            &rows0,
            v_halo,
            None,
            &mut pairs,
            Reduce::Argmax,
            |r| r,
        );
        for ((o, a), &(x, u)) in out.iter_mut().zip(actions.iter_mut()).zip(&pairs) {
            *o = x;
            *a = u;
        }
        Ok(())
    }

    /// The backup of `V = 0` on the cores of output slabs `slabs`, `max_u rho` for a
    /// state-only reward (every action ties), without a pass over the blocks: the first full
    /// backup of modified policy iteration. [`SolveError::PolicyEvaluation`] where the
    /// operator cannot run that scheme.
    pub fn reward_slabs(&self, slabs: Range<usize>, out: &mut [T]) -> Result<(), SolveError> {
        let (_, slab) = self.slab_range(&slabs)?;
        check_len("output", slabs.len() * slab, out.len())?;
        if !self.can_evaluate() {
            return Err(SolveError::PolicyEvaluation);
        }
        let base = slabs.start * slab;
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.finish_max(base + i, T::ZERO);
        }
        Ok(())
    }

    /// `gamma max_{d non-goal, u} |(P dv)[d, u]|` over the cores `d` of output slabs `slabs`,
    /// from the halo of `dv` as in [`Self::apply_slabs`]: the maximum of these over a
    /// partition of the slabs is the exact change of theta the stopping rule tests.
    pub fn abs_max_slabs(
        &self,
        slabs: Range<usize>,
        halo: &[u32],
        dv_halo: &[T],
    ) -> Result<T, SolveError> {
        let (_, slab) = self.slab_range(&slabs)?;
        let mut out = std::vec![T::ZERO; slabs.len() * slab];
        let (b, rows0) = self.slab_check(&slabs, halo, dv_halo, out.len())?;
        b.each_core_in(
            self,
            slabs,
            &rows0,
            dv_halo,
            None,
            &mut out,
            Reduce::AbsMax,
            |r| r.0,
        );
        Ok(out.into_iter().fold(T::ZERO, T::max_of))
    }

    /// One policy-evaluation sweep of the cores of output slabs `slabs` under `policy` (their
    /// joint actions, internal order): [`Self::evaluate_policy`] on a shard, from the halo as
    /// in [`Self::apply_slabs`]. [`SolveError::PolicyEvaluation`] where the operator cannot
    /// evaluate a policy.
    pub fn evaluate_slabs(
        &self,
        slabs: Range<usize>,
        halo: &[u32],
        v_halo: &[T],
        policy: &[u32],
        out: &mut [T],
    ) -> Result<(), SolveError> {
        let (b, rows0) = self.slab_check(&slabs, halo, v_halo, out.len())?;
        check_len("policy", out.len(), policy.len())?;
        self.check_policy(policy)?;
        b.each_core_in(
            self,
            slabs,
            &rows0,
            v_halo,
            Some(policy),
            out,
            Reduce::Max,
            |r| r.0,
        );
        Ok(())
    }

    /// `v` (one value per core, row-major grid order) in the internal order of the slabs.
    pub fn to_internal_order<U: bytemuck::Pod + Default + Send + Sync>(
        &self,
        v: &[U],
    ) -> Result<Vec<U>, SolveError> {
        check_len("values", self.n_cores(), v.len())?;
        Ok(self.to_internal(v))
    }

    /// `v` (one value per core, internal order) in row-major grid order.
    pub fn to_grid_order<U: bytemuck::Pod + Default + Send + Sync>(
        &self,
        v: &[U],
    ) -> Result<Vec<U>, SolveError> {
        check_len("values", self.n_cores(), v.len())?;
        Ok(self.to_grid(v))
    }

    /// The block operator and slab length, if `slabs` is a non-empty range of slabs.
    fn slab_range(
        &self,
        slabs: &Range<usize>,
    ) -> Result<(&super::block::BlockOperator<T>, usize), SolveError> {
        let Path::Block(b) = &self.path else {
            return Err(SolveError::Slabs {
                reason: "the generic backup path has no slabs",
            });
        };
        if slabs.start >= slabs.end || slabs.end > b.n_slabs() {
            return Err(SolveError::Slabs {
                reason: "the slab range is empty or ends past the last slab",
            });
        }
        Ok((b, b.slab_len()))
    }

    /// [`Self::slab_range`] plus the halo and the buffer lengths; the block operator and the
    /// range's first-block rows renumbered into the halo.
    fn slab_check(
        &self,
        slabs: &Range<usize>,
        halo: &[u32],
        v_halo: &[T],
        out_len: usize,
    ) -> Result<(&super::block::BlockOperator<T>, RowsBuf<T>), SolveError> {
        let (b, slab) = self.slab_range(slabs)?;
        if halo.windows(2).any(|w| w[0] >= w[1]) || halo.iter().any(|&c| c as usize >= b.n_slabs())
        {
            return Err(SolveError::Slabs {
                reason: "the halo's slabs are not strictly increasing slab indices",
            });
        }
        let rows0 = b.halo_rows(slabs, halo).ok_or(SolveError::Slabs {
            reason: "the halo lacks an input slab of the range (see input_slabs)",
        })?;
        check_len("V halo", halo.len() * slab, v_halo.len())?;
        check_len("output", slabs.len() * slab, out_len)?;
        Ok((b, rows0))
    }
}
