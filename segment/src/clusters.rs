//! Euclidean clustering: the connected components of the graph joining two points closer than
//! a tolerance (single linkage cut at that distance), as PCL's `EuclideanClusterExtraction`
//! defines them (Rusu, "Semantic 3D object maps for everyday manipulation in human living
//! environments", 2009, §6.2), found on a voxel hash grid with cells of the tolerance instead
//! of a k-d tree: a point's neighbours lie in the 27 cells around its cell. Neighbours are
//! joined in a union–find forest (Tarjan, "Efficiency of a good but not linear set
//! union algorithm", JACM 1975), so the result does not depend on point order.
//!
//! Stages in order: neighbours (on the [`VoxelGrid`]) → `UnionFind` →
//! [`euclidean_clusters`] (the entry point).

use glam::Vec3;

use crate::grid::VoxelGrid;
use crate::range::RangeDistance;

/// Disjoint sets with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grandparent = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grandparent;
            x = grandparent;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a as usize] < self.size[b as usize] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b as usize] = a;
        self.size[a as usize] += self.size[b as usize];
    }
}

/// Clusters `candidates` (ascending indices of finite points) into groups chained by steps of
/// at most `tolerance` (at the farther point's range), keeps those with `min_points..=max_points`
/// points, and returns them largest first (ties: lowest first index first), each ascending.
///
/// `weights[i]`, if `weights` is not empty, is how many input points point `i` stands for (a
/// voxel cell's centroid stands for the points of its cell); sizes are sums of weights.
///
/// A tolerance that grows with range is searched in range bands: band 0 holds the points whose
/// tolerance is the base one, band `k` those whose tolerance is up to `2^k` times it, each on a
/// grid with cells of its largest tolerance. A point looks for neighbours in its own band's
/// grid and in the next farther band's, whose cells are large enough for any pair across the
/// two. Bands two apart are never linked: a band is far deeper than a tolerance (band 1 of the
/// live settings spans 1.7–2.4 m for tolerances of 15–30 mm), which holds to tens of metres.
pub(crate) fn euclidean_clusters(
    points: &[Vec3],
    candidates: &[u32],
    weights: &[u32],
    tolerance: &RangeDistance,
    min_points: usize,
    max_points: usize,
) -> Vec<Vec<u32>> {
    let base_m = tolerance.base_m;
    if candidates.is_empty() || base_m <= 0.0 || !base_m.is_finite() {
        return Vec::new();
    }
    let bands: Vec<u8> = candidates
        .iter()
        .map(|&i| tolerance.band(points[i as usize]) as u8)
        .collect();
    let band_count = bands.iter().copied().max().map_or(1, |b| b as usize + 1);
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); band_count];
    for (&i, &b) in candidates.iter().zip(&bands) {
        members[b as usize].push(i);
    }
    let grids: Vec<Option<VoxelGrid>> = members
        .iter()
        .enumerate()
        .map(|(k, m)| {
            (!m.is_empty()).then(|| VoxelGrid::new(points, m, base_m * (1u32 << k) as f32))
        })
        .collect();
    // Position of each candidate in `candidates`, to index the forest.
    let mut slot = vec![u32::MAX; points.len()];
    for (k, &i) in candidates.iter().enumerate() {
        slot[i as usize] = k as u32;
    }
    let fixed_sq = base_m * base_m;
    // Sequential: each neighbour pair is a union of two (usually already joined) sets, which
    // costs less than collecting the millions of pairs a dense scan has for a parallel pass.
    let mut sets = UnionFind::new(candidates.len());
    for (a, (&i, &band)) in candidates.iter().zip(&bands).enumerate() {
        let p = points[i as usize];
        let band = band as usize;
        if let Some(grid) = &grids[band] {
            let own_sq = if band == 0 {
                fixed_sq
            } else {
                tolerance.at(p).powi(2)
            };
            grid.for_each_near(p, |j| {
                if j > i {
                    let q = points[j as usize];
                    let d2 = p.distance_squared(q);
                    let reach_sq = if band == 0 {
                        fixed_sq
                    } else {
                        own_sq.max(tolerance.at(q).powi(2))
                    };
                    if d2 <= reach_sq {
                        sets.union(a as u32, slot[j as usize]);
                    }
                }
            });
        }
        if let Some(Some(farther)) = grids.get(band + 1) {
            farther.for_each_near(p, |j| {
                let q = points[j as usize];
                if p.distance_squared(q) <= tolerance.at(q).powi(2) {
                    sets.union(a as u32, slot[j as usize]);
                }
            });
        }
    }

    // Components to point lists, in ascending point order.
    let mut cluster_of_root = vec![u32::MAX; candidates.len()];
    let mut clusters: Vec<Vec<u32>> = Vec::new();
    for (k, &i) in candidates.iter().enumerate() {
        let root = sets.find(k as u32) as usize;
        if cluster_of_root[root] == u32::MAX {
            cluster_of_root[root] = clusters.len() as u32;
            clusters.push(Vec::new());
        }
        clusters[cluster_of_root[root] as usize].push(i);
    }
    let size = |c: &[u32]| -> usize {
        if weights.is_empty() {
            c.len()
        } else {
            c.iter().map(|&i| weights[i as usize] as usize).sum()
        }
    };
    let mut sized: Vec<(usize, Vec<u32>)> = clusters
        .into_iter()
        .map(|c| (size(&c), c))
        .filter(|(n, _)| (min_points..=max_points).contains(n))
        .collect();
    sized.sort_by(|a, b| b.0.cmp(&a.0).then(a.1[0].cmp(&b.1[0])));
    sized.into_iter().map(|(_, c)| c).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixed(tolerance_m: f32) -> RangeDistance {
        RangeDistance::new(tolerance_m, 0.0, 1.0, Vec3::ZERO)
    }

    #[test]
    fn far_points_link_across_a_depth_step_near_ones_do_not() {
        // Rows of points 1 cm apart along x, a 4 cm gap along the line of sight between two
        // rows: at 1 m that is a gap between objects, at 4 m one depth step of a Kinect.
        let rows = |z: f32| -> Vec<Vec3> {
            (0..2)
                .flat_map(|r| {
                    (0..20).map(move |k| Vec3::new(k as f32 * 0.01, 0.0, z + r as f32 * 0.04))
                })
                .collect()
        };
        let tolerance = RangeDistance::new(0.015, 0.0035, 1.5, Vec3::ZERO);
        for (z, expected) in [(1.0, 2), (2.0, 2), (4.0, 1)] {
            let points = rows(z);
            let all: Vec<u32> = (0..points.len() as u32).collect();
            let clusters = euclidean_clusters(&points, &all, &[], &tolerance, 1, usize::MAX);
            assert_eq!(clusters.len(), expected, "at {z} m");
        }
        // Across bands: a chain from 1.5 m to 4.5 m, spaced below the tolerance everywhere, is
        // one cluster.
        let mut chain = Vec::new();
        let mut z: f32 = 1.5;
        while z < 4.5 {
            chain.push(Vec3::new(0.0, 0.0, z));
            z += 0.9 * tolerance.at(Vec3::new(0.0, 0.0, z));
        }
        let all: Vec<u32> = (0..chain.len() as u32).collect();
        assert_eq!(
            euclidean_clusters(&chain, &all, &[], &tolerance, 1, usize::MAX).len(),
            1
        );
    }

    #[test]
    fn clusters_join_chains_and_split_at_gaps() {
        // Two chains of points 1 cm apart, separated by a 5 cm gap, tolerance 2 cm.
        let mut points: Vec<Vec3> = (0..10)
            .map(|k| Vec3::new(k as f32 * 0.01, 0.0, 0.0))
            .collect();
        points.extend((0..5).map(|k| Vec3::new(0.14 + k as f32 * 0.01, 0.0, 0.0)));
        let all: Vec<u32> = (0..points.len() as u32).collect();
        let clusters = euclidean_clusters(&points, &all, &[], &fixed(0.02), 1, usize::MAX);
        assert_eq!(
            clusters,
            vec![(0..10).collect::<Vec<u32>>(), (10..15).collect()]
        );
    }

    #[test]
    fn clusters_join_across_two_cells_on_the_diagonal() {
        // Points 1.9 cm apart along a diagonal reach two cells away on each of two axes.
        let step = 0.019 / 2f32.sqrt();
        let points: Vec<Vec3> = (0..20)
            .map(|k| Vec3::new(k as f32 * step, k as f32 * step, 0.0))
            .collect();
        let all: Vec<u32> = (0..points.len() as u32).collect();
        assert_eq!(
            euclidean_clusters(&points, &all, &[], &fixed(0.02), 1, usize::MAX).len(),
            1
        );
    }

    #[test]
    fn clusters_drop_small_and_large() {
        let mut points: Vec<Vec3> = (0..3)
            .map(|k| Vec3::new(k as f32 * 0.01, 0.0, 0.0))
            .collect();
        points.extend((0..50).map(|k| Vec3::new(1.0 + k as f32 * 0.01, 0.0, 0.0)));
        points.extend((0..10).map(|k| Vec3::new(3.0 + k as f32 * 0.01, 0.0, 0.0)));
        let all: Vec<u32> = (0..points.len() as u32).collect();
        let clusters = euclidean_clusters(&points, &all, &[], &fixed(0.02), 5, 20);
        assert_eq!(clusters, vec![(53..63).collect::<Vec<u32>>()]);
    }
}
