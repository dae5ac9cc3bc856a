//! PCD point cloud files (PCL's format, v0.7 and older headers): `ascii`, `binary`
//! and `binary_compressed` data, read into a [`PointCloud2`] so that one decoder
//! ([`crate::payloads::cloud::cloud_points`]) handles every cloud travmap reads: field layout,
//! non-finite points, the intensity scale.
//!
//! The header is checked against the data before anything is allocated: a header
//! that lies (more points than the data holds, sizes that overflow) is an error.

use std::io::{BufRead, Read};
use std::path::Path;

use super::point_rows::{Encoding, Rows, header_line, open_buffered, read_rows};
use travmap_formats::ros::{PointCloud2, PointField, datatype};

/// No scan is near this; a header claiming more is not believed.
const LARGEST_CLOUD_BYTES: usize = 1 << 30;

/// One header field per column: name, byte size, type letter, count.
struct Column {
    name: String,
    size: usize,
    kind: char,
    count: usize,
}

impl Column {
    fn datatype(&self) -> Result<u8, String> {
        Ok(match (self.kind, self.size) {
            ('F', 4) => datatype::FLOAT32,
            ('F', 8) => datatype::FLOAT64,
            ('U', 1) => datatype::UINT8,
            ('U', 2) => datatype::UINT16,
            ('U', 4) => datatype::UINT32,
            ('I', 1) => datatype::INT8,
            ('I', 2) => datatype::INT16,
            ('I', 4) => datatype::INT32,
            (kind, size) => {
                return Err(format!(
                    "field `{}` has TYPE {kind} with SIZE {size}, which PCD does not define (F 4/8, U or I 1/2/4)",
                    self.name
                ));
            }
        })
    }
}

/// What a PCD header says: the columns, the records' layout (fields, point_step,
/// width and height; no data) and how the data is written.
struct PcdHeader {
    columns: Vec<Column>,
    layout: PointCloud2,
    points: usize,
    data_kind: String,
}

impl PcdHeader {
    fn rows(&self) -> Rows<'_> {
        Rows {
            layout: &self.layout,
            points: self.points,
            noun: ("point", "points"),
        }
    }

    /// The bytes of every record: `points` x `point_step`, if that fits.
    fn total_bytes(&self) -> Option<usize> {
        self.points.checked_mul(self.layout.point_step as usize)
    }
}

/// Parses a PCD file into a cloud in frame `frame_id`; the error says what is wrong.
pub fn parse_pcd(bytes: &[u8], frame_id: &str) -> Result<PointCloud2, String> {
    let mut read = bytes;
    let header = read_header(&mut read)?;
    let total = header
        .total_bytes()
        .filter(|total| *total <= LARGEST_CLOUD_BYTES)
        .ok_or_else(|| {
            format!(
                "{} points of {} bytes: more than the {LARGEST_CLOUD_BYTES} bytes travmap reads",
                header.points, header.layout.point_step
            )
        })?;
    // Bounded by the bytes present: a header cannot make this reserve more.
    let mut data = Vec::with_capacity(total.min(bytes.len()));
    read_body(&mut read, &header, &mut |chunk| {
        data.extend_from_slice(&chunk.data);
        Ok(())
    })?;
    let mut cloud = header.layout;
    cloud.header.frame_id = frame_id.to_string();
    cloud.data = data;
    Ok(cloud)
}

/// Reads the PCD file at `path` a chunk of points at a time (see `read_rows`),
/// so memory stays the chunk's: ascii and binary data stream from the file;
/// binary_compressed data (LZF over whole columns) is decompressed whole first.
pub fn stream_pcd(
    path: &Path,
    on_chunk: &mut dyn FnMut(&PointCloud2) -> Result<(), String>,
) -> Result<(), String> {
    let mut read = open_buffered(path)?;
    let header = read_header(&mut read)?;
    header.total_bytes().ok_or_else(|| {
        format!(
            "{} points of {} bytes overflow",
            header.points, header.layout.point_step
        )
    })?;
    read_body(&mut read, &header, on_chunk)
}

