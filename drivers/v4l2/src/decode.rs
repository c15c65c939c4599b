//! V4L2 16-bit frame buffers → depth units → [`DepthFrame`]s, with no device and no `v4l`
//! dependency.
//!
//! Follows the kernel's pixel-format pages: `V4L2_PIX_FMT_Z16` (`'Z16 '`, "16-bit depth data
//! with distance values at each pixel … stored in a 16-bit word in the little endian byte
//! order", unit negotiated separately) and `V4L2_PIX_FMT_Y16` (`'Y16 '`, 16-bit greyscale,
//! little-endian). Rows are `bytesperline` apart (`struct v4l2_pix_format`), which may exceed
//! `2 · width`; the padding after the last row may be missing, so a buffer needs
//! `bytesperline · (height − 1) + 2 · width` bytes. Bytes past that (mmap buffers are rounded
//! up to pages) are ignored.
//!
//! Stages, in the order they run: `frame_layout` (check the geometry once) → `decode_rows`
//! (bytes → `u16` units) → [`units_to_metres`] → [`DepthDecoder::decode`] (the whole frame).

use std::time::Duration;

use glam::Affine3A;
use tacmesh_source::{DepthFrame, Intrinsics};

use crate::V4l2Error;

/// The 16-bit V4L2 pixel formats this crate reads, in the default order of preference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    /// `V4L2_PIX_FMT_Z16`: depth, little-endian, unit negotiated with the device.
    Z16,
    /// `V4L2_PIX_FMT_Y16`: 16-bit grey, little-endian (some depth cameras expose depth so).
    Y16,
}

impl PixelFormat {
    /// Z16 first, then Y16.
    pub const PREFERENCE: [PixelFormat; 2] = [PixelFormat::Z16, PixelFormat::Y16];

    /// The four-character code as V4L2 spells it, space padding included.
    pub const fn fourcc(self) -> [u8; 4] {
        match self {
            PixelFormat::Z16 => *b"Z16 ",
            PixelFormat::Y16 => *b"Y16 ",
        }
    }

    /// The format with this four-character code, if it is one of ours.
    pub fn from_fourcc(code: [u8; 4]) -> Option<Self> {
        Self::PREFERENCE.into_iter().find(|f| f.fourcc() == code)
    }
}

impl std::fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PixelFormat::Z16 => "Z16",
            PixelFormat::Y16 => "Y16",
        })
    }
}

/// The geometry of one 16-bit frame, checked: pixel count and minimum buffer length in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct FrameLayout {
    width: usize,
    height: usize,
    bytes_per_line: usize,
    pixels: usize,
    needed_bytes: usize,
}

/// Checks width, height and stride once, with overflow-free arithmetic.
fn frame_layout(width: u32, height: u32, bytes_per_line: u32) -> Result<FrameLayout, V4l2Error> {
    if width == 0 || height == 0 {
        return Err(V4l2Error::EmptyImage { width, height });
    }
    let row_bytes = 2 * u64::from(width);
    if u64::from(bytes_per_line) < row_bytes {
        return Err(V4l2Error::StrideTooSmall {
            bytes_per_line,
            width,
            needed: row_bytes,
        });
    }
    if !bytes_per_line.is_multiple_of(2) {
        return Err(V4l2Error::OddStride { bytes_per_line });
    }
    let needed = u64::from(bytes_per_line) * (u64::from(height) - 1) + row_bytes;
    let pixels = u64::from(width) * u64::from(height);
    let too_large = |_| V4l2Error::TooLarge {
        width,
        height,
        bytes_per_line,
    };
    Ok(FrameLayout {
        width: width as usize,
        height: height as usize,
        bytes_per_line: bytes_per_line as usize,
        pixels: usize::try_from(pixels).map_err(too_large)?,
        needed_bytes: usize::try_from(needed).map_err(too_large)?,
    })
}

/// Copies the rows of little-endian 16-bit pixels out of `bytes` into `out` (cleared first).
fn decode_rows(bytes: &[u8], layout: &FrameLayout, out: &mut Vec<u16>) -> Result<(), V4l2Error> {
    if bytes.len() < layout.needed_bytes {
        return Err(V4l2Error::ShortBuffer {
            got: bytes.len(),
            needed: layout.needed_bytes as u64,
            width: layout.width as u32,
            height: layout.height as u32,
            bytes_per_line: layout.bytes_per_line as u32,
        });
    }
    out.clear();
    out.reserve(layout.pixels);
    for v in 0..layout.height {
        let start = v * layout.bytes_per_line;
        let row = &bytes[start..start + 2 * layout.width];
        out.extend(
            row.chunks_exact(2)
                .map(|pair| u16::from_le_bytes([pair[0], pair[1]])),
        );
    }
    Ok(())
}

