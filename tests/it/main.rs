//! Integration and property tests of fuzzyq: one binary, several modules.

mod memberships;
mod solver;
mod train_rollout;
