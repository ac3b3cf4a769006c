//! The `fuzzyq` command line: train fuzzy Q-iteration policies, roll them out, plot them.
//!
//! The crate is the binary `fuzzyq` and this library, whose [`run`] is the whole program (the
//! Python package calls it for its own `fuzzyq` command); [`Cli`] is its clap definition,
//! from which the command-line reference (docs/site/cli/reference.md) is generated.
//!
//! Every error is printed as one line on stderr and exits with code 2 (130 when Ctrl-C stops
//! a training run). A command's output files are one transaction (`output::transaction`):
//! planned before any work (no output over another or over an input), staged in full, and put
//! in place only when the command has succeeded, so a failure replaces no file.
//!
//! - `cmd/`: one file per subcommand (`train`, `rollout`, `compare`, `config`, `bench`,
//!   `export`); each parses
//!   its flags with clap, turns them into the library's validated settings in one place, and
//!   writes its outputs;
//! - `output/`: what every subcommand shares to read flags and write files;
//! - `plot/`: the figures, one file per figure kind.

mod cmd;
mod output;
mod plot;

use std::ffi::OsString;

use clap::{Parser, Subcommand};

/// Multi-agent fuzzy Q-iteration (Luviano-Cruz et al. 2018) for continuous-state robots.
#[derive(Parser, Debug)]
#[command(name = "fuzzyq", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Train a policy (fuzzy Q-iteration by default) and write the policy file.
    Train(Box<cmd::train::TrainArgs>),
    /// Run a trained policy from an initial state; write the trajectory, figures and metrics.
    Rollout(cmd::rollout::RolloutArgs),
    /// Rerun the paper's Table 1: train fuzzy and crisp learners on the point-mass task, roll
    /// each out from the same start and random starts, write the table and figures.
    Compare(cmd::compare::CompareArgs),
    /// Print an environment's default configuration (the paper's values) as TOML.
    Config(cmd::config::ConfigArgs),
    /// Export a fuzzy Q-iteration policy in the compact format a `no_std` controller reads in
    /// place (`fuzzyq_core::view::PolicyView`).
    Export(cmd::export::ExportArgs),
    /// Know the machine: CPU, caches, kernels, the measured multiply-add peak, and the
    /// solver's full backups on a problem (the paper's by default) as a fraction of it.
    Bench(cmd::bench::BenchArgs),
}

/// Why the program stops with a non-zero exit code other than 2.
#[derive(Debug)]
pub(crate) enum Failure {
    /// Ctrl-C stopped a long run.
    Interrupted(String),
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Interrupted(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Failure {}

/// Runs the command line on `args` (the program's name first, as `std::env::args_os`) and
/// returns its exit code: 0 on success (help and version too), 2 for any error (one line on
/// stderr), 130 when Ctrl-C stopped a training run. The `fuzzyq` binary and the Python
/// package's `fuzzyq` command (`python -m fuzzyq`) both call this.
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        // Help and version go to stdout with code 0.
        Err(e) if !e.use_stderr() => {
            let _ = e.print();
            return 0;
        }
        // Usage errors are one line (with the possible values where clap lists them), code 2.
        Err(e) => {
            let text = e.render().to_string();
            let first = text.split("\n\n").next().unwrap_or_default();
            eprintln!("{}", output::one_line(first));
            return 2;
        }
    };
    let result = match cli.command {
        Command::Train(args) => cmd::train::run(*args),
        Command::Rollout(args) => cmd::rollout::run(args),
        Command::Compare(args) => cmd::compare::run(args),
        Command::Config(args) => cmd::config::run(args),
        Command::Bench(args) => cmd::bench::run(args),
        Command::Export(args) => cmd::export::run(args),
    };
    // The outputs go in place only when the whole command has succeeded.
    // A closed stdout (`fuzzyq ... | head`) is a normal end: what was written stays.
    let result = match result {
        Ok(()) => output::commit(),
        Err(e) if output::is_broken_pipe(&e) => output::commit().and(Err(e)),
        Err(e) => {
            output::discard();
            Err(e)
        }
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            if output::is_broken_pipe(&e) {
                return 0;
            }
            eprintln!("error: {}", output::one_line(&format!("{e:#}")));
            match e.downcast_ref::<Failure>() {
                Some(Failure::Interrupted(_)) => 130,
                None => 2,
            }
        }
    }
}
