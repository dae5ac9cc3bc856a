//! Writing: ROS 2 (CDR) MCAP files, atomically, with compression off the caller's
//! thread.
//!
//! An [`McapSink`] hands every record to a writer thread that owns the
//! [`McapWriter`], which compresses chunks on threads of its own, so compression
//! (zstd by default) overlaps with the caller reading, running the method and
//! encoding the next frames, and with itself. It writes to a temporary file beside the output and renames it over
//! the output only in [`McapSink::finish`]; dropped unfinished (an error, a panic), it
//! deletes the temporary file, so a failed run never leaves a file that looks complete.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use crate::atomic::{AtomicFile, WritebackFile, sync_output, write_failure};
use travmap_core::error::{Error, Result};
use travmap_formats::mcap::stored::{StoredChunk, StoredLog};
use travmap_formats::mcap::writer::{Compression, FinishedChunk, McapWriter};
use travmap_formats::ros::{RosMessage, encode};

/// Chunks of about this many bytes (uncompressed): a few frames each, so that
/// several compress at once.
const CHUNK_BYTES: usize = 8 << 20;

/// rosbag2's `offered_qos_profiles` for one publisher: reliable, transient local,
/// keep last 1, the durations unset (rmw's "infinite"): how map_server offers `/map`.
const TRANSIENT_LOCAL_QOS: &str = "- history: 1
  depth: 1
  reliability: 1
  durability: 1
  deadline:
    sec: 2147483647
    nsec: 4294967295
  lifespan:
    sec: 2147483647
    nsec: 4294967295
  liveliness: 1
  liveliness_lease_duration:
    sec: 2147483647
    nsec: 4294967295
  avoid_ros_namespace_conventions: false
";

/// Records queued for the writer thread before the caller waits: about three
/// frames of `annotate`, so that a busy writer holds back the caller, not memory.
const QUEUE: usize = 16;

enum Record {
    Schema {
        id: u16,
        name: String,
        encoding: String,
        data: Vec<u8>,
    },
    Channel {
        channel: mcap::records::Channel,
        precompressed: bool,
    },
    Message {
        channel_id: u16,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: Vec<u8>,
    },
    CopiedChunk(FinishedChunk),
    Metadata {
        name: String,
        entries: BTreeMap<String, String>,
    },
}

/// An MCAP being written; see the module documentation.
pub struct McapSink {
    sender: Option<SyncSender<Record>>,
    thread: Option<JoinHandle<std::io::Result<()>>>,
    /// None once finished.
    output: Option<AtomicFile>,
    path: PathBuf,
    compression: Compression,
    /// Channel and schema ids by topic and schema name.
    channels: HashMap<String, u16>,
    schemas: HashMap<String, u16>,
    /// Ids in use: copied chunks keep their input's.
    channel_ids: BTreeSet<u16>,
    schema_ids: BTreeSet<u16>,
    sequence: u32,
    /// Whether copied chunks wait for the messages of their time
    /// ([`Self::copy_chunks_by_time`]), and those still waiting, in file order.
    chunks_by_time: bool,
    waiting_chunks: VecDeque<StoredChunk>,
}

/// The writer thread: writes records until the queue closes, then the summary.
fn write_records(
    mut writer: McapWriter<BufWriter<WritebackFile>>,
    records: Receiver<Record>,
) -> std::io::Result<()> {
    for record in records {
        match record {
            Record::Schema {
                id,
                name,
                encoding,
                data,
            } => writer.add_schema(id, &name, &encoding, &data),
            Record::Channel {
                channel,
                precompressed,
            } => writer.add_channel(&channel, precompressed),
            Record::Message {
                channel_id,
                sequence,
                log_time_ns,
                publish_time_ns,
                data,
            } => writer.write_message(channel_id, sequence, log_time_ns, publish_time_ns, &data)?,
            Record::CopiedChunk(chunk) => writer.copy_chunk(chunk)?,
            Record::Metadata { name, entries } => writer.write_metadata(&name, &entries),
        }
    }
    let file = writer.finish()?.into_inner().map_err(|e| e.into_error())?;
    sync_output(&file.into_inner())
}

/// Whether messages of type `schema_name` carry an already compressed payload
/// (images, video): zstd gains nothing on them (level 1 turns the shipped
/// 886,551-byte PNG into 886,582 bytes, at 500 MB/s), so they are stored
/// uncompressed, in chunks of their own.
fn precompressed_payload(schema_name: &str) -> bool {
    let name = schema_name.rsplit(['/', '.']).next().unwrap_or_default();
    matches!(
        name,
        "CompressedImage" | "CompressedVideo" | "CompressedPointCloud2" | "FFMPEGPacket"
    )
}

