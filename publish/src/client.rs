//! One subscriber: its pending updates, its writer thread and its reader thread.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{ErrorKind, Read, Write};
use std::net::Shutdown;
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tacmesh_protocol::{
    encode, FrameDecoder, Kinds, Message, Pose, Sender, Session, Subscribe, FIRST_SUPPORT_ID,
    MAX_REASON_BYTES,
};

use crate::{lock, Shared};

/// Write timeout for the Goodbye, so that shutdown is quick even for a stalled subscriber.
const GOODBYE_WRITE_TIMEOUT: Duration = Duration::from_millis(500);

/// The send buffer asked for when the daemon says Goodbye (see [`Client::say_goodbye`]).
const SHUTDOWN_SEND_BUFFER_BYTES: usize = 4 * 1024 * 1024;

/// A client has nothing legitimate to send that is longer than this (a Subscribe with the
/// most ids is 8 KiB), so more unparsed bytes than this mean it is not speaking the protocol.
const CLIENT_BUFFER_CAP: usize = 64 * 1024;

/// The frame of SnapshotDone: `01 00 00 00 04`.
const SNAPSHOT_DONE: [u8; 5] = [1, 0, 0, 0, 4];

/// An object's shape, encoded both ways (a subscriber asks for one), and its version.
pub struct EncodedShape {
    pub version: u64,
    /// The shape's `new_frame` flag: a body made from an earlier shape no longer fits.
    pub new_frame: bool,
    /// The pose inside it.
    pub pose: Pose,
    /// The Shape frame in [`Encoding::Full`](tacmesh_protocol::Encoding::Full).
    pub full: Vec<u8>,
    /// The Shape frame in [`Encoding::Compact`](tacmesh_protocol::Encoding::Compact).
    pub compact: Vec<u8>,
}

impl EncodedShape {
    /// The frame in `encoding`.
    pub fn bytes(&self, encoding: tacmesh_protocol::Encoding) -> &[u8] {
        match encoding {
            tacmesh_protocol::Encoding::Full => &self.full,
            tacmesh_protocol::Encoding::Compact => &self.compact,
        }
    }
}

/// A Pose frame and the pose it carries.
pub struct EncodedPose {
    pub pose: Pose,
    pub bytes: Vec<u8>,
}

/// An object's collision body, encoded both ways (its proxy mesh in a subscriber's encoding),
/// and the shape version it was made from.
pub struct EncodedBody {
    pub shape_version: u64,
    /// The Body frame with its proxy in [`Encoding::Full`](tacmesh_protocol::Encoding::Full).
    pub full: Vec<u8>,
    /// The Body frame with its proxy in
    /// [`Encoding::Compact`](tacmesh_protocol::Encoding::Compact).
    pub compact: Vec<u8>,
}

impl EncodedBody {
    /// The frame in `encoding`.
    pub fn bytes(&self, encoding: tacmesh_protocol::Encoding) -> &[u8] {
        match encoding {
            tacmesh_protocol::Encoding::Full => &self.full,
            tacmesh_protocol::Encoding::Compact => &self.compact,
        }
    }
}

/// What is current of one object: its shape, its collision body, and a pose newer than the one
/// inside the shape.
#[derive(Clone, Default)]
pub(crate) struct ObjectFrames {
    pub(crate) shape: Option<Arc<EncodedShape>>,
    pub(crate) body: Option<Arc<EncodedBody>>,
    pub(crate) pose: Option<Arc<EncodedPose>>,
    /// The first shape version in the object's current frame (the last shape with the
    /// `new_frame` flag, or 0): a body made from an earlier one does not fit. Kept by the
    /// publisher's current state only.
    pub(crate) frame_since_version: u64,
}

impl ObjectFrames {
    fn is_empty(&self) -> bool {
        self.shape.is_none() && self.body.is_none() && self.pose.is_none()
    }

    /// These frames as `options` let them through: without the body unless bodies are asked for.
    fn for_options(&self, options: &Subscribe) -> ObjectFrames {
        ObjectFrames {
            body: self
                .body
                .clone()
                .filter(|_| options.kinds.contains(Kinds::BODIES)),
            ..self.clone()
        }
    }
}

