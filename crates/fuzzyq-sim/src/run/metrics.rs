//! A run's record ([`Trajectory`]) and what it achieved, measured in one place per task: the point masses and the robots
//! ([`RolloutMetrics`], [`KheperaMetrics`], and over many starts [`PointMassReport`],
//! [`SuccessReport`]) and the classic benchmarks ([`RunSummary`], [`MonteCarlo`]).

use fuzzyq_core::q::PolicyKind;
use serde::{Deserialize, Serialize};

use crate::model::khepera::KheperaModel;
use crate::model::pointmass::PointMass;
use crate::world::Collisions;

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

/// An agent has arrived when its position is within this distance of the origin (m).
pub const ARRIVAL_RADIUS: f64 = 0.1;

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
    /// The value the policy predicts for the start: `V` interpolated at `x0` (fuzzy
    /// Q-iteration) or `max_u Q` at the first observations (a policy learned from samples).
    pub value_x0: f64,
}

/// The metrics of a trajectory whose states hold `(s_x, s_y, v_x, v_y)` per agent (the point
/// masses, and the robots in the paper's state), with the reward region given by `in_goal`.
pub fn measure(
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

/// The point-mass metrics of a run (the reward region of `model`).
#[must_use]
pub fn measure_point_masses(
    model: &PointMass,
    t: &Trajectory,
    gamma: f64,
    kind: PolicyKind,
    value_x0: f64,
) -> RolloutMetrics {
    measure(|x| model.in_goal_f64(x), t, gamma, kind, value_x0)
}

/// Mean over agents of the final distance to the goal (cm).
#[must_use]
pub fn mean_final_error_cm(m: &RolloutMetrics) -> f64 {
    100.0 * m.final_error_m.iter().sum::<f64>() / m.final_error_m.len().max(1) as f64
}

/// The point masses over many starts: how many reach the reward region, how fast, how close
/// they end.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointMassReport {
    /// Number of starts.
    pub starts: usize,
    /// Fraction of the starts from which the run reaches the reward region.
    pub success_rate: f64,
    /// Mean time to the reward region over the successful runs (s).
    pub mean_time_to_goal_s: Option<f64>,
    /// Mean over runs and agents of the final distance to the goal (cm).
    pub mean_final_error_cm: f64,
}

impl PointMassReport {
    /// Summarises the runs.
    #[must_use]
    pub fn from_runs(runs: &[RolloutMetrics]) -> Self {
        let reached: Vec<f64> = runs.iter().filter_map(|m| m.reach_time_s).collect();
        Self {
            starts: runs.len(),
            success_rate: if runs.is_empty() {
                0.0
            } else {
                reached.len() as f64 / runs.len() as f64
            },
            mean_time_to_goal_s: (!reached.is_empty())
                .then(|| reached.iter().sum::<f64>() / reached.len() as f64),
            mean_final_error_cm: if runs.is_empty() {
                f64::NAN
            } else {
                runs.iter().map(mean_final_error_cm).sum::<f64>() / runs.len() as f64
            },
        }
    }
}

/// A Khepera run on the plant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KheperaRun {
    /// The run in the paper's state (actions are the wheel speeds `(v_l, v_r)` per robot).
    pub trajectory: Trajectory,
    /// Poses `(x, y, heading)` per robot, `steps + 1` of them.
    pub poses: Vec<Vec<[f64; 3]>>,
    /// Discrete action index per robot and step (see [`crate::model::khepera::ACTION_NAMES`]); for
    /// the interpolated policy, the nearest of the four to the averaged wheel speeds.
    pub action_indices: Vec<Vec<usize>>,
    /// Sonar readings per robot at every state (m).
    pub sonar: Vec<Vec<Vec<f64>>>,
}

/// What a Khepera run achieved: the point-mass metrics plus collisions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KheperaMetrics {
    /// The metrics shared with the point-mass rollout.
    #[serde(flatten)]
    pub rollout: RolloutMetrics,
    /// Initial headings (degrees).
    pub headings_deg: Vec<f64>,
    /// The plant's seed.
    pub seed: u64,
    /// Collisions on the plant.
    pub collisions: Collisions,
    /// `||x||` of the final 8-D state.
    pub final_norm: f64,
    /// The final state is inside the reward region and no collision happened.
    pub success: bool,
}

