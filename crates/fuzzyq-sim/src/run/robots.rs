//! Running a trained Khepera policy on the rapier plant ([`KheperaWorld`]) and measuring it.
//!
//! The policy decides on the robots' poses (the learning state); the plant moves the discs,
//! resolves contacts and reads the sonars. The run is reported in the paper's 8-D state
//! `[s_1x, s_1y, v_1x, v_1y, s_2x, s_2y, v_2x, v_2y]` (velocity = displacement over the last
//! control period), so the point-mass metrics and figures apply unchanged, plus the headings,
//! the sonars and the collisions.

use fuzzyq_core::{Model, Real};
use rand::Rng;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError};
use crate::model::EnvModel;
use crate::model::khepera::{KheperaConfig, KheperaModel, wrap_angle};
use crate::run::policy::{Actor, AnyPolicy, Policy, PolicyKind};
use crate::run::rollout::{RolloutMetrics, Trajectory, measure_with};
use crate::world::{Collisions, KheperaWorld};

/// The paper's start for the robot experiment (section 3.3): `[-4, 5, 0, 0, 5, 3, 0, 0]`.
pub const PAPER_KHEPERA_X0: [f64; 8] = [-4.0, 5.0, 0.0, 0.0, 5.0, 3.0, 0.0, 0.0];

/// A Khepera run on the plant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KheperaRun {
    /// The run in the paper's state (actions are the wheel speeds `(v_l, v_r)` per robot).
    pub trajectory: Trajectory,
    /// Poses `(x, y, heading)` per robot, `steps + 1` of them.
    pub poses: Vec<Vec<[f64; 3]>>,
    /// Discrete action index per robot and step (see [`crate::model::khepera::ACTION_NAMES`]); for
    /// the interpolated policy, the nearest of the four to the averaged wheel speeds.
    pub action_indices: Vec<Vec<usize>>,
    /// Sonar readings per robot at every state (m).
    pub sonar: Vec<Vec<Vec<f64>>>,
}

/// What a Khepera run achieved: the point-mass metrics plus collisions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KheperaMetrics {
    /// The metrics shared with the point-mass rollout.
    #[serde(flatten)]
    pub rollout: RolloutMetrics,
    /// Initial headings (degrees).
    pub headings_deg: Vec<f64>,
    /// The plant's seed.
    pub seed: u64,
    /// Collisions on the plant.
    pub collisions: Collisions,
    /// `||x||` of the final 8-D state.
    pub final_norm: f64,
    /// The final state is inside the reward region and no collision happened.
    pub success: bool,
}

/// The Khepera model of a policy, or an error naming the policy's environment.
pub fn khepera_of<T: Real>(policy: &Policy<T>) -> Result<&KheperaModel, SimError>
where
    EnvModel: Model<T>,
{
    policy.model().khepera().ok_or_else(|| {
        ConfigError::invalid(
            "env",
            format!(
                "this is a {} policy; Khepera rollouts need a khepera policy",
                policy.model().name()
            ),
        )
        .into()
    })
}

/// Poses from the paper's 8-D state (velocities must be zero: robots start at rest) and
/// headings in degrees.
pub fn poses_from_paper(
    config: &KheperaConfig,
    x0: &[f64],
    headings_deg: &[f64],
) -> Result<Vec<[f64; 3]>, SimError> {
    let n = config.agents;
    if x0.len() != 4 * n {
        return Err(ConfigError::invalid(
            "x0",
            format!(
                "needs {} values ([s_x, s_y, v_x, v_y] per robot), got {}",
                4 * n,
                x0.len()
            ),
        )
        .into());
    }
    if headings_deg.len() != n {
        return Err(ConfigError::invalid(
            "headings",
            format!(
                "needs {n} values (one per robot), got {}",
                headings_deg.len()
            ),
        )
        .into());
    }
    if let Some(v) = x0.iter().find(|v| !v.is_finite()) {
        return Err(ConfigError::invalid("x0", format!("must be finite, got {v}")).into());
    }
    if let Some(h) = headings_deg.iter().find(|v| !v.is_finite()) {
        return Err(ConfigError::invalid("headings", format!("must be finite, got {h}")).into());
    }
    (0..n)
        .map(|i| {
            if x0[4 * i + 2] != 0.0 || x0[4 * i + 3] != 0.0 {
                return Err(ConfigError::invalid(
                    "x0",
                    format!("robot {} must start at rest (zero velocity)", i + 1),
                )
                .into());
            }
            Ok([
                x0[4 * i],
                x0[4 * i + 1],
                wrap_angle(headings_deg[i].to_radians()),
            ])
        })
        .collect()
}

