//! tacmesh: live depth scans to small, accurate, physics-ready meshes of the objects in view.

pub mod frame_ring;
pub mod latency;
pub mod pipeline;

pub use tacmesh_formats as formats;
pub use tacmesh_reconstruct as reconstruct;
pub use tacmesh_sim as sim;
pub use tacmesh_simplify as simplify;
pub use tacmesh_source as source;
pub use tacmesh_source::{glam, PointCloud, TriMesh};
