//! The iteration drivers over an [`Operator`]: value iteration (the paper's synchronous
//! sweeps, optionally extrapolated, or asynchronous ones) and modified policy iteration
//! ([`Scheme`]), their stopping rules and the passes over `V` between sweeps.

use core::ops::ControlFlow;
use std::time::Instant;
use std::vec::Vec;

use std::borrow::Cow;

use super::{
    Delta, Grid, Operator, Progress, Reduce, Scheme, Solution, SolveError, SolverConfig,
    SolverState, Stop, SweepMode, SweepRecord, par,
};
use crate::backup::Backup;
use crate::model::Model;
use crate::real::Real;

/// Elements per task of the passes over `V` between sweeps.
const PASS_CHUNK: usize = 1 << 16;

/// `(max |a - (b - s)|, min (a - b), max (a - b))`, in `f64`: maxima and minima, so the same
/// bits for any split over threads.
fn diff_stats<T: Real>(a: &[T], b: &[T], s: T) -> (f64, f64, f64) {
    let s = s.to_f64();
    par::map_reduce(
        a.len().min(b.len()),
        PASS_CHUNK,
        (0.0f64, f64::INFINITY, f64::NEG_INFINITY),
        |r| {
            a[r.clone()].iter().zip(&b[r]).fold(
                (0.0f64, f64::INFINITY, f64::NEG_INFINITY),
                |(m, lo, hi), (&x, &y)| {
                    let d = x.to_f64() - y.to_f64();
                    (m.max((d + s).abs()), lo.min(d), hi.max(d))
                },
            )
        },
        |x, y| (x.0.max(y.0), x.1.min(y.1), x.2.max(y.2)),
    )
}

fn max_abs_diff<T: Real>(a: &[T], b: &[T]) -> f64 {
    diff_stats(a, b, T::ZERO).0
}

/// Runs fuzzy Q-iteration on `model` over `grid` from `theta_0 = 0`.
///
/// `observer` sees every sweep and may stop the run (`ControlFlow::Break`), which returns
/// [`SolveError::Interrupted`].
pub fn solve<T, M>(
    model: &M,
    grid: &Grid<T>,
    config: &SolverConfig,
    mut observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Solution<T>, SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    solve_from(model, grid, config, None, |p, _| observer(p))
}

/// [`solve`], continued from `resume` (a state an earlier run of the same model, grid and
/// configuration showed its observer) or started afresh (`None`); the observer also sees the
/// run's state after every sweep that does not end it, which it may keep
/// ([`SolverState::into_owned`]) or store to continue later.
///
/// A run continued from the state after sweep `k` returns the same values, greedy actions and
/// sweep records (except their timings) as a run that was never stopped, bit for bit.
/// Errors: those of [`solve`], and [`SolveError::Resume`] when `resume` does not fit the run
/// (its scheme, sweep mode, core or action counts, or a run already over).
pub fn solve_from<T, M>(
    model: &M,
    grid: &Grid<T>,
    config: &SolverConfig,
    resume: Option<SolverState<'_, T>>,
    observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    config.validate()?;
    let start = Instant::now();
    let run = prepare(model, grid, config)?;
    if let Some(state) = &resume {
        check_resume(&run, config, state)?;
    }
    if run.scheme == Scheme::ModifiedPolicy {
        return modified_policy_iteration(&run, config, start, resume, observer);
    }
    value_iteration(
        run,
        config,
        model.has_terminal_states(),
        start,
        resume,
        observer,
    )
}

