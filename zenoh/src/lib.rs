//! The daemon's objects over Zenoh, for subscribers on other machines (the operator's
//! simulation across a wide-area link). No protocol of our own: every sample's payload is one
//! frame of `docs/protocol.md`, and Zenoh (ROS 2's `rmw_zenoh` transport, with routers, TLS
//! and access control of its own) carries it.
//!
//! Key expressions, under `tacmesh/<robot>` ([`Keys`]):
//! - `objects/<id>/shape`: each new Shape (reliable; a slow link delays shapes, it never
//!   loses the latest);
//! - `objects/<id>/pose`: each Pose, dropped under congestion, so a slow link gets the newest
//!   pose, never a backlog;
//! - `objects/<id>/body`: each Body (the collision body; reliable, like shapes);
//! - `objects/<id>/removed`: the Remove frame when the object is gone;
//! - `stats`: the Stats frames, dropped under congestion.
//!
//! A query on `tacmesh/<robot>/objects/**` is answered with the current Shape of every object,
//! its Body and its newer Pose, if any: a late joiner gets every object at once.
//!
//! Entry points: [`ZenohSettings`] (what the `[zenoh]` section of a config says),
//! [`ZenohMirror`] (the daemon's side, a [`tacmesh_publish::Mirror`]) and [`ZenohSubscription`]
//! (a client: the snapshot by query, then the samples, as [`Message`]s).

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tacmesh_protocol::{Encoding, FrameDecoder, Message, Sender, WireError};
use tacmesh_publish::{EncodedBody, EncodedPose, EncodedShape, Mirror};
use zenoh::qos::CongestionControl;
use zenoh::query::ConsolidationMode;
use zenoh::Wait;

/// How long [`ZenohMirror::shutdown`](Mirror::shutdown) waits for queued updates to go out.
pub const SHUTDOWN_GRACE: Duration = Duration::from_secs(1);

/// Everything that can go wrong with Zenoh, said so that the operator knows what to do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ZenohError {
    #[error("cannot read the Zenoh configuration {}: {cause}", path.display())]
    ConfigFile { path: PathBuf, cause: String },

    #[error("the [zenoh] setting `{key}` = {value} is refused by Zenoh: {cause}")]
    Setting {
        key: &'static str,
        value: String,
        cause: String,
    },

    #[error(
        "robot name {name:?} cannot be part of a key expression: use letters, digits, `-` and \
         `_` only"
    )]
    RobotName { name: String },

    #[error(
        "cannot open the Zenoh session: {cause}; check the [zenoh] endpoints (a `listen` \
         address already in use, or a `connect` peer that does not answer)"
    )]
    Open { cause: String },

    #[error("cannot declare {what} on Zenoh: {cause}")]
    Declare { what: String, cause: String },

    #[error("the query for the scene on {key} failed: {cause}")]
    Query { key: String, cause: String },

    #[error("a sample on {key} is not a tacmesh frame: {cause}")]
    Wire { key: String, cause: WireError },

    #[error("the Zenoh subscription ended (its session closed)")]
    Closed,
}

/// How to join the Zenoh network and under which robot name: what the `[zenoh]` section of a
/// tacmesh config says (each key is documented there, in `src/daemon/config.rs`, and in
/// `tacmesh.example.toml`).
#[derive(Debug, Clone, PartialEq)]
pub struct ZenohSettings {
    pub robot: String,
    pub mode: String,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    pub multicast_scouting: bool,
    /// Zenoh's own configuration (JSON5: TLS, access control), which the fields above are
    /// applied on top of.
    pub config_file: Option<PathBuf>,
    /// How the daemon encodes the shapes it puts (every Zenoh subscriber gets the same).
    pub encoding: Encoding,
}

impl Default for ZenohSettings {
    fn default() -> Self {
        Self {
            robot: "robot".into(),
            mode: "peer".into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            config_file: None,
            encoding: Encoding::Compact,
        }
    }
}

