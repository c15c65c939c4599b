//! Writing then reading gives back the same data; PCD variants written by hand read as meant.

use glam::Vec3;
use tacmesh_formats::{pcd, read_cloud, read_mesh, write_cloud, write_mesh};
use tacmesh_source::PointCloud;

use crate::util::data;
use crate::util::{ply_header_len, read, scratch, scratch_file, small_mesh};

/// The first `n` points of the bunny scan, with made-up unit normals when asked.
fn bunny_cloud(n: usize, with_normals: bool) -> PointCloud {
    let points: Vec<Vec3> = read_cloud(&data("pointclouds/stanford_bunny/bun000.ply"))
        .unwrap()
        .points
        .into_iter()
        .take(n)
        .collect();
    if with_normals {
        let normals = points.iter().map(|p| p.normalize_or(Vec3::Z)).collect();
        PointCloud::with_normals(points, normals)
    } else {
        PointCloud::new(points)
    }
}

#[test]
fn binary_ply_mesh_round_trips_with_its_face_lists_intact() {
    let mesh = read_mesh(&data("meshes/suzanne.obj")).unwrap();
    let (_dir, path) = scratch("suzanne.ply");
    write_mesh(&path, &mesh).unwrap();

    let bytes = read(&path);
    let header_len = ply_header_len(&bytes);
    let header = std::str::from_utf8(&bytes[..header_len]).unwrap();
    assert!(
        header.contains("format binary_little_endian 1.0\n"),
        "{header}"
    );
    assert!(header.contains("element face 968\n"), "{header}");
    assert!(
        header.contains("property list uchar uint vertex_indices\n"),
        "{header}"
    );
    // 3 floats per vertex; a count byte and 3 u32 per face: nothing more, nothing less.
    assert_eq!(bytes.len(), header_len + 507 * 12 + 968 * 13);

    assert_eq!(read_mesh(&path).unwrap(), mesh);
}

#[test]
fn obj_mesh_round_trips_exactly() {
    for mesh in [
        small_mesh(),
        read_mesh(&data("meshes/suzanne.obj")).unwrap(),
    ] {
        let (_dir, path) = scratch("m.obj");
        write_mesh(&path, &mesh).unwrap();
        assert_eq!(read_mesh(&path).unwrap(), mesh);
    }
}

#[test]
fn ply_cloud_round_trips_with_and_without_normals() {
    for with_normals in [false, true] {
        let cloud = bunny_cloud(1000, with_normals);
        let (_dir, path) = scratch("c.ply");
        write_cloud(&path, &cloud).unwrap();
        let properties = if with_normals { 6 } else { 3 };
        let bytes = read(&path);
        assert_eq!(bytes.len(), ply_header_len(&bytes) + 1000 * 4 * properties);
        assert_eq!(read_cloud(&path).unwrap(), cloud);
    }
}

#[test]
fn xyz_cloud_round_trips_with_and_without_normals() {
    for with_normals in [false, true] {
        let cloud = bunny_cloud(1000, with_normals);
        let (_dir, path) = scratch("c.xyz");
        write_cloud(&path, &cloud).unwrap();
        assert_eq!(read_cloud(&path).unwrap(), cloud);
    }
}

#[test]
fn ply_mesh_reads_as_a_cloud_of_its_vertices() {
    let mesh = small_mesh();
    let (_dir, path) = scratch("m.PLY");
    write_mesh(&path, &mesh).unwrap();
    assert_eq!(read_cloud(&path).unwrap().points, mesh.vertices);
}

/// An organised 2x2 cloud with normals, a label, a packed float `rgb`, a `_` padding field and
/// a 3-element histogram that must be skipped; one point invalid.
const ASCII_PCD: &str = "# .PCD v0.7 - Point Cloud Data file format\n\
VERSION .7\n\
FIELDS x y z _ normal_x normal_y normal_z label rgb hist\n\
SIZE 4 4 4 1 4 4 4 4 4 2\n\
TYPE F F F U F F F U F U\n\
COUNT 1 1 1 1 1 1 1 1 1 3\n\
WIDTH 2\n\
HEIGHT 2\n\
VIEWPOINT 0 0 0 1 0 0 0\n\
POINTS 4\n\
DATA ascii\n\
0.5 -1.25 2 0 0 0 1 7 4.2108e+06 1 2 3\n\
nan nan nan 0 nan nan nan 0 0 0 0 0\n\
1 2 3 255 1 0 0 21 0 65535 0 9\n\
-4 5e-3 6.5 9 0 1 0 30 1 4 5 6\n";

