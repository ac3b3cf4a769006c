//! `Policy`: the sim crate's policy of any learner, acting on states and observations and
//! rolling out through the command line's one rollout path ([`evaluate::run`]).

use std::borrow::Cow;
use std::sync::Arc;

use fuzzyq_core::q::PolicyKind;
use fuzzyq_sim::SimError;
use fuzzyq_sim::learn::tasks::khepera::observation;
use fuzzyq_sim::model::{Dynamics, F64Model};
use fuzzyq_sim::run::evaluate::{self, Outcome, PlantChoice, RolloutSpec};
use fuzzyq_sim::run::metrics::{KheperaRun, Trajectory};
use fuzzyq_sim::run::policy::{AdditivePolicy, Policy as SimPolicy, Scratch, TaskPolicyData};
use fuzzyq_sim::world::PointMassPlantConfig;
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};
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
    /// What the policy was made from, for pickling.
    origin: Origin,
}

/// What a [`Policy`] was made from.
pub(crate) enum Origin {
    /// `Solution.policy(kind)` (the `Solution`, untyped here: the solution module is above
    /// this one).
    Solution(Py<PyAny>),
    /// A policy file learned from samples (its bytes).
    File(Vec<u8>),
    /// A policy learned from samples of a system of your own, as JSON
    /// ([`fuzzyq_sim::run::policy::TaskPolicyData`]).
    Task(String),
}

/// Each agent's observation in an input of a policy learned from samples.
fn split<'a>(p: &AdditivePolicy, x: &'a [f64]) -> Result<Vec<Cow<'a, [f64]>>, SimError> {
    p.split(x)
}

