//! The dozen OpenNI2 C functions this crate calls, declared by hand from `OniCAPI.h` (OpenNI
//! 2.2), and the owners of their handles. This is the crate's only module with `unsafe`.
//!
//! Ownership encodes the only shutdown order OpenNI2 survives:
//! [`DepthStream`] owns its [`Device`], which owns a [`Context`] token. Dropping a stream
//! stops it, destroys it, then drops the device, which closes it, then drops the token; the
//! last token shuts the library down. No handle can outlive `oniShutdown`, and no frame
//! outlives its `oniFrameRelease`: pixels are copied out first.
//!
//! Layouts were checked against the Debian 2.2.0.33 headers with `offsetof` (OniFrame: 80
//! bytes, `timestamp` at 24, `videoMode` at 44, `stride` at 72); the `const` assertions below
//! keep them.

#![deny(clippy::undocumented_unsafe_blocks)]

use std::ffi::{c_char, c_float, c_int, c_void, CStr, CString};
use std::mem::size_of;
use std::ptr;
use std::sync::{Mutex, PoisonError};

use crate::depth_pixels::{unpack_rows, RawDepthImage};
use crate::{OniStatus, OpenNi2Error};

// ---- C declarations (OniCTypes.h, OniCEnums.h, OniCProperties.h, OniVersion.h) ----

/// `ONI_API_VERSION` of OpenNI 2.2: `ONI_CREATE_API_VERSION(2, 2)` = 2 * 1000 + 2.
const ONI_API_VERSION: c_int = 2002;
const ONI_SENSOR_DEPTH: c_int = 3;
const ONI_STREAM_PROPERTY_HORIZONTAL_FOV: c_int = 1;
const ONI_STREAM_PROPERTY_VERTICAL_FOV: c_int = 2;
const ONI_STREAM_PROPERTY_VIDEO_MODE: c_int = 3;
const ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES: c_int = 8;
const ONI_DEVICE_PROPERTY_PLAYBACK_SPEED: c_int = 100;
const ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED: c_int = 101;

type OniDeviceHandle = *mut c_void;
type OniStreamHandle = *mut c_void;
/// `OniBool`: a C `int`, not a one-byte bool.
type OniBool = c_int;

#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct OniVideoMode {
    pub pixel_format: c_int,
    pub resolution_x: c_int,
    pub resolution_y: c_int,
    pub fps: c_int,
}

#[repr(C)]
struct OniSensorInfo {
    sensor_type: c_int,
    num_supported_video_modes: c_int,
    supported_video_modes: *const OniVideoMode,
}

#[repr(C)]
struct OniFrame {
    data_size: c_int,
    data: *mut c_void,
    sensor_type: c_int,
    timestamp: u64,
    frame_index: c_int,
    width: c_int,
    height: c_int,
    video_mode: OniVideoMode,
    cropping_enabled: OniBool,
    crop_origin_x: c_int,
    crop_origin_y: c_int,
    stride: c_int,
}

const _: () = assert!(size_of::<OniVideoMode>() == 16);
const _: () = assert!(size_of::<OniSensorInfo>() == 16);
const _: () = assert!(size_of::<OniFrame>() == 80);
const _: () = assert!(std::mem::offset_of!(OniFrame, timestamp) == 24);
const _: () = assert!(std::mem::offset_of!(OniFrame, video_mode) == 44);
const _: () = assert!(std::mem::offset_of!(OniFrame, stride) == 72);

