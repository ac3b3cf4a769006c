//! The inverted pendulum swing-up of Busoniu et al. 2010 (section 4.5.4 and ApproxRL's
//! `ipsetup_problem`, type `ip`, LQR reward).
//!
//! A weight of mass `m` at distance `l` from the axis of a DC motor's disc (inertia
//! `J = J0 + m l^2`), driven by a voltage `u` that is too weak to lift it in one go:
//! `alpha_ddot = (m g l sin(alpha) - (b + K^2/R) alpha_dot + (K/R) u) / J`. The state is
//! `x = [alpha, alpha_dot]` with `alpha = 0` pointing up and `+-pi` hanging down.
//!
//! # Transition and reward
//! `u` is limited to `[-3, 3]`, the ODE is integrated over `Ts = 0.005 s` with one classical
//! RK4 step (the toolbox's `ode4` with one step per sample time; [`Integrator::Rk4`] selects
//! more), then the angle is wrapped with MATLAB's `mod(alpha + pi, 2 pi) - pi` (into
//! `[-pi, pi)`; [`wrap_angle_octave`] reproduces Octave's `mod` exactly) and the velocity is
//! saturated to `[-15 pi, 15 pi]`. The reward is evaluated at the current state with the
//! limited `u`: `rho(x, u) = -x' Q x - R u^2`, `Q = diag(5, 0.1)`, `R = 1`.
//! [`Integrator::Zoh`] is refused: the model is nonlinear.
//!
//! # Presets
//! - `"toolbox-demo"`: the toolbox demo `invertedpendulum_demo.m` as run by the parity tests:
//!   41 x 21 equidistant cores on `[-pi, pi] x [-15 pi, 15 pi]` (`symequidgrid`), 5 equidistant
//!   actions on `[-3, 3]`, `gamma = 0.98`, and `xi = 0.01` (the demo stops at `eps = 1`; the
//!   oracle run uses `fuzzyqi`'s default `0.01`).
//! - `"fine"`: the default fuzzy grid of `ipsetup_problem('fuzzy')`: cores
//!   `-pi : 5*pi/180 : pi` and `-15 pi : pi/3 : 15 pi` (73 x 91), 15 actions
//!   `symloggrid(15, 3, -1)` (logarithmically denser near 0), `gamma = 0.98`, `xi = 0.01`.

use std::f64::consts::PI;

use fuzzyq_core::solver::Precision;
use serde::{Deserialize, Serialize};

use super::octave::{rk4, rk4_step_sizes, sat, symloggrid, wrap_angle_octave};
use super::{Benchmark, Classic, Integrator, Preset, RotaryPresets, lqr_reward};
use crate::error::{ConfigError, non_negative, positive, require};
use crate::model::{Dynamics, EnvKind, symmetric};

/// The names of the pendulum's presets.
pub const PRESETS: [&str; 2] = ["toolbox-demo", "fine"];

/// The swing-up's physical parameters, bounds, reward weights and integrator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PendulumConfig {
    /// Inertia of the rotor and disc without the weight, `J0` (kg m^2), `> 0`.
    pub disc_inertia: f64,
    /// Mass of the weight `m` (kg), `>= 0`.
    pub mass: f64,
    /// Distance `l` of the weight from the axis (m), `>= 0`.
    pub length: f64,
    /// Gravitational acceleration `g` (m/s^2), `>= 0`.
    pub gravity: f64,
    /// Viscous damping `b` (N m s/rad), `>= 0`.
    pub damping: f64,
    /// Torque constant `K` (N m/A), `> 0`.
    pub torque_constant: f64,
    /// Rotor resistance `R` (Ohm), `> 0`.
    pub resistance: f64,
    /// Sample time `Ts` (s), `> 0`.
    pub sample_time: f64,
    /// The angular velocity is saturated to `[-max_velocity, max_velocity]` (rad/s), `> 0`.
    pub max_velocity: f64,
    /// The voltage is limited to `[-max_voltage, max_voltage]` (V), `> 0`.
    pub max_voltage: f64,
    /// The diagonal of the state weight `Q` of the reward, each `>= 0`.
    pub q: [f64; 2],
    /// The action weight `R` of the reward, `>= 0`.
    pub r: f64,
    /// How a sample time is integrated (RK4 only: the model is nonlinear).
    pub integrator: Integrator,
}

