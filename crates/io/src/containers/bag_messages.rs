//! The messages of a ROS 1 bag ([`super::bag::BagFile`]), in file order: its chunks
//! decompressed a batch at a time on as many threads as the pass may use (a bz2
//! chunk decompresses at tens of MB/s), each message's records copied as far as
//! the pass asks.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use super::bag::{BagFile, Record, connection, op, stamp_ns};
use travmap_formats::log_message::{
    ChunkSpan, Connection, Damage, LogMessage, Parts, in_parallel, part_of,
};

/// The messages of a bag, streamed chunk by chunk: see [`BagMessages::new`].
pub struct BagMessages<'a> {
    bag: &'a BagFile,
    connections: HashMap<u32, Arc<Connection>>,
    parts: Option<Parts<'a>>,
    threads: usize,
    /// Chunks decompressed ahead, in file order: each its index and its records, or
    /// why they cannot be read.
    ready: VecDeque<(usize, Result<Vec<u8>, String>)>,
    /// The next chunk to decompress, and the one being read.
    next_chunk: usize,
    current: usize,
    /// The current chunk's records and where the next one starts.
    chunk: Vec<u8>,
    at: usize,
    /// Buffers of chunks read, for the next ones.
    spare: Vec<Vec<u8>>,
    failed: bool,
}

impl<'a> BagMessages<'a> {
    /// Every message of `bag` in file order, of each the `Part` `parts` says
    /// (all of it when None); up to `threads` chunks decompressed at once.
    pub fn new(bag: &'a BagFile, threads: usize, parts: Option<Parts<'a>>) -> Self {
        Self {
            bag,
            connections: bag.connections().clone(),
            parts,
            threads: threads.max(1),
            ready: VecDeque::new(),
            next_chunk: 0,
            current: 0,
            chunk: Vec::new(),
            at: 0,
            spare: Vec::new(),
            failed: false,
        }
    }

    /// Decompresses the next `threads` chunks, side by side.
    fn fill(&mut self) {
        let chunks = self.bag.chunks();
        let batch: Vec<(usize, Vec<u8>)> = (self.next_chunk..chunks.len())
            .take(self.threads)
            .map(|index| (index, self.spare.pop().unwrap_or_default()))
            .collect();
        self.next_chunk += batch.len();
        let bag = self.bag;
        let read = in_parallel(batch, |(index, mut records)| {
            let read = bag.chunk(chunks[index].0, &mut records);
            (index, read.map(|()| records))
        });
        self.ready.extend(read);
    }

    /// A chunk's damage: with its log times from the index, the rest of the chunk
    /// is lost and reading goes on after it; without, it is the end.
    fn damage(&mut self, problem: String) -> Damage {
        let (offset, times) = self.bag.chunks()[self.current];
        self.chunk.clear();
        Damage {
            problem,
            chunk: times.map(|(start_ns, end_ns)| ChunkSpan {
                bytes: offset..offset,
                start_ns,
                end_ns,
                lost: Vec::new(),
            }),
        }
    }

    fn next_message(&mut self) -> Option<std::result::Result<LogMessage, Damage>> {
        self.next_in_chunk()
            .map(|message| message.map_err(|problem| self.damage(problem)))
    }

    fn next_in_chunk(&mut self) -> Option<std::result::Result<LogMessage, String>> {
        loop {
            if self.at >= self.chunk.len() {
                if self.ready.is_empty() {
                    self.fill();
                }
                let (index, read) = self.ready.pop_front()?;
                self.current = index;
                self.at = 0;
                match read {
                    Ok(records) => {
                        let done = std::mem::replace(&mut self.chunk, records);
                        self.spare.push(done);
                    }
                    Err(problem) => return Some(Err(problem)),
                }
                continue;
            }
            let (chunk_offset, _) = self.bag.chunks()[self.current];
            let in_chunk =
                |problem: String| format!("in the chunk at byte {chunk_offset}, {problem}");
            let record = match Record::at(&self.chunk, self.at) {
                Ok(record) => record,
                Err(problem) => return Some(Err(in_chunk(problem))),
            };
            self.at = record.end;
            match record.op() {
                Ok(op::CONNECTION) => match connection(&record) {
                    Ok((id, connection)) => {
                        self.connections
                            .entry(id)
                            .or_insert_with(|| Arc::new(connection));
                    }
                    Err(problem) => return Some(Err(in_chunk(problem))),
                },
                Ok(op::MESSAGE_DATA) => return Some(self.message(&record).map_err(in_chunk)),
                Ok(_) => {}
                Err(problem) => return Some(Err(in_chunk(problem))),
            }
        }
    }