/// [`split`]'s observations as the Q-function takes them.
fn slices<'a>(obs: &'a [Cow<'_, [f64]>]) -> Vec<&'a [f64]> {
    obs.iter().map(AsRef::as_ref).collect()
}

impl Policy {
    pub(crate) fn new(inner: Arc<SimPolicy>, kind: PolicyKind, origin: Origin) -> Self {
        Self {
            inner,
            kind,
            origin,
        }
    }

    /// The greedy policy of a file learned from samples (fuzzy Q-learning, VQQL).
    pub(crate) fn from_learned(
        py: Python<'_>,
        file: fuzzyq_sim::io::policy_file::PolicyFile,
    ) -> PyResult<Self> {
        let bytes = file.to_bytes().map_err(|e| sim_error(py, &e))?;
        let policy = crate::pool::detach(py, || SimPolicy::from_file(file))
            .map_err(|e| sim_error(py, &e))?;
        Ok(Self::new(
            Arc::new(policy),
            PolicyKind::Greedy,
            Origin::File(bytes),
        ))
    }

    /// The greedy policy learned from samples of a system of your own.
    pub(crate) fn from_task(py: Python<'_>, data: TaskPolicyData) -> PyResult<Self> {
        let json =
            serde_json::to_string(&data).map_err(|e| error(py, Kind::Internal, e.to_string()))?;
        let policy = AdditivePolicy::for_task(data).map_err(|e| sim_error(py, &e))?;
        Ok(Self::new(
            Arc::new(SimPolicy::Additive(policy)),
            PolicyKind::Greedy,
            Origin::Task(json),
        ))
    }

    /// Rebuilds a pickled policy: `(solution, kind)`, `(file bytes, "greedy")` or
    /// `(task policy JSON, "greedy")`.
    pub(crate) fn restore(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let (origin, kind): (Bound<'_, PyAny>, String) = data.extract()?;
        if let Ok(json) = origin.extract::<String>() {
            let data: TaskPolicyData = serde_json::from_str(&json)
                .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
            return Ok(Py::new(py, Self::from_task(py, data)?)?.into_any());
        }
        let Ok(bytes) = crate::pickle::bytes(&origin) else {
            // A solution's policy: the solution rebuilds it.
            return Ok(origin.call_method1("policy", (kind,))?.unbind());
        };
        let file = fuzzyq_sim::io::policy_file::PolicyFile::from_bytes(&bytes, "<pickle>".as_ref())
            .map_err(|e| crate::errors::policy_file_error(py, &e))?;
        let policy = crate::pool::detach(py, || SimPolicy::from_file(file))
            .map_err(|e| sim_error(py, &e))?;
        Ok(Py::new(
            py,
            Self::new(Arc::new(policy), PolicyKind::Greedy, Origin::File(bytes)),
        )?
        .into_any())
    }

    fn state_dim_(&self) -> usize {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.state_dim(),
            SimPolicy::Additive(p) => p.input_dim(),
        }
    }

    fn action_dim_(&self) -> usize {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.action_dim(),
            SimPolicy::Additive(p) => p.action_dim(),
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
        self.decide_with(x, q, u, &mut Scratch::default())
    }

    /// [`Self::decide`] with reusable buffers.
    fn decide_with(
        &self,
        x: &[f64],
        q: &mut [f64],
        u: &mut [f64],
        scratch: &mut Scratch,
    ) -> Result<Option<usize>, SimError> {
        match &*self.inner {
            SimPolicy::Fqi(p) => p.act_with(self.kind, x, q, u, scratch),
            SimPolicy::Additive(p) => {
                let mut idx = vec![0; p.q().n_agents()];
                p.q().greedy_joint(&slices(&split(p, x)?), &mut idx)?;
                p.write_actions(&idx, u);
                Ok(Some(p.joint()?.compose(&idx)?))
            }
        }
    }

    /// The decisions at a batch of states `xs` (rows of `state_dim`), in parallel with the GIL
    /// released: the joint action vectors (rows of `action_dim`) and, for a greedy policy, the
    /// joint action indices. Each state's decision is independent of the others', so the
    /// result does not depend on the number of threads.
    fn decide_batch(&self, py: Python<'_>, xs: &[f64]) -> PyResult<(Vec<f64>, Vec<i64>)> {
        use rayon::prelude::*;
        /// States per parallel task.
        const CHUNK: usize = 32;
        let (e, a) = (self.state_dim_(), self.action_dim_());
        let n = xs.len() / e.max(1);
        let mut us = vec![0.0; n * a];
        let mut idx = vec![-1i64; n];
        crate::pool::detach(py, || {
            xs.par_chunks(e * CHUNK)
                .zip(us.par_chunks_mut(a * CHUNK))
                .zip(idx.par_chunks_mut(CHUNK))
                .try_for_each(|((xs, us), idx)| {
                    let mut q = self.scratch();
                    let mut scratch = Scratch::default();
                    for ((x, u), i) in xs.chunks_exact(e).zip(us.chunks_exact_mut(a)).zip(idx) {
                        if let Some(j) = self.decide_with(x, &mut q, u, &mut scratch)? {
                            *i = j as i64;
                        }
                    }
                    Ok::<(), SimError>(())
                })
        })
        .map_err(|e| sim_error(py, &e))?;
        Ok((us, idx))
    }

    /// `Q(x, .)` at a batch of states, rows of `n_joint_actions`, in parallel with the GIL
    /// released.
    fn q_batch(&self, py: Python<'_>, xs: &[f64]) -> PyResult<Vec<f64>> {
        use rayon::prelude::*;
        let e = self.state_dim_();
        let m = self.n_joint_();
        let n = xs.len() / e.max(1);
        let mut out = vec![0.0; n * m];
        crate::pool::detach(py, || {
            xs.par_chunks(e)
                .zip(out.par_chunks_mut(m))
                .try_for_each(|(x, row)| {
                    row.copy_from_slice(&self.joint_q(x)?);
                    Ok::<(), SimError>(())
                })
        })
        .map_err(|e| sim_error(py, &e))?;
        Ok(out)
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
                let obs = split(p, x)?;
                let per_agent = p
                    .q()
                    .actions()
                    .iter()
                    .enumerate()
                    .map(|(i, &m)| {
                        let mut qi = vec![0.0; m];
                        p.q().q_agent(i, &obs[i], &mut qi).map(|()| qi)
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let joint = p.joint()?;
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

/// A JSON list of runs (objects) as columns: a numpy array per field whose values are all
/// numbers or booleans, a list otherwise.
fn columns<'py>(py: Python<'py>, runs: &Value) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let Some(runs) = runs.as_array() else {
        return Ok(out);
    };
    let Some(first) = runs.first().and_then(Value::as_object) else {
        return Ok(out);
    };
    let np = py.import("numpy")?;
    for key in first.keys() {
        let values: Vec<&Value> = runs.iter().map(|r| &r[key]).collect();
        let list = crate::json::to_python(
            py,
            &Value::Array(values.iter().map(|v| (*v).clone()).collect()),
        )?;
        let scalar = values
            .iter()
            .all(|v| v.is_number() || v.is_boolean() || v.is_null());
        let rectangular = values.iter().all(|v| v.is_array())
            && values
                .iter()
                .map(|v| v.as_array().map_or(0, Vec::len))
                .collect::<std::collections::BTreeSet<_>>()
                .len()
                == 1
            && values
                .iter()
                .flat_map(|v| v.as_array().into_iter().flatten())
                .all(|x| x.is_number() || x.is_boolean());
        if scalar && values.iter().any(|v| v.is_null()) {
            // Missing values (a run that never reached the goal) as NaN.
            let floats: Vec<f64> = values
                .iter()
                .map(|v| v.as_f64().unwrap_or(f64::NAN))
                .collect();
            out.set_item(key, PyArray1::from_vec(py, floats))?;
        } else if scalar || rectangular {
            out.set_item(key, np.call_method1("asarray", (list,))?)?;
        } else {
            out.set_item(key, list)?;
        }
    }
    Ok(out)
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

    /// The joint action vectors at a batch of states, shape `(n, state_dim)` -> `(n,
    /// action_dim)` (one state `(state_dim,)` gives `(1, action_dim)`): decided in parallel
    /// in Rust with the GIL released, identical to `act` state by state.
    fn act_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            let (e, a) = (self.state_dim_(), self.action_dim_());
            let (xs, b) = one_or_batch(states, "states", e)?;
            let n = b.unwrap_or(1);
            let (us, _) = self.decide_batch(py, &xs)?;
            Ok(PyArray2::from_owned_array(
                py,
                Array2::from_shape_vec((n, a), us).expect("n x a"),
            ))
        })
    }

    /// The greedy joint action index at `x` (lowest index on ties): an `int` for one state
    /// `(state_dim,)`, an int64 array `(n,)` for a batch `(n, state_dim)` (decided in
    /// parallel, as `act_batch`).
    fn act_index<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        guard(py, || {
            self.require_greedy(py, "act_index")?;
            let (xs, b) = one_or_batch(x, "x", self.state_dim_())?;
            match b {
                None => Ok(self.greedy_index(py, &xs)?.into_pyobject(py)?.into_any()),
                Some(_) => {
                    let (_, idx) = self.decide_batch(py, &xs)?;
                    Ok(PyArray1::from_vec(py, idx).into_any())
                }
            }
        })
    }

    /// Stable-Baselines3's `predict`: `(actions, None)` for an observation `(state_dim,)` or
    /// a batch `(n, state_dim)`.
    ///
    /// The actions are those of the fuzzyq Gymnasium environments' action spaces: joint action
    /// indices (int64, shape `()` or `(n,)`) for a greedy policy (a `Discrete` space), joint
    /// action vectors (`(action_dim,)` or `(n, action_dim)`) for the interpolated policy (a
    /// `Box`). The policies are deterministic: `deterministic`, `state` and `episode_start`
    /// are accepted for the convention and change nothing (`state` is returned as `None`).
    #[pyo3(signature = (observation, state = None, episode_start = None, deterministic = true))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        observation: &Bound<'py, PyAny>,
        state: Option<&Bound<'py, PyAny>>,
        episode_start: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = arg)] deterministic: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Option<Py<PyAny>>)> {
        let _ = (state, episode_start, deterministic);
        guard(py, || {
            let (e, a) = (self.state_dim_(), self.action_dim_());
            let (xs, b) = one_or_batch(observation, "observation", e)?;
            let (us, idx) = self.decide_batch(py, &xs)?;
            let n = b.unwrap_or(1);
            let actions = if self.kind == PolicyKind::Greedy {
                let arr = PyArray1::from_vec(py, idx);
                match b {
                    None => arr.call_method1("reshape", (pyo3::types::PyTuple::empty(py),))?,
                    Some(_) => arr.into_any(),
                }
            } else {
                match b {
                    None => PyArray1::from_vec(py, us).into_any(),
                    Some(_) => PyArray2::from_owned_array(
                        py,
                        Array2::from_shape_vec((n, a), us).expect("n x a"),
                    )
                    .into_any(),
                }
            };
            Ok((actions, None))
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
                SimPolicy::Additive(p) => p
                    .joint()
                    .and_then(|j| j.decompose(u, &mut out))
                    .map_err(SimError::from),
            };
            r.map_err(|e| sim_error(py, &e))?;
            Ok(out)
        })
    }

    /// `Q(x, .)`, one value per joint action: fuzzy Q-iteration's one-step lookahead on `V`
    /// (eq 7), or the sum of the agents' terms of a policy learned from samples.
    ///
    /// A batch `(n, state_dim)` gives `(n, n_joint_actions)`, computed in parallel.
    fn q_values<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        guard(py, || {
            let (xs, b) = one_or_batch(x, "x", self.state_dim_())?;
            let m = self.n_joint_();
            let rows = b.unwrap_or(1);
            if (matches!(&*self.inner, SimPolicy::Additive(_)) && m > MAX_JOINT_Q)
                || rows.saturating_mul(m) > 50_000_000
            {
                return Err(error(
                    py,
                    Kind::Input,
                    format!("q_values: {rows} x {m} Q-values are too many to return"),
                ));
            }
            match b {
                None => {
                    let q = self.joint_q(&xs).map_err(|e| sim_error(py, &e))?;
                    Ok(PyArray1::from_vec(py, q).into_any())
                }
                Some(n) => {
                    let q = self.q_batch(py, &xs)?;
                    Ok(PyArray2::from_owned_array(
                        py,
                        Array2::from_shape_vec((n, m), q).expect("n x m"),
                    )
                    .into_any())
                }
            }
        })
    }

    /// The value the policy predicts at `x`: `V` interpolated (fuzzy Q-iteration) or
    /// `max_u Q(x, u)` (a policy learned from samples).
    fn value(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim_()))?;
            let r = match &*self.inner {
                SimPolicy::Fqi(p) => p.value(&x),
                SimPolicy::Additive(p) => split(p, &x).and_then(|o| p.q().value(&slices(&o))),
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
    #[pyo3(signature = (x0 = None, steps = None, *, seed = 0, headings = None, plant = None, radius = None, task = None))]
    #[allow(clippy::too_many_arguments)] // the rollout's settings, as keyword arguments
    fn rollout<'py>(
        slf: &Bound<'py, Self>,
        py: Python<'py>,
        x0: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = arg)] steps: Option<usize>,
        #[pyo3(from_py_with = arg)] seed: u64,
        headings: Option<&Bound<'py, PyAny>>,
        plant: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = arg)] radius: Option<f64>,
        task: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if let Some(system) = plant.filter(|p| !p.is_instance_of::<PyString>()) {
            system_plant(system)?;
            let kwargs = PyDict::new(py);
            kwargs.set_item("seed", seed)?;
            kwargs.set_item("task", task)?;
            return Ok(py
                .import("fuzzyq._interact")?
                .getattr("rollout")?
                .call((slf, system, x0, steps), Some(&kwargs))?
                .cast_into::<PyDict>()?);
        }
        let plant: Option<String> = plant.map(|p| p.extract()).transpose()?;
        let plant = plant.as_deref();
        let this = slf.get();
        guard(py, || {
            let Some(model) = this.inner.model() else {
                return Err(error(
                    py,
                    Kind::Config,
                    "rollout: a policy of a CallableModel or a Task runs on the system given as \
                     plant= (the CallableModel, or a Gymnasium environment with task=)",
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
            let per_step = 3.0 * 8.0 * (this.state_dim_() + this.action_dim_() + 2) as f64;
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
                kind: this.kind,
                steps,
                plant,
                seed,
            };
            let policy = &*this.inner;
            let outcome = crate::pool::detach(py, || evaluate::run(policy, &start, &rollout))
                .map_err(|e| sim_error(py, &e))?;
            let out = PyDict::new(py);
            let a = this.action_dim_();
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

    /// Monte-Carlo evaluation on the policy's environment, as `fuzzyq compare` evaluates
    /// policies: runs from many starts, each as `rollout` runs one.
    ///
    /// `starts` (an array `(n, state_dim)` of model states; the point masses and the classic
    /// benchmarks) defaults to `count` states drawn uniformly within the model's state bounds
    /// with `seed`; the robots always start from `count` random collision-free poses of
    /// `seed` (run `k` on the plant seeded with `seed + k`). `steps` defaults to the
    /// environment's. Point masses run on their model, run `i` with its process noise (if
    /// any) seeded with `i`.
    ///
    /// Returns a dict: `runs`, every run's metrics as columns (a numpy array per numeric
    /// field, one entry per run, with the names of `fuzzyq rollout --json`), and `summary`: the
    /// robots' success report, or the classic benchmarks' mean discounted return (a dict).
    #[pyo3(signature = (starts = None, steps = None, *, count = 100, seed = 0, plant = None, task = None))]
    #[allow(clippy::too_many_arguments)] // the evaluation's settings, as keyword arguments
    fn evaluate<'py>(
        slf: &Bound<'py, Self>,
        py: Python<'py>,
        starts: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = arg)] steps: Option<usize>,
        #[pyo3(from_py_with = arg)] count: usize,
        #[pyo3(from_py_with = arg)] seed: u64,
        plant: Option<&Bound<'py, PyAny>>,
        task: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if let Some(system) = plant {
            system_plant(system)?;
            let kwargs = PyDict::new(py);
            kwargs.set_item("count", count)?;
            kwargs.set_item("steps", steps)?;
            kwargs.set_item("seed", seed)?;
            kwargs.set_item("starts", starts)?;
            kwargs.set_item("task", task)?;
            return Ok(py
                .import("fuzzyq._interact")?
                .getattr("evaluate")?
                .call((slf, system), Some(&kwargs))?
                .cast_into::<PyDict>()?);
        }
        let this = slf.get();
        guard(py, || {
            let Some(model) = this.inner.model() else {
                return Err(error(
                    py,
                    Kind::Config,
                    "evaluate: a policy of a CallableModel or a Task runs on the system given as \
                     plant= (the CallableModel, or a Gymnasium environment with task=)",
                ));
            };
            let spec = model.kind().spec();
            let steps = steps.unwrap_or(spec.default_steps);
            if steps == 0 || count == 0 {
                return Err(error(
                    py,
                    Kind::Config,
                    "steps and count: must be at least 1",
                ));
            }
            if steps.saturating_mul(count) > 100_000_000 {
                return Err(error(
                    py,
                    Kind::Config,
                    format!("steps x count: {steps} x {count} steps are too many (at most 1e8)"),
                ));
            }
            let e = F64Model::state_dim(model);
            let robots = spec.robot_plant;
            if robots && starts.is_some() {
                return Err(error(
                    py,
                    Kind::Config,
                    "starts: the robots start from `count` random poses of `seed`",
                ));
            }
            let starts: Vec<Vec<f64>> = match starts {
                Some(s) => {
                    let (xs, b) = one_or_batch(s, "starts", e)?;
                    if b.is_none() {
                        return Err(error(
                            py,
                            Kind::Input,
                            format!("starts: expected shape (n, {e}), one start per row"),
                        ));
                    }
                    xs.chunks_exact(e).map(<[f64]>::to_vec).collect()
                }
                None if robots => Vec::new(),
                None => {
                    let (lo, hi): (Vec<f64>, Vec<f64>) =
                        (0..e).map(|d| Dynamics::state_bounds(model, d)).unzip();
                    let rng = py
                        .import("numpy")?
                        .getattr("random")?
                        .call_method1("default_rng", (seed,))?;
                    let xs = rng.call_method1("uniform", (lo, hi, (count, e)))?;
                    let (xs, _) = one_or_batch(&xs, "starts", e)?;
                    xs.chunks_exact(e).map(<[f64]>::to_vec).collect()
                }
            };
            let kind = this.kind;
            let inner = &this.inner;
            let (runs, summary) =
                crate::pool::detach(py, || -> Result<(Value, Value), SimError> {
                    fn json<T: serde::Serialize>(v: &T) -> Value {
                        serde_json::to_value(v).unwrap_or(Value::Null)
                    }
                    if robots {
                        let (report, runs) =
                            evaluate::khepera_starts(inner, count, seed, steps, kind)?;
                        Ok((json(&runs), json(&report)))
                    } else if matches!(model, fuzzyq_sim::model::EnvModel::PointMass(_)) {
                        let runs = evaluate::point_mass_starts(inner, &starts, steps, kind)?;
                        Ok((json(&runs), Value::Null))
                    } else {
                        let mc = evaluate::monte_carlo(inner, &starts, steps, kind)?;
                        let mut summary = serde_json::to_value(&mc).unwrap_or(Value::Null);
                        let runs = summary
                            .as_object_mut()
                            .and_then(|m| m.remove("runs"))
                            .unwrap_or(Value::Null);
                        Ok((runs, summary))
                    }
                })
                .map_err(|e| sim_error(py, &e))?;
            let out = PyDict::new(py);
            out.set_item("runs", columns(py, &runs)?)?;
            out.set_item("summary", crate::json::to_python(py, &summary)?)?;
            Ok(out)
        })
    }

    /// Pickling: the solution and the kind, or the bytes of the learned policy's file.
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let origin = match &self.origin {
            Origin::Solution(s) => s.bind(py).clone().into_any(),
            Origin::File(b) => pyo3::types::PyBytes::new(py, b).into_any(),
            Origin::Task(json) => json.into_pyobject(py)?.into_any(),
        };
        let data = (origin, self.kind.name()).into_pyobject(py)?.into_any();
        crate::pickle::reduce(py, "policy", data)
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

/// Checks that `plant` is a system a policy can run on besides its own environment: a
/// `CallableModel` or a Gymnasium environment (an object with `action_space`, `reset` and
/// `step`).
fn system_plant(plant: &Bound<'_, PyAny>) -> PyResult<()> {
    let gym = ["action_space", "reset", "step"]
        .iter()
        .all(|a| plant.hasattr(*a).unwrap_or(false));
    if plant.is_instance_of::<crate::callable::CallableModel>() || gym {
        return Ok(());
    }
    Err(error(
        plant.py(),
        Kind::InputType,
        format!(
            "plant: expected \"model\", \"rapier\", a fuzzyq.CallableModel or a Gymnasium \
             environment, got {}",
            crate::convert::describe(plant)
        ),
    ))
}
