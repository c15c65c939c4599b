use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::default_socket_path;
use tacmesh::daemon::planes::FIRST_PLANE_ID;
use tacmesh::protocol::{Message, SimplifyStats, Upsert};
use tacmesh::source::monotonic_now;
use tacmesh::subscriber::Subscription;
use tacmesh::TriMesh;

/// Connect to a running daemon and print one line per message: object (or support plane),
/// version, faces and the age of the data; a move of an unchanged mesh is marked as such.
#[derive(Debug, Args)]
pub struct SubscribeArgs {
    /// Socket path [default, as `tacmesh run`: $XDG_RUNTIME_DIR/tacmesh.sock; without a runtime
    /// directory, /tmp/tacmesh-UID.sock (UID: your numeric user id; $TMPDIR instead of /tmp
    /// when set)]
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Write each object's latest mesh to DIR/object-ID.ply and each support plane's to
    /// DIR/plane-N.ply (replaced whole on every update, never left half-written; deleted when
    /// the object is removed)
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Exit after this many mesh updates
    #[arg(long, value_name = "N")]
    count: Option<u64>,
    /// Also print the daemon's periodic stats
    #[arg(long)]
    stats: bool,
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

fn subscribe(args: SubscribeArgs) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    let socket = args.socket.unwrap_or_else(default_socket_path);
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    }
    let mut subscription = Subscription::connect(&socket, None)?;
    writeln!(
        out,
        "connected to {} on {}",
        subscription.server,
        socket.display()
    )?;
    let mut upserts = 0u64;
    let mut last: BTreeMap<u64, Shown> = BTreeMap::new();
    loop {
        if args.count.is_some_and(|n| upserts >= n) {
            return Ok(());
        }
        let message = subscription.next_message()?;
        match message {
            Message::Upsert(upsert) => {
                upserts += 1;
                let age = Duration::from_nanos(
                    (monotonic_now().as_nanos() as u64).saturating_sub(upsert.capture_time_ns),
                );
                writeln!(
                    out,
                    "{}",
                    describe_upsert(&upsert, last.get(&upsert.object_id), age)
                )?;
                if let Some(dir) = &args.out {
                    let path = dir.join(file_name(upsert.object_id));
                    write_mesh_whole(&path, &upsert.mesh)
                        .with_context(|| format!("writing {}", path.display()))?;
                }
                last.insert(upsert.object_id, Shown::of(upsert));
            }
            Message::Remove { object_id } => {
                writeln!(out, "remove {}", Id(object_id))?;
                last.remove(&object_id);
                if let Some(dir) = &args.out {
                    // Absent when the object never got a mesh here; nothing to do then.
                    let _ = std::fs::remove_file(dir.join(file_name(object_id)));
                }
            }
            Message::SnapshotDone => {
                let planes = last.range(FIRST_PLANE_ID..).count();
                let objects = last.len() - planes;
                let plural = |n: usize| if n == 1 { "" } else { "s" };
                writeln!(
                    out,
                    "snapshot done: {objects} object{}, {planes} plane{}",
                    plural(objects),
                    plural(planes)
                )?;
            }
            Message::Stats(stats) => {
                if args.stats {
                    writeln!(
                    out,
                        "stats frames in {} dropped {} objects {} meshing runs {} published {} bytes {} frame-to-publish p50 {:.1} ms p99 {:.1} ms",
                        stats.frames_in,
                        stats.frames_dropped,
                        stats.objects_tracked,
                        stats.meshing_runs,
                        stats.meshes_published,
                        stats.bytes_sent,
                        stats.frame_to_publish_p50_ms,
                        stats.frame_to_publish_p99_ms
                    )?;
                }
            }
            Message::Goodbye { reason } => {
                writeln!(out, "goodbye: {reason}")?;
                return Ok(());
            }
            other => writeln!(out, "unexpected {} message; ignored", other.name())?,
        }
    }
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

/// What was last shown of an object, to tell a move of the same mesh from a new mesh.
struct Shown {
    mesh: TriMesh,
    report: SimplifyStats,
}

impl Shown {
    fn of(upsert: Upsert) -> Self {
        Self {
            mesh: upsert.mesh,
            report: upsert.report,
        }
    }
}

/// Data older than this is shown in seconds, with a note that the mesh is unchanged since:
/// the daemon re-meshes an object only when new data changed it, so a static object that
/// converged keeps the capture time of its last meshing while it is still tracked (a tracked
/// object that is no longer seen is removed, and a Remove says so).
const UNCHANGED_AFTER: Duration = Duration::from_secs(1);

