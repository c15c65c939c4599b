//! The fused state forgets: what the camera now sees through is carved away, and no voxel
//! keeps more than its cap of past points.

// The helpers are shared with tracking.rs; this file uses some of them.
#[allow(dead_code)]
mod util;

use std::time::Duration;

use glam::{Affine3A, Vec3};
use tacmesh_track::{FrameClusters, FreeSpace, ObjectMap, TrackConfig};
use util::{at, posed, rng, view, Body, FRAME};

/// A wall of points `depth_m` in front of the sensor (at the origin, looking along +z),
/// 2 mm apart like a VGA depth camera's pixels at 1 m, covering ±0.3 m.
fn wall(depth_m: f32) -> Vec<Vec3> {
    (-150..=150)
        .flat_map(|i| (-150..=150).map(move |j| Vec3::new(i as f32, j as f32, 0.0) * 0.002))
        .map(|p| p + Vec3::Z * depth_m)
        .collect()
}

/// One frame: the objects' clusters, and the free space of everything the camera saw (the
/// clusters and the background, nearer points hiding farther ones per direction).
fn frame(index: u32, clusters: Vec<Vec<Vec3>>, background: &[Vec3]) -> FrameClusters {
    let mut all: Vec<Vec3> = background.to_vec();
    all.extend(clusters.iter().flatten());
    FrameClusters {
        capture_time: FRAME * index,
        viewpoint_m: Vec3::ZERO,
        free_space: Some(FreeSpace::from_points(&all, Affine3A::IDENTITY)),
        clusters,
    }
}

/// Objects stay until seen through, not until a timeout: a long `leave_after`.
fn patient_map() -> ObjectMap {
    ObjectMap::new(TrackConfig {
        leave_after: Duration::from_secs(60),
        ..TrackConfig::default()
    })
    .expect("valid config")
}

const CUBE: Body = Body::Cube { half_m: 0.05 };

#[test]
fn an_object_taken_away_is_gone_within_a_second_and_a_hidden_one_stays() {
    let mut rng = rng(1);
    let background = wall(1.5);
    let place = at(0.0, 0.0, 1.0);
    for hidden in [false, true] {
        let mut map = patient_map();
        let mut frame_index = 0;
        for _ in 0..30 {
            let cube = view(CUBE, place, Vec3::ZERO, 3000, 0.002, &mut rng);
            let report = map.integrate(&frame(frame_index, vec![cube], &background));
            assert!(report.removed.is_empty(), "removed while in view");
            frame_index += 1;
        }
        assert_eq!(map.len(), 1);
        // The cube is taken away (the camera sees the wall through where it was), or a board
        // comes in front of it (the camera cannot see where it was).
        let scene = if hidden {
            wall(0.6)
        } else {
            background.clone()
        };
        let mut gone_after = None;
        for k in 1..=30 {
            let report = map.integrate(&frame(frame_index, vec![], &scene));
            frame_index += 1;
            if !report.removed.is_empty() {
                gone_after = Some(k);
                break;
            }
        }
        if hidden {
            assert_eq!(gone_after, None, "a hidden object was carved away");
            assert_eq!(map.len(), 1);
        } else {
            let frames = gone_after.expect("the object taken away is still there after 1 s");
            eprintln!("taken away: gone after {frames} frames");
            assert!(map.is_empty());
        }
    }
}

