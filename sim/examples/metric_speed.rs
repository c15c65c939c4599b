//! Times `mesh_distance` at the paper's sample count on a coarse and a dense sphere
//! (1,000 against 20,000 triangles), and prints the metric for the grown-cube check.
//!
//! `cargo run --release -p tacmesh-sim --example metric_speed`

use std::time::Instant;

use tacmesh_sim::{mesh_distance, point_to_mesh_distances, uv_sphere, Shape, PAPER_SAMPLES};

fn main() -> Result<(), tacmesh_sim::SimError> {
    let coarse = uv_sphere(25, 21, 0.5);
    let dense = uv_sphere(100, 101, 0.5);
    println!(
        "{} vs {} triangles, {} samples per side, {} threads",
        coarse.triangles.len(),
        dense.triangles.len(),
        PAPER_SAMPLES,
        rayon::current_num_threads()
    );
    let mut times_ms = Vec::new();
    let mut last = None;
    for run in 0..7 {
        let start = Instant::now();
        let d = mesh_distance(&coarse, &dense, PAPER_SAMPLES, run)?;
        times_ms.push(start.elapsed().as_secs_f64() * 1e3);
        last = Some(d);
    }
    times_ms.sort_by(f64::total_cmp);
    println!(
        "mesh_distance: min {:.1} ms, median {:.1} ms, max {:.1} ms; last {:?}",
        times_ms[0], times_ms[3], times_ms[6], last
    );

    let points = tacmesh_sim::SurfaceSampler::new(&coarse)?.sample_points(100_000, 0);
    let start = Instant::now();
    let distances = point_to_mesh_distances(&dense, &points)?;
    println!(
        "point_to_mesh_distances: {} points to {} triangles in {:.1} ms",
        distances.len(),
        dense.triangles.len(),
        start.elapsed().as_secs_f64() * 1e3
    );

    let small = Shape::Cube.mesh();
    let mut big = small.clone();
    big.transform(1.02, glam::Vec3::ZERO);
    println!(
        "cube vs cube x1.02: {:?}",
        mesh_distance(&small, &big, PAPER_SAMPLES, 1)?
    );
    Ok(())
}
