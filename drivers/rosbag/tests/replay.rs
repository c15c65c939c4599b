//! BagReplay on the real bag.

use std::time::Instant;

use tacmesh_rosbag::{BagReplay, Pacing, ReplayOptions};
use tacmesh_source::glam::{Affine3A, Vec3};
use tacmesh_source::{monotonic_now, DepthSource, Observation, SourceError};

use crate::util::{d435_bag, d435_frame0_z16};

fn depth(obs: Observation) -> tacmesh_source::DepthFrame {
    match obs {
        Observation::Depth(f) => f,
        other => panic!("expected depth, got {other:?}"),
    }
}

#[test]
fn replay_yields_both_frames_in_metres_then_ends() {
    let pose = Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0));
    let opts = ReplayOptions {
        pacing: Pacing::MaxRate,
        ..Default::default()
    };
    let mut replay = BagReplay::open(d435_bag(), pose, opts).unwrap();
    assert_eq!(replay.name(), format!("replay:{}", d435_bag().display()));
    assert_eq!(replay.depth_units_m(), 0.001);
    let before = monotonic_now();
    let f0 = depth(replay.next_observation().unwrap());
    assert!(f0.is_consistent());
    assert_eq!(f0.world_from_sensor, pose);
    assert!(f0.capture_time >= before);
    assert!(
        (f0.intrinsics.fx - 390.4315).abs() < 1e-3 && (f0.intrinsics.cy - 242.1873).abs() < 1e-3
    );
    let raw = d435_frame0_z16();
    for (i, z) in f0.depth_m.iter().enumerate() {
        let mm = u16::from_le_bytes([raw[2 * i], raw[2 * i + 1]]);
        assert_eq!(*z, f32::from(mm) * 0.001);
    }
    assert_eq!(f0.depth_m.iter().filter(|&&z| z > 0.0).count(), 286_520);
    depth(replay.next_observation().unwrap());
    assert!(matches!(
        replay.next_observation(),
        Err(SourceError::EndOfStream { .. })
    ));
}

#[test]
fn looping_replay_starts_over() {
    let opts = ReplayOptions {
        pacing: Pacing::MaxRate,
        looping: true,
        ..Default::default()
    };
    let mut replay = BagReplay::open(d435_bag(), Affine3A::IDENTITY, opts).unwrap();
    let frames: Vec<_> = (0..5)
        .map(|_| depth(replay.next_observation().unwrap()))
        .collect();
    assert_eq!(frames[0].depth_m, frames[2].depth_m);
    assert_eq!(frames[1].depth_m, frames[3].depth_m);
    assert_ne!(frames[0].depth_m, frames[1].depth_m);
}

#[test]
fn recorded_pacing_spaces_frames_by_message_time() {
    // The two depth messages' record-time difference.
    let msgs = crate::util::read_all(&d435_bag()).unwrap();
    let times: Vec<_> = msgs
        .iter()
        .filter(|m| m.connection.topic == crate::util::DEPTH_TOPIC)
        .map(|m| m.time.as_duration())
        .collect();
    let recorded_gap = times[1] - times[0];
    println!("recorded gap between depth frames: {recorded_gap:?}");
    let mut replay =
        BagReplay::open(d435_bag(), Affine3A::IDENTITY, ReplayOptions::default()).unwrap();
    replay.next_observation().unwrap();
    let started = Instant::now();
    replay.next_observation().unwrap();
    let waited = started.elapsed();
    assert!(
        waited + std::time::Duration::from_millis(2) >= recorded_gap,
        "{waited:?} < {recorded_gap:?}"
    );
    assert!(
        waited < recorded_gap + std::time::Duration::from_millis(200),
        "{waited:?}"
    );
}
