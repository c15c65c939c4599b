//! Recorded depth images to raw 16-bit depth units.
//!
//! Entry points:
//! - [`read_depth_image`]: a file, format chosen by extension (`.png`, `.tif`/`.tiff`, `.pgm`,
//!   `.z16`/`.raw`).
//! - [`decode_png`], [`decode_tiff`], [`decode_pgm`], [`decode_z16`]: the same over bytes, with
//!   the file's name only for the error messages.
//!
//! Each returns a [`DepthImage`] of raw sensor units; the caller knows the depth scale
//! (metres per unit), which no depth image format records. Only single-channel 16-bit images
//! are accepted: an 8-bit image is a colour or visualisation image, not depth, and is refused
//! rather than silently widened.
//!
//! PNG and TIFF go through the `png` and `tiff` crates. PGM is parsed here: the binary
//! Netpbm header is a magic, three numbers and comments, about ten lines of code, not worth a
//! dependency. Raw Z16 (RealSense) has no header at all; its layout is given by [`Z16Layout`].

use std::path::Path;

/// A decoded depth image: `depth[v * width + u]` in the sensor's raw units (0 = no reading).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthImage {
    pub width: u32,
    pub height: u32,
    pub depth: Vec<u16>,
}

impl DepthImage {
    /// How many pixels have a reading (a non-zero value).
    pub fn valid_pixels(&self) -> usize {
        self.depth.iter().filter(|&&d| d != 0).count()
    }

    /// The smallest and largest non-zero value, or `None` when no pixel has a reading.
    pub fn valid_range(&self) -> Option<(u16, u16)> {
        self.depth
            .iter()
            .filter(|&&d| d != 0)
            .fold(None, |acc, &d| match acc {
                None => Some((d, d)),
                Some((lo, hi)) => Some((lo.min(d), hi.max(d))),
            })
    }
}

/// The layout of a headerless little-endian Z16 buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Z16Layout {
    pub width: u32,
    pub height: u32,
    /// Bytes from the start of one row to the next; `None` means packed (`2 * width`).
    pub row_stride_bytes: Option<usize>,
}

impl Z16Layout {
    /// A packed layout of `width` x `height`.
    pub fn packed(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            row_stride_bytes: None,
        }
    }

    /// Reads `WIDTHxHEIGHT` from a file name such as `frame0_640x480.z16` (the last
    /// `_`/`-`/`.`-separated token of the stem that has that shape), packed.
    pub fn from_file_name(path: &Path) -> Option<Self> {
        let stem = path.file_stem()?.to_str()?;
        stem.rsplit(['_', '-', '.']).find_map(|token| {
            let (w, h) = token.split_once(['x', 'X'])?;
            let (width, height) = (w.parse().ok()?, h.parse().ok()?);
            (width > 0 && height > 0).then(|| Self::packed(width, height))
        })
    }

    fn stride(&self) -> usize {
        self.row_stride_bytes.unwrap_or(2 * self.width as usize)
    }
}

/// Why a depth image could not be decoded. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    #[error("{name}: cannot read: {error}")]
    Io { name: String, error: std::io::Error },
    #[error("{name}: not a readable PNG: {error}")]
    Png {
        name: String,
        error: png::DecodingError,
    },
    #[error("{name}: not a readable TIFF: {error}")]
    Tiff {
        name: String,
        error: tiff::TiffError,
    },
    /// A valid image, but not one channel of 16 bits.
    #[error(
        "{name}: is {found}, not a 16-bit single-channel depth image \
         (is this the colour image of the pair?)"
    )]
    NotDepth16 { name: String, found: String },
    /// The contents do not match what the header or the configured layout says.
    #[error("{name}: {reason}")]
    Malformed { name: String, reason: String },
    /// A Z16 file without a configured or file-name layout.
    #[error(
        "{name}: a raw Z16 file has no header: give its width and height \
         (or name it like frame_640x480.z16)"
    )]
    NoZ16Layout { name: String },
    #[error("{name}: unknown depth image extension; depth images can be .png, .tif, .tiff, .pgm, .z16 or .raw")]
    UnsupportedExtension { name: String },
}

fn malformed(name: &str, reason: impl Into<String>) -> DecodeError {
    DecodeError::Malformed {
        name: name.to_owned(),
        reason: reason.into(),
    }
}

