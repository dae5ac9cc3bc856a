//! A recorded ROS log, whatever holds it: an MCAP file (ROS 2 CDR or ROS 1
//! messages), a ROS 1 bag ([`super::bag`]), a rosbag2 directory or a single rosbag2
//! sqlite3 file ([`super::rosbag2`]). Each is read as one stream of [`LogMessage`]s in
//! the order they were written, every message linked to its [`Connection`] (topic,
//! type, encodings).

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::bag::BagFile;
use super::bag_messages::BagMessages;
use super::pcap::PcapFile;
use super::rosbag2::{Rosbag2Directory, says_zstd_messages};
use super::sqlite::SqliteFile;
use crate::format::{InputFormat, refuse};
use travmap_core::error::{Error, LostMessage, Result};
use travmap_formats::foxglove;
use travmap_formats::log_message::{ChunkSpan, HEADER_BYTES};
pub use travmap_formats::log_message::{Connection, Damage, FileMap, LogMessage, Part, Parts};
use travmap_formats::mcap::messages::Messages;
use travmap_formats::mcap::records::check_chunk_sizes;
use travmap_formats::mcap::stored::{Release, StoredLog, stored_log};

/// One file of a log.
pub enum LogFile {
    Mcap(McapFile),
    Bag(BagFile),
    Sqlite(SqliteFile),
    Pcap(PcapFile),
}

impl LogFile {
    /// Opens `path` read as `format`, one of the single-file log formats (another
    /// format is refused: a rosbag2 directory's storage file that is no log).
    pub fn open(path: &Path, format: InputFormat) -> Result<Self> {
        Ok(match format {
            InputFormat::Mcap => LogFile::Mcap(McapFile::open(path)?),
            InputFormat::Bag => LogFile::Bag(BagFile::open(path)?),
            InputFormat::Sqlite => LogFile::Sqlite(SqliteFile::open(path)?),
            InputFormat::Pcap => LogFile::Pcap(PcapFile::open(path)?),
            InputFormat::Kitti
            | InputFormat::ScanFolder
            | InputFormat::Rosbag2
            | InputFormat::SiteCloud(_) => return Err(refuse(path, format)),
        })
    }

    pub fn path(&self) -> &Path {
        match self {
            LogFile::Mcap(file) => &file.path,
            LogFile::Bag(file) => file.path(),
            LogFile::Sqlite(file) => file.path(),
            LogFile::Pcap(file) => file.path(),
        }
    }

    fn messages<'a>(
        &'a self,
        threads: usize,
        parts: Option<Parts<'a>>,
    ) -> Box<dyn Iterator<Item = std::result::Result<LogMessage, Damage>> + 'a> {
        match self {
            LogFile::Mcap(file) => Box::new(file.messages(threads, parts)),
            LogFile::Bag(file) => Box::new(BagMessages::new(file, threads, parts)),
            LogFile::Sqlite(file) => Box::new(file.messages(parts).map(whole_file_damage)),
            LogFile::Pcap(file) => Box::new(file.messages()),
        }
    }
}

/// A failure of a container read without chunks to step over: the end of it.
fn whole_file_damage(
    message: std::result::Result<LogMessage, String>,
) -> std::result::Result<LogMessage, Damage> {
    message.map_err(|problem| Damage {
        problem,
        chunk: None,
    })
}

/// A recorded log: one file, or the files of a rosbag2 directory in order.
pub struct Log {
    path: PathBuf,
    files: Vec<LogFile>,
    /// What the reader noticed and worked around (an unindexed bag, ...).
    notices: Vec<String>,
    /// Each message's data is a zstd frame (rosbag2's message compression).
    zstd_messages: bool,
    /// Storage files decompressed for reading (rosbag2's file compression), kept
    /// while the files are open.
    _decompressed: Option<tempfile::TempDir>,
}

