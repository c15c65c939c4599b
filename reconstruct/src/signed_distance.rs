//! A signed distance to the data, sampled only near it (Hoppe et al. 1992 §4.3, smoothed the
//! way implicit moving least squares does: Kolluri 2008).
//!
//! Hoppe's distance at x is the signed distance to the tangent plane nearest x; with sensor
//! noise that switches plane from corner to corner and the surface comes out terraced. Here x
//! takes a Gaussian-weighted mean of the signed distances to the planes of the voxels around
//! it, which is smooth and averages the noise once more.
//!
//! Only grid corners with a plane within `band_voxels` are evaluated; everything else stays
//! unknown, so marching cubes leaves gaps in the data open instead of closing them with a
//! residue (the paper's objection to Poisson reconstruction).
//!
//! Entry point: [`signed_distance_near`].

use glam::{IVec3, Vec3};
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use crate::cell_planes::CellPlane;
use crate::sparse_sdf::{local_index, SdfBlock, SparseSdf, BLOCK_EDGE};

/// Settings of the signed distance, with units in the names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignedDistanceConfig {
    pub voxel_size_m: f32,
    /// A corner averages the planes of the voxels within this many voxels (and is unknown
    /// when there are none).
    pub band_voxels: i32,
    /// Width of the Gaussian weight on the distance from a corner to a plane's point, voxels.
    pub kernel_width_voxels: f32,
}

/// Corner `x` reads the voxels `x + [-band, band)` on each axis: those whose cube lies within
/// `band` voxels of it.
fn blocks_near_planes(planes: &[CellPlane], band: i32) -> Vec<IVec3> {
    let mut blocks = FxHashSet::default();
    for plane in planes {
        // Corners that read this voxel: cell + (-band, band] on each axis.
        let lo = SparseSdf::split(plane.cell - IVec3::splat(band - 1)).0;
        let hi = SparseSdf::split(plane.cell + IVec3::splat(band)).0;
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    blocks.insert(IVec3::new(x, y, z));
                }
            }
        }
    }
    let mut blocks: Vec<IVec3> = blocks.into_iter().collect();
    blocks.sort_unstable_by_key(|k| (k.z, k.y, k.x));
    blocks
}

/// Evaluates one block's corners from a dense window of the planes around it.
fn evaluate_block(
    key: IVec3,
    planes: &[CellPlane],
    slot: &FxHashMap<IVec3, u32>,
    config: &SignedDistanceConfig,
    origin: Vec3,
) -> Option<SdfBlock> {
    let band = config.band_voxels;
    let window = BLOCK_EDGE + 2 * band;
    let window_min = key * BLOCK_EDGE - IVec3::splat(band);
    let mut dense: Vec<u32> = vec![u32::MAX; (window * window * window) as usize];
    let mut any = false;
    for z in 0..window {
        for y in 0..window {
            for x in 0..window {
                if let Some(&i) = slot.get(&(window_min + IVec3::new(x, y, z))) {
                    dense[(x + window * (y + window * z)) as usize] = i;
                    any = true;
                }
            }
        }
    }
    if !any {
        return None;
    }
    let voxel = config.voxel_size_m;
    let inv_width_sq = 1.0 / (config.kernel_width_voxels * voxel).powi(2);
    let mut block = SdfBlock::default();
    for z in 0..BLOCK_EDGE {
        for y in 0..BLOCK_EDGE {
            for x in 0..BLOCK_EDGE {
                let local = IVec3::new(x, y, z);
                let corner = origin + (key * BLOCK_EDGE + local).as_vec3() * voxel;
                let (mut sum, mut weight) = (0.0f32, 0.0f32);
                // Window coordinates of voxel corner + d, d in [-band, band): local + band + d.
                for wz in z..z + 2 * band {
                    for wy in y..y + 2 * band {
                        for wx in x..x + 2 * band {
                            let i = dense[(wx + window * (wy + window * wz)) as usize];
                            if i == u32::MAX {
                                continue;
                            }
                            let plane = &planes[i as usize];
                            // Support squared: a box centred on the surface holds several
                            // times the points of one centred in the noise fringe beside it,
                            // and its plane should outvote the fringe's.
                            let w = plane.points
                                * plane.points
                                * (-(corner - plane.point).length_squared() * inv_width_sq).exp();
                            sum += w * plane.signed_distance(corner);
                            weight += w;
                        }
                    }
                }
                if weight > 1e-12 {
                    block.values_m[local_index(local)] = sum / weight;
                }
            }
        }
    }
    Some(block)
}

/// Samples the smoothed signed distance to `planes` on the corners of a sparse grid near them.
/// The grid's corners sit on the voxel corners of the planes' grid (origin 0).
pub fn signed_distance_near(planes: &[CellPlane], config: &SignedDistanceConfig) -> SparseSdf {
    let origin = Vec3::ZERO;
    let mut sdf = SparseSdf::new(config.voxel_size_m, origin);
    let slot: FxHashMap<IVec3, u32> = planes
        .iter()
        .enumerate()
        .map(|(i, p)| (p.cell, i as u32))
        .collect();
    let keys = blocks_near_planes(planes, config.band_voxels.max(1));
    let blocks: Vec<(IVec3, SdfBlock)> = keys
        .par_iter()
        .filter_map(|&key| Some((key, evaluate_block(key, planes, &slot, config, origin)?)))
        .collect();
    sdf.blocks.extend(blocks);
    sdf
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_planes(z: f32, voxel: f32) -> Vec<CellPlane> {
        let mut planes = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let point = Vec3::new((i as f32 + 0.5) * voxel, (j as f32 + 0.5) * voxel, z);
                planes.push(CellPlane {
                    cell: (point / voxel).floor().as_ivec3(),
                    point,
                    normal: Vec3::Z,
                    points: 5.0,
                });
            }
        }
        planes
    }

    #[test]
    fn plane_data_gives_exact_distance_near_it_and_unknown_far_away() {
        let config = SignedDistanceConfig {
            voxel_size_m: 0.02,
            band_voxels: 2,
            kernel_width_voxels: 1.0,
        };
        let sdf = signed_distance_near(&flat_planes(0.21, 0.02), &config);
        let above = IVec3::new(10, 10, 11);
        let d = sdf
            .get(above)
            .expect("corner just above the plane is known");
        let expected = sdf.position(above).z - 0.21;
        assert!((d - expected).abs() < 1e-5, "{d} vs {expected}");
        assert_eq!(sdf.get(IVec3::new(10, 10, 20)), None);
        assert_eq!(sdf.get(IVec3::new(60, 10, 11)), None);
    }
}