impl ZenohSettings {
    /// The Zenoh configuration these settings make.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, ZenohError> {
        Keys::new(&self.robot)?;
        let mut config = match &self.config_file {
            Some(path) => {
                zenoh::Config::from_file(path).map_err(|cause| ZenohError::ConfigFile {
                    path: path.clone(),
                    cause: cause.to_string(),
                })?
            }
            None => zenoh::Config::default(),
        };
        let json_list = |items: &[String]| {
            let quoted: Vec<String> = items.iter().map(|i| format!("{i:?}")).collect();
            format!("[{}]", quoted.join(","))
        };
        let mut set = |key: &'static str, value: String| {
            config
                .insert_json5(key, &value)
                .map_err(|cause| ZenohError::Setting {
                    key,
                    value,
                    cause: cause.to_string(),
                })
        };
        set("mode", format!("{:?}", self.mode))?;
        if !self.listen.is_empty() {
            set("listen/endpoints", json_list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            set("connect/endpoints", json_list(&self.connect))?;
        }
        set(
            "scouting/multicast/enabled",
            self.multicast_scouting.to_string(),
        )?;
        Ok(config)
    }

    /// Opens a Zenoh session with these settings.
    pub fn open(&self) -> Result<zenoh::Session, ZenohError> {
        let config = self.zenoh_config()?;
        zenoh::open(config)
            .wait()
            .map_err(|cause| ZenohError::Open {
                cause: cause.to_string(),
            })
    }
}

/// The key expressions of one robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    pub fn new(robot: &str) -> Result<Self, ZenohError> {
        let valid = !robot.is_empty()
            && robot
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !valid {
            return Err(ZenohError::RobotName {
                name: robot.to_owned(),
            });
        }
        Ok(Self {
            prefix: format!("tacmesh/{robot}"),
        })
    }

    pub fn shape(&self, object_id: u64) -> String {
        format!("{}/objects/{object_id}/shape", self.prefix)
    }

    pub fn pose(&self, object_id: u64) -> String {
        format!("{}/objects/{object_id}/pose", self.prefix)
    }

    pub fn body(&self, object_id: u64) -> String {
        format!("{}/objects/{object_id}/body", self.prefix)
    }

    pub fn removed(&self, object_id: u64) -> String {
        format!("{}/objects/{object_id}/removed", self.prefix)
    }

    pub fn stats(&self) -> String {
        format!("{}/stats", self.prefix)
    }

    /// Every object's keys: what the scene's queryable answers, what a query asks for.
    pub fn objects(&self) -> String {
        format!("{}/objects/**", self.prefix)
    }

    /// Everything of this robot: what a subscriber subscribes to.
    pub fn all(&self) -> String {
        format!("{}/**", self.prefix)
    }
}

/// Locks a mutex, going on with the data if a thread panicked while holding it (every state
/// here is consistent between statements).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What is waiting to be put: the latest shape, body and pose of each object, removes, stats.
#[derive(Default)]
struct Pending {
    shapes: BTreeMap<u64, Arc<EncodedShape>>,
    bodies: BTreeMap<u64, Arc<EncodedBody>>,
    poses: BTreeMap<u64, Arc<EncodedPose>>,
    removes: BTreeSet<u64>,
    stats: Option<Arc<Vec<u8>>>,
    stopping: bool,
}

impl Pending {
    fn is_empty(&self) -> bool {
        self.shapes.is_empty()
            && self.bodies.is_empty()
            && self.poses.is_empty()
            && self.removes.is_empty()
            && self.stats.is_none()
    }
}

/// An object's current shape, its body if it has one, and the pose newer than the one inside
/// the shape, if any.
#[derive(Clone)]
struct CurrentObject {
    shape: Arc<EncodedShape>,
    body: Option<Arc<EncodedBody>>,
    pose: Option<Arc<EncodedPose>>,
}

/// The current shape, body and newer pose of every object, for the scene's queryable.
type Current = BTreeMap<u64, CurrentObject>;

struct Shared {
    keys: Keys,
    encoding: Encoding,
    pending: Mutex<Pending>,
    wake: Condvar,
    current: Mutex<Current>,
    samples_put: AtomicU64,
    bytes_put: AtomicU64,
    put_errors: AtomicU64,
}

/// The daemon's side: a [`Mirror`] of the publisher that puts every update on Zenoh from a
/// thread of its own (the pipeline never waits on the network) and answers queries for the
/// current scene.
pub struct ZenohMirror {
    shared: Arc<Shared>,
    session: zenoh::Session,
    worker: Mutex<Option<JoinHandle<()>>>,
    _queryable: zenoh::query::Queryable<()>,
}

/// What the mirror has put so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MirrorCounters {
    pub samples_put: u64,
    pub bytes_put: u64,
    pub put_errors: u64,
}

