//! `tacmesh run`: the daemon. A source thread reads the sensor into a drop-oldest ring; the
//! perception thread segments, tracks and fuses each frame; the mesher thread re-meshes dirty
//! objects; the publisher serves subscribers. The calling thread sends stats and waits for
//! the stop signal.
//!
//! ```text
//! source ─► FrameRing ─► perception (deproject, segment, track + fuse) ─► MeshQueue ─► mesher
//!                                     │ planes, moves, removals              │ new meshes
//!                                     └──────────────► Board ◄───────────────┘
//!                                                       │ versions
//!                                                       ▼
//!                                                   Publisher ─► subscribers
//! ```
//!
//! The calling thread also tells systemd how the daemon is doing and feeds its watchdog from
//! the pipeline's liveness ([`notify`]).
//!
//! Entry points: [`Daemon::start`], [`Daemon::run_until_stopped`], [`StopSignal`].

pub mod access;
mod board;
mod bodies;
pub mod config;
mod counters;
mod job_queue;
mod mesher;
pub mod notify;
mod perception;
pub mod planes;
pub mod sensor;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tacmesh_publish::{PublishError, Publisher, PublisherConfig};
use tacmesh_source::{DepthSource, SourceError};

pub use crate::socket_dir::default_socket_path;
/// The daemon's own body making, for tests and benchmarks that judge what it publishes.
pub use bodies::{make_body, BodyError, BodyJob};
pub use config::{ConfigError, DaemonConfig};
pub use counters::CounterSnapshot;
pub use mesher::MAX_FUSED_POINTS;
pub use perception::track_config;
/// What the daemon segments of a frame, and with which settings (`tacmesh capture --segments`).
pub use perception::{points_in_workspace, segment_config};
pub use sensor::{SensorError, SensorSpec};

use crate::frame_ring::FrameRing;
use board::Board;
use bodies::BodyQueue;
use counters::Counters;
use mesher::MeshQueue;
use notify::{Heartbeat, Heartbeats, Notifier, SystemdFeed};
use perception::Perception;

