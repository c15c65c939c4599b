//! Publishing over Zenoh (the `zenoh` feature), on loopback only: a daemon listening on
//! 127.0.0.1 with multicast scouting off, and `tacmesh subscribe --zenoh` in another process,
//! see the same objects as a subscriber on the Unix socket. The late joiner gets the scene by
//! query before any update.

use std::collections::BTreeMap;
use std::process::Command;
use std::time::{Duration, Instant};

use tacmesh::glam::Vec3;
use tacmesh::protocol::{Scene, FIRST_SUPPORT_ID};
use tacmesh::TriMesh;

use crate::daemon::ONE_DAEMON_AT_A_TIME;
use crate::reliability::Run;

/// A TCP port on 127.0.0.1 that was free a moment ago.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .expect("a free port on loopback")
        .port()
}

fn centroid(mesh: &TriMesh) -> Vec3 {
    mesh.vertices.iter().copied().sum::<Vec3>() / mesh.vertices.len().max(1) as f32
}

#[test]
fn a_zenoh_subscriber_in_another_process_sees_what_the_socket_subscriber_sees() {
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().expect("a temporary folder");
    let port = free_port();
    let daemon_config = dir.path().join("daemon.toml");
    std::fs::write(
        &daemon_config,
        format!("[zenoh]\nrobot = \"test-rig\"\nlisten = [\"tcp/127.0.0.1:{port}\"]\n"),
    )
    .expect("writes");
    let client_config = dir.path().join("client.toml");
    std::fs::write(
        &client_config,
        format!("[zenoh]\nrobot = \"test-rig\"\nconnect = [\"tcp/127.0.0.1:{port}\"]\n"),
    )
    .expect("writes");
    let mut daemon = Run::start(
        &[
            "--sensor",
            "sim:demo",
            "--config",
            crate::util::path_str(&daemon_config),
        ],
        &dir.path().join("t.sock"),
    );
    // Past the cylinder's arrival at 5 s, so that the scene has all five objects.
    std::thread::sleep(Duration::from_secs(7));
    let mut socket = daemon.subscribe();
    let mut scene = Scene::new();
    let until = Instant::now() + Duration::from_secs(2);
    while Instant::now() < until {
        scene.apply(&socket.next_message().expect("the socket subscription"));
    }

    let out = dir.path().join("zenoh-out");
    let started = Instant::now();
    let zenoh = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["subscribe", "--count", "60", "--zenoh"])
        .arg(&client_config)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("tacmesh subscribe runs");
    let took = started.elapsed();
    let stdout = String::from_utf8_lossy(&zenoh.stdout);
    let stderr = String::from_utf8_lossy(&zenoh.stderr);
    assert!(
        zenoh.status.success(),
        "{stdout}\n{stderr}\n{}",
        daemon.log()
    );
    eprintln!("the Zenoh subscriber read 60 updates in {took:?}");
    // The socket's subscriber catches up (it did not read while the other process ran).
    let until = Instant::now() + Duration::from_millis(200);
    while Instant::now() < until {
        scene.apply(&socket.next_message().expect("the socket subscription"));
    }

    // Its snapshot came by query, before any live update.
    let lines: Vec<&str> = stdout.lines().collect();
    let done = lines
        .iter()
        .position(|l| l.starts_with("snapshot done: 5 objects, 1 plane"))
        .unwrap_or_else(|| panic!("no snapshot of five objects and the table:\n{stdout}"));
    assert!(lines[1..done].iter().all(|l| l.starts_with("shape ")
        || l.starts_with("body ")
        || l.starts_with("seen ")
        || l.starts_with("pose ")));
    // The objects' collision bodies come over Zenoh too (protocol 3): in the snapshot for
    // those made by then, live for the others (a body follows its shape by up to a few
    // hundred milliseconds, more on a loaded machine).
    let bodies = lines
        .iter()
        .filter(|l| l.starts_with("body object"))
        .count();
    assert!(bodies >= 1, "no body over Zenoh:\n{stdout}");
    let moves = lines[done..]
        .iter()
        .filter(|l| l.starts_with("pose object"))
        .count();
    assert!(moves >= 20, "only {moves} moves over Zenoh:\n{stdout}");

    // The same objects, each where the socket's subscriber has it (the cone moves: it is
    // compared by where it is along its path, within what it moves in the time between).
    let from_zenoh: BTreeMap<String, TriMesh> = std::fs::read_dir(&out)
        .expect("the --out folder")
        .map(|entry| {
            let path = entry.expect("an entry").path();
            let name = path
                .file_stem()
                .expect("a name")
                .to_string_lossy()
                .into_owned();
            (
                name,
                tacmesh::formats::read_mesh(&path).expect("a readable PLY"),
            )
        })
        .collect();
    let from_socket: BTreeMap<String, TriMesh> = scene
        .objects()
        .map(|object| {
            let id = object.object_id();
            let name = match id.checked_sub(FIRST_SUPPORT_ID) {
                Some(k) => format!("plane-{}", k + 1),
                None => format!("object-{id}"),
            };
            (name, object.world_mesh())
        })
        .collect();
    assert_eq!(
        from_zenoh.keys().collect::<Vec<_>>(),
        from_socket.keys().collect::<Vec<_>>(),
        "{stdout}"
    );
    for (name, mesh) in &from_zenoh {
        let apart = centroid(mesh).distance(centroid(&from_socket[name]));
        eprintln!(
            "{name}: {} faces over Zenoh, centroids {:.1} mm apart",
            mesh.triangles.len(),
            apart * 1e3
        );
        assert!(apart < 0.05, "{name}: {apart} m apart");
    }
    let (status, _) = daemon.terminate();
    assert!(status.success(), "{status}");
    let log = daemon.log();
    assert!(
        log.contains("publishing on Zenoh under tacmesh/test-rig/**"),
        "{log}"
    );
    assert!(log.contains("stopped publishing on Zenoh"), "{log}");
}