impl ZenohMirror {
    /// Opens a session with `settings`, declares the scene's queryable and starts the thread
    /// that puts updates.
    pub fn start(settings: &ZenohSettings) -> Result<Arc<Self>, ZenohError> {
        let keys = Keys::new(&settings.robot)?;
        let session = settings.open()?;
        let shared = Arc::new(Shared {
            keys: keys.clone(),
            encoding: settings.encoding,
            pending: Mutex::new(Pending::default()),
            wake: Condvar::new(),
            current: Mutex::new(Current::new()),
            samples_put: AtomicU64::new(0),
            bytes_put: AtomicU64::new(0),
            put_errors: AtomicU64::new(0),
        });
        let answering = Arc::clone(&shared);
        let queryable = session
            .declare_queryable(keys.objects())
            .callback(move |query| answering.answer(&query))
            .wait()
            .map_err(|cause| ZenohError::Declare {
                what: format!("the scene's queryable on {}", keys.objects()),
                cause: cause.to_string(),
            })?;
        let (putting, put_session) = (Arc::clone(&shared), session.clone());
        let worker = std::thread::Builder::new()
            .name("zenoh-put".into())
            .spawn(move || putting.put_loop(&put_session))
            .map_err(|cause| ZenohError::Declare {
                what: "the thread that puts updates".into(),
                cause: cause.to_string(),
            })?;
        tracing::info!(
            "publishing on Zenoh under {} ({:?} shapes; session {})",
            keys.all(),
            settings.encoding,
            session.zid()
        );
        Ok(Arc::new(Self {
            shared,
            session,
            worker: Mutex::new(Some(worker)),
            _queryable: queryable,
        }))
    }

    pub fn counters(&self) -> MirrorCounters {
        MirrorCounters {
            samples_put: self.shared.samples_put.load(Ordering::Relaxed),
            bytes_put: self.shared.bytes_put.load(Ordering::Relaxed),
            put_errors: self.shared.put_errors.load(Ordering::Relaxed),
        }
    }
}

impl Mirror for ZenohMirror {
    fn shape(&self, object_id: u64, shape: &Arc<EncodedShape>) {
        let mut current = lock(&self.shared.current);
        // The body stays with the object's newer shapes, unless this one is in a new frame.
        let body = current
            .remove(&object_id)
            .and_then(|held| held.body)
            .filter(|_| !shape.new_frame);
        current.insert(
            object_id,
            CurrentObject {
                shape: Arc::clone(shape),
                body,
                pose: None,
            },
        );
        drop(current);
        let mut pending = lock(&self.shared.pending);
        pending.removes.remove(&object_id);
        pending.poses.remove(&object_id);
        if shape.new_frame {
            pending.bodies.remove(&object_id);
        }
        pending.shapes.insert(object_id, Arc::clone(shape));
        drop(pending);
        self.shared.wake.notify_one();
    }

    fn pose(&self, object_id: u64, pose: &Arc<EncodedPose>) {
        if let Some(entry) = lock(&self.shared.current).get_mut(&object_id) {
            entry.pose = Some(Arc::clone(pose));
        }
        lock(&self.shared.pending)
            .poses
            .insert(object_id, Arc::clone(pose));
        self.shared.wake.notify_one();
    }

    fn body(&self, object_id: u64, body: &Arc<EncodedBody>) {
        if let Some(entry) = lock(&self.shared.current).get_mut(&object_id) {
            entry.body = Some(Arc::clone(body));
        }
        lock(&self.shared.pending)
            .bodies
            .insert(object_id, Arc::clone(body));
        self.shared.wake.notify_one();
    }

    fn remove(&self, object_id: u64) {
        lock(&self.shared.current).remove(&object_id);
        let mut pending = lock(&self.shared.pending);
        pending.shapes.remove(&object_id);
        pending.bodies.remove(&object_id);
        pending.poses.remove(&object_id);
        pending.removes.insert(object_id);
        drop(pending);
        self.shared.wake.notify_one();
    }

    fn stats(&self, frame: &Arc<Vec<u8>>) {
        lock(&self.shared.pending).stats = Some(Arc::clone(frame));
        self.shared.wake.notify_one();
    }

    fn shutdown(&self) {
        lock(&self.shared.pending).stopping = true;
        self.shared.wake.notify_one();
        if let Some(worker) = lock(&self.worker).take() {
            let deadline = Instant::now() + SHUTDOWN_GRACE;
            while !worker.is_finished() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            if worker.is_finished() {
                let _ = worker.join();
            }
        }
        if let Err(error) = self.session.close().wait() {
            tracing::warn!("closing the Zenoh session: {error}");
        }
        let counters = self.counters();
        tracing::info!(
            "stopped publishing on Zenoh ({} samples, {} bytes put, {} failed)",
            counters.samples_put,
            counters.bytes_put,
            counters.put_errors
        );
    }
}

