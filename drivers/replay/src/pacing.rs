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
            Pacing::Fixed { fps } if !(fps.is_finite() && fps > 0.0) => Err(format!(
                "a fixed rate of {fps} frames per second is not a positive rate"
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
                    .map(|p| last + p)
            }),
            (Pacing::Recorded, Some(t)) => match self.anchor {
                None => {
                    self.anchor = Some((now, t));
                    None
                }
                // Timestamps that go backwards mean "now", not a panic.
                Some((start, t0)) => Duration::try_from_secs_f64(t - t0).ok().map(|d| start + d),
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
        let again = Instant::now();
        pacer.wait(Some(100.0));
        assert!(again.elapsed() < Duration::from_millis(20));
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