// Linked by build.rs (`-lOpenNI2`) when the `device` feature is on.
extern "C" {
    fn oniInitialize(api_version: c_int) -> c_int;
    fn oniShutdown();
    fn oniGetExtendedError() -> *const c_char;

    fn oniDeviceOpen(uri: *const c_char, device: *mut OniDeviceHandle) -> c_int;
    fn oniDeviceClose(device: OniDeviceHandle) -> c_int;
    fn oniDeviceCreateStream(
        device: OniDeviceHandle,
        sensor_type: c_int,
        stream: *mut OniStreamHandle,
    ) -> c_int;
    fn oniDeviceSetProperty(
        device: OniDeviceHandle,
        property_id: c_int,
        data: *const c_void,
        data_size: c_int,
    ) -> c_int;

    fn oniStreamDestroy(stream: OniStreamHandle);
    fn oniStreamGetSensorInfo(stream: OniStreamHandle) -> *const OniSensorInfo;
    fn oniStreamStart(stream: OniStreamHandle) -> c_int;
    fn oniStreamStop(stream: OniStreamHandle);
    fn oniStreamGetProperty(
        stream: OniStreamHandle,
        property_id: c_int,
        data: *mut c_void,
        data_size: *mut c_int,
    ) -> c_int;
    fn oniStreamSetProperty(
        stream: OniStreamHandle,
        property_id: c_int,
        data: *const c_void,
        data_size: c_int,
    ) -> c_int;
    fn oniWaitForAnyStream(
        streams: *mut OniStreamHandle,
        num_streams: c_int,
        stream_index: *mut c_int,
        timeout_ms: c_int,
    ) -> c_int;
    fn oniStreamReadFrame(stream: OniStreamHandle, frame: *mut *mut OniFrame) -> c_int;
    fn oniFrameRelease(frame: *mut OniFrame);
}

// ---- Status and extended error ----

/// `oniGetExtendedError()` as an owned string ("" if none).
fn extended_error() -> String {
    // SAFETY: oniGetExtendedError takes no arguments and may be called at any time, before
    // or after oniInitialize; it returns a pointer to a NUL-terminated buffer owned by
    // OpenNI2 (or, defensively, null, handled below).
    let text = unsafe { oniGetExtendedError() };
    if text.is_null() {
        return String::new();
    }
    // SAFETY: non-null, NUL-terminated, and valid until the next OpenNI2 call on this
    // thread; it is copied into a String before any other call is made.
    unsafe { CStr::from_ptr(text) }
        .to_string_lossy()
        .trim()
        .to_owned()
}

/// `Ok` for `ONI_STATUS_OK`, else the error with the extended error read right away (it is
/// overwritten by the next call).
fn check(call: &'static str, code: c_int) -> Result<(), OpenNi2Error> {
    OniStatus::check(code).map_err(|status| OpenNi2Error::Call {
        call,
        status,
        detail: extended_error(),
    })
}

// ---- Context: oniInitialize once per process, oniShutdown at exit ----

/// Library state, behind one lock that also serialises oniInitialize and oniShutdown.
struct Library {
    initialised: bool,
    /// Live [`Context`] tokens (and so devices and streams).
    tokens: usize,
}

static LIBRARY: Mutex<Library> = Mutex::new(Library {
    initialised: false,
    tokens: 0,
});

/// Proof that OpenNI2 is initialised.
///
/// OpenNI2 is initialised by the first token and stays initialised until the process exits,
/// when an `atexit` hook shuts it down if no token is left. Shutting down when the last
/// token dropped and initialising again later crashes Debian's 2.2.0.33: a second
/// oniInitialize segfaulted in `pthread_kill` on a thread handle left from the first run
/// (reproduced by running this crate's tests on 8 threads). Calling oniShutdown from the
/// `atexit` hook runs it before libOpenNI2's own static destructors (registered earlier, run
/// later), the order whose violation is OpenNI/OpenNI2#34.
#[derive(Debug)]
pub(crate) struct Context(());

