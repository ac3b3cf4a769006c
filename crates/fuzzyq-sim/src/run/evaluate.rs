//! Runs at the level of a task: one run with the task's plant and metrics ([`run`]), and
//! evaluations over many starts ([`point_mass_starts`], [`khepera_starts`], [`monte_carlo`]),
//! all through the one [`rollout`] loop with one controller prepared per evaluation.
//!
//! The classic benchmarks are judged as the ApproxRL toolbox judges them: a policy is run
//! from each state of a set of initial states for a fixed number of steps, and the score is
//! the discounted return `sum_{k < K} gamma^k rho(x_k, u_k)` of each run (no infinite-horizon
//! tail), averaged over the set. [`lattice`] gives the usual set of initial states: an evenly
//! spaced lattice over the state bounds. A run ends early when the model reaches a terminal
//! state (the car on the hill); [`RunSummary::terminal`] says so.

use fuzzyq_core::q::PolicyKind;

use crate::error::{ConfigError, SimError};
use crate::model::khepera::{poses_from_paper, random_starts};
use crate::model::{Dynamics, EnvModel, F64Model};
use crate::run::metrics::{
    KheperaMetrics, KheperaRun, MonteCarlo, RolloutMetrics, RunSummary, SuccessReport, Trajectory,
    measure_khepera, measure_point_masses,
};
use crate::run::plant::{KheperaPlant, ModelPlant, RapierPointMasses};
use crate::run::policy::Policy;
use crate::run::rollout::{Controller, rollout};
use crate::world::{Collisions, PointMassPlantConfig};

/// Where the point masses run.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum PlantChoice {
    /// The analytic model the policy was trained on.
    #[default]
    Model,
    /// Colliding discs on the rapier plant.
    Rapier(PointMassPlantConfig),
}

/// How to run a policy once.
#[derive(Clone, Debug, PartialEq)]
pub struct RolloutSpec {
    /// The policy to act with.
    pub kind: PolicyKind,
    /// Steps (sample times); a classic run may end earlier at a terminal state.
    pub steps: usize,
    /// The point masses' plant (the robots always run on their rapier plant, the classic
    /// benchmarks on their model).
    pub plant: PlantChoice,
    /// Seed of the plant's noise: the robots' wheel and sensor noise, and the point masses'
    /// process noise on the model plant ([`crate::model::pointmass::PointMassConfig::velocity_noise`]).
    pub seed: u64,
}

/// A run measured as its task measures it.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The point masses, on the model or the rapier plant.
    PointMass {
        /// The run.
        trajectory: Trajectory,
        /// What it achieved.
        metrics: RolloutMetrics,
        /// The collisions on the rapier plant (`None` on the model).
        collisions: Option<Collisions>,
    },
    /// The robots on their plant.
    Khepera {
        /// The run with poses, sonars and action indices.
        run: KheperaRun,
        /// What it achieved.
        metrics: KheperaMetrics,
    },
    /// A classic benchmark on its model.
    Classic {
        /// The run.
        trajectory: Trajectory,
        /// What it achieved.
        summary: RunSummary,
    },
}

/// The model a policy acts in, or an error for a policy without one (a tabulated model).
fn model_of(policy: &Policy) -> Result<&EnvModel, SimError> {
    policy.model().ok_or_else(|| {
        ConfigError::invalid(
            "policy",
            "a policy of a tabulated model has no plant to run on",
        )
        .into()
    })
}

/// Runs `policy` once from `start`: the model state for the point masses and the classic
/// benchmarks, the robots' flat poses `[x_1, y_1, heading_1, ...]` for the robots (see
/// [`crate::model::khepera::poses_from_paper`]).
pub fn run(policy: &Policy, start: &[f64], spec: &RolloutSpec) -> Result<Outcome, SimError> {
    let mut controller = policy.controller(spec.kind)?;
    run_with(policy, &mut *controller, start, spec)
}

