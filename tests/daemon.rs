//! The live daemon end to end: a real `tacmesh run` on a simulated scene, real subscribers on
//! its socket. The daemons of these tests run one at a time (they share two cores with the
//! other tests, and each paces a 30 fps camera).

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use tacmesh::glam::Vec3;
use tacmesh::physics::orientation::signed_volume_m3;
use tacmesh::physics::proxy::{collision_proxy, ProxyConfig, SupportPlane};
use tacmesh::protocol::{Body, BodySolid, Message, Scene, SceneChange, Shape};
use tacmesh::sim::{
    contact_fidelity, point_to_mesh_distances, sample_cloud, ContactConfig, SampleConfig,
    SceneFile, SceneObject,
};
use tacmesh::subscriber::Subscription;
use tacmesh::TriMesh;

/// Support planes have ids from here up (see `tacmesh::daemon::planes`).
pub(crate) const FIRST_PLANE_ID: u64 = 1 << 32;

pub static ONE_DAEMON_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A `tacmesh run` child process on a scene written to a temporary folder.
struct Daemon {
    child: Child,
    socket: PathBuf,
    scene: SceneFile,
    _dir: tempfile::TempDir,
}

impl Daemon {
    fn start(scene_toml: &str) -> Daemon {
        Self::start_cameras(&[scene_toml])
    }

