//! One subscriber: its pending updates, its writer thread and its reader thread.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{ErrorKind, Read, Write};
use std::net::Shutdown;
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use tacmesh_protocol::{encode, FrameDecoder, Message, Sender};

use crate::{lock, Shared};

/// Write timeout for the Goodbye, so that shutdown is quick even for a stalled subscriber.
const GOODBYE_WRITE_TIMEOUT: Duration = Duration::from_millis(500);

/// The send buffer asked for when the daemon says Goodbye (see [`Client::say_goodbye`]).
const SHUTDOWN_SEND_BUFFER_BYTES: usize = 4 * 1024 * 1024;

/// A client has nothing legitimate to send that is longer than this (Subscribe is 5 bytes), so
/// more unparsed bytes than this mean it is not speaking the protocol.
const CLIENT_BUFFER_CAP: usize = 64 * 1024;

/// The frame of SnapshotDone: `01 00 00 00 04`.
const SNAPSHOT_DONE: [u8; 5] = [1, 0, 0, 0, 4];

/// An encoded Upsert and its version.
pub(crate) struct Frame {
    pub(crate) version: u64,
    pub(crate) bytes: Vec<u8>,
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
    /// The latest unsent mesh of each object.
    upserts: BTreeMap<u64, Arc<Frame>>,
    /// Unsent removes; an id is never in both maps.
    removes: BTreeSet<u64>,
    /// The latest unsent stats frame.
    stats: Option<Arc<Vec<u8>>>,
}

impl Updates {
    fn is_empty(&self) -> bool {
        self.upserts.is_empty() && self.removes.is_empty() && self.stats.is_none()
    }
}

struct Pending {
    updates: Updates,
    goodbye: Option<Arc<Vec<u8>>>,
    closed: bool,
}

pub(crate) struct Client {
    pub(crate) id: u64,
    stream: UnixStream,
    pending: Mutex<Pending>,
    wake: Condvar,
    /// Set with `goodbye`: a write error after it is the shutdown's, not the subscriber's.
    leaving: AtomicBool,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl Client {
    pub(crate) fn new(id: u64, stream: UnixStream, snapshot: BTreeMap<u64, Arc<Frame>>) -> Self {
        Self {
            id,
            stream,
            pending: Mutex::new(Pending {
                updates: Updates {
                    upserts: snapshot,
                    ..Updates::default()
                },
                goodbye: None,
                closed: false,
            }),
            wake: Condvar::new(),
            leaving: AtomicBool::new(false),
            threads: Mutex::new(Vec::new()),
        }
    }

    pub(crate) fn queue_upsert(&self, object_id: u64, frame: &Arc<Frame>) {
        let mut pending = lock(&self.pending);
        pending.updates.removes.remove(&object_id);
        pending.updates.upserts.insert(object_id, Arc::clone(frame));
        drop(pending);
        self.wake.notify_one();
    }

    pub(crate) fn queue_remove(&self, object_id: u64) {
        let mut pending = lock(&self.pending);
        pending.updates.upserts.remove(&object_id);
        pending.updates.removes.insert(object_id);
        drop(pending);
        self.wake.notify_one();
    }

    pub(crate) fn queue_stats(&self, frame: &Arc<Vec<u8>>) {
        lock(&self.pending).updates.stats = Some(Arc::clone(frame));
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
            if let Some(how) = read_loop(&reader_client) {
                reader_shared.retire(&reader_client, how);
            }
        })?;
    lock(&client.threads).push(reader);
    Ok(())
}

enum Next {
    Updates(Updates),
    /// The Goodbye, and what was still pending when it came (flushed first).
    Goodbye(Arc<Vec<u8>>, Updates),
    Closed,
}

/// Writes Hello, the snapshot, SnapshotDone, then updates as they come; returns how it ended.
fn write_loop(shared: &Shared, client: &Client) -> Retire {
    match write_all_frames(shared, client) {
        Ok(()) => Retire::Quiet,
        Err(_) if client.is_closed() || client.leaving.load(Ordering::Relaxed) => Retire::Quiet,
        Err(error) if matches!(error.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
            Retire::Dropped(format!(
                "it read nothing for {} s",
                shared.write_timeout.as_secs_f32()
            ))
        }
        // A subscriber that closed its end: its reader saw the end of its input, and only a
        // write tells a half-closed connection (still reading) from a closed one.
        Err(error)
            if matches!(
                error.kind(),
                ErrorKind::BrokenPipe | ErrorKind::ConnectionReset
            ) =>
        {
            Retire::Gone("disconnected".into())
        }
        Err(error) => Retire::Gone(format!("write failed: {error}")),
    }
}

