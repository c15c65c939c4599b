//! Telling systemd how the daemon is doing (the `sd_notify(3)` protocol) and feeding its
//! watchdog from the pipeline's own liveness, so that a stuck thread gets the daemon restarted.
//!
//! The protocol is one datagram of `KEY=VALUE` lines to the Unix socket named by
//! `$NOTIFY_SOCKET` (a path, or an abstract name when it starts with `@`), written here with
//! std's `UnixDatagram`: READY=1 once the socket is bound and a sensor is being read, STATUS=
//! with a one-line summary every [`STATUS_INTERVAL`], WATCHDOG=1 every half `$WATCHDOG_USEC`
//! while the pipeline is alive, STOPPING=1 at shutdown. Without `$NOTIFY_SOCKET` every call is
//! a no-op; `$WATCHDOG_PID`, when set, must name this process for the watchdog to be fed.
//!
//! Liveness, and what is not a stall: each thread that must keep moving shows it one of two
//! ways, and the daemon is stalled when one of them has not for [`STALL_AFTER`].
//! - A source thread beats a [`Heartbeat`] on every turn of its supervisor loop: after every
//!   frame or error from the device, every 20 ms while it waits to reopen a lost device, every
//!   50 ms while a recording waits for room in the ring. A sensor that is unplugged and being
//!   reopened with backoff is therefore alive; only a thread stuck inside one call (a device
//!   read that never returns, a deadlock) or dead by a panic stops beating. A thread that ends
//!   normally (a recording at its end) retires its heartbeat.
//! - The perception thread is watched by its [`Progress`] through the ring: it is stalled when
//!   frames have waited in the ring, with none taken, for the whole time. An idle pipeline (no
//!   frames because the sensor is gone) is not stalled.
//! - Each mesher thread beats its own heartbeat when it takes a job and sets it idle while it
//!   waits for one, so one worker stuck inside a meshing run (or dead by a panic in one) trips
//!   the watchdog even while the others keep meshing. Its limit is
//!   [`MESH_RUN_LIMIT`], not [`STALL_AFTER`]: one run of a large object is legitimately long.
//!   The mesh queue is also watched as a whole: stalled when jobs have waited and no meshing
//!   run has finished.
//! - The daemon's main thread does the looking and the sending, so if it is stuck, nothing is
//!   sent either.
//!
//! Known blind spot: a source whose device call legitimately blocks longer than
//! [`STALL_AFTER`] (a paced recording with a longer gap between two frames) looks stuck.
//!
//! Entry points: [`Notifier::from_env`], [`Heartbeats`], [`SystemdFeed::tick`].

use std::ffi::OsString;
use std::io;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::counters::CounterSnapshot;

/// A thread that has shown no sign of life for this long is stuck. Far above anything a
/// healthy thread takes (a frame is tens of milliseconds, opening a device a second or two),
/// so that a loaded machine is not mistaken for a stuck one; systemd's own `WatchdogSec=` then
/// adds its delay before it kills the daemon.
pub const STALL_AFTER: Duration = Duration::from_secs(5);

/// A mesher thread that has been inside one meshing run for this long is stuck. A run of the
/// largest object the default size limits allow takes well under a second in a release build
/// and a few seconds in a debug build on a loaded machine.
pub const MESH_RUN_LIMIT: Duration = Duration::from_secs(30);

/// How often the STATUS= line is refreshed.
pub const STATUS_INTERVAL: Duration = Duration::from_secs(2);

/// The way to the service manager: `$NOTIFY_SOCKET` and the watchdog period, if any.
#[derive(Debug, Default)]
pub struct Notifier {
    target: Option<Target>,
    /// `$WATCHDOG_USEC`: systemd kills the daemon when no WATCHDOG=1 came for this long.
    watchdog_timeout: Option<Duration>,
    /// A failed send is logged once, not at every ping.
    send_failed: AtomicBool,
}

#[derive(Debug)]
struct Target {
    socket: UnixDatagram,
    addr: SocketAddr,
    /// `$NOTIFY_SOCKET` as given, for log lines.
    name: String,
}

