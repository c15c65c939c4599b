//! Latency percentiles over a sliding window of recent samples, for the daemon's stats
//! (per-stage and frame-to-publish p50/p99).
//!
//! Exact percentiles of the last `capacity` samples: at frame rate a window of a few thousand
//! samples costs a sort of that many floats once per stats period, which is cheaper to get
//! right than a streaming sketch. Entry point: [`LatencyWindow`].

use std::collections::VecDeque;

/// The last `capacity` latencies, in milliseconds.
#[derive(Debug, Clone)]
pub struct LatencyWindow {
    samples_ms: VecDeque<f32>,
    capacity: usize,
}

impl LatencyWindow {
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            samples_ms: VecDeque::with_capacity(capacity),
            capacity,
        }
    }

    /// Records one latency; non-finite or negative values are ignored.
    pub fn record_ms(&mut self, ms: f32) {
        if !(ms.is_finite() && ms >= 0.0) {
            return;
        }
        if self.samples_ms.len() == self.capacity {
            self.samples_ms.pop_front();
        }
        self.samples_ms.push_back(ms);
    }

    pub fn len(&self) -> usize {
        self.samples_ms.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples_ms.is_empty()
    }

    /// The `q`-quantile (0 ≤ q ≤ 1, nearest rank) of the window, or `None` when empty.
    pub fn percentile_ms(&self, q: f32) -> Option<f32> {
        if self.samples_ms.is_empty() {
            return None;
        }
        let mut sorted: Vec<f32> = self.samples_ms.iter().copied().collect();
        sorted.sort_unstable_by(f32::total_cmp);
        let rank = (q.clamp(0.0, 1.0) * sorted.len() as f32).ceil() as usize;
        Some(sorted[rank.saturating_sub(1).min(sorted.len() - 1)])
    }

    /// `(p50, p99)` in milliseconds, zeros when empty.
    pub fn p50_p99_ms(&self) -> (f32, f32) {
        (
            self.percentile_ms(0.5).unwrap_or(0.0),
            self.percentile_ms(0.99).unwrap_or(0.0),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_one_to_a_hundred() {
        let mut w = LatencyWindow::new(1000);
        for i in (1..=100).rev() {
            w.record_ms(i as f32);
        }
        assert_eq!(w.p50_p99_ms(), (50.0, 99.0));
        assert_eq!(w.percentile_ms(1.0), Some(100.0));
        assert_eq!(w.percentile_ms(0.0), Some(1.0));
    }

    #[test]
    fn window_forgets_the_oldest_samples() {
        let mut w = LatencyWindow::new(3);
        for ms in [100.0, 1.0, 2.0, 3.0] {
            w.record_ms(ms);
        }
        assert_eq!(w.len(), 3);
        assert_eq!(w.percentile_ms(1.0), Some(3.0));
    }

    #[test]
    fn empty_window_and_bad_samples() {
        let mut w = LatencyWindow::new(4);
        w.record_ms(f32::NAN);
        w.record_ms(-1.0);
        assert!(w.is_empty());
        assert_eq!(w.p50_p99_ms(), (0.0, 0.0));
    }
}
