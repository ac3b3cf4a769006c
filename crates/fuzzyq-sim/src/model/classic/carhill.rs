//! The car on the hill (Moore and Atkeson 1995; Ernst, Geurts and Wehenkel 2005; Busoniu et
//! al. 2010, section 4.5.4; ApproxRL's `hillcar_problem`, `hillcar_mdp_ode4` and
//! `hillcar_trans`).
//!
//! A car of mass `m` (point) drives along the hill `H(p) = p^2 + p` for `p < 0` and
//! `H(p) = p / sqrt(1 + 5 p^2)` for `p >= 0` under a horizontal force `u`. With
//! `H'`, `H''` the slope and curvature,
//! `p_ddot = (u / m - g H'(p) - p_dot^2 H'(p) H''(p)) / (1 + H'(p)^2)`, `g = 9.81`
//! (the toolbox writes it with `m = 1`; Ernst et al. divide `u` by `m`). The state is
//! `x = [p, p_dot]`. The mechanical energy `m g H(p) + m p_dot^2 (1 + H'(p)^2) / 2` is
//! conserved when `u = 0` ([`CarHill::energy`]).
//!
//! # Transition, terminal states and reward
//! Each sample time `Ts = 0.1` s is integrated with the force held constant, by classical RK4
//! with `substeps` equal steps of `Ts / substeps` (the toolbox's `hillcar_mdp_ode4`, 10 steps).
//! The episode ends when the successor leaves the box `|p| <= 1`, `|p_dot| <= 3`
//! ([`Model::is_terminal`]; the model [declares][`Model::has_terminal_states`] terminal states,
//! so fuzzy Q-iteration gives such transitions no future value, the toolbox's
//! `cfg.term = 'zero'`). The reward belongs to the transition and depends on the successor:
//! `+1` if it is terminal with `p > 1` and `p_dot <= 3` (the car reached the top of the hill
//! slowly enough), `-1` if it is terminal otherwise (it left on the left, or too fast), and 0
//! for a regular successor. fuzzyq's [`Model::reward`] is evaluated at the current state, so
//! it steps the model itself (rounded to the model's precision, so that the reward and
//! [`Model::is_terminal`] see the same successor).
//!
//! The toolbox clips a terminal successor back into the box "for the sake of the
//! approximators"; here [`Model::step`] returns it unclipped, since its value is never used
//! and [`Model::is_terminal`] must recognise it. The toolbox's success test `p_dot <= 3` (not
//! `|p_dot| <= 3` as in Ernst et al.) is kept; the two differ only for `p > 1` with
//! `p_dot < -3`, which a step from inside the box cannot produce. [`Model::is_goal`] is that
//! success region (outside the box, so the absorbing-goal option of the solver has no effect).
//!
//! # Presets
//! - `"fine"`: the toolbox's default fuzzy grid `hillcar_problem('fuzzy')`: cores
//!   `-1 : 0.05 : 1` and `-3 : 0.2 : 3` (41 x 31), actions `{-4, 4}`, `gamma = 0.95`, and
//!   `fuzzyqi`'s default `eps = 0.01`.
//! - `"coarse"`: 17 x 17 equidistant cores (`symequidgrid`) with the same actions, `gamma`
//!   and `xi`, for quick runs and tests (our choice, not the book's). From the standard start
//!   `p = -0.5`, `p_dot = 0` its greedy policy reaches the top in 19 steps, as the fine
//!   grid's does; square equidistant grids of 16 to 25 cores per variable all do, 13 or
//!   fewer do not.
//!
//! [`Model::is_terminal`]: fuzzyq_core::Model::is_terminal
//! [`Model::has_terminal_states`]: fuzzyq_core::Model::has_terminal_states
//! [`Model::reward`]: fuzzyq_core::Model::reward
//! [`Model::step`]: fuzzyq_core::Model::step
//! [`Model::is_goal`]: fuzzyq_core::Model::is_goal

use fuzzyq_core::solver::Precision;
use serde::{Deserialize, Serialize};

use super::octave::{colon, rk4, symequidgrid};
use super::{Benchmark, Classic, Integrator, Preset};
use crate::error::{ConfigError, non_negative, positive, require};
use crate::model::{Dynamics, EnvKind, symmetric};

/// The names of the car's presets.
pub const PRESETS: [&str; 2] = ["fine", "coarse"];

