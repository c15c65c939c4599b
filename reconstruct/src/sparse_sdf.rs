//! Sparse storage of a signed distance field: 8³-voxel blocks in a hash map, allocated only
//! where there is data, so memory and time follow the surface, not the bounding box
//! (the voxblox layout).

use std::collections::HashMap;

use glam::{IVec3, Vec3};

/// Voxels per block edge.
pub const BLOCK_EDGE: i32 = 8;
/// Voxels per block.
pub const BLOCK_VOXELS: usize = (BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE) as usize;

/// One block of signed distances in metres; `NaN` marks a grid corner with no estimate
/// (too far from any data), and marching cubes emits nothing for a cell touching one.
#[derive(Debug, Clone)]
pub struct SdfBlock {
    pub values_m: Box<[f32; BLOCK_VOXELS]>,
}

impl Default for SdfBlock {
    fn default() -> Self {
        Self {
            values_m: Box::new([f32::NAN; BLOCK_VOXELS]),
        }
    }
}

/// Index of voxel `local` (each component in `0..BLOCK_EDGE`) inside a block.
pub fn local_index(local: IVec3) -> usize {
    (local.x + BLOCK_EDGE * (local.y + BLOCK_EDGE * local.z)) as usize
}

/// A signed distance sampled on the corners of a regular grid, stored sparsely.
///
/// Grid corner `ijk` sits at `origin + ijk * voxel_size_m` in the cloud's frame.
#[derive(Debug, Clone)]
pub struct SparseSdf {
    pub voxel_size_m: f32,
    pub origin: Vec3,
    pub blocks: HashMap<IVec3, SdfBlock>,
}

impl SparseSdf {
    pub fn new(voxel_size_m: f32, origin: Vec3) -> Self {
        Self {
            voxel_size_m,
            origin,
            blocks: HashMap::new(),
        }
    }

    /// The block holding grid corner `ijk`, and the corner's place inside it.
    pub fn split(ijk: IVec3) -> (IVec3, IVec3) {
        let block = ijk.div_euclid(IVec3::splat(BLOCK_EDGE));
        (block, ijk - block * BLOCK_EDGE)
    }

    /// Signed distance at grid corner `ijk`, or `None` where it is unknown.
    pub fn get(&self, ijk: IVec3) -> Option<f32> {
        let (block, local) = Self::split(ijk);
        let v = self.blocks.get(&block)?.values_m[local_index(local)];
        v.is_finite().then_some(v)
    }

    /// World position of grid corner `ijk`.
    pub fn position(&self, ijk: IVec3) -> Vec3 {
        self.origin + ijk.as_vec3() * self.voxel_size_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_handles_negative_corners() {
        assert_eq!(
            SparseSdf::split(IVec3::new(-1, 0, 9)),
            (IVec3::new(-1, 0, 1), IVec3::new(7, 0, 1))
        );
    }

    #[test]
    fn unknown_corner_reads_none() {
        let mut sdf = SparseSdf::new(0.1, Vec3::ZERO);
        sdf.blocks.insert(IVec3::ZERO, SdfBlock::default());
        sdf.blocks.get_mut(&IVec3::ZERO).unwrap().values_m[local_index(IVec3::new(1, 2, 3))] = 0.5;
        assert_eq!(sdf.get(IVec3::new(1, 2, 3)), Some(0.5));
        assert_eq!(sdf.get(IVec3::new(1, 2, 4)), None);
        assert_eq!(sdf.get(IVec3::new(100, 0, 0)), None);
    }
}