/// [`run`] with a prepared controller of `policy`.
fn run_with(
    policy: &Policy,
    controller: &mut dyn Controller,
    start: &[f64],
    spec: &RolloutSpec,
) -> Result<Outcome, SimError> {
    let model = model_of(policy)?;
    let gamma = policy.gamma();
    Ok(match model {
        EnvModel::PointMass(pm) => {
            let (r, collisions) = match &spec.plant {
                PlantChoice::Model => {
                    let mut plant = ModelPlant::seeded(model, spec.seed);
                    (rollout(controller, &mut plant, start, spec.steps)?, None)
                }
                PlantChoice::Rapier(config) => {
                    let mut plant = RapierPointMasses::new(pm, config)?;
                    let r = rollout(controller, &mut plant, start, spec.steps)?;
                    (r, Some(plant.collisions().clone()))
                }
            };
            let metrics = measure_point_masses(pm, &r.trajectory, gamma, spec.kind, r.value_x0);
            Outcome::PointMass {
                trajectory: r.trajectory,
                metrics,
                collisions,
            }
        }
        EnvModel::Khepera(k) => {
            let mut plant = KheperaPlant::new(k, spec.seed)?;
            let r = rollout(controller, &mut plant, start, spec.steps)?;
            let collisions = plant.collisions().clone();
            let run = plant.into_run(r.trajectory);
            let metrics =
                measure_khepera(k, &run, collisions, gamma, spec.kind, r.value_x0, spec.seed);
            Outcome::Khepera { run, metrics }
        }
        classic => {
            let mut plant = ModelPlant::new(classic);
            let r = rollout(controller, &mut plant, start, spec.steps)?;
            let summary = RunSummary::of(&r.trajectory, start, r.terminal, gamma, r.value_x0);
            Outcome::Classic {
                trajectory: r.trajectory,
                summary,
            }
        }
    })
}

/// The start of one run of a policy of `model`, as [`run`] takes it: `x0` (`None`: the
/// environment's default start, the paper's for two agents); for the robots, their poses from
/// the paper's state `x0` and `headings` in degrees (`None`: 0 for every robot), or `x0`
/// itself when it already holds `[x, y, heading]` per robot and no headings are given.
pub fn start_for(
    model: &EnvModel,
    x0: Option<Vec<f64>>,
    headings: Option<&[f64]>,
) -> Result<Vec<f64>, SimError> {
    let spec = model.kind().spec();
    let agents = F64Model::n_agents(model);
    let x0 = match x0 {
        Some(x0) => x0,
        None if spec.multi_agent && agents != 2 => {
            return Err(ConfigError::invalid(
                "x0",
                format!(
                    "the policy has {agents} agent{}; give x0 with {} values (the default start \
                     is the paper's, for 2 agents)",
                    if agents == 1 { "" } else { "s" },
                    spec.state_names.len() * agents
                ),
            )
            .into());
        }
        None => spec.default_start.to_vec(),
    };
    let EnvModel::Khepera(k) = model else {
        return Ok(x0);
    };
    if headings.is_none() && x0.len() == 3 * agents {
        return Ok(x0);
    }
    let headings = headings.map_or_else(|| vec![0.0; agents], <[f64]>::to_vec);
    let poses = poses_from_paper(k.config(), &x0, &headings)?;
    Ok(poses.into_iter().flatten().collect())
}

/// The point masses from every state of `starts` on the model plant (run `i` with its process
/// noise, if the task has any, seeded with `i`): each run's metrics.
pub fn point_mass_starts(
    policy: &Policy,
    starts: &[Vec<f64>],
    steps: usize,
    kind: PolicyKind,
) -> Result<Vec<RolloutMetrics>, SimError> {
    if !matches!(policy.model(), Some(EnvModel::PointMass(_))) {
        return Err(not_for(policy, "point-mass starts"));
    }
    let spec = RolloutSpec {
        kind,
        steps,
        plant: PlantChoice::Model,
        seed: 0,
    };
    let mut controller = policy.controller(kind)?;
    starts
        .iter()
        .enumerate()
        .map(|(i, s)| {
            // Run i's process noise (if the task has any) is seeded with i.
            let spec = RolloutSpec {
                seed: i as u64,
                ..spec.clone()
            };
            match run_with(policy, &mut *controller, s, &spec)? {
                Outcome::PointMass { metrics, .. } => Ok(metrics),
                _ => unreachable!("a point-mass policy runs the point masses"),
            }
        })
        .collect()
}

fn not_for(policy: &Policy, what: &str) -> SimError {
    ConfigError::invalid(
        "env",
        format!(
            "{what} need a policy of that environment, this is a {} policy",
            policy.env().map_or("tabulated", |e| e.name())
        ),
    )
    .into()
}

