//! The whole reconstruction in pipeline order: moments per voxel → a tangent plane per voxel →
//! orientation → signed distance near the data → close thin parts (no viewpoint only) →
//! marching cubes → drop noise fragments.
//!
//! Entry points: [`reconstruct_surface`] for one cloud, [`mesh_moment_grid`] for a fused state
//! that grows frame by frame.

use std::time::Instant;

use glam::Vec3;
use tacmesh_source::{PointCloud, TriMesh};

use crate::cell_planes::{
    fit_cell_planes, orient_by_propagation, orient_towards, CellPlane, TwoScaleGrid,
};
use crate::enclosed_band::close_where_band_ends;
use crate::marching_cubes::marching_cubes;
use crate::moment_grid::{MomentGrid, SortedVoxels};
use crate::signed_distance::{signed_distance_near, SignedDistanceConfig};
use crate::ReconstructError;

/// How normals get a consistent sign.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Orientation {
    /// Every normal faces this sensor position (one-view scans; what the daemon uses).
    TowardsViewpoint(Vec3),
    /// Hoppe's spanning-tree propagation (merged scans, sampled shapes, files with no viewpoint).
    Propagate,
}

/// Reconstruction settings, units in the names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReconstructConfig {
    /// Voxel edge of the fused moments and of marching cubes, metres.
    pub voxel_size_m: f32,
    /// Voxels with fewer points than this in the 4×4×4-voxel box around them are noise.
    pub min_points: f32,
    /// Grid corners with no plane within this many voxels stay unknown (and the mesh open).
    pub band_voxels: i32,
    /// Radius of the signed distance's weight on nearby planes, voxels.
    pub kernel_width_voxels: f32,
    /// Marching-cubes cell edge in voxels: the signed distance is sampled on every
    /// `mesh_step_voxels`-th voxel corner (1: every corner), which cuts the dense mesh's faces
    /// about by its square while the planes and their smoothing stay at the voxel's scale. A
    /// closed object (orientation by propagation) whose coarser mesh comes out open (or, from
    /// every third corner, in pieces) is meshed again on finer corners (see
    /// [`mesh_moment_grid`]).
    pub mesh_step_voxels: i32,
    pub orientation: Orientation,
    /// Connected pieces with fewer faces than this fraction of the largest piece are noise
    /// fragments and are dropped.
    pub min_piece_fraction: f32,
}

impl ReconstructConfig {
    /// Marching cubes on every `step`-th voxel corner (see
    /// [`ReconstructConfig::mesh_step_voxels`]), with the band and kernel widened to match: a
    /// corner of a cell the surface crosses lies up to `step` voxels from the crossing along
    /// each axis, so the band reaches one voxel past that (`step + 1`) and the kernel half a
    /// voxel further (`step + 1.5`); step 1 gives the defaults. Measured on the six sampled
    /// shapes at 0–40 mm noise, 40,000 points (three seeds each): step 2 with the step-1 band
    /// and kernel (2, 2.5) left Suzanne open on every seed at 0 mm; band 3 with kernel 3.0 left
    /// the torus open at 20 mm; 3 and 3.5 close every shape.
    pub fn with_mesh_step(self, step: i32) -> Self {
        let step = step.max(1);
        Self {
            mesh_step_voxels: step,
            band_voxels: step + 1,
            kernel_width_voxels: step as f32 + 1.5,
            ..self
        }
    }

    /// Defaults for a given voxel size.
    pub fn with_voxel_size(voxel_size_m: f32) -> Self {
        Self {
            voxel_size_m,
            min_points: 8.0,
            band_voxels: 2,
            kernel_width_voxels: 2.5,
            mesh_step_voxels: 1,
            orientation: Orientation::Propagate,
            min_piece_fraction: 0.02,
        }
    }
}

/// What reconstruction did and how long each stage took.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ReconstructReport {
    pub points: usize,
    pub voxels: usize,
    pub planes: usize,
    pub faces: usize,
    pub pieces_dropped: usize,
    /// The marching-cubes cell edge used, voxels: 1 when a coarser mesh of a closed object came
    /// out open and was made again.
    pub mesh_step_voxels: i32,
    pub integrate_ms: f64,
    pub normals_ms: f64,
    pub orient_ms: f64,
    pub distance_ms: f64,
    pub marching_cubes_ms: f64,
}

fn elapsed_ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Keeps the connected pieces (sharing vertices) with at least `min_fraction` of the largest
/// piece's faces; returns how many pieces went.
pub fn drop_small_pieces(mesh: &mut TriMesh, min_fraction: f32) -> usize {
    let n = mesh.vertices.len();
    let (piece_of_face, pieces_before) = mesh.face_pieces();
    let mut faces_per_piece = vec![0usize; pieces_before];
    for &piece in &piece_of_face {
        faces_per_piece[piece as usize] += 1;
    }
    let largest = faces_per_piece.iter().copied().max().unwrap_or(0);
    let keep_from = (largest as f32 * min_fraction).ceil() as usize;
    let mut kept = piece_of_face
        .iter()
        .map(|&piece| faces_per_piece[piece as usize] >= keep_from);
    mesh.triangles.retain(|_| kept.next().unwrap_or(false));
    let pieces_after = faces_per_piece
        .iter()
        .filter(|&&f| f >= keep_from.max(1))
        .count();

    // Drop vertices no triangle uses any more.
    let mut remap = vec![u32::MAX; n];
    let mut vertices = Vec::new();
    for t in &mut mesh.triangles {
        for i in t.iter_mut() {
            if remap[*i as usize] == u32::MAX {
                remap[*i as usize] = vertices.len() as u32;
                vertices.push(mesh.vertices[*i as usize]);
            }
            *i = remap[*i as usize];
        }
    }
    mesh.vertices = vertices;
    pieces_before - pieces_after
}