fn write_all_frames(shared: &Shared, client: &Client) -> std::io::Result<()> {
    let send = |bytes: &[u8]| -> std::io::Result<()> {
        (&client.stream).write_all(bytes)?;
        shared
            .bytes_sent
            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(())
    };
    send(&shared.hello)?;
    let mut snapshot_sent = false;
    loop {
        let next = {
            let mut pending = lock(&client.pending);
            loop {
                if pending.closed {
                    break Next::Closed;
                }
                if let Some(goodbye) = pending.goodbye.take() {
                    break Next::Goodbye(goodbye, std::mem::take(&mut pending.updates));
                }
                // The first batch (the snapshot) is taken even when empty, for SnapshotDone.
                if !snapshot_sent || !pending.updates.is_empty() {
                    break Next::Updates(std::mem::take(&mut pending.updates));
                }
                pending = client
                    .wake
                    .wait(pending)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
            }
        };
        match next {
            Next::Closed => return Ok(()),
            Next::Goodbye(frame, updates) => {
                // What was queued before the Goodbye is sent first (bounded: each write by
                // GOODBYE_WRITE_TIMEOUT, the whole by the publisher's grace, after which the
                // socket is closed under the writer).
                client
                    .stream
                    .set_write_timeout(Some(GOODBYE_WRITE_TIMEOUT))?;
                send_updates(&send, shared, client, &updates, &mut snapshot_sent)?;
                send(&frame)?;
                let _ = client.stream.shutdown(Shutdown::Both);
                return Ok(());
            }
            Next::Updates(updates) => {
                send_updates(&send, shared, client, &updates, &mut snapshot_sent)?;
            }
        }
    }
}

/// Writes one batch: its Upserts, SnapshotDone after the first batch, its Removes and Stats.
fn send_updates(
    send: &impl Fn(&[u8]) -> std::io::Result<()>,
    shared: &Shared,
    client: &Client,
    updates: &Updates,
    snapshot_sent: &mut bool,
) -> std::io::Result<()> {
    for (object_id, frame) in &updates.upserts {
        send(&frame.bytes)?;
        shared.meshes_published.fetch_add(1, Ordering::Relaxed);
        tracing::trace!(
            client = client.id,
            object_id,
            version = frame.version,
            "sent mesh"
        );
    }
    if !*snapshot_sent {
        send(&SNAPSHOT_DONE)?;
        *snapshot_sent = true;
    }
    let mut bytes = Vec::new();
    for &object_id in &updates.removes {
        bytes.clear();
        encode(&Message::Remove { object_id }, &mut bytes)
            .map_err(|error| std::io::Error::other(error.to_string()))?;
        send(&bytes)?;
    }
    if let Some(stats) = &updates.stats {
        send(stats)?;
    }
    Ok(())
}

/// Reads what the subscriber sends until it disconnects or misbehaves; returns how it ended, or
/// `None` when the subscriber only stopped sending (the end of its input at a frame boundary).
fn read_loop(client: &Client) -> Option<Retire> {
    let mut decoder = FrameDecoder::new(Sender::Client);
    let mut buffer = [0u8; 4096];
    loop {
        let read = match (&client.stream).read(&mut buffer) {
            Ok(0) if client.is_closed() => return Some(Retire::Quiet),
            Ok(0) if decoder.buffered_len() > 0 => {
                return Some(Retire::Gone(format!(
                    "disconnected in the middle of a frame ({} bytes unparsed)",
                    decoder.buffered_len()
                )))
            }
            // The subscriber sends nothing more: it may have closed only its sending side
            // and still read (the server needs nothing from it). The writer finds out which
            // at its next write; this thread just ends.
            Ok(0) => return None,
            Ok(read) => read,
            Err(error) if error.kind() == ErrorKind::Interrupted => continue,
            Err(_) if client.is_closed() => return Some(Retire::Quiet),
            Err(error) => return Some(Retire::Gone(format!("read failed: {error}"))),
        };
        decoder.push(&buffer[..read]);
        loop {
            match decoder.next_message() {
                Ok(Some(Message::Subscribe)) => {
                    tracing::debug!(client = client.id, "subscriber sent Subscribe");
                }
                Ok(Some(other)) => {
                    // The decoder refuses server kinds already; this is for kinds added later.
                    return Some(Retire::Dropped(format!(
                        "it sent {}, which a subscriber may not send",
                        other.name()
                    )));
                }
                Ok(None) => break,
                Err(error) => {
                    return Some(Retire::Dropped(format!("it sent a bad frame: {error}")))
                }
            }
        }
        if decoder.buffered_len() > CLIENT_BUFFER_CAP {
            return Some(Retire::Dropped(format!(
                "it sent {} bytes without completing a frame; subscriber frames are a few bytes",
                decoder.buffered_len()
            )));
        }
    }
}
