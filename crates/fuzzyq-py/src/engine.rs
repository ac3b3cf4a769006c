//! Decision engines: a model, a grid, `V` and the per-core greedy actions, owned together
//! with the prepared backup operator that borrows them (so a decision costs microseconds, not
//! the operator's set-up). One concrete type per (precision, model), behind [`Engine`].

use std::sync::Arc;

use fuzzyq_core::solver::{BackupPath, Grid, Operator, SolveError, TabulatedModel};
use fuzzyq_core::{Backup, EvalError, Model, Real, q};
use fuzzyq_sim::PointMass;
use rayon::prelude::*;

/// What a policy needs, whatever the precision and model.
pub(crate) trait Engine: Send + Sync {
    fn state_dim(&self) -> usize;
    fn action_dim(&self) -> usize;
    fn n_joint(&self) -> usize;
    fn n_agents(&self) -> usize;
    fn n_cores(&self) -> usize;
    /// `Q(x, .)` (eq 7), one value per joint action.
    fn q_values(&self, x: &[f64], out: &mut [f64]) -> Result<(), SolveError>;
    /// The joint action vector of joint action `u`.
    fn joint_vector(&self, u: usize, out: &mut [f64]);
    /// Per-agent action indices of joint action `u`.
    fn agent_indices(&self, u: usize) -> Vec<usize>;
    /// The interpolated policy (eq 22) at `x`.
    fn interpolated(&self, x: &[f64], out: &mut [f64]) -> Result<(), EvalError>;
    /// `V` interpolated at `x`.
    fn value(&self, x: &[f64]) -> Result<f64, EvalError>;
    /// `theta[d, u]` for every core and joint action, core-major.
    fn theta(&self) -> Result<Vec<f64>, SolveError>;
}

/// What an engine owns.
pub(crate) struct Owned<T, M> {
    pub(crate) model: Arc<M>,
    pub(crate) grid: Grid<T>,
    pub(crate) v: Vec<T>,
    pub(crate) greedy: Vec<u32>,
}

fn to_t<T: Real>(x: &[f64]) -> Vec<T> {
    x.iter().map(|&v| T::from_f64(v)).collect()
}

fn q_values<T: Real, M: Model<T> + Sync>(
    o: &Owned<T, M>,
    op: &Operator<'_, T, M>,
    x: &[f64],
    out: &mut [f64],
) -> Result<(), SolveError> {
    let mut q = vec![T::ZERO; out.len()];
    op.q_values(&o.v, &to_t::<T>(x), &mut q)?;
    for (a, b) in out.iter_mut().zip(&q) {
        *a = b.to_f64();
    }
    Ok(())
}

fn interpolated<T: Real, M: Model<T> + Sync>(
    o: &Owned<T, M>,
    op: &Operator<'_, T, M>,
    x: &[f64],
    out: &mut [f64],
) -> Result<(), EvalError> {
    let mut u = vec![T::ZERO; out.len()];
    q::interpolated_action(&o.grid.view(), op.joint(), &o.greedy, &to_t::<T>(x), &mut u)?;
    for (a, b) in out.iter_mut().zip(&u) {
        *a = b.to_f64();
    }
    Ok(())
}

fn theta<T: Real, M: Model<T> + Send + Sync>(
    o: &Owned<T, M>,
    op: &Operator<'_, T, M>,
) -> Result<Vec<f64>, SolveError> {
    let (n, m, e) = (o.grid.n_cores(), op.joint().n_joint(), o.grid.n_dims());
    let view = o.grid.view();
    let mut out = vec![0.0; n * m];
    out.par_chunks_mut(m).enumerate().try_for_each(|(d, row)| {
        let mut x = vec![T::ZERO; e];
        view.core_state(d, &mut x)?;
        let mut q = vec![T::ZERO; m];
        // At a core the memberships are (1, 0, ...), so Q(x_d, .) is theta[d, .].
        op.q_values(&o.v, &x, &mut q)?;
        for (a, b) in row.iter_mut().zip(&q) {
            *a = b.to_f64();
        }
        Ok::<(), SolveError>(())
    })?;
    Ok(out)
}

macro_rules! engine {
    ($name:ident, $dep:ident, $t:ty, $m:ty) => {
        type $dep<'a> = Operator<'a, $t, $m>;

        self_cell::self_cell!(
            pub(crate) struct $name {
                owner: Owned<$t, $m>,
                #[covariant]
                dependent: $dep,
            }
        );

        impl $name {
            pub(crate) fn build(
                owned: Owned<$t, $m>,
                backup: Backup<$t>,
            ) -> Result<Self, SolveError> {
                Self::try_new(owned, |o| {
                    Operator::new(&*o.model, o.grid.view(), backup, BackupPath::Auto)
                })
            }
        }

        impl Engine for $name {
            fn state_dim(&self) -> usize {
                self.borrow_owner().grid.n_dims()
            }
            fn action_dim(&self) -> usize {
                self.borrow_dependent().joint().dim()
            }
            fn n_joint(&self) -> usize {
                self.borrow_dependent().joint().n_joint()
            }
            fn n_agents(&self) -> usize {
                self.borrow_dependent().joint().n_agents()
            }
            fn n_cores(&self) -> usize {
                self.borrow_owner().grid.n_cores()
            }
            fn q_values(&self, x: &[f64], out: &mut [f64]) -> Result<(), SolveError> {
                q_values(self.borrow_owner(), self.borrow_dependent(), x, out)
            }
            fn joint_vector(&self, u: usize, out: &mut [f64]) {
                let j = self.borrow_dependent().joint();
                let mut v = vec![<$t>::default(); j.dim()];
                j.vector_unchecked(u, &mut v);
                for (a, &b) in out.iter_mut().zip(&v) {
                    *a = f64::from(b);
                }
            }
            fn agent_indices(&self, u: usize) -> Vec<usize> {
                let j = self.borrow_dependent().joint();
                (0..j.n_agents()).map(|i| j.agent_index(u, i)).collect()
            }
            fn interpolated(&self, x: &[f64], out: &mut [f64]) -> Result<(), EvalError> {
                interpolated(self.borrow_owner(), self.borrow_dependent(), x, out)
            }
            fn value(&self, x: &[f64]) -> Result<f64, EvalError> {
                let o = self.borrow_owner();
                Ok(f64::from(
                    o.grid.view().active(&to_t::<$t>(x))?.interpolate(&o.v),
                ))
            }
            fn theta(&self) -> Result<Vec<f64>, SolveError> {
                theta(self.borrow_owner(), self.borrow_dependent())
            }
        }
    };
}

engine!(PointMass32, OpPointMass32, f32, PointMass);
engine!(PointMass64, OpPointMass64, f64, PointMass);
engine!(Table32, OpTable32, f32, TabulatedModel<f32>);
engine!(Table64, OpTable64, f64, TabulatedModel<f64>);
