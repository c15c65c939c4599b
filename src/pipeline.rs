//! One point cloud to one small mesh: reconstruct (normals → signed distance → marching cubes),
//! then simplify until the maximum residual would pass its bound.
//!
//! Entry points: [`mesh_cloud`] for a cloud, [`mesh_fused_grid`] for the daemon's fused state.

use std::time::Instant;

use serde::Serialize;
use tacmesh_physics::orientation::{orient_outward, orientation};
use tacmesh_reconstruct::moment_grid::{MomentGrid, SortedVoxels};
use tacmesh_reconstruct::noise::estimate_noise_and_density;
#[cfg(doc)]
use tacmesh_reconstruct::noise::{estimate_noise_m, estimate_points_per_m2};
use tacmesh_reconstruct::surface::{
    mesh_moment_grid, reconstruct_surface, Orientation, ReconstructConfig, Reconstruction,
};
use tacmesh_simplify::{
    fit_to_samples, rms_distance_m, simplify, simplify_near_held_points, FitConfig, FitSamples,
    HeldPoints, SimplifyConfig, WeightedSample,
};
use tacmesh_source::{glam::Vec3, PointCloud, TriMesh};

/// A length given either in metres or as a fraction of the object's extent (the largest side
/// of the cloud's bounding box), so one default fits a mug and a table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Length {
    Metres(f32),
    OfExtent(f32),
}

impl Length {
    pub fn resolve_m(self, extent_m: f32) -> f32 {
        match self {
            Length::Metres(m) => m,
            Length::OfExtent(f) => f * extent_m,
        }
    }
}

/// Settings of the whole cloud-to-mesh pipeline. [`MeshConfig::default`] is what `tacmesh mesh`
/// uses and what `BENCHMARKS.md` measures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshConfig {
    /// Marching-cubes cell edge. Relative to the extent, it is the smallest the pipeline uses:
    /// with [`MeshConfig::adapt_to_data`] a noisy or sparse cloud gets a larger one.
    pub voxel_size: Length,
    /// The simplifier's stop rule: no input-mesh vertex may end farther than this from the
    /// output surface.
    pub max_residual: Length,
    /// Where the sensor was, when known (one-view scans); otherwise normals are oriented by
    /// propagation.
    pub viewpoint: Option<Vec3>,
    /// Fit the simplified mesh's vertices to the data afterwards (sharpens corners that
    /// marching cubes rounded); vertices move at most one residual bound.
    pub fit_to_data: bool,
    /// Grow a relative `voxel_size` with the noise estimated in the cloud (up to
    /// [`MAX_NOISE_VOXEL_GROWTH`] times) and with the points' spacing (up to
    /// [`MAX_DENSITY_VOXEL_GROWTH`] times): the smoothing scale follows the voxel, and one sized
    /// for 20 mm noise keeps 40 mm noise as bumps that cost hundreds of faces, while one finer
    /// than a sparse cloud's spacing leaves voxel boxes too empty for a plane and the surface
    /// in pieces. A voxel given in metres is used as given.
    pub adapt_to_data: bool,
    /// Marching-cubes cell edge in voxels (the signed distance is sampled on every this-many
    /// voxel corner); `None` picks, for a cloud with no viewpoint, [`MESH_STEP_VOXELS`] when the
    /// noise dominates ([`noise_dominates`]), else [`DENSE_MESH_STEP_VOXELS`] for a dense cloud
    /// ([`points_are_dense`], see [`MAX_DENSE_MESH_CELL_OF_EXTENT`]), else
    /// [`MESH_STEP_VOXELS`] while its cell stays within [`MAX_MESH_CELL_OF_EXTENT`] of the
    /// extent, else 1; and 1 for a one-view scan.
    pub mesh_step_voxels: Option<i32>,
    /// Measure the fitted mesh's distance to the data ([`MeshReport::fit_rms_after`]): one
    /// more nearest-triangle pass over the fit's samples, 2-3 % of a one-core run on the
    /// paper's shapes, that changes nothing in the mesh. Off by default; `tacmesh mesh --json`
    /// turns it on.
    pub measure_fit: bool,
}

impl Default for MeshConfig {
    fn default() -> Self {
        Self {
            voxel_size: Length::OfExtent(DEFAULT_VOXEL_OF_EXTENT),
            max_residual: Length::OfExtent(DEFAULT_RESIDUAL_OF_EXTENT),
            viewpoint: None,
            fit_to_data: true,
            adapt_to_data: true,
            mesh_step_voxels: None,
            measure_fit: false,
        }
    }
}

/// The voxel for noise of standard deviation σ (as [`estimate_noise_m`] finds it) is this many
/// σ, when that is more than the relative default. Measured on the six shapes at 40,000 points
/// (`cargo bench --bench table1`, BENCHMARKS.md): at 20 mm noise (estimated 16–19 mm) 1.4 σ
/// gives 23–27 mm voxels and fewer faces than the default 20 mm on every shape (cone 58 → 38,
/// monkey 172 → 126) at 0.9–1.2× the error, still 0.25–0.4× Table 1's, and 40 % less time;
/// 0.9 σ left the default in place there. At 10 mm and below the default stays. The larger of
/// this and the spacing's voxel is taken.
pub const NOISE_VOXEL_RATIO: f32 = 1.4;

/// The noise never grows the voxel beyond this multiple of the relative default (1/50 of the
/// extent): 1.4 keeps the voxel near the residual bound (1/40 of the extent). Measured at 30
/// and 40 mm noise, seeds 101–103, voxel at 1.3, 1.4 and 1.5 times the default: at 1.5 the
/// marching-cubes cube's edges round off by more than the bound and cost chamfers (30 mm
/// noise: 60–76 faces, 3.6–4.7 mm, against 36–38 faces and 1.7–2.6 mm at 1.4); at 1.3 the
/// noise is left as bumps (cone at 40 mm: 102–120 faces against 76–88). A voxel of 1/25 of the
/// object opens the torus's tube (its smoothing reaches across it).
pub const MAX_NOISE_VOXEL_GROWTH: f32 = 1.4;

/// The voxel for points spaced `s` apart on the surface (`s²` square metres per point, see
/// [`estimate_points_per_m2`]) is at least this many `s`. Measured on the six shapes at 5,000
/// to 20,000 points and 0 to 30 mm noise (1 m objects, `s` 17–37 mm at 5,000 points): the
/// cube needs 40–50 mm voxels to close at 5,000 points (the default 20 mm leaves it in
/// pieces with 381–476 faces), the cone and sphere about 30 mm, the monkey and torus close at
/// 20–25 mm; 1.2 left the cone open at 10,000 points and 10 mm, and growing the voxel with
/// noise and spacing together (in quadrature) opened the torus's tube.
pub const DENSITY_VOXEL_RATIO: f32 = 1.35;

/// The spacing never grows the voxel beyond this multiple of the relative default.
pub const MAX_DENSITY_VOXEL_GROWTH: f32 = 2.5;

/// Whether points `spacing_m` apart are dense enough that their spacing does not grow the
/// default voxel `base_voxel_m` (see [`DENSITY_VOXEL_RATIO`]).
pub fn points_are_dense(spacing_m: f32, base_voxel_m: f32) -> bool {
    DENSITY_VOXEL_RATIO * spacing_m <= base_voxel_m
}

