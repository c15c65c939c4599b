//! The messages, their kind bytes and the limits of the format.

use tacmesh_source::TriMesh;

use crate::error::WireError;

/// The protocol version this crate speaks, sent in every [`Message::Hello`]. Any change to the
/// format bumps it: a new message kind (existing layouts untouched, so a newer client can still
/// read an older server) or a changed layout (see `docs/protocol.md`, "Versioning").
/// Version 2 put each object's shape in its own frame with a pose, so that a move is a
/// [`Pose`] of under 100 bytes instead of a whole mesh; version 3 added each object's collision
/// body ([`Body`]: a closed proxy, convex parts, mass properties); version 4 made the body
/// the object's completed solid (a primitive where it is one), its kind `0x0C`.
pub const PROTOCOL_VERSION: u16 = 4;

/// The largest frame either side sends or accepts, counted as the value of the length prefix
/// (message kind byte plus payload, not the 4 prefix bytes): 64 MiB. A simplified object mesh is
/// kilobytes; this only guards against a corrupt or hostile length prefix. A full-encoding
/// [`Shape`] of about 2.8 million vertices and as many triangles would reach it.
pub const MAX_FRAME_BYTES: usize = 64 * 1024 * 1024;

/// The longest server name (in [`Message::Hello`]) and stage name (in [`StageLatency`]), in
/// UTF-8 bytes.
pub const MAX_NAME_BYTES: usize = 64;

/// The longest [`Message::Goodbye`] reason, in UTF-8 bytes.
pub const MAX_REASON_BYTES: usize = 1024;

/// The most object ids a [`Subscribe`] may list.
pub const MAX_SUBSCRIBE_IDS: usize = 1024;

/// The lowest non-zero [`Subscribe::max_rate_hz`]: one update of an object every 100 s. A
/// lower rate is refused rather than rounded, since a client that asks for it is broken.
pub const MIN_RATE_HZ: f32 = 0.01;

/// The highest [`Subscribe::max_rate_hz`]: above it the cap would never hold anything back
/// (no sensor runs this fast); a client that wants no cap sends 0.
pub const MAX_RATE_HZ: f32 = 10_000.0;

/// The most convex hulls a [`Body`] may have.
pub const MAX_HULLS: usize = 16;

/// The most vertices one hull of a [`Body`] may have (its indices are one byte).
pub const MAX_HULL_VERTICES: usize = 255;

/// The fewest vertices a hull has: a tetrahedron's.
pub const MIN_HULL_VERTICES: usize = 4;

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

/// The kind bytes. Never reuse a retired value: `0x02` (version 1's Upsert), `0x05`
/// (version 1's Stats) and `0x0B` (version 3's Body) are retired; `0x80` (version 1's empty Subscribe) is still decoded, so
/// that a server can tell a version-1 client why it is refused.
pub(crate) mod kind {
    pub const HELLO: u8 = 0x01;
    pub const REMOVE: u8 = 0x03;
    pub const SNAPSHOT_DONE: u8 = 0x04;
    pub const GOODBYE: u8 = 0x06;
    pub const SESSION: u8 = 0x07;
    pub const SHAPE: u8 = 0x08;
    pub const POSE: u8 = 0x09;
    pub const STATS: u8 = 0x0a;
    pub const BODY: u8 = 0x0c;
    pub const SUBSCRIBE_V1: u8 = 0x80;
    pub const SUBSCRIBE: u8 = 0x81;

