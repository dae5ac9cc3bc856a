//! The message pass over an MCAP file: the crate's sans-io [`LinearReader`] fed
//! from the memory map, every record's lengths checked before it is parsed
//! ([`check_lengths`]), and a damaged chunk stepped over rather than the end of
//! the file.

use std::borrow::Cow;

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{McapError, Message};

use super::log_message::FileMap;
use super::mcap_records::{ChunkSpan, check_lengths};

/// Bytes a pass reads before it gives the pages behind it back.
const RELEASE_BYTES: usize = 32 << 20;

/// The messages of `file` in file order, linked to their channels.
pub(super) struct Messages<'a> {
    file: &'a [u8],
    read: usize,
    /// The map `file` is, if it is one, and how far its pages were given back: the
    /// reader copies what it reads, so what lies before `read` is not read again.
    map: Option<&'a FileMap>,
    released: usize,
    reader: LinearReader,
    options: LinearReaderOptions,
    /// The file's chunks: a damaged one is stepped over, not the end of the file.
    chunks: &'a [ChunkSpan],
    /// Where reading last resumed after a damaged chunk.
    resumed_at: usize,
    channels: mcap::read::ChannelAccumulator<'static>,
    past_data_end: bool,
    done: bool,
}

/// Why a message could not be read; with `chunk`, only that chunk's messages are
/// lost and reading goes on after it.
#[derive(Debug)]
pub(super) struct Damage {
    pub(super) problem: String,
    pub(super) chunk: Option<ChunkSpan>,
}

impl<'a> Messages<'a> {
    /// The messages of `file` (the complete records of a cut file: `cut` true reads
    /// to its end without the summary and closing magic); `chunks` as
    /// [`check_chunk_sizes`] found them.
    pub(super) fn new(
        file: &'a [u8],
        longest_record: usize,
        map: Option<&'a FileMap>,
        cut: bool,
        chunks: &'a [ChunkSpan],
    ) -> Self {
        // CRCs checked before a chunk's records are handed on: a damaged chunk gives
        // no made-up messages.
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(longest_record)
            .with_skip_end_magic(cut)
            .with_emit_chunks(false);
        Self {
            file,
            read: 0,
            map,
            released: 0,
            reader: LinearReader::new_with_options(options.clone()),
            options,
            chunks,
            resumed_at: 0,
            channels: Default::default(),
            past_data_end: false,
            done: false,
        }
    }

    /// The damage of a failed read: the chunk being read when it failed, if any, is
    /// stepped over; reading goes on after it with a fresh reader.
    fn damage(&mut self, problem: String) -> Damage {
        let read = self.read;
        // Only forwards: a chunk that ends where reading resumed is not the culprit.
        let resumed_at = self.resumed_at;
        let chunk = self
            .chunks
            .iter()
            .find(|chunk| {
                chunk.bytes.start < read && read <= chunk.bytes.end && chunk.bytes.end > resumed_at
            })
            .cloned();
        if let Some(chunk) = &chunk {
            self.read = chunk.bytes.end;
            self.resumed_at = chunk.bytes.end;
            self.reader =
                LinearReader::new_with_options(self.options.clone().with_skip_start_magic(true));
        }
        Damage { problem, chunk }
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
                    if let Some(map) = self.map
                        && self.read - self.released >= RELEASE_BYTES
                    {
                        map.release(self.released..self.read);
                        self.released = self.read;
                    }
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
    type Item = Result<Message<'static>, Damage>;

    /// Nothing after an error outside a chunk; after a damaged chunk, the messages
    /// that follow it.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.next_message()? {
            Ok(message) => Some(Ok(message)),
            Err(problem) => {
                let damage = self.damage(problem);
                self.done = damage.chunk.is_none();
                Some(Err(damage))
            }
        }
    }
}
