//! The message pass over an MCAP file: its records walked in place in the memory
//! map, every length checked before a record is parsed ([`check_lengths`]), the
//! chunks decompressed a batch at a time on as many threads as the pass may use,
//! and a damaged chunk stepped over rather than the end of the file.

use std::borrow::Cow;
use std::collections::VecDeque;
use std::io::Read;

use mcap::records::{Record, op};
use mcap::{McapError, Message};

use crate::log_message::{ChunkSpan, Damage, FileMap, Part, Parts, in_parallel, part_of};
use crate::mcap::records::{RecordWalk, check_lengths, chunk_parts, chunk_span, summary_start};

/// Bytes a pass reads before it gives the pages behind it back.
const RELEASE_BYTES: usize = 32 << 20;
/// Records outside chunks queued at most before they are read (an unchunked file).
const RECORDS_PER_BATCH: usize = 1024;
/// Stored (uncompressed) chunks a batch holds at most beside its compressed ones:
/// they are read in place, but a file of nothing else (rosbag2's MCAP) must not be
/// walked, its pages read, in one batch.
const STORED_PER_BATCH: usize = 8;
const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// The messages of `file` in file order, linked to their channels.
pub struct Messages<'a> {
    walk: RecordWalk<'a>,
    /// The map `file` is, if it is one, and how far its pages were given back.
    map: Option<&'a FileMap>,
    released: usize,
    /// The batch being read: records walked, chunks decompressed.
    batch: VecDeque<Pending<'a>>,
    /// Chunks per batch, each decompressed on its own thread.
    threads: usize,
    /// Buffers of chunks read, for the next ones: no allocation per chunk.
    spare: Vec<Vec<u8>>,
    channels: mcap::read::ChannelAccumulator<'static>,
    /// How much of each message to copy (all of every one without).
    parts: Option<Parts<'a>>,
    /// The data section's end, or the file's, was reached.
    walked: bool,
    done: bool,
    /// Damaged stretches stepped over, in file order, each with why
    /// ([`crate::mcap::records::Layout::damaged`]).
    damaged: VecDeque<(ChunkSpan, String)>,
}

enum Pending<'a> {
    Record {
        opcode: u8,
        body: &'a [u8],
    },
    /// A chunk's records (or why they cannot be read, and the buffer that was to
    /// hold them), read on from `at`.
    Chunk {
        span: ChunkSpan,
        records: Result<Cow<'a, [u8]>, (String, Vec<u8>)>,
        at: usize,
    },
    /// Nothing can be read past this.
    End(String),
}

impl<'a> Messages<'a> {
    /// The messages of `file`: its data section, or for a cut file the complete
    /// records `file` holds, its declared chunk sizes checked as
    /// [`crate::mcap::records::check_chunk_sizes`] does; up to `threads` chunks
    /// decompressed at once; of each message, the [`Part`] `parts` says.
    pub fn new(
        file: &'a [u8],
        map: Option<&'a FileMap>,
        threads: usize,
        parts: Option<Parts<'a>>,
    ) -> Self {
        let mut batch = VecDeque::new();
        if !file.starts_with(MAGIC) {
            batch.push_back(Pending::End(McapError::BadMagic.to_string()));
        }
        Self {
            walk: RecordWalk {
                bytes: file,
                offset: MAGIC.len(),
            },
            map,
            released: 0,
            walked: !batch.is_empty(),
            batch,
            threads: threads.max(1),
            spare: Vec::new(),
            channels: Default::default(),
            parts,
            done: false,
            damaged: VecDeque::new(),
        }
    }

    /// These messages, the `damaged` stretches stepped over: each is a damaged chunk
    /// whose messages are lost, read on after it.
    /// The summary's schemas and channels are read first, so that messages after a
    /// damaged chunk that held their channel still read, the first chunk among
    /// them (damage found only as it is read, a bad CRC, included).
    pub fn stepping_over(mut self, damaged: Vec<(ChunkSpan, String)>) -> Self {
        let whole = self.walk.bytes.ends_with(MAGIC);
        if let Some(summary) = summary_start(self.walk.bytes).filter(|_| whole) {
            let walk = RecordWalk {
                bytes: self.walk.bytes,
                offset: summary,
            };
            let definitions = walk
                .map_while(Result::ok)
                .filter(|(_, opcode, _)| matches!(*opcode, op::SCHEMA | op::CHANNEL));
            for (_, opcode, body) in definitions {
                self.batch.push_back(Pending::Record { opcode, body });
            }
        }
        self.damaged = damaged.into();
        self
    }

