//! Ground truth for tacmesh: the paper's test shapes, seeded noisy surface sampling, and the
//! mean Hausdorff error (MHE) metric that Table 1 reports.
//!
//! Entry points:
//! - [`Shape`]: the six Blender primitives of the paper's Table 1 ([`Shape::ALL`], in table
//!   order). [`Shape::blender_mesh`] is Blender's default primitive in Blender units and axes;
//!   [`Shape::mesh`] is the same fitted into a 1 m bounding box ([`fit_to_extent`]).
//! - [`cube`], [`cylinder`], [`cone`], [`uv_sphere`], [`torus`]: the same primitives with other
//!   resolutions, for tests and benchmarks that need denser meshes.
//! - [`SurfaceSampler`]: area-weighted Monte-Carlo points on a mesh surface, reproducible from a
//!   `u64` seed; [`sample_cloud`] with a [`SampleConfig`] adds isotropic Gaussian noise and
//!   returns the synthetic scan as a [`PointCloud`](tacmesh_source::PointCloud).
//! - [`SimulatedDepthCamera`]: a depth camera ray casting a scene, as a
//!   [`DepthSource`](tacmesh_source::DepthSource), with per-frame ground truth
//!   ([`scene_at`](SimulatedDepthCamera::scene_at),
//!   [`visible_surface`](SimulatedDepthCamera::visible_surface)).
//! - [`Scene`] (static) and [`DynamicScene`] (objects with a [`Motion`] along [`Waypoint`]s,
//!   appearing and leaving, optionally looping); [`SceneFile`] reads both the scene and the
//!   camera from TOML (`scenes/*.toml` at the workspace root; [`SceneFile::demo`] is embedded).
//! - [`Fault`]: a [`FaultKind`] (read error, disconnect, wrong size, zeros, NaN, absurd
//!   intrinsics, a stalled read) injected into the camera's frames by index, from a scene
//!   file's `[[fault]]` tables or [`SimulatedDepthCamera::set_faults`].
//! - [`mesh_distance`]: the symmetric sampled surface distance between two meshes
//!   ([`MeshDistance::mhe_m`] is the paper's MHE; use [`PAPER_SAMPLES`] per side);
//!   [`point_to_mesh_distances`] gives the exact unsigned distance from points to a surface.
//! - [`contact_fidelity`]: probe balls moved toward both meshes along the same lines; errors of
//!   first contact, contact normal and penetration at a push, per probe radius
//!   ([`ContactConfig`], [`ContactFidelity`]).
//!
//! Everything here is deterministic: the same inputs and seed give bit-identical outputs
//! whatever the thread count (see `sampling.rs` for the one cross-platform caveat, the
//! Gaussian noise's rare libm calls).

mod contact;
mod depth_camera;
mod dynamic_scene;
mod faults;
mod metric;
mod motion;
mod sampling;
mod scene;
mod scene_file;
mod shapes;

use glam::Vec3;
use tacmesh_source::TriMesh;

pub use contact::{
    contact_fidelity, ContactConfig, ContactErrors, ContactFidelity, ErrorSummary, RadiusFidelity,
    DEFAULT_PROBE_LINES, DEFAULT_PROBE_RADII_M, DEFAULT_PUSH_M,
};
pub use depth_camera::{
    look_at, DepthCameraConfig, DepthCameraError, DepthNoise, SimulatedDepthCamera,
    DEFAULT_INTRINSICS, DEFAULT_VIEW_DISTANCE_M,
};
pub use dynamic_scene::{DynamicObject, DynamicScene, DynamicSceneBvh};
pub use faults::{check_faults, Fault, FaultKind};
pub use metric::{mesh_distance, point_to_mesh_distances, MeshDistance, PAPER_SAMPLES};
pub use motion::{Motion, PathMode, Waypoint};
pub use sampling::{sample_cloud, SampleConfig, SurfaceSampler};
pub use scene::{
    RayHit, Scene, SceneBvh, SceneError, SceneObject, TABLETOP_OBJECT_EXTENT_M,
    TABLETOP_TABLE_SIDE_M,
};
pub use scene_file::{SceneFile, SceneFileError, DEMO_SCENE_TOML};
pub use shapes::{cone, cube, cylinder, fit_to_extent, square, torus, uv_sphere, Shape};

