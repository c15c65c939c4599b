//! The publish stage: serves the current shape and pose of every object to subscribers on a
//! Unix stream socket, in the wire format of `tacmesh-protocol` (`docs/protocol.md`).
//!
//! Entry points:
//! - [`Publisher::bind`]: claim the socket path (refusing a live daemon or a non-socket, removing
//!   a stale socket), set its mode, and start accepting subscribers.
//! - [`Publisher::shape`], [`Publisher::body`], [`Publisher::pose`], [`Publisher::remove`],
//!   [`Publisher::stats`]: called by the pipeline; they never wait for a subscriber.
//! - [`Publisher::counters`], [`Publisher::shutdown`].
//!
//! Every subscriber gets `Hello`, a snapshot (`Session`, a `Shape` of every current object,
//! `SnapshotDone`), then live updates, and a new snapshot when its `Subscribe` asks for one.
//! Each subscriber has a pending state that holds at most the latest unsent shape, body and
//! pose of each object, the unsent removes and the latest stats: a slow subscriber skips
//! versions, and its memory stays bounded by the number of objects. The next batch of it is
//! taken only when the last has gone into the socket, under the subscriber's options
//! (encoding, rate cap per object, which objects). Its socket's kernel buffer is kept small
//! ([`SEND_BUFFER_BYTES`]), so that little can be stale there when it reads again. A subscriber
//! whose socket takes nothing for [`WRITE_TIMEOUT`] is dropped (told why in a Goodbye after the
//! frame it stalled in, when they fit in a raised buffer); one that only closes its sending
//! side goes on being served. What a subscriber sends is decoded as it comes; anything but a
//! well-formed `Subscribe` gets it dropped with a Goodbye saying why and one WARN line.
//!
//! One thread serves every subscriber: an epoll loop over the listening socket and the
//! connections (see `serve.rs`); the pipeline's calls queue and wake it.

mod bind;
mod client;
mod serve;

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::os::fd::OwnedFd;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tacmesh_protocol::{
    encode, Body, Encoding, Message, Pose, Shape, Stats, WireError, MAX_REASON_BYTES,
};

use crate::client::{Client, ObjectFrames, Peer, Retire};
pub use crate::client::{EncodedBody, EncodedPose, EncodedShape};

/// Socket file mode when the config does not say otherwise: owner and group read and write.
pub const DEFAULT_SOCKET_MODE: u32 = 0o660;

/// Subscribers served at once when the config does not say otherwise. Each costs a socket and
/// its buffers: 1,100 unbounded connections once exhausted the daemon's 1,024 descriptors.
pub const DEFAULT_MAX_SUBSCRIBERS: usize = 64;

/// Subscribers one user may have at once when the config does not say otherwise, so that one
/// client in a reconnect loop cannot take every place.
pub const DEFAULT_MAX_SUBSCRIBERS_PER_USER: usize = 16;

/// The least time between two Subscribes of one subscriber that the publisher acts on; a
/// sooner one waits (nothing more is read from it meanwhile, so a flood backs up in the
/// client's own socket). A
/// client asking for a fresh snapshot 600 times a second once cost a quarter of the frame rate.
pub const RESUBSCRIBE_INTERVAL: Duration = Duration::from_millis(100);

/// A subscriber whose socket accepts no bytes for this long is dropped: the clock starts when
/// its socket's buffer is full, shortly after it stops reading. A stalled subscriber costs little meanwhile (the latest update
/// of each object, and [`SEND_BUFFER_BYTES`] in the kernel), so it is given long enough to
/// come back: a client paused 20 s in a debugger or a garbage collection resumes with current
/// data.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(30);

/// The kernel's send buffer asked for each subscriber's socket (`SO_SNDBUF`; Linux doubles it
/// for its bookkeeping and grants at least 4.5 KiB, which holds 1–4 KiB of frames). What a subscriber that stops reading has not yet read is this buffer
/// and the frame being written, then only the latest update of each object in the daemon's
/// own queue: with the default buffer (131–154 kB queued) a client back from a 20 s stall read
/// 56–59 frames of every version in order, 17–20 s old, before anything current.
pub const SEND_BUFFER_BYTES: usize = 2 * 1024;

/// How long [`Publisher::shutdown`] waits for subscribers to take their `Goodbye` before it
/// closes their sockets anyway.
pub const GOODBYE_GRACE: Duration = Duration::from_secs(1);