/// How a subscriber leaves, for the one log line.
pub(crate) enum Retire {
    /// Shutdown, or the other thread already said why.
    Quiet,
    /// It disconnected (INFO).
    Gone(String),
    /// It misbehaved and is dropped (WARN, counted).
    Dropped(String),
}

/// What is waiting to be written to one subscriber. Bounded by the number of objects.
#[derive(Default)]
struct Updates {
    /// A snapshot is to be written first: Session, `objects`, SnapshotDone.
    snapshot: bool,
    /// The latest unsent shape, body and pose of each object.
    objects: BTreeMap<u64, ObjectFrames>,
    /// Unsent removes; an id is never in both.
    removes: BTreeSet<u64>,
    /// The latest unsent stats frame.
    stats: Option<Arc<Vec<u8>>>,
}

impl Updates {
    fn is_empty(&self) -> bool {
        !self.snapshot && self.objects.is_empty() && self.removes.is_empty() && self.stats.is_none()
    }
}

struct Pending {
    updates: Updates,
    options: Subscribe,
    goodbye: Option<Arc<Vec<u8>>>,
    closed: bool,
}

/// Whether `options` let an object through to the subscriber.
fn passes(options: &Subscribe, object_id: u64) -> bool {
    let kind = if object_id >= FIRST_SUPPORT_ID {
        Kinds::SUPPORTS
    } else {
        Kinds::OBJECTS
    };
    options.kinds.contains(kind)
        && (options.object_ids.is_empty() || options.object_ids.contains(&object_id))
}

/// The objects of `current` that `options` let through.
fn filtered(
    current: &BTreeMap<u64, ObjectFrames>,
    options: &Subscribe,
) -> BTreeMap<u64, ObjectFrames> {
    current
        .iter()
        .filter(|(&id, _)| passes(options, id))
        .map(|(&id, frames)| (id, frames.for_options(options)))
        .filter(|(_, frames)| !frames.is_empty())
        .collect()
}

/// Who is at the other end of a subscriber's connection, as the kernel reported it
/// (`SO_PEERCRED`) when it connected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Peer {
    pub(crate) uid: u32,
    pub(crate) gid: u32,
    pub(crate) pid: i32,
}

impl Peer {
    pub(crate) fn of(stream: &UnixStream) -> std::io::Result<Peer> {
        let cred = rustix::net::sockopt::socket_peercred(stream)?;
        Ok(Peer {
            uid: cred.uid.as_raw(),
            gid: cred.gid.as_raw(),
            pid: cred.pid.as_raw_nonzero().get(),
        })
    }
}

