//! Policies: what every learner leaves behind, ready to act.
//!
//! - [`FqiPolicy`]: a fuzzy Q-iteration solution (`V` per core and the per-core greedy joint
//!   actions) with the greedy policy of eq 7 (the model's one-step lookahead on `V`, through
//!   the solver's prepared backup operator, built once on first use) and the interpolated
//!   policy of eq 22. It owns its model and grid, is shared between threads, and serves a
//!   built-in environment or a tabulated model alike.
//! - [`AdditivePolicy`]: a Q-function learned from samples (fuzzy Q-learning, VQQL) in the
//!   additive layout, acting greedily and decentralised on each agent's own observation.
//! - [`Policy`]: either, as read from any policy file ([`Policy::load`]).
//!
//! A policy acts on a plant through a [`Controller`] ([`Policy::controller`]).

use std::path::Path;
use std::sync::{Arc, OnceLock};

use fuzzyq_core::error::check_len;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::{BackupPath, Grid, Operator, SolveError, TabulatedModel};
use fuzzyq_core::{Backup, EvalError, Model, Real, q};

use crate::error::{ConfigError, SimError, require};
use crate::io::config::TrainConfig;
use crate::io::policy_file::{
    KheperaPolicyFile, PointMassPolicyFile, PolicyArtifact, PolicyFile, Values,
};
use crate::learn::additive::AdditiveQ;
use crate::learn::tasks::khepera::{self as khepera_task, observation};
use crate::learn::tasks::pointmass as pointmass_task;
use crate::model::khepera::KheperaModel;
use crate::model::pointmass::PointMass;
use crate::model::{ActionTable, EnvKind, EnvModel, F64Model, Wide};
use crate::run::plant::Observation;
use crate::run::rollout::Controller;

/// What a decision needs from a solution, whatever its precision and model.
trait Engine: Send + Sync {
    fn state_dim(&self) -> usize;
    fn action_dim(&self) -> usize;
    fn n_joint(&self) -> usize;
    fn n_agents(&self) -> usize;
    fn n_cores(&self) -> usize;
    /// Builds the greedy policy's backup operator now (it is built on first use otherwise).
    fn prepare(&self) -> Result<(), SolveError>;
    /// `Q(x, .)` (eq 7), one value per joint action.
    fn q_values(&self, x: &[f64], out: &mut [f64]) -> Result<(), SolveError>;
    /// The greedy joint action index at `x` and its vector (`q`: scratch of `M` values).
    fn greedy(&self, x: &[f64], q: &mut [f64], u: &mut [f64]) -> Result<usize, SolveError>;
    /// The interpolated policy (eq 22) at `x`.
    fn interpolated(&self, x: &[f64], out: &mut [f64]) -> Result<(), EvalError>;
    /// `V` interpolated at `x`.
    fn value(&self, x: &[f64]) -> Result<f64, EvalError>;
    /// The joint action vector of joint action `u`.
    fn joint_vector(&self, u: usize, out: &mut [f64]) -> Result<(), EvalError>;
    /// The per-agent action indices of joint action `u`.
    fn agent_indices(&self, u: usize, out: &mut [usize]) -> Result<(), EvalError>;
    /// `theta[d, u]` at every core, core-major.
    fn theta(&self) -> Result<Vec<f64>, SolveError>;
}

/// What an engine owns.
struct Parts<T, M> {
    model: Arc<M>,
    grid: Grid<T>,
    v: Vec<T>,
    greedy: Vec<u32>,
    backup: Backup<T>,
}

fn to_t<T: Real>(x: &[f64]) -> Vec<T> {
    x.iter().map(|&v| T::from_f64(v)).collect()
}

fn operator<'o, 'a, T: Real, M: Model<T> + Sync>(
    p: &'a Parts<T, M>,
    op: &'o OnceLock<Operator<'a, T, M>>,
) -> Result<&'o Operator<'a, T, M>, SolveError> {
    if let Some(op) = op.get() {
        return Ok(op);
    }
    let built = Operator::new(&*p.model, p.grid.view(), p.backup, BackupPath::Auto)?;
    // A concurrent first use may have set it meanwhile; both are the same operator.
    let _ = op.set(built);
    Ok(op.get().expect("just set"))
}