/// The classic force levels (N).
pub const CLASSIC_ACTIONS: [f64; 2] = [-4.0, 4.0];

/// The car on the hill's physical parameters, bounds and integrator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CarHillConfig {
    /// Mass of the car `m` (kg), `> 0`.
    pub mass: f64,
    /// Gravitational acceleration `g` (m/s^2), `>= 0` and finite.
    pub gravity: f64,
    /// Sample time `Ts` (s), `> 0`.
    pub sample_time: f64,
    /// The episode ends when `|p|` exceeds this (m), `> 0`.
    pub position_limit: f64,
    /// The episode ends when `|p_dot|` exceeds this (m/s), `> 0`.
    pub velocity_limit: f64,
    /// How a sample time is integrated (RK4 only: the dynamics are nonlinear).
    pub integrator: Integrator,
}

impl Default for CarHillConfig {
    /// The classic values (toolbox and Ernst et al.): `m = 1`, `g = 9.81`, `Ts = 0.1`, the box
    /// `|p| <= 1`, `|p_dot| <= 3`, RK4 with 10 steps per sample time.
    fn default() -> Self {
        Self {
            mass: 1.0,
            gravity: 9.81,
            sample_time: 0.1,
            position_limit: 1.0,
            velocity_limit: 3.0,
            integrator: Integrator::Rk4 { substeps: 10 },
        }
    }
}

impl CarHillConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("env.mass", self.mass)?;
        non_negative("env.gravity", self.gravity)?;
        positive("env.sample_time", self.sample_time)?;
        positive("env.position_limit", self.position_limit)?;
        positive("env.velocity_limit", self.velocity_limit)?;
        self.integrator.validate("env.integrator")?;
        require!(
            self.integrator != Integrator::Zoh,
            "env.integrator",
            "the car on the hill is nonlinear: use rk4 (no exact zero-order hold)",
        );
        Ok(())
    }
}

/// The hill's height `H(p)`.
#[must_use]
pub fn hill(p: f64) -> f64 {
    if p < 0.0 {
        p * p + p
    } else {
        p / (1.0 + 5.0 * p * p).sqrt()
    }
}

/// The hill's slope and curvature `(H'(p), H''(p))`, written as the toolbox's
/// `hillcar_trans` writes them.
#[must_use]
pub fn hill_derivatives(p: f64) -> (f64, f64) {
    if p < 0.0 {
        (2.0 * p + 1.0, 2.0)
    } else {
        let s = 1.0 + 5.0 * p * p;
        (s.powf(-1.5), -15.0 * p / s.powf(2.5))
    }
}

/// The car on the hill's dynamics (a [`Classic`] benchmark: [`CarHillModel`] is the model).
#[derive(Clone, Debug)]
pub struct CarHill {
    config: CarHillConfig,
    /// RK4 step sizes.
    steps: Vec<f64>,
}

/// The car on the hill benchmark: [`CarHill`] dynamics with a discrete force set.
pub type CarHillModel = Classic<CarHill>;

impl CarHill {
    /// Builds the dynamics from validated parameters.
    pub fn new(config: CarHillConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let substeps = match config.integrator {
            Integrator::Rk4 { substeps } => substeps,
            Integrator::Zoh => unreachable!("refused by validate"),
        };
        Ok(Self {
            steps: vec![config.sample_time / substeps as f64; substeps],
            config,
        })
    }

    /// The parameters.
    #[must_use]
    pub fn config(&self) -> &CarHillConfig {
        &self.config
    }

    /// The time derivative `[p_dot, p_ddot]` at `x` under force `u`.
    #[must_use]
    pub fn derivative(&self, x: [f64; 2], u: f64) -> [f64; 2] {
        let (h1, h2) = hill_derivatives(x[0]);
        let c = &self.config;
        [
            x[1],
            (u / c.mass - c.gravity * h1 - x[1] * x[1] * h1 * h2) / (1.0 + h1 * h1),
        ]
    }

    /// The successor of `x` under force `u` after one sample time (not clipped: it may be
    /// terminal).
    #[must_use]
    pub fn step_f64(&self, x: [f64; 2], u: f64) -> [f64; 2] {
        rk4(|y| self.derivative(y, u), x, &self.steps)
    }

