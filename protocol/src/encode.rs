//! Message → frame. Every check a decoder makes is a function here that both sides call, so
//! whatever [`encode`] accepts decodes, and what it refuses a decoder would refuse too.
//!
//! In the order a frame is built: the layout sizes, the checks, the compact encoding's box and
//! quantisation, the payload writers, and [`encode`] last.

use glam::Vec3;
use tacmesh_source::TriMesh;

use crate::error::WireError;
use crate::message::{
    quantisation_bound_m, Body, BodyPrimitive, BodySolid, Encoding, Hull, Kinds, Message, Pose,
    Session, Shape, Stats, Subscribe, MAX_FRAME_BYTES, MAX_HULLS, MAX_HULL_VERTICES,
    MAX_NAME_BYTES, MAX_RATE_HZ, MAX_REASON_BYTES, MAX_SUBSCRIBE_IDS, MIN_HULL_VERTICES,
    MIN_RATE_HZ, SHAPE_CLOSED, SHAPE_NEW_FRAME, SHAPE_SUPPORT,
};

// ---- layout sizes (docs/protocol.md, "Messages") ----------------------------------------------

/// Bytes of the length prefix.
pub(crate) const PREFIX_BYTES: usize = 4;
/// A Pose payload: five u64 (ids and times), a quaternion and three vectors of f32.
pub(crate) const POSE_BYTES: usize = 5 * 8 + 4 * 4 + 3 * 3 * 4;
/// A Shape payload before its geometry: the pose, two u64 times, the flags byte, the report
/// (2 × u32 + f32), the encoding byte and the two u32 counts.
pub(crate) const SHAPE_HEADER_BYTES: usize = POSE_BYTES + 2 * 8 + 1 + 3 * 4 + 1 + 2 * 4;
/// Full encoding: one vertex (3 × f32), one triangle (3 × u32).
pub(crate) const VERTEX_BYTES: usize = 12;
pub(crate) const TRIANGLE_BYTES: usize = 12;
/// Compact encoding: the box (2 × 3 × f32) and one quantised vertex (3 × u16).
pub(crate) const BOX_BYTES: usize = 2 * 3 * 4;
pub(crate) const COMPACT_VERTEX_BYTES: usize = 3 * 2;
/// The most vertices a compact shape may have and still write its indices as u16.
pub(crate) const MAX_NARROW_INDEX_VERTICES: usize = 1 << 16;
/// A Subscribe payload without its ids: encoding, flags, rate, kinds, id count.
pub(crate) const SUBSCRIBE_FIXED_BYTES: usize = 1 + 1 + 4 + 1 + 4;
/// Bytes of one subscribed object id.
pub(crate) const ID_BYTES: usize = 8;
/// A Session payload before its options: the two clocks.
pub(crate) const SESSION_CLOCK_BYTES: usize = 2 * 8;
/// A Stats payload without its stages: 19 × u64, the u32 window, 2 × f32, the u32 stage count.
pub(crate) const STATS_HEADER_BYTES: usize = 19 * 8 + 4 + 2 * 4 + 4;
/// Bytes of one stage besides its name: u16 name length, 2 × f32 latencies.
pub(crate) const STAGE_FIXED_BYTES: usize = 2 + 2 * 4;
/// A Body payload before its solid's geometry: id and version, the solid byte, the margin,
/// volume, centre of mass and six inertia entries, the primitive, the encoding byte and the
/// two u32 counts.
pub(crate) const BODY_HEADER_BYTES: usize =
    2 * 8 + 1 + 4 + 4 + 3 * 4 + 6 * 4 + PRIMITIVE_BYTES + 1 + 2 * 4;
/// A Body's primitive: the kind byte, three sizes, the rotation, the centre, the residual.
pub(crate) const PRIMITIVE_BYTES: usize = 1 + 3 * 4 + 4 * 4 + 3 * 4 + 4;
/// A hull before its vertices: the u8 vertex count and the u16 triangle count.
pub(crate) const HULL_HEADER_BYTES: usize = 1 + 2;
/// One hull triangle: three u8 indices.
pub(crate) const HULL_TRIANGLE_BYTES: usize = 3;

