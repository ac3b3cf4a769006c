//! Model-free fuzzy Q-learning ([`crate::learn::fql`]) on the Khepera robots of the rapier plant
//! ([`KheperaWorld`]): the paper's future work (a model-free variant, stochastic dynamics) on
//! its robot task (sections 3.2-3.3).
//!
//! Fuzzy Q-iteration ([`crate::train`]) learns the Khepera task on the joint pose with the
//! kinematic model. Here each robot learns from what it senses instead, as the paper's robots
//! do: no model, the plant's contacts and (optionally noisy) sonars, and the additive,
//! decentralised layout of [`crate::learn::fql`] (`docs/design.md`, section 2).
//!
//! # Observations ([`observation`], [`observation_cores`])
//! Robot `i` observes `E = S + 2` continuous values: its `S` sonar readings (5 by default, in
//! the order of `sonar_angles_deg`; noisy when the configuration's noise is on), then its
//! distance to the goal (the origin) and the relative angle to the goal from
//! [`goal_polar`] (radians in `(-pi, pi]`, positive counter-clockwise). The fuzzy partition
//! mirrors the paper's quantisation (section 3.2) with one core per level, placed so that every
//! quantisation threshold lies strictly between two neighbouring cores:
//!
//! - each sonar: 3 cores `[sonar_min_range, (t_0 + t_1) / 2, sonar_max_range]` (near, medium,
//!   far) for the thresholds `sonar_levels = [t_0, t_1]` (default `[0.25, 0.75, 2.0]` m;
//!   [`sonar_level`] of core `k` is `k`);
//! - goal distance: 9 cores, `0`, the midpoints of the levels 1-7 of `distance_edges`
//!   `e_0 < ... < e_7`, and `e_7 + (e_7 - e_6) / 2` for the open level 8 (default
//!   `[0, 0.35, 0.75, 1.25, 1.75, 2.5, 3.5, 5, 7]` m; [`distance_level`] of core `k` is `k`);
//! - relative angle: 9 cores evenly over `[-pi, pi]` (every 45 degrees). The 9 angle levels of
//!   [`angle_level`] are 40 degrees wide with boundaries at +-20, +-60, +-100 and +-140
//!   degrees, each strictly between two cores. The partition is not periodic: the cores at
//!   `-pi` and `pi` both mean "goal straight behind".
//!
//! Per robot that is `3^5 * 9 * 9 = 19683` cores and, with the four actions, `78732`
//! parameters in the additive layout; every robot has the same partition ([`feature_space`]).
//!
//! # The environment ([`KheperaEnv`])
//! - [`reset`](Environment::reset) draws a start as [`random_starts`] does (one start, from a
//!   seed drawn from the learner's generator) and rebuilds the plant with a second drawn seed,
//!   so that the sonar and wheel noise of an episode also come from the learner's generator:
//!   the environment is deterministic for the learner's seed, and the evaluation episodes of
//!   [`fql::learn`] (their own generator) do not change what is learned.
//! - [`step`](Environment::step) holds the wheel speeds of each robot's action
//!   ([`KheperaConfig::wheels`]) for one control period on the plant, then reads the sonars.
//! - Reward: the paper's joint reward of the new joint pose, [`KheperaModel::reward_f64`]
//!   (`goal_reward` when `||(s_1, s_2)|| < goal_radius`, `-collision_penalty` when two robots
//!   overlap or a robot touches a wall or an obstacle, 0 otherwise). In addition, a step in which
//!   a contact started on the plant (a robot touched a wall, an obstacle or the other robot:
//!   [`StepContacts`] not empty) pays `-collision_penalty` in place of that reward: the plant
//!   resolves contacts, so the robots rarely overlap, and a bump is what the penalty is for.
//! - Termination: the episode ends (terminal, no bootstrap) when the joint pose enters the
//!   reward region; [`success`](Environment::success) then reports true unless a contact
//!   started in that last step. The learner truncates at [`FqlConfig::max_steps`].
//! - Optional [`Shaping`] (off by default and off in [`train_fql`]): a potential-based term
//!   for diagnosis, never part of the paper's reward.
//!
//! # Acting
//! A learned Q-function acts through `run::policy::AdditivePolicy` (each robot the argmax of
//! its own term at its own observation, lowest index on ties) on the robot plant, and is
//! measured exactly as a fuzzy Q-iteration policy is (`run::evaluate`): the paper's 8-D state
//! with the measured velocities, rewards `rho(x_k)` of the state before each action, the same
//! metrics and success rule (final 8-D state in the region, no collision during the run).
//! Unlike a learning episode, a rollout does not stop at the region.
//!
//! ```no_run
//! use std::ops::ControlFlow;
//!
//! use fuzzyq_sim::learn::fql::EpisodeRecord;
//! use fuzzyq_sim::learn::tasks::khepera::{default_fql_config, train_fql};
//! use fuzzyq_sim::model::khepera::KheperaConfig;
//!
//! let config = KheperaConfig::default();
//! let fql = default_fql_config();
//! let outcome = train_fql(&config, &fql, |_: &EpisodeRecord| ControlFlow::Continue(()))?;
//! println!("{} episodes", outcome.curve.len());
//! # Ok::<(), fuzzyq_sim::SimError>(())
//! ```

