//! The Body message (`0x0C`): the document's example byte by byte, round trips in both
//! encodings, the refusals that are the Body's own, and what a Scene keeps of bodies.

use glam::Vec3;
use tacmesh_source::TriMesh;

use super::{decode_err, decode_one, encoded, example_shape, frame};
use crate::*;

/// The tetrahedron of the document's example, wound counter-clockwise seen from outside.
fn tetrahedron() -> TriMesh {
    TriMesh::new(
        vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    )
}

/// The Body example of `docs/protocol.md`.
pub(super) fn example_body(encoding: Encoding) -> Body {
    let (diagonal, off) = (1.0 / 80.0, 1.0 / 480.0);
    Body {
        object_id: 7,
        shape_version: 2,
        solid: BodySolid::ShadowVolume,
        margin_m: 0.25,
        volume_m3: 1.0 / 6.0,
        centre_of_mass: Vec3::splat(0.25),
        inertia: [
            [diagonal, off, off],
            [off, diagonal, off],
            [off, off, diagonal],
        ],
        primitive: None,
        mesh: tetrahedron(),
        encoding,
        hulls: vec![Hull {
            vertices: tetrahedron().vertices,
            triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        }],
    }
}

/// A closed shape's body: the shape is the solid, no mesh is repeated.
pub(super) fn shape_body() -> Body {
    Body {
        solid: BodySolid::Shape,
        margin_m: 0.0,
        mesh: TriMesh::default(),
        shape_version: u64::MAX,
        ..example_body(Encoding::Full)
    }
}

/// The example's payload, field by field from the document's table (not from the encoder).
fn example_payload() -> Vec<u8> {
    let mut p = Vec::new();
    let f32s = |p: &mut Vec<u8>, values: &[f32]| {
        for v in values {
            p.extend_from_slice(&v.to_le_bytes());
        }
    };
    p.extend_from_slice(&7u64.to_le_bytes()); // object_id
    p.extend_from_slice(&2u64.to_le_bytes()); // shape_version
    p.push(3); // solid: shadow volume
    f32s(&mut p, &[0.25]); // margin_m
    f32s(&mut p, &[1.0 / 6.0]); // volume_m3
    f32s(&mut p, &[0.25, 0.25, 0.25]); // centre_of_mass
    let (d, o) = (1.0 / 80.0, 1.0 / 480.0);
    f32s(&mut p, &[d, d, d, o, o, o]); // ixx iyy izz ixy ixz iyz
    p.extend_from_slice(&[0; 45]); // no primitive: kind 0 and 44 zero bytes
    p.push(0); // encoding full
    p.extend_from_slice(&4u32.to_le_bytes()); // vertex_count
    p.extend_from_slice(&4u32.to_le_bytes()); // triangle_count
    let corners = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    for c in corners {
        f32s(&mut p, &c);
    }
    for t in [[0u32, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]] {
        for i in t {
            p.extend_from_slice(&i.to_le_bytes());
        }
    }
    p.push(1); // hull_count
    p.push(4); // the hull's vertex_count
    p.extend_from_slice(&4u16.to_le_bytes()); // its triangle_count
    for c in corners {
        f32s(&mut p, &c);
    }
    for t in [[0u8, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]] {
        p.extend_from_slice(&t);
    }
    p
}

/// The bytes of the document's Body example: the hex pairs that start each line of the code
/// block after its caption (the annotations after them are skipped).
fn document_example(caption: &str) -> Vec<u8> {
    let document = include_str!("../../../docs/protocol.md");
    let caption = document
        .find(caption)
        .expect("docs/protocol.md has the Body example");
    let block = document[caption..]
        .split("```")
        .nth(1)
        .expect("the example's code block");
    block
        .lines()
        .flat_map(|line| {
            line.split_whitespace()
                .map_while(|token| {
                    (token.len() == 2 && token.chars().all(|c| c.is_ascii_hexdigit()))
                        .then(|| u8::from_str_radix(token, 16).ok())
                        .flatten()
                })
                .collect::<Vec<u8>>()
        })
        .collect()
}

#[test]
fn body_golden_bytes() {
    let expected = frame(0x0c, &example_payload());
    assert_eq!(expected.len(), 280, "the document's frame size");
    let message = Message::Body(example_body(Encoding::Full));
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
    assert_eq!(
        document_example("Example, the body of object 7"),
        expected,
        "docs/protocol.md's Body example"
    );
}

