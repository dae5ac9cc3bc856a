//! The MCAP container as travmap writes it: records gathered into chunks, each
//! chunk compressed on a pool of threads and written in order, chunks of an input
//! copied as they are stored, and the summary that indexes them.
//!
//! Not the mcap crate's writer, for two reasons measured on `annotate`: it
//! compresses one chunk at a time on the thread that writes, and it cannot copy a
//! stored chunk, so passing an input through meant decompressing and compressing
//! every byte of it again.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::{self, Write};
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use bytes::Bytes;
use mcap::records::op;

use crate::io::mcap_stored::{Release, StoredChunk};
use crate::outputs::writing::Compression;

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// zstd level of `Compression::Zstd`: -1 (`zstd --fast=1`). By the README's
/// compression table, against level 1: about 1.3-1.5x the `convert` frames/s for
/// files 2.5 % (converted) to 4 % (annotated) larger on the six real frames; level 3,
/// the mcap crate's default, writes 10 % less for half the speed.
const ZSTD_LEVEL: i32 = -1;

/// Largest single write: one 8 MB write() took ten times as long per byte as 1 MB
/// ones here (measured with strace on `convert`: 6.2 ms against 0.09 ms a call).
const WRITE_BYTES: usize = 1 << 20;

/// Writes `opcode`, then the body `fields` put after it, then patches the length
/// in: one pass, no copy of the body.
fn put_record(out: &mut Vec<u8>, opcode: u8, fields: impl FnOnce(&mut Vec<u8>)) {
    out.push(opcode);
    let length_at = out.len();
    out.extend_from_slice(&[0; 8]);
    fields(out);
    let length = (out.len() - length_at - 8) as u64;
    out[length_at..length_at + 8].copy_from_slice(&length.to_le_bytes());
}

fn put_u16(out: &mut Vec<u8>, value: u16) {
    out.extend_from_slice(&value.to_le_bytes());
}

fn put_u32(out: &mut Vec<u8>, value: u32) {
    out.extend_from_slice(&value.to_le_bytes());
}

fn put_u64(out: &mut Vec<u8>, value: u64) {
    out.extend_from_slice(&value.to_le_bytes());
}

/// A string or byte array: u32 length, then the bytes.
fn put_bytes(out: &mut Vec<u8>, bytes: &[u8]) {
    put_u32(out, bytes.len() as u32);
    out.extend_from_slice(bytes);
}

/// A map or array: u32 byte length, then the entries `entries` puts.
fn put_sized(out: &mut Vec<u8>, entries: impl FnOnce(&mut Vec<u8>)) {
    let length_at = out.len();
    put_u32(out, 0);
    entries(out);
    let length = (out.len() - length_at - 4) as u32;
    out[length_at..length_at + 4].copy_from_slice(&length.to_le_bytes());
}

fn put_string_map(out: &mut Vec<u8>, map: &BTreeMap<String, String>) {
    put_sized(out, |out| {
        for (key, value) in map {
            put_bytes(out, key.as_bytes());
            put_bytes(out, value.as_bytes());
        }
    });
}

/// A schema record, as written in chunks and in the summary.
fn schema_record(id: u16, name: &str, encoding: &str, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len() + name.len() + 32);
    put_record(&mut out, op::SCHEMA, |out| {
        put_u16(out, id);
        put_bytes(out, name.as_bytes());
        put_bytes(out, encoding.as_bytes());
        put_bytes(out, data);
    });
    out
}

/// A channel record, as written in chunks and in the summary.
fn channel_record(channel: &mcap::records::Channel) -> Vec<u8> {
    let mut out = Vec::new();
    put_record(&mut out, op::CHANNEL, |out| {
        put_u16(out, channel.id);
        put_u16(out, channel.schema_id);
        put_bytes(out, channel.topic.as_bytes());
        put_bytes(out, channel.message_encoding.as_bytes());
        put_string_map(out, &channel.metadata);
    });
    out
}