fn q_values<T: Real, M: Model<T> + Sync>(
    p: &Parts<T, M>,
    op: &Operator<'_, T, M>,
    x: &[f64],
    out: &mut [f64],
) -> Result<(), SolveError> {
    let mut q = vec![T::ZERO; out.len()];
    op.q_values(&p.v, &to_t::<T>(x), &mut q)?;
    for (a, b) in out.iter_mut().zip(&q) {
        *a = b.to_f64();
    }
    Ok(())
}

fn joint_vector<T: Real, M: Model<T>>(
    p: &Parts<T, M>,
    u: usize,
    out: &mut [f64],
) -> Result<(), EvalError> {
    let joint = fuzzyq_core::model::joint_actions(&*p.model)?;
    let mut v = vec![T::ZERO; joint.dim()];
    joint.vector(u, &mut v)?;
    check_len("joint action vector", v.len(), out.len())?;
    for (a, b) in out.iter_mut().zip(&v) {
        *a = b.to_f64();
    }
    Ok(())
}

fn interpolated<T: Real, M: Model<T>>(
    p: &Parts<T, M>,
    x: &[f64],
    out: &mut [f64],
) -> Result<(), EvalError> {
    let joint = fuzzyq_core::model::joint_actions(&*p.model)?;
    let mut u = vec![T::ZERO; out.len()];
    q::interpolated_action(&p.grid.view(), &joint, &p.greedy, &to_t::<T>(x), &mut u)?;
    for (a, b) in out.iter_mut().zip(&u) {
        *a = b.to_f64();
    }
    Ok(())
}

fn theta<T: Real, M: Model<T> + Sync>(
    p: &Parts<T, M>,
    op: &Operator<'_, T, M>,
) -> Result<Vec<f64>, SolveError> {
    let (n, m, e) = (p.grid.n_cores(), op.joint().n_joint(), p.grid.n_dims());
    let view = p.grid.view();
    let mut out = vec![0.0; n * m];
    let mut x = vec![T::ZERO; e];
    let mut q = vec![T::ZERO; m];
    for (d, row) in out.chunks_mut(m).enumerate() {
        view.core_state(d, &mut x)?;
        // At a core the memberships are (1, 0, ...), so Q(x_d, .) is theta[d, .].
        op.q_values(&p.v, &x, &mut q)?;
        for (a, b) in row.iter_mut().zip(&q) {
            *a = b.to_f64();
        }
    }
    Ok(out)
}

/// Checks a solution's parts against each other and assembles them.
fn parts<T: Real, M: Model<T>>(
    model: Arc<M>,
    grid: Grid<T>,
    v: Vec<T>,
    greedy: Vec<u32>,
    gamma: f64,
    absorbing_goal: bool,
) -> Result<Parts<T, M>, SimError> {
    let n = grid.n_cores();
    require!(
        v.len() == n && greedy.len() == n,
        "policy",
        format!(
            "{} values and {} greedy actions for a grid of {n} cores",
            v.len(),
            greedy.len()
        ),
    );
    if Model::<T>::state_dim(&*model) != grid.n_dims() {
        return Err(SolveError::StateDim {
            model: Model::<T>::state_dim(&*model),
            grid: grid.n_dims(),
        }
        .into());
    }
    let backup = Backup {
        gamma: T::from_f64(gamma),
        absorbing_goal,
    };
    Ok(Parts {
        model,
        grid,
        v,
        greedy,
        backup,
    })
}

