//! `Policy`: the sim crate's policy of any learner, acting on states and observations and
//! rolling out through the command line's one rollout path ([`evaluate::run`]).

use std::sync::Arc;

use fuzzyq_core::model::joint_actions;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_sim::SimError;
use fuzzyq_sim::learn::tasks::khepera::observation;
use fuzzyq_sim::model::F64Model;
use fuzzyq_sim::run::evaluate::{self, Outcome, PlantChoice, RolloutSpec};
use fuzzyq_sim::run::metrics::{KheperaRun, Trajectory};
use fuzzyq_sim::run::policy::{AdditivePolicy, Policy as SimPolicy};
use fuzzyq_sim::world::PointMassPlantConfig;
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::Value;

use crate::convert::{arg, finite_vector, one_or_batch, vector};
use crate::errors::{Kind, error, guard, machine_limit, memory_error, sim_error};

/// Joint Q-values of a policy learned from samples are returned up to this many joint actions.
const MAX_JOINT_Q: usize = 10_000_000;

/// A policy of any learner, ready to act.
///
/// From `Solution.policy(kind)` (fuzzy Q-iteration: `"greedy"`, eq 7, or `"interpolated"`,
/// eq 22) or from `fuzzyq.load` of a policy learned from samples (fuzzy Q-learning, VQQL:
/// greedy, each agent acting on its own observation). A state `x` is what the policy acts on:
/// the model's state; for fuzzy Q-iteration on the robots their poses `[x, y, heading]` per
/// robot; for a policy learned on the robots each robot's observation
/// `[sonar_1, ..., sonar_S, goal distance, goal angle]`, concatenated.
#[pyclass(module = "fuzzyq", frozen)]
pub struct Policy {
    inner: Arc<SimPolicy>,
    kind: PolicyKind,
}

/// Each agent's slice of a joint observation of a policy learned from samples.
fn split<'a>(p: &AdditivePolicy, x: &'a [f64]) -> Vec<&'a [f64]> {
    let features = p.q().features();
    let mut start = 0;
    (0..p.q().n_agents())
        .map(|i| {
            let d = features.obs_dim(i).unwrap_or(0);
            let s = &x[start..start + d];
            start += d;
            s
        })
        .collect()
}

impl Policy {
    pub(crate) fn new(inner: Arc<SimPolicy>, kind: PolicyKind) -> Self {
        Self { inner, kind }
    }

