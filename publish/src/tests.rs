//! Publisher tests on real Unix sockets in a temporary directory. Every wait is bounded.

use std::io::{ErrorKind, Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glam::{Quat, Vec3};
use tacmesh_protocol::{
    Encoding, FrameDecoder, Kinds, Message, Pose, Sender, Shape, SimplifyStats, Stats, Subscribe,
    PROTOCOL_VERSION,
};
use tacmesh_source::TriMesh;

use crate::{AllowedPeers, PublishError, Publisher, PublisherConfig};

/// How long a test waits for a message or an event before it fails: a hang guard, generous
/// for a busy machine, never a bound on speed.
const WAIT: Duration = Duration::from_secs(30);

fn socket_in(dir: &tempfile::TempDir) -> PathBuf {
    dir.path().join("tacmesh.sock")
}

fn publisher(path: &Path) -> Publisher {
    let mut config = PublisherConfig::new(path);
    config.server_name = "tacmesh-test".into();
    Publisher::bind(config).expect("bind in a fresh temp dir")
}

/// A mesh of `triangles` triangles over as many vertices (about 24 bytes per triangle).
fn mesh(triangles: usize) -> TriMesh {
    let vertices = (0..triangles.max(3))
        .map(|i| Vec3::new(i as f32 * 1e-3, 0.5, -0.25))
        .collect::<Vec<_>>();
    let n = vertices.len() as u32;
    let tris = (0..triangles as u32)
        .map(|i| [i % n, (i + 1) % n, (i + 2) % n])
        .collect();
    TriMesh::new(vertices, tris)
}

fn pose(object_id: u64, shape_version: u64, time: u64) -> Pose {
    Pose {
        object_id,
        shape_version,
        pose_time_ns: time,
        pose_time_realtime_ns: time,
        last_seen_ns: time,
        rotation: Quat::IDENTITY,
        translation: Vec3::new(time as f32 * 1e-6, 0.0, 1.0),
        linear_velocity: Vec3::ZERO,
        angular_velocity: Vec3::ZERO,
    }
}

fn shape(object_id: u64, version: u64, triangles: usize) -> Shape {
    Shape {
        pose: pose(object_id, version, version * 1000),
        shape_time_ns: version * 1000,
        shape_time_realtime_ns: version * 1000,
        flags: 0,
        mesh: mesh(triangles),
        report: SimplifyStats {
            faces_in: 100,
            faces_out: triangles as u32,
            max_residual_m: 0.01,
        },
        encoding: Encoding::Full,
    }
}

struct TestClient {
    stream: UnixStream,
    decoder: FrameDecoder,
    /// Bytes read from the socket so far.
    received: u64,
}

impl TestClient {
    fn connect(path: &Path) -> Self {
        let stream = UnixStream::connect(path).expect("connect to the publisher");
        Self {
            stream,
            decoder: FrameDecoder::new(Sender::Server),
            received: 0,
        }
    }

    /// The next message, or None at EOF; panics after `WAIT`.
    fn next(&mut self) -> Option<Message> {
        let deadline = Instant::now() + WAIT;
        let mut buffer = vec![0u8; 64 * 1024];
        loop {
            if let Some(message) = self.decoder.next_message().expect("a valid server frame") {
                return Some(message);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            assert!(!left.is_zero(), "no message within {WAIT:?}");
            self.stream.set_read_timeout(Some(left)).unwrap();
            match self.stream.read(&mut buffer) {
                Ok(0) => return None,
                Ok(n) => {
                    self.received += n as u64;
                    self.decoder.push(&buffer[..n]);
                }
                Err(e) if e.kind() == ErrorKind::ConnectionReset => return None,
                Err(e) => panic!("read failed: {e}"),
            }
        }
    }

    fn expect(&mut self) -> Message {
        self.next().expect("a message, not EOF")
    }

    /// Reads Hello and checks it.
    fn hello(&mut self) {
        match self.expect() {
            Message::Hello {
                protocol_version,
                server,
            } => {
                assert_eq!(protocol_version, PROTOCOL_VERSION);
                assert_eq!(server, "tacmesh-test");
            }
            other => panic!("expected Hello, got {other:?}"),
        }
    }

    /// Reads a Session and the Shapes up to SnapshotDone; returns (object id, version) of
    /// each.
    fn snapshot(&mut self) -> Vec<(u64, u64)> {
        match self.expect() {
            Message::Session(_) => {}
            other => panic!("expected Session, got {other:?}"),
        }
        let mut objects = Vec::new();
        loop {
            match self.expect() {
                Message::Shape(u) => objects.push((u.object_id(), u.version())),
                Message::SnapshotDone => return objects,
                other => panic!("expected Shape or SnapshotDone, got {other:?}"),
            }
        }
    }

    fn shape(&mut self) -> Shape {
        match self.expect() {
            Message::Shape(u) => u,
            other => panic!("expected Shape, got {other:?}"),
        }
    }

    fn send(&mut self, message: Message) {
        let mut frame = Vec::new();
        tacmesh_protocol::encode(&message, &mut frame).expect("encodes");
        self.stream.write_all(&frame).expect("the publisher reads");
    }
}

/// A publisher with nothing published yet on a socket in `dir`, and one client that has read
/// its Hello and empty snapshot.
fn serving_one_client(dir: &tempfile::TempDir) -> (PathBuf, Publisher, TestClient) {
    let path = socket_in(dir);
    let publisher = publisher(&path);
    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![]);
    (path, publisher, client)
}

fn wait_until(what: &str, mut condition: impl FnMut() -> bool) {
    let deadline = Instant::now() + WAIT;
    while !condition() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn late_joiner_gets_hello_snapshot_and_snapshot_done() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let publisher = publisher(&path);
    publisher.shape(shape(1, 1, 4)).unwrap();
    publisher.shape(shape(2, 1, 4)).unwrap();
    publisher.shape(shape(3, 1, 4)).unwrap();
    publisher.shape(shape(3, 5, 4)).unwrap();
    publisher.remove(2);

    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![(1, 1), (3, 5)]);

    publisher.shape(shape(4, 1, 4)).unwrap();
    let live = client.shape();
    assert_eq!((live.object_id(), live.version()), (4, 1));
    assert_eq!(live, shape(4, 1, 4));
    publisher.remove(1);
    assert_eq!(client.expect(), Message::Remove { object_id: 1 });
}

#[test]
fn empty_snapshot_still_ends_with_snapshot_done() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let _publisher = publisher(&path);
    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![]);
}

#[test]
fn update_reaches_two_clients() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let publisher = publisher(&path);
    let mut a = TestClient::connect(&path);
    let mut b = TestClient::connect(&path);
    for client in [&mut a, &mut b] {
        client.hello();
        assert_eq!(client.snapshot(), vec![]);
    }
    wait_until("both clients registered", || {
        publisher.counters().clients_connected == 2
    });
    publisher.shape(shape(9, 1, 10)).unwrap();
    let stats = Stats {
        frames_in: 30,
        ..Stats::default()
    };
    publisher.stats(stats.clone()).unwrap();
    for client in [&mut a, &mut b] {
        assert_eq!(client.shape().object_id(), 9);
        assert_eq!(client.expect(), Message::Stats(stats.clone()));
    }
    wait_until("meshes counted", || {
        publisher.counters().shapes_published == 2
    });
    assert!(publisher.counters().bytes_sent > 0);
}