impl Default for PendulumConfig {
    /// The toolbox's values (`ipsetup_problem`): `J0 = 9.396e-5`, `m = 0.055`, `l = 0.042`,
    /// `g = 9.81`, `b = 3e-6`, `K = 0.0536`, `R = 9.5`, `Ts = 0.005`, velocity bound `15 pi`,
    /// voltage bound 3, `Q = diag(5, 0.1)`, reward `R = 1`, one RK4 step per sample time.
    fn default() -> Self {
        Self {
            disc_inertia: 9.3960e-5,
            mass: 0.055,
            length: 0.042,
            gravity: 9.81,
            damping: 3.0e-6,
            torque_constant: 53.6e-3,
            resistance: 9.50,
            sample_time: 0.005,
            max_velocity: 15.0 * PI,
            max_voltage: 3.0,
            q: [5.0, 0.1],
            r: 1.0,
            integrator: Integrator::Rk4 { substeps: 1 },
        }
    }
}

/// The derived coefficients of the ODE, computed as the toolbox computes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PendulumCoefficients {
    /// Total inertia `J = J0 + m l^2`.
    pub inertia: f64,
    /// `m g l`.
    pub mgl: f64,
    /// `b + K^2/R`.
    pub friction: f64,
    /// `Km = K/R`.
    pub km: f64,
}

impl PendulumConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("env.disc_inertia", self.disc_inertia)?;
        non_negative("env.mass", self.mass)?;
        non_negative("env.length", self.length)?;
        non_negative("env.gravity", self.gravity)?;
        non_negative("env.damping", self.damping)?;
        positive("env.torque_constant", self.torque_constant)?;
        positive("env.resistance", self.resistance)?;
        positive("env.sample_time", self.sample_time)?;
        positive("env.max_velocity", self.max_velocity)?;
        positive("env.max_voltage", self.max_voltage)?;
        non_negative("env.q", self.q[0])?;
        non_negative("env.q", self.q[1])?;
        non_negative("env.r", self.r)?;
        self.integrator.validate("env.integrator")?;
        require!(
            self.integrator != Integrator::Zoh,
            "env.integrator",
            "\"zoh\" is exact for linear models only; the pendulum needs rk4",
        );
        let c = self.coefficients();
        let rates = [c.mgl / c.inertia, c.friction / c.inertia, c.km / c.inertia];
        require!(
            rates.iter().all(|r| r.is_finite()),
            "env.disc_inertia",
            "the pendulum's rates overflow with these parameters",
        );
        Ok(())
    }

    /// `J`, `m g l`, `b + K^2/R` and `K/R`, with the toolbox's operation order.
    #[must_use]
    pub fn coefficients(&self) -> PendulumCoefficients {
        let (k, r) = (self.torque_constant, self.resistance);
        PendulumCoefficients {
            inertia: self.disc_inertia + self.mass * (self.length * self.length),
            mgl: self.mass * self.gravity * self.length,
            friction: self.damping + (k * k) / r,
            km: k / r,
        }
    }
}

/// The swing-up's dynamics (a [`Classic`] benchmark: [`PendulumModel`] is the model).
#[derive(Clone, Debug)]
pub struct Pendulum {
    config: PendulumConfig,
    coef: PendulumCoefficients,
    /// RK4 step sizes.
    steps: Vec<f64>,
}

/// The swing-up benchmark: [`Pendulum`] dynamics with a discrete voltage set.
pub type PendulumModel = Classic<Pendulum>;

impl Pendulum {
    /// Builds the dynamics from validated parameters.
    pub fn new(config: PendulumConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let Integrator::Rk4 { substeps } = config.integrator else {
            return Err(ConfigError::invalid(
                "env.integrator",
                "the pendulum needs rk4",
            ));
        };
        Ok(Self {
            coef: config.coefficients(),
            steps: rk4_step_sizes(config.sample_time, substeps),
            config,
        })
    }

    /// The parameters.
    #[must_use]
    pub fn config(&self) -> &PendulumConfig {
        &self.config
    }

    /// The derived ODE coefficients.
    #[must_use]
    pub fn coefficients(&self) -> PendulumCoefficients {
        self.coef
    }

    /// The state derivative at `x` under the (already limited) voltage `u`.
    #[must_use]
    pub fn derivative(&self, x: [f64; 2], u: f64) -> [f64; 2] {
        let c = &self.coef;
        [
            x[1],
            (c.mgl * x[0].sin() - c.friction * x[1] + c.km * u) / c.inertia,
        ]
    }

    /// The successor of `x` under voltage `u` (limited to the voltage bound), with the angle
    /// wrapped and the velocity saturated.
    #[must_use]
    pub fn step_f64(&self, x: [f64; 2], u: f64) -> [f64; 2] {
        let u = self.limit(u);
        let y = rk4(|y| self.derivative(y, u), x, &self.steps);
        let v = self.config.max_velocity;
        [wrap_angle_octave(y[0]), sat(y[1], -v, v)]
    }

