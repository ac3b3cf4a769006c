//! Khepera IV robots (paper sections 3.2-3.3): differential-drive discs with five sonars.
//!
//! # Robot
//! A Khepera IV is a disc of about 140 mm with two wheels 105 mm apart and a top speed of
//! about 0.8 m/s. Its pose is `(x, y, heading)`; wheel speeds `(v_l, v_r)` held for the
//! sample time `T` move it along an exact circular arc ([`drive`]): forward speed
//! `v = (v_l + v_r) / 2`, turn rate `w = (v_r - v_l) / wheel_base`.
//!
//! # Actions (the paper's four)
//! Forward (both wheels at `forward_speed`), turn clockwise, turn counter-clockwise (wheels
//! at `-+turn_speed`: a rotation in place) and stand still. An action is the vector of the two
//! wheel speeds, so the interpolated policy (eq 22) averages wheel speeds.
//!
//! # State and reward
//! The learning state is the joint pose `[x_1, y_1, h_1, x_2, y_2, h_2]` (headings in radians,
//! `[-pi, pi]`). The paper's 8-D state `[s_1x, s_1y, v_1x, v_1y, s_2x, s_2y, v_2x, v_2y]`
//! (eq 42) adds each robot's velocity, which for a kinematic robot is set by the action. The
//! reward is `goal_reward` when the positions satisfy `||(s_1, s_2)|| < goal_radius`: for
//! robots at rest (zero velocity) this is eq 42 exactly, and it keeps the reward a function
//! of the state alone, which keeps the solver's backup cheap; rollouts judge arrival on the
//! full 8-D state with the measured velocities. A joint state in which two robots overlap, or a robot touches a wall or an obstacle, pays
//! `-collision_penalty`.
//! Two 140 mm robots cannot both sit at the origin: the region `||x|| < 0.2` holds, for
//! instance, both robots 0.1 m from the origin on opposite sides.
//!
//! # Sonars and observations
//! Five ultrasonic sonars at `sonar_angles_deg` from the heading, each a cone of
//! `rays_per_sonar` rays over `sonar_cone_deg`, measure from the robot's rim to the nearest
//! wall, obstacle or other robot, clamped to `[sonar_min_range, sonar_max_range]` (no echo
//! reads the maximum). The paper's observations quantise each sonar to 3 levels (0 near, 1
//! medium, 2 far) and the distance and relative angle to the goal to 9 levels each (0-8):
//! [`sonar_level`], [`distance_level`], [`angle_level`].

use std::f64::consts::PI;

use fuzzyq_core::solver::Precision;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, non_negative, positive, require};
use crate::model::arena::{Arena, norm_clearly_below};
use crate::model::{ActionTable, BlockSpec, Dynamics, F64Model};

/// Optional sensor and actuator noise (the paper's future work: stochastic dynamics).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// Standard deviation of the Gaussian noise added to every sonar reading (m).
    #[serde(default)]
    pub sonar_std: f64,
    /// Probability that a sonar reading is lost (reads the maximum range).
    #[serde(default)]
    pub sonar_dropout: f64,
    /// Standard deviation of the multiplicative Gaussian noise on each wheel speed (fraction).
    #[serde(default)]
    pub wheel_std: f64,
}

impl NoiseConfig {
    /// Whether any noise is switched on.
    #[must_use]
    pub fn is_active(&self) -> bool {
        self.sonar_std > 0.0 || self.sonar_dropout > 0.0 || self.wheel_std > 0.0
    }
}

