//! rosbag2's sqlite3 storage: a `.db3` file's topics and messages.
//!
//! SQLite is the bundled library (no system one needed), and a `.db3` is opened
//! immutable and read-only: reading never creates a journal or `-shm` file beside an
//! input (one with a write-ahead log beside it is read from a copy:
//! `super::sqlite_wal`). Messages come in the order they were written (their row
//! ids), as they do from an MCAP file.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rusqlite::{MAIN_DB, OpenFlags, params};

use super::rosbag2::says_zstd_messages;
use super::sqlite_wal::Readable;
use travmap_core::error::{Error, Result};
use travmap_formats::log_message::{
    Connection, FileMessages, HEADER_BYTES, LogMessage, Part, Parts,
};

/// Rows read from the `messages` table per query, at most.
const PAGE_ROWS: usize = 256;
/// Message bytes a page holds at most (past it, the next row begins the next page):
/// 256 rows of LiDAR scans and images held several hundred MB at once.
const PAGE_BYTES: usize = 16 << 20;

/// A rosbag2 sqlite3 file: its topics read at open, its messages streamed.
pub struct SqliteFile {
    path: PathBuf,
    /// Where its messages are read from: the file, or a copy with its log.
    readable: Readable,
    connections: HashMap<i64, Arc<Connection>>,
    /// Its own metadata (rosbag2 Iron and later keep a copy in the file) says each
    /// message is a zstd frame: read when the file is given without its directory.
    pub zstd_messages: bool,
}

