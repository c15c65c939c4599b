//! Helpers that let the tests read like shell scripts.

use std::path::Path;
use std::process::{Command, Output};

/// Runs `tacmesh` with `args`; returns its output whatever the exit status.
pub fn tacmesh(args: &[&str]) -> Output {
    tacmesh_logging(args, "warn")
}

/// As [`tacmesh`], logging at `level` (a `RUST_LOG` filter) on standard error.
pub fn tacmesh_logging(args: &[&str], level: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(args)
        .env("RUST_LOG", level)
        .output()
        .expect("the tacmesh binary runs")
}

/// Runs `tacmesh` and insists it succeeds; returns standard output.
pub fn tacmesh_ok(args: &[&str]) -> String {
    let out = tacmesh(args);
    assert!(
        out.status.success(),
        "tacmesh {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("stdout is UTF-8")
}

/// Runs `tacmesh ... --json` and parses its one JSON object.
pub fn tacmesh_json(args: &[&str]) -> serde_json::Value {
    let stdout = tacmesh_ok(args);
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("not JSON ({e}): {stdout}"))
}

/// A file in the repository's test data (`testdata/`, see its SOURCES.md); a missing one fails
/// the test naming the file and where it should be.
pub use tacmesh_testdata::path as test_data;

pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}

/// Sends SIGTERM to `child` and waits for it to exit; returns the exit status and how long the
/// exit took. Fails after `hang_guard`: a guard against a hang, not a performance bound.
pub fn terminate(
    child: &mut std::process::Child,
    hang_guard: std::time::Duration,
) -> (std::process::ExitStatus, std::time::Duration) {
    let sent = std::time::Instant::now();
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(kill.success());
    loop {
        if let Some(status) = child.try_wait().expect("waits") {
            return (status, sent.elapsed());
        }
        assert!(sent.elapsed() < hang_guard, "no exit after SIGTERM");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}
