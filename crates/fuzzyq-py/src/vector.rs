//! `_step_batch`: many copies of a built-in model stepped in one call, with the GIL released:
//! what `fuzzyq.envs.ModelVectorEnv` steps its environments with.

use fuzzyq_core::Model;
use fuzzyq_sim::model::Dynamics;
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::classic::ClassicModel;
use crate::convert::matrix;
use crate::errors::{Kind, error, guard};
use crate::model::PointMass;

/// Every row's transition: `(next_states, rewards, terminal)` for states `xs` (`e` values
/// per row) under action vectors `us` (`a` per row). The reward is the model's at the row's
/// state under its action; `terminal` whether the next state is terminal.
fn step_rows<M: Dynamics + Model<f64> + Sync>(
    m: &M,
    xs: &[f64],
    us: &[f64],
    e: usize,
    a: usize,
) -> (Vec<f64>, Vec<f64>, Vec<bool>) {
    let n = xs.len() / e.max(1);
    let mut next = vec![0.0; n * e];
    let mut rewards = vec![0.0; n];
    let mut terminal = vec![false; n];
    let terminals = Dynamics::has_terminal_states(m);
    // Rows are independent: in parallel on the process's pool, the same bits on any count.
    next.par_chunks_mut(e.max(1))
        .zip(rewards.par_iter_mut())
        .zip(terminal.par_iter_mut())
        .enumerate()
        .with_min_len(16)
        .for_each(|(i, ((y, r), t))| {
            let (x, u) = (&xs[i * e..(i + 1) * e], &us[i * a..(i + 1) * a]);
            *r = Model::<f64>::reward(m, x, u);
            Dynamics::step(m, x, u, y);
            *t = terminals && Dynamics::is_terminal(m, y);
        });
    (next, rewards, terminal)
}

/// Steps a batch of a built-in model's states: `states` of shape `(n, state_dim)` under
/// `actions` of shape `(n, action_dim)` (any action vectors) give `(next_states (n,
/// state_dim), rewards (n,), terminal (n,))`, computed in Rust with the GIL released.
#[pyfunction]
#[allow(clippy::type_complexity)] // the three arrays
pub(crate) fn _step_batch<'py>(
    py: Python<'py>,
    model: &Bound<'py, PyAny>,
    states: &Bound<'py, PyAny>,
    actions: &Bound<'py, PyAny>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<bool>>,
)> {
    guard(py, || {
        let (e, a) = if let Ok(pm) = model.cast::<PointMass>() {
            let m = &pm.get().model;
            (
                Model::<f64>::state_dim(&**m),
                Model::<f64>::n_agents(&**m) * Model::<f64>::action_set(&**m, 0).dim(),
            )
        } else if let Ok(c) = model.cast::<ClassicModel>() {
            let m = &*c.get().model;
            (
                Model::<f64>::state_dim(m),
                Model::<f64>::action_set(m, 0).dim(),
            )
        } else {
            return Err(error(
                py,
                Kind::InputType,
                "model: expected a fuzzyq.PointMass or a classic benchmark",
            ));
        };
        let (n, _, xs) = matrix(states, "states", None, Some(e))?;
        let (_, _, us) = matrix(actions, "actions", Some(n), Some(a))?;
        let (next, rewards, terminal) = if let Ok(pm) = model.cast::<PointMass>() {
            let m = pm.get().model.clone();
            crate::pool::detach(py, || step_rows(&*m, &xs, &us, e, a))
        } else {
            let m = model.cast::<ClassicModel>()?.get().model.clone();
            crate::pool::detach(py, || step_rows(&*m, &xs, &us, e, a))
        };
        let next = Array2::from_shape_vec((n, e), next).expect("n x e");
        Ok((
            PyArray2::from_owned_array(py, next),
            PyArray1::from_vec(py, rewards),
            PyArray1::from_vec(py, terminal),
        ))
    })
}