/// Default voxel: 1/50 of the object's extent (2 cm for the paper's 1 m shapes).
pub const DEFAULT_VOXEL_OF_EXTENT: f32 = 0.02;

/// Marching cubes runs on every second voxel corner: the points are fused, their planes fitted
/// and smoothed at the voxel's scale, and only the mesh is coarser. The dense mesh has about a
/// quarter of the faces (the cube at 20 mm: 19,100 -> 5,064; the paper's own are 2,952-4,832)
/// and so does the simplifier's work. Measured on the six shapes at 0-40 mm noise, 40,000
/// points, seeds 101-103, one thread: 1.5-2.8x faster from cloud to mesh (cube at 20 mm 96 ->
/// 56 ms), faces the same or fewer (cone at 40 mm 54 -> 32), every shape closed, MHE within
/// 0.85-1.2x except Suzanne's at 20-30 mm (8.1 -> 10.5 mm, 1.2-1.3x, its thin ears smoothed
/// more by the wider kernel). A marching-cubes voxel of the same size without the fine planes
/// opened the torus (0.03 of the extent at 20 mm noise).
pub const MESH_STEP_VOXELS: i32 = 2;

/// A dense closed cloud whose noise does not dominate ([`noise_dominates`]) goes one step
/// further, to every third voxel corner: about half the faces of every second corner (the cube
/// at 20 mm noise and 50,000 points: 5,396 -> 2,060), so the simplifier's first pass takes
/// about half the time. Measured on the six shapes at 0-40 mm noise and 5,000-100,000 points,
/// seeds 101-103 (`cargo bench --bench table1`, the sweep): it applies from 10,000-20,000
/// points at 0-20 mm, and every such cell is still one closed piece with Table 1's faces and
/// error, at 0.8-1.35x the error of every second corner (cone at 0 mm from 20,000 points 1.87
/// -> 2.52 mm at 24 faces; cone at 20 mm from 40,000 points 2.87 -> 2.61 mm, cube at 50,000
/// points 0.78 -> 0.70 mm) and within eight faces of it (cone at 20 mm from 20,000 points 24
/// -> 32, torus at 0 mm from 100,000 points 88 -> 80). One core, 50,000 points at 20 mm: cone 31 ->
/// 27 ms, cube 43 -> 33, cylinder 42 -> 32, sphere 39 -> 31. Suzanne's ears (at 0-10 mm) come
/// out cut off and the torus's tube (at 20 mm) open on every third corner; reconstruction
/// makes those again on every second corner (see [`tacmesh_reconstruct::mesh_moment_grid`]),
/// for about 1 ms. A noisy cloud stays on every second corner: on every third, the torus at 40
/// mm from 5,000 points had 184 faces.
pub const DENSE_MESH_STEP_VOXELS: i32 = 3;

/// The coarser marching cubes is for closed objects (no viewpoint), where an open result is
/// caught and meshed again; a one-view scan is open anyway, and on PCL's stereo mug scene the
/// coarser mesh turned 76 % of its area to face the camera instead of 85 % or more.
///
/// It runs only while its cell stays within this share of the extent: a sparse cloud's voxel
/// is already grown (up to [`MAX_DENSITY_VOXEL_GROWTH`] times the default), and doubling that
/// cost faces and error at 5,000 points (seeds 101-103: cube at 20 mm 28 -> 36 faces and 3.9
/// -> 4.2 mm, cone at 0 mm 34 -> 50 faces). The noise alone (at most
/// [`MAX_NOISE_VOXEL_GROWTH`] times the default) stays within it. A noisy cloud is the
/// exception: see [`noise_dominates`].
pub const MAX_MESH_CELL_OF_EXTENT: f32 = 0.06;

/// Every third corner ([`DENSE_MESH_STEP_VOXELS`]) runs only while its cell stays within this
/// share of the extent, the noise does not dominate and the points' spacing did not grow the
/// voxel: a thin part drawn by few points (Suzanne's ears from 5,000 points at 0-10 mm) came
/// out closed and in one piece with the tip of an ear shaved off (Hausdorff 0.15 m, MHE 7.6-8.5
/// -> 10.1-11.1 mm), which no check of the mesh catches. The noise alone (at most
/// [`MAX_NOISE_VOXEL_GROWTH`] times the default, 2.8 % of the extent) stays within it; at 8 %
/// the cone at 20 mm noise (voxel 2.4-2.7 % of its extent) fell on either side from seed to
/// seed, and 10 % to 20 % gave the same sweep.
pub const MAX_DENSE_MESH_CELL_OF_EXTENT: f32 = 0.1;

/// Whether a cloud's noise (σ, as [`estimate_noise_m`] finds it) reaches the default voxel
/// `base_voxel_m`: the noise has then grown the voxel to its cap
/// ([`NOISE_VOXEL_RATIO`] and [`MAX_NOISE_VOXEL_GROWTH`] are both 1.4) and the surface the
/// points give is no sharper than the coarser marching-cubes cell, so the coarser mesh is used
/// however sparse the cloud ([`MAX_MESH_CELL_OF_EXTENT`] does not apply). Measured on the six
/// shapes at 0-40 mm noise and 5,000-20,000 points, seeds 101-103, each meshed with
/// [`MeshConfig::mesh_step_voxels`] forced to 2 and left to the rules: at 40 mm noise (σ
/// estimated 26-34 mm on 1 m shapes) every corner left the noise as bumps (cone at 5,000
/// points 106-172 faces and 10.2-11.3 mm, cube at 10,000 68-100 faces) where every second
/// corner gave 62-70 faces and 9.1-10.1 mm, and 46-58; at 30 mm (σ 21-24 mm) fewer faces
/// too (cone at 5,000 points 52-70 -> 40-50), MHE within 0.8-1.2x. At 20 mm (σ 16-17.5 mm,
/// under the cone's 18 mm and the cube's 22 mm default voxels) and below it cost faces and
/// error (cube at 5,000 points and 10 mm: 38-44 -> 44 faces, 3.6-4.2 -> 7.6-8.1 mm), and the
/// rule leaves every one of those clouds as it was. Monkey and torus were not changed: the
/// monkey's coarser mesh at 40 mm and 5,000 points comes out open and is made again.
pub fn noise_dominates(noise_m: f32, base_voxel_m: f32) -> bool {
    noise_m >= base_voxel_m
}

/// When a closed object's mesh comes out open or in pieces, it is made again on the other
/// marching-cubes step and then, when the noise or the spacing had grown the voxel, with the
/// voxel this many times larger (on every second corner), in this order; the first mesh that
/// is one closed piece is kept, and when none is the first mesh stays. Measured at 40 mm
/// noise from 5,000 points, seeds 101-103: Suzanne's ears (open at 24 mm on seed 102: 523
/// faces) close at 1.4x (90 faces) but not at 1.2x, the torus (open at 27 mm on seed 103)
/// closes at 1.2x (76 faces, 11.3 mm for 13.1) while at 1.3x its 20 cm tube opens on every
/// seed. Clouds that come out closed are never remeshed; an open scan with no viewpoint pays
/// for up to three tries more.
pub const LARGER_VOXEL_RETRIES: [f32; 2] = [1.2, 1.4];

