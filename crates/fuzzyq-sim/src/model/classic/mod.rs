//! The classic single-agent benchmarks of fuzzy Q-iteration: the problems of Busoniu, Babuska,
//! De Schutter and Ernst, *Reinforcement Learning and Dynamic Programming Using Function
//! Approximators* (CRC Press, 2010), chapter 4, as implemented in its companion MATLAB toolbox
//! ApproxRL (Lucian Busoniu, 2010).
//!
//! - [`dcmotor`]: the DC motor (`dc_problem` with the linear, saturated model `dc_linmdp` and
//!   the LQR reward): state `[alpha, alpha_dot]`, voltage `u`, the exact zero-order-hold
//!   discretisation.
//! - [`pendulum`]: the inverted pendulum swing-up (`ipsetup_problem`, type `ip`, LQR reward):
//!   a weight on a DC motor's disc that the motor alone cannot lift in one go, integrated with
//!   one classical RK4 step per sample time, angle wrapped to `[-pi, pi)`.
//! - [`carhill`]: the car on the hill (`hillcar_problem`): state `[p, p_dot]`, force `u`,
//!   terminal states outside the box, reward on reaching the top slowly enough.
//! - [`arm`]: the two-link robot arm (`rarm_problem`): state of two angles and their
//!   velocities, a torque per joint.
//!
//! Every benchmark is one [`Benchmark`] (with its [`Dynamics`]) wrapped by the generic [`Classic`]
//! (the action table, [`F64Model`] and so [`fuzzyq_core::Model`] for `f32` and `f64`, one
//! agent), computes in `f64` whatever the solver's precision, and comes with named
//! [`Preset`]s: the grid, actions, `gamma` and stopping threshold of a toolbox run. The
//! `"toolbox-demo"` presets are the configurations the parity tests check transition by
//! transition, sweep by sweep and step by step against the toolbox run under GNU Octave
//! (`tests/it/approxrl.rs`, data and provenance in `tests/data/approxrl/`).
//!
//! # Conventions shared with the toolbox
//! - The reward is evaluated at the **current** state with the applied action:
//!   `rho(x, u) = -x' Q x - R u^2`.
//! - Grids are built the way the toolbox builds them, with Octave's colon ranges
//!   ([`colon`], [`symequidgrid`]): the cores are the same doubles, bit for bit.
//! - The toolbox numbers cores in MATLAB's column-major order (first state variable fastest);
//!   fuzzyq numbers them row-major (last variable fastest). [`toolbox_core_index`](octave::toolbox_core_index) and
//!   [`core_index_from_toolbox`](octave::core_index_from_toolbox) convert.

pub mod arm;
pub mod carhill;
pub mod dcmotor;
pub mod octave;
pub mod pendulum;

pub use dcmotor::{DcMotor, DcMotorConfig};
pub use pendulum::{Pendulum, PendulumConfig};

use std::f64::consts::PI;

use fuzzyq_core::Real;
use fuzzyq_core::solver::{Grid, Precision, SolverConfig};
use serde::{Deserialize, Serialize};

use self::octave::{colon, symequidgrid};
use crate::error::{ConfigError, SimError, discount, positive, require};
use crate::model::{ActionTable, BlockSpec, Dynamics, EnvKind, F64Model};

/// The preset of a classic benchmark when none is named: the toolbox's default fine grid.
pub const DEFAULT_PRESET: &str = "fine";

/// The most RK4 substeps per sample time a configuration may ask for.
pub const MAX_RK4_SUBSTEPS: usize = 10_000;

/// How a classic model integrates one sample time.
///
/// In a config file: `integrator = "zoh"` or `integrator = { rk4 = { substeps = 1 } }`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum Integrator {
    /// The exact zero-order-hold discretisation (linear models only).
    Zoh,
    /// Classical fourth-order Runge-Kutta with the action held constant.
    Rk4 {
        /// Steps per sample time (1 to [`MAX_RK4_SUBSTEPS`]). The step sizes are the
        /// differences of Octave's range `0 : Ts/substeps : Ts`, as the toolbox's fixed-step
        /// integration uses them.
        substeps: usize,
    },
}

