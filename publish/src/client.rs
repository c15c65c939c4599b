//! One subscriber: what is pending for it, and how a batch of it becomes bytes on its wire.
//! The connection itself (reading, writing, timers) is the event loop's, in `serve.rs`.

use std::collections::{BTreeMap, BTreeSet};
use std::os::unix::net::UnixStream;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tacmesh_protocol::{
    encode, Kinds, Message, Pose, Session, Subscribe, FIRST_SUPPORT_ID, MAX_REASON_BYTES,
};

use crate::{lock, Shared};

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
#[derive(Clone)]
pub(crate) enum Retire {
    /// Shutdown, or it was already said why.
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
    /// A Goodbye to send after what is already on its way, instead of anything pending.
    goodbye: Option<Arc<Vec<u8>>>,
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

/// What the pipeline's threads and the event loop share of one subscriber: who it is and what
/// is pending for it. The `queue_*` calls are made with the publisher's state locked; the caller
/// wakes the event loop afterwards.
pub(crate) struct Client {
    pub(crate) id: u64,
    /// The user and primary group at the other end (`SO_PEERCRED`, fixed when it connected):
    /// for the per-user cap and for allow lists read again later.
    pub(crate) peer: Option<Peer>,
    pending: Mutex<Pending>,
}

impl Client {
    pub(crate) fn new(id: u64, peer: Option<Peer>, current: &BTreeMap<u64, ObjectFrames>) -> Self {
        let options = Subscribe::default();
        Self {
            id,
            peer,
            pending: Mutex::new(Pending {
                updates: Updates {
                    snapshot: true,
                    objects: filtered(current, &options),
                    ..Updates::default()
                },
                options,
                goodbye: None,
            }),
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
    }

    /// A new collision body of an object (it replaces an unsent body, and goes after an
    /// unsent shape), if the subscriber asked for bodies.
    pub(crate) fn queue_body(&self, object_id: u64, frames: &Arc<EncodedBody>) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) || !pending.options.kinds.contains(Kinds::BODIES) {
            return;
        }
        pending.updates.objects.entry(object_id).or_default().body = Some(Arc::clone(frames));
    }

    /// A new pose of an object (it replaces an unsent pose, and goes after an unsent shape).
    pub(crate) fn queue_pose(&self, object_id: u64, frame: &Arc<EncodedPose>) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) {
            return;
        }
        pending.updates.objects.entry(object_id).or_default().pose = Some(Arc::clone(frame));
    }

    pub(crate) fn queue_remove(&self, object_id: u64) {
        let mut pending = lock(&self.pending);
        if !passes(&pending.options, object_id) {
            return;
        }
        pending.updates.objects.remove(&object_id);
        pending.updates.removes.insert(object_id);
    }

    pub(crate) fn queue_stats(&self, frame: &Arc<Vec<u8>>) {
        lock(&self.pending).updates.stats = Some(Arc::clone(frame));
    }

    /// Takes the subscriber's new options; with `resend`, what is pending gives way to a
    /// snapshot of `current` under them. Called with the publisher's state locked (so that no
    /// update can come between the snapshot and the next update).
    pub(crate) fn resubscribe(&self, options: Subscribe, current: &BTreeMap<u64, ObjectFrames>) {
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
    }

    /// The subscriber is told `frame` (a Goodbye) instead of anything still pending, and let go.
    fn dismiss(&self, frame: Vec<u8>) {
        let mut pending = lock(&self.pending);
        pending.updates = Updates::default();
        pending.goodbye = Some(Arc::new(frame));
    }

    /// The daemon stops: the subscriber is told `frame` after what is pending for it.
    pub(crate) fn say_goodbye(&self, frame: &Arc<Vec<u8>>) {
        lock(&self.pending).goodbye = Some(Arc::clone(frame));
    }

    /// Whether a Goodbye waits to be written after what is on its way.
    pub(crate) fn has_goodbye(&self) -> bool {
        lock(&self.pending).goodbye.is_some()
    }

    /// What the event loop is to write next: a Goodbye with everything still pending before
    /// it, else the updates due now (see [`take_due`]) and when the next held-back one is due.
    pub(crate) fn take_next(&self, written: &Written, now: Instant) -> Next {
        let mut pending = lock(&self.pending);
        let options = pending.options.clone();
        if let Some(goodbye) = pending.goodbye.take() {
            let updates = std::mem::take(&mut pending.updates);
            return Next::Goodbye(goodbye, Batch { updates, options });
        }
        let (updates, next_due) = take_due(&mut pending, written, now);
        Next::Updates(Batch { updates, options }, next_due)
    }
}

/// A batch taken to be written, with the options it is to be written under.
pub(crate) struct Batch {
    updates: Updates,
    options: Subscribe,
}

