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
use rustc_hash::FxHashMap;

use crate::cell_index::floor_div;
use crate::cell_planes::CellPlane;
use crate::sparse_sdf::{local_index, SdfBlock, SparseSdf, BLOCK_EDGE, BLOCK_VOXELS};

/// Settings of the signed distance, with units in the names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignedDistanceConfig {
    pub voxel_size_m: f32,
    /// A corner averages the planes of the voxels within this many voxels (and is unknown
    /// when there are none).
    pub band_voxels: i32,
    /// Radius of the weight on the distance from a corner to a plane's point, voxels.
    pub kernel_width_voxels: f32,
    /// The distance is sampled on every `corner_step`-th voxel corner along each axis (1: every
    /// corner), so the grid it returns has cells `corner_step` voxels wide; the planes, the
    /// band and the kernel stay those of the voxels.
    pub corner_step: i32,
}

/// For every block, the planes in its window: the voxels `block · span + [−band, span + band)`
/// on each axis (`span` = 8 corners × `step` voxels), which holds every voxel within `band` of
/// the block's corners. Built by walking the planes once (each lands in one to eight windows)
/// rather than looking up every window voxel.
fn planes_by_window(planes: &[CellPlane], band: i32, step: i32) -> Vec<(IVec3, Vec<u32>)> {
    // A window is `BLOCK_EDGE` corners of `step` voxels: floor division by the block's voxels
    // is one by `BLOCK_EDGE` (a power of two: a shift) and one by `step`.
    const _: () = assert!(BLOCK_EDGE.count_ones() == 1);
    let shift = BLOCK_EDGE.trailing_zeros() as i32;
    let mut windows: FxHashMap<IVec3, Vec<u32>> = FxHashMap::default();
    for (i, plane) in planes.iter().enumerate() {
        let lo = floor_div((plane.cell - IVec3::splat(band)) >> shift, step);
        let hi = floor_div((plane.cell + IVec3::splat(band)) >> shift, step);
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    windows
                        .entry(IVec3::new(x, y, z))
                        .or_default()
                        .push(i as u32);
                }
            }
        }
    }
    let mut windows: Vec<(IVec3, Vec<u32>)> = windows.into_iter().collect();
    windows.sort_unstable_by_key(|(k, _)| (k.z, k.y, k.x));
    windows
}

/// A plane as the corner loop reads it, made once per plane rather than once per window it
/// lands in (up to eight): the corner range takes six integer divisions by the step.
#[derive(Clone, Copy)]
struct WindowPlane {
    point: Vec3,
    normal: Vec3,
    /// `normal · point`, so the signed distance is `normal · x − offset_m`.
    offset_m: f32,
    weight: f32,
    /// The corners it reaches, as grid corner indices: those whose voxel index
    /// `c = corner · step` has the plane's cell in `[c − band, c + band)`, that is `c` in
    /// `[cell − band + 1, cell + band]`.
    lowest_corner: IVec3,
    highest_corner: IVec3,
}

impl WindowPlane {
    fn new(plane: &CellPlane, band: i32, step: i32) -> Self {
        let cell = plane.cell;
        Self {
            point: plane.point,
            normal: plane.normal,
            offset_m: plane.normal.dot(plane.point),
            // Support squared: a box centred on the surface holds several times the points of
            // one centred in the noise fringe beside it, and its plane should outvote the
            // fringe's.
            weight: plane.points * plane.points,
            lowest_corner: -floor_div(-(cell - IVec3::splat(band - 1)), step),
            highest_corner: floor_div(cell + IVec3::splat(band), step),
        }
    }
}