/// Refuses a state that does not continue a run of `run`'s operator under `config`.
fn check_resume<T, M>(
    run: &Prepared<'_, T, M>,
    config: &SolverConfig,
    s: &SolverState<'_, T>,
) -> Result<(), SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    let fail = |reason| Err(SolveError::Resume { reason });
    let n = run.op.n_cores();
    let mpi = run.scheme == Scheme::ModifiedPolicy;
    let sync = config.sweep == SweepMode::Synchronous && !mpi;
    if s.scheme != run.scheme {
        return fail("it was saved by a run of another iteration scheme");
    }
    if s.v.len() != n {
        return fail("its V has another number of cores");
    }
    if s.v_prev.len() != if sync { n } else { 0 } {
        return fail("it was saved by a run of another sweep mode");
    }
    if s.policy.len() != if mpi { n } else { 0 } {
        return fail("its policy has another number of cores");
    }
    let joint = run.op.joint().n_joint();
    if s.policy.iter().any(|&u| u as usize >= joint) {
        return fail("its policy names a joint action that does not exist");
    }
    if s.v
        .iter()
        .chain(s.v_prev.iter())
        .any(|x| !x.to_f64().is_finite())
    {
        return fail("its V is not finite");
    }
    let full = s.records.iter().filter(|r| !r.evaluation).count();
    let numbered = s.records.iter().enumerate().all(|(i, r)| r.sweep == i + 1);
    if s.records.is_empty() || !numbered {
        return fail("its sweep records are not numbered 1, 2, ...");
    }
    if full >= config.max_sweeps && s.evaluations_left == 0 {
        return fail("its run already reached the sweep limit");
    }
    if !mpi && (s.evaluations_left != 0 || s.records.iter().any(|r| r.evaluation)) {
        return fail("it holds evaluation sweeps, which value iteration does not run");
    }
    Ok(())
}

