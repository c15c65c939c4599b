//! Small hand-built bags: unindexed bags, compressions, unknown connections.

use tacmesh_rosbag::{Bag, BagError, ChunkError};

use crate::util::build::{chunk, connection, message, unindexed_bag};

fn write_temp(name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("tacmesh-rosbag-synth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn inner() -> Vec<u8> {
    [
        connection(0, "/a", "std_msgs/Float32"),
        message(0, 10, &1.5f32.to_le_bytes()),
        connection(1, "/b", "std_msgs/Float32"),
        message(1, 11, &2.5f32.to_le_bytes()),
        message(0, 12, &3.5f32.to_le_bytes()),
    ]
    .concat()
}

#[test]
fn unindexed_bag_reads_messages_in_file_order_from_both_compressions() {
    for compression in ["none", "lz4"] {
        let path = write_temp(
            &format!("{compression}.bag"),
            &unindexed_bag(&[chunk(compression, &inner())]),
        );
        let bag = Bag::open(&path).unwrap();
        assert_eq!(bag.connections().count(), 0, "no index section");
        let msgs: Vec<_> = bag.messages().unwrap().collect::<Result<_, _>>().unwrap();
        let seen: Vec<_> = msgs
            .iter()
            .map(|m| {
                (
                    m.connection.topic.as_str(),
                    m.time.sec,
                    tacmesh_rosbag::decode_float32(&m.data).unwrap(),
                )
            })
            .collect();
        assert_eq!(
            seen,
            vec![("/a", 10, 1.5), ("/b", 11, 2.5), ("/a", 12, 3.5)]
        );
    }
}

#[test]
fn bz2_chunk_is_unsupported_compression_error() {
    let path = write_temp("bz2.bag", &unindexed_bag(&[chunk("bz2", &inner())]));
    let err = Bag::open(&path)
        .unwrap()
        .messages()
        .unwrap()
        .next()
        .unwrap()
        .unwrap_err();
    match &err {
        BagError::Chunk {
            offset,
            error: ChunkError::UnsupportedCompression(c),
            ..
        } => {
            assert_eq!(c, "bz2");
            assert!(*offset > 13);
        }
        other => panic!("{other}"),
    }
    assert!(err.to_string().contains("bz2.bag"), "{err}");
}

#[test]
fn message_of_undefined_connection_is_an_error() {
    let path = write_temp(
        "orphan.bag",
        &unindexed_bag(&[chunk("none", &message(9, 1, &[0; 4]))]),
    );
    let err = Bag::open(&path)
        .unwrap()
        .messages()
        .unwrap()
        .next()
        .unwrap()
        .unwrap_err();
    assert!(
        matches!(err, BagError::UnknownConnection { conn: 9, .. }),
        "{err}"
    );
}