/// What reconstruction made.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// The dense marching-cubes mesh (simplify it next).
    pub mesh: TriMesh,
    /// The fused points in voxels twice the reconstruction's (the scale its normals were
    /// fitted at), for later stages to fit to: made once here rather than again by them.
    pub coarse_grid: SortedVoxels,
    pub report: ReconstructReport,
}

/// Reconstructs the surface of `cloud` as a marching-cubes mesh (dense; simplify it next), with
/// the fused points at twice the voxel (later stages fit to them).
pub fn reconstruct_surface(
    cloud: &PointCloud,
    config: &ReconstructConfig,
) -> Result<Reconstruction, ReconstructError> {
    if !(config.voxel_size_m.is_finite() && config.voxel_size_m > 0.0) {
        return Err(ReconstructError::BadVoxelSize {
            voxel_size_m: config.voxel_size_m,
        });
    }
    let start = Instant::now();
    let mut grid = MomentGrid::new(config.voxel_size_m);
    let points = grid.integrate(&cloud.points);
    let integrate_ms = elapsed_ms(start);
    let mut reconstruction = mesh_moment_grid(&grid, config)?;
    reconstruction.report.points = points;
    reconstruction.report.integrate_ms = integrate_ms;
    Ok(reconstruction)
}

/// Meshes a fused moment grid (its voxel size wins over `config.voxel_size_m`).
pub fn mesh_moment_grid(
    grid: &MomentGrid,
    config: &ReconstructConfig,
) -> Result<Reconstruction, ReconstructError> {
    let mut report = ReconstructReport {
        voxels: grid.len(),
        ..Default::default()
    };
    let start = Instant::now();
    let two_scale = TwoScaleGrid::new(grid);
    let mut planes = fit_cell_planes(&two_scale, config.min_points);
    report.normals_ms = elapsed_ms(start);
    report.planes = planes.len();
    if planes.len() < 4 {
        return Err(ReconstructError::TooFewPoints {
            voxels: grid.len(),
            planes: planes.len(),
        });
    }

    let start = Instant::now();
    match config.orientation {
        Orientation::TowardsViewpoint(viewpoint) => orient_towards(&mut planes, viewpoint),
        Orientation::Propagate => orient_by_propagation(&mut planes, &two_scale),
    }
    report.orient_ms = elapsed_ms(start);
    let coarse_grid = two_scale.coarse;

    let mut mesh = surface_of_planes(&planes, grid.voxel_size_m(), config, &mut report);
    // A closed object sampled too coarsely comes out with holes: a thin part (Suzanne's ears at
    // 40 mm noise from 5,000-10,000 points), or a crossed cell with a corner beyond every
    // plane's kernel (the torus's rim at 20 mm from 5,000-10,000 points). Mesh it again on
    // finer corners, which costs the coarse try's signed distance and marching cubes (a
    // quarter of the fine ones or less). Giving such corners the nearest plane's distance
    // instead closed the torus but thickened Suzanne's ears (MHE at 20 mm 10.5 -> 13.0 mm).
    // From every third corner a thin part can also come out closed but cut off (Suzanne's
    // ears at 0-10 mm from 40,000 points) or open (the torus's tube at 20 mm): every second
    // corner, tried first, closes both, and every corner is the last resort.
    let closed_object = config.orientation == Orientation::Propagate;
    let mut step = config.mesh_step_voxels;
    while step > 1
        && closed_object
        && (mesh.has_open_edge() || (step > 2 && mesh.face_pieces().1 > 1))
    {
        step = if step > 2 { 2 } else { 1 };
        let finer = config.with_mesh_step(step);
        mesh = surface_of_planes(&planes, grid.voxel_size_m(), &finer, &mut report);
    }
    report.faces = mesh.triangles.len();
    Ok(Reconstruction {
        mesh,
        coarse_grid,
        report,
    })
}

/// The signed distance to `planes` and its marching-cubes surface at `config`'s step; adds the
/// stages' times to `report` and sets its step and dropped pieces.
fn surface_of_planes(
    planes: &[CellPlane],
    voxel_size_m: f32,
    config: &ReconstructConfig,
    report: &mut ReconstructReport,
) -> TriMesh {
    let start = Instant::now();
    let step = config.mesh_step_voxels.max(1);
    let mut sdf = signed_distance_near(
        planes,
        &SignedDistanceConfig {
            voxel_size_m,
            band_voxels: config.band_voxels,
            kernel_width_voxels: config.kernel_width_voxels,
            corner_step: step,
        },
    );
    // A closed object's thin parts (one plane for both sides) end where the band ends; close
    // them there. A one-view scan is an open shell with no inside, and stays open. The band is
    // in voxels; the fill peels layers of the sampled grid.
    if config.orientation == Orientation::Propagate {
        close_where_band_ends(&mut sdf, (config.band_voxels / step).max(1));
    }
    report.distance_ms += elapsed_ms(start);

    let start = Instant::now();
    let mut mesh = marching_cubes(&sdf);
    report.pieces_dropped = drop_small_pieces(&mut mesh, config.min_piece_fraction);
    report.marching_cubes_ms += elapsed_ms(start);
    report.mesh_step_voxels = step;
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drop_small_pieces_removes_a_lone_fragment() {
        let mut mesh = TriMesh::new(
            vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::ONE,
                Vec3::new(5.0, 0.0, 0.0),
                Vec3::new(6.0, 0.0, 0.0),
                Vec3::new(5.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [1, 3, 2], [0, 3, 1], [4, 5, 6]],
        );
        assert_eq!(drop_small_pieces(&mut mesh, 0.5), 1);
        assert_eq!(mesh.triangles.len(), 3);
        assert_eq!(mesh.vertices.len(), 4);
    }
}