#[test]
fn stalled_client_does_not_delay_another() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    // A write timeout longer than the test: the stalled client is still held, its socket
    // buffer full, when the reader has had everything (a publisher that waited on it would
    // never get there).
    let mut config = PublisherConfig::new(&path);
    config.server_name = "tacmesh-test".into();
    let publisher = Publisher::bind_with_write_timeout(config, Duration::from_secs(600)).unwrap();
    let _stalled = UnixStream::connect(&path).unwrap(); // never reads
    let mut reader = TestClient::connect(&path);
    reader.hello();
    assert_eq!(reader.snapshot(), vec![]);
    wait_until("both clients registered", || {
        publisher.counters().clients_connected == 2
    });

    let receive = std::thread::spawn(move || {
        let start = Instant::now();
        let mut ids = Vec::new();
        while ids.len() < 200 {
            ids.push(reader.shape().object_id());
        }
        (ids, start.elapsed())
    });
    // 200 meshes of 20 000 triangles (about 480 kB each, 96 MB in all): the stalled client's
    // socket buffer fills within the first one.
    let mut slowest_call = Duration::ZERO;
    for id in 0..200 {
        let update = shape(id, 1, 20_000);
        let start = Instant::now();
        publisher.shape(update).unwrap();
        slowest_call = slowest_call.max(start.elapsed());
    }
    let (ids, elapsed) = receive.join().unwrap();
    assert_eq!(ids, (0..200).collect::<Vec<_>>());
    eprintln!("the reader took {elapsed:?}; the slowest publish call {slowest_call:?}");
    // The stalled client is still held (the reader has closed and left).
    assert_eq!(publisher.counters().clients_dropped, 0);
    wait_until("the reader gone, the stalled one held", || {
        publisher.counters().clients_connected == 1
    });
}

#[test]
fn garbage_client_is_dropped_while_another_keeps_receiving() {
    let dir = tempfile::tempdir().unwrap();
    let (path, publisher, mut good) = serving_one_client(&dir);
    let mut bad = TestClient::connect(&path);
    bad.hello();
    bad.snapshot();
    // A well-formed Subscribe is fine, then a frame of unknown kind 0x7f.
    bad.stream
        .write_all(&[
            12, 0, 0, 0, 0x81, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 0, 3, 0, 0, 0, 0x7f, 1, 2,
        ])
        .unwrap();
    wait_until("the garbage client dropped", || {
        publisher.counters().clients_dropped == 1
    });
    match bad.next() {
        Some(Message::Goodbye { reason }) => {
            assert!(reason.contains("unknown message kind 0x7f"), "{reason}")
        }
        other => panic!("expected a Goodbye saying why, got {other:?}"),
    }
    assert_eq!(bad.next(), None, "the bad client's connection is closed");
    assert_eq!(publisher.counters().clients_connected, 1);

    publisher.shape(shape(5, 1, 3)).unwrap();
    assert_eq!(good.shape().object_id(), 5);
}

#[test]
fn oversize_and_wrong_direction_frames_drop_the_client() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let publisher = publisher(&path);
    let mut oversize = UnixStream::connect(&path).unwrap();
    oversize.write_all(&u32::MAX.to_le_bytes()).unwrap();
    let mut wrong = UnixStream::connect(&path).unwrap();
    wrong.write_all(&[1, 0, 0, 0, 0x04]).unwrap(); // SnapshotDone is a server kind
    wait_until("both dropped", || publisher.counters().clients_dropped == 2);
}

#[test]
fn newer_shape_replaces_an_unsent_older_one() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    // Object 1 is larger than the socket buffers, so the writer is stuck on it while the client
    // does not read; object 2 meanwhile gets three versions.
    publisher.shape(shape(1, 1, 200_000)).unwrap();
    std::thread::sleep(Duration::from_millis(50));
    for version in 1..=3 {
        publisher.shape(shape(2, version, 3)).unwrap();
    }
    assert_eq!(client.shape().object_id(), 1);
    let latest = client.shape();
    assert_eq!((latest.object_id(), latest.version()), (2, 3));

    // A remove cancels an unsent shape of the same object.
    publisher.shape(shape(3, 1, 200_000)).unwrap();
    std::thread::sleep(Duration::from_millis(50));
    publisher.shape(shape(4, 1, 3)).unwrap();
    publisher.remove(4);
    assert_eq!(client.shape().object_id(), 3);
    assert_eq!(client.expect(), Message::Remove { object_id: 4 });
}

#[test]
fn older_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let publisher = publisher(&socket_in(&dir));
    publisher.shape(shape(1, 2, 3)).unwrap();
    assert!(matches!(
        publisher.shape(shape(1, 2, 3)),
        Err(PublishError::VersionNotNewer { current: 2, .. })
    ));
}

#[test]
fn stale_socket_is_removed_and_bind_succeeds() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    drop(UnixListener::bind(&path).unwrap()); // leaves the file, nobody listening
    assert!(path.exists());
    let _publisher = publisher(&path);
    let mut client = TestClient::connect(&path);
    client.hello();
}

/// The socket file appears only once the daemon listens: a client that sees the file connects
/// (no refusal between bind and listen), and no private name is left beside it.
#[test]
fn the_socket_file_appears_listening_and_alone() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let publisher = std::thread::spawn({
        let path = path.clone();
        move || publisher(&path)
    });
    while !path.exists() {
        std::thread::yield_now();
    }
    std::os::unix::net::UnixStream::connect(&path).expect("listening as soon as it exists");
    let _publisher = publisher.join().unwrap();
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|entry| entry.unwrap().file_name())
        .collect();
    assert_eq!(names, [path.file_name().unwrap()]);
}

#[test]
fn live_publisher_makes_second_bind_fail() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let first = publisher(&path);
    let error = Publisher::bind(PublisherConfig::new(&path)).unwrap_err();
    assert!(
        matches!(&error, PublishError::AlreadyRunning { path: p } if p == &path),
        "{error}"
    );
    assert!(error
        .to_string()
        .contains("another tacmesh daemon is serving"));
    // The first one is untouched.
    first.shape(shape(1, 1, 3)).unwrap();
    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![(1, 1)]);
}

#[test]
fn regular_file_at_path_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    std::fs::write(&path, b"not a socket").unwrap();
    let error = Publisher::bind(PublisherConfig::new(&path)).unwrap_err();
    assert!(matches!(error, PublishError::NotASocket { .. }), "{error}");
    assert_eq!(std::fs::read(&path).unwrap(), b"not a socket");
}

#[test]
fn missing_directory_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nope").join("tacmesh.sock");
    let error = Publisher::bind(PublisherConfig::new(&path)).unwrap_err();
    assert!(matches!(error, PublishError::NoSocketDir { .. }), "{error}");
}

