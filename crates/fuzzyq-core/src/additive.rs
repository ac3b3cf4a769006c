//! The `additive` layout (the paper's eqs 12-13 read per agent) and the sample updates of its
//! parameters (eqs 23-27), on caller-provided slices, in `f32` or `f64`, without allocating:
//! what a robot needs to learn on board.
//!
//! # Layout
//! Agent `i` fuzzifies its own observation `x_i` with its own product partition (`N_i` cores)
//! and has `M_i` discrete actions. Its parameters `phi_i` are one table of `N_i * M_i` values,
//! **core-major**: the parameter of core `d` and action `j` is `phi_i[d * M_i + j]`
//! ([`index`]). The joint Q-function is the sum of the agents' terms, a linear fuzzy value
//! decomposition:
//!
//! ```text
//! Q(x, u) = sum_i sum_d mu_d(x_i) phi_i[d * M_i + u_i]
//! ```
//!
//! The paper's eq 12 numbers the same `z = n N M` parameters `d + j N + i N M` (core fastest);
//! storing them core-major instead keeps a core's `M` values together, so the action values at
//! a state read `2^E` contiguous rows. Since `Q` is a sum of per-agent terms, its maximum over
//! joint actions is the sum of the agents' maxima and the greedy joint action is the tuple of
//! the agents' greedy actions (decentralised; ties go to the lowest index, [`crate::q::argmax`]).
//! The layout has no contraction guarantee; it is trained from samples, from `phi = 0` (eq 23).
//!
//! # The sample updates ([`Update`])
//! After the transition `(x_k, u_k) -> (r_{k+1}, x_{k+1})`, with `beta = gamma max Q(x_{k+1}, .)`
//! (0 when `x_{k+1}` is terminal, an absorbing end; a truncated episode bootstraps normally):
//!
//! - [`Update::Corrected`] (the default), semi-gradient Q-learning with the memberships as
//!   features: `delta = r + beta - Q(x_k, u_k)` and, for every agent `i` and every core `d`
//!   active at `x_k`, `phi_i[d, u_{k,i}] += alpha delta mu_d(x_{k,i})`.
//! - [`Update::Literal`], eqs 24-26 as printed: `Gamma = Q(x_{k+1}, u_k)` (the memberships of
//!   the *next* state), `Omega = sum_i sum_d mu_d(x_{k+1,i})` (a scalar, `n` for normalised
//!   memberships), and the one increment `alpha (r + beta - Gamma) Omega` added to the taken
//!   action's parameter of every core active (membership `> 0`) at `x_{k+1}`. A model-free
//!   learner cannot look two steps ahead, so `beta` is taken at `x_{k+1}` like `Gamma`. The
//!   printed form keeps no credit assignment; it is kept to measure exactly that.
//!
//! An update is all or nothing: if any parameter would become non-finite, none changes
//! ([`update`] returns `None`). [`update`] does one whole transition; [`Td`] and
//! [`Increment`] are its two halves, for learners that keep the action values of the next
//! state (to choose the next action) or log what each update overwrites.
//!
//! ```
//! use fuzzyq_core::additive::{self, Agent, Update};
//! use fuzzyq_core::ProductPartition;
//!
//! // One agent on [0, 1] with three cores and two actions; phi starts at 0.
//! let cores = [0.0_f32, 0.5, 1.0];
//! let grid = ProductPartition::try_new(&[&cores[..]]).unwrap();
//! let mut phi = [0.0_f32; 6];
//! let (cur, next) = (grid.active(&[0.25]).unwrap(), grid.active(&[0.5]).unwrap());
//! let mut agents = [Agent { phi: &mut phi, n_actions: 2, cur, next, action: 1 }];
//! let delta = additive::update(Update::Corrected, &mut agents, 1.0, false, 0.9, 0.5).unwrap();
//! assert_eq!(delta, Some(1.0)); // r + gamma max Q(x') - Q(x, u) = 1 + 0 - 0
//! assert_eq!(phi, [0.0, 0.25, 0.0, 0.25, 0.0, 0.0]); // alpha delta mu_d(0.25) on action 1
//! ```

