//! Rolling a policy out on the model and measuring the run.

use fuzzyq_core::{Model, Real};
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError};
use crate::learn::fql::AdditiveQ;
use crate::model::EnvModel;
use crate::model::pointmass::PointMass;
use crate::run::policy::{AnyPolicy, Policy, PolicyKind};

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
    crate::run::evaluate::check_state(model, x0)
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
    plant: impl FnMut(&[f64], &[f64], &mut [f64]) -> Result<(), SimError>,
) -> Result<(Trajectory, RolloutMetrics), SimError>
where
    EnvModel: Model<T>,
{
    let model = point_mass_of(policy)?;
    check_x0(model, x0)?;
    let mut actor = policy.actor(kind)?;
    let action_dim = actor.action_dim();
    let trajectory = drive(
        model,
        x0,
        steps,
        action_dim,
        |x, u| actor.act(x, u).map(|_| ()),
        plant,
    )?;
    let metrics = measure(
        model,
        &trajectory,
        policy.config().solver.gamma,
        kind,
        policy.value(x0)?,
    );
    Ok((trajectory, metrics))
}

/// The core of every point-mass rollout: from `x0` (already checked), for `steps` steps,
/// `act(x, u)` writes the joint force `u` (length `action_dim`) for state `x`, the reward
/// `rho(x, u)` is recorded and `plant(x, u, next)` advances the state.
pub(crate) fn drive(
    model: &PointMass,
    x0: &[f64],
    steps: usize,
    action_dim: usize,
    mut act: impl FnMut(&[f64], &mut [f64]) -> Result<(), SimError>,
    mut plant: impl FnMut(&[f64], &[f64], &mut [f64]) -> Result<(), SimError>,
) -> Result<Trajectory, SimError> {
    let n = x0.len();
    let mut states = vec![x0.to_vec()];
    let mut actions = Vec::with_capacity(steps);
    let mut rewards = Vec::with_capacity(steps);
    let mut u = vec![0.0; action_dim];
    let mut next = vec![0.0; n];
    for _ in 0..steps {
        let x = states.last().expect("at least x0");
        act(x, &mut u)?;
        rewards.push(Model::<f64>::reward(model, x, &u));
        plant(x, &u, &mut next)?;
        actions.push(u.clone());
        states.push(next.clone());
    }
    Ok(Trajectory {
        dt: model.config().sample_time,
        agents: model.config().agents,
        states,
        actions,
        rewards,
    })
}

/// Checks that `q` is a Q-function for the point-mass model: one term per agent, each
/// observing its own state `(s_x, s_y, v_x, v_y)` (4 values) with the model's per-agent
/// actions.
pub fn check_additive(model: &PointMass, q: &AdditiveQ) -> Result<(), SimError> {
    let agents = model.config().agents;
    if q.n_agents() != agents {
        return Err(ConfigError::invalid(
            "q",
            format!(
                "has {} agents, the point-mass model has {agents}",
                q.n_agents()
            ),
        )
        .into());
    }
    for i in 0..agents {
        let dim = q.features().obs_dim(i).unwrap_or(0);
        if dim != 4 {
            return Err(ConfigError::invalid(
                "q",
                format!(
                    "agent {i} observes {dim} values; a point-mass agent observes its own \
                     (s_x, s_y, v_x, v_y)"
                ),
            )
            .into());
        }
        let m = Model::<f64>::action_set(model, i).n_actions();
        if q.actions()[i] != m {
            return Err(ConfigError::invalid(
                "q",
                format!(
                    "agent {i} has {} actions, the model has {m} per agent",
                    q.actions()[i]
                ),
            )
            .into());
        }
    }
    Ok(())
}

