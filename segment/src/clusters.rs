//! Euclidean clustering: the connected components of the graph joining two points closer than
//! a tolerance (single linkage cut at that distance), as PCL's `EuclideanClusterExtraction`
//! defines them (Rusu, "Semantic 3D object maps for everyday manipulation in human living
//! environments", 2009, §6.2), found on voxel hash grids with cells of the tolerance instead
//! of a k-d tree (the links, `links.rs`). Neighbours are joined in a union–find forest
//! (Tarjan, "Efficiency of a good but not linear set union algorithm", JACM 1975), so the
//! result does not depend on point order.
//!
//! Stages in order: links (`links.rs`) → `DisjointSets` (`sets.rs`) → `components`; the entry points are
//! [`euclidean_clusters`] (searching the links) and [`clusters_of_links`] (links found
//! beforehand).

use glam::Vec3;

use crate::links::{for_each_link, Links};
use crate::range::RangeDistance;
use crate::sets::DisjointSets;

/// Clusters `candidates` (ascending indices of finite points) into groups chained by steps of
/// at most `tolerance` (at the farther point's range; see `links.rs`), keeps those with
/// `min_points..=max_points` points, and returns them largest first (ties: lowest first index
/// first), each ascending.
///
/// `weights[i]`, if `weights` is not empty, is how many input points point `i` stands for (a
/// voxel cell's centroid stands for the points of its cell); sizes are sums of weights.
pub(crate) fn euclidean_clusters(
    points: &[Vec3],
    candidates: &[u32],
    weights: &[u32],
    tolerance: &RangeDistance,
    min_points: usize,
    max_points: usize,
) -> Vec<Vec<u32>> {
    if candidates.is_empty() || !links_at_all(tolerance) {
        return Vec::new();
    }
    // Sequential: each link is a union of two (usually already joined) sets, which costs less
    // than collecting the millions of links a dense scan has for a parallel pass.
    let mut sets = DisjointSets::singletons(candidates.len());
    for_each_link(points, candidates, tolerance, |a, b| {
        sets.union(a, b);
    });
    components(&mut sets, candidates, weights, min_points, max_points)
}

/// Whether `tolerance` links anything: a zero, negative or non-finite base leaves every point
/// alone, and no cluster is an object.
pub(crate) fn links_at_all(tolerance: &RangeDistance) -> bool {
    tolerance.base_m > 0.0 && tolerance.base_m.is_finite()
}

/// [`euclidean_clusters`] of `candidates` from the links of every one of the `points`
/// (`links.of(i)` lists the points linked to point `i`): the same clusters, as the links
/// among the candidates are the links of all points between two candidates.
pub(crate) fn clusters_of_links(
    points: usize,
    candidates: &[u32],
    links: &Links,
    weights: &[u32],
    min_points: usize,
    max_points: usize,
) -> Vec<Vec<u32>> {
    let mut slot = vec![u32::MAX; points];
    for (k, &i) in candidates.iter().enumerate() {
        slot[i as usize] = k as u32;
    }
    let mut sets = DisjointSets::singletons(candidates.len());
    for (a, &i) in candidates.iter().enumerate() {
        for &j in links.of(i as usize) {
            if j > i && slot[j as usize] != u32::MAX {
                sets.union(a as u32, slot[j as usize]);
            }
        }
    }
    components(&mut sets, candidates, weights, min_points, max_points)
}

/// The sets of `candidates` (by position) as point lists in ascending order, those weighing
/// `min_points..=max_points`, largest first (ties: lowest first index first).
fn components(
    sets: &mut DisjointSets,
    candidates: &[u32],
    weights: &[u32],
    min_points: usize,
    max_points: usize,
) -> Vec<Vec<u32>> {
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