/// Why a mesh could not be sampled or measured.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("the mesh has no triangles: there is no surface to sample or measure against (did reconstruction or simplification return an empty mesh?)")]
    EmptyMesh,

    #[error("triangle {triangle} refers to vertex {index} but the mesh has only {vertices} vertices: the index buffer is corrupt or belongs to another vertex list")]
    IndexOutOfRange {
        triangle: usize,
        index: u32,
        vertices: usize,
    },

    #[error("vertex {vertex} is not finite ({position}): remove NaN or infinite vertices before sampling or measuring")]
    NonFiniteVertex { vertex: usize, position: Vec3 },

    #[error("the mesh's {triangles} triangles have zero total area, so no point can be sampled on them: check the mesh's scale and whether all its triangles collapsed")]
    ZeroArea { triangles: usize },

    #[error("query point {index} is not finite ({position}): drop NaN or infinite points before measuring distances")]
    NonFinitePoint { index: usize, position: Vec3 },

    #[error("noise sigma must be a finite number of metres >= 0, got {sigma_m}")]
    InvalidNoise { sigma_m: f32 },

    #[error("samples per side must be at least 1 (the paper uses {paper})", paper = PAPER_SAMPLES)]
    NoSamples,

    #[error("a probe radius must be a finite number of metres > 0, got {radius_m}")]
    InvalidProbeRadius { radius_m: f32 },

    #[error("no probe radius given: name at least one (the defaults are 5, 10, 20 and 50 mm)")]
    NoProbeRadii,

    #[error("the number of probe lines must be at least 1 (the default is {default})", default = contact::DEFAULT_PROBE_LINES)]
    NoProbeLines,

    #[error("contact setting {name} must be a finite number >= 0, got {value}")]
    InvalidContactSetting { name: &'static str, value: f32 },

    #[error("the viewpoint is not finite ({viewpoint}): give the sensor's position in metres")]
    NonFiniteViewpoint { viewpoint: Vec3 },

    #[error("no probe of radius {radius_m} m touched either mesh (with a viewpoint, on a surface facing it from its side): is the viewpoint in the meshes' frame and in metres?")]
    NoContacts { radius_m: f32 },

    #[error("in the {role} mesh")]
    InMesh {
        /// `"reference"` or `"candidate"`.
        role: &'static str,
        #[source]
        source: Box<SimError>,
    },
}

impl SimError {
    /// Tags an error with the mesh it concerns (`"reference"` or `"candidate"`).
    fn in_mesh(role: &'static str) -> impl FnOnce(SimError) -> SimError {
        move |source| SimError::InMesh {
            role,
            source: Box::new(source),
        }
    }

    /// The underlying error, looking through [`SimError::InMesh`].
    pub fn root(&self) -> &SimError {
        match self {
            SimError::InMesh { source, .. } => source.root(),
            other => other,
        }
    }
}

/// Checks what every consumer here needs: at least one triangle, indices in range and finite
/// vertices. Zero-area triangles are allowed (they still have well-defined distances).
fn check_mesh(mesh: &TriMesh) -> Result<(), SimError> {
    if mesh.triangles.is_empty() {
        return Err(SimError::EmptyMesh);
    }
    if let Some((triangle, index)) = mesh.first_bad_index() {
        return Err(SimError::IndexOutOfRange {
            triangle,
            index,
            vertices: mesh.vertices.len(),
        });
    }
    if let Some((vertex, &position)) = mesh
        .vertices
        .iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
    {
        return Err(SimError::NonFiniteVertex { vertex, position });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_mesh_names_the_first_defect() {
        assert!(matches!(
            check_mesh(&TriMesh::default()),
            Err(SimError::EmptyMesh)
        ));
        let bad_index = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 7]]);
        assert!(matches!(
            check_mesh(&bad_index),
            Err(SimError::IndexOutOfRange {
                triangle: 0,
                index: 7,
                vertices: 3
            })
        ));
        let nan = TriMesh::new(
            vec![Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Y],
            vec![[0, 1, 2]],
        );
        assert!(matches!(
            check_mesh(&nan),
            Err(SimError::NonFiniteVertex { vertex: 1, .. })
        ));
    }

    #[test]
    fn in_mesh_error_says_which_mesh_and_keeps_the_cause() {
        let err = SimError::in_mesh("candidate")(SimError::EmptyMesh);
        assert_eq!(err.to_string(), "in the candidate mesh");
        assert!(matches!(err.root(), SimError::EmptyMesh));
        let source = std::error::Error::source(&err).map(|s| s.to_string());
        assert_eq!(source, Some(SimError::EmptyMesh.to_string()));
    }
}
