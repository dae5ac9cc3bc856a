//! ROS 1 bag files, format 2.0 (`rosbag record`): memory-mapped and streamed chunk by
//! chunk.
//!
//! A bag is the line `#ROSBAG V2.0`, then records: a `uint32` header length, header
//! fields (`uint32` length, `name=value`), a `uint32` data length, the data. Messages
//! live in chunk records (uncompressed, bz2 or lz4), each chunk holding the
//! connection records of its topics before their messages. The index at the end
//! (`index_pos` in the bag header) repeats every connection and says where each chunk
//! starts. A bag whose recording was cut off has no index (`index_pos` 0): it is read
//! by a linear scan over the chunks, and the reader says so. Every length is checked
//! against the file before it is used.

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::format::BAG_MAGIC;
use travmap_core::error::{Error, Result};
use travmap_formats::log_message::{Connection, FileMap};

/// Record opcodes (the `op` header field).
pub(crate) mod op {
    pub const MESSAGE_DATA: u8 = 0x02;
    pub const BAG_HEADER: u8 = 0x03;
    pub const CHUNK: u8 = 0x05;
    pub const CHUNK_INFO: u8 = 0x06;
    pub const CONNECTION: u8 = 0x07;
}

/// No real chunk is near this (rosbag's default is 768 KiB); a size above it is corrupt.
const LARGEST_CHUNK: usize = 1 << 30;

/// A header field: its name and value.
type Field<'a> = (&'a [u8], &'a [u8]);

/// One record: its header fields and data, and where it starts in the file.
pub(crate) struct Record<'a> {
    pub(crate) offset: usize,
    fields: Vec<Field<'a>>,
    pub(crate) data: &'a [u8],
    /// Where the next record starts.
    pub(crate) end: usize,
}

impl<'a> Record<'a> {
    /// The record at `offset` of `bytes`, checked against their length.
    pub(crate) fn at(bytes: &'a [u8], offset: usize) -> std::result::Result<Self, String> {
        let mut at = offset;
        let mut take = |what: &str| -> std::result::Result<&'a [u8], String> {
            let length = read_u32(bytes, at).ok_or_else(|| {
                format!("the record at byte {offset} is cut off in its {what} length")
            })? as usize;
            let start = at + 4;
            let end = start
                .checked_add(length)
                .filter(|end| *end <= bytes.len())
                .ok_or_else(|| {
                    format!(
                        "the record at byte {offset} claims a {length}-byte {what}, beyond the end ({} bytes)",
                        bytes.len()
                    )
                })?;
            at = end;
            Ok(&bytes[start..end])
        };
        let header = take("header")?;
        let data = take("data")?;
        let fields = header_fields(header)
            .map_err(|problem| format!("the record at byte {offset}: {problem}"))?;
        Ok(Self {
            offset,
            fields,
            data,
            end: at,
        })
    }

    fn field(&self, name: &str) -> std::result::Result<&'a [u8], String> {
        self.fields
            .iter()
            .find(|(key, _)| *key == name.as_bytes())
            .map(|(_, value)| *value)
            .ok_or_else(|| {
                format!(
                    "the record at byte {} has no `{name}` header field",
                    self.offset
                )
            })
    }

    pub(crate) fn op(&self) -> std::result::Result<u8, String> {
        match self.field("op")? {
            [op] => Ok(*op),
            other => Err(format!(
                "the record at byte {} has an `op` of {} bytes, not 1",
                self.offset,
                other.len()
            )),
        }
    }

    /// A little-endian field of exactly `N` bytes.
    fn bytes<const N: usize>(&self, name: &str) -> std::result::Result<[u8; N], String> {
        let value = self.field(name)?;
        value.try_into().map_err(|_| {
            format!(
                "the record at byte {}: `{name}` has {} bytes, not {N}",
                self.offset,
                value.len()
            )
        })
    }

    pub(crate) fn u32(&self, name: &str) -> std::result::Result<u32, String> {
        self.bytes(name).map(u32::from_le_bytes)
    }

    pub(crate) fn u64(&self, name: &str) -> std::result::Result<u64, String> {
        self.bytes(name).map(u64::from_le_bytes)
    }

    fn text(&self, name: &str) -> std::result::Result<String, String> {
        Ok(String::from_utf8_lossy(self.field(name)?).into_owned())
    }
}

fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let four = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(four.try_into().ok()?))
}

/// `name=value` fields, each after its `uint32` length.
fn header_fields(mut header: &[u8]) -> std::result::Result<Vec<Field<'_>>, String> {
    let mut fields = Vec::new();
    while !header.is_empty() {
        let length = read_u32(header, 0)
            .ok_or("a header field length is cut off")?
            .try_into()
            .unwrap_or(usize::MAX);
        let field = header
            .get(4..)
            .and_then(|rest| rest.get(..length))
            .ok_or_else(|| {
                format!(
                    "a header field claims {length} bytes, {} are left",
                    header.len() - 4
                )
            })?;
        let split = field
            .iter()
            .position(|b| *b == b'=')
            .ok_or("a header field has no `=`")?;
        fields.push((&field[..split], &field[split + 1..]));
        header = &header[4 + length..];
    }
    Ok(fields)
}

/// A connection record: `conn` and `topic` in its header, the rest in its data.
pub(crate) fn connection(record: &Record) -> std::result::Result<(u32, Connection), String> {
    let id = record.u32("conn")?;
    let details = Record {
        offset: record.offset,
        fields: header_fields(record.data)
            .map_err(|problem| format!("the connection at byte {}: {problem}", record.offset))?,
        data: &[],
        end: record.end,
    };
    let connection = Connection {
        topic: record.text("topic")?,
        schema_name: details.text("type")?,
        schema_encoding: "ros1msg".into(),
        schema_data: details
            .field("message_definition")
            .unwrap_or_default()
            .to_vec(),
        message_encoding: "ros1".into(),
    };
    Ok((id, connection))
}

/// An opened bag: where its chunks are and the connections its index lists.
pub struct BagFile {
    path: PathBuf,
    /// Its pages given back once a chunk is read (see [`FileMap`]).
    map: FileMap,
    /// Where each chunk starts, and its messages' log times when the index says.
    chunks: Vec<(usize, Option<(u64, u64)>)>,
    connections: HashMap<u32, Arc<Connection>>,
    notice: Option<String>,
}

impl BagFile {
    pub fn open(path: &Path) -> Result<Self> {
        let map = FileMap::open(path)?;
        let container = |problem: String| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        };
        if !map.as_ref().starts_with(BAG_MAGIC) {
            return Err(container("not a ROS 1 bag of format 2.0".into()));
        }
        let header = Record::at(map.as_ref(), BAG_MAGIC.len()).map_err(container)?;
        if header.op().map_err(container)? != op::BAG_HEADER {
            return Err(container(format!(
                "the first record (byte {}) is not the bag header",
                BAG_MAGIC.len()
            )));
        }
        let index_pos = header.u64("index_pos").map_err(container)?;
        let chunk_count = header.u32("chunk_count").map_err(container)? as usize;
        let header_end = header.end;
        let mut bag = Self {
            path: path.to_path_buf(),
            chunks: Vec::new(),
            connections: HashMap::new(),
            notice: None,
            map,
        };
        if index_pos == 0 {
            bag.scan(header_end).map_err(container)?;
            return Ok(bag);
        }
        let index_pos = usize::try_from(index_pos)
            .ok()
            .filter(|pos| *pos >= header_end && *pos <= bag.map.as_ref().len())
            .ok_or_else(|| {
                container(format!(
                    "its index should start at byte {index_pos} but the file ends at byte {}: the bag was cut off (copy it again, or run `rosbag reindex` on a copy)",
                    bag.map.as_ref().len()
                ))
            })?;
        bag.read_index(index_pos).map_err(|problem| {
            container(format!(
                "its index (from byte {index_pos}) is damaged or cut off: {problem}"
            ))
        })?;
        if bag.chunks.len() != chunk_count {
            return Err(container(format!(
                "its header counts {chunk_count} chunks but its index lists {}",
                bag.chunks.len()
            )));
        }
        Ok(bag)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Said when the bag could not be read as written (no index).
    pub fn notice(&self) -> Option<&str> {
        self.notice.as_deref()
    }

