//! The publisher's one thread: an epoll loop over the listening socket, every subscriber's
//! connection and a wake-up eventfd, with the timers of rate caps, stalls and Goodbyes.
//!
//! Written on epoll rather than a thread per subscriber because each subscriber used to cost
//! two threads: 1,100 connections once took 2,053 threads and every file descriptor. Here a
//! subscriber costs its socket and its buffers. The loop is small enough, and its timers
//! specific enough, that an async runtime would bring more than it saves.

use std::collections::HashMap;
use std::io::{ErrorKind, Read, Write};
use std::net::Shutdown;
use std::os::fd::OwnedFd;
use std::os::unix::net::{UnixListener, UnixStream};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use rustix::event::epoll::{self, EventData, EventFlags};
use tacmesh_protocol::{encode, FrameDecoder, Message, Sender, Subscribe};

use crate::client::{self, Client, Next, Peer, Retire, Written};
use crate::{lock, LogThrottle, Shared, GOODBYE_GRACE, RESUBSCRIBE_INTERVAL, SEND_BUFFER_BYTES};

/// How long a connection that is being told Goodbye may take no bytes before it is closed
/// anyway, so that shutdown is quick even for a stalled subscriber.
const GOODBYE_WRITE_TIMEOUT: Duration = Duration::from_millis(500);

/// The send buffer asked for when the daemon says Goodbye. Freshness no longer matters then: a
/// buffer large enough for what is queued and the Goodbye lets a client that is not reading
/// just now find both when it reads, after the daemon has gone (the kernel keeps what was
/// written). The kernel caps it at `net.core.wmem_max`.
const GOODBYE_SEND_BUFFER_BYTES: usize = 4 * 1024 * 1024;

/// A client has nothing legitimate to send that is longer than this (a Subscribe with the
/// most ids is 8 KiB), so more unparsed bytes than this mean it is not speaking the protocol.
const CLIENT_BUFFER_CAP: usize = 64 * 1024;

/// What is read from a subscriber at a time. A Subscribe is a few bytes to 8 KiB; reading in
/// small steps keeps a Subscribe flood backed up in the client's own socket while one of its
/// Subscribes is held back.
const READ_CHUNK: usize = 4096;

/// After a failed accept (out of file descriptors), the listener rests this long.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// Epoll tokens of the two descriptors that are not subscribers (subscriber ids count up
/// from 0 and never reach these).
const LISTENER: u64 = u64::MAX;
const WAKER: u64 = u64::MAX - 1;

/// One subscriber's connection as the loop sees it.
struct Connection {
    client: Arc<Client>,
    stream: UnixStream,
    /// Bytes on their way: whole frames, the first `sent` of them written.
    out: Vec<u8>,
    sent: usize,
    written: Written,
    /// Since when bytes wait in `out` without the socket taking any.
    stalled_since: Option<Instant>,
    /// When an update held back by the rate cap may go.
    next_due: Option<Instant>,
    decoder: FrameDecoder,
    last_subscribe: Option<Instant>,
    /// A Subscribe that came sooner than [`RESUBSCRIBE_INTERVAL`] after the one before, and
    /// when it is acted on; nothing more is read from the subscriber until then.
    held: Option<(Subscribe, Instant)>,
    /// False once the subscriber closed its sending side (it may still read).
    reading: bool,
    /// Set when it was dropped or refused: what it sends is read and thrown away.
    ignoring_input: bool,
    /// Set once its Goodbye is in `out`: how it retires when that is written, and when not.
    leaving: Option<(Retire, Retire)>,
    /// Whether its send buffer was raised for a Goodbye.
    raised: bool,
    /// The events it is registered for.
    interest: EventFlags,
}

impl Connection {
    fn wants(&self) -> EventFlags {
        let mut flags = EventFlags::empty();
        if self.reading && self.held.is_none() {
            flags |= EventFlags::IN;
        }
        if self.sent < self.out.len() {
            flags |= EventFlags::OUT;
        }
        flags
    }

