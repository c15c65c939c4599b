//! An emulated RPLIDAR A-series: the device side of the protocol, for tests and demos.
//!
//! [`EmulatedDevice`] is the pure state machine (request bytes in, reply bytes out);
//! [`spawn_emulated_rplidar`] runs it on a thread over any byte port, e.g. the master end of a
//! pseudo-terminal pair, pacing its output to the serial line's byte rate. The scene is a
//! [`SquareRoom`] seen from a sensor standing inside it, axis-aligned with the walls.
//!
//! Entry points: [`SquareRoom`], [`EmulatorConfig`], [`EmulatedDevice`],
//! [`spawn_emulated_rplidar`].

use std::io::{self, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use glam::Vec2;

use crate::rplidar::{
    Command, DeviceInfo, Health, HealthStatus, ResponseDescriptor, ScanNode, SYNC,
};

/// A square room centred on the origin, walls parallel to the axes, and where the sensor stands.
/// The sensor's forward axis (angle 0) is the room's +x, its left the room's +y.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SquareRoom {
    pub width_m: f32,
    pub sensor_in_room_m: Vec2,
}

impl SquareRoom {
    /// Range from the sensor to the first wall along the clockwise scan angle `angle_deg`.
    pub fn range_m(&self, angle_deg: f32) -> f32 {
        let theta = angle_deg.to_radians();
        let direction = Vec2::new(theta.cos(), -theta.sin());
        let half = self.width_m / 2.0;
        let hit = |origin: f32, dir: f32| {
            if dir.abs() < 1e-9 {
                f32::INFINITY
            } else {
                (half * dir.signum() - origin) / dir
            }
        };
        hit(self.sensor_in_room_m.x, direction.x).min(hit(self.sensor_in_room_m.y, direction.y))
    }

    /// How far `p_in_room` is from the nearest wall line, in metres (0 on a wall).
    pub fn wall_distance_m(&self, p_in_room: Vec2) -> f32 {
        (p_in_room.abs().max_element() - self.width_m / 2.0).abs()
    }
}

/// What the emulated device reports and how it streams.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    pub room: SquareRoom,
    pub nodes_per_revolution: u16,
    /// Output pacing: the serial line's byte rate (baud / 10), or `None` to write as fast as the
    /// port accepts.
    pub bytes_per_s: Option<u32>,
    /// Insert 1–3 bytes of garbage after every this many nodes (to exercise resynchronisation).
    pub garbage_every_nodes: Option<u32>,
    pub info: DeviceInfo,
    pub health: Health,
}

impl EmulatorConfig {
    /// An A1-like device (model 0x18, firmware 1.29) at 115200 baud in a 4 m room, standing
    /// 0.5 m forward and 0.3 m right of the centre, 360 nodes per revolution.
    pub fn a1_in_4m_room() -> Self {
        Self {
            room: SquareRoom {
                width_m: 4.0,
                sensor_in_room_m: Vec2::new(0.5, -0.3),
            },
            nodes_per_revolution: 360,
            bytes_per_s: Some(115_200 / 10),
            garbage_every_nodes: None,
            info: DeviceInfo {
                model: 0x18,
                firmware_major: 1,
                firmware_minor: 29,
                hardware: 7,
                serial_number: *b"TACMESH-EMULATED",
            },
            health: Health {
                status: HealthStatus::Good,
                error_code: 0,
            },
        }
    }
}

/// The device's state machine: parses requests, queues replies and scan nodes.
#[derive(Debug)]
pub struct EmulatedDevice {
    config: EmulatorConfig,
    scanning: bool,
    next_node: u64,
    request_bytes: Vec<u8>,
    /// Every request understood, in order.
    pub requests: Vec<Command>,
    garbage_seed: u32,
}

impl EmulatedDevice {
    pub fn new(config: EmulatorConfig) -> Self {
        Self {
            config,
            scanning: false,
            next_node: 0,
            request_bytes: Vec::new(),
            requests: Vec::new(),
            garbage_seed: 0x1234_5678,
        }
    }

    pub fn scanning(&self) -> bool {
        self.scanning
    }

