//! The offline pipeline end to end through the CLI: sample a shape with the paper's 20 mm
//! noise, mesh it with the defaults, judge it against the ground truth.

use crate::util::{path_str, tacmesh, tacmesh_json, tacmesh_logging, tacmesh_ok};

/// Samples `shape`, meshes it, evaluates it; returns (faces, recon_faces, mhe).
fn sample_mesh_eval(shape: &str, seed: &str) -> (u64, u64, f64) {
    let dir = tempfile::tempdir().expect("temp dir");
    let cloud = dir.path().join(format!("{shape}.ply"));
    let mesh = dir.path().join(format!("{shape}_mesh.ply"));
    tacmesh_ok(&[
        "sim",
        "sample",
        shape,
        "--noise-mm",
        "20",
        "--points",
        "50000",
        "--seed",
        seed,
        "-o",
        path_str(&cloud),
    ]);
    let report = tacmesh_json(&["mesh", path_str(&cloud), "-o", path_str(&mesh), "--json"]);
    let eval = tacmesh_json(&["eval", shape, path_str(&mesh), "--json"]);
    let faces = report["faces"].as_u64().expect("faces");
    assert_eq!(
        eval["faces"].as_u64(),
        Some(faces),
        "eval reads what mesh wrote"
    );
    assert!(
        report["max_residual"].as_f64().expect("max_residual")
            <= report["max_residual_bound_m"].as_f64().expect("bound") + 1e-6
    );
    for stage in [
        "normals_ms",
        "distance_ms",
        "marching_cubes_ms",
        "simplify_ms",
        "total_ms",
    ] {
        assert!(report[stage].as_f64().is_some(), "report has {stage}");
    }
    (
        faces,
        report["recon_faces"].as_u64().expect("recon_faces"),
        eval["mhe"].as_f64().expect("mhe"),
    )
}

// Bounds: the paper's Table 1 (cube: 118 faces at MHE 0.00488 m; torus: 134 faces at
// 0.0143 m) with room for seed-to-seed spread; BENCHMARKS.md has the medians, well inside.

#[test]
fn cube_at_20mm_noise_beats_table1() {
    let (faces, recon_faces, mhe) = sample_mesh_eval("cube", "7");
    assert!(
        recon_faces > 1000,
        "marching cubes gives a dense mesh first: {recon_faces}"
    );
    assert!(faces <= 118, "cube faces {faces}");
    assert!(mhe <= 0.00488, "cube MHE {mhe}");
}

#[test]
fn torus_at_20mm_noise_beats_table1() {
    let (faces, _, mhe) = sample_mesh_eval("torus", "8");
    assert!(faces <= 134, "torus faces {faces}");
    assert!(mhe <= 0.0143, "torus MHE {mhe}");
}

/// The README's offline example runs as written (with this build's binary for `cargo run
/// --release -q --`) and leaves no file in the folder it is run from, the repository root for
/// a reader following the README.
#[test]
fn readme_offline_example_runs_and_leaves_no_files_behind() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).expect("README");
    let section = readme
        .split("## The offline pipeline")
        .nth(1)
        .expect("an offline pipeline section");
    let example = section
        .split("```sh\n")
        .nth(1)
        .and_then(|block| block.split("```").next())
        .expect("a shell example");
    assert!(example.contains("cargo run --release -q --"), "{example}");
    let script = example.replace(
        "cargo run --release -q --",
        &format!("'{}'", env!("CARGO_BIN_EXE_tacmesh")),
    );
    let cwd = tempfile::tempdir().expect("temp dir");
    let tmp = tempfile::tempdir().expect("temp dir");
    let out = std::process::Command::new("sh")
        .args(["-c", &script])
        .current_dir(cwd.path())
        .env("TMPDIR", tmp.path())
        .env("RUST_LOG", "warn")
        .output()
        .expect("sh runs");
    assert!(
        out.status.success(),
        "{script}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let left: Vec<_> = std::fs::read_dir(cwd.path()).expect("lists").collect();
    assert!(left.is_empty(), "the example left {left:?} behind");
}

