//! Helpers shared by the integration tests.

use std::path::PathBuf;

use tacmesh_rosbag::{Bag, BagError, Image, Message};

/// The real RealSense D435 recording (SOURCES.md, `recordings/`).
pub fn d435_bag() -> PathBuf {
    tacmesh_testdata::path("recordings/realsense_d435_single_depth_color_640x480.bag")
}

/// The first depth frame of that bag as raw little-endian Z16 (SOURCES.md, `depth/realsense_d435/`).
pub fn d435_frame0_z16() -> Vec<u8> {
    tacmesh_testdata::bytes("depth/realsense_d435/frame0_640x480.z16")
}

pub const DEPTH_TOPIC: &str = "/device_0/sensor_0/Depth_0/image/data";

/// Every message of the bag at `path`, or the first error (from opening or iterating).
pub fn read_all(path: &std::path::Path) -> Result<Vec<Message>, BagError> {
    Bag::open(path)?.messages()?.collect()
}

/// Reads a bag and decodes every depth image in it; any failure as a string.
pub fn read_and_decode(path: &std::path::Path) -> Result<usize, String> {
    let msgs = read_all(path).map_err(|e| e.to_string())?;
    let mut frames = 0;
    for m in msgs.iter().filter(|m| m.connection.topic == DEPTH_TOPIC) {
        let img = Image::decode(&m.data).map_err(|e| e.to_string())?;
        img.depth_u16().map_err(|e| e.to_string())?;
        frames += 1;
    }
    Ok(frames)
}

/// A small deterministic generator (xorshift64*), so corruption tests are reproducible.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Builds small synthetic bags record by record (uncompressed or LZ4 chunks).
pub mod build {
    pub fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut f = ((name.len() + 1 + value.len()) as u32)
            .to_le_bytes()
            .to_vec();
        f.extend_from_slice(name.as_bytes());
        f.push(b'=');
        f.extend_from_slice(value);
        f
    }

    pub fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
        let header: Vec<u8> = fields.iter().flat_map(|(n, v)| field(n, v)).collect();
        let mut out = (header.len() as u32).to_le_bytes().to_vec();
        out.extend(header);
        out.extend((data.len() as u32).to_le_bytes());
        out.extend(data);
        out
    }

    pub fn connection(id: u32, topic: &str, msg_type: &str) -> Vec<u8> {
        let data: Vec<u8> = [
            field("topic", topic.as_bytes()),
            field("type", msg_type.as_bytes()),
            field("md5sum", &[b'0'; 32]),
            field("message_definition", b"float32 data\n"),
        ]
        .concat();
        record(
            &[
                ("op", &[7]),
                ("conn", &id.to_le_bytes()),
                ("topic", topic.as_bytes()),
            ],
            &data,
        )
    }

    pub fn message(conn: u32, sec: u32, data: &[u8]) -> Vec<u8> {
        let mut time = sec.to_le_bytes().to_vec();
        time.extend(0u32.to_le_bytes());
        record(
            &[("op", &[2]), ("conn", &conn.to_le_bytes()), ("time", &time)],
            data,
        )
    }

    pub fn chunk(compression: &str, inner: &[u8]) -> Vec<u8> {
        let data = match compression {
            "lz4" => {
                use std::io::Write;
                let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
                enc.write_all(inner).unwrap();
                enc.finish().unwrap()
            }
            _ => inner.to_vec(),
        };
        record(
            &[
                ("op", &[5]),
                ("compression", compression.as_bytes()),
                ("size", &(inner.len() as u32).to_le_bytes()),
            ],
            &data,
        )
    }

    /// A bag without an index section (`index_pos` 0): magic, bag header, then `chunks`.
    pub fn unindexed_bag(chunks: &[Vec<u8>]) -> Vec<u8> {
        let mut out = b"#ROSBAG V2.0\n".to_vec();
        out.extend(record(
            &[
                ("op", &[3]),
                ("index_pos", &0u64.to_le_bytes()),
                ("conn_count", &0u32.to_le_bytes()),
                ("chunk_count", &(chunks.len() as u32).to_le_bytes()),
            ],
            &[b' '; 64],
        ));
        for c in chunks {
            out.extend(c);
        }
        out
    }
}
