//! The kernels' fixed capacities: they size stack buffers, so nothing needs a heap.

/// The largest number of state variables a [`ProductPartition`](crate::ProductPartition)
/// supports.
pub const MAX_DIMS: usize = 16;

/// The largest number of agents a [`JointActions`](crate::JointActions) supports.
pub const MAX_AGENTS: usize = 16;
