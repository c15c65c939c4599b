use std::time::Duration;

use tacmesh_source::glam::{Affine3A, Vec3};
use tacmesh_v4l2::{decode_y16, decode_z16, DepthDecoder, PixelFormat, V4l2Error};

use crate::util::{d435_intrinsics, d435_png_units, d435_z16, with_stride, HEIGHT, WIDTH};

#[test]
fn real_d435_z16_matches_png_pixel_for_pixel() {
    let bytes = d435_z16();
    assert_eq!(bytes.len(), 614_400);
    let units = decode_z16(&bytes, WIDTH, HEIGHT, 2 * WIDTH).unwrap();
    let png = d435_png_units();
    assert_eq!(units.len(), 307_200);
    assert_eq!(png.len(), 307_200);
    let first_difference = units.iter().zip(&png).position(|(a, b)| a != b);
    assert_eq!(first_difference, None, "Z16 and PNG differ");

    // SOURCES.md: 286,520 valid pixels, 341–3182 mm.
    let valid: Vec<u16> = units.iter().copied().filter(|&u| u != 0).collect();
    assert_eq!(valid.len(), 286_520);
    assert_eq!(valid.iter().min(), Some(&341));
    assert_eq!(valid.iter().max(), Some(&3182));
}

#[test]
fn real_d435_padded_stride_decodes_identically() {
    let tight = d435_z16();
    let expected = decode_z16(&tight, WIDTH, HEIGHT, 2 * WIDTH).unwrap();
    // 1344 = 1280 rounded up to 64 bytes; 2048 a page-ish stride.
    for stride in [1282, 1344, 2048] {
        let padded = with_stride(&tight, WIDTH, stride);
        assert_eq!(
            padded.len(),
            stride as usize * (HEIGHT as usize - 1) + 2 * WIDTH as usize
        );
        assert_eq!(
            decode_z16(&padded, WIDTH, HEIGHT, stride).unwrap(),
            expected
        );
        assert_eq!(
            decode_y16(&padded, WIDTH, HEIGHT, stride).unwrap(),
            expected
        );
        // Trailing bytes beyond the frame (page-rounded mmap buffers) are ignored.
        let mut rounded = padded.clone();
        rounded.resize(padded.len().next_multiple_of(4096), 0xFF);
        assert_eq!(
            decode_z16(&rounded, WIDTH, HEIGHT, stride).unwrap(),
            expected
        );
        // One byte short of the last pixel is an error.
        let err = decode_z16(&padded[..padded.len() - 1], WIDTH, HEIGHT, stride).unwrap_err();
        assert!(matches!(err, V4l2Error::ShortBuffer { .. }), "{err}");
    }
}

#[test]
fn real_d435_frame_in_metres_with_intrinsics_and_pose() {
    let bytes = with_stride(&d435_z16(), WIDTH, 1344);
    let pose = Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.5));
    let mut decoder = DepthDecoder::new(
        PixelFormat::Z16,
        1344,
        d435_intrinsics(),
        DepthDecoder::REALSENSE_DEPTH_SCALE_M,
        pose,
    )
    .unwrap();
    let frame = decoder.decode(&bytes, Duration::from_millis(1234)).unwrap();
    assert!(frame.is_consistent());
    assert_eq!(frame.intrinsics, d435_intrinsics());
    assert_eq!(frame.world_from_sensor, pose);
    assert_eq!(frame.capture_time, Duration::from_millis(1234));

    let valid: Vec<f32> = frame.depth_m.iter().copied().filter(|&z| z > 0.0).collect();
    assert_eq!(valid.len(), 286_520);
    let (lo, hi) = valid
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &z| (lo.min(z), hi.max(z)));
    assert!(
        (lo - 0.341).abs() < 1e-6 && (hi - 3.182).abs() < 1e-6,
        "{lo} {hi}"
    );
    // Everything deprojects within the camera's range.
    let cloud = frame.deproject(10.0);
    assert_eq!(cloud.points_in_world.len(), 286_520);
    assert_eq!(cloud.invalid_pixels, 307_200 - 286_520);
}

#[test]
fn real_d435_decoder_rejects_wrong_resolution_buffer() {
    // The 640x480 frame handed to a decoder configured for 848x480 (a D435 mode) is too short.
    let mut intrinsics = d435_intrinsics();
    intrinsics.width = 848;
    let mut decoder = DepthDecoder::new(
        PixelFormat::Z16,
        1696,
        intrinsics,
        0.001,
        Affine3A::IDENTITY,
    )
    .unwrap();
    let err = decoder.decode(&d435_z16(), Duration::ZERO).unwrap_err();
    assert!(
        matches!(
            err,
            V4l2Error::ShortBuffer {
                got: 614_400,
                needed: 814_080,
                ..
            }
        ),
        "{err}"
    );
}
