//! [`OpenNi2Source`]: an OpenNI2 depth stream as a [`DepthSource`].

use std::path::Path;

use tacmesh_source::{monotonic_now, DepthFrame, DepthSource, Observation, SourceError};

use crate::ffi::{Context, DepthStream, Device, OniVideoMode};
use crate::intrinsics::{cropped, intrinsics_from_fov};
use crate::status::{open_error, read_error};
use crate::{depth_m_from_raw, DepthPixelFormat, OpenNi2Error, OpenNi2Options, VideoMode};

/// An OpenNI2 device or recording streaming depth.
///
/// Capture times are read on the host clock ([`monotonic_now`]) when a frame is read: the
/// device's own timestamp counts from an unknown epoch on the device.
#[derive(Debug)]
pub struct OpenNi2Source {
    name: String,
    stream: DepthStream,
    options: OpenNi2Options,
    fov_rad: (f32, f32),
    video_mode: VideoMode,
    /// For a recording, its length when OpenNI2 reports one.
    frames_in_recording: Option<u32>,
    frames_read: u32,
}

impl OpenNi2Source {
    /// Opens `uri` and starts its depth stream: `None` is the first device OpenNI2 finds, a
    /// string is a device URI (e.g. `"1d27/0601@3/2"`, or `"Dummy"` for OpenNI2's test
    /// driver) or a path to an `.oni` recording, which OpenNI2 opens as a device too.
    ///
    /// Every failure is [`SourceError::DeviceMissing`] naming the URI, with OpenNI2's extended
    /// error text. Recordings play once (no looping).
    pub fn open(uri: Option<&str>, options: OpenNi2Options) -> Result<Self, SourceError> {
        // The spec as typed first, so that it never reads as a device named "first device".
        let name = uri.map_or_else(
            || "openni2: (the first device found)".to_owned(),
            |uri| format!("openni2:{uri}"),
        );
        let recording = uri.is_some_and(is_recording);
        if let Some(path) = uri.filter(|u| is_recording(u) && !Path::new(u).is_file()) {
            return Err(SourceError::DeviceMissing {
                device: name,
                hint: format!("no recording at {path}: is the path right?"),
            });
        }
        let (stream, fov_rad, video_mode, frames) =
            start(uri, recording, &options).map_err(|e| open_error(&name, e))?;
        tracing::info!(
            "{name}: streaming {}×{} @ {} Hz {:?}, fov {:.3}×{:.3} rad{}",
            video_mode.width,
            video_mode.height,
            video_mode.fps,
            video_mode.pixel_format,
            fov_rad.0,
            fov_rad.1,
            frames.map_or(String::new(), |n| format!(", {n} recorded frames")),
        );
        Ok(Self {
            name,
            stream,
            options,
            fov_rad,
            video_mode,
            frames_in_recording: frames,
            frames_read: 0,
        })
    }

    /// The video mode the stream runs in (which may differ from the one asked for).
    pub fn video_mode(&self) -> VideoMode {
        self.video_mode
    }

    /// Horizontal and vertical field of view in radians (the device's, or the fallback).
    pub fn fov_rad(&self) -> (f32, f32) {
        self.fov_rad
    }

    fn read(&mut self) -> Result<DepthFrame, OpenNi2Error> {
        self.stream.wait_for_frame(self.options.frame_timeout_ms)?;
        let raw = self.stream.read_frame()?;
        let capture_time = monotonic_now();
        let format = DepthPixelFormat::from_code(raw.pixel_format)
            .ok_or(OpenNi2Error::UnsupportedPixelFormat(raw.pixel_format))?;
        let (hfov, vfov) = self.fov_rad;
        let full = intrinsics_from_fov(raw.full_width, raw.full_height, hfov, vfov)
            .ok_or_else(|| OpenNi2Error::NoFieldOfView(format!("{hfov} × {vfov} rad")))?;
        tracing::trace!(
            "{}: frame {} at device time {} µs",
            self.name,
            raw.frame_index,
            raw.device_timestamp_us
        );
        Ok(DepthFrame {
            intrinsics: cropped(full, raw.crop_origin, raw.width, raw.height),
            depth_m: depth_m_from_raw(format, &raw.units),
            world_from_sensor: self.options.world_from_sensor,
            capture_time,
        })
    }
}

