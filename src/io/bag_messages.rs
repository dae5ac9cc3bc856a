//! The messages of a ROS 1 bag ([`super::bag::BagFile`]), in file order: its chunks
//! decompressed a batch at a time on as many threads as the pass may use (a bz2
//! chunk decompresses at tens of MB/s), each message's records copied as far as
//! the pass asks.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use super::bag::{BagFile, Record, connection, op, stamp_ns};
use super::log_message::{ChunkSpan, Connection, Damage, LogMessage, Parts, in_parallel, part_of};

/// The messages of a bag, streamed chunk by chunk: see [`BagFile::messages`].
pub struct BagMessages<'a> {
    bag: &'a BagFile,
    connections: HashMap<u32, Arc<Connection>>,
    parts: Option<Parts<'a>>,
    threads: usize,
    /// Chunks decompressed ahead, in file order: each its index and its records, or
    /// why they cannot be read.
    ready: VecDeque<(usize, Result<Vec<u8>, String>)>,
    /// The next chunk to decompress, and the one being read.
    next_chunk: usize,
    current: usize,
    /// The current chunk's records and where the next one starts.
    chunk: Vec<u8>,
    at: usize,
    /// Buffers of chunks read, for the next ones.
    spare: Vec<Vec<u8>>,
    failed: bool,
}

impl<'a> BagMessages<'a> {
    pub(super) fn new(
        bag: &'a BagFile,
        connections: HashMap<u32, Arc<Connection>>,
        threads: usize,
        parts: Option<Parts<'a>>,
    ) -> Self {
        Self {
            bag,
            connections,
            parts,
            threads: threads.max(1),
            ready: VecDeque::new(),
            next_chunk: 0,
            current: 0,
            chunk: Vec::new(),
            at: 0,
            spare: Vec::new(),
            failed: false,
        }
    }

    /// Decompresses the next `threads` chunks, side by side.
    fn fill(&mut self) {
        let chunks = self.bag.chunks();
        let batch: Vec<(usize, Vec<u8>)> = (self.next_chunk..chunks.len())
            .take(self.threads)
            .map(|index| (index, self.spare.pop().unwrap_or_default()))
            .collect();
        self.next_chunk += batch.len();
        let bag = self.bag;
        let read = in_parallel(batch, |(index, mut records)| {
            let read = bag.chunk(chunks[index].0, &mut records);
            (index, read.map(|()| records))
        });
        self.ready.extend(read);
    }

    /// A chunk's damage: with its log times from the index, the rest of the chunk
    /// is lost and reading goes on after it; without, it is the end.
    fn damage(&mut self, problem: String) -> Damage {
        let (offset, times) = self.bag.chunks()[self.current];
        self.chunk.clear();
        Damage {
            problem,
            chunk: times.map(|(start_ns, end_ns)| ChunkSpan {
                bytes: offset..offset,
                start_ns,
                end_ns,
            }),
        }
    }

    fn next_message(&mut self) -> Option<std::result::Result<LogMessage, Damage>> {
        self.next_in_chunk()
            .map(|message| message.map_err(|problem| self.damage(problem)))
    }

    fn next_in_chunk(&mut self) -> Option<std::result::Result<LogMessage, String>> {
        loop {
            if self.at >= self.chunk.len() {
                if self.ready.is_empty() {
                    self.fill();
                }
                let (index, read) = self.ready.pop_front()?;
                self.current = index;
                self.at = 0;
                match read {
                    Ok(records) => {
                        let done = std::mem::replace(&mut self.chunk, records);
                        self.spare.push(done);
                    }
                    Err(problem) => return Some(Err(problem)),
                }
                continue;
            }
            let (chunk_offset, _) = self.bag.chunks()[self.current];
            let in_chunk =
                |problem: String| format!("in the chunk at byte {chunk_offset}, {problem}");
            let record = match Record::at(&self.chunk, self.at) {
                Ok(record) => record,
                Err(problem) => return Some(Err(in_chunk(problem))),
            };
            self.at = record.end;
            match record.op() {
                Ok(op::CONNECTION) => match connection(&record) {
                    Ok((id, connection)) => {
                        self.connections
                            .entry(id)
                            .or_insert_with(|| Arc::new(connection));
                    }
                    Err(problem) => return Some(Err(in_chunk(problem))),
                },
                Ok(op::MESSAGE_DATA) => return Some(self.message(&record).map_err(in_chunk)),
                Ok(_) => {}
                Err(problem) => return Some(Err(in_chunk(problem))),
            }
        }
    }

    fn message(&self, record: &Record) -> std::result::Result<LogMessage, String> {
        let id = record.u32("conn")?;
        let connection = self.connections.get(&id).ok_or_else(|| {
            format!(
                "the message at byte {} is on connection {id}, which no connection record defines",
                record.offset
            )
        })?;
        let stamp_ns = stamp_ns(record.u64("time")?);
        let data = match &self.parts {
            None => record.data.to_vec(),
            Some(parts) => part_of(
                record.data,
                parts(&connection.topic, &connection.schema_name),
            ),
        };
        Ok(LogMessage {
            connection: connection.clone(),
            log_time_ns: stamp_ns,
            publish_time_ns: stamp_ns,
            data,
        })
    }
}

impl Iterator for BagMessages<'_> {
    type Item = std::result::Result<LogMessage, Damage>;

    /// Nothing after the first error but a damaged chunk's (see [`Damage`]).
    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let next = self.next_message();
        self.failed = matches!(next, Some(Err(Damage { chunk: None, .. })));
        next
    }
}