    /// The kind's name as errors print it, or `None` for a kind this version does not know.
    pub fn name(kind: u8) -> Option<&'static str> {
        Some(match kind {
            HELLO => "Hello",
            REMOVE => "Remove",
            SNAPSHOT_DONE => "SnapshotDone",
            GOODBYE => "Goodbye",
            SESSION => "Session",
            SHAPE => "Shape",
            POSE => "Pose",
            STATS => "Stats",
            BODY => "Body",
            SUBSCRIBE_V1 => "Subscribe (version 1)",
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
    /// Server → client: a snapshot begins (after Hello, and after a Subscribe asking for one).
    Session(Session),
    /// Server → client: a new object, or a new shape of a known one, with its pose.
    Shape(Shape),
    /// Server → client: an object's new pose (its shape unchanged), or that it was seen again.
    Pose(Pose),
    /// Server → client: an object's collision body, made from one of its shapes.
    Body(Body),
    /// Server → client: the object is gone; forget it.
    Remove { object_id: u64 },
    /// Server → client: every object of the snapshot has been sent.
    SnapshotDone,
    /// Server → client: the daemon's counters, sent periodically.
    Stats(Stats),
    /// Server → client: the daemon is shutting down or refuses the client; the connection
    /// closes after this.
    Goodbye {
        /// Why, for a human; at most [`MAX_REASON_BYTES`].
        reason: String,
    },
    /// Client → server: what the client wants; optional.
    Subscribe(Subscribe),
    /// Client → server: version 1's empty Subscribe. A version-2 server answers it with a
    /// Goodbye saying which versions are spoken, and closes the connection.
    SubscribeV1,
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
            Message::Session(_) => kind::SESSION,
            Message::Shape(_) => kind::SHAPE,
            Message::Pose(_) => kind::POSE,
            Message::Body(_) => kind::BODY,
            Message::Remove { .. } => kind::REMOVE,
            Message::SnapshotDone => kind::SNAPSHOT_DONE,
            Message::Stats(_) => kind::STATS,
            Message::Goodbye { .. } => kind::GOODBYE,
            Message::Subscribe(_) => kind::SUBSCRIBE,
            Message::SubscribeV1 => kind::SUBSCRIBE_V1,
        }
    }
}

/// How a [`Shape`]'s vertices and triangles are laid out on the wire.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// Vertices as three `f32`, triangles as three `u32`: 12 bytes each.
    #[default]
    Full,
    /// Vertices quantised to 16 bits per axis within the shape's bounding box, triangles as
    /// three `u16` when there are at most 65,536 vertices (else three `u32`): about 9 bytes a
    /// face instead of 18. Adds at most [`quantisation_bound_m`] of error, which the sent
    /// `max_residual_m` includes.
    Compact,
}

impl Encoding {
    pub(crate) fn byte(self) -> u8 {
        match self {
            Encoding::Full => 0,
            Encoding::Compact => 1,
        }
    }

    pub(crate) fn from_byte(byte: u8) -> Option<Self> {
        match byte {
            0 => Some(Encoding::Full),
            1 => Some(Encoding::Compact),
            _ => None,
        }
    }
}

/// The largest distance a vertex of the box from `min` to `max` (object frame, metres) reads
/// back from where it was with [`Encoding::Compact`]: half a step of 1/65,535 of the box's
/// extent on each axis, plus what a receiver's `f32` arithmetic adds to it (per axis about
/// three roundings of the step times up to 65,535, 3 · 2⁻²⁴ of the extent, and one of the
/// coordinate, 2⁻²⁴ of it: negligible for an object whose frame's origin is near it). The
/// encoder adds it to the residual, so the residual a client reads is a true bound.
pub fn quantisation_bound_m(min: glam::Vec3, max: glam::Vec3) -> f32 {
    let extent = (max - min).max(glam::Vec3::ZERO);
    let rounding = f32::EPSILON / 2.0;
    0.5 * extent.length() / 65_535.0
        + rounding * (3.0 * extent.length() + min.abs().max(max.abs()).length())
}

/// What a client is sent: which objects by kind ([`Kinds::OBJECTS`], [`Kinds::SUPPORTS`] or
/// both), and whether the objects' collision bodies too ([`Kinds::BODIES`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Kinds(pub(crate) u8);

impl Kinds {
    /// Tracked objects (ids below 2^32).
    pub const OBJECTS: Kinds = Kinds(1);
    /// Support planes: tables, floors (ids from 2^32).
    pub const SUPPORTS: Kinds = Kinds(2);
    /// The [`Body`] of each object sent.
    pub const BODIES: Kinds = Kinds(4);
    pub const ALL: Kinds = Kinds(7);

    /// The kinds in `bits` (bit 0 objects, bit 1 supports, bit 2 bodies), or `None` when
    /// neither objects nor supports are asked for or a bit is unknown.
    pub fn from_bits(bits: u8) -> Option<Self> {
        (bits & 3 != 0 && bits & !7 == 0).then_some(Kinds(bits))
    }

    pub fn bits(self) -> u8 {
        self.0
    }

    pub fn contains(self, other: Kinds) -> bool {
        self.0 & other.0 == other.0
    }

