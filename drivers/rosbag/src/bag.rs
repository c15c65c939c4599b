//! Reading a bag file: the bag header, the connections of the index section, and the messages
//! of the chunk section in file order.
//!
//! Layout of a v2.0 bag: version line, bag header record (op 0x03, padded to 4 KiB, holding
//! `index_pos`, `conn_count`, `chunk_count`), then chunks (op 0x05) each followed by its index
//! data records (op 0x04), then at `index_pos` the index section: one connection record (op 0x07)
//! per connection and one chunk info record (op 0x06) per chunk. Connection records are also
//! repeated inside the chunks, ahead of their first message.
//!
//! Entry points: [`Bag::open`], [`Bag::connections`], [`Bag::messages`].

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::chunk::{self, ChunkError};
use crate::record::{self, FieldError, Header, Op, Record, RecordError, MAGIC};
use crate::Time;

/// Why a bag could not be read. Every variant names the file and, where it applies, the byte
/// offset in the file of the record at fault.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("cannot read {path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path} is not a ROS bag v2.0 (no `#ROSBAG V2.0` line at its start)")]
    NotABag { path: PathBuf },
    #[error("{path} is truncated or corrupt at byte {offset}: {reason}")]
    Corrupt {
        path: PathBuf,
        offset: u64,
        reason: String,
    },
    #[error("{path}: chunk at byte {offset}: {error}")]
    Chunk {
        path: PathBuf,
        offset: u64,
        error: ChunkError,
    },
    #[error(
        "{path}: message at byte {offset} refers to connection {conn}, which the bag never defines"
    )]
    UnknownConnection {
        path: PathBuf,
        offset: u64,
        conn: u32,
    },
}

/// One connection: a topic with its message type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Connection {
    pub id: u32,
    pub topic: String,
    /// Message type, e.g. `sensor_msgs/Image`.
    pub msg_type: String,
    pub md5sum: String,
    /// Full text of the message definition.
    pub message_definition: String,
}

/// One message: its connection, its record time, and its serialised bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Message {
    pub connection: Arc<Connection>,
    /// Record (receive) time from the message data header.
    pub time: Time,
    pub data: Vec<u8>,
}

/// An opened bag: its header and the connections listed in its index section.
#[derive(Debug, Clone)]
pub struct Bag {
    path: PathBuf,
    file_len: u64,
    /// Where the chunk section starts (just after the bag header record).
    chunks_start: u64,
    /// Where the chunk section ends (`index_pos`, or the file's end in an unindexed bag).
    chunks_end: u64,
    chunk_count: u32,
    connections: BTreeMap<u32, Arc<Connection>>,
}

