//! Per-stage times of segmentation on one thread, the daemon's budget: `cargo bench -p
//! tacmesh-segment` (release). Each scene is segmented with the exact per-point defaults
//! (`SegmentConfig::default()`), the daemon's settings (`SegmentConfig::live()`), and the
//! daemon's settings with the previous frame's planes as hints; the ratio is against the
//! defaults in the same process. Median of `RUNS` runs after one warm-up.

#[path = "../tests/util/mod.rs"]
#[allow(dead_code)] // the benchmark uses the frames, not the IoU helper
mod util;

use std::time::Duration;

use glam::Vec3;
use tacmesh_segment::{segment_timed, SegmentConfig, StageTimes};

const RUNS: usize = 15;

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Median per stage (each stage's own median) over `RUNS` runs, after a warm-up.
fn time(points: &[Vec3], config: &SegmentConfig, with_hints: bool) -> StageTimes {
    let (warm, _) = segment_timed(points, config, &[]);
    let hints = if with_hints { warm.planes } else { Vec::new() };
    let runs: Vec<StageTimes> = (0..RUNS)
        .map(|_| segment_timed(points, config, &hints).1)
        .collect();
    let median = |stage: fn(&StageTimes) -> Duration| {
        let mut v: Vec<Duration> = runs.iter().map(stage).collect();
        v.sort_unstable();
        v[v.len() / 2]
    };
    StageTimes {
        planes: median(|t| t.planes),
        classify: median(|t| t.classify),
        voxels: median(|t| t.voxels),
        creases: median(|t| t.creases),
        clusters: median(|t| t.clusters),
        convexity: median(|t| t.convexity),
    }
}

fn report(scene: &str, points: &[Vec3], world_from_sensor: glam::Affine3A) {
    let finite = points.iter().filter(|p| p.is_finite()).count();
    println!("{scene}: {finite} finite points");
    println!(
        "  {:<22} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>6}",
        "config",
        "planes",
        "classify",
        "voxels",
        "creases",
        "clusters",
        "convexity",
        "total",
        "ratio"
    );
    let exact = SegmentConfig::default().seen_from(world_from_sensor);
    let live = SegmentConfig::live().seen_from(world_from_sensor);
    let mut baseline = None;
    for (name, config, with_hints) in [
        ("default", &exact, false),
        ("live", &live, false),
        ("live + plane hints", &live, true),
    ] {
        let t = time(points, config, with_hints);
        let total = ms(t.total());
        let base = *baseline.get_or_insert(total);
        println!(
            "  {name:<22} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>9.2} {:>8.2} {:>6.3}",
            ms(t.planes),
            ms(t.classify),
            ms(t.voxels),
            ms(t.creases),
            ms(t.clusters),
            ms(t.convexity),
            total,
            total / base
        );
    }
}

fn main() {
    // One thread, as in the daemon (the other core renders or reads the camera).
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build();
    let Ok(pool) = pool else {
        eprintln!("cannot build a one-thread pool");
        return;
    };
    pool.install(|| {
        let frame = util::tabletop_frame(7, 0);
        report(
            "simulated tabletop 640x480",
            &frame.points_in_world,
            frame.world_from_sensor,
        );
        // The daemon's path: the organised frame, every 2nd pixel in each direction.
        let camera = tacmesh_sim::SimulatedDepthCamera::tabletop(7);
        let organised = camera
            .render(0, Duration::ZERO)
            .deproject_organised(camera.config().max_range_m)
            .points_in_world;
        let (width, height) = (
            camera.config().intrinsics.width as usize,
            camera.config().intrinsics.height as usize,
        );
        let strided: Vec<Vec3> = (0..height)
            .step_by(2)
            .flat_map(|v| (0..width).step_by(2).map(move |u| v * width + u))
            .map(|i| organised[i])
            .collect();
        report(
            "simulated tabletop, every 2nd pixel (the daemon's path)",
            &strided,
            frame.world_from_sensor,
        );
        for name in ["mosd/osd_test0.pcd", "mosd/osd_test35.pcd"] {
            let path = tacmesh_testdata::path(&format!("pointclouds/{name}"));
            match tacmesh_formats::pcd::read_pcd(&path) {
                Ok(cloud) => report(name, &cloud.points, glam::Affine3A::IDENTITY),
                Err(err) => println!("{name}: skipped ({err})"),
            }
        }
    });
}