/// A box replaced by a ball in the same place: within a second every fused voxel of whatever
/// object holds that place lies on the ball, none on the box that is gone.
#[test]
fn an_object_replaced_in_place_leaves_nothing_of_itself_behind() {
    let mut rng = rng(2);
    let background = wall(1.5);
    let place = at(0.0, 0.0, 1.0);
    let mut map = patient_map();
    for i in 0..30 {
        let cube = view(CUBE, place, Vec3::ZERO, 3000, 0.002, &mut rng);
        map.integrate(&frame(i, vec![cube], &background));
    }
    let ball_centre = Vec3::new(0.0, 0.0, 1.02);
    let ball = Body::Sphere { radius_m: 0.035 };
    for i in 30..60 {
        let points = view(
            ball,
            Affine3A::from_translation(ball_centre),
            Vec3::ZERO,
            1500,
            0.002,
            &mut rng,
        );
        map.integrate(&frame(i, vec![points], &background));
    }
    let jobs = map.take_mesh_jobs(FRAME * 60);
    assert!(!jobs.is_empty(), "nothing to mesh");
    for job in &jobs {
        let mut worst = 0.0f32;
        for (_, m) in job.grid.iter() {
            let p = job
                .world_from_object
                .transform_point3(m.centroid().expect("occupied"));
            worst = worst.max((p.distance(ball_centre) - 0.035).abs());
        }
        eprintln!(
            "object {}: farthest voxel {:.1} mm off the ball",
            job.object_id,
            worst * 1e3
        );
        assert!(
            worst < 0.015,
            "a voxel {worst} m off the ball: the box was not forgotten"
        );
    }
}

/// A static object watched for 10 s: no voxel holds more than the cap, and the fused weight
/// stops growing (memory and the history's influence are bounded).
#[test]
fn a_voxel_keeps_at_most_its_cap_of_points() {
    let mut rng = rng(3);
    let background = wall(1.5);
    let mut map = patient_map();
    let cap = map.config().max_cell_points;
    for i in 0..300 {
        let cube = view(CUBE, at(0.0, 0.0, 1.0), Vec3::ZERO, 3000, 0.002, &mut rng);
        map.integrate(&frame(i, vec![cube], &background));
    }
    let jobs = map.take_mesh_jobs(FRAME * 300);
    let heaviest = jobs[0]
        .grid
        .iter()
        .map(|(_, m)| m.count)
        .fold(0.0f64, f64::max);
    assert!(
        heaviest <= f64::from(cap) + 1e-6,
        "a voxel holds {heaviest} points"
    );
    assert!(
        heaviest > f64::from(cap) - 2.0,
        "the cap was never reached: {heaviest}"
    );
}

/// A table top (the plane y = 0.2, 20 cm below a sensor at the origin that looks along +z),
/// its points 2 mm apart from 0.5 m to 1.5 m away.
fn table() -> Vec<Vec3> {
    (-150..=150)
        .flat_map(|i| {
            (0..=500).map(move |j| Vec3::new(i as f32 * 0.002, 0.2, 0.5 + j as f32 * 0.002))
        })
        .collect()
}

/// A flat board facing the sensor at `depth_m`, 20 cm wide, from `top_y` down to `bottom_y`
/// (y grows downwards), points 2 mm apart.
fn board(depth_m: f32, top_y: f32, bottom_y: f32) -> Vec<Vec3> {
    let rows = ((bottom_y - top_y) / 0.002).round() as i32;
    (-50..=50)
        .flat_map(|i| {
            (0..=rows).map(move |j| Vec3::new(i as f32 * 0.002, top_y + j as f32 * 0.002, depth_m))
        })
        .collect()
}

/// The fused voxels of the map's only object, world frame (from its first mesh job).
fn fused_points(map: &mut ObjectMap, now: Duration) -> Vec<Vec3> {
    let jobs = map.take_mesh_jobs(now);
    let job = jobs.first().expect("a mesh job");
    job.grid
        .iter()
        .filter_map(|(_, m)| m.centroid())
        .map(|c| job.world_from_object.transform_point3(c))
        .collect()
}

