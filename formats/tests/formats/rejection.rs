//! Broken files are errors that name the file and say what is wrong, never panics.

use std::path::Path;

use tacmesh_formats::{read_cloud, read_mesh, write_cloud, write_mesh, FormatError};
use tacmesh_source::{PointCloud, TriMesh};

use crate::round_trip::{binary_pcd_sample, compressed_pcd};
use crate::util::data;
use crate::util::{ply_header_len, read, scratch, scratch_file, small_mesh};

type Reader = fn(&Path) -> Result<(), FormatError>;

fn cloud_reader(path: &Path) -> Result<(), FormatError> {
    read_cloud(path).map(drop)
}

fn mesh_reader(path: &Path) -> Result<(), FormatError> {
    read_mesh(path).map(drop)
}

/// Reads `bytes[..len]` from a scratch file and expects an error naming that file.
fn expect_error(file_name: &str, bytes: &[u8], len: usize, reader: Reader) -> String {
    let (_dir, path) = scratch_file(file_name, &bytes[..len]);
    match reader(&path) {
        Ok(()) => panic!(
            "{file_name} cut to {len} of {} bytes was accepted",
            bytes.len()
        ),
        Err(e) => {
            let message = e.to_string();
            let prefix = format!("{}: ", path.display());
            assert!(message.starts_with(&prefix), "{message}");
            message[prefix.len()..].to_owned()
        }
    }
}

/// Lengths to cut a file at: nothing, inside the header, just before and after its end, and
/// through the data.
fn cut_points(len: usize, header_len: usize) -> Vec<usize> {
    vec![
        0,
        3,
        header_len / 2,
        header_len - 1,
        header_len,
        header_len + 1,
        header_len + (len - header_len) / 3,
        header_len + (len - header_len) * 9 / 10,
        len - 1,
    ]
}

fn pcd_header_len(bytes: &[u8]) -> usize {
    let data = b"\nDATA ";
    let at = bytes.windows(data.len()).position(|w| w == data).unwrap() + 1;
    at + bytes[at..].iter().position(|&b| b == b'\n').unwrap() + 1
}

#[test]
fn truncated_compressed_pcd_is_an_error() {
    let bytes = read(&data("pointclouds/pcl/milk.pcd"));
    let header_len = pcd_header_len(&bytes);
    // PCL pads the file past the compressed block (3913 bytes here); cutting the padding is
    // harmless, so the cuts are made up to the block's end.
    let compressed: [u8; 4] = bytes[header_len..header_len + 4].try_into().unwrap();
    let end = header_len + 8 + u32::from_le_bytes(compressed) as usize;
    assert_eq!(bytes.len() - end, 3913);
    for len in cut_points(end, header_len) {
        expect_error("milk.pcd", &bytes, len, cloud_reader);
    }
}

#[test]
fn truncated_binary_pcd_is_an_error() {
    let bytes = binary_pcd_sample();
    for len in cut_points(bytes.len(), pcd_header_len(&bytes)) {
        expect_error("mixed.pcd", &bytes, len, cloud_reader);
    }
    let message = expect_error("mixed.pcd", &bytes, bytes.len() - 5, cloud_reader);
    assert_eq!(
        message,
        "header says 3 points but the binary data ends after 2 (64 bytes at 23 bytes per point)"
    );
}

#[test]
fn truncated_ascii_pcd_is_an_error() {
    let bytes = b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\n\
        DATA ascii\n1 2 3\n4 5 6\n7 8 9\n";
    let header_len = pcd_header_len(bytes);
    // Cuts inside the last line can leave a shorter but valid number, so stop before it.
    for len in cut_points(bytes.len() - 6, header_len) {
        expect_error("a.pcd", bytes, len, cloud_reader);
    }
    let message = expect_error("a.pcd", bytes, bytes.len() - 6, cloud_reader);
    assert_eq!(
        message,
        "header says 3 points but the ascii data has only 2"
    );
    let message = expect_error("a.pcd", bytes, bytes.len() - 3, cloud_reader);
    assert_eq!(message, "line 10 ends before field z");
}

#[test]
fn truncated_binary_ply_is_an_error() {
    let (_dir, path) = scratch("m.ply");
    write_mesh(&path, &small_mesh()).unwrap();
    let bytes = read(&path);
    for len in cut_points(bytes.len(), ply_header_len(&bytes)) {
        expect_error("m.ply", &bytes, len, mesh_reader);
        expect_error("m.ply", &bytes, len, cloud_reader);
    }
}

#[test]
fn truncated_ascii_ply_is_an_error() {
    let bytes = read(&data("pointclouds/stanford_bunny/bun_zipper_res2.ply"));
    // The last face line is "3 a b c"; cutting inside it can leave a valid shorter number.
    for len in cut_points(bytes.len() - 30, ply_header_len(&bytes)) {
        expect_error("bunny.ply", &bytes, len, mesh_reader);
    }
    let message = expect_error("bunny.ply", &bytes, bytes.len() / 2, mesh_reader);
    assert!(
        message.starts_with("header declares 8171 vertex, 16301 face (24472 lines) but only"),
        "{message}"
    );
}

#[test]
fn obj_cut_inside_a_vertex_or_before_referenced_vertices_is_an_error() {
    let bytes = read(&data("meshes/cube.obj"));
    let text = std::str::from_utf8(&bytes).unwrap();
    let inside_vertex = text.find("v 1.000000 -1.000000 -1.000000").unwrap() + 20;
    let message = expect_error("cube.obj", &bytes, inside_vertex, mesh_reader);
    assert_eq!(message, "line 10: a vertex needs 3 coordinates");

    let without_last_vertex: String = text
        .lines()
        .filter(|l| !l.starts_with("v 1.000000 1.000000 -1"))
        .map(|l| format!("{l}\n"))
        .collect();
    let message = expect_error(
        "cube.obj",
        without_last_vertex.as_bytes(),
        without_last_vertex.len(),
        mesh_reader,
    );
    assert_eq!(
        message,
        "line 13: face refers to vertex 8 but there are 7 vertices"
    );
}