impl Context {
    pub fn acquire() -> Result<Self, OpenNi2Error> {
        let mut library = LIBRARY.lock().unwrap_or_else(PoisonError::into_inner);
        if !library.initialised {
            // SAFETY: called with the API version of the headers these declarations follow,
            // at most once per process (guarded by `initialised` under the LIBRARY lock).
            let code = unsafe { oniInitialize(ONI_API_VERSION) };
            check("oniInitialize", code)?;
            library.initialised = true;
            // SAFETY: registers a plain `extern "C" fn()` with the C library; it is called
            // at most once, at exit.
            if unsafe { atexit(shutdown_at_exit) } != 0 {
                tracing::warn!("could not register OpenNI2 shutdown at exit");
            }
        }
        library.tokens += 1;
        Ok(Self(()))
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        let mut library = LIBRARY.lock().unwrap_or_else(PoisonError::into_inner);
        library.tokens -= 1;
    }
}

extern "C" {
    fn atexit(callback: extern "C" fn()) -> c_int;
}

/// Shuts OpenNI2 down at process exit, unless a device or stream is still alive (leaked, or
/// held by a thread that outlives `main`): closing the library under it would crash, and the
/// kernel reclaims everything anyway.
extern "C" fn shutdown_at_exit() {
    let mut library = LIBRARY.lock().unwrap_or_else(PoisonError::into_inner);
    if library.initialised && library.tokens == 0 {
        // SAFETY: OpenNI2 was initialised (flag under the lock) and no token, hence no
        // device or stream handle, exists; clearing the flag makes this run once.
        unsafe { oniShutdown() };
        library.initialised = false;
    }
}

// ---- Device ----

/// An open device (camera or recording), closed on drop.
#[derive(Debug)]
pub(crate) struct Device {
    handle: OniDeviceHandle,
    /// Dropped after `Drop::drop` closed the handle.
    _context: Context,
}

// SAFETY: an OpenNI2 device handle is not tied to the thread that opened it (OpenNI2 keeps no
// thread-local state per device and locks internally); Device is not Sync, so it is only ever
// used from one thread at a time.
unsafe impl Send for Device {}

impl Device {
    /// Opens `uri` (a device URI or a path to an `.oni` recording), or the first device
    /// OpenNI2 finds when `None`.
    pub fn open(context: Context, uri: Option<&str>) -> Result<Self, OpenNi2Error> {
        let uri = uri
            .map(|u| CString::new(u).map_err(|_| OpenNi2Error::BadUri(u.to_owned())))
            .transpose()?;
        let uri_ptr = uri.as_ref().map_or(ptr::null(), |u| u.as_ptr());
        let mut handle: OniDeviceHandle = ptr::null_mut();
        // SAFETY: `context` proves the library is initialised; uri_ptr is null (documented as
        // "any device") or a NUL-terminated string alive until after the call; handle is a
        // valid out-pointer.
        let code = unsafe { oniDeviceOpen(uri_ptr, &mut handle) };
        check("oniDeviceOpen", code)?;
        if handle.is_null() {
            return Err(OpenNi2Error::Call {
                call: "oniDeviceOpen",
                status: OniStatus::Error,
                detail: "returned OK but no device handle".into(),
            });
        }
        Ok(Self {
            handle,
            _context: context,
        })
    }

    /// For a recording: whether to loop at the end, and the playback speed (see
    /// `OpenNi2Options::playback_speed`).
    pub fn set_playback(&self, repeat: bool, speed: f32) -> Result<(), OpenNi2Error> {
        let repeat = OniBool::from(repeat);
        // SAFETY: the handle is open (self exists); data points at an OniBool (C int) alive
        // for the call and the size passed is exactly its size, as the property requires.
        let code = unsafe {
            oniDeviceSetProperty(
                self.handle,
                ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED,
                (&repeat as *const OniBool).cast(),
                size_of::<OniBool>() as c_int,
            )
        };
        check("oniDeviceSetProperty(PLAYBACK_REPEAT_ENABLED)", code)?;
        let speed: c_float = speed;
        // SAFETY: as above, with a C float for the float-valued speed property.
        let code = unsafe {
            oniDeviceSetProperty(
                self.handle,
                ONI_DEVICE_PROPERTY_PLAYBACK_SPEED,
                (&speed as *const c_float).cast(),
                size_of::<c_float>() as c_int,
            )
        };
        check("oniDeviceSetProperty(PLAYBACK_SPEED)", code)
    }