    /// When this connection next needs the loop without an event.
    fn deadline(&self, write_timeout: Duration) -> Option<Instant> {
        let limit = if self.leaving.is_some() {
            GOODBYE_WRITE_TIMEOUT
        } else {
            write_timeout
        };
        let stall = self
            .stalled_since
            .map(|since| since.checked_add(limit).unwrap_or(since));
        let due = if self.out.is_empty() {
            self.next_due
        } else {
            None
        };
        [stall, due, self.held.as_ref().map(|(_, at)| *at)]
            .into_iter()
            .flatten()
            .min()
    }

    /// Writes what the socket takes of `out`. `Ok` when it took everything or would block.
    fn flush(&mut self, shared: &Shared, now: Instant) -> std::io::Result<()> {
        let mut progressed = false;
        while self.sent < self.out.len() {
            match (&self.stream).write(&self.out[self.sent..]) {
                Ok(0) => return Err(ErrorKind::WriteZero.into()),
                Ok(n) => {
                    self.sent += n;
                    progressed = true;
                    shared.bytes_sent.fetch_add(n as u64, Ordering::Relaxed);
                }
                Err(error) if error.kind() == ErrorKind::Interrupted => {}
                Err(error) if error.kind() == ErrorKind::WouldBlock => break,
                Err(error) => return Err(error),
            }
        }
        if self.sent == self.out.len() {
            self.out.clear();
            self.sent = 0;
            self.stalled_since = None;
        } else if progressed || self.stalled_since.is_none() {
            self.stalled_since = Some(now);
        }
        Ok(())
    }

    /// The end of the frame that the next unsent byte belongs to (frames are a 4-byte
    /// little-endian length and that many bytes).
    fn end_of_current_frame(&self) -> usize {
        let mut start = 0;
        while start < self.out.len() {
            let Some(prefix) = self.out.get(start..start + 4) else {
                return self.out.len();
            };
            let length = u32::from_le_bytes([prefix[0], prefix[1], prefix[2], prefix[3]]);
            let end = (start + 4 + length as usize).min(self.out.len());
            if end > self.sent {
                return end;
            }
            start = end;
        }
        self.out.len()
    }

    /// How it retires when it turns out to be gone: as its Goodbye said when it was being
    /// told one, quietly when it was dropped already, else as disconnected.
    fn gone(&mut self) -> Retire {
        match self.leaving.take() {
            Some((_, untold)) => untold,
            None if self.ignoring_input => Retire::Quiet,
            None => Retire::Gone("disconnected".to_owned()),
        }
    }

    /// Raises the send buffer for what is on its way and a Goodbye after it: a subscriber that
    /// is not reading just now finds both when it reads again, even after the daemon is gone
    /// (with the small buffer it would be cut off at the end of the grace without its Goodbye).
    fn raise_send_buffer(&mut self) {
        if !self.raised {
            self.raised = true;
            let _ = rustix::net::sockopt::set_socket_send_buffer_size(
                &self.stream,
                GOODBYE_SEND_BUFFER_BYTES,
            );
        }
    }

    /// How a write error ends the subscriber. What it sent and was not yet read is read first,
    /// so that one that hung up in the middle of a frame is named so.
    fn gone_on_write(&mut self, error: &std::io::Error) -> Retire {
        let mut buffer = [0u8; READ_CHUNK];
        let mut read_error = None;
        while self.reading && self.decoder.buffered_len() <= CLIENT_BUFFER_CAP {
            match (&self.stream).read(&mut buffer) {
                Ok(0) => break,
                Ok(n) => self.decoder.push(&buffer[..n]),
                Err(error) if error.kind() == ErrorKind::Interrupted => {}
                Err(error) if error.kind() == ErrorKind::WouldBlock => break,
                Err(error) => {
                    read_error = Some(error);
                    break;
                }
            }
        }
        // Whole frames it sent are of no interest now: only a partial one is named.
        while let Ok(Some(_)) = self.decoder.next_message() {}
        match (self.decoder.buffered_len(), error.kind()) {
            (0, ErrorKind::BrokenPipe | ErrorKind::ConnectionReset) => {
                // A subscriber that closed its end: only a write tells a half-closed
                // connection (still reading) from a closed one.
                Retire::Gone("disconnected".to_owned())
            }
            (0, _) => Retire::Gone(format!("write failed: {error}")),
            (buffered, _) => client::gone_while_reading(buffered, read_error.as_ref()),
        }
    }

