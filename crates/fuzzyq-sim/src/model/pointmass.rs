//! The point-mass task of the paper's section 3.1 (eqs 38-41), for any number of agents.
//!
//! Agent `i` is a point mass `m` on the plane with friction: `m s'' = -eta(s) s' + u`, with a
//! piecewise-constant force `u = (u_x, u_y)` held over each sample time `T` (zero-order hold).
//! The state is `[s_1x, s_1y, v_1x, v_1y, s_2x, ...]` (as printed in the paper); after each step
//! positions are clamped to `[-P, P]` and velocities to `[-V, V]`. Each agent's actions are
//! the square of the force levels, `u_x` slowest: with levels `{-2, -0.2, 0, 0.2, 2}`,
//! 25 actions per agent and `25^n` joint actions. The shared reward is `R` when the whole state
//! is within `goal_radius` of the origin (eq 40, evaluated at the current state), else 0.
//!
//! # The shaped reward
//! With `reward = "shaped"` ([`RewardShape::Shaped`]) every transition also pays the
//! potential-based shaping term of Ng, Harada and Russell (1999),
//! `F(x, u) = gamma * Phi(f(x, u)) - Phi(x)`, with the potential
//! `Phi(x) = -sum_i ||x_i||_2`: minus each agent's distance to its goal state, measured over
//! its own `(s_x, s_y, v_x, v_y)` as the reward region is. The shaped reward is
//! `rho(x) + F(x, u)`. Along any path the terms telescope: the discounted return from `x_0`
//! changes by `-Phi(x_0)` whatever the actions, so every policy's ranking, and the optimal
//! policy, stay those of the paper's reward, while each step now says whether it brought the
//! agents closer. `gamma` is [`PointMassConfig::shaping_discount`], which must be the
//! learner's discount for the identity to hold (the training configuration checks it). The
//! successor is the model's noise-free `f(x, u)`; on a noisy plant the term is that of the
//! mean dynamics. The reward then depends on the action.
//!
//! # Integration
//! - `exact` (constant friction only): the closed-form zero-order-hold solution. With
//!   `a = eta / m` and `w = u / eta`: `v' = w + (v - w) e^{-aT}`,
//!   `s' = s + w T + (v - w)(1 - e^{-aT}) / a` (and the frictionless limit for `eta = 0`).
//! - `rk4`: classical Runge-Kutta with `rk4_substeps` substeps per sample time, for any
//!   friction field `eta(s)`.
//!
//! Arithmetic runs in `f64` whatever the solver's precision; results are rounded once.
//!
//! # Blocks
//! With constant friction the dynamics separate per agent and axis: block `(s_ix, v_ix)`
//! depends on `u_ix` only. The model declares these `2n` blocks (agent-major, x before y:
//! the joint action's radix order). A position-dependent friction couples an agent's axes, so
//! the model then declares one 4-variable block per agent.

use std::sync::Arc;

use fuzzyq_core::solver::Precision;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, non_negative, positive, require};
use crate::model::{ActionTable, BlockSpec, Dynamics, F64Model, check_state_as, symmetric};
use crate::paper;

/// A friction field `eta(s_x, s_y)` in kg/s, as written in a config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FrictionConfig {
    /// The same `eta` everywhere (the paper's setting, `eta = 1`).
    Constant {
        /// Friction coefficient, `>= 0`.
        eta: f64,
    },
    /// `base` everywhere except inside discs, where the disc's `eta` applies (the last
    /// listed disc that contains the point wins): rough patches on the floor.
    Patches {
        /// Friction outside every patch.
        base: f64,
        /// The patches.
        patches: Vec<FrictionPatch>,
    },
}

/// A disc of different friction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionPatch {
    /// Centre `(x, y)` in m.
    pub center: [f64; 2],
    /// Radius in m, `> 0`.
    pub radius: f64,
    /// Friction inside, `>= 0`.
    pub eta: f64,
}

/// How a step is integrated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Closed-form zero-order hold (constant friction only).
    #[default]
    Exact,
    /// Classical RK4 with substeps.
    Rk4,
}

/// The point-mass task's reward: the paper's, or the same with a potential-based shaping
/// term (see the [module docs](self#the-shaped-reward)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RewardShape {
    /// `R` inside the reward region, else 0 (eq 40).
    #[default]
    Paper,
    /// The paper's reward plus `gamma * Phi(f(x, u)) - Phi(x)`, `Phi(x) = -sum_i ||x_i||_2`.
    Shaped,
}