/// One line for an Upsert: a new mesh, or (same triangles and report as `previous`) the same
/// mesh moved to a new pose.
fn describe_upsert(upsert: &Upsert, previous: Option<&Shown>, age: Duration) -> String {
    let id = Id(upsert.object_id);
    let age = if age < UNCHANGED_AFTER {
        format!("age {:.0} ms", age.as_secs_f64() * 1e3)
    } else {
        format!(
            "age {:.1} s (mesh unchanged since; still tracked)",
            age.as_secs_f64()
        )
    };
    let mesh = &upsert.mesh;
    let pose_only = previous.filter(|p| {
        p.report == upsert.report
            && p.mesh.triangles == mesh.triangles
            && p.mesh.vertices.len() == mesh.vertices.len()
    });
    if let Some(previous) = pose_only {
        let moved_m = previous
            .mesh
            .vertices
            .iter()
            .zip(&mesh.vertices)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0f32, f32::max);
        return format!(
            "upsert {id} version {} pose only: same {} faces, moved up to {:.1} mm; {age}",
            upsert.version,
            mesh.triangles.len(),
            moved_m * 1e3
        );
    }
    if upsert.object_id >= FIRST_PLANE_ID {
        return format!(
            "upsert {id} version {} faces {} vertices {}; {age}",
            upsert.version,
            mesh.triangles.len(),
            mesh.vertices.len()
        );
    }
    format!(
        "upsert {id} version {} faces {} vertices {} (from {} faces, residual {:.1} mm); {age}",
        upsert.version,
        mesh.triangles.len(),
        mesh.vertices.len(),
        upsert.report.faces_in,
        upsert.report.max_residual_m * 1e3
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
    use tacmesh::glam::Vec3;

    fn upsert(object_id: u64, version: u64, shift: f32) -> Upsert {
        Upsert {
            object_id,
            version,
            capture_time_ns: 0,
            mesh: TriMesh::new(
                vec![
                    Vec3::new(shift, 0.0, 0.0),
                    Vec3::new(shift + 0.1, 0.0, 0.0),
                    Vec3::new(shift, 0.1, 0.0),
                ],
                vec![[0, 1, 2]],
            ),
            report: SimplifyStats {
                faces_in: 40,
                faces_out: 1,
                max_residual_m: 0.002,
            },
        }
    }

    const FRESH: Duration = Duration::from_millis(30);

    #[test]
    fn planes_read_as_plane_1_not_as_a_huge_object_id() {
        let line = describe_upsert(&upsert(FIRST_PLANE_ID, 1, 0.0), None, FRESH);
        assert!(line.starts_with("upsert plane 1 version 1 "), "{line}");
        let line = describe_upsert(&upsert(FIRST_PLANE_ID + 1, 1, 0.0), None, FRESH);
        assert!(line.starts_with("upsert plane 2 "), "{line}");
        assert_eq!(Id(FIRST_PLANE_ID).to_string(), "plane 1");
        assert_eq!(Id(7).to_string(), "object 7");
        assert_eq!(file_name(FIRST_PLANE_ID), "plane-1.ply");
        assert_eq!(file_name(7), "object-7.ply");
    }

    #[test]
    fn a_move_of_the_same_mesh_is_marked_pose_only() {
        let first = upsert(3, 1, 0.0);
        let line = describe_upsert(&first, None, FRESH);
        assert!(!line.contains("pose only"), "{line}");
        let moved = upsert(3, 2, 0.012);
        let line = describe_upsert(&moved, Some(&Shown::of(first)), FRESH);
        assert!(
            line.contains("upsert object 3 version 2 pose only") && line.contains("12.0 mm"),
            "{line}"
        );
        // A new mesh (another report) is not a move.
        let mut remeshed = upsert(3, 3, 0.0);
        remeshed.report.faces_in = 41;
        let line = describe_upsert(&remeshed, Some(&Shown::of(moved)), FRESH);
        assert!(!line.contains("pose only"), "{line}");
    }

    #[test]
    fn an_old_mesh_of_a_tracked_object_says_it_is_unchanged_not_stale() {
        let line = describe_upsert(&upsert(3, 1, 0.0), None, FRESH);
        assert!(line.ends_with("age 30 ms"), "{line}");
        let line = describe_upsert(&upsert(3, 1, 0.0), None, Duration::from_secs(75));
        assert!(
            line.ends_with("age 75.0 s (mesh unchanged since; still tracked)"),
            "{line}"
        );
    }

    /// A reader that has the mesh file open while it is replaced still reads the whole old
    /// mesh, and a reader that opens it afterwards the whole new one: the file is replaced,
    /// not rewritten in place (which truncates it under the reader).
    #[test]
    fn out_files_are_replaced_whole_never_rewritten_in_place() {
        use std::io::Read;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("object-3.ply");
        let old = upsert(3, 1, 0.0).mesh;
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