    /// Queues `goodbye` after what is on its way, with a raised send buffer for both.
    fn leave(&mut self, goodbye: &[u8], told: Retire, untold: Retire) {
        self.raise_send_buffer();
        self.out.extend_from_slice(goodbye);
        self.stalled_since = None;
        self.ignoring_input = true;
        self.leaving = Some((told, untold));
    }
}

/// The loop's state.
pub(crate) struct Serve {
    shared: Arc<Shared>,
    epoll: OwnedFd,
    listener: Option<UnixListener>,
    connections: HashMap<u64, Connection>,
    /// The listener rests until then after a failed accept.
    accept_paused_until: Option<Instant>,
    accept_log: LogThrottle,
    /// Set when shutdown began: by then every subscriber has been told Goodbye.
    grace_ends: Option<Instant>,
}

impl Serve {
    /// Sets up the epoll set; the waker is `shared.waker`.
    pub(crate) fn new(shared: Arc<Shared>, listener: UnixListener) -> std::io::Result<Serve> {
        let epoll = epoll::create(epoll::CreateFlags::CLOEXEC)?;
        listener.set_nonblocking(true)?;
        epoll::add(
            &epoll,
            &listener,
            EventData::new_u64(LISTENER),
            EventFlags::IN,
        )?;
        epoll::add(
            &epoll,
            &shared.waker,
            EventData::new_u64(WAKER),
            EventFlags::IN,
        )?;
        Ok(Serve {
            shared,
            epoll,
            listener: Some(listener),
            connections: HashMap::new(),
            accept_paused_until: None,
            accept_log: LogThrottle::default(),
            grace_ends: None,
        })
    }

    /// Serves until shutdown has told every subscriber Goodbye (or the grace is over).
    pub(crate) fn run(mut self) {
        let mut events = Vec::with_capacity(64);
        loop {
            let now = Instant::now();
            if self.grace_ends.is_none() && lock(&self.shared.state).stopping {
                self.grace_ends = now.checked_add(GOODBYE_GRACE).or(Some(now));
                if let Some(listener) = self.listener.take() {
                    let _ = epoll::delete(&self.epoll, &listener);
                }
            }
            if let Some(end) = self.grace_ends {
                if self.connections.is_empty() || now >= end {
                    break;
                }
            }
            if let Some(until) = self.accept_paused_until {
                if now >= until {
                    self.accept_paused_until = None;
                    self.set_listener_interest(EventFlags::IN);
                }
            }
            let ids: Vec<u64> = self.connections.keys().copied().collect();
            for id in ids {
                self.service(id, now);
            }
            let timeout = self.next_deadline().map(|at| {
                let wait = at.saturating_duration_since(Instant::now());
                // Rounded up to the next millisecond so that the loop does not wake early and
                // spin until the deadline; capped so that epoll takes it on any kernel.
                rustix::event::Timespec {
                    tv_sec: wait.as_secs().min(3600) as i64,
                    tv_nsec: i64::from(wait.subsec_nanos().div_ceil(1_000_000) * 1_000_000)
                        .min(999_999_999),
                }
            });
            events.clear();
            match epoll::wait(
                &self.epoll,
                rustix::buffer::spare_capacity(&mut events),
                timeout.as_ref(),
            ) {
                Ok(_) => {}
                Err(rustix::io::Errno::INTR) => continue,
                Err(error) => {
                    // Not expected on a valid epoll descriptor; serve on rather than spin.
                    tracing::error!("the publisher cannot wait for its sockets: {error}");
                    std::thread::sleep(ACCEPT_BACKOFF);
                    continue;
                }
            }
            for event in events.drain(..) {
                let flags = event.flags;
                match event.data.u64() {
                    LISTENER => self.accept_all(),
                    WAKER => {
                        let mut count = [0u8; 8];
                        let _ = rustix::io::read(&self.shared.waker, &mut count);
                    }
                    id => self.on_event(id, flags),
                }
            }
        }
        let ids: Vec<u64> = self.connections.keys().copied().collect();
        for id in ids {
            self.retire(id, Retire::Quiet);
        }
    }

