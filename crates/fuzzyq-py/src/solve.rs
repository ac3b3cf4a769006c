//! `solve`, `load` and `Solution`: fuzzy Q-iteration through the sim crate (the command
//! line's training path for built-in models, the solver on a table for Python callables), and
//! every policy file the command line writes.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use fuzzyq_core::NamedOption;
use fuzzyq_core::options::UnknownName;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::{
    self, CoarseStart, Device, IterationOperator, Kernel, Precision, Progress, Scheme, SolveError,
    TabulatedModel,
};
use fuzzyq_sim::SimError;
use fuzzyq_sim::io::checkpoint::FqiState;
use fuzzyq_sim::io::config::{EnvConfig, GridConfig, SolverOverrides, SolverSettings, TrainConfig};
use fuzzyq_sim::io::policy_file::{
    PolicyArtifact, PolicyFile, TabulatedArtifact, TrainSummary, Values,
};
use fuzzyq_sim::learn::fit::FitConfig;
use fuzzyq_sim::learn::samples::{Collection, Exploration, Transitions};
use fuzzyq_sim::memory::{Estimate, Limit};
use fuzzyq_sim::model::learned::BlockTables;
use fuzzyq_sim::model::{Dynamics, EnvModel, F64Model};
use fuzzyq_sim::run::policy::{FqiPolicy, Policy as SimPolicy};
use fuzzyq_sim::train::DeviceReal;
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::callable::CallableModel;
use crate::classic::ClassicModel;
use crate::convert::{arg, describe, finite_vector, matrix};
use crate::errors::{
    Kind, config_error, error, guard, machine_limit, memory_error, policy_file_error, sim_error,
    solve_error,
};
use crate::model::{Grid, PointMass};
use crate::policy::Policy;
use crate::task::Task;

/// The option named `got`, or a `ConfigError` naming `field` and the accepted names.
pub(crate) fn parse_option<T: FromStr<Err = UnknownName>>(
    py: Python<'_>,
    field: &str,
    got: &str,
) -> PyResult<T> {
    got.parse()
        .map_err(|e: UnknownName| error(py, Kind::Config, format!("{field}: {e}, got {got:?}")))
}

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
        let bar = if progress {
            let tqdm = py.import("tqdm").map_err(|_| {
                error(
                    py,
                    Kind::Config,
                    "progress: progress=True shows a tqdm bar, but tqdm is not installed (pip \
                     install tqdm)",
                )
            })?;
            let kwargs = PyDict::new(py);
            kwargs.set_item("total", max_sweeps)?;
            kwargs.set_item("unit", "sweep")?;
            kwargs.set_item("desc", "fuzzy Q-iteration")?;
            Some(tqdm.getattr("tqdm")?.call((), Some(&kwargs))?.unbind())
        } else {
            None
        };
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
            let table = callable_table::<f32>(py, tables, g, actions)?;
            solve_table(py, table, grid, &settings, run, source)
        }
        Precision::F64 => {
            let table = callable_table::<f64>(py, tables, g, actions)?;
            solve_table(py, table, grid, &settings, run, source)
        }
    }
}