/// Another way out for what is published (Zenoh, for subscribers on other machines): it is
/// handed every update as the Unix socket's subscribers get it, already encoded, in the order
/// the pipeline publishes. Each call is made with the publisher's state locked and must return
/// at once (queue the update; never wait on a network).
pub trait Mirror: Send + Sync {
    /// A new shape of an object, with the pose it comes with.
    fn shape(&self, object_id: u64, shape: &Arc<EncodedShape>);
    /// A new pose of an object's published shape (a Pose frame).
    fn pose(&self, object_id: u64, pose: &Arc<EncodedPose>);
    /// A new collision body of an object.
    fn body(&self, object_id: u64, body: &Arc<EncodedBody>);
    /// The object is gone.
    fn remove(&self, object_id: u64);
    /// The latest Stats frame.
    fn stats(&self, frame: &Arc<Vec<u8>>);
    /// The daemon stops: send what is queued, then stop (bounded in time).
    fn shutdown(&self);
}

/// Where and how to publish.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PublisherConfig {
    /// The Unix socket path. Its directory must exist.
    pub socket_path: PathBuf,
    /// Permission bits of the socket file (connecting needs write permission), e.g. `0o660`.
    pub mode: u32,
    /// Sent in `Hello`, e.g. `tacmesh 0.1.0`; at most 64 bytes.
    pub server_name: String,
    /// Group (gid) to give the socket file, so that members of it may connect (with a mode
    /// such as `0o660`); `None` leaves the daemon's own group.
    pub group: Option<u32>,
    /// Only peers these credentials allow may subscribe; `None` admits whoever the socket
    /// file's mode lets connect.
    pub allowed_peers: Option<AllowedPeers>,
    /// The most subscribers served at once; one more is told so in a Goodbye and refused.
    pub max_subscribers: usize,
    /// The most subscribers of one user (by `SO_PEERCRED`) served at once.
    pub max_subscribers_per_user: usize,
}

/// Which peers may subscribe, by the credentials the kernel reports for the connecting process
/// (`SO_PEERCRED`: its user id and its primary group id at `connect` time). The kernel does
/// not report supplementary groups there, so the members of each allowed group (a user added
/// with `usermod -aG`) are looked up once, at start, and listed in `member_uids`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AllowedPeers {
    /// Users allowed by name or number.
    pub uids: Vec<u32>,
    /// Primary groups allowed.
    pub gids: Vec<u32>,
    /// Users who are supplementary members of an allowed group.
    pub member_uids: Vec<u32>,
}

impl AllowedPeers {
    pub fn allows(&self, uid: u32, gid: u32) -> bool {
        self.uids.contains(&uid) || self.gids.contains(&gid) || self.member_uids.contains(&uid)
    }
}

impl PublisherConfig {
    /// A config with the default mode ([`DEFAULT_SOCKET_MODE`]) and server name (`tacmesh 0.1.0`).
    pub fn new(socket_path: impl Into<PathBuf>) -> Self {
        Self {
            socket_path: socket_path.into(),
            mode: DEFAULT_SOCKET_MODE,
            server_name: format!("tacmesh {}", env!("CARGO_PKG_VERSION")),
            group: None,
            allowed_peers: None,
            max_subscribers: DEFAULT_MAX_SUBSCRIBERS,
            max_subscribers_per_user: DEFAULT_MAX_SUBSCRIBERS_PER_USER,
        }
    }
}

/// What the publisher has done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PublisherCounters {
    /// Subscribers connected now.
    pub clients_connected: usize,
    /// Subscribers the publisher disconnected because they misbehaved: sent a malformed,
    /// oversize or wrong-direction frame, or read nothing for [`WRITE_TIMEOUT`]. Subscribers that
    /// simply disconnect are not counted.
    pub clients_dropped: u64,
    /// Connections refused because the peer's credentials are not in
    /// [`PublisherConfig::allowed_peers`] (or could not be read), or because the subscribers
    /// (all, or the peer user's) were at their cap.
    pub clients_refused: u64,
    /// Subscribes held back to [`RESUBSCRIBE_INTERVAL`] after the previous one.
    pub subscribes_throttled: u64,
    /// Shape frames written to subscribers (snapshots and live), summed over subscribers.
    pub shapes_published: u64,
    /// Pose frames written to subscribers, summed over subscribers.
    pub poses_published: u64,
    /// Body frames written to subscribers, summed over subscribers.
    pub bodies_published: u64,
    /// Bytes written to all subscribers.
    pub bytes_sent: u64,
}

