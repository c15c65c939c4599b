//! Decoding the ROS 1 messages a depth replay needs from their wire serialisation.
//!
//! ROS 1 serialisation is little-endian and unpadded: fixed-size fields in declaration order,
//! `string` and variable arrays `T[]` as a `u32` length then the elements, fixed arrays
//! `T[N]` as just the `N` elements, `time` as `sec: u32, nsec: u32`, `bool` as one byte.
//!
//! Entry points: [`Image::decode`] and [`Image::depth_u16`] (`sensor_msgs/Image`),
//! [`CameraInfo::decode`] and [`CameraInfo::intrinsics`] (`sensor_msgs/CameraInfo`),
//! [`decode_float32`] (`std_msgs/Float32`, RealSense option values).

use tacmesh_source::Intrinsics;

use crate::Time;

/// Why a message's bytes could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MessageError {
    #[error(
        "{msg_type} ends early: {field} needs {needed} bytes at byte {offset}, {available} remain"
    )]
    Truncated {
        msg_type: &'static str,
        field: &'static str,
        offset: usize,
        needed: u64,
        available: usize,
    },
    #[error("{msg_type} field {field} is not UTF-8")]
    NotUtf8 {
        msg_type: &'static str,
        field: &'static str,
    },
    #[error("image encoding `{0}` is not a 16-bit depth encoding (expected `mono16` or `16UC1`)")]
    UnsupportedEncoding(String),
    #[error("inconsistent image: {0}")]
    BadImage(String),
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RosHeader {
    pub seq: u32,
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    pub header: RosHeader,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: bool,
    /// Bytes per row, including any padding.
    pub step: u32,
    pub data: Vec<u8>,
}

/// `sensor_msgs/CameraInfo` (`roi` flattened).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    pub header: RosHeader,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    /// Row-major 3×3 camera matrix `[fx 0 cx; 0 fy cy; 0 0 1]`.
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    /// `roi`: x_offset, y_offset, height, width.
    pub roi: [u32; 4],
    pub roi_do_rectify: bool,
}

impl Image {
    const TYPE: &'static str = "sensor_msgs/Image";

    /// Decodes a serialised `sensor_msgs/Image`.
    pub fn decode(bytes: &[u8]) -> Result<Image, MessageError> {
        let mut r = Reader::new(bytes, Self::TYPE);
        Ok(Image {
            header: r.header()?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            encoding: r.string("encoding")?,
            is_bigendian: r.u8("is_bigendian")? != 0,
            step: r.u32("step")?,
            data: r.byte_array("data")?,
        })
    }

    /// The pixels of a 16-bit depth image (`mono16` or `16UC1`) in row-major order, honouring
    /// the row stride `step` and the byte order `is_bigendian`.
    pub fn depth_u16(&self) -> Result<Vec<u16>, MessageError> {
        if self.encoding != "mono16" && self.encoding != "16UC1" {
            return Err(MessageError::UnsupportedEncoding(self.encoding.clone()));
        }
        let (w, h, step) = (
            u64::from(self.width),
            u64::from(self.height),
            u64::from(self.step),
        );
        if step < 2 * w {
            return Err(MessageError::BadImage(format!(
                "step {step} is shorter than a row of {w} 16-bit pixels"
            )));
        }
        // The last row needs only its pixels, not the full stride.
        let needed = if h == 0 { 0 } else { step * (h - 1) + 2 * w };
        if (self.data.len() as u64) < needed {
            return Err(MessageError::BadImage(format!(
                "{w}x{h} at step {step} needs {needed} data bytes, has {}",
                self.data.len()
            )));
        }
        // No pixels, however many rows it claims: with step 0 nothing bounds the row count, and
        // walking 4 billion empty rows took seconds (found writing the fuzz target in `fuzz/`).
        if w == 0 {
            return Ok(Vec::new());
        }
        let mut out = Vec::with_capacity((w * h) as usize);
        for row in 0..h as usize {
            let start = row * step as usize;
            let row_bytes = &self.data[start..start + 2 * w as usize];
            out.extend(row_bytes.chunks_exact(2).map(|b| {
                if self.is_bigendian {
                    u16::from_be_bytes([b[0], b[1]])
                } else {
                    u16::from_le_bytes([b[0], b[1]])
                }
            }));
        }
        Ok(out)
    }
}

impl CameraInfo {
    const TYPE: &'static str = "sensor_msgs/CameraInfo";