    /// These kinds and `other`'s.
    pub fn with(self, other: Kinds) -> Kinds {
        Kinds(self.0 | other.0)
    }

    /// These kinds without `other`'s bits, or `None` when no object kind would be left.
    pub fn without(self, other: Kinds) -> Option<Kinds> {
        Kinds::from_bits(self.0 & !other.0)
    }
}

impl Default for Kinds {
    fn default() -> Self {
        Kinds::ALL
    }
}

/// The first id of a support plane; objects have ids from 1 below it.
pub const FIRST_SUPPORT_ID: u64 = 1 << 32;

/// What a client asks for. Every Subscribe replaces the options of the one before.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Subscribe {
    /// How shapes are to be encoded.
    pub encoding: Encoding,
    /// Send a fresh snapshot (Session, a Shape of every object, SnapshotDone) under the new
    /// options.
    pub resend: bool,
    /// The client extrapolates each pose by its velocity ([`Pose::extrapolated`]): the server
    /// sends a Pose only when that extrapolation would be off by more than
    /// [`EXTRAPOLATION_TOLERANCE_M`] or [`EXTRAPOLATION_TOLERANCE_RAD`], or when the object's
    /// last Pose to the client is [`EXTRAPOLATION_REFRESH`] old (dead reckoning).
    pub extrapolate: bool,
    /// At most this many Shapes and Poses a second per object (the latest is sent when the
    /// interval is over); 0 for no cap, else from [`MIN_RATE_HZ`] to [`MAX_RATE_HZ`].
    pub max_rate_hz: f32,
    /// Which kinds of object to send.
    pub kinds: Kinds,
    /// Only these objects (of those kinds); empty for all. At most [`MAX_SUBSCRIBE_IDS`].
    pub object_ids: Vec<u64>,
}

/// A snapshot begins: the server's clocks now, and the options it follows from here on.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Session {
    /// `CLOCK_MONOTONIC` of the daemon's host when this message was written, nanoseconds.
    pub monotonic_ns: u64,
    /// `CLOCK_REALTIME` (nanoseconds since the Unix epoch) at the same moment.
    pub realtime_ns: u64,
    /// The options in effect (the defaults until the client sends a Subscribe).
    pub options: Subscribe,
}

/// Where an object is and how it moves. The whole payload of a Pose message, and the start of
/// a Shape's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub object_id: u64,
    /// The version of the shape this pose places.
    pub shape_version: u64,
    /// Capture time of the frame this pose was estimated from, `CLOCK_MONOTONIC` nanoseconds;
    /// never goes backwards for one object.
    pub pose_time_ns: u64,
    /// The same instant on `CLOCK_REALTIME` (nanoseconds since the Unix epoch).
    pub pose_time_realtime_ns: u64,
    /// Capture time of the newest frame in which the object was seen where this pose puts it
    /// (`CLOCK_MONOTONIC`); at least `pose_time_ns`, never goes backwards.
    pub last_seen_ns: u64,
    /// `world_from_object`: a unit quaternion and a translation in metres.
    pub rotation: glam::Quat,
    pub translation: glam::Vec3,
    /// Velocity of the object frame's origin in the world, m/s.
    pub linear_velocity: glam::Vec3,
    /// Angular velocity in the world frame, rad/s (axis × rate).
    pub angular_velocity: glam::Vec3,
}

impl Pose {
    /// `world_from_object` as an affine transform.
    pub fn world_from_object(&self) -> glam::Affine3A {
        glam::Affine3A::from_rotation_translation(self.rotation, self.translation)
    }

    /// `world_from_object` at `time_ns` (`CLOCK_MONOTONIC`), extrapolated from the pose time by
    /// the velocities: the translation moves by `linear_velocity · Δt`, the rotation turns by
    /// `angular_velocity · Δt` (about the world axis, before the pose's own rotation).
    pub fn extrapolated(&self, time_ns: u64) -> glam::Affine3A {
        let (rotation, translation) = self.extrapolated_parts(time_ns);
        glam::Affine3A::from_rotation_translation(rotation, translation)
    }