#[test]
fn socket_file_mode_follows_config() {
    let dir = tempfile::tempdir().unwrap();
    for mode in [0o660, 0o600] {
        let path = dir.path().join(format!("m{mode:o}.sock"));
        let mut config = PublisherConfig::new(&path);
        config.mode = mode;
        let _publisher = Publisher::bind(config).unwrap();
        let actual = std::fs::metadata(&path).unwrap().permissions().mode() & 0o7777;
        assert_eq!(actual, mode);
    }
    assert_eq!(PublisherConfig::new("x").mode, 0o660);
}

/// A directory others can write and that is not sticky is refused, saying why; a sticky one
/// (such as /tmp) and the daemon's own are served in.
#[test]
fn a_socket_directory_others_can_write_is_refused_unless_sticky() {
    let dir = tempfile::tempdir().unwrap();
    let set_mode = |mode: u32| {
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(mode)).unwrap()
    };
    for mode in [0o777, 0o775, 0o757] {
        set_mode(mode);
        let error = Publisher::bind(PublisherConfig::new(socket_in(&dir))).unwrap_err();
        assert!(
            matches!(error, PublishError::UnsafeSocketDir { .. }),
            "{mode:o}: {error}"
        );
        assert!(error.to_string().contains("not sticky"), "{error}");
        assert!(!socket_in(&dir).exists());
    }
    for mode in [0o1777, 0o755, 0o700] {
        set_mode(mode);
        let publisher = Publisher::bind(PublisherConfig::new(socket_in(&dir)));
        assert!(publisher.is_ok(), "{mode:o}: {:?}", publisher.err());
    }
}

/// Another user who can make entries in the socket's directory (a sticky one here) puts a
/// symlink where the daemon makes its private name, pointing at a directory with a file named
/// as the socket inside: the daemon's chmod and chown never reach that file (they once
/// followed such a swapped name), and the socket is still served.
#[test]
fn the_mode_and_group_never_land_on_a_file_behind_a_planted_symlink() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o1777)).unwrap();
    let elsewhere = tempfile::tempdir().unwrap();
    let victim = elsewhere.path().join("s");
    std::fs::write(&victim, b"secret").unwrap();
    std::fs::set_permissions(&victim, std::fs::Permissions::from_mode(0o600)).unwrap();
    let path = socket_in(&dir);
    for planted in [
        format!(".tacmesh.sock.{}.binding", std::process::id()),
        "tacmesh.sock".to_owned(),
    ] {
        let link = dir.path().join(&planted);
        std::os::unix::fs::symlink(elsewhere.path(), &link).unwrap();
        let mut config = PublisherConfig::new(&path);
        config.server_name = "tacmesh-test".into();
        config.mode = 0o666;
        let (_, gid) = own_ids(&elsewhere);
        config.group = Some(gid);
        let bound = Publisher::bind(config);
        let mode = std::fs::metadata(&victim).unwrap().permissions().mode() & 0o7777;
        assert_eq!(
            mode, 0o600,
            "the planted {planted} led the chmod to the victim"
        );
        assert_eq!(std::fs::read(&victim).unwrap(), b"secret");
        if planted == "tacmesh.sock" {
            // A symlink at the socket's own path is not a socket: refused, untouched.
            assert!(matches!(bound, Err(PublishError::NotASocket { .. })));
        } else {
            let _publisher = bound.expect("served beside the planted name");
            let mut client = TestClient::connect(&path);
            client.hello();
        }
        std::fs::remove_file(&link).unwrap();
    }
}

/// Between the bind and the chmod, "another user" renames the daemon's private directory away
/// and puts a symlink to a directory of theirs in its place, holding a file named as the
/// socket. The mode and group are set through the private directory's descriptor, so they
/// land on the socket, not on that file (by path, they once did).
#[test]
fn the_mode_and_group_follow_no_name_swapped_during_the_bind() {
    let dir = tempfile::tempdir().unwrap();
    let elsewhere = tempfile::tempdir().unwrap();
    let victim = elsewhere.path().join("s");
    std::fs::write(&victim, b"secret").unwrap();
    std::fs::set_permissions(&victim, std::fs::Permissions::from_mode(0o600)).unwrap();
    let target = elsewhere.path().to_path_buf();
    crate::bind::tests::on_bind_in(dir.path(), move |dir, private_name| {
        std::fs::rename(dir.join(private_name), dir.join("moved")).unwrap();
        std::os::unix::fs::symlink(&target, dir.join(private_name)).unwrap();
    });
    let path = socket_in(&dir);
    let mut config = PublisherConfig::new(&path);
    config.server_name = "tacmesh-test".into();
    config.mode = 0o666;
    let _publisher = Publisher::bind(config).expect("bound");
    let mode = std::fs::metadata(&victim).unwrap().permissions().mode() & 0o7777;
    assert_eq!(mode, 0o600, "the chmod followed the swapped name");
    let socket_mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o7777;
    assert_eq!(socket_mode, 0o666, "the socket got its mode");
    let mut client = TestClient::connect(&path);
    client.hello();
}

/// Access is read again: a subscriber whose user the new lists no longer admit (removed from
/// an allowed group) gets a Goodbye saying so and is dropped; one still admitted stays, and a
/// newcomer of the revoked user is refused.
#[test]
fn revoked_peers_are_dropped_when_the_lists_are_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let (uid, gid) = own_ids(&dir);
    let path = socket_in(&dir);
    let mut config = PublisherConfig::new(&path);
    config.server_name = "tacmesh-test".into();
    config.allowed_peers = Some(AllowedPeers {
        member_uids: vec![uid],
        ..AllowedPeers::default()
    });
    let publisher = Publisher::bind(config).unwrap();
    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![]);
    // The same lists again: nobody is dropped.
    let same = AllowedPeers {
        member_uids: vec![uid],
        ..AllowedPeers::default()
    };
    assert_eq!(publisher.set_allowed_peers(Some(same)), None);
    let revoked = AllowedPeers {
        uids: vec![uid.wrapping_add(1)],
        gids: vec![gid.wrapping_add(1)],
        member_uids: vec![],
    };
    assert_eq!(publisher.set_allowed_peers(Some(revoked)), Some(1));
    match client.next() {
        Some(Message::Goodbye { reason }) => {
            assert!(reason.contains("no longer in"), "{reason}");
        }
        other => panic!("expected a Goodbye, got {other:?}"),
    }
    assert_eq!(client.next(), None);
    let mut newcomer = TestClient::connect(&path);
    match newcomer.next() {
        Some(Message::Goodbye { reason }) => assert!(reason.contains("not allowed"), "{reason}"),
        other => panic!("expected a Goodbye, got {other:?}"),
    }
    // No lists at all: everyone the file mode lets in.
    assert_eq!(publisher.set_allowed_peers(None), Some(0));
    let mut again = TestClient::connect(&path);
    again.hello();
}