    fn message(&self, record: &Record) -> std::result::Result<LogMessage, String> {
        let id = record.u32("conn")?;
        let connection = self.connections.get(&id).ok_or_else(|| {
            format!(
                "the message at byte {} is on connection {id}, which no connection record defines",
                record.offset
            )
        })?;
        let stamp_ns = stamp_ns(record.u64("time")?);
        let data = match &self.parts {
            None => record.data.to_vec(),
            Some(parts) => part_of(
                record.data,
                parts(&connection.topic, &connection.schema_name),
            ),
        };
        Ok(LogMessage {
            connection: connection.clone(),
            log_time_ns: stamp_ns,
            publish_time_ns: stamp_ns,
            data,
        })
    }
}

impl Iterator for BagMessages<'_> {
    type Item = std::result::Result<LogMessage, Damage>;

    /// Nothing after the first error but a damaged chunk's (see [`Damage`]).
    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let next = self.next_message();
        self.failed = matches!(next, Some(Err(Damage { chunk: None, .. })));
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::containers::bag::{BagFile, op};
    use crate::format::BAG_MAGIC;
    use travmap_core::error::Result;
    use travmap_formats::log_message::Part;

    fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut out = ((name.len() + 1 + value.len()) as u32)
            .to_le_bytes()
            .to_vec();
        out.extend_from_slice(name.as_bytes());
        out.push(b'=');
        out.extend_from_slice(value);
        out
    }

    fn record(fields: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
        let header: Vec<u8> = fields.concat();
        let mut out = (header.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(&header);
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(data);
        out
    }

    /// A bag of one chunk holding one connection and one message, without an index.
    fn unindexed_bag(message: &[u8]) -> Vec<u8> {
        unindexed_bag_of(&[message])
    }

    /// A bag without an index: a chunk per message, each holding the connection
    /// and its message.
    fn unindexed_bag_of(messages: &[&[u8]]) -> Vec<u8> {
        let connection = record(
            &[
                field("op", &[op::CONNECTION]),
                field("conn", &0u32.to_le_bytes()),
                field("topic", b"/chatter"),
            ],
            &[
                field("topic", b"/chatter"),
                field("type", b"std_msgs/String"),
                field("md5sum", b"992ce8a1687cec8c8bd883ec73ca41d1"),
                field("message_definition", b"string data\n"),
            ]
            .concat(),
        );
        // uint32 seconds (7), then uint32 nanoseconds (5).
        let time = (5u64 << 32) | 7;
        let chunk = |message: &[u8]| {
            let message = record(
                &[
                    field("op", &[op::MESSAGE_DATA]),
                    field("conn", &0u32.to_le_bytes()),
                    field("time", &time.to_le_bytes()),
                ],
                message,
            );
            let records = [connection.clone(), message].concat();
            record(
                &[
                    field("op", &[op::CHUNK]),
                    field("compression", b"none"),
                    field("size", &(records.len() as u32).to_le_bytes()),
                ],
                &records,
            )
        };
        let header = record(
            &[
                field("op", &[op::BAG_HEADER]),
                field("index_pos", &0u64.to_le_bytes()),
                field("conn_count", &0u32.to_le_bytes()),
                field("chunk_count", &0u32.to_le_bytes()),
            ],
            &[],
        );
        let chunks = messages.iter().map(|message| chunk(message));
        [BAG_MAGIC.to_vec(), header]
            .into_iter()
            .chain(chunks)
            .collect::<Vec<_>>()
            .concat()
    }

    fn open(bytes: &[u8]) -> Result<BagFile> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.bag");
        std::fs::write(&path, bytes).unwrap();
        BagFile::open(&path)
    }

    #[test]
    fn an_unindexed_bag_is_scanned_and_says_so() {
        let payload = b"\x02\0\0\0hi";
        let bag = open(&unindexed_bag(payload)).unwrap();
        assert!(bag.notice().unwrap().contains("no index"));
        let messages: Vec<_> = BagMessages::new(&bag, 1, None)
            .collect::<std::result::Result<_, _>>()
            .unwrap();
        assert_eq!(messages.len(), 1);
        assert_eq!(messages[0].connection.topic, "/chatter");
        assert_eq!(messages[0].connection.type_name(), "std_msgs/msg/String");
        assert_eq!(messages[0].log_time_ns, 7_000_000_005);
        assert_eq!(messages[0].data, payload);
    }

    #[test]
    fn every_cut_of_a_bag_is_an_error_or_a_notice_never_a_panic() {
        let bytes = unindexed_bag(b"\x02\0\0\0hi");
        for cut in 0..bytes.len() {
            if let Ok(bag) = open(&bytes[..cut]) {
                assert!(bag.notice().is_some());
                BagMessages::new(&bag, 1, None).for_each(drop);
            }
        }
    }

    #[test]
    fn a_chunk_that_lies_about_its_size_is_refused() {
        let mut bytes = unindexed_bag(b"\x02\0\0\0hi");
        let size_at = bytes
            .windows(5)
            .position(|w| w == b"size=")
            .expect("the chunk's size field")
            + 5;
        bytes[size_at] += 1;
        let bag = open(&bytes).unwrap();
        let err = BagMessages::new(&bag, 1, None)
            .next()
            .unwrap()
            .unwrap_err()
            .problem;
        assert!(err.contains("decompresses to") && err.contains("claims"));
    }

    #[test]
    fn chunks_decompressed_side_by_side_read_as_one_at_a_time() {
        let payloads: Vec<Vec<u8>> = (0..7u8)
            .map(|i| [&[3, 0, 0, 0][..], &[b'a' + i; 3]].concat())
            .collect();
        let payloads: Vec<&[u8]> = payloads.iter().map(Vec::as_slice).collect();
        let mut bytes = unindexed_bag_of(&payloads);
        let bag = open(&bytes).unwrap();
        let read = |bag: &BagFile, threads, parts| -> Vec<std::result::Result<Vec<u8>, String>> {
            (BagMessages::new(bag, threads, parts))
                .map(|m| m.map(|m| m.data).map_err(|damage| damage.problem))
                .collect()
        };
        let one = read(&bag, 1, None);
        assert_eq!(
            one,
            payloads.iter().map(|p| Ok(p.to_vec())).collect::<Vec<_>>()
        );
        for threads in [2, 3] {
            assert_eq!(read(&bag, threads, None), one);
        }
        let nothing: Parts = Arc::new(|_: &str, _: &str| Part::Nothing);
        let read_nothing = read(&bag, 2, Some(nothing));
        assert_eq!(read_nothing, vec![Ok(Vec::new()); payloads.len()]);
        // The fifth chunk lies about its size: the same four messages, then its
        // error, then nothing (an unindexed bag has no times to step over it by).
        let size_at = (bytes.windows(5))
            .enumerate()
            .filter(|(_, w)| w == b"size=")
            .nth(4)
            .expect("a fifth chunk")
            .0
            + 5;
        bytes[size_at] += 1;
        let bag = open(&bytes).unwrap();
        let one = read(&bag, 1, None);
        assert_eq!(one.len(), 5);
        assert!(one[..4].iter().all(Result::is_ok));
        assert!(one[4].as_ref().unwrap_err().contains("claims"));
        for threads in [2, 3] {
            assert_eq!(read(&bag, threads, None), one);
        }
    }
}
