//! `fuzzyq`: train fuzzy Q-iteration policies, roll them out, plot them (the library's
//! [`fuzzyq_cli::run`] on the program's arguments).

use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(fuzzyq_cli::run(std::env::args_os()))
}
