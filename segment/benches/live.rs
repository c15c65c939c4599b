//! Per-stage times of segmentation on one thread, the daemon's budget: `cargo bench -p
//! tacmesh-segment` (release).
//!
//! Two tables:
//! - The recordings the daemon must keep up with at 30 fps (issue 11: pcl_kinect, milk, TUM),
//!   each frame through the daemon's path: [`segment_organised_timed`] on every 2nd pixel with
//!   [`SegmentConfig::live`] and the previous frame's planes as hints, as the daemon segments
//!   every frame after the first. The `organised` column is picking the strided pixels and
//!   labelling every pixel from its strided neighbour.
//! - Simulated and labelled scenes, each segmented with the exact per-point defaults
//!   (`SegmentConfig::default()`), the daemon's settings (`SegmentConfig::live()`), and the
//!   daemon's settings with the previous frame's planes as hints; the ratio is against the
//!   defaults in the same process.
//!
//! Each figure is the median of `--runs` runs (default 15) after one warm-up, per stage (each
//! stage's own median) and in total (the median of the totals), on a pool of `--threads`
//! threads (default 1). An argument that is not an option keeps only the scenes whose name
//! contains it. For instruction counts, which do
//! not depend on the machine's load, run one hinted frame under callgrind and count only the
//! measured runs:
//!
//! ```text
//! valgrind --tool=callgrind --toggle-collect='*measured_runs*' \
//!     target/release/deps/live-HASH pcl_kinect --runs 1
//! ```

#[path = "../tests/util/mod.rs"]
#[allow(dead_code)] // the benchmark uses the frames, not the IoU helper
mod util;

use std::time::Duration;

use glam::Vec3;
use tacmesh_segment::{
    segment_organised_timed, segment_timed, SegmentConfig, StageTimes, SupportPlane,
};
use tacmesh_source::{DepthFrame, Intrinsics};

/// Runs per figure unless `--runs` says otherwise.
const RUNS: usize = 15;

/// The daemon's segmentation stride (`pipeline.segment_stride`) and range limit
/// (`pipeline.max_range_m`).
const STRIDE: u32 = 2;
const MAX_RANGE_M: f32 = 4.0;

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// One stage's time in [`StageTimes`].
type Stage = fn(&StageTimes) -> Duration;

/// The stages in the order they run, with their column names.
const STAGES: [(&str, Stage); 7] = [
    ("planes", |t| t.planes),
    ("classify", |t| t.classify),
    ("voxels", |t| t.voxels),
    ("creases", |t| t.creases),
    ("clusters", |t| t.clusters),
    ("convexity", |t| t.convexity),
    ("organised", |t| t.organised),
];

/// The timed runs, apart so that callgrind can count them alone (`--toggle-collect`).
#[inline(never)]
fn measured_runs(runs: usize, run: &mut dyn FnMut() -> StageTimes) -> Vec<StageTimes> {
    (0..runs).map(|_| run()).collect()
}

/// Each stage's median and the median total over `runs`.
fn medians(runs: &[StageTimes]) -> (Vec<Duration>, Duration) {
    let median = |mut v: Vec<Duration>| {
        v.sort_unstable();
        v[v.len() / 2]
    };
    let stages = STAGES
        .iter()
        .map(|(_, stage)| median(runs.iter().map(stage).collect()))
        .collect();
    (stages, median(runs.iter().map(StageTimes::total).collect()))
}

fn header(first: &str) {
    print!("  {first:<24}");
    for (name, _) in STAGES {
        print!(" {name:>9}");
    }
    println!(" {:>8} {:>6}", "total", "ratio");
}

fn row(name: &str, runs: &[StageTimes], baseline: &mut Option<f64>) {
    let (stages, total) = medians(runs);
    print!("  {name:<24}");
    for stage in stages {
        print!(" {:>9.2}", ms(stage));
    }
    let total = ms(total);
    let base = *baseline.get_or_insert(total);
    println!(" {total:>8.2} {:>6.3}", total / base);
}

/// A scene segmented with the defaults, the live settings, and the live settings with hints.
fn report(scene: &str, points: &[Vec3], world_from_sensor: glam::Affine3A, runs: usize) {
    let finite = points.iter().filter(|p| p.is_finite()).count();
    println!("{scene}: {finite} finite points");
    header("config");
    let exact = SegmentConfig::default().seen_from(world_from_sensor);
    let live = SegmentConfig::live().seen_from(world_from_sensor);
    let mut baseline = None;
    for (name, config, with_hints) in [
        ("default", &exact, false),
        ("live", &live, false),
        ("live + plane hints", &live, true),
    ] {
        let (warm, _) = segment_timed(points, config, &[]);
        let hints = if with_hints { warm.planes } else { Vec::new() };
        let times = measured_runs(runs, &mut || segment_timed(points, config, &hints).1);
        row(name, &times, &mut baseline);
    }
}

