//! The two-link robot arm of Busoniu et al. 2010 (section 4.5.2; ApproxRL's `rarm_problem`
//! and `rarm_mdpstandalone`, "physics as in the FUZZ-IEEE paper").
//!
//! Two rigid links of lengths `l_1`, `l_2`, masses `m_1`, `m_2`, inertias `I_1`, `I_2` about
//! their centres of mass (at `c_1`, `c_2` from the joints) and joint dampings `b_1`, `b_2`
//! move in a **horizontal** plane (gravity does not act) under joint torques
//! `tau = [tau_1, tau_2]`. The state is `x = [alpha_1, alpha_1_dot, alpha_2, alpha_2_dot]`
//! (rad, rad/s; `alpha_2` relative to the first link) and
//! `M(alpha_2) alpha_ddot + C(alpha, alpha_dot) alpha_dot = tau` with
//! `P_1 = m_1 c_1^2 + m_2 l_1^2 + I_1`, `P_2 = m_2 c_2^2 + I_2`, `P_3 = m_2 l_1 c_2`,
//! `M = [[P_1 + P_2 + 2 P_3 cos alpha_2, P_2 + P_3 cos alpha_2], [P_2 + P_3 cos alpha_2, P_2]]`,
//! `C = [[b_1 - P_3 alpha_2_dot sin alpha_2, -P_3 (alpha_1_dot + alpha_2_dot) sin alpha_2],
//!       [P_3 alpha_1_dot sin alpha_2, b_2]]`.
//! Without damping and torque the kinetic energy `alpha_dot' M alpha_dot / 2` is conserved
//! ([`Arm::kinetic_energy`]).
//!
//! # Transition and reward
//! The torques are limited to `|tau_j| <= max_torque[j]` and held over the sample time
//! `Ts = 0.05` s, integrated by classical RK4 with 5 steps (the differences of Octave's range
//! `0 : Ts/5 : Ts`, as the toolbox's fixed-step `ode4` uses them). Then the angles are wrapped
//! into `[-pi, pi)` as `mod(alpha + pi, 2 pi) - pi` and the velocities saturated to
//! `|alpha_j_dot| <= max_velocity[j] = 2 pi` (with `wrap = false`, the angles are saturated to
//! `[-pi, pi]` instead). The reward is evaluated at the current state with the limited
//! torques, `rho(x, tau) = -x' Q x - tau' R tau` with `Q = diag(1, 0.05, 1, 0.05)` and
//! `R = 0`: the goal is the stretched-out arm at rest, `x = 0`. The task is continuing (no
//! terminal states).
//!
//! # Parameters
//! `l = [0.4, 0.4]` m, `m = [1.25, 0.8]` kg, `I_j = m_j l_j^2 / 3` (`[0.0667, 0.0427]`
//! kg m^2), `c = l / 2`, `b = [0.08, 0.02]` kg/s, `max_velocity = [2 pi, 2 pi]` rad/s,
//! `max_torque = [1.5, 1]` N m, `gamma = 0.98`.
//!
//! # Actions
//! One agent with two action components `[tau_1, tau_2]`: the joint action set is the product
//! of a torque set per joint, `tau_1` slowest. A [`Preset`]'s `actions` are the torque
//! **levels** as fractions of each joint's maximum torque (in `[-1, 1]`): the classic levels
//! `[-1, 0, 1]` give `tau_1 in {-1.5, 0, 1.5}`, `tau_2 in {-1, 0, 1}` (9 joint actions).
//!
//! # Presets
//! - `"fine"`: the grid of the original fuzzy Q-iteration experiments, `rarm_problem('fuzzy')`:
//!   angle cores `[-180 -130 -80 -30 -15 -5 0 5 15 30 80 130 180]` degrees, velocity cores
//!   `[-360 -180 -30 0 30 180 360]` deg/s (13 x 7 x 13 x 7 = 8281 cores), levels
//!   `[-1, 0, 1]`, `gamma = 0.98`, `fuzzyqi`'s default `eps = 0.01`.
//! - `"coarse"`: angle cores `[-180 -90 -30 -10 0 10 30 90 180]` degrees and velocity cores
//!   `[-360 -90 -20 0 20 90 360]` deg/s (9 x 7 x 9 x 7 = 3969 cores) with the same levels
//!   and `gamma`, and `xi = 0.1`: for quick runs and tests (our choice, not the book's; like
//!   the book's grid it is denser near the goal, without which the greedy policy stalls
//!   tens of degrees away from it).