/// Reads the header through its DATA line.
fn read_header(read: &mut impl BufRead) -> Result<PcdHeader, String> {
    let mut columns: Vec<Column> = Vec::new();
    let (mut width, mut height, mut points) = (None, 1usize, None);
    let (mut at, mut bytes) = (0, Vec::new());
    let data_kind = loop {
        if !header_line(read, &mut bytes)? {
            return Err("the header ends before its DATA line".into());
        }
        let line = std::str::from_utf8(&bytes)
            .map_err(|_| format!("header line at byte {at} is not text"))?
            .trim();
        at += bytes.len();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut words = line.split_whitespace();
        let key = words.next().unwrap_or_default().to_ascii_uppercase();
        let values: Vec<&str> = words.collect();
        let number = |v: &str| {
            v.parse::<usize>()
                .map_err(|_| format!("{key}: `{v}` is not a count"))
        };
        match key.as_str() {
            "FIELDS" => {
                columns = values
                    .iter()
                    .map(|name| Column {
                        name: name.to_string(),
                        size: 4,
                        kind: 'F',
                        count: 1,
                    })
                    .collect();
            }
            "SIZE" | "TYPE" | "COUNT" => {
                if values.len() != columns.len() {
                    return Err(format!(
                        "{key} has {} values for {} FIELDS",
                        values.len(),
                        columns.len()
                    ));
                }
                for (column, value) in columns.iter_mut().zip(&values) {
                    match key.as_str() {
                        "SIZE" => column.size = number(value)?,
                        "COUNT" => column.count = number(value)?,
                        _ => column.kind = value.chars().next().unwrap_or('?'),
                    }
                }
            }
            "WIDTH" => width = Some(number(values.first().copied().unwrap_or_default())?),
            "HEIGHT" => height = number(values.first().copied().unwrap_or_default())?,
            "POINTS" => points = Some(number(values.first().copied().unwrap_or_default())?),
            "DATA" => break values.first().copied().unwrap_or_default().to_string(),
            // VERSION, VIEWPOINT: nothing the method needs.
            _ => {}
        }
    };
    if columns.is_empty() {
        return Err("no FIELDS line before DATA".into());
    }
    let width = width.ok_or("no WIDTH line before DATA")?;
    let points = points.unwrap_or(width.saturating_mul(height));
    if width.checked_mul(height) != Some(points) {
        return Err(format!(
            "WIDTH {width} x HEIGHT {height} is not POINTS {points}"
        ));
    }
    // A field of no values holds no data, so its neighbours' bytes would be read as
    // another field's: PCL writes COUNT 1 for scalars, never 0.
    if let Some(empty) = columns.iter().find(|c| c.count == 0 || c.size == 0) {
        return Err(format!(
            "field {} has SIZE {} and COUNT {}: every field holds at least one value of at least one byte",
            empty.name, empty.size, empty.count
        ));
    }
    let mut fields = Vec::with_capacity(columns.len());
    let mut point_step = 0usize;
    for column in &columns {
        fields.push(PointField {
            name: column.name.clone(),
            offset: u32::try_from(point_step).map_err(|_| "fields too wide")?,
            datatype: column.datatype()?,
            count: u32::try_from(column.count).map_err(|_| "COUNT too large")?,
        });
        point_step = column
            .size
            .checked_mul(column.count)
            .and_then(|bytes| point_step.checked_add(bytes))
            .ok_or("SIZE x COUNT overflows")?;
    }
    let point_step_u32 = u32::try_from(point_step).map_err(|_| "fields too wide")?;
    let layout = PointCloud2 {
        height: u32::try_from(height).map_err(|_| "HEIGHT too large")?,
        width: u32::try_from(width).map_err(|_| "WIDTH too large")?,
        fields,
        point_step: point_step_u32,
        row_step: point_step
            .saturating_mul(width)
            .try_into()
            .unwrap_or(u32::MAX),
        ..PointCloud2::default()
    };
    Ok(PcdHeader {
        columns,
        layout,
        points,
        data_kind,
    })
}

