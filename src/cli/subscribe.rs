use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::default_socket_path;
use tacmesh::daemon::planes::FIRST_PLANE_ID;
use tacmesh::physics::{write_mjcf, write_sdf, write_urdf, MjcfConfig, SdfConfig, UrdfConfig};
use tacmesh::physics_scene::PhysicsScene;
use tacmesh::protocol::{Encoding, Kinds, Message, Pose, Scene, SceneChange, Shape, Subscribe};
use tacmesh::source::monotonic_now;
use tacmesh::subscriber::{Subscription, TrustedServers};
use tacmesh::TriMesh;

/// Connect to a running daemon and print one line per message: a new shape of an object (or
/// support plane) with its faces and the age of its data, a move (a pose) with how far and how
/// fast, a sighting of a static object, a removal.
#[derive(Debug, Args)]
pub struct SubscribeArgs {
    /// Socket path [default, as `tacmesh run`: $XDG_RUNTIME_DIR/tacmesh.sock; without a runtime
    /// directory, /tmp/tacmesh-UID/tacmesh.sock (UID: your numeric user id; $TMPDIR instead of
    /// /tmp when set)]
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Write each object's latest mesh, in the world, to DIR/object-ID.ply and each support
    /// plane's to DIR/plane-N.ply (replaced whole on every shape or move, never left
    /// half-written; deleted when the object is removed)
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// With --out: also keep a MuJoCo scene of the objects there, DIR/scene.xml with its meshes
    /// in DIR/meshes: each object a free body, the box, cylinder or sphere its shape is when
    /// one explains it, else the convex collision parts and mass properties (at 500 kg/m³) of
    /// its published collision body (until it has one, of its shape, an open one-view shell
    /// first extruded down onto its support); each support a finite slab; gravity towards the
    /// largest. Bodies collide with each other but for pairs that start inside each other; one
    /// that does not stand on a support by itself is static. Rewritten whole after every new
    /// shape, body or removal and at most once a second for moves
    #[arg(long, requires = "out")]
    mjcf: bool,
    /// With --out: also keep the same scene as an SDFormat world, DIR/scene.sdf (Gazebo loads
    /// it; PyBullet with loadSDF), its meshes in DIR/meshes beside the MuJoCo scene's: each
    /// object a model with the same collision and mass, static where --mjcf's is, each support
    /// a static slab, the same gravity. Kept as --mjcf keeps its scene
    #[arg(long, requires = "out")]
    sdf: bool,
    /// With --out: also keep the scene as URDF, one robot per object and support in
    /// DIR/urdf/NAME.urdf (URDF has no world: DIR/urdf/scene.json gives each one's pose, whether
    /// it is static, the gravity and the pairs that must not collide), with the same meshes.
    /// Kept as --mjcf keeps its scene
    #[arg(long, requires = "out")]
    urdf: bool,
    /// Exit after this many updates (shapes and poses; bodies are not counted)
    #[arg(long, value_name = "N")]
    count: Option<u64>,
    /// Also print the daemon's periodic stats
    #[arg(long)]
    stats: bool,
    /// Ask for shapes in the compact encoding (16-bit vertices within each object's box, about
    /// half the bytes; the residual says what it adds)
    #[arg(long)]
    compact: bool,
    /// At most this many updates a second per object (the latest is sent when the interval is
    /// over): 0 for no cap, else 0.01 to 10000
    #[arg(long, value_name = "HZ", value_parser = parse_rate_hz, allow_hyphen_values = true)]
    max_rate_hz: Option<f32>,
    /// Ask for a Pose only when extrapolating the last one by its velocity would be off by more
    /// than 2 mm or 1° (or once a second): fewer poses for a client that extrapolates; the
    /// printed poses are what was sent
    #[arg(long)]
    extrapolate: bool,
    /// Only objects, or only support planes
    #[arg(long, value_name = "KIND", value_parser = ["objects", "supports"])]
    only: Option<String>,
    /// Do not ask for the objects' collision bodies (a Body message after each shape: closed
    /// proxy, convex hulls, mass properties)
    #[arg(long)]
    no_bodies: bool,
    /// Accept a daemon run by this user id too (repeat, or separate with commas). By default
    /// only a daemon run by you, root or the service user `tacmesh` is believed: another
    /// local user could otherwise bind the socket first and serve forged meshes
    #[arg(long = "trust-uid", value_name = "UID", value_delimiter = ',')]
    trust_uids: Vec<u32>,
    /// Only these object ids (repeat, or separate with commas)
    #[arg(long = "id", value_name = "ID", value_delimiter = ',')]
    ids: Vec<u64>,
    /// Read from Zenoh instead of the socket, joining as FILE's [zenoh] section says (the same
    /// section as the daemon's, with `connect` naming the daemon's or a router's endpoint);
    /// needs a build with the `zenoh` feature
    #[arg(long, value_name = "FILE", conflicts_with_all = ["socket", "compact", "max_rate_hz", "extrapolate", "only", "ids", "no_bodies", "trust_uids"])]
    zenoh: Option<PathBuf>,
}

