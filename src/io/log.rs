//! A recorded ROS log, whatever holds it: an MCAP file (ROS 2 CDR or ROS 1
//! messages), a ROS 1 bag ([`super::bag`]), a rosbag2 directory or a single rosbag2
//! sqlite3 file ([`super::rosbag2`]). Each is read as one stream of [`LogMessage`]s in
//! the order they were written, every message linked to its [`Connection`] (topic,
//! type, encodings).

use std::borrow::Cow;
use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::bag::BagFile;
use super::format::InputFormat;
use super::mcap_records::{Messages, Release, StoredLog, check_chunk_sizes, stored_log};
use super::ros::MessageEncoding;
use super::rosbag2::{Rosbag2Directory, SqliteFile};
use crate::error::{Error, Result};

/// A topic of a log: what its messages are and how they are encoded.
#[derive(Debug, PartialEq)]
pub struct Connection {
    pub topic: String,
    /// The type as the log names it: `sensor_msgs/msg/PointCloud2` in ROS 2,
    /// `sensor_msgs/PointCloud2` in ROS 1.
    pub schema_name: String,
    /// `ros2msg`, `ros1msg`, ... as MCAP names it; empty without a definition.
    pub schema_encoding: String,
    /// The message definition text.
    pub schema_data: Vec<u8>,
    /// `cdr`, `ros1`, ...
    pub message_encoding: String,
}

impl Connection {
    /// The ROS 2 name of the type (`pkg/msg/Type`), whichever ROS wrote it.
    pub fn type_name(&self) -> Cow<'_, str> {
        match self.schema_name.split_once('/') {
            Some((package, name)) if !name.contains('/') => {
                Cow::Owned(format!("{package}/msg/{name}"))
            }
            _ => Cow::Borrowed(&self.schema_name),
        }
    }

    /// The encoding, when travmap reads it.
    pub fn encoding(&self) -> Option<MessageEncoding> {
        MessageEncoding::from_name(&self.message_encoding)
    }
}

/// One recorded message, undecoded.
#[derive(Debug)]
pub struct LogMessage {
    pub connection: Arc<Connection>,
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    pub data: Vec<u8>,
}

/// A stream of messages of one file; an error names where in the file it is.
pub type FileMessages<'a> = Box<dyn Iterator<Item = std::result::Result<LogMessage, String>> + 'a>;

/// One file of a log.
pub enum LogFile {
    Mcap(McapFile),
    Bag(BagFile),
    Sqlite(SqliteFile),
}

impl LogFile {
    /// Opens `path` read as `format`, one of the single-file formats.
    pub fn open(path: &Path, format: InputFormat) -> Result<Self> {
        Ok(match format {
            InputFormat::Bag => LogFile::Bag(BagFile::open(path)?),
            InputFormat::Sqlite => LogFile::Sqlite(SqliteFile::open(path)?),
            _ => LogFile::Mcap(McapFile::open(path)?),
        })
    }

    pub fn path(&self) -> &Path {
        match self {
            LogFile::Mcap(file) => &file.path,
            LogFile::Bag(file) => file.path(),
            LogFile::Sqlite(file) => file.path(),
        }
    }

    fn messages(&self) -> FileMessages<'_> {
        match self {
            LogFile::Mcap(file) => Box::new(file.messages()),
            LogFile::Bag(file) => Box::new(file.messages()),
            LogFile::Sqlite(file) => file.messages(),
        }
    }
}

/// A recorded log: one file, or the files of a rosbag2 directory in order.
pub struct Log {
    path: PathBuf,
    files: Vec<LogFile>,
    /// What the reader noticed and worked around (an unindexed bag, ...).
    notices: Vec<String>,
}