/// The bits a Shape's `flags` may have.
pub(crate) const SHAPE_FLAGS: u8 = SHAPE_CLOSED | SHAPE_SUPPORT | SHAPE_NEW_FRAME;
/// Subscribe's `flags`: bit 0 `resend`, bit 1 `extrapolate`.
pub(crate) const SUBSCRIBE_RESEND: u8 = 1;
pub(crate) const SUBSCRIBE_EXTRAPOLATE: u8 = 2;
/// The bits a Subscribe's `kinds` may have.
pub(crate) const KIND_BITS: u8 = Kinds::ALL.0;

/// How far a rotation's norm may be from 1 and still count as a unit quaternion.
pub(crate) const MAX_QUATERNION_NORM_ERROR: f32 = 1e-3;

// ---- checks, shared with the decoder ------------------------------------------------------------

/// Residuals, rates and latencies are finite and not negative.
pub(crate) fn check_number(field: &'static str, value: f32) -> Result<(), WireError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(WireError::InvalidNumber { field, value })
    }
}

/// Every component of a pose, velocity or box is finite.
pub(crate) fn check_finite(
    message: &'static str,
    field: &'static str,
    values: &[f32],
) -> Result<(), WireError> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(&value) => Err(WireError::NonFinite {
            message,
            field,
            value,
        }),
        None => Ok(()),
    }
}

/// A pose is finite, its rotation a unit quaternion, and it was not last seen before its time.
pub(crate) fn check_pose(pose: &Pose, message: &'static str) -> Result<(), WireError> {
    check_finite(message, "rotation", &pose.rotation.to_array())?;
    check_finite(message, "translation", &pose.translation.to_array())?;
    check_finite(message, "linear_velocity", &pose.linear_velocity.to_array())?;
    check_finite(
        message,
        "angular_velocity",
        &pose.angular_velocity.to_array(),
    )?;
    let norm = pose.rotation.length();
    if (norm - 1.0).abs() > MAX_QUATERNION_NORM_ERROR {
        return Err(WireError::NotUnitQuaternion {
            object_id: pose.object_id,
            norm,
        });
    }
    if pose.last_seen_ns < pose.pose_time_ns {
        return Err(WireError::TimesOutOfOrder {
            object_id: pose.object_id,
            pose_time_ns: pose.pose_time_ns,
            last_seen_ns: pose.last_seen_ns,
        });
    }
    Ok(())
}

/// Only the bits in `defined` may be set.
pub(crate) fn check_flags(
    message: &'static str,
    field: &'static str,
    value: u8,
    defined: u8,
) -> Result<(), WireError> {
    if value & !defined == 0 {
        Ok(())
    } else {
        Err(WireError::InvalidFlags {
            message,
            field,
            value,
            defined,
        })
    }
}

/// Objects or supports or both (bodies optional), and no bit beyond the three defined.
pub(crate) fn check_kinds(message: &'static str, bits: u8) -> Result<Kinds, WireError> {
    check_flags(message, "kinds", bits, KIND_BITS)?;
    Kinds::from_bits(bits).ok_or(WireError::NoKinds { message })
}

/// A Subscribe's (or a Session's options') rate and id count. `count` is u64 so that the
/// decoder can check a count read from the wire before it sizes anything by it.
pub(crate) fn check_id_count(message: &'static str, count: u64) -> Result<(), WireError> {
    if count <= MAX_SUBSCRIBE_IDS as u64 {
        Ok(())
    } else {
        Err(WireError::TooManyIds {
            message,
            count,
            max: MAX_SUBSCRIBE_IDS,
        })
    }
}

/// A rate cap is 0 (none) or within [`MIN_RATE_HZ`]..=[`MAX_RATE_HZ`]: a server turns it into
/// an interval, and the interval of a tiny rate overflows every clock. The error says so.
pub fn check_rate(value: f32) -> Result<(), WireError> {
    if value == 0.0 || (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&value) {
        Ok(())
    } else {
        Err(WireError::InvalidRate { value })
    }
}

fn check_options(options: &Subscribe, message: &'static str) -> Result<(), WireError> {
    check_rate(options.max_rate_hz)?;
    check_kinds(message, options.kinds.bits())?;
    check_id_count(message, options.object_ids.len() as u64)
}

/// Every vertex coordinate is finite.
pub(crate) fn check_vertex(vertex: usize, p: Vec3) -> Result<(), WireError> {
    match p.to_array().into_iter().find(|v| !v.is_finite()) {
        Some(value) => Err(WireError::NonFiniteVertex { vertex, value }),
        None => Ok(()),
    }
}