    fn next_deadline(&self) -> Option<Instant> {
        let write_timeout = self.shared.write_timeout;
        self.connections
            .values()
            .filter_map(|c| c.deadline(write_timeout))
            .chain(self.accept_paused_until)
            .chain(self.grace_ends)
            .min()
    }

    fn set_listener_interest(&self, flags: EventFlags) {
        if let Some(listener) = &self.listener {
            let _ = epoll::modify(&self.epoll, listener, EventData::new_u64(LISTENER), flags);
        }
    }

    fn accept_all(&mut self) {
        loop {
            let Some(listener) = &self.listener else {
                return;
            };
            match listener.accept() {
                Ok((stream, _)) => self.admit(stream),
                Err(error) if error.kind() == ErrorKind::WouldBlock => return,
                Err(error) if error.kind() == ErrorKind::Interrupted => {}
                Err(error) => {
                    // Typically out of file descriptors: rest instead of spinning.
                    if let Some(note) = self.accept_log.allow(Instant::now()) {
                        tracing::warn!("cannot accept a subscriber: {error}{note}");
                    }
                    self.accept_paused_until = Instant::now().checked_add(ACCEPT_BACKOFF);
                    self.set_listener_interest(EventFlags::empty());
                    return;
                }
            }
        }
    }

    /// Registers a new subscriber with the current snapshot, or refuses it with a Goodbye.
    fn admit(&mut self, stream: UnixStream) {
        let shared = Arc::clone(&self.shared);
        let peer = Peer::of(&stream);
        if let Some(why) = shared
            .peer_refusal(&peer)
            .or_else(|| shared.over_cap(peer.as_ref().ok().map(|p| p.uid)))
        {
            crate::refuse(stream, &why);
            return;
        }
        let peer = peer.ok();
        if let Err(error) =
            rustix::net::sockopt::set_socket_send_buffer_size(&stream, SEND_BUFFER_BYTES)
        {
            tracing::warn!("cannot shrink a new subscriber's send buffer: {error}");
        }
        if let Err(error) = stream.set_nonblocking(true) {
            tracing::warn!("cannot set up a new subscriber's socket: {error}");
            return;
        }
        let client = {
            let mut state = lock(&shared.state);
            if state.stopping {
                return;
            }
            let id = state.next_client;
            state.next_client += 1;
            let client = Arc::new(Client::new(id, peer, &state.objects));
            state.clients.insert(id, Arc::clone(&client));
            client
        };
        let id = client.id;
        let interest = EventFlags::IN | EventFlags::OUT;
        if let Err(error) = epoll::add(&self.epoll, &stream, EventData::new_u64(id), interest) {
            lock(&shared.state).clients.remove(&id);
            tracing::warn!(
                client = id,
                "cannot watch a new subscriber's socket: {error}"
            );
            return;
        }
        self.connections.insert(
            id,
            Connection {
                client,
                stream,
                out: shared.hello.clone(),
                sent: 0,
                written: Written::default(),
                stalled_since: None,
                next_due: None,
                decoder: FrameDecoder::new(Sender::Client),
                last_subscribe: None,
                held: None,
                reading: true,
                ignoring_input: false,
                leaving: None,
                raised: false,
                interest,
            },
        );
        let note = lock(&shared.connection_log).allow(Instant::now());
        if let Some(note) = note {
            tracing::info!(client = id, "subscriber connected{note}");
        }
    }

