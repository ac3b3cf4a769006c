//! The subcommands, one file each.

pub(crate) mod bench;
mod checkpoints;
pub(crate) mod compare;
pub(crate) mod config;
pub(crate) mod export;
pub(crate) mod rollout;
pub(crate) mod train;

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use fuzzyq_sim::TrainConfig;
use fuzzyq_sim::model::EnvKind;

use crate::output;

/// The task a command trains or times: an environment's default configuration, a classic
/// benchmark's preset, or a configuration file (`train` and `bench` share these flags).
#[derive(Args, Debug)]
pub(crate) struct TaskArgs {
    /// The environment.
    #[arg(long, value_parser = output::env(), default_value = "pointmass")]
    pub(crate) env: EnvKind,
    /// A TOML configuration (see `fuzzyq config`); flags below override its values.
    #[arg(long, value_name = "FILE.toml")]
    pub(crate) config: Option<PathBuf>,
    /// A classic benchmark's named grid, actions, gamma and xi (`toolbox-demo`: the toolbox
    /// demo's coarse grid; `fine`: the toolbox's default fine grid) [default: fine].
    #[arg(long, value_name = "NAME")]
    pub(crate) preset: Option<String>,
}

impl TaskArgs {
    /// The task's configuration, before any other flag.
    pub(crate) fn load(&self) -> anyhow::Result<TrainConfig> {
        load_config(self.config.as_deref(), self.env, self.preset.as_deref())
    }
}

/// The configuration file `path` (or the defaults of `env`, or its named preset), which must
/// describe `env`.
pub(crate) fn load_config(
    path: Option<&Path>,
    env: EnvKind,
    preset: Option<&str>,
) -> anyhow::Result<TrainConfig> {
    let config = match (path, preset) {
        (Some(_), Some(_)) => anyhow::bail!("give either --config or --preset, not both"),
        (Some(path), None) => {
            let text = fuzzyq_sim::fs::read_text(path, fuzzyq_sim::fs::MAX_TEXT_BYTES)
                .with_context(|| format!("cannot read config {}", path.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("config {}", path.display()))?
        }
        (None, Some(p)) => TrainConfig::from_preset(env, p)?,
        (None, None) => TrainConfig::default_for(env)?,
    };
    if config.env.kind() != env {
        anyhow::bail!(
            "the config describes env \"{}\" but --env is {}",
            config.env.name(),
            env.name()
        );
    }
    Ok(config)
}

/// Starts the global thread pool with `threads` workers (default: one per core).
pub(crate) fn start_pool(threads: Option<usize>) -> anyhow::Result<()> {
    if let Some(n) = threads {
        fuzzyq_sim::train::check_threads(n).map_err(|e| anyhow::anyhow!("--threads: {e}"))?;
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot start the thread pool")?;
    }
    Ok(())
}
