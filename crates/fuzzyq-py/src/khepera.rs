//! `Khepera`: the paper's Khepera IV robots (sections 3.2-3.3) as a model to solve from Python.

use std::sync::Arc;

use fuzzyq_core::model::joint_actions;
use fuzzyq_sim::io::config::{EnvConfig, TrainConfig};
use fuzzyq_sim::model::khepera::{KheperaConfig, KheperaModel, random_starts};
use fuzzyq_sim::model::{Dynamics, EnvKind, EnvModel, F64Model};
use fuzzyq_sim::world::KheperaWorld;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use serde_json::Value;

use crate::convert::{arg, finite_vector};
use crate::errors::{Kind, config_error, error, eval_error, guard, sim_error};
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

    /// The joint action index of per-robot action indices (robot 0 most significant).
    fn joint_index(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = arg)] per_agent: Vec<usize>,
    ) -> PyResult<usize> {
        guard(py, || {
            let j = joint_actions::<f64, _>(self.m()).map_err(|e| eval_error(py, &e))?;
            crate::joint::index(py, &j, &per_agent)
        })
    }

    /// The per-robot action indices of joint action `index`.
    fn agent_indices(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Vec<usize>> {
        guard(py, || {
            let j = joint_actions::<f64, _>(self.m()).map_err(|e| eval_error(py, &e))?;
            crate::joint::per_agent(py, &j, index)
        })
    }

    /// `count` random starts drawn from `seed` as `fuzzyq rollout --starts` draws them: shape
    /// `(count, 3 * agents)`, poses at least 0.5 m inside the walls, 0.3 m clear of the
    /// obstacles and 0.5 m apart.
    #[pyo3(signature = (count, seed = 0))]
    fn random_starts<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = arg)] count: usize,
        #[pyo3(from_py_with = arg)] seed: u64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            let starts = random_starts(&self.config, count, seed).map_err(|e| sim_error(py, &e))?;
            let rows: Vec<Vec<f64>> = starts
                .iter()
                .map(|poses| poses.iter().flatten().copied().collect())
                .collect();
            if rows.is_empty() {
                return Ok(PyArray2::zeros(py, [0, self.state_dim()], false));
            }
            PyArray2::from_vec2(py, &rows).map_err(|e| error(py, Kind::Internal, e.to_string()))
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

/// The Khepera robots on the rapier plant: colliding discs with ray-cast sonars and the
/// configured noise, stepped one control period at a time (what `Policy.rollout` runs on, and
/// what `fuzzyq.envs.ModelEnv(fuzzyq.Khepera())` steps).
///
/// `KheperaPlant(robots, seed=0)`; `reset(poses)` places the robots at rest, `step(u)` drives
/// them with joint wheel speeds for one sample time.
#[pyclass(module = "fuzzyq")]
pub struct KheperaPlant {
    model: KheperaModel,
    world: KheperaWorld,
    /// The flat poses `[x, y, heading, ...]` after the last reset or step.
    poses: Vec<f64>,
    /// Sonar readings, one row per robot, read after the last reset or step.
    sonar: Vec<Vec<f64>>,
    placed: bool,
}

impl KheperaPlant {
    /// Reads the poses and every robot's sonars.
    fn sense(&mut self, py: Python<'_>) -> PyResult<()> {
        for (r, s) in self.sonar.iter_mut().enumerate() {
            self.world.sonar(r, s).map_err(|e| sim_error(py, &e))?;
        }
        self.poses.clear();
        self.poses.extend(self.world.poses().iter().flatten());
        Ok(())
    }

    fn require_placed(&self, py: Python<'_>) -> PyResult<()> {
        if self.placed {
            Ok(())
        } else {
            Err(error(
                py,
                Kind::Config,
                "call reset(poses) before stepping the plant",
            ))
        }
    }
}