use std::f64::consts::PI;

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, require};
use crate::learn::fql::{
    self, AdditiveQ, Environment, FeatureSpace, FqlConfig, FqlOutcome, Transition,
};
use crate::model::khepera::random_starts;
use crate::model::khepera::{KheperaConfig, KheperaModel, N_ACTIONS, goal_polar};
#[cfg(doc)]
use crate::model::khepera::{angle_level, distance_level, sonar_level};
use crate::world::KheperaWorld;
#[cfg(doc)]
use crate::world::StepContacts;

/// The goal of the task: the origin.
pub const GOAL: [f64; 2] = [0.0, 0.0];

/// The sonar cores `[sonar_min_range, (t_0 + t_1) / 2, sonar_max_range]` (near, medium, far).
#[must_use]
pub fn sonar_cores(config: &KheperaConfig) -> Vec<f64> {
    let [t0, t1] = config.sonar_levels;
    vec![
        config.sonar_min_range,
        0.5 * (t0 + t1),
        config.sonar_max_range,
    ]
}

/// The 9 goal-distance cores: 0, the midpoints of levels 1-7 of `distance_edges`, and
/// `e_7 + (e_7 - e_6) / 2` for level 8.
#[must_use]
pub fn distance_cores(config: &KheperaConfig) -> Vec<f64> {
    let e = &config.distance_edges;
    let mut cores = Vec::with_capacity(9);
    cores.push(0.0);
    cores.extend(e.windows(2).map(|w| 0.5 * (w[0] + w[1])));
    cores.push(e[7] + 0.5 * (e[7] - e[6]));
    cores
}

/// The 9 relative-angle cores, evenly over `[-pi, pi]` (every 45 degrees).
#[must_use]
pub fn angle_cores() -> Vec<f64> {
    (0..9).map(|k| -PI + f64::from(k) * PI / 4.0).collect()
}

/// The fuzzy partition of one robot's observation: [`sonar_cores`] for each sonar, then
/// [`distance_cores`] and [`angle_cores`] (see the [module docs](self)).
#[must_use]
pub fn observation_cores(config: &KheperaConfig) -> Vec<Vec<f64>> {
    let mut cores = vec![sonar_cores(config); config.sonar_angles_deg.len()];
    cores.push(distance_cores(config));
    cores.push(angle_cores());
    cores
}

/// The feature space of the task: [`observation_cores`] for every robot. Fails (naming the
/// field) on an invalid configuration, or when the cores are not increasing (the medium sonar
/// core `(t_0 + t_1) / 2` must lie strictly inside `(sonar_min_range, sonar_max_range)`) or
/// there are more than 14 sonars (16 observation dimensions at most).
pub fn feature_space(config: &KheperaConfig) -> Result<FeatureSpace, SimError> {
    config.validate()?;
    let [t0, t1] = config.sonar_levels;
    let mid = 0.5 * (t0 + t1);
    require!(
        config.sonar_min_range < mid && mid < config.sonar_max_range,
        "env.sonar_levels",
        format!(
            "the medium sonar core {mid} must lie strictly between sonar_min_range = {} and sonar_max_range = {}",
            config.sonar_min_range, config.sonar_max_range
        ),
    );
    let cores = observation_cores(config);
    FeatureSpace::new(vec![cores; config.agents])
}