/// A board standing on a table whose fused state reaches 6 cm under the table top (as a
/// smear of alignment leaves it: no camera sees there, so nothing is ever seen through): with
/// the table known as the frame's support, what lies under it beyond the carving margin (2 cm
/// at 1 m, plus half a voxel) is forgotten within a second and the board above it stays;
/// without supports it stays for ever. A board that hangs under a shelf (all of it beyond the
/// shelf's plane) is hidden by the shelf, not forgotten.
#[test]
fn what_a_support_hides_of_an_object_standing_on_it_is_forgotten() {
    let table_plane = (Vec3::Y, 0.2);
    let with_support = |clusters: Vec<Vec<Vec3>>, index: u32, supports: bool| {
        let mut f = frame(index, clusters, &table());
        if supports {
            f.free_space = f.free_space.map(|free| free.with_supports([table_plane]));
        }
        f
    };
    for supports in [true, false] {
        let mut map = patient_map();
        // The first frame's cluster holds the smear under the table; later ones do not.
        map.integrate(&with_support(vec![board(1.0, 0.05, 0.26)], 0, supports));
        for i in 1..30 {
            map.integrate(&with_support(vec![board(1.0, 0.05, 0.2)], i, supports));
        }
        assert_eq!(map.len(), 1);
        let fused = fused_points(&mut map, FRAME * 40);
        let under = fused.iter().filter(|p| p.y > 0.225).count();
        let above = fused.iter().filter(|p| p.y < 0.18).count();
        eprintln!("supports {supports}: {under} voxels under the table, {above} above it");
        assert!(above > 100, "the board itself went: {above} voxels");
        if supports {
            assert_eq!(under, 0, "the smear under the table stayed");
        } else {
            assert!(under > 10, "carved without supports: {under} voxels left");
        }
    }

    // Under a shelf: the board is seen while the shelf is not there, then the shelf (the same
    // plane, measured in front of it) hides it. Nothing of it is forgotten.
    let mut map = patient_map();
    let hanging = || board(1.0, 0.23, 0.35);
    for i in 0..10 {
        map.integrate(&frame(i, vec![hanging()], &wall(1.5)));
    }
    let cells = |map: &ObjectMap| map.objects().next().map(|o| o.cells);
    let before = cells(&map);
    assert!(before > Some(100), "{before:?}");
    for i in 10..40 {
        map.integrate(&with_support(vec![], i, true));
    }
    assert_eq!(map.len(), 1, "the board under the shelf was removed");
    assert_eq!(cells(&map), before, "voxels under the shelf were forgotten");
}

/// A moving camera with poses (slambook's `pose.txt`) sees each object from two places, and its
/// poses are a few centimetres off each other (slambook's two frames by about 4 cm and 1.1°):
/// each view's points land a little off the other's, and each view's free space passes close
/// by the other view's surfaces. Each object should still be one object fused from both views:
/// both views' clusters go to the same id, and nothing is carved away or born again.
///
/// Without the camera-error estimate (`tacmesh_track::camera_error`) it failed: the first
/// view-B frame aligned each object onto B's points, so the object moved by B's pose error; in
/// the next view-A frame its predicted centroid was beyond the match distance of A's cluster,
/// and A's cluster was born again, a new set of objects every two frames (as on the TUM desk's
/// two unposed views). Three objects: fewer cannot tell the camera's motion from their own.
#[test]
fn a_moving_camera_with_poses_a_little_off_fuses_both_views_into_one_object_each() {
    use glam::Quat;
    let places = [
        at(-0.15, 0.0, 1.0),
        at(0.15, 0.05, 1.1),
        posed(Quat::from_rotation_y(0.4), Vec3::new(0.0, -0.1, 1.25)),
    ];
    let bodies = [
        CUBE,
        Body::Sphere { radius_m: 0.06 },
        Body::Cube { half_m: 0.04 },
    ];
    // B's reported pose is 4 cm and 1.1° off its true one, so its points are deprojected (and
    // its free space projected) through the wrong pose.
    let error = Affine3A::from_rotation_translation(
        glam::Quat::from_rotation_x(1.1f32.to_radians()),
        Vec3::new(0.03, -0.02, 0.02),
    );
    two_views(&places, &bodies, view_b() * error, 7);
}