/// Everything that can go wrong when publishing, said so that the operator knows what to do.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PublishError {
    #[error("another tacmesh daemon is serving {}; stop it or choose another --socket", path.display())]
    AlreadyRunning { path: PathBuf },

    #[error(
        "{} exists and is not a socket; tacmesh will not replace it: remove it or choose \
         another --socket",
        path.display()
    )]
    NotASocket { path: PathBuf },

    #[error(
        "the directory {} for the socket does not exist: create it or choose another --socket",
        dir.display()
    )]
    NoSocketDir { dir: PathBuf },

    #[error(
        "will not serve a socket in {}: {reason}; use a directory only the daemon's user \
         (or root) can write, such as $XDG_RUNTIME_DIR or systemd's RuntimeDirectory \
         (/run/tacmesh)",
        dir.display()
    )]
    UnsafeSocketDir { dir: PathBuf, reason: String },

    #[error(
        "cannot check whether a daemon serves {}: {cause}; check the permissions of the \
         path or choose another --socket",
        path.display()
    )]
    Probe {
        path: PathBuf,
        cause: std::io::Error,
    },

    #[error(
        "cannot remove the stale socket {}: {cause}; remove it yourself or choose another \
         --socket",
        path.display()
    )]
    RemoveStale {
        path: PathBuf,
        cause: std::io::Error,
    },

    #[error(
        "cannot bind the socket {}: {cause}; check that its directory is writable and the \
         path is shorter than 108 bytes",
        path.display()
    )]
    Bind {
        path: PathBuf,
        cause: std::io::Error,
    },

    #[error("cannot set mode {mode:04o} on the socket {}: {cause}", path.display())]
    SetMode {
        path: PathBuf,
        mode: u32,
        cause: std::io::Error,
    },

    #[error(
        "cannot give the socket {} to group {gid}: {cause}; the daemon's user must be a \
         member of that group",
        path.display()
    )]
    SetGroup {
        path: PathBuf,
        gid: u32,
        cause: std::io::Error,
    },

    #[error("socket mode {mode:o} is not a set of permission bits: give a mode such as 0o660")]
    InvalidMode { mode: u32 },

    #[error("server name {name:?} cannot be sent in a Hello: {cause}")]
    ServerName { name: String, cause: WireError },

    #[error("cannot start the publisher's thread: {cause}")]
    Spawn { cause: std::io::Error },

    #[error(
        "object {object_id}: version {version} is not newer than the published version \
         {current}; every new mesh of an object needs a higher version"
    )]
    VersionNotNewer {
        object_id: u64,
        version: u64,
        current: u64,
    },

    #[error("the shape of object {object_id} cannot be published: {cause}")]
    EncodeShape { object_id: u64, cause: WireError },

    #[error("the pose of object {object_id} cannot be published: {cause}")]
    EncodePose { object_id: u64, cause: WireError },

    #[error(
        "a pose of object {object_id} names shape version {version}, but {}; publish the \
         shape first",
        match current { Some(v) => format!("its published shape is version {v}"),
                        None => "it has no published shape".to_owned() }
    )]
    PoseForUnknownShape {
        object_id: u64,
        version: u64,
        current: Option<u64>,
    },

    #[error("the stats cannot be published: {cause}")]
    EncodeStats { cause: WireError },

    #[error("the body of object {object_id} cannot be published: {cause}")]
    EncodeBody { object_id: u64, cause: WireError },

    #[error(
        "a body of object {object_id} was made from shape version {version}, which {why}; a \
         body is published after its shape, in that shape's frame"
    )]
    BodyDoesNotFit {
        object_id: u64,
        version: u64,
        why: String,
    },
}

/// State shared by the publisher handle (the pipeline's threads) and the serving thread.
pub(crate) struct Shared {
    /// The encoded Hello, the same for every subscriber.
    hello: Vec<u8>,
    /// An eventfd that wakes the serving thread when something was queued.
    waker: OwnedFd,
    /// [`WRITE_TIMEOUT`] except in tests.
    write_timeout: Duration,
    state: Mutex<State>,
    /// Replaced by [`Publisher::set_allowed_peers`] when the daemon reads the lists again.
    allowed_peers: Mutex<Option<AllowedPeers>>,
    /// [`PublisherConfig::max_subscribers`] and [`PublisherConfig::max_subscribers_per_user`].
    max_subscribers: (usize, usize),
    /// "subscriber connected" and "left" lines, at most a few a second.
    connection_log: Mutex<LogThrottle>,
    clients_dropped: AtomicU64,
    clients_refused: AtomicU64,
    pub(crate) subscribes_throttled: AtomicU64,
    shapes_published: AtomicU64,
    poses_published: AtomicU64,
    bodies_published: AtomicU64,
    bytes_sent: AtomicU64,
}