    /// Consumes request bytes from the host; appends replies to `out`. STOP and RESET discard
    /// whatever `out` still holds (the device stops sending at once).
    pub fn receive(&mut self, bytes: &[u8], out: &mut Vec<u8>) {
        self.request_bytes.extend_from_slice(bytes);
        loop {
            let Some(sync) = self.request_bytes.iter().position(|&b| b == SYNC) else {
                self.request_bytes.clear();
                return;
            };
            self.request_bytes.drain(..sync);
            let Some(&code) = self.request_bytes.get(1) else {
                return;
            };
            let mut used = 2;
            if code & 0x80 != 0 {
                // Payload requests: A5 cmd len payload checksum; skipped whole, not answered.
                let Some(&len) = self.request_bytes.get(2) else {
                    return;
                };
                used = 4 + len as usize;
                if self.request_bytes.len() < used {
                    return;
                }
            }
            self.request_bytes.drain(..used);
            if let Some(command) = Command::from_code(code) {
                self.requests.push(command);
                self.answer(command, out);
            }
        }
    }

    fn answer(&mut self, command: Command, out: &mut Vec<u8>) {
        match command {
            Command::Stop => {
                self.scanning = false;
                out.clear();
            }
            Command::Reset => {
                self.scanning = false;
                out.clear();
                out.extend_from_slice(b"RP LIDAR System.\r\nEmulated by tacmesh\r\n");
            }
            Command::GetHealth => {
                out.extend_from_slice(&ResponseDescriptor::HEALTH.encode());
                out.extend_from_slice(&self.config.health.encode());
            }
            Command::GetInfo => {
                out.extend_from_slice(&ResponseDescriptor::INFO.encode());
                out.extend_from_slice(&self.config.info.encode());
            }
            Command::Scan | Command::ForceScan => {
                out.extend_from_slice(&ResponseDescriptor::SCAN.encode());
                self.scanning = true;
                self.next_node = 0;
            }
        }
    }

    /// Appends the next `count` scan nodes (and any configured garbage) to `out`, if scanning.
    pub fn stream(&mut self, count: usize, out: &mut Vec<u8>) {
        if !self.scanning {
            return;
        }
        let per_revolution = u64::from(self.config.nodes_per_revolution.max(1));
        for _ in 0..count {
            let index = self.next_node % per_revolution;
            // Half a step of offset keeps angles off exact multiples (as a real motor would).
            let angle_deg = (index as f32 + 0.5) * 360.0 / per_revolution as f32;
            let range_m = self.config.room.range_m(angle_deg);
            let node = ScanNode {
                start: index == 0,
                quality: 47,
                angle_q6: (angle_deg * 64.0).round() as u16,
                distance_q2: (range_m * 4000.0).round().clamp(0.0, 65535.0) as u16,
            };
            out.extend_from_slice(&node.encode());
            self.next_node += 1;
            if let Some(every) = self.config.garbage_every_nodes {
                if self.next_node.is_multiple_of(u64::from(every.max(1))) {
                    self.push_garbage(out);
                }
            }
        }
    }

    fn push_garbage(&mut self, out: &mut Vec<u8>) {
        // A small LCG: deterministic, no dependency.
        let mut next = || {
            self.garbage_seed = self
                .garbage_seed
                .wrapping_mul(1_664_525)
                .wrapping_add(1_013_904_223);
            (self.garbage_seed >> 24) as u8
        };
        let len = 1 + next() % 3;
        for _ in 0..len {
            out.push(next());
        }
    }
}

/// A running emulator thread. Dropping it stops the thread.
pub struct EmulatedRplidar {
    stop: Arc<AtomicBool>,
    requests: Arc<Mutex<Vec<Command>>>,
    thread: Option<JoinHandle<()>>,
}

impl EmulatedRplidar {
    /// The requests the device has understood so far, in order.
    pub fn requests(&self) -> Vec<Command> {
        self.requests
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone()
    }

    /// Stops the thread (closing its port) and returns the requests the device understood.
    pub fn stop(mut self) -> Vec<Command> {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        self.requests()
    }
}

