//! Convex parts (issue 13): tacmesh's `convex_parts` (one hull when the mesh fills it, else
//! parry3d's V-HACD, merged to at most 8 hulls of at most 64 vertices) against CoACD with the
//! same bounds, on the pipeline's meshes of the six shapes at 20 mm noise.
//!
//! `cargo bench --bench convex` prints one Markdown table for BENCHMARKS.md. CoACD runs in
//! `benches/convex_peer.py` under the Python named by `--python PATH` or
//! `TACMESH_COACD_PYTHON` (else `python3`), when that Python has `coacd`; without it the
//! table has tacmesh's columns only. Options: `--seed N`, `--noise-mm MM`, `--points N`.
//!
//! Both decompositions are judged by one metric, here:
//! - **volume ratio**: the hulls' volumes summed over the mesh's volume (≥ 1 where the hulls
//!   bridge concavities; overlaps count twice);
//! - **sticks out**: points sampled on the hulls' union (on a hull, not inside another one),
//!   their distance to the mesh, mean and max: how far a simulated contact happens before
//!   the real surface;
//! - **misses**: points sampled on the mesh that no hull covers, their farthest distance to
//!   the hulls: how deep a contact can sink in before the hulls feel it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use tacmesh::glam::Vec3;
use tacmesh::physics::{convex_parts, ConvexConfig, MassProperties};
use tacmesh::pipeline::{mesh_cloud, MeshConfig};
use tacmesh::sim::{point_to_mesh_distances, sample_cloud, SampleConfig, Shape, SurfaceSampler};
use tacmesh::TriMesh;

/// Points sampled per side for the distance figures.
const SAMPLES: usize = 20_000;
/// Timed repetitions of our decomposition (median).
const REPS: usize = 5;

struct Options {
    seed: u64,
    noise_mm: f32,
    points: usize,
    python: String,
}

fn parse_options() -> Options {
    let mut options = Options {
        seed: 1,
        noise_mm: 20.0,
        points: 50_000,
        python: std::env::var("TACMESH_COACD_PYTHON").unwrap_or_else(|_| "python3".into()),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let value = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--seed" => options.seed = value.parse().expect("--seed N"),
            "--noise-mm" => options.noise_mm = value.parse().expect("--noise-mm MM"),
            "--points" => options.points = value.parse().expect("--points N"),
            "--python" => options.python = value,
            _ => {
                i += 1; // cargo bench passes --bench; ignore what is not ours
                continue;
            }
        }
        i += 2;
    }
    options
}

/// What a decomposition achieved on one mesh.
struct Quality {
    ms: f64,
    hulls: usize,
    max_hull_vertices: usize,
    volume_ratio: f64,
    out_mean_m: f64,
    out_max_m: f64,
    missed_max_m: f64,
}

/// Volume of a closed mesh whichever way it faces.
fn volume_m3(mesh: &TriMesh) -> f64 {
    let mut flipped = mesh.clone();
    for t in &mut flipped.triangles {
        t.swap(1, 2);
    }
    MassProperties::of_closed_mesh(mesh)
        .or_else(|_| MassProperties::of_closed_mesh(&flipped))
        .map_or(0.0, |m| f64::from(m.volume_m3))
}

/// How far `p` is outside the convex `hull` along its farthest face plane (≤ 0 inside).
fn plane_distance(hull: &TriMesh, p: Vec3) -> f32 {
    // CoACD's hulls may face either way; ours face outward.
    let sign = if MassProperties::of_closed_mesh(hull).is_ok() {
        1.0
    } else {
        -1.0
    };
    (0..hull.triangles.len())
        .filter_map(|t| {
            let [a, b, c] = hull.corners(t);
            let normal = (b - a).cross(c - a).try_normalize()?;
            Some(sign * normal.dot(p - a))
        })
        .fold(f32::NEG_INFINITY, f32::max)
}

/// Whether `p` is inside the closed `mesh`: its generalised winding number (the solid angle
/// the triangles subtend, over 4π; Van Oosterom and Strackee) is above one half.
fn inside(mesh: &TriMesh, p: Vec3) -> bool {
    let mut solid_angle = 0.0f64;
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t).map(|v| (v - p).as_dvec3());
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let numerator = a.dot(b.cross(c));
        let denominator = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        solid_angle += 2.0 * numerator.atan2(denominator);
    }
    solid_angle / (4.0 * std::f64::consts::PI) > 0.5
}

