//! Writing: ROS 2 (CDR) MCAP files, atomically, with compression off the caller's
//! thread.
//!
//! An [`McapSink`] hands every record to a writer thread that owns the mcap
//! `Writer`, so chunk compression (zstd by default, itself multi-threaded by the
//! mcap crate) overlaps with the caller reading, running the method and encoding the
//! next frames. It writes to a temporary file beside the output and renames it over
//! the output only in [`McapSink::finish`]; dropped unfinished (an error, a panic), it
//! deletes the temporary file, so a failed run never leaves a file that looks complete.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use crate::error::{Error, Result};
use crate::io::ros::{RosMessage, encode};

/// Temporary files being written, so that an interrupted run (SIGINT) can remove
/// them: it leaves nothing at or beside the output.
static TEMPORARY_FILES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Records a temporary file until [`forget_temporary`].
pub fn track_temporary(path: &Path) {
    if let Ok(mut files) = TEMPORARY_FILES.lock() {
        files.push(path.to_path_buf());
    }
}

pub fn forget_temporary(path: &Path) {
    if let Ok(mut files) = TEMPORARY_FILES.lock() {
        files.retain(|p| p != path);
    }
}

/// Deletes every tracked temporary file (from the signal handler).
pub fn remove_temporary_files() {
    if let Ok(files) = TEMPORARY_FILES.lock() {
        for path in files.iter() {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// What tells a temporary output from others: `.NAME.tmp-PID` beside `NAME`.
pub const TEMPORARY_INFIX: &str = ".tmp-";

/// The temporary file an output is written to: hidden, beside it, named after this
/// process so that a later run can tell a dead run's leftovers from a live one's.
pub fn temporary_path(path: &Path) -> std::io::Result<PathBuf> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the output path has no file name",
        )
    })?;
    Ok(dir.join(format!(
        ".{}{TEMPORARY_INFIX}{}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

/// An output being written under a temporary name beside it: [`AtomicFile::commit`]
/// renames it over the output; dropped uncommitted, it deletes the temporary file.
pub struct AtomicFile {
    path: PathBuf,
    temporary_path: PathBuf,
    committed: bool,
}

impl AtomicFile {
    /// The guard and the temporary file to write.
    pub fn create(path: &Path) -> Result<(Self, File)> {
        let write_error = |source| Error::Write {
            path: path.to_path_buf(),
            source,
        };
        let temporary_path = temporary_path(path).map_err(write_error)?;
        let file = File::create(&temporary_path).map_err(write_error)?;
        track_temporary(&temporary_path);
        let guard = Self {
            path: path.to_path_buf(),
            temporary_path,
            committed: false,
        };
        Ok((guard, file))
    }

    /// The output path (not the temporary one).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the written file over the output (the caller has flushed and synced it).
    /// Bytes in the temporary file so far.
    pub fn written_bytes(&self) -> u64 {
        std::fs::metadata(&self.temporary_path).map_or(0, |m| m.len())
    }

    pub fn commit(mut self) -> Result<()> {
        std::fs::rename(&self.temporary_path, &self.path).map_err(|source| Error::Write {
            path: self.path.clone(),
            source,
        })?;
        self.committed = true;
        forget_temporary(&self.temporary_path);
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.temporary_path);
            forget_temporary(&self.temporary_path);
        }
    }
}

/// The error of a failed write to `output`'s temporary file: a full disk says so
/// with the bytes written (of `expected_bytes`, when known).
pub fn write_failure(
    path: &Path,
    output: &AtomicFile,
    error: Option<mcap::McapError>,
    expected_bytes: Option<u64>,
) -> Error {
    match error {
        Some(mcap::McapError::Io(source)) if source.raw_os_error() == Some(libc::ENOSPC) => {
            Error::NoSpace {
                path: path.to_path_buf(),
                written_bytes: output.written_bytes(),
                expected_bytes,
            }
        }
        Some(mcap::McapError::Io(source)) => Error::Write {
            path: path.to_path_buf(),
            source,
        },
        Some(other) => Error::McapWrite {
            path: path.to_path_buf(),
            source: other,
        },
        None => Error::WriterStopped {
            path: path.to_path_buf(),
        },
    }
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let (guard, mut file) = AtomicFile::create(path)?;
    file.write_all(bytes)
        .and_then(|_| file.sync_all())
        .map_err(|source| {
            write_failure(
                path,
                &guard,
                Some(mcap::McapError::Io(source)),
                Some(bytes.len() as u64),
            )
        })?;
    guard.commit()
}

/// Chunk compression of the written MCAP.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    #[default]
    Zstd,
    Lz4,
    None,
}

