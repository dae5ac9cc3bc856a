//! Chunks of the MCAP file travmap writes: records gathered, compressed on a pool
//! of threads of their own into reused buffers, or copied from an input as stored.

use std::collections::BTreeMap;
use std::io::{self, Write};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use bytes::Bytes;
use mcap::records::op;

use crate::mcap::encoding::{put_bytes, put_record, put_sized, put_u16, put_u32, put_u64};
use crate::mcap::stored::{Release, StoredChunk};

/// Chunk compression of the written MCAP.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    #[default]
    Zstd,
    Lz4,
    None,
}

impl Compression {
    /// The name chunk records give it.
    pub fn chunk_name(self) -> &'static str {
        match self {
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
            Compression::None => "",
        }
    }
}

/// zstd level of `Compression::Zstd`: -1 (`zstd --fast=1`). By docs/speed.md's
/// compression table, against level 1: about 1.3-1.5x the `convert` frames/s for
/// files 2.5 % (converted) to 4 % (annotated) larger on the six real frames; level 3,
/// the mcap crate's default, writes 10 % less for half the speed.
const ZSTD_LEVEL: i32 = -1;

/// Records gathered for a chunk, not yet compressed.
#[derive(Default)]
pub struct OpenChunk {
    pub records: Vec<u8>,
    /// Log time range of its messages (None: no message yet).
    pub time_ns: Option<(u64, u64)>,
    /// Per channel, the log time and offset in `records` of each of its messages.
    pub index: BTreeMap<u16, Vec<(u64, u64)>>,
}

/// One channel's part of a written chunk.
pub struct IndexedChannel {
    pub id: u16,
    /// Where its message index record starts, from the end of the chunk record.
    pub index_offset: u64,
    pub messages: u64,
}

/// Chunk-sized buffers for reuse. Fresh ones cost a page fault every 4 KB: in
/// `convert`, twice the system time of the mcap crate's writer, which reuses its own.
#[derive(Clone, Default)]
pub struct Buffers(Arc<Mutex<Vec<Vec<u8>>>>);

/// Buffers kept for reuse at most: the chunks in flight and the open ones.
const KEPT_BUFFERS: usize = 8;

impl Buffers {
    /// An empty buffer with room for `bytes`, exactly: grown by doubling, the kept
    /// buffers ratcheted up to twice a chunk each over a long drive.
    pub fn take(&self, bytes: usize) -> Vec<u8> {
        let kept = self.0.lock().ok().and_then(|mut kept| kept.pop());
        let mut buffer = kept.unwrap_or_default();
        buffer.clear();
        buffer.reserve_exact(bytes);
        buffer
    }

    pub fn give(&self, buffer: Vec<u8>) {
        if let Ok(mut kept) = self.0.lock()
            && kept.len() < KEPT_BUFFERS
        {
            kept.push(buffer);
        }
    }
}

/// A chunk record: built here, in a buffer to reuse, or copied from an input.
pub enum ChunkRecord {
    Built(Vec<u8>),
    Copied(Bytes),
}

impl ChunkRecord {
    pub fn bytes(&self) -> &[u8] {
        match self {
            ChunkRecord::Built(bytes) => bytes,
            ChunkRecord::Copied(bytes) => bytes,
        }
    }
}

/// A chunk ready to be written: its record and the message index records after it.
pub struct FinishedChunk {
    /// For a copied chunk: what gives its input's pages back once written.
    pub release: Option<Release>,
    pub record: ChunkRecord,
    pub message_indexes: Bytes,
    pub time_ns: Option<(u64, u64)>,
    pub compression: String,
    pub compressed_bytes: u64,
    pub uncompressed_bytes: u64,
    pub channels: Vec<IndexedChannel>,
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
pub fn finish_chunk(
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
pub struct Compressors {
    jobs: Option<Sender<Job>>,
    threads: Vec<JoinHandle<()>>,
}

impl Compressors {
    pub fn start(count: usize, buffers: &Buffers) -> io::Result<Self> {
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

    pub fn compress(
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