impl RewardShape {
    /// The name in a config file (`"paper"`, `"shaped"`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Shaped => "shaped",
        }
    }

    /// Parses a [`name`](Self::name); the error names `field`.
    pub fn parse(name: &str, field: &str) -> Result<Self, ConfigError> {
        match name {
            "paper" => Ok(Self::Paper),
            "shaped" => Ok(Self::Shaped),
            _ => Err(ConfigError::invalid(
                field,
                format!("{name:?} is not a reward: use \"paper\" or \"shaped\""),
            )),
        }
    }

    fn is_paper(&self) -> bool {
        *self == Self::Paper
    }
}

fn is_paper_gamma(g: &f64) -> bool {
    *g == paper::GAMMA
}

fn paper_gamma() -> f64 {
    paper::GAMMA
}

/// The point-mass task's parameters (the `[env]` table of a config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointMassConfig {
    /// Number of agents, 1 to 4.
    pub agents: usize,
    /// Mass of each agent in kg, `> 0`.
    pub mass: f64,
    /// Sample time `T` in s, `> 0`.
    pub sample_time: f64,
    /// Positions are clamped to `[-position_limit, position_limit]` (m).
    pub position_limit: f64,
    /// Velocities are clamped to `[-velocity_limit, velocity_limit]` (m/s).
    pub velocity_limit: f64,
    /// Force levels per axis (N); each agent's actions are their square, `u_x` slowest.
    pub force_levels: Vec<f64>,
    /// The reward region: `||x||_2 < goal_radius` over the whole state.
    pub goal_radius: f64,
    /// Reward inside the region.
    pub goal_reward: f64,
    /// Integration method.
    pub integrator: Integrator,
    /// RK4 substeps per sample time (used by `rk4`).
    pub rk4_substeps: usize,
    /// Friction field.
    pub friction: FrictionConfig,
    /// Process noise of the plant: the standard deviation (m/s) of the zero-mean Gaussian
    /// noise added to every velocity after each step (then clamped), independently per agent
    /// and axis; `>= 0`, default 0 (the paper's deterministic dynamics). The model's
    /// transition `f` stays noise-free; the model plant (rollouts, comparisons) and data
    /// collection add it, seeded; the rapier plant does not.
    #[serde(default)]
    pub velocity_noise: f64,
    /// The reward: `"paper"` (default) or `"shaped"` (see the
    /// [module docs](self#the-shaped-reward)).
    #[serde(default, skip_serializing_if = "RewardShape::is_paper")]
    pub reward: RewardShape,
    /// The discount `gamma` of the shaping term, in `(0, 1]`; it must equal the learner's
    /// discount. Default: the paper's 0.96.
    #[serde(default = "paper_gamma", skip_serializing_if = "is_paper_gamma")]
    pub shaping_discount: f64,
}

impl Default for PointMassConfig {
    /// The paper's section 3.1 values.
    fn default() -> Self {
        Self {
            agents: 2,
            mass: 0.5,
            sample_time: 0.4,
            position_limit: 6.0,
            velocity_limit: 3.0,
            force_levels: paper::FORCE_LEVELS.to_vec(),
            goal_radius: 0.1,
            goal_reward: 5.0,
            integrator: Integrator::Exact,
            rk4_substeps: 10,
            friction: FrictionConfig::Constant { eta: 1.0 },
            velocity_noise: 0.0,
            reward: RewardShape::Paper,
            shaping_discount: paper::GAMMA,
        }
    }
}

/// The largest number of point-mass agents (the joint action count grows as `L^(2n)`).
pub const MAX_POINT_MASS_AGENTS: usize = 4;

