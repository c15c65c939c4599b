//! The decoders and sources against the real recordings in `testdata/` (see its SOURCES.md).

use std::path::PathBuf;
use std::time::Duration;

use tacmesh_replay::decode::{decode_pgm, decode_png, decode_tiff, decode_z16};
use tacmesh_replay::{
    read_depth_image, CloudSequence, CloudSequenceConfig, DecodeError, DepthFile, ImageSequence,
    ImageSequenceConfig, Pacing, Rate, ReplayError, ReplayKind, ReplaySource, ReplaySpec,
    Z16Layout,
};
use tacmesh_source::glam::{Affine3A, Vec3};
use tacmesh_source::{DepthFrame, DepthSource, Intrinsics, Observation, SourceError};

use tacmesh_testdata::{bytes, path as data};

const D435_Z16: &str = "depth/realsense_d435/frame0_640x480.z16";
const D435_PNG: &str = "depth/realsense_d435/frame0_depth.png";
const KINECT_TIFF: &str = "depth/pcl_kinect_grabber/frame_20121214T142255.814212_depth.tiff";
const KINECT_PCD: &str = "depth/pcl_kinect_grabber/frame_20121214T142255.814212.pcd";

fn kinect_intrinsics() -> Intrinsics {
    Intrinsics {
        width: 640,
        height: 480,
        fx: 525.0,
        fy: 525.0,
        cx: 320.0,
        cy: 240.0,
    }
}