/// Decodes a `V4L2_PIX_FMT_Z16` buffer into row-major depth units, honouring the row stride
/// `bytes_per_line` (at least `2 · width`, even; the last row's padding may be missing).
///
/// Errors, never panics: [`V4l2Error::EmptyImage`], [`V4l2Error::StrideTooSmall`],
/// [`V4l2Error::OddStride`], [`V4l2Error::TooLarge`], [`V4l2Error::ShortBuffer`].
pub fn decode_z16(
    bytes: &[u8],
    width: u32,
    height: u32,
    bytes_per_line: u32,
) -> Result<Vec<u16>, V4l2Error> {
    let layout = frame_layout(width, height, bytes_per_line)?;
    let mut units = Vec::new();
    decode_rows(bytes, &layout, &mut units)?;
    Ok(units)
}

/// Decodes a `V4L2_PIX_FMT_Y16` (16-bit grey, little-endian) buffer: the same layout and errors
/// as [`decode_z16`].
pub fn decode_y16(
    bytes: &[u8],
    width: u32,
    height: u32,
    bytes_per_line: u32,
) -> Result<Vec<u16>, V4l2Error> {
    decode_z16(bytes, width, height, bytes_per_line)
}

/// Depth units → metres along the optical axis; unit 0 (no reading) stays 0.
pub fn units_to_metres(units: &[u16], depth_scale_m: f32) -> Vec<f32> {
    units
        .iter()
        .map(|&u| f32::from(u) * depth_scale_m)
        .collect()
}

/// Turns one negotiated V4L2 frame buffer into a [`DepthFrame`]: the stream's pixel format and
/// stride, the camera's intrinsics (their width and height are the image's), the depth scale
/// and the sensor pose.
#[derive(Debug, Clone)]
pub struct DepthDecoder {
    format: PixelFormat,
    layout: FrameLayout,
    intrinsics: Intrinsics,
    depth_scale_m: f32,
    world_from_sensor: Affine3A,
    units: Vec<u16>,
}

impl DepthDecoder {
    /// Depth scale of Intel RealSense cameras: one unit is a millimetre.
    pub const REALSENSE_DEPTH_SCALE_M: f32 = 0.001;

    /// Checks the geometry and scale once. `depth_scale_m` is metres per unit and must be
    /// positive and finite.
    pub fn new(
        format: PixelFormat,
        bytes_per_line: u32,
        intrinsics: Intrinsics,
        depth_scale_m: f32,
        world_from_sensor: Affine3A,
    ) -> Result<Self, V4l2Error> {
        if !(depth_scale_m.is_finite() && depth_scale_m > 0.0) {
            return Err(V4l2Error::BadDepthScale { depth_scale_m });
        }
        Ok(Self {
            format,
            layout: frame_layout(intrinsics.width, intrinsics.height, bytes_per_line)?,
            intrinsics,
            depth_scale_m,
            world_from_sensor,
            units: Vec::new(),
        })
    }

    pub fn format(&self) -> PixelFormat {
        self.format
    }

    /// The row stride in bytes this decoder expects.
    pub fn bytes_per_line(&self) -> u32 {
        self.layout.bytes_per_line as u32
    }

    /// Bytes a frame buffer must hold at least.
    pub fn needed_bytes(&self) -> usize {
        self.layout.needed_bytes
    }