/// Where the messages come from: the daemon's socket, or Zenoh.
enum Source {
    Socket(Subscription),
    #[cfg(feature = "zenoh")]
    Zenoh(tacmesh::zenoh::ZenohSubscription),
}

impl Source {
    fn open(args: &SubscribeArgs) -> anyhow::Result<(Source, String)> {
        if let Some(file) = &args.zenoh {
            return Self::open_zenoh(file);
        }
        let socket = match &args.socket {
            Some(socket) => socket.clone(),
            None => {
                // Without a runtime directory the default socket is in a directory of the
                // user's own: one that another user made is refused before connecting.
                if let Some(dir) = tacmesh::socket_dir::private_fallback_dir() {
                    match tacmesh::socket_dir::check_private_dir(&dir) {
                        Err(tacmesh::socket_dir::SocketDirError::Probe { cause, .. })
                            if cause.kind() == std::io::ErrorKind::NotFound => {}
                        other => other?,
                    }
                }
                default_socket_path()
            }
        };
        let trusted = args
            .trust_uids
            .iter()
            .fold(TrustedServers::default(), |trusted, &uid| {
                trusted.with_uid(uid)
            });
        let subscription = Subscription::connect_trusting(&socket, None, args.options(), &trusted)?;
        let from = format!("{} on {}", subscription.server, socket.display());
        Ok((Source::Socket(subscription), from))
    }

    #[cfg(feature = "zenoh")]
    fn open_zenoh(file: &Path) -> anyhow::Result<(Source, String)> {
        let config = tacmesh::daemon::DaemonConfig::load(file)?;
        let section = config.zenoh.with_context(|| {
            format!(
                "{} has no [zenoh] section to join Zenoh with",
                file.display()
            )
        })?;
        let settings = section.settings()?;
        let subscription =
            tacmesh::zenoh::ZenohSubscription::connect(&settings, Duration::from_secs(5))?;
        let from = format!("Zenoh, robot {:?}", settings.robot);
        Ok((Source::Zenoh(subscription), from))
    }

    #[cfg(not(feature = "zenoh"))]
    fn open_zenoh(_: &Path) -> anyhow::Result<(Source, String)> {
        anyhow::bail!(
            "this tacmesh was built without the `zenoh` feature: build it with \
             `cargo build --release --features zenoh` to subscribe over Zenoh"
        )
    }

    fn next_message(&mut self) -> anyhow::Result<Message> {
        match self {
            Source::Socket(subscription) => Ok(subscription.next_message()?),
            #[cfg(feature = "zenoh")]
            Source::Zenoh(subscription) => loop {
                if let Some(message) = subscription.next_message(Duration::from_secs(60))? {
                    return Ok(message);
                }
            },
        }
    }
}

