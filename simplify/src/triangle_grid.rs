//! Triangles bucketed in a uniform grid, for "which triangles can be within `cell_m` of this
//! point" on small meshes, asked for the same points of mesh after mesh: the fit's
//! nearest-triangle search and the later passes' assignment of extra support points.

use glam::{I64Vec3, IVec3, Vec3};
use rustc_hash::FxHashMap;
use tacmesh_source::floor_ivec3;

/// The occupied cells of a fixed set of query points in a uniform grid of `cell_m` cubes, found
/// once and then bucketed against mesh after mesh (the fit moves the same mesh's vertices and
/// asks again for the same samples; the simplifier's passes hold each new mesh to the same
/// points): hashing every point on every round was over half of the fit's time.
///
/// [`PointCells::bucket`] puts each triangle in every cell that holds a query point, touches
/// its bounding box grown by `cell_m`, and has its centre within `cell_m` plus half the cell's
/// diagonal of the triangle's plane, so a point's cell lists every triangle within `cell_m` of
/// it (in ascending triangle order). The meshes it serves are small (tens to hundreds of
/// triangles), so a flat grid is all the acceleration they need.
///
/// Only cells with query points are filled. A triangle whose grown box spans few cells walks
/// them through the map; a larger one (a flat face of a large object under a tight residual
/// spans millions of cells, nearly all empty: filling them all took over a minute and hundreds
/// of megabytes, found by fuzzing, see `fuzz/README.md`) is tested against each occupied cell,
/// box and plane, with no hashing. The plane test keeps a large face out of the cells its box
/// only grazes: fewer exact distances for the queries.
pub(crate) struct PointCells {
    cell_m: f32,
    /// Occupied cell -> its slot in `occupied` (and in a [`CellLists`]).
    index: FxHashMap<IVec3, u32>,
    occupied: Vec<IVec3>,
    /// The slot of each query point's cell, in the order the points were given; `NO_CELL` for
    /// a non-finite point.
    slot_of_point: Vec<u32>,
    /// The occupied cells grouped in blocks of `BLOCK_CELLS`³, for triangles too large to walk.
    blocks: Vec<Block>,
    /// The occupied slots, block by block (each [`Block`] holds a range of it).
    block_slots: Vec<u32>,
}

/// A cube of `BLOCK_CELLS`³ grid cells with at least one occupied cell.
struct Block {
    /// The block's first cell on each axis (a multiple of `BLOCK_CELLS`).
    first_cell: IVec3,
    /// `block_slots[from..to]` are its occupied cells' slots.
    from: u32,
    to: u32,
}

/// The triangles listed per occupied cell of a [`PointCells`], all in one array.
pub(crate) struct CellLists {
    /// Cell slot `s` lists `triangles[start[s]..start[s + 1]]`.
    start: Vec<u32>,
    triangles: Vec<u32>,
}

impl CellLists {
    /// The triangles listed in cell slot `slot`, ascending.
    pub(crate) fn of_slot(&self, slot: u32) -> &[u32] {
        let slot = slot as usize;
        match (self.start.get(slot), self.start.get(slot + 1)) {
            (Some(&from), Some(&to)) => &self.triangles[from as usize..to as usize],
            _ => &[],
        }
    }
}

const NO_CELL: u32 = u32::MAX;

/// A triangle's grown box spanning at most this many cells walks them; a larger one is tested
/// against the occupied cells of the blocks its box and plane reach.
const MAX_WALKED_CELLS: i64 = 64;

/// Cells per block edge, a power of two (a block is a cell's coordinates shifted right by
/// `BLOCK_SHIFT`). A large triangle was tested against every occupied cell (thousands on a 1 m
/// object under a 25 mm bound, for each of its faces and on every fit): 5-6 % of the whole
/// pipeline. Against blocks first, only the cells of the few blocks near its plane are tested.
const BLOCK_SHIFT: i32 = 3;
const BLOCK_CELLS: i32 = 1 << BLOCK_SHIFT;

