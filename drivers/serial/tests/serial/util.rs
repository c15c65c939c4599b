//! Helpers that make the tests read like scripts.

use std::io::{self, Write};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use tacmesh_serial::camsense::CamsenseScanner;
use tacmesh_serial::Revolution;

/// The recorded Camsense X1-style byte stream (see `testdata/SOURCES.md`, serial/).
pub fn capture() -> Vec<u8> {
    tacmesh_testdata::bytes("serial/camsense_x1_protocol_uart_capture.bin")
}

/// A pseudo-terminal pair: the master (the "device" end, short timeouts), the slave kept open
/// so the master never sees a hang-up, and the slave's path for the source to open.
pub fn pty() -> (TTYPort, TTYPort, String) {
    let (mut master, slave) = TTYPort::pair().expect("create a pseudo-terminal pair");
    master
        .set_timeout(Duration::from_millis(5))
        .expect("set master timeout");
    let path = slave.name().expect("the slave pty has a path");
    (master, slave, path)
}

/// Writes all of `bytes`, retrying while the pty is full; gives up after 5 s.
pub fn write_fully(port: &mut TTYPort, mut bytes: &[u8]) -> io::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(5);
    while !bytes.is_empty() {
        match port.write(bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(e) if e.kind() == io::ErrorKind::TimedOut && Instant::now() < deadline => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Plays `bytes` into `master` at `bytes_per_s` on a thread, then keeps the master open until
/// `close` receives (or is dropped), so the reader sees every byte before any hang-up.
pub fn feed_paced(
    mut master: TTYPort,
    bytes: Vec<u8>,
    bytes_per_s: usize,
) -> (mpsc::Sender<()>, JoinHandle<io::Result<()>>) {
    let (close, closed) = mpsc::channel::<()>();
    let thread = std::thread::spawn(move || {
        let chunk = (bytes_per_s / 100).max(1); // 10 ms worth
        let started = Instant::now();
        for (i, piece) in bytes.chunks(chunk).enumerate() {
            let due = started + Duration::from_secs_f64((i * chunk) as f64 / bytes_per_s as f64);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            write_fully(&mut master, piece)?;
        }
        // Bounded: the test either signals or drops the sender.
        let _ = closed.recv_timeout(Duration::from_secs(30));
        drop(master);
        Ok(())
    });
    (close, thread)
}

/// The complete revolutions the pure decoder gets from `bytes` (the reference for pty tests).
pub fn complete_revolutions(bytes: &[u8]) -> Vec<Revolution> {
    let mut scanner = CamsenseScanner::new();
    let mut out = Vec::new();
    scanner.feed(bytes, &mut out);
    out.retain(|r| r.complete);
    out
}

/// A tiny deterministic generator (LCG) for corruption positions and garbage.
pub struct Lcg(pub u64);

impl Lcg {
    pub fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        self.0 >> 33
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}
