//! The MCAP container as travmap writes it: records gathered into chunks, each
//! chunk compressed on a pool of threads and written in order, chunks of an input
//! copied as they are stored, and the summary that indexes them.
//!
//! Not the mcap crate's writer, for two reasons measured on `annotate`: it
//! compresses one chunk at a time on the thread that writes, and it cannot copy a
//! stored chunk, so passing an input through meant decompressing and compressing
//! every byte of it again.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::{self, Write};
use std::sync::mpsc::{Receiver, TryRecvError};

use mcap::records::op;

use crate::mcap::chunks::{Buffers, ChunkRecord, Compressors, OpenChunk};
pub use crate::mcap::chunks::{Compression, FinishedChunk};
use crate::mcap::encoding::{
    MAGIC, channel_record, put_bytes, put_record, put_sized, put_string_map, put_u16, put_u32,
    put_u64, schema_record,
};

/// Largest single write: one 8 MB write() took ten times as long per byte as 1 MB
/// ones here (measured with strace on `convert`: 6.2 ms against 0.09 ms a call).
const WRITE_BYTES: usize = 1 << 20;
/// A message record before its data: opcode, length, channel, sequence, two times.
const MESSAGE_HEADER_BYTES: usize = 1 + 8 + 2 + 4 + 8 + 8;

/// What is due in the file, in order.
enum Due {
    Compressing(Receiver<io::Result<FinishedChunk>>),
    Chunk(FinishedChunk),
    /// A record outside chunks; with the name, a metadata record to index.
    Record(Vec<u8>, Option<String>),
}

/// An MCAP file being written to `out`; [`McapWriter::finish`] completes it.
pub struct McapWriter<W: Write> {
    out: W,
    position: u64,
    /// CRC of every byte before the DataEnd record.
    data_crc: crc32fast::Hasher,
    compression: Compression,
    compressors: Compressors,
    buffers: Buffers,
    /// A chunk is closed once its records reach this many bytes.
    chunk_bytes: usize,
    /// Chunks being compressed at most: bounds memory.
    in_flight_limit: usize,
    /// The chunk being gathered, and the one for channels whose payload is
    /// already compressed, which is stored uncompressed.
    open: [OpenChunk; 2],
    /// Channels whose messages go into the second chunk.
    precompressed: BTreeSet<u16>,
    due: VecDeque<Due>,
    /// Records for the summary, by id.
    schemas: BTreeMap<u16, Vec<u8>>,
    channels: BTreeMap<u16, (u16, Vec<u8>)>,
    /// Schemas and channels whose record the file already holds (or a chunk due).
    schemas_written: BTreeSet<u16>,
    channels_written: BTreeSet<u16>,
    chunk_indexes: Vec<u8>,
    metadata_indexes: Vec<u8>,
    chunks: u32,
    metadata: u32,
    message_counts: BTreeMap<u16, u64>,
    time_ns: Option<(u64, u64)>,
}

fn widen(range: Option<(u64, u64)>, with: (u64, u64)) -> Option<(u64, u64)> {
    Some(range.map_or(with, |(start, end)| (start.min(with.0), end.max(with.1))))
}

impl<W: Write> McapWriter<W> {
    /// Starts the file: magic and header (`profile`, `library`). Chunks of about
    /// `chunk_bytes` (uncompressed) are compressed on `threads` threads.
    pub fn new(
        out: W,
        profile: &str,
        library: &str,
        compression: Compression,
        chunk_bytes: usize,
        threads: usize,
    ) -> io::Result<Self> {
        let threads = threads.max(1);
        let buffers = Buffers::default();
        let mut writer = Self {
            out,
            position: 0,
            data_crc: crc32fast::Hasher::new(),
            compression,
            compressors: Compressors::start(threads, &buffers)?,
            buffers,
            chunk_bytes,
            in_flight_limit: threads + 1,
            open: Default::default(),
            precompressed: BTreeSet::new(),
            due: VecDeque::new(),
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            schemas_written: BTreeSet::new(),
            channels_written: BTreeSet::new(),
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            chunks: 0,
            metadata: 0,
            message_counts: BTreeMap::new(),
            time_ns: None,
        };
        let mut header = MAGIC.to_vec();
        put_record(&mut header, op::HEADER, |out| {
            put_bytes(out, profile.as_bytes());
            put_bytes(out, library.as_bytes());
        });
        writer.emit(&header)?;
        Ok(writer)
    }