/// Lock order: `State` before any `Client::pending`.
#[derive(Default)]
struct State {
    /// The latest encoded shape and pose of every current object: the snapshot a new
    /// subscriber gets.
    objects: BTreeMap<u64, ObjectFrames>,
    clients: BTreeMap<u64, Arc<Client>>,
    /// Other ways out (see [`Mirror`]).
    mirrors: Vec<Arc<dyn Mirror>>,
    next_client: u64,
    /// Set by shutdown: no new subscribers.
    stopping: bool,
}

/// Locks a mutex, going on with the data if a thread panicked while holding it: every state
/// here stays consistent between statements, and the publisher must keep serving the others.
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The publish stage. Dropping it shuts it down (see [`Publisher::shutdown`]).
pub struct Publisher {
    shared: Arc<Shared>,
    path: PathBuf,
    /// (device, inode) of the socket file we bound, so that shutdown removes only our own file.
    file_id: Option<(u64, u64)>,
    serve: Mutex<Option<JoinHandle<()>>>,
    shut_down: std::sync::atomic::AtomicBool,
}

impl std::fmt::Debug for Publisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Publisher")
            .field("path", &self.path)
            .field("counters", &self.counters())
            .finish_non_exhaustive()
    }
}

impl Publisher {
    /// Claims `config.socket_path` and starts serving subscribers.
    ///
    /// An existing path: if a daemon answers a connect on it, [`PublishError::AlreadyRunning`];
    /// if it is a socket nobody answers (left by a daemon that died), it is removed; if it is not
    /// a socket, [`PublishError::NotASocket`]. The socket file gets `config.mode`.
    pub fn bind(config: PublisherConfig) -> Result<Publisher, PublishError> {
        Self::bind_with_write_timeout(config, WRITE_TIMEOUT)
    }

    /// [`Publisher::bind`] with another write timeout, so that tests need not wait for the
    /// real one.
    pub(crate) fn bind_with_write_timeout(
        config: PublisherConfig,
        write_timeout: Duration,
    ) -> Result<Publisher, PublishError> {
        let mut hello = Vec::new();
        encode(&Message::hello(config.server_name.as_str()), &mut hello).map_err(|source| {
            PublishError::ServerName {
                name: config.server_name.clone(),
                cause: source,
            }
        })?;
        let bound = bind::claim(&config.socket_path, config.mode, config.group)?;
        let spawn_failed = |cause: std::io::Error| {
            bind::remove_if_ours(&config.socket_path, bound.file_id);
            PublishError::Spawn { cause }
        };
        let waker = rustix::event::eventfd(
            0,
            rustix::event::EventfdFlags::CLOEXEC | rustix::event::EventfdFlags::NONBLOCK,
        )
        .map_err(|errno| spawn_failed(errno.into()))?;
        let shared = Arc::new(Shared {
            hello,
            waker,
            write_timeout,
            state: Mutex::new(State::default()),
            allowed_peers: Mutex::new(config.allowed_peers.clone()),
            max_subscribers: (config.max_subscribers, config.max_subscribers_per_user),
            connection_log: Mutex::new(LogThrottle::default()),
            clients_dropped: AtomicU64::new(0),
            clients_refused: AtomicU64::new(0),
            subscribes_throttled: AtomicU64::new(0),
            shapes_published: AtomicU64::new(0),
            poses_published: AtomicU64::new(0),
            bodies_published: AtomicU64::new(0),
            bytes_sent: AtomicU64::new(0),
        });
        let serve = serve::Serve::new(Arc::clone(&shared), bound.listener)
            .and_then(|serve| {
                std::thread::Builder::new()
                    .name("publish".into())
                    .spawn(move || serve.run())
            })
            .map_err(spawn_failed)?;
        tracing::info!(
            "publishing meshes on {} (mode {:04o})",
            config.socket_path.display(),
            config.mode
        );
        Ok(Publisher {
            shared,
            path: config.socket_path,
            file_id: bound.file_id,
            serve: Mutex::new(Some(serve)),
            shut_down: std::sync::atomic::AtomicBool::new(false),
        })
    }

    /// The socket path this publisher serves.
    pub fn socket_path(&self) -> &Path {
        &self.path
    }

