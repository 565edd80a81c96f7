//! `ribreg`: command line of the ribreg toolkit. See `ribreg --help` and `cli`.

use clap::Parser;
use std::process::ExitCode;

mod cli;

fn main() -> ExitCode {
    match cli::Cli::parse().run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Every error class exits with 2 (README, "Command line").
            eprintln!("ribreg: error: {e}");
            ExitCode::from(2)
        }
    }
}