impl Notifier {
    /// The notifier the environment asks for: `$NOTIFY_SOCKET`, `$WATCHDOG_USEC` and
    /// `$WATCHDOG_PID`. Without `$NOTIFY_SOCKET`, a notifier that sends nothing. A variable
    /// that cannot be used is logged and ignored: notifications must never stop the daemon.
    pub fn from_env() -> Notifier {
        let var = |name: &str| std::env::var(name).ok();
        Self::from_vars(
            std::env::var_os("NOTIFY_SOCKET"),
            var("WATCHDOG_USEC").as_deref(),
            var("WATCHDOG_PID").as_deref(),
            std::process::id(),
        )
    }

    /// [`Notifier::from_env`] on given values, for tests.
    pub fn from_vars(
        notify_socket: Option<OsString>,
        watchdog_usec: Option<&str>,
        watchdog_pid: Option<&str>,
        own_pid: u32,
    ) -> Notifier {
        let Some(name) = notify_socket.filter(|name| !name.is_empty()) else {
            return Notifier::default();
        };
        let name = name.to_string_lossy().into_owned();
        let target = match connect(&name) {
            Ok((socket, addr)) => Target { socket, addr, name },
            Err(err) => {
                tracing::warn!(
                    "NOTIFY_SOCKET={name} cannot be used ({err}); not notifying systemd"
                );
                return Notifier::default();
            }
        };
        // sd_watchdog_enabled(3): WATCHDOG_PID, when set, names the process to feed it.
        let ours = watchdog_pid.is_none_or(|pid| pid.trim().parse::<u32>() == Ok(own_pid));
        let watchdog_timeout = match watchdog_usec.map(|usec| usec.trim().parse::<u64>()) {
            _ if !ours => None,
            None | Some(Ok(0)) => None,
            Some(Ok(usec)) => Some(Duration::from_micros(usec)),
            Some(Err(_)) => {
                tracing::warn!(
                    "WATCHDOG_USEC={:?} is not a number of microseconds; not feeding the watchdog",
                    watchdog_usec.unwrap_or_default()
                );
                None
            }
        };
        Notifier {
            target: Some(target),
            watchdog_timeout,
            send_failed: AtomicBool::new(false),
        }
    }

    /// True when there is a service manager to tell.
    pub fn is_enabled(&self) -> bool {
        self.target.is_some()
    }

    /// How often to send WATCHDOG=1: half the watchdog timeout, as sd_watchdog_enabled(3)
    /// advises. `None` when systemd runs no watchdog for this process.
    pub fn watchdog_interval(&self) -> Option<Duration> {
        self.watchdog_timeout.map(|timeout| timeout / 2)
    }

    /// READY=1, with a first status line.
    pub fn ready(&self, status: &str) {
        self.send(&format!("READY=1\nSTATUS={}", one_line(status)));
    }

    /// STATUS=, shown by `systemctl status`.
    pub fn status(&self, status: &str) {
        self.send(&format!("STATUS={}", one_line(status)));
    }

    /// WATCHDOG=1: the daemon is alive.
    pub fn ping_watchdog(&self) {
        self.send("WATCHDOG=1");
    }

    /// STOPPING=1: the daemon is shutting down on purpose.
    pub fn stopping(&self) {
        self.send("STOPPING=1\nSTATUS=stopping");
    }

    fn send(&self, message: &str) {
        let Some(target) = &self.target else {
            return;
        };
        match target.socket.send_to_addr(message.as_bytes(), &target.addr) {
            Ok(_) => {
                if self.send_failed.swap(false, Ordering::Relaxed) {
                    tracing::info!("notifying systemd at {} again", target.name);
                }
            }
            Err(err) => {
                if !self.send_failed.swap(true, Ordering::Relaxed) {
                    tracing::warn!("cannot notify systemd at {}: {err}", target.name);
                }
            }
        }
    }
}