impl Shared {
    /// Puts what is pending until shutdown, then what is left.
    fn put_loop(&self, session: &zenoh::Session) {
        loop {
            let (batch, stopping) = {
                let mut pending = lock(&self.pending);
                while pending.is_empty() && !pending.stopping {
                    pending = self
                        .wake
                        .wait(pending)
                        .unwrap_or_else(PoisonError::into_inner);
                }
                let stopping = pending.stopping;
                (std::mem::take(&mut *pending), stopping)
            };
            self.put_batch(session, &batch);
            if stopping {
                return;
            }
        }
    }

    fn put_batch(&self, session: &zenoh::Session, batch: &Pending) {
        let keys = &self.keys;
        for (&id, shape) in &batch.shapes {
            self.put(session, keys.shape(id), shape.bytes(self.encoding), true);
        }
        for (&id, body) in &batch.bodies {
            self.put(session, keys.body(id), body.bytes(self.encoding), true);
        }
        for (&id, pose) in &batch.poses {
            self.put(session, keys.pose(id), &pose.bytes, false);
        }
        let mut remove = Vec::new();
        for &id in &batch.removes {
            remove.clear();
            if tacmesh_protocol::encode(&Message::Remove { object_id: id }, &mut remove).is_ok() {
                self.put(session, keys.removed(id), &remove, true);
            }
        }
        if let Some(stats) = &batch.stats {
            self.put(session, keys.stats(), stats, false);
        }
    }

    /// One put: `reliable` ones wait for a congested link (shapes, bodies, removes: the latest must
    /// arrive), the others are dropped under congestion (poses, stats: a newer one follows).
    fn put(&self, session: &zenoh::Session, key: String, frame: &[u8], reliable: bool) {
        let congestion = if reliable {
            CongestionControl::Block
        } else {
            CongestionControl::Drop
        };
        let put = session
            .put(&key, frame.to_vec())
            .congestion_control(congestion)
            .express(!reliable)
            .wait();
        match put {
            Ok(()) => {
                self.samples_put.fetch_add(1, Ordering::Relaxed);
                self.bytes_put
                    .fetch_add(frame.len() as u64, Ordering::Relaxed);
            }
            Err(error) => {
                let failed = self.put_errors.fetch_add(1, Ordering::Relaxed) + 1;
                if failed.is_power_of_two() {
                    tracing::warn!("Zenoh put on {key} failed ({failed} so far): {error}");
                }
            }
        }
    }

    /// Answers a query for the scene: every object's shape, its body, then its newer pose.
    fn answer(&self, query: &zenoh::query::Query) {
        // Copied out (a few Arcs), so that the mirror's callbacks are not held up by replies.
        let current: Vec<(u64, CurrentObject)> = lock(&self.current)
            .iter()
            .map(|(&id, entry)| (id, entry.clone()))
            .collect();
        for (id, CurrentObject { shape, body, pose }) in current {
            let mut replies = vec![(self.keys.shape(id), shape.bytes(self.encoding).to_vec())];
            if let Some(body) = body {
                replies.push((self.keys.body(id), body.bytes(self.encoding).to_vec()));
            }
            if let Some(pose) = pose {
                replies.push((self.keys.pose(id), pose.bytes.clone()));
            }
            for (key, frame) in replies {
                if let Err(error) = query.reply(&key, frame).wait() {
                    tracing::debug!("a scene query's reply on {key} failed: {error}");
                }
            }
        }
    }
}

/// A client over Zenoh: the current scene by query (as a snapshot ending in SnapshotDone),
/// then every sample as it comes, each decoded as the frame it carries.
pub struct ZenohSubscription {
    session: zenoh::Session,
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    queued: VecDeque<Message>,
}