/// The metrics of a run on the plant.
pub fn measure_khepera(
    model: &KheperaModel,
    run: &KheperaRun,
    collisions: Collisions,
    gamma: f64,
    kind: PolicyKind,
    value_x0: f64,
    seed: u64,
) -> KheperaMetrics {
    let in_region = |x: &[f64]| model.in_region_paper(x);
    let t = &run.trajectory;
    let rollout = measure(in_region, t, gamma, kind, value_x0);
    let last = t.states.last().expect("at least x0");
    KheperaMetrics {
        success: in_region(last) && collisions.total == 0,
        rollout,
        headings_deg: run.poses[0].iter().map(|p| p[2].to_degrees()).collect(),
        seed,
        collisions,
        final_norm: last.iter().map(|v| v * v).sum::<f64>().sqrt(),
    }
}

/// Success over many starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SuccessReport {
    /// Number of starts.
    pub starts: usize,
    /// Seed of the starts (and base seed of the plant).
    pub seed: u64,
    /// Runs that ended in the reward region without a collision.
    pub successes: usize,
    /// `successes / starts`.
    pub success_rate: f64,
    /// Runs with at least one collision.
    pub runs_with_collisions: usize,
    /// Mean time to first reach the reward region over the runs that reached it (s).
    pub mean_reach_time_s: Option<f64>,
    /// Mean final `||x||` over all runs.
    pub mean_final_norm: f64,
}

impl SuccessReport {
    /// Summarises the runs from the starts drawn with `seed`.
    #[must_use]
    pub fn from_runs(seed: u64, runs: &[KheperaMetrics]) -> Self {
        let count = runs.len();
        let successes = runs.iter().filter(|m| m.success).count();
        let reached: Vec<f64> = runs.iter().filter_map(|m| m.rollout.reach_time_s).collect();
        Self {
            starts: count,
            seed,
            successes,
            success_rate: successes as f64 / count.max(1) as f64,
            runs_with_collisions: runs.iter().filter(|m| m.collisions.total > 0).count(),
            mean_reach_time_s: (!reached.is_empty())
                .then(|| reached.iter().sum::<f64>() / reached.len() as f64),
            mean_final_norm: runs.iter().map(|m| m.final_norm).sum::<f64>() / count.max(1) as f64,
        }
    }
}

/// What one run achieved.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// The initial state.
    pub x0: Vec<f64>,
    /// Steps simulated (fewer than asked when the run reached a terminal state).
    pub steps: usize,
    /// Whether the run ended in a terminal state of the model.
    pub terminal: bool,
    /// Discounted return `sum_k gamma^k rho(x_k, u_k)` over the run.
    #[serde(rename = "return")]
    pub discounted_return: f64,
    /// The final state.
    pub final_state: Vec<f64>,
    /// The value the policy predicts for the start: `V` interpolated at `x0` (fuzzy
    /// Q-iteration) or `max_u Q` at the first observations (a policy learned from samples).
    pub value_x0: f64,
}

/// The Monte-Carlo evaluation of a policy over a set of initial states.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MonteCarlo {
    /// The policy used.
    pub policy_kind: PolicyKind,
    /// Steps per run.
    pub steps: usize,
    /// The discount of the returns.
    pub gamma: f64,
    /// Mean discounted return over the runs.
    pub mean_return: f64,
    /// Smallest return.
    pub min_return: f64,
    /// Largest return.
    pub max_return: f64,
    /// Every run, in the order of the initial states.
    pub runs: Vec<RunSummary>,
}

impl RunSummary {
    /// The summary of a run from `x0` (`terminal`: it ended in a terminal state).
    #[must_use]
    pub fn of(t: &Trajectory, x0: &[f64], terminal: bool, gamma: f64, value_x0: f64) -> Self {
        Self {
            x0: x0.to_vec(),
            steps: t.actions.len(),
            terminal,
            discounted_return: t.rewards.iter().rev().fold(0.0, |acc, &r| r + gamma * acc),
            final_state: t.states.last().expect("at least x0").clone(),
            value_x0,
        }
    }
}

impl MonteCarlo {
    /// Averages the returns of `runs` (at least one).
    #[must_use]
    pub fn from_runs(runs: Vec<RunSummary>, kind: PolicyKind, steps: usize, gamma: f64) -> Self {
        let returns = runs.iter().map(|r| r.discounted_return);
        Self {
            policy_kind: kind,
            steps,
            gamma,
            mean_return: returns.clone().sum::<f64>() / runs.len() as f64,
            min_return: returns.clone().fold(f64::INFINITY, f64::min),
            max_return: returns.fold(f64::NEG_INFINITY, f64::max),
            runs,
        }
    }
}