/// Past the cap on subscribers (all, then one user's), a newcomer gets a Goodbye naming the
/// setting, is counted as refused, and those already in are served on; once one leaves there
/// is room again.
#[test]
fn subscribers_past_the_caps_are_refused_with_a_goodbye() {
    let dir = tempfile::tempdir().unwrap();
    for (max, per_user, key) in [
        (3, 16, "socket.max_subscribers"),
        (16, 3, "socket.max_subscribers_per_user"),
    ] {
        let path = dir.path().join(format!("{max}-{per_user}.sock"));
        let mut config = PublisherConfig::new(&path);
        config.server_name = "tacmesh-test".into();
        config.max_subscribers = max;
        config.max_subscribers_per_user = per_user;
        let publisher = Publisher::bind(config).unwrap();
        let mut clients: Vec<TestClient> = (0..3)
            .map(|_| {
                let mut client = TestClient::connect(&path);
                client.hello();
                assert_eq!(client.snapshot(), vec![]);
                client
            })
            .collect();
        let mut over = TestClient::connect(&path);
        match over.next() {
            Some(Message::Goodbye { reason }) => assert!(reason.contains(key), "{reason}"),
            other => panic!("{key}: expected a Goodbye, got {other:?}"),
        }
        assert_eq!(over.next(), None);
        assert_eq!(publisher.counters().clients_refused, 1, "{key}");
        publisher.shape(shape(1, 1, 3)).unwrap();
        for client in &mut clients {
            assert_eq!(client.shape().object_id(), 1);
        }
        // A client that closes is gone at once, without a write to find it out.
        drop(clients.pop());
        wait_until("the leaver unregistered", || {
            publisher.counters().clients_connected == 2
        });
        let mut again = TestClient::connect(&path);
        again.hello();
    }
}

/// Threads of this process whose name starts with `prefix`.
fn threads_named(prefix: &str) -> usize {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc/self/task lists this process's threads")
        .filter_map(|task| std::fs::read_to_string(task.ok()?.path().join("comm")).ok())
        .filter(|name| name.starts_with(prefix))
        .count()
}

/// Subscribers cost no thread each: 300 served at once (each gets its snapshot and a live
/// shape) run on the publisher's one thread. With a writer and a reader thread per subscriber
/// this once took 600 threads (1,100 connections took every file descriptor).
#[test]
fn many_subscribers_are_served_by_one_thread() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let mut config = PublisherConfig::new(&path);
    config.server_name = "tacmesh-test".into();
    config.max_subscribers = 400;
    config.max_subscribers_per_user = 400;
    let publisher = Publisher::bind(config).unwrap();
    publisher.shape(shape(1, 1, 20)).unwrap();
    let mut clients: Vec<TestClient> = (0..300)
        .map(|_| {
            let mut client = TestClient::connect(&path);
            client.hello();
            assert_eq!(client.snapshot(), vec![(1, 1)]);
            client
        })
        .collect();
    assert_eq!(publisher.counters().clients_connected, 300);
    // Other tests run beside this one, each with a publisher thread or two; 300 subscribers
    // on a thread (or two) each would be hundreds.
    let threads = threads_named("publish");
    assert!(
        threads < 50,
        "{threads} publisher threads for 300 subscribers"
    );
    publisher.shape(shape(1, 2, 20)).unwrap();
    for client in &mut clients {
        assert_eq!(client.shape().version(), 2);
    }
}

/// Subscribes sent back to back are acted on one per RESUBSCRIBE_INTERVAL, each answered
/// (none is lost: a client counting answers gets them all), and the holding back is counted.
#[test]
fn a_subscribe_flood_is_spaced_out_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    let resend = Subscribe {
        resend: true,
        ..Subscribe::default()
    };
    for _ in 0..5 {
        client.send(Message::Subscribe(resend.clone()));
    }
    let mut answers = 0;
    while answers < 5 {
        if let Message::Session(session) = client.expect() {
            assert!(session.options.resend);
            answers += 1;
        }
    }
    wait_until("the flood counted", || {
        publisher.counters().subscribes_throttled >= 4
    });
}

#[test]
fn the_connection_log_keeps_to_its_budget_and_says_what_it_left_out() {
    let mut throttle = crate::LogThrottle::default();
    let t0 = Instant::now();
    let allowed = (0..100).filter(|_| throttle.allow(t0).is_some()).count();
    assert_eq!(allowed, 20);
    let later = t0 + Duration::from_secs(11);
    assert_eq!(
        throttle.allow(later).as_deref(),
        Some(" (80 connection lines like this were left out)")
    );
    assert_eq!(throttle.allow(later).as_deref(), Some(""));
}

/// A socket path so long that the private directory's longer path cannot be bound (a Unix
/// socket address holds 107 bytes) is bound in place, and still gets its mode and group.
#[test]
fn a_socket_too_long_for_the_private_name_is_bound_in_place_with_its_mode() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path().to_str().unwrap().len() + 1;
    let name = format!("{}.sock", "s".repeat(100 - base - 5));
    let path = dir.path().join(&name);
    assert_eq!(path.to_str().unwrap().len(), 100);
    let (_, gid) = own_ids(&dir);
    let mut config = PublisherConfig::new(&path);
    config.server_name = "tacmesh-test".into();
    config.mode = 0o600;
    config.group = Some(gid);
    let _publisher = Publisher::bind(config).expect("bound in place");
    use std::os::unix::fs::MetadataExt;
    let metadata = std::fs::metadata(&path).unwrap();
    assert_eq!(metadata.permissions().mode() & 0o7777, 0o600);
    assert_eq!(metadata.gid(), gid);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n != "ids")
        .collect();
    assert_eq!(
        names,
        vec![std::ffi::OsString::from(&name)],
        "only the socket"
    );
    let mut client = TestClient::connect(&path);
    client.hello();
}

/// This process's user and group, as the kernel will report them for its connections.
fn own_ids(dir: &tempfile::TempDir) -> (u32, u32) {
    use std::os::unix::fs::MetadataExt;
    let probe = dir.path().join("ids");
    std::fs::write(&probe, b"").unwrap();
    let metadata = std::fs::metadata(&probe).unwrap();
    (metadata.uid(), metadata.gid())
}

#[test]
fn only_allowed_peers_may_subscribe() {
    let dir = tempfile::tempdir().unwrap();
    let (uid, gid) = own_ids(&dir);
    let others = AllowedPeers {
        uids: vec![uid.wrapping_add(1)],
        gids: vec![gid.wrapping_add(1)],
        member_uids: vec![uid.wrapping_add(2)],
    };
    for (name, allowed, admitted) in [
        ("others", others.clone(), false),
        (
            "our uid",
            AllowedPeers {
                uids: vec![uid],
                ..others.clone()
            },
            true,
        ),
        (
            "our gid",
            AllowedPeers {
                gids: vec![gid],
                ..others.clone()
            },
            true,
        ),
        (
            "a member of an allowed group",
            AllowedPeers {
                member_uids: vec![uid],
                ..others.clone()
            },
            true,
        ),
    ] {
        let path = dir.path().join(format!("{}.sock", name.replace(' ', "-")));
        let mut config = PublisherConfig::new(&path);
        config.server_name = "tacmesh-test".into();
        config.allowed_peers = Some(allowed);
        let publisher = Publisher::bind(config).unwrap();
        publisher.shape(shape(1, 1, 4)).unwrap();
        let mut client = TestClient::connect(&path);
        if admitted {
            client.hello();
            assert_eq!(client.snapshot(), vec![(1, 1)], "{name}");
            assert_eq!(publisher.counters().clients_refused, 0, "{name}");
        } else {
            // No Hello: a Goodbye saying why, then the end.
            match client.next() {
                Some(Message::Goodbye { reason }) => {
                    assert!(reason.contains("not allowed to subscribe"), "{reason}");
                    assert!(reason.contains(&format!("uid {uid} ")), "{reason}");
                }
                other => panic!("{name}: expected a Goodbye, got {other:?}"),
            }
            assert_eq!(client.next(), None, "{name}");
            wait_until("the refusal is counted", || {
                publisher.counters().clients_refused == 1
            });
            assert_eq!(publisher.counters().clients_connected, 0);
            // Retrying is refused every time, and counted.
            let mut again = TestClient::connect(&path);
            assert!(matches!(again.next(), Some(Message::Goodbye { .. })));
            assert_eq!(again.next(), None);
            wait_until("both refusals", || {
                publisher.counters().clients_refused == 2
            });
        }
    }
}

