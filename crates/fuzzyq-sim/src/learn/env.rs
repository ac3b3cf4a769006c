//! What a learner from samples interacts with: an episodic multi-agent environment.

use rand_pcg::Pcg64Mcg;

/// An episodic multi-agent environment that a model-free learner interacts with.
///
/// The learner calls [`reset`](Self::reset), then alternates [`observe`](Self::observe) (for
/// every agent) and [`step`](Self::step) until a terminal transition or the step limit. Every
/// random draw of the environment should come from the `rng` it is given, so that a run is
/// reproducible from its seed.
pub trait Environment {
    /// Number of agents `n` (at least 1).
    fn n_agents(&self) -> usize;
    /// Number of discrete actions `M_i` of agent `agent` (at least 1).
    fn n_actions(&self, agent: usize) -> usize;
    /// Length of agent `agent`'s observation vector (the dimensions of its fuzzy partition).
    fn obs_dim(&self, agent: usize) -> usize;
    /// Starts a new episode; the environment draws its start state from `rng` if it randomises.
    fn reset(&mut self, rng: &mut Pcg64Mcg);
    /// Agent `agent`'s current observation (continuous values; the learner fuzzifies them).
    /// `out` has length [`obs_dim(agent)`](Self::obs_dim).
    fn observe(&self, agent: usize, out: &mut [f64]);
    /// Applies one discrete action index per agent and advances one step.
    fn step(&mut self, actions: &[usize], rng: &mut Pcg64Mcg) -> Transition;
    /// Whether the current state counts as a success (checked when an evaluation episode
    /// ends). The default reports none; an evaluation episode also succeeds when it ends with
    /// a terminal transition of positive reward.
    fn success(&self) -> bool {
        false
    }
    /// Whether the environment cut the episode at the last step (a time limit of its own,
    /// such as a Gymnasium `TimeLimit`): the episode ends there, and the last transition
    /// bootstraps as one cut at the learner's step limit does. The default never cuts.
    fn truncated(&self) -> bool {
        false
    }
    /// The largest magnitude of a step's reward, when the environment knows it: the learners
    /// from samples then keep every parameter within `reward_bound / (1 - gamma)`, the
    /// largest discounted return (the projected update; see [`crate::learn::fql`]). The
    /// default knows none and projects nothing.
    fn reward_bound(&self) -> Option<f64> {
        None
    }
}

/// The outcome of one [`Environment::step`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition {
    /// The reward `r_{k+1}` (must be finite).
    pub reward: f64,
    /// The episode ended in an absorbing state: no bootstrap from the next state.
    pub terminal: bool,
}
