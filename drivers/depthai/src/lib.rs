//! Luxonis OAK cameras (OAK-D, OAK-D Lite, OAK-D Pro…) through DepthAI's Python library,
//! embedded with pyo3, as a tacmesh depth source; and DepthAI's own `.mcap` recordings.
//!
//! Entry points:
//! - [`DepthAiSource`] (feature `device`): [`DepthAiSource::open`] a camera's stereo-depth
//!   pipeline or a recording, with [`DepthAiOptions`]; it implements
//!   [`tacmesh_source::DepthSource`]. [`record_depth_frames`] writes frames into a recording
//!   with DepthAI's recorder, without a camera.
//! - Hardware-free, always built: [`DepthAiOptions::parse_spec`] (the daemon's `depthai:`
//!   spec), [`depth_frame`] / [`intrinsics_from_matrix`] / [`raw16_from_metres`] (frames as
//!   DepthAI carries them), [`VirtualEnv`] (where a venv keeps `depthai`), [`DepthAiError`].
//!
//! # Why Python
//! DepthAI's C++ core has no Debian package and its build fetches some twenty dependencies
//! through vcpkg, while `pip install depthai` is one wheel with the device firmware inside. So
//! the backend embeds CPython and drives the `depthai` package. What that takes:
//! - **One interpreter thread** owns Python for the whole process (`interpreter.rs`); sources
//!   talk to it over channels, and the daemon's own threads never take the GIL.
//! - **libpython by rpath.** pyo3 links `libpython3.X.so` by name only; the build scripts add
//!   an rpath to the directory of the Python found at build time, so the same library loads at
//!   run time.
//! - **Virtual environments by hand.** An embedded interpreter ignores venvs; the venv named
//!   with `venv=` (or `$VIRTUAL_ENV`) has its `site-packages` added to `sys.path`, and must be
//!   of the same Python minor version ([`VirtualEnv`]).
//! - **No phoning home.** Telemetry, crash-dump uploads, start-up notifications and model-zoo
//!   checks are switched off before `depthai` loads (`bridge.py`); an operator's explicit
//!   environment setting is kept and logged.
//! - **Bounded waits.** A missing camera fails after `DEPTHAI_SEARCH_TIMEOUT`
//!   (`search_timeout_ms`, 3 s by default) with a clear error; a pipeline is always stopped
//!   *and waited for* before its objects go, which otherwise crashes at exit.
//!
//! Recordings use DepthAI's own host-side recorder and player (`RecordMessage` /
//! `ReplayMessage`, MCAP files): `record=FILE.mcap` records a live camera's depth, and a spec
//! naming an `.mcap` file plays it back, with the intrinsics each frame carries.

#![forbid(unsafe_code)]

mod error;
mod frame;
#[cfg(feature = "device")]
mod interpreter;
mod options;
#[cfg(feature = "device")]
mod source;
mod venv;

pub use error::DepthAiError;
pub use frame::{
    depth_frame, intrinsics_from_matrix, raw16_from_metres, RawDepthImage, DEPTH_UNIT_M,
};
pub use options::{DepthAiOptions, DepthAlign, LiveOptions, Mode, ReplayOptions};
#[cfg(feature = "device")]
pub use source::{record_depth_frames, DepthAiSource};
pub use venv::VirtualEnv;