fn depth_frame(observation: Observation) -> DepthFrame {
    match observation {
        Observation::Depth(frame) => frame,
        other => panic!("expected a depth frame, got {other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Decoding

#[test]
fn realsense_z16_equals_its_png_pixel_for_pixel() {
    let z16 = decode_z16(&bytes(D435_Z16), D435_Z16, Z16Layout::packed(640, 480)).expect("z16");
    let png = decode_png(&bytes(D435_PNG), D435_PNG).expect("png");
    assert_eq!((z16.width, z16.height), (640, 480));
    assert_eq!(z16, png);
    assert_eq!(z16.valid_pixels(), 286_520);
    assert_eq!(z16.valid_range(), Some((341, 3182)));
}

#[test]
fn z16_layout_comes_from_the_file_name() {
    let image = read_depth_image(&data(D435_Z16), None).expect("named layout");
    assert_eq!((image.width, image.height), (640, 480));
}

#[test]
fn padded_stride_z16_decodes_identically() {
    let packed = bytes(D435_Z16);
    let mut padded = Vec::new();
    for row in packed.chunks_exact(1280) {
        padded.extend_from_slice(row);
        padded.extend_from_slice(&[0xab; 64]);
    }
    let layout = Z16Layout {
        row_stride_bytes: Some(1280 + 64),
        ..Z16Layout::packed(640, 480)
    };
    let expected = decode_z16(&packed, "packed", Z16Layout::packed(640, 480)).expect("packed");
    assert_eq!(
        decode_z16(&padded, "padded", layout).expect("padded"),
        expected
    );
    // Without the last row's padding, too.
    let trimmed = &padded[..padded.len() - 64];
    assert_eq!(
        decode_z16(trimmed, "trimmed", layout).expect("trimmed"),
        expected
    );
}

#[test]
fn z16_of_the_wrong_size_names_the_file_and_the_sizes() {
    let packed = bytes(D435_Z16);
    let err = decode_z16(
        &packed[..packed.len() - 2],
        "short.z16",
        Z16Layout::packed(640, 480),
    )
    .unwrap_err();
    let message = err.to_string();
    assert!(matches!(err, DecodeError::Malformed { .. }), "{message}");
    assert!(
        message.contains("short.z16") && message.contains("614398"),
        "{message}"
    );
    let err = decode_z16(&packed, "wide.z16", Z16Layout::packed(641, 480)).unwrap_err();
    assert!(err.to_string().contains("wide.z16"), "{err}");
}

#[test]
fn z16_without_a_layout_says_to_give_one() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("frame.z16");
    std::fs::write(&path, bytes(D435_Z16)).expect("copy");
    let err = read_depth_image(&path, None).unwrap_err();
    assert!(matches!(err, DecodeError::NoZ16Layout { .. }), "{err}");
}

#[test]
fn tum_pngs_are_640x480_with_the_recorded_valid_counts() {
    for (rel, valid) in [
        ("depth/tum_fr1/1_depth.png", 204_859),
        ("depth/tum_fr1/2_depth.png", 201_565),
    ] {
        let image = decode_png(&bytes(rel), rel).expect("TUM depth PNG");
        assert_eq!((image.width, image.height), (640, 480), "{rel}");
        assert_eq!(image.valid_pixels(), valid, "{rel}");
    }
}

#[test]
fn eight_bit_png_is_refused_as_not_depth() {
    let rel = "depth/tum_fr1/1_rgb.png";
    let err = decode_png(&bytes(rel), rel).unwrap_err();
    assert!(matches!(err, DecodeError::NotDepth16 { .. }), "{err}");
    assert!(err.to_string().contains("1_rgb.png"), "{err}");
}

#[test]
fn truncated_png_is_an_error_naming_the_file() {
    let png = bytes(D435_PNG);
    let err = decode_png(&png[..png.len() / 2], "half.png").unwrap_err();
    assert!(matches!(err, DecodeError::Png { .. }), "{err}");
    assert!(err.to_string().contains("half.png"), "{err}");
}

#[test]
fn kinect_tiffs_are_640x480_millimetres() {
    // SOURCES.md gives 666–1731 mm over the three frames and 271,575 valid pixels in frame 1.
    let (mut lo, mut hi) = (u16::MAX, 0);
    for (rel, valid) in [
        (KINECT_TIFF, 271_575),
        (
            "depth/pcl_kinect_grabber/frame_20121214T142256.068683_depth.tiff",
            271_395,
        ),
        (
            "depth/pcl_kinect_grabber/frame_20121214T142256.332395_depth.tiff",
            271_328,
        ),
    ] {
        let image = decode_tiff(&bytes(rel), rel).expect("PackBits TIFF");
        assert_eq!((image.width, image.height), (640, 480), "{rel}");
        assert_eq!(image.valid_pixels(), valid, "{rel}");
        let (frame_lo, frame_hi) = image.valid_range().expect("readings");
        (lo, hi) = (lo.min(frame_lo), hi.max(frame_hi));
    }
    assert_eq!((lo, hi), (666, 1731));
}

#[test]
fn rgb_tiff_and_truncated_tiff_are_errors() {
    let rel = "depth/pcl_kinect_grabber/frame_20121214T142255.814212_rgb.tiff";
    let err = decode_tiff(&bytes(rel), rel).unwrap_err();
    assert!(matches!(err, DecodeError::NotDepth16 { .. }), "{err}");
    let tiff = bytes(KINECT_TIFF);
    let err = decode_tiff(&tiff[..tiff.len() / 2], "half.tiff").unwrap_err();
    assert!(err.to_string().contains("half.tiff"), "{err}");
}

#[test]
fn slambook_pgm_is_big_endian_millimetres() {
    let rel = "depth/slambook_kinect/1.pgm";
    let image = decode_pgm(&bytes(rel), rel).expect("16-bit PGM");
    assert_eq!((image.width, image.height), (640, 480));
    assert_eq!(image.valid_pixels(), 209_236);
    assert_eq!(image.valid_range(), Some((946, 9823)));
}

#[test]
fn truncated_pgm_says_how_many_bytes_are_missing() {
    let pgm = bytes("depth/slambook_kinect/1.pgm");
    let err = decode_pgm(&pgm[..pgm.len() - 1], "cut.pgm").unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains("cut.pgm") && message.contains("614400"),
        "{message}"
    );
}

// ---------------------------------------------------------------------------------------------
// Deprojection

/// SOURCES.md: the grabber's TIFF deprojected with fx = fy = 525, cx = 320, cy = 240 and
/// 1 mm units reproduces the PCD saved beside it, pixel for pixel.
#[test]
fn kinect_tiff_deprojects_to_the_grabbers_pcd() {
    let image = read_depth_image(&data(KINECT_TIFF), None).expect("TIFF");
    let frame = DepthFrame {
        intrinsics: kinect_intrinsics(),
        depth_m: image.depth.iter().map(|&d| f32::from(d) * 0.001).collect(),
        world_from_sensor: Affine3A::IDENTITY,
        capture_time: Duration::ZERO,
    };
    let deprojected = frame.deproject(10.0);
    let pcd = tacmesh_formats::pcd::read_pcd(&data(KINECT_PCD)).expect("PCD");
    assert_eq!((pcd.width, pcd.height), (640, 480));
    let expected: Vec<Vec3> = pcd.points.iter().copied().filter(|p| p.z > 0.0).collect();
    assert_eq!(deprojected.points_in_world.len(), 271_575);
    assert_eq!(expected.len(), 271_575);
    assert_eq!(deprojected.invalid_pixels, 640 * 480 - 271_575);
    let worst = deprojected
        .points_in_world
        .iter()
        .zip(&expected)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    eprintln!("worst deprojection difference {worst:e} m");
    assert!(worst < 1e-6, "differs from PCL by up to {worst} m");
}

// ---------------------------------------------------------------------------------------------
// Image sequences

fn kinect_sequence(config: ImageSequenceConfig) -> ImageSequence {
    ImageSequence::from_directory(&data("depth/pcl_kinect_grabber"), config).expect("sequence")
}

#[test]
fn directory_sequence_plays_depth_frames_in_name_order_then_ends() {
    let mut source = kinect_sequence(ImageSequenceConfig::new(kinect_intrinsics(), 0.001));
    let names: Vec<_> = source
        .files()
        .iter()
        .map(|f| f.path.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "frame_20121214T142255.814212_depth.tiff",
            "frame_20121214T142256.068683_depth.tiff",
            "frame_20121214T142256.332395_depth.tiff",
        ]
    );
    let mut last_time = Duration::ZERO;
    for _ in 0..3 {
        let frame = depth_frame(source.next_observation().expect("frame"));
        assert!(frame.is_consistent());
        assert!(frame.capture_time > last_time);
        last_time = frame.capture_time;
        let valid: Vec<f32> = frame.depth_m.iter().copied().filter(|&z| z > 0.0).collect();
        assert!(valid.iter().all(|&z| (0.665..1.732).contains(&z)));
    }
    assert!(matches!(
        source.next_observation(),
        Err(SourceError::EndOfStream { .. })
    ));
}