impl SqliteFile {
    pub fn open(path: &Path) -> Result<Self> {
        let readable = Readable::of(path)?;
        let database = open_database(path, &readable)?;
        let container = |problem| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        };
        let connections = topics(&database).map_err(container)?;
        let zstd_messages = (own_metadata(&database).as_deref())
            .map(says_zstd_messages)
            .transpose()
            .map_err(container)?;
        Ok(Self {
            path: path.to_path_buf(),
            readable,
            connections,
            zstd_messages: zstd_messages.unwrap_or(false),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Said when its messages are read from a copy (see `Readable`).
    pub fn notice(&self) -> Option<&str> {
        self.readable.notice.as_deref()
    }

    /// The messages in row order, a page at a time: each page is its own query, so
    /// no statement outlives a call (the database handle is not shared between
    /// threads either). Of each message, the [`Part`] `parts` says: SQLite leaves
    /// the rest of a blob on disk.
    pub fn messages<'a>(&'a self, parts: Option<Parts<'a>>) -> FileMessages<'a> {
        let database = match open_database(&self.path, &self.readable) {
            Ok(database) => database,
            Err(error) => return Box::new(std::iter::once(Err(error.to_string()))),
        };
        // The topics not read whole, by id, and how much of them is.
        let mut partial_topics: Vec<(i64, Part)> = (self.connections.iter())
            .filter_map(|(&id, c)| Some((id, parts.as_ref()?(&c.topic, &c.schema_name))))
            .filter(|&(_, part)| part != Part::Whole)
            .collect();
        partial_topics.sort_unstable_by_key(|&(id, _)| id);
        let mut page: VecDeque<std::result::Result<LogMessage, String>> = VecDeque::new();
        let mut after_id = i64::MIN;
        let mut done = false;
        Box::new(std::iter::from_fn(move || {
            if page.is_empty() && !done {
                match self.page(&database, after_id, &partial_topics) {
                    Ok((rows, last_id, exhausted)) => {
                        done = exhausted;
                        after_id = last_id.unwrap_or(after_id);
                        page.extend(rows.into_iter().map(Ok));
                    }
                    Err(problem) => {
                        done = true;
                        page.push_back(Err(problem));
                    }
                }
            }
            page.pop_front()
        }))
    }

    /// Up to [`PAGE_ROWS`] messages (and about [`PAGE_BYTES`]) after row `after_id`,
    /// the last row's id, and whether the table ended there; of the rows on
    /// `partial_topics` only the part of the data they say.
    fn page(
        &self,
        database: &rusqlite::Connection,
        after_id: i64,
        partial_topics: &[(i64, Part)],
    ) -> std::result::Result<(Vec<LogMessage>, Option<i64>, bool), String> {
        // SQLite reads a column only when it is used: a partial row's blob is left
        // unread here, and its header read below.
        let ids: Vec<String> = partial_topics
            .iter()
            .map(|(id, _)| id.to_string())
            .collect();
        let sql = format!(
            "SELECT id, topic_id, timestamp, CASE WHEN topic_id IN ({}) THEN NULL ELSE data END, \
             rowid FROM messages WHERE id > ?1 ORDER BY id LIMIT ?2",
            ids.join(",")
        );
        let mut statement = database
            .prepare_cached(&sql)
            .map_err(unreadable(MESSAGES_COLUMNS))?;
        let mut rows = statement
            .query(params![after_id, PAGE_ROWS as i64])
            .map_err(unreadable(MESSAGES_COLUMNS))?;
        let mut messages = Vec::with_capacity(PAGE_ROWS);
        let (mut last_id, mut bytes) = (None, 0);
        while let Some(row) = rows
            .next()
            .map_err(|e| format!("the messages table after row {after_id}: {e}"))?
        {
            let read = |e: rusqlite::Error| format!("message row after {after_id}: {e}");
            let id: i64 = row.get(0).map_err(read)?;
            let topic_id: i64 = row.get(1).map_err(read)?;
            let timestamp: i64 = row.get(2).map_err(read)?;
            let part = partial_topics
                .binary_search_by_key(&topic_id, |&(id, _)| id)
                .map_or(Part::Whole, |at| partial_topics[at].1);
            let data: Vec<u8> = match part {
                Part::Whole => row.get(3).map_err(read)?,
                Part::Header => header_of(database, row.get(4).map_err(read)?).map_err(read)?,
                Part::Nothing => Vec::new(),
            };
            bytes += data.len();
            let connection = self.connections.get(&topic_id).ok_or_else(|| {
                format!("message row {id} is on topic id {topic_id}, which the topics table does not list")
            })?;
            let stamp_ns = u64::try_from(timestamp)
                .map_err(|_| format!("message row {id} has a negative timestamp {timestamp}"))?;
            messages.push(LogMessage {
                connection: connection.clone(),
                log_time_ns: stamp_ns,
                publish_time_ns: stamp_ns,
                data,
            });
            last_id = Some(id);
            if bytes >= PAGE_BYTES {
                return Ok((messages, last_id, false));
            }
        }
        let exhausted = messages.len() < PAGE_ROWS;
        Ok((messages, last_id, exhausted))
    }
}

/// The first [`HEADER_BYTES`] of the data of row `rowid`, read from the blob alone.
fn header_of(database: &rusqlite::Connection, rowid: i64) -> rusqlite::Result<Vec<u8>> {
    let blob = database.blob_open(MAIN_DB, c"messages", c"data", rowid, true)?;
    let mut header = vec![0; blob.len().min(HEADER_BYTES)];
    blob.read_at_exact(&mut header, 0)?;
    Ok(header)
}

/// `path` opened read-only and immutable (see the module's comment); or, for a
/// file with a write-ahead log, its copy, as SQLite opens a file with a log (it
/// writes the `-shm` index of the log beside the copy).
fn open_database(path: &Path, readable: &Readable) -> Result<rusqlite::Connection> {
    let (uri, flags) = match readable.immutable {
        true => (
            format!("file:{}?immutable=1", uri_path(&readable.path)),
            OpenFlags::SQLITE_OPEN_READ_ONLY,
        ),
        false => (
            format!("file:{}", uri_path(&readable.path)),
            OpenFlags::SQLITE_OPEN_READ_WRITE,
        ),
    };
    let flags = flags | OpenFlags::SQLITE_OPEN_URI | OpenFlags::SQLITE_OPEN_NO_MUTEX;
    rusqlite::Connection::open_with_flags(uri, flags).map_err(|e| Error::LogContainer {
        path: path.to_path_buf(),
        problem: format!("cannot open as sqlite3: {e}"),
    })
}

/// The bag's metadata a `.db3` holds in its `metadata` table, when it has one.
pub(crate) fn own_metadata(database: &rusqlite::Connection) -> Option<String> {
    database
        .query_row("SELECT metadata FROM metadata LIMIT 1", [], |row| {
            row.get(0)
        })
        .ok()
}

/// An absolute path percent-encoded for an SQLite URI.
fn uri_path(path: &Path) -> String {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut out = String::new();
    for byte in absolute.as_os_str().as_encoded_bytes() {
        match byte {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'/' | b'-' | b'_' | b'.' | b'~' => {
                out.push(*byte as char)
            }
            other => out.push_str(&format!("%{other:02X}")),
        }
    }
    out
}

/// What rosbag2 writes in the tables travmap reads.
const TOPICS_COLUMNS: &str = "rosbag2's `topics` table: id, name, type, serialization_format";
const DEFINITIONS_COLUMNS: &str =
    "rosbag2's `message_definitions` table: topic_type, encoding, encoded_message_definition";
const MESSAGES_COLUMNS: &str = "rosbag2's `messages` table: id, topic_id, timestamp, data";

/// A database error in words, without the SQL it came from, and what rosbag2 writes
/// there (`expected`).
fn unreadable(expected: &str) -> impl Fn(rusqlite::Error) -> String + '_ {
    move |e| {
        let problem = match &e {
            rusqlite::Error::SqlInputError { msg, .. } => msg.clone(),
            other => other.to_string(),
        };
        format!("not a rosbag2 database: {problem} (expected: {expected})")
    }
}

/// The topics table, with each type's definition where the file has one (rosbag2
/// from Iron on keeps them in `message_definitions`).
fn topics(
    database: &rusqlite::Connection,
) -> std::result::Result<HashMap<i64, Arc<Connection>>, String> {
    let has_definitions: bool = database
        .query_row(
            "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'message_definitions'",
            [],
            |row| row.get::<_, i64>(0),
        )
        .map_err(unreadable("an SQLite file"))?
        > 0;
    let mut definitions: HashMap<String, (String, Vec<u8>)> = HashMap::new();
    if has_definitions {
        let mut statement = database
            .prepare(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions",
            )
            .map_err(unreadable(DEFINITIONS_COLUMNS))?;
        let rows = statement
            .query_map([], |row| {
                Ok((
                    row.get::<_, String>(0)?,
                    row.get::<_, String>(1)?,
                    row.get::<_, String>(2)?,
                ))
            })
            .map_err(unreadable(DEFINITIONS_COLUMNS))?;
        for row in rows {
            let (topic_type, encoding, text) = row.map_err(unreadable(DEFINITIONS_COLUMNS))?;
            if encoding != "unknown" {
                definitions.insert(topic_type, (encoding, text.into_bytes()));
            }
        }
    }
    let mut statement = database
        .prepare("SELECT id, name, type, serialization_format FROM topics")
        .map_err(unreadable(TOPICS_COLUMNS))?;
    let rows = statement
        .query_map([], |row| {
            Ok((
                row.get::<_, i64>(0)?,
                row.get::<_, String>(1)?,
                row.get::<_, String>(2)?,
                row.get::<_, String>(3)?,
            ))
        })
        .map_err(unreadable(TOPICS_COLUMNS))?;
    let mut connections = HashMap::new();
    for row in rows {
        let (id, topic, schema_name, mut message_encoding) =
            row.map_err(unreadable(TOPICS_COLUMNS))?;
        // Some writers leave it empty (nebula's VLS-128 test bag); rosbag2 then plays
        // the messages as CDR, its one serialisation.
        if message_encoding.is_empty() {
            message_encoding = "cdr".into();
        }
        let (schema_encoding, schema_data) =
            definitions.get(&schema_name).cloned().unwrap_or_default();
        connections.insert(
            id,
            Arc::new(Connection {
                topic,
                schema_name,
                schema_encoding,
                schema_data,
                message_encoding,
            }),
        );
    }
    Ok(connections)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uri_paths_escape_what_sqlite_would_read_as_syntax() {
        assert_eq!(
            uri_path(Path::new("/d/a b?c#d%e.db3")),
            "/d/a%20b%3Fc%23d%25e.db3"
        );
    }

    #[test]
    fn a_topic_without_serialization_format_is_read_as_cdr() {
        let database = rusqlite::Connection::open_in_memory().unwrap();
        database
            .execute_batch(
                "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT,
                     serialization_format TEXT, offered_qos_profiles TEXT);
                 INSERT INTO topics VALUES (1, '/velodyne_packets', 'velodyne_msgs/msg/VelodyneScan', '', '');",
            )
            .unwrap();
        let connections = topics(&database).unwrap();
        assert_eq!(connections[&1].message_encoding, "cdr");
    }

