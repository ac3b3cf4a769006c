//! The DC motor of Busoniu et al. 2010 (section 4.5.3 and ApproxRL's `dc_problem` with the
//! linear model `dc_linmdp` and the LQR reward).
//!
//! A DC motor with inertia `J`, viscous damping `b`, torque constant `K` and rotor resistance
//! `Re`, driven by a voltage `u` (the inductance is neglected):
//! `alpha_ddot = -(b/J + K^2/(Re J)) alpha_dot + K/(Re J) u`. The state is
//! `x = [alpha, alpha_dot]` (rad, rad/s).
//!
//! # Discretisation
//! - [`Integrator::Zoh`] (the toolbox's choice): the exact zero-order hold over `Ts`,
//!   `x' = A x + B u`, in closed form. With `a = b/J + K^2/(Re J)`, `c = K/(Re J)` and
//!   `z = a Ts`: `A = [[1, Ts phi1(z)], [0, e^-z]]`, `B = [c Ts^2 phi2(z), c Ts phi1(z)]` where
//!   `phi1(z) = (1 - e^-z)/z` and `phi2(z) = (e^-z - 1 + z)/z^2` (a series for small `z`, so
//!   no digits cancel). The toolbox gets the same matrices from Octave's `c2d`; they agree
//!   to a few ulps.
//! - [`Integrator::Rk4`]: classical RK4 on the continuous model.
//!
//! # Transition and reward
//! `x' = sat(A x + B u, -maxx, maxx)` elementwise with `maxx = [pi, 16 pi]` (the angle is
//! saturated, not wrapped; `u` is not limited). The reward is evaluated at the current state
//! with the applied `u`: `rho(x, u) = -x' Q x - R u^2`, `Q = diag(5, 0.01)`, `R = 0.01`.
//!
//! # Presets
//! - `"toolbox-demo"`: the configuration of the toolbox demo `qi_demo.m` run by the parity
//!   tests: 21 x 21 equidistant cores on `[-pi, pi] x [-16 pi, 16 pi]` (`symequidgrid`),
//!   5 equidistant actions on `[-10, 10]`, `gamma = 0.98`, `xi = 0.01`.
//! - `"fine"`: the default fuzzy grid of `dc_problem('fuzzy')`: cores `-pi : 5*pi/180 : pi`
//!   and `-16 pi : pi/6 : 16 pi` (73 x 193), actions `[-10, -5, -1, -0.1, 0, 0.1, 1, 5, 10]`,
//!   `gamma = 0.95` (`dc_problem`'s default) and `fuzzyqi`'s default `eps = 0.01`.

use std::f64::consts::PI;

use fuzzyq_core::solver::Precision;
use serde::{Deserialize, Serialize};

use super::octave::{rk4, rk4_step_sizes, sat};
use super::{Benchmark, Classic, Integrator, Preset, RotaryPresets, lqr_reward};
use crate::error::{ConfigError, non_negative, positive, require};
use crate::model::{Dynamics, EnvKind, symmetric};

/// The names of the DC motor's presets.
pub const PRESETS: [&str; 2] = ["toolbox-demo", "fine"];

/// The DC motor's physical parameters, bounds, reward weights and integrator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DcMotorConfig {
    /// Rotor and load inertia `J` (kg m^2), `> 0`.
    pub inertia: f64,
    /// Viscous damping `b` (N m s/rad), `>= 0`.
    pub damping: f64,
    /// Torque constant `K` (N m/A), `> 0`.
    pub torque_constant: f64,
    /// Rotor resistance `Re` (Ohm), `> 0`.
    pub resistance: f64,
    /// Sample time `Ts` (s), `> 0`.
    pub sample_time: f64,
    /// The angle is saturated to `[-max_angle, max_angle]` (rad), `> 0`.
    pub max_angle: f64,
    /// The angular velocity is saturated to `[-max_velocity, max_velocity]` (rad/s), `> 0`.
    pub max_velocity: f64,
    /// The diagonal of the state weight `Q` of the reward, each `>= 0`.
    pub q: [f64; 2],
    /// The action weight `R` of the reward, `>= 0`.
    pub r: f64,
    /// How a sample time is integrated.
    pub integrator: Integrator,
}