    /// Creates the depth stream; the stream takes the device, so it is closed only after the
    /// stream is destroyed.
    pub fn into_depth_stream(self) -> Result<DepthStream, OpenNi2Error> {
        let mut handle: OniStreamHandle = ptr::null_mut();
        // SAFETY: the device handle is open; handle is a valid out-pointer.
        let code = unsafe { oniDeviceCreateStream(self.handle, ONI_SENSOR_DEPTH, &mut handle) };
        check("oniDeviceCreateStream(ONI_SENSOR_DEPTH)", code)?;
        if handle.is_null() {
            return Err(OpenNi2Error::Call {
                call: "oniDeviceCreateStream(ONI_SENSOR_DEPTH)",
                status: OniStatus::Error,
                detail: "returned OK but no stream handle".into(),
            });
        }
        Ok(DepthStream {
            handle,
            started_at: None,
            _device: self,
        })
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the handle came from a successful oniDeviceOpen and is closed only here;
        // every stream of it owned this Device and has been destroyed already; the library is
        // still initialised because our Context token (which blocks shutdown) drops after this.
        let code = unsafe { oniDeviceClose(self.handle) };
        if let Err(error) = check("oniDeviceClose", code) {
            tracing::warn!("closing OpenNI2 device: {error}");
        }
    }
}

// ---- DepthStream ----

/// How long a stopped stream is left before it is destroyed (see `DepthStream::drop`).
const STOP_GRACE: std::time::Duration = std::time::Duration::from_millis(100);

/// A depth stream of its device; stopped and destroyed on drop, before the device closes.
#[derive(Debug)]
pub(crate) struct DepthStream {
    handle: OniStreamHandle,
    started_at: Option<std::time::Instant>,
    /// Dropped (closed) after `Drop::drop` destroyed the stream.
    _device: Device,
}

// SAFETY: as for Device: the stream handle is usable from any thread, and DepthStream is not
// Sync, so one thread at a time uses it.
unsafe impl Send for DepthStream {}

impl DepthStream {
    /// The video modes the sensor lists (empty if it lists none).
    pub fn supported_video_modes(&self) -> Vec<OniVideoMode> {
        // SAFETY: the stream handle is alive; the result is null or points at sensor info
        // owned by the stream.
        let info = unsafe { oniStreamGetSensorInfo(self.handle) };
        if info.is_null() {
            return Vec::new();
        }
        // SAFETY: non-null, and the sensor info lives as long as the stream, which outlives
        // this borrow; it is only read.
        let info = unsafe { &*info };
        let count = usize::try_from(info.num_supported_video_modes).unwrap_or(0);
        if count == 0 || info.supported_video_modes.is_null() {
            return Vec::new();
        }
        // SAFETY: OpenNI2 documents pSupportedVideoModes as an array of
        // numSupportedVideoModes modes, owned by the stream; copied out immediately.
        unsafe { std::slice::from_raw_parts(info.supported_video_modes, count) }.to_vec()
    }

    pub fn video_mode(&self) -> Result<OniVideoMode, OpenNi2Error> {
        let mut mode = OniVideoMode::default();
        self.get_property("VIDEO_MODE", ONI_STREAM_PROPERTY_VIDEO_MODE, &mut mode)?;
        Ok(mode)
    }

    pub fn set_video_mode(&self, mode: OniVideoMode) -> Result<(), OpenNi2Error> {
        let size = size_of::<OniVideoMode>() as c_int;
        // SAFETY: the stream handle is alive; data points at an OniVideoMode alive for the
        // call and `size` is its exact size, as the VIDEO_MODE property requires.
        let code = unsafe {
            oniStreamSetProperty(
                self.handle,
                ONI_STREAM_PROPERTY_VIDEO_MODE,
                (&mode as *const OniVideoMode).cast(),
                size,
            )
        };
        check("oniStreamSetProperty(VIDEO_MODE)", code)
    }

