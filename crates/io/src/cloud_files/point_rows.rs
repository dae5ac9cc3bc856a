//! The body of a point cloud file (PCD, PLY) read a chunk of points at a time as
//! PointCloud2 rows: binary records as they are, ascii lines written into the same
//! little-endian layout. A site cloud streams through it with memory bounded by the
//! chunk whatever the file's size; a scan is one pass that keeps every chunk.

use std::io::BufRead;

use travmap_formats::ros::{PointCloud2, datatype};

/// Points per chunk: 1-2 MB of rows for the usual layouts.
pub const CHUNK_POINTS: usize = 1 << 16;
/// Bytes per chunk at most: a header of many properties (100,000 in a PLY: 800 kB a
/// record) would make [`CHUNK_POINTS`] records 50 GB.
const CHUNK_BYTES: usize = 16 << 20;

/// What the body of a file holds, as its header says.
pub struct Rows<'a> {
    /// The fields and `point_step` of every record (width and data are the chunk's).
    pub layout: &'a PointCloud2,
    pub points: usize,
    /// How the file names one record and several ("point", "points").
    pub noun: (&'static str, &'static str),
}

/// How the records are written.
pub enum Encoding {
    /// Packed records of `point_step` bytes.
    Binary,
    /// One record per non-empty line: this datatype per value, in order.
    Ascii(Vec<u8>),
}

/// Reads the `rows.points` records of `body`, giving each chunk of up to
/// [`CHUNK_POINTS`] (and [`CHUNK_BYTES`]) to `on_chunk` as a cloud of that many
/// points (height 1).
pub fn read_rows(
    body: &mut impl BufRead,
    rows: &Rows,
    encoding: &Encoding,
    on_chunk: &mut dyn FnMut(&PointCloud2) -> Result<(), String>,
) -> Result<(), String> {
    let step = rows.layout.point_step as usize;
    let mut chunk: PointCloud2 = PointCloud2 {
        fields: rows.layout.fields.clone(),
        is_bigendian: rows.layout.is_bigendian,
        point_step: rows.layout.point_step,
        height: 1,
        ..PointCloud2::default()
    };
    let mut line = String::new();
    let mut done = 0;
    while done < rows.points {
        let n = (CHUNK_POINTS.min(CHUNK_BYTES / step.max(1)).max(1)).min(rows.points - done);
        chunk.data.clear();
        match encoding {
            Encoding::Binary => {
                chunk.data.resize(n * step, 0);
                let got = read_fully(body, &mut chunk.data)
                    .map_err(|e| format!("reading the data: {e}"))?;
                if got < chunk.data.len() {
                    let total = rows.points as u128 * step as u128;
                    return Err(format!(
                        "the header says {} {} of {step} bytes ({total} bytes) but {} bytes of data follow",
                        rows.points,
                        rows.noun.1,
                        done * step + got
                    ));
                }
            }
            Encoding::Ascii(value_types) => {
                for index in done..done + n {
                    if !next_line(body, &mut line)? {
                        return Err(format!(
                            "the header says {} {} but the data ends after {index}",
                            rows.points, rows.noun.1
                        ));
                    }
                    ascii_record(&line, value_types, &mut chunk.data)
                        .map_err(|e| format!("{} {index}: {e}", rows.noun.0))?;
                }
            }
        }
        chunk.width = n as u32;
        chunk.row_step = (n * step) as u32;
        on_chunk(&chunk)?;
        done += n;
    }
    Ok(())
}

/// Fills `buffer` from `read` as far as it goes; the bytes read.
fn read_fully(read: &mut impl BufRead, buffer: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buffer.len() {
        match read.read(&mut buffer[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// The next non-empty line into `line`; false at the end.
fn next_line(read: &mut impl BufRead, line: &mut String) -> Result<bool, String> {
    loop {
        line.clear();
        let n = read
            .read_line(line)
            .map_err(|_| "ascii data that is not text".to_string())?;
        if n == 0 {
            return Ok(false);
        }
        if !line.trim().is_empty() {
            return Ok(true);
        }
    }
}

/// One ascii record written as little-endian values of `value_types`; values after
/// those are ignored.
fn ascii_record(line: &str, value_types: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    let mut values = line.split_whitespace();
    for (i, &datatype_id) in value_types.iter().enumerate() {
        let value = values
            .next()
            .ok_or_else(|| format!("{i} values; the header's fields need {}", value_types.len()))?;
        let number: f64 = value
            .parse()
            .map_err(|_| format!("`{value}` is not a number"))?;
        match datatype_id {
            datatype::INT8 => out.push(number as i8 as u8),
            datatype::UINT8 => out.push(number as u8),
            datatype::INT16 => out.extend((number as i16).to_le_bytes()),
            datatype::UINT16 => out.extend((number as u16).to_le_bytes()),
            datatype::INT32 => out.extend((number as i32).to_le_bytes()),
            datatype::UINT32 => out.extend((number as u32).to_le_bytes()),
            datatype::FLOAT32 => out.extend((number as f32).to_le_bytes()),
            _ => out.extend(number.to_le_bytes()),
        }
    }
    Ok(())
}

/// The file at `path`, buffered for reading its header and body in chunks.
pub fn open_buffered(path: &std::path::Path) -> Result<std::io::BufReader<std::fs::File>, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    Ok(std::io::BufReader::with_capacity(1 << 20, file))
}

/// Reads a header line of at most 64 KiB (with its newline) into `line`, for
/// headers read from a reader: a binary file with no newline is not read whole.
/// False at the end of the input.
pub fn header_line(read: &mut impl BufRead, line: &mut Vec<u8>) -> Result<bool, String> {
    const LONGEST: u64 = 1 << 16;
    line.clear();
    let n = std::io::Read::take(&mut *read, LONGEST)
        .read_until(b'\n', line)
        .map_err(|e| format!("reading the header: {e}"))?;
    if n as u64 == LONGEST && line.last() != Some(&b'\n') {
        return Err("a header line is longer than 64 KiB: not a point cloud header".into());
    }
    Ok(n > 0)
}
