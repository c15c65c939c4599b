//! Where log lines go: standard error, written so that a reader that went away costs log lines,
//! never the process.
//!
//! - [`StderrSink`]: the `tracing` writer; a failed write drops the line and counts it.
//! - [`dropped_lines`]: how many lines were lost so far (the daemon reports it in its counters
//!   and in its systemd STATUS line, which do not travel through standard error).
//! - [`eprint_line`]: one line to standard error for the binary's own messages, same rule.
//!
//! Why by hand: `std::io::stderr` itself is fine, but the macros around it are not. `eprintln!`
//! panics when the write fails (`failed printing to stderr: Broken pipe`), and tracing-
//! subscriber's fmt layer reports its own write failures with `eprintln!`, so a daemon started
//! as `tacmesh run 2>&1 | head -1`, or a service whose journald restarted, aborted on the next
//! log line (the release profile aborts on panic). SIGPIPE is ignored by the Rust runtime, so
//! the write returns `EPIPE` instead of killing the process; this module turns that error into
//! a count.

use std::io::{self, Write};
use std::sync::atomic::{AtomicU64, Ordering};

static DROPPED_LINES: AtomicU64 = AtomicU64::new(0);

/// Log lines (and binary messages) that could not be written to standard error.
pub fn dropped_lines() -> u64 {
    DROPPED_LINES.load(Ordering::Relaxed)
}

/// A `tracing_subscriber` writer for standard error that never fails: a write that cannot be
/// done is dropped and counted. Each event is formatted whole and written with one call, so a
/// line is either written or counted once.
#[derive(Debug, Clone, Copy, Default)]
pub struct StderrSink;

impl Write for StderrSink {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if io::stderr().lock().write_all(buf).is_err() {
            DROPPED_LINES.fetch_add(1, Ordering::Relaxed);
        }
        // Claim the whole buffer either way: the caller must not retry or report the failure.
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        // Standard error is unbuffered; a failure here would have shown in `write`.
        let _ = io::stderr().flush();
        Ok(())
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for StderrSink {
    type Writer = StderrSink;

    fn make_writer(&'a self) -> Self::Writer {
        StderrSink
    }
}

/// Writes `line` and a newline to standard error; a closed or broken standard error drops it
/// and counts it, as for log lines.
pub fn eprint_line(line: &str) {
    let mut sink = StderrSink;
    let _ = sink.write(format!("{line}\n").as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The writer swallows any buffer whole, so tracing-subscriber never sees an error to
    /// report (its report is an `eprintln!`, which panics on a broken pipe).
    #[test]
    fn stderr_sink_claims_every_byte() {
        let mut sink = StderrSink;
        assert_eq!(sink.write(b"").ok(), Some(0));
        assert_eq!(sink.write(b"a line\n").ok(), Some(7));
        assert!(sink.flush().is_ok());
    }
}