/// Every corner of a triangle is a vertex of the mesh.
pub(crate) fn check_triangle(
    triangle: usize,
    corners: [u32; 3],
    vertex_count: usize,
) -> Result<(), WireError> {
    match corners.into_iter().find(|&i| i as usize >= vertex_count) {
        Some(index) => Err(WireError::IndexOutOfRange {
            triangle,
            index,
            vertex_count,
        }),
        None => Ok(()),
    }
}

/// A body's volume is finite and positive, a solid that is the shape itself or a primitive
/// carries no mesh, and a primitive is there exactly when the solid is one.
pub(crate) fn check_body_solid(
    object_id: u64,
    solid: BodySolid,
    volume_m3: f32,
    has_primitive: bool,
    vertex_count: usize,
    triangle_count: usize,
) -> Result<(), WireError> {
    if !(volume_m3.is_finite() && volume_m3 > 0.0) {
        return Err(WireError::BodyVolume {
            object_id,
            volume_m3,
        });
    }
    if !solid.carries_mesh() && (vertex_count > 0 || triangle_count > 0) {
        return Err(WireError::SolidMeshNotEmpty {
            object_id,
            solid: solid.as_str(),
            vertex_count,
            triangle_count,
        });
    }
    if has_primitive != (solid == BodySolid::Primitive) {
        return Err(WireError::PrimitiveMismatch {
            object_id,
            solid: solid.as_str(),
            has_primitive,
        });
    }
    Ok(())
}

/// A primitive's sizes are finite and positive (the unused ones 0), its rotation a unit
/// quaternion, its centre finite and its residual finite and not negative.
pub(crate) fn check_primitive(object_id: u64, primitive: &BodyPrimitive) -> Result<(), WireError> {
    let sizes = primitive.shape.sizes();
    let used = primitive.shape.used_sizes();
    let good_size = |(k, &size): (usize, &f32)| {
        if k < used {
            size.is_finite() && size > 0.0
        } else {
            size == 0.0
        }
    };
    if !sizes.iter().enumerate().all(good_size) {
        return Err(WireError::BadPrimitiveSize {
            object_id,
            kind: primitive.shape.name(),
            sizes,
        });
    }
    check_finite("Body", "primitive rotation", &primitive.rotation.to_array())?;
    let norm = primitive.rotation.length();
    if (norm - 1.0).abs() > MAX_QUATERNION_NORM_ERROR {
        return Err(WireError::NotUnitQuaternion { object_id, norm });
    }
    check_finite("Body", "primitive centre", &primitive.centre.to_array())?;
    check_number("primitive residual_m", primitive.residual_m)
}

/// At most [`MAX_HULLS`] hulls.
pub(crate) fn check_hull_count(object_id: u64, count: usize) -> Result<(), WireError> {
    if count <= MAX_HULLS {
        Ok(())
    } else {
        Err(WireError::TooManyHulls {
            object_id,
            count,
            max: MAX_HULLS,
        })
    }
}

/// A hull has 4 to 255 vertices and at most twice as many triangles.
pub(crate) fn check_hull_size(
    object_id: u64,
    hull: usize,
    vertex_count: usize,
    triangle_count: usize,
) -> Result<(), WireError> {
    if (MIN_HULL_VERTICES..=MAX_HULL_VERTICES).contains(&vertex_count)
        && triangle_count <= 2 * vertex_count
    {
        Ok(())
    } else {
        Err(WireError::BadHull {
            object_id,
            hull,
            vertex_count,
            triangle_count,
        })
    }
}

/// A string's byte length is within its cap.
fn check_text(
    text: &str,
    message: &'static str,
    field: &'static str,
    max: usize,
) -> Result<(), WireError> {
    if text.len() <= max {
        Ok(())
    } else {
        Err(WireError::TextTooLong {
            message,
            field,
            len: text.len(),
            max,
        })
    }
}

// ---- the compact encoding's box ------------------------------------------------------------------

const AXES: [&str; 3] = ["x", "y", "z"];

/// The quantisation steps per axis: q runs over `0..=65535`.
const STEPS: f32 = 65_535.0;

/// The box a compact shape's vertices are quantised in: the component-wise minimum and maximum
/// of the vertices, zeros for an empty shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CompactBox {
    pub min: Vec3,
    pub max: Vec3,
}