    /// Publishes a new shape of an object (new or known) with its pose. Returns at once: each
    /// subscriber's writer sends it when it can, in the encoding that subscriber asked for, and
    /// a newer shape of the same object replaces an unsent shape and pose.
    ///
    /// Errors: [`PublishError::VersionNotNewer`] if the shape's version is not above the
    /// version last published for this object (nothing is published),
    /// [`PublishError::EncodeShape`] for a shape the wire format refuses (non-finite vertex,
    /// bad index, not a unit quaternion, over the frame cap).
    pub fn shape(&self, shape: Shape) -> Result<(), PublishError> {
        let object_id = shape.object_id();
        let version = shape.version();
        if let Some(current) = self.current_version(object_id) {
            if version <= current {
                return Err(PublishError::VersionNotNewer {
                    object_id,
                    version,
                    current,
                });
            }
        }
        let encode_as = |encoding: Encoding| {
            frame_of(&Message::Shape(Shape {
                encoding,
                ..shape.clone()
            }))
            .map_err(|cause| PublishError::EncodeShape { object_id, cause })
        };
        let frames = Arc::new(EncodedShape {
            version,
            new_frame: shape.is_new_frame(),
            pose: shape.pose,
            full: encode_as(Encoding::Full)?,
            compact: encode_as(Encoding::Compact)?,
        });

        let mut state = lock(&self.shared.state);
        if let Some(current) = state.objects.get(&object_id).and_then(|o| o.shape.as_ref()) {
            // Checked again under the lock in case two threads publish the same object.
            if version <= current.version {
                return Err(PublishError::VersionNotNewer {
                    object_id,
                    version,
                    current: current.version,
                });
            }
        }
        let object = state.objects.entry(object_id).or_default();
        object.shape = Some(Arc::clone(&frames));
        object.pose = None;
        if frames.new_frame {
            // Made in the frame before: it does not fit the new shape.
            object.body = None;
            object.frame_since_version = version;
        }
        for client in state.clients.values() {
            client.queue_shape(object_id, &frames);
        }
        self.shared.wake();
        for mirror in &state.mirrors {
            mirror.shape(object_id, &frames);
        }
        Ok(())
    }

    /// Publishes a new pose of an object whose shape is published (a rigid move, or that it
    /// was seen again). Returns at once; a newer pose replaces an unsent one.
    ///
    /// Errors: [`PublishError::PoseForUnknownShape`] if `pose.shape_version` is not the
    /// version of the object's published shape, [`PublishError::EncodePose`] for a pose the
    /// wire format refuses.
    pub fn pose(&self, pose: Pose) -> Result<(), PublishError> {
        let object_id = pose.object_id;
        let mut bytes = Vec::new();
        encode(&Message::Pose(pose), &mut bytes)
            .map_err(|cause| PublishError::EncodePose { object_id, cause })?;
        let frame = Arc::new(EncodedPose { pose, bytes });
        let mut state = lock(&self.shared.state);
        let current = state
            .objects
            .get(&object_id)
            .and_then(|o| o.shape.as_ref())
            .map(|shape| shape.version);
        if current != Some(pose.shape_version) {
            return Err(PublishError::PoseForUnknownShape {
                object_id,
                version: pose.shape_version,
                current,
            });
        }
        if let Some(object) = state.objects.get_mut(&object_id) {
            object.pose = Some(Arc::clone(&frame));
        }
        for client in state.clients.values() {
            client.queue_pose(object_id, &frame);
        }
        self.shared.wake();
        for mirror in &state.mirrors {
            mirror.pose(object_id, &frame);
        }
        Ok(())
    }