/// When the noise's tails stand out ([`noise_tails_stand_out`]), the fit leaves out the
/// coarse voxels that hold fewer points than this fraction of the mean over their occupied
/// neighbours (`SortedVoxels::thin_voxels`): voxels beside the surface that hold only a tail
/// of the noise. Their centroids lie outside a convex edge or rim, and where they were all the
/// data a small face had, the fit pulled its vertex out after them, a little more on every
/// refit: a spike 144 mm below the cone's base at 30 mm noise from 5,000 points, where the
/// nearest point was 69 mm below it.
///
/// Measured on the six shapes at 30 and 40 mm noise and 5,000-40,000 points, seeds 101-103
/// (48 cases), against keeping every voxel, in geometric mean over the cases: MHE, and the
/// farthest point of the mesh from the true surface. With the tails dropped wherever the
/// noise dominated: 0.5 gave 0.96x and 0.98x, 0.7 0.95x and 0.88x, 0.85 0.98x and 0.92x;
/// faces 0.97-0.98x. With the gate of [`MIN_TAIL_NOISE_OF_VOXEL`], 0.7 gives 0.95x and 0.89x,
/// the cube at 40 mm from 10,000 points 6.12 -> 4.42 mm, the cylinder 7.82 -> 7.39 and the
/// cone 9.50 -> 8.85 (Table 1: 4.88, 7.48, 8.87).
pub const NOISE_TAIL_FRACTION: f64 = 0.7;

/// The noise's tails stand out of the fit's samples only when the noise is at least this
/// fraction of the voxel (the samples are voxels twice as wide). Where the spacing grew the
/// voxel well past the noise, a thin voxel is as often one that clips an edge: with the
/// tails dropped whenever the noise dominated, the cube at 40 mm from 5,000 points (noise
/// found 26 mm, voxel 52 mm) went 6.2-7.7 -> 7.7-9.1 mm on seeds 41-42, and the cylinder and
/// sphere at 30 mm from 5,000 points lost 2-5 %. 0.6 keeps those as they were and stays clear
/// of 1/1.4, the ratio of a voxel that follows the noise ([`NOISE_VOXEL_RATIO`]); 0.7 gave the
/// same MHE in geometric mean over the 48 cases above (0.95x).
pub const MIN_TAIL_NOISE_OF_VOXEL: f32 = 0.6;

/// Whether the fit drops the noise's tails ([`NOISE_TAIL_FRACTION`]): the noise dominates the
/// default voxel (`base_voxel_m`, see [`noise_dominates`]) and is at least
/// [`MIN_TAIL_NOISE_OF_VOXEL`] of the voxel used (`voxel_m`). With little noise a thin voxel is
/// one that clips an edge or a corner, the fit's best data for it: dropping them (below 0.5 of
/// the mean) at 0-20 mm cost the cube from 5,000 points with no noise 0.27 -> 0.55 mm, and
/// 0-20 mm lost 7 % of MHE in geometric mean over 90 cases. So at 20 mm only the smaller torus and
/// Suzanne (whose default voxel is smaller than the noise) drop any; the real scans of the
/// tests, with noise of 1-5 mm, never do.
pub fn noise_tails_stand_out(noise_m: f32, base_voxel_m: f32, voxel_m: f32) -> bool {
    noise_dominates(noise_m, base_voxel_m) && noise_m >= MIN_TAIL_NOISE_OF_VOXEL * voxel_m
}

/// Default residual bound: 2.5 % of the object's extent (25 mm for a 1 m object).
pub const DEFAULT_RESIDUAL_OF_EXTENT: f32 = 0.025;

/// Passes of simplification over the fitted mesh, each followed by a fit, at most (they stop
/// early once a pass removes nothing). Measured on the paper's shapes, seeds 101-103: three
/// against one (with three-iteration refits then), fewer faces or as many everywhere (the cube
/// at 20,000 points 20 -> 14, the cone 34 -> 26 and the cylinder at 5,000 points 66 -> 48, both
/// at 20 mm), the MHE within 0.9-1.1x
/// at 20-30 mm (at 40 mm see [`MAX_UNHELD_PER_VERTEX`]); each pass costs 2-4 ms on a 1 m
/// object, and its fit one iteration ([`REFIT_ITERATIONS`]).
pub const REFINE_PASSES: usize = 3;

/// Iterations of the fit after each pass (the first fit has 3): the vertices a pass leaves are
/// already fitted. Measured on the paper's shapes (30 cases of shape, noise and points, seeds
/// 101-103): the same faces within 4 and MHE within 0.9-1.1x of three iterations, the fits
/// 23-33 % faster on one thread.
pub const REFIT_ITERATIONS: usize = 1;

/// Another pass after the fit runs only while the last one held all but one in this many of
/// the marching-cubes vertices. At 40 mm noise the fits carry the surface beyond the bound of
/// 2-8 % of them (a 20 mm cloud: 0-0.15 %), and further passes, held to fewer, drifted: the
/// torus from 10,000 points 11.7 -> 14.4 mm, the cone from 20,000 7.2 -> 9.3 mm, both past
/// Table 1's error.
pub const MAX_UNHELD_PER_VERTEX: usize = 100;

/// The residual bound per metre of target mean Hausdorff error in the error-target mode
/// (`tacmesh mesh --target-mhe-m`). Measured on the paper's six shapes at 20 mm noise and
/// 50,000 points: the MHE comes out at 0.20–0.27 of the bound on the curved shapes (sphere,
/// torus, monkey), 0.10–0.16 on the cone and cylinder and 0.02–0.06 on the cube. The torus is
/// the closest to its target: at 3.75 its median over seeds 1–5 came out 2 % over Table 1's
/// MHE once the second simplification pass removed more of its vertices; at 3.5 it is 13.8 mm
/// for 14.3 (3.4 gave 12.9 mm, but the sphere's 56 faces against the 58 that are ½ of Table
/// 1's).
pub const RESIDUAL_PER_TARGET_MHE: f32 = 3.5;

/// The residual bound, metres, that aims at a mean Hausdorff error of `target_mhe_m`: the
/// simplifier's guarantee is kept (no input vertex ends farther than the bound), and the mean
/// error it leaves is a fraction of the bound (see [`RESIDUAL_PER_TARGET_MHE`]). An aim, not a
/// guarantee: the mean error depends on the shape.
pub fn residual_for_target_mhe_m(target_mhe_m: f32) -> f32 {
    RESIDUAL_PER_TARGET_MHE * target_mhe_m
}

