//! Bad input gets a clear error naming what is wrong, and a failing exit status; never a panic.

use std::io::Write;

use crate::util::{path_str, tacmesh};

fn stderr_of(args: &[&str]) -> String {
    let out = tacmesh(args);
    assert!(!out.status.success(), "tacmesh {args:?} should fail");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        !stderr.contains("panicked"),
        "tacmesh {args:?} panicked: {stderr}"
    );
    stderr
}

#[test]
fn missing_cloud_file_is_named() {
    let stderr = stderr_of(&["mesh", "/nonexistent/cloud.ply", "-o", "/tmp/never.ply"]);
    assert!(stderr.contains("/nonexistent/cloud.ply"), "{stderr}");
}

#[test]
fn truncated_ply_is_an_error_not_a_panic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("cut.ply");
    let mut f = std::fs::File::create(&path).expect("create");
    f.write_all(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00\x80\x3f")
        .expect("write");
    drop(f);
    let out = path_str(&dir.path().join("out.ply")).to_owned();
    let stderr = stderr_of(&["mesh", path_str(&path), "-o", &out]);
    assert!(stderr.contains("cut.ply"), "{stderr}");
}

#[test]
fn unknown_shape_lists_the_shapes() {
    let stderr = stderr_of(&["eval", "dodecahedron", "cube"]);
    assert!(
        stderr.contains("cube") && stderr.contains("torus"),
        "{stderr}"
    );
}

#[test]
fn too_few_points_is_a_clear_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("three.xyz");
    std::fs::write(&path, "0 0 0\n1 0 0\n0 1 0\n").expect("write");
    let out = path_str(&dir.path().join("out.ply")).to_owned();
    let stderr = stderr_of(&["mesh", path_str(&path), "-o", &out]);
    assert!(stderr.contains("too few"), "{stderr}");
}

/// `tacmesh eval … | head -0`: a closed standard output is a clear error and exit 1, not the
/// panic (exit 101) that `println!` gives on a broken pipe.
#[test]
fn a_closed_stdout_is_an_error_not_a_panic() {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["eval", "cube", "cube"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("tacmesh runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("waits");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{}: {stderr}", out.status);
    assert!(
        stderr.contains("cannot write to standard output"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}
