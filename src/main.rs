//! The `tacmesh` binary: argument parsing and exit codes; the work lives in the library.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    // Logging is set up by `cli::run`, once the command has read its config.
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            // One place reports errors: the chain says what failed and why. Not `eprintln!`,
            // which panics when standard error is closed.
            tacmesh::log_sink::eprint_line(&format!("tacmesh: error: {err:#}"));
            ExitCode::FAILURE
        }
    }
}