    /// Reads what a subscriber sent, or learns that it hung up.
    fn on_event(&mut self, id: u64, flags: EventFlags) {
        let Some(connection) = self.connections.get_mut(&id) else {
            return;
        };
        let hung_up = flags.contains(EventFlags::HUP);
        if !connection.reading || connection.held.is_some() {
            // Nothing is to be read now; a hang-up means it is gone (both sides shut).
            if hung_up {
                let how = connection.gone();
                self.retire(id, how);
            }
            return;
        }
        if !flags.intersects(EventFlags::IN | EventFlags::ERR | EventFlags::HUP) {
            return;
        }
        let mut buffer = [0u8; READ_CHUNK];
        let read = loop {
            match (&connection.stream).read(&mut buffer) {
                Err(error) if error.kind() == ErrorKind::Interrupted => {}
                other => break other,
            }
        };
        match read {
            Ok(0) => {
                let buffered = connection.decoder.buffered_len();
                if buffered > 0 && !connection.ignoring_input {
                    self.retire(id, client::gone_while_reading(buffered, None));
                    return;
                }
                if hung_up || client::peer_closed(&connection.stream) {
                    // Closed whole, it is gone now (it would hold a place under the caps
                    // until the next write to it failed). With only its sending side closed it
                    // still reads (the server needs nothing from it) and is served on.
                    let how = connection.gone();
                    self.retire(id, how);
                    return;
                }
                connection.reading = false;
            }
            Ok(n) => {
                if !connection.ignoring_input {
                    connection.decoder.push(&buffer[..n]);
                    self.act_on_input(id, Instant::now());
                }
            }
            Err(error) if error.kind() == ErrorKind::WouldBlock => {}
            Err(error) => {
                let how = if connection.ignoring_input {
                    connection.gone()
                } else {
                    client::gone_while_reading(connection.decoder.buffered_len(), Some(&error))
                };
                self.retire(id, how);
                return;
            }
        }
        self.update_interest(id);
    }

    /// Acts on the whole frames a subscriber sent, in order, until one is held back.
    fn act_on_input(&mut self, id: u64, now: Instant) {
        let shared = Arc::clone(&self.shared);
        let Some(connection) = self.connections.get_mut(&id) else {
            return;
        };
        let client = Arc::clone(&connection.client);
        while connection.held.is_none() && !connection.ignoring_input {
            match connection.decoder.next_message() {
                Ok(Some(Message::Subscribe(options))) => {
                    tracing::debug!(client = id, ?options, "subscriber sent Subscribe");
                    // One Subscribe acted on per RESUBSCRIBE_INTERVAL: a sooner one waits, and
                    // what the client sends meanwhile backs up in its own socket.
                    let earliest = connection
                        .last_subscribe
                        .and_then(|at| at.checked_add(RESUBSCRIBE_INTERVAL));
                    match earliest {
                        Some(at) if at > now => {
                            shared.subscribes_throttled.fetch_add(1, Ordering::Relaxed);
                            connection.held = Some((options, at));
                        }
                        _ => {
                            connection.last_subscribe = Some(now);
                            let state = lock(&shared.state);
                            client.resubscribe(options, &state.objects);
                        }
                    }
                }
                Ok(Some(Message::SubscribeV1)) => {
                    client::refuse_version_1(&shared, &client);
                    connection.ignoring_input = true;
                }
                Ok(Some(other)) => {
                    // The decoder refuses server kinds already; this is for kinds added later.
                    let why = format!("it sent {}, which a subscriber may not send", other.name());
                    client::dismiss_with_goodbye(&shared, &client, &why);
                    connection.ignoring_input = true;
                }
                Ok(None) => break,
                Err(error) => {
                    let why = format!("it sent a bad frame: {error}");
                    client::dismiss_with_goodbye(&shared, &client, &why);
                    connection.ignoring_input = true;
                }
            }
        }
        if !connection.ignoring_input && connection.decoder.buffered_len() > CLIENT_BUFFER_CAP {
            let why = format!(
                "it sent {} bytes without completing a frame; subscriber frames are a few bytes",
                connection.decoder.buffered_len()
            );
            client::dismiss_with_goodbye(&shared, &client, &why);
            connection.ignoring_input = true;
        }
    }