/// The Khepera task's parameters (the `[env]` table with `kind = "khepera"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KheperaConfig {
    /// Number of robots (1 to 4).
    pub agents: usize,
    /// Robot radius (m).
    pub radius: f64,
    /// Distance between the wheels (m).
    pub wheel_base: f64,
    /// Top wheel speed of the robot (m/s); action speeds may not exceed it.
    pub max_wheel_speed: f64,
    /// Wheel speed of the forward action (m/s).
    pub forward_speed: f64,
    /// Wheel speed of the turn actions, one wheel forward and one backward (m/s).
    pub turn_speed: f64,
    /// Control period `T` (s).
    pub sample_time: f64,
    /// The reward region `||x|| < goal_radius` over the paper's 8-D state (eq 42).
    pub goal_radius: f64,
    /// Reward inside the region.
    pub goal_reward: f64,
    /// Reward lost in a joint state where two robots overlap (`>= 0`).
    pub collision_penalty: f64,
    /// Sonar directions relative to the heading (degrees, counter-clockwise).
    pub sonar_angles_deg: Vec<f64>,
    /// Opening of each sonar's cone (degrees).
    pub sonar_cone_deg: f64,
    /// Rays cast per sonar, spread evenly over the cone.
    pub rays_per_sonar: usize,
    /// Shortest distance a sonar reports (m).
    pub sonar_min_range: f64,
    /// Longest distance a sonar reports; no echo reads this (m).
    pub sonar_max_range: f64,
    /// Readings below the first threshold are "near" (0), below the second "medium" (1),
    /// others "far" (2) (m).
    pub sonar_levels: [f64; 2],
    /// Upper edges of the goal-distance levels 0-7; beyond the last is level 8 (m).
    pub distance_edges: [f64; 8],
    /// The arena.
    #[serde(default)]
    pub arena: Arena,
    /// Optional noise in the physics plant.
    #[serde(default)]
    pub noise: NoiseConfig,
}

impl Default for KheperaConfig {
    fn default() -> Self {
        Self {
            agents: 2,
            radius: 0.07,
            wheel_base: 0.105,
            max_wheel_speed: 0.8,
            forward_speed: 0.15,
            turn_speed: 0.05,
            sample_time: 0.4,
            goal_radius: 0.2,
            goal_reward: 5.0,
            collision_penalty: 5.0,
            sonar_angles_deg: vec![-90.0, -45.0, 0.0, 45.0, 90.0],
            sonar_cone_deg: 20.0,
            rays_per_sonar: 3,
            sonar_min_range: 0.25,
            sonar_max_range: 2.0,
            sonar_levels: [0.5, 1.0],
            distance_edges: [0.2, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0],
            arena: Arena::default(),
            noise: NoiseConfig::default(),
        }
    }
}

/// The largest number of robots.
pub const MAX_ROBOTS: usize = 4;

/// Number of actions per robot.
pub const N_ACTIONS: usize = 4;

/// Names of the four actions, in index order.
pub const ACTION_NAMES: [&str; N_ACTIONS] = ["forward", "turn_cw", "turn_ccw", "stand"];

