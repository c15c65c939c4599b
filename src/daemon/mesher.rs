//! The meshing worker: turns an object's fused state into a simplified mesh, off the frame
//! path, so that a slow meshing run never holds up frames.
//!
//! Jobs wait in a [`LatestJobs`] queue: a newer job of an object replaces its waiting one (the
//! newer state contains the older), so the queue is bounded by the number of objects. Each
//! published object mesh is handed on to the bodies worker ([`super::bodies`]).

use std::time::Instant;

use tacmesh_protocol::SimplifyStats;
use tacmesh_track::MeshJob;

use super::bodies::BodyJob;
use super::counters::{Counters, Stage};
use super::job_queue::{LatestJobs, ObjectJob};
use super::notify::Heartbeat;
use super::Shared;
use crate::pipeline::mesh_fused_grid;

/// Mesh jobs waiting for the worker, at most one per object.
pub type MeshQueue = LatestJobs<MeshJob>;

impl ObjectJob for MeshJob {
    fn object_id(&self) -> u64 {
        self.object_id
    }
}

/// The worker loop: runs until the queue is closed. `heartbeat` is idle while the worker waits
/// for a job, beaten when it starts one, and retired when the queue closes; a worker stuck in
/// a run, or dead by a panic in one, stays silent and trips the watchdog (see `notify`).
///
/// Idle rather than beaten every second from a timed wait: with the timed wait the daemon's
/// RSS grew by 50 MiB over 20 s of overload (`reliability::overload_…`, twice in a row, and
/// not with a plain wait). The cause was not pinned down; more runs of the two workers at
/// once, each in its own allocator arena, is the likely one.
pub fn run_mesher(shared: &Shared, heartbeat: &Heartbeat) {
    // A thread pool of this worker's own, this thread its first member (with as many threads
    // in all as rayon's default: the machine's cores, or RAYON_NUM_THREADS), so a run's
    // parallel stages (normals, signed distance, marching cubes, the fit) start at once. On
    // the global pool they waited behind the frame path's segmentation, which keeps that pool
    // busy with many small tasks: the same object's normals took 0.4-9 ms from run to run and
    // its signed distance 0.8-26 ms, and a new mesh came that much later (demo scene, new
    // meshes at the subscriber p99 113-114 -> 59-66 ms, with the frame path's speed-ups).
    let _own_pool = rayon::ThreadPoolBuilder::new()
        .use_current_thread()
        .thread_name(|k| format!("mesher pool {k}"))
        .build()
        .inspect_err(|err| {
            tracing::warn!("mesher: runs on the shared thread pool ({err})");
        });
    loop {
        heartbeat.idle();
        let Some(job) = shared.mesh_queue.take() else {
            break;
        };
        heartbeat.beat();
        mesh_one(shared, job);
    }
    heartbeat.retire();
}

fn mesh_one(shared: &Shared, job: MeshJob) {
    let counters = &shared.counters;
    let started = Instant::now();
    counters.record(
        Stage::MeshWait,
        tacmesh_source::monotonic_now().saturating_sub(job.newest_capture),
    );
    let result = mesh_fused_grid(
        &job.grid,
        Some(job.viewpoint_in_object),
        shared.config.mesh.max_residual_m,
        shared.config.mesh.fit_to_data,
        shared.config.mesh.mesh_step_voxels,
    );
    Counters::add(&counters.meshing_runs, 1);
    let (mesh, report) = match result {
        Ok(done) => done,
        Err(err) => {
            // Too little data yet is normal for a new object; anything else is worth a look.
            Counters::add(&counters.meshing_failures, 1);
            if job.end_of_stream {
                // No later frame brings more data: this object gets no mesh.
                tracing::warn!(
                    "object {}: cannot be meshed at the end of the stream: {err}",
                    job.object_id
                );
            } else {
                tracing::debug!("object {}: not meshed yet: {err}", job.object_id);
            }
            return;
        }
    };
    let mesh_ms =
        report.normals_ms + report.orient_ms + report.distance_ms + report.marching_cubes_ms;
    counters.record(
        Stage::Mesh,
        std::time::Duration::from_secs_f64(mesh_ms / 1e3),
    );
    counters.record(
        Stage::Simplify,
        std::time::Duration::from_secs_f64((report.simplify_ms + report.fit_ms) / 1e3),
    );
    if job.end_of_stream {
        tracing::info!(
            "object {}: meshed at the end of the stream: {} points into {} faces",
            job.object_id,
            report.points,
            report.faces
        );
    }
    tracing::debug!(
        "object {}: meshed {} points into {} faces (from {}, {} after the first pass) in {:.1} ms \
         (mesh {:.1}, simplify {:.1} of which refine {:.1}, fit {:.1})",
        job.object_id,
        report.points,
        report.faces,
        report.recon_faces,
        report.first_pass_faces,
        started.elapsed().as_secs_f64() * 1e3,
        mesh_ms,
        report.simplify_ms,
        report.refine_ms,
        report.fit_ms
    );
    let stats = SimplifyStats {
        faces_in: report.recon_faces.min(u32::MAX as usize) as u32,
        faces_out: report.faces.min(u32::MAX as usize) as u32,
        max_residual_m: report.max_residual.max(0.0),
    };
    let mut board = crate::lock(&shared.board);
    let published = board.new_mesh(
        job.object_id,
        mesh,
        stats,
        job.newest_capture,
        &shared.publisher,
        counters,
    );
    // Its collision body is made off this thread: V-HACD takes a few hundred milliseconds on
    // a concave object, and the next mesh should not wait for it.
    if let Some(published) = published {
        let in_world: Vec<glam::Vec3> = published
            .mesh_in_object
            .vertices
            .iter()
            .map(|&v| published.world_from_object.transform_point3(v))
            .collect();
        let supports = board.supports();
        // What it stands on: a support plane, or the top of another object on it (then the
        // plane through that top: the body rests there, not on the table under both).
        let support = tacmesh_physics::standing_on(&supports, &in_world, || {
            board.other_objects_in_world(job.object_id)
        })
        .map(|plane| plane.in_frame(published.world_from_object));
        drop(board);
        let fused = job.grid.surface_means(MAX_FUSED_POINTS);
        shared.body_queue.submit(BodyJob {
            object_id: job.object_id,
            shape_version: published.shape_version,
            mesh_in_object: published.mesh_in_object,
            viewpoint_in_object: Some(job.viewpoint_in_object),
            support,
            margin_m: stats.max_residual_m,
            fused_points: fused.points,
            fused_roughness_m: fused.roughness_m,
        });
    }
}