    /// Whether `x` lies outside the box `|p| <= position_limit`, `|p_dot| <= velocity_limit`
    /// (a NaN component counts as outside).
    #[must_use]
    pub fn is_terminal_f64(&self, x: [f64; 2]) -> bool {
        let c = &self.config;
        !(x[0].abs() <= c.position_limit && x[1].abs() <= c.velocity_limit)
    }

    /// Whether `x` is in the success region: past the top (`p > position_limit`) with
    /// `p_dot <= velocity_limit`.
    #[must_use]
    pub fn is_success_f64(&self, x: [f64; 2]) -> bool {
        let c = &self.config;
        x[0] > c.position_limit && x[1] <= c.velocity_limit
    }

    /// The reward of a transition that ends in `next`: `+1` for a terminal success, `-1` for
    /// any other terminal state, 0 otherwise.
    #[must_use]
    pub fn transition_reward(&self, next: [f64; 2]) -> f64 {
        if !self.is_terminal_f64(next) {
            0.0
        } else if self.is_success_f64(next) {
            1.0
        } else {
            -1.0
        }
    }

    /// The reward `rho(x, u)` of the transition from `x` under `u` (steps the model).
    #[must_use]
    pub fn reward_f64(&self, x: [f64; 2], u: f64) -> f64 {
        self.transition_reward(self.step_f64(x, u))
    }

    /// The mechanical energy `m g H(p) + m p_dot^2 (1 + H'(p)^2) / 2` (J), conserved when the
    /// force is 0.
    #[must_use]
    pub fn energy(&self, x: [f64; 2]) -> f64 {
        let c = &self.config;
        let (h1, _) = hill_derivatives(x[0]);
        c.mass * c.gravity * hill(x[0]) + 0.5 * c.mass * x[1] * x[1] * (1.0 + h1 * h1)
    }
}

impl Dynamics for CarHill {
    fn sample_time(&self) -> f64 {
        self.config.sample_time
    }

    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        symmetric(if dim == 0 {
            self.config.position_limit
        } else {
            self.config.velocity_limit
        })
    }

    /// The unclipped successor.
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next.copy_from_slice(&self.step_f64([x[0], x[1]], u[0]));
    }

    /// `+1`, `-1` or 0 by the successor rounded to the solver's precision, so that the reward
    /// and [`is_terminal`](Dynamics::is_terminal) see the successor the solver sees (see the
    /// [module docs](self)).
    fn reward(&self, x: &[f64], u: &[f64], precision: Precision) -> f64 {
        let y = self.step_f64([x[0], x[1]], u[0]);
        self.transition_reward(y.map(|c| precision.round(c)))
    }

    fn is_goal(&self, x: &[f64]) -> bool {
        self.is_success_f64([x[0], x[1]])
    }

    fn is_terminal(&self, x: &[f64]) -> bool {
        self.is_terminal_f64([x[0], x[1]])
    }

    fn has_terminal_states(&self) -> bool {
        true
    }
}

impl Benchmark for CarHill {
    const ENV: EnvKind = EnvKind::Carhill;
    const STATE_DIM: usize = 2;
    const ACTION_DIM: usize = 1;
    type Config = CarHillConfig;

    fn new(config: CarHillConfig) -> Result<Self, ConfigError> {
        CarHill::new(config)
    }

    /// See the [module docs](self) for where each value comes from.
    fn preset(name: &str) -> Result<Preset, ConfigError> {
        match name {
            "fine" => Ok(Preset::new(
                name,
                vec![colon(-1.0, 0.05, 1.0)?, colon(-3.0, 0.2, 3.0)?],
                CLASSIC_ACTIONS.to_vec(),
                0.95,
                0.01,
            )),
            "coarse" => Ok(Preset::new(
                name,
                vec![symequidgrid(1.0, 17)?, symequidgrid(3.0, 17)?],
                CLASSIC_ACTIONS.to_vec(),
                0.95,
                0.01,
            )),
            _ => Err(Self::ENV.unknown_preset(name)),
        }
    }

    /// The classic forces `{-4, 4}`.
    fn default_actions() -> Vec<f64> {
        CLASSIC_ACTIONS.to_vec()
    }
}

#[cfg(test)]
mod tests {
    use std::ops::ControlFlow;

    use fuzzyq_core::solver::{BackupPath, Grid, Operator, SolverConfig, solve};
    use fuzzyq_core::{Backup, q};

    use super::*;
    use fuzzyq_core::Model;

