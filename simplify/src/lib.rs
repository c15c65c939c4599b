//! Edge-collapse simplification of triangle meshes, stopped by a maximum residual in metres.
//!
//! Entry point: [`simplify`] takes a [`TriMesh`](tacmesh_source::TriMesh) (usually a dense
//! marching-cubes mesh) and a [`SimplifyConfig`], and returns the simplified mesh with a
//! [`SimplifyReport`] of what it did, including the residual it actually reached.
//! [`simplify_near_points`] holds extra points to the same bound besides the mesh's own
//! vertices: the pipeline's second pass over a fitted mesh, held to the marching-cubes mesh the
//! first pass started from.
//!
//! # Method
//!
//! Greedy edge collapse: edges are ranked by the quadric error of
//! Garland & Heckbert, with the new vertex placed at the quadric minimiser plus a tiny version
//! of Hoppe's spring energy; each popped edge must pass a topology test (the link condition of
//! Dey et al.), a geometry test (no flipped, folded, degenerate or needle triangles) and the
//! residual test below. Simplification runs until no edge passes, or [`SimplifyConfig::min_faces`]
//! is reached.
//!
//! # The residual (the stop rule)
//!
//! Every vertex of the input mesh that is used by a triangle with three distinct indices is a
//! *support point*. Throughout the run each support point is assigned to exactly one face of the
//! current mesh, initially to its largest incident face (distance 0); its *residual* is its exact
//! point-to-triangle distance, in metres, to that face. A collapse of edge `ab` to the position
//! `v*` is accepted only if
//!
//! 1. every support point assigned to a face incident to `a` or `b` lies within
//!    [`SimplifyConfig::max_residual_m`] of at least one of the faces around `v*` after the
//!    collapse (exact point-to-triangle distances), and
//! 2. `v*` itself lies within `max_residual_m` of the faces around `a` and `b` before the
//!    collapse (so the new vertex cannot bulge away from the surface).
//!
//! The points are then reassigned: to the nearest face around `v*`, except that a point whose
//! own face survives and stays within half of `max_residual_m` of it keeps that face (this skips
//! most of the search and, on the test shapes, changes no face count). The check bails out at the
//! first point that is too far, and only the popped edge is checked.
//!
//! So at every step, and in the output, **every input vertex lies within `max_residual_m` of the
//! output surface**: the one-sided Hausdorff distance from the input vertices to the output is
//! bounded without any Hausdorff pass. [`SimplifyReport::max_residual_m`] is the largest distance
//! from a support point to its assigned face at the end, an upper bound of that distance (it can
//! exceed the true distance to the nearest output face). This plays the role of the "maximum
//! directional residual" that the paper this project follows stops on (Hoppe's `E_dist`
//! measured on the input points, taken as a maximum instead of a sum). It bounds distances from
//! input vertices, not from points inside input triangles; for marching-cubes input, whose
//! triangles are smaller than a voxel, the difference is a fraction of a voxel.
//!
//! # Papers
//!
//! - M. Garland, P. S. Heckbert, "Surface Simplification Using Quadric Error Metrics",
//!   SIGGRAPH 1997 (ranking, placement, boundary constraint planes).
//! - H. Hoppe, "Progressive Meshes", SIGGRAPH 1996, and H. Hoppe, T. DeRose, T. Duchamp,
//!   J. McDonald, W. Stuetzle, "Mesh Optimization", SIGGRAPH 1993 (distance energy over the input
//!   points with reassignment of points to faces, spring energy).
//! - T. K. Dey, H. Edelsbrunner, S. Guha, D. V. Nekhayev, "Topology Preserving Edge Contraction",
//!   Publ. Inst. Math. (Beograd) 66, 1999 (link condition).
//! - After simplification, [`fit_to_samples`] moves the few remaining vertices onto the raw
//!   data (Hoppe 1993's continuous step), which restores the sharp corners and flat faces that
//!   marching cubes rounded.
//! - C. Ericson, *Real-Time Collision Detection*, 2004, §5.1.5 (point-to-triangle distance).