impl Default for DcMotorConfig {
    /// The toolbox's values (`dc_problem`): `J = 3.24e-5`, `b = 3e-6`, `K = 0.0536`,
    /// `Re = 9.5`, `Ts = 0.005`, bounds `pi` and `16 pi`, `Q = diag(5, 0.01)`, `R = 0.01`,
    /// exact zero-order hold.
    fn default() -> Self {
        Self {
            inertia: 3.24e-5,
            damping: 3.0e-6,
            torque_constant: 53.6e-3,
            resistance: 9.50,
            sample_time: 0.005,
            max_angle: PI,
            max_velocity: 16.0 * PI,
            q: [5.0, 0.01],
            r: 0.01,
            integrator: Integrator::Zoh,
        }
    }
}

impl DcMotorConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("env.inertia", self.inertia)?;
        non_negative("env.damping", self.damping)?;
        positive("env.torque_constant", self.torque_constant)?;
        positive("env.resistance", self.resistance)?;
        positive("env.sample_time", self.sample_time)?;
        positive("env.max_angle", self.max_angle)?;
        positive("env.max_velocity", self.max_velocity)?;
        non_negative("env.q", self.q[0])?;
        non_negative("env.q", self.q[1])?;
        non_negative("env.r", self.r)?;
        self.integrator.validate("env.integrator")?;
        let (a, c) = self.continuous();
        require!(
            a.is_finite() && c.is_finite() && (a * self.sample_time).is_finite(),
            "env.inertia",
            "the motor's time constant overflows with these parameters",
        );
        Ok(())
    }

    /// `(a, c)` of the continuous model `alpha_ddot = -a alpha_dot + c u`:
    /// `a = b/J + K^2/(Re J)`, `c = K/(Re J)` (evaluated as the toolbox writes them).
    #[must_use]
    pub fn continuous(&self) -> (f64, f64) {
        let (j, b, k, re) = (
            self.inertia,
            self.damping,
            self.torque_constant,
            self.resistance,
        );
        (b / j + (k * k) / (re * j), k / (re * j))
    }
}

/// The DC motor's dynamics (a [`Classic`] benchmark: [`DcMotorModel`] is the model).
#[derive(Clone, Debug)]
pub struct DcMotor {
    config: DcMotorConfig,
    /// The zero-order-hold matrices.
    a: [[f64; 2]; 2],
    b: [f64; 2],
    /// `(a, c)` of the continuous model.
    cont: (f64, f64),
    /// RK4 step sizes (empty for the zero-order hold).
    steps: Vec<f64>,
}

/// The DC motor benchmark: [`DcMotor`] dynamics with a discrete voltage set.
pub type DcMotorModel = Classic<DcMotor>;

/// `phi1(z) = (1 - e^-z) / z` (1 at 0).
fn phi1(z: f64) -> f64 {
    if z == 0.0 { 1.0 } else { -(-z).exp_m1() / z }
}

/// `phi2(z) = (e^-z - 1 + z) / z^2` (1/2 at 0): the series `sum_k (-z)^k / (k+2)!` below 1,
/// where the closed form would cancel digits.
fn phi2(z: f64) -> f64 {
    if z.abs() < 1.0 {
        // Horner from the smallest term: coefficients 1/(k+2)! for k = 0..24.
        let mut coef = [0.0f64; 25];
        let mut f = 2.0;
        for (k, c) in coef.iter_mut().enumerate() {
            *c = 1.0 / f;
            f *= (k + 3) as f64;
        }
        coef.iter().rev().fold(0.0, |p, &c| c - z * p)
    } else {
        ((-z).exp_m1() + z) / (z * z)
    }
}