use crate::error::EvalError;
use crate::partition::ActiveCores;
use crate::real::Real;

crate::named_option! {
    /// Which sample update trains the parameters (see the [module docs](self)).
    #[derive(Default)]
    pub enum Update: "update" {
        /// Semi-gradient Q-learning, `phi += alpha delta mu(x_k)`.
        #[default]
        Corrected = "corrected" => "semi-gradient Q-learning: phi += alpha delta mu(x_k)",
        /// Eqs 24-26 as printed: one increment `alpha (r + beta - Gamma) Omega` for every
        /// updated parameter, kept for ablation.
        Literal = "literal" => "eqs 24-26 as printed: one increment alpha (r + beta - Gamma) Omega",
    }
}

/// The position of the parameter of core `core` and action `action` in an agent's table of
/// `n_actions` actions per core (`core * n_actions + action`).
#[inline]
#[must_use]
pub const fn index(core: usize, action: usize, n_actions: usize) -> usize {
    core * n_actions + action
}

/// Checks that every active core has a row of `n_actions` parameters in `phi`.
fn check_rows<T: Real>(
    active: &ActiveCores<T>,
    phi: &[T],
    n_actions: usize,
) -> Result<(), EvalError> {
    let rows = phi.len() / n_actions.max(1);
    if n_actions == 0 || !phi.len().is_multiple_of(n_actions) {
        return Err(EvalError::Length {
            what: "parameters (a whole number of rows of the action count)",
            expected: rows.max(1) * n_actions.max(1),
            found: phi.len(),
        });
    }
    let mut bad = None;
    active.for_each(|d, _| {
        if d >= rows {
            bad = Some(d);
        }
    });
    match bad {
        Some(index) => Err(EvalError::OutOfRange {
            what: "active core",
            index,
            len: rows,
        }),
        None => Ok(()),
    }
}

/// One agent's action values at its active cores: `out[j] = sum_d mu_d phi[d * M + j]`
/// (`M = out.len()`).
pub fn q_values<T: Real>(
    active: &ActiveCores<T>,
    phi: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    check_rows(active, phi, out.len())?;
    q_values_unchecked(active, phi, out);
    Ok(())
}

/// [`q_values`] for inputs the caller has checked.
#[inline]
pub fn q_values_unchecked<T: Real>(active: &ActiveCores<T>, phi: &[T], out: &mut [T]) {
    let m = out.len();
    out.fill(T::ZERO);
    active.for_each(|d, w| {
        for (o, &p) in out.iter_mut().zip(&phi[d * m..(d + 1) * m]) {
            *o += w * p;
        }
    });
}

/// One agent's value of action `action`: `sum_d mu_d phi[d * M + action]`.
pub fn q_value<T: Real>(
    active: &ActiveCores<T>,
    phi: &[T],
    n_actions: usize,
    action: usize,
) -> Result<T, EvalError> {
    check_rows(active, phi, n_actions)?;
    check_action(action, n_actions)?;
    Ok(q_value_unchecked(active, phi, n_actions, action))
}

#[inline]
fn q_value_unchecked<T: Real>(
    active: &ActiveCores<T>,
    phi: &[T],
    n_actions: usize,
    action: usize,
) -> T {
    let mut v = T::ZERO;
    active.for_each(|d, w| v += w * phi[index(d, action, n_actions)]);
    v
}

fn check_action(action: usize, n_actions: usize) -> Result<(), EvalError> {
    if action < n_actions {
        Ok(())
    } else {
        Err(EvalError::OutOfRange {
            what: "agent action",
            index: action,
            len: n_actions,
        })
    }
}