impl SubscribeArgs {
    /// The Subscribe these options ask for, or `None` for the defaults (nothing to send).
    fn options(&self) -> Option<Subscribe> {
        let options = Subscribe {
            encoding: if self.compact {
                Encoding::Compact
            } else {
                Encoding::Full
            },
            resend: true,
            extrapolate: self.extrapolate,
            max_rate_hz: self.max_rate_hz.unwrap_or(0.0),
            kinds: {
                let kinds = match self.only.as_deref() {
                    Some("objects") => Kinds::OBJECTS.with(Kinds::BODIES),
                    Some("supports") => Kinds::SUPPORTS,
                    _ => Kinds::ALL,
                };
                if self.no_bodies {
                    kinds.without(Kinds::BODIES).unwrap_or(kinds)
                } else {
                    kinds
                }
            },
            object_ids: self.ids.clone(),
        };
        let defaults = Subscribe {
            resend: true,
            ..Subscribe::default()
        };
        (options != defaults).then_some(options)
    }
}

pub fn run(args: SubscribeArgs) -> anyhow::Result<()> {
    match subscribe(args) {
        // Standard output closed (`tacmesh subscribe | head`): the reader has all it wanted.
        Err(err)
            if err
                .downcast_ref::<std::io::Error>()
                .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            Ok(())
        }
        other => other,
    }
}

/// `--max-rate-hz`: the range the protocol allows (docs/protocol.md, Subscribe), checked here
/// so that the daemon never has to drop this client for it.
fn parse_rate_hz(text: &str) -> Result<f32, String> {
    use tacmesh::protocol::{check_rate, MAX_RATE_HZ, MIN_RATE_HZ};
    match text.trim().parse::<f32>() {
        Ok(rate) if check_rate(rate).is_ok() => Ok(rate),
        _ => Err(format!(
            "give 0 (no cap) or a rate from {MIN_RATE_HZ} to {MAX_RATE_HZ} updates a second"
        )),
    }
}

