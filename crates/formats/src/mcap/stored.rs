//! An MCAP file's chunks as stored, for copying them into another file without
//! decompressing them (`annotate` and `convert` pass an input through this way).
//! Lengths are checked by the record walk of [`crate::mcap::records`].

use std::ops::Range;

use bytes::Bytes;
use mcap::records::{Record, op};

use crate::foxglove;
use crate::log_message::FileMap;
use crate::mcap::records::{RecordWalk, check_lengths, chunk_parts};
use crate::ros::MessageEncoding;

/// One channel's part of a stored chunk.
pub struct StoredChannel {
    pub id: u16,
    /// Where its message index record starts, from the end of the chunk record.
    pub index_offset: u64,
    pub messages: u64,
}

/// Gives a stored chunk's pages back to the page cache ([`FileMap::release`]) once
/// it has been copied.
pub struct Release(pub FileMap, pub Range<usize>);

impl Release {
    pub fn run(self) {
        self.0.release(self.1);
    }
}

/// A chunk of an MCAP file as stored, with the message index records after it:
/// what a writer needs to copy it without decompressing it. The bytes are slices of
/// the file's memory map, not copies.
pub struct StoredChunk {
    /// Where the chunk record starts in the file.
    pub offset: usize,
    /// For a memory-mapped file.
    pub release: Option<Release>,
    /// The whole chunk record, opcode and length included.
    pub record: Bytes,
    pub message_indexes: Bytes,
    /// Log time range of its messages (None: it holds none).
    pub time_ns: Option<(u64, u64)>,
    pub compression: String,
    pub compressed_bytes: u64,
    pub uncompressed_bytes: u64,
    pub channels: Vec<StoredChannel>,
}

/// The chunks of an MCAP file and the schemas and channels their messages use.
#[derive(Default)]
pub struct StoredLog {
    /// Each schema's header and data.
    pub schemas: Vec<(mcap::records::SchemaHeader, Vec<u8>)>,
    pub channels: Vec<mcap::records::Channel>,
    pub chunks: Vec<StoredChunk>,
}

impl StoredLog {
    pub fn messages(&self) -> u64 {
        let chunks = self.chunks.iter().flat_map(|chunk| &chunk.channels);
        chunks.map(|channel| channel.messages).sum()
    }

    /// Whether some channel holds messages that are read as ROS 2 only once
    /// re-encoded: ROS 1's, or a Foxglove schema that stands for a ROS type. Without
    /// one, the chunks can be copied as stored.
    pub fn needs_translation(&self) -> bool {
        let schema_name = |id| self.schemas.iter().find(|(s, _)| s.id == id);
        let translated = |c: &mcap::records::Channel| match c.message_encoding.as_str() {
            encoding if foxglove::reads(encoding) => schema_name(c.schema_id)
                .is_some_and(|(s, _)| foxglove::ros_equivalent(&s.name).is_some()),
            encoding => MessageEncoding::from_name(encoding) == Some(MessageEncoding::Ros1),
        };
        self.channels.iter().any(translated)
    }

    /// Collects a schema or channel record (once per id: the summary repeats them).
    fn declare(&mut self, opcode: u8, body: &[u8]) -> Option<()> {
        check_lengths(opcode, body).ok()?;
        match mcap::parse_record(opcode, body).ok()? {
            Record::Schema { header, data }
                if !self.schemas.iter().any(|(known, _)| known.id == header.id) =>
            {
                self.schemas.push((header, data.into_owned()));
            }
            Record::Channel(channel) if !self.channels.iter().any(|k| k.id == channel.id) => {
                self.channels.push(channel);
            }
            _ => {}
        }
        Some(())
    }

    /// Whether every chunk's channels, and their schemas, are declared.
    fn declares_all(&self) -> bool {
        let mut used = self.chunks.iter().flat_map(|chunk| &chunk.channels);
        used.all(|used| {
            self.channels.iter().any(|channel| {
                channel.id == used.id
                    && (channel.schema_id == 0
                        || self.schemas.iter().any(|(s, _)| s.id == channel.schema_id))
            })
        })
    }
}

/// A message index record's channel and message count.
fn message_index(body: &[u8]) -> Option<(u16, u64)> {
    let id = u16::from_le_bytes(body.get(0..2)?.try_into().ok()?);
    let entries = u32::from_le_bytes(body.get(2..6)?.try_into().ok()?) as usize;
    (entries == body.len() - 6 && entries.is_multiple_of(16)).then_some((id, entries as u64 / 16))
}

/// The file's chunks as stored, when they hold every message and their message
/// indexes say which: None for a file with messages outside chunks, a chunk
/// without message indexes, or a channel that neither the data section nor the
/// summary declares. Lengths are checked as `check_chunk_sizes` does.
pub fn stored_log(map: &Bytes) -> Option<StoredLog> {
    let mut log = StoredLog::default();
    // Where the message index records after the last chunk start; None once another
    // record came between.
    let mut indexes_start = None;
    for record in (RecordWalk {
        bytes: map,
        offset: 8,
    }) {
        let (offset, opcode, body) = record.ok()?;
        let end = offset + 9 + body.len();
        match (opcode, indexes_start) {
            (op::DATA_END, _) => break,
            (op::MESSAGE, _) => return None,
            (op::SCHEMA | op::CHANNEL, _) => log.declare(opcode, body)?,
            (op::CHUNK, _) => {
                let (declared, compression, records) = chunk_parts(body)?;
                let time =
                    |at: usize| Some(u64::from_le_bytes(body.get(at..at + 8)?.try_into().ok()?));
                log.chunks.push(StoredChunk {
                    offset,
                    release: None,
                    record: map.slice(offset..end),
                    message_indexes: Bytes::new(),
                    time_ns: Some((time(0)?, time(8)?)),
                    compression: compression.to_string(),
                    compressed_bytes: records.len() as u64,
                    uncompressed_bytes: declared,
                    channels: Vec::new(),
                });
                indexes_start = Some(end);
                continue;
            }
            (op::MESSAGE_INDEX, Some(start)) => {
                let (id, messages) = message_index(body)?;
                let chunk = log.chunks.last_mut()?;
                chunk.channels.push(StoredChannel {
                    id,
                    index_offset: (offset - start) as u64,
                    messages,
                });
                chunk.message_indexes = map.slice(start..end);
                continue;
            }
            (op::MESSAGE_INDEX, None) => return None,
            _ => {}
        }
        indexes_start = None;
    }
    if log.chunks.iter().any(|chunk| chunk.channels.is_empty()) {
        return None;
    }
    for chunk in &mut log.chunks {
        if chunk.channels.iter().all(|channel| channel.messages == 0) {
            chunk.time_ns = None;
        }
    }
    // The footer (29 bytes before the closing magic) says where the summary starts.
    let footer = map.len().checked_sub(37)?;
    let summary_start = u64::from_le_bytes(map.get(footer + 9..footer + 17)?.try_into().ok()?);
    if summary_start != 0 {
        let summary = map.get(usize::try_from(summary_start).ok()?..footer)?;
        for record in (RecordWalk {
            bytes: summary,
            offset: 0,
        }) {
            let (_, opcode, body) = record.ok()?;
            if matches!(opcode, op::SCHEMA | op::CHANNEL) {
                log.declare(opcode, body)?;
            }
        }
    }
    log.declares_all().then_some(log)
}
