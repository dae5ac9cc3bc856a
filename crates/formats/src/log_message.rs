//! What every log container yields, and where it reads from: a [`LogMessage`] with
//! its [`Connection`] (topic, type, encodings), and the read-only [`FileMap`] of a
//! file. The containers ([`crate::mcap::records`], the readers' ROS 1 bag and rosbag2 containers)
//! produce these; the readers' `Log` (`travmap_io::Log`) composes them into one stream.

use std::borrow::Cow;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use super::ros::MessageEncoding;
use travmap_core::error::{Error, Result};

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
        ros2_type_name(&self.schema_name)
    }

    /// The encoding, when travmap reads it.
    pub fn encoding(&self) -> Option<MessageEncoding> {
        MessageEncoding::from_name(&self.message_encoding)
    }
}

/// A message type's ROS 2 name: ROS 1's `package/Type` as `package/msg/Type`.
pub fn ros2_type_name(schema_name: &str) -> Cow<'_, str> {
    match schema_name.split_once('/') {
        Some((package, name)) if !name.contains('/') => Cow::Owned(format!("{package}/msg/{name}")),
        _ => Cow::Borrowed(schema_name),
    }
}

/// How much of a message a pass reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    Whole,
    /// Its first [`HEADER_BYTES`]: a pass that needs a cloud's or an image's header
    /// need not copy (or, from SQLite, read) its megabytes.
    Header,
    /// None of its bytes (the message comes with empty data): a topic the pass
    /// does not use.
    Nothing,
}

/// Of a pass: how much of each message to read, by its topic and its type (the
/// schema name as recorded).
pub type Parts<'a> = Arc<dyn Fn(&str, &str) -> Part + Send + Sync + 'a>;

/// What a [`Part::Header`] message keeps of its bytes: more than any header needs.
pub const HEADER_BYTES: usize = 64 * 1024;

/// The bytes of a message's `data` that `part` asks for.
pub fn part_of(data: &[u8], part: Part) -> Vec<u8> {
    match part {
        Part::Whole => data.to_vec(),
        Part::Header => data[..data.len().min(HEADER_BYTES)].to_vec(),
        Part::Nothing => Vec::new(),
    }
}

/// `f` of every item, in order, each on its own scoped thread (the first on this
/// one): not the rayon pool, which the method's frames may be keeping busy.
pub fn in_parallel<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let mut items = items.into_iter();
    let Some(first) = items.next() else {
        return Vec::new();
    };
    std::thread::scope(|scope| {
        let f = &f;
        let others: Vec<_> = items.map(|item| scope.spawn(move || f(item))).collect();
        let mut results = vec![f(first)];
        results.extend(
            others
                .into_iter()
                .map(|other| other.join().expect("a decompressing thread panicked")),
        );
        results
    })
}

/// One recorded message, undecoded.
#[derive(Debug)]
pub struct LogMessage {
    pub connection: Arc<Connection>,
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    pub data: Vec<u8>,
}

/// Where a chunk lies in the file and the log times of its messages: what a reader
/// needs to step over a damaged one and name it.
#[derive(Clone, Debug, PartialEq)]
pub struct ChunkSpan {
    pub bytes: std::ops::Range<usize>,
    pub start_ns: u64,
    pub end_ns: u64,
    /// The messages its damage lost, topic and log time in log order, where the file
    /// lists them apart from the damage (an MCAP's message indexes); empty where not.
    pub lost: Vec<(String, u64)>,
}

/// Why a message could not be read; with `chunk`, only that chunk's messages are
/// lost and reading goes on after it.
#[derive(Debug)]
pub struct Damage {
    pub problem: String,
    pub chunk: Option<ChunkSpan>,
}

/// A stream of messages of one file; an error names where in the file it is.
pub type FileMessages<'a> = Box<dyn Iterator<Item = std::result::Result<LogMessage, String>> + 'a>;

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
