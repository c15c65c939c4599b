//! A voxel hash grid over a subset of the points (Teschner et al., "Optimized spatial hashing
//! for collision detection of deformable objects", VMV 2003): cells of a given side keyed by
//! their integer coordinates in a hash map, each holding a slice of point indices. A ball of
//! radius at most the side around any point lies in the 27 cells around the point's cell.
//!
//! Points of one cell share those 27 cells: a search for every binned point goes cell by cell,
//! with the occupied cells around every cell found at once by merging the sorted keys
//! ([`VoxelGrid::neighbourhoods`]) instead of 27 hash lookups per cell or per point.

use glam::Vec3;
use rustc_hash::FxHashMap;
use tacmesh_source::floor_i32;

type Cell = [i32; 3];

pub struct VoxelGrid {
    inv_cell_m: f32,
    cell_ids: FxHashMap<Cell, u32>,
    /// The key of each cell, by id.
    keys: Vec<Cell>,
    /// `start[c]..start[c + 1]` indexes `members` and `slots` for cell `c`.
    start: Vec<u32>,
    /// Point indices grouped by cell, ascending within each cell.
    members: Vec<u32>,
    /// The position in the binned `indices` of each of `members`.
    slots: Vec<u32>,
}

/// Flipping the sign bit orders `i32`s as `u32`s.
const SIGN: u32 = 1 << 31;

/// The grid cell of `p`. Coordinates beyond `i32` saturate, which only merges cells of absurdly
/// distant points.
fn cell_of(p: Vec3, inv_cell_m: f32) -> Cell {
    let q = p * inv_cell_m;
    [floor_i32(q.x), floor_i32(q.y), floor_i32(q.z)]
}

impl VoxelGrid {
    /// Bins `indices` (of finite points, ascending) into cells of side `cell_m` (> 0).
    pub fn new(points: &[Vec3], indices: &[u32], cell_m: f32) -> Self {
        let inv_cell_m = 1.0 / cell_m;
        let mut cell_ids: FxHashMap<Cell, u32> = FxHashMap::default();
        let mut keys = Vec::new();
        let point_cell: Vec<u32> = indices
            .iter()
            .map(|&i| {
                let key = cell_of(points[i as usize], inv_cell_m);
                *cell_ids.entry(key).or_insert_with(|| {
                    keys.push(key);
                    keys.len() as u32 - 1
                })
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
        let mut slots = vec![0u32; indices.len()];
        for (slot, (&i, &c)) in indices.iter().zip(&point_cell).enumerate() {
            members[fill[c as usize] as usize] = i;
            slots[fill[c as usize] as usize] = slot as u32;
            fill[c as usize] += 1;
        }
        Self {
            inv_cell_m,
            cell_ids,
            keys,
            start,
            members,
            slots,
        }
    }

    /// How many cells hold points.
    pub(crate) fn cell_count(&self) -> usize {
        self.keys.len()
    }

    /// The binned points of cell `c` (`c < cell_count()`), ascending, and their positions in
    /// the binned `indices`.
    pub(crate) fn cell(&self, c: usize) -> (&[u32], &[u32]) {
        let range = self.start[c] as usize..self.start[c + 1] as usize;
        (&self.members[range.clone()], &self.slots[range])
    }

    /// The key of the cell `p` falls in, occupied or not.
    pub(crate) fn key_of(&self, p: Vec3) -> [i32; 3] {
        cell_of(p, self.inv_cell_m)
    }

    /// Calls `visit` with each occupied cell (by id) among the 27 around the cell of key `c`
    /// (see [`VoxelGrid::key_of`]), in the order [`VoxelGrid::for_each_near`] visits them.
    pub(crate) fn around_key(&self, c: Cell, mut visit: impl FnMut(u32)) {
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    if let Some(&id) = self.cell_ids.get(&key) {
                        visit(id);
                    }
                }
            }
        }
    }

    /// The occupied cells around every occupied cell, as [`VoxelGrid::around_key`] finds
    /// them for one: the keys are sorted once, and the cells of each of the nine columns
    /// around a cell (its x, y offsets) are the next keys of a cursor through the sorted keys
    /// for that column, which only moves forward as the cells are taken in key order.
    pub(crate) fn neighbourhoods(&self) -> Neighbourhoods {
        let n = self.keys.len();
        // Each cell as one integer, which orders as its key and compares in two steps: the
        // key's coordinates (sign bits flipped, to order as unsigned) above the cell's id.
        let packed = |key: Cell| {
            key.iter().fold(0u128, |packed, &x| {
                (packed << 32) | u128::from(x as u32 ^ SIGN)
            }) << 32
        };
        let mut sorted: Vec<u128> = self
            .keys
            .iter()
            .enumerate()
            .map(|(c, &key)| packed(key) | c as u128)
            .collect();
        sorted.sort_unstable();
        let mut cursors = [0usize; 9];
        let mut ranges = vec![(0, 0); n];
        let mut cells = Vec::with_capacity(9 * n);
        for &entry in &sorted {
            let c = entry as u32 as usize;
            let key = self.keys[c];
            let begin = cells.len() as u32;
            if key.iter().any(|&x| x == i32::MIN || x == i32::MAX) {
                // Offsets saturate at the edge of the key space, as `around_key` has them.
                self.around_key(key, |id| cells.push(id));
            } else {
                for (column, cursor) in cursors.iter_mut().enumerate() {
                    let (dx, dy) = (column as i32 / 3 - 1, column as i32 % 3 - 1);
                    let lowest = packed([key[0] + dx, key[1] + dy, key[2] - 1]);
                    // Past the column's last cell: the next column's first, or the cell three
                    // above the lowest.
                    let highest =
                        packed([key[0] + dx, key[1] + dy, key[2] + 1]) | u128::from(u32::MAX);
                    while *cursor < n && sorted[*cursor] < lowest {
                        *cursor += 1;
                    }
                    for &other in sorted[*cursor..(*cursor + 3).min(n)].iter() {
                        if other > highest {
                            break;
                        }
                        cells.push(other as u32);
                    }
                }
            }
            ranges[c] = (begin, cells.len() as u32);
        }
        Neighbourhoods { ranges, cells }
    }

    /// Calls `visit` with every binned point in the 27 cells around `p`'s cell (a superset of
    /// the binned points within one cell side of `p`).
    pub fn for_each_near(&self, p: Vec3, mut visit: impl FnMut(u32)) {
        self.around_key(cell_of(p, self.inv_cell_m), |id| {
            for &j in self.cell(id as usize).0 {
                visit(j);
            }
        });
    }
}