    /// Connections and chunk positions from the index section at `index_pos`.
    fn read_index(&mut self, index_pos: usize) -> std::result::Result<(), String> {
        let mut offset = index_pos;
        while offset < self.map.as_ref().len() {
            let record = Record::at(self.map.as_ref(), offset)?;
            match record.op()? {
                op::CONNECTION => {
                    let (id, connection) = connection(&record)?;
                    self.connections.insert(id, Arc::new(connection));
                }
                op::CHUNK_INFO => {
                    let position = record.u64("chunk_pos")?;
                    let position = usize::try_from(position)
                        .ok()
                        .filter(|p| *p < index_pos)
                        .ok_or_else(|| {
                            format!(
                                "the chunk info at byte {offset} places a chunk at byte {position}, outside the data before the index"
                            )
                        })?;
                    let times = (record.u64("start_time")?, record.u64("end_time")?);
                    self.chunks
                        .push((position, Some((stamp_ns(times.0), stamp_ns(times.1)))));
                }
                _ => {}
            }
            offset = record.end;
        }
        self.chunks.sort_unstable_by_key(|&(position, _)| position);
        Ok(())
    }

    /// Chunk positions by walking every record after the bag header, for a bag
    /// without an index; an incomplete last record is left out, and said.
    fn scan(&mut self, start: usize) -> std::result::Result<(), String> {
        let mut offset = start;
        while offset < self.map.as_ref().len() {
            let record = match Record::at(self.map.as_ref(), offset) {
                Ok(record) => record,
                Err(problem) => {
                    self.notice = Some(format!(
                        "{}: the bag has no index (its recording was cut off?): read by a linear scan, which left out the last {} bytes ({problem})",
                        self.path.display(),
                        self.map.as_ref().len() - offset
                    ));
                    return Ok(());
                }
            };
            if record.op()? == op::CHUNK {
                self.chunks.push((offset, None));
            }
            offset = record.end;
        }
        self.notice = Some(format!(
            "{}: the bag has no index (its recording was cut off?): read by a linear scan",
            self.path.display()
        ));
        Ok(())
    }

    /// The connections the index lists (an unindexed bag's come with its chunks).
    pub(crate) fn connections(&self) -> &HashMap<u32, Arc<Connection>> {
        &self.connections
    }

    /// Where each chunk starts, and its messages' log times when the index says.
    pub(crate) fn chunks(&self) -> &[(usize, Option<(u64, u64)>)] {
        &self.chunks
    }

    /// The records of the chunk at `offset`, decompressed into `out`.
    pub(crate) fn chunk(
        &self,
        offset: usize,
        out: &mut Vec<u8>,
    ) -> std::result::Result<(), String> {
        let record = Record::at(self.map.as_ref(), offset)?;
        if record.op()? != op::CHUNK {
            return Err(format!("the record at byte {offset} is not a chunk"));
        }
        let compression = record.text("compression")?;
        let size = record.u32("size")? as usize;
        if size > LARGEST_CHUNK {
            return Err(format!(
                "the chunk at byte {offset} claims {size} bytes decompressed, more than the {LARGEST_CHUNK} travmap reads"
            ));
        }
        out.clear();
        let limit = size as u64 + 1;
        let read = match compression.as_str() {
            "none" => {
                out.extend_from_slice(record.data);
                Ok(out.len())
            }
            "bz2" => bzip2::read::BzDecoder::new(record.data)
                .take(limit)
                .read_to_end(out),
            "lz4" => lz4::Decoder::new(record.data)
                .and_then(|decoder| decoder.take(limit).read_to_end(out)),
            other => {
                return Err(format!(
                    "the chunk at byte {offset} is compressed with `{other}`; ROS 1 bags use none, bz2 or lz4"
                ));
            }
        };
        // Its records are copied out: the file's pages may leave the resident set.
        self.map.release(offset..record.end);
        match read {
            Ok(n) if n == size => Ok(()),
            Ok(n) => Err(format!(
                "the chunk at byte {offset} decompresses to {}{n} bytes but claims {size}",
                if n > size { "more than " } else { "" }
            )),
            Err(e) => Err(format!(
                "the {compression} chunk at byte {offset} does not decompress: {e}"
            )),
        }
    }
}

/// A bag's `time` (uint32 seconds, then uint32 nanoseconds) in nanoseconds.
pub(crate) fn stamp_ns(time: u64) -> u64 {
    (time & 0xffff_ffff) * 1_000_000_000 + (time >> 32)
}
