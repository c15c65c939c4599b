//! Helpers that let the tests read like shell scripts.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `tacmesh` with `args`; returns its output whatever the exit status.
pub fn tacmesh(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(args)
        .env("RUST_LOG", "warn")
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

/// A file in the shared test data (`../shared/data` beside the repository).
pub fn shared_data(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(relative)
}

pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}
