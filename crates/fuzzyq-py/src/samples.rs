//! `learn_from_samples`: fuzzy Q-learning and VQQL on the built-in multi-agent tasks, run by
//! the code `fuzzyq train --learner fql|vqql` runs (so the same seed gives the same policy
//! file and learning curve), and on a system of your own: a `CallableModel` or a Gymnasium
//! environment stepped from Python through `fuzzyq._interact`'s episodes
//! ([`PyEpisodes`], an [`Environment`] of the learners), declared by a `Task`.

use std::cell::RefCell;
use std::ops::ControlFlow;
use std::sync::Mutex;
use std::time::Instant;

use fuzzyq_sim::io::config::TrainConfig;
use fuzzyq_sim::learn::fql::{
    self, Environment, EpisodeRecord, FeatureSpace, FqlConfig, FqlOutcome, StopReason, Transition,
};
use fuzzyq_sim::learn::vqql::{self, LloydReport, VqqlConfig};
use fuzzyq_sim::model::EnvKind;
use fuzzyq_sim::run::policy::TaskPolicyData;
use fuzzyq_sim::train::{self, Learner, SampleLearning, SampleOptions};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rand::Rng;
use rand_pcg::Pcg64Mcg;

use crate::convert::{arg, describe, parse_option};
use crate::errors::{Kind, config_error, error, guard, sim_error};
use crate::khepera::Khepera;
use crate::model::{Grid, PointMass};
use crate::policy::Policy;
use crate::solve::progress_bar;
use crate::task::Task;

/// The training configuration `fuzzyq train --env ENV` reads for a built-in model the
/// learners from samples learn (the point masses, the robots); `None` for any other source.
fn builtin_config(py: Python<'_>, source: &Bound<'_, PyAny>) -> PyResult<Option<TrainConfig>> {
    if let Ok(pm) = source.cast::<PointMass>() {
        let mut c =
            TrainConfig::default_for(EnvKind::Pointmass).map_err(|e| config_error(py, &e))?;
        c.env = fuzzyq_sim::io::config::EnvConfig::Pointmass(pm.get().model.config().clone());
        return Ok(Some(c));
    }
    match source.cast::<Khepera>() {
        Ok(k) => Ok(Some(k.get().train_config(py)?)),
        Err(_) => Ok(None),
    }
}

/// Between two episodes: Ctrl-C (an exception a signal handler raised) and the bar's step.
fn between_episodes(py: Python<'_>, bar: Option<&Py<PyAny>>) -> PyResult<()> {
    py.check_signals()?;
    if let Some(b) = bar {
        b.bind(py).call_method1("update", (1,))?;
    }
    Ok(())
}

/// The learning curve as numpy columns named as `fuzzyq train --curve` names them.
fn curve_dict<'py>(py: Python<'py>, curve: &[EpisodeRecord]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let ints = |f: fn(&EpisodeRecord) -> usize| {
        PyArray1::from_vec(py, curve.iter().map(|r| f(r) as i64).collect())
    };
    let floats =
        |f: fn(&EpisodeRecord) -> f64| PyArray1::from_vec(py, curve.iter().map(f).collect());
    d.set_item("episode", ints(|r| r.episode))?;
    d.set_item("steps", ints(|r| r.steps))?;
    d.set_item("return", floats(|r| r.ret))?;
    d.set_item("discounted_return", floats(|r| r.discounted_return))?;
    d.set_item("mean_abs_td", floats(|r| r.mean_abs_td))?;
    d.set_item("max_abs_td", floats(|r| r.max_abs_td))?;
    d.set_item("epsilon", floats(|r| r.epsilon))?;
    d.set_item("alpha", floats(|r| r.alpha))?;
    d.set_item("param_change", floats(|r| r.param_change))?;
    let terminal: Vec<bool> = curve.iter().map(|r| r.terminal).collect();
    d.set_item("terminal", PyArray1::from_vec(py, terminal))?;
    d.set_item(
        "eval_mean_return",
        floats(|r| r.eval_mean_return.unwrap_or(f64::NAN)),
    )?;
    d.set_item(
        "eval_success_rate",
        floats(|r| r.eval_success_rate.unwrap_or(f64::NAN)),
    )?;
    Ok(d)
}