impl PointMassConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        require!(
            (1..=MAX_POINT_MASS_AGENTS).contains(&self.agents),
            "env.agents",
            format!(
                "must be between 1 and {MAX_POINT_MASS_AGENTS}, got {}",
                self.agents
            ),
        );
        positive("env.mass", self.mass)?;
        positive("env.sample_time", self.sample_time)?;
        positive("env.position_limit", self.position_limit)?;
        positive("env.velocity_limit", self.velocity_limit)?;
        non_negative("env.goal_radius", self.goal_radius)?;
        non_negative("env.velocity_noise", self.velocity_noise)?;
        require!(
            self.shaping_discount > 0.0 && self.shaping_discount <= 1.0,
            "env.shaping_discount",
            format!("must be in (0, 1], got {}", self.shaping_discount),
        );
        require!(
            self.goal_reward.is_finite(),
            "env.goal_reward",
            "must be a finite number",
        );
        crate::error::single_precision("env.goal_reward", &[self.goal_reward])?;
        require!(
            !self.force_levels.is_empty(),
            "env.force_levels",
            "needs at least one level",
        );
        crate::error::single_precision("env.force_levels", &self.force_levels)?;
        let joint = (self.force_levels.len() as u64)
            .checked_pow(2 * self.agents as u32)
            .unwrap_or(u64::MAX);
        require!(
            joint <= 1 << 20,
            "env.force_levels",
            format!(
                "{} levels for {} agents make {joint} joint actions (at most 2^20)",
                self.force_levels.len(),
                self.agents
            ),
        );
        require!(
            (1..=10_000).contains(&self.rk4_substeps),
            "env.rk4_substeps",
            format!("must be between 1 and 10000, got {}", self.rk4_substeps),
        );
        match &self.friction {
            FrictionConfig::Constant { eta } => non_negative("env.friction.eta", *eta)?,
            FrictionConfig::Patches { base, patches } => {
                non_negative("env.friction.base", *base)?;
                for p in patches {
                    non_negative("env.friction.patches.eta", p.eta)?;
                    positive("env.friction.patches.radius", p.radius)?;
                    require!(
                        p.center[0].is_finite() && p.center[1].is_finite(),
                        "env.friction.patches.center",
                        "must be finite numbers",
                    );
                }
                require!(
                    self.integrator != Integrator::Exact,
                    "env.integrator",
                    "\"exact\" needs constant friction; use \"rk4\" with friction patches",
                );
            }
        }
        Ok(())
    }

    /// Length of the state vector, `4 n`.
    #[must_use]
    pub fn state_dim(&self) -> usize {
        4 * self.agents
    }
}

/// A friction field for the Rust API: any `eta(s_x, s_y)`.
pub type FrictionFn = Arc<dyn Fn(f64, f64) -> f64 + Send + Sync>;

#[derive(Clone)]
enum Friction {
    Constant(f64),
    Field(FrictionFn),
}

/// The point-mass model (implements [`Model`](fuzzyq_core::Model) for `f32` and `f64`).
#[derive(Clone)]
pub struct PointMass {
    config: PointMassConfig,
    friction: Friction,
    actions: ActionTable,
    blocks: Vec<BlockSpec>,
}

impl std::fmt::Debug for PointMass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointMass")
            .field("config", &self.config)
            .finish()
    }
}

impl PointMass {
    /// Builds the model from a validated config.
    pub fn new(config: PointMassConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let friction = match &config.friction {
            FrictionConfig::Constant { eta } => Friction::Constant(*eta),
            FrictionConfig::Patches { base, patches } => {
                let (base, patches) = (*base, patches.clone());
                Friction::Field(Arc::new(move |x, y| {
                    patches
                        .iter()
                        .rev()
                        .find(|p| (x - p.center[0]).hypot(y - p.center[1]) <= p.radius)
                        .map_or(base, |p| p.eta)
                }))
            }
        };
        Ok(Self::build(config, friction))
    }

    /// Builds the model with an arbitrary friction field `eta(s_x, s_y)` (integrated with RK4;
    /// `config.friction` is ignored). Such a model cannot be written to a policy file.
    pub fn with_friction_fn(
        mut config: PointMassConfig,
        eta: FrictionFn,
    ) -> Result<Self, ConfigError> {
        config.integrator = Integrator::Rk4;
        config.friction = FrictionConfig::Constant { eta: 0.0 };
        config.validate()?;
        Ok(Self::build(config, Friction::Field(eta)))
    }

    fn build(config: PointMassConfig, friction: Friction) -> Self {
        let levels = &config.force_levels;
        let mut actions = Vec::with_capacity(2 * levels.len() * levels.len());
        for &ux in levels {
            for &uy in levels {
                actions.push(ux);
                actions.push(uy);
            }
        }
        let block = |state_dims: Vec<usize>, action_components: Vec<usize>| BlockSpec {
            state_dims,
            action_components,
        };
        let blocks = match friction {
            Friction::Constant(_) => (0..config.agents)
                .flat_map(|i| (0..2).map(move |axis| (i, axis)))
                .map(|(i, axis)| block(vec![4 * i + axis, 4 * i + 2 + axis], vec![2 * i + axis]))
                .collect(),
            Friction::Field(_) => (0..config.agents)
                .map(|i| block((4 * i..4 * i + 4).collect(), vec![2 * i, 2 * i + 1]))
                .collect(),
        };
        Self {
            config,
            friction,
            actions: ActionTable::new(actions, 2),
            blocks,
        }
    }

