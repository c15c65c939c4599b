use crate::codec::CodecError;

/// Why an `.oni` recording could not be read. Every variant names the file (as given to the
/// reader) and, where there is one, the byte offset of the record at fault.
#[derive(Debug, thiserror::Error)]
pub enum OniError {
    #[error("cannot read ONI recording {file}: {error}")]
    Io { file: String, error: std::io::Error },
    #[error("{file} is not an ONI recording: it starts with {found:02x?}, not \"NI10\"")]
    BadMagic { file: String, found: Vec<u8> },
    #[error(
        "{file} is truncated: {what} at offset {offset} needs {needed} bytes but only \
         {available} remain; was the recording cut short?"
    )]
    Truncated {
        file: String,
        offset: u64,
        what: &'static str,
        needed: u64,
        available: u64,
    },
    #[error("{file}: malformed record at offset {offset}: {reason}")]
    BadRecord {
        file: String,
        offset: u64,
        reason: String,
    },
    #[error("{file} has no depth node: was the recording made with a depth stream enabled?")]
    NoDepthNode { file: String },
    #[error(
        "{file}: depth node {node:?} (record at offset {offset}) uses codec {codec:?}; only 16zT \
         is supported"
    )]
    UnsupportedCodec {
        file: String,
        offset: u64,
        node: String,
        codec: String,
    },
    #[error("{file}: depth node {node:?} lacks {what}")]
    MissingProperty {
        file: String,
        node: String,
        what: &'static str,
    },
    #[error("{file}: depth frame {frame_number} (record at offset {offset}): {error}")]
    Frame {
        file: String,
        offset: u64,
        frame_number: u32,
        error: CodecError,
    },
    #[error("{file} has no depth frame at index {index}: it holds {count}")]
    NoSuchFrame {
        file: String,
        index: usize,
        count: usize,
    },
}