    fn emit(&mut self, bytes: &[u8]) -> io::Result<()> {
        for piece in bytes.chunks(WRITE_BYTES) {
            self.out.write_all(piece)?;
        }
        self.data_crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    /// Declares a schema; its record goes into the file before its first channel's.
    pub fn add_schema(&mut self, id: u16, name: &str, encoding: &str, data: &[u8]) {
        self.schemas
            .insert(id, schema_record(id, name, encoding, data));
    }

    /// Declares a channel; its record goes into the file before its first message.
    /// The messages of one whose payload is already compressed (`precompressed`:
    /// images, video) go into chunks of their own, stored uncompressed.
    pub fn add_channel(&mut self, channel: &mcap::records::Channel, precompressed: bool) {
        self.channels
            .insert(channel.id, (channel.schema_id, channel_record(channel)));
        if precompressed {
            self.precompressed.insert(channel.id);
        }
    }

    /// Puts the records of channel `id` and its schema, unless the file has them, in
    /// open chunk `chunk`, or outside chunks (None).
    fn define(&mut self, id: u16, chunk: Option<usize>) -> io::Result<()> {
        if !self.channels_written.insert(id) {
            return Ok(());
        }
        let (schema_id, channel) = self.channels.get(&id).cloned().ok_or_else(|| {
            io::Error::other(format!("channel {id} was written before it was declared"))
        })?;
        let mut records = Vec::new();
        if schema_id != 0 && self.schemas_written.insert(schema_id) {
            let schema = self.schemas.get(&schema_id).ok_or_else(|| {
                io::Error::other(format!(
                    "schema {schema_id} of channel {id} was not declared"
                ))
            })?;
            records.extend_from_slice(schema);
        }
        records.extend_from_slice(&channel);
        match chunk {
            Some(chunk) => self.open_chunk(chunk).records.extend_from_slice(&records),
            None => self.due.push_back(Due::Record(records, None)),
        }
        Ok(())
    }

    /// Open chunk `chunk`, its records in a buffer with room for a whole chunk.
    fn open_chunk(&mut self, chunk: usize) -> &mut OpenChunk {
        let open = &mut self.open[chunk];
        if open.records.capacity() == 0 {
            open.records = self.buffers.take(self.chunk_bytes + self.chunk_bytes / 4);
        }
        open
    }

    pub fn write_message(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> io::Result<()> {
        let chunk = usize::from(self.precompressed.contains(&channel_id));
        self.define(channel_id, Some(chunk))?;
        let open = self.open_chunk(chunk);
        open.index
            .entry(channel_id)
            .or_default()
            .push((log_time_ns, open.records.len() as u64));
        open.time_ns = widen(open.time_ns, (log_time_ns, log_time_ns));
        // A message past the buffer's room grows it to fit, not to double the chunk.
        open.records
            .reserve_exact(MESSAGE_HEADER_BYTES + data.len());
        put_record(&mut open.records, op::MESSAGE, |out| {
            put_u16(out, channel_id);
            put_u32(out, sequence);
            put_u64(out, log_time_ns);
            put_u64(out, publish_time_ns);
            out.extend_from_slice(data);
        });
        if open.records.len() >= self.chunk_bytes {
            self.close_chunks();
            self.write_due(false)?;
        }
        Ok(())
    }

    /// Copies a chunk of an input as stored. Its channels must be declared with the
    /// ids its records use; their records go before it, outside chunks, in case the
    /// input held them outside chunks too.
    pub fn copy_chunk(&mut self, chunk: FinishedChunk) -> io::Result<()> {
        for channel in &chunk.channels {
            self.define(channel.id, None)?;
        }
        self.due.push_back(Due::Chunk(chunk));
        self.write_due(false)
    }

    pub fn write_metadata(&mut self, name: &str, entries: &BTreeMap<String, String>) {
        let mut record = Vec::new();
        put_record(&mut record, op::METADATA, |out| {
            put_bytes(out, name.as_bytes());
            put_string_map(out, entries);
        });
        self.due
            .push_back(Due::Record(record, Some(name.to_string())));
    }

    /// Closes both open chunks, the already-compressed payloads' first: a reader
    /// that goes by file order (travmap's, pairing each cloud with the image nearest
    /// in time) then meets a span's images before its clouds, never long after.
    fn close_chunks(&mut self) {
        self.close_chunk(1);
        self.close_chunk(0);
    }

    /// Hands open chunk `chunk` to the compressors.
    fn close_chunk(&mut self, chunk: usize) {
        if self.open[chunk].records.is_empty() {
            return;
        }
        let open = std::mem::take(&mut self.open[chunk]);
        let compression = if chunk == 0 {
            self.compression
        } else {
            Compression::None
        };
        let compressing = self.compressors.compress(open, compression);
        self.due.push_back(Due::Compressing(compressing));
    }

    /// Writes what is due in order: everything (`all`), or up to the first chunk
    /// still compressing once no more than `in_flight_limit` are.
    fn write_due(&mut self, all: bool) -> io::Result<()> {
        while let Some(front) = self.due.pop_front() {
            let in_flight = self
                .due
                .iter()
                .filter(|due| matches!(due, Due::Compressing(_)))
                .count();
            let ready = match front {
                Due::Compressing(result) => {
                    let received = if all || in_flight >= self.in_flight_limit {
                        result.recv().map_err(|_| TryRecvError::Disconnected)
                    } else {
                        result.try_recv()
                    };
                    match received {
                        Ok(chunk) => Due::Chunk(chunk?),
                        Err(TryRecvError::Empty) => {
                            self.due.push_front(Due::Compressing(result));
                            return Ok(());
                        }
                        Err(TryRecvError::Disconnected) => {
                            return Err(io::Error::other("a chunk compression thread stopped"));
                        }
                    }
                }
                other => other,
            };
            match ready {
                Due::Chunk(chunk) => self.write_chunk(chunk)?,
                Due::Record(record, metadata_name) => {
                    let offset = self.position;
                    self.emit(&record)?;
                    if let Some(name) = metadata_name {
                        self.metadata += 1;
                        put_record(&mut self.metadata_indexes, op::METADATA_INDEX, |out| {
                            put_u64(out, offset);
                            put_u64(out, record.len() as u64);
                            put_bytes(out, name.as_bytes());
                        });
                    }
                }
                Due::Compressing(_) => unreachable!("received above"),
            }
        }
        Ok(())
    }

    fn write_chunk(&mut self, mut chunk: FinishedChunk) -> io::Result<()> {
        let start = self.position;
        self.emit(chunk.record.bytes())?;
        let indexes_start = self.position;
        self.emit(&chunk.message_indexes)?;
        if let Some(release) = chunk.release.take() {
            release.run();
        }
        let record_bytes = chunk.record.bytes().len() as u64;
        let (start_ns, end_ns) = chunk.time_ns.unwrap_or((0, 0));
        put_record(&mut self.chunk_indexes, op::CHUNK_INDEX, |out| {
            put_u64(out, start_ns);
            put_u64(out, end_ns);
            put_u64(out, start);
            put_u64(out, record_bytes);
            put_sized(out, |out| {
                for channel in &chunk.channels {
                    put_u16(out, channel.id);
                    put_u64(out, indexes_start + channel.index_offset);
                }
            });
            put_u64(out, chunk.message_indexes.len() as u64);
            put_bytes(out, chunk.compression.as_bytes());
            put_u64(out, chunk.compressed_bytes);
            put_u64(out, chunk.uncompressed_bytes);
        });
        self.chunks += 1;
        for channel in &chunk.channels {
            *self.message_counts.entry(channel.id).or_default() += channel.messages;
        }
        if let Some(range) = chunk.time_ns {
            self.time_ns = widen(self.time_ns, range);
        }
        if let ChunkRecord::Built(buffer) = chunk.record {
            self.buffers.give(buffer);
        }
        Ok(())
    }

    /// Writes the rest, the summary and the footer; returns the output.
    pub fn finish(mut self) -> io::Result<W> {
        self.close_chunks();
        self.write_due(true)?;
        let mut data_end = Vec::new();
        let crc = self.data_crc.clone().finalize();
        put_record(&mut data_end, op::DATA_END, |out| put_u32(out, crc));
        self.emit(&data_end)?;

        let summary_start = self.position;
        let mut summary = Vec::new();
        let mut offsets = Vec::new();
        let mut group = |summary: &mut Vec<u8>, opcode: u8, records: &[u8]| {
            if records.is_empty() {
                return;
            }
            put_record(&mut offsets, op::SUMMARY_OFFSET, |out| {
                out.push(opcode);
                put_u64(out, summary_start + summary.len() as u64);
                put_u64(out, records.len() as u64);
            });
            summary.extend_from_slice(records);
        };
        let schemas: Vec<u8> = self.schemas.values().flatten().copied().collect();
        group(&mut summary, op::SCHEMA, &schemas);
        let channels: Vec<u8> = self
            .channels
            .values()
            .flat_map(|(_, record)| record)
            .copied()
            .collect();
        group(&mut summary, op::CHANNEL, &channels);
        let mut statistics = Vec::new();
        let (start_ns, end_ns) = self.time_ns.unwrap_or((0, 0));
        put_record(&mut statistics, op::STATISTICS, |out| {
            put_u64(out, self.message_counts.values().sum());
            put_u16(out, self.schemas.len() as u16);
            put_u32(out, self.channels.len() as u32);
            put_u32(out, 0);
            put_u32(out, self.metadata);
            put_u32(out, self.chunks);
            put_u64(out, start_ns);
            put_u64(out, end_ns);
            put_sized(out, |out| {
                for (&id, &count) in &self.message_counts {
                    put_u16(out, id);
                    put_u64(out, count);
                }
            });
        });
        group(&mut summary, op::STATISTICS, &statistics);
        group(&mut summary, op::CHUNK_INDEX, &self.chunk_indexes);
        group(&mut summary, op::METADATA_INDEX, &self.metadata_indexes);

        let summary_offset_start = summary_start + summary.len() as u64;
        summary.extend_from_slice(&offsets);
        summary.push(op::FOOTER);
        put_u64(&mut summary, 20);
        put_u64(&mut summary, summary_start);
        put_u64(&mut summary, summary_offset_start);
        // The summary CRC covers the summary up to this field of the footer.
        let crc = crc32fast::hash(&summary);
        put_u32(&mut summary, crc);
        summary.extend_from_slice(MAGIC);
        self.out.write_all(&summary)?;
        self.out.flush()?;
        let Self { out, .. } = self;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytes::Bytes;
    use mcap::sans_io::{
        IndexedReadEvent, IndexedReader, IndexedReaderOptions, LinearReadEvent, LinearReader,
        LinearReaderOptions,
    };

    fn channel(id: u16, schema_id: u16, topic: &str) -> mcap::records::Channel {
        mcap::records::Channel {
            id,
            schema_id,
            topic: topic.into(),
            message_encoding: "cdr".into(),
            metadata: BTreeMap::from([("k".to_string(), "v".to_string())]),
        }
    }

    /// (channel, sequence, log time, data) of every message, in file order, read by
    /// the mcap crate with every CRC checked.
    fn read_linearly(file: &[u8]) -> Vec<(u16, u32, u64, Vec<u8>)> {
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true);
        let mut reader = LinearReader::new_with_options(options);
        let mut read = 0;
        let mut messages = Vec::new();
        while let Some(event) = reader.next_event() {
            match event.expect("the file reads") {
                LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(file.len() - read);
                    reader.insert(n).copy_from_slice(&file[read..read + n]);
                    reader.notify_read(n);
                    read += n;
                }
                LinearReadEvent::Record { opcode, data } => {
                    if let mcap::records::Record::Message { header, data } =
                        mcap::parse_record(opcode, data).expect("a record")
                    {
                        messages.push((
                            header.channel_id,
                            header.sequence,
                            header.log_time,
                            data.to_vec(),
                        ));
                    }
                }
            }
        }
        messages
    }

    /// Log times of every message in log-time order, read through the summary's
    /// chunk indexes.
    fn read_by_index(file: &[u8]) -> Vec<u64> {
        let summary = mcap::Summary::read(file).unwrap().expect("a summary");
        let mut reader =
            IndexedReader::new_with_options(&summary, IndexedReaderOptions::new()).unwrap();
        let mut times = Vec::new();
        while let Some(event) = reader.next_event() {
            match event.unwrap() {
                IndexedReadEvent::ReadChunkRequest { offset, length } => {
                    let chunk = &file[offset as usize..offset as usize + length];
                    reader.insert_chunk_record_data(offset, chunk).unwrap();
                }
                IndexedReadEvent::Message { header, .. } => times.push(header.log_time),
            }
        }
        times
    }

    fn write_file(compression: Compression, chunk_bytes: usize) -> Vec<u8> {
        let mut writer =
            McapWriter::new(Vec::new(), "ros2", "test", compression, chunk_bytes, 2).unwrap();
        writer.add_schema(1, "pkg/msg/A", "ros2msg", b"int32 a");
        writer.add_channel(&channel(3, 1, "/a"), false);
        // Its messages go into uncompressed chunks of their own.
        writer.add_channel(&channel(4, 1, "/b"), true);
        for i in 0..50u32 {
            // Out of order within channel /b, as recorded logs can be.
            let (id, time) = if i.is_multiple_of(2) {
                (3, 100 + i as u64)
            } else {
                (4, 200 - i as u64)
            };
            writer
                .write_message(id, i, time, time + 1, &vec![i as u8; 300 + i as usize])
                .unwrap();
        }
        writer.write_metadata("m", &BTreeMap::from([("x".into(), "1".into())]));
        writer.finish().unwrap()
    }

    #[test]
    fn the_mcap_crate_reads_every_message_in_order_with_every_crc_right() {
        for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
            let file = write_file(compression, 2000);
            let mut messages = read_linearly(&file);
            // /b's chunks come apart from /a's: file order interleaves the two.
            messages.sort_by_key(|m| m.1);
            assert_eq!(messages.len(), 50);
            for (i, (id, sequence, time, data)) in messages.iter().enumerate() {
                let i = i as u32;
                assert_eq!((*sequence, data.len()), (i, 300 + i as usize));
                assert_eq!(*id, if i.is_multiple_of(2) { 3 } else { 4 });
                assert_eq!(
                    *time,
                    if i.is_multiple_of(2) {
                        100 + i as u64
                    } else {
                        200 - i as u64
                    }
                );
            }
            let summary = mcap::Summary::read(&file).unwrap().unwrap();
            let stats = summary.stats.as_ref().unwrap();
            assert_eq!(stats.message_count, 50);
            assert_eq!(
                stats.channel_message_counts,
                BTreeMap::from([(3, 25), (4, 25)])
            );
            assert_eq!(
                (stats.message_start_time, stats.message_end_time),
                (100, 199)
            );
            assert_eq!(stats.metadata_count, 1);
            assert!(summary.chunk_indexes.len() > 3, "several chunks");
            assert_eq!(stats.chunk_count as usize, summary.chunk_indexes.len());
            assert_eq!(summary.channels[&4].topic, "/b");
            let stored_as =
                |name: &str| summary.chunk_indexes.iter().any(|c| c.compression == name);
            assert!(stored_as(compression.chunk_name()) && stored_as(""));
            assert_eq!(
                summary.channels[&4].schema.as_ref().unwrap().name,
                "pkg/msg/A"
            );
            let mut times: Vec<u64> = messages.iter().map(|m| m.2).collect();
            times.sort();
            assert_eq!(read_by_index(&file), times);
            for index in &summary.chunk_indexes {
                let indexes = summary.read_message_indexes(&file, index).unwrap();
                let count: usize = indexes.values().map(Vec::len).sum();
                assert!(count > 0);
            }
        }
    }

