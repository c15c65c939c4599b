//! Who the socket belongs to: a second local user can neither squat the default socket path
//! nor make a client accept the meshes of a daemon it runs (docs/operating.md, "Security").
//!
//! The other user is `nobody` (uid 65534): the tests that need one run only as root, which can
//! start a process as another user, and say so when skipped.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::util::path_str;

const NOBODY: u32 = 65534;

fn running_as_root() -> bool {
    std::fs::metadata("/proc/self").expect("procfs").uid() == 0
}

/// `tacmesh` with `args` and environment `env`, without a runtime directory, logging warnings.
fn tacmesh_env(args: &[&str], env: &[(&str, &Path)]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_tacmesh"));
    command
        .args(args)
        .env_remove("XDG_RUNTIME_DIR")
        .env("RUST_LOG", "warn");
    for (key, value) in env {
        command.env(key, value);
    }
    command.output().expect("the tacmesh binary runs")
}

/// A daemon on the demo scene run by `nobody`, from a copy of the binary `nobody` can read
/// (the build's own folder may be private), on a socket in a folder that is `nobody`'s.
struct Impostor {
    child: Child,
    socket: PathBuf,
    _dir: tempfile::TempDir,
}

impl Impostor {
    fn start() -> Impostor {
        use std::os::unix::process::CommandExt;
        let dir = tempfile::tempdir().expect("a temporary folder");
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        let binary = dir.path().join("tacmesh");
        std::fs::copy(env!("CARGO_BIN_EXE_tacmesh"), &binary).expect("the binary copied");
        let home = dir.path().join("home");
        std::fs::create_dir(&home).unwrap();
        std::os::unix::fs::chown(&home, Some(NOBODY), Some(NOBODY)).unwrap();
        let socket = home.join("t.sock");
        let child = Command::new(&binary)
            .args(["run", "--sensor", "sim:demo", "--socket", path_str(&socket)])
            .env("RUST_LOG", "warn")
            .env_remove("XDG_RUNTIME_DIR")
            .uid(NOBODY)
            .gid(NOBODY)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("the impostor starts");
        let deadline = Instant::now() + Duration::from_secs(120);
        while !socket.exists() {
            assert!(
                Instant::now() < deadline,
                "the impostor did not serve within 120 s"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        Impostor {
            child,
            socket,
            _dir: dir,
        }
    }
}

impl Drop for Impostor {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn a_client_refuses_a_daemon_run_by_another_user_unless_told_to_trust_it() {
    if !running_as_root() {
        eprintln!("skipped: only root can start a daemon as another user");
        return;
    }
    let impostor = Impostor::start();
    let socket = path_str(&impostor.socket);
    let refused = tacmesh_env(&["subscribe", "--socket", socket, "--count", "1"], &[]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("served by uid 65534 (nobody)") && stderr.contains("--trust-uid 65534"),
        "{stderr}"
    );
    assert!(
        refused.stdout.is_empty(),
        "the refused client printed: {}",
        String::from_utf8_lossy(&refused.stdout)
    );

    let trusting = tacmesh_env(
        &[
            "subscribe",
            "--socket",
            socket,
            "--count",
            "1",
            "--trust-uid",
            "65534",
        ],
        &[],
    );
    let stdout = String::from_utf8_lossy(&trusting.stdout);
    assert!(
        trusting.status.success(),
        "{}",
        String::from_utf8_lossy(&trusting.stderr)
    );
    assert!(stdout.contains("connected to"), "{stdout}");
}

/// `nobody` made the fallback socket directory of root first (as `/tmp/tacmesh-0`): the
/// daemon will not serve in it and the client will not connect through it, each saying whose
/// it is.
#[test]
fn a_default_socket_directory_another_user_made_is_refused_by_daemon_and_client() {
    if !running_as_root() {
        eprintln!("skipped: only root can give a directory to another user");
        return;
    }
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let squatted = tmp.path().join("tacmesh-0");
    std::fs::create_dir(&squatted).unwrap();
    std::fs::set_permissions(&squatted, std::fs::Permissions::from_mode(0o700)).unwrap();
    std::os::unix::fs::chown(&squatted, Some(NOBODY), Some(NOBODY)).unwrap();
    let env = [("TMPDIR", tmp.path())];
    let daemon = tacmesh_env(&["run", "--sensor", "sim:demo", "--duration-s", "5"], &env);
    let client = tacmesh_env(&["subscribe", "--count", "1"], &env);
    for (what, out) in [("run", daemon), ("subscribe", client)] {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{what} used the squatted directory");
        assert!(
            stderr.contains("belongs to uid 65534") && stderr.contains("impersonating"),
            "{what}: {stderr}"
        );
    }
    assert_eq!(std::fs::read_dir(&squatted).unwrap().count(), 0);
}

/// Without a runtime directory the daemon makes its socket directory private (0700, its own)
/// and removes the socket when it stops; any user can check this.
#[test]
fn the_default_socket_directory_is_made_private() {
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let env = [("TMPDIR", tmp.path())];
    let out = tacmesh_env(
        &["run", "--sensor", "sim:demo", "--duration-s", "0.5"],
        &env,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let uid = std::fs::metadata("/proc/self").expect("procfs").uid();
    let dir = tmp.path().join(format!("tacmesh-{uid}"));
    let metadata = std::fs::symlink_metadata(&dir).expect("the private directory was made");
    assert!(metadata.is_dir());
    assert_eq!(metadata.mode() & 0o7777, 0o700);
    assert_eq!(metadata.uid(), uid);
    assert!(!dir.join("tacmesh.sock").exists(), "the socket was left");
}
