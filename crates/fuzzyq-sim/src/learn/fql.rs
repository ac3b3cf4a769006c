//! Model-free fuzzy Q-learning (paper section 2.5, eqs 23-27) for episodic multi-agent tasks.
//!
//! Fuzzy Q-iteration ([`crate::train`]) needs the model `f` and the reward `rho`; this module
//! learns from interaction alone, which is the model-free variant the paper lists as future
//! work and the algorithm of its section 2.5 read as on-line Q-learning. A learner only needs
//! an [`Environment`]: episodes that start with [`reset`](Environment::reset), observations per
//! agent and one discrete action per agent per step.
//!
//! # Parameter layout (project notes, section 2, `additive`)
//! Agent `i` observes a vector `obs_i(x)` of `E_i` continuous values, fuzzified by its own
//! product of triangular partitions with `N_i` cores (a [`FeatureSpace`]), and has `M_i`
//! discrete actions. Its parameters `phi[i]` are one flat table of `N_i * M_i` values, row-major
//! by core: the parameter of core `d` and action `u_i` is `phi[i][d * M_i + u_i]`. The joint
//! Q-function is eq 13 read per agent, a linear fuzzy value decomposition:
//!
//! ```text
//! Q(x, u) = sum_i sum_d mu_d(obs_i(x)) phi[i][d * M_i + u_i]
//! ```
//!
//! Only the `<= 2^E_i` cores active at `obs_i(x)` contribute, with memberships summing to 1.
//! Because `Q` is a sum of per-agent terms, the maximum over joint actions is the sum of the
//! per-agent maxima, and the greedy joint action is the tuple of per-agent greedy actions
//! (decentralised; every agent breaks ties by the lowest action index). The layout has no
//! contraction guarantee (unlike the `joint` layout of fuzzy Q-iteration); it is trained by the
//! sample updates below, starting from `phi = 0` (eq 23).
//!
//! # The corrected update ([`Update::Corrected`], the default; notes, section 3)
//! Semi-gradient Q-learning with the memberships as features. After the transition
//! `(x_k, u_k) -> (r_{k+1}, x_{k+1})`:
//!
//! ```text
//! delta = r_{k+1} + gamma * max_{u'} Q(x_{k+1}, u') - Q(x_k, u_k)
//! phi[i][d * M_i + u_{k,i}] += alpha_k * delta * mu_d(obs_i(x_k))   for every agent i and
//!                                                                   every core d active at x_k
//! ```
//!
//! The bootstrap term `gamma * max Q(x_{k+1}, .)` is 0 when the transition is
//! [`terminal`](Transition::terminal) (an absorbing end); an episode cut at
//! [`max_steps`](FqlConfig::max_steps) is a truncation and bootstraps normally.
//!
//! # The literal update ([`Update::Literal`], eqs 24-26 as printed, kept for ablation)
//! As printed, `Gamma` (eq 25) weighs the parameters with the memberships of the *next* state
//! `f(x_k, u_k) = x_{k+1}`, `beta` (eq 24) looks two steps ahead (`f(x_{k+1}, u')`), and
//! `Omega` (eq 26) is the sum of all normalised memberships, a scalar. A model-free learner
//! cannot look two steps ahead, so this module evaluates `beta` at `x_{k+1}` like `Gamma`:
//!
//! ```text
//! Gamma   = sum_i sum_d mu_d(obs_i(x_{k+1})) phi[i][d * M_i + u_{k,i}]     = Q(x_{k+1}, u_k)
//! beta    = gamma * max_{u'} sum_i sum_d mu_d(obs_i(x_{k+1})) phi[i][d * M_i + u'_i]
//!                                                                         = gamma * max Q(x_{k+1}, .)
//! Omega   = sum_i sum_d mu_d(obs_i(x_{k+1}))                              (= n, the agent count)
//! phi[i][d * M_i + u_{k,i}] += alpha_k * (r_{k+1} + beta - Gamma) * Omega
//! ```
//!
//! `beta` is 0 on a terminal transition, as in the corrected form. The printed left-hand side
//! leaves the core `d` and the action `j` free; updating literally every parameter would shift
//! the whole table by one constant, which never changes a greedy action. This module applies the
//! increment to the parameters of the action each agent took at every core active (membership
//! `> 0`) in the next state `x_{k+1}`, the states eqs 25-26 look at. Every updated parameter
//! gets the *same* increment, whatever its membership: the printed form keeps no credit
//! assignment, so it need not learn well. It is kept to measure exactly that.
//!
//! # Codebook features: tabular Q-learning ([`FeatureSpace::codebook`], VQQL)
//! The cells of an observation need not be fuzzy. With codebook features each agent's
//! observation activates exactly one cell, its nearest [`Codebook`] centroid, with membership
//! 1 ([`ActiveCores::single`]), so `Q(x, u) = sum_i phi[i][c_i(x) * M_i + u_i]` and the
//! corrected update `phi[i][c_i(x_k) * M_i + u_{k,i}] += alpha_k * delta` is exactly tabular
//! Q-learning over the cells (with the same additive joint value and decentralised greedy
//! action). The literal update then adds its increment to the cell of the next state. Every
//! other part of [`learn`] (exploration, schedules, evaluations, the convergence window, the
//! curve) is shared; the fuzzy path is compiled separately and unchanged.
//!
//! # Exploration and step sizes
//! Epsilon-greedy per agent: each agent independently takes a uniformly random action with
//! probability `epsilon_k` and its greedy action otherwise. `epsilon_k` decays linearly from
//! [`epsilon`](FqlConfig::epsilon) to [`epsilon_min`](FqlConfig::epsilon_min) over
//! [`epsilon_decay_episodes`](FqlConfig::epsilon_decay_episodes) episodes (0: constant
//! `epsilon`). The step size of episode `k` (0-based) is
//! `alpha_k = alpha / (1 + k / alpha_decay)`; `alpha_decay` of 0 or infinity keeps it constant.
//!
//! # Convergence (eq 27)
//! Eq 27 stops when `||phi_{k+1} - phi_k||_inf <= xi`. Per sample, that change is
//! `alpha * |delta| * mu`, which does not vanish while exploration keeps visiting states whose
//! TD error the approximation cannot remove, so the criterion is applied over a window: after
//! episode `k`, `param_change = ||phi_k - phi_{k - window}||_inf` (the parameters after episode
//! `k` against those after episode `k - window`; `NaN` until a full window has passed). The
//! run has converged at the first episode with `param_change <= tolerance`, but not while no
//! update has changed any parameter yet: with `phi = 0` and no reward seen, every change is 0
//! and the test would pass vacuously. The window difference is computed exactly from a log of
//! the values each update overwrote during the last `window` episodes, so it costs memory in
//! proportion to the updates in a window, not `window` copies of `phi`.
//!
//! # Evaluation and determinism
//! Every [`eval_every`](FqlConfig::eval_every) episodes (and after the last one) the greedy
//! policy (`epsilon = 0`, no learning) runs [`eval_episodes`](FqlConfig::eval_episodes)
//! episodes. They draw from their own RNG stream, seeded by [`eval_seed`] of the configured
//! seed and reseeded at every evaluation, so every evaluation faces the same start states
//! (common random numbers) and evaluating never changes what is learned. Learning draws from a
//! [`Pcg64Mcg`] seeded with [`seed`](FqlConfig::seed); the same seed, configuration and
//! environment give bit-identical parameters and learning curves.
//!
//! ```
//! use fuzzyq_sim::learn::fql::{self, Environment, FeatureSpace, FqlConfig, Transition};
//! use rand_pcg::Pcg64Mcg;
//!
//! /// One agent on [0, 1]: left, stay or right by 0.25; reward 1 on reaching 1.
//! struct Line(f64);
//! impl Environment for Line {
//!     fn n_agents(&self) -> usize { 1 }
//!     fn n_actions(&self, _: usize) -> usize { 3 }
//!     fn obs_dim(&self, _: usize) -> usize { 1 }
//!     fn reset(&mut self, _: &mut Pcg64Mcg) { self.0 = 0.0 }
//!     fn observe(&self, _: usize, out: &mut [f64]) { out[0] = self.0 }
//!     fn step(&mut self, actions: &[usize], _: &mut Pcg64Mcg) -> Transition {
//!         self.0 = (self.0 + 0.25 * (actions[0] as f64 - 1.0)).clamp(0.0, 1.0);
//!         Transition { reward: f64::from(u8::from(self.0 >= 1.0)), terminal: self.0 >= 1.0 }
//!     }
//! }
//!
//! let features = FeatureSpace::new(vec![vec![vec![0.0, 0.25, 0.5, 0.75, 1.0]]])?;
//! // Explore fully at first: with phi = 0 the greedy action is the lowest index (left).
//! let config = FqlConfig {
//!     episodes: 200,
//!     max_steps: 20,
//!     epsilon: 1.0,
//!     epsilon_decay_episodes: 100,
//!     ..FqlConfig::default()
//! };
//! let outcome = fql::learn(&mut Line(0.0), &features, &config, |_| {
//!     std::ops::ControlFlow::Continue(())
//! })?;
//! assert_eq!(outcome.q.greedy(0, &[0.5])?, 2); // right
//! assert_eq!(outcome.curve.last().and_then(|r| r.eval_success_rate), Some(1.0));
//! # Ok::<(), fuzzyq_sim::SimError>(())
//! ```

use std::collections::VecDeque;
use std::fmt;
use std::io::Write;
use std::ops::ControlFlow;

use fuzzyq_core::partition::{ActiveCores, ProductPartition};
use fuzzyq_core::{EvalError, MAX_DIMS};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::ser::SerializeStruct;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::error::{ConfigError, SimError};

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
}

/// The outcome of one [`Environment::step`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition {
    /// The reward `r_{k+1}` (must be finite).
    pub reward: f64,
    /// The episode ended in an absorbing state: no bootstrap from the next state.
    pub terminal: bool,
}

/// Which sample update trains the parameters (see the [module docs](self)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Update {
    /// Semi-gradient Q-learning: `phi += alpha * delta * mu(x_k)` (project notes, section 3).
    #[default]
    Corrected,
    /// Eqs 24-26 as printed (one increment `alpha * (r + beta - Gamma) * Omega` for every
    /// updated parameter), kept for ablation.
    Literal,
}

/// Why a [`learn`] run stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// All [`episodes`](FqlConfig::episodes) ran.
    EpisodeLimit,
    /// The convergence test passed and [`stop_at_convergence`](FqlConfig::stop_at_convergence)
    /// is set.
    Converged,
    /// The progress callback returned [`ControlFlow::Break`].
    Callback,
    /// An update would have made a parameter non-finite; it was not applied and the run ended
    /// with the last finite parameters.
    Diverged,
}

/// Settings of a fuzzy Q-learning run. Missing fields take their [`Default`] values when
/// deserialised; unknown fields are rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FqlConfig {
    /// The sample update.
    pub update: Update,
    /// Discount factor `gamma`, in `[0, 1)`.
    pub gamma: f64,
    /// Maximum number of learning episodes, `>= 1`.
    pub episodes: usize,
    /// Steps per episode, `>= 1`; an episode cut here is truncated (it bootstraps normally).
    pub max_steps: usize,
    /// Initial step size `alpha`, in `(0, 1]`.
    pub alpha: f64,
    /// Step-size decay: `alpha_k = alpha / (1 + k / alpha_decay)` in episode `k`; 0 or infinity
    /// keeps `alpha` constant. Must not be negative.
    pub alpha_decay: f64,
    /// Initial exploration probability, in `[0, 1]`.
    pub epsilon: f64,
    /// Final exploration probability, in `[0, epsilon]`.
    pub epsilon_min: f64,
    /// Episodes over which `epsilon` decays linearly to `epsilon_min`; 0 keeps `epsilon`
    /// constant.
    pub epsilon_decay_episodes: usize,
    /// Seed of the learning RNG (evaluations use [`eval_seed`] of it).
    pub seed: u64,
    /// Convergence threshold `xi` of eq 27 on the windowed change, finite and `>= 0`.
    pub tolerance: f64,
    /// Episodes between the two parameter vectors compared by the convergence test, `>= 1`.
    pub window: usize,
    /// Stop at the first converged episode (otherwise only report it and run all episodes).
    pub stop_at_convergence: bool,
    /// Evaluate the greedy policy every this many episodes (and after the last); 0 disables.
    pub eval_every: usize,
    /// Episodes per evaluation, `>= 1` when evaluating.
    pub eval_episodes: usize,
}

impl Default for FqlConfig {
    /// The corrected update with the paper's discount (0.96), a constant step size of 0.1 and
    /// epsilon decaying from 0.3 to 0.05 over 500 of 1000 episodes.
    fn default() -> Self {
        Self {
            update: Update::Corrected,
            gamma: 0.96,
            episodes: 1000,
            max_steps: 200,
            alpha: 0.1,
            alpha_decay: 0.0,
            epsilon: 0.3,
            epsilon_min: 0.05,
            epsilon_decay_episodes: 500,
            seed: 0,
            tolerance: 1e-3,
            window: 50,
            stop_at_convergence: true,
            eval_every: 50,
            eval_episodes: 10,
        }
    }
}