/// What the pipeline did, stage by stage; serialised as `tacmesh mesh --json`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct MeshReport {
    pub points: usize,
    pub extent_m: f32,
    pub voxel_size_m: f32,
    /// Marching-cubes cell edge used, in voxels (see [`MeshConfig::mesh_step_voxels`]; smaller
    /// than chosen when the coarser mesh of a closed object came out open or cut in pieces and
    /// was made again on finer corners).
    pub mesh_step_voxels: i32,
    /// The noise estimated across the surface (standard deviation, metres; see
    /// [`estimate_noise_m`]), 0 when there were too few points to tell.
    pub noise_m: f32,
    /// How far apart the points are on the surface, metres: one over the square root of the
    /// points per square metre (see [`estimate_points_per_m2`]), 0 when it could not be told.
    pub spacing_m: f32,
    pub max_residual_bound_m: f32,
    pub recon_faces: usize,
    /// Faces after the first simplification, before the fit and the passes after it (see
    /// `simplify_and_fit`).
    pub first_pass_faces: usize,
    pub faces: usize,
    pub vertices: usize,
    /// The residual the simplified mesh actually reached (≤ the bound), metres: the largest
    /// distance from a marching-cubes vertex to it, before the last fit; with the fit on,
    /// over the vertices the last pass held.
    pub max_residual: f32,
    /// Marching-cubes vertices already farther than the bound from the fitted mesh, which the
    /// last pass could not hold to it (0 with the fit off).
    pub vertices_beyond_bound: usize,
    /// The cloud's extent, noise and density, estimated to choose the voxel before integration
    /// (0 for a fused grid, whose voxel is fixed).
    pub estimate_ms: f64,
    pub integrate_ms: f64,
    pub normals_ms: f64,
    pub orient_ms: f64,
    pub distance_ms: f64,
    pub marching_cubes_ms: f64,
    /// Every simplification pass, and of it the passes after the fit (0 with the fit off).
    pub simplify_ms: f64,
    pub refine_ms: f64,
    /// Weighted RMS distance of the data (voxel centroids) to the mesh before and after the
    /// fit, and the largest vertex move it made, metres (zeros when the fit is off).
    pub fit_rms_before: f32,
    /// 0 unless [`MeshConfig::measure_fit`].
    pub fit_rms_after: f32,
    pub fit_max_move: f32,
    /// Voxel centroids the fit left out as tails of the noise ([`NOISE_TAIL_FRACTION`]; 0
    /// unless [`noise_tails_stand_out`]), of all the voxels it had.
    pub fit_tail_voxels: usize,
    pub fit_voxels: usize,
    pub fit_ms: f64,
    /// Connected pieces of the output, those with a boundary (open shells or holes), and
    /// those the orientation check turned outward (see [`orient_outward`]).
    pub pieces: usize,
    pub open_pieces: usize,
    pub pieces_flipped: usize,
    /// Whether the output is closed and consistently wound, and the volume it encloses, m³
    /// (positive: closed outputs always face out); an open output encloses none (`None`: its
    /// signed volume would depend on where the opening is, and could be negative).
    pub closed: bool,
    /// Meshes made again because a closed object's came out open or in pieces (on the other
    /// marching-cubes step or a larger voxel, [`LARGER_VOXEL_RETRIES`]); 0 when the first
    /// was one closed piece or there was a viewpoint. `voxel_size_m` and `mesh_step_voxels`
    /// are the kept mesh's.
    pub closing_retries: usize,
    pub volume_m3: Option<f64>,
    pub total_ms: f64,
}