impl KheperaConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        require!(
            (1..=MAX_ROBOTS).contains(&self.agents),
            "env.agents",
            format!("must be between 1 and {MAX_ROBOTS}, got {}", self.agents),
        );
        positive("env.radius", self.radius)?;
        positive("env.wheel_base", self.wheel_base)?;
        positive("env.max_wheel_speed", self.max_wheel_speed)?;
        crate::error::single_precision("env.max_wheel_speed", &[self.max_wheel_speed])?;
        positive("env.forward_speed", self.forward_speed)?;
        positive("env.turn_speed", self.turn_speed)?;
        positive("env.sample_time", self.sample_time)?;
        positive("env.goal_radius", self.goal_radius)?;
        for (f, v) in [
            ("env.forward_speed", self.forward_speed),
            ("env.turn_speed", self.turn_speed),
        ] {
            require!(
                v <= self.max_wheel_speed,
                f,
                format!(
                    "{v} m/s exceeds max_wheel_speed = {} m/s",
                    self.max_wheel_speed
                ),
            );
        }
        require!(
            self.goal_reward.is_finite(),
            "env.goal_reward",
            "must be a finite number",
        );
        non_negative("env.collision_penalty", self.collision_penalty)?;
        require!(
            !self.sonar_angles_deg.is_empty()
                && self.sonar_angles_deg.len() <= 16
                && self.sonar_angles_deg.iter().all(|a| a.is_finite()),
            "env.sonar_angles_deg",
            "needs 1 to 16 finite angles",
        );
        require!(
            self.sonar_cone_deg.is_finite() && (0.0..180.0).contains(&self.sonar_cone_deg),
            "env.sonar_cone_deg",
            format!("must be in [0, 180), got {}", self.sonar_cone_deg),
        );
        require!(
            (1..=32).contains(&self.rays_per_sonar),
            "env.rays_per_sonar",
            format!("must be between 1 and 32, got {}", self.rays_per_sonar),
        );
        positive("env.sonar_min_range", self.sonar_min_range)?;
        require!(
            self.sonar_max_range.is_finite() && self.sonar_max_range > self.sonar_min_range,
            "env.sonar_max_range",
            format!(
                "must exceed sonar_min_range = {}, got {}",
                self.sonar_min_range, self.sonar_max_range
            ),
        );
        require!(
            self.sonar_levels[0].is_finite()
                && self.sonar_levels[0] < self.sonar_levels[1]
                && self.sonar_levels[1].is_finite(),
            "env.sonar_levels",
            format!(
                "must be two increasing thresholds, got {:?}",
                self.sonar_levels
            ),
        );
        require!(
            self.distance_edges
                .iter()
                .all(|e| e.is_finite() && *e > 0.0)
                && self.distance_edges.windows(2).all(|w| w[0] < w[1]),
            "env.distance_edges",
            format!(
                "must be 8 increasing positive distances, got {:?}",
                self.distance_edges
            ),
        );
        for (f, v) in [
            ("env.noise.sonar_std", self.noise.sonar_std),
            ("env.noise.wheel_std", self.noise.wheel_std),
        ] {
            non_negative(f, v)?;
        }
        require!(
            (0.0..=1.0).contains(&self.noise.sonar_dropout),
            "env.noise.sonar_dropout",
            format!("must be a probability, got {}", self.noise.sonar_dropout),
        );
        self.arena.validate()?;
        let lo = self.arena.x[0].max(self.arena.y[0]);
        let hi = self.arena.x[1].min(self.arena.y[1]);
        require!(
            hi - lo > 4.0 * self.radius,
            "env.arena",
            "is too small for the robots",
        );
        Ok(())
    }

    /// Wheel speeds `(v_l, v_r)` of action `a` (see [`ACTION_NAMES`]).
    #[must_use]
    pub fn wheels(&self, a: usize) -> [f64; 2] {
        match a {
            0 => [self.forward_speed, self.forward_speed],
            1 => [self.turn_speed, -self.turn_speed],
            2 => [-self.turn_speed, self.turn_speed],
            _ => [0.0, 0.0],
        }
    }

    /// Length of the learning state, `3 n`.
    #[must_use]
    pub fn state_dim(&self) -> usize {
        3 * self.agents
    }
}

/// Wraps a heading to `(-pi, pi]`.
#[must_use]
pub fn wrap_heading(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI { w + 2.0 * PI } else { w }
}

/// The pose after holding wheel speeds `wheels = (v_l, v_r)` for `dt` seconds from `pose`:
/// the exact arc of a differential drive with wheel base `base` (heading wrapped to
/// `(-pi, pi]`).
#[must_use]
pub fn drive(pose: [f64; 3], wheels: [f64; 2], base: f64, dt: f64) -> [f64; 3] {
    let v = 0.5 * (wheels[0] + wheels[1]);
    let w = (wheels[1] - wheels[0]) / base;
    let h = pose[2];
    let dh = w * dt;
    let (dx, dy) = if dh.abs() < 1e-9 {
        // Straight line, with the second-order term of the arc for continuity.
        let hm = h + 0.5 * dh;
        (v * dt * hm.cos(), v * dt * hm.sin())
    } else {
        let r = v / w;
        (
            r * ((h + dh).sin() - h.sin()),
            -r * ((h + dh).cos() - h.cos()),
        )
    };
    [pose[0] + dx, pose[1] + dy, wrap_heading(h + dh)]
}

/// Linear velocity `(v_x, v_y)` of a robot with heading `h` driven by `wheels`.
#[must_use]
pub fn velocity(h: f64, wheels: [f64; 2]) -> [f64; 2] {
    let v = 0.5 * (wheels[0] + wheels[1]);
    [v * h.cos(), v * h.sin()]
}

/// Quantised sonar reading: 0 near, 1 medium, 2 far.
#[must_use]
pub fn sonar_level(reading: f64, levels: [f64; 2]) -> u8 {
    if reading < levels[0] {
        0
    } else if reading < levels[1] {
        1
    } else {
        2
    }
}