pub(crate) struct Client {
    pub(crate) id: u64,
    /// The user and primary group at the other end (`SO_PEERCRED`, fixed when it connected):
    /// for the per-user cap and for allow lists read again later.
    pub(crate) peer: Option<Peer>,
    stream: UnixStream,
    pending: Mutex<Pending>,
    wake: Condvar,
    /// Set with `goodbye`: a write error after it is the shutdown's, not the subscriber's.
    leaving: AtomicBool,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl Client {
    pub(crate) fn new(
        id: u64,
        stream: UnixStream,
        peer: Option<Peer>,
        current: &BTreeMap<u64, ObjectFrames>,
    ) -> Self {
        let options = Subscribe::default();
        Self {
            id,
            peer,
            stream,
            pending: Mutex::new(Pending {
                updates: Updates {
                    snapshot: true,
                    objects: filtered(current, &options),
                    ..Updates::default()
                },
                options,
                goodbye: None,
                closed: false,
            }),
            wake: Condvar::new(),
            leaving: AtomicBool::new(false),
            threads: Mutex::new(Vec::new()),
        }
    }

    /// A new shape of an object (it replaces an unsent shape and pose of it, and an unsent
    /// body when the shape is in a new frame).
    pub(crate) fn queue_shape(&self, object_id: u64, frames: &Arc<EncodedShape>) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) {
            return;
        }
        pending.updates.removes.remove(&object_id);
        let queued = pending.updates.objects.entry(object_id).or_default();
        queued.shape = Some(Arc::clone(frames));
        queued.pose = None;
        if frames.new_frame {
            queued.body = None;
        }
        drop(pending);
        self.wake.notify_one();
    }

    /// A new collision body of an object (it replaces an unsent body, and goes after an
    /// unsent shape), if the subscriber asked for bodies.
    pub(crate) fn queue_body(&self, object_id: u64, frames: &Arc<EncodedBody>) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) || !pending.options.kinds.contains(Kinds::BODIES) {
            return;
        }
        pending.updates.objects.entry(object_id).or_default().body = Some(Arc::clone(frames));
        drop(pending);
        self.wake.notify_one();
    }

    /// A new pose of an object (it replaces an unsent pose, and goes after an unsent shape).
    pub(crate) fn queue_pose(&self, object_id: u64, frame: &Arc<EncodedPose>) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) {
            return;
        }
        pending.updates.objects.entry(object_id).or_default().pose = Some(Arc::clone(frame));
        drop(pending);
        self.wake.notify_one();
    }

    pub(crate) fn queue_remove(&self, object_id: u64) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) {
            return;
        }
        pending.updates.objects.remove(&object_id);
        pending.updates.removes.insert(object_id);
        drop(pending);
        self.wake.notify_one();
    }

    pub(crate) fn queue_stats(&self, frame: &Arc<Vec<u8>>) {
        lock(&self.pending).updates.stats = Some(Arc::clone(frame));
        self.wake.notify_one();
    }

    /// Takes the subscriber's new options; with `resend`, what is pending gives way to a
    /// snapshot of `current` under them. Called with the publisher's state locked (so that no
    /// update can come between the snapshot and the next update).
    fn resubscribe(&self, options: Subscribe, current: &BTreeMap<u64, ObjectFrames>) {
        let mut pending = lock(&self.pending);
        if options.resend {
            let stats = pending.updates.stats.take();
            pending.updates = Updates {
                snapshot: true,
                objects: filtered(current, &options),
                stats,
                ..Updates::default()
            };
        } else {
            let Updates {
                objects, removes, ..
            } = &mut pending.updates;
            objects.retain(|&id, frames| {
                *frames = frames.for_options(&options);
                passes(&options, id) && !frames.is_empty()
            });
            removes.retain(|&id| passes(&options, id));
        }
        pending.options = options;
        drop(pending);
        self.wake.notify_one();
    }

    /// The subscriber is told `frame` (a Goodbye) instead of anything still pending, and let go.
    fn dismiss(&self, frame: Vec<u8>) {
        let mut pending = lock(&self.pending);
        pending.updates = Updates::default();
        pending.goodbye = Some(Arc::new(frame));
        drop(pending);
        self.leaving.store(true, Ordering::Relaxed);
        self.wake.notify_one();
    }

    pub(crate) fn say_goodbye(&self, frame: &Arc<Vec<u8>>) {
        // Freshness no longer matters: a socket buffer large enough for what is queued and the
        // Goodbye lets a client that is not reading just now find both when it reads, after the
        // daemon has gone (the kernel keeps what was written). With the small buffer such a
        // client would be cut off at the end of the grace without its Goodbye. Raising it wakes
        // a writer blocked on the small one; the kernel caps it at net.core.wmem_max.
        let _ = rustix::net::sockopt::set_socket_send_buffer_size(
            &self.stream,
            SHUTDOWN_SEND_BUFFER_BYTES,
        );
        lock(&self.pending).goodbye = Some(Arc::clone(frame));
        self.leaving.store(true, Ordering::Relaxed);
        self.wake.notify_one();
    }

    pub(crate) fn take_threads(&self) -> Vec<JoinHandle<()>> {
        std::mem::take(&mut *lock(&self.threads))
    }

    /// Marks the subscriber closed and shuts its socket down, which unblocks both threads.
    /// Returns whether this call closed it (false if it was closed already).
    pub(crate) fn close(&self) -> bool {
        let first = !std::mem::replace(&mut lock(&self.pending).closed, true);
        self.wake.notify_all();
        let _ = self.stream.shutdown(Shutdown::Both);
        first
    }

    fn is_closed(&self) -> bool {
        lock(&self.pending).closed
    }
}