/// A scanner's misses written as `nan` and `inf` in an ascii PLY are left out and counted, in
/// `--json` and in the log, as in every other format; they do not fail the file.
#[test]
fn non_finite_points_in_an_ascii_ply_are_left_out_and_counted() {
    let dir = tempfile::tempdir().expect("temp dir");
    let xyz = dir.path().join("cube.xyz");
    tacmesh_ok(&[
        "sim",
        "sample",
        "cube",
        "--points",
        "20000",
        "--seed",
        "1",
        "-o",
        path_str(&xyz),
    ]);
    let lines: Vec<String> = std::fs::read_to_string(&xyz)
        .expect("sampled cloud")
        .lines()
        .map(str::to_owned)
        .collect();
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nend_header\n",
        lines.len() + 2
    );
    for (i, line) in lines.iter().enumerate() {
        if i == 100 {
            ply += "nan nan nan\n0.1 inf 0.2\n";
        }
        ply += line;
        ply.push('\n');
    }
    let cloud = dir.path().join("cube.ply");
    std::fs::write(&cloud, ply).expect("write the ascii PLY");
    let mesh = dir.path().join("mesh.ply");
    let out = tacmesh_logging(
        &["mesh", path_str(&cloud), "-o", path_str(&mesh), "--json"],
        "info",
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(report["non_finite_points"], 2, "{report}");
    assert_eq!(report["points"], lines.len(), "{report}");
    assert!(
        stderr.contains("left out 2 points with a NaN or infinite coordinate"),
        "{stderr}"
    );
}

/// The paper's 1 m torus written in millimetres meshed as a 954 m object without a word; now
/// a warning names the fix, `--scale 0.001`, and that fix meshes it as the metre-sized torus.
#[test]
fn millimetre_cloud_is_warned_about_and_scale_makes_it_metres() {
    let dir = tempfile::tempdir().expect("temp dir");
    let metres = dir.path().join("torus.xyz");
    tacmesh_ok(&[
        "sim",
        "sample",
        "torus",
        "--points",
        "20000",
        "--seed",
        "2",
        "-o",
        path_str(&metres),
    ]);
    let millimetres: String = std::fs::read_to_string(&metres)
        .expect("sampled cloud")
        .lines()
        .map(|line| {
            let mm: Vec<String> = line
                .split_whitespace()
                .map(|v| (v.parse::<f64>().expect("a number") * 1000.0).to_string())
                .collect();
            mm.join(" ") + "\n"
        })
        .collect();
    let cloud = dir.path().join("torus_mm.xyz");
    std::fs::write(&cloud, millimetres).expect("write the millimetre cloud");
    let mesh = dir.path().join("mesh.ply");
    let mesh_args = |scale: Option<&str>| {
        let mut args = vec!["mesh", path_str(&cloud), "-o", path_str(&mesh), "--json"];
        if let Some(factor) = scale {
            args.extend(["--scale", factor]);
        }
        let out = tacmesh(&args);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stderr}");
        let report: serde_json::Value =
            serde_json::from_slice(&out.stdout).expect("one JSON object");
        (report["extent_m"].as_f64().expect("extent"), stderr)
    };

    let (extent_m, stderr) = mesh_args(None);
    assert!(extent_m > 900.0, "{extent_m}");
    assert!(
        stderr.contains("m across, more than a depth camera sees"),
        "{stderr}"
    );
    assert!(stderr.contains("--scale 0.001"), "{stderr}");

    let (extent_m, stderr) = mesh_args(Some("0.001"));
    assert!((0.9..1.0).contains(&extent_m), "{extent_m}");
    assert!(!stderr.contains("WARN"), "{stderr}");
    let eval = tacmesh_json(&["eval", "torus", path_str(&mesh), "--json"]);
    let mhe = eval["mhe"].as_f64().expect("mhe");
    assert!(mhe <= 0.0143, "torus MHE {mhe} after --scale 0.001");
}