#[test]
fn looping_sequence_starts_over() {
    let mut config = ImageSequenceConfig::new(kinect_intrinsics(), 0.001);
    config.looping = true;
    let mut source = kinect_sequence(config);
    let first = depth_frame(source.next_observation().expect("frame 1"));
    for _ in 0..2 {
        source.next_observation().expect("frames 2, 3");
    }
    let again = depth_frame(source.next_observation().expect("frame 1 again"));
    assert_eq!(first.depth_m, again.depth_m);
}

#[test]
fn missing_or_wrong_size_frame_is_malformed_and_the_next_frame_plays() {
    let tum = data("depth/tum_fr1/1_depth.png");
    let files = vec![
        DepthFile::new(data(KINECT_TIFF)),
        DepthFile::new(data("depth/pcl_kinect_grabber").join("gone.tiff")),
        DepthFile::new(data("depth/tum_fr1/1_rgb.png")),
        DepthFile::new(tum),
    ];
    let mut intrinsics = kinect_intrinsics();
    intrinsics.width = 320;
    let mut source = ImageSequence::new(
        "test",
        files.clone(),
        ImageSequenceConfig::new(kinect_intrinsics(), 0.001),
    )
    .expect("sequence");
    source.next_observation().expect("frame 1 plays");
    for what in ["gone.tiff", "1_rgb.png"] {
        match source.next_observation() {
            Err(SourceError::Malformed { reason, .. }) => {
                assert!(reason.contains(what), "{reason}")
            }
            other => panic!("expected Malformed for {what}, got {other:?}"),
        }
    }
    source.next_observation().expect("the frame after plays");

    // A first frame that cannot be played fails the start, as an unreadable .oni does: the
    // daemon would otherwise serve nothing for ever.
    match ImageSequence::new("narrow", files, ImageSequenceConfig::new(intrinsics, 0.001)) {
        Err(ReplayError::FirstFrame { reason, .. }) => {
            assert!(
                reason.contains("640x480") && reason.contains("320x480"),
                "{reason}"
            )
        }
        other => panic!("expected FirstFrame for the size, got {other:?}"),
    }
}