/// The centre of grid cell `cell` of `cell_m` cubes.
fn centre_of(cell: IVec3, cell_m: f32) -> Vec3 {
    (cell.as_vec3() + 0.5) * cell_m
}

/// Which cells one triangle can be within `cell_m` of: those in its bounding box grown by
/// `cell_m` whose centre is near its plane (see [`TriangleReach::near_plane`]).
struct TriangleReach {
    a: Vec3,
    normal: Vec3,
    /// The grown box, in cells.
    lo: IVec3,
    hi: IVec3,
    /// How far from the plane a cell's centre may be.
    plane_reach: f32,
}

impl TriangleReach {
    fn new([a, b, c]: [Vec3; 3], cell_m: f32) -> Self {
        let cell_of = |p: Vec3| floor_ivec3(p / cell_m);
        Self {
            a,
            normal: (b - a).cross(c - a).normalize_or_zero(),
            lo: cell_of(a.min(b).min(c) - cell_m),
            hi: cell_of(a.max(b).max(c) + cell_m),
            // A point within `cell_m` of the triangle is within `cell_m` of its plane, and the
            // cell's centre within half the diagonal of the point; a little more for rounding.
            plane_reach: cell_m * (1.0 + 0.5 * 3f32.sqrt()) * 1.001,
        }
    }

    /// How many cells the grown box spans.
    fn box_cells(&self) -> i64 {
        let span = (self.hi.as_i64vec3() - self.lo.as_i64vec3() + 1).max(I64Vec3::ZERO);
        span.x.saturating_mul(span.y).saturating_mul(span.z)
    }

    /// Whether `centre` is within the cells' reach plus `extra_reach` of the plane, with a
    /// margin for rounding relative to how far from the origin it and the triangle are.
    fn near_plane(&self, centre: Vec3, extra_reach: f32) -> bool {
        let rounding = |p: Vec3| 16.0 * f32::EPSILON * p.abs().max_element();
        self.normal.dot(centre - self.a).abs()
            <= self.plane_reach + extra_reach + rounding(centre) + rounding(self.a)
    }

    /// Whether the triangle can be within `cell_m` of a point in `cell`.
    fn reaches(&self, cell: IVec3, cell_m: f32) -> bool {
        cell.cmpge(self.lo).all()
            && cell.cmple(self.hi).all()
            && self.near_plane(centre_of(cell, cell_m), 0.0)
    }
}

impl PointCells {
    /// The cells of `points` (non-finite ones have none). `cell_m` must be positive.
    pub(crate) fn new(points: impl Iterator<Item = Vec3>, cell_m: f32) -> Self {
        let mut index: FxHashMap<IVec3, u32> = FxHashMap::default();
        let mut occupied: Vec<IVec3> = Vec::new();
        let slot_of_point = points
            .map(|p| {
                if !p.is_finite() {
                    return NO_CELL;
                }
                let cell = floor_ivec3(p / cell_m);
                *index.entry(cell).or_insert_with(|| {
                    occupied.push(cell);
                    (occupied.len() - 1) as u32
                })
            })
            .collect();
        let block_of = |slot: u32| occupied[slot as usize] >> BLOCK_SHIFT;
        let mut block_slots: Vec<u32> = (0..occupied.len() as u32).collect();
        block_slots.sort_unstable_by_key(|&slot| {
            let block = block_of(slot);
            (block.z, block.y, block.x, slot)
        });
        let mut blocks: Vec<Block> = Vec::new();
        for (i, &slot) in block_slots.iter().enumerate() {
            let first_cell = block_of(slot) * BLOCK_CELLS;
            match blocks.last_mut() {
                Some(block) if block.first_cell == first_cell => block.to = i as u32 + 1,
                _ => blocks.push(Block {
                    first_cell,
                    from: i as u32,
                    to: i as u32 + 1,
                }),
            }
        }
        Self {
            cell_m,
            index,
            occupied,
            slot_of_point,
            blocks,
            block_slots,
        }
    }