use std::f64::consts::PI;

use fuzzyq_core::solver::Precision;
use serde::{Deserialize, Serialize};

use super::octave::{rk4_step_sizes, wrap_angle_floor};
use super::{Benchmark, Classic, Integrator, Preset, validate_actions};
use crate::error::{ConfigError, non_negative, positive, require};
use crate::model::{ActionTable, Dynamics, EnvKind, symmetric};

/// The names of the arm's presets.
pub const PRESETS: [&str; 2] = ["fine", "coarse"];

/// The classic torque levels, as fractions of each joint's maximum torque.
pub const CLASSIC_LEVELS: [f64; 3] = [-1.0, 0.0, 1.0];

/// The most joint actions an arm may have.
pub const MAX_JOINT_ACTIONS: usize = 4096;

/// The two-link arm's physical parameters, limits, reward weights and integrator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArmConfig {
    /// Link lengths `l` (m), each `> 0`.
    pub link_lengths: [f64; 2],
    /// Link masses `m` (kg), each `> 0`.
    pub masses: [f64; 2],
    /// Link inertias `I` about their centres of mass (kg m^2), each `>= 0`.
    pub inertias: [f64; 2],
    /// Distances `c` of the centres of mass from the joints (m), each `>= 0`.
    pub centres_of_mass: [f64; 2],
    /// Joint dampings `b` (kg/s), each `>= 0`.
    pub damping: [f64; 2],
    /// Angular velocity limits (rad/s), each `> 0`.
    pub max_velocity: [f64; 2],
    /// Torque limits (N m), each `> 0`.
    pub max_torque: [f64; 2],
    /// The diagonal of the state weight `Q` of the reward, each `>= 0`.
    pub q: [f64; 4],
    /// The diagonal of the torque weight `R` of the reward, each `>= 0`.
    pub r: [f64; 2],
    /// Sample time `Ts` (s), `> 0`.
    pub sample_time: f64,
    /// Wrap the angles into `[-pi, pi)` (`true`, the toolbox's default) or saturate them.
    pub wrap: bool,
    /// How a sample time is integrated (RK4 only: the dynamics are nonlinear).
    pub integrator: Integrator,
}

impl Default for ArmConfig {
    /// The toolbox's values (see the [module docs](self)).
    fn default() -> Self {
        let (l, m) = ([0.4, 0.4], [1.25, 0.8]);
        Self {
            link_lengths: l,
            masses: m,
            inertias: [m[0] * (l[0] * l[0]) / 3.0, m[1] * (l[1] * l[1]) / 3.0],
            centres_of_mass: [l[0] / 2.0, l[1] / 2.0],
            damping: [0.08, 0.02],
            max_velocity: [2.0 * PI, 2.0 * PI],
            max_torque: [1.5, 1.0],
            q: [1.0, 0.05, 1.0, 0.05],
            r: [0.0, 0.0],
            sample_time: 0.05,
            wrap: true,
            integrator: Integrator::Rk4 { substeps: 5 },
        }
    }
}

impl ArmConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for j in 0..2 {
            positive("env.link_lengths", self.link_lengths[j])?;
            positive("env.masses", self.masses[j])?;
            non_negative("env.inertias", self.inertias[j])?;
            non_negative("env.centres_of_mass", self.centres_of_mass[j])?;
            non_negative("env.damping", self.damping[j])?;
            positive("env.max_velocity", self.max_velocity[j])?;
            positive("env.max_torque", self.max_torque[j])?;
            non_negative("env.r", self.r[j])?;
        }
        for &q in &self.q {
            non_negative("env.q", q)?;
        }
        positive("env.sample_time", self.sample_time)?;
        self.integrator.validate("env.integrator")?;
        require!(
            self.integrator != Integrator::Zoh,
            "env.integrator",
            "the arm is nonlinear: use rk4 (no exact zero-order hold)",
        );
        let [p1, p2, p3] = self.inertia_parameters();
        // det M = P_1 P_2 - P_3^2 cos^2(alpha_2) >= P_1 P_2 - P_3^2 > 0 keeps M invertible.
        let det = p1 * p2 - p3 * p3;
        require!(
            det > 0.0 && det.is_finite() && p1.is_finite(),
            "env.inertias",
            format!(
                "the mass matrix must stay invertible (P1 P2 - P3^2 = {det} with these masses, lengths, centres of mass and inertias)"
            ),
        );
        Ok(())
    }

    /// `[P_1, P_2, P_3]` of the mass matrix (see the [module docs](self)).
    #[must_use]
    pub fn inertia_parameters(&self) -> [f64; 3] {
        let (m, l, c, i) = (
            self.masses,
            self.link_lengths,
            self.centres_of_mass,
            self.inertias,
        );
        [
            m[0] * c[0] * c[0] + m[1] * l[0] * l[0] + i[0],
            m[1] * c[1] * c[1] + i[1],
            m[1] * l[0] * c[1],
        ]
    }
}

