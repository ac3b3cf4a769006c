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
use crate::model::khepera::random_starts;
use crate::model::{EnvModel, F64Model};
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
    /// Seed of the robot plant's noise.
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
                    let mut plant = ModelPlant::new(model);
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

/// The point masses from every state of `starts` on the model: each run's metrics.
pub fn point_mass_starts(
    policy: &Policy,
    starts: &[Vec<f64>],
    steps: usize,
    kind: PolicyKind,
) -> Result<Vec<RolloutMetrics>, SimError> {
    let spec = RolloutSpec {
        kind,
        steps,
        plant: PlantChoice::Model,
        seed: 0,
    };
    let mut controller = policy.controller(kind)?;
    starts
        .iter()
        .map(|s| match run_with(policy, &mut *controller, s, &spec)? {
            Outcome::PointMass { metrics, .. } => Ok(metrics),
            _ => Err(not_for(policy, "point-mass starts")),
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
            plant: PlantChoice::Model,
            seed: seed.wrapping_add(k as u64),
        };
        let flat: Vec<f64> = poses.iter().flatten().copied().collect();
        if let Outcome::Khepera { metrics, .. } = run_with(policy, &mut *controller, &flat, &spec)?
        {
            runs.push(metrics);
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
    for x0 in starts {
        let mut plant = ModelPlant::new(model);
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
            let (lo, hi) = F64Model::state_bounds(model, d);
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
