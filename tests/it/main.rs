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
// The Python package's panic guard, plain `std`: its test runs here, so that the extension
// module needs no unit-test binary of its own (crates/fuzzyq-py/Cargo.toml).
#[path = "../../crates/fuzzyq-py/src/panics.rs"]
mod python_panics;
mod schemes;
mod sharded;
mod slabs;
mod solver;
mod table;
mod train_rollout;
