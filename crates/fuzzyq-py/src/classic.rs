//! The classic single-agent benchmarks (Busoniu et al. 2010): `ClassicModel` and its four
//! subclasses `DcMotor`, `Pendulum`, `CarHill` and `Arm`, built from the sim crate's
//! configuration types and presets (the same models `fuzzyq train --env ...` builds).

use std::sync::Arc;

use fuzzyq_core::Model;
use fuzzyq_core::model::joint_actions;
use fuzzyq_sim::io::config::{ClassicEnv, EnvConfig, GridConfig};
use fuzzyq_sim::model::classic::arm::Arm as ArmDynamics;
use fuzzyq_sim::model::classic::carhill::CarHill as CarHillDynamics;
use fuzzyq_sim::model::classic::dcmotor::DcMotor as DcMotorDynamics;
use fuzzyq_sim::model::classic::pendulum::Pendulum as PendulumDynamics;
use fuzzyq_sim::model::classic::{self, Benchmark, Preset};
use fuzzyq_sim::model::{Dynamics, EnvModel, F64Model};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use crate::convert::{arg, distinct, finite_vector, one_or_batch};
use crate::errors::{Kind, config_error, error, eval_error, guard};
use crate::model::Grid;

/// A classic benchmark: the base class of `DcMotor`, `Pendulum`, `CarHill` and `Arm`.
///
/// One agent; the model computes in float64. `preset` names the grid, actions, `gamma` and
/// `xi` of a toolbox run (`grid()`, `gamma`, `xi`); `fuzzyq.solve(model, model.grid())` solves
/// it as `fuzzyq train --env ENV --preset PRESET` does.
#[pyclass(module = "fuzzyq", subclass, frozen)]
pub struct ClassicModel {
    /// The environment as a configuration file describes it (actions and parameters).
    pub(crate) env: EnvConfig,
    pub(crate) model: Arc<EnvModel>,
    preset: Preset,
}

/// The model's parameters from keyword arguments: the configuration's fields (`[env.model]`
/// of a config file), each optional. `integrator="rk4"` stands for RK4 with the model's
/// default number of substeps (one step per sample time for the DC motor, whose default is
/// the exact `"zoh"`).
fn parameters<S>(py: Python<'_>, params: Option<&Bound<'_, PyDict>>) -> PyResult<S::Config>
where
    S: Benchmark,
    S::Config: Serialize + DeserializeOwned,
{
    let name = S::ENV.name();
    let mut value = match params {
        Some(d) => crate::json::to_value(d.as_any(), name)?,
        None => Value::Object(Map::new()),
    };
    if let Value::Object(m) = &mut value
        && m.get("integrator").and_then(Value::as_str) == Some("rk4")
    {
        let defaults = serde_json::to_value(S::Config::default()).unwrap_or(Value::Null);
        let substeps = defaults
            .pointer("/integrator/rk4/substeps")
            .and_then(Value::as_u64)
            .unwrap_or(1);
        m.insert(
            "integrator".into(),
            serde_json::json!({ "rk4": { "substeps": substeps } }),
        );
    }
    // Each field alone first (the others default), so that an error names its field.
    if let Value::Object(m) = &value {
        for (key, v) in m {
            let mut one = Map::new();
            one.insert(key.clone(), v.clone());
            serde_json::from_value::<S::Config>(Value::Object(one))
                .map_err(|e| error(py, serde_kind(&e), format!("{name}.{key}: {e}")))?;
        }
    }
    serde_json::from_value(value).map_err(|e| error(py, serde_kind(&e), format!("{name}: {e}")))
}

/// The class of a parameter the configuration cannot read: a value of the wrong type (serde's
/// `invalid type: ...`) is an `InputTypeError`, any other (unknown field, value out of range) a
/// `ConfigError`.
fn serde_kind(e: &serde_json::Error) -> Kind {
    if e.to_string().starts_with("invalid type") {
        Kind::InputType
    } else {
        Kind::Config
    }
}

