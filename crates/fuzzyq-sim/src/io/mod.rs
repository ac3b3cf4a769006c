//! Files: training configurations and policy files.

pub mod config;
pub mod policy_file;