/// The document's second example: a box of 0.2 × 0.1 × 0.3 m standing on the object frame's
/// origin, turned a quarter about z.
pub(super) fn box_body() -> Body {
    let half = Vec3::new(0.1, 0.05, 0.15);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let centre = Vec3::new(0.0, 0.0, 0.15);
    // Corner k of the box's own frame has bit 0 for x, bit 1 for y, bit 2 for z; the quarter
    // turn takes its (x, y) to (−y, x).
    let corners: Vec<Vec3> = (0..8)
        .map(|k| {
            let sign = |bit: u32| if k & (1 << bit) == 0 { -1.0 } else { 1.0 };
            Vec3::new(
                -sign(1) * half.y,
                sign(0) * half.x,
                centre.z + sign(2) * half.z,
            )
        })
        .collect();
    // The box's principal moments, V (b² + c²) / 12 and so on, about its own x, y, z; the
    // quarter turn swaps x and y in the object's frame.
    let (ix, iy, iz) = (5e-5, 6.5e-5, 2.5e-5);
    Body {
        object_id: 9,
        shape_version: 4,
        solid: BodySolid::Primitive,
        margin_m: 0.0,
        volume_m3: 0.006,
        centre_of_mass: centre,
        inertia: [[iy, 0.0, 0.0], [0.0, ix, 0.0], [0.0, 0.0, iz]],
        primitive: Some(BodyPrimitive {
            shape: PrimitiveShape::Box { half_m: half },
            rotation: glam::Quat::from_xyzw(0.0, 0.0, h, h),
            centre,
            residual_m: 0.002,
        }),
        mesh: TriMesh::default(),
        encoding: Encoding::Full,
        hulls: vec![Hull {
            vertices: corners,
            // Counter-clockwise from outside: −x, +x, −y, +y, −z, +z (corner k has bit 0 for
            // x, 1 for y, 2 for z).
            triangles: vec![
                [0, 4, 6],
                [0, 6, 2],
                [1, 3, 7],
                [1, 7, 5],
                [0, 1, 5],
                [0, 5, 4],
                [2, 6, 7],
                [2, 7, 3],
                [0, 2, 3],
                [0, 3, 1],
                [4, 5, 7],
                [4, 7, 6],
            ],
        }],
    }
}

#[test]
fn primitive_body_golden_bytes() {
    let body = box_body();
    let hull = tacmesh_source::TriMesh::new(
        body.hulls[0].vertices.clone(),
        body.hulls[0]
            .triangles
            .iter()
            .map(|t| t.map(u32::from))
            .collect(),
    );
    assert!(hull.is_closed(), "the example's hull is closed");
    let mut p = Vec::new();
    let f32s = |p: &mut Vec<u8>, values: &[f32]| {
        for v in values {
            p.extend_from_slice(&v.to_le_bytes());
        }
    };
    p.extend_from_slice(&9u64.to_le_bytes());
    p.extend_from_slice(&4u64.to_le_bytes());
    p.push(1); // solid: primitive
    f32s(&mut p, &[0.0, body.volume_m3]);
    f32s(&mut p, &body.centre_of_mass.to_array());
    let i = body.inertia;
    f32s(&mut p, &[i[0][0], i[1][1], i[2][2], 0.0, 0.0, 0.0]);
    p.push(1); // primitive kind: box
    f32s(&mut p, &[0.1, 0.05, 0.15]); // half sides
    let h = std::f32::consts::FRAC_1_SQRT_2;
    f32s(&mut p, &[0.0, 0.0, h, h]); // rotation x, y, z, w
    f32s(&mut p, &[0.0, 0.0, 0.15, 0.002]); // centre, residual_m
    p.push(0); // encoding full
    p.extend_from_slice(&[0; 8]); // no mesh
    p.push(1); // one hull
    p.push(8);
    p.extend_from_slice(&12u16.to_le_bytes());
    for v in &body.hulls[0].vertices {
        f32s(&mut p, &v.to_array());
    }
    for t in &body.hulls[0].triangles {
        p.extend_from_slice(t);
    }
    let expected = frame(0x0c, &p);
    assert_eq!(expected.len(), 256, "the document's frame size");
    let message = Message::Body(body);
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
    assert_eq!(
        document_example("Example, the body of object 9"),
        expected,
        "docs/protocol.md's primitive Body example"
    );
}

