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

/// Named once, with the OS's reason once: the context `main` prints adds no second copy.
#[test]
fn missing_cloud_file_is_named_once_with_its_reason() {
    let stderr = stderr_of(&["mesh", "/nonexistent/cloud.ply", "-o", "/tmp/never.ply"]);
    assert_eq!(
        stderr.matches("/nonexistent/cloud.ply").count(),
        1,
        "{stderr}"
    );
    assert_eq!(stderr.matches("os error 2").count(), 1, "{stderr}");
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

/// Contact settings clap can check are refused by clap, naming the flag; a contact setting
/// without `--contact` is refused too rather than silently ignored.
#[test]
fn bad_contact_settings_are_clap_errors() {
    for (flag, value) in [
        ("--probe-radii-mm", "5,-10"),
        ("--probe-radii-mm", "nan"),
        ("--probe-radii-mm", "0"),
        ("--probe-radii-mm", "-5"),
        ("--push-mm", "NaN"),
        ("--push-mm", "-1"),
        ("--probes", "0"),
        ("--viewpoint", "1,nan,2"),
        ("--viewpoint", "1,2"),
    ] {
        let stderr = stderr_of(&["eval", "cube", "cube", "--contact", flag, value]);
        assert!(
            stderr.contains("invalid value") && stderr.contains(flag),
            "{flag} {value}: {stderr}"
        );
    }
    let stderr = stderr_of(&["eval", "cube", "cube", "--push-mm", "5"]);
    assert!(stderr.contains("--contact"), "{stderr}");
}

/// Rates and durations that once aborted the subscriber's daemon or `run` itself are refused
/// by clap with the range they must be in, before anything connects or starts.
#[test]
fn absurd_rates_and_durations_are_clap_errors() {
    for value in ["1e-45", "-1", "inf", "1e6"] {
        let stderr = stderr_of(&["subscribe", "--max-rate-hz", value, "--count", "1"]);
        assert!(
            stderr.contains("invalid value") && stderr.contains("0 (no cap)"),
            "--max-rate-hz {value}: {stderr}"
        );
    }
    for value in ["inf", "-1", "1e30", "NaN"] {
        let out = tacmesh(&[
            "run",
            "--duration-s",
            value,
            "--socket",
            "/nonexistent/t.sock",
        ]);
        assert_eq!(out.status.code(), Some(2), "--duration-s {value}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains("a year"), "--duration-s {value}: {stderr}");
    }
}

/// An output mesh of a kind that cannot be written is refused before the cloud is read and
/// meshed (it once failed only after the work).
#[test]
fn an_unwritable_output_mesh_is_refused_before_meshing() {
    let stderr = stderr_of(&["mesh", "/nonexistent/cloud.ply", "-o", "x.stl"]);
    assert!(
        stderr.contains("x.stl") && stderr.contains(".ply or .obj"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("cloud.ply"),
        "the cloud was read first: {stderr}"
    );
}

/// A device or a FIFO given as a file (`/dev/zero` behind a `.ply` or `.png` name, a FIFO as
/// a recording) is refused at once, saying what it is: it was once read without end, or
/// blocked the start waiting for a writer.
#[test]
fn devices_and_fifos_given_as_files_are_refused_at_once() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let zero = dir.path().join("zero.ply");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("a symlink");
    let stderr = stderr_of(&["mesh", path_str(&zero), "-o", "x.ply"]);
    assert!(stderr.contains("a device"), "{stderr}");
    let zero_png = dir.path().join("zero.png");
    std::os::unix::fs::symlink("/dev/zero", &zero_png).expect("a symlink");
    let spec = format!("replay:{}?fx=500&fy=500&cx=320&cy=240", zero_png.display());
    let stderr = stderr_of(&["run", "--sensor", &spec, "--socket", "/nonexistent/t.sock"]);
    assert!(stderr.contains("a device"), "{stderr}");
    let fifo = dir.path().join("take.oni");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let spec = format!("replay:{}", fifo.display());
        let stderr = stderr_of(&["run", "--sensor", &spec, "--socket", "/nonexistent/t.sock"]);
        assert!(stderr.contains("FIFO"), "{stderr}");
    }
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

/// Without `$USER` and `$XDG_RUNTIME_DIR` (a cron job, `env -i`, a bare service), the default
/// socket is named by the numeric user id, which is always known, the same for the daemon
/// and the client.
#[test]
fn default_socket_without_user_or_runtime_dir_is_named_by_uid() {
    use std::os::unix::fs::MetadataExt;
    let uid = std::fs::metadata("/proc/self").expect("procfs").uid();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .args(["subscribe", "--count", "0"])
        .env_remove("USER")
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("TMPDIR")
        .env("RUST_LOG", "warn")
        .output()
        .expect("the tacmesh binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let expected = format!("/tmp/tacmesh-{uid}/tacmesh.sock");
    // A daemon of this user may be serving there; then the client connects, prints where and
    // stops (`--count 0`).
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stderr.contains(&expected) || stdout.contains(&expected),
        "{stderr}{stdout}"
    );
}

/// Each cause is said once: an error whose message includes its cause does not also hand it
/// on as a source, which `main`'s chain printer would print a second time
/// ("… (os error 2): No such file or directory (os error 2)").
#[test]
fn a_missing_file_or_daemon_is_said_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let socket = dir.path().join("nobody.sock");
    let scene = format!("sim:{}", dir.path().join("nope.toml").display());
    for args in [
        vec!["run", "--config", "/nonexistent/tacmesh.toml"],
        vec!["run", "--sensor", &scene, "--duration-s", "0"],
        vec!["subscribe", "--socket", path_str(&socket)],
    ] {
        let stderr = stderr_of(&args);
        assert_eq!(
            stderr.matches("os error 2").count(),
            1,
            "tacmesh {args:?}: {stderr}"
        );
    }
}

/// A missing recording, bag or scene file is reported with the OS's reason once: the error
/// chain printed by `main` must not repeat it.
#[test]
fn missing_sensor_file_says_no_such_file_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let socket = path_str(&dir.path().join("tacmesh.sock")).to_owned();
    for spec in [
        "replay:/nonexistent/recording.oni",
        "replay:/nonexistent/recording.bag",
        "replay:/nonexistent/cloud.pcd",
        "sim:/nonexistent/scene.toml",
    ] {
        let stderr = stderr_of(&["run", "--sensor", spec, "--socket", &socket]);
        assert_eq!(stderr.matches("os error 2").count(), 1, "{spec}: {stderr}");
        assert!(stderr.contains("/nonexistent/"), "{spec}: {stderr}");
    }
}

