//! How fast a replay hands out frames: as fast as asked, at a fixed rate, or at the rate the
//! frames were recorded.

use std::time::{Duration, Instant};

use tacmesh_source::SourceError;

/// The rate a replay delivers at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// Each frame as soon as it is asked for.
    Max,
    /// At most `fps` frames per second, evenly spaced.
    Fixed { fps: f64 },
    /// At the recorded rate: frame `i` is due `t_i - t_0` seconds after the first frame of the
    /// pass. Needs per-frame timestamps (a TUM `depth.txt`).
    Recorded,
}

/// The slowest fixed replay rate: a frame every 100 s.
pub const MIN_FPS: f64 = 0.01;
/// The fastest fixed replay rate (faster is `rate=max`).
pub const MAX_FPS: f64 = 1_000.0;

/// The clock side of [`Pacing`]: remembers when the pass started and sleeps until each frame
/// is due.
#[derive(Debug, Clone)]
pub(crate) struct Pacer {
    pacing: Pacing,
    /// The wall time and recorded timestamp of the pass's first frame.
    anchor: Option<(Instant, f64)>,
    last: Option<Instant>,
}

impl Pacer {
    pub(crate) fn new(pacing: Pacing) -> Self {
        Self {
            pacing,
            anchor: None,
            last: None,
        }
    }

    /// Why this pacing cannot be followed, if it cannot: a fixed rate must be positive.
    pub(crate) fn check(pacing: Pacing) -> Result<(), String> {
        match pacing {
            Pacing::Fixed { fps } if !(MIN_FPS..=MAX_FPS).contains(&fps) => Err(format!(
                "a fixed rate of {fps} frames per second is not from {MIN_FPS} to {MAX_FPS}"
            )),
            _ => Ok(()),
        }
    }

    /// Starts a new pass (after looping): the recorded clock restarts from its next frame.
    pub(crate) fn restart(&mut self) {
        self.anchor = None;
    }

    /// Blocks until a frame with this recorded timestamp is due.
    pub(crate) fn wait(&mut self, timestamp_s: Option<f64>) {
        let now = Instant::now();
        let due = match (self.pacing, timestamp_s) {
            (Pacing::Max, _) => None,
            (Pacing::Fixed { fps }, _) => self.last.and_then(|last| {
                Duration::try_from_secs_f64(1.0 / fps)
                    .ok()
                    .and_then(|p| last.checked_add(p))
            }),
            (Pacing::Recorded, Some(t)) => match self.anchor {
                None => {
                    self.anchor = Some((now, t));
                    None
                }
                // Timestamps that go backwards, or so far ahead that no clock holds them,
                // mean "now", not a panic.
                Some((start, t0)) => Duration::try_from_secs_f64(t - t0)
                    .ok()
                    .and_then(|d| start.checked_add(d)),
            },
            (Pacing::Recorded, None) => None,
        };
        if let Some(due) = due {
            std::thread::sleep(due.saturating_duration_since(now));
        }
        self.last = Some(due.map_or(now, |due| due.max(now)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_rate_spaces_frames() {
        let mut pacer = Pacer::new(Pacing::Fixed { fps: 50.0 });
        let start = Instant::now();
        for _ in 0..3 {
            pacer.wait(None);
        }
        assert!(start.elapsed() >= Duration::from_millis(40));
    }

    #[test]
    fn recorded_rate_follows_timestamps_and_restarts() {
        let mut pacer = Pacer::new(Pacing::Recorded);
        let start = Instant::now();
        pacer.wait(Some(100.0));
        pacer.wait(Some(100.03));
        assert!(start.elapsed() >= Duration::from_millis(30));
        pacer.restart();
        assert_eq!(pacer.anchor, None);
        pacer.wait(Some(100.0));
        assert_eq!(pacer.anchor.map(|(_, t0)| t0), Some(100.0));
    }

    /// A recorded timestamp too far ahead for any clock (a corrupt recording) is "now", and a
    /// fixed rate whose period overflows is refused when the spec is checked.
    #[test]
    fn timestamps_and_rates_past_the_clock_do_not_panic() {
        let mut pacer = Pacer::new(Pacing::Recorded);
        pacer.wait(Some(0.0));
        pacer.wait(Some(1e300));
        pacer.wait(Some(f64::INFINITY));
        pacer.wait(Some(f64::NAN));
        for fps in [1e-30, 0.0, -1.0, f64::NAN, f64::INFINITY, 1e9] {
            let err = Pacer::check(Pacing::Fixed { fps }).unwrap_err();
            assert!(err.contains("not from 0.01 to 1000"), "{fps}: {err}");
        }
        assert!(Pacer::check(Pacing::Fixed { fps: 30.0 }).is_ok());
    }
}

/// Where a replay is in its list of files, and what happens at the end of it.
#[derive(Debug, Clone)]
pub(crate) struct Playhead {
    next: usize,
    len: usize,
    looping: bool,
}

impl Playhead {
    pub(crate) fn new(len: usize, looping: bool) -> Self {
        Self {
            next: 0,
            len,
            looping,
        }
    }

    /// The index of the next file to play. At the end of the list: a new pass (restarting
    /// `pacer`'s recorded clock) when looping, else [`SourceError::EndOfStream`] for `name`.
    pub(crate) fn advance(&mut self, pacer: &mut Pacer, name: &str) -> Result<usize, SourceError> {
        if self.next >= self.len {
            if !self.looping || self.len == 0 {
                return Err(SourceError::EndOfStream {
                    device: name.to_owned(),
                });
            }
            self.next = 0;
            pacer.restart();
        }
        self.next += 1;
        Ok(self.next - 1)
    }
}
