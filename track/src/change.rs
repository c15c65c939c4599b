//! How much an object's fused state changed since it was last meshed (its "dirty" measure).
//!
//! A voxel has changed enough when, since the last meshing, it became part of the surface
//! (reached `occupied` points) or, not yet settled, its point count reached
//! `min(2 × count at meshing, saturated)`. Each voxel can therefore change only about
//! `log2(saturated / occupied) + 1` times over its life, so an object watched from a static
//! camera stops changing once its voxels settle and no new ones fill up: re-meshing converges.
//!
//! Voxels that the surface barely clips, or that only the noise's tails reach, fill up so slowly
//! that, left alone, some of them would cross a threshold in every frame for hundreds of
//! frames. Two rules keep them quiet:
//! - a voxel whose 3×3×3 neighbourhood already holds `BOX_SATURATION × saturated` points is
//!   settled, whatever its own count: the planes fitted around it (over boxes of that size,
//!   see `tacmesh_reconstruct::cell_planes`) no longer move when it gains a few points;
//! - voxels are weighed by their point count capped at `saturated`, and the object is
//!   re-meshed when the changed voxels hold a fraction of the total weight, so a sparse voxel
//!   counts for what it adds to the planes, while a newly seen part of the object quickly
//!   gains the weight of the old parts.
//!
//! The cost is two look-ups per fused point, plus a neighbourhood sum (27 look-ups) each time a
//! voxel crosses a threshold, which happens a handful of times in a voxel's life; the memory is
//! one count per voxel, like the grid.

use glam::IVec3;
use rustc_hash::{FxHashMap, FxHashSet};
use tacmesh_reconstruct::moment_grid::MomentGrid;

/// A voxel is settled when its 3×3×3 neighbourhood holds this many times the saturation count:
/// about eight saturated voxels, as many as a surface patch through the box crosses.
const BOX_SATURATION: f64 = 8.0;

/// A voxel whose 3×3×3 neighbourhood holds fewer than this many times the saturation count is
/// isolated: flying pixels at silhouettes and the far tails of the depth noise, which no
/// plane fit leans on. Its changes are not counted (and its count at meshing is not
/// advanced), so they cannot trickle into a re-mesh every few seconds for ever; a genuinely
/// new part of the surface fills its neighbourhood within a few frames and is counted at its
/// next doubling. Measured on the daemon's static demo objects: without this rule, 2–3 % of
/// the weight kept changing every few seconds as flying-pixel voxels filled up.
const ISOLATED_BELOW: f64 = 2.0;

/// Per-voxel counts at the last meshing and the voxels changed since.
#[derive(Debug, Clone, Default)]
pub struct ChangeTracker {
    occupied_points: u32,
    saturated_points: u32,
    /// Point count of each voxel when it last changed enough and was then meshed.
    counts_at_meshing: FxHashMap<IVec3, u32>,
    changed: FxHashSet<IVec3>,
    /// Σ min(count, saturated) over the changed voxels, and over all voxels.
    changed_weight: u64,
    total_weight: u64,
    meshed: bool,
}

impl ChangeTracker {
    pub fn new(occupied_points: u32, saturated_points: u32) -> Self {
        Self {
            occupied_points,
            saturated_points,
            ..Default::default()
        }
    }

    /// Records that `cell` of `grid` now holds `count` points (one more than before). Changes
    /// of isolated voxels (see [`ISOLATED_BELOW`]) are not recorded.
    pub fn note_point(&mut self, grid: &MomentGrid, cell: IVec3, count: u32) {
        let gained = u64::from(count <= self.saturated_points);
        self.total_weight += gained;
        if count < self.occupied_points {
            return;
        }
        if self.changed.contains(&cell) {
            self.changed_weight += gained;
            return;
        }
        let before = self.counts_at_meshing.get(&cell).copied().unwrap_or(0);
        let changed = before < self.occupied_points
            || (before < self.saturated_points && count >= (2 * before).min(self.saturated_points));
        if !changed {
            return;
        }
        let around = grid.neighbourhood(cell, 1).count;
        if around < ISOLATED_BELOW * f64::from(self.saturated_points) {
            return;
        }
        if around >= BOX_SATURATION * f64::from(self.saturated_points) {
            // Settled for good: never look at it again.
            self.counts_at_meshing.insert(cell, self.saturated_points);
        } else {
            self.changed.insert(cell);
            self.changed_weight += u64::from(count.min(self.saturated_points));
        }
    }

    /// Records that `cell` was forgotten (its weight carved away, see `crate::free_space`).
    /// A voxel that was part of the surface at the last meshing is a change of the weight it
    /// had there; one that never was is none. Refilled later, it counts as new.
    pub fn note_removed(&mut self, cell: IVec3) {
        let before = self.counts_at_meshing.remove(&cell).unwrap_or(0);
        let weight = u64::from(before.min(self.saturated_points));
        self.total_weight = self.total_weight.saturating_sub(weight);
        if before >= self.occupied_points && self.changed.insert(cell) {
            self.changed_weight += weight;
        }
    }

    /// Voxels that changed enough since the last meshing.
    pub fn changed_cells(&self) -> usize {
        self.changed.len()
    }

    /// Weight of the changed voxels over the weight of all; 0 for an empty object.
    pub fn changed_fraction(&self) -> f32 {
        if self.total_weight == 0 {
            0.0
        } else {
            (self.changed_weight as f64 / self.total_weight as f64).min(1.0) as f32
        }
    }

    /// Whether the object was meshed since it was created or last reset.
    pub fn meshed(&self) -> bool {
        self.meshed
    }

