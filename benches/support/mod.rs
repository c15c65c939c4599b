//! What the daemon benchmarks share: starting the real `tacmesh run` (this profile's build) on
//! a socket in a temporary folder, and reading its memory from /proc.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running daemon and the folder its socket lives in (removed on drop).
pub struct RunningDaemon {
    pub child: Child,
    pub socket: PathBuf,
    /// Kept so that the folder outlives the daemon.
    pub dir: tempfile::TempDir,
}

/// Starts `tacmesh run --sensor SENSOR --socket … EXTRA…` and waits until its socket exists.
pub fn start_daemon(sensor: &str, extra: &[&str]) -> RunningDaemon {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let socket = dir.path().join("bench.sock");
    let mut child = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["run", "--sensor", sensor, "--socket"])
        .arg(&socket)
        .args(extra)
        // The caller's log filter if it set one (a stage's debug lines), else the default.
        .env(
            "RUST_LOG",
            std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()),
        )
        .stderr(Stdio::inherit())
        .spawn()
        .expect("tacmesh runs");
    let started = Instant::now();
    while !socket.exists() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("tacmesh run exited before binding its socket: {status}");
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "daemon never bound its socket"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    RunningDaemon { child, socket, dir }
}

/// A `kB` field of /proc/PID/status (`VmRSS`, `VmHWM`…) in KiB; `None` once the process is
/// gone.
pub fn proc_status_kib(pid: u32, field: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status.lines().find_map(|line| {
        let value = line.strip_prefix(field)?.strip_prefix(':')?;
        value.trim().trim_end_matches("kB").trim().parse().ok()
    })
}
