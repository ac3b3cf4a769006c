//! Model-free fuzzy Q-learning (paper section 2.5, eqs 23-27) for episodic multi-agent tasks.
//!
//! Fuzzy Q-iteration ([`crate::train`]) needs the model `f` and the reward `rho`; this module
//! learns from interaction alone, which is the model-free variant the paper lists as future
//! work and the algorithm of its section 2.5 read as on-line Q-learning. A learner only needs
//! an [`Environment`]: episodes that start with [`reset`](Environment::reset), observations per
//! agent and one discrete action per agent per step.
//!
//! # Parameter layout (`additive`; `docs/design.md`, section 2)
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
//! # The corrected update ([`Update::Corrected`], the default; `docs/design.md`, section 3)
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
//! observation activates exactly one cell, its nearest [`Codebook`](crate::learn::codebook::Codebook) centroid, with membership
//! 1 ([`ActiveCores::single`]), so `Q(x, u) = sum_i phi[i][c_i(x) * M_i + u_i]` and the
//! corrected update `phi[i][c_i(x_k) * M_i + u_{k,i}] += alpha_k * delta` is exactly tabular
//! Q-learning over the cells (with the same additive joint value and decentralised greedy
//! action). The literal update then adds its increment to the cell of the next state. Every
//! other part of [`learn`] (exploration, schedules, evaluations, the convergence window, the
//! curve) is shared; the fuzzy path is compiled separately and unchanged.
//!
//! # The projected update
//! The additive value is a value decomposition trained off-policy with bootstrapping, and
//! such linear TD updates can diverge (they did on the point masses learning near the goal:
//! parameters of 2e60 with the corrected update, 2e225 with the literal one). When the
//! environment bounds its rewards, `|r| <= R` ([`Environment::reward_bound`]: the point
//! masses' goal reward, the robots' goal reward or collision penalty), every changed parameter
//! is clamped into `[-R / (1 - gamma), R / (1 - gamma)]`, the range of every discounted
//! return: a projection onto a box that holds every agent's share of the true values, so the
//! parameters stay bounded whatever the step size (Bertsekas and Tsitsiklis 1996, projected
//! stochastic approximation). Runs whose parameters stay inside are unchanged, bit for bit;
//! an environment that knows no bound is not projected.
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
//! let outcome = fql::learn(&mut Line(0.0), &features, &config, |_: &fql::EpisodeRecord| {
//!     std::ops::ControlFlow::Continue(())
//! })?;
//! assert_eq!(outcome.q.greedy(0, &[0.5])?, 2); // right
//! assert_eq!(outcome.curve.last().and_then(|r| r.eval_success_rate), Some(1.0));
//! # Ok::<(), fuzzyq_sim::SimError>(())
//! ```

use std::collections::VecDeque;
use std::fmt;
use std::io::Write;

use fuzzyq_core::additive;
use fuzzyq_core::partition::ActiveCores;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

pub use fuzzyq_core::additive::Update;

use crate::error::{ConfigError, SimError, discount, require};
pub use crate::learn::additive::{AdditiveQ, Sample};
use crate::learn::additive::{Rates, Step, td_update};
pub use crate::learn::env::{Environment, Transition};
pub use crate::learn::features::FeatureSpace;
use crate::learn::features::{FeatureKind, Lookup};

mod resume;

pub use resume::{FqlState, Observer, Snapshot};

/// Why a [`learn`] run stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// All [`episodes`](FqlConfig::episodes) ran.
    EpisodeLimit,
    /// The convergence test passed and [`stop_at_convergence`](FqlConfig::stop_at_convergence)
    /// is set.
    Converged,
    /// The progress callback returned [`ControlFlow::Break`](std::ops::ControlFlow::Break).
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
            gamma: crate::paper::GAMMA,
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
        discount("fql.gamma", self.gamma)?;
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

/// One learning episode of a [`learn`] run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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

