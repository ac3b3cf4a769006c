//! Rolling a policy out on the model and measuring the run.

use fuzzyq_core::{Model, Real};
use serde::{Deserialize, Serialize};

use crate::env::EnvModel;
use crate::error::{ConfigError, SimError};
use crate::pointmass::PointMass;
use crate::policy::{AnyPolicy, Policy, PolicyKind};

/// An agent has arrived when its position is within this distance of the origin (m).
pub const ARRIVAL_RADIUS: f64 = 0.1;

/// The paper's initial state for figures 2-4.
pub const PAPER_X0: [f64; 8] = [-4.0, -6.0, -2.0, 2.0, 5.0, 3.0, 2.0, -1.0];

/// A simulated run: `steps + 1` states, `steps` actions and rewards.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    /// Sample time (s).
    pub dt: f64,
    /// Number of agents.
    pub agents: usize,
    /// States `x_0 ..= x_K`.
    pub states: Vec<Vec<f64>>,
    /// Joint action vectors `u_0 .. u_{K-1}`.
    pub actions: Vec<Vec<f64>>,
    /// Rewards `rho(x_k, u_k)`, `k < K`.
    pub rewards: Vec<f64>,
}

impl Trajectory {
    /// Time of step `k` (s).
    #[must_use]
    pub fn time(&self, k: usize) -> f64 {
        k as f64 * self.dt
    }
}

/// What a rollout achieved (the `--json` of `fuzzyq rollout`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RolloutMetrics {
    /// The policy used.
    pub policy_kind: PolicyKind,
    /// The initial state.
    pub x0: Vec<f64>,
    /// Steps simulated.
    pub steps: usize,
    /// Sample time (s).
    pub dt: f64,
    /// First step at which the reward condition holds (`None` if never).
    pub reach_step: Option<usize>,
    /// `reach_step * dt`.
    pub reach_time_s: Option<f64>,
    /// Per agent: first time within [`ARRIVAL_RADIUS`] of the origin.
    pub arrival_time_s: Vec<Option<f64>>,
    /// Per agent: distance to the origin at the end (m).
    pub final_error_m: Vec<f64>,
    /// Discounted return `sum_k gamma^k rho(x_k, u_k)`.
    #[serde(rename = "return")]
    pub discounted_return: f64,
    /// Steps spent in the reward region.
    pub steps_in_goal: usize,
    /// `V` interpolated at `x0`: the value the solution predicts for the start.
    pub value_x0: f64,
}

/// Checks an initial state against the model's state space.
pub fn check_x0(model: &PointMass, x0: &[f64]) -> Result<(), SimError> {
    let n = Model::<f64>::state_dim(model);
    if x0.len() != n {
        return Err(ConfigError::invalid(
            "x0",
            format!("needs {n} values (the state length), got {}", x0.len()),
        )
        .into());
    }
    for (i, &v) in x0.iter().enumerate() {
        let (lo, hi) = Model::<f64>::state_bounds(model, i);
        if !(v >= lo && v <= hi) {
            return Err(ConfigError::invalid(
                "x0",
                format!("x0[{i}] = {v} is outside the state range [{lo}, {hi}]"),
            )
            .into());
        }
    }
    Ok(())
}

/// The point-mass model of a policy, or an error naming the policy's environment.
pub fn point_mass_of<T: Real>(policy: &Policy<T>) -> Result<&PointMass, SimError>
where
    EnvModel: Model<T>,
{
    policy.model().point_mass().ok_or_else(|| {
        ConfigError::invalid(
            "env",
            format!(
                "this is a {} policy; point-mass rollouts need a pointmass policy",
                policy.model().name()
            ),
        )
        .into()
    })
}

/// Runs `policy` for `steps` steps from `x0` on the model (integrated in `f64`).
pub fn rollout<T: Real>(
    policy: &Policy<T>,
    x0: &[f64],
    steps: usize,
    kind: PolicyKind,
) -> Result<(Trajectory, RolloutMetrics), SimError>
where
    EnvModel: Model<T>,
{
    let model = point_mass_of(policy)?;
    rollout_on(policy, x0, steps, kind, |x, u, next| {
        model.step_f64(x, u, next);
        Ok(())
    })
}

