//! # fuzzyq-sim
//!
//! The environments of fuzzyq and everything between a configuration and a measured run:
//! models, rapier worlds, learners from samples, configuration and policy files, policies,
//! rollouts and the paper's Table 1. Built on the no_std numeric core, `fuzzyq-core`.
//!
//! ## Layers
//! Each folder has one job, and a module only names lower layers (checked in CI by
//! `scripts/check-layers.py`; `docs/design.md` explains the design):
//!
//! | layer | module | job |
//! |---|---|---|
//! | 0 | [`error`], [`paper`], [`fs`] | typed errors; the numbers taken from the paper; bounded reading of input files |
//! | 1 | [`model`] | the environment registry ([`model::EnvKind`]) and the models: point masses, Khepera robots, classic benchmarks |
//! | 2 | [`world`] | rapier2d worlds: colliding point masses, robots with ray-cast sonars |
//! | 3 | [`learn`] | learning from samples: fuzzy Q-learning, VQQL, the tasks as environments |
//! | 4 | [`io`] | TOML configurations and the policy files of every learner |
//! | 5 | [`run`], [`slabs`] | policies, plants, the one rollout loop, metrics, evaluations; a configuration's operator for sharded sweeps |
//! | 6 | [`train`] | a configuration in, a policy out, for every learner |
//! | 7 | [`compare`] | the paper's Table 1: every learner trained and measured alike |
//!
//! ## A first example
//! ```
//! use fuzzyq_core::q::PolicyKind;
//! use fuzzyq_sim::io::config::{EnvConfig, GridConfig, TrainConfig};
//! use fuzzyq_sim::run::evaluate::{self, Outcome, RolloutSpec};
//! use fuzzyq_sim::run::policy::{FqiPolicy, Policy};
//!
//! // The paper's task with one agent on a coarse grid.
//! let mut config = TrainConfig::default();
//! if let EnvConfig::Pointmass(p) = &mut config.env {
//!     p.agents = 1;
//! }
//! let (pos, vel) = (vec![-6.0, -1.0, 0.0, 1.0, 6.0], vec![-3.0, 0.0, 3.0]);
//! config.grid = GridConfig::explicit(vec![pos.clone(), pos, vel.clone(), vel]);
//! let artifact = fuzzyq_sim::train::train(&config, |_| std::ops::ControlFlow::Continue(()))?;
//! assert!(artifact.summary.converged);
//! let policy = Policy::Fqi(FqiPolicy::from_artifact(artifact)?);
//! let spec = RolloutSpec {
//!     kind: PolicyKind::Greedy,
//!     steps: 40,
//!     plant: evaluate::PlantChoice::Model,
//!     seed: 0,
//! };
//! let Outcome::PointMass { trajectory, metrics, .. } =
//!     evaluate::run(&policy, &[-4.0, 3.0, 0.0, 0.0], &spec)?
//! else {
//!     unreachable!("a point-mass policy")
//! };
//! assert_eq!(trajectory.states.len(), 41);
//! assert!(metrics.final_error_m[0] < 4.0);
//! # Ok::<(), fuzzyq_sim::SimError>(())
//! ```
#![deny(missing_docs)]

pub mod compare;
pub mod error;
pub mod fs;
pub mod io;
pub mod learn;
pub mod memory;
pub mod model;
pub mod paper;
pub mod run;
pub mod slabs;
#[cfg(test)]
mod test_support;
mod toml_doc;
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

/// The Rust guide's examples (docs/site/rust/guide.md), compiled as doctests likewise.
#[cfg(doctest)]
#[doc = include_str!("../../../docs/site/rust/guide.md")]
pub struct RustGuideDoctests;
