//! Point cloud to surface: PCA normals, a sparse signed distance near the data, marching cubes.
//!
//! Entry points:
//! - [`sparse_sdf::SparseSdf`]: signed distances on grid corners, in sparse 8³ blocks.
//! - [`marching_cubes::marching_cubes`]: the zero level set of a `SparseSdf` as a mesh.

pub mod marching_cubes;
pub mod sparse_sdf;