/// Records gathered for a chunk, not yet compressed.
#[derive(Default)]
struct OpenChunk {
    records: Vec<u8>,
    /// Log time range of its messages (None: no message yet).
    time_ns: Option<(u64, u64)>,
    /// Per channel, the log time and offset in `records` of each of its messages.
    index: BTreeMap<u16, Vec<(u64, u64)>>,
}

/// One channel's part of a written chunk.
struct IndexedChannel {
    id: u16,
    /// Where its message index record starts, from the end of the chunk record.
    index_offset: u64,
    messages: u64,
}

/// Chunk-sized buffers for reuse. Fresh ones cost a page fault every 4 KB: in
/// `convert`, twice the system time of the mcap crate's writer, which reuses its own.
#[derive(Clone, Default)]
struct Buffers(Arc<Mutex<Vec<Vec<u8>>>>);

/// Buffers kept for reuse at most: the chunks in flight and the open ones.
const KEPT_BUFFERS: usize = 8;

impl Buffers {
    /// An empty buffer with room for `bytes`.
    fn take(&self, bytes: usize) -> Vec<u8> {
        let kept = self.0.lock().ok().and_then(|mut kept| kept.pop());
        let mut buffer = kept.unwrap_or_default();
        buffer.clear();
        buffer.reserve(bytes);
        buffer
    }

    fn give(&self, buffer: Vec<u8>) {
        if let Ok(mut kept) = self.0.lock()
            && kept.len() < KEPT_BUFFERS
        {
            kept.push(buffer);
        }
    }
}

/// A chunk record: built here, in a buffer to reuse, or copied from an input.
enum ChunkRecord {
    Built(Vec<u8>),
    Copied(Bytes),
}

impl ChunkRecord {
    fn bytes(&self) -> &[u8] {
        match self {
            ChunkRecord::Built(bytes) => bytes,
            ChunkRecord::Copied(bytes) => bytes,
        }
    }
}

/// A chunk ready to be written: its record and the message index records after it.
pub struct FinishedChunk {
    /// For a copied chunk: what gives its input's pages back once written.
    release: Option<Release>,
    record: ChunkRecord,
    message_indexes: Bytes,
    time_ns: Option<(u64, u64)>,
    compression: String,
    compressed_bytes: u64,
    uncompressed_bytes: u64,
    channels: Vec<IndexedChannel>,
}

impl FinishedChunk {
    /// A stored chunk of an input, copied as it is.
    pub fn copied(stored: &mut StoredChunk) -> Self {
        Self {
            release: stored.release.take(),
            record: ChunkRecord::Copied(stored.record.clone()),
            message_indexes: stored.message_indexes.clone(),
            time_ns: stored.time_ns,
            compression: stored.compression.clone(),
            compressed_bytes: stored.compressed_bytes,
            uncompressed_bytes: stored.uncompressed_bytes,
            channels: stored
                .channels
                .iter()
                .map(|c| IndexedChannel {
                    id: c.id,
                    index_offset: c.index_offset,
                    messages: c.messages,
                })
                .collect(),
        }
    }
}

/// `records` compressed with `compression`, appended to `out`.
fn compress_into(out: Vec<u8>, records: &[u8], compression: Compression) -> io::Result<Vec<u8>> {
    match compression {
        Compression::Zstd => {
            // One shot on the whole chunk: a stream encoder would copy it into its
            // window first and match across the copy (measured slower).
            let start = out.len();
            let mut out = io::Cursor::new(out);
            out.get_mut()
                .reserve(zstd::zstd_safe::compress_bound(records.len()));
            out.set_position(start as u64);
            zstd::bulk::Compressor::new(ZSTD_LEVEL)?.compress_to_buffer(records, &mut out)?;
            Ok(out.into_inner())
        }
        Compression::Lz4 => {
            let mut encoder = lz4::EncoderBuilder::new().build(out)?;
            encoder.write_all(records)?;
            let (out, result) = encoder.finish();
            result.map(|()| out)
        }
        Compression::None => {
            let mut out = out;
            out.extend_from_slice(records);
            Ok(out)
        }
    }
}