/// One agent's greedy action and its value: the lowest index of the largest action value
/// (see [`crate::q::argmax`]), computed without a buffer.
pub fn greedy<T: Real>(
    active: &ActiveCores<T>,
    phi: &[T],
    n_actions: usize,
) -> Result<(usize, T), EvalError> {
    check_rows(active, phi, n_actions)?;
    let mut best: Option<(usize, T)> = None;
    for j in 0..n_actions {
        let v = q_value_unchecked(active, phi, n_actions, j);
        let better = match best {
            Some((_, b)) => v > b,
            None => !v.is_nan(),
        };
        if better {
            best = Some((j, v));
        }
    }
    Ok(best.unwrap_or((0, T::ZERO)))
}

/// The largest value (`-inf` for an empty slice): `fold(-inf, max)`, NaNs ignored.
#[inline]
#[must_use]
pub fn max_value<T: Real>(q: &[T]) -> T {
    largest(q.iter().copied())
}

/// The largest of `values`, NaNs ignored (`-inf` if there is none).
#[inline]
fn largest<T: Real>(values: impl Iterator<Item = T>) -> T {
    values.fold(-T::ONE / T::ZERO, |m, v| if v > m { v } else { m })
}

/// What one transition contributes to an update, summed over the agents (see [`Td::add_agent`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Td<T> {
    /// `Q(x_k, u_k)`: the agents' values of the actions they took, at `x_k`.
    pub q_taken: T,
    /// `max Q(x_{k+1}, .)`: the sum of the agents' largest action values at `x_{k+1}`.
    pub next_max: T,
    /// `Gamma = Q(x_{k+1}, u_k)` (eq 25): the taken actions valued at `x_{k+1}`.
    pub next_taken: T,
    /// `Omega` (eq 26): the memberships at `x_{k+1}`, summed over agents and cores.
    pub omega: T,
}

impl<T: Real> Td<T> {
    /// Adds agent `i`'s part: `q_taken`, its value of the action `action` it took at `x_k`;
    /// `q_next`, its action values at `x_{k+1}`; and `next`, its active cores at `x_{k+1}`.
    /// `action` must index `q_next`.
    pub fn add_agent(&mut self, q_taken: T, q_next: &[T], action: usize, next: &ActiveCores<T>) {
        self.add(q_taken, max_value(q_next), q_next[action], next);
    }

    fn add(&mut self, q_taken: T, next_max: T, next_taken: T, next: &ActiveCores<T>) {
        self.q_taken += q_taken;
        self.next_max += next_max;
        self.next_taken += next_taken;
        next.for_each(|_, w| self.omega += w);
    }
}

/// The change one transition makes (see [`Update::increment`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Increment<T> {
    rule: Update,
    /// The TD error `delta` ([`Update::Corrected`]) or the bracket `r + beta - Gamma`
    /// ([`Update::Literal`]).
    pub error: T,
    /// `alpha delta` (scaled by each core's membership) or `alpha (r + beta - Gamma) Omega`
    /// (the same for every updated parameter).
    pub step: T,
}

impl Update {
    /// The increment of a transition with reward `reward` (finite) and the sums `td`;
    /// `terminal`: `x_{k+1}` is absorbing (no bootstrap). `None` when it is not finite.
    #[must_use]
    pub fn increment<T: Real>(
        self,
        td: &Td<T>,
        reward: T,
        terminal: bool,
        gamma: T,
        alpha: T,
    ) -> Option<Increment<T>> {
        let beta = if terminal {
            T::ZERO
        } else {
            gamma * td.next_max
        };
        let (error, step) = match self {
            Self::Corrected => {
                let delta = reward + beta - td.q_taken;
                (delta, alpha * delta)
            }
            Self::Literal => {
                let bracket = reward + beta - td.next_taken;
                (bracket, alpha * bracket * td.omega)
            }
        };
        step.is_finite().then_some(Increment {
            rule: self,
            error,
            step,
        })
    }
}