impl CompactBox {
    /// The box of `vertices`, which are finite.
    pub fn of(vertices: &[Vec3]) -> Self {
        match vertices.split_first() {
            None => CompactBox {
                min: Vec3::ZERO,
                max: Vec3::ZERO,
            },
            Some((&first, rest)) => rest.iter().fold(
                CompactBox {
                    min: first,
                    max: first,
                },
                |b, &p| CompactBox {
                    min: b.min.min(p),
                    max: b.max.max(p),
                },
            ),
        }
    }

    /// What a decoder requires of a box read from the wire: finite, and no maximum below its
    /// minimum.
    pub fn check(&self, message: &'static str) -> Result<(), WireError> {
        check_finite(message, "box_min", &self.min.to_array())?;
        check_finite(message, "box_max", &self.max.to_array())?;
        for (axis, (min, max)) in AXES
            .into_iter()
            .zip(self.min.to_array().into_iter().zip(self.max.to_array()))
        {
            if max < min {
                return Err(WireError::BadBox { axis, min, max });
            }
        }
        Ok(())
    }

    /// What the encoder requires besides: every quantised value dequantises to a finite
    /// coordinate. It fails only for vertices spanning more than an `f32` can hold (about
    /// 3.4e38 m), where the box's extent overflows.
    pub fn check_encodable(&self) -> Result<(), WireError> {
        for (axis, (min, max)) in AXES
            .into_iter()
            .zip(self.min.to_array().into_iter().zip(self.max.to_array()))
        {
            // Dequantisation is monotonic in q, so the largest q gives the largest value.
            if !(max - min).is_finite() || !dequantise(min, max, u16::MAX).is_finite() {
                return Err(WireError::CompactBoxTooLarge { axis, min, max });
            }
        }
        Ok(())
    }

    /// How far a vertex may move when quantised in this box: [`quantisation_bound_m`].
    pub fn quantisation_bound_m(&self) -> f32 {
        quantisation_bound_m(self.min, self.max)
    }

    /// The nearest step to `p` on each axis (0 where the box is flat), computed in f64 so that
    /// the rounding is the only error.
    pub fn quantise(&self, p: Vec3) -> [u16; 3] {
        let axis = |v: f32, min: f32, max: f32| {
            if max <= min {
                return 0;
            }
            let t = (f64::from(v) - f64::from(min)) / (f64::from(max) - f64::from(min));
            // In range after the clamp, so the cast is exact.
            (t * f64::from(STEPS)).round().clamp(0.0, f64::from(STEPS)) as u16
        };
        [
            axis(p.x, self.min.x, self.max.x),
            axis(p.y, self.min.y, self.max.y),
            axis(p.z, self.min.z, self.max.z),
        ]
    }

    /// The vertex a decoder reads for `q`.
    pub fn dequantise(&self, q: [u16; 3]) -> Vec3 {
        Vec3::new(
            dequantise(self.min.x, self.max.x, q[0]),
            dequantise(self.min.y, self.max.y, q[1]),
            dequantise(self.min.z, self.max.z, q[2]),
        )
    }
}

/// One coordinate from its step, in f32 exactly as `docs/protocol.md` gives it, so that every
/// implementation reads the same value.
fn dequantise(min: f32, max: f32, q: u16) -> f32 {
    min + f32::from(q) * ((max - min) / STEPS)
}

/// Bytes of one compact triangle index: u16 while every index fits in one.
pub(crate) fn compact_index_bytes(vertex_count: usize) -> usize {
    if vertex_count <= MAX_NARROW_INDEX_VERTICES {
        2
    } else {
        4
    }
}

// ---- sizes ---------------------------------------------------------------------------------------

/// The payload size in bytes, computed without writing, in u64 so that no input overflows it.
fn payload_len(message: &Message) -> u64 {
    let text = |s: &str| 2 + s.len() as u64;
    let options =
        |o: &Subscribe| SUBSCRIBE_FIXED_BYTES as u64 + o.object_ids.len() as u64 * ID_BYTES as u64;
    match message {
        Message::Hello { server, .. } => 2 + text(server),
        Message::Session(session) => SESSION_CLOCK_BYTES as u64 + options(&session.options),
        Message::Shape(shape) => shape_payload_len(shape),
        Message::Pose(_) => POSE_BYTES as u64,
        Message::Body(body) => body_payload_len(body),
        Message::Remove { .. } => 8,
        Message::SnapshotDone | Message::SubscribeV1 => 0,
        Message::Stats(stats) => {
            STATS_HEADER_BYTES as u64
                + stats
                    .stage_latencies
                    .iter()
                    .map(|s| STAGE_FIXED_BYTES as u64 + s.stage.len() as u64)
                    .sum::<u64>()
        }
        Message::Goodbye { reason } => text(reason),
        Message::Subscribe(subscribe) => options(subscribe),
    }
}