/// The lowest id not in `used` (ids start at 1: schema id 0 means "no schema").
fn free_id(used: &BTreeSet<u16>) -> u16 {
    (1..=u16::MAX).find(|id| !used.contains(id)).unwrap_or(0)
}

impl McapSink {
    pub fn create(path: &Path, compression: Compression) -> Result<Self> {
        let (output, file) = AtomicFile::create(path)?;
        let writer = McapWriter::new(
            BufWriter::with_capacity(1 << 20, WritebackFile::new(file)),
            "ros2",
            concat!("travmap ", env!("CARGO_PKG_VERSION")),
            compression,
            CHUNK_BYTES,
            rayon::current_num_threads(),
        )
        .map_err(|e| write_failure(path, &output, Some(e), None))?;
        let (sender, receiver) = sync_channel(QUEUE);
        let thread = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || write_records(writer, receiver))
            .map_err(|source| Error::Write {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(Self {
            sender: Some(sender),
            thread: Some(thread),
            output: Some(output),
            path: path.to_path_buf(),
            compression,
            channels: HashMap::new(),
            schemas: HashMap::new(),
            channel_ids: BTreeSet::new(),
            schema_ids: BTreeSet::new(),
            sequence: 0,
            chunks_by_time: false,
            waiting_chunks: VecDeque::new(),
        })
    }

    /// Queues a record; if the writer thread has stopped, its error.
    fn send(&mut self, record: Record) -> Result<()> {
        let sent = self.sender.as_ref().is_some_and(|s| s.send(record).is_ok());
        if sent {
            return Ok(());
        }
        Err(self.writer_error())
    }

    /// The writer thread's error, after it stopped.
    fn writer_error(&mut self) -> Error {
        let error = self.join_writer().and_then(Result::err);
        self.failure(error)
    }

    /// Closes the queue and waits for the writer thread: its result, or None when it
    /// panicked or was already joined.
    fn join_writer(&mut self) -> Option<std::io::Result<()>> {
        self.sender = None;
        self.thread.take()?.join().ok()
    }

    fn failure(&self, error: Option<std::io::Error>) -> Error {
        match &self.output {
            Some(output) => write_failure(&self.path, output, error, None),
            None => Error::WriterStopped {
                path: self.path.clone(),
            },
        }
    }

    /// The channel of `topic`, created with its schema on first use.
    pub fn channel(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_encoding: &str,
        schema: &[u8],
        message_encoding: &str,
    ) -> Result<u16> {
        let metadata = BTreeMap::new();
        self.channel_with(
            topic,
            schema_name,
            schema_encoding,
            schema,
            message_encoding,
            metadata,
        )
    }

    /// [`Self::channel`], created with `metadata` (rosbag2's QoS profiles, say).
    fn channel_with(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_encoding: &str,
        schema: &[u8],
        message_encoding: &str,
        metadata: BTreeMap<String, String>,
    ) -> Result<u16> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(schema_name) {
            Some(&id) => id,
            None => {
                let id = free_id(&self.schema_ids);
                self.send(Record::Schema {
                    id,
                    name: schema_name.into(),
                    encoding: schema_encoding.into(),
                    data: schema.to_vec(),
                })?;
                self.schema_ids.insert(id);
                self.schemas.insert(schema_name.to_string(), id);
                id
            }
        };
        let id = free_id(&self.channel_ids);
        self.send(Record::Channel {
            channel: mcap::records::Channel {
                id,
                schema_id,
                topic: topic.into(),
                message_encoding: message_encoding.into(),
                metadata,
            },
            precompressed: precompressed_payload(schema_name),
        })?;
        self.channel_ids.insert(id);
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// Copies the chunks of an input as they are stored, under the input's schema
    /// and channel ids (their records use them). Only before any channel of the
    /// sink's own: returns false, copying nothing, when one was created, and when
    /// some chunk is compressed otherwise than this sink's chunks unless
    /// `any_compression`.
    pub fn copy_chunks(
        &mut self,
        log: StoredLog,
        any_compression: bool,
        on_chunk: &dyn Fn(&StoredChunk),
    ) -> Result<bool> {
        let compression = self.compression.chunk_name();
        let same_compression = log.chunks.iter().all(|c| c.compression == compression);
        let fresh = self.channel_ids.is_empty() && self.schema_ids.is_empty();
        if !fresh || !(same_compression || any_compression) {
            return Ok(false);
        }
        for (header, data) in &log.schemas {
            self.send(Record::Schema {
                id: header.id,
                name: header.name.clone(),
                encoding: header.encoding.clone(),
                data: data.clone(),
            })?;
            self.schema_ids.insert(header.id);
            self.schemas.entry(header.name.clone()).or_insert(header.id);
        }
        for channel in &log.channels {
            self.send(Record::Channel {
                channel: channel.clone(),
                precompressed: false,
            })?;
            self.channel_ids.insert(channel.id);
            self.channels
                .entry(channel.topic.clone())
                .or_insert(channel.id);
        }
        for chunk in &log.chunks {
            on_chunk(chunk);
        }
        self.waiting_chunks.extend(log.chunks);
        if !self.chunks_by_time {
            self.send_waiting_chunks(u64::MAX)?;
        }
        Ok(true)
    }

    /// From here on, chunks copied from an input ([`Self::copy_chunks`]) wait until
    /// a message of their start time or later is written, or the sink finishes: the
    /// writer then copies them while the caller works (annotate's method), instead
    /// of holding the caller back until all but the queue's last were written.
    pub fn copy_chunks_by_time(&mut self) {
        self.chunks_by_time = true;
    }

    /// Queues the waiting chunks that start at `until_ns` or earlier, in file order.
    fn send_waiting_chunks(&mut self, until_ns: u64) -> Result<()> {
        while let Some(chunk) = self.waiting_chunks.front() {
            if chunk
                .time_ns
                .is_some_and(|(start_ns, _)| start_ns > until_ns)
            {
                break;
            }
            let mut chunk = self.waiting_chunks.pop_front().expect("a front chunk");
            self.send(Record::CopiedChunk(FinishedChunk::copied(&mut chunk)))?;
        }
        Ok(())
    }

    /// Writes already-encoded bytes on a channel.
    pub fn write_raw(
        &mut self,
        channel_id: u16,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: Vec<u8>,
    ) -> Result<()> {
        self.send_waiting_chunks(log_time_ns)?;
        self.sequence += 1;
        self.send(Record::Message {
            channel_id,
            sequence: self.sequence,
            log_time_ns,
            publish_time_ns,
            data,
        })
    }

    /// Encodes and writes a ROS 2 message on `topic`.
    pub fn write<T: RosMessage>(&mut self, topic: &str, stamp_ns: u64, message: &T) -> Result<()> {
        self.write_encoded::<T>(topic, stamp_ns, encode(message, 0))
    }

    /// Writes a message of type `T` that is already CDR-encoded (see [`encode`]).
    pub fn write_encoded<T: RosMessage>(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        bytes: Vec<u8>,
    ) -> Result<()> {
        let channel = self.channel(topic, T::NAME, "ros2msg", T::SCHEMA.as_bytes(), "cdr")?;
        // Log time = header stamp: tools that order by log time then show sensor time.
        self.write_raw(channel, stamp_ns, stamp_ns, bytes)
    }

    /// Writes a ROS 2 message on `topic`, whose channel offers rosbag2's
    /// transient-local QoS (a latched topic: `ros2 bag play` republishes it so, and a
    /// late subscriber such as nav2's static layer still receives it).
    pub fn write_latched<T: RosMessage>(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        message: &T,
    ) -> Result<()> {
        let metadata = BTreeMap::from([(
            "offered_qos_profiles".to_string(),
            TRANSIENT_LOCAL_QOS.to_string(),
        )]);
        let schema = T::SCHEMA.as_bytes();
        let channel = self.channel_with(topic, T::NAME, "ros2msg", schema, "cdr", metadata)?;
        self.write_raw(channel, stamp_ns, stamp_ns, encode(message, 0))
    }

    pub fn write_metadata(&mut self, name: &str, entries: BTreeMap<String, String>) -> Result<()> {
        self.send_waiting_chunks(u64::MAX)?;
        self.send(Record::Metadata {
            name: name.to_string(),
            entries,
        })
    }

    /// Waits for the writer, then renames the temporary file over the output.
    pub fn finish(mut self) -> Result<()> {
        self.send_waiting_chunks(u64::MAX)?;
        let error = match self.join_writer() {
            Some(Ok(())) => None,
            Some(Err(error)) => Some(error),
            None => {
                return Err(Error::WriterStopped {
                    path: self.path.clone(),
                });
            }
        };
        if let Some(error) = error {
            return Err(self.failure(Some(error)));
        }
        match self.output.take() {
            Some(output) => output.commit(),
            None => Ok(()),
        }
    }
}

impl Drop for McapSink {
    fn drop(&mut self) {
        // Unfinished: let the writer thread end before the output guard deletes
        // the temporary file.
        self.sender = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
