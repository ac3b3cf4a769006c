//! `solve`, `collect` and `load`: fuzzy Q-iteration through the sim crate (the command line's
//! training path for built-in models, the solver on a table for Python callables and for
//! `Task`s learned from transitions), and every policy file the command line writes. The
//! result, `Solution`, is in [`crate::solution`].

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use fuzzyq_core::NamedOption;
use fuzzyq_core::options::UnknownName;
use fuzzyq_core::solver::{
    self, Device, IterationOperator, Kernel, Precision, Progress, Scheme, SolveError,
    TabulatedModel,
};
use fuzzyq_sim::SimError;
use fuzzyq_sim::io::checkpoint::FqiState;
use fuzzyq_sim::io::config::{EnvConfig, GridConfig, SolverOverrides, SolverSettings, TrainConfig};
use fuzzyq_sim::io::policy_file::{PolicyFile, TrainSummary};
use fuzzyq_sim::learn::fit::FitConfig;
use fuzzyq_sim::learn::samples::{Collection, Exploration, Transitions};
use fuzzyq_sim::memory::{Estimate, Limit};
use fuzzyq_sim::model::{Dynamics, EnvModel, F64Model};
use fuzzyq_sim::train::DeviceReal;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::callable::CallableModel;
use crate::classic::ClassicModel;
use crate::convert::{arg, describe};
use crate::convert::{parse_option, transitions_dict, transitions_of};
use crate::errors::{
    Kind, config_error, error, guard, machine_limit, memory_error, policy_file_error, sim_error,
    solve_error,
};
use crate::model::{Grid, PointMass};
use crate::policy::Policy;
use crate::solution::{Solution, Source, Table, coarse_dict};
use crate::task::Task;

/// The solver settings as given to `solve` (`None`: the task's default, decided by
/// [`TrainConfig::solver_defaults`] as for `fuzzyq train`).
struct Settings<'a> {
    gamma: Option<f64>,
    xi: Option<f64>,
    max_sweeps: Option<usize>,
    sweep: Option<&'a str>,
    extrapolate: Option<bool>,
    evaluation_sweeps: Option<usize>,
    coarse_start: Option<bool>,
    absorbing_goal: Option<bool>,
    precision: Option<&'a str>,
    backup: Option<&'a str>,
    kernel: Option<&'a str>,
    operator: Option<&'a str>,
    device: Option<&'a str>,
}

impl Settings<'_> {
    /// The settings given, their names parsed (`"float32"` and `"float64"` are accepted for
    /// the precisions as numpy names them).
    fn overrides(&self, py: Python<'_>) -> PyResult<SolverOverrides> {
        fn named<T: FromStr<Err = UnknownName>>(
            py: Python<'_>,
            field: &str,
            got: Option<&str>,
        ) -> PyResult<Option<T>> {
            got.map(|g| parse_option(py, field, g)).transpose()
        }
        let precision = match self.precision {
            Some("float32") => Some(Precision::F32),
            Some("float64") => Some(Precision::F64),
            p => named(py, "precision", p)?,
        };
        Ok(SolverOverrides {
            gamma: self.gamma,
            xi: self.xi,
            max_sweeps: self.max_sweeps,
            sweep: named(py, "sweep", self.sweep)?,
            absorbing_goal: self.absorbing_goal,
            backup: named(py, "backup", self.backup)?,
            precision,
            extrapolate: self.extrapolate,
            evaluation_sweeps: self.evaluation_sweeps,
            coarse_start: self.coarse_start,
            kernel: named(py, "kernel", self.kernel)?,
            operator: named(py, "operator", self.operator)?,
            device: named(py, "device", self.device)?,
        })
    }
}

/// What a solve's observer reports back: a raised exception, or the sweep at which the
/// callback asked to stop (returning `False`) and the run's state one sweep before, from which
/// the partial solution is finished.
/// The tqdm bar of `progress=True`: `total` steps of `unit`, labelled `desc`.
pub(crate) fn progress_bar(
    py: Python<'_>,
    total: usize,
    unit: &str,
    desc: &str,
) -> PyResult<Py<PyAny>> {
    let tqdm = py.import("tqdm").map_err(|_| {
        error(
            py,
            Kind::Config,
            "progress: progress=True shows a tqdm bar, but tqdm is not installed (pip install \
             tqdm)",
        )
    })?;
    let kwargs = PyDict::new(py);
    kwargs.set_item("total", total)?;
    kwargs.set_item("unit", unit)?;
    kwargs.set_item("desc", desc)?;
    Ok(tqdm.getattr("tqdm")?.call((), Some(&kwargs))?.unbind())
}