impl Bag {
    /// Opens `path`, reads the bag header and the index section's connection records.
    ///
    /// A bag whose recording was cut short (`index_pos` 0) is read without an index:
    /// connections are then learned from the chunks as [`Bag::messages`] walks them.
    pub fn open(path: impl AsRef<Path>) -> Result<Bag, BagError> {
        let path = path.as_ref().to_path_buf();
        let io = |error| BagError::Io {
            path: path.clone(),
            error,
        };
        // A FIFO would block the open until a writer came; a device would never end.
        tacmesh_source::check_regular_file(&path, u64::MAX).map_err(io)?;
        let file = File::open(&path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut reader = BufReader::new(file);
        let mut magic = [0u8; MAGIC.len()];
        if file_len < MAGIC.len() as u64 {
            return Err(BagError::NotABag { path });
        }
        reader.read_exact(&mut magic).map_err(io)?;
        if &magic != MAGIC {
            return Err(BagError::NotABag { path });
        }
        let mut bag = Bag {
            path,
            file_len,
            chunks_start: 0,
            chunks_end: file_len,
            chunk_count: 0,
            connections: BTreeMap::new(),
        };
        let start = MAGIC.len() as u64;
        let header = bag
            .read_record(&mut reader, start, file_len)?
            .ok_or_else(|| bag.corrupt(start, "no bag header record".into()))?;
        if bag.op(&header)? != Op::BagHeader {
            return Err(bag.corrupt(start, "first record is not the bag header (op 0x03)".into()));
        }
        let field = |e: FieldError| bag.corrupt(start, format!("bag header: {e}"));
        let index_pos = header.header.u64("index_pos").map_err(field)?;
        let conn_count = header.header.u32("conn_count").map_err(field)?;
        let chunk_count = header.header.u32("chunk_count").map_err(field)?;
        bag.chunks_start = start + header.size;
        bag.chunk_count = chunk_count;
        if index_pos == 0 {
            tracing::warn!(path = %bag.path.display(), "bag has no index (recording cut short?); reading chunks only");
            return Ok(bag);
        }
        if index_pos < bag.chunks_start || index_pos > file_len {
            return Err(bag.corrupt(
                start,
                format!("index position {index_pos} lies outside the file's {file_len} bytes"),
            ));
        }
        bag.chunks_end = index_pos;
        bag.read_index(&mut reader, index_pos, conn_count, chunk_count)?;
        Ok(bag)
    }

    /// The file this bag was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The number of chunks the bag header declares.
    pub fn chunk_count(&self) -> u32 {
        self.chunk_count
    }

    /// The connections of the index section, by id (empty for an unindexed bag).
    pub fn connections(&self) -> impl Iterator<Item = &Connection> {
        self.connections.values().map(|c| c.as_ref())
    }

    /// The distinct topics of the index section, sorted.
    pub fn topics(&self) -> Vec<&str> {
        let mut topics: Vec<&str> = self.connections().map(|c| c.topic.as_str()).collect();
        topics.sort_unstable();
        topics.dedup();
        topics
    }

    /// Iterates over every message in file order (chunk by chunk; within a chunk, as written).
    /// Opens its own handle on the file, so several iterations can run side by side.
    pub fn messages(&self) -> Result<Messages, BagError> {
        let mut file = File::open(&self.path).map_err(|error| BagError::Io {
            path: self.path.clone(),
            error,
        })?;
        file.seek(SeekFrom::Start(self.chunks_start))
            .map_err(|error| BagError::Io {
                path: self.path.clone(),
                error,
            })?;
        Ok(Messages {
            bag: self.clone(),
            reader: BufReader::new(file),
            pos: self.chunks_start,
            pending: std::collections::VecDeque::new(),
            failed: false,
        })
    }

    fn read_index(
        &mut self,
        reader: &mut BufReader<File>,
        index_pos: u64,
        conn_count: u32,
        chunk_count: u32,
    ) -> Result<(), BagError> {
        reader
            .seek(SeekFrom::Start(index_pos))
            .map_err(|error| BagError::Io {
                path: self.path.clone(),
                error,
            })?;
        let (mut pos, mut chunk_infos) = (index_pos, 0u32);
        while let Some(rec) = self.read_record(reader, pos, self.file_len)? {
            match self.op(&rec)? {
                Op::Connection => {
                    let conn = self.parse_connection(&rec, pos)?;
                    self.connections.insert(conn.id, Arc::new(conn));
                }
                Op::ChunkInfo => chunk_infos += 1,
                _ => {}
            }
            pos += rec.size;
        }
        // Counting catches a file cut exactly at a record boundary in the index section.
        if self.connections.len() as u64 != u64::from(conn_count) || chunk_infos != chunk_count {
            return Err(self.corrupt(
                index_pos,
                format!(
                    "index section holds {} connections and {chunk_infos} chunk infos, the bag header declares {conn_count} and {chunk_count} (file cut short?)",
                    self.connections.len()
                ),
            ));
        }
        Ok(())
    }

    fn read_record<R: Read>(
        &self,
        reader: &mut R,
        offset: u64,
        end: u64,
    ) -> Result<Option<Record>, BagError> {
        record::read_record(reader, offset, end.saturating_sub(offset))
            .map_err(|e| self.record_error(e, 0))
    }

    fn record_error(&self, e: RecordError, base: u64) -> BagError {
        match e {
            RecordError::Io { error, .. } => BagError::Io {
                path: self.path.clone(),
                error,
            },
            other => self.corrupt(base + other.offset(), other.to_string()),
        }
    }

    fn op(&self, rec: &Record) -> Result<Op, BagError> {
        rec.header
            .op()
            .map_err(|e| self.corrupt(rec.offset, e.to_string()))
    }

    fn parse_connection(&self, rec: &Record, offset: u64) -> Result<Connection, BagError> {
        let bad = |e: FieldError| self.corrupt(offset, format!("connection record: {e}"));
        let id = rec.header.u32("conn").map_err(bad)?;
        let topic = rec.header.string("topic").map_err(bad)?;
        let fields = Header::parse(&rec.data)
            .map_err(|reason| self.corrupt(offset, format!("connection record data: {reason}")))?;
        Ok(Connection {
            id,
            topic,
            msg_type: fields.string("type").map_err(bad)?,
            md5sum: fields.string("md5sum").map_err(bad)?,
            message_definition: fields.string("message_definition").map_err(bad)?,
        })
    }

    fn corrupt(&self, offset: u64, reason: String) -> BagError {
        BagError::Corrupt {
            path: self.path.clone(),
            offset,
            reason,
        }
    }
}

/// Iterator over a bag's messages in file order; see [`Bag::messages`]. After the first error
/// it yields `None`.
pub struct Messages {
    bag: Bag,
    reader: BufReader<File>,
    pos: u64,
    pending: std::collections::VecDeque<Message>,
    failed: bool,
}

impl Messages {
    /// Reads top-level records until a chunk yields messages or the chunk section ends.
    fn fill(&mut self) -> Result<(), BagError> {
        while self.pending.is_empty() {
            let Some(rec) =
                self.bag
                    .read_record(&mut self.reader, self.pos, self.bag.chunks_end)?
            else {
                return Ok(());
            };
            let offset = self.pos;
            self.pos += rec.size;
            match self.bag.op(&rec)? {
                Op::Chunk => self.read_chunk(&rec, offset)?,
                Op::Connection => {
                    let conn = self.bag.parse_connection(&rec, offset)?;
                    self.bag
                        .connections
                        .entry(conn.id)
                        .or_insert(Arc::new(conn));
                }
                Op::MessageData => {
                    let msg = self.message(rec, offset)?;
                    self.pending.push_back(msg);
                }
                _ => {} // index data, chunk info and unknown records carry no messages
            }
        }
        Ok(())
    }