/// Why the daemon could not start.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Boxed: backend errors carry paths and sources, and this is the cold path.
    #[error(transparent)]
    Sensor(#[from] Box<SensorError>),
    #[error(transparent)]
    Publish(#[from] PublishError),
    #[error(transparent)]
    SocketDir(#[from] crate::socket_dir::SocketDirError),
    #[cfg(feature = "zenoh")]
    #[error("config [zenoh]: {0}")]
    Zenoh(#[from] tacmesh_zenoh::ZenohError),
    /// Not `#[from]`: that would make the message's `{0}` a source too, printed twice by an
    /// error chain printer.
    #[error("config [track]: {0}")]
    Track(tacmesh_track::TrackError),
    #[error("cannot start the {name} thread: {cause}")]
    Spawn {
        name: &'static str,
        cause: std::io::Error,
    },
}

/// A stop request that any thread (or a signal handler) can raise and the daemon waits on.
#[derive(Debug, Clone, Default)]
pub struct StopSignal {
    inner: Arc<(Mutex<bool>, Condvar)>,
}

impl StopSignal {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn request(&self) {
        let (flag, changed) = &*self.inner;
        *crate::lock(flag) = true;
        changed.notify_all();
    }

    pub fn is_requested(&self) -> bool {
        *crate::lock(&self.inner.0)
    }

    /// Waits up to `timeout`; true when a stop was requested.
    pub fn wait_timeout(&self, timeout: Duration) -> bool {
        let (flag, changed) = &*self.inner;
        // A timeout past what the clock can hold waits until a stop.
        let deadline = Instant::now().checked_add(timeout);
        let mut requested = crate::lock(flag);
        while !*requested {
            let left = deadline.map_or(timeout, |d| d.saturating_duration_since(Instant::now()));
            if left.is_zero() {
                break;
            }
            requested = changed
                .wait_timeout(requested, left)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        *requested
    }
}

/// The allow lists for a log line.
fn describe_peers(peers: Option<&tacmesh_publish::AllowedPeers>) -> String {
    match peers {
        None => "anyone the socket's mode lets connect".to_owned(),
        Some(peers) => format!(
            "users {:?}, primary groups {:?}, group members {:?}",
            peers.uids, peers.gids, peers.member_uids
        ),
    }
}

/// What the daemon's threads share.
pub(crate) struct Shared {
    config: DaemonConfig,
    ring: FrameRing<tacmesh_source::Observation>,
    counters: Counters,
    board: Mutex<Board>,
    mesh_queue: MeshQueue,
    /// Published shapes waiting for their collision bodies ([`bodies`]).
    body_queue: BodyQueue,
    publisher: Publisher,
    source_stop: AtomicBool,
    /// Sources whose stream ended (a recording played once). When every configured sensor's
    /// has, the perception thread meshes what was held back ([`perception`]).
    streams_ended: AtomicUsize,
    /// Set by the perception thread once it has handed out those last jobs.
    end_of_stream_flushed: AtomicBool,
}

impl Shared {
    /// Whether every sensor's stream has ended, so that no frame will come again.
    fn every_stream_ended(&self) -> bool {
        self.streams_ended.load(Ordering::Acquire) >= self.config.sensor.len()
    }
}

/// A running daemon.
pub struct Daemon {
    shared: Arc<Shared>,
    sources: Vec<JoinHandle<()>>,
    perception: Option<JoinHandle<()>>,
    meshers: Vec<JoinHandle<()>>,
    bodies: Option<JoinHandle<()>>,
    started: Instant,
    /// The source and mesher threads' heartbeats, for the watchdog.
    heartbeats: Heartbeats,
    /// READY=1, STATUS=, WATCHDOG=1 and STOPPING=1 to systemd (a no-op without it).
    systemd: SystemdFeed,
}

/// How often the allow lists are resolved again (group membership changes without a restart:
/// a user removed from an allowed group loses access within this time).
const ACCESS_REFRESH: Duration = Duration::from_secs(10);

impl Daemon {
    /// Opens the sensor, binds the socket and starts the threads. Fails before starting
    /// anything on a bad config, a sensor that cannot be opened or a socket that cannot be
    /// claimed.
    pub fn start(config: DaemonConfig) -> Result<Daemon, DaemonError> {
        config.validate()?;
        let objects = tacmesh_track::ObjectMap::new(perception::track_config(&config))
            .map_err(DaemonError::Track)?;
        // Every sensor is opened before anything starts, so that a wrong spec, a missing file or
        // a backend not built fails the start. A device that is not there (yet) does not: the
        // daemon serves without it and its supervisor keeps trying to open it, with backoff.
        let mut sensors = Vec::with_capacity(config.sensor.len());
        for section in &config.sensor {
            let spec = SensorSpec::parse(&section.spec).map_err(Box::new)?;
            let source = match spec.open(section) {
                Ok(source) => Some(source),
                Err(err) if err.is_device_absent() => {
                    tracing::warn!(
                        "{}: {err}; serving without it and trying again with backoff",
                        section.spec
                    );
                    None
                }
                Err(err) => return Err(Box::new(err).into()),
            };
            sensors.push((spec, section.clone(), source));
        }
        // The default socket without a runtime directory is in a directory of the user's own,
        // made here and checked, so that no other user can have bound the path first.
        if config.socket.path.is_none() {
            if let Some(dir) = crate::socket_dir::private_fallback_dir() {
                crate::socket_dir::ensure_private_dir(&dir)?;
            }
        }
        let mut publisher_config = PublisherConfig::new(config.socket_path());
        publisher_config.mode = config.socket_mode()?;
        (publisher_config.group, publisher_config.allowed_peers) = config.socket_access()?;
        publisher_config.max_subscribers = config.socket.max_subscribers;
        publisher_config.max_subscribers_per_user = config.socket.max_subscribers_per_user;
        let publisher = Publisher::bind(publisher_config)?;
        #[cfg(feature = "zenoh")]
        if let Some(section) = &config.zenoh {
            let mirror = tacmesh_zenoh::ZenohMirror::start(&section.settings()?)?;
            publisher.add_mirror(mirror);
        }
        for (_, _, source) in &sensors {
            if let Some(source) = source {
                tracing::info!("reading {}", source.name());
            }
        }
        let shared = Arc::new(Shared {
            ring: FrameRing::new(config.pipeline.ring_capacity),
            config,
            counters: Counters::default(),
            board: Mutex::new(Board::default()),
            mesh_queue: MeshQueue::default(),
            body_queue: BodyQueue::default(),
            publisher,
            source_stop: AtomicBool::new(false),
            streams_ended: AtomicUsize::new(0),
            end_of_stream_flushed: AtomicBool::new(false),
        });
        let mut daemon = Daemon {
            shared: Arc::clone(&shared),
            sources: Vec::new(),
            perception: None,
            meshers: Vec::new(),
            bodies: None,
            started: Instant::now(),
            heartbeats: Heartbeats::default(),
            systemd: SystemdFeed::new(Notifier::from_env(), Instant::now()),
        };
        let spawn = |name: &'static str, body: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(body)
                .map_err(|cause| DaemonError::Spawn { name, cause })
        };
        for worker in 0..shared.config.mesh.workers {
            let s = Arc::clone(&shared);
            // Each worker is watched on its own: one stuck in a run stops the watchdog pings
            // even while the others keep meshing.
            let heartbeat = daemon
                .heartbeats
                .register_worker(&format!("mesher {worker}"), notify::MESH_RUN_LIMIT);
            daemon.meshers.push(spawn(
                "mesher",
                Box::new(move || mesher::run_mesher(&s, &heartbeat)),
            )?);
        }
        let s = Arc::clone(&shared);
        let heartbeat = daemon
            .heartbeats
            .register_worker("bodies", notify::MESH_RUN_LIMIT);
        daemon.bodies = Some(spawn(
            "bodies",
            Box::new(move || bodies::run_bodies(&s, &heartbeat)),
        )?);
        let s = Arc::clone(&shared);
        daemon.perception = Some(spawn(
            "perception",
            Box::new(move || Perception::new(objects).run(&s)),
        )?);
        for (spec, section, source) in sensors {
            let s = Arc::clone(&shared);
            let heartbeat = daemon
                .heartbeats
                .register(&format!("source ({})", section.spec));
            daemon.sources.push(spawn(
                "source",
                Box::new(move || read_source(&s, &spec, &section, source, heartbeat)),
            )?);
        }
        Ok(daemon)
    }

    /// The socket the daemon serves.
    pub fn socket_path(&self) -> &std::path::Path {
        self.shared.publisher.socket_path()
    }

    /// The counters now.
    pub fn counters(&self) -> CounterSnapshot {
        self.shared.counters.snapshot(
            self.shared.ring.stats(),
            self.shared.publisher.counters(),
            self.started.elapsed(),
        )
    }

    /// Sends stats and logs counters periodically until `stop` is requested, then shuts down.
    /// Tells systemd READY=1 once a source thread runs (the socket is bound by then), then
    /// keeps STATUS= fresh and feeds the watchdog while the pipeline is alive.
    pub fn run_until_stopped(mut self, stop: &StopSignal) -> CounterSnapshot {
        let stats_every = self.shared.config.stats_publish_interval();
        let log_every = self.shared.config.stats_log_interval();
        let mut next_log = Instant::now() + log_every;
        let mut said_ended = false;
        // The sensors opened and the socket was bound in `start`; ready once a source thread
        // has begun reading (it beats first thing, so this is a moment).
        while !self.heartbeats.any_beaten() && !self.sources.iter().all(|s| s.is_finished()) {
            if stop.wait_timeout(Duration::from_millis(5)) {
                return self.shutdown();
            }
        }
        self.systemd.notifier().ready(&format!(
            "serving meshes on {}",
            self.shared.publisher.socket_path().display()
        ));
        let mut next_stats = Instant::now() + stats_every;
        let mut next_access = Instant::now() + ACCESS_REFRESH;
        loop {
            let wake = next_stats.min(self.systemd.next_due()).min(next_access);
            if stop.wait_timeout(wake.saturating_duration_since(Instant::now())) {
                break;
            }
            let now = Instant::now();
            if now >= self.systemd.next_due() {
                let snapshot = self.counters();
                let mesh_jobs_waiting = self.shared.mesh_queue.len();
                self.systemd
                    .tick(now, &self.heartbeats, &snapshot, mesh_jobs_waiting);
            }
            if now >= next_access {
                next_access = now + ACCESS_REFRESH;
                self.refresh_access();
            }
            if now < next_stats {
                continue;
            }
            next_stats = now + stats_every;
            let snapshot = self.counters();
            let (monotonic_ns, realtime_ns) = tacmesh_source::now_on_both_clocks_ns();
            let stats = snapshot.to_stats(monotonic_ns, realtime_ns);
            if let Err(err) = self.shared.publisher.stats(stats) {
                tracing::warn!("stats not sent: {err}");
            }
            if Instant::now() >= next_log {
                tracing::info!("{}", snapshot.log_line());
                next_log += log_every;
            }
            // Recordings end; the daemon keeps serving their last meshes until it is stopped.
            if !said_ended
                && self.sources.iter().all(|s| s.is_finished())
                && self.shared.end_of_stream_flushed.load(Ordering::Acquire)
                && self.shared.ring.stats().queued == 0
                && self.shared.mesh_queue.is_empty()
            {
                tracing::info!(
                    "the sensors have no more frames; serving the last meshes until stopped"
                );
                said_ended = true;
            }
        }
        self.shutdown()
    }

    /// Resolves the allow lists again and hands changes to the publisher, which drops the
    /// subscribers no longer admitted. A name that no longer resolves keeps the lists as they
    /// were, with a warning (a passing NSS failure must not lock everyone out).
    fn refresh_access(&self) {
        let socket = &self.shared.config.socket;
        if socket.allow_users.is_none() && socket.allow_groups.is_none() {
            return;
        }
        match self.shared.config.socket_access() {
            Ok((_, peers)) => {
                let described = describe_peers(peers.as_ref());
                if let Some(dropped) = self.shared.publisher.set_allowed_peers(peers) {
                    tracing::info!(
                        "socket.allow_users / allow_groups read again: {described} ({dropped} \
                         subscribers no longer admitted were dropped)"
                    );
                }
            }
            Err(err) => tracing::warn!("{err}; keeping who may subscribe as it was"),
        }
    }

    /// Stops the source, finishes the frame and the mesh in flight, says goodbye to
    /// subscribers and removes the socket.
    pub fn shutdown(mut self) -> CounterSnapshot {
        let begun = Instant::now();
        self.systemd.notifier().stopping();
        tracing::info!("stopping");
        self.shared.source_stop.store(true, Ordering::Relaxed);
        self.shared.ring.close();
        if let Some(perception) = self.perception.take() {
            join(perception, "perception");
        }
        self.shared.mesh_queue.close();
        for mesher in self.meshers.drain(..) {
            join(mesher, "mesher");
        }
        self.shared.body_queue.close();
        if let Some(bodies) = self.bodies.take() {
            join(bodies, "bodies");
        }
        // A source blocked in a device read may not return soon; it holds only its own
        // handle and a reference to the shared state, so it is left to end with the process.
        let deadline = Instant::now() + Duration::from_millis(500);
        for source in self.sources.drain(..) {
            while !source.is_finished() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            if source.is_finished() {
                join(source, "source");
            } else {
                tracing::warn!("a sensor did not stop within 0.5 s; leaving it behind");
            }
        }
        let snapshot = self.counters();
        tracing::info!("{}", snapshot.log_line());
        // The publisher lives in the shared state; a left-behind source thread may still hold
        // a reference, so shut the publisher down through the shared reference.
        self.shared.publisher.shutdown("tacmesh is stopping");
        tracing::info!(
            "stopped in {:.0} ms after running {:.1} s",
            begun.elapsed().as_secs_f64() * 1e3,
            self.started.elapsed().as_secs_f64()
        );
        snapshot
    }
}

fn join(handle: JoinHandle<()>, name: &str) {
    if handle.join().is_err() {
        tracing::error!("the {name} thread panicked");
    }
}

/// A source thread: reads observations into the ring until stopped, placing each with the
/// sensor's configured pose. It supervises its source: malformed frames are counted and skipped;
/// a device that disconnects or goes missing is reopened with backoff (100 ms doubling to 5 s),
/// counted as a restart, while the rest of the daemon keeps serving the last meshes; a
/// recording at its end stops the thread. Errors are logged once per burst.
fn read_source(
    shared: &Shared,
    spec: &SensorSpec,
    section: &config::SensorSection,
    source: Option<Box<dyn DepthSource>>,
    heartbeat: Heartbeat,
) {
    let supervised = Supervised {
        label: section.spec.clone(),
        recording: spec.is_recording(),
        world_from_rig: section
            .pose
            .as_ref()
            .map(config::PoseSection::world_from_sensor),
        reopen: Box::new(|| spec.open(section)),
        first_backoff: Duration::from_millis(100),
        heartbeat,
    };
    supervise(shared, &supervised, source);
    // Ended normally (stopped, or a recording at its end): no longer watched. A panic skips
    // this, and the silent heartbeat stops the watchdog pings.
    supervised.heartbeat.retire();
}

/// How one sensor is supervised.
struct Supervised<'a> {
    /// The spec, for log lines.
    label: String,
    /// Recordings wait for room in the ring instead of dropping frames.
    recording: bool,
    world_from_rig: Option<glam::Affine3A>,
    reopen: Box<dyn Fn() -> Result<Box<dyn DepthSource>, SensorError> + Send + 'a>,
    /// The first wait before reopening; it doubles up to 5 s.
    first_backoff: Duration,
    /// Beaten on every turn of the supervisor loop and while it waits (to reopen a lost device,
    /// or for room in the ring): only a thread stuck in one call falls silent (see [`notify`]).
    heartbeat: Heartbeat,
}

/// Reads `source` (or, if it is `None` because the device was absent at start, first opens it
/// with backoff) into the ring until stopped or the recording ends.
fn supervise(shared: &Shared, sensor: &Supervised<'_>, source: Option<Box<dyn DepthSource>>) {
    const MAX_BACKOFF: Duration = Duration::from_secs(5);
    let first_backoff = sensor.first_backoff;
    let rig = sensor.world_from_rig;
    let mut backoff = first_backoff;
    let mut in_burst = false;
    let stopped = || shared.source_stop.load(Ordering::Relaxed);
    let beat = || sensor.heartbeat.beat();
    // Sleeps up to `pause`, waking early on stop; true when stopped. Beats while it waits: a
    // device being reopened with backoff is not a stall.
    let pause = |pause: Duration| {
        let until = Instant::now() + pause;
        while Instant::now() < until {
            beat();
            if stopped() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20).min(pause));
        }
        stopped()
    };
    // Waits, reopens, and again with a doubled wait, until the sensor opens; None once stopped.
    // Failed attempts are logged at the 1st, 2nd, 4th, 8th… so that a sensor left unplugged
    // for hours does not fill the journal (at most every 5 s, that is about 12 a minute).
    let reopen = |backoff: &mut Duration| -> Option<Box<dyn DepthSource>> {
        let mut attempts = 0u64;
        loop {
            if pause(*backoff) {
                return None;
            }
            *backoff = (*backoff * 2).min(MAX_BACKOFF);
            Counters::add(&shared.counters.source_restarts, 1);
            attempts += 1;
            match (sensor.reopen)() {
                Ok(reopened) => {
                    tracing::info!("{}: reopened", reopened.name());
                    return Some(reopened);
                }
                Err(err) if attempts.is_power_of_two() => tracing::warn!(
                    "{}: {err}; retrying every {backoff:?} ({attempts} attempts so far, logged \
                     at powers of two)",
                    sensor.label
                ),
                Err(err) => tracing::debug!("{}: {err}; retrying in {backoff:?}", sensor.label),
            }
        }
    };
    let mut source = match source {
        Some(source) => source,
        None => match reopen(&mut backoff) {
            Some(source) => source,
            None => return,
        },
    };
    while !stopped() {
        beat();
        match source.next_observation() {
            Ok(mut observation) => {
                if in_burst {
                    tracing::info!("{}: delivering again", source.name());
                }
                in_burst = false;
                backoff = first_backoff;
                if let Some(rig) = rig {
                    place(&mut observation, rig);
                }
                if sensor.recording {
                    // Waiting for room is not a stall of this thread (a stuck perception
                    // thread shows as its own stall).
                    shared.ring.push_wait(observation, || {
                        beat();
                        stopped()
                    });
                } else {
                    shared.ring.push(observation);
                }
            }
            Err(SourceError::EndOfStream { device }) => {
                tracing::info!("{device} has no more frames");
                // After its last frame is in the ring: the perception thread flushes only
                // once the ring is empty too.
                shared.streams_ended.fetch_add(1, Ordering::AcqRel);
                break;
            }
            Err(err @ SourceError::Malformed { .. }) => {
                Counters::add(&shared.counters.source_errors, 1);
                if !in_burst {
                    tracing::warn!("{}: {err}; skipped (logged once per burst)", source.name());
                }
                in_burst = true;
            }
            Err(err) => {
                Counters::add(&shared.counters.source_errors, 1);
                tracing::warn!("{}: {err}; reopening in {backoff:?}", source.name());
                in_burst = true;
                match reopen(&mut backoff) {
                    Some(reopened) => source = reopened,
                    None => return,
                }
            }
        }
    }
}