struct Watch<'a, S> {
    callback: Option<&'a Py<PyAny>>,
    /// The tqdm bar of `progress=True`.
    bar: Option<Py<PyAny>>,
    failure: Mutex<Option<PyErr>>,
    /// Set by [`interrupt`](Self::interrupt): the run stops after its current sweep.
    interrupted: AtomicBool,
    halt: Mutex<Halt<S>>,
}

struct Halt<S> {
    /// The sweep after which the callback asked to stop.
    at: Option<usize>,
    /// The state after the sweep before the latest one (kept only with a callback).
    before: Option<S>,
    latest: Option<S>,
}

impl<'a, S> Watch<'a, S> {
    fn new(
        py: Python<'_>,
        callback: Option<&'a Py<PyAny>>,
        progress: bool,
        max_sweeps: usize,
    ) -> PyResult<Self> {
        let bar = progress
            .then(|| progress_bar(py, max_sweeps, "sweep", "fuzzy Q-iteration"))
            .transpose()?;
        Ok(Self {
            callback,
            bar,
            failure: Mutex::new(None),
            interrupted: AtomicBool::new(false),
            halt: Mutex::new(Halt {
                at: None,
                before: None,
                latest: None,
            }),
        })
    }

    /// Ctrl-C (or another exception a signal handler raised, `e`): the run stops after its
    /// current sweep and `e` is raised.
    fn interrupt(&self, e: PyErr) {
        self.failure.lock().expect("not poisoned").get_or_insert(e);
        self.interrupted.store(true, Ordering::SeqCst);
    }

    /// After each sweep: stops if interrupted, checks for Ctrl-C, updates the bar, calls the callback (an exception
    /// it raises is kept to be re-raised; `False` asks to stop), and keeps the state (`state`
    /// is called only when a callback could stop the run).
    fn see(&self, p: &Progress, state: impl FnOnce() -> Option<S>) -> ControlFlow<()> {
        if self.callback.is_some() {
            let mut h = self.halt.lock().expect("not poisoned");
            h.before = h.latest.take();
            h.latest = state();
        }
        if self.interrupted.load(Ordering::SeqCst) {
            return ControlFlow::Break(());
        }
        Python::attach(|py| {
            let result = py.check_signals().and_then(|()| {
                if let Some(bar) = &self.bar {
                    let bar = bar.bind(py);
                    if p.record.sweep == 1 && p.bound > 0 {
                        bar.setattr("total", p.bound.min(bar.getattr("total")?.extract()?))?;
                    }
                    let post = PyDict::new(py);
                    post.set_item("delta", format!("{:.3e}", p.record.delta.upper))?;
                    post.set_item("xi", p.xi)?;
                    bar.call_method1("set_postfix", (post,))?;
                    bar.call_method1("update", (1,))?;
                }
                match self.callback {
                    None => Ok(true),
                    Some(cb) => {
                        let d = PyDict::new(py);
                        d.set_item("sweep", p.record.sweep)?;
                        d.set_item("delta_lower", p.record.delta.lower)?;
                        d.set_item("delta_upper", p.record.delta.upper)?;
                        d.set_item("extrapolated", p.record.extrapolated)?;
                        d.set_item("evaluation", p.record.evaluation)?;
                        d.set_item("seconds", p.record.seconds)?;
                        d.set_item("bound", p.bound)?;
                        d.set_item("xi", p.xi)?;
                        set_run_choices(&d, p)?;
                        let r = cb.call1(py, (d,))?;
                        // Only `False` itself stops: a callback returning nothing continues.
                        Ok(!r.bind(py).is(pyo3::types::PyBool::new(py, false)))
                    }
                }
            });
            match result {
                Ok(true) => ControlFlow::Continue(()),
                Ok(false) => {
                    self.halt.lock().expect("not poisoned").at = Some(p.record.sweep);
                    ControlFlow::Break(())
                }
                Err(e) => {
                    *self.failure.lock().expect("not poisoned") = Some(e);
                    ControlFlow::Break(())
                }
            }
        })
    }

    /// Whether the run's state is kept after each sweep (only a callback can stop a run and
    /// need it): a GPU run reads it back from the device only then.
    fn wants_state(&self) -> bool {
        self.callback.is_some()
    }

    /// The observer of a run without state.
    fn plain(&self) -> impl FnMut(&Progress) -> ControlFlow<()> + Send + '_
    where
        S: Send,
    {
        move |p| self.see(p, || None)
    }

