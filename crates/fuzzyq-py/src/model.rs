//! `Grid` and `PointMass`.

use std::sync::Arc;

use fuzzyq_core::model::joint_actions;
use fuzzyq_core::{ActionSet, JointActions, Model};
use fuzzyq_sim::model::pointmass::{
    FrictionConfig, FrictionPatch, Integrator, PointMassConfig, RewardShape,
};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::convert::{Patch, arg, distinct, finite_vector, one_or_batch, vector};
use crate::errors::{Kind, config_error, error, eval_error, guard};

/// Active core indices and their memberships.
type Memberships<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<f64>>);

/// A fuzzy grid: triangular membership functions on each state variable, combined by product.
///
/// `Grid(cores)` takes one increasing sequence of cores per state variable. Cores are numbered
/// in row-major (C) order: `values.reshape(grid.shape)` views per-core values as an array over
/// the grid.
#[pyclass(module = "fuzzyq", frozen)]
pub struct Grid {
    pub(crate) inner: fuzzyq_core::solver::Grid<f64>,
}

impl Grid {
    /// Rebuilds a pickled grid: `(cores, membership name)`.
    pub(crate) fn restore(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let (cores, membership): (Vec<Vec<f64>>, String) = data.extract()?;
        let membership: fuzzyq_core::Membership = membership
            .parse()
            .map_err(|e| error(py, Kind::Input, format!("_restore: membership: {e}")))?;
        let mut grid = Self::checked(py, cores)?;
        grid.inner = grid.inner.with_membership(membership);
        Ok(Py::new(py, grid)?.into_any())
    }

    pub(crate) fn from_inner(inner: fuzzyq_core::solver::Grid<f64>) -> Self {
        Self { inner }
    }

    /// A grid of `cores`, checked in both precisions: cores beyond `f32`'s range, or too close
    /// to stay distinct in it, are refused here rather than when the grid is solved in `f32`.
    pub(crate) fn checked(py: Python<'_>, cores: Vec<Vec<f64>>) -> PyResult<Self> {
        let inner = fuzzyq_core::solver::Grid::new(cores)
            .map_err(|e| error(py, Kind::Config, format!("cores: {e}")))?;
        let grid = Self { inner };
        grid.to_precision::<f32>(py)?;
        Ok(grid)
    }

    /// The grid in precision `T`.
    pub(crate) fn to_precision<T: fuzzyq_core::Real>(
        &self,
        py: Python<'_>,
    ) -> PyResult<fuzzyq_core::solver::Grid<T>> {
        let cores = self
            .inner
            .cores()
            .iter()
            .map(|c| c.iter().map(|&v| T::from_f64(v)).collect())
            .collect();
        Ok(fuzzyq_core::solver::Grid::new(cores)
            .map_err(|e| {
                error(
                    py,
                    Kind::Config,
                    format!("cores: the grid in single precision: {e}"),
                )
            })?
            .with_membership(self.inner.membership()))
    }
}

/// Checks that a batch of states and one of actions have the same size.
pub(crate) fn same_batch(py: Python<'_>, bx: Option<usize>, bu: Option<usize>) -> PyResult<()> {
    if bx == bu {
        return Ok(());
    }
    Err(error(
        py,
        Kind::Input,
        format!(
            "x and u: expected the same batch size, got {} and {}",
            bx.map_or("none".into(), |b| b.to_string()),
            bu.map_or("none".into(), |b| b.to_string())
        ),
    ))
}

#[pymethods]
impl Grid {
    #[new]
    fn new(py: Python<'_>, cores: &Bound<'_, PyAny>) -> PyResult<Self> {
        guard(py, || {
            let items = cores.try_iter().map_err(|_| {
                error(
                    py,
                    Kind::InputType,
                    "cores: expected a sequence of 1-D arrays, one per state variable",
                )
            })?;
            let mut all = Vec::new();
            for (i, item) in items.enumerate() {
                all.push(vector(&item?, &format!("cores[{i}]"), None)?);
            }
            Self::checked(py, all)
        })
    }

    /// Number of state variables.
    #[getter]
    fn n_dims(&self) -> usize {
        self.inner.n_dims()
    }

    /// Number of joint cores (the product of the per-variable counts).
    #[getter]
    fn n_cores(&self) -> usize {
        self.inner.n_cores()
    }

