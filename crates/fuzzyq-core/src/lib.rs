//! # fuzzyq-core
//!
//! The numeric core of fuzzyq: fuzzy Q-iteration with a linear fuzzy (triangular, product)
//! parameterisation of the joint Q-function, after Busoniu et al. and Luviano-Cruz et al. 2018.
//!
//! With default features the crate is `no_std` and never allocates: every function works on
//! slices the caller provides and reports bad input as a typed error. A robot controller can
//! embed it, hold its tables in `static` memory, and act in microseconds.
//!
//! ## The pieces
//! - [`Partition`] / [`ProductPartition`]: triangular memberships per state variable and their
//!   product, the fuzzy grid. [`ProductPartition::active`] finds the at most `2^E` active cores
//!   of a state.
//! - [`ActionSet`] / [`JointActions`]: per-agent discrete actions and the joint action set.
//! - [`Model`]: a deterministic model `f`, `rho` with optional independent dynamics blocks.
//! - [`q`]: Q evaluation for the `joint` layout, the greedy policy with lowest-index
//!   tie-breaking, and the interpolated policy of eq 22.
//! - [`additive`]: the `additive` layout (eqs 12-13 per agent) and the sample updates of its
//!   parameters (the corrected and the printed form of eqs 23-27): what a robot needs to
//!   learn on board.
//! - [`options`]: the named settings (sweep order, backup path, membership kind, update,
//!   policy kind, ...), each spelled once for files, the command line and Python.
//! - [`backup`]: the backup kernels (generic and per-block) on caller buffers.
//! - [`view`]: a trained policy exported by `fuzzyq-sim` (`io::export`), checked and borrowed
//!   in place from bytes (flash, `include_bytes!`): the interpolated policy without a heap.
//! - `solver` (feature `std`, parallel with `parallel`): the fuzzy Q-iteration driver that keeps
//!   only `V` and exploits the block structure of the dynamics.
//!
//! ## A first example
//! ```
//! use fuzzyq_core::{ActionSet, JointActions, ProductPartition, q};
//!
//! // One state variable with cores at -1, 0 and 1; one agent with actions -1 and +1.
//! let cores = [-1.0_f32, 0.0, 1.0];
//! let grid = ProductPartition::try_new(&[&cores[..]]).unwrap();
//! let actions = [-1.0_f32, 1.0];
//! let joint = JointActions::try_new(&[ActionSet::try_new(&actions, 1).unwrap()]).unwrap();
//!
//! // theta[d, u]: Q-values at the cores (stored row-major, one row per core).
//! let theta = [0.0, 1.0, /* core 0 */ 2.0, 2.0, /* core 1 */ 1.0, 0.0 /* core 2 */];
//! let mut qx = [0.0; 2];
//! q::q_values(&grid, &theta, &[0.5], &mut qx).unwrap();
//! assert_eq!(qx, [1.5, 1.0]);
//!
//! // Greedy (eq 7) and interpolated (eq 22) policies.
//! let u = q::greedy_action(&grid, &theta, &[0.5], &mut qx).unwrap();
//! assert_eq!(u, 0);
//! let greedy_per_core = [1, 0, 0];
//! let mut h = [0.0];
//! q::interpolated_action(&grid, &joint, &greedy_per_core, &[-0.5], &mut h).unwrap();
//! assert_eq!(h, [0.0]); // half of +1 (core -1) and half of -1 (core 0)
//! ```
//!
//! ## Conventions
//! - Joint cores are numbered row-major (last state variable fastest); joint actions
//!   mixed-radix with agent 0 most significant. Ties between actions go to the lowest index.
//! - Values outside a partition's cores saturate at the edge core.
//! - Results never depend on the number of threads: every sum runs in a fixed order and work
//!   is split only where the split cannot change a value.
#![cfg_attr(not(any(feature = "std", test)), no_std)]
#![deny(missing_docs)]

pub mod action;
pub mod additive;
pub mod backup;
pub mod error;
pub mod limits;
pub mod model;
pub mod options;
pub mod partition;
pub mod q;
pub mod real;
#[cfg(feature = "std")]
pub mod solver;
pub mod view;

pub use action::{ActionSet, JointActions};
pub use backup::Backup;
pub use error::{CoresError, EvalError, PartitionError};
pub use limits::{MAX_AGENTS, MAX_DIMS};
pub use model::{Block, BlockRows, Model, Tabulated};
pub use options::NamedOption;
pub use partition::{ActiveCores, Membership, Partition, ProductPartition, Segment};
pub use real::Real;
