//! tacmesh: live depth scans to small, accurate, physics-ready meshes of the objects in view.
//!
//! Entry points:
//! - [`pipeline::mesh_cloud`]: one point cloud to one small mesh, with a stage-by-stage report.
//! - [`frame_ring::FrameRing`]: the bounded, drop-oldest queue between sensors and pipeline.
//! - [`latency::LatencyWindow`]: p50/p99 latencies for the daemon's stats.
//! - Re-exported crates: [`formats`] (files), [`reconstruct`], [`simplify`], [`sim`] (shapes,
//!   sampling, the metric, a simulated depth camera), [`source`] (the depth-source trait and
//!   the frame, cloud and mesh types).

pub mod frame_ring;
pub mod latency;
pub mod pipeline;

pub use tacmesh_formats as formats;
pub use tacmesh_reconstruct as reconstruct;
pub use tacmesh_sim as sim;
pub use tacmesh_simplify as simplify;
pub use tacmesh_source as source;
pub use tacmesh_source::{glam, PointCloud, TriMesh};
