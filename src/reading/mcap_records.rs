//! The messages of an MCAP file, read so that no length field makes travmap reserve
//! memory the file does not hold.
//!
//! The mcap crate parses a record's strings and byte arrays by reserving each one's
//! declared length (a u32, up to 4 GiB) before reading it, and does not bound a
//! record's length inside a compressed chunk. So this drives the crate's sans-io
//! [`LinearReader`] itself: chunk CRCs checked, no record longer than the caller's
//! limit, and every length field inside a record checked against the bytes that
//! follow it before the record is parsed.

use std::borrow::Cow;

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{McapError, Message};

/// One field of a record, in the MCAP specification's order.
#[derive(Clone, Copy)]
enum Field {
    Fixed(usize),
    /// u32 length, then that many bytes (strings, schema data, message index arrays,
    /// maps of fixed-size entries).
    Bytes32(&'static str),
    /// u64 length, then that many bytes (attachment data).
    Bytes64(&'static str),
    /// u32 byte length, then string-to-string entries, each a u32-prefixed key and value.
    StringMap(&'static str),
    /// The rest of the record (message data).
    Rest,
}

use Field::*;

/// The layout of every record the reader parses. Top-level chunks are checked
/// before reading (`check_chunk_sizes`) and their records one by one here.
fn layout(opcode: u8) -> &'static [Field] {
    match opcode {
        op::HEADER => &[Bytes32("profile"), Bytes32("library")],
        op::SCHEMA => &[
            Fixed(2),
            Bytes32("name"),
            Bytes32("encoding"),
            Bytes32("data"),
        ],
        op::CHANNEL => &[
            Fixed(4),
            Bytes32("topic"),
            Bytes32("message_encoding"),
            StringMap("metadata"),
        ],
        op::MESSAGE => &[Fixed(22), Rest],
        // Only a chunk inside a chunk reaches here: the reader opens top-level ones.
        op::CHUNK => &[Fixed(28), Bytes32("compression"), Bytes64("records")],
        op::MESSAGE_INDEX => &[Fixed(2), Bytes32("records")],
        op::CHUNK_INDEX => &[
            Fixed(32),
            Bytes32("message_index_offsets"),
            Fixed(8),
            Bytes32("compression"),
            Fixed(16),
        ],
        op::ATTACHMENT => &[
            Fixed(16),
            Bytes32("name"),
            Bytes32("media_type"),
            Bytes64("data"),
            Fixed(4),
        ],
        op::ATTACHMENT_INDEX => &[Fixed(40), Bytes32("name"), Bytes32("media_type")],
        op::STATISTICS => &[Fixed(42), Bytes32("channel_message_counts")],
        op::METADATA => &[Bytes32("name"), StringMap("metadata")],
        op::METADATA_INDEX => &[Fixed(16), Bytes32("name")],
        _ => &[Rest],
    }
}

/// Checks that every length in a record of `opcode` fits in the bytes after it.
fn check_lengths(opcode: u8, body: &[u8]) -> Result<(), String> {
    let mut at = 0usize;
    let length = |at: usize, width: usize| -> Option<u64> {
        let bytes = body.get(at..at + width)?;
        Some(if width == 4 {
            u32::from_le_bytes(bytes.try_into().ok()?) as u64
        } else {
            u64::from_le_bytes(bytes.try_into().ok()?)
        })
    };
    // Moves past a length-prefixed field, or says which length is impossible.
    let skip = |at: usize, width: usize, end: usize, name: &str| -> Result<usize, String> {
        let claimed = length(at, width)
            .filter(|_| at + width <= end)
            .ok_or_else(|| {
                format!("record (opcode {opcode:#04x}) ends inside the length of its {name}")
            })?;
        let remaining = (end - at - width) as u64;
        if claimed > remaining {
            return Err(format!(
                "record (opcode {opcode:#04x}): its {name} claims {claimed} bytes, but {remaining} follow"
            ));
        }
        Ok(at + width + claimed as usize)
    };
    for field in layout(opcode) {
        at = match *field {
            Fixed(n) => at + n,
            Bytes32(name) => skip(at, 4, body.len(), name)?,
            Bytes64(name) => skip(at, 8, body.len(), name)?,
            StringMap(name) => {
                let end = skip(at, 4, body.len(), name)?;
                let mut entry = at + 4;
                while entry < end {
                    entry = skip(entry, 4, end, name)?;
                    entry = skip(entry, 4, end, name)?;
                }
                end
            }
            Rest => body.len(),
        };
        if at > body.len() {
            return Err(format!(
                "record (opcode {opcode:#04x}) is {} bytes, shorter than its fields",
                body.len()
            ));
        }
    }
    Ok(())
}

/// The messages of `file` in file order, linked to their channels.
pub(super) struct Messages<'a> {
    file: &'a [u8],
    read: usize,
    reader: LinearReader,
    channels: mcap::read::ChannelAccumulator<'static>,
    past_data_end: bool,
    done: bool,
}

impl<'a> Messages<'a> {
    pub(super) fn new(file: &'a [u8], longest_record: usize) -> Self {
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(longest_record)
            .with_emit_chunks(false);
        Self {
            file,
            read: 0,
            reader: LinearReader::new_with_options(options),
            channels: Default::default(),
            past_data_end: false,
            done: false,
        }
    }

