//! Records of a ROS bag v2.0 file and the `name=value` headers that open each of them.
//!
//! Format (wiki.ros.org/Bags/Format/2.0): after the 13-byte version line `#ROSBAG V2.0\n`
//! the file is a sequence of records, each
//!
//! ```text
//! header_len: u32 LE | header: header_len bytes | data_len: u32 LE | data: data_len bytes
//! ```
//!
//! and a header is a sequence of fields `field_len: u32 LE | name '=' value` where `field_len`
//! counts the name, the `=` and the value. Every header has an `op` field (one byte) naming the
//! record type; integers in field values are little-endian.
//!
//! Entry points: [`read_record`] (from any reader, with a byte budget that caps allocations),
//! [`Header`] and its typed field getters, [`Op`].

use std::io::Read;

use crate::Time;

/// The version line every v2.0 bag starts with.
pub const MAGIC: &[u8; 13] = b"#ROSBAG V2.0\n";

/// The record types of bag format 2.0 (value of the `op` header field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// 0x02: one serialised message of a connection.
    MessageData,
    /// 0x03: the bag header (index position, connection and chunk counts).
    BagHeader,
    /// 0x04: per-connection index of the preceding chunk.
    IndexData,
    /// 0x05: a (possibly compressed) block of connection and message records.
    Chunk,
    /// 0x06: summary of one chunk, in the index section.
    ChunkInfo,
    /// 0x07: a topic with its message type, md5sum and definition.
    Connection,
    /// Anything else (op 0x01 is the v1.2 message definition); readers skip these.
    Other(u8),
}

impl Op {
    fn from_byte(op: u8) -> Op {
        match op {
            0x02 => Op::MessageData,
            0x03 => Op::BagHeader,
            0x04 => Op::IndexData,
            0x05 => Op::Chunk,
            0x06 => Op::ChunkInfo,
            0x07 => Op::Connection,
            other => Op::Other(other),
        }
    }
}

/// Why a record or header could not be read. Offsets are relative to the start of whatever was
/// being read (the file, or a chunk's decompressed data); the caller adds the context.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error(
        "truncated at byte {offset}: the {what} needs {needed} bytes but only {available} remain"
    )]
    Truncated {
        offset: u64,
        what: &'static str,
        needed: u64,
        available: u64,
    },
    #[error("malformed record header at byte {offset}: {reason}")]
    BadHeader { offset: u64, reason: String },
    #[error("read failed at byte {offset}: {error}")]
    Io { offset: u64, error: std::io::Error },
}

impl RecordError {
    /// The byte offset the error refers to, relative to what was being read.
    pub fn offset(&self) -> u64 {
        match self {
            RecordError::Truncated { offset, .. }
            | RecordError::BadHeader { offset, .. }
            | RecordError::Io { offset, .. } => *offset,
        }
    }
}

/// A parsed record header: its fields in file order (names are unique).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Header {
    fields: Vec<(String, Vec<u8>)>,
}

