//! Real sensor data from `../shared/data` (see its SOURCES.md) through the CLI.

use crate::util::{path_str, shared_data, tacmesh_json};

/// One Cyberware range scan of the Stanford bunny (bun000, already in the reference frame per
/// bun.conf) meshed with the defaults lies on the zippered reconstruction of all ten scans.
/// Only the candidate-to-reference direction is meaningful: one view covers part of the
/// bunny. The bound, 2 mm on a 14 cm object, is twice what the pipeline reaches (1.0 mm).
#[test]
fn bunny_range_scan_lies_on_the_reference_surface() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mesh = dir.path().join("bunny.ply");
    let scan = shared_data("pointclouds/stanford_bunny/bun000.ply");
    let reference = shared_data("pointclouds/stanford_bunny/bun_zipper_res2.ply");
    let report = tacmesh_json(&["mesh", path_str(&scan), "-o", path_str(&mesh), "--json"]);
    let faces = report["faces"].as_u64().expect("faces");
    assert!((20..400).contains(&faces), "bunny faces {faces}");
    let eval = tacmesh_json(&["eval", path_str(&reference), path_str(&mesh), "--json"]);
    let off_surface = eval["mean_candidate_to_reference"]
        .as_f64()
        .expect("one-sided mean");
    assert!(
        off_surface < 0.002,
        "mesh is {off_surface} m off the reference on average"
    );
}

/// A real segmented Kinect-style scan (PCL's milk carton, binary_compressed PCD) meshes into a
/// small mesh.
#[test]
fn milk_carton_scan_meshes_small() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mesh = dir.path().join("milk.obj");
    let scan = shared_data("pointclouds/pcl/milk.pcd");
    let report = tacmesh_json(&["mesh", path_str(&scan), "-o", path_str(&mesh), "--json"]);
    let faces = report["faces"].as_u64().expect("faces");
    assert!((4..200).contains(&faces), "milk carton faces {faces}");
    assert!(report["recon_faces"].as_u64().expect("recon") > 10 * faces);
}

/// The PCL Kinect grabber's organised cloud was made from its depth image with fx = fy = 525,
/// cx = 320, cy = 240 (SOURCES.md). Taking each valid pixel's z as the depth and deprojecting
/// it must give back that pixel's x and y: the pinhole convention matches PCL's.
#[test]
fn kinect_frame_deprojects_like_pcl() {
    use tacmesh::glam::{Affine3A, Vec3};
    use tacmesh::source::{DepthFrame, Intrinsics};

    let pcd = tacmesh::formats::pcd::read_pcd(&shared_data(
        "depth/pcl_kinect_grabber/frame_20121214T142255.814212.pcd",
    ))
    .expect("the grabber's PCD reads");
    assert_eq!((pcd.width, pcd.height), (640, 480));
    let frame = DepthFrame {
        intrinsics: Intrinsics {
            width: 640,
            height: 480,
            fx: 525.0,
            fy: 525.0,
            cx: 320.0,
            cy: 240.0,
        },
        depth_m: pcd.points.iter().map(|p| p.z).collect(),
        world_from_sensor: Affine3A::IDENTITY,
        capture_time: std::time::Duration::ZERO,
    };
    let deprojected = frame.deproject(10.0);
    let expected: Vec<Vec3> = pcd.points.iter().copied().filter(|p| p.z > 0.0).collect();
    assert_eq!(deprojected.points_in_world.len(), 271_575);
    assert_eq!(deprojected.invalid_pixels, 640 * 480 - 271_575);
    let worst = deprojected
        .points_in_world
        .iter()
        .zip(&expected)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-6,
        "deprojection differs from PCL by up to {worst} m"
    );
}