/// Degrees to radians as the toolbox writes it (`deg * pi/180`).
fn radians(deg: &[f64]) -> Vec<f64> {
    deg.iter().map(|&d| d * (PI / 180.0)).collect()
}

/// The two-link arm's dynamics (a [`Classic`] benchmark: [`ArmModel`] is the model; one agent
/// with two torque components).
#[derive(Clone, Debug)]
pub struct Arm {
    config: ArmConfig,
    /// `[P_1, P_2, P_3]`.
    p: [f64; 3],
    /// RK4 step sizes.
    steps: Vec<f64>,
}

/// The two-link arm benchmark: [`Arm`] dynamics with a discrete torque set.
pub type ArmModel = Classic<Arm>;

impl Arm {
    /// Builds the dynamics from validated parameters.
    pub fn new(config: ArmConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let substeps = match config.integrator {
            Integrator::Rk4 { substeps } => substeps,
            Integrator::Zoh => unreachable!("refused by validate"),
        };
        Ok(Self {
            p: config.inertia_parameters(),
            steps: rk4_step_sizes(config.sample_time, substeps),
            config,
        })
    }

    /// The joint actions `[tau_1, tau_2]` of the torque sets `tau1` and `tau2` (N m; each 1
    /// to 4096 finite values, at most [`MAX_JOINT_ACTIONS`] pairs; torques beyond the limits
    /// are limited when applied), action-major, `tau_1` slowest.
    pub fn torque_table(
        &self,
        field: &str,
        tau1: &[f64],
        tau2: &[f64],
    ) -> Result<ActionTable, ConfigError> {
        validate_actions(field, tau1)?;
        validate_actions(field, tau2)?;
        require!(
            tau1.len() * tau2.len() <= MAX_JOINT_ACTIONS,
            field,
            format!(
                "{} x {} torques make more than {MAX_JOINT_ACTIONS} joint actions",
                tau1.len(),
                tau2.len()
            ),
        );
        let pairs = tau1
            .iter()
            .flat_map(|&a| tau2.iter().flat_map(move |&b| [a, b]))
            .collect();
        Ok(ActionTable::new(pairs, 2))
    }

    /// The parameters.
    #[must_use]
    pub fn config(&self) -> &ArmConfig {
        &self.config
    }

    /// The torques `tau` limited to `|tau_j| <= max_torque[j]`.
    #[must_use]
    pub fn limit_torques(&self, tau: [f64; 2]) -> [f64; 2] {
        let m = self.config.max_torque;
        [tau[0].clamp(-m[0], m[0]), tau[1].clamp(-m[1], m[1])]
    }

    /// The time derivative of `x` under torques `tau` (applied as given).
    #[must_use]
    pub fn derivative(&self, x: [f64; 4], tau: [f64; 2]) -> [f64; 4] {
        let [p1, p2, p3] = self.p;
        let [b1, b2] = self.config.damping;
        let (w1, w2) = (x[1], x[3]);
        let (s2, c2) = x[2].sin_cos();
        let m11 = p1 + p2 + 2.0 * p3 * c2;
        let m12 = p2 + p3 * c2;
        let m22 = p2;
        let cw1 = (b1 - p3 * w2 * s2) * w1 + (-p3 * (w1 + w2) * s2) * w2;
        let cw2 = (p3 * w1 * s2) * w1 + b2 * w2;
        let (r1, r2) = (tau[0] - cw1, tau[1] - cw2);
        let det = m11 * m22 - m12 * m12;
        [
            w1,
            (m22 * r1 - m12 * r2) / det,
            w2,
            (m11 * r2 - m12 * r1) / det,
        ]
    }