impl DepthSource for OpenNi2Source {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        if self
            .frames_in_recording
            .is_some_and(|n| self.frames_read >= n)
        {
            return Err(SourceError::EndOfStream {
                device: self.name.clone(),
            });
        }
        let frame = self
            .read()
            .map_err(|e| read_error(&self.name, e, self.options.frame_timeout_ms))?;
        self.frames_read += 1;
        Ok(Observation::Depth(frame))
    }
}

/// Whether OpenNI2 will treat `uri` as a recording (its file driver claims `*.oni`).
fn is_recording(uri: &str) -> bool {
    Path::new(uri)
        .extension()
        .is_some_and(|ext| ext.eq_ignore_ascii_case("oni"))
}

type Started = (DepthStream, (f32, f32), VideoMode, Option<u32>);

/// Initialise → open → create the depth stream → choose its mode → start. On any error the
/// handles made so far drop in reverse order.
fn start(
    uri: Option<&str>,
    recording: bool,
    options: &OpenNi2Options,
) -> Result<Started, OpenNi2Error> {
    let device = Device::open(Context::acquire()?, uri)?;
    if recording {
        device.set_playback(false, options.playback_speed)?;
    }
    let mut stream = device.into_depth_stream()?;
    if !recording {
        choose_video_mode(&stream, options.video_mode);
    }
    let fov_rad = match (stream.fov_rad(), options.fallback_fov_rad) {
        (Ok(fov), _) if intrinsics_from_fov(1, 1, fov.0, fov.1).is_some() => fov,
        (reported, Some(fallback)) => {
            let reported = reported.map_or_else(|e| e.to_string(), |f| format!("{f:?} rad"));
            tracing::warn!(
                "no usable field of view from the device ({reported}); assuming {fallback:?} rad"
            );
            fallback
        }
        (Ok(fov), None) => return Err(OpenNi2Error::NoFieldOfView(format!("{fov:?} rad"))),
        (Err(e), None) => return Err(OpenNi2Error::NoFieldOfView(e.to_string())),
    };
    let frames = recording.then(|| stream.number_of_frames()).flatten();
    // Everything that can fail is asked before starting: a stream dropped right after
    // oniStreamStart races the start of some drivers' producer threads.
    let mode = stream.video_mode()?;
    let video_mode = VideoMode {
        width: u32::try_from(mode.resolution_x).unwrap_or(0),
        height: u32::try_from(mode.resolution_y).unwrap_or(0),
        fps: u32::try_from(mode.fps).unwrap_or(0),
        pixel_format: DepthPixelFormat::from_code(mode.pixel_format)
            .ok_or(OpenNi2Error::UnsupportedPixelFormat(mode.pixel_format))?,
    };
    stream.start()?;
    Ok((stream, fov_rad, video_mode, frames))
}

/// Sets `wanted` if the sensor lists it; otherwise keeps the current mode. Not fatal: some
/// drivers (the dummy device) list a mode but cannot set any.
fn choose_video_mode(stream: &DepthStream, wanted: VideoMode) {
    let wanted = OniVideoMode {
        pixel_format: wanted.pixel_format.code(),
        resolution_x: wanted.width as i32,
        resolution_y: wanted.height as i32,
        fps: wanted.fps as i32,
    };
    if stream.video_mode().is_ok_and(|current| current == wanted) {
        return;
    }
    let supported = stream.supported_video_modes();
    if !supported.contains(&wanted) {
        tracing::info!(
            "depth mode {wanted:?} not offered (offered: {supported:?}); keeping the current one"
        );
        return;
    }
    if let Err(error) = stream.set_video_mode(wanted) {
        tracing::warn!("setting depth mode {wanted:?}: {error}; keeping the current one");
    }
}
