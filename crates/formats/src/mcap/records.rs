//! The messages of an MCAP file, read so that no length field makes travmap reserve
//! memory the file does not hold.
//!
//! The mcap crate parses a record's strings and byte arrays by reserving each one's
//! declared length (a u32, up to 4 GiB) before reading it, and does not bound a
//! record's length inside a compressed chunk. So [`crate::mcap::messages`] walks the
//! records itself and hands the crate one record at a time, with the checks that
//! live here: the file's layout (its chunks' declared sizes, where a cut file ends),
//! no record longer than the bytes that hold it, and every length field inside a
//! record checked against the bytes that follow it before the record is parsed.

use mcap::records::op;

use crate::log_message::ChunkSpan;

/// One field of a record, in the MCAP specification's order.
#[derive(Clone, Copy)]
enum Field {
    Fixed(usize),
    /// u32 length, then that many bytes (strings, schema data).
    Bytes32(&'static str),
    /// u32 byte length, then entries of the given size (message index arrays, maps
    /// of fixed-size entries): the crate reads whole entries until the length is
    /// used up, so a length that is not a whole number of them moves every field
    /// after it off the place checked here.
    Entries32(&'static str, usize),
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
        op::MESSAGE_INDEX => &[Fixed(2), Entries32("records", 16)],
        op::CHUNK_INDEX => &[
            Fixed(32),
            Entries32("message_index_offsets", 10),
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
        op::STATISTICS => &[Fixed(42), Entries32("channel_message_counts", 10)],
        op::METADATA => &[Bytes32("name"), StringMap("metadata")],
        op::METADATA_INDEX => &[Fixed(16), Bytes32("name")],
        _ => &[Rest],
    }
}

/// Checks that every length in a record of `opcode` fits in the bytes after it.
pub fn check_lengths(opcode: u8, body: &[u8]) -> Result<(), String> {
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
            Entries32(name, size) => {
                let end = skip(at, 4, body.len(), name)?;
                let bytes = end - at - 4;
                if !bytes.is_multiple_of(size) {
                    return Err(format!(
                        "record (opcode {opcode:#04x}): its {name} are {bytes} bytes, not a whole number of {size}-byte entries"
                    ));
                }
                end
            }
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

/// A compressed chunk may claim up to this many times its compressed size, or up
/// to `TRUSTED_CHUNK_BYTES`, before its claim is checked by decompressing it.
const TRUSTED_CHUNK_RATIO: u64 = 64;
const TRUSTED_CHUNK_BYTES: u64 = 64 << 20;

/// A record whose length runs past the bytes that hold it.
#[derive(Debug)]
pub struct Overrun {
    pub offset: usize,
    pub opcode: u8,
    pub length: u64,
    pub available: usize,
}

/// The records of `bytes` from `offset` on, each an opcode, a u64 length and a
/// body: yields (offset, opcode, body). It ends at a header cut short, leaving
/// `offset` there, or with an [`Overrun`] at a body that does not fit.
pub struct RecordWalk<'a> {
    pub bytes: &'a [u8],
    pub offset: usize,
}

impl<'a> Iterator for RecordWalk<'a> {
    type Item = Result<(usize, u8, &'a [u8]), Overrun>;

    fn next(&mut self) -> Option<Self::Item> {
        let offset = self.offset;
        let opcode = *self.bytes.get(offset)?;
        let length = u64::from_le_bytes(self.bytes.get(offset + 1..offset + 9)?.try_into().ok()?);
        let available = self.bytes.len() - offset - 9;
        let Some(end) = usize::try_from(length)
            .ok()
            .filter(|&length| length <= available)
            .map(|length| offset + 9 + length)
        else {
            // Nothing after an overrun can be found.
            self.offset = self.bytes.len();
            return Some(Err(Overrun {
                offset,
                opcode,
                length,
                available,
            }));
        };
        self.offset = end;
        Some(Ok((offset, opcode, &self.bytes[offset + 9..end])))
    }
}

/// What [`check_chunk_sizes`] found of a file's layout.
#[derive(Debug)]
pub struct Layout {
    /// For a file cut short (a recorder killed before it wrote the summary, or in the
    /// middle of a record): where its last complete record ends.
    pub cut_at: Option<usize>,
    /// Its data section ends with its DataEnd record: a file cut after it lost its
    /// summary alone, none of the recording.
    pub data_complete: bool,
    /// The bag's metadata a rosbag2 MCAP keeps (its `rosbag2` metadata record's
    /// `serialized_metadata`): whether its messages are compressed one by one.
    pub rosbag2_metadata: Option<String>,
    /// Damaged stretches of the data section that reading steps over, each with why:
    /// a chunk whose declared size is wrong, or (in a whole file) a record that does
    /// not read, up to the next chunk the summary's chunk index names.
    pub damaged: Vec<(ChunkSpan, String)>,
}

/// A chunk record's place in the file (`bytes`) and its messages' times, from its
/// `body`'s header (0 where it is too short to hold them).
pub(crate) fn chunk_span(bytes: std::ops::Range<usize>, body: &[u8]) -> ChunkSpan {
    let time = |at: usize| {
        body.get(at..at + 8)
            .map_or(0, |b| u64::from_le_bytes(b.try_into().unwrap_or_default()))
    };
    ChunkSpan {
        bytes,
        start_ns: time(0),
        end_ns: time(8),
        lost: Vec::new(),
    }
}

/// Where a whole file's reading resumes after damage at `offset`: the next chunk its
/// summary indexes, else its DataEnd record (just before the summary).
fn resume_after(map: &[u8], indexed: &[(usize, u64, u64)], offset: usize) -> Option<usize> {
    let next_chunk = indexed.iter().map(|c| c.0).find(|&start| start > offset);
    next_chunk.or_else(|| {
        let data_end = summary_start(map)?.checked_sub(13)?;
        (data_end > offset && map[data_end] == op::DATA_END).then_some(data_end)
    })
}

/// Where the summary of a file with a footer begins.
pub(crate) fn summary_start(map: &[u8]) -> Option<usize> {
    let footer = map.len().checked_sub(8 + 29)?;
    let at = u64::from_le_bytes(map.get(footer + 9..footer + 17)?.try_into().ok()?);
    usize::try_from(at)
        .ok()
        .filter(|&at| at >= 8 && at < footer)
}

/// Each chunk the summary's chunk indexes name: where it starts and the times of
/// its messages (none for a file without a footer, or whose summary does not read).
fn indexed_chunks(map: &[u8]) -> Vec<(usize, u64, u64)> {
    let word = |bytes: &[u8], at: usize| -> Option<u64> {
        Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?))
    };
    let Some(summary) = summary_start(map) else {
        return Vec::new();
    };
    let footer = map.len() - 8 - 29;
    let walk = RecordWalk {
        bytes: &map[..footer],
        offset: summary,
    };
    let mut chunks: Vec<(usize, u64, u64)> = walk
        .map_while(Result::ok)
        .filter(|(_, opcode, _)| *opcode == op::CHUNK_INDEX)
        .filter_map(|(_, _, body)| {
            let start = usize::try_from(word(body, 16)?).ok()?;
            (map.get(start) == Some(&op::CHUNK)).then_some((start, word(body, 0)?, word(body, 8)?))
        })
        .collect();
    chunks.sort_unstable();
    chunks
}

/// The stretch from a damaged record at `offset` to `resume`, with the times of the
/// indexed chunks in it.
fn damaged_span(offset: usize, resume: usize, indexed: &[(usize, u64, u64)]) -> ChunkSpan {
    let inside = indexed
        .iter()
        .filter(|(start, _, _)| (offset..resume).contains(start));
    ChunkSpan {
        bytes: offset..resume,
        start_ns: inside.clone().map(|c| c.1).min().unwrap_or(0),
        end_ns: inside.map(|c| c.2).max().unwrap_or(0),
        lost: Vec::new(),
    }
}

/// Checks every chunk's declared uncompressed size before the mcap crate, which
/// reserves that size up front, sees it: an uncompressed chunk must declare its own
/// length, and a compressed one claiming more than `TRUSTED_CHUNK_RATIO` times its
/// bytes is decompressed into a counter (no buffer) to confirm the claim. So
/// allocation follows the data a file holds, not what its header says. A file that
/// ends before its data section does (no DataEnd record) is cut: its complete
/// records are what can be read.
pub fn check_chunk_sizes(map: &[u8]) -> Result<Layout, String> {
    let mut walk = RecordWalk {
        bytes: map,
        offset: 8,
    };
    let mut complete = walk.offset;
    let mut data_end = false;
    let mut rosbag2_metadata = None;
    let mut damaged = Vec::new();
    // A whole file ends with the footer and the closing magic; a recorder killed
    // after the data section leaves neither.
    let magic = b"\x89MCAP0\r\n";
    let footer = map.len().checked_sub(magic.len() + 29);
    let whole = map.ends_with(magic) && footer.is_some_and(|at| map[at] == op::FOOTER);
    // In a whole file a record that does not read is stepped over to the next chunk
    // its summary indexes: the summary is read at the first damage, if any.
    let indexed = std::cell::OnceCell::new();
    let indexed = || indexed.get_or_init(|| indexed_chunks(map)).as_slice();
    // Why the walk stopped before the data section's end, when a record did not read.
    let mut damage = None;
    // After the 8-byte magic. A malformed chunk header ends the walk, as does a
    // record header cut short, unless the summary says where the next chunk is.
    while let Some(record) = walk.next() {
        let (offset, opcode, body) = match record {
            Ok(record) => record,
            Err(overrun) => {
                let problem = format!(
                    "the record at byte {} (opcode 0x{:02x}) claims {} bytes where {} remain",
                    overrun.offset, overrun.opcode, overrun.length, overrun.available
                );
                match whole
                    .then(|| resume_after(map, indexed(), overrun.offset))
                    .flatten()
                {
                    Some(resume) => {
                        damaged.push((damaged_span(overrun.offset, resume, indexed()), problem));
                        walk.offset = resume;
                        continue;
                    }
                    None => {
                        damage = Some(problem);
                        break;
                    }
                }
            }
        };
        complete = walk.offset;
        if opcode == op::DATA_END {
            data_end = true;
            break;
        }
        if opcode == op::METADATA && rosbag2_metadata.is_none() {
            rosbag2_metadata = metadata_value(body, "rosbag2", "serialized_metadata");
        }
        if opcode != op::CHUNK {
            continue;
        }
        // A damaged chunk is stepped over, its times from its own header; in a whole
        // file its length is not trusted either: reading resumes where the summary
        // says the next chunk is.
        let span = chunk_span(offset..walk.offset, body);
        let mut step_over = |mut span: ChunkSpan, walk: &mut RecordWalk, problem: String| {
            if let Some(resume) = whole
                .then(|| resume_after(map, indexed(), offset))
                .flatten()
            {
                span.bytes.end = resume;
                walk.offset = resume;
            }
            damaged.push((span, problem));
        };
        let Some((declared, compression, records)) = chunk_parts(body) else {
            step_over(
                span,
                &mut walk,
                format!("the chunk at byte {offset} has a malformed header"),
            );
            continue;
        };
        let present = records.len() as u64;
        let plausible = declared <= TRUSTED_CHUNK_BYTES.max(present * TRUSTED_CHUNK_RATIO);
        let actual = match compression {
            "" if declared != present => Some(present),
            "zstd" | "lz4" if !plausible => Some(
                decompressed_len(compression, records, declared).map_err(|e| {
                    format!("chunk at byte {offset}: its {compression} data do not decompress: {e}")
                })?,
            ),
            _ => None,
        };
        if let Some(actual) = actual.filter(|&actual| actual != declared) {
            let kind = if compression.is_empty() {
                "uncompressed"
            } else {
                compression
            };
            step_over(
                span,
                &mut walk,
                format!(
                    "chunk at byte {offset} declares {declared} bytes uncompressed, but its {present} bytes of {kind} data hold {actual}"
                ),
            );
            continue;
        }
        if compression.is_empty()
            && let Err(e) = check_chunk_records(records)
        {
            step_over(span, &mut walk, format!("chunk at byte {offset}: {e}"));
        }
    }
    // With its footer and closing magic the file was not cut short: a record that
    // does not read in the middle is damage, not its end (once read as a cut
    // recording: 7 frames of 30 and exit 0).
    if whole && !data_end {
        let damage = damage.unwrap_or_else(|| {
            format!("the records from byte {complete} on do not read as the data section's")
        });
        return Err(format!(
            "{damage}: the file is damaged there (its summary and closing magic are intact, so it was not cut short); `mcap recover` rewrites what it can read"
        ));
    }
    Ok(Layout {
        cut_at: (!(data_end && whole)).then_some(complete),
        data_complete: data_end,
        rosbag2_metadata,
        damaged,
    })
}

/// The value of `key` in a metadata record's body, when the record is `name`'s and
/// its lengths hold.
fn metadata_value(body: &[u8], name: &str, key: &str) -> Option<String> {
    check_lengths(op::METADATA, body).ok()?;
    // A u32 length and that many bytes, from the front of `rest`.
    fn take<'a>(rest: &mut &'a [u8]) -> Option<&'a [u8]> {
        let (length, after) = rest.split_first_chunk::<4>()?;
        let (field, after) = after.split_at_checked(u32::from_le_bytes(*length) as usize)?;
        *rest = after;
        Some(field)
    }
    let mut rest = body;
    if take(&mut rest)? != name.as_bytes() {
        return None;
    }
    let mut entries = take(&mut rest)?;
    while !entries.is_empty() {
        let (entry_key, value) = (take(&mut entries)?, take(&mut entries)?);
        if entry_key == key.as_bytes() {
            return String::from_utf8(value.to_vec()).ok();
        }
    }
    None
}