impl ClassicModel {
    fn build<S>(
        py: Python<'_>,
        preset: &str,
        actions: Option<&Bound<'_, PyAny>>,
        params: Option<&Bound<'_, PyDict>>,
        wrap: fn(ClassicEnv<S::Config>) -> EnvConfig,
    ) -> PyResult<Self>
    where
        S: Benchmark,
        S::Config: Serialize + DeserializeOwned,
    {
        let preset = classic::preset::<S>(preset).map_err(|e| config_error(py, &e))?;
        let config = parameters::<S>(py, params)?;
        let actions = match actions {
            Some(a) => finite_vector(a, "actions", None)?,
            None => preset.actions.clone(),
        };
        distinct(py, "actions", "level", &actions, 1)?;
        let env = wrap(ClassicEnv {
            actions,
            model: config,
        });
        let model = env.build().map_err(|e| config_error(py, &e))?;
        Ok(Self {
            env,
            model: Arc::new(model),
            preset,
        })
    }

    /// The grid configuration of `grid` for this environment (explicit cores).
    pub(crate) fn grid_config(grid: &Grid) -> GridConfig {
        let mut g = GridConfig::explicit(grid.inner.cores().to_vec());
        g.position_cores.clear();
        g.velocity_cores.clear();
        g.membership = grid.inner.membership();
        g
    }

    /// The preset's name (its solver defaults are `fuzzyq train --preset`'s).
    pub(crate) fn preset_name(&self) -> &str {
        &self.preset.name
    }

    fn m(&self) -> &EnvModel {
        &self.model
    }

    fn action_dim_(&self) -> usize {
        F64Model::actions(self.m()).dim()
    }

    fn params_value(&self) -> serde_json::Result<Value> {
        match &self.env {
            EnvConfig::Dcmotor(c) => serde_json::to_value(&c.model),
            EnvConfig::Pendulum(c) => serde_json::to_value(&c.model),
            EnvConfig::Carhill(c) => serde_json::to_value(&c.model),
            EnvConfig::Arm(c) => serde_json::to_value(&c.model),
            _ => Ok(Value::Null),
        }
    }

    fn levels(&self) -> &[f64] {
        match &self.env {
            EnvConfig::Dcmotor(c) => &c.actions,
            EnvConfig::Pendulum(c) => &c.actions,
            EnvConfig::Carhill(c) => &c.actions,
            EnvConfig::Arm(c) => &c.actions,
            _ => &[],
        }
    }
}