impl<T: Real> Increment<T> {
    /// The cores whose parameters this increment changes: those active at `x_k`
    /// ([`Update::Corrected`]) or at `x_{k+1}` ([`Update::Literal`]).
    #[must_use]
    pub fn cores<'a>(
        &self,
        cur: &'a ActiveCores<T>,
        next: &'a ActiveCores<T>,
    ) -> &'a ActiveCores<T> {
        match self.rule {
            Update::Corrected => cur,
            Update::Literal => next,
        }
    }

    /// Calls `f(index, change)` for every parameter of one agent this increment changes, given
    /// the cores from [`cores`](Self::cores) and the agent's action.
    #[inline]
    fn for_each(
        &self,
        cores: &ActiveCores<T>,
        n_actions: usize,
        action: usize,
        mut f: impl FnMut(usize, T),
    ) {
        match self.rule {
            Update::Corrected => {
                cores.for_each(|d, w| f(index(d, action, n_actions), self.step * w));
            }
            Update::Literal => cores.for_each(|d, w| {
                if w > T::ZERO {
                    f(index(d, action, n_actions), self.step);
                }
            }),
        }
    }

    /// Whether adding the increment keeps every changed parameter of one agent finite.
    #[must_use]
    pub fn keeps_finite(
        &self,
        phi: &[T],
        n_actions: usize,
        cores: &ActiveCores<T>,
        action: usize,
    ) -> bool {
        let mut finite = true;
        self.for_each(cores, n_actions, action, |k, c| {
            finite &= (phi[k] + c).is_finite();
        });
        finite
    }

    /// [`apply`](Self::apply) projected onto the box `[-bound, bound]`: each changed
    /// parameter is clamped into it (the projected update; an infinite `bound` is `apply`).
    pub fn apply_within(
        &self,
        phi: &mut [T],
        n_actions: usize,
        cores: &ActiveCores<T>,
        action: usize,
        bound: T,
        mut log: impl FnMut(usize, T),
    ) {
        self.for_each(cores, n_actions, action, |k, c| {
            log(k, phi[k]);
            phi[k] = (phi[k] + c).clamp_to(T::ZERO - bound, bound);
        });
    }

    /// Adds the increment to one agent's parameters; `log(index, old_value)` sees each
    /// parameter before it changes.
    pub fn apply(
        &self,
        phi: &mut [T],
        n_actions: usize,
        cores: &ActiveCores<T>,
        action: usize,
        mut log: impl FnMut(usize, T),
    ) {
        self.for_each(cores, n_actions, action, |k, c| {
            log(k, phi[k]);
            phi[k] += c;
        });
    }
}

/// One agent in an [`update`]: its parameters and what the transition looked like to it.
#[derive(Debug)]
pub struct Agent<'a, T> {
    /// The agent's table, `N * n_actions` values, core-major.
    pub phi: &'a mut [T],
    /// Its action count `M`.
    pub n_actions: usize,
    /// Its active cores at `x_k`.
    pub cur: ActiveCores<T>,
    /// Its active cores at `x_{k+1}`.
    pub next: ActiveCores<T>,
    /// The action it took.
    pub action: usize,
}