fn judge(mesh: &TriMesh, hulls: &[TriMesh], ms: f64, seed: u64) -> Quality {
    let mesh_volume = volume_m3(mesh);
    let hull_volume: f64 = hulls.iter().map(volume_m3).sum();
    let extent = mesh
        .bounds()
        .map_or(1.0, |(lo, hi)| (hi - lo).max_element());
    // On another hull's boundary (a shared cut) counts as inside it.
    let touching_m = 1e-3 * extent;
    // Sticking out: samples on each hull that lie inside no other hull; those inside the
    // mesh (the union's cavities, if any) stick out by 0.
    let areas: Vec<f32> = hulls.iter().map(TriMesh::area).collect();
    let total_area: f32 = areas.iter().sum();
    let mut outer = Vec::new();
    for (k, hull) in hulls.iter().enumerate() {
        let n = ((SAMPLES as f32) * areas[k] / total_area).ceil() as usize;
        let sampler = SurfaceSampler::new(hull).expect("hulls have area");
        outer.extend(
            sampler
                .sample_points(n, seed + k as u64)
                .into_iter()
                .filter(|&p| {
                    hulls
                        .iter()
                        .enumerate()
                        .all(|(j, other)| j == k || plane_distance(other, p) > touching_m)
                }),
        );
    }
    let mut out = point_to_mesh_distances(mesh, &outer).expect("the mesh indexes");
    for (d, &p) in out.iter_mut().zip(&outer) {
        if inside(mesh, p) {
            *d = 0.0;
        }
    }
    // Missing: samples on the mesh outside every hull.
    let on_mesh = SurfaceSampler::new(mesh)
        .expect("the mesh has area")
        .sample_points(SAMPLES, seed);
    let uncovered: Vec<Vec3> = on_mesh
        .into_iter()
        .filter(|&p| hulls.iter().all(|h| plane_distance(h, p) > touching_m))
        .collect();
    let missed_max_m = if uncovered.is_empty() {
        0.0
    } else {
        let distances = point_to_mesh_distances(&TriMesh::concatenated(hulls), &uncovered)
            .expect("hulls index");
        f64::from(distances.iter().copied().fold(0.0f32, f32::max))
    };
    Quality {
        ms,
        hulls: hulls.len(),
        max_hull_vertices: hulls.iter().map(|h| h.vertices.len()).max().unwrap_or(0),
        volume_ratio: hull_volume / mesh_volume,
        out_mean_m: out.iter().map(|&d| f64::from(d)).sum::<f64>() / out.len().max(1) as f64,
        out_max_m: f64::from(out.iter().copied().fold(0.0f32, f32::max)),
        missed_max_m,
    }
}

