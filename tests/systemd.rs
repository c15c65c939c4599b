//! tacmesh as systemd sees it: a real `tacmesh run` with `NOTIFY_SOCKET` pointing at a
//! datagram socket this test binds (as systemd does for `Type=notify`), `WATCHDOG_USEC` set
//! (as `WatchdogSec=` does) and standard error named as the journal stream (as
//! `JOURNAL_STREAM` does), checked for the notifications and the log format the units rely on.

use std::io::Read;
use std::os::unix::fs::MetadataExt;
use std::os::unix::net::{UnixDatagram, UnixStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use tacmesh::subscriber::Subscription;

use crate::daemon::ONE_DAEMON_AT_A_TIME;
use crate::util::path_str;

/// A small, cheap scene: a cube on a table seen by a 320 × 240 camera.
const SCENE: &str = r#"
[camera]
width = 320
height = 240
eye = [0.0, -0.8485, 0.8485]
target = [0.0, 0.0, 0.0]
[table]
size_m = 2.0
[[object]]
id = 1
shape = "cube"
size_m = 0.2
position = [0.0, 0.0]
"#;

/// 0.4 s: the daemon pings every 0.2 s.
const WATCHDOG_USEC: &str = "400000";

/// The messages received until `until`, or until one satisfies `stop_at` (included).
fn receive(manager: &UnixDatagram, until: Instant, stop_at: impl Fn(&str) -> bool) -> Vec<String> {
    let mut messages = Vec::new();
    let mut buf = [0u8; 4096];
    while Instant::now() < until {
        match manager.recv(&mut buf) {
            Ok(n) => {
                let message = String::from_utf8_lossy(&buf[..n]).into_owned();
                let last = stop_at(&message);
                messages.push(message);
                if last {
                    break;
                }
            }
            Err(err)
                if matches!(
                    err.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(err) => panic!("the notify socket failed: {err}"),
        }
    }
    messages
}

/// `kill -TERM`, then the exit status (within 10 s).
fn terminate(child: &mut Child) -> std::process::ExitStatus {
    crate::util::terminate(child, Duration::from_secs(10)).0
}

fn notify_socket(dir: &Path) -> UnixDatagram {
    let manager = UnixDatagram::bind(dir.join("notify")).expect("the notify socket binds");
    manager
        .set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout set");
    manager
}

/// READY=1 comes once the socket accepts subscribers; STATUS= lines follow with live
/// counters; WATCHDOG=1 comes every half WATCHDOG_USEC; SIGTERM brings STOPPING=1 and exit 0.
/// With standard error as the journal stream, log lines carry syslog priorities and no
/// timestamps, and the config's `[log] level` applies when `RUST_LOG` is unset.
#[test]
fn notifies_ready_status_watchdog_and_stopping_and_logs_for_the_journal() {
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().expect("a temporary folder");
    let scene = dir.path().join("scene.toml");
    std::fs::write(&scene, SCENE).expect("scene written");
    let config = dir.path().join("tacmesh.toml");
    std::fs::write(
        &config,
        format!(
            "[[sensor]]\nspec = \"sim:{}\"\n\n[log]\nlevel = \"debug\"\n",
            scene.display()
        ),
    )
    .expect("config written");
    let socket = dir.path().join("tacmesh.sock");
    let manager = notify_socket(dir.path());
    // Standard error to a file that JOURNAL_STREAM names, as systemd names its journal stream.
    let log_path = dir.path().join("stderr.log");
    let log = std::fs::File::create(&log_path).expect("log file");
    let log_id = log.metadata().expect("log metadata");
    let mut child = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["run", "--config", path_str(&config), "--socket"])
        .arg(&socket)
        .env("NOTIFY_SOCKET", dir.path().join("notify"))
        .env("WATCHDOG_USEC", WATCHDOG_USEC)
        .env(
            "JOURNAL_STREAM",
            format!("{}:{}", log_id.dev(), log_id.ino()),
        )
        .env_remove("WATCHDOG_PID")
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("tacmesh runs");

    // READY=1, and at that moment the socket takes a subscriber and greets it.
    let before_ready = receive(&manager, Instant::now() + Duration::from_secs(60), |m| {
        m.lines().any(|l| l == "READY=1")
    });
    let ready = before_ready.last().cloned().unwrap_or_default();
    assert!(
        ready.lines().any(|l| l == "READY=1"),
        "no READY=1 within 60 s: {before_ready:?}"
    );
    assert!(
        before_ready[..before_ready.len() - 1]
            .iter()
            .all(|m| !m.contains("WATCHDOG=1")),
        "pings before READY: {before_ready:?}"
    );
    let mut subscription = Subscription::connect(&socket, Some(Duration::from_secs(10)))
        .expect("the socket accepts a subscriber as soon as READY=1 is sent");
    assert!(ready.contains(&format!("STATUS=serving meshes on {}", socket.display())));
    // A well-behaved subscriber: it reads everything, so it counts in STATUS= as connected.
    let reader = std::thread::spawn(move || while subscription.next_message().is_ok() {});

    // Five seconds of a running daemon.
    let running = receive(&manager, Instant::now() + Duration::from_secs(5), |_| false);
    let pings = running.iter().filter(|m| *m == "WATCHDOG=1").count();
    // 25 are due; a loaded machine may delay some, a daemon that does not ping sends none.
    assert!(pings >= 10, "{pings} WATCHDOG=1 in 5 s: {running:?}");
    let statuses: Vec<&str> = running
        .iter()
        .filter_map(|m| m.strip_prefix("STATUS="))
        .collect();
    assert!(statuses.len() >= 2, "STATUS= lines: {running:?}");
    assert!(
        statuses
            .iter()
            .all(|s| s.contains("frames/s") && s.contains("objects") && !s.contains('\n')),
        "{statuses:?}"
    );
    assert!(
        statuses.iter().any(|s| s.contains("1 subscriber,")),
        "{statuses:?}"
    );

    // SIGTERM: STOPPING=1, then exit 0.
    let status = terminate(&mut child);
    let stopping = receive(&manager, Instant::now() + Duration::from_secs(2), |m| {
        m.lines().any(|l| l == "STOPPING=1")
    });
    assert!(
        stopping
            .iter()
            .any(|m| m.lines().any(|l| l == "STOPPING=1")),
        "no STOPPING=1: {stopping:?}"
    );
    assert!(status.success(), "exit after SIGTERM: {status}");
    reader.join().expect("the reader ends with the daemon");

    // The log: syslog priorities, no timestamps, no colours; debug lines from [log] level.
    let mut text = String::new();
    std::fs::File::open(&log_path)
        .and_then(|mut f| f.read_to_string(&mut text))
        .expect("log read");
    let tracing_lines: Vec<&str> = text.lines().filter(|l| l.starts_with('<')).collect();
    assert!(
        tracing_lines.iter().any(|l| l.starts_with("<6>")),
        "no info lines with their priority: {text}"
    );
    assert!(
        tracing_lines.iter().any(|l| l.starts_with("<7>")),
        "[log] level = \"debug\" was not applied: {text}"
    );
    for line in &tracing_lines {
        let after = line
            .split_once('>')
            .map_or("", |(_, rest)| rest)
            .trim_start();
        assert!(
            !after.starts_with(|c: char| c.is_ascii_digit()),
            "a timestamp under the journal: {line}"
        );
    }
    assert!(!text.contains('\x1b'), "colours in a log file: {text}");
}

/// A config that cannot be used fails the start before READY=1: systemd sees a failed start,
/// not a ready service.
#[test]
fn a_bad_config_fails_before_ready() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let config = dir.path().join("tacmesh.toml");
    std::fs::write(&config, "[log]\nlevel = \"loud\"\n").expect("config written");
    let manager = notify_socket(dir.path());
    let out = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["run", "--config", path_str(&config), "--socket"])
        .arg(dir.path().join("tacmesh.sock"))
        .env("NOTIFY_SOCKET", dir.path().join("notify"))
        .env("WATCHDOG_USEC", WATCHDOG_USEC)
        .output()
        .expect("tacmesh runs");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("log.level"), "{stderr}");
    let messages = receive(
        &manager,
        Instant::now() + Duration::from_millis(200),
        |_| false,
    );
    assert!(messages.is_empty(), "{messages:?}");
    // Nothing listens on the socket path.
    assert!(UnixStream::connect(dir.path().join("tacmesh.sock")).is_err());
}