/// A voxel finer than the data's spacing leaves no neighbourhood with enough points; that is
/// what the error says, with the voxel size that would do, not "too few points".
#[test]
fn voxel_finer_than_the_point_spacing_says_so() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("plane.xyz");
    // A 40 × 40 grid, 1 cm apart, on a gentle slope.
    let mut text = String::new();
    for i in 0..40 {
        for j in 0..40 {
            let (x, y) = (i as f32 * 0.01, j as f32 * 0.01);
            text += &format!("{x} {y} {}\n", 0.2 * x);
        }
    }
    std::fs::write(&path, text).expect("write");
    let out = path_str(&dir.path().join("out.ply")).to_owned();
    let stderr = stderr_of(&["mesh", path_str(&path), "-o", &out, "--voxel-m", "0.001"]);
    assert!(
        stderr.contains("voxel size 0.001 m is finer than the points are spaced (0.01 m"),
        "{stderr}"
    );
    assert!(stderr.contains("at least 0.01 m"), "{stderr}");
    assert!(!stderr.contains("too few points"), "{stderr}");
}

/// Offline output that once said nothing of what went wrong: a cloud spread too far to fuse
/// gives no surface (it wrote an empty mesh, exit 0), an absurd voxel is refused by clap,
/// `--objects` that finds nothing fails saying so, and a mesh file in millimetres given to
/// `eval` or `sim sample` is warned about as `mesh` warns of a cloud.
#[test]
fn offline_results_with_nothing_in_them_or_in_other_units_are_said() {
    let dir = tempfile::tempdir().expect("temp dir");
    let spread = dir.path().join("spread.xyz");
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2e30 - 1e30
    };
    let text: String = (0..1000)
        .map(|_| format!("{} {} {}\n", next(), next(), next()))
        .collect();
    std::fs::write(&spread, text).expect("write");
    let out = path_str(&dir.path().join("out.ply")).to_owned();
    let stderr = stderr_of(&["mesh", path_str(&spread), "-o", &out]);
    assert!(
        stderr.contains("no surface") || stderr.contains("spread"),
        "{stderr}"
    );
    assert!(
        !std::path::Path::new(&out).exists(),
        "an empty mesh was written"
    );
    for voxel in ["1e30", "0", "-1", "NaN"] {
        let stderr = stderr_of(&["mesh", path_str(&spread), "-o", &out, "--voxel-m", voxel]);
        assert!(stderr.contains("from 0.0001 to 10"), "{voxel}: {stderr}");
    }

    // A flat floor alone: a support, no object.
    let floor = dir.path().join("floor.xyz");
    let mut text = String::new();
    for i in 0..60 {
        for j in 0..60 {
            let (x, y) = (i as f32 * 0.01 - 0.3, j as f32 * 0.01 - 0.3);
            text += &format!("{x} {y} 1.0\n");
        }
    }
    std::fs::write(&floor, text).expect("write");
    let objects = path_str(&dir.path().join("objects")).to_owned();
    let stderr = stderr_of(&["mesh", path_str(&floor), "-o", &objects, "--objects"]);
    assert!(stderr.contains("no object found"), "{stderr}");

    // A tetrahedron 1,000 units across: a metre-sized one written in millimetres.
    let big = dir.path().join("big.obj");
    std::fs::write(
        &big,
        "v 0 0 0\nv 1000 0 0\nv 0 1000 0\nv 0 0 1000\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .expect("write");
    let eval = crate::util::tacmesh(&["eval", "cube", path_str(&big)]);
    let cloud = path_str(&dir.path().join("c.ply")).to_owned();
    let sample = crate::util::tacmesh(&[
        "sim",
        "sample",
        path_str(&big),
        "-o",
        &cloud,
        "--points",
        "1000",
    ]);
    for (what, out) in [("eval", eval), ("sim sample", sample)] {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains("1000 m across") && stderr.contains("millimetres"),
            "{what}: {stderr}"
        );
    }
}

