//! Both backends through pseudo-terminal pairs. Time limits here only bound hangs; nothing
//! asserts on wall-clock durations.

use std::time::{Duration, Instant};

use glam::{Affine3A, Vec2, Vec3};
use tacmesh_serial::emulator::{spawn_emulated_rplidar, EmulatorConfig};
use tacmesh_serial::rplidar::Command;
use tacmesh_serial::{CamsenseSource, HealthStatus, RplidarSource, SerialConfig};
use tacmesh_source::{DepthSource, Observation, SourceError};

use crate::util::{capture, complete_revolutions, feed_paced, pty, write_fully};

/// 115200 baud, 8N1: ten bits a byte.
const CAMSENSE_BYTES_PER_S: usize = 115_200 / 10;

fn mount() -> Affine3A {
    Affine3A::from_translation(Vec3::new(1.0, 2.0, 0.3))
}

/// Short limits so failing cases end quickly.
const FAST: SerialConfig = SerialConfig {
    baud_rate: 115_200,
    read_timeout_ms: 20,
    stall_timeout_ms: 300,
    revolution_timeout_ms: 2_000,
};

#[test]
fn camsense_capture_at_baud_rate_matches_the_pure_decoder() {
    // The first 2 s of the capture at 115200 baud: about 11 revolutions.
    let bytes = capture()[..2 * CAMSENSE_BYTES_PER_S].to_vec();
    let expected = complete_revolutions(&bytes);
    assert!(expected.len() >= 8, "{}", expected.len());

    let (master, _slave, path) = pty();
    let mut source = CamsenseSource::open_with(&path, FAST, mount()).expect("open the pty");
    assert_eq!(source.name(), format!("camsense:{path}"));
    let (close, feeder) = feed_paced(master, bytes, CAMSENSE_BYTES_PER_S);

    let mut last_time = Duration::ZERO;
    for (i, want) in expected.iter().enumerate() {
        let (revolution, capture_time) = source.next_revolution().expect("a revolution");
        assert_eq!(&revolution, want, "revolution {i}");
        assert!(capture_time >= last_time);
        last_time = capture_time;
    }
    let stats = source.stats();
    assert_eq!(stats.skipped_bytes, 20);
    assert_eq!(stats.bad_packets, 0);
    assert!(source
        .speed_rev_per_s()
        .is_some_and(|s| (4.9..5.5).contains(&s)));

    // The device end closes: the source reports it instead of hanging.
    close.send(()).expect("feeder is waiting");
    feeder
        .join()
        .expect("feeder thread")
        .expect("feeder wrote everything");
    let err = source.next_observation().expect_err("no device any more");
    assert!(matches!(err, SourceError::Disconnected { .. }), "{err}");
}

#[test]
fn camsense_observation_carries_cloud_pose_and_time() {
    let bytes = capture()[..CAMSENSE_BYTES_PER_S].to_vec();
    let expected = complete_revolutions(&bytes);
    let (master, _slave, path) = pty();
    let mut source = CamsenseSource::open_with(&path, FAST, mount()).expect("open the pty");
    let (_close, _feeder) = feed_paced(master, bytes, CAMSENSE_BYTES_PER_S * 4);
    let before = tacmesh_source::monotonic_now();
    let Observation::Cloud {
        cloud,
        world_from_sensor,
        capture_time,
        ..
    } = source.next_observation().expect("an observation")
    else {
        panic!("a range scanner yields clouds");
    };
    assert_eq!(cloud, expected[0].to_cloud().0);
    assert_eq!(world_from_sensor, mount());
    assert!(capture_time >= before && capture_time <= tacmesh_source::monotonic_now());
}

#[test]
fn camsense_corrupted_stream_resyncs_through_the_pty() {
    let mut bytes = capture()[..CAMSENSE_BYTES_PER_S * 3 / 2].to_vec();
    // Garbage every ~2 kB, one truncated packet, one flipped header byte.
    for at in (2_000..bytes.len() - 100).step_by(2_000).rev() {
        bytes.splice(at..at, [0x55, 0xAA, 0x00, 0x13, 0x37]);
    }
    bytes.drain(5_020..5_030);
    bytes[9_020] ^= 0x40;
    let expected = complete_revolutions(&bytes);
    assert!(expected.len() >= 5);

    let (master, _slave, path) = pty();
    let mut source = CamsenseSource::open_with(&path, FAST, mount()).expect("open the pty");
    let (_close, _feeder) = feed_paced(master, bytes, CAMSENSE_BYTES_PER_S * 2);
    for want in &expected {
        let (revolution, _) = source.next_revolution().expect("a revolution");
        assert_eq!(&revolution, want);
    }
    let stats = source.stats();
    assert!(stats.bad_packets >= 1, "{stats:?}");
    assert!(stats.skipped_bytes > 20 + 5 * 5, "{stats:?}");
}

#[test]
fn camsense_silent_port_is_disconnected_after_the_stall_timeout() {
    let (master, _slave, path) = pty();
    let mut source = CamsenseSource::open_with(&path, FAST, mount()).expect("open the pty");
    let err = source.next_observation().expect_err("nothing arrives");
    assert!(
        matches!(&err, SourceError::Disconnected { device, reason } if device == &path && reason.contains("no bytes")),
        "{err}"
    );
    drop(master);
}