impl Integrator {
    /// Checks the substep count.
    pub fn validate(&self, field: &str) -> Result<(), ConfigError> {
        match *self {
            Self::Zoh => Ok(()),
            Self::Rk4 { substeps } if (1..=MAX_RK4_SUBSTEPS).contains(&substeps) => Ok(()),
            Self::Rk4 { substeps } => Err(ConfigError::invalid(
                field,
                format!("rk4 substeps must be between 1 and {MAX_RK4_SUBSTEPS}, got {substeps}"),
            )),
        }
    }
}

/// A named problem setup: the fuzzy grid, the discrete actions, the discount factor and the
/// stopping threshold of a toolbox run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preset {
    /// The preset's name (`"toolbox-demo"`, `"fine"`).
    pub name: String,
    /// The cores of each state variable, in increasing order.
    pub cores: Vec<Vec<f64>>,
    /// The discrete actions (one component each), in increasing order.
    pub actions: Vec<f64>,
    /// Discount factor, in `[0, 1)`.
    pub gamma: f64,
    /// Stopping threshold on `||theta_k - theta_{k-1}||_inf` (the toolbox's `eps`).
    pub xi: f64,
}

impl Preset {
    /// The preset `name`: the cores of each state variable, the discrete actions, `gamma` and
    /// `xi` of a toolbox run.
    #[must_use]
    pub fn new(name: &str, cores: Vec<Vec<f64>>, actions: Vec<f64>, gamma: f64, xi: f64) -> Self {
        Self {
            name: name.to_owned(),
            cores,
            actions,
            gamma,
            xi,
        }
    }

    /// Checks the grid, actions, `gamma` and `xi`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        require!(
            !self.cores.is_empty(),
            "preset.cores",
            "needs at least one state variable",
        );
        for (dim, c) in self.cores.iter().enumerate() {
            require!(
                c.len() >= 2,
                "preset.cores",
                format!(
                    "state variable {dim} needs at least 2 cores, got {}",
                    c.len()
                ),
            );
            require!(
                !(c.iter().any(|v| !v.is_finite()) || c.windows(2).any(|w| w[0] >= w[1])),
                "preset.cores",
                format!("the cores of state variable {dim} must be finite and increasing"),
            );
        }
        validate_actions("preset.actions", &self.actions)?;
        discount("preset.gamma", self.gamma)?;
        positive("preset.xi", self.xi)?;
        Ok(())
    }

    /// Number of joint cores (the product of the per-variable core counts).
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.cores.iter().map(Vec::len).product()
    }

    /// The fuzzy grid in precision `T` (triangular memberships).
    pub fn grid<T: Real>(&self) -> Result<Grid<T>, SimError> {
        self.validate()?;
        let cores = self
            .cores
            .iter()
            .map(|c| c.iter().map(|&v| T::from_f64(v)).collect())
            .collect();
        Ok(Grid::new(cores)?)
    }

    /// The toolbox's iteration: synchronous plain sweeps from `theta_0 = 0` with the preset's
    /// `gamma` and `xi` and the toolbox's limit of 1000 iterations (no extrapolation).
    #[must_use]
    pub fn solver_config(&self) -> SolverConfig {
        SolverConfig {
            gamma: self.gamma,
            xi: self.xi,
            max_sweeps: 1000,
            extrapolate: false,
            ..SolverConfig::default()
        }
    }
}

/// The toolbox's quadratic reward `-x' Q x - R u^2` with a diagonal `Q = diag(q)`, for two state
/// variables and one action component (the DC motor and the pendulum).
#[must_use]
pub(crate) fn lqr_reward(q: [f64; 2], r: f64, x: [f64; 2], u: f64) -> f64 {
    -(q[0] * x[0] * x[0] + q[1] * x[1] * x[1]) - r * u * u
}

/// The presets of a motor-driven rotary benchmark (the DC motor and the pendulum), which the
/// toolbox builds alike: `"toolbox-demo"` has `demo_cores` equidistant cores on
/// `[-pi, pi] x [-max_velocity, max_velocity]` (`symequidgrid`), 5 equidistant voltages on
/// `[-max_voltage, max_voltage]`, `gamma = 0.98`; `"fine"` has cores every 5 degrees and every
/// `velocity_step` rad/s (Octave's colon ranges), `fine_actions` and `fine_gamma`. Both stop at
/// `xi = 0.01`.
pub(crate) struct RotaryPresets {
    /// The environment (for the error on an unknown name).
    pub env: EnvKind,
    /// Core counts of the demo grid (angle, velocity).
    pub demo_cores: [usize; 2],
    /// The velocity bound of both grids.
    pub max_velocity: f64,
    /// The bound of the demo's voltages.
    pub max_voltage: f64,
    /// The fine grid's velocity spacing.
    pub velocity_step: f64,
    /// The fine preset's actions.
    pub fine_actions: fn() -> Result<Vec<f64>, ConfigError>,
    /// The fine preset's discount factor.
    pub fine_gamma: f64,
}