/// One engine type per (precision, model): the owner and its lazily built operator in one
/// self-referential cell.
macro_rules! engine {
    ($name:ident, $dep:ident, $t:ty, $m:ty) => {
        type $dep<'a> = OnceLock<Operator<'a, $t, $m>>;

        self_cell::self_cell!(
            struct $name {
                owner: Parts<$t, $m>,
                #[not_covariant]
                dependent: $dep,
            }
        );

        impl Engine for $name {
            fn state_dim(&self) -> usize {
                self.borrow_owner().grid.n_dims()
            }
            fn action_dim(&self) -> usize {
                let m = &*self.borrow_owner().model;
                (0..Model::<$t>::n_agents(m))
                    .map(|i| Model::<$t>::action_set(m, i).dim())
                    .sum()
            }
            fn n_joint(&self) -> usize {
                let m = &*self.borrow_owner().model;
                (0..Model::<$t>::n_agents(m))
                    .map(|i| Model::<$t>::action_set(m, i).n_actions())
                    .product()
            }
            fn n_agents(&self) -> usize {
                Model::<$t>::n_agents(&*self.borrow_owner().model)
            }
            fn n_cores(&self) -> usize {
                self.borrow_owner().grid.n_cores()
            }
            fn prepare(&self) -> Result<(), SolveError> {
                self.with_dependent(|p, op| operator(p, op).map(|_| ()))
            }
            fn q_values(&self, x: &[f64], out: &mut [f64]) -> Result<(), SolveError> {
                self.with_dependent(|p, op| q_values(p, operator(p, op)?, x, out))
            }
            fn greedy(
                &self,
                x: &[f64],
                qv: &mut [f64],
                u: &mut [f64],
            ) -> Result<usize, SolveError> {
                self.with_dependent(|p, op| {
                    q_values(p, operator(p, op)?, x, qv)?;
                    let best = q::argmax(qv).unwrap_or(0);
                    joint_vector(p, best, u)?;
                    Ok(best)
                })
            }
            fn interpolated(&self, x: &[f64], out: &mut [f64]) -> Result<(), EvalError> {
                interpolated(self.borrow_owner(), x, out)
            }
            fn value(&self, x: &[f64]) -> Result<f64, EvalError> {
                let p = self.borrow_owner();
                Ok(p.grid
                    .view()
                    .active(&to_t::<$t>(x))?
                    .interpolate(&p.v)
                    .to_f64())
            }
            fn joint_vector(&self, u: usize, out: &mut [f64]) -> Result<(), EvalError> {
                joint_vector(self.borrow_owner(), u, out)
            }
            fn agent_indices(&self, u: usize, out: &mut [usize]) -> Result<(), EvalError> {
                fuzzyq_core::model::joint_actions::<$t, _>(&*self.borrow_owner().model)?
                    .decompose(u, out)
            }
            fn theta(&self) -> Result<Vec<f64>, SolveError> {
                self.with_dependent(|p, op| theta(p, operator(p, op)?))
            }
        }
    };
}

engine!(EnvEngine32, EnvOp32, f32, EnvModel);
engine!(EnvEngine64, EnvOp64, f64, EnvModel);
engine!(TableEngine32, TableOp32, f32, TabulatedModel<f32>);
engine!(TableEngine64, TableOp64, f64, TabulatedModel<f64>);

/// A fuzzy Q-iteration solution ready to act (see the [module docs](self)).
pub struct FqiPolicy {
    engine: Box<dyn Engine>,
    config: Option<TrainConfig>,
    model: Option<Arc<EnvModel>>,
    gamma: f64,
}

impl std::fmt::Debug for FqiPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FqiPolicy")
            .field("env", &self.model.as_ref().map(|m| m.name()))
            .field("cores", &self.engine.n_cores())
            .field("joint_actions", &self.engine.n_joint())
            .finish()
    }
}

impl FqiPolicy {
    /// The policy of a built-in environment: its training configuration (model, grid,
    /// solver settings), `V` per core and the greedy joint action per core (grid order).
    pub fn new(config: TrainConfig, values: Values, greedy: Vec<u32>) -> Result<Self, SimError> {
        let model = Arc::new(config.build_model()?);
        let (gamma, absorbing_goal) = (config.solver.gamma, config.solver.absorbing_goal);
        let engine: Box<dyn Engine> = match values {
            Values::F32(v) => {
                let grid = config.grid::<f32>()?;
                let parts = parts(model.clone(), grid, v, greedy, gamma, absorbing_goal)?;
                Box::new(EnvEngine32::new(parts, |_| OnceLock::new()))
            }
            Values::F64(v) => {
                let grid = config.grid::<f64>()?;
                let parts = parts(model.clone(), grid, v, greedy, gamma, absorbing_goal)?;
                Box::new(EnvEngine64::new(parts, |_| OnceLock::new()))
            }
        };
        Ok(Self {
            engine,
            config: Some(config),
            model: Some(model),
            gamma,
        })
    }

    /// The policy of a trained policy file's content.
    pub fn from_artifact(a: PolicyArtifact) -> Result<Self, SimError> {
        Self::new(a.config, a.values, a.greedy)
    }

