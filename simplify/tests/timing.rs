//! Timing and face-count reports (all `#[ignore]`d: no timed assertions). Run with
//! `cargo test -p tacmesh-simplify --release --test timing -- --ignored --nocapture`, or one of
//! them by name: `timings`, `residual_sweep`, `scaling`, `profile_loop` (set
//! `PROFILE_ITERATIONS`, e.g. under `perf record` or `valgrind --tool=callgrind`).

mod util;

use std::time::Instant;

use tacmesh_simplify::{simplify, SimplifyConfig, SimplifyReport};
use tacmesh_source::glam::Vec3;
use tacmesh_source::TriMesh;
use util::*;

fn config(max_residual_m: f32) -> SimplifyConfig {
    SimplifyConfig {
        max_residual_m,
        ..SimplifyConfig::default()
    }
}

/// Best of `runs` wall-clock milliseconds, and the last result.
fn best_of(runs: usize, mesh: &TriMesh, max_residual_m: f32) -> (f64, TriMesh, SimplifyReport) {
    let mut best = f64::INFINITY;
    let mut result = None;
    for _ in 0..runs {
        let start = Instant::now();
        let r = simplify(mesh, &config(max_residual_m)).expect("simplifies");
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
        result = Some(r);
    }
    let (out, report) = result.expect("at least one run");
    (best, out, report)
}

/// Smallest triangle quality `4√3·area/Σedge²` and smallest angle (degrees).
fn worst_shape(mesh: &TriMesh) -> (f32, f32) {
    let mut quality = f32::INFINITY;
    let mut angle = 180.0f32;
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        let sum = (b - a).length_squared() + (c - b).length_squared() + (a - c).length_squared();
        quality = quality.min(2.0 * 3f32.sqrt() * (b - a).cross(c - a).length() / sum);
        let at = |p: Vec3, q: Vec3, r: Vec3| (q - p).angle_between(r - p).to_degrees();
        angle = angle.min(at(a, b, c)).min(at(b, c, a)).min(at(c, a, b));
    }
    (quality, angle)
}

/// Mean and max distance from the input vertices to the output surface (brute force).
fn vertex_distances(input: &TriMesh, output: &TriMesh) -> (f32, f32) {
    let used: std::collections::BTreeSet<u32> = input.triangles.iter().flatten().copied().collect();
    let d: Vec<f32> = used
        .iter()
        .map(|&v| point_mesh_distance(input.vertices[v as usize], output))
        .collect();
    (
        d.iter().sum::<f32>() / d.len().max(1) as f32,
        d.iter().copied().fold(0.0, f32::max),
    )
}

fn marching_tet_sphere(bumps_m: f32) -> TriMesh {
    let sdf = move |p: Vec3| {
        p.length() - 0.5 + bumps_m * (37.0 * p.x).sin() * (41.0 * p.y).sin() * (43.0 * p.z).sin()
    };
    marching_tetrahedra(sdf, Vec3::splat(-0.5713), 0.0335, 36)
}

fn marching_tet_cube() -> TriMesh {
    let rounded_box = |p: Vec3| {
        let q = p.abs() - Vec3::splat(0.49);
        q.max(Vec3::ZERO).length() + q.max_element().min(0.0) - 0.01
    };
    marching_tetrahedra(rounded_box, Vec3::splat(-0.5713), 0.037, 32)
}

#[test]
#[ignore = "timing report, run in release with --nocapture"]
fn timings() {
    let mut noise = Noise::new(1);
    let cases = [
        ("icosphere r 0.5 m", icosphere(5, 0.5, |_| 0.0), 0.012),
        (
            "icosphere r 0.5 m, ±5 mm noise",
            icosphere(5, 0.5, |_| 0.005 * noise.next()),
            0.012,
        ),
        (
            "marching-tet sphere r 0.5 m",
            marching_tet_sphere(0.0),
            0.012,
        ),
        (
            "marching-tet bumpy sphere",
            marching_tet_sphere(0.004),
            0.012,
        ),
        (
            "rounded cube 1 m (24²/side)",
            rounded_cube(24, 0.5, 0.01),
            0.01,
        ),
        ("marching-tet cube 1 m", marching_tet_cube(), 0.01),
        ("flat grid 20×20", grid(20, 1.0), 0.01),
    ];
    for (name, mesh, max_residual_m) in cases {
        let (ms, out, report) = best_of(7, &mesh, max_residual_m);
        let (mean, max) = vertex_distances(&mesh, &out);
        let (quality, angle) = worst_shape(&out);
        println!(
            "{name:<32} {:>6} -> {:>4} faces {ms:>7.2} ms | max_residual {max_residual_m} m: \
             reported {:.4}, input vertices to output mean {mean:.4} max {max:.4} | worst \
             quality {quality:.2}, angle {angle:.1}° | collapses {}, refused residual {} \
             topology {} geometry {}",
            report.faces_in,
            report.faces_out,
            report.max_residual_m,
            report.collapses,
            report.rejected_by_residual,
            report.rejected_by_topology,
            report.rejected_by_geometry
        );
    }
}