#[test]
fn the_socket_file_gets_the_configured_group() {
    use std::os::unix::fs::MetadataExt;
    let dir = tempfile::tempdir().unwrap();
    let (_, gid) = own_ids(&dir);
    let path = socket_in(&dir);
    let mut config = PublisherConfig::new(&path);
    config.group = Some(gid);
    let _publisher = Publisher::bind(config).unwrap();
    assert_eq!(std::fs::metadata(&path).unwrap().gid(), gid);
}

#[test]
fn shutdown_sends_goodbye_and_removes_the_socket() {
    let dir = tempfile::tempdir().unwrap();
    let (path, publisher, mut client) = serving_one_client(&dir);
    let _stalled = UnixStream::connect(&path).unwrap();
    wait_until("both clients registered", || {
        publisher.counters().clients_connected == 2
    });
    // The stalled client's writer is blocked in the middle of a mesh larger than its socket
    // buffer; the reading client takes the mesh.
    publisher.shape(shape(1, 1, 200_000)).unwrap();
    assert_eq!(client.shape().object_id(), 1);
    let start = Instant::now();
    publisher.shutdown("SIGTERM received");
    // A hang guard: the stalled client cannot hold the shutdown past its grace for long.
    assert!(
        start.elapsed() < crate::GOODBYE_GRACE + WAIT,
        "shutdown took {:?}",
        start.elapsed()
    );
    assert_eq!(
        client.expect(),
        Message::Goodbye {
            reason: "SIGTERM received".into()
        }
    );
    assert_eq!(client.next(), None);
    assert!(!path.exists());
    assert_eq!(publisher.counters().clients_connected, 0);
}

#[test]
fn drop_removes_the_socket() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    drop(publisher(&path));
    assert!(!path.exists());
}

#[test]
fn client_that_reads_nothing_is_dropped_after_the_write_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let write_timeout = Duration::from_millis(300);
    let mut config = PublisherConfig::new(&path);
    config.server_name = "tacmesh-test".into();
    let publisher = Publisher::bind_with_write_timeout(config, write_timeout).unwrap();
    // Reads its (empty) snapshot, then nothing until it was dropped. Read first, so that the
    // snapshot is not still being written when the big shape comes (it would then carry the
    // shape, and the SnapshotDone would be lost behind the timeout).
    let mut stalled = TestClient::connect(&path);
    stalled.hello();
    assert_eq!(stalled.snapshot(), vec![]);
    let mut reader = TestClient::connect(&path);
    reader.hello();
    reader.snapshot();
    wait_until("the client registered", || {
        publisher.counters().clients_connected == 2
    });
    // The other client reads all the time (with this short timeout it must).
    let receive =
        std::thread::spawn(move || [reader.shape().object_id(), reader.shape().object_id()]);
    // Ten times the stalled client's socket buffer, and small enough that what is left of it
    // and a Goodbye fit once the buffer is raised.
    publisher.shape(shape(1, 1, 2_000)).unwrap();
    let started = Instant::now();
    let deadline = started + 2 * write_timeout + WAIT;
    while publisher.counters().clients_dropped == 0 {
        assert!(
            Instant::now() < deadline,
            "the stalled client was never dropped"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(started.elapsed() >= write_timeout);
    assert_eq!(publisher.counters().clients_connected, 1);
    // The reading client is still served.
    publisher.shape(shape(2, 1, 3)).unwrap();
    assert_eq!(receive.join().unwrap(), [1, 2]);
    assert_eq!(publisher.counters().clients_dropped, 1);
    // The dropped client finds, when it reads again, whole frames ending in a Goodbye that
    // says why (the frame it stalled in was finished first).
    assert_eq!(stalled.shape().object_id(), 1);
    match stalled.expect() {
        Message::Goodbye { reason } => {
            assert!(
                reason.starts_with("dropped: it read nothing for 0.3 s"),
                "{reason}"
            )
        }
        other => panic!("expected Goodbye, got {other:?}"),
    }
    assert_eq!(stalled.next(), None);
}

/// A client that closes its sending side (it has nothing to say: the server needs nothing from
/// it) goes on receiving updates; one that closes both sides is let go as gone, not dropped.
#[test]
fn a_half_closed_client_keeps_receiving() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    client.stream.shutdown(std::net::Shutdown::Write).unwrap();
    // Whether the publisher sees the end of the client's input before or after the shape,
    // the shape arrives.
    publisher.shape(shape(1, 1, 10)).unwrap();
    assert_eq!(client.shape().object_id(), 1);
    assert_eq!(publisher.counters().clients_connected, 1);

    drop(client);
    // The hang-up is seen at once; a write would find it too.
    publisher.shape(shape(1, 2, 10)).unwrap();
    wait_until("the closed client unregistered", || {
        publisher.counters().clients_connected == 0
    });
    assert_eq!(publisher.counters().clients_dropped, 0);
}

/// Updates queued for a subscriber when the daemon stops are sent before the Goodbye.
#[test]
fn shutdown_sends_what_is_queued_before_goodbye() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let publisher = publisher(&path);
    publisher.shape(shape(3, 1, 10)).unwrap();
    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![(3, 1)]);
    // A mesh far larger than the socket's buffer keeps the writer busy while the client does
    // not read; the next updates wait in the queue behind it.
    publisher.shape(shape(1, 1, 50_000)).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    publisher.shape(shape(2, 1, 10)).unwrap();
    publisher.shape(shape(1, 2, 10)).unwrap();
    publisher.remove(3);
    let stopping = std::thread::spawn(move || {
        publisher.shutdown("SIGTERM received");
        publisher
    });
    std::thread::sleep(Duration::from_millis(100));
    let mut seen = Vec::new();
    while let Some(message) = client.next() {
        seen.push(match message {
            Message::Shape(u) => format!("shape {}", u.object_id()),
            Message::Remove { object_id } => format!("remove {object_id}"),
            Message::Goodbye { .. } => "goodbye".into(),
            other => other.name().to_string(),
        });
    }
    stopping.join().unwrap();
    assert_eq!(
        seen,
        ["shape 1", "shape 1", "shape 2", "remove 3", "goodbye"]
    );
}

