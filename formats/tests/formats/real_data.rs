//! Counts and ranges of the real sample files, as recorded in `testdata/SOURCES.md`.

use std::collections::BTreeSet;

use tacmesh_formats::{pcd, read_cloud, read_mesh};

use crate::util::data;

#[test]
fn milk_pcd_is_13704_unorganised_points() {
    let pcd = pcd::read_pcd(&data("pointclouds/pcl/milk.pcd")).unwrap();
    assert_eq!((pcd.width, pcd.height), (13704, 1));
    assert_eq!(pcd.points.len(), 13704);
    assert_eq!(pcd.rgba, None);
    let cloud = read_cloud(&data("pointclouds/pcl/milk.pcd")).unwrap();
    assert_eq!(cloud.len(), 13704);
}

#[test]
fn table_scene_mug_is_640x480_with_209280_finite_points_from_0_69_to_2_59_m() {
    let path = &data("pointclouds/pcl/table_scene_mug_stereo_textured.pcd");
    let pcd = pcd::read_pcd(path).unwrap();
    assert_eq!((pcd.width, pcd.height), (640, 480));
    assert_eq!(pcd.points.len(), 307_200);
    assert_eq!(pcd.rgba.as_ref().map(Vec::len), Some(307_200));

    let cloud = read_cloud(path).unwrap();
    assert_eq!(cloud.len(), 209_280);
    let (lo, hi) = cloud.bounds().unwrap();
    assert!((0.68..0.70).contains(&lo.z), "nearest z {}", lo.z);
    assert!((2.58..2.60).contains(&hi.z), "farthest z {}", hi.z);
}

#[test]
fn osd_test0_has_a_label_per_pixel_and_two_objects() {
    let pcd = pcd::read_pcd(&data("pointclouds/mosd/osd_test0.pcd")).unwrap();
    assert_eq!((pcd.width, pcd.height), (640, 480));
    let labels = pcd.labels.as_ref().expect("a label field");
    assert_eq!(labels.len(), 307_200);
    let finite = pcd.points.iter().filter(|p| p.is_finite()).count();
    assert_eq!(finite, 189_198);
    // Label 0 marks invalid points; labels of 20 and up are object id * 10 + part.
    for (p, &label) in pcd.points.iter().zip(labels) {
        assert_eq!(label == 0, !p.is_finite(), "label {label} at {p}");
    }
    let objects: BTreeSet<u32> = labels
        .iter()
        .filter(|&&l| l >= 20)
        .map(|l| l / 10)
        .collect();
    assert_eq!(objects.len(), 2, "objects {objects:?}");
}

#[test]
fn kinect_grabber_frame_is_640x480_with_271575_finite_points() {
    let path = &data("depth/pcl_kinect_grabber/frame_20121214T142255.814212.pcd");
    let pcd = pcd::read_pcd(path).unwrap();
    assert_eq!((pcd.width, pcd.height), (640, 480));
    assert_eq!(pcd.points.len(), 307_200);
    assert!(pcd.rgba.is_some());
    let cloud = read_cloud(path).unwrap();
    assert_eq!(cloud.len(), 271_575);
    // Depth range 666-1731 mm in the matching depth image.
    let (lo, hi) = cloud.bounds().unwrap();
    assert!(lo.z >= 0.665 && hi.z <= 1.732, "z {} to {}", lo.z, hi.z);
}

#[test]
fn bun000_reads_40256_vertices_past_its_range_grid() {
    let cloud = read_cloud(&data("pointclouds/stanford_bunny/bun000.ply")).unwrap();
    assert_eq!(cloud.len(), 40_256);
    assert_eq!(cloud.normals, None);
}

#[test]
fn bun_zipper_res2_is_8171_vertices_and_16301_triangles() {
    let path = &data("pointclouds/stanford_bunny/bun_zipper_res2.ply");
    let mesh = read_mesh(path).unwrap();
    assert_eq!(mesh.vertices.len(), 8171);
    assert_eq!(mesh.triangles.len(), 16_301);
    assert_eq!(mesh.first_bad_index(), None);
    assert_eq!(read_cloud(path).unwrap().len(), 8171);
}

#[test]
fn suzanne_obj_is_507_vertices_and_968_triangles() {
    let mesh = read_mesh(&data("meshes/suzanne.obj")).unwrap();
    assert_eq!(mesh.vertices.len(), 507);
    assert_eq!(mesh.triangles.len(), 968);
    let (lo, hi) = mesh.bounds().unwrap();
    assert!((hi.x - 1.367).abs() < 1e-3 && (lo.x + 1.367).abs() < 1e-3);
}

#[test]
fn suzanne_with_uvs_and_normals_reads_as_the_same_mesh() {
    let plain = read_mesh(&data("meshes/suzanne.obj")).unwrap();
    let textured = read_mesh(&data("meshes/suzanne_blender283_with_uv_normals.obj")).unwrap();
    assert_eq!(textured.vertices.len(), plain.vertices.len());
    assert_eq!(textured.triangles.len(), plain.triangles.len());
}

#[test]
fn cube_obj_is_8_vertices_and_12_triangles_of_area_24() {
    let mesh = read_mesh(&data("meshes/cube.obj")).unwrap();
    assert_eq!(mesh.vertices.len(), 8);
    assert_eq!(mesh.triangles.len(), 12);
    assert!((mesh.area() - 24.0).abs() < 1e-4);
}