fn shape_payload_len(shape: &Shape) -> u64 {
    SHAPE_HEADER_BYTES as u64 + geometry_len(&shape.mesh, shape.encoding)
}

/// Bytes of a mesh's vertices and triangles in `encoding` (the box included when compact).
fn geometry_len(mesh: &TriMesh, encoding: Encoding) -> u64 {
    let v = mesh.vertices.len() as u64;
    let t = mesh.triangles.len() as u64;
    match encoding {
        Encoding::Full => v * VERTEX_BYTES as u64 + t * TRIANGLE_BYTES as u64,
        Encoding::Compact => {
            let index_bytes = compact_index_bytes(mesh.vertices.len()) as u64;
            BOX_BYTES as u64 + v * COMPACT_VERTEX_BYTES as u64 + t * 3 * index_bytes
        }
    }
}

fn body_payload_len(body: &Body) -> u64 {
    let hulls: u64 = body
        .hulls
        .iter()
        .map(|h| {
            (HULL_HEADER_BYTES
                + h.vertices.len() * VERTEX_BYTES
                + h.triangles.len() * HULL_TRIANGLE_BYTES) as u64
        })
        .sum();
    BODY_HEADER_BYTES as u64 + geometry_len(&body.mesh, body.encoding) + 1 + hulls
}

// ---- payload writers -----------------------------------------------------------------------------

/// Checks the whole message, then writes its payload; nothing is written when a check fails.
fn write_payload(message: &Message, out: &mut Vec<u8>) -> Result<(), WireError> {
    match message {
        Message::Hello {
            protocol_version,
            server,
        } => {
            check_text(server, "Hello", "server", MAX_NAME_BYTES)?;
            out.extend_from_slice(&protocol_version.to_le_bytes());
            write_text(out, server);
        }
        Message::Session(session) => write_session(session, out)?,
        Message::Shape(shape) => write_shape(shape, out)?,
        Message::Pose(pose) => {
            check_pose(pose, "Pose")?;
            write_pose(pose, out);
        }
        Message::Body(body) => write_body(body, out)?,
        Message::Remove { object_id } => out.extend_from_slice(&object_id.to_le_bytes()),
        Message::SnapshotDone | Message::SubscribeV1 => {}
        Message::Stats(stats) => write_stats(stats, out)?,
        Message::Goodbye { reason } => {
            check_text(reason, "Goodbye", "reason", MAX_REASON_BYTES)?;
            write_text(out, reason);
        }
        Message::Subscribe(subscribe) => {
            check_options(subscribe, "Subscribe")?;
            write_options(subscribe, out);
        }
    }
    Ok(())
}

fn write_session(session: &Session, out: &mut Vec<u8>) -> Result<(), WireError> {
    check_options(&session.options, "Session")?;
    out.extend_from_slice(&session.monotonic_ns.to_le_bytes());
    out.extend_from_slice(&session.realtime_ns.to_le_bytes());
    write_options(&session.options, out);
    Ok(())
}

/// A Subscribe payload, also the tail of a Session's; already checked.
fn write_options(options: &Subscribe, out: &mut Vec<u8>) {
    out.push(options.encoding.byte());
    let resend = if options.resend { SUBSCRIBE_RESEND } else { 0 };
    let extrapolate = if options.extrapolate {
        SUBSCRIBE_EXTRAPOLATE
    } else {
        0
    };
    out.push(resend | extrapolate);
    out.extend_from_slice(&options.max_rate_hz.to_le_bytes());
    out.push(options.kinds.bits());
    // At most MAX_SUBSCRIBE_IDS, checked.
    out.extend_from_slice(&(options.object_ids.len() as u32).to_le_bytes());
    for id in &options.object_ids {
        out.extend_from_slice(&id.to_le_bytes());
    }
}

/// A Pose payload, also the head of a Shape's; already checked.
fn write_pose(pose: &Pose, out: &mut Vec<u8>) {
    for field in [
        pose.object_id,
        pose.shape_version,
        pose.pose_time_ns,
        pose.pose_time_realtime_ns,
        pose.last_seen_ns,
    ] {
        out.extend_from_slice(&field.to_le_bytes());
    }
    write_f32s(out, &pose.rotation.to_array());
    write_f32s(out, &pose.translation.to_array());
    write_f32s(out, &pose.linear_velocity.to_array());
    write_f32s(out, &pose.angular_velocity.to_array());
}