pub(crate) fn start_threads(shared: &Arc<Shared>, client: &Arc<Client>) -> std::io::Result<()> {
    let (writer_shared, writer_client) = (Arc::clone(shared), Arc::clone(client));
    let writer = std::thread::Builder::new()
        .name(format!("publish-w{}", client.id))
        .spawn(move || {
            let how = write_loop(&writer_shared, &writer_client);
            writer_shared.retire(&writer_client, how);
        })?;
    lock(&client.threads).push(writer);
    let (reader_shared, reader_client) = (Arc::clone(shared), Arc::clone(client));
    let reader = std::thread::Builder::new()
        .name(format!("publish-r{}", client.id))
        .spawn(move || {
            if let Some(how) = read_loop(&reader_shared, &reader_client) {
                reader_shared.retire(&reader_client, how);
            }
        })?;
    lock(&client.threads).push(reader);
    Ok(())
}

/// A batch the writer took, with the options it is to be written under.
struct Batch {
    updates: Updates,
    options: Subscribe,
}

enum Next {
    Updates(Batch),
    /// The Goodbye, and what was still pending when it came (flushed first).
    Goodbye(Arc<Vec<u8>>, Batch),
    Closed,
}

/// What the writer knows of what it wrote to its subscriber, per object: when it last wrote
/// an update of it (for the rate cap) and the last pose it told (for extrapolating clients).
#[derive(Default)]
struct Written {
    at: std::collections::HashMap<u64, Instant>,
    pose: std::collections::HashMap<u64, Pose>,
}

/// Takes what may be written now: everything, except the updates of objects written
/// less than 1/`max_rate_hz` ago (a snapshot takes everything). For a client that
/// extrapolates poses, a Pose its extrapolation already matches is dropped, not sent. Returns
/// the batch and when the earliest held-back object may go.
fn take_due(pending: &mut Pending, written: &Written, now: Instant) -> (Updates, Option<Instant>) {
    if pending.options.extrapolate && !pending.updates.snapshot {
        pending.updates.objects.retain(|id, frames| {
            if let (None, Some(pose), Some(told)) =
                (&frames.shape, &frames.pose, written.pose.get(id))
            {
                if !told.extrapolation_misses(&pose.pose) {
                    frames.pose = None;
                }
            }
            !frames.is_empty()
        });
    }
    let last_sent = &written.at;
    let rate = pending.options.max_rate_hz;
    if pending.updates.snapshot || rate <= 0.0 {
        return (std::mem::take(&mut pending.updates), None);
    }
    // The decoder holds a rate to MIN_RATE_HZ..=MAX_RATE_HZ, so these cannot fail; a rate
    // that got past it anyway is taken as no cap rather than as a panic.
    let Ok(interval) = Duration::try_from_secs_f32(1.0 / rate) else {
        return (std::mem::take(&mut pending.updates), None);
    };
    let mut next_due: Option<Instant> = None;
    let mut due = BTreeMap::new();
    pending.updates.objects.retain(|&id, frames| {
        match last_sent.get(&id).and_then(|&at| at.checked_add(interval)) {
            Some(at) if at > now => {
                next_due = Some(next_due.map_or(at, |n| n.min(at)));
                true
            }
            _ => {
                due.insert(id, std::mem::take(frames));
                false
            }
        }
    });
    let updates = Updates {
        snapshot: false,
        objects: due,
        removes: std::mem::take(&mut pending.updates.removes),
        stats: pending.updates.stats.take(),
    };
    (updates, next_due)
}

/// Writes Hello, the snapshot, then updates as they come; returns how it ended.
fn write_loop(shared: &Shared, client: &Client) -> Retire {
    match write_all_frames(shared, client) {
        Ok(()) => Retire::Quiet,
        Err(_) if client.is_closed() || client.leaving.load(Ordering::Relaxed) => Retire::Quiet,
        Err(WriteFailure { error, unsent })
            if matches!(error.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) =>
        {
            let why = format!(
                "it read nothing for {} s",
                shared.write_timeout.as_secs_f32()
            );
            if farewell(client, &unsent, &why) {
                Retire::Dropped(format!("{why} (told so in a Goodbye)"))
            } else {
                Retire::Dropped(why)
            }
        }
        // A subscriber that closed its end: its reader saw the end of its input, and only a
        // write tells a half-closed connection (still reading) from a closed one.
        Err(WriteFailure { error, .. })
            if matches!(
                error.kind(),
                ErrorKind::BrokenPipe | ErrorKind::ConnectionReset
            ) =>
        {
            Retire::Gone("disconnected".into())
        }
        Err(WriteFailure { error, .. }) => Retire::Gone(format!("write failed: {error}")),
    }
}

