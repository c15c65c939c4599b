//! Segmentation of simulated depth frames (`tacmesh_sim::SimulatedDepthCamera::tabletop`: a
//! table and three 0.2 m objects seen from 1.2 m at 45°, RealSense-like noise, dropouts and
//! flying pixels) against the renderer's ground truth, with the daemon's settings.

mod util;

use glam::Vec3;
use tacmesh_segment::{segment, segment_with_hints, SegmentConfig};

use util::{best_ious, tabletop_frame};

#[test]
fn live_segmentation_finds_table_and_three_objects() {
    let frame = tabletop_frame(7, 0);
    let config = SegmentConfig::live().seen_from(frame.world_from_sensor);
    let seg = segment(&frame.points_in_world, &config);
    assert_eq!(seg.planes.len(), 1);
    let table = &seg.planes[0];
    // The table top is z = 0 facing +Z.
    assert!(table.normal.dot(Vec3::Z) > 0.999, "{:?}", table.normal);
    assert!(table.offset_m.abs() < 0.003, "{}", table.offset_m);
    let ious = best_ious(&frame.truth, &[1, 2, 3], &seg);
    eprintln!(
        "simulated tabletop: {} points, objects {:?}, IoU {ious:?}",
        frame.points_in_world.len(),
        seg.objects.iter().map(Vec::len).collect::<Vec<_>>()
    );
    assert_eq!(seg.objects.len(), 3);
    for (id, iou) in ious {
        assert!(iou >= 0.9, "object {id}: IoU {iou:.3}");
    }

    // The next frame (new noise) with this frame's plane as a hint: the same table, without
    // a RANSAC search, and the same objects.
    let next = tabletop_frame(7, 1);
    let seg_next = segment_with_hints(&next.points_in_world, &config, &seg.planes);
    assert_eq!(seg_next.planes.len(), 1);
    assert!(seg_next.planes[0].normal.dot(table.normal) > 0.9999);
    assert!((seg_next.planes[0].offset_m - table.offset_m).abs() < 0.001);
    let ious = best_ious(&next.truth, &[1, 2, 3], &seg_next);
    eprintln!("simulated tabletop, next frame with hints: IoU {ious:?}");
    assert_eq!(seg_next.objects.len(), 3);
    for (id, iou) in ious {
        assert!(iou >= 0.9, "object {id}: IoU {iou:.3} (with hints)");
    }
}

#[test]
fn stale_hint_falls_back_to_ransac() {
    let frame = tabletop_frame(3, 0);
    let config = SegmentConfig::live().seen_from(frame.world_from_sensor);
    let fresh = segment(&frame.points_in_world, &config);
    // A wall far from everything: holds no points, so RANSAC finds the table again.
    let mut stale = fresh.planes[0].clone();
    stale.normal = Vec3::X;
    stale.offset_m = 5.0;
    let hinted = segment_with_hints(&frame.points_in_world, &config, &[stale]);
    assert_eq!(hinted.planes.len(), 1);
    assert!(hinted.planes[0].normal.dot(Vec3::Z) > 0.999);
    assert_eq!(hinted.objects.len(), fresh.objects.len());
}