/// A chunk's declared uncompressed size, compression and records: after the start
/// and end times (16 bytes) come the size (8) and the uncompressed CRC (4).
pub fn chunk_parts(body: &[u8]) -> Option<(u64, &str, &[u8])> {
    let u64_at = |at: usize| Some(u64::from_le_bytes(body.get(at..at + 8)?.try_into().ok()?));
    let declared = u64_at(16)?;
    let name_len = u32::from_le_bytes(body.get(28..32)?.try_into().ok()?) as usize;
    let name_end = 32usize.checked_add(name_len)?;
    let compression = std::str::from_utf8(body.get(32..name_end)?).ok()?;
    let records_len = usize::try_from(u64_at(name_end)?).ok()?;
    let records = body.get(name_end + 8..(name_end + 8).checked_add(records_len)?)?;
    Some((declared, compression, records))
}

/// Checks that the records of an uncompressed chunk tile it exactly: the mcap
/// crate subtracts each record's declared length from what the chunk has left, and
/// one longer than the rest would wrap that count around.
fn check_chunk_records(records: &[u8]) -> Result<(), String> {
    let mut walk = RecordWalk {
        bytes: records,
        offset: 0,
    };
    for record in walk.by_ref() {
        record.map_err(|o| {
            format!(
                "its record at {} (opcode {:#04x}) claims {} bytes, but {} are left in the chunk",
                o.offset, o.opcode, o.length, o.available
            )
        })?;
    }
    if walk.offset < records.len() {
        return Err(format!(
            "its records end inside the header of the one at {}",
            walk.offset
        ));
    }
    Ok(())
}