impl RotaryPresets {
    /// The preset `name`.
    pub fn preset(&self, name: &str) -> Result<Preset, ConfigError> {
        let v = self.max_velocity;
        match name {
            "toolbox-demo" => Ok(Preset::new(
                name,
                vec![
                    symequidgrid(PI, self.demo_cores[0])?,
                    symequidgrid(v, self.demo_cores[1])?,
                ],
                self.demo_actions()?,
                0.98,
                0.01,
            )),
            "fine" => Ok(Preset::new(
                name,
                vec![
                    colon(-PI, 5.0 * PI / 180.0, PI)?,
                    colon(-v, self.velocity_step, v)?,
                ],
                (self.fine_actions)()?,
                self.fine_gamma,
                0.01,
            )),
            _ => Err(self.env.unknown_preset(name)),
        }
    }

    /// The demo's actions: 5 equidistant voltages on `[-max_voltage, max_voltage]`.
    pub fn demo_actions(&self) -> Result<Vec<f64>, ConfigError> {
        symequidgrid(self.max_voltage, 5)
    }
}

/// Checks a discrete action list: 1 to 4096 finite values.
pub(crate) fn validate_actions(field: &str, actions: &[f64]) -> Result<(), ConfigError> {
    require!(
        (1..=4096).contains(&actions.len()),
        field,
        format!("needs 1 to 4096 actions, got {}", actions.len()),
    );
    crate::error::single_precision(field, actions)
}

/// A classic benchmark's definition beyond its [`Dynamics`]: its registry entry, sizes,
/// physical parameters and presets: what distinguishes the four. [`Classic`] adds what they
/// share (the discrete actions, the one dynamics block and the
/// [`Model`](fuzzyq_core::Model) implementation).
pub trait Benchmark: Dynamics + Clone + std::fmt::Debug + Send + Sync + Sized {
    /// The environment (its name and presets in the registry).
    const ENV: EnvKind;
    /// Length of the state vector.
    const STATE_DIM: usize;
    /// Components of an action vector.
    const ACTION_DIM: usize;
    /// The physical parameters (`[env.model]` in a config file).
    type Config: Clone + Default;

    /// Builds the dynamics from validated parameters.
    fn new(config: Self::Config) -> Result<Self, ConfigError>;
    /// The named preset (an error listing the presets for an unknown name).
    fn preset(name: &str) -> Result<Preset, ConfigError>;
    /// The action list of a preset or config (`actions = [...]`) when none is given.
    fn default_actions() -> Vec<f64>;
    /// The action vectors of a listed action set (one component each by default; the arm
    /// combines torque levels per joint). Errors name `field`.
    fn action_table(&self, field: &str, listed: &[f64]) -> Result<ActionTable, ConfigError> {
        validate_actions(field, listed)?;
        Ok(ActionTable::new(listed.to_vec(), 1))
    }
}

/// The named preset `name` of benchmark `S`, or an error listing its presets.
pub fn preset<S: Benchmark>(name: &str) -> Result<Preset, ConfigError> {
    S::preset(name)
}

/// Every preset of benchmark `S`, in registry order.
#[must_use]
pub fn presets<S: Benchmark>() -> Vec<Preset> {
    S::ENV
        .spec()
        .presets
        .iter()
        .filter_map(|name| preset::<S>(name).ok())
        .collect()
}

/// A classic benchmark: its [`Benchmark`] dynamics with a discrete action set. One agent; one dynamics
/// block (the whole state and action), which lets the solver tabulate the transitions once
/// (the toolbox's precomputed activation matrix) instead of stepping the model every sweep.
/// Dereferences to the dynamics (`config()`, `step_f64`, ...).
#[derive(Clone, Debug)]
pub struct Classic<S> {
    dynamics: S,
    actions: ActionTable,
    blocks: [BlockSpec; 1],
}

impl<S: Benchmark> Classic<S> {
    /// The benchmark with the action list `actions` (see [`Benchmark::action_table`]).
    pub fn new(dynamics: S, actions: &[f64]) -> Result<Self, ConfigError> {
        let table = dynamics.action_table("actions", actions)?;
        Ok(Self::from_table(dynamics, table))
    }

