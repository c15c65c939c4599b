//! Seeded truncations and single-byte corruptions of every sample file: each parser must
//! return `Ok` or `Err`, never panic, hang or allocate without bound.

use tacmesh_formats::{obj, pcd, ply, write_cloud, write_mesh, xyz};

use crate::round_trip::{binary_pcd_sample, compressed_pcd};
use crate::util::data;
use crate::util::{read, scratch, Lcg};

#[derive(Debug, Clone, Copy)]
enum Format {
    Pcd,
    PlyCloud,
    PlyMesh,
    Obj,
    Xyz,
}

/// Runs every parser for the format; returns whether all of them accepted the bytes.
fn parse(format: Format, bytes: &[u8]) -> bool {
    match format {
        Format::Pcd => pcd::parse(bytes, "m.pcd").is_ok(),
        Format::PlyCloud => ply::parse_cloud(bytes, "m.ply").is_ok(),
        Format::PlyMesh => {
            let cloud = ply::parse_cloud(bytes, "m.ply").is_ok();
            ply::parse_mesh(bytes, "m.ply").is_ok() && cloud
        }
        Format::Obj => obj::parse(bytes, "m.obj").is_ok(),
        Format::Xyz => xyz::parse(bytes, "m.xyz").is_ok(),
    }
}

/// Bytes most likely to matter: the header, or the first lines of a text format.
const HEAD_BYTES: usize = 600;
const TRUNCATIONS: usize = 16;
const CORRUPTIONS: usize = 32;

fn mangle(name: &str, format: Format, bytes: &[u8], seed: u64) {
    assert!(parse(format, bytes), "{name} does not parse unmangled");
    let mut rng = Lcg::new(seed);
    let mut accepted = 0;
    for i in 0..TRUNCATIONS {
        let limit = if i % 2 == 0 {
            HEAD_BYTES.min(bytes.len())
        } else {
            bytes.len()
        };
        let len = rng.below(limit);
        accepted += usize::from(parse(format, &bytes[..len]));
    }
    let mut copy = bytes.to_vec();
    for i in 0..CORRUPTIONS {
        let limit = if i % 2 == 0 {
            HEAD_BYTES.min(bytes.len())
        } else {
            bytes.len()
        };
        let at = rng.below(limit);
        let was = copy[at];
        // Half the time a byte that keeps text looking like text.
        copy[at] = if i % 4 < 2 {
            b"0123456789 -.\nxyzeE#/"[rng.below(21)]
        } else {
            rng.next_u64() as u8
        };
        accepted += usize::from(parse(format, &copy));
        copy[at] = was;
    }
    eprintln!(
        "{name}: {accepted} of {} mangled versions accepted",
        TRUNCATIONS + CORRUPTIONS
    );
}

#[test]
fn mangled_real_files_never_panic() {
    let files = [
        (
            "milk.pcd",
            Format::Pcd,
            read(&data("pointclouds/pcl/milk.pcd")),
        ),
        (
            "table_scene_mug_stereo_textured.pcd",
            Format::Pcd,
            read(&data("pointclouds/pcl/table_scene_mug_stereo_textured.pcd")),
        ),
        (
            "osd_test0.pcd",
            Format::Pcd,
            read(&data("pointclouds/mosd/osd_test0.pcd")),
        ),
        (
            "frame_20121214T142255.814212.pcd",
            Format::Pcd,
            read(&data(
                "depth/pcl_kinect_grabber/frame_20121214T142255.814212.pcd",
            )),
        ),
        (
            "bun000.ply",
            Format::PlyCloud,
            read(&data("pointclouds/stanford_bunny/bun000.ply")),
        ),
        (
            "bun_zipper_res2.ply",
            Format::PlyMesh,
            read(&data("pointclouds/stanford_bunny/bun_zipper_res2.ply")),
        ),
        (
            "suzanne.obj",
            Format::Obj,
            read(&data("meshes/suzanne.obj")),
        ),
        (
            "suzanne_blender283_with_uv_normals.obj",
            Format::Obj,
            read(&data("meshes/suzanne_blender283_with_uv_normals.obj")),
        ),
        ("cube.obj", Format::Obj, read(&data("meshes/cube.obj"))),
    ];
    for (seed, (name, format, bytes)) in files.iter().enumerate() {
        mangle(name, *format, bytes, seed as u64 + 1);
    }
}

#[test]
fn mangled_written_files_never_panic() {
    let mesh = tacmesh_formats::read_mesh(&data("meshes/suzanne.obj")).unwrap();
    let (_dir, ply_path) = scratch("suzanne.ply");
    write_mesh(&ply_path, &mesh).unwrap();
    let cloud = tacmesh_source::PointCloud::with_normals(
        mesh.vertices.clone(),
        mesh.vertices
            .iter()
            .map(|v| v.normalize_or_zero())
            .collect(),
    );
    let (_dir2, cloud_path) = scratch("suzanne_cloud.ply");
    write_cloud(&cloud_path, &cloud).unwrap();
    let (_dir3, xyz_path) = scratch("suzanne.xyz");
    write_cloud(&xyz_path, &cloud).unwrap();

    let files = [
        ("binary mesh .ply", Format::PlyMesh, read(&ply_path)),
        ("binary cloud .ply", Format::PlyCloud, read(&cloud_path)),
        (".xyz", Format::Xyz, read(&xyz_path)),
        ("binary .pcd", Format::Pcd, binary_pcd_sample()),
        ("compressed .pcd", Format::Pcd, compressed_pcd(500)),
    ];
    for (seed, (name, format, bytes)) in files.iter().enumerate() {
        mangle(name, *format, bytes, seed as u64 + 100);
    }
}