    /// Walks the next records up to `threads` chunks, and decompresses those.
    fn fill(&mut self) {
        if let Some(map) = self.map
            && self.walk.offset - self.released >= RELEASE_BYTES
        {
            map.release(self.released..self.walk.offset);
            self.released = self.walk.offset;
        }
        // Compressed chunks, and where they wait in the batch; stored ones are read
        // in place. Stored chunks do not take a compressed one's place: where they
        // alternate (images beside clouds, as travmap writes them), a batch would
        // hold one chunk to decompress, and decompress them one at a time.
        let (mut chunks, mut waiting, mut stored_chunks) = (Vec::new(), Vec::new(), 0);
        while !self.walked
            && chunks.len() < self.threads
            && stored_chunks < STORED_PER_BATCH
            && self.batch.len() < RECORDS_PER_BATCH
        {
            if let Some((span, _)) = self.damaged.front()
                && span.bytes.start <= self.walk.offset
            {
                let (span, problem) = self.damaged.pop_front().expect("the front");
                self.walk.offset = self.walk.offset.max(span.bytes.end);
                self.batch.push_back(Pending::Chunk {
                    span,
                    records: Err((problem, Vec::new())),
                    at: 0,
                });
                continue;
            }
            match self.walk.next() {
                // A cut file's readable part ends with its last complete record.
                None => self.walked = true,
                Some(Err(overrun)) => {
                    self.walked = true;
                    self.batch.push_back(Pending::End(format!(
                        "the record at byte {} (opcode {:#04x}) claims {} bytes, {} are left",
                        overrun.offset, overrun.opcode, overrun.length, overrun.available
                    )));
                }
                // After the data section the summary repeats schemas and channels.
                Some(Ok((_, op::DATA_END, _))) => self.walked = true,
                Some(Ok((offset, op::CHUNK, body))) => {
                    let stored = chunk_parts(body).is_some_and(|(_, c, _)| c.is_empty());
                    let records = if stored {
                        stored_chunks += 1;
                        chunk_records(body, Vec::new())
                    } else {
                        waiting.push(self.batch.len());
                        chunks.push((body, self.spare.pop().unwrap_or_default()));
                        Ok(Cow::Borrowed(body))
                    };
                    self.batch.push_back(Pending::Chunk {
                        span: chunk_span(offset..self.walk.offset, body),
                        records,
                        at: 0,
                    });
                }
                Some(Ok((_, opcode, body))) => {
                    self.batch.push_back(Pending::Record { opcode, body })
                }
            }
        }
        let decompressed = in_parallel(chunks, |(body, buffer)| chunk_records(body, buffer));
        for (at, decompressed) in waiting.into_iter().zip(decompressed) {
            if let Some(Pending::Chunk { records, .. }) = self.batch.get_mut(at) {
                *records = decompressed;
            }
        }
    }