#[test]
#[ignore = "face counts against the residual, for tuning the default"]
fn residual_sweep() {
    for (name, mesh) in [
        ("marching-tet sphere", marching_tet_sphere(0.0)),
        ("marching-tet cube", marching_tet_cube()),
    ] {
        for max_residual_m in [0.005, 0.01, 0.015, 0.02, 0.03, 0.05] {
            let (out, _) = simplify(&mesh, &config(max_residual_m)).expect("simplifies");
            let (mean, max) = vertex_distances(&mesh, &out);
            println!(
                "{name:<20} max_residual {max_residual_m:.3} m: {:>5} faces, input vertices to \
                 output mean {mean:.4} m max {max:.4} m",
                out.triangles.len(),
            );
        }
    }
}

#[test]
#[ignore = "scaling report"]
fn scaling() {
    for level in 3..=6 {
        let sphere = icosphere(level, 0.5, |_| 0.0);
        let (ms, _, report) = best_of(5, &sphere, 0.012);
        println!(
            "icosphere level {level}: {:>6} faces -> {:>4}, {ms:>8.2} ms, {:.2} µs per collapse",
            sphere.triangles.len(),
            report.faces_out,
            ms * 1e3 / report.collapses.max(1) as f64
        );
    }
}

#[test]
#[ignore = "profiling loop"]
fn profile_loop() {
    let mt = marching_tet_sphere(0.0);
    let sphere = icosphere(5, 0.5, |_| 0.0);
    let iterations = std::env::var("PROFILE_ITERATIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let (mut best_mt, mut best_ico) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..iterations {
        best_mt = best_mt.min(best_of(1, &mt, 0.012).0);
        best_ico = best_ico.min(best_of(1, &sphere, 0.012).0);
    }
    println!(
        "best of {iterations}: marching-tet sphere ({} faces) {best_mt:.2} ms, icosphere ({} \
         faces) {best_ico:.2} ms",
        mt.triangles.len(),
        sphere.triangles.len()
    );
}

/// Reads a mesh dumped as little-endian `u32 vertex count, u32 triangle count, f32 xyz…,
/// u32 abc…` (e.g. the pipeline's dense marching-cubes output).
fn read_dump(path: &std::path::Path) -> Option<TriMesh> {
    let bytes = std::fs::read(path).ok()?;
    let word = |i: usize| -> Option<[u8; 4]> { bytes.get(4 * i..4 * i + 4)?.try_into().ok() };
    let nv = u32::from_le_bytes(word(0)?) as usize;
    let nt = u32::from_le_bytes(word(1)?) as usize;
    let f = |i: usize| word(i).map(f32::from_le_bytes);
    let u = |i: usize| word(i).map(u32::from_le_bytes);
    let vertices = (0..nv)
        .map(|v| Some(Vec3::new(f(2 + 3 * v)?, f(3 + 3 * v)?, f(4 + 3 * v)?)))
        .collect::<Option<Vec<_>>>()?;
    let base = 2 + 3 * nv;
    let triangles = (0..nt)
        .map(|t| Some([u(base + 3 * t)?, u(base + 3 * t + 1)?, u(base + 3 * t + 2)?]))
        .collect::<Option<Vec<_>>>()?;
    Some(TriMesh::new(vertices, triangles))
}

#[test]
#[ignore = "needs dumped meshes: TACMESH_MESH_DUMPS=dir with *.bin"]
fn dumped_meshes() {
    let Ok(dir) = std::env::var("TACMESH_MESH_DUMPS") else {
        println!("set TACMESH_MESH_DUMPS to a directory of *.bin mesh dumps");
        return;
    };
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    paths.retain(|p| p.extension().is_some_and(|e| e == "bin"));
    paths.sort();
    let iterations = std::env::var("PROFILE_ITERATIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    for path in paths {
        let Some(mesh) = read_dump(&path) else {
            continue;
        };
        for max_residual_m in [0.01, 0.02] {
            let (ms, _, report) = best_of(iterations, &mesh, max_residual_m);
            println!(
                "{:<24} max_residual {max_residual_m} m: {:>6} -> {:>4} faces {ms:>7.2} ms | \
                 collapses {}, refused residual {} topology {} geometry {}",
                path.file_name()
                    .map(|n| n.to_string_lossy())
                    .unwrap_or_default(),
                report.faces_in,
                report.faces_out,
                report.collapses,
                report.rejected_by_residual,
                report.rejected_by_topology,
                report.rejected_by_geometry
            );
        }
    }
}