/// A write that failed, with what of its frame had not gone out (a write timeout can strike
/// in the middle of a frame).
struct WriteFailure {
    error: std::io::Error,
    unsent: Vec<u8>,
}

impl From<std::io::Error> for WriteFailure {
    fn from(error: std::io::Error) -> Self {
        Self {
            error,
            unsent: Vec::new(),
        }
    }
}

/// Tells a subscriber dropped for not reading why, if the socket can still take it: the
/// buffer is raised (as at shutdown, up to `net.core.wmem_max`) and the rest of the frame it
/// stalled in is written first, so that its stream stays whole and ends in a Goodbye it
/// finds when it reads again. Returns whether the Goodbye was written; bounded by
/// [`GOODBYE_WRITE_TIMEOUT`].
fn farewell(client: &Client, unsent: &[u8], why: &str) -> bool {
    let mut goodbye = Vec::new();
    let reason = format!("dropped: {why}");
    if encode(&Message::Goodbye { reason }, &mut goodbye).is_err() {
        return false;
    }
    let _ = rustix::net::sockopt::set_socket_send_buffer_size(
        &client.stream,
        SHUTDOWN_SEND_BUFFER_BYTES,
    );
    if client
        .stream
        .set_write_timeout(Some(GOODBYE_WRITE_TIMEOUT))
        .is_err()
    {
        return false;
    }
    let mut stream = &client.stream;
    stream.write_all(unsent).is_ok() && stream.write_all(&goodbye).is_ok()
}

fn write_all_frames(shared: &Shared, client: &Client) -> Result<(), WriteFailure> {
    // By hand rather than `write_all`, to know what of a frame is left when a write fails.
    let send = |bytes: &[u8]| -> Result<(), WriteFailure> {
        let mut written = 0;
        while written < bytes.len() {
            match (&client.stream).write(&bytes[written..]) {
                Ok(0) => {
                    return Err(WriteFailure {
                        error: ErrorKind::WriteZero.into(),
                        unsent: bytes[written..].to_vec(),
                    })
                }
                Ok(n) => {
                    written += n;
                    shared.bytes_sent.fetch_add(n as u64, Ordering::Relaxed);
                }
                Err(error) if error.kind() == ErrorKind::Interrupted => {}
                Err(error) => {
                    return Err(WriteFailure {
                        error,
                        unsent: bytes[written..].to_vec(),
                    })
                }
            }
        }
        Ok(())
    };
    send(&shared.hello)?;
    let mut written = Written::default();
    loop {
        let next = {
            let mut pending = lock(&client.pending);
            loop {
                if pending.closed {
                    break Next::Closed;
                }
                if let Some(goodbye) = pending.goodbye.take() {
                    let batch = Batch {
                        updates: std::mem::take(&mut pending.updates),
                        options: pending.options.clone(),
                    };
                    break Next::Goodbye(goodbye, batch);
                }
                let now = Instant::now();
                let (updates, next_due) = take_due(&mut pending, &written, now);
                if !updates.is_empty() {
                    break Next::Updates(Batch {
                        updates,
                        options: pending.options.clone(),
                    });
                }
                pending = match next_due {
                    Some(at) => {
                        client
                            .wake
                            .wait_timeout(pending, at.saturating_duration_since(now))
                            .unwrap_or_else(std::sync::PoisonError::into_inner)
                            .0
                    }
                    None => client
                        .wake
                        .wait(pending)
                        .unwrap_or_else(std::sync::PoisonError::into_inner),
                };
            }
        };
        match next {
            Next::Closed => return Ok(()),
            Next::Goodbye(frame, batch) => {
                // What was queued before the Goodbye is sent first (bounded: each write by
                // GOODBYE_WRITE_TIMEOUT, the whole by the publisher's grace, after which the
                // socket is closed under the writer).
                client
                    .stream
                    .set_write_timeout(Some(GOODBYE_WRITE_TIMEOUT))?;
                send_batch(&send, shared, client, &batch, &mut written)?;
                send(&frame)?;
                let _ = client.stream.shutdown(Shutdown::Both);
                return Ok(());
            }
            Next::Updates(batch) => {
                send_batch(&send, shared, client, &batch, &mut written)?;
            }
        }
    }
}