    /// Horizontal and vertical field of view in radians.
    pub fn fov_rad(&self) -> Result<(f32, f32), OpenNi2Error> {
        let (mut h, mut v): (c_float, c_float) = (0.0, 0.0);
        self.get_property("HORIZONTAL_FOV", ONI_STREAM_PROPERTY_HORIZONTAL_FOV, &mut h)?;
        self.get_property("VERTICAL_FOV", ONI_STREAM_PROPERTY_VERTICAL_FOV, &mut v)?;
        Ok((h, v))
    }

    /// Frames in a recording (`None` for live devices, which do not report it).
    pub fn number_of_frames(&self) -> Option<u32> {
        let mut count: c_int = 0;
        self.get_property(
            "NUMBER_OF_FRAMES",
            ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES,
            &mut count,
        )
        .ok()
        .and_then(|()| u32::try_from(count).ok())
    }

    /// Reads a fixed-size property into `value`. Only instantiated with C plain-old-data
    /// types (`c_int`, `c_float`, `OniVideoMode`), for which any bit pattern is valid.
    fn get_property<T: Copy>(
        &self,
        name: &'static str,
        property_id: c_int,
        value: &mut T,
    ) -> Result<(), OpenNi2Error> {
        let mut size = size_of::<T>() as c_int;
        // SAFETY: the stream handle is alive; data points at a writable T of `size` bytes; T
        // is plain old data (see above), so whatever the driver writes is a valid T.
        let code = unsafe {
            oniStreamGetProperty(
                self.handle,
                property_id,
                (value as *mut T).cast(),
                &mut size,
            )
        };
        OniStatus::check(code).map_err(|status| OpenNi2Error::Call {
            call: "oniStreamGetProperty",
            status,
            detail: format!("{name}: {}", extended_error()),
        })?;
        if size != size_of::<T>() as c_int {
            return Err(OpenNi2Error::Call {
                call: "oniStreamGetProperty",
                status: OniStatus::BadParameter,
                detail: format!("{name}: {size} B returned, {} B expected", size_of::<T>()),
            });
        }
        Ok(())
    }

    pub fn start(&mut self) -> Result<(), OpenNi2Error> {
        // SAFETY: the stream handle is alive and not started (start is only called once).
        let code = unsafe { oniStreamStart(self.handle) };
        check("oniStreamStart", code)?;
        self.started_at = Some(std::time::Instant::now());
        Ok(())
    }

    /// Waits at most `timeout_ms` for a frame; `ONI_STATUS_TIME_OUT` if none came.
    pub fn wait_for_frame(&self, timeout_ms: u32) -> Result<(), OpenNi2Error> {
        let mut streams = [self.handle];
        let mut ready: c_int = -1;
        let timeout = c_int::try_from(timeout_ms).unwrap_or(c_int::MAX);
        // SAFETY: streams is an array of one live stream handle and its length is passed;
        // ready is a valid out-pointer; a finite timeout is passed, so the call returns.
        let code = unsafe { oniWaitForAnyStream(streams.as_mut_ptr(), 1, &mut ready, timeout) };
        check("oniWaitForAnyStream", code)
    }

    /// Reads the next frame (blocks until there is one: call [`wait_for_frame`] first), copies
    /// its pixels out and releases it.
    ///
    /// [`wait_for_frame`]: Self::wait_for_frame
    pub fn read_frame(&self) -> Result<RawDepthImage, OpenNi2Error> {
        let mut frame: *mut OniFrame = ptr::null_mut();
        // SAFETY: the stream handle is alive and started; frame is a valid out-pointer.
        let code = unsafe { oniStreamReadFrame(self.handle, &mut frame) };
        check("oniStreamReadFrame", code)?;
        if frame.is_null() {
            return Err(OpenNi2Error::MalformedFrame(
                "oniStreamReadFrame returned OK but no frame".into(),
            ));
        }
        let frame = FrameRef(frame);
        // SAFETY: the frame is non-null and stays valid until FrameRef's drop releases it,
        // after this borrow ends; it is only read.
        copy_depth(unsafe { &*frame.0 })
    }
}