/// The run's report: the curve, when it converged, its steps, why it stopped, its time and
/// VQQL's quantiser.
fn report<'py>(
    py: Python<'py>,
    outcome: &FqlOutcome,
    lloyd: Option<&fuzzyq_sim::learn::vqql::LloydReport>,
    seconds: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("curve", curve_dict(py, &outcome.curve)?)?;
    d.set_item("converged_at", outcome.converged_at)?;
    d.set_item("steps_total", outcome.steps_total)?;
    let stop = match outcome.stop {
        StopReason::EpisodeLimit => "episode-limit",
        StopReason::Converged => "converged",
        StopReason::Callback => "interrupted",
        StopReason::Diverged => "diverged",
    };
    d.set_item("stop", stop)?;
    d.set_item("seconds", seconds)?;
    let lloyd = match lloyd {
        Some(l) => {
            let v =
                serde_json::to_value(l).map_err(|e| error(py, Kind::Internal, e.to_string()))?;
            Some(crate::json::to_python(py, &v)?)
        }
        None => None,
    };
    d.set_item("lloyd", lloyd)?;
    Ok(d)
}

/// Learns a task from samples: a built-in multi-agent task as `fuzzyq train --learner
/// fql|vqql` does (fuzzy Q-learning with the additive layout, or VQQL: k-means cells, tabular
/// Q-learning; the point masses only), or a system of your own declared by a `Task` and
/// fuzzified on a `Grid`. Returns the greedy, decentralised `Policy` and the run's report
/// (see the stub).
#[pyfunction]
#[pyo3(signature = (source, learner = "fql", *, task = None, grid = None, episodes = None, episode_steps = None, gamma = None, reward_bound = None, literal = false, cells = None, seed = 0, starts = None, progress = false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn learn_from_samples<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = arg)] learner: &str,
    task: Option<&Bound<'py, PyAny>>,
    grid: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = arg)] episodes: Option<usize>,
    #[pyo3(from_py_with = arg)] episode_steps: Option<usize>,
    #[pyo3(from_py_with = arg)] gamma: Option<f64>,
    #[pyo3(from_py_with = arg)] reward_bound: Option<f64>,
    #[pyo3(from_py_with = arg)] literal: bool,
    #[pyo3(from_py_with = arg)] cells: Option<usize>,
    #[pyo3(from_py_with = arg)] seed: u64,
    starts: Option<&Bound<'py, PyAny>>,
    #[pyo3(from_py_with = arg)] progress: bool,
) -> PyResult<(Py<Policy>, Bound<'py, PyDict>)> {
    guard(py, || {
        let learner: Learner = parse_option(py, "learner", learner)?;
        if !matches!(learner, Learner::Fql | Learner::Vqql) {
            return Err(error(
                py,
                Kind::Config,
                format!(
                    "learner: expected \"fql\" or \"vqql\", got {:?} (fuzzy Q-iteration is \
                     fuzzyq.solve, the learned model fuzzyq.learn)",
                    learner.to_string()
                ),
            ));
        }
        let options = SampleOptions {
            episodes,
            literal,
            cells,
            seed,
        };
        let given = |v: Option<&Bound<'_, PyAny>>| v.is_some_and(|v| !v.is_none());
        if let Some(config) = builtin_config(py, source)? {
            let own = [
                ("task", given(task)),
                ("grid", given(grid)),
                ("episode_steps", episode_steps.is_some()),
                ("gamma", gamma.is_some()),
                ("reward_bound", reward_bound.is_some()),
                ("starts", given(starts)),
            ];
            if let Some((name, _)) = own.iter().find(|(_, set)| *set) {
                return Err(error(
                    py,
                    Kind::Config,
                    format!(
                        "{name}: applies to a system of your own (a CallableModel or a Gymnasium \
                         environment); a built-in task learns with fuzzyq train's settings"
                    ),
                ));
            }
            return learn_builtin(py, &config, learner, &options, progress);
        }
        if source.cast::<crate::classic::ClassicModel>().is_ok() {
            return Err(error(
                py,
                Kind::Config,
                format!(
                    "source: of the built-in tasks, fuzzy Q-learning and VQQL learn the point \
                     masses and the robots, not {} (fuzzyq.solve solves it on its model)",
                    describe(source)
                ),
            ));
        }
        let task: &Bound<'py, Task> = required(
            py,
            task,
            "task",
            format!(
                "learning {} from samples needs a fuzzyq.Task declaring its state bounds and \
                 actions",
                describe(source)
            ),
        )?;
        let grid: &Bound<'py, Grid> = required(
            py,
            grid,
            "grid",
            "a system of your own needs a fuzzyq.Grid over the task's state (the fuzzy \
             partition each agent observes its variables on)"
                .into(),
        )?;
        let own = OwnSystem {
            task,
            grid: grid.get(),
            gamma: gamma.unwrap_or(fuzzyq_sim::paper::GAMMA),
            max_steps: episode_steps,
            reward_bound,
        };
        learn_own(py, source, learner, &own, &options, starts, progress)
    })
}

