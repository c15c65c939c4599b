//! Depth pixels as OpenNI2 delivers them (16-bit, rows `stride` bytes apart) to metres.
//!
//! Pipeline: [`unpack_rows`] (strip row padding, native-endian `u16`) → [`depth_m_from_raw`]
//! (scale by the pixel format's unit). 0 means "no reading" in every OpenNI2 depth format
//! and stays 0.

use crate::OpenNi2Error;

/// The depth pixel formats this crate converts (`OniPixelFormat`, `OniCEnums.h`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthPixelFormat {
    /// `ONI_PIXEL_FORMAT_DEPTH_1_MM` (100): one unit is one millimetre.
    Millimetre,
    /// `ONI_PIXEL_FORMAT_DEPTH_100_UM` (101): one unit is 100 micrometres.
    HundredMicrometre,
}

impl DepthPixelFormat {
    /// The format for an `OniPixelFormat` code, or `None` for any other format.
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            100 => Some(Self::Millimetre),
            101 => Some(Self::HundredMicrometre),
            _ => None,
        }
    }

    /// The `OniPixelFormat` code.
    pub fn code(self) -> i32 {
        match self {
            Self::Millimetre => 100,
            Self::HundredMicrometre => 101,
        }
    }

    /// Pixel units per metre (1000 or 10000; dividing by it rounds correctly, multiplying
    /// by 1e-3 does not).
    pub fn units_per_metre(self) -> f32 {
        match self {
            Self::Millimetre => 1e3,
            Self::HundredMicrometre => 1e4,
        }
    }
}

/// One depth image copied out of an OpenNI2 frame before the frame was released: tightly
/// packed rows of raw 16-bit units, and the frame's metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct RawDepthImage {
    pub width: u32,
    pub height: u32,
    /// The `OniPixelFormat` code of the frame's video mode.
    pub pixel_format: i32,
    /// The stream's full resolution; differs from `width`×`height` when cropping is on.
    pub full_width: u32,
    pub full_height: u32,
    /// Top-left pixel of the crop in the full image, `(0, 0)` without cropping.
    pub crop_origin: (u32, u32),
    /// The device's frame counter and clock (microseconds, device epoch).
    pub frame_index: i32,
    pub device_timestamp_us: u64,
    /// `width * height` raw units, row-major.
    pub units: Vec<u16>,
}

/// Copies `height` rows of `width` native-endian `u16` pixels out of `bytes`, rows starting
/// `stride_bytes` apart. Fails if the buffer is too short or the stride narrower than a row.
pub fn unpack_rows(
    bytes: &[u8],
    width: usize,
    height: usize,
    stride_bytes: usize,
) -> Result<Vec<u16>, OpenNi2Error> {
    let row_bytes = width * 2;
    if stride_bytes < row_bytes {
        return Err(OpenNi2Error::MalformedFrame(format!(
            "stride {stride_bytes} B is narrower than a row of {width} 16-bit pixels"
        )));
    }
    let needed = match height {
        0 => 0,
        h => stride_bytes * (h - 1) + row_bytes,
    };
    if bytes.len() < needed {
        return Err(OpenNi2Error::MalformedFrame(format!(
            "{} B of data for {width}×{height} pixels with stride {stride_bytes} B (needs {needed} B)",
            bytes.len()
        )));
    }
    let mut units = Vec::with_capacity(width * height);
    for row in 0..height {
        let start = row * stride_bytes;
        units.extend(
            bytes[start..start + row_bytes]
                .chunks_exact(2)
                .map(|b| u16::from_ne_bytes([b[0], b[1]])),
        );
    }
    Ok(units)
}

/// Raw units to metres along the optical axis; 0 ("no reading") stays 0.
pub fn depth_m_from_raw(format: DepthPixelFormat, units: &[u16]) -> Vec<f32> {
    let units_per_metre = format.units_per_metre();
    units
        .iter()
        .map(|&u| f32::from(u) / units_per_metre)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn millimetres_and_hundred_micrometres_become_metres() {
        let mm = depth_m_from_raw(DepthPixelFormat::Millimetre, &[0, 1000, 1234, 65535]);
        assert_eq!(mm, vec![0.0, 1.0, 1.234, 65.535]);
        let um = depth_m_from_raw(DepthPixelFormat::HundredMicrometre, &[0, 10000, 12345]);
        assert_eq!(um, vec![0.0, 1.0, 1.2345]);
    }

    #[test]
    fn pixel_format_codes_round_trip_and_reject_shifted_formats() {
        for format in [
            DepthPixelFormat::Millimetre,
            DepthPixelFormat::HundredMicrometre,
        ] {
            assert_eq!(DepthPixelFormat::from_code(format.code()), Some(format));
        }
        assert_eq!(
            DepthPixelFormat::from_code(100),
            Some(DepthPixelFormat::Millimetre)
        );
        // ONI_PIXEL_FORMAT_SHIFT_9_2 / SHIFT_9_3 and RGB888 are not depth in metres.
        for code in [102, 103, 200] {
            assert_eq!(DepthPixelFormat::from_code(code), None);
        }
    }

    #[test]
    fn unpack_rows_drops_row_padding() {
        // 2×2 pixels, rows 6 bytes apart (2 bytes of padding each).
        let mut bytes = Vec::new();
        for (px, pad) in [([1u16, 2], [0xAA, 0xAA]), ([3, 4], [0xBB, 0xBB])] {
            bytes.extend(px[0].to_ne_bytes());
            bytes.extend(px[1].to_ne_bytes());
            bytes.extend(pad);
        }
        assert_eq!(unpack_rows(&bytes, 2, 2, 6).unwrap(), vec![1, 2, 3, 4]);
        // The last row needs no padding after it.
        assert_eq!(
            unpack_rows(&bytes[..10], 2, 2, 6).unwrap(),
            vec![1, 2, 3, 4]
        );
    }

    #[test]
    fn unpack_rows_rejects_short_buffer_and_narrow_stride() {
        let bytes = [0u8; 7];
        assert!(matches!(
            unpack_rows(&bytes, 2, 2, 4),
            Err(OpenNi2Error::MalformedFrame(_))
        ));
        assert!(matches!(
            unpack_rows(&bytes, 2, 1, 3),
            Err(OpenNi2Error::MalformedFrame(_))
        ));
    }
}
