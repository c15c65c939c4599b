//! Real scenes played live (issue 11): what `tacmesh run` publishes from real depth data is
//! what is there now. Each test plays a recording from `testdata/` through the daemon and
//! judges the published meshes against the data (and its labels, where it has them).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use tacmesh::glam::Vec3;
use tacmesh::protocol::{Message, Scene as Published, SceneChange};
use tacmesh::segment::grid::VoxelGrid;
use tacmesh::source::monotonic_now;
use tacmesh::TriMesh;

use crate::daemon::{FIRST_PLANE_ID, ONE_DAEMON_AT_A_TIME};
use crate::reliability::Run;
use crate::util::{path_str, test_data};

/// Points on a mesh's surface, area-uniform (noise-free samples).
fn surface_samples(mesh: &TriMesh, n: usize) -> Vec<Vec3> {
    tacmesh::sim::sample_cloud(
        mesh,
        &tacmesh::sim::SampleConfig {
            points: n,
            noise_sigma_m: 0.0,
            seed: 7,
        },
    )
    .map(|c| c.points)
    .unwrap_or_else(|_| mesh.vertices.clone())
}

/// Nearest-point distances to a fixed cloud, within `reach_m` (farther is `reach_m`).
struct Nearest<'a> {
    points: &'a [Vec3],
    grid: VoxelGrid,
    reach_m: f32,
}

impl<'a> Nearest<'a> {
    fn new(points: &'a [Vec3], reach_m: f32) -> Self {
        let indices: Vec<u32> = (0..points.len() as u32).collect();
        Nearest {
            points,
            grid: VoxelGrid::new(points, &indices, reach_m),
            reach_m,
        }
    }

    fn distance(&self, p: Vec3) -> f32 {
        let mut best = self.reach_m;
        self.grid
            .for_each_near(p, |j| best = best.min(p.distance(self.points[j as usize])));
        best
    }
}

