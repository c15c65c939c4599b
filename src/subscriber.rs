//! A blocking client of the daemon's socket: connects, checks the Hello, then yields messages.
//! `tacmesh subscribe` and the integration tests use it; any other client follows
//! `docs/protocol.md`.

use std::io::Read;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use tacmesh_protocol::{check_hello, encode, FrameDecoder, Message, Sender, Subscribe, WireError};

/// Why a subscription failed.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
pub enum SubscribeError {
    #[error(
        "cannot connect to {}: {cause}; is `tacmesh run` running with this --socket?",
        path.display()
    )]
    Connect {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("reading from {}: {cause}", path.display())]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("writing to {}: {cause}", path.display())]
    Write {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("the daemon on {} sent something unreadable: {cause}", path.display())]
    Wire { path: PathBuf, cause: WireError },
    #[error("the daemon on {} closed the connection", path.display())]
    Closed { path: PathBuf },
    #[error("the daemon on {} refused this subscriber: {reason}", path.display())]
    Refused { path: PathBuf, reason: String },
    #[error(
        "{} is served by uid {uid}{}, not by you, root or the tacmesh service user: another \
         local user may be impersonating the daemon; pass --trust-uid {uid} if you meant to \
         connect to it",
        path.display(),
        user.as_ref().map(|name| format!(" ({name})")).unwrap_or_default()
    )]
    Untrusted {
        path: PathBuf,
        uid: u32,
        user: Option<String>,
    },
    #[error("cannot tell who serves {}: {cause}", path.display())]
    PeerCredentials {
        path: PathBuf,
        cause: std::io::Error,
    },
}

/// The users a subscriber accepts as the server at the other end of the socket (checked with
/// the kernel's `SO_PEERCRED` when it connects): anyone who can bind a socket path first could
/// otherwise serve forged meshes to it, and from it to an operator's physics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrustedServers {
    uids: Vec<u32>,
}

/// The system user the packaged service runs as (systemd/tacmesh.sysusers).
pub const SERVICE_USER: &str = "tacmesh";

impl Default for TrustedServers {
    /// The subscriber's own effective user, root, and the service user `tacmesh` if this
    /// system has one.
    fn default() -> Self {
        let trusted = Self { uids: Vec::new() }
            .with_uid(nix::unistd::geteuid().as_raw())
            .with_uid(0);
        match nix::unistd::User::from_name(SERVICE_USER) {
            Ok(Some(user)) => trusted.with_uid(user.uid.as_raw()),
            _ => trusted,
        }
    }
}

impl TrustedServers {
    /// Trusts `uid` too (a daemon run by another user on purpose).
    pub fn with_uid(mut self, uid: u32) -> Self {
        if !self.uids.contains(&uid) {
            self.uids.push(uid);
        }
        self
    }

    pub fn trusts(&self, uid: u32) -> bool {
        self.uids.contains(&uid)
    }

    /// Refuses the server at the other end of `stream` unless it runs as a trusted user.
    fn check(&self, stream: &UnixStream, path: &Path) -> Result<(), SubscribeError> {
        let credentials = rustix::net::sockopt::socket_peercred(stream).map_err(|errno| {
            SubscribeError::PeerCredentials {
                path: path.to_owned(),
                cause: errno.into(),
            }
        })?;
        let uid = credentials.uid.as_raw();
        if self.trusts(uid) {
            return Ok(());
        }
        let user = nix::unistd::User::from_uid(nix::unistd::Uid::from_raw(uid))
            .ok()
            .flatten()
            .map(|user| user.name);
        Err(SubscribeError::Untrusted {
            path: path.to_owned(),
            uid,
            user,
        })
    }
}

/// One connection to the daemon.
pub struct Subscription {
    stream: UnixStream,
    path: PathBuf,
    decoder: FrameDecoder,
    buffer: Vec<u8>,
    /// The Hello's server name.
    pub server: String,
}

impl Subscription {
    /// Connects and reads the Hello (refusing another protocol version), with the daemon's
    /// default options. `read_timeout` bounds each wait for data (`None`: wait for ever).
    pub fn connect(path: &Path, read_timeout: Option<Duration>) -> Result<Self, SubscribeError> {
        Self::connect_with(path, read_timeout, None)
    }

