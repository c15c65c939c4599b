//! DepthAI depth frames, as the bridge copies them out of Python, → [`DepthFrame`]s. No Python
//! here: these are the hardware-free steps, tested without DepthAI.

use std::time::Duration;

use glam::Affine3A;
use tacmesh_source::{DepthFrame, Intrinsics};

use crate::DepthAiError;

/// StereoDepth's `depth` output counts millimetres.
pub const DEPTH_UNIT_M: f32 = 0.001;

/// One `dai.ImgFrame` as copied out of Python: its bytes and the metadata needed to read them.
#[derive(Debug, Clone, PartialEq)]
pub struct RawDepthImage {
    pub width: u32,
    pub height: u32,
    /// Bytes from one row to the next (`ImgFrame.getStride()`).
    pub stride_bytes: u32,
    /// `ImgFrame.getType()`'s member name, e.g. `RAW16`.
    pub type_name: String,
    pub data: Vec<u8>,
    /// The frame's own pinhole matrix (`getTransformation().getIntrinsicMatrix()`), row-major,
    /// when its transformation is valid.
    pub intrinsic_matrix: Option<[[f32; 3]; 3]>,
    pub sequence: i64,
    /// `ImgFrame.getTimestamp()`: DepthAI's host clock, `std::chrono::steady_clock`, which on
    /// Linux is `CLOCK_MONOTONIC`, the clock of [`tacmesh_source::monotonic_now`].
    pub timestamp: Duration,
}

/// A 3×3 pinhole matrix → [`Intrinsics`] for a `width`×`height` image, refusing what cannot be
/// a camera: non-finite entries, a last row other than `0 0 1`, the identity DepthAI reports
/// for frames without calibration, focal lengths outside 0.05–50 image widths, or a principal
/// point outside the image.
pub fn intrinsics_from_matrix(
    m: [[f32; 3]; 3],
    width: u32,
    height: u32,
) -> Result<Intrinsics, DepthAiError> {
    let no = |reason: String| Err(DepthAiError::NoIntrinsics { reason });
    if m.iter().flatten().any(|x| !x.is_finite()) {
        return no(format!("non-finite matrix {m:?}"));
    }
    if m[2] != [0.0, 0.0, 1.0] || m[1][0] != 0.0 {
        return no(format!("not a pinhole matrix: {m:?}"));
    }
    let (fx, fy, cx, cy) = (m[0][0], m[1][1], m[0][2], m[1][2]);
    if fx == 1.0 && fy == 1.0 && cx == 0.0 && cy == 0.0 {
        return no("the identity matrix, DepthAI's value for a frame without calibration".into());
    }
    let (w, h) = (width as f32, height as f32);
    let plausible = |f: f32| f >= 0.05 * w && f <= 50.0 * w;
    if !(plausible(fx) && plausible(fy)) {
        return no(format!(
            "focal lengths {fx} × {fy} px for a {width}-pixel-wide image"
        ));
    }
    if !((0.0..=w).contains(&cx) && (0.0..=h).contains(&cy)) {
        return no(format!(
            "principal point ({cx}, {cy}) outside the {width}×{height} image"
        ));
    }
    Ok(Intrinsics {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
    })
}

/// Decodes a RAW16 depth frame (millimetres, rows `stride_bytes` apart) with `intrinsics`
/// (whose size must be the frame's) into a [`DepthFrame`].
pub fn depth_frame(
    raw: &RawDepthImage,
    intrinsics: Intrinsics,
    world_from_sensor: Affine3A,
    capture_time: Duration,
) -> Result<DepthFrame, DepthAiError> {
    if raw.type_name != "RAW16" {
        return Err(DepthAiError::NotDepth {
            type_name: raw.type_name.clone(),
        });
    }
    if (intrinsics.width, intrinsics.height) != (raw.width, raw.height) {
        return Err(DepthAiError::SizeMismatch {
            width: raw.width,
            height: raw.height,
            intrinsics_width: intrinsics.width,
            intrinsics_height: intrinsics.height,
        });
    }
    let units = tacmesh_v4l2::decode_z16(&raw.data, raw.width, raw.height, raw.stride_bytes)?;
    Ok(DepthFrame {
        intrinsics,
        depth_m: tacmesh_v4l2::units_to_metres(&units, DEPTH_UNIT_M),
        world_from_sensor,
        capture_time,
    })
}