/// The robots from `count` random starts ([`random_starts`] of `seed`), run `k` on the plant
/// seeded with `seed + k`: the success report and every run's metrics.
pub fn khepera_starts(
    policy: &Policy,
    count: usize,
    seed: u64,
    steps: usize,
    kind: PolicyKind,
) -> Result<(SuccessReport, Vec<KheperaMetrics>), SimError> {
    let Some(EnvModel::Khepera(model)) = policy.model() else {
        return Err(not_for(policy, "random robot starts"));
    };
    let starts = random_starts(model.config(), count, seed)?;
    let mut controller = policy.controller(kind)?;
    let mut runs = Vec::with_capacity(count);
    for (k, poses) in starts.iter().enumerate() {
        let spec = RolloutSpec {
            kind,
            steps,
            plant: PlantChoice::Model, // unused: the robots always run on their rapier plant
            seed: seed.wrapping_add(k as u64),
        };
        let flat: Vec<f64> = poses.iter().flatten().copied().collect();
        match run_with(policy, &mut *controller, &flat, &spec)? {
            Outcome::Khepera { metrics, .. } => runs.push(metrics),
            _ => unreachable!("a robot policy runs the robots"),
        }
    }
    Ok((SuccessReport::from_runs(seed, &runs), runs))
}

/// Runs `policy` from every state of `starts` on its model and averages the discounted
/// returns.
pub fn monte_carlo(
    policy: &Policy,
    starts: &[Vec<f64>],
    steps: usize,
    kind: PolicyKind,
) -> Result<MonteCarlo, SimError> {
    if starts.is_empty() {
        return Err(ConfigError::invalid("starts", "needs at least one initial state").into());
    }
    let model = model_of(policy)?;
    let mut controller = policy.controller(kind)?;
    let gamma = policy.gamma();
    let mut runs = Vec::with_capacity(starts.len());
    let mut plant = ModelPlant::new(model);
    for x0 in starts {
        let r = rollout(&mut *controller, &mut plant, x0, steps)?;
        runs.push(RunSummary::of(
            &r.trajectory,
            x0,
            r.terminal,
            gamma,
            r.value_x0,
        ));
    }
    Ok(MonteCarlo::from_runs(runs, kind, steps, gamma))
}