/// `eval --contact --json` on a meshed cube: the contact object has every radius asked for and
/// every figure, in plausible bounds (BENCHMARKS.md has the cube at about 1 mm first-contact
/// error and under 1° median normal error with 20 mm noise), and the MHE fields are unchanged.
#[test]
fn eval_contact_reports_every_radius_in_millimetres_and_degrees() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cloud = dir.path().join("cube.ply");
    let mesh = dir.path().join("cube_mesh.ply");
    tacmesh_ok(&[
        "sim",
        "sample",
        "cube",
        "--noise-mm",
        "20",
        "--seed",
        "3",
        "-o",
        path_str(&cloud),
    ]);
    tacmesh_ok(&["mesh", path_str(&cloud), "-o", path_str(&mesh)]);
    let plain = tacmesh_json(&["eval", "cube", path_str(&mesh), "--json"]);
    assert!(plain.get("contact").is_none(), "{plain}");
    let eval = tacmesh_json(&[
        "eval",
        "cube",
        path_str(&mesh),
        "--json",
        "--contact",
        "--probe-radii-mm",
        "5,20",
        "--probes",
        "1000",
    ]);
    assert_eq!(eval["mhe"], plain["mhe"], "--contact leaves the MHE alone");
    let contact = &eval["contact"];
    assert_eq!(contact["push_mm"], 10.0, "{contact}");
    assert_eq!(contact["probe_lines"], 1000, "{contact}");
    let radii: Vec<f64> = contact["per_radius"]
        .as_array()
        .expect("per_radius")
        .iter()
        .map(|r| r["probe_radius_mm"].as_f64().expect("probe_radius_mm"))
        .collect();
    assert_eq!(radii, [5.0, 20.0], "{contact}");
    let mut rows: Vec<&serde_json::Value> = contact["per_radius"]
        .as_array()
        .expect("per_radius")
        .iter()
        .collect();
    rows.push(&contact["overall"]);
    for row in rows {
        let probes = row["probes"].as_u64().expect("probes");
        assert!(probes > 300, "{row}");
        let misses = row["missed_by_candidate"].as_u64().expect("missed")
            + row["extra_in_candidate"].as_u64().expect("extra");
        assert!(misses * 20 < probes, "fewer than 5 % misses: {row}");
        let figure = |name: &str, stat: &str| {
            row[name][stat]
                .as_f64()
                .unwrap_or_else(|| panic!("{name}.{stat} in {row}"))
        };
        for name in [
            "first_contact_mm",
            "first_contact_along_approach_mm",
            "normal_deg",
            "penetration_mm",
        ] {
            assert!(
                0.0 <= figure(name, "p50")
                    && figure(name, "p50") <= figure(name, "p95")
                    && figure(name, "p95") <= figure(name, "max"),
                "{name}: {row}"
            );
            assert!(figure(name, "mean") <= figure(name, "max"), "{name}: {row}");
        }
        assert!(figure("first_contact_mm", "mean") < 4.0, "{row}");
        assert!(
            figure("first_contact_mm", "max") <= 50.0 + 1e-3,
            "capped: {row}"
        );
        assert!(figure("normal_deg", "p50") < 3.0, "{row}");
        assert!(figure("penetration_mm", "mean") < 4.0, "{row}");
    }
}

/// Samples `shape` with `points` points and `noise_m` of noise (seed `seed`), meshes the cloud
/// with the default pipeline, and judges the mesh against the shape (MHE over 20,000 samples
/// per side, metres): the robustness tests of issue 14 below.
fn mesh_sampled_shape(
    shape: tacmesh::sim::Shape,
    points: usize,
    noise_m: f32,
    seed: u64,
) -> (tacmesh::pipeline::MeshReport, f64) {
    use tacmesh::pipeline::{mesh_cloud, MeshConfig};
    use tacmesh::sim::{mesh_distance, sample_cloud, SampleConfig};
    let truth = shape.mesh();
    let cloud = sample_cloud(
        &truth,
        &SampleConfig {
            points,
            noise_sigma_m: noise_m,
            seed,
        },
    )
    .expect("samples");
    let (mesh, report) = mesh_cloud(&cloud, &MeshConfig::default()).expect("meshes");
    let mhe = mesh_distance(&truth, &mesh, 20_000, 1)
        .expect("measures")
        .mhe_m;
    (report, mhe)
}