/// Quantised distance to the goal, 0 (closest) to 8: the number of `edges` at or below `d`.
#[must_use]
pub fn distance_level(d: f64, edges: &[f64; 8]) -> u8 {
    edges.iter().filter(|&&e| d >= e).count() as u8
}

/// Quantised relative angle to the goal, 0 to 8: level `4` is straight ahead (within
/// +-20 degrees), levels below turn clockwise (negative angles), above counter-clockwise; each
/// level spans 40 degrees.
#[must_use]
pub fn angle_level(rel: f64) -> u8 {
    let a = wrap_heading(rel);
    let step = 2.0 * PI / 9.0;
    (((a + PI) / step).floor() as i64).clamp(0, 8) as u8
}

/// Distance and relative angle from `pose` to the goal at `goal`.
#[must_use]
pub fn goal_polar(pose: [f64; 3], goal: [f64; 2]) -> (f64, f64) {
    let dx = goal[0] - pose[0];
    let dy = goal[1] - pose[1];
    (dx.hypot(dy), wrap_heading(dy.atan2(dx) - pose[2]))
}

/// Whether two robots of radius `r` at the given positions overlap.
#[must_use]
pub fn robots_overlap(a: [f64; 2], b: [f64; 2], r: f64) -> bool {
    let d = [a[0] - b[0], a[1] - b[1]];
    norm_clearly_below(d[0], d[1], 2.0 * r).unwrap_or_else(|| d[0].hypot(d[1]) < 2.0 * r)
}

/// The Khepera model for fuzzy Q-iteration: exact kinematics of every robot in the arena
/// (a move that would touch a wall or an obstacle leaves the robot where it was), one
/// dynamics block per robot, and the reward of the [module docs](self).
///
/// Robot-robot contacts are not part of the transition (they would couple the blocks); the
/// reward's collision penalty keeps the joint policy apart, and the physics plant
/// ([`crate::world::KheperaWorld`]) resolves contacts for real and counts them.
#[derive(Clone, Debug)]
pub struct KheperaModel {
    config: KheperaConfig,
    actions: ActionTable,
    blocks: Vec<BlockSpec>,
}

