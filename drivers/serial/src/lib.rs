//! 360° serial range scanners as tacmesh depth sources: Camsense X1-style sensors and Slamtec
//! RPLIDAR A-series (standard scan mode).
//!
//! Entry points:
//! - [`CamsenseSource`] and [`RplidarSource`]: [`tacmesh_source::DepthSource`]s on a serial port,
//!   one revolution per [`tacmesh_source::Observation::Cloud`] (capture time read on
//!   [`tacmesh_source::monotonic_now`] when the revolution's last byte arrived), with
//!   [`SerialConfig`] for baud rate and time limits.
//! - [`camsense`]: the pure Camsense packet decoder ([`CamsenseDecoder`], [`CamsenseScanner`]).
//! - [`rplidar`]: the pure RPLIDAR protocol (requests, response descriptors, GET_INFO,
//!   GET_HEALTH, standard scan nodes, [`RplidarScanner`]).
//! - [`revolution`]: samples → revolutions → planar clouds; it states the sensor-frame
//!   convention (x forward, y left, z up, scan angles clockwise seen from above).
//! - [`emulator`]: the device side of an RPLIDAR in a square room, for tests over a
//!   pseudo-terminal.
//!
//! The protocol modules do no I/O and take byte chunks of any size, so they can be tested against
//! recorded bytes and fuzzed; only [`port`] touches a device.

#![forbid(unsafe_code)]

pub mod camsense;
pub mod emulator;
pub mod port;
pub mod revolution;
pub mod rplidar;

pub use camsense::{CamsenseDecoder, CamsensePacket, CamsenseScanner, CamsenseStats};
pub use port::{CamsenseSource, RplidarSource, SerialConfig};
pub use revolution::{Revolution, RevolutionAssembler, ScanSample};
pub use rplidar::{DeviceInfo, Health, HealthStatus, NodeStats, RplidarScanner, ScanNode};