fn flat(poses: &[[f64; 3]]) -> Vec<f64> {
    poses.iter().flat_map(|p| p.iter().copied()).collect()
}

/// Runs `policy` for `steps` control periods from `start` on the plant seeded with `seed`.
pub fn rollout_khepera<T: Real>(
    policy: &Policy<T>,
    start: &[[f64; 3]],
    steps: usize,
    kind: PolicyKind,
    seed: u64,
) -> Result<(KheperaRun, KheperaMetrics), SimError>
where
    EnvModel: Model<T>,
{
    let mut actor = policy.actor(kind)?;
    rollout_khepera_with(policy, &mut actor, start, steps, kind, seed)
}

/// [`rollout_khepera`] with a prepared actor (preparing one builds the backup tables, so
/// many runs share one).
pub fn rollout_khepera_with<T: Real>(
    policy: &Policy<T>,
    actor: &mut Actor<'_, T>,
    start: &[[f64; 3]],
    steps: usize,
    kind: PolicyKind,
    seed: u64,
) -> Result<(KheperaRun, KheperaMetrics), SimError>
where
    EnvModel: Model<T>,
{
    let model = khepera_of(policy)?;
    let (run, collisions) = run_on_plant(model, start, steps, seed, |poses, _, u| {
        actor.act(&flat(poses), u).map(|_| ())
    })?;
    let value_x0 = policy.value(&flat(start))?;
    let metrics = measure_run(
        model,
        &run,
        collisions,
        policy.config().solver.gamma,
        kind,
        value_x0,
        seed,
    );
    Ok((run, metrics))
}

/// Runs a controller on the plant seeded with `seed` for `steps` control periods from
/// `start`: before every period, `decide(poses, sonar, wheels)` writes the joint wheel speeds
/// `(v_l, v_r)` per robot from the current poses and sonar readings.
pub(crate) fn run_on_plant(
    model: &KheperaModel,
    start: &[[f64; 3]],
    steps: usize,
    seed: u64,
    mut decide: impl FnMut(&[[f64; 3]], &[Vec<f64>], &mut [f64]) -> Result<(), SimError>,
) -> Result<(KheperaRun, Collisions), SimError> {
    let config = model.config();
    let n = config.agents;
    let mut world = KheperaWorld::new(config, seed)?;
    world.reset(start)?;
    let n_sonar = config.sonar_angles_deg.len();
    let read = |world: &mut KheperaWorld| -> Result<Vec<Vec<f64>>, SimError> {
        (0..n)
            .map(|r| {
                let mut s = vec![0.0; n_sonar];
                world.sonar(r, &mut s)?;
                Ok(s)
            })
            .collect()
    };
    let paper = |poses: &[[f64; 3]], vel: Option<&[[f64; 2]]>| -> Vec<f64> {
        (0..n)
            .flat_map(|i| {
                let v = vel.map_or([0.0, 0.0], |v| v[i]);
                [poses[i][0], poses[i][1], v[0], v[1]]
            })
            .collect()
    };
    let mut poses = vec![world.poses().to_vec()];
    let mut states = vec![paper(world.poses(), None)];
    let mut sonar = vec![read(&mut world)?];
    let mut actions = Vec::with_capacity(steps);
    let mut indices = Vec::with_capacity(steps);
    let mut rewards = Vec::with_capacity(steps);
    let mut u = vec![0.0; 2 * n];
    for k in 0..steps {
        decide(world.poses(), &sonar[k], &mut u)?;
        rewards.push(model.reward_f64(&flat(world.poses())));
        let wheels: Vec<[f64; 2]> = (0..n).map(|i| [u[2 * i], u[2 * i + 1]]).collect();
        indices.push(wheels.iter().map(|w| nearest_action(config, *w)).collect());
        world.step(&wheels)?;
        actions.push(u.clone());
        poses.push(world.poses().to_vec());
        states.push(paper(world.poses(), Some(world.velocities())));
        sonar.push(read(&mut world)?);
    }
    let trajectory = Trajectory {
        dt: config.sample_time,
        agents: n,
        states,
        actions,
        rewards,
    };
    let run = KheperaRun {
        trajectory,
        poses,
        action_indices: indices,
        sonar,
    };
    Ok((run, world.collisions().clone()))
}