    /// The paper's model (section 3.1): two agents, `m = 0.5`, `eta = 1`, `T = 0.4`.
    #[must_use]
    pub fn paper() -> Self {
        Self::new(PointMassConfig::default()).expect("the default config is valid")
    }

    /// The parameters.
    #[must_use]
    pub fn config(&self) -> &PointMassConfig {
        &self.config
    }

    /// Whether the friction is the same everywhere (then the `exact` integrator applies).
    #[must_use]
    pub fn has_constant_friction(&self) -> bool {
        matches!(self.friction, Friction::Constant(_))
    }

    /// The successor in `f64`: one sample time from `x` under joint force vector `u`.
    pub fn step_f64(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        let c = &self.config;
        for i in 0..c.agents {
            let s = &x[4 * i..4 * i + 4];
            let f = [u[2 * i], u[2 * i + 1]];
            let out = match (&self.friction, c.integrator) {
                (Friction::Constant(eta), Integrator::Exact) => {
                    exact_step(c.mass, *eta, c.sample_time, s, f)
                }
                (Friction::Constant(eta), Integrator::Rk4) => {
                    let eta = *eta;
                    rk4_step(c.mass, &|_, _| eta, c.sample_time, c.rk4_substeps, s, f)
                }
                (Friction::Field(eta), _) => {
                    rk4_step(c.mass, eta.as_ref(), c.sample_time, c.rk4_substeps, s, f)
                }
            };
            let n = &mut next[4 * i..4 * i + 4];
            for axis in 0..2 {
                n[axis] = out[axis].clamp(-c.position_limit, c.position_limit);
                n[2 + axis] = out[2 + axis].clamp(-c.velocity_limit, c.velocity_limit);
            }
        }
    }

    /// Whether `x` is in the reward region, `||x||_2 < goal_radius`.
    pub fn in_goal_f64(&self, x: &[f64]) -> bool {
        x.iter().map(|v| v * v).sum::<f64>().sqrt() < self.config.goal_radius
    }

    /// The shaping potential `Phi(x) = -sum_i ||x_i||_2` (each agent's own state).
    #[must_use]
    pub fn potential(x: &[f64]) -> f64 {
        -x.chunks(4)
            .map(|a| a.iter().map(|v| v * v).sum::<f64>().sqrt())
            .sum::<f64>()
    }

    /// The shaping term `gamma * Phi(next) - Phi(x)` of a transition from `x` to `next`.
    #[must_use]
    pub fn shaping(&self, x: &[f64], next: &[f64]) -> f64 {
        self.config.shaping_discount * Self::potential(next) - Self::potential(x)
    }

    /// The largest `|r|` of a step: the goal reward, plus under the shaped reward the largest
    /// shaping term (`|Phi|` is at most the agents' distance from the origin to a corner of
    /// the state box, and `gamma <= 1`).
    #[must_use]
    pub fn reward_bound(&self) -> f64 {
        let c = &self.config;
        let goal = c.goal_reward.abs();
        match c.reward {
            RewardShape::Paper => goal,
            RewardShape::Shaped => {
                let corner =
                    (2.0 * c.position_limit.powi(2) + 2.0 * c.velocity_limit.powi(2)).sqrt();
                goal + c.agents as f64 * corner
            }
        }
    }

    /// Agent `i`'s position `(s_x, s_y)` in state `x`.
    #[must_use]
    pub fn position(x: &[f64], agent: usize) -> [f64; 2] {
        [x[4 * agent], x[4 * agent + 1]]
    }
}

/// Where episodes start: a learner's episodes ([`crate::learn::tasks::pointmass::PointMassEnv`]).
///
/// Written in TOML as `starts = { fixed = [...] }` or
/// `starts = { uniform = { position = 6.0, velocity = 0.0 } }`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Starts {
    /// Always this state (length `4 n`, inside the state bounds).
    Fixed(Vec<f64>),
    /// Each agent's position uniform in `[-position, position]^2` and velocity uniform in
    /// `[-velocity, velocity]^2`, drawn per agent in the order `s_x, s_y, v_x, v_y`.
    Uniform {
        /// Half-width of the position square (m), in `[0, position_limit]`.
        position: f64,
        /// Half-width of the velocity square (m/s), in `[0, velocity_limit]`.
        velocity: f64,
    },
}