/// The point-mass rollout driver: `plant(x, u, next)` advances the state `x` under the joint
/// force `u` by one sample time (the analytic model, or a physics plant).
pub(crate) fn rollout_on<T: Real>(
    policy: &Policy<T>,
    x0: &[f64],
    steps: usize,
    kind: PolicyKind,
    mut plant: impl FnMut(&[f64], &[f64], &mut [f64]) -> Result<(), SimError>,
) -> Result<(Trajectory, RolloutMetrics), SimError>
where
    EnvModel: Model<T>,
{
    let model = point_mass_of(policy)?;
    check_x0(model, x0)?;
    let mut actor = policy.actor(kind)?;
    let n = x0.len();
    let mut states = vec![x0.to_vec()];
    let mut actions = Vec::with_capacity(steps);
    let mut rewards = Vec::with_capacity(steps);
    let mut u = vec![0.0; actor.action_dim()];
    let mut next = vec![0.0; n];
    for _ in 0..steps {
        let x = states.last().expect("at least x0");
        actor.act(x, &mut u)?;
        rewards.push(Model::<f64>::reward(model, x, &u));
        plant(x, &u, &mut next)?;
        actions.push(u.clone());
        states.push(next.clone());
    }
    let trajectory = Trajectory {
        dt: model.config().sample_time,
        agents: model.config().agents,
        states,
        actions,
        rewards,
    };
    let metrics = measure(
        model,
        &trajectory,
        policy.config().solver.gamma,
        kind,
        policy.value(x0)?,
    );
    Ok((trajectory, metrics))
}

/// Runs a policy of either precision.
pub fn rollout_any(
    policy: &AnyPolicy,
    x0: &[f64],
    steps: usize,
    kind: PolicyKind,
) -> Result<(Trajectory, RolloutMetrics), SimError> {
    match policy {
        AnyPolicy::F32(p) => rollout(p, x0, steps, kind),
        AnyPolicy::F64(p) => rollout(p, x0, steps, kind),
    }
}

fn measure(
    model: &PointMass,
    t: &Trajectory,
    gamma: f64,
    kind: PolicyKind,
    value_x0: f64,
) -> RolloutMetrics {
    measure_with(|x| model.in_goal_f64(x), t, gamma, kind, value_x0)
}

/// The metrics of a trajectory whose states hold `(s_x, s_y, v_x, v_y)` per agent, with the
/// reward region given by `in_goal`.
pub(crate) fn measure_with(
    in_goal: impl Fn(&[f64]) -> bool,
    t: &Trajectory,
    gamma: f64,
    kind: PolicyKind,
    value_x0: f64,
) -> RolloutMetrics {
    let reach_step = t.states.iter().position(|x| in_goal(x));
    let dist = |x: &[f64], i: usize| {
        let p = PointMass::position(x, i);
        p[0].hypot(p[1])
    };
    let arrival_time_s = (0..t.agents)
        .map(|i| {
            t.states
                .iter()
                .position(|x| dist(x, i) < ARRIVAL_RADIUS)
                .map(|k| t.time(k))
        })
        .collect();
    let last = t.states.last().expect("at least x0");
    let discounted_return = t.rewards.iter().rev().fold(0.0, |acc, &r| r + gamma * acc);
    RolloutMetrics {
        policy_kind: kind,
        x0: t.states[0].clone(),
        steps: t.actions.len(),
        dt: t.dt,
        reach_step,
        reach_time_s: reach_step.map(|k| t.time(k)),
        arrival_time_s,
        final_error_m: (0..t.agents).map(|i| dist(last, i)).collect(),
        discounted_return,
        steps_in_goal: t.states.iter().filter(|x| in_goal(x)).count(),
        value_x0,
    }
}