    /// The error of a run that ended with `e`: the callback's exception, if it raised one.
    fn error(&self, py: Python<'_>, e: &SolveError) -> PyErr {
        match self.failure.lock().expect("not poisoned").take() {
            Some(err) => err,
            None => solve_error(py, e),
        }
    }

    /// `Some((k, state after sweep k - 1))` if the callback stopped the run after sweep `k`.
    fn stopped(&self) -> Option<(usize, Option<S>)> {
        let mut h = self.halt.lock().expect("not poisoned");
        let at = h.at?;
        Some((at, h.before.take()))
    }

    fn close(&self, py: Python<'_>) {
        if let Some(bar) = &self.bar {
            let _ = bar.bind(py).call_method0("close");
        }
    }
}

/// Solves a model on a grid by fuzzy Q-iteration (the paper's eq 20), with the GIL released.
///
/// `model` is a built-in model (`PointMass`, `DcMotor`, `Pendulum`, `CarHill`, `Arm`), solved
/// through the same code as `fuzzyq train`, or a `CallableModel`, tabulated on the grid first.
/// Settings left at `None` take the task's defaults, those `fuzzyq train` runs
/// ([`TrainConfig::solver_defaults`]): a classic benchmark's preset's `gamma` and `xi` with
/// plain sweeps in `"f64"`; the robots' paper settings with a coarse start; otherwise
/// `gamma=0.96`, `xi=0.05`, `extrapolate=True`, `evaluation_sweeps=5`, `"f32"`.
/// `coarse_start=True` starts modified policy iteration from the solution on the grid with
/// every other core, interpolated: the same error bound, fewer sweeps on fine grids.
/// `operator="q-values"` runs Busoniu's fuzzy Q-iteration (theta stored; built-in models).
/// `device="gpu"` runs the block backup's sweeps on a GPU through wgpu, in `"f32"` (the CPU's
/// bits where the adapter fuses multiply-adds; see the `fuzzyq-gpu` crate).
/// `callback(info)` is called after every sweep with a dict (`sweep`, `delta_lower`,
/// `delta_upper`, `extrapolated`, `evaluation`, `seconds`, `bound`, `xi`); an exception it raises stops the
/// solve and propagates. Ctrl-C raises `KeyboardInterrupt` at the end of the current sweep.
///
/// `transitions` (a built-in model only; a dict of `states`, `actions`, `next_states`,
/// `rewards` arrays as `collect` returns, or a user's logged data) solves a model *learned*
/// from them instead of the model's own dynamics: every dynamics block's transition table is
/// estimated from the transitions (as `fuzzyq train --learner learned-model` does) and the
/// model supplies only the reward, actions and state ranges. The solution can be saved and
/// acts on the learned model.
///
/// `absorbing_goal=True` needs a model with goal states at some core of the grid (the point
/// masses' reward region; the classic benchmarks have none, the car's hilltop is a terminal
/// state beyond the grid); elsewhere it is refused. `max_memory_gb` (default:
/// 90% of the machine's memory, as `fuzzyq train --max-memory`) bounds the memory the solve
/// needs (a `CallableModel`'s tables of successors and rewards of every core and joint action,
/// the per-core vectors or `operator="q-values"`'s Q-values of a built-in model): a larger
/// problem is refused with its estimate before anything is allocated or any callable called;
/// pass a larger limit to solve it anyway.
#[pyfunction]
#[pyo3(signature = (
    model,
    grid,
    *,
    gamma = None,
    xi = None,
    max_sweeps = None,
    sweep = None,
    extrapolate = None,
    evaluation_sweeps = None,
    coarse_start = None,
    absorbing_goal = None,
    precision = None,
    backup = None,
    kernel = None,
    operator = None,
    device = None,
    threads = None,
    callback = None,
    transitions = None,
    max_memory_gb = None,
    progress = false,
))]
#[allow(clippy::too_many_arguments)] // the solver's settings, as keyword arguments
pub(crate) fn solve(
    py: Python<'_>,
    model: &Bound<'_, PyAny>,
    #[pyo3(from_py_with = arg)] grid: &Bound<'_, Grid>,
    #[pyo3(from_py_with = arg)] gamma: Option<f64>,
    #[pyo3(from_py_with = arg)] xi: Option<f64>,
    #[pyo3(from_py_with = arg)] max_sweeps: Option<usize>,
    #[pyo3(from_py_with = arg)] sweep: Option<&str>,
    #[pyo3(from_py_with = arg)] extrapolate: Option<bool>,
    #[pyo3(from_py_with = arg)] evaluation_sweeps: Option<usize>,
    #[pyo3(from_py_with = arg)] coarse_start: Option<bool>,
    #[pyo3(from_py_with = arg)] absorbing_goal: Option<bool>,
    #[pyo3(from_py_with = arg)] precision: Option<&str>,
    #[pyo3(from_py_with = arg)] backup: Option<&str>,
    #[pyo3(from_py_with = arg)] kernel: Option<&str>,
    #[pyo3(from_py_with = arg)] operator: Option<&str>,
    #[pyo3(from_py_with = arg)] device: Option<&str>,
    #[pyo3(from_py_with = arg)] threads: Option<usize>,
    callback: Option<Py<PyAny>>,
    transitions: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = arg)] max_memory_gb: Option<f64>,
    #[pyo3(from_py_with = arg)] progress: bool,
) -> PyResult<Solution> {
    let given = Settings {
        gamma,
        xi,
        max_sweeps,
        sweep,
        extrapolate,
        evaluation_sweeps,
        coarse_start,
        absorbing_goal,
        precision,
        backup,
        kernel,
        operator,
        device,
    };
    guard(py, || {
        solve_(
            py,
            model,
            grid,
            &given,
            threads,
            callback,
            transitions,
            max_memory_gb,
            progress,
        )
    })
}