/// Every replay source fails the start on a first frame it cannot play (garbage, empty,
/// truncated, all zeros, every depth far beyond any camera's range) and on intrinsics no camera
/// has, naming the file or the key; the later frames of a good start are skipped when bad.
#[test]
fn a_replay_whose_first_frame_cannot_be_played_fails_at_start() {
    let dir = tempfile::tempdir().expect("temp dir");
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).expect("written");
        path
    };
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    for (name, bytes) in [
        ("garbage.ply", garbage.as_slice()),
        ("empty.ply", b"".as_slice()),
        ("garbage.pcd", garbage.as_slice()),
        ("truncated.pcd", b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3".as_slice()),
        (
            "nan.pcd",
            b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\nnan nan nan\n".as_slice(),
        ),
    ] {
        let path = write(name, bytes);
        match CloudSequence::new(name, vec![path], CloudSequenceConfig::default()) {
            Err(err @ ReplayError::FirstFrame { .. }) => {
                assert!(err.to_string().contains("nothing would be served"), "{err}")
            }
            other => panic!("{name}: expected FirstFrame, got {other:?}"),
        }
    }
    // Depth images: all zeros, and TUM's 1/5000 taken for metres (every depth thousands of
    // metres away).
    let zeros = write("zeros.pgm", &{
        let mut b = b"P5 4 2 65535\n".to_vec();
        b.extend([0u8; 16]);
        b
    });
    let intrinsics = Intrinsics {
        width: 4,
        height: 2,
        fx: 3.0,
        fy: 3.0,
        cx: 2.0,
        cy: 1.0,
    };
    let err = ImageSequence::new(
        "zeros",
        vec![DepthFile::new(zeros)],
        ImageSequenceConfig::new(intrinsics, 0.001),
    )
    .expect_err("all zeros");
    assert!(err.to_string().contains("every pixel is 0"), "{err}");
    let tum = DepthFile::new(data("depth/tum_fr1/1_depth.png"));
    let tum_intrinsics = Intrinsics {
        width: 640,
        height: 480,
        fx: 517.3,
        fy: 516.5,
        cx: 318.6,
        cy: 255.3,
    };
    let err = ImageSequence::new(
        "tum",
        vec![tum.clone()],
        ImageSequenceConfig::new(tum_intrinsics, 1.0),
    )
    .expect_err("metres");
    assert!(err.to_string().contains("is the scale right"), "{err}");
    assert!(ImageSequence::new(
        "tum",
        vec![tum.clone()],
        ImageSequenceConfig::new(tum_intrinsics, 1.0 / 5000.0)
    )
    .is_ok());
    // Intrinsics no camera has.
    for (key, k) in [
        (
            "fx=-5",
            Intrinsics {
                fx: -5.0,
                ..tum_intrinsics
            },
        ),
        (
            "fy=0",
            Intrinsics {
                fy: 0.0,
                ..tum_intrinsics
            },
        ),
        (
            "fx=0.5",
            Intrinsics {
                fx: 0.5,
                ..tum_intrinsics
            },
        ),
        (
            "fx=100000",
            Intrinsics {
                fx: 100_000.0,
                ..tum_intrinsics
            },
        ),
        (
            "cx=-1",
            Intrinsics {
                cx: -1.0,
                ..tum_intrinsics
            },
        ),
        (
            "cy=NaN",
            Intrinsics {
                cy: f32::NAN,
                ..tum_intrinsics
            },
        ),
    ] {
        let err = ImageSequence::new(
            "tum",
            vec![tum.clone()],
            ImageSequenceConfig::new(k, 1.0 / 5000.0),
        )
        .expect_err(key);
        let name = key.split('=').next().unwrap();
        assert!(
            err.to_string().contains(&format!("{name}=")),
            "{key}: {err}"
        );
    }
}

