//! Serial-port backends: [`CamsenseSource`] and [`RplidarSource`], each a
//! [`DepthSource`] yielding one revolution per observation.
//!
//! Both read with a short per-call timeout and never block forever: no bytes for
//! [`SerialConfig::stall_timeout_ms`] is [`SourceError::Disconnected`]; bytes that never
//! make a complete revolution within [`SerialConfig::revolution_timeout_ms`] are
//! [`SourceError::Malformed`] (usually a wrong baud rate). The first, partial revolution after
//! opening is dropped; every observation is a whole turn.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use glam::Affine3A;
use serialport::{ClearBuffer, SerialPort};
use tacmesh_source::{monotonic_now, DepthSource, Observation, SourceError};

use crate::camsense::{CamsenseScanner, CamsenseStats};
use crate::revolution::Revolution;
use crate::rplidar::{
    request, Command, DeviceInfo, Health, HealthStatus, NodeStats, ResponseDescriptor,
    RplidarScanner, DESCRIPTOR_LEN, DESCRIPTOR_SYNC, HEALTH_LEN, INFO_LEN,
};

/// Line settings and time limits of a serial scanner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialConfig {
    pub baud_rate: u32,
    /// Longest a single read call waits.
    pub read_timeout_ms: u64,
    /// No byte at all for this long: the device is gone or stopped ([`SourceError::Disconnected`]).
    pub stall_timeout_ms: u64,
    /// Bytes arrive but no complete revolution for this long ([`SourceError::Malformed`]).
    pub revolution_timeout_ms: u64,
}

impl SerialConfig {
    /// Camsense X1-style sensors: 115200 baud, ≈ 5 rev/s.
    pub const CAMSENSE: Self = Self {
        baud_rate: 115_200,
        read_timeout_ms: 50,
        stall_timeout_ms: 1_000,
        revolution_timeout_ms: 3_000,
    };
    /// RPLIDAR A1 and A2: 115200 baud. The revolution limit leaves time for motor spin-up.
    pub const RPLIDAR_A1_A2: Self = Self {
        baud_rate: 115_200,
        read_timeout_ms: 50,
        stall_timeout_ms: 2_000,
        revolution_timeout_ms: 5_000,
    };
    /// RPLIDAR A3: 256000 baud.
    pub const RPLIDAR_A3: Self = Self {
        baud_rate: 256_000,
        ..Self::RPLIDAR_A1_A2
    };
}

/// Opens `path` for raw 8N1 reading with the config's timeout.
fn open_port(path: &str, config: &SerialConfig) -> Result<Box<dyn SerialPort>, SourceError> {
    serialport::new(path, config.baud_rate)
        .timeout(Duration::from_millis(config.read_timeout_ms))
        .open()
        .map_err(|error| {
            let hint = match error.kind() {
                serialport::ErrorKind::NoDevice
                | serialport::ErrorKind::Io(io::ErrorKind::NotFound) => {
                    "no such serial port: is the scanner plugged in (see `ls /dev/ttyUSB* \
                     /dev/ttyACM*`), or is another program holding it?"
                        .to_string()
                }
                serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied) => {
                    "permission denied: is the user in group `dialout`?".to_string()
                }
                _ => format!("could not open it as a serial port: {error}"),
            };
            SourceError::DeviceMissing {
                device: path.to_string(),
                hint,
            }
        })
}