impl Drop for DepthStream {
    fn drop(&mut self) {
        if let Some(started_at) = self.started_at {
            // Not every driver's start and stop are synchronous: OpenNI2's own DummyDevice
            // starts a thread that sets its "running" flag when it first runs, and
            // `OzStream::stop` only clears that flag without joining (the thread sleeps 33 ms
            // between frames). Stopped too soon after starting, the thread sets the flag
            // after the stop and runs forever; destroyed too soon after stopping, it runs on
            // in a deleted stream or an unloaded driver. Both crashed our tests (SIGSEGV in
            // libDummyDevice.so). A grace period on both sides lets such a thread start and
            // then see the flag and exit; real drivers (PS1080) join and lose nothing but it.
            std::thread::sleep(STOP_GRACE.saturating_sub(started_at.elapsed()));
            // SAFETY: the handle is alive and started.
            unsafe { oniStreamStop(self.handle) };
            std::thread::sleep(STOP_GRACE);
        }
        // SAFETY: the handle came from oniDeviceCreateStream and is destroyed only here, while
        // its device (dropped after this) is still open; no frame of it is held (frames are
        // released before read_frame returns).
        unsafe { oniStreamDestroy(self.handle) };
    }
}

/// A frame from oniStreamReadFrame, released on drop (also on early return).
struct FrameRef(*mut OniFrame);

impl Drop for FrameRef {
    fn drop(&mut self) {
        // SAFETY: the pointer came from a successful oniStreamReadFrame and is released
        // exactly once, here; nothing borrowed from it outlives this.
        unsafe { oniFrameRelease(self.0) };
    }
}

/// Copies a depth frame's pixels and metadata out of OpenNI2's buffer.
fn copy_depth(frame: &OniFrame) -> Result<RawDepthImage, OpenNi2Error> {
    let as_u32 = |what: &str, v: c_int| {
        u32::try_from(v).map_err(|_| OpenNi2Error::MalformedFrame(format!("{what} is {v}")))
    };
    let (width, height) = (
        as_u32("width", frame.width)?,
        as_u32("height", frame.height)?,
    );
    let data_size = as_u32("dataSize", frame.data_size)? as usize;
    if frame.data.is_null() || width == 0 || height == 0 {
        return Err(OpenNi2Error::MalformedFrame(format!(
            "{width}×{height} frame with {} data",
            if frame.data.is_null() { "no" } else { "some" }
        )));
    }
    // Some drivers leave stride 0 for tightly packed rows.
    let stride = match frame.stride {
        s if s > 0 => s as usize,
        _ => width as usize * 2,
    };
    // SAFETY: OpenNI2 documents `data` as a buffer of `dataSize` bytes, valid until the frame
    // is released, which happens only after this function returns; read as bytes, so no
    // alignment is assumed.
    let bytes = unsafe { std::slice::from_raw_parts(frame.data.cast::<u8>(), data_size) };
    let units = unpack_rows(bytes, width as usize, height as usize, stride)?;
    let cropped = frame.cropping_enabled != 0;
    let full = |v: c_int, own: u32| u32::try_from(v).ok().filter(|&v| v > 0).unwrap_or(own);
    Ok(RawDepthImage {
        width,
        height,
        pixel_format: frame.video_mode.pixel_format,
        full_width: full(frame.video_mode.resolution_x, width),
        full_height: full(frame.video_mode.resolution_y, height),
        crop_origin: if cropped {
            (
                u32::try_from(frame.crop_origin_x).unwrap_or(0),
                u32::try_from(frame.crop_origin_y).unwrap_or(0),
            )
        } else {
            (0, 0)
        },
        frame_index: frame.frame_index,
        device_timestamp_us: frame.timestamp,
        units,
    })
}
