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

use std::borrow::Cow;
use std::path::Path;
use std::sync::{Arc, OnceLock};

use fuzzyq_core::error::check_len;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::{BackupPath, Grid, Operator, SolveError, TabulatedModel};
use fuzzyq_core::{Backup, EvalError, Model, Real, q};
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, require};
use crate::io::config::TrainConfig;
use crate::io::policy_file::{
    KheperaPolicyFile, PointMassPolicyFile, PolicyArtifact, PolicyFile, Values,
};
use crate::learn::additive::AdditiveQ;
use crate::learn::tasks::khepera::{self as khepera_task, observation};
use crate::learn::tasks::pointmass as pointmass_task;
use crate::model::khepera::KheperaModel;
use crate::model::learned::{BlockTables, LearnedModel};
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
    fn q_values(&self, x: &[f64], out: &mut [f64], s: &mut Scratch) -> Result<(), SolveError>;
    /// The greedy joint action index at `x` and its vector (`q`: scratch of `M` values).
    fn greedy(
        &self,
        x: &[f64],
        q: &mut [f64],
        u: &mut [f64],
        s: &mut Scratch,
    ) -> Result<usize, SolveError>;
    /// The interpolated policy (eq 22) at `x`.
    fn interpolated(&self, x: &[f64], out: &mut [f64], s: &mut Scratch) -> Result<(), EvalError>;
    /// `V` interpolated at `x`.
    fn value(&self, x: &[f64], s: &mut Scratch) -> Result<f64, EvalError>;
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

/// Reusable buffers of decisions in a solution's own precision (the state, `Q(x, .)` and the
/// action vector): a [`FqiController`] keeps one, so its decisions allocate nothing after the
/// first.
#[derive(Debug, Default)]
pub struct Scratch {
    f32: Buffers<f32>,
    f64: Buffers<f64>,
}

#[derive(Debug, Default)]
struct Buffers<T> {
    x: Vec<T>,
    q: Vec<T>,
    u: Vec<T>,
}

impl<T: Real> Buffers<T> {
    /// `x` in `T`, and `m` and `d` values of room for `Q(x, .)` and an action vector; a
    /// finite element of `x` that `T` cannot hold is refused (it would become infinite).
    #[allow(clippy::type_complexity)] // the three buffers
    fn load(
        &mut self,
        x: &[f64],
        m: usize,
        d: usize,
    ) -> Result<(&[T], &mut [T], &mut [T]), EvalError> {
        self.x.clear();
        self.x.extend(x.iter().map(|&v| T::from_f64(v)));
        if let Some(index) = (0..x.len()).find(|&i| x[i].is_finite() && !self.x[i].is_finite()) {
            return Err(EvalError::BeyondPrecision {
                what: "state",
                index,
            });
        }
        self.q.resize(m, T::ZERO);
        self.u.resize(d, T::ZERO);
        Ok((&self.x, &mut self.q, &mut self.u))
    }
}

/// Widens `from` into `to`.
fn widen<T: Real>(from: &[T], to: &mut [f64]) {
    for (a, b) in to.iter_mut().zip(from) {
        *a = b.to_f64();
    }
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
    b: &mut Buffers<T>,
) -> Result<(), SolveError> {
    let (x, q, _) = b.load(x, out.len(), 0)?;
    op.q_values(&p.v, x, q)?;
    widen(q, out);
    Ok(())
}

fn greedy<T: Real, M: Model<T> + Sync>(
    p: &Parts<T, M>,
    op: &Operator<'_, T, M>,
    x: &[f64],
    q: &mut [f64],
    out: &mut [f64],
    b: &mut Buffers<T>,
) -> Result<usize, SolveError> {
    q_values(p, op, x, q, b)?;
    let best = q::argmax(q).unwrap_or(0);
    let joint = op.joint();
    check_len("joint action vector", joint.dim(), out.len())?;
    let (_, _, u) = b.load(&[], 0, joint.dim())?;
    joint.vector(best, u)?;
    widen(u, out);
    Ok(best)
}