/// The solver's model of a `CallableModel`'s `tables` on `grid`, in precision `T`.
fn callable_table<T: TableReal>(
    py: Python<'_>,
    tables: crate::callable::Tables,
    grid: &Grid,
    actions: &[(Vec<f64>, usize)],
) -> PyResult<TabulatedModel<T>> {
    let grid_t = grid.to_precision::<T>(py)?;
    crate::pool::detach(py, || tables.model(grid_t, actions)).map_err(|e| solve_error(py, &e))
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

/// The transitions of `obj` (see [`transitions_from`]) for states of `e` and joint action
/// vectors of `d` values.
pub(crate) fn transitions_of(obj: &Bound<'_, PyAny>, e: usize, d: usize) -> PyResult<Transitions> {
    let py = obj.py();
    let field = |name: &str| -> PyResult<Bound<'_, PyAny>> {
        obj.get_item(name).map_err(|_| {
            error(
                py,
                Kind::InputType,
                format!(
                    "transitions: expected a mapping with states, actions, next_states and \
                     rewards (as fuzzyq.collect returns); {name} is missing"
                ),
            )
        })
    };
    let (n, _, x) = matrix(&field("states")?, "transitions.states", None, Some(e))?;
    let (_, _, u) = matrix(&field("actions")?, "transitions.actions", Some(n), Some(d))?;
    let (_, _, next) = matrix(
        &field("next_states")?,
        "transitions.next_states",
        Some(n),
        Some(e),
    )?;
    let r = finite_vector(&field("rewards")?, "transitions.rewards", Some(n))?;
    Transitions::from_columns(e, d, x, u, next, r).map_err(|err| config_error(py, &err))
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
            learned => {
                let bytes = learned.to_bytes().map_err(|e| sim_error(py, &e))?;
                let policy = crate::pool::detach(py, || SimPolicy::from_file(learned))
                    .map_err(|e| sim_error(py, &e))?;
                let policy = Policy::new(
                    Arc::new(policy),
                    PolicyKind::Greedy,
                    crate::policy::Origin::File(bytes),
                );
                Ok(Py::new(py, policy)?.into_any())
            }
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

/// What a solution's policy needs besides `V` and the greedy actions.
enum Source {
    /// A built-in model: the training configuration (model, grid, settings) and, for a
    /// policy of a learned model, its transition tables; can be saved.
    Env(Box<TrainConfig>, Option<Box<BlockTables>>),
    /// A `CallableModel`, with its table in the solver's precision (tabulated again on first
    /// use when the solution was unpickled).
    Callable(Py<CallableModel>, OnceLock<Table>),
    /// A `Task` learned from transitions: the task, the transitions, the estimation's report
    /// and the learned table in the solver's precision (learned again on first use when the
    /// solution was unpickled).
    Learned {
        task: Py<Task>,
        data: Arc<Transitions>,
        report: serde_json::Value,
        table: OnceLock<Table>,
    },
}

/// A tabulated model in the solver's precision.
#[derive(Clone)]
enum Table {
    F32(Arc<TabulatedModel<f32>>),
    F64(Arc<TabulatedModel<f64>>),
}

/// The result of [`solve`] or [`load`]: `V`, the greedy actions, the run's record, and
/// policies.
#[pyclass(module = "fuzzyq", frozen)]
pub struct Solution {
    v: Py<PyAny>,
    greedy: Py<PyArray1<u32>>,
    grid: Py<Grid>,
    summary: TrainSummary,
    gamma: f64,
    xi: f64,
    absorbing_goal: bool,
    precision: Precision,
    source: Source,
    /// The sim crate's policy, built (and prepared) on first use.
    policy: OnceLock<Arc<SimPolicy>>,
    /// Whether the callback stopped the solve.
    stopped: bool,
}

impl Solution {
    fn assemble(
        py: Python<'_>,
        v: Py<PyAny>,
        greedy: Vec<u32>,
        grid: Py<Grid>,
        summary: TrainSummary,
        settings: &SolverSettings,
        source: Source,
    ) -> PyResult<Self> {
        Ok(Self {
            v,
            greedy: PyArray1::from_vec(py, greedy).unbind(),
            grid,
            summary,
            gamma: settings.gamma,
            xi: settings.xi,
            absorbing_goal: settings.absorbing_goal,
            precision: settings.precision,
            source,
            policy: OnceLock::new(),
            stopped: false,
        })
    }

    pub(crate) fn from_artifact(
        py: Python<'_>,
        a: PolicyArtifact,
        grid: Option<Py<Grid>>,
    ) -> PyResult<Self> {
        let grid = match grid {
            Some(g) => g,
            None => {
                let inner = a.config.grid::<f64>().map_err(|e| sim_error(py, &e))?;
                Py::new(py, Grid::from_inner(inner))?
            }
        };
        let v = match a.values {
            Values::F32(v) => PyArray1::from_vec(py, v).into_any().unbind(),
            Values::F64(v) => PyArray1::from_vec(py, v).into_any().unbind(),
        };
        let settings = a.config.solver.clone();
        Self::assemble(
            py,
            v,
            a.greedy,
            grid,
            a.summary,
            &settings,
            Source::Env(Box::new(a.config), a.learned),
        )
    }

    /// A copy of `V` in the solver's precision.
    fn values(&self, py: Python<'_>) -> PyResult<Values> {
        let v = self.v.bind(py);
        Ok(match self.precision {
            Precision::F32 => {
                Values::F32(v.cast::<PyArray1<f32>>()?.readonly().as_slice()?.to_vec())
            }
            Precision::F64 => {
                Values::F64(v.cast::<PyArray1<f64>>()?.readonly().as_slice()?.to_vec())
            }
        })
    }

    /// The sim crate's policy of this solution, built and prepared (with the GIL released) on
    /// first use from a copy of `V`.
    pub(crate) fn sim_policy(&self, py: Python<'_>) -> PyResult<Arc<SimPolicy>> {
        if let Some(p) = self.policy.get() {
            return Ok(p.clone());
        }
        let greedy: Vec<u32> = self.greedy.bind(py).readonly().as_slice()?.to_vec();
        let values = self.values(py)?;
        let (gamma, absorbing) = (self.gamma, self.absorbing_goal);
        let prepared = |p: FqiPolicy| p.prepare().map(|()| p);
        let built = match (&self.source, values) {
            (Source::Env(config, learned), values) => {
                let config = (**config).clone();
                let learned = learned.as_deref().cloned();
                crate::pool::detach(py, || {
                    FqiPolicy::with_model(config, learned, values, greedy).and_then(prepared)
                })
            }
            (_, values) => {
                let table = self.table(py)?;
                match (table, values) {
                    (Table::F32(t), Values::F32(v)) => {
                        let grid = self.grid.get().to_precision::<f32>(py)?;
                        crate::pool::detach(py, || {
                            FqiPolicy::tabulated(t, grid, v, greedy, gamma, absorbing)
                                .and_then(prepared)
                        })
                    }
                    (Table::F64(t), Values::F64(v)) => {
                        let grid = self.grid.get().to_precision::<f64>(py)?;
                        crate::pool::detach(py, || {
                            FqiPolicy::tabulated(t, grid, v, greedy, gamma, absorbing)
                                .and_then(prepared)
                        })
                    }
                    _ => unreachable!("a tabulated model is solved in the precision of its table"),
                }
            }
        };
        let policy = built.map_err(|e| sim_error(py, &e))?;
        Ok(self
            .policy
            .get_or_init(|| Arc::new(SimPolicy::Fqi(policy)))
            .clone())
    }
}

impl Solution {
    /// The table of a solution of a model known only at the cores: kept from the solve, or
    /// computed again (a `CallableModel` tabulated, a `Task` learned) after unpickling.
    fn table(&self, py: Python<'_>) -> PyResult<Table> {
        let (cell, grid) = match &self.source {
            Source::Env(..) => unreachable!("a built-in model's solution has no table"),
            Source::Callable(_, t) | Source::Learned { table: t, .. } => (t, self.grid.get()),
        };
        if let Some(t) = cell.get() {
            return Ok(t.clone());
        }
        let built = match &self.source {
            Source::Callable(model, _) => {
                let limit = Limit::new(None).map_err(|e| sim_error(py, &e))?;
                let tables = model
                    .get()
                    .tabulate(py, &grid.inner, self.precision, &limit)?;
                let actions = &model.get().actions;
                match self.precision {
                    Precision::F32 => {
                        Table::F32(Arc::new(callable_table(py, tables, grid, actions)?))
                    }
                    Precision::F64 => {
                        Table::F64(Arc::new(callable_table(py, tables, grid, actions)?))
                    }
                }
            }
            Source::Learned { task, data, .. } => match self.precision {
                Precision::F32 => {
                    let g = grid.to_precision::<f32>(py)?;
                    Table::F32(Arc::new(task.get().learn(py, &grid.inner, g, data)?.model))
                }
                Precision::F64 => {
                    let g = grid.to_precision::<f64>(py)?;
                    Table::F64(Arc::new(task.get().learn(py, &grid.inner, g, data)?.model))
                }
            },
            Source::Env(..) => unreachable!("handled above"),
        };
        Ok(cell.get_or_init(|| built).clone())
    }
}

/// Pickling.
impl Solution {
    /// The policy artifact of a solution of a built-in model (what its file holds).
    fn artifact(&self, py: Python<'_>) -> PyResult<Option<PolicyArtifact>> {
        let Source::Env(config, learned) = &self.source else {
            return Ok(None);
        };
        Ok(Some(PolicyArtifact {
            config: (**config).clone(),
            values: self.values(py)?,
            greedy: self.greedy.bind(py).readonly().as_slice()?.to_vec(),
            summary: self.summary.clone(),
            learned: learned.clone(),
        }))
    }

    /// A solution read from a file of a `CallableModel`'s solution, acting with `model`
    /// (checked to have the file's state length and actions).
    fn from_tabulated(
        py: Python<'_>,
        t: TabulatedArtifact,
        model: &Bound<'_, CallableModel>,
    ) -> PyResult<Self> {
        let m = model.get();
        if t.cores.len() != m.state_dim() || t.actions != m.actions {
            return Err(error(
                py,
                Kind::Config,
                format!(
                    "model: the file's solution has a state of {} variables and actions {:?}; \
                     the model has {} and {:?}",
                    t.cores.len(),
                    t.actions,
                    m.state_dim(),
                    m.actions
                ),
            ));
        }
        let mut grid = Grid::checked(py, t.cores)?;
        grid.inner = grid.inner.with_membership(t.membership);
        let precision = t.values.precision();
        let v = match t.values {
            Values::F32(v) => PyArray1::from_vec(py, v).into_any().unbind(),
            Values::F64(v) => PyArray1::from_vec(py, v).into_any().unbind(),
        };
        Ok(Self {
            v,
            greedy: PyArray1::from_vec(py, t.greedy).unbind(),
            grid: Py::new(py, grid)?,
            summary: t.summary,
            gamma: t.gamma,
            xi: t.xi,
            absorbing_goal: t.absorbing_goal,
            precision,
            source: Source::Callable(model.clone().unbind(), OnceLock::new()),
            policy: OnceLock::new(),
            stopped: false,
        })
    }

    /// Rebuilds a pickled solution (see `__reduce__`).
    pub(crate) fn restore(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let tag: String = data.get_item(0)?.extract()?;
        let mut solution = if tag == "env" {
            let (_, bytes, seconds, stopped): (String, Bound<'_, PyAny>, f64, bool) =
                data.extract()?;
            let file = PolicyFile::from_bytes(&crate::pickle::bytes(&bytes)?, "<pickle>".as_ref())
                .map_err(|e| policy_file_error(py, &e))?;
            let PolicyFile::Fqi(a) = file else {
                return Err(error(
                    py,
                    Kind::Input,
                    "_restore: not a fuzzy Q-iteration solution",
                ));
            };
            let mut s = Self::from_artifact(py, a, None)?;
            s.summary.seconds = seconds;
            s.stopped = stopped;
            s
        } else {
            #[allow(clippy::type_complexity)] // the pickled fields, in order
            let (_, model, grid, v, greedy, summary, gamma, xi, absorbing_goal, precision, stopped): (
                String,
                Bound<'_, PyAny>,
                Py<Grid>,
                Bound<'_, PyAny>,
                Vec<u32>,
                String,
                f64,
                f64,
                bool,
                String,
                bool,
            ) = data.extract()?;
            let precision: Precision = parse_option(py, "precision", &precision)?;
            let np = py.import("numpy")?;
            let dtype = match precision {
                Precision::F32 => "float32",
                Precision::F64 => "float64",
            };
            let v = np.call_method1("ascontiguousarray", (v, dtype))?.unbind();
            let summary: TrainSummary = serde_json::from_str(&summary)
                .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
            Self {
                v,
                greedy: PyArray1::from_vec(py, greedy).unbind(),
                grid,
                summary,
                gamma,
                xi,
                absorbing_goal,
                precision,
                source: restored_source(py, &tag, &model)?,
                policy: OnceLock::new(),
                stopped,
            }
        };
        solution.policy = OnceLock::new();
        Ok(Py::new(py, solution)?.into_any())
    }
}

/// The source of a pickled solution of a `CallableModel` (`tag` `"callable"`: the model) or
/// of a `Task` (`"learned"`: the task, its transitions and the estimation's report).
fn restored_source(py: Python<'_>, tag: &str, model: &Bound<'_, PyAny>) -> PyResult<Source> {
    if tag == "callable" {
        return Ok(Source::Callable(model.extract()?, OnceLock::new()));
    }
    let (task, data, report): (Py<Task>, Bound<'_, PyAny>, String) = model.extract()?;
    let t = task.get();
    let data = transitions_of(&data, t.shape.state_dim(), t.action_dim())?;
    let report = serde_json::from_str(&report)
        .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
    Ok(Source::Learned {
        task,
        data: Arc::new(data),
        report,
        table: OnceLock::new(),
    })
}

/// `data` as the dict `collect` returns: `states`, `actions`, `next_states`, `rewards`.
pub(crate) fn transitions_dict<'py>(
    py: Python<'py>,
    data: &Transitions,
) -> PyResult<Bound<'py, PyDict>> {
    let (x, u, next, r) = data.columns();
    let (n, e, a) = (data.len(), data.state_dim(), data.action_dim());
    let rows = |v: &[f64], k: usize| {
        PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((n, k), v.to_vec()).expect("rows"),
        )
    };
    let d = PyDict::new(py);
    d.set_item("states", rows(x, e))?;
    d.set_item("actions", rows(u, a))?;
    d.set_item("next_states", rows(next, e))?;
    d.set_item("rewards", PyArray1::from_slice(py, r))?;
    Ok(d)
}

