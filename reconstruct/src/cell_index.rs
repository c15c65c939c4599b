//! Where each voxel of a fixed list is: cell → its position in the list; and [`CellBox`], the
//! box a compact list of voxels spans, for dense arrays over it (this index, and the counting
//! sort of `moment_grid`).
//!
//! The plane fits read 27, 8 and 1 neighbouring voxels per voxel, and with a hash map those
//! look-ups were most of their time. An object's voxels fill a compact box (a 1 m object's
//! surface fills about a fifth of its coarse voxels' bounding box), so a dense array over the box
//! answers each look-up with one read; a list spread far apart (a scene with distant outliers)
//! falls back to a hash map. Written here rather than taken from a crate because it is one array
//! with a bounds check, shaped to the voxel keys.

use glam::{I64Vec3, IVec3};
use rustc_hash::FxHashMap;

use crate::moments::PointMoments;

const NONE: u32 = u32::MAX;

/// The steps to the six voxels that share a face with a voxel, in the order the callers walk
/// them (orientation's spanning tree pushes its edges in this order, so it decides ties).
pub(crate) const FACE_STEPS: [IVec3; 6] = [
    IVec3::X,
    IVec3::NEG_X,
    IVec3::Y,
    IVec3::NEG_Y,
    IVec3::Z,
    IVec3::NEG_Z,
];

/// The cell of step `step` (a positive number of cells) that holds `cell`:
/// `cell.div_euclid(step)` per axis. The steps the pipeline uses (1 to 4) are matched to
/// constants, which the compiler turns into shifts and multiplications: with the step known
/// only at run time, `IVec3::div_euclid` is three integer divisions. The signed distance
/// divides each plane's cell by its corner step four times (1.4 % of the one-core pipeline on
/// the cube), and the coarse grid each fine voxel's cell by its factor, 2.
#[inline(always)]
pub(crate) fn floor_div(cell: IVec3, step: i32) -> IVec3 {
    match step {
        1 => cell,
        2 => cell >> 1,
        3 => floor_div_by::<3>(cell),
        4 => cell >> 2,
        _ => cell.div_euclid(IVec3::splat(step)),
    }
}

/// `cell.div_euclid(D)` per axis, with `D` a constant.
#[inline(always)]
fn floor_div_by<const D: i32>(cell: IVec3) -> IVec3 {
    IVec3::new(
        cell.x.div_euclid(D),
        cell.y.div_euclid(D),
        cell.z.div_euclid(D),
    )
}

/// The index's dense array may hold at most this many entries per listed voxel (4 bytes each).
const MAX_BOX_CELLS_PER_CELL: i64 = 64;
/// A dense array over a [`CellBox`] may have this many cells whatever the list's length...
const MIN_DENSE_CELLS: i64 = 1 << 12;
/// ...and never more than this (64 MiB of 4-byte entries).
const MAX_DENSE_CELLS: i64 = 1 << 24;

/// The box of voxels a list spans, addressed as a dense array in (z, y, x) order.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CellBox {
    min: I64Vec3,
    dims: I64Vec3,
}

impl CellBox {
    /// The box around `cells` (`count` of them) when a dense array over it has at most
    /// `max_cells_per_cell` entries per listed cell (or [`MIN_DENSE_CELLS`] for short lists,
    /// never more than [`MAX_DENSE_CELLS`]); `None` for a list spread farther, or empty.
    pub(crate) fn compact_around(
        mut cells: impl Iterator<Item = IVec3>,
        count: usize,
        max_cells_per_cell: i64,
    ) -> Option<Self> {
        let first = cells.next()?;
        let (lo, hi) = cells.fold((first, first), |(lo, hi), c| (lo.min(c), hi.max(c)));
        let (min, dims) = (lo.as_i64vec3(), hi.as_i64vec3() - lo.as_i64vec3() + 1);
        let box_cells = dims.x.saturating_mul(dims.y).saturating_mul(dims.z);
        let limit = max_cells_per_cell
            .saturating_mul(count as i64)
            .clamp(MIN_DENSE_CELLS, MAX_DENSE_CELLS);
        (box_cells <= limit).then_some(Self { min, dims })
    }