impl Log {
    /// Opens the log at `path`, of a format [`crate::format::detect`] found.
    pub fn open(path: &Path, format: InputFormat) -> Result<Self> {
        let mut notices = Vec::new();
        let (files, zstd_messages, decompressed) = match format {
            InputFormat::Rosbag2 => {
                let directory = Rosbag2Directory::open(path)?;
                let files = (directory.storage.iter())
                    .map(|(file, format)| LogFile::open(file, *format))
                    .collect::<Result<Vec<_>>>()?;
                notices.extend(directory.notice);
                (files, directory.zstd_messages, directory.decompressed)
            }
            _ => (vec![LogFile::open(path, format)?], false, None),
        };
        let zstd_messages = zstd_messages
            || (files.iter()).any(|file| match file {
                LogFile::Sqlite(db3) => db3.zstd_messages,
                LogFile::Mcap(mcap) => mcap.zstd_messages,
                LogFile::Bag(_) | LogFile::Pcap(_) => false,
            });
        for file in &files {
            match file {
                LogFile::Bag(bag) => notices.extend(bag.notice().map(str::to_string)),
                LogFile::Mcap(mcap) => notices.extend(mcap.notice()),
                LogFile::Sqlite(db3) => notices.extend(db3.notice().map(str::to_string)),
                LogFile::Pcap(pcap) => notices.extend(pcap.notice().map(str::to_string)),
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            files,
            notices,
            zstd_messages,
            _decompressed: decompressed,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn notices(&self) -> &[String] {
        &self.notices
    }

    /// A capture's UDP datagrams in words (each port's count and sizes), for an
    /// error that finds no LiDAR among them; None for other logs.
    pub fn capture_datagrams(&self) -> Option<String> {
        self.files.iter().find_map(|file| match file {
            LogFile::Pcap(pcap) => Some(pcap.datagrams_by_port()),
            _ => None,
        })
    }

    /// Whether the log is a packet capture (pcap): no topics, no recorded metadata.
    pub fn is_capture(&self) -> bool {
        (self.files.iter()).any(|file| matches!(file, LogFile::Pcap(_)))
    }

    /// What each file cut short lost: everything recorded after its last complete
    /// record, in words.
    pub fn lost_to_cuts(&self) -> Vec<String> {
        (self.files.iter())
            .filter_map(|file| match file {
                LogFile::Mcap(mcap) => mcap.lost_to_cut(),
                _ => None,
            })
            .collect()
    }

    /// Whether a file of the log was cut short (read as far as it goes).
    pub fn is_cut(&self) -> bool {
        self.files
            .iter()
            .any(|file| matches!(file, LogFile::Mcap(mcap) if mcap.cut_at.is_some()))
    }

    /// A one-file MCAP log's chunks as stored, when they hold every message as
    /// it reads (not compressed one by one).
    pub fn stored(&self) -> Option<StoredLog> {
        match self.files.as_slice() {
            [LogFile::Mcap(file)] if !self.zstd_messages => file.stored(),
            _ => None,
        }
    }

    /// Every message of every file, in order; nothing after the first error but a
    /// lost stretch ([`Error::is_lost_stretch`]: a damaged chunk or message), after
    /// which the messages that follow it.
    /// As many chunks of an MCAP file are decompressed at once as there are threads.
    pub fn messages(&self) -> impl Iterator<Item = Result<LogMessage>> + '_ {
        self.messages_with(rayon::current_num_threads(), None)
    }

    /// [`Self::messages`], up to `threads` chunks decompressed at once (one beside
    /// the method's frames, which keep the cores busy: more only held more chunks
    /// in memory there, for no gain), and of each message the [`Part`] `parts`
    /// says (of a ROS 1 bag's, all). A message of a Foxglove schema in protobuf
    /// comes as its ROS 2 equivalent ([`foxglove::to_cdr`]; `parts` is asked by
    /// that type's name); one that does not read is lost, as a damaged one is.
    pub fn messages_in_parts<'a>(
        &'a self,
        threads: usize,
        parts: Parts<'a>,
    ) -> impl Iterator<Item = Result<LogMessage>> + 'a {
        self.messages_with(threads, Some(parts))
    }

