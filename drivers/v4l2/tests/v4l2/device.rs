//! The capture backend's errors on nodes that are not depth cameras; no hardware needed.
//! A test against a real camera would be `#[ignore]` and name the device.

use tacmesh_source::SourceError;
use tacmesh_v4l2::{V4l2Config, V4l2Error, V4l2Source};

use crate::util::d435_intrinsics;

#[test]
fn open_missing_node_is_device_missing_naming_it() {
    let err = V4l2Source::open(&V4l2Config::new("/dev/video99", d435_intrinsics())).unwrap_err();
    assert!(
        matches!(&err, V4l2Error::Source(SourceError::DeviceMissing { device, .. }) if device == "/dev/video99"),
        "{err}"
    );
    assert!(err.to_string().contains("/dev/video99"), "{err}");
}

#[test]
fn open_non_video_file_is_a_clear_error() {
    let err = V4l2Source::open(&V4l2Config::new("/dev/null", d435_intrinsics())).unwrap_err();
    assert!(
        matches!(&err, V4l2Error::NotVideoDevice { device, .. } if device == "/dev/null"),
        "{err}"
    );
    let message = err.to_string();
    assert!(
        message.contains("/dev/null") && message.contains("not a V4L2 device"),
        "{message}"
    );
}

#[test]
fn open_regular_file_is_a_clear_error() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml");
    let err = V4l2Source::open(&V4l2Config::new(path, d435_intrinsics())).unwrap_err();
    // Opened read-write it may be refused outright, or the ioctl fails; either names the file.
    assert!(
        matches!(&err, V4l2Error::NotVideoDevice { device, .. } | V4l2Error::Open { device, .. } if device == path),
        "{err}"
    );
}

#[test]
fn open_checks_config_before_the_device() {
    let mut config = V4l2Config::new("/dev/video99", d435_intrinsics());
    config.depth_scale_m = 0.0;
    let err = V4l2Source::open(&config).unwrap_err();
    assert!(matches!(err, V4l2Error::BadDepthScale { .. }), "{err}");
}

/// Needs an Intel RealSense D435 (or another Z16 camera) at 640x480 on `TACMESH_V4L2_DEVICE`
/// (default `/dev/video2`): `cargo test -p tacmesh-v4l2 --features device -- --ignored`.
#[test]
#[ignore = "needs a RealSense D435 depth node (TACMESH_V4L2_DEVICE, default /dev/video2)"]
fn realsense_d435_streams_depth_frames() {
    use tacmesh_source::{monotonic_now, DepthSource, Observation};

    let device = std::env::var("TACMESH_V4L2_DEVICE").unwrap_or_else(|_| "/dev/video2".into());
    let mut source = V4l2Source::open(&V4l2Config::new(device, d435_intrinsics())).unwrap();
    let before = monotonic_now();
    for _ in 0..3 {
        let Observation::Depth(frame) = source.next_observation().unwrap() else {
            panic!("a V4L2 source yields depth frames");
        };
        assert!(frame.is_consistent());
        assert!(frame.capture_time >= before);
        assert!(frame.depth_m.iter().any(|&z| z > 0.0), "an all-zero frame");
    }
}

#[test]
fn open_errors_read_as_advice() {
    for path in ["/dev/video99", "/dev/null"] {
        let err = V4l2Source::open(&V4l2Config::new(path, d435_intrinsics())).unwrap_err();
        eprintln!("{path}: {err}");
    }
}
