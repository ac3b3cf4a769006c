//! Acting with a trained policy: the greedy policy (eq 7) and the interpolated policy (eq 22).

use fuzzyq_core::solver::{BackupPath, Grid, Operator};
use fuzzyq_core::{Backup, JointActions, Model, Real, q};
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError};
use crate::io::config::TrainConfig;
use crate::io::policy_file::{PolicyArtifact, Values};
use crate::model::EnvModel;
use crate::train::{build_grid, build_model};

/// Which policy to derive from a solution.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PolicyKind {
    /// The joint action maximising `Q(x, .)`, lowest index on ties (eq 7).
    #[default]
    Greedy,
    /// The membership-weighted average of the active cores' greedy actions (eq 22).
    Interpolated,
}

impl PolicyKind {
    /// The name used on the command line.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Self::Greedy => "greedy",
            Self::Interpolated => "interpolated",
        }
    }
}

/// A trained policy in precision `T`: the model, the grid, `V` and the per-core greedy actions.
pub struct Policy<T: Real> {
    config: TrainConfig,
    model: EnvModel,
    grid: Grid<T>,
    v: Vec<T>,
    greedy: Vec<u32>,
}

impl<T: Real> Policy<T>
where
    EnvModel: Model<T>,
{
    /// Assembles a policy from its parts (lengths are checked).
    pub fn new(config: TrainConfig, v: Vec<T>, greedy: Vec<u32>) -> Result<Self, SimError> {
        let model = build_model(&config)?;
        let grid = build_grid::<T>(&config)?;
        if v.len() != grid.n_cores() || greedy.len() != grid.n_cores() {
            return Err(ConfigError::invalid(
                "policy",
                format!(
                    "{} values and {} greedy actions for a grid of {} cores",
                    v.len(),
                    greedy.len(),
                    grid.n_cores()
                ),
            )
            .into());
        }
        Ok(Self {
            config,
            model,
            grid,
            v,
            greedy,
        })
    }

    /// The training configuration.
    #[must_use]
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The model.
    #[must_use]
    pub fn model(&self) -> &EnvModel {
        &self.model
    }

    /// `V` per core.
    #[must_use]
    pub fn values(&self) -> &[T] {
        &self.v
    }

    /// The fuzzy interpolation of `V` at `x`.
    pub fn value(&self, x: &[f64]) -> Result<f64, SimError> {
        let xt: Vec<T> = x.iter().map(|&v| T::from_f64(v)).collect();
        Ok(self.grid.view().active(&xt)?.interpolate(&self.v).to_f64())
    }

    /// An actor for `kind`: holds the work buffers (and, for the greedy policy, the prepared
    /// backup operator) so that each decision allocates nothing new.
    pub fn actor(&self, kind: PolicyKind) -> Result<Actor<'_, T>, SimError> {
        let op = match kind {
            PolicyKind::Greedy => {
                let s = &self.config.solver;
                let backup = Backup {
                    gamma: T::from_f64(s.gamma),
                    absorbing_goal: s.absorbing_goal,
                };
                Some(Operator::new(
                    &self.model,
                    self.grid.view(),
                    backup,
                    BackupPath::Auto,
                )?)
            }
            PolicyKind::Interpolated => None,
        };
        let joint = fuzzyq_core::model::joint_actions(&self.model)?;
        Ok(Actor {
            policy: self,
            kind,
            op,
            q: vec![T::ZERO; joint.n_joint()],
            x: vec![T::ZERO; self.grid.n_dims()],
            u: vec![T::ZERO; joint.dim()],
            joint,
        })
    }
}

/// Decides joint actions for a [`Policy`].
pub struct Actor<'p, T: Real> {
    policy: &'p Policy<T>,
    kind: PolicyKind,
    op: Option<Operator<'p, T, EnvModel>>,
    joint: JointActions<'p, T>,
    q: Vec<T>,
    x: Vec<T>,
    u: Vec<T>,
}

impl<T: Real> Actor<'_, T>
where
    EnvModel: Model<T>,
{
    /// Length of the joint action vector.
    #[must_use]
    pub fn action_dim(&self) -> usize {
        self.joint.dim()
    }

    /// The joint action vector at state `x`, written into `out`. Returns the joint action index
    /// for the greedy policy (`None` for the interpolated one, whose action is continuous).
    pub fn act(&mut self, x: &[f64], out: &mut [f64]) -> Result<Option<usize>, SimError> {
        if x.len() != self.x.len() {
            return Err(fuzzyq_core::EvalError::Length {
                what: "state",
                expected: self.x.len(),
                found: x.len(),
            }
            .into());
        }
        for (a, &b) in self.x.iter_mut().zip(x) {
            *a = T::from_f64(b);
        }
        let index = match (&self.op, self.kind) {
            (Some(op), PolicyKind::Greedy) => {
                op.q_values(&self.policy.v, &self.x, &mut self.q)?;
                let u = q::argmax(&self.q).unwrap_or(0);
                self.joint.vector(u, &mut self.u)?;
                Some(u)
            }
            _ => {
                q::interpolated_action(
                    &self.policy.grid.view(),
                    &self.joint,
                    &self.policy.greedy,
                    &self.x,
                    &mut self.u,
                )?;
                None
            }
        };
        for (o, &u) in out.iter_mut().zip(&self.u) {
            *o = u.to_f64();
        }
        Ok(index)
    }

    /// `Q(x, .)` of the last greedy decision.
    #[must_use]
    pub fn last_q(&self) -> &[T] {
        &self.q
    }
}

/// A policy of either precision, as loaded from a file.
pub enum AnyPolicy {
    /// Single precision.
    F32(Policy<f32>),
    /// Double precision.
    F64(Policy<f64>),
}

impl AnyPolicy {
    /// Builds the policy a policy file describes.
    pub fn from_artifact(a: PolicyArtifact) -> Result<Self, SimError> {
        Ok(match a.values {
            Values::F32(v) => Self::F32(Policy::new(a.config, v, a.greedy)?),
            Values::F64(v) => Self::F64(Policy::new(a.config, v, a.greedy)?),
        })
    }
}