#[test]
fn identical_points_say_they_coincide() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("same.xyz");
    std::fs::write(&path, "0.5 0.25 1\n".repeat(100)).expect("write");
    let out = path_str(&dir.path().join("out.ply")).to_owned();
    for extra in [&[][..], &["--voxel-m", "0.01"][..]] {
        let mut args = vec!["mesh", path_str(&path), "-o", &out];
        args.extend(extra);
        let stderr = stderr_of(&args);
        assert!(
            stderr.contains("all 100 points coincide, at 0.5,0.25,1"),
            "{stderr}"
        );
        assert!(!stderr.contains("voxel size 0 m"), "{stderr}");
    }
}

/// `mesh --help` names every cloud extension the reader takes: the list in the reader's own
/// error for an unknown extension.
#[test]
fn mesh_help_names_every_cloud_extension_the_reader_takes() {
    let stderr = stderr_of(&["mesh", "scan.las", "-o", "/tmp/never.ply"]);
    let supported = stderr
        .split("point clouds can be ")
        .nth(1)
        .unwrap_or_else(|| panic!("no list of extensions: {stderr}"));
    let extensions: Vec<&str> = supported
        .split([',', ' ', '\n'])
        .filter(|word| word.starts_with('.'))
        .collect();
    assert!(extensions.len() >= 5, "{stderr}");
    let help = crate::util::tacmesh_ok(&["mesh", "--help"]);
    // The CLOUD argument's own help, not `labels.txt` further down.
    let cloud_help = help
        .split("Arguments:")
        .nth(1)
        .and_then(|rest| rest.split("Options:").next())
        .unwrap_or_else(|| panic!("no CLOUD argument: {help}"));
    for extension in extensions {
        assert!(
            cloud_help.contains(extension),
            "mesh --help omits {extension}: {cloud_help}"
        );
    }
}

#[test]
fn capture_of_a_missing_recording_or_a_bad_spec_is_an_error_not_a_panic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("frames");
    let out = out.to_str().expect("a UTF-8 path");
    let stderr = stderr_of(&[
        "capture",
        "--sensor",
        "replay:/nonexistent/x.oni",
        "--out",
        out,
    ]);
    assert!(stderr.contains("/nonexistent/x.oni"), "{stderr}");
    let stderr = stderr_of(&["capture", "--sensor", "nosuch:thing", "--out", out]);
    assert!(stderr.contains("nosuch"), "{stderr}");
}

/// A recording shorter than `--frames` is captured whole, and the shortfall said (exit 0); one
/// that ends before the first frame to write is an error.
#[test]
fn capture_of_a_short_recording_writes_what_it_has() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("frames");
    let out = path_str(&out);
    let scan = crate::util::test_data("pointclouds/pcl/table_scene_mug_stereo_textured.pcd");
    let spec = format!("replay:{}", scan.display());
    let run = crate::util::tacmesh(&["capture", "--sensor", &spec, "--frames", "2", "--out", out]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("wrote 1 of the 2 asked for"), "{stderr}");
    assert!(dir.path().join("frames/frame-0.ply").exists());
    let stderr = stderr_of(&["capture", "--sensor", &spec, "--skip", "1", "--out", out]);
    assert!(stderr.contains("ended after 1 frames"), "{stderr}");
}
