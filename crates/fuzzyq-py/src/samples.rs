//! `learn_from_samples`: fuzzy Q-learning and VQQL on the built-in multi-agent tasks, run by
//! the code `fuzzyq train --learner fql|vqql` runs, so the same seed gives the same policy
//! file and learning curve.

use std::ops::ControlFlow;
use std::sync::Mutex;
use std::time::Instant;

use fuzzyq_sim::io::config::TrainConfig;
use fuzzyq_sim::learn::fql::{EpisodeRecord, FqlOutcome, StopReason};
use fuzzyq_sim::model::EnvKind;
use fuzzyq_sim::train::{self, Learner, SampleLearning, SampleOptions};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{arg, describe, parse_option};
use crate::errors::{Kind, config_error, error, guard, sim_error};
use crate::khepera::Khepera;
use crate::model::PointMass;
use crate::policy::Policy;

/// The training configuration `fuzzyq train --env ENV` reads for a built-in multi-agent model.
fn config_of(py: Python<'_>, model: &Bound<'_, PyAny>) -> PyResult<TrainConfig> {
    if let Ok(pm) = model.cast::<PointMass>() {
        let mut c =
            TrainConfig::default_for(EnvKind::Pointmass).map_err(|e| config_error(py, &e))?;
        c.env = fuzzyq_sim::io::config::EnvConfig::Pointmass(pm.get().model.config().clone());
        return Ok(c);
    }
    if let Ok(k) = model.cast::<Khepera>() {
        return k.get().train_config(py);
    }
    Err(error(
        py,
        Kind::Config,
        format!(
            "model: fuzzy Q-learning and VQQL learn the point masses (fuzzyq.PointMass) and the \
             robots (fuzzyq.Khepera), got {}",
            describe(model)
        ),
    ))
}

/// The tqdm bar of `progress=True` over `episodes`.
fn bar(py: Python<'_>, episodes: usize, what: &str) -> PyResult<Py<PyAny>> {
    let tqdm = py.import("tqdm").map_err(|_| {
        error(
            py,
            Kind::Config,
            "progress: progress=True shows a tqdm bar, but tqdm is not installed (pip install tqdm)",
        )
    })?;
    let kwargs = PyDict::new(py);
    kwargs.set_item("total", episodes)?;
    kwargs.set_item("unit", "episode")?;
    kwargs.set_item("desc", what)?;
    Ok(tqdm.getattr("tqdm")?.call((), Some(&kwargs))?.unbind())
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

/// Learns a built-in multi-agent task from samples, as `fuzzyq train --learner fql|vqql`
/// does: fuzzy Q-learning with the additive layout, or VQQL (k-means cells, tabular
/// Q-learning; the point masses only). Returns the greedy, decentralised `Policy` and the
/// run's report (see the stub).
#[pyfunction]
#[pyo3(signature = (model, learner = "fql", *, episodes = None, literal = false, cells = None, seed = 0, progress = false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn learn_from_samples<'py>(
    py: Python<'py>,
    model: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = arg)] learner: &str,
    #[pyo3(from_py_with = arg)] episodes: Option<usize>,
    #[pyo3(from_py_with = arg)] literal: bool,
    #[pyo3(from_py_with = arg)] cells: Option<usize>,
    #[pyo3(from_py_with = arg)] seed: u64,
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
        let config = config_of(py, model)?;
        let options = SampleOptions {
            episodes,
            literal,
            cells,
            seed,
        };
        let learning = SampleLearning::with_options(&config, learner, &options)
            .map_err(|e| sim_error(py, &e))?;
        let what = if learner == Learner::Vqql {
            "VQQL"
        } else {
            "fuzzy Q-learning"
        };
        let bar = progress
            .then(|| bar(py, learning.fql.episodes, what))
            .transpose()?;
        let failure: Mutex<Option<PyErr>> = Mutex::new(None);
        let observer = |_: &EpisodeRecord| {
            Python::attach(|py| {
                let seen = py.check_signals().and_then(|()| match &bar {
                    Some(b) => b.bind(py).call_method1("update", (1,)).map(|_| ()),
                    None => Ok(()),
                });
                match seen {
                    Ok(()) => ControlFlow::Continue(()),
                    Err(e) => {
                        failure.lock().expect("not poisoned").get_or_insert(e);
                        ControlFlow::Break(())
                    }
                }
            })
        };
        let started = Instant::now();
        let learned = crate::pool::detach(py, || {
            train::learn_from_samples(&config, &learning, observer)
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
    })
}