#[test]
fn bodies_round_trip_in_both_encodings() {
    let full = example_body(Encoding::Full);
    assert_eq!(
        decode_one(&encoded(&Message::Body(full.clone())), Sender::Server),
        Ok(Message::Body(full.clone()))
    );
    // Compact: the proxy's vertices move by at most the box's quantisation bound; the hulls are
    // always full precision.
    let compact = Body {
        mesh: TriMesh::new(
            vec![
                Vec3::new(0.013, -0.2, 0.5),
                Vec3::new(0.31, 0.0, 0.45),
                Vec3::new(0.0, 0.21, 0.7),
                Vec3::new(0.1, 0.1, 0.9),
            ],
            tetrahedron().triangles,
        ),
        ..example_body(Encoding::Compact)
    };
    let bytes = encoded(&Message::Body(compact.clone()));
    assert_eq!(
        bytes.len(),
        280 - 4 * 6 - 4 * 6 + 24,
        "compact: 6 bytes a vertex and a triangle, and the box"
    );
    let Ok(Message::Body(read)) = decode_one(&bytes, Sender::Server) else {
        panic!("a compact body decodes");
    };
    let bound = quantisation_bound_m(Vec3::new(0.0, -0.2, 0.45), Vec3::new(0.31, 0.21, 0.9));
    for (a, b) in read.mesh.vertices.iter().zip(&compact.mesh.vertices) {
        assert!(a.distance(*b) <= bound, "{a} {b} {bound}");
    }
    assert_eq!(read.hulls, compact.hulls);
    assert_eq!(read.mesh.triangles, compact.mesh.triangles);
    assert_eq!(
        (read.volume_m3, read.inertia, read.encoding),
        (compact.volume_m3, compact.inertia, Encoding::Compact)
    );
}

/// Offsets in the example frame (payload offset + 5).
mod at {
    pub const SOLID: usize = 5 + 16;
    pub const MARGIN: usize = 5 + 17;
    pub const VOLUME: usize = 5 + 21;
    pub const CENTRE: usize = 5 + 25;
    pub const INERTIA: usize = 5 + 37;
    pub const PRIMITIVE: usize = 5 + 61;
    pub const HULL_COUNT: usize = 5 + 115 + 48 + 48;
    pub const HULL_VERTEX_COUNT: usize = HULL_COUNT + 1;
    pub const HULL_TRIANGLE_COUNT: usize = HULL_COUNT + 2;
    pub const HULL_VERTICES: usize = HULL_COUNT + 4;
    pub const HULL_TRIANGLES: usize = HULL_VERTICES + 48;
}

fn example_frame() -> Vec<u8> {
    encoded(&Message::Body(example_body(Encoding::Full)))
}

fn patched(offset: usize, value: &[u8]) -> Vec<u8> {
    super::patched(&example_frame(), offset, value)
}

