//! A tangent plane per occupied voxel, consistently oriented (Hoppe et al. 1992, "Surface
//! reconstruction from unorganized points", §4.1–4.2, with the k-nearest neighbourhood replaced
//! by a box of voxels whose point moments are summed).
//!
//! Each voxel's plane is fitted to the points in the 4×4×4-voxel box centred on it: with 20 mm
//! noise a plane fitted over one 2 cm voxel is a guess, and a box much wider sinks into curved
//! surfaces. The box is read as 2×2×2 voxels of a grid twice as coarse, so a fit costs eight
//! look-ups instead of sixty-four. Orientation works on the coarse grid too (eight times fewer
//! nodes) and hands each coarse sign down to the voxels inside.
//!
//! Entry points, in pipeline order: [`fit_cell_planes`], then [`orient_towards`] (one-view scans)
//! or [`orient_by_propagation`] (no single viewpoint).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::cell_index::{CellIndex, FACE_STEPS};
use crate::moment_grid::{MomentGrid, SortedVoxels};
use crate::moments::PointMoments;
use glam::{IVec3, Vec3};
use rayon::prelude::*;

/// The tangent plane of one voxel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellPlane {
    pub cell: IVec3,
    /// Centroid of the points around the voxel, on the plane.
    pub point: Vec3,
    pub normal: Vec3,
    /// Points in the box the plane was fitted to: its support, which weighs it in the signed
    /// distance.
    pub points: f32,
}

impl CellPlane {
    /// Signed distance of `p` from the plane, positive on the normal's side, metres.
    pub fn signed_distance(&self, p: Vec3) -> f32 {
        self.normal.dot(p - self.point)
    }
}

/// The fused points at two scales: the voxels, and voxels twice as large with their planes.
pub struct TwoScaleGrid {
    /// The fine voxels' size, metres.
    fine_voxel_m: f32,
    /// The fine voxels' cells in (z, y, x) order.
    fine_cells: Vec<IVec3>,
    /// The coarse voxels in (z, y, x) order with their moments: the fits below read them by
    /// cell dozens of times each, through `coarse_index`.
    pub coarse: SortedVoxels,
    coarse_index: CellIndex,
    /// A plane per coarse voxel (see [`fit_coarse_planes`]), unoriented.
    pub coarse_planes: Vec<CellPlane>,
    /// For each coarse voxel (in `coarse.cells` order), its plane's index in `coarse_planes`;
    /// `NO_PLANE` when too few points fit one.
    plane_of_coarse: Vec<u32>,
}

const NO_PLANE: u32 = u32::MAX;

impl TwoScaleGrid {
    pub fn new(fine: &MomentGrid) -> Self {
        let fine_voxels = fine.sorted_voxels();
        let coarse = SortedVoxels::coarsened(&fine_voxels, 2, fine.voxel_size_m());
        let fine_cells = fine_voxels.iter().map(|&(cell, _)| cell).collect();
        let coarse_index = CellIndex::new(&coarse.cells);
        let (coarse_planes, plane_of_coarse) =
            fit_coarse_planes(&coarse.cells, &coarse.moments, &coarse_index);
        Self {
            fine_voxel_m: fine.voxel_size_m(),
            fine_cells,
            coarse,
            coarse_index,
            coarse_planes,
            plane_of_coarse,
        }
    }

    /// The index in `coarse_planes` of the plane of the coarse voxel holding fine voxel `cell`.
    fn parent_plane_index(&self, cell: IVec3) -> Option<usize> {
        let slot = self.coarse_index.get(cell >> 1)?;
        match self.plane_of_coarse[slot as usize] {
            NO_PLANE => None,
            plane => Some(plane as usize),
        }
    }

    /// The plane of the coarse voxel holding fine voxel `cell`.
    fn parent_plane(&self, cell: IVec3) -> Option<&CellPlane> {
        self.coarse_planes.get(self.parent_plane_index(cell)?)
    }

    /// The lowest coarse voxel of the box of 2×2×2 coarse voxels (4×4×4 fine voxels) centred
    /// on fine voxel `cell`: the coarse voxels on the side of `cell`'s own that it is nearest
    /// to.
    fn box_first(cell: IVec3) -> IVec3 {
        let parent = cell >> 1; // floor(cell / 2), without a division
        let odd = cell - parent * 2; // 0 or 1 per axis
        parent + odd - IVec3::ONE
    }
}

