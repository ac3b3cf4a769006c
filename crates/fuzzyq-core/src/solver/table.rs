//! Models known only at a grid's cores: [`TabulatedModel`].
//!
//! A model written in another language (a vectorised Python callable, say) is evaluated once at
//! every (core, joint action) pair of the grid to be solved; fuzzy Q-iteration needs nothing
//! else, because `theta[d, u] = rho(x_d, u) + gamma V~(f(x_d, u))` only involves the cores
//! `x_d`, and so do the greedy and interpolated policies. The solver reads the table directly
//! (successors' memberships are precomputed once); [`Model::step`] and [`Model::reward`] look
//! the table up, so they are defined at the cores and the discrete joint actions only.

use std::vec::Vec;

use super::{Grid, SolveError};
use crate::action::{ActionSet, MAX_AGENTS};
use crate::model::{Model, Tabulated};
use crate::real::Real;

/// Successors and rewards of every (core, joint action) pair of one grid.
#[derive(Clone, Debug)]
pub struct TabulatedModel<T> {
    grid: Grid<T>,
    /// Per agent: action components (action-major) and components per action.
    actions: Vec<(Vec<T>, usize)>,
    n_joint: usize,
    next_states: Vec<T>,
    rewards: Vec<T>,
}

impl<T: Real> TabulatedModel<T> {
    /// Builds the table. `actions[i]` holds agent `i`'s actions (`values`, action-major, and the
    /// number of components per action); `next_states` has `N * M * E` values and `rewards`
    /// `N * M`, ordered by core (row-major) then joint action (agent 0 most significant).
    pub fn new(
        grid: Grid<T>,
        actions: Vec<(Vec<T>, usize)>,
        next_states: Vec<T>,
        rewards: Vec<T>,
    ) -> Result<Self, SolveError> {
        if actions.is_empty() || actions.len() > MAX_AGENTS {
            return Err(crate::EvalError::Agents {
                found: actions.len(),
            }
            .into());
        }
        let mut n_joint = 1usize;
        for (values, dim) in &actions {
            let set = ActionSet::try_new(values, *dim)?;
            n_joint = n_joint
                .checked_mul(set.n_actions())
                .ok_or(SolveError::TooLarge {
                    what: "joint action set",
                })?;
        }
        let (n, e) = (grid.n_cores(), grid.n_dims());
        let pairs = n.checked_mul(n_joint).ok_or(SolveError::TooLarge {
            what: "transition table",
        })?;
        crate::error::check_len("rewards", pairs, rewards.len())?;
        crate::error::check_len("next states", pairs * e, next_states.len())?;
        if next_states.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite { what: "successor" });
        }
        if rewards.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite { what: "reward" });
        }
        Ok(Self {
            grid,
            actions,
            n_joint,
            next_states,
            rewards,
        })
    }

    /// The grid the table was computed on.
    #[must_use]
    pub fn grid(&self) -> &Grid<T> {
        &self.grid
    }

    /// Number of joint actions.
    #[must_use]
    pub fn n_joint(&self) -> usize {
        self.n_joint
    }

    /// The core index of `x` if every component is exactly a core.
    fn core_of(&self, x: &[T]) -> Option<usize> {
        let mut d = 0;
        for (c, &v) in self.grid.cores().iter().zip(x) {
            let i = c.iter().position(|&ci| ci == v)?;
            d = d * c.len() + i;
        }
        Some(d)
    }

    /// The joint index of `u` if each agent's components are exactly one of its actions.
    fn joint_of(&self, u: &[T]) -> Option<usize> {
        let mut j = 0;
        let mut off = 0;
        for (values, dim) in &self.actions {
            let m = values.len() / dim;
            let a = (0..m).find(|&a| values[a * dim..(a + 1) * dim] == u[off..off + dim])?;
            j = j * m + a;
            off += dim;
        }
        Some(j)
    }
}

impl<T: Real> Model<T> for TabulatedModel<T> {
    fn state_dim(&self) -> usize {
        self.grid.n_dims()
    }

    fn n_agents(&self) -> usize {
        self.actions.len()
    }

    fn action_set(&self, agent: usize) -> ActionSet<'_, T> {
        let (values, dim) = &self.actions[agent];
        ActionSet::try_new(values, *dim).expect("validated in new")
    }

    fn state_bounds(&self, dim: usize) -> (T, T) {
        let c = &self.grid.cores()[dim];
        (c[0], c[c.len() - 1])
    }

    /// The tabulated successor; NaN unless `x` is a core and `u` a joint action.
    fn step(&self, x: &[T], u: &[T], next: &mut [T]) {
        let e = self.grid.n_dims();
        match (self.core_of(x), self.joint_of(u)) {
            (Some(d), Some(j)) => {
                let i = (d * self.n_joint + j) * e;
                next.copy_from_slice(&self.next_states[i..i + e]);
            }
            _ => next.fill(T::from_f64(f64::NAN)),
        }
    }

    /// The tabulated reward; NaN unless `x` is a core and `u` a joint action.
    fn reward(&self, x: &[T], u: &[T]) -> T {
        match (self.core_of(x), self.joint_of(u)) {
            (Some(d), Some(j)) => self.rewards[d * self.n_joint + j],
            _ => T::from_f64(f64::NAN),
        }
    }

    fn tabulated(&self) -> Option<Tabulated<'_, T>> {
        Some(Tabulated {
            n_cores: self.grid.n_cores(),
            next_states: &self.next_states,
            rewards: &self.rewards,
        })
    }
}