#[test]
fn body_refusals() {
    assert_eq!(
        decode_err(&patched(at::SOLID, &[5]), Sender::Server),
        WireError::InvalidEnum {
            message: "Body",
            field: "solid",
            value: 5,
            defined: "0 shape, 1 primitive, 2 completed solid, 3 shadow volume, 4 extrusion",
        }
    );
    // A solid that is the shape carries no mesh.
    assert_eq!(
        decode_err(&patched(at::SOLID, &[0]), Sender::Server),
        WireError::SolidMeshNotEmpty {
            object_id: 7,
            solid: "shape",
            vertex_count: 4,
            triangle_count: 4
        }
    );
    // A primitive solid needs its primitive, and only it has one.
    let primitive = encoded(&Message::Body(box_body()));
    let primitive_patched = |offset: usize, value: &[u8]| super::patched(&primitive, offset, value);
    assert_eq!(
        decode_err(&primitive_patched(at::SOLID, &[2]), Sender::Server),
        WireError::PrimitiveMismatch {
            object_id: 9,
            solid: "completed solid",
            has_primitive: true
        }
    );
    assert!(matches!(
        decode_err(&primitive_patched(at::PRIMITIVE, &[5]), Sender::Server),
        WireError::InvalidEnum {
            field: "primitive kind",
            value: 5,
            ..
        }
    ));
    // A box's three sizes are positive; a cylinder's third is 0.
    for (kind, size, at) in [
        (1u8, 0.0f32, 1),
        (1, f32::NAN, 5),
        (1, -0.1, 9),
        (2, 0.15, 9),
    ] {
        let mut bytes = primitive_patched(at::PRIMITIVE, &[kind]);
        bytes[at::PRIMITIVE + at..at::PRIMITIVE + at + 4].copy_from_slice(&size.to_le_bytes());
        let err = decode_err(&bytes, Sender::Server);
        assert!(
            matches!(err, WireError::BadPrimitiveSize { object_id: 9, .. }),
            "kind {kind} size {size}: {err}"
        );
    }
    assert!(matches!(
        decode_err(
            &primitive_patched(at::PRIMITIVE + 13, &0.5f32.to_le_bytes()),
            Sender::Server
        ),
        WireError::NotUnitQuaternion { object_id: 9, .. }
    ));
    assert!(matches!(
        decode_err(
            &primitive_patched(at::PRIMITIVE + 41, &(-0.001f32).to_le_bytes()),
            Sender::Server
        ),
        WireError::InvalidNumber {
            field: "primitive residual_m",
            ..
        }
    ));
    // No primitive: kind 0 with any byte after it set is garbage, not ignored.
    assert!(matches!(
        decode_err(&patched(at::PRIMITIVE + 44, &[1]), Sender::Server),
        WireError::BadPrimitiveSize { object_id: 7, .. }
    ));
    assert_eq!(
        decode_err(&patched(at::PRIMITIVE, &[1]), Sender::Server),
        WireError::BadPrimitiveSize {
            object_id: 7,
            kind: "box",
            sizes: [0.0; 3]
        }
    );
    for volume in [0.0f32, -1.0, f32::NAN, f32::INFINITY] {
        let err = decode_err(&patched(at::VOLUME, &volume.to_le_bytes()), Sender::Server);
        assert!(
            matches!(err, WireError::BodyVolume { object_id: 7, .. }),
            "{err}"
        );
    }
    assert!(matches!(
        decode_err(
            &patched(at::MARGIN, &(-0.5f32).to_le_bytes()),
            Sender::Server
        ),
        WireError::InvalidNumber {
            field: "margin_m",
            ..
        }
    ));
    assert!(matches!(
        decode_err(
            &patched(at::CENTRE + 4, &f32::NAN.to_le_bytes()),
            Sender::Server
        ),
        WireError::NonFinite {
            field: "centre_of_mass",
            ..
        }
    ));
    assert!(matches!(
        decode_err(
            &patched(at::INERTIA + 20, &f32::INFINITY.to_le_bytes()),
            Sender::Server
        ),
        WireError::NonFinite {
            field: "inertia",
            ..
        }
    ));
    // Hull caps: the count, a hull's vertices (4 to 255), its triangles (at most 2·n).
    assert_eq!(
        decode_err(&patched(at::HULL_COUNT, &[17]), Sender::Server),
        WireError::TooManyHulls {
            object_id: 7,
            count: 17,
            max: MAX_HULLS
        }
    );
    assert_eq!(
        decode_err(&patched(at::HULL_VERTEX_COUNT, &[3]), Sender::Server),
        WireError::BadHull {
            object_id: 7,
            hull: 0,
            vertex_count: 3,
            triangle_count: 4
        }
    );
    assert!(matches!(
        decode_err(
            &patched(at::HULL_TRIANGLE_COUNT, &9u16.to_le_bytes()),
            Sender::Server
        ),
        WireError::BadHull {
            triangle_count: 9,
            ..
        }
    ));
    assert_eq!(
        decode_err(&patched(at::HULL_TRIANGLES + 1, &[4]), Sender::Server),
        WireError::IndexOutOfRange {
            triangle: 0,
            index: 4,
            vertex_count: 4
        }
    );
    assert!(matches!(
        decode_err(
            &patched(at::HULL_VERTICES, &f32::NAN.to_le_bytes()),
            Sender::Server
        ),
        WireError::NonFiniteVertex { vertex: 0, .. }
    ));
    // A hull count that promises more than the frame holds, and a byte too many.
    assert!(matches!(
        decode_err(&patched(at::HULL_COUNT, &[2]), Sender::Server),
        WireError::Truncated { .. }
    ));
    let mut longer = example_frame();
    longer.push(0);
    let length = (longer.len() - 4) as u32;
    longer[..4].copy_from_slice(&length.to_le_bytes());
    assert!(matches!(
        decode_err(&longer, Sender::Server),
        WireError::TrailingBytes {
            message: "Body",
            ..
        }
    ));
}

