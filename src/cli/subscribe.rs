use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::default_socket_path;
use tacmesh::protocol::Message;
use tacmesh::source::monotonic_now;
use tacmesh::subscriber::Subscription;

/// Connect to a running daemon and print one line per message: object, version, faces and the
/// age of the data in milliseconds.
#[derive(Debug, Args)]
pub struct SubscribeArgs {
    /// Socket path [default, as `tacmesh run`: $XDG_RUNTIME_DIR/tacmesh.sock; without a runtime
    /// directory, /tmp/tacmesh-UID.sock (UID: your numeric user id; $TMPDIR instead of /tmp
    /// when set)]
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Write each object's latest mesh to DIR/object-ID.ply (replaced on every update,
    /// deleted when the object is removed)
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
    let mut versions: BTreeMap<u64, u64> = BTreeMap::new();
    loop {
        if args.count.is_some_and(|n| upserts >= n) {
            return Ok(());
        }
        let message = subscription.next_message()?;
        match message {
            Message::Upsert(upsert) => {
                upserts += 1;
                let age_ms = monotonic_now()
                    .as_nanos()
                    .saturating_sub(upsert.capture_time_ns as u128)
                    as f64
                    / 1e6;
                writeln!(
                    out,
                    "upsert object {} version {} faces {} vertices {} (from {} faces, residual {:.1} mm) age {:.0} ms",
                    upsert.object_id,
                    upsert.version,
                    upsert.mesh.triangles.len(),
                    upsert.mesh.vertices.len(),
                    upsert.report.faces_in,
                    upsert.report.max_residual_m * 1e3,
                    age_ms
                )?;
                versions.insert(upsert.object_id, upsert.version);
                if let Some(dir) = &args.out {
                    let path = dir.join(format!("object-{}.ply", upsert.object_id));
                    tacmesh::formats::write_mesh(&path, &upsert.mesh)
                        .with_context(|| format!("writing {}", path.display()))?;
                }
            }
            Message::Remove { object_id } => {
                writeln!(out, "remove object {object_id}")?;
                versions.remove(&object_id);
                if let Some(dir) = &args.out {
                    let path = dir.join(format!("object-{object_id}.ply"));
                    // Absent when the object never got a mesh here; nothing to do then.
                    let _ = std::fs::remove_file(path);
                }
            }
            Message::SnapshotDone => {
                writeln!(out, "snapshot done: {} objects", versions.len())?;
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