/// Checks a mesh for the wire: finite vertices, indices below the vertex count, and a box the
/// compact encoding can hold. Returns that box when `encoding` is compact.
fn check_geometry(mesh: &TriMesh, encoding: Encoding) -> Result<Option<CompactBox>, WireError> {
    for (vertex, &p) in mesh.vertices.iter().enumerate() {
        check_vertex(vertex, p)?;
    }
    for (triangle, &corners) in mesh.triangles.iter().enumerate() {
        check_triangle(triangle, corners, mesh.vertices.len())?;
    }
    match encoding {
        Encoding::Full => Ok(None),
        Encoding::Compact => {
            let compact_box = CompactBox::of(&mesh.vertices);
            compact_box.check_encodable()?;
            Ok(Some(compact_box))
        }
    }
}

fn write_shape(shape: &Shape, out: &mut Vec<u8>) -> Result<(), WireError> {
    // Every check first, so that the writing below cannot fail halfway.
    check_pose(&shape.pose, "Shape")?;
    check_flags("Shape", "flags", shape.flags, SHAPE_FLAGS)?;
    check_number("max_residual_m", shape.report.max_residual_m)?;
    let compact_box = check_geometry(&shape.mesh, shape.encoding)?;
    let max_residual_m = match &compact_box {
        None => shape.report.max_residual_m,
        Some(compact_box) => {
            let residual = shape.report.max_residual_m + compact_box.quantisation_bound_m();
            check_number("max_residual_m", residual)?;
            residual
        }
    };

    write_pose(&shape.pose, out);
    out.extend_from_slice(&shape.shape_time_ns.to_le_bytes());
    out.extend_from_slice(&shape.shape_time_realtime_ns.to_le_bytes());
    out.push(shape.flags);
    out.extend_from_slice(&shape.report.faces_in.to_le_bytes());
    out.extend_from_slice(&shape.report.faces_out.to_le_bytes());
    out.extend_from_slice(&max_residual_m.to_le_bytes());
    write_geometry(&shape.mesh, shape.encoding, compact_box, out);
    Ok(())
}

/// The encoding byte, the two counts and the geometry of a checked mesh (Shape's layout, also
/// a Body's proxy's).
fn write_geometry(
    mesh: &TriMesh,
    encoding: Encoding,
    compact_box: Option<CompactBox>,
    out: &mut Vec<u8>,
) {
    let TriMesh {
        vertices,
        triangles,
    } = mesh;
    out.push(encoding.byte());
    // The frame cap, checked before writing, keeps both counts below 2^32.
    out.extend_from_slice(&(vertices.len() as u32).to_le_bytes());
    out.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
    match compact_box {
        None => {
            for p in vertices {
                write_f32s(out, &p.to_array());
            }
            for corners in triangles {
                for index in corners {
                    out.extend_from_slice(&index.to_le_bytes());
                }
            }
        }
        Some(compact_box) => {
            write_f32s(out, &compact_box.min.to_array());
            write_f32s(out, &compact_box.max.to_array());
            for &p in vertices {
                for q in compact_box.quantise(p) {
                    out.extend_from_slice(&q.to_le_bytes());
                }
            }
            let narrow = compact_index_bytes(vertices.len()) == 2;
            for corners in triangles {
                for &index in corners {
                    if narrow {
                        // Below the vertex count, checked, which is at most 2^16 here.
                        out.extend_from_slice(&(index as u16).to_le_bytes());
                    } else {
                        out.extend_from_slice(&index.to_le_bytes());
                    }
                }
            }
        }
    }
}

/// The inertia entries in wire order: `ixx, iyy, izz, ixy, ixz, iyz`.
pub(crate) fn inertia_entries(inertia: &[[f32; 3]; 3]) -> [f32; 6] {
    [
        inertia[0][0],
        inertia[1][1],
        inertia[2][2],
        inertia[0][1],
        inertia[0][2],
        inertia[1][2],
    ]
}