    /// The benchmark with an action table built by [`Benchmark::action_table`].
    #[must_use]
    pub fn from_table(dynamics: S, actions: ActionTable) -> Self {
        Self {
            blocks: [BlockSpec {
                state_dims: (0..S::STATE_DIM).collect(),
                action_components: (0..actions.dim()).collect(),
            }],
            dynamics,
            actions,
        }
    }

    /// The benchmark with parameters `config` and its default actions.
    pub fn from_config(config: S::Config) -> Result<Self, ConfigError> {
        Self::new(S::new(config)?, &S::default_actions())
    }

    /// The benchmark for a preset: `config` with the preset's actions (errors name
    /// `preset.*`).
    pub fn for_preset(config: S::Config, preset: &Preset) -> Result<Self, ConfigError> {
        preset.validate()?;
        require!(
            preset.cores.len() == S::STATE_DIM,
            "preset.cores",
            format!(
                "the {} has {} state variables, the preset {}",
                S::ENV.name(),
                S::STATE_DIM,
                preset.cores.len()
            ),
        );
        let dynamics = S::new(config)?;
        let table = dynamics.action_table("preset.actions", &preset.actions)?;
        Ok(Self::from_table(dynamics, table))
    }

    /// The same benchmark with the action list `actions`.
    pub fn with_actions(self, actions: &[f64]) -> Result<Self, ConfigError> {
        Self::new(self.dynamics, actions)
    }
}

impl<S> std::ops::Deref for Classic<S> {
    type Target = S;
    fn deref(&self) -> &S {
        &self.dynamics
    }
}

impl<S: Benchmark> Dynamics for Classic<S> {
    fn sample_time(&self) -> f64 {
        self.dynamics.sample_time()
    }
    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        self.dynamics.state_bounds(dim)
    }
    fn is_periodic(&self, dim: usize) -> bool {
        self.dynamics.is_periodic(dim)
    }
    /// The successor (NaN for inputs of the wrong length).
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        if x.len() == S::STATE_DIM && u.len() == S::ACTION_DIM && next.len() == S::STATE_DIM {
            self.dynamics.step(x, u, next);
        } else {
            next.fill(f64::NAN);
        }
    }
    /// The reward (NaN for inputs of the wrong length).
    fn reward(&self, x: &[f64], u: &[f64], precision: Precision) -> f64 {
        if x.len() == S::STATE_DIM && u.len() == S::ACTION_DIM {
            self.dynamics.reward(x, u, precision)
        } else {
            f64::NAN
        }
    }
    fn reward_depends_on_action(&self) -> bool {
        self.dynamics.reward_depends_on_action()
    }
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        self.dynamics.reward_depends_on_state(dim)
    }
    fn is_goal(&self, x: &[f64]) -> bool {
        x.len() == S::STATE_DIM && self.dynamics.is_goal(x)
    }
    fn is_terminal(&self, x: &[f64]) -> bool {
        x.len() != S::STATE_DIM || self.dynamics.is_terminal(x)
    }
    fn has_terminal_states(&self) -> bool {
        self.dynamics.has_terminal_states()
    }
}

impl<S: Benchmark> F64Model for Classic<S> {
    fn state_dim(&self) -> usize {
        S::STATE_DIM
    }
    fn n_agents(&self) -> usize {
        1
    }
    fn actions(&self) -> &ActionTable {
        &self.actions
    }
    fn blocks(&self) -> &[BlockSpec] {
        &self.blocks
    }
}

crate::model::impl_model!(Classic<S> where S: Benchmark);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrator_serde_is_lowercase() {
        #[derive(Deserialize, Serialize)]
        struct W {
            integrator: Integrator,
        }
        let w: W = toml::from_str("integrator = \"zoh\"").unwrap();
        assert_eq!(w.integrator, Integrator::Zoh);
        let w: W = toml::from_str("integrator = { rk4 = { substeps = 4 } }").unwrap();
        assert_eq!(w.integrator, Integrator::Rk4 { substeps: 4 });
        assert!(toml::from_str::<W>("integrator = { rk4 = { steps = 4 } }").is_err());
        assert!(
            Integrator::Rk4 { substeps: 0 }
                .validate("env.integrator")
                .is_err()
        );
    }
}