    #[test]
    fn large_rows_are_paged_by_bytes_and_header_types_read_only_in_part() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("drive.db3");
        let database = rusqlite::Connection::open(&path).unwrap();
        database
            .execute_batch(
                "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT,
                     serialization_format TEXT, offered_qos_profiles TEXT);
                 CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER,
                     timestamp INTEGER, data BLOB);
                 INSERT INTO topics VALUES (1, '/points', 'sensor_msgs/msg/PointCloud2', 'cdr', '');
                 INSERT INTO topics VALUES (2, '/tf', 'tf2_msgs/msg/TFMessage', 'cdr', '');",
            )
            .unwrap();
        // 400 KB scans, 40 MB in all (pages of 16 MiB), a small message after each.
        let scan = |i: i64| -> Vec<u8> { (0..400_000).map(|j| (i + j) as u8).collect() };
        for i in 0..100i64 {
            let insert = "INSERT INTO messages (topic_id, timestamp, data) VALUES (?1, ?2, ?3)";
            database
                .execute(insert, params![1, 2 * i, scan(i)])
                .unwrap();
            database
                .execute(insert, params![2, 2 * i + 1, vec![i as u8; 5]])
                .unwrap();
        }
        drop(database);
        let file = SqliteFile::open(&path).unwrap();
        for part in [
            None,
            Some(Part::Whole),
            Some(Part::Header),
            Some(Part::Nothing),
        ] {
            let of_scans = |_: &str, schema: &str| match schema {
                "sensor_msgs/msg/PointCloud2" => part.unwrap_or(Part::Whole),
                _ => Part::Whole,
            };
            let parts: Option<Parts> = part.map(|_| Arc::new(of_scans) as Parts);
            let messages: Vec<_> = file
                .messages(parts)
                .collect::<std::result::Result<_, _>>()
                .unwrap();
            assert_eq!(messages.len(), 200);
            for (i, message) in (0..).zip(&messages) {
                assert_eq!(message.log_time_ns, i as u64);
                let expected = match i % 2 {
                    0 => scan(i / 2),
                    _ => vec![(i / 2) as u8; 5],
                };
                let kept = match (part, i % 2) {
                    (Some(Part::Header), 0) => HEADER_BYTES,
                    (Some(Part::Nothing), 0) => 0,
                    _ => expected.len(),
                };
                assert_eq!(message.data, expected[..kept], "message {i}");
            }
        }
    }

    #[test]
    fn a_database_is_read_without_writing_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("drive.db3");
        {
            let database = rusqlite::Connection::open(&path).unwrap();
            database
                .execute_batch(
                    "PRAGMA journal_mode=WAL;
                     CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT,
                         serialization_format TEXT, offered_qos_profiles TEXT);
                     CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER,
                         timestamp INTEGER, data BLOB);
                     INSERT INTO topics VALUES (1, '/chatter', 'std_msgs/msg/String', 'cdr', '');",
                )
                .unwrap();
            for i in 0..600i64 {
                database
                    .execute(
                        "INSERT INTO messages (topic_id, timestamp, data) VALUES (1, ?1, ?2)",
                        params![i * 10, vec![i as u8; 3]],
                    )
                    .unwrap();
            }
        }
        let before: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        let file = SqliteFile::open(&path).unwrap();
        let messages: Vec<_> = file
            .messages(None)
            .collect::<std::result::Result<_, _>>()
            .unwrap();
        assert_eq!(messages.len(), 600);
        assert_eq!(messages[599].log_time_ns, 5990);
        assert_eq!(messages[599].data, vec![87u8; 3]);
        assert_eq!(messages[0].connection.type_name(), "std_msgs/msg/String");
        let after: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(before, after);
    }
}
