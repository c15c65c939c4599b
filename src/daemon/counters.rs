//! The daemon's counters and latency windows: written by the pipeline threads, read into the
//! Stats message and the periodic log line.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use tacmesh_protocol::{StageLatency, Stats};
use tacmesh_publish::PublisherCounters;

use crate::frame_ring::RingStats;
use crate::latency::LatencyWindow;

/// The pipeline stages whose latency is reported, in pipeline order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Deproject,
    Segment,
    Integrate,
    /// From the capture of the newest frame in a mesh job to the start of its meshing run:
    /// the frame path before the job was made and the wait for a free mesher. With the mesh,
    /// simplify and publish stages it makes up how old a new mesh is when it goes out.
    MeshWait,
    Mesh,
    Simplify,
    Publish,
    /// A collision body (proxy, convex parts, mass), after its shape was published.
    Body,
}

impl Stage {
    pub const ALL: [Stage; 8] = [
        Stage::Deproject,
        Stage::Segment,
        Stage::Integrate,
        Stage::MeshWait,
        Stage::Mesh,
        Stage::Simplify,
        Stage::Publish,
        Stage::Body,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Deproject => "deproject",
            Stage::Segment => "segment",
            Stage::Integrate => "integrate",
            Stage::MeshWait => "mesh wait",
            Stage::Mesh => "mesh",
            Stage::Simplify => "simplify",
            Stage::Publish => "publish",
            Stage::Body => "body",
        }
    }
}

/// Samples kept per latency window: a minute and a half of frames at 30 fps.
const WINDOW: usize = 2048;

struct Windows {
    stages: Vec<LatencyWindow>,
    frame_to_publish: LatencyWindow,
}

/// Counters shared by the daemon's threads. Frame in/dropped counts live in the ring and
/// subscriber counts in the publisher; [`Counters::stats`] joins them.
pub struct Counters {
    pub invalid_pixels: AtomicU64,
    pub frames_processed: AtomicU64,
    pub source_errors: AtomicU64,
    pub source_restarts: AtomicU64,
    pub malformed_frames: AtomicU64,
    pub objects_tracked: AtomicU64,
    pub meshing_runs: AtomicU64,
    pub meshing_failures: AtomicU64,
    pub pose_updates: AtomicU64,
    /// Collision bodies made, and shapes that got none (see `bodies`).
    pub bodies_made: AtomicU64,
    pub body_failures: AtomicU64,
    /// Solids the decomposition found no convex parts of (those bodies fell back to one hull).
    pub decompositions_failed: AtomicU64,
    /// Objects created and removed by the tracker, whether confirmed or not: on a static
    /// scene both should stop once it has been seen (churn, see [`Counters::births_per_s`]).
    pub objects_born: AtomicU64,
    pub objects_removed: AtomicU64,
    windows: Mutex<Windows>,
    /// When the births of the last [`BIRTH_WINDOW`] happened.
    recent_births: Mutex<std::collections::VecDeque<Instant>>,
}

/// Births per second are counted over this window.
pub const BIRTH_WINDOW: Duration = Duration::from_secs(10);

impl Default for Counters {
    fn default() -> Self {
        Self {
            invalid_pixels: AtomicU64::new(0),
            frames_processed: AtomicU64::new(0),
            source_errors: AtomicU64::new(0),
            source_restarts: AtomicU64::new(0),
            malformed_frames: AtomicU64::new(0),
            objects_tracked: AtomicU64::new(0),
            meshing_runs: AtomicU64::new(0),
            meshing_failures: AtomicU64::new(0),
            pose_updates: AtomicU64::new(0),
            bodies_made: AtomicU64::new(0),
            body_failures: AtomicU64::new(0),
            decompositions_failed: AtomicU64::new(0),
            objects_born: AtomicU64::new(0),
            objects_removed: AtomicU64::new(0),
            recent_births: Mutex::new(std::collections::VecDeque::new()),
            windows: Mutex::new(Windows {
                stages: Stage::ALL
                    .iter()
                    .map(|_| LatencyWindow::new(WINDOW))
                    .collect(),
                frame_to_publish: LatencyWindow::new(WINDOW),
            }),
        }
    }
}