/// Checks a hull's size, vertices and indices.
pub(crate) fn check_hull(object_id: u64, index: usize, hull: &Hull) -> Result<(), WireError> {
    check_hull_size(object_id, index, hull.vertices.len(), hull.triangles.len())?;
    for (vertex, &p) in hull.vertices.iter().enumerate() {
        check_vertex(vertex, p)?;
    }
    for (triangle, corners) in hull.triangles.iter().enumerate() {
        check_triangle(triangle, corners.map(u32::from), hull.vertices.len())?;
    }
    Ok(())
}

fn write_body(body: &Body, out: &mut Vec<u8>) -> Result<(), WireError> {
    // Every check first, so that the writing below cannot fail halfway.
    let inertia = inertia_entries(&body.inertia);
    check_number("margin_m", body.margin_m)?;
    check_finite("Body", "centre_of_mass", &body.centre_of_mass.to_array())?;
    check_finite("Body", "inertia", &inertia)?;
    check_body_solid(
        body.object_id,
        body.solid,
        body.volume_m3,
        body.primitive.is_some(),
        body.mesh.vertices.len(),
        body.mesh.triangles.len(),
    )?;
    if let Some(primitive) = &body.primitive {
        check_primitive(body.object_id, primitive)?;
    }
    let compact_box = check_geometry(&body.mesh, body.encoding)?;
    check_hull_count(body.object_id, body.hulls.len())?;
    for (index, hull) in body.hulls.iter().enumerate() {
        check_hull(body.object_id, index, hull)?;
    }

    out.extend_from_slice(&body.object_id.to_le_bytes());
    out.extend_from_slice(&body.shape_version.to_le_bytes());
    out.push(body.solid.byte());
    out.extend_from_slice(&body.margin_m.to_le_bytes());
    out.extend_from_slice(&body.volume_m3.to_le_bytes());
    write_f32s(out, &body.centre_of_mass.to_array());
    write_f32s(out, &inertia);
    match &body.primitive {
        Some(primitive) => {
            out.push(primitive.shape.byte());
            write_f32s(out, &primitive.shape.sizes());
            write_f32s(out, &primitive.rotation.to_array());
            write_f32s(out, &primitive.centre.to_array());
            write_f32s(out, &[primitive.residual_m]);
        }
        None => out.extend_from_slice(&[0; PRIMITIVE_BYTES]),
    }
    write_geometry(&body.mesh, body.encoding, compact_box, out);
    // At most MAX_HULLS, checked; each hull's counts fit their fields, checked.
    out.push(body.hulls.len() as u8);
    for hull in &body.hulls {
        out.push(hull.vertices.len() as u8);
        out.extend_from_slice(&(hull.triangles.len() as u16).to_le_bytes());
        for p in &hull.vertices {
            write_f32s(out, &p.to_array());
        }
        for corners in &hull.triangles {
            out.extend_from_slice(corners);
        }
    }
    Ok(())
}

fn write_stats(stats: &Stats, out: &mut Vec<u8>) -> Result<(), WireError> {
    check_number("frame_to_publish_p50_ms", stats.frame_to_publish_p50_ms)?;
    check_number("frame_to_publish_p99_ms", stats.frame_to_publish_p99_ms)?;
    for stage in &stats.stage_latencies {
        check_text(&stage.stage, "Stats", "stage", MAX_NAME_BYTES)?;
        check_number("p50_ms", stage.p50_ms)?;
        check_number("p99_ms", stage.p99_ms)?;
    }
    for counter in [
        stats.monotonic_ns,
        stats.realtime_ns,
        stats.frames_in,
        stats.frames_dropped,
        stats.invalid_pixels,
        stats.malformed_frames,
        stats.source_errors,
        stats.source_restarts,
        stats.objects_tracked,
        stats.objects_born,
        stats.objects_removed,
        stats.meshing_runs,
        stats.meshing_failures,
        stats.shapes_published,
        stats.poses_published,
        stats.bytes_sent,
        stats.clients_connected,
        stats.clients_dropped,
        stats.clients_refused,
    ] {
        out.extend_from_slice(&counter.to_le_bytes());
    }
    out.extend_from_slice(&stats.latency_window.to_le_bytes());
    out.extend_from_slice(&stats.frame_to_publish_p50_ms.to_le_bytes());
    out.extend_from_slice(&stats.frame_to_publish_p99_ms.to_le_bytes());
    // The frame cap, checked before writing, keeps the count below 2^32.
    out.extend_from_slice(&(stats.stage_latencies.len() as u32).to_le_bytes());
    for stage in &stats.stage_latencies {
        write_text(out, &stage.stage);
        out.extend_from_slice(&stage.p50_ms.to_le_bytes());
        out.extend_from_slice(&stage.p99_ms.to_le_bytes());
    }
    Ok(())
}

