//! The tasks as learning environments.

pub mod khepera;
pub mod pointmass;