fn subscribe(args: SubscribeArgs) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    }
    anyhow::ensure!(
        args.ids.len() <= tacmesh::protocol::MAX_SUBSCRIBE_IDS,
        "--id: at most {} ids",
        tacmesh::protocol::MAX_SUBSCRIBE_IDS
    );
    let (mut subscription, from) = Source::open(&args)?;
    writeln!(out, "connected to {from}")?;
    let mut updates = 0u64;
    let mut scene = Scene::new();
    let mut physics_files = (args.mjcf || args.sdf || args.urdf).then(|| PhysicsFiles {
        mjcf: args.mjcf,
        sdf: args.sdf,
        urdf: args.urdf,
        physics: PhysicsScene::new(),
        written_at: None,
        warned: Default::default(),
        held_still: Default::default(),
        overlapping: Default::default(),
        primitives: Default::default(),
    });
    // With options of its own, the daemon's first snapshot (under the default options, sent
    // before it read them) is not what was asked for: everything up to the Session answering
    // the Subscribe is skipped, so that filtered-out objects are neither printed, counted nor
    // written.
    let mut awaiting_answer = args.zenoh.is_none() && args.options().is_some();
    loop {
        if args.count.is_some_and(|n| updates >= n) {
            return Ok(());
        }
        let message = subscription.next_message()?;
        if awaiting_answer {
            match &message {
                Message::Session(session) if session.options.resend => awaiting_answer = false,
                Message::Goodbye { .. } => {}
                _ => continue,
            }
        }
        let previous_pose = match &message {
            Message::Pose(pose) => scene.get(pose.object_id).map(|object| object.pose),
            _ => None,
        };
        let change = scene.apply(&message);
        let changed = match (change, &message) {
            (SceneChange::Added(id) | SceneChange::Reshaped(id), Message::Shape(shape)) => {
                updates += 1;
                writeln!(
                    out,
                    "{}",
                    describe_shape(shape, age_of(shape.shape_time_ns))
                )?;
                Some(id)
            }
            (SceneChange::Moved(id), Message::Pose(pose)) => {
                updates += 1;
                let previous = previous_pose.unwrap_or(*pose);
                writeln!(out, "{}", describe_pose(pose, &previous))?;
                (pose.pose_time_ns != previous.pose_time_ns).then_some(id)
            }
            (SceneChange::Bodied(id), Message::Body(body)) => {
                writeln!(out, "{}", describe_body(body))?;
                Some(id)
            }
            (SceneChange::Removed(id), _) => {
                writeln!(out, "remove {}", Id(id))?;
                if let Some(dir) = &args.out {
                    // Absent when the object never got a mesh here; nothing to do then.
                    let _ = std::fs::remove_file(dir.join(file_name(id)));
                }
                None
            }
            (SceneChange::SnapshotDone, _) => {
                let planes = scene
                    .objects()
                    .filter(|o| o.object_id() >= FIRST_PLANE_ID)
                    .count();
                let objects = scene.len() - planes;
                let plural = |n: usize| if n == 1 { "" } else { "s" };
                writeln!(
                    out,
                    "snapshot done: {objects} object{}, {planes} plane{}",
                    plural(objects),
                    plural(planes)
                )?;
                None
            }
            (_, Message::Stats(stats)) => {
                if args.stats {
                    writeln!(
                        out,
                        "stats frames in {} dropped {} objects {} meshing runs {} shapes {} poses {} bytes {} \
                         source errors {} malformed frames {} subscribers {} frame-to-publish p50 {:.1} ms p99 {:.1} ms",
                        stats.frames_in,
                        stats.frames_dropped,
                        stats.objects_tracked,
                        stats.meshing_runs,
                        stats.shapes_published,
                        stats.poses_published,
                        stats.bytes_sent,
                        stats.source_errors,
                        stats.malformed_frames,
                        stats.clients_connected,
                        stats.frame_to_publish_p50_ms,
                        stats.frame_to_publish_p99_ms
                    )?;
                }
                None
            }
            (_, Message::Goodbye { reason }) => {
                writeln!(out, "goodbye: {reason}")?;
                return Ok(());
            }
            // A Session (the scene starts again), a stale update, a Remove of an object not
            // held: nothing to show.
            (
                _,
                Message::Session(_)
                | Message::Shape(_)
                | Message::Body(_)
                | Message::Pose(_)
                | Message::Remove { .. },
            ) => None,
            (_, other) => {
                writeln!(out, "unexpected {} message; ignored", other.name())?;
                None
            }
        };
        let changed_mesh = changed.filter(|_| !matches!(change, SceneChange::Bodied(_)));
        if let (Some(dir), Some(id)) = (&args.out, changed_mesh) {
            if let Some(mesh) = scene.world_mesh(id) {
                let path = dir.join(file_name(id));
                write_mesh_whole(&path, &mesh)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
        if let (Some(dir), Some(files)) = (&args.out, physics_files.as_mut()) {
            let reshaped = matches!(
                change,
                SceneChange::SnapshotDone
                    | SceneChange::Added(_)
                    | SceneChange::Reshaped(_)
                    | SceneChange::Bodied(_)
                    | SceneChange::Removed(_)
            );
            let moved = matches!(change, SceneChange::Moved(_));
            if scene.snapshot_done() && (reshaped || (moved && files.due())) {
                files.write(dir, &scene)?;
            }
        }
    }
}

/// The physics scenes `--mjcf`, `--sdf` and `--urdf` keep in the output folder.
struct PhysicsFiles {
    /// Write DIR/scene.xml.
    mjcf: bool,
    /// Write DIR/scene.sdf.
    sdf: bool,
    /// Write DIR/urdf/.
    urdf: bool,
    physics: PhysicsScene,
    written_at: Option<Instant>,
    /// Objects already warned about, so a shape that cannot collide is said once.
    warned: std::collections::HashSet<u64>,
    /// Objects already said to be held still.
    held_still: std::collections::HashSet<u64>,
    /// Pairs already said to start inside each other.
    overlapping: std::collections::HashSet<(String, String)>,
    /// The primitive each object was last said to be (or none).
    primitives: std::collections::HashMap<u64, Option<&'static str>>,
}

impl PhysicsFiles {
    /// Moves alone rewrite the scene at most this often.
    const MOVE_INTERVAL: Duration = Duration::from_secs(1);

    fn due(&self) -> bool {
        self.written_at
            .is_none_or(|at| at.elapsed() >= Self::MOVE_INTERVAL)
    }

    fn write(&mut self, dir: &Path, scene: &Scene) -> anyhow::Result<()> {
        let update = self.physics.update(scene);
        for (id, why) in &update.left_out {
            if self.warned.insert(*id) {
                tracing::warn!("object {id} is left out of the physics scene: {why}");
            }
        }
        for (id, why) in &update.held_still {
            if self.held_still.insert(*id) {
                tracing::info!("object {id} is static in the physics scene: {why}");
            }
        }
        for &(id, fit) in &update.primitives {
            let kind = fit.map(|(kind, _)| kind);
            let was = self.primitives.insert(id, kind).flatten();
            match (was, fit) {
                (was, Some((kind, residual_m))) if was != Some(kind) => tracing::info!(
                    "object {id} is a {kind} in the physics scene ({:.1} mm from its shape at \
                     the 95th percentile)",
                    residual_m * 1e3
                ),
                (Some(was), None) => tracing::info!(
                    "object {id} is no longer a {was} in the physics scene: no primitive \
                     explains its new shape"
                ),
                _ => {}
            }
        }
        for (a, b, depth_m) in &update.overlaps {
            if self.overlapping.insert((a.clone(), b.clone())) {
                tracing::info!(
                    "{a} and {b} start {:.0} mm inside each other: they do not collide with \
                     each other in the physics scene",
                    depth_m * 1e3
                );
            }
        }
        let mut keep: std::collections::HashSet<PathBuf> = Default::default();
        if self.mjcf {
            let written = write_mjcf(dir, &update.scene, &MjcfConfig::default())
                .with_context(|| format!("writing the MuJoCo scene in {}", dir.display()))?;
            keep.extend(written.mesh_files);
        }
        if self.sdf {
            let written = write_sdf(dir, &update.scene, &SdfConfig::default())
                .with_context(|| format!("writing the SDF world in {}", dir.display()))?;
            keep.extend(written.mesh_files);
        }
        if self.urdf {
            let written = write_urdf(dir, &update.scene, &UrdfConfig::default())
                .with_context(|| format!("writing the URDF files in {}", dir.display()))?;
            keep.extend(written.mesh_files);
            // The robots of objects gone: the index no longer names them.
            let robots: std::collections::HashSet<PathBuf> =
                written.robot_files.into_iter().collect();
            let urdf_dir = dir.join(tacmesh::physics::urdf::URDF_FOLDER);
            for entry in std::fs::read_dir(&urdf_dir)
                .with_context(|| format!("listing {}", urdf_dir.display()))?
                .flatten()
            {
                let path = entry.path();
                if path.extension().is_some_and(|e| e == "urdf") && !robots.contains(&path) {
                    let _ = std::fs::remove_file(&path);
                }
            }
        }
        self.written_at = Some(Instant::now());
        // Meshes of objects gone, or parts an object no longer has: no scene names them.
        let mesh_dir = dir.join(tacmesh::physics::scene::MESH_FOLDER);
        for entry in std::fs::read_dir(&mesh_dir)
            .with_context(|| format!("listing {}", mesh_dir.display()))?
            .flatten()
        {
            let path = entry.path();
            if path.extension().is_some_and(|e| e == "stl") && !keep.contains(path.as_path()) {
                let _ = std::fs::remove_file(&path);
            }
        }
        Ok(())
    }
}

/// The age of data captured at `capture_ns` on this host's monotonic clock.
fn age_of(capture_ns: u64) -> Duration {
    Duration::from_nanos((monotonic_now().as_nanos() as u64).saturating_sub(capture_ns))
}

/// An object id as a reader takes it: objects by their id, support planes (ids from 2^32 up,
/// see `tacmesh::daemon::planes`) counted from 1, so that `plane 4294967296` does not read as
/// a four-billionth object.
struct Id(u64);

impl Id {
    /// `("object", id)` or `("plane", N)`.
    fn kind_and_number(&self) -> (&'static str, u64) {
        match self.0.checked_sub(FIRST_PLANE_ID) {
            Some(k) => ("plane", k + 1),
            None => ("object", self.0),
        }
    }
}

impl std::fmt::Display for Id {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (kind, number) = self.kind_and_number();
        write!(f, "{kind} {number}")
    }
}