/// The most fused points a body job carries: a primitive's fit is linear in them, and a
/// few thousand voxels' means pin a primitive's few parameters to a millimetre or two.
pub const MAX_FUSED_POINTS: usize = 4096;

#[cfg(test)]
mod tests {
    use super::*;
    use tacmesh_reconstruct::moment_grid::MomentGrid;

    fn job(object_id: u64, capture_ms: u64) -> MeshJob {
        MeshJob {
            object_id,
            grid: MomentGrid::new(0.01),
            world_from_object: glam::Affine3A::IDENTITY,
            viewpoint_in_object: glam::Vec3::ZERO,
            newest_capture: std::time::Duration::from_millis(capture_ms),
            end_of_stream: false,
        }
    }

    #[test]
    fn jobs_come_out_oldest_first_and_a_newer_job_keeps_its_place() {
        let queue = MeshQueue::default();
        queue.submit(job(7, 1));
        queue.submit(job(3, 2));
        queue.submit(job(7, 3));
        assert_eq!(queue.len(), 2, "one job per object");
        let first = queue.take().unwrap();
        assert_eq!((first.object_id, first.newest_capture.as_millis()), (7, 3));
        assert_eq!(queue.take().unwrap().object_id, 3);
        assert!(queue.is_empty());
    }

    /// The wait before a meshing run is counted from its newest frame's capture, whether the
    /// run then makes a mesh or (as here, on an empty grid) finds too little data.
    #[test]
    fn a_meshing_run_records_its_wait_since_the_capture() {
        let dir = tempfile::tempdir().unwrap();
        let shared = crate::daemon::tests::shared(dir.path());
        let waited = std::time::Duration::from_millis(40);
        let captured = tacmesh_source::monotonic_now().saturating_sub(waited);
        mesh_one(
            &shared,
            MeshJob {
                newest_capture: captured,
                ..job(1, 0)
            },
        );
        let snapshot = shared.counters.snapshot(
            shared.ring.stats(),
            shared.publisher.counters(),
            std::time::Duration::from_secs(1),
        );
        let (_, p50, p99) = snapshot
            .stages
            .iter()
            .find(|(name, ..)| *name == Stage::MeshWait.name())
            .copied()
            .expect("the stage is reported");
        assert!(p50 >= 40.0 && p99 < 40_000.0, "mesh wait {p50} / {p99} ms");
        assert_eq!(snapshot.meshing_runs, 1);
        assert_eq!(snapshot.meshing_failures, 1);
        shared.publisher.shutdown("test over");
    }

    #[test]
    fn cancel_and_close() {
        let queue = MeshQueue::default();
        queue.submit(job(1, 1));
        queue.submit(job(2, 1));
        queue.cancel(1);
        assert_eq!(queue.len(), 1);
        queue.close();
        assert!(queue.take().is_none(), "closed: waiting jobs are dropped");
    }
}
