//! A voxel hash grid over a subset of the points (Teschner et al., "Optimized spatial hashing
//! for collision detection of deformable objects", VMV 2003): cells of a given side keyed by
//! their integer coordinates in a hash map, each holding a slice of point indices. A ball of
//! radius at most the side around any point lies in the 27 cells around the point's cell.

use glam::Vec3;
use rustc_hash::FxHashMap;

type Cell = [i32; 3];

pub struct VoxelGrid {
    inv_cell_m: f32,
    cell_ids: FxHashMap<Cell, u32>,
    /// `start[c]..start[c + 1]` indexes `members` for cell `c`.
    start: Vec<u32>,
    /// Point indices grouped by cell, ascending within each cell.
    members: Vec<u32>,
}

/// The grid cell of `p`. Coordinates beyond `i32` saturate, which only merges cells of absurdly
/// distant points.
fn cell_of(p: Vec3, inv_cell_m: f32) -> Cell {
    let q = (p * inv_cell_m).floor();
    [q.x as i32, q.y as i32, q.z as i32]
}

impl VoxelGrid {
    /// Bins `indices` (of finite points, ascending) into cells of side `cell_m` (> 0).
    pub fn new(points: &[Vec3], indices: &[u32], cell_m: f32) -> Self {
        let inv_cell_m = 1.0 / cell_m;
        let mut cell_ids: FxHashMap<Cell, u32> = FxHashMap::default();
        let point_cell: Vec<u32> = indices
            .iter()
            .map(|&i| {
                let next = cell_ids.len() as u32;
                *cell_ids
                    .entry(cell_of(points[i as usize], inv_cell_m))
                    .or_insert(next)
            })
            .collect();
        // Counting sort by cell keeps ascending point order within a cell.
        let mut start = vec![0u32; cell_ids.len() + 1];
        for &c in &point_cell {
            start[c as usize + 1] += 1;
        }
        for k in 0..cell_ids.len() {
            start[k + 1] += start[k];
        }
        let mut fill = start.clone();
        let mut members = vec![0u32; indices.len()];
        for (&i, &c) in indices.iter().zip(&point_cell) {
            members[fill[c as usize] as usize] = i;
            fill[c as usize] += 1;
        }
        Self {
            inv_cell_m,
            cell_ids,
            start,
            members,
        }
    }

    /// Calls `visit` with every binned point in the 27 cells around `p`'s cell (a superset of
    /// the binned points within one cell side of `p`).
    pub fn for_each_near(&self, p: Vec3, mut visit: impl FnMut(u32)) {
        let c = cell_of(p, self.inv_cell_m);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    if let Some(&id) = self.cell_ids.get(&key) {
                        let range =
                            self.start[id as usize] as usize..self.start[id as usize + 1] as usize;
                        for &j in &self.members[range] {
                            visit(j);
                        }
                    }
                }
            }
        }
    }
}