/// Decodes a 16-bit grayscale PNG (TUM RGB-D, RealSense exports). PNG stores samples
/// big-endian; the result is in native `u16`.
pub fn decode_png(bytes: &[u8], name: &str) -> Result<DepthImage, DecodeError> {
    let png_error = |error| DecodeError::Png {
        name: name.to_owned(),
        error,
    };
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(png_error)?;
    check_pixels(name, reader.info().width, reader.info().height)?;
    let (color, depth) = reader.output_color_type();
    if color != png::ColorType::Grayscale || depth != png::BitDepth::Sixteen {
        return Err(DecodeError::NotDepth16 {
            name: name.to_owned(),
            found: format!("a PNG of {color:?} with {} bits", depth as u8),
        });
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| malformed(name, "PNG dimensions too large for memory"))?;
    let mut buf = vec![0u8; size];
    let info = reader.next_frame(&mut buf).map_err(png_error)?;
    let depth = buf
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect();
    Ok(DepthImage {
        width: info.width,
        height: info.height,
        depth,
    })
}

/// Decodes a 16-bit grayscale TIFF (PCL's grabber frames are PackBits-compressed; LZW and
/// Deflate are also read).
pub fn decode_tiff(bytes: &[u8], name: &str) -> Result<DepthImage, DecodeError> {
    let tiff_error = |error| DecodeError::Tiff {
        name: name.to_owned(),
        error,
    };
    let mut decoder =
        tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).map_err(tiff_error)?;
    let color = decoder.colortype().map_err(tiff_error)?;
    if color != tiff::ColorType::Gray(16) {
        return Err(DecodeError::NotDepth16 {
            name: name.to_owned(),
            found: format!("a TIFF of {color:?}"),
        });
    }
    let (width, height) = decoder.dimensions().map_err(tiff_error)?;
    check_pixels(name, width, height)?;
    let depth = match decoder.read_image().map_err(tiff_error)? {
        tiff::decoder::DecodingResult::U16(depth) => depth,
        _ => {
            return Err(DecodeError::NotDepth16 {
                name: name.to_owned(),
                found: "a TIFF whose samples are not unsigned 16-bit".to_owned(),
            })
        }
    };
    if depth.len() != width as usize * height as usize {
        return Err(malformed(
            name,
            format!(
                "TIFF of {width}x{height} decoded to {} samples",
                depth.len()
            ),
        ));
    }
    Ok(DepthImage {
        width,
        height,
        depth,
    })
}

/// Decodes a binary PGM (`P5`) with maxval above 255, whose samples are 16-bit big-endian
/// per the Netpbm spec (slambook's Kinect frames). Bytes after the first image are ignored
/// (Netpbm allows several images in one file).
pub fn decode_pgm(bytes: &[u8], name: &str) -> Result<DepthImage, DecodeError> {
    let mut header = PgmHeader { bytes, at: 0 };
    if bytes.get(..2) != Some(b"P5") {
        return Err(malformed(
            name,
            "not a binary PGM: it does not start with P5",
        ));
    }
    header.at = 2;
    let mut field = |what| {
        header
            .number()
            .ok_or_else(|| malformed(name, format!("PGM header: no valid {what}")))
    };
    let (width, height, maxval) = (field("width")?, field("height")?, field("maxval")?);
    // Exactly one whitespace byte separates the header from the samples.
    let data_start = header.at + 1;
    if maxval <= 255 {
        return Err(DecodeError::NotDepth16 {
            name: name.to_owned(),
            found: format!("an 8-bit PGM (maxval {maxval})"),
        });
    }
    if width == 0 || height == 0 || maxval > 65535 {
        return Err(malformed(
            name,
            format!("PGM header {width}x{height} maxval {maxval} is out of range"),
        ));
    }
    let expected = (width as usize)
        .checked_mul(height as usize)
        .and_then(|n| n.checked_mul(2))
        .ok_or_else(|| malformed(name, "PGM dimensions too large"))?;
    let data = bytes
        .get(data_start..)
        .and_then(|rest| rest.get(..expected))
        .ok_or_else(|| {
            malformed(
                name,
                format!(
                    "truncated: a {width}x{height} 16-bit PGM needs {expected} bytes of samples, the file has {}",
                    bytes.len().saturating_sub(data_start)
                ),
            )
        })?;
    Ok(DepthImage {
        width,
        height,
        depth: data
            .chunks_exact(2)
            .map(|b| u16::from_be_bytes([b[0], b[1]]))
            .collect(),
    })
}

/// The cursor over a PGM header: whitespace-separated decimal numbers, `#` comments to the end
/// of the line.
struct PgmHeader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl PgmHeader<'_> {
    fn number(&mut self) -> Option<u32> {
        loop {
            match self.bytes.get(self.at)? {
                b'#' => {
                    while *self.bytes.get(self.at)? != b'\n' {
                        self.at += 1;
                    }
                }
                c if c.is_ascii_whitespace() => self.at += 1,
                _ => break,
            }
        }
        let start = self.at;
        while self.bytes.get(self.at).is_some_and(u8::is_ascii_digit) {
            self.at += 1;
        }
        std::str::from_utf8(&self.bytes[start..self.at])
            .ok()?
            .parse()
            .ok()
    }
}