fn interpolated<T: Real, M: Model<T>>(
    p: &Parts<T, M>,
    x: &[f64],
    out: &mut [f64],
    b: &mut Buffers<T>,
) -> Result<(), EvalError> {
    let joint = fuzzyq_core::model::joint_actions(&*p.model)?;
    let (x, _, u) = b.load(x, 0, out.len())?;
    q::interpolated_action(&p.grid.view(), &joint, &p.greedy, x, u)?;
    widen(u, out);
    Ok(())
}

fn value<T: Real, M>(p: &Parts<T, M>, x: &[f64], b: &mut Buffers<T>) -> Result<f64, EvalError> {
    let (x, _, _) = b.load(x, 0, 0)?;
    Ok(p.grid.view().active(x)?.interpolate(&p.v).to_f64())
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
    ($name:ident, $dep:ident, $t:ident, $m:ty) => {
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
            fn q_values(
                &self,
                x: &[f64],
                out: &mut [f64],
                s: &mut Scratch,
            ) -> Result<(), SolveError> {
                self.with_dependent(|p, op| q_values(p, operator(p, op)?, x, out, &mut s.$t))
            }
            fn greedy(
                &self,
                x: &[f64],
                q: &mut [f64],
                u: &mut [f64],
                s: &mut Scratch,
            ) -> Result<usize, SolveError> {
                self.with_dependent(|p, op| greedy(p, operator(p, op)?, x, q, u, &mut s.$t))
            }
            fn interpolated(
                &self,
                x: &[f64],
                out: &mut [f64],
                s: &mut Scratch,
            ) -> Result<(), EvalError> {
                interpolated(self.borrow_owner(), x, out, &mut s.$t)
            }
            fn value(&self, x: &[f64], s: &mut Scratch) -> Result<f64, EvalError> {
                value(self.borrow_owner(), x, &mut s.$t)
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
engine!(LearnedEngine32, LearnedOp32, f32, LearnedModel);
engine!(LearnedEngine64, LearnedOp64, f64, LearnedModel);
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
        Self::with_model(config, None, values, greedy)
    }

    /// [`new`](Self::new) for a solution of the learned model with transition tables
    /// `learned` (`None`: the environment's own model). The policy's one-step lookahead
    /// uses the model it was solved on; its plant stays the environment's.
    pub fn with_model(
        config: TrainConfig,
        learned: Option<BlockTables>,
        values: Values,
        greedy: Vec<u32>,
    ) -> Result<Self, SimError> {
        let model = Arc::new(config.build_model()?);
        let (gamma, absorbing_goal) = (config.solver.gamma, config.solver.absorbing_goal);
        let learned = match learned {
            Some(tables) => {
                require!(
                    tables.cores == config.grid_cores()
                        && tables.membership == config.grid.membership,
                    "learned_model",
                    "its tables are not on the configured grid",
                );
                Some(Arc::new(LearnedModel::new((*model).clone(), tables)?))
            }
            None => None,
        };
        let engine: Box<dyn Engine> = match (values, learned) {
            (Values::F32(v), None) => {
                let grid = config.grid::<f32>()?;
                let parts = parts(model.clone(), grid, v, greedy, gamma, absorbing_goal)?;
                Box::new(EnvEngine32::new(parts, |_| OnceLock::new()))
            }
            (Values::F64(v), None) => {
                let grid = config.grid::<f64>()?;
                let parts = parts(model.clone(), grid, v, greedy, gamma, absorbing_goal)?;
                Box::new(EnvEngine64::new(parts, |_| OnceLock::new()))
            }
            (Values::F32(v), Some(l)) => {
                let grid = config.grid::<f32>()?;
                let parts = parts(l, grid, v, greedy, gamma, absorbing_goal)?;
                Box::new(LearnedEngine32::new(parts, |_| OnceLock::new()))
            }
            (Values::F64(v), Some(l)) => {
                let grid = config.grid::<f64>()?;
                let parts = parts(l, grid, v, greedy, gamma, absorbing_goal)?;
                Box::new(LearnedEngine64::new(parts, |_| OnceLock::new()))
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
        Self::with_model(a.config, a.learned.map(|t| *t), a.values, a.greedy)
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
        Ok(self.engine.q_values(x, out, &mut Scratch::default())?)
    }

    /// The fuzzy interpolation of `V` at `x`.
    pub fn value(&self, x: &[f64]) -> Result<f64, SimError> {
        Ok(self.engine.value(x, &mut Scratch::default())?)
    }

    /// Writes the joint action vector of policy `kind` at `x` into `u`; returns the joint
    /// action index for the greedy policy (`None` for the interpolated one, whose action is
    /// continuous). `q` is scratch of [`n_joint_actions`](Self::n_joint_actions) values.
    /// Repeated decisions reuse their buffers through [`act_with`](Self::act_with).
    pub fn act(
        &self,
        kind: PolicyKind,
        x: &[f64],
        q: &mut [f64],
        u: &mut [f64],
    ) -> Result<Option<usize>, SimError> {
        self.act_with(kind, x, q, u, &mut Scratch::default())
    }

    /// [`act`](Self::act) with the caller's [`Scratch`]: no allocation once it has grown.
    pub fn act_with(
        &self,
        kind: PolicyKind,
        x: &[f64],
        q: &mut [f64],
        u: &mut [f64],
        scratch: &mut Scratch,
    ) -> Result<Option<usize>, SimError> {
        check_len("state", self.state_dim(), x.len())?;
        match kind {
            PolicyKind::Greedy => Ok(Some(self.engine.greedy(x, q, u, scratch)?)),
            PolicyKind::Interpolated => {
                self.engine.interpolated(x, u, scratch)?;
                Ok(None)
            }
        }
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
            scratch: Scratch::default(),
        }
    }
}

/// Decides with an [`FqiPolicy`] on the plant's state.
#[derive(Debug)]
pub struct FqiController<'p> {
    policy: &'p FqiPolicy,
    kind: PolicyKind,
    q: Vec<f64>,
    scratch: Scratch,
}

impl Controller for FqiController<'_> {
    fn act(&mut self, obs: &Observation<'_>, u: &mut [f64]) -> Result<(), SimError> {
        self.policy
            .act_with(self.kind, obs.state, &mut self.q, u, &mut self.scratch)
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
    /// The listed variables of a task's state of `state_dim` values (a system declared in
    /// Python), agent by agent.
    Variables {
        state_dim: usize,
        of_agent: Vec<Vec<usize>>,
    },
}

/// A Q-function learned from samples in the additive layout, with the task it acts in: a
/// built-in model, or a task given by each agent's actions and the state variables it
/// observes ([`for_task`](Self::for_task)).
#[derive(Clone, Debug)]
pub struct AdditivePolicy {
    model: Option<EnvModel>,
    /// Each agent's actions.
    actions: Vec<ActionTable>,
    q: AdditiveQ,
    gamma: f64,
    observe: Observe,
}

/// An [`AdditivePolicy`] of a task ([`AdditivePolicy::for_task`]) as data: what pickles it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskPolicyData {
    /// The learned Q-function.
    pub q: AdditiveQ,
    /// Per agent: its actions' components (action-major) and components per action.
    pub actions: Vec<(Vec<f64>, usize)>,
    /// Length of the task's state.
    pub state_dim: usize,
    /// Per agent: the state variables it observes.
    pub variables: Vec<Vec<usize>>,
    /// The learning discount.
    pub gamma: f64,
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

    /// A Q-function learned on a task of `data.state_dim` state variables, agent `i`
    /// observing `data.variables[i]` and acting with `data.actions[i]`. Errors name what does
    /// not fit the Q-function.
    pub fn for_task(data: TaskPolicyData) -> Result<Self, SimError> {
        let TaskPolicyData {
            q,
            actions,
            state_dim,
            variables,
            gamma,
        } = data;
        let n = q.n_agents();
        require!(
            actions.len() == n && variables.len() == n,
            "policy",
            format!(
                "{n} agents in the Q-function, {} action sets and {} observations",
                actions.len(),
                variables.len()
            ),
        );
        let mut tables = Vec::with_capacity(n);
        for (i, (values, dim)) in actions.into_iter().enumerate() {
            let table = ActionTable::new(values, dim);
            require!(
                dim > 0 && table.values().len() == dim * q.actions()[i],
                &format!("actions[{i}]"),
                format!("expected {} actions of {dim} values", q.actions()[i]),
            );
            let observed = &variables[i];
            require!(
                q.features().obs_dim(i) == Some(observed.len())
                    && observed.iter().all(|&d| d < state_dim),
                &format!("variables[{i}]"),
                format!(
                    "expected {:?} variables below {state_dim}, got {observed:?}",
                    q.features().obs_dim(i)
                ),
            );
            tables.push(table);
        }
        let observe = Observe::Variables {
            state_dim,
            of_agent: variables,
        };
        Self::checked(None, tables, q, gamma, observe)
    }

    fn with(model: EnvModel, q: AdditiveQ, gamma: f64, observe: Observe) -> Result<Self, SimError> {
        let tables = vec![F64Model::actions(&model).clone(); F64Model::n_agents(&model)];
        Self::checked(Some(model), tables, q, gamma, observe)
    }

    fn checked(
        model: Option<EnvModel>,
        actions: Vec<ActionTable>,
        q: AdditiveQ,
        gamma: f64,
        observe: Observe,
    ) -> Result<Self, SimError> {
        if !(0.0..=1.0).contains(&gamma) {
            return Err(
                ConfigError::invalid("gamma", format!("must be in [0, 1], got {gamma}")).into(),
            );
        }
        Ok(Self {
            model,
            actions,
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
        file.validate()?;
        let model = KheperaModel::new(file.config)?;
        Self::robots(model, file.q, file.fql.gamma)
    }

    /// A task's policy as data (`None` for a built-in model's, which its policy file holds).
    #[must_use]
    pub fn task_data(&self) -> Option<TaskPolicyData> {
        let Observe::Variables {
            state_dim,
            of_agent,
        } = &self.observe
        else {
            return None;
        };
        Some(TaskPolicyData {
            q: self.q.clone(),
            actions: self
                .actions
                .iter()
                .map(|t| (t.values().to_vec(), t.dim()))
                .collect(),
            state_dim: *state_dim,
            variables: of_agent.clone(),
            gamma: self.gamma,
        })
    }

    /// The learned Q-function.
    #[must_use]
    pub fn q(&self) -> &AdditiveQ {
        &self.q
    }

    /// The task's model (`None` for a task given by its actions, [`for_task`](Self::for_task)).
    #[must_use]
    pub fn model(&self) -> Option<&EnvModel> {
        self.model.as_ref()
    }

    /// The learning discount.
    #[must_use]
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// Each agent's actions.
    #[must_use]
    pub fn actions(&self) -> &[ActionTable] {
        &self.actions
    }

    /// The joint actions: every agent's actions, agent 0 most significant.
    pub fn joint(&self) -> Result<fuzzyq_core::JointActions<'_, f64>, EvalError> {
        let mut sets = [fuzzyq_core::ActionSet::default(); fuzzyq_core::MAX_AGENTS];
        let n = self.actions.len();
        if n == 0 || n > fuzzyq_core::MAX_AGENTS {
            return Err(EvalError::Agents { found: n });
        }
        for (s, t) in sets.iter_mut().zip(&self.actions) {
            *s = t.set::<f64>();
        }
        fuzzyq_core::JointActions::try_new(&sets[..n])
    }

    /// Length of the joint action vector.
    #[must_use]
    pub fn action_dim(&self) -> usize {
        self.actions.iter().map(ActionTable::dim).sum()
    }

    /// Length of what the policy acts on: the task's state, or the agents' observations
    /// concatenated (a point mass's own state, a robot's sensors).
    #[must_use]
    pub fn input_dim(&self) -> usize {
        match &self.observe {
            Observe::Variables { state_dim, .. } => *state_dim,
            _ => (0..self.q.n_agents())
                .map(|i| self.q.features().obs_dim(i).unwrap_or(0))
                .sum(),
        }
    }

    /// Every agent's observation in an input `x` of [`input_dim`](Self::input_dim) values:
    /// its variables of the task's state, or its consecutive slice.
    pub fn split<'a>(&self, x: &'a [f64]) -> Result<Vec<Cow<'a, [f64]>>, SimError> {
        check_len("state", self.input_dim(), x.len())?;
        if let Observe::Variables { of_agent, .. } = &self.observe {
            return Ok(of_agent
                .iter()
                .map(|vars| Cow::Owned(vars.iter().map(|&d| x[d]).collect()))
                .collect());
        }
        let mut start = 0;
        Ok((0..self.q.n_agents())
            .map(|i| {
                let d = self.q.features().obs_dim(i).unwrap_or(0);
                start += d;
                Cow::Borrowed(&x[start - d..start])
            })
            .collect())
    }

    /// Writes agent action indices `indices` as the joint action vector `u`.
    pub fn write_actions(&self, indices: &[usize], u: &mut [f64]) {
        let mut at = 0;
        for (t, &a) in self.actions.iter().zip(indices) {
            u[at..at + t.dim()].copy_from_slice(t.action(a));
            at += t.dim();
        }
    }

    /// Calls `f` with every agent's observation at `obs`: its own slice of the state (the point
    /// masses), its sensors computed into `buf` (the robots), or its variables of the state.
    fn each_observation(
        &self,
        obs: &Observation<'_>,
        buf: &mut Vec<f64>,
        mut f: impl FnMut(usize, &[f64]) -> Result<(), SimError>,
    ) -> Result<(), SimError> {
        if self.observe != Observe::Sensors {
            for (i, o) in self.split(obs.state)?.iter().enumerate() {
                f(i, o)?;
            }
            return Ok(());
        }
        for i in 0..self.q.n_agents() {
            let pose = obs.state.get(3 * i..3 * i + 3);
            let (Some(p), Some(sonar)) = (pose, obs.sonar.get(i)) else {
                return Err(ConfigError::invalid(
                    "plant",
                    "a robot policy needs the robots' poses and sonars",
                )
                .into());
            };
            buf.resize(sonar.len() + 2, 0.0);
            observation([p[0], p[1], p[2]], sonar, buf);
            f(i, buf)?;
        }
        Ok(())
    }

    /// The greedy joint action at `obs`: each agent's action index into `out`.
    pub fn act_indices(&self, obs: &Observation<'_>, out: &mut [usize]) -> Result<(), SimError> {
        self.act_indices_with(obs, out, &mut Vec::new())
    }

    fn act_indices_with(
        &self,
        obs: &Observation<'_>,
        out: &mut [usize],
        buf: &mut Vec<f64>,
    ) -> Result<(), SimError> {
        check_len("joint action", self.q.n_agents(), out.len())?;
        self.each_observation(obs, buf, |i, o| {
            out[i] = self.q.greedy(i, o)?;
            Ok(())
        })
    }

    /// `max_u Q` at `obs`.
    pub fn value(&self, obs: &Observation<'_>) -> Result<f64, SimError> {
        let mut total = 0.0;
        self.each_observation(obs, &mut Vec::new(), |i, o| {
            total += self.q.greedy_with_value(i, o)?.1;
            Ok(())
        })?;
        Ok(total)
    }
}