/// A header field that is missing or has the wrong size or content.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FieldError {
    #[error("header has no `{0}` field")]
    Missing(&'static str),
    #[error("header field `{name}` is {len} bytes, expected {expected}")]
    WrongSize {
        name: &'static str,
        len: usize,
        expected: usize,
    },
    #[error("header field `{0}` is not UTF-8")]
    NotUtf8(&'static str),
}

impl Header {
    /// Parses the `field_len | name=value` sequence of one header.
    pub fn parse(bytes: &[u8]) -> Result<Header, String> {
        let mut fields: Vec<(String, Vec<u8>)> = Vec::new();
        // A hash set, not a scan of `fields`: a hostile header of many tiny fields must not
        // cost quadratic time.
        let mut seen = std::collections::HashSet::new();
        let mut pos = 0usize;
        while pos < bytes.len() {
            let Some(len_bytes) = bytes.get(pos..pos + 4) else {
                return Err(format!(
                    "{} stray bytes at header byte {pos} (a field needs a 4-byte length)",
                    bytes.len() - pos
                ));
            };
            let len = u32::from_le_bytes([len_bytes[0], len_bytes[1], len_bytes[2], len_bytes[3]])
                as usize;
            pos += 4;
            let Some(field) = bytes.get(pos..).and_then(|rest| rest.get(..len)) else {
                return Err(format!(
                    "field at header byte {} claims {len} bytes but only {} remain",
                    pos - 4,
                    bytes.len() - pos
                ));
            };
            pos += len;
            let Some(eq) = field.iter().position(|&b| b == b'=') else {
                return Err(format!("field at header byte {} has no `=`", pos - len - 4));
            };
            let (name, value) = (&field[..eq], &field[eq + 1..]);
            if name.is_empty() || !name.iter().all(|b| (0x20..=0x7e).contains(b)) {
                return Err(format!(
                    "field at header byte {} has an empty or non-printable name",
                    pos - len - 4
                ));
            }
            // Checked printable ASCII just above, so this is valid UTF-8.
            let name = String::from_utf8_lossy(name).into_owned();
            if !seen.insert(name.clone()) {
                return Err(format!("field `{name}` appears twice"));
            }
            fields.push((name, value.to_vec()));
        }
        Ok(Header { fields })
    }

    /// The raw value of field `name`, if present.
    pub fn get(&self, name: &str) -> Option<&[u8]> {
        self.fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// Field names in file order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.fields.iter().map(|(n, _)| n.as_str())
    }

    /// The record type (`op`, one byte).
    pub fn op(&self) -> Result<Op, FieldError> {
        Ok(Op::from_byte(self.fixed::<1>("op")?[0]))
    }

    /// A little-endian `u32` field.
    pub fn u32(&self, name: &'static str) -> Result<u32, FieldError> {
        Ok(u32::from_le_bytes(self.fixed(name)?))
    }

    /// A little-endian `u64` field.
    pub fn u64(&self, name: &'static str) -> Result<u64, FieldError> {
        Ok(u64::from_le_bytes(self.fixed(name)?))
    }

    /// A ROS time field (`sec: u32`, `nsec: u32`, both little-endian).
    pub fn time(&self, name: &'static str) -> Result<Time, FieldError> {
        let b: [u8; 8] = self.fixed(name)?;
        Ok(Time {
            sec: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            nsec: u32::from_le_bytes([b[4], b[5], b[6], b[7]]),
        })
    }

    /// A UTF-8 string field.
    pub fn string(&self, name: &'static str) -> Result<String, FieldError> {
        let v = self.get(name).ok_or(FieldError::Missing(name))?;
        String::from_utf8(v.to_vec()).map_err(|_| FieldError::NotUtf8(name))
    }

    fn fixed<const N: usize>(&self, name: &'static str) -> Result<[u8; N], FieldError> {
        let v = self.get(name).ok_or(FieldError::Missing(name))?;
        v.try_into().map_err(|_| FieldError::WrongSize {
            name,
            len: v.len(),
            expected: N,
        })
    }
}

/// One record: where it started, its header, and its data bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    /// Byte offset of the record's `header_len`, relative to what it was read from.
    pub offset: u64,
    pub header: Header,
    pub data: Vec<u8>,
    /// Total bytes of the record: both length prefixes, the header and the data.
    pub size: u64,
}

/// Reads one record starting at `offset` from `reader`, of which `available` bytes remain.
///
/// Returns `Ok(None)` at a clean end (`available == 0`). Every length is checked against
/// `available` before anything is allocated, so a hostile `header_len` or `data_len` costs an
/// error, not memory.
pub fn read_record<R: Read>(
    reader: &mut R,
    offset: u64,
    available: u64,
) -> Result<Option<Record>, RecordError> {
    if available == 0 {
        return Ok(None);
    }
    let mut cursor = Budget {
        reader,
        pos: offset,
        left: available,
    };
    let header_len = cursor.u32("record's header length")?;
    let header_offset = cursor.pos;
    let header_bytes = cursor.bytes(header_len, "record header")?;
    let header = Header::parse(&header_bytes).map_err(|reason| RecordError::BadHeader {
        offset: header_offset,
        reason,
    })?;
    let data_len = cursor.u32("record's data length")?;
    let data = cursor.bytes(data_len, "record data")?;
    Ok(Some(Record {
        offset,
        header,
        size: 8 + u64::from(header_len) + data.len() as u64,
        data,
    }))
}

