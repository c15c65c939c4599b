//! The meshing worker: turns an object's fused state into a simplified mesh, off the frame
//! path, so that a slow meshing run never holds up frames.
//!
//! Jobs wait in a map keyed by object: a newer job of an object replaces its waiting one (the
//! newer state contains the older), so the queue is bounded by the number of objects.

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use tacmesh_protocol::SimplifyStats;
use tacmesh_track::MeshJob;

use super::counters::{Counters, Stage};
use super::notify::Heartbeat;
use super::Shared;
use crate::pipeline::mesh_fused_grid;

/// How often a waiting worker shows it is alive.
const IDLE_BEAT: Duration = Duration::from_secs(1);

#[derive(Default)]
struct Queue {
    /// Per object: the order in which it was first queued, and its newest job.
    jobs: BTreeMap<u64, (u64, MeshJob)>,
    next_seq: u64,
    closed: bool,
}

/// Mesh jobs waiting for the worker, at most one per object.
#[derive(Default)]
pub struct MeshQueue {
    queue: Mutex<Queue>,
    ready: Condvar,
}

impl MeshQueue {
    /// Queues a job, replacing a waiting job of the same object.
    pub fn submit(&self, job: MeshJob) {
        let mut queue = crate::lock(&self.queue);
        let seq = queue.next_seq;
        queue.next_seq += 1;
        // A newer job replaces the waiting one but keeps its place in line.
        let place = queue
            .jobs
            .get(&job.object_id)
            .map_or(seq, |(place, _)| *place);
        queue.jobs.insert(job.object_id, (place, job));
        self.ready.notify_one();
    }

    /// Drops the waiting job of a removed object.
    pub fn cancel(&self, object_id: u64) {
        crate::lock(&self.queue).jobs.remove(&object_id);
    }

    /// Jobs waiting now.
    pub fn len(&self) -> usize {
        crate::lock(&self.queue).jobs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// No more jobs: the worker finishes the one in hand and stops; waiting jobs are dropped.
    pub fn close(&self) {
        crate::lock(&self.queue).closed = true;
        self.ready.notify_all();
    }

    /// The job of the object that has waited longest, or `None` once closed. Calls `alive`
    /// at least every [`IDLE_BEAT`] while it waits, so that an idle worker is not taken for a
    /// stuck one.
    fn take(&self, alive: &dyn Fn()) -> Option<MeshJob> {
        let mut queue = crate::lock(&self.queue);
        loop {
            alive();
            if queue.closed {
                return None;
            }
            let oldest = queue
                .jobs
                .iter()
                .min_by_key(|(_, (place, _))| *place)
                .map(|(&id, _)| id);
            if let Some((_, job)) = oldest.and_then(|id| queue.jobs.remove(&id)) {
                return Some(job);
            }
            queue = self
                .ready
                .wait_timeout(queue, IDLE_BEAT)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }
}

/// The worker loop: runs until the queue is closed. `heartbeat` is beaten while the worker
/// waits for a job and around each run, and retired when the queue closes; a worker stuck in
/// a run, or dead by a panic, falls silent and trips the watchdog (see `notify`).
pub fn run_mesher(shared: &Shared, heartbeat: &Heartbeat) {
    while let Some(job) = shared.mesh_queue.take(&|| heartbeat.beat()) {
        mesh_one(shared, job);
        heartbeat.beat();
    }
    heartbeat.retire();
}

fn mesh_one(shared: &Shared, job: MeshJob) {
    let counters = &shared.counters;
    let started = Instant::now();
    let result = mesh_fused_grid(
        &job.grid,
        Some(job.viewpoint_in_object),
        shared.config.mesh.max_residual_m,
        shared.config.mesh.fit_to_data,
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
        "object {}: meshed {} points into {} faces (from {}) in {:.1} ms",
        job.object_id,
        report.points,
        report.faces,
        report.recon_faces,
        started.elapsed().as_secs_f64() * 1e3
    );
    let stats = SimplifyStats {
        faces_in: report.recon_faces.min(u32::MAX as usize) as u32,
        faces_out: report.faces.min(u32::MAX as usize) as u32,
        max_residual_m: report.max_residual.max(0.0),
    };
    crate::lock(&shared.board).new_mesh(
        job.object_id,
        mesh,
        stats,
        job.newest_capture,
        &shared.publisher,
        counters,
    );
}

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
        let first = queue.take(&|| {}).unwrap();
        assert_eq!((first.object_id, first.newest_capture.as_millis()), (7, 3));
        assert_eq!(queue.take(&|| {}).unwrap().object_id, 3);
        assert!(queue.is_empty());
    }

    #[test]
    fn cancel_and_close() {
        let queue = MeshQueue::default();
        queue.submit(job(1, 1));
        queue.submit(job(2, 1));
        queue.cancel(1);
        assert_eq!(queue.len(), 1);
        queue.close();
        assert!(
            queue.take(&|| {}).is_none(),
            "closed: waiting jobs are dropped"
        );
    }

    /// A worker waiting for a job keeps showing it is alive, so only a worker stuck inside a
    /// run goes silent.
    #[test]
    fn a_waiting_worker_beats_and_takes_the_job_that_arrives() {
        let queue = MeshQueue::default();
        let beats = std::sync::atomic::AtomicU32::new(0);
        std::thread::scope(|scope| {
            let taker = scope.spawn(|| {
                queue.take(&|| {
                    beats.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                })
            });
            std::thread::sleep(IDLE_BEAT * 2 + Duration::from_millis(500));
            queue.submit(job(4, 1));
            let taken = taker.join().expect("no panic").expect("a job");
            assert_eq!(taken.object_id, 4);
        });
        assert!(beats.load(std::sync::atomic::Ordering::Relaxed) >= 3);
    }
}