    /// Decodes one frame buffer captured at `capture_time` (on [`tacmesh_source::monotonic_now`]).
    /// Z16 and Y16 share one layout, so the format only names what is decoded.
    pub fn decode(
        &mut self,
        bytes: &[u8],
        capture_time: Duration,
    ) -> Result<DepthFrame, V4l2Error> {
        decode_rows(bytes, &self.layout, &mut self.units)?;
        Ok(DepthFrame {
            intrinsics: self.intrinsics,
            depth_m: units_to_metres(&self.units, self.depth_scale_m),
            world_from_sensor: self.world_from_sensor,
            capture_time,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two rows of three pixels, stride 8 (2 bytes of padding per row).
    fn padded_2x3() -> Vec<u8> {
        vec![
            1, 0, 2, 0, 3, 1, 0xEE, 0xEE, // row 0: 1, 2, 259, padding
            0, 1, 5, 0, 0xFF, 0xFF, 0xEE, 0xEE, // row 1: 256, 5, 65535, padding
        ]
    }

    #[test]
    fn decode_reads_little_endian_and_skips_padding() {
        let units = decode_z16(&padded_2x3(), 3, 2, 8).unwrap();
        assert_eq!(units, vec![1, 2, 259, 256, 5, 65535]);
        assert_eq!(decode_y16(&padded_2x3(), 3, 2, 8).unwrap(), units);
    }

    #[test]
    fn decode_accepts_missing_padding_after_last_row() {
        let bytes = padded_2x3();
        assert_eq!(
            decode_z16(&bytes[..14], 3, 2, 8).unwrap(),
            vec![1, 2, 259, 256, 5, 65535]
        );
        assert!(matches!(
            decode_z16(&bytes[..13], 3, 2, 8),
            Err(V4l2Error::ShortBuffer {
                got: 13,
                needed: 14,
                ..
            })
        ));
    }

    #[test]
    fn decode_rejects_stride_narrower_than_a_row() {
        assert!(matches!(
            decode_z16(&[0; 64], 3, 2, 5),
            Err(V4l2Error::StrideTooSmall {
                bytes_per_line: 5,
                width: 3,
                needed: 6
            })
        ));
    }

    #[test]
    fn decode_rejects_odd_stride() {
        assert!(matches!(
            decode_z16(&[0; 64], 3, 2, 7),
            Err(V4l2Error::OddStride { bytes_per_line: 7 })
        ));
    }

    #[test]
    fn decode_rejects_odd_length_tight_buffer() {
        // A tight 3x2 frame is 12 bytes; 11 is one byte (half a pixel) short.
        assert!(matches!(
            decode_z16(&[0; 11], 3, 2, 6),
            Err(V4l2Error::ShortBuffer {
                got: 11,
                needed: 12,
                ..
            })
        ));
        assert!(matches!(
            decode_z16(&[], 3, 2, 6),
            Err(V4l2Error::ShortBuffer { got: 0, .. })
        ));
    }

    #[test]
    fn decode_rejects_empty_image() {
        assert!(matches!(
            decode_z16(&[0; 8], 0, 2, 8),
            Err(V4l2Error::EmptyImage {
                width: 0,
                height: 2
            })
        ));
        assert!(matches!(
            decode_z16(&[0; 8], 2, 0, 8),
            Err(V4l2Error::EmptyImage { .. })
        ));
    }

    #[test]
    fn decode_of_huge_geometry_is_an_error_not_a_panic() {
        // The largest stride and height: the byte count still fits in u64 (no overflow panic).
        let err = decode_z16(&[0; 16], u32::MAX / 2, u32::MAX, u32::MAX - 1).unwrap_err();
        assert!(
            matches!(
                err,
                V4l2Error::TooLarge { .. } | V4l2Error::ShortBuffer { .. }
            ),
            "{err}"
        );
    }

    #[test]
    fn pixel_format_fourcc_round_trips() {
        for f in PixelFormat::PREFERENCE {
            assert_eq!(PixelFormat::from_fourcc(f.fourcc()), Some(f));
        }
        assert_eq!(PixelFormat::from_fourcc(*b"YUYV"), None);
        assert_eq!(PixelFormat::Z16.fourcc(), *b"Z16 ");
    }

    fn intrinsics(width: u32, height: u32) -> Intrinsics {
        Intrinsics {
            width,
            height,
            fx: 1.0,
            fy: 1.0,
            cx: 0.0,
            cy: 0.0,
        }
    }

    #[test]
    fn decoder_scales_units_to_metres_and_keeps_zero() {
        let pose = Affine3A::from_translation(glam::Vec3::Z);
        let mut decoder =
            DepthDecoder::new(PixelFormat::Z16, 8, intrinsics(3, 2), 0.001, pose).unwrap();
        assert_eq!(decoder.needed_bytes(), 14);
        let mut bytes = padded_2x3();
        bytes[0] = 0; // pixel (0, 0) has no reading
        let frame = decoder.decode(&bytes, Duration::from_secs(7)).unwrap();
        let expected_m = [0.0, 0.002, 0.259, 0.256, 0.005, 65.535];
        assert_eq!(frame.depth_m.len(), expected_m.len());
        for (got, want) in frame.depth_m.iter().zip(expected_m) {
            assert!((got - want).abs() <= want * 1e-6, "{got} vs {want}");
        }
        assert_eq!(frame.depth_m[0], 0.0);
        assert_eq!(frame.world_from_sensor, pose);
        assert_eq!(frame.capture_time, Duration::from_secs(7));
        assert!(frame.is_consistent());
    }

    #[test]
    fn decoder_rejects_bad_depth_scale() {
        for scale in [0.0, -0.001, f32::NAN, f32::INFINITY] {
            let err = DepthDecoder::new(
                PixelFormat::Z16,
                6,
                intrinsics(3, 2),
                scale,
                Affine3A::IDENTITY,
            )
            .unwrap_err();
            assert!(matches!(err, V4l2Error::BadDepthScale { .. }), "{err}");
        }
    }
}