/// One whole sample update of every agent's parameters (see the [module docs](self)):
/// returns the TD error (or the literal bracket), or `None`, leaving every parameter as it
/// was, when a parameter would become non-finite. Errors: a table that does not fit its
/// cores, an action out of range, a non-finite reward.
pub fn update<T: Real>(
    rule: Update,
    agents: &mut [Agent<'_, T>],
    reward: T,
    terminal: bool,
    gamma: T,
    alpha: T,
) -> Result<Option<T>, EvalError> {
    if !reward.is_finite() {
        return Err(EvalError::NotFinite {
            what: "reward",
            index: 0,
        });
    }
    let mut td = Td::default();
    for a in agents.iter() {
        check_rows(&a.cur, a.phi, a.n_actions)?;
        check_rows(&a.next, a.phi, a.n_actions)?;
        check_action(a.action, a.n_actions)?;
        let next = |j| q_value_unchecked(&a.next, a.phi, a.n_actions, j);
        td.add(
            q_value_unchecked(&a.cur, a.phi, a.n_actions, a.action),
            largest((0..a.n_actions).map(next)),
            next(a.action),
            &a.next,
        );
    }
    let Some(inc) = rule.increment(&td, reward, terminal, gamma, alpha) else {
        return Ok(None);
    };
    let finite = agents
        .iter()
        .all(|a| inc.keeps_finite(a.phi, a.n_actions, inc.cores(&a.cur, &a.next), a.action));
    if !finite {
        return Ok(None);
    }
    for a in agents.iter_mut() {
        let cores = *inc.cores(&a.cur, &a.next);
        inc.apply(a.phi, a.n_actions, &cores, a.action, |_, _| {});
    }
    Ok(Some(inc.error))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::partition::ProductPartition;

    fn grid() -> ([f64; 3], [f64; 2]) {
        ([0.0, 0.5, 1.0], [0.0, 1.0])
    }

    #[test]
    fn index_is_core_major_and_a_permutation_of_eq12() {
        // Eq 12 (1-based): [i, d, j] = d + (j - 1) N + (i - 1) N M. Both numberings cover
        // 0..n N M once; ours keeps a core's M actions together.
        let (n, m, agents) = (7, 3, 2);
        let mut seen = [false; 42];
        for i in 0..agents {
            for d in 0..n {
                for j in 0..m {
                    let ours = i * n * m + index(d, j, m);
                    let eq12 = d + j * n + i * n * m;
                    assert!(!seen[ours]);
                    seen[ours] = true;
                    // Ours decodes to the same (agent, core, action) that eq 12 numbers.
                    let (agent, within) = (ours / (n * m), ours % (n * m));
                    let (core, action) = (within / m, within % m);
                    assert_eq!(core + action * n + agent * n * m, eq12);
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
        assert_eq!(index(2, 1, 3), 7);
    }

    #[test]
    fn values_greedy_and_checks() {
        let (c, _) = grid();
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let phi = [1.0, 0.0, 0.0, 3.0, 5.0, 5.0];
        let a = g.active(&[0.25]).unwrap(); // cores 0 and 1, 1/2 each
        let mut q = [0.0; 2];
        q_values(&a, &phi, &mut q).unwrap();
        assert_eq!(q, [0.5, 1.5]);
        assert_eq!(q_value(&a, &phi, 2, 1).unwrap(), 1.5);
        assert_eq!(greedy(&a, &phi, 2).unwrap(), (1, 1.5));
        let b = g.active(&[1.0]).unwrap();
        assert_eq!(greedy(&b, &phi, 2).unwrap(), (0, 5.0)); // tie: lowest index
        assert!(q_values(&b, &phi[..4], &mut q).is_err()); // core 2 has no row
        assert!(q_value(&a, &phi, 2, 2).is_err());
        assert!(q_values(&a, &phi[..5], &mut q).is_err());
        assert_eq!(max_value::<f64>(&[]), f64::NEG_INFINITY);
    }

    #[test]
    fn corrected_update_by_hand() {
        let (c, _) = grid();
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let mut phi0 = [0.0, 2.0, 0.0, 4.0, 1.0, 0.0];
        let mut phi1 = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (cur0, next0) = (g.active(&[0.25]).unwrap(), g.active(&[1.0]).unwrap());
        let (cur1, next1) = (g.active(&[0.0]).unwrap(), g.active(&[0.5]).unwrap());
        let mut agents = [
            Agent {
                phi: &mut phi0,
                n_actions: 2,
                cur: cur0,
                next: next0,
                action: 1,
            },
            Agent {
                phi: &mut phi1,
                n_actions: 2,
                cur: cur1,
                next: next1,
                action: 0,
            },
        ];
        // Q(x, u) = (0.5 * 2 + 0.5 * 4) + 1 = 4; max Q(x') = 1 + 0 = 1.
        let delta = update(Update::Corrected, &mut agents, 0.5, false, 0.9, 0.1)
            .unwrap()
            .unwrap();
        assert!((delta - (0.5 + 0.9 - 4.0)).abs() < 1e-12);
        let s = 0.1 * delta;
        assert_eq!(phi0, [0.0, 2.0 + 0.5 * s, 0.0, 4.0 + 0.5 * s, 1.0, 0.0]);
        assert_eq!(phi1, [1.0 + s, 0.0, 0.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn the_projected_update_clamps_each_changed_parameter() {
        let (c, _) = grid();
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let cores = g.active(&[0.25]).unwrap();
        let inc = Increment {
            rule: Update::Corrected,
            error: 10.0,
            step: 10.0,
        };
        let mut phi = [0.0, 2.0, 0.0, 4.0, 1.0, -9.0];
        let mut logged = [f64::NAN; 6];
        inc.apply_within(&mut phi, 2, &cores, 1, 5.0, |k, old| logged[k] = old);
        // Cores 0 and 1 hold half each: +5 on action 1, clamped to 5; the rest untouched.
        assert_eq!(phi, [0.0, 5.0, 0.0, 5.0, 1.0, -9.0]);
        assert_eq!(logged[1], 2.0);
        assert_eq!(logged[3], 4.0);
        // An infinite bound is the plain update.
        let mut free = [0.0, 2.0, 0.0, 4.0, 1.0, -9.0];
        let mut plain = free;
        inc.apply_within(&mut free, 2, &cores, 1, f64::INFINITY, |_, _| {});
        inc.apply(&mut plain, 2, &cores, 1, |_, _| {});
        assert_eq!(free, plain);
    }

    #[test]
    fn literal_update_gives_every_next_core_the_same_increment() {
        let (c, _) = grid();
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let mut phi = [0.0, 0.0, 2.0, 0.0, 0.0, 0.0];
        let (cur, next) = (g.active(&[1.0]).unwrap(), g.active(&[0.75]).unwrap());
        let mut agents = [Agent {
            phi: &mut phi,
            n_actions: 2,
            cur,
            next,
            action: 0,
        }];
        // Gamma = 0.5 * 2 = 1 (taken action at x'), beta = 0.9 * 1, Omega = 1.
        let bracket = update(Update::Literal, &mut agents, 0.0, false, 0.9, 0.5)
            .unwrap()
            .unwrap();
        assert!((bracket - (0.9 - 1.0)).abs() < 1e-12);
        let inc = 0.5 * bracket;
        assert_eq!(phi, [0.0, 0.0, 2.0 + inc, 0.0, inc, 0.0]);
        // Terminal: no bootstrap.
        let mut phi = [0.0; 6];
        let mut agents = [Agent {
            phi: &mut phi,
            n_actions: 2,
            cur,
            next,
            action: 1,
        }];
        let e = update(Update::Literal, &mut agents, 1.0, true, 0.9, 1.0).unwrap();
        assert_eq!(e, Some(1.0));
        assert_eq!(phi, [0.0, 0.0, 0.0, 1.0, 0.0, 1.0]);
    }

    #[test]
    fn an_update_that_would_overflow_changes_nothing() {
        let (c, _) = grid();
        let c = c.map(|v| v as f32);
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let mut phi = [0.0, 3.0e38_f32, 0.0, 0.0, 0.0, 0.0];
        let a = g.active(&[0.0]).unwrap();
        fn one(phi: &mut [f32], a: ActiveCores<f32>) -> [Agent<'_, f32>; 1] {
            [Agent {
                phi,
                n_actions: 2,
                cur: a,
                next: a,
                action: 1,
            }]
        }
        let mut agents = one(&mut phi, a);
        // delta = 3.4e38 - 3e38 = 4e37 and alpha delta = 8e37 are finite, but 3e38 + 8e37
        // overflows: nothing changes.
        let r = update(Update::Corrected, &mut agents, 3.4e38, true, 0.5, 2.0).unwrap();
        assert_eq!(r, None);
        assert_eq!(phi[1], 3.0e38);
        let mut agents = one(&mut phi, a);
        // A step that is itself infinite.
        assert_eq!(
            update(Update::Corrected, &mut agents, 3.4e38, true, 0.5, 10.0).unwrap(),
            None
        );
        assert!(update(Update::Corrected, &mut agents, f32::NAN, true, 0.5, 1.0).is_err());
    }
}