/// A client that reads nothing for a while and then reads again gets current data after at
/// most a few stale frames: what the kernel's small send buffer ([`crate::SEND_BUFFER_BYTES`])
/// and the frame being written hold. The daemon's own queue keeps only the latest update of
/// each object.
#[test]
fn a_client_back_from_a_stall_reads_little_that_is_stale() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    // 300 versions of two objects (about 2.5 kB each) while the client does not read.
    for version in 1..=300u64 {
        publisher.shape(shape(1, version, 100)).unwrap();
        publisher.shape(shape(2, version, 100)).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    std::thread::sleep(Duration::from_millis(200));
    let mut stale = 0;
    let mut current = std::collections::BTreeSet::new();
    while current.len() < 2 {
        let u = client.shape();
        if u.version() == 300 {
            current.insert(u.object_id());
        } else {
            stale += 1;
        }
    }
    eprintln!("{stale} stale frames before both objects' latest");
    // With the default buffer (over 100 kB) this was about 50.
    assert!(stale <= 6, "{stale} stale frames before the current ones");
    assert_eq!(publisher.counters().clients_dropped, 0);
}

/// A client that is not reading when the daemon stops still finds what was queued for it and
/// the Goodbye when it reads, after the daemon is gone: at shutdown the small socket buffer
/// is raised so that both fit in the kernel.
#[test]
fn a_client_not_reading_at_shutdown_still_gets_its_goodbye() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    // About 50 kB queued: ten times the small buffer.
    for id in 1..=20 {
        publisher.shape(shape(id, 1, 100)).unwrap();
    }
    publisher.shutdown("SIGTERM received");
    let mut shapes = 0;
    loop {
        match client.next() {
            Some(Message::Shape(_)) => shapes += 1,
            Some(Message::Goodbye { reason }) => {
                assert_eq!(reason, "SIGTERM received");
                break;
            }
            Some(other) => panic!("unexpected {other:?}"),
            None => panic!("the connection ended without a Goodbye after {shapes} shapes"),
        }
    }
    assert_eq!(shapes, 20);
    assert_eq!(client.next(), None);
}

/// A rigid move is a Pose after the shape it places, never the mesh again; a newer pose of an
/// object replaces its unsent one.
#[test]
fn a_move_is_a_pose_and_a_newer_pose_replaces_an_unsent_one() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    publisher.shape(shape(1, 1, 10)).unwrap();
    publisher.pose(pose(1, 1, 2000)).unwrap();
    assert_eq!(client.shape().version(), 1);
    assert_eq!(client.expect(), Message::Pose(pose(1, 1, 2000)));
    // A big shape of another object fills the socket (the client reads nothing yet), so the
    // writer cannot be done with it before both poses are queued and the newer replaces the
    // older. Whether the writer took the shape before the poses came (the shape, then the
    // pose) or not (one batch, in object order: the pose, then the shape) is the scheduler's
    // choice; on a loaded CI machine it was the second.
    publisher.shape(shape(2, 1, 200_000)).unwrap();
    publisher.pose(pose(1, 1, 3000)).unwrap();
    publisher.pose(pose(1, 1, 4000)).unwrap();
    let newer = Message::Pose(pose(1, 1, 4000));
    let is_shape_2 = |message: &Message| matches!(message, Message::Shape(s) if s.object_id() == 2);
    let describe = |message: &Message| match message {
        Message::Shape(s) => format!("the shape of object {}", s.object_id()),
        other => format!("{other:?}"),
    };
    let (first, second) = (client.expect(), client.expect());
    assert!(
        (is_shape_2(&first) && second == newer) || (first == newer && is_shape_2(&second)),
        "expected object 2's shape and the pose at 4000, got {} and {}",
        describe(&first),
        describe(&second)
    );
    // The writer counts a frame once its write returns, which may be just after the client
    // has read it.
    wait_until("two shapes and two poses counted", || {
        let counters = publisher.counters();
        (counters.shapes_published, counters.poses_published) == (2, 2)
    });
    // A late joiner gets the shape and the pose newer than the one inside it.
    let mut late = TestClient::connect(&socket_in(&dir));
    late.hello();
    assert!(matches!(late.expect(), Message::Session(_)));
    assert_eq!(late.shape().object_id(), 1);
    assert_eq!(late.expect(), Message::Pose(pose(1, 1, 4000)));
    assert_eq!(late.shape().object_id(), 2);
    assert_eq!(late.expect(), Message::SnapshotDone);
}

#[test]
fn a_pose_for_a_shape_not_published_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let publisher = publisher(&socket_in(&dir));
    assert!(matches!(
        publisher.pose(pose(1, 1, 1000)),
        Err(PublishError::PoseForUnknownShape { current: None, .. })
    ));
    publisher.shape(shape(1, 2, 3)).unwrap();
    let refused = publisher.pose(pose(1, 1, 1000)).unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("its published shape is version 2"),
        "{refused}"
    );
}

/// A client that asks for the compact encoding and a resend gets a second snapshot whose
/// Session states the options and whose shapes are compact and smaller.
#[test]
fn a_resend_in_compact_encoding_gives_a_fresh_smaller_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let path = socket_in(&dir);
    let publisher = publisher(&path);
    publisher.shape(shape(1, 1, 200)).unwrap();
    let mut client = TestClient::connect(&path);
    client.hello();
    assert_eq!(client.snapshot(), vec![(1, 1)]);
    // The publisher counts a write after it: the client may read a frame before it is
    // counted. Everything the client has read is counted before the count is taken.
    let read = client.received;
    wait_until("the first snapshot counted", || {
        publisher.counters().bytes_sent >= read
    });
    let before = publisher.counters().bytes_sent;
    let options = Subscribe {
        encoding: Encoding::Compact,
        resend: true,
        ..Subscribe::default()
    };
    client.send(Message::Subscribe(options.clone()));
    match client.expect() {
        Message::Session(session) => assert_eq!(session.options, options),
        other => panic!("expected Session, got {other:?}"),
    }
    let compact = client.shape();
    assert_eq!(compact.encoding, Encoding::Compact);
    assert_eq!(client.expect(), Message::SnapshotDone);
    let full = shape(1, 1, 200);
    for (a, b) in compact.mesh.vertices.iter().zip(&full.mesh.vertices) {
        assert!(a.distance(*b) <= compact.report.max_residual_m);
    }
    let read = client.received;
    wait_until("the compact snapshot counted", || {
        publisher.counters().bytes_sent >= read
    });
    let compact_bytes = publisher.counters().bytes_sent - before;
    let mut full_frame = Vec::new();
    tacmesh_protocol::encode(&Message::Shape(full), &mut full_frame).unwrap();
    assert!(
        (compact_bytes as usize) < full_frame.len() * 6 / 10,
        "compact snapshot {compact_bytes} B, full shape alone {} B",
        full_frame.len()
    );
}