    /// One daemon with a simulated camera per scene file (all feed one object map);
    /// `scene` is the first.
    fn start_cameras(scene_tomls: &[&str]) -> Daemon {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let mut command = Command::new(env!("CARGO_BIN_EXE_tacmesh"));
        command.arg("run");
        let mut scenes = Vec::new();
        for (k, toml) in scene_tomls.iter().enumerate() {
            let scene_path = dir.path().join(format!("scene-{k}.toml"));
            std::fs::write(&scene_path, toml).expect("scene written");
            scenes.push(SceneFile::load(&scene_path).expect("the test scene parses"));
            command
                .arg("--sensor")
                .arg(format!("sim:{}", scene_path.display()));
        }
        let scene = scenes.into_iter().next().expect("at least one scene");
        let socket = dir.path().join("tacmesh.sock");
        let child = command
            .arg("--socket")
            .arg(&socket)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("tacmesh runs");
        let started = Instant::now();
        while !socket.exists() {
            assert!(
                started.elapsed() < Duration::from_secs(120),
                "the daemon did not bind its socket"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        Daemon {
            child,
            socket,
            scene,
            _dir: dir,
        }
    }

    /// Connects: the socket file appears only once the daemon listens on it.
    fn subscribe(&self) -> Subscription {
        Subscription::connect(&self.socket, Some(Duration::from_secs(10))).expect("subscribes")
    }

    /// Sends SIGTERM; returns the exit status and how long the exit took.
    fn terminate(&mut self) -> (std::process::ExitStatus, Duration) {
        crate::util::terminate(&mut self.child, Duration::from_secs(10))
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Every message a subscriber received, with when.
#[derive(Default)]
pub(crate) struct Received {
    /// Every new state of an object: each Shape, and each Pose applied to the shape it names
    /// (so that `world_mesh()` of any entry is where the object was then).
    pub(crate) updates: Vec<(Instant, Shape)>,
    /// How many of `updates` were Pose messages.
    pub(crate) poses: usize,
    pub(crate) removes: Vec<(Instant, u64)>,
    pub(crate) stats: Vec<(Instant, tacmesh::protocol::Stats)>,
    pub(crate) goodbye: bool,
    /// The latest state of each object.
    scene: Scene,
}

impl Received {
    /// Reads until `until` (or the connection ends).
    pub(crate) fn collect(subscription: &mut Subscription, until: Instant, into: &mut Received) {
        while Instant::now() < until && !into.goodbye {
            let message = match subscription.next_message() {
                Ok(message) => message,
                Err(err) => panic!("subscription failed: {err}"),
            };
            let now = Instant::now();
            match into.scene.apply(&message) {
                SceneChange::Added(id) | SceneChange::Reshaped(id) | SceneChange::Moved(id) => {
                    let object = into.scene.get(id).expect("just applied");
                    if matches!(message, Message::Pose(_)) {
                        into.poses += 1;
                    }
                    let mut state = object.shape.clone();
                    state.pose = object.pose;
                    into.updates.push((now, state));
                }
                SceneChange::Removed(id) => into.removes.push((now, id)),
                _ => {}
            }
            match message {
                Message::Stats(s) => into.stats.push((now, s)),
                Message::Goodbye { .. } => into.goodbye = true,
                _ => {}
            }
        }
    }

    /// The latest collision body of an object, placed in the world by its current pose: the
    /// solid (the shape itself for a closed shape, a primitive's fine tessellation) and the
    /// convex hulls together.
    fn world_body(&self, object_id: u64) -> Option<(Body, TriMesh, TriMesh)> {
        let object = self.scene.get(object_id)?;
        let body = object.body.clone()?;
        let pose = object.pose.world_from_object();
        let place = |mesh: &TriMesh| {
            TriMesh::new(
                mesh.vertices
                    .iter()
                    .map(|&v| pose.transform_point3(v))
                    .collect(),
                mesh.triangles.clone(),
            )
        };
        let proxy = match (body.solid, &body.primitive) {
            (BodySolid::Shape, _) => object.world_mesh(),
            (BodySolid::Primitive, Some(primitive)) => {
                place(&tacmesh::physics_scene::physics_primitive(primitive).mesh_with(128, 64))
            }
            _ => place(&body.mesh),
        };
        let mut hulls = TriMesh::default();
        for hull in &body.hulls {
            let offset = hulls.vertices.len() as u32;
            let placed = place(&hull.mesh());
            hulls.vertices.extend(placed.vertices);
            hulls
                .triangles
                .extend(placed.triangles.iter().map(|t| t.map(|i| i + offset)));
        }
        Some((body, proxy, hulls))
    }

    /// Whether every object (not the supports) holds the body of its latest shape.
    fn every_body_is_current(&self) -> bool {
        self.scene
            .objects()
            .filter(|o| o.object_id() < FIRST_PLANE_ID)
            .all(|o| {
                o.body
                    .as_ref()
                    .is_some_and(|b| b.shape_version == o.shape.version())
            })
    }

    /// The latest state of every object still there.
    pub(crate) fn latest_meshes(&self) -> BTreeMap<u64, Shape> {
        self.scene
            .objects()
            .map(|object| {
                let mut state = object.shape.clone();
                state.pose = object.pose;
                (object.object_id(), state)
            })
            .collect()
    }
}

fn centroid(mesh: &TriMesh) -> Vec3 {
    mesh.vertices.iter().copied().sum::<Vec3>() / mesh.vertices.len().max(1) as f32
}

fn world_mesh(object: &SceneObject) -> TriMesh {
    TriMesh::new(
        object
            .mesh
            .vertices
            .iter()
            .map(|&v| object.world_from_object.transform_point3(v))
            .collect(),
        object.mesh.triangles.clone(),
    )
}

fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}

pub(crate) const STATIC_SCENE: &str = r#"
[camera]
eye = [0.0, -0.8485, 0.8485]
target = [0.0, 0.0, 0.0]
[table]
size_m = 2.0
[[object]]
id = 1
shape = "cube"
position = [-0.3, 0.0]
[[object]]
id = 2
shape = "sphere"
position = [0.0, 0.15]
[[object]]
id = 3
shape = "torus"
position = [0.3, 0.0]
"#;

/// Every object of a static tabletop gets an accurate, small mesh; the table comes as a few
/// triangles; once the objects are fused, meshing stops.
///
/// Accuracy is judged on what the camera can see: one static view never shows an object's
/// back or bottom, so the paper's symmetric MHE against the whole shape would mostly measure
/// the unseen half. Instead: the mean distance from the published surface to the true surface
/// (is what we publish right?) and from the truly visible surface points to the published
/// mesh (is everything visible covered?), averaged like the paper's MHE. The bound, 3 mm: the
/// simplifier keeps every reconstructed vertex within 4 mm (the daemon's residual bound) and
/// the fit pulls the few output vertices back onto the data, so a mean error of three quarters
/// of the bound leaves room for the 1–1.3 mm depth noise at these 1.1–1.3 m ranges while still
/// failing a mesh that is off by a voxel or misses part of the visible surface.
#[test]
fn static_tabletop_objects_get_accurate_small_meshes_and_stop_being_remeshed() {
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let mut daemon = Daemon::start(STATIC_SCENE);
    let mut subscription = daemon.subscribe();
    let mut got = Received::default();

    // A second daemon on the same socket refuses to start and says why.
    let second = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["run", "--duration-s", "1", "--socket"])
        .arg(&daemon.socket)
        .env("RUST_LOG", "warn")
        .output()
        .expect("tacmesh runs");
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(
        !second.status.success(),
        "a second daemon started: {stderr}"
    );
    assert!(
        stderr.contains("another tacmesh daemon is serving"),
        "{stderr}"
    );
    assert!(
        daemon.socket.exists(),
        "the second daemon removed the first one's socket"
    );

    // Meshing converges in frames, not seconds (a loaded machine processes fewer of them), so
    // the test counts frames: after WARM_UP processed frames, at most two more meshing runs (of
    // three objects) in the next WINDOW frames, against 20–30 in the warm-up. Two, not zero:
    // under heavy load (this binary's other tests beside it) a late doubling of a sparse
    // silhouette voxel was seen once. Early on each object is re-meshed up to 4 times a second as its
    // voxels fill; in the daemon's own runs the last run came near frame 330, then none for
    // 600 frames. The deadline only stops a hang.
    const WARM_UP: u64 = 450;
    const WINDOW: u64 = 150;
    let processed = |s: &tacmesh::protocol::Stats| s.frames_in - s.frames_dropped;
    let deadline = Instant::now() + Duration::from_secs(180);
    let mut runs_after_warm_up = None;
    let last = loop {
        Received::collect(
            &mut subscription,
            Instant::now() + Duration::from_secs(1),
            &mut got,
        );
        let Some((_, stats)) = got.stats.last() else {
            continue;
        };
        let frames = processed(stats);
        if runs_after_warm_up.is_none() && frames >= WARM_UP {
            runs_after_warm_up = Some(stats.meshing_runs);
        }
        if frames >= WARM_UP + WINDOW {
            break stats.clone();
        }
        assert!(Instant::now() < deadline, "only {frames} frames processed");
    };
    let before = runs_after_warm_up.expect("the warm-up ended");
    eprintln!(
        "meshing runs: {before} in the first {WARM_UP} frames, {} more in the next {WINDOW}",
        last.meshing_runs - before
    );
    assert!(before > 0);
    assert!(
        last.meshing_runs - before <= 2,
        "static objects were still being re-meshed: {} runs after frame {WARM_UP}, {} by frame {}",
        before,
        last.meshing_runs,
        processed(&last)
    );
    assert_eq!(last.objects_tracked, 3, "{last:?}");

    // Each object's body is made from its shape off the mesher's thread, at a low priority:
    // on a loaded machine it comes a while after the shape. Wait until every object holds the
    // body of its latest shape (the deadline only stops a hang).
    let deadline = Instant::now() + Duration::from_secs(60);
    while !got.every_body_is_current() {
        assert!(
            Instant::now() < deadline,
            "bodies still behind their shapes after a minute"
        );
        Received::collect(
            &mut subscription,
            Instant::now() + Duration::from_millis(500),
            &mut got,
        );
    }

    let latest = got.latest_meshes();
    let planes: Vec<_> = latest
        .values()
        .filter(|u| u.object_id() >= FIRST_PLANE_ID)
        .collect();
    assert_eq!(planes.len(), 1, "one table plane: {:?}", latest.keys());
    let table = &planes[0].world_mesh();
    assert!(
        (1..=8).contains(&table.triangles.len()),
        "the table is {} triangles",
        table.triangles.len()
    );
    assert!(table.vertices.iter().all(|v| v.z.abs() < 0.01), "{table:?}");
    assert!(table.area() > 0.5, "table area {}", table.area());

    let camera = daemon.scene.clone().into_camera().expect("camera");
    let eye = Vec3::from(camera.config().world_from_sensor.translation);
    // The table: z = 0, up.
    const TABLE: SupportPlane = SupportPlane {
        normal: Vec3::Z,
        offset: 0.0,
    };
    let truth = camera.scene_at(0);
    let visible = camera.visible_surface(0);
    let objects: Vec<&Shape> = latest
        .values()
        .filter(|u| u.object_id() < FIRST_PLANE_ID)
        .collect();
    assert_eq!(objects.len(), 3, "one mesh per object: {:?}", latest.keys());
    for upsert in objects {
        let c = centroid(&upsert.world_mesh());
        let object = truth
            .iter()
            .filter(|o| o.id != 0)
            .min_by(|a, b| {
                let da = world_mesh(a)
                    .bounds()
                    .map_or(f32::MAX, |(lo, hi)| c.distance(0.5 * (lo + hi)));
                let db = world_mesh(b)
                    .bounds()
                    .map_or(f32::MAX, |(lo, hi)| c.distance(0.5 * (lo + hi)));
                da.total_cmp(&db)
            })
            .expect("objects in the scene");
        let true_mesh = world_mesh(object);
        let seen = &visible
            .iter()
            .find(|(id, _)| *id == object.id)
            .expect("visible")
            .1;
        let samples = sample_cloud(
            &upsert.world_mesh(),
            &SampleConfig {
                points: 20_000,
                noise_sigma_m: 0.0,
                seed: 1,
            },
        )
        .expect("the published mesh samples");
        let accuracy = mean(&point_to_mesh_distances(&true_mesh, &samples.points).unwrap());
        let completeness = mean(&point_to_mesh_distances(&upsert.world_mesh(), seen).unwrap());
        let visible_mhe = 0.5 * (accuracy + completeness);
        let faces = upsert.world_mesh().triangles.len();
        eprintln!(
            "object {} (scene id {}): {faces} faces, accuracy {:.2} mm, completeness {:.2} mm, visible MHE {:.2} mm",
            upsert.object_id(),
            object.id,
            accuracy * 1e3,
            completeness * 1e3,
            visible_mhe * 1e3
        );
        assert!(
            visible_mhe < 0.003,
            "object {}: visible MHE {visible_mhe}",
            object.id
        );
        assert!(faces <= 300, "object {}: {faces} faces", object.id);

        // Contact (issue 13) against the true object at its true pose, with 10 mm probes: the
        // published shell from the camera's side; the published body's proxy (closed along the
        // camera's rays by the daemon) and its convex hulls, and the proxy a subscriber can
        // build itself (closed straight down), from every side, where a conservative proxy
        // lets no probe through.
        let probes = |viewpoint_m| ContactConfig {
            probe_radii_m: vec![0.01],
            probe_lines: 2_000,
            viewpoint_m,
            ..ContactConfig::default()
        };
        let seen = contact_fidelity(&true_mesh, &upsert.world_mesh(), &probes(Some(eye)))
            .expect("contact with the shell")
            .overall;
        let (body, published_proxy, hulls) = got
            .world_body(upsert.object_id())
            .unwrap_or_else(|| panic!("object {}: no collision body", object.id));
        assert_eq!(
            body.shape_version,
            upsert.version(),
            "the body of the latest shape"
        );
        // The cube and the ball are primitives when a fit explains their shape within its
        // bound (most shapes; a bumpier one is left to the fallback: the fits are pinned
        // down in `physics` and `daemon::bodies`); the torus is none. A one-view shell that
        // is no primitive has the shadow volume, flagged as the fallback it is, or its shell
        // turned about its axis when that lies within the shadow volume.
        let expected = match (object.id, body.primitive.map(|p| p.shape.name())) {
            (1, Some(kind)) => {
                assert_eq!(kind, "box");
                Some(kind)
            }
            (2, Some(kind)) => {
                assert_eq!(kind, "sphere");
                Some(kind)
            }
            (_, Some(kind)) => panic!("object {}: a {kind}", object.id),
            (_, None) => None,
        };
        if expected.is_none() {
            assert!(
                matches!(body.solid, BodySolid::ShadowVolume | BodySolid::Completed),
                "object {}: a one-view shell's body: {:?}",
                object.id,
                body.solid
            );
        }
        assert!(
            (1..=tacmesh::protocol::MAX_HULLS).contains(&body.hulls.len()),
            "{} hulls",
            body.hulls.len()
        );
        // What the body costs on the wire, beside its shape (full / compact encoding).
        let bytes = |message: Message| {
            let mut frame = Vec::new();
            tacmesh::protocol::encode(&message, &mut frame).expect("a published message encodes");
            frame.len()
        };
        let compact = tacmesh::protocol::Encoding::Compact;
        eprintln!(
            "object {}: shape {} / {} bytes, body {} / {} bytes ({} proxy faces, {} hulls of {} \
             vertices)",
            upsert.object_id(),
            bytes(Message::Shape(upsert.clone())),
            bytes(Message::Shape(Shape {
                encoding: compact,
                ..upsert.clone()
            })),
            bytes(Message::Body(body.clone())),
            bytes(Message::Body(Body {
                encoding: compact,
                ..body.clone()
            })),
            body.mesh.triangles.len(),
            body.hulls.len(),
            body.hulls.iter().map(|h| h.vertices.len()).sum::<usize>()
        );
        let proxy_volume = signed_volume_m3(&published_proxy);
        let tolerance = if expected.is_some() { 2e-3 } else { 1e-3 };
        assert!(
            (f64::from(body.volume_m3) - proxy_volume).abs() < tolerance * proxy_volume,
            "the body's volume {} is its solid's, {proxy_volume}",
            body.volume_m3
        );
        if expected.is_some() || body.solid == BodySolid::Completed {
            // A primitive is the object whole: its mass and centre of mass are the truth's; a
            // completed solid (the torus turned about its axis, its unseen lower half the
            // mirror of its upper) to issue 40's bounds for shapes that are no primitive.
            let ratio = proxy_volume / signed_volume_m3(&true_mesh);
            let world_centre = upsert
                .pose
                .world_from_object()
                .transform_point3(body.centre_of_mass);
            let truth = tacmesh::physics::MassProperties::of_closed_mesh(&true_mesh)
                .expect("the true object is closed");
            let off = world_centre.distance(truth.centre_of_mass);
            // Principal moments, smallest first, each against the truth's (frames apart).
            let moments = tacmesh::physics::MassProperties {
                volume_m3: body.volume_m3,
                centre_of_mass: body.centre_of_mass,
                inertia: body.inertia,
            }
            .principal_moments();
            let inertia: Vec<f32> = moments
                .iter()
                .zip(truth.principal_moments())
                .map(|(got, truth)| got / truth)
                .collect();
            eprintln!(
                "object {}: {:?}, {ratio:.3}× the true volume, centre of mass {:.1} mm off \
                 ({world_centre} against {}), principal inertia {inertia:.2?}× the truth's",
                upsert.object_id(),
                body.primitive,
                off * 1e3,
                truth.centre_of_mass
            );
            assert!(
                inertia.iter().all(|r| (0.7..1.5).contains(r)),
                "object {}: principal inertia {inertia:?}× the truth's",
                object.id
            );
            let (volumes, off_m) = if expected.is_some() {
                (0.8..1.25, 0.015)
            } else {
                (0.7..1.5, 0.020)
            };
            assert!(volumes.contains(&ratio), "object {}: {ratio}×", object.id);
            assert!(off < off_m, "object {}: {off} m off", object.id);
        }
        let straight_down = collision_proxy(
            &upsert.world_mesh(),
            None,
            Some(TABLE),
            &ProxyConfig {
                margin_m: upsert.report.max_residual_m,
                ..ProxyConfig::default()
            },
        );
        for (how, candidate, closed) in [
            ("the published solid", &published_proxy, true),
            ("the published hulls", &hulls, true),
            (
                "the proxy closed straight down",
                &straight_down.mesh,
                straight_down.closed,
            ),
        ] {
            let all_round = contact_fidelity(&true_mesh, candidate, &probes(None))
                .expect("contact with the proxy")
                .overall;
            let through = all_round.missed_by_candidate as f64 / all_round.probes as f64;
            eprintln!(
                "object {}: shell from the camera: first contact {:.1} mm, normal p95 {:.0}°; \
                 {how}: {:.2}× the true volume, {:.1} % of probes through, \
                 {:.1} % stopped where nothing is",
                upsert.object_id(),
                seen.first_contact_m.mean * 1e3,
                seen.normal_deg.p95,
                signed_volume_m3(candidate) / signed_volume_m3(&true_mesh),
                through * 100.0,
                all_round.extra_in_candidate as f64 / all_round.probes as f64 * 100.0
            );
            assert!(closed, "object {}: {how} is open", object.id);
            // Straight down is a subscriber's guess (it does not know the camera): a rounded
            // object's far side bulges past it. The daemon's fallback body is the guarantee; a
            // primitive or a completed solid is the object itself, up to the seen surface's
            // error, and its contact from every side is where the object's is.
            // The bound is the shape's: its top runs on past the edges the camera did not see
            // (by up to one meshing cell, 5–9 mm on this cube), and the box fitted to it
            // with them (p95 11–18 mm over runs; the shadow volume was 161 mm from behind).
            // The torus turned about its axis: its 4 cm tube's section is a polygon of a few
            // slices' noisy radii (about 20 mm at p95).
            if !body.solid.is_fallback() && !how.contains("straight down") {
                let bound_m = if body.solid == BodySolid::Completed {
                    0.030
                } else {
                    0.020
                };
                assert!(
                    all_round.first_contact_m.p95 < bound_m,
                    "object {}: first contact p95 {} m against its body",
                    object.id,
                    all_round.first_contact_m.p95
                );
                continue;
            }
            assert!(
                how.contains("straight down") || through < 0.03,
                "object {}: {:.1} % of the probes pass through {how}",
                object.id,
                through * 100.0
            );
        }
        assert!(
            seen.first_contact_m.mean < 0.008,
            "object {}: first contact {:?}",
            object.id,
            seen.first_contact_m
        );
    }

    // `tacmesh subscribe --count N --out DIR` takes the snapshot's meshes and exits: a Shape of
    // each of the three objects and the table, and each object's latest sighting (a Pose: a
    // static object is told seen about once a second).
    let out_dir = tempfile::tempdir().expect("a temporary folder");
    let subscribe = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["subscribe", "--count", "7", "--socket"])
        .arg(&daemon.socket)
        .arg("--out")
        .arg(out_dir.path())
        .output()
        .expect("tacmesh subscribe runs");
    let stdout = String::from_utf8_lossy(&subscribe.stdout);
    assert!(subscribe.status.success(), "{stdout}");
    let shaped: std::collections::BTreeSet<&str> = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("shape "))
        .filter_map(|l| l.split(" version").next())
        .collect();
    assert_eq!(shaped.len(), 4, "{stdout}");
    let written: Vec<_> = std::fs::read_dir(out_dir.path()).unwrap().collect();
    assert_eq!(written.len(), 4, "{stdout}");
    for entry in written {
        let mesh = tacmesh::formats::read_mesh(&entry.unwrap().path()).expect("a readable PLY");
        assert!(!mesh.triangles.is_empty());
    }