    fn state_dim_(&self) -> usize {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.state_dim(),
            SimPolicy::Additive(p) => {
                let f = p.q().features();
                (0..p.q().n_agents())
                    .map(|i| f.obs_dim(i).unwrap_or(0))
                    .sum()
            }
        }
    }

    fn action_dim_(&self) -> usize {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.action_dim(),
            SimPolicy::Additive(p) => p.q().n_agents() * F64Model::actions(p.model()).dim(),
        }
    }

    fn n_joint_(&self) -> usize {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.n_joint_actions(),
            SimPolicy::Additive(p) => p
                .q()
                .actions()
                .iter()
                .fold(1usize, |a, &m| a.saturating_mul(m)),
        }
    }

    fn n_agents_(&self) -> usize {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.n_agents(),
            SimPolicy::Additive(p) => p.q().n_agents(),
        }
    }

    /// The policy's action at `x` into `u` (`q`: scratch of `n_joint` values for fuzzy
    /// Q-iteration); the joint action index, or `None` for the interpolated policy.
    fn decide(&self, x: &[f64], q: &mut [f64], u: &mut [f64]) -> Result<Option<usize>, SimError> {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.act(self.kind, x, q, u),
            SimPolicy::Additive(p) => {
                let mut idx = vec![0; p.q().n_agents()];
                p.q().greedy_joint(&split(p, x), &mut idx)?;
                let d = F64Model::actions(p.model()).dim();
                for (i, &a) in idx.iter().enumerate() {
                    u[d * i..d * (i + 1)].copy_from_slice(p.action(a));
                }
                Ok(Some(joint_actions::<f64, _>(p.model())?.compose(&idx)?))
            }
        }
    }

    fn require_greedy(&self, py: Python<'_>, what: &str) -> PyResult<()> {
        if self.kind == PolicyKind::Greedy {
            Ok(())
        } else {
            Err(error(
                py,
                Kind::Config,
                format!("{what}: only the greedy policy has discrete actions"),
            ))
        }
    }

    fn greedy_index(&self, py: Python<'_>, x: &[f64]) -> PyResult<usize> {
        let mut q = self.scratch();
        let mut u = vec![0.0; self.action_dim_()];
        let j = self
            .decide(x, &mut q, &mut u)
            .map_err(|e| sim_error(py, &e))?;
        Ok(j.expect("a greedy decision has a joint action index"))
    }

    fn scratch(&self) -> Vec<f64> {
        match &*self.inner {
            SimPolicy::Fqi(p) => vec![0.0; p.n_joint_actions()],
            SimPolicy::Additive(_) => Vec::new(),
        }
    }

    fn joint_q(&self, x: &[f64]) -> Result<Vec<f64>, SimError> {
        match &*self.inner {
            SimPolicy::Fqi(p) => {
                let mut q = vec![0.0; p.n_joint_actions()];
                p.q_values(x, &mut q)?;
                Ok(q)
            }
            SimPolicy::Additive(p) => {
                let obs = split(p, x);
                let per_agent = p
                    .q()
                    .actions()
                    .iter()
                    .enumerate()
                    .map(|(i, &m)| {
                        let mut qi = vec![0.0; m];
                        p.q().q_agent(i, obs[i], &mut qi).map(|()| qi)
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let joint = joint_actions::<f64, _>(p.model())?;
                let mut idx = vec![0; joint.n_agents()];
                (0..joint.n_joint())
                    .map(|u| {
                        joint.decompose(u, &mut idx)?;
                        Ok(idx.iter().zip(&per_agent).map(|(&a, qi)| qi[a]).sum())
                    })
                    .collect()
            }
        }
    }
}

fn matrix<'py>(py: Python<'py>, rows: &[Vec<f64>], cols: usize) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    PyArray2::from_owned_array(
        py,
        Array2::from_shape_vec((rows.len(), cols), flat).expect("rows of equal length"),
    )
}

/// The trajectory's arrays into `out`: `states`, `actions`, `rewards`, `times`.
fn trajectory_into(
    py: Python<'_>,
    t: &Trajectory,
    action_dim: usize,
    out: &Bound<'_, PyDict>,
) -> PyResult<()> {
    let e = t.states.first().map_or(0, Vec::len);
    out.set_item("states", matrix(py, &t.states, e))?;
    out.set_item("actions", matrix(py, &t.actions, action_dim))?;
    out.set_item("rewards", PyArray1::from_slice(py, &t.rewards))?;
    let times: Vec<f64> = (0..t.states.len()).map(|k| t.time(k)).collect();
    out.set_item("times", PyArray1::from_vec(py, times))?;
    Ok(())
}

/// The robots' logs into `out`: `poses`, `sonar`, `observations`, `action_indices`.
fn robot_logs(py: Python<'_>, run: &KheperaRun, out: &Bound<'_, PyDict>) -> PyResult<()> {
    let k = run.poses.len();
    let n = run.poses.first().map_or(0, Vec::len);
    let s = run
        .sonar
        .first()
        .and_then(|r| r.first())
        .map_or(0, Vec::len);
    let poses: Vec<f64> = run.poses.iter().flatten().flatten().copied().collect();
    let sonar: Vec<f64> = run.sonar.iter().flatten().flatten().copied().collect();
    let mut obs = vec![0.0; k * n * (s + 2)];
    for (o, (pose, sonar)) in obs
        .chunks_exact_mut(s + 2)
        .zip(run.poses.iter().flatten().zip(run.sonar.iter().flatten()))
    {
        observation(*pose, sonar, o);
    }
    let indices: Vec<i64> = run
        .action_indices
        .iter()
        .flatten()
        .map(|&a| a as i64)
        .collect();
    let a3 = |v: Vec<f64>, c: usize| {
        PyArray3::from_owned_array(py, Array3::from_shape_vec((k, n, c), v).expect("k x n x c"))
    };
    out.set_item("poses", a3(poses, 3))?;
    out.set_item("sonar", a3(sonar, s))?;
    out.set_item("observations", a3(obs, s + 2))?;
    out.set_item(
        "action_indices",
        PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((run.action_indices.len(), n), indices).expect("steps x n"),
        ),
    )?;
    Ok(())
}