    #[cfg(test)]
    pub(crate) fn cell_count(&self) -> usize {
        self.occupied.len()
    }

    /// Lists each triangle (given by its corners, in order) in the occupied cells it can be
    /// within `cell_m` of (see [`PointCells`]).
    pub(crate) fn bucket(&self, triangles: impl Iterator<Item = [Vec3; 3]>) -> CellLists {
        let cell_m = self.cell_m;
        // (cell slot, triangle), in triangle order; sorted by slot below, stably, so that each
        // cell lists its triangles in ascending order.
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        // A cell of a block reaches the triangle's plane only if the block's centre is within
        // the cells' reach plus the distance from it to the farthest cell centre
        // ((BLOCK_CELLS - 1) / 2 cells on each axis); the cells of a block that passes are
        // tested one by one.
        let block_extra_reach = 0.5 * (BLOCK_CELLS - 1) as f32 * 3f32.sqrt() * cell_m * 1.001;
        for (t, corners) in triangles.enumerate() {
            let t = t as u32;
            let reach = TriangleReach::new(corners, cell_m);
            let (lo, hi) = (reach.lo, reach.hi);
            if reach.box_cells() <= MAX_WALKED_CELLS {
                for z in lo.z..=hi.z {
                    for y in lo.y..=hi.y {
                        for x in lo.x..=hi.x {
                            let cell = IVec3::new(x, y, z);
                            if let Some(&slot) = self.index.get(&cell) {
                                if reach.near_plane(centre_of(cell, cell_m), 0.0) {
                                    pairs.push((slot, t));
                                }
                            }
                        }
                    }
                }
            } else {
                for block in &self.blocks {
                    let last_cell = block.first_cell + (BLOCK_CELLS - 1);
                    if block.first_cell.cmpgt(hi).any() || last_cell.cmplt(lo).any() {
                        continue;
                    }
                    let centre = (block.first_cell.as_vec3() + 0.5 * BLOCK_CELLS as f32) * cell_m;
                    if !reach.near_plane(centre, block_extra_reach) {
                        continue;
                    }
                    for &slot in &self.block_slots[block.from as usize..block.to as usize] {
                        if reach.reaches(self.occupied[slot as usize], cell_m) {
                            pairs.push((slot, t));
                        }
                    }
                }
            }
        }
        let mut start = vec![0u32; self.occupied.len() + 1];
        for &(slot, _) in &pairs {
            start[slot as usize + 1] += 1;
        }
        for s in 1..start.len() {
            start[s] += start[s - 1];
        }
        let mut next = start.clone();
        let mut listed = vec![0u32; pairs.len()];
        for &(slot, t) in &pairs {
            listed[next[slot as usize] as usize] = t;
            next[slot as usize] += 1;
        }
        CellLists {
            start,
            triangles: listed,
        }
    }

