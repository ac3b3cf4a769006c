//! Learning from samples: model-free fuzzy Q-learning and VQQL.

pub mod fql;
pub mod tasks;
pub mod vqql;
