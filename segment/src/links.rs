//! The links of Euclidean clustering: the pairs of points closer than a distance that grows
//! with range ([`RangeDistance`]), at the farther point's range, found on one voxel hash grid
//! per range band.
//!
//! Band 0 holds the points whose distance is the base one, band `k` those whose distance is up
//! to `2^k` times it, each on a grid with cells of its largest distance. A point looks for
//! neighbours in its own band's grid and in the next farther band's, whose cells are large
//! enough for any pair across the two. Bands two apart are never linked: a band is far deeper
//! than a distance (band 1 of the live settings spans 1.7–2.4 m for distances of 15–30 mm),
//! which holds to tens of metres.
//!
//! The search goes cell by cell of each band's grid: the points of a cell share the 27 cells
//! around it, gathered once for all of them.
//!
//! Entry points: [`for_each_link`] streams the pairs (Euclidean clustering of points, where
//! they are too many to keep); [`Links::new`] keeps them as adjacency lists (on voxel cells,
//! where clustering, creases joining their objects and the convexity split all walk them).

use glam::Vec3;

use crate::grid::VoxelGrid;
use crate::range::{RangeDistance, MAX_BAND};

/// Calls `visit(a, b)` once for each linked pair of `indices` (ascending indices of finite
/// points), with `a` and `b` their positions in `indices`: pairs within `reach` of each other
/// at the farther point's range (within a band, at either point's, whichever is larger).
pub(crate) fn for_each_link(
    points: &[Vec3],
    indices: &[u32],
    reach: &RangeDistance,
    mut visit: impl FnMut(u32, u32),
) {
    let base_m = reach.base_m;
    if indices.is_empty() || base_m <= 0.0 || !base_m.is_finite() {
        return;
    }
    let bands: Vec<u8> = indices
        .iter()
        .map(|&i| reach.band(points[i as usize]) as u8)
        .collect();
    let band_count = bands.iter().copied().max().map_or(1, |b| b as usize + 1);
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); band_count];
    for (&i, &b) in indices.iter().zip(&bands) {
        members[b as usize].push(i);
    }
    let grids: Vec<Option<VoxelGrid>> = members
        .iter()
        .enumerate()
        .map(|(k, m)| {
            (!m.is_empty()).then(|| VoxelGrid::new(points, m, base_m * (1u32 << k) as f32))
        })
        .collect();
    // Position of each point in `indices`.
    let mut slot = vec![u32::MAX; points.len()];
    for (k, &i) in indices.iter().enumerate() {
        slot[i as usize] = k as u32;
    }
    let fixed_sq = base_m * base_m;
    let mut around: Vec<u32> = Vec::new();
    // The farther band's cells around the last point's cell there, and that cell's key.
    let mut farther_around: Vec<u32> = Vec::new();
    let mut farther_key = None;
    for (band, grid) in grids.iter().enumerate() {
        let Some(grid) = grid else { continue };
        let farther = grids.get(band + 1).and_then(Option::as_ref);
        // A point of the farther band is at least `band_start_m` away and reaches at most
        // 2^(band + 1) base distances (but the last band, which has no bound): points nearer
        // than that by more than the reach (and a margin well above rounding) have no link
        // there and do not search it.
        let farther_reach_m = base_m * (1u32 << (band + 1)) as f32;
        let search_farther_from_m = if band + 1 < MAX_BAND {
            let start_m = reach.band_start_m(band + 1);
            start_m - farther_reach_m - (1e-3 * start_m + 1e-4)
        } else {
            0.0
        };
        let neighbourhoods = grid.neighbourhoods();
        for c in 0..grid.cell_count() {
            around.clear();
            for &id in neighbourhoods.of(c) {
                around.extend_from_slice(grid.cell(id as usize).0);
            }
            for &i in grid.cell(c).0 {
                let p = points[i as usize];
                let a = slot[i as usize];
                let own_sq = if band == 0 {
                    fixed_sq
                } else {
                    reach.at(p).powi(2)
                };
                for &j in &around {
                    if j > i {
                        let q = points[j as usize];
                        let reach_sq = if band == 0 {
                            fixed_sq
                        } else {
                            own_sq.max(reach.at(q).powi(2))
                        };
                        if p.distance_squared(q) <= reach_sq {
                            visit(a, slot[j as usize]);
                        }
                    }
                }
                let Some(farther) = farther else { continue };
                if p.distance(reach.viewpoint) < search_farther_from_m {
                    continue;
                }
                let key = farther.key_of(p);
                if farther_key != Some((band, key)) {
                    farther_key = Some((band, key));
                    farther_around.clear();
                    farther.around_key(key, |id| {
                        farther_around.extend_from_slice(farther.cell(id as usize).0)
                    });
                }
                for &j in &farther_around {
                    let q = points[j as usize];
                    if p.distance_squared(q) <= reach.at(q).powi(2) {
                        visit(a, slot[j as usize]);
                    }
                }
            }
        }
    }
}