#[pymethods]
impl KheperaPlant {
    #[new]
    #[pyo3(signature = (robots, seed = 0))]
    fn new(
        py: Python<'_>,
        robots: &Khepera,
        #[pyo3(from_py_with = arg)] seed: u64,
    ) -> PyResult<Self> {
        guard(py, || {
            let config = robots.config.clone();
            let world = KheperaWorld::new(&config, seed).map_err(|e| sim_error(py, &e))?;
            let n = config.agents;
            Ok(Self {
                sonar: vec![vec![0.0; config.sonar_angles_deg.len()]; n],
                model: KheperaModel::new(config).map_err(|e| config_error(py, &e))?,
                world,
                poses: vec![0.0; 3 * n],
                placed: false,
            })
        })
    }

    /// Places the robots at rest at `poses` (`[x, y, heading]` per robot, flat) and clears
    /// the collision counts; with `seed`, the noise generator restarts from it.
    #[pyo3(signature = (poses, seed = None))]
    fn reset(
        &mut self,
        py: Python<'_>,
        poses: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = arg)] seed: Option<u64>,
    ) -> PyResult<()> {
        guard(py, || {
            let flat = finite_vector(poses, "poses", Some(self.poses.len()))?;
            if let Some(seed) = seed {
                self.world =
                    KheperaWorld::new(self.model.config(), seed).map_err(|e| sim_error(py, &e))?;
            }
            let per_robot: Vec<[f64; 3]> =
                flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
            self.world
                .reset(&per_robot)
                .map_err(|e| error(py, Kind::Input, e.to_string()))?;
            self.placed = true;
            self.sense(py)
        })
    }

    /// Drives every robot for one sample time with joint wheel speeds `u`
    /// (`[v_left, v_right]` per robot, flat; limited to `+-max_wheel_speed`); returns the
    /// number of contacts that started.
    fn step(&mut self, py: Python<'_>, u: &Bound<'_, PyAny>) -> PyResult<usize> {
        guard(py, || {
            self.require_placed(py)?;
            let u = finite_vector(u, "u", Some(2 * self.model.config().agents))?;
            let wheels: Vec<[f64; 2]> = u.chunks_exact(2).map(|w| [w[0], w[1]]).collect();
            let contacts = self.world.step(&wheels).map_err(|e| sim_error(py, &e))?;
            self.sense(py)?;
            Ok(contacts.starts.len())
        })
    }

    /// The flat poses `[x, y, heading, ...]` (heading in `(-pi, pi]`), a new array.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.poses)
    }

    /// The paper's state `[s_x, s_y, v_x, v_y]` per robot, flat (velocity: displacement over
    /// the last sample time; zero after a reset), a new array.
    #[getter]
    fn paper_state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let out: Vec<f64> = self
            .world
            .poses()
            .iter()
            .zip(self.world.velocities())
            .flat_map(|(p, v)| [p[0], p[1], v[0], v[1]])
            .collect();
        PyArray1::from_vec(py, out)
    }

    /// The sonar readings (m) read after the last reset or step: one row per robot, one
    /// column per sonar angle, a new array.
    #[getter]
    fn sonar<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        PyArray2::from_vec2(py, &self.sonar).map_err(|e| error(py, Kind::Internal, e.to_string()))
    }

    /// The reward of the current poses (the goal reward inside the region, minus the collision
    /// penalty where robots overlap or touch the arena, else 0).
    #[getter]
    fn reward(&self) -> f64 {
        self.model.reward_f64(&self.poses)
    }

    /// Whether the current poses are in the reward region (the task's goal).
    #[getter]
    fn in_goal(&self) -> bool {
        self.placed && self.model.in_region(&self.poses)
    }

    /// Collisions since the last reset: `total`, `robot_robot`, `robot_wall`,
    /// `robot_obstacle` and `per_agent`.
    #[getter]
    fn collisions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.world.collisions();
        let d = PyDict::new(py);
        d.set_item("total", c.total)?;
        d.set_item("robot_robot", c.robot_robot)?;
        d.set_item("robot_wall", c.robot_wall)?;
        d.set_item("robot_obstacle", c.robot_obstacle)?;
        d.set_item("per_agent", c.per_agent.clone())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!("KheperaPlant(agents={})", self.model.config().agents)
    }
}
