//! Object identity across frames and per-object incremental fusion, with dirty tracking.
//!
//! Each frame the daemon hands in the world points of every segmented object; the map keeps
//! one track per physical object: its id (from 1, never reused), its fused point moments in its
//! own frame, its pose and motion, and how much it changed since it was last meshed.
//!
//! Entry points:
//! - [`ObjectMap::integrate`]: one frame's [`FrameClusters`] in, a [`FrameReport`] out
//!   (created, removed, moved, reset objects).
//! - [`ObjectMap::take_mesh_jobs`]: the objects that changed enough to re-mesh, as
//!   [`MeshJob`]s (a grid for `tacmesh_reconstruct::surface::mesh_moment_grid`).
//! - [`ObjectMap::flush_mesh_jobs`]: at the end of a stream, every object whose latest state
//!   was held back from meshing, with why ([`HeldBack`]).
//! - [`ObjectMap::objects`]: an [`ObjectSummary`] per object.
//!
//! Modules, in the order a frame runs through them: [`camera_error`] (one correction of the
//! frame from the objects standing still, for a camera whose pose is off or missing),
//! [`associate`] (greedy nearest centroids), [`icp`] (point-to-plane alignment to the fused
//! moments, with [`solve6`]), [`object`]
//! (pose dead band, fusion with a weight cap), [`free_space`] (what the frame saw through,
//! which the objects forget), [`change`] (the dirty measure), [`object_map`] (the whole).

pub mod associate;
pub mod camera_error;
pub mod change;
pub mod config;
pub mod free_space;
pub mod icp;
pub mod object;
pub mod object_map;
pub mod solve6;

pub use config::{TrackConfig, TrackError};
pub use free_space::FreeSpace;
pub use object_map::{FrameClusters, FrameReport, HeldBack, MeshJob, ObjectMap, ObjectSummary};
