//! The bounded queue between sensor backends and the pipeline.
//!
//! When the pipeline falls behind, the oldest frame is dropped (and counted) to make room for
//! the newest: a tactile predictor wants the freshest view, and memory stays bounded whatever
//! the sensor rate. A `Mutex<VecDeque>` with a `Condvar` is all this needs: one lock per frame
//! at 30–90 frames per second is far below contention, and no channel crate offers
//! drop-oldest with a blocking, closable receiver.
//!
//! Entry point: [`FrameRing`].

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

/// What [`FrameRing::pop_timeout`] found.
#[derive(Debug, PartialEq)]
pub enum Pop<T> {
    Item(T),
    TimedOut,
    /// Closed and drained: no item will ever come.
    Closed,
}

/// Counters of a ring, for the daemon's stats.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RingStats {
    pub pushed: u64,
    pub dropped: u64,
    pub queued: usize,
}

struct State<T> {
    items: VecDeque<T>,
    pushed: u64,
    dropped: u64,
    closed: bool,
}

/// A bounded multi-producer queue that drops its oldest item when full.
pub struct FrameRing<T> {
    state: Mutex<State<T>>,
    ready: Condvar,
    /// Signalled when an item leaves, for [`FrameRing::push_wait`].
    space: Condvar,
    capacity: usize,
}

impl<T> FrameRing<T> {
    /// A ring holding at most `capacity` items (at least one).
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            state: Mutex::new(State {
                items: VecDeque::with_capacity(capacity),
                pushed: 0,
                dropped: 0,
                closed: false,
            }),
            ready: Condvar::new(),
            space: Condvar::new(),
            capacity,
        }
    }

    // A panic while holding the lock cannot leave the queue half-updated (every update is a
    // single VecDeque call plus counters), so a poisoned lock is still safe to use.
    fn lock(&self) -> MutexGuard<'_, State<T>> {
        self.state
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Queues `item`; returns the oldest item if it had to be dropped to make room. After
    /// [`close`](Self::close) the item is returned unqueued.
    pub fn push(&self, item: T) -> Option<T> {
        let mut state = self.lock();
        if state.closed {
            return Some(item);
        }
        state.pushed += 1;
        let dropped = if state.items.len() >= self.capacity {
            state.dropped += 1;
            state.items.pop_front()
        } else {
            None
        };
        state.items.push_back(item);
        drop(state);
        self.ready.notify_one();
        dropped
    }

    /// Queues `item` without dropping anything: waits while the ring is full (a recording read
    /// as fast as possible must not lose frames to its own speed). Gives the item back if the
    /// ring is closed meanwhile or `give_up` turns true (checked every 50 ms).
    pub fn push_wait(&self, item: T, give_up: impl Fn() -> bool) -> Option<T> {
        let mut state = self.lock();
        loop {
            if state.closed || give_up() {
                return Some(item);
            }
            if state.items.len() < self.capacity {
                break;
            }
            state = self
                .space
                .wait_timeout(state, Duration::from_millis(50))
                .unwrap_or_else(|poisoned| poisoned.into_inner())
                .0;
        }
        state.pushed += 1;
        state.items.push_back(item);
        drop(state);
        self.ready.notify_one();
        None
    }

    /// The oldest queued item, waiting up to `timeout` for one.
    pub fn pop_timeout(&self, timeout: Duration) -> Pop<T> {
        let state = self.lock();
        let (mut state, _) = self
            .ready
            .wait_timeout_while(state, timeout, |s| s.items.is_empty() && !s.closed)
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        match state.items.pop_front() {
            Some(item) => {
                self.space.notify_one();
                Pop::Item(item)
            }
            None if state.closed => Pop::Closed,
            None => Pop::TimedOut,
        }
    }

    /// Refuses further pushes and wakes every waiting consumer; queued items can still be
    /// popped.
    pub fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_all();
        self.space.notify_all();
    }

    pub fn stats(&self) -> RingStats {
        let state = self.lock();
        RingStats {
            pushed: state.pushed,
            dropped: state.dropped,
            queued: state.items.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn push_wait_waits_for_room_instead_of_dropping() {
        let ring = Arc::new(FrameRing::new(1));
        assert_eq!(ring.push_wait(1, || false), None);
        let producer = {
            let ring = Arc::clone(&ring);
            std::thread::spawn(move || ring.push_wait(2, || false))
        };
        // The producer waits until the consumer takes item 1; nothing is dropped.
        assert_eq!(ring.pop_timeout(Duration::from_secs(5)), Pop::Item(1));
        assert_eq!(producer.join().unwrap(), None);
        assert_eq!(ring.pop_timeout(Duration::from_secs(5)), Pop::Item(2));
        assert_eq!(ring.stats().dropped, 0);
        // A full ring and a give-up condition: the item comes back.
        ring.push(3);
        assert_eq!(ring.push_wait(4, || true), Some(4));
        ring.close();
        assert_eq!(ring.push_wait(5, || false), Some(5));
    }

    #[test]
    fn full_ring_drops_oldest_and_counts_it() {
        let ring = FrameRing::new(2);
        assert_eq!(ring.push(1), None);
        assert_eq!(ring.push(2), None);
        assert_eq!(ring.push(3), Some(1));
        assert_eq!(
            ring.stats(),
            RingStats {
                pushed: 3,
                dropped: 1,
                queued: 2
            }
        );
        assert_eq!(ring.pop_timeout(Duration::ZERO), Pop::Item(2));
        assert_eq!(ring.pop_timeout(Duration::ZERO), Pop::Item(3));
        assert_eq!(ring.pop_timeout(Duration::ZERO), Pop::TimedOut);
    }

    #[test]
    fn close_wakes_a_waiting_consumer_after_the_queue_drains() {
        let ring = Arc::new(FrameRing::new(4));
        ring.push(7);
        let consumer = {
            let ring = Arc::clone(&ring);
            std::thread::spawn(move || {
                let first = ring.pop_timeout(Duration::from_secs(10));
                let second = ring.pop_timeout(Duration::from_secs(10));
                (first, second)
            })
        };
        std::thread::sleep(Duration::from_millis(20));
        ring.close();
        assert_eq!(ring.push(8), Some(8), "a closed ring queues nothing");
        let (first, second) = consumer.join().expect("consumer thread");
        assert_eq!(first, Pop::Item(7));
        assert_eq!(second, Pop::Closed);
    }

    #[test]
    fn concurrent_producers_lose_nothing_uncounted() {
        let ring = Arc::new(FrameRing::new(8));
        let producers: Vec<_> = (0..4)
            .map(|p| {
                let ring = Arc::clone(&ring);
                std::thread::spawn(move || {
                    for i in 0..1000 {
                        ring.push(p * 1000 + i);
                    }
                })
            })
            .collect();
        let mut popped = 0u64;
        let mut finished = false;
        while !finished {
            finished = producers.iter().all(|p| p.is_finished());
            while let Pop::Item(_) = ring.pop_timeout(Duration::from_millis(1)) {
                popped += 1;
            }
        }
        for p in producers {
            p.join().expect("producer thread");
        }
        while let Pop::Item(_) = ring.pop_timeout(Duration::ZERO) {
            popped += 1;
        }
        let stats = ring.stats();
        assert_eq!(stats.pushed, 4000);
        assert_eq!(popped + stats.dropped, 4000);
        assert_eq!(stats.queued, 0);
    }
}