    /// The policy of a tabulated model (a model known only at the grid's cores, such as one
    /// given as a Python function), in `f32` or `f64`.
    pub fn tabulated<T: Wide>(
        model: Arc<TabulatedModel<T>>,
        grid: Grid<T>,
        v: Vec<T>,
        greedy: Vec<u32>,
        gamma: f64,
        absorbing_goal: bool,
    ) -> Result<Self, SimError> {
        use std::any::Any;
        let parts: Box<dyn Any> = Box::new(parts(model, grid, v, greedy, gamma, absorbing_goal)?);
        let engine: Box<dyn Engine> = match parts.downcast::<Parts<f32, TabulatedModel<f32>>>() {
            Ok(p) => Box::new(TableEngine32::new(*p, |_| OnceLock::new())),
            Err(other) => match other.downcast::<Parts<f64, TabulatedModel<f64>>>() {
                Ok(p) => Box::new(TableEngine64::new(*p, |_| OnceLock::new())),
                Err(_) => unreachable!("`Wide` is implemented for f32 and f64 only"),
            },
        };
        Ok(Self {
            engine,
            config: None,
            model: None,
            gamma,
        })
    }

    /// The training configuration (`None` for a tabulated model).
    #[must_use]
    pub fn config(&self) -> Option<&TrainConfig> {
        self.config.as_ref()
    }

    /// The environment's model (`None` for a tabulated model).
    #[must_use]
    pub fn model(&self) -> Option<&EnvModel> {
        self.model.as_deref()
    }

    /// The discount of the solution.
    #[must_use]
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// Length of the state.
    #[must_use]
    pub fn state_dim(&self) -> usize {
        self.engine.state_dim()
    }

    /// Length of the joint action vector.
    #[must_use]
    pub fn action_dim(&self) -> usize {
        self.engine.action_dim()
    }

    /// Number of joint actions.
    #[must_use]
    pub fn n_joint_actions(&self) -> usize {
        self.engine.n_joint()
    }

    /// Number of agents.
    #[must_use]
    pub fn n_agents(&self) -> usize {
        self.engine.n_agents()
    }

    /// Number of cores.
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.engine.n_cores()
    }

    /// Builds what the greedy policy needs (the backup operator: block tables, rewards) now
    /// rather than at its first decision.
    pub fn prepare(&self) -> Result<(), SimError> {
        Ok(self.engine.prepare()?)
    }

    /// `Q(x, .)`: one value per joint action (the greedy policy's lookahead on `V`).
    pub fn q_values(&self, x: &[f64], out: &mut [f64]) -> Result<(), SimError> {
        Ok(self.engine.q_values(x, out)?)
    }

    /// The fuzzy interpolation of `V` at `x`.
    pub fn value(&self, x: &[f64]) -> Result<f64, SimError> {
        Ok(self.engine.value(x)?)
    }

    /// Writes the joint action vector of policy `kind` at `x` into `u`; returns the joint
    /// action index for the greedy policy (`None` for the interpolated one, whose action is
    /// continuous). `q` is scratch of [`n_joint_actions`](Self::n_joint_actions) values.
    pub fn act(
        &self,
        kind: PolicyKind,
        x: &[f64],
        q: &mut [f64],
        u: &mut [f64],
    ) -> Result<Option<usize>, SimError> {
        check_len("state", self.state_dim(), x.len())?;
        match kind {
            PolicyKind::Greedy => Ok(Some(self.engine.greedy(x, q, u)?)),
            PolicyKind::Interpolated => {
                self.engine.interpolated(x, u)?;
                Ok(None)
            }
        }
    }

    /// The joint action vector of joint action `u`.
    pub fn joint_vector(&self, u: usize, out: &mut [f64]) -> Result<(), SimError> {
        Ok(self.engine.joint_vector(u, out)?)
    }

    /// The per-agent action indices of joint action `u`.
    pub fn agent_indices(&self, u: usize, out: &mut [usize]) -> Result<(), SimError> {
        Ok(self.engine.agent_indices(u, out)?)
    }

    /// `theta[d, u] = rho(x_d, u) + gamma V~(f(x_d, u))` at every core, core-major.
    pub fn theta(&self) -> Result<Vec<f64>, SimError> {
        Ok(self.engine.theta()?)
    }

    /// A controller of policy `kind`.
    #[must_use]
    pub fn controller(&self, kind: PolicyKind) -> FqiController<'_> {
        FqiController {
            policy: self,
            kind,
            q: vec![0.0; self.n_joint_actions()],
        }
    }
}