fn median(mut values: Vec<f32>) -> f32 {
    values.sort_by(f32::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(f32::NAN)
}

/// One labelled mOSD scan: its finite points, and each labelled object's points.
struct Scene {
    name: &'static str,
    points: Vec<Vec3>,
    objects: BTreeMap<u32, Vec<Vec3>>,
}

fn scene(name: &'static str) -> Scene {
    let pcd = tacmesh::formats::pcd::read_pcd(&test_data(&format!("pointclouds/mosd/{name}.pcd")))
        .expect("the scan reads");
    let labels = pcd.labels.expect("mOSD scans carry labels");
    let mut objects: BTreeMap<u32, Vec<Vec3>> = BTreeMap::new();
    let mut points = Vec::new();
    for (&p, &label) in pcd.points.iter().zip(&labels) {
        if !p.is_finite() {
            continue;
        }
        points.push(p);
        // Labels 20 and up are objects (object = label / 10); see testdata/SOURCES.md.
        if label >= 20 {
            objects.entry(label / 10).or_default().push(p);
        }
    }
    Scene {
        name,
        points,
        objects,
    }
}

/// The labelled mOSD scans played as one recording that switches scenes every 3 s at 30 fps
/// (the first scene again at the end): from 1.2 s into each scene and before the next, what is
/// published is this scene and nothing of the last one. Every published object lies on the scene's points (median
/// distance of its surface samples under 1 cm), and every labelled object is published (at
/// least half of its points within 2 cm of a published object's surface).
#[test]
fn a_scene_change_replaces_what_is_published_before_the_next_scene() {
    const NAMES: [&str; 9] = tacmesh_testdata::MOSD_SCENE_CHANGE;
    const FRAMES_PER_SCENE: usize = 90;
    // 1.2 s into a scene. What the camera sees through is gone within a few frames; but an
    // old object hidden behind the new scene's objects cannot be seen through (it may still be
    // there) and leaves `leave_after` (1 s) after it was last seen, so a judgement at exactly
    // one second would race that.
    const JUDGED_AFTER_FRAMES: usize = 36;
    const FPS: f64 = 30.0;
    let scene_time = Duration::from_secs_f64(FRAMES_PER_SCENE as f64 / FPS);
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().expect("a temporary folder");
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).expect("a frames folder");
    for (k, name) in NAMES.iter().enumerate() {
        let scan = test_data(&format!("pointclouds/mosd/{name}.pcd"));
        for i in 0..FRAMES_PER_SCENE {
            let link = frames.join(format!("f{:05}.pcd", k * FRAMES_PER_SCENE + i));
            std::os::unix::fs::symlink(&scan, link).expect("a frame link");
        }
    }
    let scenes: Vec<Scene> = NAMES.iter().map(|&n| scene(n)).collect();
    let spec = format!("replay:{}?rate={FPS}", frames.display());
    // Stats five times a second: their frame count tells which scene is playing.
    let config = dir.path().join("tacmesh.toml");
    std::fs::write(&config, "[stats]\npublish_interval_s = 0.2\n").expect("a config file");
    let mut daemon = Run::start(
        &["--config", path_str(&config), "--sensor", &spec],
        &dir.path().join("t.sock"),
    );
    let mut subscription = daemon.subscribe();

    let mut published = Published::new();
    let mut checked = 0;
    let mut missed = Vec::new();
    let mut failures = Vec::new();
    // The problems found at the latest judgement of scene `checked`, if it was judged.
    let mut judged: Option<Vec<String>> = None;
    let deadline = Instant::now() + scene_time * NAMES.len() as u32 * 3 + Duration::from_secs(30);
    while checked < NAMES.len() && Instant::now() < deadline {
        let message = subscription.next_message().expect("the subscription");
        published.apply(&message);
        let Message::Stats(stats) = message else {
            continue;
        };
        let frames_in = stats.frames_in as usize;
        // Scene `checked` is judged at each Stats from 1.2 s of its frames on, until it
        // passes; if it never does before the next scene's first frame, the problems of its
        // last judgement are the failures. On a quiet machine it passes at its first judgement
        // (the output says when); a busy one may take longer to mesh what it sees.
        if frames_in < checked * FRAMES_PER_SCENE + JUDGED_AFTER_FRAMES {
            continue;
        }
        if frames_in >= (checked + 1) * FRAMES_PER_SCENE {
            match judged.take() {
                Some(problems) => {
                    eprintln!("{} (scene {checked}): failed", scenes[checked].name);
                    failures.extend(problems);
                }
                None => missed.push(checked),
            }
            checked += 1;
            continue;
        }
        let mut problems = Vec::new();
        let now_ns = monotonic_now().as_nanos() as u64;
        let scene = &scenes[checked];
        let near_scene = Nearest::new(&scene.points, 0.05);
        let mut surfaces = Vec::new();
        for object in published
            .objects()
            .filter(|o| o.object_id() < FIRST_PLANE_ID)
        {
            let (id, mesh) = (object.object_id(), object.world_mesh());
            let capture_ns = object.shape.shape_time_ns.max(object.pose.last_seen_ns);
            let samples = surface_samples(&mesh, 2000);
            let off = median(samples.iter().map(|&p| near_scene.distance(p)).collect());
            let age_s = now_ns.saturating_sub(capture_ns) as f64 / 1e9;
            eprintln!(
                "{} (scene {checked}): object {id}: {} faces, median {:.1} mm off the scene, \
                 data {age_s:.1} s old",
                scene.name,
                mesh.triangles.len(),
                off * 1e3
            );
            if off >= 0.01 {
                problems.push(format!(
                    "{} (scene {checked}): object {id} lies {:.1} mm (median) off the scene \
                     ({age_s:.1} s old)",
                    scene.name,
                    off * 1e3
                ));
            }
            surfaces.extend(samples);
        }
        let near_published = Nearest::new(&surfaces, 0.05);
        for (label, points) in &scene.objects {
            let covered = points
                .iter()
                .step_by(10)
                .filter(|&&p| near_published.distance(p) < 0.02)
                .count() as f32
                / points.len().div_ceil(10) as f32;
            let centroid = points.iter().fold(Vec3::ZERO, |a, &p| a + p) / points.len() as f32;
            eprintln!(
                "{} (scene {checked}): labelled object {label} ({} points, centroid \
                 {centroid:.3}) {:.0} % covered",
                scene.name,
                points.len(),
                covered * 100.0
            );
            if covered < 0.5 {
                problems.push(format!(
                    "{} (scene {checked}): labelled object {label} ({} points) is not \
                     published ({:.0} % covered)",
                    scene.name,
                    points.len(),
                    covered * 100.0
                ));
            }
        }
        if problems.is_empty() {
            eprintln!(
                "{} (scene {checked}): passed {} frames in",
                scene.name,
                frames_in - checked * FRAMES_PER_SCENE
            );
            judged = None;
            checked += 1;
        } else {
            judged = Some(problems);
        }
    }
    assert!(daemon.running(), "the daemon died:\n{}", daemon.log());
    let daemon_log = daemon.log();
    let (status, _) = daemon.terminate();
    assert!(status.success(), "{status}");
    assert_eq!(checked, NAMES.len(), "only {checked} scenes played in time");
    assert!(
        missed.is_empty(),
        "no stats came while scenes {missed:?} played"
    );
    let events: Vec<&str> = log_lines_about_objects(&daemon_log);
    assert!(
        failures.is_empty(),
        "{}\nthe daemon's object events:\n{}",
        failures.join("\n"),
        events.join("\n")
    );
}