impl Starts {
    /// Checks the starts against the model's state space; errors name the field
    /// (`starts.fixed`, `starts.position`, `starts.velocity`).
    pub fn validate(&self, model: &PointMass) -> Result<(), ConfigError> {
        let c = model.config();
        match self {
            Self::Fixed(x0) => check_state_as("starts.fixed", model, x0),
            Self::Uniform { position, velocity } => {
                half_width("starts.position", *position, c.position_limit)?;
                half_width("starts.velocity", *velocity, c.velocity_limit)
            }
        }
    }

    /// Draws a start into `x` (length `4 n`) from `rng` (nothing is drawn for
    /// [`Fixed`](Self::Fixed)). The starts must be valid for the model.
    pub fn draw(&self, rng: &mut Pcg64Mcg, x: &mut [f64]) {
        match self {
            Self::Fixed(x0) => x.copy_from_slice(x0),
            Self::Uniform { position, velocity } => {
                for agent in x.chunks_mut(4) {
                    agent[0] = rng.random_range(-position..=*position);
                    agent[1] = rng.random_range(-position..=*position);
                    agent[2] = rng.random_range(-velocity..=*velocity);
                    agent[3] = rng.random_range(-velocity..=*velocity);
                }
            }
        }
    }
}

fn half_width(field: &'static str, v: f64, limit: f64) -> Result<(), ConfigError> {
    if v >= 0.0 && v <= limit {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            field,
            format!("must be a number in [0, {limit}] (the state bound), got {v}"),
        ))
    }
}

/// The usual `position` of [`random_starts`] (m): every start of Table 1's evaluation, and of
/// `fuzzyq rollout --starts`, has each position coordinate within this distance of the goal.
pub const START_POSITION: f64 = 5.0;

/// `count` starts at rest, each agent's position uniform in `[-position, position]^2`, drawn
/// from a [`Pcg64Mcg`] seeded with `seed` (agent-major, `s_x` then `s_y`): the same starts for
/// every learner, whatever its own seed. `position` must lie in `[0, position_limit]`.
pub fn random_starts(
    model: &PointMass,
    count: usize,
    seed: u64,
    position: f64,
) -> Result<Vec<Vec<f64>>, SimError> {
    half_width("position", position, model.config().position_limit)?;
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let n = model.config().state_dim();
    Ok((0..count)
        .map(|_| {
            let mut x = vec![0.0; n];
            for agent in x.chunks_mut(4) {
                agent[0] = rng.random_range(-position..=position);
                agent[1] = rng.random_range(-position..=position);
            }
            x
        })
        .collect())
}

/// Exact zero-order-hold step of one agent `[s_x, s_y, v_x, v_y]`.
fn exact_step(m: f64, eta: f64, t: f64, s: &[f64], f: [f64; 2]) -> [f64; 4] {
    let mut out = [0.0; 4];
    for axis in 0..2 {
        let (p, v, u) = (s[axis], s[2 + axis], f[axis]);
        let (p1, v1) = if eta == 0.0 {
            (p + v * t + 0.5 * u / m * t * t, v + u / m * t)
        } else {
            let a = eta / m;
            let w = u / eta;
            let decay = (-a * t).exp();
            // (1 - e^{-aT}) / a, written with exp_m1 to stay accurate for small aT.
            let gain = -(-a * t).exp_m1() / a;
            (p + w * t + (v - w) * gain, w + (v - w) * decay)
        };
        out[axis] = p1;
        out[2 + axis] = v1;
    }
    out
}

/// RK4 step of one agent under friction field `eta`.
fn rk4_step(
    m: f64,
    eta: &(dyn Fn(f64, f64) -> f64 + Send + Sync),
    t: f64,
    substeps: usize,
    s: &[f64],
    f: [f64; 2],
) -> [f64; 4] {
    let deriv = |y: [f64; 4]| -> [f64; 4] {
        let e = eta(y[0], y[1]);
        [y[2], y[3], (-e * y[2] + f[0]) / m, (-e * y[3] + f[1]) / m]
    };
    let h = t / substeps as f64;
    let mut y = [s[0], s[1], s[2], s[3]];
    let add = |y: [f64; 4], k: [f64; 4], c: f64| -> [f64; 4] {
        [
            y[0] + c * k[0],
            y[1] + c * k[1],
            y[2] + c * k[2],
            y[3] + c * k[3],
        ]
    };
    for _ in 0..substeps {
        let k1 = deriv(y);
        let k2 = deriv(add(y, k1, h / 2.0));
        let k3 = deriv(add(y, k2, h / 2.0));
        let k4 = deriv(add(y, k3, h));
        for j in 0..4 {
            y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
        }
    }
    y
}

