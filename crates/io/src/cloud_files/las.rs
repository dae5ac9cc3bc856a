//! LAS and LAZ point clouds (ASPRS LAS 1.0-1.4, any point format; LAZ through the
//! `las` crate's laz support) as a site cloud: coordinates with the file's scale and
//! offset applied, then moved to a local origin so float32 keeps centimetres.
//!
//! Survey clouds sit in projected coordinates (UTM northings of millions of metres),
//! where a float32 steps in tenths of a metre: the points are stored relative to
//! [`LasPlace::origin_m`], the bounds' minimum floored to 100 m, and the notice says so.
//! Intensity is read as it is stored: LAS asks writers to scale it to 16 bits, but
//! files hold 8-bit, 12-bit and 16-bit values alike, so its scale is unknown.

use std::path::Path;

use travmap_core::error::contain_panics;

/// Bytes of point records decoded per batch: the decoded copy stays this small
/// whatever the file, and a header claiming 64 KiB records cannot make it large.
const BATCH_BYTES: u64 = 8 << 20;

/// What is given each batch of points (x, y, z, intensity), to keep or refuse.
pub type OnPoints<'a> = dyn FnMut(&[[f32; 4]]) -> Result<(), String> + 'a;

/// Where a LAS / LAZ file's points lie.
pub struct LasPlace {
    /// Where the points' (0, 0, 0) lies in the file's coordinates.
    pub origin_m: [f64; 3],
    /// The coordinate reference system the file names (its WKT), when it names one.
    pub crs_wkt: Option<String>,
    /// Points dropped for a non-finite coordinate.
    pub dropped: usize,
}

/// The local origin of points within `min`: floored to 100 m, so it reads plainly.
fn local_origin(min: [f64; 3]) -> [f64; 3] {
    min.map(|v| (v / 100.0).floor() * 100.0)
}

/// Reads the LAS or LAZ file at `path` a batch of points at a time: x, y, z
/// relative to the returned origin, and the intensity as stored. Errors say what is
/// wrong.
pub fn stream_las(path: &Path, on_points: &mut OnPoints) -> Result<LasPlace, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let file_bytes = file.metadata().map_or(0, |m| m.len());
    las_points(std::io::BufReader::new(file), file_bytes, on_points)
}

/// [`stream_las`] on a reader of `file_bytes` bytes. The laz crate panics on some
/// damaged LAZ data rather than returning an error: the panic becomes the error.
pub fn las_points<R>(read: R, file_bytes: u64, on_points: &mut OnPoints) -> Result<LasPlace, String>
where
    R: std::io::Read + std::io::Seek + Send + Sync + 'static,
{
    contain_panics(|| read_points(read, file_bytes, on_points)).unwrap_or_else(|panic| {
        Err(format!(
            "damaged LAS / LAZ data (the reader stopped: {panic})"
        ))
    })
}

fn read_points<R>(read: R, file_bytes: u64, on_points: &mut OnPoints) -> Result<LasPlace, String>
where
    R: std::io::Read + std::io::Seek + Send + Sync + 'static,
{
    let mut read = read;
    check_chunk_table(&mut read, file_bytes)?;
    let mut reader = las::Reader::new(read)
        .map_err(|e| format!("not a readable LAS / LAZ header (cut off or damaged?): {e}"))?;
    let header = reader.header();
    // A scale of 0 puts every point at the offset (the cloud collapses), a negative
    // one mirrors the axis: no writer means either, and the map would be of nothing
    // or of a mirrored site.
    let transforms = header.transforms();
    for (axis, transform) in [
        ("x", transforms.x),
        ("y", transforms.y),
        ("z", transforms.z),
    ] {
        if !(transform.scale.is_finite() && transform.scale > 0.0) {
            return Err(format!(
                "the header's {axis} scale is {}: a positive scale expected (0 collapses the cloud onto one point, a negative scale mirrors it)",
                transform.scale
            ));
        }
    }
    let bounds = header.bounds();
    let origin_m = local_origin([bounds.min.x, bounds.min.y, bounds.min.z]);
    let crs_wkt = header.get_wkt_crs_bytes().map(|bytes| {
        String::from_utf8_lossy(bytes)
            .trim_end_matches('\0')
            .to_string()
    });
    let total = header.number_of_points();
    let batch_points = (BATCH_BYTES / u64::from(header.point_format().len()).max(1)).max(1);
    let mut points = Vec::new();
    let (mut kept, mut dropped) = (0, 0);
    loop {
        let batch = reader.read_points(batch_points).map_err(|e| {
            format!(
                "the point data is damaged or cut off after {} points ({e})",
                kept + dropped
            )
        })?;
        if batch.is_empty() {
            break;
        }
        points.clear();
        let xyz = batch.x().zip(batch.y()).zip(batch.z());
        for (((x, y), z), intensity) in xyz.zip(batch.intensity()) {
            let local = [x - origin_m[0], y - origin_m[1], z - origin_m[2]];
            if local.iter().all(|v| v.is_finite()) {
                let intensity = f32::from(intensity);
                points.push([local[0] as f32, local[1] as f32, local[2] as f32, intensity]);
            } else {
                dropped += 1;
            }
        }
        kept += points.len();
        on_points(&points)?;
    }
    if (kept + dropped) as u64 != total {
        return Err(format!(
            "the header says {total} points but {} could be read",
            kept + dropped
        ));
    }
    Ok(LasPlace {
        origin_m,
        crs_wkt,
        dropped,
    })
}