fn is_transient(error: &io::Error) -> bool {
    matches!(
        error.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

fn disconnected(device: &str, reason: String) -> SourceError {
    SourceError::Disconnected {
        device: device.to_string(),
        reason,
    }
}

/// The read loop both sources share: bytes → decoder → queue of timestamped revolutions.
struct RevolutionReader {
    port: Box<dyn SerialPort>,
    device: String,
    config: SerialConfig,
    ready: VecDeque<(Revolution, Duration)>,
    closed: Vec<Revolution>,
    buf: Vec<u8>,
}

impl RevolutionReader {
    fn new(port: Box<dyn SerialPort>, device: &str, config: SerialConfig) -> Self {
        Self {
            port,
            device: device.to_string(),
            config,
            ready: VecDeque::new(),
            closed: Vec::new(),
            buf: vec![0; 4096],
        }
    }

    /// The next complete revolution and the monotonic time of the read that completed it.
    /// `decode` feeds bytes to the protocol decoder and appends revolutions it closes.
    fn next(
        &mut self,
        sensor_hint: &str,
        mut decode: impl FnMut(&[u8], &mut Vec<Revolution>),
    ) -> Result<(Revolution, Duration), SourceError> {
        let started = Instant::now();
        let mut last_bytes = Instant::now();
        loop {
            if let Some(ready) = self.ready.pop_front() {
                return Ok(ready);
            }
            match self.port.read(&mut self.buf) {
                Ok(0) => {}
                Ok(n) => {
                    last_bytes = Instant::now();
                    let capture_time = monotonic_now();
                    decode(&self.buf[..n], &mut self.closed);
                    for revolution in self.closed.drain(..) {
                        if revolution.complete {
                            self.ready.push_back((revolution, capture_time));
                        } else {
                            tracing::trace!(
                                device = %self.device,
                                samples = revolution.samples.len(),
                                "dropping partial first revolution"
                            );
                        }
                    }
                    if !self.ready.is_empty() {
                        continue;
                    }
                }
                Err(e) if is_transient(&e) => {}
                Err(e) => {
                    return Err(disconnected(
                        &self.device,
                        format!("read failed ({e}): was the scanner unplugged?"),
                    ))
                }
            }
            if last_bytes.elapsed() > Duration::from_millis(self.config.stall_timeout_ms) {
                return Err(disconnected(
                    &self.device,
                    format!(
                        "no bytes for {} ms: is the scanner powered and its motor spinning?",
                        self.config.stall_timeout_ms
                    ),
                ));
            }
            if started.elapsed() > Duration::from_millis(self.config.revolution_timeout_ms) {
                return Err(SourceError::Malformed {
                    device: self.device.clone(),
                    reason: format!(
                        "bytes arrive but no complete revolution in {} ms: is it a {sensor_hint} \
                         at {} baud?",
                        self.config.revolution_timeout_ms, self.config.baud_rate
                    ),
                });
            }
        }
    }
}

/// Turns a revolution into the observation every tacmesh source yields.
fn observation(
    device: &str,
    revolution: &Revolution,
    world_from_sensor: Affine3A,
    capture_time: Duration,
) -> Observation {
    let (cloud, skipped) = revolution.to_cloud();
    tracing::trace!(device, points = cloud.len(), skipped, "revolution decoded");
    Observation::Cloud {
        cloud,
        grid: None,
        world_from_sensor,
        capture_time,
    }
}

/// A Camsense X1-style scanner on a serial port. It streams as soon as it is powered; there is
/// nothing to send.
pub struct CamsenseSource {
    name: String,
    reader: RevolutionReader,
    scanner: CamsenseScanner,
    world_from_sensor: Affine3A,
}

impl CamsenseSource {
    /// Opens `path` at 115200 baud ([`SerialConfig::CAMSENSE`]); `world_from_sensor` is the
    /// mount pose attached to every observation.
    pub fn open(path: &str, world_from_sensor: Affine3A) -> Result<Self, SourceError> {
        Self::open_with(path, SerialConfig::CAMSENSE, world_from_sensor)
    }

    pub fn open_with(
        path: &str,
        config: SerialConfig,
        world_from_sensor: Affine3A,
    ) -> Result<Self, SourceError> {
        let port = open_port(path, &config)?;
        tracing::info!(
            port = path,
            baud = config.baud_rate,
            "camsense scanner opened"
        );
        Ok(Self {
            name: format!("camsense:{path}"),
            reader: RevolutionReader::new(port, path, config),
            scanner: CamsenseScanner::new(),
            world_from_sensor,
        })
    }

    /// The next whole revolution and its capture time (monotonic, at the read that ended it).
    pub fn next_revolution(&mut self) -> Result<(Revolution, Duration), SourceError> {
        let scanner = &mut self.scanner;
        self.reader.next("Camsense X1-style scanner", |bytes, out| {
            scanner.feed(bytes, out)
        })
    }

    /// Decoder counts so far (packets, skipped bytes, bad packets, flagged samples).
    pub fn stats(&self) -> CamsenseStats {
        self.scanner.stats()
    }

    /// The motor speed of the latest packet.
    pub fn speed_rev_per_s(&self) -> Option<f32> {
        self.scanner.speed_rev_per_s()
    }
}

impl DepthSource for CamsenseSource {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let (revolution, capture_time) = self.next_revolution()?;
        Ok(observation(
            &self.reader.device,
            &revolution,
            self.world_from_sensor,
            capture_time,
        ))
    }
}

/// An RPLIDAR A-series scanner in standard SCAN mode. Opening stops any running scan, checks
/// health, reads the device info and starts scanning; dropping it sends STOP.
pub struct RplidarSource {
    name: String,
    reader: RevolutionReader,
    scanner: RplidarScanner,
    world_from_sensor: Affine3A,
    info: DeviceInfo,
    health: Health,
}

/// Time the device gets to answer a request.
const ANSWER_TIMEOUT: Duration = Duration::from_millis(1_000);

impl RplidarSource {
    /// Opens `path` with `config` (e.g. [`SerialConfig::RPLIDAR_A1_A2`] or
    /// [`SerialConfig::RPLIDAR_A3`]) and starts a scan; `world_from_sensor` is the mount pose.
    pub fn open(
        path: &str,
        config: SerialConfig,
        world_from_sensor: Affine3A,
    ) -> Result<Self, SourceError> {
        let mut port = open_port(path, &config)?;
        // On A1/A2 USB adapters DTR low runs the motor; a pty or plain UART may refuse it.
        if let Err(error) = port.write_data_terminal_ready(false) {
            tracing::debug!(port = path, %error, "could not clear DTR (motor control)");
        }
        send(&mut port, path, Command::Stop)?;
        std::thread::sleep(Duration::from_millis(20));
        if let Err(error) = port.clear(ClearBuffer::Input) {
            tracing::debug!(port = path, %error, "could not flush input after STOP");
        }

        send(&mut port, path, Command::GetHealth)?;
        let mut health = [0u8; HEALTH_LEN];
        answer(&mut port, path, &ResponseDescriptor::HEALTH, &mut health)?;
        let health = Health::parse(&health);
        match health.status {
            HealthStatus::Good => {}
            HealthStatus::Warning => tracing::warn!(
                port = path,
                code = health.error_code,
                "RPLIDAR reports a health warning"
            ),
            HealthStatus::Error | HealthStatus::Unknown(_) => {
                return Err(disconnected(
                    path,
                    format!(
                        "health check reports {:?} (code {:#06x}): the device has stopped \
                         itself; power-cycle it",
                        health.status, health.error_code
                    ),
                ))
            }
        }

        send(&mut port, path, Command::GetInfo)?;
        let mut info = [0u8; INFO_LEN];
        answer(&mut port, path, &ResponseDescriptor::INFO, &mut info)?;
        let info = DeviceInfo::parse(&info);
        tracing::info!(
            port = path,
            model = info.model,
            firmware = format!("{}.{:02}", info.firmware_major, info.firmware_minor),
            hardware = info.hardware,
            serial = info.serial_hex(),
            "RPLIDAR opened"
        );

        send(&mut port, path, Command::Scan)?;
        answer(&mut port, path, &ResponseDescriptor::SCAN, &mut [])?;
        Ok(Self {
            name: format!("rplidar:{path}"),
            reader: RevolutionReader::new(port, path, config),
            scanner: RplidarScanner::new(),
            world_from_sensor,
            info,
            health,
        })
    }

    pub fn device_info(&self) -> DeviceInfo {
        self.info
    }

    pub fn health(&self) -> Health {
        self.health
    }

    /// Node-stream counts so far (nodes, no-reading nodes, resynchronisations).
    pub fn stats(&self) -> NodeStats {
        self.scanner.stats()
    }

    /// The next whole revolution and its capture time (monotonic, at the read that ended it).
    pub fn next_revolution(&mut self) -> Result<(Revolution, Duration), SourceError> {
        let scanner = &mut self.scanner;
        self.reader
            .next("RPLIDAR A-series", |bytes, out| scanner.feed(bytes, out))
    }
}

impl DepthSource for RplidarSource {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let (revolution, capture_time) = self.next_revolution()?;
        Ok(observation(
            &self.reader.device,
            &revolution,
            self.world_from_sensor,
            capture_time,
        ))
    }
}