impl KheperaModel {
    /// Builds the model from a validated configuration.
    pub fn new(config: KheperaConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let actions = (0..N_ACTIONS).flat_map(|a| config.wheels(a)).collect();
        let blocks = (0..config.agents)
            .map(|i| BlockSpec {
                state_dims: vec![3 * i, 3 * i + 1, 3 * i + 2],
                action_components: vec![2 * i, 2 * i + 1],
            })
            .collect();
        Ok(Self {
            actions: ActionTable::new(actions, 2),
            blocks,
            config,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &KheperaConfig {
        &self.config
    }

    /// One robot's move: the arc, or no move if the arc would touch the arena.
    #[must_use]
    pub fn move_robot(&self, pose: [f64; 3], wheels: [f64; 2]) -> [f64; 3] {
        let c = &self.config;
        let next = drive(pose, wheels, c.wheel_base, c.sample_time);
        // Check the end point and two intermediate points of the arc: a step is at most
        // `max_wheel_speed * sample_time` long.
        let blocked = [0.5, 1.0].iter().any(|&f| {
            let p = if f == 1.0 {
                next
            } else {
                drive(pose, wheels, c.wheel_base, f * c.sample_time)
            };
            c.arena.disc_collides([p[0], p[1]], c.radius)
        });
        if blocked && !c.arena.disc_collides([pose[0], pose[1]], c.radius) {
            [pose[0], pose[1], next[2]]
        } else {
            next
        }
    }

    /// The joint transition in `f64`.
    pub fn step_f64(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        for i in 0..self.config.agents {
            let p = self.move_robot(
                [x[3 * i], x[3 * i + 1], x[3 * i + 2]],
                [u[2 * i], u[2 * i + 1]],
            );
            next[3 * i..3 * i + 3].copy_from_slice(&p);
        }
    }

    /// The paper's 8-D state (positions and velocities per robot) at pose state `x` under
    /// joint wheel speeds `u`.
    #[must_use]
    pub fn paper_state(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(4 * self.config.agents);
        for i in 0..self.config.agents {
            let v = velocity(x[3 * i + 2], [u[2 * i], u[2 * i + 1]]);
            out.extend_from_slice(&[x[3 * i], x[3 * i + 1], v[0], v[1]]);
        }
        out
    }

    /// Whether the joint pose `x` is in the reward region: positions within `goal_radius`
    /// (eq 42 for robots at rest), no two robots overlapping, none touching the arena (where
    /// [`reward_f64`](Self::reward_f64) pays the goal reward).
    #[must_use]
    pub fn in_region(&self, x: &[f64]) -> bool {
        let sq: f64 = x.chunks_exact(3).map(|p| p[0] * p[0] + p[1] * p[1]).sum();
        sq.sqrt() < self.config.goal_radius && !self.any_overlap(x) && !self.any_touches_arena(x)
    }

    /// Whether the paper's 8-D state `[s_1x, s_1y, v_1x, v_1y, ...]` is in the reward region:
    /// `||x|| < goal_radius` with the velocities (eq 42), no overlap, nothing touching the arena.
    #[must_use]
    pub fn in_region_paper(&self, paper_x: &[f64]) -> bool {
        let n = self.config.agents;
        let mut pose = [0.0f64; 3 * MAX_ROBOTS];
        for i in 0..n {
            pose[3 * i] = paper_x[4 * i];
            pose[3 * i + 1] = paper_x[4 * i + 1];
        }
        let pose = &pose[..3 * n];
        paper_x.iter().map(|v| v * v).sum::<f64>().sqrt() < self.config.goal_radius
            && !self.any_overlap(pose)
            && !self.any_touches_arena(pose)
    }

    /// Whether a robot at pose state `x` touches a wall or an obstacle.
    #[must_use]
    pub fn any_touches_arena(&self, x: &[f64]) -> bool {
        (0..self.config.agents).any(|i| {
            self.config
                .arena
                .disc_collides([x[3 * i], x[3 * i + 1]], self.config.radius)
        })
    }

    /// Whether two robots overlap at pose state `x`.
    #[must_use]
    pub fn any_overlap(&self, x: &[f64]) -> bool {
        let n = self.config.agents;
        (0..n).any(|i| {
            (i + 1..n).any(|j| {
                robots_overlap(
                    [x[3 * i], x[3 * i + 1]],
                    [x[3 * j], x[3 * j + 1]],
                    self.config.radius,
                )
            })
        })
    }

    /// The reward in `f64` (it depends on the poses only; see the [module docs](self)).
    #[must_use]
    pub fn reward_f64(&self, x: &[f64]) -> f64 {
        if self.any_overlap(x) || self.any_touches_arena(x) {
            return -self.config.collision_penalty;
        }
        let sq: f64 = (0..self.config.agents)
            .map(|i| x[3 * i] * x[3 * i] + x[3 * i + 1] * x[3 * i + 1])
            .sum();
        if sq.sqrt() < self.config.goal_radius {
            self.config.goal_reward
        } else {
            0.0
        }
    }
}

/// Poses from the paper's 8-D state (velocities must be zero: robots start at rest) and
/// headings in degrees.
pub fn poses_from_paper(
    config: &KheperaConfig,
    x0: &[f64],
    headings_deg: &[f64],
) -> Result<Vec<[f64; 3]>, SimError> {
    let n = config.agents;
    require!(
        x0.len() == 4 * n,
        "x0",
        format!(
            "needs {} values ([s_x, s_y, v_x, v_y] per robot), got {}",
            4 * n,
            x0.len()
        ),
    );
    require!(
        headings_deg.len() == n,
        "headings",
        format!(
            "needs {n} values (one per robot), got {}",
            headings_deg.len()
        ),
    );
    if let Some(v) = x0.iter().find(|v| !v.is_finite()) {
        return Err(ConfigError::invalid("x0", format!("must be finite, got {v}")).into());
    }
    if let Some(h) = headings_deg.iter().find(|v| !v.is_finite()) {
        return Err(ConfigError::invalid("headings", format!("must be finite, got {h}")).into());
    }
    (0..n)
        .map(|i| {
            require!(
                x0[4 * i + 2] == 0.0 && x0[4 * i + 3] == 0.0,
                "x0",
                format!("robot {} must start at rest (zero velocity)", i + 1),
            );
            Ok([
                x0[4 * i],
                x0[4 * i + 1],
                wrap_heading(headings_deg[i].to_radians()),
            ])
        })
        .collect()
}

/// `count` random starts in the arena, drawn from `seed`: positions uniform at least 0.5 m
/// inside the walls and 0.3 m clear of every obstacle, robots at least 0.5 m apart, headings
/// uniform.
pub fn random_starts(
    config: &KheperaConfig,
    count: usize,
    seed: u64,
) -> Result<Vec<Vec<[f64; 3]>>, SimError> {
    let a = &config.arena;
    let margin = 0.5;
    let (x0, x1) = (a.x[0] + margin, a.x[1] - margin);
    let (y0, y1) = (a.y[0] + margin, a.y[1] - margin);
    if x0 >= x1 || y0 >= y1 {
        return Err(ConfigError::invalid("arena", "too small for random starts").into());
    }
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let mut poses: Vec<[f64; 3]> = Vec::with_capacity(config.agents);
        let mut tries = 0usize;
        while poses.len() < config.agents {
            tries += 1;
            require!(
                tries <= 100_000,
                "arena",
                "no room for random starts clear of the obstacles",
            );
            let p = [
                rng.random_range(x0..x1),
                rng.random_range(y0..y1),
                rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
            ];
            let clear = !a.disc_collides([p[0], p[1]], config.radius + 0.3)
                && poses
                    .iter()
                    .all(|q| (q[0] - p[0]).hypot(q[1] - p[1]) >= 0.5);
            if clear {
                poses.push(p);
            }
        }
        out.push(poses);
    }
    Ok(out)
}

impl Dynamics for KheperaModel {
    fn sample_time(&self) -> f64 {
        self.config.sample_time
    }

    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        let a = &self.config.arena;
        match dim % 3 {
            0 => (a.x[0], a.x[1]),
            1 => (a.y[0], a.y[1]),
            _ => (-PI, PI),
        }
    }

    fn is_periodic(&self, dim: usize) -> bool {
        dim % 3 == 2
    }

    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.step_f64(x, u, next);
    }