/// Writes robot observation `[sonar_0, ..., sonar_{S-1}, distance, angle]` for the robot at
/// `pose` with sonar readings `sonar` into `out` (length `sonar.len() + 2`).
///
/// # Panics
/// If `out.len() != sonar.len() + 2`.
pub fn observation(pose: [f64; 3], sonar: &[f64], out: &mut [f64]) {
    let s = sonar.len();
    assert_eq!(out.len(), s + 2, "observation length");
    out[..s].copy_from_slice(sonar);
    let (d, a) = goal_polar(pose, GOAL);
    out[s] = d;
    out[s + 1] = a;
}

/// Optional potential-based reward shaping (Ng, Harada and Russell 1999), for diagnosis only:
/// the paper's reward is unshaped and [`train_fql`] never shapes.
///
/// With the potential `Phi(x) = -weight * sum_i d_i(x)` (`d_i` the distance of robot `i` to
/// the goal), a step `x -> x'` pays `gamma * Phi(x') - Phi(x)` on top of the reward, with
/// `Phi = 0` at a terminal state. This leaves the optimal policies of the discounted task
/// unchanged when `gamma` is the learner's discount; `gamma = 1` pays the plain progress
/// `weight * (sum_i d_i(x) - sum_i d_i(x'))` (not policy-invariant, but a denser signal).
///
/// Measured with [`default_fql_config`] (seeds 0-2): the invariant form (`gamma = 0.96`) still
/// never reaches the region, because with `phi = 0` it pays `(1 - gamma) * weight * d` per step
/// for staying far; the progress form (`gamma = 1`, `weight = 1`) reaches it in about half of
/// the learning episodes and is how the learner was checked to work on this task.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shaping {
    /// Weight of the potential (reward per metre), `>= 0`.
    pub weight: f64,
    /// The discount of the potential, in `[0, 1]` (the learner's `gamma` for invariance).
    pub gamma: f64,
}

/// The Khepera task on the rapier plant as an episodic [`Environment`] (see the
/// [module docs](self)): 2 robots (`config.agents`), [`N_ACTIONS`] actions each, observations
/// of [`observation`].
#[derive(Debug)]
pub struct KheperaEnv {
    config: KheperaConfig,
    model: KheperaModel,
    world: KheperaWorld,
    n_sonar: usize,
    obs: Vec<Vec<f64>>,
    sonar: Vec<f64>,
    wheels: Vec<[f64; 2]>,
    pose_flat: Vec<f64>,
    in_region: bool,
    last_contact: bool,
    shaping: Option<Shaping>,
    error: Option<SimError>,
}

fn flatten(poses: &[[f64; 3]], out: &mut Vec<f64>) {
    out.clear();
    out.extend(poses.iter().flatten());
}

