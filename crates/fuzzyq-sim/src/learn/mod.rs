//! Learning from samples: model-free fuzzy Q-learning and VQQL, the tasks as learning
//! environments, and the learned fuzzy model that fuzzy Q-iteration solves.
//!
//! - [`env`](mod@env): the episodic [`env::Environment`] a learner interacts with;
//! - [`features`]: fuzzy partitions or codebooks turning observations into active cells;
//! - [`codebook`]: VQQL's vector quantisers (exact k-d tree lookups);
//! - [`additive`]: the additive Q-function and its sample update (the core's arithmetic);
//! - [`fql`]: the learning loop (exploration, schedules, evaluations, convergence, curves);
//! - [`fitted`]: fuzzy Q-iteration from samples (batch fitted Q-iteration with the fuzzy
//!   averager, per agent);
//! - [`vqql`]: the Generalized Lloyd algorithm and VQQL on the point masses;
//! - [`tasks`]: the point masses and the robots as learning environments;
//! - [`samples`]: transitions `(x, u, x', r)` and their collection from a plant;
//! - [`fit`]: the learned fuzzy model, block transition tables estimated from transitions;
//! - [`reward`]: rewards at the cores estimated from transitions (a system without a known
//!   reward function).

pub mod additive;
pub mod codebook;
pub mod env;
pub mod features;
pub mod fit;
pub mod fitted;
pub mod fql;
pub mod reward;
pub mod samples;
pub mod tasks;
pub mod vqql;