    /// Publishes an object's collision body, made from its shape of `body.shape_version`.
    /// Returns at once; a newer body replaces an unsent one. It stays the object's body, with
    /// its newer shapes too, until another body replaces it or a shape in a new frame comes.
    ///
    /// Errors: [`PublishError::BodyDoesNotFit`] when that shape was not published, or a shape
    /// in a new frame (or a newer body) has been published since; [`PublishError::EncodeBody`]
    /// for a body the wire format refuses.
    pub fn body(&self, body: Body) -> Result<(), PublishError> {
        let object_id = body.object_id;
        let version = body.shape_version;
        let encode_as = |encoding: Encoding| {
            frame_of(&Message::Body(Body {
                encoding,
                ..body.clone()
            }))
            .map_err(|cause| PublishError::EncodeBody { object_id, cause })
        };
        let frames = Arc::new(EncodedBody {
            shape_version: version,
            full: encode_as(Encoding::Full)?,
            compact: encode_as(Encoding::Compact)?,
        });
        let mut state = lock(&self.shared.state);
        let does_not_fit = |why: String| PublishError::BodyDoesNotFit {
            object_id,
            version,
            why,
        };
        let object = state
            .objects
            .get_mut(&object_id)
            .ok_or_else(|| does_not_fit("is not published (the object is unknown)".into()))?;
        let shape = object
            .shape
            .as_ref()
            .ok_or_else(|| does_not_fit("is not published".into()))?;
        if version > shape.version {
            return Err(does_not_fit(format!(
                "is newer than the published shape, version {}",
                shape.version
            )));
        }
        if version < object.frame_since_version {
            return Err(does_not_fit(format!(
                "is in another frame than the published shapes since version {}",
                object.frame_since_version
            )));
        }
        if let Some(held) = &object.body {
            if held.shape_version > version {
                return Err(does_not_fit(format!(
                    "is older than that of the published body, version {}",
                    held.shape_version
                )));
            }
        }
        object.body = Some(Arc::clone(&frames));
        for client in state.clients.values() {
            client.queue_body(object_id, &frames);
        }
        self.shared.wake();
        for mirror in &state.mirrors {
            mirror.body(object_id, &frames);
        }
        Ok(())
    }

    /// Publishes that an object is gone. An unsent mesh of it is not sent. Unknown ids are
    /// ignored. Returns at once.
    pub fn remove(&self, object_id: u64) {
        let mut state = lock(&self.shared.state);
        if state.objects.remove(&object_id).is_none() {
            return;
        }
        for client in state.clients.values() {
            client.queue_remove(object_id);
        }
        self.shared.wake();
        for mirror in &state.mirrors {
            mirror.remove(object_id);
        }
    }

    /// Publishes stats; a subscriber that has not yet been sent the previous stats gets only
    /// these. Returns at once. Errors: [`PublishError::EncodeStats`] for values the wire format
    /// refuses (a NaN or negative latency, a stage name over 64 bytes).
    pub fn stats(&self, stats: Stats) -> Result<(), PublishError> {
        let mut bytes = Vec::new();
        encode(&Message::Stats(stats), &mut bytes)
            .map_err(|source| PublishError::EncodeStats { cause: source })?;
        let frame = Arc::new(bytes);
        let state = lock(&self.shared.state);
        for client in state.clients.values() {
            client.queue_stats(&frame);
        }
        self.shared.wake();
        for mirror in &state.mirrors {
            mirror.stats(&frame);
        }
        Ok(())
    }

    /// Hands every update from now on to `mirror` too, starting with the current shape and pose
    /// of every object.
    pub fn add_mirror(&self, mirror: Arc<dyn Mirror>) {
        let mut state = lock(&self.shared.state);
        for (&object_id, frames) in &state.objects {
            if let Some(shape) = &frames.shape {
                mirror.shape(object_id, shape);
            }
            if let Some(body) = &frames.body {
                mirror.body(object_id, body);
            }
            if let Some(pose) = &frames.pose {
                mirror.pose(object_id, pose);
            }
        }
        state.mirrors.push(mirror);
    }

    /// Replaces who may subscribe (the daemon reads its allow lists again, so that a user
    /// removed from an allowed group loses access without a restart). `None` when the lists
    /// are the ones held already; else how many subscribers connected now the new lists do
    /// not admit, each told so in a Goodbye and dropped.
    pub fn set_allowed_peers(&self, allowed: Option<AllowedPeers>) -> Option<usize> {
        {
            let mut held = lock(&self.shared.allowed_peers);
            if *held == allowed {
                return None;
            }
            held.clone_from(&allowed);
        }
        let Some(allowed) = allowed else {
            return Some(0);
        };
        let clients: Vec<Arc<Client>> =
            lock(&self.shared.state).clients.values().cloned().collect();
        let mut revoked = 0;
        for client in clients {
            let Some(Peer { uid, gid, .. }) = client.peer else {
                continue;
            };
            if allowed.allows(uid, gid) {
                continue;
            }
            revoked += 1;
            client::dismiss_with_goodbye(
                &self.shared,
                &client,
                &format!(
                    "uid {uid} gid {gid} is no longer in the daemon's socket.allow_users or \
                     socket.allow_groups"
                ),
            );
        }
        Some(revoked)
    }