    /// The rotation and translation of [`Pose::extrapolated`].
    pub fn extrapolated_parts(&self, time_ns: u64) -> (glam::Quat, glam::Vec3) {
        let dt = (time_ns as f64 - self.pose_time_ns as f64) as f32 * 1e-9;
        let turn = glam::Quat::from_scaled_axis(self.angular_velocity * dt);
        (
            (turn * self.rotation).normalize(),
            self.translation + self.linear_velocity * dt,
        )
    }

    /// Whether `newer` (of the same object) must be sent to a client that extrapolates this
    /// pose: its extrapolation to `newer`'s time is off by more than the tolerances, or it is
    /// [`EXTRAPOLATION_REFRESH`] old.
    pub fn extrapolation_misses(&self, newer: &Pose) -> bool {
        if newer.shape_version != self.shape_version
            || newer.last_seen_ns.saturating_sub(self.last_seen_ns)
                >= EXTRAPOLATION_REFRESH.as_nanos() as u64
        {
            return true;
        }
        let (rotation, translation) = self.extrapolated_parts(newer.pose_time_ns);
        translation.distance(newer.translation) > EXTRAPOLATION_TOLERANCE_M
            || rotation.angle_between(newer.rotation) > EXTRAPOLATION_TOLERANCE_RAD
    }
}

/// How far a client's extrapolated pose may be from the daemon's estimate before the daemon
/// sends it a Pose ([`Subscribe::extrapolate`]): 2 mm…
pub const EXTRAPOLATION_TOLERANCE_M: f32 = 0.002;
/// …and 1°.
pub const EXTRAPOLATION_TOLERANCE_RAD: f32 = std::f32::consts::PI / 180.0;
/// An extrapolating client gets a Pose of each object at least this often while the object is
/// seen, so that its last-seen time advances.
pub const EXTRAPOLATION_REFRESH: std::time::Duration = std::time::Duration::from_secs(1);

/// A shape flag: the mesh is closed (every edge shared by two triangles), wound
/// counter-clockwise seen from outside.
pub const SHAPE_CLOSED: u8 = 1;
/// A shape flag: the object is a support plane (a table, a floor), its fan facing the side the
/// sensor saw it from.
pub const SHAPE_SUPPORT: u8 = 2;
/// A shape flag: the object's frame is not the one its earlier shapes were in, so a [`Body`]
/// made from an earlier shape does not fit this one.
pub const SHAPE_NEW_FRAME: u8 = 4;

/// A new shape of one object (in its own frame) and the pose that places it.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// `pose.shape_version` is this shape's version; it grows with every new shape.
    pub pose: Pose,
    /// Capture time of the newest frame fused into the shape, `CLOCK_MONOTONIC` nanoseconds;
    /// never goes backwards for one object.
    pub shape_time_ns: u64,
    pub shape_time_realtime_ns: u64,
    /// [`SHAPE_CLOSED`], [`SHAPE_SUPPORT`].
    pub flags: u8,
    /// Vertices in metres in the object's frame. Every coordinate is finite and every index is
    /// below the vertex count.
    pub mesh: TriMesh,
    /// What simplification did; its residual includes the quantisation of a compact encoding.
    pub report: SimplifyStats,
    /// How the shape is (to be) laid out on the wire.
    pub encoding: Encoding,
}

impl Shape {
    /// The mesh placed in the world by its pose.
    pub fn world_mesh(&self) -> TriMesh {
        let pose = self.pose.world_from_object();
        TriMesh::new(
            self.mesh
                .vertices
                .iter()
                .map(|&v| pose.transform_point3(v))
                .collect(),
            self.mesh.triangles.clone(),
        )
    }

    pub fn object_id(&self) -> u64 {
        self.pose.object_id
    }

    pub fn version(&self) -> u64 {
        self.pose.shape_version
    }

    pub fn is_closed(&self) -> bool {
        self.flags & SHAPE_CLOSED != 0
    }

    pub fn is_support(&self) -> bool {
        self.flags & SHAPE_SUPPORT != 0
    }

    pub fn is_new_frame(&self) -> bool {
        self.flags & SHAPE_NEW_FRAME != 0
    }
}