/// The body of [`solve`].
#[allow(clippy::too_many_arguments)] // solve's arguments
fn solve_(
    py: Python<'_>,
    model: &Bound<'_, PyAny>,
    grid: &Bound<'_, Grid>,
    given: &Settings<'_>,
    threads: Option<usize>,
    callback: Option<Py<PyAny>>,
    transitions: Option<&Bound<'_, PyAny>>,
    max_memory_gb: Option<f64>,
    progress: bool,
) -> PyResult<Solution> {
    check_threads(py, threads)?;
    let limit = Limit::new(max_memory_gb).map_err(|e| sim_error(py, &e))?;
    if let Some(cb) = &callback
        && !cb.bind(py).is_callable()
    {
        return Err(error(py, Kind::InputType, "callback: expected a callable"));
    }
    let g = grid.get();

    // A built-in model: the configuration `fuzzyq train` would read (the task's defaults,
    // then the settings given), trained the same way.
    let overrides = given.overrides(py)?;
    let explicit = || GridConfig {
        membership: g.inner.membership(),
        ..GridConfig::explicit(g.inner.cores().to_vec())
    };
    let builtin = if let Ok(pm) = model.cast::<PointMass>() {
        Some((
            EnvConfig::Pointmass(pm.get().model.config().clone()),
            explicit(),
            None,
        ))
    } else if let Ok(k) = model.cast::<crate::khepera::Khepera>() {
        Some((k.get().train_config(py)?.env, explicit(), None))
    } else if let Ok(c) = model.cast::<ClassicModel>() {
        let c = c.get();
        Some((
            c.env.clone(),
            ClassicModel::grid_config(g),
            Some(c.preset_name()),
        ))
    } else {
        None
    };
    let run = Run {
        threads,
        callback: callback.as_ref(),
        progress,
        limit: &limit,
    };
    if let Some((env, grid_config, preset)) = builtin {
        let config = TrainConfig::for_task(env, grid_config, preset, &overrides)
            .map_err(|e| config_error(py, &e))?;
        return solve_builtin(py, grid, &config, transitions, &run);
    }
    if let Ok(task) = model.cast::<Task>() {
        let Some(data) = transitions else {
            return Err(error(
                py,
                Kind::Config,
                "transitions: a fuzzyq.Task is learned from transitions; pass \
                 transitions=fuzzyq.collect(...) or logged data",
            ));
        };
        return solve_learned(py, task, grid, data, &overrides, &run);
    }
    if transitions.is_some() {
        return Err(error(
            py,
            Kind::Config,
            "transitions: a model learned from transitions takes its reward, actions and blocks \
             from a built-in model (fuzzyq.PointMass or a classic benchmark) or a fuzzyq.Task",
        ));
    }
    let Ok(cm) = model.cast::<CallableModel>() else {
        return Err(error(
            py,
            Kind::InputType,
            format!(
                "model: expected a fuzzyq.PointMass, a fuzzyq.Khepera, a classic benchmark (fuzzyq.DcMotor, \
                 fuzzyq.Pendulum, fuzzyq.CarHill, fuzzyq.Arm), a fuzzyq.CallableModel or a \
                 fuzzyq.Task, got {}",
                describe(model)
            ),
        ));
    };
    solve_callable(py, cm, grid, &overrides, &run)
}