impl DcMotor {
    /// Builds the dynamics from validated parameters.
    pub fn new(config: DcMotorConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let (a, c) = config.continuous();
        let ts = config.sample_time;
        let z = a * ts;
        let p1 = phi1(z);
        let steps = match config.integrator {
            Integrator::Zoh => Vec::new(),
            Integrator::Rk4 { substeps } => rk4_step_sizes(ts, substeps),
        };
        Ok(Self {
            a: [[1.0, ts * p1], [0.0, (-z).exp()]],
            b: [c * ts * ts * phi2(z), c * ts * p1],
            cont: (a, c),
            steps,
            config,
        })
    }

    /// The parameters.
    #[must_use]
    pub fn config(&self) -> &DcMotorConfig {
        &self.config
    }

    /// The exact zero-order-hold matrices `(A, B)` of `x' = A x + B u` (before saturation),
    /// whatever the integrator.
    #[must_use]
    pub fn zoh_matrices(&self) -> ([[f64; 2]; 2], [f64; 2]) {
        (self.a, self.b)
    }

    /// The successor of `x` under voltage `u`, saturated to the state bounds.
    #[must_use]
    pub fn step_f64(&self, x: [f64; 2], u: f64) -> [f64; 2] {
        let y = if self.steps.is_empty() {
            let (a, b) = (&self.a, &self.b);
            [
                (a[0][0] * x[0] + a[0][1] * x[1]) + b[0] * u,
                (a[1][0] * x[0] + a[1][1] * x[1]) + b[1] * u,
            ]
        } else {
            let (a, c) = self.cont;
            rk4(|y| [y[1], -a * y[1] + c * u], x, &self.steps)
        };
        let c = &self.config;
        [
            sat(y[0], -c.max_angle, c.max_angle),
            sat(y[1], -c.max_velocity, c.max_velocity),
        ]
    }

    /// The reward at the current state `x` under voltage `u`: `-x' Q x - R u^2`.
    #[must_use]
    pub fn reward_f64(&self, x: [f64; 2], u: f64) -> f64 {
        lqr_reward(self.config.q, self.config.r, x, u)
    }
}

/// The DC motor's presets (see the [module docs](self)).
const DCMOTOR_PRESETS: RotaryPresets = RotaryPresets {
    env: EnvKind::Dcmotor,
    demo_cores: [21, 21],
    max_velocity: 16.0 * PI,
    max_voltage: 10.0,
    velocity_step: PI / 6.0,
    fine_actions: || Ok(vec![-10.0, -5.0, -1.0, -0.1, 0.0, 0.1, 1.0, 5.0, 10.0]),
    fine_gamma: 0.95,
};

impl Dynamics for DcMotor {
    fn sample_time(&self) -> f64 {
        self.config.sample_time
    }

    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        symmetric(if dim == 0 {
            self.config.max_angle
        } else {
            self.config.max_velocity
        })
    }

    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next.copy_from_slice(&self.step_f64([x[0], x[1]], u[0]));
    }

    fn reward(&self, x: &[f64], u: &[f64], _precision: Precision) -> f64 {
        self.reward_f64([x[0], x[1]], u[0])
    }
}

impl Benchmark for DcMotor {
    const ENV: EnvKind = EnvKind::Dcmotor;
    const STATE_DIM: usize = 2;
    const ACTION_DIM: usize = 1;
    type Config = DcMotorConfig;

    fn new(config: DcMotorConfig) -> Result<Self, ConfigError> {
        DcMotor::new(config)
    }

    /// See the [module docs](self) for where each value comes from.
    fn preset(name: &str) -> Result<Preset, ConfigError> {
        DCMOTOR_PRESETS.preset(name)
    }