#[test]
fn xyz_line_with_two_numbers_is_an_error() {
    let bytes = b"0 0 0\n1 0 0\n1 1\n";
    let message = expect_error("s.xyz", bytes, bytes.len(), cloud_reader);
    assert_eq!(
        message,
        "line 3: has 2 numbers; expected 3 (x y z) or 6 (x y z nx ny nz)"
    );
}

#[test]
fn pcd_points_disagreeing_with_width_times_height_is_an_error() {
    let bytes = b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\n\
        POINTS 5\nDATA ascii\n";
    let message = expect_error("p.pcd", bytes, bytes.len(), cloud_reader);
    assert_eq!(
        message,
        "header: POINTS is 5 but WIDTH * HEIGHT is 2 * 2 = 4"
    );
}

/// Overwrites the compressed (`which` = 0) or uncompressed (1) size of a compressed PCD.
fn with_size(bytes: &[u8], which: usize, size: u32) -> Vec<u8> {
    let mut bytes = bytes.to_vec();
    let at = pcd_header_len(&bytes) + 4 * which;
    bytes[at..at + 4].copy_from_slice(&size.to_le_bytes());
    bytes
}

#[test]
fn compressed_pcd_whose_sizes_lie_is_an_error() {
    let honest = compressed_pcd(500);
    let at = pcd_header_len(&honest);
    let compressed = u32::from_le_bytes(honest[at..at + 4].try_into().unwrap());
    let unpacked = u32::from_le_bytes(honest[at + 4..at + 8].try_into().unwrap());
    assert_eq!(unpacked, 500 * 24);

    let lie = with_size(&honest, 1, unpacked + 24);
    let message = expect_error("c.pcd", &lie, lie.len(), cloud_reader);
    assert_eq!(
        message,
        "header says 500 points of 24 bytes (12000 bytes) but the compressed block says it \
         unpacks to 12024"
    );

    let lie = with_size(&honest, 0, compressed + 1);
    let message = expect_error("c.pcd", &lie, lie.len(), cloud_reader);
    assert_eq!(
        message,
        format!(
            "compressed block is {} bytes but the file ends after {compressed}",
            compressed + 1
        )
    );

    // A shorter block stops the LZF stream early: it unpacks to too little or fails.
    let lie = with_size(&honest, 0, compressed - 10);
    expect_error("c.pcd", &lie, lie.len(), cloud_reader);
}

#[test]
fn compressed_pcd_claiming_gigabytes_is_refused_before_allocating() {
    let mut bytes = b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 100000000\n\
        HEIGHT 1\nDATA binary_compressed\n"
        .to_vec();
    bytes.extend(16u32.to_le_bytes());
    bytes.extend(1_200_000_000u32.to_le_bytes());
    bytes.extend([0u8; 16]);
    let message = expect_error("huge.pcd", &bytes, bytes.len(), cloud_reader);
    assert_eq!(message, "16 bytes of LZF data cannot unpack to 1200000000");
}

#[test]
fn pcd_without_coordinates_is_an_error() {
    let bytes = b"VERSION .7\nFIELDS label\nSIZE 4\nTYPE U\nWIDTH 1\nHEIGHT 1\nDATA ascii\n3\n";
    let message = expect_error("l.pcd", bytes, bytes.len(), cloud_reader);
    assert_eq!(message, "has no x y z fields (fields are: label)");
}

#[test]
fn binary_ply_face_index_out_of_range_is_an_error() {
    let (_dir, path) = scratch("m.ply");
    write_mesh(&path, &small_mesh()).unwrap();
    let mut bytes = read(&path);
    let last = bytes.len() - 4;
    bytes[last..].copy_from_slice(&900u32.to_le_bytes());
    let message = expect_error("m.ply", &bytes, bytes.len(), mesh_reader);
    assert_eq!(
        message,
        "face 5 refers to vertex 900 but there are 5 vertices"
    );
}

#[test]
fn unknown_extension_is_an_error_listing_the_supported_ones() {
    let message = read_cloud(Path::new("scan.las")).unwrap_err().to_string();
    assert_eq!(
        message,
        "scan.las: unsupported extension; point clouds can be .ply, .pcd, .xyz, .txt or .pts"
    );
    let message = read_mesh(Path::new("part.stl")).unwrap_err().to_string();
    assert_eq!(
        message,
        "part.stl: unsupported extension; meshes can be .obj or .ply"
    );
    let (_dir, path) = scratch("out.pcd");
    let message = write_cloud(&path, &PointCloud::default())
        .unwrap_err()
        .to_string();
    assert!(
        message.ends_with("point clouds can be .ply or .xyz"),
        "{message}"
    );
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let message = read_mesh(Path::new("/nonexistent/part.obj"))
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with("/nonexistent/part.obj: cannot read: "),
        "{message}"
    );
}

#[test]
fn mesh_with_a_bad_index_is_not_written() {
    let (_dir, path) = scratch("bad.ply");
    let mesh = TriMesh::new(small_mesh().vertices, vec![[0, 1, 5]]);
    let message = write_mesh(&path, &mesh).unwrap_err().to_string();
    assert!(
        message.ends_with("cannot write: triangle 0 refers to vertex 5 but there are 5 vertices"),
        "{message}"
    );
}