    /// The triangles of `lists` that can be within `cell_m` of `p` (a superset of them),
    /// ascending.
    #[cfg(test)]
    pub(crate) fn near<'l>(&self, lists: &'l CellLists, p: Vec3) -> &'l [u32] {
        let cell = floor_ivec3(p / self.cell_m);
        self.index
            .get(&cell)
            .map_or(&[], |&slot| lists.of_slot(slot))
    }

    /// As [`PointCells::near`] for the `i`-th of the points the cells were made from, without
    /// finding its cell again.
    pub(crate) fn near_point<'l>(&self, lists: &'l CellLists, i: usize) -> &'l [u32] {
        match self.slot_of_point.get(i) {
            Some(&slot) if slot != NO_CELL => lists.of_slot(slot),
            _ => &[],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::point_triangle::TriangleQuery;

    /// A small deterministic generator of numbers in [0, 1] (xorshift): the tests need
    /// spread, not statistics.
    fn numbers_from(seed: u32) -> impl FnMut() -> f32 {
        let mut state = seed;
        move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        }
    }

    /// Large triangles find the same cells through the blocks as [`TriangleReach::reaches`]
    /// asked of every occupied cell, which is what [`PointCells::bucket`] did before it had
    /// blocks.
    #[test]
    fn blocks_list_the_same_cells_as_a_test_of_every_cell() {
        let mut next = numbers_from(0x9e37_79b9);
        for offset in [Vec3::ZERO, Vec3::new(-250.0, 80.0, 40.0)] {
            let mut random_point = |scale: f32| Vec3::new(next(), next(), next()) * scale;
            // Points on and around a sphere's shell, as a simplifier's held points are.
            let points: Vec<Vec3> = (0..4000)
                .map(|_| {
                    let p = random_point(2.0) - 1.0;
                    offset + p.normalize_or_zero() * (0.5 + 0.02 * (random_point(1.0).x - 0.5))
                })
                .collect();
            let triangles: Vec<[Vec3; 3]> = (0..40)
                .map(|_| {
                    let a = offset + random_point(1.2) - 0.6;
                    [
                        a,
                        a + random_point(0.7) - 0.35,
                        a + random_point(0.7) - 0.35,
                    ]
                })
                .collect();
            let cell_m = 0.025;
            let cells = PointCells::new(points.iter().copied(), cell_m);
            assert!(cells.blocks.len() > 20, "{} blocks", cells.blocks.len());
            let lists = cells.bucket(triangles.iter().copied());
            let mut listed = 0;
            for (slot, &cell) in cells.occupied.iter().enumerate() {
                let expected: Vec<u32> = triangles
                    .iter()
                    .enumerate()
                    .filter(|(_, &corners)| {
                        TriangleReach::new(corners, cell_m).reaches(cell, cell_m)
                    })
                    .map(|(t, _)| t as u32)
                    .collect();
                assert_eq!(
                    lists.of_slot(slot as u32),
                    expected.as_slice(),
                    "cell {cell}"
                );
                listed += expected.len();
            }
            assert!(listed > 500, "the test must list many pairs: {listed}");
        }
    }

    /// Every triangle within `cell_m` of a point is listed in its cell, for triangles small
    /// (their box walked), middling and large (tested through the blocks) against the
    /// cell, near the origin and 100 m from it.
    #[test]
    fn a_cell_lists_every_triangle_within_reach() {
        for offset in [Vec3::ZERO, Vec3::new(100.0, -60.0, 30.0)] {
            let mut next = numbers_from(0x2545_f491);
            let mut random_point = |scale: f32| Vec3::new(next(), next(), next()) * scale;
            let triangles: Vec<[Vec3; 3]> = (0..90)
                .map(|i| {
                    let size = [2.0, 0.05, 0.004][i % 3];
                    let a = offset + random_point(1.0);
                    [a, a + random_point(size), a + random_point(size)]
                })
                .collect();
            // Half spread through the volume, half next to a triangle's corner.
            let points: Vec<Vec3> = (0..600)
                .map(|i| {
                    if i % 2 == 0 {
                        offset + random_point(1.2) - 0.1
                    } else {
                        triangles[(i / 2) % triangles.len()][0] + random_point(0.06) - 0.03
                    }
                })
                .collect();
            let cell_m = 0.03;
            let cells = PointCells::new(points.iter().copied(), cell_m);
            let lists = cells.bucket(triangles.iter().copied());
            let mut within = [0; 3];
            for (i, &p) in points.iter().enumerate() {
                let near = cells.near_point(&lists, i);
                assert_eq!(near, cells.near(&lists, p));
                assert!(near.windows(2).all(|w| w[0] < w[1]), "ascending: {near:?}");
                for (t, [a, b, c]) in triangles.iter().enumerate() {
                    let d = TriangleQuery::new(*a, *b, *c).distance_sq(p).sqrt();
                    if d <= cell_m {
                        within[t % 3] += 1;
                        assert!(near.contains(&(t as u32)), "triangle {t} at {d} m of {p}");
                    }
                }
            }
            assert!(
                within.iter().all(|&n| n > 3),
                "the test must exercise every kind of triangle: {within:?} pairs within reach"
            );
        }
    }
}