    /// The `"toolbox-demo"` actions: 5 equidistant voltages on `[-10, 10]`.
    fn default_actions() -> Vec<f64> {
        DCMOTOR_PRESETS.demo_actions().expect("a valid grid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fuzzyq_core::Model;

    fn preset(name: &str) -> Result<Preset, ConfigError> {
        super::super::preset::<DcMotor>(name)
    }

    #[test]
    fn zoh_matches_fine_rk4() {
        let zoh = DcMotorModel::from_config(DcMotorConfig::default()).unwrap();
        let rk = DcMotorModel::from_config(DcMotorConfig {
            integrator: Integrator::Rk4 { substeps: 50 },
            ..DcMotorConfig::default()
        })
        .unwrap();
        for (x, u) in [([0.3, -5.0], 7.0), ([-1.0, 20.0], -10.0), ([0.0, 0.0], 0.1)] {
            let (a, b) = (zoh.step_f64(x, u), rk.step_f64(x, u));
            for j in 0..2 {
                assert!(
                    (a[j] - b[j]).abs() <= 1e-12 * (1.0 + a[j].abs()),
                    "{a:?} vs {b:?}"
                );
            }
        }
    }

    #[test]
    fn phi_series_and_closed_form_agree_at_the_switch() {
        for z in [0.5f64, 0.9, 0.999] {
            let closed = ((-z).exp_m1() + z) / (z * z);
            assert!((phi2(z) - closed).abs() <= 4e-15 * closed, "{z}");
        }
        // Continuous across the switch at 1 (the slope is about -0.13).
        assert!((phi2(1.0 - 1e-9) - phi2(1.0 + 1e-9)).abs() < 1e-9);
        assert_eq!(phi2(0.0), 0.5);
        assert_eq!(phi1(0.0), 1.0);
    }

    #[test]
    fn saturates_and_rewards_at_the_current_state() {
        let m = DcMotorModel::from_config(DcMotorConfig::default()).unwrap();
        let y = m.step_f64([PI, 16.0 * PI], 10.0);
        assert_eq!(y, [PI, 16.0 * PI]);
        assert_eq!(m.reward_f64([1.0, 2.0], 3.0), -(5.0 + 0.04) - 0.09);
    }

    #[test]
    fn presets_have_the_documented_sizes() {
        let demo = preset("toolbox-demo").unwrap();
        assert_eq!((demo.cores[0].len(), demo.cores[1].len()), (21, 21));
        assert_eq!(demo.actions, [-10.0, -5.0, 0.0, 5.0, 10.0]);
        let fine = preset("fine").unwrap();
        assert_eq!((fine.cores[0].len(), fine.cores[1].len()), (73, 193));
        assert_eq!(fine.actions.len(), 9);
        assert_eq!(fine.gamma, 0.95);
        assert!(preset("coarse").is_err());
        let m = DcMotorModel::for_preset(DcMotorConfig::default(), &fine).unwrap();
        assert_eq!(Model::<f64>::action_set(&m, 0).n_actions(), 9);
    }

    #[test]
    fn rejects_bad_configs() {
        let bad = |f: fn(&mut DcMotorConfig)| {
            let mut c = DcMotorConfig::default();
            f(&mut c);
            DcMotorModel::from_config(c).unwrap_err().to_string()
        };
        assert!(bad(|c| c.inertia = 0.0).contains("env.inertia"));
        assert!(bad(|c| c.resistance = f64::NAN).contains("env.resistance"));
        assert!(bad(|c| c.q = [-1.0, 0.0]).contains("env.q"));
        assert!(bad(|c| c.integrator = Integrator::Rk4 { substeps: 0 }).contains("env.integrator"));
        assert!(bad(|c| c.inertia = 1e-320).contains("env.inertia"));
        let m = DcMotorModel::from_config(DcMotorConfig::default()).unwrap();
        assert!(m.with_actions(&[]).is_err());
        let toml_text = "inertia = 1e-4\nintegrator = { rk4 = { substeps = 2 } }";
        let c: DcMotorConfig = toml::from_str(toml_text).unwrap();
        assert_eq!(c.inertia, 1e-4);
        assert_eq!(c.resistance, 9.5);
        assert!(toml::from_str::<DcMotorConfig>("mass = 1.0").is_err());
    }
}
