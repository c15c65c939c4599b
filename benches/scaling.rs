//! How the cloud-to-mesh pipeline scales with the number of points: one 1 m shape at 20 mm
//! noise, from 40,000 to 2.56 million points, each cloud meshed by `tacmesh mesh --json` in
//! its own process on one core (`RAYON_NUM_THREADS=1`), so that the peak memory is that
//! cloud's alone. Reports milliseconds per stage, nanoseconds per point, and the process's peak
//! resident memory (`VmHWM`) with bytes per point.
//!
//! `cargo bench --bench scaling` prints Markdown for BENCHMARKS.md;
//! `-- --shape cube --max-points 640000 --runs 1` for a quick look.

use std::path::Path;
use std::process::Command;

use tacmesh::sim::{sample_cloud, SampleConfig, Shape};

struct Options {
    shape: Shape,
    max_points: usize,
    runs: usize,
}

fn parse_options() -> Options {
    let mut options = Options {
        shape: Shape::Sphere,
        max_points: 2_560_000,
        runs: 3,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let value = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--shape" => options.shape = Shape::from_name(&value).expect("--shape cube|sphere|…"),
            "--max-points" => options.max_points = value.parse().expect("--max-points N"),
            "--runs" => options.runs = value.parse().expect("--runs N"),
            _ => {
                i += 1; // cargo bench passes --bench; ignore what is not ours
                continue;
            }
        }
        i += 2;
    }
    options
}

/// The fields of `tacmesh mesh --json` this benchmark reads.
#[derive(serde::Deserialize, Clone, Copy)]
struct MeshJson {
    read_ms: f64,
    peak_memory_mb: Option<f64>,
    recon_faces: usize,
    faces: usize,
    integrate_ms: f64,
    normals_ms: f64,
    orient_ms: f64,
    distance_ms: f64,
    marching_cubes_ms: f64,
    simplify_ms: f64,
    fit_ms: f64,
    total_ms: f64,
}

fn mesh_once(cloud: &Path, out: &Path) -> MeshJson {
    let output = Command::new(env!("CARGO_BIN_EXE_tacmesh"))
        .arg("mesh")
        .arg(cloud)
        .arg("-o")
        .arg(out)
        .arg("--json")
        .env("RAYON_NUM_THREADS", "1")
        .env("RUST_LOG", "warn")
        .output()
        .expect("tacmesh mesh runs");
    assert!(
        output.status.success(),
        "tacmesh mesh {}: {}",
        cloud.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("tacmesh mesh --json prints its report")
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn main() {
    let options = parse_options();
    let dir = tempfile::tempdir().expect("a temporary folder");
    let truth = options.shape.mesh();
    let sizes: Vec<usize> = std::iter::successors(Some(40_000usize), |n| Some(n * 2))
        .take_while(|&n| n <= options.max_points)
        .collect();

    println!(
        "### Scaling: {}, 20 mm noise, one core, median of {} runs (`tacmesh mesh --json` in a \
         process per run)\n",
        options.shape.name(),
        options.runs
    );
    println!(
        "| points | read | integrate | normals | orient | signed distance | marching cubes | \
         simplify | fit | **pipeline** | ns per point (pipeline) | recon faces | faces | peak \
         memory (MiB) | bytes per point |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &points in &sizes {
        let cloud = sample_cloud(
            &truth,
            &SampleConfig {
                points,
                noise_sigma_m: 0.02,
                seed: 1,
            },
        )
        .expect("sampling a shape");
        let path = dir.path().join(format!("cloud-{points}.ply"));
        tacmesh::formats::write_cloud(&path, &cloud).expect("writing the cloud");
        drop(cloud);
        let runs: Vec<MeshJson> = (0..options.runs)
            .map(|run| {
                eprintln!("{points} points, run {}", run + 1);
                mesh_once(&path, &dir.path().join("mesh.ply"))
            })
            .collect();
        let m = |f: fn(&MeshJson) -> f64| median(runs.iter().map(f).collect());
        let total = m(|r| r.total_ms);
        let memory = m(|r| r.peak_memory_mb.unwrap_or(f64::NAN));
        println!(
            "| {points} | {:.0} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | **{total:.1}** \
             | {:.0} | {} | {} | {memory:.0} | {:.0} |",
            m(|r| r.read_ms),
            m(|r| r.integrate_ms),
            m(|r| r.normals_ms),
            m(|r| r.orient_ms),
            m(|r| r.distance_ms),
            m(|r| r.marching_cubes_ms),
            m(|r| r.simplify_ms),
            m(|r| r.fit_ms),
            total * 1e6 / points as f64,
            runs[0].recon_faces,
            runs[0].faces,
            memory * 1024.0 * 1024.0 / points as f64,
        );
        std::fs::remove_file(&path).ok();
    }
}