    fn read_chunk(&mut self, rec: &Record, offset: u64) -> Result<(), BagError> {
        let bad = |e: FieldError| self.bag.corrupt(offset, format!("chunk record: {e}"));
        let compression = rec.header.string("compression").map_err(bad)?;
        let size = rec.header.u32("size").map_err(bad)?;
        let data =
            chunk::decompress(&compression, size, &rec.data).map_err(|error| BagError::Chunk {
                path: self.bag.path.clone(),
                offset,
                error,
            })?;
        let (mut inner, len) = (data.as_slice(), data.len() as u64);
        let mut inner_pos = 0u64;
        let path = self.bag.path.clone();
        let in_chunk = |e: String, at: u64| BagError::Corrupt {
            path: path.clone(),
            offset,
            reason: format!("in the chunk's decompressed data at byte {at}: {e}"),
        };
        let mut found = Vec::new();
        loop {
            let rec = match record::read_record(&mut inner, inner_pos, len - inner_pos) {
                Ok(Some(rec)) => rec,
                Ok(None) => break,
                Err(e) => return Err(in_chunk(e.to_string(), e.offset())),
            };
            let at = inner_pos;
            inner_pos += rec.size;
            match rec.header.op().map_err(|e| in_chunk(e.to_string(), at))? {
                Op::Connection => {
                    let conn = self.bag.parse_connection(&rec, offset)?;
                    self.bag
                        .connections
                        .entry(conn.id)
                        .or_insert(Arc::new(conn));
                }
                Op::MessageData => found.push(self.message(rec, offset)?),
                _ => {}
            }
        }
        self.pending.extend(found);
        Ok(())
    }

    fn message(&self, rec: Record, offset: u64) -> Result<Message, BagError> {
        let bad = |e: FieldError| self.bag.corrupt(offset, format!("message record: {e}"));
        let conn = rec.header.u32("conn").map_err(bad)?;
        let time = rec.header.time("time").map_err(bad)?;
        let connection = self.bag.connections.get(&conn).cloned().ok_or_else(|| {
            BagError::UnknownConnection {
                path: self.bag.path.clone(),
                offset,
                conn,
            }
        })?;
        Ok(Message {
            connection,
            time,
            data: rec.data,
        })
    }
}

impl Iterator for Messages {
    type Item = Result<Message, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        if let Err(e) = self.fill() {
            self.failed = true;
            return Some(Err(e));
        }
        self.pending.pop_front().map(Ok)
    }
}