    #[test]
    fn copied_chunks_are_indexed_beside_new_ones() {
        let input = Bytes::from(write_file(Compression::Zstd, 2000));
        let mut stored = crate::mcap::stored::stored_log(&input).expect("copyable");
        assert_eq!(stored.messages(), 50);
        let mut writer =
            McapWriter::new(Vec::new(), "ros2", "test", Compression::Zstd, 2000, 1).unwrap();
        for (header, data) in &stored.schemas {
            writer.add_schema(header.id, &header.name, &header.encoding, data);
        }
        for channel in &stored.channels {
            writer.add_channel(channel, false);
        }
        for chunk in &mut stored.chunks {
            writer.copy_chunk(FinishedChunk::copied(chunk)).unwrap();
        }
        writer.add_channel(&channel(5, 1, "/c"), false);
        writer.write_message(5, 0, 150, 150, b"new").unwrap();
        let file = writer.finish().unwrap();
        let messages = read_linearly(&file);
        assert_eq!(messages.len(), 51);
        // Copied chunks keep their order in the file.
        assert_eq!(&messages[..50], &read_linearly(&input)[..]);
        assert_eq!(messages[50], (5, 0, 150, b"new".to_vec()));
        let mut times: Vec<u64> = messages.iter().map(|m| m.2).collect();
        times.sort();
        assert_eq!(read_by_index(&file), times);
        let summary = mcap::Summary::read(&file).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 51);
    }
}