/// One snapshot of everything, for the log line and the Stats message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CounterSnapshot {
    pub ring: RingStats,
    pub publisher: PublisherCounters,
    pub frames_processed: u64,
    pub invalid_pixels: u64,
    pub source_errors: u64,
    pub source_restarts: u64,
    pub malformed_frames: u64,
    pub objects_tracked: u64,
    pub meshing_runs: u64,
    pub meshing_failures: u64,
    pub pose_updates: u64,
    pub bodies_made: u64,
    pub body_failures: u64,
    pub decompositions_failed: u64,
    pub objects_born: u64,
    pub objects_removed: u64,
    /// Object births per second over the last [`BIRTH_WINDOW`] (or since start, if shorter).
    pub births_per_s: f64,
    /// Log lines that standard error did not take (a log reader or journald went away).
    pub log_lines_dropped: u64,
    /// `(stage name, p50 ms, p99 ms)` in pipeline order.
    pub stages: Vec<(&'static str, f32, f32)>,
    pub frame_to_publish_p50_ms: f32,
    pub frame_to_publish_p99_ms: f32,
}

impl Counters {
    /// Adds `n` to `counter`; returns its value before.
    pub fn add(counter: &AtomicU64, n: u64) -> u64 {
        counter.fetch_add(n, Ordering::Relaxed)
    }

    pub fn record(&self, stage: Stage, elapsed: Duration) {
        let index = Stage::ALL.iter().position(|&s| s == stage).unwrap_or(0);
        crate::lock(&self.windows).stages[index].record_ms(elapsed.as_secs_f32() * 1e3);
    }

    /// Counts `n` objects born now.
    pub fn record_births(&self, n: usize) {
        if n == 0 {
            return;
        }
        Self::add(&self.objects_born, n as u64);
        let now = Instant::now();
        let mut recent = crate::lock(&self.recent_births);
        recent.extend(std::iter::repeat_n(now, n));
        Self::expire_births(&mut recent, now);
    }

    fn expire_births(recent: &mut std::collections::VecDeque<Instant>, now: Instant) {
        while recent
            .front()
            .is_some_and(|&t| now.duration_since(t) > BIRTH_WINDOW)
        {
            recent.pop_front();
        }
    }

    /// Births per second over the last [`BIRTH_WINDOW`], or over `uptime` if that is shorter
    /// (at least one second, so that the first frame's objects do not read as a storm).
    pub fn births_per_s(&self, uptime: Duration) -> f64 {
        let now = Instant::now();
        let mut recent = crate::lock(&self.recent_births);
        Self::expire_births(&mut recent, now);
        let window = uptime.clamp(Duration::from_secs(1), BIRTH_WINDOW);
        recent.len() as f64 / window.as_secs_f64()
    }

    pub fn record_frame_to_publish(&self, latency: Duration) {
        crate::lock(&self.windows)
            .frame_to_publish
            .record_ms(latency.as_secs_f32() * 1e3);
    }

    pub fn snapshot(
        &self,
        ring: RingStats,
        publisher: PublisherCounters,
        uptime: Duration,
    ) -> CounterSnapshot {
        let load = |c: &AtomicU64| c.load(Ordering::Relaxed);
        let births_per_s = self.births_per_s(uptime);
        let windows = crate::lock(&self.windows);
        let stages = Stage::ALL
            .iter()
            .zip(&windows.stages)
            .map(|(stage, window)| {
                let (p50, p99) = window.p50_p99_ms();
                (stage.name(), p50, p99)
            })
            .collect();
        let (frame_to_publish_p50_ms, frame_to_publish_p99_ms) =
            windows.frame_to_publish.p50_p99_ms();
        CounterSnapshot {
            ring,
            publisher,
            frames_processed: load(&self.frames_processed),
            invalid_pixels: load(&self.invalid_pixels),
            source_errors: load(&self.source_errors),
            source_restarts: load(&self.source_restarts),
            malformed_frames: load(&self.malformed_frames),
            objects_tracked: load(&self.objects_tracked),
            meshing_runs: load(&self.meshing_runs),
            meshing_failures: load(&self.meshing_failures),
            pose_updates: load(&self.pose_updates),
            bodies_made: load(&self.bodies_made),
            body_failures: load(&self.body_failures),
            decompositions_failed: load(&self.decompositions_failed),
            objects_born: load(&self.objects_born),
            objects_removed: load(&self.objects_removed),
            births_per_s,
            log_lines_dropped: crate::log_sink::dropped_lines(),
            stages,
            frame_to_publish_p50_ms,
            frame_to_publish_p99_ms,
        }
    }
}

