//! What every subcommand shares: flag parsing helpers and the output files, written as one
//! transaction ([`transaction`]).

mod transaction;

use std::path::Path;

pub(crate) use transaction::{commit, discard, plan, stage};

use anyhow::Context;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use fuzzyq_core::NamedOption;
use fuzzyq_sim::model::EnvKind;

/// A clap value parser for a named option of the library: its values, each with its help
/// line, come from the option's one declaration ([`NamedOption::ALL`]).
pub(crate) fn named<E: NamedOption + Send + Sync + Clone>() -> impl TypedValueParser<Value = E> {
    PossibleValuesParser::new(
        E::ALL
            .iter()
            .map(|v| PossibleValue::new(v.name()).help(v.help())),
    )
    .map(|s| E::from_name(&s).expect("clap checked the value"))
}

/// The `--env` parser: the registry's environments, with their presets in the help.
pub(crate) fn env() -> impl TypedValueParser<Value = EnvKind> {
    PossibleValuesParser::new(
        EnvKind::ALL
            .iter()
            .map(|v| PossibleValue::new(v.name()).help(v.help_line())),
    )
    .map(|s| EnvKind::from_name(&s).expect("clap checked the value"))
}

/// Parses `-4,-6,-2,2` (also with spaces or surrounding brackets) given to `flag`.
pub(crate) fn parse_list(text: &str, flag: &str) -> anyhow::Result<Vec<f64>> {
    let t = text.trim().trim_start_matches('[').trim_end_matches(']');
    t.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .enumerate()
        .map(|(i, s)| {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{flag}: value {} ({s:?}) is not a finite number", i + 1))
        })
        .collect()
}

/// Refuses a run whose memory `estimate` exceeds the limit: `--max-memory GB` if given
/// (`max_memory_gb`), else 90% of the machine's memory; the message names the flag.
pub(crate) fn check_memory(
    max_memory_gb: Option<f64>,
    estimate: &fuzzyq_sim::memory::Estimate,
) -> anyhow::Result<()> {
    let limit = fuzzyq_sim::memory::Limit::new(max_memory_gb)
        .map_err(|_| anyhow::anyhow!("--max-memory must be a positive number of GB"))?;
    limit
        .check(estimate)
        .map_err(|e| anyhow::anyhow!("{e}; --max-memory GB raises the limit"))
}

/// The memory of rolling out `runs` runs of `steps` steps with `threads` threads on a task
/// with `state_dim` state variables and `action_dim` action components: each thread keeps one
/// trajectory (state, action, reward and the written rows per step), each run its metrics.
pub(crate) fn rollout_estimate(
    runs: usize,
    steps: usize,
    threads: usize,
    state_dim: usize,
    action_dim: usize,
) -> fuzzyq_sim::memory::Estimate {
    let per_step = 3.0 * 8.0 * (state_dim + action_dim + 2) as f64;
    let per_run = 64.0 * (state_dim + 8) as f64;
    let mut e = fuzzyq_sim::memory::rollouts(runs as f64, steps as f64, 0.0, per_run);
    e.bytes += (threads.min(runs.max(1))) as f64 * steps as f64 * per_step;
    e
}

/// Fails naming `flag` if it was given (`set`) where it does not apply (`why`).
pub(crate) fn refuse(set: bool, flag: &str, why: &str) -> anyhow::Result<()> {
    if set {
        anyhow::bail!("{flag} {why}");
    }
    Ok(())
}

/// Writes `text` to stdout.
pub(crate) fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())?;
    out.flush()?;
    Ok(())
}

/// Whether an error is a broken pipe on stdout (a normal end: `fuzzyq ... | head`).
pub(crate) fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Collapses a message to one line.
pub(crate) fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Stages `bytes` as the content of the output `path` (planned with [`plan`]); it is put in
/// place when the command succeeds.
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    transaction::stage_bytes(path, bytes)
}

/// Stages the policy `file` as the output `path` ([`write_file`]), encoded as it is written:
/// no copy of it is held (three point masses on the paper's cores make a 48 GB policy).
pub(crate) fn write_policy(
    path: &Path,
    file: &fuzzyq_sim::io::policy_file::PolicyFile,
) -> anyhow::Result<()> {
    transaction::stage(path, |tmp| {
        file.write_to(std::fs::File::create(tmp)?)
            .with_context(|| format!("cannot write the policy {}", path.display()))?;
        Ok(())
    })
}

/// Stages `value` as pretty JSON for the output `path` ([`write_file`]).
pub(crate) fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    write_file(path, text.as_bytes())
}

/// Sets a flag on Ctrl-C; a second Ctrl-C while the first is being honoured ends the process.
pub(crate) fn interrupt_flag() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let _ = ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    });
    stop
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_x0_forms() {
        assert_eq!(
            parse_list("-4,-6,2", "--x0").unwrap(),
            vec![-4.0, -6.0, 2.0]
        );
        assert_eq!(parse_list("[1, 2.5]", "--x0").unwrap(), vec![1.0, 2.5]);
        let e = parse_list("1,x", "--headings").unwrap_err().to_string();
        assert!(e.starts_with("--headings: value 2"), "{e}");
        assert!(parse_list("1,nan", "--x0").is_err());
    }
}