    fn messages_with<'a>(
        &'a self,
        threads: usize,
        parts: Option<Parts<'a>>,
    ) -> impl Iterator<Item = Result<LogMessage>> + 'a {
        let mut failed = false;
        // A compressed message is read whole (its header is inside the frame), then
        // decompressed as far as its part asks.
        // So is a Foxglove one: its header may follow its payload.
        let stored_parts: Option<Parts<'a>> = parts.clone().map(|parts| -> Parts<'a> {
            let zstd_messages = self.zstd_messages;
            Arc::new(move |topic: &str, schema: &str| {
                let (part, foxglove) = match foxglove::ros_equivalent(schema) {
                    Some((ros, _)) => (parts(topic, ros), true),
                    None => (parts(topic, schema), false),
                };
                match part {
                    Part::Header if zstd_messages || foxglove => Part::Whole,
                    part => part,
                }
            })
        });
        self.files
            .iter()
            .flat_map(move |file| {
                let parts = parts.clone();
                let mut translated = HashMap::new();
                let lost = move |ordinal, (topic, log_time_ns), problem| {
                    Error::LogMessageLost(LostMessage {
                        path: file.path().to_path_buf(),
                        ordinal,
                        topic,
                        log_time_ns,
                        problem,
                    })
                };
                file.messages(threads, stored_parts.clone())
                    .enumerate()
                    .map(move |(ordinal, message)| {
                        let mut message = match message {
                            Ok(message) => message,
                            Err(Damage {
                                problem,
                                chunk: Some(chunk),
                            }) => {
                                return Err(Error::LogChunk {
                                    path: file.path().to_path_buf(),
                                    offset: chunk.bytes.start,
                                    start_s: chunk.start_ns as f64 * 1e-9,
                                    end_s: chunk.end_ns as f64 * 1e-9,
                                    problem,
                                    lost: chunk.lost,
                                });
                            }
                            Err(Damage { problem, .. }) => {
                                return Err(Error::LogRecord {
                                    path: file.path().to_path_buf(),
                                    ordinal,
                                    problem,
                                });
                            }
                        };
                        let recorded = message.connection.clone();
                        if self.zstd_messages {
                            let part = (parts.as_ref())
                                .map_or(Part::Whole, |p| p(&recorded.topic, &recorded.schema_name));
                            let at = (recorded.topic.clone(), message.log_time_ns);
                            message = decompressed(message, part)
                                .map_err(|problem| lost(ordinal, at, problem))?;
                        }
                        match &parts {
                            Some(parts) if foxglove::reads(&recorded.message_encoding) => {
                                let at = (recorded.topic.clone(), message.log_time_ns);
                                as_ros2(message, parts, &mut translated)
                                    .map_err(|problem| lost(ordinal, at, problem))
                            }
                            _ => Ok(message),
                        }
                    })
            })
            .take_while(move |message| {
                let go_on = !failed;
                failed |= matches!(message, Err(error) if !error.is_lost_stretch());
                go_on
            })
    }
}

/// A message of a Foxglove schema as its ROS 2 equivalent, as much of it as `parts`
/// asks, on a connection made once per topic (`connections`); another protobuf
/// message as it is.
fn as_ros2(
    message: LogMessage,
    parts: &Parts<'_>,
    connections: &mut HashMap<String, Arc<Connection>>,
) -> std::result::Result<LogMessage, String> {
    let recorded = &message.connection;
    let Some((name, schema)) = foxglove::ros_equivalent(&recorded.schema_name) else {
        return Ok(message);
    };
    let data = match parts(&recorded.topic, name) {
        Part::Nothing => Vec::new(),
        part => foxglove::to_cdr(
            &recorded.schema_name,
            &recorded.message_encoding,
            &message.data,
            part,
        )?,
    };
    let connection = match connections.get(&recorded.topic) {
        Some(connection) => connection.clone(),
        None => {
            let connection = Arc::new(Connection {
                topic: recorded.topic.clone(),
                schema_name: name.into(),
                schema_encoding: "ros2msg".into(),
                schema_data: schema.as_bytes().to_vec(),
                message_encoding: "cdr".into(),
            });
            connections.insert(recorded.topic.clone(), connection.clone());
            connection
        }
    };
    Ok(LogMessage {
        connection,
        data,
        ..message
    })
}

/// The most a compressed message may decompress to.
const LARGEST_MESSAGE: u64 = 1 << 30;

/// A message of a log compressed message by message (rosbag2's zstd message mode),
/// its data decompressed as far as `part` asks.
fn decompressed(mut message: LogMessage, part: Part) -> std::result::Result<LogMessage, String> {
    let limit = match part {
        Part::Nothing => return Ok(message),
        Part::Header => HEADER_BYTES as u64,
        Part::Whole => LARGEST_MESSAGE + 1,
    };
    let mut data = Vec::new();
    zstd::stream::read::Decoder::new(&message.data[..])
        .and_then(|decoder| decoder.take(limit).read_to_end(&mut data))
        .map_err(|e| format!("it does not decompress (zstd): {e}"))?;
    if data.len() as u64 > LARGEST_MESSAGE {
        return Err(format!(
            "it decompresses to more than {LARGEST_MESSAGE} bytes"
        ));
    }
    message.data = data;
    Ok(message)
}

/// An MCAP file, memory-mapped, its chunk sizes checked at open.
pub struct McapFile {
    path: PathBuf,
    file: FileMap,
    /// The memory map, shared with chunks copied from it (see [`stored_log`]).
    map: bytes::Bytes,
    /// For a file cut short: where its last complete record ends.
    cut_at: Option<usize>,
    /// Cut or not, its data section is whole (its DataEnd record read).
    data_complete: bool,
    /// Damaged stretches its messages step over.
    damaged: Vec<(ChunkSpan, String)>,
    /// Its own copy of a rosbag2 bag's metadata says each message is a zstd frame.
    zstd_messages: bool,
}