impl CounterSnapshot {
    /// The wire form of these counters, taken at `monotonic_ns` (and the matching wall-clock
    /// time).
    pub fn to_stats(&self, monotonic_ns: u64, realtime_ns: u64) -> Stats {
        Stats {
            monotonic_ns,
            realtime_ns,
            frames_in: self.ring.pushed,
            frames_dropped: self.ring.dropped,
            invalid_pixels: self.invalid_pixels,
            malformed_frames: self.malformed_frames,
            source_errors: self.source_errors,
            source_restarts: self.source_restarts,
            objects_tracked: self.objects_tracked,
            objects_born: self.objects_born,
            objects_removed: self.objects_removed,
            meshing_runs: self.meshing_runs,
            meshing_failures: self.meshing_failures,
            shapes_published: self.publisher.shapes_published,
            poses_published: self.publisher.poses_published,
            bytes_sent: self.publisher.bytes_sent,
            clients_connected: self.publisher.clients_connected as u64,
            clients_dropped: self.publisher.clients_dropped,
            clients_refused: self.publisher.clients_refused,
            latency_window: WINDOW as u32,
            stage_latencies: self
                .stages
                .iter()
                .map(|&(stage, p50_ms, p99_ms)| StageLatency {
                    stage: stage.into(),
                    p50_ms,
                    p99_ms,
                })
                .collect(),
            frame_to_publish_p50_ms: self.frame_to_publish_p50_ms,
            frame_to_publish_p99_ms: self.frame_to_publish_p99_ms,
        }
    }

    /// One log line of the counters.
    pub fn log_line(&self) -> String {
        let stages: Vec<String> = self
            .stages
            .iter()
            .map(|(name, p50, p99)| format!("{name} {p50:.1}/{p99:.1}"))
            .collect();
        format!(
            "frames in {} processed {} dropped {}, invalid pixels {}, source errors {} (restarts {}), malformed frames {}, \
             objects {} (born {}, {:.2}/s; removed {}), meshing runs {} (failed {}), pose updates {}, bodies made {} (failed {}, decompositions fell back {}), shapes published {}, bodies published {}, poses published {}, \
             bytes sent {}, subscribers {} (dropped {}, refused {}), subscribes held back {}, log lines lost {}; frame-to-publish p50/p99 {:.1}/{:.1} ms; \
             stage p50/p99 ms: {}",
            self.ring.pushed,
            self.frames_processed,
            self.ring.dropped,
            self.invalid_pixels,
            self.source_errors,
            self.source_restarts,
            self.malformed_frames,
            self.objects_tracked,
            self.objects_born,
            self.births_per_s,
            self.objects_removed,
            self.meshing_runs,
            self.meshing_failures,
            self.pose_updates,
            self.bodies_made,
            self.body_failures,
            self.decompositions_failed,
            self.publisher.shapes_published,
            self.publisher.bodies_published,
            self.publisher.poses_published,
            self.publisher.bytes_sent,
            self.publisher.clients_connected,
            self.publisher.clients_dropped,
            self.publisher.clients_refused,
            self.publisher.subscribes_throttled,
            self.log_lines_dropped,
            self.frame_to_publish_p50_ms,
            self.frame_to_publish_p99_ms,
            stages.join(", ")
        )
    }
}