/// Evaluates one block's corners by spreading each plane of its window onto the corners it
/// reaches.
///
/// A corner at voxel index `c` (per axis) averages the planes of the voxels `[c − band, c +
/// band)` whose point lies within `h` of it, `h = kernel_width_voxels · voxel`, with the kernel
/// `(1 − d²/h²)²` (Wendland-like, compact and cheaper than a Gaussian); a corner with none stays
/// unknown. Written as a scatter rather than a gather over each corner's window: the surface
/// fills about a sixth of a corner's `(2 · band)³` window, and the gather read every empty
/// voxel of it (and zeroed a dense copy of the window per block), which made this the
/// pipeline's largest stage. `in_window` is in the planes' order, sorted by cell (z, y, x) as
/// [`crate::cell_planes`] makes them, so each corner adds its planes in the order the gather
/// did and the values are the same to the bit.
fn evaluate_block(
    key: IVec3,
    planes: &[WindowPlane],
    in_window: &[u32],
    config: &SignedDistanceConfig,
    origin: Vec3,
) -> Option<SdfBlock> {
    let step = config.corner_step;
    let voxel = config.voxel_size_m;
    let width_sq = (config.kernel_width_voxels * voxel).powi(2);
    let inv_width_sq = 1.0 / width_sq;
    let first_corner = key * BLOCK_EDGE;
    let last_local = IVec3::splat(BLOCK_EDGE - 1);
    // The corners' coordinates, per axis: a corner is (x[i], y[j], z[k]). Everything a plane
    // needs at a corner is a sum of one term per axis, so the terms are worked out per axis
    // (8 each) rather than per corner (512), in the same order of operations as the
    // `Vec3` arithmetic they replace (`(corner - point).length_squared()` sums x², y², z² left
    // to right, `normal.dot(corner)` likewise): the values are the same to the bit.
    const EDGE: usize = BLOCK_EDGE as usize;
    let axis = |k: usize| -> [f32; EDGE] {
        std::array::from_fn(|i| origin[k] + ((first_corner[k] + i as i32) * step) as f32 * voxel)
    };
    let coords = [axis(0), axis(1), axis(2)];
    let mut sums = [0.0f32; BLOCK_VOXELS];
    let mut weights = [0.0f32; BLOCK_VOXELS];
    for &i in in_window {
        let plane = &planes[i as usize];
        if plane.weight == 0.0 {
            continue;
        }
        // The corners it reaches, local to the block, clipped.
        let lo = (plane.lowest_corner - first_corner).max(IVec3::ZERO);
        let hi = (plane.highest_corner - first_corner).min(last_local);
        let (point, normal) = (plane.point.to_array(), plane.normal.to_array());
        let mut dist_sq = [[0.0f32; EDGE]; 3];
        let mut along_normal = [[0.0f32; EDGE]; 3];
        for k in 0..3 {
            for c in lo[k] as usize..=hi[k] as usize {
                let d = coords[k][c] - point[k];
                dist_sq[k][c] = d * d;
                along_normal[k][c] = normal[k] * coords[k][c];
            }
        }
        for z in lo.z as usize..=hi.z as usize {
            for y in lo.y as usize..=hi.y as usize {
                for x in lo.x as usize..=hi.x as usize {
                    let d_sq = dist_sq[0][x] + dist_sq[1][y] + dist_sq[2][z];
                    if d_sq >= width_sq {
                        continue;
                    }
                    let falloff = 1.0 - d_sq * inv_width_sq;
                    let w = plane.weight * falloff * falloff;
                    let at = local_index(IVec3::new(x as i32, y as i32, z as i32));
                    let height = along_normal[0][x] + along_normal[1][y] + along_normal[2][z];
                    sums[at] += w * (height - plane.offset_m);
                    weights[at] += w;
                }
            }
        }
    }
    let mut block = SdfBlock::default();
    let mut known = false;
    for ((value, &sum), &weight) in block.values_m.iter_mut().zip(&sums).zip(&weights) {
        if weight > 0.0 {
            *value = sum / weight;
            known = true;
        }
    }
    known.then_some(block)
}