/// Writes one batch: a Session first if it is a snapshot, each object's shape, body and pose
/// (then SnapshotDone for a snapshot), the removes and the stats.
fn send_batch(
    send: &impl Fn(&[u8]) -> Result<(), WriteFailure>,
    shared: &Shared,
    client: &Client,
    batch: &Batch,
    written: &mut Written,
) -> Result<(), WriteFailure> {
    let Batch { updates, options } = batch;
    let mut bytes = Vec::new();
    let to_io = |error: tacmesh_protocol::WireError| {
        WriteFailure::from(std::io::Error::other(error.to_string()))
    };
    if updates.snapshot {
        let (monotonic_ns, realtime_ns) = tacmesh_source::now_on_both_clocks_ns();
        let session = Session {
            monotonic_ns,
            realtime_ns,
            options: options.clone(),
        };
        encode(&Message::Session(session), &mut bytes).map_err(to_io)?;
        send(&bytes)?;
    }
    let now = Instant::now();
    for (&object_id, frames) in &updates.objects {
        if let Some(shape) = &frames.shape {
            send(shape.bytes(options.encoding))?;
            written.pose.insert(object_id, shape.pose);
            shared.shapes_published.fetch_add(1, Ordering::Relaxed);
            tracing::trace!(
                client = client.id,
                object_id,
                version = shape.version,
                "sent shape"
            );
        }
        if let Some(body) = &frames.body {
            send(body.bytes(options.encoding))?;
            shared.bodies_published.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(pose) = &frames.pose {
            send(&pose.bytes)?;
            written.pose.insert(object_id, pose.pose);
            shared.poses_published.fetch_add(1, Ordering::Relaxed);
        }
        if !frames.is_empty() {
            written.at.insert(object_id, now);
        }
    }
    if updates.snapshot {
        send(&SNAPSHOT_DONE)?;
    }
    for &object_id in &updates.removes {
        bytes.clear();
        encode(&Message::Remove { object_id }, &mut bytes).map_err(to_io)?;
        send(&bytes)?;
        written.at.remove(&object_id);
        written.pose.remove(&object_id);
    }
    if let Some(stats) = &updates.stats {
        send(stats)?;
    }
    Ok(())
}

/// Why a subscriber's connection ended under its reader: `buffered` bytes of a frame it had
/// begun, and the read error if it was not a plain end of input. A subscriber that hangs up
/// with data it never read is seen as a reset, not an end of input, and a frame it left half
/// sent is named either way.
pub(crate) fn gone_while_reading(buffered: usize, error: Option<&std::io::Error>) -> Retire {
    let half_frame = format!("in the middle of a frame ({buffered} bytes unparsed)");
    Retire::Gone(match (buffered, error) {
        (0, None) => "disconnected".to_owned(),
        (0, Some(error)) => format!("read failed: {error}"),
        (_, None) => format!("disconnected {half_frame}"),
        (_, Some(error)) => format!("read failed {half_frame}: {error}"),
    })
}

/// Reads what the subscriber sends until it disconnects or misbehaves; returns how it ended, or
/// `None` when the subscriber only stopped sending (the end of its input at a frame boundary)
/// or was told to go.
fn read_loop(shared: &Shared, client: &Client) -> Option<Retire> {
    let mut decoder = FrameDecoder::new(Sender::Client);
    let mut buffer = [0u8; 4096];
    let mut last_subscribe: Option<Instant> = None;
    loop {
        let read = match (&client.stream).read(&mut buffer) {
            Ok(0) if client.is_closed() => return Some(Retire::Quiet),
            Ok(0) if decoder.buffered_len() > 0 => {
                return Some(gone_while_reading(decoder.buffered_len(), None))
            }
            // The subscriber sends nothing more. Closed whole, it is gone now (it holds a place
            // under the caps otherwise until the next write to it fails); with only its
            // sending side closed it still reads (the server needs nothing from it), and this
            // thread just ends.
            Ok(0) if peer_closed(&client.stream) => {
                return Some(Retire::Gone("disconnected".to_owned()))
            }
            Ok(0) => return None,
            Ok(read) => read,
            Err(error) if error.kind() == ErrorKind::Interrupted => continue,
            Err(_) if client.is_closed() => return Some(Retire::Quiet),
            Err(error) => return Some(gone_while_reading(decoder.buffered_len(), Some(&error))),
        };
        decoder.push(&buffer[..read]);
        loop {
            match decoder.next_message() {
                Ok(Some(Message::Subscribe(options))) => {
                    tracing::debug!(client = client.id, ?options, "subscriber sent Subscribe");
                    // One Subscribe acted on per RESUBSCRIBE_INTERVAL: a sooner one waits here,
                    // and what the client sends meanwhile backs up in its own socket.
                    if let Some(earliest) =
                        last_subscribe.and_then(|at| at.checked_add(crate::RESUBSCRIBE_INTERVAL))
                    {
                        let wait = earliest.saturating_duration_since(Instant::now());
                        if !wait.is_zero() {
                            shared.subscribes_throttled.fetch_add(1, Ordering::Relaxed);
                            std::thread::sleep(wait);
                        }
                    }
                    last_subscribe = Some(Instant::now());
                    let state = lock(&shared.state);
                    client.resubscribe(options, &state.objects);
                }
                Ok(Some(Message::SubscribeV1)) => {
                    refuse_version_1(shared, client);
                    return None;
                }
                Ok(Some(other)) => {
                    // The decoder refuses server kinds already; this is for kinds added later.
                    let why = format!("it sent {}, which a subscriber may not send", other.name());
                    dismiss_with_goodbye(shared, client, &why);
                    return None;
                }
                Ok(None) => break,
                Err(error) => {
                    dismiss_with_goodbye(shared, client, &format!("it sent a bad frame: {error}"));
                    return None;
                }
            }
        }
        if decoder.buffered_len() > CLIENT_BUFFER_CAP {
            let why = format!(
                "it sent {} bytes without completing a frame; subscriber frames are a few bytes",
                decoder.buffered_len()
            );
            dismiss_with_goodbye(shared, client, &why);
            return None;
        }
    }
}

/// Whether the peer closed its socket whole (both directions), not just its sending side: the
/// kernel reports a hang-up (`POLLHUP`) for a Unix socket only when both are shut down.
fn peer_closed(stream: &UnixStream) -> bool {
    use rustix::event::{poll, PollFd, PollFlags, Timespec};
    let mut fds = [PollFd::new(stream, PollFlags::OUT)];
    let now = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    poll(&mut fds, Some(&now)).is_ok() && fds[0].revents().contains(PollFlags::HUP)
}

/// A subscriber broke the protocol: it is counted as dropped, the log says why, and so does the
/// Goodbye its writer sends before closing (what was queued for it is discarded), so that a
/// client with a bug learns what it did. Everyone else is served as before.
pub(crate) fn dismiss_with_goodbye(shared: &Shared, client: &Client, why: &str) {
    shared.clients_dropped.fetch_add(1, Ordering::Relaxed);
    tracing::warn!(client = client.id, "dropping subscriber: {why}");
    let reason =
        crate::cap_at_char_boundary(&format!("dropped: {why}"), MAX_REASON_BYTES).to_owned();
    let mut frame = Vec::new();
    if encode(&Message::Goodbye { reason }, &mut frame).is_ok() {
        client.dismiss(frame);
    } else {
        client.close();
    }
}

/// A version-1 client sent its Subscribe: it is told in a Goodbye that this server speaks
/// version 2 (it may not have checked the Hello) and let go; counted as dropped.
fn refuse_version_1(shared: &Shared, client: &Client) {
    let reason = format!(
        "this daemon speaks tacmesh protocol version {}; the client sent a version-1 Subscribe: \
         use a client from the same release",
        tacmesh_protocol::PROTOCOL_VERSION
    );
    shared.clients_dropped.fetch_add(1, Ordering::Relaxed);
    tracing::warn!(
        client = client.id,
        "dropping subscriber: it speaks protocol version 1"
    );
    let mut frame = Vec::new();
    if encode(&Message::Goodbye { reason }, &mut frame).is_ok() {
        client.dismiss(frame);
    } else {
        client.close();
    }
}