    /// The successor of `x` under torques `tau` (limited, held over the sample time; angles
    /// wrapped or saturated, velocities saturated).
    #[must_use]
    pub fn step_f64(&self, x: [f64; 4], tau: [f64; 2]) -> [f64; 4] {
        let tau = self.limit_torques(tau);
        let mut y = x;
        for &h in &self.steps {
            let add = |c: f64, k: [f64; 4]| core::array::from_fn(|i| y[i] + c * k[i]);
            let k1 = self.derivative(y, tau);
            let k2 = self.derivative(add(0.5 * h, k1), tau);
            let k3 = self.derivative(add(0.5 * h, k2), tau);
            let k4 = self.derivative(add(h, k3), tau);
            let c = h / 6.0;
            for i in 0..4 {
                y[i] += c * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        let c = &self.config;
        for (i, j) in [(0, 0), (2, 1)] {
            y[i] = if c.wrap {
                wrap_angle_floor(y[i])
            } else {
                y[i].clamp(-PI, PI)
            };
            y[i + 1] = y[i + 1].clamp(-c.max_velocity[j], c.max_velocity[j]);
        }
        y
    }

    /// The reward at the current state `x` under torques `tau` (limited):
    /// `-x' Q x - tau' R tau`.
    #[must_use]
    pub fn reward_f64(&self, x: [f64; 4], tau: [f64; 2]) -> f64 {
        let tau = self.limit_torques(tau);
        let (q, r) = (self.config.q, self.config.r);
        let state =
            q[0] * x[0] * x[0] + q[1] * x[1] * x[1] + q[2] * x[2] * x[2] + q[3] * x[3] * x[3];
        -state - (r[0] * tau[0] * tau[0] + r[1] * tau[1] * tau[1])
    }

    /// The kinetic energy `alpha_dot' M(alpha_2) alpha_dot / 2` (J).
    #[must_use]
    pub fn kinetic_energy(&self, x: [f64; 4]) -> f64 {
        let [p1, p2, p3] = self.p;
        let c2 = x[2].cos();
        let (w1, w2) = (x[1], x[3]);
        0.5 * ((p1 + p2 + 2.0 * p3 * c2) * w1 * w1 + 2.0 * (p2 + p3 * c2) * w1 * w2 + p2 * w2 * w2)
    }
}

impl Dynamics for Arm {
    fn sample_time(&self) -> f64 {
        self.config.sample_time
    }

    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        symmetric(match dim {
            1 => self.config.max_velocity[0],
            3 => self.config.max_velocity[1],
            _ => PI,
        })
    }

    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next.copy_from_slice(&self.step_f64([x[0], x[1], x[2], x[3]], [u[0], u[1]]));
    }

    fn reward(&self, x: &[f64], u: &[f64], _precision: Precision) -> f64 {
        self.reward_f64([x[0], x[1], x[2], x[3]], [u[0], u[1]])
    }

    fn reward_depends_on_action(&self) -> bool {
        self.config.r != [0.0, 0.0]
    }
}

impl Benchmark for Arm {
    const ENV: EnvKind = EnvKind::Arm;
    const STATE_DIM: usize = 4;
    const ACTION_DIM: usize = 2;
    type Config = ArmConfig;

    fn new(config: ArmConfig) -> Result<Self, ConfigError> {
        Arm::new(config)
    }

    /// See the [module docs](self) for where each value comes from.
    fn preset(name: &str) -> Result<Preset, ConfigError> {
        let (angles, velocities, xi): (&[f64], &[f64], f64) = match name {
            "fine" => (
                &[
                    -180.0, -130.0, -80.0, -30.0, -15.0, -5.0, 0.0, 5.0, 15.0, 30.0, 80.0, 130.0,
                    180.0,
                ],
                &[-360.0, -180.0, -30.0, 0.0, 30.0, 180.0, 360.0],
                0.01,
            ),
            "coarse" => (
                &[-180.0, -90.0, -30.0, -10.0, 0.0, 10.0, 30.0, 90.0, 180.0],
                &[-360.0, -90.0, -20.0, 0.0, 20.0, 90.0, 360.0],
                0.1,
            ),
            _ => return Err(Self::ENV.unknown_preset(name)),
        };
        let (th, om) = (radians(angles), radians(velocities));
        Ok(Preset::new(
            name,
            vec![th.clone(), om.clone(), th, om],
            CLASSIC_LEVELS.to_vec(),
            0.98,
            xi,
        ))
    }