/// Decides with an [`FqiPolicy`] on the plant's state.
#[derive(Debug)]
pub struct FqiController<'p> {
    policy: &'p FqiPolicy,
    kind: PolicyKind,
    q: Vec<f64>,
}

impl FqiController<'_> {
    /// `Q(x, .)` of the last greedy decision.
    #[must_use]
    pub fn last_q(&self) -> &[f64] {
        &self.q
    }
}

impl Controller for FqiController<'_> {
    fn act(&mut self, obs: &Observation<'_>, u: &mut [f64]) -> Result<(), SimError> {
        self.policy
            .act(self.kind, obs.state, &mut self.q, u)
            .map(|_| ())
    }

    fn value_at_start(&self, start: &[f64], _first: &Observation<'_>) -> Result<f64, SimError> {
        self.policy.value(start)
    }
}

/// What an agent of an [`AdditivePolicy`] observes.
#[derive(Clone, Debug, PartialEq)]
enum Observe {
    /// Its own state `(s_x, s_y, v_x, v_y)` (the point masses).
    OwnState,
    /// Its sonars and the goal's distance and angle (the robots, [`observation`]).
    Sensors,
}

/// A Q-function learned from samples in the additive layout, with the task it acts in.
#[derive(Clone, Debug)]
pub struct AdditivePolicy {
    model: EnvModel,
    q: AdditiveQ,
    gamma: f64,
    observe: Observe,
}

impl AdditivePolicy {
    /// A Q-function learned on the point masses of `model` (each agent observing its own
    /// `(s_x, s_y, v_x, v_y)`), with the learning discount `gamma` (for the returns).
    pub fn point_masses(model: PointMass, q: AdditiveQ, gamma: f64) -> Result<Self, SimError> {
        pointmass_task::check_q(&model, &q)?;
        Self::with(EnvModel::PointMass(model), q, gamma, Observe::OwnState)
    }

    /// A Q-function learned on the robots of `model` (each observing its sonars and the goal).
    pub fn robots(model: KheperaModel, q: AdditiveQ, gamma: f64) -> Result<Self, SimError> {
        khepera_task::check_q(&q, model.config())?;
        Self::with(EnvModel::Khepera(model), q, gamma, Observe::Sensors)
    }

    fn with(model: EnvModel, q: AdditiveQ, gamma: f64, observe: Observe) -> Result<Self, SimError> {
        if !(0.0..=1.0).contains(&gamma) {
            return Err(
                ConfigError::invalid("gamma", format!("must be in [0, 1], got {gamma}")).into(),
            );
        }
        Ok(Self {
            model,
            q,
            gamma,
            observe,
        })
    }

    /// The policy of a point-mass policy file (fuzzy Q-learning or VQQL).
    pub fn from_point_mass_file(file: PointMassPolicyFile) -> Result<Self, SimError> {
        let model = file.validate()?;
        Self::point_masses(model, file.q, file.fql.gamma)
    }

    /// The policy of a Khepera fuzzy Q-learning policy file.
    pub fn from_khepera_file(file: KheperaPolicyFile) -> Result<Self, SimError> {
        let model = KheperaModel::new(file.config)?;
        Self::robots(model, file.q, file.fql.gamma)
    }

    /// The learned Q-function.
    #[must_use]
    pub fn q(&self) -> &AdditiveQ {
        &self.q
    }

    /// The task's model.
    #[must_use]
    pub fn model(&self) -> &EnvModel {
        &self.model
    }

    /// The learning discount.
    #[must_use]
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The observations of every agent at `obs` (one slice per agent).
    fn observations(&self, obs: &Observation<'_>) -> Result<Vec<Vec<f64>>, SimError> {
        let n = self.q.n_agents();
        match self.observe {
            Observe::OwnState => {
                let dim = obs.state.len() / n.max(1);
                Ok(obs.state.chunks(dim.max(1)).map(<[f64]>::to_vec).collect())
            }
            Observe::Sensors => (0..n)
                .map(|i| {
                    let pose = obs.state.get(3 * i..3 * i + 3);
                    match (pose, obs.sonar.get(i)) {
                        (Some(p), Some(s)) => {
                            let mut o = vec![0.0; s.len() + 2];
                            observation([p[0], p[1], p[2]], s, &mut o);
                            Ok(o)
                        }
                        _ => Err(ConfigError::invalid(
                            "plant",
                            "a robot policy needs the robots' poses and sonars",
                        )
                        .into()),
                    }
                })
                .collect(),
        }
    }

