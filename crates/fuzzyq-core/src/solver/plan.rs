//! The block path laid bare for a backend that computes its passes itself
//! ([`BlockPlan`], [`Operator::block_plan`], [`Operator::reward_rows`]).

use std::vec::Vec;

use super::{Operator, Path, STATE_CHUNK, par};
use crate::model::Model;
use crate::real::Real;

/// The block path's operator laid bare for a backend that computes its passes itself (a GPU,
/// say): every table in contraction order and what the reduction needs
/// ([`Operator::block_plan`]). A backend that sums each row's entries in order with fused
/// multiply-adds from 0, stage after stage, and reduces as described here gets the CPU
/// kernels' bits.
///
/// Stage `b` maps a tensor `[k_b][r][p]` (`r < r_len`, `p < p_len`) to `[r][a_b][p]`:
/// `out[(r A + a) P + p] = sum_e w_e in[(k_e R + r) P + p]` over the row `c_b A + a` of table
/// `b`, for each block core `c_b`; stage 0 reads `V` (internal order) and stage `b + 1` reads
/// stage `b`'s output of the same prefix `(c_0, ..., c_b)`. The last stage leaves one
/// expected value per core `(c_0, ..., c_{B-1})` (internal order, `c_0` slowest) and product
/// action `p`.
#[derive(Clone, Debug)]
pub struct BlockPlan<'o, T> {
    /// The tables in contraction order.
    pub tables: Vec<PlanTable<'o, T>>,
    /// Joint action -> product action, `None` where they coincide.
    pub joint_to_product: Option<&'o [u32]>,
    /// Number of joint actions.
    pub n_joint: usize,
    /// The discount factor, in the run's precision.
    pub gamma: T,
    /// `rho(x_d)` per core (internal order), when the reward does not depend on the action:
    /// `V[d] = rho_d + gamma max_u ev[d, u]` (unfused), the greedy action the lowest
    /// maximiser of `ev`.
    pub rewards: Option<&'o [T]>,
    /// `rho(x_d, u)` per core (internal order) and joint action, for a reward that depends on
    /// the action: `theta = rho + gamma ev` (unfused), the lowest `u` with the largest.
    pub reward_table: Option<&'o [T]>,
    /// Absorbing goal flags per core (internal order; empty without an absorbing goal): a
    /// goal core's value is its reward (of action 0) and its greedy action 0.
    pub goal: &'o [bool],
    /// Whether the model has terminal (core, joint action) pairs (their rows are zeroed
    /// before the reduction; a backend may refuse such models).
    pub terminals: bool,
    /// Whether the operator runs policy-evaluation sweeps ([`Operator::evaluate_policy`]).
    pub can_evaluate: bool,
}

/// One block's table of a [`BlockPlan`]: row `c A + a` (block core `c`, block action `a`)
/// holds the memberships of the block's successor, entries `ptr[row]..ptr[row + 1]` of
/// `col` and `weight`, in the order the kernels sum them.
#[derive(Clone, Copy, Debug)]
pub struct PlanTable<'o, T> {
    /// Block cores.
    pub n_cores: usize,
    /// Block actions.
    pub n_actions: usize,
    /// The product of the later blocks' core counts (the stage's `R`).
    pub r_len: usize,
    /// The product of the earlier blocks' action counts (the stage's `P`).
    pub p_len: usize,
    /// Row starts, `n_cores * n_actions + 1` of them.
    pub ptr: &'o [u32],
    /// Columns (block cores of the successor).
    pub col: &'o [u32],
    /// Weights (memberships), finite and non-negative.
    pub weight: &'o [T],
}

impl<T: Copy> PlanTable<'_, T> {
    /// Most actions of a block [`PlanTable::merged_steps`] merges.
    pub const MERGED_ACTIONS: usize = 32;

    /// Block core `c`'s rows (one per block action) merged by column, as the CPU's merged
    /// stage reads them: each step reads the smallest column among the rows' next entries,
    /// and every row whose next entry reads it takes the step, so each row's entries still
    /// come in its own order (a backend that keeps one sum per action and adds each step's
    /// products to the sums of the rows taking it gets each row's sum in the same order).
    /// Calls `take(step, column, action, weight)` for each action taking each step, in
    /// order, and returns the number of steps; `None` (nothing taken) where the block has more
    /// than [`PlanTable::MERGED_ACTIONS`] actions.
    pub fn merged_steps(&self, c: usize, take: impl FnMut(usize, u32, usize, T)) -> Option<usize> {
        const N: usize = PlanTable::<'static, f32>::MERGED_ACTIONS;
        let na = self.n_actions;
        if na > N {
            return None;
        }
        let rows: [(&[u32], &[T]); N] = core::array::from_fn(|a| {
            if a < na {
                let row = c * na + a;
                let (s, e) = (self.ptr[row] as usize, self.ptr[row + 1] as usize);
                (&self.col[s..e], &self.weight[s..e])
            } else {
                (&[][..], &[][..])
            }
        });
        super::simd::merge_rows::<T, N>(&rows[..na], usize::MAX, take)
    }
}