/// How a solve runs: its threads, its callback and progress bar, its memory limit.
struct Run<'a> {
    threads: Option<usize>,
    callback: Option<&'a Py<PyAny>>,
    progress: bool,
    limit: &'a Limit,
}

/// Solves a built-in model's task (`config`, as `fuzzyq train` would read it) on `grid`, or
/// the model learned from `transitions`.
fn solve_builtin(
    py: Python<'_>,
    grid: &Bound<'_, Grid>,
    config: &TrainConfig,
    transitions: Option<&Bound<'_, PyAny>>,
    run: &Run<'_>,
) -> PyResult<Solution> {
    let g = grid.get();
    run.limit
        .check(&fuzzyq_sim::memory::train(config))
        .map_err(|e| memory_error(py, "max_memory_gb", &e))?;
    if config.solver.absorbing_goal {
        let task = config.build_model().map_err(|e| sim_error(py, &e))?;
        let inner = &g.inner;
        let any_goal = crate::pool::detach(py, || any_core(inner, |x| Dynamics::is_goal(&task, x)));
        if !any_goal {
            return Err(no_goal(
                py,
                &format!(
                    "no core of the grid is a goal state of the {} model",
                    task.name()
                ),
            ));
        }
    }
    let data = transitions
        .map(|t| transitions_from(t, config))
        .transpose()?;
    let solve = |limit: Option<usize>,
                 resume: Option<FqiState<'static>>,
                 watch: &Watch<'_, FqiState<'static>>| {
        let mut config = config.clone();
        config.solver.max_sweeps = limit.unwrap_or(config.solver.max_sweeps);
        let interrupted = |e| watch.interrupt(e);
        crate::pool::run_interruptible(py, run.threads, interrupted, || match &data {
            None => {
                fuzzyq_sim::train::train_showing(&config, resume, watch.wants_state(), |p, s| {
                    watch.see(p, || s.map(|s| s.clone().into_owned()))
                })
            }
            Some(d) => fuzzyq_sim::train::train_on_transitions(
                &config,
                d,
                &FitConfig::default(),
                watch.plain(),
            )
            .map(|r| r.artifact),
        })
        .map_err(|e| error(py, Kind::Config, format!("threads: {e}")))
    };
    let (artifact, stopped) = run_watched(
        py,
        run.callback,
        run.progress,
        config.solver.max_sweeps,
        solve,
    )?;
    let mut solution = Solution::from_artifact(py, artifact, Some(grid.clone().unbind()))?;
    solution.stopped = stopped;
    Ok(solution)
}

/// The settings of a model known only at the cores (a `CallableModel`, a `Task`): the
/// overrides over the defaults, with the options such a model cannot take refused. `what`
/// names the model in errors.
fn table_settings(
    py: Python<'_>,
    overrides: &SolverOverrides,
    what: &str,
) -> PyResult<SolverSettings> {
    let mut settings = SolverSettings::default();
    overrides.apply(&mut settings);
    if settings.operator != IterationOperator::Values {
        return Err(error(
            py,
            Kind::Config,
            format!(
                "operator: \"q-values\" solves the built-in models; a {what} is solved with \
                 \"values\""
            ),
        ));
    }
    if settings.absorbing_goal {
        return Err(no_goal(py, &format!("a {what} has no goal states")));
    }
    if settings.device == Device::Gpu && settings.precision != Precision::F32 {
        return Err(error(
            py,
            Kind::Config,
            "device: \"gpu\" runs in float32; pass precision=\"f32\"",
        ));
    }
    Ok(settings)
}

/// Solves a `CallableModel` on `grid`: tabulated first, then solved on the table.
fn solve_callable(
    py: Python<'_>,
    cm: &Bound<'_, CallableModel>,
    grid: &Bound<'_, Grid>,
    overrides: &SolverOverrides,
    run: &Run<'_>,
) -> PyResult<Solution> {
    let settings = table_settings(py, overrides, "CallableModel")?;
    let g = grid.get();
    let tables = cm
        .get()
        .tabulate(py, &g.inner, settings.precision, run.limit)?;
    let source = |t| Source::Callable(cm.clone().unbind(), OnceLock::from(t));
    let actions = &cm.get().actions;
    match settings.precision {
        Precision::F32 => {
            let table = tables.model_on::<f32>(py, g, actions)?;
            solve_table(py, table, grid, &settings, run, source)
        }
        Precision::F64 => {
            let table = tables.model_on::<f64>(py, g, actions)?;
            solve_table(py, table, grid, &settings, run, source)
        }
    }
}