/// Refuses a LAZ file whose chunk table claims more chunks than its bytes could
/// hold, before the laz crate reserves a table of that size (an allocation that
/// fails aborts the process: a damaged file must be an error, not a crash).
fn check_chunk_table<R: std::io::Read + std::io::Seek>(
    read: &mut R,
    file_bytes: u64,
) -> Result<(), String> {
    use std::io::SeekFrom;
    let at = |read: &mut R, offset: u64, bytes: usize| -> Option<u64> {
        let mut word = [0u8; 8];
        read.seek(SeekFrom::Start(offset)).ok()?;
        read.read_exact(&mut word[..bytes]).ok()?;
        Some(u64::from_le_bytes(word))
    };
    // Header: offset to point data at byte 96, point format at 104 (bit 7 or 6: LAZ).
    let (Some(point_data), Some(format)) = (at(read, 96, 4), at(read, 104, 1)) else {
        read.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
        return Ok(()); // too short: the las crate says what is wrong
    };
    if format & 0xC0 != 0 {
        // The point data of a LAZ file begins with the chunk table's offset (-1: none).
        let table = at(read, point_data, 8).map(|v| v as i64);
        if let Some(table @ 0..) = table {
            let chunks = at(read, table as u64 + 4, 4);
            if let Some(chunks) = chunks.filter(|&c| c.saturating_mul(8) > file_bytes) {
                return Err(format!(
                    "the LAZ chunk table at byte {table} claims {chunks} chunks, more than the file's {file_bytes} bytes could hold: the file is damaged"
                ));
            }
        }
    }
    read.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_local_origin_floors_to_100_m() {
        assert_eq!(
            local_origin([512_345.67, 4_102_999.9, -12.5]),
            [512_300.0, 4_102_900.0, -100.0]
        );
    }

    #[test]
    fn a_written_las_file_reads_back_relative_to_its_origin() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("site.las");
        let mut builder = las::Builder::from((1, 2));
        builder.transforms = las::Vector {
            x: las::Transform {
                scale: 0.001,
                offset: 512_000.0,
            },
            y: las::Transform {
                scale: 0.001,
                offset: 4_100_000.0,
            },
            z: las::Transform {
                scale: 0.001,
                offset: 0.0,
            },
        };
        let mut writer = las::Writer::from_path(&path, builder.into_header().unwrap()).unwrap();
        for (x, y, z) in [
            (512_345.678, 4_102_345.001, 10.5),
            (512_350.0, 4_102_300.25, 11.0),
        ] {
            writer
                .write_point(las::Point {
                    x,
                    y,
                    z,
                    intensity: 900,
                    ..Default::default()
                })
                .unwrap();
        }
        writer.close().unwrap();
        let mut points = Vec::new();
        let mut keep = |batch: &[[f32; 4]]| {
            points.extend_from_slice(batch);
            Ok(())
        };
        let place = stream_las(&path, &mut keep).unwrap();
        assert_eq!(place.origin_m, [512_300.0, 4_102_300.0, 0.0]);
        assert_eq!(place.dropped, 0);
        let expected = [[45.678, 45.001, 10.5], [50.0, 0.25, 11.0]];
        assert_eq!(points.len(), 2);
        for (p, e) in points.iter().zip(expected) {
            for k in 0..3 {
                assert!((p[k] as f64 - e[k]).abs() < 1e-3, "{p:?} {e:?}");
            }
            assert_eq!(p[3], 900.0, "the intensity as stored");
        }
        assert!(stream_las(&dir.path().join("missing.las"), &mut |_| Ok(())).is_err());

        // The header's x scale (bytes 131..139 of a LAS header) set to 0, then -0.001.
        for scale in [0.0f64, -0.001] {
            let mut bytes = std::fs::read(&path).unwrap();
            bytes[131..139].copy_from_slice(&scale.to_le_bytes());
            let bad = dir.path().join("bad.las");
            std::fs::write(&bad, bytes).unwrap();
            let err = stream_las(&bad, &mut |_| Ok(())).err().unwrap();
            assert!(
                err.contains(&format!("the header's x scale is {scale}")),
                "{err}"
            );
        }
    }

    /// GPS times from two interleaved sequences (two flight lines, or two sensors'
    /// returns) make LASzip switch sequence at almost every point: the patched laz
    /// (vendor/laz/TRAVMAP.md) loops where it recursed, and must decode the same.
    #[test]
    fn a_laz_file_with_interleaved_gps_times_reads_back_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("site.laz");
        let mut builder = las::Builder::from((1, 2));
        builder.point_format = las::point::Format::new(1).unwrap();
        builder.point_format.is_compressed = true;
        let mut writer = las::Writer::from_path(&path, builder.into_header().unwrap()).unwrap();
        let xyz_mm = |i: i32| [i * 7 % 1000, i * 13 % 997, i % 50];
        let points = 5_000;
        for i in 0..points {
            let [x, y, z] = xyz_mm(i).map(|mm| f64::from(mm) / 1000.0);
            let line_start_s = if i % 2 == 0 { 1_000.0 } else { 2_000_000.0 };
            writer
                .write_point(las::Point {
                    x,
                    y,
                    z,
                    gps_time: Some(line_start_s + f64::from(i) * 1e-4),
                    ..Default::default()
                })
                .unwrap();
        }
        writer.close().unwrap();
        let mut read = Vec::new();
        let place = stream_las(&path, &mut |batch: &[[f32; 4]]| {
            read.extend_from_slice(batch);
            Ok(())
        })
        .unwrap();
        assert_eq!(place.origin_m, [0.0; 3]);
        assert_eq!(read.len(), points as usize);
        for (i, p) in (0..points).zip(&read) {
            let mm = p.map(|v| (v * 1000.0).round() as i32);
            assert_eq!(mm[..3], xyz_mm(i), "point {i}");
        }
    }
}