/// The argument `name` as a `T`: a `ConfigError` saying `missing` when it is absent, an
/// `InputTypeError` when it is something else.
fn required<'a, 'py, T: pyo3::PyClass>(
    py: Python<'py>,
    arg: Option<&'a Bound<'py, PyAny>>,
    name: &str,
    missing: String,
) -> PyResult<&'a Bound<'py, T>> {
    let arg = arg
        .filter(|a| !a.is_none())
        .ok_or_else(|| error(py, Kind::Config, format!("{name}: {missing}")))?;
    arg.cast::<T>().map_err(|_| {
        error(
            py,
            Kind::InputType,
            format!("{name}: expected a fuzzyq.{}", T::NAME),
        )
    })
}

/// [`learn_from_samples`] of a built-in task: the command line's run.
fn learn_builtin<'py>(
    py: Python<'py>,
    config: &TrainConfig,
    learner: Learner,
    options: &SampleOptions,
    progress: bool,
) -> PyResult<(Py<Policy>, Bound<'py, PyDict>)> {
    let learning =
        SampleLearning::with_options(config, learner, options).map_err(|e| sim_error(py, &e))?;
    let bar = progress
        .then(|| progress_bar(py, learning.fql.episodes, "episode", learner_name(learner)))
        .transpose()?;
    let failure: Mutex<Option<PyErr>> = Mutex::new(None);
    let observer = |_: &EpisodeRecord| {
        Python::attach(|py| match between_episodes(py, bar.as_ref()) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                failure.lock().expect("not poisoned").get_or_insert(e);
                ControlFlow::Break(())
            }
        })
    };
    let started = Instant::now();
    let learned = crate::pool::detach(py, || {
        train::learn_from_samples(config, &learning, observer)
    });
    let seconds = started.elapsed().as_secs_f64();
    if let Some(b) = &bar {
        b.bind(py).call_method0("close")?;
    }
    if let Some(e) = failure.lock().expect("not poisoned").take() {
        return Err(e);
    }
    let learned = learned.map_err(|e| sim_error(py, &e))?;
    let report = report(py, &learned.outcome, learned.lloyd.as_ref(), seconds)?;
    let policy = Policy::from_learned(py, learned.file)?;
    Ok((Py::new(py, policy)?, report))
}

/// A system of your own as an [`Environment`] of the learners: `fuzzyq._interact`'s episodes
/// of a `CallableModel` or a Gymnasium environment, stepped from Rust with the GIL held. Agent
/// `i` observes the state variables `variables[i]`. A Python exception is kept in `failure`
/// and ends the episode (a terminal transition of reward 0); the run then stops.
struct PyEpisodes<'py, 'f> {
    src: Bound<'py, PyAny>,
    n_actions: Vec<usize>,
    variables: Vec<Vec<usize>>,
    state_dim: usize,
    x: Vec<f64>,
    truncated: bool,
    success: bool,
    reward_bound: Option<f64>,
    failure: &'f RefCell<Option<PyErr>>,
}

impl PyEpisodes<'_, '_> {
    /// `value` as a finite state, or the error to keep.
    fn state(&self, value: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
        crate::convert::finite_vector(value, "observation", Some(self.state_dim))
    }

    fn fail(&mut self, e: PyErr) {
        self.failure.borrow_mut().get_or_insert(e);
        self.x.fill(0.0);
    }

    fn try_step(&mut self, actions: &[usize]) -> PyResult<Transition> {
        let joint = actions
            .iter()
            .zip(&self.n_actions)
            .fold(0, |j, (&a, &m)| j * m + a);
        let x = PyArray1::from_slice(self.src.py(), &self.x);
        let out = self.src.call_method1("step", (x, joint))?;
        let (next, reward, terminated, truncated, success): (
            Bound<'_, PyAny>,
            f64,
            bool,
            bool,
            Option<bool>,
        ) = out.extract()?;
        self.x = self.state(&next)?;
        self.truncated = truncated;
        self.success = success.unwrap_or(false);
        Ok(Transition {
            reward,
            terminal: terminated,
        })
    }
}

