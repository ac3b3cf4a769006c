//! The subcommands, one file each.

pub(crate) mod bench;
mod checkpoints;
pub(crate) mod compare;
pub(crate) mod config;
pub(crate) mod export;
pub(crate) mod rollout;
pub(crate) mod train;
