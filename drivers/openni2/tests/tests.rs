//! One integration binary. Everything here talks to the real libOpenNI2 (feature `device`)
//! but needs no camera: it uses "no device", OpenNI2's own dummy driver and a recording.

#[cfg(feature = "device")]
mod device;
#[cfg(feature = "device")]
mod util;