impl Environment for PyEpisodes<'_, '_> {
    fn n_agents(&self) -> usize {
        self.n_actions.len()
    }
    fn n_actions(&self, agent: usize) -> usize {
        self.n_actions[agent]
    }
    fn obs_dim(&self, agent: usize) -> usize {
        self.variables[agent].len()
    }
    /// Episode `k` of the source, `k` drawn from `rng` (a Gymnasium environment resets with
    /// `seed + k`), so an evaluation's episodes are the same at every evaluation.
    fn reset(&mut self, rng: &mut Pcg64Mcg) {
        let k: u32 = rng.random();
        self.truncated = false;
        self.success = false;
        if self.failure.borrow().is_some() {
            return;
        }
        match self
            .src
            .call_method1("reset", (k,))
            .and_then(|x| self.state(&x))
        {
            Ok(x) => self.x = x,
            Err(e) => self.fail(e),
        }
    }
    fn observe(&self, agent: usize, out: &mut [f64]) {
        for (o, &d) in out.iter_mut().zip(&self.variables[agent]) {
            *o = self.x[d];
        }
    }
    fn step(&mut self, actions: &[usize], _rng: &mut Pcg64Mcg) -> Transition {
        if self.failure.borrow().is_some() {
            return Transition {
                reward: 0.0,
                terminal: true,
            };
        }
        self.try_step(actions).unwrap_or_else(|e| {
            self.fail(e);
            Transition {
                reward: 0.0,
                terminal: true,
            }
        })
    }
    fn success(&self) -> bool {
        self.success
    }
    fn truncated(&self) -> bool {
        self.truncated
    }
    fn reward_bound(&self) -> Option<f64> {
        self.reward_bound
    }
}

/// The state variables each agent of `task` observes: its own block's, when the declared
/// blocks give every agent a block of its own; otherwise the whole state.
fn agent_variables(task: &Task) -> Vec<Vec<usize>> {
    let shape = &task.shape;
    let n = shape.actions.len();
    let mut first = 0;
    let components: Vec<std::ops::Range<usize>> = shape
        .actions
        .iter()
        .map(|(_, dim)| {
            first += dim;
            first - dim..first
        })
        .collect();
    let own: Vec<Option<Vec<usize>>> = components
        .iter()
        .map(|c| {
            let mut blocks = task
                .blocks
                .iter()
                .filter(|(_, comps)| comps.iter().any(|k| c.contains(k)));
            match (blocks.next(), blocks.next()) {
                (Some((vars, comps)), None) if comps.iter().all(|k| c.contains(k)) => {
                    Some(vars.clone())
                }
                _ => None,
            }
        })
        .collect();
    if own.iter().all(Option::is_some) {
        own.into_iter().flatten().collect()
    } else {
        vec![(0..shape.bounds.len()).collect(); n]
    }
}

/// How a system of your own is learned: its declaration, the fuzzy grid and the learner's
/// settings beyond [`SampleOptions`].
struct OwnSystem<'a, 'py> {
    task: &'a Bound<'py, Task>,
    grid: &'a Grid,
    gamma: f64,
    max_steps: Option<usize>,
    /// The largest magnitude of a step's reward, if the user knows it (the projection).
    reward_bound: Option<f64>,
}