    fn preset(name: &str) -> Result<Preset, ConfigError> {
        super::super::preset::<CarHill>(name)
    }

    fn presets() -> Vec<Preset> {
        super::super::presets::<CarHill>()
    }

    fn car() -> CarHillModel {
        CarHillModel::from_config(CarHillConfig::default()).unwrap()
    }

    /// The toolbox's `hillcar_trans`, transcribed independently.
    fn toolbox_derivative(x: [f64; 2], u: f64) -> [f64; 2] {
        let p = x[0];
        let (h1, h2) = if p < 0.0 {
            (2.0 * p + 1.0, 2.0)
        } else {
            (
                (1.0 + 5.0 * p * p).powf(-1.5),
                -15.0 * p / (1.0 + 5.0 * p * p).powf(2.5),
            )
        };
        [
            x[1],
            (u - 9.81 * h1 - x[1].powi(2) * h1 * h2) / (1.0 + h1 * h1),
        ]
    }

    #[test]
    fn dynamics_match_hand_computed_values() {
        let m = car();
        // At the bottom of the valley (p = -0.5, H' = 0): only the force accelerates.
        assert_eq!(m.derivative([-0.5, 0.0], 4.0), [0.0, 4.0]);
        // p = 0: H' = 1, H'' = 0 from the right: (u - g) / 2.
        assert_eq!(m.derivative([0.0, 1.0], 4.0), [1.0, (4.0 - 9.81) / 2.0]);
        // p = -1: H' = -1, H'' = 2: (u + g - 2 v^2 (-1)) / 2 = (u + g + 2 v^2) / 2.
        assert_eq!(
            m.derivative([-1.0, 2.0], -4.0),
            [2.0, (-4.0 + 9.81 + 8.0) / 2.0]
        );
        // p = 1: H' = 6^-1.5, H'' = -15 * 6^-2.5.
        let (h1, h2) = (6f64.powf(-1.5), -15.0 / 6f64.powf(2.5));
        let a = (4.0 - 9.81 * h1 - 0.25 * h1 * h2) / (1.0 + h1 * h1);
        assert!((m.derivative([1.0, 0.5], 4.0)[1] - a).abs() < 1e-15);
        for x in [[-0.9, 2.5], [-0.2, -1.0], [0.3, 0.7], [0.95, -2.9]] {
            for u in [-4.0, 0.0, 4.0] {
                assert_eq!(m.derivative(x, u), toolbox_derivative(x, u), "{x:?} {u}");
            }
        }
        // The hill is continuous with a continuous slope at 0.
        assert_eq!(hill(0.0), 0.0);
        assert!((hill(-1e-9) - hill(1e-9)).abs() < 3e-9);
        assert_eq!(hill_derivatives(-1e-300).0, 1.0);
        assert_eq!(hill_derivatives(0.0).0, 1.0);
    }

    /// One sample time against an independent integration (1000 RK4 steps).
    #[test]
    fn step_matches_a_fine_integration() {
        let m = car();
        let fine = CarHillModel::from_config(CarHillConfig {
            integrator: Integrator::Rk4 { substeps: 1000 },
            ..CarHillConfig::default()
        })
        .unwrap();
        for x in [[-0.5, 0.0], [-0.9, 2.0], [0.4, -1.5], [0.9, 2.9]] {
            for u in CLASSIC_ACTIONS {
                let (a, b) = (m.step_f64(x, u), fine.step_f64(x, u));
                for j in 0..2 {
                    assert!((a[j] - b[j]).abs() < 1e-6, "{x:?} {u}: {a:?} vs {b:?}");
                }
            }
        }
        // Explicit Euler with tiny steps agrees to its first-order error.
        let mut y = [-0.5, 0.0];
        let h = 0.1 / 100_000.0;
        for _ in 0..100_000 {
            let d = toolbox_derivative(y, 4.0);
            y = [y[0] + h * d[0], y[1] + h * d[1]];
        }
        let s = m.step_f64([-0.5, 0.0], 4.0);
        assert!((s[0] - y[0]).abs() < 1e-5 && (s[1] - y[1]).abs() < 1e-4);
    }