    /// The counters so far.
    pub fn counters(&self) -> PublisherCounters {
        let clients_connected = lock(&self.shared.state).clients.len();
        PublisherCounters {
            clients_connected,
            clients_dropped: self.shared.clients_dropped.load(Ordering::Relaxed),
            clients_refused: self.shared.clients_refused.load(Ordering::Relaxed),
            subscribes_throttled: self.shared.subscribes_throttled.load(Ordering::Relaxed),
            shapes_published: self.shared.shapes_published.load(Ordering::Relaxed),
            poses_published: self.shared.poses_published.load(Ordering::Relaxed),
            bodies_published: self.shared.bodies_published.load(Ordering::Relaxed),
            bytes_sent: self.shared.bytes_sent.load(Ordering::Relaxed),
        }
    }

    /// Says `Goodbye` with `reason` to every subscriber after the updates queued for it
    /// (waiting at most [`GOODBYE_GRACE`] for them to take both), closes their connections,
    /// stops every thread and removes the socket file. A subscriber that has not taken them
    /// within the grace is cut off. Calling it again does nothing; dropping the publisher
    /// calls it if it was not called.
    /// Takes `&self` so that a publisher shared between threads (in an `Arc`) can be shut down
    /// by whichever thread stops the daemon.
    pub fn shutdown(&self, reason: &str) {
        if self.shut_down.swap(true, Ordering::SeqCst) {
            return;
        }

        let mut goodbye = Vec::new();
        let reason_capped = cap_at_char_boundary(reason, MAX_REASON_BYTES);
        if let Err(error) = encode(
            &Message::Goodbye {
                reason: reason_capped.to_owned(),
            },
            &mut goodbye,
        ) {
            // Unreachable with a capped UTF-8 string; subscribers then just see the socket close.
            tracing::warn!("cannot encode Goodbye: {error}");
            goodbye.clear();
        }
        let goodbye = Arc::new(goodbye);

        let (clients, mirrors): (Vec<Arc<Client>>, Vec<Arc<dyn Mirror>>) = {
            let mut state = lock(&self.shared.state);
            state.stopping = true;
            (
                state.clients.values().cloned().collect(),
                std::mem::take(&mut state.mirrors),
            )
        };
        for mirror in &mirrors {
            mirror.shutdown();
        }
        for client in &clients {
            client.say_goodbye(&goodbye);
        }
        // The serving thread sees `stopping`, stops accepting, writes each subscriber what is
        // queued and the Goodbye, and ends when all have taken it or the grace is over.
        self.shared.wake();
        if let Some(serve) = lock(&self.serve).take() {
            let _ = serve.join();
        }
        bind::remove_if_ours(&self.path, self.file_id);
        tracing::info!("stopped publishing on {} ({reason})", self.path.display());
    }

    fn current_version(&self, object_id: u64) -> Option<u64> {
        lock(&self.shared.state)
            .objects
            .get(&object_id)
            .and_then(|object| object.shape.as_ref())
            .map(|shape| shape.version)
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        self.shutdown("the daemon is shutting down");
    }
}

/// One message as one frame.
fn frame_of(message: &Message) -> Result<Vec<u8>, WireError> {
    let mut bytes = Vec::new();
    encode(message, &mut bytes).map(|()| bytes)
}