/// Solves the model of a `Task` learned from `transitions` on `grid`.
fn solve_learned(
    py: Python<'_>,
    task: &Bound<'_, Task>,
    grid: &Bound<'_, Grid>,
    transitions: &Bound<'_, PyAny>,
    overrides: &SolverOverrides,
    run: &Run<'_>,
) -> PyResult<Solution> {
    let settings = table_settings(py, overrides, "Task")?;
    let t = task.get();
    let data = transitions_of(transitions, t.shape.state_dim(), t.action_dim())?;
    let data = Arc::new(data);
    match settings.precision {
        Precision::F32 => learn_and_solve::<f32>(py, task, grid, data, &settings, run),
        Precision::F64 => learn_and_solve::<f64>(py, task, grid, data, &settings, run),
    }
}

/// Learns `task`'s model from `data` on `grid` in precision `T` and solves it.
fn learn_and_solve<T: TableReal>(
    py: Python<'_>,
    task: &Bound<'_, Task>,
    grid: &Bound<'_, Grid>,
    data: Arc<Transitions>,
    settings: &SolverSettings,
    run: &Run<'_>,
) -> PyResult<Solution> {
    let g = grid.get();
    let learned = task
        .get()
        .learn::<T>(py, &g.inner, g.to_precision::<T>(py)?, &data)?;
    let source = learned_source(task, &data, learned.report);
    solve_table(py, learned.model, grid, settings, run, source)
}

/// The source of a solution of `task` learned from `data` (with the estimation's `report`).
fn learned_source<'a>(
    task: &'a Bound<'_, Task>,
    data: &'a Arc<Transitions>,
    report: serde_json::Value,
) -> impl FnOnce(Table) -> Source + 'a {
    move |t| Source::Learned {
        task: task.clone().unbind(),
        data: data.clone(),
        report,
        table: OnceLock::from(t),
    }
}

/// A precision tabulated models are solved in.
trait TableReal: DeviceReal + numpy::Element {
    /// The table in the precision-tagged form a solution keeps.
    fn table(t: Arc<TabulatedModel<Self>>) -> Table;
}

impl TableReal for f32 {
    fn table(t: Arc<TabulatedModel<f32>>) -> Table {
        Table::F32(t)
    }
}

impl TableReal for f64 {
    fn table(t: Arc<TabulatedModel<f64>>) -> Table {
        Table::F64(t)
    }
}

/// Solves a model known only at the cores (`table`) on `grid`; `source` makes the solution's
/// source from the table.
fn solve_table<T: TableReal>(
    py: Python<'_>,
    table: TabulatedModel<T>,
    grid: &Bound<'_, Grid>,
    settings: &SolverSettings,
    run: &Run<'_>,
    source: impl FnOnce(Table) -> Source,
) -> PyResult<Solution> {
    let config = settings.solver_config();
    let table = Arc::new(table);
    let grid_t = grid.get().to_precision::<T>(py)?;
    let solve = |limit: Option<usize>,
                 resume: Option<solver::SolverState<'static, T>>,
                 watch: &Watch<'_, solver::SolverState<'static, T>>| {
        let config = solver::SolverConfig {
            max_sweeps: limit.unwrap_or(config.max_sweeps),
            ..config
        };
        let interrupted = |e| watch.interrupt(e);
        crate::pool::run_interruptible(py, run.threads, interrupted, || {
            T::solve_on_device(
                settings.device,
                &*table,
                &grid_t,
                &config,
                resume,
                watch.wants_state(),
                |p, s| watch.see(p, || s.map(|s| s.clone().into_owned())),
            )
        })
        .map_err(|e| error(py, Kind::Config, format!("threads: {e}")))
    };
    let (s, stopped) = run_watched(py, run.callback, run.progress, config.max_sweeps, solve)?;
    let summary = TrainSummary::from_solution(&s);
    let v = PyArray1::from_vec(py, s.v).into_any().unbind();
    let mut solution = Solution::assemble(
        py,
        v,
        s.greedy,
        grid.clone().unbind(),
        summary,
        settings,
        source(T::table(table)),
    )?;
    solution.stopped = stopped;
    Ok(solution)
}