/// Issue 14's robustness bounds, on seeds the tuning did not see: at 40 mm noise (40,000
/// points) and at 5,000 points (20 mm noise, and none) every shape comes out as one closed piece with no
/// more faces than the paper's Table 1 gives at 20 mm and dense clouds, and within 1.5 times
/// its error. Before the voxel followed the noise and the spacing, the cube had 490–717 faces
/// at 40 mm, and at 5,000 points every mesh was open and in pieces.
#[test]
fn high_noise_and_sparse_clouds_close_with_few_faces() {
    use tacmesh::sim::Shape;
    // (shape, Table 1's faces, Table 1's MHE in metres)
    let table1 = [
        (Shape::Cone, 104, 0.00887),
        (Shape::Cube, 118, 0.00488),
        (Shape::Cylinder, 158, 0.00748),
        (Shape::Monkey, 926, 0.0213),
        (Shape::Torus, 134, 0.0143),
        (Shape::Sphere, 116, 0.0111),
    ];
    let mut failures = Vec::new();
    for (points, noise_m) in [(40_000, 0.04), (5_000, 0.02), (5_000, 0.0)] {
        for (shape, faces_bound, mhe_bound) in table1 {
            let (report, mhe) = mesh_sampled_shape(shape, points, noise_m, 21);
            let line = format!(
                "{} at {points} points, {:.0} mm: {} faces, {} pieces, closed {}, MHE {mhe:.5} \
                 (voxel {:.1} mm, noise {:.1} mm, spacing {:.1} mm)",
                shape.name(),
                noise_m * 1e3,
                report.faces,
                report.pieces,
                report.closed,
                report.voxel_size_m * 1e3,
                report.noise_m * 1e3,
                report.spacing_m * 1e3,
            );
            println!("{line}");
            if !(report.closed
                && report.pieces == 1
                && report.faces <= faces_bound
                && mhe <= 1.5 * mhe_bound)
            {
                failures.push(line);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue 14's noise and sparsity together, on seeds the tuning did not see: at 40 mm noise
/// from 5,000 points the cone, cube, cylinder and sphere come out as one closed piece with no
/// more faces than Table 1 gives at 20 mm and dense clouds, on the coarser marching-cubes grid
/// ([`tacmesh::pipeline::noise_dominates`]), and within twice Table 1's error (the cube's
/// 6.5-9.3 mm misses Table 1's 4.88 mm on these seeds). Meshed on every voxel corner the noise
/// stayed as bumps: cone 120-146 faces on seeds 41-43.
#[test]
fn noisy_sparse_clouds_close_with_few_faces_on_the_coarser_grid() {
    use tacmesh::sim::Shape;
    // (shape, Table 1's faces, Table 1's MHE in metres)
    let table1 = [
        (Shape::Cone, 104, 0.00887),
        (Shape::Cube, 118, 0.00488),
        (Shape::Cylinder, 158, 0.00748),
        (Shape::Sphere, 116, 0.0111),
    ];
    let mut failures = Vec::new();
    for (shape, faces_bound, mhe_bound) in table1 {
        for seed in [41, 42] {
            let (report, mhe) = mesh_sampled_shape(shape, 5_000, 0.04, seed);
            let line = format!(
                "{} seed {seed}: {} faces (marching-cubes step {}), {} pieces, closed {}, \
                 MHE {mhe:.5} (noise {:.1} mm, voxel {:.1} mm)",
                shape.name(),
                report.faces,
                report.mesh_step_voxels,
                report.pieces,
                report.closed,
                report.noise_m * 1e3,
                report.voxel_size_m * 1e3,
            );
            println!("{line}");
            if !(report.mesh_step_voxels == 2
                && report.closed
                && report.pieces == 1
                && report.faces <= faces_bound
                && mhe <= 2.0 * mhe_bound)
            {
                failures.push(line);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The noise's tails left out of the fit (`tacmesh::pipeline::NOISE_TAIL_FRACTION`), on seeds
/// the tuning did not see: at 40 mm noise from 10,000 points the cone, cube and cylinder come
/// out as one closed piece within Table 1's faces and 1.1 times its error. With the tails kept
/// the fit pulled the cube's faces out after them: 6.8-7.0 mm on seeds 41-43 against Table 1's
/// 4.88 (4.5-4.9 mm without them), the cone 9.3-9.5 mm for 8.87 (8.75).
#[test]
fn noisy_clouds_are_fitted_without_the_noises_tails() {
    use tacmesh::sim::Shape;
    // (shape, Table 1's faces, Table 1's MHE in metres)
    let table1 = [
        (Shape::Cone, 104, 0.00887),
        (Shape::Cube, 118, 0.00488),
        (Shape::Cylinder, 158, 0.00748),
    ];
    let mut failures = Vec::new();
    for (shape, faces_bound, mhe_bound) in table1 {
        for seed in [41, 42] {
            let (report, mhe) = mesh_sampled_shape(shape, 10_000, 0.04, seed);
            let line = format!(
                "{} seed {seed}: {} faces, {} pieces, closed {}, MHE {mhe:.5} for {mhe_bound} \
                 (noise {:.1} mm, voxel {:.1} mm)",
                shape.name(),
                report.faces,
                report.pieces,
                report.closed,
                report.noise_m * 1e3,
                report.voxel_size_m * 1e3,
            );
            println!("{line}");
            if !(report.closed
                && report.pieces == 1
                && report.faces <= faces_bound
                && mhe <= 1.1 * mhe_bound)
            {
                failures.push(line);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Suzanne at 40 mm noise from 5,000 points, on seeds the tuning did not see: her ears come out
/// open on the voxel the noise and the spacing give (24 mm; 391-423 faces on these seeds, on
/// every corner too), and a mesh made again on a larger voxel
/// ([`tacmesh::pipeline::LARGER_VOXEL_RETRIES`]) is one closed piece with far fewer faces,
/// within Table 1's error.
#[test]
fn a_closed_object_that_comes_out_open_is_made_again_on_a_larger_voxel() {
    let mut failures = Vec::new();
    for seed in [41, 44] {
        let (report, mhe) = mesh_sampled_shape(tacmesh::sim::Shape::Monkey, 5_000, 0.04, seed);
        let line = format!(
            "seed {seed}: {} faces, {} pieces, closed {}, MHE {mhe:.5}, voxel {:.1} mm, \
             step {}, {} retries",
            report.faces,
            report.pieces,
            report.closed,
            report.voxel_size_m * 1e3,
            report.mesh_step_voxels,
            report.closing_retries,
        );
        println!("{line}");
        if !(report.closed
            && report.pieces == 1
            && report.closing_retries >= 1
            && report.faces <= 200
            && mhe <= 0.0213)
        {
            failures.push(line);
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue 14's planes and sharp features, on seeds the tuning did not see (20 mm noise, 40,000
/// points): the cube comes out with at most 16 faces (its true 12 plus a corner's worth) and
/// the cylinder with at most 64, both closed and within Table 1's error. Before the second
/// simplification pass over the fitted mesh the cube kept 28-38 faces: chamfers at its corners
/// that marching cubes' rounding had needed.
#[test]
fn cube_and_cylinder_keep_their_planes_and_edges_with_few_faces() {
    use tacmesh::sim::Shape;
    let mut failures = Vec::new();
    for (shape, faces_bound, mhe_bound) in
        [(Shape::Cube, 16, 0.00488), (Shape::Cylinder, 64, 0.00748)]
    {
        for seed in [31, 32] {
            let (report, mhe) = mesh_sampled_shape(shape, 40_000, 0.02, seed);
            let line = format!(
                "{} seed {seed}: {} faces ({} after the first pass), closed {}, MHE {mhe:.5}",
                shape.name(),
                report.faces,
                report.first_pass_faces,
                report.closed,
            );
            println!("{line}");
            if !(report.closed && report.faces <= faces_bound && mhe <= mhe_bound) {
                failures.push(line);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue 14's density bound, on seeds the tuning did not see: at 20 mm noise the cube from
/// 20,000 points has at most 1.5 times the faces it has from 40,000 (medians), and every mesh
/// at most 16 faces, closed and within Table 1's error. With one pass after the fit the cube
/// kept 12-24 faces (24 at 40,000 points, seed 41; 18-24 at 20,000 on seeds 101-103, whose
/// coarser voxel rounds the edges more): the chamfers straighten only over several fits.
#[test]
fn the_cube_from_half_the_points_keeps_its_few_faces() {
    let mut lines = Vec::new();
    let mut faces_at = |points: usize, seed: u64| {
        let (report, mhe) = mesh_sampled_shape(tacmesh::sim::Shape::Cube, points, 0.02, seed);
        lines.push(format!(
            "{points} points, seed {seed}: {} faces ({} after the first pass), closed {}, \
             MHE {mhe:.5}",
            report.faces, report.first_pass_faces, report.closed
        ));
        assert!(
            report.closed && report.faces <= 16 && mhe <= 0.00488,
            "{lines:#?}"
        );
        report.faces
    };
    let (mut dense, mut half) = (Vec::new(), Vec::new());
    for seed in [41, 42, 43] {
        dense.push(faces_at(40_000, seed));
        half.push(faces_at(20_000, seed));
    }
    println!("{lines:#?}");
    let median = |mut v: Vec<usize>| {
        v.sort_unstable();
        v[v.len() / 2]
    };
    let (dense, half) = (median(dense), median(half));
    assert!(
        2 * half <= 3 * dense,
        "median {half} faces at 20,000 points against {dense} at 40,000: {lines:#?}"
    );
}

/// The error-target mode aims at a mean error with as few faces as that allows: at Table 1's
/// MHE the sphere needs half Table 1's faces (116 / 2), and its error stays under the target
/// (an unseen seed). It takes no residual bound beside it.
#[test]
fn error_target_mode_reaches_half_table1_faces_on_the_sphere() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cloud = dir.path().join("sphere.ply");
    let mesh = dir.path().join("sphere_mesh.ply");
    tacmesh_ok(&[
        "sim",
        "sample",
        "sphere",
        "--points",
        "50000",
        "--seed",
        "9",
        "-o",
        path_str(&cloud),
    ]);
    let report = tacmesh_json(&[
        "mesh",
        path_str(&cloud),
        "-o",
        path_str(&mesh),
        "--target-mhe-m",
        "0.0111",
        "--json",
    ]);
    let eval = tacmesh_json(&["eval", "sphere", path_str(&mesh), "--json"]);
    let faces = report["faces"].as_u64().expect("faces");
    let mhe = eval["mhe"].as_f64().expect("mhe");
    assert!(faces <= 58, "sphere faces {faces}");
    assert!(mhe <= 0.0111, "sphere MHE {mhe}");

    let both = tacmesh(&[
        "mesh",
        path_str(&cloud),
        "-o",
        path_str(&mesh),
        "--target-mhe-m",
        "0.01",
        "--max-residual-m",
        "0.02",
    ]);
    assert!(!both.status.success());
    let bad = tacmesh(&[
        "mesh",
        path_str(&cloud),
        "-o",
        path_str(&mesh),
        "--target-mhe-m",
        "-1",
    ]);
    assert!(
        String::from_utf8_lossy(&bad.stderr).contains("expected a mean error in metres > 0"),
        "{}",
        String::from_utf8_lossy(&bad.stderr)
    );
}

/// The first `mass="…"` of an MJCF text (a body's inertial), kilograms.
fn first_mass(xml: &str) -> f64 {
    xml.split(r#"mass=""#)
        .nth(1)
        .and_then(|rest| rest.split('"').next())
        .and_then(|m| m.parse().ok())
        .expect("an inertial mass")
}

/// `mesh --mjcf/--sdf/--urdf` writes the body `subscribe` would keep: one closed cloud gives
/// one free body whose mass is its volume at 500 kg/m³; a real one-view scan with --objects
/// gives its objects on the table as a finite slab.
#[test]
fn mesh_writes_the_physics_body_of_an_offline_cloud() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cloud = dir.path().join("cube.ply");
    tacmesh_ok(&[
        "sim",
        "sample",
        "cube",
        "--noise-mm",
        "5",
        "--points",
        "20000",
        "--seed",
        "1",
        "-o",
        path_str(&cloud),
    ]);
    let scene_dir = dir.path().join("scene");
    let report = tacmesh_json(&[
        "mesh",
        path_str(&cloud),
        "-o",
        path_str(&dir.path().join("cube.obj")),
        "--mjcf",
        path_str(&scene_dir),
        "--urdf",
        path_str(&scene_dir),
        "--json",
    ]);
    let volume = report["volume_m3"]
        .as_f64()
        .expect("a closed mesh has a volume");
    let xml = std::fs::read_to_string(scene_dir.join("scene.xml")).expect("scene.xml");
    assert_eq!(xml.matches("<freejoint").count(), 1, "{xml}");
    let mass = first_mass(&xml);
    // The body is the mesh's convex parts; its mass the mesh's own volume at 500 kg/m³.
    assert!(
        (mass / (500.0 * volume) - 1.0).abs() < 0.02,
        "{mass} kg for {volume} m³"
    );
    let index = std::fs::read_to_string(scene_dir.join("urdf/scene.json")).expect("scene.json");
    assert!(index.contains(r#""static": false"#), "{index}");

    let milk = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/testdata/pointclouds/pcl/milk_cartoon_all_small_clorox.pcd"
    );
    let objects_dir = dir.path().join("objects");
    let scene_dir = dir.path().join("milk");
    let out = tacmesh_logging(
        &[
            "mesh",
            milk,
            "--objects",
            "-o",
            path_str(&objects_dir),
            "--mjcf",
            path_str(&scene_dir),
        ],
        "info",
    );
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    let xml = std::fs::read_to_string(scene_dir.join("scene.xml")).expect("scene.xml");
    assert!(xml.contains(r#"class="support" type="box""#), "{xml}");
    assert!(!xml.contains(r#"type="plane""#), "{xml}");
    assert!(xml.matches("<freejoint").count() >= 4, "{log}\n{xml}");
}

/// `tacmesh capture` of the static tabletop's first frame, with `extra` arguments, into
/// `dir/frames`; returns that folder.
fn capture_static_tabletop(dir: &std::path::Path, extra: &[&str]) -> std::path::PathBuf {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/static.toml");
    let frames = dir.join("frames");
    let sensor = format!("sim:{scene}");
    let mut args = vec!["capture", "--sensor", &sensor, "--frames", "1"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", path_str(&frames)]);
    tacmesh_ok(&args);
    frames
}

/// `mesh --objects --mjcf` on a frame of the static tabletop captured in its z-up world frame
/// (`tacmesh capture`, then `--up 0,0,1` and the camera as the viewpoint) makes the bodies the
/// daemon makes: the cube a box, the ball a sphere, each near its true mass, and the torus its
/// shell turned about its axis, its mass within issue 40's bounds for a shape that is no
/// primitive (the shadow volume it had was twice the torus).
#[test]
fn mesh_objects_makes_the_daemons_bodies_of_a_captured_frame() {
    let dir = tempfile::tempdir().expect("temp dir");
    let frames = capture_static_tabletop(dir.path(), &[]);
    let out = dir.path().join("objects");
    let physics = dir.path().join("scene");
    // The demo camera: 1.2 m from the table's centre, 45° above it.
    let eye = 1.2 * std::f32::consts::FRAC_1_SQRT_2;
    let run = tacmesh_logging(
        &[
            "mesh",
            path_str(&frames.join("frame-0.ply")),
            "--objects",
            "--up",
            "0,0,1",
            &format!("--viewpoint=0,{},{eye}", -eye),
            "-o",
            path_str(&out),
            "--mjcf",
            path_str(&physics),
        ],
        "info",
    );
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{log}");
    assert!(log.contains("planes=1 objects=3"), "{log}");
    let xml = std::fs::read_to_string(physics.join("scene.xml")).expect("scene.xml");
    // Each object body's mass (500 kg/m³) and its collision geoms' types.
    let bodies: Vec<(f64, String)> = xml
        .split(r#"<body name="object-"#)
        .skip(1)
        .map(|body| {
            let mass = first_mass(body);
            let end = body.find("</body>").unwrap_or(body.len());
            (mass, body[..end].to_owned())
        })
        .collect();
    assert_eq!(bodies.len(), 3, "{xml}");
    let density = 500.0;
    let cube = 0.2f64.powi(3);
    let ball = 4.0 / 3.0 * std::f64::consts::PI * 0.1f64.powi(3);
    // The torus fitted into 0.2 m: tube radius 2 cm about a 8 cm ring.
    let torus = 2.0 * std::f64::consts::PI.powi(2) * 0.08 * 0.02f64.powi(2);
    let (cube_body, ball_body, torus_body) = (&bodies[0], &bodies[1], &bodies[2]);
    assert!(cube_body.1.contains(r#"type="box""#), "{}", cube_body.1);
    assert!(ball_body.1.contains(r#"type="sphere""#), "{}", ball_body.1);
    for (name, (mass, _), truth, range) in [
        ("cube", cube_body, cube, 0.8..1.25),
        ("ball", ball_body, ball, 0.8..1.25),
        ("torus", torus_body, torus, 0.7..1.5),
    ] {
        let ratio = mass / (density * truth);
        assert!(range.contains(&ratio), "{name}: {ratio}× its mass");
    }
}

/// `capture --segments` draws how the daemon cuts a frame: on the static tabletop, the range
/// image beside the segmentation, in which the table is a support and the three shapes are an
/// object each, in the first three object colours.
#[test]
fn capture_draws_the_daemons_segments_of_a_frame() {
    let dir = tempfile::tempdir().expect("temp dir");
    let frames = capture_static_tabletop(dir.path(), &["--segments"]);
    let file = std::fs::File::open(frames.join("frame-0-segments.png")).expect("the picture");
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .expect("a PNG");
    let mut rgb = vec![0; reader.output_buffer_size().expect("its size")];
    let info = reader.next_frame(&mut rgb).expect("its pixels");
    assert_eq!((info.width, info.height), (2 * 640, 480));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    // The right half: the segmentation.
    let mut counts: std::collections::BTreeMap<[u8; 3], usize> = Default::default();
    for row in rgb.chunks_exact(3 * 1280) {
        for px in row[3 * 640..].chunks_exact(3) {
            *counts.entry([px[0], px[1], px[2]]).or_default() += 1;
        }
    }
    let support = counts.get(&[170, 200, 235]).copied().unwrap_or(0);
    assert!(
        support > 640 * 480 / 4,
        "{support} support pixels: {counts:?}"
    );
    for object in [[230, 25, 75], [60, 180, 75], [255, 225, 25]] {
        let n = counts.get(&object).copied().unwrap_or(0);
        assert!(n > 1000, "{n} pixels of {object:?}: {counts:?}");
    }
    // A fourth object colour would be a fourth object.
    assert_eq!(counts.get(&[0, 130, 200]), None, "{counts:?}");
}
