//! What can go wrong when a mesh is turned into something a physics engine loads.

use std::path::PathBuf;

/// Errors of the physics crate. Each message says what was wrong with the input and what to
/// do about it.
#[derive(Debug, thiserror::Error)]
pub enum PhysicsError {
    /// The mesh has no triangles or a triangle refers past the vertex list.
    #[error("the mesh has no usable triangles ({reason}): pass a closed mesh of a solid")]
    EmptyMesh { reason: String },

    /// All vertices lie (nearly) in one plane or on one line: there is no volume to
    /// decompose or weigh.
    #[error(
        "the mesh is flat: its thinnest extent is {thickness_m:.2e} m against {extent_m:.2e} m \
         across; a table top or a one-view shell needs a closed collision proxy first"
    )]
    FlatMesh { thickness_m: f32, extent_m: f32 },

    /// The mesh encloses no positive volume: it is open, or its triangles face inward.
    #[error(
        "the mesh encloses {volume_m3:.3e} m³: it must be closed and counter-clockwise seen \
         from outside (orient it first, or close it with a proxy)"
    )]
    NoVolume { volume_m3: f64 },

    /// A mass density that is not a positive finite number.
    #[error("density {density_kg_m3} kg/m³ is not a positive finite number")]
    BadDensity { density_kg_m3: f32 },

    /// A scene that cannot be written as asked (an empty name list, a zero normal…).
    #[error("invalid scene: {0}")]
    InvalidScene(String),

    /// Writing a scene or mesh file failed.
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}