impl ZenohSubscription {
    /// Joins with `settings`, subscribes to everything of its robot, then asks for the scene
    /// (waiting at most `query_timeout` for the answers).
    pub fn connect(settings: &ZenohSettings, query_timeout: Duration) -> Result<Self, ZenohError> {
        let keys = Keys::new(&settings.robot)?;
        let session = settings.open()?;
        let subscriber = session
            .declare_subscriber(keys.all())
            .wait()
            .map_err(|cause| ZenohError::Declare {
                what: format!("a subscriber on {}", keys.all()),
                cause: cause.to_string(),
            })?;
        let replies = session
            .get(keys.objects())
            .consolidation(ConsolidationMode::None)
            .timeout(query_timeout)
            .wait()
            .map_err(|cause| ZenohError::Query {
                key: keys.objects(),
                cause: cause.to_string(),
            })?;
        // Replies come in any order: shapes first, so that a body or pose finds its object.
        let (mut shapes, mut poses) = (Vec::new(), Vec::new());
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else {
                continue;
            };
            let key = sample.key_expr().as_str().to_owned();
            for message in decode(&key, &sample.payload().to_bytes())? {
                match message {
                    Message::Shape(_) => shapes.push(message),
                    _ => poses.push(message),
                }
            }
        }
        let mut queued: VecDeque<Message> = shapes.into_iter().chain(poses).collect();
        queued.push_back(Message::SnapshotDone);
        Ok(Self {
            session,
            subscriber,
            queued,
        })
    }

    /// The next message: the scene's first, then the samples; `None` after `timeout`.
    pub fn next_message(&mut self, timeout: Duration) -> Result<Option<Message>, ZenohError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(message) = self.queued.pop_front() {
                return Ok(Some(message));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let sample = match self.subscriber.recv_timeout(left) {
                Ok(Some(sample)) => sample,
                Ok(None) => return Ok(None),
                Err(_) => return Err(ZenohError::Closed),
            };
            let key = sample.key_expr().as_str().to_owned();
            self.queued
                .extend(decode(&key, &sample.payload().to_bytes())?);
        }
    }

    /// The Zenoh session, e.g. to close it.
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }
}

/// The frames of one sample's payload.
fn decode(key: &str, payload: &[u8]) -> Result<Vec<Message>, ZenohError> {
    let mut decoder = FrameDecoder::new(Sender::Server);
    decoder.push(payload);
    let mut messages = Vec::new();
    loop {
        match decoder.next_message() {
            Ok(Some(message)) => messages.push(message),
            Ok(None) => break,
            Err(cause) => {
                return Err(ZenohError::Wire {
                    key: key.to_owned(),
                    cause,
                })
            }
        }
    }
    if decoder.buffered_len() > 0 {
        return Err(ZenohError::Wire {
            key: key.to_owned(),
            cause: WireError::Truncated {
                message: "sample",
                field: "frame",
                needed: 4,
                available: decoder.buffered_len(),
            },
        });
    }
    Ok(messages)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_names_are_checked_and_make_the_keys() {
        let keys = Keys::new("arm-2").expect("a plain name");
        assert_eq!(keys.shape(7), "tacmesh/arm-2/objects/7/shape");
        assert_eq!(keys.pose(7), "tacmesh/arm-2/objects/7/pose");
        assert_eq!(keys.body(7), "tacmesh/arm-2/objects/7/body");
        assert_eq!(keys.removed(7), "tacmesh/arm-2/objects/7/removed");
        assert_eq!(keys.stats(), "tacmesh/arm-2/stats");
        assert_eq!(keys.objects(), "tacmesh/arm-2/objects/**");
        for bad in ["", "a/b", "a*", "x y", "$"] {
            assert!(
                matches!(Keys::new(bad), Err(ZenohError::RobotName { .. })),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn settings_become_a_zenoh_config_and_bad_ones_are_refused() {
        let settings = ZenohSettings {
            listen: vec!["tcp/127.0.0.1:0".into()],
            ..ZenohSettings::default()
        };
        settings.zenoh_config().expect("a valid config");
        let bad = ZenohSettings {
            mode: "sideways".into(),
            ..ZenohSettings::default()
        };
        let error = bad.zenoh_config().expect_err("an unknown mode");
        assert!(error.to_string().contains("`mode`"), "{error}");
        let missing = ZenohSettings {
            config_file: Some("/nonexistent/zenoh.json5".into()),
            ..ZenohSettings::default()
        };
        assert!(matches!(
            missing.zenoh_config(),
            Err(ZenohError::ConfigFile { .. })
        ));
    }

    #[test]
    fn a_sample_that_is_not_a_frame_is_an_error_naming_its_key() {
        let error = decode("tacmesh/r/objects/1/pose", &[1, 2, 3, 4, 5, 6]).unwrap_err();
        assert!(
            error.to_string().contains("tacmesh/r/objects/1/pose"),
            "{error}"
        );
    }
}