    /// The classic levels `[-1, 0, 1]` of each joint's maximum torque.
    fn default_actions() -> Vec<f64> {
        CLASSIC_LEVELS.to_vec()
    }

    /// The listed actions are torque **levels**, fractions of each joint's maximum torque in
    /// `[-1, 1]`, combined per joint (`tau_1` slowest).
    fn action_table(&self, field: &str, levels: &[f64]) -> Result<ActionTable, ConfigError> {
        validate_actions(field, levels)?;
        if let Some(l) = levels.iter().find(|l| l.abs() > 1.0) {
            return Err(ConfigError::invalid(
                field,
                format!("torque levels are fractions of the maximum torque in [-1, 1], got {l}"),
            ));
        }
        let [t1, t2] = self.config.max_torque;
        let tau1: Vec<f64> = levels.iter().map(|&l| l * t1).collect();
        let tau2: Vec<f64> = levels.iter().map(|&l| l * t2).collect();
        self.torque_table(field, &tau1, &tau2)
    }
}

#[cfg(test)]
mod tests {
    use std::ops::ControlFlow;

    use fuzzyq_core::solver::{BackupPath, SolverConfig, solve};
    use fuzzyq_core::{Backup, q};

    use super::*;
    use fuzzyq_core::Model;

    fn preset(name: &str) -> Result<Preset, ConfigError> {
        super::super::preset::<Arm>(name)
    }

    fn presets() -> Vec<Preset> {
        super::super::presets::<Arm>()
    }

    fn arm() -> ArmModel {
        ArmModel::from_config(ArmConfig::default()).unwrap()
    }

    #[test]
    fn parameters_and_dynamics_match_hand_computed_values() {
        let m = arm();
        let c = m.config();
        assert!(
            (c.inertias[0] - 0.0666667).abs() < 1e-6 && (c.inertias[1] - 0.0426667).abs() < 1e-6
        );
        // P1 = 1.25 0.04 + 0.8 0.16 + 0.0666.. = 0.2446..., P2 = 0.032 + 0.04266... = 0.07466...,
        // P3 = 0.8 0.4 0.2 = 0.064.
        let [p1, p2, p3] = c.inertia_parameters();
        assert!((p1 - (0.05 + 0.128 + 0.2 / 3.0)).abs() < 1e-15);
        assert!((p2 - (0.032 + 0.128 / 3.0)).abs() < 1e-15);
        assert!((p3 - 0.064).abs() < 1e-15);
        // At rest with alpha_2 = 0: M alpha_ddot = tau.
        let m11 = p1 + p2 + 2.0 * p3;
        let m12 = p2 + p3;
        let det = m11 * p2 - m12 * m12;
        let d = m.derivative([0.3, 0.0, 0.0, 0.0], [1.5, 1.0]);
        assert_eq!((d[0], d[2]), (0.0, 0.0));
        assert!((d[1] - (p2 * 1.5 - m12) / det).abs() < 1e-12);
        assert!((d[3] - (m11 - m12 * 1.5) / det).abs() < 1e-12);
        // Damping alone, alpha_2 = pi/2 (cos 0, sin 1), no torque:
        // C w = [b1 w1 - P3 w2 w1 - P3 (w1 + w2) w2, P3 w1^2 + b2 w2].
        let (w1, w2) = (1.0, -2.0);
        let x = [0.0, w1, PI / 2.0, w2];
        let cw = [
            0.08 * w1 - p3 * w2 * w1 - p3 * (w1 + w2) * w2,
            p3 * w1 * w1 + 0.02 * w2,
        ];
        let mm = [[p1 + p2, p2], [p2, p2]];
        let dd = m.derivative(x, [0.0, 0.0]);
        let lhs = [
            mm[0][0] * dd[1] + mm[0][1] * dd[3],
            mm[1][0] * dd[1] + mm[1][1] * dd[3],
        ];
        assert!((lhs[0] + cw[0]).abs() < 1e-12 && (lhs[1] + cw[1]).abs() < 1e-12);
    }

