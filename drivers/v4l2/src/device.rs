//! The capture backend: [`V4l2Source`], a [`DepthSource`] on a `/dev/videoN` node.
//!
//! Opening runs these stages in order, each with its own error: the node exists
//! ([`SourceError::DeviceMissing`]) → it opens ([`V4l2Error::Open`]) → it is a V4L2 device
//! (`VIDIOC_QUERYCAP`, [`V4l2Error::NotVideoDevice`]) that streams captures
//! ([`V4l2Error::NotCapture`]) → it offers a depth format (`VIDIOC_ENUM_FMT`,
//! [`V4l2Error::NoDepthFormat`] listing what it does offer) → the driver accepts the size
//! (`VIDIOC_S_FMT`, [`V4l2Error::FormatRejected`]) → frame rate (`VIDIOC_S_PARM`, best effort)
//! → memory-mapped buffers (`VIDIOC_REQBUFS`). Streaming starts with the first frame read.
//!
//! Reading: a frame not dequeued within [`V4l2Config::read_timeout_ms`], or any dequeue
//! failure, is [`SourceError::Disconnected`]; a frame the driver flags as corrupt or that does
//! not decode is [`SourceError::Malformed`].

use std::io;
use std::time::Duration;

use tacmesh_source::{monotonic_now, DepthSource, Observation, SourceError};
use tracing::{info, trace, warn};
use v4l::buffer::{Flags as BufferFlags, Type};
use v4l::capability::Flags as CapabilityFlags;
use v4l::io::mmap::Stream;
use v4l::io::traits::CaptureStream;
use v4l::video::capture::Parameters;
use v4l::video::Capture;
use v4l::{Device, Format, FourCC};

use crate::decode::{DepthDecoder, PixelFormat};
use crate::{V4l2Config, V4l2Error};

/// `errno` of a device that went away (unplugged, USB reset).
const ENODEV: i32 = 19;

/// What the driver agreed to stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Negotiated {
    pub format: PixelFormat,
    pub width: u32,
    pub height: u32,
    /// Row stride in bytes, as the driver reported it.
    pub bytes_per_line: u32,
    /// Frames per second the driver reports after `VIDIOC_S_PARM`, if it reports one.
    pub fps: Option<f32>,
}

/// A V4L2 depth camera streaming through memory-mapped buffers.
pub struct V4l2Source {
    name: String,
    device: String,
    negotiated: Negotiated,
    decoder: DepthDecoder,
    read_timeout_ms: u64,
    // `Stream` keeps its own handle on the device, so the `Device` need not outlive it here.
    // Known limits of `v4l` 0.14 that this crate cannot reach without `unsafe`: dropping a
    // stream whose VIDIOC_STREAMOFF fails with anything but ENODEV panics inside `v4l`, and
    // `query_caps` unwraps the driver's card name as UTF-8.
    stream: Stream<'static>,
}

impl std::fmt::Debug for V4l2Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4l2Source")
            .field("device", &self.device)
            .field("negotiated", &self.negotiated)
            .finish_non_exhaustive()
    }
}

/// The node exists, or [`SourceError::DeviceMissing`] naming it.
fn check_present(device: &str) -> Result<(), V4l2Error> {
    match std::fs::metadata(device) {
        Ok(_) => Ok(()),
        Err(error) if error.kind() == io::ErrorKind::NotFound => Err(SourceError::DeviceMissing {
            device: device.to_string(),
            hint: "is the camera plugged in? (`v4l2-ctl --list-devices` lists the video \
                   nodes; a RealSense camera's depth stream is usually the first of its group)"
                .to_string(),
        }
        .into()),
        Err(source) => Err(V4l2Error::Open {
            device: device.to_string(),
            hint: "",
            source,
        }),
    }
}

fn open_device(device: &str) -> Result<Device, V4l2Error> {
    Device::with_path(device).map_err(|source| V4l2Error::Open {
        device: device.to_string(),
        hint: match source.kind() {
            io::ErrorKind::PermissionDenied => " (is the user in group `video`?)",
            _ => "",
        },
        source,
    })
}

/// The device is a V4L2 node that can stream video captures.
fn check_capture(dev: &Device, device: &str) -> Result<(), V4l2Error> {
    let caps = dev
        .query_caps()
        .map_err(|source| V4l2Error::NotVideoDevice {
            device: device.to_string(),
            source,
        })?;
    let needed = CapabilityFlags::VIDEO_CAPTURE | CapabilityFlags::STREAMING;
    if !caps.capabilities.contains(needed) {
        return Err(V4l2Error::NotCapture {
            device: device.to_string(),
            card: caps.card,
            capabilities: caps.capabilities.to_string(),
        });
    }
    Ok(())
}

/// The first configured format the device offers, or [`V4l2Error::NoDepthFormat`].
fn choose_format(
    dev: &Device,
    device: &str,
    wanted: &[PixelFormat],
) -> Result<PixelFormat, V4l2Error> {
    let offered = dev.enum_formats().map_err(|source| V4l2Error::Device {
        device: device.to_string(),
        what: "listing formats (VIDIOC_ENUM_FMT)",
        source,
    })?;
    wanted
        .iter()
        .copied()
        .find(|w| offered.iter().any(|o| o.fourcc.repr == w.fourcc()))
        .ok_or_else(|| V4l2Error::NoDepthFormat {
            device: device.to_string(),
            wanted: wanted.iter().map(|w| w.to_string()).collect(),
            offered: offered
                .iter()
                .map(|o| format!("{} ({})", o.fourcc, o.description))
                .collect(),
        })
}

