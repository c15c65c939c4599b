//! The one clock every frame's capture time is read on.
//!
//! `CLOCK_MONOTONIC` of the host rather than a daemon-private `Instant` epoch: a client on the
//! same machine (the socket is local) reads the same clock, so it can tell how old a mesh's data
//! is without any handshake; and several sources in one daemon agree without sharing a start.

use std::time::Duration;

/// Now on the host's `CLOCK_MONOTONIC` (time since an arbitrary point near boot, not counting
/// suspend), the clock of [`crate::DepthFrame::capture_time`] and of the wire format's times.
pub fn monotonic_now() -> Duration {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::Monotonic);
    Duration::new(
        t.tv_sec.max(0) as u64,
        t.tv_nsec.clamp(0, 999_999_999) as u32,
    )
}

/// Now on the host's `CLOCK_REALTIME`, nanoseconds since the Unix epoch (0 for a clock set
/// before it): the wire format gives times on it too, for a client on another host.
pub fn realtime_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |since| since.as_nanos().min(u64::MAX as u128) as u64)
}

/// The `CLOCK_REALTIME` nanoseconds of the `CLOCK_MONOTONIC` instant `monotonic`, by the two
/// clocks' offset now (a wall clock stepped since `monotonic` shifts the answer with it).
pub fn realtime_of(monotonic: Duration) -> u64 {
    let offset = realtime_now_ns() as i128 - monotonic_now().as_nanos() as i128;
    (monotonic.as_nanos() as i128 + offset).clamp(0, u64::MAX as i128) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_now_advances_with_std_instant() {
        // Each Instant is read between two readings of ours: on the same clock, the Instant's
        // interval lies between the inner and the outer interval of ours, however long a busy
        // machine holds the thread between the reads.
        let (a0, started, a1) = (monotonic_now(), std::time::Instant::now(), monotonic_now());
        std::thread::sleep(Duration::from_millis(20));
        let (b0, ended, b1) = (monotonic_now(), std::time::Instant::now(), monotonic_now());
        let waited = ended - started;
        assert!(b0 - a1 >= Duration::from_millis(20), "{:?}", b0 - a1);
        assert!(
            b0 - a1 <= waited && waited <= b1 - a0,
            "Instant's {waited:?} is not between ours {:?} and {:?}",
            b0 - a1,
            b1 - a0
        );
    }
}
