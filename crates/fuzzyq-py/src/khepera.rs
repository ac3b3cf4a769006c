//! `Khepera`: the paper's Khepera IV robots (sections 3.2-3.3) as a model to solve from Python.

use std::sync::Arc;

use fuzzyq_core::model::joint_actions;
use fuzzyq_sim::io::config::{EnvConfig, TrainConfig};
use fuzzyq_sim::model::khepera::KheperaConfig;
use fuzzyq_sim::model::{Dynamics, EnvKind, EnvModel, F64Model};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use serde_json::Value;

use crate::convert::{arg, finite_vector};
use crate::errors::{Kind, config_error, error, eval_error, guard};
use crate::model::Grid;

/// The paper's Khepera IV robots (sections 3.2-3.3), solved on their kinematic model.
///
/// `Khepera(agents=2, **params)`: every field of `[env]` in `fuzzyq config --env khepera`
/// (`radius`, `forward_speed`, `turn_speed`, `sample_time`, `goal_radius`, `goal_reward`,
/// `collision_penalty`, the sonars, `arena` as a dict with `x`, `y` and `obstacle`, `noise`,
/// ...) is a keyword argument. The state fuzzy Q-iteration solves is each robot's pose
/// `[x, y, heading]`; its four actions are forward, turn clockwise, turn counter-clockwise and
/// stop. `grid()` is the default grid (`fuzzyq train --env khepera`); `solve(robots,
/// robots.grid())` trains as the command line does, and the solution's policies roll out on
/// the rapier plant with sonars (`Policy.rollout`, `Policy.evaluate`).
#[pyclass(module = "fuzzyq", frozen)]
pub struct Khepera {
    pub(crate) config: KheperaConfig,
    model: Arc<EnvModel>,
}

impl Khepera {
    fn from_config(py: Python<'_>, config: KheperaConfig) -> PyResult<Self> {
        let model = EnvConfig::Khepera(config.clone())
            .build()
            .map_err(|e| config_error(py, &e))?;
        Ok(Self {
            config,
            model: Arc::new(model),
        })
    }

    /// Rebuilds a pickled model: its configuration as JSON.
    pub(crate) fn restore(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let json: String = data.extract()?;
        let config: KheperaConfig = serde_json::from_str(&json)
            .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
        Ok(Py::new(py, Self::from_config(py, config)?)?.into_any())
    }

    /// The default training configuration of these robots.
    pub(crate) fn train_config(&self, py: Python<'_>) -> PyResult<TrainConfig> {
        let mut c = TrainConfig::default_for(EnvKind::Khepera).map_err(|e| config_error(py, &e))?;
        c.env = EnvConfig::Khepera(self.config.clone());
        Ok(c)
    }

    fn m(&self) -> &EnvModel {
        &self.model
    }
}

#[pymethods]
impl Khepera {
    #[new]
    #[pyo3(signature = (agents = 2, **params))]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = arg)] agents: usize,
        params: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        guard(py, || {
            let mut value = serde_json::to_value(KheperaConfig::default())
                .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
            if let (Value::Object(base), Some(p)) = (&mut value, params)
                && let Value::Object(given) = crate::json::to_value(p.as_any(), "khepera")?
            {
                for (k, v) in given {
                    if !base.contains_key(&k) {
                        return Err(error(
                            py,
                            Kind::Config,
                            format!("khepera: unknown parameter {k:?}"),
                        ));
                    }
                    base.insert(k, v);
                }
            }
            value["agents"] = Value::from(agents);
            let config: KheperaConfig = serde_json::from_value(value).map_err(|e| {
                let kind = if e.to_string().starts_with("invalid type") {
                    Kind::InputType
                } else {
                    Kind::Config
                };
                error(py, kind, format!("khepera: {e}"))
            })?;
            Self::from_config(py, config)
        })
    }

    /// Length of the state: 3 per robot (`x`, `y`, heading).
    #[getter]
    fn state_dim(&self) -> usize {
        F64Model::state_dim(self.m())
    }

    /// Number of robots.
    #[getter]
    fn n_agents(&self) -> usize {
        F64Model::n_agents(self.m())
    }

    /// Length of the joint action vector (two wheel speeds per robot).
    #[getter]
    fn action_dim(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || {
            Ok(joint_actions::<f64, _>(self.m())
                .map_err(|e| eval_error(py, &e))?
                .dim())
        })
    }

    /// Number of joint actions (`4 ** agents`).
    #[getter]
    fn n_joint_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || {
            Ok(joint_actions::<f64, _>(self.m())
                .map_err(|e| eval_error(py, &e))?
                .n_joint())
        })
    }

    /// The control period, seconds.
    #[getter]
    fn sample_time(&self) -> f64 {
        Dynamics::sample_time(self.m())
    }

    /// Every parameter, as the configuration's `[env]` table.
    #[getter]
    fn params(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let v = serde_json::to_value(&self.config)
            .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
        Ok(crate::json::to_python(py, &v)?.unbind())
    }

    /// The joint action vector (wheel speeds) of joint action `index`.
    fn joint_action<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || {
            let j = joint_actions::<f64, _>(self.m()).map_err(|e| eval_error(py, &e))?;
            crate::joint::vector(py, &j, index)
        })
    }

    /// The kinematic model's successor of poses `x` under wheel speeds `u`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim()))?;
            let u = finite_vector(u, "u", Some(self.action_dim(py)?))?;
            let mut next = vec![0.0; x.len()];
            Dynamics::step(self.m(), &x, &u, &mut next);
            Ok(PyArray1::from_vec(py, next))
        })
    }

    /// The reward `rho(x, u)` (eq 42: the goal reward near the origin, the collision penalty
    /// where robots overlap).
    fn reward(&self, py: Python<'_>, x: &Bound<'_, PyAny>, u: &Bound<'_, PyAny>) -> PyResult<f64> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim()))?;
            let u = finite_vector(u, "u", Some(self.action_dim(py)?))?;
            Ok(Dynamics::reward(
                self.m(),
                &x,
                &u,
                fuzzyq_core::solver::Precision::F64,
            ))
        })
    }

    /// The default grid of these robots (`fuzzyq train --env khepera`): per robot the
    /// position cores on `x` and `y` and 17 heading cores over `[-pi, pi]`.
    fn grid(&self, py: Python<'_>) -> PyResult<Grid> {
        guard(py, || {
            let cores = self.train_config(py)?.grid_cores();
            Grid::checked(py, cores)
        })
    }

    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let json = serde_json::to_string(&self.config)
            .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
        crate::pickle::reduce(py, "khepera", json.into_pyobject(py)?.into_any())
    }

    fn __repr__(&self) -> String {
        format!(
            "Khepera(agents={}, sample_time={})",
            self.config.agents, self.config.sample_time
        )
    }
}
