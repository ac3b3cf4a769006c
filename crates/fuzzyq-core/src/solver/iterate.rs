//! The iteration drivers over an [`Operator`]: value iteration (the paper's synchronous
//! sweeps, optionally extrapolated, or asynchronous ones) and modified policy iteration
//! ([`Scheme`]), their stopping rules and the passes over `V` between sweeps.

use core::ops::ControlFlow;
use std::time::Instant;
use std::vec::Vec;

use super::{
    Delta, Grid, Operator, Progress, Reduce, Scheme, Solution, SolveError, SolverConfig, Stop,
    SweepMode, SweepRecord, par,
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
    config.validate()?;
    let start = Instant::now();
    let run = prepare(model, grid, config)?;
    if run.scheme == Scheme::ModifiedPolicy {
        return modified_policy_iteration(&run, config, start, observer);
    }
    let Prepared { op, bound, .. } = run;
    let gamma = config.gamma;
    let mut records = Vec::new();
    let mut stop = Stop::SweepLimit;
    let mut final_delta = f64::NAN;

    let mut v_prev = op.zeros();
    let mut v_cur = op.zeros();
    let mut v_next = op.zeros();
    // Shift added to `v_cur` after it was computed (extrapolation), 0 if none.
    let mut shift_in = T::ZERO;
    // Absorbing goals and terminal successors break the shift property MacQueen's bounds
    // rest on (their rows of P sum to less than 1).
    let extrapolate = config.extrapolate
        && !config.absorbing_goal
        && !model.has_terminal_states()
        && config.gamma > 0.0;
    let mut sweep_seconds = 0.0;
    for sweep in 1..=config.max_sweeps {
        let t0 = Instant::now();
        let extrapolated = shift_in != T::ZERO;
        let (delta, delta_v, converged) = match config.sweep {
            SweepMode::Synchronous => {
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
            }
            SweepMode::Asynchronous => {
                let dv = op.sweep_async(&mut v_cur)?;
                sweep_seconds += t0.elapsed().as_secs_f64();
                (Delta::exact(dv), dv, dv <= config.xi)
            }
        };
        let record = SweepRecord {
            sweep,
            delta,
            delta_v,
            seconds: start.elapsed().as_secs_f64(),
            extrapolated,
            evaluation: false,
        };
        records.push(record);
        if converged {
            stop = Stop::Converged;
        }
        let flow = observer(&Progress {
            record,
            bound,
            xi: config.xi,
        });
        if let Some(d) = delta.value() {
            final_delta = d;
        }
        if converged {
            break;
        }
        if flow.is_break() {
            return Err(SolveError::Interrupted { sweeps: sweep });
        }
    }
    let last = records.last().expect("at least one sweep");
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
        seconds: start.elapsed().as_secs_f64(),
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
    mut observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Solution<T>, SolveError>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
{
    let op = &run.op;
    let gamma = config.gamma;
    let n = op.n_cores();
    let mut v = op.zeros();
    let mut next = op.zeros();
    let mut policy = vec![0u32; n];
    let mut pairs: Vec<(T, u32)> = vec![(T::ZERO, 0); n];
    let mut records: Vec<SweepRecord> = Vec::new();
    let mut stop = Stop::SweepLimit;
    let mut final_delta = f64::NAN;
    let mut sweep_seconds = 0.0;
    let mut evaluation_seconds = 0.0;
    let mut full = 0usize;
    // The greedy actions of the returned `V`, when the last full backup already gave them.
    let mut greedy: Option<Vec<u32>> = None;
    // Ends a sweep whose result is in `next`: moves it to the midpoint of MacQueen's bounds,
    // makes it `v` (the sweep's input is left in `next`), records the sweep and shows it to
    // the observer. Returns the half-span and the largest magnitude of the sweep's change,
    // and the observer's answer.
    let mut settle = |v: &mut Vec<T>,
                      next: &mut Vec<T>,
                      records: &mut Vec<SweepRecord>,
                      extrapolated: bool,
                      evaluation: bool| {
        let (dv, lo, hi) = diff_stats(next, v, T::ZERO);
        let half = 0.5 * (hi - lo);
        midpoint(next, gamma, lo, hi);
        core::mem::swap(v, next);
        let record = SweepRecord {
            sweep: records.len() + 1,
            delta: Delta::exact(half),
            delta_v: dv,
            seconds: start.elapsed().as_secs_f64(),
            extrapolated,
            evaluation,
        };
        records.push(record);
        let flow = observer(&Progress {
            record,
            bound: run.bound,
            xi: config.xi,
        });
        (half, dv, flow)
    };
    'outer: while full < config.max_sweeps {
        let t0 = Instant::now();
        if full == 0 {
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
        sweep_seconds += t0.elapsed().as_secs_f64();
        full += 1;
        let (half, change, flow) = settle(&mut v, &mut next, &mut records, full > 1, false);
        final_delta = half;
        if full > 1 && change <= gamma * config.xi {
            // The backup's input is already within `change / (1 - gamma)` of `V*`, at most
            // the guarantee, and `policy` is exactly its greedy policy: return it as it was
            // (`settle` left it in `next`) and skip the greedy pass.
            core::mem::swap(&mut v, &mut next);
            final_delta = change / gamma;
            stop = Stop::Converged;
            greedy = Some(core::mem::take(&mut policy));
            break;
        }
        if half <= config.xi {
            stop = Stop::Converged;
            break;
        }
        if flow.is_break() {
            return Err(SolveError::Interrupted {
                sweeps: records.len(),
            });
        }
        // The first policy is arbitrary (every action ties at V = 0): nothing to evaluate.
        let evaluations = if full == 1 {
            0
        } else {
            config.evaluation_sweeps
        };
        // Evaluation stops once it has cut the full backup's half-span tenfold, or below
        // xi / 2: beyond that the policy, not its evaluation, limits the next full backup.
        let eval_tol = (EVALUATION_PROGRESS * half).max(0.5 * config.xi);
        for _ in 0..evaluations {
            let t0 = Instant::now();
            op.evaluate(&v, &policy, &mut next);
            let dt = t0.elapsed().as_secs_f64();
            sweep_seconds += dt;
            evaluation_seconds += dt;
            let (half, _, flow) = settle(&mut v, &mut next, &mut records, true, true);
            if flow.is_break() {
                return Err(SolveError::Interrupted {
                    sweeps: records.len(),
                });
            }
            if half <= eval_tol {
                continue 'outer;
            }
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
        seconds: start.elapsed().as_secs_f64(),
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
