use tacmesh_source::SourceError;

/// Why a V4L2 depth frame could not be decoded or a V4L2 device could not be opened.
///
/// The decoding variants name no device (the decoder is pure); the device variants all name the
/// device node as it was configured.
#[derive(Debug, thiserror::Error)]
pub enum V4l2Error {
    #[error("a {width}x{height} image has no pixels: configure a non-zero width and height")]
    EmptyImage { width: u32, height: u32 },
    #[error(
        "a {width}x{height} image of 16-bit pixels is too large to address ({bytes_per_line} \
         bytes per line)"
    )]
    TooLarge {
        width: u32,
        height: u32,
        bytes_per_line: u32,
    },
    #[error(
        "row stride of {bytes_per_line} bytes is less than 2 x width {width} = {needed}: the \
         stream is not 16 bits per pixel, or the driver reported a wrong bytesperline"
    )]
    StrideTooSmall {
        bytes_per_line: u32,
        width: u32,
        needed: u64,
    },
    #[error(
        "row stride of {bytes_per_line} bytes is odd, so rows do not start on a 16-bit pixel: \
         the stream is not a 16-bit format"
    )]
    OddStride { bytes_per_line: u32 },
    #[error(
        "frame buffer holds {got} bytes but a {width}x{height} 16-bit image with \
         {bytes_per_line} bytes per line needs {needed}: the frame was cut short or the \
         negotiated format is not the one configured"
    )]
    ShortBuffer {
        got: usize,
        needed: u64,
        width: u32,
        height: u32,
        bytes_per_line: u32,
    },
    #[error(
        "the intrinsics are for {intrinsics_width}x{intrinsics_height} but the image is \
         {width}x{height}: use the calibration of the streamed resolution"
    )]
    SizeMismatch {
        width: u32,
        height: u32,
        intrinsics_width: u32,
        intrinsics_height: u32,
    },
    #[error(
        "depth scale {depth_scale_m} m per unit is not a positive finite number (RealSense \
         cameras use 0.001)"
    )]
    BadDepthScale { depth_scale_m: f32 },
    /// The device node is missing ([`SourceError::DeviceMissing`]).
    #[error(transparent)]
    Source(#[from] SourceError),
    #[error("cannot open {device}: {source}{hint}")]
    Open {
        device: String,
        hint: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{device} is not a V4L2 device (VIDIOC_QUERYCAP failed: {source}): give the /dev/videoN \
         node of the camera's depth stream (`v4l2-ctl --list-devices` lists them)"
    )]
    NotVideoDevice {
        device: String,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{device} ({card}) cannot stream video captures (capabilities: {capabilities}): it is \
         probably the camera's metadata node; try the neighbouring /dev/videoN"
    )]
    NotCapture {
        device: String,
        card: String,
        capabilities: String,
    },
    #[error(
        "{device} offers no depth format (wanted one of {wanted:?}); it offers {offered:?}: it \
         is probably the colour or infrared node of the camera; try the neighbouring /dev/videoN"
    )]
    NoDepthFormat {
        device: String,
        wanted: Vec<String>,
        offered: Vec<String>,
    },
    #[error("{device}: {what} failed: {source}")]
    Device {
        device: String,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{device} would not stream {requested}; the driver chose {granted}: pick a resolution \
         the camera offers (`v4l2-ctl -d {device} --list-formats-ext`)"
    )]
    FormatRejected {
        device: String,
        requested: String,
        granted: String,
    },
}