/// An unbound datagram socket and the address of `$NOTIFY_SOCKET`.
fn connect(name: &str) -> io::Result<(UnixDatagram, SocketAddr)> {
    let addr = if let Some(abstract_name) = name.strip_prefix('@') {
        abstract_addr(abstract_name)?
    } else if name.starts_with('/') {
        SocketAddr::from_pathname(name)?
    } else {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "neither an absolute path nor an abstract name (@...)",
        ));
    };
    let socket = UnixDatagram::unbound()?;
    // A manager that does not read (its queue holds only net.unix.max_dgram_qlen datagrams,
    // 10 by default) must not block the daemon's main loop: a full queue fails the send.
    socket.set_nonblocking(true)?;
    Ok((socket, addr))
}

#[cfg(any(target_os = "linux", target_os = "android"))]
fn abstract_addr(name: &str) -> io::Result<SocketAddr> {
    #[cfg(target_os = "android")]
    use std::os::android::net::SocketAddrExt;
    #[cfg(target_os = "linux")]
    use std::os::linux::net::SocketAddrExt;
    SocketAddr::from_abstract_name(name.as_bytes())
}

#[cfg(not(any(target_os = "linux", target_os = "android")))]
fn abstract_addr(_name: &str) -> io::Result<SocketAddr> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "abstract socket names exist only on Linux",
    ))
}

/// A STATUS= value must not break the line protocol.
fn one_line(text: &str) -> String {
    text.replace(['\n', '\r'], " ")
}

/// The heartbeats of the threads that show their liveness themselves (the source threads).
#[derive(Debug)]
pub struct Heartbeats {
    epoch: Instant,
    slots: Mutex<Vec<Arc<Slot>>>,
}

impl Default for Heartbeats {
    fn default() -> Self {
        Self {
            epoch: Instant::now(),
            slots: Mutex::new(Vec::new()),
        }
    }
}

#[derive(Debug)]
struct Slot {
    name: String,
    /// Milliseconds after the epoch of the last beat; [`RETIRED`] once the thread has ended.
    last_beat_ms: AtomicU64,
    beaten: AtomicBool,
    /// A worker's own silence limit, instead of the one [`Heartbeats::stalled`] is given;
    /// `None` for a source thread.
    limit: Option<Duration>,
}

const RETIRED: u64 = u64::MAX;
/// A worker waiting for work: not watched until its next beat.
const IDLE: u64 = u64::MAX - 1;

/// One thread's heartbeat. Registering counts as a beat, so a thread that has not started yet
/// has a moment before it is missed.
#[derive(Debug, Clone)]
pub struct Heartbeat {
    slot: Arc<Slot>,
    epoch: Instant,
}

impl Heartbeat {
    /// The thread is alive now.
    pub fn beat(&self) {
        self.slot
            .last_beat_ms
            .store(millis_since(self.epoch, Instant::now()), Ordering::Relaxed);
        self.slot.beaten.store(true, Ordering::Relaxed);
    }

    /// The thread waits for work and is not watched until it beats again (a mesher between
    /// jobs: an empty queue is not a stall).
    pub fn idle(&self) {
        self.slot.last_beat_ms.store(IDLE, Ordering::Relaxed);
    }

    /// The thread has ended normally and is no longer watched. A thread that dies by a panic
    /// does not retire: its silence trips the watchdog.
    pub fn retire(&self) {
        self.slot.last_beat_ms.store(RETIRED, Ordering::Relaxed);
    }
}

impl Heartbeats {
    /// A heartbeat for the thread `name`, counted as beaten now.
    pub fn register(&self, name: &str) -> Heartbeat {
        self.register_slot(name, None)
    }

    /// A heartbeat for the worker thread `name` (a mesher), stalled only after `limit` of
    /// silence ([`MESH_RUN_LIMIT`]) whatever limit [`Heartbeats::stalled`] is given. A worker
    /// reads no sensor, so its beats do not count for [`Heartbeats::any_beaten`].
    pub fn register_worker(&self, name: &str, limit: Duration) -> Heartbeat {
        self.register_slot(name, Some(limit))
    }