    // Filters hold from the first message: the daemon's default snapshot, sent before it read
    // the options, is neither printed, counted nor written (it once was).
    let filtered = |args: &[&str]| {
        let out_dir = tempfile::tempdir().expect("a temporary folder");
        let out = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
            .arg("subscribe")
            .args(args)
            .arg("--socket")
            .arg(&daemon.socket)
            .arg("--out")
            .arg(out_dir.path())
            .output()
            .expect("tacmesh subscribe runs");
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "{args:?}: {stdout}");
        let mut files: Vec<String> = std::fs::read_dir(out_dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        (stdout, files)
    };
    // "shape object 3 version …", "seen plane 1: still …": the id a line is about.
    let ids_printed = |stdout: &str| -> Vec<(String, String)> {
        stdout
            .lines()
            .filter_map(|line| {
                let mut words = line.split_whitespace();
                let what = words.next()?;
                ["shape", "pose", "seen", "body"].contains(&what).then(|| {
                    let kind = words.next().unwrap_or_default().to_owned();
                    let number = words.next().unwrap_or_default().trim_end_matches(':');
                    (format!("{what} {kind}"), number.to_owned())
                })
            })
            .collect()
    };
    let (stdout, files) = filtered(&["--only", "supports", "--count", "1"]);
    let printed = ids_printed(&stdout);
    assert!(!printed.is_empty(), "{stdout}");
    assert!(
        printed.iter().all(|(what, _)| what.ends_with(" plane")),
        "--only supports printed an object:\n{stdout}"
    );
    assert!(files.iter().all(|f| f.starts_with("plane-")), "{files:?}");
    let number = shaped
        .iter()
        .find_map(|id| id.strip_prefix("object "))
        .expect("an object in the snapshot");
    let (stdout, files) = filtered(&["--id", number, "--no-bodies", "--count", "2"]);
    let printed = ids_printed(&stdout);
    assert!(!printed.is_empty(), "{stdout}");
    for (what, id) in &printed {
        assert!(
            what.ends_with(" object") && id == number,
            "{what} {id}:\n{stdout}"
        );
        assert!(
            !what.starts_with("body"),
            "a body with --no-bodies:\n{stdout}"
        );
    }
    assert_eq!(files, vec![format!("object-{number}.ply")], "{stdout}");