impl FqlConfig {
    /// Checks every field; the error names the first invalid one (`fql.<field>`).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad =
            |field: &str, reason: String| Err(ConfigError::invalid(format!("fql.{field}"), reason));
        if !(0.0..1.0).contains(&self.gamma) {
            return bad("gamma", format!("must be in [0, 1), got {}", self.gamma));
        }
        if self.episodes == 0 {
            return bad("episodes", "must be at least 1".into());
        }
        if self.max_steps == 0 {
            return bad("max_steps", "must be at least 1".into());
        }
        if !(self.alpha > 0.0 && self.alpha <= 1.0) {
            return bad("alpha", format!("must be in (0, 1], got {}", self.alpha));
        }
        if self.alpha_decay.is_nan() || self.alpha_decay < 0.0 {
            return bad(
                "alpha_decay",
                format!(
                    "must be >= 0 (0 or inf: constant step size), got {}",
                    self.alpha_decay
                ),
            );
        }
        if !(0.0..=1.0).contains(&self.epsilon) {
            return bad(
                "epsilon",
                format!("must be in [0, 1], got {}", self.epsilon),
            );
        }
        if !(0.0..=self.epsilon).contains(&self.epsilon_min) {
            return bad(
                "epsilon_min",
                format!(
                    "must be in [0, epsilon = {}], got {}",
                    self.epsilon, self.epsilon_min
                ),
            );
        }
        if !(self.tolerance >= 0.0 && self.tolerance.is_finite()) {
            return bad(
                "tolerance",
                format!("must be a finite number >= 0, got {}", self.tolerance),
            );
        }
        if self.window == 0 {
            return bad("window", "must be at least 1".into());
        }
        if self.eval_every > 0 && self.eval_episodes == 0 {
            return bad(
                "eval_episodes",
                "must be at least 1 when eval_every > 0".into(),
            );
        }
        Ok(())
    }

    /// The step size `alpha_k` of episode `episode` (0-based).
    #[must_use]
    pub fn alpha_at(&self, episode: usize) -> f64 {
        if self.alpha_decay == 0.0 || self.alpha_decay.is_infinite() {
            self.alpha
        } else {
            self.alpha / (1.0 + episode as f64 / self.alpha_decay)
        }
    }

    /// The exploration probability `epsilon_k` of episode `episode` (0-based).
    #[must_use]
    pub fn epsilon_at(&self, episode: usize) -> f64 {
        if self.epsilon_decay_episodes == 0 {
            self.epsilon
        } else {
            let t = (episode as f64 / self.epsilon_decay_episodes as f64).min(1.0);
            self.epsilon * (1.0 - t) + self.epsilon_min * t
        }
    }
}

/// The seed of the evaluation RNG stream derived from a learning seed.
#[must_use]
pub fn eval_seed(seed: u64) -> u64 {
    // Any fixed odd constant gives an unrelated PCG stream after `seed_from_u64`'s mixing.
    seed ^ 0x9E37_79B9_7F4A_7C15
}

/// How every agent's observation is turned into active cells: fuzzy partitions (the paper's
/// triangular grids) or crisp codebooks (vector quantisers, for VQQL). All agents use the same
/// kind.
///
/// - Fuzzy ([`FeatureSpace::new`]): per agent, the cores of each observation dimension,
///   validated as a product partition; the active cores of an observation are its at most
///   `2^E` cores with non-zero membership. Serialised as the nested core lists
///   (`[agent][dimension][core]`), the format of every fuzzy policy file.
/// - Codebook ([`FeatureSpace::codebook`]): per agent a [`Codebook`]; the active set of an
///   observation is the single cell of its nearest centroid with membership 1
///   ([`ActiveCores::single`]). Serialised as a table `{ codebooks = [...] }`.
///
/// Deserialising accepts either form and validates it.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureSpace {
    kind: Kind,
    n_cores: Vec<usize>,
}

#[derive(Clone, Debug, PartialEq)]
enum Kind {
    Fuzzy(Vec<Vec<Vec<f64>>>),
    Codebook(Vec<Codebook>),
}

/// Builds the product partition of one agent's cores (at most [`MAX_DIMS`] dimensions).
fn grid_of<'a>(field: &str, cores: &'a [Vec<f64>]) -> Result<ProductPartition<'a, f64>, SimError> {
    if cores.len() > MAX_DIMS {
        return Err(ConfigError::invalid(
            field,
            format!(
                "an observation has at most {MAX_DIMS} dimensions, found {}",
                cores.len()
            ),
        )
        .into());
    }
    let mut refs: [&[f64]; MAX_DIMS] = [&[]; MAX_DIMS];
    for (r, c) in refs.iter_mut().zip(cores) {
        *r = c.as_slice();
    }
    ProductPartition::try_new(&refs[..cores.len()])
        .map_err(|e| ConfigError::invalid(field, e.to_string()).into())
}

impl FeatureSpace {
    /// Validates `per_agent_cores[i][e]`, the sorted cores of observation dimension `e` of
    /// agent `i` (at least one agent; per agent 1 to [`MAX_DIMS`] dimensions of at least two
    /// finite, strictly increasing cores). Errors name the agent (`features[i]`).
    pub fn new(per_agent_cores: Vec<Vec<Vec<f64>>>) -> Result<Self, SimError> {
        if per_agent_cores.is_empty() {
            return Err(ConfigError::invalid("features", "needs at least one agent").into());
        }
        let mut n_cores = Vec::with_capacity(per_agent_cores.len());
        for (i, cores) in per_agent_cores.iter().enumerate() {
            n_cores.push(grid_of(&format!("features[{i}]"), cores)?.n_cores());
        }
        Ok(Self {
            kind: Kind::Fuzzy(per_agent_cores),
            n_cores,
        })
    }

    /// Crisp features: agent `i` quantises its observation with `codebooks[i]` (at least one
    /// agent). Its "cores" are the codebook's cells, and the additive Q-function over them is
    /// a table: [`learn`] then runs tabular Q-learning (see the [module docs](self)).
    pub fn codebook(codebooks: Vec<Codebook>) -> Result<Self, SimError> {
        if codebooks.is_empty() {
            return Err(ConfigError::invalid("features", "needs at least one agent").into());
        }
        let n_cores = codebooks.iter().map(Codebook::n_cells).collect();
        Ok(Self {
            kind: Kind::Codebook(codebooks),
            n_cores,
        })
    }

    /// Number of agents.
    #[must_use]
    pub fn n_agents(&self) -> usize {
        self.n_cores.len()
    }

    /// Whether the features are codebooks (crisp cells) rather than fuzzy partitions.
    #[must_use]
    pub fn is_codebook(&self) -> bool {
        matches!(self.kind, Kind::Codebook(_))
    }

    /// The fuzzy cores, `[agent][dimension][core]`; empty for codebook features.
    #[must_use]
    pub fn cores(&self) -> &[Vec<Vec<f64>>] {
        match &self.kind {
            Kind::Fuzzy(cores) => cores,
            Kind::Codebook(_) => &[],
        }
    }

    /// The codebooks, one per agent; empty for fuzzy features.
    #[must_use]
    pub fn codebooks(&self) -> &[Codebook] {
        match &self.kind {
            Kind::Fuzzy(_) => &[],
            Kind::Codebook(books) => books,
        }
    }

    /// Observation length of agent `agent`, or `None` if there is no such agent.
    #[must_use]
    pub fn obs_dim(&self, agent: usize) -> Option<usize> {
        match &self.kind {
            Kind::Fuzzy(cores) => cores.get(agent).map(Vec::len),
            Kind::Codebook(books) => books.get(agent).map(Codebook::dim),
        }
    }

    /// Number of joint cores `N_i` of agent `agent` (cells, for a codebook), or `None` if
    /// there is no such agent.
    #[must_use]
    pub fn n_cores(&self, agent: usize) -> Option<usize> {
        self.n_cores.get(agent).copied()
    }

    /// The product partition of agent `agent` (row-major core order, see
    /// [`fuzzyq_core::partition`]). Fails for codebook features.
    pub fn grid(&self, agent: usize) -> Result<ProductPartition<'_, f64>, SimError> {
        let cores = match &self.kind {
            Kind::Fuzzy(cores) => cores,
            Kind::Codebook(_) => {
                return Err(ConfigError::invalid(
                    "features",
                    "codebook features have no fuzzy grid",
                )
                .into());
            }
        };
        let cores = cores.get(agent).ok_or(EvalError::OutOfRange {
            what: "agent",
            index: agent,
            len: cores.len(),
        })?;
        grid_of(&format!("features[{agent}]"), cores)
    }

    fn grids(&self) -> Result<Vec<ProductPartition<'_, f64>>, SimError> {
        (0..self.n_agents()).map(|i| self.grid(i)).collect()
    }

    /// The active cores of agent `agent` at its observation `obs` (checked length, finite
    /// values): the fuzzy cores with non-zero membership, or the nearest codebook cell with
    /// membership 1.
    pub fn active(&self, agent: usize, obs: &[f64]) -> Result<ActiveCores<f64>, SimError> {
        let observation = |e: EvalError| match e {
            EvalError::Length {
                expected, found, ..
            } => EvalError::Length {
                what: "observation",
                expected,
                found,
            },
            EvalError::NotFinite { index, .. } => EvalError::NotFinite {
                what: "observation",
                index,
            },
            other => other,
        };
        match &self.kind {
            Kind::Fuzzy(_) => {
                let grid = self.grid(agent)?;
                Ok(grid.active(obs).map_err(observation)?)
            }
            Kind::Codebook(books) => {
                let book = books.get(agent).ok_or(EvalError::OutOfRange {
                    what: "agent",
                    index: agent,
                    len: books.len(),
                })?;
                Ok(ActiveCores::single(book.nearest(obs)?))
            }
        }
    }

    /// Number of parameters `sum_i N_i * M_i` of the additive layout for `actions[i] = M_i`
    /// actions per agent (one count per agent, each `>= 1`).
    pub fn n_params(&self, actions: &[usize]) -> Result<usize, SimError> {
        if actions.len() != self.n_agents() {
            return Err(ConfigError::invalid(
                "actions",
                format!(
                    "expected one action count per agent ({}), found {}",
                    self.n_agents(),
                    actions.len()
                ),
            )
            .into());
        }
        let mut total = 0usize;
        for (i, (&m, &n)) in actions.iter().zip(&self.n_cores).enumerate() {
            if m == 0 {
                return Err(ConfigError::invalid(
                    format!("actions[{i}]"),
                    "an agent needs at least one action",
                )
                .into());
            }
            total = n
                .checked_mul(m)
                .and_then(|p| total.checked_add(p))
                .ok_or_else(|| ConfigError::invalid("features", "too many parameters"))?;
        }
        Ok(total)
    }
}

/// The serialised form of codebook features.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CodebookFeatures<B> {
    codebooks: B,
}

impl Serialize for FeatureSpace {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match &self.kind {
            Kind::Fuzzy(cores) => cores.serialize(s),
            Kind::Codebook(books) => CodebookFeatures { codebooks: books }.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for FeatureSpace {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Either;
        impl<'de> Visitor<'de> for Either {
            type Value = FeatureSpace;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("fuzzy cores [agent][dimension][core] or a table { codebooks = [...] }")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
                let cores = Vec::<Vec<Vec<f64>>>::deserialize(SeqAccessDeserializer::new(seq))?;
                FeatureSpace::new(cores).map_err(de::Error::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                let data = CodebookFeatures::<Vec<Codebook>>::deserialize(
                    MapAccessDeserializer::new(map),
                )?;
                FeatureSpace::codebook(data.codebooks).map_err(de::Error::custom)
            }
        }
        d.deserialize_any(Either)
    }
}

/// A vector quantiser of one agent's observation: `K` centroids `c_j` in `E` dimensions and a
/// positive scale per dimension.
///
/// An observation `x` falls in the cell of its nearest centroid under the scaled squared
/// Euclidean distance `d(x, c_j) = sum_e (x_e / s_e - c_je / s_e)^2`, computed as
/// `sum_e (x_e * w_e - z_je)^2` with `w_e = 1 / s_e` and the scaled centroids
/// `z_je = c_je * w_e` (both rounded once, in that order; every lookup and [`distance`]
/// use exactly this arithmetic). Ties go to the lowest centroid index. The scale makes
/// dimensions of different ranges (positions in m, velocities in m/s) weigh comparably;
/// a scale of 1 everywhere is the plain Euclidean distance.
///
/// Lookups use a k-d tree over the scaled centroids that returns exactly the centroid a
/// brute-force scan would (same distances, same tie rule). Serialised as
/// `{ scale = [...], centroids = [[...], ...] }` (centroids in the observation's units);
/// deserialising validates.
///
/// [`distance`]: Self::distance
#[derive(Clone, Debug)]
pub struct Codebook {
    dim: usize,
    scale: Vec<f64>,
    /// Centroids in the observation's units, row-major (`K x E`).
    centroids: Vec<f64>,
    /// `1 / scale`.
    weights: Vec<f64>,
    tree: KdTree,
}

impl PartialEq for Codebook {
    fn eq(&self, other: &Self) -> bool {
        // Everything else is derived from these.
        self.dim == other.dim && self.scale == other.scale && self.centroids == other.centroids
    }
}

impl Codebook {
    /// Validates the centroids (at least one; all of the same length, 1 to [`MAX_DIMS`];
    /// finite) and the scale (one positive, finite value per dimension) and builds the
    /// lookup. Errors name the field (`codebook.centroids`, `codebook.scale`).
    pub fn new(centroids: Vec<Vec<f64>>, scale: Vec<f64>) -> Result<Self, SimError> {
        let dim = centroids.first().map_or(0, Vec::len);
        if let Some(j) = centroids.iter().position(|c| c.len() != dim) {
            return Err(ConfigError::invalid(
                "codebook.centroids",
                format!(
                    "centroid {j} has {} values, centroid 0 has {dim}",
                    centroids[j].len()
                ),
            )
            .into());
        }
        Self::from_flat(dim, centroids.concat(), scale)
    }

