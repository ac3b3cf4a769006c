//! Acting: policies, rollouts and their evaluation.

pub mod evaluate;
pub mod policy;
pub mod robots;
pub mod rollout;