/// The metrics of a run on the plant.
pub(crate) fn measure_run(
    model: &KheperaModel,
    run: &KheperaRun,
    collisions: Collisions,
    gamma: f64,
    kind: PolicyKind,
    value_x0: f64,
    seed: u64,
) -> KheperaMetrics {
    let in_region = |x: &[f64]| model.in_region_paper(x);
    let t = &run.trajectory;
    let rollout = measure_with(in_region, t, gamma, kind, value_x0);
    let last = t.states.last().expect("at least x0");
    KheperaMetrics {
        success: in_region(last) && collisions.total == 0,
        rollout,
        headings_deg: run.poses[0].iter().map(|p| p[2].to_degrees()).collect(),
        seed,
        collisions,
        final_norm: last.iter().map(|v| v * v).sum::<f64>().sqrt(),
    }
}

/// Runs a policy of either precision on the plant.
pub fn rollout_khepera_any(
    policy: &AnyPolicy,
    start: &[[f64; 3]],
    steps: usize,
    kind: PolicyKind,
    seed: u64,
) -> Result<(KheperaRun, KheperaMetrics), SimError> {
    match policy {
        AnyPolicy::F32(p) => rollout_khepera(p, start, steps, kind, seed),
        AnyPolicy::F64(p) => rollout_khepera(p, start, steps, kind, seed),
    }
}

/// The action whose wheel speeds are nearest to `w`.
fn nearest_action(config: &KheperaConfig, w: [f64; 2]) -> usize {
    (0..crate::model::khepera::N_ACTIONS)
        .min_by(|&a, &b| {
            let d = |k: usize| {
                let c = config.wheels(k);
                (c[0] - w[0]).powi(2) + (c[1] - w[1]).powi(2)
            };
            d(a).total_cmp(&d(b))
        })
        .unwrap_or(3)
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
            if tries > 100_000 {
                return Err(ConfigError::invalid(
                    "arena",
                    "no room for random starts clear of the obstacles",
                )
                .into());
            }
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

/// Success over many starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SuccessReport {
    /// Number of starts.
    pub starts: usize,
    /// Seed of the starts (and base seed of the plant).
    pub seed: u64,
    /// Runs that ended in the reward region without a collision.
    pub successes: usize,
    /// `successes / starts`.
    pub success_rate: f64,
    /// Runs with at least one collision.
    pub runs_with_collisions: usize,
    /// Mean time to first reach the reward region over the runs that reached it (s).
    pub mean_reach_time_s: Option<f64>,
    /// Mean final `||x||` over all runs.
    pub mean_final_norm: f64,
}

impl SuccessReport {
    /// Summarises the runs from the starts drawn with `seed`.
    #[must_use]
    pub fn from_runs(seed: u64, runs: &[KheperaMetrics]) -> Self {
        let count = runs.len();
        let successes = runs.iter().filter(|m| m.success).count();
        let reached: Vec<f64> = runs.iter().filter_map(|m| m.rollout.reach_time_s).collect();
        Self {
            starts: count,
            seed,
            successes,
            success_rate: successes as f64 / count.max(1) as f64,
            runs_with_collisions: runs.iter().filter(|m| m.collisions.total > 0).count(),
            mean_reach_time_s: (!reached.is_empty())
                .then(|| reached.iter().sum::<f64>() / reached.len() as f64),
            mean_final_norm: runs.iter().map(|m| m.final_norm).sum::<f64>() / count.max(1) as f64,
        }
    }
}

/// Rolls the policy out from `count` random starts (see [`random_starts`]); run `k` uses the
/// plant seed `seed + k`.
pub fn success_over_starts(
    policy: &AnyPolicy,
    count: usize,
    seed: u64,
    steps: usize,
    kind: PolicyKind,
) -> Result<(SuccessReport, Vec<KheperaMetrics>), SimError> {
    let config = match policy {
        AnyPolicy::F32(p) => khepera_of(p)?.config().clone(),
        AnyPolicy::F64(p) => khepera_of(p)?.config().clone(),
    };
    let starts = random_starts(&config, count, seed)?;
    fn runs<T: Real>(
        p: &Policy<T>,
        starts: &[Vec<[f64; 3]>],
        steps: usize,
        kind: PolicyKind,
        seed: u64,
    ) -> Result<Vec<KheperaMetrics>, SimError>
    where
        EnvModel: Model<T>,
    {
        let mut actor = p.actor(kind)?;
        starts
            .iter()
            .enumerate()
            .map(|(k, s)| {
                rollout_khepera_with(p, &mut actor, s, steps, kind, seed.wrapping_add(k as u64))
                    .map(|r| r.1)
            })
            .collect()
    }
    let all = match policy {
        AnyPolicy::F32(p) => runs(p, &starts, steps, kind, seed)?,
        AnyPolicy::F64(p) => runs(p, &starts, steps, kind, seed)?,
    };
    Ok((SuccessReport::from_runs(seed, &all), all))
}