/// An organised frame (`width × height` points in the sensor frame, NaN without a reading)
/// through the daemon's path, hinted by a warm-up frame's planes.
fn report_organised(scene: &str, points: &[Vec3], width: u32, height: u32, runs: usize) {
    let config = SegmentConfig::live();
    let warm = |hints: &[SupportPlane]| {
        segment_organised_timed(points, width, height, STRIDE, &config, hints).0
    };
    let hints = warm(&[]).strided.plane_hints();
    let found = warm(&hints);
    let times = measured_runs(runs, &mut || {
        segment_organised_timed(points, width, height, STRIDE, &config, &hints).1
    });
    let finite = points.iter().filter(|p| p.is_finite()).count();
    let sizes: Vec<usize> = found.objects.iter().map(Vec::len).collect();
    row(&format!("{scene} ({finite} pts)"), &times, &mut None);
    println!("  {:<24} objects {sizes:?}", "");
}

/// An organised frame: its points (in the sensor frame, NaN without a reading), width and
/// height; or why it could not be read.
type Organised = Result<(Vec<Vec3>, u32, u32), String>;

/// An organised PCD.
fn organised_pcd(relative: &str) -> Organised {
    let path = tacmesh_testdata::path(relative);
    let cloud = tacmesh_formats::pcd::read_pcd(&path).map_err(|err| err.to_string())?;
    if cloud.height <= 1 {
        return Err(format!("{relative} is not organised"));
    }
    Ok((cloud.points, cloud.width, cloud.height))
}

/// A depth image deprojected as the daemon does it (`replay:PATH?fx=..`).
fn depth_image(
    relative: &str,
    (fx, fy, cx, cy): (f32, f32, f32, f32),
    depth_scale_m: f32,
) -> Organised {
    let path = tacmesh_testdata::path(relative);
    let image = tacmesh_replay::read_depth_image(&path, None).map_err(|err| err.to_string())?;
    let frame = DepthFrame {
        intrinsics: Intrinsics {
            width: image.width,
            height: image.height,
            fx,
            fy,
            cx,
            cy,
        },
        depth_m: image
            .depth
            .iter()
            .map(|&d| d as f32 * depth_scale_m)
            .collect(),
        world_from_sensor: glam::Affine3A::IDENTITY,
        capture_time: Duration::ZERO,
    };
    let points = frame.deproject_organised(MAX_RANGE_M).points_in_world;
    Ok((points, image.width, image.height))
}

/// The recordings issue 11 asks 30 fps of, by name.
const RECORDINGS: [&str; 3] = ["pcl_kinect", "milk", "tum_fr1"];

/// One frame of a recording in [`RECORDINGS`].
fn recording(name: &str) -> Organised {
    match name {
        "pcl_kinect" => organised_pcd("depth/pcl_kinect_grabber/frame_20121214T142255.814212.pcd"),
        "milk" => organised_pcd("pointclouds/pcl/milk_cartoon_all_small_clorox.pcd"),
        // The intrinsics and scale of BENCHMARKS.md's TUM spec.
        "tum_fr1" => depth_image(
            "depth/tum_fr1/1_depth.png",
            (520.9, 521.0, 325.1, 249.7),
            0.0002,
        ),
        _ => Err(format!("no recording named {name}")),
    }
}

fn main() {
    let mut filter = String::new();
    let mut runs = RUNS;
    let mut threads = 1;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--runs" => match args.next().and_then(|n| n.parse().ok()) {
                Some(n) if n > 0 => runs = n,
                _ => {
                    eprintln!("--runs needs a positive number");
                    return;
                }
            },
            "--threads" => match args.next().and_then(|n| n.parse().ok()) {
                Some(n) if n > 0 => threads = n,
                _ => {
                    eprintln!("--threads needs a positive number");
                    return;
                }
            },
            // What cargo bench passes to every bench binary.
            "--bench" => {}
            _ if arg.starts_with('-') => {
                eprintln!("unknown option {arg}");
                return;
            }
            _ => filter = arg,
        }
    }
    let wanted = |scene: &str| scene.contains(&filter);

    // One thread by default, as in the daemon (the other core fuses the previous frame).
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
    let Ok(pool) = pool else {
        eprintln!("cannot build a pool of {threads} threads");
        return;
    };
    pool.install(|| {
        println!("The daemon's path on recordings (live settings, stride {STRIDE}, hinted), ms:");
        header("recording");
        for name in RECORDINGS {
            if !wanted(name) {
                continue;
            }
            match recording(name) {
                Ok((points, width, height)) => report_organised(name, &points, width, height, runs),
                Err(err) => println!("  {name}: skipped ({err})"),
            }
        }
        println!();

        let scene = "simulated tabletop 640x480";
        if wanted(scene) {
            let frame = util::tabletop_frame(7, 0);
            report(scene, &frame.points_in_world, frame.world_from_sensor, runs);
        }
        // The daemon's path: the organised frame, every 2nd pixel in each direction.
        let scene = "simulated tabletop, every 2nd pixel (the daemon's path)";
        if wanted(scene) {
            let camera = tacmesh_sim::SimulatedDepthCamera::tabletop(7);
            let frame = camera.render(0, Duration::ZERO);
            let organised = frame
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
            report(scene, &strided, frame.world_from_sensor, runs);
        }
        for name in ["mosd/osd_test0.pcd", "mosd/osd_test35.pcd"] {
            if !wanted(name) {
                continue;
            }
            let path = tacmesh_testdata::path(&format!("pointclouds/{name}"));
            match tacmesh_formats::pcd::read_pcd(&path) {
                Ok(cloud) => report(name, &cloud.points, glam::Affine3A::IDENTITY, runs),
                Err(err) => println!("{name}: skipped ({err})"),
            }
        }
    });
}