/// Compresses an open chunk into its chunk record and message index records.
fn finish_chunk(
    open: OpenChunk,
    compression: Compression,
    buffers: &Buffers,
) -> io::Result<FinishedChunk> {
    let name = compression.chunk_name();
    let (start_ns, end_ns) = open.time_ns.unwrap_or((0, 0));
    let bound = zstd::zstd_safe::compress_bound(open.records.len());
    let mut record = buffers.take(bound + 64);
    record.push(op::CHUNK);
    put_u64(&mut record, 0);
    put_u64(&mut record, start_ns);
    put_u64(&mut record, end_ns);
    put_u64(&mut record, open.records.len() as u64);
    put_u32(&mut record, crc32fast::hash(&open.records));
    put_bytes(&mut record, name.as_bytes());
    let size_at = record.len();
    put_u64(&mut record, 0);
    let mut record = compress_into(record, &open.records, compression)?;
    let compressed_bytes = (record.len() - size_at - 8) as u64;
    record[size_at..size_at + 8].copy_from_slice(&compressed_bytes.to_le_bytes());
    let length = (record.len() - 9) as u64;
    record[1..9].copy_from_slice(&length.to_le_bytes());

    let mut message_indexes = Vec::new();
    let mut channels = Vec::with_capacity(open.index.len());
    for (id, mut entries) in open.index {
        // Readers binary-search an index by time; within one time, file order.
        entries.sort_by_key(|&(log_time_ns, _)| log_time_ns);
        channels.push(IndexedChannel {
            id,
            index_offset: message_indexes.len() as u64,
            messages: entries.len() as u64,
        });
        put_record(&mut message_indexes, op::MESSAGE_INDEX, |out| {
            put_u16(out, id);
            put_sized(out, |out| {
                for (log_time_ns, offset) in entries {
                    put_u64(out, log_time_ns);
                    put_u64(out, offset);
                }
            });
        });
    }
    let uncompressed_bytes = open.records.len() as u64;
    buffers.give(open.records);
    Ok(FinishedChunk {
        release: None,
        record: ChunkRecord::Built(record),
        message_indexes: message_indexes.into(),
        time_ns: open.time_ns,
        compression: name.to_string(),
        compressed_bytes,
        uncompressed_bytes,
        channels,
    })
}

struct Job {
    chunk: OpenChunk,
    compression: Compression,
    done: Sender<io::Result<FinishedChunk>>,
}

/// Threads that compress chunks, as many as rayon's (RAYON_NUM_THREADS caps both).
/// Own threads, not rayon's pool: the thread that waits for a chunk may itself be
/// one of rayon's, and with one thread it would wait for itself.
struct Compressors {
    jobs: Option<Sender<Job>>,
    threads: Vec<JoinHandle<()>>,
}

impl Compressors {
    fn start(count: usize, buffers: &Buffers) -> io::Result<Self> {
        let (jobs, queue) = channel::<Job>();
        let queue = Arc::new(Mutex::new(queue));
        let threads = (0..count)
            .map(|i| {
                let queue = Arc::clone(&queue);
                let buffers = buffers.clone();
                std::thread::Builder::new()
                    .name(format!("mcap-compress-{i}"))
                    .spawn(move || {
                        loop {
                            // The lock is held only to take the next job.
                            let job = match queue.lock() {
                                Ok(queue) => queue.recv(),
                                Err(_) => return,
                            };
                            let Ok(job) = job else { return };
                            let finished = finish_chunk(job.chunk, job.compression, &buffers);
                            let _ = job.done.send(finished);
                        }
                    })
            })
            .collect::<io::Result<Vec<_>>>()?;
        Ok(Self {
            jobs: Some(jobs),
            threads,
        })
    }

    fn compress(
        &self,
        chunk: OpenChunk,
        compression: Compression,
    ) -> Receiver<io::Result<FinishedChunk>> {
        let (done, result) = channel();
        let job = Job {
            chunk,
            compression,
            done,
        };
        // A closed queue drops the job, and the receiver then reports it.
        if let Some(jobs) = &self.jobs {
            let _ = jobs.send(job);
        }
        result
    }
}