/// Puts an observation from a sensor mounted at `world_from_rig` into the world frame.
fn place(observation: &mut tacmesh_source::Observation, world_from_rig: glam::Affine3A) {
    match observation {
        tacmesh_source::Observation::Depth(frame) => {
            frame.world_from_sensor = world_from_rig * frame.world_from_sensor;
        }
        tacmesh_source::Observation::Cloud {
            world_from_sensor, ..
        } => *world_from_sensor = world_from_rig * *world_from_sensor,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;
    use std::sync::atomic::AtomicUsize;
    use tacmesh_source::{Observation, PointCloud};

    /// A source that plays a script, then says it has no more frames.
    struct Scripted(VecDeque<Result<Observation, SourceError>>);

    impl DepthSource for Scripted {
        fn name(&self) -> &str {
            "scripted"
        }
        fn next_observation(&mut self) -> Result<Observation, SourceError> {
            self.0.pop_front().unwrap_or(Err(SourceError::EndOfStream {
                device: "scripted".into(),
            }))
        }
    }

    fn cloud() -> Result<Observation, SourceError> {
        Ok(Observation::Cloud {
            cloud: PointCloud::new(vec![glam::Vec3::ZERO]),
            grid: None,
            world_from_sensor: glam::Affine3A::IDENTITY,
            capture_time: Duration::ZERO,
        })
    }

    pub(super) fn shared(dir: &std::path::Path) -> Shared {
        let config = DaemonConfig::default();
        Shared {
            ring: FrameRing::new(64),
            counters: Counters::default(),
            board: Mutex::new(Board::default()),
            mesh_queue: MeshQueue::default(),
            body_queue: BodyQueue::default(),
            publisher: Publisher::bind(PublisherConfig::new(dir.join("t.sock"))).unwrap(),
            source_stop: AtomicBool::new(false),
            streams_ended: AtomicUsize::new(0),
            end_of_stream_flushed: AtomicBool::new(false),
            config,
        }
    }

    /// Malformed frames are skipped; a disconnect reopens the source (after one failed
    /// attempt, with backoff) and frames flow again; the mount pose is applied; the end of
    /// the stream ends the thread.
    #[test]
    fn supervisor_skips_bad_frames_and_reopens_a_lost_device() {
        let dir = tempfile::tempdir().unwrap();
        let shared = shared(dir.path());
        let attempts = AtomicUsize::new(0);
        let rig = glam::Affine3A::from_translation(glam::Vec3::new(0.0, 0.0, 2.0));
        let sensor = Supervised {
            label: "scripted".into(),
            recording: true,
            world_from_rig: Some(rig),
            reopen: Box::new(|| {
                if attempts.fetch_add(1, Ordering::SeqCst) == 0 {
                    Err(SensorError::Unknown {
                        spec: "still unplugged".into(),
                    })
                } else {
                    Ok(Box::new(Scripted(VecDeque::from([cloud(), cloud()]))))
                }
            }),
            first_backoff: Duration::from_millis(1),
            heartbeat: Heartbeats::default().register("test"),
        };
        let first = Scripted(VecDeque::from([
            cloud(),
            Err(SourceError::Malformed {
                device: "scripted".into(),
                reason: "wrong size".into(),
            }),
            cloud(),
            Err(SourceError::Disconnected {
                device: "scripted".into(),
                reason: "unplugged".into(),
            }),
        ]));
        supervise(&shared, &sensor, Some(Box::new(first)));
        assert_eq!(attempts.load(Ordering::SeqCst), 2);
        let load = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
        assert_eq!(load(&shared.counters.source_errors), 2);
        assert_eq!(load(&shared.counters.source_restarts), 2);
        assert_eq!(shared.ring.stats().pushed, 4);
        assert_eq!(shared.ring.stats().dropped, 0);
        match shared.ring.pop_timeout(Duration::ZERO) {
            crate::frame_ring::Pop::Item(Observation::Cloud {
                world_from_sensor, ..
            }) => assert_eq!(world_from_sensor, rig),
            _ => panic!("a placed cloud"),
        }
        shared.publisher.shutdown("test over");
    }

    /// A sensor that is gone and being reopened with backoff is not a stall: the supervisor
    /// beats its heartbeat while it waits, so the watchdog stays fed.
    #[test]
    fn supervisor_beats_while_waiting_to_reopen() {
        let dir = tempfile::tempdir().unwrap();
        let shared = shared(dir.path());
        let heartbeats = Heartbeats::default();
        let heartbeat = heartbeats.register("source (gone)");
        let sensor = Supervised {
            label: "gone".into(),
            recording: false,
            world_from_rig: None,
            reopen: Box::new(|| {
                Err(SensorError::Unknown {
                    spec: "gone".into(),
                })
            }),
            // Backoff far longer than the staleness limit below.
            first_backoff: Duration::from_secs(2),
            heartbeat: heartbeat.clone(),
        };
        let gone = Scripted(VecDeque::from([Err(SourceError::Disconnected {
            device: "gone".into(),
            reason: "unplugged".into(),
        })]));
        let limit = Duration::from_millis(200);
        std::thread::scope(|scope| {
            let shared = &shared;
            let worker = scope.spawn(move || supervise(shared, &sensor, Some(Box::new(gone))));
            for _ in 0..10 {
                std::thread::sleep(Duration::from_millis(50));
                assert_eq!(heartbeats.stalled(Instant::now(), limit), None);
            }
            shared.source_stop.store(true, Ordering::Relaxed);
            worker.join().unwrap();
        });
        // A thread that stopped beating is stale, unless it retired.
        let later = Instant::now() + limit * 2;
        assert!(heartbeats.stalled(later, limit).is_some());
        heartbeat.retire();
        assert_eq!(heartbeats.stalled(later, limit), None);
        shared.publisher.shutdown("test over");
    }

    /// A stop request ends the thread while it waits to reopen a device.
    #[test]
    fn supervisor_stops_while_waiting_to_reopen() {
        let dir = tempfile::tempdir().unwrap();
        let shared = shared(dir.path());
        let sensor = Supervised {
            label: "gone".into(),
            recording: false,
            world_from_rig: None,
            reopen: Box::new(|| {
                Err(SensorError::Unknown {
                    spec: "gone".into(),
                })
            }),
            first_backoff: Duration::from_millis(10),
            heartbeat: Heartbeats::default().register("test"),
        };
        let gone = Scripted(VecDeque::from([Err(SourceError::DeviceMissing {
            device: "gone".into(),
            hint: "unplugged".into(),
        })]));
        let stop = &shared.source_stop;
        std::thread::scope(|scope| {
            let shared = &shared;
            let worker = scope.spawn(move || supervise(shared, &sensor, Some(Box::new(gone))));
            std::thread::sleep(Duration::from_millis(100));
            stop.store(true, Ordering::Relaxed);
            worker.join().unwrap();
        });
        assert!(shared.counters.source_restarts.load(Ordering::Relaxed) >= 1);
        shared.publisher.shutdown("test over");
    }

    /// A device absent at start is opened once it appears, and its frames flow.
    #[test]
    fn supervisor_opens_a_device_that_was_absent_at_start() {
        let dir = tempfile::tempdir().unwrap();
        let shared = shared(dir.path());
        let attempts = AtomicUsize::new(0);
        let sensor = Supervised {
            label: "late".into(),
            recording: true,
            world_from_rig: None,
            reopen: Box::new(|| {
                // Absent for the first two attempts, then plugged in.
                if attempts.fetch_add(1, Ordering::SeqCst) < 2 {
                    return Err(SensorError::Device(SourceError::DeviceMissing {
                        device: "late".into(),
                        hint: "not plugged in yet".into(),
                    }));
                }
                Ok(Box::new(Scripted(VecDeque::from([cloud(), cloud()]))))
            }),
            first_backoff: Duration::from_millis(5),
            heartbeat: Heartbeats::default().register("test"),
        };
        std::thread::scope(|scope| {
            let shared = &shared;
            let worker = scope.spawn(move || supervise(shared, &sensor, None));
            // The recording pushes without loss: take both frames out of the ring.
            for _ in 0..2 {
                assert!(matches!(
                    shared.ring.pop_timeout(Duration::from_secs(5)),
                    crate::frame_ring::Pop::Item(_)
                ));
            }
            worker.join().unwrap();
        });
        assert_eq!(attempts.load(Ordering::SeqCst), 3);
        assert_eq!(shared.counters.source_restarts.load(Ordering::Relaxed), 3);
        shared.publisher.shutdown("test over");
    }
}
