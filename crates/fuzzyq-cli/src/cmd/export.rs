//! `fuzzyq export`: a fuzzy Q-iteration policy in the compact format the `no_std` core reads
//! in place (`fuzzyq_core::view::PolicyView`).

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;
use fuzzyq_sim::io::export::export_bytes;
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
    /// Leave `V` out: the interpolated policy needs only the greedy actions.
    #[arg(long)]
    no_values: bool,
}

pub(crate) fn run(args: ExportArgs) -> anyhow::Result<()> {
    output::plan(
        &[(Some(&args.out), "--out")],
        &[(Some(&args.policy), "--policy")],
    )?;
    let PolicyFile::Fqi(artifact) = PolicyFile::load(&args.policy)? else {
        bail!(
            "--policy {}: only fuzzy Q-iteration policies can be exported (this one was learned \
             from samples)",
            args.policy.display()
        );
    };
    let bytes = export_bytes(&artifact, !args.no_values)?;
    output::write_file(&args.out, &bytes)?;
    eprintln!(
        "exported {} to {}: {} bytes ({} cores{})",
        args.policy.display(),
        args.out.display(),
        bytes.len(),
        artifact.greedy.len(),
        if args.no_values {
            ", without V"
        } else {
            ", with V"
        }
    );
    Ok(())
}