/// The tracker's lines about object births, resets and removals.
fn log_lines_about_objects(log: &str) -> Vec<&str> {
    log.lines()
        .filter(|l| {
            ["appeared", "reset", "left", "gone"]
                .iter()
                .any(|w| l.contains(w))
        })
        .collect()
}

/// Area of a mesh, square metres.
fn area_m2(mesh: &TriMesh) -> f32 {
    mesh.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum()
}

/// The frames of a shaken camera in the first frame's coordinates, where the daemon's world is
/// (its camera correction maps every frame there): each later frame is aligned to the first
/// as a whole (point-to-plane ICP on 5 and 20 mm grids of the first frame, from no motion).
/// Compared with the raw frames instead, a part of an object at the image's edge that only a
/// later frame sees would count as off the data by that frame's shake (1.5–3 cm here).
fn onto_first_frame(frames: &[Vec<Vec3>]) -> Vec<Vec3> {
    use tacmesh::reconstruct::moment_grid::MomentGrid;
    use tacmesh::track::icp::{align_to_grids, IcpLevel, IcpScratch};
    let finite = |points: &[Vec3]| -> Vec<Vec3> {
        points.iter().copied().filter(|p| p.is_finite()).collect()
    };
    let first = finite(&frames[0]);
    let (mut fine, mut coarse) = (MomentGrid::new(0.005), MomentGrid::new(0.02));
    for &p in &first {
        fine.add_point(p);
        coarse.add_point(p);
    }
    let levels = [
        IcpLevel {
            grid: &coarse,
            iterations: 30,
            reject_m: 0.08,
        },
        IcpLevel {
            grid: &fine,
            iterations: 30,
            reject_m: 0.015,
        },
    ];
    let settings = tacmesh::track::TrackConfig::default().icp_settings();
    let mut data = first.clone();
    for frame in &frames[1..] {
        let points = finite(frame);
        let sample: Vec<Vec3> = points
            .iter()
            .step_by(points.len().div_ceil(20_000).max(1))
            .copied()
            .collect();
        let aligned = align_to_grids(
            &levels,
            &sample,
            tacmesh::glam::Affine3A::IDENTITY,
            None,
            &settings,
            &mut IcpScratch::default(),
        )
        .expect("a later frame aligns to the first");
        eprintln!(
            "a later frame aligned to the first: moved {:.1} mm at 1 m ahead, {:.1} mm RMS \
             on {} of {} points",
            1e3 * (aligned.object_from_world.transform_point3(Vec3::Z) - Vec3::Z).length(),
            1e3 * aligned.rms_m,
            aligned.inliers,
            sample.len()
        );
        data.extend(
            points
                .iter()
                .map(|&p| aligned.object_from_world.transform_point3(p)),
        );
    }
    data
}

/// How far a mesh is from the camera (at the origin): the length of the mean of its surface
/// samples, metres.
fn mean_range_m(samples: &[Vec3]) -> f32 {
    (samples.iter().fold(Vec3::ZERO, |a, &p| a + p) / samples.len().max(1) as f32).length()
}

/// An object's size: the longest side of its bounding box (world axes), metres. A cluster
/// larger than `[workspace] max_object_size_m` (twice its farthest point from its centroid)
/// is never an object; fusion adds the noise of many frames and views to that.
fn size_m(mesh: &TriMesh) -> f32 {
    let (lo, hi) = mesh
        .vertices
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (hi - lo).max_element().max(0.0)
}