pub(crate) fn cap_at_char_boundary(text: &str, max: usize) -> &str {
    if text.len() <= max {
        return text;
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// Tells a refused peer why, in a Goodbye instead of the Hello (docs/protocol.md), and closes
/// the connection. Best effort and bounded: the frame is small enough for the socket's buffer,
/// and a peer that cannot take it at once loses only the explanation. What the peer sent is
/// read first, since closing a Unix socket with unread data resets the connection and the
/// peer would then see "connection reset" instead of the reason.
fn refuse(mut stream: UnixStream, why: &str) {
    use std::io::{Read, Write};
    let mut goodbye = Vec::new();
    let reason = cap_at_char_boundary(why, MAX_REASON_BYTES).to_owned();
    if encode(&Message::Goodbye { reason }, &mut goodbye).is_err()
        || stream.set_nonblocking(true).is_err()
    {
        return;
    }
    let mut sent_by_peer = [0u8; 256];
    while matches!(stream.read(&mut sent_by_peer), Ok(n) if n > 0) {}
    let _ = stream.write_all(&goodbye);
    let _ = stream.shutdown(std::net::Shutdown::Write);
}

impl Shared {
    /// Wakes the serving thread (something was queued, or it is to stop).
    fn wake(&self) {
        // An eventfd write fails only when its counter is full, and then it is awake anyway.
        let _ = rustix::io::write(&self.waker, &1u64.to_ne_bytes());
    }

    /// Counts a refused subscriber; the first refusal and every power of two after it are
    /// logged (`refused a subscriber: {what} (N refused so far)`), so that a client retrying in
    /// a loop cannot flood the log.
    fn count_refusal(&self, what: &str) {
        let refused = self.clients_refused.fetch_add(1, Ordering::Relaxed) + 1;
        if refused.is_power_of_two() {
            tracing::warn!("refused a subscriber: {what} ({refused} refused so far)");
        }
    }

    /// Why a new subscriber of user `uid` is refused for the caps on subscribers, or `None`
    /// when there is room. Counted and logged as the refusals of the allow lists are.
    fn over_cap(&self, uid: Option<u32>) -> Option<String> {
        let (max, max_per_user) = self.max_subscribers;
        let why = {
            let state = lock(&self.state);
            let of_user = state
                .clients
                .values()
                .filter(|c| uid.is_some() && c.peer.map(|p| p.uid) == uid)
                .count();
            if state.clients.len() >= max {
                format!(
                    "the daemon serves at most {max} subscribers at once (socket.max_subscribers); \
                     try again when one has left"
                )
            } else if of_user >= max_per_user {
                format!(
                    "uid {} has {of_user} subscribers already, the most one user may have \
                     (socket.max_subscribers_per_user)",
                    uid.unwrap_or_default()
                )
            } else {
                return None;
            }
        };
        self.count_refusal(&why);
        Some(why)
    }

    /// Why [`PublisherConfig::allowed_peers`] does not admit the process at the other end, or
    /// `None` when it does. A refusal is counted; the first and every power of two after it
    /// are logged, so a client retrying in a loop cannot flood the log.
    fn peer_refusal(&self, peer: &std::io::Result<Peer>) -> Option<String> {
        let allowed = lock(&self.allowed_peers).clone()?;
        let (verdict, who) = match peer {
            Ok(Peer { uid, gid, pid }) => (
                allowed.allows(*uid, *gid),
                format!("uid {uid} gid {gid} (pid {pid})"),
            ),
            Err(error) => (
                false,
                format!("a peer whose credentials cannot be read ({error})"),
            ),
        };
        if verdict {
            return None;
        }
        self.count_refusal(&format!(
            "{who} is not in socket.allow_users / socket.allow_groups"
        ));
        Some(format!(
            "not allowed to subscribe: {who} is not in the daemon's socket.allow_users or \
             socket.allow_groups"
        ))
    }

    /// Unregisters a subscriber whose connection the serving thread closed; logs and counts
    /// how it left.
    fn retire(&self, client: &Client, how: Retire) {
        lock(&self.state).clients.remove(&client.id);
        match how {
            Retire::Quiet => {}
            Retire::Gone(why) => {
                if let Some(note) = lock(&self.connection_log).allow(Instant::now()) {
                    tracing::info!(client = client.id, "subscriber left: {why}{note}");
                }
            }
            Retire::Dropped(why) => {
                self.clients_dropped.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(client = client.id, "dropping subscriber: {why}");
            }
        }
    }
}

/// A budget of log lines: at most [`LogThrottle::LINES`] in each [`LogThrottle::WINDOW`], and
/// the next line after a silence says how many were left out. Thousands of connections a second
/// (a client in a tight reconnect loop) once wrote thousands of lines.
#[derive(Debug, Default)]
struct LogThrottle {
    window_start: Option<Instant>,
    in_window: u32,
    left_out: u64,
}

impl LogThrottle {
    const LINES: u32 = 20;
    const WINDOW: Duration = Duration::from_secs(10);

    /// `Some(note)` when a line may be written now (the note is empty, or says how many lines
    /// were left out before it); `None` when it is to be left out.
    fn allow(&mut self, now: Instant) -> Option<String> {
        let start = *self.window_start.get_or_insert(now);
        if now.saturating_duration_since(start) >= Self::WINDOW {
            self.window_start = Some(now);
            self.in_window = 0;
        }
        if self.in_window >= Self::LINES {
            self.left_out += 1;
            return None;
        }
        self.in_window += 1;
        let note = match std::mem::take(&mut self.left_out) {
            0 => String::new(),
            n => format!(" ({n} connection lines like this were left out)"),
        };
        Some(note)
    }
}
