//! The Body message (`0x0B`): the document's example byte by byte, round trips in both
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
        proxy: BodyProxy::ShadowVolume,
        margin_m: 0.25,
        volume_m3: 1.0 / 6.0,
        centre_of_mass: Vec3::splat(0.25),
        inertia: [
            [diagonal, off, off],
            [off, diagonal, off],
            [off, off, diagonal],
        ],
        mesh: tetrahedron(),
        encoding,
        hulls: vec![Hull {
            vertices: tetrahedron().vertices,
            triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        }],
    }
}

/// A closed shape's body: the shape is the proxy, no mesh is repeated.
pub(super) fn shape_body() -> Body {
    Body {
        proxy: BodyProxy::Shape,
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
    p.push(1); // proxy: shadow volume
    f32s(&mut p, &[0.25]); // margin_m
    f32s(&mut p, &[1.0 / 6.0]); // volume_m3
    f32s(&mut p, &[0.25, 0.25, 0.25]); // centre_of_mass
    let (d, o) = (1.0 / 80.0, 1.0 / 480.0);
    f32s(&mut p, &[d, d, d, o, o, o]); // ixx iyy izz ixy ixz iyz
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
fn document_example() -> Vec<u8> {
    let document = include_str!("../../../docs/protocol.md");
    let caption = document
        .find("Example, the body of object 7")
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
    let expected = frame(0x0b, &example_payload());
    assert_eq!(expected.len(), 235, "the document's frame size");
    let message = Message::Body(example_body(Encoding::Full));
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
    assert_eq!(
        document_example(),
        expected,
        "docs/protocol.md's Body example"
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
        235 - 4 * 6 - 4 * 6 + 24,
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
    pub const PROXY: usize = 5 + 16;
    pub const MARGIN: usize = 5 + 17;
    pub const VOLUME: usize = 5 + 21;
    pub const CENTRE: usize = 5 + 25;
    pub const INERTIA: usize = 5 + 37;
    pub const HULL_COUNT: usize = 5 + 70 + 48 + 48;
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
        decode_err(&patched(at::PROXY, &[3]), Sender::Server),
        WireError::InvalidEnum {
            message: "Body",
            field: "proxy",
            value: 3,
            defined: "0 shape, 1 shadow volume, 2 extrusion",
        }
    );
    // A proxy that is the shape carries no mesh.
    assert_eq!(
        decode_err(&patched(at::PROXY, &[0]), Sender::Server),
        WireError::ProxyMeshNotEmpty {
            object_id: 7,
            vertex_count: 4,
            triangle_count: 4
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
                proxy: BodyProxy::Shape,
                ..example_body(Encoding::Full)
            },
            WireError::ProxyMeshNotEmpty {
                object_id: 7,
                vertex_count: 4,
                triangle_count: 4,
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
