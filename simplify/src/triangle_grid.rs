//! Triangles bucketed in a uniform grid, for "which triangles can be within `cell_m` of this
//! point" on small meshes: the fit's nearest-triangle search and the second pass's assignment
//! of extra support points.

use glam::{I64Vec3, IVec3, Vec3};
use rustc_hash::FxHashMap;

/// Triangles bucketed in a uniform grid of `cell_m` cubes: each triangle goes in every cell
/// that its bounding box grown by `cell_m` touches and that holds a query point, so a point's
/// cell lists every triangle within `cell_m` of it (in ascending triangle order). The meshes
/// it serves are small (tens to hundreds of triangles), so a flat grid is all the acceleration
/// they need.
///
/// Only cells with query points are filled, and each triangle walks its own cells or the
/// occupied ones, whichever are fewer: a triangle much larger than `cell_m` (a flat face of a
/// large object under a tight residual) spans millions of cells, nearly all empty, and filling
/// them all took over a minute and hundreds of megabytes (found by fuzzing, see
/// `fuzz/README.md`).
pub(crate) struct TriangleGrid {
    cell_m: f32,
    pub(crate) cells: FxHashMap<IVec3, Vec<u32>>,
}

impl TriangleGrid {
    /// `triangles` gives the corners of each triangle in order; `points` are where
    /// [`TriangleGrid::near`] will be asked (non-finite ones are skipped). `cell_m` must be
    /// positive.
    pub(crate) fn new(
        triangles: impl Iterator<Item = [Vec3; 3]>,
        points: impl Iterator<Item = Vec3>,
        cell_m: f32,
    ) -> Self {
        let cell_of = |p: Vec3| (p / cell_m).floor().as_ivec3();
        let mut cells: FxHashMap<IVec3, Vec<u32>> = points
            .filter(|p| p.is_finite())
            .map(|p| (cell_of(p), Vec::new()))
            .collect();
        let occupied: Vec<IVec3> = cells.keys().copied().collect();
        for (t, [a, b, c]) in triangles.enumerate() {
            let lo = cell_of(a.min(b).min(c) - cell_m);
            let hi = cell_of(a.max(b).max(c) + cell_m);
            let span = (hi.as_i64vec3() - lo.as_i64vec3() + 1).max(I64Vec3::ZERO);
            let box_cells = span.x.saturating_mul(span.y).saturating_mul(span.z);
            if box_cells <= occupied.len() as i64 {
                for z in lo.z..=hi.z {
                    for y in lo.y..=hi.y {
                        for x in lo.x..=hi.x {
                            if let Some(triangles) = cells.get_mut(&IVec3::new(x, y, z)) {
                                triangles.push(t as u32);
                            }
                        }
                    }
                }
            } else {
                for cell in &occupied {
                    if cell.cmpge(lo).all() && cell.cmple(hi).all() {
                        if let Some(triangles) = cells.get_mut(cell) {
                            triangles.push(t as u32);
                        }
                    }
                }
            }
        }
        Self { cell_m, cells }
    }

    /// The triangles that can be within `cell_m` of `p` (a superset of them), ascending.
    pub(crate) fn near(&self, p: Vec3) -> &[u32] {
        let cell = (p / self.cell_m).floor().as_ivec3();
        self.cells.get(&cell).map_or(&[], |v| v.as_slice())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::point_triangle::TriangleQuery;

    /// Every triangle within `cell_m` of a point is listed in its cell, for triangles small and
    /// large against the cell (the large ones take the occupied-cells path).
    #[test]
    fn a_cell_lists_every_triangle_within_reach() {
        // A small deterministic generator: the test needs spread, not statistics.
        let mut state = 0x2545_f491_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        let mut random_point = |scale: f32| Vec3::new(next(), next(), next()) * scale;
        let triangles: Vec<[Vec3; 3]> = (0..60)
            .map(|i| {
                let size = if i % 3 == 0 { 2.0 } else { 0.05 };
                let a = random_point(1.0);
                [a, a + random_point(size), a + random_point(size)]
            })
            .collect();
        let points: Vec<Vec3> = (0..400).map(|_| random_point(1.2) - 0.1).collect();
        let cell_m = 0.03;
        let grid = TriangleGrid::new(triangles.iter().copied(), points.iter().copied(), cell_m);
        let mut within = 0;
        for &p in &points {
            let near = grid.near(p);
            assert!(near.windows(2).all(|w| w[0] < w[1]), "ascending: {near:?}");
            for (t, [a, b, c]) in triangles.iter().enumerate() {
                let d = TriangleQuery::new(*a, *b, *c).distance_sq(p).sqrt();
                if d <= cell_m {
                    within += 1;
                    assert!(near.contains(&(t as u32)), "triangle {t} at {d} m of {p}");
                }
            }
        }
        assert!(
            within > 20,
            "the test must exercise the grid: {within} pairs within reach"
        );
    }
}