/// Runs the greedy decentralised policy of an additive Q-function `q` (fuzzy or codebook
/// features, see [`crate::learn::fql`]) for `steps` steps from `x0` on the point-mass model: agent
/// `i` takes the argmax of its own term at its own state `(s_x, s_y, v_x, v_y)` (the lowest
/// action index on ties), as the model's per-agent action of that index. Measured as
/// [`rollout`] measures a fuzzy Q-iteration policy ([`PolicyKind::Greedy`]; `gamma`, in
/// `[0, 1]`, discounts the return; `value_x0` is [`AdditiveQ::value`] at `x0`).
///
/// Errors: `q` does not fit the model (agents, observation length 4, action counts), `x0`
/// outside the state space, `gamma` out of range.
pub fn rollout_additive(
    model: &PointMass,
    q: &AdditiveQ,
    x0: &[f64],
    steps: usize,
    gamma: f64,
) -> Result<(Trajectory, RolloutMetrics), SimError> {
    check_additive(model, q)?;
    check_x0(model, x0)?;
    if !(0.0..=1.0).contains(&gamma) {
        return Err(
            ConfigError::invalid("gamma", format!("must be in [0, 1], got {gamma}")).into(),
        );
    }
    let agents = model.config().agents;
    let trajectory = drive(
        model,
        x0,
        steps,
        2 * agents,
        |x, u| {
            for i in 0..agents {
                let a = q.greedy(i, &x[4 * i..4 * i + 4])?;
                u[2 * i..2 * i + 2].copy_from_slice(Model::<f64>::action_set(model, i).action(a));
            }
            Ok(())
        },
        |x, u, next| {
            model.step_f64(x, u, next);
            Ok(())
        },
    )?;
    let obs: Vec<&[f64]> = x0.chunks(4).collect();
    let value_x0 = q.value(&obs)?;
    let metrics = measure(model, &trajectory, gamma, PolicyKind::Greedy, value_x0);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::fql::{Codebook, FeatureSpace};
    use crate::model::pointmass::PointMassConfig;

    fn one_agent() -> PointMass {
        PointMass::new(PointMassConfig {
            agents: 1,
            ..PointMassConfig::default()
        })
        .unwrap()
    }

    /// Cores `[-6, 0, 6]` for positions and `[-3, 0, 3]` for velocities (81 cores): action 0
    /// `(-2, -2)` is worth 1 at the cores with `s_x = 6`, action 24 `(2, 2)` is worth 0.8 at
    /// the cores with `s_x = 0`, everything else 0.
    fn hand_q() -> AdditiveQ {
        let p = vec![-6.0, 0.0, 6.0];
        let v = vec![-3.0, 0.0, 3.0];
        let features = FeatureSpace::new(vec![vec![p.clone(), p, v.clone(), v]]).unwrap();
        let mut phi = vec![0.0; 81 * 25];
        for d in 0..81 {
            // Row-major: s_x is the slowest index (stride 27).
            match d / 27 {
                2 => phi[d * 25] = 1.0,
                1 => phi[d * 25 + 24] = 0.8,
                _ => {}
            }
        }
        AdditiveQ::from_params(features, vec![25], vec![phi]).unwrap()
    }

    #[test]
    fn rollout_additive_takes_the_hand_computed_greedy_actions() {
        let model = one_agent();
        let q = hand_q();
        // s_x = 3: memberships 1/2 at s_x = 0 and 6, so Q = (0.5, ..., 0.4): action 0.
        let (t, m) = rollout_additive(&model, &q, &[3.0, 1.0, 0.5, 0.0], 3, 0.9).unwrap();
        assert_eq!(t.actions[0], [-2.0, -2.0]);
        assert!((m.value_x0 - 0.5).abs() < 1e-12);
        let mut next = [0.0; 4];
        model.step_f64(&[3.0, 1.0, 0.5, 0.0], &[-2.0, -2.0], &mut next);
        assert_eq!(t.states[1], next);
        assert_eq!(
            (t.states.len(), t.actions.len(), t.rewards.len()),
            (4, 3, 3)
        );
        assert_eq!(m.policy_kind, PolicyKind::Greedy);
        assert_eq!(m.steps, 3);
        // s_x = 1: memberships 5/6 at s_x = 0, 1/6 at 6: Q(0) = 1/6 < Q(24) = 2/3: action 24.
        let (t, m) = rollout_additive(&model, &q, &[1.0, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [2.0, 2.0]);
        assert!((m.value_x0 - 0.8 * 5.0 / 6.0).abs() < 1e-12);
        // s_x = -6: only cores with s_x = -6 are active, every value is 0 and the lowest index
        // wins: action 0.
        let (t, _) = rollout_additive(&model, &q, &[-6.0, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [-2.0, -2.0]);
    }

    #[test]
    fn rollout_additive_runs_codebook_policies_and_checks_its_inputs() {
        let model = one_agent();
        let book = Codebook::new(
            vec![vec![2.0, 0.0, 0.0, 0.0], vec![-2.0, 0.0, 0.0, 0.0]],
            vec![1.0; 4],
        )
        .unwrap();
        let features = FeatureSpace::codebook(vec![book]).unwrap();
        let mut phi = vec![0.0; 2 * 25];
        phi[7] = 1.0; // cell 0: (-0.2, 0)
        phi[25 + 22] = 2.0; // cell 1: (2, 0) = (levels[4], levels[2])
        let q = AdditiveQ::from_params(features, vec![25], vec![phi]).unwrap();
        let (t, m) = rollout_additive(&model, &q, &[0.5, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [-0.2, 0.0]);
        assert_eq!(m.value_x0, 1.0);
        let (t, m) = rollout_additive(&model, &q, &[-0.5, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [2.0, 0.0]);
        assert_eq!(m.value_x0, 2.0);

        // Mismatches are errors.
        let err = |r: Result<(Trajectory, RolloutMetrics), SimError>| {
            r.expect_err("expected an error").to_string()
        };
        let two = PointMass::paper();
        assert!(err(rollout_additive(&two, &q, &[0.0; 8], 1, 0.9)).contains("has 1 agents"));
        let nine = PointMass::new(PointMassConfig {
            agents: 1,
            force_levels: vec![-1.0, 0.0, 1.0],
            ..PointMassConfig::default()
        })
        .unwrap();
        assert!(err(rollout_additive(&nine, &q, &[0.0; 4], 1, 0.9)).contains("25 actions"));
        let wide = FeatureSpace::new(vec![vec![vec![0.0, 1.0]; 3]]).unwrap();
        let q3 = AdditiveQ::new(wide, vec![25]).unwrap();
        assert!(err(rollout_additive(&model, &q3, &[0.0; 4], 1, 0.9)).contains("observes 3"));
        assert!(err(rollout_additive(&model, &q, &[0.0; 3], 1, 0.9)).starts_with("x0:"));
        assert!(
            err(rollout_additive(
                &model,
                &q,
                &[f64::NAN, 0.0, 0.0, 0.0],
                1,
                0.9
            ))
            .starts_with("x0:")
        );
        assert!(err(rollout_additive(&model, &q, &[0.0; 4], 1, f64::NAN)).starts_with("gamma:"));
        let (t, _) = rollout_additive(&model, &q, &[0.0; 4], 0, 0.9).unwrap();
        assert_eq!(t.states.len(), 1);
    }
}
