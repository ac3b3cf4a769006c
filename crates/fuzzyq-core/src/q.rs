//! Q evaluation and policies for the two parameter layouts.
//!
//! # `joint` layout (eqs 7, 8, 20)
//! `theta[d, u]` over joint cores `d` and joint actions `u`, stored row-major
//! (`theta[d * M + u]`). `Q(x, u) = sum_d mu_d(x) theta[d, u]`. For problems too large to store
//! `theta` (the paper's has 2.56e9 entries) the solver keeps only `V[d] = max_u theta[d, u]`;
//! [`crate::backup::q_values_from_v`] evaluates `Q(x, .)` from `V` and the model.
//!
//! # `additive` layout (eqs 12-13)
//! One parameter vector `phi` of `z = n N M` entries: agent `i`, core `d` of the agent's own
//! state partition (`N` cores), own action `j` (`M` per agent) at the paper's eq 12 index
//! `d + j N + i N M` (0-based). `Q(x, u) = sum_i sum_d mu_d(x_i) phi[i, d, u_i]` where `x_i` is
//! agent `i`'s own state. The greedy joint action decomposes into per-agent argmaxes.
//!
//! # Policies
//! - greedy (eq 7): the joint action maximising `Q(x, .)`, ties broken towards the lowest
//!   joint index ([`argmax`]). Every agent applies the same rule to the same values, which is
//!   the implicit coordination of the paper's section 2.2.
//! - interpolated (eq 22): `h(x) = sum_d mu_d(x) u(j*_d)` with `j*_d` the greedy joint action of
//!   core `d`: a continuous joint action vector, the membership-weighted average of the cores'
//!   greedy actions. It needs only a per-core action table, so a controller can run it in
//!   microseconds.

use crate::action::JointActions;
use crate::error::{EvalError, check_len};
use crate::partition::ProductPartition;
use crate::real::Real;

/// Index of the largest value, the lowest index among ties; NaNs never win. `None` if `q` is
/// empty or all NaN.
#[inline]
#[must_use]
pub fn argmax<T: Real>(q: &[T]) -> Option<usize> {
    let mut best: Option<(usize, T)> = None;
    for (i, &v) in q.iter().enumerate() {
        if v.is_nan() {
            continue;
        }
        match best {
            Some((_, b)) if v <= b => {}
            _ => best = Some((i, v)),
        }
    }
    best.map(|(i, _)| i)
}

/// `out[u] = Q(x, u) = sum_d mu_d(x) theta[d, u]` for the `joint` layout with stored `theta`
/// (`theta.len() == N * M`, `out.len() == M`).
pub fn q_values<T: Real>(
    grid: &ProductPartition<'_, T>,
    theta: &[T],
    x: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    let m = out.len();
    check_len("theta", grid.n_cores() * m, theta.len())?;
    let active = grid.active(x)?;
    out.fill(T::ZERO);
    active.for_each(|d, w| {
        let row = &theta[d * m..(d + 1) * m];
        for (o, &t) in out.iter_mut().zip(row) {
            *o += w * t;
        }
    });
    Ok(())
}

/// The greedy joint action at `x` for stored `theta` (eq 7), using `q` (length `M`) as scratch.
pub fn greedy_action<T: Real>(
    grid: &ProductPartition<'_, T>,
    theta: &[T],
    x: &[T],
    q: &mut [T],
) -> Result<usize, EvalError> {
    q_values(grid, theta, x, q)?;
    argmax(q).ok_or(EvalError::Length {
        what: "Q-values",
        expected: 1,
        found: 0,
    })
}

/// The interpolated policy of eq 22: `out = sum_d mu_d(x) u(greedy[d])`, where `greedy[d]` is
/// the greedy joint action index of core `d` and `u(.)` its joint action vector
/// (`out.len() == joint.dim()`).
pub fn interpolated_action<T: Real>(
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    greedy: &[u32],
    x: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    check_len("greedy actions", grid.n_cores(), greedy.len())?;
    check_len("joint action vector", joint.dim(), out.len())?;
    let active = grid.active(x)?;
    // Validate before accumulating so the callback cannot fail halfway.
    let mut bad = None;
    active.for_each(|d, _| {
        if greedy[d] as usize >= joint.n_joint() {
            bad = Some(greedy[d] as usize);
        }
    });
    if let Some(index) = bad {
        return Err(EvalError::OutOfRange {
            what: "greedy action",
            index,
            len: joint.n_joint(),
        });
    }
    out.fill(T::ZERO);
    active.for_each(|d, w| {
        let u = greedy[d] as usize;
        for i in 0..joint.n_agents() {
            let set = joint.agent(i);
            let a = set.action(joint.agent_index(u, i));
            let off = joint.agent_offset(i);
            for (o, &c) in out[off..off + set.dim()].iter_mut().zip(a) {
                *o += w * c;
            }
        }
    });
    Ok(())
}

/// The `additive` layout (paper eqs 12-13): per-agent parameters over the agent's own state.
pub mod additive {
    use super::*;

    /// The paper's eq 12 index of `phi[i, d, j]` (all 0-based): `d + j N + i N M`.
    #[inline]
    #[must_use]
    pub const fn index(
        agent: usize,
        core: usize,
        action: usize,
        n_cores: usize,
        n_actions: usize,
    ) -> usize {
        core + action * n_cores + agent * n_cores * n_actions
    }

    /// Length `z = n N M` of the parameter vector.
    #[inline]
    #[must_use]
    pub const fn len(n_agents: usize, n_cores: usize, n_actions: usize) -> usize {
        n_agents * n_cores * n_actions
    }

