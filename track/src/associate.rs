//! Which cluster belongs to which track: greedy nearest pairs by centroid distance.
//!
//! Every (cluster, track) pair within the match distance is ranked by the distance between the
//! cluster's centroid and the track's predicted centroid; pairs are taken nearest first, each
//! cluster and each track at most once. Greedy is optimal when objects are farther apart than
//! they move per frame, which the match distance assumes anyway, and needs no Hungarian solve.
//! Centroids shift as the visible part of an object changes; that is fine here (a few
//! millimetres against a match distance of centimetres) but not for pose, which alignment does.

use glam::Vec3;

/// Pairs `(cluster index, track index)`; `clusters[i]` is `None` for clusters to ignore.
pub fn associate_greedy(
    clusters: &[Option<Vec3>],
    predicted: &[Vec3],
    match_distance_m: f32,
) -> Vec<(usize, usize)> {
    let mut candidates: Vec<(f32, usize, usize)> = Vec::new();
    for (ci, centroid) in clusters.iter().enumerate() {
        let Some(centroid) = centroid else { continue };
        for (ti, p) in predicted.iter().enumerate() {
            let d = centroid.distance(*p);
            if d <= match_distance_m {
                candidates.push((d, ci, ti));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
    let mut cluster_taken = vec![false; clusters.len()];
    let mut track_taken = vec![false; predicted.len()];
    let mut pairs = Vec::new();
    for (_, ci, ti) in candidates {
        if !cluster_taken[ci] && !track_taken[ti] {
            cluster_taken[ci] = true;
            track_taken[ti] = true;
            pairs.push((ci, ti));
        }
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_pair_wins_and_each_side_is_used_once() {
        let clusters = [Some(Vec3::ZERO), Some(Vec3::new(0.03, 0.0, 0.0)), None];
        let predicted = [Vec3::new(0.02, 0.0, 0.0), Vec3::new(5.0, 0.0, 0.0)];
        let pairs = associate_greedy(&clusters, &predicted, 0.08);
        assert_eq!(pairs, vec![(1, 0)]);
    }

    #[test]
    fn nothing_beyond_match_distance() {
        let pairs = associate_greedy(&[Some(Vec3::ZERO)], &[Vec3::X], 0.5);
        assert!(pairs.is_empty());
    }
}
