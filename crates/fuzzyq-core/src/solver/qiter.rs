//! Busoniu's fuzzy Q-iteration with `theta` stored: the ApproxRL toolbox's operator.
//!
//! [`solve`](super::solve) interpolates per-core maxima,
//! `theta[d, u] = rho + gamma sum_d' mu_d'(x') max_u' theta[d', u']`, which needs only `V`.
//! Busoniu et al. (Automatica 2010; the book of 2010, ch. 4; the ApproxRL `fuzzyqi`) maximise
//! the interpolated Q-values instead:
//!
//! ```text
//! theta_k[d, u] = rho(x_d, u) + gamma max_u' sum_d' mu_d'(f(x_d, u)) theta_{k-1}[d', u']
//! ```
//!
//! Both are gamma-contractions with different fixed points: they agree where a successor's
//! active cores share their greedy action, and the first is larger elsewhere (a convex
//! combination of maxima is at least the maximum of the convex combination). [`solve_q`]
//! iterates the second, storing `theta` (`N * M` values) and the successors' memberships (at
//! most `2^E` per core and joint action), so it suits grids of up to a few million
//! Q-values. It is synchronous, starts from `theta_0 = 0` and stops after the first iteration
//! with `||theta_k - theta_{k-1}||_inf <= xi`, as `fuzzyqi` does; terminal successors and
//! absorbing goal cores are handled as in [`solve`](super::solve).

use core::ops::ControlFlow;
use std::time::Instant;
use std::vec::Vec;

use super::{Grid, SolveError, SolverConfig, Stop};
use crate::action::JointActions;
use crate::error::EvalError;
use crate::model::{Model, joint_actions};
use crate::partition::ProductPartition;
use crate::real::Real;

/// The result of [`solve_q`].
#[derive(Clone, Debug, PartialEq)]
pub struct QSolution<T> {
    /// `theta_K`, row-major: `theta[d * M + u]` for core `d` (the grid's row-major order) and
    /// joint action `u`.
    pub theta: Vec<T>,
    /// Number of joint actions `M`.
    pub n_joint: usize,
    /// `V[d] = max_u theta_K[d, u]`.
    pub v: Vec<T>,
    /// The lowest-index `u` maximising `theta_K[d, u]`, per core.
    pub greedy: Vec<u32>,
    /// `||theta_k - theta_{k-1}||_inf` of every iteration (the first is `max |rho|`).
    pub deltas: Vec<f64>,
    /// `||V_k - V_{k-1}||_inf` of every iteration, `V_k = max_u theta_k`.
    pub v_deltas: Vec<f64>,
    /// Why it stopped.
    pub stop: Stop,
    /// Wall-clock seconds, the successor tables included.
    pub seconds: f64,
}

impl<T: Real> QSolution<T> {
    /// Number of iterations performed.
    #[must_use]
    pub fn iterations(&self) -> usize {
        self.deltas.len()
    }

    /// `Q(x, u) = sum_d mu_d(x) theta[d, u]` for every joint action `u`, written into `out`
    /// (length `M`): the Q-function the toolbox's crisp policy maximises.
    pub fn q_values(&self, grid: &Grid<T>, x: &[T], out: &mut [T]) -> Result<(), SolveError> {
        crate::error::check_len("q values", self.n_joint, out.len())?;
        let active = grid.view().active(x)?;
        out.fill(T::ZERO);
        let m = self.n_joint;
        active.for_each(|d, w| {
            for (o, &t) in out.iter_mut().zip(&self.theta[d * m..(d + 1) * m]) {
                *o += w * t;
            }
        });
        Ok(())
    }
}

/// Every (core, joint action)'s reward and successor memberships, row-major (from the
/// model's table where it gives one), and which cores are absorbing goals.
struct QTransitions<T> {
    /// Where each row's entries start in `entries` (one more than the rows).
    offsets: Vec<usize>,
    /// `(core, membership)` of the successors; none for a terminal successor.
    entries: Vec<(u32, T)>,
    rewards: Vec<T>,
    goal: Vec<bool>,
}

