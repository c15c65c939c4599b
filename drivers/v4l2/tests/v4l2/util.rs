use std::path::PathBuf;

use tacmesh_source::Intrinsics;

/// `testdata/depth/realsense_d435/` (see `testdata/SOURCES.md`).
pub fn d435_dir() -> PathBuf {
    tacmesh_testdata::path("depth/realsense_d435")
}

pub const WIDTH: u32 = 640;
pub const HEIGHT: u32 = 480;

/// The D435 depth intrinsics from the recording's camera_info (SOURCES.md).
pub fn d435_intrinsics() -> Intrinsics {
    Intrinsics {
        width: WIDTH,
        height: HEIGHT,
        fx: 390.4315,
        fy: 390.4315,
        cx: 331.3879,
        cy: 242.1873,
    }
}

/// The raw Z16 payload of the recording's first depth frame: 640x480, tightly packed.
pub fn d435_z16() -> Vec<u8> {
    std::fs::read(d435_dir().join("frame0_640x480.z16")).unwrap()
}

/// The same frame as a 16-bit greyscale PNG, decoded independently of the crate under test.
pub fn d435_png_units() -> Vec<u16> {
    let file = std::fs::File::open(d435_dir().join("frame0_depth.png")).unwrap();
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().unwrap();
    assert_eq!(
        reader.output_color_type(),
        (png::ColorType::Grayscale, png::BitDepth::Sixteen)
    );
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (WIDTH, HEIGHT));
    // PNG stores 16-bit samples big-endian.
    buf[..info.buffer_size()]
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect()
}

/// `tight` (rows of `2 * width` bytes) re-laid with `bytes_per_line`, padding filled with 0xA5
/// and the last row's padding left off, as a driver may hand it over.
pub fn with_stride(tight: &[u8], width: u32, bytes_per_line: u32) -> Vec<u8> {
    let (row, stride) = (2 * width as usize, bytes_per_line as usize);
    let rows: Vec<&[u8]> = tight.chunks_exact(row).collect();
    let mut out = Vec::with_capacity(stride * rows.len());
    for (i, r) in rows.iter().enumerate() {
        out.extend_from_slice(r);
        if i + 1 < rows.len() {
            out.resize(out.len() + stride - row, 0xA5);
        }
    }
    out
}