    fn register_slot(&self, name: &str, limit: Option<Duration>) -> Heartbeat {
        let slot = Arc::new(Slot {
            name: name.to_owned(),
            last_beat_ms: AtomicU64::new(millis_since(self.epoch, Instant::now())),
            beaten: AtomicBool::new(false),
            limit,
        });
        crate::lock(&self.slots).push(Arc::clone(&slot));
        Heartbeat {
            slot,
            epoch: self.epoch,
        }
    }

    /// True once any source thread has beaten its heartbeat itself (it is reading, not just
    /// spawned): the daemon is ready then.
    pub fn any_beaten(&self) -> bool {
        crate::lock(&self.slots)
            .iter()
            .any(|slot| slot.limit.is_none() && slot.beaten.load(Ordering::Relaxed))
    }

    /// The first thread whose last beat is older than its limit at `now` (`limit`, unless it
    /// was registered with its own), described.
    pub fn stalled(&self, now: Instant, limit: Duration) -> Option<String> {
        let now_ms = millis_since(self.epoch, now);
        crate::lock(&self.slots).iter().find_map(|slot| {
            let limit_ms = slot.limit.unwrap_or(limit).as_millis() as u64;
            let last = slot.last_beat_ms.load(Ordering::Relaxed);
            let silent_ms = now_ms.saturating_sub(last);
            (last != RETIRED && last != IDLE && silent_ms > limit_ms).then(|| {
                format!(
                    "the {} thread has not moved for {:.1} s",
                    slot.name,
                    silent_ms as f64 / 1e3
                )
            })
        })
    }
}

fn millis_since(epoch: Instant, now: Instant) -> u64 {
    now.saturating_duration_since(epoch).as_millis() as u64
}

/// A consumer watched from outside through the work it takes: stalled when work has been
/// waiting, with none taken, at every look for longer than the limit. Work that has just
/// arrived after a long idle time is not a stall.
#[derive(Debug)]
pub struct Progress {
    /// The thread, and what it takes, for messages.
    name: &'static str,
    item: &'static str,
    taken: u64,
    /// Since when work has waited without any being taken.
    waiting_since: Option<Instant>,
}

impl Progress {
    pub fn new(name: &'static str, item: &'static str) -> Self {
        Self {
            name,
            item,
            taken: 0,
            waiting_since: None,
        }
    }

    /// Records a look at `now`: `taken` items taken so far, `waiting` whether any wait now.
    pub fn observe(&mut self, taken: u64, waiting: bool, now: Instant) {
        if taken != self.taken || !waiting {
            self.waiting_since = None;
        } else if self.waiting_since.is_none() {
            self.waiting_since = Some(now);
        }
        self.taken = taken;
    }

    /// Described, when work has waited untaken for longer than `limit` at `now`.
    pub fn stalled(&self, now: Instant, limit: Duration) -> Option<String> {
        let waited = now.saturating_duration_since(self.waiting_since?);
        (waited > limit).then(|| {
            format!(
                "the {} thread has taken no {} for {:.1} s while some wait",
                self.name,
                self.item,
                waited.as_secs_f64()
            )
        })
    }
}

/// What the daemon's main loop does for systemd: watches liveness, pings the watchdog while
/// the pipeline is alive, refreshes STATUS=, and logs a stall once when it begins and ends.
/// It runs (and logs stalls) without systemd too.
#[derive(Debug)]
pub struct SystemdFeed {
    notifier: Notifier,
    perception: Progress,
    meshers: Progress,
    /// The stall being reported, if any.
    stall: Option<String>,
    next_ping: Option<Instant>,
    next_status: Instant,
    /// When the last STATUS= was computed and the frames processed by then, for the rate.
    last_status: (Instant, u64),
}

impl SystemdFeed {
    pub fn new(notifier: Notifier, now: Instant) -> Self {
        Self {
            next_ping: notifier.watchdog_interval().map(|_| now),
            notifier,
            perception: Progress::new("perception", "frame"),
            meshers: Progress::new("mesher", "mesh job"),
            stall: None,
            next_status: now + STATUS_INTERVAL,
            // Made before the threads start: no frame has been processed yet.
            last_status: (now, 0),
        }
    }