/// A reader with a byte budget: refuses to read (or allocate for) more than `left` bytes.
struct Budget<'r, R> {
    reader: &'r mut R,
    pos: u64,
    left: u64,
}

impl<R: Read> Budget<'_, R> {
    fn u32(&mut self, what: &'static str) -> Result<u32, RecordError> {
        let b = self.bytes(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn bytes(&mut self, len: u32, what: &'static str) -> Result<Vec<u8>, RecordError> {
        let len = u64::from(len);
        if len > self.left {
            return Err(RecordError::Truncated {
                offset: self.pos,
                what,
                needed: len,
                available: self.left,
            });
        }
        // `len` is at most the bytes left in the file or chunk, so this allocation is bounded.
        let mut buf = vec![0u8; len as usize];
        self.reader
            .read_exact(&mut buf)
            .map_err(|error| match error.kind() {
                std::io::ErrorKind::UnexpectedEof => RecordError::Truncated {
                    offset: self.pos,
                    what,
                    needed: len,
                    available: 0,
                },
                _ => RecordError::Io {
                    offset: self.pos,
                    error,
                },
            })?;
        self.pos += len;
        self.left -= len;
        Ok(buf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut f = ((name.len() + 1 + value.len()) as u32)
            .to_le_bytes()
            .to_vec();
        f.extend_from_slice(name.as_bytes());
        f.push(b'=');
        f.extend_from_slice(value);
        f
    }

    #[test]
    fn header_parses_fields_with_binary_values() {
        let mut bytes = field("op", &[0x02]);
        bytes.extend(field("conn", &7u32.to_le_bytes()));
        bytes.extend(field("topic", b"/a=b"));
        let h = Header::parse(&bytes).unwrap();
        assert_eq!(h.op().unwrap(), Op::MessageData);
        assert_eq!(h.u32("conn").unwrap(), 7);
        // Only the first `=` separates name and value.
        assert_eq!(h.string("topic").unwrap(), "/a=b");
        assert_eq!(
            h.u64("conn").unwrap_err().to_string(),
            "header field `conn` is 4 bytes, expected 8"
        );
    }

    #[test]
    fn header_rejects_field_longer_than_header() {
        let mut bytes = field("op", &[0x02]);
        bytes[0] = 200;
        let err = Header::parse(&bytes).unwrap_err();
        assert!(err.contains("claims 200 bytes"), "{err}");
    }

    #[test]
    fn header_rejects_field_without_equals_and_duplicates() {
        let mut bytes = 2u32.to_le_bytes().to_vec();
        bytes.extend_from_slice(b"op");
        assert!(Header::parse(&bytes).unwrap_err().contains("no `=`"));
        let mut dup = field("op", &[2]);
        dup.extend(field("op", &[3]));
        assert!(Header::parse(&dup).unwrap_err().contains("twice"));
    }

    #[test]
    fn read_record_refuses_hostile_length_without_allocating() {
        // header_len = 4 GiB - 1 in a 12-byte input: must be a typed error, not an allocation.
        let mut bytes = u32::MAX.to_le_bytes().to_vec();
        bytes.extend_from_slice(&[0; 8]);
        let err = read_record(&mut bytes.as_slice(), 100, bytes.len() as u64).unwrap_err();
        match err {
            RecordError::Truncated {
                offset,
                needed,
                available,
                ..
            } => assert_eq!((offset, needed, available), (104, u32::MAX as u64, 8)),
            other => panic!("{other}"),
        }
    }

    #[test]
    fn read_record_reads_header_and_data() {
        let header = field("op", &[0x05]);
        let mut bytes = (header.len() as u32).to_le_bytes().to_vec();
        bytes.extend(&header);
        bytes.extend(3u32.to_le_bytes());
        bytes.extend(b"abc");
        let rec = read_record(&mut bytes.as_slice(), 0, bytes.len() as u64)
            .unwrap()
            .unwrap();
        assert_eq!(rec.header.op().unwrap(), Op::Chunk);
        assert_eq!(rec.data, b"abc");
        assert!(read_record(&mut [].as_slice(), 0, 0).unwrap().is_none());
    }
}
