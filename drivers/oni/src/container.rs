//! The NI10 container: a file header, then a flat sequence of records.
//!
//! Layout as written by OpenNI 1.x's recorder and read by OpenNI 1.x `XnPlayerImpl` and OpenNI2's
//! `OniFile` driver (`DataRecords.h`); all integers little-endian.
//!
//! File header (24 bytes): magic `NI10`; version `u8 major, u8 minor, u16 maintenance,
//! u32 build`; `u64` largest timestamp (µs); `u32` largest node id.
//!
//! Record header (28 bytes; 24 in files older than version 1.0.1.0, whose undo position is
//! `u32`):
//!
//! | field          | type  | meaning                                                 |
//! |----------------|-------|---------------------------------------------------------|
//! | magic          | `u32` | `NIR\0`                                                 |
//! | type           | `u32` | [`RecordType`]                                          |
//! | node id        | `u32` | which node the record is about                          |
//! | fields size    | `u32` | header + type-specific fields, bytes                    |
//! | payload size   | `u32` | bytes of payload after the fields (frame data, tables)  |
//! | undo position  | `u64` | offset of the record this one supersedes (for seeking)  |
//!
//! The next record starts at `offset + fields size + payload size`. Strings in fields are a
//! `u32` length including the terminating NUL, then the bytes. Fields by type:
//!
//! | type                 | fields after the header                                       |
//! |----------------------|---------------------------------------------------------------|
//! | NodeAdded (2, 12, 13)| name, `u32` node type (2 = depth), 4-byte codec id, then      |
//! |                      | frame count, timestamps and seek-table position (ignored)     |
//! | Int/Real/String/General property (3–6) | name, `u32` value size, value (`u64`,  |
//! |                      | `f64`, NUL-terminated string, raw bytes)                      |
//! | NewData (10)         | `u64` timestamp (µs), `u32` frame number; payload = the frame |
//! | End (11)             | none; the last record of a complete file                      |
//! | NodeRemoved (7), NodeDataBegin (8), NodeStateReady (9), SeekTable (14) | skipped     |
//!
//! Entry points: [`FileHeader`], and the crate-internal `RecordReader` that walks records
//! with every size checked against the bytes left in the file.

use std::io::{Read, Seek, SeekFrom};

use crate::OniError;

/// The magic at offset 0 of every `.oni` file.
pub const FILE_MAGIC: &[u8; 4] = b"NI10";
const RECORD_MAGIC: u32 = u32::from_le_bytes(*b"NIR\0");
const FILE_HEADER_LEN: u64 = 24;
const RECORD_HEADER_LEN: u64 = 28;
const RECORD_HEADER_LEN_OLD32: u64 = 24;
/// Largest fields block accepted (property values such as the S2D/D2S tables are ~20 KiB).
const MAX_FIELDS_LEN: u64 = 1 << 20;

/// Recorder version stored in the file header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Version {
    pub major: u8,
    pub minor: u8,
    pub maintenance: u16,
    pub build: u32,
}

/// The 24-byte header at the start of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileHeader {
    pub version: Version,
    /// Largest data timestamp in the file, microseconds.
    pub max_timestamp_us: u64,
    pub max_node_id: u32,
}

/// Record types (OpenNI's `RecordType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordType {
    /// Any of the three NodeAdded generations (0x02, 0x0C, 0x0D); they share a prefix.
    NodeAdded,
    IntProperty,
    RealProperty,
    StringProperty,
    GeneralProperty,
    NodeRemoved,
    NodeDataBegin,
    NodeStateReady,
    NewData,
    End,
    SeekTable,
}

impl RecordType {
    fn from_u32(value: u32) -> Option<Self> {
        Some(match value {
            0x02 | 0x0C | 0x0D => Self::NodeAdded,
            0x03 => Self::IntProperty,
            0x04 => Self::RealProperty,
            0x05 => Self::StringProperty,
            0x06 => Self::GeneralProperty,
            0x07 => Self::NodeRemoved,
            0x08 => Self::NodeDataBegin,
            0x09 => Self::NodeStateReady,
            0x0A => Self::NewData,
            0x0B => Self::End,
            0x0E => Self::SeekTable,
            _ => return None,
        })
    }
}

