//! The PLY reader over bytes held in memory: `tacmesh_formats::ply::parse_cloud` and
//! `parse_mesh` (what `read_cloud` and `read_mesh` call for a `.ply` file).
//!
//! Properties beyond "no panic": a cloud with normals has one per point, and every triangle of
//! a mesh refers to a vertex that exists.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_formats::ply;

fuzz_target!(|data: &[u8]| {
    if let Ok(cloud) = ply::parse_cloud(data, "fuzz.ply") {
        if let Some(normals) = &cloud.normals {
            assert_eq!(normals.len(), cloud.points.len());
        }
    }
    if let Ok(mesh) = ply::parse_mesh(data, "fuzz.ply") {
        assert_eq!(mesh.first_bad_index(), None, "mesh with a bad index");
    }
});
