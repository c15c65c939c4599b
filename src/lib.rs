//! tacmesh: live depth scans to small, accurate, physics-ready meshes of the objects in view.
//!
//! Entry points:
//! - [`pipeline::mesh_cloud`]: one point cloud to one small mesh, with a stage-by-stage report.
//! - [`frame_ring::FrameRing`]: the bounded, drop-oldest queue between sensors and pipeline.
//! - [`latency::LatencyWindow`]: p50/p99 latencies for the daemon's stats.
//! - [`log_sink::StderrSink`]: log output that survives a log reader going away.
//! - [`daemon::Daemon`]: `tacmesh run`, the live daemon; [`subscriber::Subscription`]: a client;
//!   [`socket_dir`]: the default socket path and its private directory.
//! - Re-exported crates: [`formats`] (files), [`reconstruct`], [`simplify`], [`sim`] (shapes,
//!   sampling, the metric, a simulated depth camera), [`source`] (the depth-source trait and
//!   the frame, cloud and mesh types).

pub mod daemon;
pub mod frame_ring;
pub mod latency;
pub mod log_sink;
pub mod physics_scene;
pub mod pipeline;
pub mod socket_dir;
pub mod subscriber;

pub use tacmesh_formats as formats;
pub use tacmesh_physics as physics;
pub use tacmesh_protocol as protocol;
pub use tacmesh_reconstruct as reconstruct;
pub use tacmesh_segment as segment;
pub use tacmesh_sim as sim;
pub use tacmesh_simplify as simplify;
pub use tacmesh_source as source;
pub use tacmesh_source::{glam, PointCloud, TriMesh};
pub use tacmesh_track as track;
#[cfg(feature = "zenoh")]
pub use tacmesh_zenoh as zenoh;

/// Locks a mutex, taking the data even if another thread panicked while holding it: every
/// structure guarded here stays consistent between statements, and a daemon that keeps
/// serving beats one that cascades a panic.
pub(crate) fn lock<T>(mutex: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}