    /// The next message, or why none could be read.
    fn next_message(&mut self) -> Option<Result<Message<'static>, Damage>> {
        loop {
            if self.batch.is_empty() {
                if self.walked {
                    return None;
                }
                self.fill();
                continue;
            }
            let read = match self.batch.pop_front()? {
                Pending::Record { opcode, body } => {
                    self.record(opcode, body).map_err(|problem| Damage {
                        problem,
                        chunk: None,
                    })
                }
                Pending::End(problem) => Err(Damage {
                    problem,
                    chunk: None,
                }),
                Pending::Chunk {
                    span,
                    records: Err((problem, buffer)),
                    ..
                } => {
                    self.spare.push(buffer);
                    Err(Damage {
                        problem,
                        chunk: Some(self.with_lost(span, 0)),
                    })
                }
                Pending::Chunk {
                    span,
                    records: Ok(records),
                    at,
                } => {
                    let mut walk = RecordWalk {
                        bytes: &records,
                        offset: at,
                    };
                    let read = match walk.next() {
                        None if at == records.len() => {
                            if let Cow::Owned(buffer) = records {
                                self.spare.push(buffer);
                            }
                            continue;
                        }
                        None => Err(McapError::UnexpectedEoc.to_string()),
                        Some(Err(overrun)) => Err(format!(
                            "its record at {} (opcode {:#04x}) claims {} bytes, but {} are left in the chunk",
                            overrun.offset, overrun.opcode, overrun.length, overrun.available
                        )),
                        Some(Ok((_, opcode, body))) => self.record(opcode, body),
                    };
                    match read {
                        Ok(message) => {
                            let at = walk.offset;
                            self.batch.push_front(Pending::Chunk {
                                span,
                                records: Ok(records),
                                at,
                            });
                            Ok(message)
                        }
                        Err(problem) => {
                            if let Cow::Owned(buffer) = records {
                                self.spare.push(buffer);
                            }
                            Err(Damage {
                                problem,
                                chunk: Some(self.with_lost(span, at)),
                            })
                        }
                    }
                }
            };
            match read {
                Ok(None) => continue,
                Ok(Some(message)) => return Some(Ok(message)),
                Err(damage) => return Some(Err(damage)),
            }
        }
    }

    /// `span` with the messages it loses from byte `from` of its records on, as the
    /// message index records after the chunk list them: topic and log time, in log
    /// order (none where the file has no index after the chunk).
    fn with_lost(&self, mut span: ChunkSpan, from: usize) -> ChunkSpan {
        let walk = RecordWalk {
            bytes: self.walk.bytes,
            offset: span.bytes.end,
        };
        let indexes = walk
            .map_while(Result::ok)
            .take_while(|(_, opcode, _)| *opcode == op::MESSAGE_INDEX)
            .filter(|(_, _, body)| check_lengths(op::MESSAGE_INDEX, body).is_ok());
        for (_, _, body) in indexes {
            let channel = u16::from_le_bytes([body[0], body[1]]);
            let Some(topic) = self.channels.get(channel).map(|c| c.topic.clone()) else {
                continue;
            };
            // Entries of (log time, offset in the chunk's records), 16 bytes each.
            for entry in body[6..].chunks_exact(16) {
                let word = |at: usize| {
                    u64::from_le_bytes(entry[at..at + 8].try_into().unwrap_or_default())
                };
                if word(8) >= from as u64 {
                    span.lost.push((topic.clone(), word(0)));
                }
            }
        }
        span.lost.sort_by_key(|(_, log_time_ns)| *log_time_ns);
        span
    }

    /// Reads one record: a message is returned, a schema or channel remembered.
    fn record(&mut self, opcode: u8, body: &[u8]) -> Result<Option<Message<'static>>, String> {
        check_lengths(opcode, body)?;
        let added = match mcap::parse_record(opcode, body).map_err(|e| e.to_string())? {
            Record::Schema { header, data } => self.channels.add_schema_from_slice(header, &data),
            Record::Channel(channel) => self.channels.add_channel(channel),
            Record::Message { header, data } => {
                let Some(channel) = self.channels.get(header.channel_id) else {
                    let error = McapError::UnknownChannel(header.sequence, header.channel_id);
                    return Err(error.to_string());
                };
                let schema = channel.schema.as_ref().map_or("", |schema| &schema.name);
                let data = match self
                    .parts
                    .as_ref()
                    .map(|parts| parts(&channel.topic, schema))
                {
                    None | Some(Part::Whole) => data.into_owned(),
                    Some(part) => part_of(&data, part),
                };
                return Ok(Some(Message {
                    channel,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: Cow::Owned(data),
                }));
            }
            _ => Ok(()),
        };
        added.map(|()| None).map_err(|e| e.to_string())
    }
}