/// The fuzzy Q-iteration policy inside a sim policy built by [`Solution::sim_policy`].
fn fqi(p: &SimPolicy) -> &FqiPolicy {
    match p {
        SimPolicy::Fqi(f) => f,
        SimPolicy::Additive(_) => unreachable!("a solution's policy is fuzzy Q-iteration"),
    }
}

#[pymethods]
impl Solution {
    /// `V[d] = max_u theta[d, u]` per core (row-major grid order), in the solver's precision.
    #[getter(V)]
    fn v(&self, py: Python<'_>) -> Py<PyAny> {
        self.v.clone_ref(py)
    }

    /// The lowest-index greedy joint action of every core.
    #[getter]
    fn greedy(&self, py: Python<'_>) -> Py<PyArray1<u32>> {
        self.greedy.clone_ref(py)
    }

    /// The grid.
    #[getter]
    fn grid(&self, py: Python<'_>) -> Py<Grid> {
        self.grid.clone_ref(py)
    }

    /// The environment's name (`"pointmass"`, `"khepera"`, `"dcmotor"`, ...), or `None` for
    /// a `CallableModel`.
    #[getter]
    fn env(&self) -> Option<&'static str> {
        match &self.source {
            Source::Env(c, _) => Some(c.env.name()),
            _ => None,
        }
    }

    /// Sweeps performed.
    #[getter]
    fn sweeps(&self) -> usize {
        self.summary.sweeps
    }

    /// Whether the stopping rule was met.
    #[getter]
    fn converged(&self) -> bool {
        self.summary.converged
    }

    /// Whether the callback stopped the solve (returning `False`): the solution is then that of
    /// the run limited to the sweeps done, with its error bound.
    #[getter]
    fn stopped(&self) -> bool {
        self.stopped
    }

    /// The exact change `||theta_K - theta_{K-1}||_inf` of the last sweep.
    #[getter]
    fn final_delta(&self) -> f64 {
        self.summary.final_delta
    }

    /// `gamma / (1 - gamma) * final_delta`: a bound on the distance to the fixed point.
    #[getter]
    fn error_bound(&self) -> f64 {
        self.gamma / (1.0 - self.gamma) * self.summary.final_delta
    }

    /// `(lower, upper)` bounds of every sweep's change, shape `(sweeps, 2)`.
    #[getter]
    fn deltas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            Ok({
                let flat: Vec<f64> = self
                    .summary
                    .deltas
                    .iter()
                    .flat_map(|&(a, b)| [a, b])
                    .collect();
                PyArray2::from_owned_array(
                    py,
                    Array2::from_shape_vec((self.summary.deltas.len(), 2), flat).expect("pairs"),
                )
            })
        })
    }

    /// Wall-clock seconds of the solve (0 for a solution loaded from a file: files keep no
    /// timings, so that the same problem gives the same file).
    #[getter]
    fn seconds(&self) -> f64 {
        self.summary.seconds
    }

    /// The coarse start (`coarse_start=True`): a dict of the coarse grid's `cores`, its
    /// `sweeps` and the `seconds` of its solve and interpolation; `None` for a run without
    /// one and for a solution loaded from a file.
    #[getter]
    fn coarse_start<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.summary
            .coarse
            .as_deref()
            .map(|c| coarse_dict(py, c))
            .transpose()
    }

    /// How a `Task`'s model was learned from its transitions (None for every other model):
    /// ``samples``; per block, ``blocks`` (its ``state_dims`` and ``action_components``, its
    /// ``rows``, ``samples_per_action``, ``entries_per_row``, ``residual_rms`` per variable,
    /// ``under_sampled_rows`` and the first of them, ``under_sampled``: the rows that needed a
    /// wider kernel); and ``reward`` (None with a reward function, else
    /// ``depends_on_action``, ``pairs_without_samples``, ``cores_without_samples``,
    /// ``fallback`` and ``residual_rms``).
    #[getter]
    fn fit<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match &self.source {
            Source::Learned { report, .. } => crate::json::to_python(py, report).map(Some),
            _ => Ok(None),
        }
    }

    /// The kernel instance used (`"avx512"`, `"avx2"`, `"portable"`, `"scalar"`, `"generic"` or
    /// `"q-values"`).
    #[getter]
    fn kernel(&self) -> &str {
        &self.summary.kernel
    }

    /// The discount factor.
    #[getter]
    fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The stopping threshold.
    #[getter]
    fn xi(&self) -> f64 {
        self.xi
    }

    /// `theta[d, u]` for every core and joint action, shape `(n_cores, n_joint_actions)`.
    /// Only for problems with at most 5e7 Q-values (the paper's has 2.56e9).
    fn theta<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            let policy = self.sim_policy(py)?;
            let p = fqi(&policy);
            let (n, m) = (p.n_cores(), p.n_joint_actions());
            if n.saturating_mul(m) > 50_000_000 {
                return Err(error(
                    py,
                    Kind::Input,
                    format!(
                        "theta: {n} cores x {m} joint actions is more than 5e7 Q-values; use V and policies"
                    ),
                ));
            }
            let t = crate::pool::detach(py, || p.theta()).map_err(|e| sim_error(py, &e))?;
            Ok(PyArray2::from_owned_array(
                py,
                Array2::from_shape_vec((n, m), t).expect("n x m"),
            ))
        })
    }

    /// `V` interpolated at state `x`.
    fn value(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        guard(py, || {
            let policy = self.sim_policy(py)?;
            let p = fqi(&policy);
            let x = finite_vector(x, "x", Some(p.state_dim()))?;
            p.value(&x).map_err(|e| sim_error(py, &e))
        })
    }

    /// A policy: `"greedy"` (eq 7, the maximiser of `Q(x, .)`) or `"interpolated"` (eq 22).
    #[pyo3(signature = (kind = "greedy"))]
    fn policy(slf: &Bound<'_, Self>, #[pyo3(from_py_with = arg)] kind: &str) -> PyResult<Policy> {
        let py = slf.py();
        guard(py, || {
            let kind = parse_option::<PolicyKind>(py, "kind", kind)?;
            Ok(Policy::new(
                slf.get().sim_policy(py)?,
                kind,
                crate::policy::Origin::Solution(slf.clone().into_any().unbind()),
            ))
        })
    }

    /// Pickling (`pickle`, `copy`, `joblib`, process pools): a solution of a built-in model
    /// as its policy file's bytes (and its timing), a solution of a `CallableModel` as the
    /// model (its function pickled by reference: a module-level function), the grid, `V`, the
    /// greedy actions and the run's record; its table is computed again on first use.
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let data = match self.artifact(py)? {
            Some(a) => {
                let bytes = PolicyFile::Fqi(a)
                    .to_bytes()
                    .map_err(|e| sim_error(py, &e))?;
                (
                    "env",
                    pyo3::types::PyBytes::new(py, &bytes),
                    self.summary.seconds,
                    self.stopped,
                )
                    .into_pyobject(py)?
                    .into_any()
            }
            None => {
                let (tag, model) = match &self.source {
                    Source::Callable(model, _) => ("callable", model.bind(py).clone().into_any()),
                    Source::Learned {
                        task, data, report, ..
                    } => (
                        "learned",
                        (
                            task.clone_ref(py),
                            transitions_dict(py, data)?,
                            report.to_string(),
                        )
                            .into_pyobject(py)?
                            .into_any(),
                    ),
                    Source::Env(..) => unreachable!("a built-in model's solution has an artifact"),
                };
                let summary = serde_json::to_string(&self.summary)
                    .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
                let greedy: Vec<u32> = self.greedy.bind(py).readonly().as_slice()?.to_vec();
                PyTuple::new(
                    py,
                    [
                        tag.into_pyobject(py)?.into_any(),
                        model,
                        self.grid.bind(py).clone().into_any(),
                        self.v.bind(py).clone(),
                        greedy.into_pyobject(py)?.into_any(),
                        summary.into_pyobject(py)?.into_any(),
                        self.gamma.into_pyobject(py)?.into_any(),
                        self.xi.into_pyobject(py)?.into_any(),
                        pyo3::types::PyBool::new(py, self.absorbing_goal)
                            .to_owned()
                            .into_any(),
                        self.precision.name().into_pyobject(py)?.into_any(),
                        pyo3::types::PyBool::new(py, self.stopped)
                            .to_owned()
                            .into_any(),
                    ],
                )?
                .into_any()
            }
        };
        crate::pickle::reduce(py, "solution", data)
    }

    /// Writes the policy file (the format `fuzzyq rollout` reads), atomically. Only solutions
    /// of built-in models can be saved; a solution of a `CallableModel` pickles.
    fn save(&self, py: Python<'_>, #[pyo3(from_py_with = arg)] path: PathBuf) -> PyResult<()> {
        guard(py, || {
            let Some(artifact) = self.artifact(py)? else {
                let Source::Callable(model, _) = &self.source else {
                    return Err(error(
                        py,
                        Kind::Config,
                        "save: a solution learned for a fuzzy.Task is kept by pickling it (its \
                         policy file format holds built-in models and CallableModels)",
                    ));
                };
                let m = model.get();
                let g = &self.grid.get().inner;
                let file = PolicyFile::Tabulated(Box::new(TabulatedArtifact {
                    cores: g.cores().to_vec(),
                    membership: g.membership(),
                    actions: m.actions.clone(),
                    blocks: m.declared_blocks().to_vec(),
                    values: self.values(py)?,
                    greedy: self.greedy.bind(py).readonly().as_slice()?.to_vec(),
                    gamma: self.gamma,
                    xi: self.xi,
                    absorbing_goal: self.absorbing_goal,
                    summary: self.summary.clone(),
                }));
                file.check()
                    .map_err(|e| error(py, Kind::Input, format!("save: {e}")))?;
                return crate::pool::detach(py, || file.save(&path)).map_err(|e| sim_error(py, &e));
            };
            artifact
                .check()
                .map_err(|e| error(py, Kind::Input, format!("save: {e}")))?;
            crate::pool::detach(py, || PolicyFile::Fqi(artifact).save(&path))
                .map_err(|e| sim_error(py, &e))
        })
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok({
                format!(
                    "Solution(env={}, sweeps={}, converged={}, final_delta={:.4}, seconds={:.2}, kernel={:?})",
                    self.env()
                        .map_or_else(|| "None".into(), |e| format!("{e:?}")),
                    self.summary.sweeps,
                    if self.summary.converged {
                        "True"
                    } else {
                        "False"
                    },
                    self.summary.final_delta,
                    self.summary.seconds,
                    self.summary.kernel
                )
            })
        })
    }
}

/// A coarse start as a dict: the coarse grid's `cores`, its `sweeps` and the `seconds` of its
/// solve and interpolation.
fn coarse_dict<'py>(py: Python<'py>, c: &CoarseStart) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("cores", c.cores)?;
    d.set_item("sweeps", c.sweeps)?;
    d.set_item("seconds", c.seconds)?;
    Ok(d)
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
