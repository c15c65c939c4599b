//! The messages, their kind bytes and the limits of the format.

use tacmesh_source::TriMesh;

use crate::error::WireError;

/// The protocol version this crate speaks, sent in every [`Message::Hello`]. Any change to the
/// format bumps it: a new message kind (existing layouts untouched, so a newer client can still
/// read an older server) or a changed layout (see `docs/protocol.md`, "Versioning").
pub const PROTOCOL_VERSION: u16 = 1;

/// The largest frame either side sends or accepts, counted as the value of the length prefix
/// (message kind byte plus payload, not the 4 prefix bytes): 64 MiB. A simplified object mesh is
/// kilobytes; this only guards against a corrupt or hostile length prefix. An [`Upsert`] of
/// about 2.8 million vertices and as many triangles would reach it.
pub const MAX_FRAME_BYTES: usize = 64 * 1024 * 1024;

/// The longest server name (in [`Message::Hello`]) and stage name (in [`StageLatency`]), in
/// UTF-8 bytes.
pub const MAX_NAME_BYTES: usize = 64;

/// The longest [`Message::Goodbye`] reason, in UTF-8 bytes.
pub const MAX_REASON_BYTES: usize = 1024;

/// Who sends a message kind. Kinds `0x01..=0x7f` are sent by the server (the daemon), kinds
/// `0x80..=0xff` by a client; `0x00` is never valid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sender {
    Server,
    Client,
}

impl std::fmt::Display for Sender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Sender::Server => "server",
            Sender::Client => "client",
        })
    }
}

/// The kind bytes. Never reuse a retired value.
pub(crate) mod kind {
    pub const HELLO: u8 = 0x01;
    pub const UPSERT: u8 = 0x02;
    pub const REMOVE: u8 = 0x03;
    pub const SNAPSHOT_DONE: u8 = 0x04;
    pub const STATS: u8 = 0x05;
    pub const GOODBYE: u8 = 0x06;
    pub const SUBSCRIBE: u8 = 0x80;

    /// The kind's name as errors print it, or `None` for a kind this version does not know.
    pub fn name(kind: u8) -> Option<&'static str> {
        Some(match kind {
            HELLO => "Hello",
            UPSERT => "Upsert",
            REMOVE => "Remove",
            SNAPSHOT_DONE => "SnapshotDone",
            STATS => "Stats",
            GOODBYE => "Goodbye",
            SUBSCRIBE => "Subscribe",
            _ => return None,
        })
    }
}

/// One message on the wire.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// Server → client, always the first message on a connection. Its layout never changes in
    /// any protocol version, so every client can read the version and refuse cleanly.
    Hello {
        protocol_version: u16,
        /// The daemon's name and version, e.g. `tacmesh 0.1.0`; at most [`MAX_NAME_BYTES`].
        server: String,
    },
    /// Server → client: a new object, or a new mesh of a known object.
    Upsert(Upsert),
    /// Server → client: the object is gone; forget its mesh.
    Remove { object_id: u64 },
    /// Server → client: every object that existed at connect time has been sent as an Upsert.
    SnapshotDone,
    /// Server → client: the daemon's counters, sent periodically.
    Stats(Stats),
    /// Server → client: the daemon is shutting down; the connection closes after this.
    Goodbye {
        /// Why, for a human; at most [`MAX_REASON_BYTES`].
        reason: String,
    },
    /// Client → server: optional, empty in this version. The daemon sends the snapshot whether or
    /// not a client sends it.
    Subscribe,
}

impl Message {
    /// The Hello this crate's version sends.
    pub fn hello(server: impl Into<String>) -> Self {
        Message::Hello {
            protocol_version: PROTOCOL_VERSION,
            server: server.into(),
        }
    }

    /// Who may send this message.
    pub fn sender(&self) -> Sender {
        if self.kind() & 0x80 == 0 {
            Sender::Server
        } else {
            Sender::Client
        }
    }

    /// The message's name, as errors and logs print it.
    pub fn name(&self) -> &'static str {
        kind::name(self.kind()).unwrap_or("unknown")
    }

    pub(crate) fn kind(&self) -> u8 {
        match self {
            Message::Hello { .. } => kind::HELLO,
            Message::Upsert(_) => kind::UPSERT,
            Message::Remove { .. } => kind::REMOVE,
            Message::SnapshotDone => kind::SNAPSHOT_DONE,
            Message::Stats(_) => kind::STATS,
            Message::Goodbye { .. } => kind::GOODBYE,
            Message::Subscribe => kind::SUBSCRIBE,
        }
    }
}

/// A new mesh of one object.
#[derive(Debug, Clone, PartialEq)]
pub struct Upsert {
    /// Stable for as long as the daemon tracks the object; never reused within a daemon run.
    pub object_id: u64,
    /// Grows with every new mesh of this object; a client keeps the highest it has seen.
    pub version: u64,
    /// Capture time, in nanoseconds on the host's `CLOCK_MONOTONIC`
    /// ([`tacmesh_source::monotonic_now`]), of the newest depth frame that contributed to this
    /// mesh. A client on the same host subtracts it from its own monotonic now for the age.
    pub capture_time_ns: u64,
    /// Vertices in metres (world frame), triangles counter-clockwise seen from outside. Every
    /// coordinate is finite and every index is below the vertex count.
    pub mesh: TriMesh,
    pub report: SimplifyStats,
}

/// What simplification did to produce [`Upsert::mesh`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimplifyStats {
    /// Triangles before simplification (the marching-cubes mesh).
    pub faces_in: u32,
    /// Triangles after simplification.
    pub faces_out: u32,
    /// The largest distance, in metres, from an input vertex to the output surface; finite and
    /// not negative.
    pub max_residual_m: f32,
}

/// The daemon's counters since it started, and its latencies over a recent window.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stats {
    pub frames_in: u64,
    pub frames_dropped: u64,
    pub invalid_pixels: u64,
    pub objects_tracked: u64,
    pub meshing_runs: u64,
    pub meshes_published: u64,
    pub bytes_sent: u64,
    /// Per pipeline stage (deproject, segment, integrate, mesh, simplify, publish, …).
    pub stage_latencies: Vec<StageLatency>,
    /// From a frame's capture to the publication of a mesh it contributed to, milliseconds.
    pub frame_to_publish_p50_ms: f32,
    pub frame_to_publish_p99_ms: f32,
}

/// The latency of one pipeline stage. Latencies are finite and not negative; a stage with no
/// samples yet reports 0.
#[derive(Debug, Clone, PartialEq)]
pub struct StageLatency {
    /// At most [`MAX_NAME_BYTES`] of UTF-8.
    pub stage: String,
    pub p50_ms: f32,
    pub p99_ms: f32,
}

/// What a client does with the first message of a connection: `Ok` for a Hello of
/// [`PROTOCOL_VERSION`], [`WireError::VersionMismatch`] for another version,
/// [`WireError::NotHello`] for any other message.
pub fn check_hello(message: &Message) -> Result<(), WireError> {
    match message {
        Message::Hello {
            protocol_version, ..
        } if *protocol_version == PROTOCOL_VERSION => Ok(()),
        Message::Hello {
            protocol_version, ..
        } => Err(WireError::VersionMismatch {
            ours: PROTOCOL_VERSION,
            theirs: *protocol_version,
        }),
        other => Err(WireError::NotHello { got: other.name() }),
    }
}