    /// Agent `agent`'s contributions `out[j] = sum_d mu_d(x_i) phi[agent, d, j]` at its own
    /// state `x_i` (`out.len() == M`, `phi.len() == n N M`).
    pub fn agent_q_values<T: Real>(
        grid: &ProductPartition<'_, T>,
        phi: &[T],
        n_agents: usize,
        agent: usize,
        x_i: &[T],
        out: &mut [T],
    ) -> Result<(), EvalError> {
        let n = grid.n_cores();
        let m = out.len();
        check_len("phi", len(n_agents, n, m), phi.len())?;
        if agent >= n_agents {
            return Err(EvalError::OutOfRange {
                what: "agent",
                index: agent,
                len: n_agents,
            });
        }
        let active = grid.active(x_i)?;
        out.fill(T::ZERO);
        active.for_each(|d, w| {
            for (j, o) in out.iter_mut().enumerate() {
                *o += w * phi[index(agent, d, j, n, m)];
            }
        });
        Ok(())
    }

    /// `Q(x, u)` of eq 13 for per-agent actions `u` (one index per agent); `agent_states`
    /// concatenates the agents' own states (`n * E_agent` values).
    pub fn q_value<T: Real>(
        grid: &ProductPartition<'_, T>,
        phi: &[T],
        n_actions: usize,
        agent_states: &[T],
        u: &[usize],
    ) -> Result<T, EvalError> {
        let n_agents = u.len();
        let e = grid.n_dims();
        let n = grid.n_cores();
        check_len("agent states", n_agents * e, agent_states.len())?;
        check_len("phi", len(n_agents, n, n_actions), phi.len())?;
        let mut q = T::ZERO;
        for (i, &j) in u.iter().enumerate() {
            if j >= n_actions {
                return Err(EvalError::OutOfRange {
                    what: "agent action",
                    index: j,
                    len: n_actions,
                });
            }
            let active = grid.active(&agent_states[i * e..(i + 1) * e])?;
            active.for_each(|d, w| q += w * phi[index(i, d, j, n, n_actions)]);
        }
        Ok(q)
    }

    /// The greedy per-agent actions (each agent's argmax of its own contribution, lowest index
    /// on ties), written into `out` (one per agent); `q` (length `M`) is scratch.
    pub fn greedy_actions<T: Real>(
        grid: &ProductPartition<'_, T>,
        phi: &[T],
        agent_states: &[T],
        q: &mut [T],
        out: &mut [usize],
    ) -> Result<(), EvalError> {
        let n_agents = out.len();
        let e = grid.n_dims();
        check_len("agent states", n_agents * e, agent_states.len())?;
        for (i, o) in out.iter_mut().enumerate() {
            agent_q_values(grid, phi, n_agents, i, &agent_states[i * e..(i + 1) * e], q)?;
            *o = argmax(q).ok_or(EvalError::Length {
                what: "Q-values",
                expected: 1,
                found: 0,
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::ActionSet;

    #[test]
    fn argmax_prefers_lowest_index_and_skips_nan() {
        assert_eq!(argmax(&[1.0f32, 3.0, 3.0, 2.0]), Some(1));
        assert_eq!(argmax(&[f32::NAN, 0.5, 0.5]), Some(1));
        assert_eq!(argmax::<f64>(&[]), None);
        assert_eq!(argmax(&[f64::NAN]), None);
        assert_eq!(argmax(&[f64::NEG_INFINITY, -1.0]), Some(1));
    }

    #[test]
    fn joint_q_interpolates_theta() {
        let c = [0.0f64, 1.0];
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let theta = [1.0, 0.0, 0.0, 3.0]; // core 0: (1, 0), core 1: (0, 3)
        let mut q = [0.0; 2];
        q_values(&g, &theta, &[0.25], &mut q).unwrap();
        assert_eq!(q, [0.75, 0.75]);
        assert_eq!(greedy_action(&g, &theta, &[0.25], &mut q).unwrap(), 0);
        assert_eq!(greedy_action(&g, &theta, &[0.3], &mut q).unwrap(), 1);
    }

    #[test]
    fn interpolated_policy_averages_core_actions() {
        let c = [0.0f64, 1.0];
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let a = [-2.0, 0.0, 2.0];
        let set = ActionSet::try_new(&a, 1).unwrap();
        let j = JointActions::try_new(&[set]).unwrap();
        let mut out = [0.0];
        interpolated_action(&g, &j, &[0, 2], &[0.25], &mut out).unwrap();
        assert!((out[0] - (0.75 * -2.0 + 0.25 * 2.0)).abs() < 1e-12);
        assert!(interpolated_action(&g, &j, &[0, 3], &[0.25], &mut out).is_err());
    }

    #[test]
    fn additive_index_matches_eq12() {
        // [i, d, j] = [d + (j - 1) N] + (i - 1) N M with 1-based i, d, j.
        let (n, m) = (7, 3);
        for i in 1..=2 {
            for d in 1..=n {
                for j in 1..=m {
                    let one_based = (d + (j - 1) * n) + (i - 1) * n * m;
                    assert_eq!(additive::index(i - 1, d - 1, j - 1, n, m) + 1, one_based);
                }
            }
        }
    }

    #[test]
    fn additive_q_sums_agents() {
        let c = [0.0f64, 1.0];
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let (n, m) = (2, 2);
        let mut phi = [0.0; 8];
        phi[additive::index(0, 1, 1, n, m)] = 4.0;
        phi[additive::index(1, 0, 0, n, m)] = 2.0;
        let states = [1.0, 0.5];
        let q = additive::q_value(&g, &phi, m, &states, &[1, 0]).unwrap();
        assert!((q - (4.0 + 1.0)).abs() < 1e-12);
        let mut out = [9; 2];
        let mut scratch = [0.0; 2];
        additive::greedy_actions(&g, &phi, &states, &mut scratch, &mut out).unwrap();
        assert_eq!(out, [1, 0]);
    }
}