mod edge_collapse;
mod fit_to_samples;
mod min_heap;
mod point_triangle;
mod quadric;
mod triangle_grid;

pub use edge_collapse::{simplify, simplify_near_held_points, simplify_near_points, HeldPoints};
pub use fit_to_samples::{
    fit_to_samples, rms_distance_m, FitConfig, FitReport, FitSamples, WeightedSample,
};

use glam::Vec3;

/// How far [`simplify`] may go.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimplifyConfig {
    /// Stop rule, metres: no input vertex may end farther than this from the output surface
    /// (see the crate docs for the exact definition). `0` keeps all geometry that is not exactly
    /// flat to rounding; `f32::INFINITY` simplifies as far as topology and geometry allow.
    pub max_residual_m: f32,
    /// Never go below this many faces in total. Independently of this, every closed connected
    /// component keeps at least 4 faces (a tetrahedron) and every open one at least 1.
    pub min_faces: usize,
}

impl Default for SimplifyConfig {
    fn default() -> Self {
        Self {
            max_residual_m: 0.01,
            min_faces: 4,
        }
    }
}

/// What [`simplify`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimplifyReport {
    /// Input triangles, including degenerate ones that were dropped.
    pub faces_in: usize,
    pub faces_out: usize,
    pub vertices_out: usize,
    /// Edge collapses performed.
    pub collapses: usize,
    /// Refusals (an edge refused again after its neighbourhood changed counts again) because a
    /// support point or the new vertex would end farther than `max_residual_m`.
    pub rejected_by_residual: usize,
    /// Refusals because the result would not be a 2-manifold of the same topology (link
    /// condition, boundary rules, minimum faces per component, duplicate faces).
    pub rejected_by_topology: usize,
    /// Refusals because a triangle would flip, fold, degenerate or become a needle.
    pub rejected_by_geometry: usize,
    /// Metres: the largest distance from a support point (input vertex, or extra point of
    /// [`simplify_near_points`]) to its assigned output face; never above the configured
    /// `max_residual_m`.
    pub max_residual_m: f32,
    /// Extra points of [`simplify_near_points`] left out because they were already farther
    /// than `max_residual_m` from the input mesh.
    pub points_beyond_bound: usize,
    /// What the run did to get there, for profiling.
    pub work: SimplifyWork,
}

/// Counts of the simplifier's unit steps in one run: where its time goes, independent of the
/// machine. Counting costs a few additions per collapse.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimplifyWork {
    /// Entries taken from the edge queue, including those of merged-away vertices and those
    /// ranked before a collapse moved an end (re-ranked, then queued again or evaluated).
    pub queue_pops: usize,
    /// Edges run through the collapse checks (topology, geometry, residual).
    pub evaluations: usize,
    /// Support points checked by the residual rule (each point on a face around an evaluated
    /// edge, until one fails).
    pub support_checks: usize,
    /// Of those, the points that needed a search over every face around the new vertex (their
    /// face was removed, or the surviving face moved away from them).
    pub support_searches: usize,
}

/// Why [`simplify`] refused its input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimplifyError {
    #[error(
        "triangle {triangle} uses vertex {index} but the mesh has only {vertex_count} vertices: \
         the mesh is corrupt, check the mesher or reader that produced it"
    )]
    IndexOutOfRange {
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error(
        "vertex {index} is not finite ({position}): drop NaN or infinite samples before meshing"
    )]
    NonFiniteVertex { index: usize, position: Vec3 },
    #[error("max_residual_m is {value}: it must be a distance in metres, zero or more")]
    InvalidMaxResidual { value: f32 },
    #[error(
        "the mesh has {triangles} triangles and {vertices} vertices, more than 32-bit indices \
         can address here: split it before simplifying"
    )]
    TooLarge { triangles: usize, vertices: usize },
}