#[pymethods]
impl ClassicModel {
    /// The environment's name (`"dcmotor"`, `"pendulum"`, `"carhill"`, `"arm"`).
    #[getter]
    fn env(&self) -> &'static str {
        self.model.name()
    }

    /// The preset's name.
    #[getter]
    fn preset(&self) -> &str {
        &self.preset.name
    }

    /// The preset's discount factor (the default of `fuzzyq.solve` for this model).
    #[getter]
    fn gamma(&self) -> f64 {
        self.preset.gamma
    }

    /// The preset's stopping threshold (the default of `fuzzyq.solve` for this model).
    #[getter]
    fn xi(&self) -> f64 {
        self.preset.xi
    }

    /// The preset's grid.
    fn grid(&self, py: Python<'_>) -> PyResult<Grid> {
        guard(py, || {
            let g = self
                .preset
                .grid::<f64>()
                .map_err(|e| crate::errors::sim_error(py, &e))?;
            Ok(Grid::from_inner(g))
        })
    }

    /// The model's parameters (the configuration's `[env.model]` fields), as a dict.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        guard(py, || {
            let v = self
                .params_value()
                .map_err(|e| error(py, Kind::Solver, e.to_string()))?;
            crate::json::to_python(py, &v)
        })
    }

    /// Length of the state vector.
    #[getter]
    fn state_dim(&self) -> usize {
        F64Model::state_dim(self.m())
    }

    /// Number of agents (1).
    #[getter]
    fn n_agents(&self) -> usize {
        1
    }

    /// Length of an action vector.
    #[getter]
    fn action_dim(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.action_dim_()))
    }

    /// Number of discrete actions.
    #[getter]
    fn n_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(F64Model::actions(self.m()).len()))
    }

    /// Number of joint actions (the actions: one agent).
    #[getter]
    fn n_joint_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(F64Model::actions(self.m()).len()))
    }

    /// The listed action levels (the configuration's `actions`; for the arm, torque levels as
    /// fractions of each joint's maximum torque, combined per joint).
    #[getter]
    fn action_levels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || Ok(PyArray1::from_slice(py, self.levels())))
    }

    /// The discrete action vectors, shape `(n_actions, action_dim)`.
    #[getter]
    fn actions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            Ok({
                let table = F64Model::actions(self.m());
                let a = Array2::from_shape_vec((table.len(), table.dim()), table.values().to_vec())
                    .expect("n x dim values");
                PyArray2::from_owned_array(py, a)
            })
        })
    }

    /// Sample time (s).
    #[getter]
    fn sample_time(&self, py: Python<'_>) -> PyResult<f64> {
        guard(py, || Ok(Dynamics::sample_time(self.m())))
    }

    /// The range `(low, high)` of every state variable, shape `(state_dim, 2)`.
    #[getter]
    fn state_bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            Ok({
                let e = F64Model::state_dim(self.m());
                let flat: Vec<f64> = (0..e)
                    .flat_map(|d| {
                        let (lo, hi) = Dynamics::state_bounds(self.m(), d);
                        [lo, hi]
                    })
                    .collect();
                PyArray2::from_owned_array(py, Array2::from_shape_vec((e, 2), flat).expect("pairs"))
            })
        })
    }

    /// The default start of a rollout (`fuzzyq rollout`'s).
    #[getter]
    fn default_start<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || {
            Ok(PyArray1::from_slice(
                py,
                self.model.kind().spec().default_start,
            ))
        })
    }

    /// The action vector of action `index`.
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

    /// The successor of state `x` under action vector `u` and the reward of `u` at `x`:
    /// `(next_state, reward)`; also batches: `x` of shape `(n, state_dim)` with `u` of shape
    /// `(n, action_dim)` give `(next_states (n, state_dim), rewards (n,))`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        guard(py, || {
            let (e, a) = (self.state_dim(), self.action_dim_());
            let (xs, bx) = one_or_batch(x, "x", e)?;
            let (us, bu) = one_or_batch(u, "u", a)?;
            crate::model::same_batch(py, bx, bu)?;
            let n = bx.unwrap_or(1);
            let mut next = vec![0.0; n * e];
            let mut rewards = vec![0.0; n];
            let m = self.m();
            for i in 0..n {
                let (x, u) = (&xs[i * e..(i + 1) * e], &us[i * a..(i + 1) * a]);
                rewards[i] = Model::<f64>::reward(m, x, u);
                Dynamics::step(m, x, u, &mut next[i * e..(i + 1) * e]);
            }
            match bx {
                None => (PyArray1::from_vec(py, next), rewards[0]).into_pyobject(py),
                Some(b) => (
                    PyArray2::from_owned_array(
                        py,
                        Array2::from_shape_vec((b, e), next).expect("b x e"),
                    ),
                    PyArray1::from_vec(py, rewards),
                )
                    .into_pyobject(py),
            }
        })
    }

    /// The reward of action vector `u` at state `x`.
    fn reward(&self, py: Python<'_>, x: &Bound<'_, PyAny>, u: &Bound<'_, PyAny>) -> PyResult<f64> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim()))?;
            let u = finite_vector(u, "u", Some(self.action_dim_()))?;
            Ok(Model::<f64>::reward(self.m(), &x, &u))
        })
    }

    /// Whether `x` is a terminal state (the car that left the hill); a rollout stops there.
    fn is_terminal(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<bool> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim()))?;
            Ok(Dynamics::has_terminal_states(self.m()) && Dynamics::is_terminal(self.m(), &x))
        })
    }

    /// Pickling: the preset's name, the actions and every parameter, as keyword arguments of
    /// the class.
    fn __getnewargs_ex__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
        let value = serde_json::to_value(&self.env)
            .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
        let json = py.import("json")?;
        let kwargs = PyDict::new(py);
        if let Some(model) = value.get("model") {
            let params = json.call_method1("loads", (model.to_string(),))?;
            kwargs.update(params.cast::<pyo3::types::PyMapping>()?)?;
        }
        if let Some(actions) = value.get("actions") {
            kwargs.set_item(
                "actions",
                json.call_method1("loads", (actions.to_string(),))?,
            )?;
        }
        Ok((PyTuple::new(py, [self.preset.name.as_str()])?, kwargs))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok({
                let class = match self.model.kind() {
                    fuzzyq_sim::model::EnvKind::Dcmotor => "DcMotor",
                    fuzzyq_sim::model::EnvKind::Pendulum => "Pendulum",
                    fuzzyq_sim::model::EnvKind::Carhill => "CarHill",
                    _ => "Arm",
                };
                format!(
                    "{class}(preset={:?}, actions={}, sample_time={})",
                    self.preset.name,
                    F64Model::actions(self.m()).len(),
                    Dynamics::sample_time(self.m())
                )
            })
        })
    }
}