    /// The box with `by` more cells on every side.
    fn grown(self, by: i64) -> Self {
        Self {
            min: self.min - by,
            dims: self.dims + 2 * by,
        }
    }

    /// Cells in the box.
    pub(crate) fn len(&self) -> usize {
        (self.dims.x * self.dims.y * self.dims.z) as usize
    }

    /// The array position of `cell`, which must lie in the box.
    #[inline]
    pub(crate) fn slot_inside(&self, cell: IVec3) -> usize {
        let d = cell.as_i64vec3() - self.min;
        (d.x + self.dims.x * (d.y + self.dims.y * d.z)) as usize
    }

    /// The array position of `cell`, if it lies in the box.
    #[inline]
    pub(crate) fn slot(&self, cell: IVec3) -> Option<usize> {
        let d = cell.as_i64vec3() - self.min;
        if d.cmplt(I64Vec3::ZERO).any() || d.cmpge(self.dims).any() {
            return None;
        }
        Some((d.x + self.dims.x * (d.y + self.dims.y * d.z)) as usize)
    }
}

/// Cell → index into the list the index was made from.
#[derive(Debug, Clone)]
pub struct CellIndex {
    lookup: Lookup,
}

#[derive(Debug, Clone)]
enum Lookup {
    /// `slots[cells.slot(cell)]` for each cell in the box, which reaches one cell beyond the
    /// listed cells on every side: the boxes of neighbours that the fits read around a listed
    /// cell lie inside it, and are read by stepping through the array (see
    /// [`CellIndex::moments_in_box`]).
    Dense {
        cells: CellBox,
        slots: Vec<u32>,
    },
    Sparse(FxHashMap<IVec3, u32>),
}

impl CellIndex {
    /// Indexes `cells` (distinct; a repeated cell finds its last position).
    pub fn new(cells: &[IVec3]) -> Self {
        let compact =
            CellBox::compact_around(cells.iter().copied(), cells.len(), MAX_BOX_CELLS_PER_CELL);
        let lookup = if let Some(cell_box) = compact {
            let cell_box = cell_box.grown(1);
            let mut slots = vec![NONE; cell_box.len()];
            for (i, &cell) in cells.iter().enumerate() {
                slots[cell_box.slot_inside(cell)] = i as u32;
            }
            Lookup::Dense {
                cells: cell_box,
                slots,
            }
        } else {
            Lookup::Sparse(
                cells
                    .iter()
                    .enumerate()
                    .map(|(i, &c)| (c, i as u32))
                    .collect(),
            )
        };
        Self { lookup }
    }

    /// The sum of `moments` (one per listed cell, in the list's order) over the listed cells
    /// of the 3 × 3 × 3 box around `cell`, added in (z, y, x) order as
    /// [`crate::moment_grid::MomentGrid::neighbourhood`] adds them: the same sum to the bit.
    pub fn moments_around(&self, moments: &[PointMoments], cell: IVec3) -> PointMoments {
        self.moments_in_box::<3>(moments, cell - IVec3::ONE)
    }

    /// The sum of `moments` over the listed cells of the `N` × `N` × `N` box whose lowest
    /// cell is `first`, added in (z, y, x) order.
    pub fn moments_in_box<const N: i32>(
        &self,
        moments: &[PointMoments],
        first: IVec3,
    ) -> PointMoments {
        let mut sum = PointMoments::default();
        self.for_each_in_box::<N>(first, |slot| sum += &moments[slot as usize]);
        sum
    }

