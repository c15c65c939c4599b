//! Helpers shared by the integration tests and `benches/live.rs`: simulated depth frames with
//! their ground truth, and the IoU of predicted objects against it.

use std::time::Duration;

use glam::Vec3;
use rustc_hash::FxHashMap;
use tacmesh_segment::Segmentation;
use tacmesh_sim::SimulatedDepthCamera;

/// One frame of the simulated tabletop camera, deprojected into the world frame as the daemon
/// does it.
pub struct SimFrame {
    /// The valid pixels' points in the world frame, row-major.
    pub points_in_world: Vec<Vec3>,
    /// The object each point's pixel sees without noise (0 the table, 1..=3 the objects,
    /// `u32::MAX` nothing).
    pub truth: Vec<u32>,
    /// The sensor's pose in the world frame.
    pub world_from_sensor: glam::Affine3A,
}

/// Frame `frame_index` of `SimulatedDepthCamera::tabletop(seed)`.
pub fn tabletop_frame(seed: u64, frame_index: u64) -> SimFrame {
    let camera = SimulatedDepthCamera::tabletop(seed);
    let frame = camera.render(frame_index, Duration::ZERO);
    let max_range_m = camera.config().max_range_m;
    let ids = camera.render_ids(frame_index);
    let points_in_world = frame.deproject(max_range_m).points_in_world;
    // `deproject` keeps the pixels with a depth in (0, max range], in pixel order.
    let truth: Vec<u32> = frame
        .depth_m
        .iter()
        .zip(&ids)
        .filter(|(&z, _)| z > 0.0 && z <= max_range_m)
        .map(|(_, id)| id.unwrap_or(u32::MAX))
        .collect();
    assert_eq!(truth.len(), points_in_world.len());
    SimFrame {
        points_in_world,
        truth,
        world_from_sensor: frame.world_from_sensor,
    }
}

/// For each ground-truth object id in `ids`, the IoU of its points (`truth[i] == id`) with the
/// best-matching predicted object.
pub fn best_ious(truth: &[u32], ids: &[u32], seg: &Segmentation) -> Vec<(u32, f64)> {
    let mut truth_sizes: FxHashMap<u32, usize> = FxHashMap::default();
    let mut overlaps: FxHashMap<(u32, u32), usize> = FxHashMap::default();
    for (&t, &p) in truth.iter().zip(&seg.labels) {
        if ids.contains(&t) {
            *truth_sizes.entry(t).or_default() += 1;
            if p > 0 {
                *overlaps.entry((t, p)).or_default() += 1;
            }
        }
    }
    ids.iter()
        .map(|&id| {
            let size = truth_sizes.get(&id).copied().unwrap_or(0);
            let best = (1..=seg.objects.len() as u32)
                .map(|p| {
                    let inter = overlaps.get(&(id, p)).copied().unwrap_or(0);
                    let union = size + seg.objects[p as usize - 1].len() - inter;
                    inter as f64 / union as f64
                })
                .fold(0.0, f64::max);
            (id, best)
        })
        .collect()
}