    fn reward(&self, x: &[f64], _u: &[f64], _precision: Precision) -> f64 {
        self.reward_f64(x)
    }

    fn reward_depends_on_action(&self) -> bool {
        false
    }

    /// The positions only: not the headings (`x[3 i + 2]`).
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        dim % 3 != 2
    }

    fn is_goal(&self, x: &[f64]) -> bool {
        self.in_region(x)
    }
}

impl F64Model for KheperaModel {
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
}

crate::model::impl_model!(KheperaModel);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drive_is_exact() {
        // Straight ahead.
        let p = drive([1.0, 2.0, 0.0], [0.2, 0.2], 0.105, 0.5);
        assert!((p[0] - 1.1).abs() < 1e-15 && (p[1] - 2.0).abs() < 1e-15 && p[2] == 0.0);
        // In place: a quarter turn counter-clockwise.
        let w = 0.105 * PI / 2.0 / 2.0; // (v_r - v_l) / base * dt = pi/2 with dt = 1
        let p = drive([0.0, 0.0, 0.0], [-w, w], 0.105, 1.0);
        assert!(p[0].abs() < 1e-15 && p[1].abs() < 1e-15);
        assert!((p[2] - PI / 2.0).abs() < 1e-12);
        // An arc: half a circle of radius r ends 2r to the left.
        let (vl, vr) = (0.1, 0.3);
        let w = (vr - vl) / 0.105;
        let r = 0.5 * (vl + vr) / w;
        let p = drive([0.0, 0.0, 0.0], [vl, vr], 0.105, PI / w);
        assert!(
            p[0].abs() < 1e-12 && (p[1] - 2.0 * r).abs() < 1e-12,
            "{p:?}"
        );
        // Composition: two half steps equal one step.
        let a = drive([0.3, -0.2, 1.0], [0.1, 0.25], 0.105, 0.4);
        let h = drive([0.3, -0.2, 1.0], [0.1, 0.25], 0.105, 0.2);
        let b = drive(h, [0.1, 0.25], 0.105, 0.2);
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn wrap_and_levels() {
        assert!((wrap_heading(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_heading(-PI), PI);
        assert_eq!(wrap_heading(PI), PI);
        let lv = [0.5, 1.0];
        assert_eq!(sonar_level(0.25, lv), 0);
        assert_eq!(sonar_level(0.4999, lv), 0);
        assert_eq!(sonar_level(0.5, lv), 1);
        assert_eq!(sonar_level(0.9999, lv), 1);
        assert_eq!(sonar_level(1.0, lv), 2);
        assert_eq!(sonar_level(2.0, lv), 2);
        let e = KheperaConfig::default().distance_edges;
        assert_eq!(distance_level(0.0, &e), 0);
        assert_eq!(distance_level(0.1999, &e), 0);
        assert_eq!(distance_level(0.2, &e), 1);
        assert_eq!(distance_level(5.9, &e), 7);
        assert_eq!(distance_level(6.0, &e), 8);
        assert_eq!(distance_level(100.0, &e), 8);
        let step = 40f64.to_radians();
        assert_eq!(angle_level(0.0), 4);
        assert_eq!(angle_level(0.5 * step - 1e-9), 4);
        assert_eq!(angle_level(0.5 * step + 1e-9), 5);
        assert_eq!(angle_level(-0.5 * step - 1e-9), 3);
        assert_eq!(angle_level(PI), 8);
        assert_eq!(angle_level(-PI + 1e-9), 0);
        let (d, a) = goal_polar([1.0, 0.0, PI / 2.0], [0.0, 0.0]);
        assert!(
            (d - 1.0).abs() < 1e-15 && (a - PI / 2.0).abs() < 1e-12,
            "{a}"
        );
    }

    #[test]
    fn model_blocks_at_walls_and_rewards_the_region() {
        let m = KheperaModel::new(KheperaConfig::default()).unwrap();
        // Facing the wall 1 cm away: forward leaves the robot in place.
        let p = m.move_robot([5.92, 0.0, 0.0], m.config().wheels(0));
        assert_eq!(p, [5.92, 0.0, 0.0]);
        // Facing away: it moves.
        let p = m.move_robot([5.92, 0.0, PI], m.config().wheels(0));
        assert!(p[0] < 5.92);
        assert_eq!(m.reward_f64(&[0.1, 0.0, 0.0, -0.1, 0.0, 0.0]), 5.0);
        assert_eq!(m.reward_f64(&[0.05, 0.0, 0.0, -0.05, 0.0, 0.0]), -5.0);
        assert_eq!(m.reward_f64(&[1.0, 0.0, 0.0, -0.1, 0.0, 0.0]), 0.0);
        // Touching a wall.
        assert_eq!(m.reward_f64(&[6.0, 0.0, 0.0, -0.1, 0.0, 0.0]), -5.0);
    }

    proptest::proptest! {
        /// The reward ignores the headings, as `reward_depends_on_state` declares (the
        /// solver evaluates it once per position and copies it across the headings): any
        /// headings give the same bits, at poses near each other, the walls and the goal.
        #[test]
        fn the_reward_ignores_the_headings(
            p in proptest::collection::vec(-6.2f64..6.2, 4),
            near in proptest::bool::ANY,
            h in proptest::collection::vec(-PI..PI, 4),
        ) {
            let m = KheperaModel::new(KheperaConfig::default()).unwrap();
            let s = if near { 0.05 } else { 1.0 };
            let pose = |h1: f64, h2: f64| [s * p[0], s * p[1], h1, s * p[2], s * p[3], h2];
            let r = m.reward_f64(&pose(h[0], h[1]));
            proptest::prop_assert_eq!(r.to_bits(), m.reward_f64(&pose(h[2], h[3])).to_bits());
            for d in 0..6 {
                proptest::prop_assert_eq!(Dynamics::reward_depends_on_state(&m, d), d % 3 != 2);
            }
        }
    }

    #[test]
    fn bad_config_names_the_field() {
        let c = KheperaConfig {
            forward_speed: 2.0,
            ..KheperaConfig::default()
        };
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("env.forward_speed")
        );
        let c = KheperaConfig {
            agents: 0,
            ..KheperaConfig::default()
        };
        assert!(c.validate().unwrap_err().to_string().contains("env.agents"));
    }
}