/// [`Scheme::Value`]: synchronous (optionally extrapolated) or asynchronous sweeps, each a
/// full backup, stopped by the paper's rule.
fn value_iteration<T, M>(
    run: Prepared<'_, T, M>,
    config: &SolverConfig,
    terminal_states: bool,
    start: Instant,
    resume: Option<SolverState<'_, T>>,
    mut observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    let Prepared { op, bound, .. } = run;
    let gamma = config.gamma;
    let mut stop = Stop::SweepLimit;
    let mut v_next = op.zeros();
    // `v_cur` is V_k; `v_prev` V_{k-1} (synchronous sweeps only); `shift_in` the constant
    // added to `v_cur` after it was computed (extrapolation), 0 if none.
    let (mut v_prev, mut v_cur, mut shift_in, mut records, mut final_delta, mut sweep_seconds) =
        match resume {
            Some(s) => (
                if s.v_prev.is_empty() {
                    op.zeros()
                } else {
                    s.v_prev.into_owned()
                },
                s.v.into_owned(),
                T::from_f64(s.shift),
                s.records.into_owned(),
                s.final_delta,
                s.sweep_seconds,
            ),
            None => (op.zeros(), op.zeros(), T::ZERO, Vec::new(), f64::NAN, 0.0),
        };
    let offset = records.last().map_or(0.0, |r| r.seconds);
    let synchronous = config.sweep == SweepMode::Synchronous;
    // Absorbing goals and terminal successors break the shift property MacQueen's bounds
    // rest on (their rows of P sum to less than 1).
    let extrapolate =
        config.extrapolate && !config.absorbing_goal && !terminal_states && config.gamma > 0.0;
    for sweep in records.len() + 1..=config.max_sweeps {
        let t0 = Instant::now();
        let extrapolated = shift_in != T::ZERO;
        let (delta, delta_v, converged) = if synchronous {
            op.sweep_sync(&v_cur, &mut v_next)?;
            sweep_seconds += t0.elapsed().as_secs_f64();
            // max theta_k = v_cur - shift_in; theta_k = rho + gamma P v_prev and
            // theta_{k+1} = rho + gamma P v_cur, so
            // ||V_{k+1} - (v_cur - s)|| <= ||theta_{k+1} - theta_k|| <= gamma ||v_cur - v_prev||.
            let (dv, lo, hi) = diff_stats(&v_next, &v_cur, shift_in);
            let testable = shift_in == T::ZERO;
            let delta = if sweep == 1 {
                Delta::exact(op.reward_bound())
            } else {
                let lower = dv;
                let upper = gamma * max_abs_diff(&v_cur, &v_prev);
                if testable && lower <= config.xi && config.xi < upper {
                    Delta::exact(exact_delta(&op, &v_cur, &v_prev)?)
                } else {
                    Delta { lower, upper }
                }
            };
            let converged = testable && delta.upper <= config.xi;
            // Extrapolate after a testable sweep that did not converge: MacQueen's bounds
            // V* in V_{k+1} + gamma/(1-gamma) [min dV, max dV] hold because the operator
            // commutes with constant shifts (T(V + c) = T(V) + gamma c); move to their
            // midpoint.
            shift_in = T::ZERO;
            if extrapolate && testable && !converged {
                shift_in = midpoint(&mut v_next, gamma, lo, hi);
            }
            core::mem::swap(&mut v_prev, &mut v_cur);
            core::mem::swap(&mut v_cur, &mut v_next);
            (delta, dv, converged)
        } else {
            let dv = op.sweep_async(&mut v_cur)?;
            sweep_seconds += t0.elapsed().as_secs_f64();
            (Delta::exact(dv), dv, dv <= config.xi)
        };
        let record = SweepRecord {
            sweep,
            delta,
            delta_v,
            seconds: offset + start.elapsed().as_secs_f64(),
            extrapolated,
            evaluation: false,
        };
        records.push(record);
        if let Some(d) = delta.value() {
            final_delta = d;
        }
        let done = converged || sweep == config.max_sweeps;
        let state = (!done).then(|| SolverState {
            scheme: Scheme::Value,
            v: Cow::Borrowed(&v_cur[..]),
            v_prev: Cow::Borrowed(if synchronous { &v_prev[..] } else { &[] }),
            policy: Cow::Borrowed(&[][..]),
            shift: shift_in.to_f64(),
            evaluations_left: 0,
            evaluation_tolerance: 0.0,
            final_delta,
            sweep_seconds,
            evaluation_seconds: 0.0,
            records: Cow::Borrowed(&records[..]),
        });
        let flow = observer(
            &Progress {
                record,
                bound,
                xi: config.xi,
            },
            state.as_ref(),
        );
        if converged {
            stop = Stop::Converged;
            break;
        }
        if flow.is_break() && !done {
            return Err(SolveError::Interrupted { sweeps: sweep });
        }
    }
    let last = records.last().ok_or(SolveError::MaxSweeps)?;
    if last.delta.value().is_none() {
        // Converged (or stopped) on the bounds: report the exact final change. After the
        // rotation `v_cur = V_K`, `v_prev = V_{K-1}`, `v_next = V_{K-2}`, and
        // `theta_K - theta_{K-1} = gamma P (V_{K-1} - V_{K-2})`.
        final_delta = exact_delta(&op, &v_prev, &v_next)?;
    }
    let mut greedy = vec![0u32; op.n_cores()];
    op.greedy_internal(&v_cur, &mut greedy)?;
    Ok(Solution {
        v: op.to_grid(&v_cur),
        greedy: op.to_grid(&greedy),
        sweeps: records,
        scheme: Scheme::Value,
        stop,
        final_delta,
        bound,
        reward_bound: op.reward_bound(),
        path: op.path(),
        kernel: op.kernel(),
        multiply_adds_per_sweep: op.multiply_adds_per_sweep(),
        sweep_seconds,
        evaluation_seconds: 0.0,
        seconds: offset + start.elapsed().as_secs_f64(),
    })
}

/// The operator of a run and how it will iterate.
struct Prepared<'a, T: Real, M: ?Sized> {
    op: Operator<'a, T, M>,
    bound: usize,
    scheme: Scheme,
}

fn prepare<'a, T, M>(
    model: &'a M,
    grid: &'a Grid<T>,
    config: &SolverConfig,
) -> Result<Prepared<'a, T, M>, SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    let backup = Backup {
        gamma: T::from_f64(config.gamma),
        absorbing_goal: config.absorbing_goal,
    };
    let mut op = Operator::new(model, grid.view(), backup, config.path)?;
    if let Some(k) = config.kernel {
        op = op.with_kernel(k)?;
    }
    let bound = config.sweep_bound(op.reward_bound());
    let mpi = config.evaluation_sweeps > 0
        && config.extrapolate
        && config.sweep == SweepMode::Synchronous
        && !config.absorbing_goal
        && !model.has_terminal_states()
        && config.gamma > 0.0
        && op.can_evaluate();
    Ok(Prepared {
        op,
        bound,
        scheme: if mpi {
            Scheme::ModifiedPolicy
        } else {
            Scheme::Value
        },
    })
}