    /// Decodes a serialised `sensor_msgs/CameraInfo`.
    pub fn decode(bytes: &[u8]) -> Result<CameraInfo, MessageError> {
        let mut r = Reader::new(bytes, Self::TYPE);
        Ok(CameraInfo {
            header: r.header()?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            distortion_model: r.string("distortion_model")?,
            d: r.f64_array("D")?,
            k: r.f64_fixed("K")?,
            r: r.f64_fixed("R")?,
            p: r.f64_fixed("P")?,
            binning_x: r.u32("binning_x")?,
            binning_y: r.u32("binning_y")?,
            roi: [
                r.u32("roi.x_offset")?,
                r.u32("roi.y_offset")?,
                r.u32("roi.height")?,
                r.u32("roi.width")?,
            ],
            roi_do_rectify: r.u8("roi.do_rectify")? != 0,
        })
    }

    /// The pinhole intrinsics from `K` (fx = K[0], cx = K[2], fy = K[4], cy = K[5]) and the
    /// image size.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics {
            width: self.width,
            height: self.height,
            fx: self.k[0] as f32,
            fy: self.k[4] as f32,
            cx: self.k[2] as f32,
            cy: self.k[5] as f32,
        }
    }
}

/// Decodes a `std_msgs/Float32` (4 little-endian bytes).
pub fn decode_float32(bytes: &[u8]) -> Result<f32, MessageError> {
    let mut r = Reader::new(bytes, "std_msgs/Float32");
    Ok(f32::from_le_bytes(r.take_fixed("data")?))
}