impl Drop for Compressors {
    fn drop(&mut self) {
        self.jobs = None;
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

/// What is due in the file, in order.
enum Due {
    Compressing(Receiver<io::Result<FinishedChunk>>),
    Chunk(FinishedChunk),
    /// A record outside chunks; with the name, a metadata record to index.
    Record(Vec<u8>, Option<String>),
}

/// An MCAP file being written to `out`; [`McapWriter::finish`] completes it.
pub struct McapWriter<W: Write> {
    out: W,
    position: u64,
    /// CRC of every byte before the DataEnd record.
    data_crc: crc32fast::Hasher,
    compression: Compression,
    compressors: Compressors,
    buffers: Buffers,
    /// A chunk is closed once its records reach this many bytes.
    chunk_bytes: usize,
    /// Chunks being compressed at most: bounds memory.
    in_flight_limit: usize,
    /// The chunk being gathered, and the one for channels whose payload is
    /// already compressed, which is stored uncompressed.
    open: [OpenChunk; 2],
    /// Channels whose messages go into the second chunk.
    precompressed: BTreeSet<u16>,
    due: VecDeque<Due>,
    /// Records for the summary, by id.
    schemas: BTreeMap<u16, Vec<u8>>,
    channels: BTreeMap<u16, (u16, Vec<u8>)>,
    /// Schemas and channels whose record the file already holds (or a chunk due).
    schemas_written: BTreeSet<u16>,
    channels_written: BTreeSet<u16>,
    chunk_indexes: Vec<u8>,
    metadata_indexes: Vec<u8>,
    chunks: u32,
    metadata: u32,
    message_counts: BTreeMap<u16, u64>,
    time_ns: Option<(u64, u64)>,
}

fn widen(range: Option<(u64, u64)>, with: (u64, u64)) -> Option<(u64, u64)> {
    Some(range.map_or(with, |(start, end)| (start.min(with.0), end.max(with.1))))
}

impl<W: Write> McapWriter<W> {
    /// Starts the file: magic and header (`profile`, `library`). Chunks of about
    /// `chunk_bytes` (uncompressed) are compressed on `threads` threads.
    pub fn new(
        out: W,
        profile: &str,
        library: &str,
        compression: Compression,
        chunk_bytes: usize,
        threads: usize,
    ) -> io::Result<Self> {
        let threads = threads.max(1);
        let buffers = Buffers::default();
        let mut writer = Self {
            out,
            position: 0,
            data_crc: crc32fast::Hasher::new(),
            compression,
            compressors: Compressors::start(threads, &buffers)?,
            buffers,
            chunk_bytes,
            in_flight_limit: threads + 1,
            open: Default::default(),
            precompressed: BTreeSet::new(),
            due: VecDeque::new(),
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            schemas_written: BTreeSet::new(),
            channels_written: BTreeSet::new(),
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            chunks: 0,
            metadata: 0,
            message_counts: BTreeMap::new(),
            time_ns: None,
        };
        let mut header = MAGIC.to_vec();
        put_record(&mut header, op::HEADER, |out| {
            put_bytes(out, profile.as_bytes());
            put_bytes(out, library.as_bytes());
        });
        writer.emit(&header)?;
        Ok(writer)
    }

    fn emit(&mut self, bytes: &[u8]) -> io::Result<()> {
        for piece in bytes.chunks(WRITE_BYTES) {
            self.out.write_all(piece)?;
        }
        self.data_crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    /// Declares a schema; its record goes into the file before its first channel's.
    pub fn add_schema(&mut self, id: u16, name: &str, encoding: &str, data: &[u8]) {
        self.schemas
            .insert(id, schema_record(id, name, encoding, data));
    }

    /// Declares a channel; its record goes into the file before its first message.
    /// The messages of one whose payload is already compressed (`precompressed`:
    /// images, video) go into chunks of their own, stored uncompressed.
    pub fn add_channel(&mut self, channel: &mcap::records::Channel, precompressed: bool) {
        self.channels
            .insert(channel.id, (channel.schema_id, channel_record(channel)));
        if precompressed {
            self.precompressed.insert(channel.id);
        }
    }

    /// Puts the records of channel `id` and its schema, unless the file has them, in
    /// open chunk `chunk`, or outside chunks (None).
    fn define(&mut self, id: u16, chunk: Option<usize>) -> io::Result<()> {
        if !self.channels_written.insert(id) {
            return Ok(());
        }
        let (schema_id, channel) = self.channels.get(&id).cloned().ok_or_else(|| {
            io::Error::other(format!("channel {id} was written before it was declared"))
        })?;
        let mut records = Vec::new();
        if schema_id != 0 && self.schemas_written.insert(schema_id) {
            let schema = self.schemas.get(&schema_id).ok_or_else(|| {
                io::Error::other(format!(
                    "schema {schema_id} of channel {id} was not declared"
                ))
            })?;
            records.extend_from_slice(schema);
        }
        records.extend_from_slice(&channel);
        match chunk {
            Some(chunk) => self.open_chunk(chunk).records.extend_from_slice(&records),
            None => self.due.push_back(Due::Record(records, None)),
        }
        Ok(())
    }

    /// Open chunk `chunk`, its records in a buffer with room for a whole chunk.
    fn open_chunk(&mut self, chunk: usize) -> &mut OpenChunk {
        let open = &mut self.open[chunk];
        if open.records.capacity() == 0 {
            open.records = self.buffers.take(self.chunk_bytes + self.chunk_bytes / 4);
        }
        open
    }

    pub fn write_message(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> io::Result<()> {
        let chunk = usize::from(self.precompressed.contains(&channel_id));
        self.define(channel_id, Some(chunk))?;
        let open = self.open_chunk(chunk);
        open.index
            .entry(channel_id)
            .or_default()
            .push((log_time_ns, open.records.len() as u64));
        open.time_ns = widen(open.time_ns, (log_time_ns, log_time_ns));
        put_record(&mut open.records, op::MESSAGE, |out| {
            put_u16(out, channel_id);
            put_u32(out, sequence);
            put_u64(out, log_time_ns);
            put_u64(out, publish_time_ns);
            out.extend_from_slice(data);
        });
        if open.records.len() >= self.chunk_bytes {
            self.close_chunks();
            self.write_due(false)?;
        }
        Ok(())
    }

    /// Copies a chunk of an input as stored. Its channels must be declared with the
    /// ids its records use; their records go before it, outside chunks, in case the
    /// input held them outside chunks too.
    pub fn copy_chunk(&mut self, chunk: FinishedChunk) -> io::Result<()> {
        for channel in &chunk.channels {
            self.define(channel.id, None)?;
        }
        self.due.push_back(Due::Chunk(chunk));
        self.write_due(false)
    }

    pub fn write_metadata(&mut self, name: &str, entries: &BTreeMap<String, String>) {
        let mut record = Vec::new();
        put_record(&mut record, op::METADATA, |out| {
            put_bytes(out, name.as_bytes());
            put_string_map(out, entries);
        });
        self.due
            .push_back(Due::Record(record, Some(name.to_string())));
    }

    /// Closes both open chunks, the already-compressed payloads' first: a reader
    /// that goes by file order (travmap's, pairing each cloud with the image nearest
    /// in time) then meets a span's images before its clouds, never long after.
    fn close_chunks(&mut self) {
        self.close_chunk(1);
        self.close_chunk(0);
    }

    /// Hands open chunk `chunk` to the compressors.
    fn close_chunk(&mut self, chunk: usize) {
        if self.open[chunk].records.is_empty() {
            return;
        }
        let open = std::mem::take(&mut self.open[chunk]);
        let compression = if chunk == 0 {
            self.compression
        } else {
            Compression::None
        };
        let compressing = self.compressors.compress(open, compression);
        self.due.push_back(Due::Compressing(compressing));
    }

    /// Writes what is due in order: everything (`all`), or up to the first chunk
    /// still compressing once no more than `in_flight_limit` are.
    fn write_due(&mut self, all: bool) -> io::Result<()> {
        while let Some(front) = self.due.pop_front() {
            let in_flight = self
                .due
                .iter()
                .filter(|due| matches!(due, Due::Compressing(_)))
                .count();
            let ready = match front {
                Due::Compressing(result) => {
                    let received = if all || in_flight >= self.in_flight_limit {
                        result.recv().map_err(|_| TryRecvError::Disconnected)
                    } else {
                        result.try_recv()
                    };
                    match received {
                        Ok(chunk) => Due::Chunk(chunk?),
                        Err(TryRecvError::Empty) => {
                            self.due.push_front(Due::Compressing(result));
                            return Ok(());
                        }
                        Err(TryRecvError::Disconnected) => {
                            return Err(io::Error::other("a chunk compression thread stopped"));
                        }
                    }
                }
                other => other,
            };
            match ready {
                Due::Chunk(chunk) => self.write_chunk(chunk)?,
                Due::Record(record, metadata_name) => {
                    let offset = self.position;
                    self.emit(&record)?;
                    if let Some(name) = metadata_name {
                        self.metadata += 1;
                        put_record(&mut self.metadata_indexes, op::METADATA_INDEX, |out| {
                            put_u64(out, offset);
                            put_u64(out, record.len() as u64);
                            put_bytes(out, name.as_bytes());
                        });
                    }
                }
                Due::Compressing(_) => unreachable!("received above"),
            }
        }
        Ok(())
    }

    fn write_chunk(&mut self, mut chunk: FinishedChunk) -> io::Result<()> {
        let start = self.position;
        self.emit(chunk.record.bytes())?;
        let indexes_start = self.position;
        self.emit(&chunk.message_indexes)?;
        if let Some(release) = chunk.release.take() {
            release.run();
        }
        let record_bytes = chunk.record.bytes().len() as u64;
        let (start_ns, end_ns) = chunk.time_ns.unwrap_or((0, 0));
        put_record(&mut self.chunk_indexes, op::CHUNK_INDEX, |out| {
            put_u64(out, start_ns);
            put_u64(out, end_ns);
            put_u64(out, start);
            put_u64(out, record_bytes);
            put_sized(out, |out| {
                for channel in &chunk.channels {
                    put_u16(out, channel.id);
                    put_u64(out, indexes_start + channel.index_offset);
                }
            });
            put_u64(out, chunk.message_indexes.len() as u64);
            put_bytes(out, chunk.compression.as_bytes());
            put_u64(out, chunk.compressed_bytes);
            put_u64(out, chunk.uncompressed_bytes);
        });
        self.chunks += 1;
        for channel in &chunk.channels {
            *self.message_counts.entry(channel.id).or_default() += channel.messages;
        }
        if let Some(range) = chunk.time_ns {
            self.time_ns = widen(self.time_ns, range);
        }
        if let ChunkRecord::Built(buffer) = chunk.record {
            self.buffers.give(buffer);
        }
        Ok(())
    }

    /// Writes the rest, the summary and the footer; returns the output.
    pub fn finish(mut self) -> io::Result<W> {
        self.close_chunks();
        self.write_due(true)?;
        let mut data_end = Vec::new();
        let crc = self.data_crc.clone().finalize();
        put_record(&mut data_end, op::DATA_END, |out| put_u32(out, crc));
        self.emit(&data_end)?;

        let summary_start = self.position;
        let mut summary = Vec::new();
        let mut offsets = Vec::new();
        let mut group = |summary: &mut Vec<u8>, opcode: u8, records: &[u8]| {
            if records.is_empty() {
                return;
            }
            put_record(&mut offsets, op::SUMMARY_OFFSET, |out| {
                out.push(opcode);
                put_u64(out, summary_start + summary.len() as u64);
                put_u64(out, records.len() as u64);
            });
            summary.extend_from_slice(records);
        };
        let schemas: Vec<u8> = self.schemas.values().flatten().copied().collect();
        group(&mut summary, op::SCHEMA, &schemas);
        let channels: Vec<u8> = self
            .channels
            .values()
            .flat_map(|(_, record)| record)
            .copied()
            .collect();
        group(&mut summary, op::CHANNEL, &channels);
        let mut statistics = Vec::new();
        let (start_ns, end_ns) = self.time_ns.unwrap_or((0, 0));
        put_record(&mut statistics, op::STATISTICS, |out| {
            put_u64(out, self.message_counts.values().sum());
            put_u16(out, self.schemas.len() as u16);
            put_u32(out, self.channels.len() as u32);
            put_u32(out, 0);
            put_u32(out, self.metadata);
            put_u32(out, self.chunks);
            put_u64(out, start_ns);
            put_u64(out, end_ns);
            put_sized(out, |out| {
                for (&id, &count) in &self.message_counts {
                    put_u16(out, id);
                    put_u64(out, count);
                }
            });
        });
        group(&mut summary, op::STATISTICS, &statistics);
        group(&mut summary, op::CHUNK_INDEX, &self.chunk_indexes);
        group(&mut summary, op::METADATA_INDEX, &self.metadata_indexes);

        let summary_offset_start = summary_start + summary.len() as u64;
        summary.extend_from_slice(&offsets);
        summary.push(op::FOOTER);
        put_u64(&mut summary, 20);
        put_u64(&mut summary, summary_start);
        put_u64(&mut summary, summary_offset_start);
        // The summary CRC covers the summary up to this field of the footer.
        let crc = crc32fast::hash(&summary);
        put_u32(&mut summary, crc);
        summary.extend_from_slice(MAGIC);
        self.out.write_all(&summary)?;
        self.out.flush()?;
        let Self { out, .. } = self;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::sans_io::{
        IndexedReadEvent, IndexedReader, IndexedReaderOptions, LinearReadEvent, LinearReader,
        LinearReaderOptions,
    };

    fn channel(id: u16, schema_id: u16, topic: &str) -> mcap::records::Channel {
        mcap::records::Channel {
            id,
            schema_id,
            topic: topic.into(),
            message_encoding: "cdr".into(),
            metadata: BTreeMap::from([("k".to_string(), "v".to_string())]),
        }
    }

    /// (channel, sequence, log time, data) of every message, in file order, read by
    /// the mcap crate with every CRC checked.
    fn read_linearly(file: &[u8]) -> Vec<(u16, u32, u64, Vec<u8>)> {
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true);
        let mut reader = LinearReader::new_with_options(options);
        let mut read = 0;
        let mut messages = Vec::new();
        while let Some(event) = reader.next_event() {
            match event.expect("the file reads") {
                LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(file.len() - read);
                    reader.insert(n).copy_from_slice(&file[read..read + n]);
                    reader.notify_read(n);
                    read += n;
                }
                LinearReadEvent::Record { opcode, data } => {
                    if let mcap::records::Record::Message { header, data } =
                        mcap::parse_record(opcode, data).expect("a record")
                    {
                        messages.push((
                            header.channel_id,
                            header.sequence,
                            header.log_time,
                            data.to_vec(),
                        ));
                    }
                }
            }
        }
        messages
    }

    /// Log times of every message in log-time order, read through the summary's
    /// chunk indexes.
    fn read_by_index(file: &[u8]) -> Vec<u64> {
        let summary = mcap::Summary::read(file).unwrap().expect("a summary");
        let mut reader =
            IndexedReader::new_with_options(&summary, IndexedReaderOptions::new()).unwrap();
        let mut times = Vec::new();
        while let Some(event) = reader.next_event() {
            match event.unwrap() {
                IndexedReadEvent::ReadChunkRequest { offset, length } => {
                    let chunk = &file[offset as usize..offset as usize + length];
                    reader.insert_chunk_record_data(offset, chunk).unwrap();
                }
                IndexedReadEvent::Message { header, .. } => times.push(header.log_time),
            }
        }
        times
    }

    fn write_file(compression: Compression, chunk_bytes: usize) -> Vec<u8> {
        let mut writer =
            McapWriter::new(Vec::new(), "ros2", "test", compression, chunk_bytes, 2).unwrap();
        writer.add_schema(1, "pkg/msg/A", "ros2msg", b"int32 a");
        writer.add_channel(&channel(3, 1, "/a"), false);
        // Its messages go into uncompressed chunks of their own.
        writer.add_channel(&channel(4, 1, "/b"), true);
        for i in 0..50u32 {
            // Out of order within channel /b, as recorded logs can be.
            let (id, time) = if i.is_multiple_of(2) {
                (3, 100 + i as u64)
            } else {
                (4, 200 - i as u64)
            };
            writer
                .write_message(id, i, time, time + 1, &vec![i as u8; 300 + i as usize])
                .unwrap();
        }
        writer.write_metadata("m", &BTreeMap::from([("x".into(), "1".into())]));
        writer.finish().unwrap()
    }

    #[test]
    fn the_mcap_crate_reads_every_message_in_order_with_every_crc_right() {
        for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
            let file = write_file(compression, 2000);
            let mut messages = read_linearly(&file);
            // /b's chunks come apart from /a's: file order interleaves the two.
            messages.sort_by_key(|m| m.1);
            assert_eq!(messages.len(), 50);
            for (i, (id, sequence, time, data)) in messages.iter().enumerate() {
                let i = i as u32;
                assert_eq!((*sequence, data.len()), (i, 300 + i as usize));
                assert_eq!(*id, if i.is_multiple_of(2) { 3 } else { 4 });
                assert_eq!(
                    *time,
                    if i.is_multiple_of(2) {
                        100 + i as u64
                    } else {
                        200 - i as u64
                    }
                );
            }
            let summary = mcap::Summary::read(&file).unwrap().unwrap();
            let stats = summary.stats.as_ref().unwrap();
            assert_eq!(stats.message_count, 50);
            assert_eq!(
                stats.channel_message_counts,
                BTreeMap::from([(3, 25), (4, 25)])
            );
            assert_eq!(
                (stats.message_start_time, stats.message_end_time),
                (100, 199)
            );
            assert_eq!(stats.metadata_count, 1);
            assert!(summary.chunk_indexes.len() > 3, "several chunks");
            assert_eq!(stats.chunk_count as usize, summary.chunk_indexes.len());
            assert_eq!(summary.channels[&4].topic, "/b");
            let stored_as =
                |name: &str| summary.chunk_indexes.iter().any(|c| c.compression == name);
            assert!(stored_as(compression.chunk_name()) && stored_as(""));
            assert_eq!(
                summary.channels[&4].schema.as_ref().unwrap().name,
                "pkg/msg/A"
            );
            let mut times: Vec<u64> = messages.iter().map(|m| m.2).collect();
            times.sort();
            assert_eq!(read_by_index(&file), times);
            for index in &summary.chunk_indexes {
                let indexes = summary.read_message_indexes(&file, index).unwrap();
                let count: usize = indexes.values().map(Vec::len).sum();
                assert!(count > 0);
            }
        }
    }

    #[test]
    fn copied_chunks_are_indexed_beside_new_ones() {
        let input = Bytes::from(write_file(Compression::Zstd, 2000));
        let mut stored = crate::io::mcap_stored::stored_log(&input).expect("copyable");
        assert_eq!(stored.messages(), 50);
        let mut writer =
            McapWriter::new(Vec::new(), "ros2", "test", Compression::Zstd, 2000, 1).unwrap();
        for (header, data) in &stored.schemas {
            writer.add_schema(header.id, &header.name, &header.encoding, data);
        }
        for channel in &stored.channels {
            writer.add_channel(channel, false);
        }
        for chunk in &mut stored.chunks {
            writer.copy_chunk(FinishedChunk::copied(chunk)).unwrap();
        }
        writer.add_channel(&channel(5, 1, "/c"), false);
        writer.write_message(5, 0, 150, 150, b"new").unwrap();
        let file = writer.finish().unwrap();
        let messages = read_linearly(&file);
        assert_eq!(messages.len(), 51);
        // Copied chunks keep their order in the file.
        assert_eq!(&messages[..50], &read_linearly(&input)[..]);
        assert_eq!(messages[50], (5, 0, 150, b"new".to_vec()));
        let mut times: Vec<u64> = messages.iter().map(|m| m.2).collect();
        times.sort();
        assert_eq!(read_by_index(&file), times);
        let summary = mcap::Summary::read(&file).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 51);
    }
}
