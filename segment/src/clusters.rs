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
/// at most `tolerance_m`, keeps those with `min_points..=max_points` points, and returns them
/// largest first (ties: lowest first index first), each ascending.
///
/// `weights[i]`, if `weights` is not empty, is how many input points point `i` stands for (a
/// voxel cell's centroid stands for the points of its cell); sizes are sums of weights.
pub(crate) fn euclidean_clusters(
    points: &[Vec3],
    candidates: &[u32],
    weights: &[u32],
    tolerance_m: f32,
    min_points: usize,
    max_points: usize,
) -> Vec<Vec<u32>> {
    if candidates.is_empty() || tolerance_m <= 0.0 || !tolerance_m.is_finite() {
        return Vec::new();
    }
    let grid = VoxelGrid::new(points, candidates, tolerance_m);
    // Position of each candidate in `candidates`, to index the forest.
    let mut slot = vec![u32::MAX; points.len()];
    for (k, &i) in candidates.iter().enumerate() {
        slot[i as usize] = k as u32;
    }
    let tolerance_sq = tolerance_m * tolerance_m;
    // Sequential: each neighbour pair is a union of two (usually already joined) sets, which
    // costs less than collecting the millions of pairs a dense scan has for a parallel pass.
    let mut sets = UnionFind::new(candidates.len());
    for (a, &i) in candidates.iter().enumerate() {
        let p = points[i as usize];
        grid.for_each_near(p, |j| {
            if j > i && p.distance_squared(points[j as usize]) <= tolerance_sq {
                sets.union(a as u32, slot[j as usize]);
            }
        });
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

    #[test]
    fn clusters_join_chains_and_split_at_gaps() {
        // Two chains of points 1 cm apart, separated by a 5 cm gap, tolerance 2 cm.
        let mut points: Vec<Vec3> = (0..10)
            .map(|k| Vec3::new(k as f32 * 0.01, 0.0, 0.0))
            .collect();
        points.extend((0..5).map(|k| Vec3::new(0.14 + k as f32 * 0.01, 0.0, 0.0)));
        let all: Vec<u32> = (0..points.len() as u32).collect();
        let clusters = euclidean_clusters(&points, &all, &[], 0.02, 1, usize::MAX);
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
            euclidean_clusters(&points, &all, &[], 0.02, 1, usize::MAX).len(),
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
        let clusters = euclidean_clusters(&points, &all, &[], 0.02, 5, 20);
        assert_eq!(clusters, vec![(53..63).collect::<Vec<u32>>()]);
    }
}