/// A camera with no poses at all that jumps between the same two views every frame (the TUM
/// desk's two frames, looped): B's frames come as if taken from A, every object 15° and up to
/// 30 cm off where A put it, far beyond the match distance. The camera's motion is found from
/// the objects' centroids (RANSAC), and each object is still one object fed by both views.
#[test]
fn a_camera_jumping_between_two_unposed_views_fuses_both_into_one_object_each() {
    use glam::Quat;
    let places = [
        at(-0.25, 0.0, 1.0),
        at(0.15, 0.05, 1.1),
        posed(Quat::from_rotation_y(0.4), Vec3::new(0.0, -0.1, 1.25)),
        posed(Quat::from_rotation_x(0.3), Vec3::new(0.3, -0.15, 1.4)),
        at(-0.1, 0.15, 1.5),
    ];
    let bodies = [
        CUBE,
        Body::Sphere { radius_m: 0.06 },
        Body::Cube { half_m: 0.04 },
        Body::Cube { half_m: 0.06 },
        Body::Sphere { radius_m: 0.05 },
    ];
    two_views(&places, &bodies, Affine3A::IDENTITY, 11);
}

/// View B: 0.3 m to the right of A (at the origin) and 0.1 m forward, turned 15° towards the
/// objects.
fn view_b() -> Affine3A {
    Affine3A::from_rotation_translation(
        glam::Quat::from_rotation_y(-15f32.to_radians()),
        Vec3::new(0.3, 0.0, 0.1),
    )
}

/// Bodies at places seen alternately from A and from B (40 frames), B's frames deprojected
/// through `reported_b` instead of B's true pose: the map must correct every frame onto the
/// map to within a few millimetres where the objects stand, remove nothing, give birth to
/// nothing after the first frames, and send both views' clusters to the same objects, one per
/// body.
fn two_views(places: &[Affine3A], bodies: &[Body], reported_b: Affine3A, seed: u64) {
    let mut rng = rng(seed);
    let true_b = view_b();
    let seen_as_reported_b = reported_b * true_b.inverse();
    let mut map = patient_map();
    let mut ids_per_view: [std::collections::BTreeSet<u64>; 2] = Default::default();
    for index in 0..40u32 {
        let from_b = index % 2 == 1;
        // Where the camera really is, and where its pose says it is.
        let (true_sensor, world_from_sensor) = if from_b {
            (true_b, reported_b)
        } else {
            (Affine3A::IDENTITY, Affine3A::IDENTITY)
        };
        let true_viewpoint = Vec3::from(true_sensor.translation);
        let viewpoint = Vec3::from(world_from_sensor.translation);
        let mut clusters: Vec<Vec<Vec3>> = bodies
            .iter()
            .zip(places)
            .map(|(&body, &place)| view(body, place, true_viewpoint, 3000, 0.002, &mut rng))
            .collect();
        let mut background = wall(1.6);
        if from_b {
            for p in clusters.iter_mut().flatten().chain(background.iter_mut()) {
                *p = seen_as_reported_b.transform_point3(*p);
            }
        }
        let mut all = background;
        all.extend(clusters.iter().flatten());
        let report = map.integrate(&FrameClusters {
            capture_time: FRAME * index,
            viewpoint_m: viewpoint,
            free_space: Some(FreeSpace::from_points(&all, world_from_sensor)),
            clusters,
        });
        // The camera's error is found from the first view-B frame on: the frame is corrected
        // onto the map to within a few millimetres where the objects stand.
        let truth = if from_b {
            seen_as_reported_b.inverse()
        } else {
            Affine3A::IDENTITY
        };
        let middle = places
            .iter()
            .map(|p| Vec3::from(p.translation))
            .sum::<Vec3>()
            / places.len() as f32;
        let off_m = report
            .camera_correction
            .transform_point3(middle)
            .distance(truth.transform_point3(middle));
        assert!(off_m < 0.005, "frame {index}: correction {off_m} m off");
        assert!(
            report.removed.is_empty(),
            "frame {index}: {:?} removed while in view",
            report.removed
        );
        if index >= 4 {
            assert!(
                report.created.is_empty(),
                "frame {index}: {:?} born again",
                report.created
            );
            ids_per_view[usize::from(from_b)].extend(report.cluster_ids.iter().flatten());
        }
    }
    assert_eq!(map.len(), bodies.len(), "one object per body");
    assert_eq!(
        ids_per_view[0], ids_per_view[1],
        "both views' clusters go to the same objects"
    );
    assert_eq!(ids_per_view[0].len(), bodies.len());
}