    /// One sample time against an independent integration (2000 RK4 steps).
    #[test]
    fn step_matches_a_fine_integration() {
        let m = arm();
        let fine = ArmModel::from_config(ArmConfig {
            integrator: Integrator::Rk4 { substeps: 2000 },
            ..ArmConfig::default()
        })
        .unwrap();
        for x in [[0.5, 1.0, -1.0, -2.0], [-2.0, -3.0, 2.5, 4.0], [0.0; 4]] {
            for tau in [[1.5, -1.0], [0.0, 1.0], [-1.5, 0.0]] {
                let (a, b) = (m.step_f64(x, tau), fine.step_f64(x, tau));
                for i in 0..4 {
                    assert!((a[i] - b[i]).abs() < 1e-6, "{x:?} {tau:?}: {a:?} vs {b:?}");
                }
            }
        }
    }

    #[test]
    fn energy_is_conserved_without_damping_and_torque() {
        let m = ArmModel::from_config(ArmConfig {
            damping: [0.0, 0.0],
            max_velocity: [100.0, 100.0],
            ..ArmConfig::default()
        })
        .unwrap();
        let mut x = [0.2, 2.0, -0.7, -3.0];
        let e0 = m.kinetic_energy(x);
        for _ in 0..100 {
            x = m.step_f64(x, [0.0, 0.0]);
            assert!((m.kinetic_energy(x) - e0).abs() < 1e-7 * e0, "{x:?}");
        }
        // Damping dissipates it.
        let d = arm();
        let x = [0.2, 2.0, -0.7, -3.0];
        assert!(d.kinetic_energy(d.step_f64(x, [0.0, 0.0])) < d.kinetic_energy(x));
    }