    fn next_message(&mut self) -> Option<Result<Message<'static>, String>> {
        loop {
            let (opcode, data) = match self.reader.next_event()? {
                Err(error) => return Some(Err(error.to_string())),
                Ok(LinearReadEvent::ReadRequest(need)) => {
                    let n = need.min(self.file.len() - self.read);
                    self.reader
                        .insert(n)
                        .copy_from_slice(&self.file[self.read..self.read + n]);
                    self.reader.notify_read(n);
                    self.read += n;
                    continue;
                }
                Ok(LinearReadEvent::Record { opcode, data }) => (opcode, data),
            };
            if let Err(message) = check_lengths(opcode, data) {
                return Some(Err(message));
            }
            // After the data section the summary repeats schemas and channels.
            if opcode == op::DATA_END {
                self.past_data_end = true;
            }
            if self.past_data_end {
                continue;
            }
            let record = match mcap::parse_record(opcode, data) {
                Ok(record) => record,
                Err(error) => return Some(Err(error.to_string())),
            };
            let added = match record {
                Record::Schema { header, data } => {
                    self.channels.add_schema_from_slice(header, &data)
                }
                Record::Channel(channel) => self.channels.add_channel(channel),
                Record::Message { header, data } => {
                    let Some(channel) = self.channels.get(header.channel_id) else {
                        let error = McapError::UnknownChannel(header.sequence, header.channel_id);
                        return Some(Err(error.to_string()));
                    };
                    return Some(Ok(Message {
                        channel,
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: Cow::Owned(data.into_owned()),
                    }));
                }
                _ => Ok(()),
            };
            if let Err(error) = added {
                return Some(Err(error.to_string()));
            }
        }
    }
}

impl Iterator for Messages<'_> {
    type Item = Result<Message<'static>, String>;

    /// Nothing after the first error.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let next = self.next_message();
        self.done = !matches!(next, Some(Ok(_)));
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &str) -> Vec<u8> {
        let mut out = (s.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(s.as_bytes());
        out
    }

    fn channel(topic: &[u8], metadata: &[u8]) -> Vec<u8> {
        let mut body = vec![1, 0, 0, 0];
        body.extend_from_slice(topic);
        body.extend_from_slice(&string("cdr"));
        body.extend_from_slice(metadata);
        body
    }

    #[test]
    fn lengths_beyond_the_record_are_refused_before_parsing() {
        let mut map = string("key");
        map.extend_from_slice(&string("value"));
        let mut metadata = (map.len() as u32).to_le_bytes().to_vec();
        metadata.extend_from_slice(&map);
        let good = channel(&string("/points"), &metadata);
        assert_eq!(check_lengths(op::CHANNEL, &good), Ok(()));
        assert!(mcap::parse_record(op::CHANNEL, &good).is_ok());

        // A topic claiming 3.4 GB (what the fuzzer found) and a map entry claiming
        // more than its map holds.
        let mut huge_topic = 3_414_607_977u32.to_le_bytes().to_vec();
        huge_topic.extend_from_slice(b"/points");
        let err = check_lengths(op::CHANNEL, &channel(&huge_topic, &metadata)).unwrap_err();
        assert!(err.contains("its topic claims 3414607977 bytes"), "{err}");
        let mut bad_map = metadata.clone();
        bad_map[4] = 200;
        let err = check_lengths(op::CHANNEL, &channel(&string("/p"), &bad_map)).unwrap_err();
        assert!(err.contains("its metadata claims 200 bytes"), "{err}");
        let err = check_lengths(op::CHANNEL, &good[..6]).unwrap_err();
        assert!(err.contains("ends inside the length of its topic"), "{err}");
        let err = check_lengths(op::CHANNEL, &good[..3]).unwrap_err();
        assert!(err.contains("shorter than its fields"), "{err}");
    }
}