impl Drop for RplidarSource {
    fn drop(&mut self) {
        // Best effort: leave the device idle for the next user.
        let _ = self.reader.port.write_all(&request(Command::Stop));
    }
}

fn send(port: &mut Box<dyn SerialPort>, path: &str, command: Command) -> Result<(), SourceError> {
    port.write_all(&request(command))
        .and_then(|()| port.flush())
        .map_err(|e| disconnected(path, format!("could not send {command:?} ({e})")))
}

/// Reads the response descriptor (skipping stray bytes before `A5 5A`), checks it is `expected`,
/// then reads `payload.len()` bytes, all within [`ANSWER_TIMEOUT`].
fn answer(
    port: &mut Box<dyn SerialPort>,
    path: &str,
    expected: &ResponseDescriptor,
    payload: &mut [u8],
) -> Result<(), SourceError> {
    let deadline = Instant::now() + ANSWER_TIMEOUT;
    let no_answer = || {
        disconnected(
            path,
            format!(
                "no answer (type {:#04x}) within {} ms: is it an RPLIDAR, powered, at this baud \
                 rate?",
                expected.data_type,
                ANSWER_TIMEOUT.as_millis()
            ),
        )
    };
    let mut descriptor = [0u8; DESCRIPTOR_LEN];
    // Hunt for the two sync bytes one byte at a time.
    let mut have = 0;
    while have < 2 {
        let mut byte = [0u8; 1];
        if !read_within(port, path, &mut byte, deadline)? {
            return Err(no_answer());
        }
        if byte[0] == DESCRIPTOR_SYNC[have] {
            have += 1;
        } else {
            have = usize::from(byte[0] == DESCRIPTOR_SYNC[0]);
        }
    }
    descriptor[..2].copy_from_slice(&DESCRIPTOR_SYNC);
    if !read_within(port, path, &mut descriptor[2..], deadline)? {
        return Err(no_answer());
    }
    ResponseDescriptor::parse(&descriptor)
        .and_then(|d| d.expect(expected))
        .map_err(|e| SourceError::Malformed {
            device: path.to_string(),
            reason: e.to_string(),
        })?;
    if !read_within(port, path, payload, deadline)? {
        return Err(no_answer());
    }
    Ok(())
}