#[test]
fn tum_association_file_gives_timestamps_and_recorded_pacing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let association = dir.path().join("depth.txt");
    let tum = data("depth/tum_fr1");
    std::fs::write(
        &association,
        format!(
            "# timestamp filename\n1305031102.160407 {0}/1_depth.png\n1305031102.260407 {0}/2_depth.png\n",
            tum.display()
        ),
    )
    .expect("write depth.txt");
    let mut config = ImageSequenceConfig::new(
        Intrinsics {
            width: 640,
            height: 480,
            fx: 517.3,
            fy: 516.5,
            cx: 318.6,
            cy: 255.3,
        },
        1.0 / 5000.0,
    );
    config.pacing = Pacing::Recorded;
    let mut source = ImageSequence::from_association_file(&association, config).expect("seq");
    let a = depth_frame(source.next_observation().expect("frame 1"));
    let b = depth_frame(source.next_observation().expect("frame 2"));
    let gap = b.capture_time - a.capture_time;
    assert!(gap >= Duration::from_millis(95), "frames {gap:?} apart");
    // Median of frame 1 is 1.50 m (SOURCES.md).
    let mut valid: Vec<f32> = a.depth_m.iter().copied().filter(|&z| z > 0.0).collect();
    assert_eq!(valid.len(), 204_859);
    valid.sort_by(f32::total_cmp);
    let median = valid[valid.len() / 2];
    assert!((median - 1.5).abs() < 0.05, "median {median} m");
}

#[test]
fn recorded_pacing_without_timestamps_is_refused() {
    let mut config = ImageSequenceConfig::new(kinect_intrinsics(), 0.001);
    config.pacing = Pacing::Recorded;
    let err = ImageSequence::from_directory(&data("depth/pcl_kinect_grabber"), config).unwrap_err();
    assert!(matches!(err, ReplayError::NoTimestamps { .. }), "{err}");
}

#[test]
fn slambook_poses_place_each_frame() {
    let poses =
        tacmesh_replay::read_pose_file(&data("depth/slambook_kinect/pose.txt")).expect("pose.txt");
    assert_eq!(poses.len(), 5);
    let mut config = ImageSequenceConfig::new(
        Intrinsics {
            width: 640,
            height: 480,
            fx: 518.0,
            fy: 519.0,
            cx: 325.5,
            cy: 253.5,
        },
        0.001,
    );
    config.poses = Some(poses.clone());
    let mut source = ImageSequence::from_directory(&data("depth/slambook_kinect"), config)
        .expect("sequence of 1.pgm, 2.pgm");
    assert_eq!(source.files().len(), 2);
    for pose in &poses[..2] {
        let frame = depth_frame(source.next_observation().expect("frame"));
        assert_eq!(frame.world_from_sensor, *pose);
    }
    let first = poses[0].translation;
    assert!(Vec3::from(first).distance(Vec3::new(-0.228993, 0.00645704, 0.0287837)) < 1e-6);
}

#[test]
fn too_few_poses_is_refused() {
    let mut config = ImageSequenceConfig::new(kinect_intrinsics(), 0.001);
    config.poses = Some(vec![Affine3A::IDENTITY]);
    let err = ImageSequence::from_directory(&data("depth/pcl_kinect_grabber"), config).unwrap_err();
    assert!(
        matches!(
            err,
            ReplayError::TooFewPoses {
                poses: 1,
                frames: 3,
                ..
            }
        ),
        "{err}"
    );
}

// ---------------------------------------------------------------------------------------------
// Cloud sequences

/// The grabber's organised PCD replays as the organised cloud its TIFF deprojects to: the same
/// point at every pixel, and no point (non-finite) at the same pixels.
#[test]
fn organised_pcd_replays_as_its_depth_image_deprojected_pixel_for_pixel() {
    let mut source = CloudSequence::new(
        "kinect",
        vec![data(KINECT_PCD)],
        CloudSequenceConfig::default(),
    )
    .expect("sequence");
    let Observation::Cloud { cloud, grid, .. } = source.next_observation().expect("cloud") else {
        panic!("a cloud sequence yields clouds");
    };
    let grid = grid.expect("a 640x480 PCD is organised");
    assert_eq!((grid.width, grid.height), (640, 480));
    let image = read_depth_image(&data(KINECT_TIFF), None).expect("TIFF");
    let frame = DepthFrame {
        intrinsics: kinect_intrinsics(),
        depth_m: image.depth.iter().map(|&d| f32::from(d) * 0.001).collect(),
        world_from_sensor: Affine3A::IDENTITY,
        capture_time: Duration::ZERO,
    };
    let pixels = frame.deproject_organised(10.0).points_in_world;
    assert_eq!(cloud.len(), pixels.len());
    for (i, (p, q)) in cloud.points.iter().zip(&pixels).enumerate() {
        assert_eq!(p.is_finite(), q.is_finite(), "pixel {i}: {p} vs {q}");
        assert!(
            !p.is_finite() || p.distance(*q) < 1e-6,
            "pixel {i}: {p} vs {q}"
        );
    }
}

