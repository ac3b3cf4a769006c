//! `fuzzyq`: train fuzzy Q-iteration policies, roll them out, plot them.
//!
//! Every error is printed as one line on stderr and exits with code 2 (130 when Ctrl-C stops
//! a training run). Output files are written atomically: a failure never leaves a
//! half-written file.

mod compare;
mod plot;
mod rollout;
mod train;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};

/// Multi-agent fuzzy Q-iteration (Luviano-Cruz et al. 2018) for continuous-state robots.
#[derive(Parser, Debug)]
#[command(name = "fuzzyq", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Train a joint fuzzy Q-function by fuzzy Q-iteration and write the policy file.
    Train(train::TrainArgs),
    /// Run a trained policy from an initial state; write the trajectory, figures and metrics.
    Rollout(rollout::RolloutArgs),
    /// Rerun the paper's Table 1: train fuzzy and crisp learners on the point-mass task, roll
    /// each out from the same start and random starts, write the table and figures.
    Compare(compare::CompareArgs),
    /// Print an environment's default configuration (the paper's values) as TOML.
    Config {
        /// The environment.
        #[arg(long, value_enum, default_value_t = Env::Pointmass)]
        env: Env,
        /// dcmotor, pendulum: the named grid, actions, gamma and xi [default: fine].
        #[arg(long, value_name = "NAME")]
        preset: Option<String>,
    },
}

/// The environments.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Env {
    /// Point masses on the plane (paper section 3.1).
    Pointmass,
    /// Two Khepera IV robots with sonars (paper sections 3.2-3.3).
    Khepera,
    /// The DC motor of the classic benchmarks (presets: toolbox-demo, fine).
    Dcmotor,
    /// The inverted pendulum swing-up (presets: toolbox-demo, fine).
    Pendulum,
    /// The car on the hill (presets: fine, coarse).
    Carhill,
    /// The two-link robot arm (presets: fine, coarse).
    Arm,
}

impl Env {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Pointmass => "pointmass",
            Self::Khepera => "khepera",
            Self::Dcmotor => "dcmotor",
            Self::Pendulum => "pendulum",
            Self::Carhill => "carhill",
            Self::Arm => "arm",
        }
    }
}

/// Why the program stops with a non-zero exit code.
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

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // Help and version go to stdout with code 0; usage errors exit with 2.
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if is_broken_pipe(&e) {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {}", one_line(&format!("{e:#}")));
            match e.downcast_ref::<Failure>() {
                Some(Failure::Interrupted(_)) => ExitCode::from(130),
                None => ExitCode::from(2),
            }
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Train(args) => train::run(args),
        Command::Rollout(args) => rollout::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Config { env, preset } => {
            use fuzzyq_sim::io::config::TrainConfig;
            match (env, preset) {
                (Env::Pointmass | Env::Khepera, Some(_)) => {
                    anyhow::bail!("--preset applies to --env dcmotor or pendulum only")
                }
                (Env::Pointmass | Env::Khepera, None) => {
                    print_stdout(TrainConfig::default_toml(env.name())?)?;
                }
                (_, preset) => {
                    let name = preset
                        .as_deref()
                        .unwrap_or(fuzzyq_sim::io::config::DEFAULT_PRESET);
                    let c = TrainConfig::from_preset(env.name(), name)?;
                    print_stdout(&format!(
                        "# fuzzyq training configuration: {}, preset \"{name}\".\n\
                         # Edit and pass back with `fuzzyq train --env {} --config FILE.toml`.\n\n{}",
                        env.name(),
                        env.name(),
                        c.to_toml()
                    ))?;
                }
            }
            Ok(())
        }
    }
}

pub(crate) fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())?;
    out.flush()?;
    Ok(())
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Collapses a message to one line.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Checks, before any long work, that `path` can be created: its directory exists and
/// accepts a new file. Nothing is left behind.
pub(crate) fn check_writable(path: &Path, what: &str) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if path.is_dir() {
        anyhow::bail!("{what} {} is a directory", path.display());
    }
    if !dir.is_dir() {
        anyhow::bail!(
            "{what} {}: directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    tempfile_probe(&dir).with_context(|| format!("{what} {}: cannot write there", path.display()))
}

fn tempfile_probe(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(format!(".fuzzyq-probe-{}", std::process::id()));
    std::fs::File::create(&probe)?;
    std::fs::remove_file(&probe)
}

/// Writes a file atomically, naming it in the error.
pub(crate) fn write_file(path: &Path, bytes: &[u8], what: &str) -> anyhow::Result<()> {
    fuzzyq_sim::io::policy_file::write_atomically(path, bytes)
        .with_context(|| format!("cannot write {what} {}", path.display()))
}

/// Serialises `value` as pretty JSON into `path`, atomically.
pub(crate) fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    write_file(path, text.as_bytes(), "JSON")
}