/// Decides with an [`AdditivePolicy`]: every agent the argmax of its own term.
#[derive(Debug)]
pub struct AdditiveController<'p> {
    policy: &'p AdditivePolicy,
    indices: Vec<usize>,
    obs: Vec<f64>,
}

impl Controller for AdditiveController<'_> {
    fn act(&mut self, obs: &Observation<'_>, u: &mut [f64]) -> Result<(), SimError> {
        self.policy
            .act_indices_with(obs, &mut self.indices, &mut self.obs)?;
        self.policy.write_actions(&self.indices, u);
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
            PolicyFile::Tabulated(_) => {
                return Err(ConfigError::invalid(
                    "policy",
                    "the file holds a solution of a model defined in Python (a \
                     fuzzyq.CallableModel), which only Python can run: \
                     fuzzyq.load(path, model=...)",
                )
                .into());
            }
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
            Self::Additive(p) => p.model(),
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
                    obs: Vec::new(),
                })
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::fql::FeatureSpace;

    /// Two agents of a 4-variable task: agent 0 observes variables 0 and 1 and has 2 actions
    /// of one value, agent 1 observes variable 3 and has 3 actions of two values.
    fn task_data() -> TaskPolicyData {
        let features = FeatureSpace::new(vec![
            vec![vec![0.0, 1.0], vec![0.0, 1.0]],
            vec![vec![0.0, 0.5, 1.0]],
        ])
        .unwrap();
        let mut q = AdditiveQ::new(features, vec![2, 3]).unwrap();
        // Agent 0 prefers action 1 everywhere, agent 1 action 2 near variable 3 = 1.
        q.phi[0] = vec![0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        q.phi[1] = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 2.0];
        TaskPolicyData {
            q,
            actions: vec![
                (vec![-1.0, 1.0], 1),
                (vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0], 2),
            ],
            state_dim: 4,
            variables: vec![vec![0, 1], vec![3]],
            gamma: 0.9,
        }
    }

    #[test]
    fn a_task_policy_observes_its_variables_and_writes_each_agents_actions() {
        let policy = AdditivePolicy::for_task(task_data()).unwrap();
        assert!(policy.model().is_none());
        assert_eq!((policy.input_dim(), policy.action_dim()), (4, 3));
        let x = [0.2, 0.7, 123.0, 1.0];
        let obs = policy.split(&x).unwrap();
        assert_eq!(obs[0].as_ref(), &[0.2, 0.7]);
        assert_eq!(obs[1].as_ref(), &[1.0]);
        let mut indices = [0; 2];
        policy
            .act_indices(
                &Observation {
                    state: &x,
                    sonar: &[],
                },
                &mut indices,
            )
            .unwrap();
        assert_eq!(indices, [1, 2]);
        let mut u = [0.0; 3];
        policy.write_actions(&indices, &mut u);
        assert_eq!(u, [1.0, 0.0, 1.0]);
        assert_eq!(policy.joint().unwrap().compose(&indices).unwrap(), 5);
        assert!(policy.split(&x[..3]).is_err());
        // It round-trips as data.
        let again = AdditivePolicy::for_task(policy.task_data().unwrap()).unwrap();
        assert_eq!(again.task_data(), policy.task_data());
    }

    #[test]
    fn a_task_policy_that_does_not_fit_its_q_function_is_refused() {
        let mut data = task_data();
        data.variables[1] = vec![4];
        let e = AdditivePolicy::for_task(data).unwrap_err().to_string();
        assert!(e.contains("variables[1]"), "{e}");
        let mut data = task_data();
        data.actions[0] = (vec![-1.0, 0.0, 1.0], 1);
        let e = AdditivePolicy::for_task(data).unwrap_err().to_string();
        assert!(e.contains("actions[0]"), "{e}");
        let mut data = task_data();
        data.variables.pop();
        assert!(AdditivePolicy::for_task(data).is_err());
        let mut data = task_data();
        data.gamma = 1.5;
        assert!(AdditivePolicy::for_task(data).is_err());
    }
}