    /// Marks the current state of `grid` as meshed: remembers the counts of the changed voxels
    /// (the others keep their count at the meshing after their last change, which still
    /// measures how far they have come) and clears the changed set.
    pub fn mark_meshed(&mut self, grid: &MomentGrid) {
        for cell in self.changed.drain() {
            if let Some(m) = grid.get(cell) {
                self.counts_at_meshing.insert(cell, m.count as u32);
            }
        }
        self.changed_weight = 0;
        self.meshed = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn fill(grid: &mut MomentGrid, tracker: &mut ChangeTracker, p: Vec3, n: usize) {
        for _ in 0..n {
            if let Some((cell, m)) = grid.add_point(p) {
                let count = m.count as u32;
                tracker.note_point(grid, cell, count);
            }
        }
    }

    #[test]
    fn voxel_changes_when_occupied_then_on_doubling_until_saturated() {
        let mut grid = MomentGrid::new(1.0);
        let mut tracker = ChangeTracker::new(4, 64);
        // Neighbours enough that the voxel is not isolated, too few to settle it.
        for x in [-0.5, 1.5] {
            for y in [-0.5, 1.5] {
                fill(&mut grid, &mut tracker, Vec3::new(x, y, 0.5), 40);
            }
        }
        tracker.mark_meshed(&grid);
        let p = Vec3::splat(0.5);
        fill(&mut grid, &mut tracker, p, 3);
        assert_eq!(tracker.changed_cells(), 0);
        fill(&mut grid, &mut tracker, p, 1);
        assert_eq!(tracker.changed_cells(), 1);
        tracker.mark_meshed(&grid);
        fill(&mut grid, &mut tracker, p, 3);
        assert_eq!(tracker.changed_cells(), 0, "7 < 2 × 4");
        fill(&mut grid, &mut tracker, p, 1);
        assert_eq!(tracker.changed_cells(), 1);
        tracker.mark_meshed(&grid);
        fill(&mut grid, &mut tracker, p, 40);
        tracker.mark_meshed(&grid);
        // 48 at meshing: changed again only at the saturation count, then never.
        fill(&mut grid, &mut tracker, p, 15);
        assert_eq!(tracker.changed_cells(), 0);
        fill(&mut grid, &mut tracker, p, 1);
        assert_eq!(tracker.changed_cells(), 1);
        tracker.mark_meshed(&grid);
        fill(&mut grid, &mut tracker, p, 1000);
        assert_eq!(tracker.changed_cells(), 0);
        assert_eq!(tracker.changed_fraction(), 0.0);
    }

    #[test]
    fn voxel_beside_a_saturated_patch_is_settled() {
        let mut grid = MomentGrid::new(1.0);
        let mut tracker = ChangeTracker::new(4, 64);
        for i in 0..3 {
            for j in 0..3 {
                fill(
                    &mut grid,
                    &mut tracker,
                    Vec3::new(i as f32 + 0.5, j as f32 + 0.5, 0.5),
                    64,
                );
            }
        }
        tracker.mark_meshed(&grid);
        fill(&mut grid, &mut tracker, Vec3::new(1.5, 1.5, 1.5), 10);
        assert_eq!(tracker.changed_cells(), 0);
    }

    #[test]
    fn sparse_fringe_voxel_weighs_little() {
        let mut grid = MomentGrid::new(1.0);
        let mut tracker = ChangeTracker::new(4, 64);
        for i in 0..40 {
            fill(
                &mut grid,
                &mut tracker,
                Vec3::new(i as f32 + 0.5, 0.5, 0.5),
                64,
            );
        }
        tracker.mark_meshed(&grid);
        // Next to the row: counted, but weighs little.
        fill(&mut grid, &mut tracker, Vec3::new(3.5, 1.5, 0.5), 4);
        assert_eq!(tracker.changed_cells(), 1);
        assert!(
            tracker.changed_fraction() < 0.002,
            "{}",
            tracker.changed_fraction()
        );
    }

    #[test]
    fn a_forgotten_surface_voxel_is_a_change_and_an_unmeshed_one_is_not() {
        let mut grid = MomentGrid::new(1.0);
        let mut tracker = ChangeTracker::new(4, 64);
        // Round after round, so that no voxel fills up while its neighbours are empty.
        for _ in 0..64 {
            for i in 0..10 {
                fill(
                    &mut grid,
                    &mut tracker,
                    Vec3::new(i as f32 + 0.5, 0.5, 0.5),
                    1,
                );
            }
        }
        tracker.mark_meshed(&grid);
        assert_eq!(tracker.changed_cells(), 0);
        tracker.note_removed(IVec3::new(20, 0, 0));
        assert_eq!(tracker.changed_cells(), 0, "never meshed");
        for i in 1..=5 {
            tracker.note_removed(IVec3::new(i, 0, 0));
        }
        assert_eq!(tracker.changed_cells(), 5);
        assert!((tracker.changed_fraction() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn isolated_voxel_never_counts() {
        let mut grid = MomentGrid::new(1.0);
        let mut tracker = ChangeTracker::new(4, 64);
        for i in 0..40 {
            fill(
                &mut grid,
                &mut tracker,
                Vec3::new(i as f32 + 0.5, 0.5, 0.5),
                64,
            );
        }
        tracker.mark_meshed(&grid);
        // A flying-pixel voxel far from the surface, however full it gets.
        fill(&mut grid, &mut tracker, Vec3::new(0.5, 5.5, 0.5), 100);
        assert_eq!(tracker.changed_cells(), 0);
    }
}