macro_rules! classic_class {
    ($(#[$doc:meta])* $name:ident, $dynamics:ty, $variant:ident) => {
        $(#[$doc])*
        #[pyclass(module = "fuzzyq", extends = ClassicModel, frozen)]
        pub struct $name {}

        #[pymethods]
        impl $name {
            #[new]
            #[pyo3(signature = (preset = "fine", *, actions = None, **params))]
            fn new(
                py: Python<'_>,
                #[pyo3(from_py_with = arg)] preset: &str,
                actions: Option<&Bound<'_, PyAny>>,
                params: Option<&Bound<'_, PyDict>>,
            ) -> PyResult<PyClassInitializer<Self>> {
                guard(py, || {
                    let base = ClassicModel::build::<$dynamics>(
                        py,
                        preset,
                        actions,
                        params,
                        EnvConfig::$variant,
                    )?;
                    Ok(PyClassInitializer::from(base).add_subclass(Self {}))
                })
            }
        }
    };
}

classic_class!(
    /// The DC motor (Busoniu et al. 2010, section 4.5.3): state `[angle, angular velocity]`,
    /// voltage actions.
    ///
    /// `DcMotor(preset="fine", *, actions=None, **params)`: `preset` is `"toolbox-demo"` or
    /// `"fine"`; `actions` defaults to the preset's; `params` are the configuration's fields
    /// (`inertia`, `damping`, `torque_constant`, `resistance`, `sample_time`, `max_angle`,
    /// `max_velocity`, `q`, `r`, `integrator`).
    DcMotor,
    DcMotorDynamics,
    Dcmotor
);

classic_class!(
    /// The inverted pendulum swing-up: state `[angle (0 = up), angular velocity]`, voltage
    /// actions.
    ///
    /// `Pendulum(preset="fine", *, actions=None, **params)`: `preset` is `"toolbox-demo"` or
    /// `"fine"`; `params` are the configuration's fields (`disc_inertia`, `mass`, `length`,
    /// `gravity`, `damping`, `torque_constant`, `resistance`, `sample_time`, `max_velocity`,
    /// `max_voltage`, `q`, `r`, `integrator`).
    Pendulum,
    PendulumDynamics,
    Pendulum
);

classic_class!(
    /// The car on the hill: state `[position, velocity]`, force actions; a run ends when the
    /// car leaves the hill.
    ///
    /// `CarHill(preset="fine", *, actions=None, **params)`: `preset` is `"fine"` or
    /// `"coarse"`; `params` are the configuration's fields (`mass`, `gravity`, `sample_time`,
    /// `position_limit`, `velocity_limit`, `integrator`).
    CarHill,
    CarHillDynamics,
    Carhill
);

classic_class!(
    /// The two-link robot arm: state `[angle 1, angular velocity 1, angle 2, angular
    /// velocity 2]`, torque actions (the action levels are fractions of each joint's maximum
    /// torque, combined per joint).
    ///
    /// `Arm(preset="fine", *, actions=None, **params)`: `preset` is `"fine"` or `"coarse"`;
    /// `params` are the configuration's fields (`link_lengths`, `masses`, `inertias`,
    /// `centres_of_mass`, `damping`, `max_velocity`, `max_torque`, `q`, `r`, `sample_time`,
    /// `wrap`, `integrator`).
    Arm,
    ArmDynamics,
    Arm
);
