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
            tacmesh::log_sink::eprint_line(&format!("tacmesh: error: {}", error_chain(&err)));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes, `: `-separated, as anyhow's `{:#}` prints them, except that a
/// cause whose text the line already holds is left out. Many library errors say their cause
/// in their own message (so that a log line of them is complete) and also return it as their
/// source; printed as a chain, the cause came twice: `… (os error 2): No such file or
/// directory (os error 2)`.
fn error_chain(err: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot open /dev/video9: {source}")]
    struct OpenError {
        source: std::io::Error,
    }

    #[test]
    fn a_cause_already_in_the_message_is_printed_once() {
        let io = std::io::Error::from(std::io::ErrorKind::NotFound);
        let err = anyhow::Error::new(OpenError { source: io }).context("the sensor");
        let line = error_chain(&err);
        assert_eq!(line.matches("entity not found").count(), 1, "{line}");
        assert!(
            line.starts_with("the sensor: cannot open /dev/video9"),
            "{line}"
        );
    }

    #[test]
    fn causes_not_in_the_message_are_all_printed() {
        let err = anyhow::anyhow!("inner").context("middle").context("outer");
        assert_eq!(error_chain(&err), "outer: middle: inner");
    }
}