/// Samples the smoothed signed distance to `planes` on the corners of a sparse grid near them.
/// The grid's corners sit on every `corner_step`-th voxel corner of the planes' grid (origin 0),
/// and its cells are `corner_step` voxels wide.
pub fn signed_distance_near(planes: &[CellPlane], config: &SignedDistanceConfig) -> SparseSdf {
    let origin = Vec3::ZERO;
    let config = SignedDistanceConfig {
        corner_step: config.corner_step.max(1),
        ..*config
    };
    let step = config.corner_step;
    let mut sdf = SparseSdf::new(config.voxel_size_m * step as f32, origin);
    let windows = planes_by_window(planes, config.band_voxels.max(1), step);
    let window_planes: Vec<WindowPlane> = planes
        .par_iter()
        .map(|plane| WindowPlane::new(plane, config.band_voxels, step))
        .collect();
    let blocks: Vec<(IVec3, SdfBlock)> = windows
        .par_iter()
        .filter_map(|(key, in_window)| {
            Some((
                *key,
                evaluate_block(*key, &window_planes, in_window, &config, origin)?,
            ))
        })
        .collect();
    sdf.blocks.extend(blocks);
    sdf
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window's shift-then-divide floors as `div_euclid` by the block's voxels does, on
    /// both sides of zero.
    #[test]
    fn window_division_is_div_euclid() {
        for step in 1..=7 {
            for x in -200..=200 {
                let v = IVec3::new(x, -x, x / 3 - 7);
                assert_eq!(
                    floor_div(v >> BLOCK_EDGE.trailing_zeros(), step),
                    v.div_euclid(IVec3::splat(BLOCK_EDGE * step)),
                    "{v} / 8·{step}"
                );
            }
        }
    }

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
            corner_step: 1,
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

    /// A plane in every voxel a sphere passes through (some of them at negative indices),
    /// each on the sphere and facing out.
    fn sphere_planes(centre: Vec3, radius: f32, voxel: f32) -> Vec<CellPlane> {
        let reach = ((radius + voxel) / voxel).ceil() as i32 + 1;
        let mut planes = Vec::new();
        for z in -reach..reach {
            for y in -reach..reach {
                for x in -reach..reach {
                    let cell = IVec3::new(x, y, z) + (centre / voxel).floor().as_ivec3();
                    let middle = (cell.as_vec3() + 0.5) * voxel;
                    let normal = (middle - centre).normalize();
                    let point = centre + normal * radius;
                    if (point / voxel).floor().as_ivec3() == cell {
                        planes.push(CellPlane {
                            cell,
                            point,
                            normal,
                            points: 4.0 + (x & 3) as f32,
                        });
                    }
                }
            }
        }
        planes
    }

    #[test]
    fn every_corner_is_the_weighted_mean_of_its_planes_to_the_bit() {
        // The definition, corner by corner and plane by plane in the planes' order, against
        // the scatter over blocks with its per-axis terms.
        let voxel = 0.02;
        let planes = sphere_planes(Vec3::new(0.05, -0.07, 0.02), 0.25, voxel);
        for corner_step in [1, 3] {
            let config = SignedDistanceConfig {
                voxel_size_m: voxel,
                band_voxels: 3,
                kernel_width_voxels: 3.5,
                corner_step,
            };
            let sdf = signed_distance_near(&planes, &config);
            let width_sq = (config.kernel_width_voxels * voxel).powi(2);
            let mut known = 0;
            for (key, block) in &sdf.blocks {
                for i in 0..BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE {
                    let local = IVec3::new(i % BLOCK_EDGE, (i / BLOCK_EDGE) % BLOCK_EDGE, i / 64);
                    let ijk = *key * BLOCK_EDGE + local;
                    let corner = (ijk * corner_step).as_vec3() * voxel;
                    let (mut sum, mut weight) = (0.0f32, 0.0f32);
                    for plane in &planes {
                        let offset = plane.cell - ijk * corner_step;
                        let in_band = offset.cmpge(IVec3::splat(-config.band_voxels)).all()
                            && offset.cmplt(IVec3::splat(config.band_voxels)).all();
                        let d_sq = (corner - plane.point).length_squared();
                        if !in_band || d_sq >= width_sq {
                            continue;
                        }
                        let falloff = 1.0 - d_sq * (1.0 / width_sq);
                        let w = plane.points * plane.points * falloff * falloff;
                        sum += w * (plane.normal.dot(corner) - plane.normal.dot(plane.point));
                        weight += w;
                    }
                    let value = block.values_m[local_index(local)];
                    if weight > 0.0 {
                        known += 1;
                        assert_eq!(value.to_bits(), (sum / weight).to_bits(), "{ijk}");
                    } else {
                        assert!(value.is_nan(), "{ijk}: {value}");
                    }
                }
            }
            assert!(known > 400, "step {corner_step}: {known} corners");
        }
    }

    #[test]
    fn a_coarser_grid_samples_the_same_distance_on_every_other_corner() {
        let voxel = 0.02;
        let planes = sphere_planes(Vec3::new(0.05, -0.07, 0.02), 0.3, voxel);
        let config = SignedDistanceConfig {
            voxel_size_m: voxel,
            band_voxels: 3,
            kernel_width_voxels: 2.5,
            corner_step: 1,
        };
        let fine = signed_distance_near(&planes, &config);
        let coarse = signed_distance_near(
            &planes,
            &SignedDistanceConfig {
                corner_step: 2,
                ..config
            },
        );
        assert_eq!(coarse.voxel_size_m, 2.0 * voxel);
        // Every corner the fine grid knows at an even index, the coarse grid knows at half
        // that index with the same value, and it knows no other.
        let known = |sdf: &SparseSdf| -> Vec<(IVec3, f32)> {
            let mut corners: Vec<(IVec3, f32)> = sdf
                .blocks
                .iter()
                .flat_map(|(key, block)| {
                    let key = *key;
                    (0..BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE).filter_map(move |i| {
                        let local =
                            IVec3::new(i % BLOCK_EDGE, (i / BLOCK_EDGE) % BLOCK_EDGE, i / 64);
                        let value = block.values_m[local_index(local)];
                        value
                            .is_finite()
                            .then_some((key * BLOCK_EDGE + local, value))
                    })
                })
                .collect();
            corners.sort_by_key(|(ijk, _)| (ijk.z, ijk.y, ijk.x));
            corners
        };
        let even: Vec<(IVec3, f32)> = known(&fine)
            .into_iter()
            .filter(|(ijk, _)| ijk.rem_euclid(IVec3::splat(2)) == IVec3::ZERO)
            .map(|(ijk, value)| (ijk / 2, value))
            .collect();
        let sampled = known(&coarse);
        assert!(sampled.len() > 1000, "{} corners", sampled.len());
        assert_eq!(sampled.len(), even.len());
        for ((ijk, value), (expected_ijk, expected)) in sampled.iter().zip(&even) {
            assert_eq!(ijk, expected_ijk);
            assert_eq!(coarse.position(*ijk), fine.position(2 * *ijk));
            assert!(
                (value - expected).abs() < 1e-6,
                "{ijk}: {value} vs {expected}"
            );
        }
    }
}