    let (status, _took) = daemon.terminate();
    assert!(status.success(), "{status}");
}

const DYNAMIC_SCENE: &str = r#"
[camera]
eye = [0.0, -0.8485, 0.8485]
target = [0.0, 0.0, 0.0]
[table]
size_m = 2.0
[[object]]
id = 1
shape = "cube"
position = [-0.3, 0.2]
[[object]]
id = 2
shape = "sphere"
size_m = 0.15
[object.path]
mode = "pingpong"
waypoints = [
    { time_s = 0.0, position = [-0.25, -0.25] },
    { time_s = 4.0, position = [0.25, -0.25] },
]
[[object]]
id = 3
shape = "cylinder"
size_m = 0.15
position = [0.3, 0.25]
leave_s = 4.0
"#;

/// A moving object keeps its id, a leaving one is removed, a stalled subscriber and a
/// garbage-sending client do not disturb a well-behaved subscriber, and SIGTERM ends it all
/// cleanly.
#[test]
fn moving_and_leaving_objects_with_misbehaving_clients_then_sigterm() {
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let mut daemon = Daemon::start(DYNAMIC_SCENE);
    let mut good = daemon.subscribe();
    let started = Instant::now();
    let mut got = Received::default();

    // A subscriber that never reads, from the start.
    let stalled = UnixStream::connect(&daemon.socket).expect("connects");
    // Let the scene play a while, then a client sends garbage.
    Received::collect(&mut good, started + Duration::from_secs(3), &mut got);
    let mut garbage = UnixStream::connect(&daemon.socket).expect("connects");
    garbage
        .write_all(&[0xde, 0xad, 0xbe, 0xef, 0xff, 0xff, 0xff, 0x7f, 1, 2, 3])
        .expect("writes");
    let garbage_sent = Instant::now();
    Received::collect(&mut good, started + Duration::from_secs(9), &mut got);

    // The garbage client was cut off: its read ends (after the Hello it was sent).
    garbage
        .set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout set");
    let mut sink = Vec::new();
    let end = garbage.read_to_end(&mut sink);
    assert!(
        end.is_ok() || matches!(end, Err(ref e) if e.kind() == std::io::ErrorKind::ConnectionReset),
        "the daemon kept the garbage client: {end:?}"
    );

    // The moving sphere: one id whose meshes follow the path (y = -0.25) across x.
    let near_path = |u: &Shape| {
        let c = centroid(&u.world_mesh());
        u.object_id() < FIRST_PLANE_ID && (c.y + 0.25).abs() < 0.07 && c.x.abs() < 0.4
    };
    let mut path_ids: BTreeMap<u64, (f32, f32, usize)> = BTreeMap::new();
    for (_, u) in got.updates.iter().filter(|(_, u)| near_path(u)) {
        let x = centroid(&u.world_mesh()).x;
        let entry = path_ids.entry(u.object_id()).or_insert((x, x, 0));
        entry.0 = entry.0.min(x);
        entry.1 = entry.1.max(x);
        entry.2 += 1;
    }
    assert_eq!(
        path_ids.len(),
        1,
        "the moving sphere changed ids: {path_ids:?}"
    );
    let (&sphere_id, &(x_min, x_max, updates)) = path_ids.iter().next().unwrap();
    assert!(
        x_max - x_min > 0.25,
        "the sphere's mesh did not follow it: x from {x_min} to {x_max}"
    );
    assert!(!got.removes.iter().any(|(_, id)| *id == sphere_id));

    // The stalled subscriber did not hold the good one back: the sphere's updates kept coming
    // all through the run, including after the garbage client (a blocking design would stall
    // for the daemon's 5 s write timeout).
    let sphere_times: Vec<Instant> = got
        .updates
        .iter()
        .filter(|(_, u)| u.object_id() == sphere_id)
        .map(|(t, _)| *t)
        .collect();
    let largest_gap = sphere_times
        .windows(2)
        .map(|w| w[1] - w[0])
        .max()
        .unwrap_or_default();
    assert!(updates >= 20, "only {updates} updates of the moving sphere");
    // A design that blocked on the stalled subscriber would pause for the daemon's 5 s write
    // timeout; a busy machine may space updates out, but not that far.
    assert!(
        largest_gap < Duration::from_secs(5),
        "updates paused {largest_gap:?}"
    );
    assert!(sphere_times
        .iter()
        .any(|&t| t > garbage_sent + Duration::from_secs(2)));

    // The cylinder left at 4 s: its id was removed and did not come back.
    let cylinder_ids: Vec<u64> = got
        .updates
        .iter()
        .filter(|(_, u)| {
            let c = centroid(&u.world_mesh());
            u.object_id() < FIRST_PLANE_ID && c.distance(Vec3::new(0.3, 0.25, 0.07)) < 0.08
        })
        .map(|(_, u)| u.object_id())
        .collect();
    let cylinder_id = *cylinder_ids.first().expect("the cylinder got a mesh");
    let removed_at = got
        .removes
        .iter()
        .find(|(_, id)| *id == cylinder_id)
        .map(|(t, _)| *t)
        .expect("the cylinder was removed after it left");
    assert!(got
        .updates
        .iter()
        .all(|(t, u)| u.object_id() != cylinder_id || *t < removed_at));

    drop(stalled);
    // SIGTERM: exit 0 within a couple of seconds, goodbye sent, socket removed.
    let (status, took) = daemon.terminate();
    Received::collect(&mut good, Instant::now() + Duration::from_secs(2), &mut got);
    assert!(status.success(), "{status}");
    assert!(got.goodbye, "no Goodbye before the socket closed");
    assert!(!daemon.socket.exists(), "the socket file was left behind");
    eprintln!("SIGTERM to exit: {took:?}");
    // A hang guard: how quickly it exits is measured by the benches, not asserted here.
    assert!(took < Duration::from_secs(30), "exit took {took:?}");
}