fn write_f32s(out: &mut Vec<u8>, values: &[f32]) {
    for value in values {
        out.extend_from_slice(&value.to_le_bytes());
    }
}

/// A string as a u16 byte length and its UTF-8 bytes; its length is already checked against a
/// cap below `u16::MAX`.
fn write_text(out: &mut Vec<u8>, text: &str) {
    out.extend_from_slice(&(text.len() as u16).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
}

// ---- the entry point -----------------------------------------------------------------------------

/// Appends `message` to `out` as one frame. On error `out` is left as it was.
///
/// A [`Shape`] is laid out in its `encoding`. In [`Encoding::Compact`] the box is the
/// component-wise minimum and maximum of the vertices (zeros for an empty mesh), each coordinate
/// is rounded to the nearest of 65,536 steps across it (step 0 on an axis where the box is
/// flat), indices are u16 when there are at most 65,536 vertices, and the `max_residual_m`
/// written is the shape's plus [`quantisation_bound_m`] of the box, since the vertices a
/// receiver reads have moved by up to that. So a compact round trip is not exact: it gives back
/// the dequantised vertices and the larger residual (and another compact round trip would add
/// the bound again). [`Encoding::Full`] round-trips exactly.
///
/// Errors, all checked before anything is written:
/// - [`WireError::FrameTooLarge`] when the frame would exceed [`MAX_FRAME_BYTES`];
/// - what a decoder would refuse: [`WireError::TextTooLong`], [`WireError::NonFiniteVertex`],
///   [`WireError::NonFinite`] (a pose or velocity), [`WireError::NotUnitQuaternion`],
///   [`WireError::TimesOutOfOrder`], [`WireError::IndexOutOfRange`],
///   [`WireError::InvalidFlags`] (shape flags other than closed and support),
///   [`WireError::NoKinds`], [`WireError::TooManyIds`] (over
///   [`crate::MAX_SUBSCRIBE_IDS`]) and [`WireError::InvalidNumber`] (a residual, rate or
///   latency that is negative or not finite, the compact residual included);
/// - [`WireError::CompactBoxTooLarge`] for a compact shape whose vertices span more than an
///   `f32` can hold.
pub fn encode(message: &Message, out: &mut Vec<u8>) -> Result<(), WireError> {
    let length = 1 + payload_len(message);
    if length > MAX_FRAME_BYTES as u64 {
        return Err(WireError::FrameTooLarge { length });
    }
    let start = out.len();
    out.reserve(PREFIX_BYTES + length as usize);
    // The cap check above guarantees the length fits in a u32.
    out.extend_from_slice(&(length as u32).to_le_bytes());
    out.push(message.kind());
    let written = write_payload(message, out);
    if written.is_err() {
        out.truncate(start);
    }
    debug_assert!(written.is_err() || out.len() - start == PREFIX_BYTES + length as usize);
    written
}

#[cfg(test)]
mod compact_tests {
    use super::*;

    #[test]
    fn layout_sizes_match_the_document() {
        assert_eq!(POSE_BYTES, 92);
        assert_eq!(SHAPE_HEADER_BYTES, 130);
        assert_eq!(SHAPE_HEADER_BYTES + BOX_BYTES, 154);
        assert_eq!(SUBSCRIBE_FIXED_BYTES, 11);
        assert_eq!(STATS_HEADER_BYTES, 168);
        assert_eq!(BODY_HEADER_BYTES, 115);
    }

    #[test]
    fn flat_axis_quantises_to_zero_and_reads_back_exactly() {
        let b = CompactBox::of(&[Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 5.0, 3.0)]);
        assert_eq!(b.quantise(Vec3::new(1.0, 5.0, 3.0)), [0, 65_535, 0]);
        assert_eq!(b.dequantise([0, 0, 0]), Vec3::new(1.0, 2.0, 3.0));
    }

    #[test]
    fn box_spanning_more_than_f32_is_not_encodable() {
        let b = CompactBox::of(&[Vec3::splat(-3e38), Vec3::splat(3e38)]);
        assert!(matches!(
            b.check_encodable(),
            Err(WireError::CompactBoxTooLarge { axis: "x", .. })
        ));
        assert_eq!(CompactBox::of(&[]).check_encodable(), Ok(()));
    }
}