    #[test]
    fn energy_is_conserved_without_force_and_grows_with_it() {
        let m = car();
        let mut x = [-0.9, 0.0];
        let e0 = m.energy(x);
        for _ in 0..50 {
            x = m.step_f64(x, 0.0);
            assert!((m.energy(x) - e0).abs() < 1e-6, "{x:?}");
        }
        // Pushing in the direction of motion adds energy.
        let x = [-0.5, 1.0];
        assert!(m.energy(m.step_f64(x, 4.0)) > m.energy(x));
        assert!(m.energy(m.step_f64(x, -4.0)) < m.energy(x));
        // Without force the car settles back: it oscillates in the valley around p = -0.5.
        let mut x = [-0.2, 0.0];
        let mut lo = 0.0f64;
        for _ in 0..30 {
            x = m.step_f64(x, 0.0);
            lo = lo.min(x[0]);
        }
        assert!(
            (lo + 0.8).abs() < 0.01,
            "mirror image of -0.2 around -0.5: {lo}"
        );
    }

    #[test]
    fn terminal_states_and_rewards_at_the_boundaries() {
        let m = car();
        let t = |p: f64, v: f64| Model::<f64>::is_terminal(&m, &[p, v]);
        assert!(!t(1.0, 3.0) && !t(-1.0, -3.0) && !t(0.0, 0.0));
        assert!(t(1.0 + 1e-12, 0.0) && t(-1.0 - 1e-12, 0.0));
        assert!(t(0.0, 3.0 + 1e-12) && t(0.0, -3.0 - 1e-12) && t(f64::NAN, 0.0));
        assert_eq!(m.transition_reward([1.0, 3.0]), 0.0);
        assert_eq!(m.transition_reward([1.01, 3.0]), 1.0);
        assert_eq!(m.transition_reward([1.01, 3.01]), -1.0);
        assert_eq!(m.transition_reward([-1.01, 0.0]), -1.0);
        assert_eq!(m.transition_reward([0.5, -3.5]), -1.0);
        assert!(Model::<f64>::is_goal(&m, &[1.2, 2.0]));
        assert!(!Model::<f64>::is_goal(&m, &[0.9, 2.0]));
        // A car near the top moving fast enough gets over: reward +1, the successor terminal.
        let x = [0.95, 2.0];
        let next = m.step_f64(x, 4.0);
        assert!(next[0] > 1.0 && next[1] <= 3.0);
        assert_eq!(m.reward_f64(x, 4.0), 1.0);
        let mut n = [0.0; 2];
        Model::<f64>::step(&m, &x, &[4.0], &mut n);
        assert_eq!(n, next);
        assert!(Model::<f64>::is_terminal(&m, &n));
        assert_eq!(Model::<f64>::reward(&m, &x, &[4.0]), 1.0);
        // Leaving on the left costs -1.
        assert_eq!(m.reward_f64([-0.98, -2.5], -4.0), -1.0);
        // From the valley floor nothing ends.
        assert_eq!(m.reward_f64([-0.5, 0.0], 4.0), 0.0);
        // f32 agrees and rewards its own rounded successor.
        assert_eq!(Model::<f32>::reward(&m, &[0.95, 2.0], &[4.0]), 1.0);
        // Bad lengths give NaN, never a panic.
        let mut n3 = [0.0f64; 3];
        Model::<f64>::step(&m, &[0.0], &[4.0], &mut n3);
        assert!(n3.iter().all(|v| v.is_nan()));
        assert!(Model::<f64>::reward(&m, &[0.0, 0.0], &[]).is_nan());
        assert!(Model::<f64>::is_terminal(&m, &[0.0]));
    }

    #[test]
    fn presets_have_the_documented_sizes() {
        let fine = preset("fine").unwrap();
        assert_eq!((fine.cores[0].len(), fine.cores[1].len()), (41, 31));
        assert_eq!((fine.cores[0][20], fine.cores[1][15]), (0.0, 0.0));
        assert_eq!(fine.actions, [-4.0, 4.0]);
        assert_eq!((fine.gamma, fine.xi), (0.95, 0.01));
        let coarse = preset("coarse").unwrap();
        assert_eq!(coarse.n_cores(), 17 * 17);
        assert_eq!(presets().len(), PRESETS.len());
        assert!(preset("book").unwrap_err().to_string().contains("preset"));
        let m = CarHillModel::for_preset(CarHillConfig::default(), &fine).unwrap();
        assert_eq!(Model::<f32>::action_set(&m, 0).n_actions(), 2);
        let bad = Preset {
            cores: vec![vec![0.0, 1.0]],
            ..fine
        };
        assert!(CarHillModel::for_preset(CarHillConfig::default(), &bad).is_err());
    }