/// Runs a solve (`run(limit, resume, watch)`) watched by `callback` and the `progress` bar.
/// If the callback stopped it after sweep `k`, the result is the run limited to `k` sweeps:
/// `run` again with the limit `k` from the state after sweep `k - 1` (the same bits as the
/// stopped run's, and the bound of a run that ends there). Returns the result and whether the
/// callback stopped it; an exception the callback raised propagates.
fn run_watched<S, R>(
    py: Python<'_>,
    callback: Option<&Py<PyAny>>,
    progress: bool,
    max_sweeps: usize,
    run: impl Fn(Option<usize>, Option<S>, &Watch<'_, S>) -> PyResult<Result<R, SimError>>,
) -> PyResult<(R, bool)> {
    let watch = Watch::new(py, callback, progress, max_sweeps)?;
    let result = run(None, None, &watch)?;
    watch.close(py);
    match result {
        Ok(r) => Ok((r, false)),
        Err(SimError::Solve(e)) => {
            let Some((k, before)) = watch.stopped() else {
                return Err(watch.error(py, &e));
            };
            let quiet = Watch::new(py, None, false, k)?;
            match run(Some(k), before, &quiet)? {
                Ok(r) => Ok((r, true)),
                Err(SimError::Solve(e)) => Err(quiet.error(py, &e)),
                Err(e) => Err(sim_error(py, &e)),
            }
        }
        Err(e) => Err(sim_error(py, &e)),
    }
}

/// Checks `threads` as `fuzzyq train --threads` does ([`fuzzyq_sim::train::check_threads`]).
fn check_threads(py: Python<'_>, threads: Option<usize>) -> PyResult<()> {
    match threads.map(fuzzyq_sim::train::check_threads) {
        Some(Err(e)) => Err(error(py, Kind::Config, format!("threads: {e}"))),
        _ => Ok(()),
    }
}

/// Whether `is_goal` holds at any core of `grid` (in parallel; stops at the first).
fn any_core(
    grid: &fuzzyq_core::solver::Grid<f64>,
    is_goal: impl Fn(&[f64]) -> bool + Sync,
) -> bool {
    use rayon::prelude::*;
    let view = grid.view();
    (0..grid.n_cores()).into_par_iter().any(|d| {
        let mut x = [0.0; fuzzyq_core::MAX_DIMS];
        let x = &mut x[..grid.n_dims()];
        view.core_state(d, x).is_ok() && is_goal(x)
    })
}

/// The error of `absorbing_goal=True` on a model without goal states (`why`): the option would
/// change nothing but the iteration scheme, hence silently the result.
fn no_goal(py: Python<'_>, why: &str) -> PyErr {
    error(
        py,
        Kind::Config,
        format!(
            "absorbing_goal: {why}, so there is nothing to absorb (the option would only change \
             the iteration scheme); leave absorbing_goal=False"
        ),
    )
}

/// The transitions of `obj` (a mapping with `states`, `actions`, `next_states` and
/// `rewards`, as [`collect`] returns) for the task of `config`.
fn transitions_from(obj: &Bound<'_, PyAny>, config: &TrainConfig) -> PyResult<Transitions> {
    let py = obj.py();
    let task = config.build_model().map_err(|e| sim_error(py, &e))?;
    let e = F64Model::state_dim(&task);
    let d = F64Model::actions(&task).dim() * F64Model::n_agents(&task);
    transitions_of(obj, e, d)
}

/// Collects `samples` transitions on the plant of a built-in `model` as
/// `fuzzyq train --learner learned-model` does: seeded episodes of `episode_steps` random
/// joint actions from the task's random starts, with the model's process noise (for example
/// `fuzzyq.PointMass(velocity_noise=0.05)`). Returns a dict of float64 arrays: `states`
/// `(n, state_dim)`, `actions` `(n, action_dim)`, `next_states` `(n, state_dim)` and
/// `rewards` `(n,)`, ready for `fuzzyq.solve(model, grid, transitions=...)`.
#[pyfunction]
#[pyo3(signature = (model, samples, *, seed = 0, episode_steps = 50))]
pub(crate) fn collect<'py>(
    py: Python<'py>,
    model: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = arg)] samples: usize,
    #[pyo3(from_py_with = arg)] seed: u64,
    #[pyo3(from_py_with = arg)] episode_steps: usize,
) -> PyResult<Bound<'py, PyDict>> {
    guard(py, || {
        let task = if let Ok(pm) = model.cast::<PointMass>() {
            EnvModel::PointMass((*pm.get().model).clone())
        } else if let Ok(c) = model.cast::<ClassicModel>() {
            (*c.get().model).clone()
        } else {
            return Err(error(
                py,
                Kind::InputType,
                format!(
                    "model: expected a fuzzyq.PointMass or a classic benchmark (fuzzyq.DcMotor, \
                 fuzzyq.Pendulum, fuzzyq.CarHill, fuzzyq.Arm), got {}",
                    describe(model)
                ),
            ));
        };
        // States, actions, successors and rewards of every sample.
        let (e, d) = (F64Model::state_dim(&task), F64Model::actions(&task).dim());
        let per_sample = 8.0 * (2 * e + d * F64Model::n_agents(&task) + 1) as f64;
        machine_limit(py)?
            .check(&Estimate {
                bytes: 2.0 * per_sample * samples as f64,
                what: format!("{samples} transitions"),
            })
            .map_err(|err| memory_error(py, "samples", &err))?;
        let collection = Collection {
            samples,
            episode_steps,
            seed,
        };
        let data = crate::pool::detach(py, || {
            fuzzyq_sim::train::collect_from_plant(&task, &collection, &mut Exploration::Random)
        })
        .map_err(|e| sim_error(py, &e))?;
        transitions_dict(py, &data)
    })
}

