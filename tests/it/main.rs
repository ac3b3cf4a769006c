//! Integration and property tests of fuzzyq: one binary, several modules.

mod alloc_count;
mod approxrl;
mod coarse;
mod export;
mod fuzz;
mod gpu;
mod khepera;
mod learned;
mod memberships;
mod sharded;
mod slabs;
mod solver;
mod table;
mod train_rollout;