/// Only the kinds and ids a client asked for reach it, Removes included.
#[test]
fn a_filter_by_kind_and_id_holds_back_everything_else() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    client.send(Message::Subscribe(Subscribe {
        kinds: Kinds::OBJECTS,
        object_ids: vec![2],
        ..Subscribe::default()
    }));
    // Wait until the publisher has read it: a resend is the only visible answer.
    client.send(Message::Subscribe(Subscribe {
        kinds: Kinds::OBJECTS,
        object_ids: vec![2],
        resend: true,
        ..Subscribe::default()
    }));
    assert_eq!(client.snapshot(), vec![]);
    let support = tacmesh_protocol::FIRST_SUPPORT_ID;
    publisher.shape(shape(support, 1, 3)).unwrap();
    publisher.shape(shape(1, 1, 3)).unwrap();
    publisher.shape(shape(2, 1, 3)).unwrap();
    assert_eq!(client.shape().object_id(), 2);
    publisher.remove(1);
    publisher.remove(support);
    publisher.remove(2);
    assert_eq!(client.expect(), Message::Remove { object_id: 2 });
    publisher.stats(Stats::default()).unwrap();
    assert!(matches!(client.expect(), Message::Stats(_)));
}

/// With a rate cap, updates of one object within the interval wait and only the latest goes
/// out when it is over; other objects are not held back by it.
#[test]
fn a_rate_cap_sends_the_latest_update_once_per_interval() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    client.send(Message::Subscribe(Subscribe {
        max_rate_hz: 2.0,
        resend: true,
        ..Subscribe::default()
    }));
    assert_eq!(client.snapshot(), vec![]);
    publisher.shape(shape(1, 1, 3)).unwrap();
    assert_eq!(client.shape().version(), 1);
    let sent = Instant::now();
    for time in 2..=20 {
        publisher.pose(pose(1, 1, time * 1000)).unwrap();
    }
    publisher.shape(shape(2, 1, 3)).unwrap();
    assert_eq!(
        client.shape().object_id(),
        2,
        "another object is not held back"
    );
    assert_eq!(client.expect(), Message::Pose(pose(1, 1, 20_000)));
    let waited = sent.elapsed();
    assert!(
        waited >= Duration::from_millis(400),
        "the pose came {waited:?} after the shape, within the 500 ms interval"
    );
    assert_eq!(publisher.counters().poses_published, 1);
}

/// A version-1 client that sends its empty Subscribe gets a Goodbye saying which version the
/// server speaks, and is let go; others are served on.
#[test]
fn a_version_1_subscribe_gets_a_goodbye_naming_the_version_spoken() {
    let dir = tempfile::tempdir().unwrap();
    let (path, publisher, mut other) = serving_one_client(&dir);
    let mut old = TestClient::connect(&path);
    old.send(Message::SubscribeV1);
    old.hello();
    let mut reason = None;
    while let Some(message) = old.next() {
        if let Message::Goodbye { reason: why } = message {
            reason = Some(why);
        }
    }
    let reason = reason.expect("a Goodbye before the end");
    assert!(
        reason.contains(&format!("protocol version {PROTOCOL_VERSION}")),
        "{reason}"
    );
    assert!(reason.contains("version-1 Subscribe"), "{reason}");
    wait_until("the old client counted", || {
        publisher.counters().clients_dropped == 1
    });
    publisher.shape(shape(1, 1, 3)).unwrap();
    assert_eq!(other.shape().object_id(), 1);
}

/// A Subscribe whose rate no clock can hold (1e-45 Hz once aborted the daemon: its interval
/// overflowed `Duration`) drops its sender with a Goodbye that names the field; the publisher
/// serves the others on, and the same again after it.
#[test]
fn a_subscribe_with_an_absurd_rate_gets_a_goodbye_and_the_others_are_served() {
    let dir = tempfile::tempdir().unwrap();
    let (path, publisher, mut other) = serving_one_client(&dir);
    publisher.shape(shape(1, 1, 3)).unwrap();
    assert_eq!(other.shape().object_id(), 1);
    for (round, rate) in [1e-45f32, 1.1e-19, f32::NAN, -1.0].into_iter().enumerate() {
        let mut bad = TestClient::connect(&path);
        bad.hello();
        bad.snapshot();
        // Subscribe { full, no flags, `rate`, objects and supports, no ids }, as raw bytes:
        // the encoder refuses to write it.
        let mut frame = vec![12, 0, 0, 0, 0x81, 0, 0];
        frame.extend_from_slice(&rate.to_le_bytes());
        frame.extend_from_slice(&[3, 0, 0, 0, 0]);
        bad.stream.write_all(&frame).unwrap();
        let mut reason = None;
        while let Some(message) = bad.next() {
            if let Message::Goodbye { reason: why } = message {
                reason = Some(why);
            }
        }
        let reason = reason.expect("a Goodbye before the end");
        assert!(reason.contains("max_rate_hz"), "{reason}");
        wait_until("the client counted as dropped", || {
            publisher.counters().clients_dropped == round as u64 + 1
        });
        publisher.shape(shape(1, round as u64 + 2, 3)).unwrap();
        assert_eq!(other.shape().version(), round as u64 + 2);
    }
}

/// A client that extrapolates poses by their velocity is sent a Pose only when its
/// extrapolation of the last one it got would be off by more than 2 mm or 1°, or once a second
/// (by last seen).
#[test]
fn an_extrapolating_client_gets_only_the_poses_its_extrapolation_misses() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    client.send(Message::Subscribe(Subscribe {
        extrapolate: true,
        resend: true,
        ..Subscribe::default()
    }));
    assert_eq!(client.snapshot(), vec![]);
    // Sliding at 0.1 m/s along x from 1 s on.
    let sliding = |ms: u64, off_m: f32| {
        let time = 1_000_000_000 + ms * 1_000_000;
        Pose {
            pose_time_ns: time,
            pose_time_realtime_ns: time,
            last_seen_ns: time,
            translation: Vec3::new(ms as f32 * 1e-4, off_m, 1.0),
            linear_velocity: Vec3::new(0.1, 0.0, 0.0),
            ..pose(1, 1, 0)
        }
    };
    let mut first = shape(1, 1, 3);
    first.pose = sliding(0, 0.0);
    publisher.shape(first).unwrap();
    assert_eq!(client.shape().version(), 1);
    // A frame every 33 ms along the path for 0.9 s, each waited for by the writer.
    for k in 1..=27u64 {
        publisher.pose(sliding(k * 33, 0.0)).unwrap();
        std::thread::sleep(Duration::from_millis(3));
    }
    // Then 3 mm off the path: sent. Then along the new path: only when the last one sent is a
    // second old.
    publisher.pose(sliding(900, 0.003)).unwrap();
    assert_eq!(client.expect(), Message::Pose(sliding(900, 0.003)));
    for ms in [1000, 1500, 1899, 1900] {
        publisher.pose(sliding(ms, 0.003)).unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(20));
    publisher.stats(Stats::default()).unwrap();
    let mut after = Vec::new();
    loop {
        match client.expect() {
            Message::Stats(_) => break,
            other => after.push(other),
        }
    }
    assert_eq!(
        after,
        vec![Message::Pose(sliding(1900, 0.003))],
        "on the extrapolated path: nothing until the last one sent is a second old"
    );
    assert_eq!(publisher.counters().poses_published, 2);
}

