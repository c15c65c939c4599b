//! Chunk records (op 0x05): a block of connection and message records, stored as-is
//! (`compression=none`) or compressed (`lz4`, `bz2`); the `size` header field is the
//! uncompressed length.
//!
//! ROS writes `lz4` chunks with `roslz4`, which produces the standard LZ4 *frame* format
//! (magic `04 22 4D 18`), so [`lz4_flex::frame::FrameDecoder`] reads them. `bz2` is not
//! supported: re-compress such bags with `rosbag compress --lz4`.
//!
//! Entry point: [`decompress`].

use std::io::Read;

/// The largest expansion LZ4 can achieve (a run encodes at most ~255 bytes per input byte);
/// a declared size beyond this is a lie and would only serve to make us allocate.
const LZ4_MAX_RATIO: u64 = 255;

/// Why a chunk's data could not be turned into records.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ChunkError {
    #[error("unsupported chunk compression `{0}` (only `none` and `lz4` are read; convert with `rosbag compress --lz4`)")]
    UnsupportedCompression(String),
    #[error("chunk declares {declared} uncompressed bytes but holds {actual}")]
    SizeMismatch { declared: u64, actual: u64 },
    #[error(
        "chunk declares {declared} uncompressed bytes, impossible from {compressed} LZ4 bytes"
    )]
    ImplausibleSize { declared: u64, compressed: u64 },
    #[error("corrupt LZ4 chunk data: {0}")]
    Lz4(String),
}

/// Decompresses one chunk's data according to its `compression` field, checking the result
/// against the declared uncompressed `size`. Never allocates more than `size` (which is itself
/// checked against the compressed length first).
pub fn decompress(compression: &str, size: u32, data: &[u8]) -> Result<Vec<u8>, ChunkError> {
    let declared = u64::from(size);
    match compression {
        "none" => {
            if declared != data.len() as u64 {
                return Err(ChunkError::SizeMismatch {
                    declared,
                    actual: data.len() as u64,
                });
            }
            Ok(data.to_vec())
        }
        "lz4" => {
            let compressed = data.len() as u64;
            if declared > compressed.saturating_mul(LZ4_MAX_RATIO) + 64 {
                return Err(ChunkError::ImplausibleSize {
                    declared,
                    compressed,
                });
            }
            let mut out = Vec::with_capacity(declared as usize);
            // One byte more than declared, to notice a chunk that holds more than it says.
            lz4_flex::frame::FrameDecoder::new(data)
                .take(declared + 1)
                .read_to_end(&mut out)
                .map_err(|e| ChunkError::Lz4(e.to_string()))?;
            if out.len() as u64 != declared {
                return Err(ChunkError::SizeMismatch {
                    declared,
                    actual: out.len() as u64,
                });
            }
            Ok(out)
        }
        other => Err(ChunkError::UnsupportedCompression(other.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    fn lz4(data: &[u8]) -> Vec<u8> {
        let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
        enc.write_all(data).unwrap();
        enc.finish().unwrap()
    }

    #[test]
    fn lz4_chunk_round_trips() {
        let data: Vec<u8> = (0..10_000u32).map(|i| (i % 251) as u8).collect();
        assert_eq!(decompress("lz4", 10_000, &lz4(&data)).unwrap(), data);
    }

    #[test]
    fn lz4_chunk_with_wrong_declared_size_is_an_error() {
        let packed = lz4(&[7u8; 100]);
        assert_eq!(
            decompress("lz4", 99, &packed),
            Err(ChunkError::SizeMismatch {
                declared: 99,
                actual: 100
            })
        );
        assert_eq!(
            decompress("lz4", 101, &packed),
            Err(ChunkError::SizeMismatch {
                declared: 101,
                actual: 100
            })
        );
    }

    #[test]
    fn lz4_chunk_declaring_gigabytes_is_refused_before_allocating() {
        let packed = lz4(&[7u8; 100]);
        assert!(matches!(
            decompress("lz4", u32::MAX, &packed),
            Err(ChunkError::ImplausibleSize { .. })
        ));
    }

    #[test]
    fn corrupt_lz4_is_an_error() {
        let mut packed = lz4(b"hello hello hello hello");
        packed[0] ^= 0xff; // break the frame magic
        assert!(matches!(
            decompress("lz4", 23, &packed),
            Err(ChunkError::Lz4(_))
        ));
    }

    #[test]
    fn none_chunk_checks_size_and_bz2_is_unsupported() {
        assert_eq!(decompress("none", 3, b"abc").unwrap(), b"abc");
        assert!(matches!(
            decompress("none", 4, b"abc"),
            Err(ChunkError::SizeMismatch { .. })
        ));
        assert_eq!(
            decompress("bz2", 3, b"abc"),
            Err(ChunkError::UnsupportedCompression("bz2".into()))
        );
    }
}