/// `per_dim` evenly spaced values over each state variable's bounds (both ends included),
/// combined into a lattice of `per_dim^E` states, the first variable varying slowest.
pub fn lattice(model: &EnvModel, per_dim: usize) -> Result<Vec<Vec<f64>>, SimError> {
    let e = F64Model::state_dim(model);
    let total = u32::try_from(e)
        .ok()
        .and_then(|e| per_dim.checked_pow(e))
        .filter(|&t| (1..=1_000_000).contains(&t) && per_dim >= 2);
    let Some(total) = total else {
        return Err(ConfigError::invalid(
            "starts",
            format!(
                "a lattice needs at least 2 values per state variable and at most 1,000,000 \
                 states ({per_dim}^{e} requested)"
            ),
        )
        .into());
    };
    let axes: Vec<Vec<f64>> = (0..e)
        .map(|d| {
            let (lo, hi) = Dynamics::state_bounds(model, d);
            (0..per_dim)
                .map(|i| lo + (hi - lo) * i as f64 / (per_dim - 1) as f64)
                .collect()
        })
        .collect();
    Ok((0..total)
        .map(|mut k| {
            let mut x = vec![0.0; e];
            for d in (0..e).rev() {
                x[d] = axes[d][k % per_dim];
                k /= per_dim;
            }
            x
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use fuzzyq_core::q::PolicyKind;

    use super::*;
    use crate::error::SimError;
    use crate::io::config::{EnvConfig, GridConfig, TrainConfig};
    use crate::learn::additive::AdditiveQ;
    use crate::learn::codebook::Codebook;
    use crate::learn::features::FeatureSpace;
    use crate::learn::tasks::khepera::feature_space;
    use crate::model::khepera::{KheperaConfig, KheperaModel, N_ACTIONS, random_starts};
    use crate::model::pointmass::{PointMass, PointMassConfig};
    use crate::run::metrics::RolloutMetrics;
    use crate::run::policy::{AdditivePolicy, FqiPolicy};
    use crate::test_support::rollout_additive;

    use crate::test_support::one_point_mass as one_agent;

    fn spec(steps: usize) -> RolloutSpec {
        RolloutSpec {
            kind: PolicyKind::Greedy,
            steps,
            plant: PlantChoice::Model,
            seed: 0,
        }
    }

    /// Cores `[-6, 0, 6]` for positions and `[-3, 0, 3]` for velocities (81 cores): action 0
    /// `(-2, -2)` is worth 1 at the cores with `s_x = 6`, action 24 `(2, 2)` is worth 0.8 at
    /// the cores with `s_x = 0`, everything else 0.
    fn hand_q() -> AdditiveQ {
        let p = vec![-6.0, 0.0, 6.0];
        let v = vec![-3.0, 0.0, 3.0];
        let features = FeatureSpace::new(vec![vec![p.clone(), p, v.clone(), v]]).unwrap();
        let mut phi = vec![0.0; 81 * 25];
        for d in 0..81 {
            // Row-major: s_x is the slowest index (stride 27).
            match d / 27 {
                2 => phi[d * 25] = 1.0,
                1 => phi[d * 25 + 24] = 0.8,
                _ => {}
            }
        }
        AdditiveQ::from_params(features, vec![25], vec![phi]).unwrap()
    }

    #[test]
    fn rollout_additive_takes_the_hand_computed_greedy_actions() {
        let model = one_agent();
        let q = hand_q();
        // s_x = 3: memberships 1/2 at s_x = 0 and 6, so Q = (0.5, ..., 0.4): action 0.
        let (t, m) = rollout_additive(&model, &q, &[3.0, 1.0, 0.5, 0.0], 3, 0.9).unwrap();
        assert_eq!(t.actions[0], [-2.0, -2.0]);
        assert!((m.value_x0 - 0.5).abs() < 1e-12);
        let mut next = [0.0; 4];
        model.step_f64(&[3.0, 1.0, 0.5, 0.0], &[-2.0, -2.0], &mut next);
        assert_eq!(t.states[1], next);
        assert_eq!(
            (t.states.len(), t.actions.len(), t.rewards.len()),
            (4, 3, 3)
        );
        assert_eq!(m.policy_kind, PolicyKind::Greedy);
        assert_eq!(m.steps, 3);
        // s_x = 1: memberships 5/6 at s_x = 0, 1/6 at 6: Q(0) = 1/6 < Q(24) = 2/3: action 24.
        let (t, m) = rollout_additive(&model, &q, &[1.0, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [2.0, 2.0]);
        assert!((m.value_x0 - 0.8 * 5.0 / 6.0).abs() < 1e-12);
        // s_x = -6: only cores with s_x = -6 are active, every value is 0 and the lowest index
        // wins: action 0.
        let (t, _) = rollout_additive(&model, &q, &[-6.0, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [-2.0, -2.0]);
    }

    #[test]
    fn rollout_additive_runs_codebook_policies_and_checks_its_inputs() {
        let model = one_agent();
        let book = Codebook::new(
            vec![vec![2.0, 0.0, 0.0, 0.0], vec![-2.0, 0.0, 0.0, 0.0]],
            vec![1.0; 4],
        )
        .unwrap();
        let features = FeatureSpace::codebook(vec![book]).unwrap();
        let mut phi = vec![0.0; 2 * 25];
        phi[7] = 1.0; // cell 0: (-0.2, 0)
        phi[25 + 22] = 2.0; // cell 1: (2, 0) = (levels[4], levels[2])
        let q = AdditiveQ::from_params(features, vec![25], vec![phi]).unwrap();
        let (t, m) = rollout_additive(&model, &q, &[0.5, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [-0.2, 0.0]);
        assert_eq!(m.value_x0, 1.0);
        let (t, m) = rollout_additive(&model, &q, &[-0.5, 0.0, 0.0, 0.0], 1, 0.9).unwrap();
        assert_eq!(t.actions[0], [2.0, 0.0]);
        assert_eq!(m.value_x0, 2.0);

        // Mismatches are errors.
        let err = |r: Result<(Trajectory, RolloutMetrics), SimError>| {
            r.expect_err("expected an error").to_string()
        };
        let two = PointMass::paper();
        assert!(err(rollout_additive(&two, &q, &[0.0; 8], 1, 0.9)).contains("has 1 agents"));
        let nine = PointMass::new(PointMassConfig {
            agents: 1,
            force_levels: vec![-1.0, 0.0, 1.0],
            ..PointMassConfig::default()
        })
        .unwrap();
        assert!(err(rollout_additive(&nine, &q, &[0.0; 4], 1, 0.9)).contains("25 actions"));
        let wide = FeatureSpace::new(vec![vec![vec![0.0, 1.0]; 3]]).unwrap();
        let q3 = AdditiveQ::new(wide, vec![25]).unwrap();
        assert!(err(rollout_additive(&model, &q3, &[0.0; 4], 1, 0.9)).contains("observes 3"));
        assert!(err(rollout_additive(&model, &q, &[0.0; 3], 1, 0.9)).starts_with("x0:"));
        assert!(
            err(rollout_additive(
                &model,
                &q,
                &[f64::NAN, 0.0, 0.0, 0.0],
                1,
                0.9
            ))
            .starts_with("x0:")
        );
        assert!(err(rollout_additive(&model, &q, &[0.0; 4], 1, f64::NAN)).starts_with("gamma:"));
        let (t, _) = rollout_additive(&model, &q, &[0.0; 4], 0, 0.9).unwrap();
        assert_eq!(t.states.len(), 1);
    }

    fn fqi(config: &TrainConfig) -> Policy {
        let a = crate::train::train(config, |_| std::ops::ControlFlow::Continue(())).unwrap();
        Policy::Fqi(FqiPolicy::from_artifact(a).unwrap())
    }

    fn dcmotor() -> Policy {
        let mut c =
            TrainConfig::from_preset(crate::model::EnvKind::Dcmotor, "toolbox-demo").unwrap();
        c.solver.precision = fuzzyq_core::solver::Precision::F64;
        fqi(&c)
    }

    fn classic(
        policy: &Policy,
        x0: &[f64],
        steps: usize,
        kind: PolicyKind,
    ) -> (Trajectory, RunSummary) {
        let spec = RolloutSpec {
            kind,
            ..spec(steps)
        };
        match run(policy, x0, &spec).unwrap() {
            Outcome::Classic {
                trajectory,
                summary,
            } => (trajectory, summary),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn returns_are_discounted_sums_and_the_motor_is_brought_to_rest() {
        let p = dcmotor();
        let (t, s) = classic(&p, &[-1.0, 0.0], 400, PolicyKind::Interpolated);
        assert_eq!(t.states.len(), 401);
        let g: f64 = 0.98;
        let manual: f64 = t
            .rewards
            .iter()
            .enumerate()
            .map(|(k, r)| g.powi(k as i32) * r)
            .sum();
        assert!((manual - s.discounted_return).abs() <= 1e-9 * manual.abs());
        assert!(s.final_state[0].abs() < 0.05, "{:?}", s.final_state);
        assert!(s.discounted_return < 0.0 && s.value_x0 < 0.0);
        assert!(run(&p, &[0.0], &spec(10)).is_err());
        assert!(run(&p, &[4.0, 0.0], &spec(10)).is_err());
    }

    #[test]
    fn monte_carlo_averages_over_a_lattice() {
        let p = dcmotor();
        let starts = lattice(p.model().unwrap(), 3).unwrap();
        assert_eq!(starts.len(), 9);
        assert_eq!(
            starts[0],
            vec![-std::f64::consts::PI, -16.0 * std::f64::consts::PI]
        );
        assert_eq!(starts[1][0], starts[0][0]);
        let mc = monte_carlo(&p, &starts, 100, PolicyKind::Greedy).unwrap();
        assert_eq!(mc.runs.len(), 9);
        let mean = mc.runs.iter().map(|r| r.discounted_return).sum::<f64>() / 9.0;
        assert!((mean - mc.mean_return).abs() < 1e-9);
        assert!(mc.min_return <= mc.mean_return && mc.mean_return <= mc.max_return);
        // Each run equals the single run from its start.
        let (_, one) = classic(&p, &starts[4], 100, PolicyKind::Greedy);
        assert_eq!(mc.runs[4], one);
        assert!(lattice(p.model().unwrap(), 1).is_err());
        assert!(monte_carlo(&p, &[], 10, PolicyKind::Greedy).is_err());
    }

    #[test]
    fn the_rapier_plant_equals_the_model_without_contacts() {
        let mut config = TrainConfig::default();
        if let EnvConfig::Pointmass(p) = &mut config.env {
            p.agents = 1;
        }
        let (pos, vel) = (vec![-6.0, -1.0, 0.0, 1.0, 6.0], vec![-3.0, 0.0, 3.0]);
        config.grid = GridConfig::explicit(vec![pos.clone(), pos, vel.clone(), vel]);
        for precision in [
            fuzzyq_core::solver::Precision::F32,
            fuzzyq_core::solver::Precision::F64,
        ] {
            config.solver.precision = precision;
            let p = fqi(&config);
            let x0 = [-4.0, 3.0, 0.0, 0.0];
            let Outcome::PointMass {
                trajectory: a,
                metrics: ma,
                collisions: none,
            } = run(&p, &x0, &spec(40)).unwrap()
            else {
                panic!("point masses")
            };
            assert!(none.is_none());
            let rapier = RolloutSpec {
                plant: PlantChoice::Rapier(PointMassPlantConfig::default()),
                ..spec(40)
            };
            let Outcome::PointMass {
                trajectory: b,
                metrics: mb,
                collisions: Some(col),
            } = run(&p, &x0, &rapier).unwrap()
            else {
                panic!("point masses on the rapier plant")
            };
            assert_eq!(col.total, 0);
            assert_eq!(a.actions, b.actions);
            for (x, y) in a.states.iter().zip(&b.states) {
                for (p, q) in x.iter().zip(y) {
                    assert!((p - q).abs() < 1e-9, "{x:?} vs {y:?}");
                }
            }
            assert_eq!(ma.reach_step, mb.reach_step);
            assert!((ma.discounted_return - mb.discounted_return).abs() < 1e-12);
            // Many starts: each run equals the single run from its start.
            let starts = vec![x0.to_vec(), vec![3.0, -2.0, 0.0, 0.0]];
            let all = point_mass_starts(&p, &starts, 40, PolicyKind::Greedy).unwrap();
            assert_eq!(all[0], ma);
        }
    }

    /// The robots' greedy policy of a learned `q` on their plant.
    fn robots(q: &AdditiveQ, config: &KheperaConfig, gamma: f64) -> Result<Policy, SimError> {
        let model = KheperaModel::new(config.clone())?;
        Ok(Policy::Additive(AdditivePolicy::robots(
            model,
            q.clone(),
            gamma,
        )?))
    }

    fn robot_run(
        policy: &Policy,
        start: &[[f64; 3]],
        steps: usize,
        seed: u64,
    ) -> (KheperaRun, KheperaMetrics) {
        let flat: Vec<f64> = start.iter().flatten().copied().collect();
        let spec = RolloutSpec {
            seed,
            ..spec(steps)
        };
        match run(policy, &flat, &spec).unwrap() {
            Outcome::Khepera { run, metrics } => (run, metrics),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn rollout_returns_every_pose_and_matches_success_over_starts() {
        let config = KheperaConfig::default();
        let features = feature_space(&config).unwrap();
        let q = AdditiveQ::new(features, vec![N_ACTIONS; 2]).unwrap();
        let start = [[-4.0, 5.0, 0.0], [5.0, 3.0, 0.0]];
        let policy = robots(&q, &config, 0.96).unwrap();
        let (run, m) = robot_run(&policy, &start, 30, 0);
        assert_eq!(run.poses.len(), 31);
        assert_eq!(run.trajectory.states.len(), 31);
        assert_eq!(run.trajectory.actions.len(), 30);
        assert_eq!(run.sonar.len(), 31);
        assert_eq!(run.action_indices.len(), 30);
        // phi = 0: every robot takes action 0 (forward) on the tie.
        assert!(run.action_indices.iter().flatten().all(|&a| a == 0));
        assert_eq!(run.poses[0], start.to_vec());
        let d = config.forward_speed * config.sample_time * 30.0;
        assert!(
            (run.poses[30][0][0] - (-4.0 + d)).abs() < 1e-6,
            "{:?}",
            run.poses[30]
        );
        assert_eq!(m.rollout.steps, 30);
        assert_eq!(m.rollout.value_x0, 0.0);
        assert!(!m.success);

        let (report, all) = khepera_starts(&policy, 3, 7, 20, PolicyKind::Greedy).unwrap();
        assert_eq!(report.starts, 3);
        assert_eq!(all.len(), 3);
        let starts = random_starts(&config, 3, 7).unwrap();
        let (_, m1) = robot_run(&policy, &starts[1], 20, 8);
        assert_eq!(all[1], m1);

        // A Q-function of another configuration is refused.
        let other = KheperaConfig {
            distance_edges: [0.3, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0],
            ..KheperaConfig::default()
        };
        assert!(robots(&q, &other, 0.96).is_err());
        // A learned policy acts greedily only.
        assert!(policy.controller(PolicyKind::Interpolated).is_err());
    }
}