    /// Cores per state variable, as a tuple.
    #[getter]
    fn shape<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, self.inner.cores().iter().map(Vec::len))
    }

    /// The cores of each state variable.
    #[getter]
    fn cores<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<f64>>> {
        self.inner
            .cores()
            .iter()
            .map(|c| PyArray1::from_slice(py, c))
            .collect()
    }

    /// The active cores of state `x` and their memberships (which sum to 1).
    fn memberships<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Memberships<'py>> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.inner.n_dims()))?;
            let active = self
                .inner
                .view()
                .active(&x)
                .map_err(|e| eval_error(py, &e))?;
            let (mut idx, mut w) = (Vec::new(), Vec::new());
            active.for_each(|d, m| {
                idx.push(d as i64);
                w.push(m);
            });
            Ok((PyArray1::from_vec(py, idx), PyArray1::from_vec(py, w)))
        })
    }

    /// The state at which core `index` has membership 1.
    fn core_state<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || {
            let mut x = vec![0.0; self.inner.n_dims()];
            self.inner
                .view()
                .core_state(index, &mut x)
                .map_err(|e| eval_error(py, &e))?;
            Ok(PyArray1::from_vec(py, x))
        })
    }

    /// Every core's state, shape `(n_cores, n_dims)`.
    fn core_states<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            let (n, e) = (self.inner.n_cores(), self.inner.n_dims());
            if n.saturating_mul(e) > 200_000_000 {
                return Err(error(
                    py,
                    Kind::Input,
                    format!("core_states: {n} x {e} values are too many to return"),
                ));
            }
            let view = self.inner.view();
            let mut out = vec![0.0; n * e];
            for (d, row) in out.chunks_exact_mut(e).enumerate() {
                view.core_state(d, row)
                    .map_err(|err| eval_error(py, &err))?;
            }
            let a = Array2::from_shape_vec((n, e), out).expect("n x e values");
            Ok(PyArray2::from_owned_array(py, a))
        })
    }

    /// The fuzzy interpolation `sum_d mu_d(x) values[d]` of per-core values at `x`.
    fn interpolate(
        &self,
        py: Python<'_>,
        values: &Bound<'_, PyAny>,
        x: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        guard(py, || {
            let v = vector(values, "values", Some(self.inner.n_cores()))?;
            let x = finite_vector(x, "x", Some(self.inner.n_dims()))?;
            let active = self
                .inner
                .view()
                .active(&x)
                .map_err(|e| eval_error(py, &e))?;
            Ok(active.interpolate(&v))
        })
    }

    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let data = (
            self.inner.cores().to_vec(),
            fuzzyq_core::NamedOption::name(self.inner.membership()),
        );
        crate::pickle::reduce(py, "grid", data.into_pyobject(py)?.into_any())
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok({
                let shape: Vec<String> = self
                    .inner
                    .cores()
                    .iter()
                    .map(|c| c.len().to_string())
                    .collect();
                format!(
                    "Grid(shape=({}), n_cores={})",
                    shape.join(", "),
                    self.inner.n_cores()
                )
            })
        })
    }
}

/// The point-mass task of the paper's section 3.1 for `agents` agents.
///
/// Each agent is a point mass on the plane with friction, `m s'' = -eta s' + u`; forces are
/// held over each sample time. The state is `[s1x, s1y, v1x, v1y, s2x, ...]`; each agent's
/// actions are the square of `force_levels` (`u_x` slowest); the shared reward is
/// `goal_reward` while the whole state is within `goal_radius` of the origin.
/// `velocity_noise` (m/s, default 0) is the standard deviation of the plant's Gaussian
/// process noise on every velocity per step; the model solved stays noise-free.
#[pyclass(module = "fuzzyq", frozen)]
pub struct PointMass {
    pub(crate) model: Arc<fuzzyq_sim::PointMass>,
}

impl PointMass {
    /// Rebuilds a pickled point-mass model: its configuration as JSON.
    pub(crate) fn restore(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let json: String = data.extract()?;
        let config: PointMassConfig = serde_json::from_str(&json)
            .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
        Ok(Py::new(py, Self::from_config(py, config)?)?.into_any())
    }

    pub(crate) fn from_config(py: Python<'_>, config: PointMassConfig) -> PyResult<Self> {
        let model = fuzzyq_sim::PointMass::new(config).map_err(|e| config_error(py, &e))?;
        Ok(Self {
            model: Arc::new(model),
        })
    }

    fn joint(&self) -> JointActions<'_, f64> {
        joint_actions(&*self.model).expect("a validated point mass")
    }
}