/// `object-ID.ply` or `plane-N.ply`, as [`Id`] names it.
fn file_name(object_id: u64) -> String {
    let (kind, number) = Id(object_id).kind_and_number();
    format!("{kind}-{number}.ply")
}

/// Data older than this is shown in seconds, with a note that the shape is unchanged since:
/// the daemon re-meshes an object only when new data changed it, so a static object that
/// converged keeps the time of its last meshing while it is still tracked (its sightings say
/// it is still there, and a Remove says when it is gone).
const UNCHANGED_AFTER: Duration = Duration::from_secs(1);

fn describe_age(age: Duration, what: &str) -> String {
    if age < UNCHANGED_AFTER {
        format!("age {:.0} ms", age.as_secs_f64() * 1e3)
    } else {
        format!("age {:.1} s ({what} unchanged since)", age.as_secs_f64())
    }
}

/// One line for a Shape: a new mesh of an object.
fn describe_shape(shape: &Shape, age: Duration) -> String {
    let id = Id(shape.object_id());
    let age = describe_age(age, "shape");
    let mesh = &shape.mesh;
    let closed = if shape.is_closed() { "closed" } else { "open" };
    if shape.is_support() {
        return format!(
            "shape {id} version {} faces {} vertices {}; {age}",
            shape.version(),
            mesh.triangles.len(),
            mesh.vertices.len()
        );
    }
    format!(
        "shape {id} version {} faces {} vertices {} {closed} (from {} faces, residual {:.1} mm); {age}",
        shape.version(),
        mesh.triangles.len(),
        mesh.vertices.len(),
        shape.report.faces_in,
        shape.report.max_residual_m * 1e3
    )
}