/// How many bytes `records` decompress to, counting at most `limit + 1`.
fn decompressed_len(compression: &str, records: &[u8], limit: u64) -> std::io::Result<u64> {
    use std::io::Read;
    let mut sink = std::io::sink();
    match compression {
        "zstd" => zstd::stream::read::Decoder::new(records).and_then(|decoder| {
            std::io::copy(&mut decoder.take(limit.saturating_add(1)), &mut sink)
        }),
        _ => lz4::Decoder::new(records).and_then(|decoder| {
            std::io::copy(&mut decoder.take(limit.saturating_add(1)), &mut sink)
        }),
    }
}

/// An MCAP in memory of one message per payload on `/blob` (sequence numbers from
/// 0, log times from 1), in chunks of `chunk_bytes` (the crate's default when None).
#[cfg(test)]
pub fn blob_file(
    payloads: &[&[u8]],
    compression: Option<mcap::Compression>,
    chunk_bytes: Option<u64>,
) -> Vec<u8> {
    let mut writer = mcap::WriteOptions::new()
        .compression(compression)
        .chunk_size(chunk_bytes.or(Some(mcap::WriteOptions::DEFAULT_CHUNK_SIZE)))
        .create(std::io::Cursor::new(Vec::new()))
        .unwrap();
    let schema = writer.add_schema("blob", "", b"").unwrap();
    let channel = writer
        .add_channel(schema, "/blob", "cdr", &Default::default())
        .unwrap();
    for (sequence, payload) in (0..).zip(payloads) {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence,
            log_time: u64::from(sequence) + 1,
            publish_time: u64::from(sequence) + 1,
        };
        writer.write_to_known_channel(&header, payload).unwrap();
    }
    writer.finish().unwrap();
    writer.into_inner().into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcap::messages::Messages;

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
    fn a_metadata_records_value_is_found_by_name_and_key() {
        let entry = |key: &str, value: &str| [string(key), string(value)].concat();
        let map = [entry("other", "x"), entry("serialized_metadata", "mode: m")].concat();
        let body = [
            string("rosbag2"),
            (map.len() as u32).to_le_bytes().to_vec(),
            map.clone(),
        ]
        .concat();
        let value = |body: &[u8]| metadata_value(body, "rosbag2", "serialized_metadata");
        assert_eq!(value(&body).as_deref(), Some("mode: m"));
        let other_name = [
            string("other"),
            (map.len() as u32).to_le_bytes().to_vec(),
            map,
        ]
        .concat();
        assert_eq!(value(&other_name), None);
        assert_eq!(value(&body[..body.len() - 1]), None, "cut short");
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

    #[test]
    fn entry_arrays_of_part_entries_are_refused_before_parsing() {
        // A chunk index whose message index offsets (u16 -> u64 entries) are one byte:
        // the crate reads a whole entry past it, then takes the compression string's
        // length from inside another field (3.4 GB, what the fuzzer found).
        let chunk_index = |offsets: &[u8]| {
            let mut body = vec![0u8; 32];
            body.extend((offsets.len() as u32).to_le_bytes());
            body.extend(offsets);
            body.extend([0u8; 8]);
            body.extend(string("zstd"));
            body.extend([0u8; 16]);
            body
        };
        let whole = chunk_index(&[0u8; 10]);
        assert_eq!(check_lengths(op::CHUNK_INDEX, &whole), Ok(()));
        assert!(mcap::parse_record(op::CHUNK_INDEX, &whole).is_ok());
        let err = check_lengths(op::CHUNK_INDEX, &chunk_index(&[0u8; 11])).unwrap_err();
        assert!(
            err.contains(
                "its message_index_offsets are 11 bytes, not a whole number of 10-byte entries"
            ),
            "{err}"
        );
        let mut index = vec![0u8; 2];
        index.extend(17u32.to_le_bytes());
        index.extend([0u8; 17]);
        let err = check_lengths(op::MESSAGE_INDEX, &index).unwrap_err();
        assert!(err.contains("its records are 17 bytes"), "{err}");
    }

    /// The byte offset of the first chunk's declared uncompressed size.
    fn declared_size_offset(file: &[u8]) -> usize {
        let walk = RecordWalk {
            bytes: file,
            offset: 8,
        };
        let (offset, ..) = walk
            .map(|r| r.ok().unwrap())
            .find(|&(_, opcode, _)| opcode == op::CHUNK)
            .unwrap();
        offset + 9 + 16
    }

    #[test]
    fn a_chunk_that_really_decompresses_a_thousandfold_is_accepted() {
        // 80 MiB of zeros compress to a few kB, past both trust limits, so the
        // claim is checked by decompressing, and holds.
        let zeros = vec![0u8; 80 << 20];
        for compression in [mcap::Compression::Zstd, mcap::Compression::Lz4] {
            let file = blob_file(&[&zeros], Some(compression), None);
            assert!(file.len() < 1 << 20, "{}", file.len());
            // The records may be as long as the chunk, and the message is read whole.
            assert!(check_chunk_sizes(&file).is_ok());
            let message = Messages::new(&file, None, 2, None).next().unwrap().unwrap();
            assert_eq!(message.data.len(), 80 << 20);
        }
    }

    #[test]
    fn chunks_that_claim_more_than_they_hold_are_stepped_over() {
        let payload: Vec<u8> = (0..4096u32).map(|i| (i * 7 % 251) as u8).collect();
        for compression in [
            Some(mcap::Compression::Zstd),
            Some(mcap::Compression::Lz4),
            None,
        ] {
            let mut file = blob_file(&[&payload], compression, None);
            assert!(check_chunk_sizes(&file).is_ok());
            let at = declared_size_offset(&file);
            file[at..at + 8].copy_from_slice(&(1u64 << 40).to_le_bytes());
            // Never decompressed into the size it claims: a damaged chunk, its
            // messages lost, named.
            let layout = check_chunk_sizes(&file).unwrap();
            let [(span, problem)] = &layout.damaged[..] else {
                panic!("one damaged chunk: {layout:?}");
            };
            assert!(
                problem.contains("declares 1099511627776 bytes uncompressed")
                    && problem.contains("hold"),
                "{problem}"
            );
            assert!(span.bytes.start < at && at < span.bytes.end);
        }
    }
}