/// Two cameras on opposite sides of the same table feed one object map: each object keeps
/// one id (not one per camera), the table is one plane, and the fused meshes cover both
/// sides (their extent along the cameras' axis is the objects' full depth).
#[test]
fn two_cameras_feed_one_object_map() {
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let back = STATIC_SCENE.replace(
        "eye = [0.0, -0.8485, 0.8485]",
        "eye = [0.0, 0.8485, 0.8485]",
    );
    let daemon = Daemon::start_cameras(&[STATIC_SCENE, &back]);
    let mut subscription = daemon.subscribe();
    let mut got = Received::default();
    Received::collect(
        &mut subscription,
        Instant::now() + Duration::from_secs(10),
        &mut got,
    );
    drop(daemon);

    let last = &got.stats.last().expect("stats").1;
    assert_eq!(last.objects_tracked, 3, "{last:?}");
    let latest = got.latest_meshes();
    let planes = latest.keys().filter(|&&id| id >= FIRST_PLANE_ID).count();
    assert_eq!(planes, 1, "{:?}", latest.keys());
    for upsert in latest.values().filter(|u| u.object_id() < FIRST_PLANE_ID) {
        let (lo, hi) = upsert.world_mesh().bounds().expect("a mesh");
        // Seen from both sides, a 0.2 m object's mesh spans (nearly) its full depth in y;
        // one view of the sphere or torus gives about half of it.
        assert!(
            hi.y - lo.y > 0.17,
            "object {}: y extent {} m",
            upsert.object_id(),
            hi.y - lo.y
        );
    }
}