#[test]
fn encode_refuses_the_bodies_a_decoder_would_refuse() {
    let cases: Vec<(Body, WireError)> = vec![
        (
            Body {
                volume_m3: 0.0,
                ..example_body(Encoding::Full)
            },
            WireError::BodyVolume {
                object_id: 7,
                volume_m3: 0.0,
            },
        ),
        (
            Body {
                solid: BodySolid::Shape,
                ..example_body(Encoding::Full)
            },
            WireError::SolidMeshNotEmpty {
                object_id: 7,
                solid: "shape",
                vertex_count: 4,
                triangle_count: 4,
            },
        ),
        (
            Body {
                primitive: None,
                ..box_body()
            },
            WireError::PrimitiveMismatch {
                object_id: 9,
                solid: "primitive",
                has_primitive: false,
            },
        ),
        (
            Body {
                primitive: box_body().primitive.map(|p| BodyPrimitive {
                    shape: PrimitiveShape::Sphere { radius_m: -1.0 },
                    ..p
                }),
                ..box_body()
            },
            WireError::BadPrimitiveSize {
                object_id: 9,
                kind: "sphere",
                sizes: [-1.0, 0.0, 0.0],
            },
        ),
        (
            Body {
                hulls: vec![example_body(Encoding::Full).hulls[0].clone(); MAX_HULLS + 1],
                ..example_body(Encoding::Full)
            },
            WireError::TooManyHulls {
                object_id: 7,
                count: MAX_HULLS + 1,
                max: MAX_HULLS,
            },
        ),
        (
            Body {
                hulls: vec![Hull {
                    vertices: vec![Vec3::ZERO; MAX_HULL_VERTICES + 1],
                    triangles: vec![],
                }],
                ..example_body(Encoding::Full)
            },
            WireError::BadHull {
                object_id: 7,
                hull: 0,
                vertex_count: MAX_HULL_VERTICES + 1,
                triangle_count: 0,
            },
        ),
    ];
    for (body, expected) in cases {
        let mut out = vec![0xaa];
        assert_eq!(encode(&Message::Body(body), &mut out), Err(expected));
        assert_eq!(out, [0xaa], "nothing written");
    }
}

/// A Scene keeps the newest body beside the shape; a body of an object not held, or older
/// than the held one, is stale; a Shape with `new_frame` drops a body made before it.
#[test]
fn a_scene_keeps_the_newest_body_until_the_frame_changes() {
    let mut scene = Scene::new();
    let body = |version: u64| {
        Message::Body(Body {
            shape_version: version,
            ..example_body(Encoding::Full)
        })
    };
    let shape = |version: u64, flags: u8| {
        let mut shape = example_shape(Encoding::Full);
        shape.pose.shape_version = version;
        shape.flags = flags;
        Message::Shape(shape)
    };
    assert_eq!(
        scene.apply(&body(2)),
        SceneChange::Stale(7),
        "no such object"
    );
    assert_eq!(scene.apply(&shape(2, 0)), SceneChange::Added(7));
    assert_eq!(scene.apply(&body(2)), SceneChange::Bodied(7));
    // A newer shape in the same frame keeps the body; an older body is stale.
    assert_eq!(scene.apply(&shape(3, 0)), SceneChange::Reshaped(7));
    assert_eq!(
        scene
            .get(7)
            .and_then(|o| o.body.as_ref())
            .map(|b| b.shape_version),
        Some(2)
    );
    assert_eq!(scene.apply(&body(1)), SceneChange::Stale(7));
    assert_eq!(scene.apply(&body(3)), SceneChange::Bodied(7));
    // A new frame drops the body made before it, not one made from it.
    assert_eq!(
        scene.apply(&shape(5, SHAPE_NEW_FRAME)),
        SceneChange::Reshaped(7)
    );
    assert!(scene.get(7).is_some_and(|o| o.body.is_none()));
    // A body made in the frame before, arriving late, does not fit.
    assert_eq!(scene.apply(&body(4)), SceneChange::Stale(7));
    assert_eq!(scene.apply(&body(6)), SceneChange::Bodied(7));
    assert_eq!(
        scene.apply(&shape(6, SHAPE_NEW_FRAME)),
        SceneChange::Reshaped(7)
    );
    assert!(scene.get(7).is_some_and(|o| o.body.is_some()));
    // A subscription without bodies forgets them.
    scene.retain_subscribed(&Subscribe {
        kinds: Kinds::OBJECTS,
        ..Subscribe::default()
    });
    assert!(scene.get(7).is_some_and(|o| o.body.is_none()));
}

#[test]
fn hull_mesh_widens_its_indices() {
    let hull = &example_body(Encoding::Full).hulls[0];
    assert_eq!(hull.mesh(), tetrahedron());
}