    /// Calls `visit` with the list position of each listed cell of the `N` × `N` × `N` box
    /// whose lowest cell is `first`, in (z, y, x) order.
    ///
    /// A box inside the dense array (any box reaching at most one cell beyond the listed ones)
    /// is read by stepping through the array from its first cell: looking each cell up with
    /// its own bounds checks was most of the time the plane fits spent on their 27 and 8
    /// neighbours (5 % of meshing a 1 m cube on one core).
    #[inline]
    pub fn for_each_in_box<const N: i32>(&self, first: IVec3, mut visit: impl FnMut(u32)) {
        if let Lookup::Dense { cells, slots } = &self.lookup {
            let inside = cells
                .slot(first)
                .zip(cells.slot(first + IVec3::splat(N - 1)));
            if let Some((base, _)) = inside {
                let (row, layer) = (
                    cells.dims.x as usize,
                    (cells.dims.x * cells.dims.y) as usize,
                );
                for dz in 0..N as usize {
                    for dy in 0..N as usize {
                        let start = base + dz * layer + dy * row;
                        for &slot in &slots[start..start + N as usize] {
                            if slot != NONE {
                                visit(slot);
                            }
                        }
                    }
                }
                return;
            }
        }
        for dz in 0..N {
            for dy in 0..N {
                for dx in 0..N {
                    if let Some(slot) = self.get(first + IVec3::new(dx, dy, dz)) {
                        visit(slot);
                    }
                }
            }
        }
    }

    /// [`Self::moments_in_box`] for every box of `firsts` (their lowest cells), each distinct
    /// box summed once: `sums[box_of[i]]` is the box of `firsts[i]`. Boxes repeat where their
    /// callers' cells share them: the fine plane fits' 2 × 2 × 2 boxes of coarse voxels each
    /// serve up to eight fine voxels (a 1 m cube's 22,300 fine voxels read 6,216 boxes).
    pub fn moments_in_boxes<const N: i32>(
        &self,
        moments: &[PointMoments],
        firsts: &[IVec3],
    ) -> (Vec<u32>, Vec<PointMoments>) {
        let Lookup::Dense { cells, slots } = &self.lookup else {
            // No dense array to mark the boxes summed in: each caller's box is its own.
            let sums = firsts
                .iter()
                .map(|&first| self.moments_in_box::<N>(moments, first))
                .collect();
            return ((0..firsts.len() as u32).collect(), sums);
        };
        let mut sums = Vec::new();
        let mut box_of = Vec::with_capacity(firsts.len());
        let mut summed = vec![NONE; slots.len()];
        for &first in firsts {
            let at = cells.slot(first);
            let index = match at {
                Some(at) if summed[at] != NONE => summed[at],
                _ => {
                    sums.push(self.moments_in_box::<N>(moments, first));
                    let index = (sums.len() - 1) as u32;
                    if let Some(at) = at {
                        summed[at] = index;
                    }
                    index
                }
            };
            box_of.push(index);
        }
        (box_of, sums)
    }