impl Dynamics for PointMass {
    fn sample_time(&self) -> f64 {
        self.config.sample_time
    }

    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        symmetric(if dim % 4 < 2 {
            self.config.position_limit
        } else {
            self.config.velocity_limit
        })
    }

    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.step_f64(x, u, next);
    }

    fn reward(&self, x: &[f64], u: &[f64], precision: Precision) -> f64 {
        let goal = if self.in_goal_f64(x) {
            self.config.goal_reward
        } else {
            0.0
        };
        match self.config.reward {
            RewardShape::Paper => goal,
            RewardShape::Shaped => {
                // The successor as the solver sees it (rounded to its precision).
                let mut next = [0.0; 4 * MAX_POINT_MASS_AGENTS];
                let next = &mut next[..x.len()];
                self.step_f64(x, u, next);
                next.iter_mut().for_each(|v| *v = precision.round(*v));
                goal + self.shaping(x, next)
            }
        }
    }

    fn reward_depends_on_action(&self) -> bool {
        self.config.reward == RewardShape::Shaped
    }

    fn is_goal(&self, x: &[f64]) -> bool {
        self.in_goal_f64(x)
    }
}

impl F64Model for PointMass {
    fn state_dim(&self) -> usize {
        self.config.state_dim()
    }

    fn n_agents(&self) -> usize {
        self.config.agents
    }

    fn actions(&self) -> &ActionTable {
        &self.actions
    }

    fn blocks(&self) -> &[BlockSpec] {
        &self.blocks
    }

    fn add_process_noise(&self, x: &mut [f64], rng: &mut Pcg64Mcg) {
        let sigma = self.config.velocity_noise;
        if sigma == 0.0 {
            return;
        }
        let lim = self.config.velocity_limit;
        for agent in x.chunks_mut(4) {
            for v in &mut agent[2..4] {
                let z: f64 = rng.sample(rand_distr::StandardNormal);
                *v = (*v + sigma * z).clamp(-lim, lim);
            }
        }
    }
}

crate::model::impl_model!(PointMass);

#[cfg(test)]
mod tests {
    use fuzzyq_core::Model;

    use super::*;