#[pymethods]
impl PointMass {
    #[new]
    #[pyo3(signature = (
        agents = 2,
        *,
        mass = 0.5,
        sample_time = 0.4,
        position_limit = 6.0,
        velocity_limit = 3.0,
        force_levels = None,
        goal_radius = 0.1,
        goal_reward = 5.0,
        integrator = "exact",
        rk4_substeps = 10,
        friction = 1.0,
        friction_patches = None,
        velocity_noise = 0.0,
        reward = "paper",
        shaping_discount = 0.96,
    ))]
    #[allow(clippy::too_many_arguments)] // the model's parameters, as keyword arguments
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = arg)] agents: usize,
        #[pyo3(from_py_with = arg)] mass: f64,
        #[pyo3(from_py_with = arg)] sample_time: f64,
        #[pyo3(from_py_with = arg)] position_limit: f64,
        #[pyo3(from_py_with = arg)] velocity_limit: f64,
        force_levels: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = arg)] goal_radius: f64,
        #[pyo3(from_py_with = arg)] goal_reward: f64,
        #[pyo3(from_py_with = arg)] integrator: &str,
        #[pyo3(from_py_with = arg)] rk4_substeps: usize,
        #[pyo3(from_py_with = arg)] friction: f64,
        #[pyo3(from_py_with = arg)] friction_patches: Option<Vec<Patch>>,
        #[pyo3(from_py_with = arg)] velocity_noise: f64,
        #[pyo3(from_py_with = arg)] reward: &str,
        #[pyo3(from_py_with = arg)] shaping_discount: f64,
    ) -> PyResult<Self> {
        guard(py, || {
            let reward = RewardShape::parse(reward, "reward").map_err(|e| config_error(py, &e))?;
            let integrator = match integrator {
                "exact" => Integrator::Exact,
                "rk4" => Integrator::Rk4,
                other => {
                    return Err(error(
                        py,
                        Kind::Config,
                        format!("integrator: expected \"exact\" or \"rk4\", got {other:?}"),
                    ));
                }
            };
            let force_levels = match force_levels {
                Some(f) => finite_vector(f, "force_levels", None)?,
                None => PointMassConfig::default().force_levels,
            };
            distinct(py, "force_levels", "level", &force_levels, 1)?;
            let friction = match friction_patches {
                None => FrictionConfig::Constant { eta: friction },
                Some(p) => FrictionConfig::Patches {
                    base: friction,
                    patches: p
                        .into_iter()
                        .map(|((x, y), radius, eta)| FrictionPatch {
                            center: [x, y],
                            radius,
                            eta,
                        })
                        .collect(),
                },
            };
            Self::from_config(
                py,
                PointMassConfig {
                    agents,
                    mass,
                    sample_time,
                    position_limit,
                    velocity_limit,
                    force_levels,
                    goal_radius,
                    goal_reward,
                    integrator,
                    rk4_substeps,
                    friction,
                    velocity_noise,
                    reward,
                    shaping_discount,
                },
            )
        })
    }

    /// Length of the state vector, `4 * agents`.
    #[getter]
    fn state_dim(&self) -> usize {
        self.model.config().state_dim()
    }

    /// Number of agents.
    #[getter]
    fn n_agents(&self) -> usize {
        self.model.config().agents
    }

    /// Length of the joint action vector, `2 * agents`.
    #[getter]
    fn action_dim(&self) -> usize {
        2 * self.model.config().agents
    }

    /// Actions per agent.
    #[getter]
    fn n_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || {
            Ok(Model::<f64>::action_set(&*self.model, 0).n_actions())
        })
    }

    /// Joint actions, `n_actions ** agents`.
    #[getter]
    fn n_joint_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.joint().n_joint()))
    }

    /// Sample time (s).
    #[getter]
    fn sample_time(&self) -> f64 {
        self.model.config().sample_time
    }

    /// Positions are clamped to `[-position_limit, position_limit]`.
    #[getter]
    fn position_limit(&self) -> f64 {
        self.model.config().position_limit
    }

    /// Velocities are clamped to `[-velocity_limit, velocity_limit]`.
    #[getter]
    fn velocity_limit(&self) -> f64 {
        self.model.config().velocity_limit
    }

    /// The reward region's radius.
    #[getter]
    fn goal_radius(&self) -> f64 {
        self.model.config().goal_radius
    }

    /// The reward inside the region.
    #[getter]
    fn goal_reward(&self) -> f64 {
        self.model.config().goal_reward
    }

    /// Each agent's actions, shape `(n_actions, 2)`: forces `(u_x, u_y)`.
    #[getter]
    fn actions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            Ok({
                let set: ActionSet<'_, f64> = Model::<f64>::action_set(&*self.model, 0);
                let a = Array2::from_shape_vec((set.n_actions(), 2), set.values().to_vec())
                    .expect("pairs");
                PyArray2::from_owned_array(py, a)
            })
        })
    }

    /// The joint action vector (all agents' forces) of joint action `index`.
    fn joint_action<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || crate::joint::vector(py, &self.joint(), index))
    }

    /// The joint action index of per-agent action indices.
    fn joint_index(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = arg)] per_agent: Vec<usize>,
    ) -> PyResult<usize> {
        guard(py, || crate::joint::index(py, &self.joint(), &per_agent))
    }

    /// The per-agent action indices of joint action `index`.
    fn agent_indices(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Vec<usize>> {
        guard(py, || crate::joint::per_agent(py, &self.joint(), index))
    }

    /// The successor of state `x` under joint force vector `u`; also batches: `x` of shape
    /// `(n, state_dim)` with `u` of shape `(n, action_dim)`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        guard(py, || {
            let (e, a) = (self.state_dim(), self.action_dim());
            let (xs, bx) = one_or_batch(x, "x", e)?;
            let (us, bu) = one_or_batch(u, "u", a)?;
            same_batch(py, bx, bu)?;
            let n = bx.unwrap_or(1);
            let mut out = vec![0.0; n * e];
            for i in 0..n {
                self.model.step_f64(
                    &xs[i * e..(i + 1) * e],
                    &us[i * a..(i + 1) * a],
                    &mut out[i * e..(i + 1) * e],
                );
            }
            Ok(match bx {
                None => PyArray1::from_vec(py, out).into_any(),
                Some(b) => PyArray2::from_owned_array(
                    py,
                    Array2::from_shape_vec((b, e), out).expect("b x e"),
                )
                .into_any(),
            })
        })
    }

    /// The reward of joint force vector `u` at state `x`; `u` may be left out under the
    /// paper's reward, which does not depend on it.
    #[pyo3(signature = (x, u = None))]
    fn reward(
        &self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        u: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<f64> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim()))?;
            let dim = 2 * self.model.config().agents;
            let u = match u {
                Some(u) => finite_vector(u, "u", Some(dim))?,
                None if self.model.config().reward == RewardShape::Paper => vec![0.0; dim],
                None => {
                    return Err(error(
                        py,
                        Kind::Input,
                        "u is missing: the shaped reward depends on the action",
                    ));
                }
            };
            Ok(fuzzyq_core::Model::<f64>::reward(&*self.model, &x, &u))
        })
    }

    /// Whether `x` is in the reward region.
    fn in_goal(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<bool> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim()))?;
            Ok(self.model.in_goal_f64(&x))
        })
    }

    /// The paper's grid for this number of agents: position cores
    /// `[-6, -3, -0.3, -0.1, 0, 0.1, 0.3, 3, 6]` and velocity cores `[-3, -1, 0, 1, 3]`.
    fn paper_grid(&self, py: Python<'_>) -> PyResult<Grid> {
        guard(py, || {
            let pos = vec![-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0];
            let vel = vec![-3.0, -1.0, 0.0, 1.0, 3.0];
            let mut cores = Vec::new();
            for _ in 0..self.n_agents() {
                cores.extend([pos.clone(), pos.clone(), vel.clone(), vel.clone()]);
            }
            Grid::checked(py, cores)
        })
    }

    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let json = serde_json::to_string(self.model.config())
            .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
        crate::pickle::reduce(py, "pointmass", json.into_pyobject(py)?.into_any())
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok({
                let c = self.model.config();
                format!(
                    "PointMass(agents={}, mass={}, sample_time={}, force_levels={:?})",
                    c.agents, c.mass, c.sample_time, c.force_levels
                )
            })
        })
    }
}

/// A `fuzzyq.Grid` as an argument.
impl<'a, 'py> crate::convert::Arg<'a, 'py> for &'a Bound<'py, Grid> {
    fn from_arg(obj: &'a Bound<'py, PyAny>) -> PyResult<Self> {
        obj.cast::<Grid>()
            .map_err(|_| crate::convert::wrong_type(obj, "a fuzzyq.Grid"))
    }
}