/// Depth in metres → the RAW16 millimetres DepthAI carries, rounded; 0, non-finite and negative
/// depths (no reading) become 0, depths beyond 65.535 m saturate. Used to record frames.
pub fn raw16_from_metres(depth_m: &[f32]) -> Vec<u8> {
    depth_m
        .iter()
        .flat_map(|&z| {
            let mm = if z.is_finite() && z > 0.0 {
                (z / DEPTH_UNIT_M).round().min(f32::from(u16::MAX)) as u16
            } else {
                0
            };
            mm.to_le_bytes()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const OAK_D_640X400: [[f32; 3]; 3] =
        [[398.8, 0.0, 319.4], [0.0, 398.8, 201.6], [0.0, 0.0, 1.0]];

    fn raw(width: u32, height: u32, stride_bytes: u32, data: Vec<u8>) -> RawDepthImage {
        RawDepthImage {
            width,
            height,
            stride_bytes,
            type_name: "RAW16".into(),
            data,
            intrinsic_matrix: None,
            sequence: 0,
            timestamp: Duration::ZERO,
        }
    }

    #[test]
    fn calibrated_matrices_become_intrinsics() {
        let k = intrinsics_from_matrix(OAK_D_640X400, 640, 400).unwrap();
        assert_eq!(
            (k.width, k.height, k.fx, k.cx, k.cy),
            (640, 400, 398.8, 319.4, 201.6)
        );
    }

    #[test]
    fn absurd_matrices_are_refused_with_the_reason() {
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut nan = OAK_D_640X400;
        nan[0][0] = f32::NAN;
        let mut tiny = OAK_D_640X400;
        tiny[1][1] = 3.0;
        let mut off_image = OAK_D_640X400;
        off_image[0][2] = 900.0;
        let mut projective = OAK_D_640X400;
        projective[2][0] = 0.1;
        for (m, needle) in [
            (identity, "identity"),
            (nan, "non-finite"),
            (tiny, "focal lengths"),
            (off_image, "principal point"),
            (projective, "not a pinhole"),
        ] {
            let err = intrinsics_from_matrix(m, 640, 400).unwrap_err().to_string();
            assert!(err.contains(needle), "{err}");
            assert!(err.contains("fx, fy, cx and cy"), "{err}");
        }
    }

    #[test]
    fn raw16_frames_decode_to_metres_honouring_the_stride() {
        // 2×2 pixels, rows 6 bytes apart: 1000 mm, 0 (no reading); 65535 mm, 1 mm.
        let bytes = vec![0xE8, 0x03, 0, 0, 0xAA, 0xAA, 0xFF, 0xFF, 1, 0, 0xAA, 0xAA];
        let intrinsics = Intrinsics {
            width: 2,
            height: 2,
            fx: 2.0,
            fy: 2.0,
            cx: 1.0,
            cy: 1.0,
        };
        let frame = depth_frame(
            &raw(2, 2, 6, bytes),
            intrinsics,
            Affine3A::IDENTITY,
            Duration::from_millis(5),
        )
        .unwrap();
        assert_eq!(frame.depth_m, vec![1.0, 0.0, 65.535, 0.001]);
        assert_eq!(frame.capture_time, Duration::from_millis(5));
    }

    #[test]
    fn wrong_type_size_or_short_buffer_is_an_error() {
        let k = intrinsics_from_matrix(OAK_D_640X400, 640, 400).unwrap();
        let mut disparity = raw(640, 400, 1280, vec![0; 1280 * 400]);
        disparity.type_name = "RAW8".into();
        let err = depth_frame(&disparity, k, Affine3A::IDENTITY, Duration::ZERO).unwrap_err();
        assert!(err.to_string().contains("RAW8"), "{err}");
        let small = raw(320, 200, 640, vec![0; 640 * 200]);
        let err = depth_frame(&small, k, Affine3A::IDENTITY, Duration::ZERO).unwrap_err();
        assert!(err.to_string().contains("320x200"), "{err}");
        let short = raw(640, 400, 1280, vec![0; 1280 * 399]);
        let err = depth_frame(&short, k, Affine3A::IDENTITY, Duration::ZERO).unwrap_err();
        assert!(matches!(err, DepthAiError::Frame(_)), "{err}");
    }

    #[test]
    fn metres_round_trip_through_raw16() {
        let depth = [0.0, 1.2344, f32::NAN, -1.0, 70.0, 0.0004, 0.0006];
        let bytes = raw16_from_metres(&depth);
        let units: Vec<u16> = bytes
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        assert_eq!(units, vec![0, 1234, 0, 0, 65535, 0, 1]);
    }
}
