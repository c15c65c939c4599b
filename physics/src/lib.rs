//! What a physics engine needs from a mesh, beyond its distance to the truth: a closed,
//! outward-facing surface for a solid, a closed collision proxy for a one-view shell, and
//! convex parts with mass properties for a body that can move, and scenes of them all for
//! MuJoCo (MJCF), for Gazebo and PyBullet (SDF) and for the tools that read URDF.

pub mod convex;
pub mod error;
pub mod mass;
pub mod mjcf;
pub mod orientation;
pub mod overlap;
pub mod primitive;
pub mod proxy;
pub mod revolution;
pub mod scene;
pub mod sdf;
pub mod split;
pub mod stl;
pub mod support;
pub mod urdf;

pub use convex::{
    convex_parts, convex_parts_with, vhacd_part_points, ConvexConfig, ConvexParts, Decomposition,
};
pub use error::PhysicsError;
pub use mass::MassProperties;
pub use mjcf::{mjcf_document, write_mjcf, MjcfConfig, MjcfDocument};
pub use overlap::{lift_onto_supports, starting_overlaps, LIFT_MAX_M, OVERLAP_TOLERANCE_M};
pub use primitive::{
    fit_closed_primitive, fit_primitive, lies_within, primitive_of_shape, surface_points,
    FusedPoints, Primitive, PrimitiveShape, MAX_VOLUME_OVER_CONTAINER, PRIMITIVE_NOISE_M,
};
pub use proxy::{collision_proxy, Proxy, ProxyConfig, ProxyKind, SupportPlane};
pub use revolution::{revolve, Revolved};
pub use scene::{
    Exclusion, Member, Motion, Scene, SceneBody, SceneSupport, WorldFromBody, WrittenScene,
    SUPPORT_MARGIN_M, SUPPORT_THICKNESS_M,
};
pub use sdf::{sdf_document, write_sdf, SdfConfig, SdfDocument};
pub use split::split_part_points;
pub use support::{
    min_area_rectangle, resting_top, rests_on, standing_on, support_under, WorldSupport,
    RESTING_GAP_M,
};
pub use tacmesh_source::TriMesh;
pub use urdf::{urdf_documents, write_urdf, UrdfConfig, UrdfDocuments, WrittenUrdf};