impl Log {
    /// Opens the log at `path`, of a format [`super::format::detect`] found.
    pub fn open(path: &Path, format: InputFormat) -> Result<Self> {
        let (files, mut notices) = match format {
            InputFormat::Rosbag2 => {
                let directory = Rosbag2Directory::open(path)?;
                (directory.files, directory.notices)
            }
            _ => (vec![LogFile::open(path, format)?], Vec::new()),
        };
        for file in &files {
            if let LogFile::Bag(bag) = file {
                notices.extend(bag.notice().map(str::to_string));
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            files,
            notices,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn notices(&self) -> &[String] {
        &self.notices
    }

    /// A one-file MCAP log's chunks as stored, when they hold every message.
    pub fn stored(&self) -> Option<StoredLog> {
        match self.files.as_slice() {
            [LogFile::Mcap(file)] => file.stored(),
            _ => None,
        }
    }

    /// Every message of every file, in order; nothing after the first error.
    pub fn messages(&self) -> impl Iterator<Item = Result<LogMessage>> + '_ {
        let mut failed = false;
        self.files
            .iter()
            .flat_map(|file| {
                file.messages().enumerate().map(move |(ordinal, message)| {
                    message.map_err(|problem| Error::LogRecord {
                        path: file.path().to_path_buf(),
                        ordinal,
                        problem,
                    })
                })
            })
            .take_while(move |message| {
                let go_on = !failed;
                failed |= message.is_err();
                go_on
            })
    }
}

/// A file memory-mapped read-only and shared (chunks copied from it are slices of
/// it), whose pages a pass over it gives back once past them: they stay in the page
/// cache but leave travmap's resident set, which so stays flat over a log of any
/// length (measured: a 1 GB MCAP input otherwise adds 1 GB to it).
#[derive(Clone)]
pub struct FileMap(Arc<memmap2::Mmap>);

impl FileMap {
    pub fn open(path: &Path) -> Result<Self> {
        Ok(Self(Arc::new(map_file(path)?)))
    }

    /// The whole file, sharing the map.
    pub fn bytes(&self) -> bytes::Bytes {
        bytes::Bytes::from_owner(self.clone())
    }

    /// Gives back the pages wholly inside `range`.
    pub fn release(&self, range: Range<usize>) {
        const PAGE: usize = 4096;
        let start = range.start.next_multiple_of(PAGE);
        let end = range.end.min(self.0.len()) / PAGE * PAGE;
        if end > start {
            // SAFETY: the map is of a file, read-only: dropping its pages loses
            // nothing, and a later access reads them again from the file. A failure
            // only leaves the pages resident.
            let _ = unsafe {
                self.0.unchecked_advise_range(
                    memmap2::UncheckedAdvice::DontNeed,
                    start,
                    end - start,
                )
            };
        }
    }
}

impl AsRef<[u8]> for FileMap {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// An MCAP file, memory-mapped, its chunk sizes checked at open.
pub struct McapFile {
    path: PathBuf,
    file: FileMap,
    /// The memory map, shared with chunks copied from it (see [`stored_log`]).
    map: bytes::Bytes,
    /// See [`check_chunk_sizes`]: no record of the file is longer.
    longest_record: usize,
}

impl McapFile {
    pub fn open(path: &Path) -> Result<Self> {
        let file = FileMap::open(path)?;
        let map = file.bytes();
        let longest_record = check_chunk_sizes(&map).map_err(|problem| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        })?;
        file.release(0..map.len());
        Ok(Self {
            path: path.to_path_buf(),
            file,
            map,
            longest_record,
        })
    }

    /// Its chunks as stored, when they hold every message (see [`stored_log`]).
    pub fn stored(&self) -> Option<StoredLog> {
        let mut log = stored_log(&self.map)?;
        for chunk in &mut log.chunks {
            let end = chunk.offset + chunk.record.len() + chunk.message_indexes.len();
            chunk.release = Some(Release(self.file.clone(), chunk.offset..end));
        }
        Some(log)
    }

    fn messages(&self) -> impl Iterator<Item = std::result::Result<LogMessage, String>> + '_ {
        let mut connections: HashMap<u16, Arc<Connection>> = HashMap::new();
        Messages::new(&self.map, self.longest_record, Some(&self.file)).map(move |message| {
            let message = message?;
            let channel = &message.channel;
            let connection = connections.entry(channel.id).or_insert_with(|| {
                let (schema_name, schema_encoding, schema_data) = match &channel.schema {
                    Some(schema) => (
                        schema.name.clone(),
                        schema.encoding.clone(),
                        schema.data.to_vec(),
                    ),
                    None => Default::default(),
                };
                Arc::new(Connection {
                    topic: channel.topic.clone(),
                    schema_name,
                    schema_encoding,
                    schema_data,
                    message_encoding: channel.message_encoding.clone(),
                })
            });
            Ok(LogMessage {
                connection: connection.clone(),
                log_time_ns: message.log_time,
                publish_time_ns: message.publish_time,
                data: message.data.into_owned(),
            })
        })
    }
}

/// `path` memory-mapped read-only.
pub fn map_file(path: &Path) -> Result<memmap2::Mmap> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    // SAFETY: the file is opened read-only and not modified while mapped by travmap;
    // another process truncating it under us is outside what any reader can guard.
    unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn released_pages_read_back_the_same() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        let content: Vec<u8> = (0..100_000u32).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(&path, &content).unwrap();
        let map = FileMap::open(&path).unwrap();
        let bytes = map.bytes();
        map.release(0..content.len());
        map.release(5000..70_000);
        assert_eq!(&bytes[..], &content[..]);
    }

    #[test]
    fn ros1_type_names_read_as_ros2_ones() {
        let connection = |name: &str| Connection {
            topic: "/t".into(),
            schema_name: name.into(),
            schema_encoding: String::new(),
            schema_data: Vec::new(),
            message_encoding: "ros1".into(),
        };
        assert_eq!(
            connection("sensor_msgs/PointCloud2").type_name(),
            "sensor_msgs/msg/PointCloud2"
        );
        assert_eq!(
            connection("tf2_msgs/msg/TFMessage").type_name(),
            "tf2_msgs/msg/TFMessage"
        );
        assert_eq!(connection("").type_name(), "");
    }
}
