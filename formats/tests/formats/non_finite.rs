//! One rule for every format: a point with a NaN or infinite coordinate is read (never an
//! error), counted, and dropped or kept as the caller asks.

use glam::Vec3;
use tacmesh_formats::{read_cloud_file, NonFinite};

use crate::util::scratch_file;

/// The finite points every file below holds, in order, with two non-finite ones among them.
const FINITE: [Vec3; 3] = [
    Vec3::new(0.5, 0.0, 1.0),
    Vec3::new(1.0, 2.0, 3.0),
    Vec3::new(-1.0, 0.25, 2.0),
];

fn points_with_two_non_finite() -> [Vec3; 5] {
    [
        FINITE[0],
        Vec3::new(f32::NAN, 1.0, 2.0),
        FINITE[1],
        Vec3::new(1.0, f32::NEG_INFINITY, 0.0),
        FINITE[2],
    ]
}

fn ascii_ply() -> Vec<u8> {
    let mut text = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\n\
        property float y\nproperty float z\nend_header\n"
        .to_owned();
    // numpy's and most scanners' spellings: `nan`, `-inf`; `.5` has no leading digit.
    text += ".5 0 1\nnan 1 2\n1 2 3\n1 -inf 0\n-1 0.25 2\n";
    text.into_bytes()
}

fn binary_ply() -> Vec<u8> {
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 5\n\
        property float x\nproperty float y\nproperty float z\nend_header\n"
        .to_vec();
    for p in points_with_two_non_finite() {
        for c in p.to_array() {
            bytes.extend(c.to_le_bytes());
        }
    }
    bytes
}

fn pcd_header(data: &str) -> String {
    format!(
        "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 5\nHEIGHT 1\nPOINTS 5\n\
         DATA {data}\n"
    )
}

fn ascii_pcd() -> Vec<u8> {
    (pcd_header("ascii") + "0.5 0 1\nnan 1 2\n1 2 3\n1 -inf 0\n-1 0.25 2\n").into_bytes()
}

fn binary_pcd() -> Vec<u8> {
    let mut bytes = pcd_header("binary").into_bytes();
    for p in points_with_two_non_finite() {
        for c in p.to_array() {
            bytes.extend(c.to_le_bytes());
        }
    }
    bytes
}

fn xyz() -> Vec<u8> {
    b"0.5 0 1\nnan 1 2\n1 2 3\n1 -inf 0\n-1 0.25 2\n".to_vec()
}

fn every_format() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("ascii.ply", ascii_ply()),
        ("binary.ply", binary_ply()),
        ("ascii.pcd", ascii_pcd()),
        ("binary.pcd", binary_pcd()),
        ("scan.xyz", xyz()),
        ("scan.txt", xyz()),
        ("scan.pts", xyz()),
    ]
}

#[test]
fn every_format_drops_and_counts_non_finite_points() {
    for (file_name, bytes) in every_format() {
        let (_dir, path) = scratch_file(file_name, &bytes);
        let file = read_cloud_file(&path, NonFinite::Drop)
            .unwrap_or_else(|err| panic!("{file_name}: {err}"));
        assert_eq!(file.cloud.points, FINITE, "{file_name}");
        assert_eq!(file.non_finite, 2, "{file_name}");
    }
}

#[test]
fn every_format_keeps_and_counts_non_finite_points_in_file_order() {
    for (file_name, bytes) in every_format() {
        let (_dir, path) = scratch_file(file_name, &bytes);
        let file = read_cloud_file(&path, NonFinite::Keep)
            .unwrap_or_else(|err| panic!("{file_name}: {err}"));
        assert_eq!(file.cloud.points.len(), 5, "{file_name}");
        assert_eq!(file.cloud.points[2], FINITE[1], "{file_name}");
        assert!(file.cloud.points[1].x.is_nan(), "{file_name}");
        assert_eq!(file.non_finite, 2, "{file_name}");
    }
}

/// An organised PCD (3×2 pixels) with a pixel that has no reading.
fn organised_pcd(middle: &str) -> Vec<u8> {
    let header = "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 2\n\
                  POINTS 6\nDATA ascii\n";
    format!("{header}0 0 1\n1 0 1\n2 0 1\n0 1 1\n{middle}\n2 1 1\n").into_bytes()
}

#[test]
fn an_organised_pcd_keeps_its_grid_while_its_points_stay_in_place() {
    let grid = Some(tacmesh_source::CloudGrid {
        width: 3,
        height: 2,
    });
    let (_dir, path) = scratch_file("organised.pcd", &organised_pcd("nan nan nan"));
    let kept = read_cloud_file(&path, NonFinite::Keep).expect("organised PCD");
    assert_eq!(kept.grid, grid);
    assert!(kept.cloud.points[4].is_nan());
    assert_eq!(kept.cloud.points[5], Vec3::new(2.0, 1.0, 1.0));
    // Dropping the missing pixel takes the cloud off its grid.
    let dropped = read_cloud_file(&path, NonFinite::Drop).expect("organised PCD");
    assert_eq!((dropped.cloud.len(), dropped.grid), (5, None));
    // With nothing to drop, the grid holds either way.
    let (_dir, full) = scratch_file("full.pcd", &organised_pcd("1 1 1"));
    assert_eq!(
        read_cloud_file(&full, NonFinite::Drop).expect("full").grid,
        grid
    );
}

#[test]
fn unorganised_files_have_no_grid() {
    for (file_name, bytes) in every_format() {
        let (_dir, path) = scratch_file(file_name, &bytes);
        let file = read_cloud_file(&path, NonFinite::Keep)
            .unwrap_or_else(|err| panic!("{file_name}: {err}"));
        assert_eq!(file.grid, None, "{file_name}");
    }
}