/// Fills `buf` before `deadline`; `Ok(false)` on timeout.
fn read_within(
    port: &mut Box<dyn SerialPort>,
    path: &str,
    buf: &mut [u8],
    deadline: Instant,
) -> Result<bool, SourceError> {
    let mut filled = 0;
    while filled < buf.len() {
        if Instant::now() > deadline {
            return Ok(false);
        }
        match port.read(&mut buf[filled..]) {
            Ok(n) => filled += n,
            Err(e) if is_transient(&e) => {}
            Err(e) => return Err(disconnected(path, format!("read failed ({e})"))),
        }
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_port_is_device_missing_naming_the_port() {
        let path = "/dev/tacmesh-no-such-serial-port";
        let err = match CamsenseSource::open(path, Affine3A::IDENTITY) {
            Err(e) => e,
            Ok(_) => panic!("opened a port that does not exist"),
        };
        assert!(
            matches!(&err, SourceError::DeviceMissing { device, .. } if device == path),
            "{err}"
        );
        assert!(err.to_string().contains(path));
        let err = RplidarSource::open(path, SerialConfig::RPLIDAR_A1_A2, Affine3A::IDENTITY)
            .err()
            .expect("no such port");
        assert!(matches!(err, SourceError::DeviceMissing { .. }), "{err}");
    }
}
