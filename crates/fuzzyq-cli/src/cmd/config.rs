//! `fuzzyq config`.

use clap::Args;
use fuzzyq_sim::TrainConfig;
use fuzzyq_sim::model::EnvKind;

use crate::output::{self, print_stdout};

#[derive(Args, Debug)]
pub(crate) struct ConfigArgs {
    /// The environment.
    #[arg(long, value_parser = output::env(), default_value = "pointmass")]
    env: EnvKind,
    /// A classic benchmark's named grid, actions, gamma and xi [default: fine].
    #[arg(long, value_name = "NAME")]
    preset: Option<String>,
}

pub(crate) fn run(args: ConfigArgs) -> anyhow::Result<()> {
    print_stdout(&TrainConfig::default_toml(
        args.env,
        args.preset.as_deref(),
    )?)
}