/// The plane of every coarse voxel, fitted over it and its 26 neighbours (a box six fine voxels
/// wide); normals unoriented. Returns the planes in the voxels' order and, per voxel, its
/// plane's index (`NO_PLANE` for none).
fn fit_coarse_planes(
    cells: &[IVec3],
    moments: &[PointMoments],
    index: &CellIndex,
) -> (Vec<CellPlane>, Vec<u32>) {
    let fitted: Vec<Option<CellPlane>> = cells
        .par_iter()
        .map(|&cell| {
            let around = index.moments_around(moments, cell);
            let plane = around.plane()?;
            Some(CellPlane {
                cell,
                point: plane.point,
                normal: plane.normal,
                points: around.count as f32,
            })
        })
        .collect();
    let mut planes = Vec::with_capacity(fitted.len());
    let plane_of = fitted
        .into_iter()
        .map(|plane| match plane {
            Some(plane) => {
                planes.push(plane);
                (planes.len() - 1) as u32
            }
            None => NO_PLANE,
        })
        .collect();
    (planes, plane_of)
}

/// Fits a plane to every occupied voxel whose 4×4×4 box holds at least `min_points` points
/// (fewer: isolated noise, no plane). The plane passes through the box's centroid; its normal is
/// that of the voxel's coarse parent, fitted over a box six voxels wide: under 20 mm noise the
/// points in a 4-voxel box form a nearly round blob, and their least-spread direction is
/// little better than random. Normals are unoriented.
pub fn fit_cell_planes(grid: &TwoScaleGrid, min_points: f32) -> Vec<CellPlane> {
    let voxel = grid.fine_voxel_m;
    let firsts: Vec<IVec3> = grid
        .fine_cells
        .iter()
        .map(|&cell| TwoScaleGrid::box_first(cell))
        .collect();
    let (box_of, boxes) = grid
        .coarse_index
        .moments_in_boxes::<2>(&grid.coarse.moments, &firsts);
    grid.fine_cells
        .par_iter()
        .zip(&box_of)
        .filter_map(|(&cell, &b)| {
            let around = &boxes[b as usize];
            if around.count < f64::from(min_points.max(3.0)) {
                return None;
            }
            let normal = grid.parent_plane(cell)?.normal;
            let point = around.centroid()?;
            // A voxel the surface crosses has its centre within √3/2 voxel of it; one farther
            // away only holds noise from beside the surface, and its plane (fitted to a box
            // clipped off the noise) would only bias the distance.
            let centre = (cell.as_vec3() + 0.5) * voxel;
            if normal.dot(centre - point).abs() > voxel {
                return None;
            }
            Some(CellPlane {
                cell,
                point,
                normal,
                points: around.count as f32,
            })
        })
        .collect()
}

/// Flips every normal to face `viewpoint` (the sensor): the right rule for one-view scans.
pub fn orient_towards(planes: &mut [CellPlane], viewpoint: Vec3) {
    planes.par_iter_mut().for_each(|plane| {
        if plane.normal.dot(viewpoint - plane.point) < 0.0 {
            plane.normal = -plane.normal;
        }
    });
}

/// Consistent orientation with no viewpoint: orient the coarse voxels' planes (each fitted over
/// the coarse voxel and its 26 neighbours) by [`orient_by_spanning_tree`], then flip each fine
/// plane to agree with its coarse parent.
pub fn orient_by_propagation(planes: &mut [CellPlane], grid: &TwoScaleGrid) {
    let mut coarse = grid.coarse_planes.clone();
    orient_by_spanning_tree(&mut coarse);
    planes.par_iter_mut().for_each(|plane| {
        let oriented = grid
            .parent_plane_index(plane.cell)
            .and_then(|i| coarse.get(i));
        if let Some(parent) = oriented {
            if plane.normal.dot(parent.normal) < 0.0 {
                plane.normal = -plane.normal;
            }
        }
    });
}

/// An edge of the voxel adjacency graph; `BinaryHeap` pops the lowest cost first, and of equal
/// costs the lowest `to`. The two are packed in one integer so that a comparison is one
/// instruction (the heap's pops were a sixth of orienting): the cost's bits, mapped so that
/// they order as `f32::total_cmp` orders the costs, above `to`.
#[derive(PartialEq, Eq)]
struct GraphEdge {
    cost_then_to: u64,
    from: u32,
}

impl GraphEdge {
    fn new(cost: f32, to: u32, from: u32) -> Self {
        let bits = cost.to_bits();
        // Negative numbers order backwards in their bits: flip them all; flip the sign of the
        // others so that they come after.
        let ordered = if bits >> 31 == 1 {
            !bits
        } else {
            bits | 1 << 31
        };
        Self {
            cost_then_to: u64::from(ordered) << 32 | u64::from(to),
            from,
        }
    }