/// Object births in a daemon log so far.
fn births(log: &str) -> usize {
    log.lines()
        .filter(|l| l.contains("object appeared"))
        .count()
}

/// Plays `spec` looped (paced, as recorded) for `seconds` and returns the last mesh of every
/// object published at the end (support planes left out), the births in the first and the
/// second half of the run, the daemon's peak resident memory in MiB and its log.
fn play(spec: &str, seconds: f64) -> (BTreeMap<u64, TriMesh>, usize, usize, f64, String) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut daemon = Run::start(&["--sensor", spec, "--loop"], &dir.path().join("t.sock"));
    let mut subscription = daemon.subscribe();
    let started = Instant::now();
    let mut published = Published::new();
    let mut half_births = None;
    let mut peak_kib = 0;
    while started.elapsed() < Duration::from_secs_f64(seconds) {
        if half_births.is_none() && started.elapsed() >= Duration::from_secs_f64(seconds / 2.0) {
            half_births = Some(births(&daemon.log()));
        }
        peak_kib = peak_kib.max(daemon.rss_kib());
        published.apply(&subscription.next_message().expect("the subscription"));
    }
    assert!(daemon.running(), "the daemon died:\n{}", daemon.log());
    let log = daemon.log();
    let (status, _) = daemon.terminate();
    assert!(status.success(), "{status}\n{log}");
    let first_half = half_births.unwrap_or(0);
    let second_half = births(&log) - first_half;
    (
        world_meshes(&published),
        first_half,
        second_half,
        peak_kib as f64 / 1024.0,
        log,
    )
}