    #[test]
    fn exact_step_matches_fine_rk4() {
        let mut rk = PointMassConfig {
            integrator: Integrator::Rk4,
            rk4_substeps: 400,
            ..PointMassConfig::default()
        };
        let exact = PointMass::new(PointMassConfig::default()).unwrap();
        let fine = PointMass::new(rk.clone()).unwrap();
        let x = [-4.0, -6.0, -2.0, 2.0, 5.0, 3.0, 2.0, -1.0];
        let u = [2.0, -0.2, 0.0, 2.0];
        let (mut a, mut b) = ([0.0; 8], [0.0; 8]);
        exact.step_f64(&x, &u, &mut a);
        fine.step_f64(&x, &u, &mut b);
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).abs() < 1e-10, "{a:?} vs {b:?}");
        }
        // Frictionless limit.
        rk.friction = FrictionConfig::Constant { eta: 0.0 };
        let fine0 = PointMass::new(rk).unwrap();
        let exact0 = PointMass::new(PointMassConfig {
            friction: FrictionConfig::Constant { eta: 0.0 },
            ..PointMassConfig::default()
        })
        .unwrap();
        exact0.step_f64(&[0.0; 8], &u, &mut a);
        fine0.step_f64(&[0.0; 8], &u, &mut b);
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).abs() < 1e-10);
        }
    }

    #[test]
    fn clamps_positions_and_velocities() {
        let m = PointMass::paper();
        let mut n = [0.0; 8];
        m.step_f64(
            &[5.9, 0.0, 3.0, 0.0, -5.9, 0.0, -3.0, 0.0],
            &[2.0, 0.0, -2.0, 0.0],
            &mut n,
        );
        assert_eq!(n[0], 6.0);
        assert_eq!(n[4], -6.0);
        assert!(n[2] <= 3.0 && n[6] >= -3.0);
    }

    #[test]
    fn declares_blocks_in_radix_order() {
        let m = PointMass::paper();
        assert_eq!(Model::<f32>::n_blocks(&m), 4);
        let b = Model::<f32>::block(&m, 3);
        assert_eq!(b.state_dims, &[5, 7]);
        assert_eq!(b.action_components, &[3]);
        let set = Model::<f64>::action_set(&m, 0);
        assert_eq!(set.n_actions(), 25);
        assert_eq!(set.action(1), &[-2.0, -0.2]);
    }

    #[test]
    fn rejects_bad_configs() {
        let bad = |f: fn(&mut PointMassConfig)| {
            let mut c = PointMassConfig::default();
            f(&mut c);
            PointMass::new(c).unwrap_err().to_string()
        };
        assert!(bad(|c| c.mass = 0.0).contains("env.mass"));
        assert!(bad(|c| c.agents = 0).contains("env.agents"));
        assert!(bad(|c| c.force_levels.clear()).contains("env.force_levels"));
        assert!(
            bad(|c| c.friction = FrictionConfig::Patches {
                base: 1.0,
                patches: vec![]
            })
            .contains("rk4")
        );
    }

    #[test]
    fn the_shaped_reward_telescopes_along_any_path() {
        // Sum_k gamma^k (rho(x_k) + F(x_k, u_k)) = sum_k gamma^k rho(x_k) + gamma^K Phi(x_K)
        // - Phi(x_0): the shaping adds the same for every action sequence (Ng et al. 1999).
        let paper = PointMass::paper();
        let shaped = PointMass::new(PointMassConfig {
            reward: RewardShape::Shaped,
            ..PointMassConfig::default()
        })
        .unwrap();
        assert!(Model::<f64>::reward_depends_on_action(&shaped));
        assert!(!Model::<f64>::reward_depends_on_action(&paper));
        let gamma = paper::GAMMA;
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        for start in [[0.05, 0.0, 0.0, 0.0, -0.02, 0.03, 0.0, 0.0], TABLE1_START] {
            let (mut x, mut next) = (start.to_vec(), vec![0.0; 8]);
            let (mut plain, mut with, mut discount) = (0.0, 0.0, 1.0);
            for _ in 0..60 {
                let u: Vec<f64> = (0..4)
                    .map(|_| paper::FORCE_LEVELS[rng.random_range(0..5)])
                    .collect();
                plain += discount * Model::<f64>::reward(&paper, &x, &u);
                with += discount * Model::<f64>::reward(&shaped, &x, &u);
                paper.step_f64(&x, &u, &mut next);
                std::mem::swap(&mut x, &mut next);
                discount *= gamma;
            }
            let expected =
                plain + discount * PointMass::potential(&x) - PointMass::potential(&start);
            assert!((with - expected).abs() < 1e-9, "{with} against {expected}");
        }
        // Each step's reward stays within the bound the learners project onto.
        let bound = shaped.reward_bound();
        assert!((bound - (5.0 + 2.0 * 90f64.sqrt())).abs() < 1e-12);
        assert_eq!(paper.reward_bound(), 5.0);
    }

    const TABLE1_START: [f64; 8] = [-4.0, 5.0, 0.0, 0.0, 5.0, -3.0, 0.0, 0.0];

    #[test]
    fn the_paper_reward_serialises_as_before_and_the_shaping_discount_is_checked() {
        let text = toml::to_string(&PointMassConfig::default()).unwrap();
        assert!(
            !text.contains("\nreward") && !text.contains("shaping"),
            "{text}"
        );
        let shaped = PointMassConfig {
            reward: RewardShape::Shaped,
            shaping_discount: 0.9,
            ..PointMassConfig::default()
        };
        let text = toml::to_string(&shaped).unwrap();
        assert!(text.contains("reward = \"shaped\""), "{text}");
        assert_eq!(toml::from_str::<PointMassConfig>(&text).unwrap(), shaped);
        for bad in [0.0, 1.5, f64::NAN] {
            let e = PointMass::new(PointMassConfig {
                shaping_discount: bad,
                ..shaped.clone()
            })
            .unwrap_err();
            assert!(e.to_string().contains("env.shaping_discount"), "{e}");
        }
        assert!(
            RewardShape::parse("dense", "--reward")
                .unwrap_err()
                .to_string()
                .contains("--reward")
        );
    }
}
