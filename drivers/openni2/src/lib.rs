//! OpenNI2 devices (PrimeSense Carmine, Asus Xtion, Kinect through the freenect driver,
//! Orbbec) and `.oni` recordings as a tacmesh depth source, through a small FFI of our own.
//!
//! Entry points:
//! - [`OpenNi2Source`] (feature `device`): [`OpenNi2Source::open`] a device or recording with
//!   [`OpenNi2Options`]; it implements [`tacmesh_source::DepthSource`].
//! - Hardware-free, always built: [`depth_m_from_raw`] / [`unpack_rows`] (DEPTH_1_MM and
//!   DEPTH_100_UM pixels to metres), [`intrinsics_from_fov`] (pinhole from the reported fields
//!   of view), [`OniStatus`] / [`OpenNi2Error`] and their mapping to
//!   [`tacmesh_source::SourceError`] ([`open_error`], [`read_error`]).
//!
//! # Why our own FFI, not the `openni2` crate
//! The `openni2` crate (TooManyBees/rust-openni2, last released 2018) ties nothing to the
//! library's lifetime: `openni2::init()` and `openni2::shutdown()` are free functions, and
//! `Device` / `Stream` call `oniDeviceClose` / `oniStreamDestroy` in their `Drop`s, so a
//! shutdown before the last handle drops (or a static dropped after it) makes those calls
//! into a shut-down library — the crash on close/shutdown we saw. OpenNI2's own tracker has
//! the same failure from the C++ side (OpenNI/OpenNI2#34, "Segfault on shutdown": OpenNI shut
//! down before objects that still used it were destroyed). The crate also passes a one-byte
//! Rust `bool` for `OniBool` (a C `int`) properties such as `PLAYBACK_REPEAT_ENABLED`, and
//! goes through bindgen (`openni2-sys`), which needs libclang in every build.
//!
//! Here ownership fixes the order instead (see `ffi.rs`): a stream owns its device, a device
//! owns a library token, so dropping is always stop → destroy stream → close device; frames are
//! copied out and released inside the read call; all `unsafe` is in `ffi.rs`, one
//! `// SAFETY:` comment per block, with `const` layout assertions checked against Debian's
//! 2.2.0.33 headers. What we measured against Debian's libopenni2 2.2.0.33 decided the rest:
//! - `oniShutdown` then `oniInitialize` again segfaulted (in `pthread_kill` on a thread handle
//!   left from the first run), so the library is initialised once per process and shut down
//!   by an `atexit` hook, only if no device is still open.
//! - OpenNI2's DummyDevice driver starts and stops its producer thread asynchronously; a
//!   stream stopped right after starting, or destroyed right after stopping, crashed in
//!   `libDummyDevice.so`. Dropping a stream therefore waits up to 100 ms before and 100 ms
//!   after `oniStreamStop`.
//! - Once a URI such as `"Dummy"` was opened, OpenNI2 keeps that device listed, so a later
//!   `open(None)` in the same process opens it.
//!
//! OpenNI2's file driver plays back the OpenNI 1 recording in `testdata/recordings`
//! (NI10 container, PrimeSense 16zT depth): all 12 frames, identical to `tacmesh-oni`'s.

//! # Building
//! Default builds need no OpenNI2. `--features device` links `libOpenNI2` (Debian/Ubuntu:
//! `apt-get install libopenni2-dev`, which pulls `libopenni2-0` with the PS1080, PSLink,
//! OniFile and DummyDevice drivers); `build.rs` explains where it looks.

#![deny(unsafe_code)]

mod depth_pixels;
#[cfg(feature = "device")]
#[allow(unsafe_code)]
mod ffi;
mod intrinsics;
mod options;
#[cfg(feature = "device")]
mod source;
mod status;

pub use depth_pixels::{depth_m_from_raw, unpack_rows, DepthPixelFormat, RawDepthImage};
pub use intrinsics::{cropped, intrinsics_from_fov};
pub use options::{OpenNi2Options, VideoMode};
#[cfg(feature = "device")]
pub use source::OpenNi2Source;
pub use status::{open_error, read_error, OniStatus, OpenNi2Error};