/// A bounds-checked little-endian cursor over one message.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    msg_type: &'static str,
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8], msg_type: &'static str) -> Self {
        Reader {
            bytes,
            pos: 0,
            msg_type,
        }
    }

    fn take(&mut self, len: u64, field: &'static str) -> Result<&'a [u8], MessageError> {
        let available = self.bytes.len() - self.pos;
        if len > available as u64 {
            return Err(MessageError::Truncated {
                msg_type: self.msg_type,
                field,
                offset: self.pos,
                needed: len,
                available,
            });
        }
        let out = &self.bytes[self.pos..self.pos + len as usize];
        self.pos += len as usize;
        Ok(out)
    }

    fn take_fixed<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], MessageError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N as u64, field)?);
        Ok(out)
    }

    fn u8(&mut self, field: &'static str) -> Result<u8, MessageError> {
        Ok(self.take_fixed::<1>(field)?[0])
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, MessageError> {
        Ok(u32::from_le_bytes(self.take_fixed(field)?))
    }

    fn f64(&mut self, field: &'static str) -> Result<f64, MessageError> {
        Ok(f64::from_le_bytes(self.take_fixed(field)?))
    }

    /// A length-prefixed `uint8[]`; the length is checked against the bytes left before the
    /// copy, so a hostile length cannot allocate.
    fn byte_array(&mut self, field: &'static str) -> Result<Vec<u8>, MessageError> {
        let len = self.u32(field)?;
        Ok(self.take(u64::from(len), field)?.to_vec())
    }

    fn string(&mut self, field: &'static str) -> Result<String, MessageError> {
        let len = self.u32(field)?;
        let bytes = self.take(u64::from(len), field)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| MessageError::NotUtf8 {
            msg_type: self.msg_type,
            field,
        })
    }

    fn f64_array(&mut self, field: &'static str) -> Result<Vec<f64>, MessageError> {
        let len = self.u32(field)?;
        let bytes = self.take(u64::from(len) * 8, field)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
            .collect())
    }

    fn f64_fixed<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], MessageError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(field)?;
        }
        Ok(out)
    }

    fn header(&mut self) -> Result<RosHeader, MessageError> {
        Ok(RosHeader {
            seq: self.u32("header.seq")?,
            stamp: Time {
                sec: self.u32("header.stamp.sec")?,
                nsec: self.u32("header.stamp.nsec")?,
            },
            frame_id: self.string("header.frame_id")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ros_header(out: &mut Vec<u8>) {
        out.extend(9u32.to_le_bytes());
        out.extend(100u32.to_le_bytes());
        out.extend(5u32.to_le_bytes());
        out.extend(3u32.to_le_bytes());
        out.extend(b"cam");
    }

    fn image_bytes(w: u32, h: u32, enc: &str, big: bool, step: u32, data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        ros_header(&mut out);
        out.extend(h.to_le_bytes());
        out.extend(w.to_le_bytes());
        out.extend((enc.len() as u32).to_le_bytes());
        out.extend(enc.as_bytes());
        out.push(big as u8);
        out.extend(step.to_le_bytes());
        out.extend((data.len() as u32).to_le_bytes());
        out.extend(data);
        out
    }

    #[test]
    fn depth_honours_row_stride_padding() {
        // 2x2 mono16 with 2 padding bytes per row (step 6).
        let data = [1, 0, 2, 0, 0xee, 0xee, 3, 0, 4, 1, 0xee, 0xee];
        let img = Image::decode(&image_bytes(2, 2, "mono16", false, 6, &data)).unwrap();
        assert_eq!(img.header.frame_id, "cam");
        assert_eq!(img.header.stamp, Time { sec: 100, nsec: 5 });
        assert_eq!(img.depth_u16().unwrap(), vec![1, 2, 3, 0x0104]);
    }

    /// Without the zero-width shortcut this walks 4 billion empty rows (seconds per message).
    #[test]
    fn zero_width_depth_with_four_billion_rows_is_empty() {
        let img = Image::decode(&image_bytes(0, u32::MAX, "mono16", false, 0, &[])).unwrap();
        assert_eq!(img.depth_u16().unwrap(), Vec::<u16>::new());
    }

    #[test]
    fn depth_honours_big_endian_16uc1() {
        let img = Image::decode(&image_bytes(2, 1, "16UC1", true, 4, &[1, 2, 0, 5])).unwrap();
        assert_eq!(img.depth_u16().unwrap(), vec![0x0102, 5]);
    }

    #[test]
    fn depth_last_row_may_omit_padding() {
        let img =
            Image::decode(&image_bytes(1, 2, "mono16", false, 4, &[1, 0, 9, 9, 2, 0])).unwrap();
        assert_eq!(img.depth_u16().unwrap(), vec![1, 2]);
    }

    #[test]
    fn depth_rejects_other_encodings_and_short_data() {
        let rgb = Image::decode(&image_bytes(1, 1, "rgb8", false, 3, &[1, 2, 3])).unwrap();
        assert_eq!(
            rgb.depth_u16(),
            Err(MessageError::UnsupportedEncoding("rgb8".into()))
        );
        let short = Image::decode(&image_bytes(2, 2, "mono16", false, 4, &[0; 6])).unwrap();
        assert!(matches!(short.depth_u16(), Err(MessageError::BadImage(_))));
        let narrow = Image::decode(&image_bytes(2, 1, "mono16", false, 3, &[0; 6])).unwrap();
        assert!(matches!(narrow.depth_u16(), Err(MessageError::BadImage(_))));
    }

    #[test]
    fn image_with_hostile_data_length_is_truncated_error() {
        let mut bytes = image_bytes(1, 1, "mono16", false, 2, &[0, 0]);
        let n = bytes.len();
        bytes[n - 6..n - 2].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            Image::decode(&bytes),
            Err(MessageError::Truncated { field: "data", .. })
        ));
    }

    #[test]
    fn camera_info_k_gives_intrinsics() {
        let mut out = Vec::new();
        ros_header(&mut out);
        out.extend(480u32.to_le_bytes());
        out.extend(640u32.to_le_bytes());
        out.extend(12u32.to_le_bytes());
        out.extend(b"plumb_bob   ");
        out.extend(5u32.to_le_bytes());
        for _ in 0..5 {
            out.extend(0.0f64.to_le_bytes());
        }
        let k: [f64; 9] = [500.0, 0.0, 320.5, 0.0, 501.0, 240.25, 0.0, 0.0, 1.0];
        for v in k.iter().chain(&[0.0; 9]).chain(&[0.0; 12]) {
            out.extend(v.to_le_bytes());
        }
        out.extend([0u8; 4 * 6 + 1]);
        let info = CameraInfo::decode(&out).unwrap();
        assert_eq!(info.d.len(), 5);
        let i = info.intrinsics();
        assert_eq!((i.width, i.height), (640, 480));
        assert_eq!((i.fx, i.fy, i.cx, i.cy), (500.0, 501.0, 320.5, 240.25));
        // One byte short: the last field is missing.
        assert!(CameraInfo::decode(&out[..out.len() - 1]).is_err());
    }

    #[test]
    fn float32_decodes_and_rejects_short_input() {
        assert_eq!(decode_float32(&0.001f32.to_le_bytes()).unwrap(), 0.001);
        assert!(decode_float32(&[0, 0]).is_err());
    }
}
