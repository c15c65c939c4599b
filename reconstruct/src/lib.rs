//! Point cloud to surface: voxel moments, tangent planes, a sparse signed distance near the data,
//! marching cubes.
//!
//! Entry points:
//! - [`surface::reconstruct_surface`]: one cloud to a dense marching-cubes mesh, stage by stage:
//! - [`moment_grid::MomentGrid`]: the fused state, point moments per voxel;
//! - [`cell_planes::fit_cell_planes`] and the orient functions: a tangent plane per voxel;
//! - [`signed_distance::signed_distance_near`]: a smoothed signed distance in sparse blocks;
//! - [`enclosed_band::close_where_band_ends`]: closes thin parts of a closed surface;
//! - [`marching_cubes::marching_cubes`]: the zero level set of a [`sparse_sdf::SparseSdf`].

pub mod cell_index;
pub mod cell_planes;
pub mod enclosed_band;
pub mod marching_cubes;
pub mod moment_grid;
pub mod moments;
pub mod noise;
pub mod signed_distance;
pub mod sparse_sdf;
pub mod surface;

/// Why a cloud could not be turned into a surface.
#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    #[error(
        "too few points to reconstruct a surface: {voxels} occupied voxels gave {planes} tangent \
         planes (need 4); give more points or a larger voxel size"
    )]
    TooFewPoints { voxels: usize, planes: usize },
    #[error("voxel size {voxel_size_m} m is not a positive finite length")]
    BadVoxelSize { voxel_size_m: f32 },
}