    /// [`new`](Self::new) with the centroids row-major in one slice (`K x dim` values).
    pub fn from_flat(dim: usize, centroids: Vec<f64>, scale: Vec<f64>) -> Result<Self, SimError> {
        let field = "codebook.centroids";
        if dim == 0 || dim > MAX_DIMS {
            return Err(ConfigError::invalid(
                field,
                format!("centroids need 1 to {MAX_DIMS} dimensions, found {dim}"),
            )
            .into());
        }
        if centroids.is_empty() || !centroids.len().is_multiple_of(dim) {
            return Err(ConfigError::invalid(
                field,
                format!(
                    "needs at least one centroid of {dim} values, found {} values",
                    centroids.len()
                ),
            )
            .into());
        }
        let k = centroids.len() / dim;
        if k > u32::MAX as usize {
            return Err(ConfigError::invalid(field, format!("{k} centroids are too many")).into());
        }
        if scale.len() != dim {
            return Err(ConfigError::invalid(
                "codebook.scale",
                format!(
                    "needs one value per dimension ({dim}), found {}",
                    scale.len()
                ),
            )
            .into());
        }
        if let Some(s) = scale.iter().find(|s| !(**s > 0.0 && s.is_finite())) {
            return Err(ConfigError::invalid(
                "codebook.scale",
                format!("must be positive finite numbers, found {s}"),
            )
            .into());
        }
        let weights: Vec<f64> = scale.iter().map(|s| 1.0 / s).collect();
        let mut scaled = centroids.clone();
        for (k, v) in scaled.iter_mut().enumerate() {
            *v *= weights[k % dim];
            if !v.is_finite() {
                return Err(ConfigError::invalid(
                    field,
                    format!(
                        "centroid {} element {} is {} (must be finite, also after scaling)",
                        k / dim,
                        k % dim,
                        centroids[k]
                    ),
                )
                .into());
            }
        }
        let tree = KdTree::build(dim, scaled);
        Ok(Self {
            dim,
            scale,
            centroids,
            weights,
            tree,
        })
    }

    /// Number of cells (centroids) `K`.
    #[must_use]
    pub fn n_cells(&self) -> usize {
        self.centroids.len() / self.dim
    }

    /// Observation length `E`.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The scale `s_e` of each dimension.
    #[must_use]
    pub fn scale(&self) -> &[f64] {
        &self.scale
    }

    /// The centroids in the observation's units, row-major: centroid `j` is
    /// `centroids()[j * E..(j + 1) * E]`.
    #[must_use]
    pub fn centroids(&self) -> &[f64] {
        &self.centroids
    }

    /// Centroid `j`, or `None` if there is no such cell.
    #[must_use]
    pub fn centroid(&self, j: usize) -> Option<&[f64]> {
        self.centroids.get(j * self.dim..(j + 1) * self.dim)
    }

    fn check(&self, x: &[f64]) -> Result<(), EvalError> {
        if x.len() != self.dim {
            return Err(EvalError::Length {
                what: "observation",
                expected: self.dim,
                found: x.len(),
            });
        }
        if let Some(index) = x.iter().position(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite {
                what: "observation",
                index,
            });
        }
        Ok(())
    }

    /// The scaled coordinates `x_e * w_e` of an observation.
    #[inline]
    fn scaled(&self, x: &[f64]) -> [f64; MAX_DIMS] {
        let mut q = [0.0; MAX_DIMS];
        for ((q, &x), &w) in q.iter_mut().zip(x).zip(&self.weights) {
            *q = x * w;
        }
        q
    }

    /// The cell of `x` (length `E`, finite): its nearest centroid, the lowest index on ties.
    pub fn nearest(&self, x: &[f64]) -> Result<usize, SimError> {
        self.check(x)?;
        Ok(self.nearest_unchecked(x).0)
    }

    /// [`nearest`](Self::nearest) and its distance, for an observation the caller checked.
    #[inline]
    pub(crate) fn nearest_unchecked(&self, x: &[f64]) -> (usize, f64) {
        let q = self.scaled(x);
        self.tree.nearest(&q[..self.dim])
    }

    /// The nearest cell by scanning every centroid (the reference the k-d tree must match).
    #[cfg(test)]
    pub(crate) fn nearest_brute_force(&self, x: &[f64]) -> (usize, f64) {
        let q = self.scaled(x);
        self.tree.nearest_brute_force(&q[..self.dim])
    }

    /// The scaled squared distance `d(x, c_cell)` (see the [type docs](Self)).
    pub fn distance(&self, x: &[f64], cell: usize) -> Result<f64, SimError> {
        self.check(x)?;
        if cell >= self.n_cells() {
            return Err(EvalError::OutOfRange {
                what: "cell",
                index: cell,
                len: self.n_cells(),
            }
            .into());
        }
        let q = self.scaled(x);
        let t = self.tree.slot_of(cell);
        Ok(sq_dist(&q[..self.dim], self.tree.point(t)))
    }
}

/// `sum_e (a_e - b_e)^2`, summed in dimension order: the one distance of every codebook
/// lookup, so that the k-d tree and a brute-force scan agree bit for bit.
#[inline]
pub(crate) fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        let t = x - y;
        s += t * t;
    }
    s
}

/// Leaves hold at most this many centroids.
const KD_LEAF: usize = 8;

/// A k-d tree over scaled centroids for exact nearest-centroid queries.
#[derive(Clone, Debug)]
struct KdTree {
    dim: usize,
    /// Scaled centroids in tree order, row-major.
    points: Vec<f64>,
    /// Centroid index of each tree slot.
    index: Vec<usize>,
    /// Tree slot of each centroid index.
    slot: Vec<usize>,
    nodes: Vec<KdNode>,
}

/// A node: the tree slots `start..end`; an inner node splits them at `split` along
/// `split_dim` (left: coordinates `<= split`, right: `>= split`).
#[derive(Clone, Copy, Debug)]
struct KdNode {
    start: usize,
    end: usize,
    split_dim: usize,
    split: f64,
    /// Child node indices, `None` for a leaf.
    children: Option<(usize, usize)>,
}

impl KdTree {
    fn build(dim: usize, scaled: Vec<f64>) -> Self {
        let k = scaled.len() / dim;
        let mut order: Vec<usize> = (0..k).collect();
        let mut nodes = Vec::with_capacity(2 * k / KD_LEAF + 1);
        Self::build_node(&mut nodes, &mut order, 0, k, &scaled, dim);
        let mut points = Vec::with_capacity(scaled.len());
        let mut slot = vec![0; k];
        for (t, &j) in order.iter().enumerate() {
            points.extend_from_slice(&scaled[j * dim..(j + 1) * dim]);
            slot[j] = t;
        }
        Self {
            dim,
            points,
            index: order,
            slot,
            nodes,
        }
    }

    fn build_node(
        nodes: &mut Vec<KdNode>,
        order: &mut [usize],
        start: usize,
        end: usize,
        scaled: &[f64],
        dim: usize,
    ) -> usize {
        let id = nodes.len();
        nodes.push(KdNode {
            start,
            end,
            split_dim: 0,
            split: 0.0,
            children: None,
        });
        if end - start <= KD_LEAF {
            return id;
        }
        // Split the widest dimension at its median (ties ordered by index: deterministic).
        let (mut best, mut spread) = (0, 0.0);
        for e in 0..dim {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for &j in &order[start..end] {
                let v = scaled[j * dim + e];
                lo = lo.min(v);
                hi = hi.max(v);
            }
            if hi - lo > spread {
                (best, spread) = (e, hi - lo);
            }
        }
        if spread <= 0.0 {
            // All centroids of this node coincide: one leaf, scanned in full.
            return id;
        }
        let mid = start + (end - start) / 2;
        order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            scaled[a * dim + best]
                .total_cmp(&scaled[b * dim + best])
                .then(a.cmp(&b))
        });
        let split = scaled[order[mid] * dim + best];
        let left = Self::build_node(nodes, order, start, mid, scaled, dim);
        let right = Self::build_node(nodes, order, mid, end, scaled, dim);
        nodes[id] = KdNode {
            start,
            end,
            split_dim: best,
            split,
            children: Some((left, right)),
        };
        id
    }

    #[inline]
    fn point(&self, t: usize) -> &[f64] {
        &self.points[t * self.dim..(t + 1) * self.dim]
    }

    fn slot_of(&self, cell: usize) -> usize {
        self.slot[cell]
    }

    /// The nearest centroid of the scaled query `q` and its distance (lowest index on ties).
    #[inline]
    fn nearest(&self, q: &[f64]) -> (usize, f64) {
        let mut best = (usize::MAX, f64::INFINITY);
        self.search(0, q, &mut best);
        best
    }

    fn search(&self, node: usize, q: &[f64], best: &mut (usize, f64)) {
        let n = self.nodes[node];
        match n.children {
            None => self.scan(n.start, n.end, q, best),
            Some((left, right)) => {
                let diff = q[n.split_dim] - n.split;
                let (near, far) = if diff < 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.search(near, q, best);
                // Every centroid on the far side is at least |diff| away along this axis, and
                // the rounded distance is monotone in each term, so `diff^2` is a true lower
                // bound. Equal distances must be visited: a lower index may win the tie.
                if diff * diff <= best.1 {
                    self.search(far, q, best);
                }
            }
        }
    }

    #[inline]
    fn scan(&self, start: usize, end: usize, q: &[f64], best: &mut (usize, f64)) {
        for t in start..end {
            let d = sq_dist(q, self.point(t));
            let j = self.index[t];
            if d < best.1 || (d == best.1 && j < best.0) {
                *best = (j, d);
            }
        }
    }

    #[cfg(test)]
    fn nearest_brute_force(&self, q: &[f64]) -> (usize, f64) {
        let mut best = (usize::MAX, f64::INFINITY);
        for j in 0..self.index.len() {
            let d = sq_dist(q, self.point(self.slot[j]));
            if d < best.1 || best.0 == usize::MAX {
                best = (j, d);
            }
        }
        best
    }
}

/// Serialises the row-major centroids as one list per centroid.
struct Rows<'a>(&'a [f64], usize);

impl Serialize for Rows<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.chunks(self.1))
    }
}

impl Serialize for Codebook {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("Codebook", 2)?;
        st.serialize_field("scale", &self.scale)?;
        st.serialize_field("centroids", &Rows(&self.centroids, self.dim))?;
        st.end()
    }
}

impl<'de> Deserialize<'de> for Codebook {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Data {
            scale: Vec<f64>,
            centroids: Vec<Vec<f64>>,
        }
        let data = Data::deserialize(d)?;
        Self::new(data.centroids, data.scale).map_err(de::Error::custom)
    }
}

/// How [`learn`] and [`evaluate`] find the active cells of an observation the learner has
/// already checked (right length, finite): monomorphised per feature kind, so the fuzzy path
/// is the plain grid lookup.
trait Lookup {
    fn n_dims(&self) -> usize;
    fn lookup(&self, obs: &[f64]) -> ActiveCores<f64>;
}

impl Lookup for ProductPartition<'_, f64> {
    #[inline]
    fn n_dims(&self) -> usize {
        ProductPartition::n_dims(self)
    }
    #[inline]
    fn lookup(&self, obs: &[f64]) -> ActiveCores<f64> {
        self.active_unchecked(obs)
    }
}

impl Lookup for Codebook {
    #[inline]
    fn n_dims(&self) -> usize {
        self.dim
    }
    #[inline]
    fn lookup(&self, obs: &[f64]) -> ActiveCores<f64> {
        ActiveCores::single(self.nearest_unchecked(obs).0)
    }
}

/// One transition for [`AdditiveQ::update`]: per-agent observations before and after, the
/// joint action taken, the reward and whether the next state is absorbing.
#[derive(Clone, Copy, Debug)]
pub struct Sample<'a> {
    /// Observations `obs_i(x_k)`, one slice per agent.
    pub obs: &'a [&'a [f64]],
    /// The joint action `u_k`, one index per agent.
    pub actions: &'a [usize],
    /// The reward `r_{k+1}`.
    pub reward: f64,
    /// Observations `obs_i(x_{k+1})`, one slice per agent.
    pub next_obs: &'a [&'a [f64]],
    /// `x_{k+1}` is absorbing: no bootstrap.
    pub terminal: bool,
}

/// The additive fuzzy Q-function of the project notes (section 2):
/// `Q(x, u) = sum_i sum_d mu_d(obs_i) phi[i][d * M_i + u_i]`.
///
/// Serialised with its feature space, action counts and parameters; deserialising validates
/// their shapes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AdditiveQ {
    features: FeatureSpace,
    actions: Vec<usize>,
    phi: Vec<Vec<f64>>,
}

impl<'de> Deserialize<'de> for AdditiveQ {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Data {
            features: FeatureSpace,
            actions: Vec<usize>,
            phi: Vec<Vec<f64>>,
        }
        let data = Data::deserialize(d)?;
        Self::from_params(data.features, data.actions, data.phi).map_err(serde::de::Error::custom)
    }
}

