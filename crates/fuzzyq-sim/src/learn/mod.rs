//! Learning from samples: model-free fuzzy Q-learning and VQQL, and the tasks as learning
//! environments.
//!
//! - [`env`](mod@env): the episodic [`env::Environment`] a learner interacts with;
//! - [`features`]: fuzzy partitions or codebooks turning observations into active cells;
//! - [`codebook`]: VQQL's vector quantisers (exact k-d tree lookups);
//! - [`additive`]: the additive Q-function and its sample update (the core's arithmetic);
//! - [`fql`]: the learning loop (exploration, schedules, evaluations, convergence, curves);
//! - [`vqql`]: the Generalized Lloyd algorithm and VQQL on the point masses;
//! - [`tasks`]: the point masses and the robots as learning environments.

pub mod additive;
pub mod codebook;
pub mod env;
pub mod features;
pub mod fql;
pub mod tasks;
pub mod vqql;