/// Sets format and size; the driver must grant both exactly.
fn set_format(
    dev: &Device,
    device: &str,
    format: PixelFormat,
    width: u32,
    height: u32,
) -> Result<Format, V4l2Error> {
    let requested = Format::new(width, height, FourCC::new(&format.fourcc()));
    let granted = dev
        .set_format(&requested)
        .map_err(|source| V4l2Error::Device {
            device: device.to_string(),
            what: "setting the format (VIDIOC_S_FMT; is another program streaming from it?)",
            source,
        })?;
    if (granted.width, granted.height, granted.fourcc) != (width, height, requested.fourcc) {
        return Err(V4l2Error::FormatRejected {
            device: device.to_string(),
            requested: format!("{format} {width}x{height}"),
            granted: format!("{} {}x{}", granted.fourcc, granted.width, granted.height),
        });
    }
    Ok(granted)
}

/// Requests `fps`; drivers without `VIDIOC_S_PARM` keep their rate, which is worth a warning
/// but not a failure. Returns the rate the driver reports.
fn set_fps(dev: &Device, device: &str, fps: u32) -> Option<f32> {
    let params = match dev.set_params(&Parameters::with_fps(fps)) {
        Ok(params) => params,
        Err(error) => {
            warn!(device, fps, %error, "could not set the frame rate; keeping the driver's");
            dev.params().ok()?
        }
    };
    let interval = params.interval;
    (interval.numerator > 0).then(|| interval.denominator as f32 / interval.numerator as f32)
}

fn disconnected(device: &str, error: &io::Error, timeout_ms: u64) -> SourceError {
    let reason = if error.kind() == io::ErrorKind::TimedOut {
        format!(
            "no frame within {timeout_ms} ms: is the camera still plugged in, and does its USB \
             port have the bandwidth for this mode?"
        )
    } else if error.raw_os_error() == Some(ENODEV) {
        "the device went away (unplugged or reset)".to_string()
    } else {
        format!("reading a frame failed: {error}")
    };
    SourceError::Disconnected {
        device: device.to_string(),
        reason,
    }
}

impl V4l2Source {
    /// Opens `config.device`, negotiates the first of `config.formats` it offers at the
    /// intrinsics' resolution, requests `config.fps` and maps `config.buffer_count` buffers.
    /// Streaming starts on the first [`DepthSource::next_observation`].
    pub fn open(config: &V4l2Config) -> Result<Self, V4l2Error> {
        let device = config.device.as_str();
        let (width, height) = (config.intrinsics.width, config.intrinsics.height);
        let wanted = config.formats_to_try();
        // Check the configuration before touching the device: scale, and a non-empty image.
        DepthDecoder::new(
            wanted[0],
            width.saturating_mul(2),
            config.intrinsics,
            config.depth_scale_m,
            config.world_from_sensor,
        )?;

        check_present(device)?;
        let dev = open_device(device)?;
        check_capture(&dev, device)?;
        let format = choose_format(&dev, device, &wanted)?;
        let granted = set_format(&dev, device, format, width, height)?;
        let fps = set_fps(&dev, device, config.fps);
        // A stride of 0 is how some drivers say "packed".
        let bytes_per_line = match granted.stride {
            0 => width.saturating_mul(2),
            stride => stride,
        };
        let decoder = DepthDecoder::new(
            format,
            bytes_per_line,
            config.intrinsics,
            config.depth_scale_m,
            config.world_from_sensor,
        )?;

        let mut stream = Stream::with_buffers(&dev, Type::VideoCapture, config.buffer_count.max(1))
            .map_err(|source| V4l2Error::Device {
                device: device.to_string(),
                what: "mapping capture buffers (VIDIOC_REQBUFS)",
                source,
            })?;
        // `set_timeout` takes whole milliseconds as an `i32`.
        let read_timeout_ms = config.read_timeout_ms.clamp(1, i32::MAX as u64);
        stream.set_timeout(Duration::from_millis(read_timeout_ms));

        let negotiated = Negotiated {
            format,
            width,
            height,
            bytes_per_line,
            fps,
        };
        info!(device, ?negotiated, "V4L2 depth stream ready");
        Ok(Self {
            name: format!("v4l2:{device}"),
            device: device.to_string(),
            negotiated,
            decoder,
            read_timeout_ms,
            stream,
        })
    }

    /// What the driver agreed to stream.
    pub fn negotiated(&self) -> &Negotiated {
        &self.negotiated
    }
}

impl DepthSource for V4l2Source {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let (bytes, meta) = CaptureStream::next(&mut self.stream)
            .map_err(|error| disconnected(&self.device, &error, self.read_timeout_ms))?;
        let capture_time = monotonic_now();
        if meta.flags.contains(BufferFlags::ERROR) {
            return Err(SourceError::Malformed {
                device: self.device.clone(),
                reason: format!("the driver flagged frame {} as corrupt", meta.sequence),
            });
        }
        // Only `bytesused` bytes hold the frame; mmap buffers are rounded up to whole pages.
        let used = match meta.bytesused as usize {
            0 => bytes.len(),
            used => used.min(bytes.len()),
        };
        trace!(device = %self.device, sequence = meta.sequence, used, "V4L2 frame");
        let frame = self
            .decoder
            .decode(&bytes[..used], capture_time)
            .map_err(|error| SourceError::Malformed {
                device: self.device.clone(),
                reason: error.to_string(),
            })?;
        Ok(Observation::Depth(frame))
    }
}
