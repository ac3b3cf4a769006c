//! # fuzzyq-sim
//!
//! Models and environments for fuzzyq, and the glue from a configuration to a trained policy
//! and back to actions:
//!
//! - [`classic`]: the classic single-agent benchmarks of Busoniu et al. 2010 (ApproxRL): the DC
//!   motor and the inverted pendulum swing-up, with the toolbox's grids as presets;
//! - [`pointmass`]: the paper's point-mass task (section 3.1) for `n` agents, with the exact
//!   zero-order-hold step or RK4 for a position-dependent friction, declaring its independent
//!   dynamics blocks to the solver;
//! - [`config`]: the TOML training configuration (environment, grid, solver);
//! - [`train`]: configuration in, [`PolicyArtifact`] out;
//! - [`artifact`]: the policy file (tagged, versioned, checksummed, written atomically);
//! - [`policy`] and [`rollout`]: greedy and interpolated policies, simulated runs and their
//!   metrics.
//! - [`fql`]: model-free fuzzy Q-learning (section 2.5) on any episodic [`fql::Environment`].
//! - [`evaluate`]: rollouts and Monte-Carlo evaluation of a policy on any environment.
//! - [`compare`]: the paper's Table 1 rerun: fuzzy and crisp learners side by side.
//! - [`khepera_fql`]: model-free fuzzy Q-learning of the Khepera task on the rapier plant.
//! - [`pointmass_fql`]: the point-mass task as a model-free environment, its fuzzy features,
//!   learning defaults and policy file.
//! - [`vqql`]: the crisp baseline of Table 1 (a k-means vector quantiser of each agent's state
//!   plus tabular Q-learning).
//! - [`physics`]: rapier2d plants (colliding point masses, Khepera robots with sonars) that
//!   move exactly as the models do in open space.
//!
//! ```
//! use fuzzyq_sim::io::config::{GridConfig, TrainConfig};
//! use fuzzyq_sim::run::policy::{AnyPolicy, PolicyKind};
//!
//! // The paper's task with one agent on a coarse grid.
//! let mut config = TrainConfig::default();
//! if let fuzzyq_sim::io::config::EnvConfig::Pointmass(p) = &mut config.env {
//!     p.agents = 1;
//! }
//! config.grid = GridConfig {
//!     position_cores: vec![-6.0, -1.0, 0.0, 1.0, 6.0],
//!     velocity_cores: vec![-3.0, 0.0, 3.0],
//!     heading_divisions: None,
//!     cores: None,
//!     membership: Default::default(),
//! };
//! let artifact = fuzzyq_sim::train::train(&config, |_| std::ops::ControlFlow::Continue(()))?;
//! assert!(artifact.summary.converged);
//! let policy = AnyPolicy::from_artifact(artifact)?;
//! let (trajectory, metrics) =
//!     fuzzyq_sim::run::rollout::rollout_any(&policy, &[-4.0, 3.0, 0.0, 0.0], 40, PolicyKind::Greedy)?;
//! assert_eq!(trajectory.states.len(), 41);
//! assert!(metrics.final_error_m[0] < 4.0);
//! # Ok::<(), fuzzyq_sim::SimError>(())
//! ```
#![deny(missing_docs)]

pub mod compare;
pub mod error;
pub mod io;
pub mod learn;
pub mod model;
pub mod paper;
pub mod run;
pub mod train;
pub mod world;

pub use error::{ConfigError, PolicyFileError, SimError};
pub use io::config::TrainConfig;
pub use io::policy_file::PolicyArtifact;
pub use model::pointmass::{PointMass, PointMassConfig};

/// The README's Rust examples, compiled as doctests so that they cannot drift from the API.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
pub struct ReadmeDoctests;
