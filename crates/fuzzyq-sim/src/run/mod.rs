//! Acting: policies, plants, the one rollout loop, and what runs achieved.
//!
//! - [`policy`]: every learner's policy ([`policy::Policy`]) and its controllers;
//! - [`plant`]: what a policy acts on (a model, the rapier point masses, the robots);
//! - [`rollout`]: the one controller x plant loop;
//! - [`metrics`]: a run's record and its measures, one place per task;
//! - [`evaluate`]: task-level runs (one start, many starts, Monte-Carlo lattices).

pub mod evaluate;
pub mod metrics;
pub mod plant;
pub mod policy;
pub mod rollout;