    fn to(&self) -> u32 {
        self.cost_then_to as u32
    }
}

impl Ord for GraphEdge {
    fn cmp(&self, other: &Self) -> Ordering {
        other.cost_then_to.cmp(&self.cost_then_to)
    }
}

impl PartialOrd for GraphEdge {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Consistent orientation with no viewpoint (Hoppe 1992 §4.2): a minimum spanning tree over
/// the planes of voxels sharing a face with edge cost `1 − |nᵢ·nⱼ|`, so the sign
/// travels first across nearly parallel planes and only then around sharp bends; each reached
/// normal is flipped to agree with its parent. Every connected part starts at its highest
/// plane, oriented to +z, and is then turned as a whole by [`face_extremes_out`].
fn orient_by_spanning_tree(planes: &mut [CellPlane]) {
    let cells: Vec<IVec3> = planes.iter().map(|p| p.cell).collect();
    let slot = CellIndex::new(&cells);
    let mut reached = vec![false; planes.len()];
    let mut heap = BinaryHeap::new();
    let mut part = Vec::new();
    // Seeds go highest first, of equal heights the lowest index first. An object's planes are
    // usually one part, which the highest plane reaches whole: it is found by a scan, and the
    // others are sorted only if some remain unreached (sorting them all up front was 1.4 % of
    // meshing a 1 m cube on one core).
    let highest = (0..planes.len() as u32).reduce(|best, i| {
        let (z, best_z) = (planes[i as usize].point.z, planes[best as usize].point.z);
        if z.total_cmp(&best_z) == Ordering::Greater {
            i
        } else {
            best
        }
    });
    let Some(highest) = highest else {
        return;
    };
    let mut grow = |seed: u32, planes: &mut [CellPlane], reached: &mut [bool]| {
        reached[seed as usize] = true;
        if planes[seed as usize].normal.z < 0.0 {
            planes[seed as usize].normal = -planes[seed as usize].normal;
        }
        part.clear();
        part.push(seed);
        push_edges(&slot, planes, reached, seed, &mut heap);
        while let Some(edge) = heap.pop() {
            let (to, from) = (edge.to(), edge.from);
            if reached[to as usize] {
                continue;
            }
            reached[to as usize] = true;
            part.push(to);
            if planes[to as usize].normal.dot(planes[from as usize].normal) < 0.0 {
                planes[to as usize].normal = -planes[to as usize].normal;
            }
            push_edges(&slot, planes, reached, to, &mut heap);
        }
        face_extremes_out(planes, &part);
    };
    grow(highest, planes, &mut reached);
    let mut rest: Vec<u32> = (0..planes.len() as u32)
        .filter(|&i| !reached[i as usize])
        .collect();
    rest.sort_by(|&a, &b| {
        planes[b as usize]
            .point
            .z
            .total_cmp(&planes[a as usize].point.z)
    });
    for seed in rest {
        if !reached[seed as usize] {
            grow(seed, planes, &mut reached);
        }
    }
}

/// Turns a consistently oriented part as a whole so that its extreme planes face away from it.
///
/// The seed's rule (the highest plane faces up) fails where the top is a point or an edge:
/// at a cone's apex the fitted normal is nearly horizontal, its sign is noise, and the whole
/// cone came out inside out. Here the planes farthest along each of the six axis directions
/// vote, each with the cosine between its normal and its direction (a plane on a flat top
/// votes with weight one, one at an apex or on an edge with little), and the part is flipped
/// when the vote is negative. For a closed surface every extreme faces out; for a shell seen
/// from one side the side facing the most extremes wins.
fn face_extremes_out(planes: &mut [CellPlane], part: &[u32]) {
    let directions = [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ];
    let vote: f32 = directions
        .iter()
        .filter_map(|&d| {
            part.iter()
                .max_by(|&&a, &&b| {
                    let (pa, pb) = (&planes[a as usize], &planes[b as usize]);
                    pa.point.dot(d).total_cmp(&pb.point.dot(d))
                })
                .map(|&extreme| planes[extreme as usize].normal.dot(d))
        })
        .sum();
    if vote < 0.0 {
        for &i in part {
            planes[i as usize].normal = -planes[i as usize].normal;
        }
    }
}

fn push_edges(
    slot: &CellIndex,
    planes: &[CellPlane],
    reached: &[bool],
    from: u32,
    heap: &mut BinaryHeap<GraphEdge>,
) {
    let here = planes[from as usize];
    // Face neighbours only: the noisy surface is several voxels thick, so it stays connected,
    // and the tree is built from a quarter of the edges of the full 26-neighbourhood.
    for step in FACE_STEPS {
        let Some(to) = slot.get(here.cell + step) else {
            continue;
        };
        if !reached[to as usize] {
            let cost = 1.0 - here.normal.dot(planes[to as usize].normal).abs();
            heap.push(GraphEdge::new(cost, to, from));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The packed edges order as the cost by `f32::total_cmp` and then `to`, reversed (the heap
    /// pops the greatest): rounding can make `1 − |n·m|` a hair negative, and the edges the tree
    /// takes must not change with the packing.
    #[test]
    fn packed_edges_order_as_their_costs_then_targets() {
        let costs = [-1e-7, -0.0, 0.0, 1e-30, 0.25, 0.5, 1.0, 1.0 + 1e-7];
        let targets = [0, 1, 7, u32::MAX];
        for (c1, t1) in costs.into_iter().flat_map(|c| targets.map(|t| (c, t))) {
            for (c2, t2) in costs.into_iter().flat_map(|c| targets.map(|t| (c, t))) {
                let packed = GraphEdge::new(c1, t1, 0).cmp(&GraphEdge::new(c2, t2, 5));
                let plain = c2.total_cmp(&c1).then(t2.cmp(&t1));
                assert_eq!(packed, plain, "({c1}, {t1}) against ({c2}, {t2})");
            }
        }
    }

    fn fibonacci_sphere(n: usize, radius: f32) -> Vec<Vec3> {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f32;
                Vec3::new(r * phi.cos(), r * phi.sin(), z) * radius
            })
            .collect()
    }

    const MIN_POINTS: f32 = 8.0;

    #[test]
    fn propagation_orients_sphere_normals_outward() {
        let mut grid = MomentGrid::new(0.02);
        grid.integrate(&fibonacci_sphere(20_000, 0.5));
        let two = TwoScaleGrid::new(&grid);
        let mut planes = fit_cell_planes(&two, MIN_POINTS);
        assert!(planes.len() > 1000);
        orient_by_propagation(&mut planes, &two);
        for plane in &planes {
            let outward = plane.point.normalize();
            assert!(plane.normal.dot(outward) > 0.95, "{plane:?}");
        }
    }

    /// Two spheres apart are two parts: the lower one is seeded after the higher one's tree
    /// is grown, and both come out facing out.
    #[test]
    fn propagation_orients_every_part() {
        let mut points = fibonacci_sphere(12_000, 0.3);
        let below = Vec3::new(1.5, 0.2, -1.0);
        points.extend(fibonacci_sphere(12_000, 0.3).into_iter().map(|p| p + below));
        let mut grid = MomentGrid::new(0.02);
        grid.integrate(&points);
        let two = TwoScaleGrid::new(&grid);
        let mut planes = fit_cell_planes(&two, MIN_POINTS);
        orient_by_propagation(&mut planes, &two);
        let (mut upper, mut lower) = (0, 0);
        for plane in &planes {
            let centre = if plane.point.z < -0.5 {
                below
            } else {
                Vec3::ZERO
            };
            let outward = (plane.point - centre).normalize();
            assert!(plane.normal.dot(outward) > 0.95, "{plane:?}");
            if centre == Vec3::ZERO {
                upper += 1;
            } else {
                lower += 1;
            }
        }
        assert!(upper > 500 && lower > 500, "{upper} and {lower} planes");
    }

    #[test]
    fn viewpoint_orientation_faces_the_sensor() {
        let points: Vec<Vec3> = (0..2500)
            .map(|i| Vec3::new((i % 50) as f32 * 0.004, (i / 50) as f32 * 0.004, 1.0))
            .collect();
        let mut grid = MomentGrid::new(0.02);
        grid.integrate(&points);
        let mut planes = fit_cell_planes(&TwoScaleGrid::new(&grid), MIN_POINTS);
        orient_towards(&mut planes, Vec3::ZERO);
        assert!(!planes.is_empty());
        assert!(planes.iter().all(|p| p.normal.z < -0.99));
    }

    #[test]
    fn isolated_points_get_no_plane() {
        let mut grid = MomentGrid::new(0.02);
        grid.integrate(&[
            Vec3::ZERO,
            Vec3::new(0.001, 0.0, 0.0),
            Vec3::new(0.0, 0.001, 0.0),
        ]);
        assert!(fit_cell_planes(&TwoScaleGrid::new(&grid), MIN_POINTS).is_empty());
    }
}
