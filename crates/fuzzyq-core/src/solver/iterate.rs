//! The iteration drivers over an [`Operator`]: value iteration (the paper's synchronous
//! sweeps, optionally extrapolated, or asynchronous ones) and modified policy iteration
//! ([`Scheme`]), their stopping rules and the passes over `V` between sweeps, which a
//! [`Sweeps`] backend runs.

use core::ops::ControlFlow;
use std::time::Instant;
use std::vec::Vec;

use std::borrow::Cow;

use super::sweeps::{Buf, Local, Sweeps};
use super::{
    CoarseStart, Delta, Grid, Operator, Progress, Scheme, Solution, SolveError, SolverConfig,
    SolverState, Stop, SweepMode, SweepRecord,
};
use crate::backup::Backup;
use crate::model::Model;
use crate::real::Real;

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
    let mut sweeps = Local::new(&run.op);
    let coarse = coarse_start(
        &run,
        (grid, config),
        &resume,
        &mut sweeps,
        solve_locally(model),
    )?;
    drive(
        &run,
        config,
        &mut sweeps,
        start,
        resume,
        coarse,
        true,
        observer,
    )
}

/// [`solve_from`] with the passes over `V` run by `sweeps` (a backend whose three value
/// buffers and policy buffer all start at 0), for example one holding `V` in shards on other
/// machines. The driver builds the operator here only for the run's scalars (its reward
/// bound, the scheme it can run, the grid order of the result); the result is
/// [`solve_from`]'s, bit for bit, when `sweeps` computes every pass as [`Local`] does.
///
/// With `show_state` false the observer is never shown a state (which would read every value
/// of the backend after each sweep).
pub fn solve_on<T, M, S>(
    model: &M,
    grid: &Grid<T>,
    config: &SolverConfig,
    sweeps: &mut S,
    resume: Option<SolverState<'_, T>>,
    show_state: bool,
    observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, S::Error>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
    S: Sweeps<T>,
{
    config.validate()?;
    let start = Instant::now();
    let run = prepare(model, grid, config)?;
    let coarse = coarse_start(&run, (grid, config), &resume, sweeps, solve_locally(model))?;
    drive(
        &run, config, sweeps, start, resume, coarse, show_state, observer,
    )
}

impl Scheme {
    /// The value buffers the scheme's driver asks a [`Sweeps`] backend for: `Buf(0)` up to
    /// `Buf(n - 1)` (value iteration keeps the previous `V` beside the current one and the
    /// sweep's output; modified policy iteration only the current one and the output). A
    /// backend may hold just these (a GPU's memory).
    #[must_use]
    pub fn value_buffers(self) -> u8 {
        match self {
            Scheme::Value => 3,
            Scheme::ModifiedPolicy => 2,
        }
    }

    /// Whether the scheme's driver asks for [`Sweeps::exact_delta`] (value iteration's exact
    /// stopping rule), for which a backend may hold work buffers.
    #[must_use]
    pub fn uses_exact_delta(self) -> bool {
        self == Scheme::Value
    }
}

/// Builds a [`Sweeps`] backend for a prepared operator and the scheme the run will iterate
/// by ([`solve_with`]; [`Scheme::value_buffers`] says what the scheme asks of a backend).
/// `Send`: a coarse start's backend is made on another thread of the pool.
pub type MakeSweeps<'m, T, M, S> =
    dyn FnMut(&super::Operator<'_, T, M>, Scheme) -> Result<S, <S as Sweeps<T>>::Error> + Send + 'm;

/// [`solve_from`] with the passes over `V` run by a backend that `make` builds from the run's
/// operator (a GPU holding its own copy of the block tables, say): the operator is prepared
/// once, and a coarse start ([`SolverConfig::coarse_start`]) is solved by a backend `make`
/// builds for the coarse grid's operator. The result is [`solve_from`]'s, bit for bit, when
/// every backend computes each pass as [`Local`] does. With `show_state` false the observer
/// is never shown a state (which would read every value of the backend after each sweep).
///
/// A fresh run that may take a coarse start solves it on another thread of the caller's pool
/// while this one prepares the run's operator (the rewards and block tables: the CPU's part
/// of the set-up), so that a backend on a device runs the coarse sweeps beside that
/// preparation instead of after it; `make` builds the run's own backend once the coarse
/// start is over. Where the operator turns out to take no coarse start (it cannot evaluate a
/// policy), the coarse solve is dropped.
pub fn solve_with<T, M, S>(
    model: &M,
    grid: &Grid<T>,
    config: &SolverConfig,
    resume: Option<SolverState<'_, T>>,
    show_state: bool,
    make: &mut MakeSweeps<'_, T, M, S>,
    observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, S::Error>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
    S: Sweeps<T>,
    S::Error: Send,
{
    config.validate()?;
    let start = Instant::now();
    let coarse_grid = (resume.is_none() && may_start_coarse(model, config))
        .then(|| grid.coarsened())
        .flatten();
    // The preparation here, the coarse solve (without a coarse start of its own) taken by
    // another thread of the pool; each notes when it ended.
    let make_coarse = &mut *make;
    let ((run, prepared), beside) = super::par::join(
        || (prepare(model, grid, config), Instant::now()),
        || {
            coarse_grid.as_ref().map(|coarse| {
                let config = SolverConfig {
                    coarse_start: false,
                    ..*config
                };
                // A function pointer for its observer, not a closure: the recursive call
                // instantiates this function once more, not once per nesting.
                let noop: fn(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()> =
                    |_, _| ControlFlow::Continue(());
                let solved = solve_with(model, coarse, &config, None, false, make_coarse, noop);
                (solved, Instant::now())
            })
        },
    );
    let run = run?;
    let mut sweeps = make(&run.op, run.scheme)?;
    // A run that takes a coarse start had it solved beside its preparation (`run.coarse` is
    // `Some` only where `coarse_grid` is, the same grid); its seconds are those the run
    // waited for it beyond the preparation, and its interpolation.
    let coarse = match beside {
        Some((solved, at)) => coarse_start(&run, (grid, config), &resume, &mut sweeps, |_, _| {
            solved
        })?
        .map(|c| CoarseStart {
            seconds: c.seconds + at.saturating_duration_since(prepared).as_secs_f64(),
            ..c
        }),
        None => {
            debug_assert!(
                run.coarse.is_none() || resume.is_some(),
                "a coarse start unsolved"
            );
            None
        }
    };
    drive(
        &run,
        config,
        &mut sweeps,
        start,
        resume,
        coarse,
        show_state,
        observer,
    )
}

/// The coarse start of a fresh run of `run` ([`SolverConfig::coarse_start`]): the same scheme
/// on [`Prepared::coarse`] (without a coarse start of its own), solved by `solve_coarse`, its
/// `V` interpolated onto `grid` and loaded into `sweeps`'s first buffer.
fn coarse_start<T, M, S>(
    run: &Prepared<'_, T, M>,
    (grid, config): (&Grid<T>, &SolverConfig),
    resume: &Option<SolverState<'_, T>>,
    sweeps: &mut S,
    solve_coarse: impl FnOnce(&Grid<T>, &SolverConfig) -> Result<Solution<T>, S::Error>,
) -> Result<Option<CoarseStart>, S::Error>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
    S: Sweeps<T>,
{
    let Some(coarse) = run.coarse.as_ref().filter(|_| resume.is_none()) else {
        return Ok(None);
    };
    let start = Instant::now();
    let config = SolverConfig {
        coarse_start: false,
        ..*config
    };
    let s = solve_coarse(coarse, &config)?;
    let v = grid.interpolated_from(coarse, &s.v)?;
    sweeps.load(Buf(0), &run.op.to_internal(&v))?;
    Ok(Some(CoarseStart {
        cores: coarse.n_cores(),
        sweeps: s.sweeps.len(),
        seconds: start.elapsed().as_secs_f64(),
    }))
}

/// The CPU solve of a coarse start.
fn solve_locally<T: Real, M: Model<T> + Sync + ?Sized, E: From<SolveError>>(
    model: &M,
) -> impl FnOnce(&Grid<T>, &SolverConfig) -> Result<Solution<T>, E> {
    move |g, c| Ok(solve(model, g, c, |_| ControlFlow::Continue(()))?)
}

/// Checks `resume`, loads it into `sweeps` and runs the scheme of `run` (from the coarse
/// start's `V`, already in `sweeps`, when `coarse` is set).
#[allow(clippy::too_many_arguments)] // the run, its backend, and how it starts
fn drive<T, M, S>(
    run: &Prepared<'_, T, M>,
    config: &SolverConfig,
    sweeps: &mut S,
    start: Instant,
    resume: Option<SolverState<'_, T>>,
    coarse: Option<CoarseStart>,
    show_state: bool,
    observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, S::Error>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
    S: Sweeps<T>,
{
    if let Some(state) = &resume {
        check_resume(run, config, state)?;
    }
    // Everything so far but the coarse start: the operator and the backend.
    let setup_seconds =
        (start.elapsed().as_secs_f64() - coarse.as_ref().map_or(0.0, |c| c.seconds)).max(0.0);
    let mut d = Driver {
        run,
        config,
        sweeps,
        start,
        setup_seconds,
        show_state,
        coarse,
    };
    if run.scheme == Scheme::ModifiedPolicy {
        return d.modified_policy_iteration(resume, observer);
    }
    d.value_iteration(resume, observer)
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
    let numbered = s.records.iter().enumerate().all(|(i, r)| r.sweep == i + 1);
    if s.records.is_empty() || !numbered {
        return fail("its sweep records are not numbered 1, 2, ...");
    }
    if s.records.len() >= config.max_sweeps {
        return fail("its run already reached the sweep limit");
    }
    if !mpi && (s.evaluations_left != 0 || s.records.iter().any(|r| r.evaluation)) {
        return fail("it holds evaluation sweeps, which value iteration does not run");
    }
    Ok(())
}

/// A run in progress: its operator and settings, its backend, and the records so far.
struct Driver<'r, 'a, T: Real, M: ?Sized, S> {
    run: &'r Prepared<'a, T, M>,
    config: &'r SolverConfig,
    sweeps: &'r mut S,
    start: Instant,
    /// Seconds from `start` to the first sweep, without the coarse start.
    setup_seconds: f64,
    show_state: bool,
    /// The run's coarse start, if it had one.
    coarse: Option<CoarseStart>,
}

/// `(shift, lo, hi)` of MacQueen's bounds after a sweep whose change lies in `[lo, hi]`:
/// the shift `gamma/(1-gamma) (lo + hi)/2` to their midpoint.
fn midpoint<T: Real>(gamma: f64, lo: f64, hi: f64) -> T {
    T::from_f64(gamma / (1.0 - gamma) * 0.5 * (lo + hi))
}

/// Evaluation sweeps after a full backup stop once they have cut its half-span by this factor
/// (measured on the paper's grid: 0.1 and 0.2 give the same sweeps within 5%).
const EVALUATION_PROGRESS: f64 = 0.1;

impl<T, M, S> Driver<'_, '_, T, M, S>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
    S: Sweeps<T>,
{
    /// The result of a run whose values are in `v` and whose greedy actions are in the
    /// policy buffer.
    fn solution(
        &self,
        v: Buf,
        records: Vec<SweepRecord>,
        stop: Stop,
        final_delta: f64,
        seconds: (f64, f64, f64),
    ) -> Result<Solution<T>, S::Error> {
        let op = &self.run.op;
        let (offset, sweep_seconds, evaluation_seconds) = seconds;
        let t0 = Instant::now();
        let values = super::sweeps::grid_order(op, |each| self.sweeps.values_by_piece(v, each))?;
        let greedy = super::sweeps::grid_order(op, |each| self.sweeps.policy_by_piece(each))?;
        let result_seconds = t0.elapsed().as_secs_f64();
        Ok(Solution {
            v: values,
            greedy,
            sweeps: records,
            scheme: self.run.scheme,
            stop,
            final_delta,
            bound: self.run.bound,
            reward_bound: op.reward_bound(),
            path: op.path(),
            kernel: self.sweeps.kernel().unwrap_or_else(|| op.kernel()),
            multiply_adds_per_sweep: op.multiply_adds_per_sweep(),
            sweep_seconds,
            evaluation_seconds,
            seconds: offset + self.start.elapsed().as_secs_f64(),
            setup_seconds: Some(self.setup_seconds),
            result_seconds: Some(result_seconds),
            coarse: self.coarse,
        })
    }

    /// [`Scheme::Value`]: synchronous (optionally extrapolated) or asynchronous sweeps, each a
    /// full backup, stopped by the paper's rule.
    fn value_iteration(
        &mut self,
        resume: Option<SolverState<'_, T>>,
        mut observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
    ) -> Result<Solution<T>, S::Error> {
        let config = self.config;
        let gamma = config.gamma;
        let mut stop = Stop::SweepLimit;
        // `cur` holds V_k; `prev` V_{k-1} (synchronous sweeps only); `next` the sweep's
        // output; `shift_in` the constant added to `cur` after it was computed
        // (extrapolation), 0 if none.
        let (mut prev, mut cur, mut next) = (Buf(0), Buf(1), Buf(2));
        let (mut shift_in, mut records, mut final_delta, mut sweep_seconds) =
            (T::ZERO, Vec::new(), f64::NAN, 0.0);
        if let Some(s) = resume {
            if !s.v_prev.is_empty() {
                self.sweeps.load(prev, &s.v_prev)?;
            }
            self.sweeps.load(cur, &s.v)?;
            shift_in = T::from_f64(s.shift);
            records = s.records.into_owned();
            (final_delta, sweep_seconds) = (s.final_delta, s.sweep_seconds);
        }
        let offset = records.last().map_or(0.0, |r| r.seconds);
        let synchronous = config.sweep == SweepMode::Synchronous;
        for sweep in records.len() + 1..=config.max_sweeps {
            let t0 = Instant::now();
            let extrapolated = shift_in != T::ZERO;
            let (delta, delta_v, converged) = if synchronous {
                self.sweeps.backup(cur, next)?;
                sweep_seconds += t0.elapsed().as_secs_f64();
                // max theta_k = cur - shift_in; theta_k = rho + gamma P prev and
                // theta_{k+1} = rho + gamma P cur, so
                // ||V_{k+1} - (cur - s)|| <= ||theta_{k+1} - theta_k|| <= gamma ||cur - prev||.
                let d = self.sweeps.diff_stats(next, cur, shift_in)?;
                let testable = shift_in == T::ZERO;
                let delta = if sweep == 1 {
                    Delta::exact(self.run.op.reward_bound())
                } else {
                    let lower = d.change;
                    let upper = gamma * self.sweeps.diff_stats(cur, prev, T::ZERO)?.change;
                    if testable && lower <= config.xi && config.xi < upper {
                        Delta::exact(self.sweeps.exact_delta(cur, prev)?)
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
                if self.run.extrapolate && testable && !converged {
                    shift_in = midpoint(gamma, d.lo, d.hi);
                    if shift_in != T::ZERO {
                        self.sweeps.shift(next, shift_in)?;
                    }
                }
                (prev, cur, next) = (cur, next, prev);
                (delta, d.change, converged)
            } else {
                let dv = self.sweeps.sweep_async(cur)?;
                sweep_seconds += t0.elapsed().as_secs_f64();
                (Delta::exact(dv), dv, dv <= config.xi)
            };
            let record = SweepRecord {
                sweep,
                delta,
                delta_v,
                seconds: offset + self.start.elapsed().as_secs_f64(),
                extrapolated,
                evaluation: false,
            };
            records.push(record);
            if let Some(d) = delta.value() {
                final_delta = d;
            }
            let done = converged || sweep == config.max_sweeps;
            let flow = if self.show_state && !done {
                let state = SolverState {
                    scheme: Scheme::Value,
                    v: self.sweeps.values(cur)?,
                    v_prev: if synchronous {
                        self.sweeps.values(prev)?
                    } else {
                        Cow::Borrowed(&[][..])
                    },
                    policy: Cow::Borrowed(&[][..]),
                    shift: shift_in.to_f64(),
                    evaluations_left: 0,
                    evaluation_tolerance: 0.0,
                    final_delta,
                    sweep_seconds,
                    evaluation_seconds: 0.0,
                    records: Cow::Borrowed(&records[..]),
                };
                observer(&self.progress(record), Some(&state))
            } else {
                observer(&self.progress(record), None)
            };
            if converged {
                stop = Stop::Converged;
                break;
            }
            if flow.is_break() && !done {
                return Err(SolveError::Interrupted { sweeps: sweep }.into());
            }
        }
        let last = records.last().ok_or(SolveError::MaxSweeps)?;
        if last.delta.value().is_none() {
            // Converged (or stopped) on the bounds: report the exact final change. After the
            // rotation `cur = V_K`, `prev = V_{K-1}`, `next = V_{K-2}`, and
            // `theta_K - theta_{K-1} = gamma P (V_{K-1} - V_{K-2})`.
            final_delta = self.sweeps.exact_delta(prev, next)?;
        }
        self.sweeps.greedy(cur)?;
        self.solution(
            cur,
            records,
            stop,
            final_delta,
            (offset, sweep_seconds, 0.0),
        )
    }

    /// The progress report of a sweep.
    fn progress(&self, record: SweepRecord) -> Progress {
        let mpi = self.run.scheme == Scheme::ModifiedPolicy;
        Progress {
            record,
            bound: self.run.bound,
            xi: self.config.xi,
            scheme: self.run.scheme,
            extrapolate: self.run.extrapolate
                && (mpi || self.config.sweep == SweepMode::Synchronous),
            coarse: self.coarse,
        }
    }

    /// [`Scheme::ModifiedPolicy`]: full backups recording the greedy actions, each followed
    /// by evaluation sweeps under them, every sweep extrapolated; the span rule on full
    /// backups.
    fn modified_policy_iteration(
        &mut self,
        resume: Option<SolverState<'_, T>>,
        mut observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
    ) -> Result<Solution<T>, S::Error> {
        let config = self.config;
        let gamma = config.gamma;
        let (mut v, mut next) = (Buf(0), Buf(1));
        let mut stop = Stop::SweepLimit;
        // The policy buffer: the greedy actions of the last full backup; `evaluations_left`:
        // evaluation sweeps still allowed under it (0: a full backup is next), until the
        // half-span falls to `eval_tol`.
        let (mut records, mut final_delta) = (Vec::new(), f64::NAN);
        let (mut evaluations_left, mut eval_tol, mut sweep_seconds, mut evaluation_seconds) =
            (0usize, 0.0f64, 0.0f64, 0.0f64);
        if let Some(s) = resume {
            self.sweeps.load(v, &s.v)?;
            self.sweeps.load_policy(&s.policy)?;
            (records, final_delta) = (s.records.into_owned(), s.final_delta);
            (evaluations_left, eval_tol) = (s.evaluations_left, s.evaluation_tolerance);
            (sweep_seconds, evaluation_seconds) = (s.sweep_seconds, s.evaluation_seconds);
        }
        let offset = records.last().map_or(0.0, |r| r.seconds);
        let mut full = records.iter().filter(|r| !r.evaluation).count();
        // From `V = 0` every action ties at the first full backup, so its policy is not worth
        // evaluating; from a coarse start's `V` it is. (A continued run decides the same way:
        // from its configuration, not from whether it started coarse this time.)
        let first_policy = usize::from(self.run.coarse.is_none());
        // Whether the policy buffer already holds the greedy actions of the returned `V`.
        let mut greedy_known = false;
        // Every sweep, of either kind, counts against `max_sweeps`; the last one allowed is a
        // full backup, so that a run cut short still ends on MacQueen's bound.
        while records.len() < config.max_sweeps {
            let last = records.len() + 1 == config.max_sweeps;
            let evaluation = evaluations_left > 0 && !last;
            let t0 = Instant::now();
            if evaluation {
                self.sweeps.evaluate(v, next)?;
            } else if full == 0 && self.coarse.is_none() {
                // From V = 0 every expected value is 0: T(0) = rho exactly, and every action
                // ties (the lowest, 0, is greedy). No pass needed.
                self.sweeps.rewards(next)?;
            } else {
                self.sweeps.backup_greedy(v, next)?;
            }
            let dt = t0.elapsed().as_secs_f64();
            sweep_seconds += dt;
            if evaluation {
                evaluation_seconds += dt;
            }
            // Move the sweep's result to the midpoint of MacQueen's bounds and make it `v`
            // (the sweep's input stays in `next`).
            let d = self.sweeps.diff_stats(next, v, T::ZERO)?;
            let half = 0.5 * (d.hi - d.lo);
            let s = midpoint(gamma, d.lo, d.hi);
            if s != T::ZERO {
                self.sweeps.shift(next, s)?;
            }
            (v, next) = (next, v);
            let record = SweepRecord {
                sweep: records.len() + 1,
                delta: Delta::exact(half),
                delta_v: d.change,
                seconds: offset + self.start.elapsed().as_secs_f64(),
                extrapolated: evaluation || full > 0,
                evaluation,
            };
            records.push(record);
            let mut converged = false;
            if evaluation {
                // Evaluation stops once it has cut the full backup's half-span tenfold, or
                // below xi / 2: beyond that the policy, not its evaluation, limits the next
                // full backup.
                evaluations_left = if half <= eval_tol {
                    0
                } else {
                    evaluations_left - 1
                };
            } else {
                full += 1;
                final_delta = half;
                if full > first_policy && d.change <= gamma * config.xi {
                    // The backup's input is already within `change / (1 - gamma)` of `V*`,
                    // at most the guarantee, and the policy buffer holds exactly its greedy
                    // policy: return it as it was (left in `next`) and skip the greedy pass.
                    (v, next) = (next, v);
                    final_delta = d.change / gamma;
                    greedy_known = true;
                    converged = true;
                } else if half <= config.xi {
                    converged = true;
                } else if full > first_policy {
                    evaluations_left = config.evaluation_sweeps;
                    eval_tol = (EVALUATION_PROGRESS * half).max(0.5 * config.xi);
                }
            }
            let done = converged || records.len() >= config.max_sweeps;
            let flow = if self.show_state && !done {
                let state = SolverState {
                    scheme: Scheme::ModifiedPolicy,
                    v: self.sweeps.values(v)?,
                    v_prev: Cow::Borrowed(&[][..]),
                    policy: self.sweeps.policy()?,
                    shift: 0.0,
                    evaluations_left,
                    evaluation_tolerance: eval_tol,
                    final_delta,
                    sweep_seconds,
                    evaluation_seconds,
                    records: Cow::Borrowed(&records[..]),
                };
                observer(&self.progress(record), Some(&state))
            } else {
                observer(&self.progress(record), None)
            };
            if converged {
                stop = Stop::Converged;
                break;
            }
            if flow.is_break() && !done {
                return Err(SolveError::Interrupted {
                    sweeps: records.len(),
                }
                .into());
            }
        }
        if !greedy_known {
            self.sweeps.greedy(v)?;
        }
        self.solution(
            v,
            records,
            stop,
            final_delta,
            (offset, sweep_seconds, evaluation_seconds),
        )
    }
}

/// The operator of a run and how it will iterate.
struct Prepared<'a, T: Real, M: ?Sized> {
    op: Operator<'a, T, M>,
    bound: usize,
    scheme: Scheme,
    /// Whether value iteration extrapolates: absorbing goals and terminal successors break
    /// the shift property MacQueen's bounds rest on (their rows of P sum to less than 1).
    extrapolate: bool,
    /// The grid a fresh run first solves and starts from ([`SolverConfig::coarse_start`],
    /// modified policy iteration on a grid that has a coarser one, for a model not known only
    /// on its grid); `None` for a start from `V = 0`.
    coarse: Option<Grid<T>>,
}

/// Whether `config` runs modified policy iteration on `model` where its operator can
/// evaluate a policy.
fn policy_iteration<T: Real, M: Model<T> + ?Sized>(model: &M, config: &SolverConfig) -> bool {
    config.evaluation_sweeps > 0
        && config.extrapolate
        && config.sweep == SweepMode::Synchronous
        && !config.absorbing_goal
        && !model.has_terminal_states()
        && config.gamma > 0.0
}

/// Whether a fresh run of `config` on `model` starts from a coarse grid's solve where its
/// operator can evaluate a policy (and its grid has a coarser one).
fn may_start_coarse<T: Real, M: Model<T> + ?Sized>(model: &M, config: &SolverConfig) -> bool {
    config.coarse_start
        && policy_iteration(model, config)
        && !super::coarse::known_only_on_its_grid(model)
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
    let mpi = policy_iteration(model, config) && op.can_evaluate();
    let extrapolate = config.extrapolate
        && !config.absorbing_goal
        && !model.has_terminal_states()
        && config.gamma > 0.0;
    Ok(Prepared {
        op,
        bound,
        extrapolate,
        coarse: if mpi && may_start_coarse(model, config) {
            grid.coarsened()
        } else {
            None
        },
        scheme: if mpi {
            Scheme::ModifiedPolicy
        } else {
            Scheme::Value
        },
    })
}
