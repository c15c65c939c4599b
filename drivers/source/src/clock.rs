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
    (monotonic.as_nanos() as i128 + realtime_minus_monotonic_ns()).clamp(0, u64::MAX as i128) as u64
}

/// Now on both clocks, as a pair a client can take the offset between them from: the
/// monotonic time in nanoseconds and the wall-clock time of the same instant (see
/// [`realtime_of`] for how the two are matched).
pub fn now_on_both_clocks_ns() -> (u64, u64) {
    let monotonic = monotonic_now();
    (monotonic.as_nanos() as u64, realtime_of(monotonic))
}

/// `CLOCK_REALTIME` − `CLOCK_MONOTONIC` now, nanoseconds. The wall clock is read between two
/// readings of the monotonic one, and their midpoint taken; of a few tries, the one with the
/// two readings closest together. A thread preempted between a single pair of reads (26 ms once,
/// on a busy machine) would otherwise put its delay into every time converted with it.
fn realtime_minus_monotonic_ns() -> i128 {
    let mut best: Option<(i128, i128)> = None; // (gap, offset)
    for _ in 0..4 {
        let before = monotonic_now().as_nanos() as i128;
        let real = realtime_now_ns() as i128;
        let after = monotonic_now().as_nanos() as i128;
        let gap = after - before;
        let offset = real - (before + gap / 2);
        if best.is_none_or(|(best_gap, _)| gap < best_gap) {
            best = Some((gap, offset));
        }
        // Both reads within 20 µs: as close as it gets.
        if gap < 20_000 {
            break;
        }
    }
    best.map_or(0, |(_, offset)| offset)
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