/// A node property's value as recorded.
#[derive(Debug, Clone, PartialEq)]
pub enum Property {
    Int(u64),
    Real(f64),
    String(String),
    General(Vec<u8>),
}

/// What a record says, for the record types replay needs.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Content {
    NodeAdded {
        name: String,
        node_type: u32,
        codec: [u8; 4],
    },
    Property {
        name: String,
        value: Property,
    },
    NewData {
        timestamp_us: u64,
        frame_number: u32,
    },
    End,
    Skipped,
}

/// One record: where it is, whose it is, what it says and where its payload lies.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Record {
    pub offset: u64,
    pub node_id: u32,
    pub content: Content,
    pub payload_offset: u64,
    pub payload_len: u32,
}

/// Walks the records of a recording, reading only headers and fields; payloads are skipped.
pub(crate) struct RecordReader<R> {
    reader: R,
    file: String,
    file_len: u64,
    next_offset: u64,
    header_len: u64,
}

impl<R: Read + Seek> RecordReader<R> {
    /// Reads and checks the file header; the reader is then positioned at the first record.
    pub fn new(mut reader: R, file: String) -> Result<(Self, FileHeader), OniError> {
        let io = |error| OniError::Io {
            file: file.clone(),
            error,
        };
        let file_len = reader.seek(SeekFrom::End(0)).map_err(io)?;
        reader.seek(SeekFrom::Start(0)).map_err(io)?;
        let mut this = Self {
            reader,
            file,
            file_len,
            next_offset: 0,
            header_len: RECORD_HEADER_LEN,
        };
        let magic_len = file_len.min(4) as usize;
        let magic = this.read_exact_at(0, magic_len, "the file magic")?;
        if magic.as_slice() != FILE_MAGIC {
            return Err(OniError::BadMagic {
                file: this.file,
                found: magic,
            });
        }
        let bytes = this.read_exact_at(0, FILE_HEADER_LEN as usize, "the file header")?;
        let mut f = Fields::new(&bytes[4..], 0, &this.file);
        let header = FileHeader {
            version: Version {
                major: f.u8()?,
                minor: f.u8()?,
                maintenance: f.u16()?,
                build: f.u32()?,
            },
            max_timestamp_us: f.u64()?,
            max_node_id: f.u32()?,
        };
        let first_64bit = Version {
            major: 1,
            minor: 0,
            maintenance: 1,
            build: 0,
        };
        if header.version < first_64bit {
            this.header_len = RECORD_HEADER_LEN_OLD32;
        }
        this.next_offset = FILE_HEADER_LEN;
        Ok((this, header))
    }

    pub fn file(&self) -> &str {
        &self.file
    }

    /// The next record. A file that ends before an End record is truncated.
    pub fn next_record(&mut self) -> Result<Record, OniError> {
        let offset = self.next_offset;
        let header = self.read_exact_at(offset, self.header_len as usize, "a record header")?;
        let mut h = Fields::new(&header, offset, &self.file);
        let magic = h.u32()?;
        let kind = h.u32()?;
        let node_id = h.u32()?;
        let fields_len = u64::from(h.u32()?);
        let payload_len = h.u32()?;
        if magic != RECORD_MAGIC {
            return Err(self.bad(
                offset,
                format!("record magic is {magic:#010x}, not \"NIR\""),
            ));
        }
        let kind = RecordType::from_u32(kind)
            .ok_or_else(|| self.bad(offset, format!("unknown record type {kind:#x}")))?;
        if !(self.header_len..=MAX_FIELDS_LEN).contains(&fields_len) {
            return Err(self.bad(
                offset,
                format!(
                    "fields size {fields_len} is outside {}..={MAX_FIELDS_LEN}",
                    self.header_len
                ),
            ));
        }
        let payload_offset = offset + fields_len;
        let end = payload_offset + u64::from(payload_len);
        if end > self.file_len {
            return Err(OniError::Truncated {
                file: self.file.clone(),
                offset,
                what: "a record",
                needed: end - offset,
                available: self.file_len - offset,
            });
        }
        let fields = self.read_exact_at(
            offset + self.header_len,
            (fields_len - self.header_len) as usize,
            "record fields",
        )?;
        let content = self.parse_fields(kind, offset, &fields)?;
        self.next_offset = end;
        Ok(Record {
            offset,
            node_id,
            content,
            payload_offset,
            payload_len,
        })
    }