    /// The position of `cell` in the list, if it is there.
    #[inline]
    pub fn get(&self, cell: IVec3) -> Option<u32> {
        match &self.lookup {
            Lookup::Dense { cells, slots } => {
                let slot = slots[cells.slot(cell)?];
                (slot != NONE).then_some(slot)
            }
            Lookup::Sparse(map) => map.get(&cell).copied(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The constant steps and the general one floor as `div_euclid` does, on both sides of
    /// zero.
    #[test]
    fn floor_division_by_the_step_is_div_euclid() {
        for step in 1..=7 {
            for x in -200..=200 {
                let v = IVec3::new(x, -x, x / 3 - 7);
                assert_eq!(
                    floor_div(v, step),
                    v.div_euclid(IVec3::splat(step)),
                    "{v} / {step}"
                );
            }
        }
    }

    #[test]
    fn moments_around_a_cell_are_the_grids_neighbourhood_to_the_bit() {
        use crate::moment_grid::MomentGrid;
        use glam::Vec3;
        let points: Vec<Vec3> = (0..2_000)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                Vec3::new(t.sin(), (1.7 * t).cos(), (0.3 * t).sin() * 0.2) * 0.3
            })
            .collect();
        let mut grid = MomentGrid::new(0.04);
        grid.integrate(&points);
        let cells = grid.sorted_cells();
        let moments: Vec<PointMoments> =
            cells.iter().filter_map(|&c| grid.get(c)).copied().collect();
        let index = CellIndex::new(&cells);
        for &cell in &cells {
            for probe in [cell, cell + IVec3::new(2, 0, -1)] {
                assert_eq!(
                    index.moments_around(&moments, probe),
                    grid.neighbourhood(probe, 1),
                    "{probe}"
                );
            }
            // The 2 × 2 × 2 boxes the fine planes read, from either side of the cell, against
            // the same cells looked up one by one (the path for boxes outside the array).
            for first in [cell - IVec3::ONE, cell, cell + IVec3::new(1, -2, 0)] {
                let mut expected = PointMoments::default();
                for dz in 0..2 {
                    for dy in 0..2 {
                        for dx in 0..2 {
                            if let Some(m) = grid.get(first + IVec3::new(dx, dy, dz)) {
                                expected += m;
                            }
                        }
                    }
                }
                assert_eq!(
                    index.moments_in_box::<2>(&moments, first),
                    expected,
                    "{first}"
                );
            }
        }
    }

    /// Boxes summed once each give every caller the sum it would have summed itself, for
    /// repeated boxes, boxes beyond the dense array, and a sparse index.
    #[test]
    fn shared_boxes_are_each_callers_own_sum() {
        let cells: Vec<IVec3> = (0..300)
            .map(|i| IVec3::new(i % 9 - 4, (i / 9) % 6 - 3, i / 54))
            .collect();
        let moments: Vec<PointMoments> = (0..cells.len())
            .map(|i| {
                let mut m = PointMoments::default();
                m.add_point(glam::Vec3::new(i as f32 * 0.01, 0.3, -(i as f32).sqrt()));
                m
            })
            .collect();
        let mut far_flung = cells.clone();
        far_flung.push(IVec3::new(i32::MAX / 2, 0, 0));
        for listed in [cells.clone(), far_flung] {
            let index = CellIndex::new(&listed);
            let firsts: Vec<IVec3> = cells
                .iter()
                .flat_map(|&c| [c, c - IVec3::ONE, c, c + IVec3::new(5, 0, -7)])
                .collect();
            let (box_of, sums) = index.moments_in_boxes::<2>(&moments, &firsts);
            assert_eq!(box_of.len(), firsts.len());
            for (&first, &b) in firsts.iter().zip(&box_of) {
                assert_eq!(sums[b as usize], index.moments_in_box::<2>(&moments, first));
            }
            // The dense index sums each repeated box once (a sparse one sums every box).
            if matches!(index.lookup, Lookup::Dense { .. }) {
                assert!(sums.len() < firsts.len(), "{} boxes", sums.len());
            }
        }
    }

    /// Compact lists go dense and far-flung ones sparse; both find every listed cell and
    /// nothing else, including cells beyond the box on every side and at the ends of `i32`.
    #[test]
    fn every_listed_cell_is_found_and_no_other() {
        let compact: Vec<IVec3> = (0..200)
            .map(|i| IVec3::new(i % 7 - 3, (i / 7) % 5 - 9, i / 35))
            .collect();
        let mut far_flung = compact.clone();
        far_flung.push(IVec3::new(i32::MAX, 0, i32::MIN));
        for cells in [compact, far_flung] {
            let index = CellIndex::new(&cells);
            let dense = matches!(index.lookup, Lookup::Dense { .. });
            assert_eq!(dense, cells.len() == 200);
            for (i, &cell) in cells.iter().enumerate() {
                assert_eq!(index.get(cell), Some(i as u32));
            }
            for cell in [
                IVec3::new(4, -9, 0),
                IVec3::new(-4, -9, 0),
                IVec3::new(0, -10, 0),
                IVec3::new(0, -4, 0),
                IVec3::new(0, -9, -1),
                IVec3::new(0, -9, 6),
                IVec3::splat(i32::MIN),
                IVec3::splat(i32::MAX),
            ] {
                assert_eq!(index.get(cell), None, "{cell}");
            }
        }
        assert_eq!(CellIndex::new(&[]).get(IVec3::ZERO), None);
    }
}