impl<T: Real> QTransitions<T> {
    fn tabulate<M: Model<T> + ?Sized>(
        model: &M,
        view: &ProductPartition<'_, T>,
        joint: &JointActions<'_, T>,
        config: &SolverConfig,
    ) -> Result<Self, SolveError> {
        let (n, m, e) = (view.n_cores(), joint.n_joint(), view.n_dims());
        let terminals = model.has_terminal_states();
        let table = model.tabulated();
        if let Some(t) = &table {
            crate::error::check_len("tabulated rewards", n * m, t.rewards.len())?;
            crate::error::check_len("tabulated next states", n * m * e, t.next_states.len())?;
        }
        // Successor memberships of every (core, joint action), row-major, and the rewards.
        let mut offsets = Vec::with_capacity(n * m + 1);
        let mut entries: Vec<(u32, T)> = Vec::with_capacity(n * m * 4);
        let mut rewards = Vec::with_capacity(n * m);
        let mut goal = Vec::with_capacity(n);
        let (mut x, mut next, mut u) = (
            vec![T::ZERO; e],
            vec![T::ZERO; e],
            vec![T::ZERO; joint.dim()],
        );
        offsets.push(0);
        for d in 0..n {
            view.core_state(d, &mut x)?;
            goal.push(config.absorbing_goal && model.is_goal(&x));
            for a in 0..m {
                let row = d * m + a;
                let r = match &table {
                    Some(t) => {
                        next.copy_from_slice(&t.next_states[row * e..(row + 1) * e]);
                        t.rewards[row]
                    }
                    None => {
                        joint.vector(a, &mut u)?;
                        model.step(&x, &u, &mut next);
                        model.reward(&x, &u)
                    }
                };
                if !r.is_finite() {
                    return Err(SolveError::Eval(EvalError::NotFinite {
                        what: "reward",
                        index: row,
                    }));
                }
                rewards.push(r);
                if !(terminals && model.is_terminal(&next)) {
                    view.active(&next)?
                        .for_each(|k, w| entries.push((k as u32, w)));
                }
                offsets.push(entries.len());
            }
        }
        Ok(Self {
            offsets,
            entries,
            rewards,
            goal,
        })
    }
}

/// Each row's maximum (`V`) and its lowest maximising column (the greedy action) of the
/// `m`-wide rows of `theta`.
fn maxima<T: Real>(theta: &[T], m: usize) -> (Vec<T>, Vec<u32>) {
    let n = theta.len() / m;
    let mut v = Vec::with_capacity(n);
    let mut greedy = Vec::with_capacity(n);
    for row in theta.chunks_exact(m) {
        let (mut best, mut arg) = (row[0], 0u32);
        for (a, &t) in row.iter().enumerate().skip(1) {
            if t > best {
                best = t;
                arg = a as u32;
            }
        }
        v.push(best);
        greedy.push(arg);
    }
    (v, greedy)
}