    /// Reads `len` bytes at `offset`, after checking they lie inside the file.
    pub fn read_exact_at(
        &mut self,
        offset: u64,
        len: usize,
        what: &'static str,
    ) -> Result<Vec<u8>, OniError> {
        let available = self.file_len.saturating_sub(offset);
        if len as u64 > available {
            return Err(OniError::Truncated {
                file: self.file.clone(),
                offset,
                what,
                needed: len as u64,
                available,
            });
        }
        let mut bytes = vec![0; len];
        let io = |error| OniError::Io {
            file: self.file.clone(),
            error,
        };
        self.reader.seek(SeekFrom::Start(offset)).map_err(io)?;
        self.reader.read_exact(&mut bytes).map_err(io)?;
        Ok(bytes)
    }

    fn parse_fields(
        &self,
        kind: RecordType,
        offset: u64,
        fields: &[u8],
    ) -> Result<Content, OniError> {
        let mut f = Fields::new(fields, offset, &self.file);
        Ok(match kind {
            RecordType::NodeAdded => Content::NodeAdded {
                name: f.string()?,
                node_type: f.u32()?,
                codec: f.array()?,
            },
            RecordType::IntProperty
            | RecordType::RealProperty
            | RecordType::StringProperty
            | RecordType::GeneralProperty => {
                let name = f.string()?;
                let len = f.u32()? as usize;
                let raw = f.take(len)?;
                let value = match kind {
                    RecordType::IntProperty => Property::Int(u64::from_le_bytes(
                        raw.try_into()
                            .map_err(|_| self.bad(offset, wrong_size(&name, len, 8)))?,
                    )),
                    RecordType::RealProperty => Property::Real(f64::from_le_bytes(
                        raw.try_into()
                            .map_err(|_| self.bad(offset, wrong_size(&name, len, 8)))?,
                    )),
                    RecordType::StringProperty => Property::String(c_string(raw)),
                    _ => Property::General(raw.to_vec()),
                };
                Content::Property { name, value }
            }
            RecordType::NewData => Content::NewData {
                timestamp_us: f.u64()?,
                frame_number: f.u32()?,
            },
            RecordType::End => Content::End,
            _ => Content::Skipped,
        })
    }

    fn bad(&self, offset: u64, reason: String) -> OniError {
        OniError::BadRecord {
            file: self.file.clone(),
            offset,
            reason,
        }
    }
}

fn wrong_size(name: &str, len: usize, expected: usize) -> String {
    format!("property {name:?} has {len} value bytes, expected {expected}")
}

/// Text up to the first NUL (or the end), lossily decoded.
fn c_string(raw: &[u8]) -> String {
    let text = raw.split(|&b| b == 0).next().unwrap_or_default();
    String::from_utf8_lossy(text).into_owned()
}

/// A bounds-checked little-endian cursor over one record's fields.
struct Fields<'a> {
    bytes: &'a [u8],
    at: usize,
    record_offset: u64,
    file: &'a str,
}

impl<'a> Fields<'a> {
    fn new(bytes: &'a [u8], record_offset: u64, file: &'a str) -> Self {
        Self {
            bytes,
            at: 0,
            record_offset,
            file,
        }
    }