/// zstd level of `Compression::Zstd`. Level 1 against the crate's default (3), on
/// the shipped scans: 2.2-2.7x the `convert` frames/s for files 11 % larger (the
/// README's compression table).
const ZSTD_LEVEL: u32 = 1;

/// Chunks of about this many bytes (uncompressed): a few frames each.
const CHUNK_BYTES: u64 = 8 << 20;

/// Records queued for the writer thread before the caller waits (a few frames).
const QUEUE: usize = 64;

enum Record {
    Schema {
        id: u16,
        name: String,
        encoding: String,
        data: Vec<u8>,
    },
    Channel {
        id: u16,
        schema_id: u16,
        topic: String,
        message_encoding: String,
    },
    Message {
        channel_id: u16,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: Vec<u8>,
    },
    Metadata(mcap::records::Metadata),
}

/// An MCAP being written; see the module documentation.
pub struct McapSink {
    sender: Option<SyncSender<Record>>,
    thread: Option<JoinHandle<std::result::Result<(), mcap::McapError>>>,
    /// None once finished.
    output: Option<AtomicFile>,
    path: PathBuf,
    channels: HashMap<String, u16>,
    schemas: HashMap<String, u16>,
    sequence: u32,
}

/// The writer thread: writes records until the queue closes, then the summary.
fn write_records(
    mut writer: mcap::Writer<BufWriter<File>>,
    records: Receiver<Record>,
) -> std::result::Result<(), mcap::McapError> {
    let fail = |e: mcap::McapError| e;
    for record in records {
        match record {
            Record::Schema {
                id,
                name,
                encoding,
                data,
            } => {
                writer
                    .add_schema_with_id(id, &name, &encoding, &data)
                    .map_err(fail)?;
            }
            Record::Channel {
                id,
                schema_id,
                topic,
                message_encoding,
            } => {
                writer
                    .add_channel_with_id(id, schema_id, &topic, &message_encoding, &BTreeMap::new())
                    .map_err(fail)?;
            }
            Record::Message {
                channel_id,
                sequence,
                log_time_ns,
                publish_time_ns,
                data,
            } => {
                let header = mcap::records::MessageHeader {
                    channel_id,
                    sequence,
                    log_time: log_time_ns,
                    publish_time: publish_time_ns,
                };
                writer
                    .write_to_known_channel(&header, &data)
                    .map_err(fail)?;
            }
            Record::Metadata(metadata) => writer.write_metadata(&metadata).map_err(fail)?,
        }
    }
    writer.finish().map_err(fail)?;
    let file = writer
        .into_inner()
        .into_inner()
        .map_err(|e| mcap::McapError::Io(e.into_error()))?;
    Ok(file.sync_all()?)
}

impl McapSink {
    pub fn create(path: &Path, compression: Compression) -> Result<Self> {
        let (output, file) = AtomicFile::create(path)?;
        // As many compression threads as rayon workers (RAYON_NUM_THREADS caps both).
        let threads = rayon::current_num_threads() as u32;
        let options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("travmap ", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(CHUNK_BYTES))
            .compression(match compression {
                Compression::Zstd => Some(mcap::Compression::Zstd),
                Compression::Lz4 => Some(mcap::Compression::Lz4),
                Compression::None => None,
            })
            .compression_threads(threads)
            .compression_level(ZSTD_LEVEL);
        let writer = options
            .create(BufWriter::with_capacity(1 << 20, file))
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
            channels: HashMap::new(),
            schemas: HashMap::new(),
            sequence: 0,
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
    fn join_writer(&mut self) -> Option<std::result::Result<(), mcap::McapError>> {
        self.sender = None;
        self.thread.take()?.join().ok()
    }

    fn failure(&self, error: Option<mcap::McapError>) -> Error {
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
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(schema_name) {
            Some(&id) => id,
            None => {
                let id = self.schemas.len() as u16 + 1;
                self.send(Record::Schema {
                    id,
                    name: schema_name.into(),
                    encoding: schema_encoding.into(),
                    data: schema.to_vec(),
                })?;
                self.schemas.insert(schema_name.to_string(), id);
                id
            }
        };
        let id = self.channels.len() as u16;
        self.send(Record::Channel {
            id,
            schema_id,
            topic: topic.into(),
            message_encoding: message_encoding.into(),
        })?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// Writes already-encoded bytes on a channel.
    pub fn write_raw(
        &mut self,
        channel_id: u16,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: Vec<u8>,
    ) -> Result<()> {
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

    pub fn write_metadata(&mut self, name: &str, entries: BTreeMap<String, String>) -> Result<()> {
        self.send(Record::Metadata(mcap::records::Metadata {
            name: name.to_string(),
            metadata: entries,
        }))
    }

    /// Waits for the writer, then renames the temporary file over the output.
    pub fn finish(mut self) -> Result<()> {
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