/// Why a cloud could not be meshed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("the cloud has no finite points to mesh")]
    EmptyCloud,
    #[error(
        "all {points} points coincide, at {}: there is no surface to mesh; is the file one \
         repeated point?",
        at.to_array().map(|c| c.to_string()).join(",")
    )]
    PointsCoincide { points: usize, at: Vec3 },
    #[error(
        "voxel size {voxel_size_m} m is finer than the points are spaced ({} m from a point to \
         its nearest neighbour, median), so too few voxel neighbourhoods hold the points a \
         tangent plane needs; use a voxel of at least {} m, or the default (1/50 of the \
         cloud's extent)",
        metres_up(*spacing_m),
        metres_up(*spacing_m)
    )]
    VoxelFinerThanSpacing { voxel_size_m: f32, spacing_m: f32 },
    #[error(transparent)]
    Reconstruct(#[from] tacmesh_reconstruct::ReconstructError),
    #[error(transparent)]
    Simplify(#[from] tacmesh_simplify::SimplifyError),
}

/// Points [`robust_extent_m`] reads at most: its percentiles are as good from a sample, and
/// selecting them from every point of a 40,000-point cloud took 0.5 ms, 2 % of meshing it on
/// one core.
pub const EXTENT_SAMPLES: usize = 16_384;

/// The object's size for relative lengths: the largest side of the box between the 2nd and
/// 98th percentile of the points on each axis, so that a few noisy outliers do not inflate it
/// (with the paper's 20 mm noise the full bounding box of a 1 m cube is ~1.15 m). Non-finite
/// points are ignored; `None` when there is no finite point. The percentiles come from at most
/// [`EXTENT_SAMPLES`] of the finite points, taken evenly through the cloud.
pub fn robust_extent_m(points: &[Vec3]) -> Option<f32> {
    let finite_count = points.iter().filter(|p| p.is_finite()).count();
    if finite_count == 0 {
        return None;
    }
    let stride = finite_count.div_ceil(EXTENT_SAMPLES).max(1);
    let finite = || points.iter().filter(|p| p.is_finite()).step_by(stride);
    let mut extent = 0.0f32;
    let mut values = Vec::with_capacity(finite_count.div_ceil(stride));
    for axis in 0..3 {
        values.clear();
        values.extend(finite().map(|p| p[axis]));
        let last = values.len() - 1;
        let lo_rank = last * 2 / 100;
        let hi_rank = last - lo_rank;
        let (_, &mut lo, above) = values.select_nth_unstable_by(lo_rank, f32::total_cmp);
        // Everything above the low rank is no smaller: the high rank is found among those.
        let hi = match hi_rank.checked_sub(lo_rank + 1) {
            Some(rank) => *above.select_nth_unstable_by(rank, f32::total_cmp).1,
            None => lo,
        };
        extent = extent.max(hi - lo);
    }
    Some(extent)
}

/// Fewer points than this are "too few" whatever the voxel: no spacing estimate for them.
const MIN_POINTS_FOR_SPACING: usize = 64;

/// The median distance from a point to its nearest neighbour, metres, over up to 2,000 points
/// spread through the cloud: how finely the data samples its surface. Neighbours are looked for
/// in the segmentation's voxel hash grid with cells `extent_m / 50` wide (the default voxel),
/// four times wider while most points find none there. `None` with fewer than two finite
/// points.
pub fn median_point_spacing_m(points: &[Vec3], extent_m: f32) -> Option<f32> {
    let finite: Vec<u32> = (0..points.len() as u32)
        .filter(|&i| points[i as usize].is_finite())
        .collect();
    if finite.len() < 2 || !(extent_m.is_finite() && extent_m > 0.0) {
        return None;
    }
    let stride = finite.len().div_ceil(2000);
    let mut cell_m = extent_m / 50.0;
    while cell_m <= 2.0 * extent_m {
        let grid = tacmesh_segment::grid::VoxelGrid::new(points, &finite, cell_m);
        let mut nearest: Vec<f32> = Vec::new();
        let mut sampled = 0;
        for &i in finite.iter().step_by(stride) {
            sampled += 1;
            let p = points[i as usize];
            let mut best = f32::INFINITY;
            grid.for_each_near(p, |j| {
                if j != i {
                    best = best.min(p.distance(points[j as usize]));
                }
            });
            // Farther than one cell, a neighbour in the 27 cells may not be the nearest.
            if best <= cell_m {
                nearest.push(best);
            }
        }
        if 2 * nearest.len() > sampled {
            let middle = nearest.len() / 2;
            return Some(*nearest.select_nth_unstable_by(middle, f32::total_cmp).1);
        }
        cell_m *= 4.0;
    }
    None
}

/// A length in metres to two significant digits, rounded up (it is shown as a bound to meet),
/// without trailing zeros.
fn metres_up(m: f32) -> String {
    if !(m.is_finite() && m > 0.0) {
        return m.to_string();
    }
    let exponent = m.log10().floor() as i32 - 1;
    let step = 10f64.powi(exponent);
    let rounded = (f64::from(m) / step).ceil() * step;
    let text = format!("{rounded:.*}", (-exponent).max(0) as usize);
    match text.contains('.') {
        true => text.trim_end_matches('0').trim_end_matches('.').to_owned(),
        false => text,
    }
}

/// Reconstruction reports a voxel finer than the data's spacing as too few points per
/// neighbourhood; when that is the cause, say so and how large a voxel would do.
fn explain(
    err: tacmesh_reconstruct::ReconstructError,
    points: &[Vec3],
    extent_m: f32,
    voxel_size_m: f32,
) -> PipelineError {
    use tacmesh_reconstruct::ReconstructError;
    if matches!(err, ReconstructError::TooFewPoints { .. })
        && points.len() >= MIN_POINTS_FOR_SPACING
    {
        // A plane needs 8 points in the box 4 voxels wide around its voxel. On the paper's
        // torus (20,000 points, 1 m) reconstruction fails below half the neighbour distance
        // with or without noise; a voxel as large as that distance works on both.
        if let Some(spacing_m) = median_point_spacing_m(points, extent_m) {
            if voxel_size_m < spacing_m {
                return PipelineError::VoxelFinerThanSpacing {
                    voxel_size_m,
                    spacing_m,
                };
            }
        }
    }
    err.into()
}

/// Meshes one cloud with `config`; returns the simplified mesh and a report.
pub fn mesh_cloud(
    cloud: &PointCloud,
    config: &MeshConfig,
) -> Result<(TriMesh, MeshReport), PipelineError> {
    mesh_cloud_with_dense(cloud, config).map(|(_dense, mesh, report)| (mesh, report))
}

/// As [`mesh_cloud`], also returning the dense marching-cubes mesh before simplification
/// (benchmarks compare simplifiers on it).
pub fn mesh_cloud_with_dense(
    cloud: &PointCloud,
    config: &MeshConfig,
) -> Result<(TriMesh, TriMesh, MeshReport), PipelineError> {
    let start = Instant::now();
    let finite = || cloud.points.iter().copied().filter(|p| p.is_finite());
    let first = finite().next().ok_or(PipelineError::EmptyCloud)?;
    let (lo, hi) = finite().fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
    if lo == hi {
        return Err(PipelineError::PointsCoincide {
            points: finite().count(),
            at: lo,
        });
    }
    // When 96 % of the points coincide and a few outliers do not, they are all the extent.
    let extent_m = robust_extent_m(&cloud.points)
        .filter(|&e| e > 0.0)
        .unwrap_or((hi - lo).max_element());
    let base_voxel_m = config.voxel_size.resolve_m(extent_m);
    // The density over cells that hold the noise's spread: 2 × voxel, or twice the noise.
    let estimates = estimate_noise_and_density(&cloud.points, 2.0 * base_voxel_m);
    let noise_m = estimates.noise_m.unwrap_or(0.0);
    let spacing_m = estimates
        .points_per_m2
        .map_or(0.0, |density| density.recip().sqrt());
    let voxel_size_m = match config.voxel_size {
        Length::OfExtent(_) if config.adapt_to_data => {
            let for_noise =
                (NOISE_VOXEL_RATIO * noise_m).min(MAX_NOISE_VOXEL_GROWTH * base_voxel_m);
            let for_density =
                (DENSITY_VOXEL_RATIO * spacing_m).min(MAX_DENSITY_VOXEL_GROWTH * base_voxel_m);
            base_voxel_m.max(for_noise).max(for_density)
        }
        _ => base_voxel_m,
    };
    let estimate_ms = start.elapsed().as_secs_f64() * 1e3;
    let max_residual_m = config.max_residual.resolve_m(extent_m);
    let cell_fits =
        |step: i32, max_of_extent: f32| step as f32 * voxel_size_m <= max_of_extent * extent_m;
    let mesh_step_voxels = config
        .mesh_step_voxels
        .unwrap_or(if config.viewpoint.is_some() {
            1
        } else if noise_dominates(noise_m, base_voxel_m) {
            MESH_STEP_VOXELS
        } else if points_are_dense(spacing_m, base_voxel_m)
            && cell_fits(DENSE_MESH_STEP_VOXELS, MAX_DENSE_MESH_CELL_OF_EXTENT)
        {
            DENSE_MESH_STEP_VOXELS
        } else if cell_fits(MESH_STEP_VOXELS, MAX_MESH_CELL_OF_EXTENT) {
            MESH_STEP_VOXELS
        } else {
            1
        });

    let attempt = |voxel_size_m: f32, mesh_step_voxels: i32| {
        let recon_config = ReconstructConfig {
            orientation: match config.viewpoint {
                Some(v) => Orientation::TowardsViewpoint(v),
                None => Orientation::Propagate,
            },
            ..ReconstructConfig::with_voxel_size(voxel_size_m)
        }
        .with_mesh_step(mesh_step_voxels);
        // Reconstruction skips non-finite points itself (and counts the rest).
        let Reconstruction {
            mesh: mut dense,
            coarse_grid,
            report: recon,
        } = reconstruct_surface(cloud, &recon_config)
            .map_err(|err| explain(err, &cloud.points, extent_m, voxel_size_m))?;
        orient_outward(&mut dense, config.viewpoint);
        let (mesh, mut report) = simplify_and_fit(
            &dense,
            &coarse_grid,
            max_residual_m,
            FitStep {
                fit_to_data: config.fit_to_data,
                measure: config.measure_fit,
                drop_noise_tails: noise_tails_stand_out(noise_m, base_voxel_m, voxel_size_m),
            },
            config.viewpoint,
        )?;
        report.points = recon.points;
        report.extent_m = extent_m;
        report.voxel_size_m = voxel_size_m;
        report.noise_m = noise_m;
        report.spacing_m = spacing_m;
        report.estimate_ms = estimate_ms;
        report.integrate_ms = recon.integrate_ms;
        report.take_meshing_figures(&recon);
        Ok::<_, PipelineError>((dense, mesh, report))
    };
    let mut meshed = attempt(voxel_size_m, mesh_step_voxels)?;

    // A closed object (no viewpoint) whose mesh came out open or in pieces, on a grid the
    // pipeline chose: try the nearby grids and keep the first that gives one closed piece
    // (see [`LARGER_VOXEL_RETRIES`]).
    let whole = |report: &MeshReport| report.closed && report.pieces == 1;
    if !whole(&meshed.2) && config.viewpoint.is_none() && config.mesh_step_voxels.is_none() {
        let mut retries = Vec::new();
        match (mesh_step_voxels, meshed.2.mesh_step_voxels) {
            (1, _) => retries.push((voxel_size_m, MESH_STEP_VOXELS)),
            // Reconstruction already made it again on every corner when it came out open.
            (_, 1) => {}
            _ => retries.push((voxel_size_m, 1)),
        }
        if config.adapt_to_data && voxel_size_m > base_voxel_m {
            retries.extend(
                LARGER_VOXEL_RETRIES.map(|growth| (growth * voxel_size_m, MESH_STEP_VOXELS)),
            );
        }
        for (voxel_m, step) in retries {
            meshed.2.closing_retries += 1;
            match attempt(voxel_m, step) {
                Ok(retry) if whole(&retry.2) => {
                    tracing::debug!(
                        voxel_m,
                        step = retry.2.mesh_step_voxels,
                        "a closed object's mesh, open or in pieces, came out whole on another grid"
                    );
                    let closing_retries = meshed.2.closing_retries;
                    meshed = retry;
                    meshed.2.closing_retries = closing_retries;
                    break;
                }
                Ok(_) => {}
                Err(err) => tracing::debug!(voxel_m, step, %err, "retry on another grid failed"),
            }
        }
    }
    meshed.2.total_ms = start.elapsed().as_secs_f64() * 1e3;
    tracing::debug!(report = ?meshed.2, "meshed cloud");
    Ok(meshed)
}

impl MeshReport {
    /// The step, face count and stage times of reconstruction from the moment grid on (both
    /// [`mesh_cloud`] and [`mesh_fused_grid`] report them; integration is the cloud's alone).
    fn take_meshing_figures(&mut self, recon: &tacmesh_reconstruct::surface::ReconstructReport) {
        self.mesh_step_voxels = recon.mesh_step_voxels;
        self.recon_faces = recon.faces;
        self.normals_ms = recon.normals_ms;
        self.orient_ms = recon.orient_ms;
        self.distance_ms = recon.distance_ms;
        self.marching_cubes_ms = recon.marching_cubes_ms;
    }
}

/// Meshes an already fused moment grid (the daemon's per-object state) in its own frame: the
/// same stages as [`mesh_cloud`] after integration. `viewpoint` is the sensor position in the
/// grid's frame, when all the data came from one side; `None` orients by propagation.
/// Marching cubes runs on every `mesh_step_voxels`-th voxel corner (1: every one).
pub fn mesh_fused_grid(
    grid: &MomentGrid,
    viewpoint: Option<Vec3>,
    max_residual_m: f32,
    fit_to_data: bool,
    mesh_step_voxels: i32,
) -> Result<(TriMesh, MeshReport), PipelineError> {
    let start = Instant::now();
    let recon_config = ReconstructConfig {
        orientation: match viewpoint {
            Some(v) => Orientation::TowardsViewpoint(v),
            None => Orientation::Propagate,
        },
        ..ReconstructConfig::with_voxel_size(grid.voxel_size_m())
    }
    .with_mesh_step(mesh_step_voxels);
    let Reconstruction {
        mesh: dense,
        coarse_grid,
        report: recon,
    } = mesh_moment_grid(grid, &recon_config)?;
    // Nothing reads the fit's distance to the data live: it is not measured. The fused grid
    // carries no noise estimate, so its samples are all kept.
    let fit_step = FitStep {
        fit_to_data,
        measure: false,
        drop_noise_tails: false,
    };
    let (mesh, mut report) =
        simplify_and_fit(&dense, &coarse_grid, max_residual_m, fit_step, viewpoint)?;
    report.points = grid.iter().map(|(_, m)| m.count as usize).sum();
    report.voxel_size_m = grid.voxel_size_m();
    report.take_meshing_figures(&recon);
    report.total_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok((mesh, report))
}

/// Whether [`simplify_and_fit`] fits the simplified mesh to the data, and whether it measures
/// the result's distance to them ([`MeshConfig::measure_fit`]).
#[derive(Debug, Clone, Copy)]
struct FitStep {
    fit_to_data: bool,
    measure: bool,
    /// Leave the thin voxels out of the fit's samples ([`NOISE_TAIL_FRACTION`]).
    drop_noise_tails: bool,
}

/// Simplifies the marching-cubes mesh `dense` under `max_residual_m`, then (optionally) fits
/// the result to the voxel centroids of `coarse_grid` (the fused points in voxels twice the
/// reconstruction's), simplifies the fitted mesh again under the same
/// bound on the same marching-cubes vertices and fits once more (up to [`REFINE_PASSES`]
/// times, while a pass removes faces), and last makes every piece face
/// out (closed pieces by their volume, open ones towards `viewpoint` when known). Fills the
/// simplify, fit and orientation fields of the report.
fn simplify_and_fit(
    dense: &TriMesh,
    coarse_grid: &SortedVoxels,
    max_residual_m: f32,
    FitStep {
        fit_to_data,
        measure: measure_fit,
        drop_noise_tails,
    }: FitStep,
    viewpoint: Option<Vec3>,
) -> Result<(TriMesh, MeshReport), PipelineError> {
    let simplify_config = SimplifyConfig {
        max_residual_m,
        ..SimplifyConfig::default()
    };
    let simplify_start = Instant::now();
    let (mut mesh, simplified) = simplify(dense, &simplify_config)?;
    let first_pass_ms = simplify_start.elapsed().as_secs_f64() * 1e3;
    let mut simplify_ms = first_pass_ms;

    let fit_start = Instant::now();
    let mut last_pass = None;
    let mut refine_ms = 0.0;
    let mut fit_tail_voxels = 0;
    let fit = if fit_to_data {
        // Centroids of voxels twice the reconstruction's: a quarter of the samples, each the
        // mean of several points, and still far finer than the simplified triangles.
        let tails = drop_noise_tails.then(|| coarse_grid.thin_voxels(NOISE_TAIL_FRACTION));
        fit_tail_voxels = tails
            .as_ref()
            .map_or(0, |thin| thin.iter().filter(|&&t| t).count());
        let samples: Vec<WeightedSample> = coarse_grid
            .moments
            .iter()
            .enumerate()
            .filter(|&(i, _)| !tails.as_ref().is_some_and(|thin| thin[i]))
            .filter_map(|(_, m)| {
                Some(WeightedSample {
                    point: m.centroid()?,
                    weight: m.count as f32,
                })
            })
            .collect();
        let data = FitSamples::new(&samples, 2.5 * max_residual_m);
        let fit_config = FitConfig {
            iterations: 3,
            max_move_m: max_residual_m,
            stiffness: 1e-3,
            // Measured once, on the final mesh, below.
            measure_after: false,
        };
        let mut fit = fit_to_samples(&mut mesh, &data, &fit_config);
        // The fit put back the corners and edges that marching cubes had rounded, so chamfer
        // vertices the first pass had to keep now lie on the sharp planes: a pass over the
        // small fitted mesh, held to the same marching-cubes vertices under the same bound,
        // removes them, and a fit places what is left; that fit can straighten more, so the
        // two repeat while a pass removes faces, at most `REFINE_PASSES` times (cube at 20 mm:
        // 28-34 faces after the first pass, 12-14 after one more; at 20,000 points 54-60,
        // 18-24 after one and 12-16 after three). A vertex the fit carried beyond the bound is
        // not held (there is no face it could be held to); the report counts them.
        let held = HeldPoints::new(&dense.vertices, max_residual_m);
        for _ in 0..REFINE_PASSES {
            let pass_start = Instant::now();
            let (merged, pass) = simplify_near_held_points(&mesh, &held, &simplify_config)?;
            last_pass = Some(pass);
            refine_ms += pass_start.elapsed().as_secs_f64() * 1e3;
            if merged.triangles.len() >= mesh.triangles.len() {
                break;
            }
            mesh = merged;
            let refit = fit_to_samples(
                &mut mesh,
                &data,
                &FitConfig {
                    iterations: REFIT_ITERATIONS,
                    ..fit_config
                },
            );
            fit.max_move_m = fit.max_move_m.max(refit.max_move_m);
            if pass.points_beyond_bound * MAX_UNHELD_PER_VERTEX > dense.vertices.len() {
                // The fits have carried the surface away from the marching-cubes vertices
                // (noisy clouds): another pass would be held to fewer of them and drift.
                break;
            }
        }
        simplify_ms += refine_ms;
        if measure_fit {
            fit.rms_after_m = rms_distance_m(&mesh, &data);
        }
        fit
    } else {
        Default::default()
    };
    let fit_ms = fit_start.elapsed().as_secs_f64() * 1e3 - (simplify_ms - first_pass_ms);

    // The guarantee a physics engine needs (a positive volume, or the seen side out), checked
    // on what is published rather than trusted to the reconstruction's normals.
    let turned = orient_outward(&mut mesh, viewpoint);
    let faced = orientation(&mesh);

    let report = MeshReport {
        pieces: turned.pieces,
        open_pieces: turned.open_pieces,
        pieces_flipped: turned.pieces_flipped,
        closed: faced.is_closed(),
        volume_m3: faced.is_closed().then_some(faced.signed_volume_m3),
        max_residual_bound_m: max_residual_m,
        first_pass_faces: simplified.faces_out,
        faces: mesh.triangles.len(),
        vertices: mesh.vertices.len(),
        max_residual: last_pass.map_or(simplified.max_residual_m, |last| last.max_residual_m),
        vertices_beyond_bound: last_pass.map_or(0, |last| last.points_beyond_bound),
        simplify_ms,
        refine_ms,
        fit_rms_before: fit.rms_before_m,
        fit_rms_after: fit.rms_after_m,
        fit_max_move: fit.max_move_m,
        fit_tail_voxels,
        fit_voxels: if fit_to_data {
            coarse_grid.moments.len()
        } else {
            0
        },
        fit_ms,
        ..MeshReport::default()
    };
    Ok((mesh, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_extent_ignores_a_far_outlier() {
        let mut points: Vec<Vec3> = (0..1000)
            .map(|i| Vec3::new(i as f32 / 999.0, 0.0, 0.0))
            .collect();
        points.push(Vec3::new(50.0, 0.0, 0.0));
        points.push(Vec3::NAN);
        let extent = robust_extent_m(&points).unwrap();
        assert!((0.9..1.0).contains(&extent), "{extent}");
    }

    /// A cloud larger than the extent's sample, with every other point missing as a depth
    /// image's holes can be: the sample is taken over the finite points, so it neither comes
    /// up empty nor loses the percentiles.
    #[test]
    fn robust_extent_of_a_large_cloud_with_holes_is_sampled_over_its_finite_points() {
        let n = 8 * EXTENT_SAMPLES;
        let points: Vec<Vec3> = (0..n)
            .map(|i| {
                if i % 2 == 0 {
                    Vec3::NAN
                } else {
                    // A 2 m line along x, visited in a scrambled order.
                    let t = (i * 7919 % n) as f32 / n as f32;
                    Vec3::new(2.0 * t, 0.1 * t, 0.0)
                }
            })
            .collect();
        let extent = robust_extent_m(&points).unwrap();
        // The 2nd to 98th percentile of a uniform 2 m spread is 1.92 m.
        assert!((extent - 1.92).abs() < 0.01, "{extent}");
        let all_missing = vec![Vec3::NAN; n];
        assert_eq!(robust_extent_m(&all_missing), None);
    }

    /// Marching cubes rounds the cube's edges; fitting the simplified vertices to the data
    /// puts its faces back where the points are.
    #[test]
    fn fit_to_data_brings_the_cube_closer() {
        let truth = tacmesh_sim::Shape::Cube.mesh();
        let cloud = tacmesh_sim::sample_cloud(
            &truth,
            &tacmesh_sim::SampleConfig {
                points: 30_000,
                noise_sigma_m: 0.02,
                seed: 3,
            },
        )
        .unwrap();
        let mhe = |fit_to_data| {
            let config = MeshConfig {
                fit_to_data,
                ..MeshConfig::default()
            };
            let (mesh, _) = mesh_cloud(&cloud, &config).unwrap();
            tacmesh_sim::mesh_distance(&truth, &mesh, 20_000, 1)
                .unwrap()
                .mhe_m
        };
        let (with_fit, without) = (mhe(true), mhe(false));
        assert!(with_fit < 0.7 * without, "fit {with_fit} vs none {without}");
    }

    /// Measuring the fit's distance to the data after it is a report figure only: the mesh
    /// is the same to the bit either way, and the figure is there only when asked for (and
    /// below the distance before, on a cube whose corners the fit puts back).
    #[test]
    fn measuring_the_fit_changes_nothing_but_the_report() {
        let cloud = sampled(tacmesh_sim::Shape::Cube, 20_000, 0.02, 5);
        let run = |measure_fit| {
            mesh_cloud(
                &cloud,
                &MeshConfig {
                    measure_fit,
                    ..MeshConfig::default()
                },
            )
            .unwrap()
        };
        let ((measured, with), (unmeasured, without)) = (run(true), run(false));
        assert_eq!(measured.vertices, unmeasured.vertices);
        assert_eq!(measured.triangles, unmeasured.triangles);
        assert_eq!(without.fit_rms_after, 0.0);
        assert!(
            with.fit_rms_after > 0.0 && with.fit_rms_after < with.fit_rms_before,
            "after {} before {}",
            with.fit_rms_after,
            with.fit_rms_before
        );
        assert_eq!(with.fit_rms_before, without.fit_rms_before);
    }

    fn sampled(shape: tacmesh_sim::Shape, points: usize, noise_m: f32, seed: u64) -> PointCloud {
        tacmesh_sim::sample_cloud(
            &shape.mesh(),
            &tacmesh_sim::SampleConfig {
                points,
                noise_sigma_m: noise_m,
                seed,
            },
        )
        .unwrap()
    }

    #[test]
    fn a_dense_closed_cloud_is_meshed_on_every_third_corner() {
        let shape = tacmesh_sim::Shape::Sphere;
        let cloud = sampled(shape, 40_000, 0.02, 7);
        let mesh_at = |mesh_step_voxels| {
            let config = MeshConfig {
                mesh_step_voxels,
                ..MeshConfig::default()
            };
            let (mesh, report) = mesh_cloud(&cloud, &config).unwrap();
            let mhe = tacmesh_sim::mesh_distance(&shape.mesh(), &mesh, 20_000, 1)
                .unwrap()
                .mhe_m;
            (report, mhe)
        };
        let (coarse, coarse_mhe) = mesh_at(None);
        let (fine, fine_mhe) = mesh_at(Some(1));
        assert_eq!(
            (coarse.mesh_step_voxels, fine.mesh_step_voxels),
            (DENSE_MESH_STEP_VOXELS, 1)
        );
        // About a ninth of the faces; the sphere at seed 7 has 1,924 against 17,000 or so.
        assert!(
            6 * coarse.recon_faces < fine.recon_faces,
            "{} vs {} marching-cubes faces",
            coarse.recon_faces,
            fine.recon_faces
        );
        for report in [&coarse, &fine] {
            assert!(report.closed && report.pieces == 1, "{report:?}");
        }
        assert!(coarse_mhe < 1.25 * fine_mhe, "{coarse_mhe} vs {fine_mhe}");
        // A one-view scan (a viewpoint) keeps every corner.
        let config = MeshConfig {
            viewpoint: Some(Vec3::new(0.0, 0.0, 3.0)),
            ..MeshConfig::default()
        };
        assert_eq!(mesh_cloud(&cloud, &config).unwrap().1.mesh_step_voxels, 1);
    }

    #[test]
    fn a_noisy_closed_cloud_is_meshed_on_every_second_corner() {
        let cloud = sampled(tacmesh_sim::Shape::Cube, 20_000, 0.04, 101);
        let (_, report) = mesh_cloud(&cloud, &MeshConfig::default()).unwrap();
        let base_voxel_m = DEFAULT_VOXEL_OF_EXTENT * report.extent_m;
        assert!(noise_dominates(report.noise_m, base_voxel_m), "{report:?}");
        assert_eq!(report.mesh_step_voxels, MESH_STEP_VOXELS, "{report:?}");
        assert!(report.closed && report.pieces == 1, "{report:?}");
    }

    #[test]
    fn a_thin_part_cut_off_on_every_third_corner_is_made_again_on_every_second() {
        // Suzanne at 10 mm from 40,000 points: every third corner is chosen and leaves an ear
        // as a piece of its own (on seeds 1-5); reconstruction makes her again on every second
        // corner, which keeps her in one.
        let cloud = sampled(tacmesh_sim::Shape::Monkey, 40_000, 0.01, 1);
        let (_, report) = mesh_cloud(&cloud, &MeshConfig::default()).unwrap();
        let base_voxel_m = DEFAULT_VOXEL_OF_EXTENT * report.extent_m;
        assert!(!noise_dominates(report.noise_m, base_voxel_m), "{report:?}");
        assert!(
            DENSE_MESH_STEP_VOXELS as f32 * report.voxel_size_m
                <= MAX_DENSE_MESH_CELL_OF_EXTENT * report.extent_m
                && points_are_dense(report.spacing_m, base_voxel_m),
            "every third corner was not chosen: {report:?}"
        );
        assert_eq!(report.mesh_step_voxels, MESH_STEP_VOXELS, "{report:?}");
        assert!(report.closed && report.pieces == 1, "{report:?}");
        assert_eq!(report.closing_retries, 0, "{report:?}");
    }

    #[test]
    fn a_coarse_mesh_that_comes_out_open_is_made_again_on_every_corner() {
        // Suzanne's ears at 40 mm noise from 5,000 points: every second corner (the noise
        // dominates) leaves holes there (on seeds 101-103), every corner closes them.
        let cloud = sampled(tacmesh_sim::Shape::Monkey, 5_000, 0.04, 101);
        let (_, report) = mesh_cloud(&cloud, &MeshConfig::default()).unwrap();
        let base_voxel_m = DEFAULT_VOXEL_OF_EXTENT * report.extent_m;
        assert!(
            noise_dominates(report.noise_m, base_voxel_m),
            "the coarser mesh was not tried: {report:?}"
        );
        assert_eq!(report.mesh_step_voxels, 1, "{report:?}");
        assert!(report.closed && report.pieces == 1, "{report:?}");
    }

    #[test]
    fn point_spacing_of_a_grid_is_its_pitch() {
        let points: Vec<Vec3> = (0..10_000)
            .map(|i| Vec3::new((i % 100) as f32 * 0.004, (i / 100) as f32 * 0.004, 0.0))
            .collect();
        let spacing = median_point_spacing_m(&points, 0.4).unwrap();
        assert!((spacing - 0.004).abs() < 1e-5, "{spacing}");
    }

    /// A sparse cloud's neighbours lie beyond the first cells searched; the search widens.
    #[test]
    fn point_spacing_of_a_sparse_cloud_is_found_in_wider_cells() {
        let points: Vec<Vec3> = (0..100)
            .map(|i| Vec3::new((i % 10) as f32 * 0.1, (i / 10) as f32 * 0.1, 0.0))
            .collect();
        let spacing = median_point_spacing_m(&points, 0.9).unwrap();
        assert!((spacing - 0.1).abs() < 1e-5, "{spacing}");
    }

    /// The gate of the fit's tail filter, on the clouds it was measured on (noise found, the
    /// default voxel, the voxel used; millimetres): the cube at 20 mm and at 40 mm from 5,000
    /// points keep every voxel, the cube at 40 mm from 10,000 points and the torus at 30 mm do
    /// not.
    #[test]
    fn the_noises_tails_stand_out_where_the_noise_dominates_a_voxel_it_sized() {
        let stands_out = |noise: f32, base: f32, voxel: f32| {
            noise_tails_stand_out(noise * 1e-3, base * 1e-3, voxel * 1e-3)
        };
        assert!(!stands_out(17.6, 21.0, 24.6), "cube, 20 mm, 40,000 points");
        assert!(!stands_out(26.3, 22.0, 52.2), "cube, 40 mm, 5,000 points");
        assert!(stands_out(26.8, 22.0, 36.7), "cube, 40 mm, 10,000 points");
        assert!(stands_out(33.5, 19.2, 26.9), "torus, 30 mm, 10,000 points");
    }

    #[test]
    fn bounds_shown_to_the_user_are_rounded_up_to_two_digits() {
        assert_eq!(metres_up(0.009_61), "0.0097");
        assert_eq!(metres_up(0.01), "0.01");
        assert_eq!(metres_up(0.0195), "0.02");
        assert_eq!(metres_up(2.01), "2.1");
        assert_eq!(metres_up(153.0), "160");
    }

    #[test]
    fn coincident_points_are_an_error_saying_so() {
        let cloud = PointCloud::new(vec![Vec3::ONE; 50]);
        let err = mesh_cloud(&cloud, &MeshConfig::default()).unwrap_err();
        assert!(
            matches!(err, PipelineError::PointsCoincide { points: 50, at } if at == Vec3::ONE),
            "{err}"
        );
    }

    #[test]
    fn empty_cloud_is_an_error() {
        let err = mesh_cloud(&PointCloud::default(), &MeshConfig::default()).unwrap_err();
        assert!(matches!(err, PipelineError::EmptyCloud));
    }
}
