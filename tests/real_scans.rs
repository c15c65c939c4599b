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
