//! The command-line reference of the documentation site (docs/site/cli/reference.md) is the
//! command line's own help, every subcommand's: generated from the clap definitions and
//! compared here, so that it cannot drift. `FUZZYQ_BLESS=1` rewrites it.

use std::path::Path;

use clap::CommandFactory;

/// The reference page: the top-level help, then every subcommand's long help (`--help`).
fn reference() -> String {
    let mut cli = fuzzyq_cli::Cli::command().term_width(100);
    cli.build();
    let mut page = String::from(
        "# Command-line reference\n\n\
         Every subcommand of `fuzzyq` and its flags, as `fuzzyq <command> --help` prints them. \
         This page is generated from the command line's definitions by \
         `cargo test -p fuzzyq-cli --test cli -- reference` (set `FUZZYQ_BLESS=1` to rewrite \
         it), which fails when the two differ. The [guide](guide.md) shows the commands at \
         work.\n",
    );
    let mut section = |title: &str, help: String| {
        page.push_str(&format!(
            "\n## {title}\n\n```text\n{}\n```\n",
            help.trim_end()
        ));
    };
    section("fuzzyq", cli.render_long_help().to_string());
    for sub in cli.get_subcommands_mut() {
        let title = format!("fuzzyq {}", sub.get_name());
        section(&title, sub.render_long_help().to_string());
    }
    page
}

#[test]
fn cli_reference_is_the_commands_help() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/site/cli/reference.md");
    let want = reference();
    if std::env::var_os("FUZZYQ_BLESS").is_some() {
        std::fs::write(&path, &want).expect("write the reference");
        return;
    }
    let have = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        have == want,
        "{} is not the command line's help: run \
         `FUZZYQ_BLESS=1 cargo test -p fuzzyq-cli --test cli -- reference` and commit it",
        path.display()
    );
}
