//! Fixtures shared by the unit tests of several modules.

use crate::error::SimError;
use crate::learn::additive::AdditiveQ;
use crate::learn::fql::FqlConfig;
use crate::learn::tasks::pointmass::default_fql_config;
use crate::model::pointmass::{PointMass, PointMassConfig, Starts};
use crate::run::evaluate::{self, Outcome, RolloutSpec};
use crate::run::metrics::{RolloutMetrics, Trajectory};
use crate::run::policy::{AdditivePolicy, Policy};

/// The greedy rollout of `q` on the model (the one rollout path).
pub fn rollout_additive(
    model: &PointMass,
    q: &AdditiveQ,
    x0: &[f64],
    steps: usize,
    gamma: f64,
) -> Result<(Trajectory, RolloutMetrics), SimError> {
    let policy = Policy::Additive(AdditivePolicy::point_masses(
        model.clone(),
        q.clone(),
        gamma,
    )?);
    let spec = RolloutSpec {
        kind: fuzzyq_core::q::PolicyKind::Greedy,
        steps,
        plant: evaluate::PlantChoice::Model,
        seed: 0,
    };
    match evaluate::run(&policy, x0, &spec)? {
        Outcome::PointMass {
            trajectory,
            metrics,
            ..
        } => Ok((trajectory, metrics)),
        _ => unreachable!("a point-mass policy"),
    }
}

/// The paper's point mass, one agent.
pub fn one_point_mass() -> PointMass {
    PointMass::new(PointMassConfig {
        agents: 1,
        ..PointMassConfig::default()
    })
    .unwrap()
}

/// One agent, forces `{-2, 0, 2}` per axis (9 actions), a goal ball of radius 1 in its
/// 4-D state.
pub fn tiny_model() -> PointMass {
    PointMass::new(PointMassConfig {
        agents: 1,
        force_levels: vec![-2.0, 0.0, 2.0],
        goal_radius: 1.0,
        ..PointMassConfig::default()
    })
    .unwrap()
}

/// Starts at rest within 3 m.
pub fn tiny_starts() -> Starts {
    Starts::Uniform {
        position: 3.0,
        velocity: 0.0,
    }
}

/// Learning settings that solve [`tiny_model`] in well under a second.
pub fn tiny_fql() -> FqlConfig {
    FqlConfig {
        gamma: 0.95,
        episodes: 1500,
        max_steps: 40,
        alpha: 0.2,
        epsilon: 1.0,
        epsilon_min: 0.05,
        epsilon_decay_episodes: 1000,
        seed: 3,
        eval_every: 100,
        eval_episodes: 20,
        ..default_fql_config()
    }
}

/// A start of [`tiny_model`] 3.6 m from the goal.
pub const TINY_X0: [f64; 4] = [-3.0, 2.0, 0.0, 0.0];