    /// Everything a connection needs without an event: a held Subscribe that is due, the
    /// next batch when the last is written, writing, and the stall and Goodbye timers.
    fn service(&mut self, id: u64, now: Instant) {
        let due_subscribe = self
            .connections
            .get(&id)
            .and_then(|c| c.held.as_ref())
            .is_some_and(|(_, at)| *at <= now);
        if due_subscribe {
            if let Some(connection) = self.connections.get_mut(&id) {
                if let Some((options, _)) = connection.held.take() {
                    connection.last_subscribe = Some(now);
                    let state = lock(&self.shared.state);
                    connection.client.resubscribe(options, &state.objects);
                }
            }
            self.act_on_input(id, now);
        }
        let shared = Arc::clone(&self.shared);
        let Some(connection) = self.connections.get_mut(&id) else {
            return;
        };
        if !connection.raised && connection.client.has_goodbye() {
            // Before the batch on its way is written, or it could wait behind the small buffer
            // of a subscriber that is not reading until the grace is over.
            connection.raise_send_buffer();
        }
        let outcome = loop {
            if let Err(error) = connection.flush(&shared, now) {
                break Err(error);
            }
            if !connection.out.is_empty() || connection.leaving.is_some() {
                break Ok(());
            }
            match connection.client.take_next(&connection.written, now) {
                Next::Goodbye(goodbye, batch) => {
                    client::encode_batch(
                        &shared,
                        id,
                        &batch,
                        &mut connection.written,
                        &mut connection.out,
                    );
                    connection.leave(&goodbye, Retire::Quiet, Retire::Quiet);
                }
                Next::Updates(batch, next_due) => {
                    connection.next_due = next_due;
                    if batch.is_empty() {
                        break Ok(());
                    }
                    client::encode_batch(
                        &shared,
                        id,
                        &batch,
                        &mut connection.written,
                        &mut connection.out,
                    );
                }
            }
        };
        if let Err(error) = outcome {
            let how = match connection.leaving.take() {
                Some((_, untold)) => untold,
                None if connection.ignoring_input => Retire::Quiet,
                None => connection.gone_on_write(&error),
            };
            self.retire(id, how);
            return;
        }
        if connection.out.is_empty() {
            // Its Goodbye is written: the subscriber finds it before the end of the stream
            // (unread input on our side resets the connection only after what it holds).
            if let Some((told, _)) = connection.leaving.take() {
                self.retire(id, told);
                return;
            }
        } else if let Some(since) = connection.stalled_since {
            let limit = if connection.leaving.is_some() {
                GOODBYE_WRITE_TIMEOUT
            } else {
                shared.write_timeout
            };
            if now.saturating_duration_since(since) >= limit {
                if let Some((_, untold)) = connection.leaving.take() {
                    self.retire(id, untold);
                    return;
                }
                // It read nothing for the write timeout: it is told why after the frame it
                // stalled in, when that fits in a raised buffer, and dropped.
                let why = format!(
                    "it read nothing for {} s",
                    shared.write_timeout.as_secs_f32()
                );
                let mut goodbye = Vec::new();
                let reason = format!("dropped: {why}");
                let _ = encode(&Message::Goodbye { reason }, &mut goodbye);
                let end = connection.end_of_current_frame();
                connection.out.truncate(end);
                connection.leave(
                    &goodbye,
                    Retire::Dropped(format!("{why} (told so in a Goodbye)")),
                    Retire::Dropped(why),
                );
                // The raised buffer may take it at once.
                if connection.flush(&shared, now).is_ok() && connection.out.is_empty() {
                    let how = connection.leaving.take().map_or(Retire::Quiet, |(t, _)| t);
                    self.retire(id, how);
                    return;
                }
            }
        }
        self.update_interest(id);
    }

    fn update_interest(&mut self, id: u64) {
        let Some(connection) = self.connections.get_mut(&id) else {
            return;
        };
        let wants = connection.wants();
        if wants != connection.interest
            && epoll::modify(
                &self.epoll,
                &connection.stream,
                EventData::new_u64(id),
                wants,
            )
            .is_ok()
        {
            connection.interest = wants;
        }
    }

    /// Disconnects a subscriber: unregisters it and closes its socket. Logs and counts how.
    fn retire(&mut self, id: u64, how: Retire) {
        if let Some(connection) = self.connections.remove(&id) {
            let _ = epoll::delete(&self.epoll, &connection.stream);
            let _ = connection.stream.shutdown(Shutdown::Both);
            self.shared.retire(&connection.client, how);
        }
    }
}
