//! Integration and property tests of fuzzyq: one binary, several modules.

mod alloc_count;
mod approxrl;
mod coarse;
mod export;
mod fuzz;
mod gpu;
mod khepera;
mod large_grids;
mod learned;
mod memberships;
mod schemes;
mod sharded;
mod slabs;
mod solver;
mod table;
mod train_rollout;