/// Per-action values of one agent's term at its active cores: `out[u] = sum_d w_d phi[d*m+u]`.
#[inline]
fn agent_q(active: &ActiveCores<f64>, phi: &[f64], m: usize, out: &mut [f64]) {
    out.fill(0.0);
    active.for_each(|d, w| {
        for (o, &p) in out.iter_mut().zip(&phi[d * m..(d + 1) * m]) {
            *o += w * p;
        }
    });
}

/// The lowest index of the largest value.
#[inline]
fn argmax(q: &[f64]) -> usize {
    let mut best = 0;
    for (u, &v) in q.iter().enumerate().skip(1) {
        if v > q[best] {
            best = u;
        }
    }
    best
}

/// The largest value (`-inf` for an empty slice, which the learner never passes).
#[inline]
fn max_of(q: &[f64]) -> f64 {
    q.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

/// One transition as the update kernel sees it: the active cores before and after, the value
/// of the taken action before, the per-agent action values at the next state (before the
/// update) and the joint action.
struct Step<'s> {
    cur: &'s [ActiveCores<f64>],
    next: &'s [ActiveCores<f64>],
    q_taken: f64,
    q_next: &'s [Vec<f64>],
    actions: &'s [usize],
    reward: f64,
    terminal: bool,
}

/// Applies one sample update in place. Returns the TD error `delta` (corrected) or the bracket
/// `r + beta - Gamma` (literal), or `None`, leaving `phi` untouched, when the update is not
/// finite. `log(agent, index, old_value)` is called before each parameter is overwritten.
fn td_update(
    rule: Update,
    phi: &mut [Vec<f64>],
    m: &[usize],
    step: &Step<'_>,
    gamma: f64,
    alpha: f64,
    mut log: impl FnMut(usize, usize, f64),
) -> Option<f64> {
    let bootstrap = if step.terminal {
        0.0
    } else {
        gamma * step.q_next.iter().map(|q| max_of(q)).sum::<f64>()
    };
    match rule {
        Update::Corrected => {
            let delta = step.reward + bootstrap - step.q_taken;
            let scale = alpha * delta;
            if !scale.is_finite() {
                return None;
            }
            let mut finite = true;
            for (i, active) in step.cur.iter().enumerate() {
                let (phi_i, m_i, u_i) = (&phi[i], m[i], step.actions[i]);
                active.for_each(|d, w| finite &= (phi_i[d * m_i + u_i] + scale * w).is_finite());
            }
            if !finite {
                return None;
            }
            for (i, active) in step.cur.iter().enumerate() {
                let (phi_i, m_i, u_i) = (&mut phi[i], m[i], step.actions[i]);
                active.for_each(|d, w| {
                    let k = d * m_i + u_i;
                    log(i, k, phi_i[k]);
                    phi_i[k] += scale * w;
                });
            }
            Some(delta)
        }
        Update::Literal => {
            // Gamma (eq 25): the taken joint action valued at the next state.
            let gamma_term: f64 = step
                .q_next
                .iter()
                .zip(step.actions)
                .map(|(q, &u)| q[u])
                .sum();
            // Omega (eq 26): the memberships of the next state, summed over cores and agents.
            let mut omega = 0.0;
            for active in step.next {
                active.for_each(|_, w| omega += w);
            }
            let bracket = step.reward + bootstrap - gamma_term;
            let increment = alpha * bracket * omega;
            if !increment.is_finite() {
                return None;
            }
            let mut finite = true;
            for (i, active) in step.next.iter().enumerate() {
                let (phi_i, m_i, u_i) = (&phi[i], m[i], step.actions[i]);
                active.for_each(|d, w| {
                    if w > 0.0 {
                        finite &= (phi_i[d * m_i + u_i] + increment).is_finite();
                    }
                });
            }
            if !finite {
                return None;
            }
            for (i, active) in step.next.iter().enumerate() {
                let (phi_i, m_i, u_i) = (&mut phi[i], m[i], step.actions[i]);
                active.for_each(|d, w| {
                    if w > 0.0 {
                        let k = d * m_i + u_i;
                        log(i, k, phi_i[k]);
                        phi_i[k] += increment;
                    }
                });
            }
            Some(bracket)
        }
    }
}

impl AdditiveQ {
    /// All parameters zero (eq 23), for `actions[i] = M_i` actions per agent.
    pub fn new(features: FeatureSpace, actions: Vec<usize>) -> Result<Self, SimError> {
        let total = features.n_params(&actions)?;
        let mut phi = Vec::with_capacity(features.n_agents());
        for (&n, &m) in features.n_cores.iter().zip(&actions) {
            let mut table = Vec::new();
            table.try_reserve_exact(n * m).map_err(|_| {
                ConfigError::invalid(
                    "features",
                    format!("{total} parameters do not fit in memory"),
                )
            })?;
            table.resize(n * m, 0.0);
            phi.push(table);
        }
        Ok(Self {
            features,
            actions,
            phi,
        })
    }

    /// Given parameters: `phi[i]` has `N_i * M_i` finite values, row-major by core
    /// (`phi[i][d * M_i + u_i]`).
    pub fn from_params(
        features: FeatureSpace,
        actions: Vec<usize>,
        phi: Vec<Vec<f64>>,
    ) -> Result<Self, SimError> {
        features.n_params(&actions)?;
        if phi.len() != features.n_agents() {
            return Err(ConfigError::invalid(
                "phi",
                format!(
                    "expected one table per agent ({}), found {}",
                    features.n_agents(),
                    phi.len()
                ),
            )
            .into());
        }
        for (i, table) in phi.iter().enumerate() {
            let expected = features.n_cores[i] * actions[i];
            if table.len() != expected {
                return Err(ConfigError::invalid(
                    format!("phi[{i}]"),
                    format!(
                        "expected {} cores x {} actions = {expected} values, found {}",
                        features.n_cores[i],
                        actions[i],
                        table.len()
                    ),
                )
                .into());
            }
            if let Some(k) = table.iter().position(|v| !v.is_finite()) {
                return Err(ConfigError::invalid(
                    format!("phi[{i}]"),
                    format!("value {k} is not a finite number"),
                )
                .into());
            }
        }
        Ok(Self {
            features,
            actions,
            phi,
        })
    }

    /// The fuzzy partitions of the agents' observations.
    #[must_use]
    pub fn features(&self) -> &FeatureSpace {
        &self.features
    }

    /// Number of agents `n`.
    #[must_use]
    pub fn n_agents(&self) -> usize {
        self.actions.len()
    }

    /// Action counts `M_i`, one per agent.
    #[must_use]
    pub fn actions(&self) -> &[usize] {
        &self.actions
    }

    /// The parameters: `params()[i][d * M_i + u_i]` for agent `i`, core `d`, action `u_i`.
    #[must_use]
    pub fn params(&self) -> &[Vec<f64>] {
        &self.phi
    }

    /// The active cores of agent `agent` at `obs` (checked length, finite values).
    fn active(&self, agent: usize, obs: &[f64]) -> Result<ActiveCores<f64>, SimError> {
        self.features.active(agent, obs)
    }

    fn check_joint(&self, obs: &[&[f64]], what: &'static str) -> Result<(), EvalError> {
        if obs.len() == self.n_agents() {
            Ok(())
        } else {
            Err(EvalError::Length {
                what,
                expected: self.n_agents(),
                found: obs.len(),
            })
        }
    }

    fn check_actions(&self, actions: &[usize]) -> Result<(), EvalError> {
        if actions.len() != self.n_agents() {
            return Err(EvalError::Length {
                what: "joint action",
                expected: self.n_agents(),
                found: actions.len(),
            });
        }
        for (&u, &m) in actions.iter().zip(&self.actions) {
            if u >= m {
                return Err(EvalError::OutOfRange {
                    what: "action",
                    index: u,
                    len: m,
                });
            }
        }
        Ok(())
    }

    /// Per-action values of agent `agent`'s term at its observation `obs`:
    /// `out[u] = sum_d mu_d(obs) phi[agent][d * M + u]` (`out` has length `M_agent`).
    pub fn q_agent(&self, agent: usize, obs: &[f64], out: &mut [f64]) -> Result<(), SimError> {
        let active = self.active(agent, obs)?;
        let m = self.actions[agent];
        if out.len() != m {
            return Err(EvalError::Length {
                what: "action values",
                expected: m,
                found: out.len(),
            }
            .into());
        }
        agent_q(&active, &self.phi[agent], m, out);
        Ok(())
    }

    /// Agent `agent`'s greedy action at `obs` (the lowest index on ties).
    pub fn greedy(&self, agent: usize, obs: &[f64]) -> Result<usize, SimError> {
        let active = self.active(agent, obs)?;
        let (m, phi) = (self.actions[agent], &self.phi[agent]);
        let mut best = (0, f64::NEG_INFINITY);
        for u in 0..m {
            let mut v = 0.0;
            active.for_each(|d, w| v += w * phi[d * m + u]);
            if v > best.1 {
                best = (u, v);
            }
        }
        Ok(best.0)
    }

    /// The greedy joint action: each agent's [`greedy`](Self::greedy) action, into `out`.
    pub fn greedy_joint(&self, obs: &[&[f64]], out: &mut [usize]) -> Result<(), SimError> {
        self.check_joint(obs, "observations")?;
        if out.len() != self.n_agents() {
            return Err(EvalError::Length {
                what: "joint action",
                expected: self.n_agents(),
                found: out.len(),
            }
            .into());
        }
        for (i, (o, u)) in obs.iter().zip(out.iter_mut()).enumerate() {
            *u = self.greedy(i, o)?;
        }
        Ok(())
    }

    /// `Q(x, u)`: the sum over agents of their terms at `obs[i]` and action `actions[i]`.
    pub fn q(&self, obs: &[&[f64]], actions: &[usize]) -> Result<f64, SimError> {
        self.check_joint(obs, "observations")?;
        self.check_actions(actions)?;
        let mut total = 0.0;
        for (i, (o, &u)) in obs.iter().zip(actions).enumerate() {
            let active = self.active(i, o)?;
            let (m, phi) = (self.actions[i], &self.phi[i]);
            active.for_each(|d, w| total += w * phi[d * m + u]);
        }
        Ok(total)
    }

    /// `max_u Q(x, u)`: the sum over agents of their largest action value.
    pub fn value(&self, obs: &[&[f64]]) -> Result<f64, SimError> {
        self.check_joint(obs, "observations")?;
        let mut total = 0.0;
        for (i, o) in obs.iter().enumerate() {
            let u = self.greedy(i, o)?;
            total += self.q_single(i, o, u)?;
        }
        Ok(total)
    }

    fn q_single(&self, agent: usize, obs: &[f64], u: usize) -> Result<f64, SimError> {
        let active = self.active(agent, obs)?;
        let (m, phi) = (self.actions[agent], &self.phi[agent]);
        let mut v = 0.0;
        active.for_each(|d, w| v += w * phi[d * m + u]);
        Ok(v)
    }

    /// Applies one sample update (see the [module docs](self)) with discount `gamma` in
    /// `[0, 1)` and step size `alpha > 0`. Returns the TD error `delta` ([`Update::Corrected`])
    /// or the bracket `r + beta - Gamma` ([`Update::Literal`]). An update that would make a
    /// parameter non-finite is refused and leaves the parameters unchanged.
    pub fn update(
        &mut self,
        rule: Update,
        sample: &Sample<'_>,
        gamma: f64,
        alpha: f64,
    ) -> Result<f64, SimError> {
        if !(0.0..1.0).contains(&gamma) {
            return Err(
                ConfigError::invalid("gamma", format!("must be in [0, 1), got {gamma}")).into(),
            );
        }
        if !(alpha > 0.0 && alpha.is_finite()) {
            return Err(ConfigError::invalid(
                "alpha",
                format!("must be a positive number, got {alpha}"),
            )
            .into());
        }
        if !sample.reward.is_finite() {
            return Err(EvalError::NotFinite {
                what: "reward",
                index: 0,
            }
            .into());
        }
        self.check_joint(sample.obs, "observations")?;
        self.check_joint(sample.next_obs, "next observations")?;
        self.check_actions(sample.actions)?;
        let n = self.n_agents();
        let mut cur = Vec::with_capacity(n);
        let mut next = Vec::with_capacity(n);
        let mut q_next = Vec::with_capacity(n);
        let mut q_taken = 0.0;
        for i in 0..n {
            cur.push(self.active(i, sample.obs[i])?);
            next.push(self.active(i, sample.next_obs[i])?);
            q_taken += self.q_single(i, sample.obs[i], sample.actions[i])?;
            let mut q = vec![0.0; self.actions[i]];
            agent_q(&next[i], &self.phi[i], self.actions[i], &mut q);
            q_next.push(q);
        }
        let step = Step {
            cur: &cur,
            next: &next,
            q_taken,
            q_next: &q_next,
            actions: sample.actions,
            reward: sample.reward,
            terminal: sample.terminal,
        };
        td_update(
            rule,
            &mut self.phi,
            &self.actions,
            &step,
            gamma,
            alpha,
            |_, _, _| {},
        )
        .ok_or_else(|| {
            EvalError::NotFinite {
                what: "parameter update",
                index: 0,
            }
            .into()
        })
    }
}