/// What a [`Body`] is: the solid its mass properties and hulls are of, best first. The first
/// three are the object completed where it was not seen; the last two are conservative
/// fallbacks that take in all the space behind what was seen, flagged as such.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BodySolid {
    /// The shape is closed and is its own solid; the body carries no mesh.
    Shape,
    /// The object is a primitive ([`Body::primitive`]); the body carries no mesh.
    Primitive,
    /// The seen shell closed by the object's symmetry (an axis of revolution along the
    /// support's normal), standing on its support, within the space the sensor did not see
    /// as free.
    Completed,
    /// Fallback: the open shell swept away from the sensor along its rays to the support plane.
    ShadowVolume,
    /// Fallback: the open shell swept straight down onto the support plane (no sensor position
    /// known).
    Extrusion,
}

impl BodySolid {
    pub(crate) fn byte(self) -> u8 {
        match self {
            BodySolid::Shape => 0,
            BodySolid::Primitive => 1,
            BodySolid::Completed => 2,
            BodySolid::ShadowVolume => 3,
            BodySolid::Extrusion => 4,
        }
    }

    pub(crate) fn from_byte(byte: u8) -> Option<Self> {
        match byte {
            0 => Some(BodySolid::Shape),
            1 => Some(BodySolid::Primitive),
            2 => Some(BodySolid::Completed),
            3 => Some(BodySolid::ShadowVolume),
            4 => Some(BodySolid::Extrusion),
            _ => None,
        }
    }

    /// Whether the body carries its solid's surface as a mesh (the shape and a primitive need
    /// none).
    pub fn carries_mesh(self) -> bool {
        !matches!(self, BodySolid::Shape | BodySolid::Primitive)
    }

    /// Whether the solid is a conservative fallback (the shadow volume or the extrusion): its
    /// mass properties are those of the space behind what was seen, not of the object.
    pub fn is_fallback(self) -> bool {
        matches!(self, BodySolid::ShadowVolume | BodySolid::Extrusion)
    }

    pub fn as_str(self) -> &'static str {
        match self {
            BodySolid::Shape => "shape",
            BodySolid::Primitive => "primitive",
            BodySolid::Completed => "completed solid",
            BodySolid::ShadowVolume => "shadow volume",
            BodySolid::Extrusion => "extrusion",
        }
    }
}

/// The sizes of a [`BodyPrimitive`], in its own frame: a box's sides along x, y, z; a
/// cylinder's and a capsule's axis along z, centred on the origin; a sphere about the origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PrimitiveShape {
    Box {
        half_m: glam::Vec3,
    },
    Cylinder {
        radius_m: f32,
        half_height_m: f32,
    },
    Sphere {
        radius_m: f32,
    },
    /// A cylinder of `half_height_m` either side of the origin with a hemisphere on each end
    /// (MuJoCo's and Bullet's capsule: its whole length is `2 * (half_height_m + radius_m)`).
    Capsule {
        radius_m: f32,
        half_height_m: f32,
    },
}

impl PrimitiveShape {
    pub(crate) fn byte(&self) -> u8 {
        match self {
            PrimitiveShape::Box { .. } => 1,
            PrimitiveShape::Cylinder { .. } => 2,
            PrimitiveShape::Sphere { .. } => 3,
            PrimitiveShape::Capsule { .. } => 4,
        }
    }

    /// The three size fields of the wire, unused ones 0.
    pub(crate) fn sizes(&self) -> [f32; 3] {
        match *self {
            PrimitiveShape::Box { half_m } => half_m.to_array(),
            PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            }
            | PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            } => [radius_m, half_height_m, 0.0],
            PrimitiveShape::Sphere { radius_m } => [radius_m, 0.0, 0.0],
        }
    }

    /// The shape of a kind byte (1 to 4) and its size fields, or `None` for another byte.
    pub(crate) fn from_wire(kind: u8, sizes: [f32; 3]) -> Option<Self> {
        let [a, b, c] = sizes;
        Some(match kind {
            1 => PrimitiveShape::Box {
                half_m: glam::Vec3::new(a, b, c),
            },
            2 => PrimitiveShape::Cylinder {
                radius_m: a,
                half_height_m: b,
            },
            3 => PrimitiveShape::Sphere { radius_m: a },
            4 => PrimitiveShape::Capsule {
                radius_m: a,
                half_height_m: b,
            },
            _ => return None,
        })
    }

    /// How many of the three size fields the kind uses (the rest are 0 on the wire).
    pub(crate) fn used_sizes(&self) -> usize {
        match self {
            PrimitiveShape::Box { .. } => 3,
            PrimitiveShape::Cylinder { .. } | PrimitiveShape::Capsule { .. } => 2,
            PrimitiveShape::Sphere { .. } => 1,
        }
    }

    /// A short name: `box`, `cylinder`, `sphere`, `capsule`.
    pub fn name(&self) -> &'static str {
        match self {
            PrimitiveShape::Box { .. } => "box",
            PrimitiveShape::Cylinder { .. } => "cylinder",
            PrimitiveShape::Sphere { .. } => "sphere",
            PrimitiveShape::Capsule { .. } => "capsule",
        }
    }
}

