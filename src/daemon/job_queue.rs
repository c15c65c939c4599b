//! A queue of jobs keyed by object that keeps only each object's newest job: a newer job
//! replaces the waiting one (it holds everything the older one did) and keeps its place in
//! line, so the queue is bounded by the number of objects. The mesher's and the bodies
//! worker's queues.

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};

/// A job about one object.
pub trait ObjectJob {
    fn object_id(&self) -> u64;
}

struct Queue<J> {
    /// Per object: the order in which it was first queued, and its newest job.
    jobs: BTreeMap<u64, (u64, J)>,
    next_seq: u64,
    closed: bool,
}

/// Jobs waiting for a worker, at most one per object.
pub struct LatestJobs<J> {
    queue: Mutex<Queue<J>>,
    ready: Condvar,
}

impl<J> Default for LatestJobs<J> {
    fn default() -> Self {
        Self {
            queue: Mutex::new(Queue {
                jobs: BTreeMap::new(),
                next_seq: 0,
                closed: false,
            }),
            ready: Condvar::new(),
        }
    }
}

impl<J: ObjectJob> LatestJobs<J> {
    /// Queues a job, replacing a waiting job of the same object.
    pub fn submit(&self, job: J) {
        let mut queue = crate::lock(&self.queue);
        let seq = queue.next_seq;
        queue.next_seq += 1;
        let id = job.object_id();
        let place = queue.jobs.get(&id).map_or(seq, |(place, _)| *place);
        queue.jobs.insert(id, (place, job));
        self.ready.notify_one();
    }

    /// Drops the waiting job of a removed object.
    pub fn cancel(&self, object_id: u64) {
        crate::lock(&self.queue).jobs.remove(&object_id);
    }

    /// Jobs waiting now.
    pub fn len(&self) -> usize {
        crate::lock(&self.queue).jobs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// No more jobs: a worker finishes the one in hand and stops; waiting jobs are dropped.
    pub fn close(&self) {
        crate::lock(&self.queue).closed = true;
        self.ready.notify_all();
    }

    /// The job of the object that has waited longest, or `None` once closed.
    pub fn take(&self) -> Option<J> {
        self.take_first_by(|_| ())
    }

    /// The job that comes first by `urgency` (lower first), then by how long its object has
    /// waited; `None` once closed. Waits while the queue is empty.
    pub fn take_first_by<K: Ord>(&self, urgency: impl Fn(&J) -> K) -> Option<J> {
        let mut queue = crate::lock(&self.queue);
        loop {
            if queue.closed {
                return None;
            }
            let oldest = queue
                .jobs
                .iter()
                .min_by_key(|(_, (place, job))| (urgency(job), *place))
                .map(|(&id, _)| id);
            if let Some((_, job)) = oldest.and_then(|id| queue.jobs.remove(&id)) {
                return Some(job);
            }
            queue = self
                .ready
                .wait(queue)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }
}