    /// The greedy joint action at `obs`: each agent's action index into `out`.
    pub fn act_indices(&self, obs: &Observation<'_>, out: &mut [usize]) -> Result<(), SimError> {
        let o = self.observations(obs)?;
        let refs: Vec<&[f64]> = o.iter().map(Vec::as_slice).collect();
        self.q.greedy_joint(&refs, out)
    }

    /// `max_u Q` at `obs`.
    pub fn value(&self, obs: &Observation<'_>) -> Result<f64, SimError> {
        let o = self.observations(obs)?;
        let refs: Vec<&[f64]> = o.iter().map(Vec::as_slice).collect();
        self.q.value(&refs)
    }

    /// The action vector of agent action `a` (the model's per-agent actions).
    #[must_use]
    pub fn action(&self, a: usize) -> &[f64] {
        F64Model::actions(&self.model).action(a)
    }

    fn actions(&self) -> &ActionTable {
        F64Model::actions(&self.model)
    }
}

/// Decides with an [`AdditivePolicy`]: every agent the argmax of its own term.
#[derive(Debug)]
pub struct AdditiveController<'p> {
    policy: &'p AdditivePolicy,
    indices: Vec<usize>,
}

impl Controller for AdditiveController<'_> {
    fn act(&mut self, obs: &Observation<'_>, u: &mut [f64]) -> Result<(), SimError> {
        self.policy.act_indices(obs, &mut self.indices)?;
        let table = self.policy.actions();
        let d = table.dim();
        for (i, &a) in self.indices.iter().enumerate() {
            u[d * i..d * (i + 1)].copy_from_slice(table.action(a));
        }
        Ok(())
    }

    fn value_at_start(&self, _start: &[f64], first: &Observation<'_>) -> Result<f64, SimError> {
        self.policy.value(first)
    }
}

/// A trained policy of any learner (see the [module docs](self)).
#[derive(Debug)]
pub enum Policy {
    /// Fuzzy Q-iteration.
    Fqi(FqiPolicy),
    /// Learned from samples (fuzzy Q-learning, VQQL).
    Additive(AdditivePolicy),
}

impl Policy {
    /// The policy of a policy file's content.
    pub fn from_file(file: PolicyFile) -> Result<Self, SimError> {
        Ok(match file {
            PolicyFile::Fqi(a) => Self::Fqi(FqiPolicy::from_artifact(a)?),
            PolicyFile::PointMass(f) => Self::Additive(AdditivePolicy::from_point_mass_file(f)?),
            PolicyFile::Khepera(f) => Self::Additive(AdditivePolicy::from_khepera_file(f)?),
        })
    }

    /// Reads a policy file of any kind (see [`PolicyFile::load`]).
    pub fn load(path: &Path) -> Result<Self, SimError> {
        Self::from_file(PolicyFile::load(path)?)
    }

    /// The environment's model (`None` for a tabulated model).
    #[must_use]
    pub fn model(&self) -> Option<&EnvModel> {
        match self {
            Self::Fqi(p) => p.model(),
            Self::Additive(p) => Some(p.model()),
        }
    }

    /// The environment (`None` for a tabulated model).
    #[must_use]
    pub fn env(&self) -> Option<EnvKind> {
        self.model().map(EnvModel::kind)
    }

    /// The discount the policy was trained with.
    #[must_use]
    pub fn gamma(&self) -> f64 {
        match self {
            Self::Fqi(p) => p.gamma(),
            Self::Additive(p) => p.gamma(),
        }
    }

    /// A controller of policy `kind`; a policy learned from samples acts greedily only.
    pub fn controller(&self, kind: PolicyKind) -> Result<Box<dyn Controller + '_>, SimError> {
        Ok(match self {
            Self::Fqi(p) => Box::new(p.controller(kind)),
            Self::Additive(p) => {
                require!(
                    kind == PolicyKind::Greedy,
                    "policy_kind",
                    "a policy learned from samples (fql, vqql) acts greedily (decentralised)",
                );
                Box::new(AdditiveController {
                    policy: p,
                    indices: vec![0; p.q.n_agents()],
                })
            }
        })
    }
}