impl KheperaEnv {
    /// The environment of `config` (validated), its robots placed at the first start of
    /// `random_starts(config, 1, 0)` on a plant seeded with 0 until the first reset.
    pub fn new(config: &KheperaConfig) -> Result<Self, SimError> {
        let model = KheperaModel::new(config.clone())?;
        let world = KheperaWorld::new(config, 0)?;
        let n_sonar = config.sonar_angles_deg.len();
        let mut env = Self {
            config: config.clone(),
            model,
            world,
            n_sonar,
            obs: vec![vec![0.0; n_sonar + 2]; config.agents],
            sonar: vec![0.0; n_sonar],
            wheels: vec![[0.0; 2]; config.agents],
            pose_flat: Vec::with_capacity(3 * config.agents),
            in_region: false,
            last_contact: false,
            shaping: None,
            error: None,
        };
        let start = random_starts(config, 1, 0)?;
        env.reset_to(&start[0], 0)?;
        Ok(env)
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &KheperaConfig {
        &self.config
    }

    /// The plant.
    #[must_use]
    pub fn world(&self) -> &KheperaWorld {
        &self.world
    }

    /// Switches the diagnostic [`Shaping`] on (`Some`) or off (`None`, the default). Fails on a
    /// negative or non-finite weight or a discount outside `[0, 1]`.
    pub fn set_shaping(&mut self, shaping: Option<Shaping>) -> Result<(), ConfigError> {
        if let Some(s) = shaping {
            require!(
                s.weight >= 0.0 && s.weight.is_finite(),
                "shaping.weight",
                format!("must be a finite number >= 0, got {}", s.weight),
            );
            require!(
                (0.0..=1.0).contains(&s.gamma),
                "shaping.gamma",
                format!("must be in [0, 1], got {}", s.gamma),
            );
        }
        self.shaping = shaping;
        Ok(())
    }

    /// The shaping in use (`None` by default).
    #[must_use]
    pub fn shaping(&self) -> Option<Shaping> {
        self.shaping
    }

    /// Starts an episode at `poses` (one `[x, y, heading]` per robot) on a fresh plant seeded
    /// with `plant_seed` (the seed of its sonar and wheel noise).
    pub fn reset_to(&mut self, poses: &[[f64; 3]], plant_seed: u64) -> Result<(), SimError> {
        let mut world = KheperaWorld::new(&self.config, plant_seed)?;
        world.reset(poses)?;
        self.world = world;
        self.last_contact = false;
        self.sense()?;
        flatten(self.world.poses(), &mut self.pose_flat);
        self.in_region = self.model.in_region(&self.pose_flat);
        Ok(())
    }

    /// Reads every robot's sonars (noisy if configured) and refreshes the observations.
    fn sense(&mut self) -> Result<(), SimError> {
        for i in 0..self.config.agents {
            self.world.sonar(i, &mut self.sonar)?;
            let pose = self.world.poses()[i];
            observation(pose, &self.sonar, &mut self.obs[i]);
        }
        Ok(())
    }

    /// Whether the current joint pose is in the reward region.
    #[must_use]
    pub fn in_region(&self) -> bool {
        self.in_region
    }

    /// The first plant error met by [`reset`](Environment::reset) or
    /// [`step`](Environment::step), if any (taking it clears it). Those methods cannot
    /// return errors; after one, every observation is `NaN`, so that [`fql::learn`] stops.
    pub fn take_error(&mut self) -> Option<SimError> {
        self.error.take()
    }

    fn fail(&mut self, e: SimError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        for o in &mut self.obs {
            o.fill(f64::NAN);
        }
    }

    fn potential(&self) -> f64 {
        let s = self.shaping.map_or(0.0, |s| s.weight);
        -s * self
            .world
            .poses()
            .iter()
            .map(|p| p[0].hypot(p[1]))
            .sum::<f64>()
    }

    fn try_step(&mut self, actions: &[usize]) -> Result<Transition, SimError> {
        let phi_before = self.potential();
        for (w, &a) in self.wheels.iter_mut().zip(actions) {
            *w = self.config.wheels(a);
        }
        let contacts = self.world.step(&self.wheels)?;
        self.sense()?;
        flatten(self.world.poses(), &mut self.pose_flat);
        self.last_contact = !contacts.is_empty();
        self.in_region = self.model.in_region(&self.pose_flat);
        let mut reward = if self.last_contact {
            -self.config.collision_penalty
        } else {
            self.model.reward_f64(&self.pose_flat)
        };
        if let Some(s) = self.shaping {
            let phi_after = if self.in_region {
                0.0
            } else {
                self.potential()
            };
            reward += s.gamma * phi_after - phi_before;
        }
        Ok(Transition {
            reward,
            terminal: self.in_region,
        })
    }
}

impl Environment for KheperaEnv {
    fn n_agents(&self) -> usize {
        self.config.agents
    }

    fn n_actions(&self, _agent: usize) -> usize {
        N_ACTIONS
    }

    fn obs_dim(&self, _agent: usize) -> usize {
        self.n_sonar + 2
    }

    fn reset(&mut self, rng: &mut Pcg64Mcg) {
        let start_seed: u64 = rng.random();
        let plant_seed: u64 = rng.random();
        let result = random_starts(&self.config, 1, start_seed)
            .and_then(|s| self.reset_to(&s[0], plant_seed));
        if let Err(e) = result {
            self.fail(e);
        }
    }

    fn observe(&self, agent: usize, out: &mut [f64]) {
        out.copy_from_slice(&self.obs[agent]);
    }

    fn step(&mut self, actions: &[usize], _rng: &mut Pcg64Mcg) -> Transition {
        match self.try_step(actions) {
            Ok(t) => t,
            Err(e) => {
                self.fail(e);
                Transition {
                    reward: 0.0,
                    terminal: true,
                }
            }
        }
    }

    fn success(&self) -> bool {
        self.in_region && !self.last_contact
    }