impl<T: Real, M: Model<T> + Sync + ?Sized> Operator<'_, T, M> {
    /// `rho(x_d, u)` of every core (internal order) and joint action, a row of joint actions
    /// per core: the table a backend that reduces on its own needs for a reward of the action
    /// that the model computes ([`BlockPlan::reward_table`] is `None` then). The same values
    /// the CPU's reduction computes, from the same core states.
    #[must_use]
    pub fn reward_rows(&self) -> Vec<T> {
        if let Some(t) = &self.reward_table {
            return t.to_vec();
        }
        let (n, m) = (self.n_cores(), self.joint.n_joint());
        let (e, a) = (self.state_dim(), self.joint.dim());
        let coords = self.block_coords();
        let mut out = vec![T::ZERO; n * m];
        par::for_each_chunk_mut(
            &mut out,
            STATE_CHUNK * m,
            || (vec![T::ZERO; e], vec![T::ZERO; a]),
            |(x, u), ci, chunk| {
                let first = ci * STATE_CHUNK;
                let range = first..first + chunk.len() / m;
                self.for_each_core_state(&coords, range, x, |i, x| {
                    for j in 0..m {
                        self.joint.vector_unchecked(j, u);
                        chunk[(i - first) * m + j] = self.model.reward(x, u);
                    }
                });
            },
        );
        out
    }

    /// The block path's tables and reduction ([`BlockPlan`]); `None` on the generic path.
    #[must_use]
    pub fn block_plan(&self) -> Option<BlockPlan<'_, T>> {
        let Path::Block(b) = &self.path else {
            return None;
        };
        Some(BlockPlan {
            tables: b.plan_tables(),
            joint_to_product: b.joint_to_product(),
            n_joint: self.joint.n_joint(),
            gamma: self.gamma,
            rewards: self.rewards.as_deref(),
            reward_table: self.reward_table.as_deref(),
            goal: &self.goal,
            terminals: b.has_terminals(),
            can_evaluate: self.can_evaluate(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::PlanTable;
    use proptest::prelude::*;
    use std::vec::Vec;

    proptest! {
        /// Every action's row comes back from the merged steps entry by entry, in its own
        /// order, each step reading the smallest of the rows' next columns (rows unsorted,
        /// with repeated columns).
        #[test]
        fn merged_steps_give_every_row_in_order(
            rows in prop::collection::vec(
                prop::collection::vec((0u32..7, 0.0f32..1.0), 0..6), 1..6),
            cores in 1usize..3,
        ) {
            let na = rows.len();
            let (mut ptr, mut col, mut weight) = (vec![0u32], Vec::new(), Vec::new());
            for _ in 0..cores {
                for r in &rows {
                    col.extend(r.iter().map(|e| e.0));
                    weight.extend(r.iter().map(|e| e.1));
                    ptr.push(col.len() as u32);
                }
            }
            let t = PlanTable { n_cores: cores, n_actions: na, r_len: 1, p_len: 1,
                ptr: &ptr, col: &col, weight: &weight };
            for c in 0..cores {
                let mut got = vec![Vec::new(); na];
                let mut order = Vec::new();
                let steps = t
                    .merged_steps(c, |step, k, a, w| {
                        order.push((step, k));
                        got[a].push((step, k, w));
                    })
                    .unwrap();
                // Steps in order, every row taking a step reading its column.
                prop_assert!(order.windows(2).all(|w| w[0].0 < w[1].0 || w[0] == w[1]));
                for (a, r) in rows.iter().enumerate() {
                    let entries: Vec<(u32, f32)> = got[a].iter().map(|e| (e.1, e.2)).collect();
                    prop_assert_eq!(&entries, r);
                    // At most one entry of a row per step.
                    prop_assert!(got[a].windows(2).all(|w| w[0].0 < w[1].0));
                }
                prop_assert!(got.iter().flatten().all(|e| e.0 < steps));
            }
        }
    }

    #[test]
    fn blocks_of_more_actions_are_not_merged() {
        let n = PlanTable::<f32>::MERGED_ACTIONS + 1;
        let ptr = vec![0u32; n + 1];
        let t = PlanTable::<f32> {
            n_cores: 1,
            n_actions: n,
            r_len: 1,
            p_len: 1,
            ptr: &ptr,
            col: &[],
            weight: &[],
        };
        assert_eq!(
            t.merged_steps(0, |_, _, _, _| panic!("nothing taken")),
            None
        );
    }
}