/// One learning episode of a [`learn`] run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EpisodeRecord {
    /// Episode index (0-based).
    pub episode: usize,
    /// Steps taken (`<= max_steps`).
    pub steps: usize,
    /// Undiscounted sum of rewards.
    pub ret: f64,
    /// `sum_k gamma^k r_{k+1}`.
    pub discounted_return: f64,
    /// Mean of `|delta|` over the episode's updates (the bracket `r + beta - Gamma` for the
    /// literal update); `NaN` if none was applied.
    pub mean_abs_td: f64,
    /// Largest `|delta|` of the episode (0 if no update was applied).
    pub max_abs_td: f64,
    /// Exploration probability used.
    pub epsilon: f64,
    /// Step size used.
    pub alpha: f64,
    /// `||phi - phi_{window episodes ago}||_inf` after this episode, or `NaN` before a full
    /// window.
    pub param_change: f64,
    /// The episode ended with a terminal transition.
    pub terminal: bool,
    /// Mean undiscounted return of the greedy evaluation after this episode, if one ran.
    pub eval_mean_return: Option<f64>,
    /// Fraction of successful evaluation episodes, if an evaluation ran.
    pub eval_success_rate: Option<f64>,
}

/// The result of a [`learn`] run.
#[derive(Clone, Debug)]
pub struct FqlOutcome {
    /// The learned Q-function (the last finite parameters).
    pub q: AdditiveQ,
    /// One record per learning episode run.
    pub curve: Vec<EpisodeRecord>,
    /// The first episode that passed the convergence test, if any.
    pub converged_at: Option<usize>,
    /// Learning steps over all episodes (evaluation steps excluded).
    pub steps_total: usize,
    /// Why the run stopped.
    pub stop: StopReason,
}

/// Result of a greedy evaluation ([`evaluate`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Evaluation {
    /// Mean undiscounted return per episode.
    pub mean_return: f64,
    /// Fraction of episodes that succeeded: ended with a terminal transition of positive
    /// reward, or with [`Environment::success`] true.
    pub success_rate: f64,
}

/// The log of overwritten parameter values over the last `window` episodes, from which the
/// windowed change `||phi_now - phi_{window episodes ago}||_inf` is exact.
struct WindowLog {
    window: usize,
    /// `(agent, index, value before the update)`, oldest first.
    entries: VecDeque<(usize, usize, f64)>,
    /// Entries per logged episode, oldest first.
    per_episode: VecDeque<usize>,
    /// Entries of the episode in progress.
    open: usize,
    /// `stamps[agent][index] == generation`: already seen in the current scan.
    stamps: Vec<Vec<u32>>,
    generation: u32,
}

impl WindowLog {
    fn new(window: usize, phi: &[Vec<f64>]) -> Self {
        Self {
            window,
            entries: VecDeque::new(),
            per_episode: VecDeque::with_capacity(window.saturating_add(1).min(1 << 16)),
            open: 0,
            stamps: phi.iter().map(|t| vec![0; t.len()]).collect(),
            generation: 0,
        }
    }

    #[inline]
    fn record(&mut self, agent: usize, index: usize, old: f64) {
        self.entries.push_back((agent, index, old));
        self.open += 1;
    }

    /// Closes the episode and returns the windowed change (`NaN` before a full window).
    fn end_episode(&mut self, phi: &[Vec<f64>]) -> f64 {
        self.per_episode.push_back(self.open);
        self.open = 0;
        while self.per_episode.len() > self.window {
            let k = self.per_episode.pop_front().unwrap_or(0);
            self.entries.drain(..k);
        }
        if self.per_episode.len() < self.window {
            return f64::NAN;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            for s in &mut self.stamps {
                s.fill(0);
            }
            self.generation = 1;
        }
        // The first logged value of a parameter is its value `window` episodes ago.
        let mut change: f64 = 0.0;
        for &(a, k, old) in &self.entries {
            if self.stamps[a][k] != self.generation {
                self.stamps[a][k] = self.generation;
                change = change.max((phi[a][k] - old).abs());
            }
        }
        change
    }
}

/// Buffers of a run, allocated once.
struct Buffers {
    m: Vec<usize>,
    obs: Vec<Vec<f64>>,
    next_obs: Vec<Vec<f64>>,
    active: Vec<ActiveCores<f64>>,
    next_active: Vec<ActiveCores<f64>>,
    q: Vec<Vec<f64>>,
    q_next: Vec<Vec<f64>>,
    actions: Vec<usize>,
}

impl Buffers {
    fn new<L: Lookup>(grids: &[L], m: &[usize]) -> Self {
        let obs: Vec<Vec<f64>> = grids.iter().map(|g| vec![0.0; g.n_dims()]).collect();
        let active: Vec<ActiveCores<f64>> =
            grids.iter().zip(&obs).map(|(g, o)| g.lookup(o)).collect();
        let q: Vec<Vec<f64>> = m.iter().map(|&mi| vec![0.0; mi]).collect();
        Self {
            m: m.to_vec(),
            next_obs: obs.clone(),
            obs,
            next_active: active.clone(),
            active,
            q_next: q.clone(),
            q,
            actions: vec![0; m.len()],
        }
    }
}

/// Where an observation was taken, for error messages.
#[derive(Clone, Copy)]
enum At {
    Learning { episode: usize, step: usize },
    Evaluation { step: usize },
}

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Learning { episode, step } => {
                write!(f, "learning episode {episode}, step {step}")
            }
            Self::Evaluation { step } => write!(f, "evaluation, step {step}"),
        }
    }
}

/// Observes every agent into `obs` and fuzzifies into `active`, rejecting non-finite values.
fn observe_all<E: Environment, L: Lookup>(
    env: &E,
    grids: &[L],
    obs: &mut [Vec<f64>],
    active: &mut [ActiveCores<f64>],
    at: At,
) -> Result<(), SimError> {
    for (i, (o, a)) in obs.iter_mut().zip(active.iter_mut()).enumerate() {
        env.observe(i, o);
        if let Some(e) = o.iter().position(|v| !v.is_finite()) {
            return Err(ConfigError::invalid(
                "env",
                format!(
                    "agent {i} observed a non-finite value ({}) in element {e} ({at})",
                    o[e]
                ),
            )
            .into());
        }
        *a = grids[i].lookup(o);
    }
    Ok(())
}

fn check_reward(reward: f64, at: At) -> Result<(), SimError> {
    if reward.is_finite() {
        Ok(())
    } else {
        Err(
            ConfigError::invalid("env", format!("the reward is not finite ({reward}) ({at})"))
                .into(),
        )
    }
}

/// Checks that `env` matches `features` and returns its action counts.
fn check_env<E: Environment>(env: &E, features: &FeatureSpace) -> Result<Vec<usize>, SimError> {
    let n = env.n_agents();
    if n != features.n_agents() {
        return Err(ConfigError::invalid(
            "features",
            format!(
                "has {} agents, the environment has {n}",
                features.n_agents()
            ),
        )
        .into());
    }
    let mut m = Vec::with_capacity(n);
    for i in 0..n {
        let (dim, expected) = (env.obs_dim(i), features.obs_dim(i).unwrap_or(0));
        if dim != expected {
            return Err(ConfigError::invalid(
                format!("features[{i}]"),
                format!(
                    "has {expected} observation dimensions, the environment observes {dim} for agent {i}"
                ),
            )
            .into());
        }
        let mi = env.n_actions(i);
        if mi == 0 {
            return Err(ConfigError::invalid("env", format!("agent {i} has no actions")).into());
        }
        m.push(mi);
    }
    Ok(m)
}

/// Runs `episodes` greedy episodes from a fresh RNG seeded with `seed`.
fn evaluate_with<E: Environment, L: Lookup>(
    env: &mut E,
    grids: &[L],
    phi: &[Vec<f64>],
    bufs: &mut Buffers,
    episodes: usize,
    max_steps: usize,
    seed: u64,
) -> Result<Evaluation, SimError> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let (mut total, mut successes) = (0.0, 0usize);
    for _ in 0..episodes {
        env.reset(&mut rng);
        let mut ret = 0.0;
        let mut success = false;
        for step in 0..max_steps {
            let at = At::Evaluation { step };
            observe_all(env, grids, &mut bufs.obs, &mut bufs.active, at)?;
            for i in 0..bufs.m.len() {
                agent_q(&bufs.active[i], &phi[i], bufs.m[i], &mut bufs.q[i]);
                bufs.actions[i] = argmax(&bufs.q[i]);
            }
            let tr = env.step(&bufs.actions, &mut rng);
            check_reward(tr.reward, at)?;
            ret += tr.reward;
            if tr.terminal {
                success = tr.reward > 0.0;
                break;
            }
        }
        success |= env.success();
        total += ret;
        successes += usize::from(success);
    }
    Ok(Evaluation {
        mean_return: total / episodes as f64,
        success_rate: successes as f64 / episodes as f64,
    })
}

/// Runs the greedy policy of `q` (no exploration, no learning) for `episodes` episodes of at
/// most `max_steps` steps, drawing from a [`Pcg64Mcg`] seeded with `seed`. [`learn`] evaluates
/// with `seed = eval_seed(config.seed)`.
pub fn evaluate<E: Environment>(
    env: &mut E,
    q: &AdditiveQ,
    episodes: usize,
    max_steps: usize,
    seed: u64,
) -> Result<Evaluation, SimError> {
    if episodes == 0 {
        return Err(ConfigError::invalid("episodes", "must be at least 1").into());
    }
    let m = check_env(env, &q.features)?;
    if m != q.actions {
        return Err(ConfigError::invalid(
            "env",
            format!(
                "has action counts {m:?}, the Q-function was learned with {:?}",
                q.actions
            ),
        )
        .into());
    }
    match &q.features.kind {
        Kind::Fuzzy(_) => {
            let grids = q.features.grids()?;
            let mut bufs = Buffers::new(&grids, &m);
            evaluate_with(env, &grids, &q.phi, &mut bufs, episodes, max_steps, seed)
        }
        Kind::Codebook(books) => {
            let mut bufs = Buffers::new(books, &m);
            evaluate_with(env, books, &q.phi, &mut bufs, episodes, max_steps, seed)
        }
    }
}

/// Learns an [`AdditiveQ`] on `env` by fuzzy Q-learning (see the [module docs](self)).
///
/// `progress` sees every episode's record (after its evaluation, if any) and may stop the run
/// with [`ControlFlow::Break`]; the outcome then holds what was learned so far with
/// [`StopReason::Callback`]. Errors: an invalid configuration, a feature space that does not
/// match the environment (agent count, observation lengths), an agent without actions, a
/// non-finite observation (naming the agent) or reward.
pub fn learn<E: Environment>(
    env: &mut E,
    features: &FeatureSpace,
    config: &FqlConfig,
    progress: impl FnMut(&EpisodeRecord) -> ControlFlow<()>,
) -> Result<FqlOutcome, SimError> {
    config.validate()?;
    let m = check_env(env, features)?;
    let q = AdditiveQ::new(features.clone(), m.clone())?;
    match &features.kind {
        Kind::Fuzzy(_) => {
            let grids = features.grids()?;
            learn_with(env, &grids, q, m, config, progress)
        }
        Kind::Codebook(books) => learn_with(env, books, q, m, config, progress),
    }
}