    /// The reward at the current state `x` under voltage `u` (limited): `-x' Q x - R u^2`.
    #[must_use]
    pub fn reward_f64(&self, x: [f64; 2], u: f64) -> f64 {
        let u = self.limit(u);
        lqr_reward(self.config.q, self.config.r, x, u)
    }

    fn limit(&self, u: f64) -> f64 {
        sat(u, -self.config.max_voltage, self.config.max_voltage)
    }
}

/// The swing-up's presets (see the [module docs](self)).
const PENDULUM_PRESETS: RotaryPresets = RotaryPresets {
    env: EnvKind::Pendulum,
    demo_cores: [41, 21],
    max_velocity: 15.0 * PI,
    max_voltage: 3.0,
    velocity_step: PI / 3.0,
    fine_actions: || symloggrid(15, 3.0, -1.0, 1.0),
    fine_gamma: 0.98,
};

impl Dynamics for Pendulum {
    fn sample_time(&self) -> f64 {
        self.config.sample_time
    }

    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        symmetric(if dim == 0 {
            PI
        } else {
            self.config.max_velocity
        })
    }

    fn is_periodic(&self, dim: usize) -> bool {
        dim == 0
    }

    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next.copy_from_slice(&self.step_f64([x[0], x[1]], u[0]));
    }

    fn reward(&self, x: &[f64], u: &[f64], _precision: Precision) -> f64 {
        self.reward_f64([x[0], x[1]], u[0])
    }
}

impl Benchmark for Pendulum {
    const ENV: EnvKind = EnvKind::Pendulum;
    const STATE_DIM: usize = 2;
    const ACTION_DIM: usize = 1;
    type Config = PendulumConfig;

    fn new(config: PendulumConfig) -> Result<Self, ConfigError> {
        Pendulum::new(config)
    }

    /// See the [module docs](self) for where each value comes from.
    fn preset(name: &str) -> Result<Preset, ConfigError> {
        PENDULUM_PRESETS.preset(name)
    }

    /// The `"toolbox-demo"` actions: 5 equidistant voltages on `[-3, 3]` (values beyond the
    /// voltage bound act as the bound).
    fn default_actions() -> Vec<f64> {
        PENDULUM_PRESETS.demo_actions().expect("a valid grid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn preset(name: &str) -> Result<Preset, ConfigError> {
        super::super::preset::<Pendulum>(name)
    }

    #[test]
    fn coefficients_match_the_toolbox() {
        let c = PendulumConfig::default().coefficients();
        assert!((c.inertia - 1.9098e-4).abs() < 1e-18);
        assert!((c.mgl - 0.0226611).abs() < 1e-15);
        assert!((c.km - 0.005642105263157895).abs() < 1e-18);
    }

    #[test]
    fn limits_the_voltage_and_saturates_the_velocity() {
        let m = PendulumModel::from_config(PendulumConfig::default()).unwrap();
        assert_eq!(m.step_f64([0.1, 2.0], 30.0), m.step_f64([0.1, 2.0], 3.0));
        assert_eq!(m.reward_f64([0.0, 0.0], -7.0), -9.0);
        let y = m.step_f64([0.0, 15.0 * PI], 3.0);
        assert_eq!(y[1], 15.0 * PI);
        // Hanging down at rest stays (nearly) there without a voltage.
        let y = m.step_f64([-PI, 0.0], 0.0);
        assert!(y[0] == -PI || (y[0] + PI).abs() < 1e-12 || (y[0] - PI).abs() < 1e-12);
    }

    #[test]
    fn presets_have_the_documented_sizes() {
        let demo = preset("toolbox-demo").unwrap();
        assert_eq!((demo.cores[0].len(), demo.cores[1].len()), (41, 21));
        assert_eq!(demo.actions, [-3.0, -1.5, 0.0, 1.5, 3.0]);
        let fine = preset("fine").unwrap();
        assert_eq!((fine.cores[0].len(), fine.cores[1].len()), (73, 91));
        assert_eq!(fine.actions.len(), 15);
        assert!(preset("x").is_err());
    }

    #[test]
    fn rejects_bad_configs() {
        let bad = |f: fn(&mut PendulumConfig)| {
            let mut c = PendulumConfig::default();
            f(&mut c);
            PendulumModel::from_config(c).unwrap_err().to_string()
        };
        assert!(bad(|c| c.integrator = Integrator::Zoh).contains("env.integrator"));
        assert!(bad(|c| c.mass = -1.0).contains("env.mass"));
        assert!(bad(|c| c.max_voltage = f64::INFINITY).contains("env.max_voltage"));
        assert!(
            bad(|c| {
                c.mass = 0.0;
                c.disc_inertia = 1e-320
            })
            .contains("env.disc_inertia")
        );
    }
}