/// The data after the header, a chunk of points at a time.
fn read_body(
    read: &mut impl BufRead,
    header: &PcdHeader,
    on_chunk: &mut dyn FnMut(&PointCloud2) -> Result<(), String>,
) -> Result<(), String> {
    let rows = header.rows();
    match header.data_kind.as_str() {
        "binary" => read_rows(read, &rows, &Encoding::Binary, on_chunk),
        "ascii" => {
            let value_types = (header.columns.iter())
                .map(|c| c.datatype().map(|d| std::iter::repeat_n(d, c.count)))
                .collect::<Result<Vec<_>, _>>()?
                .into_iter()
                .flatten()
                .collect();
            read_rows(read, &rows, &Encoding::Ascii(value_types), on_chunk)
        }
        "binary_compressed" => {
            let body = compressed_rows(read, header)?;
            read_rows(&mut &body[..], &rows, &Encoding::Binary, on_chunk)
        }
        other => Err(format!(
            "DATA `{other}`; PCD data is ascii, binary or binary_compressed"
        )),
    }
}

/// `binary_compressed`: sizes, then LZF of the columns one after another (all x, then
/// all y, ...), turned back into rows.
fn compressed_rows(read: &mut impl BufRead, header: &PcdHeader) -> Result<Vec<u8>, String> {
    let (points, columns) = (header.points, &header.columns);
    let total = header.total_bytes().unwrap_or(usize::MAX);
    let mut sizes = [0u8; 8];
    read.read_exact(&mut sizes)
        .map_err(|_| "binary_compressed DATA shorter than its two sizes".to_string())?;
    let word = |at: usize| {
        u32::from_le_bytes([sizes[at], sizes[at + 1], sizes[at + 2], sizes[at + 3]]) as usize
    };
    let (compressed, uncompressed) = (word(0), word(4));
    if uncompressed != total {
        return Err(format!(
            "binary_compressed DATA says {uncompressed} bytes uncompressed; {points} points of the header's fields are {total}"
        ));
    }
    // Grown as it is read: a size that lies cannot make this reserve more.
    let mut source = Vec::new();
    read.take(compressed as u64)
        .read_to_end(&mut source)
        .map_err(|e| format!("reading binary_compressed DATA: {e}"))?;
    if source.len() < compressed {
        return Err(format!(
            "binary_compressed DATA claims {compressed} compressed bytes, {} follow",
            source.len()
        ));
    }
    // LZF shortens by a few times at most: a larger claim is not believed.
    let largest = source.len().saturating_mul(8).max(LARGEST_CLOUD_BYTES);
    if total > largest {
        return Err(format!(
            "binary_compressed DATA says {total} bytes uncompressed from {compressed}: more than LZF can make"
        ));
    }
    let columnar = lzf_decompress(&source, uncompressed)?;
    drop(source);
    let point_step = total / points.max(1);
    let mut rows = vec![0u8; total];
    let (mut column_start, mut offset) = (0, 0);
    for column in columns {
        let width = column.size * column.count;
        for point in 0..points {
            let from = column_start + point * width;
            let to = point * point_step + offset;
            rows[to..to + width].copy_from_slice(&columnar[from..from + width]);
        }
        column_start += width * points;
        offset += width;
    }
    Ok(rows)
}