    /// The goal reward or the collision penalty, whichever is larger; none with the
    /// diagnostic [`Shaping`] on.
    fn reward_bound(&self) -> Option<f64> {
        let c = self.model.config();
        self.shaping
            .is_none()
            .then(|| c.goal_reward.abs().max(c.collision_penalty.abs()))
    }
}

/// The default learning settings of [`train_fql`] on the Khepera task:
///
/// - the corrected update (semi-gradient Q-learning), the paper's discount `gamma = 0.96`;
/// - 2000 episodes of at most 400 control periods (160 s; a robot crosses the 12 m arena in
///   about 80 s at the forward speed of 0.15 m/s);
/// - epsilon-greedy exploration decaying linearly from 1.0 (pure exploration: with `phi = 0`
///   the greedy action is "forward") to 0.05 over the first 1500 episodes;
/// - step size `alpha_k = 0.2 / (1 + k / 1000)` (from 0.2 down to 0.067 at the end);
/// - seed 0; the windowed convergence test of eq 27 with `xi = 1e-3` over 50 episodes is
///   reported but does not stop the run;
/// - a greedy evaluation of 20 episodes every 100 episodes.
///
/// A run takes about 30 s (one core, release build; about 35 us per learning step, rapier's 8
/// substeps and the sonar rays included).
#[must_use]
pub fn default_fql_config() -> FqlConfig {
    FqlConfig {
        episodes: 2000,
        max_steps: 400,
        alpha: 0.2,
        alpha_decay: 1000.0,
        epsilon: 1.0,
        epsilon_decay_episodes: 1500,
        stop_at_convergence: false,
        eval_every: 100,
        eval_episodes: 20,
        ..FqlConfig::default()
    }
}

/// Learns the Khepera task by fuzzy Q-learning on [`KheperaEnv`] with the paper's reward
/// (no shaping) and the partition of [`feature_space`]. `progress` sees every episode's record
/// and may stop the run (see [`fql::learn`]). Errors: an invalid configuration or a plant
/// failure.
pub fn train_fql(
    config: &KheperaConfig,
    fql: &FqlConfig,
    progress: impl crate::learn::fql::Observer,
) -> Result<FqlOutcome, SimError> {
    let mut env = KheperaEnv::new(config)?;
    train_fql_on(&mut env, fql, progress)
}

/// [`train_fql`] on a given environment (for instance one with [`Shaping`]).
pub fn train_fql_on(
    env: &mut KheperaEnv,
    fql: &FqlConfig,
    progress: impl crate::learn::fql::Observer,
) -> Result<FqlOutcome, SimError> {
    let features = feature_space(env.config())?;
    let result = fql::learn(env, &features, fql, progress);
    // A plant failure shows up as NaN observations; report the plant's own error.
    match (result, env.take_error()) {
        (_, Some(e)) => Err(e),
        (r, None) => r,
    }
}

/// Checks that `q` was learned on the feature space and actions of `config`.
pub fn check_q(q: &AdditiveQ, config: &KheperaConfig) -> Result<(), SimError> {
    let features = feature_space(config)?;
    require!(
        q.features() == &features,
        "q",
        "its feature space is not the one of this configuration (observation_cores per robot)",
    );
    require!(
        q.actions().iter().all(|&m| m == N_ACTIONS),
        "q",
        format!(
            "has action counts {:?}, the robots have {N_ACTIONS} actions",
            q.actions()
        ),
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::ops::ControlFlow;

    use super::*;
    use crate::learn::fql::EpisodeRecord;
    use crate::model::khepera::{angle_level, distance_level, sonar_level};

    /// `t` lies strictly between two neighbouring cores.
    fn between(cores: &[f64], t: f64) -> bool {
        cores.windows(2).any(|w| w[0] < t && t < w[1])
    }

    #[test]
    fn observation_cores_are_partitions_mirroring_the_quantisation() {
        let config = KheperaConfig::default();
        let cores = observation_cores(&config);
        assert_eq!(cores.len(), 7);
        for c in &cores[..5] {
            assert_eq!(c, &vec![0.25, 0.75, 2.0]);
        }
        assert_eq!(cores[5].len(), 9);
        assert_eq!(cores[6].len(), 9);
        let features = feature_space(&config).unwrap();
        assert_eq!(features.n_agents(), 2);
        for i in 0..2 {
            assert_eq!(features.n_cores(i), Some(19683));
            assert_eq!(features.obs_dim(i), Some(7));
            assert_eq!(features.cores()[i], cores);
        }
        assert_eq!(features.n_params(&[N_ACTIONS; 2]).unwrap(), 2 * 19683 * 4);

        // Sonar: core k reads level k; both thresholds sit between cores.
        for (k, &c) in cores[0].iter().enumerate() {
            assert_eq!(usize::from(sonar_level(c, config.sonar_levels)), k);
        }
        for t in config.sonar_levels {
            assert!(between(&cores[0], t), "sonar threshold {t}");
        }
        // Distance: core k is in level k; every edge sits between cores.
        for (k, &c) in cores[5].iter().enumerate() {
            assert_eq!(
                usize::from(distance_level(c, &config.distance_edges)),
                k,
                "{c}"
            );
        }
        for e in config.distance_edges {
            assert!(between(&cores[5], e), "distance edge {e}");
        }
        // Angle: evenly over [-pi, pi]; every level boundary sits between cores.
        assert!((cores[6][0] + PI).abs() < 1e-15 && (cores[6][8] - PI).abs() < 1e-15);
        assert!(
            cores[6]
                .windows(2)
                .all(|w| (w[1] - w[0] - PI / 4.0).abs() < 1e-12)
        );
        let step = 2.0 * PI / 9.0;
        for b in 1..9 {
            let t = -PI + f64::from(b) * step;
            assert_eq!(angle_level(t - 1e-9), (b - 1) as u8);
            assert_eq!(angle_level(t + 1e-9), b as u8);
            assert!(between(&cores[6], t), "angle boundary {}", t.to_degrees());
        }

        // Memberships of a partition: they sum to 1 and a core value is fully its own core.
        let grid = features.grid(0).unwrap();
        let x = [0.3, 0.75, 1.9, 2.0, 0.6, 2.2, -0.4];
        let a = grid.active(&x).unwrap();
        let mut sum = 0.0;
        a.for_each(|_, w| sum += w);
        assert!((sum - 1.0).abs() < 1e-12);

        // A medium sonar core outside the sonar range is refused.
        let bad = KheperaConfig {
            sonar_levels: [2.5, 3.0],
            ..KheperaConfig::default()
        };
        assert!(
            feature_space(&bad)
                .unwrap_err()
                .to_string()
                .contains("env.sonar_levels")
        );
    }

    /// Runs `episodes` short episodes with actions drawn from `rng`; returns every
    /// observation, reward and terminal flag in order.
    fn scripted(seed: u64, noise: bool) -> Vec<f64> {
        let mut config = KheperaConfig::default();
        if noise {
            config.noise.sonar_std = 0.05;
            config.noise.wheel_std = 0.1;
        }
        let mut env = KheperaEnv::new(&config).unwrap();
        let mut rng = <Pcg64Mcg as rand::SeedableRng>::seed_from_u64(seed);
        let mut out = Vec::new();
        let mut o = [0.0; 7];
        for _ in 0..3 {
            env.reset(&mut rng);
            for _ in 0..25 {
                for i in 0..2 {
                    env.observe(i, &mut o);
                    out.extend_from_slice(&o);
                }
                let actions = [rng.random_range(0..4), rng.random_range(0..4)];
                let t = env.step(&actions, &mut rng);
                out.push(t.reward);
                out.push(f64::from(u8::from(t.terminal)));
            }
        }
        assert!(env.take_error().is_none());
        out
    }

    #[test]
    fn the_environment_is_deterministic_for_a_seed() {
        for noise in [false, true] {
            let a = scripted(3, noise);
            let b = scripted(3, noise);
            assert_eq!(a.len(), 3 * 25 * 16);
            assert!(a.iter().all(|v| v.is_finite()));
            assert_eq!(a, b, "noise {noise}");
            assert_ne!(a, scripted(4, noise), "another seed, other starts");
        }
        // The observation is what it claims to be: sonars in range, then distance and angle.
        let config = KheperaConfig::default();
        let mut env = KheperaEnv::new(&config).unwrap();
        let mut rng = <Pcg64Mcg as rand::SeedableRng>::seed_from_u64(1);
        env.reset(&mut rng);
        let mut o = [0.0; 7];
        env.observe(1, &mut o);
        let pose = env.world().poses()[1];
        assert!(o[..5].iter().all(|s| (0.25..=2.0).contains(s)));
        assert!((o[5] - pose[0].hypot(pose[1])).abs() < 1e-12);
        assert_eq!(o[6], goal_polar(pose, GOAL).1);
    }

    #[test]
    fn reward_is_the_joint_reward_and_the_region_is_terminal() {
        let config = KheperaConfig::default();
        let mut env = KheperaEnv::new(&config).unwrap();
        let mut rng = <Pcg64Mcg as rand::SeedableRng>::seed_from_u64(0);
        // Both robots 0.1 m from the origin on opposite sides, at rest: standing still keeps
        // them in the region (reward 5, terminal, success). Driving forward from just outside
        // the region, facing the origin, reaches it; standing still there gets nothing.
        let inside = [[0.1, 0.0, 0.0], [-0.1, 0.0, PI]];
        let outside = [[0.16, 0.0, PI], [-0.16, 0.0, 0.0]];
        for (start, action, reward) in [
            (inside, [3, 3], 5.0),
            (outside, [0, 0], 5.0),
            (outside, [3, 3], 0.0),
        ] {
            env.reset_to(&start, 0).unwrap();
            assert_eq!(env.in_region(), start == inside);
            let t = env.step(&action, &mut rng);
            let terminal = reward > 0.0;
            assert_eq!(t, Transition { reward, terminal }, "{start:?} {action:?}");
            assert_eq!(env.success(), terminal);
        }
        // Facing each other 0.2 m apart (centres), driving forward: they bump (contact).
        env.reset_to(&[[1.0, 1.0, 0.0], [1.2, 1.0, PI]], 0).unwrap();
        let t = env.step(&[0, 0], &mut rng);
        assert_eq!(t.reward, -config.collision_penalty);
        assert!(!t.terminal && !env.success());
        // Shaping is off by default; switched on, it pays for approaching.
        assert_eq!(env.shaping(), None);
        env.set_shaping(Some(Shaping {
            weight: 1.0,
            gamma: 0.96,
        }))
        .unwrap();
        env.reset_to(&[[3.0, 0.0, PI], [-3.0, 0.0, 0.0]], 0)
            .unwrap();
        let t = env.step(&[0, 0], &mut rng);
        let moved = 2.0 * config.forward_speed * config.sample_time;
        let expected = 0.96 * -(6.0 - moved) + 6.0;
        assert!(
            (t.reward - expected).abs() < 1e-9,
            "{} vs {expected}",
            t.reward
        );
        assert!(
            env.set_shaping(Some(Shaping {
                weight: -1.0,
                gamma: 0.9
            }))
            .is_err()
        );
        assert!(
            env.set_shaping(Some(Shaping {
                weight: 1.0,
                gamma: 1.5
            }))
            .is_err()
        );
    }

    fn smoke_config() -> FqlConfig {
        FqlConfig {
            episodes: 20,
            max_steps: 50,
            eval_every: 10,
            eval_episodes: 2,
            ..default_fql_config()
        }
    }

    #[test]
    fn a_short_training_run_gives_a_curve_and_finite_parameters() {
        let config = KheperaConfig::default();
        let fql = smoke_config();
        let mut seen = 0;
        let out = train_fql(&config, &fql, |_: &EpisodeRecord| {
            seen += 1;
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(out.curve.len(), 20);
        assert_eq!(seen, 20);
        assert!(out.curve.iter().all(|r| r.steps >= 1 && r.steps <= 50));
        assert_eq!(out.curve[0].epsilon, 1.0);
        assert!(out.curve[9].eval_success_rate.is_some());
        assert!(out.q.params().iter().flatten().all(|v| v.is_finite()));
        assert_eq!(out.q.params()[0].len(), 19683 * 4);
        // Deterministic: the same seed learns the same parameters.
        let again =
            train_fql(&config, &fql, |_: &EpisodeRecord| ControlFlow::Continue(())).unwrap();
        assert_eq!(again.q, out.q);
        // (Debug text: `param_change` is NaN before a full window, and NaN != NaN.)
        assert_eq!(format!("{:?}", again.curve), format!("{:?}", out.curve));
        // The paper's reward is sparse: 20 short episodes from random starts never reach the
        // region, so only contacts could move phi. With shaping the parameters must move.
        let mut env = KheperaEnv::new(&config).unwrap();
        env.set_shaping(Some(Shaping {
            weight: 1.0,
            gamma: 1.0,
        }))
        .unwrap();
        let shaped = train_fql_on(
            &mut env,
            &fql,
            |_: &EpisodeRecord| ControlFlow::Continue(()),
        )
        .unwrap();
        assert_eq!(shaped.curve.len(), 20);
        assert!(shaped.q.params().iter().flatten().all(|v| v.is_finite()));
        assert!(shaped.q.params().iter().flatten().any(|v| *v != 0.0));
        assert!(shaped.curve.iter().all(|r| r.max_abs_td > 0.0));
    }
}