#[test]
fn cloud_sequence_plays_clouds_with_the_configured_pose_at_a_fixed_rate() {
    let pose = Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0));
    let config = CloudSequenceConfig {
        pacing: Pacing::Fixed { fps: 20.0 },
        looping: true,
        world_from_sensor: pose,
        ..CloudSequenceConfig::default()
    };
    let mut source = CloudSequence::new(
        "milk",
        vec![
            data("pointclouds/pcl/milk.pcd"),
            data("pointclouds/stanford_bunny/bun000.ply"),
        ],
        config,
    )
    .expect("sequence");
    let mut times = Vec::new();
    for expected in [13_704, 40_256, 13_704] {
        match source.next_observation().expect("cloud") {
            Observation::Cloud {
                cloud,
                grid,
                world_from_sensor,
                capture_time,
            } => {
                assert_eq!(cloud.len(), expected);
                assert_eq!(grid, None, "neither file is organised");
                assert_eq!(world_from_sensor, pose);
                times.push(capture_time);
            }
            other => panic!("expected a cloud, got {other:?}"),
        }
    }
    assert!(
        times[2] - times[0] >= Duration::from_millis(95),
        "{times:?}"
    );
}

#[test]
fn unreadable_cloud_is_malformed_then_the_sequence_ends() {
    let mut source = CloudSequence::new(
        "clouds",
        vec![
            data("pointclouds/pcl/milk.pcd"),
            PathBuf::from("/nonexistent/x.pcd"),
        ],
        CloudSequenceConfig::default(),
    )
    .expect("sequence");
    source.next_observation().expect("milk");
    assert!(matches!(
        source.next_observation(),
        Err(SourceError::Malformed { .. })
    ));
    assert!(matches!(
        source.next_observation(),
        Err(SourceError::EndOfStream { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Specs

#[test]
fn spec_opens_a_realsense_z16_with_its_intrinsics() {
    let spec = ReplaySpec::parse(&format!(
        "{}?fx=390.4315&fy=390.4315&cx=331.3879&cy=242.1873&depth_scale_m=0.001",
        data(D435_Z16).display()
    ))
    .expect("spec");
    let mut source = spec.open().expect("opens");
    assert!(matches!(source, ReplaySource::Images(_)));
    let frame = depth_frame(source.next_observation().expect("frame"));
    assert_eq!(
        (frame.intrinsics.width, frame.intrinsics.height),
        (640, 480)
    );
    let valid = frame.depth_m.iter().filter(|&&z| z > 0.0).count();
    assert_eq!(valid, 286_520);
    assert!(matches!(
        source.next_observation(),
        Err(SourceError::EndOfStream { .. })
    ));
}

#[test]
fn spec_detects_images_in_a_mixed_directory_and_clouds_when_asked() {
    let dir = data("depth/pcl_kinect_grabber");
    let images = ReplaySpec::parse(&format!("{}?fx=525&fy=525&cx=320&cy=240", dir.display()))
        .expect("spec")
        .open()
        .expect("opens");
    match images {
        ReplaySource::Images(seq) => assert_eq!(seq.files().len(), 3),
        other => panic!("expected images, got {other:?}"),
    }
    let clouds = ReplaySpec::parse(&format!("{}?kind=clouds&rate=max&loop", dir.display()))
        .expect("spec")
        .open()
        .expect("opens");
    match clouds {
        ReplaySource::Clouds(seq) => assert_eq!(seq.files().len(), 1),
        other => panic!("expected clouds, got {other:?}"),
    }
}

#[test]
fn spec_for_images_without_intrinsics_is_refused() {
    let err = ReplaySpec::new(data(KINECT_TIFF)).open().unwrap_err();
    assert!(
        matches!(err, ReplayError::MissingIntrinsics { .. }),
        "{err}"
    );
}

#[test]
fn spec_refuses_image_keys_for_clouds() {
    let err = ReplaySpec::parse(&format!(
        "{}?fx=500",
        data("pointclouds/pcl/milk.pcd").display()
    ))
    .expect("spec")
    .open()
    .unwrap_err();
    assert!(err.to_string().contains("fx"), "{err}");
}

#[test]
fn spec_refuses_recordings_of_other_crates() {
    let err = ReplaySpec::new(data("recordings/openni1_primesense_12frames_640x480.oni"))
        .open()
        .unwrap_err();
    assert!(err.to_string().contains("tacmesh-oni"), "{err}");
    let err = ReplaySpec::new(data(
        "recordings/realsense_d435_single_depth_color_640x480.bag",
    ))
    .open()
    .unwrap_err();
    assert!(err.to_string().contains("tacmesh-rosbag"), "{err}");
}

#[test]
fn spec_deserializes_from_a_table() {
    #[derive(serde::Deserialize)]
    struct Wrapper {
        replay: ReplaySpec,
    }
    let text = r#"{"replay": {"path": "/d/seq", "kind": "images", "fx": 525, "rate": 15,
                   "loop": true, "world_from_sensor": [0, 0, 1, 0, 0, 0, 1]}}"#;
    let wrapper: Wrapper = serde_json::from_str(text).expect("deserializes");
    let spec = wrapper.replay;
    assert_eq!(spec.kind, Some(ReplayKind::Images));
    assert_eq!(spec.rate, Some(Rate::Fps(15.0)));
    assert!(spec.looping);
    let named: ReplaySpec =
        serde_json::from_str(r#"{"path": "x", "rate": "recorded"}"#).expect("named rate");
    assert_eq!(named.rate, Some(Rate::Recorded));
    assert!(serde_json::from_str::<ReplaySpec>(r#"{"path": "x", "fps": 3}"#).is_err());
}

#[test]
fn spec_tells_association_txt_from_xyz_txt() {
    let dir = tempfile::tempdir().expect("temp dir");
    let association = dir.path().join("depth.txt");
    std::fs::write(
        &association,
        format!("1.0 {}\n", data("depth/tum_fr1/1_depth.png").display()),
    )
    .expect("write depth.txt");
    let xyz = dir.path().join("points.txt");
    std::fs::write(&xyz, "0 0 1\n0 1 1\n1 0 1\n").expect("write xyz");

    let spec = format!(
        "{}?fx=517.3&fy=516.5&cx=318.6&cy=255.3&depth_scale_m=0.0002",
        association.display()
    );
    match ReplaySpec::parse(&spec)
        .expect("spec")
        .open()
        .expect("opens")
    {
        ReplaySource::Images(seq) => assert_eq!(seq.files()[0].timestamp_s, Some(1.0)),
        other => panic!("expected images, got {other:?}"),
    }
    // The directory plays its depth.txt too.
    let spec = format!(
        "{}?fx=517.3&fy=516.5&cx=318.6&cy=255.3",
        dir.path().display()
    );
    let mut source = ReplaySpec::parse(&spec)
        .expect("spec")
        .open()
        .expect("opens");
    assert!(matches!(source, ReplaySource::Images(_)));
    source.next_observation().expect("the TUM frame");

    match ReplaySpec::new(&xyz).open().expect("opens") {
        ReplaySource::Clouds(mut seq) => match seq.next_observation().expect("cloud") {
            Observation::Cloud { cloud, .. } => assert_eq!(cloud.len(), 3),
            other => panic!("expected a cloud, got {other:?}"),
        },
        other => panic!("expected clouds, got {other:?}"),
    }
}

#[test]
fn non_positive_fixed_rate_is_refused() {
    let mut config = ImageSequenceConfig::new(kinect_intrinsics(), 0.001);
    config.pacing = Pacing::Fixed { fps: 0.0 };
    let err = ImageSequence::from_directory(&data("depth/pcl_kinect_grabber"), config).unwrap_err();
    assert!(matches!(err, ReplayError::InvalidConfig { .. }), "{err}");
}