/// The learning loop of [`learn`] for one kind of features.
fn learn_with<E: Environment, L: Lookup>(
    env: &mut E,
    grids: &[L],
    mut q: AdditiveQ,
    m: Vec<usize>,
    config: &FqlConfig,
    mut progress: impl FnMut(&EpisodeRecord) -> ControlFlow<()>,
) -> Result<FqlOutcome, SimError> {
    let mut bufs = Buffers::new(grids, &m);
    let mut log = WindowLog::new(config.window, &q.phi);
    let mut rng = Pcg64Mcg::seed_from_u64(config.seed);
    let eval_seed = eval_seed(config.seed);
    let n = m.len();

    let mut curve = Vec::with_capacity(config.episodes.min(1 << 20));
    let mut converged_at = None;
    let mut steps_total = 0usize;
    let mut moved = false;
    let mut stop = StopReason::EpisodeLimit;

    for episode in 0..config.episodes {
        let epsilon = config.epsilon_at(episode);
        let alpha = config.alpha_at(episode);
        env.reset(&mut rng);
        let at = At::Learning { episode, step: 0 };
        observe_all(env, grids, &mut bufs.obs, &mut bufs.active, at)?;
        for i in 0..n {
            agent_q(&bufs.active[i], &q.phi[i], m[i], &mut bufs.q[i]);
        }

        let (mut steps, mut ret, mut discounted, mut discount) = (0usize, 0.0, 0.0, 1.0);
        let (mut td_sum, mut td_max, mut updates) = (0.0, 0.0_f64, 0usize);
        let (mut terminal, mut diverged) = (false, false);
        while steps < config.max_steps {
            // Epsilon-greedy, independently per agent.
            let mut q_taken = 0.0;
            for i in 0..n {
                let u = if rng.random::<f64>() < epsilon {
                    rng.random_range(0..m[i])
                } else {
                    argmax(&bufs.q[i])
                };
                bufs.actions[i] = u;
                q_taken += bufs.q[i][u];
            }
            let tr = env.step(&bufs.actions, &mut rng);
            steps += 1;
            let at = At::Learning {
                episode,
                step: steps,
            };
            check_reward(tr.reward, at)?;
            ret += tr.reward;
            discounted += discount * tr.reward;
            discount *= config.gamma;
            observe_all(env, grids, &mut bufs.next_obs, &mut bufs.next_active, at)?;
            for i in 0..n {
                agent_q(&bufs.next_active[i], &q.phi[i], m[i], &mut bufs.q_next[i]);
            }
            let step = Step {
                cur: &bufs.active,
                next: &bufs.next_active,
                q_taken,
                q_next: &bufs.q_next,
                actions: &bufs.actions,
                reward: tr.reward,
                terminal: tr.terminal,
            };
            let result = td_update(
                config.update,
                &mut q.phi,
                &m,
                &step,
                config.gamma,
                alpha,
                |a, k, old| {
                    log.record(a, k, old);
                },
            );
            let Some(delta) = result else {
                diverged = true;
                break;
            };
            moved |= delta != 0.0;
            td_sum += delta.abs();
            td_max = td_max.max(delta.abs());
            updates += 1;
            std::mem::swap(&mut bufs.obs, &mut bufs.next_obs);
            std::mem::swap(&mut bufs.active, &mut bufs.next_active);
            if tr.terminal {
                terminal = true;
                break;
            }
            for i in 0..n {
                agent_q(&bufs.active[i], &q.phi[i], m[i], &mut bufs.q[i]);
            }
        }
        steps_total += steps;

        let param_change = log.end_episode(&q.phi);
        if converged_at.is_none() && moved && !diverged && param_change <= config.tolerance {
            converged_at = Some(episode);
        }
        let last = if diverged {
            stop = StopReason::Diverged;
            true
        } else if converged_at.is_some() && config.stop_at_convergence {
            stop = StopReason::Converged;
            true
        } else {
            episode + 1 == config.episodes
        };

        let evaluation =
            if config.eval_every > 0 && ((episode + 1) % config.eval_every == 0 || last) {
                Some(evaluate_with(
                    env,
                    grids,
                    &q.phi,
                    &mut bufs,
                    config.eval_episodes,
                    config.max_steps,
                    eval_seed,
                )?)
            } else {
                None
            };

        let record = EpisodeRecord {
            episode,
            steps,
            ret,
            discounted_return: discounted,
            mean_abs_td: if updates > 0 {
                td_sum / updates as f64
            } else {
                f64::NAN
            },
            max_abs_td: td_max,
            epsilon,
            alpha,
            param_change,
            terminal,
            eval_mean_return: evaluation.map(|e| e.mean_return),
            eval_success_rate: evaluation.map(|e| e.success_rate),
        };
        let flow = progress(&record);
        curve.push(record);
        if last {
            break;
        }
        if flow.is_break() {
            stop = StopReason::Callback;
            break;
        }
    }

    Ok(FqlOutcome {
        q,
        curve,
        converged_at,
        steps_total,
        stop,
    })
}

/// A CSV field: empty for `None` and `NaN`, otherwise the shortest round-trip decimal.
struct Field(Option<f64>);

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(v) if !v.is_nan() => write!(f, "{v}"),
            _ => Ok(()),
        }
    }
}