impl Batch {
    pub(crate) fn is_empty(&self) -> bool {
        self.updates.is_empty()
    }
}

/// What [`Client::take_next`] found.
pub(crate) enum Next {
    /// The updates due now (perhaps none), and when the earliest held-back one may go.
    Updates(Batch, Option<Instant>),
    /// The Goodbye, and what was still pending when it came (written first).
    Goodbye(Arc<Vec<u8>>, Batch),
}

/// What was written to a subscriber, per object: when an update of it was last taken (for the
/// rate cap) and the last pose told (for extrapolating clients).
#[derive(Default)]
pub(crate) struct Written {
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

/// Appends one batch to `out`: a Session first if it is a snapshot, each object's shape, body
/// and pose (then SnapshotDone for a snapshot), the removes and the stats. Counted as published
/// here: the frames are on their way, behind at most what the connection already holds.
pub(crate) fn encode_batch(
    shared: &Shared,
    client_id: u64,
    batch: &Batch,
    written: &mut Written,
    out: &mut Vec<u8>,
) {
    let Batch { updates, options } = batch;
    if updates.snapshot {
        let (monotonic_ns, realtime_ns) = tacmesh_source::now_on_both_clocks_ns();
        let session = Session {
            monotonic_ns,
            realtime_ns,
            options: options.clone(),
        };
        // Options that came through the decoder encode again; if one ever did not, the
        // client gets the snapshot without its Session rather than nothing.
        if let Err(error) = encode(&Message::Session(session), out) {
            tracing::warn!(client = client_id, "cannot encode a Session: {error}");
        }
    }
    let now = Instant::now();
    for (&object_id, frames) in &updates.objects {
        if let Some(shape) = &frames.shape {
            out.extend_from_slice(shape.bytes(options.encoding));
            written.pose.insert(object_id, shape.pose);
            shared.shapes_published.fetch_add(1, Ordering::Relaxed);
            tracing::trace!(
                client = client_id,
                object_id,
                version = shape.version,
                "sent shape"
            );
        }
        if let Some(body) = &frames.body {
            out.extend_from_slice(body.bytes(options.encoding));
            shared.bodies_published.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(pose) = &frames.pose {
            out.extend_from_slice(&pose.bytes);
            written.pose.insert(object_id, pose.pose);
            shared.poses_published.fetch_add(1, Ordering::Relaxed);
        }
        if !frames.is_empty() {
            written.at.insert(object_id, now);
        }
    }
    if updates.snapshot {
        out.extend_from_slice(&SNAPSHOT_DONE);
    }
    for &object_id in &updates.removes {
        // A Remove of any id encodes.
        let _ = encode(&Message::Remove { object_id }, out);
        written.at.remove(&object_id);
        written.pose.remove(&object_id);
    }
    if let Some(stats) = &updates.stats {
        out.extend_from_slice(stats);
    }
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

/// Whether the peer closed its socket whole (both directions), not just its sending side: the
/// kernel reports a hang-up (`POLLHUP`) for a Unix socket only when both are shut down.
pub(crate) fn peer_closed(stream: &UnixStream) -> bool {
    use rustix::event::{poll, PollFd, PollFlags, Timespec};
    let mut fds = [PollFd::new(stream, PollFlags::OUT)];
    let now = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    poll(&mut fds, Some(&now)).is_ok() && fds[0].revents().contains(PollFlags::HUP)
}

/// A subscriber broke the protocol: it is counted as dropped, the log says why, and so does the
/// Goodbye sent before closing (what was queued for it is discarded), so that a
/// client with a bug learns what it did. Everyone else is served as before.
pub(crate) fn dismiss_with_goodbye(shared: &Shared, client: &Client, why: &str) {
    shared.clients_dropped.fetch_add(1, Ordering::Relaxed);
    tracing::warn!(client = client.id, "dropping subscriber: {why}");
    let reason =
        crate::cap_at_char_boundary(&format!("dropped: {why}"), MAX_REASON_BYTES).to_owned();
    let mut frame = Vec::new();
    if encode(&Message::Goodbye { reason }, &mut frame).is_err() {
        // Unreachable: the reason is capped to what a Goodbye holds.
        frame = Vec::new();
    }
    client.dismiss(frame);
    shared.wake();
}

/// A version-1 client sent its Subscribe: it is told in a Goodbye that this server speaks
/// version 2 (it may not have checked the Hello) and let go; counted as dropped.
pub(crate) fn refuse_version_1(shared: &Shared, client: &Client) {
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
    if encode(&Message::Goodbye { reason }, &mut frame).is_err() {
        frame = Vec::new();
    }
    client.dismiss(frame);
    shared.wake();
}
