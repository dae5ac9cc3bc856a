//! A recorded ROS log, whatever holds it: an MCAP file (ROS 2 CDR or ROS 1
//! messages), a ROS 1 bag ([`super::bag`]), a rosbag2 directory or a single rosbag2
//! sqlite3 file ([`super::rosbag2`]). Each is read as one stream of [`LogMessage`]s in
//! the order they were written, every message linked to its [`Connection`] (topic,
//! type, encodings).

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::bag::BagFile;
use super::format::InputFormat;
use super::mcap_records::{Messages, StoredLog, check_chunk_sizes, stored_log};
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

/// An MCAP file, memory-mapped, its chunk sizes checked at open.
pub struct McapFile {
    path: PathBuf,
    /// The memory map, shared with chunks copied from it (see [`stored_log`]).
    map: bytes::Bytes,
    /// See [`check_chunk_sizes`]: no record of the file is longer.
    longest_record: usize,
}

impl McapFile {
    pub fn open(path: &Path) -> Result<Self> {
        let map = map_file(path)?;
        let longest_record = check_chunk_sizes(&map).map_err(|problem| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        })?;
        Ok(Self {
            path: path.to_path_buf(),
            map: bytes::Bytes::from_owner(map),
            longest_record,
        })
    }

    /// Its chunks as stored, when they hold every message (see [`stored_log`]).
    pub fn stored(&self) -> Option<StoredLog> {
        stored_log(&self.map)
    }

    fn messages(&self) -> impl Iterator<Item = std::result::Result<LogMessage, String>> + '_ {
        let mut connections: HashMap<u16, Arc<Connection>> = HashMap::new();
        Messages::new(&self.map, self.longest_record).map(move |message| {
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
