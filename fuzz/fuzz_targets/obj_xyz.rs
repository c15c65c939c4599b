//! The two text readers of `tacmesh-formats`: `obj::parse` (what `read_mesh` calls for `.obj`)
//! and `xyz::parse` (`.xyz`, `.txt`, `.pts`), on the same bytes.
//!
//! Properties beyond "no panic": every triangle of a mesh refers to a vertex that exists, and a
//! cloud with normals has one per point. A mesh written back as OBJ reads back the same.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_formats::{obj, xyz};

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = obj::parse(data, "fuzz.obj") {
        assert_eq!(mesh.first_bad_index(), None, "mesh with a bad index");
        if mesh.vertices.iter().all(|v| v.is_finite()) {
            let mut written = Vec::new();
            obj::write(&mut written, &mesh).expect("writing to memory succeeds");
            let read_back = obj::parse(&written, "written.obj").expect("a written OBJ reads back");
            assert_eq!(read_back, mesh);
        }
    }
    if let Ok(cloud) = xyz::parse(data, "fuzz.xyz") {
        if let Some(normals) = &cloud.normals {
            assert_eq!(normals.len(), cloud.points.len());
        }
    }
});