/// LZF (liblzf), as PCL writes it: literal runs and back references, decompressing
/// to exactly `expected` bytes.
fn lzf_decompress(input: &[u8], expected: usize) -> Result<Vec<u8>, String> {
    let corrupt =
        |at: usize| format!("binary_compressed DATA is corrupt at byte {at} of its LZF stream");
    let mut out = Vec::with_capacity(expected);
    let mut at = 0;
    while at < input.len() {
        let control = input[at] as usize;
        at += 1;
        if control < 32 {
            let run = control + 1;
            let literal = input.get(at..at + run).ok_or_else(|| corrupt(at))?;
            if out.len() + run > expected {
                return Err(corrupt(at));
            }
            out.extend_from_slice(literal);
            at += run;
        } else {
            let mut length = control >> 5;
            if length == 7 {
                length += *input.get(at).ok_or_else(|| corrupt(at))? as usize;
                at += 1;
            }
            let low = *input.get(at).ok_or_else(|| corrupt(at))? as usize;
            at += 1;
            let distance = ((control & 0x1f) << 8) + low + 1;
            let length = length + 2;
            if distance > out.len() || out.len() + length > expected {
                return Err(corrupt(at));
            }
            // Byte by byte: a reference may overlap what it writes.
            let start = out.len() - distance;
            for k in 0..length {
                out.push(out[start + k]);
            }
        }
    }
    if out.len() != expected {
        return Err(format!(
            "binary_compressed DATA decompresses to {} bytes, not the {expected} it says",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payloads::cloud::cloud_points;

    const HEADER: &str = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\n";
    const POINTS: [[f32; 4]; 3] = [
        [1.0, 2.0, 3.0, 0.5],
        [-1.0, 0.0, 0.25, 0.0],
        [4.0, 5.0, 6.0, 1.0],
    ];

    fn rows() -> Vec<u8> {
        POINTS
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }

    #[test]
    fn ascii_binary_and_compressed_give_the_same_points() {
        let ascii = format!("{HEADER}DATA ascii\n1 2 3 0.5\n-1 0 0.25 0\n4 5 6 1\n");
        let binary = [format!("{HEADER}DATA binary\n").into_bytes(), rows()].concat();
        // Columns one after another, stored as LZF literal runs (what liblzf writes
        // for data it cannot shorten).
        let columnar: Vec<u8> = (0..4)
            .flat_map(|c| POINTS.iter().flat_map(move |p| p[c].to_le_bytes()))
            .collect();
        let mut lzf = Vec::new();
        for run in columnar.chunks(32) {
            lzf.push(run.len() as u8 - 1);
            lzf.extend_from_slice(run);
        }
        let mut compressed = format!("{HEADER}DATA binary_compressed\n").into_bytes();
        compressed.extend_from_slice(&(lzf.len() as u32).to_le_bytes());
        compressed.extend_from_slice(&(columnar.len() as u32).to_le_bytes());
        compressed.extend_from_slice(&lzf);
        for bytes in [ascii.into_bytes(), binary, compressed] {
            let cloud = parse_pcd(&bytes, "lidar").unwrap();
            let points = cloud_points(&cloud).unwrap();
            assert_eq!(points.points, POINTS.to_vec());
            assert_eq!(points.remission, travmap_core::frame::RemissionScale::Unit);
        }
    }

    #[test]
    fn a_field_of_no_values_is_refused() {
        let header = HEADER.replace("COUNT 1 1 1 1", "COUNT 0 1 1 1");
        let binary = [format!("{header}DATA binary\n").into_bytes(), rows()].concat();
        let err = parse_pcd(&binary, "lidar").unwrap_err();
        assert!(err.contains("field x has SIZE 4 and COUNT 0"), "{err}");
        let header = HEADER.replace("SIZE 4 4 4 4", "SIZE 4 4 0 4");
        let binary = [format!("{header}DATA binary\n").into_bytes(), rows()].concat();
        assert!(
            parse_pcd(&binary, "lidar")
                .unwrap_err()
                .contains("field z has SIZE 0")
        );
    }

    #[test]
    fn lzf_back_references_repeat_what_came_before() {
        // "abc" then a reference 3 back of length 6: "abcabcabc".
        let input = [2, b'a', b'b', b'c', (4 << 5) as u8, 2];
        assert_eq!(lzf_decompress(&input, 9).unwrap(), b"abcabcabc");
        assert!(lzf_decompress(&input, 8).is_err());
        assert!(lzf_decompress(&[(1 << 5) as u8, 9], 3).is_err());
    }

    #[test]
    fn headers_that_lie_are_errors() {
        let short = [
            format!("{HEADER}DATA binary\n").into_bytes(),
            rows()[..20].to_vec(),
        ]
        .concat();
        let err = parse_pcd(&short, "lidar").unwrap_err();
        assert!(
            err.contains("3 points of 16 bytes (48 bytes) but 20 bytes"),
            "{err}"
        );
        let huge = HEADER
            .replace("WIDTH 3", "WIDTH 4000000000")
            .replace("POINTS 3", "POINTS 4000000000");
        let err = parse_pcd(format!("{huge}DATA binary\n").as_bytes(), "lidar").unwrap_err();
        assert!(err.contains("more than the"), "{err}");
        let few = format!("{HEADER}DATA ascii\n1 2 3 0.5\n");
        assert!(
            parse_pcd(few.as_bytes(), "lidar")
                .unwrap_err()
                .contains("the data ends after 1")
        );
        let mismatch = HEADER.replace("SIZE 4 4 4 4", "SIZE 4 4 4");
        assert!(
            parse_pcd(format!("{mismatch}DATA binary\n").as_bytes(), "lidar")
                .unwrap_err()
                .contains("SIZE has 3 values for 4 FIELDS")
        );
    }
}