/// The room-scale recordings, played as recorded: what is published is objects, not walls,
/// ceilings or slices of depth (none larger than the workspace's largest object, 1.2 m, or
/// over a face budget), the object set settles (no births on a static recording once it has
/// been seen), and the daemon stays under 256 MiB.
#[test]
fn room_recordings_publish_objects_not_walls() {
    /// No object needs more faces than this at the default residual; the wall of the D435
    /// recording had 31,763 before the scene model.
    const FACE_BUDGET: usize = 3000;
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let recordings = [
        (
            "PrimeSense .oni",
            format!(
                "replay:{}",
                path_str(&test_data(
                    "recordings/openni1_primesense_12frames_640x480.oni"
                ))
            ),
        ),
        (
            "RealSense D435 .bag",
            format!(
                "replay:{}",
                path_str(&test_data(
                    "recordings/realsense_d435_single_depth_color_640x480.bag"
                ))
            ),
        ),
        (
            "slambook",
            format!(
                "replay:{}?fx=518&fy=519&cx=325.5&cy=253.5",
                path_str(&test_data("depth/slambook_kinect"))
            ),
        ),
        // Two frames of a desk 15° and 7 cm apart with no poses, looped: a camera jumping
        // back and forth every frame. Each view's clusters must go to the same objects (the
        // camera's motion is estimated from them, `tacmesh_track::camera_error`); before
        // that, one far object was born again about ten times a second.
        (
            "TUM fr1",
            format!(
                "replay:{}?fx=520.9&fy=521.0&cx=325.1&cy=249.7&depth_scale_m=0.0002&rate=30",
                path_str(&test_data("depth/tum_fr1"))
            ),
        ),
    ];
    let mut failures = Vec::new();
    for (name, spec) in &recordings {
        let (published, early, late, peak_mib, log) = play(spec, 8.0);
        eprintln!(
            "{name}: {} objects published, births {early} then {late}, peak RSS {peak_mib:.0} MiB",
            published.len()
        );
        for (id, mesh) in &published {
            let (faces, size) = (mesh.triangles.len(), size_m(mesh));
            eprintln!(
                "{name}: object {id}: {faces} faces, {size:.2} m, {:.3} m²",
                area_m2(mesh)
            );
            if faces > FACE_BUDGET || size > 1.2 * 1.1 {
                failures.push(format!("{name}: object {id}: {faces} faces, {size:.2} m"));
            }
        }
        if published.is_empty() {
            failures.push(format!("{name}: nothing published\n{log}"));
        }
        // The PrimeSense recording is 12 frames (0.4 s) of a person moving, looped: its scene
        // jumps back at every loop, and a few objects are born again (0-9 in 4 s measured,
        // more when the machine is busy and fewer frames of each loop are seen). The other two
        // are static: once seen, nothing new.
        let churn_allowed = if name.starts_with("PrimeSense") {
            20
        } else {
            2
        };
        if late > churn_allowed {
            failures.push(format!(
                "{name}: {late} objects born in the last 4 s (after {early} in the first 4 s)"
            ));
        }
        if peak_mib > 256.0 {
            failures.push(format!("{name}: peak RSS {peak_mib:.0} MiB"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The PCL Kinect grabber frames (three frames of a floor with a laptop and a box, about 1 cm
/// of camera jitter between them) looped for 60 s at 30 fps: no object in view is removed, and
/// each object keeps its area within the bound below of its first converged mesh (the one
/// published 10 s in), with under 5 % of its area farther than 3 cm from the measured points.
/// Before the weight cap and free-space carving the laptop grew from 0.11 to 0.20–0.27 m² with
/// 27–45 % of its area off the data.
///
/// The bound is 10 % of the area, or one fused voxel (at the object's range) along its whole
/// rim where that is more: 4/n of the area for an object n voxels across, the least a rim of
/// that size can change by when the surface shifts by one voxel at its edge. The first bound
/// alone failed one CI run in eleven, on the clutter at the back (26 voxels across, 1.57 m
/// away): 0.0283 → 0.0254 m², −10.4 %, two thirds of a voxel along its rim. That object comes
/// out in one of two states: 0.039–0.042 m², unchanged from 10 to 60 s (four runs), or, after
/// a reset on its second frame (118 of 595 points near its fused surface, in the failing run),
/// 0.028 m² at 10 s and still moving by the end (−10.4 % and −6.5 % in two runs). Why it takes
/// one or the other is left for the next look at the scene model. The laptop's bloat that this
/// test was written for (0.11 → 0.20–0.27 m², 78 voxels across) is far outside both bounds.
///
/// Not held to the area bound: an object under 12 fused voxels across (at its range), where a
/// voxel more or less along the rim is a third of the area or more. The one such object is the
/// chair's caster at the right edge (5–6 cm at 1 m, 0.002–0.003 m², shiny, seen differently in
/// each frame; its pose still turns by a few degrees most frames): printed, not held.
///
/// Until moves had to be evident (`tacmesh_track::object`, `MOVE_EVIDENCE`), the clutter
/// 1.2–1.7 m away at the back (a cardboard box, a cart, a blue bin, cut by the image's edges
/// and seen differently in each frame) moved every other frame by 2–9 cm and degrees, was
/// fused where each move put it, and ended with up to half its area off the data, now and
/// then removed while in view and born again; those objects were printed, not held.
///
/// The laptop lid, a flat face whose slide along itself alignment can barely see, crept with
/// the camera shake in most runs of the third stop's first builds (0.12–0.18 m², up to 25 % of
/// its area off the data): each jolt was carried into the next frame's prediction, and capture
/// times off the wall clock made every run different. Since only a steady motion is predicted
/// on (`tacmesh_track::object`) and what a support hides is forgotten, it holds 0.11–0.12 m²
/// with nothing off the data, the box 0.066 m².
#[test]
fn camera_jitter_neither_bloats_nor_drops_static_objects() {
    const SECONDS: f64 = 60.0;
    const CONVERGED_AT_S: f64 = 10.0;
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().expect("a temporary folder");
    let frames = test_data("depth/pcl_kinect_grabber");
    let spec = format!("replay:{}?fx=525&fy=525&cx=320&cy=240", path_str(&frames));
    // The measured points: the three frames, as the daemon sees them.
    let captured = dir.path().join("frames");
    let out = crate::util::tacmesh(&[
        "capture",
        "--sensor",
        &spec,
        "--frames",
        "3",
        "--out",
        path_str(&captured),
    ]);
    assert!(out.status.success(), "{out:?}");
    let frames: Vec<Vec<Vec3>> = (0..3)
        .map(|k| {
            tacmesh::formats::read_cloud(&captured.join(format!("frame-{k}.ply")))
                .expect("a captured frame")
                .points
        })
        .collect();
    let data = onto_first_frame(&frames);
    let near_data = Nearest::new(&data, 0.05);

    let mut daemon = Run::start(&["--sensor", &spec, "--loop"], &dir.path().join("t.sock"));
    let mut subscription = daemon.subscribe();
    let started = Instant::now();
    let mut published = Published::new();
    let mut converged: Option<BTreeMap<u64, (f32, f32, f32)>> = None;
    let mut removed = Vec::new();
    while started.elapsed() < Duration::from_secs_f64(SECONDS) {
        if converged.is_none() && started.elapsed() >= Duration::from_secs_f64(CONVERGED_AT_S) {
            converged = Some(
                world_meshes(&published)
                    .iter()
                    .map(|(&id, m)| {
                        let range_m = mean_range_m(&surface_samples(m, 4000));
                        (id, (area_m2(m), range_m, size_m(m)))
                    })
                    .collect(),
            );
        }
        let message = subscription.next_message().expect("the subscription");
        if let SceneChange::Removed(object_id) = published.apply(&message) {
            if converged.is_some() {
                removed.push(object_id);
            }
        }
    }
    let latest = world_meshes(&published);
    assert!(daemon.running(), "the daemon died:\n{}", daemon.log());
    let log = daemon.log();
    let (status, _) = daemon.terminate();
    assert!(status.success(), "{status}");
    let converged = converged.expect("the run reached its converged time");
    assert!(!converged.is_empty(), "nothing was published:\n{log}");
    let track = tacmesh::daemon::track_config(&tacmesh::daemon::DaemonConfig::default());
    let mut failures = Vec::new();
    for (id, &(first, first_range_m, first_size_m)) in &converged {
        let Some(mesh) = latest.get(id) else {
            failures.push(format!(
                "object {id} ({first:.3} m², {first_range_m:.2} m away) was removed while in view"
            ));
            continue;
        };
        let area = area_m2(mesh);
        let samples = surface_samples(mesh, 4000);
        let range_m = mean_range_m(&samples);
        let voxels_across = first_size_m / track.voxel_at_range(first_range_m);
        let area_held = voxels_across >= 12.0;
        let off = samples
            .iter()
            .filter(|&&p| near_data.distance(p) > 0.03)
            .count() as f32
            / samples.len().max(1) as f32;
        eprintln!(
            "object {id} ({range_m:.2} m away, {voxels_across:.0} voxels across): {first:.4} m² \
             at {CONVERGED_AT_S} s, {area:.4} m² at {SECONDS} s ({:+.1} %{}), {:.1} % of its area \
             over 3 cm from the data, {} faces",
            100.0 * (area / first - 1.0),
            if area_held { "" } else { ", not held" },
            100.0 * off,
            mesh.triangles.len()
        );
        let area_bound = 0.10f32.max(4.0 / voxels_across);
        if area_held && (area / first - 1.0).abs() > area_bound {
            failures.push(format!(
                "object {id}: area {first:.4} -> {area:.4} m² ({:+.1} %, bound {:.1} %)",
                100.0 * (area / first - 1.0),
                100.0 * area_bound
            ));
        }
        if off >= 0.05 {
            failures.push(format!(
                "object {id}: {:.1} % of its area is over 3 cm from the data",
                100.0 * off
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{}\nremoved after convergence: {removed:?}\nthe daemon's object events:\n{}",
        failures.join("\n"),
        log_lines_about_objects(&log).join("\n")
    );
}

/// The world mesh of every object (support planes left out) a subscriber holds.
fn world_meshes(scene: &Published) -> BTreeMap<u64, TriMesh> {
    scene
        .objects()
        .filter(|object| object.object_id() < FIRST_PLANE_ID)
        .map(|object| (object.object_id(), object.world_mesh()))
        .collect()
}

/// How many objects the daemon's end-of-stream line says it meshed ("… meshing what was held
/// back: object 1 (…), object 2 (…)"), once it is logged; 0 for "every object's mesh is up to
/// date".
fn held_back_at_end(log: &str) -> Option<usize> {
    let line = log.lines().find(|l| l.contains("end of stream"))?;
    if line.contains("every object's mesh is up to date") {
        return Some(0);
    }
    let (_, listed) = line.split_once("meshing what was held back: ")?;
    Some(
        listed
            .match_indices("object ")
            .filter(|(at, _)| {
                listed[at + "object ".len()..].starts_with(|c: char| c.is_ascii_digit())
            })
            .count(),
    )
}

/// One segmentation offline and live (issue 41): `tacmesh mesh --objects` on a labelled scan
/// and the daemon on the same scan replayed once give the same objects. Each object meshed
/// offline lies on one published object (90 % of its points within 1.5 cm of its surface), a
/// different one for each, and the daemon publishes no other object.
#[test]
fn mesh_objects_and_the_daemon_give_the_same_objects_on_the_labelled_scans() {
    // The eight scans, each once (the scene-change order plays the first again at its end).
    let scans = &tacmesh_testdata::MOSD_SCENE_CHANGE[..8];
    let _one = ONE_DAEMON_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let mut failures = Vec::new();
    for name in scans {
        let scan = test_data(&format!("pointclouds/mosd/{name}.pcd"));
        let dir = tempfile::tempdir().expect("a temporary folder");
        let out = dir.path().join("objects");
        crate::util::tacmesh_ok(&["mesh", "--objects", path_str(&scan), "-o", path_str(&out)]);
        let points = tacmesh::formats::pcd::read_pcd(&scan)
            .expect("the scan reads")
            .points;
        let labels: Vec<u32> = std::fs::read_to_string(out.join("labels.txt"))
            .expect("labels.txt")
            .lines()
            .map(|l| l.parse().expect("a label"))
            .collect();
        assert_eq!(labels.len(), points.len(), "{name}: a label per point");
        // The objects meshed offline (a sliver too thin to mesh has a label but no file).
        let mut offline: BTreeMap<u32, Vec<Vec3>> = BTreeMap::new();
        for (&label, &p) in labels.iter().zip(&points) {
            if label > 0 && out.join(format!("object-{label}.ply")).exists() {
                offline.entry(label).or_default().push(p);
            }
        }

        let spec = format!("replay:{}", scan.display());
        let daemon = Run::start(&["--sensor", &spec], &dir.path().join("t.sock"));
        let mut subscription = daemon.subscribe();
        let mut published = Published::new();
        let deadline = Instant::now() + Duration::from_secs(120);
        // Until every object the stream's end released is published or has failed to mesh.
        let live = loop {
            let message = subscription.next_message().expect("the subscription");
            published.apply(&message);
            let meshes = world_meshes(&published);
            let failed = match &message {
                Message::Stats(stats) => Some(stats.meshing_failures as usize),
                _ => None,
            };
            if let (Some(held), Some(failed)) = (held_back_at_end(&daemon.log()), failed) {
                let meshed = meshes.values().filter(|m| !m.triangles.is_empty()).count();
                if meshed + failed >= held {
                    break meshes;
                }
            }
            assert!(
                Instant::now() < deadline,
                "{name}: the daemon did not mesh the scan in 2 minutes:\n{}",
                daemon.log()
            );
        };
        drop(daemon);

        let surfaces: Vec<(u64, Vec<Vec3>)> = live
            .iter()
            .map(|(&id, mesh)| (id, surface_samples(mesh, 4000)))
            .collect();
        let mut matched: BTreeMap<u64, u32> = BTreeMap::new();
        for (label, object) in &offline {
            // The share of the object's points on each published surface.
            let best = surfaces
                .iter()
                .map(|(id, samples)| {
                    let near = Nearest::new(samples, 0.05);
                    let on = object
                        .iter()
                        .step_by(4)
                        .filter(|&&p| near.distance(p) <= 0.015)
                        .count() as f32
                        / object.len().div_ceil(4) as f32;
                    (on, *id)
                })
                .max_by(|a, b| a.0.total_cmp(&b.0));
            eprintln!(
                "{name}: offline object {label} ({} points): {:?}",
                object.len(),
                best.map(|(on, id)| format!("{:.0} % on published {id}", on * 100.0))
            );
            match best {
                Some((on, id)) if on >= 0.9 => {
                    if let Some(other) = matched.insert(id, *label) {
                        failures.push(format!(
                            "{name}: offline objects {other} and {label} are one published \
                             object {id}"
                        ));
                    }
                }
                _ => failures.push(format!(
                    "{name}: offline object {label} ({} points) is no published object",
                    object.len()
                )),
            }
        }
        for id in live.keys() {
            if !matched.contains_key(id) {
                failures.push(format!(
                    "{name}: published object {id} is no offline object"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