impl Drop for EmulatedRplidar {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn is_transient(error: &io::Error) -> bool {
    matches!(
        error.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// Runs an [`EmulatedDevice`] on a thread over `port`, whose reads must time out (a
/// `serialport` port with a short timeout, e.g. 5 ms). The thread ends when stopped or when the
/// port fails (the host side closed).
pub fn spawn_emulated_rplidar<P>(mut port: P, config: EmulatorConfig) -> EmulatedRplidar
where
    P: Read + Write + Send + 'static,
{
    let stop = Arc::new(AtomicBool::new(false));
    let stop_flag = Arc::clone(&stop);
    let requests = Arc::new(Mutex::new(Vec::new()));
    let request_log = Arc::clone(&requests);
    let thread = std::thread::spawn(move || {
        let bytes_per_s = config.bytes_per_s;
        let mut device = EmulatedDevice::new(config);
        let mut pending: Vec<u8> = Vec::new();
        let mut buf = [0u8; 256];
        // Pacing: bytes allowed since streaming began.
        let mut paced_since: Option<(Instant, u64)> = None;
        while !stop_flag.load(Ordering::Relaxed) {
            match port.read(&mut buf) {
                Ok(n) => {
                    device.receive(&buf[..n], &mut pending);
                    let mut log = request_log
                        .lock()
                        .unwrap_or_else(|poisoned| poisoned.into_inner());
                    let logged = log.len();
                    log.extend_from_slice(&device.requests[logged..]);
                }
                Err(e) if is_transient(&e) => {}
                Err(_) => break,
            }
            if device.scanning() {
                let (since, sent) = paced_since.get_or_insert((Instant::now(), 0));
                let due_nodes = match bytes_per_s {
                    Some(rate) => {
                        let allowed = (since.elapsed().as_secs_f64() * f64::from(rate)) as u64;
                        (allowed.saturating_sub(*sent) / 5) as usize
                    }
                    None => 64,
                };
                if pending.len() < 4096 && due_nodes > 0 {
                    let before = pending.len();
                    device.stream(due_nodes.min(512), &mut pending);
                    *sent += (pending.len() - before) as u64;
                }
            } else {
                paced_since = None;
            }
            if !pending.is_empty() {
                match port.write(&pending) {
                    Ok(n) => {
                        pending.drain(..n);
                    }
                    Err(e) if is_transient(&e) => {}
                    Err(_) => break,
                }
            }
        }
    });
    EmulatedRplidar {
        stop,
        requests,
        thread: Some(thread),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rplidar::{request, RplidarScanner, DESCRIPTOR_LEN};

    #[test]
    fn room_range_hits_the_nearest_wall() {
        let room = SquareRoom {
            width_m: 4.0,
            sensor_in_room_m: Vec2::new(0.5, -0.3),
        };
        assert!((room.range_m(0.0) - 1.5).abs() < 1e-5);
        // Clockwise 90° looks to the sensor's right, towards y = −2.
        assert!((room.range_m(90.0) - 1.7).abs() < 1e-5);
        assert!((room.range_m(180.0) - 2.5).abs() < 1e-5);
        assert!((room.range_m(270.0) - 2.3).abs() < 1e-5);
    }

    #[test]
    fn device_answers_health_info_and_streams_after_scan() {
        let mut device = EmulatedDevice::new(EmulatorConfig::a1_in_4m_room());
        let mut out = Vec::new();
        device.receive(&request(Command::GetHealth), &mut out);
        assert_eq!(&out[..DESCRIPTOR_LEN], &ResponseDescriptor::HEALTH.encode());
        assert_eq!(out.len(), DESCRIPTOR_LEN + 3);
        out.clear();
        device.receive(&[0x00, 0xA5, 0x50], &mut out);
        assert_eq!(out.len(), DESCRIPTOR_LEN + 20);
        out.clear();
        device.receive(&request(Command::Scan), &mut out);
        assert!(device.scanning());
        device.stream(1000, &mut out);
        let mut scanner = RplidarScanner::new();
        let mut revolutions = Vec::new();
        scanner.feed(&out[DESCRIPTOR_LEN..], &mut revolutions);
        assert_eq!(revolutions.len(), 2);
        device.receive(&request(Command::Stop), &mut out);
        assert!(out.is_empty() && !device.scanning());
        assert_eq!(
            device.requests,
            [
                Command::GetHealth,
                Command::GetInfo,
                Command::Scan,
                Command::Stop
            ]
        );
    }
}