#[test]
fn ascii_pcd_keeps_grid_labels_colours_and_skips_padding_and_histograms() {
    let pcd = pcd::parse(ASCII_PCD.as_bytes(), "hand.pcd").unwrap();
    assert_eq!((pcd.width, pcd.height), (2, 2));
    assert_eq!(pcd.points.len(), 4);
    assert_eq!(pcd.points[0], Vec3::new(0.5, -1.25, 2.0));
    assert!(pcd.points[1].is_nan());
    assert_eq!(pcd.points[3], Vec3::new(-4.0, 0.005, 6.5));
    let normals = pcd.normals.as_ref().unwrap();
    assert_eq!(
        (normals[0], normals[2], normals[3]),
        (Vec3::Z, Vec3::X, Vec3::Y)
    );
    assert_eq!(pcd.labels, Some(vec![7, 0, 21, 30]));
    let rgb = pcd.rgba.as_ref().unwrap();
    assert_eq!(rgb[0], 4.2108e6f32.to_bits());

    let (_dir, path) = scratch_file("hand.pcd", ASCII_PCD.as_bytes());
    let cloud = read_cloud(&path).unwrap();
    assert_eq!(cloud.len(), 3);
    assert_eq!(cloud.normals.unwrap()[1], Vec3::X);
}

/// A binary PCD with mixed types: x double, y float, z short (millimetres, say), 3 padding
/// bytes, rgba, and a 2-byte label.
fn binary_pcd(points: &[(f64, f32, i16, u32, u16)]) -> Vec<u8> {
    let mut bytes = format!(
        "VERSION 0.7\nFIELDS x y z _ rgba label\nSIZE 8 4 2 1 4 2\nTYPE F F I U U U\n\
         COUNT 1 1 1 3 1 1\nWIDTH {}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {}\nDATA binary\n",
        points.len(),
        points.len()
    )
    .into_bytes();
    for &(x, y, z, rgba, label) in points {
        bytes.extend(x.to_le_bytes());
        bytes.extend(y.to_le_bytes());
        bytes.extend(z.to_le_bytes());
        bytes.extend([0xAA; 3]);
        bytes.extend(rgba.to_le_bytes());
        bytes.extend(label.to_le_bytes());
    }
    bytes
}

pub fn binary_pcd_sample() -> Vec<u8> {
    binary_pcd(&[
        (1.5, 2.5, -3, 0xFF102030, 1),
        (-0.25, 1e-3, 32767, 0, 65535),
        (1e10, f32::NAN, 0, 7, 2),
    ])
}

#[test]
fn binary_pcd_with_mixed_types_reads_back() {
    let pcd = pcd::parse(&binary_pcd_sample(), "mixed.pcd").unwrap();
    assert_eq!((pcd.width, pcd.height), (3, 1));
    assert_eq!(pcd.points[0], Vec3::new(1.5, 2.5, -3.0));
    assert_eq!(pcd.points[1], Vec3::new(-0.25, 1e-3, 32767.0));
    assert!(pcd.points[2].y.is_nan());
    assert_eq!(pcd.rgba, Some(vec![0xFF102030, 0, 7]));
    assert_eq!(pcd.labels, Some(vec![1, 65535, 2]));

    let (_dir, path) = scratch_file("mixed.pcd", &binary_pcd_sample());
    assert_eq!(read_cloud(&path).unwrap().len(), 2);
}

/// A binary_compressed PCD of `n` points on a line, with a 2-element field between the
/// coordinates and the colour, laid out field by field as PCL writes it.
pub fn compressed_pcd(n: usize) -> Vec<u8> {
    let mut columns = Vec::new();
    for axis in 0..3 {
        for i in 0..n {
            columns.extend((i as f32 * (axis + 1) as f32).to_le_bytes());
        }
    }
    for i in 0..n {
        columns.extend((i as f32).to_le_bytes());
        columns.extend((-(i as f32)).to_le_bytes());
    }
    for i in 0..n {
        columns.extend((0xFF000000u32 | i as u32).to_le_bytes());
    }
    let packed = lzf::compress(&columns).unwrap();
    let mut bytes = format!(
        "VERSION 0.7\nFIELDS x y z pair rgba\nSIZE 4 4 4 4 4\nTYPE F F F F U\n\
         COUNT 1 1 1 2 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n\
         DATA binary_compressed\n"
    )
    .into_bytes();
    bytes.extend((packed.len() as u32).to_le_bytes());
    bytes.extend((columns.len() as u32).to_le_bytes());
    bytes.extend(packed);
    bytes
}

#[test]
fn compressed_pcd_is_read_field_by_field() {
    let pcd = pcd::parse(&compressed_pcd(500), "c.pcd").unwrap();
    assert_eq!(pcd.points.len(), 500);
    assert_eq!(pcd.points[7], Vec3::new(7.0, 14.0, 21.0));
    assert_eq!(pcd.rgba.as_ref().unwrap()[499], 0xFF000000 | 499);
}