/// The links of a set of points as adjacency lists: `of(k)` lists the points (indices into
/// `points`, not positions) linked to `indices[k]`, in no particular order.
pub(crate) struct Links {
    start: Vec<u32>,
    neighbours: Vec<u32>,
}

impl Links {
    /// The links of `indices` (ascending indices of finite points) within `reach`, as
    /// [`for_each_link`] finds them.
    pub(crate) fn new(points: &[Vec3], indices: &[u32], reach: &RangeDistance) -> Self {
        // Voxel cells have about ten links each.
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(8 * indices.len());
        for_each_link(points, indices, reach, |a, b| pairs.push((a, b)));
        // Counting sort by position, both ways round.
        let mut start = vec![0u32; indices.len() + 1];
        for &(a, b) in &pairs {
            start[a as usize + 1] += 1;
            start[b as usize + 1] += 1;
        }
        for k in 0..indices.len() {
            start[k + 1] += start[k];
        }
        let mut fill = start.clone();
        let mut neighbours = vec![0u32; 2 * pairs.len()];
        for &(a, b) in &pairs {
            neighbours[fill[a as usize] as usize] = indices[b as usize];
            fill[a as usize] += 1;
            neighbours[fill[b as usize] as usize] = indices[a as usize];
            fill[b as usize] += 1;
        }
        Self { start, neighbours }
    }

    /// The points linked to the `k`-th point of the `indices` the links were found for.
    pub(crate) fn of(&self, k: usize) -> &[u32] {
        &self.neighbours[self.start[k] as usize..self.start[k + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_are_the_pairs_within_reach_at_the_farther_point() {
        // A line of points along the line of sight from 1 m to 4 m, unevenly spaced: every
        // pair within the farther point's reach is a link, and no other.
        let reach = RangeDistance::new(0.015, 0.0035, 1.5, Vec3::ZERO);
        let mut points = vec![Vec3::NAN];
        let mut z: f32 = 1.0;
        let mut k = 0;
        while z < 4.0 {
            points.push(Vec3::new(0.001 * (k % 3) as f32, 0.0, z));
            z += 0.004 + 0.006 * (k % 5) as f32 + 0.01 * z;
            k += 1;
        }
        let indices: Vec<u32> = (1..points.len() as u32).collect();
        let links = Links::new(&points, &indices, &reach);
        for (a, &i) in indices.iter().enumerate() {
            let expected: Vec<u32> = indices
                .iter()
                .copied()
                .filter(|&j| j != i)
                .filter(|&j| {
                    let (p, q) = (points[i as usize], points[j as usize]);
                    p.distance_squared(q) <= reach.at(p).max(reach.at(q)).powi(2)
                })
                .collect();
            let mut found = links.of(a).to_vec();
            found.sort_unstable();
            assert_eq!(found, expected, "point {i} at {}", points[i as usize]);
        }
    }
}
