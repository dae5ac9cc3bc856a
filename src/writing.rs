//! Writing: ROS 2 (CDR) MCAP files, atomically.
//!
//! An [`McapSink`] writes to a temporary file beside the output and renames it over
//! the output only in [`McapSink::finish`]; dropped unfinished (an error, a panic),
//! it deletes the temporary file, so a failed run never leaves a file that looks
//! complete. zstd chunks are compressed on worker threads by the mcap crate.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::ros::{RosMessage, encode};

/// Chunk compression of the written MCAP.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    #[default]
    Zstd,
    Lz4,
    None,
}

/// Chunks of about this many bytes (uncompressed): a few frames each.
const CHUNK_BYTES: u64 = 8 << 20;

/// An MCAP being written; see the module documentation.
pub struct McapSink {
    writer: Option<mcap::Writer<BufWriter<File>>>,
    temporary_path: PathBuf,
    path: PathBuf,
    channels: HashMap<String, u16>,
    schemas: HashMap<String, u16>,
    sequence: u32,
}

impl McapSink {
    pub fn create(path: &Path, compression: Compression) -> Result<Self> {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = path.file_name().ok_or_else(|| Error::Mcap {
            path: path.to_path_buf(),
            message: "output path has no file name".into(),
        })?;
        let temporary_path = dir.join(format!(
            ".{}.tmp-{}",
            name.to_string_lossy(),
            std::process::id()
        ));
        let file = File::create(&temporary_path).map_err(|e| Error::io(&temporary_path, e))?;
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get()) as u32;
        let options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("travmap ", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(CHUNK_BYTES))
            .compression(match compression {
                Compression::Zstd => Some(mcap::Compression::Zstd),
                Compression::Lz4 => Some(mcap::Compression::Lz4),
                Compression::None => None,
            })
            .compression_threads(threads);
        let writer = options
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(|e| Error::Mcap {
                path: temporary_path.clone(),
                message: e.to_string(),
            })?;
        Ok(Self {
            writer: Some(writer),
            temporary_path,
            path: path.to_path_buf(),
            channels: HashMap::new(),
            schemas: HashMap::new(),
            sequence: 0,
        })
    }

    fn fail(&self, e: impl std::fmt::Display) -> Error {
        Error::Mcap {
            path: self.path.clone(),
            message: format!("writing failed: {e}"),
        }
    }

    fn writer(&mut self) -> &mut mcap::Writer<BufWriter<File>> {
        self.writer.as_mut().expect("the writer lives until finish")
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
                let id = self
                    .writer()
                    .add_schema(schema_name, schema_encoding, schema)
                    .map_err(|e| self.fail(e))?;
                self.schemas.insert(schema_name.to_string(), id);
                id
            }
        };
        let id = self
            .writer()
            .add_channel(schema_id, topic, message_encoding, &BTreeMap::new())
            .map_err(|e| self.fail(e))?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// Writes already-encoded bytes on a channel.
    pub fn write_raw(
        &mut self,
        channel_id: u16,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        self.sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        self.writer()
            .write_to_known_channel(&header, data)
            .map_err(|e| self.fail(e))
    }

    /// Encodes and writes a ROS 2 message on `topic`.
    pub fn write<T: RosMessage>(&mut self, topic: &str, stamp_ns: u64, message: &T) -> Result<()> {
        let bytes = encode(message, 0);
        self.write_encoded::<T>(topic, stamp_ns, &bytes)
    }

    /// Writes a message of type `T` that is already CDR-encoded (see [`encode`]).
    pub fn write_encoded<T: RosMessage>(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        bytes: &[u8],
    ) -> Result<()> {
        let channel = self.channel(topic, T::NAME, "ros2msg", T::SCHEMA.as_bytes(), "cdr")?;
        // Log time = header stamp: tools that order by log time then show sensor time.
        self.write_raw(channel, stamp_ns, stamp_ns, bytes)
    }

    pub fn write_metadata(&mut self, name: &str, entries: BTreeMap<String, String>) -> Result<()> {
        let metadata = mcap::records::Metadata {
            name: name.to_string(),
            metadata: entries,
        };
        self.writer()
            .write_metadata(&metadata)
            .map_err(|e| self.fail(e))
    }

    /// Writes the summary, syncs, and renames the temporary file over the output.
    pub fn finish(mut self) -> Result<()> {
        let mut writer = self.writer.take().expect("finish runs once");
        writer.finish().map_err(|e| self.fail(e))?;
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| self.fail(e.error()))?;
        file.sync_all().map_err(|e| self.fail(e))?;
        std::fs::rename(&self.temporary_path, &self.path).map_err(|e| self.fail(e))?;
        Ok(())
    }
}

impl Drop for McapSink {
    fn drop(&mut self) {
        if self.writer.is_some() {
            // Unfinished: leave nothing behind.
            let _ = std::fs::remove_file(&self.temporary_path);
        }
    }
}