/// A chunk's records: decompressed into `buffer` to the size the chunk declares,
/// checked against its CRC (when it has one) before any of them is read.
fn chunk_records(body: &[u8], mut buffer: Vec<u8>) -> Result<Cow<'_, [u8]>, (String, Vec<u8>)> {
    let Some((declared, compression, data)) = chunk_parts(body) else {
        return Err(("its header ends before its records do".into(), buffer));
    };
    let declared = usize::try_from(declared).unwrap_or(usize::MAX);
    buffer.clear();
    let decompressed = match compression {
        "" => Ok(()),
        "zstd" => buffer
            .try_reserve_exact(declared)
            .map_err(|e| e.to_string())
            .and_then(|()| {
                zstd::bulk::Decompressor::new()
                    .and_then(|mut zstd| zstd.decompress_to_buffer(data, &mut buffer))
                    .map_err(|e| McapError::DecompressionError(e.to_string()).to_string())
            })
            .map(|_| ()),
        "lz4" => lz4::Decoder::new(data)
            .and_then(|decoder| decoder.take(declared as u64 + 1).read_to_end(&mut buffer))
            .map(|_| ())
            .map_err(|e| McapError::DecompressionError(e.to_string()).to_string()),
        other => Err(McapError::UnsupportedCompression(other.to_string()).to_string()),
    };
    if let Err(problem) = decompressed {
        return Err((problem, buffer));
    }
    let records = match compression {
        "" => Cow::Borrowed(data),
        _ => Cow::Owned(buffer),
    };
    let problem = if records.len() != declared {
        format!(
            "its records are {} bytes uncompressed, it declares {declared}",
            records.len()
        )
    } else {
        let saved = u32::from_le_bytes(body[24..28].try_into().expect("chunk_parts read past it"));
        let calculated = crc32fast::hash(&records);
        if saved == 0 || saved == calculated {
            return Ok(records);
        }
        McapError::BadChunkCrc { saved, calculated }.to_string()
    };
    let buffer = match records {
        Cow::Owned(buffer) => buffer,
        Cow::Borrowed(_) => Vec::new(),
    };
    Err((problem, buffer))
}