/// Evaluation sweeps after a full backup stop once they have cut its half-span by this factor
/// (measured on the paper's grid: 0.1 and 0.2 give the same sweeps within 5%).
const EVALUATION_PROGRESS: f64 = 0.1;

/// Moves `v` to the midpoint of MacQueen's bounds after a sweep whose change `v - prev` lies
/// in `[lo, hi]`: adds `gamma/(1-gamma) (lo + hi)/2`, and returns that shift.
fn midpoint<T: Real>(v: &mut [T], gamma: f64, lo: f64, hi: f64) -> T {
    let s = T::from_f64(gamma / (1.0 - gamma) * 0.5 * (lo + hi));
    if s != T::ZERO {
        par::for_each_chunk_mut(
            v,
            PASS_CHUNK,
            || (),
            |_, _, c| {
                for x in c {
                    *x += s;
                }
            },
        );
    }
    s
}

/// [`Scheme::ModifiedPolicy`]: full backups recording the greedy actions, each followed by
/// evaluation sweeps under them, every sweep extrapolated; the span rule on full backups.
fn modified_policy_iteration<T, M>(
    run: &Prepared<'_, T, M>,
    config: &SolverConfig,
    start: Instant,
    resume: Option<SolverState<'_, T>>,
    mut observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    let op = &run.op;
    let gamma = config.gamma;
    let n = op.n_cores();
    let mut next = op.zeros();
    let mut pairs: Vec<(T, u32)> = vec![(T::ZERO, 0); n];
    let mut stop = Stop::SweepLimit;
    // `policy`: the greedy actions of the last full backup; `evaluations_left`: evaluation
    // sweeps still allowed under it (0: a full backup is next), until the half-span falls to
    // `eval_tol`.
    let (mut v, mut policy, mut records, mut final_delta) =
        (op.zeros(), vec![0u32; n], vec![], f64::NAN);
    let (mut evaluations_left, mut eval_tol, mut sweep_seconds, mut evaluation_seconds) =
        (0usize, 0.0f64, 0.0f64, 0.0f64);
    if let Some(s) = resume {
        (v, policy, records, final_delta) = (
            s.v.into_owned(),
            s.policy.into_owned(),
            s.records.into_owned(),
            s.final_delta,
        );
        (evaluations_left, eval_tol) = (s.evaluations_left, s.evaluation_tolerance);
        (sweep_seconds, evaluation_seconds) = (s.sweep_seconds, s.evaluation_seconds);
    }
    let offset = records.last().map_or(0.0, |r| r.seconds);
    let mut full = records.iter().filter(|r| !r.evaluation).count();
    // The greedy actions of the returned `V`, when the last full backup already gave them.
    let mut greedy: Option<Vec<u32>> = None;
    loop {
        let evaluation = evaluations_left > 0;
        if !evaluation && full >= config.max_sweeps {
            break;
        }
        let t0 = Instant::now();
        if evaluation {
            op.evaluate(&v, &policy, &mut next);
        } else if full == 0 {
            // From V = 0 every expected value is 0: T(0) = rho exactly, and every action
            // ties (the lowest, 0, is greedy). No pass needed.
            for (i, o) in next.iter_mut().enumerate() {
                *o = op.finish_max(i, T::ZERO);
            }
        } else {
            op.each_core(&v, &mut pairs, Reduce::Argmax, |r| r)?;
            for ((o, p), &(x, u)) in next.iter_mut().zip(policy.iter_mut()).zip(&pairs) {
                *o = x;
                *p = u;
            }
        }
        let dt = t0.elapsed().as_secs_f64();
        sweep_seconds += dt;
        if evaluation {
            evaluation_seconds += dt;
        }
        // Move the sweep's result to the midpoint of MacQueen's bounds and make it `v` (the
        // sweep's input stays in `next`).
        let (change, lo, hi) = diff_stats(&next, &v, T::ZERO);
        let half = 0.5 * (hi - lo);
        midpoint(&mut next, gamma, lo, hi);
        core::mem::swap(&mut v, &mut next);
        let record = SweepRecord {
            sweep: records.len() + 1,
            delta: Delta::exact(half),
            delta_v: change,
            seconds: offset + start.elapsed().as_secs_f64(),
            extrapolated: evaluation || full > 0,
            evaluation,
        };
        records.push(record);
        let mut converged = false;
        if evaluation {
            // Evaluation stops once it has cut the full backup's half-span tenfold, or below
            // xi / 2: beyond that the policy, not its evaluation, limits the next full backup.
            evaluations_left = if half <= eval_tol {
                0
            } else {
                evaluations_left - 1
            };
        } else {
            full += 1;
            final_delta = half;
            if full > 1 && change <= gamma * config.xi {
                // The backup's input is already within `change / (1 - gamma)` of `V*`, at
                // most the guarantee, and `policy` is exactly its greedy policy: return it as
                // it was (left in `next`) and skip the greedy pass.
                core::mem::swap(&mut v, &mut next);
                final_delta = change / gamma;
                greedy = Some(core::mem::take(&mut policy));
                converged = true;
            } else if half <= config.xi {
                converged = true;
            } else if full > 1 {
                // (The first policy is arbitrary: every action ties at V = 0.)
                evaluations_left = config.evaluation_sweeps;
                eval_tol = (EVALUATION_PROGRESS * half).max(0.5 * config.xi);
            }
        }
        let done = converged || (evaluations_left == 0 && full >= config.max_sweeps);
        let state = (!done).then(|| SolverState {
            scheme: Scheme::ModifiedPolicy,
            v: Cow::Borrowed(&v[..]),
            v_prev: Cow::Borrowed(&[][..]),
            policy: Cow::Borrowed(&policy[..]),
            shift: 0.0,
            evaluations_left,
            evaluation_tolerance: eval_tol,
            final_delta,
            sweep_seconds,
            evaluation_seconds,
            records: Cow::Borrowed(&records[..]),
        });
        let flow = observer(
            &Progress {
                record,
                bound: run.bound,
                xi: config.xi,
            },
            state.as_ref(),
        );
        if converged {
            stop = Stop::Converged;
            break;
        }
        if flow.is_break() && !done {
            return Err(SolveError::Interrupted {
                sweeps: records.len(),
            });
        }
    }
    let greedy = match greedy {
        Some(g) => g,
        None => {
            let mut g = vec![0u32; n];
            op.greedy_internal(&v, &mut g)?;
            g
        }
    };
    Ok(Solution {
        v: op.to_grid(&v),
        greedy: op.to_grid(&greedy),
        sweeps: records,
        scheme: Scheme::ModifiedPolicy,
        stop,
        final_delta,
        bound: run.bound,
        reward_bound: op.reward_bound(),
        path: op.path(),
        kernel: op.kernel(),
        multiply_adds_per_sweep: op.multiply_adds_per_sweep(),
        sweep_seconds,
        evaluation_seconds,
        seconds: offset + start.elapsed().as_secs_f64(),
    })
}

/// `||theta_{k+1} - theta_k||_inf = gamma ||P (V_k - V_{k-1})||_inf` (goal cores excluded when
/// absorbing: their theta does not change).
fn exact_delta<T: Real, M: Model<T> + Sync + ?Sized>(
    op: &Operator<'_, T, M>,
    v_k: &[T],
    v_km1: &[T],
) -> Result<f64, SolveError> {
    let dv: Vec<T> = v_k.iter().zip(v_km1).map(|(&a, &b)| a - b).collect();
    Ok(op.abs_max(&dv)?.to_f64())
}