/// Runs Busoniu's fuzzy Q-iteration of `model` on `grid`, with `theta` stored.
///
/// [`solve`](super::solve) interpolates per-core maxima,
/// `theta[d, u] = rho + gamma sum_d' mu_d'(x') max_u' theta[d', u']`, which needs only `V`.
/// Busoniu et al. (Automatica 2010; the book of 2010, ch. 4; the ApproxRL toolbox's
/// `fuzzyqi`) maximise the interpolated Q-values instead,
/// `theta_k[d, u] = rho(x_d, u) + gamma max_u' sum_d' mu_d'(f(x_d, u)) theta_{k-1}[d', u']`.
/// Both are gamma-contractions; they agree where a successor's active cores share their
/// greedy action, and the first is larger elsewhere, so their fixed points differ. This
/// function iterates the second synchronously from `theta_0 = 0` and stops after the first
/// iteration with `||theta_k - theta_{k-1}||_inf <= xi`, as `fuzzyqi` does. It stores
/// `theta` and the successors' memberships (`cores x joint actions` rows of at most `2^E`
/// entries), so it suits grids of up to a few million Q-values. Terminal successors and
/// absorbing goal cores are handled as in [`solve`](super::solve); with the `parallel`
/// feature the cores of an iteration are split between threads (results do not depend on
/// the thread count).
///
/// Uses `config.gamma`, `xi`, `max_sweeps` (the iteration limit) and `absorbing_goal`; the
/// sweep mode, path, kernel and extrapolation do not apply. `observer` sees each iteration's
/// number and change and may stop the run ([`SolveError::Interrupted`]).
pub fn solve_q<T, M>(
    model: &M,
    grid: &Grid<T>,
    config: &SolverConfig,
    mut observer: impl FnMut(usize, f64) -> ControlFlow<()>,
) -> Result<QSolution<T>, SolveError>
where
    T: Real,
    M: Model<T> + ?Sized,
{
    config.validate()?;
    let start = Instant::now();
    let view = grid.view();
    if model.state_dim() != view.n_dims() {
        return Err(SolveError::StateDim {
            model: model.state_dim(),
            grid: view.n_dims(),
        });
    }
    let joint = joint_actions(model)?;
    let (n, m) = (view.n_cores(), joint.n_joint());
    super::generic::check_u32_cores(n, "grid of Q-iteration")?;
    let gamma = T::from_f64(config.gamma);
    if (0..model.n_blocks()).any(|b| model.block_rows(b).is_some()) {
        return Err(SolveError::BlockRowsOnly {
            what: "Q-iteration (Busoniu's operator)",
        });
    }
    let QTransitions {
        offsets,
        entries,
        rewards,
        goal,
    } = QTransitions::tabulate(model, &view, &joint, config)?;
    let mut theta = vec![T::ZERO; n * m];
    let mut new = vec![T::ZERO; n * m];
    let mut deltas = Vec::new();
    let mut v_deltas = Vec::new();
    let mut stop = Stop::SweepLimit;
    // One core's new row of theta; returns its largest change.
    let update = |d: usize, out: &mut [T], q: &mut [T], theta: &[T]| -> f64 {
        let mut delta = 0.0_f64;
        for (a, o) in out.iter_mut().enumerate() {
            let row = d * m + a;
            let mut value = rewards[row];
            let succ = &entries[offsets[row]..offsets[row + 1]];
            if !goal[d] && !succ.is_empty() {
                q.fill(T::ZERO);
                for &(i, w) in succ {
                    let base = i as usize * m;
                    for (qa, &t) in q.iter_mut().zip(&theta[base..base + m]) {
                        *qa += w * t;
                    }
                }
                let best = q.iter().copied().fold(q[0], T::max_of);
                value += gamma * best;
            }
            delta = delta.max((value - theta[row]).abs().to_f64());
            *o = value;
        }
        delta
    };
    #[cfg(not(feature = "parallel"))]
    let mut q = vec![T::ZERO; m];
    for k in 1..=config.max_sweeps {
        // Every core is computed by one task and the maximum is exact, so the result does
        // not depend on the thread count.
        #[cfg(feature = "parallel")]
        let delta = {
            use rayon::prelude::*;
            let theta = &theta;
            new.par_chunks_mut(m)
                .enumerate()
                .map_init(|| vec![T::ZERO; m], |q, (d, out)| update(d, out, q, theta))
                .reduce(|| 0.0, f64::max)
        };
        #[cfg(not(feature = "parallel"))]
        let delta = new
            .chunks_mut(m)
            .enumerate()
            .map(|(d, out)| update(d, out, &mut q, &theta))
            .fold(0.0, f64::max);
        let mut delta_v = 0.0_f64;
        for (rn, ro) in new.chunks_exact(m).zip(theta.chunks_exact(m)) {
            let vn = rn.iter().copied().fold(rn[0], T::max_of);
            let vo = ro.iter().copied().fold(ro[0], T::max_of);
            delta_v = delta_v.max((vn - vo).abs().to_f64());
        }
        core::mem::swap(&mut theta, &mut new);
        deltas.push(delta);
        v_deltas.push(delta_v);
        if observer(k, delta).is_break() {
            return Err(SolveError::Interrupted { sweeps: k });
        }
        if delta <= config.xi {
            stop = Stop::Converged;
            break;
        }
    }
    let (v, greedy) = maxima(&theta, m);
    Ok(QSolution {
        theta,
        n_joint: m,
        v,
        greedy,
        deltas,
        v_deltas,
        stop,
        seconds: start.elapsed().as_secs_f64(),
    })
}