/// The box `[-b, b]` every parameter is projected onto: `b = reward_bound / (1 - gamma)`, the
/// largest discounted return, when the environment bounds its rewards; infinite (no
/// projection) otherwise.
fn param_bound(reward_bound: Option<f64>, gamma: f64) -> Result<f64, ConfigError> {
    match reward_bound {
        None => Ok(f64::INFINITY),
        Some(r) if r >= 0.0 && r.is_finite() => Ok(r / (1.0 - gamma)),
        Some(r) => Err(ConfigError::invalid(
            "reward_bound",
            format!("the environment's reward bound must be a finite number >= 0, got {r}"),
        )),
    }
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

/// The lowest index of the largest value (the learner's values are finite).
#[inline]
fn greedy_index(q: &[f64]) -> usize {
    fuzzyq_core::q::argmax(q).unwrap_or(0)
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
    require!(
        n == features.n_agents(),
        "features",
        format!(
            "has {} agents, the environment has {n}",
            features.n_agents()
        ),
    );
    let mut m = Vec::with_capacity(n);
    for i in 0..n {
        let (dim, expected) = (env.obs_dim(i), features.obs_dim(i).unwrap_or(0));
        require!(
            dim == expected,
            &format!("features[{i}]"),
            format!(
                "has {expected} observation dimensions, the environment observes {dim} for agent {i}"
            ),
        );
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
                additive::q_values_unchecked(&bufs.active[i], &phi[i], &mut bufs.q[i]);
                bufs.actions[i] = greedy_index(&bufs.q[i]);
            }
            let tr = env.step(&bufs.actions, &mut rng);
            check_reward(tr.reward, at)?;
            ret += tr.reward;
            if tr.terminal {
                success = tr.reward > 0.0;
                break;
            }
            if env.truncated() {
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
    require!(
        m == q.actions,
        "env",
        format!(
            "has action counts {m:?}, the Q-function was learned with {:?}",
            q.actions
        ),
    );
    match &q.features.kind {
        FeatureKind::Fuzzy(_) => {
            let grids = q.features.grids()?;
            let mut bufs = Buffers::new(&grids, &m);
            evaluate_with(env, &grids, &q.phi, &mut bufs, episodes, max_steps, seed)
        }
        FeatureKind::Codebook(books) => {
            let mut bufs = Buffers::new(books, &m);
            evaluate_with(env, books, &q.phi, &mut bufs, episodes, max_steps, seed)
        }
    }
}

/// Learns an [`AdditiveQ`] on `env` by fuzzy Q-learning (see the [module docs](self)).
///
/// `progress` sees every episode's record (after its evaluation, if any) and may stop the run
/// with [`ControlFlow::Break`](std::ops::ControlFlow::Break); the outcome then holds what was learned so far with
/// [`StopReason::Callback`]. An [`Observer`] that is not a closure also sees the run's state
/// after every episode and may continue an earlier run from its state
/// ([`Observer::resume`]): the run then learns exactly what the uninterrupted one learns. Errors: an invalid configuration, a feature space that does not
/// match the environment (agent count, observation lengths), an agent without actions, a
/// non-finite observation (naming the agent) or reward.
pub fn learn<E: Environment>(
    env: &mut E,
    features: &FeatureSpace,
    config: &FqlConfig,
    progress: impl Observer,
) -> Result<FqlOutcome, SimError> {
    config.validate()?;
    let m = check_env(env, features)?;
    let q = AdditiveQ::new(features.clone(), m.clone())?;
    match &features.kind {
        FeatureKind::Fuzzy(_) => {
            let grids = features.grids()?;
            learn_with(env, &grids, q, m, config, progress)
        }
        FeatureKind::Codebook(books) => learn_with(env, books, q, m, config, progress),
    }
}

/// The learning loop of [`learn`] for one kind of features.
fn learn_with<E: Environment, L: Lookup>(
    env: &mut E,
    grids: &[L],
    mut q: AdditiveQ,
    m: Vec<usize>,
    config: &FqlConfig,
    mut progress: impl Observer,
) -> Result<FqlOutcome, SimError> {
    let mut bufs = Buffers::new(grids, &m);
    let mut log = WindowLog::new(config.window, &q.phi);
    let mut rng = Pcg64Mcg::seed_from_u64(config.seed);
    let eval_seed = eval_seed(config.seed);

    let mut curve = Vec::with_capacity(config.episodes.min(1 << 20));
    let mut converged_at = None;
    let mut steps_total = 0usize;
    let mut moved = false;
    let mut stop = StopReason::EpisodeLimit;
    let bound = param_bound(env.reward_bound(), config.gamma)?;
    if let Some(state) = progress.resume() {
        state.check(&q.phi, config)?;
        state.restore(&mut resume::Restored {
            phi: &mut q.phi,
            rng: &mut rng,
            log: &mut log,
            curve: &mut curve,
            converged_at: &mut converged_at,
            steps_total: &mut steps_total,
            moved: &mut moved,
        });
    }

    for episode in curve.len()..config.episodes {
        let epsilon = config.epsilon_at(episode);
        let alpha = config.alpha_at(episode);
        let e = learning_episode(
            env,
            grids,
            &mut q.phi,
            &m,
            config,
            &mut bufs,
            &mut rng,
            &mut log,
            (episode, epsilon, alpha, bound),
        )?;
        moved |= e.moved;
        let (steps, ret, discounted, terminal, diverged) =
            (e.steps, e.ret, e.discounted, e.terminal, e.diverged);
        let (td_sum, td_max, updates) = (e.td_sum, e.td_max, e.updates);
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
        curve.push(record);
        let snapshot = (!last).then(|| Snapshot {
            phi: &q.phi,
            rng: &rng,
            window: &log.entries,
            window_episodes: &log.per_episode,
            curve: &curve,
            converged_at,
            steps_total,
            moved,
        });
        let flow = progress.episode(&curve[curve.len() - 1], snapshot.as_ref());
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

/// What one learning episode did (see [`learning_episode`]).
struct EpisodeRun {
    steps: usize,
    ret: f64,
    discounted: f64,
    td_sum: f64,
    td_max: f64,
    updates: usize,
    terminal: bool,
    diverged: bool,
    /// Whether any update changed a parameter.
    moved: bool,
}

/// One episode of fuzzy Q-learning from a reset of `env`: epsilon-greedy actions per agent,
/// a temporal-difference update of `phi` after every step (each change logged), until a
/// terminal state, `config.max_steps` or a diverging update. `at` is the episode's number,
/// epsilon, alpha and the parameters' bound.
#[allow(clippy::too_many_arguments)] // the learner's state, passed apart so each borrow is its own
fn learning_episode<E: Environment, L: Lookup>(
    env: &mut E,
    grids: &[L],
    phi: &mut [Vec<f64>],
    m: &[usize],
    config: &FqlConfig,
    bufs: &mut Buffers,
    rng: &mut Pcg64Mcg,
    log: &mut WindowLog,
    (episode, epsilon, alpha, bound): (usize, f64, f64, f64),
) -> Result<EpisodeRun, SimError> {
    let n = m.len();
    let mut moved = false;
    env.reset(rng);
    let at = At::Learning { episode, step: 0 };
    observe_all(env, grids, &mut bufs.obs, &mut bufs.active, at)?;
    for i in 0..n {
        additive::q_values_unchecked(&bufs.active[i], &phi[i], &mut bufs.q[i]);
    }

    let (mut steps, mut ret, mut discounted, mut discount) = (0usize, 0.0, 0.0, 1.0);
    let (mut td_sum, mut td_max, mut updates) = (0.0, 0.0_f64, 0usize);
    let (mut terminal, mut diverged) = (false, false);
    while steps < config.max_steps {
        // Epsilon-greedy, independently per agent.
        for i in 0..n {
            bufs.actions[i] = if rng.random::<f64>() < epsilon {
                rng.random_range(0..m[i])
            } else {
                greedy_index(&bufs.q[i])
            };
        }
        let tr = env.step(&bufs.actions, rng);
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
            additive::q_values_unchecked(&bufs.next_active[i], &phi[i], &mut bufs.q_next[i]);
        }
        let step = Step {
            cur: &bufs.active,
            next: &bufs.next_active,
            q: &bufs.q,
            q_next: &bufs.q_next,
            actions: &bufs.actions,
            reward: tr.reward,
            terminal: tr.terminal,
        };
        let rates = Rates {
            rule: config.update,
            gamma: config.gamma,
            alpha,
            bound,
        };
        let result = td_update(rates, phi, m, &step, |a, k, old| {
            log.record(a, k, old);
        });
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
        if env.truncated() {
            break;
        }
        for i in 0..n {
            additive::q_values_unchecked(&bufs.active[i], &phi[i], &mut bufs.q[i]);
        }
    }
    Ok(EpisodeRun {
        steps,
        ret,
        discounted,
        td_sum,
        td_max,
        updates,
        terminal,
        diverged,
        moved,
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
mod tests;