/// Reads a policy file written by `fuzzyq train` (any environment, any learner) or by
/// `Solution.save`.
///
/// Returns a `Solution` for a fuzzy Q-iteration policy (`V`, `greedy`, `grid`, the run's
/// record, `.policy(kind)`), and a `Policy` for a policy learned from samples (fuzzy
/// Q-learning, VQQL: greedy and decentralised, each agent acting on its own observation).
#[pyfunction]
#[pyo3(signature = (path, model = None))]
pub(crate) fn load(
    py: Python<'_>,
    #[pyo3(from_py_with = arg)] path: PathBuf,
    model: Option<&Bound<'_, PyAny>>,
) -> PyResult<Py<PyAny>> {
    guard(py, || {
        let file = crate::pool::detach(py, || PolicyFile::load(&path))
            .map_err(|e| policy_file_error(py, &e))?;
        let model = match model {
            Some(m) if !m.is_none() => Some(m.cast::<CallableModel>().map_err(|_| {
                error(
                    py,
                    Kind::InputType,
                    format!(
                        "model: expected the fuzzyq.CallableModel the solution was solved with, \
                         got {}",
                        describe(m)
                    ),
                )
            })?),
            _ => None,
        };
        if let PolicyFile::Tabulated(t) = file {
            let Some(model) = model else {
                return Err(error(
                    py,
                    Kind::Config,
                    "model: the file holds a solution of a fuzzyq.CallableModel; pass that model \
                     (load(path, model=...)), whose function the file cannot hold",
                ));
            };
            return Ok(Py::new(py, Solution::from_tabulated(py, *t, model)?)?.into_any());
        }
        if model.is_some() {
            return Err(error(
                py,
                Kind::Config,
                "model: applies to files of CallableModel solutions only; this file names its own \
                 environment",
            ));
        }
        match file {
            PolicyFile::Fqi(a) => {
                Ok(Py::new(py, Solution::from_artifact(py, a, None)?)?.into_any())
            }
            PolicyFile::Tabulated(_) => unreachable!("returned above"),
            learned => Ok(Py::new(py, Policy::from_learned(py, learned)?)?.into_any()),
        }
    })
}

/// The kernel instances this CPU runs, fastest first (`"avx512"`, `"avx2"`, `"portable"`, `"scalar"`).
#[pyfunction]
pub(crate) fn available_kernels() -> Vec<&'static str> {
    <Kernel as NamedOption>::ALL
        .iter()
        .copied()
        .filter(|k| k.is_available())
        .map(Kernel::name)
        .collect()
}

/// Sets what the solver chose for a run in a progress record `d` (the same after every
/// sweep): `scheme` (`"value-iteration"` or `"modified-policy-iteration"`), `extrapolate`
/// and `coarse_start` (None or [`coarse_dict`]).
pub(crate) fn set_run_choices(d: &Bound<'_, PyDict>, p: &Progress) -> PyResult<()> {
    let scheme = match p.scheme {
        Scheme::Value => "value-iteration",
        Scheme::ModifiedPolicy => "modified-policy-iteration",
    };
    d.set_item("scheme", scheme)?;
    d.set_item("extrapolate", p.extrapolate)?;
    let coarse = p.coarse.map(|c| coarse_dict(d.py(), &c)).transpose()?;
    d.set_item("coarse_start", coarse)
}
