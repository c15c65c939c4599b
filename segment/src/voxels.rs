//! Voxel-grid downsampling (PCL's `VoxelGrid` filter; Rusu 2009, §2.3): the points fall into
//! cubic cells of a given side, and each occupied cell is represented by the centroid of its
//! points and how many there are. Later stages (creases, clustering) run on the centroids, and
//! every point takes the label of its cell.
//!
//! Cells are keyed in a hash map by their integer coordinates. Points of a depth image arrive
//! in pixel order, so consecutive points usually share a cell: the last cell is remembered and
//! the hash lookup skipped for repeats (a speed-up only; any point order gives the same cells).

use glam::{DVec3, Vec3};
use rustc_hash::FxHashMap;

use crate::range::RangeDistance;
use tacmesh_source::floor_i32;

/// The occupied cells of a set of points.
pub(crate) struct Cells {
    /// Centroid of each cell's points, in order of first occurrence.
    pub(crate) centroids: Vec<Vec3>,
    /// How many points each cell holds (at least 1).
    pub(crate) counts: Vec<u32>,
    /// The cell of each input index, in the order of the input.
    pub(crate) cell_of: Vec<u32>,
}

/// Bins `indices` (of finite points) into cells of side `cell_m` (> 0, finite), times `2^k`
/// for points in range band `k` of `coarsen` (see `RangeDistance::band`): far away, where
/// the sensor resolves less and the clustering links farther, cells grow as the links do, so
/// that a far wall costs the later stages no more per square metre of view than a near table.
pub(crate) fn voxel_cells(
    points: &[Vec3],
    indices: &[u32],
    cell_m: f32,
    coarsen: &RangeDistance,
) -> Cells {
    let mut id_of: FxHashMap<[i32; 4], u32> = FxHashMap::default();
    // Sums relative to each cell's corner, so that far-off clouds keep their precision.
    let mut sums: Vec<DVec3> = Vec::new();
    let mut counts: Vec<u32> = Vec::new();
    let mut corners: Vec<Vec3> = Vec::new();
    let mut cell_of = Vec::with_capacity(indices.len());
    let mut last: Option<([i32; 4], u32)> = None;
    for &i in indices {
        let p = points[i as usize];
        let band = coarsen.band(p);
        let side_m = cell_m * (1u32 << band) as f32;
        let q = p / side_m;
        // Saturating casts: absurdly distant points only share cells.
        let key = [floor_i32(q.x), floor_i32(q.y), floor_i32(q.z), band as i32];
        let id = match last {
            Some((last_key, id)) if last_key == key => id,
            _ => {
                let next = counts.len() as u32;
                let id = *id_of.entry(key).or_insert(next);
                if id == next {
                    sums.push(DVec3::ZERO);
                    counts.push(0);
                    corners.push(q.floor() * side_m);
                }
                last = Some((key, id));
                id
            }
        };
        sums[id as usize] += (p - corners[id as usize]).as_dvec3();
        counts[id as usize] += 1;
        cell_of.push(id);
    }
    let centroids = sums
        .iter()
        .zip(&counts)
        .zip(&corners)
        .map(|((&sum, &n), &corner)| corner + (sum / n as f64).as_vec3())
        .collect();
    Cells {
        centroids,
        counts,
        cell_of,
    }
}

/// The points of each list of cells in `lists` (disjoint lists of cells of `cells`), from the
/// input of [`voxel_cells`] (`indices`, ascending): one pass over the points, which keeps each
/// list of points ascending without a sort.
pub(crate) fn points_of_cell_lists(
    cells: &Cells,
    indices: &[u32],
    lists: &[Vec<u32>],
) -> Vec<Vec<u32>> {
    let mut list_of = vec![u32::MAX; cells.counts.len()];
    let mut points: Vec<Vec<u32>> = lists
        .iter()
        .enumerate()
        .map(|(k, list)| {
            let mut size = 0;
            for &c in list {
                list_of[c as usize] = k as u32;
                size += cells.counts[c as usize] as usize;
            }
            Vec::with_capacity(size)
        })
        .collect();
    for (&i, &c) in indices.iter().zip(&cells.cell_of) {
        let k = list_of[c as usize];
        if k != u32::MAX {
            points[k as usize].push(i);
        }
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxel_cells_average_the_points_of_each_cell() {
        let points = [
            Vec3::new(0.001, 0.001, 0.001),
            Vec3::new(0.013, 0.001, 0.001),
            Vec3::new(0.003, 0.003, 0.003),
            Vec3::NAN, // not listed below
            Vec3::new(0.017, 0.001, 0.001),
        ];
        let fixed = RangeDistance::new(0.015, 0.0, 1.0, Vec3::ZERO);
        let cells = voxel_cells(&points, &[0, 1, 2, 4], 0.01, &fixed);
        assert_eq!(cells.counts, vec![2, 2]);
        assert_eq!(cells.cell_of, vec![0, 1, 0, 1]);
        assert!(cells.centroids[0].distance(Vec3::splat(0.002)) < 1e-6);
        assert!(cells.centroids[1].distance(Vec3::new(0.015, 0.001, 0.001)) < 1e-6);
        assert_eq!(
            points_of_cell_lists(&cells, &[0, 1, 2, 4], &[vec![1], vec![0]]),
            vec![vec![1, 4], vec![0, 2]]
        );
    }
}