/// One line for a Body: what its solid is, its hulls and its volume.
fn describe_body(body: &tacmesh::protocol::Body) -> String {
    use tacmesh::protocol::{BodySolid, PrimitiveShape};
    let vertices: usize = body.hulls.iter().map(|h| h.vertices.len()).sum();
    let solid = match (body.solid, &body.primitive) {
        (BodySolid::Shape, _) => "the shape itself".to_owned(),
        (BodySolid::Primitive, Some(p)) => {
            let mm = |m: f32| m * 1e3;
            let sizes = match p.shape {
                PrimitiveShape::Box { half_m } => format!(
                    "{:.0} × {:.0} × {:.0} mm",
                    mm(2.0 * half_m.x),
                    mm(2.0 * half_m.y),
                    mm(2.0 * half_m.z)
                ),
                PrimitiveShape::Cylinder {
                    radius_m,
                    half_height_m,
                }
                | PrimitiveShape::Capsule {
                    radius_m,
                    half_height_m,
                } => format!(
                    "radius {:.0} mm, axis {:.0} mm",
                    mm(radius_m),
                    mm(2.0 * half_height_m)
                ),
                PrimitiveShape::Sphere { radius_m } => format!("radius {:.0} mm", mm(radius_m)),
            };
            format!(
                "a {} ({sizes}, seen within {:.1} mm)",
                p.shape.name(),
                mm(p.residual_m)
            )
        }
        (other, _) => format!(
            "{} of {} faces, grown {:.1} mm",
            other.as_str(),
            body.mesh.triangles.len(),
            body.margin_m * 1e3
        ),
    };
    format!(
        "body {} shape {}: {solid}, {} convex hulls ({vertices} vertices), volume {:.2} l",
        Id(body.object_id),
        body.shape_version,
        body.hulls.len(),
        body.volume_m3 * 1e3
    )
}

