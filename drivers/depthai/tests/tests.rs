//! Integration tests of the DepthAI backend (one binary). With the `device` feature they drive
//! the real `depthai` Python package, host-only: DepthAI's recorder writes simulated depth
//! frames into an `.mcap` file and the backend plays it back; the camera path is exercised up
//! to DepthAI's device search, which fails here (no camera) and must fail clearly and soon.
//!
//! Python: the interpreter pyo3 linked at build time; `depthai` from the venv named by
//! `TACMESH_DEPTHAI_VENV` (CI makes one), else `$VIRTUAL_ENV`, else that interpreter's own
//! packages.

#[cfg(feature = "device")]
mod device;