/// Learns a system of your own (`source`, through `fuzzyq._interact._episodes`) with fuzzy
/// Q-learning on `grid`'s cores or VQQL, from [`FqlConfig::default`]'s settings.
fn learn_own<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    learner: Learner,
    own: &OwnSystem<'_, 'py>,
    options: &SampleOptions,
    starts: Option<&Bound<'py, PyAny>>,
    progress: bool,
) -> PyResult<(Py<Policy>, Bound<'py, PyDict>)> {
    let task = own.task.get();
    let cores = own.grid.inner.cores();
    if cores.len() != task.shape.bounds.len() {
        return Err(error(
            py,
            Kind::Config,
            format!(
                "grid: the task's state has {} variables, the grid {} dimensions",
                task.shape.bounds.len(),
                cores.len()
            ),
        ));
    }
    let variables = agent_variables(task);
    let mut config = FqlConfig {
        seed: options.seed,
        gamma: own.gamma,
        ..FqlConfig::default()
    };
    if let Some(n) = options.episodes {
        config.episodes = n;
    }
    if let Some(n) = own.max_steps {
        config.max_steps = n;
    }
    if options.literal {
        config.update = fuzzyq_core::additive::Update::Literal;
    }
    config.validate().map_err(|e| config_error(py, &e))?;
    if options.cells.is_some() && learner != Learner::Vqql {
        return Err(error(
            py,
            Kind::Config,
            "cells: applies to the vqql learner only",
        ));
    }
    let rng = py
        .import("numpy.random")?
        .call_method1("default_rng", (options.seed,))?;
    let src = py
        .import("fuzzyq._interact")?
        .getattr("_episodes")?
        .call1((source, own.task, starts, options.seed, rng))?;
    let failure = RefCell::new(None);
    let mut env = PyEpisodes {
        src,
        n_actions: task
            .shape
            .actions
            .iter()
            .map(|(v, d)| v.len() / d)
            .collect(),
        state_dim: cores.len(),
        x: vec![0.0; cores.len()],
        variables: variables.clone(),
        truncated: false,
        success: false,
        reward_bound: own.reward_bound,
        failure: &failure,
    };
    let per_agent: Vec<Vec<Vec<f64>>> = variables
        .iter()
        .map(|vars| vars.iter().map(|&d| cores[d].clone()).collect())
        .collect();
    let (features, lloyd) = features(py, learner, &mut env, per_agent, options, &config)?;
    if let Some(e) = failure.borrow_mut().take() {
        return Err(e);
    }
    let bar = progress
        .then(|| progress_bar(py, config.episodes, "episode", learner_name(learner)))
        .transpose()?;
    let observer = |_: &EpisodeRecord| match between_episodes(py, bar.as_ref()) {
        Ok(()) if failure.borrow().is_none() => ControlFlow::Continue(()),
        Ok(()) => ControlFlow::Break(()),
        Err(e) => {
            failure.borrow_mut().get_or_insert(e);
            ControlFlow::Break(())
        }
    };
    let started = Instant::now();
    let outcome = fql::learn(&mut env, &features, &config, observer);
    let seconds = started.elapsed().as_secs_f64();
    if let Some(b) = &bar {
        b.bind(py).call_method0("close")?;
    }
    if let Some(e) = failure.borrow_mut().take() {
        return Err(e);
    }
    let outcome = outcome.map_err(|e| sim_error(py, &e))?;
    let report = report(py, &outcome, lloyd.as_ref(), seconds)?;
    let data = TaskPolicyData {
        q: outcome.q,
        actions: task.shape.actions.clone(),
        state_dim: cores.len(),
        variables,
        gamma: config.gamma,
    };
    Ok((Py::new(py, Policy::from_task(py, data)?)?, report))
}

fn learner_name(learner: Learner) -> &'static str {
    if learner == Learner::Vqql {
        "VQQL"
    } else {
        "fuzzy Q-learning"
    }
}

/// The learner's features: each agent's fuzzy partition of its variables (fuzzy Q-learning),
/// or codebooks of explored observations (VQQL, as many cells per agent as the largest of
/// those partitions has cores unless `cells` says otherwise).
fn features(
    py: Python<'_>,
    learner: Learner,
    env: &mut PyEpisodes<'_, '_>,
    per_agent: Vec<Vec<Vec<f64>>>,
    options: &SampleOptions,
    config: &FqlConfig,
) -> PyResult<(FeatureSpace, Option<LloydReport>)> {
    let fuzzy = FeatureSpace::new(per_agent).map_err(|e| sim_error(py, &e))?;
    if learner != Learner::Vqql {
        return Ok((fuzzy, None));
    }
    let largest = (0..env.n_agents())
        .map(|i| fuzzy.n_cores(i).unwrap_or(1))
        .max()
        .unwrap_or(1);
    let vqql = VqqlConfig {
        cells: options.cells.unwrap_or(largest),
        explore_steps: config.max_steps,
        seed: options.seed,
        ..VqqlConfig::default()
    };
    let (books, report) = vqql::build_codebook_on(env, &vqql).map_err(|e| sim_error(py, &e))?;
    Ok((books, Some(report)))
}