/// One line for a Pose: a move (how far, how fast) or a sighting of an object held still.
fn describe_pose(pose: &Pose, previous: &Pose) -> String {
    let id = Id(pose.object_id);
    if pose.pose_time_ns == previous.pose_time_ns {
        return format!(
            "seen {id}: still, last seen {}",
            describe_age(age_of(pose.last_seen_ns), "pose").replace("age ", "")
        );
    }
    let moved_mm = pose.translation.distance(previous.translation) * 1e3;
    let turned_deg = pose.rotation.angle_between(previous.rotation).to_degrees();
    format!(
        "pose {id} shape {}: moved {moved_mm:.1} mm, turned {turned_deg:.1}°, velocity {:.3} m/s {:.2} rad/s; {}",
        pose.shape_version,
        pose.linear_velocity.length(),
        pose.angular_velocity.length(),
        describe_age(age_of(pose.pose_time_ns), "pose")
    )
}

/// Writes `mesh` to `path` as PLY through a temporary file in the same folder, renamed over
/// `path` once complete: a reader that opens `path` at any moment sees the old mesh or the
/// new one, never a truncated one.
fn write_mesh_whole(path: &Path, mesh: &TriMesh) -> anyhow::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Hidden, and named by process, so that neither a `*.ply` glob nor another subscriber
    // writing to the same folder picks it up.
    let partial = dir.join(format!(".{name}.{}.partial", std::process::id()));
    let written = (|| -> std::io::Result<()> {
        let mut file = std::io::BufWriter::new(std::fs::File::create(&partial)?);
        tacmesh::formats::ply::write_mesh(&mut file, mesh)?;
        file.into_inner().map_err(|e| e.into_error())?.sync_data()?;
        std::fs::rename(&partial, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&partial);
    }
    written.with_context(|| format!("through {}", partial.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tacmesh::glam::{Quat, Vec3};
    use tacmesh::protocol::{SimplifyStats, SHAPE_SUPPORT};

    fn pose(object_id: u64, shape_version: u64, time_ms: u64, x: f32) -> Pose {
        Pose {
            object_id,
            shape_version,
            pose_time_ns: time_ms * 1_000_000,
            pose_time_realtime_ns: 0,
            last_seen_ns: time_ms * 1_000_000,
            rotation: Quat::IDENTITY,
            translation: Vec3::new(x, 0.0, 0.0),
            linear_velocity: Vec3::new(0.4, 0.0, 0.0),
            angular_velocity: Vec3::ZERO,
        }
    }

    fn shape(object_id: u64, version: u64) -> Shape {
        Shape {
            pose: pose(object_id, version, 0, 0.0),
            shape_time_ns: 0,
            shape_time_realtime_ns: 0,
            flags: if object_id >= FIRST_PLANE_ID {
                SHAPE_SUPPORT
            } else {
                0
            },
            mesh: TriMesh::new(
                vec![
                    Vec3::ZERO,
                    Vec3::new(0.1, 0.0, 0.0),
                    Vec3::new(0.0, 0.1, 0.0),
                ],
                vec![[0, 1, 2]],
            ),
            report: SimplifyStats {
                faces_in: 40,
                faces_out: 1,
                max_residual_m: 0.002,
            },
            encoding: Encoding::Full,
        }
    }

    const FRESH: Duration = Duration::from_millis(30);

    #[test]
    fn planes_read_as_plane_1_not_as_a_huge_object_id() {
        let line = describe_shape(&shape(FIRST_PLANE_ID, 1), FRESH);
        assert!(line.starts_with("shape plane 1 version 1 "), "{line}");
        let line = describe_shape(&shape(FIRST_PLANE_ID + 1, 1), FRESH);
        assert!(line.starts_with("shape plane 2 "), "{line}");
        assert_eq!(Id(FIRST_PLANE_ID).to_string(), "plane 1");
        assert_eq!(Id(7).to_string(), "object 7");
        assert_eq!(file_name(FIRST_PLANE_ID), "plane-1.ply");
        assert_eq!(file_name(7), "object-7.ply");
    }

    #[test]
    fn a_move_says_how_far_and_a_sighting_says_still() {
        let before = pose(3, 1, 100, 0.0);
        let line = describe_pose(&pose(3, 1, 133, 0.012), &before);
        assert!(
            line.starts_with(
                "pose object 3 shape 1: moved 12.0 mm, turned 0.0°, velocity 0.400 m/s"
            ),
            "{line}"
        );
        let mut seen = before;
        seen.last_seen_ns += 500_000_000;
        let line = describe_pose(&seen, &before);
        assert!(
            line.starts_with("seen object 3: still, last seen "),
            "{line}"
        );
    }

    #[test]
    fn an_old_shape_says_it_is_unchanged_not_stale() {
        let line = describe_shape(&shape(3, 1), FRESH);
        assert!(
            line.contains(" open (from 40 faces, residual 2.0 mm)"),
            "{line}"
        );
        assert!(line.ends_with("age 30 ms"), "{line}");
        let line = describe_shape(&shape(3, 1), Duration::from_secs(75));
        assert!(
            line.ends_with("age 75.0 s (shape unchanged since)"),
            "{line}"
        );
    }

    #[test]
    fn default_options_send_nothing_and_others_ask_for_a_resend() {
        let parse = |args: &[&str]| {
            use clap::Parser;
            #[derive(clap::Parser)]
            struct Cli {
                #[command(flatten)]
                args: SubscribeArgs,
            }
            Cli::parse_from(std::iter::once("subscribe").chain(args.iter().copied())).args
        };
        assert_eq!(parse(&[]).options(), None);
        let options = parse(&[
            "--compact",
            "--only",
            "objects",
            "--id",
            "3,5",
            "--max-rate-hz",
            "10",
        ])
        .options()
        .expect("options");
        assert_eq!(options.encoding, Encoding::Compact);
        assert!(options.resend);
        assert_eq!(options.kinds, Kinds::OBJECTS.with(Kinds::BODIES));
        assert_eq!(options.object_ids, vec![3, 5]);
        assert_eq!(options.max_rate_hz, 10.0);
        let no_bodies = parse(&["--no-bodies"]).options().expect("options");
        assert_eq!(no_bodies.kinds, Kinds::OBJECTS.with(Kinds::SUPPORTS));
        let supports = parse(&["--only", "supports"]).options().expect("options");
        assert_eq!(supports.kinds, Kinds::SUPPORTS);
    }

    /// `--max-rate-hz` takes the protocol's range, negative numbers included (clap once took
    /// `-1` for an unknown option), and says what it takes otherwise.
    #[test]
    fn max_rate_hz_is_checked_against_the_protocol_range() {
        use clap::Parser;
        #[derive(clap::Parser, Debug)]
        struct Cli {
            #[command(flatten)]
            args: SubscribeArgs,
        }
        for good in ["0", "0.01", "30", "10000"] {
            let cli = Cli::try_parse_from(["subscribe", "--max-rate-hz", good]);
            assert!(cli.is_ok(), "{good}: {cli:?}");
        }
        for bad in ["1e-45", "-1", "0.001", "1e5", "inf", "NaN", "ten"] {
            let err = Cli::try_parse_from(["subscribe", "--max-rate-hz", bad])
                .expect_err(bad)
                .to_string();
            assert!(err.contains("0 (no cap)"), "{bad}: {err}");
        }
    }

    /// A reader that has the mesh file open while it is replaced still reads the whole old
    /// mesh, and a reader that opens it afterwards the whole new one: the file is replaced,
    /// not rewritten in place (which truncates it under the reader).
    #[test]
    fn out_files_are_replaced_whole_never_rewritten_in_place() {
        use std::io::Read;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("object-3.ply");
        let old = shape(3, 1).mesh;
        write_mesh_whole(&path, &old).unwrap();
        let mut reader = std::fs::File::open(&path).unwrap();
        let big = TriMesh::new(
            (0..3000).map(|i| Vec3::splat(i as f32)).collect(),
            (0..1000).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect(),
        );
        write_mesh_whole(&path, &big).unwrap();
        let mut bytes = Vec::new();
        reader.read_to_end(&mut bytes).unwrap();
        let partial = dir.path().join("held.ply");
        std::fs::write(&partial, &bytes).unwrap();
        assert_eq!(tacmesh::formats::read_mesh(&partial).unwrap(), old);
        assert_eq!(tacmesh::formats::read_mesh(&path).unwrap(), big);
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 2, "no partial file left: {names:?}");
    }
}