    fn take(&mut self, len: usize) -> Result<&'a [u8], OniError> {
        let end = self
            .at
            .checked_add(len)
            .filter(|&end| end <= self.bytes.len());
        let Some(end) = end else {
            return Err(OniError::BadRecord {
                file: self.file.to_owned(),
                offset: self.record_offset,
                reason: format!(
                    "fields end after {} bytes, {} more needed at field byte {}",
                    self.bytes.len(),
                    len,
                    self.at
                ),
            });
        };
        let taken = &self.bytes[self.at..end];
        self.at = end;
        Ok(taken)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], OniError> {
        let mut out = [0; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    fn u8(&mut self) -> Result<u8, OniError> {
        Ok(self.array::<1>()?[0])
    }

    fn u16(&mut self) -> Result<u16, OniError> {
        self.array().map(u16::from_le_bytes)
    }

    fn u32(&mut self) -> Result<u32, OniError> {
        self.array().map(u32::from_le_bytes)
    }

    fn u64(&mut self) -> Result<u64, OniError> {
        self.array().map(u64::from_le_bytes)
    }

    fn string(&mut self) -> Result<String, OniError> {
        let len = self.u32()? as usize;
        Ok(c_string(self.take(len)?))
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn file_header() -> Vec<u8> {
        let mut bytes = b"NI10".to_vec();
        bytes.extend([1, 0, 1, 0, 0, 0, 0, 0]);
        bytes.extend(0u64.to_le_bytes());
        bytes.extend(1u32.to_le_bytes());
        bytes
    }

    fn record(kind: u32, node: u32, fields: &[u8], payload: &[u8]) -> Vec<u8> {
        let mut bytes = b"NIR\0".to_vec();
        bytes.extend(kind.to_le_bytes());
        bytes.extend(node.to_le_bytes());
        bytes.extend((28 + fields.len() as u32).to_le_bytes());
        bytes.extend((payload.len() as u32).to_le_bytes());
        bytes.extend(0u64.to_le_bytes());
        bytes.extend(fields);
        bytes.extend(payload);
        bytes
    }

    fn reader(bytes: Vec<u8>) -> RecordReader<Cursor<Vec<u8>>> {
        RecordReader::new(Cursor::new(bytes), "test.oni".into())
            .unwrap()
            .0
    }

    #[test]
    fn int_property_record_parses() {
        let mut fields = 4u32.to_le_bytes().to_vec();
        fields.extend(b"ZPD\0");
        fields.extend(8u32.to_le_bytes());
        fields.extend(120u64.to_le_bytes());
        let mut bytes = file_header();
        bytes.extend(record(3, 7, &fields, &[]));
        let r = reader(bytes).next_record().unwrap();
        assert_eq!(r.node_id, 7);
        assert_eq!(
            r.content,
            Content::Property {
                name: "ZPD".into(),
                value: Property::Int(120)
            }
        );
    }

    #[test]
    fn new_data_record_points_at_its_payload() {
        let mut fields = 33_000u64.to_le_bytes().to_vec();
        fields.extend(4u32.to_le_bytes());
        let mut bytes = file_header();
        bytes.extend(record(10, 2, &fields, &[9, 9, 9]));
        let r = reader(bytes).next_record().unwrap();
        assert_eq!(
            r.content,
            Content::NewData {
                timestamp_us: 33_000,
                frame_number: 4
            }
        );
        assert_eq!((r.payload_offset, r.payload_len), (24 + 28 + 12, 3));
    }

    #[test]
    fn record_with_payload_past_file_end_is_truncated() {
        let mut bytes = file_header();
        bytes.extend(record(10, 2, &[0; 12], &[1, 2, 3, 4]));
        bytes.truncate(bytes.len() - 1);
        assert!(matches!(
            reader(bytes).next_record(),
            Err(OniError::Truncated { offset: 24, .. })
        ));
    }

    #[test]
    fn huge_string_length_is_a_bad_record_not_an_allocation() {
        let mut fields = u32::MAX.to_le_bytes().to_vec();
        fields.extend([0; 8]);
        let mut bytes = file_header();
        bytes.extend(record(13, 1, &fields, &[]));
        assert!(matches!(
            reader(bytes).next_record(),
            Err(OniError::BadRecord { offset: 24, .. })
        ));
    }

    #[test]
    fn unknown_record_type_is_rejected() {
        let mut bytes = file_header();
        bytes.extend(record(0x55, 1, &[], &[]));
        let err = reader(bytes).next_record().unwrap_err();
        assert!(
            err.to_string().contains("unknown record type 0x55"),
            "{err}"
        );
    }

    #[test]
    fn wrong_magic_is_rejected() {
        let result = RecordReader::new(Cursor::new(b"NI20 and more".to_vec()), "x.oni".into());
        assert!(matches!(result, Err(OniError::BadMagic { .. })));
    }
}
