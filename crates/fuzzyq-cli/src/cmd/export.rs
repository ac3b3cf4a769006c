//! `fuzzyq export`: a fuzzy Q-iteration policy in the compact format the `no_std` core reads
//! in place (`fuzzyq_core::view::PolicyView`), or as a Rust module of `static` arrays.

use std::path::PathBuf;

use anyhow::bail;
use clap::{Args, ValueEnum};
use fuzzyq_sim::io::export::{ExportOptions, export_bytes, export_rust};
use fuzzyq_sim::io::policy_file::PolicyFile;

use crate::output;

#[derive(Args, Debug)]
pub(crate) struct ExportArgs {
    /// The policy file (fuzzy Q-iteration, as `fuzzyq train` writes it).
    #[arg(long, value_name = "POLICY")]
    policy: PathBuf,
    /// Where to write the exported policy.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// The form: the binary file `PolicyView::parse` reads in place (for `include_bytes!` or
    /// flash), or a Rust module of `static` arrays with a `view()` function.
    #[arg(long, value_enum, default_value_t = Format::Bin)]
    format: Format,
    /// Leave `V` out: the interpolated policy needs only the greedy actions.
    #[arg(long, conflicts_with = "greedy")]
    no_values: bool,
    /// Also write the decision tables (the model's block tables and the rewards), so that the
    /// controller takes greedy decisions without the model (block-path models without
    /// terminal states or an absorbing goal, such as the point masses; binary format only).
    #[arg(long)]
    greedy: bool,
}

/// The forms of an exported policy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Format {
    /// The compact binary format (fuzzyq_core::view).
    Bin,
    /// A Rust module of static arrays (for `mod policy;`).
    Rust,
}

pub(crate) fn run(args: ExportArgs) -> anyhow::Result<()> {
    output::plan(
        &[(Some(&args.out), "--out")],
        &[(Some(&args.policy), "--policy")],
    )?;
    if args.greedy && args.format == Format::Rust {
        bail!("--greedy: the decision tables are written in the binary format only (--format bin)");
    }
    let PolicyFile::Fqi(artifact) = PolicyFile::load(&args.policy)? else {
        bail!(
            "--policy {}: only fuzzy Q-iteration policies can be exported (this one was learned \
             from samples)",
            args.policy.display()
        );
    };
    let bytes = match args.format {
        Format::Bin => export_bytes(
            &artifact,
            ExportOptions {
                values: !args.no_values,
                decisions: args.greedy,
            },
        )?,
        Format::Rust => export_rust(&artifact, !args.no_values)?.into_bytes(),
    };
    output::write_file(&args.out, &bytes)?;
    eprintln!(
        "exported {} to {}: {} bytes{} ({} cores{})",
        args.policy.display(),
        args.out.display(),
        bytes.len(),
        if args.format == Format::Rust {
            " of Rust"
        } else {
            ""
        },
        artifact.greedy.len(),
        if args.no_values {
            ", without V"
        } else if args.greedy {
            ", with V and the decision tables"
        } else {
            ", with V"
        }
    );
    Ok(())
}
