//! PLY point clouds (Stanford Triangle Format), as Open3D, CloudCompare, PCL and
//! Python's plyfile write them: `ascii`, `binary_little_endian` and
//! `binary_big_endian`, read as a PointCloud2 of the `vertex` element's scalar
//! properties, which must come first (the elements after it, faces, are ignored).
//!
//! A binary vertex element is already a packed record per point: it becomes the
//! cloud's data as it is, each property a field at its offset. ASCII values are
//! written into the same layout. CloudCompare's `scalar_Intensity` is the intensity.

use std::io::BufRead;
use std::path::Path;

use super::point_rows::{self, Rows, header_line, open_buffered, read_rows};
use travmap_formats::ros::{PointCloud2, PointField, datatype};

/// The PointField datatype and size of a PLY scalar type.
fn scalar_type(name: &str) -> Option<(u8, usize)> {
    Some(match name {
        "char" | "int8" => (datatype::INT8, 1),
        "uchar" | "uint8" => (datatype::UINT8, 1),
        "short" | "int16" => (datatype::INT16, 2),
        "ushort" | "uint16" => (datatype::UINT16, 2),
        "int" | "int32" => (datatype::INT32, 4),
        "uint" | "uint32" => (datatype::UINT32, 4),
        "float" | "float32" => (datatype::FLOAT32, 4),
        "double" | "float64" => (datatype::FLOAT64, 8),
        _ => return None,
    })
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

/// The field name travmap reads a PLY property as.
fn field_name(property: &str) -> &str {
    match property {
        "scalar_Intensity" | "scalar_intensity" | "Intensity" => "intensity",
        other => other,
    }
}

/// What a PLY header says of its vertices: their layout (fields, point_step; no
/// data), count and encoding.
struct PlyHeader {
    layout: PointCloud2,
    points: usize,
    encoding: Encoding,
}

impl PlyHeader {
    fn read_body(
        &self,
        read: &mut impl BufRead,
        on_chunk: &mut dyn FnMut(&PointCloud2) -> Result<(), String>,
    ) -> Result<(), String> {
        let rows = Rows {
            layout: &self.layout,
            points: self.points,
            noun: ("vertex", "vertices"),
        };
        let encoding = match self.encoding {
            Encoding::Ascii => {
                point_rows::Encoding::Ascii(self.layout.fields.iter().map(|f| f.datatype).collect())
            }
            Encoding::LittleEndian | Encoding::BigEndian => point_rows::Encoding::Binary,
        };
        read_rows(read, &rows, &encoding, on_chunk)
    }
}

/// The PLY file `bytes` as a cloud in `frame_id`; errors say what is wrong. The
/// readers stream PLY files (`stream_ply`); this whole-file form is the fuzzer's.
#[cfg(any(test, feature = "fuzzing"))]
pub fn parse_ply(bytes: &[u8], frame_id: &str) -> Result<PointCloud2, String> {
    let mut read = bytes;
    let header = read_header(&mut read)?;
    // Bounded by the bytes present: a header cannot make this reserve more.
    let mut data = Vec::with_capacity(
        (header.layout.point_step as usize)
            .saturating_mul(header.points)
            .min(bytes.len()),
    );
    header.read_body(&mut read, &mut |chunk| {
        data.extend_from_slice(&chunk.data);
        Ok(())
    })?;
    let mut cloud = header.layout;
    cloud.header.frame_id = frame_id.to_string();
    cloud.width = header.points as u32;
    cloud.row_step = data.len() as u32;
    cloud.data = data;
    Ok(cloud)
}

/// Reads the PLY file at `path` a chunk of vertices at a time (see `read_rows`),
/// so memory stays the chunk's whatever the file's size.
pub fn stream_ply(
    path: &Path,
    on_chunk: &mut dyn FnMut(&PointCloud2) -> Result<(), String>,
) -> Result<(), String> {
    let mut read = open_buffered(path)?;
    read_header(&mut read)?.read_body(&mut read, on_chunk)
}

/// Reads the header through its `end_header` line.
fn read_header(read: &mut impl BufRead) -> Result<PlyHeader, String> {
    let mut encoding = None;
    let mut points: Option<usize> = None;
    let (mut in_vertex, mut past_vertex) = (false, false);
    let mut fields = Vec::new();
    let mut step = 0usize;
    let mut bytes = Vec::new();
    let mut first = true;
    loop {
        if !header_line(read, &mut bytes)? {
            return Err("no `end_header` line: not a PLY file, or cut off in its header".into());
        }
        let line = std::str::from_utf8(&bytes)
            .map_err(|_| "the header is not text".to_string())?
            .trim();
        if std::mem::take(&mut first) {
            if line != "ply" {
                return Err("does not begin with `ply`".into());
            }
            continue;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            // The elements after the vertices are not read.
            _ if past_vertex => {}
            ["format", format, "1.0"] => {
                encoding = Some(match *format {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::LittleEndian,
                    "binary_big_endian" => Encoding::BigEndian,
                    other => return Err(format!("unknown format `{other}`")),
                });
            }
            ["element", name, count] => {
                if points.is_some() {
                    past_vertex = true;
                    continue;
                }
                if *name != "vertex" {
                    return Err(format!(
                        "the first element is `{name}`; travmap reads PLY files whose first element is `vertex`"
                    ));
                }
                in_vertex = true;
                points = Some(
                    count
                        .parse()
                        .map_err(|_| format!("element vertex count `{count}`"))?,
                );
            }
            ["property", "list", ..] if in_vertex => {
                return Err("the vertex element has a list property; travmap reads scalar vertex properties".into());
            }
            ["property", kind, name] if in_vertex => {
                let (datatype, size) = scalar_type(kind)
                    .ok_or_else(|| format!("property `{name}` has unknown type `{kind}`"))?;
                fields.push(PointField::scalar(field_name(name), step as u32, datatype));
                step += size;
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["property", ..] => {}
            _ => return Err(format!("header line `{line}` is not PLY")),
        }
    }
    let encoding = encoding.ok_or("no `format` line")?;
    let points = points.ok_or("no `element vertex` line")?;
    if step == 0 {
        return Err("the vertex element has no property".into());
    }
    let layout = PointCloud2 {
        height: 1,
        fields,
        is_bigendian: encoding == Encoding::BigEndian,
        point_step: step as u32,
        ..PointCloud2::default()
    };
    Ok(PlyHeader {
        layout,
        points,
        encoding,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payloads::cloud::cloud_points;

    const POINTS: [[f32; 4]; 2] = [[1.0, 2.0, 3.0, 0.5], [-4.0, 5.5, -6.25, 0.25]];

    fn header(format: &str) -> String {
        format!(
            "ply\nformat {format} 1.0\ncomment made by a test\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty double scalar_Intensity\nproperty uchar red\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
        )
    }

    fn read(bytes: &[u8]) -> Vec<[f32; 4]> {
        cloud_points(&parse_ply(bytes, "site").unwrap())
            .unwrap()
            .points
    }

    #[test]
    fn ascii_and_both_binary_encodings_read_the_same_points() {
        let mut ascii = header("ascii");
        for p in POINTS {
            ascii += &format!("{} {} {} {} 200\n", p[0], p[1], p[2], p[3]);
        }
        let binary = |big: bool| {
            let mut bytes = header(if big {
                "binary_big_endian"
            } else {
                "binary_little_endian"
            })
            .into_bytes();
            for p in POINTS {
                for v in &p[..3] {
                    bytes.extend(if big {
                        v.to_be_bytes()
                    } else {
                        v.to_le_bytes()
                    });
                }
                let i = p[3] as f64;
                bytes.extend(if big {
                    i.to_be_bytes()
                } else {
                    i.to_le_bytes()
                });
                bytes.push(200);
            }
            bytes
        };
        assert_eq!(read(ascii.as_bytes()), POINTS);
        assert_eq!(read(&binary(false)), POINTS);
        assert_eq!(read(&binary(true)), POINTS);
    }

    #[test]
    fn a_file_that_lies_or_is_not_a_point_list_is_refused() {
        let cut = header("binary_little_endian").into_bytes();
        let err = parse_ply(&cut, "site").unwrap_err();
        assert!(
            err.contains("2 vertices of 21 bytes (42 bytes) but 0 bytes"),
            "{err}"
        );
        let short = header("ascii") + "1 2 3 0.5 200\n";
        let err = parse_ply(short.as_bytes(), "site").unwrap_err();
        assert!(err.contains("the data ends after 1"), "{err}");
        let faces_first = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 1\nproperty float x\nend_header\n";
        let err = parse_ply(faces_first.as_bytes(), "site").unwrap_err();
        assert!(err.contains("first element is `face`"), "{err}");
        let err = parse_ply(b"ply\nformat ascii 1.0\nelement vertex 1\n", "site").unwrap_err();
        assert!(err.contains("end_header"), "{err}");
    }
}