impl Iterator for Messages<'_> {
    type Item = Result<Message<'static>, Damage>;

    /// Nothing after an error outside a chunk; after a damaged chunk, the messages
    /// that follow it.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let message = self.next_message()?;
        self.done = matches!(&message, Err(Damage { chunk: None, .. }));
        Some(message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log_message::HEADER_BYTES;
    use crate::mcap::records::blob_file;

    /// An MCAP of `n` messages (payload: their index, 4 KiB of it) in chunks of
    /// about 16 KiB.
    fn chunked_file(n: u32, compression: Option<mcap::Compression>) -> Vec<u8> {
        let payloads: Vec<Vec<u8>> = (0..n)
            .map(|i| i.to_le_bytes().iter().copied().cycle().take(4096).collect())
            .collect();
        let payloads: Vec<&[u8]> = payloads.iter().map(Vec::as_slice).collect();
        blob_file(&payloads, compression, Some(16 << 10))
    }

    /// Each message's sequence number, or the damaged chunk's first byte.
    fn read(file: &[u8], threads: usize) -> Vec<Result<u32, usize>> {
        Messages::new(file, None, threads, None)
            .map(|message| match message {
                Ok(message) => {
                    let sequence = message.sequence.to_le_bytes();
                    assert!(message.data.chunks(4).all(|w| w == sequence));
                    Ok(message.sequence)
                }
                Err(damage) => Err(damage.chunk.expect("a chunk's damage").bytes.start),
            })
            .collect()
    }

    #[test]
    fn chunks_decompressed_together_read_as_one_at_a_time() {
        for compression in [
            Some(mcap::Compression::Zstd),
            Some(mcap::Compression::Lz4),
            None,
        ] {
            let file = chunked_file(100, compression);
            let one = read(&file, 1);
            assert_eq!(one, (0..100).map(Ok).collect::<Vec<_>>());
            assert_eq!(read(&file, 3), one);
        }
    }

    /// The records of `file` as (opcode, whole record), in file order.
    fn records(file: &[u8]) -> Vec<(u8, &[u8])> {
        let walk = RecordWalk {
            bytes: file,
            offset: MAGIC.len(),
        };
        (walk.map(Result::unwrap))
            .map(|(offset, opcode, body)| (opcode, &file[offset..offset + 9 + body.len()]))
            .collect()
    }

    #[test]
    fn stored_chunks_between_compressed_ones_leave_a_batch_its_compressed_chunks() {
        // Every other chunk stored, as travmap writes images beside clouds: the
        // same chunk boundaries in both files, so the messages stay in order.
        let compressed = chunked_file(100, Some(mcap::Compression::Zstd));
        let stored = chunked_file(100, None);
        let chunks_of = |file| -> Vec<&[u8]> {
            (records(file).into_iter())
                .filter(|(opcode, _)| *opcode == op::CHUNK)
                .map(|(_, record)| record)
                .collect()
        };
        let stored_chunks = chunks_of(&stored);
        let mut file = MAGIC.to_vec();
        let mut at = 0;
        for (opcode, record) in records(&compressed) {
            match (opcode, at % 2) {
                (op::CHUNK, 1) => file.extend_from_slice(stored_chunks[at]),
                _ => file.extend_from_slice(record),
            }
            at += usize::from(opcode == op::CHUNK);
        }
        file.extend_from_slice(MAGIC);
        assert!(at > 10, "{at}");
        let one = read(&file, 1);
        assert_eq!(one, (0..100).map(Ok).collect::<Vec<_>>());
        for threads in [2, 3] {
            assert_eq!(read(&file, threads), one);
            let mut messages = Messages::new(&file, None, threads, None);
            messages.fill();
            let decompressed = (messages.batch.iter())
                .filter(|p| {
                    matches!(
                        p,
                        Pending::Chunk {
                            records: Ok(Cow::Owned(_)),
                            ..
                        }
                    )
                })
                .count();
            assert_eq!(decompressed, threads);
        }
    }

    #[test]
    fn a_damaged_chunk_among_those_decompressed_together_is_stepped_over() {
        let mut file = chunked_file(100, Some(mcap::Compression::Zstd));
        let chunks: Vec<_> = RecordWalk {
            bytes: &file,
            offset: MAGIC.len(),
        }
        .map(Result::unwrap)
        .filter(|&(_, opcode, _)| opcode == op::CHUNK)
        .map(|(offset, _, body)| offset..offset + 9 + body.len())
        .collect();
        assert!(chunks.len() > 10, "{}", chunks.len());
        let damaged = chunks[4].clone();
        file[damaged.end - 100] ^= 0x55;
        for threads in [1, 2, 3] {
            let read = read(&file, threads);
            assert_eq!(read.iter().filter(|r| r.is_err()).count(), 1);
            assert!(read.contains(&Err(damaged.start)));
            // Every other chunk's messages are read, in order.
            let sequences: Vec<u32> = read.iter().filter_map(|r| r.ok()).collect();
            assert!(sequences.windows(2).all(|w| w[0] < w[1]));
            assert!(
                sequences.len() > 90 && sequences.len() < 100,
                "{}",
                sequences.len()
            );
            assert!(sequences.contains(&0) && sequences.contains(&99));
        }
    }

    #[test]
    fn messages_are_read_whole_to_their_headers_or_not_at_all_as_asked() {
        let large: Vec<u8> = (0..100_000u32).map(|i| i as u8).collect();
        let small = vec![7u8; 100];
        let file = blob_file(&[&large, &small], Some(mcap::Compression::Zstd), None);
        let lengths = |parts: Option<Parts>| -> Vec<usize> {
            Messages::new(&file, None, 2, parts)
                .map(|message| {
                    let data = message.unwrap().data;
                    let whole = if data.len() == small.len() {
                        &small
                    } else {
                        &large
                    };
                    assert_eq!(data[..], whole[..data.len()]);
                    data.len()
                })
                .collect()
        };
        assert_eq!(lengths(None), [100_000, 100]);
        let of_blobs = |part: Part| {
            move |_: &str, schema: &str| match schema {
                "blob" => part,
                _ => Part::Whole,
            }
        };
        let lengths_of_blobs = |part| lengths(Some(std::sync::Arc::new(of_blobs(part))));
        assert_eq!(lengths_of_blobs(Part::Whole), [100_000, 100]);
        assert_eq!(lengths_of_blobs(Part::Header), [HEADER_BYTES, 100]);
        assert_eq!(lengths_of_blobs(Part::Nothing), [0, 0]);
    }

    #[test]
    fn a_file_without_the_magic_is_refused() {
        let mut file = chunked_file(3, None);
        file[1] = b'X';
        let damage = Messages::new(&file, None, 1, None)
            .next()
            .unwrap()
            .unwrap_err();
        assert!(damage.chunk.is_none());
        assert!(
            damage.problem.to_lowercase().contains("magic"),
            "{}",
            damage.problem
        );
    }
}