    pub fn notifier(&self) -> &Notifier {
        &self.notifier
    }

    /// When [`SystemdFeed::tick`] next has something to do.
    pub fn next_due(&self) -> Instant {
        self.next_ping
            .map_or(self.next_status, |ping| ping.min(self.next_status))
    }

    /// Looks at the pipeline at `now` (its heartbeats, counters and the mesh jobs waiting)
    /// and sends what is due.
    pub fn tick(
        &mut self,
        now: Instant,
        heartbeats: &Heartbeats,
        counters: &CounterSnapshot,
        mesh_jobs_waiting: usize,
    ) {
        let ring = counters.ring;
        let taken = ring
            .pushed
            .saturating_sub(ring.dropped + ring.queued as u64);
        self.perception.observe(taken, ring.queued > 0, now);
        self.meshers
            .observe(counters.meshing_runs, mesh_jobs_waiting > 0, now);
        let stall = heartbeats
            .stalled(now, STALL_AFTER)
            .or_else(|| self.perception.stalled(now, STALL_AFTER))
            .or_else(|| self.meshers.stalled(now, STALL_AFTER));
        match (&self.stall, &stall) {
            (None, Some(reason)) => {
                let consequence = if self.notifier.watchdog_interval().is_some() {
                    "the systemd watchdog is no longer fed and will restart the daemon"
                } else {
                    "no watchdog runs: restart the daemon if it does not recover"
                };
                tracing::error!("the pipeline is stuck: {reason}; {consequence}");
            }
            (Some(_), None) => tracing::info!("the pipeline moves again"),
            _ => {}
        }
        self.stall = stall;

        if let (Some(due), Some(every)) = (self.next_ping, self.notifier.watchdog_interval()) {
            if now >= due {
                if self.stall.is_none() {
                    self.notifier.ping_watchdog();
                }
                self.next_ping = Some(now + every);
            }
        }
        if now >= self.next_status {
            let (then, frames_then) = self.last_status;
            let seconds = now.saturating_duration_since(then).as_secs_f64();
            let frames_per_s = if seconds > 0.0 {
                counters.frames_processed.saturating_sub(frames_then) as f64 / seconds
            } else {
                0.0
            };
            self.last_status = (now, counters.frames_processed);
            let line = match &self.stall {
                Some(reason) => format!("stuck: {reason}"),
                None => status_line(frames_per_s, counters),
            };
            self.notifier.status(&line);
            self.next_status = now + STATUS_INTERVAL;
        }
    }
}