/// The occupied cells among the 27 around each occupied cell of a [`VoxelGrid`]
/// ([`VoxelGrid::neighbourhoods`]).
pub(crate) struct Neighbourhoods {
    /// `cells[ranges[c].0..ranges[c].1]` for cell `c`.
    ranges: Vec<(u32, u32)>,
    cells: Vec<u32>,
}

impl Neighbourhoods {
    /// The occupied cells (by id) around cell `c`, in the order [`VoxelGrid::for_each_near`]
    /// visits them for a point of cell `c`.
    pub(crate) fn of(&self, c: usize) -> &[u32] {
        let (begin, end) = self.ranges[c];
        &self.cells[begin as usize..end as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_sees_what_each_of_its_points_sees() {
        let points: Vec<Vec3> = (0..200)
            .map(|k| {
                let k = k as f32;
                Vec3::new((k * 0.37).sin(), (k * 0.91).cos(), (k * 0.13).sin()) * 0.05
            })
            .collect();
        let indices: Vec<u32> = (0..points.len() as u32).filter(|i| i % 3 != 1).collect();
        let grid = VoxelGrid::new(&points, &indices, 0.02);
        let neighbourhoods = grid.neighbourhoods();
        let mut seen = 0;
        for c in 0..grid.cell_count() {
            let around: Vec<u32> = neighbourhoods
                .of(c)
                .iter()
                .flat_map(|&id| grid.cell(id as usize).0)
                .copied()
                .collect();
            let (members, slots) = grid.cell(c);
            for (&i, &slot) in members.iter().zip(slots) {
                assert_eq!(indices[slot as usize], i);
                let mut near = Vec::new();
                grid.for_each_near(points[i as usize], |j| near.push(j));
                assert_eq!(near, around);
                seen += 1;
            }
        }
        assert_eq!(seen, indices.len());
    }
}