/// Decodes a raw little-endian Z16 buffer (RealSense's native depth format) of the given
/// layout. With a row stride, the bytes past `2 * width` in each row are padding and skipped;
/// the last row needs no padding. A buffer of any other size than the layout implies is an
/// error, as the layout is then certainly wrong.
pub fn decode_z16(bytes: &[u8], name: &str, layout: Z16Layout) -> Result<DepthImage, DecodeError> {
    let Z16Layout { width, height, .. } = layout;
    let (row_bytes, stride) = (2 * width as usize, layout.stride());
    if width == 0 || height == 0 || stride < row_bytes {
        return Err(malformed(
            name,
            format!(
                "Z16 layout {width}x{height} with a row stride of {stride} bytes is impossible"
            ),
        ));
    }
    // The layout comes from the spec or a file name: a stride or height whose product
    // overflows (row_stride_bytes=576460752303424768 once panicked here) fits no file.
    let Some(padded) = stride.checked_mul(height as usize) else {
        return Err(malformed(
            name,
            format!(
                "{} bytes, but a {width}x{height} Z16 image with a row stride of {stride} bytes \
                 would be larger than memory: check the width, height and stride",
                bytes.len()
            ),
        ));
    };
    let tight = padded - (stride - row_bytes);
    if bytes.len() != padded && bytes.len() != tight {
        return Err(malformed(
            name,
            format!(
                "{} bytes, but a {width}x{height} Z16 image with a row stride of {stride} bytes has {padded}: \
                 check the width, height and stride",
                bytes.len()
            ),
        ));
    }
    let mut depth = Vec::with_capacity(width as usize * height as usize);
    for row in 0..height as usize {
        let start = row * stride;
        depth.extend(
            bytes[start..start + row_bytes]
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]])),
        );
    }
    Ok(DepthImage {
        width,
        height,
        depth,
    })
}

/// The largest depth image file read: 256 MiB (a 4096x4096 16-bit frame is 32 MiB).
pub const MAX_DEPTH_FILE_BYTES: u64 = 256 << 20;

/// The most pixels a depth image may have: 4096x4096 (depth cameras give 2 million at most; a
/// 20000x20000 PNG, a few kB on disk, once took 1.5 GB to decode).
pub const MAX_DEPTH_PIXELS: u64 = 4096 * 4096;

/// Refuses an image whose header promises more than [`MAX_DEPTH_PIXELS`], before anything is
/// allocated for it.
fn check_pixels(name: &str, width: u32, height: u32) -> Result<(), DecodeError> {
    if u64::from(width) * u64::from(height) > MAX_DEPTH_PIXELS {
        return Err(malformed(
            name,
            format!(
                "{width}x{height} pixels, more than the {MAX_DEPTH_PIXELS} (4096x4096) a depth \
                 image may have"
            ),
        ));
    }
    Ok(())
}

/// Whether a path has the extension of a depth image format [`read_depth_image`] reads.
pub fn is_depth_image_path(path: &Path) -> bool {
    matches!(
        extension(path).as_str(),
        "png" | "tif" | "tiff" | "pgm" | "z16" | "raw"
    )
}

/// Reads a depth image, choosing the format by extension. `z16` is the layout of `.z16` and
/// `.raw` files; when `None`, it is read from the file name (`..._640x480.z16`).
pub fn read_depth_image(path: &Path, z16: Option<Z16Layout>) -> Result<DepthImage, DecodeError> {
    let name = path.display().to_string();
    let read = || {
        tacmesh_source::read_regular_file(path, MAX_DEPTH_FILE_BYTES).map_err(|error| {
            DecodeError::Io {
                name: name.clone(),
                error,
            }
        })
    };
    match extension(path).as_str() {
        "png" => decode_png(&read()?, &name),
        "tif" | "tiff" => decode_tiff(&read()?, &name),
        "pgm" => decode_pgm(&read()?, &name),
        "z16" | "raw" => {
            let layout = z16
                .or_else(|| Z16Layout::from_file_name(path))
                .ok_or_else(|| DecodeError::NoZ16Layout { name: name.clone() })?;
            decode_z16(&read()?, &name, layout)
        }
        _ => Err(DecodeError::UnsupportedExtension { name }),
    }
}

pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pgm_header_skips_comments_and_reads_big_endian_samples() {
        let mut bytes = b"P5\n# made by hand\n2 1\n65535\n".to_vec();
        bytes.extend([0x01, 0x02, 0xff, 0x00]);
        let image = decode_pgm(&bytes, "t.pgm").expect("valid PGM");
        assert_eq!((image.width, image.height), (2, 1));
        assert_eq!(image.depth, vec![0x0102, 0xff00]);
    }

    #[test]
    fn pgm_refuses_eight_bit() {
        let bytes = b"P5 1 1 255\n\x07";
        let err = decode_pgm(bytes, "eight.pgm").unwrap_err();
        assert!(matches!(err, DecodeError::NotDepth16 { .. }), "{err}");
        assert!(err.to_string().contains("eight.pgm"), "{err}");
    }

    #[test]
    fn pgm_refuses_ascii_magic() {
        let err = decode_pgm(b"P2 1 1 65535\n7", "ascii.pgm").unwrap_err();
        assert!(err.to_string().contains("P5"), "{err}");
    }

    #[test]
    fn z16_layout_from_file_name() {
        assert_eq!(
            Z16Layout::from_file_name(Path::new("d/frame0_640x480.z16")),
            Some(Z16Layout::packed(640, 480))
        );
        assert_eq!(Z16Layout::from_file_name(Path::new("frame0.z16")), None);
    }

    #[test]
    fn z16_skips_row_padding() {
        // 2x2 with a stride of 6 bytes: 2 bytes of padding per row, last row's optional.
        let bytes = [1, 0, 2, 0, 0xee, 0xee, 3, 0, 4, 1];
        let layout = Z16Layout {
            row_stride_bytes: Some(6),
            ..Z16Layout::packed(2, 2)
        };
        let image = decode_z16(&bytes, "t.z16", layout).expect("padded Z16");
        assert_eq!(image.depth, vec![1, 2, 3, 0x0104]);
    }

    /// A PNG whose header promises 20000x20000 pixels (a few bytes on disk) is refused before
    /// its 800 MB buffer is allocated.
    #[test]
    fn png_larger_than_the_pixel_cap_is_refused_before_decoding() {
        fn crc32(bytes: &[u8]) -> u32 {
            let mut crc = !0u32;
            for &b in bytes {
                crc ^= u32::from(b);
                for _ in 0..8 {
                    crc = (crc >> 1) ^ (0xedb8_8320 & (crc & 1).wrapping_neg());
                }
            }
            !crc
        }
        fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
            let mut out = (data.len() as u32).to_be_bytes().to_vec();
            let body: Vec<u8> = kind.iter().chain(data).copied().collect();
            out.extend(&body);
            out.extend(crc32(&body).to_be_bytes());
            out
        }
        let mut ihdr = 20_000u32.to_be_bytes().to_vec();
        ihdr.extend(20_000u32.to_be_bytes());
        ihdr.extend([16, 0, 0, 0, 0]); // 16-bit grey, deflate, no filter method, no interlace
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend(chunk(b"IHDR", &ihdr));
        png.extend(chunk(b"IDAT", &[]));
        png.extend(chunk(b"IEND", &[]));
        let err = decode_png(&png, "huge.png").unwrap_err().to_string();
        assert!(
            err.contains("20000x20000") && err.contains("4096x4096"),
            "{err}"
        );
    }

    /// A stride times height that overflows `usize` is a malformed layout, not a panic.
    #[test]
    fn z16_rejects_a_layout_larger_than_memory() {
        for (width, height, stride) in [
            (640, 480, 576_460_752_303_424_768usize),
            (u32::MAX, u32::MAX, usize::MAX),
            (1, u32::MAX, usize::MAX / 2),
        ] {
            let layout = Z16Layout {
                row_stride_bytes: Some(stride),
                ..Z16Layout::packed(width, height)
            };
            let err = decode_z16(&[0; 64], "t.z16", layout).unwrap_err();
            assert!(matches!(err, DecodeError::Malformed { .. }), "{err}");
        }
        // Packed, the stride is computed: 2 × u32::MAX fits a 64-bit usize, × height does not.
        let err = decode_z16(&[0; 64], "t.z16", Z16Layout::packed(u32::MAX, u32::MAX)).unwrap_err();
        assert!(matches!(err, DecodeError::Malformed { .. }), "{err}");
    }

    #[test]
    fn z16_rejects_stride_shorter_than_a_row() {
        let layout = Z16Layout {
            row_stride_bytes: Some(2),
            ..Z16Layout::packed(2, 2)
        };
        assert!(decode_z16(&[0; 8], "t.z16", layout).is_err());
    }
}