fn to_json<T: serde::Serialize>(py: Python<'_>, v: &T) -> PyResult<Value> {
    serde_json::to_value(v).map_err(|e| error(py, Kind::Solver, e.to_string()))
}

#[pymethods]
impl Policy {
    /// `"greedy"` or `"interpolated"` (a policy learned from samples is greedy).
    #[getter]
    fn kind(&self) -> &'static str {
        self.kind.name()
    }

    /// What learned it: `"fqi"` (fuzzy Q-iteration), `"fql"` (fuzzy Q-learning) or `"vqql"`.
    #[getter]
    fn learner(&self) -> &'static str {
        match &*self.inner {
            SimPolicy::Fqi(_) => "fqi",
            SimPolicy::Additive(p) if p.q().features().is_codebook() => "vqql",
            SimPolicy::Additive(_) => "fql",
        }
    }

    /// The environment's name (`"pointmass"`, `"khepera"`, `"dcmotor"`, ...), or `None` for a
    /// `CallableModel`.
    #[getter]
    fn env(&self, py: Python<'_>) -> PyResult<Option<&'static str>> {
        guard(py, || Ok(self.inner.env().map(|e| e.name())))
    }

    /// The discount the policy was trained with.
    #[getter]
    fn gamma(&self, py: Python<'_>) -> PyResult<f64> {
        guard(py, || Ok(self.inner.gamma()))
    }

    /// Length of the state (or joint observation) the policy acts on.
    #[getter]
    fn state_dim(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.state_dim_()))
    }

    /// Length of the joint action vector.
    #[getter]
    fn action_dim(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.action_dim_()))
    }

    /// Number of joint actions.
    #[getter]
    fn n_joint_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.n_joint_()))
    }

    /// Number of agents.
    #[getter]
    fn n_agents(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.n_agents_()))
    }

    /// The joint action vector at state `x` (the greedy action's, or the interpolated one).
    fn act<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim_()))?;
            let mut q = self.scratch();
            let mut u = vec![0.0; self.action_dim_()];
            self.decide(&x, &mut q, &mut u)
                .map_err(|e| sim_error(py, &e))?;
            Ok(PyArray1::from_vec(py, u))
        })
    }

    /// The joint action vectors at a batch of states, shape `(n, state_dim)` -> `(n, action_dim)`.
    fn act_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            let (e, a) = (self.state_dim_(), self.action_dim_());
            let (xs, b) = one_or_batch(states, "states", e)?;
            let n = b.unwrap_or(1);
            let out = py
                .detach(|| {
                    let mut q = self.scratch();
                    let mut out = vec![0.0; n * a];
                    for (x, u) in xs.chunks_exact(e).zip(out.chunks_exact_mut(a)) {
                        self.decide(x, &mut q, u)?;
                    }
                    Ok::<_, SimError>(out)
                })
                .map_err(|e| sim_error(py, &e))?;
            Ok(PyArray2::from_owned_array(
                py,
                Array2::from_shape_vec((n, a), out).expect("n x a"),
            ))
        })
    }

    /// The greedy joint action index at `x` (lowest index on ties).
    fn act_index(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<usize> {
        guard(py, || {
            self.require_greedy(py, "act_index")?;
            let x = finite_vector(x, "x", Some(self.state_dim_()))?;
            self.greedy_index(py, &x)
        })
    }

    /// The greedy action of each agent at `x` (indices into each agent's action set).
    fn agent_actions(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
        guard(py, || {
            self.require_greedy(py, "agent_actions")?;
            let x = finite_vector(x, "x", Some(self.state_dim_()))?;
            let u = self.greedy_index(py, &x)?;
            let mut out = vec![0; self.n_agents_()];
            let r = match &*self.inner {
                SimPolicy::Fqi(p) => p.agent_indices(u, &mut out),
                SimPolicy::Additive(p) => joint_actions::<f64, _>(p.model())
                    .and_then(|j| j.decompose(u, &mut out))
                    .map_err(SimError::from),
            };
            r.map_err(|e| sim_error(py, &e))?;
            Ok(out)
        })
    }

    /// `Q(x, .)`, one value per joint action: fuzzy Q-iteration's one-step lookahead on `V`
    /// (eq 7), or the sum of the agents' terms of a policy learned from samples.
    fn q_values<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim_()))?;
            let m = self.n_joint_();
            if matches!(&*self.inner, SimPolicy::Additive(_)) && m > MAX_JOINT_Q {
                return Err(error(
                    py,
                    Kind::Input,
                    format!("q_values: {m} joint actions are too many to return"),
                ));
            }
            let q = self.joint_q(&x).map_err(|e| sim_error(py, &e))?;
            Ok(PyArray1::from_vec(py, q))
        })
    }

    /// The value the policy predicts at `x`: `V` interpolated (fuzzy Q-iteration) or
    /// `max_u Q(x, u)` (a policy learned from samples).
    fn value(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim_()))?;
            let r = match &*self.inner {
                SimPolicy::Fqi(p) => p.value(&x),
                SimPolicy::Additive(p) => p.q().value(&split(p, &x)),
            };
            r.map_err(|e| sim_error(py, &e))
        })
    }

    /// Runs the policy on its environment, as `fuzzyq rollout` does (the same code).
    ///
    /// `x0` is the start in the state the environment reports (default: the environment's,
    /// as `fuzzyq rollout`'s): the model's state; for the robots the paper's 8-D state
    /// `[s_x, s_y, v_x, v_y]` per robot at rest, with `headings` in degrees (default 0), or
    /// their poses `[x, y, heading (rad)]` per robot. `steps` defaults to the environment's
    /// (75 for the point masses, 250 for the robots, ...). `plant` defaults to the
    /// environment's own: the point masses run on `plant="model"` or on `plant="rapier"`
    /// (colliding discs of `radius`); the robots always run on their rapier plant (sonars,
    /// contacts, noise seeded by `seed`), the classic benchmarks on their model (a run may
    /// end early at a terminal state).
    ///
    /// Returns a dict of numpy arrays: `states` (K+1, E) as `fuzzyq rollout --csv` writes them
    /// (the robots' paper state), `actions` (K, A), `rewards` (K,), `times` (K+1,); for the
    /// robots also `poses` (K+1, n, 3), `sonar` (K+1, n, S), `observations` (K+1, n, S+2)
    /// (what a policy learned on the robots acts on) and `action_indices` (K, n); and
    /// `metrics`, a dict with the fields of `fuzzyq rollout --json`.
    #[pyo3(signature = (x0 = None, steps = None, *, seed = 0, headings = None, plant = None, radius = None))]
    #[allow(clippy::too_many_arguments)] // the rollout's settings, as keyword arguments
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        x0: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = arg)] steps: Option<usize>,
        #[pyo3(from_py_with = arg)] seed: u64,
        headings: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = arg)] plant: Option<&str>,
        #[pyo3(from_py_with = arg)] radius: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        guard(py, || {
            let Some(model) = self.inner.model() else {
                return Err(error(
                    py,
                    Kind::Config,
                    "rollout: a policy of a CallableModel has no plant to run on; step the model \
                 with act()",
                ));
            };
            let env = model.kind();
            let spec = env.spec();
            let rapier = match plant {
                None => spec.robot_plant,
                Some("model") if spec.robot_plant => {
                    return Err(error(
                        py,
                        Kind::Config,
                        "plant: khepera policies run on the rapier plant only",
                    ));
                }
                Some("model") => false,
                Some("rapier") => true,
                Some(other) => {
                    return Err(error(
                        py,
                        Kind::Config,
                        format!("plant: expected \"model\" or \"rapier\", got {other:?}"),
                    ));
                }
            };
            if rapier && !(spec.rapier_point_masses || spec.robot_plant) {
                return Err(error(
                    py,
                    Kind::Config,
                    format!(
                        "plant: \"rapier\" does not apply to {env} policies (they run on their model)"
                    ),
                ));
            }
            if radius.is_some() && !(rapier && spec.rapier_point_masses) {
                return Err(error(
                    py,
                    Kind::Config,
                    "radius: applies to point-mass policies on plant=\"rapier\" only",
                ));
            }
            if headings.is_some() && !spec.robot_plant {
                return Err(error(
                    py,
                    Kind::Config,
                    "headings: applies to khepera policies only",
                ));
            }
            let steps = steps.unwrap_or(spec.default_steps);
            if steps == 0 {
                return Err(error(py, Kind::Config, "steps: must be at least 1"));
            }
            // The trajectory (states, actions, rewards) and its copies into numpy arrays, as
            // `fuzzyq rollout` estimates it.
            let per_step = 3.0 * 8.0 * (self.state_dim_() + self.action_dim_() + 2) as f64;
            machine_limit(py)?
                .check(&fuzzyq_sim::memory::rollouts(
                    1.0,
                    steps as f64,
                    per_step,
                    0.0,
                ))
                .map_err(|err| memory_error(py, "steps", &err))?;
            let x0 = x0.map(|x| vector(x, "x0", None)).transpose()?;
            let headings = headings.map(|h| vector(h, "headings", None)).transpose()?;
            let start = evaluate::start_for(model, x0, headings.as_deref())
                .map_err(|e| sim_error(py, &e))?;
            let plant = if rapier && spec.rapier_point_masses {
                let defaults = PointMassPlantConfig::default();
                PlantChoice::Rapier(PointMassPlantConfig {
                    radius: radius.unwrap_or(defaults.radius),
                    ..defaults
                })
            } else {
                PlantChoice::Model
            };
            let rollout = RolloutSpec {
                kind: self.kind,
                steps,
                plant,
                seed,
            };
            let policy = &*self.inner;
            let outcome = py
                .detach(|| evaluate::run(policy, &start, &rollout))
                .map_err(|e| sim_error(py, &e))?;
            let out = PyDict::new(py);
            let a = self.action_dim_();
            let metrics = match &outcome {
                Outcome::PointMass {
                    trajectory,
                    metrics,
                    collisions,
                } => {
                    trajectory_into(py, trajectory, a, &out)?;
                    let mut m = to_json(py, metrics)?;
                    if let (Some(c), Value::Object(map)) = (collisions, &mut m) {
                        map.insert("plant".into(), Value::String("rapier".into()));
                        map.insert("collisions".into(), to_json(py, c)?);
                    }
                    m
                }
                Outcome::Khepera { run, metrics } => {
                    trajectory_into(py, &run.trajectory, a, &out)?;
                    robot_logs(py, run, &out)?;
                    to_json(py, metrics)?
                }
                Outcome::Classic {
                    trajectory,
                    summary,
                } => {
                    trajectory_into(py, trajectory, a, &out)?;
                    to_json(py, summary)?
                }
            };
            out.set_item("metrics", crate::json::to_python(py, &metrics)?)?;
            Ok(out)
        })
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok({
                format!(
                    "Policy(kind={:?}, learner={:?}, env={}, state_dim={}, action_dim={})",
                    self.kind(),
                    self.learner(),
                    self.inner
                        .env()
                        .map_or_else(|| "None".into(), |e| format!("{:?}", e.name())),
                    self.state_dim_(),
                    self.action_dim_()
                )
            })
        })
    }
}
