//! The one rollout loop: a [`Controller`] acting on a [`Plant`].
//!
//! Every run in fuzzyq goes through [`rollout`], whatever the learner (fuzzy Q-iteration's
//! greedy and interpolated policies, the additive policies learned from samples) and whatever
//! the plant (a model, the rapier point masses, the robots with sonars): from the start, for
//! each step, the controller decides from what the plant shows, the reward of that action is
//! recorded, and the plant advances; a run stops early at a terminal state of the model.
//! [`crate::run::evaluate`] builds the task-level runs on it (one start, many starts) and
//! [`crate::run::metrics`] measures them.

use crate::error::SimError;
use crate::run::metrics::Trajectory;
use crate::run::plant::{Observation, Plant};

/// What decides the joint action at each step.
pub trait Controller {
    /// Writes the joint action vector for what the plant shows into `u` (the plant's
    /// [`action_dim`](Plant::action_dim) values).
    fn act(&mut self, obs: &Observation<'_>, u: &mut [f64]) -> Result<(), SimError>;

    /// The value the policy predicts for a run from `start`, whose first observation is
    /// `first` (the interpolated `V` of fuzzy Q-iteration at the start state; `max Q` of a
    /// learned policy at the first observations).
    fn value_at_start(&self, start: &[f64], first: &Observation<'_>) -> Result<f64, SimError>;
}

/// A run: its trajectory, whether it ended in a terminal state, and the value the policy
/// predicted for its start.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    /// States, actions and rewards.
    pub trajectory: Trajectory,
    /// The run stopped at a terminal state of the model.
    pub terminal: bool,
    /// See [`Controller::value_at_start`].
    pub value_x0: f64,
}

/// Runs `controller` on `plant` for at most `steps` steps from `start`.
pub fn rollout<C, P>(
    controller: &mut C,
    plant: &mut P,
    start: &[f64],
    steps: usize,
) -> Result<Run, SimError>
where
    C: Controller + ?Sized,
    P: Plant + ?Sized,
{
    plant.reset(start)?;
    let value_x0 = controller.value_at_start(start, &plant.observe())?;
    let mut states = vec![plant.recorded_state()];
    let mut actions = Vec::with_capacity(steps);
    let mut rewards = Vec::with_capacity(steps);
    let mut u = vec![0.0; plant.action_dim()];
    let mut terminal = false;
    for _ in 0..steps {
        controller.act(&plant.observe(), &mut u)?;
        rewards.push(plant.reward(&u));
        terminal = plant.step(&u)?;
        actions.push(u.clone());
        states.push(plant.recorded_state());
        if terminal {
            break;
        }
    }
    Ok(Run {
        trajectory: Trajectory {
            dt: plant.sample_time(),
            agents: plant.n_agents(),
            states,
            actions,
            rewards,
        },
        terminal,
        value_x0,
    })
}
