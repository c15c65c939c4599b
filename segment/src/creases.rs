//! Concave creases by local plane fitting: a point's *valley depth* is how far it lies below the
//! total-least-squares plane of its neighbours within a radius (Hoppe et al., "Surface
//! reconstruction from unorganized points", SIGGRAPH 1992, for the local plane; the sign
//! convention, normals towards the viewpoint, as in Rusu 2009, §4.3). It is positive in concave
//! creases, where one object stands on or leans against another, negative on convex edges (box
//! corners, cylinder rims), and near zero on flat and gently curved surfaces. Setting the
//! creases aside before Euclidean clustering separates touching objects, the job LCCP (Stein et
//! al., "Object partitioning using local convexity", CVPR 2014) does on supervoxels; a
//! point-wise convexity test between neighbours was tried first and failed on the mOSD stacked
//! cylinders, whose crease is smeared over a few centimetres by the sensor.

use glam::Vec3;
use rayon::prelude::*;

use crate::grid::VoxelGrid;
use crate::planes::fit_plane;

/// At most this many neighbours (an even stride through them) fit a point's local plane.
const MAX_FIT_POINTS: usize = 192;

/// The local plane at a point: its unit normal (towards the viewpoint) and how deep the point
/// lies below it (its valley depth, in metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LocalPlane {
    pub(crate) normal: Vec3,
    pub(crate) valley_depth_m: f32,
}

/// The local plane of each of `indices` (ascending, finite points), from its neighbours among
/// `indices` within `radius_m`, with the normal turned towards `viewpoint`; a zero normal and
/// depth where the neighbours do not determine a plane. In the order of `indices`.
///
/// The neighbours are searched cell by cell of a grid of the radius: the points of a cell share
/// the 27 cells around it, gathered once (positions side by side) for all of them.
pub(crate) fn local_planes(
    points: &[Vec3],
    indices: &[u32],
    radius_m: f32,
    viewpoint: Vec3,
) -> Vec<LocalPlane> {
    let grid = VoxelGrid::new(points, indices, radius_m);
    let neighbourhoods = grid.neighbourhoods();
    let radius_sq = radius_m * radius_m;
    let per_cell: Vec<Vec<(u32, LocalPlane)>> = (0..grid.cell_count())
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(around, near): &mut (Vec<Vec3>, Vec<u32>), c| {
                around.clear();
                for &id in neighbourhoods.of(c) {
                    let members = grid.cell(id as usize).0;
                    around.extend(members.iter().map(|&j| points[j as usize]));
                }
                let (members, slots) = grid.cell(c);
                members
                    .iter()
                    .zip(slots)
                    .map(|(&i, &slot)| {
                        let p = points[i as usize];
                        // `near` indexes `around`, in the order of a search around `p`.
                        // Without a branch: about a third of the candidates are in the
                        // ball, in no order a branch predictor could learn.
                        near.resize(around.len(), 0);
                        let mut kept = 0;
                        for (k, &q) in around.iter().enumerate() {
                            near[kept] = k as u32;
                            kept += usize::from(p.distance_squared(q) <= radius_sq);
                        }
                        near.truncate(kept);
                        (slot, local_plane(around, near, p, viewpoint))
                    })
                    .collect()
            },
        )
        .collect();
    let mut planes = vec![
        LocalPlane {
            normal: Vec3::ZERO,
            valley_depth_m: 0.0,
        };
        indices.len()
    ];
    for (slot, plane) in per_cell.into_iter().flatten() {
        planes[slot as usize] = plane;
    }
    planes
}

/// The local plane at `p` through `near` (indices into `around`, its neighbours).
fn local_plane(around: &[Vec3], near: &mut Vec<u32>, p: Vec3, viewpoint: Vec3) -> LocalPlane {
    // A plane through a few hundred neighbours is as good as through thousands (a Kinect sees
    // ~1500 points in a 2.5 cm ball at 0.7 m): fit to an even stride.
    let stride = near.len().div_ceil(MAX_FIT_POINTS).max(1);
    if stride > 1 {
        let mut k = 0;
        near.retain(|_| {
            k += 1;
            (k - 1) % stride == 0
        });
    }
    // The valley depth is `(centroid − p)·n` with `n · centroid = d`, `n` towards the
    // viewpoint.
    match fit_plane(around, near) {
        Some((n, d)) if n.dot(viewpoint - p) < 0.0 => LocalPlane {
            normal: -n,
            valley_depth_m: n.dot(p) - d,
        },
        Some((n, d)) => LocalPlane {
            normal: n,
            valley_depth_m: d - n.dot(p),
        },
        None => LocalPlane {
            normal: Vec3::ZERO,
            valley_depth_m: 0.0,
        },
    }
}