    #[test]
    fn dynamics_are_odd_and_rest_is_an_equilibrium() {
        let m = arm();
        assert_eq!(m.step_f64([0.0; 4], [0.0, 0.0]), [0.0; 4]);
        // At rest anywhere (wrapping rounds the angle by an ulp or two).
        let y = m.step_f64([0.7, 0.0, -1.2, 0.0], [0.0, 0.0]);
        assert!(
            (y[0] - 0.7).abs() < 1e-15 && (y[2] + 1.2).abs() < 1e-15,
            "{y:?}"
        );
        assert_eq!((y[1], y[3]), (0.0, 0.0));
        for (x, tau) in [
            ([0.5, 1.0, -1.0, -2.0], [1.5, -1.0]),
            ([-0.3, 2.0, 0.4, 1.0], [0.0, 1.0]),
        ] {
            let a = m.step_f64(x, tau);
            let b = m.step_f64(x.map(|v| -v), [-tau[0], -tau[1]]);
            for i in 0..4 {
                assert!((a[i] + b[i]).abs() < 1e-14, "{a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn wraps_angles_and_limits_velocities_and_torques() {
        let m = arm();
        // Near pi and turning fast: the angle comes out on the other side.
        let y = m.step_f64([PI - 0.01, 2.0 * PI, 0.0, 0.0], [0.0, 0.0]);
        assert!(y[0] < -2.5 && y[0] >= -PI, "{y:?}");
        for a in [-7.0, -PI, -1.0, 0.0, 3.0, PI, 10.0] {
            let w = super::super::octave::wrap_angle_floor(a);
            assert!((-PI..PI + 1e-12).contains(&w), "{a} -> {w}");
            assert!(((a - w) / (2.0 * PI) - ((a - w) / (2.0 * PI)).round()).abs() < 1e-12);
        }
        assert_eq!(super::super::octave::wrap_angle_floor(PI), -PI);
        assert!(super::super::octave::wrap_angle_floor(f64::NAN).is_nan());
        // Velocities saturate at 2 pi.
        let y = m.step_f64([0.0, 2.0 * PI, 0.0, -2.0 * PI], [1.5, -1.0]);
        assert!(y[1] <= 2.0 * PI && y[3] >= -2.0 * PI);
        assert!(y[1] == 2.0 * PI || y[3] == -2.0 * PI, "{y:?}");
        // Torques beyond the limits act as the limits.
        let x = [0.1, 0.2, 0.3, 0.4];
        assert_eq!(m.step_f64(x, [10.0, -10.0]), m.step_f64(x, [1.5, -1.0]));
        // Without wrapping the angle saturates at pi.
        let s = ArmModel::from_config(ArmConfig {
            wrap: false,
            ..ArmConfig::default()
        })
        .unwrap();
        assert_eq!(
            s.step_f64([PI - 0.01, 2.0 * PI, 0.0, 0.0], [0.0, 0.0])[0],
            PI
        );
    }

    #[test]
    fn rewards_at_the_current_state() {
        let m = arm();
        assert_eq!(m.reward_f64([0.0; 4], [1.5, 1.0]), 0.0);
        assert_eq!(
            m.reward_f64([1.0, 2.0, -1.0, -2.0], [0.0, 0.0]),
            -(1.0 + 0.2 + 1.0 + 0.2)
        );
        assert!(!Model::<f64>::reward_depends_on_action(&m));
        let r = ArmModel::from_config(ArmConfig {
            r: [1.0, 2.0],
            ..ArmConfig::default()
        })
        .unwrap();
        assert!(Model::<f32>::reward_depends_on_action(&r));
        // Torques are limited before they are charged.
        assert_eq!(r.reward_f64([0.0; 4], [3.0, -1.0]), -(2.25 + 2.0));
        assert_eq!(
            Model::<f64>::reward(&r, &[0.0; 4], &[3.0, -1.0]),
            -(2.25 + 2.0)
        );
        // The bound of the toolbox's maxr: Q-weighted squared limits.
        let worst = m.reward_f64([PI, 2.0 * PI, PI, 2.0 * PI], [0.0, 0.0]);
        assert!((worst + 2.0 * PI * PI * (1.0 + 0.2)).abs() < 1e-12);
        // Bad lengths give NaN, never a panic.
        assert!(Model::<f64>::reward(&m, &[0.0; 3], &[0.0, 0.0]).is_nan());
        let mut n = [0.0f32; 4];
        Model::<f32>::step(&m, &[0.0; 4], &[0.0], &mut n);
        assert!(n.iter().all(|v| v.is_nan()));
    }

    #[test]
    fn actions_are_the_product_of_joint_torques() {
        let m = arm();
        let set = Model::<f64>::action_set(&m, 0);
        assert_eq!((set.n_actions(), set.dim()), (9, 2));
        assert_eq!(set.action(0), [-1.5, -1.0]);
        assert_eq!(set.action(1), [-1.5, 0.0]);
        assert_eq!(set.action(5), [0.0, 1.0]);
        assert_eq!(set.action(8), [1.5, 1.0]);
        let t = m.torque_table("actions", &[-1.0, 1.0], &[0.5]).unwrap();
        assert_eq!(t.values(), [-1.0, 0.5, 1.0, 0.5]);
        assert!(arm().with_actions(&[2.0]).is_err());
        assert!(m.torque_table("actions", &[0.0; 100], &[0.0; 100]).is_err());
    }

    #[test]
    fn presets_have_the_documented_sizes() {
        let fine = preset("fine").unwrap();
        assert_eq!(fine.n_cores(), 13 * 7 * 13 * 7);
        assert_eq!((fine.cores[0][0], fine.cores[0][12]), (-PI, PI));
        assert_eq!(fine.cores[0][6], 0.0);
        assert!((fine.cores[1][0] + 2.0 * PI).abs() < 1e-15);
        assert_eq!(fine.cores[0], fine.cores[2]);
        assert_eq!((fine.gamma, fine.xi), (0.98, 0.01));
        assert_eq!(preset("coarse").unwrap().n_cores(), 9 * 7 * 9 * 7);
        assert_eq!(presets().len(), 2);
        assert!(preset("vertical").is_err());
        let m = ArmModel::for_preset(ArmConfig::default(), &fine).unwrap();
        assert_eq!(Model::<f64>::action_set(&m, 0).n_actions(), 9);
        let e = ArmModel::for_preset(
            ArmConfig::default(),
            &Preset {
                actions: vec![-2.0, 2.0],
                ..fine.clone()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("preset.actions"), "{e}");
        let e = ArmModel::for_preset(
            ArmConfig::default(),
            &Preset {
                cores: fine.cores[..2].to_vec(),
                ..fine
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("preset.cores"), "{e}");
    }

    #[test]
    fn rejects_bad_configs() {
        let bad = |f: fn(&mut ArmConfig)| {
            let mut c = ArmConfig::default();
            f(&mut c);
            ArmModel::from_config(c).unwrap_err().to_string()
        };
        assert!(bad(|c| c.link_lengths[1] = 0.0).contains("env.link_lengths"));
        assert!(bad(|c| c.masses[0] = f64::NAN).contains("env.masses"));
        assert!(bad(|c| c.inertias[0] = -1.0).contains("env.inertias"));
        assert!(bad(|c| c.damping[1] = -0.1).contains("env.damping"));
        assert!(bad(|c| c.max_velocity[0] = 0.0).contains("env.max_velocity"));
        assert!(bad(|c| c.max_torque[1] = f64::INFINITY).contains("env.max_torque"));
        assert!(bad(|c| c.q[3] = -1.0).contains("env.q"));
        assert!(bad(|c| c.r[0] = f64::NAN).contains("env.r"));
        assert!(bad(|c| c.sample_time = 0.0).contains("env.sample_time"));
        assert!(bad(|c| c.integrator = Integrator::Zoh).contains("env.integrator"));
        // Point masses at the link ends with a massless first link: M becomes singular at
        // alpha_2 = 0 (P1 P2 = P3^2).
        assert!(
            bad(|c| {
                c.inertias = [0.0, 0.0];
                c.centres_of_mass = [0.0, 0.4];
                c.masses = [1e-300, 1.0];
            })
            .contains("env.inertias")
        );
        let c: ArmConfig = toml::from_str("sample_time = 0.1\nwrap = false").unwrap();
        assert_eq!((c.sample_time, c.wrap, c.masses), (0.1, false, [1.25, 0.8]));
        assert!(toml::from_str::<ArmConfig>("gravity = 9.81").is_err());
    }

    /// Fuzzy Q-iteration on the coarse preset converges (block and generic paths agree) and
    /// its greedy policy brings the arm close to the stretched-out rest position.
    #[test]
    fn coarse_fuzzy_q_iteration_moves_the_arm_to_its_goal() {
        let p = preset("coarse").unwrap();
        let m = ArmModel::for_preset(ArmConfig::default(), &p).unwrap();
        let grid = p.grid::<f64>().unwrap();
        let s = solve(&m, &grid, &p.solver_config(), |_| ControlFlow::Continue(())).unwrap();
        assert!(s.converged(), "{} sweeps", s.sweeps.len());
        assert_eq!(s.path, BackupPath::Block);
        let generic = solve(
            &m,
            &grid,
            &SolverConfig {
                path: BackupPath::Generic,
                max_sweeps: 3,
                ..p.solver_config()
            },
            |_| ControlFlow::Continue(()),
        )
        .unwrap();
        let block3 = solve(
            &m,
            &grid,
            &SolverConfig {
                max_sweeps: 3,
                ..p.solver_config()
            },
            |_| ControlFlow::Continue(()),
        )
        .unwrap();
        let d = block3
            .v
            .iter()
            .zip(&generic.v)
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        assert!(d < 1e-12, "{d}");

        let op = fuzzyq_core::solver::Operator::new(
            &m,
            grid.view(),
            Backup::discounted(p.gamma),
            BackupPath::Auto,
        )
        .unwrap();
        let cost = |x: [f64; 4]| -m.reward_f64(x, [0.0, 0.0]);
        let mut qx = [0.0; 9];
        for x0 in [
            [-2.0, 0.0, 1.5, 0.0],
            [1.0, 0.0, -2.5, 0.0],
            [PI, 0.0, 0.0, 0.0],
            [0.5, 1.0, 0.5, -1.0],
        ] {
            let mut x = x0;
            for _ in 0..100 {
                op.q_values(&s.v, &x, &mut qx).unwrap();
                let a = q::argmax(&qx).unwrap();
                let u = crate::model::F64Model::actions(&m).action(a);
                x = m.step_f64(x, [u[0], u[1]]);
            }
            assert!(cost(x) < 0.05 * cost(x0), "{x0:?} -> {x:?}");
        }
    }
}