    #[test]
    fn rejects_bad_configs() {
        let bad = |f: fn(&mut CarHillConfig)| {
            let mut c = CarHillConfig::default();
            f(&mut c);
            CarHillModel::from_config(c).unwrap_err().to_string()
        };
        assert!(bad(|c| c.mass = 0.0).contains("env.mass"));
        assert!(bad(|c| c.gravity = f64::NAN).contains("env.gravity"));
        assert!(bad(|c| c.gravity = -1.0).contains("env.gravity"));
        assert!(bad(|c| c.sample_time = -0.1).contains("env.sample_time"));
        assert!(bad(|c| c.position_limit = f64::INFINITY).contains("env.position_limit"));
        assert!(bad(|c| c.velocity_limit = 0.0).contains("env.velocity_limit"));
        assert!(bad(|c| c.integrator = Integrator::Zoh).contains("env.integrator"));
        assert!(bad(|c| c.integrator = Integrator::Rk4 { substeps: 0 }).contains("env.integrator"));
        assert!(car().with_actions(&[f64::NAN]).is_err());
        let c: CarHillConfig = toml::from_str("mass = 2.0").unwrap();
        assert_eq!((c.mass, c.sample_time), (2.0, 0.1));
        assert!(toml::from_str::<CarHillConfig>("friction = 1.0").is_err());
    }

    /// Greedy rollout from `x` with the model-based Q-values of `v`; the number of steps to
    /// the goal, if reached within `steps`.
    fn steps_to_goal(
        m: &CarHillModel,
        grid: &Grid<f64>,
        v: &[f64],
        x: [f64; 2],
        steps: usize,
    ) -> Option<usize> {
        let backup = Backup::discounted(0.95);
        let op = Operator::new(m, grid.view(), backup, BackupPath::Auto).unwrap();
        let mut x = x;
        let mut qx = [0.0; 2];
        for k in 1..=steps {
            op.q_values(v, &x, &mut qx).unwrap();
            let u = crate::model::F64Model::actions(m).action(q::argmax(&qx).unwrap())[0];
            x = m.step_f64(x, u);
            if m.is_terminal_f64(x) {
                return m.is_success_f64(x).then_some(k);
            }
        }
        None
    }

    /// Fuzzy Q-iteration on the coarse preset converges, its greedy policy (model-based and
    /// interpolated) drives the car from the standard start to the top, and the block and
    /// generic paths agree.
    #[test]
    fn coarse_fuzzy_q_iteration_reaches_the_top() {
        let p = preset("coarse").unwrap();
        let m = CarHillModel::for_preset(CarHillConfig::default(), &p).unwrap();
        let grid = p.grid::<f64>().unwrap();
        let s = solve(&m, &grid, &p.solver_config(), |_| ControlFlow::Continue(())).unwrap();
        assert!(s.converged(), "{} sweeps", s.sweeps.len());
        assert_eq!(s.path, BackupPath::Block);
        assert!(s.v.iter().all(|v| (-1.0..=1.0).contains(v)));
        let generic = solve(
            &m,
            &grid,
            &SolverConfig {
                path: BackupPath::Generic,
                ..p.solver_config()
            },
            |_| ControlFlow::Continue(()),
        )
        .unwrap();
        assert_eq!(generic.sweeps.len(), s.sweeps.len());
        let d =
            s.v.iter()
                .zip(&generic.v)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(d < 1e-12, "{d}");
        let k = steps_to_goal(&m, &grid, &s.v, [-0.5, 0.0], 100).expect("reaches the top");
        assert!(k <= 20, "{k} steps");
        // The interpolated policy (eq 22) over the per-core greedy actions also gets there.
        let view = grid.view();
        let joint = fuzzyq_core::model::joint_actions::<f64, _>(&m).unwrap();
        let mut x = [-0.5, 0.0];
        let mut u = [0.0];
        let mut reached = false;
        for _ in 0..100 {
            q::interpolated_action(&view, &joint, &s.greedy, &x, &mut u).unwrap();
            x = m.step_f64(x, u[0]);
            if m.is_terminal_f64(x) {
                reached = m.is_success_f64(x);
                break;
            }
        }
        assert!(reached, "interpolated policy ended at {x:?}");
    }
}