    /// [`Subscription::connect`], then sends `options` if given. With `options.resend` the
    /// daemon's first snapshot (default options) is followed by a second one under `options`:
    /// a client keeping a scene starts it again at each Session.
    pub fn connect_with(
        path: &Path,
        read_timeout: Option<Duration>,
        options: Option<Subscribe>,
    ) -> Result<Self, SubscribeError> {
        Self::connect_trusting(path, read_timeout, options, &TrustedServers::default())
    }

    /// [`Subscription::connect_with`], accepting a server run by one of `trusted` (and no
    /// other: its connection is closed before anything is read from it).
    pub fn connect_trusting(
        path: &Path,
        read_timeout: Option<Duration>,
        options: Option<Subscribe>,
        trusted: &TrustedServers,
    ) -> Result<Self, SubscribeError> {
        let connect_err = |cause| SubscribeError::Connect {
            path: path.to_owned(),
            cause,
        };
        let mut stream = UnixStream::connect(path).map_err(connect_err)?;
        trusted.check(&stream, path)?;
        stream.set_read_timeout(read_timeout).map_err(connect_err)?;
        if let Some(options) = options {
            let mut frame = Vec::new();
            encode(&Message::Subscribe(options), &mut frame).map_err(|cause| {
                SubscribeError::Wire {
                    path: path.to_owned(),
                    cause,
                }
            })?;
            // A failed write is not the error to report: a daemon that refuses this peer may
            // already have sent its Goodbye and closed (the write then fails with a broken
            // pipe), and the read below gets that Goodbye, or says what else went wrong.
            let _ = std::io::Write::write_all(&mut stream, &frame);
        }
        let mut subscription = Subscription {
            stream,
            path: path.to_owned(),
            decoder: FrameDecoder::new(Sender::Server),
            buffer: vec![0; 64 * 1024],
            server: String::new(),
        };
        let first = subscription.next_message()?;
        if let Message::Goodbye { reason } = first {
            return Err(SubscribeError::Refused {
                path: path.to_owned(),
                reason,
            });
        }
        check_hello(&first).map_err(|cause| SubscribeError::Wire {
            path: path.to_owned(),
            cause,
        })?;
        if let Message::Hello { server, .. } = first {
            subscription.server = server;
        }
        Ok(subscription)
    }

    /// The next message; blocks (up to the read timeout).
    pub fn next_message(&mut self) -> Result<Message, SubscribeError> {
        loop {
            match self.decoder.next_message() {
                Ok(Some(message)) => return Ok(message),
                Ok(None) => {}
                Err(cause) => {
                    return Err(SubscribeError::Wire {
                        path: self.path.clone(),
                        cause,
                    })
                }
            }
            // A socket read with a timeout is never restarted after a signal handler ran
            // (signal(7)), whatever SA_RESTART says: a Ctrl-C handler or a child's exit in the
            // same process would otherwise end the subscription.
            let n = loop {
                match self.stream.read(&mut self.buffer) {
                    Err(cause) if cause.kind() == std::io::ErrorKind::Interrupted => {}
                    other => {
                        break other.map_err(|cause| SubscribeError::Read {
                            path: self.path.clone(),
                            cause,
                        })?
                    }
                }
            };
            if n == 0 {
                return Err(SubscribeError::Closed {
                    path: self.path.clone(),
                });
            }
            self.decoder.push(&self.buffer[..n]);
        }
    }

    /// Sends new options (see `docs/protocol.md`, Subscribe).
    pub fn subscribe(&mut self, options: Subscribe) -> Result<(), SubscribeError> {
        let mut frame = Vec::new();
        encode(&Message::Subscribe(options), &mut frame).map_err(|cause| SubscribeError::Wire {
            path: self.path.clone(),
            cause,
        })?;
        std::io::Write::write_all(&mut self.stream, &frame).map_err(|cause| SubscribeError::Write {
            path: self.path.clone(),
            cause,
        })
    }

    /// The underlying socket (tests use it to stall or misbehave on purpose).
    pub fn stream(&self) -> &UnixStream {
        &self.stream
    }
}