/// The one-line summary `systemctl status` shows. Lost log lines are named there when there
/// are any, since the log itself cannot say so once its stream is gone.
pub fn status_line(frames_per_s: f64, counters: &CounterSnapshot) -> String {
    let subscribers = counters.publisher.clients_connected;
    let mut line = format!(
        "{frames_per_s:.1} frames/s, {} objects, {subscribers} subscriber{}, {} frames dropped, \
         {} source errors",
        counters.objects_tracked,
        if subscribers == 1 { "" } else { "s" },
        counters.ring.dropped,
        counters.source_errors,
    );
    if counters.log_lines_dropped > 0 {
        line += &format!(
            ", {} log lines lost (standard error is closed)",
            counters.log_lines_dropped
        );
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame_ring::RingStats;

    /// A datagram socket standing in for systemd, and a notifier pointing at it.
    fn manager(watchdog_usec: Option<&str>) -> (tempfile::TempDir, UnixDatagram, Notifier) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notify");
        let socket = UnixDatagram::bind(&path).unwrap();
        socket.set_nonblocking(true).unwrap();
        let notifier = Notifier::from_vars(Some(path.into_os_string()), watchdog_usec, None, 1234);
        (dir, socket, notifier)
    }

    fn received(socket: &UnixDatagram) -> Vec<String> {
        let mut messages = Vec::new();
        let mut buf = [0u8; 4096];
        while let Ok(n) = socket.recv(&mut buf) {
            messages.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
        messages
    }

    fn counters(pushed: u64, dropped: u64, queued: usize) -> CounterSnapshot {
        CounterSnapshot {
            ring: RingStats {
                pushed,
                dropped,
                queued,
            },
            ..CounterSnapshot::default()
        }
    }

    #[test]
    fn without_notify_socket_nothing_is_sent_and_no_watchdog_runs() {
        let notifier = Notifier::from_vars(None, Some("400000"), None, 1);
        assert!(!notifier.is_enabled());
        assert_eq!(notifier.watchdog_interval(), None);
        notifier.ready("ready");
        notifier.stopping();
    }

    #[test]
    fn watchdog_usec_gives_half_its_period_and_honours_watchdog_pid() {
        let (_dir, _socket, notifier) = manager(Some("400000"));
        assert_eq!(
            notifier.watchdog_interval(),
            Some(Duration::from_millis(200))
        );
        let path = _dir.path().join("notify").into_os_string();
        let other = Notifier::from_vars(Some(path.clone()), Some("400000"), Some("99"), 1234);
        assert_eq!(
            other.watchdog_interval(),
            None,
            "another process's watchdog"
        );
        let ours = Notifier::from_vars(Some(path.clone()), Some("400000"), Some("1234"), 1234);
        assert!(ours.watchdog_interval().is_some());
        let garbage = Notifier::from_vars(Some(path), Some("soon"), None, 1234);
        assert_eq!(garbage.watchdog_interval(), None);
        assert!(garbage.is_enabled());
    }

    #[test]
    fn messages_reach_a_path_socket() {
        let (_dir, socket, notifier) = manager(None);
        notifier.ready("serving\non /run/x");
        notifier.status("1 object");
        notifier.ping_watchdog();
        notifier.stopping();
        assert_eq!(
            received(&socket),
            [
                "READY=1\nSTATUS=serving on /run/x",
                "STATUS=1 object",
                "WATCHDOG=1",
                "STOPPING=1\nSTATUS=stopping"
            ]
        );
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn messages_reach_an_abstract_socket() {
        use std::os::linux::net::SocketAddrExt;
        let name = format!("tacmesh-notify-test-{}", std::process::id());
        let addr = SocketAddr::from_abstract_name(name.as_bytes()).unwrap();
        let socket = UnixDatagram::bind_addr(&addr).unwrap();
        socket.set_nonblocking(true).unwrap();
        let notifier = Notifier::from_vars(Some(format!("@{name}").into()), None, None, 1);
        notifier.ping_watchdog();
        assert_eq!(received(&socket), ["WATCHDOG=1"]);
    }

    #[test]
    fn a_relative_notify_socket_is_ignored() {
        let notifier = Notifier::from_vars(Some("notify".into()), Some("1000000"), None, 1);
        assert!(!notifier.is_enabled());
    }

    #[test]
    fn a_silent_heartbeat_is_stale_and_a_retired_one_is_not() {
        let heartbeats = Heartbeats::default();
        let source = heartbeats.register("source");
        assert!(!heartbeats.any_beaten());
        source.beat();
        assert!(heartbeats.any_beaten());
        let now = Instant::now();
        assert_eq!(heartbeats.stalled(now, STALL_AFTER), None);
        let later = now + STALL_AFTER + Duration::from_secs(1);
        let stall = heartbeats.stalled(later, STALL_AFTER).expect("stale");
        assert!(stall.contains("source"), "{stall}");
        source.retire();
        assert_eq!(heartbeats.stalled(later, STALL_AFTER), None);
    }

    #[test]
    fn progress_stalls_only_while_work_waits_untaken() {
        let limit = Duration::from_secs(5);
        let t0 = Instant::now();
        let at = |s: u64| t0 + Duration::from_secs(s);
        let mut perception = Progress::new("perception", "frame");
        // Idle for a long time: nothing waits, nothing is stalled.
        perception.observe(0, false, at(0));
        perception.observe(0, false, at(60));
        // A frame arrives after the idle time (a sensor came back): not a stall yet.
        perception.observe(0, true, at(61));
        assert_eq!(perception.stalled(at(61), limit), None);
        // Frames keep being taken: never stalled.
        perception.observe(5, true, at(64));
        perception.observe(9, true, at(70));
        assert_eq!(perception.stalled(at(70), limit), None);
        // A frame waits and none is taken for longer than the limit: stalled.
        perception.observe(9, true, at(72));
        perception.observe(9, true, at(76));
        assert_eq!(perception.stalled(at(76), limit), None);
        perception.observe(9, true, at(78));
        assert!(perception.stalled(at(78), limit).is_some());
        // It moves again.
        perception.observe(10, true, at(79));
        assert_eq!(perception.stalled(at(79), limit), None);
    }

    /// The watchdog is fed while every heartbeat is fresh and stops being fed, while STATUS=
    /// says why, once a source thread goes silent.
    #[test]
    fn a_stale_heartbeat_stops_the_watchdog_pings() {
        let (_dir, socket, notifier) = manager(Some("2000000"));
        let heartbeats = Heartbeats::default();
        let source = heartbeats.register("source");
        source.beat();
        let t0 = Instant::now();
        let mut feed = SystemdFeed::new(notifier, t0);
        assert_eq!(feed.next_due(), t0);
        feed.tick(t0, &heartbeats, &counters(0, 0, 0), 0);
        assert_eq!(received(&socket), ["WATCHDOG=1"]);
        assert_eq!(feed.next_due(), t0 + Duration::from_secs(1));

        // Long after the last beat: no ping, and the status says what is stuck.
        let late = t0 + STALL_AFTER + Duration::from_secs(2);
        feed.tick(late, &heartbeats, &counters(0, 0, 0), 0);
        let messages = received(&socket);
        assert!(
            !messages.iter().any(|m| m.contains("WATCHDOG")),
            "{messages:?}"
        );
        assert!(
            messages
                .iter()
                .any(|m| m.starts_with("STATUS=stuck: the source thread")),
            "{messages:?}"
        );
    }

    /// Frames waiting in the ring and none taken for longer than the stall limit: no ping.
    #[test]
    fn a_stuck_perception_thread_stops_the_watchdog_pings() {
        let (_dir, socket, notifier) = manager(Some("2000000"));
        let heartbeats = Heartbeats::default();
        let t0 = Instant::now();
        let mut feed = SystemdFeed::new(notifier, t0);
        // 100 frames in, 3 dropped, one queued: 96 taken; then nothing more is taken.
        let at = |s: u64| t0 + Duration::from_secs(s);
        let mut ping = |s, counters: CounterSnapshot| {
            feed.tick(at(s), &heartbeats, &counters, 0);
            received(&socket).contains(&"WATCHDOG=1".to_owned())
        };
        // The first look sees the frames taken so far; from the second on, one waits untaken.
        for s in 0..=6 {
            assert!(
                ping(s, counters(100, 3, 1)),
                "fed while the wait is short ({s} s)"
            );
        }
        assert!(!ping(7, counters(100, 3, 1)), "a wait past the limit");
        // It takes the frame: pings resume.
        assert!(ping(8, counters(101, 3, 1)));
    }

    /// Mesh jobs waiting and no meshing run finishing for longer than the stall limit: no
    /// ping. Jobs waiting while runs finish, or no jobs at all, are fine.
    #[test]
    fn stuck_meshers_stop_the_watchdog_pings() {
        let (_dir, socket, notifier) = manager(Some("2000000"));
        let heartbeats = Heartbeats::default();
        let t0 = Instant::now();
        let at = |s: u64| t0 + Duration::from_secs(s);
        let mut feed = SystemdFeed::new(notifier, t0);
        let meshed = |runs: u64| CounterSnapshot {
            meshing_runs: runs,
            ..CounterSnapshot::default()
        };
        // Ticks at these seconds with these runs finished and jobs waiting; the pings sent.
        let pings = |feed: &mut SystemdFeed,
                     seconds: std::ops::RangeInclusive<u64>,
                     runs: fn(u64) -> u64,
                     waiting| {
            let mut sent = 0;
            for s in seconds {
                feed.tick(at(s), &heartbeats, &meshed(runs(s)), waiting);
                // Read as systemd does: the socket's queue is short.
                sent += received(&socket)
                    .iter()
                    .filter(|m| *m == "WATCHDOG=1")
                    .count();
            }
            sent
        };
        // Runs finish while jobs wait, then nothing waits for a long time.
        assert_eq!(pings(&mut feed, 0..=6, |s| s, 3), 7);
        assert_eq!(pings(&mut feed, 7..=20, |_| 6, 0), 14);
        // Jobs wait and no run finishes: pings until the wait passes the limit.
        assert_eq!(pings(&mut feed, 21..=26, |_| 6, 2), 6);
        assert_eq!(pings(&mut feed, 27..=28, |_| 6, 2), 0);
    }

    #[test]
    fn the_status_line_has_rate_objects_subscribers_and_drops() {
        let mut snapshot = counters(100, 7, 0);
        snapshot.objects_tracked = 4;
        snapshot.publisher.clients_connected = 1;
        assert_eq!(
            status_line(29.96, &snapshot),
            "30.0 frames/s, 4 objects, 1 subscriber, 7 frames dropped, 0 source errors"
        );
    }

    #[test]
    fn the_status_line_names_lost_log_lines() {
        let mut snapshot = counters(100, 0, 0);
        snapshot.log_lines_dropped = 12;
        assert!(
            status_line(30.0, &snapshot)
                .ends_with(", 12 log lines lost (standard error is closed)"),
            "{}",
            status_line(30.0, &snapshot)
        );
    }

    /// Several meshers: one stuck inside a run while another keeps meshing (the queue as a
    /// whole moves) still stops the pings, once the stuck one passes its own limit; the
    /// source's shorter limit does not apply to it, and an idle one never stalls.
    #[test]
    fn one_stuck_mesher_among_several_stops_the_watchdog_pings() {
        let (_dir, socket, notifier) = manager(Some("2000000"));
        let heartbeats = Heartbeats::default();
        let source = heartbeats.register("source");
        let busy = heartbeats.register_worker("mesher 0", MESH_RUN_LIMIT);
        let stuck = heartbeats.register_worker("mesher 1", MESH_RUN_LIMIT);
        // A third waits for work all along: idle is never a stall.
        let waiting = heartbeats.register_worker("mesher 2", MESH_RUN_LIMIT);
        waiting.idle();
        assert!(!heartbeats.any_beaten());
        busy.beat();
        stuck.beat();
        assert!(
            !heartbeats.any_beaten(),
            "meshers do not make the daemon ready"
        );
        let t0 = Instant::now();
        let mut feed = SystemdFeed::new(notifier, t0);
        let mut pings_at = |at: Instant, runs: u64| {
            // Shift the beats the living threads would have made by `at`.
            let beat_at = |h: &Heartbeat| {
                h.slot.last_beat_ms.store(
                    millis_since(h.epoch, at),
                    std::sync::atomic::Ordering::Relaxed,
                )
            };
            beat_at(&source);
            beat_at(&busy);
            let snapshot = CounterSnapshot {
                meshing_runs: runs,
                ..counters(0, 0, 0)
            };
            feed.tick(at, &heartbeats, &snapshot, 1);
            received(&socket)
                .iter()
                .filter(|m| *m == "WATCHDOG=1")
                .count()
        };
        // Past the source's limit but within the mesher's: still fed.
        assert_eq!(pings_at(t0, 1), 1);
        assert_eq!(pings_at(t0 + STALL_AFTER * 2, 2), 1);
        // The stuck worker passes its own limit while the other keeps finishing runs.
        assert_eq!(pings_at(t0 + MESH_RUN_LIMIT + Duration::from_secs(1), 3), 0);
        stuck.retire();
        assert_eq!(pings_at(t0 + MESH_RUN_LIMIT + Duration::from_secs(3), 4), 1);
    }
}