/// A unit cube's body for object `object_id`, made from its shape of `version`.
fn body(object_id: u64, version: u64) -> tacmesh_protocol::Body {
    let corners: Vec<Vec3> = (0..8)
        .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
        .collect();
    let faces: Vec<[u8; 3]> = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    tacmesh_protocol::Body {
        object_id,
        shape_version: version,
        solid: tacmesh_protocol::BodySolid::ShadowVolume,
        margin_m: 0.01,
        volume_m3: 1.0,
        centre_of_mass: Vec3::splat(0.5),
        inertia: [
            [1.0 / 6.0, 0.0, 0.0],
            [0.0, 1.0 / 6.0, 0.0],
            [0.0, 0.0, 1.0 / 6.0],
        ],
        primitive: None,
        mesh: TriMesh::new(
            corners.clone(),
            faces.iter().map(|f| f.map(u32::from)).collect(),
        ),
        encoding: Encoding::Full,
        hulls: vec![tacmesh_protocol::Hull {
            vertices: corners,
            triangles: faces,
        }],
    }
}

fn received_body(client: &mut TestClient) -> tacmesh_protocol::Body {
    match client.expect() {
        Message::Body(body) => body,
        other => panic!("expected Body, got {other:?}"),
    }
}

/// A body goes out after its shape and before a newer pose, live and in a late joiner's
/// snapshot, and stays with the object's newer shapes until a shape in a new frame.
#[test]
fn a_body_follows_its_shape_and_stays_until_the_frame_changes() {
    let dir = tempfile::tempdir().unwrap();
    let (path, publisher, mut client) = serving_one_client(&dir);
    publisher.shape(shape(1, 1, 10)).unwrap();
    publisher.body(body(1, 1)).unwrap();
    publisher.pose(pose(1, 1, 2000)).unwrap();
    assert_eq!(client.shape().version(), 1);
    assert_eq!(received_body(&mut client), body(1, 1));
    assert_eq!(client.expect(), Message::Pose(pose(1, 1, 2000)));
    // A newer shape in the same frame keeps the body: a late joiner gets both.
    publisher.shape(shape(1, 2, 10)).unwrap();
    assert_eq!(client.shape().version(), 2);
    let mut late = TestClient::connect(&path);
    late.hello();
    assert!(matches!(late.expect(), Message::Session(_)));
    assert_eq!(late.shape().version(), 2);
    assert_eq!(received_body(&mut late).shape_version, 1);
    assert_eq!(late.expect(), Message::SnapshotDone);
    // A shape in a new frame drops it, and a body made before it no longer fits.
    let mut moved = shape(1, 3, 10);
    moved.flags = tacmesh_protocol::SHAPE_NEW_FRAME;
    publisher.shape(moved).unwrap();
    let refused = publisher.body(body(1, 2)).unwrap_err();
    assert!(
        matches!(refused, PublishError::BodyDoesNotFit { version: 2, .. }),
        "{refused}"
    );
    assert!(refused.to_string().contains("another frame"), "{refused}");
    let mut later = TestClient::connect(&path);
    later.hello();
    assert_eq!(later.snapshot(), vec![(1, 3)], "no body in the snapshot");
    wait_until("bodies counted", || {
        publisher.counters().bodies_published == 2
    });
}

#[test]
fn a_body_for_a_shape_not_published_or_older_than_the_held_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let publisher = publisher(&socket_in(&dir));
    assert!(matches!(
        publisher.body(body(1, 1)),
        Err(PublishError::BodyDoesNotFit { .. })
    ));
    publisher.shape(shape(1, 2, 3)).unwrap();
    let newer = publisher.body(body(1, 3)).unwrap_err();
    assert!(
        newer.to_string().contains("newer than the published shape"),
        "{newer}"
    );
    publisher.body(body(1, 2)).unwrap();
    let older = publisher.body(body(1, 1)).unwrap_err();
    assert!(
        older.to_string().contains("published body, version 2"),
        "{older}"
    );
    let mut bad = body(1, 2);
    bad.volume_m3 = f32::NAN;
    assert!(matches!(
        publisher.body(bad),
        Err(PublishError::EncodeBody { object_id: 1, .. })
    ));
}

/// A client that does not ask for bodies gets none; asking for them with a resend brings them
/// in its snapshot, in the encoding it asked for.
#[test]
fn bodies_reach_only_the_clients_that_ask_for_them() {
    let dir = tempfile::tempdir().unwrap();
    let (_, publisher, mut client) = serving_one_client(&dir);
    client.send(Message::Subscribe(Subscribe {
        kinds: Kinds::OBJECTS,
        resend: true,
        ..Subscribe::default()
    }));
    assert_eq!(client.snapshot(), vec![]);
    publisher.shape(shape(1, 1, 10)).unwrap();
    publisher.body(body(1, 1)).unwrap();
    publisher.pose(pose(1, 1, 2000)).unwrap();
    assert_eq!(client.shape().version(), 1);
    assert_eq!(client.expect(), Message::Pose(pose(1, 1, 2000)), "no body");
    client.send(Message::Subscribe(Subscribe {
        kinds: Kinds::ALL,
        encoding: Encoding::Compact,
        resend: true,
        ..Subscribe::default()
    }));
    assert!(matches!(client.expect(), Message::Session(_)));
    assert_eq!(client.shape().encoding, Encoding::Compact);
    let compact = received_body(&mut client);
    assert_eq!(compact.encoding, Encoding::Compact);
    assert_eq!(compact.hulls, body(1, 1).hulls);
    assert_eq!(client.expect(), Message::Pose(pose(1, 1, 2000)));
    assert_eq!(client.expect(), Message::SnapshotDone);
}

/// A subscriber that hangs up with data it never read is a reset on the server's side, not an
/// end of input, after the bytes it did send; a frame it left half sent is named either way.
#[test]
fn a_half_frame_is_named_whether_the_hang_up_is_an_end_or_a_reset() {
    let (mut server, mut subscriber) = UnixStream::pair().unwrap();
    server.write_all(&[1, 0, 0, 0, 0x04]).unwrap(); // a frame the subscriber never reads
    subscriber.write_all(&[5, 0, 0]).unwrap();
    drop(subscriber);
    let mut buffer = [0u8; 16];
    assert_eq!(server.read(&mut buffer).unwrap(), 3, "the half frame first");
    let reset = server.read(&mut buffer).unwrap_err();
    assert_eq!(reset.kind(), ErrorKind::ConnectionReset);

    let reason = |retire: crate::client::Retire| match retire {
        crate::client::Retire::Gone(reason) => reason,
        _ => panic!("a hang-up is not a drop"),
    };
    let after_reset = reason(crate::client::gone_while_reading(3, Some(&reset)));
    assert!(
        after_reset.contains("in the middle of a frame (3 bytes unparsed)")
            && after_reset.contains("reset"),
        "{after_reset}"
    );
    let after_end = reason(crate::client::gone_while_reading(3, None));
    assert_eq!(
        after_end,
        "disconnected in the middle of a frame (3 bytes unparsed)"
    );
    let between_frames = reason(crate::client::gone_while_reading(0, Some(&reset)));
    assert!(!between_frames.contains("frame"), "{between_frames}");
}