#[test]
fn camsense_garbage_only_is_malformed_not_a_hang() {
    let (mut master, _slave, path) = pty();
    let config = SerialConfig {
        revolution_timeout_ms: 300,
        ..FAST
    };
    let mut source = CamsenseSource::open_with(&path, config, mount()).expect("open the pty");
    let feeder = std::thread::spawn(move || {
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(2) {
            if write_fully(&mut master, &[0x12; 64]).is_err() {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    });
    let err = source
        .next_observation()
        .expect_err("garbage makes no revolution");
    assert!(matches!(err, SourceError::Malformed { .. }), "{err}");
    assert!(source.stats().skipped_bytes > 0);
    drop(source);
    feeder.join().expect("feeder thread");
}

fn assert_points_on_walls(cloud: &tacmesh_source::PointCloud, config: &EmulatorConfig) -> usize {
    cloud
        .points
        .iter()
        .filter(|p| {
            let p_in_room = Vec2::new(p.x, p.y) + config.room.sensor_in_room_m;
            p.z == 0.0 && config.room.wall_distance_m(p_in_room) < 0.005
        })
        .count()
}

/// Waits (bounded) until the emulator has seen `command` last.
fn wait_for_last_request(
    emulator: &tacmesh_serial::emulator::EmulatedRplidar,
    command: Command,
) -> bool {
    let deadline = Instant::now() + Duration::from_secs(5);
    while Instant::now() < deadline {
        if emulator.requests().last() == Some(&command) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

#[test]
fn rplidar_emulated_room_through_the_pty() {
    let config = EmulatorConfig::a1_in_4m_room();
    let (master, _slave, path) = pty();
    let emulator = spawn_emulated_rplidar(master, config.clone());
    let mut source =
        RplidarSource::open(&path, SerialConfig::RPLIDAR_A1_A2, mount()).expect("open");
    assert_eq!(source.name(), format!("rplidar:{path}"));
    assert_eq!(source.device_info(), config.info);
    assert_eq!(source.health().status, HealthStatus::Good);

    let mut last_time = Duration::ZERO;
    for _ in 0..3 {
        let Observation::Cloud {
            cloud,
            world_from_sensor,
            capture_time,
            ..
        } = source.next_observation().expect("a revolution")
        else {
            panic!("a range scanner yields clouds");
        };
        assert_eq!(cloud.len(), 360);
        assert_eq!(assert_points_on_walls(&cloud, &config), 360);
        // The nearest wall is straight ahead: 2 m − 0.5 m.
        let nearest = cloud
            .points
            .iter()
            .map(|p| p.length())
            .fold(f32::MAX, f32::min);
        assert!((nearest - 1.5).abs() < 0.005, "{nearest}");
        assert_eq!(world_from_sensor, mount());
        assert!(capture_time > last_time);
        last_time = capture_time;
    }
    assert_eq!(source.stats().resyncs, 0);

    drop(source); // sends STOP
    assert!(wait_for_last_request(&emulator, Command::Stop));
    assert_eq!(
        emulator.stop(),
        [
            Command::Stop,
            Command::GetHealth,
            Command::GetInfo,
            Command::Scan,
            Command::Stop
        ]
    );
}

#[test]
fn rplidar_a3_baud_rate_opens_too() {
    let config = EmulatorConfig {
        bytes_per_s: Some(256_000 / 10),
        ..EmulatorConfig::a1_in_4m_room()
    };
    let (master, _slave, path) = pty();
    let _emulator = spawn_emulated_rplidar(master, config);
    let mut source = RplidarSource::open(&path, SerialConfig::RPLIDAR_A3, mount()).expect("open");
    let (revolution, _) = source.next_revolution().expect("a revolution");
    assert_eq!(revolution.samples.len(), 360);
}

#[test]
fn rplidar_garbage_in_the_node_stream_resyncs() {
    let config = EmulatorConfig {
        garbage_every_nodes: Some(97),
        ..EmulatorConfig::a1_in_4m_room()
    };
    let (master, _slave, path) = pty();
    let _emulator = spawn_emulated_rplidar(master, config.clone());
    let mut source =
        RplidarSource::open(&path, SerialConfig::RPLIDAR_A1_A2, mount()).expect("open");
    let (mut points, mut on_walls) = (0, 0);
    for _ in 0..4 {
        let Observation::Cloud { cloud, .. } = source.next_observation().expect("a revolution")
        else {
            panic!("a range scanner yields clouds");
        };
        points += cloud.len();
        on_walls += assert_points_on_walls(&cloud, &config);
    }
    let stats = source.stats();
    eprintln!("{stats:?}: {on_walls} of {points} points on the walls");
    assert!(stats.resyncs >= 10, "{stats:?}");
    // Standard nodes have two check bits only: a rare misaligned window can pass (module doc).
    assert!(on_walls * 100 >= points * 97, "{on_walls} of {points}");
    assert!(points >= 4 * 340, "{points}");
}

#[test]
fn rplidar_that_goes_away_is_disconnected() {
    let (master, slave, path) = pty();
    let emulator = spawn_emulated_rplidar(master, EmulatorConfig::a1_in_4m_room());
    let mut source =
        RplidarSource::open(&path, SerialConfig::RPLIDAR_A1_A2, mount()).expect("open");
    source.next_observation().expect("a revolution");
    emulator.stop(); // closes the master end
    drop(slave);
    let deadline = Instant::now() + Duration::from_secs(10);
    let err = loop {
        match source.next_observation() {
            Err(e) => break e,
            Ok(_) => assert!(Instant::now() < deadline, "still delivering"),
        }
    };
    assert!(matches!(err, SourceError::Disconnected { .. }), "{err}");
}

#[test]
fn rplidar_silent_port_fails_to_open_without_hanging() {
    let (_master, _slave, path) = pty();
    let err = RplidarSource::open(&path, SerialConfig::RPLIDAR_A1_A2, mount())
        .err()
        .expect("nobody answers");
    assert!(
        matches!(&err, SourceError::Disconnected { reason, .. } if reason.contains("no answer")),
        "{err}"
    );
}
