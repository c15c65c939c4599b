//! One test binary: the decoder against the real RealSense D435 frame in `testdata/`, and the
//! capture backend's errors on nodes that are not depth cameras (no hardware needed).

mod real_frame;
mod util;

#[cfg(feature = "device")]
mod device;