impl McapFile {
    pub fn open(path: &Path) -> Result<Self> {
        let file = FileMap::open(path)?;
        let map = file.bytes();
        let layout = check_chunk_sizes(&map).map_err(|problem| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        })?;
        file.release(0..map.len());
        let zstd_messages = (layout.rosbag2_metadata.as_deref())
            .map(says_zstd_messages)
            .transpose()
            .map_err(|problem| Error::LogContainer {
                path: path.to_path_buf(),
                problem,
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            map,
            cut_at: layout.cut_at,
            data_complete: layout.data_complete,
            damaged: layout.damaged,
            zstd_messages: zstd_messages.unwrap_or(false),
        })
    }

    /// What a file cut short lost: None for a whole file.
    fn lost_to_cut(&self) -> Option<String> {
        let cut_at = self.cut_at.filter(|_| !self.data_complete)?;
        Some(format!(
            "{}: cut short at byte {} (no summary, no closing magic): what was recorded after its last complete record, at byte {cut_at}, is lost",
            self.path.display(),
            self.map.len()
        ))
    }

    /// What a file cut short holds, for a notice: None for a whole file.
    pub fn notice(&self) -> Option<String> {
        let cut_at = self.cut_at?;
        Some(format!(
            "{}: the file ends at byte {} without its summary and closing magic (a recording cut short?): reading its complete records, up to byte {cut_at}; `mcap recover` rewrites such a file whole",
            self.path.display(),
            self.map.len()
        ))
    }

    /// Its chunks as stored, when they hold every message (see [`stored_log`]); a
    /// file cut short has no summary to check them by.
    pub fn stored(&self) -> Option<StoredLog> {
        if self.cut_at.is_some() {
            return None;
        }
        let mut log = stored_log(&self.map)?;
        for chunk in &mut log.chunks {
            let end = chunk.offset + chunk.record.len() + chunk.message_indexes.len();
            chunk.release = Some(Release(self.file.clone(), chunk.offset..end));
        }
        Some(log)
    }

    fn messages<'a>(
        &'a self,
        threads: usize,
        parts: Option<Parts<'a>>,
    ) -> impl Iterator<Item = std::result::Result<LogMessage, Damage>> + 'a {
        let mut connections: HashMap<u16, Arc<Connection>> = HashMap::new();
        let readable = &self.map[..self.cut_at.unwrap_or(self.map.len())];
        let messages = Messages::new(readable, Some(&self.file), threads, parts);
        messages
            .stepping_over(self.damaged.clone())
            .map(move |message| {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn foxglove_message(schema_name: &str, data: Vec<u8>) -> LogMessage {
        LogMessage {
            connection: Arc::new(Connection {
                topic: "/tf".into(),
                schema_name: schema_name.into(),
                schema_encoding: foxglove::PROTOBUF.into(),
                schema_data: Vec::new(),
                message_encoding: foxglove::PROTOBUF.into(),
            }),
            log_time_ns: 7,
            publish_time_ns: 7,
            data,
        }
    }

    #[test]
    fn foxglove_messages_come_as_ros2_ones_on_one_connection_per_topic() {
        let parts: Parts = Arc::new(|_: &str, _: &str| Part::Whole);
        let mut connections = HashMap::new();
        // FrameTransforms holding one transform map -> base_link.
        let transform = [0x12, 3, b'm', b'a', b'p', 0x1a, 1, b'b'];
        let mut data = vec![0x0a, transform.len() as u8];
        data.extend(transform);
        let read = |data: Vec<u8>, connections: &mut HashMap<_, _>| {
            as_ros2(
                foxglove_message("foxglove.FrameTransforms", data),
                &parts,
                connections,
            )
        };
        let first = read(data.clone(), &mut connections).unwrap();
        let second = read(data, &mut connections).unwrap();
        assert_eq!(first.connection.schema_name, "tf2_msgs/msg/TFMessage");
        assert_eq!(first.connection.message_encoding, "cdr");
        assert!(Arc::ptr_eq(&first.connection, &second.connection));
        let tf: travmap_formats::ros::TfMessage =
            travmap_formats::ros::decode(&first.data).unwrap();
        assert_eq!(tf.transforms[0].header.frame_id, "map");
        assert_eq!(first.log_time_ns, 7);
        // A message cut inside a field does not read (the pass loses it, naming
        // the file, the message, its topic and log time).
        let problem = read(vec![0x0a, 40, 0x12], &mut connections).unwrap_err();
        assert!(
            problem.starts_with("foxglove.FrameTransforms (protobuf): field 1: 40 bytes"),
            "{problem}"
        );
        // Protobuf of a schema travmap does not read passes as it is.
        let other = as_ros2(
            foxglove_message("foxglove.SceneUpdate", vec![1]),
            &parts,
            &mut connections,
        );
        assert_eq!(
            other.unwrap().connection.schema_name,
            "foxglove.SceneUpdate"
        );
    }
}
