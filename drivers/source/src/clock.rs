//! The one clock every frame's capture time is read on.
//!
//! `CLOCK_MONOTONIC` of the host rather than a daemon-private `Instant` epoch: a client on the
//! same machine (the socket is local) reads the same clock, so it can tell how old a mesh's data
//! is without any handshake; and several sources in one daemon agree without sharing a start.

use std::time::Duration;

/// Now on the host's `CLOCK_MONOTONIC` (time since boot, not counting suspend), the clock of
/// [`crate::DepthFrame::capture_time`] and of the wire format's `capture_time_ns`.
pub fn monotonic_now() -> Duration {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::Monotonic);
    Duration::new(
        t.tv_sec.max(0) as u64,
        t.tv_nsec.clamp(0, 999_999_999) as u32,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_now_advances_with_std_instant() {
        let (a, started) = (monotonic_now(), std::time::Instant::now());
        std::thread::sleep(Duration::from_millis(20));
        let (b, waited) = (monotonic_now(), started.elapsed());
        let step = b - a;
        assert!(step >= Duration::from_millis(20), "{step:?}");
        // Same clock as Instant on Linux: the two intervals agree closely.
        let diff = step.abs_diff(waited);
        assert!(diff < Duration::from_millis(5), "{step:?} vs {waited:?}");
    }
}
