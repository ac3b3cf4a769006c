//! The block operator's tables as [`super::super::BlockPlan`] shows them.

use std::vec::Vec;

use super::BlockOperator;
use crate::real::Real;

impl<T: Real> BlockOperator<T> {
    /// The tables in contraction order, with the stage lengths, for [`super::BlockPlan`].
    pub(in crate::solver) fn plan_tables(&self) -> Vec<crate::solver::PlanTable<'_, T>> {
        self.tables
            .iter()
            .enumerate()
            .map(|(b, t)| {
                let (ptr, col, weight) = t.rows.parts();
                crate::solver::PlanTable {
                    n_cores: t.n_cores,
                    n_actions: t.n_actions,
                    r_len: self.r_len[b],
                    p_len: self.p_len[b],
                    ptr,
                    col,
                    weight,
                }
            })
            .collect()
    }

    /// Whether the model has terminal (core, joint action) pairs.
    pub(in crate::solver) fn has_terminals(&self) -> bool {
        self.terminals.is_some()
    }
}