fn ours(mesh: &TriMesh, seed: u64) -> Quality {
    let config = ConvexConfig::default();
    let mut times = Vec::with_capacity(REPS);
    let mut parts = None;
    for _ in 0..REPS {
        let start = Instant::now();
        parts = Some(convex_parts(mesh, &config).expect("pipeline meshes are closed solids"));
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let parts = parts.expect("at least one repetition");
    judge(mesh, &parts.hulls, times[REPS / 2], seed)
}

fn coacd_available(python: &str) -> bool {
    Command::new(python)
        .args(["-c", "import coacd"])
        .output()
        .is_ok_and(|out| out.status.success())
}

/// Runs the peer on every `NAME.obj` in `mesh_dir`; its hulls and seconds per name.
fn coacd(python: &str, mesh_dir: &Path, out_dir: &Path) -> BTreeMap<String, (Vec<TriMesh>, f64)> {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/convex_peer.py");
    let status = Command::new(python)
        .arg(script)
        .arg(mesh_dir)
        .arg(out_dir)
        .status()
        .expect("the peer starts");
    assert!(status.success(), "benches/convex_peer.py failed: {status}");
    let timings: BTreeMap<String, f64> = serde_json::from_str(
        &std::fs::read_to_string(out_dir.join("timings.json")).expect("the peer wrote timings"),
    )
    .expect("timings are JSON");
    timings
        .into_iter()
        .map(|(name, seconds)| {
            let hulls: Vec<TriMesh> = (0..)
                .map(|k| out_dir.join(format!("{name}_hull{k}.obj")))
                .take_while(|path| path.exists())
                .map(|path: PathBuf| tacmesh::formats::read_mesh(&path).expect("a hull reads"))
                .collect();
            (name, (hulls, seconds * 1e3))
        })
        .collect()
}

fn mm(m: f64) -> String {
    format!("{:.1}", m * 1e3)
}

fn main() {
    let options = parse_options();
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mesh_dir = dir.path().join("meshes");
    std::fs::create_dir_all(&mesh_dir).expect("a mesh folder");
    let mut meshes = Vec::new();
    for shape in Shape::ALL {
        let cloud = sample_cloud(
            &shape.mesh(),
            &SampleConfig {
                points: options.points,
                noise_sigma_m: options.noise_mm / 1000.0,
                seed: options.seed,
            },
        )
        .expect("the built-in shapes sample");
        let (mesh, _) = mesh_cloud(&cloud, &MeshConfig::default()).expect("the pipeline runs");
        tacmesh::formats::write_mesh(&mesh_dir.join(format!("{}.obj", shape.name())), &mesh)
            .expect("the mesh writes");
        meshes.push((shape, mesh));
    }

    let peer = if coacd_available(&options.python) {
        Some(coacd(&options.python, &mesh_dir, &dir.path().join("coacd")))
    } else {
        eprintln!(
            "CoACD is not available to {} (pip install coacd==1.0.14, or --python PATH): \
             tacmesh's columns only",
            options.python
        );
        None
    };

    println!(
        "\n### Convex parts at {} mm noise (seed {}, {} points; at most 8 hulls of at most 64 vertices; {} samples per side)\n",
        options.noise_mm, options.seed, options.points, SAMPLES
    );
    println!("| shape | faces | ms: ours / CoACD (ratio) | hulls: ours / CoACD | max hull vertices: ours / CoACD | hull volume ÷ mesh volume: ours / CoACD | sticks out, mean mm: ours / CoACD | sticks out, max mm: ours / CoACD | misses, max mm: ours / CoACD |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (shape, mesh) in &meshes {
        let us = ours(mesh, options.seed);
        let them = peer
            .as_ref()
            .and_then(|p| p.get(shape.name()))
            .map(|(hulls, ms)| judge(mesh, hulls, *ms, options.seed));
        let pair = |a: String, b: Option<String>| match b {
            Some(b) => format!("{a} / {b}"),
            None => a,
        };
        let time = match &them {
            Some(t) => format!("{:.2} / {:.0} ({:.1e})", us.ms, t.ms, us.ms / t.ms),
            None => format!("{:.2}", us.ms),
        };
        println!(
            "| {} | {} | {time} | {} | {} | {} | {} | {} | {} |",
            shape.name(),
            mesh.triangles.len(),
            pair(
                us.hulls.to_string(),
                them.as_ref().map(|t| t.hulls.to_string())
            ),
            pair(
                us.max_hull_vertices.to_string(),
                them.as_ref().map(|t| t.max_hull_vertices.to_string())
            ),
            pair(
                format!("{:.3}", us.volume_ratio),
                them.as_ref().map(|t| format!("{:.3}", t.volume_ratio))
            ),
            pair(mm(us.out_mean_m), them.as_ref().map(|t| mm(t.out_mean_m))),
            pair(mm(us.out_max_m), them.as_ref().map(|t| mm(t.out_max_m))),
            pair(
                mm(us.missed_max_m),
                them.as_ref().map(|t| mm(t.missed_max_m))
            ),
        );
    }
    split_against_vhacd(&meshes, options.seed);
}

/// The daemon cuts solids by planes ([`tacmesh::physics::split_part_points`]) where the
/// offline path runs V-HACD: both, merged, covered and reduced the same way, on the shapes
/// that need more than one hull, judged by the same metric.
fn split_against_vhacd(meshes: &[(Shape, TriMesh)], seed: u64) {
    use tacmesh::physics::{convex_parts_with, split_part_points, Decomposition};
    let config = ConvexConfig::default();
    println!("\n### Cut by planes (the daemon's) against V-HACD (offline)\n");
    println!("| shape | ms: planes / V-HACD | hulls: planes / V-HACD | hull volume ÷ mesh volume: planes / V-HACD | sticks out, max mm: planes / V-HACD | misses, max mm: planes / V-HACD |");
    println!("|---|---|---|---|---|---|");
    for (shape, mesh) in meshes {
        let vhacd = convex_parts(mesh, &config).expect("pipeline meshes are closed solids");
        if !matches!(vhacd.decomposition, Decomposition::Decomposed { .. }) {
            continue;
        }
        let mut times = Vec::with_capacity(REPS);
        let mut hulls = Vec::new();
        for _ in 0..REPS {
            let start = Instant::now();
            hulls = convex_parts_with(mesh, &config, |m, c| Ok(split_part_points(m, c)))
                .expect("a closed solid")
                .hulls;
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        let planes = judge(mesh, &hulls, times[REPS / 2], seed);
        let them = ours(mesh, seed);
        println!(
            "| {} | {:.1} / {:.0} | {} / {} | {:.3} / {:.3} | {} / {} | {} / {} |",
            shape.name(),
            planes.ms,
            them.ms,
            planes.hulls,
            them.hulls,
            planes.volume_ratio,
            them.volume_ratio,
            mm(planes.out_max_m),
            mm(them.out_max_m),
            mm(planes.missed_max_m),
            mm(them.missed_max_m),
        );
    }
}