/// Writes a learning curve as CSV: a header row, then one row per episode. Missing values
/// (no evaluation, `param_change` before a full window, `mean_abs_td` without updates) are
/// empty fields; numbers use the shortest decimal that reads back to the same `f64`.
pub fn write_curve_csv(curve: &[EpisodeRecord], mut w: impl Write) -> std::io::Result<()> {
    writeln!(
        w,
        "episode,steps,return,discounted_return,mean_abs_td,max_abs_td,epsilon,alpha,\
         param_change,terminal,eval_mean_return,eval_success_rate"
    )?;
    for r in curve {
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            r.episode,
            r.steps,
            Field(Some(r.ret)),
            Field(Some(r.discounted_return)),
            Field(Some(r.mean_abs_td)),
            Field(Some(r.max_abs_td)),
            Field(Some(r.epsilon)),
            Field(Some(r.alpha)),
            Field(Some(r.param_change)),
            r.terminal,
            Field(r.eval_mean_return),
            Field(r.eval_success_rate),
        )?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    const STEP: f64 = 0.1;
    const GOAL: f64 = 0.95;

    /// `n` agents, each on its own line `[0, 1]`: actions left, stay, right by [`STEP`]. The
    /// joint reward 1 (terminal) comes when every agent is at `>= GOAL`. Starts are uniform in
    /// `[0, 0.9)` per agent unless fixed.
    struct Lines {
        pos: Vec<f64>,
        fixed_start: Option<Vec<f64>>,
    }

    impl Lines {
        fn new(n: usize) -> Self {
            Self {
                pos: vec![0.0; n],
                fixed_start: None,
            }
        }
    }

    impl Environment for Lines {
        fn n_agents(&self) -> usize {
            self.pos.len()
        }
        fn n_actions(&self, _: usize) -> usize {
            3
        }
        fn obs_dim(&self, _: usize) -> usize {
            1
        }
        fn reset(&mut self, rng: &mut Pcg64Mcg) {
            match &self.fixed_start {
                Some(s) => self.pos.clone_from(s),
                None => {
                    for p in &mut self.pos {
                        *p = rng.random_range(0.0..0.9);
                    }
                }
            }
        }
        fn observe(&self, agent: usize, out: &mut [f64]) {
            out[0] = self.pos[agent];
        }
        fn step(&mut self, actions: &[usize], _: &mut Pcg64Mcg) -> Transition {
            for (p, &a) in self.pos.iter_mut().zip(actions) {
                *p = (*p + STEP * (a as f64 - 1.0)).clamp(0.0, 1.0);
            }
            let done = self.pos.iter().all(|&p| p >= GOAL);
            Transition {
                reward: if done { 1.0 } else { 0.0 },
                terminal: done,
            }
        }
    }

    fn uniform_cores(k: usize) -> Vec<f64> {
        (0..k).map(|j| j as f64 / (k - 1) as f64).collect()
    }

    fn continue_all(_: &EpisodeRecord) -> ControlFlow<()> {
        ControlFlow::Continue(())
    }

    /// Runs the greedy policy of `q` from `start`; the number of steps to the goal, if reached.
    fn greedy_steps(q: &AdditiveQ, start: &[f64], limit: usize) -> Option<usize> {
        let mut env = Lines::new(start.len());
        env.pos = start.to_vec();
        let mut rng = Pcg64Mcg::seed_from_u64(0);
        let mut actions = vec![0; start.len()];
        for k in 1..=limit {
            let obs: Vec<[f64; 1]> = env.pos.iter().map(|&p| [p]).collect();
            let obs: Vec<&[f64]> = obs.iter().map(|o| &o[..]).collect();
            q.greedy_joint(&obs, &mut actions).unwrap();
            if env.step(&actions, &mut rng).terminal {
                return Some(k);
            }
        }
        None
    }

    /// Optimal values of the 1-agent line by value iteration on the lattice `j / 1000`, which
    /// the dynamics map to itself (steps of 100 lattice points).
    fn line_values(gamma: f64) -> Vec<f64> {
        let n = 1001;
        let goal = 950;
        let mut v = vec![0.0; n];
        loop {
            let mut change: f64 = 0.0;
            for j in 0..n {
                let mut best = f64::NEG_INFINITY;
                for a in [-100i64, 0, 100] {
                    let next = (j as i64 + a).clamp(0, n as i64 - 1) as usize;
                    let value = if next >= goal { 1.0 } else { gamma * v[next] };
                    best = best.max(value);
                }
                change = change.max((best - v[j]).abs());
                v[j] = best;
            }
            if change < 1e-12 {
                return v;
            }
        }
    }

    fn line_config() -> FqlConfig {
        FqlConfig {
            gamma: 0.9,
            episodes: 600,
            max_steps: 40,
            alpha: 0.2,
            alpha_decay: 200.0,
            epsilon: 1.0,
            epsilon_min: 0.05,
            epsilon_decay_episodes: 400,
            seed: 7,
            tolerance: 1e-6,
            window: 20,
            stop_at_convergence: false,
            eval_every: 25,
            eval_episodes: 20,
            ..FqlConfig::default()
        }
    }

    #[test]
    fn corridor_learns_to_reach_the_goal_with_near_optimal_values() {
        let features = FeatureSpace::new(vec![vec![uniform_cores(11)]]).unwrap();
        let config = line_config();
        let mut env = Lines::new(1);
        let out = learn(&mut env, &features, &config, continue_all).unwrap();
        assert_eq!(out.stop, StopReason::EpisodeLimit);
        assert_eq!(out.curve.len(), config.episodes);
        assert_eq!(
            out.steps_total,
            out.curve.iter().map(|r| r.steps).sum::<usize>()
        );

        // Greedy from every start reaches the goal in (nearly) the optimal number of steps.
        for j in 0..=90 {
            let start = j as f64 / 100.0;
            let optimal = ((GOAL - start) / STEP).ceil() as usize;
            let steps = greedy_steps(&out.q, &[start], 30);
            assert!(
                steps.is_some_and(|s| s <= optimal + 1),
                "start {start}: {steps:?} steps, optimal {optimal}"
            );
        }

        // Values at the cores against value iteration (within 10%).
        let v = line_values(config.gamma);
        for core in [1usize, 3, 5, 7, 9] {
            let x = core as f64 / 10.0;
            let learned = out.q.value(&[&[x]]).unwrap();
            let truth = v[core * 100];
            assert!(
                (learned - truth).abs() <= 0.1 * truth,
                "core {x}: learned {learned}, value iteration {truth}"
            );
        }

        // The learning curve's greedy evaluations reach full success and end there.
        let evals: Vec<f64> = out
            .curve
            .iter()
            .filter_map(|r| r.eval_success_rate)
            .collect();
        assert_eq!(evals.len(), config.episodes / config.eval_every);
        // The untrained greedy policy (phi = 0: lowest index, always left) never succeeds.
        let untrained = AdditiveQ::new(features.clone(), vec![3]).unwrap();
        let before = evaluate(&mut env, &untrained, 20, 40, eval_seed(config.seed)).unwrap();
        assert_eq!(before.success_rate, 0.0);
        let after = evaluate(&mut env, &out.q, 20, 40, eval_seed(config.seed)).unwrap();
        assert_eq!(after.success_rate, 1.0);
        assert_eq!(
            Some(after.mean_return),
            out.curve.last().unwrap().eval_mean_return
        );
        assert_eq!(evals.last(), Some(&1.0));
        let last = out.curve.last().unwrap();
        assert!(last.eval_mean_return.unwrap() > 0.99);
        assert!(last.param_change.is_finite());
        assert!(
            out.curve[..config.window - 1]
                .iter()
                .all(|r| r.param_change.is_nan())
        );
    }

    #[test]
    fn two_agents_learn_to_reach_the_goal_together() {
        let cores = uniform_cores(6);
        let features = FeatureSpace::new(vec![vec![cores.clone()], vec![cores]]).unwrap();
        let config = FqlConfig {
            episodes: 1000,
            max_steps: 60,
            epsilon_decay_episodes: 700,
            seed: 11,
            ..line_config()
        };
        let mut env = Lines::new(2);
        let out = learn(&mut env, &features, &config, continue_all).unwrap();
        assert_eq!(out.q.params().len(), 2);
        assert_eq!(out.q.params()[0].len(), 6 * 3);
        assert_eq!(features.n_params(&[3, 3]).unwrap(), 36);

        for a in [0.0, 0.13, 0.42, 0.77, 0.9] {
            for b in [0.0, 0.31, 0.5, 0.88] {
                let steps = greedy_steps(&out.q, &[a, b], 30);
                assert!(
                    steps.is_some_and(|s| s <= 11),
                    "start ({a}, {b}): {steps:?}"
                );
            }
        }
        assert_eq!(out.curve.last().unwrap().eval_success_rate, Some(1.0));
    }

    fn params_bits(q: &AdditiveQ) -> Vec<Vec<u64>> {
        q.params()
            .iter()
            .map(|t| t.iter().map(|v| v.to_bits()).collect())
            .collect()
    }

    fn csv(curve: &[EpisodeRecord]) -> String {
        let mut buf = Vec::new();
        write_curve_csv(curve, &mut buf).unwrap();
        String::from_utf8(buf).unwrap()
    }

    #[test]
    fn same_seed_is_bit_identical_and_other_seeds_differ() {
        let cores = uniform_cores(6);
        let features = FeatureSpace::new(vec![vec![cores.clone()], vec![cores]]).unwrap();
        let config = FqlConfig {
            episodes: 120,
            eval_every: 30,
            ..line_config()
        };
        let run = |config: &FqlConfig| {
            learn(&mut Lines::new(2), &features, config, continue_all).unwrap()
        };
        let a = run(&config);
        let b = run(&config);
        assert_eq!(params_bits(&a.q), params_bits(&b.q));
        assert_eq!(csv(&a.curve), csv(&b.curve));
        assert_eq!(a.steps_total, b.steps_total);
        let c = run(&FqlConfig {
            seed: config.seed + 1,
            ..config.clone()
        });
        assert_ne!(params_bits(&a.q), params_bits(&c.q));
        assert_ne!(csv(&a.curve), csv(&c.curve));
    }

    /// Two agents: agent 0 on cores [0, 1, 2] with 2 actions, agent 1 on cores [0, 1] with 3.
    fn hand_q() -> AdditiveQ {
        let features =
            FeatureSpace::new(vec![vec![vec![0.0, 1.0, 2.0]], vec![vec![0.0, 1.0]]]).unwrap();
        AdditiveQ::from_params(
            features,
            vec![2, 3],
            vec![
                vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                vec![0.5, -1.0, 2.0, 1.5, 0.0, -0.5],
            ],
        )
        .unwrap()
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12
    }

    #[test]
    fn corrected_update_by_hand() {
        // x_k: agent 0 at 0.25 (cores 0, 1 with 0.75, 0.25), agent 1 at 0.5 (0.5, 0.5).
        // Q(x_k, (1, 2)) = (0.75*2 + 0.25*4) + (0.5*2 + 0.5*(-0.5)) = 2.5 + 0.75 = 3.25.
        // x_{k+1}: agent 0 at 1.5 (cores 1, 2: values (4, 5), max 5), agent 1 at 1.0 (core 1:
        // values (1.5, 0, -0.5), max 1.5). max Q(x_{k+1}) = 6.5.
        // delta = 1 + 0.8 * 6.5 - 3.25 = 2.95; alpha * delta = 0.295.
        let mut q = hand_q();
        let before = q.params().to_vec();
        let sample = Sample {
            obs: &[&[0.25], &[0.5]],
            actions: &[1, 2],
            reward: 1.0,
            next_obs: &[&[1.5], &[1.0]],
            terminal: false,
        };
        assert!(close(q.q(sample.obs, sample.actions).unwrap(), 3.25));
        assert!(close(q.value(sample.next_obs).unwrap(), 6.5));
        let delta = q.update(Update::Corrected, &sample, 0.8, 0.1).unwrap();
        assert!(close(delta, 2.95), "delta {delta}");
        let mut expected = before.clone();
        expected[0][1] = 2.0 + 0.295 * 0.75;
        expected[0][3] = 4.0 + 0.295 * 0.25;
        expected[1][2] = 2.0 + 0.295 * 0.5;
        expected[1][5] = -0.5 + 0.295 * 0.5;
        for (got, want) in q.params().iter().flatten().zip(expected.iter().flatten()) {
            assert!(close(*got, *want), "{:?} vs {expected:?}", q.params());
        }
        assert!(close(q.params()[0][1], 2.22125));

        // Terminal: no bootstrap, delta = 1 - 3.25.
        let mut q = hand_q();
        let delta = q
            .update(
                Update::Corrected,
                &Sample {
                    terminal: true,
                    ..sample
                },
                0.8,
                0.1,
            )
            .unwrap();
        assert!(close(delta, -2.25));
        assert!(close(q.params()[0][1], 2.0 - 0.225 * 0.75));
        assert!(close(q.params()[1][5], -0.5 - 0.225 * 0.5));
        assert!(close(q.params()[0][0], 1.0));
    }

    #[test]
    fn literal_update_by_hand_gives_every_updated_parameter_the_same_increment() {
        // Gamma = Q(x_{k+1}, (1, 2)) = 5 + (-0.5) = 4.5; beta = 0.8 * 6.5 = 5.2;
        // bracket = 1 + 5.2 - 4.5 = 1.7; Omega = 2 (two agents); increment 0.1 * 1.7 * 2 = 0.34
        // on the taken actions at the cores active at x_{k+1}: agent 0 cores 1, 2 (action 1),
        // agent 1 core 1 (action 2).
        let mut q = hand_q();
        let before = q.params().to_vec();
        let sample = Sample {
            obs: &[&[0.25], &[0.5]],
            actions: &[1, 2],
            reward: 1.0,
            next_obs: &[&[1.5], &[1.0]],
            terminal: false,
        };
        let bracket = q.update(Update::Literal, &sample, 0.8, 0.1).unwrap();
        assert!(close(bracket, 1.7), "bracket {bracket}");
        let updated = [(0usize, 3usize), (0, 5), (1, 5)];
        for (i, (new, old)) in q.params().iter().zip(&before).enumerate() {
            for (k, (a, b)) in new.iter().zip(old).enumerate() {
                if updated.contains(&(i, k)) {
                    assert!(close(a - b, 0.34), "phi[{i}][{k}]: increment {}", a - b);
                } else {
                    assert_eq!(a, b, "phi[{i}][{k}] must not change");
                }
            }
        }
        // The corrected update of the same sample weighs by membership: unequal increments.
        let mut c = hand_q();
        c.update(Update::Corrected, &sample, 0.8, 0.1).unwrap();
        assert!(!close(c.params()[0][1] - 2.0, c.params()[0][3] - 4.0));
    }

    /// One agent, one state (on a core), two actions: reward = action index, then terminal.
    struct Bandit {
        reward_scale: f64,
    }

    impl Environment for Bandit {
        fn n_agents(&self) -> usize {
            1
        }
        fn n_actions(&self, _: usize) -> usize {
            2
        }
        fn obs_dim(&self, _: usize) -> usize {
            1
        }
        fn reset(&mut self, _: &mut Pcg64Mcg) {}
        fn observe(&self, _: usize, out: &mut [f64]) {
            out[0] = 0.0;
        }
        fn step(&mut self, actions: &[usize], _: &mut Pcg64Mcg) -> Transition {
            Transition {
                reward: self.reward_scale * actions[0] as f64,
                terminal: true,
            }
        }
    }

    #[test]
    fn windowed_convergence_stops_the_run_but_not_vacuously() {
        let features = FeatureSpace::new(vec![vec![vec![0.0, 1.0]]]).unwrap();
        let config = FqlConfig {
            episodes: 2000,
            alpha: 0.5,
            epsilon: 0.5,
            epsilon_min: 0.5,
            tolerance: 1e-6,
            window: 5,
            eval_every: 0,
            ..FqlConfig::default()
        };
        let out = learn(
            &mut Bandit { reward_scale: 1.0 },
            &features,
            &config,
            continue_all,
        )
        .unwrap();
        assert_eq!(out.stop, StopReason::Converged);
        let k = out.converged_at.unwrap();
        assert_eq!(out.curve.len(), k + 1);
        assert!(out.curve[k].param_change <= 1e-6);
        assert!(out.curve[k - 1].param_change > 1e-6 || out.curve[k - 1].param_change.is_nan());
        assert!((out.q.params()[0][1] - 1.0).abs() < 1e-5);
        assert!(out.q.params()[0][0].abs() < 1e-12);
        // Nothing evaluated when eval_every = 0.
        assert!(out.curve.iter().all(|r| r.eval_success_rate.is_none()));

        // No reward ever: phi stays 0, which must not count as convergence.
        let out = learn(
            &mut Bandit { reward_scale: 0.0 },
            &features,
            &FqlConfig {
                episodes: 50,
                ..config
            },
            continue_all,
        )
        .unwrap();
        assert_eq!(out.stop, StopReason::EpisodeLimit);
        assert_eq!(out.converged_at, None);
        assert_eq!(out.curve.len(), 50);
        assert_eq!(out.curve[10].param_change, 0.0);
    }

    #[test]
    fn callback_stops_early_and_csv_has_one_row_per_episode() {
        let features = FeatureSpace::new(vec![vec![uniform_cores(5)]]).unwrap();
        let config = FqlConfig {
            eval_every: 2,
            ..line_config()
        };
        let mut seen = 0;
        let out = learn(&mut Lines::new(1), &features, &config, |r| {
            seen += 1;
            if r.episode == 3 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .unwrap();
        assert_eq!(seen, 4);
        assert_eq!(out.stop, StopReason::Callback);
        assert_eq!(out.curve.len(), 4);
        let text = csv(&out.curve);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 5);
        assert!(lines[0].starts_with("episode,steps,return,"));
        assert_eq!(lines[1].split(',').count(), 12);
        // Episode 0: no evaluation, no full window: empty fields.
        assert!(lines[1].ends_with(",,"), "{}", lines[1]);
        assert!(!lines[2].ends_with(",,"), "{}", lines[2]);
    }

    #[test]
    fn literal_ablation_runs_and_keeps_parameters_finite() {
        let features = FeatureSpace::new(vec![vec![uniform_cores(11)]]).unwrap();
        let config = FqlConfig {
            update: Update::Literal,
            episodes: 200,
            ..line_config()
        };
        let out = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
        assert!(out.q.params().iter().flatten().all(|v| v.is_finite()));
        assert!(!out.curve.is_empty());
    }

    #[test]
    fn schedules() {
        let c = FqlConfig {
            alpha: 0.5,
            alpha_decay: 10.0,
            epsilon: 0.9,
            epsilon_min: 0.1,
            epsilon_decay_episodes: 4,
            ..FqlConfig::default()
        };
        assert_eq!(c.alpha_at(0), 0.5);
        assert!(close(c.alpha_at(10), 0.25));
        assert!(close(c.epsilon_at(2), 0.5));
        assert_eq!(c.epsilon_at(4), 0.1);
        assert_eq!(c.epsilon_at(100), 0.1);
        let constant = FqlConfig {
            alpha_decay: f64::INFINITY,
            epsilon_decay_episodes: 0,
            ..c
        };
        assert_eq!(constant.alpha_at(1000), 0.5);
        assert_eq!(constant.epsilon_at(1000), 0.9);
    }

    fn err_text<T: fmt::Debug>(r: Result<T, SimError>) -> String {
        r.expect_err("expected an error").to_string()
    }

    #[test]
    fn bad_configs_name_the_field() {
        let cases: Vec<(&str, FqlConfig)> = vec![
            (
                "fql.gamma",
                FqlConfig {
                    gamma: 1.0,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.gamma",
                FqlConfig {
                    gamma: f64::NAN,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.alpha",
                FqlConfig {
                    alpha: 0.0,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.alpha",
                FqlConfig {
                    alpha: 1.5,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.alpha_decay",
                FqlConfig {
                    alpha_decay: -1.0,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.epsilon",
                FqlConfig {
                    epsilon: 1.5,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.epsilon_min",
                FqlConfig {
                    epsilon: 0.1,
                    epsilon_min: 0.2,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.episodes",
                FqlConfig {
                    episodes: 0,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.max_steps",
                FqlConfig {
                    max_steps: 0,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.tolerance",
                FqlConfig {
                    tolerance: f64::INFINITY,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.window",
                FqlConfig {
                    window: 0,
                    ..FqlConfig::default()
                },
            ),
            (
                "fql.eval_episodes",
                FqlConfig {
                    eval_every: 5,
                    eval_episodes: 0,
                    ..FqlConfig::default()
                },
            ),
        ];
        let features = FeatureSpace::new(vec![vec![uniform_cores(5)]]).unwrap();
        for (field, config) in cases {
            let text = err_text(learn(&mut Lines::new(1), &features, &config, continue_all));
            assert!(text.starts_with(&format!("{field}:")), "{field}: {text}");
        }
        assert!(FqlConfig::default().validate().is_ok());

        // Unknown fields are rejected; missing ones default.
        let parsed: FqlConfig = toml::from_str("update = \"literal\"\ngamma = 0.5").unwrap();
        assert_eq!(parsed.update, Update::Literal);
        assert_eq!(parsed.episodes, FqlConfig::default().episodes);
        assert!(toml::from_str::<FqlConfig>("gama = 0.5").is_err());
    }

    /// Observes NaN for agent 1.
    struct NanObs(Lines);

    impl Environment for NanObs {
        fn n_agents(&self) -> usize {
            self.0.n_agents()
        }
        fn n_actions(&self, a: usize) -> usize {
            self.0.n_actions(a)
        }
        fn obs_dim(&self, a: usize) -> usize {
            self.0.obs_dim(a)
        }
        fn reset(&mut self, rng: &mut Pcg64Mcg) {
            self.0.reset(rng);
        }
        fn observe(&self, agent: usize, out: &mut [f64]) {
            self.0.observe(agent, out);
            if agent == 1 {
                out[0] = f64::NAN;
            }
        }
        fn step(&mut self, actions: &[usize], rng: &mut Pcg64Mcg) -> Transition {
            self.0.step(actions, rng)
        }
    }

    #[test]
    fn mismatched_or_bad_environments_are_errors() {
        let one = FeatureSpace::new(vec![vec![uniform_cores(5)]]).unwrap();
        let two = FeatureSpace::new(vec![vec![uniform_cores(5)], vec![uniform_cores(5)]]).unwrap();
        let config = FqlConfig::default();
        let text = err_text(learn(&mut Lines::new(2), &one, &config, continue_all));
        assert!(
            text.starts_with("features:") && text.contains("1 agents"),
            "{text}"
        );
        let wide = FeatureSpace::new(vec![vec![uniform_cores(5), uniform_cores(3)]]).unwrap();
        let text = err_text(learn(&mut Lines::new(1), &wide, &config, continue_all));
        assert!(
            text.starts_with("features[0]:") && text.contains("observation dimensions"),
            "{text}"
        );
        let text = err_text(learn(
            &mut NanObs(Lines::new(2)),
            &two,
            &config,
            continue_all,
        ));
        assert!(
            text.contains("agent 1") && text.contains("non-finite"),
            "{text}"
        );

        // Invalid feature spaces name the agent.
        let text = err_text(FeatureSpace::new(vec![
            vec![uniform_cores(3)],
            vec![vec![0.0, 0.0]],
        ]));
        assert!(text.starts_with("features[1]:"), "{text}");
        assert!(FeatureSpace::new(vec![]).is_err());
        assert!(FeatureSpace::new(vec![vec![]]).is_err());

        // Bad shapes through the Q-function API.
        let q = hand_q();
        let mut out = [0.0; 2];
        assert!(q.q_agent(0, &[0.5, 1.0], &mut out).is_err());
        assert!(q.q_agent(0, &[f64::NAN], &mut out).is_err());
        assert!(q.q_agent(2, &[0.5], &mut out).is_err());
        assert!(q.q_agent(0, &[0.5], &mut [0.0; 3]).is_err());
        q.q_agent(0, &[0.5], &mut out).unwrap();
        assert_eq!(out, [2.0, 3.0]);
        assert!(q.q(&[&[0.5], &[0.5]], &[2, 0]).is_err());
        assert!(
            AdditiveQ::from_params(q.features().clone(), vec![2, 3], vec![vec![0.0; 6]]).is_err()
        );
        assert!(
            AdditiveQ::from_params(
                q.features().clone(),
                vec![2, 3],
                vec![vec![0.0; 6], vec![f64::NAN; 6]]
            )
            .is_err()
        );
    }

    #[test]
    fn greedy_breaks_ties_by_the_lowest_index_and_serde_round_trips() {
        let features = FeatureSpace::new(vec![vec![vec![0.0, 1.0]]]).unwrap();
        let q = AdditiveQ::from_params(features, vec![3], vec![vec![0.0, 1.0, 1.0, 2.0, 2.0, 0.0]])
            .unwrap();
        assert_eq!(q.greedy(0, &[0.0]).unwrap(), 1);
        assert_eq!(q.greedy(0, &[1.0]).unwrap(), 0);
        assert_eq!(q.greedy(0, &[0.5]).unwrap(), 1); // values (1, 1.5, 0.5)
        let text = toml::to_string(&q).unwrap();
        let back: AdditiveQ = toml::from_str(&text).unwrap();
        assert_eq!(back, q);
        let bad_cores =
            "features = [[[1.0, 0.0]]]\nactions = [3]\nphi = [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]";
        assert!(toml::from_str::<AdditiveQ>(bad_cores).is_err());
        let bad_shape = "features = [[[0.0, 1.0]]]\nactions = [3]\nphi = [[0.0]]";
        assert!(toml::from_str::<AdditiveQ>(bad_shape).is_err());
    }

    /// A codebook of `k` pseudo-random centroids in `dim` dimensions (coordinates on a coarse
    /// lattice, so that exact ties and duplicates occur).
    fn lattice_codebook(k: usize, dim: usize, scale: Vec<f64>, seed: u64) -> Codebook {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let centroids: Vec<f64> = (0..k * dim)
            .map(|_| f64::from(rng.random_range(-6i32..=6)) * 0.5)
            .collect();
        Codebook::from_flat(dim, centroids, scale).unwrap()
    }

    #[test]
    fn codebook_lookup_matches_brute_force_including_ties() {
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        for (k, dim, scale) in [
            (1, 1, vec![1.0]),
            (9, 2, vec![1.0, 0.5]),
            (300, 4, vec![3.0, 3.0, 0.7, 0.7]),
            (2025, 4, vec![1.0; 4]),
            (500, 7, vec![0.3; 7]),
        ] {
            let book = lattice_codebook(k, dim, scale, k as u64);
            assert_eq!(book.n_cells(), k);
            let mut queries: Vec<Vec<f64>> = (0..2000)
                .map(|_| (0..dim).map(|_| rng.random_range(-4.0..4.0)).collect())
                .collect();
            // Lattice points (many exact ties) and every centroid itself.
            queries.extend((0..500).map(|_| {
                (0..dim)
                    .map(|_| f64::from(rng.random_range(-8i32..=8)) * 0.25)
                    .collect()
            }));
            queries.extend((0..k).map(|j| book.centroid(j).unwrap().to_vec()));
            for x in &queries {
                let (j, d) = book.nearest_brute_force(x);
                let (jt, dt) = book.nearest_unchecked(x);
                assert_eq!((jt, dt.to_bits()), (j, d.to_bits()), "k {k}, x {x:?}");
                assert_eq!(book.nearest(x).unwrap(), j);
                assert_eq!(book.distance(x, j).unwrap().to_bits(), d.to_bits());
                // The lowest index among the equally near.
                for other in 0..k {
                    let e = book.distance(x, other).unwrap();
                    assert!(
                        e > d || (e == d && other >= j),
                        "k {k}, x {x:?}: {other} beats {j}"
                    );
                }
            }
        }
        // Duplicated centroids: the first copy wins, the second cell is never chosen.
        let book = Codebook::new(vec![vec![1.0], vec![0.0], vec![1.0]], vec![1.0]).unwrap();
        assert_eq!(book.nearest(&[0.9]).unwrap(), 0);
        assert_eq!(book.nearest(&[0.5]).unwrap(), 0); // tie between cells 0 and 1
        assert_eq!(book.nearest(&[0.4]).unwrap(), 1);
        // The scale weighs the dimensions: x is nearer to c1 in raw units, to c0 once the
        // second dimension is divided by 10.
        let c = vec![vec![0.0, 5.0], vec![2.0, 0.0]];
        assert_eq!(
            Codebook::new(c.clone(), vec![1.0, 1.0])
                .unwrap()
                .nearest(&[1.5, 4.0])
                .unwrap(),
            0
        );
        assert_eq!(
            Codebook::new(c, vec![1.0, 10.0])
                .unwrap()
                .nearest(&[1.5, 4.0])
                .unwrap(),
            1
        );
    }

    #[test]
    fn bad_codebooks_are_errors() {
        let err = |r: Result<Codebook, SimError>| r.expect_err("expected an error").to_string();
        assert!(err(Codebook::new(vec![], vec![])).starts_with("codebook.centroids:"));
        assert!(err(Codebook::new(vec![vec![]], vec![])).starts_with("codebook.centroids:"));
        assert!(
            err(Codebook::new(
                vec![vec![0.0, 1.0], vec![0.0]],
                vec![1.0, 1.0]
            ))
            .starts_with("codebook.centroids:")
        );
        assert!(
            err(Codebook::new(vec![vec![0.0, f64::NAN]], vec![1.0, 1.0]))
                .starts_with("codebook.centroids:")
        );
        assert!(err(Codebook::new(vec![vec![0.0]], vec![0.0])).starts_with("codebook.scale:"));
        assert!(err(Codebook::new(vec![vec![0.0]], vec![f64::NAN])).starts_with("codebook.scale:"));
        assert!(err(Codebook::new(vec![vec![0.0]], vec![1.0, 1.0])).starts_with("codebook.scale:"));
        assert!(
            err(Codebook::new(vec![vec![1e300]], vec![1e-300])).starts_with("codebook.centroids:")
        );
        assert!(
            err(Codebook::new(vec![vec![0.0; 17]], vec![1.0; 17]))
                .starts_with("codebook.centroids:")
        );
        assert!(
            err(Codebook::from_flat(2, vec![0.0; 3], vec![1.0; 2]))
                .starts_with("codebook.centroids:")
        );
        let book = Codebook::new(vec![vec![0.0, 0.0]], vec![1.0, 1.0]).unwrap();
        assert!(book.nearest(&[0.0]).is_err());
        assert!(book.nearest(&[0.0, f64::NAN]).is_err());
        assert!(book.distance(&[0.0, 0.0], 1).is_err());
        assert_eq!(book.nearest(&[f64::MAX, -f64::MAX]).unwrap(), 0);
        assert!(FeatureSpace::codebook(vec![]).is_err());
    }

    fn two_cell_features() -> FeatureSpace {
        FeatureSpace::codebook(vec![
            Codebook::new(vec![vec![0.0], vec![1.0]], vec![1.0]).unwrap(),
            Codebook::new(
                vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![0.0, 2.0]],
                vec![1.0, 2.0],
            )
            .unwrap(),
        ])
        .unwrap()
    }

    #[test]
    fn codebook_features_are_crisp_cells_and_serialise_in_their_own_form() {
        let features = two_cell_features();
        assert!(features.is_codebook());
        assert!(features.cores().is_empty());
        assert_eq!(features.codebooks().len(), 2);
        assert_eq!(features.n_agents(), 2);
        assert_eq!(
            (features.obs_dim(1), features.n_cores(1)),
            (Some(2), Some(3))
        );
        assert_eq!(features.n_params(&[2, 4]).unwrap(), 2 * 2 + 3 * 4);
        assert!(features.grid(0).is_err());
        let mut seen = Vec::new();
        features
            .active(1, &[0.2, 1.5])
            .unwrap()
            .for_each(|d, w| seen.push((d, w)));
        assert_eq!(seen, [(2, 1.0)]);
        assert!(features.active(1, &[0.2]).is_err());
        assert!(features.active(0, &[f64::INFINITY]).is_err());
        assert!(features.active(2, &[0.0]).is_err());
        let fuzzy = FeatureSpace::new(vec![vec![uniform_cores(3)]]).unwrap();
        assert!(!fuzzy.is_codebook() && fuzzy.codebooks().is_empty());

        // Round trip through TOML, inside an AdditiveQ.
        let phi = vec![vec![0.5, -1.0, 2.0, 0.25], (0..12).map(f64::from).collect()];
        let q = AdditiveQ::from_params(features.clone(), vec![2, 4], phi).unwrap();
        let text = toml::to_string(&q).unwrap();
        assert!(text.contains("codebooks"), "{text}");
        let back: AdditiveQ = toml::from_str(&text).unwrap();
        assert_eq!(back, q);
        assert_eq!(
            toml::from_str::<FeatureSpace>(&toml::to_string(&features).unwrap()).unwrap(),
            features
        );
        // The fuzzy form is still the nested core lists.
        let text = toml::to_string(&AdditiveQ::new(fuzzy, vec![1]).unwrap()).unwrap();
        assert!(text.starts_with("features = [[[0.0, 0.5, 1.0]]]"), "{text}");
        // Bad codebook files are refused with the reason.
        let bad = "actions = [1]\nphi = [[0.0]]\n[features]\ncodebooks = [{ scale = [0.0], centroids = [[1.0]] }]";
        let e = toml::from_str::<AdditiveQ>(bad).unwrap_err().to_string();
        assert!(e.contains("codebook.scale"), "{e}");
        let unknown = "actions = [1]\nphi = [[0.0]]\n[features]\ncodebook = []";
        let e = toml::from_str::<AdditiveQ>(unknown)
            .unwrap_err()
            .to_string();
        assert!(e.contains("codebook"), "{e}");
        let good = "actions = [1]\nphi = [[0.0, 3.0]]\n[features]\ncodebooks = [{ scale = [1.0], centroids = [[1.0], [2.0]] }]";
        let q = toml::from_str::<AdditiveQ>(good).unwrap();
        assert_eq!(q.greedy(0, &[1.9]).unwrap(), 0);
        assert_eq!(q.value(&[&[1.9]]).unwrap(), 3.0);
        let mixed = "actions = [1]\nphi = [[0.0, 0.0]]\n[features]\ncodebooks = [{ scale = [1.0], centroids = [[1.0], [1.0, 2.0]] }]";
        assert!(toml::from_str::<AdditiveQ>(mixed).is_err());
        assert!(toml::from_str::<AdditiveQ>("features = 3\nactions = [1]\nphi = [[0.0]]").is_err());
    }

    #[test]
    fn codebook_update_is_tabular_q_learning() {
        // One cell of membership 1 per agent: Q(x, u) = phi0[c0 * 2 + u0] + phi1[c1 * 4 + u1].
        let features = two_cell_features();
        let phi = vec![vec![0.5, -1.0, 2.0, 0.25], (0..12).map(f64::from).collect()];
        let mut q = AdditiveQ::from_params(features, vec![2, 4], phi).unwrap();
        let before = q.params().to_vec();
        // x_k: agent 0 in cell 1 (0.8), agent 1 in cell 0 ((0.1, 0.5): scaled distances 0.0725
        // to (0, 0), 0.8725 to (1, 0) and 0.5725 to (0, 2)); actions (1, 3): Q = 0.25 + 3.
        // x_{k+1}: cell 0 (max 0.5) and cell 2 (max 11): max Q = 11.5.
        let sample = Sample {
            obs: &[&[0.8], &[0.1, 0.5]],
            actions: &[1, 3],
            reward: 2.0,
            next_obs: &[&[-0.3], &[0.0, 1.9]],
            terminal: false,
        };
        let delta = q.update(Update::Corrected, &sample, 0.9, 0.5).unwrap();
        assert!(close(delta, 2.0 + 0.9 * 11.5 - 3.25), "delta {delta}");
        let mut expected = before.clone();
        expected[0][3] += 0.5 * delta;
        expected[1][3] += 0.5 * delta;
        assert_eq!(q.params(), &expected[..]);

        // Learning the corridor over an 11-cell codebook (the cores of the fuzzy test, crisp).
        let cells: Vec<Vec<f64>> = uniform_cores(11).into_iter().map(|c| vec![c]).collect();
        let features =
            FeatureSpace::codebook(vec![Codebook::new(cells, vec![1.0]).unwrap()]).unwrap();
        let config = line_config();
        let out = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
        for j in 0..=90 {
            let start = j as f64 / 100.0;
            let optimal = ((GOAL - start) / STEP).ceil() as usize;
            let steps = greedy_steps(&out.q, &[start], 30);
            assert!(
                steps.is_some_and(|s| s <= optimal + 2),
                "start {start}: {steps:?}"
            );
        }
        assert_eq!(out.curve.last().unwrap().eval_success_rate, Some(1.0));
        let again = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
        assert_eq!(params_bits(&again.q), params_bits(&out.q));
        let eval = evaluate(&mut Lines::new(1), &out.q, 20, 40, eval_seed(config.seed)).unwrap();
        assert_eq!(eval.success_rate, 1.0);
    }
}