/// The primitive an object is ([`BodySolid::Primitive`]), placed in the object's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyPrimitive {
    pub shape: PrimitiveShape,
    /// From the primitive's frame to the object's: a unit quaternion.
    pub rotation: glam::Quat,
    /// The primitive's centre, object frame, metres.
    pub centre: glam::Vec3,
    /// The 95th percentile of the seen surface's distances from the primitive, metres.
    pub residual_m: f32,
}

/// One convex part of a [`Body`]: at most [`MAX_HULL_VERTICES`] vertices (at least
/// [`MIN_HULL_VERTICES`]) and its faces, counter-clockwise seen from outside.
#[derive(Debug, Clone, PartialEq)]
pub struct Hull {
    pub vertices: Vec<glam::Vec3>,
    pub triangles: Vec<[u8; 3]>,
}

impl Hull {
    /// The hull as a mesh.
    pub fn mesh(&self) -> TriMesh {
        TriMesh::new(
            self.vertices.clone(),
            self.triangles.iter().map(|t| t.map(u32::from)).collect(),
        )
    }
}

/// An object's collision body, made from the shape whose version it names (its vertices are
/// in that shape's frame, placed by the object's pose): the solid a physics engine gives mass
/// to (the object completed where the sensor did not see it, or a flagged fallback), the
/// convex parts covering it, and its mass properties for a density of 1 kg/m³.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    pub object_id: u64,
    /// The version of the shape it was made from.
    pub shape_version: u64,
    pub solid: BodySolid,
    /// How far the solid was grown outward from the seen surface, metres.
    pub margin_m: f32,
    /// The solid's volume, m³ (positive).
    pub volume_m3: f32,
    /// The solid's centre of mass, object frame.
    pub centre_of_mass: glam::Vec3,
    /// The solid's inertia tensor about its centre of mass, at unit density (kg·m² per kg/m³),
    /// along the object frame's axes; symmetric (the wire carries its upper triangle).
    pub inertia: [[f32; 3]; 3],
    /// The primitive, present exactly when `solid` is [`BodySolid::Primitive`].
    pub primitive: Option<BodyPrimitive>,
    /// The solid's surface, closed, counter-clockwise seen from outside; empty for
    /// [`BodySolid::Shape`] (the shape is the solid) and [`BodySolid::Primitive`].
    pub mesh: TriMesh,
    /// How `mesh` is (to be) laid out on the wire.
    pub encoding: Encoding,
    /// Convex parts whose union covers the solid; at most [`MAX_HULLS`].
    pub hulls: Vec<Hull>,
}

/// What simplification did to produce a shape's mesh.
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
    /// `CLOCK_MONOTONIC` and `CLOCK_REALTIME` when the stats were taken, nanoseconds.
    pub monotonic_ns: u64,
    pub realtime_ns: u64,
    pub frames_in: u64,
    pub frames_dropped: u64,
    pub invalid_pixels: u64,
    pub malformed_frames: u64,
    pub source_errors: u64,
    pub source_restarts: u64,
    pub objects_tracked: u64,
    pub objects_born: u64,
    pub objects_removed: u64,
    pub meshing_runs: u64,
    pub meshing_failures: u64,
    pub shapes_published: u64,
    pub poses_published: u64,
    pub bytes_sent: u64,
    pub clients_connected: u64,
    pub clients_dropped: u64,
    pub clients_refused: u64,
    /// Samples in each latency window.
    pub latency_window: u32,
    /// From a frame's capture to the publication of a shape or pose it contributed to, ms.
    pub frame_to_publish_p50_ms: f32,
    pub frame_to_publish_p99_ms: f32,
    /// Per pipeline stage (deproject, segment, integrate, mesh wait, mesh, simplify, publish,
    /// body, …).
    pub stage_latencies: Vec<StageLatency>,
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
