//! Real recordings through the live daemon: each plays through `tacmesh run --sensor
//! replay:…` into published object meshes (looped, so that objects are seen in enough frames
//! to be confirmed; the bag holds only two depth frames), and a recording played once is
//! meshed at its end.

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tacmesh::protocol::Message;
use tacmesh::subscriber::Subscription;

use crate::daemon::ONE_DAEMON_AT_A_TIME;
use crate::util::test_data;

/// Runs the daemon on `spec`, looped, until a subscriber has an object mesh; returns its face
/// count.
fn first_object_mesh(spec: &str) -> usize {
    first_object_mesh_and_log(spec, &["--loop"], "warn").0
}

/// Runs `tacmesh run --sensor SPEC OPTIONS` until a subscriber has an object mesh; returns its
/// face count and the daemon's log at `level` (read once the daemon is stopped, so keep it
/// short: a full pipe would stall the daemon).
fn first_object_mesh_and_log(spec: &str, options: &[&str], level: &str) -> (usize, String) {
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().expect("a temporary folder");
    let socket = dir.path().join("replay.sock");
    let mut child = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["run", "--sensor", spec])
        .args(options)
        .arg("--socket")
        .arg(&socket)
        .env("RUST_LOG", level)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("tacmesh runs");
    let started = Instant::now();
    while !socket.exists() {
        if let Some(status) = child.try_wait().expect("waits") {
            panic!("tacmesh run --sensor {spec} exited: {status}");
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no socket for {spec}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut subscription =
        Subscription::connect(&socket, Some(Duration::from_secs(30))).expect("subscribes");
    let faces = loop {
        match subscription.next_message() {
            Ok(Message::Shape(u)) if u.object_id() < 1 << 32 && !u.mesh.triangles.is_empty() => {
                break u.mesh.triangles.len();
            }
            Ok(_) => {}
            Err(err) => panic!("{spec}: no object mesh: {err}"),
        }
        assert!(
            started.elapsed() < Duration::from_secs(90),
            "{spec}: no object mesh"
        );
    };
    let _ = child.kill();
    let _ = child.wait();
    let mut log = String::new();
    if let Some(mut stderr) = child.stderr.take() {
        let _ = stderr.read_to_string(&mut log);
    }
    (faces, log)
}

fn path(relative: &str) -> String {
    test_data(relative).display().to_string()
}

/// One range scan played once (no `--loop`): its objects are seen in one frame only, fewer
/// than confirm an object, yet the daemon meshes them when the stream ends, and says so.
#[test]
fn a_one_shot_cloud_is_meshed_at_its_end() {
    let spec = format!("replay:{}", path("pointclouds/stanford_bunny/bun000.ply"));
    let (faces, log) = first_object_mesh_and_log(&spec, &[], "info");
    assert!(faces > 0);
    assert!(
        log.contains("end of stream after 1 frame: meshing what was held back"),
        "{log}"
    );
}

#[test]
fn oni_recording_plays_into_meshes() {
    let spec = format!(
        "replay:{}",
        path("recordings/openni1_primesense_12frames_640x480.oni")
    );
    assert!(first_object_mesh(&spec) > 0);
}

#[test]
fn realsense_bag_plays_into_meshes() {
    let spec = format!(
        "replay:{}",
        path("recordings/realsense_d435_single_depth_color_640x480.bag")
    );
    assert!(first_object_mesh(&spec) > 0);
}

#[test]
fn tum_depth_pngs_play_into_meshes() {
    let spec = format!(
        "replay:{}?fx=520.9&fy=521.0&cx=325.1&cy=249.7&depth_scale_m=0.0002",
        path("depth/tum_fr1")
    );
    assert!(first_object_mesh(&spec) > 0);
}

#[test]
fn slambook_pgms_play_into_meshes() {
    let spec = format!(
        "replay:{}?fx=518&fy=519&cx=325.5&cy=253.5&depth_scale_m=0.001",
        path("depth/slambook_kinect")
    );
    assert!(first_object_mesh(&spec) > 0);
}

/// Simulated depth recorded with DepthAI's own recorder (host-only, no camera) plays through
/// `tacmesh run --sensor depthai:FILE.mcap` into meshes. Needs the `depthai` feature and the
/// `depthai` Python package (CI names its venv with `TACMESH_DEPTHAI_VENV`).
#[cfg(feature = "depthai")]
#[test]
fn depthai_recording_plays_into_meshes() {
    use tacmesh_source::{DepthSource, Observation};

    let dir = tempfile::tempdir().expect("a temporary folder");
    let recording = dir.path().join("sim.mcap");
    let mut camera = tacmesh_sim::SceneFile::demo().into_camera().expect("demo");
    camera.set_paced(false);
    let frames: Vec<_> = (0..30)
        .map(|_| match camera.next_observation().expect("renders") {
            Observation::Depth(frame) => frame,
            other => panic!("{other:?}"),
        })
        .collect();
    let venv = std::env::var("TACMESH_DEPTHAI_VENV").ok();
    let written = tacmesh_depthai::record_depth_frames(
        &recording,
        venv.as_deref().map(std::path::Path::new),
        &frames,
    )
    .expect("DepthAI records");
    assert_eq!(written, 30);
    let spec = format!(
        "depthai:{}{}",
        recording.display(),
        venv.map_or(String::new(), |v| format!("?venv={v}"))
    );
    assert!(first_object_mesh(&spec) > 0);
}
